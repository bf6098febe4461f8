//! Computation instructions and built-in functions over whole grids.
//!
//! Input: an instruction whose operands are registers of an [`Exec`]. Output: the destination
//! register (and output-argument temporaries). Invariants: never panics on any value (division
//! by zero, NaN, out-of-range): a defined value is written and a warning is reported once per
//! shader; results are uniform when every operand is uniform.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{IVec3, Mat3, Mat4, Vec3, Vec4};

use crate::pattern::noise as pn;
use crate::shade::color;
use crate::shade::exec::{Exec, InfoValue, TextureParams};
use crate::shade::value::*;
use crate::sl::builtins::Builtin;
use crate::sl::ir::*;

#[path = "rayops.rs"]
pub(crate) mod rayops;

fn take(ex: &mut Exec, r: Reg) -> Slot {
    std::mem::take(&mut ex.regs[r as usize])
}

fn put(ex: &mut Exec, r: Reg, s: Slot) {
    let slot = &mut ex.regs[r as usize];
    match slot {
        // What `take` left (or another plain value): nothing to drop, so no call of the
        // slot's destructor per instruction.
        Slot::F(_) | Slot::T(_) => {
            // SAFETY: `slot` is a valid, initialised `Slot` whose variant owns no heap
            // memory, so overwriting it without dropping it leaks nothing.
            unsafe { std::ptr::write(slot, s) }
        }
        _ => *slot = s,
    }
}

/// `a / b`, 0 where `b` is 0 (as a select, so loops of it vectorise).
#[inline]
fn safe_div(a: f32, b: f32) -> f32 {
    let q = a / b;
    if b == 0.0 {
        0.0
    } else {
        q
    }
}

/// Whether a running point divides by zero.
fn divides_by_zero(y: F, mask: &crate::shade::exec::Mask) -> bool {
    match y {
        F::U(v) => v == 0.0,
        F::V(v) => match mask.lanes() {
            Lanes::Some(idx) => idx.iter().any(|&i| v[i as usize] == 0.0),
            Lanes::All => zero_at_running(v, &mask.bits),
        },
    }
}

crate::shade::value::kernel! {
    /// Whether `v` is zero at a point whose flag is set (no early exit: a vector loop).
    fn zero_at_running<>(v: &[f32], running: &[bool]) -> bool {
        let mut z = 0u8;
        for (&x, &m) in v.iter().zip(running) {
            z |= (m as u8) & ((x == 0.0) as u8);
        }
        z != 0
    }
}

/// `Deriv(num, den) = Du(num)/Du(den) + Dv(num)/Dv(den)` (RISpec) as weights on Du(num) and
/// Dv(num). A direction along which `den` barely changes (relative to the other) contributes
/// nothing: `den = s` on a patch has a Dv(s) of rounding noise (1e-8), and dividing by it
/// made `Deriv(P, s)` explode in a pattern of the noise (superplank's grain scale).
fn deriv_weights(du_den: f32, dv_den: f32) -> (f32, f32) {
    let scale = du_den.abs().max(dv_den.abs());
    let w = |x: f32| {
        if x.abs() > 1e-4 * scale && x != 0.0 {
            1.0 / x
        } else {
            0.0
        }
    };
    (w(du_den), w(dv_den))
}

#[inline]
/// SL `clamp` as the renderers of the era wrote it (see the `ClampF` op).
pub fn clamp_like_c(x: f32, lo: f32, hi: f32) -> f32 {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

fn normalize(v: Vec3) -> Vec3 {
    let l = v.length();
    if l > 0.0 {
        v / l
    } else {
        Vec3::ZERO
    }
}

/// Runs one computation instruction.
/// `mask` is the running mask: faults are only reported for points that are running.
/// Pointwise instructions compute the points [`Exec::lanes_for`] gives (all of them, or just
/// the running ones when few run); the others every point.
pub fn compute(ex: &mut Exec, ins: &Instr, mask: &crate::shade::exec::Mask) {
    let n = ex.n;
    let lanes = match ins.pointwise_dst() {
        Some(d) => ex.lanes_for(d, mask),
        None => Lanes::All,
    };
    match ins {
        Instr::Arith {
            op,
            kind,
            dst,
            a,
            b,
            span,
        } => {
            let mut out = take(ex, *dst);
            let (ra, rb) = (&ex.regs[*a as usize], &ex.regs[*b as usize]);
            match kind {
                Kind::Float => {
                    let (x, y) = (ra.f(), rb.f());
                    match op {
                        Arith::Add => k2(&mut out, n, lanes, x, y, |a: f32, b: f32| a + b),
                        Arith::Sub => k2(&mut out, n, lanes, x, y, |a: f32, b: f32| a - b),
                        Arith::Mul => k2(&mut out, n, lanes, x, y, |a: f32, b: f32| a * b),
                        Arith::Div => {
                            let zero = !mask.is_none() && divides_by_zero(y, mask);
                            k2(&mut out, n, lanes, x, y, safe_div);
                            if zero {
                                put(ex, *dst, out);
                                ex.warn(*span, "division by zero (result set to 0)");
                                return;
                            }
                        }
                    }
                }
                Kind::Triple => {
                    let (x, y) = (ra.t(), rb.t());
                    match op {
                        Arith::Add => t2c(&mut out, n, lanes, x, y, |a, b| a + b),
                        Arith::Sub => t2c(&mut out, n, lanes, x, y, |a, b| a - b),
                        Arith::Mul => t2c(&mut out, n, lanes, x, y, |a, b| a * b),
                        Arith::Div => t2c(&mut out, n, lanes, x, y, safe_div),
                    }
                }
                Kind::Matrix => {
                    let (x, y) = (ra.m(), rb.m());
                    let v = x.is_varying() || y.is_varying();
                    match op {
                        Arith::Add => write_m(&mut out, n, v, |i| x.at(i) + y.at(i)),
                        Arith::Sub => write_m(&mut out, n, v, |i| x.at(i) - y.at(i)),
                        // RSL row-vector a*b is glam b*a (matrices are stored transposed).
                        Arith::Mul => write_m(&mut out, n, v, |i| y.at(i) * x.at(i)),
                        Arith::Div => write_m(&mut out, n, v, |i| inverse(y.at(i)) * x.at(i)),
                    }
                }
                Kind::Str => out = Slot::S(crate::shade::value::empty_str()),
            }
            put(ex, *dst, out);
        }
        Instr::Neg { kind, dst, a } => {
            let mut out = take(ex, *dst);
            let ra = &ex.regs[*a as usize];
            match kind {
                Kind::Float => k1(&mut out, n, lanes, ra.f(), |x: f32| -x),
                Kind::Triple => t1c(&mut out, n, lanes, ra.t(), |x| -x),
                Kind::Matrix => {
                    let x = ra.m();
                    write_m(&mut out, n, x.is_varying(), |i| -x.at(i))
                }
                Kind::Str => {}
            }
            put(ex, *dst, out);
        }
        Instr::Promote { to, dst, a } => {
            let mut out = take(ex, *dst);
            let x = ex.regs[*a as usize].f();
            match to {
                Kind::Matrix => write_m(&mut out, n, x.is_varying(), |i| Mat4::IDENTITY * x.at(i)),
                _ => k1(&mut out, n, lanes, x, Vec3::splat),
            }
            put(ex, *dst, out);
        }
        Instr::Dot { dst, a, b } => {
            let mut out = take(ex, *dst);
            let (x, y) = (ex.regs[*a as usize].t(), ex.regs[*b as usize].t());
            k2(&mut out, n, lanes, x, y, |a: Vec3, b: Vec3| a.dot(b));
            put(ex, *dst, out);
        }
        Instr::Cross { dst, a, b } => {
            let mut out = take(ex, *dst);
            let (x, y) = (ex.regs[*a as usize].t(), ex.regs[*b as usize].t());
            k2(&mut out, n, lanes, x, y, |a: Vec3, b: Vec3| a.cross(b));
            put(ex, *dst, out);
        }
        Instr::Compare {
            op,
            kind,
            dst,
            a,
            b,
        } => {
            let mut out = take(ex, *dst);
            let (ra, rb) = (&ex.regs[*a as usize], &ex.regs[*b as usize]);
            let (x, y) = (ra.f(), rb.f());
            match (kind, op) {
                (Kind::Float, Cmp::Eq) => k2(&mut out, n, lanes, x, y, |x, y| b2f(x == y)),
                (Kind::Float, Cmp::Ne) => k2(&mut out, n, lanes, x, y, |x, y| b2f(x != y)),
                (Kind::Float, Cmp::Lt) => k2(&mut out, n, lanes, x, y, |x, y| b2f(x < y)),
                (Kind::Float, Cmp::Le) => k2(&mut out, n, lanes, x, y, |x, y| b2f(x <= y)),
                (Kind::Float, Cmp::Gt) => k2(&mut out, n, lanes, x, y, |x, y| b2f(x > y)),
                (Kind::Float, Cmp::Ge) => k2(&mut out, n, lanes, x, y, |x, y| b2f(x >= y)),
                (Kind::Triple, c) => {
                    let eq = *c == Cmp::Eq;
                    k2(&mut out, n, lanes, ra.t(), rb.t(), |x: Vec3, y: Vec3| {
                        b2f((x == y) == eq)
                    })
                }
                (Kind::Matrix, c) => {
                    let (x, y) = (ra.m(), rb.m());
                    let eq = *c == Cmp::Eq;
                    write_f(&mut out, n, x.is_varying() || y.is_varying(), |i| {
                        b2f((x.at(i) == y.at(i)) == eq)
                    })
                }
                (Kind::Str, c) => {
                    let eq = ra.s() == rb.s();
                    out = Slot::F(b2f(eq == (*c == Cmp::Eq)));
                }
            }
            put(ex, *dst, out);
        }
        Instr::And { dst, a, b } => {
            let mut out = take(ex, *dst);
            let (x, y) = (ex.regs[*a as usize].f(), ex.regs[*b as usize].f());
            k2(&mut out, n, lanes, x, y, |x, y| b2f(x != 0.0 && y != 0.0));
            put(ex, *dst, out);
        }
        Instr::Or { dst, a, b } => {
            let mut out = take(ex, *dst);
            let (x, y) = (ex.regs[*a as usize].f(), ex.regs[*b as usize].f());
            k2(&mut out, n, lanes, x, y, |x, y| b2f(x != 0.0 || y != 0.0));
            put(ex, *dst, out);
        }
        Instr::Not { dst, a } => {
            let mut out = take(ex, *dst);
            let x = ex.regs[*a as usize].f();
            k1(&mut out, n, lanes, x, |x: f32| b2f(x == 0.0));
            put(ex, *dst, out);
        }
        Instr::Select {
            kind,
            dst,
            cond,
            a,
            b,
        } => {
            let mut out = take(ex, *dst);
            let c = ex.regs[*cond as usize].f();
            let (ra, rb) = (&ex.regs[*a as usize], &ex.regs[*b as usize]);
            let v = c.is_varying() || ra.is_varying() || rb.is_varying();
            match kind {
                Kind::Float => k3(&mut out, n, lanes, c, ra.f(), rb.f(), |c, x, y| {
                    if c != 0.0 {
                        x
                    } else {
                        y
                    }
                }),
                Kind::Triple => k3(&mut out, n, lanes, c, ra.t(), rb.t(), |c, x, y| {
                    if c != 0.0 {
                        x
                    } else {
                        y
                    }
                }),
                Kind::Matrix => {
                    let (x, y) = (ra.m(), rb.m());
                    write_m(&mut out, n, v, |i| {
                        if c.at(i) != 0.0 {
                            x.at(i)
                        } else {
                            y.at(i)
                        }
                    })
                }
                Kind::Str => {
                    out = if c.first() != 0.0 {
                        ra.clone()
                    } else {
                        rb.clone()
                    }
                }
            }
            put(ex, *dst, out);
        }
        Instr::MakeTriple { dst, x, y, z } => {
            let mut out = take(ex, *dst);
            let (a, b, c) = (
                ex.regs[*x as usize].f(),
                ex.regs[*y as usize].f(),
                ex.regs[*z as usize].f(),
            );
            k3(&mut out, n, lanes, a, b, c, Vec3::new);
            put(ex, *dst, out);
        }
        Instr::MakeMatrix { dst, elems } => {
            let mut out = take(ex, *dst);
            let vals: Vec<F> = elems.iter().map(|r| ex.regs[*r as usize].f()).collect();
            let v = vals.iter().any(|x| x.is_varying());
            write_m(&mut out, n, v, |i| {
                let mut a = [0f32; 16];
                for (k, x) in vals.iter().enumerate() {
                    a[k] = x.at(i);
                }
                Mat4::from_cols_array(&a)
            });
            put(ex, *dst, out);
        }
        Instr::ColorFrom {
            dst,
            space,
            a,
            span,
        } => {
            let mut out = take(ex, *dst);
            let sp = ex.regs[*space as usize].s();
            let x = ex.regs[*a as usize].t();
            let ok = color::is_space(&sp);
            write_t(&mut out, n, x.is_varying(), |i| color::to_rgb(&sp, x.at(i)));
            put(ex, *dst, out);
            if !ok {
                ex.warn(
                    *span,
                    format!("unknown colour space \"{sp}\" (treated as rgb)"),
                );
            }
        }
        Instr::SpaceMatrix { dst, space, span } => {
            let sp = ex.regs[*space as usize].s();
            let m = space_matrix(ex, &sp, *span);
            put(ex, *dst, Slot::M(Box::new(m)));
        }
        Instr::Transform {
            kind,
            dst,
            from,
            to,
            a,
            span,
        } => {
            let mut out = take(ex, *dst);
            let fm = space_operand(ex, *from, true, *span);
            let tm = space_operand(ex, *to, false, *span);
            let x = ex.regs[*a as usize].t();
            let v = x.is_varying() || fm.is_varying() || tm.is_varying();
            let k = *kind;
            write_t(&mut out, n, v, |i| {
                let m = tm.at(i) * fm.at(i);
                apply(k, m, x.at(i))
            });
            put(ex, *dst, out);
        }
        Instr::GetIndex {
            kind,
            dst,
            base,
            len,
            index,
            span,
        } => {
            let mut out = take(ex, *dst);
            let idx = ex.regs[*index as usize].f();
            let len = *len as i64;
            let mut bad = false;
            let pick = |i: usize, bad: &mut bool| -> usize {
                let k = idx.at(i) as i64;
                if k < 0 || k >= len {
                    *bad = true;
                }
                (*base as i64 + k.clamp(0, len - 1)) as usize
            };
            let v = idx.is_varying() || ex.prog.regs[*dst as usize].varying;
            match kind {
                Kind::Float => {
                    let mut o = if v { take_vf(&mut out, n) } else { vec![0.0] };
                    for (i, oi) in o.iter_mut().enumerate() {
                        let r = pick(i, &mut bad);
                        *oi = ex.regs[r].f().at(i);
                    }
                    out = if v { Slot::VF(o) } else { Slot::F(o[0]) };
                }
                Kind::Triple => {
                    let mut o = if v {
                        take_vt(&mut out, n)
                    } else {
                        vec![Vec3::ZERO]
                    };
                    for (i, oi) in o.iter_mut().enumerate() {
                        let r = pick(i, &mut bad);
                        *oi = ex.regs[r].t().at(i);
                    }
                    out = if v { Slot::VT(o) } else { Slot::T(o[0]) };
                }
                Kind::Matrix => {
                    let r = pick(0, &mut bad);
                    out = ex.regs[r].clone();
                }
                Kind::Str => {
                    let r = pick(0, &mut bad);
                    out = ex.regs[r].clone();
                }
            }
            put(ex, *dst, out);
            if bad {
                ex.warn(*span, "array index out of range (clamped)");
            }
        }
        Instr::Call { f, dst, args, span } => {
            if !rayops::call(ex, *f, *dst, args, *span, mask) {
                call(ex, *f, *dst, args, *span, lanes)
            }
        }
        _ => {}
    }
}

#[inline]
fn b2f(b: bool) -> f32 {
    if b {
        1.0
    } else {
        0.0
    }
}

fn inverse(m: Mat4) -> Mat4 {
    let d = m.determinant();
    if d == 0.0 || !d.is_finite() {
        Mat4::ZERO
    } else {
        m.inverse()
    }
}

#[inline]
fn apply(k: XformKind, m: Mat4, p: Vec3) -> Vec3 {
    match k {
        XformKind::Point => {
            let h = m * Vec4::new(p.x, p.y, p.z, 1.0);
            if h.w != 0.0 && h.w != 1.0 {
                h.truncate() / h.w
            } else {
                h.truncate()
            }
        }
        XformKind::Vector => m.transform_vector3(p),
        XformKind::Normal => {
            let m3 = Mat3::from_mat4(m);
            let d = m3.determinant();
            if d == 0.0 {
                p
            } else {
                m3.inverse().transpose() * p
            }
        }
    }
}

/// camera_from_space for a named space; identity with a warning when unknown.
fn space_matrix(ex: &Exec, name: &str, span: crate::diag::Span) -> Mat4 {
    match (ex.env.spaces)(name) {
        Some(m) => m,
        None => {
            ex.warn(
                span,
                format!("unknown coordinate system \"{name}\" (identity used)"),
            );
            Mat4::IDENTITY
        }
    }
}

/// The matrix for a transform operand: `from` spaces map to current (camera), `to` spaces map
/// from current.
fn space_operand<'a>(ex: &'a Exec, s: Space, from: bool, span: crate::diag::Span) -> M<'a> {
    match s {
        Space::Current => M::U(Mat4::IDENTITY),
        Space::Named(r) => {
            let m = space_matrix(ex, &ex.regs[r as usize].s(), span);
            M::U(if from { m } else { inverse(m) })
        }
        Space::Matrix(r) => {
            // transform(m, p): m maps current to the target directly.
            let m = ex.regs[r as usize].m();
            if from {
                M::U(Mat4::IDENTITY)
            } else {
                m
            }
        }
    }
}

