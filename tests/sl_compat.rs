//! Compatibility with shaders written for other RenderMan renderers: constructs found in the
//! published collections (written here in our own small shaders), every built-in giving the
//! same values for uniform and varying arguments, analytic checks of built-ins, IR snapshots
//! and rendered diagnostics of broken shaders.

mod common;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::shade::exec::{Env, Exec};
use arbor::shade::value::Slot;
use arbor::sl::ir::Program;
use arbor::sl::library::{compile_source, CompileOptions};
use glam::{Mat4, Vec3};

/// Compiles `text`; returns the programs, the rendered diagnostics and whether any is an error.
fn compile(text: &str) -> (Vec<Program>, String, bool) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let progs = compile_source(
        "test.sl",
        text,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    (progs, diags.render_plain(&sources), diags.has_errors())
}

fn compile_ok(text: &str) -> (Program, String) {
    let (mut progs, rendered, err) = compile(text);
    assert!(!err, "unexpected errors:\n{rendered}");
    assert_eq!(progs.len(), 1, "{rendered}");
    (progs.remove(0), rendered)
}

/// Runs a surface program over `n` points (s = i/n, t = 0.5, P on the z = 1 plane, N = +z,
/// I = +z) and returns Ci and Oi per point.
fn run(prog: &Program, n: usize) -> (Vec<Vec3>, Vec<Vec3>) {
    run_reporting(prog, n, &Diagnostics::new())
}

/// [`run`], with the shader's runtime warnings going to `diags`.
fn run_reporting(prog: &Program, n: usize, diags: &Diagnostics) -> (Vec<Vec3>, Vec<Vec3>) {
    let spaces = |_: &str| Some(Mat4::IDENTITY);
    let info = |_: &str, _: &str| None;
    let env = Env {
        nu: n,
        nv: 1,
        spaces: &spaces,
        lights: &[],
        flip_normals: false,
        near: 0.1,
        far: 100.0,
        shader_name: "test",
        diags,
        info: &info,
        textures: None,
        seed: 7,
        rays: None,
        cones: None,
        displacement_outputs: &[],
        surface_params: &[],
        atmosphere_params: &[],
    };
    let mut ex = Exec::new(prog, n, &env);
    ex.run_init();
    let s: Vec<f32> = (0..n).map(|i| i as f32 / n as f32).collect();
    let p: Vec<Vec3> = s.iter().map(|&x| Vec3::new(x, 0.5, 1.0)).collect();
    let binds: [(&str, Slot); 8] = [
        ("s", Slot::VF(s.clone())),
        ("t", Slot::VF(vec![0.5; n])),
        ("u", Slot::VF(s.clone())),
        ("v", Slot::VF(vec![0.5; n])),
        ("P", Slot::VT(p)),
        ("N", Slot::VT(vec![Vec3::Z; n])),
        ("Ng", Slot::VT(vec![Vec3::Z; n])),
        ("I", Slot::VT(vec![Vec3::Z; n])),
    ];
    for (name, v) in binds {
        if let Some(g) = prog.global(name) {
            ex.set(g.reg, v);
        }
    }
    for (name, v) in [("Cs", Vec3::ONE), ("Os", Vec3::ONE)] {
        if let Some(g) = prog.global(name) {
            ex.set(g.reg, Slot::T(v));
        }
    }
    ex.run_body();
    let get = |name: &str| -> Vec<Vec3> {
        // Globals the shader never touches are not in the program.
        match prog.global(name) {
            Some(g) => (0..n).map(|i| ex.regs[g.reg as usize].t().at(i)).collect(),
            None => vec![Vec3::ZERO; n],
        }
    };
    (get("Ci"), get("Oi"))
}

/// Evaluates a float expression of `X` once with a uniform `X` and once with a varying one.
fn uniform_and_varying(expr: &str, x: f32) -> (Vec<f32>, Vec<f32>) {
    let eu = expr.replace('X', "xu");
    let ev = expr.replace('X', "xv");
    let src = format!(
        "surface t(float xu = {x};) {{ varying float xv = xu; \
         Ci = color({eu}, 0, 0); Oi = color({ev}, 0, 0); }}"
    );
    let (prog, _) = compile_ok(&src);
    let (ci, oi) = run(&prog, 5);
    (
        ci.iter().map(|c| c.x).collect(),
        oi.iter().map(|c| c.x).collect(),
    )
}

