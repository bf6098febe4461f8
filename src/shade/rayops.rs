//! The shading language's ray functions over a grid: `trace`, `transmission`, `visibility`,
//! `occlusion`, `indirectdiffuse`, `raylevel`, `isshadowray`, and the `"raytrace"` forms of
//! `shadow` and `environment`.
//!
//! Input: the running program's registers and mask; the environment's [`RayTracer`]. Output:
//! the call's result register. Invariants: only points under the running mask cast rays;
//! sample directions are stratified and hashed from each point's position and the call's place
//! in the source, so results never depend on the grid, bucket or thread; with no ray tracer
//! every function returns its "nothing there" value (black, unoccluded, unshadowed).
//!
//! Ray differentials: every ray carries a [`Cone`] whose width where it starts is the
//! footprint of the shading point (the grid's differences of `P`) and whose spread is the
//! change of the ray direction across that footprint (the differences of the normalised
//! direction: a flat mirror passes on the camera's pixel spread, a curved one widens it, as
//! ray cones do), plus the solid angle per sample for stochastic rays. On a grid of ray
//! hits laid out as [`TRIPLES`], only the hits themselves cast rays; the two footprint
//! neighbours of each hit take its answers.

use glam::Vec3;

use super::{arg, deriv_t, has_neighbours, put, vec_t, TRIPLES};
use crate::diag::Span;
use crate::ray::{cone_dir, cosine_dir, point_seed, stratified, Cone};
use crate::shade::exec::{Exec, InfoValue, Mask};
use crate::shade::rays;
use crate::shade::value::Slot;
use crate::sl::builtins::Builtin;
use crate::sl::ir::{Kind, Reg};

/// Rays further than this are clamped (keeps the ray–box arithmetic in range).
const FAR: f32 = 1.0e8;

