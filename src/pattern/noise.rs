//! Perlin gradient noise in 1–4 dimensions with RenderMan conventions, periodic noise and cell
//! noise; scalar forms, 3-channel vector forms and batch forms over slices.
//!
//! Input: points (f32 / `Vec3` / `Vec3` + time), integer periods for `pnoise`.
//! Output: `noise*` in [0,1] with mean 0.5 (exactly 0.5 on the integer lattice); `snoise*` =
//! `2·noise − 1` in [−1,1]; `cellnoise*` uniform in [0,1), constant on each integer cell.
//! Invariants: deterministic (fixed compile-time permutation, no global state); the quintic
//! fade `6t⁵ − 15t⁴ + 10t³` makes the value C² across cell faces; gradient sets are symmetric
//! under the lattice's reflections (12 cube-edge vectors in 3-D, 32 tesseract-edge vectors in
//! 4-D, 16 evenly spaced unit directions in 2-D), which avoids the axis-aligned streaks of
//! value noise (notes §3.3). The vector channels hash shifted lattices, so they are
//! decorrelated yet each is still 0.5 on the lattice. Slices of unequal length are processed
//! up to the shorter one (never a panic).

use glam::{IVec3, Vec3};

use super::hash::{hash_coords, u32_to_unit, PERM};

// ---------------------------------------------------------------------------------------------
// Lattice helpers
// ---------------------------------------------------------------------------------------------

/// `floor` as an integer without a libm call (f32→i32 truncation, corrected for negatives).
/// Out-of-range values saturate, which only wraps the pattern far from the origin.
#[inline(always)]
pub(crate) fn fast_floor(x: f32) -> i32 {
    let i = x as i32;
    i.wrapping_sub((x < i as f32) as i32)
}

/// Perlin's quintic fade: 0 and 1 at the ends with zero first and second derivatives.
#[inline(always)]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline(always)]
fn lerp(t: f32, a: f32, b: f32) -> f32 {
    a + t * (b - a)
}

/// One axis of a lattice cell: the two corner indices (already reduced to 0..=255 for the
/// permutation) and the fractional position in the cell.
#[derive(Clone, Copy)]
struct Axis {
    i0: usize,
    i1: usize,
    f: f32,
}

/// Axis of ordinary noise. `off` shifts the lattice hashing (vector channels).
#[inline(always)]
fn axis(x: f32, off: i32) -> Axis {
    let xi = fast_floor(x);
    let i0 = xi.wrapping_add(off);
    Axis {
        i0: (i0 & 255) as usize,
        i1: (i0.wrapping_add(1) & 255) as usize,
        f: x - xi as f32,
    }
}

/// Axis of periodic noise: the corner indices are taken modulo `period` before hashing, so the
/// function repeats exactly. `period <= 0` means "not periodic on this axis".
#[inline(always)]
fn axis_periodic(x: f32, period: i32, off: i32) -> Axis {
    if period <= 0 {
        return axis(x, off);
    }
    let xi = fast_floor(x);
    let i0 = xi.rem_euclid(period);
    let i1 = if i0 + 1 == period { 0 } else { i0 + 1 };
    Axis {
        i0: (i0.wrapping_add(off) & 255) as usize,
        i1: (i1.wrapping_add(off) & 255) as usize,
        f: x - xi as f32,
    }
}

/// Lattice offsets hashed by the three channels of the vector forms.
const CHANNEL_OFFSETS: [i32; 3] = [0, 101, 211];

// ---------------------------------------------------------------------------------------------
// Gradient sets and normalisation
// ---------------------------------------------------------------------------------------------

/// 1-D gradients: 16 slopes evenly spread over ±[1/8, 1], never 0 (a zero slope would flatten
/// a whole cell).
const G1: [f32; 16] = [
    0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0, -0.125, -0.25, -0.375, -0.5, -0.625, -0.75,
    -0.875, -1.0,
];

/// 2-D gradients: 16 unit vectors at angles (k + ½)·π/8, so none lies on an axis or a diagonal
/// of the lattice.
const G2: [[f32; 2]; 16] = {
    let mut g = [[0.0f32; 2]; 16];
    // cos/sin of (k+0.5)·22.5° for k = 0..3, extended by symmetry.
    let c = [0.980_785_3f32, 0.831_469_6, 0.555_570_2, 0.195_090_32];
    let s = [0.195_090_32f32, 0.555_570_2, 0.831_469_6, 0.980_785_3];
    let mut k = 0;
    while k < 4 {
        g[k] = [c[k], s[k]];
        g[k + 4] = [-s[k], c[k]];
        g[k + 8] = [-c[k], -s[k]];
        g[k + 12] = [s[k], -c[k]];
        k += 1;
    }
    g
};

/// 3-D gradients: the 12 cube-edge directions, padded to 16 with a symmetric repeat (Perlin
/// 2002) so the hash needs only a mask. Index h → (1,1,0) (−1,1,0) (1,−1,0) (−1,−1,0)
/// (1,0,1) (−1,0,1) (1,0,−1) (−1,0,−1) (0,1,1) (0,−1,1) (0,1,−1) (0,−1,−1) (1,1,0) (0,−1,1)
/// (−1,1,0) (0,−1,−1), evaluated by selects (see [`grad3`]) so lanes vectorise.
#[cfg(test)]
const G3: [[f32; 3]; 16] = [
    [1.0, 1.0, 0.0],
    [-1.0, 1.0, 0.0],
    [1.0, -1.0, 0.0],
    [-1.0, -1.0, 0.0],
    [1.0, 0.0, 1.0],
    [-1.0, 0.0, 1.0],
    [1.0, 0.0, -1.0],
    [-1.0, 0.0, -1.0],
    [0.0, 1.0, 1.0],
    [0.0, -1.0, 1.0],
    [0.0, 1.0, -1.0],
    [0.0, -1.0, -1.0],
    [1.0, 1.0, 0.0],
    [0.0, -1.0, 1.0],
    [-1.0, 1.0, 0.0],
    [0.0, -1.0, -1.0],
];

