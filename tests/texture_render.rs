//! End to end: a two-pass RIB (shadow depth render, MakeShadow, beauty with shadowdistant)
//! whose lit and shadowed pixels must match the occluder's projection; and a blurred cube
//! environment whose values are continuous across face seams.

mod common;

use std::path::Path;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::pipeline::{render_paths, Settings};
use arbor::shade::exec::{TextureLookup, TextureParams};
use arbor::texture::make::{make_cube, MakeOptions};
use arbor::texture::TextureSystem;
use glam::Vec3;

fn tmp(name: &str) -> common::Scratch {
    common::scratch(&format!("texrender-{name}"))
}

/// Camera (or light) at height `h` looking straight down -y, image up = +z, orthographic
/// over x, z ∈ [-2, 2].
fn down_camera(h: f32) -> String {
    format!(
        "Projection \"orthographic\"\nScreenWindow -2 2 -2 2\n\
         ConcatTransform [1 0 0 0  0 0 -1 0  0 1 0 0  0 0 0 1]\nTranslate 0 {} 0\n",
        -h
    )
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

#[test]
fn make_shadow_reads_a_float_depth_tiff() {
    // Essential RenderMan's shadow chapter renders depth with `Display "z.tiff" "file" "z"`
    // and then `MakeShadow "z.tiff" "map.shad"`: the depth TIFF is 32-bit float with the
    // camera's matrices in PRMan's tags, and makes the same shadow a zfile does.
    let dir = tmp("tiffshadow");
    let z = dir.join("depth.tiff");
    let tex = dir.join("depth.shad");
    let png = dir.join("beauty.png");
    let rib = format!(
        "FrameBegin 1\nDisplay \"{z}\" \"file\" \"z\"\n\
         Format 64 64 1\nPixelSamples 1 1\nPixelFilter \"box\" 1 1\n{cam}\
         WorldBegin\nPolygon \"P\" [-0.5 1 -0.5  0.5 1 -0.5  0.5 1 0.5  -0.5 1 0.5]\n\
         Polygon \"P\" [-2 0 -2  2 0 -2  2 0 2  -2 0 2]\nWorldEnd\nFrameEnd\n\
         MakeShadow \"{z}\" \"{tex}\"\n\
         FrameBegin 2\nDisplay \"{png}\" \"png\" \"rgb\"\nFormat 32 32 1\nPixelSamples 2 2\n{cam}\
         WorldBegin\n\
         LightSource \"shadowdistant\" 1 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" [\"{tex}\"] \"bias\" [0.02]\n\
         Surface \"matte\"\nPolygon \"P\" [-2 0 -2  2 0 -2  2 0 2  -2 0 2]\nWorldEnd\nFrameEnd\n",
        z = z.display(),
        tex = tex.display(),
        png = png.display(),
        cam = down_camera(10.0),
    );
    let diags = render(&dir, &rib);
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
    let back = arbor::film::tiff::read_depth(&std::fs::read(&z).unwrap()).unwrap();
    assert!(back.matrices.is_some());
    let img = image::open(&png).unwrap().to_rgb8();
    // Under the square (x, z in [-0.5, 0.5]) in shadow; outside it lit.
    for (i, j) in [(16, 16), (14, 17), (17, 14)] {
        assert!(
            img.get_pixel(i, j)[0] < 30,
            "({i},{j}) {:?}",
            img.get_pixel(i, j)
        );
    }
    for (i, j) in [(3, 3), (28, 4), (5, 27), (16, 3)] {
        assert!(
            img.get_pixel(i, j)[0] > 225,
            "({i},{j}) {:?}",
            img.get_pixel(i, j)
        );
    }
}

#[test]
fn shadow_pass_then_beauty_pass_matches_the_geometry() {
    let dir = tmp("shadow");
    let z = dir.join("light.z");
    let tex = dir.join("light.tex");
    let png = dir.join("beauty.png");
    let direct = dir.join("direct.shad");
    // The occluder: a square at y = 1 over x, z ∈ [-0.5, 0.5] with a notch cut away at
    // x > 0.25, z > 0.25 (an L shape), so orientation mistakes show.
    let occluder =
        "Polygon \"P\" [-0.5 1 -0.5  0.5 1 -0.5  0.5 1 0.25  0.25 1 0.25  0.25 1 0.5  -0.5 1 0.5]";
    let rib = format!(
        "FrameBegin 1\nDisplay \"{z}\" \"zfile\" \"z\"\nDisplay \"+{direct}\" \"shadow\" \"z\"\n\
         Format 64 64 1\nPixelSamples 1 1\nPixelFilter \"box\" 1 1\n{cam}\
         WorldBegin\n{occluder}\nPolygon \"P\" [-2 0 -2  2 0 -2  2 0 2  -2 0 2]\nWorldEnd\nFrameEnd\n\
         MakeShadow \"{z}\" \"{tex}\"\n\
         FrameBegin 2\nDisplay \"{png}\" \"png\" \"rgb\"\nFormat 32 32 1\nPixelSamples 2 2\n{cam}\
         WorldBegin\n\
         LightSource \"shadowdistant\" 1 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" [\"{tex}\"] \"bias\" [0.02]\n\
         Surface \"matte\"\nPolygon \"P\" [-2 0 -2  2 0 -2  2 0 2  -2 0 2]\nWorldEnd\nFrameEnd\n",
        z = z.display(),
        tex = tex.display(),
        png = png.display(),
        direct = direct.display(),
        cam = down_camera(10.0),
    );
    let diags = render(&dir, &rib);
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
    let img = image::open(&png).unwrap().to_rgb8();
    let in_shadow = |x: f32, z: f32| {
        (-0.5..=0.5).contains(&x) && (-0.5..=0.5).contains(&z) && !(x > 0.25 && z > 0.25)
    };
    let (mut checked, mut lit, mut dark) = (0, 0, 0);
    for j in 0..32u32 {
        for i in 0..32u32 {
            let x = -2.0 + (i as f32 + 0.5) * 4.0 / 32.0;
            let zz = 2.0 - (j as f32 + 0.5) * 4.0 / 32.0;
            // Skip the pixels straddling an edge of the shadow.
            let near_edge = [-0.5f32, 0.5, 0.25]
                .iter()
                .any(|e| (x - e).abs() < 0.1 || (zz - e).abs() < 0.1);
            if near_edge {
                continue;
            }
            let v = img.get_pixel(i, j)[0];
            checked += 1;
            if in_shadow(x, zz) {
                assert!(
                    v < 30,
                    "pixel ({i},{j}) at x={x} z={zz} should be in shadow: {v}"
                );
                dark += 1;
            } else {
                assert!(
                    v > 225,
                    "pixel ({i},{j}) at x={x} z={zz} should be lit: {v}"
                );
                lit += 1;
            }
        }
    }
    assert!(
        checked > 600 && dark > 15 && lit > 500,
        "{checked} {dark} {lit}"
    );

    // The "shadow" display wrote a shadow texture usable directly, with the same answers.
    let d2 = Diagnostics::new();
    let sys = TextureSystem::new(vec![], 1024, &d2);
    let p = TextureParams {
        samples: 16.0,
        swidth: 1.0,
        twidth: 1.0,
        bias: 0.02,
        ..Default::default()
    };
    let pts = [
        [Vec3::new(-0.2, 0.0, -0.2); 5],
        [Vec3::new(1.5, 0.0, 1.5); 5],
        [Vec3::new(-0.2, 1.0, -0.2); 5],
    ];
    let mut out = [0f32; 3];
    for name in [&tex, &direct] {
        assert!(sys.shadow(name.to_str().unwrap(), &pts, &p, &mut out));
        assert_eq!(out, [1.0, 0.0, 0.0], "{}", name.display());
    }
}

/// A smooth function of direction, continuous across cube edges.
fn env_fn(d: Vec3) -> [f32; 3] {
    let d = d.normalize();
    [0.5 + 0.5 * d.x, 0.5 + 0.5 * d.y, 0.5 + 0.5 * d.z]
}

#[test]
fn blurred_cube_environment_has_no_seams() {
    use arbor::texture::env::face_dir;
    let dir = tmp("cube");
    let n = 16u32;
    let mut faces = Vec::new();
    for face in 0..6 {
        // Each face is its own constant plus the smooth field, so unfiltered seams are steps.
        let img = image::Rgb32FImage::from_fn(n, n, |x, y| {
            let d = face_dir(
                face,
                (x as f32 + 0.5) / n as f32,
                (y as f32 + 0.5) / n as f32,
            );
            let v = env_fn(d);
            image::Rgb([v[0], v[1], v[2]])
        });
        let p = dir.join(format!("f{face}.hdr"));
        image::DynamicImage::ImageRgb32F(img).save(&p).unwrap();
        faces.push(p);
    }
    let out = dir.join("env.tex");
    make_cube(&faces, &out, &MakeOptions::default()).unwrap();
    let diags = Diagnostics::new();
    let sys = TextureSystem::new(vec![], 1024, &diags);
    let name = out.to_str().unwrap();
    // Walk around the equator through the +x/+z/-x/-z seams, one degree at a time.
    let steps = 360;
    let dirs: Vec<[Vec3; 5]> = (0..steps)
        .map(|k| {
            let a = (k as f32 + 0.3).to_radians();
            let d = Vec3::new(a.cos(), 0.1, a.sin());
            [d; 5]
        })
        .collect();
    for blur in [0.0, 0.05, 0.2] {
        let p = TextureParams {
            blur,
            sblur: blur,
            tblur: blur,
            swidth: 1.0,
            twidth: 1.0,
            filter: "gaussian".into(),
            ..Default::default()
        };
        let mut vals = vec![0f32; steps * 3];
        assert!(sys.environment(name, 0, 3, &dirs, &p, &mut vals));
        let mut max_step = 0f32;
        let mut at = 0;
        for k in 0..steps {
            let (a, b) = (
                &vals[k * 3..k * 3 + 3],
                &vals[((k + 1) % steps) * 3..((k + 1) % steps) * 3 + 3],
            );
            for c in 0..3 {
                if (a[c] - b[c]).abs() > max_step {
                    max_step = (a[c] - b[c]).abs();
                    at = k;
                }
            }
            if blur == 0.0 {
                // Unblurred: close to the function itself.
                let want = env_fn(dirs[k][0]);
                for c in 0..3 {
                    assert!(
                        (a[c] - want[c]).abs() < 0.05,
                        "dir {k} chan {c}: {} vs {}",
                        a[c],
                        want[c]
                    );
                }
            }
        }
        // One degree moves the true function by at most 0.5·π/180 ≈ 0.0087 per channel; a
        // seam would show as a step of the order of a texel (≈ 0.05) or more.
        assert!(
            max_step < 0.02,
            "blur {blur}: largest step between neighbouring directions {max_step} at {at} degrees"
        );
    }
    // Heavy blur averages the hemisphere around the direction (+x here): the mean of
    // 0.5 + 0.5·x over it is 0.75, the other channels stay 0.5.
    let p = TextureParams {
        blur: 2.0,
        sblur: 2.0,
        tblur: 2.0,
        swidth: 1.0,
        twidth: 1.0,
        filter: "gaussian".into(),
        ..Default::default()
    };
    let mut v = vec![0f32; 3];
    assert!(sys.environment(name, 0, 3, &dirs[..1], &p, &mut v));
    assert!(
        (v[0] - 0.75).abs() < 0.06 && (v[1] - 0.5).abs() < 0.06 && (v[2] - 0.5).abs() < 0.06,
        "{v:?}"
    );
}

#[test]
fn a_comma_separated_list_of_shadow_maps_averages_them() {
    // PRMan's soft shadows: maps rendered from across an area light, named in one string
    // (NCCA's `arealight`: "Spot1.shad,Spot2.shad,…"). One map sees the occluder and one
    // does not: under the occluder the light is half there.
    let dir = tmp("shadowlist");
    let (zo, zc) = (dir.join("occ.z"), dir.join("clear.z"));
    let (to, tc) = (dir.join("occ.tex"), dir.join("clear.tex"));
    let png = dir.join("beauty.png");
    let occluder = "Polygon \"P\" [-0.5 1 -0.5  0.5 1 -0.5  0.5 1 0.5  -0.5 1 0.5]";
    let floor = "Polygon \"P\" [-2 0 -2  2 0 -2  2 0 2  -2 0 2]";
    let depth = |z: &Path, world: &str| {
        format!(
            "FrameBegin 1\nDisplay \"{}\" \"zfile\" \"z\"\nFormat 64 64 1\nPixelSamples 1 1\n\
             PixelFilter \"box\" 1 1\n{}WorldBegin\n{world}\nWorldEnd\nFrameEnd\n",
            z.display(),
            down_camera(10.0)
        )
    };
    let rib = format!(
        "{}{}MakeShadow \"{}\" \"{}\"\nMakeShadow \"{}\" \"{}\"\n\
         FrameBegin 3\nDisplay \"{}\" \"png\" \"rgb\"\nFormat 32 32 1\nPixelSamples 2 2\n{}\
         WorldBegin\n\
         LightSource \"shadowdistant\" 1 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" [\"{},{}\"] \"bias\" [0.02]\n\
         Surface \"matte\"\n{floor}\nWorldEnd\nFrameEnd\n",
        depth(&zo, &format!("{occluder}\n{floor}")),
        depth(&zc, floor),
        zo.display(),
        to.display(),
        zc.display(),
        tc.display(),
        png.display(),
        down_camera(10.0),
        to.display(),
        tc.display(),
    );
    let diags = render(&dir, &rib);
    assert!(!diags.has_errors(), "{:?}", diags.snapshot());
    let img = image::open(&png).unwrap().to_rgb8();
    // Pixel (16, 16) lies under the occluder's middle, (2, 2) far outside it.
    let under = img.get_pixel(16, 16)[0] as i32;
    let open = img.get_pixel(2, 2)[0] as i32;
    assert!(open > 225, "open {open}");
    assert!((under - open / 2).abs() <= 8, "under {under}, open {open}");
}
