//! Per-thread pools of grid-sized buffers, one pool per element type.
//!
//! Input: buffers a thread is done with ([`give`]). Output: buffers of at least a requested
//! capacity ([`take`] gives them empty: callers fill them, so nothing a buffer held before
//! can show). Invariants: a pool holds at most [`Pooled::MAX`] buffers and [`MAX_BYTES`] of
//! them (more are freed); a buffer goes back to the pool of the thread that lets it go,
//! whichever thread allocated it; buffers are kept by size class, so a request finds one
//! that fits whenever the pool holds one of its class or the next two.
//!
//! Why: a grid is diced on one thread, shaded on another and let go by whichever bucket hides
//! it last. With `malloc`/`free`, a buffer freed by a thread other than its allocator goes back
//! to the allocator's arena under that arena's lock, fought over with the thread allocating
//! there: on two threads `marble.rib` spent ≈ 9 % more CPU than on one (glibc), ≈ 1 % with a
//! thread-caching allocator. A pool per thread needs no lock, and the buffer it hands out
//! next was last touched by that thread (warm in its cache).

use std::cell::RefCell;
use std::thread::LocalKey;

use glam::Vec3;

/// Bytes of buffers one thread's pool of one type keeps at most.
pub const MAX_BYTES: usize = 16 << 20;

/// Size classes: class `k` holds buffers of capacity at least [`class_size`]`(k)`, the sizes
/// 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, … (four a doubling: a buffer made for a class wastes
/// under a quarter of its room).
const CLASSES: usize = 4 * 40;

/// The capacity class `k` stands for.
fn class_size(k: usize) -> usize {
    (4 + k % 4) << (k / 4)
}

/// The smallest class whose size holds `n` elements.
fn class_for(n: usize) -> usize {
    let n = n.max(4);
    let e = (usize::BITS - 1 - n.leading_zeros()) as usize - 2;
    let m = n.div_ceil(1 << e) - 4;
    4 * e + m
}

/// The largest class whose size a buffer of capacity `c` (at least 4) holds.
fn class_of(c: usize) -> usize {
    let e = (usize::BITS - 1 - c.leading_zeros()) as usize - 2;
    4 * e + (c >> e) - 4
}

/// One thread's buffers of one element type, a stack per size class.
pub struct Pool<T> {
    classes: Vec<Vec<Vec<T>>>,
    count: usize,
    /// Their capacity in bytes.
    bytes: usize,
}

/// An element type with a per-thread pool of buffers.
pub trait Pooled: Copy + 'static {
    /// Buffers kept per thread at most.
    const MAX: usize;
    /// This thread's pool.
    fn pool() -> &'static LocalKey<RefCell<Pool<Self>>>;
}

fn size<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}

macro_rules! pooled {
    ($t:ty, $max:expr) => {
        impl Pooled for $t {
            const MAX: usize = $max;
            fn pool() -> &'static LocalKey<RefCell<Pool<Self>>> {
                thread_local! {
                    static POOL: RefCell<Pool<$t>> = const {
                        RefCell::new(Pool { classes: Vec::new(), count: 0, bytes: 0 })
                    };
                }
                &POOL
            }
        }
    };
}

// Shader registers and grid columns: a run's register file is hundreds of buffers, and a
// bucket row's diced grids (14 columns each) wait to be shaded on either thread.
pooled!(f32, 4096);
pooled!(Vec3, 4096);
// Shaded grids' projected points, colours, bounds and flags (a few per grid).
pooled!([f32; 2], 1024);
pooled!([f32; 3], 1024);
pooled!([f32; 4], 1024);
pooled!(bool, 1024);
// Filtered tiles' pixels are f32 too; a prepared bucket's ring index is u32.
pooled!(u32, 256);

/// A pooled buffer of class `k` or one of the two above, as it was given back (contents and
/// length): the one given last.
fn find<T: Pooled>(k: usize) -> Option<Vec<T>> {
    T::pool()
        .try_with(|p| {
            let mut p = p.borrow_mut();
            let v = (k..(k + 3).min(p.classes.len())).find_map(|c| p.classes[c].pop())?;
            p.count -= 1;
            p.bytes -= size(&v);
            Some(v)
        })
        .ok()
        .flatten()
}

/// A buffer with room for `n` elements, as the pool held it (contents and length), or a new
/// empty one made to its class size (so that it goes back to that class).
fn fitting<T: Pooled>(n: usize) -> Vec<T> {
    if n == 0 {
        return Vec::new();
    }
    let k = class_for(n);
    find(k).unwrap_or_else(|| Vec::with_capacity(if k < CLASSES { class_size(k) } else { n }))
}

/// An empty buffer with room for `n` elements: a pooled one, or a new one.
pub fn take<T: Pooled>(n: usize) -> Vec<T> {
    let mut v = fitting(n);
    v.clear();
    v
}

