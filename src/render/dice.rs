//! The split/dice decision: cull a surface, split it, or dice it into a grid of what size.
//!
//! Input: a [`Surface`], its camera-space bound already widened by the displacement bound,
//! the shading rate, and the frame's [`View`]. Output: a [`Decision`].
//! Invariants: the decision depends only on the surface and the camera (never on a bucket or
//! thread), so a frame renders the same micropolygons whatever the bucket size or thread count.
//! A diced grid has micropolygons whose edges are about √ShadingRate pixels long (area about
//! ShadingRate pixels), and at most `max_grid` micropolygons.

use glam::{Mat4, Vec3, Vec4};

use crate::geom::{Bound, Surface};
use crate::shade::Grid;

use super::camera::{Camera, Dof, PixelRect};

/// Points per side of the trial grid used to measure a surface's size on screen.
pub const TEST_DICE: usize = 5;

/// The frame's viewing volume as the dicer needs it.
#[derive(Clone, Debug)]
pub struct View {
    pub raster_from_camera: Mat4,
    pub screen_from_camera: Mat4,
    pub perspective: bool,
    pub near: f32,
    pub far: f32,
    /// The sampled raster region (crop window plus the filter margin): x0, y0, x1, y1.
    pub region: [f32; 4],
    /// The same region in screen space: xmin, xmax, ymin, ymax.
    pub screen: [f32; 4],
    /// Surfaces reaching closer than this to the eye plane are split, never diced (their
    /// projection is unbounded).
    pub eye_epsilon: f32,
    /// Most micropolygons in one grid; larger surfaces split.
    pub max_grid: usize,
    /// The thin lens, when DepthOfField is on: bounds widen by the circle of confusion.
    pub dof: Option<Dof>,
}

/// What to do with a surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Outside the viewing volume: drop it.
    Cull,
    /// Too big, not diceable, or straddling the eye plane (`eye`).
    Split { eye: bool },
    /// Dice into `nu × nv` micropolygons, i.e. `(nu + 1) × (nv + 1)` grid points.
    Dice { nu: usize, nv: usize },
    /// The surface's points are not finite: drop it (and report it).
    Broken,
}

impl View {
    pub fn new(camera: &Camera, region: PixelRect, max_grid: usize) -> View {
        let raster_from_camera = camera.raster_from_camera();
        let screen_from_raster = camera.raster_from_screen.inverse();
        let a =
            screen_from_raster.project_point3(Vec3::new(region.x0 as f32, region.y0 as f32, 0.0));
        let b =
            screen_from_raster.project_point3(Vec3::new(region.x1 as f32, region.y1 as f32, 0.0));
        View {
            raster_from_camera,
            screen_from_camera: camera.screen_from_camera,
            perspective: camera.perspective,
            near: camera.near,
            far: camera.far,
            region: [
                region.x0 as f32,
                region.y0 as f32,
                region.x1 as f32,
                region.y1 as f32,
            ],
            screen: [a.x.min(b.x), a.x.max(b.x), a.y.min(b.y), a.y.max(b.y)],
            // Below this depth a projected bound is no longer meaningful in f32.
            eye_epsilon: if camera.perspective {
                camera.near.clamp(1e-7, 1e-4)
            } else {
                f32::NEG_INFINITY
            },
            max_grid: max_grid.max(1),
            dof: camera.dof,
        }
    }

    /// Raster x, y of a camera-space point (z ≥ eye_epsilon for perspective views).
    #[inline]
    pub fn to_raster(&self, p: Vec3) -> [f32; 2] {
        let c = self.raster_from_camera * p.extend(1.0);
        if self.perspective {
            [c.x / c.w, c.y / c.w]
        } else {
            [c.x, c.y]
        }
    }

    /// True when the bound lies wholly outside the viewing volume (side planes of the sampled
    /// region, near and far).
    pub fn outside(&self, b: &Bound) -> bool {
        if b.is_empty() || b.max.z < self.near || b.min.z > self.far {
            return true;
        }
        let [mut x0, mut x1, mut y0, mut y1] = self.screen;
        if let Some(d) = &self.dof {
            // Out of focus a bound reaches its circle of confusion further.
            let c = d.coc_factor(b.min.z.max(self.near), b.max.z);
            if !c.is_finite() {
                return false;
            }
            let (cx, cy) = (d.screen_k[0].abs() * c, d.screen_k[1].abs() * c);
            (x0, x1, y0, y1) = (x0 - cx, x1 + cx, y0 - cy, y1 + cy);
        }
        let mut out = [true; 4];
        for p in b.corners() {
            let c: Vec4 = self.screen_from_camera * p.extend(1.0);
            // x_s = c.x / c.w ≥ x0 ⟺ c.x − x0·c.w ≥ 0 for c.w > 0; as a half-space of camera
            // space it holds for every corner, in front of the eye or not.
            out[0] &= c.x - x0 * c.w < 0.0;
            out[1] &= x1 * c.w - c.x < 0.0;
            out[2] &= c.y - y0 * c.w < 0.0;
            out[3] &= y1 * c.w - c.y < 0.0;
        }
        out.iter().any(|&o| o)
    }

