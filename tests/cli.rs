//! The `arbor` command as a user runs it: exit codes, diagnostics on stderr, files written
//! (or not) — through the real binary.

mod common;

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

fn arbor() -> Command {
    Command::new(env!("CARGO_BIN_EXE_arbor"))
}

fn tmpdir(name: &str) -> common::Scratch {
    common::scratch(&format!("cli-{name}"))
}

fn run_stdin(args: &[&str], input: &str, dir: &PathBuf) -> (i32, String) {
    let mut child = arbor()
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

const SCENE: &str = r#"Format 32 24 1
Display "out.png" "png" "rgba"
Projection "perspective" "fov" [40]
Translate 0 0 4
WorldBegin
LightSource "distantlight" 1
Surface "plastic"
Sphere 1 -1 1 360
WorldEnd
"#;

#[test]
fn render_from_stdin_writes_the_display_file() {
    let dir = tmpdir("stdin");
    let (code, err) = run_stdin(&["render", "-q"], SCENE, &dir);
    assert_eq!(code, 0, "{err}");
    let img = image::open(dir.join("out.png")).unwrap();
    assert_eq!((img.width(), img.height()), (32, 24));
}

#[test]
fn output_override_picks_the_format_from_the_extension() {
    let dir = tmpdir("override");
    let (code, err) = run_stdin(&["render", "-q", "-o", "x.tif"], SCENE, &dir);
    assert_eq!(code, 0, "{err}");
    assert!(dir.join("x.tif").exists());
    assert!(
        !dir.join("out.png").exists(),
        "-o replaces the first display"
    );
}

#[test]
fn an_unknown_request_is_an_error_with_a_suggestion_and_exit_1() {
    let dir = tmpdir("unknown");
    let (code, err) = run_stdin(
        &["check", "-"],
        "WorldBegin\nSphre 1 -1 1 360\nWorldEnd\n",
        &dir,
    );
    assert_eq!(code, 1);
    assert!(err.contains("unknown request `Sphre`"), "{err}");
    assert!(err.contains("did you mean `Sphere`"), "{err}");
    assert!(err.contains("-:2:1"), "line and column: {err}");
}

#[test]
fn shader_errors_are_reported_with_their_location() {
    let dir = tmpdir("slerr");
    std::fs::write(
        dir.join("bad.sl"),
        "surface bad() {\n  Ci = undefinedthing;\n}\n",
    )
    .unwrap();
    let out = arbor()
        .args(["check", "bad.sl"])
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("unknown variable `undefinedthing`"), "{err}");
    assert!(err.contains("bad.sl:2:8"), "{err}");
}

#[test]
fn a_missing_shader_warns_and_renders_with_the_default_surface() {
    let dir = tmpdir("missing");
    let scene = SCENE.replace("Surface \"plastic\"", "Surface \"no_such_shader\"");
    let (code, err) = run_stdin(&["render"], &scene, &dir);
    assert!(err.contains("no_such_shader"), "{err}");
    assert!(
        dir.join("out.png").exists(),
        "a missing shader must not stop the render: {err}"
    );
    assert_eq!(code, 0, "a missing shader is a warning: {err}");
    assert!(err.contains("warning"), "{err}");
}

