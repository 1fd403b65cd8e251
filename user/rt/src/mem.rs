//! `memcpy`, `memmove`, `memset`, `memcmp`, `bcmp`: the compiler emits calls to these and
//! there is no libc. Written with `rep movsb`/`rep stosb` (fast on modern CPUs) and a
//! byte loop for comparisons; plain Rust loops could be turned back into memcpy calls.
#![allow(unsafe_code)]

use core::arch::asm;

/// # Safety
/// Standard C semantics: `dest` and `src` valid for `n` bytes, not overlapping.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn memcpy(dest: *mut u8, src: *const u8, n: usize) -> *mut u8 {
    // SAFETY: the caller guarantees both ranges are valid for `n` bytes; DF is clear (ABI).
    unsafe {
        asm!("rep movsb", inout("rcx") n => _, inout("rdi") dest => _, inout("rsi") src => _, options(nostack, preserves_flags));
    }
    dest
}

/// # Safety
/// Standard C semantics: `dest` and `src` valid for `n` bytes; may overlap.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn memmove(dest: *mut u8, src: *const u8, n: usize) -> *mut u8 {
    if (dest as usize).wrapping_sub(src as usize) >= n {
        // No harmful overlap: a forward copy is correct.
        // SAFETY: as for memcpy; forward copying is safe when dest does not start inside src.
        return unsafe { memcpy(dest, src, n) };
    }
    // Copy backwards (std + rep movsb from the last byte), then restore DF. (n > 0 here:
    // with n == 0 the test above is always true.)
    let (dest_last, src_last) = (dest.wrapping_add(n - 1), src.wrapping_add(n - 1));
    // SAFETY: the caller guarantees both ranges are valid for `n` bytes.
    unsafe {
        asm!(
            "std", "rep movsb", "cld",
            inout("rcx") n => _,
            inout("rdi") dest_last => _,
            inout("rsi") src_last => _,
            options(nostack),
        );
    }
    dest
}

/// # Safety
/// Standard C semantics: `dest` valid for `n` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn memset(dest: *mut u8, value: i32, n: usize) -> *mut u8 {
    // SAFETY: the caller guarantees `dest` is valid for `n` bytes; DF is clear (ABI).
    unsafe {
        asm!("rep stosb", inout("rcx") n => _, inout("rdi") dest => _, in("al") value as u8, options(nostack, preserves_flags));
    }
    dest
}

/// # Safety
/// Standard C semantics: both pointers valid for `n` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn memcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
    let mut i = 0;
    while i < n {
        // SAFETY: i < n and the caller guarantees `a` is valid for n bytes.
        let x = unsafe { a.wrapping_add(i).read() };
        // SAFETY: likewise for `b`.
        let y = unsafe { b.wrapping_add(i).read() };
        if x != y {
            return x as i32 - y as i32;
        }
        i += 1;
    }
    0
}

/// # Safety
/// Standard C semantics: both pointers valid for `n` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn bcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
    // SAFETY: same contract as memcmp.
    unsafe { memcmp(a, b, n) }
}
