//! IOAPIC: found via the MADT; at boot every redirection entry is masked. The first one
//! (inputs from 0) carries the lines user threads attach to (`crate::irq`): line n is
//! routed to vector [`LINE_VECTOR_BASE`] + n on the boot CPU and opened or closed with
//! [`set_line_masked`].

use crate::mem::phys_to_virt;
use abi::machine::InterruptOverride;
use core::ptr::NonNull;
use volatile::VolatilePtr;

const REGISTER_SELECT: usize = 0x00;
const REGISTER_WINDOW: usize = 0x10;
const VERSION_REGISTER: u32 = 0x01;
const REDIRECTION_BASE: u32 = 0x10;
const MASKED: u32 = 1 << 16;

/// Vector of interrupt line 0.
pub const LINE_VECTOR_BASE: u8 = 0x40;

pub struct IoApic {
    base: u64,
}

/// Electrical properties of a global system interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Signal {
    pub active_low: bool,
    pub level_triggered: bool,
}

/// How input `gsi` is signalled: as an override (MADT flags: polarity bits 0-1, trigger
/// bits 2-3; 0b11 = active low / level, 0b00 = the bus default) says, else ISA inputs
/// (< 16) are edge-triggered active high and PCI inputs level-triggered active low.
pub fn signal_of(gsi: u32, overrides: &[InterruptOverride]) -> Signal {
    let isa = gsi < 16;
    let default = Signal {
        active_low: !isa,
        level_triggered: !isa,
    };
    match overrides.iter().find(|o| o.gsi == gsi) {
        None => default,
        Some(o) => Signal {
            active_low: match o.flags & 3 {
                0 => default.active_low,
                p => p == 3,
            },
            level_triggered: match (o.flags >> 2) & 3 {
                0 => default.level_triggered,
                t => t == 3,
            },
        },
    }
}

/// The IOAPIC for lines 0.. and each line's redirection entry (low word, masked).
struct Lines {
    apic: IoApic,
    count: u32,
    entries: [u32; crate::irq::LINES],
}

static LINES: spin::Once<Lines> = spin::Once::new();

/// Makes `apic` (whose inputs start at 0) the one for user lines: every line it has gets
/// its vector, signal properties and destination, and stays masked.
pub fn install(apic: IoApic, destination_apic_id: u32, overrides: &[InterruptOverride]) {
    let count = apic.line_count().min(crate::irq::LINES as u32);
    let mut entries = [MASKED; crate::irq::LINES];
    for line in 0..count {
        let signal = signal_of(line, overrides);
        entries[line as usize] = MASKED
            | (LINE_VECTOR_BASE as u32 + line)
            | (signal.active_low as u32) << 13
            | (signal.level_triggered as u32) << 15;
        apic.write(REDIRECTION_BASE + 2 * line + 1, destination_apic_id << 24);
        apic.write(REDIRECTION_BASE + 2 * line, entries[line as usize]);
    }
    LINES.call_once(|| Lines {
        apic,
        count,
        entries,
    });
}

/// Opens or closes user line `line` (ignored for lines the IOAPIC does not have).
pub fn set_line_masked(line: usize, masked: bool) {
    if let Some(l) = LINES.get()
        && (line as u32) < l.count
    {
        let entry = if masked {
            l.entries[line]
        } else {
            l.entries[line] & !MASKED
        };
        l.apic.write(REDIRECTION_BASE + 2 * line as u32, entry);
    }
}

impl IoApic {
    /// # Safety
    /// `phys` must be the register base of an IOAPIC (as listed in the MADT).
    pub unsafe fn new(phys: u64) -> Self {
        Self {
            base: phys_to_virt(phys),
        }
    }

    fn register(&self, offset: usize) -> VolatilePtr<'_, u32> {
        // SAFETY: the direct-map address of a mapped register block is never 0.
        let register = unsafe { NonNull::new_unchecked((self.base as usize + offset) as *mut u32) };
        // SAFETY: `base` maps the IOAPIC's register page (constructor contract); offsets are
        // the two architectural 32-bit registers.
        unsafe { VolatilePtr::new(register) }
    }

    fn read(&self, index: u32) -> u32 {
        self.register(REGISTER_SELECT).write(index);
        self.register(REGISTER_WINDOW).read()
    }

    fn write(&self, index: u32, value: u32) {
        self.register(REGISTER_SELECT).write(index);
        self.register(REGISTER_WINDOW).write(value);
    }

    /// Number of redirection entries (interrupt lines).
    pub fn line_count(&self) -> u32 {
        ((self.read(VERSION_REGISTER) >> 16) & 0xff) + 1
    }

    pub fn mask_all(&self) {
        for line in 0..self.line_count() {
            self.write(REDIRECTION_BASE + 2 * line, MASKED);
            self.write(REDIRECTION_BASE + 2 * line + 1, 0);
        }
    }
}

#[cfg(test)]
#[path = "../../host-tests/ioapic.rs"]
mod tests;
