//! `Procedural "DynamicLoad"` and the C RenderMan Interface its libraries call back into.
//!
//! Input: a shared library with PRMan's procedural entry points
//! `RtPointer ConvertParameters(RtString)`, `RtVoid Subdivide(RtPointer, RtFloat detail)` and
//! `RtVoid Free(RtPointer)`; inside `Subdivide` the library calls the C RI functions below
//! (`RiSphereV`, `RiPolygonV`, `RiAttributeBegin`, `RiProcedural`, …), which the `arbor`
//! binary exports (build.rs puts `Ri*` in its dynamic symbol table; `include/ri.h` declares
//! them, with the `...`/RI_NULL forms as inline wrappers over the `V` forms). Output: each call
//! becomes the RIB request of the same name, run by the scene builder in the current graphics
//! state, so it is validated (and diagnosed) like RIB; diagnostics point at the `Procedural`
//! request.
//! Invariants: the RI functions act only on the thread expanding a DynamicLoad procedural and
//! only during its calls (anywhere else they do nothing); a parameter's value count comes from
//! its declaration and the primitive's topology, as in the C binding, so an undeclared
//! parameter is an error and is dropped; a panic never unwinds into C; libraries stay loaded
//! until the process ends (a later `RiProcedural` may still point into them); a library whose
//! RI calls arbor does not provide fails to load with the linker's message instead of
//! crashing later (it is opened with RTLD_NOW).
#![allow(non_snake_case)]
#![allow(clippy::missing_safety_doc)]

