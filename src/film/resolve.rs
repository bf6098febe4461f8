//! Resolve: hider samples → filtered pixels of the [`Film`].
//!
//! Input: a [`SampleBuffer`] covering one bucket region plus the filter margin, a pixel filter
//! and a depth filter. Output: the region's pixels written into the full-frame [`Film`].
//! Invariants: each pixel is Σ wᵢ·cᵢ / Σ wᵢ over the samples inside its filter support, with wᵢ
//! from the sample's actual (jittered) position; sums are in f64 so a constant image comes out
//! exactly constant. Samples in pixels outside the image do not exist (the weights renormalise).
//! Depth (channel `z`) is never pixel-filtered: it combines only the pixel's own samples.

use super::filter::{Filter, FilterTables};
use super::SampleBuffer;
use crate::diag::{Diag, Diagnostics};
use crate::num::{ceil_i64, floor_i64};
use crate::scene::{Hider, PixelFilter};
use rayon::prelude::*;

/// The full filtered image: `channel_names.len()` floats per pixel, rows top to bottom.
/// Channels are `r g b a z` then the arbitrary output variables (a float AOV `name`, a colour
/// `name.r name.g name.b`, a point/vector/normal `name.x name.y name.z`), in [`SampleBuffer`]
/// order. Colours are premultiplied by alpha.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Film {
    pub width: usize,
    pub height: usize,
    pub channel_names: Vec<String>,
    pub data: Vec<f32>,
}

impl Film {
    /// Writes a filtered tile into the film.
    pub fn put_tile(&mut self, t: &Tile) {
        let nch = self.channels();
        for j in 0..t.h {
            let dst = ((t.y0 + j) * self.width + t.x0) * nch;
            let src = j * t.w * nch;
            self.data[dst..dst + t.w * nch].copy_from_slice(&t.data[src..src + t.w * nch]);
        }
    }

    /// [`Film::put_tile`] for each of `tiles` in order (a later tile wins where they
    /// overlap), the scanlines in parallel.
    pub fn put_tiles(&mut self, tiles: &[Tile]) {
        let (nch, width) = (self.channels(), self.width);
        let Some(y0) = tiles.iter().filter(|t| t.h > 0).map(|t| t.y0).min() else {
            return;
        };
        let y1 = tiles.iter().map(|t| t.y0 + t.h).max().unwrap_or(y0);
        if nch == 0 || width == 0 {
            return;
        }
        self.data[y0 * width * nch..y1 * width * nch]
            .par_chunks_mut(width * nch)
            .enumerate()
            .for_each(|(j, line)| {
                let y = y0 + j;
                for t in tiles.iter().filter(|t| (t.y0..t.y0 + t.h).contains(&y)) {
                    let src = (y - t.y0) * t.w * nch;
                    line[t.x0 * nch..(t.x0 + t.w) * nch]
                        .copy_from_slice(&t.data[src..src + t.w * nch]);
                }
            });
    }

    /// The pixels `x0..x1`, `y0..y1` as a film of their own (a CropWindow render's image is
    /// the size of the crop region, RISpec §4.1.1).
    pub fn cropped(&self, x0: usize, y0: usize, x1: usize, y1: usize) -> Film {
        let (x1, y1) = (x1.min(self.width), y1.min(self.height));
        let (w, h) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
        let nch = self.channel_names.len();
        let mut data = Vec::with_capacity(w * h * nch);
        for y in y0..y0 + h {
            let row = (y * self.width + x0) * nch;
            data.extend_from_slice(&self.data[row..row + w * nch]);
        }
        Film {
            width: w,
            height: h,
            channel_names: self.channel_names.clone(),
            data,
        }
    }

    /// A black, transparent film with depth = +∞.
    pub fn new(width: usize, height: usize, channel_names: Vec<String>) -> Film {
        let nch = channel_names.len();
        let mut data = vec![0.0; width * height * nch];
        if let Some(z) = channel_names.iter().position(|c| c == "z") {
            // In parallel bands: writing the depths first touches every page of a large
            // film (tens of MB at 1280 × 960), which is most of the cost.
            let band = nch.max(1) * 4096;
            data.par_chunks_mut(band).for_each(|b| {
                for px in b.chunks_exact_mut(nch.max(1)) {
                    px[z] = f32::INFINITY;
                }
            });
        }
        Film {
            width,
            height,
            channel_names,
            data,
        }
    }

    /// The size and channels of a film without its pixels: tiles can be filtered against it
    /// while the film itself is being written ([`filter_tile`] reads its region as
    /// [`Film::new`] leaves it: black, depth +∞).
    pub fn shape(&self) -> Film {
        Film {
            width: self.width,
            height: self.height,
            channel_names: self.channel_names.clone(),
            data: Vec::new(),
        }
    }

