//! The stochastic Z-buffer hider (`Hider "hidden"`), after Cook, Carpenter & Catmull (1987).
//!
//! Input: micropolygon grids overlapping a bucket's sample region, shaded on demand (a grid
//! behind every opaque sample of the bucket is skipped before it is shaded). Output: a
//! [`SampleBuffer`] with premultiplied r g b, alpha, camera depth z and output variables.
//! Invariants: `PixelSamples` stratified jittered samples per pixel, their positions a hash of
//! (pixel, stratum, seed); each micropolygon (two triangles) is tested only against the samples
//! inside its raster bound; shared edges follow a canonical tie rule so a sample on an edge is
//! hit exactly once; per-sample visible points are composited front to back in the total order
//! (depth, grid key, micropolygon), so results do not depend on the order grids arrive in.
//!
//! Layout: inside a bucket the samples are kept in *stratum rows* — sample (sx, sy) of pixel
//! (px, py) at `((py − y0)·ys + sy)·cols + (px − x0)·xs + sx` with `cols = width·xs` — as
//! separate arrays of x, y, front depth and front record (structure of arrays). A
//! micropolygon's raster bound is then a rectangle of strata whose rows are contiguous runs,
//! tested [`LANES`] samples at a time by a loop the compiler vectorises
//! ([`sample_quads`]; an AVX2 build of it is chosen at run time). The common case — a still,
//! convex micropolygon of an opaque, constant-shaded grid without output variables — keeps
//! only (depth, record) per sample, the record (grid key, micropolygon, colour) shared by all
//! the samples the micropolygon wins; everything else (transparency, smooth shading, output
//! variables, CSG, clipping planes, motion blur, depth of field, the midpoint depth filter)
//! takes the general per-sample path, which gives the same result.

// Colour loops index several parallel arrays by channel.
#![allow(clippy::needless_range_loop)]

use std::cell::RefCell;

use crate::film::gather::{PrepareCtx, Prepared, MAX_SPP};
use crate::film::SampleBuffer;

use super::super::camera::PixelRect;
use super::super::sampler::{pixel_positions, pixel_positions_xy, time_and_lens};
use super::super::stats::Stats;
use super::csg::{self, CsgHit};
use super::sweep::Sweep;
use super::timebins::{self, TimeBins};
use super::{may_meet, DepthFilter, GridSource, Hider, HiderConfig, ShadedGrid};

const NONE: u32 = u32::MAX;

/// Samples tested together by the quad kernel: one AVX register of f32.
pub const LANES: usize = 8;

/// The Z-buffer hider.
pub struct ZBuffer {
    config: HiderConfig,
}

impl ZBuffer {
    pub fn new(config: HiderConfig) -> ZBuffer {
        ZBuffer { config }
    }
}

/// A sample buffer for `rect` with every sample empty (no colour, alpha 0, z = ∞) and the
/// sample positions filled in.
pub fn empty_buffer(cfg: &HiderConfig, rect: PixelRect) -> SampleBuffer {
    let [xs, ys] = cfg.spp;
    let (w, h) = (rect.width(), rect.height());
    let n = w * h * xs * ys;
    let mut positions = Vec::with_capacity(n);
    for py in rect.y0..rect.y1 {
        for px in rect.x0..rect.x1 {
            pixel_positions(px, py, cfg.spp, cfg.jitter, cfg.seed, &mut positions);
        }
    }
    let channels = cfg.channels();
    let mut values = vec![0f32; n * channels];
    for s in 0..n {
        values[s * channels + 4] = f32::INFINITY;
    }
    SampleBuffer {
        x0: rect.x0,
        y0: rect.y0,
        width: w,
        height: h,
        spp_x: xs,
        spp_y: ys,
        positions,
        channels,
        values,
    }
}

/// One partly transparent surface seen by one sample, in front of its opaque front.
#[derive(Clone, Copy, Debug)]
struct VisPoint {
    z: f32,
    key: u64,
    sub: u32,
    next: u32,
    matte: bool,
    c: [f32; 3],
    o: [f32; 3],
    /// Offset of this point's output variables in the bucket's aov arena.
    aov: u32,
}

/// What an opaque front is: shared by every sample a micropolygon's triangle is the nearest
/// opaque surface of (one record per triangle with constant shading, one per sample with
/// smooth shading or output variables).
#[derive(Clone, Copy, Debug)]
struct Rec {
    key: u64,
    sub: u32,
    matte: bool,
    c: [f32; 3],
    o: [f32; 3],
    /// Offset of the output variables in the bucket's aov arena.
    aov: u32,
}

/// (depth, grid key, micropolygon) total order.
#[inline]
fn before(z: f32, key: u64, sub: u32, oz: f32, okey: u64, osub: u32) -> bool {
    z < oz || (z == oz && (key, sub) < (okey, osub))
}

/// A bucket's samples in stratum rows (see the module comment).
#[derive(Clone, Copy, Debug)]
struct Layout {
    x0: i32,
    y0: i32,
    /// Pixels.
    width: usize,
    height: usize,
    xs: usize,
    ys: usize,
    /// Strata per row (`width·xs`) and rows (`height·ys`).
    cols: usize,
    rows: usize,
}

impl Layout {
    fn new(rect: PixelRect, [xs, ys]: [usize; 2]) -> Layout {
        let (width, height) = (rect.width(), rect.height());
        Layout {
            x0: rect.x0,
            y0: rect.y0,
            width,
            height,
            xs,
            ys,
            cols: width * xs,
            rows: height * ys,
        }
    }

    fn len(&self) -> usize {
        self.cols * self.rows
    }

    /// The strata (clamped to `0..n`) along one axis whose samples may lie in `[t0, t1]`,
    /// for a bucket starting at pixel `origin` with `k` strata per pixel, as an inclusive
    /// range (empty when `lo > hi`). Sample positions are `p + (s + j)/k` rounded, so the
    /// range is widened by the rounding error; the exact test happens per sample.
    #[inline]
    fn strata(t0: f32, t1: f32, origin: i32, k: usize, n: usize) -> (usize, usize) {
        let (o, kf) = (origin as f64, k as f64);
        let eps = (o.abs() + (t0 as f64).abs().max((t1 as f64).abs()) + 2.0) * kf * 2.5e-7 + 1e-4;
        let lo = ((t0 as f64 - o) * kf - eps).floor().max(0.0);
        let hi = ((t1 as f64 - o) * kf + eps).floor().min(n as f64 - 1.0);
        if !(lo <= hi) {
            return (1, 0);
        }
        (lo as usize, hi as usize)
    }

    /// Columns and rows of strata whose samples may lie in the box (x0, y0, x1, y1).
    #[inline]
    fn box_strata(&self, bx: [f32; 4]) -> Option<((usize, usize), (usize, usize))> {
        let c = Layout::strata(bx[0], bx[2], self.x0, self.xs, self.cols);
        let r = Layout::strata(bx[1], bx[3], self.y0, self.ys, self.rows);
        (c.0 <= c.1 && r.0 <= r.1).then_some((c, r))
    }
}

/// Per-thread storage reused by every bucket (no allocation per bucket once warm).
#[derive(Default)]
struct Scratch {
    x: Vec<f32>,
    y: Vec<f32>,
    fz: Vec<f32>,
    fref: Vec<u32>,
    recs: Vec<Rec>,
    heads: Vec<u32>,
    second: Vec<f32>,
    pmax: Vec<f32>,
    points: Vec<VisPoint>,
    aovs: Vec<f32>,
    times: Vec<f32>,
    lens: Vec<[f32; 2]>,
    bins: TimeBins,
    lens_bins: TimeBins,
    visible: Vec<(usize, usize, [f32; 4])>,
}

thread_local! {
    /// Spare scratch per thread. A stack, not one: while a bucket waits for a grid another
    /// thread is shading, its thread hides other buckets meanwhile (see the driver's
    /// `LazyGrid`), each taking scratch of its own.
    static SCRATCH: RefCell<Vec<Scratch>> = const { RefCell::new(Vec::new()) };
}

/// Most spare scratches a thread keeps (one per bucket it hides at once).
const SCRATCH_KEPT: usize = 4;

/// Runs `f` with this thread's spare scratch (a new one when all are in use), keeping it
/// for the next bucket. No borrow is held while `f` runs, so `f` may hide another bucket.
fn with_scratch<T>(f: impl FnOnce(&mut Scratch) -> T) -> T {
    let mut scratch = SCRATCH.with(|c| c.borrow_mut().pop()).unwrap_or_default();
    let out = f(&mut scratch);
    SCRATCH.with(|c| {
        let mut kept = c.borrow_mut();
        if kept.len() < SCRATCH_KEPT {
            kept.push(scratch);
        }
    });
    out
}

/// Per-bucket hiding state.
struct Bucket<'c> {
    cfg: &'c HiderConfig,
    lay: Layout,
    /// Sample positions (stratum rows, padded by [`LANES`] so whole chunks can be read).
    x: Vec<f32>,
    y: Vec<f32>,
    /// Nearest opaque depth per sample (∞ when none) and its record (NONE when none).
    fz: Vec<f32>,
    fref: Vec<u32>,
    recs: Vec<Rec>,
    /// Lists of partly transparent points per sample (empty until the first one arrives).
    heads: Vec<u32>,
    points: Vec<VisPoint>,
    /// Second-nearest opaque depth per sample (only for the midpoint depth filter).
    second: Vec<f32>,
    /// Per pixel, the farthest opaque front of its samples (∞ while one sees none),
    /// recomputed over a grid's window before a grid that may lie behind some front: a
    /// micropolygon nearer to no sample than that is skipped.
    pmax: Vec<f32>,
    /// The nearest opaque front of any sample: a grid nearer than it hides behind nothing.
    fzmin: f32,
    aovs: Vec<f32>,
    tested: u64,
    hits: u64,
    /// Whether points behind the opaque front still matter (the midpoint depth filter).
    keep_second: bool,
    /// Samples without an opaque front yet.
    uncovered: usize,
    /// Every hit of CSG geometry (front and back faces), resolved after all grids, with
    /// their colour, opacity, matte flag and output variables.
    csg: Vec<CsgHit>,
    csg_data: Vec<([f32; 3], [f32; 3], bool)>,
    csg_aovs: Vec<f32>,
}

impl<'c> Bucket<'c> {
    /// The bucket's pixels.
    fn rect(&self) -> PixelRect {
        PixelRect {
            x0: self.lay.x0,
            y0: self.lay.y0,
            x1: self.lay.x0 + self.lay.width as i32,
            y1: self.lay.y0 + self.lay.height as i32,
        }
    }

