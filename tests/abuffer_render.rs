//! Whole-pipeline checks of `Hider "abuffer"`: transparent layers in any order, an
//! interpenetration line, and agreement with the Z-buffer hider at 16×16 samples.

use std::time::Instant;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::film::Film;
use arbor::pipeline::{render_text, Settings};

fn render_one(text: &str) -> Film {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let films = render_text(text, &Settings::default(), &sources, &diags);
    assert!(!diags.has_errors(), "{}", diags.render_plain(&sources));
    films.into_iter().next().expect("one film")
}

fn layers(order: &[usize]) -> String {
    let mut s = String::from(
        "Format 8 8 1\nPixelFilter \"box\" 1 1\nProjection \"orthographic\"\n\
         Hider \"abuffer\"\nWorldBegin\nSurface \"constant\"\nOpacity [0.5 0.5 0.5]\n",
    );
    for &k in order {
        s += &format!(
            "Color [1 1 1]\nPolygon \"P\" [-2 -2 {z} 2 -2 {z} 2 2 {z} -2 2 {z}]\n",
            z = 1 + k
        );
    }
    s + "WorldEnd\n"
}

#[test]
fn half_opaque_layers_in_any_order() {
    for n in 1..=4usize {
        let fwd: Vec<usize> = (0..n).collect();
        let mut rev = fwd.clone();
        rev.reverse();
        let (a, b) = (render_one(&layers(&fwd)), render_one(&layers(&rev)));
        let want = 1.0 - 0.5f32.powi(n as i32);
        for (x, y) in [(0, 0), (4, 4), (7, 3)] {
            assert!(
                (a.pixel(x, y)[3] - want).abs() < 1e-5,
                "{n}: {:?}",
                a.pixel(x, y)
            );
            assert!((a.pixel(x, y)[0] - want).abs() < 1e-5);
            assert_eq!(a.pixel(x, y), b.pixel(x, y));
        }
    }
}

#[test]
fn interpenetrating_planes_mix_along_the_line() {
    // A red plane tilted in x through a blue plane at z = 5: they cross along x = 0.
    let f = render_one(
        "Format 17 8 1\nPixelFilter \"box\" 1 1\nProjection \"orthographic\"\n\
         ScreenWindow -1 1 -1 1\nHider \"abuffer\"\nWorldBegin\nSurface \"constant\"\n\
         Color [0 0 1]\nPolygon \"P\" [-2 -2 5 2 -2 5 2 2 5 -2 2 5]\n\
         Color [1 0 0]\nPolygon \"P\" [-2 -2 3 2 -2 7 2 2 7 -2 2 3]\nWorldEnd\n",
    );
    // Left of the line red is in front, right of it blue; the centre column is a mix, and
    // every row sees the same colour (a straight, un-jagged line).
    assert!(f.pixel(2, 4)[0] > 0.99 && f.pixel(14, 4)[2] > 0.99);
    let mid = f.pixel(8, 4);
    assert!(
        mid[0] > 0.2 && mid[0] < 0.8 && (mid[0] + mid[2] - 1.0).abs() < 1e-4,
        "{mid:?}"
    );
    for y in 0..8 {
        for x in 0..17 {
            assert!(
                (f.pixel(x, y)[0] - f.pixel(x, 4)[0]).abs() < 1e-4,
                "{x},{y}"
            );
        }
    }
}

const SCENE: &str = r#"Format 96 72 1
PixelFilter "box" 1 1
Projection "perspective" "fov" 40
HIDER
WorldBegin
LightSource "distantlight" 1 "from" [1 1 -1] "to" [0 0 0]
Translate 0 0 6
Color [0.9 0.5 0.2]
Surface "matte"
Sphere 1.2 -1.2 1.2 360
Color [0.2 0.4 0.9]
Opacity [0.6 0.6 0.6]
Rotate 40 1 1 0
Polygon "P" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]
WorldEnd
"#;

#[test]
fn matches_the_zbuffer_at_16x16_samples() {
    let t = Instant::now();
    let a = render_one(&SCENE.replace("HIDER", "Hider \"abuffer\" \"integer masksize\" [8]"));
    let ta = t.elapsed();
    let t = Instant::now();
    let z = render_one(&SCENE.replace("HIDER", "PixelSamples 16 16"));
    let tz = t.elapsed();
    let mut sum = 0f64;
    let mut n = 0usize;
    for y in 0..72 {
        for x in 0..96 {
            for c in 0..4 {
                let d = (a.pixel(x, y)[c] - z.pixel(x, y)[c]) as f64;
                sum += d * d;
                n += 1;
            }
        }
    }
    let rms = (sum / n as f64).sqrt();
    eprintln!("abuffer 8x8: {ta:?}, zbuffer 16x16: {tz:?}, RMS {rms:.5}");
    assert!(rms < 0.01, "RMS {rms}");
}
