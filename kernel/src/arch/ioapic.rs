//! IOAPIC: found via the MADT; at boot every redirection entry is masked. Later stages
//! route granted lines to user threads.

use crate::mem::phys_to_virt;
use core::ptr::NonNull;
use volatile::VolatilePtr;

const REGISTER_SELECT: usize = 0x00;
const REGISTER_WINDOW: usize = 0x10;
const VERSION_REGISTER: u32 = 0x01;
const REDIRECTION_BASE: u32 = 0x10;
const MASKED: u32 = 1 << 16;

pub struct IoApic {
    base: u64,
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
        // SAFETY: `base` maps the IOAPIC's register page (constructor contract); offsets are
        // the two architectural 32-bit registers.
        unsafe {
            VolatilePtr::new(NonNull::new_unchecked(
                (self.base as usize + offset) as *mut u32,
            ))
        }
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
