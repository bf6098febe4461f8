//! A compact binned-SAH bounding volume hierarchy over micropolygon quads.
//!
//! Input: quads (four corners each, as `v00 v10 v01 v11` of a diced grid) with the grid and
//! quad index they came from. Output: closest-hit and all-hits queries along a ray segment.
//! Invariants: the build is sequential and depends only on the input order, so the tree (and
//! every hit) is the same whatever the thread count; nodes are 32 bytes, children are stored
//! in pairs; a quad is intersected as the two triangles `(v00 v10 v11)` and `(v00 v11 v01)`
//! and reports bilinear-style coordinates `(a, b)` in `[0, 1]²` across the quad.
//!
//! Why home-made rather than the `bvh` or `obvhs` crates: `bvh` is built on nalgebra (a
//! second linear-algebra crate beside glam) and its traversal returns a `Vec` of every shape
//! whose box the ray crosses (an allocation and no closest-hit pruning per ray); `obvhs` is
//! glam-based and fast (CWBVH, PLOC) but young (three 0.x releases within a year, API changed
//! each time) and brings its own dependency tree. A binned-SAH BVH2 with ordered traversal is
//! ~300 lines, deterministic by construction and fast enough for the targets (see
//! `benches/rays.rs`).

use glam::Vec3;

/// One micropolygon: corners `p[0]=v00, p[1]=v10, p[2]=v01, p[3]=v11`.
#[derive(Clone, Copy, Debug)]
pub struct Quad {
    pub p: [Vec3; 4],
    /// Index of the ray grid it belongs to.
    pub grid: u32,
    /// Quad index inside the grid: `j * (nu − 1) + i`.
    pub index: u32,
}

#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
struct Node {
    min: [f32; 3],
    /// Leaf: first quad. Interior: index of the left child (the right one follows it).
    first: u32,
    max: [f32; 3],
    /// Quads in a leaf; 0 for interior nodes.
    count: u32,
}

/// The closest intersection along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub grid: u32,
    pub index: u32,
    /// Position across the quad: `a` along u (v00→v10), `b` along v (v00→v01).
    pub a: f32,
    pub b: f32,
}

#[derive(Default, Debug)]
pub struct Bvh {
    nodes: Vec<Node>,
    pub quads: Vec<Quad>,
}

