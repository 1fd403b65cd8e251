//! Measuring time windows from inside a partition: how late the first instruction of a
//! window runs after the instant the schedule says the window starts. Used by the
//! time-partitioning tests and `cargo xtask bench` (window_switch, window_jitter).

use core::sync::atomic::{AtomicU64, Ordering};
use user_rt::sys::{self, TscBase, rdtsc};

/// What [`measure_window_starts`] saw besides the samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WindowStarts {
    /// Window starts recorded (= samples written).
    pub count: u64,
    /// Times the thread was seen running outside its window (before the start it was
    /// told), and the longest such time before the start (ns).
    pub outside: u64,
    pub outside_max: u64,
    /// Times two recorded starts were not one major frame apart (a window was lost).
    pub missed: u64,
    /// Distance between the two starts of the last lost window (for diagnosis).
    pub missed_gap: u64,
    /// Pauses inside a window (the host or a higher-priority thread), not recorded.
    pub pauses: u64,
}

/// Spins in the windows of time partition `tp` (the caller's) and, for each of the next
/// `samples.len()` window starts, stores the lateness in TSC ticks of the first
/// instruction it ran after being switched in. A pause longer than `gap_ns` means the
/// thread was switched out; the thread must have the CPU to itself in its windows (no
/// higher-priority TP0 thread waking up); pauses inside a window are counted, not
/// recorded.
pub fn measure_window_starts(
    tp: u64,
    major_frame_ns: u64,
    gap_ns: u64,
    samples: &[AtomicU64],
) -> WindowStarts {
    let base = TscBase::get();
    let gap = base.tsc_at(gap_ns) - base.at_boot;
    let mut seen = WindowStarts::default();
    let mut last_start = None;
    let mut previous = rdtsc();
    while (seen.count as usize) < samples.len() {
        let now = rdtsc();
        if now.wrapping_sub(previous) > gap {
            // Switched in again: the window now active is ours (asked after `now`; if the
            // question itself was interrupted by a switch, the answer is for a later
            // window than `now`, so only its start is kept).
            let start = sys::partition_info(tp).map_or(u64::MAX, |i| i.next_window_start);
            let after = rdtsc();
            previous = after;
            let at = base.tsc_at(start);
            if now < at {
                // Not a start: the thread ran outside its window, seen here because
                // something paused it just before. Normally it ran on briefly past its
                // previous window's end, whose timer interrupt was still on its way.
                seen.outside += 1;
                seen.outside_max = seen.outside_max.max(base.ns(at - now));
                continue;
            }
            if last_start == Some(start) {
                seen.pauses += 1;
                continue;
            }
            if let Some(last) = last_start
                && start != last + major_frame_ns
            {
                seen.missed += 1;
                seen.missed_gap = start.wrapping_sub(last);
            }
            last_start = Some(start);
            if after.wrapping_sub(now) > gap {
                seen.pauses += 1;
                continue;
            }
            samples[seen.count as usize].store(now.saturating_sub(at), Ordering::Relaxed);
            seen.count += 1;
        } else {
            previous = now;
        }
    }
    seen
}
