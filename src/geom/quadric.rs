//! The seven RenderMan quadrics (RISpec §5.3) as surfaces of revolution about object z.
//!
//! Input: a quadric's parameters (angles in degrees as in RIB) and `camera_from_object`.
//! Output: P, dPdu, dPdv at any (u,v) in [0,1]² in camera space, and a conservative bound of
//! any parameter rectangle.
//! Invariants: every quadric is `P(u,v) = Rz(u·thetamax) · c(v)` for a profile curve `c(v)`
//! (`c.y = 0` except for the hyperboloid), so the formulas below are exactly the spec's:
//! * sphere:      c = r (cos φ, 0, sin φ), φ = φmin + v(φmax − φmin), φmin = asin(zmin/r)
//!   (or −90° when zmin ≤ −r), φmax = asin(zmax/r) (or 90° when zmax ≥ r);
//! * cone:        c = (r(1 − v), 0, v·h);
//! * cylinder:    c = (r, 0, zmin + v(zmax − zmin));
//! * hyperboloid: c = p1 + v(p2 − p1);
//! * paraboloid:  z = zmin + v(zmax − zmin), c = (rmax·√(z/zmax), 0, z) — the spec text prints
//!   `z = v(zmax − zmin)`, a known misprint; renderers (and the spec's own figure) offset by zmin;
//! * disk:        c = (r(1 − v), 0, h);
//! * torus:       c = (R + r cos φ, 0, r sin φ), φ = φmin + v(φmax − φmin).
//!
//! Bounds are exact boxes of the region {signed radius range} × {angle range} × {z range} of the
//! patch, which shrinks with the parameter rectangle, so split children stay inside the parent.

use std::f32::consts::{FRAC_PI_2, PI, TAU};

use glam::{Mat4, Vec3};

use super::Bound;

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Profile {
    Sphere {
        r: f32,
        phi0: f32,
        phi1: f32,
    },
    Cone {
        h: f32,
        r: f32,
    },
    Cylinder {
        r: f32,
        z0: f32,
        z1: f32,
    },
    Hyperboloid {
        p1: Vec3,
        p2: Vec3,
    },
    Paraboloid {
        rmax: f32,
        z0: f32,
        z1: f32,
        zmax: f32,
    },
    Disk {
        h: f32,
        r: f32,
    },
    Torus {
        rmaj: f32,
        rmin: f32,
        phi0: f32,
        phi1: f32,
    },
}

/// A quadric placed in camera space.
#[derive(Clone, Debug)]
pub(crate) struct Quadric {
    pub profile: Profile,
    /// thetamax in radians (may be negative: the surface turns inside out).
    pub thetamax: f32,
    pub camera_from_object: Mat4,
    /// Negate dPdu × dPdv to get Ng (see `super::patch`).
    pub flip: bool,
}

impl Profile {
    /// The sphere's profile per RISpec: phi limits from the clamped z range.
    pub fn sphere(r: f32, zmin: f32, zmax: f32) -> Profile {
        let phi = |z: f32, default: f32, beyond: bool| {
            if beyond || r == 0.0 {
                default
            } else {
                (z / r).clamp(-1.0, 1.0).asin()
            }
        };
        // Literally the spec's tests (`zmin > −radius`, `zmax < radius`), also for r < 0.
        Profile::Sphere {
            r,
            phi0: phi(zmin, -FRAC_PI_2, zmin <= -r),
            phi1: phi(zmax, FRAC_PI_2, zmax >= r),
        }
    }

    /// Profile point c(v) and dc/dv.
    #[inline]
    pub fn eval(&self, v: f32) -> (Vec3, Vec3) {
        match *self {
            Profile::Sphere { r, phi0, phi1 } => {
                let dphi = phi1 - phi0;
                let (s, c) = (phi0 + v * dphi).sin_cos();
                (
                    Vec3::new(r * c, 0.0, r * s),
                    Vec3::new(-r * s, 0.0, r * c) * dphi,
                )
            }
            Profile::Cone { h, r } => (Vec3::new(r * (1.0 - v), 0.0, v * h), Vec3::new(-r, 0.0, h)),
            Profile::Cylinder { r, z0, z1 } => (
                Vec3::new(r, 0.0, z0 + v * (z1 - z0)),
                Vec3::new(0.0, 0.0, z1 - z0),
            ),
            Profile::Hyperboloid { p1, p2 } => (p1 + v * (p2 - p1), p2 - p1),
            Profile::Paraboloid { rmax, z0, z1, zmax } => {
                let dz = z1 - z0;
                let z = z0 + v * dz;
                let q = if zmax != 0.0 {
                    (z / zmax).max(0.0)
                } else {
                    0.0
                };
                let rho = rmax * q.sqrt();
                // d rho/dv = rmax · dz / (2 zmax √(z/zmax)); infinite at the apex, where the
                // normal falls back to a neighbour (see `Quadric::eval`), so clamp q there.
                let qd = q.max(1e-8);
                let drho = if zmax != 0.0 {
                    rmax * dz / (2.0 * zmax * qd.sqrt())
                } else {
                    0.0
                };
                (Vec3::new(rho, 0.0, z), Vec3::new(drho, 0.0, dz))
            }
            Profile::Disk { h, r } => (Vec3::new(r * (1.0 - v), 0.0, h), Vec3::new(-r, 0.0, 0.0)),
            Profile::Torus {
                rmaj,
                rmin,
                phi0,
                phi1,
            } => {
                let dphi = phi1 - phi0;
                let (s, c) = (phi0 + v * dphi).sin_cos();
                (
                    Vec3::new(rmaj + rmin * c, 0.0, rmin * s),
                    Vec3::new(-rmin * s, 0.0, rmin * c) * dphi,
                )
            }
        }
    }

