//! Primitive variables for dicing: moved to camera space once, picked per patch corner, and
//! interpolated over grids.
//!
//! Input: a primitive's [`ParamList`] (object space) and `camera_from_object`.
//! Output: [`SourceVar`]s in camera space (per primitive), [`PatchVars`] (the four corner values of
//! one parametric patch, shared by its split children) and the filled grid fields.
//! Invariants: points move with `camera_from_object`, vectors with its linear part, normals with
//! the inverse transpose; `hpoint`s are divided by w and become points; matrices become
//! current-from-X (RIB row-major layout kept). Every `SourceVar` has been checked to hold enough
//! values for its class, so corner picking never indexes out of range.

use glam::{Mat4, Vec3};

use crate::diag::{Diag, Diagnostics};
use crate::scene::{Class, ParamList, ParamType};
use crate::shade::{Grid, GridVar};

/// Names that are standard globals (or geometry) rather than extra grid variables.
const STANDARD: [&str; 9] = ["P", "Pw", "Pz", "N", "Cs", "Os", "s", "t", "st"];

/// One primitive variable in camera space, `width()` numbers per element.
#[derive(Clone, Debug)]
pub(crate) struct SourceVar {
    pub name: String,
    pub ty: ParamType,
    pub array_len: usize,
    pub class: Class,
    pub floats: Vec<f32>,
    pub strings: Vec<String>,
}

impl SourceVar {
    pub fn width(&self) -> usize {
        self.ty.components() * self.array_len
    }
}

/// How many elements each class needs on one primitive.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ClassCounts {
    pub uniform: usize,
    pub varying: usize,
    pub facevarying: usize,
}

/// Which element each class uses at one patch's corners (0,0) (1,0) (0,1) (1,1).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Selector {
    pub uniform: usize,
    pub vertex: [usize; 4],
    pub facevertex: [usize; 4],
}

impl Selector {
    /// Quadrics: one facet, varying values at the four parametric corners.
    pub const QUADRIC: Selector = Selector {
        uniform: 0,
        vertex: [0, 1, 2, 3],
        facevertex: [0, 1, 2, 3],
    };
    fn corners(&self, class: Class) -> Option<[usize; 4]> {
        match class {
            Class::Constant | Class::Uniform => None,
            Class::Varying | Class::Vertex => Some(self.vertex),
            Class::FaceVarying | Class::FaceVertex => Some(self.facevertex),
        }
    }
    fn single(&self, class: Class) -> usize {
        match class {
            Class::Uniform => self.uniform,
            _ => 0,
        }
    }
}

/// Moves every primitive variable except `P`/`Pw`/`Pz` to camera space and checks its count.
/// Variables with too few values are dropped with an error.
pub(crate) fn resolve(
    params: &ParamList,
    camera_from_object: Mat4,
    counts: ClassCounts,
    diags: &Diagnostics,
) -> Vec<SourceVar> {
    let normal_m = camera_from_object.inverse().transpose();
    let mut out = Vec::new();
    for p in params.iter() {
        if matches!(&*p.name, "P" | "Pw" | "Pz") {
            continue;
        }
        let need = match p.decl.class {
            Class::Constant => 1,
            Class::Uniform => counts.uniform,
            Class::Varying | Class::Vertex => counts.varying,
            Class::FaceVarying | Class::FaceVertex => counts.facevarying,
        };
        let width = p.decl.width().max(1);
        let have = p.data.len() / width;
        if have < need {
            diags.report(
                Diag::error(
                    "geom::primvar_count",
                    format!(
                        "primitive variable \"{}\" has {} values; its class needs {}",
                        p.name, have, need
                    ),
                )
                .label(p.span, "too few values")
                .help("give one value per element of the class (RISpec §5, Table 5.1)"),
            );
            continue;
        }
        if p.decl.ty == ParamType::String
            && p.decl.class != Class::Constant
            && p.decl.class != Class::Uniform
        {
            diags.report(
                Diag::warning(
                    "geom::primvar_string",
                    format!("string primitive variable \"{}\" cannot be interpolated; only its first value is used", p.name),
                )
                .label(p.span, "string values"),
            );
        }
        let mut v = SourceVar {
            name: p.name.to_string(),
            ty: p.decl.ty,
            array_len: p.decl.array_len.max(1),
            class: p.decl.class,
            floats: p.data.floats().to_vec(),
            strings: p.data.strings().to_vec(),
        };
        if v.ty == ParamType::String && v.class != Class::Constant && v.class != Class::Uniform {
            v.class = Class::Constant;
        }
        to_camera(&mut v, camera_from_object, normal_m);
        out.push(v);
    }
    out
}

