//! A compact binned-SAH bounding volume hierarchy over micropolygon quads.
//!
//! Input: quads (four corners each, as `v00 v10 v01 v11` of a diced grid, in a shared vertex
//! array) with the grid and quad index they came from. Output: closest-hit and all-hits queries along a ray segment.
//! Invariants: the build is sequential and depends only on the input order, so the tree (and
//! every hit) is the same whatever the thread count; nodes are 4 wide (a binned-SAH binary
//! tree, 16 bins on each axis, collapsed so that each node holds the boxes of up to four
//! children, tested together; leaves of up to 8 quads, their SAH cost counted in groups of
//! four, the groups the leaf test takes at once on x86-64, see `quad4`); a quad is
//! intersected, watertight, as the two triangles `(v00 v10 v11)` and `(v00 v11 v01)` and
//! reports bilinear-style coordinates `(a, b)` in `[0, 1]²` across the quad. Traversal visits
//! the nearest child in reach first (ties by lane), pushing the others farthest first.
//!
//! Why home-made rather than the `bvh` or `obvhs` crates: `bvh` is built on nalgebra (a
//! second linear-algebra crate beside glam) and its traversal returns a `Vec` of every shape
//! whose box the ray crosses (an allocation and no closest-hit pruning per ray); `obvhs` is
//! glam-based and fast (CWBVH, PLOC) but young (three 0.x releases within a year, API changed
//! each time) and brings its own dependency tree. A binned-SAH BVH4 with ordered traversal is
//! ~500 lines, deterministic by construction, and its leaves hold micropolygons with the
//! watertight test they need (see `benches/rays.rs` for its speed).

use glam::Vec3;

/// One micropolygon, its corners in the shared vertex array: `v00 = verts[k]`,
/// `v10 = verts[k + 1]`, `v01 = verts[k + row]`, `v11 = verts[k + row + 1]` (a grid's points
/// are stored once, row by row, and its micropolygons point into them: 16 bytes a quad
/// instead of 56, and the quads of a leaf share their corners' cache lines).
#[derive(Clone, Copy, Debug)]
pub struct Quad {
    pub k: u32,
    pub row: u32,
    /// Index of the ray grid it belongs to.
    pub grid: u32,
    /// Quad index inside the grid: `j * (nu − 1) + i`.
    pub index: u32,
}

impl Quad {
    /// The corners `v00 v10 v01 v11`.
    #[inline(always)]
    pub fn corners(&self, verts: &[Vec3]) -> [Vec3; 4] {
        let (k, r) = (self.k as usize, self.row as usize);
        [verts[k], verts[k + 1], verts[k + r], verts[k + r + 1]]
    }
}

/// A 4-wide node: the boxes of up to four children side by side (lane `i` of each array),
/// so one ray tests all four with the same few vector instructions.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node4 {
    /// Box corners per child lane: rows 0–2 the low x, y, z, rows 3–5 the high ones (a
    /// ray picks its near and far row per axis once, by its direction's signs). Empty lanes
    /// hold an inverted box.
    b: [[f32; 4]; 6],
    /// Interior child: node index. Leaf child: its first quad.
    child: [u32; 4],
    /// Quads in a leaf child; 0 for an interior child (and an empty lane).
    count: [u32; 4],
}

impl Node4 {
    const EMPTY: Node4 = Node4 {
        b: [
            [f32::INFINITY; 4],
            [f32::INFINITY; 4],
            [f32::INFINITY; 4],
            [f32::NEG_INFINITY; 4],
            [f32::NEG_INFINITY; 4],
            [f32::NEG_INFINITY; 4],
        ],
        child: [0; 4],
        count: [0; 4],
    };
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
    nodes: Vec<Node4>,
    pub quads: Vec<Quad>,
    /// The quads' corners (see [`Quad`]), then one padding element (the four-quad test
    /// loads 16 bytes a corner).
    pub verts: Vec<Vec3>,
    /// The root when the whole tree is one leaf (then `nodes` is empty): its quad count.
    root_leaf: u32,
}

