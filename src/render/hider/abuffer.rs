//! The A-buffer hider (`Hider "abuffer"`), after Carpenter (1984) as Watt & Watt §4.4.1 give it.
//!
//! Input: shaded micropolygon grids overlapping a bucket's sample region. Output: a
//! [`SampleBuffer`] with one sample per subpixel cell (`masksize`² per pixel, at the cell
//! centres) holding that cell's resolved premultiplied colour, alpha and depth, so the film's
//! box filter gives the area average and other pixel filters weight the subpixels.
//!
//! Invariants:
//! * each micropolygon (the quad of four grid points) becomes, in every pixel it touches, a
//!   fragment with one colour, one opacity, a depth range and a coverage mask; the mask is the
//!   XOR of per-edge masks ("1s to the right of the edge"), computed on the fly (no 45×45
//!   table, so 16×16 costs no table memory). Each edge is a lattice path that follows the edge
//!   by area (see [`rasterize`]): a pixel crossed by an edge is covered to within one cell
//!   (1/w²) of its exact area at every orientation, not only for edges far from horizontal;
//! * an edge's path is computed from its endpoints in a canonical order, so two polygons
//!   sharing an edge get complementary masks: their union has no holes (Watt & Watt Fig 4.20),
//!   and near shared vertices paths follow the cell centres so that corners of 45° or more
//!   never overlap;
//! * fragments live in one pooled `Vec` per bucket with index links and a free list; adjacent
//!   micropolygons of one grid with disjoint masks and touching depth ranges are merged (OR of
//!   masks, area-weighted colour) so a diced surface leaves no seams; the pool is bounded,
//!   and hitting the bound is reported once per render through [`Hider::finish`];
//! * a grid that moves (motion blur) or is seen through a lens (depth of field) is point
//!   sampled instead: each cell is a sample at its centre with its own shutter time and lens
//!   position, stratified over the pixel's cells and hashed from (pixel, cell, seed) like the
//!   Z-buffer's (see [`fragment_grid_blurred`]);
//! * grids are taken front to back (zmin, then key), so a pixel's fragments arrive in the
//!   same order whatever the bucket size;
//! * the resolve walks each pixel's fragments front to back in the total order
//!   (zmin, grid key, micropolygon) with a search mask; fragments whose depth ranges overlap
//!   are blended over their common cells by Carpenter's zmin/zmax rule, so the image does not
//!   depend on the order grids arrive in (transparent layers commute).

// Colour loops index several parallel arrays by channel.
#![allow(clippy::needless_range_loop)]

use crate::num::floor_i32;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::diag::{Diag, Diagnostics};
use crate::film::SampleBuffer;
use crate::scene::ParamList;

use super::super::camera::PixelRect;
use super::super::sampler::time_and_lens;
use super::super::stats::Stats;
use super::zbuffer::{edge as zedge, inside as zinside};
use super::{shade_all, DepthFilter, GridSource, Hider, HiderConfig, ShadedGrid};

const NONE: u32 = u32::MAX;

/// A coverage mask of up to 16×16 bits: row `j` (top to bottom in raster y) occupies bits
/// `j·W .. j·W + W`, cell `i` of the row bit `j·W + i`. A row never straddles two words.
pub type Mask = [u64; 4];

/// Default bound on fragments per bucket (≈ 90 MB); see [`ABuffer::with_limit`].
pub const DEFAULT_FRAGMENT_LIMIT: usize = 1 << 20;

#[inline]
fn and(a: &Mask, b: &Mask) -> Mask {
    [a[0] & b[0], a[1] & b[1], a[2] & b[2], a[3] & b[3]]
}
#[inline]
fn andnot(a: &Mask, b: &Mask) -> Mask {
    [a[0] & !b[0], a[1] & !b[1], a[2] & !b[2], a[3] & !b[3]]
}
#[inline]
fn or(a: &Mask, b: &Mask) -> Mask {
    [a[0] | b[0], a[1] | b[1], a[2] | b[2], a[3] | b[3]]
}
#[inline]
fn is_zero(a: &Mask) -> bool {
    (a[0] | a[1] | a[2] | a[3]) == 0
}
/// Number of covered cells.
#[inline]
pub fn popcount(a: &Mask) -> u32 {
    a.iter().map(|w| w.count_ones()).sum()
}

/// Calls `f(bit)` for every set bit.
#[inline]
fn for_bits(m: &Mask, mut f: impl FnMut(usize)) {
    for (w, &word) in m.iter().enumerate() {
        let mut x = word;
        while x != 0 {
            let b = x.trailing_zeros() as usize;
            f(w * 64 + b);
            x &= x - 1;
        }
    }
}

/// The mask with every cell of a `w`×`w` pixel set.
pub fn full_mask(w: usize) -> Mask {
    let bits = w * w;
    let mut m = [0u64; 4];
    for (k, word) in m.iter_mut().enumerate() {
        let lo = k * 64;
        if bits >= lo + 64 {
            *word = u64::MAX;
        } else if bits > lo {
            *word = (1u64 << (bits - lo)) - 1;
        }
    }
    m
}

/// XORs the cells `from..w` of row `row` (of a `w`-wide mask) into `m`.
#[inline]
fn flip_row(m: &mut Mask, w: usize, row: usize, from: usize) {
    if from >= w {
        return;
    }
    let bit = row * w;
    let bits = ((1u64 << w) - 1) & !((1u64 << from) - 1);
    m[bit / 64] ^= bits << (bit % 64);
}

/// XORs rows `j0..j1` of column `col` (of a `w`-wide mask, `w = 1 << sh`) into `m`.
#[inline]
fn flip_col(m: &mut Mask, sh: u32, col: usize, j0: usize, j1: usize) {
    // Bit 0 of every row that one word holds.
    let pat: u64 = match sh {
        2 => 0x1111_1111_1111_1111,
        3 => 0x0101_0101_0101_0101,
        _ => 0x0001_0001_0001_0001,
    };
    let wsh = 6 - sh; // log2 of the rows per word
    let mut j = j0;
    while j < j1 {
        let word = j >> wsh;
        let first = word << wsh;
        let end = (first + (1 << wsh)).min(j1);
        let (lo, hi) = ((j - first) << sh, (end - first) << sh);
        let range = if hi >= 64 { u64::MAX } else { (1u64 << hi) - 1 } & (u64::MAX << lo);
        m[word] ^= (pat & range) << col;
        j = end;
    }
}

/// The lattice line (cell boundary) nearest to `t` cells, rounding halves down: the cell
/// centres in `[t0, t1)` are those of cells `snap(t0)..snap(t1)`.
#[inline]
fn snap(t: f32) -> i64 {
    let x = t - 0.5;
    let i = x as i64;
    i + ((i as f32) < x) as i64
}

/// `⌊x⌋` by integer conversion (the `floorf` call is a library call without SSE4.1 and
/// dominated this loop); saturates far outside raster range, 0 for NaN.
#[inline]
fn floor_i(x: f32) -> i64 {
    let i = x as i64;
    i - ((i as f32) > x) as i64
}

/// Masks of a rectangle of pixels, addressed by global subpixel row and column.
struct Window<'m> {
    masks: &'m mut [Mask],
    w: usize,
    /// log2 w: global cell → pixel is a shift (w is a power of two).
    shift: u32,
    px0: i64,
    px1: i64,
    py0: i64,
    npx: usize,
    /// Global subpixel rows and columns of the window: `r0..r1`, `c0..c1`.
    r0: i64,
    r1: i64,
    c0: i64,
    c1: i64,
}

