//! Attacks on the kernel for the hardening scenarios. Run as the root task (every ability,
//! all memory and ports), the system-image entry `test/mode` says what it does: `paths`,
//! the longest calls beside a victim thread ([`paths::root_paths`]); otherwise the
//! system-call fuzzer below, then it ends the run with success. syssw starts it as a
//! partition; what it does then depends on the partition's name:
//!
//! * `fuzz*`: the system-call fuzzer: [`CALLS`] calls with random call numbers and random
//!   register arguments drawn from a fixed-seed generator (seed printed, so a failing run
//!   can be replayed), then a histogram of the returned codes per call, `fuzz: done ...`,
//!   and sleeps for ever;
//! * `flood-log*`: writes 512-byte kernel log lines (the longest `debug_write`) as fast as
//!   it can, for ever;
//! * `flood-map*`, `flood-io*`, `flood-kill*`, `kill-loop*`: the longest page-range calls,
//!   I/O-port grants and task kills, and a restart loop of a large task tree
//!   ([`flood_map`], [`paths`]);
//! * `peek*`, `ipc-flood*`, `spin*`: reaching for others' memory, threads and time
//!   ([`reach`]);
//! * `ports*`: at each start reads, then writes, the next of the ports no partition is
//!   granted (the kernel's: COM1, the PICs, the PIT, each port of QEMU's exit device
//!   0xf4-0xf7; and ordinary ones it was not given: keyboard controller, COM2, PCI
//!   configuration): every access must raise #GP (the scenario warm-restarts it, so a
//!   counter in its memory survives), then prints `ports: all <n> accesses faulted` and
//!   sleeps;
//! * `fault-loop*`: executes `ud2` at once at every start (the scenario cold-restarts it:
//!   a restart loop);
//! * `fault-ignore*`: a fault loop the partition survives: it starts one thread after
//!   another that executes `ud2` at once (the scenario maps that illegal request to
//!   `ignore`, so syssw kills only the faulting thread), as fast as it can, and prints
//!   `fault-ignore: <n> threads faulted` every [`FAULTS_REPORT_EVERY`] faults;
//! * `late-fault*`: faults at the very end of each of its windows, [`late_lead`] before
//!   it ends (1 to 30 us, varying): it spins until then, starts a thread that executes
//!   `ud2` or reads kernel memory (alternately; the scenario maps both to `ignore`, so
//!   syssw kills only that thread) and sleeps until its next window;
//!   `late-restart*`: at every start spins until the end of its window is as near, then
//!   executes `ud2` (the scenario cold-restarts it);
//! * `overflow*`: recurses until its stack overflows into the guard page;
//! * `forge*`: sends syssw service requests for ports it does not own (every port id
//!   0..64, read, status, receive, clear) and unknown labels, as fast as it can, and
//!   counts the requests syssw accepted (`forge: <n> requests, <m> accepted`) every
//!   10,000 requests; with each count an error report whose words and text name the
//!   victim and the kernel's fault label, and after [`FORGE_REQUESTS`] a request for IDLE
//!   whose words name the victim (syssw must idle the forger, never the victim);
//! * `hoard*`: exhausts its resource partition's kernel-memory quota: creates child tasks,
//!   threads and mappings of one page at ever new addresses (each in the most page tables)
//!   until the kernel says `QuotaExceeded`, prints `hoard: tasks=<n> threads=<n> maps=<n>,
//!   then QuotaExceeded` and sleeps;
//! * `victim*`: logs its window starts: once per window it reads the clock and compares it
//!   with the window's start (`partition_info`), counts the major frames it saw to find a
//!   missed window and whether the start is the ideal one (the first start plus whole major
//!   frames: `drift`), keeps the lateness in a constant-size histogram (a soak logs 10^6
//!   windows), creates and kills a thread if the window is at least 100 us long (its own
//!   quota is untouched by any hoarder),
//!   prints a summary every [`REPORT_EVERY`] windows, and after [`VICTIM_FRAMES`] windows
//!   (`victim-<n>`: `n` windows) creates and kills a thread once more and executes `ud2`
//!   (the scenario maps that illegal request to `shutdown_success`, ending the run);
//! * `port-victim*`: port traffic through syssw while another partition restarts: it
//!   creates a queuing port pair whose channel leads back into itself and, once per window,
//!   sends a message, receives it back and asks for its partition status (three service
//!   requests), timing each with the clock, and logs the round trip
//!   (`port-victim: round=<n> wait_ns=<longest of the three> send=<ns> receive=<ns>
//!   status=<ns> frame=<n>`); after `n` rounds (`port-victim-<n>`) it prints
//!   `port-victim: done rounds=<n> max_wait_ns=<ns> lost=<n>` (`lost`: rounds whose message
//!   did not come back unchanged or whose request failed) and executes `ud2` (the scenario
//!   maps that to `shutdown_success`).
//!
//! A test program: it must never be needed by anything but its scenarios.
#![no_std]
#![no_main]

