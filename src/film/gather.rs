//! Pixel filtering as a gather: the fast path for the usual buffer (r g b a z) and a
//! separable filter reaching at most one pixel beyond a sample's own (half widths below 1.5:
//! the default gaussian 2 × 2, box 1 × 1, triangle 2 × 2, …).
//!
//! Input: each bucket's [`SampleBuffer`], turned once — right after hiding, in parallel — into
//! a [`Prepared`] bucket: per pixel, every sample's filter weights towards the pixel's own
//! column and the columns either side (zero beyond the filter's reach), the same for rows, and
//! its r g b a, as blocks of [`LANES`] floats (structure of arrays), plus the pixel's depth
//! (its own samples through the depth filter) and the range of each channel. Output: a
//! bucket's filtered pixels ([`gather_tile`]), each the weighted mean over the samples of its
//! 3 × 3 neighbour pixels, which may belong to neighbouring buckets.
//!
//! Invariants: weights are those of the scatter in [`super::resolve`] (the same reach test and
//! the same [`FilterTables`] lookups, bit for bit); sums are f32 over [`LANES`] lanes in a fixed
//! order (neighbour by neighbour, then a fixed reduction tree), so a pixel never depends on the
//! bucket layout or the thread; a channel whose values are equal over the whole neighbourhood
//! is that value exactly (a constant image stays constant); a sample with a non-finite value
//! is skipped where its weight is 0, as the scatter does; samples outside the image do not
//! exist (the weights renormalise). Samples lie inside their own pixel (every hider keeps
//! them there), so they reach at most one pixel either side.

use super::filter::{Filter, FilterTables, Table1d};
use super::resolve::{DepthFilter, Film, Tile};
use super::SampleBuffer;

/// Samples processed together: one AVX register of f32.
pub const LANES: usize = 8;
/// Columns (rows) a sample can reach: its own and one either side.
const TAPS: usize = 3;
/// Blocks per pixel: x weights ×3, y weights ×3, r, g, b, a.
const BLOCKS: usize = 2 * TAPS + 4;

/// Most samples per pixel the gather handles (eight chunks of [`LANES`]).
pub const MAX_SPP: usize = 64;

/// Whether the gather handles a frame: r g b a z samples into an r g b a z film, through a
/// tabulated (separable) filter with half widths below 1.5, at most [`MAX_SPP`] samples per
/// pixel.
pub fn applies(
    filter: &Filter,
    tables: Option<&FilterTables>,
    buf_channels: usize,
    spp: usize,
    film: &Film,
) -> bool {
    let (hx, hy) = filter.radius();
    tables.is_some()
        && buf_channels == 5
        && (1..=MAX_SPP).contains(&spp)
        && film.channels() == 5
        && film.channel("z") == Some(4)
        && hx < 1.5
        && hy < 1.5
}

/// A bucket's samples ready for [`gather_tile`] (see the module comment).
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    /// Raster pixel of the first pixel, and the size in pixels.
    pub x0: i32,
    pub y0: i32,
    pub width: usize,
    pub height: usize,
    spp: usize,
    /// Samples per pixel rounded up to [`LANES`] (the extra lanes weigh 0).
    lanes: usize,
    /// Per pixel, [`BLOCKS`] blocks of `lanes` floats.
    data: Vec<f32>,
    /// Per pixel: depth from its own samples.
    z: Vec<f32>,
    /// Per pixel: the least r g b a over its samples, then the greatest.
    range: Vec<[f32; 8]>,
    /// Per pixel: bit `8·block + chunk` set when weight block `block` (0–5) has a non-zero
    /// weight in chunk `chunk`; bit 63 set when every r g b a is finite.
    flags: Vec<u64>,
}

const FINITE: u64 = 1 << 63;

/// What preparing a pixel needs from the frame: the filter's half widths and tables, the
/// depth filter, the kernel build to run, and the storage of filtered buckets for reuse.
#[derive(Debug)]
pub struct PrepareCtx<'a> {
    h: (f32, f32),
    t: &'a FilterTables,
    /// Each table as pairs (t[i], t[i + 1]): one 64-bit gather per lookup.
    pairs: [Vec<[f32; 2]>; 2],
    df: DepthFilter,
    kernel: Kernel,
    pool: std::sync::Mutex<Vec<Vec<f32>>>,
}

impl<'a> PrepareCtx<'a> {
    pub fn new(filter: &Filter, t: &'a FilterTables, df: DepthFilter) -> PrepareCtx<'a> {
        let pairs = |t: &Table1d| {
            let (tab, _, _) = t.parts();
            tab.windows(2).map(|w| [w[0], w[1]]).collect()
        };
        PrepareCtx {
            h: filter.radius(),
            t,
            pairs: [pairs(&t.x), pairs(&t.y)],
            df,
            kernel: pick_kernel(),
            pool: Default::default(),
        }
    }

    /// Keeps a bucket's storage for the next [`Prepared::new`] (no allocation or clearing
    /// per bucket once the first rows are done).
    pub fn recycle(&self, p: Prepared) {
        if let Ok(mut pool) = self.pool.lock() {
            pool.push(p.data);
        }
    }
}

impl Prepared {
    /// A bucket of `width × height` pixels from raster pixel (x0, y0), `spp` samples each
    /// (at most [`MAX_SPP`]), to be filled pixel by pixel with [`Prepared::rgba_mut`] and
    /// [`Prepared::finish_pixel`] (every pixel: the storage may come back from
    /// [`PrepareCtx::recycle`] holding an older bucket's values).
    pub fn new(
        ctx: &PrepareCtx,
        x0: i32,
        y0: i32,
        width: usize,
        height: usize,
        spp: usize,
    ) -> Prepared {
        assert!((1..=MAX_SPP).contains(&spp));
        let lanes = spp.div_ceil(LANES) * LANES;
        let npix = width * height;
        let mut data = ctx
            .pool
            .lock()
            .ok()
            .and_then(|mut p| p.pop())
            .unwrap_or_default();
        data.resize(npix * BLOCKS * lanes, 0.0);
        Prepared {
            x0,
            y0,
            width,
            height,
            spp,
            lanes,
            data,
            z: vec![f32::INFINITY; npix],
            range: vec![[0f32; 8]; npix],
            flags: vec![0; npix],
        }
    }

