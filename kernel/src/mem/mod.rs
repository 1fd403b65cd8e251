//! Physical memory: the direct map and the frame allocator.
//!
//! On the target every physical address is reached through the loader's direct map. In host
//! unit tests "physical memory" is an arena of [`test_arena::FRAMES`] frames, so page
//! tables, address spaces and the object logic built on them run unchanged on the host.

pub mod frames;
pub mod iommu;
pub mod paging;

#[cfg(not(test))]
use abi::boot::DIRECT_MAP_BASE;

pub const PAGE_SIZE: u64 = 4096;

/// Kernel virtual address of physical address `phys` (through the loader's direct map).
#[cfg(not(test))]
pub const fn phys_to_virt(phys: u64) -> u64 {
    DIRECT_MAP_BASE + phys
}

#[cfg(test)]
pub fn phys_to_virt(phys: u64) -> u64 {
    test_arena::base() + phys
}

/// A zeroed frame from the kernel's allocator.
pub fn alloc_zeroed_frame() -> Option<u64> {
    let frame = crate::boot::FRAMES
        .get()?
        .lock()
        .allocate(&crate::boot::DirectMapLinks)?;
    // SAFETY: a frame just taken from the allocator belongs to nobody else; the direct map
    // covers it.
    unsafe { core::ptr::write_bytes(phys_to_virt(frame) as *mut u8, 0, PAGE_SIZE as usize) };
    Some(frame)
}

/// Returns a frame obtained from [`alloc_zeroed_frame`].
///
/// # Safety
/// `frame` must come from [`alloc_zeroed_frame`], be freed once, and no longer be used:
/// not mapped, not a page table, not a bitmap the TSS may load. The allocator links free
/// frames through their first bytes, so a frame still in use would be corrupted.
pub unsafe fn free_frame(frame: u64) {
    if let Some(frames) = crate::boot::FRAMES.get() {
        frames.lock().free(frame, &mut crate::boot::DirectMapLinks);
    }
}

/// The firmware's memory map, kept from boot (its BOOT_INFO frames are never reused).
pub static MEMORY_MAP: spin::Once<&'static [abi::boot::MemoryRegion]> = spin::Once::new();

/// The local APIC's, IOAPIC's and HPET's fixed window of the PC platform.
const INTERRUPT_WINDOW: (u64, u64) = (0xfec0_0000, 0xff00_0000);

/// True if the pages from `start` can only be device registers: above the first MiB, below
/// 64 TiB, outside the interrupt controllers' window and outside every region of the
/// firmware's memory map, whatever its kind (RAM, ACPI, firmware, reserved such as ECAM,
/// flash). False until the memory map is known.
pub fn is_device_memory(start: u64, pages: u64) -> bool {
    let Some(end) = pages
        .checked_mul(PAGE_SIZE)
        .and_then(|len| start.checked_add(len))
    else {
        return false;
    };
    let overlaps = |(lo, hi): (u64, u64)| start < hi && lo < end;
    start >= 1 << 20
        && end <= 1 << 46
        && !overlaps(INTERRUPT_WINDOW)
        && MEMORY_MAP.get().is_some_and(|map| {
            !map.iter()
                .any(|r| overlaps((r.start, r.start + r.pages * PAGE_SIZE)))
        })
}

/// Frames the kernel allocator can still hand out.
pub fn free_frames() -> u64 {
    crate::boot::FRAMES
        .get()
        .map_or(0, |f| f.lock().free_frames())
}

#[cfg(test)]
pub mod test_arena {
    //! Host-test physical memory: a leaked, page-aligned arena whose frames the global
    //! frame allocator hands out (frame addresses are offsets into the arena).
    use super::PAGE_SIZE;
    use abi::boot::{MemoryKind, MemoryRegion};
    use std::sync::OnceLock;

    pub const FRAMES: u64 = 8192;
    /// The upper half of the arena is "user memory" (never handed out by the allocator).
    pub const USER_BASE: u64 = FRAMES / 2 * PAGE_SIZE;
    static BASE: OnceLock<u64> = OnceLock::new();

    pub fn base() -> u64 {
        *BASE.get_or_init(|| {
            let layout =
                std::alloc::Layout::from_size_align((FRAMES * PAGE_SIZE) as usize, 4096).unwrap();
            // SAFETY: non-zero size; the arena is leaked on purpose (lives for the test run).
            let p = unsafe { std::alloc::alloc_zeroed(layout) };
            assert!(!p.is_null());
            p as u64
        })
    }

    static EXCLUSIVE: std::sync::Mutex<()> = std::sync::Mutex::new(());

    /// Installs the arena as the kernel's frame allocator (idempotent) and serialises the
    /// tests that use it, so frame counts they measure are their own.
    pub fn init() -> std::sync::MutexGuard<'static, ()> {
        let guard = EXCLUSIVE.lock().unwrap_or_else(|e| e.into_inner());
        base();
        crate::boot::FRAMES.call_once(|| {
            let region = MemoryRegion {
                start: PAGE_SIZE,
                pages: FRAMES / 2 - 1,
                kind: MemoryKind::USABLE,
                _reserved: 0,
            };
            spin::Mutex::new(super::frames::FrameAllocator::new(&[region], PAGE_SIZE))
        });
        guard
    }
}