    /// A pixel as [`Film::new`] leaves it: zeros, depth (`z`) +∞.
    pub fn blank_pixel(&self) -> Vec<f32> {
        let mut px = vec![0.0; self.channels()];
        if let Some(z) = self.channel("z") {
            px[z] = f32::INFINITY;
        }
        px
    }

    /// The standard channels `r g b a z` followed by `aovs`.
    pub fn standard_channels(aovs: &[String]) -> Vec<String> {
        let mut v: Vec<String> = ["r", "g", "b", "a", "z"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        v.extend(aovs.iter().cloned());
        v
    }

    pub fn channels(&self) -> usize {
        self.channel_names.len()
    }

    /// Index of the channel called `name`.
    pub fn channel(&self, name: &str) -> Option<usize> {
        self.channel_names.iter().position(|c| c == name)
    }

    /// The channels of an output variable: `name` itself, else every `name.<component>`.
    pub fn aov_channels(&self, name: &str) -> Vec<usize> {
        if let Some(i) = self.channel(name) {
            return vec![i];
        }
        let prefix = format!("{name}.");
        self.channel_names
            .iter()
            .enumerate()
            .filter(|(_, c)| c.starts_with(&prefix))
            .map(|(i, _)| i)
            .collect()
    }

    /// The floats of pixel (x, y).
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let n = self.channels();
        let i = (y * self.width + x) * n;
        &self.data[i..i + n]
    }

    pub fn pixel_mut(&mut self, x: usize, y: usize) -> &mut [f32] {
        let n = self.channels();
        let i = (y * self.width + x) * n;
        &mut self.data[i..i + n]
    }
}

/// How a pixel's depth combines its samples (`Hider "hidden" "depthfilter"`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DepthFilter {
    /// The nearest sample depth (the default).
    #[default]
    Min,
    Max,
    /// The mean of the finite sample depths (+∞ when none hit anything).
    Average,
}

impl DepthFilter {
    /// The depth filter a hider asks for. `midpoint` needs the depth of the second-nearest
    /// surface per sample, which the hider does not keep: it warns and gives `Min`.
    pub fn from_hider(hider: &Hider, diags: &Diagnostics) -> DepthFilter {
        match hider.params.string("depthfilter") {
            None => DepthFilter::Min,
            Some(s) => DepthFilter::from_name(s, diags),
        }
    }

    pub fn from_name(name: &str, diags: &Diagnostics) -> DepthFilter {
        match name {
            "min" => DepthFilter::Min,
            "max" => DepthFilter::Max,
            "average" => DepthFilter::Average,
            "midpoint" => {
                diags.report(
                    Diag::warning(
                        "film::depthfilter",
                        "depthfilter \"midpoint\" is not implemented yet (it needs the \
                         second-nearest surface per sample); using \"min\"",
                    )
                    .help("use \"min\", \"max\" or \"average\""),
                );
                DepthFilter::Min
            }
            other => {
                diags.report(
                    Diag::warning(
                        "film::depthfilter",
                        format!("unknown depthfilter `{other}`; using \"min\""),
                    )
                    .help("depthfilter is one of \"min\", \"max\", \"average\", \"midpoint\""),
                );
                DepthFilter::Min
            }
        }
    }
}

/// Filters pixels `x0..x0+w`, `y0..y0+h` of `film` from `buf` (see [`filter_region`]).
#[allow(clippy::too_many_arguments)]
pub fn filter_into(
    film: &mut Film,
    buf: &SampleBuffer,
    filter: &PixelFilter,
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    depth_filter: DepthFilter,
) {
    let f = Filter::from_scene(filter);
    filter_region(film, buf, &f, x0, y0, w, h, depth_filter);
}

/// Scratch accumulators for one region, reused across calls to avoid reallocating, and the
/// tabulated filter of the frame (rebuilt when the filter changes).
#[derive(Default)]
struct Accum {
    sums: Vec<f64>,
    wsum: Vec<f64>,
    /// r g b a and the weight per pixel, for the common r g b a z buffer.
    rgbaw: Vec<[f64; 5]>,
    tables: Option<(Filter, Option<FilterTables>)>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Accum> = std::cell::RefCell::new(Accum::default());
}

/// Filters the region's pixels with a prepared filter. The buffer should cover the region
/// plus ⌈width/2⌉ pixels each side (clipped at the image edge); missing samples simply drop
/// out of the weighted average. Pixels outside the film are ignored.
#[allow(clippy::too_many_arguments)]
pub fn filter_region(
    film: &mut Film,
    buf: &SampleBuffer,
    filter: &Filter,
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    depth_filter: DepthFilter,
) {
    let tile = filter_tile(film, buf, filter, x0, y0, w, h, depth_filter);
    film.put_tile(&tile);
}

/// Filtered pixels of one region, computed without touching the film so regions can be
/// filtered in parallel and written afterwards ([`Film::put_tile`]).
#[derive(Clone, Debug, Default)]
pub struct Tile {
    pub x0: usize,
    pub y0: usize,
    pub w: usize,
    pub h: usize,
    /// `w * h` pixels of the film's channels.
    pub data: Vec<f32>,
}

