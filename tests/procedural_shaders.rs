//! The procedural and reflection-model shaders of stdlib/shaders: they compile, `arbor shade`
//! renders them, and small swatches match golden images (tests/golden/procedural_*.png).

mod common;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::sl::ast::ShaderKind;
use arbor::sl::ShaderLibrary;
use arbor::swatch::{swatch_rib, SwatchObject};
use common::{check_golden, film_rgb, manifest_dir, render_rib, stdlib_options, Tolerance};

/// The shaders this library adds (the 15 RISpec standard shaders are tested elsewhere).
const SHADERS: &[&str] = &[
    "marble",
    "wood",
    "granite",
    "clouds",
    "flame",
    "terrain",
    "planet",
    "texturetree",
    "cooktorrance",
    "torrancesparrow",
    "phongplastic",
    "blinnplastic",
    "brushedmetal",
    "orennayar",
    "glass",
];

#[test]
fn every_new_stdlib_shader_compiles_cleanly() {
    let lib = ShaderLibrary::new(stdlib_options(&[]));
    for name in SHADERS {
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let prog = lib.get(name, &sources, &diags);
        let msgs: Vec<String> = diags
            .snapshot()
            .iter()
            .map(|(d, _)| d.message.clone())
            .collect();
        let prog = prog.unwrap_or_else(|| panic!("{name} does not compile: {msgs:#?}"));
        assert!(msgs.is_empty(), "{name}: {msgs:#?}");
        assert_eq!(prog.kind, ShaderKind::Surface, "{name}");
        assert_eq!(prog.name, *name);
    }
}

#[test]
fn headers_compile_on_their_own() {
    // Each header can be included alone (its own #includes and guards are right).
    let dir = common::scratch_dir("procedural_headers");
    for h in ["filterwidth.h", "noises.h", "patterns.h", "reflectance.h"] {
        let src = format!("#include \"{h}\"\n#include \"{h}\"\nsurface t() {{ Ci = 1; }}\n");
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let progs = arbor::sl::compile_source(
            "t.sl",
            &src,
            Some(&dir.join("t.sl")),
            &sources,
            &diags,
            &stdlib_options(&[]),
        );
        assert_eq!(progs.len(), 1, "{h}: {:?}", diags.snapshot());
        assert!(!diags.has_errors());
    }
}

fn swatch(shader: &str, params: &[&str], object: SwatchObject, size: u32) -> Vec<f32> {
    let params: Vec<String> = params.iter().map(|s| s.to_string()).collect();
    let rib = swatch_rib(ShaderKind::Surface, shader, &params, object, size, 2);
    film_rgb(&render_rib(&rib, &[]))
}

#[test]
fn gallery_swatches_match_golden_images() {
    let cases: &[(&str, &str, &[&str], SwatchObject)] = &[
        ("procedural_marble", "marble", &[], SwatchObject::Sphere),
        ("procedural_wood", "wood", &[], SwatchObject::Sphere),
        ("procedural_granite", "granite", &[], SwatchObject::Sphere),
        (
            "procedural_copper",
            "cooktorrance",
            &["\"string metal\" [\"copper\"]", "\"float roughness\" [0.2]"],
            SwatchObject::Sphere,
        ),
        (
            "procedural_texturetree",
            "texturetree",
            &[],
            SwatchObject::Plane,
        ),
        ("procedural_planet", "planet", &[], SwatchObject::Sphere),
    ];
    for (golden, shader, params, object) in cases {
        let rgb = swatch(shader, params, *object, 64);
        // not blank: the swatch covers a good part of the frame
        let lit = rgb
            .chunks_exact(3)
            .filter(|p| p.iter().sum::<f32>() > 0.05)
            .count();
        assert!(lit > 64 * 64 / 5, "{shader}: only {lit} lit pixels");
        check_golden(golden, 64, 64, &rgb, Tolerance::default());
    }
}

#[test]
fn fractal_terrain_renders_as_a_landscape() {
    let rib = r#"Format 64 48 1
PixelSamples 2 2
Projection "perspective" "fov" [40]
Rotate -15 1 0 0
Translate 0 -0.6 2.2
Display "t" "file" "rgb"
WorldBegin
  LightSource "ambientlight" 1 "intensity" [0.15]
  LightSource "distantlight" 2 "from" [-1 2 -1] "to" [0 0 0]
  Surface "terrain" "float maxheight" [0.5] "float minheight" [-0.1]
  Geometry "fractalterrain" "constant float size" [3] "constant float levels" [6]
      "constant float H" [0.8] "constant float height" [0.35] "constant float seed" [7]
WorldEnd
"#;
    let rgb = film_rgb(&render_rib(rib, &[]));
    let lit = rgb
        .chunks_exact(3)
        .filter(|p| p.iter().sum::<f32>() > 0.05)
        .count();
    assert!(lit > 64 * 48 / 3, "terrain covers only {lit} pixels");
    check_golden("procedural_terrain", 64, 48, &rgb, Tolerance::default());
}

#[test]
fn arbor_shade_writes_an_image() {
    let out = common::scratch_dir("procedural_cli").join("marble.png");
    let _ = std::fs::remove_file(&out);
    let root = manifest_dir().join("stdlib");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_arbor"))
        .args([
            "-q",
            "shade",
            "marble",
            "-p",
            "veinfreq=4",
            "-p",
            "basecolor=1 0.9 0.8",
        ])
        .arg("--shaders")
        .arg(root.join("shaders"))
        .arg("-I")
        .arg(root.join("include"))
        .args(["--size", "96", "-o"])
        .arg(&out)
        .status()
        .expect("run arbor");
    assert!(status.success());
    let img = image::open(&out).expect("read swatch").to_rgba8();
    assert_eq!(img.dimensions(), (96, 96));
    // the sphere is opaque in the middle and the corners are empty
    assert_eq!(img.get_pixel(48, 48)[3], 255);
    assert_eq!(img.get_pixel(0, 0)[3], 0);
    // a misspelt parameter is an error
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_arbor"))
        .args(["-q", "shade", "plastic", "-p", "Kss=1", "-o"])
        .arg(&out)
        .status()
        .expect("run arbor");
    assert!(!bad.success());
}
