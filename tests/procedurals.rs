//! Procedural primitives that run code: `Procedural "RunProgram"` (a shell-script generator
//! written by the test) and `Procedural "DynamicLoad"` (a C library built with the system's
//! `cc`, rendered by the `arbor` binary whose RI functions it calls). Both run only when
//! allowed; their failures are diagnostics at the `Procedural` request.
//!
//! The scenes are orthographic over a 4×4 window on 64×64 pixels (16 pixels a unit), so a
//! unit sphere covers π·256 ≈ 804 pixels of alpha and a bound of [-1,1]³ has a detail (raster
//! area) of exactly 32·32 = 1024.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::film::resolve::Film;
use arbor::pipeline::{library_for, load_scenes, Settings};
use arbor::render::driver::{render_frame, RenderOptions};
use arbor::shade::system::ShadeSystem;

const HEADER: &str = "Format 64 64 1\nProjection \"orthographic\"\nScreenWindow -2 2 -2 2\n\
PixelSamples 4 4\nPixelFilter \"box\" 1 1\nTranslate 0 0 5\n";

/// Unit-sphere coverage in pixels.
const UNIT_DISC: f64 = std::f64::consts::PI * 256.0;

fn scratch(name: &str) -> PathBuf {
    let d = common::scratch_dir(&format!("procedurals-{name}"));
    for e in std::fs::read_dir(&d).unwrap().flatten() {
        let _ = std::fs::remove_file(e.path());
    }
    d
}

/// Writes an executable shell script.
fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, format!("#!/bin/sh\n{body}")).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    p
}

struct Rendered {
    film: Option<Film>,
    report: String,
    errors: usize,
    codes: Vec<&'static str>,
}

/// Builds and renders `dir/scene.rib` in process.
fn render(dir: &Path, world: &str, allow: bool, timeout: Option<f32>) -> Rendered {
    let path = dir.join("scene.rib");
    std::fs::write(&path, format!("{HEADER}WorldBegin\n{world}WorldEnd\n")).unwrap();
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let settings = Settings {
        threads: 1,
        allow_programs: allow,
        program_timeout: timeout,
        ..Default::default()
    };
    let scenes = load_scenes(&path, &settings, &sources, &diags);
    let film = scenes.first().map(|scene| {
        let library = library_for(scene, &settings);
        let system = ShadeSystem {
            library: &library,
            sources: &sources,
            diags: &diags,
            textures: None,
            aovs: Vec::new(),
            rays: Default::default(),
        };
        render_frame(scene, &system, &RenderOptions::default(), &diags)
    });
    Rendered {
        film,
        report: diags.render_plain(&sources),
        errors: diags.error_count(),
        codes: diags.snapshot().iter().map(|(d, _)| d.code).collect(),
    }
}

/// Sum of alpha over the film (covered pixels).
fn coverage(f: &Film) -> f64 {
    let a = f.channel("a").expect("alpha");
    let mut s = 0.0;
    for y in 0..f.height {
        for x in 0..f.width {
            s += f.pixel(x, y)[a] as f64;
        }
    }
    s
}

/// A generator answering "detail radius" with a sphere of that radius, logging each request.
fn sphere_generator(dir: &Path) -> PathBuf {
    let log = dir.join("requests.txt");
    script(
        dir,
        "spheres.sh",
        &format!(
            "while read detail radius; do\n  echo \"$detail $radius\" >> '{}'\n  \
             echo \"Sphere $radius -$radius $radius 360\"\n  printf '\\377'\ndone\n",
            log.display()
        ),
    );
    log
}

