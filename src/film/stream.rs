//! Streaming PNG output: a frame's 8-bit PNG displays are quantised, row-filtered and deflated
//! as the render finishes each band of scanlines, so the encoding overlaps the hiding of later
//! rows instead of running alone after the frame (it was the largest serial part of a frame).
//!
//! Input: the film's scanlines `[y0, y1)` once they are final ([`RowSink::rows`], called by the
//! render driver in scanline order). Output: a zlib stream per display, handed to
//! `output::write_displays_streamed`, which writes the file (temporary name, renamed) when the
//! frame is done.
//! Invariants: the file is byte for byte what the whole-image path writes — the same values
//! ([`Layout::row_values`]: straight colour in a PNG with alpha), the same quantiser, the same adaptive row filter choice as the `png` crate (Up, Sub, Avg, Paeth,
//! least sum of |byte as i8|, ties to the later filter, the first zero-cost filter wins), the
//! same `fdeflate` compressor fed the same row records, one IDAT chunk. Where that crate would
//! store the data uncompressed (the compressed stream is larger), or a row never arrived, the
//! stream is dropped and the display is written the old way from the film.

use super::quantize::{quantize_row_u8, unpremultiply};
use super::resolve::Film;
use crate::scene::Quantize;

/// Receives a frame's finished scanlines, in order, while the rest is still rendering.
pub trait RowSink {
    /// Scanlines `y0..y1` of `film` are final.
    fn rows(&mut self, film: &Film, y0: usize, y1: usize);
}

/// How a display's bytes come from the film: 8-bit samples, one per `src` channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Film channel of each output channel (1 to 4 of them).
    pub src: Vec<usize>,
    /// Per output channel, the film's alpha channel when that channel is written as straight
    /// colour (a PNG with alpha: see `output::straight_alpha`), else `None`.
    pub divide_by: Vec<Option<usize>>,
    pub q: Quantize,
}

impl Layout {
    /// Output channel `k` of row `row` of `film` as the floats the quantiser takes, one per
    /// pixel into `vals`: the film's values, divided by alpha where the display holds straight
    /// colour. The streamed and the whole-image paths both read rows through here.
    pub fn row_values(&self, film: &Film, row: usize, k: usize, vals: &mut [f32]) {
        let (w, nch, c) = (film.width, film.channels(), self.src[k]);
        let px = &film.data[row * w * nch..(row + 1) * w * nch];
        match self.divide_by.get(k).copied().flatten() {
            Some(a) => {
                for (v, p) in vals.iter_mut().zip(px.chunks_exact(nch)) {
                    *v = unpremultiply(p[c], p[a]);
                }
            }
            None => {
                for (v, p) in vals.iter_mut().zip(px.chunks_exact(nch)) {
                    *v = p[c];
                }
            }
        }
    }
}

/// One PNG display being encoded.
pub struct PngStream {
    pub layout: Layout,
    width: usize,
    height: usize,
    /// Scanlines encoded so far.
    next_y: usize,
    /// The previous scanline's bytes (zeros before the first, as the PNG filters define).
    prev: Vec<u8>,
    cur: Vec<u8>,
    /// The filter type byte followed by the filtered scanline: one record of the stream.
    record: Vec<u8>,
    vals: Vec<f32>,
    q8: Vec<u8>,
    deflate: Option<fdeflate::Compressor<Vec<u8>>>,
}

impl PngStream {
    pub fn new(layout: Layout, width: usize, height: usize) -> PngStream {
        let len = width * layout.src.len();
        PngStream {
            layout,
            width,
            height,
            next_y: 0,
            prev: vec![0; len],
            cur: vec![0; len],
            record: vec![0; len + 1],
            vals: vec![0.0; width],
            q8: vec![0; width],
            // Writing to a Vec cannot fail (the header goes out at once).
            deflate: fdeflate::Compressor::new(Vec::new()).ok(),
        }
    }

