//! ARINC 653 time partitioning: schedules of windows in a major frame.
//!
//! A schedule is a major frame (ns) and up to [`MAX_WINDOWS`] windows, each an offset and
//! duration inside the frame that belongs to one time partition (1..[`TIME_PARTITIONS`]).
//! Time partition 0 is the background: it never owns a window and is always eligible. The
//! root task installs up to [`MAX_SCHEDULES`] schedules; the first one installed starts at
//! once, a switch to another takes effect at the next major-frame boundary, never mid-frame.
//!
//! [`TimeTable::advance`] is the whole decision: given the time, which partition's window is
//! active and when the next boundary is. It is pure and host-tested against a model.

use crate::sched::TIME_PARTITIONS;
use crate::state::Kernel;
use abi::syscall::MIN_WINDOW;

pub const MAX_WINDOWS: usize = abi::syscall::MAX_WINDOWS as usize;
pub const MAX_SCHEDULES: usize = abi::syscall::MAX_SCHEDULES as usize;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Window {
    pub offset: u64,
    pub duration: u64,
    pub partition: u8,
}

impl Window {
    fn end(&self) -> u64 {
        self.offset + self.duration
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Schedule {
    pub major_frame: u64,
    pub windows: [Window; MAX_WINDOWS],
    pub count: usize,
}

/// Why a schedule was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScheduleError {
    /// Too short or too long a major frame (`MIN_WINDOW..=MAX_MAJOR_FRAME`), a window shorter
    /// than `MIN_WINDOW`, or too many windows.
    Empty,
    /// A window starts before the previous one ends (they must be sorted, disjoint).
    Overlap(usize),
    /// A window ends after the major frame.
    BeyondFrame(usize),
    /// A window for partition 0 (background) or an unknown partition.
    BadPartition(usize),
}

impl Schedule {
    pub fn new(major_frame: u64, windows: &[Window]) -> Result<Self, ScheduleError> {
        let frame_ok = (MIN_WINDOW..=abi::syscall::MAX_MAJOR_FRAME).contains(&major_frame);
        if !frame_ok || windows.len() > MAX_WINDOWS {
            return Err(ScheduleError::Empty);
        }
        let mut previous_end = 0;
        for (i, w) in windows.iter().enumerate() {
            if w.duration < MIN_WINDOW {
                return Err(ScheduleError::Empty);
            }
            if w.partition == 0 || w.partition as usize >= TIME_PARTITIONS {
                return Err(ScheduleError::BadPartition(i));
            }
            if w.offset < previous_end {
                return Err(ScheduleError::Overlap(i));
            }
            if w.offset
                .checked_add(w.duration)
                .is_none_or(|e| e > major_frame)
            {
                return Err(ScheduleError::BeyondFrame(i));
            }
            previous_end = w.end();
        }
        let mut s = Self {
            major_frame,
            windows: [Window::default(); MAX_WINDOWS],
            count: windows.len(),
        };
        s.windows[..windows.len()].copy_from_slice(windows);
        Ok(s)
    }

    fn windows(&self) -> &[Window] {
        &self.windows[..self.count]
    }

    /// The window containing frame position `pos` (if any) and the next boundary after
    /// `pos` (a window start or end, or the frame end), relative to the frame start.
    fn at(&self, pos: u64) -> (Option<usize>, u64) {
        for (i, w) in self.windows().iter().enumerate() {
            if pos < w.offset {
                return (None, w.offset);
            }
            if pos < w.end() {
                return (Some(i), w.end());
            }
        }
        (None, self.major_frame)
    }
}

/// Where the schedule stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Position {
    /// The partition whose window is active (None: a gap, only background runs).
    pub partition: Option<u8>,
    /// Index of the active window in the running schedule.
    pub window: Option<usize>,
    /// Absolute time of the next boundary ([`u64::MAX`] without a schedule).
    pub next_boundary: u64,
    /// Absolute start of the current major frame.
    pub frame_start: u64,
}

pub struct TimeTable {
    schedules: [Option<Schedule>; MAX_SCHEDULES],
    running: Option<usize>,
    pending: Option<usize>,
    frame_start: u64,
    /// Major frames started so far (for tests and statistics).
    pub frames: u64,
    /// Schedule switches performed.
    pub switches: u64,
}

impl Default for TimeTable {
    fn default() -> Self {
        Self::new()
    }
}

impl TimeTable {
    pub const fn new() -> Self {
        Self {
            schedules: [None; MAX_SCHEDULES],
            running: None,
            pending: None,
            frame_start: 0,
            frames: 0,
            switches: 0,
        }
    }

