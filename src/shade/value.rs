//! Register storage for the grid interpreter: one value per register, uniform or varying.
//!
//! Invariants: a varying slot holds exactly `n` values (the grid size); uniform slots hold one.
//! Helpers read operands as [`F`]/[`T`]/[`M`] views so loops specialise on uniform/varying
//! once per instruction, not per point.

use std::sync::Arc;

use glam::{Mat4, Vec3};

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

/// A float operand.
#[derive(Clone, Copy)]
pub enum F<'a> {
    U(f32),
    V(&'a [f32]),
}

impl F<'_> {
    #[inline(always)]
    pub fn at(&self, i: usize) -> f32 {
        match self {
            F::U(x) => *x,
            F::V(v) => v[i],
        }
    }
    pub fn is_varying(&self) -> bool {
        matches!(self, F::V(_))
    }
    /// The value at the first point (for uniform uses of a varying value).
    pub fn first(&self) -> f32 {
        match self {
            F::U(x) => *x,
            F::V(v) => v.first().copied().unwrap_or(0.0),
        }
    }
}

/// A triple operand.
#[derive(Clone, Copy)]
pub enum T<'a> {
    U(Vec3),
    V(&'a [Vec3]),
}

impl T<'_> {
    #[inline(always)]
    pub fn at(&self, i: usize) -> Vec3 {
        match self {
            T::U(x) => *x,
            T::V(v) => v[i],
        }
    }
    pub fn is_varying(&self) -> bool {
        matches!(self, T::V(_))
    }
    pub fn first(&self) -> Vec3 {
        match self {
            T::U(x) => *x,
            T::V(v) => v.first().copied().unwrap_or(Vec3::ZERO),
        }
    }
}

/// A matrix operand.
#[derive(Clone, Copy)]
pub enum M<'a> {
    U(Mat4),
    V(&'a [Mat4]),
}