mod paths;
mod reach;

use core::fmt::Write;
use core::sync::atomic::{AtomicUsize, Ordering};
use user_rt::abi::boot::KERNEL_BASE;
use user_rt::abi::ipc::MessageTag;
use user_rt::abi::syscall::{
    Abilities, Call, DEBUG_WRITE_MAX, Error, MAP_MAX_PAGES, MAX_MAJOR_FRAME, PageRights,
    ROOT_INFO_BASE, ThreadAttribute, ThreadId, USER_END, USER_MIN, make_id,
};
use user_rt::abi::sysimg::SystemImage;
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::partition::{DATA_BASE, POOL_BASE, SHARED_BASE, StartInfo};
use user_rt::port::outb;
use user_rt::println;
use user_rt::protocol::{Direction, Discipline, OperatingMode, PortKind, Request, ReturnCode};
use user_rt::service;
use user_rt::sys::{self, Message};

user_rt::entry!(main);

/// Calls of one fuzzing run (about 3 s of virtual time under QEMU).
const CALLS: u64 = 1_000_000;
/// The generator's seed (xorshift64*).
const SEED: u64 = 0x5eed_f022_2026_0001;
/// Windows the victim logs before it ends the run.
const VICTIM_FRAMES: u64 = 1_000;
const REPORT_EVERY: u64 = 100;

const PAGE: u64 = 4096;
/// Where a root task's start-up mappings (its information page, the system image, its
/// stack) and a partition's stack lie; the fuzzer never unmaps or protects this range of
/// its own.
const TOP_REGION: core::ops::Range<u64> = ROOT_INFO_BASE..USER_END;

fn main(start: u64, image_len: u64) {
    #[allow(unsafe_code)]
    // SAFETY: syssw starts every partition with the start record's address in rdi.
    let Some(info) = (unsafe { StartInfo::from_start(start) }) else {
        // No start record: the kernel started it as the root task (rdi = system image,
        // rsi = its length); the image's entry `test/mode` says what to do.
        let image = SystemImage::parse(root_task::system_image(start, image_len));
        let mode = image.ok().and_then(|i| i.find("test/mode")).map(|e| e.data);
        if mode == Some(b"paths".as_slice()) {
            paths::root_paths();
        }
        fuzz(CALLS, true, SEED);
        let _ = sys::system_halt(true);
        return;
    };
    let name = info.name();
    if name.starts_with("fuzz") {
        // `fuzz-<n>` draws its own sequence (seed + n), so fuzzers side by side differ.
        let n = name
            .strip_prefix("fuzz-")
            .and_then(|n| n.parse::<u64>().ok());
        fuzz(CALLS, false, SEED.wrapping_add(n.unwrap_or(0)));
        sys::sleep_until(u64::MAX);
    } else if name.starts_with("flood-log") {
        let line = [b'L'; DEBUG_WRITE_MAX as usize];
        loop {
            let _ = sys::debug_write(&line);
        }
    } else if name.starts_with("flood-map") {
        flood_map(info.pool_len);
    } else if name.starts_with("flood-io") {
        paths::flood_io();
    } else if name.starts_with("flood-kill") {
        paths::flood_kill();
    } else if name.starts_with("kill-loop") {
        paths::kill_loop();
    } else if name.starts_with("ports") {
        touch_kernel_ports(ThreadId(info.server));
    } else if name.starts_with("peek") {
        reach::peek(info);
    } else if name.starts_with("ipc-flood") {
        reach::ipc_flood(info);
    } else if name.starts_with("spin") {
        reach::spin(info);
    } else if name.starts_with("fault-loop") {
        #[allow(unsafe_code)]
        // SAFETY: ud2 only raises #UD.
        unsafe {
            core::arch::asm!("ud2")
        };
    } else if name.starts_with("fault-ignore") {
        fault_ignore(info.priority as u8);
    } else if name.starts_with("late-fault") {
        late_fault(info.time_partition, info.priority as u8);
    } else if name.starts_with("late-restart") {
        fault_at_window_end(info.time_partition);
        faulty(0);
    } else if name.starts_with("overflow") {
        println!("overflow: recursing");
        let depth = recurse(0);
        println!("overflow: returned from depth {depth}");
    } else if name.starts_with("forge") {
        forge(ThreadId(info.server));
    } else if name.starts_with("hoard") {
        hoard();
        sys::sleep_until(u64::MAX);
    } else if name.starts_with("port-victim") {
        let rounds = name
            .rsplit('-')
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or(VICTIM_FRAMES);
        port_victim(info, rounds);
    } else if name.starts_with("victim") {
        let windows = name
            .rsplit('-')
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or(VICTIM_FRAMES);
        victim(info.time_partition, windows);
        #[allow(unsafe_code)]
        // SAFETY: ud2 only raises #UD (the scenario's end).
        unsafe {
            core::arch::asm!("ud2")
        };
    } else {
        println!("attack: no role for partition `{name}`");
    }
}

