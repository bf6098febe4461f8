//! The book headers of stdlib/include (Advanced RenderMan's project.h, reflections.h,
//! displace.h, pshad.h, raysphere.h, rayserver.h, oak.h, locillum.h, material.h; Texturing and
//! Modeling's DPProctext.h; the RenderMan Repository's tile.h, rclocillum.h, PSxforms.h,
//! PSshapes.h, raytrace.h): small shaders of our own that call each header's functions compile
//! with nothing but the library embedded in the binary, and give the values the books
//! describe (projections of known points, ray/sphere distances, displacement lengths measured
//! in a named space, shading-space points, the illumination models under a head-on light).

mod common;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::sl::library::{compile_source, stdlib_includes, CompileOptions};
use common::{film_mean, render_rib, scratch_dir};

/// Compiles `src` with the default options only (no -I, no search path): every include must
/// come from the embedded library.  Returns the rendered diagnostics on failure.
fn compile_embedded(src: &str) -> Result<usize, String> {
    match compile_report(src) {
        (n, _, false) if n > 0 => Ok(n),
        (_, rendered, _) => Err(rendered),
    }
}

/// Compiles `src` against the embedded headers: (programs, rendered diagnostics, errors?).
fn compile_report(src: &str) -> (usize, String, bool) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let progs = compile_source(
        "embedded.sl",
        src,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    (
        progs.len(),
        diags.render_plain(&sources),
        diags.has_errors(),
    )
}

