//! The 8254 PIT, used as a known clock for calibration (channel 2 counts down once with its
//! gate driven through port 0x61, without interrupts) and, where an emulator runs several
//! CPUs in turns, as the turn clock (channel 0, its interrupt delivered nowhere): QEMU's
//! single-threaded TCG runs each CPU until the machine's next timer deadline, so a timer
//! that expires every few microseconds bounds every turn without costing the guest an
//! instruction (docs/architecture.md, "Multicore").

use super::cpu::{inb, outb, rdtsc};
use core::sync::atomic::{AtomicBool, Ordering};

pub const FREQUENCY_HZ: u64 = 1_193_182;

/// Busy-waits `ms` milliseconds (at most 50) on PIT channel 2 and returns the TSC ticks
/// that passed, or `None` if the PIT never signalled (no PIT present).
pub fn tsc_ticks_for_ms(ms: u64) -> Option<u64> {
    let count = (FREQUENCY_HZ * ms.min(50) / 1000) as u16;
    let gate = inb(0x61);
    outb(0x61, (gate & !0x02) | 0x01); // gate on, speaker off
    outb(0x43, 0b1011_0000); // channel 2, lobyte/hibyte, mode 0, binary
    outb(0x42, count as u8);
    outb(0x42, (count >> 8) as u8);
    // Restart the count by toggling the gate.
    let g = inb(0x61);
    outb(0x61, g & !0x01);
    outb(0x61, g | 0x01);
    let start = rdtsc();
    // OUT2 (bit 5) goes high when the count reaches zero. Give up after 10^7 polls (seconds even under emulation).
    for _ in 0..10_000_000u64 {
        if inb(0x61) & 0x20 != 0 {
            return Some(rdtsc() - start);
        }
    }
    None
}

/// The turn clock's period.
pub const TURN_NS: u64 = 20_000;
/// The CPUs run in turns and the turn clock has not started yet.
pub static TURNS: AtomicBool = AtomicBool::new(false);

/// Starts the turn clock when a thread is first put on a CPU other than CPU 0
/// ([`TURNS`]): until then the others only halt, their turns are empty, and a clock would
/// cost every idle moment of the machine (QEMU's deterministic time skips idle time only
/// up to its next timer deadline). Lets channel 0 count down in a loop, wrapping every
/// [`TURN_NS`] (rate generator); its interrupt (ISA line 0) reaches no CPU: the IOAPIC
/// keeps its line masked (no partition may own it) and the local APICs' LINT0, where the
/// 8259s would deliver it, is masked.
pub fn start_turn_clock(cpu: u8) {
    if cpu == 0 || !TURNS.swap(false, Ordering::Relaxed) {
        return;
    }
    crate::kprintln!("smp: PIT turn clock started (a thread on CPU {cpu})");
    let count = (FREQUENCY_HZ * TURN_NS / 1_000_000_000).clamp(2, 0xffff) as u16;
    outb(0x43, 0b0011_0100); // channel 0, lobyte/hibyte, mode 2, binary
    outb(0x40, count as u8);
    outb(0x40, (count >> 8) as u8);
}