/// Faults between two reports of `fault-ignore`.
const FAULTS_REPORT_EVERY: u64 = 500;

/// The stack of the threads `fault-ignore` starts (they die at their first instruction).
static mut FAULTY_STACK: [u64; 64] = [0; 64];

extern "C" fn faulty(_: u64) -> ! {
    #[allow(unsafe_code)]
    // SAFETY: ud2 only raises #UD.
    unsafe {
        core::arch::asm!("ud2", options(noreturn))
    }
}

/// A thread of `late-fault` that reads the kernel's memory (a memory violation).
extern "C" fn faulty_read(_: u64) -> ! {
    #[allow(unsafe_code)]
    // SAFETY: a read of a kernel address from ring 3 only raises #PF.
    let _ = unsafe { core::ptr::read_volatile(KERNEL_BASE as *const u64) };
    faulty(0)
}

/// How long before the end of its window in major frame `frame` `late-fault` and
/// `late-restart` fault: 1 to 30 us, another lead each frame (7 apart, modulo 30), so that
/// the faults fall on every offset the health monitor's handling could straddle the
/// window's end from.
fn late_lead(frame: u64) -> u64 {
    1_000 + frame.wrapping_mul(7) % 30 * 1_000
}

/// Spins until [`late_lead`] before the end of the current window of time partition `tp`.
fn fault_at_window_end(tp: u64) -> u64 {
    let Ok(info) = sys::partition_info(tp) else {
        println!("late: partition_info failed");
        return 0;
    };
    let end = info.next_window_start + info.window_length;
    let at = end.saturating_sub(late_lead(info.frames));
    while sys::clock() < at {}
    end
}

fn late_fault(tp: u64, priority: u8) -> ! {
    let stack_top = (&raw mut FAULTY_STACK) as u64 + core::mem::size_of::<[u64; 64]>() as u64;
    let mut faults = 0u64;
    loop {
        let end = fault_at_window_end(tp);
        let entry = match faults % 2 {
            0 => faulty as *const () as u64,
            _ => faulty_read as *const () as u64,
        };
        // At its own priority, FIFO behind this thread: it faults when this one yields.
        match sys::thread_create(None, entry, stack_top, priority, 0)
            .and_then(|t| sys::thread_start(t).map(|()| t))
        {
            Ok(_) => faults += 1,
            Err(e) => println!("late-fault: thread_create or start refused: {e:?}"),
        }
        sys::yield_now();
        if faults.is_multiple_of(100) {
            println!("late-fault: {faults} faults at the end of a window");
        }
        // Its next window (a thread of it runs only there).
        sys::sleep_until(end);
    }
}

fn fault_ignore(priority: u8) -> ! {
    let stack_top = (&raw mut FAULTY_STACK) as u64 + core::mem::size_of::<[u64; 64]>() as u64;
    let (mut faulted, mut refused) = (0u64, 0u64);
    loop {
        // At the partition's own priority, FIFO behind this thread: it faults when this
        // one yields, and syssw kills it before the next is created.
        match sys::thread_create(None, faulty as *const () as u64, stack_top, priority, 0)
            .and_then(|t| sys::thread_start(t).map(|()| t))
        {
            Ok(_) => {
                faulted += 1;
                if faulted.is_multiple_of(FAULTS_REPORT_EVERY) {
                    println!("fault-ignore: {faulted} threads faulted ({refused} refused)");
                }
            }
            Err(e) => {
                if refused == 0 {
                    println!("fault-ignore: thread_create or start refused: {e:?}");
                }
                refused += 1;
            }
        }
        sys::yield_now();
    }
}

/// Ports no partition is granted: the kernel's (COM1, the PICs, the PIT, each port of QEMU's
/// exit device) and ordinary ones this partition was not given (keyboard controller, COM2,
/// PCI configuration).
const FORBIDDEN_PORTS: [u16; 12] = [
    0x3f8, 0x3fd, 0x20, 0xa1, 0x40, 0xf4, 0xf5, 0xf6, 0xf7, 0x60, 0x2f8, 0xcf8,
];

/// Accesses `ports` makes, one per start: a read, then a write, of each forbidden port.
const PORT_ACCESSES: usize = 2 * FORBIDDEN_PORTS.len();

/// How many of [`PORT_ACCESSES`] were made (kept across warm restarts).
static PORTS_TOUCHED: AtomicUsize = AtomicUsize::new(0);

