//! Summed-area tables (Crow 1984; book §4.7.2): box-filtered texture averages over any
//! axis-aligned rectangle in O(1).
//!
//! Input: one level of a texture as an [`Image`] and its wrap modes. Output: [`Sat`], whose
//! [`Sat::average`] answers the mean texel value over a rectangle in texture units.
//! Invariants:
//! * sums are f64 prefix sums over (width+1)×(height+1) corners (row/column 0 are zero), so
//!   a 4096² map of values near 1 keeps ~1e-9 relative precision in a difference of two
//!   sums — f32 sums would lose everything past ~2²⁴/texels;
//! * the integral to a fractional corner interpolates the table bilinearly, which is exact
//!   for the piecewise-constant texture (∂²I/∂x∂y is constant in each texel), so rectangles
//!   need not align with texels;
//! * outside [0,1] the wrap modes hold exactly: periodic repeats, clamp extends the edge
//!   texels (integrals of the edge row/column), black adds nothing but still counts in the
//!   area, so edges fade to black as in the other filters;
//! * weights are the rectangle's area, so a constant texture returns its constant.
//!
//! The footprint's rectangle is the axis-aligned bounding box of the lookup's parallelogram
//! (plus blur), at least one texel wide (so magnified lookups equal bilinear
//! interpolation). Oblique footprints therefore over-blur along their minor axis: that is
//! the SAT's known trade of quality for constant cost.

use super::filter::Footprint;
use super::image_in::Image;
use super::mipmap::Wrap;

/// A summed-area table of one texture level.
pub struct Sat {
    pub width: usize,
    pub height: usize,
    pub nchan: usize,
    /// The pyramid level it was built from (0 unless memory forced a coarser one).
    pub level: usize,
    swrap: Wrap,
    twrap: Wrap,
    /// S[y][x][c] = Σ texels x' < x, y' < y; (width+1) × (height+1) × nchan.
    sums: Vec<f64>,
}

/// Up to three (coefficient, position) terms: ∫₀ˣ g = Σ coef · G(position), where G is the
/// prefix integral inside [0, len].
type Terms = ([(f64, f64); 3], usize);

fn axis_terms(x: f64, len: usize, wrap: Wrap) -> Terms {
    let l = len as f64;
    let mut t = [(0.0, 0.0); 3];
    match wrap {
        Wrap::Periodic => {
            let q = (x / l).floor();
            t[0] = (q, l);
            t[1] = (1.0, x - q * l);
            (t, 2)
        }
        Wrap::Black => {
            t[0] = (1.0, x.clamp(0.0, l));
            (t, 1)
        }
        Wrap::Clamp => {
            let xa = x.clamp(0.0, l);
            let ex = x - xa;
            t[0] = (1.0, xa);
            if ex == 0.0 {
                return (t, 1);
            }
            // Past an edge the edge texel e repeats: ex · g(e) = ex · (G(e+1) − G(e)).
            let e = if ex > 0.0 { l - 1.0 } else { 0.0 };
            t[1] = (ex, e + 1.0);
            t[2] = (-ex, e);
            (t, 3)
        }
    }
}

impl Sat {
    /// The table of `im` (a level of a map with these wrap modes).
    pub fn build(im: &Image, swrap: Wrap, twrap: Wrap, level: usize) -> Sat {
        let (w, h, nc) = (im.width, im.height, im.nchan);
        let row = (w + 1) * nc;
        let mut sums = vec![0f64; row * (h + 1)];
        let mut run = vec![0f64; nc];
        for y in 0..h {
            run.iter_mut().for_each(|r| *r = 0.0);
            let (above, here) = sums.split_at_mut((y + 1) * row);
            let above = &above[y * row..];
            let here = &mut here[..row];
            for x in 0..w {
                let px = im.px(x, y);
                let o = (x + 1) * nc;
                for c in 0..nc {
                    run[c] += px[c] as f64;
                    here[o + c] = above[o + c] + run[c];
                }
            }
        }
        Sat {
            width: w,
            height: h,
            nchan: nc,
            level,
            swrap,
            twrap,
            sums,
        }
    }

    /// Bytes a table for a w × h × nchan level takes.
    pub fn bytes_for(w: usize, h: usize, nchan: usize) -> usize {
        (w + 1) * (h + 1) * nchan * 8
    }

