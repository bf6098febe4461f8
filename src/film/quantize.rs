//! Image operations between the pixel filter and the display: `Exposure`, the standard
//! `background` imager, and `Quantize` with dithering (RISpec §4.1.4).
//!
//! Input: a filtered [`Film`]. Output: the film changed in place (exposure, imager) or
//! quantized integer / float values per display. Invariants: exposure and the imager touch
//! only the colour channels (and alpha for the imager); quantization is deterministic — the
//! dither noise is a hash of (pixel, channel), never a global random state.

use super::resolve::Film;
use crate::scene::Quantize;

/// `Exposure gain gamma`: c ← (c·gain)^(1/gamma) on r, g, b (premultiplied, as RenderMan does).
/// Negative values (filter ringing) are clamped to 0 before a non-unit gamma.
pub fn apply_exposure(film: &mut Film, gain: f32, gamma: f32) {
    if gain == 1.0 && gamma == 1.0 {
        return;
    }
    let idx = color_channels(film);
    let n = film.channels();
    if n == 0 {
        return;
    }
    let inv_gamma = if gamma > 0.0 && gamma.is_finite() {
        1.0 / gamma
    } else {
        1.0
    };
    for px in film.data.chunks_exact_mut(n) {
        for &c in idx.iter().flatten() {
            px[c] = exposure(px[c], gain, inv_gamma);
        }
    }
}

/// One value through `Exposure` (with 1/gamma precomputed).
#[inline]
pub fn exposure(c: f32, gain: f32, inv_gamma: f32) -> f32 {
    let v = c * gain;
    if inv_gamma == 1.0 {
        v
    } else {
        v.max(0.0).powf(inv_gamma)
    }
}

/// The standard `background` imager: Ci += (1 − alpha)·background; alpha = 1.
/// (General imager shaders run later through the shading runtime; this is their plain hook.)
pub fn apply_background(film: &mut Film, color: [f32; 3]) {
    let idx = color_channels(film);
    let Some(a) = film.channel("a") else {
        return;
    };
    let n = film.channels();
    for px in film.data.chunks_exact_mut(n) {
        let t = 1.0 - px[a];
        for (k, c) in idx.iter().enumerate() {
            if let Some(c) = *c {
                px[c] += t * color[k];
            }
        }
        px[a] = 1.0;
    }
}

fn color_channels(film: &Film) -> [Option<usize>; 3] {
    [film.channel("r"), film.channel("g"), film.channel("b")]
}

/// Straight (unassociated) colour from colour `c` premultiplied by alpha `a`: c / a where
/// a > 0; 0 where nothing covers the pixel (a ≤ 0, or NaN), as there is no colour to recover.
/// a = 1 returns `c` bit for bit, so fully covered pixels keep their values.
#[inline]
pub fn unpremultiply(c: f32, a: f32) -> f32 {
    if a > 0.0 {
        c / a
    } else {
        0.0
    }
}

/// Deterministic dither noise in [−1, 1) for (x, y, channel).
#[inline]
pub fn dither_noise(x: u32, y: u32, channel: u32) -> f32 {
    // A murmur3-style finaliser over the packed coordinates.
    let mut h = x
        .wrapping_mul(0x9E37_79B1)
        .wrapping_add(y.wrapping_mul(0x85EB_CA77))
        .wrapping_add(channel.wrapping_mul(0xC2B2_AE3D))
        ^ 0x27D4_EB2F;
    h ^= h >> 16;
    h = h.wrapping_mul(0x85EB_CA6B);
    h ^= h >> 13;
    h = h.wrapping_mul(0xC2B2_AE35);
    h ^= h >> 16;
    // 24 bits → [0, 1) → [−1, 1)
    (h >> 8) as f32 * (2.0 / 16_777_216.0) - 1.0
}

