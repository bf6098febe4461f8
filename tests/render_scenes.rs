//! Whole-pipeline render tests: analytic checks (DESIGN.md §4), determinism across thread
//! counts and bucket sizes, and golden images of small scenes under `tests/golden/`.
//!
//! Golden comparison is in linear float: a test fails when more than 0.05 % of the channel
//! values differ by more than 0.004, or any by more than 0.1. On failure the actual image and a
//! ×10 difference image are written under `target/golden-failures/`. `UPDATE_GOLDEN=1`
//! rewrites the references (commit them only when the change is intended).

mod common;

use std::path::PathBuf;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::film::Film;
use arbor::pipeline::{render_text, Settings};

fn render(text: &str, settings: &Settings) -> (Vec<Film>, String, bool) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let films = render_text(text, settings, &sources, &diags);
    let report = diags.render_plain(&sources);
    (films, report, diags.has_errors())
}

fn render_one(text: &str) -> Film {
    let (films, report, errors) = render(text, &Settings::default());
    assert!(!errors, "{report}");
    assert_eq!(films.len(), 1, "{report}");
    films.into_iter().next().unwrap()
}

fn px(f: &Film, x: usize, y: usize) -> [f32; 4] {
    let p = f.pixel(x, y);
    [p[0], p[1], p[2], p[3]]
}

#[test]
fn constant_surface_over_the_frame_equals_cs() {
    let f = render_one(
        r#"Format 32 24 1
        PixelSamples 3 3
        Projection "orthographic"
        ScreenWindow -1 1 -1 1
        WorldBegin
        Color [0.25 0.5 0.75]
        Surface "constant"
        Polygon "P" [-5 -5 1  5 -5 1  5 5 1  -5 5 1]
        WorldEnd"#,
    );
    for y in 0..24 {
        for x in 0..32 {
            let p = px(&f, x, y);
            assert!(
                (p[0] - 0.25).abs() < 1e-5
                    && (p[1] - 0.5).abs() < 1e-5
                    && (p[2] - 0.75).abs() < 1e-5,
                "{x},{y}: {p:?}"
            );
            assert!((p[3] - 1.0).abs() < 1e-6);
        }
    }
}

#[test]
fn matte_sphere_lit_head_on_has_centre_kd_cs() {
    // distantlight of intensity 1 shining along +z (from the eye); Ka has no ambient light.
    let f = render_one(
        r#"Format 41 41 1
        PixelSamples 4 4
        PixelFilter "box" 1 1
        Projection "orthographic"
        ScreenWindow -1.2 1.2 -1.2 1.2
        WorldBegin
        LightSource "distantlight" 1 "from" [0 0 -1] "to" [0 0 0]
        Color [0.8 0.6 0.4]
        Surface "matte" "Kd" [0.5]
        Translate 0 0 5
        Sphere 1 -1 1 360
        WorldEnd"#,
    );
    let p = px(&f, 20, 20);
    let want = [0.4, 0.3, 0.2];
    for c in 0..3 {
        assert!((p[c] - want[c]).abs() < 0.01, "centre {p:?} want {want:?}");
    }
}

#[test]
fn four_layers_of_half_opacity_transmit_one_sixteenth() {
    let mut rib = String::from(
        "Format 8 8 1\nPixelSamples 2 2\nProjection \"orthographic\"\nWorldBegin\nSurface \"constant\"\nOpacity [0.5 0.5 0.5]\n",
    );
    for z in 1..=4 {
        rib.push_str(&format!(
            "Polygon \"P\" [-5 -5 {z}  5 -5 {z}  5 5 {z}  -5 5 {z}]\n"
        ));
    }
    rib.push_str("WorldEnd\n");
    let f = render_one(&rib);
    let p = px(&f, 4, 4);
    assert!((p[3] - (1.0 - 0.5f32.powi(4))).abs() < 1e-4, "alpha {p:?}");
    // White layers over black: premultiplied colour equals alpha.
    assert!((p[0] - p[3]).abs() < 1e-4);
}

#[test]
fn half_covered_edge_pixel_has_half_coverage() {
    // A polygon covering x > 0 exactly: the middle column straddles the edge.
    let f = render_one(
        r#"Format 9 9 1
        PixelSamples 8 8
        PixelFilter "box" 1 1
        Projection "orthographic"
        ScreenWindow -1 1 -1 1
        WorldBegin
        Surface "constant"
        Polygon "P" [0 -5 1  5 -5 1  5 5 1  0 5 1]
        WorldEnd"#,
    );
    let a = px(&f, 4, 4)[3];
    assert!((a - 0.5).abs() <= 2.0 / 8.0, "edge alpha {a}");
    assert!(px(&f, 0, 4)[3] < 1e-6);
    assert!((px(&f, 8, 4)[3] - 1.0).abs() < 1e-6);
}