/// Every built-in (RISpec 3.2 §15) that is deterministic, through float-valued wrappers.
const BUILTIN_EXPRS: &[&str] = &[
    "radians(X*90)",
    "degrees(X)",
    "sin(X)",
    "cos(X)",
    "tan(X)",
    "asin(X)",
    "acos(X)",
    "atan(X)",
    "atan(X, 0.5)",
    "pow(X, 2.5)",
    "exp(X)",
    "sqrt(X)",
    "inversesqrt(X)",
    "log(X)",
    "log(X, 2)",
    "mod(X*7, 2)",
    "abs(-X)",
    "sign(X-0.5)",
    "floor(X*10)",
    "ceil(X*10)",
    "round(X*10)",
    "min(X, 0.2)",
    "max(X, 0.2, 0.3)",
    "clamp(X, 0.1, 0.2)",
    "mix(0, 10, X)",
    "step(0.3, X)",
    "smoothstep(0, 1, X)",
    "filterstep(0.3, X)",
    "filterstep(0.3, X, X+0.1)",
    "spline(X, 0, 1, 2, 3, 4, 5)",
    "spline(\"linear\", X, 0, 1, 2, 3)",
    "spline(\"bspline\", X, 0, 1, 4, 9, 16)",
    "spline(\"bezier\", X, 0, 1, 4, 9)",
    "spline(\"hermite\", X, 0, 1, 4, 9)",
    "comp(spline(X, color 0, color 1, color 2, color 3), 1)",
    "Du(X) + Dv(X) + Deriv(X, X)",
    "noise(X*3)",
    "noise(X*3, 0.25)",
    "noise(point(X, 1, 2))",
    "noise(point(X, 1, 2), X)",
    "comp(color noise(X*3), 2)",
    "ycomp(vector noise(X, 2))",
    "pnoise(X*5, 4)",
    "pnoise(point(X*5, 1, 2), point(4, 4, 4))",
    "cellnoise(X*9)",
    "comp(color cellnoise(point(X*9, 1, 2)), 0)",
    "xcomp(vector(X, 1, 2)) + ycomp(point(1, X, 2)) + zcomp(normal(1, 2, X))",
    "length(vector(X, 1, 2))",
    "xcomp(normalize(vector(X, 1, 2)))",
    "distance(point(X, 0, 0), point(0, 1, 0))",
    "ptlined(point(0, 0, 0), point(1, 0, 0), point(X, 1, 0))",
    "ycomp(rotate(point(1, 0, 0), X, point(0, 0, 0), point(0, 0, 1)))",
    "zcomp(faceforward(vector(0, 0, X-0.5), vector(0, 0, 1)))",
    "xcomp(reflect(vector(X, -1, 0), vector(0, 1, 0)))",
    "xcomp(refract(normalize(vector(X, -1, 0)), vector(0, 1, 0), 0.7))",
    "comp(ctransform(\"hsv\", color(X, 0.5, 0.2)), 0)",
    "comp(ctransform(\"hsl\", \"rgb\", color(X, 0.5, 0.5)), 1)",
    "comp(ctransform(\"xyz\", color(X, 0.5, 0.5)), 1)",
    "comp(mix(color 0, color 1, X), 0)",
    "comp(mix(color 0, color 1, color(X, 0, 0)), 0)",
    "comp(clamp(color(X), color(0.1), color(0.2)), 0)",
    "comp(max(color(X), color(0.5)), 0) + xcomp(min(point(X), point(0.2)))",
    "determinant(scale(matrix 1, point(X, 2, 3)))",
    "comp(rotate(matrix 1, X, vector(0, 0, 1)), 0, 1)",
    "comp(translate(matrix 1, vector(X, 0, 0)), 3, 0)",
    "xcomp(transform(scale(matrix 1, point(2, 2, 2)), point(X, 0, 0)))",
    "xcomp(vtransform(\"world\", vector(X, 0, 0)))",
    "xcomp(ntransform(\"object\", \"world\", normal(X, 0, 1)))",
    "xcomp(transform(\"world\", point(X, 0, 0)))",
    "comp(matrix \"world\" X, 0, 0)",
    "match(\"b+\", \"abbc\") + X",
];

