//! Partition programs for the APEX scenarios, written against the `a653rs` traits only
//! (through `apex::Warden`, as a partition of DLR's a653rs ecosystem would be). What a
//! partition does depends on its name:
//!
//! * `sender` / `receiver` (scenario `apex_ports`): sampling and queuing messages across
//!   their windows: validity flips after the refresh period, a full queue refuses
//!   (NOT_AVAILABLE) or times out, an empty one times out, a blocking receive waits across
//!   windows; long messages (10,000 and 20,000 bytes, several IPC messages each) arrive
//!   whole, also to a receive that waited for them; a process runs on a 200,000-byte
//!   stack; the receiver ends the run with an application error the configuration maps
//!   to `shutdown_success`;
//! * `victim` / `intruder` / `restarter` / `overrun` (scenario `apex_health`): the intruder
//!   writes the victim's shared memory it may only read (MEMORY_VIOLATION) while the victim
//!   keeps its windows; the restarter shows what a warm and a cold restart keep; a periodic
//!   process overruns its time capacity (DEADLINE_MISSED); the victim finally raises an
//!   error configured as `shutdown` (failure exit);
//! * `intra` (scenario `apex_intra`): buffers, blackboards, semaphores, events and mutexes
//!   between processes of different priorities: FIFO and PRIORITY wake order, time-outs,
//!   the mutex priority ceiling and the return codes in both modes (see `intra.rs`);
//! * `heap` (scenario `apex_heap`): the heap's lock under preemption, suspension and
//!   STOP (`heap.rs`).
//! * `preempt` (scenario `apex_preemption`): LOCK_PREEMPTION / UNLOCK_PREEMPTION: a
//!   higher-priority process readied while the lock is held runs only at level 0, the
//!   codes of the services a lock owner may not call, the lock level's bound (see
//!   `preemption.rs`);
//! * `prio_tx` / `prio_rx` (scenario `apex_port_priority`): queuing ports with the
//!   PRIORITY discipline: waiting receivers and waiting senders served by priority, FIFO
//!   among equals (see `port_priority.rs`);
//! * `sched` / `plain` (scenario `apex_schedule_switch`): module schedules: a switch
//!   that lands on the major-frame boundary, and a partition that may not switch (see
//!   `schedules.rs`);
//! * `switcher` / `warm` / `reborn` / `stopped` / `keeper` (scenario
//!   `apex_schedule_actions`): schedule change actions: a switch warm-starts one
//!   partition, cold-starts one and stops another (see
//!   `schedules.rs`);
//! * `handled` (scenario `apex_error_handler`): the error handler with GET_ERROR_STATUS,
//!   RAISE_APPLICATION_ERROR's codes, and what a handler may not do (see `errors.rs`);
//! * `bench-q` (`cargo xtask bench`): times queuing-port send + receive through syssw;
//! * `bench-x` / `echo-x` (`cargo xtask bench`): times a queuing-port round trip from CPU
//!   0 to CPU 1 and back (see `bench.rs`);
//! * `bench-s` / `idle` (`cargo xtask bench`): times module-schedule switches (see
//!   `schedules.rs`);
//! * `forger` / `bystander` (scenario `forged_fault_report`): the forger sends syssw a
//!   message with the kernel's fault-report label, which the kernel refuses, so syssw never
//!   stops the bystander, which counts its frames and ends the run successfully.
//!
//! Every line it prints starts with the partition's name (an interface for the scenario
//! tests).
#![no_std]
#![no_main]

extern crate alloc;

mod bench;
mod errors;
mod heap;
mod intra;
mod port_priority;
mod preemption;
mod schedules;

use apex::Warden;
use apex::a653rs::prelude::*;
use apex::user_rt::partition::SHARED_BASE;
use apex::user_rt::println;
use core::str::FromStr;
use core::sync::atomic::{AtomicU32, Ordering};
use core::time::Duration;

/// The major frame of the apex_health system: the period of its periodic processes.
const FRAME: Duration = Duration::from_millis(20);
/// The major frame of the apex_ports system.
const PORTS_FRAME: Duration = Duration::from_millis(100);

