//! The user-mode runtime shared by syssw, partitions and test programs: system-call stubs,
//! the entry macro, a heap-free line printer, a panic handler, and the `mem*` functions a
//! freestanding (libc-less) Rust binary needs; plus IPC-buffer access ([`ipc_buffer`]) and
//! the mechanism to start the caller's image in child tasks ([`spawn`]).
//!
//! It must stay free of policy and of allocation; the only `unsafe` code is the `syscall`
//! instruction stubs, the `mem*` primitives and raw accesses to memory the kernel maps
//! (IPC buffers, the own ELF headers, frames being filled), each with its justification.
#![no_std]
#![forbid(unsafe_op_in_unsafe_fn)]

pub mod ipc_buffer;
pub mod mem;
pub mod partition;
pub mod port;
pub mod print;
pub mod service;
pub mod spawn;
pub mod sys;
pub mod window;

pub use abi;

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
    service::report_error_bare(service::error::APPLICATION_ERROR);
    let _ = sys::system_halt(false);
    sys::thread_exit()
}

/// The system image the kernel mapped for the root task (`rdi`/`rsi` at entry, see
/// `abi::syscall`), as a byte slice.
pub fn system_image(base: u64, len: u64) -> &'static [u8] {
    assert_eq!(
        base,
        abi::syscall::ROOT_SYSTEM_IMAGE_BASE,
        "not started as the root task"
    );
    #[allow(unsafe_code)]
    // SAFETY: the kernel maps `len` bytes at ROOT_SYSTEM_IMAGE_BASE read-only for the whole
    // life of the root task, and nothing writes them.
    unsafe {
        core::slice::from_raw_parts(base as *const u8, len as usize)
    }
}

/// The precompiled `core` carries unwind tables that name this symbol; with `panic=abort`
/// nothing ever unwinds, so it is never called.
// SAFETY: a unique definition of the symbol (no std, no libgcc in these binaries).
#[allow(unsafe_code)]
#[unsafe(no_mangle)]
pub extern "C" fn rust_eh_personality() {}

/// The root task's start information (mapped read-only by the kernel at
/// `abi::syscall::ROOT_INFO_BASE`). Only valid in the root task.
pub fn root_info() -> &'static abi::root::RootInfo {
    #[allow(unsafe_code)]
    // SAFETY: the kernel maps a RootInfo page read-only at ROOT_INFO_BASE for the life of
    // the root task (checked by the magic below before use).
    let info = unsafe { &*(abi::syscall::ROOT_INFO_BASE as *const abi::root::RootInfo) };
    assert_eq!(info.magic, abi::root::ROOT_INFO_MAGIC, "not the root task");
    info
}