impl Window<'_> {
    /// XORs the cells of global row `r` (inside the window) from global column `x` rightwards.
    #[inline]
    fn flip_right(&mut self, r: i64, x: i64) {
        let (sh, low) = (self.shift, self.w as i64 - 1);
        let py = r >> sh;
        let row = (r & low) as usize;
        let line = (py - self.py0) as usize * self.npx;
        let pxe = x >> sh;
        if pxe > self.px1 {
            return;
        }
        let first = if pxe < self.px0 {
            self.px0
        } else {
            let from = (x & low) as usize;
            flip_row(
                &mut self.masks[line + (pxe - self.px0) as usize],
                self.w,
                row,
                from,
            );
            pxe + 1
        };
        for px in first..=self.px1 {
            flip_row(
                &mut self.masks[line + (px - self.px0) as usize],
                self.w,
                row,
                0,
            );
        }
    }

    /// XORs the cells of global column `c` (inside the window) in global rows `ra..rb`.
    #[inline]
    fn flip_column(&mut self, c: i64, ra: i64, rb: i64) {
        let (sh, wi) = (self.shift, self.w as i64);
        let (ra, rb) = (ra.max(self.r0), rb.min(self.r1));
        if ra >= rb {
            return;
        }
        let px = c >> sh;
        let col = (c & (wi - 1)) as usize;
        for py in (ra >> sh)..=((rb - 1) >> sh) {
            let base = py * wi;
            let j0 = (ra.max(base) - base) as usize;
            let j1 = (rb.min(base + wi) - base) as usize;
            let k = (py - self.py0) as usize * self.npx + (px - self.px0) as usize;
            flip_col(&mut self.masks[k], sh, col, j0, j1);
        }
    }
}

/// Subpixel rows (columns) at each end of a steep (shallow) edge whose riser (step) is placed
/// by the cell centres, as point sampling would: there the paths of edges meeting at the
/// vertex are too close for independent rounding, which could cross them and leave cells
/// covered twice by neighbouring polygons. Beyond, edges at usual micropolygon angles are
/// more than a cell apart.
const GUARD: i64 = 2;

/// Rounds an edge's exact per-row (or per-column) cell counts so that every run of rows
/// crossing one pixel stays within half a cell of the exact area: the running sum is rounded,
/// not each count. A run is named by `key` (the pixel); a new key starts a new sum.
struct Dither {
    key: (i64, i64),
    sum: f32,
    done: i64,
}

impl Dither {
    fn new() -> Dither {
        Dither {
            key: (i64::MIN, i64::MIN),
            sum: 0.0,
            done: 0,
        }
    }
    /// The whole-cell count for exact count `v` ∈ [0, w) of run `key`: `⌊v⌋` or `⌈v⌉`, the
    /// nearest (cell centres) when `centre`, else whichever keeps the run's sum closest.
    #[inline]
    fn step(&mut self, key: (i64, i64), v: f32, centre: bool) -> i64 {
        if key != self.key {
            *self = Dither {
                key,
                sum: 0.0,
                done: 0,
            };
        }
        self.sum += v;
        // v and the sum are ≥ 0, so truncation is the floor (and a NaN gives 0, no panic).
        let n = if centre {
            (v + 0.5) as i64
        } else {
            let fl = v as i64;
            let cl = fl + (v > fl as f32) as i64;
            ((self.sum + 0.5) as i64 - self.done).max(fl).min(cl)
        };
        self.done += n;
        n
    }
    fn reset(&mut self) {
        self.key = (i64::MIN, i64::MIN);
    }
}

/// Rasterises the polygon `poly` (raster coordinates, any winding, even-odd) into the
/// `w`×`w` masks of the pixels `[px0, px1] × [py0, py1]`, stored row-major in `masks`
/// (cleared first).
///
/// Every edge becomes a lattice path (along cell boundaries) between its endpoints snapped to
/// the nearest lattice points, and the mask is the set of cells inside the closed lattice
/// curve — the XOR of the per-edge masks "cells whose leftward ray crosses the edge's path",
/// Watt & Watt's "1s to the right of the edge". The path follows the edge by area, not by
/// cell centres: a steep edge (|dx| ≤ |dy|) gets one riser per subpixel row, a shallow one
/// one step per subpixel column, their positions chosen by [`Dither`] so that in each pixel
/// the cells beside an edge match the exact area within a cell at every orientation.
/// A shallow path's mask is built from its columns ("cells above the step") instead: for any
/// lattice path, the leftward-ray mask XOR the cells-above mask is the XOR of the upper-right
/// quadrants of its two endpoints, so those quadrants are flipped too.
///
/// Each edge's path depends only on its two (canonically ordered) endpoints, so polygons
/// sharing an edge get masks whose XOR is the mask of their union (no holes; Watt & Watt
/// Fig 4.20), and a pixel's mask does not depend on the window. Paths of edges leaving one
/// vertex do not cross (no cell covered twice) when the corners are 45° or more, thanks to
/// [`GUARD`]; narrower corners may share a cell.
#[allow(clippy::too_many_arguments)]
pub fn rasterize(
    poly: &[[f32; 2]],
    w: usize,
    px0: i32,
    px1: i32,
    py0: i32,
    py1: i32,
    masks: &mut Vec<Mask>,
) {
    let npx = (px1 - px0 + 1).max(0) as usize;
    let npy = (py1 - py0 + 1).max(0) as usize;
    masks.clear();
    masks.resize(npx * npy, [0; 4]);
    if npx == 0 || npy == 0 {
        return;
    }
    let wi = w as i64;
    let mut win = Window {
        masks,
        w,
        shift: w.trailing_zeros(),
        px0: px0 as i64,
        px1: px1 as i64,
        py0: py0 as i64,
        npx,
        r0: py0 as i64 * wi,
        r1: (py1 as i64 + 1) * wi,
        c0: px0 as i64 * wi,
        c1: (px1 as i64 + 1) * wi,
    };
    let n = poly.len();
    for e in 0..n {
        let (a, b) = (poly[e], poly[(e + 1) % n]);
        if (b[0] - a[0]).abs() > (b[1] - a[1]).abs() {
            // Canonical order (lower x first): both polygons sharing this edge compute the
            // same path bit for bit.
            let (a, b) = if (a[0], a[1]) > (b[0], b[1]) {
                (b, a)
            } else {
                (a, b)
            };
            shallow_edge(&mut win, a, b);
        } else {
            let (a, b) = if (a[1], a[0]) > (b[1], b[0]) {
                (b, a)
            } else {
                (a, b)
            };
            steep_edge(&mut win, a, b);
        }
    }
}

/// An edge with |dx| ≤ |dy|, `a` below `b`: in each subpixel row whose centre lies in the
/// edge's y range, the cells from the riser rightwards.
fn steep_edge(win: &mut Window, a: [f32; 2], b: [f32; 2]) {
    let wi = win.w as i64;
    let wf = win.w as f32;
    let (ea, eb) = (snap(a[1] * wf), snap(b[1] * wf));
    let (ra, rb) = (ea.max(win.r0), eb.min(win.r1));
    if ra >= rb {
        return;
    }
    let dxdy = (b[0] - a[0]) / (b[1] - a[1]);
    let (ax, ay, inv) = (a[0] * wf, a[1] * wf, 1.0 / wf);
    let mut dither = Dither::new();
    for r in ra..rb {
        // The edge at the row centre, in cells: its area left of the edge in this row.
        let u = ax + (r as f32 + 0.5 - ay) * dxdy;
        let p = floor_i(u * inv);
        if p < win.px0 {
            dither.reset();
            win.flip_right(r, win.c0);
        } else if p > win.px1 {
            dither.reset();
        } else {
            let centre = r < ea + GUARD || r >= eb - GUARD;
            let n = dither.step((r >> win.shift, p), u - (p * wi) as f32, centre);
            win.flip_right(r, p * wi + n);
        }
    }
}

/// An edge with |dx| > |dy|, `a` left of `b`: per subpixel column whose centre lies in the
/// edge's x range, the cells between the step and the higher endpoint's lattice row; and the
/// rows between the endpoints' lattice rows right of the lower endpoint's lattice column.
fn shallow_edge(win: &mut Window, a: [f32; 2], b: [f32; 2]) {
    let wi = win.w as i64;
    let wf = win.w as f32;
    let (ca, cb) = (snap(a[0] * wf), snap(b[0] * wf));
    let (ya, yb) = (snap(a[1] * wf), snap(b[1] * wf));
    let top = ya.max(yb);
    let (low, xlow) = if ya <= yb { (ya, ca) } else { (yb, cb) };
    for r in low.max(win.r0)..top.min(win.r1) {
        win.flip_right(r, xlow);
    }
    let (c0, c1) = (ca.max(win.c0), cb.min(win.c1));
    if c0 >= c1 {
        return;
    }
    let dydx = (b[1] - a[1]) / (b[0] - a[0]);
    let (ax, ay, inv) = (a[0] * wf, a[1] * wf, 1.0 / wf);
    let py1 = (win.r1 >> win.shift) - 1;
    let mut dither = Dither::new();
    for c in c0..c1 {
        // The edge at the column centre, in cells: its area below the edge in this column.
        let t = ay + (c as f32 + 0.5 - ax) * dydx;
        let p = floor_i(t * inv);
        let y = if p < win.py0 {
            dither.reset();
            win.r0
        } else if p > py1 {
            dither.reset();
            win.r1
        } else {
            let centre = c < ca + GUARD || c >= cb - GUARD;
            p * wi + dither.step((c >> win.shift, p), t - (p * wi) as f32, centre)
        };
        win.flip_column(c, y.min(top), y.max(top));
    }
}

