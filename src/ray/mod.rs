//! Ray tracing inside the REYES renderer: ray-traceable geometry, its BVH, and sample patterns.
//!
//! Input: a scene and its camera. Output: a [`RayScene`] (built once per frame, on the first
//! ray a shader casts, and cached in the shading system's [`RayCache`]) and closest-hit /
//! any-hit queries over it. Hit shading lives in `shade::rays`: a batch of hits becomes a grid
//! and runs the hit object's own shaders.
//! Invariants: everything here is deterministic: the ray geometry depends only on the scene and
//! the camera; sample directions are hashes of the shading point and the sample index, never of
//! a thread or a bucket.
//!
//! Files: `bvh` (binned-SAH BVH over micropolygons; `bvh/interleave` walks many rays at
//! once, `bvh/sah` builds its binary tree), `quad4` (its leaves' quad test four quads at a
//! time, SSE), `geometry` (ray dicing, visibility attributes), `area` (area lights' geometry,
//! sampled by area), `memhint` (prefetches and huge pages for the large arrays the walks and
//! hit shading read at random).

pub mod area;
pub mod bvh;
pub mod geometry;
pub(crate) mod memhint;
#[cfg(target_arch = "x86_64")]
mod quad4;

use std::sync::{Arc, OnceLock};

use glam::Vec3;

pub use area::{AreaSample, AreaShape};
pub use bvh::{Bvh, Hit};
pub use geometry::{RayGrid, RayScene};

/// The frame's ray geometry and area light shapes, each built on first use.
#[derive(Default)]
pub struct RayCache {
    cell: OnceLock<Arc<RayScene>>,
    /// One entry per scene light: the sampled shape of an area light, None for other lights.
    areas: OnceLock<Vec<Option<Arc<AreaShape>>>>,
}

impl RayCache {
    /// The ray scene, building it with `build` the first time (the build never re-enters
    /// rayon — its parallel parts run on plain scoped threads — so a worker thread waiting
    /// here cannot deadlock).
    pub fn get_or_build(&self, build: impl FnOnce() -> RayScene) -> Arc<RayScene> {
        self.cell.get_or_init(|| Arc::new(build())).clone()
    }
    /// The ray scene if it was built.
    pub fn get(&self) -> Option<&Arc<RayScene>> {
        self.cell.get()
    }
    /// The shapes of the scene's area lights (indexed by light), built on first use
    /// (sequentially, in light order).
    pub fn areas(
        &self,
        build: impl FnOnce() -> Vec<Option<Arc<AreaShape>>>,
    ) -> &[Option<Arc<AreaShape>>] {
        self.areas.get_or_init(build)
    }
}

impl std::fmt::Debug for RayCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RayCache")
            .field("built", &self.cell.get().is_some())
            .finish()
    }
}

/// A ray cone (Amanatides 1984; the "ray cones" of Akenine-Möller et al. 2019, a one-number
/// ray differential): the width of the ray's footprint where it starts and how fast the width
/// grows per unit of distance (the spread angle between neighbouring rays, radians). A
/// converging cone (a concave mirror) has a negative spread; its width is taken as the
/// magnitude. Hit shading uses the width at the hit for its derivatives and texture filter
/// widths (see `shade::rays`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cone {
    pub width: f32,
    pub spread: f32,
}

impl Cone {
    /// The footprint width `dist` along the ray.
    #[inline]
    pub fn width_at(&self, dist: f32) -> f32 {
        let w = (self.width + self.spread * dist).abs();
        if w.is_finite() {
            w
        } else {
            0.0
        }
    }
}

/// A uniform number in [0, 1) from a hash.
#[inline]
pub fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A seed for a shading point: its position's bits (and a per-call salt), so samples are the
/// same whatever grid, bucket or thread the point is shaded in.
#[inline]
pub fn point_seed(p: Vec3, salt: u32) -> u32 {
    use crate::pattern::hash::{hash_combine, hash_u32};
    let h = hash_u32(p.x.to_bits() ^ salt);
    let h = hash_combine(h, p.y.to_bits());
    hash_combine(h, p.z.to_bits())
}

/// Sample `k` of `count` stratified over the unit square (a √count × √count jittered grid,
/// the rest of the samples jittered over the whole square).
#[inline]
pub fn stratified(seed: u32, k: u32, count: u32) -> (f32, f32) {
    use crate::pattern::hash::hash_combine;
    let side = (count as f32).sqrt().floor().max(1.0) as u32;
    let h1 = hash_combine(seed, 2 * k);
    let h2 = hash_combine(seed, 2 * k + 1);
    if k < side * side {
        let (i, j) = (k % side, k / side);
        (
            (i as f32 + unit(h1)) / side as f32,
            (j as f32 + unit(h2)) / side as f32,
        )
    } else {
        (unit(h1), unit(h2))
    }
}

/// An orthonormal basis around the unit vector `n`: (tangent, bitangent).
#[inline]
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let a = if n.x.abs() > 0.9 { Vec3::Y } else { Vec3::X };
    let t = n.cross(a).normalize();
    (t, n.cross(t))
}

/// Cosine-weighted direction over the hemisphere around unit `n` (Malley's method), with the
/// hemisphere narrowed to a cone of half-angle `cone` (radians, ≤ π/2).
#[inline]
pub fn cosine_dir(n: Vec3, u1: f32, u2: f32, cone: f32) -> Vec3 {
    let s = cone.clamp(0.0, std::f32::consts::FRAC_PI_2).sin();
    let r = (u1).sqrt() * s;
    let phi = 2.0 * std::f32::consts::PI * u2;
    let (t, b) = basis(n);
    let z = (1.0 - r * r).max(0.0).sqrt();
    t * (r * phi.cos()) + b * (r * phi.sin()) + n * z
}

/// Uniform direction in the cone of half-angle `cone` around unit `n`.
#[inline]
pub fn cone_dir(n: Vec3, u1: f32, u2: f32, cone: f32) -> Vec3 {
    if cone <= 0.0 {
        return n;
    }
    let cos_max = cone.min(std::f32::consts::PI).cos();
    let z = 1.0 - u1 * (1.0 - cos_max);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    let (t, b) = basis(n);
    t * (r * phi.cos()) + b * (r * phi.sin()) + n * z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_samples_have_the_cosine_mean() {
        // E[cos θ] = 2/3 for a cosine-weighted hemisphere.
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let count = 4096;
        let mut sum = 0.0;
        for k in 0..count {
            let (a, b) = stratified(7, k, count);
            let d = cosine_dir(n, a, b, std::f32::consts::FRAC_PI_2);
            assert!((d.length() - 1.0).abs() < 1e-4);
            sum += d.dot(n);
        }
        assert!((sum / count as f32 - 2.0 / 3.0).abs() < 2e-3);
    }
}
