//! Sample positions: stratified jittered samples per pixel, every random number a hash.
//!
//! Input: a pixel, its stratum, the samples per pixel and a seed. Output: a raster position.
//! Invariants: the position of sample (pixel, stratum) depends only on those and the seed —
//! never on the bucket or thread — so renders are identical whatever the bucket layout.

/// A 64-bit finaliser (splitmix64): a well-mixed hash of its input.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of (pixel, sample, seed) for stream `k`.
#[inline]
pub fn hash(px: i32, py: i32, sample: u32, seed: u64, k: u64) -> u64 {
    let a = ((px as u32 as u64) << 32) | py as u32 as u64;
    mix64(mix64(mix64(a ^ seed.rotate_left(17)) ^ sample as u64) ^ k)
}

/// A uniform number in [0, 1) from a hash.
#[inline]
pub fn unit(h: u64) -> f32 {
    // 24 high bits: exactly representable, strictly below 1.
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// Raster position of stratum (sx, sy) of pixel (px, py) with `xs × ys` strata: jittered
/// uniformly inside the stratum, or its centre when `jitter` is false.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn sample_position(
    px: i32,
    py: i32,
    sx: usize,
    sy: usize,
    xs: usize,
    ys: usize,
    jitter: bool,
    seed: u64,
) -> [f32; 2] {
    let (jx, jy) = if jitter {
        let s = (sy * xs + sx) as u32;
        (
            unit(hash(px, py, s, seed, 1)),
            unit(hash(px, py, s, seed, 2)),
        )
    } else {
        (0.5, 0.5)
    };
    [
        px as f32 + (sx as f32 + jx) / xs as f32,
        py as f32 + (sy as f32 + jy) / ys as f32,
    ]
}

/// Appends the positions of every stratum of pixel (px, py), rows of `xs` strata, to `out`:
/// the same values as [`sample_position`], with the hash's per-pixel and per-sample stages
/// computed once (3 mixes per sample instead of 6).
#[inline]
pub fn pixel_positions(
    px: i32,
    py: i32,
    [xs, ys]: [usize; 2],
    jitter: bool,
    seed: u64,
    out: &mut Vec<[f32; 2]>,
) {
    let a = ((px as u32 as u64) << 32) | py as u32 as u64;
    let h0 = mix64(a ^ seed.rotate_left(17));
    let (fx, fy) = (xs as f32, ys as f32);
    for sy in 0..ys {
        for sx in 0..xs {
            let (jx, jy) = if jitter {
                let h1 = mix64(h0 ^ (sy * xs + sx) as u64);
                (unit(mix64(h1 ^ 1)), unit(mix64(h1 ^ 2)))
            } else {
                (0.5, 0.5)
            };
            out.push([
                px as f32 + (sx as f32 + jx) / fx,
                py as f32 + (sy as f32 + jy) / fy,
            ]);
        }
    }
}

