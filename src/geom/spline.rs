//! Spline mathematics for patches: basis conversion to Bézier, Bernstein polynomials,
//! de Casteljau splitting, knot validation and Bézier extraction of B-splines (Boehm).
//!
//! Input: RIB basis matrices (row-major, row-vector convention `Q(u) = [u³ u² u 1]·M·G`,
//! notes/patches.md §1–2), knot vectors and control points as flat `f32` rows of `dim` numbers.
//! Output: Bézier control points (any degree) that reproduce the same curve or surface.
//! Invariants: conversions are exact up to rounding (`A = M_bezier⁻¹ · M_X`, notes §7); knot
//! insertion uses the order-k form `aᵢ = (t' − tᵢ)/(t_{i+k−1} − tᵢ)` (notes §4.4 erratum); rational
//! data is handled by the caller passing homogeneous (w-premultiplied) rows.

/// `M_bezier⁻¹` (notes §7 "power" row): maps power coefficients to Bézier points.
const BEZIER_INV: [[f64; 4]; 4] = [
    [0.0, 0.0, 0.0, 1.0],
    [0.0, 0.0, 1.0 / 3.0, 1.0],
    [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0],
    [1.0, 1.0, 1.0, 1.0],
];

/// The matrix `A = M_bezier⁻¹ · M` taking the 4 control points of a segment in basis `m`
/// (RIB row-major) to the 4 Bézier control points of the same cubic: `b_r = Σ_c A[r][c]·p_c`.
pub fn to_bezier(m: &[f32; 16]) -> [[f32; 4]; 4] {
    let mut a = [[0.0f32; 4]; 4];
    for (r, row) in a.iter_mut().enumerate() {
        for (c, out) in row.iter_mut().enumerate() {
            let mut s = 0.0f64;
            for (k, binv) in BEZIER_INV[r].iter().enumerate() {
                s += binv * m[k * 4 + c] as f64;
            }
            *out = s as f32;
        }
    }
    a
}

/// Bernstein polynomials of degree `n` at `t` and their derivatives (`b`, `db` of length n+1).
pub fn bernstein(n: usize, t: f32, b: &mut [f32], db: &mut [f32]) {
    // Degree n−1 values first (de Casteljau style triangle), derivative from them.
    b[0] = 1.0;
    let s = 1.0 - t;
    for d in 1..=n {
        if d == n {
            // b currently holds degree n−1: derivative n·(B_{i−1,n−1} − B_{i,n−1}).
            for i in 0..=n {
                let lo = if i > 0 { b[i - 1] } else { 0.0 };
                let hi = if i < n { b[i] } else { 0.0 };
                db[i] = n as f32 * (lo - hi);
            }
        }
        let mut prev = 0.0;
        for i in 0..d {
            let cur = b[i];
            b[i] = prev + s * cur;
            prev = t * cur;
        }
        b[d] = prev;
    }
    if n == 0 {
        db[0] = 0.0;
    }
}

/// Splits the Bézier curve given by `n` rows of `dim` numbers (row `i` at `stride·i`) at `t`:
/// on return `left` holds [0,t] and `right` [t,1] (each `n·dim`, packed).
pub fn split_curve(src: &[f32], n: usize, dim: usize, t: f32, left: &mut [f32], right: &mut [f32]) {
    let mut w: Vec<f32> = src[..n * dim].to_vec();
    for r in 0..n {
        left[r * dim..(r + 1) * dim].copy_from_slice(&w[..dim]);
        let last = n - 1 - r;
        right[last * dim..(last + 1) * dim].copy_from_slice(&w[last * dim..(last + 1) * dim]);
        for i in 0..last {
            for c in 0..dim {
                w[i * dim + c] = (1.0 - t) * w[i * dim + c] + t * w[(i + 1) * dim + c];
            }
        }
    }
}

/// Why a knot vector is rejected (`None` when it is usable).
pub fn check_knots(knots: &[f32], n: usize, order: usize, min: f32, max: f32) -> Option<String> {
    if order < 2 {
        return Some(format!(
            "order {order}: a NuPatch needs order 2 or more in each direction"
        ));
    }
    if n < order || knots.len() != n + order {
        return Some(format!(
            "{} knots for {n} control points of order {order}: need n + order = {}",
            knots.len(),
            n + order
        ));
    }
    if knots.iter().any(|k| !k.is_finite()) {
        return Some("a knot is not finite".into());
    }
    if knots.windows(2).any(|w| w[1] < w[0]) {
        return Some("the knot vector decreases".into());
    }
    let (lo, hi) = (knots[order - 1], knots[n]);
    if lo >= hi {
        return Some(format!(
            "the parametric range [{lo}, {hi}] (knots order−1 and n) is empty"
        ));
    }
    if !(min.is_finite() && max.is_finite()) || min >= max || min < lo || max > hi {
        return Some(format!(
            "min/max [{min}, {max}] must be an increasing range inside [{lo}, {hi}]"
        ));
    }
    None
}

