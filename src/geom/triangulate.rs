//! Ear-clipping triangulation of a planar polygon with holes, in 2D.
//!
//! Input: loops of 2D points (the first is the outline, the others holes), each point carrying
//! the caller's id. Output: triangles as triples of ids.
//! Invariants: holes are first bridged into the outline (each hole's rightmost vertex joined to
//! a visible outline vertex, after Eberly, "Triangulation by Ear Clipping"), then ears are
//! clipped from the single resulting loop; the triangles cover the outline minus the holes, so
//! their areas sum to the polygon's area. Degenerate input never loops forever: when no ear is
//! found the flattest vertex is dropped.

use glam::Vec2;

#[inline]
fn cross(o: Vec2, a: Vec2, b: Vec2) -> f32 {
    (a - o).perp_dot(b - o)
}

fn signed_area(pts: &[Vec2], idx: &[usize]) -> f32 {
    let n = idx.len();
    let mut a = 0.0;
    for i in 0..n {
        let (p, q) = (pts[idx[i]], pts[idx[(i + 1) % n]]);
        a += p.perp_dot(q);
    }
    0.5 * a
}

/// True when `p` is inside or on triangle (a, b, c) given counter-clockwise.
#[inline]
fn in_triangle(p: Vec2, a: Vec2, b: Vec2, c: Vec2) -> bool {
    cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0
}

/// Triangulates `loops` (indices into `pts`); returns triangles as indices into `pts`.
pub fn triangulate(pts: &[Vec2], loops: &[Vec<usize>]) -> Vec<[usize; 3]> {
    let Some(outline) = loops.first() else {
        return Vec::new();
    };
    let mut poly: Vec<usize> = outline.clone();
    if signed_area(pts, &poly) < 0.0 {
        poly.reverse();
    }
    // Holes clockwise, bridged rightmost first so later bridges see earlier ones.
    let mut holes: Vec<Vec<usize>> = loops[1..]
        .iter()
        .filter(|h| h.len() >= 3)
        .map(|h| {
            let mut h = h.clone();
            if signed_area(pts, &h) > 0.0 {
                h.reverse();
            }
            h
        })
        .collect();
    let max_x = |h: &Vec<usize>| {
        h.iter()
            .map(|&i| pts[i].x)
            .fold(f32::NEG_INFINITY, f32::max)
    };
    holes.sort_by(|a, b| max_x(b).total_cmp(&max_x(a)));
    for h in &holes {
        bridge(pts, &mut poly, h);
    }
    ear_clip(pts, &poly)
}

/// Splices hole `h` into `poly` through a bridge from its rightmost vertex.
fn bridge(pts: &[Vec2], poly: &mut Vec<usize>, h: &[usize]) {
    let (mi, &m) = h
        .iter()
        .enumerate()
        .max_by(|a, b| pts[*a.1].x.total_cmp(&pts[*b.1].x))
        .expect("hole has vertices");
    let mp = pts[m];
    // Cast a ray to +x and find the closest outline edge it hits.
    let n = poly.len();
    let mut best: Option<(f32, usize)> = None; // (x of hit, position of the visible vertex)
    for i in 0..n {
        let (a, b) = (pts[poly[i]], pts[poly[(i + 1) % n]]);
        // Outline is CCW: edges crossing the ray going upward... accept both directions but
        // require the hit to be to the right of M.
        if (a.y > mp.y) == (b.y > mp.y) && a.y != mp.y && b.y != mp.y {
            continue;
        }
        if a.y == b.y {
            // Horizontal edge on the ray: its nearer end is a candidate.
            if a.y == mp.y {
                for (pos, q) in [(i, a), ((i + 1) % n, b)] {
                    if q.x >= mp.x && best.is_none_or(|(x, _)| q.x < x) {
                        best = Some((q.x, pos));
                    }
                }
            }
            continue;
        }
        let t = (mp.y - a.y) / (b.y - a.y);
        if !(0.0..=1.0).contains(&t) {
            continue;
        }
        let x = a.x + t * (b.x - a.x);
        if x < mp.x {
            continue;
        }
        if best.is_none_or(|(bx, _)| x < bx) {
            // The visible candidate: the edge end with the larger x.
            let pos = if a.x >= b.x { i } else { (i + 1) % n };
            best = Some((x, pos));
        }
    }
    let Some((hx, mut pos)) = best else {
        // The hole lies outside the outline: nothing to cut.
        return;
    };
    let hit = Vec2::new(hx, mp.y);
    let p = pts[poly[pos]];
    if p != hit {
        // Reflex outline vertices inside triangle (M, hit, P) may block the view; take the
        // one making the smallest angle with the ray.
        let (ta, tb, tc) = if cross(mp, hit, p) >= 0.0 {
            (mp, hit, p)
        } else {
            (mp, p, hit)
        };
        let mut best_ang = f32::INFINITY;
        for i in 0..n {
            let q = pts[poly[i]];
            if i == pos || q == p || q == mp {
                continue;
            }
            let prev = pts[poly[(i + n - 1) % n]];
            let next = pts[poly[(i + 1) % n]];
            let reflex = cross(prev, q, next) <= 0.0;
            if reflex && in_triangle(q, ta, tb, tc) {
                let d = q - mp;
                let ang = d.y.abs().atan2(d.x);
                if ang < best_ang
                    || (ang == best_ang && d.length() < (pts[poly[pos]] - mp).length())
                {
                    best_ang = ang;
                    pos = i;
                }
            }
        }
    }
    // A vertex already used by earlier bridges occurs several times: splice at the occurrence
    // whose interior wedge holds the new bridge, or the loop would cross itself.
    let p = pts[poly[pos]];
    let d = mp - p;
    if let Some(k) = (0..n).find(|&k| {
        pts[poly[k]] == p && {
            let a = pts[poly[(k + 1) % n]] - p;
            let b = pts[poly[(k + n - 1) % n]] - p;
            if a.perp_dot(b) > 0.0 {
                a.perp_dot(d) > 0.0 && d.perp_dot(b) > 0.0
            } else {
                !(b.perp_dot(d) >= 0.0 && d.perp_dot(a) >= 0.0)
            }
        }
    }) {
        pos = k;
    }
    let mut out = Vec::with_capacity(poly.len() + h.len() + 2);
    out.extend_from_slice(&poly[..=pos]);
    out.extend(h[mi..].iter().chain(h[..=mi].iter()));
    out.extend_from_slice(&poly[pos..]);
    *poly = out;
}

