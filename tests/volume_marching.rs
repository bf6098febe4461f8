//! `illuminance(pos)` at positions other than the surface point (volume shaders that march a
//! ray) runs the lights there: every light once over the whole grid at the new positions,
//! with `lightsource()` reading that light's values. Scenes and shaders are our own.

mod common;

use arbor::render::driver::RenderOptions;

/// Renders `rib` (21×21) with the shaders in `files`; returns the picture as rgb rows.
fn picture(name: &str, rib: &str, files: &[(&str, &str)], threads: usize) -> Vec<f32> {
    let dir = common::scratch_dir(name);
    for (f, text) in files {
        std::fs::write(dir.join(f), text).unwrap();
    }
    let opts = RenderOptions {
        threads,
        ..Default::default()
    };
    let (film, _, _) = common::render_rib_with(rib, &[dir], &opts);
    common::film_rgb(&film)
}

/// The centre pixel's rgb of [`picture`].
fn centre(name: &str, rib: &str, files: &[(&str, &str)], threads: usize) -> [f32; 3] {
    let rgb = picture(name, rib, files, threads);
    let k = (10 * 21 + 10) * 3;
    [rgb[k], rgb[k + 1], rgb[k + 2]]
}

// Light arriving halfway between the eye and the surface point (the eye is at the origin of
// camera space, so that point is P / 2), from every light whose __foglight is not 0.
const MIDWAY: &str = "volume midway()
{
    color c = 0;
    point mid = P - 0.5 * I;
    illuminance(mid) {
        float fog = 1;
        lightsource(\"__foglight\", fog);
        if (fog > 0)
            c += Cl;
    }
    Ci = c;
    Oi = 1;
}
";

const FOGLAMP: &str = "light foglamp(float intensity = 1; point from = point \"shader\" (0, 0, 0);
                     output float __foglight = 1;)
{
    illuminate(from)
        Cl = intensity / (L . L);
}
";

/// A wall at z = 4 seen through the centre pixel (21×21, no jitter, box filter: the centre
/// sample is the ray through (0, 0, 4), shaded at a grid point up to a pixel away); world
/// space is camera space.
fn scene(lights: &str) -> String {
    format!(
        r#"Format 21 21 1
PixelSamples 1 1
PixelFilter "box" 1 1
Hider "hidden" "jitter" [0]
Projection "perspective" "fov" [30]
WorldBegin
{lights}
Atmosphere "midway"
Surface "constant"
Polygon "P" [-5 -5 4  5 -5 4  5 5 4  -5 5 4]
WorldEnd
"#
    )
}