    /// The bucket's pixels (relative column and row ranges, inclusive) holding samples that
    /// may lie in box `bx`: pixel p's samples lie in [p, p + 1].
    #[inline]
    fn pixels_of(&self, bx: [f32; 4]) -> Option<((usize, usize), (usize, usize))> {
        let lay = &self.lay;
        let range = |lo: f32, hi: f32, origin: i32, n: usize| {
            let a = (lo.ceil() as i64 - 1 - origin as i64).max(0);
            let b = (hi.floor() as i64 - origin as i64).min(n as i64 - 1);
            (a <= b).then_some((a as usize, b as usize))
        };
        Some((
            range(bx[0], bx[2], lay.x0, lay.width)?,
            range(bx[1], bx[3], lay.y0, lay.height)?,
        ))
    }

    /// The farthest front of pixel (i, j)'s samples.
    #[inline]
    fn pixel_far(&self, i: usize, j: usize) -> f32 {
        let lay = &self.lay;
        let mut m = [f32::NEG_INFINITY; 4];
        for sy in 0..lay.ys {
            let row = (j * lay.ys + sy) * lay.cols + i * lay.xs;
            let zs = &self.fz[row..row + lay.xs];
            let mut c = zs.chunks_exact(4);
            for q in &mut c {
                for l in 0..4 {
                    m[l] = if q[l] > m[l] { q[l] } else { m[l] };
                }
            }
            for &z in c.remainder() {
                m[0] = m[0].max(z);
            }
        }
        m[0].max(m[1]).max(m[2].max(m[3]))
    }

    /// Recomputes [`Bucket::pmax`] over the pixels of window `win`.
    fn refresh_pmax(&mut self, win: [f32; 4]) {
        let Some(((i0, i1), (j0, j1))) = self.pixels_of(win) else {
            return;
        };
        let w = self.lay.width;
        for j in j0..=j1 {
            for i in i0..=i1 {
                self.pmax[j * w + i] = self.pixel_far(i, j);
            }
        }
    }

    /// Whether every sample box `bx` may hold sees an opaque front nearer than `z`, by
    /// [`Bucket::pmax`] (stale values are larger, so the answer stays safe).
    #[inline]
    fn occluded(&self, bx: [f32; 4], z: f32) -> bool {
        let Some(((i0, i1), (j0, j1))) = self.pixels_of(bx) else {
            return false;
        };
        let w = self.lay.width;
        for j in j0..=j1 {
            for i in i0..=i1 {
                if !(z > self.pmax[j * w + i]) {
                    return false;
                }
            }
        }
        true
    }

    /// The (grid key, micropolygon) of sample `s`'s opaque front ((MAX, MAX) when none).
    #[inline]
    fn front_key(&self, s: usize) -> (u64, u32) {
        match self.fref[s] {
            NONE => (u64::MAX, u32::MAX),
            r => {
                let r = &self.recs[r as usize];
                (r.key, r.sub)
            }
        }
    }

    /// Adds a visible point to sample `s` (the caller counts the hit).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn insert(
        &mut self,
        s: usize,
        z: f32,
        key: u64,
        sub: u32,
        c: [f32; 3],
        o: [f32; 3],
        matte: bool,
        aov: &[f32],
    ) {
        let opaque = o[0].min(o[1]).min(o[2]) >= self.cfg.zthreshold;
        let fz = self.fz[s];
        let (fk, fs) = self.front_key(s);
        if !before(z, key, sub, fz, fk, fs) {
            if opaque && self.keep_second && z < self.second[s] {
                self.second[s] = z;
            }
            return;
        }
        if opaque {
            let aov_off = self.aovs.len() as u32;
            self.aovs.extend_from_slice(aov);
            let r = self.recs.len() as u32;
            self.recs.push(Rec {
                key,
                sub,
                matte,
                c,
                o,
                aov: aov_off,
            });
            self.set_front(s, z, r, key, sub);
            return;
        }
        if self.heads.is_empty() {
            self.heads.resize(self.fz.len(), NONE);
        }
        let idx = self.points.len() as u32;
        let aov_off = self.aovs.len() as u32;
        self.aovs.extend_from_slice(aov);
        self.points.push(VisPoint {
            z,
            key,
            sub,
            next: self.heads[s],
            matte,
            c,
            o,
            aov: aov_off,
        });
        self.heads[s] = idx;
    }

    /// Makes record `r` (at depth `z`, order (key, sub)) sample `s`'s opaque front, which
    /// it is before, and drops the transparent points it hides.
    #[inline]
    fn set_front(&mut self, s: usize, z: f32, r: u32, key: u64, sub: u32) {
        let fz = self.fz[s];
        if fz == f32::INFINITY && z < f32::INFINITY {
            self.uncovered -= 1;
        }
        if self.keep_second {
            self.second[s] = fz;
        }
        self.fz[s] = z;
        self.fref[s] = r;
        self.fzmin = self.fzmin.min(z);
        if self.heads.is_empty() {
            return;
        }
        let mut prev = NONE;
        let mut cur = self.heads[s];
        while cur != NONE {
            let p = self.points[cur as usize];
            if before(p.z, p.key, p.sub, z, key, sub) {
                prev = cur;
            } else if prev == NONE {
                self.heads[s] = p.next;
            } else {
                self.points[prev as usize].next = p.next;
            }
            cur = p.next;
        }
    }
}

/// [`edge`] with its per-edge part done once per micropolygon: the canonical origin and
/// direction, and the sign. Evaluates to the same bits as `edge(a, b, p)` (negation and the
/// products are the same operations in the same order).
#[derive(Clone, Copy, Debug)]
struct Edge {
    o: [f32; 2],
    d: [f32; 2],
    neg: bool,
}

impl Edge {
    #[inline]
    fn new(a: [f32; 2], b: [f32; 2]) -> Edge {
        if (a[0], a[1]) < (b[0], b[1]) {
            Edge {
                o: a,
                d: [b[0] - a[0], b[1] - a[1]],
                neg: false,
            }
        } else {
            Edge {
                o: b,
                d: [a[0] - b[0], a[1] - b[1]],
                neg: true,
            }
        }
    }

    #[inline(always)]
    fn eval(&self, p: [f32; 2]) -> f32 {
        let e = self.d[0] * (p[1] - self.o[1]) - self.d[1] * (p[0] - self.o[0]);
        if self.neg {
            -e
        } else {
            e
        }
    }

    /// The sample is inside (or on the edge this direction owns).
    #[inline(always)]
    fn inside(&self, p: [f32; 2]) -> bool {
        let e = self.eval(p);
        e > 0.0 || (e == 0.0 && !self.neg)
    }
}

impl Hider for ZBuffer {
    fn config(&self) -> &HiderConfig {
        &self.config
    }

    fn hide(&self, rect: PixelRect, grids: &[&dyn GridSource], stats: &Stats) -> SampleBuffer {
        with_scratch(
            |scratch| match self.hide_with(scratch, rect, grids, stats, None) {
                Output::Samples(buf) => buf,
                Output::Prepared(_) => unreachable!("asked for samples"),
            },
        )
    }

    fn hide_prepared(
        &self,
        rect: PixelRect,
        grids: &[&dyn GridSource],
        stats: &Stats,
        ctx: &PrepareCtx,
    ) -> Option<Prepared> {
        if self.config.channels() != 5 || self.config.spp[0] * self.config.spp[1] > MAX_SPP {
            return None;
        }
        with_scratch(
            |scratch| match self.hide_with(scratch, rect, grids, stats, Some(ctx)) {
                Output::Prepared(p) => Some(p),
                Output::Samples(_) => None,
            },
        )
    }
}

/// A bucket's grids in the order they are hidden: front to back by [`ShadedGrid::zmin`], ties
/// by key — the order of sorting the shaded grids, so that hiding goes exactly as if every
/// grid had been shaded first — shading each only when it may be next.
///
/// The unshaded grids wait sorted by their lower bound of zmin; shaded ones wait in a heap
/// by their zmin. A shaded grid is next when its zmin is below the bound of every unshaded
/// grid (which lies at or behind its own bound); otherwise the first unshaded grid is
/// shaded, unless its bound lies behind `far`, the farthest opaque front of the bucket: then
/// the grid, wholly behind every opaque sample, changes no sample and is not shaded here.
/// Fronts only come nearer, so in the shaded order the grid would also have lain behind
/// them: the picture is the same.
struct Order<'g> {
    unshaded: Vec<&'g dyn GridSource>,
    next_unshaded: usize,
    shaded: std::collections::BinaryHeap<std::cmp::Reverse<ByDepth<'g>>>,
}

/// What [`Order::next`] gives.
enum Next<'g> {
    Hide(&'g ShadedGrid),
    /// An unshaded grid behind every opaque front.
    Culled,
    Done,
}

/// A shaded grid ordered by (zmin, key).
struct ByDepth<'g>(&'g ShadedGrid);

impl ByDepth<'_> {
    fn cmp_key(&self, o: &Self) -> std::cmp::Ordering {
        self.0
            .zmin
            .total_cmp(&o.0.zmin)
            .then(self.0.key.cmp(&o.0.key))
    }
}

impl PartialEq for ByDepth<'_> {
    fn eq(&self, o: &Self) -> bool {
        self.cmp_key(o).is_eq()
    }
}
impl Eq for ByDepth<'_> {}
impl PartialOrd for ByDepth<'_> {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp_key(o))
    }
}
impl Ord for ByDepth<'_> {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.cmp_key(o)
    }
}

impl<'g> Order<'g> {
    /// `unshaded` sorted by (lower bound of zmin, key).
    fn new(unshaded: Vec<&'g dyn GridSource>) -> Order<'g> {
        Order {
            unshaded,
            next_unshaded: 0,
            shaded: std::collections::BinaryHeap::new(),
        }
    }

    fn next(&mut self, far: f32) -> Next<'g> {
        loop {
            let bound = self.unshaded.get(self.next_unshaded).map(|g| g.zmin());
            if let Some(std::cmp::Reverse(top)) = self.shaded.peek() {
                // Strictly nearer: an unshaded grid at the same depth may have a smaller key.
                if bound.is_none_or(|z| top.0.zmin.total_cmp(&z).is_lt()) {
                    let g = top.0;
                    self.shaded.pop();
                    return Next::Hide(g);
                }
            }
            let Some(z) = bound else {
                return Next::Done;
            };
            let g = self.unshaded[self.next_unshaded];
            self.next_unshaded += 1;
            if z > far {
                return Next::Culled;
            }
            if let Some(sg) = g.shaded() {
                self.shaded.push(std::cmp::Reverse(ByDepth(sg)));
            }
        }
    }
}

