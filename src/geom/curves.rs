//! Curves (RISpec 3.2 §5.8): linear or cubic curves diced as flat ribbons.
//!
//! Input: `Geometry::Curves` (vertices per curve, wrap, the v basis and step), "P", "width"
//! (varying or vertex) or "constantwidth" (default 1 object unit), optional "N" (ribbon
//! normal), the other primitive variables, `camera_from_object`.
//! Output: one [`CurveSeg`] surface per curve segment (a cubic segment is 4 control vertices
//! evaluated with the basis matrix, `T·M·P` with T = [t³ t² t 1]; a linear one a straight
//! piece), which splits along its length and dices as a ribbon: grid u across the width
//! (0…1), grid v along the curve (the curve's global v, 0…1 over all its segments).
//! Invariants: the ribbon faces the eye (its side vector is tangent × view vector) unless "N"
//! is given, in which case it is perpendicular to N; Ng faces the eye (or along N). Vertex
//! variables are evaluated with the basis (like P), varying ones linearly between the segment
//! ends, uniform ones per curve. s, t default to u, v. Width is scaled to camera space by the
//! transform's mean scale.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use super::points::{mean_scale, positions};
use super::primvar::{resolve, ClassCounts, SourceVar};
use super::{Bound, Surface};
use crate::diag::{Diag, Diagnostics};
use crate::scene::{Basis, Class, ParamType, Primitive};
use crate::shade::{Grid, GridVar};

/// The fields of `Geometry::Curves`.
pub(crate) struct CurveArgs<'a> {
    pub cubic: bool,
    pub nverts: &'a [u32],
    pub periodic: bool,
    pub basis: Basis,
}

/// One curve segment's indices.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Seg {
    curve: usize,
    /// Control vertices (linear uses the first two).
    ctrl: [usize; 4],
    /// Varying elements at the segment's ends.
    var: [usize; 2],
    /// Global v of the segment's start, and its v length.
    v0: f32,
    vlen: f32,
}

#[derive(Debug)]
pub(crate) struct CurveData {
    index: usize,
    cubic: bool,
    /// Basis matrix, row-major (RIB layout).
    m: [f32; 16],
    /// Camera-space control points.
    p: Vec<Vec3>,
    /// Camera-space image of the object-space origin. Bases whose weights do not sum to 1
    /// (power, Hermite: some control values are tangents) are not affine-invariant, so a
    /// combination of transformed points misses the translation by `(1 − Σw)·origin`.
    origin: Vec3,
    segs: Vec<Seg>,
    vars: Vec<SourceVar>,
    /// Per-element widths (camera space) and their class, or the constant width.
    width: Option<(Class, Vec<f32>)>,
    const_width: f32,
    color: Vec3,
    opacity: Vec3,
}

/// A piece [t0, t1] of one segment.
#[derive(Debug, Clone)]
pub struct CurveSeg {
    pub(crate) data: Arc<CurveData>,
    pub(crate) seg: usize,
    pub(crate) t0: f32,
    pub(crate) t1: f32,
}

