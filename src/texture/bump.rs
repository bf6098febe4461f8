//! Bump maps: the stored form `MakeBump` writes, and Blinn's normal perturbation that the
//! shading language's `bump()` returns (book §6.4; notes shading.md §2.11).
//!
//! `bump()` and `MakeBump` are RISpec 3.0/3.1 (3.2 dropped both in favour of displacement
//! shaders; arbor follows 3.1). There `bump(name, N, dPds, dPdt, …)` returns the change of
//! the normal — Pixar's own 1989 `bumpy` shader does `N += bump(map, N, dPdu, dPdv) *
//! amplitude` — without fixing its formula; arbor returns Blinn's D, which makes the
//! bumped normal agree (to first order) with the normal of the surface displaced by
//! B·normalize(N), i.e. what `P += B * normalize(N); N = calculatenormal(P)` would give.
//!
//! Input: a height picture (any channel count; each channel is one height field B(s, t) in
//! the units of the shading space, t = 0 at the top row). Output of [`bump_image`]: an image
//! of 3n channels — the n heights, then (∂B/∂s, ∂B/∂t) for each of them — that the usual
//! pyramid code mip-maps into a [`Kind::Bump`](super::format::Kind::Bump) file.
//!
//! Why heights **and** precomputed slopes: bump() needs the gradient of the *filtered*
//! height. Filtering is linear, so it commutes with differentiation: the filtered slope
//! channels are exactly the derivative of the filtered heights, at every mip level, with one
//! filtered lookup per point (three channels) instead of four height lookups for finite
//! differences. Slopes are stored per unit s and t (central differences × the resolution),
//! so averaging them into coarser levels keeps their scale. The heights stay first so that
//! `texture("bump.tex")` still reads the height field. Plain textures still work with
//! bump(): their slopes come from finite differences across the footprint (see
//! [`super::system`]).
//!
//! Invariants: a linear ramp B = a·s + b·t stores slopes (a, b) exactly away from clamped
//! edges (one-sided differences there; periodic maps difference across the seam).

use glam::Vec3;

use super::image_in::Image;
use super::mipmap::Wrap;

/// Heights followed by their (∂/∂s, ∂/∂t) slopes: n channels in, 3n out.
pub fn bump_image(h: &Image, swrap: Wrap, twrap: Wrap) -> Image {
    let (w, ht, n) = (h.width, h.height, h.nchan);
    let mut out = Image::new(w, ht, 3 * n);
    // Neighbour indices, wrapped (periodic) or held at the edge (clamp, black).
    let nb = |i: usize, len: usize, wrap: Wrap| -> (usize, usize) {
        if wrap == Wrap::Periodic && len > 1 {
            ((i + len - 1) % len, (i + 1) % len)
        } else {
            (i.saturating_sub(1), (i + 1).min(len - 1))
        }
    };
    for y in 0..ht {
        let (ya, yb) = nb(y, ht, twrap);
        // Parameter distance between the two samples (1/len per texel).
        let dt = if yb == ya {
            0.0
        } else if twrap == Wrap::Periodic && ht > 1 {
            2.0 / ht as f32
        } else {
            (yb - ya) as f32 / ht as f32
        };
        for x in 0..w {
            let (xa, xb) = nb(x, w, swrap);
            let ds = if xb == xa {
                0.0
            } else if swrap == Wrap::Periodic && w > 1 {
                2.0 / w as f32
            } else {
                (xb - xa) as f32 / w as f32
            };
            let o = (y * w + x) * 3 * n;
            for c in 0..n {
                out.data[o + c] = h.px(x, y)[c];
                let bs = if ds > 0.0 {
                    (h.px(xb, y)[c] - h.px(xa, y)[c]) / ds
                } else {
                    0.0
                };
                let bt = if dt > 0.0 {
                    (h.px(x, yb)[c] - h.px(x, ya)[c]) / dt
                } else {
                    0.0
                };
                out.data[o + n + 2 * c] = bs;
                out.data[o + n + 2 * c + 1] = bt;
            }
        }
    }
    out
}

/// Channel of the s slope of height channel `c` in a bump map whose file has `nchan`
/// channels (the t slope follows it).
pub fn slope_channel(nchan: usize, c: usize) -> usize {
    nchan / 3 + 2 * c
}

