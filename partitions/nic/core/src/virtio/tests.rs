//! The virtio-net queues in the NIC's DMA layout against a model of the device, honest
//! and hostile.

extern crate std;

use super::*;
use ::virtio::queue::DESC_WRITE;
use ::virtio::testing::{Descriptor, DeviceModel, Ram};
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

const BUS: u64 = 0x1234_0000;

fn setup(q: u16) -> (Ram, Queue, DeviceModel) {
    let layout = DmaLayout::new(256, 512 * 1024).unwrap();
    let mut mem = Ram(vec![0xAA; layout.bytes()]);
    let queue = layout.queue(&mut mem, q, BUS).unwrap();
    let device = DeviceModel::of(&queue);
    (mem, queue, device)
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
        let Descriptor {
            id,
            addr,
            len,
            flags,
        } = dev.next(&mem).expect("a buffer");
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
    let Descriptor {
        id: got,
        addr,
        len,
        flags,
    } = dev.next(&mem).unwrap();
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
            let id = dev.next(&mem).expect("a buffer").id;
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
