//! Points (RISpec 3.2 §5.7): camera-facing disks of diameter "width" / "constantwidth"; a
//! point that carries "N" is a disk across that normal instead (as PRMan draws them).
//!
//! Input: `Geometry::Points`, "P", "width" (varying) or "constantwidth" (constant, default 1
//! object unit), the other primitive variables, `camera_from_object`.
//! Output: [`PointBatch`] surfaces. The points are ordered once by a k-d median split in camera
//! space so that halving a batch's range halves it spatially; a batch dices into one grid of
//! `nu` columns and `m` rows per point (rows stacked point after point). Each point's rows
//! parameterise a disk parallel to the image plane: row j at y = −R cos(πj/(m−1)) with half
//! width R sin(πj/(m−1)), so the first and last rows collapse to a single point and the
//! micropolygons joining two points have zero area (never sampled). The outline is a regular
//! 2(m−1)-gon whose radius is enlarged to keep the disk's area π r².
//! Invariants: N = Ng = −z (towards the camera), or the point's unit N; every grid point of a point carries that
//! point's values (points have no parametric variation: s, t, Cs, Os, user variables are
//! constant over the disk); width is scaled to camera space by the transform's mean scale.

use std::f32::consts::PI;
use std::ops::Range;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use super::primvar::{resolve, ClassCounts, SourceVar};
use super::{Bound, Surface};
use crate::diag::{Diag, Diagnostics};
use crate::scene::{Class, ParamType, Primitive};
use crate::shade::{Grid, GridVar};

/// Points per batch below which a batch may be diced.
const LEAF_POINTS: usize = 256;

#[derive(Debug)]
pub(crate) struct PointData {
    pub index: usize,
    /// Camera-space centres and radii, in k-d order.
    pub p: Vec<Vec3>,
    pub r: Vec<f32>,
    /// Original point index of each ordered point.
    pub order: Vec<u32>,
    pub vars: Vec<SourceVar>,
    pub color: Vec3,
    pub opacity: Vec3,
}

/// A range of (k-d ordered) points.
#[derive(Debug, Clone)]
pub struct PointBatch {
    pub(crate) data: Arc<PointData>,
    pub(crate) range: Range<usize>,
}

/// Mean linear scale of a transform (cube root of its 3×3 determinant).
pub(crate) fn mean_scale(m: Mat4) -> f32 {
    let d = glam::Mat3::from_mat4(m).determinant().abs();
    if d > 0.0 && d.is_finite() {
        d.cbrt()
    } else {
        1.0
    }
}

/// Object-space "P" (or "Pw" divided by w).
pub(crate) fn positions(prim: &Primitive) -> Option<Vec<Vec3>> {
    if let Some(p) = prim.primvars.floats("P").filter(|f| !f.is_empty()) {
        Some(p.chunks_exact(3).map(Vec3::from_slice).collect())
    } else {
        prim.primvars
            .floats("Pw")
            .filter(|f| !f.is_empty())
            .map(|p| {
                p.chunks_exact(4)
                    .map(|c| Vec3::new(c[0], c[1], c[2]) / if c[3] != 0.0 { c[3] } else { 1.0 })
                    .collect()
            })
    }
}

