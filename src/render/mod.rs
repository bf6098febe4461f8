//! The REYES renderer: camera, buckets, split/dice decisions, hiders, and the frame driver.
//!
//! Input: a built [`crate::scene::Scene`] and a [`GridShader`] (the shading-language runtime).
//! Output: a filtered [`crate::film::Film`]. Invariants: see [`driver`] — the image does not
//! depend on the bucket size or the thread count.
//!
//! Modules: [`camera`] (projection, crop, named spaces), [`dice`] (cull / split / dice
//! decisions), [`limits`] (clamps on absurd requests), [`lod`] (level of detail: which representation is drawn), [`driver`] (buckets, forwarding, shading, parallelism), [`hider`] (the shared
//! `ShadedGrid` form and the hiders: [`hider::zbuffer`]; an A-buffer plugs in as another
//! [`hider::Hider`]), [`sampler`] (hashed jittered sample positions), [`stats`] (`--stats`).

pub mod camera;
pub mod dice;
pub mod dispbound;
pub mod driver;
pub mod hider;
pub mod limits;
pub mod lod;
pub mod motion;
pub mod packed;
pub mod sampler;
pub mod stats;

pub use crate::film::Film;
pub use camera::{crop_region, Camera, PixelRect};
pub use driver::{render_frame, render_frame_rows, render_surfaces, RenderOptions};
pub use hider::{Aov, Hider, ShadedGrid};
pub use stats::Stats;

use crate::scene::Scene;
use crate::shade::Grid;

/// The shading hook the driver calls on every diced grid.
pub trait GridShader: Sync {
    /// Runs the displacement shader (if any) over a freshly diced grid (P moves, N recomputed;
    /// Ng should be recomputed too, as back-face culling uses the displaced geometry).
    fn displace(&self, scene: &Scene, camera: &Camera, prim: usize, grid: &mut Grid);
    /// Runs the surface shader (with lights) and the atmosphere shader: fills grid.ci / grid.oi
    /// (Ci premultiplied by Oi, as RenderMan shaders leave it).
    fn shade(&self, scene: &Scene, camera: &Camera, prim: usize, grid: &mut Grid);
}

/// A plain surface for tests and for primitives without a shader: no displacement,
/// `Oi = Os`, `Ci = Os · Cs · |N·I|` (a facing ratio, so shapes read without lights).
#[derive(Clone, Copy, Debug, Default)]
pub struct DefaultShader;

impl GridShader for DefaultShader {
    fn displace(&self, _scene: &Scene, _camera: &Camera, _prim: usize, _grid: &mut Grid) {}

    fn shade(&self, _scene: &Scene, _camera: &Camera, _prim: usize, grid: &mut Grid) {
        let n = grid.len();
        grid.ci.resize(n, glam::Vec3::ZERO);
        grid.oi.resize(n, glam::Vec3::ONE);
        for k in 0..n {
            let nn = grid
                .n
                .get(k)
                .copied()
                .unwrap_or_default()
                .normalize_or_zero();
            let ii = grid
                .i
                .get(k)
                .copied()
                .unwrap_or_default()
                .normalize_or_zero();
            let facing = if nn == glam::Vec3::ZERO || ii == glam::Vec3::ZERO {
                1.0
            } else {
                nn.dot(ii).abs()
            };
            let cs = grid.cs.get(k).copied().unwrap_or(glam::Vec3::ONE);
            let os = grid.os.get(k).copied().unwrap_or(glam::Vec3::ONE);
            grid.oi[k] = os;
            grid.ci[k] = cs * os * facing;
        }
    }
}
