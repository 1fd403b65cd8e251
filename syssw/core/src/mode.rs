//! ARINC 653 partition operating modes and their transitions: the partition's own
//! SET_PARTITION_MODE requests and the health monitor's actions. A pure state machine per
//! partition; what the glue must do about a transition comes back as a [`ModeChange`].
//!
//! # Modes
//!
//! A partition starts in [`OperatingMode::ColdStart`] with [`StartCondition::NormalStart`]
//! ([`PartitionMode::boot`]): its initialisation runs, then it asks for
//! [`OperatingMode::Normal`]. [`OperatingMode::Idle`] means stopped: no thread of it runs
//! (and it stays so until the module restarts).
//!
//! # SET_PARTITION_MODE (the partition's request, [`PartitionMode::request`])
//!
//! | current \ requested | NORMAL | IDLE | COLD_START | WARM_START |
//! |---|---|---|---|---|
//! | COLD_START | `Run` | `Stop` | `Restart{cold}` | INVALID_MODE |
//! | WARM_START | `Run` | `Stop` | `Restart{cold}` | `Restart{warm}` |
//! | NORMAL | NO_ACTION | `Stop` | `Restart{cold}` | `Restart{warm}` |
//! | IDLE | INVALID_MODE (a stopped partition has no thread that could ask) |||
//!
//! An unknown mode code is INVALID_PARAM. A restart the partition asks for sets the start
//! condition [`StartCondition::PartitionRestart`].
//!
//! # Health-monitor actions ([`PartitionMode::apply_health`])
//!
//! `ignore` → nothing; `idle` → `Stop`; `cold_restart` / `warm_restart` → `Restart` with
//! start condition [`StartCondition::HmPartitionRestart`]; a warm restart of a partition
//! that is still in COLD_START becomes a cold one (its initialised data may be half-built,
//! and ARINC refuses WARM_START from COLD_START for the same reason). `shutdown` /
//! `shutdown_success` are module-level: `Halt` (the partition's mode is left alone). An
//! action for an IDLE partition restarts or stops nothing (the report is stale: a stopped
//! partition runs no thread).
//!
//! # Schedule change actions ([`PartitionMode::apply_schedule_change`])
//!
//! When a switch to a module schedule takes effect, its `change_actions` entry for the
//! partition (ARINC 653 Part 2 SCHEDULE_CHANGE_ACTION): `ignore` → nothing; `idle` (ARINC
//! STOP) → `Stop`; `cold_start` / `warm_start` → `Restart` with start condition
//! [`StartCondition::PartitionRestart`] (ARINC 653 and a653rs have no start condition for a
//! schedule change; the restart is the module's configured one, not the health monitor's,
//! so it is not HM_PARTITION_RESTART). As for the health monitor, a warm start of a
//! partition still in COLD_START is a cold one, and an IDLE partition stays IDLE (IDLE is
//! for good until the module restarts).
//!
//! # Cold vs warm restart (what the glue does for `Restart`)
//!
//! Both stop every thread of the partition, reset its ports
//! ([`crate::ports::Ports::reset_partition`]) and start its first thread at the image's
//! entry point again. A **cold** restart re-initialises the partition from its image: its
//! memory is reloaded (data and bss as in the ELF), as at boot. A **warm** restart keeps
//! the partition's memory as it is (no reload of initialised data); the application finds
//! its start condition and decides what to re-initialise. This module only decides; the
//! glue reloads.

use config::model::{ChangeAction, HealthAction};
pub use protocol::{OperatingMode, ReturnCode, StartCondition};

/// What the glue must do after a transition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModeChange {
    /// Nothing (the mode did not change).
    None,
    /// The partition entered NORMAL: initialisation is over (nothing to stop or start;
    /// the glue may log it).
    Run,
    /// Stop the partition for good: suspend or kill its threads, reset its ports.
    Stop,
    /// Restart the partition (see the module documentation for cold vs warm).
    Restart { warm: bool },
    /// Stop the whole module: `system_halt(success)`.
    Halt { success: bool },
}

/// The mode state of one partition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartitionMode {
    mode: OperatingMode,
    start_condition: StartCondition,
    restarts: u32,
}

impl PartitionMode {
    /// A partition as the module starts it: COLD_START, NORMAL_START.
    pub const fn boot() -> Self {
        Self::starting(StartCondition::NormalStart)
    }

