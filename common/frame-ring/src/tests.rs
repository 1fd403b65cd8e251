use super::*;
use proptest::prelude::*;

/// A zeroed, 64-byte aligned segment of `size` bytes.
struct Segment(alloc_free::Buffer);

mod alloc_free {
    extern crate std;
    use std::vec::Vec;

    /// 64-byte aligned memory without a global allocator's alignment guarantees.
    #[repr(C, align(64))]
    #[derive(Clone, Copy)]
    pub struct Line([u8; 64]);

    pub struct Buffer(pub Vec<Line>);

    impl Buffer {
        pub fn zeroed(size: usize) -> Self {
            Buffer(std::vec![Line([0; 64]); size.div_ceil(64)])
        }

        pub fn as_mut_ptr(&mut self) -> *mut u8 {
            self.0.as_mut_ptr() as *mut u8
        }
    }
}

impl Segment {
    fn new(size: usize) -> Self {
        Segment(alloc_free::Buffer::zeroed(size))
    }

    /// Both ends of the link over it.
    fn ends(&mut self, size: usize) -> ((Producer, Consumer), (Producer, Consumer)) {
        let at = self.0.as_mut_ptr();
        // SAFETY: the buffer outlives the test's ends (they are dropped first), and only
        // the two ends write it.
        let tenant = unsafe { attach(at, size, Side::Tenant) };
        // SAFETY: as above.
        let driver = unsafe { attach(at, size, Side::Driver) };
        (tenant.unwrap(), driver.unwrap())
    }

    /// Writes `bytes` at `offset`, as a hostile side would.
    fn scribble(&mut self, offset: usize, bytes: &[u8]) {
        let at = self.0.as_mut_ptr();
        // SAFETY: the tests keep `offset + bytes.len()` inside the buffer.
        unsafe {
            core::ptr::copy_nonoverlapping(bytes.as_ptr(), at.wrapping_add(offset), bytes.len())
        };
    }
}

fn frame(n: u8, len: usize) -> [u8; MTU] {
    let mut f = [0u8; MTU];
    for (i, b) in f[..len].iter_mut().enumerate() {
        *b = n.wrapping_add(i as u8);
    }
    f
}

#[test]
fn sizes() {
    assert_eq!(MIN_SEGMENT, 16384);
    assert_eq!(slots_in(MIN_SEGMENT / 2), 4);
    assert_eq!(slots_in(32 * 1024), 16);
    assert_eq!(slots_in(64 * 1024), 32);
    assert_eq!(slots_in(HEADER + 3 * SLOT), 0);
    assert_eq!(slots_in(16 << 20), MAX_SLOTS);
}

#[test]
fn a_segment_too_small_or_misaligned_is_refused() {
    let mut s = Segment::new(MIN_SEGMENT + 64);
    let at = s.0.as_mut_ptr();
    // SAFETY: inside the buffer; the results are dropped at once.
    let small = unsafe { attach(at, MIN_SEGMENT - 4096, Side::Tenant) };
    assert_eq!(
        small.unwrap_err(),
        SegmentError::TooSmall(MIN_SEGMENT - 4096)
    );
    // SAFETY: as above.
    let odd = unsafe { attach(at.wrapping_add(8), MIN_SEGMENT, Side::Tenant) };
    assert!(matches!(odd, Err(SegmentError::Misaligned(_))));
}

#[test]
fn frames_go_both_ways_in_order_and_the_first_asks_for_a_kick() {
    let size = 64 * 1024;
    let mut s = Segment::new(size);
    let ((mut tenant_tx, mut tenant_rx), (mut driver_tx, mut driver_rx)) = s.ends(size);
    assert_eq!(tenant_tx.slots(), 16);
    let mut buf = [0u8; MTU];
    assert_eq!(driver_rx.pop(&mut buf), None);
    assert!(driver_rx.is_empty());
    // Up: the first frame into an empty ring asks for a kick, the next ones do not.
    for n in 0..5u8 {
        let f = frame(n, 60 + usize::from(n));
        let pushed = tenant_tx.push(&f[..60 + usize::from(n)]).unwrap();
        assert_eq!(pushed.first, n == 0);
    }
    assert_eq!(tenant_tx.pending(), 5);
    for n in 0..5u8 {
        let len = driver_rx.pop(&mut buf).unwrap().unwrap();
        assert_eq!(len, 60 + usize::from(n));
        assert_eq!(buf[..len], frame(n, len)[..len]);
    }
    assert_eq!(driver_rx.pop(&mut buf), None);
    assert_eq!(tenant_tx.pending(), 0);
    // Emptied: the next frame asks for a kick again.
    assert!(tenant_tx.push(&[1; 14]).unwrap().first);
    // Down, a full-size frame.
    let f = frame(9, MTU);
    assert!(driver_tx.push(&f).unwrap().first);
    assert_eq!(tenant_rx.pop(&mut buf), Some(Ok(MTU)));
    assert_eq!(buf, f);
}