pub(crate) fn curves(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    _flip: bool,
    a: CurveArgs<'_>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let Some(obj) = positions(prim) else {
        diags.report(
            Diag::error(
                "geom::invalid",
                "Curves needs \"P\"; the primitive is skipped",
            )
            .label(prim.span, "these curves"),
        );
        return Vec::new();
    };
    let step = a.basis.step.max(1) as usize;
    let mut segs = Vec::new();
    let (mut vbase, mut varbase) = (0usize, 0usize);
    for (c, &n) in a.nverts.iter().enumerate() {
        let n = n as usize;
        let count = match (a.cubic, a.periodic) {
            (false, false) => n.saturating_sub(1),
            (false, true) => n,
            (true, false) if n >= 4 && (n - 4) % step == 0 => (n - 4) / step + 1,
            (true, true) if n > 0 && n % step == 0 => n / step,
            _ => 0,
        };
        if vbase + n > obj.len() || count == 0 {
            diags.report(
                Diag::error(
                    "geom::invalid",
                    format!("curve {c} does not fit its vertices; the primitive is skipped"),
                )
                .label(prim.span, "these curves"),
            );
            return Vec::new();
        }
        for i in 0..count {
            let ctrl = if a.cubic {
                [0, 1, 2, 3].map(|k| vbase + (i * step + k) % n)
            } else {
                let j = (i + 1) % n;
                [vbase + i, vbase + j, vbase + j, vbase + j]
            };
            let vars_here = if a.periodic { count } else { count + 1 };
            segs.push(Seg {
                curve: c,
                ctrl,
                var: [varbase + i, varbase + (i + 1) % vars_here],
                v0: i as f32 / count as f32,
                vlen: 1.0 / count as f32,
            });
        }
        vbase += n;
        varbase += if a.periodic { count } else { count + 1 };
    }
    let counts = ClassCounts {
        uniform: a.nverts.len(),
        varying: varbase,
        facevarying: varbase,
    };
    let vars = resolve(&prim.primvars, m, counts, diags);
    let sc = mean_scale(m);
    let width = vars
        .iter()
        .find(|v| v.name == "width" && v.ty == ParamType::Float)
        .map(|v| (v.class, v.floats.iter().map(|w| w.abs() * sc).collect()));
    let const_width = vars
        .iter()
        .find(|v| v.name == "constantwidth" && v.ty == ParamType::Float)
        .and_then(|v| v.floats.first().copied())
        .unwrap_or(1.0)
        .abs()
        * sc;
    let data = Arc::new(CurveData {
        index,
        cubic: a.cubic,
        m: a.basis.matrix,
        p: obj.iter().map(|&q| m.transform_point3(q)).collect(),
        origin: m.transform_point3(Vec3::ZERO),
        segs,
        vars: vars
            .into_iter()
            .filter(|v| v.name != "width" && v.name != "constantwidth")
            .collect(),
        width,
        const_width,
        color: prim.attributes.color,
        opacity: prim.attributes.opacity,
    });
    (0..data.segs.len())
        .map(|seg| {
            Box::new(CurveSeg {
                data: data.clone(),
                seg,
                t0: 0.0,
                t1: 1.0,
            }) as Box<dyn Surface>
        })
        .collect()
}

impl CurveData {
    /// Basis weights of the 4 control vertices at t, and their derivatives.
    fn weights(&self, t: f32) -> ([f32; 4], [f32; 4]) {
        if !self.cubic {
            return ([1.0 - t, t, 0.0, 0.0], [-1.0, 1.0, 0.0, 0.0]);
        }
        let tt = [t * t * t, t * t, t, 1.0];
        let dt = [3.0 * t * t, 2.0 * t, 1.0, 0.0];
        let mut w = [0.0; 4];
        let mut d = [0.0; 4];
        for k in 0..4 {
            for r in 0..4 {
                w[k] += tt[r] * self.m[r * 4 + k];
                d[k] += dt[r] * self.m[r * 4 + k];
            }
        }
        (w, d)
    }

    /// A variable's value at parameter t of a segment (weights `w` for vertex class).
    fn eval(&self, v: &SourceVar, s: &Seg, t: f32, w: &[f32; 4], out: &mut [f32]) {
        let n = v.width();
        let at = |e: usize| &v.floats[e * n..(e + 1) * n];
        match v.class {
            Class::Constant => out.copy_from_slice(at(0)),
            Class::Uniform => out.copy_from_slice(at(s.curve)),
            Class::Vertex => {
                out.iter_mut().for_each(|x| *x = 0.0);
                for k in 0..4 {
                    for (o, &x) in out.iter_mut().zip(at(s.ctrl[k])) {
                        *o += w[k] * x;
                    }
                }
            }
            _ => {
                for ((o, &a), &b) in out.iter_mut().zip(at(s.var[0])).zip(at(s.var[1])) {
                    *o = (1.0 - t) * a + t * b;
                }
            }
        }
    }

