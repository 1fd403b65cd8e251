//! virtio-net over the modern PCI transport (virtio 1.x): where the device's structures
//! are ([`Layout`], from the function's capability list), the registers of the common
//! configuration, and the split virtqueues ([`Queue`]) in the partition's DMA region
//! ([`DmaLayout`]). Pure logic over [`Memory`]: the partition runs it on its DMA region,
//! the tests on a plain buffer with a model of the device, which may be hostile (used
//! entries naming descriptors it was never given, lengths beyond the buffer): that is
//! counted and skipped, never a panic.
//!
//! The driver keeps it simple: one descriptor per frame (the 12-byte virtio-net header
//! and the frame in one buffer, which VIRTIO_F_VERSION_1 allows), descriptor `i` always
//! bound to buffer `i`, no offloads, no event index, INTx interrupts.

use pci::Capabilities;

/// virtio's vendor-specific capability id, and its `cfg_type`s.
const VENDOR_CAPABILITY: u8 = 0x09;
const COMMON_CFG: u8 = 1;
const NOTIFY_CFG: u8 = 2;
const ISR_CFG: u8 = 3;
const DEVICE_CFG: u8 = 4;

/// A structure of the device: `length` bytes at `offset` in memory BAR `bar`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Region {
    pub bar: u8,
    pub offset: u32,
    pub length: u32,
}

/// Where the modern transport's structures are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub common: Region,
    pub notify: Region,
    /// Queue `q`'s doorbell is at `notify.offset + queue_notify_off(q) * multiplier`.
    pub notify_multiplier: u32,
    pub isr: Region,
    pub device: Region,
}

/// Why the function cannot be driven.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayoutError {
    /// The capability list lacks this virtio structure (a legacy-only device).
    Missing(&'static str),
    /// A structure's capability is shorter than its fields.
    Short(&'static str),
}

impl core::fmt::Display for LayoutError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Missing(what) => write!(
                f,
                "no virtio {what} capability (not a modern virtio device)"
            ),
            Self::Short(what) => write!(f, "the virtio {what} capability is truncated"),
        }
    }
}

impl Layout {
    /// The structures named by the vendor capabilities in `caps` (the first of each type,
    /// as the specification asks drivers to take).
    pub fn find(caps: &Capabilities) -> Result<Layout, LayoutError> {
        let mut found: [Option<Region>; 5] = [None; 5];
        let mut multiplier = None;
        for cap in caps.iter().filter(|c| c.id == VENDOR_CAPABILITY) {
            let b = cap.bytes;
            let Some(&kind) = b.get(3) else { continue };
            if !(COMMON_CFG..=DEVICE_CFG).contains(&kind) || found[usize::from(kind)].is_some() {
                continue;
            }
            let word = |at: usize| {
                b.get(at..at + 4)
                    .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            };
            let (Some(offset), Some(length)) = (word(8), word(12)) else {
                return Err(LayoutError::Short(name(kind)));
            };
            if kind == NOTIFY_CFG {
                multiplier = Some(word(16).ok_or(LayoutError::Short(name(kind)))?);
            }
            found[usize::from(kind)] = Some(Region {
                bar: b[4],
                offset,
                length,
            });
        }
        let get = |kind: u8| found[usize::from(kind)].ok_or(LayoutError::Missing(name(kind)));
        Ok(Layout {
            common: get(COMMON_CFG)?,
            notify: get(NOTIFY_CFG)?,
            notify_multiplier: multiplier.unwrap_or(0),
            isr: get(ISR_CFG)?,
            device: get(DEVICE_CFG)?,
        })
    }
}

fn name(kind: u8) -> &'static str {
    match kind {
        COMMON_CFG => "common configuration",
        NOTIFY_CFG => "notification",
        ISR_CFG => "ISR status",
        _ => "device configuration",
    }
}

/// Offsets of the common configuration's registers (virtio 1.x, 4.1.4.3).
pub mod common {
    pub const DEVICE_FEATURE_SELECT: u32 = 0x00;
    pub const DEVICE_FEATURE: u32 = 0x04;
    pub const DRIVER_FEATURE_SELECT: u32 = 0x08;
    pub const DRIVER_FEATURE: u32 = 0x0c;
    pub const DEVICE_STATUS: u32 = 0x14;
    pub const QUEUE_SELECT: u32 = 0x16;
    pub const QUEUE_SIZE: u32 = 0x18;
    pub const QUEUE_MSIX_VECTOR: u32 = 0x1a;
    pub const QUEUE_ENABLE: u32 = 0x1c;
    pub const QUEUE_NOTIFY_OFF: u32 = 0x1e;
    pub const QUEUE_DESC: u32 = 0x20;
    pub const QUEUE_DRIVER: u32 = 0x28;
    pub const QUEUE_DEVICE: u32 = 0x30;
}