use std::cell::RefCell;
use std::collections::HashMap;
use std::ffi::{c_char, c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::diag::{Diag, Span};
use crate::rib::{Arg, Request, Value};

use super::builder::Builder;
use super::params::{split_token, Counts};
use super::types::{Class, Decl, ParamType};

pub type RtInt = i32;
pub type RtFloat = f32;
pub type RtToken = *const c_char;
pub type RtPointer = *mut c_void;
/// `RtVoid (*)(RtPointer, RtFloat)`.
pub type RtProcSubdivFunc = unsafe extern "C" fn(RtPointer, RtFloat);
/// `RtVoid (*)(RtPointer)`.
pub type RtProcFreeFunc = unsafe extern "C" fn(RtPointer);
type ConvertFn = unsafe extern "C" fn(*mut c_char) -> RtPointer;

/// The most values one parameter may claim (a guard against garbage counts).
const MAX_VALUES: usize = 1 << 28;

thread_local! {
    /// The builders expanding a library on this thread, innermost last.
    static ACTIVE: RefCell<Vec<Active>> = const { RefCell::new(Vec::new()) };
}

#[derive(Clone, Copy)]
struct Active {
    builder: *mut c_void,
    span: Span,
}

/// A loaded procedural library's entry points.
struct Library {
    convert: ConvertFn,
    subdivide: RtProcSubdivFunc,
    free: RtProcFreeFunc,
    /// Never unloaded (see the module invariants).
    _lib: ManuallyDrop<libloading::Library>,
}

/// The DynamicLoad libraries of a build, by path (or why each could not be loaded).
#[derive(Default)]
pub struct Libraries {
    map: HashMap<PathBuf, Result<Arc<Library>, String>>,
}

impl Libraries {
    fn load(&mut self, path: &Path) -> Result<Arc<Library>, String> {
        self.map
            .entry(path.to_path_buf())
            .or_insert_with(|| open(path).map(Arc::new))
            .clone()
    }
}

fn open(path: &Path) -> Result<Library, String> {
    #[cfg(unix)]
    let lib: libloading::Library = unsafe {
        libloading::os::unix::Library::open(
            Some(path),
            libloading::os::unix::RTLD_NOW | libloading::os::unix::RTLD_LOCAL,
        )
    }
    .map_err(|e| e.to_string())?
    .into();
    #[cfg(not(unix))]
    let lib = unsafe { libloading::Library::new(path) }.map_err(|e| e.to_string())?;
    unsafe {
        let convert = *lib
            .get::<ConvertFn>(b"ConvertParameters\0")
            .map_err(|e| format!("no `ConvertParameters` ({e})"))?;
        let subdivide = *lib
            .get::<RtProcSubdivFunc>(b"Subdivide\0")
            .map_err(|e| format!("no `Subdivide` ({e})"))?;
        let free = *lib
            .get::<RtProcFreeFunc>(b"Free\0")
            .map_err(|e| format!("no `Free` ({e})"))?;
        Ok(Library {
            convert,
            subdivide,
            free,
            _lib: ManuallyDrop::new(lib),
        })
    }
}

impl Builder<'_> {
    /// Loads a DynamicLoad library and runs `ConvertParameters`, `Subdivide` and `Free`.
    pub(super) fn expand_dynamic_load(
        &mut self,
        name: &str,
        params: &str,
        detail: f32,
        span: Span,
        arg_span: Span,
    ) {
        let (found, searched) = self.find_procedural(name, true, span);
        let Some(path) = found else {
            let help = super::procedural::searched_help(&searched);
            let d = Diag::error(
                "scene::procedural",
                format!("cannot find the DynamicLoad library `{name}`"),
            )
            .label(arg_span, "not found")
            .help(help);
            return self.report(d);
        };
        let lib = match self.libraries.load(&path) {
            Ok(l) => l,
            Err(e) => {
                let d = Diag::error(
                    "scene::procedural",
                    format!("cannot load the DynamicLoad library `{}`: {e}", path.display()),
                )
                .label(arg_span, "this library")
                .help(format!(
                    "a procedural library exports ConvertParameters, Subdivide and Free and may call only the RI functions arbor provides: {}",
                    EXPORTED.join(", ")
                ));
                return self.report(d);
            }
        };
        let Ok(cparams) = CString::new(params) else {
            let d = Diag::error(
                "scene::procedural",
                "DynamicLoad parameters hold a NUL byte",
            )
            .label(arg_span, "here");
            return self.report(d);
        };
        let what = format!("Procedural \"DynamicLoad\" \"{name}\"");
        self.expand(what, span, |b| {
            // The library may keep (or write into) the string until Free.
            let raw = cparams.into_raw();
            call_c(b, span, || unsafe {
                let data = (lib.convert)(raw);
                (lib.subdivide)(data, detail);
                (lib.free)(data);
            });
            drop(unsafe { CString::from_raw(raw) });
        });
    }
}

/// Calls into C with `b` as the builder the RI functions act on.
fn call_c(b: &mut Builder<'_>, span: Span, f: impl FnOnce()) {
    let ptr = b as *mut Builder<'_> as *mut c_void;
    ACTIVE.with(|a| a.borrow_mut().push(Active { builder: ptr, span }));
    f();
    ACTIVE.with(|a| a.borrow_mut().pop());
}

