//! Environment maps: direction → map coordinates, and filtered environment lookups.
//!
//! Input: world-space directions (a centre and 4 corner directions per point), an opened
//! lat-long or cube map. Output: filtered channels.
//! Conventions (documented for map makers):
//! * Lat-long: +z is up. s = ½(1 + atan2(y, x)/π), t = acos(z)/π (row 0 is +z), i.e. an
//!   equirectangular picture; s wraps periodically.
//! * Cube faces px nx py ny pz nz are views from the centre along F with up U, 90° field of
//!   view, in RenderMan's left-handed camera (right R = U × F): ±x and ±z faces have U = +y,
//!   py has U = −z, ny has U = +z. On a face s = ½ + ½(d·R)/(d·F), t = ½ − ½(d·U)/(d·F).
//! Invariants: cube filtering is seamless: the EWA footprint lives on the centre's face, and
//! texels past its edge are fetched from the neighbouring face through their direction.

use glam::Vec3;

use super::cache::Fetcher;
use super::filter::{bilinear, lookup, FilterKind, Footprint};

/// (F, R, U) per cube face, in file order px nx py ny pz nz.
pub const CUBE_FRAMES: [(Vec3, Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::new(0.0, 0.0, -1.0), Vec3::Y),
    (Vec3::new(-1.0, 0.0, 0.0), Vec3::Z, Vec3::Y),
    (Vec3::Y, Vec3::X, Vec3::new(0.0, 0.0, -1.0)),
    (Vec3::new(0.0, -1.0, 0.0), Vec3::X, Vec3::Z),
    (Vec3::Z, Vec3::X, Vec3::Y),
    (
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::Y,
    ),
];

/// The cube face a direction hits and its (s, t) on that face.
pub fn cube_face(d: Vec3) -> (usize, f32, f32) {
    let a = d.abs();
    let face = if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 {
            0
        } else {
            1
        }
    } else if a.y >= a.z {
        if d.y >= 0.0 {
            2
        } else {
            3
        }
    } else if d.z >= 0.0 {
        4
    } else {
        5
    };
    let (s, t) = on_face(face, d);
    (face, s, t)
}

/// (s, t) of a direction projected onto a face's plane (gnomonic; may lie outside [0,1]).
pub fn on_face(face: usize, d: Vec3) -> (f32, f32) {
    let (f, r, u) = CUBE_FRAMES[face];
    let df = d.dot(f).max(1e-6);
    (0.5 + 0.5 * d.dot(r) / df, 0.5 - 0.5 * d.dot(u) / df)
}

/// The direction through (s, t) of a face (s, t may be outside [0,1]).
pub fn face_dir(face: usize, s: f32, t: f32) -> Vec3 {
    let (f, r, u) = CUBE_FRAMES[face];
    f + (2.0 * s - 1.0) * r - (2.0 * t - 1.0) * u
}

/// Lat-long (s, t) of a direction.
pub fn latlong(d: Vec3) -> (f32, f32) {
    let d = d.normalize_or_zero();
    let s = 0.5 * (1.0 + d.y.atan2(d.x) / std::f32::consts::PI);
    let t = d.z.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
    (s, t)
}

/// Filtered lat-long lookup: corners unwrapped around the centre's s.
pub fn latlong_lookup(
    f: &mut Fetcher,
    dirs: &[Vec3; 5],
    blur: f32,
    kind: FilterKind,
    out: &mut [f32],
) {
    let (sc, tc) = latlong(dirs[0]);
    let mut c = [0f32; 8];
    for k in 0..4 {
        let (mut s, t) = latlong(dirs[k + 1]);
        if s - sc > 0.5 {
            s -= 1.0;
        } else if sc - s > 0.5 {
            s += 1.0;
        }
        c[2 * k] = s;
        c[2 * k + 1] = t;
    }
    let mut fp = Footprint::from_corners(&c, 1.0, 1.0);
    fp.s = sc;
    fp.t = tc;
    // blur is an angle-like fraction of the map: of the width in s, of the height in t.
    lookup(f, 0, &fp, blur * 0.5, blur, kind, out);
}