/// Inserts knot `x` once into a B-spline of degree `p` (Boehm). `pts` has `knots.len() − p − 1`
/// rows of `dim` numbers.
fn insert_knot(knots: &mut Vec<f32>, pts: &mut Vec<f32>, p: usize, dim: usize, x: f32) {
    let n = knots.len() - p - 1;
    // j: last index with t_j < x (exists: x is above the first knot).
    let j = knots.iter().rposition(|&t| t < x).unwrap_or(0);
    let mut out = Vec::with_capacity((n + 1) * dim);
    for i in 0..=n {
        let a = if i + p <= j {
            1.0
        } else if i > j {
            0.0
        } else {
            let den = knots[i + p] - knots[i];
            if den > 0.0 {
                (x - knots[i]) / den
            } else {
                1.0
            }
        };
        for c in 0..dim {
            let cur = if i < n { pts[i * dim + c] } else { 0.0 };
            let prev = if i > 0 { pts[(i - 1) * dim + c] } else { cur };
            let v = if a >= 1.0 {
                cur
            } else if a <= 0.0 {
                prev
            } else {
                (1.0 - a) * prev + a * cur
            };
            out.push(v);
        }
    }
    knots.insert(j + 1, x);
    *pts = out;
}

/// A B-spline span as a Bézier piece: parameters [a, b], the original segment index (RISpec's
/// count: knot interval `order−1+seg`) and the index of its first control row after refinement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    pub a: f32,
    pub b: f32,
    pub seg: usize,
    pub first: usize,
}

/// Refines a B-spline of degree `p` until every knot in the parametric range has multiplicity
/// ≥ p, so each nonempty span is a Bézier curve. Returns the refined knots and the spans
/// (those intersecting [min, max]). Only the knots are computed; apply the same insertions to
/// control rows with [`refine`].
pub fn bezier_spans(knots: &[f32], p: usize, min: f32, max: f32) -> (Vec<f32>, Vec<Span>) {
    let n = knots.len() - p - 1;
    let mut k = knots.to_vec();
    for x in insertions(knots, p) {
        let j = k.iter().rposition(|&t| t <= x).unwrap_or(0);
        k.insert(j + 1, x);
    }
    let mut spans = Vec::new();
    for j in p..n {
        let (a, b) = (knots[j], knots[j + 1]);
        if a < b && b > min && a < max {
            let first = k.iter().rposition(|&t| t <= a).unwrap_or(0) - p;
            spans.push(Span {
                a,
                b,
                seg: j - p,
                first,
            });
        }
    }
    (k, spans)
}

/// The knot values (in increasing order, repeated) to insert for Bézier extraction.
fn insertions(knots: &[f32], p: usize) -> Vec<f32> {
    let n = knots.len() - p - 1;
    let (lo, hi) = (knots[p], knots[n]);
    let mut out = Vec::new();
    let mut i = 0;
    while i < knots.len() {
        let x = knots[i];
        let m = knots[i..].iter().take_while(|&&t| t == x).count();
        if x >= lo && x <= hi && m < p {
            out.extend(std::iter::repeat(x).take(p - m));
        }
        i += m;
    }
    out
}

/// Applies Bézier-extraction knot insertion to `count` control rows of `dim` numbers taken
/// from `src` at `offset + r·stride` (r = 0..count). Returns the refined rows, packed.
pub fn refine(
    knots: &[f32],
    p: usize,
    src: &[f32],
    offset: usize,
    stride: usize,
    count: usize,
    dim: usize,
) -> Vec<f32> {
    let mut pts = Vec::with_capacity(count * dim);
    for r in 0..count {
        let o = offset + r * stride;
        pts.extend_from_slice(&src[o..o + dim]);
    }
    let mut k = knots.to_vec();
    for x in insertions(knots, p) {
        insert_knot(&mut k, &mut pts, p, dim, x);
    }
    pts
}

