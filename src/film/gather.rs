//! Pixel filtering as a gather: the fast path for the usual buffer (r g b a z) and a
//! separable filter reaching at most one pixel beyond a sample's own (half widths below 1.5:
//! the default gaussian 2 × 2, box 1 × 1, triangle 2 × 2, …).
//!
//! Input: each bucket's samples, turned once — right after hiding, in parallel, while they are
//! in the caches — into a [`Prepared`] bucket: per pixel, each sample's filter weights towards
//! the 3 × 3 pixels around (three x weights times three y weights, zero beyond the filter's
//! reach), and from them the pixel's *contributions*: Σ w·r, Σ w·g, Σ w·b, Σ w·a and Σ w over
//! its samples towards each of the nine pixels; plus the pixel's depth (its own samples
//! through the depth filter) and the range of each channel. Output: a bucket's filtered
//! pixels ([`gather_tile`]), each the sum of what its 3 × 3 neighbour pixels (which may belong
//! to neighbouring buckets) contribute to it, normalised — nine 8-float adds per pixel.
//!
//! Invariants: weights are those of the scatter in [`super::resolve`] (the same reach test and
//! the same [`FilterTables`] lookups, bit for bit); sums are f32 in a fixed order (per pixel and
//! target: lane by lane over the chunks of [`LANES`] samples, then a fixed reduction tree; the
//! nine contributions in a fixed tree), so a pixel never depends on the bucket layout or the
//! thread, and the vector and portable builds give the same bits (the scatter sums in f64: the
//! two agree to float rounding). A channel whose values are equal over the whole
//! neighbourhood is that value exactly (a constant image stays constant); a sample with a
//! non-finite value is skipped where its weight is 0, as the scatter does; samples outside
//! the image do not exist (the weights renormalise). Samples lie inside their own pixel (every
//! hider keeps them there), so they reach at most one pixel either side.

use super::filter::{Filter, FilterTables, Table1d};
use super::resolve::{DepthFilter, Film, Tile};
use super::SampleBuffer;
use crate::pool;

/// Samples processed together: one AVX register of f32.
pub const LANES: usize = 8;
/// Columns (rows) a sample can reach: its own and one either side.
const TAPS: usize = 3;
/// Sums a pixel contributes: r g b a w towards each of its 3 × 3 neighbours.
const NSUMS: usize = 5 * TAPS * TAPS;
/// [`NSUMS`] rounded up to whole vectors.
const SUMS: usize = NSUMS.div_ceil(LANES) * LANES;

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

/// What one pixel's samples give the filtered pixels around it (see the module comment).
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug)]
struct Contrib {
    /// Towards target t, the pixel at offset (t % 3 − 1, t / 3 − 1): Σ w·r, Σ w·g, Σ w·b,
    /// Σ w·a, Σ w at 5·t … 5·t + 4; then zeros (an 8-float read at 5·t stays inside).
    sums: [f32; SUMS],
    /// The least r g b a over the samples, then the greatest ones negated (ranges combine
    /// with one lane-wise min).
    range: [f32; 8],
    /// Depth from the pixel's own samples.
    z: f32,
    /// All ones when every r g b a of the samples is finite, else 0.
    finite: u32,
    _pad: [u32; 6],
}

/// A neighbour outside the image: contributes nothing and narrows no range.
const ABSENT: Contrib = Contrib {
    sums: [0.0; SUMS],
    range: [f32::INFINITY; 8],
    z: f32::INFINITY,
    finite: !0,
    _pad: [0; 6],
};
static ABSENT_PX: Contrib = ABSENT;

/// A bucket's samples ready for [`gather_tile`] (see the module comment).
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    /// Raster pixel of the first pixel, and the size in pixels.
    pub x0: i32,
    pub y0: i32,
    pub width: usize,
    pub height: usize,
    spp: usize,
    /// Samples per pixel rounded up to [`LANES`].
    lanes: usize,
    /// Per pixel, r g b a as blocks of `lanes` floats (padding lanes repeat sample 0).
    rgba: Vec<f32>,
    /// Per pixel, its contributions.
    px: Vec<Contrib>,
    /// Scratch for one pixel's weights: x towards columns q − 1, q, q + 1, then y, `lanes`
    /// floats each.
    w: Vec<f32>,
    /// After [`Prepared::keep_ring`]: per pixel, its block in `rgba` ([`NOT_KEPT`] for the
    /// pixels already filtered); None while `rgba` holds every pixel.
    ring: Option<Vec<u32>>,
}

/// A pixel whose r g b a blocks [`Prepared::keep_ring`] let go.
const NOT_KEPT: u32 = u32::MAX;

/// What preparing a pixel needs from the frame: the filter's axes, the depth filter, the
/// kernel build to run, and the storage of filtered buckets for reuse.
#[derive(Debug)]
pub struct PrepareCtx<'a> {
    axes: [Axis<'a>; 2],
    df: DepthFilter,
    kernel: Kernel,
    /// Storage of finished buckets for reuse: r g b a blocks, and contributions (kept
    /// apart: a bucket's blocks come back as soon as its inner pixels are filtered).
    rgba_pool: std::sync::Mutex<Vec<Vec<f32>>>,
    px_pool: std::sync::Mutex<Vec<Vec<Contrib>>>,
}

/// One axis of the filter as the weight kernels read it.
#[derive(Debug)]
struct Axis<'a> {
    /// Half width.
    h: f32,
    t: &'a Table1d,
    /// The table as pairs (t[i], t[i + 1]): one 64-bit load per lookup (wide filters).
    pairs: Vec<[f32; 2]>,
    /// Narrow filters (h ≤ 1): both weights of a sample from one record.
    narrow: Option<Narrow>,
}

impl<'a> Axis<'a> {
    fn new(h: f32, t: &'a Table1d) -> Axis<'a> {
        let narrow = h <= 1.0;
        let (tab, _, _) = t.parts();
        Axis {
            h,
            t,
            pairs: if narrow {
                Vec::new()
            } else {
                tab.windows(2).map(|w| [w[0], w[1]]).collect()
            },
            narrow: narrow.then(|| Narrow::new(t)),
        }
    }
}

/// A narrow filter's weights by a sample's distance v ≤ ½ from its pixel's centre (along
/// one axis): f(v) towards its own column, f(1 − v) towards the neighbour on its side
/// (the one it is nearer). One record per node holds both, so a sample's two weights are
/// one 16-byte load and one interpolation fraction (two table lookups before). The nodes
/// are spaced like the table's; for the usual h = 1 (gaussian 2 × 2, triangle 2 × 2) they
/// are the table's own nodes (v = j/2048, 1 − v = (2048 − j)/2048, exact), so the own
/// weight is the scatter's bit for bit and the side one differs by rounding.
#[derive(Debug)]
struct Narrow {
    /// Node j (v_j = j / scale): f(v_j), f(v_j+1), f(1 − v_j), f(1 − v_j+1), the last
    /// node's values repeated past the end.
    rec: Vec<[f32; 4]>,
    scale: f32,
    steps: i32,
}

impl Narrow {
    fn new(t: &Table1d) -> Narrow {
        let (_, tscale, _) = t.parts();
        let steps = (0.5 * tscale).ceil().max(1.0) as i32;
        let scale = 2.0 * steps as f32;
        let node = |j: i32| {
            let v = j.min(steps) as f32 / scale;
            (t.at(v), t.at(1.0 - v))
        };
        let rec = (0..=steps)
            .map(|j| {
                let ((a, c), (b, d)) = (node(j), node(j + 1));
                [a, b, c, d]
            })
            .collect();
        Narrow { rec, scale, steps }
    }

