//! Two CPUs (mode `smp`, `-smp 2`): each CPU runs the threads put on it, in its own windows
//! of the one major frame; a thread goes only to an online CPU, and moves only while no
//! other CPU runs it; calls to a server on the same and on the other CPU are answered, and
//! a server that follows its callers answers on the caller's CPU; a task killed while the
//! other CPU runs its thread stops there, and that CPU goes on with its other threads; a
//! task's I/O ports work on the other CPU, and once it is killed there a task without
//! ports cannot use them.
//!
//! Schedule (major frame 10 ms): CPU 0: TP1 [0, 5 ms); CPU 1: TP2 [0, 5 ms) and TP3
//! [5, 10 ms). TP1's and TP2's windows overlap in time, which one CPU's windows may not.
//! Threads: a spinner in each of TP1 (CPU 0), TP2 and TP3 (CPU 1), each in a task of its
//! own; a server on CPU 1 (background, above the spinners); the root on CPU 0
//! (background) sleeps while they run and then reads each partition's CPU time.

use crate::check::{expect, expect_eq, expect_err, must};
use crate::child::{BASIC, Lab, MS, WAIT, worker};
use user_rt::abi::syscall::{Error, TIMEOUT_INFINITE, ThreadAttribute, ThreadId, WindowSpec};
use user_rt::println;
use user_rt::sys::{self, Message};

const MAJOR: u64 = 10 * MS;
const HALF: u64 = 5 * MS;
const SPINNER_PRIORITY: u8 = 100;
const SERVER_PRIORITY: u8 = 150;
/// Frames the spinners run while the root measures.
const FRAMES: u64 = 50;
/// Calls to the server on the other CPU.
const CALLS: u64 = 1000;

const R_SPINS: usize = 0;
const R_SERVED: usize = 0;
const R_PORT: usize = 0;
/// COM2's scratch register: what is written there reads back.
const SCRATCH: u16 = 0x2ff;

worker!(
    fn spinner(b, ipc) {
        loop {
            b.add_result(R_SPINS, 1);
            core::hint::spin_loop();
        }
    }
);

worker!(
    /// Answers each call with its first word plus one and, if its second word is 1, the
    /// time partition active on the CPU it answers on (CPU 0's are 0 and 1, CPU 1's 2
    /// and 3).
    fn server(b, ipc) {
        let mut next = sys::receive(None, TIMEOUT_INFINITE);
        loop {
            let Ok(m) = next else {
                b.finish();
                loop {
                    sys::sleep(MAJOR);
                }
            };
            b.add_result(R_SERVED, 1);
            let active = match m.message.words[1] {
                1 => sys::partition_info(0).map_or(u64::MAX, |info| info.active),
                _ => 0,
            };
            let reply = Message::new(1, [m.message.words[0] + 1, active, 0]);
            next = sys::reply_wait(Some(m.sender), TIMEOUT_INFINITE, &reply);
        }
    }
);

worker!(
    /// Writes COM2's scratch register, reads it back, then spins (step 1: done).
    fn port_user(b, ipc) {
        user_rt::port::outb(SCRATCH, 0x5a);
        b.set_result(R_PORT, u64::from(user_rt::port::inb(SCRATCH)));
        b.set_step(1);
        loop {
            core::hint::spin_loop();
        }
    }
);

worker!(
    /// Reads COM2's scratch register without a grant (step 1 before, 2 after: a #GP kills
    /// it in between).
    fn port_thief(b, ipc) {
        b.set_step(1);
        b.set_result(R_PORT, u64::from(user_rt::port::inb(SCRATCH)));
        b.set_step(2);
        loop {
            sys::sleep(MAJOR);
        }
    }
);

fn window(offset: u64, duration: u64, partition: u64, cpu: u64) -> WindowSpec {
    WindowSpec {
        offset,
        duration,
        partition,
        cpu,
    }
}

