//! Register storage for the grid interpreter: one value per register, uniform or varying.
//!
//! Invariants: a varying slot holds exactly `n` values (the grid size); uniform slots hold one.
//! Helpers read operands as [`F`]/[`T`]/[`M`] views so loops specialise on uniform/varying
//! once per instruction, not per point.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::pool;

#[derive(Clone, Debug)]
pub enum Slot {
    F(f32),
    T(Vec3),
    /// Boxed: a matrix inline would make every register 72 bytes instead of 32.
    M(Box<Mat4>),
    S(Arc<str>),
    VF(Vec<f32>),
    VT(Vec<Vec3>),
    VM(Vec<Mat4>),
}

impl Default for Slot {
    fn default() -> Slot {
        Slot::F(0.0)
    }
}

/// An operand: one value for the whole grid (`U`) or one per point (`V`).
#[derive(Clone, Copy)]
pub enum Op<'a, X> {
    U(X),
    V(&'a [X]),
}

/// A float operand.
pub type F<'a> = Op<'a, f32>;
/// A triple operand.
pub type T<'a> = Op<'a, Vec3>;
/// A matrix operand.
pub type M<'a> = Op<'a, Mat4>;

impl<X: Copy + Default> Op<'_, X> {
    #[inline(always)]
    pub fn at(&self, i: usize) -> X {
        match self {
            Op::U(x) => *x,
            Op::V(v) => v[i],
        }
    }
    pub fn is_varying(&self) -> bool {
        matches!(self, Op::V(_))
    }
    /// The value at the first point (for uniform uses of a varying value).
    pub fn first(&self) -> X {
        match self {
            Op::U(x) => *x,
            Op::V(v) => v.first().copied().unwrap_or_default(),
        }
    }
}

/// The points an instruction computes: every point, or only those listed (the running
/// points, ascending, when few of a grid's points run: a march whose points leave its loop at
/// different steps). Points not listed keep the destination's earlier values from the same
/// run (or zero), never values from another run.
#[derive(Clone, Copy, Debug)]
pub enum Lanes<'a> {
    All,
    Some(&'a [u32]),
}

/// A value kind registers store per point: how it becomes a slot, and the buffer a write
/// over some lanes goes into.
pub trait Elem: Copy + Default + 'static {
    fn uniform(x: Self) -> Slot;
    fn varying(v: Vec<Self>) -> Slot;
    /// The destination buffer for a write of `n` points over `lanes` (see [`out_vf`]).
    fn out_buf(slot: &mut Slot, n: usize, lanes: Lanes) -> Vec<Self>;
}

impl Elem for f32 {
    fn uniform(x: f32) -> Slot {
        Slot::F(x)
    }
    fn varying(v: Vec<f32>) -> Slot {
        Slot::VF(v)
    }
    #[inline]
    fn out_buf(slot: &mut Slot, n: usize, lanes: Lanes) -> Vec<f32> {
        out_vf(slot, n, lanes)
    }
}

impl Elem for Vec3 {
    fn uniform(x: Vec3) -> Slot {
        Slot::T(x)
    }
    fn varying(v: Vec<Vec3>) -> Slot {
        Slot::VT(v)
    }
    #[inline]
    fn out_buf(slot: &mut Slot, n: usize, lanes: Lanes) -> Vec<Vec3> {
        out_vt(slot, n, lanes)
    }
}

impl Elem for Mat4 {
    fn uniform(x: Mat4) -> Slot {
        Slot::M(Box::new(x))
    }
    fn varying(v: Vec<Mat4>) -> Slot {
        Slot::VM(v)
    }
    fn out_buf(slot: &mut Slot, n: usize, lanes: Lanes) -> Vec<Mat4> {
        match (std::mem::take(slot), lanes) {
            (Slot::VM(v), _) if v.len() == n => v,
            (Slot::VM(mut v), Lanes::All) => {
                v.resize(n, Mat4::IDENTITY);
                v
            }
            _ => vec![Mat4::IDENTITY; n],
        }
    }
}