/// Device status bits.
pub mod status {
    pub const ACKNOWLEDGE: u8 = 1;
    pub const DRIVER: u8 = 2;
    pub const DRIVER_OK: u8 = 4;
    pub const FEATURES_OK: u8 = 8;
    pub const FAILED: u8 = 0x80;
}

/// Feature bits the driver takes when offered: the MAC address in the device
/// configuration, and virtio 1.x itself (required: without it the device is legacy).
pub const FEATURE_MAC: u64 = 1 << 5;
pub const FEATURE_VERSION_1: u64 = 1 << 32;
/// VIRTIO_F_ACCESS_PLATFORM: the device's DMA goes through the platform's IOMMU. The
/// driver gives the device bus addresses of its DMA region (`pci::DmaRegion`), which is
/// what this feature asks for, so it accepts it; a device that offers it (QEMU's
/// `iommu_platform=on`, without which QEMU lets virtio DMA bypass VT-d) refuses a driver
/// that does not.
pub const FEATURE_ACCESS_PLATFORM: u64 = 1 << 33;

/// The features to accept of `offered`; `None` when the device is not a virtio 1.x device.
pub fn negotiate(offered: u64) -> Option<u64> {
    (offered & FEATURE_VERSION_1 != 0)
        .then_some(offered & (FEATURE_MAC | FEATURE_VERSION_1 | FEATURE_ACCESS_PLATFORM))
}

/// The virtio-net header in front of every frame (VIRTIO_F_VERSION_1: with `num_buffers`).
/// All zero on transmit: no checksum offload, no segmentation.
pub const NET_HEADER: usize = 12;
/// The receive and transmit queues' indices.
pub const RECEIVE_QUEUE: u16 = 0;
pub const TRANSMIT_QUEUE: u16 = 1;
/// The interrupt status register's "a queue was used" bit.
pub const ISR_QUEUE: u8 = 1;

/// The memory the device reads and writes by DMA: loads and stores at byte offsets of the
/// DMA region, each as one access of its width (the device sees it whole), and a barrier
/// that orders the accesses before it against those after it, for the device too.
pub trait Memory {
    fn load16(&self, at: usize) -> u16;
    fn load32(&self, at: usize) -> u32;
    fn store16(&mut self, at: usize, value: u16);
    fn store32(&mut self, at: usize, value: u32);
    fn store64(&mut self, at: usize, value: u64);
    /// Copies `bytes` in at `at`.
    fn write(&mut self, at: usize, bytes: &[u8]);
    /// Copies out `out.len()` bytes from `at`.
    fn read(&self, at: usize, out: &mut [u8]);
    fn fence(&self);
}

/// Descriptors a queue uses (the device may offer more; the driver sets the size).
pub const QUEUE_SIZE: u16 = 64;
/// One buffer per descriptor: header + the largest frame, rounded up.
pub const BUFFER_SIZE: usize = 2048;
/// Each queue's rings take one page.
const RINGS_SIZE: usize = 4096;

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
        let mut size = QUEUE_SIZE.min(device_max);
        // Split queues need a power of two.
        while size & (size.wrapping_sub(1)) != 0 {
            size &= size - 1;
        }
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

    /// Where queue `q`'s buffer `i` starts.
    pub fn buffer(&self, q: u16, i: u16) -> usize {
        2 * RINGS_SIZE + (usize::from(q) * usize::from(self.size) + usize::from(i)) * BUFFER_SIZE
    }
}

/// Descriptor flags.
const DESC_WRITE: u16 = 2;

/// What a used entry from the device says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Used {
    /// Descriptor `id` is back with `len` bytes written (receive) or sent (transmit).
    Buffer { id: u16, len: u32 },
    /// An entry naming a descriptor the driver did not hand out (a broken or hostile
    /// device); skipped.
    Bogus { id: u32 },
}

