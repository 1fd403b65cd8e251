//! Small wrappers around single instructions (port I/O, TSC, halting).

use x86_64::instructions::port::Port;

pub fn outb(port: u16, value: u8) {
    // SAFETY: port writes have no memory-safety effect on this kernel; callers only address
    // devices they own (serial, PIC, PIT, debug-exit).
    unsafe { Port::<u8>::new(port).write(value) }
}

pub fn inb(port: u16) -> u8 {
    // SAFETY: as for `outb`; reads of these device registers have no memory effect.
    unsafe { Port::<u8>::new(port).read() }
}

pub fn outl(port: u16, value: u32) {
    // SAFETY: as for `outb`.
    unsafe { Port::<u32>::new(port).write(value) }
}

pub fn inl(port: u16) -> u32 {
    // SAFETY: as for `inb`.
    unsafe { Port::<u32>::new(port).read() }
}

pub fn rdtsc() -> u64 {
    // SAFETY: RDTSC only reads the time-stamp counter.
    unsafe { core::arch::x86_64::_rdtsc() }
}

/// Stops this CPU for good (interrupts off, so only NMI/SMI could wake it; loop anyway).
pub fn halt_forever() -> ! {
    x86_64::instructions::interrupts::disable();
    loop {
        x86_64::instructions::hlt();
    }
}

/// Lets user code use SSE (the kernel itself is soft-float and never touches it):
/// CR0.MP=1, CR0.EM=0, CR4.OSFXSR=1, CR4.OSXMMEXCPT=1 (SIMD exceptions as #XM).
pub fn enable_sse_for_user() {
    use x86_64::registers::control::{Cr0, Cr0Flags, Cr4, Cr4Flags};
    // SAFETY: these bits only change how SSE instructions behave; the kernel uses none.
    unsafe {
        Cr0::update(|f| {
            f.remove(Cr0Flags::EMULATE_COPROCESSOR);
            f.insert(Cr0Flags::MONITOR_COPROCESSOR);
        })
    };
    // SAFETY: as for CR0: FXSAVE/SSE enablement and #XM delivery only.
    unsafe { Cr4::update(|f| f.insert(Cr4Flags::OSFXSR | Cr4Flags::OSXMMEXCPT_ENABLE)) };
}