/// Like [`filter_region`], into a [`Tile`] (the film is only read for its size, channels and
/// the region's current values).
#[allow(clippy::too_many_arguments)]
pub fn filter_tile(
    film: &Film,
    buf: &SampleBuffer,
    filter: &Filter,
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    depth_filter: DepthFilter,
) -> Tile {
    let mut tile = Tile {
        x0,
        y0,
        w: 0,
        h: 0,
        data: Vec::new(),
    };
    // Clip the region to the film.
    let x1 = (x0 + w).min(film.width);
    let y1 = (y0 + h).min(film.height);
    if x0 >= x1 || y0 >= y1 {
        return tile;
    }
    let (w, h) = (x1 - x0, y1 - y0);
    let nch_film = film.channels();
    tile.w = w;
    tile.h = h;
    tile.data.reserve(w * h * nch_film);
    if film.data.is_empty() {
        // A film's shape (see [`Film::shape`]): the region as `Film::new` leaves it.
        let blank = film.blank_pixel();
        for _ in 0..w * h {
            tile.data.extend_from_slice(&blank);
        }
    }
    for y in (y0..y1).filter(|_| !film.data.is_empty()) {
        let row = (y * film.width + x0) * nch_film;
        tile.data
            .extend_from_slice(&film.data[row..row + w * nch_film]);
    }
    let nch = nch_film.min(buf.channels);
    let zc = film.channel("z").filter(|&z| z < nch);
    let spp = buf.samples_per_pixel();
    if spp == 0 || nch == 0 {
        return tile;
    }
    // A buffer shorter than its own dimensions is a hider bug; never index past it.
    let nsamples = buf.width * buf.height * spp;
    debug_assert!(buf.positions.len() >= nsamples && buf.values.len() >= nsamples * buf.channels);
    if buf.positions.len() < nsamples || buf.values.len() < nsamples * buf.channels {
        return tile;
    }
    let (hx, hy) = filter.radius();

    SCRATCH.with(|cell| {
        let mut acc = cell.borrow_mut();
        let acc = &mut *acc;
        if !matches!(&acc.tables, Some((f, _)) if f == filter) {
            acc.tables = Some((*filter, filter.tables()));
        }
        let tables = acc.tables.as_ref().and_then(|(_, t)| t.as_ref());
        // The common buffer (r g b a z, no output variables) with a separable filter: the
        // fast scatter below. Depth is never filtered, so its slot carries the weight.
        let fast = match tables {
            Some(t) if nch == 5 && zc == Some(4) && buf.channels == 5 && hx.max(hy) <= 3.0 => {
                Some(t)
            }
            _ => None,
        };
        if let Some(t) = fast {
            acc.rgbaw.clear();
            acc.rgbaw.resize(w * h, [0.0; 5]);
            scatter_rgba(&mut acc.rgbaw, buf, t, film, [x0, y0, x1, y1], (hx, hy));
            for j in 0..h {
                for i in 0..w {
                    let p = j * w + i;
                    let out_base = p * nch_film;
                    let out = &mut tile.data[out_base..out_base + nch];
                    let a = &acc.rgbaw[p];
                    let ws = a[4];
                    if ws.abs() > 1e-12 {
                        let inv = 1.0 / ws;
                        for c in 0..4 {
                            out[c] = (a[c] * inv) as f32;
                        }
                    } else {
                        own_mean(out, buf, x0 + i, y0 + j, nch);
                    }
                    out[4] = own_depth(buf, x0 + i, y0 + j, 4, depth_filter);
                }
            }
            return;
        }
        acc.sums.clear();
        acc.sums.resize(w * h * nch, 0.0);
        acc.wsum.clear();
        acc.wsum.resize(w * h, 0.0);
        // Output columns/rows a sample can reach: |p + 0.5 − s| ≤ half width.
        let reach = (hx.ceil() as i64 + 1, hy.ceil() as i64 + 1);
        let mut wx = [0f32; 64];
        let mut wy = [0f32; 64];

        for by in 0..buf.height {
            let ry = buf.y0 as i64 + by as i64;
            if ry < 0 || ry >= film.height as i64 {
                continue; // samples outside the image do not exist
            }
            // Skip buffer rows too far from the region to contribute.
            if ry + reach.1 < y0 as i64 || ry - reach.1 >= y1 as i64 {
                continue;
            }
            for bx in 0..buf.width {
                let rx = buf.x0 as i64 + bx as i64;
                if rx < 0 || rx >= film.width as i64 {
                    continue;
                }
                if rx + reach.0 < x0 as i64 || rx - reach.0 >= x1 as i64 {
                    continue;
                }
                let base = (by * buf.width + bx) * spp;
                for s in base..base + spp {
                    let [sx, sy] = buf.positions[s];
                    if !(sx.is_finite() && sy.is_finite()) {
                        continue; // a broken sample must not poison its neighbours
                    }
                    // Output pixel range whose support contains the sample (clipped to the region).
                    let px_lo = ceil_i64(sx - hx - 0.5).max(x0 as i64);
                    let px_hi = floor_i64(sx + hx - 0.5).min(x1 as i64 - 1);
                    let py_lo = ceil_i64(sy - hy - 0.5).max(y0 as i64);
                    let py_hi = floor_i64(sy + hy - 0.5).min(y1 as i64 - 1);
                    if px_lo > px_hi || py_lo > py_hi {
                        continue;
                    }
                    let nx = (px_hi - px_lo + 1) as usize;
                    let ny = (py_hi - py_lo + 1) as usize;
                    let vals = &buf.values[s * buf.channels..s * buf.channels + nch];
                    if let (Some(t), true) = (tables, nx <= wx.len() && ny <= wy.len()) {
                        for (i, wxi) in wx[..nx].iter_mut().enumerate() {
                            *wxi = t.x.at((px_lo + i as i64) as f32 + 0.5 - sx);
                        }
                        for (j, wyj) in wy[..ny].iter_mut().enumerate() {
                            *wyj = t.y.at((py_lo + j as i64) as f32 + 0.5 - sy);
                        }
                        for (j, &wyj) in wy[..ny].iter().enumerate() {
                            if wyj == 0.0 {
                                continue;
                            }
                            let row = (py_lo as usize + j - y0) * w + px_lo as usize - x0;
                            for (i, &wxi) in wx[..nx].iter().enumerate() {
                                let wgt = (wxi * wyj) as f64;
                                if wgt == 0.0 {
                                    continue;
                                }
                                let p = row + i;
                                accumulate(&mut acc.sums[p * nch..p * nch + nch], vals, wgt);
                                acc.wsum[p] += wgt;
                            }
                        }
                    } else {
                        for py in py_lo..=py_hi {
                            let dy = py as f32 + 0.5 - sy;
                            let row = (py as usize - y0) * w;
                            for px in px_lo..=px_hi {
                                let wgt = filter.eval(px as f32 + 0.5 - sx, dy) as f64;
                                if wgt == 0.0 {
                                    continue;
                                }
                                let p = row + px as usize - x0;
                                accumulate(&mut acc.sums[p * nch..p * nch + nch], vals, wgt);
                                acc.wsum[p] += wgt;
                            }
                        }
                    }
                }
            }
        }

        // Normalise into the film; depth from the pixel's own samples.
        for j in 0..h {
            let ry = y0 + j;
            for i in 0..w {
                let rx = x0 + i;
                let p = j * w + i;
                let out_base = (j * w + i) * nch_film;
                let out = &mut tile.data[out_base..out_base + nch];
                let ws = acc.wsum[p];
                if ws.abs() > 1e-12 {
                    let inv = 1.0 / ws;
                    for (o, &s) in out.iter_mut().zip(&acc.sums[p * nch..p * nch + nch]) {
                        *o = (s * inv) as f32;
                    }
                } else {
                    // Nothing (or weights cancelling) in the support: fall back to the plain
                    // mean of the pixel's own samples, else zero.
                    own_mean(out, buf, rx, ry, nch);
                }
                if let Some(zc) = zc {
                    out[zc] = own_depth(buf, rx, ry, zc, depth_filter);
                }
            }
        }
    });
    tile
}

