//! Bump maps and the summed-area-table filter against analytic answers: a linear ramp of
//! heights gives a known, constant slope through MakeBump files and through plain textures
//! (finite differences), and a known tilt of the normal through the shading language's
//! bump(); SAT lookups through the texture system return exact box averages.

mod common;

use std::path::Path;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::pipeline::{render_paths, Settings};
use arbor::shade::exec::{TextureLookup, TextureParams};
use arbor::texture::bump::bump_image;
use arbor::texture::format::{self, Kind};
use arbor::texture::image_in::Image;
use arbor::texture::mipmap::{build_pyramid, Downsample, Wrap};
use arbor::texture::TextureSystem;

fn tmp(name: &str) -> common::Scratch {
    common::scratch(&format!("texbump-{name}"))
}

fn params(filter: &str) -> TextureParams {
    TextureParams {
        filter: filter.into(),
        swidth: 1.0,
        twidth: 1.0,
        ..Default::default()
    }
}

/// B = 0.5 s − 0.25 t, sampled at texel centres of a 64 × 64 map.
fn ramp() -> Image {
    let n = 64;
    let mut im = Image::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            let (s, t) = ((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
            im.data[y * n + x] = 0.5 * s - 0.25 * t;
        }
    }
    im
}

#[test]
fn a_ramp_has_its_slope_in_both_map_forms_and_every_filter() {
    let d = tmp("slopes");
    let (tex, bump) = (d.join("ramp.tex"), d.join("ramp.bump"));
    let c = Wrap::Clamp;
    let levels = build_pyramid(ramp(), c, c, Downsample::Box);
    format::write(&tex, Kind::Texture, &[levels], c, c, None).unwrap();
    let levels = build_pyramid(bump_image(&ramp(), c, c), c, c, Downsample::Box);
    format::write(&bump, Kind::Bump, &[levels], c, c, None).unwrap();
    let diags = Diagnostics::new();
    let sys = TextureSystem::new(vec![], 4096, &diags);
    // Footprints near the middle: a point, one texel, four texels, oblique.
    let fps: Vec<[f32; 8]> = vec![
        [0.5; 8],
        [0.4, 0.45, 0.416, 0.45, 0.4, 0.466, 0.416, 0.466],
        [0.45, 0.5, 0.51, 0.5, 0.45, 0.56, 0.51, 0.56],
        [0.4, 0.4, 0.46, 0.42, 0.41, 0.43, 0.47, 0.45],
    ];
    for file in [&tex, &bump] {
        let name = file.to_str().unwrap();
        // (Point sampling differences whole texels of a plain map: not a smooth gradient.)
        let filters: &[&str] = if file == &bump {
            &["point", "box", "gaussian", "sat"]
        } else {
            &["box", "gaussian", "sat"]
        };
        for &f in filters {
            let mut out = vec![0f32; 2 * fps.len()];
            assert!(sys.bump_slopes(name, 0, &fps, &params(f), &mut out));
            for (i, g) in out.chunks(2).enumerate() {
                assert!(
                    (g[0] - 0.5).abs() < 0.01 && (g[1] + 0.25).abs() < 0.01,
                    "{name} filter {f} footprint {i}: {g:?}"
                );
            }
        }
        // The heights themselves through texture().
        let mut h = [0f32];
        assert!(sys.texture(name, 0, 1, &fps[..1], &params("box"), &mut h));
        assert!((h[0] - (0.25 - 0.125)).abs() < 1e-3, "{h:?}");
    }
    // textureinfo sees a one-channel bump map; a channel it lacks has no slope.
    assert_eq!(
        format!("{:?}", sys.info(bump.to_str().unwrap(), "type")),
        "Some(Str(\"bump\"))"
    );
    let mut out = [9f32; 2];
    assert!(sys.bump_slopes(
        bump.to_str().unwrap(),
        3,
        &fps[..1],
        &params("box"),
        &mut out
    ));
    assert_eq!(out, [0.0, 0.0]);
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
}

