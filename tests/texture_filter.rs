//! Filtered texture lookups against analytic answers: constants survive every filter, and a
//! checkerboard plane receding to the horizon is much closer to a 16×16-supersampled
//! reference when filtered (trilinear, EWA) than when point sampled.

mod common;

use arbor::diag::Diagnostics;
use arbor::shade::exec::{TextureLookup, TextureParams};
use arbor::texture::make::{make_texture, MakeOptions};
use arbor::texture::mipmap::{Downsample, Wrap};
use arbor::texture::TextureSystem;

fn tmp(name: &str) -> common::Scratch {
    common::scratch(&format!("texfilter-{name}"))
}

fn params(filter: &str) -> TextureParams {
    TextureParams {
        filter: filter.into(),
        swidth: 1.0,
        twidth: 1.0,
        samples: 16.0,
        ..Default::default()
    }
}

#[test]
fn constant_colour_through_every_filter() {
    let d = tmp("const");
    let src = d.join("c.png");
    image::RgbImage::from_pixel(37, 21, image::Rgb([51, 102, 204]))
        .save(&src)
        .unwrap();
    let tex = d.join("c.tex");
    for filt in [Downsample::Box, Downsample::Gaussian] {
        let o = MakeOptions {
            swrap: Wrap::Periodic,
            twrap: Wrap::Clamp,
            filter: filt,
            ..MakeOptions::default()
        };
        make_texture(&src, &tex, &o).unwrap();
        let diags = Diagnostics::new();
        let sys = TextureSystem::new(vec![], 1024, &diags);
        let name = tex.to_str().unwrap();
        // Tiny, huge, oblique and rotated footprints, inside and outside [0,1].
        let fps: Vec<[f32; 8]> = vec![
            [0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5],
            [0.1, 0.2, 0.101, 0.2, 0.1, 0.201, 0.101, 0.201],
            [0.0, 0.0, 3.0, 0.0, 0.0, 2.0, 3.0, 2.0],
            [0.3, 0.3, 0.9, 0.31, 0.3, 0.302, 0.9, 0.312],
            [-1.7, 0.4, -1.5, 0.6, -1.9, 0.6, -1.7, 0.8],
            [0.2, 0.9, 0.2, 0.9, 0.21, 0.905, 0.21, 0.905],
        ];
        for f in ["point", "box", "gaussian", "triangle"] {
            for blur in [0.0, 0.05, 0.5] {
                let mut p = params(f);
                p.sblur = blur;
                p.tblur = blur * 0.5;
                let mut out = vec![0f32; fps.len() * 3];
                assert!(sys.texture(name, 0, 3, &fps, &p, &mut out));
                for (i, px) in out.chunks(3).enumerate() {
                    for (c, want) in [0.2f32, 0.4, 0.8].iter().enumerate() {
                        assert!(
                            (px[c] - want).abs() < 2e-3,
                            "filter {f} blur {blur} footprint {i} channel {c}: {} vs {want}",
                            px[c]
                        );
                    }
                }
            }
        }
        // A channel past the texture's last answers the fill value.
        let mut p = params("gaussian");
        p.fill = 0.25;
        let mut out = vec![0f32; 2];
        assert!(sys.texture(name, 2, 2, &fps[..1], &p, &mut out));
        assert!((out[0] - 0.8).abs() < 2e-3 && out[1] == 0.25, "{out:?}");
        // textureinfo answers.
        use arbor::shade::exec::InfoValue;
        match sys.info(name, "resolution") {
            Some(InfoValue::Floats(v)) => assert_eq!(v, vec![37.0, 21.0]),
            other => panic!("{other:?}"),
        }
        assert!(matches!(sys.info(name, "type"), Some(InfoValue::Str(s)) if s == "texture"));
        assert!(matches!(sys.info(name, "channels"), Some(InfoValue::Floats(v)) if v == vec![3.0]));
    }
}

/// The checker texture: 64×64 texels, squares of 4 texels.
fn checker_value(x: i64, y: i64) -> f32 {
    (((x.rem_euclid(64) / 4) + (y.rem_euclid(64) / 4)) % 2) as f32
}

