//! Partitions `prio_tx` and `prio_rx` (scenario `apex_port_priority`): queuing ports with
//! the PRIORITY discipline. Processes of priorities 10, 30 and 20 begin to wait in that
//! order (delayed starts 1, 2 and 3 ms apart): on `prio_rx.req` (PRIORITY) three receivers
//! wait on the empty port, on `prio_tx.back` (PRIORITY) three senders wait on the full
//! channel. Both are served 30, 20, 10. `prio_tx` runs in 0-20 ms, `prio_rx` in 50-70 ms of
//! a 100 ms frame, so every wait spans windows of the other partition.
//!
//! Every line starts with the partition's name.

use apex::Warden;
use apex::a653rs::bindings::{
    self as b, ApexErrorP4, ApexProcessP1, ApexQueuingPortP1, ApexQueuingPortP4, ErrorReturnCode,
    PortDirection, QueuingDiscipline,
};
use apex::a653rs::prelude::StartContext;
use apex::codes::apex_name;
use apex::user_rt::println;
use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};

const MS: i64 = 1_000_000;
const INFINITE: i64 = b::INFINITE_TIME_VALUE;
/// The three waiters: name suffix digit and priority, in their order of arrival.
const WAITERS: [(u8, i32); 3] = [(b'1', 10), (b'2', 30), (b'3', 20)];
/// The frame of the system: `prio_tx`'s second window starts one frame after its first.
const FRAME: i64 = 100 * MS;

/// What receiver `i` got (0: nothing yet), and how many have.
static GOT: [AtomicU8; 3] = [const { AtomicU8::new(0) }; 3];
static RECEIVED: AtomicU32 = AtomicU32::new(0);

fn code<T>(result: Result<T, ErrorReturnCode>) -> Option<ErrorReturnCode> {
    result.err()
}

fn port(name: &str) -> b::QueuingPortId {
    <Warden as ApexQueuingPortP1>::get_queuing_port_id(apex_name(name)).expect("port")
}

fn create_port(
    name: &str,
    direction: PortDirection,
    depth: b::MessageRange,
    discipline: QueuingDiscipline,
) -> Result<b::QueuingPortId, ErrorReturnCode> {
    <Warden as ApexQueuingPortP4>::create_queuing_port(
        apex_name(name),
        8,
        depth,
        direction,
        discipline,
    )
}

fn send(id: b::QueuingPortId, message: &[u8], timeout: i64) -> Result<(), ErrorReturnCode> {
    <Warden as ApexQueuingPortP4>::send_queuing_message(id, message, timeout)
}

fn receive(id: b::QueuingPortId, timeout: i64, out: &mut [u8]) -> Result<u32, ErrorReturnCode> {
    #[allow(unsafe_code)]
    // SAFETY: a653rs's contract only asks for a writable slice, which `out` is (8 bytes,
    // the ports' message size).
    unsafe {
        <Warden as ApexQueuingPortP4>::receive_queuing_message(id, timeout, out)
            .map(|(length, _)| length)
    }
}

/// Creates `name` at `priority` and starts it after `delay` ns.
fn start(name: &str, entry: extern "C" fn(), priority: i32, delay: i64) {
    let id = crate::aperiodic(name, entry, priority);
    <Warden as ApexProcessP1>::delayed_start(id, delay)
        .unwrap_or_else(|e| panic!("DELAYED_START {name}: {e:?}"));
}

/// The index (0..3) of the calling waiter, from the last digit of its name.
fn my_index() -> usize {
    let me = <Warden as ApexProcessP1>::get_my_id().expect("a process");
    let status = <Warden as ApexProcessP1>::get_process_status(me).expect("status");
    let name = apex::codes::name_bytes(&status.attributes.name);
    let digit = name.last().copied().unwrap_or(b'1');
    WAITERS
        .iter()
        .position(|&(d, _)| d == digit)
        .expect("a waiter")
}

fn waiter_name(prefix: u8, index: usize) -> [u8; 2] {
    [prefix, WAITERS[index].0]
}

// ---- prio_tx