/// What [`ZBuffer::hide_with`] makes.
enum Output {
    Samples(SampleBuffer),
    Prepared(Prepared),
}

impl ZBuffer {
    fn hide_with(
        &self,
        scratch: &mut Scratch,
        rect: PixelRect,
        grids: &[&dyn GridSource],
        stats: &Stats,
        prepare: Option<&PrepareCtx>,
    ) -> Output {
        let cfg = &self.config;
        let lay = Layout::new(rect, cfg.spp);
        let n = lay.len();
        let [xs, ys] = cfg.spp;
        let spp = xs * ys;
        let channels = cfg.channels();
        let samples = prepare.is_none();
        // Positions: pixel by pixel into the buffer, scattered into stratum rows.
        let keep_second = cfg.depth_filter == DepthFilter::Midpoint;
        let mut b = Bucket {
            cfg,
            lay,
            x: std::mem::take(&mut scratch.x),
            y: std::mem::take(&mut scratch.y),
            fz: std::mem::take(&mut scratch.fz),
            fref: std::mem::take(&mut scratch.fref),
            recs: std::mem::take(&mut scratch.recs),
            heads: std::mem::take(&mut scratch.heads),
            points: std::mem::take(&mut scratch.points),
            second: std::mem::take(&mut scratch.second),
            pmax: std::mem::take(&mut scratch.pmax),
            fzmin: f32::INFINITY,
            aovs: std::mem::take(&mut scratch.aovs),
            tested: 0,
            hits: 0,
            keep_second,
            uncovered: n,
            csg: Vec::new(),
            csg_data: Vec::new(),
            csg_aovs: Vec::new(),
        };
        // Every position is written below; the padding lanes are never used.
        b.x.resize(n + LANES, f32::NAN);
        b.y.resize(n + LANES, f32::NAN);
        b.fz.clear();
        b.fz.resize(n + LANES, f32::INFINITY);
        b.fref.clear();
        b.fref.resize(n, NONE);
        b.recs.clear();
        b.heads.clear();
        b.points.clear();
        b.second.clear();
        if keep_second {
            b.second.resize(n, f32::INFINITY);
        }
        b.aovs.clear();
        b.pmax.clear();
        b.pmax.resize(lay.width * lay.height, f32::INFINITY);

        let (mut px_x, mut px_y) = (vec![0f32; spp], vec![0f32; spp]);
        for j in 0..lay.height {
            for i in 0..lay.width {
                let (px, py) = (rect.x0 + i as i32, rect.y0 + j as i32);
                pixel_positions_xy(px, py, cfg.spp, cfg.jitter, cfg.seed, &mut px_x, &mut px_y);
                for sy in 0..ys {
                    let row = (j * ys + sy) * lay.cols + i * xs;
                    copy_short(&mut b.x[row..row + xs], &px_x[sy * xs..(sy + 1) * xs]);
                    copy_short(&mut b.y[row..row + xs], &px_y[sy * xs..(sy + 1) * xs]);
                }
            }
        }
        // Front to back by the bound known before shading (ties by key), so opaque surfaces
        // cull the grids behind them before they are shaded (see `Order`).
        let mut unshaded: Vec<&dyn GridSource> = grids
            .iter()
            .copied()
            .filter(|g| may_meet(*g, &rect))
            .collect();
        unshaded.sort_by(|a, c| a.zmin().total_cmp(&c.zmin()).then(a.key().cmp(&c.key())));
        // The farthest opaque front over the bucket (∞ while a sample sees none): a grid
        // entirely behind it hides nowhere. Refreshed as samples are hit; stale is safe
        // (fronts only come nearer).
        let mut far = f32::INFINITY;
        let mut hits_at_refresh = 0u64;
        // Motion blur and depth of field: each sample's time and lens position.
        let (mut times, mut lens) = (
            std::mem::take(&mut scratch.times),
            std::mem::take(&mut scratch.lens),
        );
        times.clear();
        lens.clear();
        let moving = unshaded.iter().any(|g| g.moving());
        if cfg.dof.is_some() || moving {
            times.resize(n, 0.0);
            lens.resize(n, [0.0; 2]);
            let (mut perm, mut t, mut l) = (Vec::new(), Vec::new(), Vec::new());
            for j in 0..lay.height {
                for i in 0..lay.width {
                    let (px, py) = (rect.x0 + i as i32, rect.y0 + j as i32);
                    t.clear();
                    l.clear();
                    time_and_lens(
                        px, py, xs, ys, cfg.jitter, cfg.seed, &mut perm, &mut t, &mut l,
                    );
                    for k in 0..spp {
                        let s = (j * ys + k / xs) * lay.cols + i * xs + k % xs;
                        times[s] = t[k];
                        lens[s] = l[k];
                    }
                }
            }
        }
        // Moving grids test their samples time slot by time slot.
        // Cells (pixels × slots) are held to about a million (4 MB of counts) for large
        // buckets, never below one slot per sample of a pixel.
        let pixels = lay.width * lay.height;
        let slots = cfg
            .time_slots
            .min((MAX_TIME_CELLS / pixels.max(1)).max(spp));
        let bins = (moving && slots > 1).then(|| {
            let (cols, w) = (lay.cols, lay.width);
            scratch.bins.build(
                slots,
                lay.width * lay.height,
                &times[..n],
                &b.x,
                &b.y,
                |s| (s / cols / ys) * w + (s % cols) / xs,
            );
            &scratch.bins
        });
        // Under depth of field, still grids test their samples lens cell by lens cell.
        let lens_bins = (cfg.dof.is_some() && cfg.lens_slots > 1).then(|| {
            let (cols, w, l) = (lay.cols, lay.width, cfg.lens_slots);
            let cell = |v: f32| (((v + 1.0) * 0.5 * l as f32) as usize).min(l - 1);
            scratch.lens_bins.build_keyed(
                l * l,
                lay.width * lay.height,
                n,
                |s| cell(lens[s][1]) * l + cell(lens[s][0]),
                |s| lens[s],
                &b.x,
                &b.y,
                |s| (s / cols / ys) * w + (s % cols) / xs,
            );
            &scratch.lens_bins
        });
        let mut visible = std::mem::take(&mut scratch.visible);
        let kernel = QuadKernel::pick();
        let mut order = Order::new(unshaded);
        // Counted here, added to the shared statistics once per bucket.
        let mut occluded = 0u64;
        loop {
            if !b.keep_second
                && b.uncovered == 0
                && (far == f32::INFINITY || b.hits - hits_at_refresh >= (n as u64 / 8).max(1))
            {
                far = b.fz[..n].iter().fold(0f32, |m, &f| m.max(f));
                hits_at_refresh = b.hits;
            }
            let g = match order.next(far) {
                Next::Hide(g) => g,
                Next::Culled => {
                    occluded += 1;
                    continue;
                }
                Next::Done => break,
            };
            if g.zmin > far {
                occluded += 1;
                continue;
            }
            if g.motion.is_some() || cfg.dof.is_some() {
                sample_grid_blurred(&mut b, g, &times, &lens, bins, lens_bins, &mut visible);
            } else {
                sample_grid(&mut b, g, kernel, &mut visible);
            }
        }
        if !b.csg.is_empty() {
            resolve_csg(&mut b);
        }
        let out = match prepare {
            None => {
                let mut positions = Vec::with_capacity(n);
                for j in 0..lay.height {
                    for i in 0..lay.width {
                        for sy in 0..ys {
                            let row = (j * ys + sy) * lay.cols + i * xs;
                            for sx in 0..xs {
                                positions.push([b.x[row + sx], b.y[row + sx]]);
                            }
                        }
                    }
                }
                let mut buf = SampleBuffer {
                    x0: rect.x0,
                    y0: rect.y0,
                    width: lay.width,
                    height: lay.height,
                    spp_x: xs,
                    spp_y: ys,
                    positions,
                    channels,
                    values: vec![0f32; n * channels],
                };
                resolve(&b, &mut buf);
                Output::Samples(buf)
            }
            Some(ctx) => Output::Prepared(resolve_prepared(&b, ctx)),
        };
        let bytes = b.points.len() * std::mem::size_of::<VisPoint>()
            + b.recs.len() * std::mem::size_of::<Rec>()
            + n * 16
            + if samples {
                n * (channels + 2) * 4
            } else {
                n * 40
            };
        stats.alloc(bytes);
        stats.free(bytes);
        Stats::add(&stats.grids_occluded, occluded);
        Stats::add(&stats.samples_tested, b.tested);
        Stats::add(&stats.samples_hit, b.hits);
        scratch.x = b.x;
        scratch.y = b.y;
        scratch.fz = b.fz;
        scratch.fref = b.fref;
        scratch.recs = b.recs;
        scratch.heads = b.heads;
        scratch.points = b.points;
        scratch.second = b.second;
        scratch.pmax = b.pmax;
        scratch.aovs = b.aovs;
        scratch.times = times;
        scratch.lens = lens;
        scratch.visible = visible;
        out
    }
}

/// Which build of the quad kernel runs: the portable one, or the same code compiled for AVX2
/// (chosen once per bucket from the CPU's features; both give the same bits — no fused
/// multiply-adds are formed).
#[derive(Clone, Copy, Debug)]
enum QuadKernel {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl QuadKernel {
    fn pick() -> QuadKernel {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("popcnt")
            && std::arch::is_x86_feature_detected!("bmi1")
        {
            return QuadKernel::Avx2;
        }
        QuadKernel::Portable
    }