/// One micropolygon's share of one pixel.
#[derive(Clone, Copy, Debug)]
struct Frag {
    mask: Mask,
    /// Camera-space depth range over the covered part of the pixel.
    zmin: f32,
    zmax: f32,
    key: u64,
    sub: u32,
    next: u32,
    matte: bool,
    /// Premultiplied colour and opacity.
    c: [f32; 3],
    o: [f32; 3],
}

impl Frag {
    #[inline]
    fn opacity(&self) -> f32 {
        (self.o[0] + self.o[1] + self.o[2]) * (1.0 / 3.0)
    }
}

/// The A-buffer hider.
pub struct ABuffer {
    config: HiderConfig,
    /// Mask width and height in cells (4, 8 or 16).
    w: usize,
    limit: usize,
    /// Fragments that arrived when a bucket's pool was full (merged into a neighbour).
    overflowed: AtomicU64,
}

impl ABuffer {
    /// `Hider "abuffer"` with its parameters: `"masksize"` 4, 8 (default) or 16, and
    /// `"fragmentlimit"`, the most fragments a bucket may hold (see [`ABuffer::with_limit`]).
    pub fn new(config: HiderConfig, params: &ParamList, diags: &Diagnostics) -> ABuffer {
        let w = match params.float("masksize") {
            None => 8,
            Some(m) if m == 4.0 || m == 8.0 || m == 16.0 => m as usize,
            Some(m) => {
                let mut d = Diag::warning(
                    "render::hider",
                    format!("A-buffer masksize {m} is not supported; using 8"),
                )
                .help("masksize is 4, 8 or 16 (cells per pixel side)");
                if let Some(p) = params.get("masksize") {
                    d = d.label(p.span, "this mask size");
                }
                diags.report(d);
                8
            }
        };
        let mut hider = ABuffer::with_mask(config, w);
        match params.float("fragmentlimit") {
            None => {}
            Some(n) if n >= 1.0 => hider = hider.with_limit(n as usize),
            Some(n) => {
                let mut d = Diag::warning(
                    "render::hider",
                    format!("A-buffer fragmentlimit {n} is not positive; using {DEFAULT_FRAGMENT_LIMIT}"),
                )
                .help("fragmentlimit is the most fragments one bucket may hold (at least 1)");
                if let Some(p) = params.get("fragmentlimit") {
                    d = d.label(p.span, "this limit");
                }
                diags.report(d);
            }
        }
        hider
    }

    /// An A-buffer with `w`×`w` masks (`w` is 4, 8 or 16).
    pub fn with_mask(config: HiderConfig, w: usize) -> ABuffer {
        assert!(matches!(w, 4 | 8 | 16), "mask size {w}");
        ABuffer {
            config,
            w,
            limit: DEFAULT_FRAGMENT_LIMIT,
            overflowed: AtomicU64::new(0),
        }
    }

    /// Bounds the fragments a bucket may hold; beyond it a new fragment is merged into the
    /// nearest fragment of its pixel instead of being stored (quality degrades, memory does not
    /// grow).
    pub fn with_limit(mut self, limit: usize) -> ABuffer {
        self.limit = limit.max(1);
        self
    }

    pub fn mask_size(&self) -> usize {
        self.w
    }

    /// Fragments merged because a pool was full, over all buckets so far.
    pub fn overflowed(&self) -> u64 {
        self.overflowed.load(Ordering::Relaxed)
    }
}

/// Per-bucket state: the fragment pool and per-pixel list heads.
struct Bucket<'c> {
    cfg: &'c HiderConfig,
    limit: usize,
    heads: Vec<u32>,
    pool: Vec<Frag>,
    free: Vec<u32>,
    /// `aw` floats per pool slot.
    aovs: Vec<f32>,
    aw: usize,
    micro_pixels: u64,
    fragments: u64,
    overflowed: u64,
}

/// Depth ranges that meet (with a little slack for non-planar micropolygons).
#[inline]
fn touching(a: &Frag, zmin: f32, zmax: f32) -> bool {
    let slack = 1e-4 * a.zmax.abs().max(zmax.abs()) + 0.1 * ((a.zmax - a.zmin) + (zmax - zmin));
    a.zmin <= zmax + slack && zmin <= a.zmax + slack
}

impl Bucket<'_> {
    /// Adds fragment `f` (with output variables `aov`) to pixel `pix`.
    fn insert(&mut self, pix: usize, mut f: Frag, aov: &[f32]) {
        let aw = self.aw;
        let opaque = f.o[0].min(f.o[1]).min(f.o[2]) >= self.cfg.zthreshold;
        // Cells already hidden by opaque fragments wholly in front never show.
        let mut hidden = [0u64; 4];
        let mut cur = self.heads[pix];
        while cur != NONE {
            let p = &self.pool[cur as usize];
            if p.zmax < f.zmin && p.o[0].min(p.o[1]).min(p.o[2]) >= self.cfg.zthreshold {
                hidden = or(&hidden, &p.mask);
            }
            cur = p.next;
        }
        f.mask = andnot(&f.mask, &hidden);
        if is_zero(&f.mask) {
            return;
        }
        // Merge with a fragment of the same grid (they sit at the head of the list): adjacent
        // micropolygons have disjoint masks and touching depth ranges.
        let mut cur = self.heads[pix];
        while cur != NONE && self.pool[cur as usize].key == f.key {
            let p = &self.pool[cur as usize];
            if p.matte == f.matte && is_zero(&and(&p.mask, &f.mask)) && touching(p, f.zmin, f.zmax)
            {
                self.merge(cur, &f, aov);
                return;
            }
            cur = p.next;
        }
        // An opaque fragment trims the cells it hides from fragments wholly behind it.
        if opaque {
            let mut prev = NONE;
            let mut cur = self.heads[pix];
            while cur != NONE {
                let next = self.pool[cur as usize].next;
                let p = &mut self.pool[cur as usize];
                if p.zmin > f.zmax {
                    p.mask = andnot(&p.mask, &f.mask);
                    if is_zero(&p.mask) {
                        if prev == NONE {
                            self.heads[pix] = next;
                        } else {
                            self.pool[prev as usize].next = next;
                        }
                        self.free.push(cur);
                        cur = next;
                        continue;
                    }
                }
                prev = cur;
                cur = next;
            }
        }
        let slot = if let Some(s) = self.free.pop() {
            s
        } else if self.pool.len() < self.limit {
            self.pool.push(f);
            self.aovs.resize(self.pool.len() * aw, 0.0);
            (self.pool.len() - 1) as u32
        } else {
            // Pool full: fold into the nearest fragment of this pixel rather than grow.
            self.overflowed += 1;
            let mut best = NONE;
            let mut cur = self.heads[pix];
            while cur != NONE {
                let p = &self.pool[cur as usize];
                if best == NONE
                    || (p.zmin - f.zmin).abs() < (self.pool[best as usize].zmin - f.zmin).abs()
                {
                    best = cur;
                }
                cur = p.next;
            }
            if best != NONE {
                self.merge(best, &f, aov);
            }
            return;
        };
        f.next = self.heads[pix];
        self.pool[slot as usize] = f;
        let s = slot as usize * aw;
        self.aovs[s..s + aw].copy_from_slice(aov);
        self.heads[pix] = slot;
        self.fragments += 1;
    }

    /// ORs `f` into fragment `into`: colour, opacity and output variables area-weighted.
    fn merge(&mut self, into: u32, f: &Frag, aov: &[f32]) {
        let p = &mut self.pool[into as usize];
        let (na, nb) = (popcount(&p.mask) as f32, popcount(&f.mask) as f32);
        let (wa, wb) = (na / (na + nb), nb / (na + nb));
        for q in 0..3 {
            p.c[q] = wa * p.c[q] + wb * f.c[q];
            p.o[q] = wa * p.o[q] + wb * f.o[q];
        }
        p.mask = or(&p.mask, &f.mask);
        p.zmin = p.zmin.min(f.zmin);
        p.zmax = p.zmax.max(f.zmax);
        p.sub = p.sub.min(f.sub);
        let s = into as usize * self.aw;
        for (d, &v) in self.aovs[s..s + self.aw].iter_mut().zip(aov) {
            *d = wa * *d + wb * v;
        }
    }
}

