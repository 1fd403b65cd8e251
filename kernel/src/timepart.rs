//! ARINC 653 time partitioning: schedules of windows in a major frame.
//!
//! A schedule is a major frame (ns) and up to [`MAX_WINDOWS`] windows, each an offset and
//! duration inside the frame on one CPU that belongs to one time partition
//! (1..[`TIME_PARTITIONS`]). Every CPU has its own windows in the one frame, which starts
//! at the same instant on all of them; the windows of one CPU are disjoint, those of
//! different CPUs may overlap.
//! Time partition 0 is the background: it never owns a window and is always eligible. The
//! root task installs up to [`MAX_SCHEDULES`] schedules; the first one installed starts at
//! once, a switch to another takes effect at the next major-frame boundary, never mid-frame.
//!
//! [`TimeTable::advance`] is the whole decision: given the time and a CPU, which
//! partition's window is active there and when its next boundary is. It is pure and host-tested against a model.

use crate::sched::TIME_PARTITIONS;
use crate::state::Kernel;
use crate::thread::NEVER;
use abi::syscall::MIN_WINDOW;

pub const MAX_WINDOWS: usize = abi::syscall::MAX_WINDOWS as usize;
pub const MAX_SCHEDULES: usize = abi::syscall::MAX_SCHEDULES as usize;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Window {
    pub offset: u64,
    pub duration: u64,
    pub partition: u8,
    pub cpu: u8,
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
    /// A window starts before the previous one of its CPU ends (they must be sorted,
    /// disjoint).
    Overlap(usize),
    /// A window ends after the major frame.
    BeyondFrame(usize),
    /// A window for partition 0 (background) or an unknown partition.
    BadPartition(usize),
    /// A window on a CPU that is not online.
    BadCpu(usize),
}

impl Schedule {
    /// Checks `windows` for a machine of `cpus` CPUs.
    pub fn new(major_frame: u64, windows: &[Window], cpus: usize) -> Result<Self, ScheduleError> {
        let frame_ok = (MIN_WINDOW..=abi::syscall::MAX_MAJOR_FRAME).contains(&major_frame);
        if !frame_ok || windows.len() > MAX_WINDOWS {
            return Err(ScheduleError::Empty);
        }
        let mut previous_end = [0; crate::sched::CPUS];
        for (i, w) in windows.iter().enumerate() {
            if w.cpu as usize >= cpus.min(crate::sched::CPUS) {
                return Err(ScheduleError::BadCpu(i));
            }
            let previous_end = &mut previous_end[w.cpu as usize];
            if w.duration < MIN_WINDOW {
                return Err(ScheduleError::Empty);
            }
            if w.partition == 0 || w.partition as usize >= TIME_PARTITIONS {
                return Err(ScheduleError::BadPartition(i));
            }
            if w.offset < *previous_end {
                return Err(ScheduleError::Overlap(i));
            }
            if w.offset
                .checked_add(w.duration)
                .is_none_or(|e| e > major_frame)
            {
                return Err(ScheduleError::BeyondFrame(i));
            }
            *previous_end = w.end();
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

    /// The window of `cpu` containing frame position `pos` (if any) and the next boundary
    /// of `cpu` after `pos` (a window start or end, or the frame end), relative to the
    /// frame start.
    fn at(&self, pos: u64, cpu: usize) -> (Option<usize>, u64) {
        let on_cpu = |(_, w): &(usize, &Window)| w.cpu as usize == cpu;
        for (i, w) in self.windows().iter().enumerate().filter(on_cpu) {
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
        self.advance(now, 0);
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

    /// Moves to time `now` (never backwards) and reports the position of `cpu`.
    pub fn advance(&mut self, now: u64, cpu: usize) -> Position {
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
        let (window, next) = schedule.at(now - self.frame_start, cpu);
        Position {
            partition: window.map(|w| schedule.windows[w].partition),
            window,
            next_boundary: self.frame_start + next,
            frame_start: self.frame_start,
        }
    }

    /// Next activation (absolute start) and length of a window of `partition` (on any CPU)
    /// at or after `now`, within the running schedule (current window included if it is
    /// active now).
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
    /// A timer event at `now` (or another CPU's interrupt): time-outs and window
    /// boundaries.
    pub fn on_timer(&mut self, now: u64) {
        // The one-shot timer has fired: re-arm it even if it fired a little early (its
        // count is rounded down) and nothing is due yet, or the next event would be missed.
        self.core_mut().timer_dirty = true;
        self.catch_up(now);
        // Another CPU whose boundary has passed too is interrupted (`cpus_to_kick`), so
        // that all switch together even when its own timer comes late (under QEMU's
        // -icount a CPU takes an interrupt only in its turn, see `next_event`).
        for core in self.cores[..self.online].iter_mut() {
            core.timer_dirty |= now >= core.next_boundary;
        }
    }

    /// Brings the entering CPU's window and the time-outs up to `now`: before it chooses a
    /// thread, whatever interrupt it did or did not take (another CPU may have woken a
    /// thread of a window that has just ended here, before this CPU's timer said so).
    pub fn catch_up(&mut self, now: u64) {
        if now >= self.core().next_deadline {
            self.expire_timeouts(now);
        }
        if now >= self.core().next_boundary {
            self.update_window(self.cpu, now);
        }
    }

    /// Recomputes the active window of `cpu` (after a boundary or a schedule change).
    pub fn update_window(&mut self, cpu: usize, now: u64) {
        let position = self.time.advance(now, cpu);
        let core = &mut self.cores[cpu];
        core.active_partition = position.partition;
        core.next_boundary = position.next_boundary;
        core.timer_dirty = true;
    }

    /// When the entering CPU's timer must fire next: the next window boundary of any CPU,
    /// or the earliest time-out of its own threads.
    ///
    /// Every CPU's timer fires at every CPU's boundaries, and the first CPU to take the
    /// interrupt interrupts those whose boundary passed ([`Kernel::on_timer`]). A CPU
    /// waking only at its own boundaries would, under QEMU's deterministic time, take its
    /// interrupt only when the turn of the CPU running then ends, which may be at the next
    /// timer deadline anywhere: a window lost. On hardware it costs an interrupt per
    /// boundary per CPU.
    pub fn next_event(&self, now: u64) -> u64 {
        // Another CPU's boundary that has passed was seen (that CPU was interrupted).
        let boundary = (self.cores[..self.online].iter().enumerate())
            .filter(|&(cpu, core)| cpu == self.cpu || core.next_boundary > now)
            .map(|(_, core)| core.next_boundary)
            .min()
            .unwrap_or(NEVER);
        self.core().next_deadline.min(boundary)
    }

    /// Charges the entering CPU's time since its last call (TSC `now`) to the partition
    /// that ran there, or idle.
    pub fn account(&mut self, now: u64) {
        let core = &mut self.cores[self.cpu];
        let delta = now.saturating_sub(core.last_account);
        core.last_account = now;
        match core.running_partition {
            Some(p) => self.cpu_ticks[p as usize] += delta,
            None => core.idle_ticks += delta,
        }
    }
}

#[cfg(test)]
#[path = "../host-tests/timepart.rs"]
mod tests;