    fn run(
        self,
        b: &mut Bucket,
        g: &ShadedGrid,
        win: [f32; 4],
        visible: &[Visible],
        occlusion: bool,
    ) {
        match self {
            QuadKernel::Portable => sample_quads(b, g, win, visible, occlusion, quad_chunk),
            // SAFETY: `pick` chose this only where the CPU has AVX2.
            #[cfg(target_arch = "x86_64")]
            QuadKernel::Avx2 => unsafe { sample_quads_avx2(b, g, win, visible, occlusion) },
        }
    }
}

/// A live micropolygon overlapping the window: (index, first corner point, raster bound).
type Visible = (usize, usize, [f32; 4]);

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt,bmi1")]
fn sample_quads_avx2(
    b: &mut Bucket,
    g: &ShadedGrid,
    win: [f32; 4],
    visible: &[Visible],
    occlusion: bool,
) {
    sample_quads(
        b,
        g,
        win,
        visible,
        occlusion,
        |q, bx, x, y, fz, n, persp, near, far| {
            avx2::quad_chunk(q, bx, x, y, fz, n, persp, near, far)
        },
    )
}

/// The sample test of a convex micropolygon, set up once: its five edges (the four sides
/// p0p1, p1p2, p2p3, p3p0 and the diagonal p0p2) in canonical form — raw value
/// `R = d.x·(y − o.y) − d.y·(x − o.x)` from the lexicographically smaller end, which is what
/// [`Edge::eval`] computes up to sign — which sign of `R` is inside each side, and each
/// triangle's depth interpolation.
#[derive(Clone, Copy, Debug)]
struct QuadTest {
    ox: [f32; 5],
    oy: [f32; 5],
    dx: [f32; 5],
    dy: [f32; 5],
    /// Side k is passed when `R < 0` (true) or `R ≥ 0` (false).
    neg: [bool; 4],
    /// The diagonal as triangle 0 sees it: the sample is in triangle 0 when it passes.
    dneg: bool,
    /// Triangle t's vertices were reordered to make it counter-clockwise: its barycentric
    /// edges (v2→v0, v0→v1) are then (side, diagonal) instead of (diagonal, side).
    swap: [bool; 2],
    /// ±1/area for the two barycentric edges of each triangle.
    ca: [f32; 2],
    cb: [f32; 2],
    /// Depth at corner 0 and its differences to the triangle's other two vertices.
    dq0: f32,
    dd1: [f32; 2],
    dd2: [f32; 2],
}

#[inline(always)]
fn lt(a: [f32; 2], b: [f32; 2]) -> bool {
    (a[0], a[1]) < (b[0], b[1])
}

/// Whether quad `p` is strictly convex counter-clockwise or clockwise (every corner turns
/// the same way); neither for a concave, bow-tie or degenerate quad.
#[inline(always)]
fn convexity(p: &[[f32; 2]; 4]) -> (bool, bool) {
    let turn = |a: [f32; 2], o: [f32; 2], c: [f32; 2]| {
        (a[0] - o[0]) * (c[1] - o[1]) - (a[1] - o[1]) * (c[0] - o[0])
    };
    let turns = [
        turn(p[1], p[0], p[3]),
        turn(p[2], p[1], p[0]),
        turn(p[3], p[2], p[1]),
        turn(p[0], p[3], p[2]),
    ];
    (
        turns.iter().all(|&t| t > 0.0),
        turns.iter().all(|&t| t < 0.0),
    )
}

impl QuadTest {
    /// The quad test of micropolygon with corners `corner` (points `p`), or None when the
    /// two-triangle fallback applies (not strictly convex, or a degenerate triangle). Makes
    /// the same decisions and the same numbers as [`sample_micro`].
    #[inline(always)]
    fn new(p: [[f32; 2]; 4], corner: [usize; 4], depth: &[f32]) -> Option<QuadTest> {
        let (ccw, cw) = convexity(&p);
        if !(ccw || cw) {
            return None;
        }
        let area = |v: [[f32; 2]; 3]| {
            (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0])
        };
        let a0 = area([p[0], p[1], p[2]]);
        let a1 = area([p[0], p[2], p[3]]);
        if a0 == 0.0 || !a0.is_finite() || a1 == 0.0 || !a1.is_finite() {
            return None;
        }
        let ends = [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2)];
        let (mut ox, mut oy, mut dx, mut dy) = ([0f32; 5], [0f32; 5], [0f32; 5], [0f32; 5]);
        for (k, &(i, j)) in ends.iter().enumerate() {
            // Edge::new(p[i], p[j]) and Edge::new(p[j], p[i]) share origin and direction.
            let e = Edge::new(p[i], p[j]);
            ox[k] = e.o[0];
            oy[k] = e.o[1];
            dx[k] = e.d[0];
            dy[k] = e.d[1];
        }
        // Directed i → j evaluates to −R exactly when p[i] is not before p[j].
        let neg = |i: usize, j: usize| !lt(p[i], p[j]);
        let (sides, dneg) = if ccw {
            ([neg(0, 1), neg(1, 2), neg(2, 3), neg(3, 0)], neg(2, 0))
        } else {
            ([neg(1, 0), neg(2, 1), neg(3, 2), neg(0, 3)], neg(0, 2))
        };
        let sign = |n: bool, inv: f32| if n { -inv } else { inv };
        let (inv0, inv1) = (1.0 / a0.abs(), 1.0 / a1.abs());
        let (swap0, swap1) = (a0 < 0.0, a1 < 0.0);
        // Triangle 0 = (p0, p1, p2): barycentric edges v2→v0, v0→v1.
        let (idx0, ca0, cb0) = if swap0 {
            ([0, 2, 1], sign(neg(1, 0), inv0), sign(neg(0, 2), inv0))
        } else {
            ([0, 1, 2], sign(neg(2, 0), inv0), sign(neg(0, 1), inv0))
        };
        // Triangle 1 = (p0, p2, p3).
        let (idx1, ca1, cb1) = if swap1 {
            ([0, 3, 2], sign(neg(2, 0), inv1), sign(neg(0, 3), inv1))
        } else {
            ([0, 2, 3], sign(neg(3, 0), inv1), sign(neg(0, 2), inv1))
        };
        let d = |i: usize| depth[corner[i]];
        let dq0 = d(0);
        Some(QuadTest {
            ox,
            oy,
            dx,
            dy,
            neg: sides,
            dneg,
            swap: [swap0, swap1],
            ca: [ca0, ca1],
            cb: [cb0, cb1],
            dq0,
            dd1: [d(idx0[1]) - dq0, d(idx1[1]) - dq0],
            dd2: [d(idx0[2]) - dq0, d(idx1[2]) - dq0],
        })
    }
}

/// Lane masks of one chunk of samples against a quad: inside the box (and a real lane),
/// hit (inside the quad at a depth inside the clipping range), at or before the sample's
/// front depth, in triangle 1; and the depth per lane.
struct Chunk {
    inbox: u32,
    hit: u32,
    front: u32,
    tri1: u32,
    z: [f32; LANES],
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn quad_chunk(
    q: &QuadTest,
    bx: &[f32; 4],
    x: &[f32; LANES],
    y: &[f32; LANES],
    fz: &[f32; LANES],
    nvalid: usize,
    persp: bool,
    near: f32,
    far: f32,
) -> Chunk {
    let mut z = [0f32; LANES];
    let (mut inbox, mut hit, mut front, mut tri1) = (0u32, 0u32, 0u32, 0u32);
    for l in 0..LANES {
        let (px, py) = (x[l], y[l]);
        let mut r = [0f32; 5];
        for k in 0..5 {
            r[k] = q.dx[k] * (py - q.oy[k]) - q.dy[k] * (px - q.ox[k]);
        }
        let pass = |r: f32, neg: bool| ((r < 0.0) & neg) | ((r >= 0.0) & !neg);
        let inb = (l < nvalid) & (px >= bx[0]) & (px <= bx[2]) & (py >= bx[1]) & (py <= bx[3]);
        let in4 = pass(r[0], q.neg[0])
            & pass(r[1], q.neg[1])
            & pass(r[2], q.neg[2])
            & pass(r[3], q.neg[3]);
        let t0 = pass(r[4], q.dneg);
        let (a0, b0) = if q.swap[0] {
            (r[0], r[4])
        } else {
            (r[4], r[0])
        };
        let (a1, b1) = if q.swap[1] {
            (r[4], r[3])
        } else {
            (r[3], r[4])
        };
        let q0 = q.dq0 + (a0 * q.ca[0]) * q.dd1[0] + (b0 * q.cb[0]) * q.dd2[0];
        let q1 = q.dq0 + (a1 * q.ca[1]) * q.dd1[1] + (b1 * q.cb[1]) * q.dd2[1];
        let qq = if t0 { q0 } else { q1 };
        let zl = if persp { 1.0 / qq } else { qq };
        let zok = (zl >= near) & (zl <= far);
        let h = inb & in4 & zok;
        z[l] = zl;
        inbox |= (inb as u32) << l;
        hit |= (h as u32) << l;
        front |= ((h & (zl <= fz[l])) as u32) << l;
        tri1 |= ((!t0) as u32) << l;
    }
    Chunk {
        inbox,
        hit,
        front,
        tri1,
        z,
    }
}

/// A build of [`quad_chunk`].
trait ChunkFn:
    Fn(
        &QuadTest,
        &[f32; 4],
        &[f32; LANES],
        &[f32; LANES],
        &[f32; LANES],
        usize,
        bool,
        f32,
        f32,
    ) -> Chunk
    + Copy
{
}

impl<F> ChunkFn for F where
    F: Fn(
            &QuadTest,
            &[f32; 4],
            &[f32; LANES],
            &[f32; LANES],
            &[f32; LANES],
            usize,
            bool,
            f32,
            f32,
        ) -> Chunk
        + Copy
{
}

/// [`quad_chunk`] in AVX2 intrinsics: the same IEEE operations lane by lane, so the same bits.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::{Chunk, QuadTest, LANES};

