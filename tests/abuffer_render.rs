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

fn render_with_diags(text: &str) -> (Film, Diagnostics) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let films = render_text(text, &Settings::default(), &sources, &diags);
    assert!(!diags.has_errors(), "{}", diags.render_plain(&sources));
    (films.into_iter().next().expect("one film"), diags)
}

#[test]
fn a_full_fragment_pool_is_reported_once() {
    // Four half-opaque layers over 8×8 pixels need 256 fragments in the one bucket.
    let text = layers(&[0, 1, 2, 3]).replace(
        "Hider \"abuffer\"",
        "Hider \"abuffer\" \"integer fragmentlimit\" [100]",
    );
    let (film, diags) = render_with_diags(&text);
    let hits: Vec<_> = diags
        .snapshot()
        .into_iter()
        .filter(|(d, _)| d.message.contains("fragment pool full"))
        .collect();
    assert_eq!(hits.len(), 1, "{:?}", diags.snapshot());
    assert_eq!(hits[0].1, 1, "reported once per render");
    assert!(
        hits[0].0.message.contains("merged"),
        "{}",
        hits[0].0.message
    );
    // Degraded, not broken: every pixel is still covered.
    assert!(film.pixel(3, 3)[3] > 0.49);
    // Within the bound nothing is reported.
    let (_, quiet) = render_with_diags(&layers(&[0, 1, 2, 3]));
    assert!(quiet.snapshot().is_empty(), "{:?}", quiet.snapshot());
}

/// The radial-line test pattern of Watt & Watt Fig 4.19 (as examples/abuffer-testpattern.rib):
/// 32 thin black wedges (1.2° wide) from the centre of an `n`×`n` image, and their raster
/// triangles.
fn radial_pattern(n: usize, mask: usize) -> (String, Vec<[[f64; 2]; 3]>) {
    let mut s = format!(
        "Format {n} {n} 1\nPixelFilter \"box\" 1 1\nProjection \"orthographic\"\n\
         ScreenWindow -1 1 -1 1\nHider \"abuffer\" \"integer masksize\" [{mask}]\n\
         WorldBegin\nSurface \"constant\"\nColor [1 1 1]\n\
         Polygon \"P\" [-2 -2 2  2 -2 2  2 2 2  -2 2 2]\nColor [0 0 0]\n"
    );
    let mut tris = Vec::new();
    let raster = |x: f64, y: f64| [(x + 1.0) * 0.5 * n as f64, (1.0 - y) * 0.5 * n as f64];
    for k in 0..32 {
        let a0 = (2.2646 + 11.25 * k as f64).to_radians();
        let a1 = a0 + 1.2f64.to_radians();
        let (p, q) = (
            [0.95 * a0.cos(), 0.95 * a0.sin()],
            [0.95 * a1.cos(), 0.95 * a1.sin()],
        );
        // The f32 values the renderer sees.
        let (p, q) = (p.map(|v| v as f32 as f64), q.map(|v| v as f32 as f64));
        s += &format!(
            "Polygon \"P\" [0 0 1  {} {} 1  {} {} 1]\n",
            p[0] as f32, p[1] as f32, q[0] as f32, q[1] as f32
        );
        tris.push([raster(0.0, 0.0), raster(p[0], p[1]), raster(q[0], q[1])]);
    }
    (s + "WorldEnd\n", tris)
}

/// Area of triangle `t` inside the unit pixel (x, y).
fn pixel_area(t: &[[f64; 2]; 3], x: f64, y: f64) -> f64 {
    let mut poly: Vec<[f64; 2]> = t.to_vec();
    // Clip by x ≥ x, x ≤ x+1, y ≥ y, y ≤ y+1 (Sutherland–Hodgman).
    for (axis, bound, keep_above) in [
        (0, x, true),
        (0, x + 1.0, false),
        (1, y, true),
        (1, y + 1.0, false),
    ] {
        let inside = |p: &[f64; 2]| {
            if keep_above {
                p[axis] >= bound
            } else {
                p[axis] <= bound
            }
        };
        let mut out = Vec::new();
        for i in 0..poly.len() {
            let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
            if inside(&p) {
                out.push(p);
            }
            if inside(&p) != inside(&q) {
                let t = (bound - p[axis]) / (q[axis] - p[axis]);
                out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
        poly = out;
        if poly.is_empty() {
            return 0.0;
        }
    }
    let m = poly.len();
    0.5 * (0..m)
        .map(|i| poly[i][0] * poly[(i + 1) % m][1] - poly[(i + 1) % m][0] * poly[i][1])
        .sum::<f64>()
        .abs()
}

/// Grey levels of the pattern's partly covered pixels away from the hub: (distinct levels,
/// worst and RMS error against the exact covered area).
fn pattern_stats(n: usize, mask: usize) -> (usize, f64, f64) {
    let (text, tris) = radial_pattern(n, mask);
    let film = render_one(&text);
    let mut levels = std::collections::BTreeSet::new();
    let (mut worst, mut sum, mut count) = (0f64, 0f64, 0usize);
    let c = n as f64 * 0.5;
    for y in 0..n {
        for x in 0..n {
            // Pixels near the hub hold many wedge tips; the book's picture is about the lines.
            let (dx, dy) = (x as f64 + 0.5 - c, y as f64 + 0.5 - c);
            if (dx * dx + dy * dy).sqrt() < 0.2 * n as f64 {
                continue;
            }
            let exact: f64 = tris.iter().map(|t| pixel_area(t, x as f64, y as f64)).sum();
            if exact <= 0.0 {
                continue;
            }
            let grey = film.pixel(x, y)[0] as f64;
            let err = (1.0 - grey - exact).abs();
            worst = worst.max(err);
            sum += err * err;
            count += 1;
            if grey > 1e-4 && grey < 1.0 - 1e-4 {
                levels.insert((grey * 65536.0).round() as i64);
            }
        }
    }
    (levels.len(), worst, (sum / count as f64).sqrt())
}

#[test]
fn the_radial_pattern_shows_more_grey_levels_at_16x16() {
    // Watt & Watt on Fig 4.19: the 16×16 mask "gives a less coarse discretization of fragment
    // area which manifests in the larger number of grey levels". At 8×8 a pixel can only be
    // k/64 grey; at 16×16, k/256.
    let (l8, w8, r8) = pattern_stats(96, 8);
    let (l16, w16, r16) = pattern_stats(96, 16);
    eprintln!("mask 8: {l8} grey levels, worst {w8:.4}, RMS {r8:.4}");
    eprintln!("mask 16: {l16} grey levels, worst {w16:.4}, RMS {r16:.4}");
    assert!(l8 <= 63, "{l8} levels cannot come from 64-cell masks");
    assert!(l16 > l8 + l8 / 2, "16×16 {l16} levels vs 8×8 {l8}");
    // Each grey is the wedges' exact area to within the mask's resolution, and the finer
    // mask is closer.
    // (Measured: 58 vs 215 levels; worst 0.053 vs 0.024, RMS 0.0137 vs 0.0061. The worst
    // pixels hold micropolygon corners of the diced wedges, where edges follow the cell
    // centres.)
    assert!(w8 <= 4.0 / 64.0 && w16 < w8, "worst {w8} {w16}");
    assert!(r8 <= 1.0 / 64.0 && r16 < 0.5 * r8, "RMS {r16} vs {r8}");
}