/// Scatters every sample of an r g b a z buffer into the pixels of region
/// `[x0, x1) × [y0, y1)` whose support holds it, adding r g b a and the weight in f64.
///
/// A sample at `sx` reaches the columns `c` with `sx − hx − 0.5 ≤ c ≤ sx + hx − 0.5` (the
/// generic path's ⌈⌉/⌊⌋ range, without the conversions): the few candidate columns of its
/// buffer pixel are fixed, so the range is two counts of compares; each reached column and
/// row costs one table read.
fn scatter_rgba(
    acc: &mut [[f64; 5]],
    buf: &SampleBuffer,
    t: &FilterTables,
    film: &Film,
    region: [usize; 4],
    (hx, hy): (f32, f32),
) {
    // Candidate columns of a buffer pixel: rx ± ⌊hx + 0.5 + slack⌋ (see `candidates`).
    let k = ((hx.max(hy) as f64 + 0.5 + CANDIDATE_SLACK).floor() as usize) * 2 + 1;
    if k <= 4 {
        scatter_k::<4>(acc, buf, t, film, region, (hx, hy));
    } else {
        scatter_k::<MAX_CANDIDATES>(acc, buf, t, film, region, (hx, hy));
    }
}

/// Most candidate columns (rows) of one buffer pixel on the fast path: half widths up to 3.
const MAX_CANDIDATES: usize = 8;