fn touch_kernel_ports(server: ThreadId) {
    // NORMAL mode first: only an initialised partition can be restarted warm (ARINC 653).
    let _ = request(
        server,
        Request::SetPartitionMode {
            mode: OperatingMode::Normal,
        },
    );
    let next = PORTS_TOUCHED.fetch_add(1, Ordering::Relaxed);
    if next >= PORT_ACCESSES {
        println!("ports: all {PORT_ACCESSES} accesses faulted");
        sys::sleep_until(u64::MAX);
        return;
    }
    let port = FORBIDDEN_PORTS[next / 2];
    if next.is_multiple_of(2) {
        println!("ports: reading port {port:#x}");
        let value = user_rt::port::inb(port);
        println!("ports: read {value:#x} from port {port:#x}: did not fault");
    } else {
        // A write to the exit device would end the run; to COM1 it would garble the log.
        println!("ports: writing port {port:#x}");
        outb(port, 0x01);
        println!("ports: port {port:#x} did not fault");
    }
}

/// Recursion with a frame the optimiser cannot drop, until the stack runs out.
#[inline(never)]
fn recurse(depth: u64) -> u64 {
    let frame = core::hint::black_box([depth; 64]);
    if depth == u64::MAX {
        return frame[0];
    }
    recurse(depth + 1) + core::hint::black_box(frame[63] & 1)
}

/// The forger's IPC buffer (replies may carry data).
#[repr(C, align(4096))]
struct IpcPage([u8; PAGE as usize]);

static mut IPC_PAGE: IpcPage = IpcPage([0; PAGE as usize]);

/// Sends a request without data to syssw; returns whether it was accepted.
fn request(server: ThreadId, request: Request) -> bool {
    let wire = request.encode();
    let message = Message {
        tag: MessageTag::new(wire.label, 0, 0),
        words: wire.words,
    };
    sys::ipc_call(server, 1_000_000, &message)
        .is_ok_and(|r| r.message.tag.label() == ReturnCode::NoError.code())
}

/// The forger: see the crate documentation.
fn forge(server: ThreadId) {
    let _ = sys::thread_set(None, ThreadAttribute::IpcBuffer, &raw const IPC_PAGE as u64);
    let (mut sent, mut accepted) = (0u64, 0u64);
    let mut rng = Rng(SEED);
    loop {
        let port = rng.below(64);
        let request = match rng.below(6) {
            0 => Request::ReadSampling { port },
            1 => Request::SamplingStatus { port },
            2 => Request::ReceiveQueuing {
                port,
                timeout: 0,
                priority: 0,
            },
            3 => Request::QueuingStatus { port },
            4 => Request::ClearQueuing { port },
            _ => Request::PartitionStatus,
        };
        let mut wire = request.encode();
        if rng.below(8) == 0 {
            // A label no request has.
            wire.label = 0x7000 + rng.below(0x1000) as u32;
        }
        let message = Message {
            tag: MessageTag::new(wire.label, 0, 0),
            words: wire.words,
        };
        let ok = sys::ipc_call(server, 1_000_000, &message)
            .is_ok_and(|r| r.message.tag.label() == ReturnCode::NoError.code());
        sent += 1;
        // PARTITION_STATUS of its own partition is the one request it may make.
        if ok && !matches!(request, Request::PartitionStatus) {
            accepted += 1;
        }
        if sent % 10_000 == 0 {
            println!("forge: {sent} requests, {accepted} accepted");
            forge_report(server);
        }
        if sent == FORGE_REQUESTS {
            forge_idle(server);
        }
    }
}

/// Requests the forger sends before it asks to be IDLE naming the victim.
const FORGE_REQUESTS: u64 = 40_000;

/// An error report whose words and text name the victim (partition 0 of `attack_floods`)
/// and the kernel's fault label: the health monitor must charge it to the forger.
fn forge_report(server: ThreadId) {
    let mut wire = Request::ReportError {
        error: user_rt::protocol::ErrorCode::ApplicationError,
        detail: b"partition=victim-200",
    }
    .encode();
    wire.words[1] = 0;
    wire.words[2] = user_rt::abi::ipc::LABEL_FAULT_REPORT as u64;
    let detail = b"partition=victim-200";
    let page = &raw const IPC_PAGE as u64;
    #[allow(unsafe_code)]
    // SAFETY: IPC_PAGE is this thread's registered IPC buffer (set by `forge`), a page.
    let ipc = unsafe { IpcBufferRef::new(page) };
    ipc.write_data(0, detail);
    let message = Message {
        tag: MessageTag::new(wire.label, detail.len(), 0),
        words: wire.words,
    };
    let ok = sys::ipc_call(server, 1_000_000, &message)
        .is_ok_and(|r| r.message.tag.label() == ReturnCode::NoError.code());
    println!(
        "forge: error report naming the victim: {}",
        if ok { "accepted as its own" } else { "refused" }
    );
}

