//! Deterministic hashing: the fixed permutation table used by gradient noise, and integer
//! hashes for cell noise, `random`-style per-sample numbers and terrain keys.
//!
//! Input: integers (lattice coordinates, seeds, keys). Output: `u32` hashes, floats in [0,1),
//! Gaussian deviates. Invariants: everything is a pure function of its arguments (no global
//! mutable state); the permutation is built at compile time from a fixed seed, so results are
//! identical across runs and platforms.

/// Seed of the permutation table. Changing it changes every noise value: don't.
const PERM_SEED: u64 = 0x6172_626f_725f_6e7a; // "arbor_nz"

/// SplitMix64 step (a good 64-bit mixer), usable in `const fn`.
const fn splitmix64(state: u64) -> (u64, u64) {
    let s = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = s;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (s, z ^ (z >> 31))
}

/// A Fisher–Yates shuffle of 0..=255, doubled to 512 entries so `PERM[PERM[i] + j]` with
/// `i, j <= 255` (and `+1` for the far corner) never needs a mask.
const fn make_perm(seed: u64) -> [u8; 512] {
    let mut p = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        p[i] = i as u8;
        i += 1;
    }
    let mut state = seed;
    let mut i = 255usize;
    while i > 0 {
        let (s, r) = splitmix64(state);
        state = s;
        let j = (r % (i as u64 + 1)) as usize;
        let t = p[i];
        p[i] = p[j];
        p[j] = t;
        i -= 1;
    }
    let mut out = [0u8; 512];
    let mut k = 0;
    while k < 512 {
        out[k] = p[k & 255];
        k += 1;
    }
    out
}

/// The fixed, doubled permutation table of gradient noise.
pub(crate) static PERM: [u8; 512] = make_perm(PERM_SEED);

/// Hash one 32-bit value to a well-mixed 32-bit value (an invertible xorshift-multiply mixer,
/// so distinct seeds give distinct hashes).
#[inline]
pub fn hash_u32(seed: u32) -> u32 {
    let mut x = seed;
    x ^= x >> 16;
    x = x.wrapping_mul(0x21f0_aaad);
    x ^= x >> 15;
    x = x.wrapping_mul(0x735a_2d97);
    x ^= x >> 15;
    x
}

/// Combine a running hash with one more value (order matters: `hash_combine(a, b)` is not
/// `hash_combine(b, a)`).
#[inline]
pub fn hash_combine(h: u32, v: u32) -> u32 {
    hash_u32(h ^ v.wrapping_mul(0x9E37_79B9).wrapping_add(0x7F4A_7C15))
}

/// Hash of an unordered pair: `hash_pair_sym(a, b) == hash_pair_sym(b, a)`. Used for the keys
/// of edge midpoints (terrain consistency: the key belongs to the edge, not its orientation).
#[inline]
pub fn hash_pair_sym(a: u32, b: u32) -> u32 {
    hash_u32(a.wrapping_add(b) ^ hash_u32(a ^ b).rotate_left(7))
}

/// Hash of up to four integer coordinates plus a seed.
#[inline]
pub fn hash_coords(seed: u32, c: [i32; 4]) -> u32 {
    let mut h = hash_u32(seed ^ 0x5bd1_e995);
    h = hash_combine(h, c[0] as u32);
    h = hash_combine(h, c[1] as u32);
    h = hash_combine(h, c[2] as u32);
    hash_combine(h, c[3] as u32)
}

/// Map a hash to a float uniform in [0,1): the top 24 bits, so every value is exact and < 1.
#[inline]
pub fn u32_to_unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A deterministic per-sample random number in [0,1) from a seed (the `random()` of SL, with
/// the seed made explicit: e.g. a hash of the grid index and the frame).
#[inline]
pub fn hash_float(seed: u32) -> f32 {
    u32_to_unit(hash_u32(seed))
}

/// A standard normal deviate (mean 0, variance 1) determined by `key` (Box–Muller on two
/// hashed uniforms; the first uniform is kept away from 0 so `ln` is finite).
#[inline]
pub fn hash_gaussian(key: u32) -> f32 {
    let a = hash_u32(key);
    let b = hash_u32(a ^ 0x68e3_1da4);
    let u1 = ((a >> 8) as f32 + 0.5) * (1.0 / 16_777_216.0);
    let u2 = (b >> 8) as f32 * (1.0 / 16_777_216.0);
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perm_is_a_doubled_permutation() {
        let mut seen = [false; 256];
        for i in 0..256 {
            assert!(!seen[PERM[i] as usize]);
            seen[PERM[i] as usize] = true;
            assert_eq!(PERM[i], PERM[i + 256]);
        }
        // Not the identity.
        assert!((0..256).filter(|&i| PERM[i] as usize == i).count() < 10);
    }

    #[test]
    fn hash_float_is_uniform_and_deterministic() {
        let n = 100_000u32;
        let mut sum = 0.0f64;
        let mut buckets = [0u32; 10];
        for i in 0..n {
            let v = hash_float(i);
            assert!((0.0..1.0).contains(&v));
            assert_eq!(v, hash_float(i));
            sum += v as f64;
            buckets[(v * 10.0) as usize] += 1;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.005);
        for b in buckets {
            assert!((b as f64 - 10_000.0).abs() < 400.0, "bucket {b}");
        }
    }

    #[test]
    fn symmetric_pair_hash() {
        for a in 0..50u32 {
            for b in 0..50u32 {
                assert_eq!(hash_pair_sym(a, b), hash_pair_sym(b, a));
            }
        }
        assert_ne!(hash_pair_sym(1, 2), hash_pair_sym(1, 3));
    }

    #[test]
    fn gaussian_moments() {
        let n = 100_000u32;
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for i in 0..n {
            let g = hash_gaussian(i) as f64;
            assert!(g.is_finite());
            s1 += g;
            s2 += g * g;
        }
        let mean = s1 / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!(mean.abs() < 0.02, "mean {mean}");
        assert!((var - 1.0).abs() < 0.03, "var {var}");
    }
}
