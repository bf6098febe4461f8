//! End to end: `MakeHorizon` (an arbor extension) writes horizon tables from a height picture
//! found on the texture search path, and the `horizon()` built-in finds `.hzn` names on the
//! texture search path (`Option "searchpath" "texture"`) like texture() does.

mod common;

use std::path::Path;

use arbor::diag::{Diagnostics, Severity, SourceMap};
use arbor::pipeline::{render_paths, Settings};
use arbor::texture::horizon::{read_height_image, HorizonTable};

fn tmp(name: &str) -> common::Scratch {
    common::scratch(&format!("hzn-{name}"))
}

fn render(dir: &Path, rib: &str) -> Diagnostics {
    let path = dir.join("scene.rib");
    std::fs::write(&path, rib).unwrap();
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    // The stdlib is named explicitly: the embedded copy may come from another checkout
    // sharing the build directory.
    let stdlib = concat!(env!("CARGO_MANIFEST_DIR"), "/stdlib/shaders").to_string();
    let settings = Settings {
        threads: 1,
        shader_paths: vec![stdlib],
        ..Default::default()
    };
    render_paths(&[path], &settings, &sources, &diags);
    diags
}

/// A 64×64 grey height picture: a few round bumps (periodic).
fn write_heights(path: &Path) {
    let n = 64u32;
    let img = image::GrayImage::from_fn(n, n, |x, y| {
        let mut h = 0.0f32;
        for (cx, cy, r) in [(16.0, 20.0, 5.0), (44.0, 40.0, 7.0), (50.0, 10.0, 4.0)] {
            let dx = (x as f32 - cx + 32.0).rem_euclid(64.0) - 32.0;
            let dy = (y as f32 - cy + 32.0).rem_euclid(64.0) - 32.0;
            h += (-(dx * dx + dy * dy) / (r * r)).exp();
        }
        image::Luma([(h.min(1.0) * 255.0).round() as u8])
    });
    img.save(path).unwrap();
}

fn warnings(d: &Diagnostics, code: &str) -> Vec<String> {
    d.snapshot()
        .into_iter()
        .filter(|(x, _)| x.code == code && x.severity == Severity::Warning)
        .map(|(x, _)| x.message)
        .collect()
}

#[test]
fn make_horizon_request_builds_the_tables() {
    let dir = tmp("make");
    write_heights(&dir.join("bumps.png"));
    let out16 = dir.join("out16.hzn");
    let out8 = dir.join("out8.hzn");
    // The picture is named relative: it is found on the texture search path (the scene's
    // folder is on it).
    let rib = format!(
        "MakeHorizon \"bumps.png\" \"{}\" \"periodic\" \"periodic\" \"directions\" [16]\n\
         MakeHorizon \"bumps.png\" \"{}\" \"clamp\" \"periodic\"\n",
        out16.display(),
        out8.display()
    );
    let diags = render(&dir, &rib);
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
    let (f, w, h) = read_height_image(&dir.join("bumps.png")).unwrap();
    let t16 = HorizonTable::read(&out16).unwrap();
    assert_eq!(t16, HorizonTable::build(&f, w, h, 16).unwrap());
    let t8 = HorizonTable::read(&out8).unwrap();
    assert_eq!(t8, HorizonTable::build(&f, w, h, 8).unwrap());
    assert!(t8.tans.iter().any(|&v| v > 0.0));
    // "clamp" is not supported: warned, built periodic.
    let w = warnings(&diags, "scene::horizon-wrap");
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("clamp"));
    assert!(!out16.with_extension("hzn.partial").exists());

    // Bad direction counts warn and fall back to 8; a missing picture is an error.
    let out = dir.join("bad.hzn");
    let rib = format!(
        "MakeHorizon \"bumps.png\" \"{}\" \"periodic\" \"periodic\" \"directions\" [7]\n\
         MakeHorizon \"nothere.png\" \"{}\" \"periodic\" \"periodic\"\n",
        out.display(),
        dir.join("never.hzn").display()
    );
    let diags = render(&dir, &rib);
    assert_eq!(warnings(&diags, "scene::horizon-directions").len(), 1);
    assert_eq!(HorizonTable::read(&out).unwrap().ndirs(), 8);
    assert_eq!(diags.error_count(), 1, "{:?}", diags.snapshot());
    assert!(!dir.join("never.hzn").exists());
}

/// Mean grey of a rendered PNG.
fn mean(path: &Path) -> f32 {
    let img = image::open(path).unwrap().to_luma8();
    img.pixels().map(|p| p[0] as f32).sum::<f32>() / (img.width() * img.height()) as f32
}