#[test]
fn illuminance_at_a_marched_point_sees_the_light_there() {
    // A point light on the axis 1 unit before the midpoint (0, 0, 2): Cl = 1 there, but 1/9
    // at the wall. (On the axis, the half-pixel offset of the shading point hardly matters.)
    let rib = scene(r#"LightSource "pointlight" 1 "from" [0 0 1]"#);
    let c = centre("vol_midway", &rib, &[("midway.sl", MIDWAY)], 1);
    for v in c {
        assert!((v - 1.0).abs() < 5e-3, "{c:?}");
    }
}

#[test]
fn lightsource_reads_the_light_being_run_at_the_marched_point() {
    // The second lamp (5 times brighter, as far on the other side) is not a fog light.
    let rib = scene(
        r#"LightSource "foglamp" 1 "from" [0 0 1]
LightSource "foglamp" 2 "from" [0 0 3] "intensity" [5] "__foglight" [0]"#,
    );
    let files = [("midway.sl", MIDWAY), ("foglamp.sl", FOGLAMP)];
    let c = centre("vol_foglight", &rib, &files, 1);
    for v in c {
        assert!((v - 1.0).abs() < 5e-3, "{c:?}");
    }
    // The same picture with every core.
    assert_eq!(centre("vol_foglight", &rib, &files, 0), c);
}

// A march whose length differs across the grid: points left of the axis take one step to the
// midpoint, points right of it take three (the last at the midpoint), so the lights run on
// fewer points than the grid holds from the second step on. Each step's light is what a light
// at that position gives, whichever points are still marching.
const UNEVEN: &str = "volume uneven()
{
    color c = 0;
    float steps = xcomp(P) < 0 ? 1 : 3;
    float k;
    for (k = 1; k <= steps; k += 1) {
        point at = P - (0.5 * k / steps) * I;
        color here = 0;
        illuminance(at) {
            float fog = 1;
            lightsource(\"__foglight\", fog);
            if (fog > 0)
                here += Cl;
        }
        c = here;
    }
    Ci = c;
    Oi = 1;
}
";

#[test]
fn lights_run_for_the_points_still_marching_see_each_points_position() {
    let rib = scene(r#"LightSource "foglamp" 1 "from" [0 0 1]"#).replace("midway", "uneven");
    let files = [("uneven.sl", UNEVEN), ("foglamp.sl", FOGLAMP)];
    let rgb = picture("vol_uneven", &rib, &files, 1);
    // Every point ends at its midpoint P/2, whatever its step count: on the axis row the
    // colour is 1 / |P/2 - (0,0,1)|², the same on both sides of the centre.
    let row = 10;
    for col in [6usize, 8, 12, 14] {
        let k = (row * 21 + col) * 3;
        // The pixel's ray through the wall at z = 4 (fov 30 over 21 pixels).
        let x = ((col as f32 + 0.5) / 21.0 * 2.0 - 1.0) * (15f32.to_radians()).tan() * 4.0;
        let mid = glam::Vec3::new(x / 2.0, 0.0, 2.0);
        let want = 1.0 / (mid - glam::Vec3::Z).length_squared();
        // The shading point is up to a pixel from the sample: a tolerance of a few percent.
        assert!(
            (rgb[k] - want).abs() < 0.04 * want,
            "column {col}: {} against {want}",
            rgb[k]
        );
    }
    assert_eq!(picture("vol_uneven", &rib, &files, 0), rgb);
}

// The standard library's `smoke` (BMRT's interface): with neither light nor noise, a uniform
// medium of density σ in front of a white wall 4 units away transmits exp(-4σ).
#[test]
fn smoke_attenuates_the_background_by_its_optical_depth() {
    let rib = scene("")
        .replace(
            "Atmosphere \"midway\"",
            "Atmosphere \"smoke\" \"density\" [0.5] \"stepsize\" [0.01] \"use_lighting\" [0] \
             \"use_noise\" [0] \"lightscale\" [0]",
        )
        .replace("Surface \"constant\"", "Surface \"constant\" Color [1 1 1]");
    let c = centre("vol_smoke_depth", &rib, &[], 1);
    let want = (-0.5f32 * 4.0).exp();
    for v in c {
        assert!((v - want).abs() < 0.01, "{c:?} against {want}");
    }
}

// A scene written for BMRT's `smoke` finds another shader of that name first on its path
// (Advanced RenderMan's, whose parameters are different): the one whose parameters the scene
// gives is used, with a warning, instead of a medium the scene never asked for.
#[test]
fn a_same_named_shader_with_the_scenes_parameters_is_preferred() {
    let other = "volume smoke(float opacdensity = 1, lightdensity = 1) { Ci = 0; Oi = 1; }";
    let rib = scene("")
        .replace(
            "Atmosphere \"midway\"",
            "Atmosphere \"smoke\" \"density\" [0.5] \"stepsize\" [0.01] \"use_lighting\" [0] \
             \"use_noise\" [0] \"lightscale\" [0]",
        )
        .replace("Surface \"constant\"", "Surface \"constant\" Color [1 1 1]");
    let dir = common::scratch_dir("vol_smoke_version");
    std::fs::write(dir.join("smoke.sl"), other).unwrap();
    let (film, diags, _) = common::render_rib_with(&rib, &[dir], &RenderOptions::default());
    assert!(
        diags.iter().any(|(d, _)| d.code == "shade::version"),
        "no version warning"
    );
    let rgb = common::film_rgb(&film);
    let k = (film.height / 2 * film.width + film.width / 2) * 3;
    assert!((rgb[k] - (-2f32).exp()).abs() < 0.01, "{}", rgb[k]);
}