    /// Heap size, for the peak-memory statistic.
    pub fn bytes(&self) -> usize {
        self.data.len() * 4 + self.z.len() * (4 + 32 + 8)
    }

    /// Floats per block (samples per pixel rounded up to [`LANES`]).
    pub fn lanes(&self) -> usize {
        self.lanes
    }

    #[inline]
    fn block(&self, i: usize) -> &[f32] {
        let n = BLOCKS * self.lanes;
        &self.data[i * n..(i + 1) * n]
    }

    /// The r g b a blocks of pixel `pix` (`4 × lanes` floats: r for samples 0…, then g, b,
    /// a), for the caller to fill before [`Prepared::finish_pixel`].
    #[inline]
    pub fn rgba_mut(&mut self, pix: usize) -> &mut [f32] {
        let n = BLOCKS * self.lanes;
        &mut self.data[pix * n + 2 * TAPS * self.lanes..(pix + 1) * n]
    }

    /// Completes pixel `pix` (raster pixel (qx, qy)) once its r g b a are in place: the
    /// filter weights of its samples at `xs`, `ys` (`lanes` each; padding lanes NaN, which
    /// reach nothing), its depth from `zs` (its samples' depths), its channel ranges.
    pub fn finish_pixel(
        &mut self,
        ctx: &PrepareCtx,
        pix: usize,
        (qx, qy): (i32, i32),
        xs: &[f32],
        ys: &[f32],
        zs: &[f32],
    ) {
        let (lanes, spp) = (self.lanes, self.spp);
        let n = BLOCKS * lanes;
        let blk = &mut self.data[pix * n..(pix + 1) * n];
        let (w, rgba) = blk.split_at_mut(2 * TAPS * lanes);
        let (wx, wy) = w.split_at_mut(TAPS * lanes);
        let fx = ctx
            .kernel
            .weights(&xs[..lanes], qx, ctx.h.0, &ctx.t.x, &ctx.pairs[0], wx);
        let fy = ctx
            .kernel
            .weights(&ys[..lanes], qy, ctx.h.1, &ctx.t.y, &ctx.pairs[1], wy);
        let mut flags = fx as u64 | (fy as u64) << (8 * TAPS);
        // Padding lanes hold no sample.
        for c in 0..4 {
            rgba[c * lanes + spp..(c + 1) * lanes].fill(0.0);
        }
        let (range, finite) = ctx.kernel.range(rgba, lanes, spp);
        if finite {
            flags |= FINITE;
        }
        self.flags[pix] = flags;
        self.range[pix] = range;
        self.z[pix] = own_depth(zs[..spp].iter().copied(), ctx.df);
    }
}

/// Per channel (r g b a) the least and greatest of the first `spp` values of each block,
/// as [lo r, lo g, lo b, lo a, hi r, …], and whether every value is finite.
fn range_portable(rgba: &[f32], lanes: usize, spp: usize) -> ([f32; 8], bool) {
    let mut range = [0f32; 8];
    let mut finite = true;
    for c in 0..4 {
        let v = &rgba[c * lanes..c * lanes + spp];
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for &x in v {
            lo = lo.min(x);
            hi = hi.max(x);
            finite &= x.is_finite();
        }
        range[c] = lo;
        range[4 + c] = hi;
    }
    (range, finite)
}

/// Prepares a bucket's r g b a z samples for [`gather_tile`] (see the module comment).
pub fn prepare(buf: &SampleBuffer, ctx: &PrepareCtx) -> Prepared {
    let spp = buf.samples_per_pixel();
    let mut p = Prepared::new(ctx, buf.x0, buf.y0, buf.width, buf.height, spp);
    let lanes = p.lanes;
    let ch = buf.channels;
    debug_assert!(ch == 5);
    let mut xs = vec![f32::NAN; lanes];
    let mut ys = vec![f32::NAN; lanes];
    let mut zs = vec![0f32; spp];
    for j in 0..buf.height {
        for i in 0..buf.width {
            let pix = j * buf.width + i;
            let base = pix * spp;
            let rgba = p.rgba_mut(pix);
            for s in 0..spp {
                let [x, y] = buf.positions[base + s];
                xs[s] = x;
                ys[s] = y;
                let v = &buf.values[(base + s) * ch..(base + s) * ch + 5];
                for c in 0..4 {
                    rgba[c * lanes + s] = v[c];
                }
                zs[s] = v[4];
            }
            let q = (buf.x0 + i as i32, buf.y0 + j as i32);
            p.finish_pixel(ctx, pix, q, &xs, &ys, &zs);
        }
    }
    p
}

/// A pixel's depth from its own samples' depths (the scatter in [`super::resolve`] uses it
/// too).
pub(super) fn own_depth(zs: impl Iterator<Item = f32>, df: DepthFilter) -> f32 {
    match df {
        DepthFilter::Min => zs.fold(f32::INFINITY, f32::min),
        DepthFilter::Max => zs.fold(f32::NEG_INFINITY, f32::max),
        DepthFilter::Average => {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for z in zs.filter(|z| z.is_finite()) {
                sum += z as f64;
                n += 1;
            }
            if n == 0 {
                f32::INFINITY
            } else {
                (sum / n as f64) as f32
            }
        }
    }
}

/// Which build of the two vectorised loops runs (both give the same bits: the same IEEE
/// operations per lane, no fused multiply-adds).
#[derive(Clone, Copy, Debug)]
enum Kernel {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

fn pick_kernel() -> Kernel {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        return Kernel::Avx2;
    }
    Kernel::Portable
}

impl Kernel {
    /// Weights of samples at coordinates `pos` (one axis; `lanes` of them) in pixel `q`
    /// towards the pixels q − 1, q, q + 1, into `out` (three blocks of `lanes`): the
    /// scatter's reach test `sx − h − 0.5 ≤ c ≤ sx + h − 0.5` and its lookup at c + 0.5 − sx.
    /// Returns bit `8·o + chunk` set where block o has a non-zero weight in that chunk.
    fn weights(
        self,
        pos: &[f32],
        q: i32,
        h: f32,
        t: &Table1d,
        pairs: &[[f32; 2]],
        out: &mut [f32],
    ) -> u32 {
        match self {
            Kernel::Portable => weights_portable(pos, q, h, t, out),
            // SAFETY: chosen only where the CPU has AVX2.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe { avx2::weights(pos, q, h, t, pairs, out) },
        }
    }

