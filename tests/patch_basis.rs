//! Basis matrices and spline conversions against the exact values in notes/patches.md §2, §4.5
//! and §7, and Bézier ↔ B-spline round trips.

use arbor::diag::{Diagnostics, SourceMap};
use arbor::geom::spline::{bezier_spans, refine, to_bezier};
use arbor::rib::parse_bytes;
use arbor::scene::{build_scenes, BuildContext, Geometry};

fn basis_of(name: &str, step: u32) -> ([f32; 16], u32) {
    let text = format!(
        "WorldBegin\nBasis \"{name}\" {step} \"{name}\" {step}\nPatch \"bicubic\" \"P\" [{}]\nWorldEnd\n",
        (0..48).map(|k| format!("{}", k % 7)).collect::<Vec<_>>().join(" ")
    );
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = parse_bytes("b.rib", text.as_bytes(), &sources, &diags);
    let scenes = build_scenes(reqs, &BuildContext::new(&sources, &diags));
    match &*scenes[0].primitives[0].geometry {
        Geometry::PatchMesh { u_basis, .. } => (u_basis.matrix, u_basis.step),
        g => panic!("unexpected geometry {g:?}"),
    }
}

fn assert_matrix(got: &[f32; 16], want: [[f64; 4]; 4], scale: f64) {
    for r in 0..4 {
        for c in 0..4 {
            let w = want[r][c] * scale;
            assert!(
                (got[r * 4 + c] as f64 - w).abs() < 1e-6,
                "[{r}][{c}] = {} want {w}",
                got[r * 4 + c]
            );
        }
    }
}

fn assert_conv(got: [[f32; 4]; 4], want: [[f64; 4]; 4], scale: f64) {
    let flat: [f32; 16] = std::array::from_fn(|k| got[k / 4][k % 4]);
    assert_matrix(&flat, want, scale);
}

#[test]
fn named_bases_match_the_notes_exactly() {
    let (m, _) = basis_of("bezier", 3);
    assert_matrix(
        &m,
        [
            [-1., 3., -3., 1.],
            [3., -6., 3., 0.],
            [-3., 3., 0., 0.],
            [1., 0., 0., 0.],
        ],
        1.0,
    );
    let (m, _) = basis_of("b-spline", 1);
    assert_matrix(
        &m,
        [
            [-1., 3., -3., 1.],
            [3., -6., 3., 0.],
            [-3., 0., 3., 0.],
            [1., 4., 1., 0.],
        ],
        1.0 / 6.0,
    );
    let (m, _) = basis_of("catmull-rom", 1);
    assert_matrix(
        &m,
        [
            [-1., 3., -3., 1.],
            [2., -5., 4., -1.],
            [-1., 0., 1., 0.],
            [0., 2., 0., 0.],
        ],
        0.5,
    );
    // RI order (P0, T0, P1, T1), not the book's (P0, P1, T0, T1): the Hermite trap.
    let (m, step) = basis_of("hermite", 2);
    assert_matrix(
        &m,
        [
            [2., 1., -2., 1.],
            [-3., -2., 3., -1.],
            [0., 1., 0., 0.],
            [1., 0., 0., 0.],
        ],
        1.0,
    );
    assert_eq!(step, 2);
    let (m, _) = basis_of("power", 4);
    assert_matrix(
        &m,
        [
            [1., 0., 0., 0.],
            [0., 1., 0., 0.],
            [0., 0., 1., 0.],
            [0., 0., 0., 1.],
        ],
        1.0,
    );
}

#[test]
fn conversions_to_bezier_match_the_notes_table() {
    assert_conv(
        to_bezier(&basis_of("b-spline", 1).0),
        [
            [1., 4., 1., 0.],
            [0., 4., 2., 0.],
            [0., 2., 4., 0.],
            [0., 1., 4., 1.],
        ],
        1.0 / 6.0,
    );
    assert_conv(
        to_bezier(&basis_of("catmull-rom", 1).0),
        [
            [0., 1., 0., 0.],
            [-1. / 6., 1., 1. / 6., 0.],
            [0., 1. / 6., 1., -1. / 6.],
            [0., 0., 1., 0.],
        ],
        1.0,
    );
    assert_conv(
        to_bezier(&basis_of("hermite", 2).0),
        [
            [1., 0., 0., 0.],
            [1., 1. / 3., 0., 0.],
            [0., 0., 1., -1. / 3.],
            [0., 0., 1., 0.],
        ],
        1.0,
    );
    assert_conv(
        to_bezier(&basis_of("power", 4).0),
        [
            [0., 0., 0., 1.],
            [0., 0., 1. / 3., 1.],
            [0., 1. / 3., 2. / 3., 1.],
            [1., 1., 1., 1.],
        ],
        1.0,
    );
}

#[test]
fn bezier_bspline_round_trip() {
    // Notes §7: Bézier → B-spline is [[6,−7,2,0],[0,2,−1,0],[0,−1,2,0],[0,2,−7,6]].
    let to_bs = [
        [6., -7., 2., 0.],
        [0., 2., -1., 0.],
        [0., -1., 2., 0.],
        [0., 2., -7., 6.],
    ];
    let a = to_bezier(&basis_of("b-spline", 1).0);
    for r in 0..4 {
        for c in 0..4 {
            let s: f64 = (0..4).map(|k| to_bs[r][k] * a[k][c] as f64).sum();
            assert!(
                (s - (r == c) as i32 as f64).abs() < 1e-5,
                "[{r}][{c}] = {s}"
            );
        }
    }
    // Points: B-spline → Bézier → B-spline returns the original control points.
    let bs = [0.3f64, -1.2, 2.5, 0.7];
    let bez: Vec<f64> = (0..4)
        .map(|r| (0..4).map(|c| a[r][c] as f64 * bs[c]).sum())
        .collect();
    for r in 0..4 {
        let back: f64 = (0..4).map(|c| to_bs[r][c] * bez[c]).sum();
        assert!((back - bs[r]).abs() < 1e-5);
    }
}

#[test]
fn knot_insertion_extracts_every_uniform_segment() {
    // A uniform cubic B-spline over 6 points has 3 segments; each extracted Bézier piece must
    // equal the matrix conversion of its 4 points.
    let pts = [0.0f32, 1.0, -0.5, 2.0, 1.5, -1.0];
    let knots: Vec<f32> = (0..10).map(|k| k as f32).collect();
    let (_, spans) = bezier_spans(&knots, 3, 3.0, 6.0);
    assert_eq!(spans.len(), 3);
    let net = refine(&knots, 3, &pts, 0, 1, 6, 1);
    let a = to_bezier(&basis_of("b-spline", 1).0);
    for (s, span) in spans.iter().enumerate() {
        assert_eq!(span.seg, s);
        for r in 0..4 {
            let want: f32 = (0..4).map(|c| a[r][c] * pts[s + c]).sum();
            let got = net[span.first + r];
            assert!(
                (got - want).abs() < 1e-5,
                "segment {s} point {r}: {got} vs {want}"
            );
        }
    }
}
