//! The virtio-blk function on the hardware: its bring-up on the shared virtio glue
//! (`virtio::hw`), one queue of four descriptors in the DMA region (header, data, status:
//! one request at a time), and [`blk_core::driver::Device`] over it. Thin glue; what a
//! request is and whether a tenant may make it is `blk_core`'s.

use blk_core::SECTOR;
use blk_core::link::{MAX_SECTORS, Operation, Status};
use blk_core::virtio_blk::{self, CONFIG_CAPACITY, DRIVER_FEATURES, HEADER};
use pci::{Capabilities, DmaRegion, Record};
use virtio::hw::{BringUp, Dma, Doorbell, Registers, Transport};
use virtio::queue::{QueueLayout, RINGS_SIZE, Segment, queue_size};
use virtio::{Memory, Queue, Used};

/// Descriptors: the header, the data and the status of the one request in flight.
const DESCRIPTORS: u16 = 4;
const HEADER_ID: u16 = 0;
const DATA_ID: u16 = 1;
const STATUS_ID: u16 = 2;
/// Each descriptor's buffer: the largest request's data.
const BUFFER: usize = MAX_SECTORS as usize * SECTOR;
/// Bytes of DMA region the driver needs.
pub const DMA_BYTES: usize = RINGS_SIZE + DESCRIPTORS as usize * BUFFER;
/// How long the device may take for a request (QEMU's write-back cache and flush to the
/// host's file), in ns of the partition's clock.
const REQUEST_TIMEOUT_NS: u64 = 5_000_000_000;
/// How long to wait for the interrupt before looking at the used ring again.
const POLL_NS: u64 = 200_000;

/// The brought-up device.
pub struct Disk {
    mem: Dma,
    queue: Queue,
    bell: Doorbell,
    isr: Registers,
    line: u64,
    /// The negotiated features (`virtio_blk::FEATURE_*`).
    pub features: u64,
    /// The disk's size in sectors.
    pub capacity: u64,
    /// Used entries the device should not have written; requests that timed out.
    pub bogus: u64,
    pub timeouts: u64,
    /// After a time-out the device still holds the request's buffers: no more requests.
    stuck: bool,
}

impl Disk {
    /// Resets the device (its structures found through `caps`), negotiates VERSION_1,
    /// ACCESS_PLATFORM behind an IOMMU, FLUSH and RO when offered, sets up queue 0 in
    /// `dma` and sets DRIVER_OK. Completion interrupts through INTx `line`.
    pub fn bring_up(
        record: &Record,
        caps: &Capabilities,
        dma: DmaRegion,
        line: u64,
    ) -> Result<Disk, BringUp> {
        let (t, features) = Transport::bring_up(record, caps, DRIVER_FEATURES, 8)?;
        let capacity = u64::from(t.device.read32(CONFIG_CAPACITY))
            | u64::from(t.device.read32(CONFIG_CAPACITY + 4)) << 32;
        if (dma.length as usize) < DMA_BYTES {
            return Err(t.fail(BringUp::Queue(0)));
        }
        // SAFETY: the region syssw gave this partition for DMA, used for nothing else.
        #[allow(unsafe_code)]
        let mut mem = unsafe { Dma::new(dma) };
        let layout = QueueLayout {
            index: 0,
            size: queue_size(t.queue_max(0), DESCRIPTORS),
            rings: 0,
            buffers: RINGS_SIZE,
            buffer_size: BUFFER,
        };
        let queue = Queue::new(&mut mem, layout, dma.bus_address)
            .filter(|q| q.size() >= 3)
            .ok_or_else(|| t.fail(BringUp::Queue(0)))?;
        let bell = t.set_up(&queue)?;
        t.driver_ok();
        Ok(Disk {
            mem,
            queue,
            bell,
            isr: t.isr,
            line,
            features,
            capacity,
            bogus: 0,
            timeouts: 0,
            stuck: false,
        })
    }

    /// One request: `len` bytes of data (from `write`, or into `read`), its status.
    fn request(
        &mut self,
        operation: Operation,
        sector: u64,
        write: &[u8],
        read: &mut [u8],
    ) -> Status {
        let len = write.len().max(read.len());
        if self.stuck || len > BUFFER {
            return Status::IoError;
        }
        let header = virtio_blk::header(operation, sector);
        self.mem.write(self.queue.buffer(HEADER_ID), &header);
        self.mem.write(self.queue.buffer(DATA_ID), write);
        self.mem.write(self.queue.buffer(STATUS_ID), &[0xff]);
        let segment = |id, len: usize, device_writes| Segment {
            id,
            len: len as u32,
            device_writes,
        };
        let data = segment(DATA_ID, len, operation == Operation::Read);
        let (head, status) = (
            segment(HEADER_ID, HEADER, false),
            segment(STATUS_ID, 1, true),
        );
        let given = if len == 0 {
            self.queue.give_chain(&mut self.mem, &[head, status])
        } else {
            self.queue.give_chain(&mut self.mem, &[head, data, status])
        };
        if !given {
            return Status::IoError;
        }
        self.bell.ring();
        let deadline = apex::user_rt::sys::clock().saturating_add(REQUEST_TIMEOUT_NS);
        loop {
            match self.queue.take(&self.mem) {
                Some(Used::Buffer { id: HEADER_ID, .. }) => break,
                Some(_) => self.bogus += 1,
                None if apex::user_rt::sys::clock() >= deadline => {
                    self.timeouts += 1;
                    self.stuck = true;
                    return Status::IoError;
                }
                None => {
                    use apex::user_rt::sys;
                    if sys::irq_wait(self.line, POLL_NS).is_ok() {
                        self.isr.read8(0);
                        let _ = sys::irq_ack(self.line);
                    }
                }
            }
        }
        let mut byte = [0u8];
        self.mem.read(self.queue.buffer(STATUS_ID), &mut byte);
        let status = virtio_blk::status(byte[0]);
        if status == Status::Ok && !read.is_empty() {
            self.mem.read(self.queue.buffer(DATA_ID), read);
        }
        status
    }
}

impl blk_core::driver::Device for Disk {
    fn read(&mut self, disk_sector: u64, out: &mut [u8]) -> Status {
        self.request(Operation::Read, disk_sector, &[], out)
    }

    fn write(&mut self, disk_sector: u64, data: &[u8]) -> Status {
        self.request(Operation::Write, disk_sector, data, &mut [])
    }

    fn flush(&mut self) -> Status {
        self.request(Operation::Flush, 0, &[], &mut [])
    }
}
