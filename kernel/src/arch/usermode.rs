//! The first switch to ring 3 (later entries return through the interrupt/syscall paths).

use core::arch::naked_asm;

/// RFLAGS for user threads: IF set, reserved bit 1 set.
pub const USER_RFLAGS: u64 = 0x202;

/// Enters ring 3 at `rip` with stack `rsp`, `rdi` = `arg0`, `rsi` = `arg1`, other general
/// registers zero, and interrupts enabled.
///
/// # Safety
/// The current CR3 must map `rip` and `rsp` as user pages of the task about to run.
#[unsafe(naked)]
pub unsafe extern "sysv64" fn enter_user(rip: u64, rsp: u64, arg0: u64, arg1: u64) -> ! {
    naked_asm!(
        "push {user_ss}",
        "push rsi",
        "push {rflags}",
        "push {user_cs}",
        "push rdi",
        "mov rdi, rdx",
        "mov rsi, rcx",
        "xor eax, eax", "xor ebx, ebx", "xor ecx, ecx", "xor edx, edx", "xor ebp, ebp",
        "xor r8d, r8d", "xor r9d, r9d", "xor r10d, r10d", "xor r11d, r11d",
        "xor r12d, r12d", "xor r13d, r13d", "xor r14d, r14d", "xor r15d, r15d",
        "iretq",
        user_ss = const 0x1b,
        user_cs = const 0x23,
        rflags = const USER_RFLAGS,
    )
}