/// Texture (s, t) where the ray through image point (x, y) ∈ [-1,1]² (y up) from a pinhole
/// 1 unit above the ground plane, looking along the horizon, hits the plane (4 units/repeat).
fn ground_st(x: f32, y: f32) -> (f32, f32) {
    let t = 1.0 / -y;
    (x * t / 4.0, t / 4.0)
}

#[test]
fn receding_checkerboard_filtered_beats_point_sampling() {
    let d = tmp("checker");
    let src = d.join("checker.png");
    let img = image::GrayImage::from_fn(64, 64, |x, y| {
        image::Luma([(checker_value(x as i64, y as i64) * 255.0) as u8])
    });
    img.save(&src).unwrap();
    let tex = d.join("checker.tex");
    make_texture(&src, &tex, &MakeOptions::default()).unwrap();
    let diags = Diagnostics::new();
    let sys = TextureSystem::new(vec![], 4096, &diags);
    let name = tex.to_str().unwrap();

    // A 64×64 image; rows below the horizon only.
    let n = 64usize;
    let px = |i: f32| 2.0 * i / n as f32 - 1.0;
    let mut fps = Vec::new();
    let mut reference = Vec::new();
    let mut rows = Vec::new();
    for row in (n / 2 + 1)..n {
        for col in 0..n {
            let (x0, x1) = (px(col as f32), px(col as f32 + 1.0));
            let (y0, y1) = (-px(row as f32), -px(row as f32 + 1.0));
            let c = [
                ground_st(x0, y0),
                ground_st(x1, y0),
                ground_st(x0, y1),
                ground_st(x1, y1),
            ];
            fps.push([
                c[0].0, c[0].1, c[1].0, c[1].1, c[2].0, c[2].1, c[3].0, c[3].1,
            ]);
            // 16×16 supersampled box-filtered reference of the texel function.
            let mut sum = 0.0;
            for j in 0..16 {
                for i in 0..16 {
                    let x = px(col as f32 + (i as f32 + 0.5) / 16.0);
                    let y = -px(row as f32 + (j as f32 + 0.5) / 16.0);
                    let (s, t) = ground_st(x, y);
                    sum += checker_value((s * 64.0).floor() as i64, (t * 64.0).floor() as i64);
                }
            }
            reference.push(sum / 256.0);
            rows.push(row);
        }
    }
    let centre = |fp: &[f32; 8]| {
        // The pixel centre's (s, t): point sampling looks up exactly there.
        let _ = fp;
    };
    centre(&fps[0]);
    let run = |filter: &str| {
        let mut out = vec![0f32; fps.len()];
        // Point sampling at the pixel centre: a zero-area footprint there.
        let looks: Vec<[f32; 8]> = if filter == "point" {
            fps.iter()
                .enumerate()
                .map(|(k, _)| {
                    let (row, col) = (rows[k], k % n);
                    let (s, t) = ground_st(px(col as f32 + 0.5), -px(row as f32 + 0.5));
                    [s, t, s, t, s, t, s, t]
                })
                .collect()
        } else {
            fps.clone()
        };
        assert!(sys.texture(name, 0, 1, &looks, &params(filter), &mut out));
        let err: f32 = out
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f32>();
        let near: f32 = out
            .iter()
            .zip(&reference)
            .zip(&rows)
            .filter(|(_, &r)| r >= n - 8)
            .map(|((a, b), _)| (a - b).abs())
            .fold(0.0, f32::max);
        ((err / out.len() as f32).sqrt(), near)
    };
    let (point, _) = run("point");
    let (tri, tri_near) = run("box");
    let (ewa, ewa_near) = run("gaussian");
    eprintln!("RMS error vs 16x16 reference: point {point:.4} trilinear {tri:.4} ewa {ewa:.4}; near-row max: tri {tri_near:.3} ewa {ewa_near:.3}");
    assert!(
        point > 0.2,
        "the point-sampled horizon should alias: {point}"
    );
    assert!(tri < 0.6 * point, "trilinear {tri} vs point {point}");
    assert!(ewa < 0.4 * point, "EWA {ewa} vs point {point}");
    assert!(
        ewa <= tri,
        "EWA {ewa} should not be worse than trilinear {tri}"
    );
    // No over-blur close to the camera, where the checks span many pixels.
    assert!(
        ewa_near < 0.5 && tri_near < 0.6,
        "near rows: ewa {ewa_near} tri {tri_near}"
    );
}
