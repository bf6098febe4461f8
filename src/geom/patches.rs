//! Builds Bézier pieces from `Patch`/`PatchMesh` (bilinear, bicubic in any basis), `NuPatch`
//! (with trim curves) and `Geometry "teapot"`.
//!
//! Input: a primitive's geometry, its primitive variables ("P", "Pw" or "Pz" control points
//! and the rest) and `camera_from_object`.
//! Output: one [`BezierPatch`] per sub-patch (per nonempty knot span for NURBS).
//! Invariants (RISpec §5.2): control points and vertex variables are listed u fastest.
//! Bicubic sub-patch (a, b) of a mesh uses points `(a·ustep + i) mod nu`, `(b·vstep + j) mod nv`
//! converted to Bézier with `A = M_bezier⁻¹·M` (notes/patches.md §7); bilinear sub-patches use
//! their four corners. Classes: uniform per sub-patch; varying (and, on bilinear meshes,
//! vertex) at sub-patch corners, bilinear across; facevarying per sub-patch corner; vertex
//! through the basis (for NURBS through the rational basis). Mesh u, v run 0..1 over the whole
//! mesh (so "Pz" height fields get x = u, y = v); NuPatch u, v are knot values. Default s, t
//! interpolate TextureCoordinates over the mesh (over [umin,umax]×[vmin,vmax] for NURBS).

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec4};

use super::bezier::{BezierPatch, Extra, Shared, Target};
use super::primvar::{self, ClassCounts, Defaults, Selector, SourceVar};
use super::spline::{bezier_spans, check_knots, refine, to_bezier};
use super::trim::Trim;
use super::Surface;
use crate::diag::{Diag, Diagnostics};
use crate::scene::{Basis, Class, Geometry, ParamList, ParamType, Primitive};

/// Homogeneous object-space control points from "P", "Pw" or "Pz" (`count` of them, on an
/// `nu`-wide grid for "Pz" whose x, y are the mesh parameters).
fn control_points(
    pv: &ParamList,
    count: usize,
    nu: usize,
    nv: usize,
    periodic: (bool, bool),
) -> Result<Vec<Vec4>, String> {
    let take = |name: &str, w: usize| -> Result<Option<&[f32]>, String> {
        match pv.floats(name) {
            Some(f) if f.len() >= count * w => Ok(Some(&f[..count * w])),
            Some(f) => Err(format!(
                "\"{name}\" has {} values; {count} control points need {}",
                f.len(),
                count * w
            )),
            None => Ok(None),
        }
    };
    if let Some(p) = take("P", 3)? {
        return Ok(p
            .chunks_exact(3)
            .map(|c| Vec4::new(c[0], c[1], c[2], 1.0))
            .collect());
    }
    if let Some(p) = take("Pw", 4)? {
        if p.chunks_exact(4).any(|c| !(c[3] > 0.0)) {
            return Err("\"Pw\" weights must be positive".into());
        }
        return Ok(p.chunks_exact(4).map(Vec4::from_slice).collect());
    }
    if let Some(z) = take("Pz", 1)? {
        let div = |n: usize, per: bool| (if per { n } else { n - 1 }).max(1) as f32;
        let (du, dv) = (div(nu, periodic.0), div(nv, periodic.1));
        return Ok(z
            .iter()
            .enumerate()
            .map(|(k, &z)| Vec4::new((k % nu) as f32 / du, (k / nu) as f32 / dv, z, 1.0))
            .collect());
    }
    Err("no control points: \"P\", \"Pw\" or \"Pz\" is needed".into())
}

/// Vertex-class variables interpolated through the basis: where they go and how wide.
fn vertex_extras(vars: &[SourceVar]) -> (Vec<Extra>, usize) {
    let mut extras = Vec::new();
    let mut off = 4;
    for v in vars {
        let w = v.width();
        let target = match (v.name.as_str(), v.ty) {
            (_, ParamType::String) => continue,
            ("s", _) => Target::S,
            ("t", _) => Target::T,
            ("st", _) if w >= 2 => Target::St,
            ("Cs", _) if w >= 3 => Target::Cs,
            ("Os", _) if w >= 3 => Target::Os,
            ("N", _) if w >= 3 => Target::N,
            _ => Target::User {
                name: v.name.clone(),
                ty: v.ty,
                array_len: v.array_len,
            },
        };
        extras.push(Extra {
            target,
            offset: off,
            width: w,
        });
        off += w;
    }
    (extras, off)
}

