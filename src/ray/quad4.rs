//! The watertight quad test four quads at a time (SSE, the x86-64 baseline).
//!
//! Input: up to four quads of a BVH leaf (per quad its four corners' numbers in the leaf's
//! own vertex list, see `bvh::Leaf`), that list, and the ray prepared by [`WtRay`] (splatted
//! into [`WtRay4`]). Output: per lane the quad's hit `(t, a, b)` as the
//! one-quad test [`intersect_quad_wt`] gives it.
//! Invariants: bit for bit the scalar test: the same operations in the same order on each
//! lane (vertex to ray frame as `(rx·A)`, edge functions, `t = tt · (1/det)`), and a lane
//! where an edge function is exactly zero (the ray through an edge or a vertex, decided in
//! double precision) is redone by the scalar test. So hits, watertightness and the choice
//! between equal distances are those of testing the quads one by one.
//!
//! Why: leaves hold about two quads a visit; testing them one by one cost ~165 instructions
//! a quad plus the loop, most of it the twelve vertex transforms, which four lanes share.

use std::arch::x86_64::*;

use super::bvh::{intersect_quad_wt, leaf_corners, WtRay};

/// `$go!(kx, ky, kz)` for the ray's axis permutation number (`WtRay::perm` numbers the
/// permutations in this order, see `WtRay::PERMS`).
macro_rules! by_perm {
    ($perm:expr, $go:ident) => {
        match $perm {
            0 => $go!(1, 2, 0),
            1 => $go!(2, 1, 0),
            2 => $go!(2, 0, 1),
            3 => $go!(0, 2, 1),
            4 => $go!(0, 1, 2),
            _ => $go!(1, 0, 2),
        }
    };
}

/// A [`WtRay`]'s origin and shear splatted across four lanes.
#[derive(Clone, Copy)]
pub(crate) struct WtRay4 {
    o: [__m128; 3],
    s: [__m128; 3],
    /// The CPU has AVX: the test runs in its three-operand encoding (the same operations,
    /// without the register copies two-operand SSE needs).
    avx: bool,
}

impl WtRay4 {
    #[inline(always)]
    pub(crate) fn new(w: &WtRay) -> WtRay4 {
        WtRay4::with_avx(w, std::arch::is_x86_feature_detected!("avx"))
    }

    /// [`WtRay4::new`] with the CPU's AVX already known (true only where it has it).
    #[inline(always)]
    pub(crate) fn with_avx(w: &WtRay, avx: bool) -> WtRay4 {
        // SAFETY: SSE is part of the x86-64 baseline.
        unsafe {
            WtRay4 {
                o: [_mm_set1_ps(w.o.x), _mm_set1_ps(w.o.y), _mm_set1_ps(w.o.z)],
                s: w.s.map(|x| _mm_set1_ps(x)),
                avx,
            }
        }
    }
}

/// Per-lane hits of a group of four quads: a bit per lane that hit, and its `(t, a, b)`.
pub(crate) struct Hits4 {
    pub mask: u32,
    pub t: [f32; 4],
    pub a: [f32; 4],
    pub b: [f32; 4],
}

