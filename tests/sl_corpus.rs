//! Real shaders written by other people for other RenderMan renderers (tests/corpus/, with
//! their sources and licences in tests/corpus/README.md) compile with no error; the ones that
//! genuinely cannot (a header that is not in the corpus) give exactly the expected diagnostic;
//! and every surface and displacement shader runs over a small grid lit by the standard three
//! lights (an ambient and two distant lights) with finite results.
//!
//! `ARBOR_SL_CORPUS=DIR` adds every `.sl` under DIR (e.g. shaders whose licences do not allow
//! committing them) to the compile-and-run check; a DIR/include folder is added to `-I`, and
//! DIR/known_bad.txt lists `path code` lines like [`KNOWN_BAD`].

use std::path::{Path, PathBuf};

use arbor::diag::{Diagnostics, SourceMap};
use arbor::shade::exec::{Env, Exec, LightResult};
use arbor::shade::value::Slot;
use arbor::sl::ast::ShaderKind;
use arbor::sl::ir::Program;
use arbor::sl::library::{compile_source, CompileOptions};
use glam::{Mat4, Vec3};

/// Committed shaders that cannot compile, with the one diagnostic code each must give.
/// (RudyCtile01/02, which include Advanced RenderMan's reflections.h, compile since the
/// standard library has that header.)
const KNOWN_BAD: &[(&str, &str)] = &[];

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus")
}

fn sl_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            sl_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "sl") {
            out.push(p);
        }
    }
}

struct Compiled {
    progs: Vec<Program>,
    codes: Vec<&'static str>,
    rendered: String,
}

fn compile_file(path: &Path, include: &[PathBuf]) -> Compiled {
    let text = std::fs::read_to_string(path).expect("read corpus file");
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let opts = CompileOptions {
        include_dirs: include.to_vec(),
        ..CompileOptions::default()
    };
    let progs = compile_source(
        &path.display().to_string(),
        &text,
        Some(path),
        &sources,
        &diags,
        &opts,
    );
    let codes = diags
        .snapshot()
        .iter()
        .filter(|(d, _)| d.is_error())
        .map(|(d, _)| d.code)
        .collect();
    Compiled {
        progs,
        codes,
        rendered: diags.render_plain(&sources),
    }
}

/// Ambient 0.1, a distant light of intensity 1 from (-1, 1, -1) and one of intensity 0.5 from
/// (1, 1, -1), both toward the origin (the shading benchmark's lights), over `n` points.
fn three_lights(n: usize) -> Vec<LightResult> {
    let light = |ambient: bool, dir: Vec3, c: f32| LightResult {
        ambient,
        lit: vec![true; n],
        l: vec![dir; n],
        l_uniform: Some(dir),
        cl: vec![Vec3::splat(c); n],
        ol: vec![Vec3::ZERO; n],
        category: std::sync::Arc::from(""),
        nondiffuse: false,
        nonspecular: false,
        program: None,
        outputs: Vec::new(),
    };
    vec![
        light(true, Vec3::ZERO, 0.1),
        light(false, Vec3::new(-1.0, 1.0, -1.0), 1.0),
        light(false, Vec3::new(1.0, 1.0, -1.0), 0.5),
    ]
}