fn to_camera(v: &mut SourceVar, m: Mat4, normal_m: Mat4) {
    match v.ty {
        ParamType::Point => {
            for c in v.floats.chunks_exact_mut(3) {
                let q = m.transform_point3(Vec3::new(c[0], c[1], c[2]));
                c.copy_from_slice(&q.to_array());
            }
        }
        ParamType::Vector => {
            for c in v.floats.chunks_exact_mut(3) {
                let q = m.transform_vector3(Vec3::new(c[0], c[1], c[2]));
                c.copy_from_slice(&q.to_array());
            }
        }
        ParamType::Normal => {
            for c in v.floats.chunks_exact_mut(3) {
                let q = normal_m.transform_vector3(Vec3::new(c[0], c[1], c[2]));
                c.copy_from_slice(&q.to_array());
            }
        }
        ParamType::HPoint => {
            // The shader sees hpoints as points (RISpec §3: divided by w).
            let mut pts = Vec::with_capacity(v.floats.len() / 4 * 3);
            for c in v.floats.chunks_exact(4) {
                let w = if c[3] != 0.0 { c[3] } else { 1.0 };
                let q = m.transform_point3(Vec3::new(c[0], c[1], c[2]) / w);
                pts.extend_from_slice(&q.to_array());
            }
            v.floats = pts;
            v.ty = ParamType::Point;
        }
        ParamType::Matrix => {
            // RIB layout is row-major for row vectors, i.e. glam's column-major layout of the
            // column-vector transform object_from_X; current_from_X = camera_from_object · it.
            for c in v.floats.chunks_exact_mut(16) {
                let a = Mat4::from_cols_slice(c);
                c.copy_from_slice(&(m * a).to_cols_array());
            }
        }
        ParamType::Float | ParamType::Integer | ParamType::Color | ParamType::String => {}
    }
}

/// A user variable's values at one patch's corners (or its single value when uniform).
#[derive(Clone, Debug)]
pub(crate) struct CornerVar {
    pub name: String,
    pub ty: ParamType,
    pub array_len: usize,
    pub uniform: bool,
    /// `width` numbers when uniform, else 4 × `width` (corners (0,0) (1,0) (0,1) (1,1)).
    pub floats: Vec<f32>,
    pub strings: Vec<String>,
}

/// Everything a parametric patch interpolates, at its corners (0,0) (1,0) (0,1) (1,1) of the
/// parameter domain [0,1]².
#[derive(Clone, Debug)]
pub(crate) struct PatchVars {
    pub s: [f32; 4],
    pub t: [f32; 4],
    pub cs: [Vec3; 4],
    pub os: [Vec3; 4],
    /// User shading normals (camera space, not normalised), when the primitive gives "N".
    pub n: Option<[Vec3; 4]>,
    pub user: Vec<CornerVar>,
}

