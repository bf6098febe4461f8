//! Patches, patch meshes, NURBS and trim curves through `geom::surfaces_for`: diced grids
//! checked against direct evaluation, known points and seams.

use arbor::diag::{Diagnostics, Severity, SourceMap};
use arbor::geom::{surfaces_for, Surface};
use arbor::rib::parse_bytes;
use arbor::scene::{build_scenes, BuildContext, Scene};
use arbor::shade::Grid;
use glam::{Mat4, Vec3};

struct Built {
    scene: Scene,
    surfaces: Vec<Vec<Box<dyn Surface>>>,
    diags: Diagnostics,
}

impl Built {
    fn errors(&self) -> Vec<String> {
        self.diags
            .snapshot()
            .into_iter()
            .filter(|(d, _)| d.severity == Severity::Error)
            .map(|(d, _)| format!("{}: {}", d.code, d.message))
            .collect()
    }
}

/// Builds `body` inside WorldBegin/WorldEnd; camera space = world space.
fn build(body: &str) -> Built {
    let text = format!("WorldBegin\n{body}\nWorldEnd\n");
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = parse_bytes("p.rib", text.as_bytes(), &sources, &diags);
    let scene = build_scenes(reqs, &BuildContext::new(&sources, &diags))
        .pop()
        .expect("a scene");
    let surfaces = scene
        .primitives
        .iter()
        .enumerate()
        .map(|(i, p)| surfaces_for(i, p, Mat4::IDENTITY, &diags))
        .collect();
    Built {
        scene,
        surfaces,
        diags,
    }
}

fn nums(v: &[f32]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).length() <= tol
}

/// Sixteen fixed, irregular control points.
fn points16() -> Vec<f32> {
    (0..16)
        .flat_map(|k| {
            let (i, j) = ((k % 4) as f32, (k / 4) as f32);
            [
                i + 0.1 * (k as f32 * 1.7).sin(),
                j + 0.2 * (k as f32 * 0.9).cos(),
                0.5 * ((i - 1.5) * (j - 1.0)).sin(),
            ]
        })
        .collect()
}

/// Direct evaluation of `U·M·P·Mᵀ·Vᵀ` (notes §1), u fastest control points.
fn direct(m: &[[f64; 4]; 4], pts: &[f32], u: f64, v: f64) -> (Vec3, Vec3) {
    let basis = |t: f64| -> [f64; 4] {
        let uu = [t * t * t, t * t, t, 1.0];
        std::array::from_fn(|c| (0..4).map(|r| uu[r] * m[r][c]).sum())
    };
    let dbasis = |t: f64| -> [f64; 4] {
        let uu = [3.0 * t * t, 2.0 * t, 1.0, 0.0];
        std::array::from_fn(|c| (0..4).map(|r| uu[r] * m[r][c]).sum())
    };
    let (bu, bv, dbu) = (basis(u), basis(v), dbasis(u));
    let (mut p, mut du) = ([0.0f64; 3], [0.0f64; 3]);
    for j in 0..4 {
        for i in 0..4 {
            for c in 0..3 {
                let x = pts[(j * 4 + i) * 3 + c] as f64;
                p[c] += bu[i] * bv[j] * x;
                du[c] += dbu[i] * bv[j] * x;
            }
        }
    }
    (
        Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32),
        Vec3::new(du[0] as f32, du[1] as f32, du[2] as f32),
    )
}