#[test]
fn the_consumer_names_whom_to_wake_and_a_scribbled_name_comes_back_when_it_looks() {
    let size = 64 * 1024;
    let mut s = Segment::new(size);
    let ((tenant_tx, mut tenant_rx), (driver_tx, mut driver_rx)) = s.ends(size);
    assert_eq!(tenant_tx.waiter(), None, "nobody named: kick");
    driver_rx.wake_me(0x1_0042, 1 << 25);
    tenant_rx.wake_me(0x2_0007, 1 << 2);
    assert_eq!(tenant_tx.waiter(), Some((0x1_0042, 1 << 25)));
    assert_eq!(driver_tx.waiter(), Some((0x2_0007, 1 << 2)));
    // The tenant overwrites the driver's words: its producer reads what it wrote (the
    // kernel refuses a thread it may not notify) until the driver finds its ring empty.
    s.scribble(WAITER, &0xdead_u64.to_le_bytes());
    s.scribble(WAKE_BITS, &0u64.to_le_bytes());
    assert_eq!(tenant_tx.waiter(), None, "no bits: kick");
    let mut buf = [0u8; MTU];
    assert_eq!(driver_rx.pop(&mut buf), None);
    assert_eq!(tenant_tx.waiter(), Some((0x1_0042, 1 << 25)));
}

#[test]
fn a_full_ring_refuses_and_wraps_around() {
    let size = MIN_SEGMENT;
    let mut s = Segment::new(size);
    let ((mut tx, _), (_, mut rx)) = s.ends(size);
    let mut buf = [0u8; MTU];
    for round in 0..100u32 {
        for n in 0..4 {
            tx.push(&[(round * 4 + n) as u8; 100]).unwrap();
        }
        assert_eq!(tx.push(&[0; 100]), Err(PushError::Full));
        for n in 0..4 {
            assert_eq!(rx.pop(&mut buf), Some(Ok(100)));
            assert_eq!(buf[0], (round * 4 + n) as u8);
        }
    }
    assert_eq!(tx.push(&[]), Err(PushError::Length(0)));
    assert_eq!(tx.push(&[0; MTU + 1]), Err(PushError::Length(MTU + 1)));
}

#[test]
fn indices_wrap_at_u32() {
    let size = MIN_SEGMENT;
    let mut s = Segment::new(size);
    let start = (u32::MAX - 2).to_le_bytes();
    s.scribble(PRODUCED, &start);
    s.scribble(CONSUMED, &start);
    let ((mut tx, _), (_, mut rx)) = s.ends(size);
    let mut buf = [0u8; MTU];
    for n in 0..10u8 {
        tx.push(&[n; 20]).unwrap();
        assert_eq!(rx.pop(&mut buf), Some(Ok(20)));
        assert_eq!(buf[0], n);
    }
}

#[test]
fn a_bogus_producer_index_or_length_costs_its_frames_only() {
    let size = MIN_SEGMENT;
    let mut s = Segment::new(size);
    let (_, (_, mut rx)) = s.ends(size);
    let mut buf = [0u8; MTU];
    // `produced` far ahead: the consumer skips to it.
    s.scribble(PRODUCED, &1000u32.to_le_bytes());
    assert_eq!(rx.pop(&mut buf), Some(Err(Bad::Index)));
    assert_eq!(rx.pop(&mut buf), None);
    // A bad length in a published slot.
    let ((mut tx2, _), _) = s.ends(size);
    tx2.push(&[7; 30]).unwrap();
    // Frame 1000 is in slot 1000 % 4 = 0.
    let slot = HEADER;
    s.scribble(slot, &u16::MAX.to_le_bytes());
    assert_eq!(
        rx.pop(&mut buf),
        Some(Err(Bad::Length(usize::from(u16::MAX))))
    );
    tx2.push(&[8; 30]).unwrap();
    assert_eq!(rx.pop(&mut buf), Some(Ok(30)));
    assert_eq!(buf[0], 8);
}

