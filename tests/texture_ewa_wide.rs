//! EWA on long, wide footprints (a plane receding to the horizon over a 512² checker):
//! the filtered value stays close to the exact box average of the footprint.

mod common;

use arbor::diag::Diagnostics;
use arbor::shade::exec::{TextureLookup, TextureParams};
use arbor::texture::make::{make_texture, MakeOptions};
use arbor::texture::TextureSystem;

fn checker(s: f32, t: f32) -> f32 {
    let (x, y) = ((s * 16.0).floor() as i64, (t * 16.0).floor() as i64);
    if (x + y).rem_euclid(2) == 0 {
        0.9
    } else {
        0.1
    }
}

#[test]
fn ewa_on_wide_footprints_tracks_the_footprint_average() {
    let dir = common::scratch("ewawide");
    let png = dir.join("checker.png");
    image::GrayImage::from_fn(512, 512, |x, y| {
        let v = checker((x as f32 + 0.5) / 512.0, (y as f32 + 0.5) / 512.0);
        image::Luma([(v * 255.0).round() as u8])
    })
    .save(&png)
    .unwrap();
    let tex = dir.join("checker.tex");
    make_texture(&png, &tex, &MakeOptions::default()).unwrap();
    let diags = Diagnostics::new();
    let sys = TextureSystem::new(vec![], 64 * 1024, &diags);
    let n = 32usize;
    let mut st = Vec::new();
    let mut want = Vec::new();
    for k in 0..n * n {
        let (i, j) = ((k % n) as f32 / n as f32, (k / n) as f32 / n as f32);
        let depth = 1.0 + 8.0 * j;
        let (s, t) = (i * depth * 0.37, depth * 0.61);
        let (ds, dt) = (0.004 * depth, 0.016 * depth);
        st.push([s, t, s + ds, t, s, t + dt, s + ds, t + dt]);
        // The exact mean over the footprint rectangle (its corners are the 4 points).
        let m = 48;
        let mut acc = 0.0;
        for a in 0..m {
            for b in 0..m {
                let u = s + ds * (a as f32 + 0.5) / m as f32;
                let v = t + dt * (b as f32 + 0.5) / m as f32;
                acc += checker(u.rem_euclid(1.0), v.rem_euclid(1.0));
            }
        }
        want.push(acc / (m * m) as f32);
    }
    let rms_of = |filter: &str| {
        let params = TextureParams {
            filter: filter.into(),
            swidth: 1.0,
            twidth: 1.0,
            ..TextureParams::default()
        };
        let mut out = vec![0f32; n * n];
        assert!(sys.texture(tex.to_str().unwrap(), 0, 1, &st, &params, &mut out));
        (out.iter()
            .zip(&want)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum::<f64>()
            / (n * n) as f64)
            .sqrt()
    };
    let (ewa, tri, point) = (rms_of("gaussian"), rms_of("box"), rms_of("point"));
    eprintln!("RMS vs the footprint mean on wide footprints: EWA {ewa:.4}, trilinear {tri:.4}, point {point:.4}");
    // A Gaussian is not a box, so some difference is expected; aliasing gives ~0.4 (point).
    assert!(ewa < 0.05 && ewa < 0.25 * point, "EWA {ewa}, point {point}");
    assert!(
        ewa < tri,
        "EWA {ewa} should beat trilinear {tri} on anisotropic footprints"
    );
}