    /// Parameters in [v0, v1] where the profile's radius or z can be extreme: the ends and the
    /// interior stationary points. Returns how many were written.
    fn candidates(&self, v0: f32, v1: f32, out: &mut [f32; 8]) -> usize {
        out[0] = v0;
        out[1] = v1;
        let mut n = 2;
        let (phi0, phi1) = match *self {
            Profile::Sphere { phi0, phi1, .. } | Profile::Torus { phi0, phi1, .. } => (phi0, phi1),
            // Linear or monotone profiles: the ends suffice.
            _ => return n,
        };
        let dphi = phi1 - phi0;
        if dphi == 0.0 {
            return n;
        }
        let (a, b) = (phi0 + v0 * dphi, phi0 + v1 * dphi);
        let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
        // cos and sin are extreme at multiples of 90°; past 360° of sweep all four are in.
        let k0 = (lo / FRAC_PI_2).ceil() as i64;
        let k1 = (hi / FRAC_PI_2).floor() as i64;
        let mut k = k0;
        while k <= k1 && n < out.len() {
            let v = (k as f32 * FRAC_PI_2 - phi0) / dphi;
            out[n] = v.clamp(v0.min(v1), v0.max(v1));
            n += 1;
            k += 1;
        }
        n
    }
}

impl Quadric {
    /// Object-space P, dPdu, dPdv at (u,v) from a profile evaluation and cos/sin of θ.
    #[inline]
    fn object(&self, c: Vec3, dc: Vec3, cos: f32, sin: f32) -> (Vec3, Vec3, Vec3) {
        let p = Vec3::new(c.x * cos - c.y * sin, c.x * sin + c.y * cos, c.z);
        let dpdu = Vec3::new(-p.y, p.x, 0.0) * self.thetamax;
        let dpdv = Vec3::new(dc.x * cos - dc.y * sin, dc.x * sin + dc.y * cos, dc.z);
        (p, dpdu, dpdv)
    }

    /// Camera-space P, dPdu, dPdv.
    #[inline]
    pub fn eval(&self, u: f32, v: f32) -> (Vec3, Vec3, Vec3) {
        let (c, dc) = self.profile.eval(v);
        let (sin, cos) = (u * self.thetamax).sin_cos();
        let (p, du, dv) = self.object(c, dc, cos, sin);
        let m = &self.camera_from_object;
        (
            m.transform_point3(p),
            m.transform_vector3(du),
            m.transform_vector3(dv),
        )
    }

    /// The geometric normal direction (unnormalised, orientation applied) at (u,v). Where the
    /// surface is degenerate (poles, apexes, the disk's centre) the normal of a point slightly
    /// inside the profile is used, which is the limit of the normals around it.
    #[inline]
    pub fn normal(&self, u: f32, v: f32, dpdu: Vec3, dpdv: Vec3) -> Vec3 {
        let n = dpdu.cross(dpdv);
        let scale = dpdu.length_squared().max(dpdv.length_squared());
        let n = if n.length_squared() > 1e-12 * scale * scale || scale == 0.0 {
            n
        } else {
            let v2 = if v > 0.5 { v - 1e-5 } else { v + 1e-5 };
            let (_, a, b) = self.eval(u, v2);
            a.cross(b)
        };
        if self.flip {
            -n
        } else {
            n
        }
    }

    /// Fills P, dPdu, dPdv, Ng and N of an `nu × nv` grid over [u0,u1] × [v0,v1].
    pub fn dice_into(&self, g: &mut crate::shade::Grid, u0: f32, du: f32, v0: f32, dv: f32) {
        let (nu, nv) = (g.nu, g.nv);
        let m = self.camera_from_object;
        // θ depends only on the column and the profile only on the row.
        let trig: Vec<(f32, f32)> = (0..nu)
            .map(|i| {
                let (s, c) = ((u0 + i as f32 * du) * self.thetamax).sin_cos();
                (c, s)
            })
            .collect();
        for j in 0..nv {
            let v = v0 + j as f32 * dv;
            let (c, dc) = self.profile.eval(v);
            for (i, &(cos, sin)) in trig.iter().enumerate() {
                let k = j * nu + i;
                let (p, a, b) = self.object(c, dc, cos, sin);
                let (a, b) = (m.transform_vector3(a), m.transform_vector3(b));
                g.p[k] = m.transform_point3(p);
                g.dpdu[k] = a;
                g.dpdv[k] = b;
                let n = self.normal(u0 + i as f32 * du, v, a, b).normalize_or_zero();
                g.ng[k] = n;
                g.n[k] = n;
            }
        }
    }