impl Hider for ABuffer {
    fn config(&self) -> &HiderConfig {
        &self.config
    }

    /// Reports, once per render, how many fragments did not fit their bucket's pool.
    fn finish(&self, diags: &Diagnostics) {
        let n = self.overflowed.swap(0, Ordering::Relaxed);
        if n > 0 {
            diags.report(
                Diag::warning(
                    "render::hider",
                    format!(
                        "A-buffer fragment pool full ({} fragments per bucket): {n} fragments \
                         were merged into the nearest fragment of their pixel instead of stored, \
                         so their pixels may be approximate",
                        self.limit
                    ),
                )
                .help(
                    "raise Hider \"abuffer\" \"fragmentlimit\", or use smaller buckets \
                     (Option \"limits\" \"bucketsize\")",
                ),
            );
        }
    }

    fn samples_per_pixel(&self) -> usize {
        self.w * self.w
    }

    fn hide(&self, rect: PixelRect, grids: &[&dyn GridSource], stats: &Stats) -> SampleBuffer {
        // Fragments behind an opaque front are trimmed, not skipped before shading: every
        // grid meeting the bucket is shaded.
        let grids = shade_all(grids, &rect);
        let cfg = &self.config;
        let w = self.w;
        let mut buf = SampleBuffer::new(
            rect.x0,
            rect.y0,
            rect.width(),
            rect.height(),
            w,
            w,
            cfg.channels(),
        );
        let aw = cfg.channels() - 5;
        let mut b = Bucket {
            cfg,
            limit: self.limit,
            heads: vec![NONE; rect.width() * rect.height()],
            pool: Vec::new(),
            free: Vec::new(),
            aovs: Vec::new(),
            aw,
            micro_pixels: 0,
            fragments: 0,
            overflowed: 0,
        };
        let mut masks = Vec::new();
        // Motion blur and depth of field: each cell's time and lens position, stratified over
        // the pixel's cells as the Z-buffer's are over its samples.
        let (mut times, mut lens) = (Vec::new(), Vec::new());
        if cfg.dof.is_some() || grids.iter().any(|g| g.motion.is_some()) {
            let mut perm = Vec::new();
            for py in rect.y0..rect.y1 {
                for px in rect.x0..rect.x1 {
                    time_and_lens(
                        px, py, w, w, cfg.jitter, cfg.seed, &mut perm, &mut times, &mut lens,
                    );
                }
            }
        }
        // Front to back, ties by key: a pixel's fragments then arrive in the same order
        // whatever the bucket (merges and trims depend on it), and opaque fronts trim early.
        let mut order: Vec<&ShadedGrid> = grids.to_vec();
        order.sort_by(|a, c| a.zmin.total_cmp(&c.zmin).then(a.key.cmp(&c.key)));
        for g in order {
            if g.aov_width != aw {
                continue;
            }
            if g.motion.is_some() || cfg.dof.is_some() {
                fragment_grid_blurred(&mut b, rect, w, g, &times, &lens);
            } else {
                fragment_grid(&mut b, rect, w, g, &mut masks);
            }
        }
        resolve(&b, w, &mut buf);
        let bytes = b.pool.capacity() * std::mem::size_of::<Frag>()
            + b.aovs.capacity() * 4
            + buf.values.len() * 4;
        stats.alloc(bytes);
        stats.free(bytes);
        Stats::add(&stats.samples_tested, b.micro_pixels);
        Stats::add(&stats.samples_hit, b.fragments);
        if b.overflowed > 0 {
            self.overflowed.fetch_add(b.overflowed, Ordering::Relaxed);
        }
        buf
    }
}

/// Turns every live micropolygon of `g` into fragments of the pixels of `rect` it covers.
fn fragment_grid(b: &mut Bucket, rect: PixelRect, w: usize, g: &ShadedGrid, masks: &mut Vec<Mask>) {
    let cfg = b.cfg;
    let nu = g.nu;
    let aw = g.aov_width;
    let Some(win) = g.window(&rect) else {
        return;
    };
    let [wx0, wy0, wx1, wy1] = win;
    let rw = rect.width();
    let mut aov = vec![0f32; aw];
    let mut visible = Vec::new();
    g.micropolygons_in(win, &mut visible);
    for &(m, k, [x0, y0, x1, y1]) in &visible {
        let corner = [k, k + 1, k + nu + 1, k + nu];
        let poly = corner.map(|c| g.xy[c]);
        let px0 = floor_i32(x0.max(wx0)).max(rect.x0);
        let px1 = floor_i32(x1.min(wx1)).min(rect.x1 - 1);
        let py0 = floor_i32(y0.max(wy0)).max(rect.y0);
        let py1 = floor_i32(y1.min(wy1)).min(rect.y1 - 1);
        if px0 > px1 || py0 > py1 {
            continue;
        }
        rasterize(&poly, w, px0, px1, py0, py1, masks);
        // Depth: the affine plane of one non-degenerate half, clamped to the corner range.
        let q = corner.map(|c| g.depth[c]);
        let (qlo, qhi) = (
            q.iter().fold(f32::INFINITY, |a, &b| a.min(b)),
            q.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)),
        );
        let plane = plane_of(&poly, &q);
        // Constant shading: the mean of the corners (see zbuffer::flat_shade).
        let (flat_c, flat_o) = super::zbuffer::flat_shade(g, &corner, &mut []);
        let npx = (px1 - px0 + 1) as usize;
        let sub = m as u32;
        for py in py0..=py1 {
            for px in px0..=px1 {
                let mask = masks[(py - py0) as usize * npx + (px - px0) as usize];
                b.micro_pixels += 1;
                if is_zero(&mask) {
                    continue;
                }
                // The covered part lies in pixel ∩ micropolygon bound.
                let (cx0, cx1) = ((px as f32).max(x0), ((px + 1) as f32).min(x1));
                let (cy0, cy1) = ((py as f32).max(y0), ((py + 1) as f32).min(y1));
                let (mut lo, mut hi) = (qlo, qhi);
                if let Some([q0, dx, dy, ox, oy]) = plane {
                    let e = |x: f32, y: f32| q0 + dx * (x - ox) + dy * (y - oy);
                    let v = [e(cx0, cy0), e(cx1, cy0), e(cx0, cy1), e(cx1, cy1)];
                    let vlo = v.iter().fold(f32::INFINITY, |a, &b| a.min(b));
                    let vhi = v.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
                    lo = vlo.clamp(qlo, qhi);
                    hi = vhi.clamp(qlo, qhi);
                }
                let (zmin, zmax) = if cfg.perspective {
                    (1.0 / hi, 1.0 / lo)
                } else {
                    (lo, hi)
                };
                if !(zmax >= cfg.near && zmin <= cfg.far) || zmin.is_nan() || zmax.is_nan() {
                    continue;
                }
                let (cx, cy) = (0.5 * (cx0 + cx1), 0.5 * (cy0 + cy1));
                if !cfg.clip_planes.is_empty() {
                    let p = cfg.camera_point(cx, cy, 0.5 * (zmin + zmax));
                    if cfg
                        .clip_planes
                        .iter()
                        .any(|pl| pl.truncate().dot(p) + pl.w > 0.0)
                    {
                        continue;
                    }
                }
                let (c, o) = if g.smooth {
                    let wts = weights_at(&poly, cx, cy);
                    let mut c = [0f32; 3];
                    let mut o = [0f32; 3];
                    for (vi, &gi) in corner.iter().enumerate() {
                        for t in 0..3 {
                            c[t] += wts[vi] * g.ci[gi][t];
                            o[t] += wts[vi] * g.oi[gi][t];
                        }
                    }
                    for t in 0..aw {
                        aov[t] = (0..4).map(|vi| wts[vi] * g.aov[corner[vi] * aw + t]).sum();
                    }
                    (c, o)
                } else {
                    for t in 0..aw {
                        aov[t] = corner.iter().map(|&c| 0.25 * g.aov[c * aw + t]).sum();
                    }
                    (flat_c, flat_o)
                };
                let pix = (py - rect.y0) as usize * rw + (px - rect.x0) as usize;
                b.insert(
                    pix,
                    Frag {
                        mask,
                        zmin,
                        zmax,
                        key: g.key,
                        sub,
                        next: NONE,
                        matte: g.matte,
                        c,
                        o,
                    },
                    &aov,
                );
            }
        }
    }
}

