//! Interleaved walks: many rays through one [`Bvh`], a step at a time.
//!
//! Input: rays (origin, direction, `tmin`, `tmax`). Output: each ray's closest hit
//! (`closest_many`), or each ray's hits handed to a callback until it says stop
//! (`each_hit_many`: shadow and transmission rays). Invariants: bit for bit [`Bvh::closest`]
//! and [`Bvh::each_hit`] for each ray: a ray makes the visits its lone walk makes in the
//! same order (the steps are `walk`'s loop cut at its memory accesses); only which ray runs
//! next changes.
//! Why: the walk of a large scene is latency-bound (its nodes and the leaves' corners are
//! rarely in the first-level cache); with several walks in flight, each step prefetching what
//! its ray needs next, one ray's waits overlap the others' work.

use glam::Vec3;

use super::{Bvh, Hit, LeafRay, QuadId, SlabRay, Stack};

/// Trees smaller than this (half a core's second-level cache here) are walked one ray at a
/// time by [`Bvh::each_hit_many`] (the same hits either way): their walks rarely wait for
/// memory, and the interleaved steps (each a dispatch on the lane's state, kept in memory)
/// cost more than the waits they hide. Shadow bench, lone vs interleaved: 7.9 vs 6.8 M
/// rays/s on a 0.19 MB tree, 4.1 vs 4.2 on 0.74 MB, 1.1 vs 1.8 on 10 MB;
/// `examples/raytrace` (a 0.11 MB tree) spent 25 % more time rendering interleaved. With
/// four-line nodes (medians of 5 pairs): 13.2 vs 12.8 M on 0.3 MB, 10.0 vs 10.5 on 0.7 MB.
const INTERLEAVE_BYTES: usize = 512 << 10;

impl Bvh {
    /// The closest hits of many rays: `out[k]` is `self.closest(o[k], d[k], tmin[k], tmax)`
    /// bit for bit (each ray's walk makes the same visits in the same order). The walks of
    /// `LANES` rays are interleaved a step at a time — a node visit, a leaf test — and each
    /// step prefetches what its ray needs next, so a ray's memory
    /// waits overlap the other rays' work instead of stalling the core (the walk of a large
    /// scene is latency-bound: its nodes and vertices are rarely in the first-level cache).
    pub fn closest_many(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: f32,
        out: &mut [Option<Hit>],
    ) {
        self.closest_many_with::<false>(o, d, tmin, tmax, out, &mut WalkStats::default());
    }

    /// [`Bvh::closest_many`] (the same hits, bit for bit) that also counts what the walks
    /// did into `stats` (added to what it holds): where a ray's time goes, for the rays
    /// bench and for choosing between tree layouts. The uncounted walk compiles the
    /// counting out.
    pub fn closest_many_counted(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: f32,
        out: &mut [Option<Hit>],
        stats: &mut WalkStats,
    ) {
        self.closest_many_with::<true>(o, d, tmin, tmax, out, stats);
    }

    /// The body of [`Bvh::closest_many`], counting into `stats` when `STATS`.
    fn closest_many_with<const STATS: bool>(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: f32,
        out: &mut [Option<Hit>],
        stats: &mut WalkStats,
    ) {
        let n = o.len().min(d.len()).min(tmin.len()).min(out.len());
        if self.nodes.is_empty() {
            // (One leaf: counted as rays alone.)
            if STATS {
                stats.rays += n as u64;
            }
            for k in 0..n {
                out[k] = self.closest(o[k], d[k], tmin[k], tmax);
            }
            return;
        }
        self.interleave::<true, STATS>(
            &o[..n],
            d,
            tmin,
            |_| tmax,
            &mut |_, best, q, t, a, b, tm| {
                *tm = t;
                *best = Some(Hit {
                    t,
                    grid: q.grid,
                    index: q.index,
                    a,
                    b,
                });
                false
            },
            &mut |k, best| out[k] = best,
            stats,
        );
    }

    /// [`Bvh::each_hit`] for many rays, their walks interleaved as in [`Bvh::closest_many`]:
    /// `f(k, hit)` is called for ray `k`'s hits with `tmin[k] < t < tmax[k]` until it returns
    /// true. Each ray's calls are exactly its lone `each_hit` calls, in the same order (the
    /// same visits in the same order); only the calls of different rays interleave, so `f`
    /// may keep per-ray state (a product of transmissions, say) and get the lone walks'
    /// results bit for bit.
    pub fn each_hit_many(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: &[f32],
        f: &mut dyn FnMut(usize, Hit) -> bool,
    ) {
        let n = o.len().min(d.len()).min(tmin.len()).min(tmax.len());
        if self.nodes.is_empty() || self.bytes() < INTERLEAVE_BYTES {
            for k in 0..n {
                self.each_hit(o[k], d[k], tmin[k], tmax[k], &mut |h| f(k, h));
            }
            return;
        }
        self.each_hit_interleaved(&o[..n], d, tmin, tmax, f);
    }