    /// Encodes scanline `y` of the image, read from row `row` of `film` (the whole film, or a
    /// band of it starting at scanline `y - row`; already exposed and imaged). Scanlines must
    /// come in order.
    pub fn push(&mut self, film: &Film, row: usize, y: usize) {
        if y != self.next_y || y >= self.height || film.width != self.width || row >= film.height {
            // Out of order or the wrong film: give up; the display is written from the film.
            self.deflate = None;
            return;
        }
        let Some(z) = &mut self.deflate else { return };
        let nout = self.layout.src.len();
        // The same values and quantiser, a row and a channel at a time, as the whole-image
        // path (the dither pattern follows the image's y).
        for k in 0..nout {
            self.layout.row_values(film, row, k, &mut self.vals);
            quantize_row_u8(&self.vals, &self.layout.q, y as u32, k as u32, &mut self.q8);
            for (x, &b) in self.q8.iter().enumerate() {
                self.cur[x * nout + k] = b;
            }
        }
        self.record[0] = adaptive_filter(nout, &self.prev, &self.cur, &mut self.record[1..]);
        if z.write_data(&self.record).is_err() {
            self.deflate = None;
            return;
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.next_y += 1;
    }

    /// The image's width and height.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The zlib stream of the whole image, or None when some row is missing or the `png`
    /// crate would have stored the rows uncompressed (the caller then encodes the film).
    pub fn finish(self) -> Option<Vec<u8>> {
        if self.next_y != self.height {
            return None;
        }
        let z = self.deflate?.finish().ok()?;
        let raw = (self.width * self.layout.src.len() + 1) * self.height;
        (z.len() <= fdeflate::StoredOnlyCompressor::<()>::compressed_size(raw)).then_some(z)
    }
}

/// Filters `cur` (with `prev` the scanline above) into `out` the way the `png` crate's
/// adaptive filter does, returning the PNG filter type (1 Sub, 2 Up, 3 Avg, 4 Paeth).
pub fn adaptive_filter(bpp: usize, prev: &[u8], cur: &[u8], out: &mut [u8]) -> u8 {
    let mut best = (u64::MAX, 0u8);
    for f in [2u8, 1, 3, 4] {
        apply_filter(f, bpp, prev, cur, out);
        let cost = cost(out);
        if cost <= best.0 {
            best = (cost, f);
            if cost == 0 {
                return f;
            }
        }
    }
    if best.1 != 4 {
        apply_filter(best.1, bpp, prev, cur, out);
    }
    best.1
}

/// The sum of the bytes' magnitudes as signed numbers (in chunks the compiler vectorises).
fn cost(out: &[u8]) -> u64 {
    out.chunks(64)
        .map(|c| {
            let s: u32 = c.iter().map(|&b| u32::from((b as i8).unsigned_abs())).sum();
            u64::from(s)
        })
        .sum()
}

/// One PNG row filter (RFC 2083 §6): each byte minus its prediction from the byte `bpp` to the
/// left (a), the byte above (b) and the one above-left (c), 0 outside the row. One loop per
/// filter without branches, so each vectorises.
fn apply_filter(f: u8, bpp: usize, prev: &[u8], cur: &[u8], out: &mut [u8]) {
    let n = cur.len();
    let bpp = bpp.min(n);
    let (head, tail) = out.split_at_mut(bpp);
    // The first pixel: a = c = 0.
    for (i, o) in head.iter_mut().enumerate() {
        let b = prev[i];
        let pred = match f {
            1 => 0,
            3 => b / 2,
            _ => b, // Up, and Paeth (a = c = 0 predicts b)
        };
        *o = cur[i].wrapping_sub(pred);
    }
    let rest = cur[bpp..]
        .iter()
        .zip(&cur[..n - bpp])
        .zip(prev[bpp..].iter().zip(&prev[..n - bpp]));
    match f {
        1 => {
            for (o, ((&x, &a), _)) in tail.iter_mut().zip(rest) {
                *o = x.wrapping_sub(a);
            }
        }
        2 => {
            for (o, ((&x, _), (&b, _))) in tail.iter_mut().zip(rest) {
                *o = x.wrapping_sub(b);
            }
        }
        3 => {
            for (o, ((&x, &a), (&b, _))) in tail.iter_mut().zip(rest) {
                // ⌊(a + b) / 2⌋ without widening.
                *o = x.wrapping_sub((a & b) + ((a ^ b) >> 1));
            }
        }
        _ => {
            for (o, ((&x, &a), (&b, &c))) in tail.iter_mut().zip(rest) {
                *o = x.wrapping_sub(paeth(a, b, c));
            }
        }
    }
}

/// The Paeth predictor: of a, b, c the one nearest a + b − c, ties in that order.
#[inline]
fn paeth(a: u8, b: u8, c: u8) -> u8 {
    let (ia, ib, ic) = (i16::from(a), i16::from(b), i16::from(c));
    let (pa, pb, pc) = ((ib - ic).abs(), (ia - ic).abs(), (ia + ib - 2 * ic).abs());
    let ab = if pb < pa { b } else { a };
    if pc < pa.min(pb) {
        c
    } else {
        ab
    }
}

/// The PNG displays of a frame being streamed (`None` for displays written from the film).
#[derive(Default)]
pub struct Streams {
    pub displays: Vec<Option<PngStream>>,
    /// Exposure and the `background` imager, applied to a copy of each band before it is
    /// quantised (the options the displays are written with).
    pub prepare: Option<crate::scene::Options>,
}

impl Streams {
    /// Whether any display is streamed.
    pub fn any(&self) -> bool {
        self.displays.iter().any(Option::is_some)
    }
}

impl RowSink for Streams {
    fn rows(&mut self, film: &Film, y0: usize, y1: usize) {
        if !self.any() || y1 <= y0 {
            return;
        }
        let band;
        let (src, at) = match &self.prepare {
            Some(opts) => {
                let n = film.channels() * film.width;
                let copy = Film {
                    width: film.width,
                    height: y1 - y0,
                    channel_names: film.channel_names.clone(),
                    data: film.data[y0 * n..y1 * n].to_vec(),
                };
                band = super::output::prepared(copy, opts);
                (&band, 0)
            }
            None => (film, y0),
        };
        for d in self.displays.iter_mut().flatten() {
            for y in y0..y1 {
                d.push(src, y - y0 + at, y);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RFC 2083 §6.6 as written.
    fn paeth_reference(a: u8, b: u8, c: u8) -> u8 {
        let p = i16::from(a) + i16::from(b) - i16::from(c);
        let (pa, pb, pc) = (
            (p - i16::from(a)).abs(),
            (p - i16::from(b)).abs(),
            (p - i16::from(c)).abs(),
        );
        if pa <= pb && pa <= pc {
            a
        } else if pb <= pc {
            b
        } else {
            c
        }
    }

    #[test]
    fn paeth_is_the_reference_predictor_for_every_input() {
        for a in 0..=255u8 {
            for b in 0..=255u8 {
                for c in (0..=255u8).step_by(3) {
                    assert_eq!(paeth(a, b, c), paeth_reference(a, b, c), "{a} {b} {c}");
                }
            }
        }
    }

    #[test]
    fn filters_and_the_adaptive_choice() {
        // Two RGB pixels; the row above is a constant 10.
        let prev = [10u8; 6];
        let cur = [12u8, 14, 16, 13, 15, 17];
        let mut out = [0u8; 6];
        apply_filter(1, 3, &prev, &cur, &mut out);
        assert_eq!(out, [12, 14, 16, 1, 1, 1], "Sub");
        apply_filter(2, 3, &prev, &cur, &mut out);
        assert_eq!(out, [2, 4, 6, 3, 5, 7], "Up");
        apply_filter(3, 3, &prev, &cur, &mut out);
        assert_eq!(
            out,
            [7, 9, 11, 2, 3, 4],
            "Avg: ⌊(a + b) / 2⌋, a = 0 on the first pixel"
        );
        apply_filter(4, 3, &prev, &cur, &mut out);
        assert_eq!(
            out,
            [2, 4, 6, 1, 1, 1],
            "Paeth picks b on the first pixel, then a"
        );
        // Costs: Up 27, Sub 45, Avg 36, Paeth 15: Paeth, left in `out`.
        assert_eq!(adaptive_filter(3, &prev, &cur, &mut out), 4);
        assert_eq!(out, [2, 4, 6, 1, 1, 1]);
        // Equal to the row above: Up costs 0 and is taken at once.
        assert_eq!(adaptive_filter(3, &prev, &prev, &mut out), 2);
        assert_eq!(out, [0; 6]);
        // A tie goes to the later filter: under a zero row, Sub and Paeth both give [20, 20]
        // (cost 40; Avg 50, Up 60).
        let zero = [0u8; 2];
        assert_eq!(adaptive_filter(1, &zero, &[20, 40], &mut out[..2]), 4);
    }
}