#[derive(Clone, Copy, Debug)]
struct Aabb {
    min: Vec3,
    max: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };
    #[inline]
    fn grow(&mut self, o: &Aabb) {
        self.min = fmin3(self.min, o.min);
        self.max = fmax3(self.max, o.max);
    }
    #[inline]
    fn grow_point(&mut self, p: Vec3) {
        self.min = fmin3(self.min, p);
        self.max = fmax3(self.max, p);
    }
    #[inline]
    fn area(&self) -> f32 {
        let d = self.max - self.min;
        if d.x < 0.0 {
            return 0.0;
        }
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// Lane-wise minimum and maximum without `f32::min`'s NaN handling (boxes are finite), so
/// they compile to single `minss`/`maxss` instructions.
#[inline(always)]
fn fmin3(a: Vec3, b: Vec3) -> Vec3 {
    let m = |x: f32, y: f32| if x < y { x } else { y };
    Vec3::new(m(a.x, b.x), m(a.y, b.y), m(a.z, b.z))
}
#[inline(always)]
fn fmax3(a: Vec3, b: Vec3) -> Vec3 {
    let m = |x: f32, y: f32| if x > y { x } else { y };
    Vec3::new(m(a.x, b.x), m(a.y, b.y), m(a.z, b.z))
}

const BINS: usize = 16;
/// Most quads in a leaf.
const MAX_LEAF: usize = 8;
/// SAH cost of a node visit relative to testing one group of up to four quads (leaves test
/// their quads four at a time, see `quad4`: a group costs about five node visits'
/// instructions, less its share of the node's cache misses).
const TRAVERSAL_COST: f32 = 0.3;

/// The SAH's intersection cost of `n` quads: the groups of four they are tested in.
#[inline]
fn groups(n: u32) -> f32 {
    n.div_ceil(4) as f32
}

/// A node of the binary tree built first (then collapsed to 4-wide nodes).
#[derive(Clone, Copy)]
struct Node2 {
    bb: Aabb,
    /// Interior: left child (right = left + 1). Leaf: first quad.
    first: u32,
    /// Quads in a leaf; 0 for interior nodes.
    count: u32,
}

impl Bvh {
    /// Builds the tree: a binned-SAH binary tree (sweeping 16 bins on each axis, partitioning
    /// in place), collapsed into 4-wide nodes. Sequential and a function of the input order
    /// alone (see the module invariants).
    pub fn build(quads: Vec<Quad>, mut verts: Vec<Vec3>) -> Bvh {
        let n = quads.len();
        if n == 0 {
            return Bvh::default();
        }
        let boxes: Vec<Aabb> = quads
            .iter()
            .map(|q| {
                let p = q.corners(&verts);
                Aabb {
                    min: p[0].min(p[1]).min(p[2].min(p[3])),
                    max: p[0].max(p[1]).max(p[2].max(p[3])),
                }
            })
            .collect();
        let cent: Vec<Vec3> = boxes.iter().map(|b| (b.min + b.max) * 0.5).collect();
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut nodes: Vec<Node2> = Vec::with_capacity(2 * n / 3 + 1);
        nodes.push(Node2 {
            bb: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        let mut stack = vec![(0usize, 0usize, n)];
        while let Some((ni, s, e)) = stack.pop() {
            let mut bb = Aabb::EMPTY;
            let mut cb = Aabb::EMPTY;
            for &k in &order[s..e] {
                bb.grow(&boxes[k as usize]);
                cb.grow_point(cent[k as usize]);
            }
            let count = e - s;
            let make_leaf = |nodes: &mut Vec<Node2>| {
                nodes[ni] = Node2 {
                    bb,
                    first: s as u32,
                    count: count as u32,
                };
            };
            if count <= 2 {
                make_leaf(&mut nodes);
                continue;
            }
            // The best split over the three axes.
            let ext = cb.max - cb.min;
            let mut best = (f32::INFINITY, 0usize, 0usize); // (cost, axis, last bin on the left)
                                                            // One pass bins every item on the three axes (an axis of no extent puts every
                                                            // item in its bin 0, where no split is possible).
            let scales: [f32; 3] = std::array::from_fn(|a| {
                if ext[a] > 0.0 && ext[a].is_finite() {
                    BINS as f32 * (1.0 - 1e-6) / ext[a]
                } else {
                    0.0
                }
            });
            let mut bins = [[(Aabb::EMPTY, 0u32); BINS]; 3];
            for &k in &order[s..e] {
                let c = cent[k as usize] - cb.min;
                let bx = &boxes[k as usize];
                for axis in 0..3 {
                    let i = ((c[axis] * scales[axis]) as usize).min(BINS - 1);
                    let bin = &mut bins[axis][i];
                    bin.0.grow(bx);
                    bin.1 += 1;
                }
            }
            for axis in 0..3 {
                if scales[axis] == 0.0 {
                    continue;
                }
                let b = &bins[axis];
                let mut right_area = [0f32; BINS];
                let mut right_count = [0u32; BINS];
                let mut acc = Aabb::EMPTY;
                let mut cnt = 0;
                for i in (1..BINS).rev() {
                    acc.grow(&b[i].0);
                    cnt += b[i].1;
                    right_area[i] = acc.area();
                    right_count[i] = cnt;
                }
                let mut acc = Aabb::EMPTY;
                let mut cnt = 0;
                for i in 0..BINS - 1 {
                    acc.grow(&b[i].0);
                    cnt += b[i].1;
                    if cnt == 0 || right_count[i + 1] == 0 {
                        continue;
                    }
                    let cost =
                        acc.area() * groups(cnt) + right_area[i + 1] * groups(right_count[i + 1]);
                    if cost < best.0 {
                        best = (cost, axis, i);
                    }
                }
            }
            let area = bb.area().max(f32::MIN_POSITIVE);
            let leaf_cost = groups(count as u32);
            let split_cost = TRAVERSAL_COST + best.0 / area;
            let mid = if best.0.is_finite() && (split_cost < leaf_cost || count > MAX_LEAF) {
                // In-place partition by the chosen bin (deterministic: depends only on the
                // order so far).
                let axis = best.1;
                let (lo, scale) = (cb.min[axis], scales[axis]);
                let left_of = |k: u32| {
                    (((cent[k as usize][axis] - lo) * scale) as usize).min(BINS - 1) <= best.2
                };
                let (mut i, mut j) = (s, e);
                while i < j {
                    if left_of(order[i]) {
                        i += 1;
                    } else {
                        j -= 1;
                        order.swap(i, j);
                    }
                }
                i
            } else if count <= MAX_LEAF {
                make_leaf(&mut nodes);
                continue;
            } else {
                // All centroids coincide: halve the range.
                s + count / 2
            };
            let left = nodes.len();
            let blank = Node2 {
                bb: Aabb::EMPTY,
                first: 0,
                count: 0,
            };
            nodes.push(blank);
            nodes.push(blank);
            nodes[ni] = Node2 {
                bb,
                first: left as u32,
                count: 0,
            };
            stack.push((left + 1, mid, e));
            stack.push((left, s, mid));
        }
        let sorted: Vec<Quad> = order.iter().map(|&k| quads[k as usize]).collect();
        drop(quads);
        verts.push(Vec3::ZERO);
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(nodes.len() / 2 + 1),
            quads: sorted,
            verts,
            root_leaf: 0,
        };
        if nodes[0].count > 0 {
            bvh.root_leaf = nodes[0].count;
            return bvh;
        }
        bvh.collapse(&nodes, 0);
        bvh
    }

    /// Makes the 4-wide node for binary interior node `i` (children first-come first-placed:
    /// the root is node 0); returns its index.
    fn collapse(&mut self, nodes: &[Node2], i: usize) -> u32 {
        // Open the interior child with the largest box until there are four.
        let mut kids: Vec<usize> = vec![nodes[i].first as usize, nodes[i].first as usize + 1];
        while kids.len() < 4 {
            let pick = kids
                .iter()
                .enumerate()
                .filter(|(_, &k)| nodes[k].count == 0)
                .max_by(|a, b| nodes[*a.1].bb.area().total_cmp(&nodes[*b.1].bb.area()));
            let Some((pos, &k)) = pick else {
                break;
            };
            let l = nodes[k].first as usize;
            kids[pos] = l;
            kids.insert(pos + 1, l + 1);
        }
        let me = self.nodes.len();
        self.nodes.push(Node4::EMPTY);
        let mut node = Node4::EMPTY;
        for (lane, &k) in kids.iter().enumerate() {
            let c = &nodes[k];
            for axis in 0..3 {
                node.b[axis][lane] = c.bb.min[axis];
                node.b[3 + axis][lane] = c.bb.max[axis];
            }
            if c.count > 0 {
                node.child[lane] = c.first;
                node.count[lane] = c.count;
            } else {
                node.child[lane] = self.collapse(nodes, k);
                node.count[lane] = 0;
            }
        }
        self.nodes[me] = node;
        me as u32
    }

    pub fn is_empty(&self) -> bool {
        self.quads.is_empty()
    }

    /// The closest hit with `tmin < t < tmax`.
    pub fn closest(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut tmax = tmax;
        self.walk::<true>(o, d, tmin, &mut tmax, &mut |q, hit_t, a, b, tmax_ref| {
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
        self.walk::<false>(o, d, tmin, &mut tm, &mut |q, t, a, b, _| {
            f(Hit {
                t,
                grid: q.grid,
                index: q.index,
                a,
                b,
            })
        });
    }

    /// Tests the quads of a leaf in order; true when `on_hit` asked to stop.
    #[cfg(not(target_arch = "x86_64"))]
    #[inline]
    fn leaf(
        &self,
        first: u32,
        count: u32,
        ray: &LeafRay,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(&Quad, f32, f32, f32, &mut f32) -> bool,
    ) -> bool {
        let (s, e) = (first as usize, (first + count) as usize);
        for q in &self.quads[s..e] {
            if let Some((t, a, b)) = intersect_quad_wt(q.corners(&self.verts), &ray.wt, tmin, *tmax)
            {
                if on_hit(q, t, a, b, tmax) {
                    return true;
                }
            }
        }
        false
    }

    /// Tests the quads of a leaf, four at a time (see `quad4::leaf`); true when `on_hit`
    /// asked to stop.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    fn leaf(
        &self,
        first: u32,
        count: u32,
        ray: &LeafRay,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(&Quad, f32, f32, f32, &mut f32) -> bool,
    ) -> bool {
        let (s, e) = (first as usize, (first + count) as usize);
        let Some(quads) = self.quads.get(s..e) else {
            return false;
        };
        super::quad4::leaf(quads, &self.verts, &ray.w4, &ray.wt, tmin, tmax, on_hit)
    }

    /// Asks for the cache line of a pushed child (an interior node, or a leaf's first quads):
    /// a later visit then finds it on the way. No effect on results.
    #[inline(always)]
    fn prefetch(&self, child: u32, count: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            // A prefetch never faults, so the address needs no bounds check (wrapping_add
            // only computes it).
            let p: *const i8 = if count == 0 {
                self.nodes.as_ptr().wrapping_add(child as usize).cast()
            } else {
                // Not the corners: finding them would wait for the quad.
                self.quads.as_ptr().wrapping_add(child as usize).cast()
            };
            // SAFETY: SSE is the x86-64 baseline; a prefetch reads nothing architecturally.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p) };
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (child, count);
    }

    /// Traversal, nearest child first when `ordered`. `on_hit(quad, t, a, b, &mut tmax)` may
    /// shrink `tmax`; returning true stops the walk.
    fn walk<const ORDERED: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(&Quad, f32, f32, f32, &mut f32) -> bool,
    ) {
        if self.quads.is_empty() {
            return;
        }
        let wt = LeafRay::new(o, d);
        if self.nodes.is_empty() {
            self.leaf(0, self.root_leaf, &wt, tmin, tmax, on_hit);
            return;
        }
        let safe = |x: f32| {
            if x.abs() < 1e-30 {
                1e-30f32.copysign(x)
            } else {
                x
            }
        };
        let inv = [1.0 / safe(d.x), 1.0 / safe(d.y), 1.0 / safe(d.z)];
        let oi = [o.x * inv[0], o.y * inv[1], o.z * inv[2]];
        let rb = SlabRay::new(inv, oi);
        // Pending children: (child, quad count (0: interior), entry distance). Deeper than
        // the array (a degenerate tree), they spill to the heap.
        // Not initialised: only entries below `sp` are ever read (no memset per ray).
        let mut stack = [std::mem::MaybeUninit::<(u32, u32, f32)>::uninit(); 64];
        let mut spill: Vec<(u32, u32, f32)> = Vec::new();
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            let n = &self.nodes[cur as usize];
            let (mask, tnear) = slab4(n, &rb, tmin, *tmax);
            // The child to visit now (lane), if any; the others in reach are pushed.
            let first = if mask == 0 {
                None
            } else if mask & (mask - 1) == 0 {
                // One child in reach (the common case deep in the tree): no ordering.
                Some(mask.trailing_zeros() as usize & 3)
            } else if mask.count_ones() == 2 {
                // Two (most of the rest): one comparison of the sort keys below, (distance
                // bits, lane); the farther one is pushed.
                let i = mask.trailing_zeros() as usize & 3;
                let j = (mask & (mask - 1)).trailing_zeros() as usize & 3;
                let (near, far) = if ORDERED && tnear[j].to_bits() < tnear[i].to_bits() {
                    (j, i)
                } else {
                    (i, j)
                };
                let e = (n.child[far], n.count[far], tnear[far]);
                self.prefetch(e.0, e.1);
                if sp < stack.len() {
                    stack[sp].write(e);
                    sp += 1;
                } else {
                    spill.push(e);
                }
                Some(near)
            } else {
                // Sort keys (a sorting network, branch-free): the entry distance's bits
                // (distances are ≥ tmin ≥ 0, whose bits order as the numbers do) above the
                // lane when `ordered`, the lane alone otherwise; lanes out of reach sort last.
                let key = sort4(std::array::from_fn(|i| {
                    let t = if ORDERED {
                        u64::from(tnear[i].to_bits()) << 2
                    } else {
                        0
                    };
                    if mask & (1 << i) != 0 {
                        t | i as u64
                    } else {
                        u64::MAX
                    }
                }));
                // Push all but the first, farthest first; visit the first now (as if pushed
                // and popped at once: the same order).
                let c = mask.count_ones() as usize;
                for &kk in key[1..c].iter().rev() {
                    let i = (kk & 3) as usize;
                    let e = (n.child[i], n.count[i], tnear[i]);
                    self.prefetch(e.0, e.1);
                    if sp < stack.len() {
                        stack[sp].write(e);
                        sp += 1;
                    } else {
                        spill.push(e);
                    }
                }
                Some((key[0] & 3) as usize)
            };
            if let Some(i) = first {
                if n.count[i] == 0 {
                    cur = n.child[i];
                    continue;
                }
                if self.leaf(n.child[i], n.count[i], &wt, tmin, tmax, on_hit) {
                    return;
                }
            }
            // Pop: leaves are tested as they come; the first interior node still in reach
            // is visited next.
            loop {
                let (c, count, t) = if let Some(e) = spill.pop() {
                    e
                } else if sp > 0 {
                    sp -= 1;
                    // SAFETY: entries below `sp` were written by the pushes above.
                    unsafe { stack[sp].assume_init() }
                } else {
                    return;
                };
                if t > *tmax {
                    continue;
                }
                if count > 0 {
                    if self.leaf(c, count, &wt, tmin, tmax, on_hit) {
                        return;
                    }
                    continue;
                }
                cur = c;
                break;
            }
        }
    }
}

/// Sorts four keys ascending: the five compare-exchanges of the optimal network, each a
/// pair of conditional moves (no branches to mispredict on the children's order).
#[inline(always)]
fn sort4(mut k: [u64; 4]) -> [u64; 4] {
    #[inline(always)]
    fn ce(k: &mut [u64; 4], a: usize, b: usize) {
        let (x, y) = (k[a], k[b]);
        k[a] = x.min(y);
        k[b] = x.max(y);
    }
    ce(&mut k, 0, 1);
    ce(&mut k, 2, 3);
    ce(&mut k, 0, 2);
    ce(&mut k, 1, 3);
    ce(&mut k, 1, 2);
    k
}

/// A ray prepared for the leaves' quad tests.
struct LeafRay {
    wt: WtRay,
    #[cfg(target_arch = "x86_64")]
    w4: super::quad4::WtRay4,
}

impl LeafRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> LeafRay {
        let wt = WtRay::new(o, d);
        LeafRay {
            #[cfg(target_arch = "x86_64")]
            w4: super::quad4::WtRay4::new(&wt),
            wt,
        }
    }
}

