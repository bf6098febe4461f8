//! Quantised child boxes for the BVH's nodes (their slab data one cache line).
//!
//! Input: a node's box (the union of its children's) and a child's exact box. Output: per
//! axis a quantum `2^e` (stored as the biased exponent `e + 127`, 1…254) and for the child
//! the 8-bit steps `qlo ≤ qhi` whose planes `origin + q · 2^e`, computed in `f32` exactly as
//! the traversal computes them ([`plane`]), enclose the exact box.
//! Invariants: conservative: `plane(o, e, qlo) ≤ lo` and `plane(o, e, qhi) ≥ hi` for every
//! finite child inside the node's box, whatever the magnitudes (flat, tiny, huge or far from
//! the origin): the steps are chosen by evaluating the very expression the traversal
//! evaluates, not by reasoning about its rounding. `q · 2^e` is exact (q < 2⁸, a power-of-two
//! quantum), so a plane is one rounding of one addition, monotone in `q`; the traversal's slab
//! test on these planes therefore never rejects a box the test on the exact box accepts.
//!
//! Why: a node of eight `f32` boxes is 192 bytes of planes, three cache lines, and the BVH
//! walk of a million-quad scene waits on memory; with 8-bit steps they fit one 64-byte line.

/// The largest step.
pub const QMAX: u8 = 255;

/// The quantum `2^(e − 127)` for a biased exponent `e` (1…254: normal numbers).
#[inline(always)]
pub fn quantum(e: u8) -> f32 {
    f32::from_bits(u32::from(e.clamp(1, 254)) << 23)
}

/// The plane of step `q`: `origin + q · 2^e`, one rounding (the product is exact). The
/// traversal computes the same operations on four lanes (`cvtdq2ps`, `mulps`, `addps`).
#[inline(always)]
pub fn plane(origin: f32, e: u8, q: u8) -> f32 {
    origin + f32::from(q) * quantum(e)
}

/// The exponent for an axis of a node spanning `origin…max`: the smallest quantum whose top
/// step reaches `max` (so every child's high side can be rounded up inside the range); an
/// axis of no extent gets the smallest quantum. Never fails: a non-finite extent gets the
/// largest quantum (whose top plane overflows to infinity, still conservative).
pub fn exponent(origin: f32, max: f32) -> u8 {
    let ext = max - origin;
    if !(ext > 0.0) {
        return 1;
    }
    // A first guess from the bits of ext / 255 rounded up, then corrected by evaluating the
    // top plane itself (the guess can be one off either way after rounding).
    let guess = ((ext / f32::from(QMAX)).to_bits() >> 23) as i32 + 1;
    let mut e = guess.clamp(1, 254) as u8;
    while e < 254 && !(plane(origin, e, QMAX) >= max) {
        e += 1;
    }
    while e > 1 && plane(origin, e - 1, QMAX) >= max {
        e -= 1;
    }
    e
}

/// The low step for an exact low side `lo`: the largest step whose plane is `≤ lo` (0 when
/// even step 0, the origin, is above: a side outside the node or not a number).
pub fn step_down(origin: f32, e: u8, lo: f32) -> u8 {
    let s = quantum(e);
    // `as u8` saturates (and maps NaN to 0); the loops make the guess exact.
    let mut q = ((lo - origin) / s).floor().clamp(0.0, f32::from(QMAX)) as u8;
    while q > 0 && !(plane(origin, e, q) <= lo) {
        q -= 1;
    }
    while q < QMAX && plane(origin, e, q + 1) <= lo {
        q += 1;
    }
    q
}