pub fn run() {
    let mut lab = Lab::new();
    let on_cpu = |w: ThreadId, tp: u64, cpu: u64| {
        must(
            "thread_set TimePartition",
            sys::thread_set(Some(w), ThreadAttribute::TimePartition, tp),
        );
        must(
            "thread_set Cpu",
            sys::thread_set(Some(w), ThreadAttribute::Cpu, cpu),
        );
    };
    let tasks = ["tp1", "tp2", "tp3"].map(|name| lab.task(name, BASIC, SPINNER_PRIORITY));
    let spinners = [0, 1, 2].map(|i| lab.worker(Some(tasks[i]), spinner, SPINNER_PRIORITY, &[]));
    expect_err(
        "thread_set Cpu to a CPU that is not online is InvalidArgument",
        sys::thread_set(Some(spinners[0].id), ThreadAttribute::Cpu, 2),
        Error::InvalidArgument,
    );
    on_cpu(spinners[0].id, 1, 0);
    on_cpu(spinners[1].id, 2, 1);
    on_cpu(spinners[2].id, 3, 1);
    let server_task = lab.task("server", BASIC, SERVER_PRIORITY);
    let server = lab.worker(Some(server_task), server, SERVER_PRIORITY, &[]);
    on_cpu(server.id, 0, 1);

    expect_err(
        "schedule_set with a window on a CPU that is not online is InvalidArgument",
        sys::schedule_set(0, MAJOR, &[window(0, HALF, 1, 2)]),
        Error::InvalidArgument,
    );
    expect_err(
        "schedule_set with overlapping windows on one CPU is InvalidArgument",
        sys::schedule_set(0, MAJOR, &[window(0, HALF, 1, 0), window(0, HALF, 2, 0)]),
        Error::InvalidArgument,
    );
    let windows = [
        window(0, HALF, 1, 0),
        window(0, HALF, 2, 1),
        window(HALF, HALF, 3, 1),
    ];
    must("schedule_set 0", sys::schedule_set(0, MAJOR, &windows));
    must("schedule_switch 0", sys::schedule_switch(0));
    for s in &spinners {
        s.start();
    }
    server.start();
    // Inside TP2's first window, which CPU 1 runs the spinner in.
    sys::sleep(MS);
    expect_err(
        "thread_set Cpu of a thread another CPU runs is NotPermitted",
        sys::thread_set(Some(spinners[1].id), ThreadAttribute::Cpu, 0),
        Error::NotPermitted,
    );

    // Each partition's CPU time over whole frames, while the root sleeps in CPU 0's gaps.
    let cpu_ns = |tp| must("partition_info", sys::partition_info(tp)).cpu_ns;
    let (start, before) = (sys::clock(), [1, 2, 3].map(cpu_ns));
    sys::sleep(FRAMES * MAJOR);
    let (elapsed, after) = (sys::clock() - start, [1, 2, 3].map(cpu_ns));
    let shares: [u64; 3] = core::array::from_fn(|i| (after[i] - before[i]) * 1000 / elapsed);
    let spins = spinners.map(|s| s.block.result(R_SPINS));
    println!(
        "smp: over {} ms, CPU time per mille of TP1 (cpu 0) {}, TP2 (cpu 1) {}, TP3 (cpu 1) {}; spins {spins:?}",
        elapsed / MS,
        shares[0],
        shares[1],
        shares[2]
    );
    expect(
        "each partition got its window's half of the time on its CPU (±10%), TP1 and TP2 at the same time",
        shares.iter().all(|&s| s.abs_diff(500) <= 100),
    );
    expect("every spinner ran", spins.iter().all(|&s| s > 0));

    // Calls from the root (CPU 0) to the server, which waits, so it may move: on the same
    // CPU, then on the other.
    let calls = |what: &str| {
        let (start, mut wrong) = (sys::clock(), 0);
        for n in 0..CALLS {
            let r = sys::ipc_call(server.id, WAIT, &Message::new(1, [n, 0, 0]));
            wrong += u64::from(r.map_or(true, |r| r.message.words[0] != n + 1));
        }
        let per_call = (sys::clock() - start) / CALLS;
        println!("smp: {CALLS} calls to a server on {what}, {per_call} ns per round trip");
        wrong
    };
    let cpu_of_server = |cpu| {
        must(
            "thread_set Cpu of the waiting server",
            sys::thread_set(Some(server.id), ThreadAttribute::Cpu, cpu),
        );
    };
    cpu_of_server(0);
    expect_eq(
        "every call on the same CPU got its answer",
        calls("the same CPU"),
        0,
    );
    cpu_of_server(1);
    expect_eq(
        "every call across CPUs got its answer",
        calls("the other CPU"),
        0,
    );
    expect_eq(
        "the server counted every call",
        server.block.result(R_SERVED),
        2 * CALLS,
    );

    // A server that follows its callers, waiting on CPU 1, answers a call from CPU 0 on
    // CPU 0 (in CPU 0's time).
    must(
        "thread_set FollowsCallers of the server",
        sys::thread_set(Some(server.id), ThreadAttribute::FollowsCallers, 1),
    );
    let mut answered_on = [0u64; 4];
    for n in 0..100 {
        let r = sys::ipc_call(server.id, WAIT, &Message::new(1, [n, 1, 0]));
        let active = r.map_or(u64::MAX, |r| r.message.words[1]);
        answered_on[(active as usize).min(3)] += 1;
    }
    expect_eq(
        "every call was answered on the caller's CPU (CPU 0: TP0 or TP1 active)",
        answered_on[0] + answered_on[1],
        100,
    );
    must(
        "thread_set FollowsCallers 0",
        sys::thread_set(Some(server.id), ThreadAttribute::FollowsCallers, 0),
    );

    // Kill TP2's task while CPU 1 runs its spinner (inside TP2's window).
    let next = must("partition_info 2", sys::partition_info(2)).next_window_start;
    sys::sleep_until(next + MS);
    must("task_kill of TP2's task", sys::task_kill(tasks[1]));
    let stopped = spinners[1].block.result(R_SPINS);
    let tp3 = spinners[2].block.result(R_SPINS);
    sys::sleep(4 * MAJOR);
    expect_eq(
        "the killed spinner ran no more on the other CPU",
        spinners[1].block.result(R_SPINS),
        stopped,
    );
    expect(
        "the other CPU goes on with TP3 after the kill",
        spinners[2].block.result(R_SPINS) > tp3,
    );
    ports_on_the_other_cpu(&mut lab);
    println!("all smp checks passed");
    let _ = sys::system_halt(true);
}