/// A ray prepared for the slab test: per axis its near and far row of a node's boxes (low
/// or high, by the direction's sign) and the reciprocal direction and origin scaled by it.
struct SlabRay {
    near: [usize; 3],
    far: [usize; 3],
    inv: [f32; 3],
    oi: [f32; 3],
}

impl SlabRay {
    #[inline(always)]
    fn new(inv: [f32; 3], oi: [f32; 3]) -> SlabRay {
        let near: [usize; 3] = std::array::from_fn(|a| if inv[a] < 0.0 { 3 + a } else { a });
        let far: [usize; 3] = std::array::from_fn(|a| if inv[a] < 0.0 { a } else { 3 + a });
        SlabRay { near, far, inv, oi }
    }
}

/// Lane-wise minimum and maximum, written so they compile to `minps`/`maxps`.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn vmin(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    std::array::from_fn(|i| if a[i] < b[i] { a[i] } else { b[i] })
}
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn vmax(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    std::array::from_fn(|i| if a[i] > b[i] { a[i] } else { b[i] })
}
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn vslab(p: &[f32; 4], inv: f32, oi: f32) -> [f32; 4] {
    std::array::from_fn(|i| p[i] * inv - oi)
}

/// The slab test of a node's four boxes: a bit per child hit, and the entry distances.
/// SSE (baseline on x86-64): the same operations in the same order as the portable form
/// (`minps`/`maxps` return their second operand exactly where `vmin`/`vmax` do), so the
/// same children are visited.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn slab4(n: &Node4, r: &SlabRay, tmin: f32, tmax: f32) -> (u32, [f32; 4]) {
    use std::arch::x86_64::*;
    // SAFETY: SSE is part of the x86-64 baseline; the loads read [f32; 4] rows of the node
    // (row indices < 6 by construction in SlabRay::new) and the store writes a [f32; 4], all
    // unaligned-safe.
    unsafe {
        let row = |i: usize| n.b.get_unchecked(i).as_ptr();
        let slab = |i: usize, a: usize| {
            _mm_sub_ps(
                _mm_mul_ps(_mm_loadu_ps(row(i)), _mm_set1_ps(r.inv[a])),
                _mm_set1_ps(r.oi[a]),
            )
        };
        let (near, far) = (r.near, r.far);
        let t0 = _mm_max_ps(
            _mm_max_ps(slab(near[0], 0), slab(near[1], 1)),
            _mm_max_ps(slab(near[2], 2), _mm_set1_ps(tmin)),
        );
        let f = _mm_min_ps(
            _mm_min_ps(slab(far[0], 0), slab(far[1], 1)),
            slab(far[2], 2),
        );
        let t1 = _mm_min_ps(_mm_mul_ps(f, _mm_set1_ps(1.000_000_24)), _mm_set1_ps(tmax));
        let mask = _mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32;
        let mut out = [0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), t0);
        (mask, out)
    }
}

