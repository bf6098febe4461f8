//! Render tests of SubdivisionMesh, Points and Curves: holes leave pixels empty, points cover
//! their analytic area, a straight curve covers its rectangle, and the example scene renders.
//! `SUBDIV_WRITE=1` also writes examples/subdiv.png from examples/subdiv.rib.

use arbor::diag::{Diagnostics, SourceMap};
use arbor::film::Film;
use arbor::pipeline::{render_text, Settings};

fn render(text: &str) -> (Film, String) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let films = render_text(text, &Settings::default(), &sources, &diags);
    let report = diags.render_plain(&sources);
    assert!(!diags.has_errors(), "{report}");
    assert_eq!(films.len(), 1, "{report}");
    (films.into_iter().next().unwrap(), report)
}

fn alpha(f: &Film, x: usize, y: usize) -> f32 {
    f.pixel(x, y)[3]
}

fn coverage(f: &Film) -> f32 {
    let mut a = 0.0;
    for y in 0..f.height {
        for x in 0..f.width {
            a += alpha(f, x, y);
        }
    }
    a
}

/// Orthographic 64×64 view of [-4, 4]²: 8 pixels per unit.
const HEAD: &str = r#"Format 64 64 1
    PixelSamples 4 4
    PixelFilter "box" 1 1
    Projection "orthographic"
    ScreenWindow -4 4 -4 4
    WorldBegin
    Surface "constant"
    Translate 0 0 5
"#;

#[test]
fn subdivision_hole_faces_are_not_rendered() {
    // A 3×3 grid of quads with interpolateboundary; the centre face is a hole.
    let mut p = String::new();
    for j in 0..4 {
        for i in 0..4 {
            p += &format!("{} {} 0  ", i as f32 * 2.0 - 3.0, j as f32 * 2.0 - 3.0);
        }
    }
    let mut faces = String::new();
    for j in 0..3 {
        for i in 0..3 {
            let a = j * 4 + i;
            faces += &format!("{} {} {} {}  ", a, a + 1, a + 5, a + 4);
        }
    }
    let rib = format!(
        "{HEAD}SubdivisionMesh \"catmull-clark\" [4 4 4 4 4 4 4 4 4] [{faces}]
         [\"interpolateboundary\" \"hole\"] [0 0 1 0] [4] [] \"P\" [{p}]\nWorldEnd"
    );
    let (f, _) = render(&rib);
    // The centre pixel (the hole) is empty, a point inside a neighbouring face is covered.
    assert_eq!(alpha(&f, 32, 32), 0.0);
    assert!(alpha(&f, 32, 14) > 0.99, "{}", alpha(&f, 32, 14));
    assert!(alpha(&f, 14, 32) > 0.99);
    // Corners are kept by interpolateboundary: the pixel just inside (-3,-3) is covered.
    assert!(alpha(&f, 9, 9) > 0.5, "{}", alpha(&f, 9, 9));
}

#[test]
fn points_cover_their_analytic_area() {
    // 9 disks of diameter 1 (8 px): each covers π·4² ≈ 50.27 pixels.
    let mut p = String::new();
    for j in 0..3 {
        for i in 0..3 {
            p += &format!("{} {} 0  ", i as f32 * 2.5 - 2.5, j as f32 * 2.5 - 2.5);
        }
    }
    let (f, _) = render(&format!(
        "{HEAD}Points \"P\" [{p}] \"constantwidth\" [1]\nWorldEnd"
    ));
    let want = 9.0 * std::f32::consts::PI * 16.0;
    let got = coverage(&f);
    assert!(
        (got - want).abs() < 0.03 * want,
        "coverage {got}, want {want}"
    );
    // Each disk's centre is covered and the gap between disks is empty.
    assert!(alpha(&f, 32, 32) > 0.99);
    assert_eq!(alpha(&f, 42, 32), 0.0);
    // Disks are round: a pixel near the bounding square's corner is empty.
    assert!(alpha(&f, 34, 34) > 0.5);
    assert_eq!(alpha(&f, 28, 28), 0.0);
}

#[test]
fn many_points_render() {
    let mut p = String::new();
    for k in 0..5000 {
        let x = ((k * 37) % 101) as f32 / 101.0 * 7.0 - 3.5;
        let y = ((k * 53) % 103) as f32 / 103.0 * 7.0 - 3.5;
        p += &format!("{x} {y} 0 ");
    }
    let (f, _) = render(&format!(
        "{HEAD}Points \"P\" [{p}] \"constantwidth\" [0.05]\nWorldEnd"
    ));
    assert!(coverage(&f) > 10.0);
}

#[test]
fn straight_linear_curve_covers_its_rectangle() {
    // From x = -3 to 3 at y = 0, width 1: a 48 × 8 pixel rectangle.
    let (f, _) = render(&format!(
        "{HEAD}Curves \"linear\" [2] \"nonperiodic\" \"P\" [-3 0 0  3 0 0] \"constantwidth\" [1]\nWorldEnd"
    ));
    let got = coverage(&f);
    assert!((got - 384.0).abs() < 8.0, "coverage {got}");
    assert!(alpha(&f, 32, 30) > 0.99 && alpha(&f, 32, 33) > 0.99);
    assert_eq!(alpha(&f, 32, 26), 0.0);
    assert_eq!(alpha(&f, 5, 32), 0.0);
}

#[test]
fn cubic_periodic_curves_and_example_scene_render() {
    let (f, report) = render(&format!(
        "{HEAD}Basis \"b-spline\" 1 \"b-spline\" 1
         Curves \"cubic\" [4] \"periodic\" \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0] \"constantwidth\" [0.3]\nWorldEnd"
    ));
    assert!(!report.contains("geom::unsupported"), "{report}");
    assert!(coverage(&f) > 50.0);
    // The closed B-spline loop leaves its centre empty.
    assert_eq!(alpha(&f, 32, 32), 0.0);
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/subdiv.rib");
    let text = std::fs::read_to_string(path).unwrap();
    let (f, report) = render(&text);
    assert!(!report.contains("geom::unsupported"), "{report}");
    assert!(coverage(&f) > 1000.0);
    if std::env::var_os("SUBDIV_WRITE").is_some() {
        let mut img = image::RgbImage::new(f.width as u32, f.height as u32);
        for y in 0..f.height {
            for x in 0..f.width {
                let p = f.pixel(x, y);
                let q = |v: f32| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8;
                img.put_pixel(x as u32, y as u32, image::Rgb([q(p[0]), q(p[1]), q(p[2])]));
            }
        }
        img.save(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/subdiv.png"))
            .unwrap();
    }
}
