//! Host tests of the time-partition schedule tables (`kernel/src/timepart.rs`); kept outside `src` so that the
//! ring-0 code budget counts only what runs in ring 0.

use super::*;
use proptest::prelude::*;

/// Test times are in microseconds (windows are at least `MIN_WINDOW`, 10 us, long).
const US: u64 = 1_000;

fn w(offset: u64, duration: u64, partition: u8) -> Window {
    Window {
        offset: offset * US,
        duration: duration * US,
        partition,
        cpu: 0,
    }
}

fn on(cpu: u8, window: Window) -> Window {
    Window { cpu, ..window }
}

#[test]
fn validation_names_the_bad_window() {
    assert_eq!(Schedule::new(0, &[], 1), Err(ScheduleError::Empty));
    assert_eq!(
        Schedule::new(MIN_WINDOW - 1, &[], 1),
        Err(ScheduleError::Empty),
        "a frame shorter than MIN_WINDOW"
    );
    assert!(Schedule::new(MIN_WINDOW, &[], 1).is_ok());
    assert!(Schedule::new(abi::syscall::MAX_MAJOR_FRAME + 1, &[], 1).is_err());
    let short = Window {
        offset: 0,
        duration: MIN_WINDOW - 1,
        partition: 1,
        cpu: 0,
    };
    assert_eq!(
        Schedule::new(100 * US, &[short], 1),
        Err(ScheduleError::Empty),
        "a window shorter than MIN_WINDOW"
    );
    assert_eq!(
        Schedule::new(100 * US, &[w(0, 50, 1), w(40, 10, 2)], 1),
        Err(ScheduleError::Overlap(1))
    );
    assert_eq!(
        Schedule::new(100 * US, &[w(90, 20, 1)], 1),
        Err(ScheduleError::BeyondFrame(0))
    );
    assert_eq!(
        Schedule::new(100 * US, &[w(0, 10, 0)], 1),
        Err(ScheduleError::BadPartition(0))
    );
    assert!(Schedule::new(100 * US, &[w(0, 50, 1), w(50, 50, 2)], 1).is_ok());
}

#[test]
fn each_cpu_has_its_own_windows_in_the_one_frame() {
    // The same partition at the same time on two CPUs, and another window on CPU 1 only.
    let windows = [w(0, 50, 1), on(1, w(0, 50, 1)), on(1, w(50, 30, 2))];
    assert_eq!(
        Schedule::new(100 * US, &windows, 1),
        Err(ScheduleError::BadCpu(1)),
        "a window on a CPU that is not online"
    );
    assert_eq!(
        Schedule::new(
            100 * US,
            &[w(0, 50, 1), on(1, w(0, 50, 1)), on(1, w(40, 30, 2))],
            2
        ),
        Err(ScheduleError::Overlap(2)),
        "windows of one CPU overlap"
    );
    let mut t = TimeTable::new();
    t.install(0, Schedule::new(100 * US, &windows, 2).unwrap())
        .unwrap();
    t.switch_to(0, 0);
    let at = |t: &mut TimeTable, now: u64, cpu| {
        let p = t.advance(now * US, cpu);
        (p.partition, p.next_boundary / US)
    };
    assert_eq!(at(&mut t, 10, 0), (Some(1), 50));
    assert_eq!(at(&mut t, 10, 1), (Some(1), 50));
    assert_eq!(
        at(&mut t, 60, 0),
        (None, 100),
        "CPU 0 has a gap to the frame end"
    );
    assert_eq!(at(&mut t, 60, 1), (Some(2), 80));
    assert_eq!(at(&mut t, 85, 1), (None, 100));
    assert_eq!(
        at(&mut t, 120, 1),
        (Some(1), 150),
        "the next frame on every CPU"
    );
    assert_eq!(at(&mut t, 120, 0), (Some(1), 150));
    assert_eq!(
        t.next_window(2, 120 * US),
        Some((150 * US, 30 * US)),
        "on CPU 1"
    );
}

