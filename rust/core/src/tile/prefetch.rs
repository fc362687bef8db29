//! Cache hints: a pass asks for the memory it reads soon, so that the misses overlap with its
//! work. A hint never faults and changes no result, only when the data arrives.

/// A hint to load `bytes` bytes from `start` into the cache; it never faults, so any address
/// will do (those past the end of an array are simply wasted).
#[inline(always)]
pub(super) fn prefetch_bytes<T>(start: *const T, bytes: usize) {
    prefetch_lines::<TO_L1, T>(start, bytes);
}

/// `prefetch_bytes` into the second-level cache (and those beyond it), not the first.
#[inline(always)]
pub(super) fn prefetch_bytes_to_l2<T>(start: *const T, bytes: usize) {
    prefetch_lines::<TO_L2, T>(start, bytes);
}

/// x86's prefetch hints (`_MM_HINT_T0`, `_MM_HINT_T1`): into every cache level, or from the
/// second level on.
const TO_L1: i32 = 3;
const TO_L2: i32 = 2;

#[inline(always)]
fn prefetch_lines<const HINT: i32, T>(start: *const T, bytes: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        let start = start.cast::<i8>();
        for offset in (0..bytes).step_by(64) {
            // SAFETY: a prefetch is only a hint to the cache and cannot fault.
            unsafe { std::arch::x86_64::_mm_prefetch::<HINT>(start.wrapping_add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (start, bytes);
}

#[cfg(all(test, target_arch = "x86_64"))]
const _: () =
    assert!(TO_L1 == std::arch::x86_64::_MM_HINT_T0 && TO_L2 == std::arch::x86_64::_MM_HINT_T1);