/// 4-D gradients: the 32 tesseract-edge directions (one zero coordinate, three ±1).
const G4: [[f32; 4]; 32] = {
    let mut g = [[0.0f32; 4]; 32];
    let mut n = 0;
    let mut zero = 0;
    while zero < 4 {
        let mut signs = 0;
        while signs < 8 {
            let mut v = [0.0f32; 4];
            let mut bit = 0;
            let mut c = 0;
            while c < 4 {
                if c != zero {
                    v[c] = if signs & (1 << bit) != 0 { -1.0 } else { 1.0 };
                    bit += 1;
                }
                c += 1;
            }
            g[n] = v;
            n += 1;
            signs += 1;
        }
        zero += 1;
    }
    g
};

// Scale factors from the raw gradient sums to snoise. They give noise the spread PRMan's has, as
// Pixar's Application Note #13 ("Properties of RenderMan Noise Functions", 1996) measured it: a
// standard deviation about the mean 0.5 of 0.0896 (1-D), 0.108 (2-D), 0.115 (3-D) and 0.111 (4-D).
// Shaders written for PRMan and BMRT threshold and mix with noise (rust that appears where a noise
// sum passes 0.8, each brick's colour `mix(c1, c2, noise(row*50 + col))`), so the spread sets how
// much rust, how varied the bricks. Unscaled, the gradient sums span [−1,1] (1-D, 2-D: their exact
// bounds ½·max|g| and √2/2; 3-D ≈1.0; 4-D ≈1.2) and noise's deviation was 0.157, 0.152, 0.130
// and 0.123: 1-D noise 75 % wider than PRMan's. The factors are those bounds' reciprocals times
// the ratio of deviations (measured over 8·10⁶ random points). Like PRMan's, 1-D noise stays
// within about [0.23, 0.77]; the clamp guards the vanishingly rare excess of 4-D.
const S1: f32 = 2.0 * 0.5719;
const S2: f32 = std::f32::consts::SQRT_2 * 0.7086;
const S3: f32 = 0.8868 / 1.04;
const S4: f32 = 0.9050 / 1.2;

/// Mean of |snoise3| and |snoise4| over space (measured, 8·10⁶ samples): the value a
/// box-filtered |snoise| tends to when the filter is much wider than a noise cell. Used by the
/// filtered turbulence.
pub const ABS_SNOISE3_MEAN: f32 = 0.1877;
/// See [`ABS_SNOISE3_MEAN`].
pub const ABS_SNOISE4_MEAN: f32 = 0.1803;

#[inline(always)]
fn clamp1(v: f32) -> f32 {
    v.clamp(-1.0, 1.0)
}

// ---------------------------------------------------------------------------------------------
// Raw gradient noise cores (signed, unclamped, unscaled)
// ---------------------------------------------------------------------------------------------

#[inline(always)]
fn core1(a: Axis) -> f32 {
    let g0 = G1[(PERM[a.i0] & 15) as usize];
    let g1 = G1[(PERM[a.i1] & 15) as usize];
    lerp(fade(a.f), g0 * a.f, g1 * (a.f - 1.0))
}

#[inline(always)]
fn grad2(h: u8, x: f32, y: f32) -> f32 {
    let g = G2[(h & 15) as usize];
    g[0] * x + g[1] * y
}

#[inline(always)]
fn core2(ax: Axis, ay: Axis) -> f32 {
    let a = PERM[ax.i0] as usize;
    let b = PERM[ax.i1] as usize;
    let (x, y) = (ax.f, ay.f);
    let (x1, y1) = (x - 1.0, y - 1.0);
    let n00 = grad2(PERM[a + ay.i0], x, y);
    let n10 = grad2(PERM[b + ay.i0], x1, y);
    let n01 = grad2(PERM[a + ay.i1], x, y1);
    let n11 = grad2(PERM[b + ay.i1], x1, y1);
    let u = fade(x);
    lerp(fade(y), lerp(u, n00, n10), lerp(u, n01, n11))
}

#[inline(always)]
fn grad3(h: u8, x: f32, y: f32, z: f32) -> f32 {
    // Branch-free selection of the cube-edge gradient `G3[h & 15]` (two of x, y, z with signs).
    let h = h & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
}

#[inline(always)]
fn core3(ax: Axis, ay: Axis, az: Axis) -> f32 {
    let a = PERM[ax.i0] as usize;
    let b = PERM[ax.i1] as usize;
    let aa = PERM[a + ay.i0] as usize;
    let ab = PERM[a + ay.i1] as usize;
    let ba = PERM[b + ay.i0] as usize;
    let bb = PERM[b + ay.i1] as usize;
    let (x, y, z) = (ax.f, ay.f, az.f);
    let (x1, y1, z1) = (x - 1.0, y - 1.0, z - 1.0);
    let n000 = grad3(PERM[aa + az.i0], x, y, z);
    let n100 = grad3(PERM[ba + az.i0], x1, y, z);
    let n010 = grad3(PERM[ab + az.i0], x, y1, z);
    let n110 = grad3(PERM[bb + az.i0], x1, y1, z);
    let n001 = grad3(PERM[aa + az.i1], x, y, z1);
    let n101 = grad3(PERM[ba + az.i1], x1, y, z1);
    let n011 = grad3(PERM[ab + az.i1], x, y1, z1);
    let n111 = grad3(PERM[bb + az.i1], x1, y1, z1);
    let u = fade(x);
    let v = fade(y);
    lerp(
        fade(z),
        lerp(v, lerp(u, n000, n100), lerp(u, n010, n110)),
        lerp(v, lerp(u, n001, n101), lerp(u, n011, n111)),
    )
}