/// A buffer of length `n` whose contents are unspecified (whatever a pooled buffer held, `x`
/// past its old length): for callers that overwrite every element, so no fill is spent.
pub fn unfilled<T: Pooled>(n: usize, x: T) -> Vec<T> {
    let mut v = fitting(n);
    v.resize(n, x);
    v
}

/// `n` copies of `x` in a pooled buffer.
pub fn filled<T: Pooled>(n: usize, x: T) -> Vec<T> {
    let mut v = take(n);
    v.resize(n, x);
    v
}

/// A copy of `src` in a pooled buffer (empty stays empty: no pooled buffer held for nothing).
pub fn copied<T: Pooled>(src: &[T]) -> Vec<T> {
    let mut v = take(src.len());
    v.extend_from_slice(src);
    v
}

/// Gives `v` to this thread's pool, or frees it when the pool is full (a buffer of under 4
/// elements would only take a place; a thread being torn down frees it too).
pub fn give<T: Pooled>(v: Vec<T>) {
    if v.capacity() < 4 {
        return;
    }
    let k = class_of(v.capacity());
    if k >= CLASSES {
        return;
    }
    let _ = T::pool().try_with(|p| {
        let mut p = p.borrow_mut();
        if p.count < T::MAX && p.bytes + size(&v) <= MAX_BYTES {
            if p.classes.len() <= k {
                p.classes.resize_with(k + 1, Vec::new);
            }
            p.count += 1;
            p.bytes += size(&v);
            p.classes[k].push(v);
        }
    });
}

/// Buffers in this thread's pool of `T` (for tests).
pub fn pooled_count<T: Pooled>() -> usize {
    T::pool().with(|p| p.borrow().count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn size_classes_hold_what_they_promise() {
        for n in 1..5000 {
            let k = class_for(n);
            assert!(class_size(k) >= n, "{n}");
            assert!(k == 0 || class_size(k - 1) < n, "{n}");
        }
        for c in 4..5000 {
            let k = class_of(c);
            assert!(class_size(k) <= c && class_size(k + 1) > c, "{c}");
        }
        assert_eq!(class_of(class_size(30)), 30);
    }

    #[test]
    fn a_given_buffer_comes_back_empty_to_a_request_it_fits() {
        let mut v = filled(100, [1.0f32, 2.0]);
        let ptr = v.as_ptr();
        v[3] = [7.0, 7.0];
        give(v);
        // Too big for what is pooled: a new buffer; the pooled one stays.
        let big: Vec<[f32; 2]> = take(1000);
        assert!(big.capacity() >= 1000 && big.is_empty());
        // Fits: the same memory, empty, and filling it shows none of the old contents.
        let w: Vec<[f32; 2]> = filled(90, [0.0, 0.0]);
        assert_eq!(w.as_ptr(), ptr);
        assert!(w.iter().all(|x| *x == [0.0, 0.0]));
        assert_eq!(copied(&[[5.0f32, 6.0]]), vec![[5.0, 6.0]]);
    }

    #[test]
    fn a_small_request_leaves_the_big_buffers() {
        give(Vec::<bool>::with_capacity(1024));
        give(Vec::<bool>::with_capacity(10));
        give(Vec::<bool>::with_capacity(100));
        assert_eq!(take::<bool>(9).capacity(), 10);
        assert!(take::<bool>(5).capacity() < 100);
        assert_eq!(take::<bool>(90).capacity(), 100);
        assert_eq!(take::<bool>(900).capacity(), 1024);
    }

    #[test]
    fn pools_stay_bounded() {
        for _ in 0..(<[f32; 4]>::MAX + 50) {
            give(Vec::<[f32; 4]>::with_capacity(8));
        }
        assert_eq!(pooled_count::<[f32; 4]>(), <[f32; 4]>::MAX);
        // By bytes too: a buffer that would pass the budget is freed.
        give(Vec::<[f32; 2]>::with_capacity(MAX_BYTES / 8 - 10));
        give(Vec::<[f32; 2]>::with_capacity(20));
        assert_eq!(pooled_count::<[f32; 2]>(), 1);
        // Tiny buffers take no place.
        let before = pooled_count::<bool>();
        give(Vec::<bool>::with_capacity(2));
        assert_eq!(pooled_count::<bool>(), before);
    }

    #[test]
    fn a_buffer_let_go_on_another_thread_joins_that_threads_pool() {
        let v: Vec<f32> = filled(64, 1.0);
        let here = pooled_count::<f32>();
        let there = std::thread::spawn(move || {
            give(v);
            pooled_count::<f32>()
        })
        .join()
        .unwrap();
        assert_eq!(there, 1);
        assert_eq!(pooled_count::<f32>(), here);
    }
}