/// The slab test of a node's four boxes: a bit per child hit, and the entry distances.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn slab4(n: &Node4, r: &SlabRay, tmin: f32, tmax: f32) -> (u32, [f32; 4]) {
    let (inv, oi) = (r.inv, r.oi);
    let near = |a: usize| &n.b[r.near[a]];
    let far = |a: usize| &n.b[r.far[a]];
    let t0 = vmax(
        vmax(vslab(near(0), inv[0], oi[0]), vslab(near(1), inv[1], oi[1])),
        vmax(vslab(near(2), inv[2], oi[2]), [tmin; 4]),
    );
    let f = vmin(
        vmin(vslab(far(0), inv[0], oi[0]), vslab(far(1), inv[1], oi[1])),
        vslab(far(2), inv[2], oi[2]),
    );
    // Widened by 2 ulps (Ize 2013): a ray grazing a box face is never lost to rounding.
    let t1 = vmin(std::array::from_fn(|i| f[i] * 1.000_000_24), [tmax; 4]);
    let mut mask = 0;
    for i in 0..4 {
        mask |= u32::from(t0[i] <= t1[i]) << i;
    }
    (mask, t0)
}

/// A ray prepared for the watertight test (Woop, Benthin & Wald 2013): the axis where the
/// direction is largest becomes z, and a shear maps the ray onto the +z axis, so a triangle
/// test reduces to 2D edge functions that neighbouring triangles evaluate identically along
/// a shared edge (a ray can never slip between two triangles that share the edge's vertices).
#[derive(Clone, Copy)]
pub(crate) struct WtRay {
    pub(crate) o: Vec3,
    /// The axes that become x, y and z (a permutation of 0, 1, 2).
    pub(crate) k: [usize; 3],
    /// The shear: a vertex `v` maps to `(A[kx] − Sx A[kz], A[ky] − Sy A[kz], Sz A[kz])`
    /// with `A = v − o`.
    pub(crate) s: [f32; 3],
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