/// A mode change to IDLE whose words name the victim: syssw must idle the forger itself.
fn forge_idle(server: ThreadId) {
    let mut wire = Request::SetPartitionMode {
        mode: OperatingMode::Idle,
    }
    .encode();
    wire.words[1] = 0;
    wire.words[2] = 0;
    println!("forge: asking for IDLE with words naming the victim");
    let message = Message {
        tag: MessageTag::new(wire.label, 0, 0),
        words: wire.words,
    };
    let _ = sys::ipc_call(server, 1_000_000, &message);
    println!("forge: still running after IDLE");
}

/// The port victim's queuing ports (their channel leads from `out` back to `in`).
const PORT_VICTIM_PORTS: [(Direction, &[u8]); 2] =
    [(Direction::Out, b"out"), (Direction::In, b"in")];

/// The port victim: see the crate documentation.
fn port_victim(info: &StartInfo, rounds: u64) {
    let server = ThreadId(info.server);
    let page = &raw const IPC_PAGE as u64;
    let _ = sys::thread_set(None, ThreadAttribute::IpcBuffer, page);
    #[allow(unsafe_code)]
    // SAFETY: IPC_PAGE is a page-aligned page (more than an IPC buffer) of this task's
    // writable data for good, registered just above, and only ever used through this ref.
    let ipc = unsafe { IpcBufferRef::new(page) };
    let call = |request: &Request| {
        let start = sys::clock();
        let reply = service::request(server, ipc, request);
        let waited = sys::clock().saturating_sub(start);
        let ok = reply.ok().filter(|r| r.label == ReturnCode::NoError.code());
        (waited, ok)
    };
    let mut ports = [0u64; 2];
    for (port, (direction, name)) in ports.iter_mut().zip(PORT_VICTIM_PORTS) {
        let (_, reply) = call(&Request::CreatePort {
            kind: PortKind::Queuing,
            direction,
            discipline: Discipline::Fifo,
            max_message_size: 8,
            refresh_or_depth: 4,
            name,
        });
        let Some(reply) = reply else {
            println!(
                "port-victim: cannot create port {:?}",
                core::str::from_utf8(name)
            );
            return;
        };
        *port = reply.words[0];
    }
    let _ = call(&Request::SetPartitionMode {
        mode: OperatingMode::Normal,
    });
    let (mut max_wait, mut lost) = (0u64, 0u64);
    for round in 1..=rounds {
        let Ok(window) = sys::partition_info(info.time_partition) else {
            println!("port-victim: partition_info failed");
            return;
        };
        let message = round.to_le_bytes();
        let (send, sent) = call(&Request::SendQueuing {
            port: ports[0],
            timeout: 0,
            priority: 0,
            staged: 0,
            message: &message,
        });
        let (receive, received) = call(&Request::ReceiveQueuing {
            port: ports[1],
            timeout: 0,
            priority: 0,
        });
        let mut back = [0u8; 8];
        if received.is_some_and(|r| r.words[0] == back.len() as u64) {
            ipc.read_data(0, &mut back);
        }
        let (status, known) = call(&Request::PartitionStatus);
        if sent.is_none() || known.is_none() || back != message {
            lost += 1;
        }
        let wait = send.max(receive).max(status);
        max_wait = max_wait.max(wait);
        println!(
            "port-victim: round={round} wait_ns={wait} send={send} receive={receive} status={status} frame={}",
            window.frames
        );
        // Ready again at the end of this window: runs at the start of the next one.
        sys::sleep_until(window.next_window_start + window.window_length);
    }
    println!("port-victim: done rounds={rounds} max_wait_ns={max_wait} lost={lost}");
    #[allow(unsafe_code)]
    // SAFETY: ud2 only raises #UD (the scenario's end).
    unsafe {
        core::arch::asm!("ud2")
    };
}

/// The hoarder: see the crate documentation.
fn hoard() {
    let mut counts = [0u64; 3];
    let mut last = [Error::Ok; 3];
    for (kind, (count, error)) in counts.iter_mut().zip(&mut last).enumerate() {
        // Bounded by the quota; the bound only guards against a kernel that never refuses.
        for i in 0..100_000u64 {
            let result = match kind {
                0 => sys::task_create(Abilities::empty(), 1, 0, "h").map(|_| ()),
                1 => sys::thread_create(None, 0x1000, 0x2000, 1, 0).map(|_| ()),
                // One page every 512 GiB: each needs three new page tables.
                _ => sys::map(
                    None,
                    scratch().start,
                    0x0000_0100_0000_0000 + i * (512 << 30),
                    1,
                    PageRights::empty(),
                ),
            };
            match result {
                Ok(()) => *count += 1,
                Err(e) => {
                    *error = e;
                    break;
                }
            }
        }
    }
    println!(
        "hoard: tasks={} threads={} maps={}, then {:?} {:?} {:?}",
        counts[0], counts[1], counts[2], last[0], last[1], last[2]
    );
}