#[inline(always)]
fn grad4(h: u8, x: f32, y: f32, z: f32, w: f32) -> f32 {
    let g = G4[(h & 31) as usize];
    g[0] * x + g[1] * y + g[2] * z + g[3] * w
}

/// The 3-D interpolation over one w-slab of the 4-D cell: `h` holds the 8 partial hashes of
/// the (x, y, z) corners, `wi` is the w corner index, `w` the offset from it, `u, v, s` the
/// faded x, y, z fractions.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // hot inner helper: plain scalars beat a struct here
fn slab4(h: [usize; 8], wi: usize, x: f32, y: f32, z: f32, w: f32, u: f32, v: f32, s: f32) -> f32 {
    let (x1, y1, z1) = (x - 1.0, y - 1.0, z - 1.0);
    let n000 = grad4(PERM[h[0] + wi], x, y, z, w);
    let n100 = grad4(PERM[h[1] + wi], x1, y, z, w);
    let n010 = grad4(PERM[h[2] + wi], x, y1, z, w);
    let n110 = grad4(PERM[h[3] + wi], x1, y1, z, w);
    let n001 = grad4(PERM[h[4] + wi], x, y, z1, w);
    let n101 = grad4(PERM[h[5] + wi], x1, y, z1, w);
    let n011 = grad4(PERM[h[6] + wi], x, y1, z1, w);
    let n111 = grad4(PERM[h[7] + wi], x1, y1, z1, w);
    lerp(
        s,
        lerp(v, lerp(u, n000, n100), lerp(u, n010, n110)),
        lerp(v, lerp(u, n001, n101), lerp(u, n011, n111)),
    )
}

#[inline(always)]
fn core4(ax: Axis, ay: Axis, az: Axis, aw: Axis) -> f32 {
    let a = PERM[ax.i0] as usize;
    let b = PERM[ax.i1] as usize;
    let aa = PERM[a + ay.i0] as usize;
    let ab = PERM[a + ay.i1] as usize;
    let ba = PERM[b + ay.i0] as usize;
    let bb = PERM[b + ay.i1] as usize;
    let h = [
        PERM[aa + az.i0] as usize,
        PERM[ba + az.i0] as usize,
        PERM[ab + az.i0] as usize,
        PERM[bb + az.i0] as usize,
        PERM[aa + az.i1] as usize,
        PERM[ba + az.i1] as usize,
        PERM[ab + az.i1] as usize,
        PERM[bb + az.i1] as usize,
    ];
    let (x, y, z, w) = (ax.f, ay.f, az.f, aw.f);
    let (u, v, s) = (fade(x), fade(y), fade(z));
    lerp(
        fade(w),
        slab4(h, aw.i0, x, y, z, w, u, v, s),
        slab4(h, aw.i1, x, y, z, w - 1.0, u, v, s),
    )
}

/// Points per batch in the slice kernels.
const LANES: usize = 8;

/// `snoise3` for `LANES` points at once, bit-identical to the scalar form (same operations in
/// the same order per lane). The lattice set-up and the gradient arithmetic run as
/// lane-parallel loops the compiler vectorises; only the permutation lookups stay scalar.
#[inline(always)]
fn snoise3_lanes(
    px: &[f32; LANES],
    py: &[f32; LANES],
    pz: &[f32; LANES],
    off: i32,
) -> [f32; LANES] {
    let mut f = [[0.0f32; LANES]; 3];
    let mut i = [[0i32; LANES]; 3];
    for l in 0..LANES {
        for (a, p) in [px, py, pz].iter().enumerate() {
            let xi = fast_floor(p[l]);
            i[a][l] = xi;
            f[a][l] = p[l] - xi as f32;
        }
    }
    let mut h = [[0u8; LANES]; 8];
    for l in 0..LANES {
        let xo = i[0][l].wrapping_add(off);
        let (x0, y0, z0) = (
            (xo & 255) as usize,
            (i[1][l] & 255) as usize,
            (i[2][l] & 255) as usize,
        );
        let (x1, y1, z1) = (
            (xo.wrapping_add(1) & 255) as usize,
            (i[1][l].wrapping_add(1) & 255) as usize,
            (i[2][l].wrapping_add(1) & 255) as usize,
        );
        let a = PERM[x0] as usize;
        let b = PERM[x1] as usize;
        let aa = PERM[a + y0] as usize;
        let ab = PERM[a + y1] as usize;
        let ba = PERM[b + y0] as usize;
        let bb = PERM[b + y1] as usize;
        h[0][l] = PERM[aa + z0];
        h[1][l] = PERM[ba + z0];
        h[2][l] = PERM[ab + z0];
        h[3][l] = PERM[bb + z0];
        h[4][l] = PERM[aa + z1];
        h[5][l] = PERM[ba + z1];
        h[6][l] = PERM[ab + z1];
        h[7][l] = PERM[bb + z1];
    }
    let mut out = [0.0f32; LANES];
    for l in 0..LANES {
        let (x, y, z) = (f[0][l], f[1][l], f[2][l]);
        let (x1, y1, z1) = (x - 1.0, y - 1.0, z - 1.0);
        let n000 = grad3(h[0][l], x, y, z);
        let n100 = grad3(h[1][l], x1, y, z);
        let n010 = grad3(h[2][l], x, y1, z);
        let n110 = grad3(h[3][l], x1, y1, z);
        let n001 = grad3(h[4][l], x, y, z1);
        let n101 = grad3(h[5][l], x1, y, z1);
        let n011 = grad3(h[6][l], x, y1, z1);
        let n111 = grad3(h[7][l], x1, y1, z1);
        let u = fade(x);
        let v = fade(y);
        let raw = lerp(
            fade(z),
            lerp(v, lerp(u, n000, n100), lerp(u, n010, n110)),
            lerp(v, lerp(u, n001, n101), lerp(u, n011, n111)),
        );
        out[l] = clamp1(S3 * raw);
    }
    out
}