    /// A vertex in the ray's sheared frame: the same for every triangle sharing the vertex.
    /// (The four-quad test computes it with the same operations.)
    #[inline(always)]
    fn xform(&self, v: Vec3) -> [f32; 3] {
        let a = v - self.o;
        let [kx, ky, kz] = self.k;
        let az = a[kz];
        [
            a[kx] - self.s[0] * az,
            a[ky] - self.s[1] * az,
            self.s[2] * az,
        ]
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
pub(crate) fn intersect_quad_wt(
    p: [Vec3; 4],
    r: &WtRay,
    tmin: f32,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let [p00, p10, p01, p11] = p;
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
fn intersect_quad(p: [Vec3; 4], o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    intersect_quad_wt(p, &WtRay::new(o, d), tmin, tmax)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quad of its own four corners `v00 v10 v01 v11`, appended to `verts`.
    fn quad(verts: &mut Vec<Vec3>, p: [Vec3; 4], grid: u32) -> Quad {
        let k = verts.len() as u32;
        verts.extend(p);
        Quad {
            k,
            row: 2,
            grid,
            index: 0,
        }
    }

    fn square(verts: &mut Vec<Vec3>, z: f32, grid: u32) -> Quad {
        quad(
            verts,
            [
                Vec3::new(-1.0, -1.0, z),
                Vec3::new(1.0, -1.0, z),
                Vec3::new(-1.0, 1.0, z),
                Vec3::new(1.0, 1.0, z),
            ],
            grid,
        )
    }

    #[test]
    fn closest_hit_of_stacked_squares() {
        let mut verts = Vec::new();
        let quads: Vec<Quad> = (0..100)
            .map(|k| square(&mut verts, k as f32 + 1.0, k))
            .collect();
        let bvh = Bvh::build(quads, verts);
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

    /// Wavy grids sharing their corners (as diced micropolygons do), many rays: the tree's
    /// closest hit is the brute-force one, bit for bit (distance and coordinates), and
    /// `each_hit` reports every quad the brute force hits.
    #[test]
    fn closest_and_all_hits_match_brute_force_on_grids() {
        let mut h = 4242u32;
        let mut rnd = || {
            h = crate::pattern::hash::hash_u32(h);
            (h as f32 / u32::MAX as f32) * 2.0 - 1.0
        };
        let mut quads = Vec::new();
        let mut verts = Vec::new();
        for g in 0..12u32 {
            let (nu, nv) = (3 + (g as usize % 7), 2 + (g as usize % 5));
            let c = Vec3::new(rnd() * 3.0, rnd() * 3.0, rnd() * 3.0);
            let (du, dv) = (
                Vec3::new(rnd(), rnd(), rnd()),
                Vec3::new(rnd(), rnd(), rnd()),
            );
            let base = verts.len();
            for j in 0..nv {
                for i in 0..nu {
                    let (x, y) = (i as f32 / 4.0, j as f32 / 4.0);
                    verts.push(c + du * x + dv * y + Vec3::Z * (0.1 * (3.0 * x + y).sin()));
                }
            }
            for j in 0..nv - 1 {
                for i in 0..nu - 1 {
                    quads.push(Quad {
                        k: (base + j * nu + i) as u32,
                        row: nu as u32,
                        grid: g,
                        index: (j * (nu - 1) + i) as u32,
                    });
                }
            }
        }
        let bvh = Bvh::build(quads.clone(), verts.clone());
        let mut hits = 0;
        for r in 0..3000 {
            // Aimed near a random corner, so most rays hit (some through shared edges).
            let o = Vec3::new(rnd(), rnd(), rnd()) * 5.0;
            let target = verts[((rnd() * 0.5 + 0.5) * (verts.len() - 1) as f32) as usize];
            let jitter = Vec3::new(rnd(), rnd(), rnd()) * 0.1;
            let d = (target + jitter - o).normalize_or(Vec3::X);
            let tmax = if r % 5 == 0 { 4.0 } else { f32::INFINITY };
            let mut best: Option<(f32, f32, f32)> = None;
            let mut all = Vec::new();
            for q in &quads {
                if let Some(x) = intersect_quad(q.corners(&verts), o, d, 0.0, tmax) {
                    all.push((q.grid, q.index));
                    if best.is_none_or(|b| x.0 < b.0) {
                        best = Some(x);
                    }
                }
            }
            let got = bvh.closest(o, d, 0.0, tmax);
            let bits = |t: f32, a: f32, b: f32| (t.to_bits(), a.to_bits(), b.to_bits());
            assert_eq!(
                got.map(|g| bits(g.t, g.a, g.b)),
                best.map(|b| bits(b.0, b.1, b.2)),
                "ray {r}"
            );
            let mut each = Vec::new();
            bvh.each_hit(o, d, 0.0, tmax, &mut |h| {
                each.push((h.grid, h.index));
                false
            });
            each.sort_unstable();
            all.sort_unstable();
            assert_eq!(each, all, "ray {r}");
            hits += usize::from(got.is_some());
        }
        assert!(hits > 1000, "{hits} rays hit");
    }

    #[test]
    fn brute_force_agrees_on_a_random_soup() {
        let mut h = 12345u32;
        let mut rnd = || {
            h = crate::pattern::hash::hash_u32(h);
            (h as f32 / u32::MAX as f32) * 2.0 - 1.0
        };
        let mut quads = Vec::new();
        let mut verts = Vec::new();
        for k in 0..500 {
            let c = Vec3::new(rnd() * 5.0, rnd() * 5.0, rnd() * 5.0);
            let u = Vec3::new(rnd(), rnd(), rnd()) * 0.4;
            let v = Vec3::new(rnd(), rnd(), rnd()) * 0.4;
            quads.push(quad(&mut verts, [c, c + u, c + v, c + u + v], k));
        }
        let bvh = Bvh::build(quads.clone(), verts.clone());
        for _ in 0..300 {
            let o = Vec3::new(rnd(), rnd(), rnd()) * 6.0;
            let d = Vec3::new(rnd(), rnd(), rnd()).normalize_or(Vec3::X);
            let mut best: Option<(f32, u32)> = None;
            for q in &quads {
                if let Some((t, _, _)) = intersect_quad(q.corners(&verts), o, d, 0.0, 1e30) {
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