const SPHERES: &str = r#"
Format 96 72 1
PixelSamples 3 3
Projection "perspective" "fov" [35]
Translate 0 0 6
WorldBegin
LightSource "ambientlight" 1 "intensity" [0.1]
LightSource "distantlight" 2 "from" [-1 1 -1] "to" [0 0 0]
LightSource "pointlight" 3 "from" [2 2 -2] "intensity" [6] "lightcolor" [1 0.8 0.6]
AttributeBegin
  Translate -1.1 0 0
  Color [1 0.3 0.2]
  Surface "plastic" "roughness" [0.08]
  Sphere 1 -1 1 360
AttributeEnd
AttributeBegin
  Translate 1.1 0 0
  Color [0.3 0.5 1]
  Surface "metal"
  Sphere 1 -1 1 300
AttributeEnd
AttributeBegin
  Translate 0 -1 0
  Rotate 90 1 0 0
  Surface "matte"
  Disk 0 3 360
AttributeEnd
WorldEnd
"#;

#[test]
fn output_is_identical_for_any_thread_count_and_bucket_size() {
    let base = Settings {
        threads: 1,
        bucket_size: Some([16, 16]),
        ..Settings::default()
    };
    let (a, ra, _) = render(SPHERES, &base);
    let (b, _, _) = render(
        SPHERES,
        &Settings {
            threads: 2,
            bucket_size: Some([32, 32]),
            ..Settings::default()
        },
    );
    let (c, _, _) = render(
        SPHERES,
        &Settings {
            threads: 2,
            bucket_size: Some([7, 13]),
            ..Settings::default()
        },
    );
    assert_eq!(a.len(), 1, "{ra}");
    assert!(a[0].data == b[0].data, "1 thread/16 vs 2 threads/32 differ");
    assert!(a[0].data == c[0].data, "bucket 16 vs 7x13 differ");
}

// ---- golden images ----

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

fn to_rgba8(f: &Film) -> image::RgbaImage {
    image::RgbaImage::from_fn(f.width as u32, f.height as u32, |x, y| {
        let p = f.pixel(x as usize, y as usize);
        let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        image::Rgba([q(p[0]), q(p[1]), q(p[2]), q(p[3])])
    })
}

/// Compares a film's rgba with a reference PNG (16-bit, linear) within DESIGN.md's tolerance.
/// The references hold the film's premultiplied values as they are (written here, not by
/// arbor's PNG display, which writes straight colour where there is alpha): compare them as
/// data, not as pictures.
fn check_golden(name: &str, f: &Film) {
    let path = golden_dir().join(format!("{name}.png"));
    let actual: image::ImageBuffer<image::Rgba<u16>, Vec<u16>> =
        image::ImageBuffer::from_fn(f.width as u32, f.height as u32, |x, y| {
            let p = f.pixel(x as usize, y as usize);
            let q = |v: f32| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
            image::Rgba([q(p[0]), q(p[1]), q(p[2]), q(p[3])])
        });
    if std::env::var("UPDATE_GOLDEN").is_ok() || !path.exists() {
        if !path.exists() && std::env::var("UPDATE_GOLDEN").is_err() && std::env::var("CI").is_ok()
        {
            panic!("golden image {} is missing", path.display());
        }
        std::fs::create_dir_all(golden_dir()).unwrap();
        actual.save(&path).unwrap();
        return;
    }
    let reference = image::open(&path).unwrap().to_rgba16();
    assert_eq!(
        reference.dimensions(),
        actual.dimensions(),
        "{name}: size changed"
    );
    let mut over = 0usize;
    let mut max = 0f32;
    let total = (f.width * f.height * 4) as f32;
    for (a, b) in actual.as_raw().iter().zip(reference.as_raw()) {
        let d = (*a as f32 - *b as f32).abs() / 65535.0;
        if d > 0.004 {
            over += 1;
        }
        max = max.max(d);
    }
    if over as f32 > total * 0.0005 || max > 0.1 {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/golden-failures");
        std::fs::create_dir_all(&dir).unwrap();
        to_rgba8(f)
            .save(dir.join(format!("{name}-actual.png")))
            .unwrap();
        let diff = image::RgbaImage::from_fn(f.width as u32, f.height as u32, |x, y| {
            let a = actual.get_pixel(x, y);
            let b = reference.get_pixel(x, y);
            let d = |k: usize| {
                ((a[k] as f32 - b[k] as f32).abs() / 65535.0 * 10.0 * 255.0).min(255.0) as u8
            };
            image::Rgba([d(0), d(1), d(2), 255])
        });
        diff.save(dir.join(format!("{name}-diff.png"))).unwrap();
        panic!(
            "{name}: {over} values differ by more than 0.004 (max {max}); see {}",
            dir.display()
        );
    }
}