fn name(text: &str) -> Name {
    Name::from_str(text).expect("names here are short")
}

fn time() -> Duration {
    <Warden as ApexTimeP4Ext>::get_time().unwrap_duration()
}

fn periodic_wait() {
    <Warden as ApexTimeP4Ext>::periodic_wait().expect("PERIODIC_WAIT of a periodic process");
}

fn raise(text: &[u8]) {
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(text);
}

/// Spins until `GET_TIME` reaches `until` (CPU work that takes wall time).
fn spin_until(until: Duration) {
    while time() < until {
        core::hint::spin_loop();
    }
}

/// Creates the aperiodic process `process_name` at `priority` (16 KiB of stack, soft
/// deadline) through the APEX bindings, for a caller that starts it as it needs.
pub(crate) fn aperiodic(
    process_name: &str,
    entry: extern "C" fn(),
    priority: i32,
) -> apex::a653rs::bindings::ProcessId {
    use apex::a653rs::bindings::{self as b, ApexProcessP4};
    let attributes = b::ApexProcessAttribute {
        period: b::INFINITE_TIME_VALUE,
        time_capacity: b::INFINITE_TIME_VALUE,
        entry_point: entry,
        stack_size: 16 * 1024,
        base_priority: priority,
        deadline: Deadline::Soft,
        name: apex::codes::apex_name(process_name),
    };
    <Warden as ApexProcessP4>::create_process(&attributes)
        .unwrap_or_else(|e| panic!("CREATE_PROCESS {process_name}: {e:?}"))
}

/// [`aperiodic`], started at once.
pub(crate) fn start_aperiodic(process_name: &str, entry: extern "C" fn(), priority: i32) {
    use apex::a653rs::bindings::ApexProcessP4;
    let id = aperiodic(process_name, entry, priority);
    <Warden as ApexProcessP4>::start(id).unwrap_or_else(|e| panic!("START {process_name}: {e:?}"));
}

/// Creates and starts a process (`period` None = aperiodic).
pub(crate) fn process(
    ctx: &mut StartContext<Warden>,
    process_name: &str,
    entry: extern "C" fn(),
    period: Option<Duration>,
    capacity: Option<Duration>,
) {
    process_with_stack(ctx, process_name, entry, period, capacity, 16 * 1024);
}

/// [`process`] with a stack of `stack_size` bytes.
pub(crate) fn process_with_stack(
    ctx: &mut StartContext<Warden>,
    process_name: &str,
    entry: extern "C" fn(),
    period: Option<Duration>,
    capacity: Option<Duration>,
    stack_size: u32,
) {
    let attributes = ProcessAttribute {
        period: period.map_or(SystemTime::Infinite, SystemTime::Normal),
        time_capacity: capacity.map_or(SystemTime::Infinite, SystemTime::Normal),
        entry_point: entry,
        stack_size,
        base_priority: 10,
        deadline: Deadline::Soft,
        name: name(process_name),
    };
    let p = ctx
        .create_process(attributes)
        .unwrap_or_else(|e| panic!("CREATE_PROCESS {process_name}: {e:?}"));
    p.start()
        .unwrap_or_else(|e| panic!("START {process_name}: {e:?}"));
}

struct Test;