#[test]
fn info_lists_a_standard_shaders_parameters() {
    let out = arbor().args(["info", "spotlight"]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(text.starts_with("light \"spotlight\""), "{text}");
    for p in [
        "intensity",
        "lightcolor",
        "from",
        "to",
        "coneangle",
        "conedeltaangle",
        "beamdistribution",
    ] {
        assert!(text.contains(&format!("\"{p}\"")), "{p} missing: {text}");
    }
}

#[test]
fn format_output_parses_back_to_the_same_requests() {
    let dir = tmpdir("format");
    std::fs::write(dir.join("s.rib"), SCENE).unwrap();
    let out = arbor()
        .args(["format", "s.rib"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        text.contains("WorldBegin\n  LightSource \"distantlight\" 1"),
        "{text}"
    );
    std::fs::write(dir.join("t.rib"), &text).unwrap();
    let again = arbor()
        .args(["format", "t.rib"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_eq!(String::from_utf8_lossy(&again.stdout), text);
}

#[test]
fn garbage_input_never_panics() {
    let dir = tmpdir("garbage");
    for input in [
        "\u{0}\u{1}\u{2}[[[[",
        "WorldBegin ]]] \"unterminated",
        "Sphere [",
        "\u{ff}\u{fe}binary\u{80}\u{81}",
    ] {
        let (code, err) = run_stdin(&["render", "-q"], input, &dir);
        assert!(!err.contains("panicked"), "{input:?}: {err}");
        assert!(code == 0 || code == 1, "{input:?}: exit {code}");
    }
}

/// The multi-pass example files render as written from their own folder: the bump-map
/// file (shader-rendered height map, MakeBump, bump()) and the shadow-map file (zfile pass,
/// MakeShadow, shadowspot) — checked on their pictures, not just their exit codes.
#[test]
fn multipass_examples_render_from_their_folders() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples");
    let dir = tmpdir("multipass");
    for f in ["bumpteapot.rib", "bumpplastic.sl", "tileheight.sl"] {
        std::fs::copy(root.join("bump").join(f), dir.join(f)).unwrap();
    }
    std::fs::copy(
        root.join("shadows/spotshadow.rib"),
        dir.join("spotshadow.rib"),
    )
    .unwrap();
    for rib in ["bumpteapot.rib", "spotshadow.rib"] {
        let out = arbor()
            .arg("render")
            .arg(rib)
            .current_dir(&dir)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{rib}: {err}");
        assert!(!err.contains("warning"), "{rib} warned:\n{err}");
    }
    assert!(dir.join("tiles.bump").exists() && dir.join("spot.tex").exists());
    // The bump map shows: along a row through the teapot's body the shading has many
    // light/dark alternations (grout lines), far more than smooth plastic would.
    let img = image::open(dir.join("bumpteapot.png")).unwrap().to_luma8();
    let y = img.height() * 11 / 20;
    let row: Vec<i32> = (img.width() / 4..img.width() * 3 / 4)
        .map(|x| img.get_pixel(x, y)[0] as i32)
        .collect();
    let swings = row.windows(2).filter(|w| (w[1] - w[0]).abs() > 12).count();
    assert!(swings > 10, "only {swings} strong steps along the row");
    // The shadow map shows: under the sphere the floor is darker than beside it.
    let shadow = image::open(dir.join("spotshadow.png")).unwrap().to_luma8();
    let (under, beside) = (shadow.get_pixel(160, 142)[0], shadow.get_pixel(100, 150)[0]);
    assert!(under < 40 && beside > 120, "under {under}, beside {beside}");
}

/// `-o` on a multi-pass file replaces the beauty picture, not the depth pass that a later
/// frame's MakeShadow reads.
#[test]
fn output_override_skips_depth_passes() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples");
    let dir = tmpdir("override-multipass");
    std::fs::copy(
        root.join("shadows/spotshadow.rib"),
        dir.join("spotshadow.rib"),
    )
    .unwrap();
    let out = arbor()
        .args(["render", "spotshadow.rib", "-o", "beauty.png"])
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        dir.join("spot.z").exists() && dir.join("spot.tex").exists(),
        "{err}"
    );
    assert!(!dir.join("spotshadow.png").exists());
    let img = image::open(dir.join("beauty.png")).unwrap();
    assert_eq!((img.width(), img.height()), (320, 240));
}

/// A missing light shader is reported even when no surface asks for lights (constant).
#[test]
fn a_missing_light_shader_is_reported_even_when_unused() {
    let dir = tmpdir("missing-light");
    let rib = "Display \"x.png\" \"file\" \"rgb\"\nFormat 16 16 1\nWorldBegin\n\
               LightSource \"nosuchlight\" 1\nSurface \"constant\"\nSphere 1 -1 1 360\nWorldEnd\n";
    let (code, err) = run_stdin(&["render", "-"], rib, &dir);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("nosuchlight") && err.contains("not found"),
        "{err}"
    );
}

