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
//!   XOR of per-edge masks ("1s to the right of the edge", rows whose centre lies in the edge's
//!   half-open y range), i.e. exact even-odd point-in-polygon at the cell centres, computed on
//!   the fly per subpixel row (no 45×45 table, so 16×16 costs no table memory);
//! * an edge's crossing is computed from its endpoints in a canonical order, so two polygons
//!   sharing an edge get disjoint masks whose union has no holes (Watt & Watt Fig 4.20);
//! * fragments live in one pooled `Vec` per bucket with index links and a free list; adjacent
//!   micropolygons of one grid with disjoint masks and touching depth ranges are merged (OR of
//!   masks, area-weighted colour) so a diced surface leaves no seams; the pool is bounded;
//! * the resolve walks each pixel's fragments front to back in the total order
//!   (zmin, grid key, micropolygon) with a search mask; fragments whose depth ranges overlap
//!   are blended over their common cells by Carpenter's zmin/zmax rule, so the image does not
//!   depend on the order grids arrive in (transparent layers commute).

// Colour loops index several parallel arrays by channel.
#![allow(clippy::needless_range_loop)]

use std::sync::atomic::{AtomicU64, Ordering};

use crate::diag::{Diag, Diagnostics};
use crate::film::SampleBuffer;
use crate::scene::ParamList;

use super::super::camera::PixelRect;
use super::super::stats::Stats;
use super::{DepthFilter, Hider, HiderConfig, ShadedGrid};

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