impl Partition<Warden> for Test {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        let info = apex::runtime::start_info();
        match info.name() {
            "sender" => {
                ctx.create_sampling_port_source(name("level"), 16)
                    .expect("CREATE_SAMPLING_PORT level");
                ctx.create_queuing_port_sender(name("cmd"), 32, 2, QueuingDiscipline::Fifo)
                    .expect("CREATE_QUEUING_PORT cmd");
                ctx.create_sampling_port_source(name("image"), IMAGE as u32)
                    .expect("CREATE_SAMPLING_PORT image");
                ctx.create_queuing_port_sender(
                    name("bulk"),
                    BULK as u32,
                    1,
                    QueuingDiscipline::Fifo,
                )
                .expect("CREATE_QUEUING_PORT bulk");
                // A port the configuration does not have is refused.
                let unknown = ctx.create_sampling_port_source(name("nonesuch"), 16);
                println!("sender: unknown port: {:?}", unknown.err());
                process_with_stack(ctx, "produce", produce, Some(PORTS_FRAME), None, 64 * 1024);
                // Stacks come from the runtime's arena as asked: a large one fits, one
                // beyond what is left does not.
                process_with_stack(ctx, "deep", deep, None, None, DEEP_STACK);
                let attributes = ProcessAttribute {
                    period: SystemTime::Infinite,
                    time_capacity: SystemTime::Infinite,
                    entry_point: deep,
                    stack_size: 1 << 20,
                    base_priority: 10,
                    deadline: Deadline::Soft,
                    name: name("huge"),
                };
                let huge = ctx.create_process(attributes);
                println!("sender: a 1 MiB stack: {:?}", huge.err());
            }
            "receiver" => {
                ctx.create_sampling_port_destination(name("level"), 16, Duration::from_millis(125))
                    .expect("CREATE_SAMPLING_PORT level");
                ctx.create_queuing_port_receiver(name("cmd"), 32, 4, QueuingDiscipline::Fifo)
                    .expect("CREATE_QUEUING_PORT cmd");
                ctx.create_sampling_port_destination(
                    name("image"),
                    IMAGE as u32,
                    Duration::from_millis(125),
                )
                .expect("CREATE_SAMPLING_PORT image");
                ctx.create_queuing_port_receiver(
                    name("bulk"),
                    BULK as u32,
                    2,
                    QueuingDiscipline::Fifo,
                )
                .expect("CREATE_QUEUING_PORT bulk");
                process_with_stack(ctx, "consume", consume, Some(PORTS_FRAME), None, 64 * 1024);
            }
            "victim" => process(ctx, "count", count, Some(FRAME), None),
            "intruder" => process(ctx, "poke", poke, Some(FRAME), None),
            "overrun" => process(
                ctx,
                "work",
                work,
                Some(FRAME),
                Some(Duration::from_millis(2)),
            ),
            "restarter" => restarter(ctx),
            "bench-q" => bench::create(ctx),
            "bench-x" => bench::create_cross(ctx),
            "echo-x" => bench::create_echo(ctx),
            "intra" => intra::create(ctx),
            "preempt" => preemption::create(ctx),
            "heap" => heap::create(),
            "prio_tx" => port_priority::create_tx(ctx),
            "prio_rx" => port_priority::create_rx(ctx),
            "sched" => schedules::create_sched(ctx),
            "handled" => errors::create(ctx),
            "plain" => schedules::create_plain(ctx),
            "bench-s" => schedules::create_bench(ctx),
            "switcher" | "warm" | "reborn" | "stopped" | "keeper" => schedules::create_actions(ctx),
            // Only fills windows (the schedule-switch bench).
            "idle" => {}
            "forger" => process(ctx, "forge", forge, Some(FRAME), None),
            "bystander" => process(ctx, "tick", tick, Some(FRAME), None),
            other => println!("{other}: no role for this partition name"),
        }
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        match apex::runtime::start_info().name() {
            "restarter" => restarter(ctx),
            _ => self.cold_start(ctx),
        }
    }
}

fn main() {
    Test.run()
}

apex::partition_entry!(main);

// ---- forged_fault_report ----

/// Tries to pass for the kernel: a fault report (the label only the kernel may send) naming
/// every task id a partition could have, which syssw would act on if it arrived.
extern "C" fn forge() {
    use apex::user_rt::abi::ipc::{LABEL_FAULT_REPORT, MessageTag};
    use apex::user_rt::abi::syscall::{TIMEOUT_INFINITE, ThreadId, make_id};
    use apex::user_rt::sys::{Message, ipc_call, send};
    let server = ThreadId(apex::runtime::start_info().server);
    let mut refused = [0u32; 2];
    for slot in 0..64 {
        let m = Message {
            tag: MessageTag::new(LABEL_FAULT_REPORT, 0, 0),
            words: [make_id(slot, 0), 0, 0],
        };
        // Both ways in: a call (as a request) and a plain send.
        refused[0] += u32::from(ipc_call(server, TIMEOUT_INFINITE, &m).is_err());
        refused[1] += u32::from(send(server, 0, &m).is_err());
    }
    println!(
        "forger: forged fault reports refused: {} calls, {} sends",
        refused[0], refused[1]
    );
    loop {
        periodic_wait();
    }
}

