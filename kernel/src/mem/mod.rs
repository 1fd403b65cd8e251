//! Physical memory: the direct map and the frame allocator.

pub mod frames;

use abi::boot::DIRECT_MAP_BASE;

pub const PAGE_SIZE: u64 = 4096;

/// Kernel virtual address of physical address `phys` (through the loader's direct map).
pub const fn phys_to_virt(phys: u64) -> u64 {
    DIRECT_MAP_BASE + phys
}

/// Physical address behind a direct-map address.
pub const fn virt_to_phys(virt: u64) -> u64 {
    virt - DIRECT_MAP_BASE
}

pub mod paging;

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