/// [`pixel_positions`] into separate x and y arrays (`xs·ys` values each, rows of `xs`
/// strata): the same bits, the hashes of four samples at a time where the CPU has AVX2.
pub fn pixel_positions_xy(
    px: i32,
    py: i32,
    [xs, ys]: [usize; 2],
    jitter: bool,
    seed: u64,
    out_x: &mut [f32],
    out_y: &mut [f32],
) {
    let n = xs * ys;
    let a = ((px as u32 as u64) << 32) | py as u32 as u64;
    let h0 = mix64(a ^ seed.rotate_left(17));
    #[cfg(target_arch = "x86_64")]
    if jitter && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        unsafe { avx2::jitter(h0, n, &mut out_x[..n], &mut out_y[..n]) };
        let (fx, fy) = (xs as f32, ys as f32);
        for sy in 0..ys {
            for sx in 0..xs {
                let k = sy * xs + sx;
                out_x[k] = px as f32 + (sx as f32 + out_x[k]) / fx;
                out_y[k] = py as f32 + (sy as f32 + out_y[k]) / fy;
            }
        }
        return;
    }
    let mut tmp = Vec::with_capacity(n);
    pixel_positions(px, py, [xs, ys], jitter, seed, &mut tmp);
    for (k, p) in tmp.iter().enumerate() {
        out_x[k] = p[0];
        out_y[k] = p[1];
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    /// The low 64 bits of a · c for four u64 lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn mul64(a: __m256i, c: u64) -> __m256i {
        let (lo, hi) = (
            _mm256_set1_epi64x(c as i64),
            _mm256_set1_epi64x((c >> 32) as i64),
        );
        let ll = _mm256_mul_epu32(a, lo);
        let hl = _mm256_mul_epu32(_mm256_srli_epi64::<32>(a), lo);
        let lh = _mm256_mul_epu32(a, hi);
        _mm256_add_epi64(ll, _mm256_slli_epi64::<32>(_mm256_add_epi64(hl, lh)))
    }

    /// [`super::mix64`] of four lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn mix64(z: __m256i) -> __m256i {
        let z = _mm256_add_epi64(z, _mm256_set1_epi64x(0x9E37_79B9_7F4A_7C15u64 as i64));
        let z = mul64(
            _mm256_xor_si256(z, _mm256_srli_epi64::<30>(z)),
            0xBF58_476D_1CE4_E5B9,
        );
        let z = mul64(
            _mm256_xor_si256(z, _mm256_srli_epi64::<27>(z)),
            0x94D0_49BB_1331_11EB,
        );
        _mm256_xor_si256(z, _mm256_srli_epi64::<31>(z))
    }

    /// [`super::unit`] of four lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn unit(h: __m256i) -> __m128 {
        let top = _mm256_srli_epi64::<40>(h);
        let packed = _mm256_permutevar8x32_epi32(top, _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6));
        let i = _mm256_castsi256_si128(packed);
        _mm_mul_ps(_mm_cvtepi32_ps(i), _mm_set1_ps(1.0 / (1u64 << 24) as f32))
    }

    /// The jitter (jx, jy) of samples 0..n of the pixel whose hash is `h0`.
    #[target_feature(enable = "avx2")]
    pub(super) fn jitter(h0: u64, n: usize, jx: &mut [f32], jy: &mut [f32]) {
        let mut k = 0;
        while k < n {
            let idx = _mm256_setr_epi64x(k as i64, k as i64 + 1, k as i64 + 2, k as i64 + 3);
            let h1 = mix64(_mm256_xor_si256(_mm256_set1_epi64x(h0 as i64), idx));
            let x = unit(mix64(_mm256_xor_si256(h1, _mm256_set1_epi64x(1))));
            let y = unit(mix64(_mm256_xor_si256(h1, _mm256_set1_epi64x(2))));
            if k + 4 <= n {
                // SAFETY: four floats from k < n - 3.
                unsafe {
                    _mm_storeu_ps(jx.as_mut_ptr().add(k), x);
                    _mm_storeu_ps(jy.as_mut_ptr().add(k), y);
                }
            } else {
                let (mut bx, mut by) = ([0f32; 4], [0f32; 4]);
                // SAFETY: four floats each.
                unsafe {
                    _mm_storeu_ps(bx.as_mut_ptr(), x);
                    _mm_storeu_ps(by.as_mut_ptr(), y);
                }
                for m in 0..n - k {
                    jx[k + m] = bx[m];
                    jy[k + m] = by[m];
                }
            }
            k += 4;
        }
    }
}

/// Shirley and Chiu's concentric map from the unit square to the unit disk (strata stay
/// compact, so stratified lens samples stay stratified).
#[inline]
pub fn concentric_disk(u: f32, v: f32) -> [f32; 2] {
    let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    if a == 0.0 && b == 0.0 {
        return [0.0, 0.0];
    }
    let q = std::f32::consts::FRAC_PI_4;
    let (r, phi) = if a.abs() > b.abs() {
        (a, q * (b / a))
    } else {
        (b, 2.0 * q - q * (a / b))
    };
    [r * phi.cos(), r * phi.sin()]
}

/// A permutation of `0..n` for pixel (px, py), stream `k` (Fisher–Yates on hashes).
fn permutation(px: i32, py: i32, n: usize, seed: u64, k: u64, out: &mut Vec<u32>) {
    out.clear();
    out.extend(0..n as u32);
    for i in (1..n).rev() {
        let j = (hash(px, py, i as u32, seed, k) % (i as u64 + 1)) as usize;
        out.swap(i, j);
    }
}