#[test]
fn every_builtin_gives_the_same_values_for_uniform_and_varying_arguments() {
    let mut failures = Vec::new();
    for expr in BUILTIN_EXPRS {
        let (u, v) = uniform_and_varying(expr, 0.37);
        for (a, b) in u.iter().zip(&v) {
            let tol = 1e-5 * a.abs().max(1.0);
            if (a - b).abs() > tol || a.is_nan() != b.is_nan() {
                failures.push(format!("{expr}: uniform {a} vs varying {b}"));
                break;
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

fn value(expr: &str) -> f32 {
    uniform_and_varying(expr, 0.0).0[0]
}

#[test]
fn analytic_values_of_builtins() {
    assert!((value("smoothstep(0, 1, 0.25)") - 0.15625).abs() < 1e-6);
    assert!((value("smoothstep(0, 2, 1)") - 0.5).abs() < 1e-6);
    // Catmull-Rom passes through the interior knots.
    assert!((value("spline(1.0/3, 0, 1, 2, 3, 4, 5)") - 2.0).abs() < 1e-5);
    assert!((value("spline(\"linear\", 0.5, 9, 0, 10, 9)") - 5.0).abs() < 1e-5);
    assert!((value("mod(-1, 3)") - 2.0).abs() < 1e-6);
    assert!((value("determinant(scale(matrix 1, point(2, 3, 4)))") - 24.0).abs() < 1e-4);
    assert!((value("comp(translate(matrix 1, vector(5, 0, 0)), 3, 0)") - 5.0).abs() < 1e-6);
    // A quarter turn about z takes x to y.
    assert!(
        (value("ycomp(transform(rotate(matrix 1, PI/2, vector(0, 0, 1)), point(1, 0, 0)))") - 1.0)
            .abs()
            < 1e-5
    );
}

#[test]
fn fresnel_at_normal_incidence_gives_kr_004_for_glass() {
    let src = "surface t() { float kr, kt; vector R, T; \
               fresnel(vector(0, 0, -1), normal(0, 0, 1), 1/1.5, kr, kt, R, T); \
               Ci = color(kr, kt, zcomp(R)); \
               fresnel(vector(0, 0, -1), normal(0, 0, 1), 1/1.5, kr, kt); Oi = color(kr); }";
    let (prog, _) = compile_ok(src);
    let (ci, oi) = run(&prog, 3);
    assert!((ci[0].x - 0.04).abs() < 1e-4, "Kr = {}", ci[0].x);
    assert!((ci[0].x + ci[0].y - 1.0).abs() < 1e-4);
    assert!((ci[0].z - 1.0).abs() < 1e-5, "R reflects back");
    assert!((oi[0].x - 0.04).abs() < 1e-4);
}

#[test]
fn colour_space_round_trips() {
    for space in ["hsv", "hsl", "xyz", "xyY", "YIQ", "rgb"] {
        let src = format!(
            "surface t() {{ color c = color(0.8, 0.3, 0.1); \
             Ci = ctransform(\"{space}\", \"rgb\", ctransform(\"{space}\", c)); }}"
        );
        let (prog, _) = compile_ok(&src);
        let (ci, _) = run(&prog, 2);
        let d = (ci[0] - Vec3::new(0.8, 0.3, 0.1)).abs().max_element();
        assert!(d < 1e-4, "{space}: {:?}", ci[0]);
    }
    // A pure hue: red is hue 0, full saturation and value.
    let (prog, _) = compile_ok("surface t() { Ci = ctransform(\"hsv\", color(1, 0, 0)); }");
    let (ci, _) = run(&prog, 1);
    assert!((ci[0] - Vec3::new(0.0, 1.0, 1.0)).abs().max_element() < 1e-5);
}

// ---- constructs found in real shader collections (our own minimal versions) ----

/// A uniform loop counter in a function that is inlined inside a varying loop stays legal:
/// its whole lifetime is under the same mask (the Worley-noise helpers of noise headers).
#[test]
fn uniform_locals_of_functions_inlined_in_varying_loops() {
    let src = "float cells(float x) { uniform float i; float best = 10; \
               for (i = -1; i <= 1; i += 1) best = min(best, abs(x - i)); return best; } \
               surface t() { float d = 0, acc = 0; \
               while (d < s) { acc += cells(d); d += 0.25; } Ci = acc; }";
    let (prog, rendered) = compile_ok(src);
    assert!(!rendered.contains("warning"), "{rendered}");
    let (ci, _) = run(&prog, 4);
    // s = 0.5: d = 0, 0.25 -> cells = 0 + 0.25
    assert!((ci[2].x - 0.25).abs() < 1e-6, "{:?}", ci);
    assert_eq!(ci[0].x, 0.0);
}

/// An explicitly uniform local assigned under varying control flow (BMRT-era fBm loops with
/// a varying exit test) is demoted to varying with a warning rather than rejected.
#[test]
fn explicit_uniform_assigned_under_varying_control_is_demoted_with_a_warning() {
    let src = "surface t() { uniform float i; float sum = 0; \
               for (i = 0; i < 4 && sum < s; i += 1) sum += 0.1; Ci = i; }";
    let (prog, rendered) = compile_ok(src);
    assert!(rendered.contains("sl::detail"), "{rendered}");
    let (ci, _) = run(&prog, 5);
    // s = 0, .2, .4, .6, .8 -> iterations 0, 2, 4 (sum reaches .2 after 2; .4 capped at 4)
    let want = [0.0, 2.0, 4.0, 4.0, 4.0];
    for (c, w) in ci.iter().zip(want) {
        assert!((c.x - w).abs() < 1e-6, "{:?}", ci);
    }
}

/// Surface shaders may move P before `calculatenormal` (Advanced RenderMan's `Displace`).
#[test]
fn surface_shaders_may_assign_p() {
    let src = "surface t() { P += normalize(N) * 0.5; Ci = color(zcomp(P)); }";
    let (prog, _) = compile_ok(src);
    let (ci, _) = run(&prog, 2);
    assert!((ci[0].x - 1.5).abs() < 1e-6);
}

/// Atmosphere shaders gather in-scattered light with `illuminance`, also in functions.
#[test]
fn volume_shaders_read_cl_inside_illuminance() {
    let src = "color gather_light(point p) { color c = 0; \
               illuminance (p) { extern color Cl; c += Cl; } return c; } \
               volume t() { Ci += gather_light(P); }";
    compile_ok(src);
    let (_, rendered, err) = compile("volume t() { Ci = Cl; }");
    assert!(
        err && rendered.contains("only defined inside `illuminance`"),
        "{rendered}"
    );
}

#[test]
fn raylevel_is_zero_for_camera_rays() {
    let (prog, _) = compile_ok("surface t() { Ci = raylevel() + isshadowray() + 1; }");
    let (ci, _) = run(&prog, 1);
    assert_eq!(ci[0].x, 1.0);
}

// ---- IR and diagnostics snapshots ----

#[test]
fn ir_listing_snapshot_of_a_small_shader() {
    let (prog, _) = compile_ok(
        "surface stripes(float freq = 4; color c2 = color(1, 0, 0)) { \
         float m = mod(s * freq, 1); \
         if (m < 0.5) Ci = Cs; else Ci = c2; }",
    );
    insta::assert_snapshot!(format!("{prog}"));
}

#[test]
fn detail_inference_snapshot() {
    // `k` only ever holds uniform values; `m` depends on s; `j` is a uniform loop counter.
    let (prog, _) = compile_ok(
        "surface d(float f = 2) { float k = f * 2; float m = s * k; float j; \
         float acc = 0; for (j = 0; j < k; j += 1) acc += m; Ci = acc; }",
    );
    insta::assert_snapshot!(format!("{prog}"));
}

#[test]
fn diagnostics_of_broken_shaders() {
    let cases = [
        "#include \"no_such_header.h\"\nsurface a() { Ci = 1; }\n",
        // Not near any known name: a DSO shadeop, one warning, and it returns 0.
        "surface b() { Ci = undefined_fn(1); }\n",
        "surface c() { uniform float x = s; Ci = comp(x); }\n",
        "imager d() { Ci = N; }\n",
        "surface e() { float x = 1 Ci = x; }\n",
    ];
    let mut all = String::new();
    for text in cases {
        let (_, rendered, err) = compile(text);
        assert!(
            err || rendered.contains("warning") || rendered.contains('⚠'),
            "{text}"
        );
        all.push_str(&rendered);
        all.push_str("\n----\n");
    }
    insta::assert_snapshot!(all);
}

/// `var = expr` hands the temporary's buffer over (no copy) only where that is invisible:
/// every point running, the temporary read once, in the block that computed it.
#[test]
fn assignments_from_temporaries_move_only_where_safe() {
    let (prog, _) = compile_ok(
        r#"surface t() {
            color a = color(s, 0, 0);          /* top level: movable */
            color b = 0;
            color k = color(0, s * 2, 0);      /* computed once, used inside the loop */
            float i;
            for (i = 0; i < 3; i += 1) {
                b = k;                          /* a variable: copied every iteration */
                b += color(0, 0, 1);
            }
            if (s > 0.5) {
                a = color(1, 1, 1);             /* masked: copies the running points */
            }
            Ci = a + b;
            Oi = 1;
        }"#,
    );
    assert!(
        prog.movable.iter().any(|&m| m),
        "the top-level assignment should move:\n{prog}"
    );
    let (ci, _) = run(&prog, 8);
    for (i, c) in ci.iter().enumerate() {
        let s = i as f32 / 8.0;
        let a = if s > 0.5 {
            Vec3::ONE
        } else {
            Vec3::new(s, 0.0, 0.0)
        };
        let b = Vec3::new(0.0, s * 2.0, 1.0);
        assert!(
            (*c - (a + b)).length() < 1e-6,
            "point {i}: {c} vs {}",
            a + b
        );
    }
}

/// `break` inside a function counts only the function's own loops: one in a function called
/// from a loop (with no loop of its own) is an error, one in the function's loop is fine.
#[test]
fn break_in_a_function_does_not_reach_the_callers_loop() {
    let (_, rendered, err) = compile(
        r#"float f(float x) { if (x > 0.5) break; return x; }
        surface brk() {
            float i, a = 0;
            for (i = 0; i < 4; i += 1) { a += f(s); }
            Ci = a;
        }"#,
    );
    assert!(err, "expected an error:\n{rendered}");
    assert!(
        rendered.contains("sl::control") && rendered.contains("function `f`"),
        "{rendered}"
    );
    let (prog, _) = compile_ok(
        r#"float g(float x) {
            float k, acc = 0;
            for (k = 0; k < 10; k += 1) { if (k >= x) break; acc += 1; }
            return acc;
        }
        surface ok() {
            float i, a = 0;
            for (i = 0; i < 2; i += 1) { a += g(3); }
            Ci = a;
            Oi = 1;
        }"#,
    );
    let (ci, _) = run(&prog, 4);
    assert!(ci.iter().all(|c| (c.x - 6.0).abs() < 1e-6), "{ci:?}");
}

/// `clamp(x, lo, hi)` with `lo > hi` behaves as the C macro of Aqsis and BMRT
/// (`x < lo ? lo : x > hi ? hi : x`), and a smoke-style marching loop that steps by
/// `clamp(ss, 0.005, end - d)` reaches its end instead of stepping by zero forever.
#[test]
fn clamp_with_crossed_bounds_keeps_marching_loops_moving() {
    assert_eq!(value("clamp(0.001, 0.005, 0.0)"), 0.005);
    assert_eq!(value("clamp(0.25, 0.005, 0.001)"), 0.001);
    assert_eq!(value("clamp(0.5, 0, 1)"), 0.5);
    assert_eq!(
        value("comp(clamp(color(0.001), color(0.005), color(0)), 1)"),
        0.005
    );
    let (prog, _) = compile_ok(
        "volume march(float stepsize = 0.25; float end = 3.7;) {
             float d = 0.1, ss = min(stepsize, end - d), steps = 0;
             while (d <= end) { ss = clamp(ss, 0.005, end - d); d += ss; steps += 1; }
             Ci = color(steps, d, 0);
         }",
    );
    let (ci, _) = run(&prog, 3);
    assert!(ci[0].x > 10.0 && ci[0].x < 40.0, "steps {}", ci[0].x);
    assert!(ci[0].y > 3.7 && ci[0].y < 3.71, "d {}", ci[0].y);
}

/// A function declared to return `uniform` that updates an outer uniform under varying control
/// flow (Advanced RenderMan's lensflare `urand()` called inside `illuminance`) compiles: the
/// outer variable and the return value are demoted to varying with warnings, not rejected.
#[test]
fn uniform_function_updating_a_demoted_uniform_compiles() {
    let src = "surface t() { uniform float n = 0;
                 uniform float next() { extern uniform float n; n += 1; return n * 10; }
                 float x = 0;
                 if (s > 0.3) { uniform float y = next(); x = y + next(); }
                 Ci = x; }";
    let (prog, rendered) = compile_ok(src);
    assert!(
        rendered.contains("declared to return a uniform value"),
        "{rendered}"
    );
    let (ci, _) = run(&prog, 5);
    let want = [0.0, 0.0, 30.0, 30.0, 30.0];
    for (c, w) in ci.iter().zip(want) {
        assert!((c.x - w).abs() < 1e-5, "{:?}", ci);
    }
}