/// [`fragment_grid`] for a grid that moves or is seen through a lens. Each cell of a pixel's
/// mask is a point sample at the cell's centre with its own shutter time and lens position
/// (`times`/`lens`, `w`² per pixel of `rect`, row-major): a cell is covered when, at its time
/// and through its lens point, it lies in the micropolygon (corners moving linearly between
/// keys, then shifted by the lens times their circle of confusion, as in the Z-buffer). The
/// fragment's depth range is the range over its covered cells; its colour the corner mean,
/// or for smooth shading the mean of the colours interpolated at its cells. Micropolygons
/// sharing an edge give disjoint cells (one canonical edge function owns points on the edge),
/// so a diced surface merges back into one fragment per pixel.
fn fragment_grid_blurred(
    b: &mut Bucket,
    rect: PixelRect,
    w: usize,
    g: &ShadedGrid,
    times: &[f32],
    lens: &[[f32; 2]],
) {
    let cfg = b.cfg;
    let nu = g.nu;
    let aw = g.aov_width;
    let Some(win) = g.window(&rect) else {
        return;
    };
    let [wx0, wy0, wx1, wy1] = win;
    let rw = rect.width();
    let n = w * w;
    let inv_w = 1.0 / w as f32;
    let dof = cfg.dof;
    let mut visible = Vec::new();
    g.micropolygons_in(win, &mut visible);
    let mut flat_aov = vec![0f32; aw];
    let mut aov = vec![0f32; aw];
    for &(m, k, mb) in &visible {
        let corner = [k, k + 1, k + nu + 1, k + nu];
        let Some(bx) = super::clip_box(mb, [wx0, wy0, wx1, wy1]) else {
            continue;
        };
        let px0 = floor_i32(bx[0]).max(rect.x0);
        let px1 = floor_i32(bx[2]).min(rect.x1 - 1);
        let py0 = floor_i32(bx[1]).max(rect.y0);
        let py1 = floor_i32(bx[3]).min(rect.y1 - 1);
        if px0 > px1 || py0 > py1 {
            continue;
        }
        // Constant shading: the mean of the corners (see zbuffer::flat_shade).
        let (flat_c, flat_o) = super::zbuffer::flat_shade(g, &corner, &mut flat_aov);
        let lens_bound = super::LensBound::new(g, &corner, dof.as_ref());
        let keys = super::KeyCorners::new(g, &corner);
        // A moving micropolygon: each pixel row only across the region it sweeps over the
        // shutter, and each pixel's cells only at the times it can be there — both
        // conservative, as the Z-buffer's time slots (see `timebins`).
        // The whole shutter's bound pad is the lens pad's too (`timebins::lens_pad`).
        let (mut sweep, mut lens_pad) = (None, None);
        if g.motion.is_some() {
            let ends = [
                super::timebins::corners(g, &corner, 0.0),
                super::timebins::corners(g, &corner, 1.0),
            ];
            if let Some((_, pad)) =
                super::timebins::bound_and_pad(g, &corner, &ends, 0.0, 1.0, dof.as_ref())
            {
                sweep = super::timebins::sweep_between(g, &corner, &ends, 0.0, 1.0, pad);
                lens_pad = Some(if dof.is_some() { pad } else { [0.0, 0.0] });
            }
        }
        for py in py0..=py1 {
            let (mut qx0, mut qx1) = (px0, px1);
            if let Some(sw) = &sweep {
                let Some((lo, hi)) = sw.x_range(py as f32, py as f32 + 1.0) else {
                    continue;
                };
                qx0 = qx0.max(floor_i32(lo));
                qx1 = qx1.min(floor_i32(hi));
            }
            for px in qx0..=qx1 {
                let pixel = [px as f32, py as f32, px as f32 + 1.0, py as f32 + 1.0];
                let window = super::timebins::grown_by_lens(pixel, lens_pad);
                let (ta, tb) = match (window, &keys) {
                    (None, _) => (f32::NEG_INFINITY, f32::INFINITY),
                    (Some(w), Some(k)) => match k.time_window(w) {
                        Some(t) => t,
                        None => continue,
                    },
                    (Some(w), None) => match super::timebins::time_window(g, &corner, w) {
                        Some(t) => t,
                        None => continue,
                    },
                };
                b.micro_pixels += 1;
                let pix = (py - rect.y0) as usize * rw + (px - rect.x0) as usize;
                let mut mask = [0u64; 4];
                let (mut zlo, mut zhi) = (f32::INFINITY, f32::NEG_INFINITY);
                let mut sum_c = [0f32; 3];
                let mut sum_o = [0f32; 3];
                aov.iter_mut().for_each(|a| *a = 0.0);
                let mut hits = 0u32;
                for j in 0..w {
                    let y = py as f32 + (j as f32 + 0.5) * inv_w;
                    if y < bx[1] || y > bx[3] {
                        continue;
                    }
                    for i in 0..w {
                        let x = px as f32 + (i as f32 + 0.5) * inv_w;
                        if x < bx[0] || x > bx[2] {
                            continue;
                        }
                        let s = pix * n + j * w + i;
                        let pos = [x, y];
                        if lens_bound
                            .as_ref()
                            .is_some_and(|lb| lb.misses(lens[s], pos))
                        {
                            continue;
                        }
                        // (NaN times are never skipped.)
                        if times.get(s).is_some_and(|&t| t < ta || t > tb) {
                            continue;
                        }
                        let (p, q) = match &keys {
                            Some(k) => k.at(times[s], lens[s], dof.as_ref()),
                            None => super::corners_at(g, &corner, times[s], lens[s], dof.as_ref()),
                        };
                        if super::zbuffer::far_from(&p, pos) {
                            continue;
                        }
                        for tri in [[0usize, 1, 2], [0, 2, 3]] {
                            let Some((v, idx, dq, area)) =
                                super::ccw_triangle(&p, &q, &corner, tri)
                            else {
                                continue;
                            };
                            let e1 = zedge(v[2], v[0], pos);
                            let e2 = zedge(v[0], v[1], pos);
                            if !(zinside(zedge(v[1], v[2], pos)) && zinside(e1) && zinside(e2)) {
                                continue;
                            }
                            let inv = 1.0 / area.abs();
                            let (w1, w2) = (e1.0 * inv, e2.0 * inv);
                            let w0 = 1.0 - w1 - w2;
                            let qz = dq[0] + w1 * (dq[1] - dq[0]) + w2 * (dq[2] - dq[0]);
                            let z = if cfg.perspective { 1.0 / qz } else { qz };
                            if !(z >= cfg.near && z <= cfg.far) {
                                break;
                            }
                            if !cfg.clip_planes.is_empty() {
                                let cp = cfg.camera_point(x, y, z);
                                if cfg
                                    .clip_planes
                                    .iter()
                                    .any(|pl| pl.truncate().dot(cp) + pl.w > 0.0)
                                {
                                    break;
                                }
                            }
                            let bit = j * w + i;
                            mask[bit / 64] |= 1u64 << (bit % 64);
                            zlo = zlo.min(z);
                            zhi = zhi.max(z);
                            hits += 1;
                            if g.smooth {
                                let wts = [w0, w1, w2];
                                for (vi, &gi) in idx.iter().enumerate() {
                                    for t in 0..3 {
                                        sum_c[t] += wts[vi] * g.ci[gi][t];
                                        sum_o[t] += wts[vi] * g.oi[gi][t];
                                    }
                                    for t in 0..aw {
                                        aov[t] += wts[vi] * g.aov[gi * aw + t];
                                    }
                                }
                            }
                            break;
                        }
                    }
                }
                if hits == 0 {
                    continue;
                }
                let (c, o) = if g.smooth {
                    let r = 1.0 / hits as f32;
                    aov.iter_mut().for_each(|a| *a *= r);
                    (sum_c.map(|v| v * r), sum_o.map(|v| v * r))
                } else {
                    aov.copy_from_slice(&flat_aov);
                    (flat_c, flat_o)
                };
                b.insert(
                    pix,
                    Frag {
                        mask,
                        zmin: zlo,
                        zmax: zhi,
                        key: g.key,
                        sub: m as u32,
                        next: NONE,
                        matte: g.matte,
                        c,
                        o,
                    },
                    &aov,
                );
            }
        }
    }
}