#[inline]
fn lum(c: Vec3) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// Handles a ray built-in; false when `f` is not one (the caller then runs it as usual).
pub(super) fn call(
    ex: &mut Exec,
    f: Builtin,
    dst: Reg,
    args: &[Reg],
    span: Span,
    mask: &Mask,
) -> bool {
    use Builtin::*;
    let raytrace_map = matches!(f, Shadow | EnvironmentC | EnvironmentF)
        && args
            .first()
            .is_some_and(|&r| &*ex.regs[r as usize].s() == "raytrace");
    if !(matches!(
        f,
        Trace | Occlusion | IndirectDiffuse | Transmission | Visibility | RayLevel | IsShadowRay
    ) || raytrace_map)
    {
        return false;
    }
    let n = ex.n;
    let triples = ex.env.nu == TRIPLES && has_neighbours(ex.env.nu, ex.env.nv, n);
    let own_bits;
    let bits: &[bool] = if triples {
        own_bits = mask
            .bits
            .iter()
            .enumerate()
            .map(|(k, &b)| b && k % 3 == 0)
            .collect::<Vec<bool>>();
        &own_bits
    } else {
        &mask.bits
    };
    let out = match f {
        RayLevel => Slot::F(ex.env.rays.map_or(0.0, |r| r.depth() as f32)),
        IsShadowRay => Slot::F(0.0),
        Trace => {
            let p = vec_t(arg(ex, args, 0), n);
            let r = vec_t(arg(ex, args, 1), n);
            let ci = trace_rays(ex, &p, &r, &r, 0.0, bits);
            if ex.prog.regs[dst as usize].kind == Kind::Float {
                Slot::VF(ci.iter().map(|c| lum(*c)).collect())
            } else {
                Slot::VT(ci)
            }
        }
        Transmission | Visibility => {
            let a = vec_t(arg(ex, args, 0), n);
            let b = vec_t(arg(ex, args, 1), n);
            let mut samples = 1.0;
            let mut cone = 0.0;
            for (name, v) in params(ex, args, 2) {
                match &*name {
                    "samples" => samples = v.f().first(),
                    "samplecone" => cone = v.f().first(),
                    "bias" | "hitmode" | "hitsides" | "label" | "subset" => {}
                    other => ex.warn(
                        span,
                        format!("{f:?} parameter \"{other}\" is not supported; ignored"),
                    ),
                }
            }
            Slot::VT(transmit(ex, &a, &b, bits, samples, cone, span))
        }
        Occlusion | IndirectDiffuse => {
            let p = vec_t(arg(ex, args, 0), n);
            let nn = vec_t(arg(ex, args, 1), n);
            let mut samples = arg(ex, args, 2).f().first();
            let mut maxdist = FAR;
            let mut cone = std::f32::consts::FRAC_PI_2;
            let mut env_color = Vec3::ZERO;
            for (name, v) in params(ex, args, 3) {
                match &*name {
                    "samples" => samples = v.f().first(),
                    "maxdist" => maxdist = v.f().first().clamp(0.0, FAR),
                    "coneangle" => cone = v.f().first(),
                    "environmentcolor" => env_color = v.t().first(),
                    // "blur" is the map lookup's in Aqsis's occlusion(mapname, …).
                    "bias" | "hitmode" | "hitsides" | "label" | "subset" | "adaptive"
                    | "minsamples" | "falloff" | "falloffmode" | "maxerror" | "maxpixeldist"
                    | "distribution" | "pointbased" | "blur" => {}
                    other => ex.warn(
                        span,
                        format!("{f:?} parameter \"{other}\" is not supported; ignored"),
                    ),
                }
            }
            let count = samples.round().clamp(1.0, 4096.0) as u32;
            hemisphere(
                ex,
                f == Occlusion,
                &p,
                &nn,
                bits,
                count,
                maxdist,
                cone,
                env_color,
                span,
            )
        }
        Shadow => {
            // shadow("raytrace", P [, "samples", n, "blur", angle, "bias", b]) in a light shader:
            // towards the light's position (Ps − L), or along −L inside solar().
            let ncoord = arg(ex, args, 2).f().first() as usize;
            let first_param = 3 + ncoord.max(1);
            let p: Vec<Vec3> = if ncoord == 4 {
                let c: Vec<Vec<Vec3>> = (0..4).map(|k| vec_t(arg(ex, args, 3 + k), n)).collect();
                (0..n)
                    .map(|i| 0.25 * (c[0][i] + c[1][i] + c[2][i] + c[3][i]))
                    .collect()
            } else {
                vec_t(arg(ex, args, 3), n)
            };
            let (samples, blur) = map_params(ex, args, first_param, span);
            let l = ex
                .prog
                .global("L")
                .map(|g| vec_t(&ex.regs[g.reg as usize], n))
                .unwrap_or_else(|| vec![Vec3::ZERO; n]);
            let ps = ex
                .prog
                .global("Ps")
                .map(|g| vec_t(&ex.regs[g.reg as usize], n))
                .unwrap_or_else(|| p.clone());
            let to: Vec<Vec3> = (0..n)
                .map(|i| {
                    if ex.in_solar {
                        p[i] - l[i].normalize_or_zero() * FAR
                    } else {
                        ps[i] - l[i]
                    }
                })
                .collect();
            let t = transmit(ex, &p, &to, bits, samples, blur, span);
            Slot::VF(t.iter().map(|c| 1.0 - lum(*c)).collect())
        }
        EnvironmentC | EnvironmentF => {
            // environment("raytrace", R [, "samples", n, "blur", angle]): what R sees from P.
            let r = vec_t(arg(ex, args, 3), n);
            let ncoord = arg(ex, args, 2).f().first() as usize;
            let (samples, blur) = map_params(ex, args, 3 + ncoord.max(1), span);
            let p = ex
                .prog
                .global("P")
                .map(|g| vec_t(&ex.regs[g.reg as usize], n))
                .unwrap_or_else(|| vec![Vec3::ZERO; n]);
            let count = samples.round().clamp(1.0, 1024.0) as u32;
            let mut acc = vec![Vec3::ZERO; n];
            let salt = span.start.wrapping_mul(0x9e37_79b9) ^ 0xe27;
            let spread = if count > 1 && blur > 0.0 {
                sample_spread(blur, count)
            } else {
                0.0
            };
            for k in 0..count {
                let dirs: Vec<Vec3> = (0..n)
                    .map(|i| {
                        if count == 1 || blur <= 0.0 {
                            return r[i];
                        }
                        let (a, b) = stratified(point_seed(p[i], salt), k, count);
                        cone_dir(r[i].normalize_or_zero(), a, b, blur) * r[i].length()
                    })
                    .collect();
                let ci = trace_rays(ex, &p, &dirs, &r, spread, bits);
                for (a, c) in acc.iter_mut().zip(ci) {
                    *a += c / count as f32;
                }
            }
            if f == EnvironmentF {
                Slot::VF(acc.iter().map(|c| lum(*c)).collect())
            } else {
                Slot::VT(acc)
            }
        }
        _ => return false,
    };
    // A hit's footprint neighbours take its answer.
    let out = match out {
        Slot::VF(mut v) if triples && v.len() == n => {
            for c in v.chunks_exact_mut(3) {
                (c[1], c[2]) = (c[0], c[0]);
            }
            Slot::VF(v)
        }
        Slot::VT(mut v) if triples && v.len() == n => {
            for c in v.chunks_exact_mut(3) {
                (c[1], c[2]) = (c[0], c[0]);
            }
            Slot::VT(v)
        }
        o => o,
    };
    let varying = ex.prog.regs[dst as usize].varying;
    let out = if varying && !out.is_varying() {
        crate::shade::exec::broadcast(&out, n)
    } else if !varying && out.is_varying() {
        match out {
            Slot::VF(v) => Slot::F(v.first().copied().unwrap_or(0.0)),
            Slot::VT(v) => Slot::T(v.first().copied().unwrap_or(Vec3::ZERO)),
            o => o,
        }
    } else {
        out
    };
    put(ex, dst, out);
    true
}