    /// (own, side) weights at distance `v` (NaN gives NaN: unreached padding lanes).
    #[inline(always)]
    fn at(&self, v: f32) -> (f32, f32) {
        let u = v * self.scale;
        // `as` gives 0 for NaN, as the vector build's clamp does.
        let i = (u as i32).clamp(0, self.steps);
        let f = u - i as f32;
        let r = self.rec[i as usize];
        (r[0] + f * (r[1] - r[0]), r[2] + f * (r[3] - r[2]))
    }
}

impl<'a> PrepareCtx<'a> {
    pub fn new(filter: &Filter, t: &'a FilterTables, df: DepthFilter) -> PrepareCtx<'a> {
        let (hx, hy) = filter.radius();
        PrepareCtx {
            axes: [Axis::new(hx, &t.x), Axis::new(hy, &t.y)],
            df,
            kernel: pick_kernel(),
            rgba_pool: Default::default(),
            px_pool: Default::default(),
        }
    }

    /// Keeps a bucket's storage for the next [`Prepared::new`] (no allocation or clearing
    /// per bucket once the first rows are done).
    pub fn recycle(&self, p: Prepared) {
        if let Ok(mut pool) = self.px_pool.lock() {
            pool.push(p.px);
        }
        // The few blocks a ring keeps, its index and the weight scratch go to this thread's
        // buffer pool (freed, they would go back to the arena of the hiding thread).
        pool::give(p.w);
        match p.ring {
            None => self.recycle_rgba(p.rgba),
            Some(at) => {
                pool::give(at);
                pool::give(p.rgba);
            }
        }
    }

    fn recycle_rgba(&self, rgba: Vec<f32>) {
        if let Ok(mut pool) = self.rgba_pool.lock() {
            pool.push(rgba);
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
        let mut rgba = ctx
            .rgba_pool
            .lock()
            .ok()
            .and_then(|mut p| p.pop())
            .unwrap_or_default();
        let mut px = ctx
            .px_pool
            .lock()
            .ok()
            .and_then(|mut p| p.pop())
            .unwrap_or_default();
        rgba.resize(npix * 4 * lanes, 0.0);
        px.resize(npix, ABSENT);
        Prepared {
            x0,
            y0,
            width,
            height,
            spp,
            lanes,
            rgba,
            px,
            w: pool::filled(2 * TAPS * lanes, 0.0),
            ring: None,
        }
    }

    /// Heap size, for the peak-memory statistic.
    pub fn bytes(&self) -> usize {
        (self.rgba.len() + self.w.len() + self.ring.as_ref().map_or(0, Vec::len)) * 4
            + self.px.len() * std::mem::size_of::<Contrib>()
    }

    /// Once [`start_tile`] has filtered `partial`'s inner pixels, keeps the r g b a blocks
    /// of the others only (the ring [`finish_tile`] filters later, which reads a pixel's own
    /// blocks when nothing in its support weighs anything; neighbours read only the
    /// contributions) and gives the full storage back to `ctx` at once. A hidden row
    /// waiting for the row below then holds about a quarter of its samples (16 × 16 buckets:
    /// 60 of 256 pixels), not all of them.
    pub fn keep_ring(&mut self, partial: &Partial, ctx: &PrepareCtx) {
        let [ix0, iy0, ix1, iy1] = partial.inner;
        let n = 4 * self.lanes;
        let npix = self.width * self.height;
        let overlap = |lo: i32, len: usize, a: usize, b: usize| {
            (lo + len as i32).min(b as i32) - lo.max(a as i32)
        };
        let inner = overlap(self.x0, self.width, ix0, ix1).max(0) as usize
            * overlap(self.y0, self.height, iy0, iy1).max(0) as usize;
        let mut at = pool::filled(npix, NOT_KEPT);
        let mut kept = pool::take((npix - inner.min(npix)) * n);
        for j in 0..self.height {
            let y = self.y0 + j as i32;
            let row_inner = y >= iy0 as i32 && y < iy1 as i32;
            for i in 0..self.width {
                let x = self.x0 + i as i32;
                if row_inner && x >= ix0 as i32 && x < ix1 as i32 {
                    continue;
                }
                let pix = j * self.width + i;
                at[pix] = (kept.len() / n) as u32;
                kept.extend_from_slice(&self.rgba[pix * n..(pix + 1) * n]);
            }
        }
        let full = std::mem::replace(&mut self.rgba, kept);
        ctx.recycle_rgba(full);
        self.ring = Some(at);
    }

    /// Floats per block (samples per pixel rounded up to [`LANES`]).
    pub fn lanes(&self) -> usize {
        self.lanes
    }

    /// The r g b a blocks of pixel `pix` (`4 × lanes` floats: r for samples 0…, then g, b,
    /// a), for the caller to fill before [`Prepared::finish_pixel`].
    #[inline]
    pub fn rgba_mut(&mut self, pix: usize) -> &mut [f32] {
        let n = 4 * self.lanes;
        &mut self.rgba[pix * n..(pix + 1) * n]
    }

    /// Completes pixel `pix` (raster pixel (qx, qy)) once its r g b a are in place: the
    /// filter weights of its samples at `xs`, `ys` (`lanes` each; padding lanes NaN, which
    /// reach nothing), its contributions, its depth from `zs` (its samples' depths), its
    /// channel ranges.
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
        let rgba = &mut self.rgba[pix * 4 * lanes..(pix + 1) * 4 * lanes];
        // Padding lanes repeat sample 0: no change to the range, and they weigh 0.
        if spp < lanes {
            for c in 0..4 {
                let v = rgba[c * lanes];
                rgba[c * lanes + spp..(c + 1) * lanes].fill(v);
            }
        }
        let (wx, wy) = self.w.split_at_mut(TAPS * lanes);
        let out = &mut self.px[pix];
        let (xs, ys) = (&xs[..lanes], &ys[..lanes]);
        if !ctx
            .kernel
            .finish(ctx, (xs, ys), (qx, qy), rgba, (wx, wy), &zs[..spp], out)
        {
            // A sum is not finite: a value is not (or the sums overflow). Again, leaving out
            // the products of weight 0, which must not poison the sums.
            contrib_portable(wx, wy, rgba, lanes, true, out);
            let finite = (0..4).all(|c| {
                rgba[c * lanes..c * lanes + spp]
                    .iter()
                    .all(|v| v.is_finite())
            });
            out.finite = if finite { !0 } else { 0 };
        }
    }
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

/// Which build of the vectorised loops runs (all give the same bits: the same IEEE
/// operations per lane in the same order, no fused multiply-adds).
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
    /// A pixel's contributions: through [`quad_portable`] where it applies, else its weights
    /// into `wx`, `wy` (see [`weights_portable`]) and its contributions from them (see
    /// [`contrib_portable`], without `skip_zero`); and its depth from `zs` ([`own_depth`])
    /// into `out.z`. One call per pixel, so the vector build runs the quadrant path and the
    /// depth inlined in one AVX2 function. Returns whether the sums are finite (when not, the
    /// weights are in `wx`, `wy` for the caller's careful sums).
    #[allow(clippy::too_many_arguments)]
    fn finish(
        self,
        ctx: &PrepareCtx,
        (xs, ys): (&[f32], &[f32]),
        (qx, qy): (i32, i32),
        rgba: &[f32],
        (wx, wy): (&mut [f32], &mut [f32]),
        zs: &[f32],
        out: &mut Contrib,
    ) -> bool {
        let lanes = xs.len();
        if lanes == QUAD_LANES {
            let quad = match self {
                Kernel::Portable => {
                    let q = quad_portable(&ctx.axes, (xs, ys), (qx, qy), rgba, out);
                    if q.is_some() {
                        out.z = own_depth(zs.iter().copied(), ctx.df);
                    }
                    q
                }
                // SAFETY: chosen only where the CPU has AVX2.
                #[cfg(target_arch = "x86_64")]
                Kernel::Avx2 => unsafe {
                    avx2::quad_and_depth(&ctx.axes, (xs, ys), (qx, qy), rgba, zs, ctx.df, out)
                },
            };
            match quad {
                Some(true) => return true,
                Some(false) => {
                    // Not finite: the caller redoes the sums from the weights, carefully.
                    weights_portable(xs, qx, &ctx.axes[0], wx);
                    weights_portable(ys, qy, &ctx.axes[1], wy);
                    return false;
                }
                None => {}
            }
        }
        out.z = self.depth(zs, ctx.df);
        match self {
            Kernel::Portable => {
                weights_portable(xs, qx, &ctx.axes[0], wx);
                weights_portable(ys, qy, &ctx.axes[1], wy);
                contrib_portable(wx, wy, rgba, lanes, false, out)
            }
            // SAFETY: chosen only where the CPU has AVX2.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => unsafe {
                avx2::finish(&ctx.axes, (xs, ys), (qx, qy), rgba, (wx, wy), out)
            },
        }
    }

