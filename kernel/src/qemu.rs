//! Ending a run under QEMU through the isa-debug-exit device (port 0xf4).
//!
//! Convention (an interface, see docs/interfaces.md): 0x10 = success (QEMU exits 33), 0x11 = failure
//! (QEMU exits 35). On a machine without the device the write does nothing and we halt.

/// The two outcomes a run can report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum ExitCode {
    Success = 0x10,
    Failure = 0x11,
}

/// Port of QEMU's isa-debug-exit device.
pub const DEBUG_EXIT_PORT: u16 = 0xf4;

pub fn exit(code: ExitCode) -> ! {
    // What the log still holds goes out first (QEMU stops at once).
    crate::log::flush();
    crate::arch::cpu::outl(DEBUG_EXIT_PORT, code as u32);
    crate::arch::cpu::halt_forever()
}
