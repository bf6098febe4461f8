//! Filtered 2-D lookups into one face of a texture: point, trilinear mip-map and EWA (the
//! summed-area-table filter lives in [`super::sat`]: it reads a table, not tiles).
//!
//! Input: a [`Fetcher`], a face, a [`Footprint`] (centre and the two axis vectors of the
//! shading point's area in [0,1] texture units) and blur. Output: `nchan` filtered channels.
//! Invariants: weights are normalised, so a constant texture returns its constant through
//! every filter; texels outside [0,1] follow the file's wrap modes (black ones weigh but add
//! nothing, so edges fade to black); channels the file lacks are left to the caller.
//!
//! * Trilinear (book §4.7 / Williams): d = √(area) in texels, k = ⌊log2 d⌋, and the blend
//!   between levels k and k+1 is linear in d: d_interp = d/2^k − 1 (erratum E5/E7 fixed).
//! * EWA (Greene–Heckbert, B = −2(u_x v_x + u_y v_y), erratum E9): the footprint's Gaussian
//!   with covariance ¼(a aᵀ + b bᵀ) + blur², evaluated on the level where the minor axis
//!   spans 1–2 texels, plus a ½-texel reconstruction term; anisotropy is capped at 16.

use super::cache::Fetcher;
use super::mipmap::Wrap;

/// Which filter a lookup uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterKind {
    /// Nearest texel of level 0 (no filtering: the reference for aliasing tests).
    Point,
    /// Trilinear mip-mapping with the book's level selection.
    Trilinear,
    /// Elliptical weighted average with a Gaussian.
    Ewa,
    /// Box average over the footprint's bounding rectangle from a summed-area table
    /// (`"filter" "sat"`; book §4.7.2). Where no table applies (environment maps) it falls
    /// back to trilinear.
    Sat,
}

impl FilterKind {
    /// RenderMan filter names; None for names arbor does not know.
    pub fn parse(name: &str) -> Option<FilterKind> {
        Some(match name.to_ascii_lowercase().as_str() {
            "point" | "nearest" | "none" => FilterKind::Point,
            "box" | "triangle" | "trilinear" | "mipmap" | "bilinear" => FilterKind::Trilinear,
            "gaussian" | "ewa" | "disk" | "radial-bspline" | "catmull-rom" | "sinc" => {
                FilterKind::Ewa
            }
            "sat" | "summed-area" | "summedarea" | "summed-area-table" => FilterKind::Sat,
            _ => return None,
        })
    }
}

/// A lookup's area: centre and two axis vectors (one micropolygon step in u and in v).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprint {
    pub s: f32,
    pub t: f32,
    pub ds1: f32,
    pub dt1: f32,
    pub ds2: f32,
    pub dt2: f32,
}

impl Footprint {
    /// From the 4 corners [s0,t0,s1,t1,s2,t2,s3,t3] (corner order (0,0) (1,0) (0,1) (1,1)),
    /// scaled by swidth/twidth.
    pub fn from_corners(c: &[f32; 8], swidth: f32, twidth: f32) -> Footprint {
        let s = 0.25 * (c[0] + c[2] + c[4] + c[6]);
        let t = 0.25 * (c[1] + c[3] + c[5] + c[7]);
        Footprint {
            s,
            t,
            ds1: 0.5 * ((c[2] - c[0]) + (c[6] - c[4])) * swidth,
            dt1: 0.5 * ((c[3] - c[1]) + (c[7] - c[5])) * twidth,
            ds2: 0.5 * ((c[4] - c[0]) + (c[6] - c[2])) * swidth,
            dt2: 0.5 * ((c[5] - c[1]) + (c[7] - c[3])) * twidth,
        }
    }
}

/// Filters one lookup into `out[..f.nchan]` (channels the texture lacks are not written).
pub fn lookup(
    f: &mut Fetcher,
    face: usize,
    fp: &Footprint,
    sblur: f32,
    tblur: f32,
    kind: FilterKind,
    out: &mut [f32],
) {
    let n = f.nchan;
    let have = f.tex.header.nchan.saturating_sub(f.first).min(n);
    let mut acc = [0f32; 16];
    let acc = &mut acc[..n.min(16)];
    let wsum = match kind {
        FilterKind::Point => point(f, face, fp, acc),
        FilterKind::Trilinear | FilterKind::Sat => trilinear(f, face, fp, sblur, tblur, acc),
        FilterKind::Ewa => ewa(f, face, fp, sblur, tblur, acc),
    };
    let inv = if wsum > 0.0 { 1.0 / wsum } else { 0.0 };
    for c in 0..have.min(acc.len()) {
        out[c] = acc[c] * inv;
    }
}