/// The shortest window in which the victim creates a thread besides logging its start.
const OBJECTS_WINDOW_NS: u64 = 100_000;

/// The victim: see the crate documentation. It reports every [`REPORT_EVERY`] windows, or
/// 100 times in all for a long run (a line takes longer than a short window). Its last line
/// is `victim: lateness windows=<n> min=<ns> median=<ns> max=<ns> missed=<n> drift=<n>`
/// (the first window left out: its start includes the partition's start-up; the median
/// within 1/64, `histogram`), which `cargo xtask bench` reads. `drift` counts the window
/// starts the kernel reported off the ideal sequence: the first start plus whole major
/// frames (the frame learnt from the first two windows, one window per frame).
fn victim(tp: u64, windows: u64) {
    println!("victim: thread {:#x}", sys::thread_self().0.0);
    let report_every = REPORT_EVERY.max(windows / 100);
    let mut lateness = histogram::Histogram::new();
    let mut first: Option<(u64, u64)> = None;
    let mut major_frame = None;
    let mut last_frame = None;
    let (mut missed, mut drift, mut max_late, mut sum_late) = (0u64, 0u64, 0u64, 0u64);
    let (mut created, mut refused) = (0u64, 0u64);
    for window in 1..=windows {
        let now = sys::clock();
        let Ok(info) = sys::partition_info(tp) else {
            println!("victim: partition_info failed");
            return;
        };
        let late = now.saturating_sub(info.next_window_start);
        if window > 1 {
            max_late = max_late.max(late);
            sum_late += late;
            lateness.record(late);
        }
        if let Some(last) = last_frame
            && info.frames != last + 1
        {
            missed += info.frames.saturating_sub(last + 1);
        }
        last_frame = Some(info.frames);
        match (first, major_frame) {
            (None, _) => first = Some((info.next_window_start, info.frames)),
            (Some((start, frame)), None) => {
                let frames = info.frames.saturating_sub(frame).max(1);
                major_frame = Some(info.next_window_start.saturating_sub(start) / frames);
            }
            (Some((start, frame)), Some(major)) => {
                let ideal = start + info.frames.saturating_sub(frame) * major;
                if info.next_window_start != ideal {
                    drift += 1;
                }
            }
        }
        if window % report_every == 0 || window == windows {
            println!(
                "victim: windows={window} missed={missed} drift={drift} late_ns max={max_late} mean={} last={late}",
                sum_late / (window - 1).max(1)
            );
        }
        // Objects of its own, whatever a neighbour hoards: a thread each window, if the
        // window is long enough not to let that spill into the next (the soak's is 20 us).
        if info.window_length >= OBJECTS_WINDOW_NS {
            match sys::thread_create(None, 0x1000, 0x2000, 1, 0) {
                Ok(thread) => {
                    created += 1;
                    let _ = sys::thread_kill(thread);
                }
                Err(_) => refused += 1,
            }
        }
        // Ready again at the end of this window: runs at the start of the next one.
        sys::sleep_until(info.next_window_start + info.window_length);
    }
    println!("victim: created {created} threads, {refused} refused");
    if let Some((min, median, max)) = lateness.summary() {
        println!(
            "victim: lateness windows={} min={min} median={median} max={max} missed={missed} drift={drift}",
            lateness.count()
        );
    }
    // Whatever a neighbour hoarded, this partition's own quota is still there.
    match sys::thread_create(None, 0x1000, 0x2000, 1, 0) {
        Ok(thread) => {
            let _ = sys::thread_kill(thread);
            println!("victim: created a thread");
        }
        Err(e) => println!("victim: cannot create a thread: {e:?}"),
    }
    println!("victim: done");
}

/// xorshift64*: small, fast and good enough to cover argument space.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Pages the fuzzer hands the kernel as valid (or formerly valid) user memory; nothing else
/// lives in them, so whatever the calls do to them (unmap, protect, receive into them)
/// cannot hurt the fuzzer itself, which never touches them.
#[repr(C, align(4096))]
struct Scratch([u8; 2 * PAGE as usize]);

// Mutable so that the kernel may write into it (it sits in the writable data segment); the
// program itself only takes its address. Text at the start, then bytes that are never
// UTF-8, so that few `debug_write`s succeed and those print short lines.
static mut SCRATCH: Scratch = Scratch({
    let mut bytes = [0xff; 2 * PAGE as usize];
    let text = b"fuzz text";
    let mut i = 0;
    while i < text.len() {
        bytes[i] = text[i];
        i += 1;
    }
    bytes
});