/// The affine depth of the quad's first non-degenerate half: (q0, ∂q/∂x, ∂q/∂y, x0, y0).
fn plane_of(p: &[[f32; 2]; 4], q: &[f32; 4]) -> Option<[f32; 5]> {
    for t in [[0, 1, 2], [0, 2, 3]] {
        let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
        let (ux, uy, vx, vy) = (b[0] - a[0], b[1] - a[1], c[0] - a[0], c[1] - a[1]);
        let det = ux * vy - uy * vx;
        if det.abs() > 1e-12 && det.is_finite() {
            let (du, dv) = (q[t[1]] - q[t[0]], q[t[2]] - q[t[0]]);
            let dx = (du * vy - dv * uy) / det;
            let dy = (dv * ux - du * vx) / det;
            return Some([q[t[0]], dx, dy, a[0], a[1]]);
        }
    }
    None
}

/// Corner weights of point (x, y) in the quad: barycentric in the half (0 1 2 or 0 2 3) that
/// holds it, clamped to that triangle.
fn weights_at(p: &[[f32; 2]; 4], x: f32, y: f32) -> [f32; 4] {
    let mut best = [0.25; 4];
    let mut best_out = f32::INFINITY;
    for t in [[0usize, 1, 2], [0, 2, 3]] {
        let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
        let det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if det.abs() <= 1e-12 || !det.is_finite() {
            continue;
        }
        let w1 = ((x - a[0]) * (c[1] - a[1]) - (y - a[1]) * (c[0] - a[0])) / det;
        let w2 = ((b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])) / det;
        let w0 = 1.0 - w1 - w2;
        let out = (-w0).max(-w1).max(-w2).max(0.0);
        if out < best_out {
            best_out = out;
            let (w0, w1, w2) = (w0.max(0.0), w1.max(0.0), w2.max(0.0));
            let s = w0 + w1 + w2;
            let mut r = [0f32; 4];
            r[t[0]] = w0 / s;
            r[t[1]] = w1 / s;
            r[t[2]] = w2 / s;
            best = r;
        }
    }
    best
}

/// Per-pixel resolve scratch, one set of accumulators per subpixel cell.
struct Cells {
    col: Vec<[f32; 3]>,
    tr: Vec<[f32; 3]>,
    alpha: Vec<f32>,
    aov: Vec<f32>,
    z: Vec<f32>,
    z2: Vec<f32>,
}

/// Resolves every pixel's fragment list into its subpixel samples.
fn resolve(b: &Bucket, w: usize, buf: &mut SampleBuffer) {
    let cfg = b.cfg;
    let ch = buf.channels;
    let aw = b.aw;
    let bits = w * w;
    let full = full_mask(w);
    let stop = 1.0 - cfg.othreshold;
    let mut order: Vec<u32> = Vec::new();
    let mut rem: Vec<Mask> = Vec::new();
    let mut cells = Cells {
        col: vec![[0.0; 3]; bits],
        tr: vec![[1.0; 3]; bits],
        alpha: vec![0.0; bits],
        aov: vec![0.0; bits * aw],
        z: vec![f32::INFINITY; bits],
        z2: vec![f32::INFINITY; bits],
    };
    for (pix, &head) in b.heads.iter().enumerate() {
        if head == NONE {
            continue;
        }
        order.clear();
        let mut cur = head;
        while cur != NONE {
            order.push(cur);
            cur = b.pool[cur as usize].next;
        }
        order.sort_unstable_by(|&x, &y| {
            let (p, q) = (&b.pool[x as usize], &b.pool[y as usize]);
            p.zmin
                .total_cmp(&q.zmin)
                .then(p.key.cmp(&q.key))
                .then(p.sub.cmp(&q.sub))
        });
        rem.clear();
        rem.extend(order.iter().map(|&i| b.pool[i as usize].mask));
        cells.col.iter_mut().for_each(|c| *c = [0.0; 3]);
        cells.tr.iter_mut().for_each(|c| *c = [1.0; 3]);
        cells.alpha.iter_mut().for_each(|c| *c = 0.0);
        cells.aov.iter_mut().for_each(|c| *c = 0.0);
        cells.z.iter_mut().for_each(|c| *c = f32::INFINITY);
        cells.z2.iter_mut().for_each(|c| *c = f32::INFINITY);
        let mut search = full;
        for a in 0..order.len() {
            if is_zero(&search) {
                break;
            }
            let f = &b.pool[order[a] as usize];
            let mut m = and(&rem[a], &search);
            if is_zero(&m) {
                continue;
            }
            // Fragments whose depth range overlaps this one's: blend over the common cells.
            for c in a + 1..order.len() {
                let g = &b.pool[order[c] as usize];
                if g.zmin >= f.zmax {
                    break; // sorted by zmin: no later fragment overlaps either
                }
                let common = and(&m, &rem[c]);
                if is_zero(&common) {
                    continue;
                }
                let (fa, ga) = (order[a] as usize * aw, order[c] as usize * aw);
                let pair = Pair::new(
                    f,
                    g,
                    &b.aovs[fa..fa + aw],
                    &b.aovs[ga..ga + aw],
                    cfg.zthreshold,
                );
                for_bits(&common, |cell| pair.add(&mut cells, cell, aw));
                rem[c] = andnot(&rem[c], &common);
                m = andnot(&m, &common);
                drop_finished(&mut search, &common, &cells.tr, stop);
            }
            let fa = order[a] as usize * aw;
            let single = Pair::single(f, &b.aovs[fa..fa + aw], cfg.zthreshold);
            for_bits(&m, |cell| single.add(&mut cells, cell, aw));
            drop_finished(&mut search, &m, &cells.tr, stop);
        }
        // Write the cells out: sample (i, j) of the pixel is cell bit j·w + i.
        let base = pix * bits;
        for cell in 0..bits {
            let out = &mut buf.values[(base + cell) * ch..(base + cell + 1) * ch];
            out[..3].copy_from_slice(&cells.col[cell]);
            out[3] = cells.alpha[cell];
            out[4] = match cfg.depth_filter {
                DepthFilter::Midpoint if cells.z2[cell].is_finite() => {
                    0.5 * (cells.z[cell] + cells.z2[cell])
                }
                _ => cells.z[cell],
            };
            out[5..5 + aw].copy_from_slice(&cells.aov[cell * aw..(cell + 1) * aw]);
        }
    }
}

/// Removes from the search mask the cells of `m` that no longer let light through.
#[inline]
fn drop_finished(search: &mut Mask, m: &Mask, tr: &[[f32; 3]], stop: f32) {
    let mut done = [0u64; 4];
    for_bits(m, |cell| {
        let t = tr[cell];
        if t[0] <= stop && t[1] <= stop && t[2] <= stop {
            done[cell / 64] |= 1 << (cell % 64);
        }
    });
    *search = andnot(search, &done);
}

/// One layer as the cells see it: a single fragment, or two intersecting fragments blended by
/// Carpenter's rule (each in front over its fraction of the common cells).
struct Pair<'a> {
    /// Premultiplied colour the layer adds (before the cell's transmittance).
    c: [f32; 3],
    /// Transmittance of the layer.
    t: [f32; 3],
    /// Alpha (per channel, averaged on output) the layer adds, and the weights of the two
    /// fragments' output variables.
    alpha: [f32; 3],
    wa: f32,
    wb: f32,
    aov_a: &'a [f32],
    aov_b: &'a [f32],
    /// Depths of the layer's opaque surfaces (nearest first).
    z: [f32; 2],
}