#[test]
fn bicubic_patches_in_every_basis_match_direct_evaluation() {
    let bases: [(&str, u32, [[f64; 4]; 4], f64); 5] = [
        (
            "bezier",
            3,
            [
                [-1., 3., -3., 1.],
                [3., -6., 3., 0.],
                [-3., 3., 0., 0.],
                [1., 0., 0., 0.],
            ],
            1.0,
        ),
        (
            "b-spline",
            1,
            [
                [-1., 3., -3., 1.],
                [3., -6., 3., 0.],
                [-3., 0., 3., 0.],
                [1., 4., 1., 0.],
            ],
            1.0 / 6.0,
        ),
        (
            "catmull-rom",
            1,
            [
                [-1., 3., -3., 1.],
                [2., -5., 4., -1.],
                [-1., 0., 1., 0.],
                [0., 2., 0., 0.],
            ],
            0.5,
        ),
        (
            "hermite",
            2,
            [
                [2., 1., -2., 1.],
                [-3., -2., 3., -1.],
                [0., 1., 0., 0.],
                [1., 0., 0., 0.],
            ],
            1.0,
        ),
        (
            "power",
            4,
            [
                [1., 0., 0., 0.],
                [0., 1., 0., 0.],
                [0., 0., 1., 0.],
                [0., 0., 0., 1.],
            ],
            1.0,
        ),
    ];
    let pts = points16();
    for (name, step, m, s) in bases {
        let m = m.map(|r| r.map(|x| x * s));
        let b = build(&format!(
            "Basis \"{name}\" {step} \"{name}\" {step}\nPatch \"bicubic\" \"P\" [{}]",
            nums(&pts)
        ));
        assert!(b.errors().is_empty(), "{:?}", b.errors());
        assert_eq!(b.surfaces[0].len(), 1, "{name}");
        let g = b.surfaces[0][0].dice(5, 5);
        for j in 0..5 {
            for i in 0..5 {
                let k = j * 5 + i;
                let (p, du) = direct(&m, &pts, i as f64 / 4.0, j as f64 / 4.0);
                assert!(
                    close(g.p[k], p, 1e-4),
                    "{name} P at {i},{j}: {} vs {p}",
                    g.p[k]
                );
                assert!(
                    close(g.dpdu[k], du, 1e-3),
                    "{name} dPdu at {i},{j}: {} vs {du}",
                    g.dpdu[k]
                );
                assert!((g.u[k] - i as f32 / 4.0).abs() < 1e-6);
            }
        }
    }
}

/// Hermite and power control values are partly tangents (their basis rows do not sum to 1),
/// so a translating camera must move the surface once, not once per weight (Aqsis's
/// Bug1102597 draws a power-basis curve over its Bézier twin; it was drawn off to one side).
#[test]
fn tangent_bases_under_a_translating_camera_match_direct_evaluation() {
    let shift = Vec3::new(0.5, -2.0, 7.0);
    let cam = Mat4::from_translation(shift);
    let hermite = [
        [2., 1., -2., 1.],
        [-3., -2., 3., -1.],
        [0., 1., 0., 0.],
        [1., 0., 0., 0.],
    ];
    let power = [
        [1., 0., 0., 0.],
        [0., 1., 0., 0.],
        [0., 0., 1., 0.],
        [0., 0., 0., 1.],
    ];
    let pts = points16();
    for (name, step, m) in [("hermite", 2, hermite), ("power", 4, power)] {
        let b = build(&format!(
            "Basis \"{name}\" {step} \"{name}\" {step}\nPatch \"bicubic\" \"P\" [{}]",
            nums(&pts)
        ));
        assert!(b.errors().is_empty(), "{:?}", b.errors());
        let surfs = surfaces_for(0, &b.scene.primitives[0], cam, &b.diags);
        let g = surfs[0].dice(5, 5);
        for j in 0..5 {
            for i in 0..5 {
                let (p, du) = direct(&m, &pts, i as f64 / 4.0, j as f64 / 4.0);
                let k = j * 5 + i;
                assert!(
                    close(g.p[k], p + shift, 1e-4),
                    "{name} patch P at {i},{j}: {} vs {}",
                    g.p[k],
                    p + shift
                );
                assert!(close(g.dpdu[k], du, 1e-3), "{name} patch dPdu at {i},{j}");
            }
        }
        // A curve in the v basis: the first row of the points as its four control values.
        let b = build(&format!(
            "Basis \"bezier\" 3 \"{name}\" {step}\nCurves \"cubic\" [4] \"nonperiodic\" \"P\" [{}] \"constantwidth\" [0.01]",
            nums(&pts[..12])
        ));
        assert!(b.errors().is_empty(), "{:?}", b.errors());
        let surfs = surfaces_for(0, &b.scene.primitives[0], cam, &b.diags);
        assert_eq!(surfs.len(), 1, "{name}: one curve segment");
        let g = surfs[0].dice(3, 5);
        for j in 0..5 {
            let t = j as f64 / 4.0;
            let tt = [t * t * t, t * t, t, 1.0];
            let mut want = Vec3::ZERO;
            for (c, _) in m.iter().enumerate() {
                let w: f64 = (0..4).map(|r| tt[r] * m[r][c]).sum();
                want += w as f32 * Vec3::new(pts[c * 3], pts[c * 3 + 1], pts[c * 3 + 2]);
            }
            // The ribbon's middle column lies on the curve.
            let mid = g.p[j * 3 + 1];
            assert!(
                close(mid, want + shift, 1e-4),
                "{name} curve at t={t}: {mid} vs {}",
                want + shift
            );
        }
    }
}