#[test]
fn windows_gaps_and_boundaries() {
    let mut t = TimeTable::new();
    t.install(
        0,
        Schedule::new(100 * US, &[w(10, 30, 1), w(60, 20, 2)], 1).unwrap(),
    )
    .unwrap();
    assert_eq!(t.switch_to(0, 1000 * US), Some(1000 * US));
    let p = t.advance(1000 * US, 0);
    assert_eq!((p.partition, p.next_boundary), (None, 1010 * US));
    let p = t.advance(1010 * US, 0);
    assert_eq!((p.partition, p.next_boundary), (Some(1), 1040 * US));
    let p = t.advance(1045 * US, 0);
    assert_eq!((p.partition, p.next_boundary), (None, 1060 * US));
    let p = t.advance(1079 * US, 0);
    assert_eq!((p.partition, p.next_boundary), (Some(2), 1080 * US));
    let p = t.advance(1100 * US, 0);
    assert_eq!(
        (p.partition, p.next_boundary, p.frame_start),
        (None, 1110 * US, 1100 * US)
    );
    assert_eq!(t.next_window(2, 1100 * US), Some((1160 * US, 20 * US)));
    assert_eq!(
        t.next_window(1, 1115 * US),
        Some((1110 * US, 30 * US)),
        "active now"
    );
    assert_eq!(
        t.next_window(1, 1141 * US),
        Some((1210 * US, 30 * US)),
        "next frame"
    );
}

#[test]
fn a_switch_waits_for_the_frame_boundary() {
    let mut t = TimeTable::new();
    t.install(0, Schedule::new(100 * US, &[w(0, 100, 1)], 1).unwrap())
        .unwrap();
    t.install(1, Schedule::new(50 * US, &[w(0, 50, 2)], 1).unwrap())
        .unwrap();
    t.switch_to(0, 0);
    t.advance(30 * US, 0);
    assert_eq!(t.switch_to(1, 30 * US), Some(100 * US), "the frame's end");
    assert_eq!(t.switch_to(5, 30 * US), None, "an empty slot");
    assert_eq!(t.advance(99 * US, 0).partition, Some(1), "not mid-frame");
    let p = t.advance(100 * US, 0);
    assert_eq!(
        (p.partition, p.frame_start, p.next_boundary),
        (Some(2), 100 * US, 150 * US)
    );
    assert_eq!(t.switches, 1);
    assert_eq!(
        t.install(1, Schedule::new(10 * US, &[w(0, 10, 3)], 1).unwrap()),
        Err(ScheduleError::Empty)
    );
}

proptest! {
    /// Against a model: the active partition at any time is the one whose window (in
    /// the frame containing that time) contains it; boundaries are never skipped.
    #[test]
    fn matches_a_model(
        raw in proptest::collection::vec((1u64..50_000, 10_000u64..60_000, 1u8..4), 1..6),
        steps in proptest::collection::vec(1u64..200_000, 1..100),
    ) {
        let mut windows = vec![];
        let mut at = 0;
        for (gap, duration, partition) in raw {
            windows.push(Window { offset: at + gap, duration, partition, cpu: 0 });
            at += gap + duration;
        }
        let major = at + 7;
        let s = Schedule::new(major, &windows, 1).unwrap();
        let mut t = TimeTable::new();
        t.install(0, s).unwrap();
        t.switch_to(0, 5);
        let mut now = 5;
        let mut boundary = t.advance(now, 0).next_boundary;
        for step in steps {
            // Never jump past a boundary (the kernel is woken at each one).
            now = (now + step).min(boundary);
            let p = t.advance(now, 0);
            let pos = (now - 5) % major;
            let expected = windows.iter().find(|w| w.offset <= pos && pos < w.end()).map(|w| w.partition);
            prop_assert_eq!(p.partition, expected);
            prop_assert!(p.next_boundary > now);
            boundary = p.next_boundary;
        }
    }
}