/// `specularbrdf` (and so `specular`) use the exponent 8/roughness of PRMan, BMRT and Aqsis,
/// not RISpec's reference 1/roughness: H at 22.5° from N with roughness 0.5 gives cos^16.
#[test]
fn specular_exponent_is_eight_over_roughness() {
    let v = value(
        "comp(specularbrdf(normalize(vector(1, 0, 1)), normal(0, 0, 1), vector(0, 0, 1), 0.5), 0)",
    );
    let want = (22.5f32.to_radians().cos()).powf(16.0);
    assert!((v - want).abs() < 1e-4, "{v} vs {want}");
}

/// BMRT's `Option "render" "prmanspecular" [0]` switches `specular()` and `specularbrdf` to
/// RISpec's reference exponent 1/roughness; without it the tight 8/roughness stays. A distant
/// light at 45° over a plane seen head-on puts H at 22.5° from N everywhere: with roughness 0.5
/// the highlight is cos^16 (tight) or cos^2 (RISpec), in every pixel.
#[test]
fn prmanspecular_zero_gives_rispec_highlights() {
    let dir = common::scratch_dir("sl_compat_prmanspecular");
    std::fs::write(
        dir.join("specprobe.sl"),
        "surface specprobe(float brdf = 0) {\n\
         normal Nf = faceforward(normalize(N), I);\n\
         vector V = -normalize(I);\n\
         Oi = 1;\n\
         if (brdf != 0) Ci = specularbrdf(normalize(vector(1, 0, -1)), Nf, V, 0.5);\n\
         else Ci = specular(Nf, V, 0.5);\n\
         }\n",
    )
    .unwrap();
    let cos = 22.5f32.to_radians().cos();
    for (option, exponent) in [
        ("", 16.0),
        ("Option \"render\" \"prmanspecular\" [0]\n", 2.0),
    ] {
        for brdf in [0, 1] {
            let rib = format!(
                "{option}Format 8 8 1\nPixelSamples 1 1\nPixelFilter \"box\" 1 1\n\
                 Projection \"orthographic\"\nScreenWindow -1 1 -1 1\nTranslate 0 0 5\n\
                 WorldBegin\nLightSource \"distantlight\" 1 \"from\" [1 0 -1] \"to\" [0 0 0]\n\
                 Surface \"specprobe\" \"brdf\" {brdf}\n\
                 Patch \"bilinear\" \"P\" [-2 -2 0  2 -2 0  -2 2 0  2 2 0]\nWorldEnd\n"
            );
            let film = common::render_rib(&rib, &[dir.clone()]);
            let rgb = common::film_rgb(&film);
            let want = cos.powf(exponent);
            for v in rgb {
                assert!(
                    (v - want).abs() < 1e-3,
                    "{option:?} brdf {brdf}: {v} vs {want}"
                );
            }
        }
    }
}

