//! Health-monitor work syssw's server leaves for the faulting partition's own window.
//!
//! The server thread runs above every partition in every window, on the CPU of the thread
//! whose message it takes (it follows its callers), so whatever it does for a partition
//! runs in the window that is current on the partition's CPU when the report arrives. A
//! partition that faults (or calls REPORT_ERROR) in the last microseconds of its window
//! would otherwise have its report handled (the health monitor's decision, its line, a
//! restart's quick part) in the next partition's window, which then starts late. So the
//! server handles an error report of a partition with windows at once only while at least
//! [`WORK_NS`] of the partition's window remain ([`fits`]); else it queues the report here
//! and handles it at the start of the partition's next window ([`next_window_after`]) on
//! its CPU (the server moves there first), above every thread of the partition, before any
//! of them runs again.
//!
//! What is not deferred: an action that stops the partition (IDLE, a restart) stops its
//! task at once (`task_stop`, a bounded kernel call), so nothing of it runs on before its
//! bookkeeping; a module shutdown is carried out at once; a background partition's reports
//! (it has no window) are handled at once; so is a restart the restart worker can start at
//! once (`crate::restart`: the server's share is forgetting the task and queueing the job,
//! less than stopping the task; the worker kills it and prints the health line in the
//! partition's windows, above every thread of it).
//! The reporting thread waits for its answer
//! (killed, or REPORT_ERROR answered) until the report is handled; no other thread of the
//! partition waits. When the queue is full ([`DEFERRED_MAX`] reports, one per waiting
//! thread) a report is handled at once as before.
//!
//! This module must never make a system call: the glue (`syssw/src/server.rs`) asks the
//! kernel where the windows are (`partition_info`) and carries out the work.

use crate::health::Detail;
use config::model::{ErrorCode, MAX_PARTITIONS, Window};

/// Reports waiting for their partition's window (each is one thread waiting for its answer).
pub const DEFERRED_MAX: usize = 32;

/// How much of its window must remain for the server to handle a partition's error report
/// at once: more than the longest handling (the decision, the health line, a restart's
/// quick part and the worker's dispatch: about 45 us on virtual time) with a margin.
pub const WORK_NS: u64 = 100_000;

/// How the reporting thread is answered once its report is handled and its partition goes
/// on (`ignore`): a faulting thread is killed, REPORT_ERROR gets NO_ERROR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answer {
    Kill,
    NoError,
}

/// An error report waiting for its partition's window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Report {
    pub partition: usize,
    /// The partition's task when it reported: a report of an instance that is gone by the
    /// time it is handled is dropped (its thread is gone too).
    pub task: u64,
    /// The thread waiting for the answer.
    pub thread: u64,
    pub answer: Answer,
    pub error: ErrorCode,
    pub detail: Detail,
    /// When it was reported (ns since boot): the health record's time.
    pub time: u64,
}

/// The waiting reports in arrival order, and per partition when its next window starts.
#[derive(Clone, Debug)]
pub struct Deferred {
    reports: [Option<Report>; DEFERRED_MAX],
    /// Arrival number of each report (handled in this order per partition).
    order: [u64; DEFERRED_MAX],
    arrivals: u64,
    wake: [u64; MAX_PARTITIONS],
}

impl Default for Deferred {
    fn default() -> Self {
        Self::new()
    }
}

impl Deferred {
    pub const fn new() -> Self {
        Deferred {
            reports: [None; DEFERRED_MAX],
            order: [0; DEFERRED_MAX],
            arrivals: 0,
            wake: [0; MAX_PARTITIONS],
        }
    }

    /// Queues `report` to be handled in its partition's window starting at `window` (ns
    /// since boot). Gives it back when the queue is full (handle it at once).
    pub fn push(&mut self, report: Report, window: u64) -> Result<(), Report> {
        let Some(slot) = self.reports.iter().position(Option::is_none) else {
            return Err(report);
        };
        if report.partition >= MAX_PARTITIONS {
            return Err(report);
        }
        self.reports[slot] = Some(report);
        self.order[slot] = self.arrivals;
        self.arrivals += 1;
        self.wake[report.partition] = window;
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        self.reports.iter().all(Option::is_none)
    }

