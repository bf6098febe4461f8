//! The reflection models of stdlib/include/reflectance.h, evaluated through the shading
//! language itself: a test shader turns (s, t) on a full-frame orthographic square into a
//! direction on the hemisphere (θ = s·π/2, φ = t·2π) and writes the integrand times the
//! Jacobian (dω = sinθ·π²·ds·dt), so the film's mean is the integral over the hemisphere.

mod common;

use common::{film_mean, render_rib, scratch_dir};

const PROBE: &str = r#"
#include "reflectance.h"
surface probe(float which = 0; float m = 0.3; float thetav = 0.5; float ax = 0.1;
              float ay = 0.3; float cosi = 1; float eta = 1.5;)
{
    float th = s * PI / 2;
    float ph = t * 2 * PI;
    vector D = vector(sin(th) * cos(ph), sin(th) * sin(ph), cos(th));
    normal Nn = normal(0, 0, 1);
    vector Vd = vector(sin(thetav), 0, cos(thetav));
    float jac = sin(th) * PI * PI;
    color f = 0;
    if (which == 0)      /* ∫ D(H) cosα dω_H: the distribution's normalisation */
        f = beckmann(cos(th), m) * cos(th) * jac;
    else if (which == 1) /* Cook–Torrance albedo with a perfect mirror (F0 → 1) */
        f = cooktorrance_brdf(Nn, D, Vd, m, color(1, 1, 1)) * cos(th) * jac;
    else if (which == 2) /* Torrance–Sparrow albedo with F ≤ 1 */
        f = torrancesparrow_brdf(Nn, D, Vd, m, 1000) * cos(th) * jac;
    else if (which == 3)
        f = ward_brdf(Nn, D, Vd, vector(1, 0, 0), ax, ay) * cos(th) * jac;
    else if (which == 4)
        f = orennayar_brdf(Nn, D, Vd, m) * cos(th) * jac;
    else if (which == 5)
        f = blinn_brdf(Nn, D, Vd, m) * cos(th) * jac;
    else if (which == 6)
        f = phong_brdf(Nn, D, Vd, m) * cos(th) * jac;
    else if (which == 7)
        f = gaussian_facets(cos(th), m) * cos(th) * jac;
    else if (which == 8) /* Cook–Torrance with real gold (conductor Fresnel) */
        f = cooktorrance_nk_brdf(Nn, D, Vd, m, color(0.143, 0.374, 1.442),
                                 color(3.983, 2.385, 1.603)) * cos(th) * jac;
    else if (which == 10) /* constants: the Fresnel terms at cos θi = cosi */
        f = fresnel_dielectric(cosi, eta);
    else if (which == 11) {
        color n = 0, k = 0;
        float ok = metal_nk("gold", n, k);
        f = fresnel_conductor_rgb(cosi, n, k);
    } else if (which == 12)
        f = fresnel_rgb(cosi, F0_GOLD);
    else if (which == 13)
        f = fresnel_conductor(cosi, eta, 0);
    Ci = f;
    Oi = 1;
}
"#;

/// Mean of the probe over the unit square of (s, t), with the given parameters.
fn probe(params: &str) -> [f64; 3] {
    // Written once: the tests run in parallel and read it concurrently.
    static DIR: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    let dir = DIR
        .get_or_init(|| {
            let d = scratch_dir("procedural_reflectance");
            std::fs::write(d.join("probe.sl"), PROBE).unwrap();
            d
        })
        .clone();
    let rib = format!(
        r#"Format 48 48 1
PixelSamples 4 4
PixelFilter "box" 1 1
Projection "orthographic"
ScreenWindow 0 1 0 1
Display "probe" "file" "rgb"
WorldBegin
  Surface "probe" {params}
  Polygon "P" [0 0 1  1 0 1  1 1 1  0 1 1]
WorldEnd
"#
    );
    film_mean(&render_rib(&rib, &[dir]))
}

fn p(name: &str, v: f32) -> String {
    format!("\"uniform float {name}\" [{v}]")
}

#[test]
fn fresnel_at_normal_incidence_for_glass_is_004() {
    let f = probe(&[p("which", 10.0), p("cosi", 1.0), p("eta", 1.5)].join(" "));
    assert!((f[0] - 0.04).abs() < 1e-5, "F(0°, n=1.5) = {}", f[0]);
    // water, and the table of notes/shading.md R3 at 60° and 85°
    let w = probe(&[p("which", 10.0), p("cosi", 1.0), p("eta", 1.333)].join(" "));
    assert!((w[0] - 0.02037).abs() < 1e-4, "F(0°, n=1.333) = {}", w[0]);
    let f60 = probe(&[p("which", 10.0), p("cosi", 0.5), p("eta", 1.5)].join(" "));
    assert!((f60[0] - 0.08919).abs() < 2e-4, "F(60°) = {}", f60[0]);
    let f85 = probe(
        &[
            p("which", 10.0),
            p("cosi", 85f32.to_radians().cos()),
            p("eta", 1.5),
        ]
        .join(" "),
    );
    assert!((f85[0] - 0.61280).abs() < 2e-3, "F(85°) = {}", f85[0]);
    // grazing: 1; and the conductor formula with k = 0 equals the dielectric one
    let g = probe(&[p("which", 10.0), p("cosi", 0.0), p("eta", 1.5)].join(" "));
    assert!((g[0] - 1.0).abs() < 1e-5);
    let c = probe(&[p("which", 13.0), p("cosi", 0.5), p("eta", 1.5)].join(" "));
    assert!(
        (c[0] - f60[0]).abs() < 1e-4,
        "conductor k=0 {} vs {}",
        c[0],
        f60[0]
    );
}