/// BMRT moved points only for primitives with `Attribute "render" "truedisplacement" [1]`;
/// otherwise its displacement shaders were bump maps, and its scenes declare no
/// `displacementbound` (PRMan needs one to move points). A sphere of radius 1 pushed out by
/// 0.5 covers π·1.5² or π·1² of the frame: displaced with a bound and without the attribute
/// anywhere (PRMan, RISpec) or with the attribute at 1 (with or without a bound); bump mapped
/// with it at 0, without it in a scene where another primitive sets it (a BMRT scene), or with
/// neither the attribute nor a bound.
#[test]
fn bmrt_truedisplacement_decides_between_displacement_and_bump() {
    let dir = common::scratch_dir("sl_compat_truedisp");
    std::fs::write(
        dir.join("pushout.sl"),
        "displacement pushout() { P += 0.5 * normalize(N); N = calculatenormal(P); }\n",
    )
    .unwrap();
    let bound = "Attribute \"displacementbound\" \"sphere\" [0.5]\n";
    let sphere = |attr: &str, bound: &str| {
        format!(
            "AttributeBegin\n{attr}Displacement \"pushout\"\n\
             {bound}Sphere 1 -1 1 360\nAttributeEnd\n"
        )
    };
    // Off screen: only its attribute matters.
    let elsewhere = "AttributeBegin\nTranslate 20 0 0\n\
                     Attribute \"render\" \"truedisplacement\" [1]\nSphere 1 -1 1 360\nAttributeEnd\n";
    let on = "Attribute \"render\" \"truedisplacement\" [1]\n";
    let off = "Attribute \"render\" \"truedisplacement\" [0]\n";
    for (world, radius) in [
        (sphere("", bound), 1.5),
        (sphere(on, bound), 1.5),
        (sphere(on, ""), 1.5),
        (sphere(off, bound), 1.0),
        (format!("{elsewhere}{}", sphere("", bound)), 1.0),
        (sphere("", ""), 1.0),
    ] {
        let rib = format!(
            "Format 40 40 1\nPixelSamples 2 2\nProjection \"orthographic\"\n\
             ScreenWindow -2 2 -2 2\nTranslate 0 0 5\nWorldBegin\n{world}WorldEnd\n"
        );
        let film = common::render_rib(&rib, &[dir.clone()]);
        let a = film.channel("a").expect("alpha");
        let mut covered = 0f32;
        for y in 0..film.height {
            for x in 0..film.width {
                covered += film.pixel(x, y)[a] / 100.0;
            }
        }
        let want = std::f32::consts::PI * radius * radius;
        assert!(
            (covered - want).abs() < 0.05 * want,
            "{world}: covered {covered} units², want {want}"
        );
    }
}