/// Apply `snoise3_lanes` to a slice of points, writing `map(snoise)` to `out` (min length);
/// the tail shorter than `LANES` uses the scalar form.
#[inline(always)]
fn snoise3_batch(p: &[Vec3], out: &mut [f32], map: impl Fn(f32) -> f32) {
    let n = p.len().min(out.len());
    let (p, out) = (&p[..n], &mut out[..n]);
    let mut pc = p.chunks_exact(LANES);
    let mut oc = out.chunks_exact_mut(LANES);
    for (pp, oo) in (&mut pc).zip(&mut oc) {
        let mut x = [0.0f32; LANES];
        let mut y = [0.0f32; LANES];
        let mut z = [0.0f32; LANES];
        for l in 0..LANES {
            x[l] = pp[l].x;
            y[l] = pp[l].y;
            z[l] = pp[l].z;
        }
        let r = snoise3_lanes(&x, &y, &z, 0);
        for l in 0..LANES {
            oo[l] = map(r[l]);
        }
    }
    for (o, q) in oc.into_remainder().iter_mut().zip(pc.remainder()) {
        *o = map(snoise3(*q));
    }
}

/// Batch `snoise3` over structure-of-arrays lanes, for the fractal kernels.
#[inline]
pub(crate) fn snoise3_x8(x: &[f32; 8], y: &[f32; 8], z: &[f32; 8]) -> [f32; 8] {
    snoise3_lanes(x, y, z, 0)
}

// ---------------------------------------------------------------------------------------------
// Signed noise, [-1, 1]
// ---------------------------------------------------------------------------------------------

/// Signed 1-D noise in [−1,1], 0 at integers.
#[inline]
pub fn snoise1(x: f32) -> f32 {
    clamp1(S1 * core1(axis(x, 0)))
}

/// Signed 2-D noise in [−1,1].
#[inline]
pub fn snoise2(x: f32, y: f32) -> f32 {
    clamp1(S2 * core2(axis(x, 0), axis(y, 0)))
}

/// Signed 3-D noise in [−1,1].
#[inline]
pub fn snoise3(p: Vec3) -> f32 {
    clamp1(S3 * core3(axis(p.x, 0), axis(p.y, 0), axis(p.z, 0)))
}

/// Signed 4-D noise (point and time) in [−1,1].
#[inline]
pub fn snoise4(p: Vec3, t: f32) -> f32 {
    clamp1(S4 * core4(axis(p.x, 0), axis(p.y, 0), axis(p.z, 0), axis(t, 0)))
}

// ---------------------------------------------------------------------------------------------
// RenderMan noise, [0, 1], mean 0.5
// ---------------------------------------------------------------------------------------------

#[inline(always)]
fn to_unit(s: f32) -> f32 {
    0.5 + 0.5 * s
}

/// RenderMan `float noise(float)`: [0,1], 0.5 at integers.
#[inline]
pub fn noise1(x: f32) -> f32 {
    to_unit(snoise1(x))
}

/// RenderMan `float noise(float, float)`.
#[inline]
pub fn noise2(x: f32, y: f32) -> f32 {
    to_unit(snoise2(x, y))
}

/// RenderMan `float noise(point)`.
#[inline]
pub fn noise3(p: Vec3) -> f32 {
    to_unit(snoise3(p))
}

/// RenderMan `float noise(point, float)`.
#[inline]
pub fn noise4(p: Vec3, t: f32) -> f32 {
    to_unit(snoise4(p, t))
}

// ---------------------------------------------------------------------------------------------
// Vector (color / point / vector) noise: three decorrelated channels
// ---------------------------------------------------------------------------------------------