/// Runs a surface or displacement program over an 8×8 patch of the z = 5 plane facing the
/// camera; returns the outputs (Ci, Oi for surfaces; P, N for displacements) that are not
/// finite, and the first output (Ci or P) at every point.
fn run(prog: &Program) -> (Vec<String>, Vec<Vec3>) {
    const W: usize = 8;
    let n = W * W;
    let diags = Diagnostics::new();
    let spaces = |_: &str| Some(Mat4::IDENTITY);
    let info = |_: &str, _: &str| None;
    let lights = if prog.kind == ShaderKind::Surface {
        three_lights(n)
    } else {
        Vec::new()
    };
    let env = Env {
        nu: W,
        nv: W,
        spaces: &spaces,
        lights: &lights,
        flip_normals: false,
        near: 0.1,
        far: 100.0,
        shader_name: "corpus",
        diags: &diags,
        info: &info,
        textures: None,
        seed: 11,
        rays: None,
        cones: None,
        displacement_outputs: &[],
        surface_params: &[],
        atmosphere_params: &[],
    };
    let mut ex = Exec::new(prog, n, &env);
    ex.run_init();
    let uv: Vec<(f32, f32)> = (0..n)
        .map(|k| {
            (
                (k % W) as f32 / (W - 1) as f32,
                (k / W) as f32 / (W - 1) as f32,
            )
        })
        .collect();
    let u: Vec<f32> = uv.iter().map(|p| p.0).collect();
    let v: Vec<f32> = uv.iter().map(|p| p.1).collect();
    let p: Vec<Vec3> = uv
        .iter()
        .map(|&(a, b)| Vec3::new(a - 0.5, b - 0.5, 5.0))
        .collect();
    let step = 1.0 / (W - 1) as f32;
    let binds: Vec<(&str, Slot)> = vec![
        ("s", Slot::VF(u.clone())),
        ("t", Slot::VF(v.clone())),
        ("u", Slot::VF(u)),
        ("v", Slot::VF(v)),
        ("du", Slot::F(step)),
        ("dv", Slot::F(step)),
        ("I", Slot::VT(p.clone())),
        ("P", Slot::VT(p)),
        ("N", Slot::VT(vec![-Vec3::Z; n])),
        ("Ng", Slot::VT(vec![-Vec3::Z; n])),
        ("dPdu", Slot::VT(vec![Vec3::X; n])),
        ("dPdv", Slot::VT(vec![Vec3::Y; n])),
        ("Cs", Slot::T(Vec3::new(0.8, 0.7, 0.6))),
        ("Os", Slot::T(Vec3::ONE)),
        ("E", Slot::T(Vec3::ZERO)),
    ];
    for (name, val) in binds {
        if let Some(g) = prog.global(name) {
            ex.set(g.reg, val);
        }
    }
    ex.run_body();
    let outs: &[&str] = if prog.kind == ShaderKind::Surface {
        &["Ci", "Oi"]
    } else {
        &["P", "N"]
    };
    let mut bad = Vec::new();
    let first = match prog.global(outs[0]) {
        Some(g) => (0..n).map(|i| ex.regs[g.reg as usize].t().at(i)).collect(),
        None => Vec::new(),
    };
    for name in outs {
        let Some(g) = prog.global(name) else { continue };
        let slot = &ex.regs[g.reg as usize];
        for i in 0..n {
            let x = slot.t().at(i);
            if !x.is_finite() {
                bad.push(format!("{name}[{i}] = {x}"));
                break;
            }
        }
    }
    (bad, first)
}

fn check_dir(
    dir: &Path,
    include: &[PathBuf],
    known_bad: &[(String, String)],
    failures: &mut Vec<String>,
) -> usize {
    let mut files = Vec::new();
    sl_files(dir, &mut files);
    for path in &files {
        let rel = path
            .strip_prefix(dir)
            .unwrap_or(path)
            .to_string_lossy()
            .replace('\\', "/");
        let c = compile_file(path, include);
        match known_bad.iter().find(|(f, _)| *f == rel) {
            Some((_, code)) => {
                if c.codes.is_empty() || c.codes.iter().any(|k| *k != code.as_str()) {
                    failures.push(format!(
                        "{rel}: expected only `{code}` errors, got {:?}\n{}",
                        c.codes, c.rendered
                    ));
                }
                continue;
            }
            None if !c.codes.is_empty() => {
                failures.push(format!("{rel}: errors\n{}", c.rendered));
                continue;
            }
            None => {}
        }
        if c.progs.is_empty() {
            failures.push(format!("{rel}: no shader compiled\n{}", c.rendered));
        }
        for prog in &c.progs {
            if matches!(prog.kind, ShaderKind::Surface | ShaderKind::Displacement) {
                let (bad, _) = run(prog);
                if !bad.is_empty() {
                    failures.push(format!("{rel}: non-finite output: {}", bad.join(", ")));
                }
            }
        }
    }
    files.len()
}

