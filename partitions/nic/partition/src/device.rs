//! The virtio-net function on the hardware: its registers (memory BAR mapped uncached by
//! syssw), its bring-up, and the DMA region as `nic_core::virtio::Memory`. Thin glue; the
//! queue logic and the layout are `nic_core::virtio`'s.

use core::sync::atomic::{Ordering, fence};
use nic_core::switch::Mac;
use nic_core::virtio::{
    self, DmaLayout, Layout, Memory, Queue, RECEIVE_QUEUE, Region, TRANSMIT_QUEUE, common, status,
};
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
        // The queue logic keeps every access inside the layout, which fits the region
        // (`DmaLayout::new`); this is the last line against a logic error.
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
struct Registers {
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
    fn read8(&self, offset: u32) -> u8 {
        // SAFETY: inside the structure, which syssw mapped uncached with its BAR.
        unsafe { self.at::<u8>(offset).read_volatile() }
    }
    fn read16(&self, offset: u32) -> u16 {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u16>(offset).read_volatile() }
    }
    fn read32(&self, offset: u32) -> u32 {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u32>(offset).read_volatile() }
    }
    fn write8(&self, offset: u32, value: u8) {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u8>(offset).write_volatile(value) }
    }
    fn write16(&self, offset: u32, value: u16) {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u16>(offset).write_volatile(value) }
    }
    fn write32(&self, offset: u32, value: u32) {
        // SAFETY: as for `read8`.
        unsafe { self.at::<u32>(offset).write_volatile(value) }
    }
    /// A 64-bit field as two 32-bit writes, low half first (virtio 1.x, 4.1.3.1).
    fn write64(&self, offset: u32, value: u64) {
        self.write32(offset, value as u32);
        self.write32(offset + 4, (value >> 32) as u32);
    }
}

/// Why the device could not be brought up.
#[derive(Clone, Copy, Debug)]
pub enum BringUp {
    Layout(virtio::LayoutError),
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

/// The brought-up device: its queues in the DMA region and where to ring them.
pub struct Net {
    pub mem: Dma,
    pub rx: Queue,
    pub tx: Queue,
    pub mac: Mac,
    isr: Registers,
    notify: [Registers; 2],
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

impl Net {
    /// Resets the device (its structures found through `caps`, its capability list), negotiates VERSION_1 (+ MAC, + ACCESS_PLATFORM behind an IOMMU), sets up both queues in `dma`
    /// (bus mastering is syssw's, with the partition's `dma`), fills the receive queue and
    /// sets DRIVER_OK. The device interrupts through INTx.
    pub fn bring_up(record: &Record, caps: &Capabilities, dma: DmaRegion) -> Result<Net, BringUp> {
        let layout = Layout::find(caps).map_err(BringUp::Layout)?;
        let cfg = structure(record, layout.common, "common configuration", 0x38)?;
        let isr = structure(record, layout.isr, "ISR status", 1)?;
        let device = structure(record, layout.device, "device configuration", 6)?;
        let notify = structure(record, layout.notify, "notification", 2)?;

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
        let fail = |e| {
            cfg.write8(common::DEVICE_STATUS, status::FAILED);
            e
        };
        let accepted = virtio::negotiate(offered).ok_or_else(|| fail(BringUp::NotVersion1))?;
        for word in 0..2u32 {
            cfg.write32(common::DRIVER_FEATURE_SELECT, word);
            cfg.write32(common::DRIVER_FEATURE, (accepted >> (32 * word)) as u32);
        }
        let so_far = status::ACKNOWLEDGE | status::DRIVER | status::FEATURES_OK;
        cfg.write8(common::DEVICE_STATUS, so_far);
        if cfg.read8(common::DEVICE_STATUS) & status::FEATURES_OK == 0 {
            return Err(fail(BringUp::FeaturesRefused));
        }

        // SAFETY: the region syssw gave this partition for DMA, used for nothing else.
        #[allow(unsafe_code)]
        let mut mem = unsafe { Dma::new(dma) };
        let mut queues: [Option<Queue>; 2] = [None, None];
        let mut doorbells = [notify; 2];
        for q in [RECEIVE_QUEUE, TRANSMIT_QUEUE] {
            cfg.write16(common::QUEUE_SELECT, q);
            let max = cfg.read16(common::QUEUE_SIZE);
            let dl =
                DmaLayout::new(max, dma.length as usize).ok_or_else(|| fail(BringUp::Queue(q)))?;
            let queue = dl
                .queue(&mut mem, q, dma.bus_address)
                .ok_or_else(|| fail(BringUp::Queue(q)))?;
            let (desc, driver, device) = queue.bus_rings();
            cfg.write16(common::QUEUE_SIZE, dl.size);
            cfg.write16(common::QUEUE_MSIX_VECTOR, 0xffff);
            cfg.write64(common::QUEUE_DESC, desc);
            cfg.write64(common::QUEUE_DRIVER, driver);
            cfg.write64(common::QUEUE_DEVICE, device);
            let off = u64::from(cfg.read16(common::QUEUE_NOTIFY_OFF))
                * u64::from(layout.notify_multiplier);
            if off + 2 > notify.length {
                return Err(fail(BringUp::Unmapped("notification")));
            }
            doorbells[usize::from(q)] = Registers {
                base: notify.base + off,
                length: 2,
            };
            cfg.write16(common::QUEUE_ENABLE, 1);
            queues[usize::from(q)] = Some(queue);
        }
        let mut mac = [0u8; 6];
        if accepted & virtio::FEATURE_MAC != 0 {
            for (i, b) in mac.iter_mut().enumerate() {
                *b = device.read8(i as u32);
            }
        }
        let [Some(mut rx), Some(tx)] = queues else {
            return Err(fail(BringUp::Queue(0)));
        };
        for id in 0..rx.size() {
            rx.give(&mut mem, id, virtio::BUFFER_SIZE as u32, true);
        }
        cfg.write8(common::DEVICE_STATUS, so_far | status::DRIVER_OK);
        let net = Net {
            mem,
            rx,
            tx,
            mac: Mac(mac),
            isr,
            notify: doorbells,
        };
        net.kick(RECEIVE_QUEUE);
        Ok(net)
    }

    /// Tells the device queue `q` has new buffers.
    pub fn kick(&self, q: u16) {
        self.notify[usize::from(q)].write16(0, q);
    }

    /// Reads (and so clears) the interrupt status; whether a queue was used.
    pub fn interrupt_status(&self) -> u8 {
        self.isr.read8(0)
    }
}