    /// [`own_depth`] (the vector build takes eight samples at a time for `Min` and `Max`:
    /// the same value, as min and max are exact).
    fn depth(self, zs: &[f32], df: DepthFilter) -> f32 {
        match (self, df) {
            // SAFETY: chosen only where the CPU has AVX2.
            #[cfg(target_arch = "x86_64")]
            (Kernel::Avx2, DepthFilter::Min | DepthFilter::Max) if zs.len() >= LANES => unsafe {
                avx2::depth(zs, df == DepthFilter::Max)
            },
            _ => own_depth(zs.iter().copied(), df),
        }
    }
}

/// Weights of samples at coordinates `pos` (one axis; `lanes` of them) in pixel `q` towards
/// the pixels q − 1, q, q + 1, into `out` (three blocks of `lanes`): the scatter's reach test
/// `sx − h − 0.5 ≤ c ≤ sx + h − 0.5`, and its lookup at c + 0.5 − sx (narrow filters: see
/// [`Narrow`]).
fn weights_portable(pos: &[f32], q: i32, ax: &Axis, out: &mut [f32]) {
    let (h, t) = (ax.h, ax.t);
    let lanes = pos.len();
    let c = [(q - 1) as f32, q as f32, (q + 1) as f32];
    let mid = q as f32 + 0.5;
    for (s, &x) in pos.iter().enumerate() {
        let w = if let Some(n) = &ax.narrow {
            // Narrow: the sample at distance v from its column's centre reaches that column
            // when v ≤ h and the nearer side (both at x = q + ½) when 1 − v ≤ h; one record
            // serves both weights. (NaN reaches nothing.)
            let v = (mid - x).abs();
            let (own, side) = n.at(v);
            let side = if v >= 1.0 - h { side } else { 0.0 };
            [
                if x <= mid { side } else { 0.0 },
                if v <= h { own } else { 0.0 },
                if x >= mid { side } else { 0.0 },
            ]
        } else {
            let (a, b) = (x - h - 0.5, x + h - 0.5);
            c.map(|c| {
                let reached = !(c < a) && c <= b;
                if reached {
                    t.at(c + 0.5 - x)
                } else {
                    0.0
                }
            })
        };
        for o in 0..TAPS {
            out[o * lanes + s] = w[o];
        }
    }
}

/// `a < b ? a : b`, as the vector min instruction (the second operand when unordered).
#[inline(always)]
fn vmin(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `a > b ? a : b`, as the vector max instruction.
#[inline(always)]
fn vmax(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// The 8 lanes combined as the vector builds combine them:
/// op(op(op(v0, v2), op(v1, v3)), op(op(v4, v6), op(v5, v7))).
#[inline(always)]
fn reduce(v: [f32; LANES], op: impl Fn(f32, f32) -> f32) -> f32 {
    op(
        op(op(v[0], v[2]), op(v[1], v[3])),
        op(op(v[4], v[6]), op(v[5], v[7])),
    )
}

/// A pixel's contributions (see [`Contrib`]) from its samples' weights `wx`, `wy` (three
/// blocks of `lanes` each, towards the columns and rows q − 1, q, q + 1) and values `rgba`
/// (four blocks): per sum, lane by lane over the chunks (acc + w·v, w = wx·wy), then
/// [`reduce`]; the ranges likewise with [`vmin`], [`vmax`]. With `skip_zero`, products of
/// weight 0 are left out (non-finite values must not poison the sums). Returns whether
/// every sum is finite (and sets `finite` so).
fn contrib_portable(
    wx: &[f32],
    wy: &[f32],
    rgba: &[f32],
    lanes: usize,
    skip_zero: bool,
    out: &mut Contrib,
) -> bool {
    let mut acc = [[0f32; LANES]; NSUMS];
    for chunk in 0..lanes / LANES {
        for l in 0..LANES {
            let s = chunk * LANES + l;
            let v = [0, 1, 2, 3].map(|c| rgba[c * lanes + s]);
            for t in 0..TAPS * TAPS {
                let w = wx[(t % TAPS) * lanes + s] * wy[(t / TAPS) * lanes + s];
                if skip_zero && w == 0.0 {
                    continue;
                }
                for c in 0..4 {
                    acc[5 * t + c][l] += w * v[c];
                }
                acc[5 * t + 4][l] += w;
            }
        }
    }
    for (s, a) in out.sums.iter_mut().zip(&acc) {
        *s = reduce(*a, |a, b| a + b);
    }
    out.sums[NSUMS..].fill(0.0);
    ranges_portable(rgba, lanes, out);
    let finite = out.sums.iter().all(|s| s.is_finite());
    out.finite = if finite { !0 } else { 0 };
    finite
}

/// Samples per pixel of the quadrant fast path ([`quad_portable`]): a 4 × 4 pattern.
const QUAD_LANES: usize = 2 * LANES;

/// Half sums of the eight lanes of a vector as the quadrant path forms them: lanes 0, 1,
/// 4, 5 (left of the pixel's centre) and lanes 2, 3, 6, 7 (right): ((v0 + v1) + (v4 + v5),
/// (v2 + v3) + (v6 + v7)) — the order of the vector build's horizontal adds.
#[inline(always)]
fn halves(v: &[f32; LANES]) -> (f32, f32) {
    ((v[0] + v[1]) + (v[4] + v[5]), (v[2] + v[3]) + (v[6] + v[7]))
}

/// The contributions of a pixel of 16 samples in the 4 × 4 pattern's order (stratum rows
/// of four, top to bottom), under a narrow filter on both axes, when each sample lies in
/// its stratum's quadrant of the pixel — samples 0, 1, 4, 5 of each chunk of eight strictly
/// left of the centre, 2, 3, 6, 7 strictly right, the first chunk strictly above, the second
/// strictly below (a jittered 4 × 4 pattern always, short of a sample exactly on a
/// midline). Then every sample reaches its own pixel and at most the neighbours on its
/// quadrant's sides, so a chunk's lanes split into a left and a right half reaching known
/// targets: the products known to be 0 are never formed (about half of
/// [`contrib_portable`]'s), and the weights never stored. Per sum, the two chunks' products
/// lane by lane where both reach the target, then [`halves`] (and L + R for the targets both
/// halves reach). Returns None when the samples are not so placed (or the filter is not
/// narrow): the general path runs. Some(finite) otherwise; the weights are those of
/// [`weights_portable`], so the sums agree with [`contrib_portable`]'s to float rounding.
fn quad_portable(
    axes: &[Axis; 2],
    (xs, ys): (&[f32], &[f32]),
    (qx, qy): (i32, i32),
    rgba: &[f32],
    out: &mut Contrib,
) -> Option<bool> {
    let (Some(nx), Some(ny)) = (&axes[0].narrow, &axes[1].narrow) else {
        return None;
    };
    let (mx, my) = (qx as f32 + 0.5, qy as f32 + 0.5);
    for s in 0..QUAD_LANES {
        let (x, y) = (xs[s], ys[s]);
        let x_ok = if s & 2 != 0 { mx < x } else { x < mx };
        let y_ok = if s >= LANES { my < y } else { y < my };
        if !(x_ok && y_ok) {
            return None;
        }
    }
    // (own, side) weights along an axis, masked by the reach as [`weights_portable`] does.
    let wt = |ax: &Axis, n: &Narrow, p: f32, mid: f32| {
        let v = (mid - p).abs();
        let (own, side) = n.at(v);
        (
            if v <= ax.h { own } else { 0.0 },
            if v >= 1.0 - ax.h { side } else { 0.0 },
        )
    };
    // Products per chunk, kind (own; x side; y side; diagonal), sum (r g b a w), lane.
    let mut prod = [[[[0f32; LANES]; 5]; 4]; 2];
    for (c, pc) in prod.iter_mut().enumerate() {
        for l in 0..LANES {
            let s = c * LANES + l;
            let (ox, sx) = wt(&axes[0], nx, xs[s], mx);
            let (oy, sy) = wt(&axes[1], ny, ys[s], my);
            let w = [ox * oy, sx * oy, ox * sy, sx * sy];
            for (k, &w) in w.iter().enumerate() {
                for ch in 0..4 {
                    pc[k][ch][l] = w * rgba[ch * QUAD_LANES + s];
                }
                pc[k][4][l] = w;
            }
        }
    }
    let both = |k: usize, ch: usize| -> [f32; LANES] {
        std::array::from_fn(|l| prod[0][k][ch][l] + prod[1][k][ch][l])
    };
    for ch in 0..5 {
        let own = halves(&both(0, ch));
        let xside = halves(&both(1, ch));
        let (ya, yb) = (halves(&prod[0][2][ch]), halves(&prod[1][2][ch]));
        let (da, db) = (halves(&prod[0][3][ch]), halves(&prod[1][3][ch]));
        // Targets row by row: (−1, −1) … (1, 1).
        let t = [
            da.0,
            ya.0 + ya.1,
            da.1,
            xside.0,
            own.0 + own.1,
            xside.1,
            db.0,
            yb.0 + yb.1,
            db.1,
        ];
        for (k, v) in t.iter().enumerate() {
            out.sums[5 * k + ch] = *v;
        }
    }
    out.sums[NSUMS..].fill(0.0);
    ranges_portable(rgba, QUAD_LANES, out);
    let finite = out.sums.iter().all(|s| s.is_finite());
    out.finite = if finite { !0 } else { 0 };
    Some(finite)
}

/// The least and greatest r g b a over a pixel's samples into `out.range` (see
/// [`Contrib`]): lane by lane over the chunks with [`vmin`], [`vmax`], then [`reduce`].
fn ranges_portable(rgba: &[f32], lanes: usize, out: &mut Contrib) {
    for c in 0..4 {
        let mut lo = [0f32; LANES];
        let mut hi = lo;
        for chunk in 0..lanes / LANES {
            for l in 0..LANES {
                let v = rgba[c * lanes + chunk * LANES + l];
                if chunk == 0 {
                    (lo[l], hi[l]) = (v, v);
                } else {
                    lo[l] = vmin(lo[l], v);
                    hi[l] = vmax(hi[l], v);
                }
            }
        }
        out.range[c] = reduce(lo, vmin);
        out.range[4 + c] = -reduce(hi, vmax);
    }
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
    tile.data = pool::filled(w * h * 5, 0.0);
    // Each pixel of the region grown by one: its contributions, ABSENT outside the image
    // (filled a row of a part at a time: no per-pixel lookup of which part holds it).
    let gw = w + 2;
    let mut nb: Vec<&Contrib> = vec![&ABSENT_PX; gw * (h + 2)];
    let (gx0, gy0) = (x0 as i64 - 1, y0 as i64 - 1);
    let (gx1, gy1) = (
        (x1 as i64 + 1).min(film.width as i64),
        (y1 as i64 + 1).min(film.height as i64),
    );
    for p in parts {
        // The part's pixels inside the grown region and the image.
        let (px0, py0) = (p.x0 as i64, p.y0 as i64);
        let xa = px0.max(gx0).max(0);
        let xb = (px0 + p.width as i64).min(gx1);
        let ya = py0.max(gy0).max(0);
        let yb = (py0 + p.height as i64).min(gy1);
        if xa >= xb {
            continue;
        }
        let n = (xb - xa) as usize;
        for y in ya..yb {
            let pi = (y - py0) as usize * p.width + (xa - px0) as usize;
            let gi = (y - gy0) as usize * gw + (xa - gx0) as usize;
            for (d, c) in nb[gi..gi + n].iter_mut().zip(&p.px[pi..pi + n]) {
                *d = c;
            }
        }
    }
    let g = Grid {
        parts,
        nb: &nb,
        gw,
        origin: (x0 as i32, y0 as i32),
    };
    match pick_kernel() {
        // SAFETY: chosen only where the CPU has AVX2.
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 => unsafe { gather_avx2(&g, w, h, &mut tile.data) },
        _ => gather_pixels(&g, w, h, &mut tile.data, combine),
    }
    tile
}

/// The pixels around a tile, for [`gather_pixels`].
struct Grid<'a> {
    parts: &'a [&'a Prepared],
    /// The contributions of each pixel of the tile grown by one ([`ABSENT_PX`] outside the
    /// image).
    nb: &'a [&'a Contrib],
    /// Width of the grown tile.
    gw: usize,
    /// Raster pixel of the tile's first pixel.
    origin: (i32, i32),
}

