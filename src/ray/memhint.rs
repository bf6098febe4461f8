//! Memory hints for the ray structures: cache-line prefetches and transparent huge pages.
//!
//! Input: addresses of data about to be read, and freshly reserved arrays. Output: nothing a
//! program can observe but time: a prefetch reads nothing architecturally and never faults;
//! a huge-page advice changes how the kernel backs memory, not its contents.
//! Invariants: no effect on any result; every call is safe on any address and silently
//! does nothing where unsupported (other architectures, other systems, a kernel that says no).
//!
//! Why: a million-micropolygon scene's BVH, corners and hit records (about 130 MB) are read
//! at random, one cache line at a time. With 4 KB pages nearly every such read also misses
//! the TLB (a second-level TLB of a few thousand entries covers about 10 MB), and the page
//! walk is paid again for each prefetch; with 2 MB pages the same arrays need a few dozen
//! entries. The machine this was measured on backs memory with huge pages only where asked
//! (`/sys/kernel/mm/transparent_hugepage/enabled` = `madvise`, a common default).

/// Asks for the cache line holding `p`.
#[inline(always)]
pub fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is the x86-64 baseline; a prefetch reads nothing architecturally and never
    // faults, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Asks for every cache line of `len` elements from `p` (the addresses are only computed:
/// `p` may point anywhere).
#[inline(always)]
pub fn prefetch_span<T>(p: *const T, len: usize) {
    let bytes = std::mem::size_of::<T>() * len;
    if bytes == 0 {
        return;
    }
    let start = p as usize;
    // (A span wrapping past the top of the address space is skipped.)
    let (first, last) = (start & !63, start.wrapping_add(bytes - 1) & !63);
    let mut line = first;
    while line <= last {
        prefetch(line as *const u8);
        line = match line.checked_add(64) {
            Some(l) => l,
            None => break,
        };
    }
}

/// Advises the kernel to back `v`'s reserved storage (its capacity) with huge pages. Call it
/// on a freshly reserved, not yet written `Vec` (the pages are chosen when first touched);
/// only whole 2 MB blocks inside the reservation are affected.
pub fn huge_pages<T>(v: &mut Vec<T>) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        const MADV_HUGEPAGE: i32 = 14;
        extern "C" {
            fn madvise(addr: *mut std::ffi::c_void, len: usize, advice: i32) -> i32;
        }
        let bytes = v.capacity() * std::mem::size_of::<T>();
        let start = v.as_mut_ptr() as usize;
        let (lo, hi) = (
            start.next_multiple_of(HUGE),
            start.saturating_add(bytes) & !(HUGE - 1),
        );
        if hi > lo {
            // SAFETY: the range lies inside `v`'s own allocation (whole pages of it), and
            // MADV_HUGEPAGE neither frees nor changes memory: only how it is backed. A
            // failure (an old kernel, huge pages disabled) leaves things as they were.
            unsafe {
                madvise(lo as *mut std::ffi::c_void, hi - lo, MADV_HUGEPAGE);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = v;
}

/// A `Vec` with room for `n` elements, advised for huge pages (see [`huge_pages`]).
pub fn huge_vec<T>(n: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(n);
    huge_pages(&mut v);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hints_leave_contents_alone() {
        // Prefetches of anything (null, dangling, past the end) are harmless.
        prefetch(std::ptr::null::<u8>());
        prefetch_span(usize::MAX as *const u64, 3);
        prefetch_span(std::ptr::null::<[u8; 100]>(), 5);
        // A huge-page reservation behaves as any other Vec.
        let mut v: Vec<u64> = huge_vec(1 << 20);
        assert!(v.capacity() >= 1 << 20 && v.is_empty());
        v.extend((0..1u64 << 20).map(|k| k * 3));
        assert_eq!(v[12345], 37035);
        assert_eq!(
            v.iter().sum::<u64>(),
            3 * ((1u64 << 20) * ((1 << 20) - 1) / 2)
        );
        let mut small: Vec<u8> = Vec::new();
        huge_pages(&mut small);
        assert!(small.is_empty());
    }
}