fn arg<'a>(ex: &'a Exec, args: &[Reg], i: usize) -> &'a Slot {
    &ex.regs[args[i] as usize]
}

/// `Env::nu` of a grid of ray hits shaded with their ray differentials (`Env::nv` is then the
/// number of hits): points `3h`, `3h + 1` and `3h + 2` are hit `h` and the surface one ray
/// footprint away from it along u and along v (see `shade::rays`). Derivatives are the
/// differences across the footprint divided by the step (`du`, `dv`), the same at the three
/// points, so `Du(x)·du` is the change of `x` over the ray's footprint as it is over a
/// micropolygon on a camera grid.
pub const TRIPLES: usize = usize::MAX;

/// Whether the points of a grid of `n` laid out as `nu × nv` (or as [`TRIPLES`]) have
/// neighbours to take differences across.
pub fn has_neighbours(nu: usize, nv: usize, n: usize) -> bool {
    n > 0
        && if nu == TRIPLES {
            nv.checked_mul(3) == Some(n)
        } else {
            nu.checked_mul(nv) == Some(n)
        }
}

/// Central differences along u (`dir` 0) or v (`dir` 1) of a float field, divided by the step
/// (forward differences across the footprint on a [`TRIPLES`] layout).
pub fn deriv_f(x: &[f32], nu: usize, nv: usize, dir: usize, step: f32) -> Vec<f32> {
    let n = x.len();
    let mut out = vec![0.0; n];
    if !has_neighbours(nu, nv, n) {
        return out;
    }
    let inv = if step != 0.0 { 1.0 / step } else { 0.0 };
    if nu == TRIPLES {
        for (o, c) in out.chunks_exact_mut(3).zip(x.chunks_exact(3)) {
            let d = (c[1 + dir.min(1)] - c[0]) * inv;
            o.fill(d);
        }
        return out;
    }
    for j in 0..nv {
        for i in 0..nu {
            let k = j * nu + i;
            let (a, b, d) = if dir == 0 {
                if nu < 2 {
                    (k, k, 1.0)
                } else if i == 0 {
                    (k, k + 1, 1.0)
                } else if i == nu - 1 {
                    (k - 1, k, 1.0)
                } else {
                    (k - 1, k + 1, 2.0)
                }
            } else if nv < 2 {
                (k, k, 1.0)
            } else if j == 0 {
                (k, k + nu, 1.0)
            } else if j == nv - 1 {
                (k - nu, k, 1.0)
            } else {
                (k - nu, k + nu, 2.0)
            };
            out[k] = (x[b] - x[a]) * inv / d;
        }
    }
    out
}

pub fn deriv_t(x: &[Vec3], nu: usize, nv: usize, dir: usize, step: f32) -> Vec<Vec3> {
    let xs: Vec<f32> = x.iter().map(|p| p.x).collect();
    let ys: Vec<f32> = x.iter().map(|p| p.y).collect();
    let zs: Vec<f32> = x.iter().map(|p| p.z).collect();
    let (a, b, c) = (
        deriv_f(&xs, nu, nv, dir, step),
        deriv_f(&ys, nu, nv, dir, step),
        deriv_f(&zs, nu, nv, dir, step),
    );
    (0..x.len()).map(|i| Vec3::new(a[i], b[i], c[i])).collect()
}

/// `N` turned, if needed, to face against `I` as judged by `nref` (RISpec `faceforward`):
/// flipped when `I` and `nref` point the same way; kept when they are perpendicular.
#[inline]
fn face_forward(n: Vec3, i: Vec3, nref: Vec3) -> Vec3 {
    if i.dot(nref) > 0.0 {
        -n
    } else {
        n
    }
}

fn global_f(ex: &Exec, name: &str) -> f32 {
    ex.prog
        .global(name)
        .map(|g| ex.regs[g.reg as usize].f().first())
        .unwrap_or(0.0)
}

fn du_dv(ex: &Exec) -> (f32, f32) {
    (global_f(ex, "du"), global_f(ex, "dv"))
}

fn vec_f(s: &Slot, n: usize) -> Vec<f32> {
    let f = s.f();
    (0..n).map(|i| f.at(i)).collect()
}

fn vec_t(s: &Slot, n: usize) -> Vec<Vec3> {
    let t = s.t();
    (0..n).map(|i| t.at(i)).collect()
}