#[test]
fn corpus_compiles_and_runs() {
    let dir = corpus_dir();
    let mut failures = Vec::new();
    let known: Vec<(String, String)> = KNOWN_BAD
        .iter()
        .map(|(f, c)| (f.to_string(), c.to_string()))
        .collect();
    let count = check_dir(&dir, &[dir.join("include")], &known, &mut failures);
    assert!(count >= 10, "corpus has only {count} shaders");
    if let Ok(extra) = std::env::var("ARBOR_SL_CORPUS") {
        let extra = PathBuf::from(extra);
        let known: Vec<(String, String)> = std::fs::read_to_string(extra.join("known_bad.txt"))
            .unwrap_or_default()
            .lines()
            .filter_map(|l| {
                let mut w = l.split_whitespace();
                Some((w.next()?.to_string(), w.next()?.to_string()))
            })
            .collect();
        let n = check_dir(&extra, &[extra.join("include")], &known, &mut failures);
        eprintln!("ARBOR_SL_CORPUS: {n} more shaders checked");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// Compiles `text`; returns the programs and every diagnostic as (code, is_error, message).
fn compile_text(text: &str) -> (Vec<Program>, Vec<(&'static str, bool, String)>) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let progs = compile_source(
        "inline.sl",
        text,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    let list = diags
        .snapshot()
        .into_iter()
        .map(|(d, _)| (d.code, d.is_error(), d.message))
        .collect();
    (progs, list)
}

#[test]
fn shader_kind_words_are_names_outside_definitions() {
    // IDscartissue.sl: `color light = …` compiled with PRMan.
    let (progs, diags) = compile_text(
        "surface t() { color light = color(1, .3, .2); float surface = 0.5; \
         Ci = light * surface; }",
    );
    assert_eq!(progs.len(), 1, "{diags:?}");
    assert!(diags.iter().all(|d| !d.1), "{diags:?}");
}

#[test]
fn extensions_warn_once_and_give_their_fallback() {
    // occlusion/indirectdiffuse are ray functions now (no warning); without a ray tracer they
    // read unoccluded and black. caustic() is still an extension: one warning, black.
    let (progs, diags) = compile_text(
        "surface t() { float o = occlusion(P, N, 16, \"maxdist\", 1); \
         float o2 = occlusion(P, N, 4); color ind = indirectdiffuse(P, N, 8); \
         color c1 = caustic(P, N); color c2 = caustic(P, N); \
         Ci = color(1 - o - o2) + ind + c1 + c2; }",
    );
    assert_eq!(progs.len(), 1, "{diags:?}");
    assert!(
        !diags.iter().any(|d| d.2.contains("`occlusion`")),
        "occlusion is a ray function: {diags:?}"
    );
    let c: Vec<_> = diags
        .iter()
        .filter(|d| d.0 == "sl::extension" && d.2.contains("`caustic`"))
        .collect();
    assert_eq!(c.len(), 1, "one warning per extension: {diags:?}");
    assert!(diags.iter().all(|d| !d.1), "{diags:?}");
    // Unoccluded and no indirect light: Ci = 1 everywhere.
    let (bad, ci) = run(&progs[0]);
    assert!(bad.is_empty(), "{bad:?}");
    assert_eq!(ci.len(), 64);
    assert!(ci.iter().all(|c| *c == Vec3::ONE), "{ci:?}");
}

#[test]
fn prman_light_extensions_are_accepted_with_warnings() {
    // envlight-style `Ns`, softbox-style `I`, arealight-style `N = normalize(N)`.
    let (progs, diags) = compile_text(
        "light t() { N = normalize(N); vector r = reflect(I, Ns); \
         solar(-N, 0) { Cl = color(xcomp(r)); } }",
    );
    assert_eq!(progs.len(), 1, "{diags:?}");
    assert!(diags.iter().all(|d| !d.1), "{diags:?}");
    for what in ["`Ns`", "`I`", "`N`"] {
        assert!(
            diags
                .iter()
                .any(|d| d.0 == "sl::extension" && d.2.contains(what)),
            "no warning naming {what}: {diags:?}"
        );
    }
    // Still an error in a surface shader, where RISpec and every renderer forbid it.
    let (_, diags) = compile_text("surface t() { Ns = N; Ci = 1; }");
    assert!(diags.iter().any(|d| d.1), "{diags:?}");
}

#[test]
fn ps_in_a_surface_shader_reads_p_with_a_warning() {
    // The RenderMan Companion's windowhighlight: `corner - Ps` for the point being shaded.
    let (progs, diags) =
        compile_text("surface t() { vector d = Ps - P; Ci = color(1 + length(d)); }");
    assert_eq!(progs.len(), 1, "{diags:?}");
    assert!(diags.iter().all(|d| !d.1), "{diags:?}");
    assert_eq!(
        diags
            .iter()
            .filter(|d| d.0 == "sl::extension" && d.2.contains("`Ps`"))
            .count(),
        1,
        "{diags:?}"
    );
    let (bad, ci) = run(&progs[0]);
    assert!(bad.is_empty(), "{bad:?}");
    assert!(ci.iter().all(|c| *c == Vec3::ONE), "{ci:?}");
}

#[test]
fn imager_surface_parameters_compile_with_a_warning() {
    // Aqsis' filmgrain imager reads s and t (the pixel's raster position; film_conventions.rs).
    let (progs, diags) =
        compile_text("imager t() { float g = float noise(s, t); Ci = Ci * (1 - 0.1 * g); }");
    assert_eq!(progs.len(), 1, "{diags:?}");
    assert!(diags.iter().all(|d| !d.1), "{diags:?}");
    assert_eq!(
        diags.iter().filter(|d| d.0 == "sl::extension").count(),
        2,
        "{diags:?}"
    );
}

#[test]
fn a_missing_header_gives_one_diagnostic_and_no_cascade() {
    let (progs, diags) = compile_text(
        "#include \"no_such_header.h\"\nsurface t() { Ci = undefined_helper(s) + MACRO_FROM_HEADER; }",
    );
    assert!(progs.is_empty());
    let errors: Vec<_> = diags.iter().filter(|d| d.1).collect();
    assert_eq!(errors.len(), 1, "{diags:?}");
    assert_eq!(errors[0].0, "sl::include");
    assert!(errors[0].2.contains("no_such_header.h"));
}

#[test]
fn random_into_a_uniform_variable_is_one_number_per_grid() {
    // Aqsis' randgrid.sl: `uniform color c; c = color(random(), random(), random());`.
    let (progs, diags) = compile_text(
        "surface t() { uniform color c; c = color(random(), random(), random()); \
         float v = random(); Ci = c; Oi = v; }",
    );
    assert_eq!(progs.len(), 1, "{diags:?}");
    assert!(
        diags.iter().all(|d| d.0 != "sl::detail"),
        "no demotion warning: {diags:?}"
    );
    let (bad, ci) = run(&progs[0]);
    assert!(bad.is_empty(), "{bad:?}");
    assert!(
        ci.iter().all(|c| *c == ci[0]),
        "one colour per grid: {ci:?}"
    );
    assert!(ci[0].min_element() >= 0.0 && ci[0].max_element() < 1.0);
    assert!(ci[0].x != ci[0].y, "each random() call is its own number");
}

#[test]
fn random_in_a_loop_differs_on_every_pass() {
    // glass.sl jitters each of its samples×samples rays with `random()` inside the loops.
    let (progs, diags) = compile_text(
        "surface t() { float i, a = 0, b = 0; for (i = 0; i < 2; i += 1) { \
         float r = random(); if (i == 0) a = r; else b = r; } Ci = color(a, b, 0); }",
    );
    assert_eq!(progs.len(), 1, "{diags:?}");
    let (bad, ci) = run(&progs[0]);
    assert!(bad.is_empty(), "{bad:?}");
    assert!(ci.iter().all(|c| c.x != c.y), "same number twice: {ci:?}");
    assert!(ci.iter().any(|c| c.x != ci[0].x), "per point too: {ci:?}");
}