    fn width_at(&self, s: &Seg, t: f32, w: &[f32; 4]) -> f32 {
        match &self.width {
            None => self.const_width,
            Some((Class::Constant, f)) => f[0],
            Some((Class::Uniform, f)) => f[s.curve],
            Some((Class::Vertex, f)) => (0..4).map(|k| w[k] * f[s.ctrl[k]]).sum::<f32>().abs(),
            Some((_, f)) => (1.0 - t) * f[s.var[0]] + t * f[s.var[1]],
        }
    }

    /// The camera-space point the basis weights `w` give:
    /// the combination of the object-space control points, transformed.
    fn center(&self, s: &Seg, w: &[f32; 4]) -> Vec3 {
        let sum: Vec3 = (0..4).map(|k| w[k] * self.p[s.ctrl[k]]).sum();
        sum + (1.0 - w.iter().sum::<f32>()) * self.origin
    }

    /// The camera-space tangent for derivative weights `dw` (translation-free).
    fn tangent(&self, s: &Seg, dw: &[f32; 4]) -> Vec3 {
        let sum: Vec3 = (0..4).map(|k| dw[k] * self.p[s.ctrl[k]]).sum();
        sum - dw.iter().sum::<f32>() * self.origin
    }
}

impl CurveSeg {
    fn seg(&self) -> &Seg {
        &self.data.segs[self.seg]
    }
}

impl Surface for CurveSeg {
    fn bound(&self) -> Bound {
        // Samples of the centre line grown by the widest half-width and a margin for the
        // curve's bulge between samples.
        let d = &*self.data;
        let s = self.seg();
        const N: usize = 9;
        let mut b = Bound::EMPTY;
        let mut wmax = 0.0f32;
        for i in 0..N {
            let t = self.t0 + (self.t1 - self.t0) * i as f32 / (N - 1) as f32;
            let (w, _) = d.weights(t);
            let c = d.center(s, &w);
            b.min = b.min.min(c);
            b.max = b.max.max(c);
            wmax = wmax.max(d.width_at(s, t, &w));
        }
        let ext = (b.max - b.min).max_element();
        super::pad(b.grow(0.5 * wmax + 0.1 * ext))
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        let m = 0.5 * (self.t0 + self.t1);
        let (mut a, mut b) = (self.clone(), self.clone());
        a.t1 = m;
        b.t0 = m;
        vec![Box::new(a), Box::new(b)]
    }

