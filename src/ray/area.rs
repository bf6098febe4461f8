//! Area light geometry: the surfaces an `AreaLightSource` shines from, diced into triangles and
//! sampled uniformly by area.
//!
//! Input: the scene, the frame's camera and an area light's index; the light's geometry is
//! every primitive whose attributes name it (`Attributes::area_light`: the primitives that
//! follow `AreaLightSource` in its attribute block, RISpec §4.2.3). Output: an [`AreaShape`]:
//! camera-space triangles with the per-vertex normal, derivatives and parameters of their
//! diced grids, in rows (a row of micropolygons of a grid), and cumulative-area tables over
//! the rows and over the triangles of each row, from which [`AreaShape::sample`] maps a point
//! of the unit square to a point of the surface: uniform in area (a surface four times
//! larger gets four times the samples), and keeping strata (v picks the row, u the triangle
//! along it, what is left of each places the point in the triangle), so a stratified pattern
//! stays spread over the surface.
//! Invariants: built sequentially in primitive order with dicing decisions that depend only on
//! the surface (not on the camera's view of it: a light is often off screen), so the samples
//! are the same whatever the thread count or bucket size. Any primitive that dices works
//! (quadrics, polygons and meshes, patches, NURBS, subdivision surfaces…); displacement of a
//! light's geometry is not applied to its samples.

use glam::Vec3;

use crate::diag::Diagnostics;
use crate::geom::Surface;
use crate::render::Camera;
use crate::scene::Scene;
use crate::shade::Grid;

/// Most micropolygons per side of one diced piece (larger or more curved pieces split).
const MAX_SIDE: usize = 64;
/// Most splits along one path.
const MAX_DEPTH: u32 = 16;
/// Chord tolerance, as a fraction of a piece's longest parameter line: a disk becomes a
/// polygon of about 80 sides, whose area is within 0.1 % of the disk's.
const REL_TOL: f32 = 1.0e-4;

/// One vertex of a light triangle: what the light shader sees there.
#[derive(Clone, Copy, Debug, Default)]
struct Vertex {
    p: Vec3,
    n: Vec3,
    ng: Vec3,
    dpdu: Vec3,
    dpdv: Vec3,
    /// u, v, s, t.
    uvst: [f32; 4],
}

/// A point sampled on an area light's surface (camera space).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AreaSample {
    pub p: Vec3,
    /// The interpolated shading normal (unit length).
    pub n: Vec3,
    /// The geometric normal (unit length).
    pub ng: Vec3,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    pub u: f32,
    pub v: f32,
    pub s: f32,
    pub t: f32,
}

/// The sampled surface of one area light.
#[derive(Debug, Default)]
pub struct AreaShape {
    tris: Vec<[Vertex; 3]>,
    /// cdf[k]: the fraction of its row's area in the row's triangles up to k (the row's last
    /// is 1).
    cdf: Vec<f32>,
    /// Rows: their first triangle (the next row's first ends them).
    rows: Vec<usize>,
    /// row_cdf[r]: the fraction of the total area in rows 0..=r (the last is 1).
    row_cdf: Vec<f32>,
    /// Total area (camera-space units²).
    pub area: f32,
    /// The primitives making up the light.
    pub prims: Vec<usize>,
}

