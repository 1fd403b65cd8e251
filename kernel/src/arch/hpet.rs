//! HPET main counter, used as the reference clock for calibration when ACPI lists one.

use crate::mem::phys_to_virt;
use core::ptr::NonNull;
use volatile::VolatilePtr;

const CAPABILITIES: usize = 0x00;
const CONFIGURATION: usize = 0x10;
const MAIN_COUNTER: usize = 0xf0;

pub struct Hpet {
    base: u64,
    /// Counter period in femtoseconds.
    period_fs: u64,
}

impl Hpet {
    /// # Safety
    /// `phys` must be the register base of an HPET (from the ACPI HPET table).
    pub unsafe fn new(phys: u64) -> Option<Self> {
        let mut hpet = Self {
            base: phys_to_virt(phys),
            period_fs: 0,
        };
        hpet.period_fs = hpet.register(CAPABILITIES).read() >> 32;
        // The specification caps the period at 100 ns; 0 or more means no usable HPET.
        if hpet.period_fs == 0 || hpet.period_fs > 100_000_000 {
            return None;
        }
        let config = hpet.register(CONFIGURATION);
        config.write(config.read() | 1); // ENABLE_CNF: the main counter runs
        Some(hpet)
    }

    fn register(&self, offset: usize) -> VolatilePtr<'_, u64> {
        // SAFETY: the direct-map address of a mapped register block is never 0.
        let register = unsafe { NonNull::new_unchecked((self.base as usize + offset) as *mut u64) };
        // SAFETY: `base` maps the HPET register block (constructor contract); the offsets are
        // 64-bit registers of its general block.
        unsafe { VolatilePtr::new(register) }
    }

    pub fn frequency_hz(&self) -> u64 {
        1_000_000_000_000_000 / self.period_fs
    }

    pub fn counter(&self) -> u64 {
        self.register(MAIN_COUNTER).read()
    }

    /// Busy-waits until `ticks` counter ticks have passed since `start`.
    pub fn wait_until(&self, start: u64, ticks: u64) {
        while self.counter().wrapping_sub(start) < ticks {
            core::hint::spin_loop();
        }
    }
}