fn scratch() -> core::ops::Range<u64> {
    let base = &raw const SCRATCH as u64;
    base..base + 2 * PAGE
}

/// Values that sit on the edges the kernel checks: sizes, page boundaries, the ends of
/// user space, kernel and non-canonical addresses, identifiers of own and other objects.
struct Pool {
    values: [u64; 96],
    /// The fixed values come first; ids learnt from successful calls fill a ring after them.
    fixed: usize,
    learnt: usize,
}

impl Pool {
    fn new(own_task: u64, own_thread: u64) -> Self {
        let s = scratch().start;
        let fixed = [
            0,
            1,
            2,
            3,
            7,
            8,
            15,
            16,
            63,
            64,
            255,
            256,
            511,
            512,
            513,
            4095,
            4096,
            4097,
            0x10_0000,
            1 << 32,
            u64::from(u32::MAX),
            i64::MAX as u64,
            u64::MAX,
            u64::MAX - 1,
            USER_MIN,
            USER_END - PAGE,
            USER_END,
            USER_END - 1,
            0xffff_8000_0000_0000,
            KERNEL_BASE,
            KERNEL_BASE + PAGE,
            DATA_BASE,
            SHARED_BASE,
            s,
            s + 1,
            s + 8,
            s + PAGE - 1,
            s + PAGE,
            MAX_MAJOR_FRAME,
            MAX_MAJOR_FRAME + 1,
            own_task,
            own_thread,
            make_id(0, 0),
            make_id(0, 1),
            make_id(1, 1),
            make_id(2, 1),
            make_id(255, 1),
            make_id(256, 1),
            make_id(63, 1),
            make_id(64, 1),
        ];
        let mut values = [0; 96];
        values[..fixed.len()].copy_from_slice(&fixed);
        Pool {
            values,
            fixed: fixed.len(),
            learnt: 0,
        }
    }

    fn pick(&self, rng: &mut Rng) -> u64 {
        let ring = self.values.len() - self.fixed;
        let len = self.fixed + self.learnt.min(ring);
        self.values[rng.below(len as u64) as usize]
    }

    /// Remembers an id a call returned, so later calls can use (and misuse) it.
    fn learn(&mut self, id: u64) {
        let ring = self.values.len() - self.fixed;
        self.values[self.fixed + self.learnt % ring] = id;
        self.learnt += 1;
    }
}

fn argument(rng: &mut Rng, pool: &Pool) -> u64 {
    match rng.below(10) {
        0..=5 => pool.pick(rng),
        6..=8 => rng.next(),
        _ => rng.below(1024),
    }
}

/// What the fuzzer never asks for because it would end or stall the fuzzer itself, not
/// because the kernel could not take it: its own end, killing or suspending itself,
/// unmapping or protecting its own code, data or stack, and long blocking (timeouts are
/// cut to at most 50 us); as the root task also halting the machine, moving itself out of
/// the background and creating threads in its own task (their faults would be the root
/// task's, which halts the machine). Returns false to skip the call.
fn tame(call: u64, a: &mut [u64; 6], me: (u64, u64), root: bool) -> bool {
    let (own_task, own_thread) = me;
    let small_timeout = |t: u64| t % 50_000;
    let own = |task: u64| task == 0 || task == own_task;
    let touches_self = |address: u64, pages: u64| {
        let end = address.saturating_add(pages.min(MAP_MAX_PAGES).saturating_mul(PAGE));
        let scratch = scratch();
        let inside_scratch = address >= scratch.start && end <= scratch.end;
        let image = end > USER_MIN && address < DATA_BASE && !inside_scratch;
        let top = end > TOP_REGION.start && address < TOP_REGION.end;
        image || top
    };
    match Call::from_code(call) {
        Some(Call::ThreadExit) => false,
        Some(Call::SystemHalt) => !root,
        // Reads only: a configuration write as the root task could reprogram the chipset
        // (the root task is trusted with it; the fuzzer would only break the machine).
        Some(Call::PciConfig) => {
            a[2] = 0;
            true
        }
        Some(Call::ThreadCreate) => !(root && own(a[0])),
        Some(Call::ThreadSet) => {
            let itself = a[0] == 0 || a[0] == own_thread;
            !(itself && a[1] == ThreadAttribute::TimePartition.code())
        }
        Some(Call::SleepUntil) => {
            a[0] = sys::clock() + small_timeout(a[0]);
            true
        }
        Some(
            Call::Send
            | Call::Receive
            | Call::Call
            | Call::ReplyWait
            | Call::NotifyWait
            | Call::IrqWait,
        ) => {
            a[1] = small_timeout(a[1]);
            true
        }
        Some(Call::ThreadKill | Call::ThreadSuspend) => a[0] != 0 && a[0] != own_thread,
        Some(Call::Unmap | Call::Protect) => !(own(a[0]) && touches_self(a[1], a[2])),
        _ => true,
    }
}

