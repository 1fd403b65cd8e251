//! The partition's DMA region (`dma`): where syssw put it and the bus address the device
//! must use. Not there yet: syssw does not hand partitions DMA regions, so the driver
//! cannot start.

use crate::device::DmaRegion;

pub fn region() -> Option<DmaRegion> {
    None
}