/// The shutter time (0…1) and lens position (unit disk) of each of the `xs × ys` samples of
/// pixel (px, py), appended to `times` and `lens`. Both are stratified over the pixel's
/// samples — sample s takes time stratum π(s) and lens stratum σ(s) for two hashed
/// permutations π, σ — so time, lens and image position are decorrelated, and each depends
/// only on (pixel, sample, seed).
#[allow(clippy::too_many_arguments)]
pub fn time_and_lens(
    px: i32,
    py: i32,
    xs: usize,
    ys: usize,
    jitter: bool,
    seed: u64,
    perm: &mut Vec<u32>,
    times: &mut Vec<f32>,
    lens: &mut Vec<[f32; 2]>,
) {
    let n = xs * ys;
    let j = |s: usize, k: u64| {
        if jitter {
            unit(hash(px, py, s as u32, seed, k))
        } else {
            0.5
        }
    };
    permutation(px, py, n, seed, 7, perm);
    for s in 0..n {
        times.push((perm[s] as f32 + j(s, 3)) / n as f32);
    }
    permutation(px, py, n, seed, 8, perm);
    for s in 0..n {
        let c = perm[s] as usize;
        let (cx, cy) = (c % xs, c / xs);
        let u = (cx as f32 + j(s, 4)) / xs as f32;
        let v = (cy as f32 + j(s, 5)) / ys as f32;
        lens.push(concentric_disk(u, v));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_and_lens_are_stratified() {
        let (mut perm, mut t, mut l) = (Vec::new(), Vec::new(), Vec::new());
        time_and_lens(3, 4, 4, 4, true, 11, &mut perm, &mut t, &mut l);
        let mut strata: Vec<usize> = t.iter().map(|&x| (x * 16.0) as usize).collect();
        strata.sort();
        assert_eq!(strata, (0..16).collect::<Vec<_>>());
        assert!(l.iter().all(|p| p[0] * p[0] + p[1] * p[1] <= 1.0 + 1e-5));
        // The concentric map keeps area: the mean of |p|² over the disk is 1/2.
        let n = 64;
        let mut m = 0.0;
        for i in 0..n {
            for j in 0..n {
                let p = concentric_disk((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                m += p[0] * p[0] + p[1] * p[1];
            }
        }
        assert!((m / (n * n) as f32 - 0.5).abs() < 0.01);
    }

    #[test]
    fn soa_positions_match_the_reference_bits() {
        for (px, py, spp) in [
            (0, 0, [4, 4]),
            (-7, 1000, [3, 5]),
            (123, 45, [1, 1]),
            (9, 9, [8, 8]),
        ] {
            for jitter in [true, false] {
                let mut v = Vec::new();
                pixel_positions(px, py, spp, jitter, 77, &mut v);
                let n = spp[0] * spp[1];
                let (mut x, mut y) = (vec![0f32; n], vec![0f32; n]);
                pixel_positions_xy(px, py, spp, jitter, 77, &mut x, &mut y);
                for k in 0..n {
                    assert_eq!(v[k][0].to_bits(), x[k].to_bits());
                    assert_eq!(v[k][1].to_bits(), y[k].to_bits());
                    let (sx, sy) = (k % spp[0], k / spp[0]);
                    assert_eq!(
                        v[k],
                        sample_position(px, py, sx, sy, spp[0], spp[1], jitter, 77)
                    );
                }
            }
        }
    }

    #[test]
    fn jittered_samples_stay_in_their_strata() {
        for (px, py) in [(0, 0), (7, -3), (1000, 20)] {
            for sy in 0..4 {
                for sx in 0..4 {
                    let [x, y] = sample_position(px, py, sx, sy, 4, 4, true, 9);
                    let (fx, fy) = (x - px as f32, y - py as f32);
                    assert!(fx >= sx as f32 / 4.0 && fx < (sx + 1) as f32 / 4.0, "{fx}");
                    assert!(fy >= sy as f32 / 4.0 && fy < (sy + 1) as f32 / 4.0, "{fy}");
                }
            }
        }
        assert_eq!(sample_position(2, 3, 1, 0, 2, 2, false, 0), [2.75, 3.25]);
    }

    #[test]
    fn pixel_positions_match_sample_position() {
        for &(xs, ys) in &[(4usize, 4usize), (3, 2), (1, 1)] {
            for &jitter in &[true, false] {
                for (px, py) in [(0, 0), (-3, 7), (1279, 959)] {
                    let mut v = Vec::new();
                    pixel_positions(px, py, [xs, ys], jitter, 0xabcdef, &mut v);
                    let mut k = 0;
                    for sy in 0..ys {
                        for sx in 0..xs {
                            let p = sample_position(px, py, sx, sy, xs, ys, jitter, 0xabcdef);
                            assert_eq!(v[k], p);
                            k += 1;
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn jitter_is_uniform_on_average() {
        let n = 20000;
        let mean: f64 = (0..n)
            .map(|i| unit(hash(i, i / 7, 3, 1, 1)) as f64)
            .sum::<f64>()
            / n as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
    }
}