    /// [`Bvh::each_hit_many`] always interleaved (for a tree of nodes; rays `0..o.len()`).
    pub(super) fn each_hit_interleaved(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: &[f32],
        f: &mut dyn FnMut(usize, Hit) -> bool,
    ) {
        self.interleave::<false, false>(
            o,
            d,
            tmin,
            |k| tmax[k],
            &mut |k, _, q, t, a, b, _| {
                f(
                    k,
                    Hit {
                        t,
                        grid: q.grid,
                        index: q.index,
                        a,
                        b,
                    },
                )
            },
            &mut |_, _| {},
            &mut WalkStats::default(),
        );
    }

    /// The tree's size in bytes: nodes and leaves.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<super::Node8>() + self.leaves.len() * 4
    }

    /// Runs the walks of rays `0..o.len()` (ordered or not, as [`Bvh::walk`]) `LANES` at a
    /// time, a step at a time. `on_hit(ray, best, quad, t, a, b, &mut tmax)` is the walk's
    /// hit callback with the ray's index and a per-ray slot (returning true ends that ray's
    /// walk); `done(ray, best)` is called as each walk ends. Needs a tree of nodes.
    ///
    /// Where the CPU has AVX2 the walks run compiled for it: the node's slab test as
    /// eight-lane vectors, and the other SSE operations in their three-operand (VEX)
    /// encoding, without the register copies two-operand SSE needs and with broadcasts from
    /// memory (no FMA is enabled, so every result is bit for bit the portable one; the leaves
    /// do the same, see `quad4`).
    #[inline(always)]
    fn interleave<const ORDERED: bool, const STATS: bool>(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: impl Fn(usize) -> f32,
        on_hit: &mut impl FnMut(usize, &mut Option<Hit>, QuadId, f32, f32, f32, &mut f32) -> bool,
        done: &mut impl FnMut(usize, Option<Hit>),
        stats: &mut WalkStats,
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 was detected just above.
            unsafe {
                self.interleave_avx2::<ORDERED, STATS>(o, d, tmin, tmax, on_hit, done, stats)
            };
            return;
        }
        self.interleave_lanes::<ORDERED, false, STATS>(o, d, tmin, tmax, on_hit, done, stats);
    }

    /// [`Bvh::interleave_lanes`] compiled for AVX2 (see [`Bvh::interleave`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn interleave_avx2<const ORDERED: bool, const STATS: bool>(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: impl Fn(usize) -> f32,
        on_hit: &mut impl FnMut(usize, &mut Option<Hit>, QuadId, f32, f32, f32, &mut f32) -> bool,
        done: &mut impl FnMut(usize, Option<Hit>),
        stats: &mut WalkStats,
    ) {
        self.interleave_lanes::<ORDERED, true, STATS>(o, d, tmin, tmax, on_hit, done, stats);
    }

    /// The body of [`Bvh::interleave`].
    #[inline(always)]
    fn interleave_lanes<const ORDERED: bool, const AVX2: bool, const STATS: bool>(
        &self,
        o: &[Vec3],
        d: &[Vec3],
        tmin: &[f32],
        tmax: impl Fn(usize) -> f32,
        on_hit: &mut impl FnMut(usize, &mut Option<Hit>, QuadId, f32, f32, f32, &mut f32) -> bool,
        done: &mut impl FnMut(usize, Option<Hit>),
        stats: &mut WalkStats,
    ) {
        let n = o.len();
        if STATS {
            stats.rays += n as u64;
        }
        // 16 rays in flight: with the tree on huge pages (no page walk per prefetch) more
        // misses overlap; on the bench, 16 lanes beat 8 in 5 of 6 interleaved runs (median
        // 2.12 against 1.95 M rays/s; 32: 2.08). Before the huge pages 16 were no faster.
        const LANES: usize = 16;
        let mut lanes: Vec<Lane> = (0..LANES.min(n)).map(|_| Lane::new()).collect();
        for (k, l) in lanes.iter_mut().enumerate() {
            l.start::<AVX2>(k, o[k], d[k], tmin[k], tmax(k));
        }
        let mut next_ray = lanes.len();
        self.prefetch(0, 0);
        while !lanes.is_empty() {
            let mut i = 0;
            while i < lanes.len() {
                if self.step::<ORDERED, AVX2, STATS>(&mut lanes[i], on_hit, stats) {
                    i += 1;
                    continue;
                }
                done(lanes[i].ray, lanes[i].best);
                if next_ray < n {
                    let k = next_ray;
                    lanes[i].start::<AVX2>(k, o[k], d[k], tmin[k], tmax(k));
                    next_ray += 1;
                    i += 1;
                } else {
                    lanes.swap_remove(i);
                }
            }
        }
    }

    /// One step of a lane's walk (see [`Bvh::interleave`]); false when the walk is over.
    /// The steps in sequence are [`Bvh::walk`]'s loop for `ORDERED`.
    #[inline(always)]
    fn step<const ORDERED: bool, const AVX2: bool, const STATS: bool>(
        &self,
        l: &mut Lane,
        on_hit: &mut impl FnMut(usize, &mut Option<Hit>, QuadId, f32, f32, f32, &mut f32) -> bool,
        stats: &mut WalkStats,
    ) -> bool {
        match l.step {
            Step::Node(c) => {
                let n = &self.nodes[c as usize];
                let depth = l.stack.len();
                let next = self.visit::<ORDERED, AVX2>(n, &l.rb, l.tmin, l.tmax, &mut l.stack);
                if STATS {
                    stats.nodes += 1;
                    stats.pushes += (l.stack.len() - depth) as u64;
                }
                match next {
                    Some((c, 0)) => {
                        self.prefetch(c, 0);
                        l.step = Step::Node(c);
                        return true;
                    }
                    Some((first, count)) => {
                        self.prefetch(first, count);
                        l.step = Step::Leaf(first, count);
                        return true;
                    }
                    None => {}
                }
            }
            Step::Leaf(first, count) => {
                if STATS {
                    stats.leaves += 1;
                    stats.quads += u64::from(count & 0xff);
                    stats.leaf_bytes += 4 * u64::from(count >> 8);
                }
                let (ray, best) = (l.ray, &mut l.best);
                let stop = self.leaf::<AVX2>(
                    first,
                    count,
                    &l.wt,
                    l.tmin,
                    &mut l.tmax,
                    &mut |q, t, a, b, tm| on_hit(ray, best, q, t, a, b, tm),
                );
                if stop {
                    return false;
                }
            }
        }
        // Pop (as `walk` does, but a leaf popped is read in later steps like any other).
        loop {
            let Some((c, count, t)) = l.stack.pop() else {
                return false;
            };
            if t > l.tmax {
                if STATS {
                    stats.skipped += 1;
                }
                continue;
            }
            // (A leaf's block was prefetched when it was pushed.)
            l.step = if count > 0 {
                Step::Leaf(c, count)
            } else {
                Step::Node(c)
            };
            return true;
        }
    }
}