extern "C" fn tick() {
    let first = time();
    loop {
        let frame = frame_of(first, FRAME);
        if frame.is_multiple_of(10) {
            println!("bystander: frame {frame}");
        }
        if frame >= 30 {
            raise(b"bystander done");
        }
        periodic_wait();
    }
}

// ---- apex_ports ----

/// Frame number (1 = the first) of a periodic process of `period` that counts from `first`
/// (rounded: a job may start a little after its release point, the next one on time).
fn frame_of(first: Duration, period: Duration) -> u32 {
    let elapsed = time().saturating_sub(first).as_micros();
    let period = period.as_micros();
    ((elapsed + period / 2) / period) as u32 + 1
}

/// The long ports' sizes (several IPC messages each) and the deep process's stack.
const IMAGE: usize = 10_000;
const BULK: usize = 20_000;
const DEEP_STACK: u32 = 200_000;

/// Byte `i` of long message `k`: every part of a message differs from the others.
fn pattern(k: u8, i: usize) -> u8 {
    (i as u8).wrapping_mul(7) ^ (i >> 8) as u8 ^ k
}

fn long_message(k: u8, buf: &mut [u8]) -> &[u8] {
    for (i, b) in buf.iter_mut().enumerate() {
        *b = pattern(k, i);
    }
    buf
}

/// Whether `msg` is long message `k` of `len` bytes.
fn intact(k: u8, msg: &[u8], len: usize) -> bool {
    msg.len() == len && msg.iter().enumerate().all(|(i, &b)| b == pattern(k, i))
}

/// Uses most of its 200,000-byte stack (a 180,000-byte array the optimiser cannot drop).
extern "C" fn deep() {
    let mut array = [0u8; 180_000];
    for (i, b) in array.iter_mut().enumerate() {
        *b = i as u8;
    }
    let array = core::hint::black_box(&mut array);
    let sum: u32 = array.iter().map(|&b| u32::from(b)).sum();
    println!("sender: deep stack used 180000 bytes, sum {sum}");
}

extern "C" fn produce() {
    let level = SamplingPortSource::<Warden>::from_name(name("level")).expect("level");
    let cmd = QueuingPortSender::<Warden>::from_name(name("cmd")).expect("cmd");
    let image = SamplingPortSource::<Warden>::from_name(name("image")).expect("image");
    let bulk = QueuingPortSender::<Warden>::from_name(name("bulk")).expect("bulk");
    let mut buf = [0u8; BULK];
    let first = time();
    loop {
        let frame = frame_of(first, PORTS_FRAME);
        if frame <= 3 {
            level
                .send(&frame.to_le_bytes())
                .expect("WRITE_SAMPLING_MESSAGE");
            image
                .send(long_message(frame as u8, &mut buf[..IMAGE]))
                .expect("WRITE_SAMPLING_MESSAGE of 10,000 bytes");
        }
        if frame == 1 {
            // A full message, a short one, and one the port is too small for.
            let zero = || SystemTime::Normal(Duration::ZERO);
            bulk.send(long_message(1, &mut buf), zero())
                .expect("SEND_QUEUING_MESSAGE of 20,000 bytes");
            bulk.send(long_message(2, &mut buf[..5000]), zero())
                .expect("SEND_QUEUING_MESSAGE of 5,000 bytes");
            let mut more = [0u8; BULK + 1];
            let refused = bulk.send(long_message(3, &mut more), zero());
            println!("sender: a 20,001-byte message: {:?}", refused.err());
        }
        if frame == 3 {
            // The receiver waits for it since its last window.
            bulk.send(
                long_message(4, &mut buf),
                SystemTime::Normal(Duration::ZERO),
            )
            .expect("SEND_QUEUING_MESSAGE to a waiting receiver");
        }
        if frame == 1 {
            // Fill the channel (2 in the source port + 4 in the destination) without waiting.
            let mut sent = 0u8;
            let refused = loop {
                match cmd.send(&[sent], SystemTime::Normal(Duration::ZERO)) {
                    Ok(()) => sent += 1,
                    Err(e) => break e,
                }
            };
            println!("sender: queued {sent} messages, then {refused:?}");
            let waited = cmd.send(&[99], SystemTime::Normal(Duration::from_millis(1)));
            println!("sender: send with 1 ms time-out: {:?}", waited.err());
        }
        if frame == 5 {
            cmd.send(&[100], SystemTime::Normal(Duration::ZERO))
                .expect("SEND_QUEUING_MESSAGE to a waiting receiver");
        }
        periodic_wait();
    }
}

