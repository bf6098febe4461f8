//! Rational tensor-product Bézier pieces: the one surface every bilinear, bicubic (any basis)
//! and NURBS patch becomes.
//!
//! Input: homogeneous camera-space control rows (`wx wy wz w`, then every vertex-class
//! variable's values times w) of degree (p, q), u fastest; the piece's corner variables
//! ([`PatchVars`], varying/uniform/facevarying classes, bilinear over the piece); the map from
//! the piece's [0,1]² to the primitive's reported (u, v); an optional trim region.
//! Output: bounds (the projected control hull), splits (exact de Casteljau halves in 4-D) and
//! grids with P, N, Ng, dPdu, dPdv, u, v, du, dv, s, t, Cs, Os, I and primitive variables.
//! Invariants: children's control rows describe exactly their half of the parent, so their
//! hulls lie inside the parent's hull (weights are positive, checked by the builder).
//! dPdu/dPdv are derivatives with respect to the reported u, v (quotient rule for rational
//! pieces); Ng = dPdu × dPdv with the `geom` orientation rule. Where that product vanishes (a
//! collapsed edge such as the teapot's lid and bottom poles, notes/patches.md §3.4) the normal
//! of a point slightly inside the piece is used, the limit of the normals around the pole.
//! Trimmed-away points get Os = 0 (and split pieces wholly trimmed have an empty bound).

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use super::primvar::{fill_grid, PatchVars};
use super::spline::{bernstein, split_curve};
use super::trim::Trim;
use super::{Bound, Surface};
use crate::scene::ParamType;
use crate::shade::{Grid, GridVar};

/// Where an interpolated vertex-class variable goes on the grid.
#[derive(Clone, Debug)]
pub(crate) enum Target {
    S,
    T,
    /// s and t from "st".
    St,
    Cs,
    Os,
    N,
    User {
        name: String,
        ty: ParamType,
        array_len: usize,
    },
}

/// A vertex-class variable carried in the control rows at `offset` (after x y z w).
#[derive(Clone, Debug)]
pub(crate) struct Extra {
    pub target: Target,
    pub offset: usize,
    pub width: usize,
}

/// What all pieces of one patch share.
#[derive(Debug)]
pub(crate) struct Shared {
    pub index: usize,
    pub flip: bool,
    pub vars: PatchVars,
    pub extras: Vec<Extra>,
    /// Reported parameters of the piece's corners: u = u0 + (u1 − u0)·a, v likewise.
    pub uv: [f32; 4],
    pub trim: Option<Arc<Trim>>,
}

/// A (piece of a) rational Bézier patch in camera space.
#[derive(Debug, Clone)]
pub struct BezierPatch {
    pub(crate) shared: Arc<Shared>,
    /// Degrees in u and v.
    pub(crate) p: usize,
    pub(crate) q: usize,
    /// Numbers per control row.
    pub(crate) dim: usize,
    /// (p+1)(q+1) rows, u fastest.
    pub(crate) ctrl: Arc<Vec<f32>>,
    /// This piece's rectangle in the patch's [0,1]²: a0, a1, b0, b1.
    pub(crate) rect: [f32; 4],
}

/// Position and derivatives (per unit of the piece's own parameters) from homogeneous sums.
#[inline]
fn project(s: &[f32], su: &[f32], sv: &[f32]) -> (Vec3, Vec3, Vec3) {
    let w = s[3];
    let p = Vec3::new(s[0], s[1], s[2]) / w;
    let du = (Vec3::new(su[0], su[1], su[2]) - p * su[3]) / w;
    let dv = (Vec3::new(sv[0], sv[1], sv[2]) - p * sv[3]) / w;
    (p, du, dv)
}

impl BezierPatch {
    pub(crate) fn new(
        shared: Arc<Shared>,
        p: usize,
        q: usize,
        dim: usize,
        ctrl: Vec<f32>,
    ) -> BezierPatch {
        BezierPatch {
            shared,
            p,
            q,
            dim,
            ctrl: Arc::new(ctrl),
            rect: [0.0, 1.0, 0.0, 1.0],
        }
    }

    /// The piece restricted to [a0,a1] × [b0,b1] of its own parameters.
    pub(crate) fn restrict(&self, a0: f32, a1: f32, b0: f32, b1: f32) -> BezierPatch {
        let mut out = self.clone();
        if a0 > 0.0 || a1 < 1.0 {
            out = out.cut(true, a0, a1);
        }
        if b0 > 0.0 || b1 < 1.0 {
            out = out.cut(false, b0, b1);
        }
        out
    }