impl AreaShape {
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Builds the shape of area light `light` (see the module invariants).
    pub fn build(scene: &Scene, camera: &Camera, light: usize, diags: &Diagnostics) -> AreaShape {
        let mut out = AreaShape::default();
        let mut areas: Vec<f64> = Vec::new();
        for (i, prim) in scene.primitives.iter().enumerate() {
            if prim.attributes.area_light != Some(light) {
                continue;
            }
            out.prims.push(i);
            let surfs = crate::geom::surfaces_for(i, prim, camera.camera_from_world, diags);
            let mut stack: Vec<(Box<dyn Surface>, u32)> =
                surfs.into_iter().rev().map(|s| (s, 0)).collect();
            while let Some((s, depth)) = stack.pop() {
                let b = s.bound();
                if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
                    continue;
                }
                let rate = if s.diceable() { dice_rate(&*s) } else { None };
                let (nu, nv) = match rate {
                    Some((nu, nv)) if nu <= MAX_SIDE && nv <= MAX_SIDE => (nu, nv),
                    Some((nu, nv)) if depth >= MAX_DEPTH => (nu.min(64), nv.min(64)),
                    _ if depth >= MAX_DEPTH && s.diceable() => (16, 16),
                    _ if depth >= MAX_DEPTH => continue,
                    _ => {
                        let kids = s.split();
                        stack.extend(kids.into_iter().rev().map(|k| (k, depth + 1)));
                        continue;
                    }
                };
                let g = s.dice(nu + 1, nv + 1);
                if g.nu < 2 || g.nv < 2 || g.p.len() != g.nu * g.nv {
                    continue;
                }
                if g.p.iter().any(|p| !p.is_finite()) {
                    continue;
                }
                out.add_grid(&g, &mut areas);
            }
        }
        let total: f64 = areas.iter().sum();
        if !(total > 0.0) || !total.is_finite() {
            out.tris.clear();
            out.rows.clear();
            return out;
        }
        out.cdf = vec![0.0; areas.len()];
        out.row_cdf = Vec::with_capacity(out.rows.len());
        let mut acc_total = 0f64;
        for r in 0..out.rows.len() {
            let (s, e) = (out.rows[r], out.row_end(r));
            let row: f64 = areas[s..e].iter().sum();
            let mut acc = 0f64;
            for k in s..e {
                acc += areas[k];
                out.cdf[k] = (acc / row) as f32;
            }
            out.cdf[e - 1] = 1.0;
            acc_total += row;
            out.row_cdf.push((acc_total / total) as f32);
        }
        if let Some(last) = out.row_cdf.last_mut() {
            *last = 1.0;
        }
        out.area = total as f32;
        out
    }

    fn row_end(&self, r: usize) -> usize {
        self.rows.get(r + 1).copied().unwrap_or(self.tris.len())
    }

    /// Cuts each micropolygon of a grid into two triangles `(v00 v10 v11)`, `(v00 v11 v01)`.
    fn add_grid(&mut self, g: &Grid, areas: &mut Vec<f64>) {
        let vert = |k: usize| Vertex {
            p: g.p[k],
            n: g.n[k],
            ng: g.ng[k],
            dpdu: g.dpdu[k],
            dpdv: g.dpdv[k],
            uvst: [g.u[k], g.v[k], g.s[k], g.t[k]],
        };
        for j in 0..g.nv - 1 {
            let first = self.tris.len();
            for i in 0..g.nu - 1 {
                let k = j * g.nu + i;
                let (a, b, c, d) = (vert(k), vert(k + 1), vert(k + g.nu), vert(k + g.nu + 1));
                for tri in [[a, b, d], [a, d, c]] {
                    let area =
                        0.5 * f64::from((tri[1].p - tri[0].p).cross(tri[2].p - tri[0].p).length());
                    if area > 0.0 && area.is_finite() {
                        self.tris.push(tri);
                        areas.push(area);
                    }
                }
            }
            if self.tris.len() > first {
                self.rows.push(first);
            }
        }
    }

    /// The point for `(u1, u2)` in the unit square: `u2` picks a row by area and `u1` a
    /// triangle along it; each is reused (rescaled) inside the triangle.
    pub fn sample(&self, u1: f32, u2: f32) -> AreaSample {
        if self.tris.is_empty() {
            return AreaSample::default();
        }
        // The index where `u` falls in `cdf`, and `u` rescaled inside that interval.
        let pick = |cdf: &[f32], u: f32| {
            let k = cdf.partition_point(|&c| c <= u).min(cdf.len() - 1);
            let lo = if k == 0 { 0.0 } else { cdf[k - 1] };
            let hi = cdf[k];
            let r = if hi > lo {
                ((u - lo) / (hi - lo)).clamp(0.0, 1.0)
            } else {
                0.5
            };
            (k, r)
        };
        let (row, r2) = pick(&self.row_cdf, u2);
        let (s, e) = (self.rows[row], self.row_end(row));
        let (k, r1) = pick(&self.cdf[s..e], u1);
        let k = s + k;
        let u2 = r2;
        // Uniform in the triangle: b0 = 1 − √r1, b1 = u2 √r1.
        let sq = r1.sqrt();
        let (b0, b1) = (1.0 - sq, u2 * sq);
        let b2 = (1.0 - b0 - b1).max(0.0);
        let [x, y, z] = &self.tris[k];
        let mix3 = |f: fn(&Vertex) -> Vec3| f(x) * b0 + f(y) * b1 + f(z) * b2;
        let mix1 = |c: usize| x.uvst[c] * b0 + y.uvst[c] * b1 + z.uvst[c] * b2;
        let ng_tri = (y.p - x.p).cross(z.p - x.p).normalize_or_zero();
        let ng_mix = mix3(|v| v.ng);
        // The triangle's own normal, turned to the side the surface's normals face.
        let ng = if ng_tri.dot(ng_mix) < 0.0 {
            -ng_tri
        } else {
            ng_tri
        };
        let n = mix3(|v| v.n).normalize_or(ng);
        AreaSample {
            p: mix3(|v| v.p),
            n,
            ng,
            dpdu: mix3(|v| v.dpdu),
            dpdv: mix3(|v| v.dpdv),
            u: mix1(0),
            v: mix1(1),
            s: mix1(2),
            t: mix1(3),
        }
    }
}

