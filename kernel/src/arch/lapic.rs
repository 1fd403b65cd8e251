//! Local APIC (xAPIC, MMIO through the direct map): enable, timer, end-of-interrupt.
//!
//! The scheduler's timer is one-shot: in TSC-deadline mode where the CPU has it (the
//! deadline is an exact TSC value, no rounding to the bus clock), else a one-shot count.

use crate::mem::phys_to_virt;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use volatile::VolatilePtr;

const ID: usize = 0x20;
const VERSION: usize = 0x30;
const TASK_PRIORITY: usize = 0x80;
const EOI: usize = 0xb0;
const SPURIOUS: usize = 0xf0;
const INTERRUPT_COMMAND_LOW: usize = 0x300;
const INTERRUPT_COMMAND_HIGH: usize = 0x310;
const LVT_TIMER: usize = 0x320;
const LVT_LINT0: usize = 0x350;
const LVT_LINT1: usize = 0x360;
const LVT_ERROR: usize = 0x370;
const TIMER_INITIAL: usize = 0x380;
const TIMER_CURRENT: usize = 0x390;
const TIMER_DIVIDE: usize = 0x3e0;

const LVT_MASKED: u32 = 1 << 16;
const TIMER_PERIODIC: u32 = 1 << 17;
const TIMER_TSC_DEADLINE: u32 = 2 << 17;
const IA32_TSC_DEADLINE: u32 = 0x6e0;
/// Divide configuration 0b0011 = divide by 16.
const DIVIDE_BY_16: u32 = 0x3;
pub const TIMER_DIVISOR: u64 = 16;

/// Virtual address of the register page; 0 until [`init`].
static BASE: AtomicU64 = AtomicU64::new(0);

fn register(offset: usize) -> VolatilePtr<'static, u32> {
    let base = BASE.load(Ordering::Relaxed);
    assert!(base != 0, "local APIC used before init");
    // SAFETY: the direct-map address of a mapped register block is never 0.
    let register = unsafe { NonNull::new_unchecked((base as usize + offset) as *mut u32) };
    // SAFETY: `base` is the direct-map address of the APIC register page found via ACPI;
    // every offset used here is a 16-byte-aligned 32-bit register inside that page.
    unsafe { VolatilePtr::new(register) }
}

fn read(offset: usize) -> u32 {
    register(offset).read()
}

fn write(offset: usize, value: u32) {
    register(offset).write(value)
}

/// Enables the local APIC at physical address `phys` with every local interrupt masked.
pub fn init(phys: u64) -> (u32, u32) {
    // IA32_APIC_BASE bit 11: global enable (firmware normally leaves it on).
    const IA32_APIC_BASE: u32 = 0x1b;
    let mut msr = x86_64::registers::model_specific::Msr::new(IA32_APIC_BASE);
    // SAFETY: reading the APIC base MSR has no side effects.
    let base = unsafe { msr.read() };
    // SAFETY: setting the global-enable bit of an APIC that exists (MADT listed it).
    unsafe { msr.write(base | (1 << 11)) };
    BASE.store(phys_to_virt(phys), Ordering::Relaxed);
    write(TASK_PRIORITY, 0);
    write(LVT_TIMER, LVT_MASKED);
    write(LVT_LINT0, LVT_MASKED);
    write(LVT_LINT1, LVT_MASKED);
    write(LVT_ERROR, LVT_MASKED);
    write(SPURIOUS, 0x100 | super::idt::SPURIOUS_VECTOR as u32);
    (read(ID) >> 24, read(VERSION) & 0xff)
}

pub fn end_of_interrupt() {
    write(EOI, 0);
}