    /// Keeps [t0, t1] of the own parameter in u (`in_u`) or v.
    fn cut(&self, in_u: bool, t0: f32, t1: f32) -> BezierPatch {
        let (lo, _) = self.halves(in_u, t1);
        let tmp = with_ctrl(self, lo);
        let t = if t1 > 0.0 { t0 / t1 } else { 0.0 };
        let (_, mid) = tmp.halves(in_u, t);
        let mut out = with_ctrl(self, mid);
        let k = if in_u { 0 } else { 2 };
        let (lo, len) = (self.rect[k], self.rect[k + 1] - self.rect[k]);
        out.rect[k] = lo + len * t0;
        out.rect[k + 1] = lo + len * t1;
        out
    }

    /// de Casteljau split at `t` along u or v: (control rows of [0,t], of [t,1]).
    fn halves(&self, in_u: bool, t: f32) -> (Vec<f32>, Vec<f32>) {
        let (p1, q1, dim) = (self.p + 1, self.q + 1, self.dim);
        let n = self.ctrl.len();
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        if in_u {
            for j in 0..q1 {
                let o = j * p1 * dim;
                let r = o..o + p1 * dim;
                let (la, lb) = (&mut a[r.clone()], &mut b[r.clone()]);
                split_curve(&self.ctrl[r], p1, dim, t, la, lb);
            }
        } else {
            let mut col = vec![0.0; q1 * dim];
            let (mut la, mut lb) = (vec![0.0; q1 * dim], vec![0.0; q1 * dim]);
            for i in 0..p1 {
                for j in 0..q1 {
                    let o = (j * p1 + i) * dim;
                    col[j * dim..(j + 1) * dim].copy_from_slice(&self.ctrl[o..o + dim]);
                }
                split_curve(&col, q1, dim, t, &mut la, &mut lb);
                for j in 0..q1 {
                    let o = (j * p1 + i) * dim;
                    a[o..o + dim].copy_from_slice(&la[j * dim..(j + 1) * dim]);
                    b[o..o + dim].copy_from_slice(&lb[j * dim..(j + 1) * dim]);
                }
            }
        }
        (a, b)
    }

    fn point(&self, k: usize) -> Vec3 {
        let c = &self.ctrl[k * self.dim..];
        Vec3::new(c[0], c[1], c[2]) / c[3]
    }

    /// P, dP/da, dP/db (per unit of the piece's own parameters) at own parameters (a, b).
    pub(crate) fn eval(&self, a: f32, b: f32) -> (Vec3, Vec3, Vec3) {
        let (p1, q1, dim) = (self.p + 1, self.q + 1, self.dim.min(4));
        let (mut bu, mut dbu) = (vec![0.0f32; p1], vec![0.0f32; p1]);
        let (mut bv, mut dbv) = (vec![0.0f32; q1], vec![0.0f32; q1]);
        bernstein(self.p, a, &mut bu, &mut dbu);
        bernstein(self.q, b, &mut bv, &mut dbv);
        let (mut s, mut su, mut sv) = ([0.0f32; 4], [0.0f32; 4], [0.0f32; 4]);
        for j in 0..q1 {
            for i in 0..p1 {
                let c = &self.ctrl[(j * p1 + i) * self.dim..];
                let (w, wu, wv) = (bu[i] * bv[j], dbu[i] * bv[j], bu[i] * dbv[j]);
                for k in 0..dim {
                    s[k] += w * c[k];
                    su[k] += wu * c[k];
                    sv[k] += wv * c[k];
                }
            }
        }
        project(&s, &su, &sv)
    }

    /// Reported-parameter scale: d(own a)/d(reported u), d(own b)/d(reported v).
    fn scale(&self) -> (f32, f32) {
        let uv = &self.shared.uv;
        let su = (self.rect[1] - self.rect[0]) * (uv[1] - uv[0]);
        let sv = (self.rect[3] - self.rect[2]) * (uv[3] - uv[2]);
        (
            if su != 0.0 { 1.0 / su } else { 0.0 },
            if sv != 0.0 { 1.0 / sv } else { 0.0 },
        )
    }

    /// Reported (u, v) of own parameters (a, b).
    fn reported(&self, a: f32, b: f32) -> Vec2 {
        let uv = &self.shared.uv;
        let x = self.rect[0] + (self.rect[1] - self.rect[0]) * a;
        let y = self.rect[2] + (self.rect[3] - self.rect[2]) * b;
        Vec2::new(uv[0] + (uv[1] - uv[0]) * x, uv[2] + (uv[3] - uv[2]) * y)
    }

