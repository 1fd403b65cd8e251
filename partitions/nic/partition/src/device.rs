//! The virtio-net function on the hardware: its bring-up on the shared virtio glue
//! (`virtio::hw`: registers, the DMA region, reset and negotiation) with the NIC's two
//! queues and its MAC. Thin glue; the queue logic and the layout are `nic_core::virtio`'s.

use nic_core::switch::Mac;
use nic_core::virtio::{self, DmaLayout, RECEIVE_QUEUE, TRANSMIT_QUEUE};
use pci::{Capabilities, DmaRegion, Record};
pub use virtio_hw::{BringUp, Dma};
use virtio_hw::{Doorbell, Registers, Transport};

use ::virtio::hw as virtio_hw;

/// The brought-up device: its queues in the DMA region and where to ring them.
pub struct Net {
    pub mem: Dma,
    pub rx: virtio::Queue,
    pub tx: virtio::Queue,
    pub mac: Mac,
    isr: Registers,
    notify: [Doorbell; 2],
}

impl Net {
    /// Resets the device (its structures found through `caps`, its capability list),
    /// negotiates VERSION_1 (+ MAC, + ACCESS_PLATFORM behind an IOMMU), sets up both
    /// queues in `dma` (bus mastering is syssw's, with the partition's `dma`), fills the
    /// receive queue and sets DRIVER_OK. The device interrupts through INTx.
    pub fn bring_up(record: &Record, caps: &Capabilities, dma: DmaRegion) -> Result<Net, BringUp> {
        let (t, accepted) = Transport::bring_up(record, caps, virtio::FEATURE_MAC, 6)?;
        // SAFETY: the region syssw gave this partition for DMA, used for nothing else.
        #[allow(unsafe_code)]
        let mut mem = unsafe { Dma::new(dma) };
        let mut queues = [None, None];
        for q in [RECEIVE_QUEUE, TRANSMIT_QUEUE] {
            let queue = DmaLayout::new(t.queue_max(q), dma.length as usize)
                .and_then(|dl| dl.queue(&mut mem, q, dma.bus_address))
                .ok_or_else(|| t.fail(BringUp::Queue(q)))?;
            let bell = t.set_up(&queue)?;
            queues[usize::from(q)] = Some((queue, bell));
        }
        let mut mac = [0u8; 6];
        if accepted & virtio::FEATURE_MAC != 0 {
            for (i, b) in mac.iter_mut().enumerate() {
                *b = t.device.read8(i as u32);
            }
        }
        let [Some((mut rx, rx_bell)), Some((tx, tx_bell))] = queues else {
            return Err(t.fail(BringUp::Queue(0)));
        };
        for id in 0..rx.size() {
            rx.give(&mut mem, id, virtio::BUFFER_SIZE as u32, true);
        }
        t.driver_ok();
        let net = Net {
            mem,
            rx,
            tx,
            mac: Mac(mac),
            isr: t.isr,
            notify: [rx_bell, tx_bell],
        };
        net.kick(RECEIVE_QUEUE);
        Ok(net)
    }

    /// Tells the device queue `q` has new buffers.
    pub fn kick(&self, q: u16) {
        self.notify[usize::from(q)].ring();
    }

    /// Reads (and so clears) the interrupt status; whether a queue was used.
    pub fn interrupt_status(&self) -> u8 {
        self.isr.read8(0)
    }
}
