//! Trim regions of NuPatch surfaces (RISpec §5.2 `TrimCurve`, attribute "trimcurve" "sense").
//!
//! Input: [`TrimCurves`] (rational B-spline loops in the surface's (u, v) parameter space).
//! Output: a [`Trim`] that answers "is this parameter point rendered?" and classifies parameter
//! rectangles (wholly kept, wholly cut, or mixed) so split pieces that are cut entirely vanish.
//! Invariants: each loop is flattened into a closed polyline (its curves joined head to tail);
//! "inside" is the odd-crossing rule over all loops. Sense "inside" (the default) keeps the
//! inside of the loops and cuts away the rest, "outside" cuts the inside away (a hole). RISpec
//! says trim curves exclude areas from the surface and defines their inside; Aqsis keeps the
//! inside, and exporters write the domain's boundary as a loop around untrimmed surfaces
//! (cutting the inside away left such a NURBS sphere invisible).

use glam::Vec2;

use super::spline::eval_curve2;
use crate::scene::TrimCurves;

/// Segments per curve span and order: enough that the chord error is far below a
/// micropolygon for ordinary trim loops.
const SAMPLES_PER_SPAN: usize = 24;

#[derive(Debug, Clone)]
pub(crate) struct Trim {
    /// Closed polylines (last point joins the first).
    loops: Vec<Vec<Vec2>>,
    cut_inside: bool,
}

impl Trim {
    /// Flattens the trim loops; `None` when no loop has any points.
    pub fn new(tc: &TrimCurves) -> Option<Trim> {
        let mut loops = Vec::new();
        let (mut curve, mut ko, mut po) = (0usize, 0usize, 0usize);
        for &nc in &tc.ncurves {
            let mut poly = Vec::new();
            for _ in 0..nc {
                let (order, n) = (tc.order[curve] as usize, tc.n[curve] as usize);
                let knots = &tc.knot[ko..ko + order + n];
                let (u, v, w) = (&tc.u[po..po + n], &tc.v[po..po + n], &tc.w[po..po + n]);
                let (lo, hi) = (
                    tc.min[curve].max(knots[order - 1]),
                    tc.max[curve].min(knots[n]),
                );
                if lo < hi && w.iter().all(|w| w.is_finite() && *w != 0.0) {
                    let spans = (n - order + 1).max(1);
                    let m = spans * SAMPLES_PER_SPAN * order.max(2) / 2;
                    for s in 0..=m {
                        let x = lo + (hi - lo) * s as f32 / m as f32;
                        let p = eval_curve2(knots, order, u, v, w, x);
                        poly.push(Vec2::new(p[0], p[1]));
                    }
                }
                curve += 1;
                ko += order + n;
                po += n;
            }
            if poly.len() >= 3 {
                loops.push(poly);
            }
        }
        (!loops.is_empty()).then_some(Trim {
            loops,
            cut_inside: tc.sense_outside,
        })
    }

    /// Odd-crossing inside test over all loops. A point on a loop (within rounding) is
    /// inside: exporters trace the domain's own boundary, and its edge points must not be cut
    /// (a seam of transparent micropolygons down a NURBS sphere).
    fn inside(&self, p: Vec2) -> bool {
        const ON_LOOP: f32 = 1e-5;
        let mut odd = false;
        for l in &self.loops {
            let mut a = l[l.len() - 1];
            for &b in l {
                let ab = b - a;
                let t =
                    ((p - a).dot(ab) / ab.length_squared().max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
                if (a + t * ab - p).length_squared() <= ON_LOOP * ON_LOOP {
                    return true;
                }
                if (a.y > p.y) != (b.y > p.y) {
                    let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
                    if p.x < x {
                        odd = !odd;
                    }
                }
                a = b;
            }
        }
        odd
    }

    /// True when the surface point at parameters `p` is rendered.
    pub fn keeps(&self, p: Vec2) -> bool {
        self.inside(p) != self.cut_inside
    }

    /// Whether every point of the rectangle [lo, hi] is cut away: no loop edge meets the
    /// rectangle and its centre is cut.
    pub fn cuts_all(&self, lo: Vec2, hi: Vec2) -> bool {
        for l in &self.loops {
            let mut a = l[l.len() - 1];
            for &b in l {
                if segment_meets_rect(a, b, lo, hi) {
                    return false;
                }
                a = b;
            }
        }
        !self.keeps(0.5 * (lo + hi))
    }
}

/// Conservative segment–rectangle overlap (Liang–Barsky clip).
fn segment_meets_rect(a: Vec2, b: Vec2, lo: Vec2, hi: Vec2) -> bool {
    let d = b - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for (p, q) in [
        (-d.x, a.x - lo.x),
        (d.x, hi.x - a.x),
        (-d.y, a.y - lo.y),
        (d.y, hi.y - a.y),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square loop [0.25, 0.75]² as four linear curves.
    pub(crate) fn square(sense_outside: bool) -> TrimCurves {
        let c = [
            (0.25, 0.25),
            (0.75, 0.25),
            (0.75, 0.75),
            (0.25, 0.75),
            (0.25, 0.25),
        ];
        let (mut u, mut v) = (Vec::new(), Vec::new());
        for k in 0..4 {
            u.extend([c[k].0, c[k + 1].0]);
            v.extend([c[k].1, c[k + 1].1]);
        }
        TrimCurves {
            ncurves: vec![4],
            order: vec![2; 4],
            knot: [0., 0., 1., 1.].repeat(4),
            min: vec![0.0; 4],
            max: vec![1.0; 4],
            n: vec![2; 4],
            u,
            v,
            w: vec![1.0; 8],
            sense_outside,
        }
    }

    #[test]
    fn outside_sense_cuts_a_hole() {
        let t = Trim::new(&square(true)).unwrap();
        assert!(!t.keeps(Vec2::new(0.5, 0.5)));
        assert!(t.keeps(Vec2::new(0.1, 0.5)));
        assert!(t.cuts_all(Vec2::new(0.4, 0.4), Vec2::new(0.6, 0.6)));
        assert!(!t.cuts_all(Vec2::new(0.1, 0.4), Vec2::new(0.6, 0.6)));
        assert!(!t.cuts_all(Vec2::new(0.0, 0.0), Vec2::new(0.2, 0.2)));
    }

    #[test]
    fn inside_sense_keeps_the_inside() {
        let t = Trim::new(&square(false)).unwrap();
        assert!(t.keeps(Vec2::new(0.5, 0.5)));
        assert!(!t.keeps(Vec2::new(0.9, 0.5)));
        assert!(t.cuts_all(Vec2::new(0.8, 0.8), Vec2::new(1.0, 1.0)));
    }
}