/// `Quantize`: clamp(round(zero + (one − zero)·v + dither·noise), min, max). Only meaningful
/// when one ≠ 0. With zero = 0 (every RiQuantize) this is `one·v`, bit for bit.
#[inline]
pub fn quantize(v: f32, q: &Quantize, x: u32, y: u32, channel: u32) -> f32 {
    let mut t = q.zero + (q.one - q.zero) * v;
    if q.dither != 0.0 {
        t += q.dither * dither_noise(x, y, channel);
    }
    let r = round(t);
    // NaN → min; clamp keeps the range even for odd min/max orders.
    if r.is_nan() {
        return q.min;
    }
    r.max(q.min).min(q.max.max(q.min))
}

/// [`quantize`] then the 8-bit clamp and cast (`clamp(0, 255) as u8`) of the values `v` of
/// pixels x = 0, 1, … of row `y`, channel `channel`, into `out`: the same bytes, eight values
/// at a time where the CPU has AVX2 (the loop is written for the compiler to vectorise: the
/// dither hash in 32-bit lanes, the round without branches; the same IEEE operations, no
/// fused multiply-adds).
pub fn quantize_row_u8(v: &[f32], q: &Quantize, y: u32, channel: u32, out: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { quantize_row_u8_avx2(v, q, y, channel, out) };
    }
    quantize_row_u8_body(v, q, y, channel, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn quantize_row_u8_avx2(v: &[f32], q: &Quantize, y: u32, channel: u32, out: &mut [u8]) {
    quantize_row_u8_body(v, q, y, channel, out)
}

#[inline(always)]
fn quantize_row_u8_body(v: &[f32], q: &Quantize, y: u32, channel: u32, out: &mut [u8]) {
    if q.dither != 0.0 {
        let d = q.dither;
        quantize_row_with(v, q, out, |x, t| t + d * dither_noise(x, y, channel));
    } else {
        quantize_row_with(v, q, out, |_, t| t);
    }
}

/// The loop of [`quantize_row_u8`], with `noise(x, zero + scale · v)` adding the dither.
#[inline(always)]
fn quantize_row_with(v: &[f32], q: &Quantize, out: &mut [u8], noise: impl Fn(u32, f32) -> f32) {
    let (zero, scale, lo, hi) = (q.zero, q.one - q.zero, q.min, q.max.max(q.min));
    for (x, (o, &v)) in out.iter_mut().zip(v).enumerate() {
        let t = noise(x as u32, zero + scale * v);
        // [`round`], the large (already whole) and NaN values passed through unchanged.
        let i = t as i32 as f32;
        let d = t - i;
        let up = if d >= 0.5 { 1.0 } else { 0.0 };
        let down = if d <= -0.5 { 1.0 } else { 0.0 };
        let small = (i + up - down).copysign(t);
        let r = if t.abs() < 8_388_608.0 { small } else { t };
        let r = if r.is_nan() { lo } else { r.max(lo).min(hi) };
        *o = r.clamp(0.0, 255.0) as u8;
    }
}

/// `t.round()` (half away from zero) without the library call the baseline x86-64 target
/// makes for it: below 2²³ the truncating cast and the fraction are exact.
#[inline]
pub fn round(t: f32) -> f32 {
    if t.abs() < 8_388_608.0 {
        let i = t as i32 as f32;
        let d = t - i;
        // Branch-free: the fraction is random under dither.
        let up = if d >= 0.5 { 1.0 } else { 0.0 };
        let down = if d <= -0.5 { 1.0 } else { 0.0 };
        (i + up - down).copysign(t)
    } else {
        t.round()
    }
}

/// True when the quantizer asks for float output (one = 0, RISpec).
pub fn is_float(q: &Quantize) -> bool {
    q.one == 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgba_film(vals: &[[f32; 5]]) -> Film {
        let mut f = Film::new(vals.len(), 1, Film::standard_channels(&[]));
        for (i, v) in vals.iter().enumerate() {
            f.pixel_mut(i, 0).copy_from_slice(v);
        }
        f
    }

    #[test]
    fn the_row_quantiser_gives_the_bytes_of_quantize() {
        let mut k = 7u32;
        let mut vals: Vec<f32> = (0..1000)
            .map(|_| {
                k = k.wrapping_mul(747796405).wrapping_add(2891336453);
                (k >> 8) as f32 / (1u32 << 24) as f32 * 1.4 - 0.2
            })
            .collect();
        vals.extend([
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            0.0,
            1e30,
            -1e30,
            0.5 / 255.0,
            1.5 / 255.0,
            -0.5 / 255.0,
        ]);
        let rgba = Quantize {
            zero: 0.0,
            one: 255.0,
            min: 0.0,
            max: 255.0,
            dither: 0.5,
        };
        let qs = [
            rgba,
            Quantize {
                dither: 0.0,
                ..rgba
            },
            Quantize {
                zero: 0.0,
                one: 255.0,
                min: 10.0,
                max: 200.0,
                dither: 2.0,
            },
            Quantize {
                zero: 0.0,
                one: 255.0,
                min: 300.0,
                max: 100.0,
                dither: 0.5,
            }, // A display's [zero one min max] (normals: −1..1 into 1..255).
            Quantize {
                zero: 128.0,
                one: 255.0,
                min: 0.0,
                max: 255.0,
                dither: 0.5,
            },
        ];
        for q in qs {
            for (y, ch) in [(0, 0), (17, 2), (959, 3)] {
                let mut got = vec![0u8; vals.len()];
                quantize_row_u8(&vals, &q, y, ch, &mut got);
                let mut portable = vec![0u8; vals.len()];
                quantize_row_u8_body(&vals, &q, y, ch, &mut portable);
                for (x, &v) in vals.iter().enumerate() {
                    let want = quantize(v, &q, x as u32, y, ch).clamp(0.0, 255.0) as u8;
                    assert_eq!(got[x], want, "{q:?} value {v} at x {x}");
                    assert_eq!(portable[x], want, "{q:?} value {v} at x {x}");
                }
            }
        }
    }

    #[test]
    fn round_is_the_library_round() {
        let mut k = 1u32;
        let mut vals = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -2.5,
            0.49999997,
            -0.49999997,
            8388607.5,
            8388608.0,
            -8388609.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e30,
            -1e-30,
            254.5,
            255.49998,
        ];
        for _ in 0..100_000 {
            k = k.wrapping_mul(747796405).wrapping_add(2891336453);
            vals.push(f32::from_bits(k));
            vals.push((k >> 8) as f32 / 65536.0 - 128.0);
        }
        for v in vals {
            let (a, b) = (round(v), v.round());
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{v}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn unpremultiply_recovers_straight_colour() {
        assert_eq!(unpremultiply(0.5, 0.5), 1.0);
        assert_eq!(unpremultiply(0.25, 0.5), 0.5);
        assert_eq!(
            unpremultiply(0.3, 1.0).to_bits(),
            0.3f32.to_bits(),
            "a = 1: unchanged"
        );
        assert_eq!(unpremultiply(0.2, 0.0), 0.0, "uncovered: no colour");
        assert_eq!(
            unpremultiply(0.2, -0.01),
            0.0,
            "negative alpha (filter ringing)"
        );
        assert_eq!(unpremultiply(0.2, f32::NAN), 0.0);
        // Over-bright straight colour is left for the quantizer's clamp.
        assert_eq!(unpremultiply(0.5, 0.25), 2.0);
    }

    #[test]
    fn exposure_gain_and_gamma() {
        let mut f = rgba_film(&[[0.25, 0.5, 1.0, 0.5, 3.0]]);
        apply_exposure(&mut f, 2.0, 2.0);
        let p = f.pixel(0, 0);
        assert!((p[0] - 0.5f32.sqrt()).abs() < 1e-6);
        assert!((p[1] - 1.0).abs() < 1e-6);
        assert!((p[2] - 2.0f32.sqrt()).abs() < 1e-6);
        assert_eq!(p[3], 0.5, "alpha untouched");
        assert_eq!(p[4], 3.0, "depth untouched");
        // gamma 1: pure gain, negatives kept
        let mut f = rgba_film(&[[-0.1, 0.5, 0.0, 1.0, 1.0]]);
        apply_exposure(&mut f, 3.0, 1.0);
        assert!((f.pixel(0, 0)[0] + 0.3).abs() < 1e-6);
        assert!((f.pixel(0, 0)[1] - 1.5).abs() < 1e-6);
    }

    #[test]
    fn background_imager_composites_under() {
        let mut f = rgba_film(&[[0.2, 0.1, 0.0, 0.25, 1.0], [0.0, 0.0, 0.0, 0.0, 1.0]]);
        apply_background(&mut f, [0.4, 0.8, 1.0]);
        let p = f.pixel(0, 0);
        assert!((p[0] - (0.2 + 0.75 * 0.4)).abs() < 1e-6);
        assert!((p[1] - (0.1 + 0.75 * 0.8)).abs() < 1e-6);
        assert!((p[2] - 0.75).abs() < 1e-6);
        assert_eq!(p[3], 1.0);
        assert_eq!(&f.pixel(1, 0)[..4], &[0.4, 0.8, 1.0, 1.0]);
    }

    #[test]
    fn dither_noise_range_and_mean() {
        let mut sum = 0.0f64;
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        let n = 256 * 256;
        for y in 0..256 {
            for x in 0..256 {
                let v = dither_noise(x, y, 1);
                lo = lo.min(v);
                hi = hi.max(v);
                sum += v as f64;
            }
        }
        assert!(lo >= -1.0 && hi < 1.0);
        assert!(lo < -0.99 && hi > 0.99, "covers the range");
        assert!((sum / n as f64).abs() < 0.01, "zero mean");
        assert_eq!(dither_noise(3, 4, 0), dither_noise(3, 4, 0));
        assert_ne!(dither_noise(3, 4, 0), dither_noise(4, 3, 0));
    }

    #[test]
    fn quantize_bounds_and_dither() {
        let q = Quantize {
            zero: 0.0,
            one: 255.0,
            min: 0.0,
            max: 255.0,
            dither: 0.5,
        };
        for y in 0..64 {
            for x in 0..64 {
                for &v in &[-1.0f32, 0.0, 0.5, 1.0, 7.0, f32::NAN] {
                    let r = quantize(v, &q, x, y, 0);
                    assert!((0.0..=255.0).contains(&r));
                    assert_eq!(r, r.round());
                }
                // dither 0.5 moves a value by at most one step
                let r = quantize(0.5, &q, x, y, 2);
                assert!(r == 127.0 || r == 128.0, "{r}");
                assert_eq!(quantize(1.0, &q, x, y, 0), 255.0);
                assert_eq!(quantize(0.0, &q, x, y, 0), 0.0);
            }
        }
        let nd = Quantize { dither: 0.0, ..q };
        assert_eq!(quantize(0.2, &nd, 0, 0, 0), 51.0);
        let centred = Quantize { zero: 128.0, ..nd };
        assert_eq!(quantize(-1.0, &centred, 0, 0, 0), 1.0);
        assert_eq!(quantize(0.0, &centred, 0, 0, 0), 128.0);
        assert_eq!(quantize(1.0, &centred, 0, 0, 0), 255.0);
        assert_eq!(
            quantize(0.5, &nd, 0, 0, 0),
            128.0,
            "round half away from zero"
        );
        // Dithering preserves the mean of a mid-level value.
        let mut s = 0.0;
        for x in 0..1000 {
            s += quantize(0.3 / 255.0 + 100.0 / 255.0, &q, x, 7, 0) as f64;
        }
        assert!((s / 1000.0 - 100.3).abs() < 0.06, "{}", s / 1000.0);
    }
}