impl PatchVars {
    /// The values at new corners, each a weighted sum of the old corners 0, 1, 2 (used to cut a
    /// triangle `(a, b, c, c)` into quads). Uniform values are kept.
    pub fn remap(&self, w: &[[f32; 3]; 4]) -> PatchVars {
        fn f(c: &[f32; 4], w: &[[f32; 3]; 4]) -> [f32; 4] {
            w.map(|w| w[0] * c[0] + w[1] * c[1] + w[2] * c[2])
        }
        fn v(c: &[Vec3; 4], w: &[[f32; 3]; 4]) -> [Vec3; 4] {
            w.map(|w| w[0] * c[0] + w[1] * c[1] + w[2] * c[2])
        }
        let user = self
            .user
            .iter()
            .map(|cv| {
                if cv.uniform || cv.ty == ParamType::String {
                    return cv.clone();
                }
                let width = cv.floats.len() / 4;
                let mut floats = Vec::with_capacity(4 * width);
                for wk in w {
                    for c in 0..width {
                        floats.push(
                            wk[0] * cv.floats[c]
                                + wk[1] * cv.floats[width + c]
                                + wk[2] * cv.floats[2 * width + c],
                        );
                    }
                }
                CornerVar {
                    floats,
                    ..cv.clone()
                }
            })
            .collect();
        PatchVars {
            s: f(&self.s, w),
            t: f(&self.t, w),
            cs: v(&self.cs, w),
            os: v(&self.os, w),
            n: self.n.as_ref().map(|n| v(n, w)),
            user,
        }
    }
}

/// Defaults for the standard globals at the four corners.
pub(crate) struct Defaults {
    pub s: [f32; 4],
    pub t: [f32; 4],
    pub color: Vec3,
    pub opacity: Vec3,
}

fn pick_f(v: &SourceVar, sel: &Selector, comp: usize) -> [f32; 4] {
    let w = v.width();
    match sel.corners(v.class) {
        Some(c) => c.map(|e| v.floats[e * w + comp]),
        None => [v.floats[sel.single(v.class) * w + comp]; 4],
    }
}

fn pick_v3(v: &SourceVar, sel: &Selector) -> [Vec3; 4] {
    let w = v.width();
    let at = |e: usize| Vec3::from_slice(&v.floats[e * w..e * w + 3]);
    match sel.corners(v.class) {
        Some(c) => c.map(at),
        None => [at(sel.single(v.class)); 4],
    }
}

/// Picks the corner values of every variable for one patch.
pub(crate) fn patch_vars(vars: &[SourceVar], sel: &Selector, d: &Defaults) -> PatchVars {
    let mut pv = PatchVars {
        s: d.s,
        t: d.t,
        cs: [d.color; 4],
        os: [d.opacity; 4],
        n: None,
        user: Vec::new(),
    };
    let find = |name: &str| {
        vars.iter()
            .find(|v| v.name == name && v.ty != ParamType::String)
    };
    let three = |v: &&SourceVar| v.width() >= 3;
    if let Some(st) = find("st").filter(|v| v.width() >= 2) {
        pv.s = pick_f(st, sel, 0);
        pv.t = pick_f(st, sel, 1);
    }
    if let Some(s) = find("s") {
        pv.s = pick_f(s, sel, 0);
    }
    if let Some(t) = find("t") {
        pv.t = pick_f(t, sel, 0);
    }
    if let Some(c) = find("Cs").filter(three) {
        pv.cs = pick_v3(c, sel);
    }
    if let Some(o) = find("Os").filter(three) {
        pv.os = pick_v3(o, sel);
    }
    if let Some(n) = find("N").filter(three) {
        pv.n = Some(pick_v3(n, sel));
    }
    for v in vars {
        if STANDARD.contains(&v.name.as_str()) {
            continue;
        }
        let w = v.width();
        let corners = sel.corners(v.class);
        let mut cv = CornerVar {
            name: v.name.clone(),
            ty: v.ty,
            array_len: v.array_len,
            uniform: corners.is_none(),
            floats: Vec::new(),
            strings: Vec::new(),
        };
        if v.ty == ParamType::String {
            let e = sel.single(v.class);
            cv.uniform = true;
            cv.strings = v.strings[e * w..(e + 1) * w].to_vec();
        } else {
            match corners {
                Some(c) => {
                    cv.floats.reserve(4 * w);
                    for e in c {
                        cv.floats.extend_from_slice(&v.floats[e * w..(e + 1) * w]);
                    }
                }
                None => {
                    let e = sel.single(v.class);
                    cv.floats.extend_from_slice(&v.floats[e * w..(e + 1) * w]);
                }
            }
        }
        pv.user.push(cv);
    }
    pv
}

