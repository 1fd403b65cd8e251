//! Test program run as the root task: checks the user-mode basics and each system call's
//! success and error paths, then ends the run. The system image entry `test/mode` selects
//! what it does:
//!
//! | mode | checks | module |
//! |---|---|---|
//! | (none) | debug_write, clock, invalid calls, SSE state across calls | here |
//! | `kernel-read` | reads kernel memory, which must fault | here |
//! | `tasks` | tasks, threads, abilities, MCP, control rights, life cycle, scheduling | [`tasks`] |
//! | `quota` | resource partitions and their quotas | [`quota`] |
//! | `memory` | map, map_physical, unmap, protect | [`memory`] |
//! | `ipc` | synchronous IPC, map/grant items, timeouts, rights, notifications | [`ipc`] |
//! | `exceptions` | exceptions and forwarded syscalls as IPC, health monitor | [`exceptions`] |
//! | `no-handler` | a fault without handler or health monitor kills only the thread | [`exceptions`] |
//! | `irq-ports` | interrupts and I/O ports at user level (COM2 in loopback) | [`devices`] |
//! | `windows` | time partitions: punctual windows, TP0 leftover time, MCP, schedule switch | [`timepart`] |
//!
//! Every check prints `check ok: <what>` or `check FAILED: <what>` (and ends the run as
//! failed); a mode that passes prints `all <mode> checks passed` and halts with success.
//! [`child`] has the machinery for running code in extra threads and child tasks.
#![no_std]
#![no_main]
// This program attacks the kernel's isolation on purpose (raw reads of kernel and unmapped
// memory, forged stacks and IPC buffers, child tasks on hand-made memory): raw memory is
// its subject, so the whole program may use `unsafe`; each block still says why it is sound.
#![allow(unsafe_code)]

mod check;
mod child;
mod devices;
mod exceptions;
mod ipc;
mod memory;
mod quota;
mod smp;
mod tasks;
mod timepart;

use check::expect;
use user_rt::abi::syscall::{Call, DEBUG_WRITE_MAX, Error};
use user_rt::abi::sysimg::SystemImage;
use user_rt::{println, sys};

user_rt::entry!(main);

fn main(image_base: u64, image_len: u64) {
    let image =
        SystemImage::parse(root_task::system_image(image_base, image_len)).expect("system image");
    let mode = image.find("test/mode").map(|e| e.data).unwrap_or(b"");
    match mode {
        b"tasks" => return tasks::run(),
        b"quota" => return quota::run(),
        b"memory" => return memory::run(),
        b"ipc" => return ipc::run(),
        b"exceptions" => return exceptions::run(),
        b"no-handler" => return exceptions::run_no_handler(),
        b"windows" => return timepart::run(),
        b"irq-ports" => return devices::run(),
        b"smp" => return smp::run(),
        _ => {}
    }
    if mode == b"kernel-read" {
        println!("reading kernel memory at 0xffffffff80000000");
        #[allow(unsafe_code)]
        // SAFETY: deliberately invalid: the kernel half is supervisor-only, so this must fault.
        let value = unsafe { core::ptr::read_volatile(0xffff_ffff_8000_0000 as *const u64) };
        expect(
            format_args!("kernel memory unreadable (read {value:#x})")
                .as_str()
                .unwrap_or("kernel memory unreadable"),
            false,
        );
        return;
    }

    expect(
        "debug_write of a user buffer",
        sys::debug_write(b"hello from ring 3").is_ok(),
    );
    let t0 = sys::clock();
    let t1 = sys::clock();
    expect("clock is monotonic and running", t1 >= t0 && t0 > 0);
    expect(
        "debug_write of a kernel address is BadAddress",
        sys::debug_write(unsafe_kernel_slice()) == Err(Error::BadAddress),
    );
    let (rax, ..) = sys::raw(Call::DebugWrite as u64, 0, 16, 0, 0);
    expect(
        "debug_write of a null pointer is BadAddress",
        rax == Error::BadAddress as u64,
    );
    let (rax, ..) = sys::raw(
        Call::DebugWrite as u64,
        image_base,
        DEBUG_WRITE_MAX + 1,
        0,
        0,
    );
    expect(
        "debug_write longer than the limit is InvalidArgument",
        rax == Error::InvalidArgument as u64,
    );
    let (rax, ..) = sys::raw(999, 0, 0, 0, 0);
    expect(
        "unknown call number is InvalidCall",
        rax == Error::InvalidCall as u64,
    );
    let (rax, ..) = sys::raw(Call::SystemHalt as u64, 7, 0, 0, 0);
    expect(
        "system_halt with a bad outcome is InvalidArgument",
        rax == Error::InvalidArgument as u64,
    );

    // Callee-saved registers and SSE state survive a system call.
    let x = core::hint::black_box(1.5f64);
    let before = core::hint::black_box(x * 3.0);
    sys::clock();
    expect(
        "floating point works and survives a syscall",
        before == 4.5 && x * x == 2.25,
    );

    println!("all user-mode checks passed");
    let _ = sys::system_halt(true);
}

/// A slice pointing into the kernel half: only its address is passed to the kernel, which
/// must refuse it; it is never dereferenced here.
fn unsafe_kernel_slice() -> &'static [u8] {
    #[allow(unsafe_code)]
    // SAFETY: never read by this program; the kernel checks the range before copying.
    unsafe {
        core::slice::from_raw_parts(0xffff_ffff_8000_0000 as *const u8, 8)
    }
}