#[test]
fn sat_lookups_are_exact_box_averages() {
    let d = tmp("sat");
    let tex = d.join("checker.tex");
    // 8 × 8 checker of 0 and 1 texels.
    let n = 8;
    let mut im = Image::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            im.data[y * n + x] = ((x + y) % 2) as f32;
        }
    }
    let p = Wrap::Periodic;
    format::write(
        &tex,
        Kind::Texture,
        &[build_pyramid(im, p, p, Downsample::Box)],
        p,
        p,
        None,
    )
    .unwrap();
    let name = tex.to_str().unwrap();
    let diags = Diagnostics::new();
    let sys = TextureSystem::new(vec![], 1024, &diags);
    // Texel-aligned 3 × 1 texel box from texel (0, 0): 1 − ... = (0 + 1 + 0) / 3.
    let (a, b) = (0.0, 3.0 / 8.0);
    let fp = [a, 0.0, b, 0.0, a, 1.0 / 8.0, b, 1.0 / 8.0];
    let mut out = [0f32];
    assert!(sys.texture(name, 0, 1, &[fp], &params("sat"), &mut out));
    assert!((out[0] - 1.0 / 3.0).abs() < 1e-5, "{out:?}");
    // A footprint of many whole periods averages to ½, with or without blur.
    let fp = [-1.3, 2.2, 1.7, 2.2, -1.3, 4.2, 1.7, 4.2];
    for blur in [0.0, 0.25] {
        let mut p = params("sat");
        p.sblur = blur;
        assert!(sys.texture(name, 0, 1, &[fp], &p, &mut out));
        assert!((out[0] - 0.5).abs() < 0.02, "blur {blur}: {out:?}");
    }
    assert!(diags.snapshot().is_empty(), "{:?}", diags.snapshot());

    // A table that does not fit the memory limit is built on a coarser level, with a warning.
    let big = d.join("big.tex");
    let mut im = Image::new(256, 256, 1);
    im.data.iter_mut().for_each(|v| *v = 0.75);
    format::write(
        &big,
        Kind::Texture,
        &[build_pyramid(im, p, p, Downsample::Box)],
        p,
        p,
        None,
    )
    .unwrap();
    let sys = TextureSystem::new(vec![], 64, &diags);
    assert!(sys.texture(
        big.to_str().unwrap(),
        0,
        1,
        &[[0.5; 8]],
        &params("sat"),
        &mut out
    ));
    assert!((out[0] - 0.75).abs() < 1e-6);
    let msgs: Vec<String> = diags
        .snapshot()
        .iter()
        .map(|(d, _)| d.message.clone())
        .collect();
    assert!(
        msgs.iter().any(|m| m.contains("summed-area table")),
        "{msgs:?}"
    );
}

const SHADER: &str = "surface bumpn(string map = \"\") {
    normal Nb = normalize(ntransform(\"world\", N + bump(map, N, dPdu, dPdv)));
    Ci = color(-xcomp(Nb), abs(ycomp(Nb)), abs(zcomp(Nb)));
    Oi = 1;
}
";

/// The same heights as true displacement, for comparison.
const DISPLACE: &str = "displacement dispn(string map = \"\") {
    P += float texture(map) * normalize(N);
    N = calculatenormal(P);
}
";

fn render(dir: &Path, rib: &str) -> Diagnostics {
    let path = dir.join("scene.rib");
    std::fs::write(&path, rib).unwrap();
    std::fs::write(dir.join("bumpn.sl"), SHADER).unwrap();
    std::fs::write(dir.join("dispn.sl"), DISPLACE).unwrap();
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let stdlib = concat!(env!("CARGO_MANIFEST_DIR"), "/stdlib/shaders").to_string();
    let settings = Settings {
        threads: 1,
        shader_paths: vec![dir.display().to_string(), stdlib],
        ..Default::default()
    };
    render_paths(&[path], &settings, &sources, &diags);
    diags
}