    /// A conservative camera-space bound of the patch [u0,u1] × [v0,v1].
    pub fn bound(&self, u0: f32, u1: f32, v0: f32, v1: f32) -> Bound {
        let (th_a, th_b) = {
            let (a, b) = (u0 * self.thetamax, u1 * self.thetamax);
            if a <= b {
                (a, b)
            } else {
                (b, a)
            }
        };
        let mut cands = [0.0f32; 8];
        let n = self.profile.candidates(v0, v1, &mut cands);
        let mut zlo = f32::INFINITY;
        let mut zhi = f32::NEG_INFINITY;
        let (rlo, rhi, alo, ahi);
        match self.profile {
            Profile::Hyperboloid { .. } => {
                // The profile is a segment off the xz plane: bound its distance to the axis and
                // the range of its own angle, then sweep.
                let (c0, _) = self.profile.eval(v0);
                let (c1, _) = self.profile.eval(v1);
                zlo = c0.z.min(c1.z);
                zhi = c0.z.max(c1.z);
                let (a, b) = (c0.truncate(), c1.truncate());
                let d = b - a;
                let t = if d.length_squared() > 0.0 {
                    (-a.dot(d) / d.length_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let rmax = a.length().max(b.length());
                let rmin = (a + t * d).length();
                if rmin <= 1e-6 * rmax || rmax == 0.0 {
                    // Through (or at) the axis: the angle is unbounded.
                    rlo = 0.0;
                    rhi = rmax;
                    alo = 0.0;
                    ahi = TAU;
                } else {
                    let a0 = a.y.atan2(a.x);
                    let mut da = b.y.atan2(b.x) - a0;
                    if da > PI {
                        da -= TAU;
                    } else if da < -PI {
                        da += TAU;
                    }
                    rlo = rmin;
                    rhi = rmax;
                    alo = th_a + a0.min(a0 + da);
                    ahi = th_b + a0.max(a0 + da);
                }
            }
            _ => {
                // c.y = 0: the signed radius c.x and z bound the profile.
                let mut lo = f32::INFINITY;
                let mut hi = f32::NEG_INFINITY;
                for &v in &cands[..n] {
                    let (c, _) = self.profile.eval(v);
                    lo = lo.min(c.x);
                    hi = hi.max(c.x);
                    zlo = zlo.min(c.z);
                    zhi = zhi.max(c.z);
                }
                rlo = lo;
                rhi = hi;
                alo = th_a;
                ahi = th_b;
            }
        }
        let obj = sector_box(rlo, rhi, alo, ahi, zlo, zhi);
        let m = self.camera_from_object;
        let b = Bound::from_points(obj.corners().iter().map(|&p| m.transform_point3(p)));
        super::pad_transformed(b)
    }
}

/// Exact box of {(ρ cos a, ρ sin a, z) : ρ ∈ [rlo, rhi], a ∈ [alo, ahi], z ∈ [zlo, zhi]}. For a
/// fixed angle x and y are linear in ρ, and for a fixed ρ they are extreme at the angle ends or at
/// multiples of 90°, so those candidates suffice (ρ may be negative).
fn sector_box(rlo: f32, rhi: f32, alo: f32, ahi: f32, zlo: f32, zhi: f32) -> Bound {
    let mut b = Bound::EMPTY;
    let mut add = |a: f32| {
        let (s, c) = a.sin_cos();
        for r in [rlo, rhi] {
            let p = Vec3::new(r * c, r * s, 0.0);
            b.min = b.min.min(p);
            b.max = b.max.max(p);
        }
    };
    add(alo);
    add(ahi);
    if ahi - alo >= TAU {
        for k in 0..4 {
            add(k as f32 * FRAC_PI_2);
        }
    } else {
        let k0 = (alo / FRAC_PI_2).ceil() as i64;
        let k1 = (ahi / FRAC_PI_2).floor() as i64;
        for k in k0..=k1 {
            // Exact axis values avoid cos(π/2) ≠ 0 rounding shrinking the box.
            let (s, c) = match k.rem_euclid(4) {
                0 => (0.0, 1.0),
                1 => (1.0, 0.0),
                2 => (0.0, -1.0),
                _ => (-1.0, 0.0),
            };
            for r in [rlo, rhi] {
                let p = Vec3::new(r * c, r * s, 0.0);
                b.min = b.min.min(p);
                b.max = b.max.max(p);
            }
        }
    }
    b.min.z = zlo;
    b.max.z = zhi;
    b
}
