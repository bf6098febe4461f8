//! Displacement bounds estimated for displaced primitives that declare none.
//!
//! Input: a primitive's surfaces, its displacement shader (through [`GridShader`]) and the
//! view. Output: a camera-space distance the primitive's bound is widened by.
//!
//! Why: a grid is sampled only inside its surface's (widened) bound, so that every bucket
//! layout gives the same picture; a displacement past the bound is cut off and shows as cracks
//! along grid edges. RISpec asks scenes to declare `Attribute "displacementbound"`; a primitive
//! that declares none is only bump mapped (see `shade::system::bump_only`) unless it asks for
//! BMRT's `Attribute "render" "truedisplacement" [1]`, which never needed a bound. Before bucketing,
//! a few coarse test grids of the primitive are displaced and the largest movement, with a
//! margin, becomes the bound. The estimate depends only on the primitive and the camera, so
//! the picture stays identical for any bucket size or thread count.

use glam::Mat4;

use crate::geom::Surface;
use crate::scene::Scene;

use super::camera::Camera;
use super::GridShader;

/// Most pieces of one primitive displaced for the estimate (evenly spread over its surfaces).
const MAX_PIECES: usize = 8;
/// Most splits taken to reach a diceable piece.
const MAX_DEPTH: u32 = 8;
/// Test grid points along a side: at most this many, at least 3.
const MAX_SIDE: usize = 33;
/// The measured movement is multiplied by this: test grids are coarser than the final ones,
/// so they can miss the highest peaks of a fine pattern.
const MARGIN: f32 = 1.5;

/// The largest distance the displacement shader moves points of primitive `prim` by, in
/// camera space, times a margin; 0 when nothing moves (or nothing could be diced).
pub fn estimate(
    scene: &Scene,
    camera: &Camera,
    raster_from_camera: &Mat4,
    shading_rate: f32,
    prim: usize,
    surfaces: &[Box<dyn Surface>],
    shader: &dyn GridShader,
) -> f32 {
    let edge = shading_rate.max(1e-4).sqrt();
    let mut most = 0f32;
    let mut budget = 2 * MAX_PIECES;
    let step = surfaces.len().div_ceil(MAX_PIECES).max(1);
    for s in surfaces.iter().step_by(step) {
        diceable_pieces(s.as_ref(), 0, &mut budget, &mut |piece| {
            // About half the final dicing rate per side: coarse enough to be cheap, fine
            // enough for the displacement's pattern to show its amplitude.
            let side = |len: f32| ((len / edge * 0.5).ceil() as usize).clamp(3, MAX_SIDE);
            let (nu, nv) = match piece.raster_lengths(raster_from_camera) {
                Some((lu, lv)) if lu.is_finite() && lv.is_finite() => (side(lu), side(lv)),
                _ => (9, 9),
            };
            let mut grid = piece.dice(nu, nv);
            if grid.p.len() != nu * nv || grid.p.iter().any(|p| !p.is_finite()) {
                return;
            }
            super::driver::set_incident(&mut grid, camera.perspective);
            let before = grid.p.clone();
            shader.displace(scene, camera, prim, &mut grid);
            for (a, b) in before.iter().zip(&grid.p) {
                let d = a.distance(*b);
                if d.is_finite() {
                    most = most.max(d);
                }
            }
        });
    }
    most * MARGIN
}

/// Calls `f` on `s` if it can be diced, else on pieces of its splits (the first and last
/// child at each level, so both ends of a mesh or patch are represented), at most `budget`
/// times in all.
fn diceable_pieces(
    s: &dyn Surface,
    depth: u32,
    budget: &mut usize,
    f: &mut dyn FnMut(&dyn Surface),
) {
    if *budget == 0 {
        return;
    }
    if s.diceable() {
        *budget -= 1;
        f(s);
        return;
    }
    if depth >= MAX_DEPTH {
        return;
    }
    let kids = s.split();
    let n = kids.len();
    for (k, kid) in kids.iter().enumerate() {
        if k == 0 || k + 1 == n {
            diceable_pieces(kid.as_ref(), depth + 1, budget, f);
        }
    }
}