/// Evaluates a rational B-spline curve in the plane (trim curves): homogeneous control points
/// (u, v, w), the point being (u/w, v/w) (RISpec: a curve "in homogeneous parameter space"),
/// by de Boor's algorithm. `x` is clamped into the span range.
pub fn eval_curve2(
    knots: &[f32],
    order: usize,
    u: &[f32],
    v: &[f32],
    w: &[f32],
    x: f32,
) -> [f32; 2] {
    let p = order - 1;
    let n = u.len();
    let x = x.clamp(knots[p], knots[n]);
    // Span: last j in [p, n−1] with t_j ≤ x (the last nonempty span is closed at the end).
    let mut j = p;
    for jj in p..n {
        if knots[jj] <= x && knots[jj] < knots[jj + 1] {
            j = jj;
        }
    }
    let mut d: Vec<[f32; 3]> = (0..=p)
        .map(|r| {
            let i = j - p + r;
            [u[i], v[i], w[i]]
        })
        .collect();
    for r in 1..=p {
        for q in (r..=p).rev() {
            let i = j - p + q;
            let den = knots[i + p + 1 - r] - knots[i];
            let a = if den > 0.0 { (x - knots[i]) / den } else { 0.0 };
            for c in 0..3 {
                d[q][c] = (1.0 - a) * d[q - 1][c] + a * d[q][c];
            }
        }
    }
    let h = d[p];
    let w = if h[2] != 0.0 { h[2] } else { 1.0 };
    [h[0] / w, h[1] / w]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Basis;

    fn eval_bezier(pts: &[f32], t: f32) -> f32 {
        let n = pts.len() - 1;
        let (mut b, mut db) = (vec![0.0; n + 1], vec![0.0; n + 1]);
        bernstein(n, t, &mut b, &mut db);
        b.iter().zip(pts).map(|(b, p)| b * p).sum()
    }

    #[test]
    fn bernstein_cubic_values_and_derivatives() {
        let (mut b, mut db) = ([0.0; 4], [0.0; 4]);
        bernstein(3, 0.25, &mut b, &mut db);
        let s = 0.75f32;
        let want = [s * s * s, 3.0 * 0.25 * s * s, 3.0 * 0.0625 * s, 0.015625];
        for i in 0..4 {
            assert!((b[i] - want[i]).abs() < 1e-6);
        }
        // d/dt (1−t)³ = −3(1−t)²
        assert!((db[0] + 3.0 * s * s).abs() < 1e-6);
        assert!((db[3] - 3.0 * 0.0625).abs() < 1e-6);
        assert!(db.iter().sum::<f32>().abs() < 1e-6);
    }

    #[test]
    fn bezier_basis_converts_to_identity() {
        let a = to_bezier(&Basis::BEZIER.matrix);
        for r in 0..4 {
            for c in 0..4 {
                assert!((a[r][c] - (r == c) as i32 as f32).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn split_curve_halves_agree_with_the_whole() {
        let p = [0.0, 2.0, -1.0, 3.0];
        let (mut l, mut r) = ([0.0; 4], [0.0; 4]);
        split_curve(&p, 4, 1, 0.3, &mut l, &mut r);
        for k in 0..=10 {
            let t = k as f32 / 10.0;
            assert!((eval_bezier(&l, t) - eval_bezier(&p, 0.3 * t)).abs() < 1e-5);
            assert!((eval_bezier(&r, t) - eval_bezier(&p, 0.3 + 0.7 * t)).abs() < 1e-5);
        }
    }

    #[test]
    fn extraction_of_a_uniform_bspline_matches_the_basis_matrix() {
        // One uniform cubic segment (knots 0..7, 4 points) → notes §4.5 matrix (1/6)[[1,4,1,0],…].
        let knots: Vec<f32> = (0..8).map(|k| k as f32).collect();
        let (k, spans) = bezier_spans(&knots, 3, 3.0, 4.0);
        assert_eq!(spans.len(), 1);
        let pts = [1.0, 0.0, 0.0, 0.0];
        let out = refine(&knots, 3, &pts, 0, 1, 4, 1);
        let s = spans[0];
        let b: Vec<f32> = out[s.first..s.first + 4].to_vec();
        let want = [1.0 / 6.0, 0.0, 0.0, 0.0];
        for i in 0..4 {
            assert!((b[i] - want[i]).abs() < 1e-6, "{b:?}");
        }
        assert_eq!(out.len(), k.len() - 4);
    }

    #[test]
    fn knot_checks_name_the_problem() {
        assert!(check_knots(&[0., 0., 1., 1.], 2, 2, 0.0, 1.0).is_none());
        assert!(check_knots(&[0., 0., 1.], 2, 2, 0.0, 1.0).is_some());
        assert!(check_knots(&[0., 1., 0., 1.], 2, 2, 0.0, 1.0).is_some());
        assert!(check_knots(&[0., 0., 1., 1.], 2, 2, 0.0, 2.0).is_some());
        assert!(check_knots(&[0., 0., 1., 1.], 2, 1, 0.0, 1.0).is_some());
    }

    #[test]
    fn quarter_circle_trim_curve() {
        let r = std::f32::consts::FRAC_1_SQRT_2;
        let knots = [0., 0., 0., 1., 1., 1.];
        for k in 0..=8 {
            let p = eval_curve2(
                &knots,
                3,
                // Homogeneous (u, v, w): (1,0,1), (r,r,r), (0,1,1).
                &[1., r, 0.],
                &[0., r, 1.],
                &[1., r, 1.],
                k as f32 / 8.0,
            );
            assert!((p[0].hypot(p[1]) - 1.0).abs() < 1e-5);
        }
    }
}