/// Camera-space homogeneous control rows: `wx wy wz w` then each vertex variable times w.
fn rows(pts: &[Vec4], m: Mat4, vars: &[SourceVar], dim: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(pts.len() * dim);
    for (k, h) in pts.iter().enumerate() {
        let w = h.w;
        let p = m.transform_point3(h.truncate() / w) * w;
        out.extend_from_slice(&[p.x, p.y, p.z, w]);
        for v in vars {
            if v.ty == ParamType::String {
                continue;
            }
            let vw = v.width();
            out.extend(v.floats[k * vw..(k + 1) * vw].iter().map(|x| x * w));
        }
    }
    debug_assert_eq!(out.len(), pts.len() * dim);
    out
}

fn bilerp(c: &[f32; 8], x: f32, y: f32, odd: usize) -> f32 {
    let v = |i: usize| c[2 * i + odd];
    (1.0 - y) * ((1.0 - x) * v(0) + x * v(1)) + y * ((1.0 - x) * v(2) + x * v(3))
}

/// Defaults for a piece covering the normalised rectangle [x0,x1]×[y0,y1] of the primitive.
fn defaults(prim: &Primitive, x: [f32; 2], y: [f32; 2]) -> Defaults {
    let tc = &prim.attributes.texture_coordinates;
    let at = |odd| {
        [
            bilerp(tc, x[0], y[0], odd),
            bilerp(tc, x[1], y[0], odd),
            bilerp(tc, x[0], y[1], odd),
            bilerp(tc, x[1], y[1], odd),
        ]
    };
    Defaults {
        s: at(0),
        t: at(1),
        color: prim.attributes.color,
        opacity: prim.attributes.opacity,
    }
}

/// Splits the parameter list into (vertex-class variables, the rest) for basis interpolation.
fn split_vertex(pv: &ParamList) -> (ParamList, ParamList) {
    let (v, o): (Vec<_>, Vec<_>) = pv
        .iter()
        .filter(|p| !matches!(&*p.name, "P" | "Pw" | "Pz"))
        .cloned()
        .partition(|p| p.decl.class == Class::Vertex && p.decl.ty != ParamType::String);
    (ParamList(v), ParamList(o))
}

/// The RenderMan sub-patch counts along one direction.
fn mesh_count(n: usize, periodic: bool, bicubic: bool, step: usize) -> usize {
    match (bicubic, periodic) {
        (false, true) => n,
        (false, false) => n.saturating_sub(1),
        (true, true) => n / step.max(1),
        (true, false) => (n.saturating_sub(4)) / step.max(1) + 1,
    }
}