impl M<'_> {
    #[inline(always)]
    pub fn at(&self, i: usize) -> Mat4 {
        match self {
            M::U(x) => *x,
            M::V(v) => v[i],
        }
    }
    pub fn is_varying(&self) -> bool {
        matches!(self, M::V(_))
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

/// Per-thread free lists of grid buffers, so the temporaries of one grid's run reuse the
/// buffers of the previous run (no allocation or zero-fill per register per run, and the
/// memory stays warm in cache). Bounded: beyond `POOL_MAX` buffers per kind they are freed.
mod pool {
    use glam::Vec3;
    use std::cell::RefCell;

    pub const POOL_MAX: usize = 512;

    thread_local! {
        pub static FLOATS: RefCell<Vec<Vec<f32>>> = const { RefCell::new(Vec::new()) };
        pub static TRIPLES: RefCell<Vec<Vec<Vec3>>> = const { RefCell::new(Vec::new()) };
    }
}

/// A float buffer of length `n` with unspecified (initialised) contents.
pub fn grid_vf(n: usize) -> Vec<f32> {
    let mut v = pool::FLOATS
        .with(|p| p.borrow_mut().pop())
        .unwrap_or_default();
    v.resize(n, 0.0);
    v
}

/// A triple buffer of length `n` with unspecified (initialised) contents.
pub fn grid_vt(n: usize) -> Vec<Vec3> {
    let mut v = pool::TRIPLES
        .with(|p| p.borrow_mut().pop())
        .unwrap_or_default();
    v.resize(n, Vec3::ZERO);
    v
}

/// A triple buffer of length `n` filled with `x`.
pub fn grid_vt_filled(n: usize, x: Vec3) -> Vec<Vec3> {
    let mut v = grid_vt(n);
    v.fill(x);
    v
}

/// Gives the grid buffers of finished registers back to this thread's pool.
pub fn recycle(slots: impl IntoIterator<Item = Slot>) {
    pool::FLOATS.with(|fp| {
        pool::TRIPLES.with(|tp| {
            let (mut fp, mut tp) = (fp.borrow_mut(), tp.borrow_mut());
            for s in slots {
                match s {
                    Slot::VF(v) if fp.len() < pool::POOL_MAX => fp.push(v),
                    Slot::VT(v) if tp.len() < pool::POOL_MAX => tp.push(v),
                    _ => {}
                }
            }
        })
    })
}

/// Takes a float vector of length `n` out of a slot to reuse its allocation (contents are
/// unspecified: callers overwrite every element).
pub fn take_vf(slot: &mut Slot, n: usize) -> Vec<f32> {
    match std::mem::take(slot) {
        Slot::VF(mut v) => {
            v.resize(n, 0.0);
            v
        }
        _ => grid_vf(n),
    }
}

pub fn take_vt(slot: &mut Slot, n: usize) -> Vec<Vec3> {
    match std::mem::take(slot) {
        Slot::VT(mut v) => {
            v.resize(n, Vec3::ZERO);
            v
        }
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

/// Writes a float result: uniform when `varying` is false (computed at point 0).
#[inline]
pub fn write_f(out: &mut Slot, n: usize, varying: bool, f: impl Fn(usize) -> f32) {
    if varying {
        let mut v = take_vf(out, n);
        for (i, o) in v.iter_mut().enumerate() {
            *o = f(i);
        }
        *out = Slot::VF(v);
    } else {
        *out = Slot::F(f(0));
    }
}

#[inline]
pub fn write_t(out: &mut Slot, n: usize, varying: bool, f: impl Fn(usize) -> Vec3) {
    if varying {
        let mut v = take_vt(out, n);
        for (i, o) in v.iter_mut().enumerate() {
            *o = f(i);
        }
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
    match (a, b) {
        (F::U(x), F::U(y)) => *out = Slot::F(f(x, y)),
        (F::V(x), F::U(y)) => {
            let mut v = take_vf(out, n);
            for (o, &xi) in v.iter_mut().zip(x) {
                *o = f(xi, y);
            }
            *out = Slot::VF(v);
        }
        (F::U(x), F::V(y)) => {
            let mut v = take_vf(out, n);
            for (o, &yi) in v.iter_mut().zip(y) {
                *o = f(x, yi);
            }
            *out = Slot::VF(v);
        }
        (F::V(x), F::V(y)) => {
            let mut v = take_vf(out, n);
            for ((o, &xi), &yi) in v.iter_mut().zip(x).zip(y) {
                *o = f(xi, yi);
            }
            *out = Slot::VF(v);
        }
    }
}

#[inline]
pub fn zip_tt(out: &mut Slot, n: usize, a: T, b: T, f: impl Fn(Vec3, Vec3) -> Vec3) {
    match (a, b) {
        (T::U(x), T::U(y)) => *out = Slot::T(f(x, y)),
        (T::V(x), T::U(y)) => {
            let mut v = take_vt(out, n);
            for (o, &xi) in v.iter_mut().zip(x) {
                *o = f(xi, y);
            }
            *out = Slot::VT(v);
        }
        (T::U(x), T::V(y)) => {
            let mut v = take_vt(out, n);
            for (o, &yi) in v.iter_mut().zip(y) {
                *o = f(x, yi);
            }
            *out = Slot::VT(v);
        }
        (T::V(x), T::V(y)) => {
            let mut v = take_vt(out, n);
            for ((o, &xi), &yi) in v.iter_mut().zip(x).zip(y) {
                *o = f(xi, yi);
            }
            *out = Slot::VT(v);
        }
    }
}

#[inline]
pub fn zip_tt_f(out: &mut Slot, n: usize, a: T, b: T, f: impl Fn(Vec3, Vec3) -> f32) {
    let varying = a.is_varying() || b.is_varying();
    write_f(out, n, varying, |i| f(a.at(i), b.at(i)));
}

/// Unary maps specialised on uniform/varying so the varying loop runs over a slice.
#[inline]
pub fn map_ff(out: &mut Slot, n: usize, a: F, f: impl Fn(f32) -> f32) {
    match a {
        F::U(x) => *out = Slot::F(f(x)),
        F::V(x) => {
            let mut v = take_vf(out, n);
            for (o, &xi) in v.iter_mut().zip(x) {
                *o = f(xi);
            }
            *out = Slot::VF(v);
        }
    }
}

#[inline]
pub fn map_tt(out: &mut Slot, n: usize, a: T, f: impl Fn(Vec3) -> Vec3) {
    match a {
        T::U(x) => *out = Slot::T(f(x)),
        T::V(x) => {
            let mut v = take_vt(out, n);
            for (o, &xi) in v.iter_mut().zip(x) {
                *o = f(xi);
            }
            *out = Slot::VT(v);
        }
    }
}

#[inline]
pub fn map_tf(out: &mut Slot, n: usize, a: T, f: impl Fn(Vec3) -> f32) {
    match a {
        T::U(x) => *out = Slot::F(f(x)),
        T::V(x) => {
            let mut v = take_vf(out, n);
            for (o, &xi) in v.iter_mut().zip(x) {
                *o = f(xi);
            }
            *out = Slot::VF(v);
        }
    }
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
