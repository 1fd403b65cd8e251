//! Time since boot from the TSC, once calibrated; the count of timer interrupts.

use core::sync::atomic::{AtomicU64, Ordering};

static TSC_AT_BOOT: AtomicU64 = AtomicU64::new(0);
static TSC_HZ: AtomicU64 = AtomicU64::new(0);
static TIMER_INTERRUPTS: AtomicU64 = AtomicU64::new(0);
/// Unix time in ns at [`TSC_AT_BOOT`] (0: unknown).
static WALL_CLOCK_AT_BOOT: AtomicU64 = AtomicU64::new(0);

/// Converts a TSC tick count to nanoseconds (0 while the frequency is unknown).
pub fn ticks_to_ns(ticks: u64, hz: u64) -> u64 {
    if hz == 0 {
        return 0;
    }
    (ticks as u128 * 1_000_000_000 / hz as u128) as u64
}

pub fn set_boot_tsc(tsc: u64) {
    TSC_AT_BOOT.store(tsc, Ordering::Relaxed);
}

pub fn set_tsc_hz(hz: u64) {
    TSC_HZ.store(hz, Ordering::Relaxed);
}

/// Records the wall-clock time of boot: the firmware's clock (`at_handoff`, Unix ns, 0 if
/// none) plus the time from the handoff to the kernel's boot TSC.
pub fn set_wall_clock(at_handoff: u64, handoff_tsc: u64) {
    if at_handoff == 0 {
        return;
    }
    let since = ticks_to_ns(boot_tsc().saturating_sub(handoff_tsc), tsc_hz());
    WALL_CLOCK_AT_BOOT.store(at_handoff.saturating_add(since), Ordering::Relaxed);
}

pub fn wall_clock_at_boot() -> u64 {
    WALL_CLOCK_AT_BOOT.load(Ordering::Relaxed)
}

pub fn boot_tsc() -> u64 {
    TSC_AT_BOOT.load(Ordering::Relaxed)
}

pub fn tsc_hz() -> u64 {
    TSC_HZ.load(Ordering::Relaxed)
}

pub fn since_boot_ns() -> u64 {
    let ticks = crate::arch::cpu::rdtsc().wrapping_sub(TSC_AT_BOOT.load(Ordering::Relaxed));
    ticks_to_ns(ticks, tsc_hz())
}

pub fn on_timer_interrupt() {
    TIMER_INTERRUPTS.fetch_add(1, Ordering::Relaxed);
}

pub fn timer_interrupts() -> u64 {
    TIMER_INTERRUPTS.load(Ordering::Relaxed)
}

#[cfg(test)]
#[path = "../host-tests/time.rs"]
mod tests;