/// The "name", value pairs from `args[first..]`.
fn params(ex: &Exec, args: &[Reg], first: usize) -> Vec<(std::sync::Arc<str>, Slot)> {
    let mut out = Vec::new();
    let mut k = first;
    while k + 1 < args.len() {
        out.push((arg(ex, args, k).s(), arg(ex, args, k + 1).clone()));
        k += 2;
    }
    out
}

/// "samples" and "blur" of a `shadow`/`environment` "raytrace" call.
fn map_params(ex: &Exec, args: &[Reg], first: usize, span: Span) -> (f32, f32) {
    let (mut samples, mut blur) = (1.0, 0.0);
    for (name, v) in params(ex, args, first) {
        match &*name {
            "samples" => samples = v.f().first(),
            "blur" => blur = v.f().first(),
            "bias" | "width" | "swidth" | "twidth" | "filter" | "fill" | "label" | "subset" => {}
            other => ex.warn(
                span,
                format!("raytrace parameter \"{other}\" is not supported; ignored"),
            ),
        }
    }
    (samples, blur.max(0.0))
}

/// Ci along each active ray (black without a ray tracer); `axis` is the direction the rays
/// are spread around (`r` itself for one ray per point) and `extra` the spread the sampling
/// adds (see [`cones`]).
fn trace_rays(
    ex: &Exec,
    p: &[Vec3],
    r: &[Vec3],
    axis: &[Vec3],
    extra: f32,
    active: &[bool],
) -> Vec<Vec3> {
    let n = p.len();
    let mut ci = vec![Vec3::ZERO; n];
    if let Some(rt) = ex.env.rays {
        let mut dist = vec![0f32; n];
        let cones = cones(ex, p, axis, extra);
        rt.trace(p, r, &cones, active, &mut ci, &mut dist);
    }
    ci
}

/// The solid angle of a cone of half-angle `angle`, per sample, as a spread angle
/// (√Ω: the side of a square of that solid angle).
pub(crate) fn sample_spread(angle: f32, count: u32) -> f32 {
    if count <= 1 && angle <= 0.0 {
        return 0.0;
    }
    let omega = 2.0 * std::f32::consts::PI * (1.0 - angle.clamp(0.0, std::f32::consts::PI).cos());
    (omega / count.max(1) as f32).sqrt()
}

/// The ray cones of rays cast from `p` around the directions `axis`: width the footprint of
/// the shading point (the largest difference of `p` to a neighbour along u or v), spread the
/// largest difference of the unit axis to a neighbour plus `extra`. On a grid of ray hits
/// without neighbours (no derivatives wanted), the incoming cone at each hit, its spread
/// passed on.
pub(crate) fn cones(ex: &Exec, p: &[Vec3], axis: &[Vec3], extra: f32) -> Vec<Cone> {
    let n = p.len();
    let (nu, nv) = (ex.env.nu, ex.env.nv);
    if has_neighbours(nu, nv, n) && axis.len() == n {
        let (pu, pv) = (deriv_t(p, nu, nv, 0, 1.0), deriv_t(p, nu, nv, 1, 1.0));
        let unit: Vec<Vec3> = axis.iter().map(|v| v.normalize_or_zero()).collect();
        let (ru, rv) = (
            deriv_t(&unit, nu, nv, 0, 1.0),
            deriv_t(&unit, nu, nv, 1, 1.0),
        );
        return (0..n)
            .map(|i| Cone {
                width: pu[i].length().max(pv[i].length()),
                spread: ru[i].length().max(rv[i].length()) + extra,
            })
            .collect();
    }
    match ex.env.cones {
        Some(c) if c.len() == n => c
            .iter()
            .map(|c| Cone {
                width: c.width,
                spread: c.spread + extra,
            })
            .collect(),
        _ => vec![
            Cone {
                width: 0.0,
                spread: extra,
            };
            n
        ],
    }
}

