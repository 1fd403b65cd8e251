//! DMA through QEMU's `edu` test function (partitions `dma*` of scenarios `dma_regions`
//! and `attack_dma`). edu copies up to 4 KiB between its own buffer (device address
//! 0x40000) and bus addresses, one transfer at a time, taking 100 ms of virtual time.
//!
//! * [`check_own_region`]: the positive control: a pattern written into the partition's DMA
//!   region is read by the device and written back at another offset of the region,
//!   where the partition finds it.

use pci::{Bar, DmaRegion, Record};
use user_rt::println;
use user_rt::protocol::layout::DEVICES_BASE;
use user_rt::sys;

/// edu's DMA registers in BAR 0 and its buffer's device address.
const EDU_DMA_SOURCE: u64 = 0x80;
const EDU_DMA_DESTINATION: u64 = 0x88;
const EDU_DMA_COUNT: u64 = 0x90;
const EDU_DMA_COMMAND: u64 = 0x98;
const EDU_BUFFER: u64 = 0x4_0000;
const COMMAND_START: u64 = 1;
const COMMAND_TO_RAM: u64 = 2;
/// Bytes each transfer of the checks moves.
pub const LENGTH: usize = 256;

/// The partition's edu function and DMA region.
pub struct Edu {
    registers: u64,
    pub record: Record,
    pub region: DmaRegion,
}

impl Edu {
    /// The first device of the partition's device page (an edu function) and its DMA
    /// region; `None` (logged) when either is missing.
    pub fn find(who: &str) -> Option<Self> {
        #[allow(unsafe_code)]
        // SAFETY: syssw maps the records page read-only at DEVICES_BASE before a partition
        // with devices starts, for the life of its task.
        let page = unsafe { core::slice::from_raw_parts(DEVICES_BASE as *const u8, 4096) };
        let record = pci::records(page).next();
        let region = pci::dma_region(page);
        match (record, region) {
            (Some(record), Some(region)) => match record.bars[0] {
                Some(Bar::Memory { base, .. }) => Some(Edu {
                    registers: base,
                    record,
                    region,
                }),
                _ => {
                    println!("{who}: check FAILED: the device has no memory BAR 0");
                    None
                }
            },
            _ => {
                println!("{who}: check FAILED: no device record or no DMA region");
                None
            }
        }
    }

    fn write(&self, offset: u64, value: u64) {
        #[allow(unsafe_code)]
        // SAFETY: syssw mapped edu's BAR 0 (1 MiB) uncached at `registers`; an aligned
        // 64-bit DMA register.
        unsafe {
            core::ptr::write_volatile((self.registers + offset) as *mut u64, value)
        };
    }

    fn read(&self, offset: u64) -> u64 {
        #[allow(unsafe_code)]
        // SAFETY: as in `write`.
        unsafe {
            core::ptr::read_volatile((self.registers + offset) as *const u64)
        }
    }

    /// One transfer of `count` bytes; waits (sleeping, at most 1 s) until edu is done.
    /// Whether it finished.
    pub fn transfer(&self, source: u64, destination: u64, count: u64, to_ram: bool) -> bool {
        self.write(EDU_DMA_SOURCE, source);
        self.write(EDU_DMA_DESTINATION, destination);
        self.write(EDU_DMA_COUNT, count);
        let direction = if to_ram { COMMAND_TO_RAM } else { 0 };
        self.write(EDU_DMA_COMMAND, COMMAND_START | direction);
        for _ in 0..100 {
            sys::sleep_until(sys::clock() + 10_000_000);
            if self.read(EDU_DMA_COMMAND) & COMMAND_START == 0 {
                return true;
            }
        }
        false
    }

    /// The partition's view of its DMA region.
    pub fn region_bytes(&self) -> &'static mut [u8] {
        #[allow(unsafe_code)]
        // SAFETY: syssw maps the DMA region read-write at `region.address` for `length`
        // bytes for the task's life; only this thread touches it (and the device, whose
        // writes the checks wait for).
        unsafe {
            core::slice::from_raw_parts_mut(
                self.region.address as *mut u8,
                self.region.length as usize,
            )
        }
    }
}

fn pattern(i: usize) -> u8 {
    (i as u8).wrapping_mul(7).wrapping_add(0x5a)
}

/// The positive control; see the module documentation. Whether it passed.
pub fn check_own_region(who: &str, edu: &Edu) -> bool {
    let region = edu.region_bytes();
    for (i, b) in region[..LENGTH].iter_mut().enumerate() {
        *b = pattern(i);
    }
    region[4096..4096 + LENGTH].fill(0);
    let bus = edu.region.bus_address;
    let read = edu.transfer(bus, EDU_BUFFER, LENGTH as u64, false);
    let written = edu.transfer(EDU_BUFFER, bus + 4096, LENGTH as u64, true);
    let landed = region[4096..4096 + LENGTH]
        .iter()
        .enumerate()
        .all(|(i, &b)| b == pattern(i));
    let ok = read && written && landed;
    println!(
        "{who}: check {}: edu copied {LENGTH} bytes from its DMA region (bus {bus:#x}) and back at offset 4096",
        if ok { "ok" } else { "FAILED" }
    );
    ok
}
