//! System-call stubs (register convention in `abi::syscall`).

use abi::syscall::{Call, Error};
use core::arch::asm;

/// Raw call: returns (`rax`, `rdi`, `rsi`, `rdx`) after the call.
#[inline(always)]
pub fn raw(call: u64, a0: u64, a1: u64, a2: u64, a3: u64) -> (u64, u64, u64, u64) {
    let (rax, rdi, rsi, rdx);
    // SAFETY: `syscall` transfers to the kernel, which preserves every register except
    // rax/rdi/rsi/rdx (results, declared as outputs), rcx and r11 (clobbered, declared) and
    // touches no memory of ours that Rust knows about except through pointers we passed.
    unsafe {
        asm!(
            "syscall",
            inlateout("rax") call => rax,
            inlateout("rdi") a0 => rdi,
            inlateout("rsi") a1 => rsi,
            inlateout("rdx") a2 => rdx,
            in("r10") a3,
            lateout("rcx") _,
            lateout("r11") _,
            options(nostack),
        );
    }
    (rax, rdi, rsi, rdx)
}

fn status(rax: u64) -> Result<(), Error> {
    match Error::from_raw(rax) {
        Some(Error::Ok) => Ok(()),
        Some(e) => Err(e),
        None => Err(Error::InvalidCall),
    }
}

pub fn debug_write(text: &[u8]) -> Result<(), Error> {
    status(
        raw(
            Call::DebugWrite as u64,
            text.as_ptr() as u64,
            text.len() as u64,
            0,
            0,
        )
        .0,
    )
}

/// Nanoseconds since boot.
pub fn clock() -> u64 {
    raw(Call::Clock as u64, 0, 0, 0, 0).1
}

pub fn thread_exit() -> ! {
    raw(Call::ThreadExit as u64, 0, 0, 0, 0);
    unreachable!("thread_exit returned")
}

/// Ends the run (success or failure); returns only if the caller may not halt.
pub fn system_halt(success: bool) -> Result<(), Error> {
    status(
        raw(
            Call::SystemHalt as u64,
            if success { 0 } else { 1 },
            0,
            0,
            0,
        )
        .0,
    )
}
