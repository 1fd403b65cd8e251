//! A virtio function on the hardware, for the driver partitions: its registers (memory BARs
//! mapped uncached by syssw), the DMA region as [`Memory`] through volatile accesses, and
//! the bring-up every virtio 1.x driver does ([`Transport`]: reset, feature negotiation,
//! queue set-up, DRIVER_OK). Thin glue over raw memory; the queue logic is [`crate::queue`]'s.

use crate::queue::Queue;
use crate::{Layout, LayoutError, Memory, Region, common, status};
use core::sync::atomic::{Ordering, fence};
use pci::{Bar, Capabilities, DmaRegion, Record};

/// The DMA region through volatile accesses (the device reads and writes it meanwhile).
pub struct Dma {
    base: *mut u8,
    len: usize,
}

impl Dma {
    /// # Safety
    /// `region` is this partition's DMA region, mapped for its whole length, used for
    /// nothing else.
    #[allow(unsafe_code)]
    pub unsafe fn new(region: DmaRegion) -> Dma {
        Dma {
            base: region.address as *mut u8,
            len: region.length as usize,
        }
    }

    fn at<T>(&self, at: usize) -> *mut T {
        // The queue logic keeps every access inside the driver's layout, which fits the
        // region; this is the last line against a logic error.
        assert!(
            at + core::mem::size_of::<T>() <= self.len,
            "DMA access out of the region"
        );
        self.base.wrapping_add(at).cast()
    }
}

#[allow(unsafe_code)]
impl Memory for Dma {
    fn load16(&self, at: usize) -> u16 {
        // SAFETY: inside the region (`at`), aligned as the virtqueue layout aligns it.
        unsafe { self.at::<u16>(at).read_volatile() }
    }
    fn load32(&self, at: usize) -> u32 {
        // SAFETY: as for `load16`.
        unsafe { self.at::<u32>(at).read_volatile() }
    }
    fn store16(&mut self, at: usize, value: u16) {
        // SAFETY: as for `load16`.
        unsafe { self.at::<u16>(at).write_volatile(value) }
    }
    fn store32(&mut self, at: usize, value: u32) {
        // SAFETY: as for `load16`.
        unsafe { self.at::<u32>(at).write_volatile(value) }
    }
    fn store64(&mut self, at: usize, value: u64) {
        // SAFETY: as for `load16`.
        unsafe { self.at::<u64>(at).write_volatile(value) }
    }
    fn write(&mut self, at: usize, bytes: &[u8]) {
        let to = self.at::<u8>(at);
        let _ = self.at::<u8>(at + bytes.len().saturating_sub(1));
        // SAFETY: both ends inside the region; a buffer the device does not hold.
        unsafe { core::ptr::copy_nonoverlapping(bytes.as_ptr(), to, bytes.len()) }
    }
    fn read(&self, at: usize, out: &mut [u8]) {
        let from = self.at::<u8>(at);
        let _ = self.at::<u8>(at + out.len().saturating_sub(1));
        // SAFETY: both ends inside the region; a buffer the device gave back.
        unsafe { core::ptr::copy_nonoverlapping(from, out.as_mut_ptr(), out.len()) }
    }
    fn fence(&self) {
        fence(Ordering::SeqCst);
    }
}

/// One of the device's structures in a mapped memory BAR.
#[derive(Clone, Copy)]
pub struct Registers {
    base: u64,
    length: u64,
}

#[allow(unsafe_code)]
impl Registers {
    fn at<T>(&self, offset: u32) -> *mut T {
        assert!(
            u64::from(offset) + core::mem::size_of::<T>() as u64 <= self.length,
            "register outside its structure"
        );
        (self.base + u64::from(offset)) as *mut T
    }
    pub fn read8(&self, offset: u32) -> u8 {
        // SAFETY: inside the structure, which syssw mapped uncached with its BAR.
        unsafe { self.at::<u8>(offset).read_volatile() }
    }
    pub fn read16(&self, offset: u32) -> u16 {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u16>(offset).read_volatile() }
    }
    pub fn read32(&self, offset: u32) -> u32 {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u32>(offset).read_volatile() }
    }
    pub fn write8(&self, offset: u32, value: u8) {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u8>(offset).write_volatile(value) }
    }
    pub fn write16(&self, offset: u32, value: u16) {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u16>(offset).write_volatile(value) }
    }
    pub fn write32(&self, offset: u32, value: u32) {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u32>(offset).write_volatile(value) }
    }
    /// A 64-bit field as two 32-bit writes, low half first (virtio 1.x, 4.1.3.1).
    pub fn write64(&self, offset: u32, value: u64) {
        self.write32(offset, value as u32);
        self.write32(offset + 4, (value >> 32) as u32);
    }
}

/// Why the device could not be brought up.
#[derive(Clone, Copy, Debug)]
pub enum BringUp {
    Layout(LayoutError),
    /// A structure in a BAR that is not a mapped memory BAR, or beyond it.
    Unmapped(&'static str),
    NotVersion1,
    FeaturesRefused,
    /// The queue is missing or the region too small for it.
    Queue(u16),
}

impl core::fmt::Display for BringUp {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Layout(e) => write!(f, "{e}"),
            Self::Unmapped(what) => write!(
                f,
                "the {what} structure is not whole in a mapped memory BAR, or too short"
            ),
            Self::NotVersion1 => write!(f, "the device does not offer VIRTIO_F_VERSION_1"),
            Self::FeaturesRefused => write!(f, "the device refused the features (FEATURES_OK)"),
            Self::Queue(q) => write!(
                f,
                "queue {q} is missing or the DMA region is too small for it"
            ),
        }
    }
}

