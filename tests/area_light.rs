//! Area lights (`AreaLightSource`), checked analytically: the irradiance on the axis of a
//! uniform Lambertian disk, the same with a coaxial occluder casting a ray-traced shadow, a
//! polygon light the same as a disk of equal area far away, and the same pictures for any
//! thread count and bucket size.

mod common;

use std::f32::consts::PI;
use std::path::PathBuf;

use arbor::render::driver::RenderOptions;
use common::film_rgb;

fn shaders() -> PathBuf {
    common::manifest_dir().join("tests").join("arealight")
}

/// A receiver at z = 10 (seen from the eye, on its axis) lit from behind by a disk light of
/// radius `r` at height `h` above it with radiance `le`; `extra` goes in the world (an
/// occluder), `light_attrs` before the light.
fn disk_scene(r: f32, h: f32, le: f32, samples: u32, light_attrs: &str, extra: &str) -> String {
    format!(
        r#"Format 4 4 1
Projection "orthographic"
ScreenWindow -0.01 0.01 -0.01 0.01
PixelSamples 1 1
PixelFilter "box" 1 1
WorldBegin
AttributeBegin
  Attribute "light" "nsamples" [{samples}]
  {light_attrs}
  AreaLightSource "lambertarea" 1 "intensity" {le} "area" {area}
  Surface "constant"
  Translate 0 0 {z}
  Disk 0 {r} 360
AttributeEnd
Illuminate 1 1
AttributeBegin
  Surface "irradiance"
  Polygon "P" [-1 -1 10  1 -1 10  1 1 10  -1 1 10]
AttributeEnd
{extra}
WorldEnd
"#,
        area = PI * r * r,
        z = 10.0 + h
    )
}

fn mean_red(rib: &str) -> f32 {
    let film = common::render_rib(rib, &[shaders()]);
    let rgb = film_rgb(&film);
    let n = rgb.len() / 3;
    rgb.chunks_exact(3).map(|p| p[0]).sum::<f32>() / n as f32
}

/// Irradiance on the axis of a Lambertian disk of radiance `le`, radius `r`, at height `h`.
fn disk_irradiance(le: f32, r: f32, h: f32) -> f32 {
    PI * le * r * r / (h * h + r * r)
}

#[test]
fn irradiance_on_the_axis_of_a_disk_light_is_the_closed_form() {
    for (r, h) in [(1.0, 1.0), (2.0, 1.5), (0.5, 3.0)] {
        let le = 0.25;
        let got = mean_red(&disk_scene(r, h, le, 256, "", ""));
        let want = disk_irradiance(le, r, h);
        eprintln!("r={r} h={h}: irradiance {got}, closed form {want}");
        assert!(
            (got / want - 1.0).abs() < 0.01,
            "r={r} h={h}: irradiance {got}, closed form {want}"
        );
    }
}

/// The standard `arealight` is a Lambertian emitter (as BMRT rendered it): each sample's
/// intensity is foreshortened by the cosine at the light, so on the axis of a disk of radius
/// r at height h the mean over the surface is intensity / (h² + r²) — a point light's
/// intensity / h² as the disk shrinks.
#[test]
fn the_standard_arealight_is_a_lambertian_emitter() {
    for (r, h) in [(1.0f32, 1.0f32), (2.0, 1.5), (0.5, 3.0)] {
        let (le, area) = (0.25f32, PI * r * r);
        // arealight shines only to the side its normal faces: turn the disk to face the
        // receiver.
        let rib = disk_scene(r, h, le, 256, "", "")
            .replace(
                &format!("AreaLightSource \"lambertarea\" 1 \"intensity\" {le} \"area\" {area}"),
                &format!("AreaLightSource \"arealight\" 1 \"intensity\" {le}"),
            )
            .replace(
                &format!("Disk 0 {r} 360"),
                &format!("Rotate 180 1 0 0\n  Disk 0 {r} 360"),
            );
        assert!(rib.contains("\"arealight\""), "{rib}");
        let got = mean_red(&rib);
        let want = le / (h * h + r * r);
        assert!(
            (got / want - 1.0).abs() < 0.01,
            "r={r} h={h}: irradiance {got}, closed form {want}"
        );
    }
}

#[test]
fn a_coaxial_occluder_casts_a_ray_traced_shadow_of_the_analytic_size() {
    // An opaque disk of radius ro halfway up blocks, from the axis point, exactly the part of
    // the light inside radius 2·ro.
    let (r, h, le, ro) = (1.5, 2.0, 0.25, 0.4);
    let occluder = format!(
        "AttributeBegin\n  Surface \"constant\"\n  Translate 0 0 {}\n  Disk 0 {ro} 360\nAttributeEnd",
        10.0 + h / 2.0
    );
    let shadows = r#"Attribute "light" "shadows" ["on"]"#;
    let got = mean_red(&disk_scene(r, h, le, 400, shadows, &occluder));
    let want = disk_irradiance(le, r, h) - disk_irradiance(le, 2.0 * ro, h);
    eprintln!("shadowed irradiance {got}, analytic {want}");
    assert!(
        (got / want - 1.0).abs() < 0.02,
        "shadowed irradiance {got}, analytic {want}"
    );
    // Without shadows the occluder changes nothing.
    let got = mean_red(&disk_scene(r, h, le, 400, "", &occluder));
    let want = disk_irradiance(le, r, h);
    assert!((got / want - 1.0).abs() < 0.01, "{got} vs {want}");
}

#[test]
fn a_far_square_light_acts_as_a_disk_of_the_same_area() {
    // Far away (h ≫ size) only the area and the radiance matter: E ≈ Le · A / h².
    let (side, h, le) = (0.5f32, 8.0f32, 4.0f32);
    let rib = disk_scene(1.0, h, le, 64, "", "")
        .replace(
            "Disk 0 1 360",
            &format!(
                "Polygon \"P\" [{a} {a} 0  {b} {a} 0  {b} {b} 0  {a} {b} 0]",
                a = -side / 2.0,
                b = side / 2.0
            ),
        )
        .replace(
            &format!("\"area\" {}", PI),
            &format!("\"area\" {}", side * side),
        );
    let got = mean_red(&rib);
    let want = le * side * side / (h * h);
    eprintln!("square light {got}, far-field {want}");
    assert!((got / want - 1.0).abs() < 0.01, "{got} vs {want}");
}

#[test]
fn area_light_pictures_are_identical_for_any_thread_count_and_bucket_size() {
    let occluder =
        "AttributeBegin\nSurface \"constant\"\nTranslate 0.3 0 11\nDisk 0 0.4 360\nAttributeEnd";
    let rib = disk_scene(
        1.5,
        2.0,
        0.25,
        9,
        r#"Attribute "light" "shadows" ["on"]"#,
        occluder,
    )
    .replace("Format 4 4 1", "Format 32 32 1")
    .replace(
        "ScreenWindow -0.01 0.01 -0.01 0.01",
        "ScreenWindow -1 1 -1 1",
    );
    let render = |threads: usize, bucket: u32| {
        let opts = RenderOptions {
            threads,
            bucket_size: Some([bucket, bucket]),
            ..Default::default()
        };
        film_rgb(&common::render_rib_with(&rib, &[shaders()], &opts).0)
    };
    let a = render(1, 16);
    let b = render(2, 5);
    assert!(a == b, "images differ");
    // The penumbra is there: neither all lit nor all dark.
    let reds: Vec<f32> = a.chunks_exact(3).map(|p| p[0]).collect();
    let (lo, hi) = reds
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    assert!(hi > 1.5 * lo && lo > 0.0, "{lo} {hi}");
}