    /// The raster bound (x0, y0, x1, y1) of a camera-space bound in front of the eye plane,
    /// widened by the largest circle of confusion over its depths when DepthOfField is on;
    /// None when it reaches behind `eye_epsilon`.
    pub fn raster_bound(&self, b: &Bound) -> Option<[f32; 4]> {
        let r = self.raster_bound_sharp(b)?;
        let Some(d) = &self.dof else {
            return Some(r);
        };
        let c = d.coc_factor(b.min.z, b.max.z);
        let (cx, cy) = (d.raster_k[0].abs() * c, d.raster_k[1].abs() * c);
        let r = [r[0] - cx, r[1] - cy, r[2] + cx, r[3] + cy];
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    /// The raster bound through the pinhole (no circle of confusion).
    pub fn raster_bound_sharp(&self, b: &Bound) -> Option<[f32; 4]> {
        if b.min.z < self.eye_epsilon {
            return None;
        }
        let mut r = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        for p in b.corners() {
            let [x, y] = self.to_raster(p);
            r[0] = r[0].min(x);
            r[1] = r[1].min(y);
            r[2] = r[2].max(x);
            r[3] = r[3].max(y);
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn overlaps_region(&self, r: &[f32; 4]) -> bool {
        r[0] <= self.region[2]
            && r[2] >= self.region[0]
            && r[1] <= self.region[3]
            && r[3] >= self.region[1]
    }
}

/// Decides how to handle `surface`, whose camera-space bound widened by the displacement
/// bound is `bound`. `shading_rate` is the micropolygon area in pixels.
pub fn decide(surface: &dyn Surface, bound: &Bound, shading_rate: f32, view: &View) -> Decision {
    if view.outside(bound) {
        return Decision::Cull;
    }
    let Some(rb) = view.raster_bound(bound) else {
        return Decision::Split { eye: true };
    };
    if !view.overlaps_region(&rb) {
        return Decision::Cull;
    }
    if !surface.diceable() {
        return Decision::Split { eye: false };
    }
    let edge = shading_rate.max(1e-4).sqrt();
    // A surface far bigger than any grid can cover: split without trial dicing. Its own
    // bound, not the displacement-widened one: splitting never shrinks the widening, so a
    // displacement bound larger than a grid would split forever.
    // Sharp and at shutter open: blur (lens or motion) does not shrink when split.
    let own = view
        .raster_bound_sharp(&surface.still_bound())
        .unwrap_or(rb);
    let (bw, bh) = ((own[2] - own[0]) / edge, (own[3] - own[1]) / edge);
    if surface.splittable()
        && bw * bh > 64.0 * view.max_grid as f32
        && bw.max(bh) > 8.0 * (view.max_grid as f32).sqrt()
    {
        return Decision::Split { eye: false };
    }
    // Trial dice: the longest u-line and v-line on screen set the dicing rates. (Once the
    // geometry's `Surface::raster_lengths` hook is available it can replace this when Some.)
    let grid = surface.dice(TEST_DICE, TEST_DICE);
    let d = decide_from_trial(surface, &grid, edge, view);
    // Its buffers came from this thread's pool: back there (freed, they would drain it).
    grid.recycle();
    d
}

/// [`decide`] once `grid`, the surface diced `TEST_DICE × TEST_DICE`, has shown how long its
/// lines are on screen (`edge`: a micropolygon's side in pixels).
fn decide_from_trial(surface: &dyn Surface, grid: &Grid, edge: f32, view: &View) -> Decision {
    let n = TEST_DICE;
    if grid.p.len() < n * n {
        return Decision::Split { eye: false };
    }
    let mut r = [[0f32; 2]; TEST_DICE * TEST_DICE];
    for (k, p) in grid.p.iter().take(n * n).enumerate() {
        if !p.is_finite() {
            return Decision::Broken;
        }
        if view.perspective && p.z < view.eye_epsilon {
            return Decision::Split { eye: true };
        }
        r[k] = view.to_raster(*p);
    }
    let dist = |a: [f32; 2], b: [f32; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let (mut ulen, mut vlen) = (0f32, 0f32);
    for j in 0..n {
        let (mut lu, mut lv) = (0f32, 0f32);
        for i in 0..n - 1 {
            lu += dist(r[j * n + i], r[j * n + i + 1]);
            lv += dist(r[i * n + j], r[(i + 1) * n + j]);
        }
        ulen = ulen.max(lu);
        vlen = vlen.max(lv);
    }
    let mut nu = (ulen / edge).ceil().max(1.0);
    let mut nv = (vlen / edge).ceil().max(1.0);
    if !(nu * nv).is_finite() {
        return Decision::Split { eye: false };
    }
    if nu * nv > view.max_grid as f32 {
        if surface.splittable() {
            return Decision::Split { eye: false };
        }
        // Nothing smaller to split into: shade it coarser, within the grid limit.
        let f = (view.max_grid as f32 / (nu * nv)).sqrt();
        nu = (nu * f).floor().max(1.0);
        nv = (nv * f).floor().max(1.0);
    }
    Decision::Dice {
        nu: nu as usize,
        nv: nv as usize,
    }
}

/// Attribute "dice" "binary": dicing rates rounded up to powers of two (neighbouring grids
/// then share more vertices, hiding cracks); a grid that would outgrow `max_grid` splits.
pub fn binary(d: Decision, max_grid: usize) -> Decision {
    match d {
        Decision::Dice { nu, nv } => {
            let (bu, bv) = (nu.next_power_of_two(), nv.next_power_of_two());
            if bu * bv > max_grid {
                Decision::Split { eye: false }
            } else {
                Decision::Dice { nu: bu, nv: bv }
            }
        }
        other => other,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn binary_dicing_rounds_to_powers_of_two() {
        assert_eq!(
            binary(Decision::Dice { nu: 5, nv: 8 }, 256),
            Decision::Dice { nu: 8, nv: 8 }
        );
        assert_eq!(
            binary(Decision::Dice { nu: 1, nv: 17 }, 256),
            Decision::Dice { nu: 1, nv: 32 }
        );
        assert_eq!(
            binary(Decision::Dice { nu: 9, nv: 17 }, 256),
            Decision::Split { eye: false }
        );
        assert_eq!(binary(Decision::Cull, 256), Decision::Cull);
    }
    use crate::shade::Grid;

    /// A bilinear quad in camera space: corners p00, p10, p01, p11 (u along p00→p10).
    #[derive(Clone, Debug)]
    pub struct Quad {
        pub p: [Vec3; 4],
        pub prim: usize,
        pub uv: [f32; 4],
    }

    impl Quad {
        pub fn new(p00: Vec3, p10: Vec3, p01: Vec3, p11: Vec3, prim: usize) -> Quad {
            Quad {
                p: [p00, p10, p01, p11],
                prim,
                uv: [0.0, 1.0, 0.0, 1.0],
            }
        }
        /// An axis-aligned rectangle [x0, x1] × [y0, y1] at depth z, facing the camera
        /// (Ng towards −z).
        pub fn rect(x0: f32, y0: f32, x1: f32, y1: f32, z: f32, prim: usize) -> Quad {
            Quad::new(
                Vec3::new(x0, y0, z),
                Vec3::new(x1, y0, z),
                Vec3::new(x0, y1, z),
                Vec3::new(x1, y1, z),
                prim,
            )
        }
        fn at(&self, u: f32, v: f32) -> Vec3 {
            let [a, b, c, d] = self.p;
            (a * (1.0 - u) + b * u) * (1.0 - v) + (c * (1.0 - u) + d * u) * v
        }
    }

    impl Surface for Quad {
        fn bound(&self) -> Bound {
            Bound::from_points(self.p)
        }
        fn split(&self) -> Vec<Box<dyn Surface>> {
            let [u0, u1, v0, v1] = self.uv;
            let lu = (self.p[1] - self.p[0]).length() + (self.p[3] - self.p[2]).length();
            let lv = (self.p[2] - self.p[0]).length() + (self.p[3] - self.p[1]).length();
            let mk = |a: (f32, f32), b: (f32, f32), c: (f32, f32), d: (f32, f32), uv| {
                let q = Quad {
                    p: [
                        self.at(a.0, a.1),
                        self.at(b.0, b.1),
                        self.at(c.0, c.1),
                        self.at(d.0, d.1),
                    ],
                    prim: self.prim,
                    uv,
                };
                Box::new(q) as Box<dyn Surface>
            };
            let (um, vm) = ((u0 + u1) * 0.5, (v0 + v1) * 0.5);
            if lu >= lv {
                vec![
                    mk((0., 0.), (0.5, 0.), (0., 1.), (0.5, 1.), [u0, um, v0, v1]),
                    mk((0.5, 0.), (1., 0.), (0.5, 1.), (1., 1.), [um, u1, v0, v1]),
                ]
            } else {
                vec![
                    mk((0., 0.), (1., 0.), (0., 0.5), (1., 0.5), [u0, u1, v0, vm]),
                    mk((0., 0.5), (1., 0.5), (0., 1.), (1., 1.), [u0, u1, vm, v1]),
                ]
            }
        }
        fn dice(&self, nu: usize, nv: usize) -> Grid {
            let mut g = Grid::with_size(nu, nv);
            let [u0, u1, v0, v1] = self.uv;
            g.du = (u1 - u0) / (nu - 1) as f32;
            g.dv = (v1 - v0) / (nv - 1) as f32;
            for j in 0..nv {
                for i in 0..nu {
                    let (u, v) = (i as f32 / (nu - 1) as f32, j as f32 / (nv - 1) as f32);
                    let k = j * nu + i;
                    let p = self.at(u, v);
                    let dpdu = (self.at(1.0, v) - self.at(0.0, v)) / (u1 - u0);
                    let dpdv = (self.at(u, 1.0) - self.at(u, 0.0)) / (v1 - v0);
                    // Chosen so that a rectangle with u along +x and v along +y faces the
                    // camera (Ng towards −z).
                    let n = dpdv.cross(dpdu).normalize_or_zero();
                    g.p[k] = p;
                    g.dpdu[k] = dpdu;
                    g.dpdv[k] = dpdv;
                    g.n[k] = n;
                    g.ng[k] = n;
                    g.u[k] = u0 + u * (u1 - u0);
                    g.v[k] = v0 + v * (v1 - v0);
                    g.s[k] = g.u[k];
                    g.t[k] = g.v[k];
                    g.i[k] = p;
                }
            }
            g
        }
        fn primitive(&self) -> usize {
            self.prim
        }
    }

    fn ortho_view(res: u32) -> View {
        let mut o = crate::scene::Options::default();
        o.xres = res;
        o.yres = res;
        let cam = Camera::from_options(&o, Mat4::IDENTITY, &Default::default());
        View::new(
            &cam,
            PixelRect {
                x0: 0,
                y0: 0,
                x1: res as i32,
                y1: res as i32,
            },
            1024,
        )
    }

    #[test]
    fn dice_rates_follow_the_shading_rate() {
        // Orthographic 64×64 over [-1,1]²: a rectangle 1 unit wide covers 32 pixels.
        let v = ortho_view(64);
        let q = Quad::rect(-0.5, -0.25, 0.5, 0.25, 1.0, 0);
        let b = q.bound();
        assert_eq!(decide(&q, &b, 1.0, &v), Decision::Dice { nu: 32, nv: 16 });
        assert_eq!(decide(&q, &b, 4.0, &v), Decision::Dice { nu: 16, nv: 8 });
        // Rate 0.25 needs 64×32 = 2048 micropolygons > 1024: split.
        assert_eq!(decide(&q, &b, 0.25, &v), Decision::Split { eye: false });
    }

    #[test]
    fn a_displacement_bound_wider_than_a_grid_does_not_force_splits() {
        // A 4-pixel square whose displacement bound reaches far over the frame: it dices at
        // its own size (the widened bound only decides culling).
        let v = ortho_view(64);
        let q = Quad::rect(-0.0625, -0.0625, 0.0625, 0.0625, 1.0, 0);
        let widened = q.bound().grow(20.0);
        assert_eq!(
            decide(&q, &widened, 1.0, &v),
            Decision::Dice { nu: 4, nv: 4 }
        );
    }

    #[test]
    fn surfaces_outside_the_frustum_are_culled() {
        let v = ortho_view(64);
        let q = Quad::rect(2.0, 2.0, 3.0, 3.0, 1.0, 0);
        assert_eq!(decide(&q, &q.bound(), 1.0, &v), Decision::Cull);
        // Behind the near plane.
        let q = Quad::rect(-0.5, -0.5, 0.5, 0.5, -1.0, 0);
        assert_eq!(decide(&q, &q.bound(), 1.0, &v), Decision::Cull);
    }

    #[test]
    fn eye_plane_straddlers_split_and_children_stay_inside() {
        let mut o = crate::scene::Options::default();
        o.xres = 64;
        o.yres = 64;
        o.projection = crate::scene::Projection::Perspective { fov: 90.0 };
        let cam = Camera::from_options(&o, Mat4::IDENTITY, &Default::default());
        let v = View::new(
            &cam,
            PixelRect {
                x0: 0,
                y0: 0,
                x1: 64,
                y1: 64,
            },
            1024,
        );
        // A floor from behind the eye to z = 10.
        let q = Quad::new(
            Vec3::new(-1.0, -1.0, -1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, -1.0, 10.0),
            Vec3::new(1.0, -1.0, 10.0),
            0,
        );
        assert_eq!(
            decide(&q, &q.bound(), 1.0, &v),
            Decision::Split { eye: true }
        );
        let parent = q.bound();
        for c in q.split() {
            let b = c.bound();
            assert!(b.min.cmpge(parent.min).all() && b.max.cmple(parent.max).all());
        }
    }
}