/// One triangle's test on four lanes, the vertices in the ray frame: `(t, w1, w2)` (weights
/// of `b` and `c`), the lanes that hit, and the lanes with an edge function exactly zero
/// (whose other results are not to be used: the scalar test redoes them).
#[inline(always)]
unsafe fn tri4(
    a: &[__m128; 3],
    b: &[__m128; 3],
    c: &[__m128; 3],
    tmin: __m128,
    tmax: __m128,
) -> (__m128, __m128, __m128, __m128, __m128) {
    let zero = _mm_setzero_ps();
    let u = _mm_sub_ps(_mm_mul_ps(c[0], b[1]), _mm_mul_ps(c[1], b[0]));
    let v = _mm_sub_ps(_mm_mul_ps(a[0], c[1]), _mm_mul_ps(a[1], c[0]));
    let w = _mm_sub_ps(_mm_mul_ps(b[0], a[1]), _mm_mul_ps(b[1], a[0]));
    let on_edge = _mm_or_ps(
        _mm_or_ps(_mm_cmpeq_ps(u, zero), _mm_cmpeq_ps(v, zero)),
        _mm_cmpeq_ps(w, zero),
    );
    // With no edge function zero, "some negative and some positive" is "the sign bits
    // differ": the sign of (u | v | w) and of (u & v & w) disagree. Inside, all three share
    // a sign, so det = u + v + w is not zero either (the scalar test's det == 0 rejection).
    let signs = _mm_xor_ps(
        _mm_or_ps(_mm_or_ps(u, v), w),
        _mm_and_ps(_mm_and_ps(u, v), w),
    );
    let outside = _mm_castsi128_ps(_mm_srai_epi32::<31>(_mm_castps_si128(signs)));
    let det = _mm_add_ps(_mm_add_ps(u, v), w);
    let tt = _mm_add_ps(
        _mm_add_ps(_mm_mul_ps(u, a[2]), _mm_mul_ps(v, b[2])),
        _mm_mul_ps(w, c[2]),
    );
    let inv = _mm_div_ps(_mm_set1_ps(1.0), det);
    let t = _mm_mul_ps(tt, inv);
    // tmin < t < tmax (false for NaN, as the scalar `!(t > tmin && t < tmax)`).
    let hit = _mm_andnot_ps(
        outside,
        _mm_and_ps(_mm_cmpgt_ps(t, tmin), _mm_cmplt_ps(t, tmax)),
    );
    (t, _mm_mul_ps(v, inv), _mm_mul_ps(w, inv), hit, on_edge)
}

#[inline(always)]
unsafe fn select(m: __m128, a: __m128, b: __m128) -> __m128 {
    _mm_or_ps(_mm_and_ps(m, a), _mm_andnot_ps(m, b))
}

/// The callback of a leaf test: `(quad's place in the leaf, t, a, b, &mut tmax)`, true to
/// stop.
pub(crate) type OnHit<'f> = dyn FnMut(usize, f32, f32, f32, &mut f32) -> bool + 'f;

/// Tests the quads of a leaf four at a time, reporting hits to `on_hit` in quad order, each
/// only while still nearer than `tmax` (which `on_hit` may shrink): the calls testing them
/// one by one with [`intersect_quad_wt`] would make (a quad's hit does not depend on `tmax`
/// but for being below it). True when `on_hit` asked to stop. `quads` holds a word per quad,
/// its corners' numbers in `verts` (bytes `v00 v10 v01 v11`, low first); `verts` is the
/// leaf's corners as `x y z` floats and must hold one float past the last corner (the loads
/// read 16 bytes a corner); a quad whose corners are out of range is never hit.
#[inline]
pub(crate) fn leaf(
    quads: &[u32],
    verts: &[f32],
    w4: &WtRay4,
    wt: &WtRay,
    tmin: f32,
    tmax: &mut f32,
    on_hit: &mut OnHit,
) -> bool {
    // The axis permutation as constants (six variants), so the ray-frame transform picks its
    // components at compile time.
    macro_rules! go {
        ($kx:literal, $ky:literal, $kz:literal) => {
            if w4.avx {
                // SAFETY: AVX was detected at run time (WtRay4::new).
                unsafe { leaf_avx::<$kx, $ky, $kz>(quads, verts, w4, wt, tmin, tmax, on_hit) }
            } else {
                leaf_k::<$kx, $ky, $kz>(quads, verts, w4, wt, tmin, tmax, on_hit)
            }
        };
    }
    by_perm!(wt.perm, go)
}

/// [`leaf`] where the caller knows the CPU has AVX: the permutation's variant compiled for
/// AVX, without the check (one function: the walk calls it directly).
///
/// # Safety
/// The CPU must have AVX.
#[target_feature(enable = "avx")]
pub(crate) unsafe fn leaf_avx_known(
    quads: &[u32],
    verts: &[f32],
    w4: &WtRay4,
    wt: &WtRay,
    tmin: f32,
    tmax: &mut f32,
    on_hit: &mut OnHit,
) -> bool {
    macro_rules! go {
        ($kx:literal, $ky:literal, $kz:literal) => {
            leaf_k::<$kx, $ky, $kz>(quads, verts, w4, wt, tmin, tmax, on_hit)
        };
    }
    by_perm!(wt.perm, go)
}