    /// See [`range_portable`].
    fn range(self, rgba: &[f32], lanes: usize, spp: usize) -> ([f32; 8], bool) {
        match self {
            Kernel::Portable => range_portable(rgba, lanes, spp),
            // SAFETY: chosen only where the CPU has AVX2.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe { avx2::range(rgba, lanes, spp) },
        }
    }
}

fn weights_portable(pos: &[f32], q: i32, h: f32, t: &Table1d, out: &mut [f32]) -> u32 {
    let lanes = pos.len();
    let mut flags = 0u32;
    let c = [(q - 1) as f32, q as f32, (q + 1) as f32];
    let mid = q as f32 + 0.5;
    for (s, &x) in pos.iter().enumerate() {
        let (a, b) = (x - h - 0.5, x + h - 0.5);
        let reached = c.map(|c| !(c < a) && c <= b);
        let w = if h <= 1.0 {
            // Narrow: the sample reaches its own column and (but at x = q + ½) one side;
            // one lookup serves whichever side is reached.
            let own = t.at(c[1] + 0.5 - x);
            let side = t.at(if x < mid {
                c[0] + 0.5 - x
            } else {
                c[2] + 0.5 - x
            });
            [side, own, side]
        } else {
            c.map(|c| t.at(c + 0.5 - x))
        };
        for o in 0..TAPS {
            let w = if reached[o] { w[o] } else { 0.0 };
            out[o * lanes + s] = w;
            if w != 0.0 {
                flags |= 1 << (8 * o + s / LANES);
            }
        }
    }
    flags
}

/// Filters the pixels `[x0, x0 + w) × [y0, y0 + h)` of `film` from the prepared buckets
/// `parts`, which must hold every pixel of the region grown by one inside the image.
pub fn gather_tile(
    film: &Film,
    parts: &[&Prepared],
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
) -> Tile {
    let x1 = (x0 + w).min(film.width);
    let y1 = (y0 + h).min(film.height);
    let mut tile = Tile {
        x0,
        y0,
        w: 0,
        h: 0,
        data: Vec::new(),
    };
    if x0 >= x1 || y0 >= y1 || parts.is_empty() {
        return tile;
    }
    let (w, h) = (x1 - x0, y1 - y0);
    tile.w = w;
    tile.h = h;
    tile.data = vec![0f32; w * h * 5];
    let lanes = parts[0].lanes;
    debug_assert!(parts.iter().all(|p| p.lanes == lanes));
    // Each pixel of the region grown by one: (bucket, pixel index), None outside the image.
    let gw = w + 2;
    let mut grid: Vec<Option<(usize, usize)>> = vec![None; gw * (h + 2)];
    let (gx0, gy0) = (x0 as i64 - 1, y0 as i64 - 1);
    let (gx1, gy1) = (
        (x1 as i64 + 1).min(film.width as i64),
        (y1 as i64 + 1).min(film.height as i64),
    );
    for (k, p) in parts.iter().enumerate() {
        // The part's pixels inside the grown region and the image.
        let (px0, py0) = (p.x0 as i64, p.y0 as i64);
        let xa = px0.max(gx0).max(0);
        let xb = (px0 + p.width as i64).min(gx1);
        let ya = py0.max(gy0).max(0);
        let yb = (py0 + p.height as i64).min(gy1);
        for y in ya..yb {
            for x in xa..xb {
                let pi = (y - py0) as usize * p.width + (x - px0) as usize;
                grid[(y - gy0) as usize * gw + (x - gx0) as usize] = Some((k, pi));
            }
        }
    }
    let kernel = pick_kernel();
    let mut nb: [(&[f32], u64); 9] = [(&[], 0); 9];
    for j in 0..h {
        for i in 0..w {
            let out = &mut tile.data[(j * w + i) * 5..(j * w + i + 1) * 5];
            let Some((ok, opi)) = grid[(j + 1) * gw + i + 1] else {
                out[4] = f32::INFINITY;
                continue;
            };
            let own = parts[ok];
            out[4] = own.z[opi];
            // The neighbours present, row by row: neighbour k is at (dx, dy) = (k % 3, k / 3)
            // in the 3 × 3 around the pixel; absent ones keep no chunk.
            let mut lo = [f32::INFINITY; 4];
            let mut hi = [f32::NEG_INFINITY; 4];
            let mut finite = FINITE;
            for k in 0..9 {
                let (dx, dy) = (k % 3, k / 3);
                nb[k] = (&[], 0);
                if let Some((pk, pi)) = grid[(j + dy) * gw + i + dx] {
                    let p = parts[pk];
                    let f = p.flags[pi];
                    // From the neighbour, the centre pixel lies at offset (1 − dx, 1 − dy):
                    // weight blocks 2 − dx (x) and 5 − dy (y); a chunk counts when both
                    // have a non-zero weight in it.
                    let chunks = ((f >> (8 * (2 - dx))) & (f >> (8 * (5 - dy)))) & 0xff;
                    nb[k] = (p.block(pi), chunks);
                    let r = &p.range[pi];
                    for c in 0..4 {
                        lo[c] = lo[c].min(r[c]);
                        hi[c] = hi[c].max(r[4 + c]);
                    }
                    finite &= f;
                }
            }
            let finite = finite != 0;
            let sums = match (finite, kernel) {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: chosen only where the CPU has AVX2.
                (true, Kernel::Avx2) => unsafe { avx2::accumulate(&nb, lanes) },
                (true, _) => accumulate_portable(&nb, lanes, false),
                (false, _) => accumulate_portable(&nb, lanes, true),
            };
            let ws = sums[4];
            if ws.abs() > 1e-12 {
                for c in 0..4 {
                    out[c] = sums[c] / ws;
                }
            } else {
                // Nothing (or weights cancelling) in the support: the plain mean of the
                // pixel's own samples.
                let b = own.block(opi);
                for c in 0..4 {
                    let s: f64 = (0..own.spp)
                        .map(|s| b[(2 * TAPS + c) * lanes + s] as f64)
                        .sum();
                    out[c] = (s / own.spp as f64) as f32;
                }
            }
            // Equal over the neighbourhood: exactly that value.
            if finite {
                for c in 0..4 {
                    if lo[c] == hi[c] {
                        out[c] = lo[c];
                    }
                }
            }
        }
    }
    tile
}

/// A bucket's output tile started right after its samples are prepared, while they are in
/// the caches: every pixel whose neighbours (inside the image) all lie in `p` is filtered
/// now; the ring of pixels needing the neighbouring buckets is left for
/// [`finish_tile`]. The values are those [`gather_tile`] gives (the same blocks in the same
/// order), so the split changes nothing.
#[derive(Clone, Debug, Default)]
pub struct Partial {
    pub tile: Tile,
    /// Pixels already filtered: [x0, x1) × [y0, y1) (empty when x0 ≥ x1 or y0 ≥ y1).
    inner: [usize; 4],
}

impl Partial {
    /// A tile of output pixels `[x0, x0 + w) × [y0, y0 + h)` with nothing filtered yet.
    pub fn empty(film: &Film, x0: usize, y0: usize, w: usize, h: usize) -> Partial {
        let (x1, y1) = ((x0 + w).min(film.width), (y0 + h).min(film.height));
        let (w, h) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
        Partial {
            tile: Tile {
                x0,
                y0,
                w,
                h,
                data: vec![0f32; w * h * 5],
            },
            inner: [0; 4],
        }
    }
}

/// Starts the tile of output pixels `[x0, x0 + w) × [y0, y0 + h)` from bucket `p` (see
/// [`Partial`]).
pub fn start_tile(film: &Film, p: &Prepared, x0: usize, y0: usize, w: usize, h: usize) -> Partial {
    let x1 = (x0 + w).min(film.width);
    let y1 = (y0 + h).min(film.height);
    let (x0c, y0c) = (x0.min(x1), y0.min(y1));
    let mut tile = Tile {
        x0,
        y0,
        w: x1 - x0c,
        h: y1 - y0c,
        data: vec![0f32; (x1 - x0c) * (y1 - y0c) * 5],
    };
    // Pixels whose 3 × 3 neighbours inside the image are all in `p`.
    let (px0, py0) = (p.x0.max(0) as usize, p.y0.max(0) as usize);
    let (px1, py1) = (
        (p.x0 + p.width as i32).max(0) as usize,
        (p.y0 + p.height as i32).max(0) as usize,
    );
    let lo = |a: usize| if a == 0 { 0 } else { a + 1 };
    let hi = |b: usize, end: usize| if b >= end { end } else { b.saturating_sub(1) };
    let inner = [
        lo(px0).max(x0c),
        lo(py0).max(y0c),
        hi(px1, film.width).min(x1),
        hi(py1, film.height).min(y1),
    ];
    if inner[0] < inner[2] && inner[1] < inner[3] {
        let part = gather_tile(
            film,
            &[p],
            inner[0],
            inner[1],
            inner[2] - inner[0],
            inner[3] - inner[1],
        );
        copy_into(&mut tile, &part);
    }
    Partial { tile, inner }
}

/// Filters the pixels of `partial` that [`start_tile`] left, from the prepared buckets
/// `parts` (which must hold every pixel of the tile grown by one inside the image), and
/// returns the whole tile.
pub fn finish_tile(film: &Film, parts: &[&Prepared], partial: Partial) -> Tile {
    let Partial { mut tile, inner } = partial;
    let [x0, y0, x1, y1] = [tile.x0, tile.y0, tile.x0 + tile.w, tile.y0 + tile.h];
    let done = inner[0] < inner[2] && inner[1] < inner[3];
    let strips = if done {
        [
            [x0, y0, x1, inner[1]],
            [x0, inner[3], x1, y1],
            [x0, inner[1], inner[0], inner[3]],
            [inner[2], inner[1], x1, inner[3]],
        ]
    } else {
        [[x0, y0, x1, y1], [0; 4], [0; 4], [0; 4]]
    };
    for [a, b, c, d] in strips {
        if a < c && b < d {
            let part = gather_tile(film, parts, a, b, c - a, d - b);
            copy_into(&mut tile, &part);
        }
    }
    tile
}

/// Copies `part` (inside `tile`) into `tile`.
fn copy_into(tile: &mut Tile, part: &Tile) {
    for j in 0..part.h {
        let src = j * part.w * 5;
        let dst = ((part.y0 + j - tile.y0) * tile.w + part.x0 - tile.x0) * 5;
        tile.data[dst..dst + part.w * 5].copy_from_slice(&part.data[src..src + part.w * 5]);
    }
}

/// Σ w·r, Σ w·g, Σ w·b, Σ w·a, Σ w over the neighbours' chunks (w = wx · wy towards the
/// centre pixel; neighbour k is (block, chunk mask), its weight blocks 2 − k % 3 and
/// 5 − k / 3): per lane, chunk by chunk into two alternating sets of accumulators (by chunk
/// index), then the sets added and each reduced by [`reduce`]. Chunks whose weights are all
/// zero are left out (they add nothing). With `skip_zero`, single products with a zero
/// weight are left out too (non-finite values must not poison the sum).
fn accumulate_portable(nb: &[(&[f32], u64); 9], lanes: usize, skip_zero: bool) -> [f32; 5] {
    let mut acc = [[[0f32; LANES]; 5]; 2];
    for (k, &(b, chunks)) in nb.iter().enumerate() {
        let (dx, dy) = (k % 3, k / 3);
        let wx = (2 - dx) * lanes;
        let wy = (TAPS + 2 - dy) * lanes;
        for chunk in 0..lanes / LANES {
            if chunks & (1 << chunk) == 0 {
                continue;
            }
            let set = chunk & 1;
            for l in 0..LANES {
                let s = chunk * LANES + l;
                let w = b[wx + s] * b[wy + s];
                if skip_zero && w == 0.0 {
                    continue;
                }
                acc[set][4][l] += w;
                for c in 0..4 {
                    acc[set][c][l] += w * b[(2 * TAPS + c) * lanes + s];
                }
            }
        }
    }
    let mut out = [0f32; 5];
    for c in 0..5 {
        let mut v = [0f32; LANES];
        for l in 0..LANES {
            v[l] = acc[0][c][l] + acc[1][c][l];
        }
        out[c] = reduce(v);
    }
    out
}

/// The sum of 8 lanes as AVX reduces them: ((v0 + v4) + (v2 + v6)) + ((v1 + v5) + (v3 + v7)).
#[inline]
fn reduce(v: [f32; LANES]) -> f32 {
    let s = [v[0] + v[4], v[1] + v[5], v[2] + v[6], v[3] + v[7]];
    (s[0] + s[2]) + (s[1] + s[3])
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::{Table1d, BLOCKS, LANES, TAPS};

    /// [`super::weights_portable`], eight samples at a time.
    #[target_feature(enable = "avx2")]
    pub(super) fn weights(
        pos: &[f32],
        q: i32,
        h: f32,
        t: &Table1d,
        pairs: &[[f32; 2]],
        out: &mut [f32],
    ) -> u32 {
        let mut flags = 0u32;
        let lanes = pos.len();
        assert!(lanes % LANES == 0 && out.len() >= TAPS * lanes);
        let (_, scale, steps) = t.parts();
        assert!(steps >= 0 && pairs.len() > steps as usize);
        let sign = _mm256_set1_ps(-0.0);
        let (hv, half) = (_mm256_set1_ps(h), _mm256_set1_ps(0.5));
        let (sc, st, zi) = (
            _mm256_set1_ps(scale),
            _mm256_set1_epi32(steps),
            _mm256_setzero_si256(),
        );
        let narrow = h <= 1.0;
        let mid = _mm256_set1_ps(q as f32 + 0.5);
        let lookup = |d: __m256| {
            let u = _mm256_mul_ps(_mm256_andnot_ps(sign, d), sc);
            // `u as i32` then min(steps); out-of-range lanes are clamped only to keep the
            // gathers in bounds (they are not reached, so they weigh 0).
            let i = _mm256_max_epi32(_mm256_min_epi32(_mm256_cvttps_epi32(u), st), zi);
            let f = _mm256_sub_ps(u, _mm256_cvtepi32_ps(i));
            // SAFETY: 0 ≤ i ≤ steps < pairs.len().
            let (g0, g1) = unsafe {
                let p = pairs.as_ptr() as *const i64;
                (
                    _mm256_castsi256_ps(_mm256_i32gather_epi64::<8>(p, _mm256_castsi256_si128(i))),
                    _mm256_castsi256_ps(_mm256_i32gather_epi64::<8>(
                        p,
                        _mm256_extracti128_si256::<1>(i),
                    )),
                )
            };
            // g0 = a0 b0 a1 b1 | a2 b2 a3 b3, g1 = a4 b4 a5 b5 | a6 b6 a7 b7.
            let order = |v: __m256| {
                _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(_mm256_castps_pd(v)))
            };
            let ta = order(_mm256_shuffle_ps::<0b10_00_10_00>(g0, g1));
            let tb = order(_mm256_shuffle_ps::<0b11_01_11_01>(g0, g1));
            _mm256_add_ps(ta, _mm256_mul_ps(f, _mm256_sub_ps(tb, ta)))
        };
        for chunk in 0..lanes / LANES {
            // SAFETY: LANES floats at chunk · LANES < lanes = pos.len().
            let x = unsafe { _mm256_loadu_ps(pos.as_ptr().add(chunk * LANES)) };
            let a = _mm256_sub_ps(_mm256_sub_ps(x, hv), half);
            let b = _mm256_sub_ps(_mm256_add_ps(x, hv), half);
            let c = [0, 1, 2].map(|o| _mm256_set1_ps((q - 1 + o as i32) as f32));
            let d = c.map(|c| _mm256_sub_ps(_mm256_add_ps(c, half), x));
            let w = if narrow {
                let own = lookup(d[1]);
                let left = _mm256_cmp_ps::<_CMP_LT_OQ>(x, mid);
                let side = lookup(_mm256_blendv_ps(d[2], d[0], left));
                [side, own, side]
            } else {
                d.map(lookup)
            };
            for o in 0..TAPS {
                let reached = _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_NLT_UQ>(c[o], a),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(c[o], b),
                );
                let w = _mm256_and_ps(reached, w[o]);
                let nz = _mm256_cmp_ps::<_CMP_NEQ_UQ>(w, _mm256_setzero_ps());
                if _mm256_movemask_ps(nz) != 0 {
                    flags |= 1 << (8 * o + chunk);
                }
                // SAFETY: LANES floats inside block o.
                unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(o * lanes + chunk * LANES), w) };
            }
        }
        flags
    }

    /// [`super::range_portable`], eight samples at a time (the padding lanes left out).
    #[target_feature(enable = "avx2")]
    pub(super) fn range(rgba: &[f32], lanes: usize, spp: usize) -> ([f32; 8], bool) {
        assert!(rgba.len() >= 4 * lanes && spp <= lanes && lanes % LANES == 0);
        let inf = _mm256_set1_ps(f32::INFINITY);
        let ninf = _mm256_set1_ps(f32::NEG_INFINITY);
        let zero = _mm256_setzero_ps();
        let mut range = [0f32; 8];
        let mut bad = _mm256_setzero_ps();
        for c in 0..4 {
            let (mut lo, mut hi) = (inf, ninf);
            for chunk in 0..lanes / LANES {
                // SAFETY: inside block c.
                let x = unsafe { _mm256_loadu_ps(rgba.as_ptr().add(c * lanes + chunk * LANES)) };
                let n = (spp - (chunk * LANES).min(spp)).min(LANES) as i32;
                let valid = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
                    _mm256_set1_epi32(n),
                    _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                ));
                lo = _mm256_min_ps(lo, _mm256_blendv_ps(inf, x, valid));
                hi = _mm256_max_ps(hi, _mm256_blendv_ps(ninf, x, valid));
                // x − x is 0 for finite x, NaN otherwise.
                let d = _mm256_sub_ps(x, x);
                bad = _mm256_or_ps(
                    bad,
                    _mm256_and_ps(valid, _mm256_cmp_ps::<_CMP_NEQ_UQ>(d, zero)),
                );
            }
            let l = _mm_min_ps(_mm256_castps256_ps128(lo), _mm256_extractf128_ps::<1>(lo));
            let l = _mm_min_ps(l, _mm_movehl_ps(l, l));
            let l = _mm_min_ss(l, _mm_shuffle_ps::<0b01>(l, l));
            let h = _mm_max_ps(_mm256_castps256_ps128(hi), _mm256_extractf128_ps::<1>(hi));
            let h = _mm_max_ps(h, _mm_movehl_ps(h, h));
            let h = _mm_max_ss(h, _mm_shuffle_ps::<0b01>(h, h));
            range[c] = _mm_cvtss_f32(l);
            range[4 + c] = _mm_cvtss_f32(h);
        }
        (range, _mm256_movemask_ps(bad) == 0)
    }

    /// One chunk of one neighbour into a set of accumulators.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn step(acc: &mut [__m256; 5], p: *const f32, wx: usize, wy: usize, rgba: usize, lanes: usize) {
        // SAFETY: the caller keeps every offset + LANES inside the block.
        unsafe {
            let w = _mm256_mul_ps(_mm256_loadu_ps(p.add(wx)), _mm256_loadu_ps(p.add(wy)));
            acc[4] = _mm256_add_ps(acc[4], w);
            for c in 0..4 {
                let v = _mm256_loadu_ps(p.add(rgba + c * lanes));
                acc[c] = _mm256_add_ps(acc[c], _mm256_mul_ps(w, v));
            }
        }
    }

    /// [`super::accumulate_portable`] without `skip_zero`, in AVX2: even chunks into one set
    /// of accumulators, odd chunks into the other.
    #[target_feature(enable = "avx2")]
    pub(super) fn accumulate(nb: &[(&[f32], u64); 9], lanes: usize) -> [f32; 5] {
        let z = _mm256_setzero_ps();
        let (mut a, mut b) = ([z; 5], [z; 5]);
        let nchunks = lanes / LANES;
        for (k, &(blk, chunks)) in nb.iter().enumerate() {
            if chunks == 0 {
                continue;
            }
            let (dx, dy) = (k % 3, k / 3);
            assert!(blk.len() >= BLOCKS * lanes && nchunks <= 8);
            let p = blk.as_ptr();
            let (wx, wy, rgba) = ((2 - dx) * lanes, (TAPS + 2 - dy) * lanes, 2 * TAPS * lanes);
            let mut chunk = 0;
            while chunk < nchunks {
                let o = chunk * LANES;
                if chunks & (1 << chunk) != 0 {
                    step(&mut a, p, wx + o, wy + o, rgba + o, lanes);
                }
                if chunk + 1 < nchunks && chunks & (2 << chunk) != 0 {
                    let o = o + LANES;
                    step(&mut b, p, wx + o, wy + o, rgba + o, lanes);
                }
                chunk += 2;
            }
        }
        let mut out = [0f32; 5];
        for c in 0..5 {
            let v = _mm256_add_ps(a[c], b[c]);
            let s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let s = _mm_add_ps(s, _mm_movehl_ps(s, s));
            let s = _mm_add_ss(s, _mm_shuffle_ps::<0b01>(s, s));
            out[c] = _mm_cvtss_f32(s);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::filter::FilterKind;
    use crate::film::resolve::filter_tile;

    /// A jittered r g b a z buffer over raster pixels [x0, x0 + w) × [y0, y0 + h).
    fn buffer(x0: i32, y0: i32, w: usize, h: usize, n: usize, seed: u32) -> SampleBuffer {
        let mut b = SampleBuffer::new(x0, y0, w, h, n, n, 5);
        let mut k = seed;
        let mut r = || {
            k = k.wrapping_mul(747796405).wrapping_add(2891336453);
            (k >> 8) as f32 / (1u32 << 24) as f32
        };
        for (s, p) in b.positions.iter_mut().enumerate() {
            let (px, py) = (p[0].floor(), p[1].floor());
            let (sx, sy) = (s % n, (s / n) % n);
            *p = [
                px + (sx as f32 + r()) / n as f32,
                py + (sy as f32 + r()) / n as f32,
            ];
        }
        for v in b.values.chunks_exact_mut(5) {
            for c in 0..4 {
                v[c] = r();
            }
            v[4] = 1.0 + r();
        }
        b
    }

    fn film(w: usize, h: usize) -> Film {
        Film::new(w, h, Film::standard_channels(&[]))
    }

    #[test]
    fn matches_the_scatter_to_float_rounding() {
        for (kind, width) in [
            (FilterKind::Gaussian, 2.0),
            (FilterKind::Box, 1.0),
            (FilterKind::Triangle, 2.0),
            (FilterKind::Sinc, 2.5),
            (FilterKind::Mitchell, 2.9),
        ] {
            let f = Filter::new(kind, width, width);
            let t = f.tables().unwrap();
            let (w, h) = (7, 5);
            for n in [1, 3, 4] {
                let whole = buffer(0, 0, w, h, n, 7);
                let fm = film(w, h);
                assert!(applies(&f, Some(&t), 5, n * n, &fm));
                let want = filter_tile(&fm, &whole, &f, 0, 0, w, h, DepthFilter::Min);
                let p = prepare(&whole, &PrepareCtx::new(&f, &t, DepthFilter::Min));
                let got = gather_tile(&fm, &[&p], 0, 0, w, h);
                for (k, (a, b)) in got.data.iter().zip(&want.data).enumerate() {
                    let tol = 2e-6 * b.abs().max(1.0);
                    assert!((a - b).abs() <= tol, "{kind:?} n={n} value {k}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn any_split_into_buckets_gives_the_same_bits() {
        let f = Filter::new(FilterKind::Gaussian, 2.0, 2.0);
        let t = f.tables().unwrap();
        let (w, h) = (9, 7);
        let whole = buffer(0, 0, w, h, 4, 3);
        let fm = film(w, h);
        let ctx = PrepareCtx::new(&f, &t, DepthFilter::Min);
        let one = gather_tile(&fm, &[&prepare(&whole, &ctx)], 0, 0, w, h);
        // Four buckets split at (4, 3), each a sub-buffer of the same samples.
        let sub = |x0: usize, y0: usize, x1: usize, y1: usize| {
            let mut b = SampleBuffer::new(x0 as i32, y0 as i32, x1 - x0, y1 - y0, 4, 4, 5);
            b.positions.clear();
            b.values.clear();
            for y in y0..y1 {
                for x in x0..x1 {
                    let s0 = (y * w + x) * 16;
                    b.positions.extend_from_slice(&whole.positions[s0..s0 + 16]);
                    b.values
                        .extend_from_slice(&whole.values[s0 * 5..(s0 + 16) * 5]);
                }
            }
            prepare(&b, &ctx)
        };
        let parts = [
            sub(0, 0, 4, 3),
            sub(4, 0, 9, 3),
            sub(0, 3, 4, 7),
            sub(4, 3, 9, 7),
        ];
        let refs: Vec<&Prepared> = parts.iter().collect();
        for (x0, y0, x1, y1) in [(0, 0, 4, 3), (4, 0, 9, 3), (0, 3, 4, 7), (4, 3, 9, 7)] {
            let tile = gather_tile(&fm, &refs, x0, y0, x1 - x0, y1 - y0);
            for j in 0..y1 - y0 {
                for i in 0..x1 - x0 {
                    let a = &tile.data[(j * (x1 - x0) + i) * 5..][..5];
                    let b = &one.data[((y0 + j) * w + x0 + i) * 5..][..5];
                    assert_eq!(
                        a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
                    );
                }
            }
        }
    }

    #[test]
    fn portable_and_vector_builds_agree_bit_for_bit() {
        let f = Filter::new(FilterKind::Gaussian, 2.0, 2.0);
        let t = f.tables().unwrap();
        let b = buffer(3, 2, 6, 5, 4, 11);
        let p = prepare(&b, &PrepareCtx::new(&f, &t, DepthFilter::Min));
        // Weights: the portable loop against whatever `prepare` ran.
        let lanes = p.lanes;
        for pix in 0..b.width * b.height {
            let (qx, qy) = (3 + (pix % b.width) as i32, 2 + (pix / b.width) as i32);
            let mut xs = vec![f32::NAN; lanes];
            let mut ys = vec![f32::NAN; lanes];
            for s in 0..16 {
                xs[s] = b.positions[pix * 16 + s][0];
                ys[s] = b.positions[pix * 16 + s][1];
            }
            let mut wx = vec![0f32; TAPS * lanes];
            let mut wy = vec![0f32; TAPS * lanes];
            weights_portable(&xs, qx, 1.0, &t.x, &mut wx);
            weights_portable(&ys, qy, 1.0, &t.y, &mut wy);
            let blk = p.block(pix);
            assert_eq!(&blk[..TAPS * lanes], &wx[..]);
            assert_eq!(&blk[TAPS * lanes..2 * TAPS * lanes], &wy[..]);
        }
        // Sums: every neighbourhood of the interior pixels.
        for j in 1..b.height - 1 {
            for i in 1..b.width - 1 {
                let mut nb: [(&[f32], u64); 9] = [(&[], 0); 9];
                for k in 0..9 {
                    nb[k] = (p.block((j + k / 3 - 1) * b.width + i + k % 3 - 1), 0xff);
                }
                let a = accumulate_portable(&nb, lanes, false);
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2.
                    let v = unsafe { avx2::accumulate(&nb, lanes) };
                    assert_eq!(a.map(f32::to_bits), v.map(f32::to_bits));
                }
                assert!(a[4] > 0.0);
            }
        }
    }

    #[test]
    fn constant_neighbourhoods_are_exact_and_nan_does_not_leak() {
        let f = Filter::new(FilterKind::Gaussian, 2.0, 2.0);
        let t = f.tables().unwrap();
        let mut b = buffer(0, 0, 6, 4, 4, 5);
        for v in b.values.chunks_exact_mut(5) {
            v[..4].copy_from_slice(&[0.1, 0.7, 0.3, 1.0]);
        }
        let fm = film(6, 4);
        let ctx = PrepareCtx::new(&f, &t, DepthFilter::Min);
        let p = prepare(&b, &ctx);
        let tile = gather_tile(&fm, &[&p], 0, 0, 6, 4);
        for px in tile.data.chunks_exact(5) {
            assert_eq!(&px[..4], &[0.1, 0.7, 0.3, 1.0]);
        }
        // A NaN sample in pixel (0, 0) lying left of its centre reaches pixel (1, 0)
        // with weight 0 in x only if it is beyond the reach: put it at the left edge.
        b.positions[0] = [0.0, 0.1];
        b.values[0] = f32::NAN;
        let p = prepare(&b, &ctx);
        let tile = gather_tile(&fm, &[&p], 0, 0, 6, 4);
        // Pixel (2, 0) does not reach the NaN sample: finite.
        assert!(tile.data[2 * 5].is_finite());
        // Pixel (1, 0): the sample at x = 0 is at distance 1.5 > 1 from its centre.
        assert!(tile.data[5].is_finite(), "{}", tile.data[5]);
        assert!(tile.data[0].is_nan());
    }
}