pub fn create_tx(_ctx: &mut StartContext<Warden>) {
    create_port("req", PortDirection::Source, 4, QueuingDiscipline::Fifo).expect("req");
    create_port(
        "back",
        PortDirection::Source,
        1,
        QueuingDiscipline::Priority,
    )
    .expect("back");
    // Fill `back` (1 in the source port + 1 in the destination) before the senders come.
    start("fill", fill, 50, 0);
    for (i, &(_, priority)) in WAITERS.iter().enumerate() {
        let name = waiter_name(b's', i);
        start(
            core::str::from_utf8(&name).unwrap_or("s"),
            sender,
            priority,
            (i as i64 + 1) * MS,
        );
    }
    start("watch", watch, 5, 10 * MS);
    // In the next window: the messages for the three waiting receivers.
    start("ask", ask, 5, FRAME);
}

extern "C" fn fill() {
    let back = port("back");
    for message in [b"x", b"y"] {
        send(back, message, 0).expect("SEND_QUEUING_MESSAGE fill");
    }
    println!("prio_tx: back full: {:?}", code(send(back, b"z", 0)));
}

extern "C" fn sender() {
    let index = my_index();
    if let Err(e) = send(port("back"), &[WAITERS[index].0], INFINITE) {
        println!("prio_tx: s{} failed: {e:?}", index + 1);
    }
}

extern "C" fn watch() {
    let status = <Warden as ApexQueuingPortP4>::get_queuing_port_status(port("back"));
    println!(
        "prio_tx: back waiting senders: {}",
        status.map_or(-1, |s| s.waiting_processes)
    );
}

extern "C" fn ask() {
    let req = port("req");
    for message in [b"a", b"b", b"c"] {
        send(req, message, 0).expect("SEND_QUEUING_MESSAGE to a waiting receiver");
    }
    println!("prio_tx: sent a b c");
}

// ---- prio_rx

pub fn create_rx(_ctx: &mut StartContext<Warden>) {
    // The discipline must be the configured one.
    println!(
        "prio_rx: CREATE_QUEUING_PORT req as FIFO: {:?}",
        code(create_port(
            "req",
            PortDirection::Destination,
            4,
            QueuingDiscipline::Fifo
        ))
    );
    create_port(
        "req",
        PortDirection::Destination,
        4,
        QueuingDiscipline::Priority,
    )
    .expect("req");
    create_port(
        "back",
        PortDirection::Destination,
        1,
        QueuingDiscipline::Fifo,
    )
    .expect("back");
    for (i, &(_, priority)) in WAITERS.iter().enumerate() {
        let name = waiter_name(b'r', i);
        start(
            core::str::from_utf8(&name).unwrap_or("r"),
            receiver,
            priority,
            (i as i64 + 1) * MS,
        );
    }
    start("drain", drain, 5, 10 * MS);
}

extern "C" fn receiver() {
    let index = my_index();
    let mut buf = [0u8; 8];
    match receive(port("req"), INFINITE, &mut buf) {
        Ok(_) => GOT[index].store(buf[0], Ordering::Relaxed),
        Err(e) => println!("prio_rx: r{} failed: {e:?}", index + 1),
    }
    if RECEIVED.fetch_add(1, Ordering::Relaxed) + 1 == 3 {
        let got = |i: usize| GOT[i].load(Ordering::Relaxed) as char;
        println!(
            "prio_rx: PRIORITY receivers got r1={} r2={} r3={}",
            got(0),
            got(1),
            got(2)
        );
        let _ = <Warden as ApexErrorP4>::raise_application_error(
            b::ErrorCode::ApplicationError,
            b"prio done",
        );
    }
}

extern "C" fn drain() {
    let back = port("back");
    let status = <Warden as ApexQueuingPortP4>::get_queuing_port_status(port("req"));
    let mut got = [b' '; 12];
    let mut n = 0;
    let mut buf = [0u8; 8];
    while n < got.len() {
        match receive(back, 0, &mut buf) {
            Ok(_) => {
                got[n] = buf[0];
                n += 2;
            }
            Err(_) => break,
        }
    }
    println!(
        "prio_rx: req waiting receivers: {}; back got {}",
        status.map_or(-1, |s| s.waiting_processes),
        core::str::from_utf8(&got[..n.saturating_sub(1)]).unwrap_or("?")
    );
}