#[test]
fn beckmann_integrates_to_one_over_the_projected_hemisphere() {
    for m in [0.2f32, 0.3, 0.6] {
        let i = probe(&[p("which", 0.0), p("m", m)].join(" "));
        assert!(
            (i[0] - 1.0).abs() < 0.01,
            "∫D cos dω = {} for m = {m}",
            i[0]
        );
    }
    // the Torrance–Sparrow Gaussian, normalised by its small-slope expansion
    for m in [0.2f32, 0.4] {
        let i = probe(&[p("which", 7.0), p("m", m)].join(" "));
        assert!(
            (i[0] - 1.0).abs() < 0.02,
            "Gaussian ∫D cos dω = {} for m = {m}",
            i[0]
        );
    }
}

#[test]
fn metals_tend_to_white_at_grazing_angles() {
    let ratio =
        |c: [f64; 3]| c.iter().cloned().fold(0.0, f64::max) / c.iter().cloned().fold(1.0, f64::min);
    for which in [11.0, 12.0] {
        let at =
            |deg: f32| probe(&[p("which", which), p("cosi", deg.to_radians().cos())].join(" "));
        let (r0, r60, r85, r89) = (
            ratio(at(0.0)),
            ratio(at(60.0)),
            ratio(at(85.0)),
            ratio(at(89.9)),
        );
        assert!(r0 > 2.0, "gold is coloured head-on: ratio {r0}");
        assert!(r0 > r60 && r60 > r85 && r85 > r89, "{r0} {r60} {r85} {r89}");
        // at grazing incidence every channel reflects everything: white
        let grazing = probe(&[p("which", which), p("cosi", 0.0)].join(" "));
        assert!(
            grazing.iter().all(|&v| (v - 1.0).abs() < 2e-3),
            "grazing {grazing:?}"
        );
    }
    // the book's RGB procedure reproduces F0 at normal incidence
    let f0 = probe(&[p("which", 12.0), p("cosi", 1.0)].join(" "));
    assert!(
        (f0[1] - 0.71).abs() < 1e-3 && (f0[2] - 0.29).abs() < 1e-3,
        "{f0:?}"
    );
}

/// White furnace: with every light direction equally bright, no model reflects more than
/// it receives, ∫ f cosθ dω ≤ 1, at normal, oblique and grazing views.
#[test]
fn no_model_reflects_more_than_it_receives() {
    let views = [0.0f32, 0.8, 1.4];
    let cases: &[(&str, f32, &[(&str, f32)])] = &[
        ("cook-torrance m=0.2", 1.0, &[("m", 0.2)]),
        ("cook-torrance m=0.5", 1.0, &[("m", 0.5)]),
        ("torrance-sparrow", 2.0, &[("m", 0.3)]),
        ("ward", 3.0, &[("ax", 0.1), ("ay", 0.3)]),
        ("ward rough", 3.0, &[("ax", 0.4), ("ay", 0.4)]),
        ("oren-nayar", 4.0, &[("m", 0.5)]),
        ("blinn n=20", 5.0, &[("m", 20.0)]),
        ("phong n=10", 6.0, &[("m", 10.0)]),
        ("gold", 8.0, &[("m", 0.3)]),
    ];
    for (name, which, extra) in cases {
        for &tv in &views {
            let mut ps = vec![p("which", *which), p("thetav", tv)];
            ps.extend(extra.iter().map(|(n, v)| p(n, *v)));
            let a = probe(&ps.join(" "));
            assert!(
                a.iter().all(|&v| v <= 1.0 + 0.01 && v >= 0.0),
                "{name} at view {tv}: albedo {a:?}"
            );
        }
    }
    // Lambert (Oren–Nayar with σ = 0) reflects exactly all of it: checks the integration.
    let lambert = probe(&[p("which", 4.0), p("m", 0.0), p("thetav", 0.3)].join(" "));
    assert!(
        (lambert[0] - 1.0).abs() < 0.01,
        "Lambert albedo {}",
        lambert[0]
    );
    // A smooth mirror-like Cook–Torrance at normal view keeps most of the light.
    let ct = probe(&[p("which", 1.0), p("m", 0.2), p("thetav", 0.0)].join(" "));
    assert!(ct[0] > 0.85, "smooth Cook–Torrance albedo {}", ct[0]);
}
