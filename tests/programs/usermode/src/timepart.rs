//! Time partitions (mode `windows`): window starts are punctual while another partition
//! spins, TP0 gets exactly the leftover time, MCP keeps a background thread below a
//! window's thread, and a schedule switch waits for the major-frame boundary.
//!
//! Schedule 0 (major frame 4 ms): TP1 [0, 1.5 ms), TP2 [2, 3 ms); gaps [1.5, 2) and
//! [3, 4) belong to TP0. Threads:
//! * `spinner` (task A, TP1, priority 100): spins through its windows (phase 1), or works
//!   1 ms per window and sleeps until the next (phase 2);
//! * `meter` (task B, TP2, priority 100): records the lateness of its window starts;
//! * `background` (task C, MCP 50, TP0): tries to raise itself above its MCP, then spins,
//!   counting every moment it runs inside a window it should not get;
//! * the root (TP0, priority 200) sleeps through each phase and reads the results.
//!
//! All times are ns since boot unless the name says ticks.

use crate::check::{expect, expect_eq, expect_err, fail, must};
use crate::child::{BASIC, Block, Lab, MS, worker};
use core::sync::atomic::{AtomicU64, Ordering};
use root_task::spawn::words_at;
use test_support::window::measure_window_starts;
use user_rt::abi::syscall::{Error, ThreadAttribute, ThreadId, WindowSpec};
use user_rt::println;
use user_rt::sys::{self, TscBase};

const US: u64 = 1000;
const MAJOR: u64 = 4 * MS;
const TP1_WINDOW: (u64, u64) = (0, 1500 * US);
const TP2_WINDOW: (u64, u64) = (2 * MS, MS);
/// Window starts the meter records (the issue asks for at least 1,000 frames).
const FRAMES: usize = 1000;
/// Phase 2 length in frames.
const IDLE_FRAMES: u64 = 250;
/// Work of the spinner per window in phase 2.
const BUSY: u64 = MS;
const SPINNER_PRIORITY: u8 = 100;
const BACKGROUND_MCP: u8 = 50;

/// Bound on window-start lateness (see `check_lateness` for why).
const LATE_MEDIAN_BOUND: u64 = 100 * US;
const LATE_P99_BOUND: u64 = 500 * US;
/// Slack for the background thread near window edges: the edge's own lateness (above the
/// 99th percentile seen under TCG).
const EDGE: u64 = 250 * US;
/// Frames in which the background thread may run inside a busy window: when the host
/// starves QEMU's timer thread, the timer interrupt that starts the window comes late and
/// the thread runs on; a kernel that let it preempt a window's thread would do so in
/// every frame.
const VIOLATIONS_BOUND: u64 = FRAMES as u64 / 50;
/// Frames in which the meter may run outside its window, or lose one (same cause).
const OUTSIDE_BOUND: u64 = FRAMES as u64 / 50;

// Block words of the workers.
const A_MODE: usize = 0; // spinner: 1 = spin, 2 = work BUSY then sleep
const R_LAST_RUN: usize = 0; // spinner: last time it ran
const R_WORKED: usize = 1; // spinner, phase 2: ns it ran (wake-up to sleep), summed
const A_FRAME0: usize = 0; // background: a TP1 window start (a frame start)
const A_BUSY1: usize = 1; // background: end of TP1's busy part within the frame
const A_BUSY2: usize = 2; // background: 0 = TP2's window is busy, 1 = idle
const R_MCP: usize = 0; // background: thread_set(Priority, 250) outcome
const R_VIOLATIONS: usize = 1; // background: frames it ran inside a busy window part
const R_WORST: usize = 2; // background: phase of the last violation
const R_SAMPLES: usize = 3;
const A_SAMPLES: usize = 0; // meter: address of FRAMES words
const A_STOP: usize = 1; // meter: stop spinning
const R_COUNT: usize = 0;
const R_OUTSIDE: usize = 1;
const R_MISSED: usize = 2;
const R_PAUSES: usize = 3;
const R_MISSED_GAP: usize = 4;
const R_OUTSIDE_MAX: usize = 5;
const R_FIRST_RUN: usize = 0; // late: first time it ran

worker!(
    fn spinner(b, ipc) {
        let base = TscBase::get();
        loop {
            let now = base.now_ns();
            b.set_result(R_LAST_RUN, now);
            if b.arg(A_MODE) == 2 {
                // BUSY of CPU time from when it runs, however late its window started; the
                // time it ran is recorded, so the root knows what TP1 used.
                let start = sys::partition_info(1).map_or(now, |i| i.next_window_start);
                while base.now_ns() < now + BUSY {}
                b.add_result(R_WORKED, base.now_ns() - now);
                sys::sleep_until(start + MAJOR);
            }
        }
    }
);