#[test]
fn dicing_at_two_rates_gives_the_same_surface() {
    let b = build(&format!(
        "Basis \"catmull-rom\" 1 \"b-spline\" 1\nPatch \"bicubic\" \"P\" [{}]",
        nums(&points16())
    ));
    let s = &b.surfaces[0][0];
    let (coarse, fine) = (s.dice(5, 5), s.dice(9, 9));
    for j in 0..5 {
        for i in 0..5 {
            let (a, f) = (coarse.p[j * 5 + i], fine.p[2 * j * 9 + 2 * i]);
            assert!(close(a, f, 1e-5), "{a} vs {f}");
            assert!(close(coarse.n[j * 5 + i], fine.n[2 * j * 9 + 2 * i], 1e-4));
        }
    }
    // Split halves reproduce the parent too (exact de Casteljau halves).
    let kids = s.split();
    assert_eq!(kids.len(), 2);
    let (ga, gb) = (kids[0].dice(3, 3), kids[1].dice(3, 3));
    let all: Vec<(f32, f32, Vec3)> = [ga, gb]
        .iter()
        .flat_map(|g| {
            (0..g.len())
                .map(|k| (g.u[k], g.v[k], g.p[k]))
                .collect::<Vec<_>>()
        })
        .collect();
    for (u, v, p) in all {
        let (i, j) = ((u * 8.0).round() as usize, (v * 8.0).round() as usize);
        assert!(
            close(p, fine.p[j * 9 + i], 1e-4),
            "child point at ({u},{v})"
        );
    }
}

#[test]
fn periodic_bspline_mesh_closes_seamlessly() {
    // 8 points around a circle (u, periodic) × 4 rings up z (v, nonperiodic).
    let mut pts = Vec::new();
    for j in 0..4 {
        for i in 0..8 {
            let a = i as f32 * std::f32::consts::TAU / 8.0;
            pts.extend([a.cos(), a.sin(), j as f32]);
        }
    }
    let b = build(&format!(
        "Basis \"b-spline\" 1 \"b-spline\" 1\nPatchMesh \"bicubic\" 8 \"periodic\" 4 \"nonperiodic\" \"P\" [{}]",
        nums(&pts)
    ));
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let s = &b.surfaces[0];
    assert_eq!(s.len(), 8);
    let grids: Vec<Grid> = s.iter().map(|s| s.dice(5, 5)).collect();
    for a in 0..8 {
        let (g, h) = (&grids[a], &grids[(a + 1) % 8]);
        for j in 0..5 {
            assert!(close(g.p[j * 5 + 4], h.p[j * 5], 1e-5), "seam {a} row {j}");
            assert!(close(g.n[j * 5 + 4], h.n[j * 5], 1e-4), "normal seam {a}");
        }
        assert!((g.u[0] - a as f32 / 8.0).abs() < 1e-6);
    }
    // The last column of the last patch meets the first column of the first.
    assert!(close(grids[7].p[4], grids[0].p[0], 1e-5));
    // Normals point outward (dPdu × dPdv with u counter-clockwise, v up).
    let g = &grids[0];
    assert!(g.ng[12].dot(Vec3::new(g.p[12].x, g.p[12].y, 0.0)) > 0.0);
}