#[test]
fn a_bogus_consumer_index_reads_as_a_full_ring_until_the_consumer_looks_again() {
    let size = MIN_SEGMENT;
    let mut s = Segment::new(size);
    let ((mut tx, _), (_, mut rx)) = s.ends(size);
    s.scribble(CONSUMED, &77u32.to_le_bytes());
    assert_eq!(tx.push(&[1; 60]), Err(PushError::Full));
    assert_eq!(tx.pending(), tx.slots());
    let mut buf = [0u8; MTU];
    assert_eq!(rx.pop(&mut buf), None, "empty: it writes its index again");
    assert_eq!(tx.pending(), 0);
    assert!(tx.push(&[1; 60]).unwrap().first);
    assert_eq!(rx.pop(&mut buf), Some(Ok(60)));
}

#[test]
fn a_bogus_producer_index_is_written_again_by_the_next_push() {
    let size = MIN_SEGMENT;
    let mut s = Segment::new(size);
    let ((mut tx, _), (_, mut rx)) = s.ends(size);
    tx.push(&[1; 20]).unwrap();
    let mut buf = [0u8; MTU];
    assert_eq!(rx.pop(&mut buf), Some(Ok(20)));
    // Overwritten with a value far behind the consumer: the consumer skips to it.
    s.scribble(PRODUCED, &0x8000_0000u32.to_le_bytes());
    assert_eq!(rx.pop(&mut buf), Some(Err(Bad::Index)));
    // The next push writes the true index: the consumer resynchronises once more, and
    // the frame after that arrives.
    let _ = tx.push(&[2; 20]);
    let _ = rx.pop(&mut buf);
    assert_eq!(rx.pop(&mut buf), None);
    tx.push(&[3; 20]).unwrap();
    assert_eq!(rx.pop(&mut buf), Some(Ok(20)));
    assert_eq!(buf[0], 3);
}

proptest! {
    /// Whatever a hostile side writes into the segment between operations, the other
    /// side never panics, never reads past a slot and never hands out more than MTU bytes;
    /// frames a well-behaved producer pushes into an untouched ring arrive in order.
    #[test]
    fn hostile_bytes_never_hurt_the_reader(
        ops in proptest::collection::vec((0u8..4, any::<u16>(), any::<u32>(), 1usize..=MTU), 1..200)
    ) {
        let size = MIN_SEGMENT;
        let mut s = Segment::new(size);
        let ((mut tx, mut rx_down), (mut driver_tx, mut rx)) = s.ends(size);
        let mut buf = [0u8; MTU];
        let mut sent = 0u32;
        let mut got = 0u32;
        let mut tampered = false;
        for (op, offset, value, len) in ops {
            match op {
                0 => {
                    if tx.push(&[sent as u8; MTU][..len]).is_ok() {
                        sent += 1;
                    }
                }
                1 => match rx.pop(&mut buf) {
                    Some(Ok(n)) => {
                        prop_assert!(n <= MTU);
                        if !tampered {
                            prop_assert_eq!(buf[0], got as u8);
                        }
                        got += 1;
                    }
                    Some(Err(_)) => prop_assert!(tampered),
                    None => {}
                },
                2 => {
                    let at = usize::from(offset) % (size - 4);
                    s.scribble(at, &value.to_le_bytes());
                    tampered = true;
                }
                _ => {
                    let _ = driver_tx.push(&buf[..len]);
                    if let Some(Ok(n)) = rx_down.pop(&mut buf) {
                        prop_assert!(n <= MTU);
                    }
                }
            }
        }
        if !tampered {
            prop_assert!(sent - got <= tx.slots());
        }
    }
}