/// Signed 3-channel 1-D noise.
#[inline]
pub fn vsnoise1(x: f32) -> Vec3 {
    let f = |o| clamp1(S1 * core1(axis(x, o)));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Signed 3-channel 2-D noise.
#[inline]
pub fn vsnoise2(x: f32, y: f32) -> Vec3 {
    let f = |o| clamp1(S2 * core2(axis(x, o), axis(y, 0)));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Signed 3-channel 3-D noise.
#[inline]
pub fn vsnoise3(p: Vec3) -> Vec3 {
    let ay = axis(p.y, 0);
    let az = axis(p.z, 0);
    let f = |o| clamp1(S3 * core3(axis(p.x, o), ay, az));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Signed 3-channel 4-D noise.
#[inline]
pub fn vsnoise4(p: Vec3, t: f32) -> Vec3 {
    let (ay, az, aw) = (axis(p.y, 0), axis(p.z, 0), axis(t, 0));
    let f = |o| clamp1(S4 * core4(axis(p.x, o), ay, az, aw));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

#[inline(always)]
fn vto_unit(v: Vec3) -> Vec3 {
    Vec3::splat(0.5) + 0.5 * v
}

/// RenderMan `color/point/vector noise(float)`.
#[inline]
pub fn vnoise1(x: f32) -> Vec3 {
    vto_unit(vsnoise1(x))
}

/// RenderMan `color/point/vector noise(float, float)`.
#[inline]
pub fn vnoise2(x: f32, y: f32) -> Vec3 {
    vto_unit(vsnoise2(x, y))
}

/// RenderMan `color/point/vector noise(point)`.
#[inline]
pub fn vnoise3(p: Vec3) -> Vec3 {
    vto_unit(vsnoise3(p))
}

/// RenderMan `color/point/vector noise(point, float)`.
#[inline]
pub fn vnoise4(p: Vec3, t: f32) -> Vec3 {
    vto_unit(vsnoise4(p, t))
}

// ---------------------------------------------------------------------------------------------
// Periodic noise
// ---------------------------------------------------------------------------------------------

/// RenderMan `pnoise(float, float period)` with an integer period (≤ 0: not periodic).
#[inline]
pub fn pnoise1(x: f32, period: i32) -> f32 {
    to_unit(clamp1(S1 * core1(axis_periodic(x, period, 0))))
}

/// `pnoise(float, float, float pu, float pv)`.
#[inline]
pub fn pnoise2(x: f32, y: f32, px: i32, py: i32) -> f32 {
    to_unit(clamp1(
        S2 * core2(axis_periodic(x, px, 0), axis_periodic(y, py, 0)),
    ))
}

/// `pnoise(point, point period)`.
#[inline]
pub fn pnoise3(p: Vec3, period: IVec3) -> f32 {
    to_unit(clamp1(
        S3 * core3(
            axis_periodic(p.x, period.x, 0),
            axis_periodic(p.y, period.y, 0),
            axis_periodic(p.z, period.z, 0),
        ),
    ))
}

/// `pnoise(point, float, point pperiod, float tperiod)`.
#[inline]
pub fn pnoise4(p: Vec3, t: f32, period: IVec3, tperiod: i32) -> f32 {
    to_unit(clamp1(
        S4 * core4(
            axis_periodic(p.x, period.x, 0),
            axis_periodic(p.y, period.y, 0),
            axis_periodic(p.z, period.z, 0),
            axis_periodic(t, tperiod, 0),
        ),
    ))
}

/// Vector `pnoise(float, float period)`.
pub fn vpnoise1(x: f32, period: i32) -> Vec3 {
    let f = |o| to_unit(clamp1(S1 * core1(axis_periodic(x, period, o))));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Vector `pnoise(float, float, float pu, float pv)`.
pub fn vpnoise2(x: f32, y: f32, px: i32, py: i32) -> Vec3 {
    let ay = axis_periodic(y, py, 0);
    let f = |o| to_unit(clamp1(S2 * core2(axis_periodic(x, px, o), ay)));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Vector `pnoise(point, point period)`.
pub fn vpnoise3(p: Vec3, period: IVec3) -> Vec3 {
    let ay = axis_periodic(p.y, period.y, 0);
    let az = axis_periodic(p.z, period.z, 0);
    let f = |o| to_unit(clamp1(S3 * core3(axis_periodic(p.x, period.x, o), ay, az)));
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Vector `pnoise(point, float, point pperiod, float tperiod)`.
pub fn vpnoise4(p: Vec3, t: f32, period: IVec3, tperiod: i32) -> Vec3 {
    let ay = axis_periodic(p.y, period.y, 0);
    let az = axis_periodic(p.z, period.z, 0);
    let aw = axis_periodic(t, tperiod, 0);
    let f = |o| {
        to_unit(clamp1(
            S4 * core4(axis_periodic(p.x, period.x, o), ay, az, aw),
        ))
    };
    Vec3::new(
        f(CHANNEL_OFFSETS[0]),
        f(CHANNEL_OFFSETS[1]),
        f(CHANNEL_OFFSETS[2]),
    )
}

/// Convert SL's float periods to the integer periods `pnoise` honours: rounded, and anything
/// below ½ (including 0 and negatives) means "not periodic".
pub fn period_from_float(p: f32) -> i32 {
    if p.is_finite() && p >= 0.5 {
        (p + 0.5).min(i32::MAX as f32) as i32
    } else {
        0
    }
}

// ---------------------------------------------------------------------------------------------
// Cell noise
// ---------------------------------------------------------------------------------------------

/// Seeds of the cell-noise hash, one per dimension and channel, so `cellnoise1(x)` is not
/// `cellnoise2(x, 0)` and the channels of `vcellnoise` are independent.
#[inline(always)]
fn cell(dim: u32, channel: u32, c: [i32; 4]) -> f32 {
    u32_to_unit(hash_coords(dim * 4 + channel, c))
}

/// RenderMan `cellnoise(float)`: uniform in [0,1), constant on `[i, i+1)`.
#[inline]
pub fn cellnoise1(x: f32) -> f32 {
    cell(1, 0, [fast_floor(x), 0, 0, 0])
}

/// `cellnoise(float, float)`.
#[inline]
pub fn cellnoise2(x: f32, y: f32) -> f32 {
    cell(2, 0, [fast_floor(x), fast_floor(y), 0, 0])
}

/// `cellnoise(point)`.
#[inline]
pub fn cellnoise3(p: Vec3) -> f32 {
    cell(3, 0, [fast_floor(p.x), fast_floor(p.y), fast_floor(p.z), 0])
}

/// `cellnoise(point, float)`.
#[inline]
pub fn cellnoise4(p: Vec3, t: f32) -> f32 {
    cell(
        4,
        0,
        [
            fast_floor(p.x),
            fast_floor(p.y),
            fast_floor(p.z),
            fast_floor(t),
        ],
    )
}

#[inline(always)]
fn vcell(dim: u32, c: [i32; 4]) -> Vec3 {
    Vec3::new(cell(dim, 1, c), cell(dim, 2, c), cell(dim, 3, c))
}

/// Vector `cellnoise(float)`.
pub fn vcellnoise1(x: f32) -> Vec3 {
    vcell(1, [fast_floor(x), 0, 0, 0])
}

/// Vector `cellnoise(float, float)`.
pub fn vcellnoise2(x: f32, y: f32) -> Vec3 {
    vcell(2, [fast_floor(x), fast_floor(y), 0, 0])
}

/// Vector `cellnoise(point)`.
pub fn vcellnoise3(p: Vec3) -> Vec3 {
    vcell(3, [fast_floor(p.x), fast_floor(p.y), fast_floor(p.z), 0])
}

/// Vector `cellnoise(point, float)`.
pub fn vcellnoise4(p: Vec3, t: f32) -> Vec3 {
    vcell(
        4,
        [
            fast_floor(p.x),
            fast_floor(p.y),
            fast_floor(p.z),
            fast_floor(t),
        ],
    )
}

// ---------------------------------------------------------------------------------------------
// Batch forms for the shading runtime (SoA grids). Each processes min(len) elements.
// ---------------------------------------------------------------------------------------------

/// `out[i] = noise1(x[i])`.
pub fn noise1_slice(x: &[f32], out: &mut [f32]) {
    for (o, &v) in out.iter_mut().zip(x) {
        *o = noise1(v);
    }
}

/// `out[i] = noise2(x[i], y[i])`.
pub fn noise2_slice(x: &[f32], y: &[f32], out: &mut [f32]) {
    for ((o, &a), &b) in out.iter_mut().zip(x).zip(y) {
        *o = noise2(a, b);
    }
}

/// `out[i] = noise3(p[i])`.
pub fn noise3_slice(p: &[Vec3], out: &mut [f32]) {
    snoise3_batch(p, out, to_unit);
}

/// `out[i] = snoise3(p[i])`.
pub fn snoise3_slice(p: &[Vec3], out: &mut [f32]) {
    snoise3_batch(p, out, |v| v);
}

/// `out[i] = noise4(p[i], t[i])`.
pub fn noise4_slice(p: &[Vec3], t: &[f32], out: &mut [f32]) {
    for ((o, &q), &s) in out.iter_mut().zip(p).zip(t) {
        *o = noise4(q, s);
    }
}

/// `out[i] = vnoise3(p[i])`.
pub fn vnoise3_slice(p: &[Vec3], out: &mut [Vec3]) {
    let n = p.len().min(out.len());
    let full = n - n % LANES;
    for c in (0..full).step_by(LANES) {
        let x = std::array::from_fn(|l| p[c + l].x);
        let y = std::array::from_fn(|l| p[c + l].y);
        let z = std::array::from_fn(|l| p[c + l].z);
        let r = CHANNEL_OFFSETS.map(|o| snoise3_lanes(&x, &y, &z, o));
        for l in 0..LANES {
            out[c + l] = vto_unit(Vec3::new(r[0][l], r[1][l], r[2][l]));
        }
    }
    for k in full..n {
        out[k] = vnoise3(p[k]);
    }
}

/// `out[i] = pnoise3(p[i], period)`.
pub fn pnoise3_slice(p: &[Vec3], period: IVec3, out: &mut [f32]) {
    for (o, &q) in out.iter_mut().zip(p) {
        *o = pnoise3(q, period);
    }
}

/// `out[i] = cellnoise3(p[i])`.
pub fn cellnoise3_slice(p: &[Vec3], out: &mut [f32]) {
    for (o, &q) in out.iter_mut().zip(p) {
        *o = cellnoise3(q);
    }
}

/// `out[i] = vcellnoise3(p[i])`.
pub fn vcellnoise3_slice(p: &[Vec3], out: &mut [Vec3]) {
    for (o, &q) in out.iter_mut().zip(p) {
        *o = vcellnoise3(q);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pattern::hash::hash_float;

    /// Deterministic pseudo-random points in a box.
    fn pts(n: u32, scale: f32, seed: u32) -> impl Iterator<Item = (Vec3, f32)> {
        (0..n).map(move |i| {
            let k = seed.wrapping_mul(7919).wrapping_add(i * 4);
            let r = |j: u32| (hash_float(k + j) * 2.0 - 1.0) * scale;
            (Vec3::new(r(0), r(1), r(2)), r(3))
        })
    }

    #[test]
    fn grad3_selects_the_table_gradient() {
        let (x, y, z) = (0.3f32, -0.7, 0.45);
        for h in 0..=255u8 {
            let g = G3[(h & 15) as usize];
            assert_eq!(grad3(h, x, y, z), g[0] * x + g[1] * y + g[2] * z, "h = {h}");
        }
    }

    #[test]
    fn batch_kernel_is_bit_identical_to_scalar() {
        let p: Vec<Vec3> = pts(1003, 300.0, 11).map(|(p, _)| p).collect();
        let mut a = vec![0.0f32; p.len()];
        let mut b = vec![0.0f32; p.len()];
        let mut v = vec![Vec3::ZERO; p.len()];
        noise3_slice(&p, &mut a);
        snoise3_slice(&p, &mut b);
        vnoise3_slice(&p, &mut v);
        for i in 0..p.len() {
            assert_eq!(a[i].to_bits(), noise3(p[i]).to_bits());
            assert_eq!(b[i].to_bits(), snoise3(p[i]).to_bits());
            let w = vnoise3(p[i]);
            assert_eq!(
                v[i].to_array().map(f32::to_bits),
                w.to_array().map(f32::to_bits)
            );
        }
    }

    #[test]
    fn fast_floor_matches_floor() {
        for &x in &[
            -2.5f32, -2.0, -0.0, 0.0, 0.3, 1.0, 1.999, -1e-7, 12345.5, -7.0001,
        ] {
            assert_eq!(fast_floor(x), x.floor() as i32, "x = {x}");
        }
    }

    #[test]
    fn range_and_mean_all_dimensions() {
        let n = 200_000;
        let mut sums = [0.0f64; 4];
        for (p, t) in pts(n, 40.0, 1) {
            let v = [noise1(p.x), noise2(p.x, p.y), noise3(p), noise4(p, t)];
            for (d, &x) in v.iter().enumerate() {
                assert!((0.0..=1.0).contains(&x), "dim {} value {x}", d + 1);
                sums[d] += x as f64;
            }
        }
        for (d, s) in sums.iter().enumerate() {
            let mean = s / n as f64;
            assert!((mean - 0.5).abs() < 0.02, "dim {} mean {mean}", d + 1);
        }
    }

    #[test]
    fn signed_is_two_noise_minus_one() {
        for (p, t) in pts(1000, 10.0, 2) {
            assert!((snoise3(p) - (2.0 * noise3(p) - 1.0)).abs() < 1e-6);
            assert!((snoise4(p, t) - (2.0 * noise4(p, t) - 1.0)).abs() < 1e-6);
            assert!((-1.0..=1.0).contains(&snoise2(p.x, p.y)));
        }
    }

    /// Standard deviation of `f` over `n` points.
    fn spread(n: u32, seed: u32, f: impl Fn(Vec3, f32) -> f32) -> f64 {
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for (p, t) in pts(n, 100.0, seed) {
            let v = f(p, t) as f64;
            s += v;
            s2 += v * v;
        }
        let m = s / n as f64;
        (s2 / n as f64 - m * m).sqrt()
    }

    #[test]
    fn spread_matches_prman_application_note_13() {
        // PRMan's noise statistics (Application Note #13): standard deviation per dimension.
        let n = 1_000_000;
        let got = [
            spread(n, 11, |p, _| noise1(p.x)),
            spread(n, 12, |p, _| noise2(p.x, p.y)),
            spread(n, 13, |p, _| noise3(p)),
            spread(n, 14, |p, t| noise4(p, t)),
        ];
        for (d, (g, want)) in got.iter().zip([0.0896, 0.108, 0.115, 0.111]).enumerate() {
            assert!(
                (g - want).abs() < 0.002,
                "dim {}: std {g}, PRMan {want}",
                d + 1
            );
        }
        // Vector channels have the same spread as the float noise.
        let v = spread(n, 15, |p, _| vnoise3(p).y);
        assert!((v - 0.115).abs() < 0.002, "vnoise3 std {v}");
    }

    #[test]
    fn raw_values_stay_inside_normalisation() {
        // The clamp is practically never active; 1-D noise keeps PRMan's narrow range (app note
        // #13: 0.21..0.78), the others reach further out.
        let (mut m1, mut m2, mut m3, mut m4) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for (p, t) in pts(300_000, 50.0, 3) {
            m1 = m1.max((S1 * core1(axis(p.x, 0))).abs());
            m2 = m2.max((S2 * core2(axis(p.x, 0), axis(p.y, 0))).abs());
            m3 = m3.max((S3 * core3(axis(p.x, 0), axis(p.y, 0), axis(p.z, 0))).abs());
            m4 = m4.max((S4 * core4(axis(p.x, 0), axis(p.y, 0), axis(p.z, 0), axis(t, 0))).abs());
        }
        assert!((0.45..0.6).contains(&m1), "1-D raw max {m1}");
        for m in [m2, m3, m4] {
            assert!(m <= 0.98, "raw max {m}");
            assert!(m > 0.6, "raw max {m}");
        }
    }

    #[test]
    fn abs_snoise_means_are_measured() {
        let n = 1_000_000u32;
        let (mut a3, mut a4) = (0.0f64, 0.0f64);
        for (p, t) in pts(n, 100.0, 21) {
            a3 += snoise3(p).abs() as f64;
            a4 += snoise4(p, t).abs() as f64;
        }
        let (a3, a4) = (a3 / n as f64, a4 / n as f64);
        assert!(
            (a3 - ABS_SNOISE3_MEAN as f64).abs() < 0.002,
            "mean |snoise3| {a3}"
        );
        assert!(
            (a4 - ABS_SNOISE4_MEAN as f64).abs() < 0.002,
            "mean |snoise4| {a4}"
        );
    }

    #[test]
    fn half_at_lattice_points() {
        for i in -5..5 {
            for j in -5..5 {
                for k in -3..3 {
                    let p = Vec3::new(i as f32, j as f32, k as f32);
                    assert_eq!(noise1(i as f32), 0.5);
                    assert_eq!(noise2(i as f32, j as f32), 0.5);
                    assert_eq!(noise3(p), 0.5);
                    assert_eq!(noise4(p, (i + j) as f32), 0.5);
                    assert_eq!(vnoise3(p), Vec3::splat(0.5));
                    assert_eq!(pnoise3(p, IVec3::new(3, 4, 5)), 0.5);
                }
            }
        }
    }

    #[test]
    fn continuity_small_step_small_change() {
        // The gradient of snoise is bounded (≈ a few units), so a step of 1e-3 changes the value
        // by well under 1e-2, including across cell faces.
        let h = 1e-3f32;
        for (p, t) in pts(20_000, 8.0, 4) {
            for d in [Vec3::X, Vec3::Y, Vec3::Z] {
                assert!((snoise3(p + d * h) - snoise3(p)).abs() < 1e-2);
                assert!((snoise4(p + d * h, t) - snoise4(p, t)).abs() < 1e-2);
            }
            assert!((snoise4(p, t + h) - snoise4(p, t)).abs() < 1e-2);
            assert!((snoise1(p.x + h) - snoise1(p.x)).abs() < 1e-2);
            assert!((snoise2(p.x + h, p.y) - snoise2(p.x, p.y)).abs() < 1e-2);
        }
        // Across a cell face the one-sided derivatives agree (quintic fade: C¹ and better).
        for (p, _) in pts(2000, 8.0, 5) {
            let q = Vec3::new(p.x.floor(), p.y, p.z);
            let e = 1e-2f32;
            let left = (snoise3(q) - snoise3(q - Vec3::X * e)) / e;
            let right = (snoise3(q + Vec3::X * e) - snoise3(q)) / e;
            assert!((left - right).abs() < 0.1, "{left} vs {right}");
        }
    }

    #[test]
    fn no_axis_aligned_bias() {
        // The variance of the derivative should not depend on the direction: compare the mean
        // squared finite difference along an axis and along a diagonal.
        let h = 1e-2f32;
        let diag = Vec3::new(1.0, 1.0, 1.0).normalize();
        let (mut sa, mut sd) = (0.0f64, 0.0f64);
        for (p, _) in pts(50_000, 30.0, 6) {
            sa += ((snoise3(p + Vec3::X * h) - snoise3(p)) / h).powi(2) as f64;
            sd += ((snoise3(p + diag * h) - snoise3(p)) / h).powi(2) as f64;
        }
        let ratio = sa / sd;
        assert!(
            (ratio - 1.0).abs() < 0.1,
            "axis/diagonal derivative ratio {ratio}"
        );
    }

    #[test]
    fn vector_channels_are_decorrelated() {
        let n = 50_000;
        let mut c = [0.0f64; 3];
        let mut s = [0.0f64; 3];
        for (p, _) in pts(n, 30.0, 7) {
            let v = vsnoise3(p);
            c[0] += (v.x * v.y) as f64;
            c[1] += (v.y * v.z) as f64;
            c[2] += (v.x * v.z) as f64;
            s[0] += (v.x * v.x) as f64;
            s[1] += (v.y * v.y) as f64;
            s[2] += (v.z * v.z) as f64;
        }
        let norm = (s[0] * s[1]).sqrt();
        for cc in c {
            assert!((cc / norm).abs() < 0.05, "correlation {}", cc / norm);
        }
        // Channel 0 is the scalar noise.
        let p = Vec3::new(1.3, -2.7, 0.4);
        assert_eq!(vnoise3(p).x, noise3(p));
    }

    #[test]
    fn pnoise_is_exactly_periodic() {
        let per = IVec3::new(3, 5, 7);
        for (p, t) in pts(5000, 20.0, 8) {
            // Points on a 1/64 grid, so shifts by whole periods are exact in f32.
            let q = (p * 64.0).round() / 64.0;
            let t = (t * 64.0).round() / 64.0;
            let a = pnoise3(q, per);
            assert_eq!(a, pnoise3(q + Vec3::new(3.0, 0.0, 0.0), per));
            assert_eq!(a, pnoise3(q - Vec3::new(0.0, 5.0, 0.0), per));
            assert_eq!(a, pnoise3(q + Vec3::new(0.0, 0.0, 14.0), per));
            assert_eq!(a, pnoise3(q + Vec3::new(-6.0, 10.0, -7.0), per));
            assert_eq!(pnoise1(q.x, 4), pnoise1(q.x + 4.0, 4));
            assert_eq!(pnoise1(q.x, 4), pnoise1(q.x - 8.0, 4));
            assert_eq!(pnoise2(q.x, q.y, 2, 6), pnoise2(q.x + 2.0, q.y - 6.0, 2, 6));
            assert_eq!(
                pnoise4(q, t, per, 2),
                pnoise4(q + Vec3::new(3.0, 5.0, 7.0), t + 2.0, per, 2)
            );
            assert_eq!(
                vpnoise3(q, per),
                vpnoise3(q + Vec3::new(-3.0, 10.0, 7.0), per)
            );
        }
        // Period 0 means "not periodic": equals the plain noise.
        let p = Vec3::new(0.3, 1.7, -2.2);
        assert_eq!(pnoise3(p, IVec3::ZERO), noise3(p));
        assert_eq!(period_from_float(0.0), 0);
        assert_eq!(period_from_float(4.2), 4);
    }

    #[test]
    fn cellnoise_constant_in_cell_and_varies_across() {
        let mut distinct = 0;
        let mut sum = 0.0f64;
        let n = 10_000;
        for (p, t) in pts(n, 100.0, 9) {
            let base = p.floor();
            let inside = base + Vec3::splat(0.999);
            assert_eq!(cellnoise3(p), cellnoise3(base));
            assert_eq!(cellnoise3(p), cellnoise3(inside));
            assert_eq!(cellnoise1(p.x), cellnoise1(base.x + 0.5));
            assert_eq!(cellnoise4(p, t), cellnoise4(base, t.floor()));
            assert_eq!(vcellnoise3(p), vcellnoise3(inside));
            let v = cellnoise3(p);
            assert!((0.0..1.0).contains(&v));
            let vv = vcellnoise2(p.x, p.y);
            assert!(vv.cmpge(Vec3::ZERO).all() && vv.cmplt(Vec3::ONE).all());
            if cellnoise3(base + Vec3::X) != v {
                distinct += 1;
            }
            sum += v as f64;
        }
        assert!(distinct > n - 5);
        assert!((sum / n as f64 - 0.5).abs() < 0.02);
    }

    #[test]
    fn slices_match_scalar_and_tolerate_length_mismatch() {
        let p: Vec<Vec3> = pts(100, 5.0, 10).map(|(p, _)| p).collect();
        let mut out = vec![-1.0f32; 120];
        noise3_slice(&p, &mut out);
        for i in 0..100 {
            assert_eq!(out[i], noise3(p[i]));
        }
        assert_eq!(out[110], -1.0);
        let mut v = vec![Vec3::ZERO; 50];
        vnoise3_slice(&p, &mut v);
        assert_eq!(v[49], vnoise3(p[49]));
        let t: Vec<f32> = p.iter().map(|q| q.x * 0.5).collect();
        let mut o4 = vec![0.0f32; 100];
        noise4_slice(&p, &t, &mut o4);
        assert_eq!(o4[7], noise4(p[7], t[7]));
    }

    #[test]
    fn deterministic_known_values() {
        // Golden values guard against accidental changes to the permutation or gradients.
        let p = Vec3::new(0.3, 1.7, -2.2);
        let a = noise3(p);
        assert_eq!(a, noise3(p));
        assert!(a != 0.5);
        assert_eq!(
            noise3(Vec3::new(1e9, -1e9, 3.5)),
            noise3(Vec3::new(1e9, -1e9, 3.5))
        );
        // Non-finite input never panics; it gives NaN or a value in range.
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3e38] {
            let v = noise3(Vec3::new(x, 0.5, 0.5));
            assert!(v.is_nan() || (0.0..=1.0).contains(&v));
            let c = cellnoise3(Vec3::new(x, 0.5, 0.5));
            assert!((0.0..1.0).contains(&c));
        }
    }
}