/// A split virtqueue whose descriptor `i` always points at buffer `i` of its queue.
#[derive(Clone, Debug)]
pub struct Queue {
    index: u16,
    layout: DmaLayout,
    /// The DMA region's bus address.
    bus: u64,
    /// The next avail index to publish, and the used index read up to.
    avail: u16,
    used: u16,
    /// Descriptors the device holds (bit i).
    given: u64,
}

impl Queue {
    /// Queue `index` of `layout` (its rings zeroed in `mem`).
    pub fn new(mem: &mut impl Memory, index: u16, layout: DmaLayout, bus: u64) -> Queue {
        let rings = layout.rings(index);
        for at in (rings..rings + RINGS_SIZE).step_by(4) {
            mem.store32(at, 0);
        }
        Queue {
            index,
            layout,
            bus,
            avail: 0,
            used: 0,
            given: 0,
        }
    }

    pub fn size(&self) -> u16 {
        self.layout.size
    }

    /// Offsets of the descriptor table, the driver (avail) ring, the device (used) ring.
    pub fn rings(&self) -> (usize, usize, usize) {
        let n = usize::from(self.layout.size);
        let desc = self.layout.rings(self.index);
        let avail = desc + 16 * n;
        let used = (avail + 6 + 2 * n + 3) & !3;
        (desc, avail, used)
    }

    /// The rings' bus addresses, for the common configuration's queue registers.
    pub fn bus_rings(&self) -> (u64, u64, u64) {
        let (d, a, u) = self.rings();
        (
            self.bus + d as u64,
            self.bus + a as u64,
            self.bus + u as u64,
        )
    }

    /// Where buffer `id`'s bytes start in the region.
    pub fn buffer(&self, id: u16) -> usize {
        self.layout.buffer(self.index, id)
    }

    /// Whether the device holds descriptor `id`.
    pub fn is_given(&self, id: u16) -> bool {
        id < self.layout.size && self.given & (1 << id) != 0
    }

    /// A descriptor the device does not hold, if any.
    pub fn free(&self) -> Option<u16> {
        let free = !self.given & mask(self.layout.size);
        (free != 0).then(|| free.trailing_zeros() as u16)
    }

    /// Hands buffer `id` to the device: `len` bytes it may write (`device_writes`, a
    /// receive buffer) or read. Published at once; notify the device after a batch.
    /// `false` (nothing done) for an id out of range or one the device already holds.
    pub fn give(&mut self, mem: &mut impl Memory, id: u16, len: u32, device_writes: bool) -> bool {
        if id >= self.layout.size || self.is_given(id) || len as usize > BUFFER_SIZE {
            return false;
        }
        let (desc, avail, _) = self.rings();
        let d = desc + 16 * usize::from(id);
        mem.store64(d, self.bus + self.buffer(id) as u64);
        mem.store32(d + 8, len);
        mem.store16(d + 12, if device_writes { DESC_WRITE } else { 0 });
        mem.store16(d + 14, 0);
        let slot = usize::from(self.avail % self.layout.size);
        mem.store16(avail + 4 + 2 * slot, id);
        // The descriptor and the ring entry before the index that publishes them.
        mem.fence();
        self.avail = self.avail.wrapping_add(1);
        mem.store16(avail + 2, self.avail);
        self.given |= 1 << id;
        true
    }

    /// The next entry the device has put in the used ring, if any. A [`Used::Buffer`]'s
    /// `len` is at most [`BUFFER_SIZE`] (a larger claim is cut to it).
    pub fn take(&mut self, mem: &impl Memory) -> Option<Used> {
        let (_, _, used) = self.rings();
        let published = mem.load16(used + 2);
        if published == self.used {
            return None;
        }
        // The entry after the index that published it.
        mem.fence();
        let slot = usize::from(self.used % self.layout.size);
        let id = mem.load32(used + 4 + 8 * slot);
        let len = mem.load32(used + 8 + 8 * slot);
        self.used = self.used.wrapping_add(1);
        match u16::try_from(id) {
            Ok(id) if self.is_given(id) => {
                self.given &= !(1 << id);
                Some(Used::Buffer {
                    id,
                    len: len.min(BUFFER_SIZE as u32),
                })
            }
            _ => Some(Used::Bogus { id }),
        }
    }
}

fn mask(size: u16) -> u64 {
    if size >= 64 {
        u64::MAX
    } else {
        (1u64 << size) - 1
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