/// The high step for an exact high side `hi`: the smallest step whose plane is `≥ hi`
/// (`QMAX` when none is: a side outside the node or not a number).
pub fn step_up(origin: f32, e: u8, hi: f32) -> u8 {
    let s = quantum(e);
    let mut q = ((hi - origin) / s).ceil().clamp(0.0, f32::from(QMAX)) as u8;
    while q < QMAX && !(plane(origin, e, q) >= hi) {
        q += 1;
    }
    while q > 0 && plane(origin, e, q - 1) >= hi {
        q -= 1;
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quantises `child` inside `node` (per axis: node low, node high, child low, child high)
    /// and checks the planes enclose the child; returns the dequantised box.
    fn check(node: [(f32, f32); 3], child: [(f32, f32); 3]) -> [(f32, f32); 3] {
        std::array::from_fn(|a| {
            let (o, max) = node[a];
            let (lo, hi) = child[a];
            let e = exponent(o, max);
            assert!(plane(o, e, QMAX) >= max, "axis {a}: top plane below {max}");
            let (ql, qh) = (step_down(o, e, lo), step_up(o, e, hi));
            let (pl, ph) = (plane(o, e, ql), plane(o, e, qh));
            // (The steps themselves may cross where planes round to the same number: a
            // quantum below the origin's ulp. Only the planes matter.)
            assert!(pl <= ph, "axis {a}: planes {pl} > {ph} (steps {ql}, {qh})");
            assert!(pl <= lo, "axis {a}: {pl} above the low side {lo}");
            assert!(ph >= hi, "axis {a}: {ph} below the high side {hi}");
            (pl, ph)
        })
    }

    #[test]
    fn a_unit_box_quantises_to_exact_steps() {
        // Node 0…255 on x: the quantum is 1, so integer sides are exact and fractions round
        // outward by less than a step.
        let node = [(0.0, 255.0), (0.0, 1.0), (-4.0, 4.0)];
        assert_eq!(exponent(0.0, 255.0), 127);
        let b = check(node, [(3.0, 7.0), (0.25, 0.5), (-1.0, 1.0)]);
        assert_eq!(b[0], (3.0, 7.0));
        let b = check(node, [(3.5, 7.25), (0.0, 1.0), (-4.0, 4.0)]);
        assert_eq!(b[0], (3.0, 8.0));
        // y: 1/255 rounded up to 2^-7, so 0.25 and 0.5 are exact steps; the node's far side
        // is inside the top step.
        assert_eq!(exponent(0.0, 1.0), 127 - 7);
        assert_eq!(b[1].0, 0.0);
        assert!(b[1].1 >= 1.0 && b[1].1 < 1.0 + 1.0 / 128.0);
    }

    #[test]
    fn flat_and_point_boxes_stay_inside_their_planes() {
        let node = [(2.0, 2.0), (-1.0, 3.0), (5.0, 5.0)];
        let b = check(node, [(2.0, 2.0), (1.0, 1.0), (5.0, 5.0)]);
        // No extent: step 0 is the origin itself on both sides.
        assert_eq!(b[0], (2.0, 2.0));
        assert_eq!(b[2], (5.0, 5.0));
        assert!(b[1].0 <= 1.0 && b[1].1 >= 1.0 && b[1].1 - b[1].0 <= 4.0 / 255.0 * 2.0);
    }

    #[test]
    fn huge_tiny_and_far_boxes_are_conservative() {
        let cases: &[([(f32, f32); 3], [(f32, f32); 3])] = &[
            // Huge coordinates, up to the top of f32.
            (
                [(-3e38, 3e38), (-1e38, 1e30), (0.0, f32::MAX)],
                [(-1e37, 2e38), (-5e37, 0.0), (1.0, f32::MAX)],
            ),
            // Tiny extents near zero (down to subnormal sides).
            (
                [(-1e-38, 1e-38), (0.0, 1e-44), (1e-30, 2e-30)],
                [(-1e-39, 3e-39), (1e-45, 1e-44), (1.5e-30, 1.7e-30)],
            ),
            // Far from the origin with a small extent: the planes round to the ulp of the
            // origin, not of the extent.
            (
                [
                    (1e7, 1e7 + 3.0),
                    (-2e6, -2e6 + 0.5),
                    (16_777_216.0, 16_777_218.0),
                ],
                [
                    (1e7 + 1.0, 1e7 + 2.0),
                    (-2e6 + 0.25, -2e6 + 0.25),
                    (16_777_218.0, 16_777_218.0),
                ],
            ),
        ];
        for (node, child) in cases {
            check(*node, *child);
            check(*node, *node);
        }
    }

    #[test]
    fn random_children_are_enclosed_and_tight() {
        let mut h = 77u32;
        let mut rnd = || {
            h = crate::pattern::hash::hash_u32(h);
            h as f32 / u32::MAX as f32
        };
        for k in 0..20_000 {
            // Magnitudes from 1e-20 to 1e20, offsets from the origin likewise.
            let scale = 10f32.powi((k % 41) - 20);
            let offset = 10f32.powi((k / 41 % 41) - 20) * (rnd() - 0.5);
            let node: [(f32, f32); 3] = std::array::from_fn(|_| {
                let a = offset + rnd() * scale;
                (a, a + rnd() * scale)
            });
            let child: [(f32, f32); 3] = std::array::from_fn(|a| {
                let (o, m) = node[a];
                let x = o + (m - o) * rnd();
                let y = o + (m - o) * rnd();
                // Inside the node (rounding may put x past m: clamp).
                (x.min(y).clamp(o, m), x.max(y).clamp(o, m))
            });
            let b = check(node, child);
            // Tight: outward by at most one step plus the rounding of the planes.
            for a in 0..3 {
                let e = exponent(node[a].0, node[a].1);
                let slack = quantum(e) + 2.0 * node[a].0.abs().max(node[a].1.abs()) * f32::EPSILON;
                assert!(child[a].0 - b[a].0 <= slack, "case {k} axis {a}");
                assert!(b[a].1 - child[a].1 <= slack, "case {k} axis {a}");
            }
        }
    }

    #[test]
    fn not_a_number_never_panics() {
        let e = exponent(f32::NAN, 1.0);
        assert_eq!(e, 1);
        // An infinite extent: the largest finite top plane is still below it, so the top
        // step overflows to infinity.
        let e = exponent(0.0, f32::INFINITY);
        assert_eq!(plane(0.0, e, QMAX), f32::INFINITY);
        assert_eq!(step_down(0.0, e, f32::NAN), 0);
        assert_eq!(step_up(0.0, e, f32::NAN), QMAX);
    }
}