/// A primitive that names no surface shader gets RISpec's `defaultsurface` (`Ka + Kd·|N·I|`,
/// whatever the lights), except in a frame written for BMRT (a displacement without a bound or
/// `truedisplacement`), where it gets `plastic`, as BMRT's pictures of such primitives show.
/// Face-on under a half-intensity light from the eye: defaultsurface gives 0.2 + 0.8 = 1,
/// plastic at most Kd·0.5 + Ks·0.5 = 0.5 (its narrow highlight is blurred by the pixel filter
/// to about 0.37).
#[test]
fn bmrt_scene_default_surface_is_plastic() {
    let dir = common::scratch_dir("sl_compat_bmrt_default");
    std::fs::write(dir.join("keep.sl"), "displacement keep() { N = N; }\n").unwrap();
    let defaultsurface = 0.97..1.01;
    let plastic = 0.3..0.5;
    for (attrs, want) in [
        ("", &defaultsurface),
        (
            "Displacement \"keep\"\nAttribute \"displacementbound\" \"sphere\" [0.1]\n",
            &defaultsurface,
        ),
        ("Displacement \"keep\"\n", &plastic),
        (
            "Attribute \"render\" \"truedisplacement\" [1]\nDisplacement \"keep\"\n",
            &plastic,
        ),
    ] {
        let rib = format!(
            "Format 21 21 1\nPixelSamples 2 2\nProjection \"orthographic\"\n\
             ScreenWindow -2 2 -2 2\nTranslate 0 0 5\nWorldBegin\n\
             LightSource \"distantlight\" 1 \"intensity\" 0.5 \"from\" [0 0 -5] \"to\" [0 0 0]\n\
             AttributeBegin\n{attrs}Sphere 1 -1 1 360\nAttributeEnd\nWorldEnd\n"
        );
        let film = common::render_rib(&rib, &[dir.clone()]);
        let r = film.channel("r").expect("red");
        let centre = film.pixel(10, 10)[r];
        assert!(
            want.contains(&centre),
            "{attrs}: centre {centre}, want {want:?}"
        );
    }
}

/// `Deriv(P, s)` where s changes only along u: Dv(s) is rounding noise (the patch's s is
/// interpolated from non-representable corner values), and dividing by it must not blow up.
/// dP/ds is the patch width over the s range everywhere: 4 / 0.6.
#[test]
fn deriv_ignores_a_direction_den_does_not_change_along() {
    let dir = common::scratch_dir("sl_compat_deriv");
    std::fs::write(
        dir.join("derivs.sl"),
        "surface derivs() { Oi = 1; Ci = length(Deriv(P, s)) * 0.6 / 8; }",
    )
    .unwrap();
    let rib = "Format 24 24 1\nPixelSamples 1 1\nPixelFilter \"box\" 1 1\n\
               Projection \"orthographic\"\nScreenWindow -2 2 -2 2\nTranslate 0 0 5\n\
               Rotate 13 0 0 1\nWorldBegin\nSurface \"derivs\"\n\
               Patch \"bilinear\" \"P\" [-2 -2 0  2 -2 0  -2 2 0  2 2 0] \
               \"st\" [0.1 0.3  0.7 0.3  0.1 0.9  0.7 0.9]\nWorldEnd\n";
    let film = common::render_rib(rib, &[dir]);
    let rgb = common::film_rgb(&film);
    // Pixels fully on the (rotated) patch read 0.5.
    let w = 24;
    for y in 8..16 {
        for x in 8..16 {
            let v = rgb[(y * w + x) * 3];
            assert!((v - 0.5).abs() < 1e-3, "pixel {x},{y}: {v}");
        }
    }
}

#[test]
fn an_ambiguous_call_inside_arithmetic_is_a_float_whatever_the_assignment() {
    // LGParquetPlank's `woodcolor *= (1 - plankvary/2 + plankvary * noise(whichplank + 0.5))`:
    // the colour being assigned does not make that `noise` a colour (PRMan and Aqsis give every
    // plank one grey factor, not a different noise per channel).
    let (prog, _) = compile_ok(
        "surface t() { color c = 1; float k = 0.8; \
         c *= (1 - k/2 + k * noise(s * 7.3 + 0.5)); \
         Ci = c; Oi = 1; }",
    );
    let (ci, _) = run(&prog, 16);
    let mut spread = 0f32;
    for c in &ci {
        assert!(
            (c.x - c.y).abs() < 1e-6 && (c.y - c.z).abs() < 1e-6,
            "{c:?}"
        );
        spread = spread.max((c.x - ci[0].x).abs());
    }
    assert!(spread > 0.01, "the noise should vary along s: {ci:?}");
    // An explicit cast or a colour sibling still asks for colour noise.
    let (prog, _) = compile_ok("surface t() { Ci = color noise(s * 7.3 + 0.5); Oi = 1; }");
    let (ci, _) = run(&prog, 16);
    assert!(ci.iter().any(|c| (c.x - c.y).abs() > 1e-3), "{ci:?}");
}

#[test]
fn triples_are_indexed_like_comp_and_setcomp() {
    // PRMan 13's `c[i]` component access (published utility headers write `d[0] = pow(c[0],
    // p)`): reads are comp(), writes and compound assignments setcomp().
    let (prog, rendered) = compile_ok(
        "surface idx() {\n  color c = color(0.25, 0.5, 0.75);\n  point p = point(s, 2, 3);\n  \
         color d;\n  d[0] = c[2];\n  d[1] = p[0] * 2;\n  d[2] = 1;\n  d[2] += c[1];\n  \
         float k = 1;\n  d[k] *= 3;\n  Ci = d;\n  Oi = p[1] - 1;\n}\n",
    );
    assert!(!rendered.contains("warning"), "{rendered}");
    let (ci, oi) = run(&prog, 4);
    for (i, (c, o)) in ci.iter().zip(&oi).enumerate() {
        let s = i as f32 / 4.0;
        assert_eq!(*c, Vec3::new(0.75, s * 2.0 * 3.0, 1.5), "point {i}");
        assert_eq!(*o, Vec3::splat(1.0));
    }
    // Arrays keep their own indexing, and a float is still not indexable.
    let (_, rendered, err) = compile("surface f() { float x = 1; Ci = x[0]; }\n");
    assert!(
        err && rendered.contains("only arrays can be indexed"),
        "{rendered}"
    );
}