impl Slot {
    pub fn f(&self) -> F<'_> {
        match self {
            Slot::F(x) => F::U(*x),
            Slot::VF(v) => F::V(v),
            Slot::T(t) => F::U(t.x),
            _ => F::U(0.0),
        }
    }
    pub fn t(&self) -> T<'_> {
        match self {
            Slot::T(x) => T::U(*x),
            Slot::VT(v) => T::V(v),
            Slot::F(x) => T::U(Vec3::splat(*x)),
            _ => T::U(Vec3::ZERO),
        }
    }
    pub fn m(&self) -> M<'_> {
        match self {
            Slot::M(x) => M::U(**x),
            Slot::VM(v) => M::V(v),
            Slot::F(x) => M::U(Mat4::IDENTITY * *x),
            _ => M::U(Mat4::IDENTITY),
        }
    }
    pub fn s(&self) -> Arc<str> {
        match self {
            Slot::S(s) => s.clone(),
            _ => empty_str(),
        }
    }
    pub fn is_varying(&self) -> bool {
        matches!(self, Slot::VF(_) | Slot::VT(_) | Slot::VM(_))
    }
}

/// The empty string, shared (string registers start empty: no allocation per register).
pub fn empty_str() -> Arc<str> {
    thread_local! {
        static EMPTY: Arc<str> = Arc::from("");
    }
    EMPTY.with(Arc::clone)
}

/// A float buffer of length `n` with unspecified (initialised) contents, from this thread's
/// buffer pool ([`crate::pool`]: the temporaries of one grid's run reuse the buffers
/// of the previous run, with no allocation or zero-fill per register per run).
pub fn grid_vf(n: usize) -> Vec<f32> {
    pool::unfilled(n, 0.0)
}

/// A triple buffer of length `n` with unspecified (initialised) contents.
pub fn grid_vt(n: usize) -> Vec<Vec3> {
    pool::unfilled(n, Vec3::ZERO)
}

/// A triple buffer of length `n` filled with `x`.
pub fn grid_vt_filled(n: usize, x: Vec3) -> Vec<Vec3> {
    pool::filled(n, x)
}

/// A pooled copy of `src` (empty stays empty: no pooled buffer held for nothing). Buffers
/// that end in [`recycle`] should come from here rather than a fresh `to_vec`: a run's
/// register file is recycled, and fresh buffers recycled into a full pool are freed, so the
/// pool would turn over through `malloc`/`free` at every run.
pub fn pooled_vt(src: &[Vec3]) -> Vec<Vec3> {
    pool::copied(src)
}

/// [`pooled_vt`] for floats.
pub fn pooled_vf(src: &[f32]) -> Vec<f32> {
    pool::copied(src)
}

/// Gives the grid buffers of finished registers back to this thread's pool.
pub fn recycle(slots: impl IntoIterator<Item = Slot>) {
    for s in slots {
        match s {
            Slot::VF(v) => pool::give(v),
            Slot::VT(v) => pool::give(v),
            _ => {}
        }
    }
}

/// `v` resized to `n` values with unspecified contents: in place when it has the room,
/// otherwise `v` goes back to the pool and a pooled buffer that fits is used (growing `v`
/// would copy values nobody reads).
fn refit_vf(mut v: Vec<f32>, n: usize) -> Vec<f32> {
    if v.capacity() >= n {
        v.resize(n, 0.0);
        v
    } else {
        recycle([Slot::VF(v)]);
        grid_vf(n)
    }
}

/// [`refit_vf`] for triples.
fn refit_vt(mut v: Vec<Vec3>, n: usize) -> Vec<Vec3> {
    if v.capacity() >= n {
        v.resize(n, Vec3::ZERO);
        v
    } else {
        recycle([Slot::VT(v)]);
        grid_vt(n)
    }
}

/// Takes a float vector of length `n` out of a slot to reuse its allocation (contents are
/// unspecified: callers overwrite every element).
pub fn take_vf(slot: &mut Slot, n: usize) -> Vec<f32> {
    match std::mem::take(slot) {
        Slot::VF(v) => refit_vf(v, n),
        _ => grid_vf(n),
    }
}

