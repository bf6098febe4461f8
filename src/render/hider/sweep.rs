//! The region a moving micropolygon sweeps over an interval of time, as a convex polygon.
//!
//! Input: the raster positions its corners take at the interval's ends and at the motion keys
//! between (each corner moves on straight segments between them), and how far every position
//! may stray from those (rounding pad, lens shift). Output: per horizontal band of the raster,
//! the least and greatest x the micropolygon can reach there.
//! Invariant: conservative. At any time of the interval each corner lies on a segment between
//! two of the points, so the micropolygon lies in their convex hull; the hull is grown by the
//! stray on each axis.
//!
//! Why: a micropolygon moving diagonally D pixels in a time slot has a bounding box of D × D
//! pixels but sweeps a band about D pixels long and its own size wide; testing the samples of
//! each pixel row only between the band's ends spares most of the box (a sphere shrinking
//! while it moves, Essential RenderMan's `deform.rib`, tested 240 samples a hit).

/// At most this many points (the ends and two keys between, four corners each); more and
/// the caller keeps the box.
pub const MAX_POINTS: usize = 16;

/// The convex hull of a moving micropolygon's positions, grown by `rx`, `ry`.
#[derive(Clone, Copy, Debug)]
pub struct Sweep {
    /// Hull vertices in order around it, `n` of them (1 or 2 when degenerate).
    hull: [[f32; 2]; MAX_POINTS],
    n: usize,
    rx: f32,
    ry: f32,
}

impl Sweep {
    /// The hull of `pts` grown by `rx` and `ry`; None when there are none, more than
    /// [`MAX_POINTS`], or one is not finite.
    pub fn new(pts: &[[f32; 2]], rx: f32, ry: f32) -> Option<Sweep> {
        if pts.is_empty()
            || pts.len() > MAX_POINTS
            || pts.iter().any(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return None;
        }
        // Sorted by x then y (insertion: a handful of points).
        let mut p = [[0f32; 2]; MAX_POINTS];
        let n = pts.len();
        for (i, &q) in pts.iter().enumerate() {
            let mut j = i;
            while j > 0 && (p[j - 1][0], p[j - 1][1]) > (q[0], q[1]) {
                p[j] = p[j - 1];
                j -= 1;
            }
            p[j] = q;
        }
        // Andrew's monotone chain. The turn is taken in f64 (products of f32 are exact
        // there), so a point is dropped only when it is within rounding of an edge, far
        // below the pad.
        let turn = |o: [f32; 2], a: [f32; 2], b: [f32; 2]| {
            let d = |u: f32, v: f32| u as f64 - v as f64;
            d(a[0], o[0]) * d(b[1], o[1]) - d(a[1], o[1]) * d(b[0], o[0])
        };
        let mut hull = [[0f32; 2]; MAX_POINTS + 1];
        let mut k = 0;
        for &q in &p[..n] {
            while k >= 2 && turn(hull[k - 2], hull[k - 1], q) <= 0.0 {
                k -= 1;
            }
            hull[k] = q;
            k += 1;
        }
        let lower = k + 1;
        for &q in p[..n].iter().rev().skip(1) {
            while k >= lower && turn(hull[k - 2], hull[k - 1], q) <= 0.0 {
                k -= 1;
            }
            hull[k] = q;
            k += 1;
        }
        // The chain ends where it began.
        let n = (k - 1).max(1);
        let mut out = [[0f32; 2]; MAX_POINTS];
        out[..n].copy_from_slice(&hull[..n]);
        Some(Sweep {
            hull: out,
            n,
            rx,
            ry,
        })
    }

