//! The APEX communication benchmarks, [`SAMPLES`] samples each, in cycles:
//! - `queuing_port_roundtrip`: one process sends a 64-byte message on a queuing port whose
//!   channel leads back into the same partition and receives it (two requests served by
//!   syssw);
//! - `queuing_port_frame_roundtrip`: the same with a 1514-byte message, a full Ethernet
//!   frame as the NIC partition and the guest exchange them (`frame-out` to `frame-in`);
//! - `queuing_port_long_roundtrip`: the same with a 20,000-byte message, longer than one
//!   request (five parts each way through the partition's staging buffer in syssw);
//! - `shared_ring_frame_roundtrip`: the same frame through a single-producer,
//!   single-consumer ring in the shared-memory segment `ring` (copied into a slot, the
//!   head index published, then the slot copied out and the tail index advanced), what a
//!   frame link over shared memory costs without its notification;
//! - `apex_blackboard_display_read`: DISPLAY_BLACKBOARD then READ_BLACKBOARD of 64 bytes;
//! - `apex_buffer_send_receive`: SEND_BUFFER then RECEIVE_BUFFER of 64 bytes (time-out 0);
//! - `apex_semaphore_pingpong`: between two processes: the measuring one signals `ping` and
//!   waits on `pong`; `echo`, of higher priority, waits on `ping` and signals `pong` (two
//!   process switches inside the partition a sample).
//!
//! Prints the `cargo xtask bench` lines, then ends the run (an APPLICATION_ERROR the bench
//! system maps to `shutdown_success`).

extern crate alloc;

use crate::{name, process_with_stack, raise};
use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::bindings::{self as b, ApexBlackboardP1, ApexBufferP1, ApexSemaphoreP1};
use apex::a653rs::prelude::*;
use apex::codes::apex_name;
use apex::user_rt::println;
use apex::user_rt::sys::rdtsc;
use core::sync::atomic::{AtomicU32, Ordering};
use core::time::Duration;

/// Samples (kept on the runtime's bounded heap: 8 bytes each).
const SAMPLES: usize = 4_000;
/// The largest Ethernet frame without its FCS (the NIC partition's port messages).
const FRAME: u32 = 1514;
/// A long message: five requests' worth.
const LONG: usize = 20_000;
/// The `ring` segment: the first (and only) shared segment of the port benchmark system.
const RING: u64 = apex::user_rt::partition::SHARED_BASE;
/// The ring's slots (a power of two) and their stride; the head and tail indices (u32)
/// sit in the segment's first 64 bytes, the slots after them.
const RING_SLOTS: u32 = 4;
const SLOT: u64 = 1536;