pub fn take_vt(slot: &mut Slot, n: usize) -> Vec<Vec3> {
    match std::mem::take(slot) {
        Slot::VT(v) => refit_vt(v, n),
        _ => grid_vt(n),
    }
}

pub fn take_vm(slot: &mut Slot, n: usize) -> Vec<Mat4> {
    match std::mem::take(slot) {
        Slot::VM(mut v) => {
            v.resize(n, Mat4::IDENTITY);
            v
        }
        _ => vec![Mat4::IDENTITY; n],
    }
}

/// The float buffer a write of `n` points over `lanes` goes into: the slot's own when it has
/// `n` values (points not written keep this run's earlier values); otherwise a pooled one,
/// zero-filled unless every point is written (a pooled buffer's old contents depend on what
/// ran before on this thread and must never show).
pub fn out_vf(slot: &mut Slot, n: usize, lanes: Lanes) -> Vec<f32> {
    match (std::mem::take(slot), lanes) {
        (Slot::VF(v), _) if v.len() == n => v,
        (Slot::VF(v), Lanes::All) => refit_vf(v, n),
        (_, Lanes::All) => grid_vf(n),
        (_, Lanes::Some(_)) => {
            let mut v = grid_vf(n);
            v.fill(0.0);
            v
        }
    }
}

/// [`out_vf`] for triples.
pub fn out_vt(slot: &mut Slot, n: usize, lanes: Lanes) -> Vec<Vec3> {
    match (std::mem::take(slot), lanes) {
        (Slot::VT(v), _) if v.len() == n => v,
        (Slot::VT(v), Lanes::All) => refit_vt(v, n),
        (_, Lanes::All) => grid_vt(n),
        (_, Lanes::Some(_)) => grid_vt_filled(n, Vec3::ZERO),
    }
}

// Triples as flat floats, so componentwise loops vectorise across points (glam's `Vec3` is
// three `f32`s, `repr(C)`, no padding).
const _: () = assert!(std::mem::size_of::<Vec3>() == 12 && std::mem::align_of::<Vec3>() == 4);

/// The components of `v` in order (x0 y0 z0 x1 …).
#[inline(always)]
pub fn flat(v: &[Vec3]) -> &[f32] {
    // SAFETY: Vec3 is repr(C) { x, y, z: f32 } with size 12 and align 4 (asserted above), so
    // a slice of n of them is 3n contiguous, initialised f32s.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<f32>(), v.len() * 3) }
}

#[inline(always)]
pub fn flat_mut(v: &mut [Vec3]) -> &mut [f32] {
    // SAFETY: as for `flat`; the borrow is unique.
    unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr().cast::<f32>(), v.len() * 3) }
}