    /// A partition that was never started (IDLE from boot): its configuration could not be
    /// carried out (a PCI device missing at boot).
    pub const fn never_started() -> Self {
        PartitionMode {
            mode: OperatingMode::Idle,
            start_condition: StartCondition::NormalStart,
            restarts: 0,
        }
    }

    /// A partition cold-starting for `condition` (e.g. HM_MODULE_RESTART after a module
    /// restart).
    pub const fn starting(condition: StartCondition) -> Self {
        PartitionMode {
            mode: OperatingMode::ColdStart,
            start_condition: condition,
            restarts: 0,
        }
    }

    pub const fn mode(&self) -> OperatingMode {
        self.mode
    }

    /// ARINC GET_PARTITION_STATUS's START_CONDITION.
    pub const fn start_condition(&self) -> StartCondition {
        self.start_condition
    }

    /// Restarts since this state was created (saturating).
    pub const fn restarts(&self) -> u32 {
        self.restarts
    }

    fn restart(&mut self, warm: bool, condition: StartCondition) -> ModeChange {
        self.mode = if warm {
            OperatingMode::WarmStart
        } else {
            OperatingMode::ColdStart
        };
        self.start_condition = condition;
        self.restarts = self.restarts.saturating_add(1);
        ModeChange::Restart { warm }
    }

    /// SET_PARTITION_MODE(`requested`) from the partition itself (see the table in the
    /// module documentation). `Ok` means the transition happened; the glue replies
    /// NO_ERROR for `Run` and carries out `Stop`/`Restart` (the caller does not get a
    /// reply then: its thread is gone).
    pub fn request(&mut self, requested: OperatingMode) -> Result<ModeChange, ReturnCode> {
        use OperatingMode as M;
        match (self.mode, requested) {
            (M::Idle, _) => Err(ReturnCode::InvalidMode),
            (M::Normal, M::Normal) => Err(ReturnCode::NoAction),
            (M::ColdStart, M::WarmStart) => Err(ReturnCode::InvalidMode),
            (_, M::Normal) => {
                self.mode = M::Normal;
                Ok(ModeChange::Run)
            }
            (_, M::Idle) => {
                self.mode = M::Idle;
                Ok(ModeChange::Stop)
            }
            (_, M::ColdStart) => Ok(self.restart(false, StartCondition::PartitionRestart)),
            (_, M::WarmStart) => Ok(self.restart(true, StartCondition::PartitionRestart)),
        }
    }

    /// The health monitor decided `action` for an error of this partition.
    pub fn apply_health(&mut self, action: HealthAction) -> ModeChange {
        use HealthAction as A;
        match action {
            A::Shutdown => ModeChange::Halt { success: false },
            A::ShutdownSuccess => ModeChange::Halt { success: true },
            _ if self.mode == OperatingMode::Idle => ModeChange::None,
            A::Ignore => ModeChange::None,
            A::Idle => {
                self.mode = OperatingMode::Idle;
                ModeChange::Stop
            }
            A::ColdRestart => self.restart(false, StartCondition::HmPartitionRestart),
            A::WarmRestart => {
                let warm = self.mode != OperatingMode::ColdStart;
                self.restart(warm, StartCondition::HmPartitionRestart)
            }
        }
    }
}

impl PartitionMode {
    /// A switch to a module schedule whose change action for this partition is `action`
    /// took effect (see the module documentation).
    pub fn apply_schedule_change(&mut self, action: ChangeAction) -> ModeChange {
        match action {
            _ if self.mode == OperatingMode::Idle => ModeChange::None,
            ChangeAction::Ignore => ModeChange::None,
            ChangeAction::Idle => {
                self.mode = OperatingMode::Idle;
                ModeChange::Stop
            }
            ChangeAction::ColdStart => self.restart(false, StartCondition::PartitionRestart),
            ChangeAction::WarmStart => {
                let warm = self.mode != OperatingMode::ColdStart;
                self.restart(warm, StartCondition::PartitionRestart)
            }
        }
    }
}

