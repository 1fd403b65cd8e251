//! The transport's layout from capabilities, and the split queues against a model of the
//! device, honest and hostile.

extern crate std;

use super::*;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

/// A DMA region in plain memory.
struct Ram(Vec<u8>);

impl Memory for Ram {
    fn load16(&self, at: usize) -> u16 {
        u16::from_le_bytes(self.0[at..at + 2].try_into().unwrap())
    }
    fn load32(&self, at: usize) -> u32 {
        u32::from_le_bytes(self.0[at..at + 4].try_into().unwrap())
    }
    fn store16(&mut self, at: usize, value: u16) {
        self.0[at..at + 2].copy_from_slice(&value.to_le_bytes());
    }
    fn store32(&mut self, at: usize, value: u32) {
        self.0[at..at + 4].copy_from_slice(&value.to_le_bytes());
    }
    fn store64(&mut self, at: usize, value: u64) {
        self.0[at..at + 8].copy_from_slice(&value.to_le_bytes());
    }
    fn write(&mut self, at: usize, bytes: &[u8]) {
        self.0[at..at + bytes.len()].copy_from_slice(bytes);
    }
    fn read(&self, at: usize, out: &mut [u8]) {
        out.copy_from_slice(&self.0[at..at + out.len()]);
    }
    fn fence(&self) {}
}

const BUS: u64 = 0x1234_0000;

/// The device's side of one queue: reads the avail ring, writes the used ring, as the
/// specification says (or as told, when hostile).
struct Device {
    desc: usize,
    avail: usize,
    used: usize,
    size: u16,
    seen: u16,
    used_idx: u16,
}

impl Device {
    fn of(q: &Queue) -> Device {
        let (desc, avail, used) = q.rings();
        Device {
            desc,
            avail,
            used,
            size: q.size(),
            seen: 0,
            used_idx: 0,
        }
    }

    /// The next available descriptor: (id, bus address, len, flags).
    fn next(&mut self, mem: &Ram) -> Option<(u16, u64, u32, u16)> {
        if mem.load16(self.avail + 2) == self.seen {
            return None;
        }
        let id = mem.load16(self.avail + 4 + 2 * usize::from(self.seen % self.size));
        self.seen = self.seen.wrapping_add(1);
        let d = self.desc + 16 * usize::from(id);
        let addr = u64::from(mem.load32(d)) | u64::from(mem.load32(d + 4)) << 32;
        Some((id, addr, mem.load32(d + 8), mem.load16(d + 12)))
    }

    fn complete(&mut self, mem: &mut Ram, id: u32, len: u32) {
        let slot = usize::from(self.used_idx % self.size);
        mem.store32(self.used + 4 + 8 * slot, id);
        mem.store32(self.used + 8 + 8 * slot, len);
        self.used_idx = self.used_idx.wrapping_add(1);
        mem.store16(self.used + 2, self.used_idx);
    }
}

fn setup(q: u16) -> (Ram, Queue, Device) {
    let layout = DmaLayout::new(256, 512 * 1024).unwrap();
    let mut mem = Ram(vec![0xAA; layout.bytes()]);
    let queue = Queue::new(&mut mem, q, layout, BUS);
    let device = Device::of(&queue);
    (mem, queue, device)
}

/// QEMU's virtio-net-pci capability list (vendor capabilities for common, ISR, device,
/// notify in BAR 4, plus an MSI-X capability).
fn qemu_capabilities() -> Capabilities {
    let mut c = Capabilities {
        first: 0x98,
        ..Capabilities::default()
    };
    let mut put = |at: usize, bytes: &[u8]| {
        c.area[at - 0x40..at - 0x40 + bytes.len()].copy_from_slice(bytes);
    };
    let vendor = |next: u8, len: u8, kind: u8, offset: u32, length: u32| {
        let mut v = vec![0x09, next, len, kind, 4, 0, 0, 0];
        v.extend_from_slice(&offset.to_le_bytes());
        v.extend_from_slice(&length.to_le_bytes());
        v
    };
    put(0x98, &[0x11, 0x84, 0, 0]);
    put(0x84, &vendor(0x70, 20, 2, 0x3000, 0x1000));
    put(0x94, &4u32.to_le_bytes());
    put(0x70, &vendor(0x60, 16, 4, 0x2000, 0x1000));
    put(0x60, &vendor(0x50, 16, 3, 0x1000, 0x1000));
    put(0x50, &vendor(0x40, 16, 1, 0, 0x1000));
    // A PCI-config-access capability (type 5) is ignored.
    put(0x40, &vendor(0, 20, 5, 0, 0));
    c
}