/// Catmull-Rom style spline evaluation over knots with a basis (RISpec §15.1).
pub fn spline_eval<V>(basis: &str, x: f32, knots: &[V]) -> V
where
    V: Copy + std::ops::Mul<f32, Output = V> + std::ops::Add<Output = V>,
{
    let (m, step): ([[f32; 4]; 4], usize) = match basis {
        "bezier" => (
            [
                [-1., 3., -3., 1.],
                [3., -6., 3., 0.],
                [-3., 3., 0., 0.],
                [1., 0., 0., 0.],
            ],
            3,
        ),
        "b-spline" | "bspline" => (
            [
                [-1. / 6., 3. / 6., -3. / 6., 1. / 6.],
                [3. / 6., -6. / 6., 3. / 6., 0.],
                [-3. / 6., 0., 3. / 6., 0.],
                [1. / 6., 4. / 6., 1. / 6., 0.],
            ],
            1,
        ),
        "hermite" => (
            [
                [2., 1., -2., 1.],
                [-3., -2., 3., -1.],
                [0., 1., 0., 0.],
                [1., 0., 0., 0.],
            ],
            2,
        ),
        "power" => (
            [
                [1., 0., 0., 0.],
                [0., 1., 0., 0.],
                [0., 0., 1., 0.],
                [0., 0., 0., 1.],
            ],
            4,
        ),
        "linear" => (
            [
                [0., 0., 0., 0.],
                [0., 0., 0., 0.],
                [0., -1., 1., 0.],
                [0., 1., 0., 0.],
            ],
            1,
        ),
        _ => (
            [
                [-0.5, 1.5, -1.5, 0.5],
                [1., -2.5, 2., -0.5],
                [-0.5, 0., 0.5, 0.],
                [0., 1., 0., 0.],
            ],
            1,
        ),
    };
    let nk = knots.len();
    if nk < 4 {
        return knots[0] * 1.0;
    }
    let nseg = (nk - 4) / step + 1;
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let fx = x * nseg as f32;
    let seg = (fx.floor() as usize).min(nseg - 1);
    let t = fx - seg as f32;
    let c = &knots[seg * step..seg * step + 4];
    // power basis: coefficients are the knots directly (highest power first per RISpec).
    let tp = [t * t * t, t * t, t, 1.0];
    let mut w = [0f32; 4];
    for (k, wk) in w.iter_mut().enumerate() {
        for r in 0..4 {
            *wk += tp[r] * m[r][k];
        }
    }
    if basis == "power" {
        return c[0] * tp[0] + c[1] * tp[1] + c[2] * tp[2] + c[3] * tp[3];
    }
    c[0] * w[0] + c[1] * w[1] + c[2] * w[2] + c[3] * w[3]
}

fn set_out(ex: &mut Exec, r: Reg, s: Slot) {
    let varying = ex.prog.regs[r as usize].varying;
    ex.regs[r as usize] = if varying && !s.is_varying() {
        crate::shade::exec::broadcast(&s, ex.n)
    } else {
        s
    };
}