#[test]
fn golden_spheres() {
    check_golden("spheres", &render_one(SPHERES));
}

#[test]
fn golden_quadrics_and_polygons() {
    let f = render_one(
        r#"Format 120 90 1
        PixelSamples 3 3
        Projection "perspective" "fov" [40]
        Rotate -14 1 0 0
        Translate 0 -2.2 7.5
        WorldBegin
        LightSource "ambientlight" 1 "intensity" [0.15]
        LightSource "spotlight" 2 "from" [0 5 0] "to" [0 0 0] "intensity" [20] "coneangle" [0.6]
        LightSource "distantlight" 3 "from" [1 1 -1] "to" [0 0 0] "intensity" [0.4]
        AttributeBegin
          Surface "matte"
          Color [0.7 0.7 0.6]
          GeneralPolygon [4 3] "P" [-4 0 -3  4 0 -3  4 0 4  -4 0 4   -1 0 -2.5  1 0 -2.5  0 0 -1]
        AttributeEnd
        AttributeBegin
          Translate -2 0.6 1
          Color [0.9 0.5 0.1]
          Surface "plastic"
          Torus 0.5 0.2 0 360 360
        AttributeEnd
        AttributeBegin
          Translate 0 0 1
          Rotate -90 1 0 0
          Color [0.2 0.8 0.3]
          Surface "plastic"
          Hyperboloid 0.8 0 0  0.3 0.3 1.5 360
        AttributeEnd
        AttributeBegin
          Translate 2 0 1
          Rotate -90 1 0 0
          Color [0.3 0.4 0.9]
          Surface "plastic"
          Paraboloid 0.7 0 1.5 360
          Cylinder 0.4 0 0.3 360
        AttributeEnd
        AttributeBegin
          Translate 0 0.8 -1.5
          Color [1 1 1]
          Opacity [0.4 0.4 0.4]
          Surface "plastic"
          Sphere 0.6 -0.6 0.6 360
        AttributeEnd
        WorldEnd"#,
    );
    check_golden("quadrics", &f);
}

/// Renders a 16 × 16 orthographic frame of a red polygon at `polygon` (RIB point list) under
/// the imager `name`, whose source is written to a scratch shader folder.
fn render_with_imager(name: &str, source: &str, polygon: &str) -> (Vec<Film>, String, bool) {
    let dir = common::scratch(&format!("imager-{name}"));
    std::fs::write(dir.join(format!("{name}.sl")), source).unwrap();
    let settings = Settings {
        shader_paths: vec![dir.display().to_string()],
        ..Settings::default()
    };
    render(
        &format!(
            "Format 16 16 1\nImager \"{name}\"\nProjection \"orthographic\"\n\
             ScreenWindow -1 1 -1 1\nWorldBegin\nSurface \"constant\"\nColor [1 0 0]\n\
             Polygon \"P\" [{polygon}]\nWorldEnd\n"
        ),
        &settings,
    )
}

#[test]
fn a_user_imager_shader_runs_over_the_image() {
    let (films, report, errors) = render_with_imager(
        "fill",
        "imager fill(color bg = color(0, 0.5, 1);) { Ci += (1 - alpha) * bg; alpha = 1; }",
        "0 -5 1  5 -5 1  5 5 1  0 5 1",
    );
    assert!(!errors, "{report}");
    let f = &films[0];
    // left half: empty, filled by the imager; right half: the red polygon.
    let l = px(f, 2, 8);
    let r = px(f, 13, 8);
    assert!(
        (l[1] - 0.5).abs() < 1e-5 && (l[2] - 1.0).abs() < 1e-5 && (l[3] - 1.0).abs() < 1e-6,
        "{l:?}"
    );
    assert!((r[0] - 1.0).abs() < 1e-5 && r[1].abs() < 1e-5, "{r:?}");
}

#[test]
fn float_noise_in_the_projective_column_is_not_a_projective_transform() {
    // mtor writes camera matrices like this one (Maya export): the ~1e-10 entries in the
    // fourth column are rounding noise, not a perspective divide.
    let (films, report, errors) = render(
        r#"Format 16 12 1
        Projection "perspective" "fov" [40]
        WorldBegin
        ConcatTransform [1 0 0 -3.368e-010  0 1 0 -3.50205e-012  0 0 1 9.40705e-011  0 0 5 1]
        Surface "constant"
        Sphere 1 -1 1 360
        WorldEnd"#,
        &Settings::default(),
    );
    assert!(!errors, "{report}");
    assert!(!report.contains("projective"), "{report}");
    let f = &films[0];
    // The sphere (radius 1 at distance 5, fov 40) covers the centre pixel.
    assert!(px(f, 8, 6)[3] > 0.99, "{:?}", px(f, 8, 6));
}