fn point(f: &mut Fetcher, face: usize, fp: &Footprint, acc: &mut [f32]) -> f32 {
    let h = &f.tex.header;
    let l = h.levels[face][0];
    let (sw, tw) = (h.swrap, h.twrap);
    let x = crate::num::floor_i64(fp.s * l.width as f32);
    let y = crate::num::floor_i64(fp.t * l.height as f32);
    if let (Some(x), Some(y)) = (sw.index(x, l.width), tw.index(y, l.height)) {
        f.accum(face, 0, x, y, 1.0, acc);
    }
    1.0
}

/// Bilinear on one level, weighted by `w`; returns the weight added.
#[inline]
pub fn bilinear(
    f: &mut Fetcher,
    face: usize,
    level: usize,
    s: f32,
    t: f32,
    w: f32,
    acc: &mut [f32],
) -> f32 {
    let h = &f.tex.header;
    let l = h.levels[face][level];
    let (sw, tw): (Wrap, Wrap) = (h.swrap, h.twrap);
    let x = s * l.width as f32 - 0.5;
    let y = t * l.height as f32 - 0.5;
    // Integer floor: f32::floor is a library call on baseline x86-64.
    let (x0, y0) = (crate::num::floor_i64(x), crate::num::floor_i64(y));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
        let Some(yy) = tw.index(y0 + dy, l.height) else {
            continue;
        };
        for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
            let Some(xx) = sw.index(x0 + dx, l.width) else {
                continue;
            };
            let ww = w * wx * wy;
            if ww != 0.0 {
                f.accum(face, level, xx, yy, ww, acc);
            }
        }
    }
    w
}

/// The book's mip level selection: (level k, blend d_interp toward k+1).
pub fn mip_level(d_texels: f32, nlevels: usize) -> (usize, f32) {
    if !(d_texels > 1.0) {
        return (0, 0.0);
    }
    let k = d_texels.log2().floor().max(0.0) as usize;
    if k >= nlevels - 1 {
        return (nlevels - 1, 0.0);
    }
    let dinterp = (d_texels / (1u64 << k) as f32 - 1.0).clamp(0.0, 1.0);
    (k, dinterp)
}

fn trilinear(
    f: &mut Fetcher,
    face: usize,
    fp: &Footprint,
    sblur: f32,
    tblur: f32,
    acc: &mut [f32],
) -> f32 {
    let l0 = f.tex.header.levels[face][0];
    let (w, h) = (l0.width as f32, l0.height as f32);
    let area = ((fp.ds1 * fp.dt2 - fp.ds2 * fp.dt1) * w * h).abs();
    let d = area.sqrt() + 0.5 * (sblur * w + tblur * h);
    let nlevels = f.tex.header.levels[face].len();
    let (k, di) = mip_level(d, nlevels);
    let mut wsum = bilinear(f, face, k, fp.s, fp.t, 1.0 - di, acc);
    if di > 0.0 {
        wsum += bilinear(f, face, k + 1, fp.s, fp.t, di, acc);
    }
    wsum
}

/// The Gaussian is cut at Q = 9 (3σ): with the minor σ at ½–1 texel on the chosen level, a
/// tighter cut leaves the truncated kernel's centroid off the centre by a visible fraction of
/// a texel (slopes taken from it are then off by a few percent).
const EWA_CUT: f32 = 9.0;
const MAX_ANISO: f32 = 16.0;
/// Variance of the pixel Gaussian per unit footprint axis (σ ≈ 0.35 of a micropolygon).
const PIXEL_VAR: f32 = 0.125;
/// Variance of the reconstruction Gaussian, in texels² of the level used.
const RECON_VAR: f32 = 0.15;

/// Inverse-covariance coefficients (A, B, C) of the Greene–Heckbert quadratic
/// Q = A u² + B uv + C v² for axis vectors (u_x, v_x), (u_y, v_y), and F = (u_x v_y − u_y v_x)².
pub fn ewa_coefficients(ux: f32, vx: f32, uy: f32, vy: f32) -> (f32, f32, f32, f32) {
    let a = vx * vx + vy * vy;
    let b = -2.0 * (ux * vx + uy * vy);
    let c = ux * ux + uy * uy;
    let ff = ux * vy - uy * vx;
    (a, b, c, ff * ff)
}