/// The change of the normal for heights B displacing the surface along N̂ (Blinn 1978; book
/// §6.4 eq. D = B_u (N̂ × O_v) − B_v (N̂ × O_u)), with O_u, O_v = dPds, dPdt and
/// (B_u, B_v) = (bs, bt), so that `n + bump_displacement(…)` is the bumped normal.
///
/// Blinn derives D against N = O_s × O_t. So that `N + D` has the right tilt whatever
/// normal the shader passes, D is scaled by |N| / |O_s × O_t| and its sign follows the
/// orientation of N against O_s × O_t (a flipped N displaces the other way). When N is
/// O_s × O_t itself this is Blinn's D unchanged. Degenerate frames return zero.
pub fn bump_displacement(n: Vec3, dpds: Vec3, dpdt: Vec3, bs: f32, bt: f32) -> Vec3 {
    let ng = dpds.cross(dpdt);
    let (nlen, area) = (n.length(), ng.length());
    if !(nlen > 0.0 && area > 0.0 && nlen.is_finite() && area.is_finite()) {
        return Vec3::ZERO;
    }
    let nh = n / nlen;
    let d = bs * nh.cross(dpdt) - bt * nh.cross(dpds);
    let sign = if n.dot(ng) < 0.0 { -1.0 } else { 1.0 };
    d * (sign * nlen / area)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5 * (1.0 + b.length())
    }

    #[test]
    fn a_ramp_stores_its_slope_everywhere() {
        // B = 0.5 s − 0.25 t on a 16 × 8 map, sampled at texel centres.
        let (w, h) = (16, 8);
        let mut im = Image::new(w, h, 1);
        for y in 0..h {
            for x in 0..w {
                let (s, t) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                im.data[y * w + x] = 0.5 * s - 0.25 * t;
            }
        }
        let b = bump_image(&im, Wrap::Clamp, Wrap::Black);
        assert_eq!(b.nchan, 3);
        assert_eq!(slope_channel(3, 0), 1);
        for y in 0..h {
            for x in 0..w {
                let p = b.px(x, y);
                assert_eq!(p[0], im.px(x, y)[0]);
                assert!((p[1] - 0.5).abs() < 1e-4, "{x},{y}: {p:?}");
                assert!((p[2] + 0.25).abs() < 1e-4, "{x},{y}: {p:?}");
            }
        }
        // Periodic: a sine stores its cosine derivative (central differences, 64 texels).
        let n = 64;
        let mut sine = Image::new(n, 1, 2);
        for x in 0..n {
            let s = (x as f32 + 0.5) / n as f32;
            sine.data[2 * x] = (std::f32::consts::TAU * s).sin();
            sine.data[2 * x + 1] = 1.0;
        }
        let b = bump_image(&sine, Wrap::Periodic, Wrap::Periodic);
        assert_eq!((b.nchan, slope_channel(6, 1)), (6, 4));
        for x in [0, 17, 63] {
            let s = (x as f32 + 0.5) / n as f32;
            let want = std::f32::consts::TAU * (std::f32::consts::TAU * s).cos();
            assert!((b.px(x, 0)[2] - want).abs() < 0.02 * std::f32::consts::TAU);
            assert_eq!(b.px(x, 0)[4], 0.0);
        }
    }

    #[test]
    fn blinn_tilt_matches_the_displaced_surface() {
        // Plane P = (2s, t, 0): heights B = a s displace along +z, so the surface is
        // z = a s = (a/2) x with normal ∝ (−a/2, 0, 1).
        let (dpds, dpdt, a) = (Vec3::new(2.0, 0.0, 0.0), Vec3::Y, 0.6);
        let want = Vec3::new(-a / 2.0, 0.0, 1.0).normalize();
        // Whatever the length of N, N + D points the same way.
        for len in [1.0, 2.0, 0.1] {
            let n = Vec3::Z * len;
            let got = (n + bump_displacement(n, dpds, dpdt, a, 0.0)).normalize();
            assert!(close(got, want), "|N| {len}: {got} vs {want}");
        }
        // With N = dPds × dPdt it is Blinn's D exactly: B_s (N̂ × dPdt).
        let n = dpds.cross(dpdt);
        let d = bump_displacement(n, dpds, dpdt, a, 0.0);
        assert!(close(d, a * Vec3::Z.cross(dpdt)));
        // A t slope tilts the other axis: B = b t gives z = b y, normal ∝ (0, −b, 1).
        let got = (Vec3::Z + bump_displacement(Vec3::Z, dpds, dpdt, 0.0, 0.3)).normalize();
        assert!(close(got, Vec3::new(0.0, -0.3, 1.0).normalize()));
        // A flipped N displaces downward (z = −a s): its normal is −(a/2, 0, 1) normalised.
        let got = (-Vec3::Z + bump_displacement(-Vec3::Z, dpds, dpdt, a, 0.0)).normalize();
        assert!(
            close(got, -Vec3::new(a / 2.0, 0.0, 1.0).normalize()),
            "{got}"
        );
        // Degenerate frames change nothing.
        assert_eq!(
            bump_displacement(Vec3::Z, Vec3::X, Vec3::X, 1.0, 1.0),
            Vec3::ZERO
        );
        assert_eq!(
            bump_displacement(Vec3::ZERO, dpds, dpdt, 1.0, 1.0),
            Vec3::ZERO
        );
    }
}
