//! Shadow-map lookups: percentage-closer filtering (Reeves, Salesin & Cook '87; notes
//! pipeline.md §4.6 with errata E11 applied).
//!
//! Input: a shadow map (depths in the light's camera space, +∞ where nothing was hit, plus
//! the light's camera_from_world and screen_from_world), world-space points (centre + the
//! 4 corners of the shading footprint), samples, bias, blur, width. Output: the fraction of
//! the footprint in shadow, in [0, 1].
//! Invariants: points outside the map or behind the light are unshadowed; each sample
//! compares its own jittered texel with a bias (no filtering of depths); the jitter is
//! stratified and deterministic (hashed from the point), so renders repeat exactly.

use glam::{Mat4, Vec3, Vec4};

use super::cache::Fetcher;

/// Parameters of one shadow() call.
#[derive(Clone, Copy, Debug)]
pub struct ShadowParams {
    pub samples: usize,
    pub bias: f32,
    pub blur: f32,
    pub width: f32,
}

/// The light's matrices as glam (column-vector) matrices.
pub struct LightView {
    pub camera_from_world: Mat4,
    pub screen_from_world: Mat4,
}

impl LightView {
    pub fn from_rows(a: &[f32; 16], b: &[f32; 16]) -> LightView {
        LightView {
            camera_from_world: Mat4::from_cols_array(a).transpose(),
            screen_from_world: Mat4::from_cols_array(b).transpose(),
        }
    }
    /// (raster x, raster y, light depth) of a world point, None behind the light.
    fn project(&self, p: Vec3, w: f32, h: f32) -> Option<(f32, f32, f32)> {
        let z = self.camera_from_world.transform_point3(p).z;
        let q = self.screen_from_world * Vec4::new(p.x, p.y, p.z, 1.0);
        if q.w <= 1e-12 || z <= 0.0 {
            return None;
        }
        let (sx, sy) = (q.x / q.w, q.y / q.w);
        Some(((sx + 1.0) * 0.5 * w, (1.0 - sy) * 0.5 * h, z))
    }
}

fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

#[inline]
fn rand01(h: &mut u32) -> f32 {
    *h = hash(h.wrapping_add(0x9e37_79b9));
    (*h >> 8) as f32 / (1u32 << 24) as f32
}

/// Fraction in shadow for one point. `pts` = [centre, 4 corners] in world space.
pub fn pcf(f: &mut Fetcher, view: &LightView, pts: &[Vec3; 5], p: &ShadowParams) -> f32 {
    let l = f.tex.header.levels[0][0];
    let (w, h) = (l.width as f32, l.height as f32);
    let Some((x, y, z)) = view.project(pts[0], w, h) else {
        return 0.0;
    };
    // Footprint half-size in texels from the corners (a bounding box), scaled by width.
    let (mut hx, mut hy) = (0f32, 0f32);
    for c in &pts[1..] {
        if let Some((cx, cy, _)) = view.project(*c, w, h) {
            hx = hx.max((cx - x).abs());
            hy = hy.max((cy - y).abs());
        }
    }
    hx = (hx * p.width).min(w) + 0.5 * p.blur * w;
    hy = (hy * p.width).min(h) + 0.5 * p.blur * h;
    hx = hx.max(0.5);
    hy = hy.max(0.5);
    if x < -hx - 1.0 || y < -hy - 1.0 || x > w + hx + 1.0 || y > h + hy + 1.0 {
        return 0.0;
    }
    let n = p.samples.clamp(1, 1024);
    // ns × nt ≈ n with ns/hx ≈ nt/hy.
    let nt = ((n as f32 * hy / hx).sqrt().round() as usize).clamp(1, n);
    let ns = (n as f32 / nt as f32).round().max(1.0) as usize;
    let (ds, dt) = (2.0 * hx / ns as f32, 2.0 * hy / nt as f32);
    let mut seed = hash(x.to_bits() ^ hash(y.to_bits() ^ hash(z.to_bits())));
    let mut count = 0usize;
    for j in 0..nt {
        for i in 0..ns {
            let su = x - hx + (i as f32 + rand01(&mut seed)) * ds;
            let tv = y - hy + (j as f32 + rand01(&mut seed)) * dt;
            let (iu, iv) = (crate::num::floor_i64(su), crate::num::floor_i64(tv));
            if iu < 0 || iv < 0 || iu >= l.width as i64 || iv >= l.height as i64 {
                continue;
            }
            let mut d = [0f32];
            f.accum(0, 0, iu as usize, iv as usize, 1.0, &mut d);
            if z > d[0] + p.bias {
                count += 1;
            }
        }
    }
    count as f32 / (ns * nt) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::cache::{Texture, TileCache};
    use crate::texture::format::{Header, Kind, TILE};
    use crate::texture::image_in::Image;
    use crate::texture::mipmap::Wrap;

    fn ortho_map(depths: Vec<f32>, n: usize) -> Texture {
        let im = Image {
            width: n,
            height: n,
            nchan: 1,
            data: depths,
        };
        let header = Header {
            kind: Kind::Shadow,
            nchan: 1,
            nfaces: 1,
            swrap: Wrap::Black,
            twrap: Wrap::Black,
            tile: TILE,
            levels: Vec::new(),
            matrices: None,
        };
        Texture::from_pyramids(1, header, &[vec![im]])
    }

    #[test]
    fn book_example_pcf_fraction() {
        // 3×3 map: 5 texels at 1.2 (blockers), 4 at 50.1; receiver at 49.8 → 5/9 in shadow.
        let d = vec![1.2, 50.1, 1.2, 50.1, 1.2, 50.1, 1.2, 50.1, 1.2];
        let tex = ortho_map(d, 3);
        let cache = TileCache::new(1 << 20);
        let mut f = Fetcher::new(&tex, &cache, 0, 1);
        // Light camera = world; screen = orthographic over [-1.5, 1.5].
        let view = LightView {
            camera_from_world: Mat4::IDENTITY,
            screen_from_world: Mat4::from_scale(Vec3::new(1.0 / 1.5, 1.0 / 1.5, 1.0)),
        };
        let c = Vec3::new(0.0, 0.0, 49.8);
        let pts = [c, c, c, c, c];
        let p = ShadowParams {
            samples: 900,
            bias: 0.0,
            blur: 1.0,
            width: 1.0,
        };
        let frac = pcf(&mut f, &view, &pts, &p);
        assert!((frac - 5.0 / 9.0).abs() < 0.03, "{frac}");
        // A receiver in front of everything, and one off the map, are lit.
        let near = Vec3::new(0.0, 0.0, 1.0);
        assert_eq!(pcf(&mut f, &view, &[near; 5], &p), 0.0);
        let off = Vec3::new(10.0, 0.0, 49.8);
        assert_eq!(
            pcf(&mut f, &view, &[off; 5], &ShadowParams { blur: 0.0, ..p }),
            0.0
        );
        // The blocker itself with a bias is not self-shadowed.
        let on = Vec3::new(-1.0, 1.0, 1.2);
        let hard = ShadowParams {
            samples: 16,
            bias: 0.01,
            blur: 0.0,
            width: 1.0,
        };
        assert_eq!(pcf(&mut f, &view, &[on; 5], &hard), 0.0);
    }
}