/// What interleaved walks did ([`Bvh::closest_many_counted`]): totals over their rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkStats {
    /// Walks (rays).
    pub rays: u64,
    /// Interior nodes visited (their slab tests: four cache lines each).
    pub nodes: u64,
    /// Leaves tested, the quads in them, and the bytes of their blocks the tests read.
    pub leaves: u64,
    pub quads: u64,
    pub leaf_bytes: u64,
    /// Children pushed for later, and of those popped, the ones skipped (beyond a closer
    /// hit found meanwhile).
    pub pushes: u64,
    pub skipped: u64,
}

/// What a lane of an interleaved walk does next.
#[derive(Clone, Copy)]
enum Step {
    /// Visit this interior node.
    Node(u32),
    /// Test this leaf's quads (its block, see [`Bvh::leaves`]).
    Leaf(u32, u32),
}

/// One ray's walk in an interleaved run ([`Bvh::closest_many`], [`Bvh::each_hit_many`]).
struct Lane {
    ray: usize,
    wt: LeafRay,
    rb: SlabRay,
    tmin: f32,
    tmax: f32,
    best: Option<Hit>,
    stack: Stack,
    step: Step,
}

impl Lane {
    fn new() -> Lane {
        Lane {
            ray: 0,
            wt: LeafRay::new(Vec3::ZERO, Vec3::Z),
            rb: SlabRay::new(Vec3::ZERO, Vec3::Z),
            tmin: 0.0,
            tmax: 0.0,
            best: None,
            stack: Stack::new(),
            step: Step::Node(0),
        }
    }

    /// Starts the walk of ray `ray` from the root, in place.
    #[inline(always)]
    fn start<const AVX2: bool>(&mut self, ray: usize, o: Vec3, d: Vec3, tmin: f32, tmax: f32) {
        self.ray = ray;
        self.wt = LeafRay::new_known::<AVX2>(o, d);
        self.rb = SlabRay::new(o, d);
        self.tmin = tmin;
        self.tmax = tmax;
        self.best = None;
        self.stack.clear();
        self.step = Step::Node(0);
    }
}