    /// Whether `partition` has a report waiting (a new one queues behind it).
    pub fn waiting(&self, partition: usize) -> bool {
        self.reports
            .iter()
            .flatten()
            .any(|r| r.partition == partition)
    }

    /// Whether `partition` has reports waiting whose window start has come by `now`.
    pub fn due(&self, partition: usize, now: u64) -> bool {
        self.wake.get(partition).is_some_and(|&w| w <= now) && self.waiting(partition)
    }

    /// Takes `partition`'s oldest report.
    pub fn take(&mut self, partition: usize) -> Option<Report> {
        let slot = (0..DEFERRED_MAX)
            .filter(|&i| self.reports[i].is_some_and(|r| r.partition == partition))
            .min_by_key(|&i| self.order[i])?;
        self.reports[slot].take()
    }

    /// `partition`'s reports wait (again) for its window starting at `window`.
    pub fn wait_until(&mut self, partition: usize, window: u64) {
        if let Some(w) = self.wake.get_mut(partition) {
            *w = window;
        }
    }

    /// The earliest window start a waiting report waits for.
    pub fn next_wake(&self) -> Option<u64> {
        self.reports
            .iter()
            .flatten()
            .map(|r| self.wake[r.partition])
            .min()
    }
}

/// Whether work of [`WORK_NS`] started at `now` ends inside the window `start..start +
/// length`. A window shorter than that takes work only in its first quarter (the work may
/// outlast it: it can never fit, and its own start is the partition's time).
pub fn fits(start: u64, length: u64, now: u64) -> bool {
    let end = start.saturating_add(length);
    let need = WORK_NS.min(length - length / 4);
    start <= now && now.saturating_add(need) <= end
}