#[test]
fn run_program_generates_geometry_only_when_allowed() {
    let dir = scratch("allowed");
    let log = sphere_generator(&dir);
    let world = "Surface \"constant\"\n\
        Procedural \"RunProgram\" [\"spheres.sh\" \"1\"] [-1 1 -1 1 -1 1]\n\
        AttributeBegin\n  Translate 10 0 0\n  \
        Procedural \"RunProgram\" [\"spheres.sh\" \"1\"] [-1 1 -1 1 -1 1]\nAttributeEnd\n\
        AttributeBegin\n  Translate 0 0 -20\n  \
        Procedural \"RunProgram\" [\"spheres.sh\" \"1\"] [-1 1 -1 1 -1 1]\nAttributeEnd\n";

    // Not allowed: a warning naming the procedural and how to allow it; nothing runs.
    let r = render(&dir, world, false, None);
    assert_eq!(r.errors, 0, "{}", r.report);
    assert!(
        r.codes.contains(&"scene::procedural-not-allowed"),
        "{}",
        r.report
    );
    assert!(r.report.contains("--allow-programs"), "{}", r.report);
    assert!(r.report.contains("spheres.sh"), "{}", r.report);
    assert_eq!(coverage(r.film.as_ref().unwrap()), 0.0);
    assert!(!log.exists(), "the program ran without permission");

    // Allowed: the sphere in view is generated; the one off the image and the one behind the
    // camera are culled by their bounds, so the program is asked once, with the bound's
    // raster area as its detail.
    let r = render(&dir, world, true, None);
    assert_eq!(r.errors, 0, "{}", r.report);
    let cov = coverage(r.film.as_ref().unwrap());
    assert!(
        (cov - UNIT_DISC).abs() < 0.01 * UNIT_DISC,
        "coverage {cov} (want {UNIT_DISC})"
    );
    let requests = std::fs::read_to_string(&log).unwrap();
    assert_eq!(requests.trim(), "1024 1", "requests: {requests:?}");
}

#[test]
fn run_program_output_is_rib_in_the_current_graphics_state() {
    // The reply's own requests stay inside the procedural; the caller's transform applies.
    let dir = scratch("state");
    script(
        &dir,
        "two.sh",
        "while read d r; do\n  echo 'Color 1 0 0 Translate 0.5 0 0'\n  \
         echo \"Sphere $r -$r $r 360\"\n  printf '\\377'\ndone\n",
    );
    let world = "Surface \"constant\"\nTranslate -1 0 0\n\
        Procedural \"RunProgram\" [\"two.sh\" \"0.5\"] [-1 1 -1 1 -1 1]\n\
        Translate 1 0 0\nDisk 0 0.25 360\n";
    let r = render(&dir, world, true, None);
    assert_eq!(r.errors, 0, "{}", r.report);
    let f = r.film.unwrap();
    let (cr, cg) = (f.channel("r").unwrap(), f.channel("g").unwrap());
    // The generated sphere sits at x = -0.5 (pixel 24), red.
    let p = f.pixel(24, 32);
    assert!(p[cr] > 0.99 && p[cg] < 0.01, "sphere pixel {p:?}");
    // The disk after the procedural is white: the reply's Color did not leak out.
    let p = f.pixel(32, 32);
    assert!(p[cr] > 0.99 && p[cg] > 0.99, "disk pixel {p:?}");
}