/// Whether this CPU has AVX2 (detected once; the kernels below then run a copy compiled for
/// it: eight points per vector instead of four, the same IEEE operations, so the same bits —
/// no fused multiply-add is enabled).
#[inline(always)]
pub fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Defines `$name` (never inlined: each caller's closure gets its own small function, where
/// the closure is inlined and the loop vectorised — inlined into the large instruction
/// dispatch, the closures stayed calls per point) running `$body`, in a copy compiled for
/// AVX2 when the CPU has it.
macro_rules! kernel {
    ($(#[$m:meta])* $vis:vis fn $name:ident <$($gen:ident $(: $bound:path)?),*> ($($arg:ident : $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {
        $(#[$m])*
        #[inline(never)]
        $vis fn $name<$($gen $(: $bound)?),*>($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn body<$($gen $(: $bound)?),*>($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2")]
            unsafe fn body_avx2<$($gen $(: $bound)?),*>($($arg: $ty),*) $(-> $ret)? {
                body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            if $crate::shade::value::has_avx2() {
                // SAFETY: the CPU has AVX2 (checked just above).
                return unsafe { body_avx2($($arg),*) };
            }
            body($($arg),*)
        }
    };
}
pub(crate) use kernel;

kernel! {
    /// `o[i] = g(i)` over the lanes.
    fn run<R: Copy, G: Fn(usize) -> R>(o: &mut [R], lanes: Lanes, g: G) {
        match lanes {
            Lanes::All => {
                for (i, x) in o.iter_mut().enumerate() {
                    *x = g(i);
                }
            }
            Lanes::Some(idx) => {
                for &i in idx {
                    let i = i as usize;
                    // Bounds-checked before g runs (g may read its operands unchecked).
                    let slot = &mut o[i];
                    *slot = g(i);
                }
            }
        }
    }
}

/// A varying operand cut to the grid size.
#[inline(always)]
fn cut<X>(v: &[X], n: usize) -> &[X] {
    &v[..n]
}

/// `x[i]` without a bounds check, for the closures [`run`] calls: `run` calls them only with
/// `i < o.len()` (its loop bound, or after indexing `o[i]`), and the callers below check
/// that `o` and every operand hold `n` values first. (With the check, the loops over a
/// closure's captured slice did not vectorise.)
#[inline(always)]
fn at<X: Copy>(x: &[X], i: usize) -> X {
    debug_assert!(i < x.len());
    // SAFETY: see above: i < o.len() == n == x.len().
    unsafe { *x.get_unchecked(i) }
}

/// Per-point function of one operand, specialised on its detail: uniform in, uniform out;
/// otherwise a loop over the lanes with the operand as a plain slice.
#[inline(always)]
pub fn k1<A: Copy, R: Elem>(out: &mut Slot, n: usize, lanes: Lanes, a: Op<A>, f: impl Fn(A) -> R) {
    match a {
        Op::U(x) => *out = R::uniform(f(x)),
        Op::V(x) => {
            let mut v = R::out_buf(out, n, lanes);
            assert_eq!(v.len(), n);
            let x = cut(x, n);
            run(&mut v, lanes, |i| f(at(x, i)));
            *out = R::varying(v);
        }
    }
}

/// Per-point function of two operands (see [`k1`]).
#[inline(always)]
pub fn k2<A: Copy, B: Copy, R: Elem>(
    out: &mut Slot,
    n: usize,
    lanes: Lanes,
    a: Op<A>,
    b: Op<B>,
    f: impl Fn(A, B) -> R,
) {
    if let (Op::U(x), Op::U(y)) = (a, b) {
        *out = R::uniform(f(x, y));
        return;
    }
    let mut v = R::out_buf(out, n, lanes);
    assert_eq!(v.len(), n);
    match (a, b) {
        (Op::V(x), Op::U(y)) => {
            let x = cut(x, n);
            run(&mut v, lanes, |i| f(at(x, i), y))
        }
        (Op::U(x), Op::V(y)) => {
            let y = cut(y, n);
            run(&mut v, lanes, |i| f(x, at(y, i)))
        }
        (Op::V(x), Op::V(y)) => {
            let (x, y) = (cut(x, n), cut(y, n));
            run(&mut v, lanes, |i| f(at(x, i), at(y, i)))
        }
        (Op::U(_), Op::U(_)) => {}
    }
    *out = R::varying(v);
}

/// Per-point function of three operands (see [`k1`]).
#[inline(always)]
pub fn k3<A: Copy, B: Copy, C: Copy, R: Elem>(
    out: &mut Slot,
    n: usize,
    lanes: Lanes,
    a: Op<A>,
    b: Op<B>,
    c: Op<C>,
    f: impl Fn(A, B, C) -> R,
) {
    use Op::{U, V};
    if let (U(x), U(y), U(z)) = (a, b, c) {
        *out = R::uniform(f(x, y, z));
        return;
    }
    let mut v = R::out_buf(out, n, lanes);
    assert_eq!(v.len(), n);
    match (a, b, c) {
        (V(x), U(y), U(z)) => {
            let x = cut(x, n);
            run(&mut v, lanes, |i| f(at(x, i), y, z))
        }
        (U(x), V(y), U(z)) => {
            let y = cut(y, n);
            run(&mut v, lanes, |i| f(x, at(y, i), z))
        }
        (U(x), U(y), V(z)) => {
            let z = cut(z, n);
            run(&mut v, lanes, |i| f(x, y, at(z, i)))
        }
        (V(x), V(y), U(z)) => {
            let (x, y) = (cut(x, n), cut(y, n));
            run(&mut v, lanes, |i| f(at(x, i), at(y, i), z))
        }
        (V(x), U(y), V(z)) => {
            let (x, z) = (cut(x, n), cut(z, n));
            run(&mut v, lanes, |i| f(at(x, i), y, at(z, i)))
        }
        (U(x), V(y), V(z)) => {
            let (y, z) = (cut(y, n), cut(z, n));
            run(&mut v, lanes, |i| f(x, at(y, i), at(z, i)))
        }
        (V(x), V(y), V(z)) => {
            let (x, y, z) = (cut(x, n), cut(y, n), cut(z, n));
            run(&mut v, lanes, |i| f(at(x, i), at(y, i), at(z, i)))
        }
        (U(_), U(_), U(_)) => {}
    }
    *out = R::varying(v);
}

/// Componentwise binary triple op `f` on each of x, y, z. Over every point the loops run on
/// the flat components (they vectorise across points; glam's `Vec3` does not); over listed
/// lanes point by point. Same `f` on the same components either way, so the same bits.
#[inline(always)]
pub fn t2c(out: &mut Slot, n: usize, lanes: Lanes, a: T, b: T, f: impl Fn(f32, f32) -> f32) {
    let g = |x: Vec3, y: Vec3| Vec3::new(f(x.x, y.x), f(x.y, y.y), f(x.z, y.z));
    let Lanes::All = lanes else {
        return k2(out, n, lanes, a, b, g);
    };
    if let (Op::U(x), Op::U(y)) = (a, b) {
        *out = Slot::T(g(x, y));
        return;
    }
    let mut v = out_vt(out, n, lanes);
    {
        let o = flat_mut(&mut v);
        let m = o.len();
        match (a, b) {
            (Op::V(x), Op::V(y)) => zip_flat(o, &flat(x)[..m], &flat(y)[..m], f),
            (Op::V(x), Op::U(y)) => pattern(o, &flat(x)[..m], y, |p, q| f(p, q)),
            (Op::U(x), Op::V(y)) => pattern(o, &flat(y)[..m], x, |p, q| f(q, p)),
            (Op::U(_), Op::U(_)) => {}
        }
    }
    *out = Slot::VT(v);
}

kernel! {
    /// `o[k] = f(x[k], y[k])` (see [`run`]).
    fn zip_flat<Fx: Fn(f32, f32) -> f32>(o: &mut [f32], x: &[f32], y: &[f32], f: Fx) {
        let m = o.len();
        let (x, y) = (&x[..m], &y[..m]);
        for i in 0..m {
            o[i] = f(x[i], y[i]);
        }
    }
}

kernel! {
    /// `o[k] = f(x[k])` (see [`run`]).
    fn map_flat<Fx: Fn(f32) -> f32>(o: &mut [f32], x: &[f32], f: Fx) {
        for (o, &x) in o.iter_mut().zip(x) {
            *o = f(x);
        }
    }
}

kernel! {
    /// `o[k] = f(x[k], u[k % 3])` over flat triples: twelve floats (four points) at a time so
    /// the repeating uniform pattern lines up with the vector lanes (see [`run`]).
    fn pattern<Fx: Fn(f32, f32) -> f32>(o: &mut [f32], x: &[f32], u: Vec3, f: Fx) {
        let p: [f32; 12] = [u.x, u.y, u.z, u.x, u.y, u.z, u.x, u.y, u.z, u.x, u.y, u.z];
        let mut oc = o.chunks_exact_mut(12);
        let mut xc = x.chunks_exact(12);
        for (oo, xx) in (&mut oc).zip(&mut xc) {
            for j in 0..12 {
                oo[j] = f(xx[j], p[j]);
            }
        }
        for (j, (oo, xx)) in oc
            .into_remainder()
            .iter_mut()
            .zip(xc.remainder())
            .enumerate()
        {
            *oo = f(*xx, p[j]);
        }
    }
}

/// Componentwise unary triple op (see [`t2c`]).
#[inline(always)]
pub fn t1c(out: &mut Slot, n: usize, lanes: Lanes, a: T, f: impl Fn(f32) -> f32) {
    let g = |x: Vec3| Vec3::new(f(x.x), f(x.y), f(x.z));
    match (a, lanes) {
        (Op::V(x), Lanes::All) => {
            let mut v = out_vt(out, n, lanes);
            {
                let o = flat_mut(&mut v);
                let x = &flat(x)[..o.len()];
                map_flat(o, x, f);
            }
            *out = Slot::VT(v);
        }
        _ => k1(out, n, lanes, a, g),
    }
}

/// Writes a float result: uniform when `varying` is false (computed at point 0).
#[inline]
pub fn write_f(out: &mut Slot, n: usize, varying: bool, f: impl Fn(usize) -> f32) {
    write_f_l(out, n, Lanes::All, varying, f)
}

/// [`write_f`] over some lanes.
#[inline]
pub fn write_f_l(out: &mut Slot, n: usize, lanes: Lanes, varying: bool, f: impl Fn(usize) -> f32) {
    if varying {
        let mut v = out_vf(out, n, lanes);
        run(&mut v, lanes, f);
        *out = Slot::VF(v);
    } else {
        *out = Slot::F(f(0));
    }
}

#[inline]
pub fn write_t(out: &mut Slot, n: usize, varying: bool, f: impl Fn(usize) -> Vec3) {
    write_t_l(out, n, Lanes::All, varying, f)
}

/// [`write_t`] over some lanes.
#[inline]
pub fn write_t_l(out: &mut Slot, n: usize, lanes: Lanes, varying: bool, f: impl Fn(usize) -> Vec3) {
    if varying {
        let mut v = out_vt(out, n, lanes);
        run(&mut v, lanes, f);
        *out = Slot::VT(v);
    } else {
        *out = Slot::T(f(0));
    }
}

#[inline]
pub fn write_m(out: &mut Slot, n: usize, varying: bool, f: impl Fn(usize) -> Mat4) {
    if varying {
        let mut v = take_vm(out, n);
        for (i, o) in v.iter_mut().enumerate() {
            *o = f(i);
        }
        *out = Slot::VM(v);
    } else {
        *out = Slot::M(Box::new(f(0)));
    }
}

/// Binary float op specialised on uniform/varying operands so the loops vectorise.
#[inline]
pub fn zip_ff(out: &mut Slot, n: usize, a: F, b: F, f: impl Fn(f32, f32) -> f32) {
    k2(out, n, Lanes::All, a, b, f)
}

#[inline]
pub fn zip_tt(out: &mut Slot, n: usize, a: T, b: T, f: impl Fn(Vec3, Vec3) -> Vec3) {
    k2(out, n, Lanes::All, a, b, f)
}

#[inline]
pub fn zip_tt_f(out: &mut Slot, n: usize, a: T, b: T, f: impl Fn(Vec3, Vec3) -> f32) {
    k2(out, n, Lanes::All, a, b, f)
}

/// Unary maps specialised on uniform/varying so the varying loop runs over a slice.
#[inline]
pub fn map_ff(out: &mut Slot, n: usize, a: F, f: impl Fn(f32) -> f32) {
    k1(out, n, Lanes::All, a, f)
}

#[inline]
pub fn map_tt(out: &mut Slot, n: usize, a: T, f: impl Fn(Vec3) -> Vec3) {
    k1(out, n, Lanes::All, a, f)
}

#[inline]
pub fn map_tf(out: &mut Slot, n: usize, a: T, f: impl Fn(Vec3) -> f32) {
    k1(out, n, Lanes::All, a, f)
}

/// The values of a triple operand at every point (a copy; uniform values repeated).
pub fn to_vec_t(a: T, n: usize, f: impl Fn(Vec3) -> Vec3) -> Vec<Vec3> {
    let mut v = grid_vt(n);
    match a {
        T::U(x) => v.fill(f(x)),
        T::V(x) => {
            for (o, &xi) in v.iter_mut().zip(x) {
                *o = f(xi);
            }
        }
    }
    v
}