#[test]
fn bump_in_a_shader_tilts_the_normal_by_the_ramp() {
    let dir = tmp("shader");
    // Heights x/255 over 256 texels: ∂B/∂s = 256/255 exactly (8 bits hold the ramp).
    let png = dir.join("ramp.png");
    image::GrayImage::from_fn(256, 4, |x, _| image::Luma([x as u8]))
        .save(&png)
        .unwrap();
    let (bump, tex) = (dir.join("ramp.bump"), dir.join("ramp.tex"));
    let out = |k: &str| dir.join(format!("{k}.png"));
    let frame = |k: &str, map: &Path| {
        let (surf, disp) = if k == "displaced" {
            (
                String::new(),
                format!(
                    "Displacement \"dispn\" \"string map\" \"{}\"\n\
                Attribute \"displacementbound\" \"sphere\" [1.2]\n",
                    map.display()
                ),
            )
        } else {
            (map.display().to_string(), String::new())
        };
        format!(
            "FrameBegin {}\nDisplay \"{}\" \"png\" \"rgb\"\nFormat 16 16 1\nPixelSamples 1 1\n\
             PixelFilter \"box\" 1 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\n\
             ConcatTransform [1 0 0 0  0 0 -1 0  0 1 0 0  0 0 0 1]\nTranslate 0 -5 0\n\
             WorldBegin\n{disp}Surface \"bumpn\" \"string map\" \"{surf}\"\n\
             Patch \"bilinear\" \"P\" [-1 0 -1  1 0 -1  -1 0 1  1 0 1]\nWorldEnd\nFrameEnd\n",
            match k {
                "bumpfile" => 1,
                "plain" => 2,
                _ => 3,
            },
            out(k).display(),
        )
    };
    let rib = format!(
        "MakeBump \"{png}\" \"{bump}\" \"clamp\" \"clamp\" \"box\" 1 1\n\
         MakeTexture \"{png}\" \"{tex}\" \"clamp\" \"clamp\" \"gaussian\" 2 2\n{}{}{}",
        frame("bumpfile", &bump),
        frame("plain", &tex),
        frame("displaced", &tex),
        png = png.display(),
        bump = bump.display(),
        tex = tex.display(),
    );
    let diags = render(&dir, &rib);
    let msgs: Vec<String> = diags
        .snapshot()
        .iter()
        .map(|(d, _)| d.message.clone())
        .collect();
    assert!(!diags.has_errors() && msgs.is_empty(), "{msgs:#?}");
    // s runs over 2 units of x: the surface rises (256/255)/2 per unit x along its normal,
    // so the bumped normal is ∝ (−k, ±1, 0) with k = 128/255, whichever way N points —
    // the normal calculatenormal finds on the truly displaced surface.
    let k = 128.0f32 / 255.0;
    let want = [k, 1.0, 0.0].map(|v| v / (1.0 + k * k).sqrt());
    for which in ["bumpfile", "plain", "displaced"] {
        let img = image::open(out(which)).unwrap().to_rgb8();
        for j in 3..13 {
            for i in 3..13 {
                let px = img.get_pixel(i, j);
                for c in 0..3 {
                    let v = px[c] as f32 / 255.0;
                    assert!(
                        (v - want[c]).abs() < 0.02,
                        "{which} pixel ({i},{j}) channel {c}: {v} vs {}",
                        want[c]
                    );
                }
            }
        }
    }
}

#[test]
fn bump_calls_type_check_in_every_form() {
    let compile = |body: &str| {
        let src = format!(
            "surface t(string m = \"\") {{ normal Nn = N; float ss = s, tt = t; {body} Ci = 1; }}\n"
        );
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let progs = arbor::sl::compile_source(
            "t.sl",
            &src,
            None,
            &sources,
            &diags,
            &arbor::sl::CompileOptions::default(),
        );
        let msgs: Vec<String> = diags
            .snapshot()
            .iter()
            .map(|(d, _)| d.message.clone())
            .collect();
        (progs.len() == 1 && !diags.has_errors(), msgs)
    };
    for ok in [
        "N += bump(m, N, dPdu, dPdv);",
        "Nn = normalize(Nn + bump(m[0], Nn, dPdu, dPdv, ss, tt));",
        "N += bump(m, N, dPdu, dPdv, ss, tt, ss, tt, ss, tt, ss, tt, \"blur\", 0.1, \"filter\", \"sat\");",
    ] {
        let (good, msgs) = compile(ok);
        assert!(good && msgs.is_empty(), "{ok}: {msgs:?}");
    }
    for bad in ["N += bump(m, N);", "N += bump(m, N, dPdu, dPdv, ss);"] {
        let (good, msgs) = compile(bad);
        assert!(!good, "{bad} should not compile");
        assert!(msgs.iter().any(|m| m.contains("bump")), "{bad}: {msgs:?}");
    }
}
