//! virtio-net on the shared virtio transport and split queue (the `virtio` crate, re-exported
//! here): the features the NIC takes, the net header, its two queues and how the NIC's DMA
//! region is laid out for them ([`DmaLayout`]).
//!
//! The driver keeps it simple: one descriptor per frame (the 12-byte virtio-net header
//! and the frame in one buffer, which VIRTIO_F_VERSION_1 allows), descriptor `i` always
//! bound to buffer `i`, no offloads, no event index, INTx interrupts (the transmit queue's
//! only while it is full: the NIC partition takes sent buffers back on its next pass).

use ::virtio::queue::{QueueLayout, RINGS_SIZE, queue_size};
pub use ::virtio::{
    FEATURE_ACCESS_PLATFORM, FEATURE_VERSION_1, ISR_QUEUE, Layout, LayoutError, Memory, Queue,
    Region, Used, common, status,
};

/// The MAC address in the device configuration: taken when offered.
pub const FEATURE_MAC: u64 = 1 << 5;

/// The features to accept of `offered`; `None` when the device is not a virtio 1.x device.
pub fn negotiate(offered: u64) -> Option<u64> {
    ::virtio::negotiate(offered, FEATURE_MAC)
}

/// The virtio-net header in front of every frame (VIRTIO_F_VERSION_1: with `num_buffers`).
/// All zero on transmit: no checksum offload, no segmentation.
pub const NET_HEADER: usize = 12;
/// The receive and transmit queues' indices.
pub const RECEIVE_QUEUE: u16 = 0;
pub const TRANSMIT_QUEUE: u16 = 1;

/// Descriptors a queue uses (the device may offer more; the driver sets the size).
pub const QUEUE_SIZE: u16 = 64;
/// One buffer per descriptor: header + the largest frame, rounded up.
pub const BUFFER_SIZE: usize = 2048;

/// The DMA region's layout: the receive queue's rings, the transmit queue's rings, then
/// the receive buffers and the transmit buffers (`size` each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DmaLayout {
    pub size: u16,
}

impl DmaLayout {
    /// A layout with queues of `size` descriptors (the device's maximum and
    /// [`QUEUE_SIZE`], whichever is smaller; a power of two) within `bytes` of region.
    pub fn new(device_max: u16, bytes: usize) -> Option<DmaLayout> {
        let size = queue_size(device_max, QUEUE_SIZE);
        let layout = DmaLayout { size };
        (size > 0 && layout.bytes() <= bytes).then_some(layout)
    }

    /// Bytes of DMA region it needs.
    pub fn bytes(&self) -> usize {
        2 * RINGS_SIZE + 2 * usize::from(self.size) * BUFFER_SIZE
    }

    /// Where queue `q`'s rings start.
    pub fn rings(&self, q: u16) -> usize {
        usize::from(q) * RINGS_SIZE
    }

    /// Queue `q` (its rings zeroed in `mem`), the region at bus address `bus`.
    pub fn queue(&self, mem: &mut impl Memory, q: u16, bus: u64) -> Option<Queue> {
        let layout = QueueLayout {
            index: q,
            size: self.size,
            rings: self.rings(q),
            buffers: self.buffer(q, 0),
            buffer_size: BUFFER_SIZE,
        };
        Queue::new(mem, layout, bus)
    }

    /// Where queue `q`'s buffer `i` starts.
    pub fn buffer(&self, q: u16, i: u16) -> usize {
        2 * RINGS_SIZE + (usize::from(q) * usize::from(self.size) + usize::from(i)) * BUFFER_SIZE
    }
}

/// The frame in a received buffer of `len` bytes (header stripped), or `None` when the
/// device wrote less than a header.
pub fn received_frame(len: u32) -> Option<core::ops::Range<usize>> {
    let len = len as usize;
    (len >= NET_HEADER).then_some(NET_HEADER..len.min(BUFFER_SIZE))
}

#[cfg(test)]
mod tests;