#[test]
fn a_bare_declaration_as_a_construct_body_stays_visible_after_it() {
    // Published light shaders write `solar() vector Lt = normalize(-L);` and use `Lt` in the
    // statements after it; Aqsis declares such a name in the enclosing scope.
    compile_ok(
        "light l() {\n  solar()\n  vector Lt = normalize(-L);\n  Cl = color(xcomp(Lt));\n}\n",
    );
    let (prog, _) = compile_ok("surface t() {\n  if (s >= 0) float k = 0.25;\n  Ci = k;\n}\n");
    let (ci, _) = run(&prog, 3);
    assert!(ci.iter().all(|c| *c == Vec3::splat(0.25)), "{ci:?}");
    // A braced body still has its own scope.
    let (_, rendered, err) = compile("surface f() { if (s >= 0) { float k = 1; } Ci = k; }\n");
    assert!(
        err && rendered.contains("unknown variable `k`"),
        "{rendered}"
    );
}

/// `faceforward(N, I)` judges the side by Ng (PRMan, Aqsis, VEX), so a bumped normal that
/// tilts past the silhouette is not turned over onto the far side; with Nref given, Nref judges.
/// Here Ng = I = +z (the back side is seen) and N is tilted so that N·I < 0.
#[test]
fn faceforward_of_two_arguments_judges_the_side_by_ng() {
    let (prog, _) = compile_ok(
        "surface ff() { normal Nb = normal(1, 0, -0.1); Ci = color(faceforward(Nb, I)); \
         Oi = color(faceforward(Nb, I, Nb)); }",
    );
    let (ci, oi) = run(&prog, 3);
    for (c, o) in ci.iter().zip(&oi) {
        assert_eq!(*c, Vec3::new(-1.0, 0.0, 0.1), "flipped because I·Ng > 0");
        assert_eq!(*o, Vec3::new(1.0, 0.0, -0.1), "kept because I·Nref < 0");
    }
}

#[test]
fn unknown_space_points_at_the_call() {
    // A scene that never declares the shader's coordinate system (`CoordinateSystem
    // "paintspace"` left out): the warning names the transform, not the whole shader.
    let dir = common::scratch_dir("sl_unknown_space_span");
    std::fs::write(
        dir.join("spc.sl"),
        "surface spc()\n{\n    point q = transform(\"paintspace\", P);\n    matrix m = matrix \"nowhere\" 1;\n    Ci = color(xcomp(q) * comp(m, 0, 0)); Oi = 1;\n}\n",
    )
    .unwrap();
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Format 4 4 1\nDisplay \"{out}\" \"png\" \"rgb\"\nProjection \"orthographic\"\n\
         WorldBegin\nSurface \"spc\"\nPolygon \"P\" [-1 -1 1 1 -1 1 1 1 1 -1 1 1]\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    assert!(
        log.contains("unknown coordinate system \"paintspace\""),
        "{log}"
    );
    assert!(
        log.contains("unknown coordinate system \"nowhere\""),
        "{log}"
    );
    assert!(log.contains("spc.sl:3:15]"), "{log}");
    assert!(log.contains("spc.sl:4:16]"), "{log}");
    assert!(!log.contains("spc.sl:1:1]"), "{log}");
}