    /// acc += k · G(x, y) for channels [first, first + acc.len()), x ∈ [0, w], y ∈ [0, h].
    #[inline]
    fn prefix(&self, x: f64, y: f64, k: f64, first: usize, acc: &mut [f64]) {
        let nc = self.nchan;
        let ix = (x.floor().max(0.0) as usize).min(self.width.saturating_sub(1));
        let iy = (y.floor().max(0.0) as usize).min(self.height.saturating_sub(1));
        let (fx, fy) = (x - ix as f64, y - iy as f64);
        let row = (self.width + 1) * nc;
        let b = iy * row + ix * nc;
        let s = &self.sums;
        let (w00, w10) = ((1.0 - fx) * (1.0 - fy) * k, fx * (1.0 - fy) * k);
        let (w01, w11) = ((1.0 - fx) * fy * k, fx * fy * k);
        for (c, a) in acc.iter_mut().enumerate() {
            let i = b + first + c;
            *a += w00 * s[i] + w10 * s[i + nc] + w01 * s[i + row] + w11 * s[i + row + nc];
        }
    }

    /// acc += k · ∫∫ over [0, x] × [0, y] (texel units, any signs), wrap modes applied.
    fn integral(&self, x: f64, y: f64, k: f64, first: usize, acc: &mut [f64]) {
        let (tx, nx) = axis_terms(x, self.width, self.swrap);
        let (ty, ny) = axis_terms(y, self.height, self.twrap);
        for &(cy, py) in &ty[..ny] {
            for &(cx, px) in &tx[..nx] {
                self.prefix(px, py, k * cx * cy, first, acc);
            }
        }
    }

    /// Mean of channels [first, first + out.len()) over [x0, x1] × [y0, y1] (texel units of
    /// this level, x0 < x1, y0 < y1). Channels past the table's are not written.
    pub fn rect_mean(&self, x0: f64, x1: f64, y0: f64, y1: f64, first: usize, out: &mut [f32]) {
        let have = self.nchan.saturating_sub(first).min(out.len()).min(16);
        let mut acc = [0f64; 16];
        let acc = &mut acc[..have];
        // Periodic: move the rectangle next to the origin (keeps the sums small).
        let shift = |v0: f64, len: usize, wrap: Wrap| {
            if wrap == Wrap::Periodic {
                (v0 / len as f64).floor() * len as f64
            } else {
                0.0
            }
        };
        let (sx, sy) = (
            shift(x0, self.width, self.swrap),
            shift(y0, self.height, self.twrap),
        );
        let (x0, x1, y0, y1) = (x0 - sx, x1 - sx, y0 - sy, y1 - sy);
        self.integral(x1, y1, 1.0, first, acc);
        self.integral(x0, y1, -1.0, first, acc);
        self.integral(x1, y0, -1.0, first, acc);
        self.integral(x0, y0, 1.0, first, acc);
        let area = (x1 - x0) * (y1 - y0);
        if !(area > 0.0) {
            return;
        }
        for (o, a) in out.iter_mut().zip(acc.iter()) {
            *o = (a / area) as f32;
        }
    }