/// Widening of a buffer pixel's candidate range beyond the exact rx ± (h + 0.5), so that the
/// f32 rounding of the per-sample bounds can never reach a column outside it.
const CANDIDATE_SLACK: f64 = 0.01;

/// The candidate columns (or rows) of buffer pixel `r` clipped to `[lo, hi]`, ascending, as
/// floats padded with +∞ (never counted), and the first one. At most
/// 2·⌊h + 0.5 + slack⌋ + 1 of them.
#[inline]
fn candidates<const N: usize>(r: i64, h: f32, lo: i64, hi: i64) -> ([f32; N], i64) {
    let reach = (h as f64 + 0.5 + CANDIDATE_SLACK).floor() as i64;
    debug_assert!((2 * reach + 1) as usize <= N);
    let c0 = (r - reach).max(lo);
    let c1 = (r + reach).min(hi);
    let mut cf = [f32::INFINITY; N];
    for (k, v) in cf.iter_mut().enumerate() {
        let c = c0 + k as i64;
        if c <= c1 {
            *v = c as f32;
        }
    }
    (cf, c0)
}

/// The indices `[lo, hi)` of the candidates `cf` inside `[a, b]` (both prefixes of `cf`).
#[inline(always)]
fn reached<const N: usize>(cf: &[f32; N], a: f32, b: f32) -> (usize, usize) {
    let (mut lo, mut hi) = (0usize, 0usize);
    for &c in cf {
        lo += (c < a) as usize;
        hi += (c <= b) as usize;
    }
    (lo, hi)
}

fn scatter_k<const N: usize>(
    acc: &mut [[f64; 5]],
    buf: &SampleBuffer,
    t: &FilterTables,
    film: &Film,
    [x0, y0, x1, y1]: [usize; 4],
    (hx, hy): (f32, f32),
) {
    let w = x1 - x0;
    let spp = buf.samples_per_pixel();
    let (rlo_x, rhi_x) = (x0 as i64, x1 as i64 - 1);
    let (rlo_y, rhi_y) = (y0 as i64, y1 as i64 - 1);
    let mut wx = [0f32; N];
    let mut wy = [0f32; N];
    for by in 0..buf.height {
        let ry = buf.y0 as i64 + by as i64;
        if ry < 0 || ry >= film.height as i64 {
            continue; // samples outside the image do not exist
        }
        let (cfy, cy0) = candidates::<N>(ry, hy, rlo_y, rhi_y);
        if cfy[0] == f32::INFINITY {
            continue; // no row of the region within reach
        }
        for bx in 0..buf.width {
            let rx = buf.x0 as i64 + bx as i64;
            if rx < 0 || rx >= film.width as i64 {
                continue;
            }
            let (cfx, cx0) = candidates::<N>(rx, hx, rlo_x, rhi_x);
            if cfx[0] == f32::INFINITY {
                continue;
            }
            let base = (by * buf.width + bx) * spp;
            let pos = &buf.positions[base..base + spp];
            let vals = &buf.values[base * 5..(base + spp) * 5];
            for (&[sx, sy], v) in pos.iter().zip(vals.chunks_exact(5)) {
                if !(sx.is_finite() && sy.is_finite()) {
                    continue;
                }
                let (ilo, ihi) = reached(&cfx, sx - hx - 0.5, sx + hx - 0.5);
                let (jlo, jhi) = reached(&cfy, sy - hy - 0.5, sy + hy - 0.5);
                if ilo >= ihi || jlo >= jhi {
                    continue;
                }
                for i in ilo..ihi {
                    wx[i] = t.x.at(cfx[i] + 0.5 - sx);
                }
                for j in jlo..jhi {
                    wy[j] = t.y.at(cfy[j] + 0.5 - sy);
                }
                let c = [v[0] as f64, v[1] as f64, v[2] as f64, v[3] as f64];
                let col = (cx0 - x0 as i64) as usize;
                for j in jlo..jhi {
                    let wyj = wy[j];
                    let row = ((cy0 - y0 as i64) as usize + j) * w + col;
                    for i in ilo..ihi {
                        let wgt = (wx[i] * wyj) as f64;
                        // A zero weight adds nothing, and must not let a non-finite
                        // sample poison the pixel.
                        if wgt == 0.0 {
                            continue;
                        }
                        let a = &mut acc[row + i];
                        a[0] += wgt * c[0];
                        a[1] += wgt * c[1];
                        a[2] += wgt * c[2];
                        a[3] += wgt * c[3];
                        a[4] += wgt;
                    }
                }
            }
        }
    }
}

#[inline]
fn accumulate(sums: &mut [f64], vals: &[f32], w: f64) {
    for (s, &v) in sums.iter_mut().zip(vals) {
        *s += w * v as f64;
    }
}