#[test]
fn a_division_by_zero_is_reported_at_the_division() {
    // RMR's KMLuna divides by the distance from the pole axis, 0 at the poles: the warning
    // used to label the whole shader (every line of it printed) instead of the `/`.
    let text = "surface divz()\n{\n    float a = 1;\n    float b = 2;\n    float c = 3;\n\
                \x20   Ci = (a + b + c) / s;\n}\n";
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let mut progs = compile_source(
        "divz.sl",
        text,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    assert_eq!(progs.len(), 1, "{}", diags.render_plain(&sources));
    let prog = progs.remove(0);
    let (ci, _) = run_reporting(&prog, 4, &diags);
    let got: Vec<f32> = ci.iter().map(|c| c.x).collect();
    assert_eq!(got, [0.0, 24.0, 12.0, 8.0]);
    let rendered = diags.render_plain(&sources);
    assert!(rendered.contains("division by zero"), "{rendered}");
    assert!(rendered.contains("divz.sl:6:11"), "{rendered}");
    assert!(!rendered.contains("surface divz"), "{rendered}");
}

#[test]
fn a_for_header_may_declare_its_loop_variables() {
    // C++-style `for (float i = 0; …)` (PRMan's and 3Delight's compilers accept it; a student
    // stone shader redeclares an outer `i` this way). The declared names live in the loop:
    // they shadow outer ones, which keep their values after it.
    let (prog, rendered) = compile_ok(
        "surface f() {\n  float i = 7, n = 0;\n  for (float i = 0, k = 2; i < 3; i += 1)\n    \
         n += k * i;\n  Ci = color(n, i, 0);\n}\n",
    );
    assert!(!rendered.contains("warning"), "{rendered}");
    let (ci, _) = run(&prog, 2);
    // n = 2 * (0 + 1 + 2) = 6, the outer i untouched.
    assert!(ci.iter().all(|c| *c == Vec3::new(6.0, 7.0, 0.0)), "{ci:?}");
    // A uniform detail is accepted, and the names do not leak out of the loop.
    compile_ok(
        "surface g() { float n = 0; for (uniform float j = 0; j < 2; j += 1) n += j; Ci = n; }\n",
    );
    let (_, rendered, err) =
        compile("surface h() { for (float j = 0; j < 2; j += 1) ; Ci = j; }\n");
    assert!(
        err && rendered.contains("unknown variable `j`"),
        "{rendered}"
    );
}

#[test]
fn an_rsl2_class_with_one_shading_method_compiles_as_that_shader() {
    // PRMan 13+ light classes that are only `light()` (a published `aw_spotlight` among them)
    // run that method with the class's parameters: the RSL 1 shader of the same body. Their
    // AOV outputs carry no default (PRMan starts them at zero).
    let (prog, rendered) = compile_ok(
        "class tint(color tint = color(0.25, 0.5, 1); output varying float aov;)\n{\n  \
         public void surface(output color Ci, Oi) {\n    Ci = tint + aov;\n    Oi = 1;\n  }\n}\n",
    );
    assert!(rendered.contains("single `surface` method"), "{rendered}");
    let (ci, _) = run(&prog, 2);
    assert!(ci.iter().all(|c| *c == Vec3::new(0.25, 0.5, 1.0)), "{ci:?}");
    // A class with more than its shading method is still named as RSL 2.0, not compiled.
    let (_, rendered, err) = compile(
        "class c(float k = 1)\n{\n  public void begin() { }\n  \
         public void surface(output color Ci, Oi) { Ci = k; }\n}\n",
    );
    assert!(
        err && rendered.contains("Shading Language 2.0"),
        "{rendered}"
    );
    // An input parameter still needs its default.
    let (_, rendered, err) = compile("surface s(float k;) { Ci = k; }\n");
    assert!(
        err && rendered.contains("has no default value"),
        "{rendered}"
    );
}

#[test]
fn illuminance_trace_and_gather_take_prmans_optional_parameters() {
    // PRMan 13 and 3Delight shaders pass "name", value pairs to illuminance (message
    // passing with the lights, the light cache), trace and gather; these were errors that
    // lost the whole shader.
    let (_, log) = compile_ok(
        r#"surface t(float Kd = 1) {
    normal Nf = faceforward(normalize(N), I);
    float nd = 0;
    color C = 0;
    illuminance("", P, Nf, PI/2, "light:__nondiffuse", nd) { C += Cl * (1 - nd); }
    illuminance(P, "lightcache", "refresh", "send:light:__coneaxis", Nf) { C += Cl; }
    illuminance("bakelight", P, "send:light:do_bake", 1) { }
    C += trace(P, reflect(I, Nf), "bias", 0.01, "samples", 4, "label", "refl");
    color hc = 0;
    gather("illuminance", P, Nf, PI/4, 4, "maxdist", 10, "label", "g", "surface:Ci", hc) {
        C += hc;
    }
    gather("illuminance", P, Nf, 0, 1, "subset", "", "volume:Ci", hc) { C += hc; }
    Ci = Kd * C;
}"#,
    );
    // What arbor does not use is named (sent values, the ray options); "light:" reads,
    // "lightcache" and the "label"s are silent.
    for said in [
        "\"send:light:__coneaxis\"",
        "\"send:light:do_bake\"",
        "`trace` parameter \"bias\"",
        "`trace` parameter \"samples\"",
        "`gather` parameter \"maxdist\"",
        "`gather` parameter \"subset\"",
    ] {
        assert!(log.contains(said), "no warning naming {said}:\n{log}");
    }
    // PRMan's "volume:Ci" is the hit's colour, as "surface:Ci".
    // Only the messages (not the quoted source lines) count.
    let messages: String = log
        .lines()
        .filter(|l| l.trim_start().starts_with('⚠') || l.trim_start().starts_with('│'))
        .collect::<Vec<_>>()
        .join("\n");
    for quiet in ["__nondiffuse", "lightcache", "\"label\"", "volume:Ci"] {
        assert!(
            !messages.contains(quiet),
            "{quiet} should be silent:\n{log}"
        );
    }
    // A "light:" target must be a variable to store into.
    let (_, log, err) = compile(
        r#"surface t() { illuminance(P, N, PI/2, "light:__nondiffuse", 1) { Ci += Cl; } }"#,
    );
    assert!(err, "a constant cannot receive a light's value:\n{log}");
}

#[test]
fn area_with_a_measure_is_the_area_with_one_warning() {
    // PRMan's `area(P, "dicing")` gives the same value as `area(P)`, point by point.
    let (two, rendered) = compile_ok(
        "surface a() { float x = area(P, \"dicing\"); float y = area(P); \
         Ci = color(x, y, x == y ? 1 : 0); Oi = 1; }",
    );
    assert_eq!(
        rendered.matches("area(P, measure)").count(),
        1,
        "{rendered}"
    );
    let (ci, _) = run(&two, 4);
    for c in ci {
        assert_eq!(c.x, c.y);
        assert_eq!(c.z, 1.0);
    }
    // A measure that is not a string is still a type error.
    let (_, rendered, err) = compile("surface b() { float x = area(P, 1); Ci = x; }");
    assert!(err, "{rendered}");
}