extern "C" fn consume() {
    let level = SamplingPortDestination::<Warden>::from_name(name("level")).expect("level");
    let cmd = QueuingPortReceiver::<Warden>::from_name(name("cmd")).expect("cmd");
    let image = SamplingPortDestination::<Warden>::from_name(name("image")).expect("image");
    let bulk = QueuingPortReceiver::<Warden>::from_name(name("bulk")).expect("bulk");
    let mut long = [0u8; BULK];
    let mut buf = [0u8; 32];
    // Frames count from the first sampling message (the receiver may start a frame before
    // the sender has written anything).
    let first = loop {
        match level.receive(&mut buf) {
            Ok(_) => break time(),
            Err(e) => println!("receiver: no message yet: {e:?}"),
        }
        periodic_wait();
    };
    loop {
        let frame = frame_of(first, PORTS_FRAME);
        match level.receive(&mut buf) {
            Ok((validity, msg)) => {
                let mut word = [0u8; 4];
                word.copy_from_slice(&msg[..4]);
                println!(
                    "receiver: frame {frame} level {} {validity:?}",
                    u32::from_le_bytes(word)
                );
            }
            Err(e) => println!("receiver: frame {frame} level {e:?}"),
        }
        if frame <= 3 {
            match image.receive(&mut long) {
                Ok((validity, msg)) => println!(
                    "receiver: frame {frame} image of {} bytes, intact {} {validity:?}",
                    msg.len(),
                    intact(frame as u8, msg, IMAGE)
                ),
                Err(e) => println!("receiver: frame {frame} image {e:?}"),
            }
        }
        if frame == 1 {
            let zero = || SystemTime::Normal(Duration::ZERO);
            for (k, len) in [(1, BULK), (2, 5000)] {
                match bulk.receive(&mut long, zero()) {
                    Ok((msg, _)) => println!(
                        "receiver: bulk message {k} of {} bytes, intact {}",
                        msg.len(),
                        intact(k, msg, len)
                    ),
                    Err(e) => println!("receiver: bulk message {k}: {e:?}"),
                }
            }
        }
        if frame == 2 {
            // Nothing is queued; the sender sends 20,000 bytes in its next window.
            match bulk.receive(&mut long, SystemTime::Normal(Duration::from_millis(150))) {
                Ok((msg, _)) => println!(
                    "receiver: waited for bulk message 4 of {} bytes, intact {}",
                    msg.len(),
                    intact(4, msg, BULK)
                ),
                Err(e) => println!("receiver: wait for bulk message 4 failed: {e:?}"),
            }
        }
        if frame == 1 {
            let mut got = [0u8; 8];
            let mut n = 0;
            let end = loop {
                match cmd.receive(&mut buf, SystemTime::Normal(Duration::ZERO)) {
                    Ok((msg, _)) if n < got.len() => {
                        got[n] = msg[0];
                        n += 1;
                    }
                    Ok(_) => break Error::InvalidConfig,
                    Err(e) => break e,
                }
            };
            let waited = cmd.receive(&mut buf, SystemTime::Normal(Duration::from_millis(2)));
            println!("receiver: frame 1 got {:?}, then {end:?}", &got[..n]);
            println!("receiver: receive with 2 ms time-out: {:?}", waited.err());
        }
        if frame == 4 {
            // Nothing is queued; the sender sends in its next window, 50 ms from now.
            let start = time();
            match cmd.receive(&mut buf, SystemTime::Normal(Duration::from_millis(150))) {
                Ok((msg, _)) => println!(
                    "receiver: waited across windows for message {} ({} ms)",
                    msg[0],
                    (time() - start).as_millis()
                ),
                Err(e) => println!("receiver: wait across windows failed: {e:?}"),
            }
        }
        if frame >= 6 {
            raise(b"ports done");
        }
        periodic_wait();
    }
}