#[test]
fn ignored_renderer_settings_show_only_with_verbose() {
    let dir = tmpdir("notes");
    let rib = "Format 8 8 1\nWorldBegin\nAttribute \"dice\" \"rasterorient\" [0]\nSphere 1 -1 1 360\nWorldEnd\n";
    std::fs::write(dir.join("n.rib"), rib).unwrap();
    let quiet = arbor()
        .args(["check", "n.rib"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(quiet.status.success());
    let q = String::from_utf8_lossy(&quiet.stderr);
    assert!(!q.contains("rasterorient"), "{q}");
    let loud = arbor()
        .args(["-v", "check", "n.rib"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(loud.status.success());
    let l = String::from_utf8_lossy(&loud.stderr);
    assert!(
        l.contains("rasterorient") && l.contains("scene::ignored-setting"),
        "{l}"
    );
    // A geometry-only archive: one warning, exit 0.
    std::fs::write(dir.join("a.rib"), "Sphere 1 -1 1 360\nCone 1 1 360\n").unwrap();
    let a = arbor()
        .args(["render", "a.rib"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(a.status.success());
    let e = String::from_utf8_lossy(&a.stderr);
    assert!(
        e.contains("looks like an archive") && !e.contains("outside `WorldBegin`"),
        "{e}"
    );
}

#[test]
fn a_reader_that_stops_early_ends_the_output_quietly() {
    // `arbor format big.rib | head`: the pipe closes before the text is written (more than a
    // pipe's buffer), which ends the output without a panic.
    let dir = tmpdir("pipe");
    let mut rib = String::from("WorldBegin\n");
    for i in 0..4000 {
        rib.push_str(&format!("Translate {i} 0 0\nSphere 1 -1 1 360\n"));
    }
    rib.push_str("WorldEnd\n");
    std::fs::write(dir.join("big.rib"), &rib).unwrap();
    let mut child = arbor()
        .args(["format", "big.rib"])
        .current_dir(&*dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
}

#[test]
fn an_exported_package_with_the_authors_absolute_paths_renders_from_its_own_folder() {
    // Exporters write every archive and the output as full paths on the author's machine;
    // the package's copies lie beside the scene and the picture goes to the working folder.
    let dir = tmpdir("foreign");
    let pkg = dir.join("Sphere");
    std::fs::create_dir_all(pkg.join("Worlds")).unwrap();
    std::fs::create_dir_all(pkg.join("Objects")).unwrap();
    let home = "/home/author-not-here/presets/Sphere";
    std::fs::write(
        pkg.join("preview.rib"),
        format!(
            "Display \"{home}/images/preview.png\" \"png\" \"rgb\"\nFormat 16 16 1\n\
             Projection \"perspective\" \"fov\" 40\nTranslate 0 0 4\n\
             ReadArchive \"{home}/Worlds/world.rib\"\n"
        ),
    )
    .unwrap();
    std::fs::write(
        pkg.join("Worlds/world.rib"),
        format!(
            "WorldBegin\nLightSource \"distantlight\" 1\n\
             ReadArchive \"{home}/Objects/ball.rib\"\nWorldEnd\n"
        ),
    )
    .unwrap();
    std::fs::write(
        pkg.join("Objects/ball.rib"),
        "Surface \"matte\"\nSphere 1 -1 1 360\n",
    )
    .unwrap();
    let out = arbor()
        .args(["render", "Sphere/preview.rib"])
        .current_dir(&*dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    // The messages wrap: compare them with the line breaks and gutters taken out.
    let flat = err
        .replace('│', " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    assert!(flat.contains("is not on this machine"), "{err}");
    assert!(flat.contains("does not exist here"), "{err}");
    let img = image::open(dir.join("preview.png")).unwrap().to_rgb8();
    // The sphere (read through both archives) is lit in the middle.
    assert!(img.get_pixel(8, 8)[0] > 40, "{:?}", img.get_pixel(8, 8));
}

/// The floats of a 32-bit float TIFF.
fn float_tiff(path: &std::path::Path) -> Vec<f32> {
    let mut d = tiff::decoder::Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
    match d.read_image().unwrap() {
        tiff::decoder::DecodingResult::F32(v) => v,
        _ => panic!("not a float TIFF"),
    }
}

// Found by fuzzing (fuzz3): shader parameters mutated to 1e38 gave infinite pixels in float
// pictures. Shaders' own NaN and infinities are caught when shaded; an imager shader writes
// the film directly and Exposure's gain can carry a value past the float range.
#[test]
fn no_picture_holds_nan_or_infinite_values() {
    let dir = tmpdir("nonfinite");
    std::fs::write(
        dir.join("blowup.sl"),
        "imager blowup(float k = 1e38) { Ci = color(k * 10, 0, 0); }\n",
    )
    .unwrap();
    let scene = |first: &str, name: &str| {
        format!(
            "{first}\nFormat 8 8 1\nDisplay \"{name}\" \"tiff\" \"rgba\"\nQuantize \"rgba\" 0 0 0 0\n\
             Projection \"orthographic\"\nWorldBegin\nSurface \"constant\"\nColor 100 50 25\n\
             Polygon \"P\" [-2 -2 1  2 -2 1  2 2 1  -2 2 1]\nWorldEnd\n"
        )
    };
    for (first, name) in [
        ("Imager \"blowup\"", "imager.tif"),
        ("Exposure 1e38 1", "exposure.tif"),
    ] {
        let (code, err) = run_stdin(&["render", "--shaders", "."], &scene(first, name), &dir);
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("NaN or infinite"), "{name}: {err}");
        let px = float_tiff(&dir.join(name));
        assert_eq!(px.len(), 8 * 8 * 4);
        assert!(px.iter().all(|v| v.is_finite()), "{name}: {px:?}");
    }
}