    /// The box-filtered average over a footprint's bounding rectangle (blur widens it, one
    /// texel at least) into `out` (channels from `first`).
    pub fn lookup(&self, fp: &Footprint, sblur: f32, tblur: f32, first: usize, out: &mut [f32]) {
        let (w, h) = (self.width as f64, self.height as f64);
        let hs = 0.5 * ((fp.ds1.abs() + fp.ds2.abs()) as f64 + sblur.max(0.0) as f64);
        let ht = 0.5 * ((fp.dt1.abs() + fp.dt2.abs()) as f64 + tblur.max(0.0) as f64);
        let hx = (hs * w).max(0.5);
        let hy = (ht * h).max(0.5);
        let (cx, cy) = (fp.s as f64 * w, fp.t as f64 * h);
        if !(cx.is_finite() && cy.is_finite() && hx.is_finite() && hy.is_finite()) {
            return;
        }
        // Wider than a few repeats: the periodic mean (or less) is all that is left.
        let hx = hx.min(4.0 * w);
        let hy = hy.min(4.0 * h);
        self.rect_mean(cx - hx, cx + hx, cy - hy, cy + hy, first, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force mean of the piecewise-constant, wrapped texture over a rectangle: every
    /// covered texel weighted by its overlap.
    fn brute(im: &Image, sw: Wrap, tw: Wrap, r: [f64; 4], c: usize) -> f64 {
        let mut sum = 0.0;
        for j in r[2].floor() as i64..r[3].ceil() as i64 {
            let oy = r[3].min(j as f64 + 1.0) - r[2].max(j as f64);
            for i in r[0].floor() as i64..r[1].ceil() as i64 {
                let ox = r[1].min(i as f64 + 1.0) - r[0].max(i as f64);
                if let (Some(xi), Some(yi)) = (sw.index(i, im.width), tw.index(j, im.height)) {
                    sum += ox * oy * im.px(xi, yi)[c] as f64;
                }
            }
        }
        sum / ((r[1] - r[0]) * (r[3] - r[2]))
    }

    fn noise_image(w: usize, h: usize, nc: usize) -> Image {
        let mut im = Image::new(w, h, nc);
        let mut x = 12345u32;
        for v in im.data.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *v = (x % 1000) as f32 / 1000.0;
        }
        im
    }

    #[test]
    fn rectangle_means_equal_brute_force_in_every_wrap_mode() {
        let im = noise_image(13, 7, 2);
        // Texel-aligned, fractional, straddling edges, far outside, wider than the map.
        let rects = [
            [2.0, 5.0, 1.0, 4.0],
            [0.0, 13.0, 0.0, 7.0],
            [1.3, 7.9, 2.25, 2.75],
            [-2.5, 3.5, -1.2, 2.0],
            [11.0, 16.0, 5.5, 9.0],
            [-30.2, -27.1, 15.0, 18.4],
            [-5.0, 25.0, -3.0, 12.0],
        ];
        for (sw, tw) in [
            (Wrap::Periodic, Wrap::Periodic),
            (Wrap::Clamp, Wrap::Clamp),
            (Wrap::Black, Wrap::Black),
            (Wrap::Periodic, Wrap::Clamp),
            (Wrap::Clamp, Wrap::Black),
        ] {
            let sat = Sat::build(&im, sw, tw, 0);
            for r in rects {
                let mut out = [0f32; 2];
                sat.rect_mean(r[0], r[1], r[2], r[3], 0, &mut out);
                for c in 0..2 {
                    let want = brute(&im, sw, tw, r, c);
                    assert!(
                        (out[c] as f64 - want).abs() < 1e-5,
                        "{sw:?}/{tw:?} {r:?} channel {c}: {} vs {want}",
                        out[c]
                    );
                }
                // Channel selection: the second channel alone.
                let mut one = [0f32; 1];
                sat.rect_mean(r[0], r[1], r[2], r[3], 1, &mut one);
                assert!((one[0] - out[1]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn constants_survive_and_magnification_is_bilinear() {
        let mut im = Image::new(64, 32, 3);
        for px in im.data.chunks_mut(3) {
            px.copy_from_slice(&[0.2, 0.4, 0.8]);
        }
        for wrap in [Wrap::Periodic, Wrap::Clamp] {
            let sat = Sat::build(&im, wrap, wrap, 0);
            for fp in [
                Footprint {
                    s: 0.5,
                    t: 0.5,
                    ..Default::default()
                },
                Footprint {
                    s: 0.01,
                    t: 0.99,
                    ds1: 0.3,
                    dt1: 0.1,
                    ds2: -0.05,
                    dt2: 0.7,
                },
                Footprint {
                    s: -7.3,
                    t: 3.1,
                    ds1: 9.0,
                    dt1: 0.0,
                    ds2: 0.0,
                    dt2: 9.0,
                },
            ] {
                let mut out = [0f32; 3];
                sat.lookup(&fp, 0.1, 0.0, 0, &mut out);
                for (c, want) in [0.2f32, 0.4, 0.8].iter().enumerate() {
                    assert!((out[c] - want).abs() < 1e-5, "{wrap:?} {fp:?}: {out:?}");
                }
            }
        }
        // A 1-texel box between two texel centres is their linear interpolation.
        let mut ramp = Image::new(4, 1, 1);
        ramp.data.copy_from_slice(&[0.0, 1.0, 2.0, 3.0]);
        let sat = Sat::build(&ramp, Wrap::Clamp, Wrap::Clamp, 0);
        let fp = Footprint {
            s: 1.8 / 4.0,
            t: 0.5,
            ..Default::default()
        };
        let mut out = [0f32];
        sat.lookup(&fp, 0.0, 0.0, 0, &mut out);
        assert!((out[0] - 1.3).abs() < 1e-5, "{out:?}");
    }

    #[test]
    fn large_maps_keep_precision() {
        // 2048² of values near 1: a one-texel rectangle deep in the table is still exact.
        let n = 2048;
        let mut im = Image::new(n, n, 1);
        im.data
            .iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = 1.0 + (i % 7) as f32 * 1e-3);
        let sat = Sat::build(&im, Wrap::Periodic, Wrap::Periodic, 0);
        let (x, y) = (2000usize, 2040usize);
        let mut out = [0f32];
        sat.rect_mean(
            x as f64,
            x as f64 + 1.0,
            y as f64,
            y as f64 + 1.0,
            0,
            &mut out,
        );
        assert!(
            (out[0] - im.px(x, y)[0]).abs() < 1e-6,
            "{} vs {}",
            out[0],
            im.px(x, y)[0]
        );
    }
}