    /// The lanes that pass a side: `R < 0` when `neg` (all ones), else `R ≥ 0`; NaN fails.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn pass(r: __m256, neg: __m256) -> __m256 {
        let zero = _mm256_setzero_ps();
        let lt = _mm256_cmp_ps::<_CMP_LT_OQ>(r, zero);
        let ge = _mm256_cmp_ps::<_CMP_GE_OQ>(r, zero);
        _mm256_blendv_ps(ge, lt, neg)
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn flag(b: bool) -> __m256 {
        _mm256_castsi256_ps(_mm256_set1_epi32(-(b as i32)))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn quad_chunk(
        q: &QuadTest,
        bx: &[f32; 4],
        x: &[f32; LANES],
        y: &[f32; LANES],
        fz: &[f32; LANES],
        nvalid: usize,
        persp: bool,
        near: f32,
        far: f32,
    ) -> Chunk {
        // SAFETY: the loads and the store touch exactly the LANES floats of their arrays.
        let (px, py, fzv) = unsafe {
            (
                _mm256_loadu_ps(x.as_ptr()),
                _mm256_loadu_ps(y.as_ptr()),
                _mm256_loadu_ps(fz.as_ptr()),
            )
        };
        let s = _mm256_set1_ps;
        let mut r = [_mm256_setzero_ps(); 5];
        for k in 0..5 {
            r[k] = _mm256_sub_ps(
                _mm256_mul_ps(s(q.dx[k]), _mm256_sub_ps(py, s(q.oy[k]))),
                _mm256_mul_ps(s(q.dy[k]), _mm256_sub_ps(px, s(q.ox[k]))),
            );
        }
        let in4 = _mm256_and_ps(
            _mm256_and_ps(pass(r[0], flag(q.neg[0])), pass(r[1], flag(q.neg[1]))),
            _mm256_and_ps(pass(r[2], flag(q.neg[2])), pass(r[3], flag(q.neg[3]))),
        );
        let t0 = pass(r[4], flag(q.dneg));
        let (a0, b0) = if q.swap[0] {
            (r[0], r[4])
        } else {
            (r[4], r[0])
        };
        let (a1, b1) = if q.swap[1] {
            (r[4], r[3])
        } else {
            (r[3], r[4])
        };
        let tri = |a: __m256, b: __m256, t: usize| {
            _mm256_add_ps(
                _mm256_add_ps(
                    s(q.dq0),
                    _mm256_mul_ps(_mm256_mul_ps(a, s(q.ca[t])), s(q.dd1[t])),
                ),
                _mm256_mul_ps(_mm256_mul_ps(b, s(q.cb[t])), s(q.dd2[t])),
            )
        };
        let qq = _mm256_blendv_ps(tri(a1, b1, 1), tri(a0, b0, 0), t0);
        let z = if persp { _mm256_div_ps(s(1.0), qq) } else { qq };
        let zok = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(z, s(near)),
            _mm256_cmp_ps::<_CMP_LE_OQ>(z, s(far)),
        );
        let inb = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(px, s(bx[0])),
                _mm256_cmp_ps::<_CMP_LE_OQ>(px, s(bx[2])),
            ),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(py, s(bx[1])),
                _mm256_cmp_ps::<_CMP_LE_OQ>(py, s(bx[3])),
            ),
        );
        let h = _mm256_and_ps(_mm256_and_ps(inb, in4), zok);
        let front = _mm256_and_ps(h, _mm256_cmp_ps::<_CMP_LE_OQ>(z, fzv));
        let valid = (1u32 << nvalid) - 1;
        let mut zs = [0f32; LANES];
        // SAFETY: stores exactly LANES floats.
        unsafe { _mm256_storeu_ps(zs.as_mut_ptr(), z) };
        Chunk {
            inbox: _mm256_movemask_ps(inb) as u32 & valid,
            hit: _mm256_movemask_ps(h) as u32 & valid,
            front: _mm256_movemask_ps(front) as u32 & valid,
            tri1: !(_mm256_movemask_ps(t0) as u32) & 0xff,
            z: zs,
        }
    }
}

/// The fast path of [`sample_grid`]: every convex micropolygon of a still, constant-shaded,
/// unclipped grid without output variables, through the vectorised quad test; the others
/// through [`sample_micro`].
#[inline(always)]
fn sample_quads(
    b: &mut Bucket,
    g: &ShadedGrid,
    win: [f32; 4],
    visible: &[Visible],
    occlusion: bool,
    chunk: impl ChunkFn,
) {
    let cfg = b.cfg;
    let nu = g.nu;
    let (persp, near, far) = (cfg.perspective, cfg.near, cfg.far);
    let lay = b.lay;
    let cols = lay.cols;
    let (mut tested, mut hits) = (0u64, 0u64);
    for &(m, k, mb) in visible {
        let Some(bx) = super::clip_box(mb, win) else {
            continue;
        };
        let corner = [k, k + 1, k + nu + 1, k + nu];
        if occlusion {
            // The nearest depth anywhere on the micropolygon (depth interpolates between
            // its corners; the margin covers the rounding).
            let d = corner.map(|c| g.depth[c]);
            let znear = if persp {
                let qmax = d[0].max(d[1]).max(d[2]).max(d[3]);
                if qmax > 0.0 {
                    1.0 / qmax
                } else {
                    0.0
                }
            } else {
                d[0].min(d[1]).min(d[2]).min(d[3])
            };
            if b.occluded(bx, znear - znear.abs() * 1e-5) {
                continue;
            }
        }
        let p = corner.map(|c| g.xy[c]);
        let Some(q) = QuadTest::new(p, corner, &g.depth) else {
            b.tested += tested;
            b.hits += hits;
            (tested, hits) = (0, 0);
            sample_micro(b, g, m, k, bx, &mut [], &mut []);
            continue;
        };
        let Some(((c0, c1), (r0, r1))) = lay.box_strata(bx) else {
            continue;
        };
        let (cc, co) = flat_shade(g, &corner, &mut []);
        let opaque = co[0].min(co[1]).min(co[2]) >= cfg.zthreshold;
        let mut recs = [NONE; 2];
        for r in r0..=r1 {
            let row = r * cols;
            let mut c = c0;
            while c <= c1 {
                let base = row + c;
                let nvalid = (c1 + 1 - c).min(LANES);
                c += LANES;
                let xa: &[f32; LANES] = b.x[base..base + LANES].try_into().unwrap();
                let ya: &[f32; LANES] = b.y[base..base + LANES].try_into().unwrap();
                let fa: &[f32; LANES] = b.fz[base..base + LANES].try_into().unwrap();
                let ch = chunk(&q, &bx, xa, ya, fa, nvalid, persp, near, far);
                tested += ch.inbox.count_ones() as u64;
                hits += ch.hit.count_ones() as u64;
                let mut mask = ch.front;
                while mask != 0 {
                    let l = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let s = base + l;
                    let t = ((ch.tri1 >> l) & 1) as usize;
                    let sub = (m as u32) << 1 | t as u32;
                    let z = ch.z[l];
                    let fz = b.fz[s];
                    if !(z < fz || (z == fz && (g.key, sub) < b.front_key(s))) {
                        continue;
                    }
                    if opaque {
                        if recs[t] == NONE {
                            recs[t] = b.recs.len() as u32;
                            b.recs.push(Rec {
                                key: g.key,
                                sub,
                                matte: g.matte,
                                c: cc,
                                o: co,
                                aov: b.aovs.len() as u32,
                            });
                        }
                        b.set_front(s, z, recs[t], g.key, sub);
                    } else {
                        b.insert(s, z, g.key, sub, cc, co, g.matte, &[]);
                    }
                }
            }
        }
    }
    b.tested += tested;
    b.hits += hits;
}

/// Tests every live micropolygon of `g` against the samples its raster bound covers.
fn sample_grid(b: &mut Bucket, g: &ShadedGrid, kernel: QuadKernel, visible: &mut Vec<Visible>) {
    let cfg = b.cfg;
    let aw = g.aov_width;
    // Sampling window: the bucket region clipped by the grid's own bound.
    let Some(win) = g.window(&b.rect()) else {
        return;
    };
    g.micropolygons_in(win, visible);
    let fast = !b.keep_second
        && cfg.clip_planes.is_empty()
        && aw == 0
        && g.csg.is_none()
        && !g.smooth
        && g.ci.len() == g.xy.len()
        && g.oi.len() == g.xy.len()
        && g.depth.len() == g.xy.len();
    if fast {
        // Some micropolygon may lie behind the fronts drawn so far: check each.
        let occlusion = g.zmin > b.fzmin;
        if occlusion {
            b.refresh_pmax(win);
        }
        kernel.run(b, g, win, visible, occlusion);
        return;
    }
    let mut mean_aov = vec![0f32; aw];
    let mut interp_aov = vec![0f32; aw];
    let [wx0, wy0, wx1, wy1] = win;
    for &(m, k, mb) in visible.iter() {
        let Some(bx) = super::clip_box(mb, [wx0, wy0, wx1, wy1]) else {
            continue;
        };
        sample_micro(b, g, m, k, bx, &mut mean_aov, &mut interp_aov);
    }
}

/// Per micropolygon constants shared by its sample tests.
struct Micro<'a> {
    m: usize,
    /// The two triangles sharing the diagonal corner 0 – corner 2, as the old two-triangle
    /// test saw them: vertices (counter-clockwise), grid point indices, 1 / area, and the
    /// edges v2→v0 and v0→v1 whose values are the barycentric weights; None when degenerate.
    tris: [Option<Tri>; 2],
    cc: [f32; 3],
    co: [f32; 3],
    mean_aov: &'a [f32],
}

#[derive(Clone, Copy, Debug)]
struct Tri {
    v: [[f32; 2]; 3],
    idx: [usize; 3],
    inv_area: f32,
    e1: Edge,
    e2: Edge,
}