/// [`leaf_k`] compiled for AVX (VEX encodings of the same SSE operations: no FMA, so the
/// results are bit for bit those of the SSE path).
#[target_feature(enable = "avx")]
unsafe fn leaf_avx<const KX: usize, const KY: usize, const KZ: usize>(
    quads: &[u32],
    verts: &[f32],
    w4: &WtRay4,
    wt: &WtRay,
    tmin: f32,
    tmax: &mut f32,
    on_hit: &mut OnHit,
) -> bool {
    leaf_k::<KX, KY, KZ>(quads, verts, w4, wt, tmin, tmax, on_hit)
}

#[inline(always)]
fn leaf_k<const KX: usize, const KY: usize, const KZ: usize>(
    quads: &[u32],
    verts: &[f32],
    w4: &WtRay4,
    wt: &WtRay,
    tmin: f32,
    tmax: &mut f32,
    on_hit: &mut OnHit,
) -> bool {
    for (g, group) in quads.chunks(4).enumerate() {
        let h = group4::<KX, KY, KZ>(group, verts, w4, wt, tmin, *tmax);
        let mut m = h.mask;
        while m != 0 {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            if h.t[l] < *tmax && on_hit(4 * g + l, h.t[l], h.a[l], h.b[l], tmax) {
                return true;
            }
        }
    }
    false
}