#[allow(clippy::too_many_arguments)]
fn call(ex: &mut Exec, f: Builtin, dst: Reg, args: &[Reg], span: crate::diag::Span, lanes: Lanes) {
    use Builtin::*;
    let n = ex.n;
    let mut out = take(ex, dst);
    macro_rules! f1 {
        ($e:expr) => {{
            let a = arg(ex, args, 0).f();
            k1(&mut out, n, lanes, a, $e);
        }};
    }
    macro_rules! f2 {
        ($e:expr) => {{
            k2(
                &mut out,
                n,
                lanes,
                arg(ex, args, 0).f(),
                arg(ex, args, 1).f(),
                $e,
            );
        }};
    }
    macro_rules! f3 {
        ($e:expr) => {{
            let (a, b, c) = (
                arg(ex, args, 0).f(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).f(),
            );
            k3(&mut out, n, lanes, a, b, c, $e);
        }};
    }
    macro_rules! t1f {
        ($e:expr) => {{
            let a = arg(ex, args, 0).t();
            k1(&mut out, n, lanes, a, $e);
        }};
    }
    macro_rules! t1t {
        ($e:expr) => {{
            let a = arg(ex, args, 0).t();
            k1(&mut out, n, lanes, a, $e);
        }};
    }
    macro_rules! varying_any {
        () => {
            args.iter().any(|r| ex.regs[*r as usize].is_varying())
        };
    }
    match f {
        Radians => f1!(|x: f32| x.to_radians()),
        Degrees => f1!(|x: f32| x.to_degrees()),
        Sin => f1!(|x: f32| x.sin()),
        Cos => f1!(|x: f32| x.cos()),
        Tan => f1!(|x: f32| x.tan()),
        Asin => f1!(|x: f32| x.clamp(-1.0, 1.0).asin()),
        Acos => f1!(|x: f32| x.clamp(-1.0, 1.0).acos()),
        Atan1 => f1!(|x: f32| x.atan()),
        Atan2 => f2!(|y: f32, x: f32| y.atan2(x)),
        Pow => f2!(|x: f32, y: f32| {
            let r = x.powf(y);
            if r.is_finite() {
                r
            } else {
                0.0
            }
        }),
        Exp => f1!(exp_f),
        Sqrt => f1!(|x: f32| x.max(0.0).sqrt()),
        InvSqrt => f1!(|x: f32| if x > 0.0 { 1.0 / x.sqrt() } else { 0.0 }),
        Log => f1!(|x: f32| if x > 0.0 { x.ln() } else { -f32::MAX }),
        LogBase => f2!(|x: f32, b: f32| if x > 0.0 && b > 0.0 && b != 1.0 {
            x.ln() / b.ln()
        } else {
            0.0
        }),
        Mod => f2!(|a: f32, b: f32| if b == 0.0 {
            0.0
        } else {
            a - b * (a / b).floor()
        }),
        Abs => f1!(|x: f32| x.abs()),
        Sign => f1!(|x: f32| if x > 0.0 {
            1.0
        } else if x < 0.0 {
            -1.0
        } else {
            0.0
        }),
        Floor => f1!(|x: f32| x.floor()),
        Ceil => f1!(|x: f32| x.ceil()),
        Round => f1!(|x: f32| x.round()),
        IsNan => f1!(|x: f32| b2f(x.is_nan())),
        MinF | MaxF if args.len() == 2 => {
            if f == MaxF {
                f2!(|a: f32, b: f32| a.max(b))
            } else {
                f2!(|a: f32, b: f32| a.min(b))
            }
        }
        MinF | MaxF if args.len() == 3 => {
            if f == MaxF {
                f3!(|a: f32, b: f32, c: f32| a.max(b).max(c))
            } else {
                f3!(|a: f32, b: f32, c: f32| a.min(b).min(c))
            }
        }
        MinF | MaxF => {
            let ops: Vec<F> = args.iter().map(|r| ex.regs[*r as usize].f()).collect();
            let mx = f == MaxF;
            write_f_l(&mut out, n, lanes, varying_any!(), |i| {
                let mut r = ops[0].at(i);
                for o in &ops[1..] {
                    r = if mx { r.max(o.at(i)) } else { r.min(o.at(i)) };
                }
                r
            });
        }
        MinT | MaxT if args.len() == 2 => {
            let (a, b) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            if f == MaxT {
                t2c(&mut out, n, lanes, a, b, f32::max)
            } else {
                t2c(&mut out, n, lanes, a, b, f32::min)
            }
        }
        MinT | MaxT => {
            let ops: Vec<T> = args.iter().map(|r| ex.regs[*r as usize].t()).collect();
            let mx = f == MaxT;
            write_t_l(&mut out, n, lanes, varying_any!(), |i| {
                let mut r = ops[0].at(i);
                for o in &ops[1..] {
                    r = if mx { r.max(o.at(i)) } else { r.min(o.at(i)) };
                }
                r
            });
        }
        // `x < lo ? lo : x > hi ? hi : x` (the C macro Aqsis and BMRT use): when lo > hi a value
        // below lo still comes back as lo, so marching loops that step by
        // `clamp(step, minstep, end - d)` keep moving instead of stepping by zero forever.
        ClampF => f3!(clamp_like_c),
        ClampT => {
            let (x, a, b) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).t(),
            );
            k3(&mut out, n, lanes, x, a, b, |x: Vec3, a: Vec3, b: Vec3| {
                Vec3::new(
                    clamp_like_c(x.x, a.x, b.x),
                    clamp_like_c(x.y, a.y, b.y),
                    clamp_like_c(x.z, a.z, b.z),
                )
            });
        }
        MixF => f3!(|a: f32, b: f32, t: f32| a * (1.0 - t) + b * t),
        MixT => {
            let (a, b, t) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).f(),
            );
            k3(&mut out, n, lanes, a, b, t, |a: Vec3, b: Vec3, t: f32| {
                a * (1.0 - t) + b * t
            });
        }
        MixTT => {
            let (a, b, t) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).t(),
            );
            k3(&mut out, n, lanes, a, b, t, |a: Vec3, b: Vec3, t: Vec3| {
                a * (Vec3::ONE - t) + b * t
            });
        }
        Step => f2!(|e: f32, x: f32| b2f(x >= e)),
        SmoothStep => f3!(smoothstep),
        FilterStep => {
            // args: npos, edge, s1 [, s2], params…
            let npos = arg(ex, args, 0).f().first() as usize;
            let edge = arg(ex, args, 1).f();
            let s1 = arg(ex, args, 2).f();
            let s2 = if npos >= 3 {
                Some(arg(ex, args, 3).f())
            } else {
                None
            };
            let mut width = 1.0;
            let mut filter: Arc<str> = Arc::from("catmull-rom");
            let mut k = 1 + npos;
            while k + 1 < args.len() {
                let name = arg(ex, args, k).s();
                match &*name {
                    "width" | "swidth" | "twidth" => width = arg(ex, args, k + 1).f().first(),
                    "filter" => filter = arg(ex, args, k + 1).s(),
                    _ => {}
                }
                k += 2;
            }
            let (du, dv) = du_dv(ex);
            let (nu, nv) = (ex.env.nu, ex.env.nv);
            let s1v = vec_f(arg(ex, args, 2), n);
            let fw: Vec<f32> = match s2 {
                Some(s2) => (0..n).map(|i| (s2.at(i) - s1.at(i)).abs()).collect(),
                None => {
                    let a = deriv_f(&s1v, nu, nv, 0, 1.0);
                    let b = deriv_f(&s1v, nu, nv, 1, 1.0);
                    let _ = (du, dv);
                    (0..n).map(|i| a[i].abs() + b[i].abs()).collect()
                }
            };
            let box_filter = &*filter == "box";
            write_f(&mut out, n, true, |i| {
                let w = fw[i] * width;
                let x = match s2 {
                    Some(s2) => 0.5 * (s1.at(i) + s2.at(i)),
                    None => s1.at(i),
                };
                filtered_step(edge.at(i), x, w, box_filter)
            });
        }
        SplineF | SplineT | SplineBasisF | SplineBasisT | SplineArrayF | SplineArrayT
        | SplineBasisArrayF | SplineBasisArrayT => {
            let has_basis = matches!(
                f,
                SplineBasisF | SplineBasisT | SplineBasisArrayF | SplineBasisArrayT
            );
            let basis: Arc<str> = if has_basis {
                arg(ex, args, 0).s()
            } else {
                Arc::from("catmull-rom")
            };
            let o = usize::from(has_basis);
            let x = arg(ex, args, o).f();
            let knots = &args[o + 1..];
            let v = varying_any!();
            if knots.len() < 4 {
                ex.warn(span, "spline needs at least 4 knots");
            }
            if matches!(f, SplineF | SplineBasisF | SplineArrayF | SplineBasisArrayF) {
                let ks: Vec<F> = knots.iter().map(|r| ex.regs[*r as usize].f()).collect();
                write_f(&mut out, n, v, |i| {
                    let kv: Vec<f32> = ks.iter().map(|k| k.at(i)).collect();
                    if kv.is_empty() {
                        0.0
                    } else {
                        spline_eval(&basis, x.at(i), &kv)
                    }
                });
            } else {
                let ks: Vec<T> = knots.iter().map(|r| ex.regs[*r as usize].t()).collect();
                write_t(&mut out, n, v, |i| {
                    let kv: Vec<Vec3> = ks.iter().map(|k| k.at(i)).collect();
                    if kv.is_empty() {
                        Vec3::ZERO
                    } else {
                        spline_eval(&basis, x.at(i), &kv)
                    }
                });
            }
        }
        DuF | DvF => {
            let (du, dv) = du_dv(ex);
            let x = vec_f(arg(ex, args, 0), n);
            let d = if f == DuF {
                deriv_f(&x, ex.env.nu, ex.env.nv, 0, du)
            } else {
                deriv_f(&x, ex.env.nu, ex.env.nv, 1, dv)
            };
            out = Slot::VF(d);
        }
        DuT | DvT => {
            let (du, dv) = du_dv(ex);
            let x = vec_t(arg(ex, args, 0), n);
            let d = if f == DuT {
                deriv_t(&x, ex.env.nu, ex.env.nv, 0, du)
            } else {
                deriv_t(&x, ex.env.nu, ex.env.nv, 1, dv)
            };
            out = Slot::VT(d);
        }
        DerivF => {
            let (du, dv) = du_dv(ex);
            let (nu, nv) = (ex.env.nu, ex.env.nv);
            let num = vec_f(arg(ex, args, 0), n);
            let den = vec_f(arg(ex, args, 1), n);
            let (a, b) = (deriv_f(&num, nu, nv, 0, du), deriv_f(&num, nu, nv, 1, dv));
            let (c, d) = (deriv_f(&den, nu, nv, 0, du), deriv_f(&den, nu, nv, 1, dv));
            out = Slot::VF(
                (0..n)
                    .map(|i| {
                        let (su, sv) = deriv_weights(c[i], d[i]);
                        su * a[i] + sv * b[i]
                    })
                    .collect(),
            );
        }
        DerivT => {
            let (du, dv) = du_dv(ex);
            let (nu, nv) = (ex.env.nu, ex.env.nv);
            let num = vec_t(arg(ex, args, 0), n);
            let den = vec_f(arg(ex, args, 1), n);
            let (a, b) = (deriv_t(&num, nu, nv, 0, du), deriv_t(&num, nu, nv, 1, dv));
            let (c, d) = (deriv_f(&den, nu, nv, 0, du), deriv_f(&den, nu, nv, 1, dv));
            out = Slot::VT(
                (0..n)
                    .map(|i| {
                        let (su, sv) = deriv_weights(c[i], d[i]);
                        su * a[i] + sv * b[i]
                    })
                    .collect(),
            );
        }
        // A uniform result (stored into a `uniform` variable): one number per grid.
        RandomF if !ex.prog.regs[dst as usize].varying => {
            out = Slot::F(pn_hash(ex.env.seed, random_site(ex, span), u32::MAX, 0));
        }
        RandomT if !ex.prog.regs[dst as usize].varying => {
            let (seed, base) = (ex.env.seed, random_site(ex, span));
            out = Slot::T(Vec3::new(
                pn_hash(seed, base, u32::MAX, 0),
                pn_hash(seed, base, u32::MAX, 1),
                pn_hash(seed, base, u32::MAX, 2),
            ));
        }
        RandomF => {
            let seed = ex.env.seed;
            let base = random_site(ex, span);
            let ex = &*ex;
            write_f_l(&mut out, n, lanes, true, |i| {
                pn_hash(seed, base, ex.point_id(i), 0)
            });
        }
        RandomT => {
            let seed = ex.env.seed;
            let base = random_site(ex, span);
            write_t_l(&mut out, n, lanes, true, |i| {
                let i = ex.point_id(i);
                Vec3::new(
                    pn_hash(seed, base, i, 0),
                    pn_hash(seed, base, i, 1),
                    pn_hash(seed, base, i, 2),
                )
            });
        }
        NoiseF1 => f1!(pn::noise1),
        NoiseF2 => f2!(pn::noise2),
        NoiseF3 => {
            let a = arg(ex, args, 0).t();
            match (a, lanes) {
                (T::V(p), Lanes::All) => {
                    let mut v = take_vf(&mut out, n);
                    pn::noise3_slice(p, &mut v);
                    out = Slot::VF(v);
                }
                _ => k1(&mut out, n, lanes, a, pn::noise3),
            }
        }
        NoiseF4 => {
            let (a, b) = (arg(ex, args, 0).t(), arg(ex, args, 1).f());
            write_f(&mut out, n, varying_any!(), |i| {
                pn::noise4(a.at(i), b.at(i))
            });
        }
        NoiseT1 => {
            let a = arg(ex, args, 0).f();
            write_t(&mut out, n, a.is_varying(), |i| pn::vnoise1(a.at(i)));
        }
        NoiseT2 => {
            let (a, b) = (arg(ex, args, 0).f(), arg(ex, args, 1).f());
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vnoise2(a.at(i), b.at(i))
            });
        }
        NoiseT3 => t1t!(pn::vnoise3),
        NoiseT4 => {
            let (a, b) = (arg(ex, args, 0).t(), arg(ex, args, 1).f());
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vnoise4(a.at(i), b.at(i))
            });
        }
        PNoiseF1 => f2!(|x, p| pn::pnoise1(x, pn::period_from_float(p))),
        PNoiseF2 => {
            let (x, y, px, py) = (
                arg(ex, args, 0).f(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).f(),
                arg(ex, args, 3).f(),
            );
            write_f(&mut out, n, varying_any!(), |i| {
                pn::pnoise2(
                    x.at(i),
                    y.at(i),
                    pn::period_from_float(px.at(i)),
                    pn::period_from_float(py.at(i)),
                )
            });
        }
        PNoiseF3 => {
            let (p, per) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            write_f(&mut out, n, varying_any!(), |i| {
                pn::pnoise3(p.at(i), iper(per.at(i)))
            });
        }
        PNoiseF4 => {
            let (p, t, per, tp) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).t(),
                arg(ex, args, 3).f(),
            );
            write_f(&mut out, n, varying_any!(), |i| {
                pn::pnoise4(
                    p.at(i),
                    t.at(i),
                    iper(per.at(i)),
                    pn::period_from_float(tp.at(i)),
                )
            });
        }
        PNoiseT1 => {
            let (x, p) = (arg(ex, args, 0).f(), arg(ex, args, 1).f());
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vpnoise1(x.at(i), pn::period_from_float(p.at(i)))
            });
        }
        PNoiseT2 => {
            let (x, y, px, py) = (
                arg(ex, args, 0).f(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).f(),
                arg(ex, args, 3).f(),
            );
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vpnoise2(
                    x.at(i),
                    y.at(i),
                    pn::period_from_float(px.at(i)),
                    pn::period_from_float(py.at(i)),
                )
            });
        }
        PNoiseT3 => {
            let (p, per) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vpnoise3(p.at(i), iper(per.at(i)))
            });
        }
        PNoiseT4 => {
            let (p, t, per, tp) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).t(),
                arg(ex, args, 3).f(),
            );
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vpnoise4(
                    p.at(i),
                    t.at(i),
                    iper(per.at(i)),
                    pn::period_from_float(tp.at(i)),
                )
            });
        }
        CellF1 => f1!(pn::cellnoise1),
        CellF2 => f2!(pn::cellnoise2),
        CellF3 => t1f!(pn::cellnoise3),
        CellF4 => {
            let (a, b) = (arg(ex, args, 0).t(), arg(ex, args, 1).f());
            write_f(&mut out, n, varying_any!(), |i| {
                pn::cellnoise4(a.at(i), b.at(i))
            });
        }
        CellT1 => {
            let a = arg(ex, args, 0).f();
            write_t(&mut out, n, a.is_varying(), |i| pn::vcellnoise1(a.at(i)));
        }
        CellT2 => {
            let (a, b) = (arg(ex, args, 0).f(), arg(ex, args, 1).f());
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vcellnoise2(a.at(i), b.at(i))
            });
        }
        CellT3 => t1t!(pn::vcellnoise3),
        CellT4 => {
            let (a, b) = (arg(ex, args, 0).t(), arg(ex, args, 1).f());
            write_t(&mut out, n, varying_any!(), |i| {
                pn::vcellnoise4(a.at(i), b.at(i))
            });
        }
        XComp => t1f!(|v: Vec3| v.x),
        YComp => t1f!(|v: Vec3| v.y),
        ZComp => t1f!(|v: Vec3| v.z),
        SetXComp | SetYComp | SetZComp => {
            // args: &q (temp holding the current value), f
            let (q, x) = (arg(ex, args, 0).t(), arg(ex, args, 1).f());
            let c = match f {
                SetXComp => 0,
                SetYComp => 1,
                _ => 2,
            };
            let mut r = Slot::default();
            write_t(&mut r, n, varying_any!(), |i| {
                let mut v = q.at(i);
                v[c] = x.at(i);
                v
            });
            set_out(ex, args[0], r);
        }
        Length => t1f!(|v: Vec3| v.length()),
        Normalize => t1t!(normalize),
        Distance => {
            let (a, b) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            zip_tt_f(&mut out, n, a, b, |a, b| a.distance(b));
        }
        PtLineD => {
            let (q, p1, p2) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).t(),
            );
            write_f(&mut out, n, varying_any!(), |i| {
                ptlined(q.at(i), p1.at(i), p2.at(i))
            });
        }
        RotatePoint => {
            let (q, ang, p1, p2) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).t(),
                arg(ex, args, 3).t(),
            );
            write_t(&mut out, n, varying_any!(), |i| {
                let axis = normalize(p2.at(i) - p1.at(i));
                if axis == Vec3::ZERO {
                    return q.at(i);
                }
                let r = glam::Quat::from_axis_angle(axis, ang.at(i));
                p1.at(i) + r * (q.at(i) - p1.at(i))
            });
        }
        Area => {
            let (du, dv) = du_dv(ex);
            let p = vec_t(arg(ex, args, 0), n);
            let a = deriv_t(&p, ex.env.nu, ex.env.nv, 0, 1.0);
            let b = deriv_t(&p, ex.env.nu, ex.env.nv, 1, 1.0);
            let _ = (du, dv);
            out = Slot::VF((0..n).map(|i| a[i].cross(b[i]).length()).collect());
        }
        FaceForward2 => {
            // The two-argument form decides the side by the geometric normal Ng, as PRMan,
            // Aqsis and VEX do: a bumped N that tilts past the silhouette is kept, not flipped
            // to the far side (which turned grazing bumps black). Where the shader has no Ng
            // (lights, volumes) or Ng is zero, N itself is the reference. The compiler makes
            // the result varying when Ng is, so uniform N and I follow the same rule.
            let (nn, i_) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            let ng = ex.prog.global("Ng").map(|g| &ex.regs[g.reg as usize]);
            match ng {
                Some(ng) => {
                    let vary = varying_any!() || ng.is_varying();
                    let ng = ng.t();
                    write_t(&mut out, n, vary, |i| {
                        let (nv, iv, gv) = (nn.at(i), i_.at(i), ng.at(i));
                        face_forward(nv, iv, if gv == Vec3::ZERO { nv } else { gv })
                    })
                }
                None => zip_tt(&mut out, n, nn, i_, |nv, iv| face_forward(nv, iv, nv)),
            }
        }
        FaceForward3 => {
            let (nn, i_) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            let nref = arg(ex, args, 2).t();
            write_t(&mut out, n, varying_any!(), |i| {
                face_forward(nn.at(i), i_.at(i), nref.at(i))
            });
        }
        Reflect => {
            let (i_, nn) = (arg(ex, args, 0).t(), arg(ex, args, 1).t());
            zip_tt(&mut out, n, i_, nn, |i, n| i - 2.0 * i.dot(n) * n);
        }
        Refract => {
            let (i_, nn, eta) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).f(),
            );
            write_t(&mut out, n, varying_any!(), |i| {
                refract(i_.at(i), nn.at(i), eta.at(i))
            });
        }
        Fresnel | FresnelRT => {
            let (i_, nn, eta) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).f(),
            );
            let v = varying_any!();
            let res: Vec<(f32, f32, Vec3, Vec3)> = (0..if v { n } else { 1 })
                .map(|i| fresnel(i_.at(i), nn.at(i), eta.at(i)))
                .collect();
            let pick = |k: usize| -> Slot {
                if v {
                    match k {
                        0 => Slot::VF(res.iter().map(|r| r.0).collect()),
                        1 => Slot::VF(res.iter().map(|r| r.1).collect()),
                        2 => Slot::VT(res.iter().map(|r| r.2).collect()),
                        _ => Slot::VT(res.iter().map(|r| r.3).collect()),
                    }
                } else {
                    match k {
                        0 => Slot::F(res[0].0),
                        1 => Slot::F(res[0].1),
                        2 => Slot::T(res[0].2),
                        _ => Slot::T(res[0].3),
                    }
                }
            };
            let outs: Vec<Slot> = (0..if f == FresnelRT { 4 } else { 2 }).map(pick).collect();
            for (k, s) in outs.into_iter().enumerate() {
                set_out(ex, args[3 + k], s);
            }
        }
        Depth => {
            let (near, far) = (ex.env.near, ex.env.far);
            let p = arg(ex, args, 0).t();
            write_f(&mut out, n, p.is_varying(), |i| {
                let z = p.at(i).z;
                if far.is_finite() && far > near {
                    ((z - near) / (far - near)).clamp(0.0, 1.0)
                } else {
                    z
                }
            });
        }
        CalculateNormal if !has_neighbours(ex.env.nu, ex.env.nv, n) => {
            // A grid of ray hits has no neighbours to differentiate: the surface normal.
            out = ex
                .prog
                .global("N")
                .or_else(|| ex.prog.global("Ng"))
                .map(|g| ex.regs[g.reg as usize].clone())
                .unwrap_or(Slot::T(Vec3::ZERO));
        }
        CalculateNormal => {
            let (du, dv) = du_dv(ex);
            let p = vec_t(arg(ex, args, 0), n);
            let a = deriv_t(&p, ex.env.nu, ex.env.nv, 0, du);
            let b = deriv_t(&p, ex.env.nu, ex.env.nv, 1, dv);
            let flip = ex.env.flip_normals;
            out = Slot::VT(
                (0..n)
                    .map(|i| {
                        let c = a[i].cross(b[i]);
                        if flip {
                            -c
                        } else {
                            c
                        }
                    })
                    .collect(),
            );
        }
        Comp => {
            let (c, k) = (arg(ex, args, 0).t(), arg(ex, args, 1).f());
            write_f(&mut out, n, varying_any!(), |i| {
                c.at(i)[(k.at(i).max(0.0) as usize).min(2)]
            });
        }
        SetComp => {
            let (c, k, x) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).f(),
            );
            let mut r = Slot::default();
            write_t(&mut r, n, varying_any!(), |i| {
                let mut v = c.at(i);
                v[(k.at(i).max(0.0) as usize).min(2)] = x.at(i);
                v
            });
            set_out(ex, args[0], r);
        }
        CTransform1 | CTransform2 => {
            let (from, to, c): (Arc<str>, Arc<str>, T) = if f == CTransform1 {
                (Arc::from("rgb"), arg(ex, args, 0).s(), arg(ex, args, 1).t())
            } else {
                (
                    arg(ex, args, 0).s(),
                    arg(ex, args, 1).s(),
                    arg(ex, args, 2).t(),
                )
            };
            write_t(&mut out, n, c.is_varying(), |i| {
                color::from_rgb(&to, color::to_rgb(&from, c.at(i)))
            });
        }
        MComp => {
            let (m, r, c) = (
                arg(ex, args, 0).m(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).f(),
            );
            write_f(&mut out, n, varying_any!(), |i| {
                let (r, c) = (
                    (r.at(i).max(0.0) as usize).min(3),
                    (c.at(i).max(0.0) as usize).min(3),
                );
                m.at(i).col(r)[c]
            });
        }
        MSetComp => {
            let (m, r, c, x) = (
                arg(ex, args, 0).m(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).f(),
                arg(ex, args, 3).f(),
            );
            let mut res = Slot::default();
            write_m(&mut res, n, varying_any!(), |i| {
                let (r, c) = (
                    (r.at(i).max(0.0) as usize).min(3),
                    (c.at(i).max(0.0) as usize).min(3),
                );
                let mut a = m.at(i).to_cols_array();
                a[r * 4 + c] = x.at(i);
                Mat4::from_cols_array(&a)
            });
            set_out(ex, args[0], res);
        }
        Determinant => {
            let m = arg(ex, args, 0).m();
            write_f(&mut out, n, m.is_varying(), |i| m.at(i).determinant());
        }
        MTranslate => {
            let (m, v) = (arg(ex, args, 0).m(), arg(ex, args, 1).t());
            // RSL: translate(m, t) = translate(t) applied before m  (row vectors: T * m).
            write_m(&mut out, n, varying_any!(), |i| {
                m.at(i) * Mat4::from_translation(v.at(i))
            });
        }
        MRotate => {
            let (m, a, v) = (
                arg(ex, args, 0).m(),
                arg(ex, args, 1).f(),
                arg(ex, args, 2).t(),
            );
            write_m(&mut out, n, varying_any!(), |i| {
                let ax = normalize(v.at(i));
                if ax == Vec3::ZERO {
                    m.at(i)
                } else {
                    m.at(i) * Mat4::from_axis_angle(ax, a.at(i))
                }
            });
        }
        MScale => {
            let (m, s) = (arg(ex, args, 0).m(), arg(ex, args, 1).t());
            write_m(&mut out, n, varying_any!(), |i| {
                m.at(i) * Mat4::from_scale(s.at(i))
            });
        }
        Concat => {
            let s: String = args
                .iter()
                .map(|r| ex.regs[*r as usize].s().to_string())
                .collect();
            out = Slot::S(Arc::from(s));
        }
        Format | Printf => {
            let text = format_text(ex, args);
            if f == Printf {
                eprint!("{text}");
            } else {
                out = Slot::S(Arc::from(text));
            }
        }
        Match => {
            let (pat, subj) = (arg(ex, args, 0).s(), arg(ex, args, 1).s());
            out = Slot::F(b2f(simple_match(&pat, &subj)));
        }
        Ambient => {
            let mut c = grid_vt_filled(n, Vec3::ZERO);
            for l in ex.env.lights.iter().filter(|l| l.ambient) {
                for (ci, cl) in c.iter_mut().zip(&l.cl) {
                    *ci += *cl;
                }
            }
            out = Slot::VT(c);
        }
        Diffuse => {
            // Normalise N once; each light's direction once per point (once per grid when
            // the light is distant).
            let nn = arg(ex, args, 0).t();
            let nv = to_vec_t(nn, n, normalize);
            let mut c = grid_vt_filled(n, Vec3::ZERO);
            for l in ex.env.lights.iter().filter(|l| !l.ambient && !l.nondiffuse) {
                let lanes = c.iter_mut().zip(&nv).zip(&l.lit).zip(&l.cl);
                match l.l_uniform.map(normalize) {
                    Some(ln) => {
                        for (((ci, nvi), &lit), cl) in lanes {
                            let d = ln.dot(*nvi);
                            if lit && d > 0.0 {
                                *ci += *cl * d;
                            }
                        }
                    }
                    None => {
                        for ((((ci, nvi), &lit), cl), li) in lanes.zip(&l.l) {
                            let d = normalize(*li).dot(*nvi);
                            if lit && d > 0.0 {
                                *ci += *cl * d;
                            }
                        }
                    }
                }
            }
            recycle([std::mem::replace(&mut out, Slot::VT(c)), Slot::VT(nv)]);
        }
        Specular | Phong | SpecularBrdf => {
            let mut c = grid_vt_filled(n, Vec3::ZERO);
            if f == SpecularBrdf {
                // specularbrdf(L, N, V, roughness) for one light direction.
                let (l, nn, vv, r) = (
                    arg(ex, args, 0).t(),
                    arg(ex, args, 1).t(),
                    arg(ex, args, 2).t(),
                    arg(ex, args, 3).f(),
                );
                let scale = ex.spec_scale;
                write_t(&mut out, n, varying_any!(), |i| {
                    Vec3::splat(spec_brdf(
                        normalize(l.at(i)),
                        normalize(nn.at(i)),
                        normalize(vv.at(i)),
                        r.at(i),
                        scale,
                    ))
                });
                put(ex, dst, out);
                return;
            }
            let (nn, vv, r) = (
                arg(ex, args, 0).t(),
                arg(ex, args, 1).t(),
                arg(ex, args, 2).f(),
            );
            let nv = to_vec_t(nn, n, normalize);
            let vn = to_vec_t(vv, n, normalize);
            let phong = f == Phong;
            // The exponent: scale/roughness (specular) or size (phong); once per grid when
            // uniform.
            let scale = ex.spec_scale;
            let exponent = |x: f32| if phong { x } else { spec_exponent(x, scale) };
            let expo: Vec<f32> = match r {
                F::U(x) => vec![exponent(x)],
                F::V(v) => v.iter().map(|&x| exponent(x)).collect(),
            };
            let stride = usize::from(expo.len() == n && n > 1);
            let refl: Vec<Vec3> = if phong {
                nv.iter()
                    .zip(&vn)
                    .map(|(&nn, &v)| reflect(-v, nn))
                    .collect()
            } else {
                Vec::new()
            };
            for l in ex
                .env
                .lights
                .iter()
                .filter(|l| !l.ambient && !l.nonspecular)
            {
                let lu = l.l_uniform.map(normalize);
                let lanes = c
                    .iter_mut()
                    .zip(&nv)
                    .zip(&vn)
                    .zip(&l.lit)
                    .zip(&l.cl)
                    .enumerate();
                for (i, ((((ci, &nvi), &vni), &lit), &cl)) in lanes {
                    if !lit {
                        continue;
                    }
                    let ln = match lu {
                        Some(v) => v,
                        None => normalize(l.l[i]),
                    };
                    if ln.dot(nvi) <= 0.0 {
                        continue;
                    }
                    let base = if phong {
                        refl[i].dot(ln)
                    } else {
                        nvi.dot(normalize(ln + vni))
                    };
                    if base > 0.0 {
                        *ci += cl * base.powf(expo[i * stride]);
                    }
                }
            }
            recycle([
                std::mem::replace(&mut out, Slot::VT(c)),
                Slot::VT(nv),
                Slot::VT(vn),
            ]);
        }
        // Ray functions run in `rayops` (they need the running mask); not reached.
        Trace | Occlusion | IndirectDiffuse | Transmission | Visibility | IsShadowRay => {
            out = if ex.prog.regs[dst as usize].kind == Kind::Float {
                Slot::F(0.0)
            } else {
                Slot::T(Vec3::ZERO)
            };
        }
        TextureF | TextureC | EnvironmentF | EnvironmentC | Shadow | Bump => {
            out = texture_call(ex, f, dst, args, span);
        }
        TextureInfo | Message => {
            let ok = message(ex, f, args);
            out = Slot::F(b2f(ok));
            let v = ex.prog.regs[dst as usize].varying;
            if v {
                out = crate::shade::exec::broadcast(&out, n);
            }
        }
        ShaderName => out = Slot::S(Arc::from(ex.env.shader_name)),
        ArrayLength => out = Slot::F(0.0),
        RayLevel => out = Slot::F(0.0),
        Horizon | HorizonHeight => out = horizon_call(ex, f, args, span),
    }
    let varying = ex.prog.regs[dst as usize].varying;
    if varying && !out.is_varying() {
        out = crate::shade::exec::broadcast(&out, n);
    }
    put(ex, dst, out);
}