/// One small shader per header, calling its main functions.
const USES: &[(&str, &str)] = &[
    (
        "project.h",
        r#"#include "project.h"
surface u(string map = ""; float mx[16] = {1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1};) {
    float ss, tt, ds, dt, a;
    ProjectTo2D("spherical", P, "shader", array_to_mx(mx), ss, tt, ds, dt);
    color c = ApplyColorTextureOver(Cs, map, "planar", P, "world", array_to_mx(mx), 0);
    float f = ApplyFloatTextureOver(0.5, map, "cylindrical", P, "object", array_to_mx(mx), 0);
    color g = GetColorTextureAndAlpha(map, "perspective", P, "shader", array_to_mx(mx), 0, 3, a);
    float h = GetFloatTextureAndAlpha(map, "st", P, "shader", array_to_mx(mx), 0, 3, a);
    spherical_projection(P, ss, tt, ds, dt);
    cylindrical_projection(P, ss, tt, ds, dt);
    Ci = c * f + g * h + ss + tt;
}"#,
    ),
    (
        "reflections.h",
        r#"#include "reflections.h"
surface u(float Kr = 1, blur = 0; DECLARE_DEFAULTED_ENVPARAMS;) {
    normal Nf = faceforward(normalize(N), I);
    vector R = reflect(normalize(I), Nf);
    float a, t0, t1;
    color c = SampleEnvironment(P, R, Kr, blur, ENVPARAMS)
            + Environment(envname, envspace, envrad, P, R, blur, a)
            + ReflMap(envname, P, blur, a) + RayTrace(P, R, Kr, blur, 0, 1, a);
    Ci = c + raysphere(P, R, 1, 1e-4, t0, t1);
}"#,
    ),
    (
        "displace.h",
        r#"#include "displace.h"
displacement u(float amp = 0.1, truedisp = 1; string space = "shader";) {
    N = Displace(normalize(N), space, amp, truedisp);
}"#,
    ),
    (
        "pshad.h",
        r#"#define USE_PREF 1
#include "pshad.h"
surface u(DEFAULT_PSHAD_PARAMS;) {
    GET_PSHAD;
    Ci = color(Pshad) * dPshad;
}"#,
    ),
    (
        "raysphere.h",
        r#"#include "raysphere.h"
surface u() { float t0, t1; Ci = raysphere(P, normalize(I), 2, 1e-4, t0, t1) * t0; }"#,
    ),
    (
        "rayserver.h",
        r#"#include "rayserver.h"
#include "reflections.h"
surface u(float Kr = 1; DECLARE_DEFAULTED_ENVPARAMS;) {
    color hc; float d; point ph, pm; normal nh; vector rm;
    float hit = fulltrace(P, normalize(I), hc, d, ph, nh, pm, rm);
    vector R = reflect(normalize(I), normalize(N));
    Ci = hc + hit + trace(worldp(P), worldv(R)) + SampleEnvironment(P, R, Kr, 0, ENVPARAMS)
       + raylevel() + isshadowray();
}"#,
    ),
    (
        "rayserver.h",
        r#"#include "rayserver.h"
light u() {
    vector axis = normalize(N);
    solar(-axis, 0) { Cl = rs_indirect(Ps, axis); }
}"#,
    ),
    (
        "raytrace.h",
        r#"#include "rayserver.h"
#include "raytrace.h"
surface u() { Ci = RayTrace(P, reflect(normalize(I), normalize(N)), 0, 1, 4); }"#,
    ),
    (
        "oak.h",
        r#"#include "pshad.h"
#include "oak.h"
surface u(DEFAULT_PSHAD_PARAMS;) {
    GET_PSHAD;
    Ci = oaktexture(Pshad, dPshad, 8, 0.5, 25, 1, 0.5, 0.1, 0.025, 0.1, 4, 1, 1);
}"#,
    ),
    (
        "locillum.h",
        r#"#include "locillum.h"
surface u() {
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Ci = LocIllumOrenNayar(Nf, V, 0.3) + LocIllumGlossy(Nf, V, 0.1, 0.5)
       + LocIllumWardAnisotropic(Nf, V, normalize(dPdu), 0.1, 0.3);
}"#,
    ),
    (
        "material.h",
        r#"#include "material.h"
surface u(float Ka = 1, Kd = 0.5, Ks = 0.5, Kr = 0.2, roughness = 0.1, blur = 0, twosided = 0;
          DECLARE_DEFAULTED_ENVPARAMS;) {
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Ci = MaterialPlastic(Nf, Cs, Ka, Kd, Ks, roughness) + MaterialMatte(Nf, Cs, Ka, Kd)
       + MaterialRoughMetal(Nf, Cs, Ka, Kd, Ks, roughness)
       + MaterialThinPlastic(Nf, V, Cs, Ka, Kd, 0.2, Ks, roughness)
       + MaterialShinyPlastic(Nf, Cs, Ka, Kd, Ks, roughness, Kr, blur, 1.5, twosided, ENVPARAMS)
       + MaterialShinyMetal(Nf, Cs, Ka, Kd, Ks, roughness, Kr, blur, twosided, ENVPARAMS)
       + MaterialClay(Nf, Cs, Ka, Kd, 0.3)
       + MaterialBrushedMetal(Nf, Cs, Ka, Kd, Ks, normalize(dPdu), 0.1, 0.3)
       + MaterialCeramic(Nf, Cs, Ka, Kd, Ks, roughness, 0.5)
       + MaterialGlass(Nf, Cs, Ka, Kd, Ks, roughness, Kr, 0, 1, 0, 1.5, color 1, 0, 1,
                       ENVPARAMS);
}"#,
    ),
    (
        "DPProctext.h",
        r#"#include "DPProctext.h"
surface u() { Ci = PULSE(0.2, 0.8, s) * boxstep(0, 1, t) * snoise(P); }"#,
    ),
    (
        "tile.h",
        r#"#include "tile.h"
surface u() {
    float sw, tw, so, to;
    Ci = tile(s, t, 0.25, 0.25, abs(Du(s) * du), abs(Dv(t) * dv), 0.1, 0.1, sw, tw, so, to);
}"#,
    ),
    (
        "rclocillum.h",
        r#"#include "rclocillum.h"
surface u() {
    normal Nf = faceforward(normalize(N), I);
    Ci = wrappedDiffuse(Nf, PI / 2) + glossy(Nf, normalize(I), 0.1, 0.5, 1, color 1);
}"#,
    ),
    (
        "PSxforms.h",
        r#"#include "PSxforms.h"
surface u() {
    float ss, tt;
    xform(0.5, 0.5, 0.1, 0.1, 0.3, s, t, ss, tt);
    Ci = xform(2, 0.1, s) + ss + tt + xscale(2, s) + xtranslate(0.5, t);
}"#,
    ),
    (
        "PSshapes.h",
        r#"#include "PSshapes.h"
surface u() {
    Ci = draw_circle(point(0.5, 0.5, 0), 0.3, 0.01, s, t)
       + draw_rect(0.1, 0.4, 0.1, 0.4, 0.01, s, t)
       + draw_line(point(0, 0, 0), point(1, 1, 0), 0.01, 0.02, s, t)
       + draw_cone(point(0.5, 0.5, 0), 0.4, 0.1, 0.1, s, t)
       + bary_triangle(point(0, 0, 0), point(1, 0, 0), point(0, 1, 0), 0.01, point(s, t, 0));
}"#,
    ),
    (
        "maps.h",
        r#"#include <maps.h>
displacement u(point maporigin = point "shader" (0, 0, 0), xaxis = point "shader" (1, 0, 0),
               yaxis = point "shader" (0, 1, 0), zaxis = point "shader" (0, 0, 1)) {
    float uu, vv, ss, tt;
    point PP = transform("shader", P);
    cylinmap(PP, uu, vv, maporigin, xaxis, yaxis, zaxis);
    sphermap(PP, uu, vv, maporigin, xaxis, yaxis, zaxis);
    planemap(PP, uu, vv, maporigin, xaxis, yaxis);
    automap(PP, uu, vv, maporigin, yaxis, ntransform("shader", N));
    float r = decalmap(PP, s, t, ss, tt, 1, maporigin, xaxis, yaxis, zaxis,
                       0, 0, 1, 0, 0, 1, 1, 1, N);
    P += normalize(N) * 0.01 * bilerp(uu, vv, 0, 1, 0, 1) * (ss + tt + r);
    N = calculatenormal(P);
}"#,
    ),
    (
        "normals.h",
        r#"#include "normals.h"
light u(float intensity = 1) {
    normal Ns = shadingnormal(N);
    illuminate(Ps + Ns) { Cl = intensity; }
}"#,
    ),
];