#[test]
fn nurbs_quarter_circle_cylinder_is_exact() {
    let r = std::f32::consts::FRAC_1_SQRT_2;
    // u: rational quadratic quarter circle; v: linear in z. Pw is homogeneous (x·w, y·w, z·w, w).
    let mut pw = Vec::new();
    for z in [0.0f32, 2.0] {
        for (x, y, w) in [(1.0, 0.0, 1.0), (1.0, 1.0, r), (0.0, 1.0, 1.0)] {
            pw.extend([x * w, y * w, z * w, w]);
        }
    }
    let b = build(&format!(
        "NuPatch 3 3 [0 0 0 1 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"Pw\" [{}]",
        nums(&pw)
    ));
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let g = b.surfaces[0][0].dice(9, 3);
    for k in 0..g.len() {
        let p = g.p[k];
        assert!((p.x.hypot(p.y) - 1.0).abs() < 1e-5, "radius at {k}: {p}");
        assert!((p.z - 2.0 * g.v[k]).abs() < 1e-5);
        // dPdu is tangent to the circle.
        assert!(g.dpdu[k].dot(Vec3::new(p.x, p.y, 0.0)).abs() < 1e-4);
    }
    assert!(close(g.p[4], Vec3::new(r, r, 0.0), 1e-5), "{}", g.p[4]);
}

/// Cox–de Boor basis function N_{i,k} (k = order), 0/0 = 0.
fn cox(knots: &[f32], i: usize, k: usize, u: f32) -> f32 {
    if k == 1 {
        let last = knots.len() - 1;
        let closed_end = u == knots[last] && knots[i + 1] == knots[last] && knots[i] < u;
        return (knots[i] <= u && u < knots[i + 1] || closed_end) as i32 as f32;
    }
    let mut s = 0.0;
    let d1 = knots[i + k - 1] - knots[i];
    if d1 > 0.0 {
        s += (u - knots[i]) / d1 * cox(knots, i, k - 1, u);
    }
    let d2 = knots[i + k] - knots[i + 1];
    if d2 > 0.0 {
        s += (knots[i + k] - u) / d2 * cox(knots, i + 1, k - 1, u);
    }
    s
}

#[test]
fn nurbs_of_degree_one_to_three_reproduce_cox_de_boor() {
    for order in 2..=4usize {
        // 5 × 2 control points, clamped knots with interior knots (two or more spans in u).
        let n = 5;
        let mut knots = vec![0.0f32; order];
        for k in 1..=(n - order) {
            knots.push(k as f32);
        }
        let end = (n - order + 1) as f32;
        knots.extend(std::iter::repeat(end).take(order));
        let xs: Vec<[f32; 3]> = (0..n)
            .map(|i| [i as f32, ((i * 7) % 3) as f32 - 1.0, (i as f32 * 0.8).sin()])
            .collect();
        let mut p = Vec::new();
        for j in 0..2 {
            for x in &xs {
                p.extend([x[0], x[1] + 3.0 * j as f32, x[2]]);
            }
        }
        let b = build(&format!(
            "NuPatch {n} {order} [{}] 0 {end} 2 2 [0 0 1 1] 0 1 \"P\" [{}]",
            nums(&knots),
            nums(&p)
        ));
        assert!(b.errors().is_empty(), "{:?}", b.errors());
        assert_eq!(
            b.surfaces[0].len(),
            n - order + 1,
            "order {order}: one piece per span"
        );
        for s in &b.surfaces[0] {
            let g = s.dice(6, 2);
            for k in 0..6 {
                let u = g.u[k];
                assert!(u >= -1e-6 && u <= end + 1e-6);
                let mut want = Vec3::ZERO;
                for (i, x) in xs.iter().enumerate() {
                    want += cox(&knots, i, order, u) * Vec3::from(*x);
                }
                assert!(
                    close(g.p[k], want, 1e-4),
                    "order {order} u {u}: {} vs {want}",
                    g.p[k]
                );
            }
        }
    }
}

