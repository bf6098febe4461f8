//! Small numeric helpers for hot loops.
//!
//! `f32::floor`/`ceil` compile to library calls on baseline x86-64 (no SSE4.1 `roundss`),
//! which costs the hiders and the pixel filter dozens of instructions per sample. These
//! integer versions give the same results as `x.floor() as i64` / `x.ceil() as i64` for every
//! input, NaN (0) and infinities (saturated) included.

/// `x.floor() as i64`.
#[inline(always)]
pub fn floor_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `x.ceil() as i64`.
#[inline(always)]
pub fn ceil_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) < x {
        i.saturating_add(1)
    } else {
        i
    }
}

/// `x.floor() as i32`.
#[inline(always)]
pub fn floor_i32(x: f32) -> i32 {
    floor_i64(x).clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_floor_and_ceil_match_the_library_everywhere() {
        let mut vals = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            2.999_999_8,
            -2.999_999_8,
            16_777_216.0,
            -16_777_217.0,
            1e20,
            -1e20,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
        ];
        let mut h = 0x9e37_79b9u32;
        for _ in 0..10_000 {
            h ^= h << 13;
            h ^= h >> 17;
            h ^= h << 5;
            vals.push(f32::from_bits(h));
            vals.push((h % 20_000) as f32 / 7.0 - 1400.0);
        }
        for x in vals {
            assert_eq!(floor_i64(x), x.floor() as i64, "floor {x}");
            assert_eq!(ceil_i64(x), x.ceil() as i64, "ceil {x}");
            assert_eq!(floor_i32(x), x.floor() as i32, "floor32 {x}");
        }
    }
}
