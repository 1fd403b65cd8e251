//! The split virtqueue (virtio 1.x, 2.7) in a partition's DMA region: descriptor `i` is
//! always bound to buffer `i` of the queue's buffers, so the driver never hands the device
//! an address it did not lay out. A request is one descriptor (a virtio-net frame) or a
//! chain of them (a virtio-blk request: header, data, status); the device names the
//! chain's head when it gives it back. No event index, no indirect descriptors.

use crate::Memory;

/// Most descriptors a queue may have (the driver's bookkeeping is a 64-bit mask).
pub const MAX_QUEUE_SIZE: u16 = 64;
/// Each queue's rings take one page (enough for [`MAX_QUEUE_SIZE`] descriptors).
pub const RINGS_SIZE: usize = 4096;

/// Descriptor flags.
pub const DESC_NEXT: u16 = 1;
pub const DESC_WRITE: u16 = 2;
/// The driver ring's flag asking the device not to interrupt when it puts a buffer in
/// the used ring (VIRTQ_AVAIL_F_NO_INTERRUPT: without the event index a hint the device
/// may ignore, which QEMU follows).
pub const AVAIL_NO_INTERRUPT: u16 = 1;

/// Where a queue lives in the DMA region (byte offsets) and how big it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueueLayout {
    /// The queue's index on the device.
    pub index: u16,
    /// Descriptors: a power of two, at most [`MAX_QUEUE_SIZE`].
    pub size: u16,
    /// Where its rings start ([`RINGS_SIZE`] bytes, 16-byte aligned).
    pub rings: usize,
    /// Where buffer 0 starts; buffer `i` is `buffer_size` bytes at `buffers + i * buffer_size`.
    pub buffers: usize,
    pub buffer_size: usize,
}

/// The largest power of two that is at most `device_max` and `limit` (and
/// [`MAX_QUEUE_SIZE`]): split queues need a power of two. 0 when the device offers none.
pub fn queue_size(device_max: u16, limit: u16) -> u16 {
    let mut size = device_max.min(limit).min(MAX_QUEUE_SIZE);
    while size & size.wrapping_sub(1) != 0 {
        size &= size - 1;
    }
    size
}

/// One descriptor of a request: buffer `id`, `len` bytes of it, which the device writes
/// (`device_writes`) or reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Segment {
    pub id: u16,
    pub len: u32,
    pub device_writes: bool,
}

/// What a used entry from the device says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Used {
    /// The request whose head is descriptor `id` is back with `len` bytes written
    /// (at most its buffers' bytes: a larger claim is cut to that).
    Buffer { id: u16, len: u32 },
    /// An entry naming a descriptor that is not the head of a request the device holds
    /// (a broken or hostile device); skipped.
    Bogus { id: u32 },
}

/// A split virtqueue.
#[derive(Clone, Debug)]
pub struct Queue {
    layout: QueueLayout,
    /// The DMA region's bus address.
    bus: u64,
    /// The next avail index to publish, and the used index read up to.
    avail: u16,
    used: u16,
    /// Descriptors the device holds (bit i).
    given: u64,
    /// For each head the device holds, the descriptors of its request.
    chains: [u64; MAX_QUEUE_SIZE as usize],
}

impl Queue {
    /// The queue of `layout` (its rings zeroed in `mem`); `None` when its size is not a
    /// power of two of at most [`MAX_QUEUE_SIZE`].
    pub fn new(mem: &mut impl Memory, layout: QueueLayout, bus: u64) -> Option<Queue> {
        let size = layout.size;
        if size == 0 || size > MAX_QUEUE_SIZE || size & (size - 1) != 0 {
            return None;
        }
        for at in (layout.rings..layout.rings + RINGS_SIZE).step_by(4) {
            mem.store32(at, 0);
        }
        Some(Queue {
            layout,
            bus,
            avail: 0,
            used: 0,
            given: 0,
            chains: [0; MAX_QUEUE_SIZE as usize],
        })
    }

    pub fn size(&self) -> u16 {
        self.layout.size
    }

    pub fn index(&self) -> u16 {
        self.layout.index
    }

    /// Offsets of the descriptor table, the driver (avail) ring, the device (used) ring.
    pub fn rings(&self) -> (usize, usize, usize) {
        let n = usize::from(self.layout.size);
        let desc = self.layout.rings;
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
        self.layout.buffers + usize::from(id) * self.layout.buffer_size
    }

    /// Bytes of each buffer.
    pub fn buffer_size(&self) -> usize {
        self.layout.buffer_size
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
        self.give_chain(
            mem,
            &[Segment {
                id,
                len,
                device_writes,
            }],
        )
    }

    /// Hands the device one request made of `segments`, chained in that order (the
    /// first is the head the device names when it gives the request back). `false`
    /// (nothing done) when there is no segment, an id is out of range, named twice or
    /// held by the device, or a length exceeds a buffer.
    pub fn give_chain(&mut self, mem: &mut impl Memory, segments: &[Segment]) -> bool {
        let mut ids = 0u64;
        for s in segments {
            if s.id >= self.layout.size
                || ids & (1 << s.id) != 0
                || self.is_given(s.id)
                || s.len as usize > self.layout.buffer_size
            {
                return false;
            }
            ids |= 1 << s.id;
        }
        let Some(head) = segments.first() else {
            return false;
        };
        let (desc, avail, _) = self.rings();
        for (k, s) in segments.iter().enumerate() {
            let d = desc + 16 * usize::from(s.id);
            let next = segments.get(k + 1);
            let flags = if s.device_writes { DESC_WRITE } else { 0 }
                | if next.is_some() { DESC_NEXT } else { 0 };
            mem.store64(d, self.bus + self.buffer(s.id) as u64);
            mem.store32(d + 8, s.len);
            mem.store16(d + 12, flags);
            mem.store16(d + 14, next.map_or(0, |n| n.id));
        }
        let slot = usize::from(self.avail % self.layout.size);
        mem.store16(avail + 4 + 2 * slot, head.id);
        // The descriptors and the ring entry before the index that publishes them.
        mem.fence();
        self.avail = self.avail.wrapping_add(1);
        mem.store16(avail + 2, self.avail);
        self.given |= ids;
        self.chains[usize::from(head.id)] = ids;
        true
    }

    /// Asks the device to interrupt, or not, when it puts a buffer of this queue in the
    /// used ring (a hint: the driver still finds the used buffers on its own, see
    /// [`AVAIL_NO_INTERRUPT`]).
    pub fn set_interrupts(&self, mem: &mut impl Memory, on: bool) {
        let (_, avail, _) = self.rings();
        mem.store16(avail, if on { 0 } else { AVAIL_NO_INTERRUPT });
        // Before the device may look again (the caller's next look at the used ring).
        mem.fence();
    }

    /// The next entry the device has put in the used ring, if any.
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
            Ok(head) if self.is_given(head) && self.chains[usize::from(head)] != 0 => {
                let chain = core::mem::take(&mut self.chains[usize::from(head)]);
                self.given &= !chain;
                let room = chain.count_ones() as usize * self.layout.buffer_size;
                Some(Used::Buffer {
                    id: head,
                    len: len.min(u32::try_from(room).unwrap_or(u32::MAX)),
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