/// Clips ears from a simple counter-clockwise loop (possibly with bridge duplicates).
fn ear_clip(pts: &[Vec2], poly: &[usize]) -> Vec<[usize; 3]> {
    let mut v: Vec<usize> = poly.to_vec();
    let mut tris = Vec::with_capacity(v.len().saturating_sub(2));
    let mut start = 0;
    while v.len() > 3 {
        let n = v.len();
        let mut clipped = false;
        for k in 0..n {
            let i = (start + k) % n;
            let (ia, ib, ic) = (v[(i + n - 1) % n], v[i], v[(i + 1) % n]);
            let (a, b, c) = (pts[ia], pts[ib], pts[ic]);
            if cross(a, b, c) <= 0.0 {
                continue;
            }
            let blocked = v.iter().any(|&j| {
                let q = pts[j];
                q != a && q != b && q != c && in_triangle(q, a, b, c)
            });
            if blocked {
                continue;
            }
            tris.push([ia, ib, ic]);
            v.remove(i);
            start = i % v.len();
            clipped = true;
            break;
        }
        if !clipped {
            // Degenerate (collinear or self-touching) input: drop the flattest vertex, keeping
            // its triangle only if it has positive area.
            let (i, _) = (0..n)
                .map(|i| {
                    let (a, b, c) = (pts[v[(i + n - 1) % n]], pts[v[i]], pts[v[(i + 1) % n]]);
                    (i, cross(a, b, c).abs())
                })
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .expect("loop has vertices");
            let (ia, ib, ic) = (v[(i + n - 1) % n], v[i], v[(i + 1) % n]);
            if cross(pts[ia], pts[ib], pts[ic]) > 0.0 {
                tris.push([ia, ib, ic]);
            }
            v.remove(i);
            start = 0;
        }
    }
    if v.len() == 3 && cross(pts[v[0]], pts[v[1]], pts[v[2]]) > 0.0 {
        tris.push([v[0], v[1], v[2]]);
    }
    tris
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(pts: &[Vec2], tris: &[[usize; 3]]) -> f32 {
        tris.iter()
            .map(|t| 0.5 * cross(pts[t[0]], pts[t[1]], pts[t[2]]))
            .sum()
    }

    #[test]
    fn concave_l_shape_area() {
        // L: 2×2 square minus the 1×1 top-right corner = 3.
        let pts: Vec<Vec2> = [(0., 0.), (2., 0.), (2., 1.), (1., 1.), (1., 2.), (0., 2.)]
            .iter()
            .map(|&(x, y)| Vec2::new(x, y))
            .collect();
        let tris = triangulate(&pts, &[(0..6).collect()]);
        assert_eq!(tris.len(), 4);
        assert!((area(&pts, &tris) - 3.0).abs() < 1e-5);
        // Every triangle is counter-clockwise (positive area).
        for t in &tris {
            assert!(cross(pts[t[0]], pts[t[1]], pts[t[2]]) > 0.0);
        }
    }

    #[test]
    fn clockwise_star_area() {
        // A concave arrow given clockwise.
        let pts: Vec<Vec2> = [(0., 0.), (1., 3.), (2., 0.), (1., 1.)]
            .iter()
            .rev()
            .map(|&(x, y)| Vec2::new(x, y))
            .collect();
        let tris = triangulate(&pts, &[(0..4).collect()]);
        // Area = big triangle (3) − notch triangle (1).
        assert!(
            (area(&pts, &tris) - 2.0).abs() < 1e-5,
            "{}",
            area(&pts, &tris)
        );
    }

    #[test]
    fn square_with_two_holes() {
        let mut pts = vec![
            Vec2::new(0., 0.),
            Vec2::new(10., 0.),
            Vec2::new(10., 10.),
            Vec2::new(0., 10.),
        ];
        // Hole 1: [1,3]×[1,3] (area 4), hole 2: triangle (6,6) (8,6) (7,8) (area 2), both CCW.
        pts.extend([(1., 1.), (3., 1.), (3., 3.), (1., 3.)].map(|(x, y)| Vec2::new(x, y)));
        pts.extend([(6., 6.), (8., 6.), (7., 8.)].map(|(x, y)| Vec2::new(x, y)));
        let loops = vec![vec![0, 1, 2, 3], vec![4, 5, 6, 7], vec![8, 9, 10]];
        let tris = triangulate(&pts, &loops);
        assert!((area(&pts, &tris) - (100.0 - 4.0 - 2.0)).abs() < 1e-3);
        for t in &tris {
            assert!(cross(pts[t[0]], pts[t[1]], pts[t[2]]) > 0.0);
            // No triangle covers a hole's centre.
            for c in [Vec2::new(2., 2.), Vec2::new(7., 6.6)] {
                assert!(!in_triangle(c, pts[t[0]], pts[t[1]], pts[t[2]]));
            }
        }
    }

    #[test]
    fn degenerate_input_terminates() {
        let pts: Vec<Vec2> = [(0., 0.), (1., 0.), (2., 0.), (3., 0.)]
            .iter()
            .map(|&(x, y)| Vec2::new(x, y))
            .collect();
        let tris = triangulate(&pts, &[(0..4).collect()]);
        assert!(area(&pts, &tris).abs() < 1e-6);
    }

    /// Random star-shaped (concave) outlines with random rectangular holes in separate cells:
    /// the triangles' areas always sum to outline area minus hole areas.
    #[test]
    fn random_polygons_with_holes_cover_their_area() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for case in 0..200 {
            let n = 8 + (rnd() * 30.0) as usize; // keeps the hole lattice inside
            let mut pts = Vec::new();
            for i in 0..n {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                let r = 6.0 + 4.0 * rnd();
                pts.push(Vec2::new(r * a.cos(), r * a.sin()));
            }
            let outline: Vec<usize> = if case % 2 == 0 {
                (0..n).collect()
            } else {
                (0..n).rev().collect()
            };
            let mut loops = vec![outline];
            let mut hole_area = 0.0;
            // Holes in the cells of a 3×3 lattice inside radius 6 (|x|,|y| < 4).
            for cell in 0..9 {
                if rnd() < 0.5 {
                    continue;
                }
                let (cx, cy) = ((cell % 3) as f32 * 2.6 - 2.6, (cell / 3) as f32 * 2.6 - 2.6);
                let (w, h) = (0.2 + rnd(), 0.2 + rnd());
                let base = pts.len();
                pts.extend([
                    Vec2::new(cx - w / 2.0, cy - h / 2.0),
                    Vec2::new(cx + w / 2.0, cy - h / 2.0),
                    Vec2::new(cx + w / 2.0, cy + h / 2.0),
                    Vec2::new(cx - w / 2.0, cy + h / 2.0),
                ]);
                loops.push((base..base + 4).collect());
                hole_area += w * h;
            }
            let want = signed_area(&pts, &(0..n).collect::<Vec<_>>()).abs() - hole_area;
            let tris = triangulate(&pts, &loops);
            let got = area(&pts, &tris);
            assert!(
                (got - want).abs() < 1e-3 * want,
                "case {case}: {got} vs {want}"
            );
            for t in &tris {
                assert!(cross(pts[t[0]], pts[t[1]], pts[t[2]]) > 0.0);
            }
        }
    }

    #[test]
    fn aligned_holes_share_ray_heights() {
        // A 10×4 rectangle with three unit holes on one row and one touching its height: the
        // bridging rays pass exactly through hole vertices.
        let mut pts = vec![
            Vec2::new(0., 0.),
            Vec2::new(10., 0.),
            Vec2::new(10., 4.),
            Vec2::new(0., 4.),
        ];
        let mut loops = vec![vec![0, 1, 2, 3]];
        for x0 in [1.0, 4.0, 7.0] {
            let b = pts.len();
            pts.extend(
                [(x0, 1.), (x0 + 1., 1.), (x0 + 1., 2.), (x0, 2.)].map(|(x, y)| Vec2::new(x, y)),
            );
            loops.push((b..b + 4).collect());
        }
        let tris = triangulate(&pts, &loops);
        assert!(
            (area(&pts, &tris) - 37.0).abs() < 1e-4,
            "{}",
            area(&pts, &tris)
        );
    }
}