#[test]
fn every_book_header_is_embedded_and_its_functions_compile_from_anywhere() {
    let names: Vec<&str> = stdlib_includes().iter().map(|(n, _)| *n).collect();
    for (header, src) in USES {
        assert!(
            names.contains(header),
            "{header} is not embedded: {names:?}"
        );
        if let Err(log) = compile_embedded(src) {
            panic!("shader using {header} does not compile:\n{log}");
        }
        // Each header may be included twice (guards) and alone.
        let twice =
            format!("#include \"{header}\"\n#include \"{header}\"\nsurface t() {{ Ci = 1; }}\n");
        if let Err(log) = compile_embedded(&twice) {
            panic!("{header} included twice:\n{log}");
        }
    }
}

#[test]
fn headers_mix_in_any_order() {
    // The Advanced RenderMan headers with RManNotes and Peachey's macros, both orders.
    let sets = [
        ["rmannotes.h", "patterns.h", "noises.h", "material.h"],
        ["material.h", "noises.h", "patterns.h", "rmannotes.h"],
        ["reflectance.h", "locillum.h", "DPProctext.h", "oak.h"],
        ["locillum.h", "reflectance.h", "tile.h", "project.h"],
    ];
    for set in sets {
        let mut src: String = set.iter().map(|h| format!("#include \"{h}\"\n")).collect();
        src.push_str("surface t() { Ci = LocIllumOrenNayar(normalize(N), -normalize(I), 0.2); }\n");
        if let Err(log) = compile_embedded(&src) {
            panic!("{set:?}:\n{log}");
        }
        assert!(!log_has_warnings(&src), "{set:?} warns");
    }
}