impl Grid<'_> {
    /// The r g b a blocks of raster pixel (x, y) and the bucket holding them.
    fn own_samples(&self, (x, y): (i32, i32)) -> Option<(&Prepared, &[f32])> {
        self.parts.iter().find_map(|p| {
            let (i, j) = (x - p.x0, y - p.y0);
            let inside = (0..p.width as i32).contains(&i) && (0..p.height as i32).contains(&j);
            inside.then_some(())?;
            let pix = j as usize * p.width + i as usize;
            let block = match &p.ring {
                Some(at) if at[pix] == NOT_KEPT => return None,
                Some(at) => at[pix] as usize,
                None => pix,
            };
            Some((*p, &p.rgba[block * 4 * p.lanes..(block + 1) * 4 * p.lanes]))
        })
    }
}

/// [`gather_pixels`] built for AVX2, with [`avx2::combine`] (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gather_avx2(g: &Grid, w: usize, h: usize, data: &mut [f32]) {
    // (The closure has this function's AVX2, so the call is safe.)
    gather_pixels(g, w, h, data, |nb| avx2::combine(nb))
}

/// What the nine neighbours (row by row) give a pixel: the sums of their contributions
/// towards it (r g b a w, in lanes 0–4) added in a fixed tree, their ranges combined
/// ([`vmin`] in order), their finiteness.
#[inline(always)]
fn combine(nb: &[&Contrib; 9]) -> ([f32; LANES], [f32; 8], u32) {
    type V = [f32; LANES];
    let add = |a: V, b: V| -> V { std::array::from_fn(|l| a[l] + b[l]) };
    let part = |k: usize| -> V {
        let t = 5 * (8 - k);
        nb[k].sums[t..t + LANES].try_into().unwrap()
    };
    let s = add(
        add(add(part(0), part(1)), add(part(2), part(3))),
        add(add(part(4), part(5)), add(part(6), part(7))),
    );
    let s = add(s, part(8));
    let mut range = nb[0].range;
    let mut finite = nb[0].finite;
    for n in &nb[1..] {
        range = std::array::from_fn(|l| vmin(range[l], n.range[l]));
        finite &= n.finite;
    }
    (s, range, finite)
}