#[test]
fn bad_nurbs_ranges_are_clear_errors() {
    let b = build("NuPatch 2 2 [0 0 1 1] 0 3 2 2 [0 0 1 1] 0 1 \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]");
    let e = b.errors();
    assert_eq!(e.len(), 1, "{e:?}");
    assert!(
        e[0].starts_with("geom::invalid") && e[0].contains("min/max"),
        "{e:?}"
    );
    assert!(b.surfaces[0].is_empty());
}

#[test]
fn trimmed_nurbs_has_a_hole() {
    // Unit square plane; a square trim loop [0.25, 0.75]² of four linear curves, sense
    // "outside": the loop's inside is cut away.
    let loop_u = "0.25 0.75 0.75 0.75 0.75 0.25 0.25 0.25";
    let loop_v = "0.25 0.25 0.25 0.75 0.75 0.75 0.75 0.25";
    let body = format!(
        "Attribute \"trimcurve\" \"sense\" \"outside\"\n\
         TrimCurve [4] [2 2 2 2] [0 0 1 1 0 0 1 1 0 0 1 1 0 0 1 1] [0 0 0 0] [1 1 1 1] [2 2 2 2] [{loop_u}] [{loop_v}] [1 1 1 1 1 1 1 1]\n\
         NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]"
    );
    let b = build(&body);
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let s = &b.surfaces[0][0];
    let g = s.dice(9, 9);
    for k in 0..g.len() {
        let (u, v) = (g.u[k], g.v[k]);
        let hole = u > 0.26 && u < 0.74 && v > 0.26 && v < 0.74;
        let kept = u < 0.24 || u > 0.76 || v < 0.24 || v > 0.76;
        if hole {
            assert_eq!(g.os[k], Vec3::ZERO, "({u},{v}) should be trimmed");
        }
        if kept {
            assert_eq!(g.os[k], Vec3::ONE, "({u},{v}) should be kept");
        }
    }
    // Splitting down, pieces wholly in the hole vanish (empty bound).
    let mut all: Vec<Box<dyn Surface>> = s.split();
    for _ in 0..5 {
        all = all.iter().flat_map(|p| p.split()).collect();
    }
    let empty = all.iter().filter(|p| p.bound().is_empty()).count();
    assert_eq!(all.len(), 64);
    assert_eq!(empty, 4, "the 2×2 pieces strictly inside the hole are cut");
}

#[test]
fn default_trim_sense_keeps_only_the_inside() {
    let body = "TrimCurve [4] [2 2 2 2] [0 0 1 1 0 0 1 1 0 0 1 1 0 0 1 1] [0 0 0 0] [1 1 1 1] [2 2 2 2] [0.25 0.75 0.75 0.75 0.75 0.25 0.25 0.25] [0.25 0.25 0.25 0.75 0.75 0.75 0.75 0.25] [1 1 1 1 1 1 1 1]\n\
         NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]";
    let b = build(body);
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let g = b.surfaces[0][0].dice(5, 5);
    assert_eq!(g.os[12], Vec3::ONE); // (0.5, 0.5)
    assert_eq!(g.os[0], Vec3::ZERO); // (0, 0)
}

/// Exporters write the parameter domain's boundary as a trim loop around surfaces they do not
/// trim, with knot ranges of their own (Aqsis's Bug1471457: [0 0 6.12 6.12] and
/// [-6.12 -6.12 0 0]); the whole surface is kept.
#[test]
fn a_loop_around_the_whole_domain_keeps_the_surface() {
    let body = "TrimCurve [4] [2 2 2 2] [0 0 1 1 0 0 6.12293 6.12293 0 0 1 1 -6.12293 -6.12293 0 0] [0 0 0 -6.12293] [1 6.12293 1 0] [2 2 2 2] [0 1 1 1 1 0 0 0] [0 0 0 1 1 1 1 0] [1 1 1 1 1 1 1 1]\n\
         NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]";
    let b = build(body);
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let s = &b.surfaces[0][0];
    assert!(s.trimmed(&s.dice(9, 9)).is_none(), "no point is cut");
    let g = s.dice(9, 9);
    for k in 0..g.len() {
        let (u, v) = (g.u[k], g.v[k]);
        if u > 0.01 && u < 0.99 && v > 0.01 && v < 0.99 {
            assert_eq!(g.os[k], Vec3::ONE, "({u},{v}) should be kept");
        }
    }
}