worker!(
    fn meter(b, ipc) {
        // SAFETY: the root passes FRAMES words it mapped for this worker.
        let samples = unsafe { words_at(b.arg(A_SAMPLES), FRAMES) };
        let seen = measure_window_starts(2, MAJOR, 50 * US, samples);
        b.set_result(R_COUNT, seen.count);
        b.set_result(R_OUTSIDE, seen.outside);
        b.set_result(R_OUTSIDE_MAX, seen.outside_max);
        b.set_result(R_MISSED, seen.missed);
        b.set_result(R_PAUSES, seen.pauses);
        b.set_result(R_MISSED_GAP, seen.missed_gap);
        b.set_step(1);
        // Keep TP2's window busy until the root has looked at the background thread.
        while b.arg(A_STOP) == 0 {}
    }
);

worker!(
    fn background(b, ipc) {
        let raised = sys::thread_set(None, ThreadAttribute::Priority, 250);
        b.set_code(R_MCP, &raised);
        let base = TscBase::get();
        let inside = |phase: u64, (from, to): (u64, u64)| phase >= from + EDGE && phase + EDGE < to;
        let mut last_violation = u64::MAX;
        loop {
            let now = base.now_ns();
            let frame0 = b.arg(A_FRAME0);
            if frame0 != 0 && now > frame0 {
                let phase = (now - frame0) % MAJOR;
                let busy1 = (TP1_WINDOW.0, b.arg(A_BUSY1));
                let tp2_busy = b.arg(A_BUSY2) == 0 && inside(phase, (TP2_WINDOW.0, TP2_WINDOW.0 + TP2_WINDOW.1));
                let frame = (now - frame0) / MAJOR;
                if (inside(phase, busy1) || tp2_busy) && frame != last_violation {
                    last_violation = frame;
                    b.add_result(R_VIOLATIONS, 1);
                    b.set_result(R_WORST, phase);
                }
                b.add_result(R_SAMPLES, 1);
            }
        }
    }
);

worker!(
    fn late(b, ipc) {
        b.set_result(R_FIRST_RUN, TscBase::get().now_ns());
        loop {
            let _ = sys::notify_wait(0, user_rt::abi::syscall::TIMEOUT_INFINITE);
        }
    }
);

/// CPU time of TP0..TP2, idle time and the clock, from `partition_info`.
#[derive(Clone, Copy)]
struct Usage {
    cpu: [u64; 3],
    idle: u64,
    at: u64,
    /// What the spinner says it ran (phase 2).
    worked: u64,
}

fn usage(spinner: &Block) -> Usage {
    let info = |tp| must("partition_info", sys::partition_info(tp));
    Usage {
        cpu: [info(0).cpu_ns, info(1).cpu_ns, info(2).cpu_ns],
        idle: info(0).idle_ns,
        at: sys::clock(),
        worked: spinner.result(R_WORKED),
    }
}

/// Checks each partition's share of the time since `from` (per mille, ±30); `want` gets the
/// share the spinner says it ran and returns the expected TP0..TP2 and idle shares.
fn check_shares(what: &str, spinner: &Block, from: Usage, want: impl Fn(u64) -> ([u64; 3], u64)) {
    let to = usage(spinner);
    let elapsed = to.at - from.at;
    let share = |a: u64, b: u64| (b - a) * 1000 / elapsed;
    let (want, want_idle) = want(share(from.worked, to.worked));
    let got = [
        share(from.cpu[0], to.cpu[0]),
        share(from.cpu[1], to.cpu[1]),
        share(from.cpu[2], to.cpu[2]),
    ];
    let idle = share(from.idle, to.idle);
    println!(
        "{what}: CPU share per mille over {} ms: TP0 {} TP1 {} TP2 {} idle {}",
        elapsed / MS,
        got[0],
        got[1],
        got[2],
        idle
    );
    let close = |g: u64, w: u64| g.abs_diff(w) <= 30;
    if !(got.iter().zip(want).all(|(&g, w)| close(g, w)) && close(idle, want_idle)) {
        fail(
            what,
            format_args!(": shares {got:?} idle {idle}, expected {want:?} idle {want_idle} (±30)"),
        );
    }
    println!("check ok: {what}");
}

