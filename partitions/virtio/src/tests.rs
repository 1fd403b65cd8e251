//! The transport's layout from capabilities, feature negotiation, and the split queue's
//! requests (single descriptors and chains) against a model of the device, honest and
//! hostile.

extern crate std;

use super::queue::{DESC_NEXT, DESC_WRITE, MAX_QUEUE_SIZE, QueueLayout, queue_size};
use super::testing::{DeviceModel, Ram};
use super::*;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

const BUS: u64 = 0x1234_0000;

fn setup(size: u16, buffer_size: usize) -> (Ram, Queue, DeviceModel) {
    let layout = QueueLayout {
        index: 0,
        size,
        rings: 0,
        buffers: queue::RINGS_SIZE,
        buffer_size,
    };
    let mut mem = Ram(vec![
        0xAA;
        queue::RINGS_SIZE + usize::from(size) * buffer_size
    ]);
    let q = Queue::new(&mut mem, layout, BUS).unwrap();
    let dev = DeviceModel::of(&q);
    (mem, q, dev)
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
fn features_are_the_transports_and_the_drivers_own() {
    const MAC: u64 = 1 << 5;
    assert_eq!(negotiate(MAC, MAC), None, "a legacy device");
    assert_eq!(
        negotiate(u64::MAX, MAC),
        Some(MAC | FEATURE_VERSION_1 | FEATURE_ACCESS_PLATFORM)
    );
    assert_eq!(negotiate(FEATURE_VERSION_1, MAC), Some(FEATURE_VERSION_1));
}

#[test]
fn queue_sizes_are_powers_of_two_within_the_limits() {
    assert_eq!(queue_size(256, 64), 64);
    assert_eq!(queue_size(48, 64), 32);
    assert_eq!(queue_size(256, 8), 8);
    assert_eq!(queue_size(256, 1000), MAX_QUEUE_SIZE);
    assert_eq!(queue_size(0, 64), 0);
    let layout = |size| QueueLayout {
        index: 0,
        size,
        rings: 0,
        buffers: 4096,
        buffer_size: 16,
    };
    let mut mem = Ram(vec![0; 8192]);
    assert!(Queue::new(&mut mem, layout(0), BUS).is_none());
    assert!(Queue::new(&mut mem, layout(48), BUS).is_none());
    assert!(Queue::new(&mut mem, layout(128), BUS).is_none());
}

#[test]
fn interrupts_are_asked_for_or_not_without_touching_the_requests() {
    let (mut mem, mut q, mut dev) = setup(8, 512);
    assert!(dev.wants_interrupts(&mem), "a new queue interrupts");
    q.set_interrupts(&mut mem, false);
    assert!(q.give(&mut mem, 2, 100, false));
    assert!(!dev.wants_interrupts(&mem));
    assert_eq!(dev.next(&mem).map(|d| (d.id, d.len)), Some((2, 100)));
    dev.complete(&mut mem, 2, 0);
    assert_eq!(q.take(&mem), Some(Used::Buffer { id: 2, len: 0 }));
    q.set_interrupts(&mut mem, true);
    assert!(dev.wants_interrupts(&mem));
    assert!(q.give(&mut mem, 2, 50, false));
    assert_eq!(dev.next(&mem).map(|d| (d.id, d.len)), Some((2, 50)));
}

#[test]
fn a_chain_is_linked_in_order_and_comes_back_whole() {
    let (mut mem, mut q, mut dev) = setup(8, 512);
    let request = [
        Segment {
            id: 3,
            len: 16,
            device_writes: false,
        },
        Segment {
            id: 4,
            len: 512,
            device_writes: true,
        },
        Segment {
            id: 5,
            len: 1,
            device_writes: true,
        },
    ];
    for round in 0..70_000u32 {
        assert!(q.give_chain(&mut mem, &request));
        assert!(!q.give_chain(&mut mem, &request), "the device holds it");
        let chain = dev.next_chain(&mem).unwrap();
        let seen: Vec<_> = chain.iter().map(|d| (d.id, d.len, d.flags)).collect();
        assert_eq!(
            seen,
            [
                (3, 16, DESC_NEXT),
                (4, 512, DESC_NEXT | DESC_WRITE),
                (5, 1, DESC_WRITE)
            ]
        );
        assert_eq!(chain[1].addr, BUS + q.buffer(4) as u64);
        assert_eq!(q.free(), Some(0));
        dev.complete(&mut mem, 3, 513 + round % 2);
        assert_eq!(
            q.take(&mem),
            Some(Used::Buffer {
                id: 3,
                len: 513 + round % 2
            })
        );
        assert!(!q.is_given(4) && !q.is_given(5));
    }
}

#[test]
fn bad_chains_are_refused_whole() {
    let (mut mem, mut q, _) = setup(8, 512);
    let s = |id, len| Segment {
        id,
        len,
        device_writes: false,
    };
    assert!(!q.give_chain(&mut mem, &[]));
    assert!(
        !q.give_chain(&mut mem, &[s(1, 16), s(1, 16)]),
        "named twice"
    );
    assert!(
        !q.give_chain(&mut mem, &[s(1, 16), s(8, 16)]),
        "out of range"
    );
    assert!(!q.give_chain(&mut mem, &[s(1, 16), s(2, 513)]), "too long");
    assert_eq!(q.free(), Some(0), "nothing given");
    assert!(q.give_chain(&mut mem, &[s(1, 16), s(2, 16)]));
    assert!(
        !q.give_chain(&mut mem, &[s(0, 16), s(2, 16)]),
        "2 is the device's"
    );
}

#[test]
fn a_hostile_device_cannot_give_back_a_chains_tail_or_a_request_twice() {
    let (mut mem, mut q, mut dev) = setup(8, 512);
    let s = |id, len| Segment {
        id,
        len,
        device_writes: true,
    };
    assert!(q.give_chain(&mut mem, &[s(0, 16), s(1, 512), s(2, 1)]));
    dev.complete(&mut mem, 1, 10);
    dev.complete(&mut mem, 0, u32::MAX);
    dev.complete(&mut mem, 0, 10);
    assert_eq!(q.take(&mem), Some(Used::Bogus { id: 1 }), "not a head");
    assert_eq!(
        q.take(&mem),
        Some(Used::Buffer {
            id: 0,
            len: 3 * 512
        }),
        "cut to its buffers"
    );
    assert_eq!(q.take(&mem), Some(Used::Bogus { id: 0 }), "returned twice");
    assert_eq!(q.take(&mem), None);
}

proptest! {
    /// Whatever the device writes into the used ring, the driver takes at most what was
    /// published, never panics, hands back each request at most once and a length within
    /// its buffers.
    #[test]
    fn random_used_rings_never_panic(
        entries in proptest::collection::vec((any::<u32>(), any::<u32>()), 0..200),
        index in any::<u16>(),
    ) {
        let (mut mem, mut q, _) = setup(MAX_QUEUE_SIZE, 64);
        for head in (0..q.size()).step_by(2) {
            let s = |id| Segment { id, len: 64, device_writes: true };
            prop_assert!(q.give_chain(&mut mem, &[s(head), s(head + 1)]));
        }
        let (_, _, used) = q.rings();
        for (slot, (id, len)) in entries.iter().enumerate().take(usize::from(q.size())) {
            mem.store32(used + 4 + 8 * slot, *id % 80);
            mem.store32(used + 8 + 8 * slot, *len);
        }
        mem.store16(used + 2, index);
        let mut back = Vec::new();
        for _ in 0..=index {
            match q.take(&mem) {
                None => break,
                Some(Used::Buffer { id, len }) => {
                    prop_assert!(len <= 128);
                    prop_assert!(id % 2 == 0 && !back.contains(&id));
                    back.push(id);
                }
                Some(Used::Bogus { .. }) => {}
            }
        }
        prop_assert_eq!(q.take(&mem), None);
    }
}