/// Surfaces of a `Patch` or `PatchMesh`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn patch_mesh(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    bicubic: bool,
    (nu, nv): (usize, usize),
    (uper, vper): (bool, bool),
    (ub, vb): (&Basis, &Basis),
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let err = |msg: String| {
        diags.report(
            Diag::error("geom::invalid", format!("{msg}; the patch is skipped"))
                .label(prim.span, "this patch"),
        );
    };
    let (us, vs) = (ub.step as usize, vb.step as usize);
    let (nup, nvp) = (
        mesh_count(nu, uper, bicubic, us),
        mesh_count(nv, vper, bicubic, vs),
    );
    if nup == 0 || nvp == 0 || (bicubic && (nu < 4 || nv < 4)) {
        err(format!("a {nu}×{nv} mesh has no sub-patches"));
        return Vec::new();
    }
    let rational = prim.primvars.get("P").is_none() && prim.primvars.get("Pw").is_some();
    let pts = match control_points(&prim.primvars, nu * nv, nu, nv, (uper, vper)) {
        Ok(p) => p,
        Err(e) => {
            err(e);
            return Vec::new();
        }
    };
    // Varying values sit at sub-patch corners (bilinear meshes: at the vertices).
    let (vu, vv) = if bicubic {
        (nup + usize::from(!uper), nvp + usize::from(!vper))
    } else {
        (nu, nv)
    };
    let counts = ClassCounts {
        uniform: nup * nvp,
        varying: vu * vv,
        facevarying: nup * nvp * 4,
    };
    let (vert_pl, other_pl) = if bicubic {
        split_vertex(&prim.primvars)
    } else {
        (ParamList(Vec::new()), (*prim.primvars).clone())
    };
    let vars = primvar::resolve(&other_pl, m, counts, diags);
    let vcounts = ClassCounts {
        uniform: 1,
        varying: nu * nv,
        facevarying: 1,
    };
    let vvars = primvar::resolve(&vert_pl, m, vcounts, diags);
    let (extras, dim) = vertex_extras(&vvars);
    let ctrl = rows(&pts, m, &vvars, dim);
    let origin = m.transform_point3(Vec3::ZERO);
    let (au, av) = (to_bezier(&ub.matrix), to_bezier(&vb.matrix));
    let deg = if bicubic { 3 } else { 1 };
    let n1 = deg + 1;
    let (ustep, vstep) = if bicubic { (us, vs) } else { (1, 1) };
    let mut out: Vec<Box<dyn Surface>> = Vec::with_capacity(nup * nvp);
    let mut src = vec![0.0f32; n1 * n1 * dim];
    let mut tmp = vec![0.0f32; n1 * n1 * dim];
    for b in 0..nvp {
        for a in 0..nup {
            for j in 0..n1 {
                for i in 0..n1 {
                    let (pi, pj) = ((a * ustep + i) % nu, (b * vstep + j) % nv);
                    let o = (pj * nu + pi) * dim;
                    let d = (j * n1 + i) * dim;
                    src[d..d + dim].copy_from_slice(&ctrl[o..o + dim]);
                }
            }
            let patch = if bicubic {
                // Bézier rows: B = A_u · P · A_vᵀ, first along u then along v.
                tmp.iter_mut().for_each(|x| *x = 0.0);
                for j in 0..4 {
                    for r in 0..4 {
                        for c in 0..4 {
                            let w = au[r][c];
                            if w != 0.0 {
                                let (d, s) = ((j * 4 + r) * dim, (j * 4 + c) * dim);
                                for k in 0..dim {
                                    tmp[d + k] += w * src[s + k];
                                }
                            }
                        }
                    }
                }
                let mut bez = vec![0.0f32; 16 * dim];
                for i in 0..4 {
                    for r in 0..4 {
                        for c in 0..4 {
                            let w = av[r][c];
                            if w != 0.0 {
                                let (d, s) = ((r * 4 + i) * dim, (c * 4 + i) * dim);
                                for k in 0..dim {
                                    bez[d + k] += w * tmp[s + k];
                                }
                            }
                        }
                    }
                }
                if !rational {
                    // Tangent-carrying bases (Hermite, power) have rows that do not sum to 1,
                    // so a Bézier point came out as A·(Σ aᵢ Pᵢ) + w·t for the camera
                    // transform's translation t, w = Σ aᵢ: it needs t once.
                    for c in bez.chunks_exact_mut(dim) {
                        let k = 1.0 - c[3];
                        c[0] += k * origin.x;
                        c[1] += k * origin.y;
                        c[2] += k * origin.z;
                        c[3] = 1.0;
                    }
                }
                bez
            } else {
                src.clone()
            };
            if patch.chunks_exact(dim).any(|c| !(c[3] > 0.0)) {
                err("a sub-patch's weights are not positive after the basis change".into());
                return Vec::new();
            }
            let uni = a + b * nup;
            let corner = |da: usize, db: usize| ((a + da) % vu) + ((b + db) % vv) * vu;
            let sel = Selector {
                uniform: uni,
                vertex: [corner(0, 0), corner(1, 0), corner(0, 1), corner(1, 1)],
                facevertex: [4 * uni, 4 * uni + 1, 4 * uni + 2, 4 * uni + 3],
            };
            let (x0, x1) = (a as f32 / nup as f32, (a + 1) as f32 / nup as f32);
            let (y0, y1) = (b as f32 / nvp as f32, (b + 1) as f32 / nvp as f32);
            let d = defaults(prim, [x0, x1], [y0, y1]);
            let shared = Shared {
                index,
                flip,
                vars: primvar::patch_vars(&vars, &sel, &d),
                extras: extras.clone(),
                uv: [x0, x1, y0, y1],
                trim: None,
            };
            out.push(Box::new(BezierPatch::new(
                Arc::new(shared),
                deg,
                deg,
                dim,
                patch,
            )));
        }
    }
    out
}

