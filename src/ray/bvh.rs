//! A compact binned-SAH bounding volume hierarchy over micropolygon quads.
//!
//! Input: quads (four corners each, as `v00 v10 v01 v11` of a diced grid, in a shared vertex
//! array) with the grid and quad index they came from. Output: closest-hit and all-hits
//! queries along a ray segment, and closest hits of many rays with their walks interleaved
//! (`interleave`).
//! Invariants: the build depends only on the input order, so the tree (and every hit) is the
//! same whatever the thread count (the binary tree's halves may be built on threads of their
//! own, `sah`); nodes are 8 wide (a binned-SAH binary
//! tree, 16 bins on each axis, collapsed so that each node holds the boxes of up to eight
//! children, tested together, as exact `f32` rows on three 64-byte cache lines, with the
//! children's indices on a fourth; leaves of up to 8 quads, their SAH cost counted in
//! groups of four, the groups the leaf test takes at once on x86-64, see `quad4`, each leaf
//! one block holding its quads' corners itself, see [`Bvh::leaves`]); a quad is
//! intersected, watertight, as the two triangles `(v00 v10 v11)` and `(v00 v11 v01)` and
//! reports bilinear-style coordinates `(a, b)` in `[0, 1]²` across the quad. Traversal visits
//! the nearest child in reach first (ties by lane), pushing the others farthest first.
//!
//! Why home-made rather than the `bvh` or `obvhs` crates: `bvh` is built on nalgebra (a
//! second linear-algebra crate beside glam) and its traversal returns a `Vec` of every shape
//! whose box the ray crosses (an allocation and no closest-hit pruning per ray); `obvhs` is
//! glam-based and fast (CWBVH, PLOC) but young (three 0.x releases within a year, API changed
//! each time) and brings its own dependency tree. A binned-SAH BVH8 with ordered traversal is
//! ~500 lines, deterministic by construction, and its leaves hold micropolygons with the
//! watertight test they need (see `benches/rays.rs` for its speed).

use glam::Vec3;

use super::memhint;

mod interleave;
mod sah;

pub use interleave::WalkStats;

/// One micropolygon given to [`Bvh::build`], its corners in the shared vertex array:
/// `v00 = verts[k]`, `v10 = verts[k + 1]`, `v01 = verts[k + row]`,
/// `v11 = verts[k + row + 1]` (a grid's points are stored once, row by row). The tree keeps
/// its own copy of each leaf's corners (see [`Bvh::leaves`]).
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

/// Children a node holds.
const WIDTH: usize = 8;

/// An 8-wide node in four 64-byte cache lines. The first three hold all the slab test
/// reads: the exact boxes of up to eight children side by side (lane `i` of each row), as
/// `f32` rows, so one ray tests all eight with the same few vector instructions (AVX2; two
/// SSE halves' worth otherwise) and no decoding. The fourth holds the children themselves,
/// read for those in reach.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node8 {
    /// The children's boxes: rows 0–2 the low x, y, z, rows 3–5 the high ones (an empty
    /// lane: +∞ low, −∞ high, and never visited anyway, see `valid`).
    b: [[f32; WIDTH]; 6],
    /// Interior child: node index. Leaf child: its block's first word in [`Bvh::leaves`].
    child: [u32; WIDTH],
    /// Leaf child: its quads (at most `MAX_LEAF`, low byte) and its block's words the walk
    /// reads (high byte, see [`Bvh::leaves`]); 0 for an interior child and an empty lane.
    count: [u16; WIDTH],
    /// A bit per lane holding a child (the others are never visited).
    valid: u8,
}

const _: () = assert!(
    std::mem::size_of::<Node8>() == 256
        && std::mem::offset_of!(Node8, child) == 192
        && MAX_LEAF <= u8::MAX as usize
);

impl Node8 {
    const EMPTY: Node8 = Node8 {
        b: [
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [0; WIDTH],
        count: [0; WIDTH],
        valid: 0,
    };
}

/// Which micropolygon a leaf's quad is (what a hit reports).
#[derive(Clone, Copy, Debug)]
pub struct QuadId {
    /// Index of the ray grid it belongs to.
    pub grid: u32,
    /// Quad index inside the grid.
    pub index: u32,
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
    nodes: Vec<Node8>,
    /// The leaves, a block of 32-bit words each, everything a leaf's test reads side by side
    /// (so a leaf visit is one dependent read, prefetched when its parent is visited, instead
    /// of the quad records and then the rows of the grid their corners lie in): per quad a
    /// word of its corners' numbers in the block's vertex list (bytes `v00 v10 v01 v11`, low
    /// first); the distinct corners of the leaf's quads (at most 32), `x y z` each, in the
    /// order the quads first name them; a padding word (the four-quad test loads 16 bytes a
    /// corner); then, read only on a hit, per quad its [`QuadId`] (two words). The corners
    /// are the input's floats bit for bit, so every hit is the one the shared vertex array
    /// gave; a leaf's quads come from one grid or two and share most corners, so the copies
    /// cost about what the shared array and the 16-byte quad records did.
    leaves: Vec<u32>,
    /// The root when the whole tree is one leaf (then `nodes` is empty): its `count` (see
    /// [`Node8::count`]); its block starts at word 0.
    root_leaf: u32,
}

/// A quad's corners' numbers in the shared vertex array: `v00 v10 v01 v11`.
#[inline]
fn quad_corners(q: &Quad) -> [usize; 4] {
    let (k, r) = (q.k as usize, q.row as usize);
    [k, k + 1, k + r, k + r + 1]
}

/// A leaf's vertex list: the distinct corners (below `len`) of its quads, in the order the
/// quads first name them.
fn leaf_vertices(quads: &[Quad], len: usize) -> Vec<usize> {
    let mut local: Vec<usize> = Vec::with_capacity(4 * quads.len());
    for g in quads.iter().flat_map(quad_corners) {
        if g < len && !local.contains(&g) {
            local.push(g);
        }
    }
    local
}

/// A leaf's corner `c` (its number in the leaf's vertex list), if in range.
#[inline(always)]
fn leaf_vertex(verts: &[f32], c: u8) -> Option<Vec3> {
    let f = 3 * c as usize;
    verts.get(f..f + 3).map(|v| Vec3::new(v[0], v[1], v[2]))
}

/// A leaf quad's corners `v00 v10 v01 v11` from its corner word (see [`Bvh::leaves`]); `None`
/// when one is out of range (such a quad is never hit).
#[inline]
pub(crate) fn leaf_corners(q: u32, verts: &[f32]) -> Option<[Vec3; 4]> {
    let [a, b, c, d] = q.to_le_bytes();
    Some([
        leaf_vertex(verts, a)?,
        leaf_vertex(verts, b)?,
        leaf_vertex(verts, c)?,
        leaf_vertex(verts, d)?,
    ])
}

/// The block's words as floats (the corners' bits).
#[inline(always)]
fn as_floats(w: &[u32]) -> &[f32] {
    // SAFETY: u32 and f32 have the same size and alignment, and every bit pattern is a
    // valid f32.
    unsafe { std::slice::from_raw_parts(w.as_ptr().cast::<f32>(), w.len()) }
}

/// A leaf's parts: the corner words, the corners' floats (with the padding) and the ids.
struct LeafBlock<'a> {
    quads: &'a [u32],
    verts: &'a [f32],
    ids: &'a [u32],
}