// ---- apex_health ----

/// The `board` segment: the first (and only) shared segment of the apex_health system.
const BOARD: u64 = SHARED_BASE;

extern "C" fn count() {
    let first = time();
    loop {
        let frame = frame_of(first, FRAME);
        #[allow(unsafe_code)]
        // SAFETY: the configuration maps `board` read-write at SHARED_BASE in this partition.
        unsafe {
            core::ptr::write_volatile(BOARD as *mut u32, frame)
        };
        if frame.is_multiple_of(10) {
            println!("victim: frame {frame}");
        }
        if frame >= 40 {
            raise(b"victim done");
        }
        periodic_wait();
    }
}

extern "C" fn poke() {
    let first = time();
    loop {
        let frame = frame_of(first, FRAME);
        #[allow(unsafe_code)]
        // SAFETY: the configuration maps `board` read-only at SHARED_BASE here: reading is
        // sound; the write below is the fault under test (the kernel stops it).
        let seen = unsafe { core::ptr::read_volatile(BOARD as *const u32) };
        println!("intruder: frame {frame} board reads {seen}");
        if frame == 3 {
            println!("intruder: writing the victim's board");
            #[allow(unsafe_code)]
            // SAFETY: see above: the page is mapped read-only, so this write faults.
            unsafe {
                core::ptr::write_volatile(BOARD as *mut u32, 0xdead)
            };
            println!("intruder: the write went through");
        }
        periodic_wait();
    }
}

extern "C" fn work() {
    let mut job = 0;
    loop {
        job += 1;
        let start = time();
        // Jobs 20..=22 need 3 ms of their 2 ms capacity, the others 1 ms (the overruns come
        // after the restarter's restarts, during which syssw serves nobody else).
        let need = if (20..=22).contains(&job) { 3 } else { 1 };
        spin_until(start + Duration::from_millis(need));
        if job == 25 {
            println!("overrun: job 25 done in time");
        }
        periodic_wait();
    }
}

/// Starts of the restarter since the image was last loaded: in .bss, so a warm restart
/// (memory kept) counts on and a cold restart (image reloaded) starts from 0 again.
static STARTS: AtomicU32 = AtomicU32::new(0);

fn restarter(ctx: &mut StartContext<Warden>) {
    let starts = STARTS.fetch_add(1, Ordering::Relaxed) + 1;
    let status = <Test as PartitionExt<Warden>>::get_status();
    println!(
        "restarter: start {starts} mode={:?} condition={:?}",
        status.operating_mode, status.start_condition
    );
    match (status.operating_mode, status.start_condition) {
        (OperatingMode::ColdStart, StartCondition::NormalStart) => {
            // Fail once NORMAL: the configuration warm-restarts it for that.
            process(ctx, "fail", fail, None, None);
        }
        (OperatingMode::WarmStart, _) => {
            println!("restarter: asking for a cold start");
            let refused = <Test as PartitionExt<Warden>>::set_mode(OperatingMode::ColdStart);
            println!("restarter: SET_PARTITION_MODE(COLD_START) returned {refused:?}");
        }
        _ => println!("restarter: settled"),
    }
}

extern "C" fn fail() {
    raise(b"restart me");
    println!("restarter: still running after the error");
}