#[derive(Clone, Copy)]
struct Aabb {
    min: Vec3,
    max: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };
    fn grow(&mut self, o: &Aabb) {
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
    }
    fn area(&self) -> f32 {
        let d = self.max - self.min;
        if d.x < 0.0 {
            return 0.0;
        }
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

const BINS: usize = 12;
const MAX_LEAF: usize = 8;

impl Bvh {
    /// Builds the tree (sequentially: see the module invariants).
    pub fn build(mut quads: Vec<Quad>) -> Bvh {
        let n = quads.len();
        if n == 0 {
            return Bvh::default();
        }
        let boxes: Vec<Aabb> = quads
            .iter()
            .map(|q| Aabb {
                min: q.p[0].min(q.p[1]).min(q.p[2].min(q.p[3])),
                max: q.p[0].max(q.p[1]).max(q.p[2].max(q.p[3])),
            })
            .collect();
        let cent: Vec<Vec3> = boxes.iter().map(|b| (b.min + b.max) * 0.5).collect();
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut nodes = Vec::with_capacity(2 * n / 2 + 1);
        nodes.push(Node::default());
        // (node index, range start, range end)
        let mut stack = vec![(0usize, 0usize, n)];
        while let Some((ni, s, e)) = stack.pop() {
            let mut bb = Aabb::EMPTY;
            let mut cb = Aabb::EMPTY;
            for &k in &order[s..e] {
                bb.grow(&boxes[k as usize]);
                let c = cent[k as usize];
                cb.grow(&Aabb { min: c, max: c });
            }
            let count = e - s;
            let leaf = |nodes: &mut Vec<Node>| {
                nodes[ni] = Node {
                    min: bb.min.to_array(),
                    first: s as u32,
                    max: bb.max.to_array(),
                    count: count as u32,
                };
            };
            if count <= 2 {
                leaf(&mut nodes);
                continue;
            }
            let ext = cb.max - cb.min;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let lo = cb.min[axis];
            let span = ext[axis];
            let mut mid = s + count / 2;
            let mut split_ok = false;
            if span > 0.0 && span.is_finite() {
                let scale = BINS as f32 / span;
                let bin_of =
                    |k: u32| (((cent[k as usize][axis] - lo) * scale) as usize).min(BINS - 1);
                let mut bins = [(Aabb::EMPTY, 0usize); BINS];
                for &k in &order[s..e] {
                    let b = &mut bins[bin_of(k)];
                    b.0.grow(&boxes[k as usize]);
                    b.1 += 1;
                }
                // Sweep: cost of splitting after bin i.
                let mut right_area = [0f32; BINS];
                let mut right_count = [0usize; BINS];
                let mut acc = Aabb::EMPTY;
                let mut cnt = 0;
                for i in (1..BINS).rev() {
                    acc.grow(&bins[i].0);
                    cnt += bins[i].1;
                    right_area[i] = acc.area();
                    right_count[i] = cnt;
                }
                let mut best = (f32::INFINITY, 0usize);
                let mut acc = Aabb::EMPTY;
                let mut cnt = 0;
                for i in 0..BINS - 1 {
                    acc.grow(&bins[i].0);
                    cnt += bins[i].1;
                    if cnt == 0 || right_count[i + 1] == 0 {
                        continue;
                    }
                    let cost =
                        acc.area() * cnt as f32 + right_area[i + 1] * right_count[i + 1] as f32;
                    if cost < best.0 {
                        best = (cost, i);
                    }
                }
                let leaf_cost = bb.area() * count as f32;
                let split_cost = 0.5 * bb.area() + best.0;
                if best.0.is_finite() && (split_cost < leaf_cost || count > MAX_LEAF) {
                    // Stable partition keeps the build independent of anything but the input.
                    let (mut l, mut r): (Vec<u32>, Vec<u32>) =
                        order[s..e].iter().partition(|&&k| bin_of(k) <= best.1);
                    mid = s + l.len();
                    l.append(&mut r);
                    order[s..e].copy_from_slice(&l);
                    split_ok = true;
                } else if count <= MAX_LEAF {
                    leaf(&mut nodes);
                    continue;
                }
            }
            if !split_ok {
                if count <= MAX_LEAF {
                    leaf(&mut nodes);
                    continue;
                }
                // All centroids coincide: split the range in half.
                mid = s + count / 2;
            }
            let left = nodes.len();
            nodes.push(Node::default());
            nodes.push(Node::default());
            nodes[ni] = Node {
                min: bb.min.to_array(),
                first: left as u32,
                max: bb.max.to_array(),
                count: 0,
            };
            stack.push((left + 1, mid, e));
            stack.push((left, s, mid));
        }
        let sorted: Vec<Quad> = order.iter().map(|&k| quads[k as usize]).collect();
        quads.clear();
        Bvh {
            nodes,
            quads: sorted,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.quads.is_empty()
    }

    /// The closest hit with `tmin < t < tmax`.
    pub fn closest(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut tmax = tmax;
        self.walk(o, d, tmin, &mut tmax, &mut |q, hit_t, a, b, tmax_ref| {
            *tmax_ref = hit_t;
            best = Some(Hit {
                t: hit_t,
                grid: q.grid,
                index: q.index,
                a,
                b,
            });
            false
        });
        best
    }

    /// Calls `f` for every hit with `tmin < t < tmax` (in no particular order) until it
    /// returns true.
    pub fn each_hit(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32, f: &mut dyn FnMut(Hit) -> bool) {
        let mut tm = tmax;
        self.walk(o, d, tmin, &mut tm, &mut |q, t, a, b, _| {
            f(Hit {
                t,
                grid: q.grid,
                index: q.index,
                a,
                b,
            })
        });
    }

    /// Ordered traversal. `on_hit(quad, t, a, b, &mut tmax)` may shrink `tmax`; returning
    /// true stops the walk.
    fn walk(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(&Quad, f32, f32, f32, &mut f32) -> bool,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let safe = |x: f32| {
            if x.abs() < 1e-30 {
                1e-30f32.copysign(x)
            } else {
                x
            }
        };
        let inv = Vec3::new(1.0 / safe(d.x), 1.0 / safe(d.y), 1.0 / safe(d.z));
        let oi = o * inv;
        let slab = |n: &Node, tmax: f32| -> f32 {
            let t0 = Vec3::from(n.min) * inv - oi;
            let t1 = Vec3::from(n.max) * inv - oi;
            let near = t0.min(t1).max_element().max(tmin);
            // Widened by 2 ulps (Ize 2013): a ray grazing a box face is never lost to rounding.
            let far = (t0.max(t1).min_element() * 1.000_000_24).min(tmax);
            if near <= far {
                near
            } else {
                f32::INFINITY
            }
        };
        let wt = WtRay::new(o, d);
        let mut stack = [0u32; 96];
        let mut sp = 0usize;
        if slab(&self.nodes[0], *tmax) == f32::INFINITY {
            return;
        }
        let mut cur = 0u32;
        loop {
            let n = &self.nodes[cur as usize];
            if n.count > 0 {
                let (s, e) = (n.first as usize, (n.first + n.count) as usize);
                for q in &self.quads[s..e] {
                    if let Some((t, a, b)) = intersect_quad_wt(q, &wt, tmin, *tmax) {
                        if on_hit(q, t, a, b, tmax) {
                            return;
                        }
                    }
                }
            } else {
                let (l, r) = (n.first, n.first + 1);
                let tl = slab(&self.nodes[l as usize], *tmax);
                let tr = slab(&self.nodes[r as usize], *tmax);
                match (tl < f32::INFINITY, tr < f32::INFINITY) {
                    (true, true) => {
                        let (near, far) = if tl <= tr { (l, r) } else { (r, l) };
                        if sp < stack.len() {
                            stack[sp] = far;
                            sp += 1;
                        }
                        cur = near;
                        continue;
                    }
                    (true, false) => {
                        cur = l;
                        continue;
                    }
                    (false, true) => {
                        cur = r;
                        continue;
                    }
                    _ => {}
                }
            }
            // Pop the next node still worth visiting.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let c = stack[sp];
                if slab(&self.nodes[c as usize], *tmax) < f32::INFINITY {
                    cur = c;
                    break;
                }
            }
        }
    }
}

/// A ray prepared for the watertight test (Woop, Benthin & Wald 2013): the axis where the
/// direction is largest becomes z, and a shear maps the ray onto the +z axis, so a triangle
/// test reduces to 2D edge functions that neighbouring triangles evaluate identically along
/// a shared edge (a ray can never slip between two triangles that share the edge's vertices).
#[derive(Clone, Copy)]
pub(crate) struct WtRay {
    o: Vec3,
    k: [usize; 3],
    s: [f32; 3],
}

impl WtRay {
    #[inline]
    pub(crate) fn new(o: Vec3, d: Vec3) -> WtRay {
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = if d[kz] == 0.0 { 1e-30 } else { d[kz] };
        WtRay {
            o,
            k: [kx, ky, kz],
            s: [d[kx] / dz, d[ky] / dz, 1.0 / dz],
        }
    }

    /// A vertex in the ray's sheared frame.
    #[inline(always)]
    fn xform(&self, v: Vec3) -> [f32; 3] {
        let a = v - self.o;
        let (ax, ay, az) = (a[self.k[0]], a[self.k[1]], a[self.k[2]]);
        [ax - self.s[0] * az, ay - self.s[1] * az, self.s[2] * az]
    }
}

/// The watertight test of the triangle (a b c) given in the ray's frame: (t, w1, w2), the
/// weights of b and c.
#[inline(always)]
fn tri_wt(a: [f32; 3], b: [f32; 3], c: [f32; 3], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let mut u = c[0] * b[1] - c[1] * b[0];
    let mut v = a[0] * c[1] - a[1] * c[0];
    let mut w = b[0] * a[1] - b[1] * a[0];
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // On an edge in single precision: decide in double, as every triangle sharing the
        // edge will.
        let f = |x: f32| f64::from(x);
        u = (f(c[0]) * f(b[1]) - f(c[1]) * f(b[0])) as f32;
        v = (f(a[0]) * f(c[1]) - f(a[1]) * f(c[0])) as f32;
        w = (f(b[0]) * f(a[1]) - f(b[1]) * f(a[0])) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let tt = u * a[2] + v * b[2] + w * c[2];
    let inv = 1.0 / det;
    let t = tt * inv;
    if !(t > tmin && t < tmax) {
        return None;
    }
    Some((t, v * inv, w * inv))
}

/// The quad's two triangles `(v00 v10 v11)` and `(v00 v11 v01)`, watertight; returns
/// (t, a, b).
#[inline]
fn intersect_quad_wt(q: &Quad, r: &WtRay, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let [p00, p10, p01, p11] = q.p;
    let (a, b, c, d) = (r.xform(p00), r.xform(p10), r.xform(p01), r.xform(p11));
    let mut best = None;
    let mut tm = tmax;
    // Triangle 1: P = w0 v00 + w1 v10 + w2 v11: a = w1 + w2, b = w2.
    if let Some((t, w1, w2)) = tri_wt(a, b, d, tmin, tm) {
        tm = t;
        best = Some((t, w1 + w2, w2));
    }
    // Triangle 2: P = w0 v00 + w1 v11 + w2 v01: a = w1, b = w1 + w2.
    if let Some((t, w1, w2)) = tri_wt(a, d, c, tmin, tm) {
        best = Some((t, w1, w1 + w2));
    }
    best
}

/// [`intersect_quad_wt`] for a ray given by origin and direction.
#[cfg(test)]
fn intersect_quad(q: &Quad, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    intersect_quad_wt(q, &WtRay::new(o, d), tmin, tmax)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f32, grid: u32) -> Quad {
        Quad {
            p: [
                Vec3::new(-1.0, -1.0, z),
                Vec3::new(1.0, -1.0, z),
                Vec3::new(-1.0, 1.0, z),
                Vec3::new(1.0, 1.0, z),
            ],
            grid,
            index: 0,
        }
    }

    #[test]
    fn closest_hit_of_stacked_squares() {
        let quads: Vec<Quad> = (0..100).map(|k| square(k as f32 + 1.0, k)).collect();
        let bvh = Bvh::build(quads);
        let h = bvh
            .closest(Vec3::new(0.5, 0.0, 0.0), Vec3::Z, 0.0, 1e30)
            .unwrap();
        assert_eq!(h.grid, 0);
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!((h.a - 0.75).abs() < 1e-6 && (h.b - 0.5).abs() < 1e-6);
        let h = bvh
            .closest(Vec3::new(0.0, 0.3, 50.5), Vec3::Z, 0.0, 1e30)
            .unwrap();
        assert_eq!(h.grid, 50);
        let mut n = 0;
        bvh.each_hit(Vec3::new(0.1, 0.1, 0.0), Vec3::Z, 0.0, 10.5, &mut |_| {
            n += 1;
            false
        });
        assert_eq!(n, 10);
        assert!(bvh
            .closest(Vec3::new(3.0, 0.0, 0.0), Vec3::Z, 0.0, 1e30)
            .is_none());
    }

    #[test]
    fn brute_force_agrees_on_a_random_soup() {
        let mut h = 12345u32;
        let mut rnd = || {
            h = crate::pattern::hash::hash_u32(h);
            (h as f32 / u32::MAX as f32) * 2.0 - 1.0
        };
        let mut quads = Vec::new();
        for k in 0..500 {
            let c = Vec3::new(rnd() * 5.0, rnd() * 5.0, rnd() * 5.0);
            let u = Vec3::new(rnd(), rnd(), rnd()) * 0.4;
            let v = Vec3::new(rnd(), rnd(), rnd()) * 0.4;
            quads.push(Quad {
                p: [c, c + u, c + v, c + u + v],
                grid: k,
                index: 0,
            });
        }
        let bvh = Bvh::build(quads.clone());
        for _ in 0..300 {
            let o = Vec3::new(rnd(), rnd(), rnd()) * 6.0;
            let d = Vec3::new(rnd(), rnd(), rnd()).normalize_or(Vec3::X);
            let mut best: Option<(f32, u32)> = None;
            for q in &quads {
                if let Some((t, _, _)) = intersect_quad(q, o, d, 0.0, 1e30) {
                    if best.is_none_or(|b| t < b.0) {
                        best = Some((t, q.grid));
                    }
                }
            }
            let got = bvh.closest(o, d, 0.0, 1e30).map(|h| (h.t, h.grid));
            assert_eq!(got.map(|g| g.1), best.map(|b| b.1));
        }
    }
}