/// Tests `quads` (one to four, as in [`leaf`]), each lane as [`intersect_quad_wt`] with
/// `tmin < t < tmax`.
#[inline(always)]
pub(crate) fn group4<const KX: usize, const KY: usize, const KZ: usize>(
    quads: &[u32],
    verts: &[f32],
    w4: &WtRay4,
    wt: &WtRay,
    tmin: f32,
    tmax: f32,
) -> Hits4 {
    let mut out = Hits4 {
        mask: 0,
        t: [0.0; 4],
        a: [0.0; 4],
        b: [0.0; 4],
    };
    if verts.len() < 4 {
        return out;
    }
    let base = verts.as_ptr();
    let n = quads.len().min(4);
    // SAFETY: SSE2 is baseline; every load below reads the 16 bytes from float offset f with
    // f + 4 <= verts.len(): f = 3c for a corner c <= (verts.len() − 4) / 3 (checked here),
    // or f = 0 (verts.len() >= 4).
    unsafe {
        // The lanes' corner words (missing lanes: corner 0 four times).
        let word = |l: usize| quads.get(l).copied().unwrap_or(0);
        let w = [word(0), word(1), word(2), word(3)];
        let words = _mm_loadu_si128(w.as_ptr().cast());
        // A corner's 16-byte load reads the float after it: in range up to the padding.
        // Per byte c <= lim (unsigned), then per lane all four.
        let lim = _mm_set1_epi8(((verts.len() - 4) / 3).min(255) as u8 as i8);
        let in_range = _mm_cmpeq_epi8(_mm_max_epu8(words, lim), lim);
        let lane_ok = _mm_cmpeq_epi32(in_range, _mm_set1_epi32(-1));
        let active = _mm_movemask_ps(_mm_castsi128_ps(lane_ok)) as u32 & ((1u32 << n) - 1);
        if active == 0 {
            return out;
        }
        // Per lane and corner the corner's first float, 3c (16 bits: no overflow); lanes
        // out of range read corner 0 and are masked off at the end.
        let c = _mm_and_si128(words, lane_ok);
        let zero = _mm_setzero_si128();
        let (lo, hi) = (_mm_unpacklo_epi8(c, zero), _mm_unpackhi_epi8(c, zero));
        let mut off = [0u16; 16];
        _mm_storeu_si128(
            off.as_mut_ptr().cast(),
            _mm_add_epi16(_mm_add_epi16(lo, lo), lo),
        );
        _mm_storeu_si128(
            off.as_mut_ptr().add(8).cast(),
            _mm_add_epi16(_mm_add_epi16(hi, hi), hi),
        );
        // The four corners in the ray frame, each as (x, y, z) vectors across the lanes.
        let corner = |c: usize| -> [__m128; 3] {
            let ld = |l: usize| _mm_loadu_ps(base.add(usize::from(off[4 * l + c])));
            let (p0, p1, p2, p3) = (ld(0), ld(1), ld(2), ld(3));
            // Transpose: lanes become quads.
            let t0 = _mm_unpacklo_ps(p0, p1); // x0 x1 y0 y1
            let t1 = _mm_unpacklo_ps(p2, p3); // x2 x3 y2 y3
            let t2 = _mm_unpackhi_ps(p0, p1); // z0 z1 . .
            let t3 = _mm_unpackhi_ps(p2, p3); // z2 z3 . .
            let p = [
                _mm_movelh_ps(t0, t1),
                _mm_movehl_ps(t1, t0),
                _mm_movelh_ps(t2, t3),
            ];
            // WtRay::xform on each lane.
            let ax = _mm_sub_ps(p[KX], w4.o[KX]);
            let ay = _mm_sub_ps(p[KY], w4.o[KY]);
            let az = _mm_sub_ps(p[KZ], w4.o[KZ]);
            [
                _mm_sub_ps(ax, _mm_mul_ps(w4.s[0], az)),
                _mm_sub_ps(ay, _mm_mul_ps(w4.s[1], az)),
                _mm_mul_ps(w4.s[2], az),
            ]
        };
        let (p00, p10, p01, p11) = (corner(0), corner(1), corner(2), corner(3));
        let tminv = _mm_set1_ps(tmin);
        // Triangle 1 (v00 v10 v11): a = w1 + w2, b = w2.
        let (t1, u1, v1, hit1, edge1) = tri4(&p00, &p10, &p11, tminv, _mm_set1_ps(tmax));
        // Triangle 2 (v00 v11 v01), nearer than triangle 1's hit: a = w1, b = w1 + w2.
        let tm2 = select(hit1, t1, _mm_set1_ps(tmax));
        let (t2, u2, v2, hit2, edge2) = tri4(&p00, &p11, &p01, tminv, tm2);
        let t = select(hit2, t2, t1);
        let a = select(hit2, u2, _mm_add_ps(u1, v1));
        let b = select(hit2, _mm_add_ps(u2, v2), v1);
        let hit = _mm_movemask_ps(_mm_or_ps(hit1, hit2)) as u32;
        let edge = _mm_movemask_ps(_mm_or_ps(edge1, edge2)) as u32;
        _mm_storeu_ps(out.t.as_mut_ptr(), t);
        _mm_storeu_ps(out.a.as_mut_ptr(), a);
        _mm_storeu_ps(out.b.as_mut_ptr(), b);
        out.mask = hit & active & !edge;
        // Through an edge or a vertex (or a degenerate triangle): the scalar test decides (in
        // double precision).
        let mut m = edge & active;
        while m != 0 {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            // (Active lanes have their corners in range.)
            let Some(p) = leaf_corners(quads[l], verts) else {
                continue;
            };
            if let Some((t, a, b)) = intersect_quad_wt(p, wt, tmin, tmax) {
                out.mask |= 1 << l;
                (out.t[l], out.a[l], out.b[l]) = (t, a, b);
            }
        }
    }
    out
}