/// Window-start lateness under TCG: the LAPIC timer is emulated on the host's clock and
/// QEMU notices it between translated blocks, so a few tens of µs are normal; the host
/// itself may deschedule QEMU now and then (a shared machine), which no kernel can hide.
/// So the median must stay below 100 µs (a kernel that let TP1's spinning thread delay
/// the switch would be late by up to TP1's 1.5 ms) and 99% below 500 µs; early or lost
/// windows are bounded separately.
fn check_lateness(samples: &[AtomicU64], base: &TscBase) {
    let mut ns = [0u64; FRAMES];
    for (n, s) in ns.iter_mut().zip(samples) {
        *n = base.ns(s.load(Ordering::Relaxed));
    }
    ns.sort_unstable();
    let (median, p99, max) = (ns[FRAMES / 2], ns[FRAMES * 99 / 100], ns[FRAMES - 1]);
    println!(
        "window-start lateness of TP2 over {FRAMES} frames while TP1 spins: median {} us, p99 {} us, min {} us, max {} us",
        median / US,
        p99 / US,
        ns[0] / US,
        max / US
    );
    expect(
        "TP2's window starts are punctual while TP1 spins (median < 100 us, p99 < 500 us)",
        median < LATE_MEDIAN_BOUND && p99 < LATE_P99_BOUND,
    );
}

pub fn run() {
    let mut lab = Lab::new();
    let base = TscBase::get();
    let task_a = lab.task("tp1", BASIC, SPINNER_PRIORITY);
    let task_b = lab.task("tp2", BASIC, SPINNER_PRIORITY);
    let task_c = lab.task("tp0", BASIC, BACKGROUND_MCP);
    let samples_at = lab.shared(Some(task_b), (FRAMES as u64 * 8).div_ceil(4096));
    let spin = lab.worker(Some(task_a), spinner, SPINNER_PRIORITY, &[1]);
    let meter = lab.worker(Some(task_b), meter, SPINNER_PRIORITY, &[samples_at, 0]);
    let back = lab.worker(
        Some(task_c),
        background,
        BACKGROUND_MCP,
        &[0, TP1_WINDOW.1, 0],
    );
    let in_tp = |w: ThreadId, tp: u64| {
        must(
            "thread_set TimePartition",
            sys::thread_set(Some(w), ThreadAttribute::TimePartition, tp),
        );
    };
    in_tp(spin.id, 1);
    in_tp(meter.id, 2);

    let window = |(offset, duration): (u64, u64), partition| WindowSpec {
        offset,
        duration,
        partition,
        cpu: 0,
    };
    expect_err(
        "schedule_set with overlapping windows is InvalidArgument",
        sys::schedule_set(0, MAJOR, &[window((0, 2 * MS), 1), window((MS, MS), 2)]),
        Error::InvalidArgument,
    );
    expect_err(
        "schedule_set with a window for TP0 is InvalidArgument",
        sys::schedule_set(0, MAJOR, &[window(TP1_WINDOW, 0)]),
        Error::InvalidArgument,
    );
    must(
        "schedule_set 0",
        sys::schedule_set(0, MAJOR, &[window(TP1_WINDOW, 1), window(TP2_WINDOW, 2)]),
    );
    must("schedule_switch 0", sys::schedule_switch(0));
    let frame0 = must("partition_info 1", sys::partition_info(1)).next_window_start;
    back.block.set_arg(A_FRAME0, frame0);
    spin.start();
    back.start();
    meter.start();

    // Phase 1: TP1 spins through its windows, TP2 measures, TP0 spins in the gaps.
    let phase1 = usage(&spin.block);
    sys::sleep(FRAMES as u64 * MAJOR + 20 * MS);
    meter.wait_step(1, "the meter records its window starts");
    // SAFETY: FRAMES words mapped writable in the root by `lab.shared`.
    check_lateness(unsafe { words_at(samples_at, FRAMES) }, &base);
    // A late timer delays a window's start and its end alike: windows move, they do not
    // shrink, so the shares stay those of the schedule.
    check_shares(
        "TP0 gets exactly the gaps while TP1 and TP2 use their windows",
        &spin.block,
        phase1,
        |_| ([375, 375, 250], 0),
    );
    let b = &meter.block;
    expect_eq(
        "every frame's TP2 window was recorded",
        b.result(R_COUNT),
        FRAMES as u64,
    );
    println!(
        "meter: {} pauses inside windows; {} runs outside the window (at most {} us before its start); {} windows lost (last gap {} us)",
        b.result(R_PAUSES),
        b.result(R_OUTSIDE),
        b.result(R_OUTSIDE_MAX) / US,
        b.result(R_MISSED),
        b.result(R_MISSED_GAP) / US
    );
    expect(
        "TP2 ran outside its window in at most 2% of the frames (timer interrupts late on a loaded host)",
        b.result(R_OUTSIDE) <= OUTSIDE_BOUND,
    );
    expect(
        "at most 2% of TP2's windows were lost (to host stalls longer than a window)",
        b.result(R_MISSED) <= OUTSIDE_BOUND,
    );
    expect_err(
        "a TP0 thread cannot raise itself above its MCP",
        sys::status(back.block.result(R_MCP)),
        Error::McpExceeded,
    );
    let bg = &back.block;
    expect(
        "the background thread ran (in the gaps)",
        bg.result(R_SAMPLES) > 0,
    );
    let violations = bg.result(R_VIOLATIONS);
    println!(
        "background: {} samples; ran inside a busy window in {violations} frames (last at phase {} us)",
        bg.result(R_SAMPLES),
        bg.result(R_WORST) / US
    );
    expect(
        "the background thread at its MCP never ran inside TP1's or TP2's busy windows",
        violations <= VIOLATIONS_BOUND,
    );

    // Phase 2: TP1 works 1 ms per window, TP2 has nobody: TP0 gets all the rest.
    bg.set_arg(A_BUSY1, BUSY);
    bg.set_arg(A_BUSY2, 1);
    meter.block.set_arg(A_STOP, 1);
    spin.block.set_arg(A_MODE, 2);
    sys::sleep(2 * MAJOR);
    let phase2 = usage(&spin.block);
    sys::sleep(IDLE_FRAMES * MAJOR);
    check_shares(
        "TP0 gets the idle part of TP1's window, TP2's unused window and the gaps",
        &spin.block,
        phase2,
        // TP1 works 1 ms of each 4 ms frame (250 per mille) plus its calls.
        |tp1| ([1000 - tp1, tp1, 0], 0),
    );
    expect(
        "the background thread never ran in TP1's busy part",
        bg.result(R_VIOLATIONS) - violations <= VIOLATIONS_BOUND,
    );
    must(
        "thread_suspend of the background thread",
        sys::thread_suspend(back.id),
    );
    let phase2b = usage(&spin.block);
    sys::sleep(IDLE_FRAMES * MAJOR);
    check_shares(
        "with TP0 idle too, the unused time is idle time, not given to TP1",
        &spin.block,
        phase2b,
        |tp1| ([0, tp1, 0], 1000 - tp1),
    );

    schedule_switch(&mut lab, &spin, frame0, task_b);
    println!("all windows checks passed");
    let _ = sys::system_halt(true);
}