/// The tile's `w × h` pixels into `data` (r g b a z each): per pixel, the nine
/// contributions towards it through `combine` (see [`combine`]), normalised by their weight.
#[inline(always)]
fn gather_pixels(
    g: &Grid,
    w: usize,
    h: usize,
    data: &mut [f32],
    combine: impl Fn(&[&Contrib; 9]) -> ([f32; LANES], [f32; 8], u32),
) {
    let gw = g.gw;
    for j in 0..h {
        let rows = [j * gw, (j + 1) * gw, (j + 2) * gw];
        for i in 0..w {
            let out = &mut data[(j * w + i) * 5..(j * w + i + 1) * 5];
            // Neighbour k at (k % 3 − 1, k / 3 − 1) from the pixel; the pixel is its
            // target 8 − k.
            let nb: [&Contrib; 9] = std::array::from_fn(|k| g.nb[rows[k / 3] + i + k % 3]);
            if std::ptr::eq(nb[4], &ABSENT_PX) {
                // Not in any bucket given.
                out[4] = f32::INFINITY;
                continue;
            }
            let (s, range, finite) = combine(&nb);
            out[4] = nb[4].z;
            let ws = s[4];
            if ws.abs() > 1e-12 {
                for c in 0..4 {
                    out[c] = s[c] / ws;
                }
            } else {
                // Nothing (or weights cancelling) in the support: the plain mean of the
                // pixel's own samples.
                let q = (g.origin.0 + i as i32, g.origin.1 + j as i32);
                if let Some((own, b)) = g.own_samples(q) {
                    for c in 0..4 {
                        let s: f64 = (0..own.spp).map(|s| b[c * own.lanes + s] as f64).sum();
                        out[c] = (s / own.spp as f64) as f32;
                    }
                }
            }
            // Equal over the neighbourhood: exactly that value.
            if finite != 0 {
                for c in 0..4 {
                    if range[c] == -range[4 + c] {
                        out[c] = range[c];
                    }
                }
            }
        }
    }
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
                data: pool::filled(w * h * 5, 0.0),
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
        data: pool::filled((x1 - x0c) * (y1 - y0c) * 5, 0.0),
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
        pool::give(part.data);
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
            pool::give(part.data);
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

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::{Axis, Contrib, DepthFilter, Narrow, LANES, NSUMS, QUAD_LANES, SUMS, TAPS};

    /// [`super::weights_portable`], eight samples at a time.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn weights(pos: &[f32], q: i32, ax: &Axis, out: &mut [f32]) {
        let lanes = pos.len();
        assert!(lanes % LANES == 0 && out.len() >= TAPS * lanes);
        let (_, scale, steps) = ax.t.parts();
        assert!(steps >= 0 && (ax.narrow.is_some() || ax.pairs.len() > steps as usize));
        let sign = _mm256_set1_ps(-0.0);
        let (hv, half) = (_mm256_set1_ps(ax.h), _mm256_set1_ps(0.5));
        let (sc, st, zi) = (
            _mm256_set1_ps(scale),
            _mm256_set1_epi32(steps),
            _mm256_setzero_si256(),
        );
        let mid = _mm256_set1_ps(q as f32 + 0.5);
        // Lanes as eight indices, clamped into [0, `top`] (NaN's index is out of range: 0).
        let index = |u: __m256, top: __m256i| {
            let i = _mm256_max_epi32(_mm256_min_epi32(_mm256_cvttps_epi32(u), top), zi);
            let mut k = [0i32; 8];
            // SAFETY: 8 lanes into 8 i32.
            unsafe { _mm256_storeu_si256(k.as_mut_ptr() as *mut __m256i, i) };
            (_mm256_sub_ps(u, _mm256_cvtepi32_ps(i)), k)
        };
        let lookup = |d: __m256| {
            let u = _mm256_mul_ps(_mm256_andnot_ps(sign, d), sc);
            // Out-of-range lanes are clamped only to keep the loads in bounds (they are not
            // reached, so they weigh 0).
            let (f, k) = index(u, st);
            // Eight 64-bit loads (faster here than two gathers).
            // SAFETY: 0 ≤ k ≤ steps < pairs.len().
            let (g0, g1) = unsafe {
                let p = ax.pairs.as_ptr() as *const f64;
                let two = |a: i32, b: i32| {
                    _mm_loadh_pd(_mm_load_sd(p.add(a as usize)), p.add(b as usize))
                };
                (
                    _mm256_castpd_ps(_mm256_set_m128d(two(k[2], k[3]), two(k[0], k[1]))),
                    _mm256_castpd_ps(_mm256_set_m128d(two(k[6], k[7]), two(k[4], k[5]))),
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
        // [`super::Narrow::at`]: (own, side) from one 16-byte record per lane.
        let narrow = ax.narrow.as_ref().map(|n| {
            (
                n.rec.as_ptr() as *const f32,
                _mm256_set1_ps(n.scale),
                _mm256_set1_epi32(n.steps),
            )
        });
        let lookup2 = |v: __m256, (rec, nsc, nst): (*const f32, __m256, __m256i)| {
            // SAFETY: `rec`, `nst` from a `Narrow`.
            unsafe { narrow_at(v, rec, nsc, nst) }
        };
        let c = [0, 1, 2].map(|o| _mm256_set1_ps((q - 1 + o as i32) as f32));
        // The side's reach test `v ≥ 1 − h` holds for every v ≥ 0 when h ≥ 1 (and NaN
        // fails the side's own compares).
        let (one_h, side_always) = (_mm256_set1_ps(1.0 - ax.h), ax.h >= 1.0);
        for chunk in 0..lanes / LANES {
            // SAFETY: LANES floats at chunk · LANES < lanes = pos.len().
            let x = unsafe { _mm256_loadu_ps(pos.as_ptr().add(chunk * LANES)) };
            let w = if let Some(n) = narrow {
                let v = _mm256_andnot_ps(sign, _mm256_sub_ps(mid, x));
                let (own, mut side) = lookup2(v, n);
                if !side_always {
                    side = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(v, one_h), side);
                }
                [
                    _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(x, mid), side),
                    _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(v, hv), own),
                    _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(x, mid), side),
                ]
            } else {
                let a = _mm256_sub_ps(_mm256_sub_ps(x, hv), half);
                let b = _mm256_sub_ps(_mm256_add_ps(x, hv), half);
                c.map(|c| {
                    let reached = _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_NLT_UQ>(c, a),
                        _mm256_cmp_ps::<_CMP_LE_OQ>(c, b),
                    );
                    _mm256_and_ps(reached, lookup(_mm256_sub_ps(_mm256_add_ps(c, half), x)))
                })
            };
            for (o, w) in w.iter().enumerate() {
                // SAFETY: LANES floats inside block o.
                unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(o * lanes + chunk * LANES), *w) };
            }
        }
    }

    /// [`super::Narrow::at`] of eight distances: (own, side) from one 16-byte record per
    /// lane.
    ///
    /// # Safety
    /// `rec` holds `steps + 1` records of 4 floats (`nst` is `steps` in every lane).
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn narrow_at(v: __m256, rec: *const f32, nsc: __m256, nst: __m256i) -> (__m256, __m256) {
        let u = _mm256_mul_ps(v, nsc);
        // Clamped into [0, steps] (NaN's index is out of range: 0).
        let i = _mm256_max_epi32(
            _mm256_min_epi32(_mm256_cvttps_epi32(u), nst),
            _mm256_setzero_si256(),
        );
        let mut k = [0i32; 8];
        // SAFETY: 8 lanes into 8 i32.
        unsafe { _mm256_storeu_si256(k.as_mut_ptr() as *mut __m256i, i) };
        let f = _mm256_sub_ps(u, _mm256_cvtepi32_ps(i));
        // SAFETY: 0 ≤ k ≤ steps < rec.len(), 4 floats each.
        let r = |a: i32, b: i32| unsafe {
            _mm256_loadu2_m128(rec.add(4 * b as usize), rec.add(4 * a as usize))
        };
        let (r0, r1, r2, r3) = (r(k[0], k[4]), r(k[1], k[5]), r(k[2], k[6]), r(k[3], k[7]));
        // Transposed: t0 = a0 a1 b0 b1 | a4 a5 b4 b5, t1 = a2 a3 b2 b3 | …, t2, t3 the
        // same of c and d.
        let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpacklo_ps(r2, r3));
        let (t2, t3) = (_mm256_unpackhi_ps(r0, r1), _mm256_unpackhi_ps(r2, r3));
        let a = _mm256_shuffle_ps::<0b01_00_01_00>(t0, t1);
        let b = _mm256_shuffle_ps::<0b11_10_11_10>(t0, t1);
        let c = _mm256_shuffle_ps::<0b01_00_01_00>(t2, t3);
        let d = _mm256_shuffle_ps::<0b11_10_11_10>(t2, t3);
        (
            _mm256_add_ps(a, _mm256_mul_ps(f, _mm256_sub_ps(b, a))),
            _mm256_add_ps(c, _mm256_mul_ps(f, _mm256_sub_ps(d, c))),
        )
    }

    /// A narrow axis's (own, side) weights of eight samples at `p` in the pixel whose
    /// centre is `mid`, masked by the reach ([`super::quad_portable`]'s `wt`).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn narrow_weights(h: f32, n: &Narrow, p: __m256, mid: __m256) -> (__m256, __m256) {
        let v = _mm256_andnot_ps(_mm256_set1_ps(-0.0), _mm256_sub_ps(mid, p));
        // SAFETY: the record table of a `Narrow` and its `steps`.
        let (own, side) = unsafe {
            narrow_at(
                v,
                n.rec.as_ptr() as *const f32,
                _mm256_set1_ps(n.scale),
                _mm256_set1_epi32(n.steps),
            )
        };
        (
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(v, _mm256_set1_ps(h)), own),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(v, _mm256_set1_ps(1.0 - h)),
                side,
            ),
        )
    }

    /// r g b a times the weights `w`, and `w`: a kind's products of a chunk.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn products(w: __m256, v: &[__m256; 4]) -> [__m256; 5] {
        [
            _mm256_mul_ps(w, v[0]),
            _mm256_mul_ps(w, v[1]),
            _mm256_mul_ps(w, v[2]),
            _mm256_mul_ps(w, v[3]),
            w,
        ]
    }

    /// Two chunks' products of a kind added lane by lane.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn add5(a: &[__m256; 5], b: &[__m256; 5]) -> [__m256; 5] {
        [
            _mm256_add_ps(a[0], b[0]),
            _mm256_add_ps(a[1], b[1]),
            _mm256_add_ps(a[2], b[2]),
            _mm256_add_ps(a[3], b[3]),
            _mm256_add_ps(a[4], b[4]),
        ]
    }

    /// [`super::halves`] of the five sums of a kind: (P, W), P = [rL gL bL aL rR gR bR aR],
    /// W = [wL wR wL wR …].
    #[inline]
    #[target_feature(enable = "avx2")]
    fn halves(k: &[__m256; 5]) -> (__m256, __m256) {
        let t1 = _mm256_hadd_ps(k[0], k[1]);
        let t2 = _mm256_hadd_ps(k[2], k[3]);
        let s = _mm256_add_ps(
            _mm256_permute2f128_ps::<0x20>(t1, t2),
            _mm256_permute2f128_ps::<0x31>(t1, t2),
        );
        let p = _mm256_permutevar8x32_ps(s, _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7));
        let t3 = _mm256_hadd_ps(k[4], k[4]);
        (p, _mm256_add_ps(t3, _mm256_permute2f128_ps::<0x01>(t3, t3)))
    }

    /// The left and right targets' r g b a w (lanes 0–4) from [`halves`].
    #[inline]
    #[target_feature(enable = "avx2")]
    fn sides((p, w): (__m256, __m256)) -> (__m256, __m256) {
        (
            _mm256_blend_ps::<0xf0>(p, w),
            _mm256_blend_ps::<0xf0>(
                _mm256_permute2f128_ps::<0x01>(p, p),
                _mm256_permute_ps::<0b10_11_00_01>(w),
            ),
        )
    }

    /// The r g b a w of the target both halves reach, L + R, from [`halves`].
    #[inline]
    #[target_feature(enable = "avx2")]
    fn whole((p, w): (__m256, __m256)) -> __m256 {
        _mm256_blend_ps::<0xf0>(
            _mm256_add_ps(p, _mm256_permute2f128_ps::<0x01>(p, p)),
            _mm256_add_ps(w, _mm256_permute_ps::<0b10_11_00_01>(w)),
        )
    }

    /// [`super::quad_portable`] in AVX2 (the same bits).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn quad(
        axes: &[Axis; 2],
        (xs, ys): (&[f32], &[f32]),
        (qx, qy): (i32, i32),
        rgba: &[f32],
        out: &mut Contrib,
    ) -> Option<bool> {
        let (Some(nx), Some(ny)) = (&axes[0].narrow, &axes[1].narrow) else {
            return None;
        };
        assert!(xs.len() >= QUAD_LANES && ys.len() >= QUAD_LANES && rgba.len() >= 4 * QUAD_LANES);
        let (px, py, pv) = (xs.as_ptr(), ys.as_ptr(), rgba.as_ptr());
        // SAFETY: 16 floats of `xs` and `ys`, 64 of `rgba` (asserted).
        let (x0, x1, y0, y1, v0, v1) = unsafe {
            (
                _mm256_loadu_ps(px),
                _mm256_loadu_ps(px.add(LANES)),
                _mm256_loadu_ps(py),
                _mm256_loadu_ps(py.add(LANES)),
                [0, 1, 2, 3].map(|c| _mm256_loadu_ps(pv.add(c * QUAD_LANES))),
                [0, 1, 2, 3].map(|c| _mm256_loadu_ps(pv.add(c * QUAD_LANES + LANES))),
            )
        };
        let (mx, my) = (
            _mm256_set1_ps(qx as f32 + 0.5),
            _mm256_set1_ps(qy as f32 + 0.5),
        );
        // Lanes 0, 1, 4, 5 left of the centre and 2, 3, 6, 7 right; the first chunk above,
        // the second below.
        let lt0 = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(x0, mx));
        let gt0 = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(mx, x0));
        let lt1 = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(x1, mx));
        let gt1 = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(mx, x1));
        let above = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(y0, my));
        let below = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(my, y1));
        if (lt0 & lt1) != 0b0011_0011 || (gt0 & gt1) != 0b1100_1100 || (above & below) != 0xff {
            return None;
        }
        let (hx, hy) = (axes[0].h, axes[1].h);
        let (ox0, sx0) = narrow_weights(hx, nx, x0, mx);
        let (oy0, sy0) = narrow_weights(hy, ny, y0, my);
        let (ox1, sx1) = narrow_weights(hx, nx, x1, mx);
        let (oy1, sy1) = narrow_weights(hy, ny, y1, my);
        let mul = |a, b| _mm256_mul_ps(a, b);
        // Per chunk, the kinds: own, x side, y side, diagonal.
        let own = add5(&products(mul(ox0, oy0), &v0), &products(mul(ox1, oy1), &v1));
        let xside = add5(&products(mul(sx0, oy0), &v0), &products(mul(sx1, oy1), &v1));
        let (d0, d2) = sides(halves(&products(mul(sx0, sy0), &v0)));
        let (d6, d8) = sides(halves(&products(mul(sx1, sy1), &v1)));
        let (x3, x5) = sides(halves(&xside));
        let t = [
            d0,
            whole(halves(&products(mul(ox0, sy0), &v0))),
            d2,
            x3,
            whole(halves(&own)),
            x5,
            d6,
            whole(halves(&products(mul(ox1, sy1), &v1))),
            // Lanes 5–7 beyond the last target's sums are zero.
            _mm256_blend_ps::<0b1110_0000>(d8, _mm256_setzero_ps()),
        ];
        // x − x is 0 for finite x, NaN otherwise; the sum of them NaN when any is.
        let mut bad = _mm256_setzero_ps();
        let po = out.sums.as_mut_ptr();
        for (k, t) in t.iter().enumerate() {
            bad = _mm256_add_ps(bad, _mm256_sub_ps(*t, *t));
            // SAFETY: 8 floats at 5·k ≤ 40 of 48 sums.
            unsafe { _mm256_storeu_ps(po.add(5 * k), *t) };
        }
        ranges(rgba, QUAD_LANES, out);
        let finite = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_UNORD_Q>(bad, bad)) == 0;
        out.finite = if finite { !0 } else { 0 };
        Some(finite)
    }

    /// [`quad`] and, where it applies, the depth of `zs` into `out.z` ([`depth`] for `Min`
    /// and `Max`, else [`super::own_depth`]), inlined together.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2")]
    pub(super) fn quad_and_depth(
        axes: &[Axis; 2],
        xy: (&[f32], &[f32]),
        q: (i32, i32),
        rgba: &[f32],
        zs: &[f32],
        df: DepthFilter,
        out: &mut Contrib,
    ) -> Option<bool> {
        let r = quad(axes, xy, q, rgba, out)?;
        out.z = match df {
            DepthFilter::Min | DepthFilter::Max if zs.len() >= LANES => {
                depth(zs, df == DepthFilter::Max)
            }
            _ => super::own_depth(zs.iter().copied(), df),
        };
        Some(r)
    }

    /// [`super::ranges_portable`].
    #[inline]
    #[target_feature(enable = "avx2")]
    fn ranges(rgba: &[f32], lanes: usize, out: &mut Contrib) {
        assert!(lanes % LANES == 0 && lanes > 0 && rgba.len() >= 4 * lanes);
        let ld = |c: usize, o: usize| {
            // SAFETY: inside block c (asserted above).
            unsafe { _mm256_loadu_ps(rgba.as_ptr().add(c * lanes + o)) }
        };
        let mut lo = [0, 1, 2, 3].map(|c| ld(c, 0));
        let mut hi = lo;
        for chunk in 1..lanes / LANES {
            for c in 0..4 {
                let v = ld(c, chunk * LANES);
                lo[c] = _mm256_min_ps(lo[c], v);
                hi[c] = _mm256_max_ps(hi[c], v);
            }
        }
        let lo = reduce8::<1>(&[lo[0], lo[1], lo[2], lo[3], lo[0], lo[1], lo[2], lo[3]]);
        let hi = reduce8::<2>(&[hi[0], hi[1], hi[2], hi[3], hi[0], hi[1], hi[2], hi[3]]);
        let r = _mm256_blend_ps::<0b1111_0000>(lo, _mm256_xor_ps(hi, _mm256_set1_ps(-0.0)));
        // SAFETY: 8 floats.
        unsafe { _mm256_storeu_ps(out.range.as_mut_ptr(), r) };
    }

    /// [`super::Kernel::finish`]: both axes' weights and the contributions, inlined.
    #[target_feature(enable = "avx2")]
    pub(super) fn finish(
        axes: &[Axis; 2],
        (xs, ys): (&[f32], &[f32]),
        (qx, qy): (i32, i32),
        rgba: &[f32],
        (wx, wy): (&mut [f32], &mut [f32]),
        out: &mut Contrib,
    ) -> bool {
        weights(xs, qx, &axes[0], wx);
        weights(ys, qy, &axes[1], wy);
        contrib(wx, wy, rgba, xs.len(), out)
    }

    /// [`super::own_depth`] for `Min` (`max` false) or `Max` of at least eight depths:
    /// lane-wise from ±∞ (a NaN depth is passed over, as `f32::min` and `max` do), then
    /// across the lanes, then the depths left over.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn depth(zs: &[f32], max: bool) -> f32 {
        let n = zs.len() / LANES * LANES;
        let start = if max {
            f32::NEG_INFINITY
        } else {
            f32::INFINITY
        };
        let mut acc = _mm256_set1_ps(start);
        for chunk in zs[..n].chunks_exact(LANES) {
            // SAFETY: LANES floats.
            let z = unsafe { _mm256_loadu_ps(chunk.as_ptr()) };
            // The second operand (acc, never NaN) when z is NaN.
            acc = if max {
                _mm256_max_ps(z, acc)
            } else {
                _mm256_min_ps(z, acc)
            };
        }
        // Across the lanes in the register (no NaN left: the order does not matter).
        let op = |a, b| {
            if max {
                _mm256_max_ps(a, b)
            } else {
                _mm256_min_ps(a, b)
            }
        };
        let m = op(acc, _mm256_permute2f128_ps::<1>(acc, acc));
        let m = op(m, _mm256_permute_ps::<0b01_00_11_10>(m));
        let m = op(m, _mm256_permute_ps::<0b10_11_00_01>(m));
        let fold = |a: f32, b: f32| if max { a.max(b) } else { a.min(b) };
        zs[n..].iter().fold(_mm256_cvtss_f32(m), |a, &b| fold(a, b))
    }

    /// [`super::combine`] in AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn combine(nb: &[&Contrib; 9]) -> ([f32; LANES], [f32; 8], u32) {
        // SAFETY: 8 floats at 5·(8 − k) ≤ 40 of 48 sums; `range` is 8 floats.
        let part = |k: usize| unsafe { _mm256_loadu_ps(nb[k].sums.as_ptr().add(5 * (8 - k))) };
        let range = |k: usize| unsafe { _mm256_loadu_ps(nb[k].range.as_ptr()) };
        let add = |a, b| _mm256_add_ps(a, b);
        let s = add(
            add(add(part(0), part(1)), add(part(2), part(3))),
            add(add(part(4), part(5)), add(part(6), part(7))),
        );
        let s = add(s, part(8));
        let mut r = range(0);
        let mut finite = nb[0].finite;
        for k in 1..9 {
            r = _mm256_min_ps(r, range(k));
            finite &= nb[k].finite;
        }
        let (mut so, mut ro) = ([0f32; LANES], [0f32; 8]);
        // SAFETY: 8 floats each.
        unsafe {
            _mm256_storeu_ps(so.as_mut_ptr(), s);
            _mm256_storeu_ps(ro.as_mut_ptr(), r);
        }
        (so, ro, finite)
    }

    /// The lanes of each of the eight vectors combined by `op`, into one vector (lane i
    /// from vector i), in the order of [`super::reduce`]. `op`: 0 add, 1 min, 2 max.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn reduce8<const OP: u8>(v: &[__m256; 8]) -> __m256 {
        let op = |a: __m256, b: __m256| match OP {
            0 => _mm256_add_ps(a, b),
            1 => _mm256_min_ps(a, b),
            _ => _mm256_max_ps(a, b),
        };
        // Pairs: [op(a0, a2) op(b0, b2) op(a1, a3) op(b1, b3) | the same of lanes 4–7].
        let p = [0, 2, 4, 6].map(|k| {
            op(
                _mm256_unpacklo_ps(v[k], v[k + 1]),
                _mm256_unpackhi_ps(v[k], v[k + 1]),
            )
        });
        // Quads: [a0123 b0123 c0123 d0123 | a4567 …].
        let q = [0, 2].map(|k| {
            op(
                _mm256_shuffle_ps::<0b01_00_01_00>(p[k], p[k + 1]),
                _mm256_shuffle_ps::<0b11_10_11_10>(p[k], p[k + 1]),
            )
        });
        op(
            _mm256_permute2f128_ps::<0x20>(q[0], q[1]),
            _mm256_permute2f128_ps::<0x31>(q[0], q[1]),
        )
    }

    /// Sums 8·B … 8·B + 7 of [`super::contrib_portable`] (see [`super::Contrib`]), over
    /// `CH` chunks (`chunks` when `CH` is 0). With `SPLIT` (two chunks, the first reaching no
    /// row below, the second none above: a 4 × 4 pattern's halves), the products known to
    /// be ±0 are left out — the same bits, as an accumulator starting at +0 never holds −0
    /// and adding ±0 to it changes nothing (the values are finite: a non-finite one shows
    /// in the middle row's sums, which use every chunk).
    ///
    /// # Safety
    /// `wx`, `wy` hold three blocks of `lanes` floats, `rgba` four, `lanes` = 8 · chunks.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn batch<const B: usize, const CH: usize, const SPLIT: bool>(
        wx: *const f32,
        wy: *const f32,
        rgba: *const f32,
        lanes: usize,
        chunks: usize,
    ) -> __m256 {
        let mut acc = [_mm256_setzero_ps(); 8];
        let chunks = if CH > 0 { CH } else { chunks };
        for chunk in 0..chunks {
            let o = chunk * LANES;
            for (i, acc) in acc.iter_mut().enumerate() {
                let k = 8 * B + i;
                if k >= NSUMS {
                    break;
                }
                let (t, c) = (k / 5, k % 5);
                if SPLIT && ((t / TAPS == 0 && chunk == 1) || (t / TAPS == 2 && chunk == 0)) {
                    continue;
                }
                // SAFETY: inside the blocks (the caller's contract).
                let p = unsafe {
                    let w = _mm256_mul_ps(
                        _mm256_loadu_ps(wx.add((t % TAPS) * lanes + o)),
                        _mm256_loadu_ps(wy.add((t / TAPS) * lanes + o)),
                    );
                    if c == 4 {
                        w
                    } else {
                        _mm256_mul_ps(w, _mm256_loadu_ps(rgba.add(c * lanes + o)))
                    }
                };
                *acc = _mm256_add_ps(*acc, p);
            }
        }
        reduce8::<0>(&acc)
    }

    /// The six vectors of sums, over `CH` chunks (`lanes / 8` when `CH` is 0).
    ///
    /// # Safety
    /// As [`batch`].
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sums<const CH: usize, const SPLIT: bool>(
        wx: *const f32,
        wy: *const f32,
        rgba: *const f32,
        lanes: usize,
    ) -> [__m256; 6] {
        let n = lanes / LANES;
        // SAFETY: the caller's contract.
        unsafe {
            [
                batch::<0, CH, SPLIT>(wx, wy, rgba, lanes, n),
                batch::<1, CH, SPLIT>(wx, wy, rgba, lanes, n),
                batch::<2, CH, SPLIT>(wx, wy, rgba, lanes, n),
                batch::<3, CH, SPLIT>(wx, wy, rgba, lanes, n),
                batch::<4, CH, SPLIT>(wx, wy, rgba, lanes, n),
                batch::<5, CH, SPLIT>(wx, wy, rgba, lanes, n),
            ]
        }
    }

    /// [`super::contrib_portable`] without `skip_zero`.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn contrib(
        wx: &[f32],
        wy: &[f32],
        rgba: &[f32],
        lanes: usize,
        out: &mut Contrib,
    ) -> bool {
        assert!(
            lanes % LANES == 0
                && lanes > 0
                && wx.len() >= TAPS * lanes
                && wy.len() >= TAPS * lanes
                && rgba.len() >= 4 * lanes
        );
        const { assert!(SUMS == 48) };
        let (px, py, pv) = (wx.as_ptr(), wy.as_ptr(), rgba.as_ptr());
        // SAFETY: the blocks as asserted.
        let s = unsafe {
            match lanes {
                8 => sums::<1, false>(px, py, pv, lanes),
                16 => {
                    // Whether the first chunk reaches no row below and the second none above.
                    let zero = _mm256_setzero_ps();
                    let nz = |at: usize| {
                        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(
                            _mm256_loadu_ps(py.add(at)),
                            zero,
                        ))
                    };
                    if nz(LANES) | nz(2 * lanes) == 0 {
                        sums::<2, true>(px, py, pv, lanes)
                    } else {
                        sums::<2, false>(px, py, pv, lanes)
                    }
                }
                _ => sums::<0, false>(px, py, pv, lanes),
            }
        };
        // x − x is 0 for finite x, NaN otherwise.
        let zero = _mm256_setzero_ps();
        let mut bad = zero;
        for (k, s) in s.iter().enumerate() {
            bad = _mm256_or_ps(
                bad,
                _mm256_cmp_ps::<_CMP_NEQ_UQ>(_mm256_sub_ps(*s, *s), zero),
            );
            // SAFETY: 8 floats at 8·k < SUMS.
            unsafe { _mm256_storeu_ps(out.sums.as_mut_ptr().add(8 * k), *s) };
        }
        ranges(rgba, lanes, out);
        let finite = _mm256_movemask_ps(bad) == 0;
        out.finite = if finite { !0 } else { 0 };
        finite
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

    /// The bucket [x0, x1) × [y0, y1) of a 4×4-sample `whole` buffer `w` pixels wide: a
    /// sub-buffer holding the same samples.
    fn bucket_of(
        whole: &SampleBuffer,
        w: usize,
        x0: usize,
        y0: usize,
        x1: usize,
        y1: usize,
    ) -> SampleBuffer {
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
            for n in [1, 3, 4, 8] {
                let mut whole = buffer(0, 0, w, h, n, 7);
                // Samples on a midline, an edge and a corner of their pixels.
                whole.positions[n * n * 8] = [1.5, 1.25];
                whole.positions[n * n * 9] = [2.0, 1.5];
                whole.positions[n * n * 16] = [2.0, 2.0];
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
        let sub = |x0, y0, x1, y1| prepare(&bucket_of(&whole, w, x0, y0, x1, y1), &ctx);
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
    fn a_bucket_keeping_only_its_ring_finishes_the_same_bits() {
        // Box 0.5: a sample farther than 0.25 from its pixel's centre weighs nothing, so a
        // pixel whose samples all sit in a corner has no weight and takes their plain mean
        // (the one read of a bucket's own blocks after start_tile).
        let f = Filter::new(FilterKind::Box, 0.5, 0.5);
        let t = f.tables().unwrap();
        let (w, h) = (9, 7);
        let mut whole = buffer(0, 0, w, h, 4, 5);
        let lonely = (3, 2); // on the right edge of the first bucket: in its ring
        let s0 = (lonely.1 * w + lonely.0) * 16;
        for s in 0..16 {
            whole.positions[s0 + s] = [lonely.0 as f32 + 0.02, lonely.1 as f32 + 0.03];
        }
        let fm = film(w, h);
        assert!(applies(&f, Some(&t), 5, 16, &fm));
        let ctx = PrepareCtx::new(&f, &t, DepthFilter::Min);
        let one = gather_tile(&fm, &[&prepare(&whole, &ctx)], 0, 0, w, h);
        let mean: Vec<f32> = (0..4)
            .map(|c| {
                let s: f64 = (0..16).map(|s| whole.values[(s0 + s) * 5 + c] as f64).sum();
                (s / 16.0) as f32
            })
            .collect();
        let at = (lonely.1 * w + lonely.0) * 5;
        assert_eq!(&one.data[at..at + 4], &mean[..]);
        let sub = |x0, y0, x1, y1| prepare(&bucket_of(&whole, w, x0, y0, x1, y1), &ctx);
        let rects = [(0, 0, 4, 3), (4, 0, 9, 3), (0, 3, 4, 7), (4, 3, 9, 7)];
        let mut parts = Vec::new();
        let mut partials = Vec::new();
        for &(x0, y0, x1, y1) in &rects {
            let mut p = sub(x0, y0, x1, y1);
            let full = p.bytes();
            let partial = start_tile(&fm, &p, x0, y0, x1 - x0, y1 - y0);
            p.keep_ring(&partial, &ctx);
            assert!(p.bytes() < full, "the inner pixels' blocks are let go");
            parts.push(p);
            partials.push(partial);
        }
        let refs: Vec<&Prepared> = parts.iter().collect();
        for (&(x0, y0, x1, y1), partial) in rects.iter().zip(partials) {
            let tile = finish_tile(&fm, &refs, partial);
            for j in 0..y1 - y0 {
                for i in 0..x1 - x0 {
                    let a = &tile.data[(j * (x1 - x0) + i) * 5..][..5];
                    let b = &one.data[((y0 + j) * w + x0 + i) * 5..][..5];
                    assert_eq!(
                        a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        b.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        "pixel ({}, {})",
                        x0 + i,
                        y0 + j
                    );
                }
            }
        }
    }

    #[test]
    fn portable_and_vector_builds_agree_bit_for_bit() {
        for (kind, width) in [(FilterKind::Gaussian, 2.0), (FilterKind::Sinc, 2.5)] {
            let f = Filter::new(kind, width, width);
            let t = f.tables().unwrap();
            let ctx = PrepareCtx::new(&f, &t, DepthFilter::Min);
            for n in [1, 3, 4, 8] {
                let spp = n * n;
                let mut b = buffer(3, 2, 6, 5, n, 11);
                // Samples on the midlines and the edges, and a non-finite value.
                b.positions[0] = [3.5, 2.5];
                b.positions[spp + spp / 2] = [4.0, 2.0];
                b.values[5 * (2 * spp) + 1] = f32::INFINITY;
                let lanes = spp.div_ceil(LANES) * LANES;
                for pix in 0..b.width * b.height {
                    let (qx, qy) = (3 + (pix % b.width) as i32, 2 + (pix / b.width) as i32);
                    let mut xs = vec![f32::NAN; lanes];
                    let mut ys = vec![f32::NAN; lanes];
                    let mut rgba = vec![0f32; 4 * lanes];
                    for s in 0..lanes {
                        let k = pix * spp + s.min(spp - 1) * (s < spp) as usize;
                        if s < spp {
                            [xs[s], ys[s]] = b.positions[k];
                        }
                        for c in 0..4 {
                            rgba[c * lanes + s] = b.values[5 * k + c];
                        }
                    }
                    let mut w = vec![0f32; 2 * TAPS * lanes];
                    let (wx, wy) = w.split_at_mut(TAPS * lanes);
                    weights_portable(&xs, qx, &ctx.axes[0], wx);
                    weights_portable(&ys, qy, &ctx.axes[1], wy);
                    let mut a = ABSENT;
                    let fa = contrib_portable(wx, wy, &rgba, lanes, false, &mut a);
                    #[cfg(target_arch = "x86_64")]
                    if std::arch::is_x86_feature_detected!("avx2") {
                        let mut v = vec![0f32; 2 * TAPS * lanes];
                        let (vx, vy) = v.split_at_mut(TAPS * lanes);
                        // SAFETY: the CPU has AVX2.
                        unsafe {
                            avx2::weights(&xs, qx, &ctx.axes[0], vx);
                            avx2::weights(&ys, qy, &ctx.axes[1], vy);
                        }
                        assert_eq!(wx, vx);
                        assert_eq!(wy, vy);
                        let mut c = ABSENT;
                        // SAFETY: the CPU has AVX2.
                        let fc = unsafe { avx2::contrib(vx, vy, &rgba, lanes, &mut c) };
                        // Both see a non-finite sum (then the careful portable path runs),
                        // or they agree bit for bit.
                        assert_eq!(fa, fc);
                        if !fa {
                            continue;
                        }
                        assert_eq!(a.sums.map(f32::to_bits), c.sums.map(f32::to_bits));
                        assert_eq!(a.range.map(f32::to_bits), c.range.map(f32::to_bits));
                        assert_eq!(a.finite, c.finite);
                    }
                    // The pixel's own weight is never zero for these filters.
                    assert!(!fa || a.sums[5 * 4 + 4] != 0.0);
                }
                // Combining the neighbours, around every interior pixel.
                let p = prepare(&b, &ctx);
                for j in 1..b.height - 1 {
                    for i in 1..b.width - 1 {
                        let nb: [&Contrib; 9] = std::array::from_fn(|k| {
                            &p.px[(j + k / 3 - 1) * b.width + i + k % 3 - 1]
                        });
                        let a = combine(&nb);
                        #[cfg(target_arch = "x86_64")]
                        if std::arch::is_x86_feature_detected!("avx2") {
                            // SAFETY: the CPU has AVX2.
                            let v = unsafe { avx2::combine(&nb) };
                            assert_eq!(a.0.map(f32::to_bits), v.0.map(f32::to_bits));
                            assert_eq!(a.1.map(f32::to_bits), v.1.map(f32::to_bits));
                            assert_eq!(a.2, v.2);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn quadrant_path_agrees_with_the_general_one_and_across_builds() {
        for (kind, width) in [
            (FilterKind::Gaussian, 2.0),
            (FilterKind::Triangle, 2.0),
            (FilterKind::Box, 1.0),
            (FilterKind::Gaussian, 1.5),
        ] {
            let f = Filter::new(kind, width, width);
            let t = f.tables().unwrap();
            let ctx = PrepareCtx::new(&f, &t, DepthFilter::Min);
            let mut b = buffer(5, 3, 6, 5, 4, 13);
            // A sample on its pixel's vertical midline (pixel 1) and one on the horizontal
            // midline (pixel 2): the general path.
            b.positions[16 + 5] = [6.5, b.positions[16 + 5][1]];
            b.positions[32 + 9] = [b.positions[32 + 9][0], 3.5];
            // A non-finite value (pixel 3): the careful path.
            b.values[5 * (48 + 6) + 2] = f32::INFINITY;
            let mut quads = 0;
            for pix in 0..b.width * b.height {
                let q = (5 + (pix % b.width) as i32, 3 + (pix / b.width) as i32);
                let (mut xs, mut ys) = (vec![0f32; 16], vec![0f32; 16]);
                let mut rgba = vec![0f32; 64];
                for s in 0..16 {
                    [xs[s], ys[s]] = b.positions[pix * 16 + s];
                    for c in 0..4 {
                        rgba[c * 16 + s] = b.values[5 * (pix * 16 + s) + c];
                    }
                }
                let mut a = ABSENT;
                let got = quad_portable(&ctx.axes, (&xs, &ys), q, &rgba, &mut a);
                assert_eq!(got.is_none(), pix == 1 || pix == 2, "pixel {pix}");
                assert_eq!(got == Some(false), pix == 3, "pixel {pix}");
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    let mut v = ABSENT;
                    // SAFETY: the CPU has AVX2.
                    let vg = unsafe { avx2::quad(&ctx.axes, (&xs, &ys), q, &rgba, &mut v) };
                    assert_eq!(got, vg);
                    if got == Some(true) {
                        assert_eq!(a.sums.map(f32::to_bits), v.sums.map(f32::to_bits));
                        assert_eq!(a.range.map(f32::to_bits), v.range.map(f32::to_bits));
                        assert_eq!(a.finite, v.finite);
                    }
                }
                if got != Some(true) {
                    continue;
                }
                quads += 1;
                let mut w = vec![0f32; 2 * TAPS * 16];
                let (wx, wy) = w.split_at_mut(TAPS * 16);
                weights_portable(&xs, q.0, &ctx.axes[0], wx);
                weights_portable(&ys, q.1, &ctx.axes[1], wy);
                let mut g = ABSENT;
                assert!(contrib_portable(wx, wy, &rgba, 16, false, &mut g));
                for (k, (x, y)) in a.sums.iter().zip(&g.sums).enumerate() {
                    assert!((x - y).abs() <= 1e-6 * y.abs().max(1.0), "{kind:?} sum {k}");
                }
                assert_eq!(a.range, g.range);
            }
            assert_eq!(quads, 27);
        }
    }

    #[test]
    fn vector_depth_is_the_sample_fold() {
        let zs: Vec<f32> = (0..19)
            .map(|k| 3.0 + ((k * 7) % 11) as f32 * 0.25)
            .collect();
        let mut with_gaps = zs.clone();
        with_gaps[3] = f32::NAN;
        with_gaps[9] = f32::INFINITY;
        with_gaps[17] = 1.5;
        for z in [
            &zs[..8],
            &zs[..16],
            &zs[..],
            &with_gaps[..16],
            &with_gaps[..],
        ] {
            for df in [DepthFilter::Min, DepthFilter::Max, DepthFilter::Average] {
                let want = own_depth(z.iter().copied(), df);
                assert_eq!(Kernel::Portable.depth(z, df).to_bits(), want.to_bits());
                assert_eq!(pick_kernel().depth(z, df).to_bits(), want.to_bits());
            }
        }
        assert_eq!(pick_kernel().depth(&with_gaps, DepthFilter::Min), 1.5);
        assert_eq!(
            pick_kernel().depth(&with_gaps, DepthFilter::Max),
            f32::INFINITY
        );
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
