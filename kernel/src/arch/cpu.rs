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