/// A prepared EWA evaluation on one level: quadratic form, centre and bounding box.
pub struct EwaSetup {
    pub level: usize,
    qa: f32,
    qb: f32,
    qc: f32,
    cx: f32,
    cy: f32,
    pub x0: i64,
    pub x1: i64,
    pub y0: i64,
    pub y1: i64,
}

/// Chooses the level and the Gaussian for a footprint on a face with these levels.
pub fn ewa_setup(
    levels: &[super::format::LevelInfo],
    fp: &Footprint,
    sblur: f32,
    tblur: f32,
) -> EwaSetup {
    let l0 = levels[0];
    let (w, h) = (l0.width as f32, l0.height as f32);
    // Covariance in level-0 texels: σ = half the footprint, plus blur (half-width σ).
    let (ax, ay) = (fp.ds1 * w, fp.dt1 * h);
    let (bx, by) = (fp.ds2 * w, fp.dt2 * h);
    let (bsx, bsy) = (0.5 * sblur * w, 0.5 * tblur * h);
    let mut sxx = PIXEL_VAR * (ax * ax + bx * bx) + bsx * bsx;
    let mut syy = PIXEL_VAR * (ay * ay + by * by) + bsy * bsy;
    let mut sxy = PIXEL_VAR * (ax * ay + bx * by);
    if !(sxx.is_finite() && syy.is_finite() && sxy.is_finite()) {
        (sxx, syy, sxy) = (0.0, 0.0, 0.0);
    }
    // Eigenvalues; cap the anisotropy by growing the minor axis.
    let tr = 0.5 * (sxx + syy);
    let det = sxx * syy - sxy * sxy;
    let disc = (tr * tr - det).max(0.0).sqrt();
    let (lmax, lmin) = (tr + disc, (tr - disc).max(0.0));
    let want_min = lmax / (MAX_ANISO * MAX_ANISO);
    let mut lmin_eff = lmin;
    if lmin < want_min {
        // Minor eigenvector: (sxy, lmin − sxx), or an axis when the form is diagonal.
        let (ex, ey) = if sxy.abs() > 1e-12 {
            (sxy, lmin - sxx)
        } else if sxx <= syy {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        let n2 = ex * ex + ey * ey;
        if n2 > 0.0 {
            let g = (want_min - lmin) / n2;
            sxx += g * ex * ex;
            syy += g * ey * ey;
            sxy += g * ex * ey;
        }
        lmin_eff = want_min;
    }
    // Level where the minor σ is ½–1 texel (with the reconstruction term, ≥ 0.6 texel: enough
    // to reconstruct; one level finer quadruples the texels visited for little gain).
    let sig_min = lmin_eff.sqrt();
    let level = if sig_min > 0.5 {
        ((sig_min.log2().floor() + 1.0) as usize).min(levels.len() - 1)
    } else {
        0
    };
    let ll = levels[level];
    let (kx, ky) = (ll.width as f32 / w, ll.height as f32 / h);
    // Scale to the level, add the reconstruction term (σ = ½ texel).
    let (sxx, syy, sxy) = (
        sxx * kx * kx + RECON_VAR,
        syy * ky * ky + RECON_VAR,
        sxy * kx * ky,
    );
    let det = sxx * syy - sxy * sxy;
    let (qa, qb, qc) = (syy / det, -2.0 * sxy / det, sxx / det);
    let rx = (EWA_CUT * sxx).sqrt().min(4.0 * ll.width as f32);
    let ry = (EWA_CUT * syy).sqrt().min(4.0 * ll.height as f32);
    let cx = fp.s * ll.width as f32 - 0.5;
    let cy = fp.t * ll.height as f32 - 0.5;
    EwaSetup {
        level,
        qa,
        qb,
        qc,
        cx,
        cy,
        x0: (cx - rx).ceil() as i64,
        x1: (cx + rx).floor() as i64,
        y0: (cy - ry).ceil() as i64,
        y1: (cy + ry).floor() as i64,
    }
}

impl EwaSetup {
    /// Runs the filter; `resolve` maps a level texel (x, y), possibly outside the level, to
    /// (face, x, y) or None (black). Returns the weight sum.
    #[inline]
    pub fn run(
        &self,
        f: &mut Fetcher,
        acc: &mut [f32],
        mut resolve: impl FnMut(i64, i64) -> Option<(usize, usize, usize)>,
    ) -> f32 {
        let level = self.level;
        self.run_with(f, acc, |f, x, y, wt, acc| {
            if let Some((face, xx, yy)) = resolve(x, y) {
                f.accum(face, level, xx, yy, wt, acc);
            }
        })
    }

    /// Runs the filter, handing each weighted texel (x, y) to `add` to accumulate.
    #[inline]
    pub fn run_with(
        &self,
        f: &mut Fetcher,
        acc: &mut [f32],
        mut add: impl FnMut(&mut Fetcher, i64, i64, f32, &mut [f32]),
    ) -> f32 {
        let mut wsum = 0.0;
        for y in self.y0..=self.y1 {
            let dy = y as f32 - self.cy;
            for x in self.x0..=self.x1 {
                let dx = x as f32 - self.cx;
                let q = self.qa * dx * dx + self.qb * dx * dy + self.qc * dy * dy;
                if q >= EWA_CUT {
                    continue;
                }
                let wt = gauss(q);
                wsum += wt;
                add(f, x, y, wt, acc);
            }
        }
        wsum
    }
}

fn ewa(
    f: &mut Fetcher,
    face: usize,
    fp: &Footprint,
    sblur: f32,
    tblur: f32,
    acc: &mut [f32],
) -> f32 {
    let setup = ewa_setup(&f.tex.header.levels[face], fp, sblur, tblur);
    let ll = f.tex.header.levels[face][setup.level];
    let (sw, tw) = (f.tex.header.swrap, f.tex.header.twrap);
    let wsum = setup.run(f, acc, |x, y| {
        Some((face, sw.index(x, ll.width)?, tw.index(y, ll.height)?))
    });
    if wsum <= 0.0 {
        // A footprint between texel centres: fall back to bilinear on that level.
        return bilinear(f, face, setup.level, fp.s, fp.t, 1.0, acc);
    }
    wsum
}

/// exp(−q/2) from a table (q in [0, EWA_CUT)).
#[inline]
fn gauss(q: f32) -> f32 {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        (0..=256)
            .map(|i| (-0.5 * EWA_CUT * i as f32 / 256.0).exp())
            .collect()
    });
    let x = q * (256.0 / EWA_CUT);
    let i = x as usize;
    if i >= 256 {
        return t[256];
    }
    let fr = x - i as f32;
    t[i] + (t[i + 1] - t[i]) * fr
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn book_level_selection() {
        // N = 512: d = 1/512 → k 0; 4/512 → k 2, 0; 6/512 → k 2, 0.5; 1 → top.
        assert_eq!(mip_level(1.0, 10), (0, 0.0));
        assert_eq!(mip_level(4.0, 10), (2, 0.0));
        assert_eq!(mip_level(6.0, 10), (2, 0.5));
        assert_eq!(mip_level(1.5, 10), (0, 0.5));
        assert_eq!(mip_level(512.0, 10), (9, 0.0));
        assert_eq!(mip_level(0.25, 10), (0, 0.0));
    }

    #[test]
    fn ewa_coefficients_follow_the_corrected_formula() {
        assert_eq!(ewa_coefficients(1.0, 0.0, 0.0, 1.0), (1.0, 0.0, 1.0, 1.0));
        let (a, _, c, ff) = ewa_coefficients(2.0, 0.0, 0.0, 1.0);
        assert_eq!((a, c, ff), (1.0, 4.0, 4.0));
        let (s, co) = (0.5f32, 0.75f32.sqrt());
        let (a, b, c, _) = ewa_coefficients(co, s, -s, co);
        assert!((a - 1.0).abs() < 1e-6 && b.abs() < 1e-6 && (c - 1.0).abs() < 1e-6);
    }

    #[test]
    fn footprint_from_corners() {
        let fp = Footprint::from_corners(&[0.0, 0.0, 0.1, 0.0, 0.0, 0.2, 0.1, 0.2], 1.0, 2.0);
        assert!((fp.s - 0.05).abs() < 1e-6 && (fp.t - 0.1).abs() < 1e-6);
        assert!((fp.ds1 - 0.1).abs() < 1e-6 && fp.dt1.abs() < 1e-6);
        assert!(fp.ds2.abs() < 1e-6 && (fp.dt2 - 0.4).abs() < 1e-6);
        assert!((gauss(0.0) - 1.0).abs() < 1e-6 && (gauss(2.0) - (-1.0f32).exp()).abs() < 1e-3);
    }
}