    /// The oriented normal direction (unnormalised) where dPdu × dPdv may vanish.
    fn normal(&self, a: f32, b: f32, da: Vec3, db: Vec3) -> Vec3 {
        let n = da.cross(db);
        let scale = da.length_squared().max(db.length_squared());
        let n = if n.length_squared() > 1e-10 * scale * scale && scale > 0.0 {
            n
        } else {
            // Step toward the middle of the piece: the limit of the neighbours' normals.
            let e = 1e-3;
            let a2 = if a > 0.5 { a - e } else { a + e };
            let b2 = if b > 0.5 { b - e } else { b + e };
            let (_, x, y) = self.eval(a2, b2);
            let m = x.cross(y);
            if m.length_squared() > 0.0 {
                m
            } else {
                n
            }
        };
        if self.shared.flip {
            -n
        } else {
            n
        }
    }
}

/// A copy of `s` with new control rows (same rectangle).
fn with_ctrl(s: &BezierPatch, ctrl: Vec<f32>) -> BezierPatch {
    BezierPatch {
        ctrl: Arc::new(ctrl),
        ..s.clone()
    }
}

impl Surface for BezierPatch {
    fn bound(&self) -> Bound {
        if let Some(t) = &self.shared.trim {
            let (lo, hi) = (self.reported(0.0, 0.0), self.reported(1.0, 1.0));
            if t.cuts_all(lo.min(hi), lo.max(hi)) {
                return Bound::EMPTY;
            }
        }
        let n = (self.p + 1) * (self.q + 1);
        super::pad(Bound::from_points((0..n).map(|k| self.point(k))))
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        self.split_as(self.split_choice())
    }

    fn split_as(&self, choice: u8) -> Vec<Box<dyn Surface>> {
        let in_u = choice == 0;
        let (a, b) = self.halves(in_u, 0.5);
        let (mut x, mut y) = (with_ctrl(self, a), with_ctrl(self, b));
        let k = if in_u { 0 } else { 2 };
        let m = 0.5 * (self.rect[k] + self.rect[k + 1]);
        x.rect[k + 1] = m;
        y.rect[k] = m;
        vec![Box::new(x), Box::new(y)]
    }

    fn split_choice(&self) -> u8 {
        // Split across the direction whose control polygon is longer in camera space.
        let (p1, q1) = (self.p + 1, self.q + 1);
        let (mut lu, mut lv) = (0.0f32, 0.0f32);
        for j in 0..q1 {
            let mut l = 0.0;
            for i in 1..p1 {
                l += (self.point(j * p1 + i) - self.point(j * p1 + i - 1)).length();
            }
            lu = lu.max(l);
        }
        for i in 0..p1 {
            let mut l = 0.0;
            for j in 1..q1 {
                l += (self.point(j * p1 + i) - self.point((j - 1) * p1 + i)).length();
            }
            lv = lv.max(l);
        }
        (lu < lv) as u8
    }