/// What a module-level error's action means for the glue (errors outside any partition
/// resolve to `shutdown`/`shutdown_success`/`ignore`, see
/// [`config::model::HealthTable::resolve`]).
pub fn module_action(action: HealthAction) -> ModeChange {
    match action {
        HealthAction::ShutdownSuccess => ModeChange::Halt { success: true },
        HealthAction::Ignore => ModeChange::None,
        // resolve() never gives a partition action for the module; fail safe if it did.
        _ => ModeChange::Halt { success: false },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use OperatingMode as M;

    fn in_mode(mode: OperatingMode) -> PartitionMode {
        PartitionMode {
            mode,
            ..PartitionMode::boot()
        }
    }

    #[test]
    fn a_partition_never_started_is_idle_and_stays_so() {
        let mut m = PartitionMode::never_started();
        assert_eq!(m.mode(), M::Idle);
        assert_eq!(m.request(M::Normal), Err(ReturnCode::InvalidMode));
        assert_eq!(m.mode(), M::Idle);
    }

    #[test]
    fn codes_are_arinc() {
        for (mode, code) in [
            (M::Idle, 0),
            (M::ColdStart, 1),
            (M::WarmStart, 2),
            (M::Normal, 3),
        ] {
            assert_eq!(mode as u64, code);
            assert_eq!(M::from_u64(code), Some(mode));
        }
        assert_eq!(M::from_u64(4), None);
        assert_eq!(StartCondition::NormalStart as u8, 0);
        assert_eq!(StartCondition::PartitionRestart as u8, 1);
        assert_eq!(StartCondition::HmModuleRestart as u8, 2);
        assert_eq!(StartCondition::HmPartitionRestart as u8, 3);
        assert_eq!(M::WarmStart.name(), "WARM_START");
        assert_eq!(
            StartCondition::HmPartitionRestart.name(),
            "HM_PARTITION_RESTART"
        );
    }

    #[test]
    fn boot_state() {
        let p = PartitionMode::boot();
        assert_eq!(p.mode(), M::ColdStart);
        assert_eq!(p.start_condition(), StartCondition::NormalStart);
        assert_eq!(p.restarts(), 0);
        let p = PartitionMode::starting(StartCondition::HmModuleRestart);
        assert_eq!(
            (p.mode(), p.start_condition()),
            (M::ColdStart, StartCondition::HmModuleRestart)
        );
    }

    #[test]
    fn the_whole_request_table() {
        use ModeChange as C;
        let table: [(M, M, Result<C, ReturnCode>, M); 16] = [
            (M::ColdStart, M::Normal, Ok(C::Run), M::Normal),
            (M::ColdStart, M::Idle, Ok(C::Stop), M::Idle),
            (
                M::ColdStart,
                M::ColdStart,
                Ok(C::Restart { warm: false }),
                M::ColdStart,
            ),
            (
                M::ColdStart,
                M::WarmStart,
                Err(ReturnCode::InvalidMode),
                M::ColdStart,
            ),
            (M::WarmStart, M::Normal, Ok(C::Run), M::Normal),
            (M::WarmStart, M::Idle, Ok(C::Stop), M::Idle),
            (
                M::WarmStart,
                M::ColdStart,
                Ok(C::Restart { warm: false }),
                M::ColdStart,
            ),
            (
                M::WarmStart,
                M::WarmStart,
                Ok(C::Restart { warm: true }),
                M::WarmStart,
            ),
            (M::Normal, M::Normal, Err(ReturnCode::NoAction), M::Normal),
            (M::Normal, M::Idle, Ok(C::Stop), M::Idle),
            (
                M::Normal,
                M::ColdStart,
                Ok(C::Restart { warm: false }),
                M::ColdStart,
            ),
            (
                M::Normal,
                M::WarmStart,
                Ok(C::Restart { warm: true }),
                M::WarmStart,
            ),
            (M::Idle, M::Normal, Err(ReturnCode::InvalidMode), M::Idle),
            (M::Idle, M::Idle, Err(ReturnCode::InvalidMode), M::Idle),
            (M::Idle, M::ColdStart, Err(ReturnCode::InvalidMode), M::Idle),
            (M::Idle, M::WarmStart, Err(ReturnCode::InvalidMode), M::Idle),
        ];
        for (from, requested, result, to) in table {
            let mut p = in_mode(from);
            assert_eq!(p.request(requested), result, "{from:?} -> {requested:?}");
            assert_eq!(p.mode(), to, "{from:?} -> {requested:?}");
            let restarted = matches!(result, Ok(C::Restart { .. }));
            assert_eq!(p.restarts(), restarted as u32);
            let condition = if restarted {
                StartCondition::PartitionRestart
            } else {
                StartCondition::NormalStart
            };
            assert_eq!(p.start_condition(), condition, "{from:?} -> {requested:?}");
        }
    }

    #[test]
    fn raw_codes() {
        use protocol::{DecodeError, Label, Request, Wire};
        // A mode code ARINC does not define never reaches the state machine: the protocol
        // refuses it with INVALID_PARAM.
        for code in [9, u64::MAX] {
            let wire = Wire {
                label: Label::SetPartitionMode.code(),
                words: [code, 0, 0],
                data: &[],
            };
            let error = Request::decode(wire).unwrap_err();
            assert_eq!(error, DecodeError::UnknownMode(code));
            assert_eq!(error.return_code(), ReturnCode::InvalidParam);
        }
        let mut p = PartitionMode::boot();
        assert_eq!(p.mode(), M::ColdStart);
        assert_eq!(p.request(M::from_u64(3).unwrap()), Ok(ModeChange::Run));
        assert_eq!(p.request(M::Normal), Err(ReturnCode::NoAction));
    }

    #[test]
    fn health_actions() {
        use HealthAction as A;
        use ModeChange as C;
        let mut p = in_mode(M::Normal);
        assert_eq!(p.apply_health(A::Ignore), C::None);
        assert_eq!(p.mode(), M::Normal);
        assert_eq!(p.apply_health(A::WarmRestart), C::Restart { warm: true });
        assert_eq!(
            (p.mode(), p.start_condition()),
            (M::WarmStart, StartCondition::HmPartitionRestart)
        );
        assert_eq!(p.apply_health(A::ColdRestart), C::Restart { warm: false });
        assert_eq!(p.mode(), M::ColdStart);
        // Warm restart during cold start: cold.
        assert_eq!(p.apply_health(A::WarmRestart), C::Restart { warm: false });
        assert_eq!(p.restarts(), 3);
        assert_eq!(p.apply_health(A::Idle), C::Stop);
        assert_eq!(p.mode(), M::Idle);
        // Stale reports for a stopped partition change nothing, except module halts.
        for a in [A::Ignore, A::Idle, A::ColdRestart, A::WarmRestart] {
            assert_eq!(p.apply_health(a), C::None);
            assert_eq!(p.mode(), M::Idle);
        }
        assert_eq!(p.apply_health(A::Shutdown), C::Halt { success: false });
        assert_eq!(
            p.apply_health(A::ShutdownSuccess),
            C::Halt { success: true }
        );
        let mut q = in_mode(M::WarmStart);
        assert_eq!(q.apply_health(A::WarmRestart), C::Restart { warm: true });
        assert_eq!(q.apply_health(A::Shutdown), C::Halt { success: false });
        assert_eq!(q.mode(), M::WarmStart);
    }

    #[test]
    fn schedule_change_actions() {
        use ChangeAction as A;
        use ModeChange as C;
        let mut p = in_mode(M::Normal);
        assert_eq!(p.apply_schedule_change(A::Ignore), C::None);
        assert_eq!(p.mode(), M::Normal);
        assert_eq!(
            p.apply_schedule_change(A::WarmStart),
            C::Restart { warm: true }
        );
        assert_eq!(
            (p.mode(), p.start_condition(), p.restarts()),
            (M::WarmStart, StartCondition::PartitionRestart, 1)
        );
        assert_eq!(
            p.apply_schedule_change(A::ColdStart),
            C::Restart { warm: false }
        );
        assert_eq!(
            (p.mode(), p.start_condition()),
            (M::ColdStart, StartCondition::PartitionRestart)
        );
        // Warm start during cold start: cold.
        assert_eq!(
            p.apply_schedule_change(A::WarmStart),
            C::Restart { warm: false }
        );
        assert_eq!(p.apply_schedule_change(A::Idle), C::Stop);
        assert_eq!(p.mode(), M::Idle);
        // IDLE is for good.
        for a in A::ALL {
            assert_eq!(p.apply_schedule_change(a), C::None);
            assert_eq!(p.mode(), M::Idle);
        }
    }

    #[test]
    fn module_actions() {
        use HealthAction as A;
        assert_eq!(module_action(A::Ignore), ModeChange::None);
        assert_eq!(
            module_action(A::ShutdownSuccess),
            ModeChange::Halt { success: true }
        );
        for a in [A::Shutdown, A::Idle, A::ColdRestart, A::WarmRestart] {
            assert_eq!(module_action(a), ModeChange::Halt { success: false });
        }
    }
}