#[test]
fn the_structures_are_found_through_the_capabilities() {
    let layout = Layout::find(&qemu_capabilities()).unwrap();
    let region = |offset, length| Region {
        bar: 4,
        offset,
        length,
    };
    assert_eq!(layout.common, region(0, 0x1000));
    assert_eq!(layout.isr, region(0x1000, 0x1000));
    assert_eq!(layout.device, region(0x2000, 0x1000));
    assert_eq!(layout.notify, region(0x3000, 0x1000));
    assert_eq!(layout.notify_multiplier, 4);
}

#[test]
fn a_device_without_the_modern_structures_is_refused_with_the_reason() {
    assert_eq!(
        Layout::find(&Capabilities::default()),
        Err(LayoutError::Missing("common configuration"))
    );
    let mut c = qemu_capabilities();
    // Unlink the notify capability: 0x98 -> 0x70.
    c.area[0x98 - 0x40 + 1] = 0x70;
    let e = Layout::find(&c).unwrap_err();
    assert_eq!(e, LayoutError::Missing("notification"));
    assert!(std::format!("{e}").contains("not a modern virtio device"));
    // A notify capability at the end of configuration space has no room for its fields.
    let mut c = qemu_capabilities();
    c.area[0x98 - 0x40 + 1] = 0xf8;
    c.area[0xf8 - 0x40..].copy_from_slice(&[0x09, 0, 20, 2, 4, 0, 0, 0]);
    assert_eq!(Layout::find(&c), Err(LayoutError::Short("notification")));
}

#[test]
fn features_are_version_1_and_the_mac_only() {
    assert_eq!(negotiate(FEATURE_MAC), None, "a legacy device");
    assert_eq!(
        negotiate(u64::MAX),
        Some(FEATURE_MAC | FEATURE_VERSION_1 | FEATURE_ACCESS_PLATFORM)
    );
    assert_eq!(
        negotiate(FEATURE_VERSION_1 | FEATURE_ACCESS_PLATFORM),
        Some(FEATURE_VERSION_1 | FEATURE_ACCESS_PLATFORM),
        "behind an IOMMU"
    );
    assert_eq!(negotiate(FEATURE_VERSION_1), Some(FEATURE_VERSION_1));
}

#[test]
fn the_dma_layout_fits_the_region_and_queues_are_powers_of_two() {
    let l = DmaLayout::new(256, 512 * 1024).unwrap();
    assert_eq!(l.size, QUEUE_SIZE);
    assert!(l.bytes() <= 512 * 1024);
    assert_eq!(DmaLayout::new(48, 512 * 1024).unwrap().size, 32);
    assert_eq!(DmaLayout::new(0, 512 * 1024), None);
    assert_eq!(DmaLayout::new(256, 64 * 1024), None, "too small a region");
    // Buffers do not overlap the rings or each other.
    assert_eq!(l.buffer(0, 0), 2 * 4096);
    assert_eq!(l.buffer(1, 0), l.buffer(0, l.size - 1) + BUFFER_SIZE);
    assert_eq!(l.buffer(1, l.size - 1) + BUFFER_SIZE, l.bytes());
}

#[test]
fn receive_buffers_go_round_through_the_device() {
    let (mut mem, mut q, mut dev) = setup(RECEIVE_QUEUE);
    for id in 0..q.size() {
        assert!(q.give(&mut mem, id, BUFFER_SIZE as u32, true));
    }
    assert_eq!(q.free(), None);
    assert!(!q.give(&mut mem, 3, 100, true), "already the device's");
    // Many times round the rings, past the 16-bit index wrap.
    for round in 0..70_000u32 {
        let (id, addr, len, flags) = dev.next(&mem).expect("a buffer");
        assert_eq!(addr, BUS + q.buffer(id) as u64);
        assert_eq!((len, flags), (BUFFER_SIZE as u32, DESC_WRITE));
        let frame_len = 60 + round % 1400;
        mem.write(q.buffer(id) + NET_HEADER, &round.to_le_bytes());
        dev.complete(&mut mem, u32::from(id), NET_HEADER as u32 + frame_len);
        let Some(Used::Buffer { id: got, len }) = q.take(&mem) else {
            panic!("the used buffer");
        };
        assert_eq!(got, id);
        let frame = received_frame(len).unwrap();
        assert_eq!(frame.len() as u32, frame_len);
        let mut first = [0u8; 4];
        mem.read(q.buffer(got) + frame.start, &mut first);
        assert_eq!(u32::from_le_bytes(first), round);
        assert_eq!(q.take(&mem), None);
        assert!(q.give(&mut mem, got, BUFFER_SIZE as u32, true));
    }
}

