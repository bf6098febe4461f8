//! A parametric patch over a parameter rectangle: a quadric piece or a bilinear (polygon) patch.
//!
//! Input: a shape in camera space, the corner values of its primitive variables
//! ([`PatchVars`]) and a rectangle [u0,u1] × [v0,v1] of the shape's domain [0,1]².
//! Output: bounds, splits (halving the rectangle along the direction that is longer in camera
//! space) and grids with every standard global filled.
//! Invariants: children's rectangles tile the parent's, and their bounds lie inside the parent's
//! bound. Grid u, v are the shape's parameters (global over the quadric; the face's own
//! parameters for polygons); du, dv are the grid steps. Ng follows the orientation rule of
//! `surfaces_for` (see `geom` docs); N = Ng unless the primitive gives "N".

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use super::primvar::{fill_grid, PatchVars};
use super::quadric::Quadric;
use super::{Bound, Surface};
use crate::shade::Grid;

/// The geometry of a patch.
#[derive(Debug)]
pub(crate) enum Shape {
    Quadric(Quadric),
    /// Corners (0,0) (1,0) (0,1) (1,1) in camera space and the face's geometric normal
    /// (unit, orientation applied). A triangle repeats its last corner.
    Bilinear {
        p: [Vec3; 4],
        ng: Vec3,
    },
}

impl Shape {
    #[inline]
    fn position(&self, u: f32, v: f32) -> Vec3 {
        match self {
            Shape::Quadric(q) => q.eval(u, v).0,
            Shape::Bilinear { p, .. } => {
                (1.0 - v) * ((1.0 - u) * p[0] + u * p[1]) + v * ((1.0 - u) * p[2] + u * p[3])
            }
        }
    }
}

/// The piece of a primitive REYES bounds, splits and dices.
#[derive(Debug, Clone)]
pub struct ParamPatch {
    pub(crate) index: usize,
    pub(crate) shape: Arc<Shape>,
    pub(crate) vars: Arc<PatchVars>,
    pub(crate) u0: f32,
    pub(crate) u1: f32,
    pub(crate) v0: f32,
    pub(crate) v1: f32,
}

impl ParamPatch {
    pub(crate) fn new(index: usize, shape: Shape, vars: PatchVars) -> ParamPatch {
        ParamPatch {
            index,
            shape: Arc::new(shape),
            vars: Arc::new(vars),
            u0: 0.0,
            u1: 1.0,
            v0: 0.0,
            v1: 1.0,
        }
    }

    /// Camera-space length of the u-line and v-line through the middle (two chords each).
    fn mid_lengths(&self) -> (f32, f32) {
        let (um, vm) = (0.5 * (self.u0 + self.u1), 0.5 * (self.v0 + self.v1));
        let s = &self.shape;
        let c = s.position(um, vm);
        let lu = (s.position(self.u0, vm) - c).length() + (s.position(self.u1, vm) - c).length();
        let lv = (s.position(um, self.v0) - c).length() + (s.position(um, self.v1) - c).length();
        (lu, lv)
    }
}

impl Surface for ParamPatch {
    fn bound(&self) -> Bound {
        match &*self.shape {
            Shape::Quadric(q) => q.bound(self.u0, self.u1, self.v0, self.v1),
            Shape::Bilinear { .. } => {
                // A bilinear patch lies in the convex hull of its corners.
                let s = &self.shape;
                super::pad(Bound::from_points([
                    s.position(self.u0, self.v0),
                    s.position(self.u1, self.v0),
                    s.position(self.u0, self.v1),
                    s.position(self.u1, self.v1),
                ]))
            }
        }
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        self.split_as(self.split_choice())
    }

    fn split_choice(&self) -> u8 {
        let (lu, lv) = self.mid_lengths();
        (lu < lv) as u8
    }

    fn split_as(&self, choice: u8) -> Vec<Box<dyn Surface>> {
        let (mut a, mut b) = (self.clone(), self.clone());
        if choice == 0 {
            let m = 0.5 * (self.u0 + self.u1);
            a.u1 = m;
            b.u0 = m;
        } else {
            let m = 0.5 * (self.v0 + self.v1);
            a.v1 = m;
            b.v0 = m;
        }
        vec![Box::new(a), Box::new(b)]
    }

    fn dice(&self, nu: usize, nv: usize) -> Grid {
        let (nu, nv) = (nu.max(2), nv.max(2));
        let mut g = Grid::with_size(nu, nv);
        let du = (self.u1 - self.u0) / (nu - 1) as f32;
        let dv = (self.v1 - self.v0) / (nv - 1) as f32;
        g.du = du;
        g.dv = dv;
        for j in 0..nv {
            let v = self.v0 + j as f32 * dv;
            for i in 0..nu {
                g.u[j * nu + i] = self.u0 + i as f32 * du;
                g.v[j * nu + i] = v;
            }
        }
        match &*self.shape {
            Shape::Quadric(q) => q.dice_into(&mut g, self.u0, du, self.v0, dv),
            Shape::Bilinear { p, ng } => {
                let (e0, e1) = (p[1] - p[0], p[3] - p[2]);
                let (f0, f1) = (p[2] - p[0], p[3] - p[1]);
                for j in 0..nv {
                    let v = self.v0 + j as f32 * dv;
                    let dpdu = (1.0 - v) * e0 + v * e1;
                    for i in 0..nu {
                        let u = self.u0 + i as f32 * du;
                        let k = j * nu + i;
                        g.p[k] = (1.0 - v) * ((1.0 - u) * p[0] + u * p[1])
                            + v * ((1.0 - u) * p[2] + u * p[3]);
                        g.dpdu[k] = dpdu;
                        g.dpdv[k] = (1.0 - u) * f0 + u * f1;
                        g.ng[k] = *ng;
                        g.n[k] = *ng;
                    }
                }
            }
        }
        fill_grid(&mut g, &self.vars, self.u0, du, self.v0, dv);
        g.i.copy_from_slice(&g.p);
        g
    }

    fn primitive(&self) -> usize {
        self.index
    }

    fn raster_lengths(&self, raster_from_camera: &Mat4) -> Option<(f32, f32)> {
        const N: usize = 5;
        let mut q = [Vec2::ZERO; N * N];
        for j in 0..N {
            let v = self.v0 + (self.v1 - self.v0) * j as f32 / (N - 1) as f32;
            for i in 0..N {
                let u = self.u0 + (self.u1 - self.u0) * i as f32 / (N - 1) as f32;
                let h = *raster_from_camera * self.shape.position(u, v).extend(1.0);
                if h.w.is_nan() || h.w <= 1e-6 {
                    return None;
                }
                q[j * N + i] = h.truncate().truncate() / h.w;
            }
        }
        let (mut lu, mut lv) = (0.0f32, 0.0f32);
        for j in 0..N {
            let (mut a, mut b) = (0.0, 0.0);
            for i in 1..N {
                a += (q[j * N + i] - q[j * N + i - 1]).length();
                b += (q[i * N + j] - q[(i - 1) * N + j]).length();
            }
            lu = lu.max(a);
            lv = lv.max(b);
        }
        Some((lu, lv))
    }
}
