//! The user-mode runtime shared by syssw, partitions and test programs: system-call stubs,
//! the entry macro, a heap-free line printer, a panic handler, and the `mem*` functions a
//! freestanding (libc-less) Rust binary needs; plus IPC-buffer access ([`ipc_buffer`]).
//! What only the root task needs (its start information, the system image, spawning images
//! in child tasks) is in `syssw/root` (crate `root-task`).
//!
//! It must stay free of policy and of allocation; the only `unsafe` code is the `syscall`
//! instruction stubs, the `mem*` primitives and raw accesses to memory the kernel maps
//! (IPC buffers), each with its justification.
#![no_std]

pub mod ipc_buffer;
pub mod mem;
pub mod partition;
pub mod port;
pub mod print;
pub mod service;
pub mod sys;

pub use abi;
pub use protocol;

/// Defines the ELF entry `_start(arg0, arg1)` that calls `$main(arg0, arg1)` and ends the
/// thread when it returns.
#[macro_export]
macro_rules! entry {
    ($main:path) => {
        // SAFETY: `_start` is the ELF entry symbol; no C start files define it.
        #[allow(unsafe_code)]
        #[unsafe(no_mangle)]
        pub extern "C" fn _start(arg0: u64, arg1: u64) -> ! {
            $main(arg0, arg1);
            $crate::sys::thread_exit()
        }
    };
}

#[cfg(not(test))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    match info.location() {
        Some(at) => println!("panic at {}:{}: {}", at.file(), at.line(), info.message()),
        None => println!("panic: {}", info.message()),
    }
    // A partition reports the panic to syssw's health monitor (APPLICATION_ERROR; the
    // configured action may stop it); the root task may end the run; anyone else just
    // stops its thread.
    service::report_error_bare(protocol::ErrorCode::ApplicationError);
    let _ = sys::system_halt(false);
    sys::thread_exit()
}

/// The precompiled `core` carries unwind tables that name this symbol; with `panic=abort`
/// nothing ever unwinds, so it is never called.
// SAFETY: a unique definition of the symbol (no std, no libgcc in these binaries; the
// host's unit tests link std's).
#[cfg(not(test))]
#[allow(unsafe_code)]
#[unsafe(no_mangle)]
pub extern "C" fn rust_eh_personality() {}

/// The precompiled `alloc` has landing pads (in `format!`, `String::from_utf8_lossy`) that
/// resume unwinding through this symbol; with `panic=abort` nothing ever unwinds, so it is
/// never called. Were it reached, it stops the thread rather than run on.
// SAFETY: a unique definition of the symbol (no libgcc_eh in these binaries; the host's
// unit tests link std's).
#[cfg(not(test))]
#[allow(unsafe_code, non_snake_case)]
#[unsafe(no_mangle)]
pub extern "C" fn _Unwind_Resume() -> ! {
    sys::thread_exit()
}