/// The general per-sample test of micropolygon `m` (first corner point `k`) against the
/// samples inside box `bx`. A convex micropolygon is one quad test (its four edges, then the
/// diagonal picks the triangle whose interpolation applies, so the result is that of the
/// two-triangle test); others fall back to two triangles.
fn sample_micro(
    b: &mut Bucket,
    g: &ShadedGrid,
    m: usize,
    k: usize,
    bx: [f32; 4],
    mean_aov: &mut [f32],
    interp_aov: &mut [f32],
) {
    let cfg = b.cfg;
    let nu = g.nu;
    let corner = [k, k + 1, k + nu + 1, k + nu];
    // Constant shading: one colour per micropolygon, the mean of its corners.
    let (cc, co) = flat_shade(g, &corner, mean_aov);
    let p = corner.map(|c| g.xy[c]);
    let mut tris = [None, None];
    for (t, tri) in [[0, 1, 2], [0, 2, 3]].into_iter().enumerate() {
        let mut v = tri.map(|i| p[i]);
        let mut idx = tri.map(|i| corner[i]);
        let area =
            (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
        if area == 0.0 || !area.is_finite() {
            continue;
        }
        if area < 0.0 {
            v.swap(1, 2);
            idx.swap(1, 2);
        }
        tris[t] = Some(Tri {
            v,
            idx,
            inv_area: 1.0 / area.abs(),
            e1: Edge::new(v[2], v[0]),
            e2: Edge::new(v[0], v[1]),
        });
    }
    let mp = Micro {
        m,
        tris,
        cc,
        co,
        mean_aov,
    };
    let (ccw, cw) = convexity(&p);
    if (ccw || cw) && mp.tris[0].is_some() && mp.tris[1].is_some() {
        // Outer edges counter-clockwise; the diagonal as triangle 0 sees it.
        let o = if ccw { [0, 1, 2, 3] } else { [0, 3, 2, 1] };
        let edges = [
            Edge::new(p[o[0]], p[o[1]]),
            Edge::new(p[o[1]], p[o[2]]),
            Edge::new(p[o[2]], p[o[3]]),
            Edge::new(p[o[3]], p[o[0]]),
        ];
        let diag0 = if ccw {
            Edge::new(p[2], p[0])
        } else {
            Edge::new(p[0], p[2])
        };
        for_samples(b, bx, |b, s, pos| {
            // Non-short-circuiting: four independent tests, one branch.
            let all = edges[0].inside(pos)
                & edges[1].inside(pos)
                & edges[2].inside(pos)
                & edges[3].inside(pos);
            if !all {
                return;
            }
            let t = if diag0.inside(pos) { 0 } else { 1 };
            hit(b, g, cfg, &mp, t, s, pos, interp_aov);
        });
    } else {
        for t in 0..2 {
            let Some(Tri { v, .. }) = mp.tris[t] else {
                continue;
            };
            let te = [
                Edge::new(v[1], v[2]),
                Edge::new(v[2], v[0]),
                Edge::new(v[0], v[1]),
            ];
            let tb = [
                v[0][0].min(v[1][0]).min(v[2][0]).max(bx[0]),
                v[0][1].min(v[1][1]).min(v[2][1]).max(bx[1]),
                v[0][0].max(v[1][0]).max(v[2][0]).min(bx[2]),
                v[0][1].max(v[1][1]).max(v[2][1]).min(bx[3]),
            ];
            if !(tb[0] <= tb[2] && tb[1] <= tb[3]) {
                continue;
            }
            for_samples(b, tb, |b, s, pos| {
                if te[0].inside(pos) & te[1].inside(pos) & te[2].inside(pos) {
                    hit(b, g, cfg, &mp, t, s, pos, interp_aov);
                }
            });
        }
    }
}

/// Tests a moving or out-of-focus grid: each sample sees the micropolygon's corners where
/// they are at its time (linear between keys), shifted by its lens position times their
/// circle of confusion, then tests the two triangles as the still path does. Only the
/// samples inside the micropolygon's bound over the whole shutter and lens are visited; a
/// fast-moving micropolygon is tested group of time slots by group (see [`timebins`]),
/// each group's samples only inside its bound over the group's times. Which samples are
/// visited never changes what a sample sees (a sample outside a bound cannot be inside the
/// micropolygon at its time), nor the order in which it meets micropolygons.
fn sample_grid_blurred(
    b: &mut Bucket,
    g: &ShadedGrid,
    times: &[f32],
    lens: &[[f32; 2]],
    bins: Option<&TimeBins>,
    lens_bins: Option<&TimeBins>,
    visible: &mut Vec<Visible>,
) {
    let cfg = b.cfg;
    let nu = g.nu;
    let aw = g.aov_width;
    let Some(win) = g.window(&b.rect()) else {
        return;
    };
    let [wx0, wy0, wx1, wy1] = win;
    let mut mean_aov = vec![0f32; aw];
    let mut interp_aov = vec![0f32; aw];
    g.micropolygons_in(win, visible);
    let dof = cfg.dof;
    // Time slots only help a moving grid.
    let bins = bins.filter(|t| g.motion.is_some() && t.trusted() && t.slots() > 1);
    let mut group_boxes: Vec<GroupBox> = Vec::new();
    for &(m, k, mb) in visible.iter() {
        let corner = [k, k + 1, k + nu + 1, k + nu];
        let Some(bx) = super::clip_box(mb, [wx0, wy0, wx1, wy1]) else {
            continue;
        };
        let (cc, co) = flat_shade(g, &corner, &mut mean_aov);
        let lens_bound = super::LensBound::new(g, &corner, dof.as_ref());
        let keys = super::KeyCorners::new(g, &corner);
        let mut test = |b: &mut Bucket, s: usize, pos: [f32; 2]| {
            if lens_bound
                .as_ref()
                .is_some_and(|lb| lb.misses(lens[s], pos))
            {
                return;
            }
            let (p, q) = match &keys {
                Some(k) => k.at(times[s], lens[s], dof.as_ref()),
                None => super::corners_at(g, &corner, times[s], lens[s], dof.as_ref()),
            };
            // Most samples under a moving bound are far from the micropolygon at their own
            // time: a box test (grown far beyond the edge functions' rounding, so it never
            // turns away a sample they would take) spares the triangles' set-up.
            if far_from(&p, pos) {
                return;
            }
            for (t, tri) in [[0usize, 1, 2], [0, 2, 3]].into_iter().enumerate() {
                let Some((v, idx, dq, area)) = super::ccw_triangle(&p, &q, &corner, tri) else {
                    continue;
                };
                if inside(edge(v[1], v[2], pos))
                    && inside(edge(v[2], v[0], pos))
                    && inside(edge(v[0], v[1], pos))
                {
                    let tri = BlurTri {
                        v,
                        idx,
                        dq,
                        inv_area: 1.0 / area.abs(),
                    };
                    let sub = (m as u32) << 1 | t as u32;
                    hit_blurred(
                        b,
                        g,
                        cfg,
                        &tri,
                        sub,
                        s,
                        pos,
                        &cc,
                        &co,
                        &mean_aov,
                        &mut interp_aov,
                    );
                    break;
                }
            }
        };
        if let (Some(lb), Some(cells)) = (&lens_bound, lens_bins) {
            if !cells.trusted() || !for_samples_in_lens_cells(b, cells, lb, bx, &mut test) {
                for_samples(b, bx, &mut test);
            }
            continue;
        }
        let Some(bins) = bins else {
            for_samples(b, bx, &mut test);
            continue;
        };
        let slots = bins.slots();
        let groups = timebins::groups(g, &corner, &mb, slots, cfg.spp[0] * cfg.spp[1]);
        if groups <= 1 || !slot_boxes(g, &corner, bins, groups, bx, dof.as_ref(), &mut group_boxes)
        {
            for_samples(b, bx, &mut test);
            continue;
        }
        for (gb, k0, k1, sweep) in &group_boxes {
            for_samples_in_slots(b, bins, *k0, *k1, *gb, sweep.as_ref(), &mut test);
        }
    }
}

/// A group of time slots of a moving micropolygon: the bound of its positions over the
/// group's times (within the bucket's), the slots `k0..=k1`, and the region it sweeps when
/// the bound spans a few pixels both ways (where a box is mostly empty).
type GroupBox = ([f32; 4], usize, usize, Option<Sweep>);

/// Whether `pos` lies outside the box of corners `p` by more than 10⁻³ pixel plus 10⁻⁵ of
/// the coordinates: outside both triangles whatever the rounding of their edge functions.
#[inline]
pub(super) fn far_from(p: &[[f32; 2]; 4], pos: [f32; 2]) -> bool {
    let [x0, y0, x1, y1] = super::corner_box(p);
    let m = 1e-3 + 1e-5 * (pos[0].abs() + pos[1].abs() + x1.abs() + y1.abs() + x0.abs() + y0.abs());
    // False for NaN corners: the triangles decide.
    pos[0] < x0 - m || pos[0] > x1 + m || pos[1] < y0 - m || pos[1] > y1 + m
}

/// The [`GroupBox`]es of the `groups` groups of time slots of a moving micropolygon (each
/// box within `bx`), into `out`: groups whose bound misses `bx` or that hold no sample are
/// left out. False when a bound cannot be trusted (test the whole `bx`).
fn slot_boxes(
    g: &ShadedGrid,
    corner: &[usize; 4],
    bins: &TimeBins,
    groups: usize,
    bx: [f32; 4],
    dof: Option<&crate::render::camera::Dof>,
    out: &mut Vec<GroupBox>,
) -> bool {
    out.clear();
    let slots = bins.slots();
    // Only the groups of the times it can be in `bx`: a micropolygon crossing many buckets
    // is in each for a few of its groups.
    let window = timebins::grown_by_lens(bx, timebins::lens_pad(g, corner, dof));
    let Some((ta, tb)) = window.map_or(Some((f32::NEG_INFINITY, f32::INFINITY)), |w| {
        timebins::time_window(g, corner, w)
    }) else {
        return true;
    };
    // A sample's slot is monotonic in its time, so those that can be hit lie in slots
    // ka..=kb; group q holds slots q·slots/groups ..= (q + 1)·slots/groups − 1.
    let groups = groups.min(timebins::MAX_SLOTS);
    let (ka, kb) = (
        bins.slot_of_time(ta.max(0.0)),
        bins.slot_of_time(tb.min(1.0)),
    );
    let group_of = |k: usize| {
        let mut q = k * groups / slots;
        while q > 0 && q * slots / groups > k {
            q -= 1;
        }
        while q + 1 < groups && (q + 1) * slots / groups <= k {
            q += 1;
        }
        q
    };
    // The groups holding samples with their time intervals. A later slot's times are never
    // earlier (slots are monotonic in time), so each group's interval reaches at most to the
    // next group's start: consecutive groups share the corners evaluated there.
    let mut spans: [(usize, usize, f32, f32); timebins::MAX_SLOTS] =
        [(0, 0, 0.0, 0.0); timebins::MAX_SLOTS];
    let mut n = 0;
    for q in group_of(ka)..=group_of(kb) {
        let (k0, k1) = (q * slots / groups, (q + 1) * slots / groups - 1);
        if let Some((t0, t1)) = bins.interval(k0, k1) {
            spans[n] = (k0, k1, t0, t1);
            n += 1;
        }
    }
    let Some(&(_, _, first, _)) = spans[..n].first() else {
        return true;
    };
    let mut at_start = timebins::corners(g, corner, first);
    for i in 0..n {
        let (k0, k1, t0, t1) = spans[i];
        let t_end = spans.get(i + 1).filter(|_| i + 1 < n).map_or(t1, |s| s.2);
        let at_end = timebins::corners(g, corner, t_end);
        let ends = [at_start, at_end];
        let Some((gb, pad)) = timebins::bound_and_pad(g, corner, &ends, t0, t_end, dof) else {
            return false;
        };
        at_start = ends[1];
        if let Some(gb) = super::clip_box(gb, bx) {
            // A hull pays for its set-up and its rows' only where the box is wide and tall.
            let sweep = (gb[2] - gb[0] > SWEEP_MIN && gb[3] - gb[1] > SWEEP_MIN)
                .then(|| timebins::sweep_between(g, corner, &ends, t0, t_end, pad))
                .flatten();
            out.push((gb, k0, k1, sweep));
        }
    }
    true
}

/// [`for_samples`] for a still micropolygon under depth of field, lens cell group by group:
/// the samples of a group of lens cells are visited only inside the micropolygon's bound
/// through that group's lens positions (`lb.box_for` their measured range, within `bx`).
/// False (nothing visited) when its blur is small beside its size: test `bx` at once.
fn for_samples_in_lens_cells(
    b: &mut Bucket,
    cells: &TimeBins,
    lb: &super::LensBound,
    bx: [f32; 4],
    f: &mut impl FnMut(&mut Bucket, usize, [f32; 2]),
) -> bool {
    let l = b.cfg.lens_slots;
    let travel = lb.travel();
    // About one group per half its own size (plus a pixel) of blur. Under callgrind on
    // examples/dof.rib at 160×100 (36 samples a pixel, 8 × 8 cells), one group per size
    // left half the visits to micropolygons blurred over one or two of their sizes (2.74 G
    // instructions against 2.79 G without cells); per half size 2.31 G, per third 2.33 G,
    // per quarter 2.42 G (the groups' set-up against the samples they spare).
    let n = 2.0 * travel[0].max(travel[1]) / (lb.size() + 1.0);
    if !(n >= 2.0) {
        return false;
    }
    let groups = (n as usize).min(l);
    for gy in 0..groups {
        let (y0, y1) = (gy * l / groups, (gy + 1) * l / groups - 1);
        for gx in 0..groups {
            let (x0, x1) = (gx * l / groups, (gx + 1) * l / groups - 1);
            // The lens range of the group's samples: the union over its rows of cells.
            let mut r = [[f32::INFINITY, f32::NEG_INFINITY]; 2];
            for cy in y0..=y1 {
                if let Some(c) = cells.ranges(cy * l + x0, cy * l + x1) {
                    for a in 0..2 {
                        r[a][0] = r[a][0].min(c[a][0]);
                        r[a][1] = r[a][1].max(c[a][1]);
                    }
                }
            }
            if !(r[0][0] <= r[0][1]) {
                continue;
            }
            let gb = lb.box_for(r[0], r[1]);
            let Some(gb) = super::clip_box(gb, bx) else {
                continue;
            };
            for cy in y0..=y1 {
                for_samples_in_slots(b, cells, cy * l + x0, cy * l + x1, gb, None, &mut *f);
            }
        }
    }
    true
}

/// Pixel × time-slot cells a bucket's time bins may hold (more slots than samples per pixel
/// only while under this).
const MAX_TIME_CELLS: usize = 1 << 20;

/// Width and height (pixels) a group's box must exceed for its swept region to be used.
const SWEEP_MIN: f32 = 3.0;

/// [`for_samples`] over the samples of time slots `k0..=k1` only; with a `sweep`, in each
/// pixel row only those within the row's span of the swept region.
#[inline]
fn for_samples_in_slots(
    b: &mut Bucket,
    bins: &TimeBins,
    k0: usize,
    k1: usize,
    bx: [f32; 4],
    sweep: Option<&Sweep>,
    mut f: impl FnMut(&mut Bucket, usize, [f32; 2]),
) {
    let Some(((i0, i1), (j0, j1))) = b.pixels_of(bx) else {
        return;
    };
    let w = b.lay.width;
    let mut tested = 0u64;
    for j in j0..=j1 {
        // Row j's samples lie in [y0 + j, y0 + j + 1].
        let (mut rx0, mut rx1, mut ri0, mut ri1) = (bx[0], bx[2], i0, i1);
        if let Some(sw) = sweep {
            let y = (b.lay.y0 + j as i32) as f32;
            let Some((lo, hi)) = sw.x_range(y.max(bx[1]), (y + 1.0).min(bx[3])) else {
                continue;
            };
            (rx0, rx1) = (rx0.max(lo), rx1.min(hi));
            let Some(((a, c), _)) = b.pixels_of([rx0, bx[1], rx1, bx[3]]) else {
                continue;
            };
            (ri0, ri1) = (a.max(i0), c.min(i1));
        }
        for i in ri0..=ri1 {
            bins.each(j * w + i, k0, k1, |s, pos| {
                if pos[0] < rx0 || pos[0] > rx1 || pos[1] < bx[1] || pos[1] > bx[3] {
                    return;
                }
                tested += 1;
                f(b, s, pos);
            });
        }
    }
    b.tested += tested;
}

/// Canonical edge function, for blurred micropolygons (whose corners move per sample, so
/// edges cannot be set up once) and as the reference [`Edge`] is tested against: the same bits for edge (a, b) and (b, a) up to sign, and
/// whether this direction owns samples exactly on the edge (exactly one of the two does).
#[inline]
pub(super) fn edge(a: [f32; 2], b: [f32; 2], p: [f32; 2]) -> (f32, bool) {
    if (a[0], a[1]) < (b[0], b[1]) {
        (
            (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]),
            true,
        )
    } else {
        (
            -((a[0] - b[0]) * (p[1] - b[1]) - (a[1] - b[1]) * (p[0] - b[0])),
            false,
        )
    }
}