pub(crate) fn points(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    npoints: usize,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let Some(obj) = positions(prim) else {
        diags.report(
            Diag::error(
                "geom::invalid",
                "Points needs \"P\"; the primitive is skipped",
            )
            .label(prim.span, "these points"),
        );
        return Vec::new();
    };
    let n = npoints.min(obj.len());
    if n == 0 {
        return Vec::new();
    }
    let counts = ClassCounts {
        uniform: 1,
        varying: n,
        facevarying: n,
    };
    let vars = resolve(&prim.primvars, m, counts, diags);
    let sc = mean_scale(m);
    let width = vars
        .iter()
        .find(|v| v.name == "width" && v.ty == ParamType::Float);
    let cwidth = vars
        .iter()
        .find(|v| v.name == "constantwidth" && v.ty == ParamType::Float)
        .and_then(|v| v.floats.first().copied());
    let radius = |k: usize| -> f32 {
        let w = match width {
            Some(v) if v.class != Class::Constant && v.class != Class::Uniform => v.floats[k],
            Some(v) => v.floats[0],
            None => cwidth.unwrap_or(1.0),
        };
        0.5 * w.abs() * sc
    };
    let p: Vec<Vec3> = obj[..n].iter().map(|&q| m.transform_point3(q)).collect();
    let mut order: Vec<u32> = (0..n as u32).collect();
    kd_order(&p, &mut order);
    let data = PointData {
        index,
        r: order.iter().map(|&k| radius(k as usize)).collect(),
        p: order.iter().map(|&k| p[k as usize]).collect(),
        order,
        vars: vars
            .into_iter()
            .filter(|v| v.name != "width" && v.name != "constantwidth")
            .collect(),
        color: prim.attributes.color,
        opacity: prim.attributes.opacity,
    };
    vec![Box::new(PointBatch {
        data: Arc::new(data),
        range: 0..n,
    })]
}

/// Orders indices by recursive median splits along the wider of x and y.
fn kd_order(p: &[Vec3], idx: &mut [u32]) {
    if idx.len() <= 8 {
        return;
    }
    let b = Bound::from_points(idx.iter().map(|&k| p[k as usize]));
    let e = b.max - b.min;
    let axis = if e.x >= e.y { 0 } else { 1 };
    let mid = idx.len() / 2;
    idx.select_nth_unstable_by(mid, |&a, &c| {
        p[a as usize][axis].total_cmp(&p[c as usize][axis])
    });
    let (l, r) = idx.split_at_mut(mid);
    kd_order(p, l);
    kd_order(p, r);
}

/// The axes of a disk lying across the camera-space normal `n` (PRMan draws points that
/// carry "N" as disks facing along it, not the camera): `(e1, e2, n̂)` with `e1 × e2 = n̂`,
/// `e1` level with the image's x axis where it can be. None for a zero or non-finite `n`.
fn disk_axes(n: Vec3) -> Option<(Vec3, Vec3, Vec3)> {
    let n = n.try_normalize()?;
    let e1 = Vec3::Y.cross(n).try_normalize().unwrap_or(Vec3::X);
    let e2 = n.cross(e1);
    Some((e1, e2, n))
}

impl PointBatch {
    /// Area-preserving radius for an outline of `rows` rows (a regular 2(rows−1)-gon).
    fn outline_scale(rows: usize) -> f32 {
        let n = (2 * (rows - 1)) as f32;
        (PI / (0.5 * n * (2.0 * PI / n).sin())).sqrt()
    }
}

impl Surface for PointBatch {
    fn bound(&self) -> Bound {
        let d = &self.data;
        let mut b = Bound::EMPTY;
        for k in self.range.clone() {
            // Up to the enlarged radius of the coarsest outline (5 rows: an octagon, ×1.0856).
            let r = d.r[k] * 1.26;
            b.min = b.min.min(d.p[k] - Vec3::splat(r));
            b.max = b.max.max(d.p[k] + Vec3::splat(r));
        }
        super::pad(b)
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        let n = self.range.len();
        if n <= 1 {
            // One point cannot be split further; the driver's split limit drops it if asked
            // again and again.
            return vec![Box::new(self.clone())];
        }
        let mid = self.range.start + n / 2;
        vec![
            Box::new(PointBatch {
                data: self.data.clone(),
                range: self.range.start..mid,
            }),
            Box::new(PointBatch {
                data: self.data.clone(),
                range: mid..self.range.end,
            }),
        ]
    }

    fn diceable(&self) -> bool {
        self.range.len() <= LEAF_POINTS
    }

    fn splittable(&self) -> bool {
        self.range.len() > 1
    }

