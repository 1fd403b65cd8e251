//! DMA through QEMU's `edu` test function (partitions `dma*` of scenarios `dma_regions`
//! and `attack_dma`). edu copies up to 4 KiB between its own buffer (device address
//! 0x40000) and bus addresses, one transfer at a time, taking 100 ms of virtual time.
//!
//! * [`check_own_region`]: the positive control: a pattern written into the partition's DMA
//!   region is read by the device and written back at another offset of the region,
//!   where the partition finds it.
//! * [`attack`] (partition `dma-attack*`, scenario `attack_dma`, with the IOMMU): the
//!   positive control, then the device writes to [`TARGETS`] outside the region, each of
//!   which the IOMMU must block (syssw reports each as the partition's memory violation),
//!   a read of the other partition's start record (the device must not get its name), then the
//!   positive control once more; logs `dma-attack: done`.

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

    /// Fills edu's buffer with `byte` (via a transfer from the region's last bytes).
    pub fn fill_buffer(&self, byte: u8) -> bool {
        let region = self.region_bytes();
        let at = region.len() - LENGTH;
        region[at..].fill(byte);
        self.transfer(
            self.region.bus_address + at as u64,
            EDU_BUFFER,
            LENGTH as u64,
            false,
        )
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

/// What a target is, and its bus address given the region's.
pub type Target = (&'static str, fn(u64) -> u64);

/// Where [`attack`] has the device write, outside its DMA region: what, and the bus
/// address, relative to the region's own (bus address = physical address, so the region's
/// bus address is its physical address). syssw allocates partitions' memory in configuration
/// order from one ascending pool, the DMA region first, so the page below the region is the
/// last page of the partition configured just before (its stack, holding its start record).
/// The kernel keeps the lowest frames above 1 MiB for itself (its page tables and
/// objects).
pub const TARGETS: [Target; 3] = [
    ("the kernel's memory (its first frame above 1 MiB)", |_| {
        0x10_0000
    }),
    (
        "another partition's memory (the top of the stack of the partition placed before)",
        |own| own - 4096,
    ),
    ("an address no memory is at", |_| 0x7f_ffff_f000),
];

/// The attack; see the module documentation.
pub fn attack(who: &str) {
    let Some(edu) = Edu::find(who) else {
        return;
    };
    let own = edu.region.bus_address;
    println!(
        "{who}: device {}, DMA region at bus address {own:#x}, {} KiB",
        edu.record.address,
        edu.region.length / 1024
    );
    check_own_region(who, &edu);
    for (what, target) in TARGETS {
        let target = target(own);
        let filled = edu.fill_buffer(0xa5);
        println!("{who}: edu writes {LENGTH} bytes to {what} at bus address {target:#x}");
        let finished = edu.transfer(EDU_BUFFER, target, LENGTH as u64, true);
        println!(
            "{who}: check {}: edu finished the write (the IOMMU, not the device, stops it)",
            if filled && finished { "ok" } else { "FAILED" }
        );
    }
    // A read of the top of the other partition's stack, where its start record (with its
    // name) lies: the device must not get those bytes (a blocked read gives it zeros).
    let filled = edu.fill_buffer(0x5a);
    let target = own - LENGTH as u64;
    println!(
        "{who}: edu reads {LENGTH} bytes of another partition's memory at bus address {target:#x}"
    );
    let finished = edu.transfer(target, EDU_BUFFER, LENGTH as u64, false);
    let region = edu.region_bytes();
    region[..LENGTH].fill(0xff);
    let shown = edu.transfer(EDU_BUFFER, own, LENGTH as u64, true);
    let got = &region[..LENGTH];
    let leaked = got.windows(6).any(|w| w == b"victim");
    println!(
        "{who}: check {}: the device got none of that partition's bytes (its buffer holds {})",
        if filled && finished && shown && !leaked {
            "ok"
        } else {
            "FAILED"
        },
        if got.iter().all(|&b| b == 0) {
            "zeros"
        } else if got.iter().all(|&b| b == 0x5a) {
            "its own bytes"
        } else {
            "other bytes"
        }
    );
    if check_own_region(who, &edu) {
        println!("{who}: its own region still works after the blocked writes");
    }
    println!("{who}: done");
}