#[inline]
pub(super) fn inside(e: (f32, bool)) -> bool {
    e.0 > 0.0 || (e.0 == 0.0 && e.1)
}

/// A triangle of a blurred micropolygon as one sample sees it.
struct BlurTri {
    v: [[f32; 2]; 3],
    idx: [usize; 3],
    /// Depth (1/z or z) at the vertices.
    dq: [f32; 3],
    inv_area: f32,
}

/// [`hit`] for a blurred micropolygon (its vertices and depths given per sample).
#[allow(clippy::too_many_arguments)]
#[inline]
fn hit_blurred(
    b: &mut Bucket,
    g: &ShadedGrid,
    cfg: &HiderConfig,
    tri: &BlurTri,
    sub: u32,
    s: usize,
    pos: [f32; 2],
    cc: &[f32; 3],
    co: &[f32; 3],
    mean_aov: &[f32],
    interp_aov: &mut [f32],
) {
    let (v, idx, dq) = (tri.v, tri.idx, tri.dq);
    let e1 = edge(v[2], v[0], pos);
    let e2 = edge(v[0], v[1], pos);
    let (w1, w2) = (e1.0 * tri.inv_area, e2.0 * tri.inv_area);
    let w0 = 1.0 - w1 - w2;
    let qz = dq[0] + w1 * (dq[1] - dq[0]) + w2 * (dq[2] - dq[0]);
    let z = if cfg.perspective { 1.0 / qz } else { qz };
    if !(z >= cfg.near && z <= cfg.far) {
        return;
    }
    if z > b.fz[s] && !b.keep_second {
        b.hits += 1;
        return;
    }
    if !cfg.clip_planes.is_empty() {
        let p = cfg.camera_point(pos[0], pos[1], z);
        if cfg
            .clip_planes
            .iter()
            .any(|pl| pl.truncate().dot(p) + pl.w > 0.0)
        {
            return;
        }
    }
    b.hits += 1;
    if g.smooth {
        let (c, o) = interpolate(g, idx, [w0, w1, w2], interp_aov);
        b.insert(s, z, g.key, sub, c, o, g.matte, interp_aov);
    } else {
        b.insert(s, z, g.key, sub, *cc, *co, g.matte, mean_aov);
    }
}

/// Calls `f(bucket, sample index, position)` for every sample of the bucket inside the closed
/// box `bx` (x0, y0, x1, y1), visiting only the strata the box reaches.
#[inline]
fn for_samples(b: &mut Bucket, bx: [f32; 4], mut f: impl FnMut(&mut Bucket, usize, [f32; 2])) {
    let Some(((c0, c1), (r0, r1))) = b.lay.box_strata(bx) else {
        return;
    };
    let cols = b.lay.cols;
    let mut tested = 0u64;
    for r in r0..=r1 {
        for s in r * cols + c0..=r * cols + c1 {
            let pos = [b.x[s], b.y[s]];
            if pos[0] < bx[0] || pos[0] > bx[2] || pos[1] < bx[1] || pos[1] > bx[3] {
                continue;
            }
            tested += 1;
            f(b, s, pos);
        }
    }
    b.tested += tested;
}

/// Sample `s` at `pos` lies in triangle `t` of micropolygon `mp`: interpolate its depth
/// (and colour when smooth) and insert it.
#[allow(clippy::too_many_arguments)]
#[inline]
fn hit(
    b: &mut Bucket,
    g: &ShadedGrid,
    cfg: &HiderConfig,
    mp: &Micro,
    t: usize,
    s: usize,
    pos: [f32; 2],
    interp_aov: &mut [f32],
) {
    let Some(Tri {
        idx,
        inv_area,
        e1,
        e2,
        ..
    }) = mp.tris[t]
    else {
        return;
    };
    let (w1, w2) = (e1.eval(pos) * inv_area, e2.eval(pos) * inv_area);
    let w0 = 1.0 - w1 - w2;
    // Relative to vertex 0, so a constant depth stays exact.
    let dq = [g.depth[idx[0]], g.depth[idx[1]], g.depth[idx[2]]];
    let q = dq[0] + w1 * (dq[1] - dq[0]) + w2 * (dq[2] - dq[0]);
    let z = if cfg.perspective { 1.0 / q } else { q };
    if !(z >= cfg.near && z <= cfg.far) {
        return;
    }
    // Behind this sample's opaque front: nothing to do unless the second depth is kept.
    if z > b.fz[s] && !b.keep_second {
        b.hits += 1;
        return;
    }
    if !cfg.clip_planes.is_empty() {
        let p = cfg.camera_point(pos[0], pos[1], z);
        if cfg
            .clip_planes
            .iter()
            .any(|pl| pl.truncate().dot(p) + pl.w > 0.0)
        {
            return;
        }
    }
    let sub = (mp.m as u32) << 1 | t as u32;
    if g.smooth {
        let (c, o) = interpolate(g, idx, [w0, w1, w2], interp_aov);
        put(b, g, mp.m, s, z, sub, c, o, interp_aov);
    } else {
        put(b, g, mp.m, s, z, sub, mp.cc, mp.co, mp.mean_aov);
    }
}

/// Inserts a visible point, or keeps a CSG grid's hit for [`resolve_csg`].
#[allow(clippy::too_many_arguments)]
#[inline]
fn put(
    b: &mut Bucket,
    g: &ShadedGrid,
    m: usize,
    s: usize,
    z: f32,
    sub: u32,
    c: [f32; 3],
    o: [f32; 3],
    aov: &[f32],
) {
    b.hits += 1;
    match &g.csg {
        None => b.insert(s, z, g.key, sub, c, o, g.matte, aov),
        Some(cg) => {
            b.csg.push(CsgHit {
                sample: s as u32,
                z,
                key: g.key,
                sub,
                leaf: cg.leaf,
                root: cg.root,
                entering: cg.entering.get(m).copied().unwrap_or(true),
                payload: b.csg_data.len() as u32,
            });
            b.csg_data.push((c, o, g.matte));
            b.csg_aovs.extend_from_slice(aov);
        }
    }
}