pub fn create(ctx: &mut StartContext<Warden>) {
    ctx.create_queuing_port_sender(name("out"), 64, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT out");
    ctx.create_queuing_port_receiver(name("in"), 64, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT in");
    ctx.create_queuing_port_sender(name("frame-out"), FRAME, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT frame-out");
    ctx.create_queuing_port_receiver(name("frame-in"), FRAME, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT frame-in");
    ctx.create_queuing_port_sender(name("long-out"), LONG as u32, 1, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT long-out");
    ctx.create_queuing_port_receiver(name("long-in"), LONG as u32, 1, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT long-in");
    let qd = QueuingDiscipline::Fifo;
    <Warden as ApexBlackboardP1>::create_blackboard(apex_name("board"), 64).expect("board");
    <Warden as ApexBufferP1>::create_buffer(apex_name("buffer"), 64, 2, qd).expect("buffer");
    for s in ["ping", "pong"] {
        <Warden as ApexSemaphoreP1>::create_semaphore(apex_name(s), 0, 1, qd).expect("semaphore");
    }
    // Room for the long message and its copy on the stack.
    process_with_stack(ctx, "roundtrip", roundtrip, None, None, 96 * 1024);
    // Above `roundtrip` (priority 10): it runs as soon as `ping` is signalled.
    crate::start_aperiodic("echo", echo, 20);
}

fn semaphore(s: &str) -> b::SemaphoreId {
    <Warden as ApexSemaphoreP1>::get_semaphore_id(apex_name(s)).expect("semaphore")
}

extern "C" fn echo() {
    let (ping, pong) = (semaphore("ping"), semaphore("pong"));
    loop {
        <Warden as ApexSemaphoreP1>::wait_semaphore(ping, b::INFINITE_TIME_VALUE).expect("ping");
        <Warden as ApexSemaphoreP1>::signal_semaphore(pong).expect("pong");
    }
}

/// Runs `pair` [`SAMPLES`] times and prints its `bench` line.
fn measure(metric: &str, mut pair: impl FnMut()) {
    let mut samples = Vec::with_capacity(SAMPLES);
    for _ in 0..SAMPLES {
        let t0 = rdtsc();
        pair();
        samples.push(rdtsc() - t0);
    }
    samples.sort_unstable();
    println!(
        "bench {metric} median={} min={} max={} unit=cycles samples={SAMPLES}",
        samples[SAMPLES / 2],
        samples[0],
        samples[SAMPLES - 1]
    );
}

/// The intra-partition objects' benchmarks.
fn intra() {
    let message = [0xa5u8; 64];
    let mut buf = [0u8; 64];
    let board = <Warden as ApexBlackboardP1>::get_blackboard_id(apex_name("board")).expect("board");
    measure("apex_blackboard_display_read", || {
        <Warden as ApexBlackboardP1>::display_blackboard(board, &message).expect("DISPLAY");
        let got = crate::intra::read(board, 0, &mut buf);
        assert_eq!(got.expect("READ_BLACKBOARD"), 64);
    });
    let buffer = <Warden as ApexBufferP1>::get_buffer_id(apex_name("buffer")).expect("buffer");
    measure("apex_buffer_send_receive", || {
        <Warden as ApexBufferP1>::send_buffer(buffer, &message, 0).expect("SEND_BUFFER");
        let got = crate::intra::receive(buffer, 0, &mut buf);
        assert_eq!(got.expect("RECEIVE_BUFFER"), 64);
    });
    let (ping, pong) = (semaphore("ping"), semaphore("pong"));
    measure("apex_semaphore_pingpong", || {
        <Warden as ApexSemaphoreP1>::signal_semaphore(ping).expect("SIGNAL ping");
        <Warden as ApexSemaphoreP1>::wait_semaphore(pong, b::INFINITE_TIME_VALUE).expect("pong");
    });
}

/// A 1514-byte frame through a queuing port and through a ring in shared memory.
#[allow(unsafe_code)]
fn frames() {
    let out = QueuingPortSender::<Warden>::from_name(name("frame-out")).expect("frame-out");
    let inp = QueuingPortReceiver::<Warden>::from_name(name("frame-in")).expect("frame-in");
    let frame = [0x5au8; FRAME as usize];
    let mut buf = [0u8; FRAME as usize];
    let poll = || SystemTime::Normal(Duration::ZERO);
    measure("queuing_port_frame_roundtrip", || {
        out.send(&frame, poll()).expect("SEND_QUEUING_MESSAGE");
        let (got, _) = inp
            .receive(&mut buf, poll())
            .expect("RECEIVE_QUEUING_MESSAGE");
        assert_eq!(got.len(), frame.len(), "the frame comes back whole");
    });
    let out = QueuingPortSender::<Warden>::from_name(name("long-out")).expect("long-out");
    let inp = QueuingPortReceiver::<Warden>::from_name(name("long-in")).expect("long-in");
    let long = [0xa5u8; LONG];
    let mut back = [0u8; LONG];
    measure("queuing_port_long_roundtrip", || {
        out.send(&long, poll()).expect("SEND_QUEUING_MESSAGE");
        let (got, _) = inp
            .receive(&mut back, poll())
            .expect("RECEIVE_QUEUING_MESSAGE");
        assert_eq!(got.len(), LONG, "the message comes back whole");
    });
    let head = RING as *const AtomicU32;
    let tail = (RING + 4) as *const AtomicU32;
    let slot = |index: u32| (RING + 64 + u64::from(index % RING_SLOTS) * SLOT) as *mut u8;
    measure("shared_ring_frame_roundtrip", || {
        // The producer: the frame into the slot at the head, then the head published.
        // SAFETY: the configuration maps `ring` (8 KiB) read-write at SHARED_BASE in this
        // partition: the indices and every slot (64 + 4 * 1536 bytes) lie inside it.
        let head = unsafe { &*head };
        // SAFETY: as above.
        let tail = unsafe { &*tail };
        let h = head.load(Ordering::Relaxed);
        // SAFETY: as above; the slot is the producer's until the head passes it.
        unsafe { core::ptr::copy_nonoverlapping(frame.as_ptr(), slot(h), frame.len()) };
        head.store(h.wrapping_add(1), Ordering::Release);
        // The consumer: the slot at the tail copied out, then the tail advanced.
        let t = tail.load(Ordering::Relaxed);
        assert_ne!(head.load(Ordering::Acquire), t, "the ring holds the frame");
        // SAFETY: as above; the slot is the consumer's until the tail passes it.
        unsafe { core::ptr::copy_nonoverlapping(slot(t), buf.as_mut_ptr(), buf.len()) };
        tail.store(t.wrapping_add(1), Ordering::Release);
    });
    assert_eq!(buf, frame, "the ring's frame comes out unchanged");
}

extern "C" fn roundtrip() {
    let out = QueuingPortSender::<Warden>::from_name(name("out")).expect("out");
    let inp = QueuingPortReceiver::<Warden>::from_name(name("in")).expect("in");
    let message = [0x5au8; 64];
    let mut buf = [0u8; 64];
    let poll = || SystemTime::Normal(Duration::ZERO);
    let mut samples = Vec::with_capacity(SAMPLES);
    for _ in 0..SAMPLES {
        let t0 = rdtsc();
        out.send(&message, poll()).expect("SEND_QUEUING_MESSAGE");
        let (got, _) = inp
            .receive(&mut buf, poll())
            .expect("RECEIVE_QUEUING_MESSAGE");
        let t1 = rdtsc();
        assert_eq!(got, &message[..], "the message comes back unchanged");
        samples.push(t1 - t0);
    }
    samples.sort_unstable();
    println!(
        "bench queuing_port_roundtrip median={} min={} max={} unit=cycles samples={SAMPLES}",
        samples[SAMPLES / 2],
        samples[0],
        samples[SAMPLES - 1]
    );
    frames();
    intra();
    raise(b"bench done");
}
