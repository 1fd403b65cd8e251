//! syssw: the system software, the root task (ring 3).
//!
//! It will read the static configuration from the system image and distribute every
//! resource (memory, I/O ports, time windows, kernel memory) to the partitions, own the
//! inter-partition ports and the health monitor. It must never allocate after start-up.
//!
//! Stage: the kernel does not start user tasks yet (boot foundation); this binary is packed
//! into `system.img` so the image layout and the user-mode build are exercised end to end.
#![no_std]
#![no_main]
#![forbid(unsafe_op_in_unsafe_fn)]
#![deny(unsafe_code)]

// SAFETY: `_start` is the ELF entry symbol; nothing else defines it (no C start files).
#[allow(unsafe_code)]
#[unsafe(no_mangle)]
pub extern "C" fn _start() -> ! {
    loop {
        core::hint::spin_loop();
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {
        core::hint::spin_loop();
    }
}