#[test]
fn horizon_maps_are_found_on_the_texture_search_path() {
    let dir = tmp("search");
    let maps = dir.join("hzn-search-maps");
    std::fs::create_dir_all(&maps).unwrap();
    write_heights(&dir.join("heights.png"));
    let (f, w, h) = read_height_image(&dir.join("heights.png")).unwrap();
    HorizonTable::build(&f, w, h, 8)
        .unwrap()
        .write(&maps.join("bumps.hzn"))
        .unwrap();
    let frame = |png: &Path, shadows: i32| {
        format!(
            "FrameBegin 1\nDisplay \"{}\" \"png\" \"rgb\"\nFormat 48 48 1\nPixelSamples 1 1\n\
             Projection \"orthographic\"\nScreenWindow -1 1 -1 1\nTranslate 0 0 5\n\
             WorldBegin\n\
             LightSource \"distantlight\" 1 \"from\" [-1 0.3 -0.12] \"to\" [0 0 0]\n\
             Surface \"horizonbump\" \"string horizonmap\" [\"bumps.hzn\"] \"float shadows\" [{shadows}]\n\
                 \"float bumpscale\" [0.08] \"float penumbra\" [0]\n\
             Polygon \"P\" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] \"st\" [0 0  1 0  1 1  0 1]\n\
             WorldEnd\nFrameEnd\n",
            png.display()
        )
    };
    let (on, off) = (dir.join("on.png"), dir.join("off.png"));
    let rib = format!(
        "Option \"searchpath\" \"texture\" [\"hzn-search-maps\"]\n{}{}",
        frame(&on, 1),
        frame(&off, 0)
    );
    let diags = render(&dir, &rib);
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
    let unavailable: Vec<_> = diags
        .snapshot()
        .into_iter()
        .filter(|(d, _)| d.message.contains("horizon map unavailable"))
        .collect();
    assert!(unavailable.is_empty(), "{unavailable:?}");
    // The grazing light leaves long bump shadows only when the map was found.
    let (m_on, m_off) = (mean(&on), mean(&off));
    assert!(m_on < 0.9 * m_off, "shadowed {m_on} vs plain {m_off}");

    // Without the search path the name is not found: warned (no bumps, no shadows).
    let lost = dir.join("lost.png");
    let diags = render(&dir, &frame(&lost, 1));
    assert!(diags
        .snapshot()
        .iter()
        .any(|(d, _)| d.message.contains("horizon map unavailable")));
    assert!(lost.exists());
}

/// Max §6 end to end: on a unit sphere under a flat map, points raised by h see a distant
/// light up to γ = √(2h/R) past the smooth terminator; without the correction the terminator
/// is where the light goes.
#[test]
fn curvature_correction_lights_raised_points_past_the_terminator() {
    let dir = tmp("curv");
    HorizonTable::build(&[1.0; 16 * 16], 16, 16, 8)
        .unwrap()
        .write(&dir.join("flat.hzn"))
        .unwrap();
    std::fs::write(
        dir.join("hvis.sl"),
        "surface hvis(string map = \"\"; float scale = 1, curvature = 1) {\n\
         Ci = 0;\n\
         illuminance(P) { Ci += horizon(map, s, t, L, \"scale\", scale, \"penumbra\", 0,\n\
                                        \"curvature\", curvature); }\n\
         Oi = 1;\n}\n",
    )
    .unwrap();
    // Sphere: s = longitude / 2π, t = (latitude + 90°) / 180°, so at the equator
    // |dP/ds × dP/dt| = 2π², and h = scale · F · |N|^½ = 0.005 for F = 1: γ = 0.1 rad.
    let scale = 0.005 / (2.0 * std::f32::consts::PI.powi(2)).sqrt();
    let frame = |png: &Path, curvature: f32| {
        format!(
            "FrameBegin 1\nDisplay \"{}\" \"png\" \"rgb\"\nFormat 240 240 1\nPixelSamples 2 2\n\
             PixelFilter \"box\" 1 1\nProjection \"orthographic\"\nScreenWindow -1.2 1.2 -1.2 1.2\n\
             Rotate -90 1 0 0\nTranslate 0 -5 0\n\
             WorldBegin\n\
             LightSource \"distantlight\" 1 \"from\" [1 0 0] \"to\" [0 0 0]\n\
             Surface \"hvis\" \"string map\" [\"flat.hzn\"] \"float scale\" [{scale}] \"float curvature\" [{curvature}]\n\
             Sphere 1 -1 1 360\nWorldEnd\nFrameEnd\n",
            png.display()
        )
    };
    let (on, off) = (dir.join("curved.png"), dir.join("flat.png"));
    let diags = render(&dir, &format!("{}{}", frame(&on, 1.0), frame(&off, 0.0)));
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
    assert!(diags.snapshot().is_empty(), "{:?}", diags.snapshot());
    // The camera looks down -y from +y: image x = world x, image up = world z. Read the
    // equator row: x = cos ψ for the point ψ round from the light.
    let row = |p: &Path| {
        let img = image::open(p).unwrap().to_luma8();
        let y = img.height() / 2;
        (0..img.width())
            .map(|i| {
                let x = -1.2 + (i as f32 + 0.5) * 2.4 / img.width() as f32;
                (x, img.get_pixel(i, y)[0] as f32 / 255.0)
            })
            .collect::<Vec<_>>()
    };
    let (curved, flat) = (row(&on), row(&off));
    let band = |r: &[(f32, f32)], lo: f32, hi: f32| {
        r.iter()
            .filter(|(x, _)| (lo..=hi).contains(x))
            .map(|&(_, v)| v)
            .collect::<Vec<_>>()
    };
    // In front of the terminator: lit either way.
    assert!(band(&curved, 0.05, 0.9).iter().all(|&v| v > 0.95));
    assert!(band(&flat, 0.05, 0.9).iter().all(|&v| v > 0.95));
    // Up to γ = 0.1 rad behind it (x down to cos(90° + 5.7°) = −0.0998): lit only when curved.
    let (c, f) = (band(&curved, -0.08, -0.02), band(&flat, -0.08, -0.02));
    assert!(c.len() >= 5 && c.iter().all(|&v| v > 0.95), "{c:?}");
    assert!(f.iter().all(|&v| v < 0.05), "{f:?}");
    // Beyond γ: dark either way.
    assert!(band(&curved, -0.9, -0.13).iter().all(|&v| v < 0.05));
}