    fn dice(&self, nu: usize, nv: usize) -> Grid {
        let d = &*self.data;
        let np = self.range.len();
        let nu = nu.max(2);
        let m = (nv / np.max(1)).max(5);
        let mut g = Grid::with_size(nu, m * np);
        g.du = 1.0 / (nu - 1) as f32;
        g.dv = 1.0 / (m - 1) as f32;
        let scale = Self::outline_scale(m);
        // Per-point source element of each variable.
        let elem = |v: &SourceVar, k: usize| match v.class {
            Class::Constant | Class::Uniform => 0,
            _ => k,
        };
        let find = |name: &str| {
            d.vars
                .iter()
                .find(|v| v.name == name && v.ty != ParamType::String)
        };
        let (st, s_v, t_v) = (find("st"), find("s"), find("t"));
        let (cs_v, os_v) = (
            find("Cs").filter(|v| v.width() >= 3),
            find("Os").filter(|v| v.width() >= 3),
        );
        let n_v = find("N").filter(|v| v.width() >= 3);
        for (q, k) in self.range.clone().enumerate() {
            let orig = d.order[k] as usize;
            let c = d.p[k];
            let r = d.r[k] * scale;
            let mut s = 0.0;
            let mut t = 0.0;
            if let Some(v) = st.filter(|v| v.width() >= 2) {
                let e = elem(v, orig) * v.width();
                s = v.floats[e];
                t = v.floats[e + 1];
            }
            if let Some(v) = s_v {
                s = v.floats[elem(v, orig) * v.width()];
            }
            if let Some(v) = t_v {
                t = v.floats[elem(v, orig) * v.width()];
            }
            let at3 = |v: &SourceVar| {
                let e = elem(v, orig) * v.width();
                Vec3::from_slice(&v.floats[e..e + 3])
            };
            let cs = cs_v.map_or(d.color, at3);
            let os = os_v.map_or(d.opacity, at3);
            // The disk's plane: facing the camera, or across the point's N when it has one.
            let (e1, e2, normal) = match n_v.map(at3).and_then(disk_axes) {
                Some(axes) => axes,
                None => (Vec3::X, Vec3::Y, Vec3::NEG_Z),
            };
            for j in 0..m {
                let a = PI * j as f32 / (m - 1) as f32;
                let (y, h) = (-r * a.cos(), r * a.sin());
                for i in 0..nu {
                    let x = h * (2.0 * i as f32 / (nu - 1) as f32 - 1.0);
                    let idx = (q * m + j) * nu + i;
                    g.p[idx] = c + x * e1 + y * e2;
                    g.n[idx] = normal;
                    g.ng[idx] = normal;
                    g.dpdu[idx] = 2.0 * r * e1;
                    g.dpdv[idx] = 2.0 * r * e2;
                    g.u[idx] = i as f32 * g.du;
                    g.v[idx] = j as f32 * g.dv;
                    g.s[idx] = s;
                    g.t[idx] = t;
                    g.cs[idx] = cs;
                    g.os[idx] = os;
                }
            }
        }
        let per_point = m * nu;
        for v in &d.vars {
            if matches!(v.name.as_str(), "N" | "Cs" | "Os" | "s" | "t" | "st") {
                continue;
            }
            let w = v.width();
            let uniform =
                matches!(v.class, Class::Constant | Class::Uniform) || v.ty == ParamType::String;
            let floats = if uniform {
                v.floats.get(..w).map(<[f32]>::to_vec).unwrap_or_default()
            } else {
                let mut f = Vec::with_capacity(g.len() * w);
                for k in self.range.clone() {
                    let e = d.order[k] as usize * w;
                    for _ in 0..per_point {
                        f.extend_from_slice(&v.floats[e..e + w]);
                    }
                }
                f
            };
            g.primvars.push(GridVar {
                name: v.name.clone(),
                ty: v.ty,
                array_len: v.array_len,
                uniform,
                floats,
                strings: v
                    .strings
                    .get(..w.min(v.strings.len()))
                    .map(<[String]>::to_vec)
                    .unwrap_or_default(),
            });
        }
        g.i.copy_from_slice(&g.p);
        g
    }

    fn primitive(&self) -> usize {
        self.data.index
    }
}