/// Keeps the CSG hits on their solids' boundaries as visible points.
fn resolve_csg(b: &mut Bucket) {
    let mut hits = std::mem::take(&mut b.csg);
    let data = std::mem::take(&mut b.csg_data);
    let aovs = std::mem::take(&mut b.csg_aovs);
    let aw = b.cfg.channels() - 5;
    let mut keep = Vec::new();
    csg::resolve(&b.cfg.csg, &mut hits, |h| keep.push(*h));
    for h in keep {
        let (c, o, matte) = data[h.payload as usize];
        let p = h.payload as usize;
        let aov = &aovs[p * aw..(p + 1) * aw];
        // Counted when found.
        b.insert(h.sample as usize, h.z, h.key, h.sub, c, o, matte, aov);
    }
}

/// A micropolygon's constant shading: the mean colour and opacity of its four corners (and
/// of their output variables, into `mean_aov`).
#[inline]
pub(super) fn flat_shade(
    g: &ShadedGrid,
    corner: &[usize; 4],
    mean_aov: &mut [f32],
) -> ([f32; 3], [f32; 3]) {
    // ShadingInterpolation "constant": the mean of the four corners. Taking the first corner
    // alone (as Aqsis does) was tried against the published renders: sharper anti-aliased
    // checks, but most PRMan/BMRT pictures (bricks, planks, the limbo frames) moved further
    // away, 68 -> 67 pictures at SSIM >= 0.9. Each sample taking its nearest corner (sharp
    // and unshifted) was no better: bump-mapped bricks moved away, 69 -> 67.
    let aw = g.aov_width;
    let mut cc = [0f32; 3];
    let mut co = [0f32; 3];
    for &c in corner {
        for q in 0..3 {
            cc[q] += g.ci[c][q] * 0.25;
            co[q] += g.oi[c][q] * 0.25;
        }
    }
    if aw > 0 && mean_aov.len() == aw {
        mean_aov.iter_mut().for_each(|v| *v = 0.0);
        for &c in corner {
            for q in 0..aw {
                mean_aov[q] += g.aov[c * aw + q] * 0.25;
            }
        }
    }
    (cc, co)
}

/// Smooth shading at a sample: colour, opacity and output variables (into `interp_aov`)
/// interpolated from a triangle's grid points `idx` with barycentric weights `w`.
#[inline]
fn interpolate(
    g: &ShadedGrid,
    idx: [usize; 3],
    w: [f32; 3],
    interp_aov: &mut [f32],
) -> ([f32; 3], [f32; 3]) {
    let aw = g.aov_width;
    let mut c = [0f32; 3];
    let mut o = [0f32; 3];
    for (vi, &gi) in idx.iter().enumerate() {
        for q in 0..3 {
            c[q] += w[vi] * g.ci[gi][q];
            o[q] += w[vi] * g.oi[gi][q];
        }
    }
    for q in 0..aw {
        interp_aov[q] = w[0] * g.aov[idx[0] * aw + q]
            + w[1] * g.aov[idx[1] * aw + q]
            + w[2] * g.aov[idx[2] * aw + q];
    }
    (c, o)
}

/// Composites each sample's visible points front to back into the buffer (pixel-major, as
/// [`SampleBuffer`] orders its samples).
fn resolve(b: &Bucket, buf: &mut SampleBuffer) {
    let lay = b.lay;
    let ch = buf.channels;
    let mut list: Vec<u32> = Vec::new();
    for j in 0..lay.height {
        for sy in 0..lay.ys {
            let srow = (j * lay.ys + sy) * lay.cols;
            for i in 0..lay.width {
                let pm = ((j * lay.width + i) * lay.ys + sy) * lay.xs;
                for sx in 0..lay.xs {
                    let s = srow + i * lay.xs + sx;
                    composite(
                        b,
                        s,
                        &mut list,
                        &mut buf.values[(pm + sx) * ch..(pm + sx + 1) * ch],
                    );
                }
            }
        }
    }
}

/// [`resolve`] straight into the gather filter's form (r g b a z buffers only).
fn resolve_prepared(b: &Bucket, ctx: &PrepareCtx) -> Prepared {
    let lay = b.lay;
    let spp = lay.xs * lay.ys;
    let mut p = Prepared::new(ctx, lay.x0, lay.y0, lay.width, lay.height, spp);
    let lanes = p.lanes();
    let mut list: Vec<u32> = Vec::new();
    let (mut xs, mut ys, mut zs) = (
        vec![f32::NAN; lanes],
        vec![f32::NAN; lanes],
        vec![0f32; spp],
    );
    // No transparent points and no second depth: each sample is its front (or nothing).
    let fronts_only = b.heads.is_empty() && b.cfg.depth_filter != DepthFilter::Midpoint;
    for j in 0..lay.height {
        for i in 0..lay.width {
            let pix = j * lay.width + i;
            let rgba = p.rgba_mut(pix);
            for sy in 0..lay.ys {
                let srow = (j * lay.ys + sy) * lay.cols + i * lay.xs;
                let k0 = sy * lay.xs;
                copy_short(&mut xs[k0..k0 + lay.xs], &b.x[srow..srow + lay.xs]);
                copy_short(&mut ys[k0..k0 + lay.xs], &b.y[srow..srow + lay.xs]);
                for sx in 0..lay.xs {
                    let (s, k) = (srow + sx, k0 + sx);
                    if fronts_only {
                        // `composite` for a sample seeing at most its opaque front.
                        zs[k] = b.fz[s];
                        let r = b.fref[s];
                        let (c, a) = match b.recs.get(r as usize) {
                            Some(r) if !r.matte => {
                                let o = r.o;
                                let w = (o[0] + o[1] + o[2]) * (1.0 / 3.0);
                                ([0.0 + r.c[0], 0.0 + r.c[1], 0.0 + r.c[2]], 0.0 + w)
                            }
                            _ => ([0.0; 3], 0.0),
                        };
                        rgba[k] = c[0];
                        rgba[lanes + k] = c[1];
                        rgba[2 * lanes + k] = c[2];
                        rgba[3 * lanes + k] = a;
                        continue;
                    }
                    let mut out = [0f32; 5];
                    composite(b, s, &mut list, &mut out);
                    for c in 0..4 {
                        rgba[c * lanes + k] = out[c];
                    }
                    zs[k] = out[4];
                }
            }
            let q = (lay.x0 + i as i32, lay.y0 + j as i32);
            p.finish_pixel(ctx, pix, q, &xs, &ys, &zs);
        }
    }
    p
}

/// `dst.copy_from_slice(src)` for the few floats of a pixel's stratum row, without a call to
/// `memcpy` for the usual four.
#[inline(always)]
fn copy_short(dst: &mut [f32], src: &[f32]) {
    if let (Ok(d), Ok(s)) = (
        <&mut [f32; 4]>::try_from(&mut *dst),
        <&[f32; 4]>::try_from(src),
    ) {
        *d = *s;
    } else {
        dst.copy_from_slice(src);
    }
}

/// Composites sample `s`'s visible points front to back into `out` (r g b a z and the
/// output variables, all zero on entry).
#[inline]
fn composite(b: &Bucket, s: usize, list: &mut Vec<u32>, out: &mut [f32]) {
    let cfg = b.cfg;
    let naov = out.len() - 5;
    let fz = b.fz[s];
    out[4] = if cfg.depth_filter == DepthFilter::Midpoint && b.second[s].is_finite() {
        0.5 * (fz + b.second[s])
    } else {
        fz
    };
    let fref = b.fref[s];
    let mut cur = if b.heads.is_empty() { NONE } else { b.heads[s] };
    if cur == NONE {
        // Only the opaque front (the common case).
        if fref != NONE {
            let r = &b.recs[fref as usize];
            if !r.matte {
                // The general loop below with one point: the same operations.
                let o = r.o;
                let w = (o[0] + o[1] + o[2]) * (1.0 / 3.0);
                for q in 0..3 {
                    out[q] = 0.0 + r.c[q];
                }
                out[3] = 0.0 + w;
                for q in 0..naov {
                    out[5 + q] = 0.0 + w * b.aovs[r.aov as usize + q];
                }
            }
        }
        return;
    }
    list.clear();
    while cur != NONE {
        list.push(cur);
        cur = b.points[cur as usize].next;
    }
    if list.len() > 1 {
        list.sort_unstable_by(|&x, &y| {
            let (p, q) = (&b.points[x as usize], &b.points[y as usize]);
            p.z.total_cmp(&q.z)
                .then(p.key.cmp(&q.key))
                .then(p.sub.cmp(&q.sub))
        });
    }
    let stop = 1.0 - cfg.othreshold;
    let mut tr = [1f32; 3];
    let mut alpha = 0f32;
    let mut rgb = [0f32; 3];
    // The transparent points before the opaque front, in order, then the front itself.
    let points = list.iter().map(|&pi| {
        let p = &b.points[pi as usize];
        (p.matte, p.c, p.o, p.aov)
    });
    let last = (fref != NONE).then(|| {
        let r = &b.recs[fref as usize];
        (r.matte, r.c, r.o, r.aov)
    });
    for (matte, c, o, aov) in points.chain(last) {
        if !matte {
            let w = (tr[0] * o[0] + tr[1] * o[1] + tr[2] * o[2]) * (1.0 / 3.0);
            for q in 0..3 {
                rgb[q] += tr[q] * c[q];
            }
            alpha += w;
            for q in 0..naov {
                out[5 + q] += w * b.aovs[aov as usize + q];
            }
        }
        for q in 0..3 {
            tr[q] *= 1.0 - o[q];
        }
        if tr[0] <= stop && tr[1] <= stop && tr[2] <= stop {
            break;
        }
    }
    out[..3].copy_from_slice(&rgb);
    out[3] = alpha;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precomputed_edges_give_the_reference_bits() {
        // Pseudo-random vertices and points, plus points exactly on an edge and its ends.
        let mut k = 12345u32;
        let mut r = || {
            k = k.wrapping_mul(747796405).wrapping_add(2891336453);
            (k >> 8) as f32 / (1u32 << 24) as f32 * 40.0 - 20.0
        };
        for _ in 0..2000 {
            let (a, b) = ([r(), r()], [r(), r()]);
            let on = [a[0] + 0.5 * (b[0] - a[0]), a[1] + 0.5 * (b[1] - a[1])];
            for p in [[r(), r()], a, b, on] {
                for (x, y) in [(a, b), (b, a)] {
                    let e = Edge::new(x, y);
                    let want = edge(x, y, p);
                    assert_eq!(e.eval(p).to_bits(), want.0.to_bits());
                    assert_eq!(e.inside(p), inside(want));
                }
                // Exactly one direction owns a sample lying on the edge.
                if Edge::new(a, b).eval(p) == 0.0 && a != b {
                    assert!(Edge::new(a, b).inside(p) ^ Edge::new(b, a).inside(p));
                }
            }
        }
    }
}