impl<'a> Pair<'a> {
    fn single(f: &Frag, aov: &'a [f32], zt: f32) -> Pair<'a> {
        let o = f.opacity();
        Pair {
            c: if f.matte { [0.0; 3] } else { f.c },
            t: [1.0 - f.o[0], 1.0 - f.o[1], 1.0 - f.o[2]],
            alpha: if f.matte { [0.0; 3] } else { f.o },
            wa: if f.matte { 0.0 } else { o },
            wb: 0.0,
            aov_a: aov,
            aov_b: aov,
            z: [
                if opaque(f, zt) { f.zmin } else { f32::INFINITY },
                f32::INFINITY,
            ],
        }
    }

    /// `f` (nearer zmin) and `g` with overlapping depth ranges: `f` is in front over
    /// (zmax_g − zmin_f) / ((zmax_f − zmin_f) + (zmax_g − zmin_g)) of the common cells.
    fn new(f: &Frag, g: &Frag, aov_f: &'a [f32], aov_g: &'a [f32], zt: f32) -> Pair<'a> {
        let den = (f.zmax - f.zmin) + (g.zmax - g.zmin);
        let front = if den > 0.0 {
            ((g.zmax - f.zmin) / den).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let cf = if f.matte { [0.0; 3] } else { f.c };
        let cg = if g.matte { [0.0; 3] } else { g.c };
        let af = if f.matte { [0.0; 3] } else { f.o };
        let ag = if g.matte { [0.0; 3] } else { g.o };
        let mut c = [0f32; 3];
        let mut t = [0f32; 3];
        let mut alpha = [0f32; 3];
        for q in 0..3 {
            let (tf, tg) = (1.0 - f.o[q], 1.0 - g.o[q]);
            c[q] = front * (cf[q] + tf * cg[q]) + (1.0 - front) * (cg[q] + tg * cf[q]);
            alpha[q] = front * (af[q] + tf * ag[q]) + (1.0 - front) * (ag[q] + tg * af[q]);
            t[q] = tf * tg;
        }
        let (of, og) = (f.opacity(), g.opacity());
        let wf = (front * of + (1.0 - front) * (1.0 - og) * of) * (!f.matte) as i32 as f32;
        let wg = (front * (1.0 - of) * og + (1.0 - front) * og) * (!g.matte) as i32 as f32;
        let mut z = [f32::INFINITY; 2];
        for (k, fr) in [f, g].into_iter().enumerate() {
            if opaque(fr, zt) {
                z[k] = fr.zmin;
            }
        }
        if z[1] < z[0] {
            z.swap(0, 1);
        }
        Pair {
            c,
            t,
            alpha,
            wa: wf,
            wb: wg,
            aov_a: aov_f,
            aov_b: aov_g,
            z,
        }
    }

    #[inline]
    fn add(&self, cells: &mut Cells, cell: usize, aw: usize) {
        let tr = cells.tr[cell];
        let tmean = (tr[0] + tr[1] + tr[2]) * (1.0 / 3.0);
        let mut a = 0f32;
        for q in 0..3 {
            cells.col[cell][q] += tr[q] * self.c[q];
            a += tr[q] * self.alpha[q];
            cells.tr[cell][q] = tr[q] * self.t[q];
        }
        cells.alpha[cell] += a * (1.0 / 3.0);
        if aw > 0 {
            let out = &mut cells.aov[cell * aw..(cell + 1) * aw];
            for q in 0..aw {
                out[q] += tmean * (self.wa * self.aov_a[q] + self.wb * self.aov_b[q]);
            }
        }
        for &z in &self.z {
            if z < cells.z[cell] {
                cells.z2[cell] = cells.z[cell];
                cells.z[cell] = z;
            } else if z < cells.z2[cell] {
                cells.z2[cell] = z;
            }
        }
    }
}

/// A surface counts for depth at opacity ≥ zthreshold (as in the Z-buffer hider).
#[inline]
fn opaque(f: &Frag, zt: f32) -> bool {
    f.o[0].min(f.o[1]).min(f.o[2]) >= zt
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator of floats in [0, 1) for the randomised tests.
    fn lcg(mut s: u64) -> impl FnMut() -> f32 {
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    fn mask_of(poly: &[[f32; 2]], w: usize) -> Mask {
        let mut masks = Vec::new();
        rasterize(poly, w, 0, 0, 0, 0, &mut masks);
        masks[0]
    }

    #[test]
    fn full_and_half_pixels() {
        for w in [4, 8, 16] {
            let full = mask_of(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], w);
            assert_eq!(full, full_mask(w));
            assert_eq!(popcount(&full) as usize, w * w);
            let left = mask_of(&[[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]], w);
            assert_eq!(popcount(&left) as usize, w * w / 2);
            // A polygon larger than the pixel covers it fully.
            let big = mask_of(&[[-3.0, -2.0], [4.0, -2.5], [4.0, 5.0], [-3.0, 5.0]], w);
            assert_eq!(big, full_mask(w));
        }
    }

    #[test]
    fn diagonal_triangle_area() {
        // (0,0) (1,0) (1,1): exactly half the pixel; the area-following path keeps it within
        // a cell (plain cell-centre sampling would give 28 of 64).
        let m = mask_of(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], 8);
        assert!((popcount(&m) as i32 - 32).abs() <= 1, "{}", popcount(&m));
        // and its complement across the diagonal tiles the pixel exactly
        let n = mask_of(&[[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]], 8);
        assert!(is_zero(&and(&m, &n)));
        assert_eq!(or(&m, &n), full_mask(8));
    }

    fn shoelace(p: &[[f32; 2]]) -> f32 {
        let n = p.len();
        let s: f32 = (0..n)
            .map(|i| p[i][0] * p[(i + 1) % n][1] - p[(i + 1) % n][0] * p[i][1])
            .sum();
        0.5 * s.abs()
    }

    #[test]
    fn masks_are_symmetric_and_area_accurate() {
        let mut rnd = lcg(12345);
        for w in [4usize, 8, 16] {
            let mut worst = 0f32;
            for _ in 0..300 {
                // A random convex quad inside the pixel (a micropolygon's shape).
                let (cx, cy, r) = (0.3 + 0.4 * rnd(), 0.3 + 0.4 * rnd(), 0.1 + 0.2 * rnd());
                let a0 = rnd() * std::f32::consts::TAU;
                let poly: Vec<[f32; 2]> = (0..4)
                    .map(|k| {
                        let t = a0 + k as f32 * std::f32::consts::FRAC_PI_2 + 0.5 * (rnd() - 0.5);
                        [cx + r * t.cos(), cy + r * t.sin()]
                    })
                    .collect();
                let m = mask_of(&poly, w);
                let mut rev = poly.clone();
                rev.reverse();
                assert_eq!(m, mask_of(&rev, w), "{poly:?}");
                let err = (popcount(&m) as f32 - shoelace(&poly) * (w * w) as f32).abs();
                worst = worst.max(err);
            }
            eprintln!("mask {w}: worst micropolygon error {worst} cells");
            // Four edges, each within about a cell of its exact area (rows where an edge
            // starts or ends are quantised to whole rows).
            assert!(
                worst <= 0.75 * w as f32,
                "mask {w}: worst error {worst} cells"
            );
        }
    }

    #[test]
    fn window_does_not_change_a_pixel_mask() {
        // Bucket independence: a pixel's mask is the same whichever window is rasterised.
        let tri = [[10.2, 20.3], [12.9, 20.6], [11.1, 21.8]];
        for w in [4, 8, 16] {
            let mut all = Vec::new();
            rasterize(&tri, w, 10, 12, 20, 21, &mut all);
            let mut one = Vec::new();
            for py in 20..=21 {
                for px in 10..=12 {
                    rasterize(&tri, w, px, px, py, py, &mut one);
                    assert_eq!(all[((py - 20) * 3 + px - 10) as usize], one[0]);
                }
            }
            let total: u32 = all.iter().map(popcount).sum();
            let exact = shoelace(&tri) * (w * w) as f32;
            assert!(
                (total as f32 - exact).abs() <= 1.5 * w as f32,
                "{total} vs {exact}"
            );
        }
    }