/// The NuPatch parameters as `surfaces_for` passes them.
pub(crate) struct Nurbs<'a> {
    pub nu: usize,
    pub uorder: usize,
    pub uknot: &'a [f32],
    pub umin: f32,
    pub umax: f32,
    pub nv: usize,
    pub vorder: usize,
    pub vknot: &'a [f32],
    pub vmin: f32,
    pub vmax: f32,
    pub trim: Option<&'a crate::scene::TrimCurves>,
}

/// Surfaces of a `NuPatch`: one rational Bézier piece per nonempty knot span.
pub(crate) fn nu_patch(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    n: &Nurbs,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let err = |msg: String| {
        diags.report(
            Diag::error("geom::invalid", format!("NuPatch: {msg}; the patch is skipped"))
                .label(prim.span, "this NuPatch")
                .help("knots: nu + uorder non-decreasing values; umin < umax inside knots[uorder−1]..knots[nu]"),
        );
    };
    if let Some(e) = check_knots(n.uknot, n.nu, n.uorder, n.umin, n.umax) {
        err(format!("u: {e}"));
        return Vec::new();
    }
    if let Some(e) = check_knots(n.vknot, n.nv, n.vorder, n.vmin, n.vmax) {
        err(format!("v: {e}"));
        return Vec::new();
    }
    let pts = match control_points(&prim.primvars, n.nu * n.nv, n.nu, n.nv, (false, false)) {
        Ok(p) => p,
        Err(e) => {
            err(e);
            return Vec::new();
        }
    };
    let (p, q) = (n.uorder - 1, n.vorder - 1);
    let (nus, nvs) = (n.nu - p, n.nv - q);
    let counts = ClassCounts {
        uniform: nus * nvs,
        varying: (nus + 1) * (nvs + 1),
        facevarying: nus * nvs * 4,
    };
    let (vert_pl, other_pl) = split_vertex(&prim.primvars);
    let vars = primvar::resolve(&other_pl, m, counts, diags);
    let vcounts = ClassCounts {
        uniform: 1,
        varying: n.nu * n.nv,
        facevarying: 1,
    };
    let vvars = primvar::resolve(&vert_pl, m, vcounts, diags);
    let (extras, dim) = vertex_extras(&vvars);
    let ctrl = rows(&pts, m, &vvars, dim);
    // Bézier extraction: refine every row in u, then every column in v.
    let (uk, uspans) = bezier_spans(n.uknot, p, n.umin, n.umax);
    let (vk, vspans) = bezier_spans(n.vknot, q, n.vmin, n.vmax);
    let nu2 = uk.len() - p - 1;
    let nv2 = vk.len() - q - 1;
    let mut net_u = Vec::with_capacity(nu2 * n.nv * dim);
    for j in 0..n.nv {
        net_u.extend(refine(n.uknot, p, &ctrl, j * n.nu * dim, dim, n.nu, dim));
    }
    let mut net = vec![0.0f32; nu2 * nv2 * dim];
    for i in 0..nu2 {
        let col = refine(n.vknot, q, &net_u, i * dim, nu2 * dim, n.nv, dim);
        for j in 0..nv2 {
            let o = (j * nu2 + i) * dim;
            net[o..o + dim].copy_from_slice(&col[j * dim..(j + 1) * dim]);
        }
    }
    let trim = n.trim.and_then(Trim::new).map(Arc::new);
    let (du, dv) = (n.umax - n.umin, n.vmax - n.vmin);
    let mut out: Vec<Box<dyn Surface>> = Vec::new();
    for sv in &vspans {
        for su in &uspans {
            let mut piece = Vec::with_capacity((p + 1) * (q + 1) * dim);
            for j in 0..=q {
                for i in 0..=p {
                    let o = ((sv.first + j) * nu2 + su.first + i) * dim;
                    piece.extend_from_slice(&net[o..o + dim]);
                }
            }
            if piece.chunks_exact(dim).any(|c| !(c[3] > 0.0)) {
                err("weights must be positive".into());
                return Vec::new();
            }
            let uni = su.seg + sv.seg * nus;
            let corner = |a: usize, b: usize| (su.seg + a) + (sv.seg + b) * (nus + 1);
            let sel = Selector {
                uniform: uni,
                vertex: [corner(0, 0), corner(1, 0), corner(0, 1), corner(1, 1)],
                facevertex: [4 * uni, 4 * uni + 1, 4 * uni + 2, 4 * uni + 3],
            };
            let nx = |x: f32| (x - n.umin) / du;
            let ny = |y: f32| (y - n.vmin) / dv;
            let d = defaults(prim, [nx(su.a), nx(su.b)], [ny(sv.a), ny(sv.b)]);
            let shared = Shared {
                index,
                flip,
                vars: primvar::patch_vars(&vars, &sel, &d),
                extras: extras.clone(),
                uv: [su.a, su.b, sv.a, sv.b],
                trim: trim.clone(),
            };
            let whole = BezierPatch::new(Arc::new(shared), p, q, dim, piece);
            let clip = |s: &super::spline::Span, lo: f32, hi: f32| {
                let l = s.b - s.a;
                (
                    ((lo - s.a) / l).clamp(0.0, 1.0),
                    ((hi - s.a) / l).clamp(0.0, 1.0),
                )
            };
            let (a0, a1) = clip(su, n.umin, n.umax);
            let (b0, b1) = clip(sv, n.vmin, n.vmax);
            if a0 >= a1 || b0 >= b1 {
                continue;
            }
            out.push(Box::new(whole.restrict(a0, a1, b0, b1)));
        }
    }
    out
}