/// Rasterises the polygon `poly` (raster coordinates, any winding, even-odd) into the
/// `w`×`w` masks of the pixels `[px0, px1] × [py0, py1]`, stored row-major in `masks`
/// (cleared first). A cell is covered when its centre is inside the polygon; a centre exactly
/// on an edge belongs to the polygon on the edge's left (in raster x), one side only.
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
    let wf = w as f32;
    let n = poly.len();
    for e in 0..n {
        let (mut a, mut b) = (poly[e], poly[(e + 1) % n]);
        // Canonical order (lower y first, then lower x): both polygons sharing this edge compute
        // bit-identical crossings.
        if (a[1], a[0]) > (b[1], b[0]) {
            std::mem::swap(&mut a, &mut b);
        }
        if a[1] == b[1] {
            continue; // horizontal edges cross no row centre
        }
        let dxdy = (b[0] - a[0]) / (b[1] - a[1]);
        // Global subpixel rows whose centre (r + ½)/w lies in [a.y, b.y). All of them are
        // walked (from the edge's own first row) so the error carry below does not depend on
        // the window; rows outside it are skipped after updating the carry.
        let ra = (a[1] * wf - 0.5).ceil() as i64;
        let rb = (b[1] * wf - 0.5).ceil() as i64;
        let (wy0, wy1) = (py0 as i64 * w as i64, (py1 as i64 + 1) * w as i64);
        // Cumulative quantisation error of this edge's crossings, in cells: choosing each row's
        // first covered cell against it keeps every run of rows within one cell of the exact
        // area right of the edge (Bresenham-style), instead of half a cell per row.
        let mut carry = 0f32;
        for r in ra..rb.min(wy1) {
            let yc = (r as f32 + 0.5) / wf;
            if !(yc >= a[1] && yc < b[1]) {
                continue;
            }
            let xe = a[0] + (yc - a[1]) * dxdy;
            // Crossing in global cell units, and the first cell counted right of it.
            let u = xe * wf;
            let first_cell = (u - carry - 0.5).floor() + 1.0;
            carry += first_cell - u;
            if r < wy0 {
                continue;
            }
            let py = r.div_euclid(w as i64);
            let row = (r - py * w as i64) as usize;
            let line = (py - py0 as i64) as usize * npx;
            // Pixel px holds cells px·w .. px·w + w; pixels right of the crossing's pixel flip
            // whole rows.
            let pxe = (first_cell / wf).floor();
            let first = if pxe < px0 as f32 {
                px0
            } else if pxe > px1 as f32 {
                continue;
            } else {
                let pxe = pxe as i32;
                let from = (first_cell - pxe as f32 * wf).clamp(0.0, wf) as usize;
                flip_row(&mut masks[line + (pxe - px0) as usize], w, row, from);
                pxe + 1
            };
            for px in first..=px1 {
                flip_row(&mut masks[line + (px - px0) as usize], w, row, 0);
            }
        }
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
    /// `Hider "abuffer"` with its parameters: `"masksize"` 4, 8 (default) or 16.
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
        ABuffer::with_mask(config, w)
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

    fn hide(&self, rect: PixelRect, grids: &[&ShadedGrid], stats: &Stats) -> SampleBuffer {
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
        for g in grids {
            if g.aov_width == aw {
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
    let wx0 = (rect.x0 as f32).max(g.bound[0]);
    let wy0 = (rect.y0 as f32).max(g.bound[1]);
    let wx1 = (rect.x1 as f32).min(g.bound[2]);
    let wy1 = (rect.y1 as f32).min(g.bound[3]);
    if !(wx0 < wx1 && wy0 < wy1) {
        return;
    }
    let rw = rect.width();
    let mut aov = vec![0f32; aw];
    for j in 0..g.nv.saturating_sub(1) {
        for i in 0..nu.saturating_sub(1) {
            let m = j * (nu - 1) + i;
            if !g.live[m] {
                continue;
            }
            let k = j * nu + i;
            let corner = [k, k + 1, k + nu + 1, k + nu];
            let poly = corner.map(|c| g.xy[c]);
            let (mut x0, mut y0, mut x1, mut y1) = (
                f32::INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::NEG_INFINITY,
            );
            for p in &poly {
                x0 = x0.min(p[0]);
                y0 = y0.min(p[1]);
                x1 = x1.max(p[0]);
                y1 = y1.max(p[1]);
            }
            if !(x0.max(wx0) <= x1.min(wx1) && y0.max(wy0) <= y1.min(wy1)) {
                continue;
            }
            let px0 = (x0.max(wx0).floor() as i32).max(rect.x0);
            let px1 = (x1.min(wx1).floor() as i32).min(rect.x1 - 1);
            let py0 = (y0.max(wy0).floor() as i32).max(rect.y0);
            let py1 = (y1.min(wy1).floor() as i32).min(rect.y1 - 1);
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
            let mean = |f: &dyn Fn(usize) -> [f32; 3]| {
                let mut s = [0f32; 3];
                for &c in &corner {
                    let v = f(c);
                    for t in 0..3 {
                        s[t] += 0.25 * v[t];
                    }
                }
                s
            };
            let flat_c = mean(&|c| g.ci[c]);
            let flat_o = mean(&|c| g.oi[c]);
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
        // (0,0) (1,0) (1,1): exactly half the pixel; the carried crossings keep it within a
        // cell (plain cell-centre sampling would give 28 of 64).
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
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        for w in [4usize, 8, 16] {
            let mut worst = 0f32;
            for _ in 0..300 {
                // A random convex quad inside the pixel (a micropolygon's shape).
                let (cx, cy, r) = (0.3 + 0.4 * rnd(), 0.3 + 0.4 * rnd(), 0.1 + 0.2 * rnd());
                let a0 = rnd() * 6.283;
                let poly: Vec<[f32; 2]> = (0..4)
                    .map(|k| {
                        let t = a0 + k as f32 * 1.5708 + 0.5 * (rnd() - 0.5);
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

    #[test]
    fn half_plane_coverage_within_one_cell() {
        // A line through the pixel at many angles: |coverage − exact area| ≤ 1/64 at 8×8.
        let mut worst = 0f32;
        for k in 0..180 {
            let th = (k as f32 + 0.37) * std::f32::consts::PI / 180.0;
            let (c, s) = (th.cos(), th.sin());
            let off = 0.13 * ((k % 7) as f32 - 3.0) / 3.0;
            // The half-plane n·(p − centre) ≤ off, as a big polygon clipped by the pixel.
            let (n, t) = ([c, s], [-s, c]);
            let o = [0.5 + n[0] * off, 0.5 + n[1] * off];
            let big = 10.0;
            let poly = [
                [o[0] + t[0] * big, o[1] + t[1] * big],
                [o[0] - t[0] * big, o[1] - t[1] * big],
                [
                    o[0] - t[0] * big - n[0] * big,
                    o[1] - t[1] * big - n[1] * big,
                ],
                [
                    o[0] + t[0] * big - n[0] * big,
                    o[1] + t[1] * big - n[1] * big,
                ],
            ];
            let cov = popcount(&mask_of(&poly, 8)) as f32 / 64.0;
            // Exact area by fine numerical integration of the clipped half-plane.
            let steps = 2000;
            let mut area = 0f64;
            for iy in 0..steps {
                let y = (iy as f64 + 0.5) / steps as f64;
                // x range in [0,1] with c·(x−o.x) + s·(y−o.y) ≤ 0
                let (c, s) = (c as f64, s as f64);
                let rhs = -s * (y - o[1] as f64);
                let len = if c.abs() < 1e-12 {
                    if rhs >= 0.0 {
                        1.0
                    } else {
                        0.0
                    }
                } else {
                    let xb = o[0] as f64 + rhs / c;
                    if c > 0.0 {
                        xb.clamp(0.0, 1.0)
                    } else {
                        1.0 - xb.clamp(0.0, 1.0)
                    }
                };
                area += len / steps as f64;
            }
            // Edges within 15° of horizontal are quantised to whole rows where they cross
            // one (the book's row masks): bounded by half a row instead.
            let shallow = (th - std::f32::consts::FRAC_PI_2).abs() < 15f32.to_radians();
            let err = (cov - area as f32).abs();
            if shallow {
                assert!(err <= 4.0 / 64.0, "angle {k}: {err}");
            } else {
                worst = worst.max(err);
            }
        }
        assert!(worst <= 1.0 / 64.0 + 1e-4, "worst coverage error {worst}");
    }
}
