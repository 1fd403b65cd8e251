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