/// Surfaces of `Geometry "teapot"`: the 32 bicubic Bézier patches of Newell's teapot.
pub(crate) fn teapot(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let fixed = ParamList(
        prim.primvars
            .iter()
            .filter(|p| matches!(p.decl.class, Class::Constant | Class::Uniform))
            .cloned()
            .collect(),
    );
    let counts = ClassCounts {
        uniform: 1,
        varying: 4,
        facevarying: 4,
    };
    let vars = primvar::resolve(&fixed, m, counts, diags);
    let d = defaults(prim, [0.0, 1.0], [0.0, 1.0]);
    let pv = primvar::patch_vars(&vars, &Selector::QUADRIC, &d);
    let mut out: Vec<Box<dyn Surface>> = Vec::with_capacity(32);
    for patch in super::teapot::PATCHES.iter() {
        let pts: Vec<Vec4> = patch
            .iter()
            .map(|&k| {
                let v = super::teapot::VERTICES[k as usize - 1];
                Vec4::new(v[0], v[1], v[2], 1.0)
            })
            .collect();
        let shared = Shared {
            index,
            flip,
            vars: pv.clone(),
            extras: Vec::new(),
            uv: [0.0, 1.0, 0.0, 1.0],
            trim: None,
        };
        let ctrl = rows(&pts, m, &[], 4);
        out.push(Box::new(BezierPatch::new(Arc::new(shared), 3, 3, 4, ctrl)));
    }
    out
}

/// Object-space Bézier control points of the teapot's patches, RI order (u fastest).
pub fn teapot_patches() -> Vec<[Vec3; 16]> {
    super::teapot::PATCHES
        .iter()
        .map(|p| p.map(|k| Vec3::from(super::teapot::VERTICES[k as usize - 1])))
        .collect()
}

/// Dispatch helper for `Geometry::PatchMesh`/`NuPatch`/`Named`; None for other kinds.
pub(crate) fn surfaces(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    diags: &Diagnostics,
) -> Option<Vec<Box<dyn Surface>>> {
    Some(match &*prim.geometry {
        Geometry::PatchMesh {
            bicubic,
            nu,
            nv,
            uperiodic,
            vperiodic,
            u_basis,
            v_basis,
        } => patch_mesh(
            index,
            prim,
            m,
            flip,
            *bicubic,
            (*nu, *nv),
            (*uperiodic, *vperiodic),
            (u_basis, v_basis),
            diags,
        ),
        Geometry::NuPatch {
            nu,
            uorder,
            uknot,
            umin,
            umax,
            nv,
            vorder,
            vknot,
            vmin,
            vmax,
            trim,
        } => nu_patch(
            index,
            prim,
            m,
            flip,
            &Nurbs {
                nu: *nu,
                uorder: *uorder,
                uknot,
                umin: *umin,
                umax: *umax,
                nv: *nv,
                vorder: *vorder,
                vknot,
                vmin: *vmin,
                vmax: *vmax,
                trim: trim.as_deref(),
            },
            diags,
        ),
        Geometry::Named { name } if name == "teapot" => teapot(index, prim, m, flip, diags),
        _ => return None,
    })
}