/// A task granted COM2's ports uses them on CPU 1 (its bitmap in CPU 1's TSS) and is killed
/// while it runs there; then a task without ports tries one on CPU 1: it faults.
fn ports_on_the_other_cpu(lab: &mut Lab) {
    let owner = lab.task("ports", BASIC, SERVER_PRIORITY);
    must("io_grant of COM2's ports", sys::io_grant(owner, 0x2f8, 8));
    let user = lab.worker(Some(owner), port_user, SERVER_PRIORITY, &[]);
    let thief_task = lab.task("thief", BASIC, SERVER_PRIORITY);
    let thief = lab.worker(Some(thief_task), port_thief, SERVER_PRIORITY, &[]);
    for w in [user.id, thief.id] {
        must(
            "thread_set Cpu 1",
            sys::thread_set(Some(w), ThreadAttribute::Cpu, 1),
        );
    }
    user.start();
    user.wait_step(1, "the port user on CPU 1 reads its port");
    expect_eq(
        "a task's granted port works on the other CPU",
        user.block.result(R_PORT),
        0x5a,
    );
    sys::sleep(MS);
    must("task_kill of the port user", sys::task_kill(owner));
    thief.start();
    thief.wait_step(1, "the thief on CPU 1 starts");
    sys::sleep(10 * MS);
    expect_eq(
        "a task without ports cannot use those of a task killed on that CPU (#GP)",
        thief.block.step(),
        1,
    );
}