fn iper(p: Vec3) -> IVec3 {
    IVec3::new(
        pn::period_from_float(p.x),
        pn::period_from_float(p.y),
        pn::period_from_float(p.z),
    )
}

/// The hash site of a `random()` call: its place in the source, and how many loop iterations
/// ran before it, so a call inside a loop (stratified sampling in glass.sl) differs per pass.
fn random_site(ex: &Exec, span: crate::diag::Span) -> u32 {
    let it = ex.loop_iterations();
    span.start ^ (it as u32).wrapping_mul(0x9E37_79B9) ^ ((it >> 32) as u32)
}

fn pn_hash(seed: u32, site: u32, i: u32, k: u32) -> f32 {
    use crate::pattern::hash::{hash_combine, hash_float};
    hash_float(hash_combine(hash_combine(hash_combine(seed, site), i), k))
}

pub fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    if x < a {
        0.0
    } else if x >= b {
        1.0
    } else if b == a {
        1.0
    } else {
        let t = (x - a) / (b - a);
        t * t * (3.0 - 2.0 * t)
    }
}

/// A step filtered over width `w` around `x`: box (linear ramp) or a smooth (catmull-rom-like)
/// ramp.
pub fn filtered_step(edge: f32, x: f32, w: f32, box_filter: bool) -> f32 {
    if w <= 0.0 {
        return b2f(x >= edge);
    }
    let t = ((x - edge) / w + 0.5).clamp(0.0, 1.0);
    if box_filter {
        t
    } else {
        t * t * (3.0 - 2.0 * t)
    }
}