#[inline]
fn bilerp(c: &[f32; 4], a: f32, b: f32) -> f32 {
    (1.0 - b) * ((1.0 - a) * c[0] + a * c[1]) + b * ((1.0 - a) * c[2] + a * c[3])
}

#[inline]
fn bilerp3(c: &[Vec3; 4], a: f32, b: f32) -> Vec3 {
    (1.0 - b) * ((1.0 - a) * c[0] + a * c[1]) + b * ((1.0 - a) * c[2] + a * c[3])
}

/// Fills s, t, Cs, Os, the user normal (when given) and every user variable of a grid whose
/// points sit at corner-domain parameters `a = a0 + i·da`, `b = b0 + j·db`.
pub(crate) fn fill_grid(g: &mut Grid, pv: &PatchVars, a0: f32, da: f32, b0: f32, db: f32) {
    let (nu, nv) = (g.nu, g.nv);
    let cs_const = pv.cs.iter().all(|&c| c == pv.cs[0]);
    let os_const = pv.os.iter().all(|&c| c == pv.os[0]);
    for j in 0..nv {
        let b = b0 + j as f32 * db;
        let row = j * nu;
        for i in 0..nu {
            let a = a0 + i as f32 * da;
            let k = row + i;
            g.s[k] = bilerp(&pv.s, a, b);
            g.t[k] = bilerp(&pv.t, a, b);
            g.cs[k] = if cs_const {
                pv.cs[0]
            } else {
                bilerp3(&pv.cs, a, b)
            };
            g.os[k] = if os_const {
                pv.os[0]
            } else {
                bilerp3(&pv.os, a, b)
            };
        }
    }
    if let Some(n) = &pv.n {
        for j in 0..nv {
            let b = b0 + j as f32 * db;
            for i in 0..nu {
                let a = a0 + i as f32 * da;
                let v = bilerp3(n, a, b).normalize_or_zero();
                let k = j * nu + i;
                // A zero user normal falls back to the geometric one.
                if v != Vec3::ZERO {
                    g.n[k] = v;
                }
            }
        }
    }
    g.primvars.reserve(pv.user.len());
    for cv in &pv.user {
        let w = cv.ty.components() * cv.array_len;
        let floats = if cv.uniform || cv.ty == ParamType::String {
            cv.floats.clone()
        } else {
            let mut out = vec![0.0f32; nu * nv * w];
            let (c0, rest) = cv.floats.split_at(w);
            let (c1, rest) = rest.split_at(w);
            let (c2, c3) = rest.split_at(w);
            for j in 0..nv {
                let b = b0 + j as f32 * db;
                for i in 0..nu {
                    let a = a0 + i as f32 * da;
                    let (w00, w10) = ((1.0 - a) * (1.0 - b), a * (1.0 - b));
                    let (w01, w11) = ((1.0 - a) * b, a * b);
                    let o = &mut out[(j * nu + i) * w..(j * nu + i + 1) * w];
                    for c in 0..w {
                        o[c] = w00 * c0[c] + w10 * c1[c] + w01 * c2[c] + w11 * c3[c];
                    }
                }
            }
            out
        };
        g.primvars.push(GridVar {
            name: cv.name.clone(),
            ty: cv.ty,
            array_len: cv.array_len,
            uniform: cv.uniform || cv.ty == ParamType::String,
            floats,
            strings: cv.strings.clone(),
        });
    }
}