/// The start of the window of time partition `tp` on CPU `cpu` that follows its window
/// `start..start + length` in a schedule with these `windows` (of every CPU: only `cpu`'s
/// count) and `major_frame`. If several of its windows could be the current one (same
/// length), the earliest candidate: a wake-up before the window only finds it not started
/// yet (the glue then asks the kernel for the exact start).
pub fn next_window_after(
    windows: &[Window],
    major_frame: u64,
    (tp, cpu): (u8, u8),
    start: u64,
    length: u64,
) -> u64 {
    let own = || {
        windows
            .iter()
            .filter(|w| w.time_partition == tp && w.cpu == cpu)
    };
    let first = own().map(|w| w.offset).min();
    own()
        .filter(|w| w.duration == length && w.offset <= start)
        .filter_map(|current| {
            let frame_start = start - current.offset;
            let later = own()
                .map(|w| w.offset)
                .filter(|&o| o > current.offset)
                .min();
            match later {
                Some(o) => Some(frame_start + o),
                None => Some(frame_start + major_frame + first?),
            }
        })
        .min()
        // Not in this schedule (a switch): the current window's end, where the kernel
        // knows the next.
        .unwrap_or(start.saturating_add(length))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(offset: u64, duration: u64, tp: u8) -> Window {
        Window {
            offset,
            duration,
            time_partition: tp,
            cpu: 0,
        }
    }

    fn report(partition: usize, thread: u64) -> Report {
        Report {
            partition,
            task: 7,
            thread,
            answer: Answer::Kill,
            error: ErrorCode::MemoryViolation,
            detail: Detail::None,
            time: 0,
        }
    }

    #[test]
    fn work_fits_only_with_enough_of_the_window_left() {
        // A 4 ms window from 1 ms.
        assert!(fits(1_000_000, 4_000_000, 1_000_000));
        assert!(fits(1_000_000, 4_000_000, 5_000_000 - WORK_NS));
        assert!(!fits(1_000_000, 4_000_000, 5_000_000 - WORK_NS + 1));
        assert!(!fits(1_000_000, 4_000_000, 999_999), "not started yet");
        assert!(!fits(1_000_000, 4_000_000, 6_000_000), "over");
        // A 20 us window takes work in its first 5 us only.
        assert!(fits(100, 20_000, 5_100));
        assert!(!fits(100, 20_000, 5_101));
    }

    #[test]
    fn the_next_window_follows_the_current_one() {
        let one = [window(0, 1_000_000, 1), window(1_000_000, 4_000_000, 2)];
        // TP2's window at 11 ms (frame from 10 ms): the next at 16 ms.
        assert_eq!(
            next_window_after(&one, 5_000_000, (2, 0), 11_000_000, 4_000_000),
            16_000_000
        );
        // Two windows of TP1 in a frame: from the first to the second, from the second to
        // the next frame's first.
        let two = [
            window(0, 1_000, 1),
            window(1_000, 2_000, 2),
            window(3_000, 5_000, 1),
        ];
        assert_eq!(
            next_window_after(&two, 10_000, (1, 0), 20_000, 1_000),
            23_000
        );
        assert_eq!(
            next_window_after(&two, 10_000, (1, 0), 23_000, 5_000),
            30_000
        );
        // Same lengths: the earlier candidate.
        let same = [window(0, 1_000, 1), window(5_000, 1_000, 1)];
        assert_eq!(
            next_window_after(&same, 10_000, (1, 0), 25_000, 1_000),
            30_000
        );
        // A window the schedule does not have: its end.
        assert_eq!(
            next_window_after(&one, 5_000_000, (3, 0), 7_000, 1_000),
            8_000
        );
    }

    #[test]
    fn only_the_windows_of_its_cpu_follow() {
        // TP1 on CPU 0 at 0 and on CPU 1 at 2 us (overlapping CPU 0's TP2 window), TP1
        // again on CPU 0 at 5 us.
        let on = |cpu, w: Window| Window { cpu, ..w };
        let windows = [
            window(0, 1_000, 1),
            window(1_000, 3_000, 2),
            on(1, window(2_000, 1_000, 1)),
            window(5_000, 1_000, 1),
        ];
        // CPU 0's TP1 window at 20 us: its next is at 25 us, not CPU 1's at 22 us.
        assert_eq!(
            next_window_after(&windows, 10_000, (1, 0), 20_000, 1_000),
            25_000
        );
        // CPU 1's only TP1 window at 22 us: the next frame's, at 32 us.
        assert_eq!(
            next_window_after(&windows, 10_000, (1, 1), 22_000, 1_000),
            32_000
        );
    }

    #[test]
    fn reports_wait_in_order_for_their_window() {
        let mut d = Deferred::new();
        assert!(d.is_empty() && d.next_wake().is_none());
        d.push(report(1, 10), 5_000).unwrap();
        d.push(report(2, 20), 3_000).unwrap();
        d.push(report(1, 11), 5_000).unwrap();
        assert_eq!(d.next_wake(), Some(3_000));
        assert!(d.due(2, 4_000) && !d.due(1, 4_000));
        assert!(d.due(1, 5_000) && d.due(2, 5_000) && !d.due(0, 5_000));
        assert_eq!(d.take(1).map(|r| r.thread), Some(10));
        d.push(report(1, 12), 5_000).unwrap();
        assert_eq!(d.take(1).map(|r| r.thread), Some(11));
        assert_eq!(d.take(1).map(|r| r.thread), Some(12));
        assert!(d.take(1).is_none() && d.waiting(2) && !d.waiting(1));
        d.wait_until(2, 9_000);
        assert_eq!(d.next_wake(), Some(9_000));
        assert!(d.take(2).is_some() && d.is_empty());
    }

    #[test]
    fn a_full_queue_gives_the_report_back() {
        let mut d = Deferred::new();
        for t in 0..DEFERRED_MAX as u64 {
            d.push(report(0, t), 0).unwrap();
        }
        assert_eq!(d.push(report(0, 99), 0), Err(report(0, 99)));
        assert!(d.push(report(MAX_PARTITIONS, 1), 0).is_err());
    }
}