    fn dice(&self, nu: usize, nv: usize) -> Grid {
        let (nu, nv) = (nu.max(2), nv.max(2));
        let (p1, q1, dim) = (self.p + 1, self.q + 1, self.dim);
        let mut g = Grid::with_size(nu, nv);
        let sh = &self.shared;
        // Bernstein values per column (u) and per row (v).
        let basis = |deg: usize, n: usize| {
            let mut b = vec![0.0f32; n * (deg + 1)];
            let mut d = vec![0.0f32; n * (deg + 1)];
            for i in 0..n {
                let t = i as f32 / (n - 1) as f32;
                let r = i * (deg + 1)..(i + 1) * (deg + 1);
                let (bb, dd) = (&mut b[r.clone()], &mut d[r]);
                bernstein(deg, t, bb, dd);
            }
            (b, d)
        };
        let (bu, dbu) = basis(self.p, nu);
        let (bv, dbv) = basis(self.q, nv);
        // Contract over u first: per column i and control row j, the curve value and slope.
        let mut r = vec![0.0f32; nu * q1 * dim];
        let mut dr = vec![0.0f32; nu * q1 * dim];
        for i in 0..nu {
            for j in 0..q1 {
                let o = (i * q1 + j) * dim;
                for ii in 0..p1 {
                    let (w, dw) = (bu[i * p1 + ii], dbu[i * p1 + ii]);
                    let c = &self.ctrl[(j * p1 + ii) * dim..(j * p1 + ii + 1) * dim];
                    for k in 0..dim {
                        r[o + k] += w * c[k];
                        dr[o + k] += dw * c[k];
                    }
                }
            }
        }
        let (ku, kv) = self.scale();
        let uv = sh.uv;
        g.du = (uv[1] - uv[0]) * (self.rect[1] - self.rect[0]) / (nu - 1) as f32;
        g.dv = (uv[3] - uv[2]) * (self.rect[3] - self.rect[2]) / (nv - 1) as f32;
        let mut s = vec![0.0f32; dim];
        let mut extras = vec![0.0f32; nu * nv * (dim - 4)];
        for j in 0..nv {
            let b = j as f32 / (nv - 1) as f32;
            for i in 0..nu {
                let a = i as f32 / (nu - 1) as f32;
                s.iter_mut().for_each(|x| *x = 0.0);
                let (mut su, mut sv) = ([0.0f32; 4], [0.0f32; 4]);
                for jj in 0..q1 {
                    let (w, dw) = (bv[j * q1 + jj], dbv[j * q1 + jj]);
                    let o = (i * q1 + jj) * dim;
                    for k in 0..dim {
                        s[k] += w * r[o + k];
                    }
                    for k in 0..4 {
                        su[k] += w * dr[o + k];
                        sv[k] += dw * r[o + k];
                    }
                }
                let (pos, da, db) = project(&s, &su, &sv);
                let k = j * nu + i;
                let (dpdu, dpdv) = (da * ku, db * kv);
                g.p[k] = pos;
                g.dpdu[k] = dpdu;
                g.dpdv[k] = dpdv;
                let n = self.normal(a, b, da, db).normalize_or_zero();
                g.ng[k] = n;
                g.n[k] = n;
                let uvk = self.reported(a, b);
                g.u[k] = uvk.x;
                g.v[k] = uvk.y;
                if dim > 4 {
                    let inv = 1.0 / s[3];
                    let o = k * (dim - 4);
                    for c in 4..dim {
                        extras[o + c - 4] = s[c] * inv;
                    }
                }
            }
        }
        let (a0, b0) = (self.rect[0], self.rect[2]);
        let da = (self.rect[1] - a0) / (nu - 1) as f32;
        let db = (self.rect[3] - b0) / (nv - 1) as f32;
        fill_grid(&mut g, &sh.vars, a0, da, b0, db);
        if dim > 4 {
            write_extras(&mut g, &sh.extras, &extras, dim - 4);
        }
        if let Some(cut) = self.trimmed(&g) {
            for (os, _) in g.os.iter_mut().zip(&cut).filter(|(_, c)| **c) {
                *os = Vec3::ZERO;
            }
        }
        g.i.copy_from_slice(&g.p);
        g
    }

    fn trimmed(&self, grid: &Grid) -> Option<Vec<bool>> {
        let t = self.shared.trim.as_ref()?;
        let cut: Vec<bool> = (0..grid.len())
            .map(|k| !t.keeps(Vec2::new(grid.u[k], grid.v[k])))
            .collect();
        cut.contains(&true).then_some(cut)
    }

    fn primitive(&self) -> usize {
        self.shared.index
    }

    fn raster_lengths(&self, raster_from_camera: &Mat4) -> Option<(f32, f32)> {
        const N: usize = 5;
        let mut q = [Vec2::ZERO; N * N];
        for j in 0..N {
            for i in 0..N {
                let (a, b) = (i as f32 / (N - 1) as f32, j as f32 / (N - 1) as f32);
                let h = *raster_from_camera * self.eval(a, b).0.extend(1.0);
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

/// Copies interpolated vertex-class values (`w` numbers per point) onto the grid.
fn write_extras(g: &mut Grid, extras: &[Extra], vals: &[f32], w: usize) {
    let n = g.len();
    for e in extras {
        let o = e.offset - 4;
        let at = |k: usize, c: usize| vals[k * w + o + c];
        let v3 = |k: usize| Vec3::new(at(k, 0), at(k, 1), at(k, 2));
        match &e.target {
            Target::S => (0..n).for_each(|k| g.s[k] = at(k, 0)),
            Target::T => (0..n).for_each(|k| g.t[k] = at(k, 0)),
            Target::St => (0..n).for_each(|k| {
                g.s[k] = at(k, 0);
                g.t[k] = at(k, 1);
            }),
            Target::Cs => (0..n).for_each(|k| g.cs[k] = v3(k)),
            Target::Os => (0..n).for_each(|k| {
                // Keep trimming's zero (applied later) and the user's value otherwise.
                g.os[k] = v3(k)
            }),
            Target::N => (0..n).for_each(|k| {
                let v = v3(k).normalize_or_zero();
                if v != Vec3::ZERO {
                    g.n[k] = v;
                }
            }),
            Target::User {
                name,
                ty,
                array_len,
            } => {
                let mut floats = Vec::with_capacity(n * e.width);
                for k in 0..n {
                    for c in 0..e.width {
                        floats.push(at(k, c));
                    }
                }
                g.primvars.retain(|v| &v.name != name);
                g.primvars.push(GridVar {
                    name: name.clone(),
                    ty: *ty,
                    array_len: *array_len,
                    uniform: false,
                    floats,
                    strings: Vec::new(),
                });
            }
        }
    }
}