/// Sends the inter-processor interrupt `command` (the command register's low word) to the
/// CPU with `apic_id`; false if the APIC still shows it pending after 1 ms.
pub fn send_ipi(apic_id: u8, command: u32) -> bool {
    const PENDING: u32 = 1 << 12;
    write(INTERRUPT_COMMAND_HIGH, u32::from(apic_id) << 24);
    write(INTERRUPT_COMMAND_LOW, command);
    let until = crate::time::since_boot_ns() + 1_000_000;
    while read(INTERRUPT_COMMAND_LOW) & PENDING != 0 {
        if crate::time::since_boot_ns() > until {
            return false;
        }
        core::hint::spin_loop();
    }
    true
}

/// Starts a masked one-shot count from the maximum; used for calibration.
pub fn start_calibration_count() {
    write(TIMER_DIVIDE, DIVIDE_BY_16);
    write(LVT_TIMER, LVT_MASKED);
    write(TIMER_INITIAL, u32::MAX);
}

/// Ticks (after the divider) since [`start_calibration_count`].
pub fn calibration_ticks() -> u64 {
    (u32::MAX - read(TIMER_CURRENT)) as u64
}

/// Fires `vector` every `ticks` timer ticks (after the divider).
pub fn start_periodic(vector: u8, ticks: u32) {
    write(TIMER_DIVIDE, DIVIDE_BY_16);
    write(LVT_TIMER, TIMER_PERIODIC | vector as u32);
    write(TIMER_INITIAL, ticks.max(1));
}

/// APIC timer ticks per second (after the divider), set by calibration.
static TIMER_HZ: AtomicU64 = AtomicU64::new(0);
/// The one-shot timer uses TSC-deadline mode.
static TSC_DEADLINE: AtomicBool = AtomicBool::new(false);

/// Whether the CPU has TSC-deadline mode (CPUID.1:ECX bit 24).
pub fn has_tsc_deadline() -> bool {
    let leaf = core::arch::x86_64::__cpuid(1);
    leaf.ecx & (1 << 24) != 0
}

/// Makes [`one_shot_at`] use TSC-deadline mode from now on.
pub fn use_tsc_deadline() {
    TSC_DEADLINE.store(true, Ordering::Relaxed);
}

fn write_tsc_deadline(tsc: u64) {
    let mut msr = x86_64::registers::model_specific::Msr::new(IA32_TSC_DEADLINE);
    // SAFETY: the MSR exists (CPUID said so before TSC_DEADLINE was set); writing it only
    // arms or (0) disarms the local timer.
    unsafe { msr.write(tsc) };
}

pub fn set_timer_hz(hz: u64) {
    TIMER_HZ.store(hz, Ordering::Relaxed);
}

/// One timer interrupt at `deadline` (ns since boot; `u64::MAX` = none). A deadline beyond
/// the counter's range fires early; the handler then simply programs the rest.
pub fn one_shot_at(deadline: u64) {
    if deadline == u64::MAX {
        stop_timer();
        return;
    }
    if TSC_DEADLINE.load(Ordering::Relaxed) {
        // Rounded up, so the interrupt never comes before the deadline.
        let hz = crate::time::tsc_hz() as u128;
        let ticks = (deadline as u128 * hz).div_ceil(1_000_000_000);
        let tsc = crate::time::boot_tsc().saturating_add(ticks.min(u64::MAX as u128) as u64);
        write(
            LVT_TIMER,
            TIMER_TSC_DEADLINE | super::idt::TIMER_VECTOR as u32,
        );
        write_tsc_deadline(tsc.max(1));
        return;
    }
    let delta = deadline.saturating_sub(crate::time::since_boot_ns());
    let ticks = (delta as u128 * TIMER_HZ.load(Ordering::Relaxed) as u128 / 1_000_000_000)
        .clamp(1, u32::MAX as u128) as u32;
    write(TIMER_DIVIDE, DIVIDE_BY_16);
    write(LVT_TIMER, super::idt::TIMER_VECTOR as u32);
    write(TIMER_INITIAL, ticks);
}

pub fn stop_timer() {
    if TSC_DEADLINE.load(Ordering::Relaxed) {
        write_tsc_deadline(0);
    }
    write(LVT_TIMER, LVT_MASKED);
    write(TIMER_INITIAL, 0);
}