#[test]
fn transmit_descriptors_are_free_until_given_and_again_when_used() {
    let (mut mem, mut q, mut dev) = setup(TRANSMIT_QUEUE);
    let id = q.free().unwrap();
    mem.write(q.buffer(id), &[0; NET_HEADER]);
    assert!(q.give(&mut mem, id, 74, false));
    assert_ne!(q.free(), Some(id));
    let (got, addr, len, flags) = dev.next(&mem).unwrap();
    assert_eq!((got, len, flags), (id, 74, 0));
    assert_eq!(addr, BUS + q.buffer(id) as u64);
    assert!(q.buffer(id) >= DmaLayout::new(256, 1 << 20).unwrap().buffer(1, 0));
    dev.complete(&mut mem, u32::from(id), 0);
    assert_eq!(q.take(&mem), Some(Used::Buffer { id, len: 0 }));
    assert_eq!(q.free(), Some(id));
    assert!(!q.give(&mut mem, q.size(), 10, false), "out of range");
    assert!(
        !q.give(&mut mem, 0, BUFFER_SIZE as u32 + 1, false),
        "too long"
    );
}

#[test]
fn a_hostile_device_cannot_make_the_driver_reuse_or_overrun_a_buffer() {
    let (mut mem, mut q, mut dev) = setup(RECEIVE_QUEUE);
    assert!(q.give(&mut mem, 5, BUFFER_SIZE as u32, true));
    // Ids never given, out of range, and a length beyond the buffer.
    dev.complete(&mut mem, 7, 100);
    dev.complete(&mut mem, 1_000_000, 100);
    dev.complete(&mut mem, 5, u32::MAX);
    dev.complete(&mut mem, 5, 100);
    assert_eq!(q.take(&mem), Some(Used::Bogus { id: 7 }));
    assert_eq!(q.take(&mem), Some(Used::Bogus { id: 1_000_000 }));
    assert_eq!(
        q.take(&mem),
        Some(Used::Buffer {
            id: 5,
            len: BUFFER_SIZE as u32
        })
    );
    assert_eq!(q.take(&mem), Some(Used::Bogus { id: 5 }), "returned twice");
    assert_eq!(received_frame(3), None, "less than a header");
}

proptest! {
    /// Whatever the device writes into the used ring, the driver takes at most what was
    /// published, never panics, and hands back each buffer it gave at most once.
    #[test]
    fn random_used_rings_never_panic(
        entries in proptest::collection::vec((any::<u32>(), any::<u32>()), 0..200),
        index in any::<u16>(),
    ) {
        let (mut mem, mut q, _) = setup(RECEIVE_QUEUE);
        for id in 0..q.size() {
            q.give(&mut mem, id, BUFFER_SIZE as u32, true);
        }
        let (_, _, used) = q.rings();
        for (slot, (id, len)) in entries.iter().enumerate().take(usize::from(q.size())) {
            mem.store32(used + 4 + 8 * slot, *id);
            mem.store32(used + 8 + 8 * slot, *len);
        }
        mem.store16(used + 2, index);
        let mut back = Vec::new();
        for _ in 0..=index {
            match q.take(&mem) {
                None => break,
                Some(Used::Buffer { id, len }) => {
                    prop_assert!(len as usize <= BUFFER_SIZE);
                    prop_assert!(!back.contains(&id));
                    back.push(id);
                }
                Some(Used::Bogus { .. }) => {}
            }
        }
        prop_assert_eq!(q.take(&mem), None);
    }
}

proptest! {
    /// Frames from the wire as the partition handles them: whatever length the device
    /// claims and whatever bytes it wrote (runts, random, oversized), the frame cut out of
    /// the buffer and routed by the switch never panics, and only 14..=1514-byte frames
    /// go anywhere.
    #[test]
    fn hostile_received_frames_never_panic(
        frames in proptest::collection::vec(
            (any::<u32>(), proptest::collection::vec(any::<u8>(), 0..BUFFER_SIZE)),
            1..40,
        ),
    ) {
        use crate::switch::{MAX_FRAME, MIN_FRAME, Mac, Port, Switch};
        let (mut mem, mut q, mut dev) = setup(RECEIVE_QUEUE);
        for id in 0..q.size() {
            q.give(&mut mem, id, BUFFER_SIZE as u32, true);
        }
        let mut switch = Switch::new(&[Mac([0x52, 0x54, 0, 0x12, 0x34, 0x56])]).unwrap();
        for (len, bytes) in frames {
            let (id, _, _, _) = dev.next(&mem).expect("a buffer");
            mem.write(q.buffer(id), &bytes);
            dev.complete(&mut mem, u32::from(id), len % (2 * BUFFER_SIZE as u32));
            let Some(Used::Buffer { id, len }) = q.take(&mem) else {
                return Err(TestCaseError::fail("the buffer given back"));
            };
            if let Some(range) = received_frame(len) {
                let mut frame = vec![0u8; range.len()];
                mem.read(q.buffer(id) + range.start, &mut frame);
                let routed = switch.route(Port::Uplink, &frame);
                prop_assert!(routed.is_err() || (MIN_FRAME..=MAX_FRAME).contains(&frame.len()));
            }
            prop_assert!(q.give(&mut mem, id, BUFFER_SIZE as u32, true));
        }
    }
}