#[test]
fn run_program_failures_are_diagnostics_at_the_request() {
    let dir = scratch("failures");
    // Bad RIB, a block closed that the procedural did not open, one left open; the good
    // sphere still renders.
    script(
        &dir,
        "bad.sh",
        "while read d r; do\n  echo 'Spher 1 -1 1 360'\n  echo 'AttributeEnd'\n  \
         echo 'AttributeBegin'\n  echo 'Sphere 1 -1 1 360'\n  printf '\\377'\ndone\n",
    );
    // Exits before ending its reply.
    script(
        &dir,
        "early.sh",
        "read line\necho 'Sphere 1 -1 1 360'\necho 'generator broke' >&2\nexit 3\n",
    );
    // Never answers.
    script(&dir, "silent.sh", "exec sleep 30\n");
    let world = "Surface \"constant\"\nAttributeBegin\n\
        Procedural \"RunProgram\" [\"bad.sh\" \"\"] [-1 1 -1 1 -1 1]\nAttributeEnd\n\
        Procedural \"RunProgram\" [\"early.sh\" \"\"] [-1 1 -1 1 -1 1]\n\
        Procedural \"RunProgram\" [\"early.sh\" \"\"] [-1 1 -1 1 -1 1]\n\
        Procedural \"RunProgram\" [\"./missing.sh\" \"\"] [-1 1 -1 1 -1 1]\n";
    let r = render(&dir, world, true, None);
    let rep = &r.report;
    assert!(rep.contains("unknown request `Spher`"), "{rep}");
    assert!(
        rep.contains("while expanding `Procedural \"RunProgram\" \"bad.sh\"` at"),
        "{rep}"
    );
    assert!(
        rep.contains("would close a block opened outside it"),
        "{rep}"
    );
    assert!(rep.contains("is never closed by `AttributeEnd`"), "{rep}");
    assert!(rep.contains("before ending its reply"), "{rep}");
    assert!(rep.contains("generator broke"), "{rep}");
    assert!(rep.contains("failed earlier"), "{rep}");
    assert!(
        rep.contains("cannot find the RunProgram program `./missing.sh`"),
        "{rep}"
    );
    // Spher, AttributeEnd, AttributeBegin, early.sh, missing.sh.
    assert_eq!(r.errors, 5, "{rep}");
    let cov = coverage(r.film.as_ref().unwrap());
    assert!(
        (cov - UNIT_DISC).abs() < 0.01 * UNIT_DISC,
        "coverage {cov}: the good sphere of bad.sh's reply"
    );
    // A program that never answers is killed after the timeout (half a second here, against
    // its 30 s sleep); the build goes on.
    let r = render(
        &dir,
        "Procedural \"RunProgram\" [\"silent.sh\" \"\"] [-1 1 -1 1 -1 1]\nSphere 1 -1 1 360\n",
        true,
        Some(0.5),
    );
    assert!(r.report.contains("wrote nothing for"), "{}", r.report);
    assert!(r.report.contains("killed"), "{}", r.report);
    assert_eq!(r.errors, 1, "{}", r.report);
    assert!(coverage(r.film.as_ref().unwrap()) > 0.99 * UNIT_DISC);
}

/// The C procedural: "n r" → n red spheres of radius r along x from the origin, then a green
/// unit square centred at x = 2 from an `RiProcedural` child; details go to stderr.
const C_PROCEDURAL: &str = r#"
#include <stdio.h>
#include <stdlib.h>
#include "ri.h"

typedef struct { int n; float r; } Params;

RtPointer ConvertParameters(RtString s) {
    Params *p = malloc(sizeof *p);
    p->n = 1; p->r = 0.25f;
    sscanf(s, "%d %f", &p->n, &p->r);
    return p;
}

static RtVoid square(RtPointer data, RtFloat detail) {
    RtPoint pts[4] = {{-0.5f, -0.5f, 0}, {0.5f, -0.5f, 0}, {0.5f, 0.5f, 0}, {-0.5f, 0.5f, 0}};
    RtColor green = {0, 1, 0};
    (void)data;
    fprintf(stderr, "child detail %g\n", detail);
    RiColor(green);
    RiPolygon(4, RI_P, (RtPointer)pts, RI_NULL);
}

RtVoid Subdivide(RtPointer data, RtFloat detail) {
    Params *p = data;
    RtColor red = {1, 0, 0};
    RtBound b = {-0.5f, 0.5f, -0.5f, 0.5f, 0, 0};
    RtToken kd = RiDeclare("myscale", "uniform float");
    float scale = 1;
    int i;
    fprintf(stderr, "detail %g\n", detail);
    RiAttributeBegin();
    RiColor(red);
    RiSurface("constant", kd, &scale, RI_NULL);
    for (i = 0; i < p->n; i++) {
        RiSphere(p->r, -p->r, p->r, 360, RI_NULL);
        RiTranslate(2 * p->r, 0, 0);
    }
    RiAttributeEnd();
    RiTranslate(2.0f, 0, 0);
    RiProcedural(NULL, b, square, NULL);
}

RtVoid Free(RtPointer data) { free(data); }
"#;

