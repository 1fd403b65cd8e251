//! The module schedule as partitions see it (ARINC 653 Part 2 SET_MODULE_SCHEDULE,
//! GET_MODULE_SCHEDULE_STATUS, GET_MODULE_SCHEDULE_ID): which of the configured schedules
//! runs, which one runs from the next major-frame boundary, and when the last switch took
//! effect.
//!
//! The kernel does the switching (`schedule_switch`, at the end of the running major frame,
//! and it says when that is); this records what was asked and settles it lazily: a
//! requested switch counts as done once `now` has reached the time the kernel named. Only
//! a partition the configuration allows (`schedule_control`) may switch (INVALID_CONFIG
//! otherwise); an id that names no schedule is INVALID_PARAM. Asking for the running
//! schedule while another is pending cancels that switch (the kernel's request is replaced;
//! "switching" to the running schedule changes nothing and is not a switch).
//!
//! Schedule ids are the schedules' indexes in the configuration; the first runs from boot.
//!
//! Schedule change actions (ARINC 653 Part 2, `change_actions` of a schedule in the
//! configuration): the glue wakes at the time of a pending switch ([`ModuleSchedule::pending_at`])
//! and takes the switch that has taken effect ([`ModuleSchedule::take_switch`]) to carry out
//! the new schedule's action for each partition
//! ([`crate::mode::PartitionMode::apply_schedule_change`]). A switch settled by a status
//! request in between is kept until the glue takes it, so no switch's actions are lost.

use crate::ReturnCode;
use protocol::ScheduleStatus;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModuleSchedule {
    count: u64,
    current: u64,
    /// The requested schedule and when the kernel switches to it.
    pending: Option<(u64, u64)>,
    last_switch: u64,
    /// A switch that took effect and whose change actions are not carried out yet.
    untaken: Option<u64>,
}

impl ModuleSchedule {
    /// `count` configured schedules, the first one running.
    pub const fn new(count: usize) -> Self {
        ModuleSchedule {
            count: count as u64,
            current: 0,
            pending: None,
            last_switch: 0,
            untaken: None,
        }
    }

    /// Whether a partition may ask for schedule `id` (`allowed`: its `schedule_control`).
    /// Ok: the glue asks the kernel, then reports [`ModuleSchedule::requested`].
    pub fn check(&self, allowed: bool, id: u64) -> Result<(), ReturnCode> {
        if !allowed {
            return Err(ReturnCode::InvalidConfig);
        }
        if id >= self.count {
            return Err(ReturnCode::InvalidParam);
        }
        Ok(())
    }

    /// The kernel switches to `id` at `at` (ns since boot); `now` is the time of the
    /// request.
    pub fn requested(&mut self, id: u64, at: u64, now: u64) {
        self.settle(now);
        self.pending = Some((id, at));
    }

    /// GET_MODULE_SCHEDULE_STATUS at `now`.
    pub fn status(&mut self, now: u64) -> ScheduleStatus {
        self.settle(now);
        ScheduleStatus {
            last_switch: self.last_switch,
            current: self.current,
            next: self.pending.map_or(self.current, |(id, _)| id),
        }
    }

    /// When the pending switch takes effect (`None`: no switch pending). A switch that took
    /// effect but is not taken yet is due at once (its time, in the past).
    pub fn pending_at(&self) -> Option<u64> {
        match (self.untaken, self.pending) {
            (Some(_), _) => Some(self.last_switch),
            (None, Some((_, at))) => Some(at),
            (None, None) => None,
        }
    }

    /// The schedule a switch made current since the last call, if one has taken effect by
    /// `now`: its change actions are to be carried out (once).
    pub fn take_switch(&mut self, now: u64) -> Option<u64> {
        self.settle(now);
        self.untaken.take()
    }

    /// A pending switch whose time has come is done.
    fn settle(&mut self, now: u64) {
        if let Some((id, at)) = self.pending
            && now >= at
        {
            if id != self.current {
                self.current = id;
                self.last_switch = at;
                self.untaken = Some(id);
            }
            self.pending = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn only_an_allowed_partition_switches_to_a_known_schedule() {
        let s = ModuleSchedule::new(2);
        assert_eq!(s.check(false, 1), Err(ReturnCode::InvalidConfig));
        assert_eq!(s.check(false, 9), Err(ReturnCode::InvalidConfig));
        assert_eq!(s.check(true, 2), Err(ReturnCode::InvalidParam));
        assert_eq!(s.check(true, 1), Ok(()));
        assert_eq!(s.check(true, 0), Ok(()));
    }

    #[test]
    fn a_switch_counts_from_the_time_the_kernel_named() {
        let mut s = ModuleSchedule::new(3);
        let initial = ScheduleStatus {
            last_switch: 0,
            current: 0,
            next: 0,
        };
        assert_eq!(s.status(5 * MS), initial);
        s.requested(1, 50 * MS, 10 * MS);
        let pending = ScheduleStatus { next: 1, ..initial };
        assert_eq!(s.status(10 * MS), pending);
        assert_eq!(s.status(50 * MS - 1), pending, "not before the boundary");
        let switched = ScheduleStatus {
            last_switch: 50 * MS,
            current: 1,
            next: 1,
        };
        assert_eq!(s.status(50 * MS), switched);
        assert_eq!(s.status(70 * MS), switched);
        // A later request replaces a pending one; asking for the running schedule cancels.
        s.requested(2, 90 * MS, 71 * MS);
        s.requested(0, 90 * MS, 72 * MS);
        assert_eq!(s.status(73 * MS).next, 0);
        s.requested(1, 90 * MS, 74 * MS);
        assert_eq!(
            s.status(91 * MS),
            switched,
            "switching to the running one is no switch"
        );
        // A request after the time of an unsettled one settles that first.
        s.requested(2, 130 * MS, 100 * MS);
        s.requested(0, 170 * MS, 140 * MS);
        assert_eq!(
            s.status(140 * MS),
            ScheduleStatus {
                last_switch: 130 * MS,
                current: 2,
                next: 0
            }
        );
    }

    #[test]
    fn each_switch_is_taken_once_for_its_change_actions() {
        let mut s = ModuleSchedule::new(3);
        assert_eq!(s.pending_at(), None, "nothing to wake for");
        assert_eq!(s.take_switch(10 * MS), None);
        s.requested(1, 50 * MS, 10 * MS);
        assert_eq!(s.pending_at(), Some(50 * MS));
        assert_eq!(s.take_switch(50 * MS - 1), None, "not before the boundary");
        assert_eq!(s.take_switch(50 * MS), Some(1));
        assert_eq!(s.take_switch(60 * MS), None, "once");
        assert_eq!(s.pending_at(), None);
        // Settled by a status request first: still taken once, and due at once.
        s.requested(2, 100 * MS, 60 * MS);
        assert_eq!(s.status(100 * MS).current, 2);
        assert_eq!(s.pending_at(), Some(100 * MS));
        assert_eq!(s.take_switch(101 * MS), Some(2));
        assert_eq!(s.take_switch(101 * MS), None);
        // A cancelled switch or one to the running schedule has no actions.
        s.requested(0, 150 * MS, 110 * MS);
        s.requested(2, 150 * MS, 120 * MS);
        assert_eq!(s.take_switch(200 * MS), None);
        assert_eq!(s.pending_at(), None);
    }
}
