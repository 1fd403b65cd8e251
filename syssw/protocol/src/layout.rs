//! A partition's address space as syssw builds it (an interface between syssw and every
//! partition program, and the input of the boot-time budget in `syssw-core`):
//!
//! | what | where | rights |
//! |---|---|---|
//! | the image's loadable segments | their ELF addresses, below [`DATA_BASE`] | per segment |
//! | its data entry (`data/<partition>` in system.img), if any | [`DATA_BASE`] | read-only |
//! | its memory pool: the rest of its `memory`, for a partition with the `map` ability | [`POOL_BASE`] | read-write |
//! | the same frames again | [`POOL_EXEC_BASE`] | read-execute |
//! | shared-memory segments it is attached to | [`shared_address`] | as configured |
//! | its PCI functions' records (`pci::records`), if it owns any (`devices`) | [`DEVICES_BASE`] | read-only |
//! | their memory BARs, uncached, each after an unmapped page | from [`DEVICES_BASE`] + 8 KiB, in the records | read-write |
//! | its DMA region (`dma`), physically contiguous, part of its `memory` | [`DMA_BASE`] (`pci::dma_region`) | read-write |
//! | the stack, the start record at its very top | below [`STACK_TOP`], one unmapped guard page under it | read-write |

/// Where syssw maps a partition's shared-memory segments: the first configured segment
/// here, each next one 2 GiB per started GiB of the ones before further up (the same
/// address in every partition that has the segment).
pub const SHARED_BASE: u64 = 0x0000_6000_0000_0000;

/// Where syssw maps a partition's data entry (e.g. a soft-PLC's program package),
/// read-only, for the partition's whole life; images must lie below it.
pub const DATA_BASE: u64 = 0x0000_5000_0000_0000;

/// Where syssw maps a partition's memory pool: for a partition with the `map` ability, the
/// part of its configured `memory` its image, data entry and stack leave free, zeroed at
/// every start but a warm restart, read-write. The partition maps these pages into its own
/// child tasks (a paravirtualized guest backs its processes' memory with them); they are
/// its own memory, so nothing of another partition is reachable through them.
pub const POOL_BASE: u64 = 0x0000_5800_0000_0000;

/// Where syssw maps the pool's frames a second time, read-execute: the source of the
/// executable pages the partition maps into its child tasks (no page is ever writable and
/// executable in one mapping). Page `i` of the pool is at `POOL_BASE + i * 4096` and
/// `POOL_EXEC_BASE + i * 4096`.
pub const POOL_EXEC_BASE: u64 = 0x0000_5c00_0000_0000;

/// Where syssw maps the page that tells a partition which PCI functions it owns and what
/// of them it got (`pci::records`: I/O ports, the addresses of the memory BARs, the
/// interrupt line); the memory BARs follow, in record order, each after an unmapped page.
/// The memory a partition's devices may reach by DMA is at [`DMA_BASE`].
pub const DEVICES_BASE: u64 = 0x0000_6800_0000_0000;

/// Where syssw maps a partition's DMA region (`dma`): physically contiguous frames of its
/// memory, zeroed at boot and at every cold restart, read-write; the device page says where
/// it is and which bus address a device must use for it (`pci::dma_region`).
pub const DMA_BASE: u64 = 0x0000_6c00_0000_0000;

/// Top of a partition's stack (its start record is at the very top).
pub const STACK_TOP: u64 = 0x0000_7ff0_0000_0000;

/// The address of a shared-memory segment whose predecessors (in configuration order)
/// have the sizes `before` (bytes): each predecessor takes 2 GiB for every whole GiB of its
/// size plus one, which leaves an unmapped gap behind every segment.
pub fn shared_address(before: impl Iterator<Item = u64>) -> u64 {
    SHARED_BASE + before.map(|size| (size >> 30) + 1).sum::<u64>() * (2 << 30)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_segments_get_two_gib_per_started_gib() {
        assert_eq!(shared_address([].into_iter()), SHARED_BASE);
        assert_eq!(shared_address([4096].into_iter()), SHARED_BASE + (2 << 30));
        assert_eq!(
            shared_address([4096, 1 << 30].into_iter()),
            SHARED_BASE + 3 * (2 << 30)
        );
    }

    #[test]
    fn the_regions_do_not_overlap() {
        const {
            assert!(
                DATA_BASE < POOL_BASE
                    && POOL_BASE < POOL_EXEC_BASE
                    && POOL_EXEC_BASE < SHARED_BASE
                    && SHARED_BASE < DEVICES_BASE
                    && DEVICES_BASE < DMA_BASE
                    && DMA_BASE < STACK_TOP
            )
        };
    }
}