fn ptlined(q: Vec3, p1: Vec3, p2: Vec3) -> f32 {
    let d = p2 - p1;
    let l2 = d.length_squared();
    if l2 == 0.0 {
        return q.distance(p1);
    }
    let t = ((q - p1).dot(d) / l2).clamp(0.0, 1.0);
    q.distance(p1 + d * t)
}

pub fn reflect(i: Vec3, n: Vec3) -> Vec3 {
    i - 2.0 * i.dot(n) * n
}

/// RISpec refract: I and N normalised by the caller; eta = ratio of indices; 0 on total
/// internal reflection.
pub fn refract(i: Vec3, n: Vec3, eta: f32) -> Vec3 {
    let idotn = i.dot(n);
    let k = 1.0 - eta * eta * (1.0 - idotn * idotn);
    if k < 0.0 {
        Vec3::ZERO
    } else {
        eta * i - (eta * idotn + k.sqrt()) * n
    }
}

/// Fresnel reflection and transmission coefficients for a dielectric (RISpec fresnel):
/// returns (Kr, Kt, R, T).
pub fn fresnel(i: Vec3, n: Vec3, eta: f32) -> (f32, f32, Vec3, Vec3) {
    let i = normalize(i);
    let n = normalize(n);
    let r = reflect(i, n);
    let c = -i.dot(n);
    let (cos_i, n_use) = if c < 0.0 { (-c, -n) } else { (c, n) };
    let e = if c < 0.0 { 1.0 / eta } else { eta };
    let t = refract(i, n_use, e);
    let sin_t2 = e * e * (1.0 - cos_i * cos_i);
    if sin_t2 >= 1.0 {
        return (1.0, 0.0, r, Vec3::ZERO);
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    // eta = n_i / n_t
    let rs = (e * cos_i - cos_t) / (e * cos_i + cos_t);
    let rp = (cos_i - e * cos_t) / (cos_i + e * cos_t);
    let kr = 0.5 * (rs * rs + rp * rp);
    (kr, 1.0 - kr, r, t)
}

/// The exponent of `specular`/`specularbrdf` for a roughness: `scale / roughness`. RISpec's
/// reference code writes `1/roughness`, but BMRT (with its default `"prmanspecular"`, meant to
/// match PRMan) renders highlights as tight as `8/roughness`, Aqsis uses `roughness/8` for the
/// same reason, and most published pictures rely on it; a scene that sets BMRT's
/// `Option "render" "prmanspecular" [0]` gets RISpec's (the scale is the execution's
/// [`crate::shade::exec::Exec::spec_scale`]).
pub fn spec_exponent(roughness: f32, scale: f32) -> f32 {
    if roughness > 0.0 {
        scale / roughness
    } else {
        scale * 1e4
    }
}

/// The specular term for one light: pow(max(0, N·H), scale/roughness) (see [`spec_exponent`]).
pub fn spec_brdf(l: Vec3, n: Vec3, v: Vec3, roughness: f32, scale: f32) -> f32 {
    let h = normalize(l + v);
    n.dot(h).max(0.0).powf(spec_exponent(roughness, scale))
}

fn format_text(ex: &Exec, args: &[Reg]) -> String {
    let fmt = arg(ex, args, 0).s();
    let mut out = String::new();
    let mut k = 1;
    let mut chars = fmt.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '%' {
            // skip flags/width
            let mut spec = String::new();
            while let Some(&d) = chars.peek() {
                if d.is_ascii_digit() || d == '.' || d == '-' {
                    spec.push(d);
                    chars.next();
                } else {
                    break;
                }
            }
            let Some(conv) = chars.next() else { break };
            if conv == '%' {
                out.push('%');
                continue;
            }
            if k >= args.len() {
                continue;
            }
            let s = arg(ex, args, k);
            k += 1;
            match conv {
                'f' | 'd' | 'i' | 'g' | 'e' => out.push_str(&format!("{}", s.f().first())),
                'p' | 'c' | 'n' | 'v' => {
                    let t = s.t().first();
                    out.push_str(&format!("{} {} {}", t.x, t.y, t.z));
                }
                'm' => {
                    let m = s.m();
                    let a = match m {
                        M::U(m) => m.to_cols_array(),
                        M::V(v) => v.first().copied().unwrap_or(Mat4::IDENTITY).to_cols_array(),
                    };
                    let parts: Vec<String> = a.iter().map(|x| x.to_string()).collect();
                    out.push_str(&parts.join(" "));
                }
                _ => out.push_str(&s.s()),
            }
        } else if c == '\\' {
            out.push(c);
        } else {
            out.push(c);
        }
    }
    out
}

/// `match(pattern, subject)`: a small regular-expression matcher (., *, +, ?, ^, $, [...]).
pub fn simple_match(pat: &str, s: &str) -> bool {
    fn m(p: &[char], s: &[char]) -> bool {
        if p.is_empty() {
            return true;
        }
        if p[0] == '$' && p.len() == 1 {
            return s.is_empty();
        }
        let (atom_len, matches_first): (usize, Box<dyn Fn(char) -> bool>) = if p[0] == '[' {
            let end = p.iter().position(|&c| c == ']').unwrap_or(p.len() - 1);
            let set: Vec<char> = p[1..end].to_vec();
            let neg = set.first() == Some(&'^');
            let set = if neg { set[1..].to_vec() } else { set };
            (
                end + 1,
                Box::new(move |c| {
                    let mut hit = false;
                    let mut i = 0;
                    while i < set.len() {
                        if i + 2 < set.len() && set[i + 1] == '-' {
                            hit |= c >= set[i] && c <= set[i + 2];
                            i += 3;
                        } else {
                            hit |= c == set[i];
                            i += 1;
                        }
                    }
                    hit != neg
                }),
            )
        } else if p[0] == '\\' && p.len() > 1 {
            let lit = p[1];
            (2, Box::new(move |c| c == lit))
        } else {
            let lit = p[0];
            (1, Box::new(move |c| lit == '.' || c == lit))
        };
        let rest = &p[atom_len.min(p.len())..];
        match rest.first() {
            Some('*') | Some('+') | Some('?') => {
                let op = rest[0];
                let rest = &rest[1..];
                let min = usize::from(op == '+');
                let max = if op == '?' { 1 } else { usize::MAX };
                let mut k = 0;
                while k < s.len() && k < max && matches_first(s[k]) {
                    k += 1;
                }
                loop {
                    if k >= min && m(rest, &s[k..]) {
                        return true;
                    }
                    if k == 0 {
                        return false;
                    }
                    k -= 1;
                    if k < min {
                        return false;
                    }
                }
            }
            _ => !s.is_empty() && matches_first(s[0]) && m(rest, &s[1..]),
        }
    }
    let p: Vec<char> = pat.chars().collect();
    let s: Vec<char> = s.chars().collect();
    if p.first() == Some(&'^') {
        return m(&p[1..], &s);
    }
    (0..=s.len()).any(|k| m(&p, &s[k..]))
}

/// texture/environment/shadow/bump: parses the optional parameters, builds each point's
/// footprint (4 corners from the grid's derivatives when only a centre is given) and asks
/// the texture system. Missing maps warn and return the fill value (shadow: 0, unshadowed;
/// bump: no change of the normal).
/// The scene's default shadow bias: `Option "shadow" "bias"`, else the middle of PRMan's
/// `"bias0"`…`"bias1"` range (arbor does not randomise it, to stay deterministic), else 0.
fn default_shadow_bias(ex: &Exec) -> f32 {
    let get = |name: &str| match (ex.env.info)("option", name) {
        Some(InfoValue::Floats(v)) => v.first().copied(),
        _ => None,
    };
    if let Some(b) = get("shadow:bias") {
        return b;
    }
    match (get("shadow:bias0"), get("shadow:bias1")) {
        (Some(a), Some(b)) => 0.5 * (a + b),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => 0.0,
    }
}

