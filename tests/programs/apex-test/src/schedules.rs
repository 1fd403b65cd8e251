//! Partitions `sched` and `plain` (scenario `apex_schedule_switch`): module schedules
//! through a653rs's `ApexScheduleP2`. Schedule `first` (50 ms frame) gives `sched` the
//! window at 0-10 ms and `plain` 20-30 ms; `second` (40 ms frame) gives `plain` 0-10 ms and
//! `sched` 20-30 ms. `sched` (configured with `schedule_control`) switches to `second` in
//! its first window; the switch must land exactly on the end of that major frame, and its
//! next window must start 20 ms after it. `plain` may not switch.
//!
//! Partition `bench-s` (`cargo xtask bench`, `tests/configs/bench_schedules.toml`, virtual
//! time) times [`SWITCHES`] switches between schedules `a` (its window at 0 ms of 10) and
//! `b` (at 4 ms of 10): each asked early in its window, then a TIMED_WAIT past the window's
//! end, so the process next runs in the first window of the new schedule.
//! `schedule_switch_latency`: from SET_MODULE_SCHEDULE (`a` to `b`) to the process running
//! in `b`'s first window, which the schedules put 14 ms after the start of the window the
//! request came in (the frame's end, then `b`'s 4 ms offset);
//! `schedule_switch_window_lateness`: from the start of the new schedule's first window to
//! the process running in it (both directions): what the switch costs beyond the schedule;
//! `schedule_steady_window_lateness`: the same after the same wait one frame later, with no
//! switch (the comparison).
//!
//! Partitions `switcher`, `warm`, `reborn`, `stopped` and `keeper` (scenario
//! `apex_schedule_actions`): schedule change actions. Schedules `first` and `second` have
//! the same windows (40 ms frame: 0, 5, 10, 20, 30 ms, 5 ms each, in that order);
//! `second`'s `change_actions` warm-start `warm`, cold-start `reborn` and stop `stopped`
//! (idle), `keeper` is left alone. `switcher` switches to `second` in the third frame; the
//! others say how they started (with a count of starts in their memory: a warm start keeps
//! it, a cold one reloads it) and tick once per frame, so the log shows `warm` and `reborn`
//! starting again with PARTITION_RESTART in their first windows under `second`, `stopped`
//! ticking no more and `keeper` ticking on.
//!
//! Every line starts with the partition's name.

use apex::Warden;
use apex::a653rs::bindings::{
    self as b, ApexErrorP4, ApexPartitionP4, ApexScheduleP2, ApexTimeP1, ApexTimeP4,
    ErrorReturnCode,
};
use apex::a653rs::prelude::StartContext;
use apex::codes::apex_name;
use apex::user_rt::{println, sys};

extern crate alloc;
use alloc::vec::Vec;
use core::sync::atomic::{AtomicU32, Ordering};

const MS: i64 = 1_000_000;

fn code<T>(result: Result<T, ErrorReturnCode>) -> Option<ErrorReturnCode> {
    result.err()
}

fn status() -> b::ApexScheduleStatus {
    <Warden as ApexScheduleP2>::get_module_schedule_status().expect("GET_MODULE_SCHEDULE_STATUS")
}

fn schedule_id(name: &str) -> Result<b::ScheduleId, ErrorReturnCode> {
    <Warden as ApexScheduleP2>::get_module_schedule_id(apex_name(name))
}

fn set(id: b::ScheduleId) -> Result<(), ErrorReturnCode> {
    <Warden as ApexScheduleP2>::set_module_schedule(id)
}

fn now() -> u64 {
    <Warden as ApexTimeP4>::get_time() as u64
}

/// The start of the partition's current window (ns since boot), from the kernel's
/// running schedule.
fn window_start() -> u64 {
    let tp = apex::runtime::start_info().time_partition;
    sys::partition_info(tp).map_or(0, |i| i.next_window_start)
}

pub fn create_sched(_ctx: &mut StartContext<Warden>) {
    crate::start_aperiodic("switcher", switcher, 10);
}

pub fn create_plain(_ctx: &mut StartContext<Warden>) {
    crate::start_aperiodic("asker", asker, 10);
}

fn print_status(who: &str, s: &b::ApexScheduleStatus) {
    println!(
        "{who}: status current {} next {} last switch {}",
        s.current_schedule,
        s.next_schedule,
        if s.time_of_last_schedule_switch == 0 {
            "none"
        } else {
            "set"
        }
    );
}