/// [`group4`] for the ray's axis permutation (tests).
#[cfg(test)]
fn quads4(quads: &[u32], verts: &[f32], w4: &WtRay4, wt: &WtRay, tmin: f32, tmax: f32) -> Hits4 {
    match wt.k() {
        [1, 2, 0] => group4::<1, 2, 0>(quads, verts, w4, wt, tmin, tmax),
        [2, 1, 0] => group4::<2, 1, 0>(quads, verts, w4, wt, tmin, tmax),
        [2, 0, 1] => group4::<2, 0, 1>(quads, verts, w4, wt, tmin, tmax),
        [0, 2, 1] => group4::<0, 2, 1>(quads, verts, w4, wt, tmin, tmax),
        [0, 1, 2] => group4::<0, 1, 2>(quads, verts, w4, wt, tmin, tmax),
        _ => group4::<1, 0, 2>(quads, verts, w4, wt, tmin, tmax),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Random quads, some sharing corners in grids and some hit through an edge or a vertex:
    /// every lane agrees bit for bit with the one-quad test.
    #[test]
    fn four_lanes_agree_with_the_scalar_test() {
        let mut h = 777u32;
        let mut rnd = || {
            h = crate::pattern::hash::hash_u32(h);
            (h as f32 / u32::MAX as f32) * 2.0 - 1.0
        };
        // A 6 × 6 grid of corners on the unit square, jittered in z, and a padding element.
        let mut verts = Vec::new();
        for j in 0..6 {
            for i in 0..6 {
                verts.push(Vec3::new(i as f32 * 0.2, j as f32 * 0.2, rnd() * 0.05));
            }
        }
        let flat: Vec<f32> = verts
            .iter()
            .flat_map(|v| v.to_array())
            .chain([0.0])
            .collect();
        // Per quad its corners v00 v10 v01 v11, a byte each.
        let quads: Vec<u32> = (0..5u32)
            .flat_map(|j| (0..5u32).map(move |i| (i, j)))
            .map(|(i, j)| {
                let k = j * 6 + i;
                u32::from_le_bytes([k, k + 1, k + 6, k + 7].map(|c| c as u8))
            })
            .collect();
        let mut hits = 0;
        let mut edges = 0;
        for r in 0..2000 {
            // Every fourth ray aims exactly at a grid corner (edge functions of zero).
            let target = if r % 4 == 0 {
                verts[(r / 4) % 36]
            } else {
                Vec3::new(rnd() * 0.6 + 0.5, rnd() * 0.6 + 0.5, 0.0)
            };
            let o = Vec3::new(rnd(), rnd(), 2.0 + rnd());
            let d = target - o;
            let wt = WtRay::new(o, d);
            let w4 = WtRay4::new(&wt);
            let tmax = if r % 3 == 0 { 1.0 } else { f32::INFINITY };
            for s in 0..quads.len() {
                let group = &quads[s..(s + 1 + r % 4).min(quads.len())];
                let got = quads4(group, &flat, &w4, &wt, 0.0, tmax);
                for (l, &q) in group.iter().enumerate() {
                    let want = intersect_quad_wt(leaf_corners(q, &flat).unwrap(), &wt, 0.0, tmax);
                    let have = (got.mask & (1 << l) != 0).then(|| (got.t[l], got.a[l], got.b[l]));
                    let bits = |x: Option<(f32, f32, f32)>| {
                        x.map(|(t, a, b)| (t.to_bits(), a.to_bits(), b.to_bits()))
                    };
                    assert_eq!(bits(have), bits(want), "ray {r} quad {s}+{l}");
                    hits += usize::from(want.is_some());
                    edges += usize::from(r % 4 == 0 && want.is_some());
                }
                assert_eq!(got.mask >> group.len(), 0);
            }
        }
        assert!(
            hits > 1000 && edges > 100,
            "{hits} hits, {edges} at corners"
        );
        // A quad naming a corner past the list (or past its padding) is never hit, and the
        // lanes beside it are as before; rays straight down through the middle of the grid.
        let past = 36u8; // the 36 corners are 0…35
        let mut beside = 0;
        for (r, &(x, y)) in [(0.5, 0.5), (0.3, 0.1), (0.9, 0.7), (0.1, 0.9)]
            .iter()
            .enumerate()
        {
            let wt = WtRay::new(Vec3::new(x, y, 1.0), Vec3::new(0.001, 0.002, -1.0));
            let w4 = WtRay4::new(&wt);
            for s in 0..quads.len() - 3 {
                let mut group: Vec<u32> = quads[s..s + 4].to_vec();
                let mut bad = group[1].to_le_bytes();
                bad[r % 4] = if r % 2 == 0 { u8::MAX } else { past };
                group[1] = u32::from_le_bytes(bad);
                let got = quads4(&group, &flat, &w4, &wt, 0.0, f32::INFINITY);
                assert_eq!(got.mask & 2, 0, "ray {r} group {s}");
                for l in [0, 2, 3] {
                    let want =
                        intersect_quad_wt(leaf_corners(group[l], &flat).unwrap(), &wt, 0.0, 1e30);
                    let have = (got.mask & (1 << l) != 0).then(|| got.t[l].to_bits());
                    assert_eq!(have, want.map(|w| w.0.to_bits()), "ray {r} group {s}");
                    beside += usize::from(have.is_some());
                }
            }
        }
        assert!(beside >= 4, "{beside} hits beside a bad quad");
    }
}