impl LeafBlock<'_> {
    #[inline(always)]
    fn id(&self, q: usize) -> QuadId {
        QuadId {
            grid: self.ids.get(2 * q).copied().unwrap_or(0),
            index: self.ids.get(2 * q + 1).copied().unwrap_or(0),
        }
    }
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

/// A node of the binary tree built first (then collapsed to 8-wide nodes).
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
    /// in place; `sah`, its large halves on threads of their own up to rayon's thread count),
    /// collapsed into 8-wide nodes. A function of the input order alone (see the module
    /// invariants).
    pub fn build(quads: Vec<Quad>, verts: Vec<Vec3>) -> Bvh {
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
        let (nodes, order) = sah::build(&boxes, rayon::current_num_threads());
        drop(boxes);
        let sorted: Vec<Quad> = order.iter().map(|&k| quads[k as usize]).collect();
        drop((quads, order));
        // The walks read the nodes and leaves at random: on huge pages where the system
        // allows (see `memhint`), the leaves' room reserved at their exact size (a huge
        // page is resident whole once touched).
        let words: usize = nodes
            .iter()
            .filter(|b| b.count > 0)
            .map(|b| {
                let (s, c) = (b.first as usize, b.count as usize);
                3 * c + 3 * leaf_vertices(&sorted[s..s + c], verts.len()).len() + 1
            })
            .sum();
        let mut bvh = Bvh {
            nodes: memhint::huge_vec(nodes.len() / 2 + 1),
            leaves: memhint::huge_vec(words),
            root_leaf: 0,
        };
        if nodes[0].count > 0 {
            bvh.root_leaf = u32::from(bvh.push_leaf(&sorted, &verts));
        } else {
            bvh.collapse(&nodes, 0, &sorted, &verts);
        }
        bvh
    }

    /// Appends the block of a leaf of `quads` (see [`Bvh::leaves`]); returns its `count`.
    fn push_leaf(&mut self, quads: &[Quad], verts: &[Vec3]) -> u16 {
        let local = leaf_vertices(quads, verts.len());
        for q in quads {
            let c = quad_corners(q).map(|g| {
                // Out of range: a number past the list, so the quad is never hit.
                local
                    .iter()
                    .position(|&x| x == g)
                    .map_or(u8::MAX, |at| at as u8)
            });
            self.leaves.push(u32::from_le_bytes(c));
        }
        for &g in &local {
            self.leaves.extend(verts[g].to_array().map(f32::to_bits));
        }
        self.leaves.push(0);
        for q in quads {
            self.leaves.extend([q.grid, q.index]);
        }
        let walk = quads.len() + 3 * local.len() + 1;
        (quads.len() | walk << 8) as u16
    }

    /// The block of the leaf at word `first` with `count` (see [`Node8::count`]).
    #[inline(always)]
    fn block(&self, first: u32, count: u32) -> Option<LeafBlock<'_>> {
        let (q, walk) = ((count & 0xff) as usize, (count >> 8) as usize);
        let s = first as usize;
        let b = self.leaves.get(s..s + walk + 2 * q)?;
        Some(LeafBlock {
            quads: b.get(..q)?,
            verts: as_floats(b.get(q..walk)?),
            ids: &b[walk..],
        })
    }

    /// Makes the 8-wide node for binary interior node `i` (children first-come first-placed:
    /// the root is node 0); returns its index.
    fn collapse(&mut self, nodes: &[Node2], i: usize, quads: &[Quad], verts: &[Vec3]) -> u32 {
        // Open the interior child with the largest box until there are eight.
        let mut kids: Vec<usize> = vec![nodes[i].first as usize, nodes[i].first as usize + 1];
        while kids.len() < WIDTH {
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
        self.nodes.push(Node8::EMPTY);
        let mut node = Node8::EMPTY;
        for (lane, &k) in kids.iter().enumerate() {
            let c = &nodes[k];
            for axis in 0..3 {
                node.b[axis][lane] = c.bb.min[axis];
                node.b[3 + axis][lane] = c.bb.max[axis];
            }
            node.valid |= 1 << lane;
            if c.count > 0 {
                let s = c.first as usize;
                node.child[lane] = self.leaves.len() as u32;
                node.count[lane] = self.push_leaf(&quads[s..s + c.count as usize], verts);
            } else {
                node.child[lane] = self.collapse(nodes, k, quads, verts);
                node.count[lane] = 0;
            }
        }
        self.nodes[me] = node;
        me as u32
    }

    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// The closest hit with `tmin < t < tmax`.
    pub fn closest(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut tmax = tmax;
        self.walk::<true>(
            o,
            d,
            tmin,
            &mut tmax,
            &mut |q: QuadId, hit_t, a, b, tmax_ref| {
                *tmax_ref = hit_t;
                best = Some(Hit {
                    t: hit_t,
                    grid: q.grid,
                    index: q.index,
                    a,
                    b,
                });
                false
            },
        );
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
    /// (`AVX2` is for the x86-64 form's sake.)
    #[cfg(not(target_arch = "x86_64"))]
    #[inline]
    fn leaf<const AVX2: bool>(
        &self,
        first: u32,
        count: u32,
        ray: &LeafRay,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(QuadId, f32, f32, f32, &mut f32) -> bool,
    ) -> bool {
        let Some(b) = self.block(first, count) else {
            return false;
        };
        for (l, &q) in b.quads.iter().enumerate() {
            let Some(p) = leaf_corners(q, b.verts) else {
                continue;
            };
            if let Some((t, a, bb)) = intersect_quad_wt(p, &ray.wt, tmin, *tmax) {
                if on_hit(b.id(l), t, a, bb, tmax) {
                    return true;
                }
            }
        }
        false
    }

    /// Tests the quads of a leaf, four at a time (see `quad4::leaf`); true when `on_hit`
    /// asked to stop. `AVX2`: the caller runs code compiled for AVX2 (only where the CPU has
    /// it), so the test is called in its AVX form directly, and this block is inlined into
    /// the walk (no call of its own, no run-time check of the CPU).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn leaf<const AVX2: bool>(
        &self,
        first: u32,
        count: u32,
        ray: &LeafRay,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(QuadId, f32, f32, f32, &mut f32) -> bool,
    ) -> bool {
        let Some(b) = self.block(first, count) else {
            return false;
        };
        let on = &mut |l, t, a, bb, tm: &mut f32| on_hit(b.id(l), t, a, bb, tm);
        if AVX2 {
            // SAFETY: `AVX2` is only set in code run where the CPU has AVX2 (hence AVX).
            unsafe {
                super::quad4::leaf_avx_known(b.quads, b.verts, &ray.w4, &ray.wt, tmin, tmax, on)
            }
        } else {
            super::quad4::leaf(b.quads, b.verts, &ray.w4, &ray.wt, tmin, tmax, on)
        }
    }

    /// Asks for the cache lines of a pushed child (an interior node's four, or a leaf's
    /// block: the part its test reads and the ids, read on a hit, which otherwise were a
    /// miss the walk waited for; rays bench, medians of 5 interleaved pairs: 2.41 → 2.46 M
    /// shaded, 3.07 → 3.12 M shadow rays/s): a later visit then finds them on the way. No
    /// effect on results.
    #[inline(always)]
    fn prefetch(&self, child: u32, count: u32) {
        if count == 0 {
            let p = self
                .nodes
                .as_ptr()
                .wrapping_add(child as usize)
                .cast::<u8>();
            for line in 0..4 {
                memhint::prefetch(p.wrapping_add(64 * line));
            }
        } else {
            let p = self.leaves.as_ptr().wrapping_add(child as usize);
            memhint::prefetch_span(p, (count >> 8) as usize + 2 * (count & 0xff) as usize);
        }
    }

    /// Visits node `n`: pushes the children in reach other than the one to visit now
    /// (farthest first, each prefetched) and returns that one as (child, quad count), if
    /// any. With `ORDERED` the nearest child in reach is visited first (ties by lane).
    /// `AVX2`: the slab test in AVX2 (only where the CPU has it; the same results).
    #[inline(always)]
    fn visit<const ORDERED: bool, const AVX2: bool>(
        &self,
        n: &Node8,
        rb: &SlabRay,
        tmin: f32,
        tmax: f32,
        stack: &mut Stack,
    ) -> Option<(u32, u32)> {
        let (mask, tnear) = slab8::<AVX2>(n, rb, tmin, tmax);
        let first = if mask == 0 {
            return None;
        } else if mask & (mask - 1) == 0 {
            // One child in reach (the common case deep in the tree): no ordering.
            mask.trailing_zeros() as usize & 7
        } else if {
            // Exactly two (without a population count: not in the baseline instruction set).
            let rest = mask & (mask - 1);
            rest & (rest - 1) == 0
        } {
            // Two (most of the rest): one comparison of the sort keys below, (distance
            // bits, lane); the farther one is pushed.
            let i = mask.trailing_zeros() as usize & 7;
            let j = (mask & (mask - 1)).trailing_zeros() as usize & 7;
            let (near, far) = if ORDERED && tnear[j].to_bits() < tnear[i].to_bits() {
                (j, i)
            } else {
                (i, j)
            };
            let e = (n.child[far], u32::from(n.count[far]), tnear[far]);
            self.prefetch(e.0, e.1);
            stack.push(e);
            near
        } else {
            // Sort keys: the entry distance's bits (distances are ≥ tmin ≥ 0, whose bits
            // order as the numbers do) above the lane when `ordered`, the lane alone
            // otherwise; an insertion sort of the lanes in reach (three or four, usually).
            let mut key = [0u64; WIDTH];
            let mut c = 0;
            let mut m = mask;
            while m != 0 {
                let i = m.trailing_zeros() as usize & 7;
                m &= m - 1;
                let k = if ORDERED {
                    u64::from(tnear[i].to_bits()) << 3 | i as u64
                } else {
                    i as u64
                };
                let mut j = c;
                while j > 0 && key[j - 1] > k {
                    key[j] = key[j - 1];
                    j -= 1;
                }
                key[j] = k;
                c += 1;
            }
            // Push all but the first, farthest first; visit the first now (as if pushed
            // and popped at once: the same order).
            for &kk in key[1..c].iter().rev() {
                let i = (kk & 7) as usize;
                let e = (n.child[i], u32::from(n.count[i]), tnear[i]);
                self.prefetch(e.0, e.1);
                stack.push(e);
            }
            (key[0] & 7) as usize
        };
        Some((n.child[first], u32::from(n.count[first])))
    }

    /// Traversal, nearest child first when `ordered`. `on_hit(quad, t, a, b, &mut tmax)` may
    /// shrink `tmax`; returning true stops the walk. Compiled for AVX2 where the CPU has it
    /// (no FMA: the same bits).
    fn walk<const ORDERED: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(QuadId, f32, f32, f32, &mut f32) -> bool,
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 was detected just above.
            unsafe { self.walk_avx2::<ORDERED>(o, d, tmin, tmax, on_hit) };
            return;
        }
        self.walk_with::<ORDERED, false>(o, d, tmin, tmax, on_hit);
    }

    /// [`Bvh::walk_with`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn walk_avx2<const ORDERED: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(QuadId, f32, f32, f32, &mut f32) -> bool,
    ) {
        self.walk_with::<ORDERED, true>(o, d, tmin, tmax, on_hit);
    }

    /// The body of [`Bvh::walk`].
    #[inline(always)]
    fn walk_with<const ORDERED: bool, const AVX2: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: &mut f32,
        on_hit: &mut dyn FnMut(QuadId, f32, f32, f32, &mut f32) -> bool,
    ) {
        if self.leaves.is_empty() {
            return;
        }
        let wt = LeafRay::new_known::<AVX2>(o, d);
        if self.nodes.is_empty() {
            self.leaf::<AVX2>(0, self.root_leaf, &wt, tmin, tmax, on_hit);
            return;
        }
        let rb = SlabRay::new(o, d);
        let mut stack = Stack::new();
        let mut cur = 0u32;
        loop {
            let n = &self.nodes[cur as usize];
            if let Some((c, count)) = self.visit::<ORDERED, AVX2>(n, &rb, tmin, *tmax, &mut stack) {
                if count == 0 {
                    cur = c;
                    continue;
                }
                if self.leaf::<AVX2>(c, count, &wt, tmin, tmax, on_hit) {
                    return;
                }
            }
            // Pop: leaves are tested as they come; the first interior node still in reach
            // is visited next.
            loop {
                let Some((c, count, t)) = stack.pop() else {
                    return;
                };
                if t > *tmax {
                    continue;
                }
                if count > 0 {
                    if self.leaf::<AVX2>(c, count, &wt, tmin, tmax, on_hit) {
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

/// The pending children of a walk: (child, quad count (0: interior), entry distance), last
/// in first out. Deeper than the array (a degenerate tree), they spill to the heap.
struct Stack {
    /// Not initialised: only entries below `sp` are ever read (no memset per ray).
    items: [std::mem::MaybeUninit<(u32, u32, f32)>; 64],
    sp: usize,
    spill: Vec<(u32, u32, f32)>,
}

impl Stack {
    #[inline(always)]
    fn new() -> Stack {
        Stack {
            items: [std::mem::MaybeUninit::uninit(); 64],
            sp: 0,
            spill: Vec::new(),
        }
    }
    #[inline(always)]
    fn clear(&mut self) {
        self.sp = 0;
        self.spill.clear();
    }
    #[inline(always)]
    fn push(&mut self, e: (u32, u32, f32)) {
        if self.sp < self.items.len() {
            // SAFETY: `sp` is in bounds (just checked).
            unsafe { self.items.get_unchecked_mut(self.sp).write(e) };
            self.sp += 1;
        } else {
            self.spill.push(e);
        }
    }
    /// Entries pending.
    #[inline(always)]
    fn len(&self) -> usize {
        self.sp + self.spill.len()
    }
    /// The spill holds entries only while the array is full, so a stack below that (all
    /// walks but a degenerate tree's) never looks at it.
    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, u32, f32)> {
        if self.sp == self.items.len() {
            if let Some(e) = self.spill.pop() {
                return Some(e);
            }
        }
        if self.sp == 0 {
            return None;
        }
        self.sp -= 1;
        // SAFETY: `sp` is in bounds and entries below it were written by `push`.
        Some(unsafe { self.items.get_unchecked(self.sp).assume_init() })
    }
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

    /// [`LeafRay::new`] where the caller knows whether the CPU has AVX2 (`AVX2`: it runs
    /// code compiled for it), sparing the run-time check at every ray's start.
    #[inline(always)]
    fn new_known<const AVX2: bool>(o: Vec3, d: Vec3) -> LeafRay {
        let wt = WtRay::new(o, d);
        LeafRay {
            #[cfg(target_arch = "x86_64")]
            w4: if AVX2 {
                super::quad4::WtRay4::with_avx(&wt, true)
            } else {
                super::quad4::WtRay4::new(&wt)
            },
            wt,
        }
    }
}

/// A ray prepared for the slab test: the reciprocal direction, the origin scaled by it (a
/// plane `p` is crossed at `p · inv − oi`), and per axis which of a node's rows holds the
/// near sides and which the far ones (chosen once per ray by the direction's sign).
struct SlabRay {
    inv: [f32; 3],
    oi: [f32; 3],
    /// Byte offsets in [`Node8::b`] of the rows the ray enters by (x, y, z) and leaves by
    /// (x, y, z): the low sides' rows where the reciprocal is positive, the high ones' where
    /// it is negative.
    row: [u32; 6],
}

impl SlabRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> SlabRay {
        // A zero component becomes a tiny one of its sign: its reciprocal stays finite.
        let safe = |x: f32| {
            if x.abs() < 1e-30 {
                1e-30f32.copysign(x)
            } else {
                x
            }
        };
        let inv = [1.0 / safe(d.x), 1.0 / safe(d.y), 1.0 / safe(d.z)];
        let oi = [o.x * inv[0], o.y * inv[1], o.z * inv[2]];
        const ROW: u32 = (4 * WIDTH) as u32;
        let near = |a: usize| ROW * (a as u32 + 3 * u32::from(inv[a].is_sign_negative()));
        let far = |a: usize| ROW * (a as u32 + 3 * u32::from(!inv[a].is_sign_negative()));
        SlabRay {
            inv,
            oi,
            row: [near(0), near(1), near(2), far(0), far(1), far(2)],
        }
    }
}

/// The slab test of a node's eight boxes: a bit per child hit, and the entry distances.
/// `AVX2` (only where the CPU has it) runs it as eight-lane vectors: the same operations in
/// the same order as the portable form (`vminps`/`vmaxps` return their second operand
/// exactly where `vmin`/`vmax` do), so the same children are visited.
///
/// Each box side is crossed at `p · inv − oi` (rounded monotonically in `p`). Per axis the
/// near side is the low one where the direction is positive and the high one where it is
/// negative (for a box with `lo ≤ hi` the smaller crossing, as a `min` of the two would
/// give; empty lanes are masked out by the node's `valid` bits), the far side the other.
#[inline(always)]
fn slab8<const AVX2: bool>(n: &Node8, r: &SlabRay, tmin: f32, tmax: f32) -> (u32, [f32; WIDTH]) {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is only set in code compiled for (and run where the CPU has) AVX2.
        return unsafe { slab8_avx2(n, r, tmin, tmax) };
    }
    slab8_portable(n, r, tmin, tmax)
}

/// [`slab8`] in AVX2 intrinsics (the caller makes sure the CPU has AVX2).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn slab8_avx2(n: &Node8, r: &SlabRay, tmin: f32, tmax: f32) -> (u32, [f32; WIDTH]) {
    use std::arch::x86_64::*;
    let base: *const u8 = n.b.as_ptr().cast();
    let cross = |k: usize, a: usize| {
        // SAFETY: `row[k]` is the offset of one of the six 32-byte rows of `b` (see
        // `SlabRay::new`), 32-byte aligned in the 64-byte aligned node.
        let p = _mm256_load_ps(base.add(r.row[k] as usize).cast());
        _mm256_sub_ps(
            _mm256_mul_ps(p, _mm256_set1_ps(r.inv[a])),
            _mm256_set1_ps(r.oi[a]),
        )
    };
    let (nx, ny, nz) = (cross(0, 0), cross(1, 1), cross(2, 2));
    let (fx, fy, fz) = (cross(3, 0), cross(4, 1), cross(5, 2));
    let t0 = _mm256_max_ps(
        _mm256_max_ps(nx, ny),
        _mm256_max_ps(nz, _mm256_set1_ps(tmin)),
    );
    let f = _mm256_min_ps(_mm256_min_ps(fx, fy), fz);
    let t1 = _mm256_min_ps(
        _mm256_mul_ps(f, _mm256_set1_ps(1.000_000_24)),
        _mm256_set1_ps(tmax),
    );
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32 & u32::from(n.valid);
    let mut out = [0f32; WIDTH];
    _mm256_storeu_ps(out.as_mut_ptr(), t0);
    (mask, out)
}

/// Lane-wise minimum and maximum, written so they compile to `minps`/`maxps`.
#[inline(always)]
fn vmin(a: [f32; WIDTH], b: [f32; WIDTH]) -> [f32; WIDTH] {
    std::array::from_fn(|i| if a[i] < b[i] { a[i] } else { b[i] })
}
#[inline(always)]
fn vmax(a: [f32; WIDTH], b: [f32; WIDTH]) -> [f32; WIDTH] {
    std::array::from_fn(|i| if a[i] > b[i] { a[i] } else { b[i] })
}

/// [`slab8`] lane by lane.
#[inline(always)]
fn slab8_portable(n: &Node8, r: &SlabRay, tmin: f32, tmax: f32) -> (u32, [f32; WIDTH]) {
    let cross = |k: usize, a: usize| -> [f32; WIDTH] {
        // (`row[k] / 32` is a row index below 6 by construction; the `% 6` only spares a
        // bounds check.)
        let p = &n.b[(r.row[k] as usize / (4 * WIDTH)) % 6];
        std::array::from_fn(|i| p[i] * r.inv[a] - r.oi[a])
    };
    let (nx, ny, nz) = (cross(0, 0), cross(1, 1), cross(2, 2));
    let (fx, fy, fz) = (cross(3, 0), cross(4, 1), cross(5, 2));
    let t0 = vmax(vmax(nx, ny), vmax(nz, [tmin; WIDTH]));
    let f = vmin(vmin(fx, fy), fz);
    // Widened by 2 ulps (Ize 2013): a ray grazing a box face is never lost to rounding.
    let t1 = vmin(std::array::from_fn(|i| f[i] * 1.000_000_24), [tmax; WIDTH]);
    let mut mask = 0;
    for i in 0..WIDTH {
        mask |= u32::from(t0[i] <= t1[i]) << i;
    }
    (mask & u32::from(n.valid), t0)
}

/// A ray prepared for the watertight test (Woop, Benthin & Wald 2013): the axis where the
/// direction is largest becomes z, and a shear maps the ray onto the +z axis, so a triangle
/// test reduces to 2D edge functions that neighbouring triangles evaluate identically along
/// a shared edge (a ray can never slip between two triangles that share the edge's vertices).
#[derive(Clone, Copy)]
pub(crate) struct WtRay {
    pub(crate) o: Vec3,
    /// The axes that become x, y and z (a permutation of 0, 1, 2) as its place in
    /// [`WtRay::PERMS`], `2 kz + swapped` (see [`WtRay::k`]): the leaf test dispatches on it
    /// with one table jump instead of comparing whole arrays, and the ray is smaller to set
    /// up and copy.
    pub(crate) perm: u8,
    /// The shear: a vertex `v` maps to `(A[kx] − Sx A[kz], A[ky] − Sy A[kz], Sz A[kz])`
    /// with `A = v − o`.
    pub(crate) s: [f32; 3],
}

impl WtRay {
    /// The axis permutations `[kx, ky, kz]`, numbered `2 kz + swapped` (x and y swapped for
    /// a negative dominant component).
    pub(crate) const PERMS: [[usize; 3]; 6] = [
        [1, 2, 0],
        [2, 1, 0],
        [2, 0, 1],
        [0, 2, 1],
        [0, 1, 2],
        [1, 0, 2],
    ];

    /// The axes that become x, y and z.
    #[inline(always)]
    pub(crate) fn k(&self) -> [usize; 3] {
        WtRay::PERMS[usize::from(self.perm) % 6]
    }

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
        // (kz + 1) % 3 and (kz + 2) % 3, without the divisions' remainders.
        let mut kx = [1, 2, 0][kz];
        let mut ky = [2, 0, 1][kz];
        let swapped = d[kz] < 0.0;
        if swapped {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = if d[kz] == 0.0 { 1e-30 } else { d[kz] };
        WtRay {
            o,
            perm: 2 * kz as u8 + u8::from(swapped),
            s: [d[kx] / dz, d[ky] / dz, 1.0 / dz],
        }
    }

    /// A vertex in the ray's sheared frame: the same for every triangle sharing the vertex.
    /// (The four-quad test computes it with the same operations.)
    #[inline(always)]
    fn xform(&self, v: Vec3) -> [f32; 3] {
        let a = v - self.o;
        let [kx, ky, kz] = self.k();
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
    /// Repeatable numbers in [-1, 1) from `seed`.
    fn signed_rng(seed: u32) -> impl FnMut() -> f32 {
        let mut h = seed;
        move || {
            h = crate::pattern::hash::hash_u32(h);
            (h as f32 / u32::MAX as f32) * 2.0 - 1.0
        }
    }

    /// `n` random quads (parallelograms) centred within ±`spread`, edges up to `size` long.
    fn random_soup(
        rnd: &mut impl FnMut() -> f32,
        n: u32,
        spread: f32,
        size: f32,
    ) -> (Vec<Quad>, Vec<Vec3>) {
        let (mut quads, mut verts) = (Vec::new(), Vec::new());
        for k in 0..n {
            let c = Vec3::new(rnd(), rnd(), rnd()) * spread;
            let u = Vec3::new(rnd(), rnd(), rnd()) * size;
            let v = Vec3::new(rnd(), rnd(), rnd()) * size;
            quads.push(quad(&mut verts, [c, c + u, c + v, c + u + v], k));
        }
        (quads, verts)
    }

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
    fn the_tree_is_the_same_for_any_thread_count() {
        // Large enough for the halves under the root to be built on threads of their own.
        let mut rnd = signed_rng(7);
        let mut cases = vec![random_soup(&mut rnd, 5000, 50.0, 1.0)];
        cases.push(random_soup(&mut rnd, 200_000, 100.0, 2.0));
        // A field of grids: shared corners, flat grids (an axis of no extent), and a run of
        // copies of one quad (coincident centroids).
        let (mut quads, mut verts) = (Vec::new(), Vec::new());
        for g in 0..40u32 {
            let (base, side) = (verts.len() as u32, 60u32);
            for j in 0..side {
                for i in 0..side {
                    let z = if g % 3 == 0 { 0.0 } else { (i as f32).sin() };
                    verts.push(Vec3::new(
                        i as f32 * 0.1 + g as f32 * 7.0,
                        j as f32 * 0.1,
                        z,
                    ));
                }
            }
            for j in 0..side - 1 {
                for i in 0..side - 1 {
                    let (k, index) = (base + j * side + i, j * (side - 1) + i);
                    quads.push(Quad {
                        k,
                        row: side,
                        grid: g,
                        index,
                    });
                }
            }
        }
        quads.extend(std::iter::repeat(quads[5]).take(300));
        cases.push((quads, verts));
        for (quads, verts) in &cases {
            let built = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
                let tree = pool
                    .unwrap()
                    .install(|| Bvh::build(quads.clone(), verts.clone()));
                (format!("{:?}", tree.nodes), tree.leaves, tree.root_leaf)
            };
            let one = built(1);
            for threads in [2, 3, 8] {
                assert!(
                    built(threads) == one,
                    "{} quads, {threads} threads",
                    quads.len()
                );
            }
        }
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
        let mut rnd = signed_rng(4242u32);
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
        let mut rays = Vec::new();
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
            rays.push((o, d, tmax));
        }
        assert!(hits > 1000, "{hits} rays hit");
        // The interleaved walks give each ray's single walk, bit for bit (batches of each
        // tmax, more rays than lanes, and a partial last round).
        for tmax in [4.0, f32::INFINITY] {
            let (o, d): (Vec<Vec3>, Vec<Vec3>) = rays
                .iter()
                .filter(|r| r.2 == tmax)
                .map(|r| (r.0, r.1))
                .unzip();
            let tmin: Vec<f32> = (0..o.len()).map(|k| (k % 3) as f32 * 0.5).collect();
            let mut out = vec![None; o.len()];
            bvh.closest_many(&o, &d, &tmin, tmax, &mut out);
            for k in 0..o.len() {
                assert_eq!(out[k], bvh.closest(o[k], d[k], tmin[k], tmax), "ray {k}");
            }
        }
        // The interleaved any-hit walks call back each ray's lone `each_hit` hits in the same
        // order, bit for bit, and stop where it stops (ray k asks to stop at its
        // (k mod 4)-th hit, never for k mod 4 = 0; tmin and tmax vary by ray).
        let o: Vec<Vec3> = rays.iter().map(|r| r.0).collect();
        let d: Vec<Vec3> = rays.iter().map(|r| r.1).collect();
        let tmin: Vec<f32> = (0..o.len()).map(|k| (k % 3) as f32 * 0.5).collect();
        let tmax: Vec<f32> = rays.iter().map(|r| r.2).collect();
        let stop_at = |k: usize| k % 4;
        let bits = |h: &Hit| (h.t.to_bits(), h.grid, h.index, h.a.to_bits(), h.b.to_bits());
        let mut many: Vec<Vec<_>> = vec![Vec::new(); o.len()];
        // (A tree this small is walked one ray at a time by `each_hit_many`: test the
        // interleaved walks themselves.)
        bvh.each_hit_interleaved(&o, &d, &tmin, &tmax, &mut |k, h| {
            many[k].push(bits(&h));
            many[k].len() == stop_at(k)
        });
        let (mut multi, mut stopped) = (0, 0);
        for k in 0..o.len() {
            let mut lone = Vec::new();
            bvh.each_hit(o[k], d[k], tmin[k], tmax[k], &mut |h| {
                lone.push(bits(&h));
                lone.len() == stop_at(k)
            });
            assert_eq!(many[k], lone, "ray {k}");
            multi += usize::from(lone.len() > 1);
            stopped += usize::from(stop_at(k) > 0 && lone.len() == stop_at(k));
        }
        assert!(
            multi > 60 && stopped > 300,
            "{multi} rays with several hits, {stopped} stopped"
        );
    }

    /// A leaf holds its quads' corners itself, each shared corner once: a 2 × 2 patch of a
    /// grid (four quads, nine corners) is one block of 4 + 27 + 1 words the walk reads and
    /// two ids a quad, and its hits are those of the shared array, bit for bit.
    #[test]
    fn leaf_blocks_hold_each_shared_corner_once() {
        let mut verts = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                verts.push(Vec3::new(i as f32, j as f32, 0.1 * (i * j) as f32));
            }
        }
        let quads: Vec<Quad> = (0..2u32)
            .flat_map(|j| {
                (0..2u32).map(move |i| Quad {
                    k: j * 3 + i,
                    row: 3,
                    grid: 7,
                    index: j * 2 + i,
                })
            })
            .collect();
        let bvh = Bvh::build(quads.clone(), verts.clone());
        assert!(bvh.nodes.is_empty());
        let b = bvh.block(0, bvh.root_leaf).unwrap();
        assert_eq!((b.quads.len(), b.verts.len(), b.ids.len()), (4, 28, 8));
        assert_eq!(bvh.leaves.len(), 4 + 28 + 8);
        let mut ids: Vec<(u32, u32)> = (0..4).map(|l| (b.id(l).grid, b.id(l).index)).collect();
        ids.sort_unstable();
        assert_eq!(ids, vec![(7, 0), (7, 1), (7, 2), (7, 3)]);
        for l in 0..4 {
            let c = leaf_corners(b.quads[l], b.verts).unwrap();
            assert!(quads.iter().any(|q| q.corners(&verts) == c));
        }
        let bits = |h: Option<Hit>| {
            h.map(|h| (h.t.to_bits(), h.grid, h.index, h.a.to_bits(), h.b.to_bits()))
        };
        let mut hits = 0;
        for (x, y) in [
            (0.5, 0.5),
            (1.5, 0.25),
            (1.0, 0.7),
            (0.3, 1.0),
            (1.0, 1.0),
            (1.9, 1.9),
        ] {
            let (o, d) = (Vec3::new(x, y, 3.0), Vec3::new(0.01, -0.02, -1.0));
            let mut want: Option<Hit> = None;
            for q in &quads {
                if let Some((t, a, bb)) = intersect_quad(q.corners(&verts), o, d, 0.0, 1e30) {
                    if want.is_none_or(|w| t < w.t) {
                        want = Some(Hit {
                            t,
                            grid: q.grid,
                            index: q.index,
                            a,
                            b: bb,
                        });
                    }
                }
            }
            let got = bvh.closest(o, d, 0.0, 1e30);
            assert_eq!(bits(got), bits(want), "ray at ({x}, {y})");
            hits += usize::from(got.is_some());
        }
        assert_eq!(hits, 6);
    }

    /// The exact box of the quads under lane `lane` of node `n`, checked (recursively) to be
    /// the box stored for that lane on the way down (enclosing its quads, and no larger).
    fn enclosed(bvh: &Bvh, n: usize, lane: usize) -> Aabb {
        let node = &bvh.nodes[n];
        let mut exact = Aabb::EMPTY;
        if node.count[lane] > 0 {
            let b = bvh
                .block(node.child[lane], u32::from(node.count[lane]))
                .unwrap();
            assert_eq!(b.quads.len(), usize::from(node.count[lane] & 0xff));
            for &q in b.quads {
                for p in leaf_corners(q, b.verts).unwrap() {
                    exact.grow_point(p);
                }
            }
        } else {
            let c = node.child[lane] as usize;
            for l in 0..WIDTH {
                if bvh.nodes[c].valid & (1 << l) != 0 {
                    exact.grow(&enclosed(bvh, c, l));
                }
            }
        }
        for a in 0..3 {
            let (lo, hi) = (node.b[a][lane], node.b[3 + a][lane]);
            assert!(
                lo <= exact.min[a] && hi >= exact.max[a],
                "node {n} lane {lane} axis {a}: box does not enclose its quads"
            );
            assert_eq!(
                (lo.to_bits(), hi.to_bits()),
                (exact.min[a].to_bits(), exact.max[a].to_bits()),
                "node {n} lane {lane} axis {a}: box not tight"
            );
        }
        exact
    }

    /// Every child's stored box is the exact box of the quads under it, in a tree over
    /// quads from tiny to huge, flat ones and ones far from the origin; empty lanes are
    /// empty boxes and not valid.
    #[test]
    fn child_boxes_are_the_exact_boxes_of_their_quads() {
        let mut h = 99u32;
        let mut rnd = || {
            h = crate::pattern::hash::hash_u32(h);
            h as f32 / u32::MAX as f32 - 0.5
        };
        let mut quads = Vec::new();
        let mut verts = Vec::new();
        for k in 0..3000u32 {
            let size = 10f32.powi((k % 13) as i32 - 6);
            let far = if k % 7 == 0 { 1e6 } else { 1.0 };
            let c = Vec3::new(rnd(), rnd(), rnd()) * 100.0 * far;
            let u = Vec3::new(rnd(), rnd(), rnd()) * size;
            // Every fifth quad flat in z (an axis-aligned micropolygon).
            let v = Vec3::new(rnd(), rnd(), if k % 5 == 0 { 0.0 } else { rnd() }) * size;
            let u = if k % 5 == 0 {
                Vec3::new(u.x, u.y, 0.0)
            } else {
                u
            };
            quads.push(quad(&mut verts, [c, c + u, c + v, c + u + v], k));
        }
        let bvh = Bvh::build(quads, verts);
        assert!(bvh.nodes.len() > 100);
        let mut total = Aabb::EMPTY;
        for l in 0..WIDTH {
            if bvh.nodes[0].valid & (1 << l) != 0 {
                total.grow(&enclosed(&bvh, 0, l));
            }
        }
        assert!(total.max.x - total.min.x > 1e7);
        for node in &bvh.nodes {
            for l in 0..WIDTH {
                if node.valid & (1 << l) == 0 {
                    assert!((0..3).all(|a| node.b[a][l] > node.b[3 + a][l]));
                }
            }
        }
    }

    /// The AVX2 slab test gives the portable one's mask and entry distances bit for bit, on
    /// every node of a tree and rays from inside and outside it (some axis-aligned).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn vector_slab_test_is_the_portable_one() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rnd = signed_rng(31u32);
        let (quads, verts) = random_soup(&mut rnd, 2000, 20.0, 0.5);
        let bvh = Bvh::build(quads, verts);
        assert!(bvh.nodes.len() > 30);
        let mut hits = 0;
        for r in 0..400 {
            let o = Vec3::new(rnd(), rnd(), rnd()) * 30.0;
            let mut d = Vec3::new(rnd(), rnd(), rnd());
            if r % 7 == 0 {
                d.y = 0.0;
            } else if r % 11 == 0 {
                // (A negative zero: the high sides are the near ones.)
                d.x = -0.0;
            }
            let ray = SlabRay::new(o, d);
            let (tmin, tmax) = if r % 3 == 0 {
                (0.5, 20.0)
            } else {
                (0.0, f32::INFINITY)
            };
            for n in &bvh.nodes {
                let (m0, t0) = slab8::<false>(n, &ray, tmin, tmax);
                // SAFETY: AVX2 was detected above.
                let (m1, t1) = unsafe { slab8_avx2(n, &ray, tmin, tmax) };
                assert_eq!(m0, m1, "ray {r}");
                assert_eq!(t0.map(f32::to_bits), t1.map(f32::to_bits), "ray {r}");
                hits += m0.count_ones();
            }
        }
        assert!(hits > 1000, "{hits} children in reach");
    }

    /// The counted interleaved walks give the uncounted ones' hits bit for bit, and their
    /// counts add up: every walk visits the root; a ray that misses the whole tree visits
    /// it alone; a leaf holds at most `MAX_LEAF` quads; only pushed entries are skipped.
    #[test]
    fn counted_walks_give_the_same_hits_and_consistent_counts() {
        let mut rnd = signed_rng(77u32);
        let (quads, verts) = random_soup(&mut rnd, 2000, 20.0, 3.0);
        let bvh = Bvh::build(quads, verts);
        assert!(bvh.nodes.len() > 30);
        let n = 600;
        let o: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rnd(), rnd(), rnd()) * 15.0)
            .collect();
        let d: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rnd(), rnd(), rnd()).normalize_or(Vec3::X))
            .collect();
        let tmin = vec![0.0; n];
        let (mut plain, mut counted) = (vec![None; n], vec![None; n]);
        bvh.closest_many(&o, &d, &tmin, f32::INFINITY, &mut plain);
        let mut st = WalkStats::default();
        bvh.closest_many_counted(&o, &d, &tmin, f32::INFINITY, &mut counted, &mut st);
        assert_eq!(plain, counted);
        let hits = plain.iter().filter(|h| h.is_some()).count();
        assert!(hits > 100, "{hits} hits");
        assert_eq!(st.rays, n as u64);
        assert!(st.nodes >= st.rays && st.leaves > 0, "{st:?}");
        assert!(st.quads >= st.leaves && st.quads <= MAX_LEAF as u64 * st.leaves);
        assert!(st.leaf_bytes >= 4 * (st.quads + 1) && st.skipped <= st.pushes);
        // Far outside, pointing away: the root's slab test alone.
        let mut miss = WalkStats::default();
        let mut out = [None];
        let far = [Vec3::splat(1e4)];
        bvh.closest_many_counted(
            &far,
            &[Vec3::ONE],
            &[0.0],
            f32::INFINITY,
            &mut out,
            &mut miss,
        );
        assert_eq!(out[0], None);
        assert_eq!(
            miss,
            WalkStats {
                rays: 1,
                nodes: 1,
                ..WalkStats::default()
            }
        );
    }

    #[test]
    fn brute_force_agrees_on_a_random_soup() {
        let mut rnd = signed_rng(12345u32);
        let (quads, verts) = random_soup(&mut rnd, 500, 5.0, 0.4);
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

    #[test]
    fn stack_pops_last_in_first_out_across_its_spill() {
        // Deeper than the array (a degenerate tree): the spill's entries come back first,
        // then the array's, each stack in reverse order of pushing.
        let mut s = Stack::new();
        for round in 0..2 {
            for k in 0..150u32 {
                s.push((k, round, k as f32));
            }
            assert_eq!(s.len(), 150);
            for k in (0..150u32).rev() {
                assert_eq!(s.pop(), Some((k, round, k as f32)));
            }
            assert_eq!(s.pop(), None);
            assert_eq!(s.len(), 0);
        }
        // Filled to exactly the array and past it, popped partly, pushed again.
        for k in 0..70u32 {
            s.push((k, 0, 0.0));
        }
        for k in (60..70u32).rev() {
            assert_eq!(s.pop(), Some((k, 0, 0.0)));
        }
        s.push((99, 0, 0.0));
        assert_eq!(s.pop(), Some((99, 0, 0.0)));
        for k in (0..60u32).rev() {
            assert_eq!(s.pop(), Some((k, 0, 0.0)));
        }
        assert_eq!(s.pop(), None);
    }

    #[test]
    fn watertight_frame_axes_are_the_cyclic_ones() {
        // The table lookups give (kz + 1) % 3 and (kz + 2) % 3, swapped for a negative
        // dominant component.
        for d in [
            Vec3::new(3.0, 1.0, -2.0),
            Vec3::new(-3.0, 1.0, 2.0),
            Vec3::new(1.0, 3.0, 2.0),
            Vec3::new(1.0, -3.0, 2.0),
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(1.0, 2.0, -3.0),
        ] {
            let w = WtRay::new(Vec3::ZERO, d);
            let kz = w.k()[2];
            let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
            if d[kz] < 0.0 {
                std::mem::swap(&mut kx, &mut ky);
            }
            assert_eq!(d.abs().max_element(), d[kz].abs());
            assert_eq!(w.k(), [kx, ky, kz]);
        }
    }
}
