//! The VT-d DMA remapping unit's registers (found through the ACPI DMAR table): turning
//! translation on over the tables of `mem::iommu`, invalidating its caches after they
//! change, and taking the faults it recorded. Every wait for the unit is bounded.

use crate::mem::iommu::DmaFault;
use crate::mem::phys_to_virt;

const CAPABILITY: u64 = 0x08;
const EXTENDED_CAPABILITY: u64 = 0x10;
const COMMAND: u64 = 0x18;
const STATUS: u64 = 0x1c;
const ROOT_TABLE: u64 = 0x20;
const CONTEXT_COMMAND: u64 = 0x28;
const FAULT_STATUS: u64 = 0x34;
/// Command/status bits: translation enable, set root-table pointer; the one-shot command
/// bits (never written back from the status).
const TRANSLATION: u32 = 1 << 31;
const SET_ROOT: u32 = 1 << 30;
const ONE_SHOT: u32 = 1 << 30 | 1 << 29 | 1 << 27 | 1 << 24;
/// Invalidate (bit 63) globally (context command: 01 in bits 62:61; IOTLB: 01 in 61:60).
const INVALIDATE_CONTEXTS: u64 = 1 << 63 | 1 << 61;
const INVALIDATE_IOTLB: u64 = 1 << 63 | 1 << 60;
/// The fault recording register's F bit (write one to clear) and the overflow status bit.
const FAULT: u64 = 1 << 63;
const FAULT_OVERFLOW: u32 = 1;
/// Polls of a status register before the unit counts as not answering.
const SPINS: u32 = 1_000_000;
/// Fault records looked at per [`Vtd::take_fault`].
const MAX_RECORDS: u64 = 16;

pub struct Vtd {
    base: u64,
    /// Second-level table levels (3: 39-bit, 4: 48-bit bus addresses) and domain ids.
    pub levels: u32,
    pub domains: u32,
    iotlb: u64,
    records: u64,
    record_count: u64,
}

impl Vtd {
    /// The unit at `base`, if it supports 3- or 4-level second-level tables.
    ///
    /// # Safety
    /// `base` must be the register base of a remapping unit (ACPI DMAR), used by nobody
    /// else (it lies in the window `map_device` never grants).
    pub unsafe fn new(base: u64) -> Option<Self> {
        let mut unit = Self {
            base,
            levels: 0,
            domains: 0,
            iotlb: 0,
            records: 0,
            record_count: 0,
        };
        let cap = unit.read64(CAPABILITY);
        let ecap = unit.read64(EXTENDED_CAPABILITY);
        unit.levels = match (cap >> 8) & 0x1f {
            sagaw if sagaw & 2 != 0 => 3,
            sagaw if sagaw & 4 != 0 => 4,
            _ => return None,
        };
        unit.domains = 1 << (4 + 2 * (cap & 7).min(6));
        unit.iotlb = ((ecap >> 8) & 0x3ff) * 16 + 8;
        unit.records = ((cap >> 24) & 0x3ff) * 16;
        unit.record_count = ((cap >> 40) & 0xff) + 1;
        Some(unit)
    }

    fn register(&self, offset: u64) -> u64 {
        phys_to_virt(self.base) + offset
    }

    fn read64(&self, offset: u64) -> u64 {
        // SAFETY: a register of the unit (constructor contract), aligned, through the
        // direct map.
        unsafe { (self.register(offset) as *const u64).read_volatile() }
    }

    fn write64(&self, offset: u64, value: u64) {
        // SAFETY: as in `read64`.
        unsafe { (self.register(offset) as *mut u64).write_volatile(value) }
    }

    fn read32(&self, offset: u64) -> u32 {
        // SAFETY: as in `read64`, a 32-bit register.
        unsafe { (self.register(offset) as *const u32).read_volatile() }
    }

    fn write32(&self, offset: u64, value: u32) {
        // SAFETY: as in `read32`.
        unsafe { (self.register(offset) as *mut u32).write_volatile(value) }
    }

    /// Issues global command `bit` and waits until the status shows `bit` (translation,
    /// root pointer) set.
    fn command(&self, bit: u32) -> bool {
        let status = self.read32(STATUS) & !ONE_SHOT;
        self.write32(COMMAND, status | bit);
        (0..SPINS).any(|_| self.read32(STATUS) & bit != 0)
    }

    /// Writes `value` to the 64-bit command register at `offset` and waits until the unit
    /// clears its bit 63 (invalidation done).
    fn invalidate_by(&self, offset: u64, value: u64) -> bool {
        self.write64(offset, value);
        (0..SPINS).any(|_| self.read64(offset) >> 63 == 0)
    }

    /// Drops every cached context entry and translation (after the tables changed).
    pub fn invalidate(&self) -> bool {
        self.invalidate_by(CONTEXT_COMMAND, INVALIDATE_CONTEXTS)
            && self.invalidate_by(self.iotlb, INVALIDATE_IOTLB)
    }

    /// Installs root table `root` and turns translation on: from then on a function reaches
    /// only what the tables give it. False if the unit did not answer.
    pub fn enable(&self, root: u64) -> bool {
        self.write64(ROOT_TABLE, root);
        self.command(SET_ROOT) && self.invalidate() && self.command(TRANSLATION)
    }

    /// The first fault the unit recorded, cleared so that the record takes the next one;
    /// `None` when none is recorded (an overflow, faults the unit could not record while
    /// its records were full, is cleared too).
    pub fn take_fault(&self) -> Option<DmaFault> {
        for i in 0..self.record_count.min(MAX_RECORDS) {
            let at = self.records + 16 * i;
            let high = self.read64(at + 8);
            if let Some(fault) = DmaFault::decode(self.read64(at), high) {
                self.write64(at + 8, FAULT);
                return Some(fault);
            }
        }
        self.write32(FAULT_STATUS, FAULT_OVERFLOW);
        None
    }
}