    /// The least and greatest x the region reaches within `y0 ≤ y ≤ y1`, or None when it
    /// does not reach the band. Rounded outwards to f32.
    pub fn x_range(&self, y0: f32, y1: f32) -> Option<(f32, f32)> {
        let (c, d) = (y0 as f64 - self.ry as f64, y1 as f64 + self.ry as f64);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut take = |x: f64| {
            lo = lo.min(x);
            hi = hi.max(x);
        };
        let h = &self.hull[..self.n];
        for i in 0..h.len() {
            // Each edge clipped to the band (a one-point hull is its own edge). A convex
            // region's extremes in x within a band lie on its boundary.
            let (p, q) = (h[i], h[(i + 1) % h.len()]);
            let (p, q) = ([p[0] as f64, p[1] as f64], [q[0] as f64, q[1] as f64]);
            if (p[1] < c && q[1] < c) || (p[1] > d && q[1] > d) {
                continue;
            }
            let dy = q[1] - p[1];
            if dy == 0.0 {
                take(p[0]);
                take(q[0]);
                continue;
            }
            let (mut ta, mut tb) = ((c - p[1]) / dy, (d - p[1]) / dy);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            let (ta, tb) = (ta.max(0.0), tb.min(1.0));
            if ta <= tb {
                take(p[0] + (q[0] - p[0]) * ta);
                take(p[0] + (q[0] - p[0]) * tb);
            }
        }
        if lo > hi {
            return None;
        }
        let (lo, hi) = (lo - self.rx as f64, hi + self.rx as f64);
        // Outwards: the f32 nearest may lie inside.
        let down = |v: f64| {
            let f = v as f32;
            if (f as f64) > v {
                f.next_down()
            } else {
                f
            }
        };
        let up = |v: f64| {
            let f = v as f32;
            if (f as f64) < v {
                f.next_up()
            } else {
                f
            }
        };
        Some((down(lo), up(hi)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_diagonal_sweep_is_a_narrow_band_per_row() {
        // A unit square moving from (0,0) to (30,30).
        let sq = |o: f32| [[o, o], [o + 1.0, o], [o + 1.0, o + 1.0], [o, o + 1.0]];
        let pts: Vec<[f32; 2]> = sq(0.0).into_iter().chain(sq(30.0)).collect();
        let s = Sweep::new(&pts, 0.01, 0.01).unwrap();
        let (lo, hi) = s.x_range(15.0, 16.0).unwrap();
        assert!(lo <= 14.0 && lo > 13.9, "{lo}");
        assert!(hi >= 17.0 && hi < 17.1, "{hi}");
        assert!(s.x_range(32.0, 33.0).is_none());
        assert!(s.x_range(-2.0, -1.0).is_none());
        // The band's end rows reach the ends' squares.
        let (lo, hi) = s.x_range(0.0, 0.5).unwrap();
        assert!(lo <= 0.0 && hi >= 1.5);
    }

    #[test]
    fn every_point_between_the_ends_is_inside_its_rows_range() {
        // Pseudo-random quads moving between two keys: a corner at every time lies within
        // the x range of the band holding it.
        let mut seed = 12345u32;
        let mut rnd = || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1 << 24) as f32
        };
        for _ in 0..500 {
            let a: Vec<[f32; 2]> = (0..4).map(|_| [rnd() * 50.0, rnd() * 50.0]).collect();
            let b: Vec<[f32; 2]> = (0..4).map(|_| [rnd() * 50.0, rnd() * 50.0]).collect();
            let pts: Vec<[f32; 2]> = a.iter().chain(&b).copied().collect();
            let s = Sweep::new(&pts, 0.01, 0.01).unwrap();
            for _ in 0..20 {
                let f = rnd();
                let (w0, w1) = (rnd(), rnd());
                // A point of the quad at time f: a mix of two corners there.
                let at = |i: usize| {
                    [
                        a[i][0] + (b[i][0] - a[i][0]) * f,
                        a[i][1] + (b[i][1] - a[i][1]) * f,
                    ]
                };
                let (p, q) = (at(0), at(2));
                let w = w0 / (w0 + w1 + 1e-6);
                let x = p[0] + (q[0] - p[0]) * w;
                let y = p[1] + (q[1] - p[1]) * w;
                let row = y.floor();
                let (lo, hi) = s.x_range(row, row + 1.0).unwrap();
                assert!(lo <= x && x <= hi, "{x} not in {lo}..{hi}");
            }
        }
    }

    #[test]
    fn degenerate_and_bad_inputs() {
        let s = Sweep::new(&[[3.0, 4.0]; 4], 0.5, 0.5).unwrap();
        assert_eq!(s.x_range(4.2, 4.3), Some((2.5, 3.5)));
        assert!(s.x_range(5.0, 6.0).is_none());
        let line = Sweep::new(&[[0.0, 0.0], [10.0, 0.0]], 0.0, 0.0).unwrap();
        assert_eq!(line.x_range(-1.0, 1.0), Some((0.0, 10.0)));
        assert!(Sweep::new(&[[f32::NAN, 0.0]], 0.0, 0.0).is_none());
        assert!(Sweep::new(&[], 0.0, 0.0).is_none());
        assert!(Sweep::new(&[[0.0, 0.0]; MAX_POINTS + 1], 0.0, 0.0).is_none());
    }
}