/// Transmission from `a` to `b`, averaged over `samples` targets jittered in a cone of
/// half-angle `cone` around the segment.
fn transmit(
    ex: &Exec,
    a: &[Vec3],
    b: &[Vec3],
    active: &[bool],
    samples: f32,
    cone: f32,
    span: Span,
) -> Vec<Vec3> {
    let n = a.len();
    let mut acc = vec![Vec3::ZERO; n];
    let Some(rt) = ex.env.rays else {
        return vec![Vec3::ONE; n];
    };
    let count = if cone > 0.0 {
        samples.round().clamp(1.0, 1024.0) as u32
    } else {
        1
    };
    let salt = span.start.wrapping_mul(0x85eb_ca6b) ^ 0x5a1;
    let mut out = vec![Vec3::ONE; n];
    for k in 0..count {
        let to: Vec<Vec3> = if count == 1 {
            b.to_vec()
        } else {
            (0..n)
                .map(|i| {
                    let d = b[i] - a[i];
                    let len = d.length().min(FAR);
                    let (u1, u2) = stratified(point_seed(a[i], salt), k, count);
                    a[i] + cone_dir(d.normalize_or_zero(), u1, u2, cone) * len
                })
                .collect()
        };
        rt.transmission(a, &to, active, &mut out);
        for (s, o) in acc.iter_mut().zip(&out) {
            *s += *o / count as f32;
        }
    }
    acc
}

/// Diffuse bounces allowed: `Attribute`/`Option "trace" "maxdiffusedepth"`, else 1 (PRMan's
/// default). Past it indirectdiffuse() casts no rays and reads black, so a diffuse shader
/// seen by its own indirectdiffuse() rays does not recurse (samples to the power of the ray
/// depth).
fn max_diffuse_depth(ex: &Exec) -> u32 {
    for which in ["attribute", "option"] {
        if let Some(InfoValue::Floats(v)) = (ex.env.info)(which, "trace:maxdiffusedepth") {
            if let Some(x) = v.first().filter(|x| x.is_finite() && **x >= 0.0) {
                return (*x as u32).min(16);
            }
        }
    }
    1
}

/// occlusion (`occl` true: the blocked fraction) or indirectdiffuse (the mean Ci seen).
#[allow(clippy::too_many_arguments)]
fn hemisphere(
    ex: &Exec,
    occl: bool,
    p: &[Vec3],
    nn: &[Vec3],
    active: &[bool],
    count: u32,
    maxdist: f32,
    cone: f32,
    env_color: Vec3,
    span: Span,
) -> Slot {
    let n = p.len();
    let Some(rt) = ex.env.rays else {
        return if occl {
            Slot::F(0.0)
        } else {
            Slot::T(Vec3::ZERO)
        };
    };
    let salt = span.start.wrapping_mul(0xc2b2_ae35) ^ if occl { 0x0cc } else { 0x1d1 };
    let units: Vec<Vec3> = nn.iter().map(|v| v.normalize_or_zero()).collect();
    if !occl {
        if rays::diffuse_depth() >= max_diffuse_depth(ex) {
            return Slot::T(Vec3::ZERO);
        }
        let cones = cones(ex, p, &units, sample_spread(cone, count));
        let seen = rays::mean_radiance(
            rt, p, &units, &cones, active, count, maxdist, cone, env_color, salt,
        );
        return Slot::VT(seen);
    }
    let mut acc = vec![0f32; n];
    let mut buf = vec![Vec3::ONE; n];
    for k in 0..count {
        let to: Vec<Vec3> = (0..n)
            .map(|i| {
                let (u1, u2) = stratified(point_seed(p[i], salt), k, count);
                p[i] + cosine_dir(units[i], u1, u2, cone) * maxdist
            })
            .collect();
        rt.transmission(p, &to, active, &mut buf);
        for (a, t) in acc.iter_mut().zip(&buf) {
            *a += 1.0 - lum(*t);
        }
    }
    let inv = 1.0 / count as f32;
    Slot::VF(acc.iter().map(|a| a * inv).collect())
}
