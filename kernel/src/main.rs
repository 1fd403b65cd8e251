//! The kernel binary: the entry point the loader jumps to and the panic handler. Everything
//! else lives in the library (`kernel::*`) so pure logic is host-testable.
#![no_std]
#![no_main]

use kernel::arch::stack::{KERNEL_STACK, KERNEL_STACK_SIZE};
use kernel::{boot, kprintln, log, qemu};

/// Entry from the loader: `rdi` = virtual address of the `BootInfo`, interrupts off, the
/// loader's stack unmapped. Sets up our stack before touching memory, then never returns.
///
/// # Safety
/// Only the loader may call this, exactly once, with the boot-info address in `rdi`.
#[allow(unsafe_code)] // the ELF entry symbol, a naked stub that sets up the stack
#[unsafe(no_mangle)]
#[unsafe(naked)]
pub unsafe extern "sysv64" fn _start(boot_info: u64) -> ! {
    core::arch::naked_asm!(
        "lea rsp, [rip + {stack} + {size}]",
        "xor ebp, ebp",
        "call {main}",
        "ud2",
        stack = sym KERNEL_STACK,
        size = const KERNEL_STACK_SIZE,
        main = sym kernel_entry,
    )
}

extern "sysv64" fn kernel_entry(boot_info: u64) -> ! {
    boot::start(boot_info)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    log::force_unlock();
    match info.location() {
        Some(at) => kprintln!(
            "KERNEL PANIC at {}:{}:{}: {}",
            at.file(),
            at.line(),
            at.column(),
            info.message()
        ),
        None => kprintln!("KERNEL PANIC: {}", info.message()),
    }
    qemu::exit(qemu::ExitCode::Failure)
}
