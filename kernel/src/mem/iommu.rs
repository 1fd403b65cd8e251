//! DMA remapping tables (Intel VT-d, legacy mode): what each PCI function may reach by DMA.
//!
//! Bus address = physical address (identity): a function confined to a DMA region reaches
//! the region's frames at bus addresses equal to their physical addresses, and no other bus
//! address translates, so every DMA outside the region (the kernel's image and memory,
//! other partitions' memory, unmapped addresses) faults in the remapping unit instead of
//! reaching memory. A function with no context entry (every function but the confined ones)
//! reaches nothing. The tables (root table, a context table per bus, one second-level page
//! table tree and domain per function) come from [`TABLE_FRAMES`] frames reserved at boot;
//! the register programming is `arch::vtd`. Pure table logic, host-tested.

use super::{PAGE_SIZE, alloc_zeroed_frame, phys_to_virt};
use abi::syscall::{Error, MAP_MAX_PAGES};

/// Frames reserved at boot for the tables (the root table is the first).
pub const TABLE_FRAMES: usize = 64;
/// Entry bits: present (root and context entries), read + write (second-level entries).
const PRESENT: u64 = 1;
const READ_WRITE: u64 = 3;
const ADDRESS: u64 = 0x000f_ffff_ffff_f000;

/// A root entry (low quadword; the high one is reserved, 0): bus `b`'s context table.
pub const fn root_entry(context_table: u64) -> u64 {
    context_table | PRESENT
}

/// A context entry (low, high quadword): untranslated requests through the second-level
/// tree at `top` (translation type 0, fault reporting on), `levels` levels (address-width
/// field `levels - 2`: 1 = 39 bits, 2 = 48 bits), tagged `domain` in the IOTLB.
pub const fn context_entry(top: u64, domain: u16, levels: u32) -> (u64, u64) {
    (top | PRESENT, (levels as u64 - 2) | (domain as u64) << 8)
}

/// A second-level entry: the next table, or at the last level the frame, read-write.
pub const fn second_level_entry(frame: u64) -> u64 {
    frame | READ_WRITE
}

/// A DMA request the remapping unit blocked, from a fault recording register.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DmaFault {
    /// The requester: bus << 8 | device << 3 | function.
    pub source: u16,
    /// The page of the bus address it asked for.
    pub address: u64,
    /// The VT-d fault reason (e.g. 2: no context entry, 6: not mapped for read, 5: write).
    pub reason: u8,
    pub write: bool,
}

impl DmaFault {
    /// The fault recorded in a 128-bit fault recording register (low, high quadword): bits
    /// 63:12 the page, 79:64 the source, 103:96 the reason, 126 the type (1 = read), 127
    /// the F bit; `None` when F is clear (nothing recorded).
    pub fn decode(low: u64, high: u64) -> Option<Self> {
        (high >> 63 != 0).then_some(Self {
            source: high as u16,
            address: low & !(PAGE_SIZE - 1),
            reason: (high >> 32) as u8,
            write: high & 1 << 62 == 0,
        })
    }
}

/// The tables and the frames they are built from.
pub struct DmaTables {
    levels: u32,
    frames: [u64; TABLE_FRAMES],
    used: usize,
    /// Domain ids handed out (1..), and how many the unit has.
    domains: u32,
    max_domains: u32,
}

/// The 64-bit entry `index` of table `table`.
fn entry(table: u64, index: u64) -> *mut u64 {
    (phys_to_virt(table) + index * 8) as *mut u64
}

fn read(table: u64, index: u64) -> u64 {
    // SAFETY: `table` is one of the frames reserved for the tables (never anything else),
    // `index` < 512; the direct map covers it.
    unsafe { entry(table, index).read_volatile() }
}

fn write(table: u64, index: u64, value: u64) {
    // SAFETY: as in `read`; the remapping unit reads these entries, so volatile.
    unsafe { entry(table, index).write_volatile(value) }
}

impl DmaTables {
    /// Reserves the frames (zeroed: an empty root table confines every function to
    /// nothing) for `levels`-level second-level tables and a unit with `max_domains`
    /// domain ids; `None` if the kernel's allocator cannot give them.
    pub fn new(levels: u32, max_domains: u32) -> Option<Self> {
        let mut frames = [0; TABLE_FRAMES];
        for frame in frames.iter_mut() {
            *frame = alloc_zeroed_frame()?;
        }
        Some(Self {
            levels,
            frames,
            used: 1,
            domains: 0,
            max_domains,
        })
    }

    /// The root table (for the unit's root-table address register).
    pub fn root(&self) -> u64 {
        self.frames[0]
    }

    fn take(&mut self) -> Result<u64, Error> {
        let frame = *self.frames.get(self.used).ok_or(Error::OutOfResources)?;
        self.used += 1;
        Ok(frame)
    }

    /// The table entry `index` of `table` points to; a fresh one made present with `bits`
    /// if it points nowhere yet.
    fn next(&mut self, table: u64, index: u64, bits: u64) -> Result<u64, Error> {
        let e = read(table, index);
        if e & PRESENT != 0 {
            return Ok(e & ADDRESS);
        }
        let frame = self.take()?;
        write(table, index, frame | bits);
        Ok(frame)
    }

    /// Lets function `source` (bus << 8 | device << 3 | function) reach the `pages`
    /// (1..=[`MAP_MAX_PAGES`]) frames from `physical` at the same bus addresses; what it
    /// reached before stays. The caller checks that the frames are memory it may give.
    pub fn confine(&mut self, source: u16, physical: u64, pages: u64) -> Result<(), Error> {
        let width = 12 + 9 * self.levels;
        if !physical.is_multiple_of(PAGE_SIZE)
            || !(1..=MAP_MAX_PAGES).contains(&pages)
            || physical > (1 << width) - pages * PAGE_SIZE
        {
            return Err(Error::InvalidArgument);
        }
        let context = self.next(self.root(), 2 * u64::from(source >> 8), PRESENT)?;
        let slot = 2 * u64::from(source & 0xff);
        let mut top = read(context, slot);
        if top & PRESENT == 0 {
            if self.domains + 1 >= self.max_domains {
                return Err(Error::OutOfResources);
            }
            let frame = self.take()?;
            self.domains += 1;
            let (low, high) = context_entry(frame, self.domains as u16, self.levels);
            write(context, slot + 1, high);
            write(context, slot, low);
            top = low;
        }
        for page in 0..pages {
            let at = physical + page * PAGE_SIZE;
            let mut table = top & ADDRESS;
            for level in (1..self.levels).rev() {
                table = self.next(table, (at >> (12 + 9 * level)) & 511, READ_WRITE)?;
            }
            write(table, (at >> 12) & 511, second_level_entry(at));
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "../../host-tests/iommu.rs"]
mod tests;
