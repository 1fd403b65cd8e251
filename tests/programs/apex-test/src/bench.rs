//! The APEX communication benchmarks, [`SAMPLES`] samples each, in cycles:
//! - `queuing_port_roundtrip`: one process sends a 64-byte message on a queuing port whose
//!   channel leads back into the same partition and receives it (two requests served by
//!   syssw);
//! - `queuing_port_frame_roundtrip`: the same with a 1514-byte message, a full Ethernet
//!   frame as the NIC partition and the guest exchange them (`frame-out` to `frame-in`);
//! - `queuing_port_long_roundtrip`: the same with a 20,000-byte message, longer than one
//!   request (five parts each way through the partition's staging buffer in syssw);
//! - `shared_ring_frame_roundtrip`: the same frame through a frame ring (`frame_ring`, the
//!   NIC partition's link to its tenants) in the shared-memory segment `ring`, pushed by
//!   the tenant's side and popped by the NIC's (copied into a slot, the index published,
//!   then the slot copied out and the other index advanced): what a frame costs the link
//!   over shared memory without its wake-up;
//! - `apex_blackboard_display_read`: DISPLAY_BLACKBOARD then READ_BLACKBOARD of 64 bytes;
//! - `apex_buffer_send_receive`: SEND_BUFFER then RECEIVE_BUFFER of 64 bytes (time-out 0);
//! - `apex_semaphore_pingpong`: between two processes: the measuring one signals `ping` and
//!   waits on `pong`; `echo`, of higher priority, waits on `ping` and signals `pong` (two
//!   process switches inside the partition a sample).
//!
//! Prints the `cargo xtask bench` lines, then ends the run (an APPLICATION_ERROR the bench
//! system maps to `shutdown_success`).
//!
//! The cross-CPU port benchmark system (`tests/configs/bench_ports_smp.toml`): partition
//! `bench-x` on CPU 0 times `queuing_port_roundtrip_cross_cpu`, a 64-byte message sent to
//! partition `echo-x` on CPU 1, which waits for it and sends it back, while `bench-x`
//! waits for the answer (both windows the whole frame, so the two run side by side): four
//! requests served by syssw, whose server follows each caller to its CPU, and a wake-up
//! on each CPU.

extern crate alloc;

use crate::{name, process_with_stack, raise};
use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::bindings::{self as b, ApexBlackboardP1, ApexBufferP1, ApexSemaphoreP1};
use apex::a653rs::prelude::*;
use apex::codes::apex_name;
use apex::user_rt::println;
use apex::user_rt::sys::rdtsc;
use core::time::Duration;

/// Samples (kept on the runtime's bounded heap: 8 bytes each).
const SAMPLES: usize = 4_000;
/// The largest Ethernet frame without its FCS (the NIC partition's port messages).
const FRAME: u32 = 1514;
/// A long message: five requests' worth.
const LONG: usize = 20_000;
/// The `ring` segment: the first (and only) shared segment of the port benchmark system,
/// and its size.
const RING: u64 = apex::user_rt::partition::SHARED_BASE;
const RING_SIZE: usize = 16 * 1024;

pub fn create(ctx: &mut StartContext<Warden>) {
    create_message_ports(ctx);
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
    // This process is both of the link's sides, one attach each.
    let at = RING as *mut u8;
    // SAFETY: the configuration maps `ring` (16 KiB) read-write at SHARED_BASE in this
    // partition only, for its life.
    let tenant = unsafe { frame_ring::attach(at, RING_SIZE, frame_ring::Side::Tenant) };
    // SAFETY: as above.
    let nic = unsafe { frame_ring::attach(at, RING_SIZE, frame_ring::Side::Driver) };
    let ((mut to_nic, _), (_, mut from_tenant)) = (tenant.expect("ring"), nic.expect("ring"));
    let mut buf = [0u8; frame_ring::MTU];
    measure("shared_ring_frame_roundtrip", || {
        to_nic.push(&frame).expect("room in the ring");
        let got = from_tenant
            .pop(&mut buf)
            .expect("the frame")
            .expect("intact");
        assert_eq!(got, frame.len(), "the frame comes back whole");
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

/// `bench-x`: the ports to `echo-x` and back, and the measuring process.
pub fn create_cross(ctx: &mut StartContext<Warden>) {
    create_message_ports(ctx);
    crate::process(ctx, "ping", cross_ping, None, None);
}

/// `echo-x`: the same ports, and the process that answers.
pub fn create_echo(ctx: &mut StartContext<Warden>) {
    create_message_ports(ctx);
    crate::process(ctx, "echo", cross_echo, None, None);
}

/// The 64-byte ports `out` and `in` (`bench-q`'s channel back into itself, `bench-x`'s and
/// `echo-x`'s to each other).
fn create_message_ports(ctx: &mut StartContext<Warden>) {
    ctx.create_queuing_port_sender(name("out"), 64, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT out");
    ctx.create_queuing_port_receiver(name("in"), 64, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT in");
}

extern "C" fn cross_ping() {
    let out = QueuingPortSender::<Warden>::from_name(name("out")).expect("out");
    let inp = QueuingPortReceiver::<Warden>::from_name(name("in")).expect("in");
    let message = [0x5au8; 64];
    let mut buf = [0u8; 64];
    measure("queuing_port_roundtrip_cross_cpu", || {
        out.send(&message, SystemTime::Infinite)
            .expect("SEND_QUEUING_MESSAGE");
        let (got, _) = inp
            .receive(&mut buf, SystemTime::Infinite)
            .expect("RECEIVE_QUEUING_MESSAGE");
        assert_eq!(got, &message[..], "the message comes back unchanged");
    });
    raise(b"bench done");
}

extern "C" fn cross_echo() {
    let out = QueuingPortSender::<Warden>::from_name(name("out")).expect("out");
    let inp = QueuingPortReceiver::<Warden>::from_name(name("in")).expect("in");
    let mut buf = [0u8; 64];
    loop {
        let (got, _) = inp
            .receive(&mut buf, SystemTime::Infinite)
            .expect("RECEIVE_QUEUING_MESSAGE");
        let len = got.len();
        out.send(&buf[..len], SystemTime::Infinite)
            .expect("SEND_QUEUING_MESSAGE");
    }
}