/// The buffer pixel holding raster pixel (rx, ry), if the buffer covers it.
fn own_samples(buf: &SampleBuffer, rx: usize, ry: usize) -> Option<std::ops::Range<usize>> {
    let bx = rx as i64 - buf.x0 as i64;
    let by = ry as i64 - buf.y0 as i64;
    if bx < 0 || by < 0 || bx >= buf.width as i64 || by >= buf.height as i64 {
        return None;
    }
    let spp = buf.samples_per_pixel();
    let base = (by as usize * buf.width + bx as usize) * spp;
    Some(base..base + spp)
}

fn own_mean(out: &mut [f32], buf: &SampleBuffer, rx: usize, ry: usize, nch: usize) {
    out.iter_mut().for_each(|o| *o = 0.0);
    let Some(r) = own_samples(buf, rx, ry) else {
        return;
    };
    let n = r.len() as f64;
    for (c, o) in out.iter_mut().enumerate().take(nch) {
        let s: f64 = r
            .clone()
            .map(|s| buf.values[s * buf.channels + c] as f64)
            .sum();
        *o = (s / n) as f32;
    }
}

fn own_depth(buf: &SampleBuffer, rx: usize, ry: usize, zc: usize, df: DepthFilter) -> f32 {
    let Some(r) = own_samples(buf, rx, ry) else {
        return f32::INFINITY;
    };
    super::gather::own_depth(r.map(|s| buf.values[s * buf.channels + zc]), df)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::filter::{FilterKind, FILTER_NAMES};

    /// A buffer over raster pixels [x0, x0+w) × [y0, y0+h), jittered deterministically.
    fn buffer(
        x0: i32,
        y0: i32,
        w: usize,
        h: usize,
        spp: usize,
        channels: usize,
        value: impl Fn(f32, f32, usize) -> f32,
    ) -> SampleBuffer {
        let mut b = SampleBuffer {
            x0,
            y0,
            width: w,
            height: h,
            spp_x: spp,
            spp_y: spp,
            channels,
            ..Default::default()
        };
        let mut k = 0u32;
        for py in 0..h {
            for px in 0..w {
                for sy in 0..spp {
                    for sx in 0..spp {
                        k = k.wrapping_mul(747796405).wrapping_add(2891336453);
                        let jx = ((k >> 8) & 0xffff) as f32 / 65536.0;
                        let jy = ((k >> 16) & 0xff) as f32 / 256.0;
                        let x = (x0 + px as i32) as f32 + (sx as f32 + jx) / spp as f32;
                        let y = (y0 + py as i32) as f32 + (sy as f32 + jy) / spp as f32;
                        b.positions.push([x, y]);
                        for c in 0..channels {
                            b.values.push(value(x, y, c));
                        }
                    }
                }
            }
        }
        b
    }

    #[test]
    fn constant_buffer_stays_exactly_constant_with_every_filter() {
        let consts = [0.3f32, 0.7, 0.123_456_7, 1.0, 0.9];
        for name in FILTER_NAMES {
            for &(xw, yw) in &[(1.0f32, 1.0f32), (2.0, 2.0), (3.0, 2.5), (4.0, 4.0)] {
                let pf = PixelFilter {
                    name: name.into(),
                    xwidth: xw,
                    ywidth: yw,
                };
                let (w, h) = (8usize, 6usize);
                let mut film = Film::new(w, h, Film::standard_channels(&[]));
                // Whole image in two buckets, each with its margin clipped at the edges.
                let m = (xw.max(yw) / 2.0).ceil() as i32;
                for &(bx0, bw) in &[(0usize, 5usize), (5, 3)] {
                    let bx = (bx0 as i32 - m).max(0);
                    let bxe = (bx0 as i32 + bw as i32 + m).min(w as i32);
                    let buf = buffer(bx, 0, (bxe - bx) as usize, h, 3, 5, |_, _, c| consts[c]);
                    filter_into(&mut film, &buf, &pf, bx0, 0, bw, h, DepthFilter::Min);
                }
                for y in 0..h {
                    for x in 0..w {
                        assert_eq!(film.pixel(x, y), &consts[..], "{name} {xw}x{yw} at {x},{y}");
                    }
                }
            }
        }
    }

    /// Σ w·c / Σ w per pixel with the analytic filter, in f64: what the tables approximate.
    fn reference(buf: &SampleBuffer, f: &Filter, w: usize, h: usize) -> Vec<[f64; 4]> {
        let (hx, hy) = f.radius();
        let mut out = vec![[0.0; 4]; w * h];
        for (p, o) in out.iter_mut().enumerate() {
            let (cx, cy) = ((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
            let (mut sum, mut ws) = ([0f64; 4], 0f64);
            for (s, &[sx, sy]) in buf.positions.iter().enumerate() {
                let (dx, dy) = (cx - sx, cy - sy);
                if dx.abs() > hx || dy.abs() > hy || sx < 0.0 || sy < 0.0 {
                    continue;
                }
                if sx >= w as f32 || sy >= h as f32 {
                    continue;
                }
                let wt = f.eval(dx, dy) as f64;
                for c in 0..4 {
                    sum[c] += wt * buf.values[s * buf.channels + c] as f64;
                }
                ws += wt;
            }
            for c in 0..4 {
                o[c] = sum[c] / ws;
            }
        }
        out
    }

    #[test]
    fn tabulated_filters_match_the_analytic_filter() {
        // A busy image, filtered bucket by bucket on the fast path, against the analytic sum.
        let (w, h) = (11usize, 9usize);
        let val = |x: f32, y: f32, c: usize| (x * 1.37 + y * 0.71 + c as f32).sin() * 0.5 + 0.5;
        for name in ["box", "triangle", "gaussian", "sinc", "mitchell"] {
            for &(xw, yw) in &[
                (1.0f32, 1.0f32),
                (2.0, 2.0),
                (2.5, 1.5),
                (3.0, 3.0),
                (4.0, 4.0),
                (6.0, 5.0),
            ] {
                let f = Filter::from_scene(&PixelFilter {
                    name: name.into(),
                    xwidth: xw,
                    ywidth: yw,
                });
                let m = (xw.max(yw) / 2.0).ceil() as i32;
                let whole = buffer(-m, -m, w + 2 * m as usize, h + 2 * m as usize, 3, 5, val);
                let want = reference(&whole, &f, w, h);
                let mut film = Film::new(w, h, Film::standard_channels(&[]));
                for &(rx, rw) in &[(0usize, 4usize), (4, 4), (8, 3)] {
                    for &(ry, rh) in &[(0usize, 5usize), (5, 4)] {
                        filter_region(&mut film, &whole, &f, rx, ry, rw, rh, DepthFilter::Min);
                    }
                }
                for p in 0..w * h {
                    for c in 0..4 {
                        let got = film.pixel(p % w, p / w)[c] as f64;
                        assert!(
                            (got - want[p][c]).abs() < 2e-6,
                            "{name} {xw}x{yw} pixel {p} channel {c}: {got} vs {}",
                            want[p][c]
                        );
                    }
                }
                // The generic path (a buffer with an output variable) gives the same bits.
                let mut aov = Film::new(w, h, Film::standard_channels(&["s".into()]));
                let whole6 = buffer(-m, -m, w + 2 * m as usize, h + 2 * m as usize, 3, 6, val);
                filter_region(&mut aov, &whole6, &f, 0, 0, w, h, DepthFilter::Min);
                for p in 0..w * h {
                    assert_eq!(
                        &aov.pixel(p % w, p / w)[..4],
                        &film.pixel(p % w, p / w)[..4],
                        "{name} {xw}x{yw} pixel {p}"
                    );
                }
            }
        }
    }

    #[test]
    fn half_covered_edge_gives_half_with_box() {
        // Coverage 1 left of x = 2.5, 0 right of it; pixel 2 is half covered.
        let pf = PixelFilter {
            name: "box".into(),
            xwidth: 1.0,
            ywidth: 1.0,
        };
        // Regular (unjittered) 4×4 samples so the answer is exact.
        let mut buf = buffer(0, 0, 5, 1, 4, 5, |_, _, _| 0.0);
        for (i, p) in buf.positions.iter_mut().enumerate() {
            let px = i / 16;
            let (sy, sx) = ((i % 16) / 4, i % 4);
            *p = [px as f32 + (sx as f32 + 0.5) / 4.0, (sy as f32 + 0.5) / 4.0];
            let cov = if p[0] < 2.5 { 1.0 } else { 0.0 };
            for c in 0..4 {
                buf.values[i * 5 + c] = cov;
            }
        }
        let mut film = Film::new(5, 1, Film::standard_channels(&[]));
        filter_into(&mut film, &buf, &pf, 0, 0, 5, 1, DepthFilter::Min);
        assert_eq!(film.pixel(1, 0)[3], 1.0);
        assert_eq!(film.pixel(2, 0)[3], 0.5);
        assert_eq!(film.pixel(3, 0)[3], 0.0);
    }

    #[test]
    fn bucket_split_does_not_change_the_result() {
        let pf = PixelFilter {
            name: "gaussian".into(),
            xwidth: 2.0,
            ywidth: 2.0,
        };
        let (w, h) = (9usize, 7usize);
        let val = |x: f32, y: f32, c: usize| (x * 0.37 + y * 0.11 + c as f32).sin();
        let whole = buffer(0, 0, w, h, 2, 5, val);
        let mut a = Film::new(w, h, Film::standard_channels(&[]));
        filter_into(&mut a, &whole, &pf, 0, 0, w, h, DepthFilter::Min);
        // Same samples, region by region: cut sub-buffers out of the whole buffer.
        let mut b = Film::new(w, h, Film::standard_channels(&[]));
        for &(rx, ry, rw, rh) in &[
            (0usize, 0usize, 4usize, 3usize),
            (4, 0, 5, 3),
            (0, 3, 4, 4),
            (4, 3, 5, 4),
        ] {
            let bx0 = rx.saturating_sub(1);
            let by0 = ry.saturating_sub(1);
            let bx1 = (rx + rw + 1).min(w);
            let by1 = (ry + rh + 1).min(h);
            let mut sub = SampleBuffer {
                x0: bx0 as i32,
                y0: by0 as i32,
                width: bx1 - bx0,
                height: by1 - by0,
                spp_x: 2,
                spp_y: 2,
                channels: 5,
                ..Default::default()
            };
            for py in by0..by1 {
                for px in bx0..bx1 {
                    for s in 0..4 {
                        let i = (py * w + px) * 4 + s;
                        sub.positions.push(whole.positions[i]);
                        sub.values
                            .extend_from_slice(&whole.values[i * 5..i * 5 + 5]);
                    }
                }
            }
            filter_into(&mut b, &sub, &pf, rx, ry, rw, rh, DepthFilter::Min);
        }
        assert_eq!(a.data, b.data);
    }

    #[test]
    fn samples_outside_the_image_are_ignored() {
        let pf = PixelFilter {
            name: "gaussian".into(),
            xwidth: 3.0,
            ywidth: 3.0,
        };
        // Raster pixels −2..4 × −2..4; anything outside the 3×3 image holds 100.
        let val = |x: f32, y: f32, c: usize| {
            if x < 0.0 || y < 0.0 || x >= 3.0 || y >= 3.0 {
                100.0
            } else {
                x * 0.1 + y * 0.01 + c as f32
            }
        };
        let wide = buffer(-2, -2, 7, 7, 2, 5, val);
        let mut a = Film::new(3, 3, Film::standard_channels(&[]));
        filter_into(&mut a, &wide, &pf, 0, 0, 3, 3, DepthFilter::Min);
        for v in &a.data {
            assert!(*v < 10.0, "outside samples leaked: {v}");
        }
        // Same as a buffer clipped to the image (same samples inside).
        let mut clipped = SampleBuffer {
            x0: 0,
            y0: 0,
            width: 3,
            height: 3,
            spp_x: 2,
            spp_y: 2,
            channels: 5,
            ..Default::default()
        };
        for py in 2..5 {
            for px in 2..5 {
                for s in 0..4 {
                    let i = (py * 7 + px) * 4 + s;
                    clipped.positions.push(wide.positions[i]);
                    clipped
                        .values
                        .extend_from_slice(&wide.values[i * 5..i * 5 + 5]);
                }
            }
        }
        let mut b = Film::new(3, 3, Film::standard_channels(&[]));
        filter_into(&mut b, &clipped, &pf, 0, 0, 3, 3, DepthFilter::Min);
        assert_eq!(a.data, b.data);
    }

    #[test]
    fn depth_min_max_average() {
        let mut buf = buffer(0, 0, 1, 1, 2, 5, |_, _, _| 0.5);
        let zs = [4.0, 2.0, f32::INFINITY, 3.0];
        for (i, z) in zs.iter().enumerate() {
            buf.values[i * 5 + 4] = *z;
        }
        let pf = PixelFilter {
            name: "box".into(),
            xwidth: 1.0,
            ywidth: 1.0,
        };
        let run = |buf: &SampleBuffer, df| {
            let mut film = Film::new(1, 1, Film::standard_channels(&[]));
            filter_into(&mut film, buf, &pf, 0, 0, 1, 1, df);
            film.pixel(0, 0)[4]
        };
        assert_eq!(run(&buf, DepthFilter::Min), 2.0);
        assert_eq!(run(&buf, DepthFilter::Max), f32::INFINITY);
        assert_eq!(run(&buf, DepthFilter::Average), 3.0, "infinity ignored");
        // All misses: average stays infinite.
        for i in 0..4 {
            buf.values[i * 5 + 4] = f32::INFINITY;
        }
        assert_eq!(run(&buf, DepthFilter::Average), f32::INFINITY);
    }

    #[test]
    fn depthfilter_names() {
        let d = Diagnostics::new();
        assert_eq!(DepthFilter::from_name("average", &d), DepthFilter::Average);
        assert_eq!(DepthFilter::from_name("max", &d), DepthFilter::Max);
        assert!(d.snapshot().is_empty());
        assert_eq!(DepthFilter::from_name("midpoint", &d), DepthFilter::Min);
        assert_eq!(d.snapshot().len(), 1);
    }

    #[test]
    fn aov_channels_by_prefix() {
        let film = Film::new(
            1,
            1,
            Film::standard_channels(&["N.x".into(), "N.y".into(), "N.z".into(), "s".into()]),
        );
        assert_eq!(film.aov_channels("N"), vec![5, 6, 7]);
        assert_eq!(film.aov_channels("s"), vec![8]);
        assert!(film.aov_channels("P").is_empty());
        assert_eq!(film.pixel(0, 0)[4], f32::INFINITY);
        let _ = FilterKind::Box;
    }
}