/// Filtered cube lookup, seamless across faces. Returns false for a zero direction.
///
/// The Gaussian lives on the sphere: directions are projected onto the plane tangent at the
/// centre direction (so the kernel does not depend on which face the centre falls on), and
/// each texel weighs by its solid angle. Texels are walked on the centre's face plane,
/// extended past its edges; those past an edge are read bilinearly from the neighbouring face.
pub fn cube_lookup(f: &mut Fetcher, dirs: &[Vec3; 5], blur: f32, out: &mut [f32]) -> bool {
    let c = dirs[0].normalize_or_zero();
    if c.length_squared() == 0.0 || !c.is_finite() {
        return false;
    }
    let (face, sc, tc) = cube_face(c);
    // Tangent frame at c.
    let e1 = if c.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let e1 = (e1 - c * c.dot(e1)).normalize();
    let e2 = c.cross(e1);
    let tangent = |d: Vec3| -> Option<(f32, f32)> {
        let dc = d.dot(c);
        if dc <= 1e-4 {
            return None;
        }
        let p = d / dc;
        Some((p.dot(e1), p.dot(e2)))
    };
    let mut corners = [0f32; 8];
    for k in 0..4 {
        let (u, v) = tangent(dirs[k + 1]).unwrap_or((0.0, 0.0));
        corners[2 * k] = u.clamp(-2.0, 2.0);
        corners[2 * k + 1] = v.clamp(-2.0, 2.0);
    }
    let fp = Footprint::from_corners(&corners, 1.0, 1.0);
    // Covariance in tangent units (a face spans 2 units at its centre).
    let pv = 0.125;
    let bl = blur * blur;
    let sxx = pv * (fp.ds1 * fp.ds1 + fp.ds2 * fp.ds2) + bl;
    let syy = pv * (fp.dt1 * fp.dt1 + fp.dt2 * fp.dt2) + bl;
    let sxy = pv * (fp.ds1 * fp.dt1 + fp.ds2 * fp.dt2);
    let tr = 0.5 * (sxx + syy);
    let det = sxx * syy - sxy * sxy;
    let disc = (tr * tr - det).max(0.0).sqrt();
    let (lmax, lmin) = (tr + disc, (tr - disc).max(0.0));
    let levels = &f.tex.header.levels[face];
    let w0 = levels[0].width as f32;
    // Level where the minor σ spans 1–2 texels (texel = 2/w tangent units).
    let sig_min_texels = lmin.max(lmax / 256.0).sqrt() * w0 * 0.5;
    let level = if sig_min_texels > 1.0 {
        (sig_min_texels.log2().floor() as usize).min(levels.len() - 1)
    } else {
        0
    };
    let ll = levels[level];
    let (w, h) = (ll.width, ll.height);
    let texel = 2.0 / w as f32;
    let recon = 0.15 * texel * texel;
    let (sxx, syy) = (sxx + recon, syy + recon);
    let det = (sxx * syy - sxy * sxy).max(1e-20);
    let (qa, qb, qc) = (syy / det, -2.0 * sxy / det, sxx / det);
    // Bounding box on the face plane (generous: the plane stretches away from the centre).
    let r = (6.0 * sxx.max(syy)).sqrt() * 3.0 / texel;
    let r = r.min(3.0 * w as f32);
    let (cx, cy) = (sc * w as f32 - 0.5, tc * h as f32 - 0.5);
    let n = f.nchan;
    let mut acc = [0f32; 16];
    let acc = &mut acc[..n.min(16)];
    let mut wsum = 0.0;
    for y in (cy - r).ceil() as i64..=(cy + r).floor() as i64 {
        for x in (cx - r).ceil() as i64..=(cx + r).floor() as i64 {
            let s = (x as f32 + 0.5) / w as f32;
            let t = (y as f32 + 0.5) / h as f32;
            let d = face_dir(face, s, t);
            let Some((u, v)) = tangent(d) else { continue };
            let q = qa * u * u + qb * u * v + qc * v * v;
            if q >= 6.0 {
                continue;
            }
            // Solid angle of a texel of the face plane at distance |d|: dA/|d|³.
            let l2 = d.length_squared();
            let wt = (-0.5 * q).exp() / (l2 * l2.sqrt());
            wsum += wt;
            if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
                f.accum(face, level, x as usize, y as usize, wt, acc);
            } else {
                let (f2, s2, t2) = cube_face(d);
                bilinear(f, f2, level, s2, t2, wt, acc);
            }
        }
    }
    if wsum <= 0.0 {
        wsum = bilinear(f, face, level, sc, tc, 1.0, acc);
    }
    let inv = 1.0 / wsum;
    let have = f.tex.header.nchan.saturating_sub(f.first).min(n);
    for k in 0..have.min(acc.len()) {
        out[k] = acc[k] * inv;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_axes_hit_their_face_centres() {
        let axes = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        for (i, a) in axes.iter().enumerate() {
            let (f, s, t) = cube_face(*a);
            assert_eq!(f, i);
            assert!((s - 0.5).abs() < 1e-6 && (t - 0.5).abs() < 1e-6);
        }
    }

    #[test]
    fn face_dir_inverts_on_face() {
        for face in 0..6 {
            for &(s, t) in &[(0.1, 0.2), (0.9, 0.5), (0.5, 0.95)] {
                let d = face_dir(face, s, t);
                let (f2, s2, t2) = cube_face(d);
                assert_eq!(f2, face);
                assert!((s - s2).abs() < 1e-5 && (t - t2).abs() < 1e-5);
            }
        }
        // Frames are right = up × forward (left-handed camera).
        for (f, r, u) in CUBE_FRAMES {
            assert!((u.cross(f) - r).length() < 1e-6);
        }
    }

    #[test]
    fn latlong_coordinates() {
        let (s, t) = latlong(Vec3::X);
        assert!((s - 0.5).abs() < 1e-6 && (t - 0.5).abs() < 1e-6);
        let (s, _) = latlong(Vec3::Y);
        assert!((s - 0.75).abs() < 1e-6);
        let (s, _) = latlong(-Vec3::Y);
        assert!((s - 0.25).abs() < 1e-6);
        assert!(latlong(Vec3::Z).1.abs() < 1e-6);
        assert!((latlong(-Vec3::Z).1 - 1.0).abs() < 1e-6);
    }
}