fn have_cc() -> bool {
    Command::new("cc")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn dynamic_load_renders_a_c_procedural() {
    if !have_cc() {
        eprintln!("skipped: no C compiler (`cc`) to build the test procedural");
        return;
    }
    let dir = scratch("dso");
    std::fs::write(dir.join("spheres.c"), C_PROCEDURAL).unwrap();
    let include = common::manifest_dir().join("include");
    let out = Command::new("cc")
        .args(["-shared", "-fPIC", "-Wall", "-Werror", "-o"])
        .arg(dir.join("spheres.so"))
        .arg(dir.join("spheres.c"))
        .arg("-I")
        .arg(&include)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cc failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // "spheres" is found on the scene's folder with the platform's suffix.
    let scene = format!(
        "{HEADER}Display \"dso.png\" \"file\" \"rgba\"\nWorldBegin\nSurface \"constant\"\n\
         Translate -1.5 0 0\n\
         Procedural \"DynamicLoad\" [\"spheres\" \"2 0.5\"] [-0.5 2.5 -0.5 0.5 -0.5 0.5]\n\
         WorldEnd\n"
    );
    std::fs::write(dir.join("scene.rib"), scene).unwrap();
    let run = |allow: bool| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_arbor"));
        c.current_dir(&dir).env_remove("ARBOR_ALLOW_PROGRAMS");
        c.args(["render", "--threads", "1"]);
        if allow {
            c.arg("--allow-programs");
        }
        c.arg("scene.rib");
        c.output().unwrap()
    };
    let read = || image::open(dir.join("dso.png")).unwrap().to_rgba8();

    let o = run(false);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{err}");
    assert!(err.contains("--allow-programs"), "{err}");
    assert!(!err.contains("detail"), "the library ran: {err}");
    assert!(read().pixels().all(|p| p[3] == 0));

    let o = run(true);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{err}");
    // The bound spans 3 × 1 units = 48 × 16 pixels; the child's unit square 16 × 16.
    assert!(err.contains("detail 768\n"), "{err}");
    assert!(err.contains("child detail 256\n"), "{err}");
    let img = read();
    let count = |f: &dyn Fn(&image::Rgba<u8>) -> bool| img.pixels().filter(|p| f(p)).count();
    let red = count(&|p| p[0] > 128 && p[1] < 128 && p[3] > 128) as f64;
    let green = count(&|p| p[1] > 128 && p[0] < 128 && p[3] > 128) as f64;
    // Two spheres of radius 0.5 (π·0.25·256 pixels each); a unit square (256 pixels).
    let want_red = 2.0 * UNIT_DISC * 0.25;
    assert!(
        (red - want_red).abs() < 0.03 * want_red,
        "red {red}, want {want_red}"
    );
    assert!((green - 256.0).abs() < 0.03 * 256.0, "green {green}");
    // The square lies two units right of the procedural's origin: x in [0, 1], pixels 32..48.
    let p = img.get_pixel(40, 32);
    assert!(p[1] > 200 && p[0] < 50, "{p:?}");
}