/// Micropolygons along u and v for a light surface, from a 5 × 5 trial dice: as few as keep
/// every chord within [`REL_TOL`] of the piece's size (a flat polygon is one micropolygon).
fn dice_rate(s: &dyn Surface) -> Option<(usize, usize)> {
    let n = 5;
    let g = s.dice(n, n);
    if g.p.len() < n * n || g.p.iter().any(|p| !p.is_finite()) {
        return None;
    }
    let (mut size, mut dev_u, mut dev_v) = (0f32, 0f32, 0f32);
    for j in 0..n {
        let (mut lu, mut lv) = (0f32, 0f32);
        for i in 0..n - 1 {
            lu += (g.p[j * n + i] - g.p[j * n + i + 1]).length();
            lv += (g.p[i * n + j] - g.p[(i + 1) * n + j]).length();
        }
        size = size.max(lu).max(lv);
        for i in 1..n - 1 {
            let k = j * n + i;
            dev_u = dev_u.max((g.p[k] - 0.5 * (g.p[k - 1] + g.p[k + 1])).length());
            let k = i * n + j;
            dev_v = dev_v.max((g.p[k] - 0.5 * (g.p[k - n] + g.p[k + n])).length());
        }
    }
    if !(size > 0.0) {
        return None;
    }
    // A point's distance from the middle of its neighbours is the sagitta of a chord spanning
    // half the piece; the sagitta falls with the square of the number of segments.
    let tol = REL_TOL * size;
    let need = |dev: f32| (2.0 * (dev / tol).sqrt()).ceil().clamp(1.0, 1e6) as usize;
    Some((need(dev_u), need(dev_v)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape_of(rib: &str) -> AreaShape {
        let sources = crate::diag::SourceMap::new();
        let diags = Diagnostics::new();
        let reqs = crate::rib::parse_bytes("<test>", rib.as_bytes(), &sources, &diags);
        let ctx = crate::scene::BuildContext::new(&sources, &diags);
        let scene = crate::scene::build_scenes(reqs, &ctx).remove(0);
        let camera = Camera::new(&scene);
        AreaShape::build(&scene, &camera, 0, &diags)
    }

    #[test]
    fn areas_of_a_disk_a_sphere_and_a_polygon() {
        let pi = std::f32::consts::PI;
        let s = shape_of(
            "WorldBegin\nAttributeBegin\nAreaLightSource \"arealight\" 1\nTranslate 0 0 5\n\
             Disk 0 2 360\nAttributeEnd\nSphere 1 -1 1 360\nWorldEnd\n",
        );
        assert_eq!(s.prims, vec![0]);
        assert!((s.area / (pi * 4.0) - 1.0).abs() < 2e-3, "disk {}", s.area);
        let s = shape_of(
            "WorldBegin\nAreaLightSource \"arealight\" 1\nTranslate 0 0 5\n\
             Sphere 1.5 -1.5 1.5 360\nWorldEnd\n",
        );
        assert!(
            (s.area / (4.0 * pi * 2.25) - 1.0).abs() < 3e-3,
            "sphere {}",
            s.area
        );
        let s = shape_of(
            "WorldBegin\nAreaLightSource \"arealight\" 1\n\
             Polygon \"P\" [0 0 5  3 0 5  3 2 5  0 2 5]\nWorldEnd\n",
        );
        assert!((s.area - 6.0).abs() < 1e-4, "polygon {}", s.area);
        // Samples land on the polygon, spread evenly: their mean is its centre.
        let mut mean = Vec3::ZERO;
        let count = 1024;
        for k in 0..count {
            let (a, b) = crate::ray::stratified(99, k, count);
            let p = s.sample(a, b);
            assert!((p.p.z - 5.0).abs() < 1e-4 && p.n.z.abs() > 0.999);
            mean += p.p;
        }
        mean /= count as f32;
        assert!((mean - Vec3::new(1.5, 1.0, 5.0)).length() < 0.02, "{mean}");
    }
}
