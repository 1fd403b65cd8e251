//! virtio 1.x over the modern PCI transport, for the driver partitions (virtio-net in
//! `nic`, virtio-blk in `blk`): where the device's structures are ([`Layout`], from the
//! function's capability list), the registers of the common configuration, the feature
//! bits every driver takes, and the split virtqueue ([`queue::Queue`]) in a partition's
//! DMA region. Pure logic over [`Memory`]: a partition runs it on its DMA region, the tests
//! on a plain buffer with a model of the device, which may be hostile (used entries naming
//! descriptors it was never given, lengths beyond the buffer): that is counted and
//! skipped, never a panic. [`hw`] is the thin glue to the hardware (registers, the DMA
//! region, the bring-up). no_std, no allocation.
#![no_std]

pub mod hw;
pub mod queue;
#[cfg(any(test, feature = "testing"))]
pub mod testing;

pub use queue::{Queue, Segment, Used};

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

/// VIRTIO_F_VERSION_1: required (without it the device is legacy).
pub const FEATURE_VERSION_1: u64 = 1 << 32;
/// VIRTIO_F_ACCESS_PLATFORM: the device's DMA goes through the platform's IOMMU. A driver
/// gives the device bus addresses of its DMA region (`pci::DmaRegion`), which is what this
/// feature asks for, so it accepts it; a device that offers it (QEMU's
/// `iommu_platform=on`, without which QEMU lets virtio DMA bypass VT-d) refuses a driver
/// that does not.
pub const FEATURE_ACCESS_PLATFORM: u64 = 1 << 33;

/// The features to accept of `offered`: the transport's ([`FEATURE_VERSION_1`],
/// [`FEATURE_ACCESS_PLATFORM`]) and those of `device_features` the device offers; `None`
/// when the device is not a virtio 1.x device.
pub fn negotiate(offered: u64, device_features: u64) -> Option<u64> {
    (offered & FEATURE_VERSION_1 != 0)
        .then_some(offered & (device_features | FEATURE_VERSION_1 | FEATURE_ACCESS_PLATFORM))
}

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

#[cfg(test)]
mod tests;