#[test]
fn teapot_is_closed_and_its_poles_have_normals() {
    let b = build("Geometry \"teapot\"");
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let s = &b.surfaces[0];
    assert_eq!(s.len(), 32);
    let grids: Vec<Grid> = s.iter().map(|s| s.dice(9, 9)).collect();
    for (pi, g) in grids.iter().enumerate() {
        for k in 0..g.len() {
            assert!(
                (g.n[k].length() - 1.0).abs() < 1e-3,
                "patch {pi} point {k}: N {}",
                g.n[k]
            );
        }
    }
    // Lid top (patches 21–24) and bottom (29–32) poles: along ±z.
    for p in 20..24 {
        assert!(grids[p].n[0].z > 0.99, "lid pole normal {}", grids[p].n[0]);
    }
    for p in 28..32 {
        assert!(
            grids[p].n[0].z < -0.99,
            "bottom pole normal {}",
            grids[p].n[0]
        );
    }
    // Rim (patch 1, v = 1) meets body (patch 5, v = 0) point for point: no cracks.
    for i in 0..9 {
        assert!(close(grids[0].p[72 + i], grids[4].p[i], 1e-5));
        assert!(close(grids[0].n[72 + i], grids[4].n[i], 1e-3));
    }
    // Body normals point outward.
    let g = &grids[4];
    assert!(g.ng[40].dot(Vec3::new(g.p[40].x, g.p[40].y, 0.0)) > 0.0);
    assert_eq!(arbor::geom::teapot_patches().len(), 32);
    let _ = &b.scene;
}

#[test]
fn height_field_and_primvar_classes() {
    // Pz bilinear mesh 3 × 2: x, y are the mesh parameters.
    let b = build(
        "PatchMesh \"bilinear\" 3 \"nonperiodic\" 2 \"nonperiodic\" \"Pz\" [0 1 2 3 4 5] \"uniform color Cs\" [1 0 0 0 1 0]",
    );
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let s = &b.surfaces[0];
    assert_eq!(s.len(), 2);
    let g = s[1].dice(3, 3);
    for k in 0..g.len() {
        let p = g.p[k];
        assert!((p.x - g.u[k]).abs() < 1e-6 && (p.y - g.v[k]).abs() < 1e-6);
        // z interpolates 0 1 2 / 3 4 5 bilinearly in (x·2, y).
        let want = 2.0 * p.x + 3.0 * p.y;
        assert!((p.z - want).abs() < 1e-5);
        assert_eq!(
            g.cs[k],
            Vec3::new(0.0, 1.0, 0.0),
            "uniform Cs of sub-patch 1"
        );
    }
    // A vertex float equal to x goes through the basis like P does.
    let pts = points16();
    let xs: Vec<f32> = pts.chunks(3).map(|c| c[0]).collect();
    let b = build(&format!(
        "Basis \"b-spline\" 1 \"b-spline\" 1\nPatch \"bicubic\" \"P\" [{}] \"vertex float foo\" [{}] \"varying float bar\" [0 1 2 3]",
        nums(&pts),
        nums(&xs)
    ));
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let g = b.surfaces[0][0].dice(4, 4);
    let foo = g.primvar("foo").expect("foo");
    let bar = g.primvar("bar").expect("bar");
    for k in 0..g.len() {
        assert!((foo.floats[k] - g.p[k].x).abs() < 1e-4);
        let want = g.u[k] + 2.0 * g.v[k];
        assert!((bar.floats[k] - want).abs() < 1e-5, "varying bilinear");
    }
}