    fn dice(&self, nu: usize, nv: usize) -> Grid {
        let d = &*self.data;
        let s = *self.seg();
        let (nu, nv) = (nu.max(2), nv.max(2));
        let mut g = Grid::with_size(nu, nv);
        let dt = (self.t1 - self.t0) / (nv - 1) as f32;
        g.du = 1.0 / (nu - 1) as f32;
        g.dv = dt * s.vlen;
        let user_n = d
            .vars
            .iter()
            .find(|v| v.name == "N" && v.width() >= 3 && v.ty != ParamType::String);
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
        let mut buf = [0.0f32; 3];
        let mut user: Vec<GridVar> = d
            .vars
            .iter()
            .filter(|v| !matches!(v.name.as_str(), "N" | "Cs" | "Os" | "s" | "t" | "st"))
            .map(|v| {
                let uniform = matches!(v.class, Class::Constant | Class::Uniform)
                    || v.ty == ParamType::String;
                let w = v.width();
                let e = if v.class == Class::Uniform {
                    s.curve
                } else {
                    0
                };
                GridVar {
                    name: v.name.clone(),
                    ty: v.ty,
                    array_len: v.array_len,
                    uniform,
                    floats: if uniform {
                        v.floats
                            .get(e * w..(e + 1) * w)
                            .map(<[f32]>::to_vec)
                            .unwrap_or_default()
                    } else {
                        Vec::with_capacity(nu * nv * w)
                    },
                    strings: v
                        .strings
                        .get(e * w..(e + 1) * w)
                        .map(<[String]>::to_vec)
                        .unwrap_or_default(),
                }
            })
            .collect();
        let user_src: Vec<&SourceVar> = d
            .vars
            .iter()
            .filter(|v| !matches!(v.name.as_str(), "N" | "Cs" | "Os" | "s" | "t" | "st"))
            .collect();
        let mut tmp = Vec::new();
        for j in 0..nv {
            let t = self.t0 + j as f32 * dt;
            let (w, dw) = d.weights(t);
            let c = d.center(&s, &w);
            let tan = d.tangent(&s, &dw);
            let width = d.width_at(&s, t, &w);
            // Ribbon orientation.
            let (side, ng) = match user_n {
                Some(nv) => {
                    d.eval(nv, &s, t, &w, &mut buf);
                    let n = Vec3::from_array(buf);
                    let side = tan.cross(n).normalize_or_zero();
                    (side, side.cross(tan).normalize_or_zero())
                }
                None => {
                    let view = if c.length_squared() > 0.0 { c } else { Vec3::Z };
                    let mut side = tan.cross(view).normalize_or_zero();
                    if side == Vec3::ZERO {
                        side = tan.any_orthonormal_vector();
                    }
                    let mut ng = side.cross(tan).normalize_or_zero();
                    if ng.dot(view) > 0.0 {
                        ng = -ng;
                    }
                    (side, ng)
                }
            };
            let (mut sv, mut tv) = (0.0, self.t0 + j as f32 * dt);
            tv = s.v0 + tv * s.vlen;
            let vglob = tv;
            let mut sv_given = false;
            if let Some(v) = st.filter(|v| v.width() >= 2) {
                let mut b2 = [0.0f32; 2];
                let mut full = vec![0.0f32; v.width()];
                d.eval(v, &s, t, &w, &mut full);
                b2.copy_from_slice(&full[..2]);
                sv = b2[0];
                tv = b2[1];
                sv_given = true;
            }
            if let Some(v) = s_v {
                d.eval(v, &s, t, &w, &mut buf[..1]);
                sv = buf[0];
                sv_given = true;
            }
            if let Some(v) = t_v {
                d.eval(v, &s, t, &w, &mut buf[..1]);
                tv = buf[0];
            }
            let get3 = |v: Option<&SourceVar>, def: Vec3| match v {
                Some(v) => {
                    let mut full = vec![0.0f32; v.width()];
                    d.eval(v, &s, t, &w, &mut full);
                    Vec3::from_slice(&full[..3])
                }
                None => def,
            };
            let cs = get3(cs_v, d.color);
            let os = get3(os_v, d.opacity);
            for (gv, sv_) in user.iter_mut().zip(&user_src) {
                if gv.uniform {
                    continue;
                }
                tmp.resize(sv_.width(), 0.0);
                d.eval(sv_, &s, t, &w, &mut tmp);
                for _ in 0..nu {
                    gv.floats.extend_from_slice(&tmp);
                }
            }
            for i in 0..nu {
                let u = i as f32 * g.du;
                let k = j * nu + i;
                g.p[k] = c + (u - 0.5) * width * side;
                g.dpdu[k] = width * side;
                g.dpdv[k] = tan / s.vlen;
                g.ng[k] = ng;
                g.n[k] = ng;
                g.u[k] = u;
                g.v[k] = vglob;
                g.s[k] = if sv_given { sv } else { u };
                g.t[k] = tv;
                g.cs[k] = cs;
                g.os[k] = os;
            }
        }
        g.primvars = user;
        g.i.copy_from_slice(&g.p);
        g
    }

    fn primitive(&self) -> usize {
        self.data.index
    }
}