#[test]
fn dynamic_load_failures_are_diagnostics() {
    if !have_cc() {
        eprintln!("skipped: no C compiler (`cc`) to build the test procedural");
        return;
    }
    let dir = scratch("dso-bad");
    // Calls an RI function arbor does not provide: loading fails with the linker's message.
    std::fs::write(
        dir.join("curves.c"),
        "typedef void *RtPointer;\nvoid RiCurvesV(int, int *, char *, int, char **, void **);\n\
         RtPointer ConvertParameters(char *s) { return s; }\n\
         void Subdivide(RtPointer d, float detail) { (void)d; (void)detail; RiCurvesV(0, 0, 0, 0, 0, 0); }\n\
         void Free(RtPointer d) { (void)d; }\n",
    )
    .unwrap();
    // No Free.
    std::fs::write(
        dir.join("nofree.c"),
        "void *ConvertParameters(char *s) { return s; }\nvoid Subdivide(void *d, float f) { (void)d; (void)f; }\n",
    )
    .unwrap();
    for name in ["curves", "nofree"] {
        let o = Command::new("cc")
            .args(["-shared", "-fPIC", "-o"])
            .arg(dir.join(format!("{name}.so")))
            .arg(dir.join(format!("{name}.c")))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let world = "Procedural \"DynamicLoad\" [\"curves\" \"\"] [-1 1 -1 1 -1 1]\n\
        Procedural \"DynamicLoad\" [\"nofree.so\" \"\"] [-1 1 -1 1 -1 1]\n\
        Procedural \"DynamicLoad\" [\"absent\" \"\"] [-1 1 -1 1 -1 1]\n\
        Sphere 1 -1 1 360\n";
    let r = render(&dir, world, true, None);
    let rep = &r.report;
    assert!(rep.contains("RiCurvesV"), "{rep}");
    assert!(rep.contains("no `Free`"), "{rep}");
    assert!(
        rep.contains("cannot find the DynamicLoad library `absent`"),
        "{rep}"
    );
    assert_eq!(r.errors, 3, "{rep}");
    // The scene's own sphere still renders.
    let cov = coverage(r.film.as_ref().unwrap());
    assert!((cov - UNIT_DISC).abs() < 0.01 * UNIT_DISC, "coverage {cov}");
}

#[test]
fn the_sphereflake_example_renders_from_another_folder() {
    let have_python = Command::new("python3")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !have_python {
        eprintln!("skipped: no python3 for examples/runprogram/sphereflake.py");
        return;
    }
    let dir = scratch("sphereflake");
    let rib = common::manifest_dir().join("examples/runprogram/sphereflake.rib");
    let out = Command::new(env!("CARGO_BIN_EXE_arbor"))
        .current_dir(&dir)
        .args([
            "render",
            "--allow-programs",
            "--res",
            "80",
            "60",
            "-o",
            "flake.png",
        ])
        .arg(&rib)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("warning"), "{err}");
    // The flake fills the middle of the picture.
    let img = image::open(dir.join("flake.png")).unwrap().to_luma8();
    let lit = img.pixels().filter(|p| p[0] > 20).count();
    assert!(lit > 80 * 60 / 8, "only {lit} lit pixels");
}

/// PRMan 19's `Procedural2 "DelayedReadArchive2" "SimpleBound"` (RenderMan for Blender and
/// Maya write each mesh so) reads its `"string filename"` archive like
/// `Procedural "DelayedReadArchive"`, culled by its `"float[6] bound"`; any other Procedural2
/// plug-in is compiled code and is skipped with a warning, not an unknown-request error.
#[test]
fn procedural2_delayed_read_archive_reads_its_archive() {
    let dir = scratch("procedural2");
    std::fs::write(dir.join("ball.rib"), "Sphere 1 -1 1 360\n").unwrap();
    let world = "Surface \"constant\"\n\
        Procedural2 \"DelayedReadArchive2\" \"SimpleBound\" \"string filename\" [\"ball.rib\"] \
        \"float[6] bound\" [-1 1 -1 1 -1 1]\n\
        AttributeBegin\n  Translate 10 0 0\n  \
        Procedural2 \"DelayedReadArchive2\" \"SimpleBound\" \"string filename\" [\"missing.rib\"] \
        \"float[6] bound\" [-1 1 -1 1 -1 1]\nAttributeEnd\n\
        Procedural2 \"DynamicLoad\" \"SimpleBound\" \"string dsoname\" [\"hair.so\"]\n";
    let r = render(&dir, world, false, None);
    // The archive off the image is culled by its bound: no error for its missing file.
    assert_eq!(r.errors, 0, "{}", r.report);
    let cov = coverage(r.film.as_ref().unwrap());
    assert!(
        (cov - UNIT_DISC).abs() < 0.01 * UNIT_DISC,
        "coverage {cov} (want {UNIT_DISC})"
    );
    assert!(
        r.codes.contains(&"scene::procedural-not-allowed"),
        "{}",
        r.report
    );
    assert!(r.report.contains("DynamicLoad"), "{}", r.report);
}