/// Returned codes per call: `Call::ALL` order, then one row for unknown call numbers.
struct Histogram([[u32; 16]; Call::COUNT + 1]);

impl Histogram {
    fn row(call: u64) -> usize {
        Call::ALL
            .iter()
            .position(|c| c.code() == call)
            .unwrap_or(Call::COUNT)
    }

    fn print(&self) {
        for (row, counts) in self.0.iter().enumerate() {
            let name = Call::ALL.get(row).map_or("(unknown call)", |c| c.name());
            let total: u32 = counts.iter().sum();
            if total == 0 {
                continue;
            }
            let mut line = Line::new();
            let _ = write!(line, "fuzz: {name} n={total}");
            for (code, &n) in counts.iter().enumerate() {
                if n > 0 {
                    let code_name = Error::from_code(code as u64).map_or("?", |e| e.name());
                    let _ = write!(line, " {code_name}={n}");
                }
            }
            line.emit();
        }
    }
}

/// One log line built piecewise (the kernel takes at most 512 bytes per line).
struct Line {
    bytes: [u8; 256],
    len: usize,
}

impl Line {
    fn new() -> Self {
        Line {
            bytes: [0; 256],
            len: 0,
        }
    }

    fn emit(&self) {
        let _ = sys::debug_write(&self.bytes[..self.len]);
    }
}

impl Write for Line {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let n = s.len().min(self.bytes.len() - self.len);
        self.bytes[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

/// The fuzzer: see the crate documentation.
fn fuzz(calls: u64, root: bool, seed: u64) {
    let (thread, task) = sys::thread_self();
    let me = (task.0, thread.0);
    println!(
        "fuzz: {calls} calls as {}, seed {seed:#x}, scratch {:#x}",
        if root { "the root task" } else { "a partition" },
        scratch().start
    );
    let mut rng = Rng(seed);
    // Every call of the ABI is drawn by name (a call the ABI gains reshuffles the sequence
    // of this seed: docs/isolation.md reports the victim's lateness for the current one).
    let named_calls = Call::COUNT;
    let mut pool = Pool::new(task.0, thread.0);
    let mut histogram = Histogram([[0; 16]; Call::COUNT + 1]);
    let (mut done, mut skipped) = (0u64, 0u64);
    while done < calls {
        let call = match rng.below(20) {
            0 => rng.next(),
            1 => rng.below(128),
            _ => Call::ALL[rng.below(named_calls as u64) as usize].code(),
        };
        let mut a = [0u64; 6];
        for slot in &mut a {
            *slot = argument(&mut rng, &pool);
        }
        if !tame(call, &mut a, me, root) {
            skipped += 1;
            continue;
        }
        let (rax, out) = sys::raw6(call, a);
        done += 1;
        let code = (rax as usize).min(15);
        histogram.0[Histogram::row(call)][code] += 1;
        if rax == 0
            && matches!(
                Call::from_code(call),
                Some(Call::TaskCreate | Call::ThreadCreate | Call::RpCreate)
            )
        {
            pool.learn(out.rdi);
        }
        if done % 20_000 == 0 {
            println!("fuzz: {done} calls");
        }
    }
    histogram.print();
    println!("fuzz: done: {done} calls, {skipped} skipped, seed {seed:#x}");
}

/// `flood-map`: the longest page-range calls a partition may make, without pause: map as
/// many pages of its pool as one call takes ([`MAP_MAX_PAGES`]) into a child task, write-
/// protect them, unmap them, again and again (the kernel walks every page of each range).
fn flood_map(pool_len: u64) {
    let pages = (pool_len / PAGE).min(MAP_MAX_PAGES);
    let child = match sys::task_create(Abilities::empty(), 1, 0, "flood-map child") {
        Ok(task) => task,
        Err(e) => {
            println!("flood-map: cannot create a task: {e:?}");
            return;
        }
    };
    const AT: u64 = 0x4000_0000;
    let mut rounds: u64 = 0;
    loop {
        let mapped = sys::map(Some(child), POOL_BASE, AT, pages, PageRights::WRITE);
        let protected = sys::protect(Some(child), AT, pages, PageRights::empty());
        let unmapped = sys::unmap(Some(child), AT, pages);
        if let Err(e) = mapped.and(protected).and(unmapped) {
            println!("flood-map: a call failed: {e:?}");
            return;
        }
        rounds += 1;
        if rounds.is_multiple_of(1000) {
            println!("flood-map: {rounds} rounds of {pages} pages");
        }
    }
}