fn texture_call(
    ex: &mut Exec,
    f: Builtin,
    dst: Reg,
    args: &[Reg],
    span: crate::diag::Span,
) -> Slot {
    use Builtin::*;
    let n = ex.n;
    let name = arg(ex, args, 0).s();
    let chan = arg(ex, args, 1).f().first().max(0.0) as usize;
    let ncoord = arg(ex, args, 2).f().first() as usize;
    let ncoord_regs = match (f, ncoord) {
        (TextureF | TextureC | Bump, 0) => 2,
        (TextureF | TextureC | Bump, k) => k,
        (_, k) => k,
    };
    // bump: N, dPds, dPdt come before the coordinates.
    let coord0 = if f == Bump { 6 } else { 3 };
    let mut params = TextureParams {
        fill: 0.0,
        filter: "gaussian".into(),
        samples: 16.0,
        swidth: 1.0,
        twidth: 1.0,
        bias: if f == Shadow {
            default_shadow_bias(ex)
        } else {
            0.0
        },
        ..Default::default()
    };
    let mut k = coord0 + ncoord_regs;
    while k + 1 < args.len() {
        let pname = arg(ex, args, k).s();
        let v = arg(ex, args, k + 1);
        match &*pname {
            "blur" => {
                params.sblur = v.f().first();
                params.tblur = params.sblur;
            }
            "sblur" => params.sblur = v.f().first(),
            "tblur" => params.tblur = v.f().first(),
            "width" => {
                params.swidth = v.f().first();
                params.twidth = params.swidth;
            }
            "swidth" => params.swidth = v.f().first(),
            "twidth" => params.twidth = v.f().first(),
            "fill" => params.fill = v.f().first(),
            "filter" => params.filter = v.s().to_string(),
            "samples" => params.samples = v.f().first(),
            "bias" => params.bias = v.f().first(),
            // PRMan's area-shadow corners and its gap bias shape the penumbra it computes
            // from several maps; arbor filters each map by itself (see the README).
            "source" | "gapbias" if f == Shadow => {}
            other => {
                let msg = format!("texture parameter \"{other}\" is not supported; ignored");
                ex.warn(span, msg);
            }
        }
        k += 2;
    }
    params.blur = params.sblur.max(params.tblur);
    let is_color = matches!(f, TextureC | EnvironmentC);
    let nchan = if is_color { 3 } else { 1 };
    let fill = params.fill;
    if name.is_empty() {
        return default_texture(f, n, fill, dst, ex);
    }
    let Some(tex) = ex.env.textures else {
        ex.warn(
            span,
            format!("texture \"{name}\" is not available (no texture system); using the fill value {fill}"),
        );
        return default_texture(f, n, fill, dst, ex);
    };
    let (nu, nv) = (ex.env.nu, ex.env.nv);
    let mut buf = vec![0f32; n * if f == Bump { 2 } else { nchan }];
    let ok = match f {
        TextureF | TextureC | Bump => {
            let coords: Vec<Vec<f32>> = (0..ncoord_regs)
                .map(|c| vec_f(arg(ex, args, coord0 + c), n))
                .collect();
            let st: Vec<[f32; 8]> = if ncoord_regs == 8 {
                (0..n)
                    .map(|i| std::array::from_fn(|c| coords[c][i]))
                    .collect()
            } else {
                let (s, t) = (&coords[0], &coords[1]);
                let (dsu, dsv) = (deriv_f(s, nu, nv, 0, 1.0), deriv_f(s, nu, nv, 1, 1.0));
                let (dtu, dtv) = (deriv_f(t, nu, nv, 0, 1.0), deriv_f(t, nu, nv, 1, 1.0));
                (0..n)
                    .map(|i| {
                        let (s0, t0) = (
                            s[i] - 0.5 * (dsu[i] + dsv[i]),
                            t[i] - 0.5 * (dtu[i] + dtv[i]),
                        );
                        [
                            s0,
                            t0,
                            s0 + dsu[i],
                            t0 + dtu[i],
                            s0 + dsv[i],
                            t0 + dtv[i],
                            s0 + dsu[i] + dsv[i],
                            t0 + dtu[i] + dtv[i],
                        ]
                    })
                    .collect()
            };
            if f == Bump {
                if tex.bump_slopes(&name, chan, &st, &params, &mut buf) {
                    // Blinn's perturbation from the filtered slopes (texture::bump).
                    let (nn, dpds, dpdt) = (
                        vec_t(arg(ex, args, 3), n),
                        vec_t(arg(ex, args, 4), n),
                        vec_t(arg(ex, args, 5), n),
                    );
                    return Slot::VT(
                        (0..n)
                            .map(|i| {
                                crate::texture::bump::bump_displacement(
                                    nn[i],
                                    dpds[i],
                                    dpdt[i],
                                    buf[2 * i],
                                    buf[2 * i + 1],
                                )
                            })
                            .collect(),
                    );
                }
                false
            } else {
                tex.texture(&name, chan, nchan, &st, &params, &mut buf)
            }
        }
        EnvironmentF | EnvironmentC | Shadow => {
            let vs: Vec<Vec<Vec3>> = (0..ncoord_regs)
                .map(|c| vec_t(arg(ex, args, 3 + c), n))
                .collect();
            let mut q: Vec<[Vec3; 5]> = if ncoord_regs == 4 {
                (0..n)
                    .map(|i| {
                        let c = [vs[0][i], vs[1][i], vs[2][i], vs[3][i]];
                        [0.25 * (c[0] + c[1] + c[2] + c[3]), c[0], c[1], c[2], c[3]]
                    })
                    .collect()
            } else {
                let p = &vs[0];
                let (du, dv) = (deriv_t(p, nu, nv, 0, 1.0), deriv_t(p, nu, nv, 1, 1.0));
                (0..n)
                    .map(|i| {
                        let c0 = p[i] - 0.5 * (du[i] + dv[i]);
                        [p[i], c0, c0 + du[i], c0 + dv[i], c0 + du[i] + dv[i]]
                    })
                    .collect()
            };
            if f == Shadow {
                // Points arrive in current (camera) space; maps hold world→light matrices.
                let world_from_camera = (ex.env.spaces)("world")
                    .map(|m| m.inverse())
                    .unwrap_or(Mat4::IDENTITY);
                for pts in &mut q {
                    for p in pts.iter_mut() {
                        *p = world_from_camera.transform_point3(*p);
                    }
                }
                shadow_maps(tex, &name, &q, &params, &mut buf)
            } else {
                tex.environment(&name, chan, nchan, &q, &params, &mut buf)
            }
        }
        _ => false,
    };
    if ok {
        return if is_color {
            Slot::VT(
                (0..n)
                    .map(|i| Vec3::new(buf[i * 3], buf[i * 3 + 1], buf[i * 3 + 2]))
                    .collect(),
            )
        } else {
            Slot::VF(buf)
        };
    }
    // A missing map reads as white (1 in every channel), as in Aqsis and Pixie: a surface
    // that multiplies its colour by the map keeps its colour instead of turning black.
    // Environments and shadows keep 0 / unshadowed.
    let missing = if matches!(f, TextureF | TextureC) {
        1.0
    } else {
        fill
    };
    ex.warn(
        span,
        format!("texture \"{name}\" is not available; using {missing} for every lookup"),
    );
    default_texture(f, n, missing, dst, ex)
}

/// `shadow()` over `names`: one map, or PRMan's comma-separated list of maps rendered from
/// points across an area light, whose results are averaged (the fraction of the maps that
/// see the point in shadow). False when no map of the list opens.
fn shadow_maps(
    tex: &dyn crate::shade::exec::TextureLookup,
    names: &str,
    q: &[[Vec3; 5]],
    params: &crate::shade::exec::TextureParams,
    out: &mut [f32],
) -> bool {
    if !names.contains(',') {
        return tex.shadow(names, q, params, out);
    }
    let mut one = vec![0f32; out.len()];
    let mut opened = 0usize;
    out.fill(0.0);
    for name in names.split(',').map(str::trim).filter(|m| !m.is_empty()) {
        if tex.shadow(name, q, params, &mut one) {
            opened += 1;
            for (o, v) in out.iter_mut().zip(&one) {
                *o += v;
            }
        }
    }
    if opened > 1 {
        let w = 1.0 / opened as f32;
        out.iter_mut().for_each(|o| *o *= w);
    }
    opened > 0
}

fn default_texture(f: Builtin, n: usize, fill: f32, dst: Reg, ex: &Exec) -> Slot {
    use Builtin::*;
    let v = ex.prog.regs[dst as usize].varying;
    let s = match f {
        TextureC | EnvironmentC => Slot::T(Vec3::splat(fill)),
        Shadow => Slot::F(0.0),
        Bump => Slot::T(Vec3::ZERO),
        _ => Slot::F(fill),
    };
    if v {
        crate::shade::exec::broadcast(&s, n)
    } else {
        s
    }
}

/// attribute/option/rendererinfo/textureinfo/lightsource/surface…: writes the output temps.
fn message(ex: &mut Exec, f: Builtin, args: &[Reg]) -> bool {
    let which = arg(ex, args, 0).s();
    let (name, ty_idx) = if f == Builtin::TextureInfo {
        (
            format!("{}\u{0}{}", arg(ex, args, 1).s(), arg(ex, args, 2).s()),
            3,
        )
    } else {
        (arg(ex, args, 1).s().to_string(), 2)
    };
    let ty = arg(ex, args, ty_idx).s();
    let outs: Vec<Reg> = args[ty_idx + 1..].to_vec();
    let value: Option<InfoValue> = match &*which {
        "lightsource" => {
            let Some(light) = ex.current_light_result() else {
                return false;
            };
            let found = light
                .program
                .as_ref()
                .and_then(|p| p.params.iter().position(|p| p.name == name));
            match found.and_then(|k| light.outputs.get(k)) {
                Some(s) => {
                    let s = s.clone();
                    if let Some(&r) = outs.first() {
                        set_out(ex, r, s);
                    }
                    return true;
                }
                None => return false,
            }
        }
        "textureinfo" => match ex.env.textures {
            // name is "map\0query" (see above).
            Some(t) => {
                let (map, query) = name.split_once('\u{0}').unwrap_or((&name, ""));
                t.info(map, query)
            }
            None => (ex.env.info)(&which, &name),
        },
        "attribute" | "option" | "rendererinfo" | "rayinfo" => (ex.env.info)(&which, &name),
        "displacement" | "surface" | "atmosphere" => {
            let vars = match &*which {
                "surface" => ex.env.surface_params,
                "atmosphere" => ex.env.atmosphere_params,
                _ => ex.env.displacement_outputs,
            };
            let Some((gv, &r)) = vars.iter().find(|v| v.name == name).zip(outs.first()) else {
                return false;
            };
            let slot = if &*ty == "string" {
                gv.strings.first().map(|s| Slot::S(Arc::from(s.as_str())))
            } else {
                passed_value(gv, &ty, ex.n)
            };
            let Some(slot) = slot else {
                return false;
            };
            // A uniform destination takes the first point's value.
            let slot = if ex.prog.regs[r as usize].varying || !slot.is_varying() {
                slot
            } else {
                match slot {
                    Slot::VF(v) => Slot::F(v.first().copied().unwrap_or(0.0)),
                    Slot::VT(v) => Slot::T(v.first().copied().unwrap_or(Vec3::ZERO)),
                    other => other,
                }
            };
            set_out(ex, r, slot);
            return true;
        }
        other => {
            ex.warn(
                ex.prog.span,
                format!("message passing `{other}()` is not supported; it reports \"not found\""),
            );
            None
        }
    };
    let Some(value) = value else { return false };
    match value {
        InfoValue::Str(s) => {
            if &*ty != "string" {
                return false;
            }
            if let Some(&r) = outs.first() {
                set_out(ex, r, Slot::S(Arc::from(s)));
            }
            true
        }
        InfoValue::Floats(v) => {
            match &*ty {
                "float" => {
                    if outs.len() > v.len() || v.is_empty() {
                        return false;
                    }
                    for (k, &r) in outs.iter().enumerate() {
                        set_out(ex, r, Slot::F(v[k]));
                    }
                }
                "color" | "point" | "vector" | "normal" => {
                    if v.len() < 3 * outs.len() {
                        return false;
                    }
                    for (k, &r) in outs.iter().enumerate() {
                        set_out(
                            ex,
                            r,
                            Slot::T(Vec3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2])),
                        );
                    }
                }
                "matrix" => {
                    if v.len() < 16 {
                        return false;
                    }
                    let mut a = [0f32; 16];
                    a.copy_from_slice(&v[..16]);
                    if let Some(&r) = outs.first() {
                        set_out(ex, r, Slot::M(Box::new(Mat4::from_cols_array(&a))));
                    }
                }
                _ => return false,
            }
            true
        }
    }
}

/// The value of another shader's variable `gv` (a displacement output, a surface parameter)
/// for a destination of type `ty`
/// (`"float"`, or a colour/point/vector/normal taking any triple): None when the two do not
/// fit, as RISpec's message passing reports a variable of another type as not found.
fn passed_value(gv: &crate::shade::GridVar, ty: &str, n: usize) -> Option<Slot> {
    let w = gv.width();
    // An area light's run covers samples × points, sample-major: point i of a longer run
    // reads the value of point i modulo the grid's.
    let points = if w == 0 {
        1
    } else {
        (gv.floats.len() / w).max(1)
    };
    let at = |i: usize, k: usize| {
        let i = if gv.uniform { 0 } else { i % points };
        gv.floats.get(i * w + k).copied().unwrap_or(0.0)
    };
    match (ty, w) {
        ("float", 1) => Some(Slot::VF((0..n).map(|i| at(i, 0)).collect())),
        ("color" | "point" | "vector" | "normal", 3) => Some(Slot::VT(
            (0..n)
                .map(|i| Vec3::new(at(i, 0), at(i, 1), at(i, 2)))
                .collect(),
        )),
        _ => None,
    }
}

