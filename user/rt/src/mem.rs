//! `memcpy`, `memmove`, `memset`, `memcmp`, `bcmp`: the compiler emits calls to these and
//! there is no libc. Copies and fills move whole words (`rep movsq`/`rep stosq`) and the
//! last bytes one at a time, as Linux's own do on CPUs without fast byte strings (ERMS,
//! which the emulated CPU lacks: there `rep movsb` moves a byte a step); comparisons are a
//! byte loop; plain Rust loops could be turned back into memcpy calls.
#![allow(unsafe_code)]

use core::arch::asm;

/// # Safety
/// Standard C semantics: `dest` and `src` valid for `n` bytes, not overlapping.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn memcpy(dest: *mut u8, src: *const u8, n: usize) -> *mut u8 {
    // SAFETY: the caller guarantees both ranges are valid for `n` bytes (n / 8 words, then
    // n % 8 bytes, in order); DF is clear (ABI).
    unsafe {
        asm!(
            "rep movsq", "mov rcx, {tail}", "rep movsb",
            tail = in(reg) n % 8,
            inout("rcx") n / 8 => _, inout("rdi") dest => _, inout("rsi") src => _,
            options(nostack, preserves_flags),
        );
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
    // SAFETY: the caller guarantees `dest` is valid for `n` bytes (n / 8 words, then n % 8
    // bytes); DF is clear (ABI).
    unsafe {
        asm!(
            "rep stosq", "mov rcx, {tail}", "rep stosb",
            tail = in(reg) n % 8,
            inout("rcx") n / 8 => _, inout("rdi") dest => _,
            in("rax") (value as u8 as u64) * 0x0101_0101_0101_0101,
            options(nostack, preserves_flags),
        );
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_and_fills_every_length_and_alignment() {
        let source: [u8; 64] = core::array::from_fn(|i| i as u8 + 1);
        for offset in 0..8 {
            for n in 0..40 {
                let mut copied = [0u8; 64];
                let mut filled = [0u8; 64];
                let (to_copy, to_fill) =
                    (copied[offset..].as_mut_ptr(), filled[offset..].as_mut_ptr());
                // SAFETY: offset + n <= 47 < 64 bytes of both arrays, which do not overlap.
                unsafe { memcpy(to_copy, source.as_ptr(), n) };
                // SAFETY: as above, for the one array.
                unsafe { memset(to_fill, 0xa5, n) };
                for i in 0..64 {
                    let inside = (offset..offset + n).contains(&i);
                    let want = if inside { source[i - offset] } else { 0 };
                    assert_eq!(
                        copied[i], want,
                        "memcpy offset {offset} length {n} byte {i}"
                    );
                    let want = if inside { 0xa5 } else { 0 };
                    assert_eq!(
                        filled[i], want,
                        "memset offset {offset} length {n} byte {i}"
                    );
                }
            }
        }
    }
}