extern "C" fn switcher() {
    print_status("sched", &status());
    let second = schedule_id("second");
    println!(
        "sched: GET_MODULE_SCHEDULE_ID second {:?}, nonesuch {:?}; SET_MODULE_SCHEDULE 7 {:?}",
        second,
        code(schedule_id("nonesuch")),
        code(set(7))
    );
    let second = second.expect("schedule second");
    let frame = window_start();
    let asked = now();
    println!("sched: SET_MODULE_SCHEDULE second {:?}", code(set(second)));
    print_status("sched", &status());
    // Wakes in the next window of `sched`, under `second`.
    let _ = <Warden as ApexTimeP1>::timed_wait(30 * MS);
    let woke = now();
    let s = status();
    print_status("sched", &s);
    let switched = s.time_of_last_schedule_switch as u64;
    println!(
        "sched: asked {} us into its window; the switch came {} us after that window's frame began",
        (asked - frame) / 1000,
        switched.wrapping_sub(frame) / 1000
    );
    println!(
        "sched: its window under second begins {} us after the switch; it ran {} us after it",
        window_start().wrapping_sub(switched) / 1000,
        woke.wrapping_sub(switched) / 1000
    );
    println!("sched: done");
    let _ = <Warden as ApexErrorP4>::raise_application_error(
        b::ErrorCode::ApplicationError,
        b"schedules done",
    );
}

extern "C" fn asker() {
    let first = schedule_id("first");
    println!(
        "plain: GET_MODULE_SCHEDULE_ID first {first:?}; SET_MODULE_SCHEDULE second {:?}, first {:?}",
        code(set(1)),
        code(set(0))
    );
    print_status("plain", &status());
}

/// Switches timed by `bench-s` (half of them `a` to `b`).
const SWITCHES: usize = 200;

pub fn create_bench(_ctx: &mut StartContext<Warden>) {
    crate::start_aperiodic("switches", switches, 10);
}

/// Prints a `bench` line of `samples` (ns).
fn bench_line(metric: &str, samples: &mut [u64]) {
    samples.sort_unstable();
    println!(
        "bench {metric} median={} min={} max={} unit=ns samples={}",
        samples[samples.len() / 2],
        samples[0],
        samples[samples.len() - 1],
        samples.len()
    );
}

extern "C" fn switches() {
    let ids = [
        schedule_id("a").expect("schedule a"),
        schedule_id("b").expect("schedule b"),
    ];
    let mut latency = Vec::with_capacity(SWITCHES / 2);
    let mut lateness = Vec::with_capacity(SWITCHES);
    let mut steady = Vec::with_capacity(SWITCHES);
    // Begin at the start of a window of `a`.
    let _ = <Warden as ApexTimeP1>::timed_wait(3 * MS);
    for i in 0..SWITCHES {
        let target = ids[(i + 1) % 2];
        let asked = now();
        set(target).expect("SET_MODULE_SCHEDULE");
        // Past this window's end (2 ms long): the next run is in the new schedule.
        let _ = <Warden as ApexTimeP1>::timed_wait(3 * MS);
        let ran = now();
        let s = status();
        assert_eq!(s.current_schedule, target, "the switch happened");
        let start = window_start();
        if target == ids[1] {
            latency.push(ran - asked);
        }
        lateness.push(ran.wrapping_sub(start));
        // The same wait and window entry without a switch, for comparison.
        let _ = <Warden as ApexTimeP1>::timed_wait(3 * MS);
        steady.push(now().wrapping_sub(window_start()));
    }
    bench_line("schedule_switch_latency", &mut latency);
    bench_line("schedule_switch_window_lateness", &mut lateness);
    bench_line("schedule_steady_window_lateness", &mut steady);
    let _ = <Warden as ApexErrorP4>::raise_application_error(
        b::ErrorCode::ApplicationError,
        b"bench done",
    );
}

/// Frames `keeper` and `stopped` tick for (the run ends in the seventh).
const TICKS: u32 = 8;

/// Starts of this partition's program while its memory was kept.
static STARTS: AtomicU32 = AtomicU32::new(0);

pub fn create_actions(_ctx: &mut StartContext<Warden>) {
    let info = apex::runtime::start_info();
    let name = info.name();
    let status = <Warden as ApexPartitionP4>::get_partition_status();
    println!(
        "{name}: start {} mode={:?} condition={:?} at t={} ms",
        STARTS.fetch_add(1, Ordering::Relaxed) + 1,
        status.operating_mode,
        status.start_condition,
        now() / MS as u64
    );
    match name {
        "switcher" => crate::start_aperiodic("switch", switch_in_third_frame, 10),
        _ => crate::start_aperiodic("tick", tick_each_frame, 10),
    }
}

extern "C" fn switch_in_third_frame() {
    let _ = <Warden as ApexTimeP1>::timed_wait(80 * MS);
    let second = schedule_id("second").expect("schedule second");
    println!(
        "switcher: SET_MODULE_SCHEDULE second {:?} at t={} ms",
        code(set(second)),
        now() / MS as u64
    );
    // Four frames of `second`.
    let _ = <Warden as ApexTimeP1>::timed_wait(190 * MS);
    let s = status();
    println!(
        "switcher: current {} last switch at t={} ms; done",
        s.current_schedule,
        s.time_of_last_schedule_switch / MS
    );
    let _ = <Warden as ApexErrorP4>::raise_application_error(
        b::ErrorCode::ApplicationError,
        b"schedule actions done",
    );
}

extern "C" fn tick_each_frame() {
    let info = apex::runtime::start_info();
    let name = info.name();
    for _ in 0..TICKS {
        println!("{name}: tick at t={} ms", now() / MS as u64);
        let _ = <Warden as ApexTimeP1>::timed_wait(40 * MS);
    }
}