#[allow(dead_code)]
fn unused() -> f32 {
    PI
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite floats of the same sign.
    fn ulps(a: f32, b: f32) -> u32 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs() as u32
    }

    #[test]
    fn exp_within_one_ulp_of_correctly_rounded_over_the_normal_range() {
        // Every 101st float from the underflow threshold up to overflow, both signs.
        let mut worst = 0;
        let mut count = 0;
        let mut check = |x: f32| {
            let exact = (x as f64).exp() as f32;
            let got = exp_f(x);
            let u = ulps(got, exact);
            assert!(u <= 1, "exp({x}) = {got:e}, correctly rounded {exact:e}");
            // And within 1e-6 relative of libm's.
            let libm = x.exp();
            assert!(
                ((got - libm) / libm).abs() <= 1e-6,
                "exp({x}): {got:e} vs libm {libm:e}"
            );
            worst = worst.max(u);
            count += 1;
        };
        let mut b = (-87.3365f32).to_bits();
        while f32::from_bits(b) < -1e-6 {
            check(f32::from_bits(b));
            b -= 101;
        }
        let mut b = 1e-6f32.to_bits();
        while f32::from_bits(b) < 88.72 {
            check(f32::from_bits(b));
            b += 101;
        }
        assert!(count > 4_000_000, "{count}");
        assert!(worst <= 1);
    }

    #[test]
    fn exp_special_values() {
        assert_eq!(exp_f(0.0), 1.0);
        assert_eq!(exp_f(-0.0), 1.0);
        assert_eq!(exp_f(1.0), std::f32::consts::E);
        assert!(exp_f(f32::NAN).is_nan());
        assert_eq!(exp_f(f32::INFINITY), f32::INFINITY);
        assert_eq!(exp_f(88.73), f32::INFINITY);
        assert_eq!(exp_f(1e30), f32::INFINITY);
        assert_eq!(exp_f(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp_f(-1e30), 0.0);
        assert_eq!(exp_f(-88.0), 0.0);
        assert_eq!(exp_f(-104.0), 0.0);
        // The largest finite result and the smallest normal one are reached.
        assert!(ulps(exp_f(88.722), (88.722f32 as f64).exp() as f32) <= 1);
        assert!(exp_f(-87.3365) >= f32::MIN_POSITIVE);
        // Never a subnormal.
        let mut x = -90.0f32;
        while x < -80.0 {
            let y = exp_f(x);
            assert!(y == 0.0 || y.is_normal(), "exp({x}) = {y:e}");
            x += 1e-4;
        }
    }

    #[test]
    fn exp_over_a_slice_matches_point_by_point() {
        // The loop the interpreter runs (vectorised) gives the scalar function's bits.
        let xs: Vec<f32> = (0..4099).map(|i| -120.0 + i as f32 * 0.0517).collect();
        let mut out = Slot::default();
        k1(&mut out, xs.len(), Lanes::All, F::V(&xs), exp_f);
        let Slot::VF(v) = out else { panic!("varying") };
        for (x, y) in xs.iter().zip(&v) {
            assert_eq!(
                y.to_bits(),
                std::hint::black_box(exp_f)(*x).to_bits(),
                "{x}"
            );
        }
    }

    #[test]
    fn fresnel_at_normal_incidence_is_004_for_glass() {
        let (kr, kt, _, _) = fresnel(
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, -1.0),
            1.0 / 1.5,
        );
        assert!((kr - 0.04).abs() < 1e-4, "Kr = {kr}");
        assert!((kr + kt - 1.0).abs() < 1e-6);
    }

    #[test]
    fn smoothstep_is_hermite() {
        assert_eq!(smoothstep(0.0, 1.0, -1.0), 0.0);
        assert_eq!(smoothstep(0.0, 1.0, 2.0), 1.0);
        assert!((smoothstep(0.0, 1.0, 0.5) - 0.5).abs() < 1e-6);
        assert!((smoothstep(0.0, 2.0, 0.5) - 0.15625).abs() < 1e-6);
    }

    #[test]
    fn catmull_rom_spline_interpolates_knots() {
        let k = [0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0];
        // interior knots 1..4 reached at x = 0, 1/3, 2/3, 1
        assert!((spline_eval("catmull-rom", 0.0, &k) - 1.0).abs() < 1e-5);
        assert!((spline_eval("catmull-rom", 1.0 / 3.0, &k) - 2.0).abs() < 1e-5);
        assert!((spline_eval("catmull-rom", 1.0, &k) - 4.0).abs() < 1e-5);
        assert!((spline_eval("linear", 0.5, &[9.0, 0.0, 10.0, 9.0]) - 5.0).abs() < 1e-5);
    }

    #[test]
    fn regex_match() {
        assert!(simple_match("^ab*c$", "abbbc"));
        assert!(!simple_match("^ab*c$", "abbbd"));
        assert!(simple_match("[0-9]+", "x42"));
    }

    #[test]
    fn derivative_of_linear_ramp_is_its_slope() {
        let x: Vec<f32> = (0..12).map(|k| (k % 4) as f32 * 0.5).collect();
        let d = deriv_f(&x, 4, 3, 0, 0.5);
        assert!(d.iter().all(|&v| (v - 1.0).abs() < 1e-6));
    }
}

/// `horizon(map, s, t, L, …)` / `horizonheight(map, s, t, …)`: gathers the grid's s, t, P
/// differences and hands them to `texture::horizon` (Max's horizon mapping).
fn horizon_call(ex: &mut Exec, f: Builtin, args: &[Reg], span: crate::diag::Span) -> Slot {
    use crate::texture::horizon as hz;
    let n = ex.n;
    let (nu, nv) = (ex.env.nu, ex.env.nv);
    let map = arg(ex, args, 0).s();
    let first_param = if f == Builtin::Horizon { 4 } else { 3 };
    let mut prm = hz::HorizonParams::default();
    let mut k = first_param;
    while k + 1 < args.len() {
        let v = arg(ex, args, k + 1).f().first();
        match &*arg(ex, args, k).s() {
            "scale" => prm.scale = v,
            "penumbra" => prm.penumbra = v.max(0.0).to_radians(),
            "width" => prm.width = v,
            "curvature" => prm.curvature = v,
            other => ex.warn(
                span,
                format!("horizon: unknown parameter \"{other}\" ignored"),
            ),
        }
        k += 2;
    }
    let fallback = if f == Builtin::Horizon { 1.0 } else { 0.0 };
    // Found like texture() names: as given, then on the texture search path.
    let search = ex.env.textures.map_or(&[][..], |t| t.search_path());
    let table = match hz::cached(&crate::texture::make::resolve(&map, search).to_string_lossy()) {
        Ok(t) => t,
        Err(e) => {
            ex.warn(
                span,
                format!("horizon map unavailable ({e}); no bump shadows"),
            );
            return Slot::VF(vec![fallback; n]);
        }
    };
    let (s, t) = (vec_f(arg(ex, args, 1), n), vec_f(arg(ex, args, 2), n));
    let l = if f == Builtin::Horizon {
        vec_t(arg(ex, args, 3), n)
    } else {
        vec![Vec3::ZERO; n]
    };
    let global_t = |name: &str| {
        ex.prog
            .global(name)
            .map(|g| vec_t(&ex.regs[g.reg as usize], n))
    };
    let p = global_t("P").unwrap_or_else(|| vec![Vec3::ZERO; n]);
    // The bumps stand on the side facing the eye, like faceforward(N, I).
    let mut up = global_t("N")
        .or_else(|| global_t("Ng"))
        .unwrap_or_else(|| vec![Vec3::Z; n]);
    if let Some(eye) = global_t("I") {
        for (u, i) in up.iter_mut().zip(&eye) {
            if u.dot(*i) > 0.0 {
                *u = -*u;
            }
        }
    }
    let (dsdu, dsdv) = (deriv_f(&s, nu, nv, 0, 1.0), deriv_f(&s, nu, nv, 1, 1.0));
    let (dtdu, dtdv) = (deriv_f(&t, nu, nv, 0, 1.0), deriv_f(&t, nu, nv, 1, 1.0));
    let (dpdu, dpdv) = (deriv_t(&p, nu, nv, 0, 1.0), deriv_t(&p, nu, nv, 1, 1.0));
    // The unit normal's differences give the surface curvature (Max §6).
    let (dndu, dndv) = if f == Builtin::Horizon && prm.curvature > 0.0 {
        let nhat: Vec<Vec3> = up.iter().map(|u| u.normalize_or_zero()).collect();
        (
            deriv_t(&nhat, nu, nv, 0, 1.0),
            deriv_t(&nhat, nu, nv, 1, 1.0),
        )
    } else {
        (Vec::new(), Vec::new())
    };
    let g = hz::GridInputs {
        s: &s,
        t: &t,
        l: &l,
        up: &up,
        dsdu: &dsdu,
        dsdv: &dsdv,
        dtdu: &dtdu,
        dtdv: &dtdv,
        dpdu: &dpdu,
        dpdv: &dpdv,
        dndu: &dndu,
        dndv: &dndv,
    };
    Slot::VF(if f == Builtin::Horizon {
        hz::grid_visibility(&table, &g, &prm)
    } else {
        hz::grid_height(&table, &g, prm.scale)
    })
}

/// `exp` for shaders, branch-free so loops of it vectorise (libm's `expf` is a call per
/// point, and takes a slow error-reporting path on underflow, which volume shaders hit at
/// every step of a march: `exp(-falloff * height)` far from a surface).
///
/// Cody–Waite reduction `x = k·ln2 + r`, |r| ≤ ln2/2, a degree-7 Taylor polynomial for e^r,
/// and the scale 2^k applied as two powers of two. Within 1 ulp of the correctly rounded
/// result wherever that is a normal number (tests below); +∞ above ln(f32::MAX); NaN for
/// NaN; 0 below −87.3365, where the result would be under 1.2e-38: no subnormal result is
/// ever made (making one costs a slow microcode assist on x86, and the volume marches that
/// call exp most are the ones that underflow).
#[inline(always)]
pub fn exp_f(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that k·LN2_HI is exact for the k that occur.
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // 1.5·2^23: adding it rounds to an integer, held in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    // Just above ln(f32::MIN_POSITIVE) = −87.336544: from here up, e^x is normal.
    const LOW: f32 = -87.3365;
    let xc = x.clamp(LOW, 89.0);
    let t = xc * LOG2E + ROUND;
    let k = t - ROUND;
    let ki = (t.to_bits() as i32).wrapping_sub(0x4B40_0000);
    let r = xc - k * LN2_HI - k * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (0.166_666_67
                    + r * (0.041_666_42
                        + r * (0.008_333_452 + r * (0.001_394_376_3 + r * 0.000_198_527_62))))));
    let k1 = ki >> 1;
    let s1 = f32::from_bits(((k1 + 127) as u32) << 23);
    // The flush to zero goes through the scale (not a select on the result), so the clamp
    // above is kept for every point and no point's product is subnormal.
    let s2 = if x < LOW {
        0.0
    } else {
        f32::from_bits(((ki - k1 + 127) as u32) << 23)
    };
    let y = p * s1 * s2;
    if x.is_nan() {
        x
    } else {
        y
    }
}
