//! Horizon mapping (Max) known answers through the public API: notes shading.md §7.4.

use arbor::texture::horizon::{standard_light, visibility, HorizonTable};
use glam::Vec3;

const N: usize = 64;

fn ridge(n: usize, x: usize, h: f32) -> Vec<f32> {
    let mut f = vec![0.0; n * n];
    for y in 0..n {
        f[y * n + x] = h;
    }
    f
}

/// Light on the standard patch from zenith angle φ (degrees) and azimuth θ (degrees).
fn light(phi: f32, theta: f32) -> Vec3 {
    let (p, t) = (phi.to_radians(), theta.to_radians());
    Vec3::new(p.sin() * t.cos(), p.sin() * t.sin(), p.cos())
}

fn centre(x: usize, y: usize) -> (f32, f32) {
    ((x as f32 + 0.5) / N as f32, (y as f32 + 0.5) / N as f32)
}

#[test]
fn ridge_64_texels_gives_68_20_degrees_through_a_file() {
    let t = HorizonTable::build(&ridge(N, 18, 0.05), N, N, 8).unwrap();
    let path = std::env::temp_dir().join(format!("arbor_ridge_{}.hzn", std::process::id()));
    t.write(&path).unwrap();
    let t = HorizonTable::read(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    let (s, tt) = centre(10, 7);
    let beta = 90.0 - t.elevation(s, tt, 0.0, 1.0).to_degrees();
    assert!((beta - 68.20).abs() < 0.01, "β_E = {beta}");
    // A light at φ = 68° (east) is lit, at 69° shadowed (hard test).
    assert_eq!(visibility(&t, s, tt, light(68.0, 0.0), 1.0, 0.0), 1.0);
    assert_eq!(visibility(&t, s, tt, light(69.0, 0.0), 1.0, 0.0), 0.0);
    // Well below the ridge's horizon the disc light is fully hidden, at the horizon half.
    let pen = 2f32.to_radians();
    assert_eq!(visibility(&t, s, tt, light(75.0, 0.0), 1.0, pen), 0.0);
    let half = visibility(&t, s, tt, light(beta, 0.0), 1.0, pen);
    assert!((half - 0.5).abs() < 0.01, "{half}");
    // Diagonal case of H2: a ridge 8 texels east is 8√2 away along NE? No: along NE the
    // ridge column is reached after 8 steps of length √2/64.
    let ne = 90.0 - t.elevation(s, tt, 45f32.to_radians(), 1.0).to_degrees();
    assert!((ne - 74.21).abs() < 0.01, "β_NE = {ne}");
    // "scale" doubles the heights exactly: tan doubles.
    let e2 = t.elevation(s, tt, 0.0, 2.0).tan();
    assert!((e2 - 0.8).abs() < 1e-4);
}

#[test]
fn flat_map_and_zenith_light_shadow_nothing() {
    let flat = HorizonTable::build(&vec![0.5; N * N], N, N, 16).unwrap();
    let bumpy: Vec<f32> = (0..N * N)
        .map(|i| ((i * 7919 % 97) as f32 / 97.0) * 0.2)
        .collect();
    let bumpy = HorizonTable::build(&bumpy, N, N, 8).unwrap();
    for y in (0..N).step_by(5) {
        for x in (0..N).step_by(3) {
            let (s, t) = centre(x, y);
            for th in (0..360).step_by(15) {
                for phi in [0.0, 30.0, 60.0, 89.0] {
                    assert_eq!(
                        visibility(&flat, s, t, light(phi, th as f32), 1.0, 0.0),
                        1.0
                    );
                }
                // Zenith never shadowed, whatever the bumps.
                assert_eq!(
                    visibility(&bumpy, s, t, light(0.0, th as f32), 1.0, 0.0),
                    1.0
                );
            }
            // Below the surface: always shadowed (H11).
            assert_eq!(visibility(&flat, s, t, light(100.0, 10.0), 1.0, 0.0), 0.0);
        }
    }
}

#[test]
fn rotating_the_map_rotates_the_directions() {
    let f: Vec<f32> = (0..N * N)
        .map(|i| ((i * 104729 % 113) as f32 / 113.0).powi(3) * 0.3)
        .collect();
    // r(x', y') with (x', y') = (−y, x): a +90° rotation of the texel grid.
    let mut r = vec![0.0; N * N];
    for y in 0..N {
        for x in 0..N {
            let (xr, yr) = ((N - y) % N, x);
            r[yr * N + xr] = f[y * N + x];
        }
    }
    for (nd, shift) in [(8usize, 2usize), (16, 4)] {
        let a = HorizonTable::build(&f, N, N, nd).unwrap();
        let b = HorizonTable::build(&r, N, N, nd).unwrap();
        for y in 0..N {
            for x in 0..N {
                let (xr, yr) = (((N - y) % N) as i64, x as i64);
                for k in 0..nd {
                    let (ta, tb) = (
                        a.tan_at(x as i64, y as i64, k),
                        b.tan_at(xr, yr, (k + shift) % nd),
                    );
                    assert!(
                        (ta - tb).abs() <= 1e-4 * ta.abs().max(1.0),
                        "{nd} dirs, k {k} at ({x},{y}): {ta} vs {tb}"
                    );
                }
            }
        }
        // Whole shadow masks rotate too, for a light between tabulated directions.
        let (th, el) = (30f32.to_radians(), 12f32.to_radians());
        let ma = table_mask(&a, th, el, false);
        let mb = table_mask(&b, th + std::f32::consts::FRAC_PI_2, el, false);
        let same = (0..N * N)
            .filter(|&i| {
                let (x, y) = (i % N, i / N);
                ma[i] == mb[x * N + (N - y) % N]
            })
            .count();
        assert!(ma.iter().filter(|v| **v).count() > N * N / 20);
        assert!(same as f32 >= 0.995 * (N * N) as f32, "{nd} dirs: {same}");
        // And so do the shadows: a light rotated by 90° sees the same visibility.
        let (s, t) = centre(20, 9);
        let (sr, tr) = centre((N - 9) % N, 20);
        for th in [10.0f32, 100.0, 200.0, 333.0] {
            for phi in [50.0, 70.0, 80.0] {
                let va = visibility(&a, s, t, light(phi, th), 1.0, 1f32.to_radians());
                let vb = visibility(&b, sr, tr, light(phi, th + 90.0), 1.0, 1f32.to_radians());
                assert!((va - vb).abs() < 1e-4, "θ {th} φ {phi}: {va} vs {vb}");
            }
        }
    }
}

/// Smooth periodic bumps: sum of wrapped Gaussians.
fn bumps(n: usize) -> Vec<f32> {
    let centres = [
        (0.2, 0.3, 0.06, 0.05),
        (0.7, 0.2, 0.05, 0.04),
        (0.5, 0.6, 0.08, 0.06),
        (0.1, 0.8, 0.04, 0.03),
        (0.85, 0.75, 0.06, 0.05),
        (0.35, 0.05, 0.03, 0.02),
    ];
    let mut f = vec![0.0; n * n];
    for y in 0..n {
        for x in 0..n {
            let (s, t) = ((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
            let mut h: f32 = 0.0;
            for &(cs, ct, r, a) in &centres {
                let ds = (s - cs + 0.5).rem_euclid(1.0) - 0.5;
                let dt = (t - ct + 0.5).rem_euclid(1.0) - 0.5;
                h += 3.0 * a * (-(ds * ds + dt * dt) / (r * r)).exp();
            }
            f[y * n + x] = h;
        }
    }
    f
}

fn bilinear(f: &[f32], n: usize, x: f32, y: f32) -> f32 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at =
        |i: i64, j: i64| f[(j.rem_euclid(n as i64) * n as i64 + i.rem_euclid(n as i64)) as usize];
    let (i, j) = (x0 as i64, y0 as i64);
    at(i, j) * (1.0 - fx) * (1.0 - fy)
        + at(i + 1, j) * fx * (1.0 - fy)
        + at(i, j + 1) * (1.0 - fx) * fy
        + at(i + 1, j + 1) * fx * fy
}

/// Ground truth: march the true height field from each texel centre towards the light.
fn marched_mask(f: &[f32], n: usize, theta: f32, elev: f32) -> Vec<bool> {
    let (c, s, tn) = (theta.cos(), theta.sin(), elev.tan());
    let mut m = vec![false; n * n];
    for y in 0..n {
        for x in 0..n {
            let z0 = f[y * n + x];
            let mut d = 0.25f32;
            while d < n as f32 {
                let (qx, qy) = (x as f32 + c * d, y as f32 + s * d);
                if bilinear(f, n, qx, qy) > z0 + tn * d / n as f32 {
                    m[y * n + x] = true;
                    break;
                }
                d += 0.25;
            }
        }
    }
    m
}

fn iou(a: &[bool], b: &[bool]) -> f32 {
    let inter = a.iter().zip(b).filter(|(p, q)| **p && **q).count();
    let union = a.iter().zip(b).filter(|(p, q)| **p || **q).count();
    if union == 0 {
        1.0
    } else {
        inter as f32 / union as f32
    }
}

/// Our shadow mask at texel centres for a standard-patch light (azimuth θ, elevation el).
fn table_mask(t: &HorizonTable, theta: f32, el: f32, max_lookup: bool) -> Vec<bool> {
    let lp = Vec3::new(el.cos() * theta.cos(), el.cos() * theta.sin(), el.sin());
    (0..N * N)
        .map(|i| {
            let (s, tt) = centre(i % N, i / N);
            if max_lookup {
                t.elevation_interpolated(s, tt, theta, 1.0) > el
            } else {
                visibility(t, s, tt, lp, 1.0, 0.0) < 0.5
            }
        })
        .collect()
}

/// Light azimuths (degrees) and elevations: on the 8 tabulated directions, then between them.
const ON: [(f32, f32); 3] = [(0.0, 15.0), (45.0, 20.0), (180.0, 12.0)];
const BETWEEN: [(f32, f32); 7] = [
    (30.0, 20.0),
    (200.0, 12.0),
    (112.5, 25.0),
    (22.5, 15.0),
    (67.5, 20.0),
    (10.0, 15.0),
    (300.0, 18.0),
];

#[test]
fn shadow_masks_agree_with_ray_marched_height_field() {
    let f = bumps(N);
    let mut report = Vec::new();
    for nd in [8usize, 16] {
        let t = HorizonTable::build(&f, N, N, nd).unwrap();
        let (mut worst_on, mut worst_between) = (1.0f32, 1.0f32);
        let (mut max_on, mut max_between) = (1.0f32, 1.0f32);
        for (between, &(theta_deg, elev_deg)) in ON
            .iter()
            .map(|c| (false, c))
            .chain(BETWEEN.iter().map(|c| (true, c)))
        {
            let (th, el) = (theta_deg.to_radians(), elev_deg.to_radians());
            let truth = marched_mask(&f, N, th, el);
            let shadowed = truth.iter().filter(|b| **b).count();
            assert!(
                shadowed > N * N / 50,
                "scene must cast shadows ({shadowed})"
            );
            let q = iou(&truth, &table_mask(&t, th, el, false));
            let qm = iou(&truth, &table_mask(&t, th, el, true));
            report.push(format!(
                "{nd} dirs θ={theta_deg} el={elev_deg}: IoU {q:.3} (Max's θ-interpolation {qm:.3})"
            ));
            if between {
                worst_between = worst_between.min(q);
                max_between = max_between.min(qm);
            } else {
                worst_on = worst_on.min(q);
                max_on = max_on.min(qm);
            }
        }
        report.push(format!(
            "{nd} dirs worst: on {worst_on:.3} between {worst_between:.3} (Max: on {max_on:.3} between {max_between:.3})"
        ));
        assert!(worst_on > 0.95, "{report:#?}");
        assert!(worst_between > 0.9, "{report:#?}");
    }
    eprintln!("{}", report.join("\n"));
}

fn hash(i: u32) -> f32 {
    let mut x = i.wrapping_mul(0x9E37_79B9) ^ 0x85eb_ca6b;
    x ^= x >> 15;
    x = x.wrapping_mul(0x2c1b_3c6d);
    x ^= x >> 12;
    (x & 0xff_ffff) as f32 / 16_777_216.0
}

/// Harder periodic height fields: 40 small bumps (radius 1.5–3.5 texels), smooth value
/// noise on 8-texel cells, and straight ridges running at atan(1/2) off the rows.
fn other_maps() -> Vec<(&'static str, Vec<f32>)> {
    let n = N as f32;
    let wrap = |d: f32| (d + n / 2.0).rem_euclid(n) - n / 2.0;
    let mut small = vec![0f32; N * N];
    for b in 0..40u32 {
        let (cx, cy) = (hash(b * 4) * n, hash(b * 4 + 1) * n);
        let (r, a) = (1.5 + hash(b * 4 + 2) * 2.0, 0.01 + hash(b * 4 + 3) * 0.04);
        for (i, v) in small.iter_mut().enumerate() {
            let (dx, dy) = (wrap((i % N) as f32 - cx), wrap((i / N) as f32 - cy));
            *v += a * (-(dx * dx + dy * dy) / (r * r)).exp();
        }
    }
    let cells = N / 8;
    let value = (0..N * N)
        .map(|i| {
            let (gx, gy) = ((i % N) as f32 / 8.0, (i / N) as f32 / 8.0);
            let (ix, iy) = (gx.floor() as usize, gy.floor() as usize);
            let v = |x: usize, y: usize| hash(((y % cells) * cells + x % cells) as u32 + 999);
            let sm = |f: f32| f * f * (3.0 - 2.0 * f);
            let (sx, sy) = (sm(gx - ix as f32), sm(gy - iy as f32));
            let top = v(ix, iy) * (1.0 - sx) + v(ix + 1, iy) * sx;
            let bot = v(ix, iy + 1) * (1.0 - sx) + v(ix + 1, iy + 1) * sx;
            0.08 * (top * (1.0 - sy) + bot * sy)
        })
        .collect();
    let ridges = (0..N * N)
        .map(|i| {
            let (x, y) = ((i % N) as f32, (i / N) as f32);
            let w = (std::f32::consts::TAU * (2.0 * x + y) / n).sin().max(0.0);
            0.03 * w * w * w
        })
        .collect();
    vec![
        ("small bumps", small),
        ("value noise", value),
        ("ridges", ridges),
    ]
}

#[test]
fn other_height_fields_agree_between_directions() {
    let mut report = Vec::new();
    for (name, f) in other_maps() {
        let t = HorizonTable::build(&f, N, N, 8).unwrap();
        for &(theta_deg, elev_deg) in &BETWEEN[..5] {
            let (th, el) = (theta_deg.to_radians(), elev_deg.to_radians());
            let truth = marched_mask(&f, N, th, el);
            if truth.iter().filter(|b| **b).count() < N * N / 100 {
                continue; // (the ridges cast no shadow along themselves)
            }
            let q = iou(&truth, &table_mask(&t, th, el, false));
            let qm = iou(&truth, &table_mask(&t, th, el, true));
            report.push(format!(
                "{name} θ={theta_deg} el={elev_deg}: IoU {q:.3} (Max {qm:.3})"
            ));
            assert!(q > 0.9, "{report:#?}");
        }
    }
    assert!(report.len() >= 13, "{report:#?}");
    eprintln!("{}", report.join("\n"));
}

#[test]
fn between_directions_no_false_shadows() {
    // Every sample the search takes lies on the light's own ray, so it never shadows a
    // point the marched truth leaves lit (beyond the march's own sampling error).
    let f = bumps(N);
    let t = HorizonTable::build(&f, N, N, 8).unwrap();
    for &(theta_deg, elev_deg) in &BETWEEN {
        let (th, el) = (theta_deg.to_radians(), elev_deg.to_radians());
        let truth = marched_mask(&f, N, th, el);
        let ours = table_mask(&t, th, el, false);
        let false_pos = truth.iter().zip(&ours).filter(|(a, b)| !**a && **b).count();
        assert!(
            false_pos <= N * N / 500,
            "θ {theta_deg}: {false_pos} false shadows"
        );
    }
}

#[test]
fn standard_light_is_scale_invariant_for_uniform_patches() {
    // Max's |N|^{1/2} scaling: doubling the patch leaves the standard-patch light direction.
    let l = Vec3::new(0.3, -0.2, 0.9);
    let a = standard_light(Vec3::X, Vec3::Y, Vec3::Z, l)
        .unwrap()
        .normalize();
    let b = standard_light(Vec3::X * 2.0, Vec3::Y * 2.0, Vec3::Z, l)
        .unwrap()
        .normalize();
    assert!((a - b).length() < 1e-6);
}

/// Build time of 1024² tables (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn time_1024() {
    let n = 1024;
    let f: Vec<f32> = (0..n * n)
        .map(|i| (((i % n) as f32 * 0.05).sin() * ((i / n) as f32 * 0.03).cos()).abs() * 0.05)
        .collect();
    for nd in [8, 16] {
        let t0 = std::time::Instant::now();
        let t = HorizonTable::build(&f, n, n, nd).unwrap();
        eprintln!(
            "1024² × {nd} directions: {:.2} s",
            t0.elapsed().as_secs_f64()
        );
        assert_eq!(t.tans.len(), n * n * nd);
        // Lookup cost, occluder search against Max's interpolation (light 20° up).
        let m = 200_000;
        let el = 20f32.to_radians(); // φ = 70°
        let mut lit = [0usize; 2];
        for (j, count) in lit.iter_mut().enumerate() {
            let t0 = std::time::Instant::now();
            for i in 0..m {
                let (s, tt) = (hash(2 * i as u32), hash(2 * i as u32 + 1));
                let th = hash(i as u32 + 77) * std::f32::consts::TAU;
                let lit = if j == 0 {
                    visibility(&t, s, tt, light(70.0, th.to_degrees()), 1.0, 0.0) > 0.5
                } else {
                    t.elevation_interpolated(s, tt, th, 1.0) < el
                };
                *count += lit as usize;
            }
            eprintln!(
                "  {}: {:.0} ns per lookup, {:.2} lit",
                ["search", "Max interpolation"][j],
                t0.elapsed().as_secs_f64() * 1e9 / m as f64,
                *count as f64 / m as f64
            );
        }
    }
}