#[test]
fn a_point_larger_than_a_grid_is_diced_coarser_not_dropped() {
    // One particle 38 pixels across: more micropolygons than a grid may hold, and a lone
    // point cannot be split (Aqsis's regression scene Bug1310740 lost all its particles).
    let (films, report, errors) = render(
        r#"Format 64 64 1
        PixelSamples 4 4
        PixelFilter "box" 1 1
        Projection "orthographic"
        ScreenWindow -1 1 -1 1
        WorldBegin
        Surface "constant"
        Color [0 1 0]
        Points "P" [0 0 1] "constantwidth" [1.2]
        WorldEnd"#,
        &Settings::default(),
    );
    assert!(!errors, "{report}");
    assert!(!report.contains("dropped"), "{report}");
    let f = &films[0];
    assert_eq!(px(f, 32, 32), [0.0, 1.0, 0.0, 1.0]);
    // Covered area in screen units against the disk's π r² (r = 0.6).
    let mut cover = 0.0;
    for y in 0..64 {
        for x in 0..64 {
            cover += px(f, x, y)[3];
        }
    }
    let area = cover * (2.0f32 / 64.0).powi(2);
    let want = std::f32::consts::PI * 0.36;
    assert!((area - want).abs() < 0.03 * want, "{area} vs {want}");
}

#[test]
fn an_imager_that_sets_oi_sets_the_alpha() {
    // RISpec's imager outputs are Ci and Oi: a watermark imager blends its opacity in with
    // `Oi = 1 - (1 - Oi) * (1 - a)` and never names alpha.
    let (films, report, errors) = render_with_imager(
        "mark",
        "imager mark() { float a = 0.5 * step(8, xcomp(P));\n  Ci = Ci * (1 - a) + color(0, 0, 1) * a;\n  Oi = 1 - (1 - Oi) * (1 - a); }",
        "-5 -5 1  5 -5 1  5 0 1  -5 0 1",
    );
    assert!(!errors, "{report}");
    let f = &films[0];
    // Lower half: the red polygon (alpha 1 everywhere); upper half empty: alpha 0 on the
    // left, the watermark's 0.5 on the right.
    assert!((px(f, 2, 13)[3] - 1.0).abs() < 1e-6, "{:?}", px(f, 2, 13));
    assert!(px(f, 2, 3)[3].abs() < 1e-6, "{:?}", px(f, 2, 3));
    let w = px(f, 13, 3);
    assert!(
        (w[3] - 0.5).abs() < 1e-5 && (w[2] - 0.5).abs() < 1e-5,
        "{w:?}"
    );
    let m = px(f, 13, 13);
    assert!(
        (m[3] - 1.0).abs() < 1e-5 && (m[0] - 0.5).abs() < 1e-5,
        "{m:?}"
    );
}

/// Points a trim curve cuts away stay empty whatever the shaders write there: an atmosphere
/// adds its colour even at opacity 0 (Aqsis's Bug1471457 fogged spheres showed their trimmed
/// parts as glowing disks).
#[test]
fn trimmed_points_stay_empty_under_an_atmosphere() {
    let f = render_one(
        r#"Format 32 32 1
        PixelSamples 2 2
        Projection "orthographic"
        ScreenWindow 0 1 0 1
        WorldBegin
        Attribute "trimcurve" "sense" "outside"
        TrimCurve [4] [2 2 2 2] [0 0 1 1 0 0 1 1 0 0 1 1 0 0 1 1] [0 0 0 0] [1 1 1 1] [2 2 2 2]
            [0.25 0.75 0.75 0.75 0.75 0.25 0.25 0.25] [0.25 0.25 0.25 0.75 0.75 0.75 0.75 0.25] [1 1 1 1 1 1 1 1]
        Surface "constant"
        Atmosphere "fog" "distance" [1] "background" [1 1 0]
        NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 "P" [0 0 1  1 0 1  0 1 1  1 1 1]
        WorldEnd"#,
    );
    // The hole's middle: nothing there.
    for (x, y) in [(16, 16), (12, 12), (19, 19)] {
        assert_eq!(px(&f, x, y), [0.0; 4], "{x},{y} lies in the trimmed hole");
    }
    // Outside the loop: the fogged surface.
    let p = px(&f, 2, 2);
    assert!(p[3] > 0.99 && p[0] > 0.5 && p[1] > 0.5, "{p:?}");
}