/// Runs `f` on the active builder (nothing happens outside a DynamicLoad expansion). A panic
/// is caught and reported, never unwound into C.
fn with_builder(name: &str, f: impl FnOnce(&mut Builder<'static>, Span)) {
    let Some(active) = ACTIVE.with(|a| a.borrow().last().copied()) else {
        return;
    };
    // SAFETY: `active.builder` was made by `call_c` from a live `&mut Builder` that is not
    // used until the C call it wraps returns, on this thread. Lifetimes do not exist at run
    // time; the builder outlives the call.
    let b = unsafe { &mut *(active.builder as *mut Builder<'static>) };
    let r = std::panic::catch_unwind(AssertUnwindSafe(|| f(&mut *b, active.span)));
    if r.is_err() {
        let d = Diag::error(
            "scene::procedural",
            format!("internal error while handling `{name}` from a DynamicLoad library"),
        )
        .label(active.span, "while expanding this procedural");
        b.report(d);
    }
}

fn arg(value: Value, span: Span) -> Arg {
    Arg { value, span }
}

/// Runs one request built from a C call.
fn run(b: &mut Builder<'_>, name: &str, span: Span, positional: Vec<Value>, params: Vec<Arg>) {
    let mut args: Vec<Arg> = positional.into_iter().map(|v| arg(v, span)).collect();
    args.extend(params);
    let req = Request {
        name: name.to_string(),
        span,
        args,
    };
    b.run(std::slice::from_ref(&req));
}

unsafe fn cstr(p: *const c_char) -> Option<String> {
    if p.is_null() {
        None
    } else {
        Some(CStr::from_ptr(p).to_string_lossy().into_owned())
    }
}

unsafe fn floats(p: *const f32, n: usize) -> Option<Vec<f32>> {
    if p.is_null() {
        None
    } else {
        Some(std::slice::from_raw_parts(p, n).to_vec())
    }
}

fn null_error(b: &mut Builder<'_>, span: Span, request: &str, what: &str) {
    let d = Diag::error(
        "scene::procedural",
        format!("`Ri{request}` from a DynamicLoad library: {what} is a null pointer"),
    )
    .label(span, "while expanding this procedural");
    b.report(d);
}

/// Every element count is `n` (shader and attribute parameters are single values).
/// The value counts of a primitive with one face (uniform) and `n` vertices.
fn one_face(n: usize) -> Counts {
    Counts {
        uniform: 1,
        varying: n,
        vertex: n,
        facevarying: n,
        facevertex: n,
    }
}

const SINGLE: Counts = Counts {
    uniform: 1,
    varying: 1,
    vertex: 1,
    facevarying: 1,
    facevertex: 1,
};

/// Reads a C parameter list (`n` tokens and value pointers) as RIB parameter arguments.
#[allow(clippy::too_many_arguments)]
unsafe fn plist(
    b: &mut Builder<'_>,
    span: Span,
    request: &str,
    counts: Counts,
    category: Option<&str>,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) -> Vec<Arg> {
    let mut out = Vec::new();
    if n <= 0 {
        return out;
    }
    if tokens.is_null() || parms.is_null() {
        null_error(b, span, request, "the parameter list");
        return out;
    }
    let ncolor = b.colors.as_ref().map_or(3, |c| c.n);
    for i in 0..n as usize {
        let Some(token) = cstr(*tokens.add(i)) else {
            null_error(b, span, request, &format!("parameter name {i}"));
            continue;
        };
        let value = *parms.add(i);
        if value.is_null() {
            null_error(b, span, request, &format!("the value of \"{token}\""));
            continue;
        }
        let decl = match resolve(b, category, &token) {
            Ok(d) => d,
            Err(msg) => {
                let d = Diag::error(
                    "scene::procedural",
                    format!("`Ri{request}` from a DynamicLoad library: {msg}"),
                )
                .label(span, "while expanding this procedural")
                .help(format!(
                    "the C interface reads as many values as the declaration says: declare it with RiDeclare(\"{token}\", \"varying float\") or inline (\"varying float {token}\")"
                ));
                b.report(d);
                continue;
            }
        };
        let comps = match decl.ty {
            ParamType::Color => ncolor,
            t => t.components(),
        };
        let count = counts
            .of(decl.class)
            .saturating_mul(decl.array_len)
            .saturating_mul(comps);
        if count > MAX_VALUES {
            let d = Diag::error(
                "scene::procedural",
                format!("`Ri{request}`: \"{token}\" would hold {count} values"),
            )
            .label(span, "while expanding this procedural");
            b.report(d);
            continue;
        }
        let v = match decl.ty {
            ParamType::String => {
                let ptrs = std::slice::from_raw_parts(value as *const *const c_char, count);
                let mut s = Vec::with_capacity(count);
                for &p in ptrs {
                    s.push(cstr(p).unwrap_or_default());
                }
                Value::StrArray(s)
            }
            ParamType::Integer => {
                let ints = std::slice::from_raw_parts(value as *const RtInt, count);
                Value::IntArray(ints.iter().map(|&i| i as i64).collect())
            }
            _ => Value::FloatArray(std::slice::from_raw_parts(value as *const f32, count).to_vec()),
        };
        out.push(arg(Value::Str(token), span));
        out.push(arg(v, span));
    }
    out
}

/// A token's declaration: inline (`"varying float foo"`) or from the dictionary.
fn resolve(b: &Builder<'_>, category: Option<&str>, token: &str) -> Result<Decl, String> {
    let (inline, name) =
        split_token(token).map_err(|e| format!("bad inline declaration \"{token}\": {e}"))?;
    let known = match category {
        Some(c) => b.dict.get_in(c, name),
        None => b.dict.get(name),
    };
    let has_class = token.split_whitespace().next().is_some_and(|w| {
        matches!(
            w,
            "constant" | "uniform" | "varying" | "vertex" | "facevarying" | "facevertex"
        )
    });
    match (inline, known) {
        (Some(mut d), Some(k)) if !has_class => {
            d.class = k.class;
            Ok(d)
        }
        (Some(mut d), None) if !has_class => {
            d.class = Class::Uniform;
            Ok(d)
        }
        (Some(d), _) => Ok(d),
        (None, Some(k)) => Ok(k),
        (None, None) => Err(format!("parameter \"{name}\" is not declared")),
    }
}

fn nums(v: &[f32]) -> Vec<Value> {
    v.iter().map(|&f| Value::Float(f)).collect()
}

/// A quadric: its numbers, then the parameter list (1 uniform, 4 varying/vertex values).
unsafe fn quadric(
    name: &'static str,
    args: &[f32],
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    let args = args.to_vec();
    with_builder(name, |b, span| {
        let p = plist(b, span, name, Counts::corners(4), None, n, tokens, parms);
        run(b, name, span, nums(&args), p);
    });
}

/// A shader request: its name, then constant parameters.
unsafe fn shader(
    request: &'static str,
    name: RtToken,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    with_builder(request, |b, span| {
        let Some(name) = cstr(name) else {
            return null_error(b, span, request, "the shader name");
        };
        let p = plist(b, span, request, SINGLE, None, n, tokens, parms);
        run(b, request, span, vec![Value::Str(name)], p);
    });
}

fn simple(name: &'static str, positional: Vec<Value>) {
    with_builder(name, |b, span| run(b, name, span, positional, Vec::new()));
}

// ---- the exported C functions (declared in include/ri.h) ----

/// Every RI function arbor exports, for messages.
pub const EXPORTED: &[&str] = &[
    "RiAttributeBegin",
    "RiAttributeEnd",
    "RiTransformBegin",
    "RiTransformEnd",
    "RiIdentity",
    "RiTransform",
    "RiConcatTransform",
    "RiTranslate",
    "RiRotate",
    "RiScale",
    "RiColor",
    "RiOpacity",
    "RiDeclare",
    "RiShadingRate",
    "RiSurfaceV",
    "RiDisplacementV",
    "RiAtmosphereV",
    "RiAttributeV",
    "RiSphereV",
    "RiConeV",
    "RiCylinderV",
    "RiDiskV",
    "RiTorusV",
    "RiParaboloidV",
    "RiHyperboloidV",
    "RiPolygonV",
    "RiPointsPolygonsV",
    "RiPatchV",
    "RiPointsV",
    "RiReadArchiveV",
    "RiProcedural",
    "RiProcDelayedReadArchive",
    "RiProcRunProgram",
    "RiProcDynamicLoad",
    "RiProcFree",
];

#[no_mangle]
pub extern "C" fn RiAttributeBegin() {
    simple("AttributeBegin", vec![]);
}

#[no_mangle]
pub extern "C" fn RiAttributeEnd() {
    simple("AttributeEnd", vec![]);
}

#[no_mangle]
pub extern "C" fn RiTransformBegin() {
    simple("TransformBegin", vec![]);
}

#[no_mangle]
pub extern "C" fn RiTransformEnd() {
    simple("TransformEnd", vec![]);
}

#[no_mangle]
pub extern "C" fn RiIdentity() {
    simple("Identity", vec![]);
}

/// `RiTransform(RtMatrix)`: 16 floats, row-major as in RIB.
#[no_mangle]
pub unsafe extern "C" fn RiTransform(m: *const f32) {
    matrix("Transform", m);
}

/// `RiConcatTransform(RtMatrix)`.
#[no_mangle]
pub unsafe extern "C" fn RiConcatTransform(m: *const f32) {
    matrix("ConcatTransform", m);
}

unsafe fn matrix(name: &'static str, m: *const f32) {
    let v = floats(m, 16);
    with_builder(name, |b, span| match v {
        Some(v) => run(b, name, span, vec![Value::FloatArray(v)], Vec::new()),
        None => null_error(b, span, name, "the matrix"),
    });
}

#[no_mangle]
pub extern "C" fn RiTranslate(dx: RtFloat, dy: RtFloat, dz: RtFloat) {
    simple("Translate", nums(&[dx, dy, dz]));
}

#[no_mangle]
pub extern "C" fn RiRotate(angle: RtFloat, dx: RtFloat, dy: RtFloat, dz: RtFloat) {
    simple("Rotate", nums(&[angle, dx, dy, dz]));
}

#[no_mangle]
pub extern "C" fn RiScale(sx: RtFloat, sy: RtFloat, sz: RtFloat) {
    simple("Scale", nums(&[sx, sy, sz]));
}

/// `RiColor(RtColor)`: as many floats as `ColorSamples` says (3 by default).
#[no_mangle]
pub unsafe extern "C" fn RiColor(c: *const f32) {
    color("Color", c);
}

/// `RiOpacity(RtColor)`.
#[no_mangle]
pub unsafe extern "C" fn RiOpacity(c: *const f32) {
    color("Opacity", c);
}

unsafe fn color(name: &'static str, c: *const f32) {
    with_builder(name, |b, span| {
        let n = b.colors.as_ref().map_or(3, |c| c.n);
        match floats(c, n) {
            Some(v) => run(b, name, span, vec![Value::FloatArray(v)], Vec::new()),
            None => null_error(b, span, name, "the colour"),
        }
    });
}

/// `RtToken RiDeclare(char *name, char *declaration)`: returns `name`.
#[no_mangle]
pub unsafe extern "C" fn RiDeclare(name: *const c_char, decl: *const c_char) -> RtToken {
    let (n, d) = (cstr(name), cstr(decl));
    with_builder("Declare", |b, span| match (n, d) {
        (Some(n), Some(d)) => run(
            b,
            "Declare",
            span,
            vec![Value::Str(n), Value::Str(d)],
            Vec::new(),
        ),
        _ => null_error(b, span, "Declare", "the name or declaration"),
    });
    name
}

#[no_mangle]
pub extern "C" fn RiShadingRate(size: RtFloat) {
    simple("ShadingRate", vec![Value::Float(size)]);
}

#[no_mangle]
pub unsafe extern "C" fn RiSurfaceV(
    name: RtToken,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    shader("Surface", name, n, tokens, parms);
}

#[no_mangle]
pub unsafe extern "C" fn RiDisplacementV(
    name: RtToken,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    shader("Displacement", name, n, tokens, parms);
}

#[no_mangle]
pub unsafe extern "C" fn RiAtmosphereV(
    name: RtToken,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    shader("Atmosphere", name, n, tokens, parms);
}

/// `RiAttributeV(name, n, tokens, parms)`: values declared as `"category:name"` or inline.
#[no_mangle]
pub unsafe extern "C" fn RiAttributeV(
    name: RtToken,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    with_builder("Attribute", |b, span| {
        let Some(cat) = cstr(name) else {
            return null_error(b, span, "Attribute", "the attribute name");
        };
        let p = plist(b, span, "Attribute", SINGLE, Some(&cat), n, tokens, parms);
        run(b, "Attribute", span, vec![Value::Str(cat)], p);
    });
}

#[no_mangle]
pub unsafe extern "C" fn RiSphereV(
    radius: RtFloat,
    zmin: RtFloat,
    zmax: RtFloat,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    quadric("Sphere", &[radius, zmin, zmax, thetamax], n, tokens, parms);
}

#[no_mangle]
pub unsafe extern "C" fn RiConeV(
    height: RtFloat,
    radius: RtFloat,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    quadric("Cone", &[height, radius, thetamax], n, tokens, parms);
}

#[no_mangle]
pub unsafe extern "C" fn RiCylinderV(
    radius: RtFloat,
    zmin: RtFloat,
    zmax: RtFloat,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    quadric(
        "Cylinder",
        &[radius, zmin, zmax, thetamax],
        n,
        tokens,
        parms,
    );
}

#[no_mangle]
pub unsafe extern "C" fn RiDiskV(
    height: RtFloat,
    radius: RtFloat,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    quadric("Disk", &[height, radius, thetamax], n, tokens, parms);
}

#[no_mangle]
pub unsafe extern "C" fn RiTorusV(
    majorradius: RtFloat,
    minorradius: RtFloat,
    phimin: RtFloat,
    phimax: RtFloat,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    quadric(
        "Torus",
        &[majorradius, minorradius, phimin, phimax, thetamax],
        n,
        tokens,
        parms,
    );
}

#[no_mangle]
pub unsafe extern "C" fn RiParaboloidV(
    rmax: RtFloat,
    zmin: RtFloat,
    zmax: RtFloat,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    quadric(
        "Paraboloid",
        &[rmax, zmin, zmax, thetamax],
        n,
        tokens,
        parms,
    );
}

/// `RiHyperboloidV(RtPoint point1, RtPoint point2, thetamax, …)`.
#[no_mangle]
pub unsafe extern "C" fn RiHyperboloidV(
    point1: *const f32,
    point2: *const f32,
    thetamax: RtFloat,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    match (floats(point1, 3), floats(point2, 3)) {
        (Some(a), Some(b)) => quadric(
            "Hyperboloid",
            &[a[0], a[1], a[2], b[0], b[1], b[2], thetamax],
            n,
            tokens,
            parms,
        ),
        _ => with_builder("Hyperboloid", |b, span| {
            null_error(b, span, "HyperboloidV", "a point")
        }),
    }
}

#[no_mangle]
pub unsafe extern "C" fn RiPolygonV(
    nvertices: RtInt,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    with_builder("Polygon", |b, span| {
        let nv = nvertices.max(0) as usize;
        let c = one_face(nv);
        let p = plist(b, span, "PolygonV", c, None, n, tokens, parms);
        run(b, "Polygon", span, vec![], p);
    });
}

#[no_mangle]
pub unsafe extern "C" fn RiPointsPolygonsV(
    npolys: RtInt,
    nverts: *const RtInt,
    verts: *const RtInt,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    with_builder("PointsPolygons", |b, span| {
        let np = npolys.max(0) as usize;
        if np > MAX_VALUES || (np > 0 && (nverts.is_null() || verts.is_null())) {
            return null_error(b, span, "PointsPolygonsV", "nverts or verts");
        }
        let counts: Vec<RtInt> = if np == 0 {
            Vec::new()
        } else {
            std::slice::from_raw_parts(nverts, np).to_vec()
        };
        let total: usize = counts.iter().map(|&c| c.max(0) as usize).sum();
        if total > MAX_VALUES {
            return null_error(b, span, "PointsPolygonsV", "nverts (too large)");
        }
        let idx: Vec<RtInt> = if total == 0 {
            Vec::new()
        } else {
            std::slice::from_raw_parts(verts, total).to_vec()
        };
        let nvertices = idx
            .iter()
            .map(|&i| i.max(0) as usize + 1)
            .max()
            .unwrap_or(0);
        let c = Counts {
            uniform: np,
            varying: nvertices,
            vertex: nvertices,
            facevarying: total,
            facevertex: total,
        };
        let p = plist(b, span, "PointsPolygonsV", c, None, n, tokens, parms);
        let ints = |v: &[RtInt]| Value::IntArray(v.iter().map(|&i| i as i64).collect());
        run(
            b,
            "PointsPolygons",
            span,
            vec![ints(&counts), ints(&idx)],
            p,
        );
    });
}

/// `RiPatchV("bilinear" | "bicubic", …)`: 4 or 16 vertices.
#[no_mangle]
pub unsafe extern "C" fn RiPatchV(
    kind: RtToken,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    with_builder("Patch", |b, span| {
        let Some(kind) = cstr(kind) else {
            return null_error(b, span, "PatchV", "the patch type");
        };
        let vertices = if kind == "bicubic" { 16 } else { 4 };
        let p = plist(
            b,
            span,
            "PatchV",
            Counts::corners(vertices),
            None,
            n,
            tokens,
            parms,
        );
        run(b, "Patch", span, vec![Value::Str(kind)], p);
    });
}

#[no_mangle]
pub unsafe extern "C" fn RiPointsV(
    npoints: RtInt,
    n: RtInt,
    tokens: *const RtToken,
    parms: *const RtPointer,
) {
    with_builder("Points", |b, span| {
        let np = npoints.max(0) as usize;
        let c = one_face(np);
        let p = plist(b, span, "PointsV", c, None, n, tokens, parms);
        run(b, "Points", span, vec![], p);
    });
}

/// `RiReadArchiveV(name, callback, …)`: the callback is not used.
#[no_mangle]
pub unsafe extern "C" fn RiReadArchiveV(
    name: RtToken,
    _callback: *const c_void,
    _n: RtInt,
    _tokens: *const RtToken,
    _parms: *const RtPointer,
) {
    let name = cstr(name);
    with_builder("ReadArchive", |b, span| match name {
        Some(n) => run(b, "ReadArchive", span, vec![Value::Str(n)], Vec::new()),
        None => null_error(b, span, "ReadArchiveV", "the archive name"),
    });
}

/// `RiProcedural(data, bound, subdivfunc, freefunc)`: `subdivfunc(data, detail)` runs now
/// unless the bound is out of view; `freefunc(data)` runs in any case.
#[no_mangle]
pub unsafe extern "C" fn RiProcedural(
    data: RtPointer,
    bound: *const f32,
    subdivide: Option<RtProcSubdivFunc>,
    free: Option<RtProcFreeFunc>,
) {
    let bound = floats(bound, 6);
    with_builder("Procedural", |b, span| {
        let Some(bound) = bound else {
            null_error(b, span, "Procedural", "the bound");
            if let Some(f) = free {
                call_c(b, span, || f(data));
            }
            return;
        };
        let bound = [bound[0], bound[1], bound[2], bound[3], bound[4], bound[5]];
        let wanted = b.world.is_some() || b.defining.is_some();
        if let (true, Some(sub)) = (wanted, subdivide) {
            if let Some(detail) = b.procedural_detail(&bound) {
                b.expand("RiProcedural".into(), span, |b| {
                    call_c(b, span, || sub(data, detail))
                });
            }
        }
        if let Some(f) = free {
            call_c(b, span, || f(data));
        }
    });
}

/// The strings of a `RtString[n]` procedural data block.
unsafe fn data_strings(data: RtPointer, n: usize) -> Option<Vec<String>> {
    if data.is_null() {
        return None;
    }
    let p = data as *const *const c_char;
    (0..n).map(|i| cstr(*p.add(i))).collect()
}

/// `RiProcDelayedReadArchive(data, detail)`: `data` is `RtString[1]`, the archive's name.
#[no_mangle]
pub unsafe extern "C" fn RiProcDelayedReadArchive(data: RtPointer, _detail: RtFloat) {
    let s = data_strings(data, 1);
    with_builder("ProcDelayedReadArchive", |b, span| match s {
        Some(s) => b.read_archive_named(&s[0], span, span),
        None => null_error(b, span, "ProcDelayedReadArchive", "the data block"),
    });
}

/// `RiProcRunProgram(data, detail)`: `data` is `RtString[2]`, the program and its data block.
#[no_mangle]
pub unsafe extern "C" fn RiProcRunProgram(data: RtPointer, detail: RtFloat) {
    let s = data_strings(data, 2);
    with_builder("ProcRunProgram", |b, span| match s {
        Some(s) => b.expand_program(&s[0], &s[1], detail, span, span),
        None => null_error(b, span, "ProcRunProgram", "the data block"),
    });
}

/// `RiProcDynamicLoad(data, detail)`: `data` is `RtString[2]`, the library and its parameters.
#[no_mangle]
pub unsafe extern "C" fn RiProcDynamicLoad(data: RtPointer, detail: RtFloat) {
    let s = data_strings(data, 2);
    with_builder("ProcDynamicLoad", |b, span| match s {
        Some(s) => b.expand_dynamic_load(&s[0], &s[1], detail, span, span),
        None => null_error(b, span, "ProcDynamicLoad", "the data block"),
    });
}

extern "C" {
    fn free(p: *mut c_void);
}

/// `RiProcFree(data)`: the C library's `free`.
#[no_mangle]
pub unsafe extern "C" fn RiProcFree(data: RtPointer) {
    if !data.is_null() {
        free(data);
    }
}

/// Makes sure every exported RI function is linked into the binary (the `arbor` binary calls
/// this once; build.rs exports `Ri*` from it).
pub fn keep_exports() {
    let table: [*const c_void; 35] = [
        RiAttributeBegin as *const c_void,
        RiAttributeEnd as *const c_void,
        RiTransformBegin as *const c_void,
        RiTransformEnd as *const c_void,
        RiIdentity as *const c_void,
        RiTransform as *const c_void,
        RiConcatTransform as *const c_void,
        RiTranslate as *const c_void,
        RiRotate as *const c_void,
        RiScale as *const c_void,
        RiColor as *const c_void,
        RiOpacity as *const c_void,
        RiDeclare as *const c_void,
        RiShadingRate as *const c_void,
        RiSurfaceV as *const c_void,
        RiDisplacementV as *const c_void,
        RiAtmosphereV as *const c_void,
        RiAttributeV as *const c_void,
        RiSphereV as *const c_void,
        RiConeV as *const c_void,
        RiCylinderV as *const c_void,
        RiDiskV as *const c_void,
        RiTorusV as *const c_void,
        RiParaboloidV as *const c_void,
        RiHyperboloidV as *const c_void,
        RiPolygonV as *const c_void,
        RiPointsPolygonsV as *const c_void,
        RiPatchV as *const c_void,
        RiPointsV as *const c_void,
        RiReadArchiveV as *const c_void,
        RiProcedural as *const c_void,
        RiProcDelayedReadArchive as *const c_void,
        RiProcRunProgram as *const c_void,
        RiProcDynamicLoad as *const c_void,
        RiProcFree as *const c_void,
    ];
    std::hint::black_box(&table);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_exported_name_is_kept() {
        assert_eq!(EXPORTED.len(), 35);
        keep_exports();
    }

    #[test]
    fn ri_calls_outside_a_dynamic_load_do_nothing() {
        RiAttributeBegin();
        unsafe { RiSphereV(1.0, -1.0, 1.0, 360.0, 0, std::ptr::null(), std::ptr::null()) };
    }
}