fn log_has_warnings(src: &str) -> bool {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    compile_source(
        "w.sl",
        src,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    !diags.snapshot().is_empty()
}

/// Renders a full-frame square (object space [0, 2]², shader space = object space, world =
/// camera, seen head-on with a distant light along the view) with the surface shader `body`
/// and returns the film's mean colour.
fn probe(name: &str, body: &str, prims: &str) -> [f64; 3] {
    let dir = scratch_dir(&format!("stdlib_headers_{name}"));
    std::fs::write(dir.join(format!("{name}.sl")), body).unwrap();
    let rib = format!(
        r#"Format 8 8 1
PixelSamples 2 2
PixelFilter "box" 1 1
Projection "orthographic"
ScreenWindow 0 1 0 1
Display "probe" "file" "rgb"
WorldBegin
  LightSource "distantlight" 1 "intensity" 1 "from" [0 0 0] "to" [0 0 1]
  Translate 0 0 5
  Scale 0.5 0.5 0.5
  Surface "{name}"
  {prims}
WorldEnd
"#
    );
    film_mean(&render_rib(&rib, &[dir]))
}

const SQUARE: &str = r#"Polygon "P" [0 0 0  2 0 0  2 2 0  0 2 0] "st" [0 0  1 0  1 1  0 1]"#;

fn assert_near(got: [f64; 3], want: [f64; 3], tol: f64, what: &str) {
    for c in 0..3 {
        assert!(
            (got[c] - want[c]).abs() <= tol,
            "{what}: got {got:?}, want {want:?}"
        );
    }
}

#[test]
fn project_to_2d_gives_the_books_coordinates_for_known_points() {
    // Errors summed into red; each must be zero.
    let body = r#"#include "project.h"
float err2(float a, b, x, y) { return abs(a - x) + abs(b - y); }
surface projprobe() {
    matrix I4 = 1;
    float ss = 0, tt = 0, ds = 0, dt = 0;
    float e = 0;
    ProjectTo2D("planar", point "world" (0.3, 0.7, 2), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.3, 0.7);
    ProjectTo2D("perspective", point "world" (1, 2, 4), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.25, 0.5);
    /* spherical: longitude 0.5 on +x, 0.25 on +y, 0.75 on -y; latitude/pi */
    ProjectTo2D("spherical", point "world" (3, 0, 0), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.5, 0);
    ProjectTo2D("spherical", point "world" (0, 2, 0), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.25, 0);
    ProjectTo2D("spherical", point "world" (0, -2, 0), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.75, 0);
    ProjectTo2D("spherical", point "world" (0, 0, 5), "world", I4, ss, tt, ds, dt);
    e += abs(tt - 0.5);
    ProjectTo2D("spherical", point "world" (1, 0, 1), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.5, 0.25);
    /* cylindrical: the same longitude, height z */
    ProjectTo2D("cylindrical", point "world" (0, 3, 0.4), "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, 0.25, 0.4);
    /* xform from 16 floats, RenderMan order: a translation in the last row */
    float m[16] = {1,0,0,0, 0,1,0,0, 0,0,1,0, 0.5,0.25,0,1};
    ProjectTo2D("planar", point "world" (0.3, 0.7, 2), "world", array_to_mx(m), ss, tt, ds, dt);
    e += err2(ss, tt, 0.8, 0.95);
    /* "st" is the surface's own s, t */
    ProjectTo2D("st", P, "world", I4, ss, tt, ds, dt);
    e += err2(ss, tt, s, t);
    /* the seam of a spherical map is not a wide footprint */
    Ci = color(e, ds < 0.5 ? 0 : 1, 0);
}"#;
    assert_near(
        probe("projprobe", body, SQUARE),
        [0.0; 3],
        1e-5,
        "ProjectTo2D",
    );
}

#[test]
fn array_to_mx_round_trips_sixteen_floats() {
    let body = r#"#include "project.h"
surface mxprobe() {
    float m[16] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
    matrix M = array_to_mx(m);
    float e = 0, i, j;
    for (i = 0; i < 4; i += 1)
        for (j = 0; j < 4; j += 1)
            e += abs(comp(M, i, j) - m[4 * i + j]);
    Ci = e;
}"#;
    assert_near(probe("mxprobe", body, SQUARE), [0.0; 3], 0.0, "array_to_mx");
}

#[test]
fn raysphere_returns_the_hits_beyond_eps_nearest_first() {
    let body = r#"#include "raysphere.h"
surface rsprobe() {
    float t0 = -1, t1 = -1, e = 0;
    /* from outside: two hits at 4 and 6 */
    e += abs(raysphere(point (0, 0, -5), vector (0, 0, 1), 1, 1e-4, t0, t1) - 2);
    e += abs(t0 - 4) + abs(t1 - 6);
    /* from the centre: only the far hit, in t0 */
    e += abs(raysphere(point (0, 0, 0), vector (0, 1, 0), 2, 1e-4, t0, t1) - 1);
    e += abs(t0 - 2);
    /* pointing away from a sphere behind the ray: none */
    e += abs(raysphere(point (0, 0, 5), vector (0, 0, 1), 1, 1e-4, t0, t1));
    /* missing it sideways: none */
    e += abs(raysphere(point (3, 0, -5), vector (0, 0, 1), 1, 1e-4, t0, t1));
    Ci = e;
}"#;
    assert_near(probe("rsprobe", body, SQUARE), [0.0; 3], 1e-5, "raysphere");
}

#[test]
fn displace_measures_the_amplitude_in_the_named_space() {
    // Shader space is scaled by 0.5: 0.1 shader units are 0.05 current units.  Bumping only
    // (truedisp 0) leaves P; a flat plane keeps its normal either way.
    let body = r#"#include "displace.h"
surface dprobe(float truedisp = 1;) {
    point P0 = P;
    normal N0 = normalize(N);
    normal Nd = Displace(vector N0, "shader", 0.1, truedisp);
    Ci = color(length(P - P0), abs(Nd . N0), 0);
}"#;
    let pr = |td: &str| {
        let prims = SQUARE.replace(
            "Polygon",
            &format!("Surface \"dprobe\" \"truedisp\" {td}\n  Polygon"),
        );
        probe("dprobe", body, &prims)
    };
    assert_near(pr("1"), [0.05, 1.0, 0.0], 1e-4, "true displacement");
    assert_near(pr("0"), [0.0, 1.0, 0.0], 1e-4, "bump only");
    assert_near(pr("0.5"), [0.025, 1.0, 0.0], 1e-4, "half and half");
}

#[test]
fn get_pshad_is_the_point_in_the_named_space_times_the_frequency() {
    // The square spans [0, 2]² in object (= shader) space: the mean of Pshad is freq·(1, 1, 0).
    let plain = r#"#include "pshad.h"
surface psprobe(PSHAD_PARAMS("shader", 0.25);) {
    GET_PSHAD;
    Ci = color(Pshad);
}"#;
    assert_near(
        probe("psprobe", plain, SQUARE),
        [0.25, 0.25, 0.0],
        2e-3,
        "GET_PSHAD",
    );
    // "current" space is camera space here: x and y run over [0, 1], z is 5.
    let cur = SQUARE.replace(
        "Polygon",
        "Surface \"psprobe\" \"shadingspace\" \"current\" \"shadingfreq\" 2\n  Polygon",
    );
    assert_near(
        probe("psprobe", plain, &cur),
        [1.0, 1.0, 10.0],
        2e-3,
        "GET_PSHAD current",
    );

    // With USE_PREF: P when the primitive has no Pref, Pref (object space) when it has one.
    let pref = r#"#define USE_PREF 1
#include "pshad.h"
surface prprobe(DEFAULT_PSHAD_PARAMS;) {
    GET_PSHAD;
    Ci = color(Pshad) * 0.25;
}"#;
    assert_near(
        probe("prprobe", pref, SQUARE),
        [0.25, 0.25, 0.0],
        2e-3,
        "no Pref",
    );
    let with = format!(r#"{SQUARE} "vertex point Pref" [2 0 0  4 0 0  4 2 0  2 2 0]"#);
    assert_near(
        probe("prprobe", pref, &with),
        [0.75, 0.25, 0.0],
        2e-3,
        "Pref",
    );
}

#[test]
fn illumination_models_under_a_head_on_light() {
    // Light and eye along the normal: Oren-Nayar gives A = 1 - 0.5 s²/(s² + 0.33), Ward
    // 1/(4 ax ay), the glossy core 1, wrapped diffuse 1, Rudy Cortes' glossy Ks.
    let body = r#"#include "material.h"
#include "rclocillum.h"
surface ilprobe(float which = 0;) {
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    color c = 0;
    if (which == 0) c = LocIllumOrenNayar(Nf, V, 0.3);
    else if (which == 1) c = LocIllumOrenNayar(Nf, V, 0) - diffuse(Nf);
    else if (which == 2) c = LocIllumWardAnisotropic(Nf, V, normalize(dPdu), 0.5, 0.25);
    else if (which == 3) c = LocIllumGlossy(Nf, V, 0.1, 0.5);
    else if (which == 4) c = MaterialClay(Nf, color 1, 0, 1, 0) - MaterialMatte(Nf, color 1, 0, 1);
    else if (which == 5) c = wrappedDiffuse(Nf, PI / 2);
    else if (which == 6) c = glossy(Nf, normalize(I), 0.1, 0.5, 0.6, color (1, 0.5, 0.25));
    else if (which == 7) c = MaterialShinyMetal(Nf, color 1, 0, 0, 0, 0.1, 1, 0, 0, "", "world", 100, 0, 1);
    Ci = c;
}"#;
    let run = |w: u32| {
        let prims = SQUARE.replace(
            "Polygon",
            &format!("Surface \"ilprobe\" \"which\" {w}\n  Polygon"),
        );
        probe("ilprobe", body, &prims)
    };
    let a = 1.0 - 0.5 * 0.09 / (0.09 + 0.33);
    assert_near(run(0), [a; 3], 1e-4, "Oren-Nayar");
    assert_near(
        run(1),
        [0.0; 3],
        1e-4,
        "Oren-Nayar at roughness 0 is diffuse()",
    );
    assert_near(run(2), [2.0; 3], 1e-3, "Ward");
    assert_near(run(3), [1.0; 3], 1e-4, "glossy");
    assert_near(run(4), [0.0; 3], 1e-4, "clay at roughness 0 is matte");
    assert_near(run(5), [1.0; 3], 1e-4, "wrapped diffuse");
    assert_near(run(6), [0.6, 0.3, 0.15], 1e-4, "Cortes glossy");
    assert_near(
        run(7),
        [0.0; 3],
        1e-6,
        "shiny metal with no map and no rays",
    );
}

#[test]
fn oak_pattern_has_rings_and_grain_and_turns_off() {
    let body = r#"#include "pshad.h"
#include "oak.h"
surface oakprobe(float ringy = 1, grainy = 1; DEFAULT_PSHAD_PARAMS;) {
    GET_PSHAD;
    float w = oaktexture(Pshad, dPshad, 4, 0.5, 25, 0.5, 0.5, 0.1, 0.025, 0.1, 4, ringy, grainy);
    Ci = color(w, w * w, (w < 0 || w > 1) ? 1 : 0);
}"#;
    let on = probe("oakprobe", body, SQUARE);
    let var = on[1] - on[0] * on[0];
    assert!(on[0] > 0.05 && on[0] < 0.95 && var > 0.01, "oak: {on:?}");
    assert_eq!(on[2], 0.0, "oak leaves [0, 1]: {on:?}");
    let off = SQUARE.replace(
        "Polygon",
        "Surface \"oakprobe\" \"ringy\" 0 \"grainy\" 0\n  Polygon",
    );
    assert_near(probe("oakprobe", body, &off), [0.0; 3], 1e-6, "oak off");
}

#[test]
fn small_pattern_headers_give_their_documented_values() {
    let body = r#"#include "tile.h"
#include "DPProctext.h"
#include "PSxforms.h"
#include "PSshapes.h"
surface patprobe() {
    float e = 0, w, o;
    /* the integral of a period-1 band pattern, band 0.2 split between the tile's ends */
    e += abs(integratedpulse(0.05, 1, 0.2, w, o) - 0.05);
    e += abs(integratedpulse(0.5, 1, 0.2, w, o) - 0.1);
    e += abs(integratedpulse(0.95, 1, 0.2, w, o) - 0.15);
    e += abs(integratedpulse(3, 2, 0.2, w, o) - 0.6) + abs(w - 1) + abs(o - 0.5);
    float sw, tw, so, to;
    e += abs(tile(0.4, 0.45, 1, 1, 0.1, 0.1, 0.2, 0.2, sw, tw, so, to));       /* inside */
    e += abs(tile(0.96, 0.5, 1, 1, 0.02, 0.02, 0.2, 0.2, sw, tw, so, to) - 1); /* grout */
    e += abs(so - 0.96) + abs(sw);
    e += abs(PULSE(0.2, 0.4, 0.3) - 1) + abs(PULSE(0.2, 0.4, 0.5)) + abs(boxstep(0, 2, 0.5) - 0.25);
    e += abs(xform(2, 0, 0.5) - 0.5) + abs(xform(0.5, 0.1, 0.8) - 0.9);
    float ss, tt;
    xform(1, 1, 0, 0, PI / 2, 0.5, 1, ss, tt);
    e += abs(ss - 0) + abs(tt - 0.5);
    e += abs(tri_area(point (0, 0, 0), point (1, 0, 0), point (0, 1, 0)) - 0.5);
    e += abs(draw_circle(point (0.5, 0.5, 0), 0.3, 0.01, 0.5, 0.5) - 1);
    e += abs(draw_circle(point (0.5, 0.5, 0), 0.3, 0.01, 0.9, 0.9));
    e += abs(bary_triangle(point (0, 0, 0), point (1, 0, 0), point (0, 1, 0), 0.01, point (0.2, 0.2, 0)) - 1);
    Ci = e;
}"#;
    assert_near(probe("patprobe", body, SQUARE), [0.0; 3], 1e-5, "patterns");
}

#[test]
fn reflections_without_rays_or_maps_are_black_and_rays_miss_an_empty_sky() {
    // Nothing but the probe square: a ray towards the eye hits nothing, with or without ray
    // tracing, so fulltrace reports a miss and the bundle's hit fraction is 0.
    let body = r#"#include "rayserver.h"
#include "reflections.h"
#include "raytrace.h"
surface rtprobe() {
    vector R = -normalize(I);
    color hc = 1; float d = 0; point ph, pm; normal nh; vector rm;
    float hit = fulltrace(P, R, hc, d, ph, nh, pm, rm);
    float a = 1;
    color c = RayTrace(P, R, 1, 0, 0, 4, a);
    color e = SampleEnvironment(P, R, 1, 0, "", "world", 100, 0, 1);
    Ci = color(hit + a, (d > 1e10) ? 0 : 1, 0) + hc + c + e + RayTrace(P, R, 0, 1, 1);
}"#;
    assert_near(probe("rtprobe", body, SQUARE), [0.0; 3], 1e-6, "rays");
}

#[test]
fn prman_maps_give_the_documented_coordinates_for_known_points() {
    // PRMan's maps.h (its texmap, diaknurl, sinknurl and threads shaders include it):
    // cylindrical turns of a fraction in [0, 1) from the x axis and height along z,
    // spherical longitude the same and 0..1 from the south to the north pole, planar
    // distances along the axes, automap across the normal. Errors summed into red.
    let body = r#"#include <maps.h>
float err2(float a, b, x, y) { return abs(a - x) + abs(b - y); }
surface mapprobe() {
    point O = point "world" (0, 0, 0), X = point "world" (1, 0, 0);
    point Y = point "world" (0, 1, 0), Z = point "world" (0, 0, 1);
    float uu = 0, vv = 0, ss = 0, tt = 0, e = 0;
    cylinmap(point "world" (0, 2, 3), uu, vv, O, X, Y, Z);
    e += err2(uu, vv, 0.25, 3);
    cylinmap(point "world" (0, -2, -1), uu, vv, O, X, Y, Z);
    e += err2(uu, vv, 0.75, -1);
    cylinmap(point "world" (5, 0, 0.5), uu, vv, O, X, Y, Z);
    e += err2(uu, vv, 0, 0.5);
    sphermap(point "world" (-3, 0, 0), uu, vv, O, X, Y, Z);
    e += err2(uu, vv, 0.5, 0.5);
    sphermap(point "world" (0, 0, 2), uu, vv, O, X, Y, Z);
    e += abs(vv - 1);
    sphermap(point "world" (0, 0, -2), uu, vv, O, X, Y, Z);
    e += abs(vv);
    planemap(point "world" (0.3, 0.7, 9), uu, vv, O, X, Y);
    e += err2(uu, vv, 0.3, 0.7);
    /* a facet facing +z with +y up: uu along x, vv along y */
    automap(point "world" (0.4, 0.6, 0), uu, vv, O, Y, normal (0, 0, 1));
    e += err2(uu, vv, 0.4, 0.6);
    /* decalmap: planar through the corners (s, t) = (u, v), and the surface's own (s, t) */
    decalmap(point "world" (0.2, 0.9, 0), 0, 0, ss, tt, 0, O, X, Y, Z,
             0, 0, 1, 0, 0, 1, 1, 1, normal (0, 0, 1));
    e += err2(ss, tt, 0.2, 0.9);
    decalmap(P, 0.125, 0.625, ss, tt, 3, O, X, Y, Z, 0, 0, 1, 0, 0, 1, 1, 1, N);
    e += err2(ss, tt, 0.125, 0.625);
    e += abs(bilerp(0.5, 0.25, 0, 1, 2, 3) - 1);
    Ci = color(e, 1, 0);
    Oi = 1;
}"#;
    let got = probe("mapprobe", body, SQUARE);
    assert_near(got, [0.0, 1.0, 0.0], 1e-4, "maps.h coordinates");
}

#[test]
fn prman_shadingnormal_turns_a_two_sided_back_face_to_the_viewer() {
    // normals.h's shadingnormal: unit length, facing the viewer on a two-sided primitive.
    // The square is drawn in both orientations: from one side its N already faces the
    // camera (kept, green 1), from the other it is turned (green 0).
    let body = r#"#include "normals.h"
surface snprobe() {
    normal Ns = shadingnormal(N);
    Ci = color(Ns . normalize(-I) > 0 ? 1 : 0, Ns . normalize(N) > 0 ? 1 : 0, length(Ns));
    Oi = 1;
}"#;
    let front = probe("snprobe", body, &format!("Sides 2 {SQUARE}"));
    let back = probe(
        "snprobe",
        body,
        &format!("Sides 2 ReverseOrientation {SQUARE}"),
    );
    for got in [front, back] {
        assert!((got[0] - 1.0).abs() < 1e-4, "faces the viewer: {got:?}");
        assert!((got[2] - 1.0).abs() < 1e-4, "unit length: {got:?}");
    }
    assert!(
        (front[1] + back[1] - 1.0).abs() < 1e-4,
        "one orientation kept, the other turned: {front:?} {back:?}"
    );
}

#[test]
fn arbors_own_headers_raise_no_extension_warnings_in_user_shaders() {
    // PRMan's lights call normals.h's shadingnormal, which reads I in a light (a PRMan
    // extension arbor supports): the warning would point into arbor's own header, so it is
    // not shown. The same read written in the user's light still warns.
    let warnings = |src: &str| {
        let (n, rendered, _) = compile_report(src);
        assert_eq!(n, 1, "{rendered}");
        rendered
    };
    let via_header = warnings(
        "#include \"normals.h\"\nlight a() { normal Ns = shadingnormal(N); \
         illuminate(Ps + Ns) { Cl = 1; } }\n",
    );
    assert!(!via_header.contains("PRMan extension"), "{via_header}");
    let own = warnings("light b() { vector v = I; illuminate(Ps + v) { Cl = 1; } }\n");
    assert!(own.contains("`I` in a light shader"), "{own}");
}
