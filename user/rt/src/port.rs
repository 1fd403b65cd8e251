//! x86 port I/O from ring 3. A port the task was not granted (`io_grant`) raises #GP,
//! delivered to the thread's exception handler like any fault.

/// Reads a byte from `port`.
pub fn inb(port: u16) -> u8 {
    let value: u8;
    // SAFETY: `in` touches no memory of this program; the TSS I/O bitmap decides whether
    // the access happens or faults.
    #[allow(unsafe_code)]
    unsafe {
        core::arch::asm!("in al, dx", out("al") value, in("dx") port, options(nomem, nostack, preserves_flags))
    };
    value
}

/// Writes a byte to `port`.
pub fn outb(port: u16, value: u8) {
    // SAFETY: as for `inb`.
    #[allow(unsafe_code)]
    unsafe {
        core::arch::asm!("out dx, al", in("dx") port, in("al") value, options(nomem, nostack, preserves_flags))
    };
}