    #[test]
    fn shared_edges_leave_no_holes_or_overlaps() {
        // Four triangles around an interior point, and the two halves of a diagonal.
        let c = [0.37, 0.61];
        let sq = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        for w in [4, 8, 16] {
            let mut union = [0u64; 4];
            for e in 0..4 {
                let m = mask_of(&[sq[e], sq[(e + 1) % 4], c], w);
                assert!(is_zero(&and(&union, &m)));
                union = or(&union, &m);
            }
            assert_eq!(union, full_mask(w));
            // Cells exactly on a vertical shared edge at x = 0.5 go to one side only.
            let a = mask_of(&[[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]], w);
            let b = mask_of(&[[0.5, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 1.0]], w);
            assert!(is_zero(&and(&a, &b)));
            assert_eq!(or(&a, &b), full_mask(w));
        }
    }

    /// Area of the unit pixel `(px, py)` on the side `n·(p − o) ≤ 0` of a line (exact, by
    /// clipping the square).
    fn clipped_area(px: f64, py: f64, n: [f64; 2], o: [f64; 2]) -> f64 {
        let sq = [
            [px, py],
            [px + 1.0, py],
            [px + 1.0, py + 1.0],
            [px, py + 1.0],
        ];
        let d = |p: [f64; 2]| n[0] * (p[0] - o[0]) + n[1] * (p[1] - o[1]);
        let mut out: Vec<[f64; 2]> = Vec::new();
        for i in 0..4 {
            let (p, q) = (sq[i], sq[(i + 1) % 4]);
            let (dp, dq) = (d(p), d(q));
            if dp <= 0.0 {
                out.push(p);
            }
            if (dp < 0.0) != (dq < 0.0) && dp != dq {
                let t = dp / (dp - dq);
                out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
        let m = out.len();
        let s: f64 = (0..m)
            .map(|i| out[i][0] * out[(i + 1) % m][1] - out[(i + 1) % m][0] * out[i][1])
            .sum();
        0.5 * s.abs()
    }

    /// The worst |coverage − exact area| of pixels crossed by one edge, sweeping the edge's
    /// direction over the full turn (every angle 0..180° with either side filled) and its
    /// offset through the pixel, at two pixel positions.
    fn worst_edge_error(w: usize) -> f64 {
        let mut worst = 0f64;
        for (px, py) in [(0i32, 0i32), (37, -12)] {
            for k in 0..720 {
                // Whole and half degrees (axis-aligned and 45° edges included), then a
                // slightly irrational one.
                let deg = if k < 360 {
                    k as f64
                } else {
                    (k - 360) as f64 + 0.5371
                };
                let th = deg.to_radians();
                let (n, t) = ([th.cos(), th.sin()], [-th.sin(), th.cos()]);
                for j in 0..15 {
                    let off = -0.7 + 1.4 * j as f64 / 14.0 + 0.013 * (k % 3) as f64;
                    let o = [px as f64 + 0.5 + n[0] * off, py as f64 + 0.5 + n[1] * off];
                    let big = 10.0;
                    let v = |s: f64, r: f64| {
                        [
                            (o[0] + t[0] * s - n[0] * r) as f32,
                            (o[1] + t[1] * s - n[1] * r) as f32,
                        ]
                    };
                    let poly = [v(big, 0.0), v(-big, 0.0), v(-big, big), v(big, big)];
                    // The f32 polygon's own line, for the exact area.
                    let (p0, p1) = (poly[0], poly[1]);
                    let dir = [(p1[0] - p0[0]) as f64, (p1[1] - p0[1]) as f64];
                    let mut nn = [dir[1], -dir[0]];
                    let inside = [poly[2][0] as f64, poly[2][1] as f64];
                    let o32 = [p0[0] as f64, p0[1] as f64];
                    if nn[0] * (inside[0] - o32[0]) + nn[1] * (inside[1] - o32[1]) > 0.0 {
                        nn = [-nn[0], -nn[1]];
                    }
                    let exact = clipped_area(px as f64, py as f64, nn, o32);
                    let mut masks = Vec::new();
                    rasterize(&poly, w, px, px, py, py, &mut masks);
                    let cov = popcount(&masks[0]) as f64 / (w * w) as f64;
                    worst = worst.max((cov - exact).abs());
                }
            }
        }
        worst
    }

    #[test]
    fn edge_coverage_is_the_exact_area_at_every_orientation() {
        // The bound: within 1/64 at 8×8, and likewise one cell (1/w²) at 4 and 16;
        // the dithered paths actually keep every orientation within about half a cell.
        for w in [4usize, 8, 16] {
            let worst = worst_edge_error(w);
            let cell = 1.0 / (w * w) as f64;
            eprintln!(
                "mask {w}: worst edge-pixel error {worst:.5} = {:.3} cells",
                worst / cell
            );
            assert!(worst <= cell, "mask {w}: worst coverage error {worst}");
        }
    }

    #[test]
    fn shared_edges_of_a_jittered_grid_tile_exactly() {
        // Micropolygons of a jittered 5×5-point grid over 2×2 pixels: adjacent ones share
        // edges, so their masks must be disjoint and their union the outline's mask.
        let mut rnd = lcg(777);
        for w in [4usize, 8, 16] {
            for _ in 0..40 {
                let mut pts = [[0f32; 2]; 25];
                for j in 0..5 {
                    for i in 0..5 {
                        let jit = |r: f32| if i % 4 == 0 && j % 4 == 0 { 0.0 } else { r };
                        pts[j * 5 + i] = [
                            0.3 + 0.37 * i as f32 + jit(0.2 * (rnd() - 0.5)),
                            0.2 + 0.41 * j as f32 + jit(0.2 * (rnd() - 0.5)),
                        ];
                    }
                }
                let mut union = vec![[0u64; 4]; 4];
                let mut masks = Vec::new();
                for j in 0..4 {
                    for i in 0..4 {
                        let k = j * 5 + i;
                        let q = [pts[k], pts[k + 1], pts[k + 6], pts[k + 5]];
                        rasterize(&q, w, 0, 1, 0, 1, &mut masks);
                        for (u, m) in union.iter_mut().zip(&masks) {
                            assert!(is_zero(&and(u, m)), "overlap");
                            *u = or(u, m);
                        }
                    }
                }
                let outline: Vec<[f32; 2]> = (0..4)
                    .map(|i| pts[i])
                    .chain((0..4).map(|j| pts[j * 5 + 4]))
                    .chain((1..5).rev().map(|i| pts[20 + i]))
                    .chain((1..5).rev().map(|j| pts[j * 5]))
                    .collect();
                rasterize(&outline, w, 0, 1, 0, 1, &mut masks);
                assert_eq!(union, masks);
            }
        }
    }

    #[test]
    fn fans_around_a_vertex_tile_exactly() {
        // Triangles around a shared vertex, corners of at least 45° (usual micropolygons):
        // the guard rows keep their paths from crossing near the vertex, so the masks are
        // disjoint and tile the fan's outline. (Narrower corners can overlap by a cell.)
        let mut rnd = lcg(99);
        for w in [4usize, 8, 16] {
            for _ in 0..300 {
                let v = [0.5 + rnd(), 0.5 + rnd()];
                let mut angs: Vec<f32> = Vec::new();
                for _ in 0..100 {
                    let a = rnd() * 360.0;
                    if angs.iter().all(|&b| {
                        let d = (a - b).abs();
                        d.min(360.0 - d) >= 45.0
                    }) {
                        angs.push(a);
                    }
                }
                angs.sort_by(f32::total_cmp);
                let pts: Vec<[f32; 2]> = angs
                    .iter()
                    .map(|a| {
                        let t = a.to_radians();
                        [v[0] + 1.3 * t.cos(), v[1] + 1.3 * t.sin()]
                    })
                    .collect();
                let mut union = vec![[0u64; 4]; 16];
                let mut masks = Vec::new();
                for i in 0..pts.len() {
                    rasterize(
                        &[v, pts[i], pts[(i + 1) % pts.len()]],
                        w,
                        -1,
                        2,
                        -1,
                        2,
                        &mut masks,
                    );
                    for (u, m) in union.iter_mut().zip(&masks) {
                        assert!(is_zero(&and(u, m)), "overlap at {v:?} {angs:?}");
                        *u = or(u, m);
                    }
                }
                rasterize(&pts, w, -1, 2, -1, 2, &mut masks);
                assert_eq!(union, masks);
            }
        }
    }
}