/// Where structure `region` is mapped, if it is whole in a mapped memory BAR and has at
/// least the `need` bytes of registers the driver touches.
fn structure(
    record: &Record,
    region: Region,
    what: &'static str,
    need: u32,
) -> Result<Registers, BringUp> {
    match record.bars.get(usize::from(region.bar)).copied().flatten() {
        Some(Bar::Memory { base, size, .. })
            if u64::from(region.offset) + u64::from(region.length) <= size
                && region.length >= need =>
        {
            Ok(Registers {
                base: base + u64::from(region.offset),
                length: u64::from(region.length),
            })
        }
        _ => Err(BringUp::Unmapped(what)),
    }
}

/// The function's structures, found and mapped.
pub struct Transport {
    cfg: Registers,
    notify: Registers,
    notify_multiplier: u32,
    /// The interrupt status (reading it clears it).
    pub isr: Registers,
    /// The device-specific configuration.
    pub device: Registers,
}

/// The status bits up to FEATURES_OK.
const NEGOTIATED: u8 = status::ACKNOWLEDGE | status::DRIVER | status::FEATURES_OK;

impl Transport {
    /// Finds the structures through `caps` (the function's capability list) in its BARs,
    /// resets the device and negotiates: VERSION_1 and ACCESS_PLATFORM (a device behind
    /// an IOMMU) and those of `device_features` it offers. The accepted features.
    pub fn bring_up(
        record: &Record,
        caps: &Capabilities,
        device_features: u64,
        device_config: u32,
    ) -> Result<(Transport, u64), BringUp> {
        let layout = Layout::find(caps).map_err(BringUp::Layout)?;
        let cfg = structure(record, layout.common, "common configuration", 0x38)?;
        let t = Transport {
            cfg,
            isr: structure(record, layout.isr, "ISR status", 1)?,
            device: structure(record, layout.device, "device configuration", device_config)?,
            notify: structure(record, layout.notify, "notification", 2)?,
            notify_multiplier: layout.notify_multiplier,
        };
        cfg.write8(common::DEVICE_STATUS, 0);
        while cfg.read8(common::DEVICE_STATUS) != 0 {
            core::hint::spin_loop();
        }
        cfg.write8(common::DEVICE_STATUS, status::ACKNOWLEDGE);
        cfg.write8(common::DEVICE_STATUS, status::ACKNOWLEDGE | status::DRIVER);
        let mut offered = 0u64;
        for word in 0..2u32 {
            cfg.write32(common::DEVICE_FEATURE_SELECT, word);
            offered |= u64::from(cfg.read32(common::DEVICE_FEATURE)) << (32 * word);
        }
        let accepted = crate::negotiate(offered, device_features)
            .ok_or_else(|| t.fail(BringUp::NotVersion1))?;
        for word in 0..2u32 {
            cfg.write32(common::DRIVER_FEATURE_SELECT, word);
            cfg.write32(common::DRIVER_FEATURE, (accepted >> (32 * word)) as u32);
        }
        cfg.write8(common::DEVICE_STATUS, NEGOTIATED);
        if cfg.read8(common::DEVICE_STATUS) & status::FEATURES_OK == 0 {
            return Err(t.fail(BringUp::FeaturesRefused));
        }
        Ok((t, accepted))
    }

    /// Sets the device's status to FAILED; `e`.
    pub fn fail(&self, e: BringUp) -> BringUp {
        self.cfg.write8(common::DEVICE_STATUS, status::FAILED);
        e
    }

    /// The most descriptors the device takes for queue `q` (0: no such queue).
    pub fn queue_max(&self, q: u16) -> u16 {
        self.cfg.write16(common::QUEUE_SELECT, q);
        self.cfg.read16(common::QUEUE_SIZE)
    }

    /// Tells the device where `queue` is and enables it; its doorbell.
    pub fn set_up(&self, queue: &Queue) -> Result<Doorbell, BringUp> {
        let q = queue.index();
        let (desc, driver, device) = queue.bus_rings();
        self.cfg.write16(common::QUEUE_SELECT, q);
        self.cfg.write16(common::QUEUE_SIZE, queue.size());
        self.cfg.write16(common::QUEUE_MSIX_VECTOR, 0xffff);
        self.cfg.write64(common::QUEUE_DESC, desc);
        self.cfg.write64(common::QUEUE_DRIVER, driver);
        self.cfg.write64(common::QUEUE_DEVICE, device);
        let off = u64::from(self.cfg.read16(common::QUEUE_NOTIFY_OFF))
            * u64::from(self.notify_multiplier);
        if off + 2 > self.notify.length {
            return Err(self.fail(BringUp::Unmapped("notification")));
        }
        self.cfg.write16(common::QUEUE_ENABLE, 1);
        Ok(Doorbell {
            registers: Registers {
                base: self.notify.base + off,
                length: 2,
            },
            queue: q,
        })
    }

    /// The driver is ready: the device may use the queues.
    pub fn driver_ok(&self) {
        self.cfg
            .write8(common::DEVICE_STATUS, NEGOTIATED | status::DRIVER_OK);
    }
}

/// Where to tell the device a queue has new buffers.
#[derive(Clone, Copy)]
pub struct Doorbell {
    registers: Registers,
    queue: u16,
}

impl Doorbell {
    pub fn ring(&self) {
        self.registers.write16(0, self.queue);
    }
}