/// Schedule 1 (major 3 ms, TP3 [0.5, 1.5 ms)), requested in the middle of a frame of
/// schedule 0, starts exactly at that frame's end.
fn schedule_switch(
    lab: &mut Lab,
    spin: &crate::child::Worker,
    frame0: u64,
    task: user_rt::abi::syscall::TaskId,
) {
    const OFFSET: u64 = 500 * US;
    must(
        "schedule_set 1",
        sys::schedule_set(
            1,
            3 * MS,
            &[WindowSpec {
                offset: OFFSET,
                duration: MS,
                partition: 3,
                cpu: 0,
            }],
        ),
    );
    expect_err(
        "schedule_set of the running schedule's slot is NotPermitted",
        sys::schedule_set(
            0,
            MAJOR,
            &[WindowSpec {
                offset: 0,
                duration: MS,
                partition: 1,
                cpu: 0,
            }],
        ),
        Error::NotPermitted,
    );
    let w = lab.worker(Some(task), late, SPINNER_PRIORITY, &[]);
    must(
        "thread_set TimePartition 3",
        sys::thread_set(Some(w.id), ThreadAttribute::TimePartition, 3),
    );
    w.start();
    // The middle of TP2's window, two frames from now.
    let k = (sys::clock() - frame0) / MAJOR + 2;
    let boundary = frame0 + (k + 1) * MAJOR;
    sys::sleep_until(frame0 + k * MAJOR + 2500 * US);
    must("schedule_switch 1", sys::schedule_switch(1));
    let requested = sys::clock();
    if requested >= boundary - MS {
        fail(
            "schedule switch setup",
            format_args!(": requested at {requested}, too close to the boundary {boundary}"),
        );
    }
    sys::sleep(10 * MS);
    let first = w.block.result(R_FIRST_RUN);
    let last_tp1 = spin.block.result(R_LAST_RUN);
    println!(
        "schedule switch requested {} us before the boundary; TP3 first ran {} us after boundary + offset",
        (boundary - requested) / US,
        first.saturating_sub(boundary + OFFSET) / US
    );
    expect(
        "TP3 (schedule 1) first runs at the frame boundary plus its window offset, not before",
        first >= boundary + OFFSET && first < boundary + OFFSET + LATE_P99_BOUND,
    );
    expect(
        "TP1 ran in the frame the switch was requested in, and not after its end",
        last_tp1 >= boundary - MAJOR && last_tp1 < boundary,
    );
    expect_eq(
        "partition_info reports TP3's window of the new schedule",
        must("partition_info 3", sys::partition_info(3)).window_length,
        MS,
    );
}