    /// Stores schedule `slot` (replacing an idle one; the running one cannot be replaced).
    pub fn install(&mut self, slot: usize, schedule: Schedule) -> Result<(), ScheduleError> {
        if slot >= MAX_SCHEDULES || self.running == Some(slot) || self.pending == Some(slot) {
            return Err(ScheduleError::Empty);
        }
        self.schedules[slot] = Some(schedule);
        Ok(())
    }

    /// Asks for schedule `slot`: at once if none runs, else from the next frame boundary
    /// (a later request before that boundary replaces this one). The time it takes effect;
    /// None for an empty slot.
    pub fn switch_to(&mut self, slot: usize, now: u64) -> Option<u64> {
        if slot >= MAX_SCHEDULES || self.schedules[slot].is_none() {
            return None;
        }
        let Some(running) = self.running else {
            self.running = Some(slot);
            self.frame_start = now;
            self.frames = 1;
            return Some(now);
        };
        self.advance(now);
        self.pending = Some(slot);
        let major = self.schedules[running].map_or(0, |s| s.major_frame);
        Some(self.frame_start + major)
    }

    pub fn running(&self) -> Option<usize> {
        self.running
    }

    pub fn schedule(&self, slot: usize) -> Option<&Schedule> {
        self.schedules.get(slot)?.as_ref()
    }

    /// Moves to time `now` (never backwards) and reports the position.
    pub fn advance(&mut self, now: u64) -> Position {
        let Some(mut slot) = self.running else {
            return Position {
                partition: None,
                window: None,
                next_boundary: u64::MAX,
                frame_start: now,
            };
        };
        let mut major = self.schedules[slot].expect("running").major_frame;
        if now >= self.frame_start + major {
            // The first boundary passed applies a pending switch; skip whole frames after.
            self.frame_start += major;
            self.frames += 1;
            if let Some(next) = self.pending.take() {
                slot = next;
                self.running = Some(next);
                self.switches += 1;
                major = self.schedules[slot].expect("installed").major_frame;
            }
            if now >= self.frame_start + major {
                let skipped = (now - self.frame_start) / major;
                self.frame_start += skipped * major;
                self.frames += skipped;
            }
        }
        let schedule = self.schedules[slot].as_ref().expect("running");
        let (window, next) = schedule.at(now - self.frame_start);
        Position {
            partition: window.map(|w| schedule.windows[w].partition),
            window,
            next_boundary: self.frame_start + next,
            frame_start: self.frame_start,
        }
    }

    /// Next activation (absolute start) and length of a window of `partition` at or after
    /// `now`, within the running schedule (current window included if it is active now).
    pub fn next_window(&self, partition: u8, now: u64) -> Option<(u64, u64)> {
        let schedule = self.schedules[self.running?].as_ref()?;
        // The table is advanced on every timer event, so `now` is in this frame or the next.
        for frame in 0..2 {
            let base = self.frame_start + frame * schedule.major_frame;
            for w in schedule.windows() {
                if w.partition == partition && base + w.end() > now {
                    return Some((base + w.offset, w.duration));
                }
            }
        }
        None
    }
}

impl Kernel {
    /// A timer event at `now`: time-outs and window boundaries.
    pub fn on_timer(&mut self, now: u64) {
        // The one-shot timer has fired: re-arm it even if it fired a little early (its
        // count is rounded down) and nothing is due yet, or the next event would be missed.
        self.timer_dirty = true;
        if now >= self.next_deadline {
            self.expire_timeouts(now);
        }
        if now >= self.next_boundary {
            self.update_window(now);
        }
    }

    /// Recomputes the active window (after a boundary or a schedule change).
    pub fn update_window(&mut self, now: u64) {
        let position = self.time.advance(now);
        self.active_partition = position.partition;
        self.next_boundary = position.next_boundary;
        self.timer_dirty = true;
    }

    /// When the timer must fire next.
    pub fn next_event(&self) -> u64 {
        self.next_deadline.min(self.next_boundary)
    }

    /// Charges the time since the last call (TSC `now`) to the partition that ran, or idle.
    pub fn account(&mut self, now: u64) {
        let delta = now.saturating_sub(self.last_account);
        self.last_account = now;
        match self.running_partition {
            Some(p) => self.cpu_ticks[p as usize] += delta,
            None => self.idle_ticks += delta,
        }
    }
}

#[cfg(test)]
#[path = "../host-tests/timepart.rs"]
mod tests;
