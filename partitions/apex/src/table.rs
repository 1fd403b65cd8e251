//! The partition's process table: ARINC 653 process states and their transitions, the
//! periodic release/deadline bookkeeping and the error handler's queue of pending errors
//! (pure: no system calls, host-tested).
//!
//! The runtime ([`crate::runtime`]) holds one [`Table`] under its lock, asks it whether a
//! request is allowed and what it changes, and performs the kernel operations the answer
//! names (create, start, suspend, resume or kill a thread). The table never sees a clock:
//! every time comes in as an argument.
//!
//! Process ids are slot + 1 (0 is ARINC's `NULL_PROCESS_ID`). Slots
//! `0..MAX_PROCESSES` hold CREATE_PROCESS's processes, slot [`ERROR_HANDLER_SLOT`] the error
//! handler.

use crate::codes::name_bytes;
use crate::time::{self, check_process_timing, finite};
use a653rs::bindings::{
    ApexProcessAttribute, ApexProcessStatus, ApexSystemTime, Deadline, ErrorCode, ErrorReturnCode,
    INFINITE_TIME_VALUE, MAX_ERROR_MESSAGE_SIZE, MAX_PRIORITY_VALUE, MIN_PRIORITY_VALUE, ProcessId,
    ProcessState, StackSize, SystemAddress,
};

/// Most processes one partition creates (besides the error handler).
pub const MAX_PROCESSES: usize = 16;
/// The error handler's slot.
pub const ERROR_HANDLER_SLOT: usize = MAX_PROCESSES;
/// Process slots, error handler included.
pub const SLOTS: usize = MAX_PROCESSES + 1;
/// The least stack a process gets, whatever smaller size it asks (Rust code that formats
/// text needs about that much).
pub const MIN_STACK: usize = 32 * 1024;
/// The stack arena a program gets unless [`crate::partition_entry!`] names another size:
/// [`MIN_STACK`] for every slot. Processes with larger stacks fit as long as the stacks of
/// all processes created add up to no more (CREATE_PROCESS answers INVALID_CONFIG beyond).
pub const STACK_ARENA_SIZE: usize = SLOTS * MIN_STACK;
/// Errors waiting for the error handler; when full, further errors go to syssw's health
/// monitor directly.
pub const ERROR_QUEUE: usize = 8;
/// The error handler's name in GET_PROCESS_STATUS.
pub const ERROR_HANDLER_NAME: &str = "ERROR_HANDLER";

type Result<T> = core::result::Result<T, ErrorReturnCode>;

pub fn id_of(slot: usize) -> ProcessId {
    slot as ProcessId + 1
}

/// The slot of a process id, if it could name one.
pub fn slot_of(id: ProcessId) -> Option<usize> {
    usize::try_from(id)
        .ok()
        .and_then(|id| id.checked_sub(1))
        .filter(|&slot| slot < SLOTS)
}

/// Where a process is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Life {
    Dormant,
    /// STARTed during initialisation: its (inactive) thread starts when NORMAL begins,
    /// `delay` ns after its first release point (DELAYED_START).
    Pending {
        delay: u64,
    },
    /// Its thread runs (or waits).
    Active,
}

/// What an active process waits for (ARINC state WAITING unless `None`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wait {
    None,
    /// Its next release point (after START or PERIODIC_WAIT).
    Release,
    /// TIMED_WAIT.
    Delay,
    /// SUSPEND_SELF, until RESUME or its time-out.
    SelfSuspended,
    /// A queuing-port send or receive that may block.
    Port,
    /// An intra-partition object (buffer, blackboard, semaphore, event, mutex).
    Object,
}

#[derive(Clone, Debug)]
pub struct Process {
    pub attributes: ApexProcessAttribute,
    /// Current priority (= kernel priority of its thread).
    pub priority: u8,
    pub life: Life,
    pub wait: Wait,
    /// SUSPENDed by another process (its thread is kernel-suspended).
    pub suspended: bool,
    /// Its current release point, or the next one while it waits for it.
    pub release: u64,
    /// Its pending deadline (none: INFINITE capacity, or already reported as missed).
    pub deadline: Option<u64>,
    /// Raw id of its kernel thread (created at START, gone when it stops).
    pub thread: Option<u64>,
    /// Its stack in the runtime's stack arena (every START of it uses the same).
    pub stack: StackPlace,
}

/// A process's stack: `size` bytes (a multiple of 16) at `offset` in the stack arena.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StackPlace {
    pub offset: usize,
    pub size: usize,
}

impl Process {
    /// A created process that has not been started.
    fn dormant(attributes: ApexProcessAttribute, priority: u8, stack: StackPlace) -> Self {
        Process {
            stack,
            attributes,
            priority,
            life: Life::Dormant,
            wait: Wait::None,
            suspended: false,
            release: 0,
            deadline: None,
            thread: None,
        }
    }

    pub fn periodic(&self) -> Option<u64> {
        finite(self.attributes.period)
    }
}

/// An error for the error handler (GET_ERROR_STATUS).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PendingError {
    pub code: ErrorCode,
    /// The failed process (0 = none, e.g. the initialisation thread).
    pub process: ProcessId,
    pub length: usize,
    pub message: [u8; MAX_ERROR_MESSAGE_SIZE],
}

impl PendingError {
    /// An error with `text` as its message (cut to [`MAX_ERROR_MESSAGE_SIZE`] bytes).
    pub fn new(code: ErrorCode, process: ProcessId, text: &[u8]) -> Self {
        let mut message = [0u8; MAX_ERROR_MESSAGE_SIZE];
        let length = text.len().min(MAX_ERROR_MESSAGE_SIZE);
        message[..length].copy_from_slice(&text[..length]);
        Self {
            code,
            process,
            length,
            message,
        }
    }

    pub fn text(&self) -> &[u8] {
        &self.message[..self.length]
    }
}

/// Where an error goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delivery {
    /// Queued for the error handler, which runs already.
    Queued,
    /// Queued; the error handler is dormant and must be started.
    StartHandler,
    /// No error handler (or initialisation, or its queue is full, or the error handler
    /// itself failed): report to syssw's health monitor.
    Monitor,
}

/// What RESUME must do to the thread.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resume {
    pub thread: u64,
    /// Wake it from SUSPEND_SELF (notification).
    pub notify: bool,
    /// Undo a SUSPEND (kernel resume).
    pub kernel_resume: bool,
}

#[derive(Debug)]
pub struct Table {
    /// NORMAL mode: initialisation is over.
    pub normal: bool,
    /// The task's maximum controlled priority: processes run below it, the watchdog and the
    /// error handler at it.
    pub mcp: u8,
    /// The partition's period (ns; 0 = none).
    pub partition_period: u64,
    pub main_thread: u64,
    pub main_priority: u8,
    pub watchdog_thread: Option<u64>,
    /// The time the watchdog sleeps until (`u64::MAX`: no deadline pending).
    pub watchdog_armed: u64,
    slots: [Option<Process>; SLOTS],
    /// Bytes of the stack arena, and how many of them created processes hold (processes
    /// are created only during initialisation and never deleted: a bump allocation, reset
    /// with the table at every start).
    stack_arena: usize,
    stack_used: usize,
    errors: [Option<PendingError>; ERROR_QUEUE],
    /// Index of the oldest queued error.
    error_head: usize,
}

impl Table {
    pub const EMPTY: Table = Table {
        normal: false,
        mcp: 0,
        partition_period: 0,
        main_thread: 0,
        main_priority: 0,
        watchdog_thread: None,
        watchdog_armed: u64::MAX,
        slots: [const { None }; SLOTS],
        stack_arena: 0,
        stack_used: 0,
        errors: [None; ERROR_QUEUE],
        error_head: 0,
    };

    /// The table of a partition that starts its initialisation, its processes' stacks to
    /// come from an arena of `stack_arena` bytes.
    pub fn new(
        mcp: u8,
        partition_period: u64,
        main_thread: u64,
        main_priority: u8,
        stack_arena: usize,
    ) -> Self {
        Self {
            mcp,
            partition_period,
            main_thread,
            main_priority,
            stack_arena,
            ..Self::EMPTY
        }
    }

    /// Where a new process's stack of (at least) `asked` bytes would go: INVALID_CONFIG
    /// when the arena has no room left (ARINC: insufficient storage capacity).
    fn place_stack(&self, asked: StackSize) -> Result<StackPlace> {
        let size = (asked as usize)
            .max(MIN_STACK)
            .checked_next_multiple_of(16)
            .ok_or(ErrorReturnCode::InvalidConfig)?;
        match self.stack_used.checked_add(size) {
            Some(end) if end <= self.stack_arena => Ok(StackPlace {
                offset: self.stack_used,
                size,
            }),
            _ => Err(ErrorReturnCode::InvalidConfig),
        }
    }

    /// Records a process created in `slot` with its stack at `stack`.
    fn occupy(&mut self, slot: usize, process: Process) {
        self.stack_used = process.stack.offset + process.stack.size;
        self.slots[slot] = Some(process);
    }

    pub fn get(&self, slot: usize) -> Option<&Process> {
        self.slots.get(slot).and_then(Option::as_ref)
    }

    fn get_mut(&mut self, slot: usize) -> Result<&mut Process> {
        self.slots
            .get_mut(slot)
            .and_then(Option::as_mut)
            .ok_or(ErrorReturnCode::InvalidParam)
    }

    /// The slot of process `id` (INVALID_PARAM if there is none).
    pub fn slot(&self, id: ProcessId) -> Result<usize> {
        slot_of(id)
            .filter(|&slot| self.get(slot).is_some())
            .ok_or(ErrorReturnCode::InvalidParam)
    }

    /// The slot whose thread is `thread`.
    pub fn slot_of_thread(&self, thread: u64) -> Option<usize> {
        (0..SLOTS).find(|&slot| self.get(slot).is_some_and(|p| p.thread == Some(thread)))
    }

    /// The priority `thread` runs at outside the runtime's critical sections.
    pub fn priority_of_thread(&self, thread: u64) -> u8 {
        if thread == self.main_thread {
            return self.main_priority;
        }
        match self.slot_of_thread(thread) {
            Some(slot) => self.slots[slot].as_ref().map_or(self.mcp, |p| p.priority),
            None => self.mcp,
        }
    }

    /// GET_PROCESS_ID: INVALID_CONFIG if no process has that name.
    pub fn find(&self, name: &[u8]) -> Result<ProcessId> {
        (0..MAX_PROCESSES)
            .find(|&slot| {
                self.get(slot)
                    .is_some_and(|p| name_bytes(&p.attributes.name) == name)
            })
            .map(id_of)
            .ok_or(ErrorReturnCode::InvalidConfig)
    }

    /// CREATE_PROCESS (ARINC 653 P1 3.3.2.3).
    pub fn create(&mut self, attributes: &ApexProcessAttribute) -> Result<ProcessId> {
        if self.normal {
            return Err(ErrorReturnCode::InvalidMode);
        }
        let name = name_bytes(&attributes.name);
        if name.is_empty() {
            return Err(ErrorReturnCode::InvalidParam);
        }
        if self.find(name).is_ok() {
            return Err(ErrorReturnCode::NoAction);
        }
        let slot = (0..MAX_PROCESSES)
            .find(|&slot| self.slots[slot].is_none())
            .ok_or(ErrorReturnCode::InvalidConfig)?;
        let stack = self.place_stack(attributes.stack_size)?;
        let priority = attributes.base_priority;
        if !(MIN_PRIORITY_VALUE..=MAX_PRIORITY_VALUE).contains(&priority) {
            return Err(ErrorReturnCode::InvalidParam);
        }
        if priority >= i32::from(self.mcp) {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        check_process_timing(
            attributes.period,
            attributes.time_capacity,
            self.partition_period,
        )?;
        self.occupy(
            slot,
            Process::dormant(attributes.clone(), priority as u8, stack),
        );
        Ok(id_of(slot))
    }

    /// CREATE_ERROR_HANDLER (ARINC 653 P1 3.8.2.2): a process at the task's MCP.
    pub fn create_error_handler(&mut self, entry: SystemAddress, stack: StackSize) -> Result<()> {
        if self.normal {
            return Err(ErrorReturnCode::InvalidMode);
        }
        if self.slots[ERROR_HANDLER_SLOT].is_some() {
            return Err(ErrorReturnCode::NoAction);
        }
        let place = self.place_stack(stack)?;
        let attributes = ApexProcessAttribute {
            period: INFINITE_TIME_VALUE,
            time_capacity: INFINITE_TIME_VALUE,
            entry_point: entry,
            stack_size: stack,
            base_priority: MAX_PRIORITY_VALUE,
            deadline: Deadline::Soft,
            name: crate::codes::apex_name(ERROR_HANDLER_NAME),
        };
        self.occupy(
            ERROR_HANDLER_SLOT,
            Process::dormant(attributes, self.mcp, place),
        );
        Ok(())
    }

    pub fn has_error_handler(&self) -> bool {
        self.slots[ERROR_HANDLER_SLOT].is_some()
    }

    /// START / DELAYED_START checks: the slot to start (its thread is created next).
    pub fn check_start(&self, id: ProcessId, delay: ApexSystemTime) -> Result<usize> {
        let slot = self.slot(id)?;
        if slot == ERROR_HANDLER_SLOT {
            return Err(ErrorReturnCode::InvalidParam);
        }
        let process = self.get(slot).ok_or(ErrorReturnCode::InvalidParam)?;
        if process.life != Life::Dormant {
            return Err(ErrorReturnCode::NoAction);
        }
        let delay = finite(delay).ok_or(ErrorReturnCode::InvalidParam)?;
        if process.periodic().is_some_and(|period| delay >= period) {
            return Err(ErrorReturnCode::InvalidParam);
        }
        Ok(slot)
    }

    /// A START during initialisation: its thread `thread` (created, not started) waits for
    /// NORMAL.
    pub fn make_pending(&mut self, slot: usize, delay: u64, thread: u64) -> Result<()> {
        let process = self.get_mut(slot)?;
        process.life = Life::Pending { delay };
        process.thread = Some(thread);
        process.priority = process.attributes.base_priority as u8;
        Ok(())
    }

    /// A START in NORMAL mode (or of the error handler): the process with thread `thread`
    /// is released at `release` (its deadline follows from its time capacity).
    pub fn activate(&mut self, slot: usize, release: u64, thread: u64) -> Result<()> {
        let process = self.get_mut(slot)?;
        process.life = Life::Active;
        process.wait = Wait::Release;
        process.suspended = false;
        process.priority = process.attributes.base_priority as u8;
        process.release = release;
        process.deadline = time::deadline(release, process.attributes.time_capacity);
        process.thread = Some(thread);
        Ok(())
    }

    /// The error handler's start (its priority stays the MCP).
    pub fn activate_error_handler(&mut self, now: u64, thread: u64) -> Result<()> {
        let mcp = self.mcp;
        self.activate(ERROR_HANDLER_SLOT, now, thread)?;
        self.get_mut(ERROR_HANDLER_SLOT)?.priority = mcp;
        Ok(())
    }

    /// NORMAL begins: every process STARTed during initialisation is released (periodic
    /// ones at `release_point`, aperiodic ones at `now`, each plus its delay). Returns the
    /// slots whose threads must be started now (bit per slot).
    pub fn begin_normal(&mut self, now: u64, release_point: u64) -> u32 {
        self.normal = true;
        let mut released = 0;
        for slot in 0..MAX_PROCESSES {
            let Some(process) = self.slots[slot].as_ref() else {
                continue;
            };
            let (Life::Pending { delay }, Some(thread)) = (process.life, process.thread) else {
                continue;
            };
            let release =
                time::first_release(process.periodic().is_some(), now, release_point, delay);
            if self.activate(slot, release, thread).is_ok() {
                released |= 1 << slot;
            }
        }
        released
    }

    /// Whether any process has a finite time capacity (the watchdog is needed).
    pub fn needs_watchdog(&self) -> bool {
        (0..MAX_PROCESSES).any(|slot| {
            self.get(slot)
                .is_some_and(|p| finite(p.attributes.time_capacity).is_some())
        })
    }

    /// The thread of `slot` reached its release point.
    pub fn released(&mut self, slot: usize) {
        if let Ok(process) = self.get_mut(slot)
            && process.wait == Wait::Release
        {
            process.wait = Wait::None;
        }
    }

    /// PERIODIC_WAIT of `slot`: its next release point (the deadline of that job is set
    /// now, so a job that reached PERIODIC_WAIT in time never counts as late).
    pub fn periodic_wait(&mut self, slot: usize) -> Result<u64> {
        if slot == ERROR_HANDLER_SLOT {
            return Err(ErrorReturnCode::InvalidMode);
        }
        let process = self
            .get_mut(slot)
            .map_err(|_| ErrorReturnCode::InvalidMode)?;
        let period = process.periodic().ok_or(ErrorReturnCode::InvalidMode)?;
        process.release = process.release.saturating_add(period);
        process.deadline = time::deadline(process.release, process.attributes.time_capacity);
        process.wait = Wait::Release;
        Ok(process.release)
    }

    /// REPLENISH of `slot` at `now` (ARINC 653 P1 3.4.2.4).
    pub fn replenish(&mut self, slot: usize, budget: ApexSystemTime, now: u64) -> Result<()> {
        if slot == ERROR_HANDLER_SLOT || !self.normal {
            return Err(ErrorReturnCode::NoAction);
        }
        let process = self.get_mut(slot).map_err(|_| ErrorReturnCode::NoAction)?;
        let deadline = finite(budget).map(|b| now.saturating_add(b));
        if let Some(period) = process.periodic() {
            let next_release = process.release.saturating_add(period);
            if deadline.is_none_or(|d| d > next_release) {
                return Err(ErrorReturnCode::InvalidMode);
            }
        }
        process.deadline = deadline;
        Ok(())
    }

    /// Sets the current priority of `slot` (a mutex's ceiling or the priority it retained);
    /// returns its thread.
    pub fn set_current_priority(&mut self, slot: usize, priority: u8) -> Option<u64> {
        let process = self.get_mut(slot).ok()?;
        process.priority = priority;
        process.thread
    }

    /// The current priority of the thread of `slot` (the main thread's for `None`).
    pub fn current_priority(&self, slot: Option<usize>) -> u8 {
        match slot {
            None => self.main_priority,
            Some(ERROR_HANDLER_SLOT) => self.mcp,
            Some(slot) => self.get(slot).map_or(self.main_priority, |p| p.priority),
        }
    }

    /// Marks what `slot` waits for (TIMED_WAIT, port waits; `Wait::None` when it is over).
    pub fn set_wait(&mut self, slot: usize, wait: Wait) {
        if let Ok(process) = self.get_mut(slot) {
            process.wait = wait;
        }
    }

    /// SUSPEND_SELF checks: whether the caller waits at all (a zero time-out does not).
    pub fn suspend_self(&mut self, slot: usize, time_out: ApexSystemTime) -> Result<bool> {
        if slot == ERROR_HANDLER_SLOT {
            return Err(ErrorReturnCode::InvalidMode);
        }
        let process = self
            .get_mut(slot)
            .map_err(|_| ErrorReturnCode::InvalidMode)?;
        if time_out == 0 {
            return Ok(false);
        }
        process.wait = Wait::SelfSuspended;
        Ok(true)
    }

    /// SUSPEND_SELF ended (woken or timed out): TIMED_OUT if no RESUME came. Returns also
    /// whether a RESUME's notification is still pending (it raced with the time-out).
    pub fn suspend_self_end(&mut self, slot: usize, woken: bool) -> (Result<()>, bool) {
        let Ok(process) = self.get_mut(slot) else {
            return (Ok(()), false);
        };
        if process.wait == Wait::SelfSuspended {
            process.wait = Wait::None;
            (Err(ErrorReturnCode::TimedOut), false)
        } else {
            (Ok(()), !woken)
        }
    }

    /// SUSPEND of another process: the thread to suspend.
    pub fn suspend(&mut self, slot: usize, caller: Option<usize>) -> Result<u64> {
        if Some(slot) == caller || slot == ERROR_HANDLER_SLOT {
            return Err(ErrorReturnCode::InvalidParam);
        }
        let process = self.get_mut(slot)?;
        if process.life == Life::Dormant {
            return Err(ErrorReturnCode::InvalidMode);
        }
        if process.suspended {
            return Err(ErrorReturnCode::NoAction);
        }
        let thread = process.thread.ok_or(ErrorReturnCode::InvalidMode)?;
        process.suspended = true;
        Ok(thread)
    }

    /// RESUME: what to undo.
    pub fn resume(&mut self, slot: usize) -> Result<Resume> {
        if slot == ERROR_HANDLER_SLOT {
            return Err(ErrorReturnCode::InvalidParam);
        }
        let process = self.get_mut(slot)?;
        if process.life == Life::Dormant {
            return Err(ErrorReturnCode::InvalidMode);
        }
        let notify = process.wait == Wait::SelfSuspended;
        let kernel_resume = process.suspended;
        if !notify && !kernel_resume {
            return Err(ErrorReturnCode::NoAction);
        }
        let thread = process.thread.ok_or(ErrorReturnCode::InvalidMode)?;
        if notify {
            process.wait = Wait::None;
        }
        process.suspended = false;
        Ok(Resume {
            thread,
            notify,
            kernel_resume,
        })
    }

    /// STOP / STOP_SELF: the process becomes dormant; returns its thread (to kill, unless it
    /// is the caller, which exits).
    pub fn stop(&mut self, slot: usize) -> Result<Option<u64>> {
        let process = self.get_mut(slot)?;
        if process.life == Life::Dormant {
            return Err(ErrorReturnCode::NoAction);
        }
        process.life = Life::Dormant;
        process.wait = Wait::None;
        process.suspended = false;
        process.deadline = None;
        Ok(process.thread.take())
    }

    /// SET_PRIORITY: the thread whose kernel priority must change (none while pending).
    pub fn set_priority(&mut self, slot: usize, priority: i32) -> Result<Option<u64>> {
        if slot == ERROR_HANDLER_SLOT {
            return Err(ErrorReturnCode::InvalidParam);
        }
        if !(MIN_PRIORITY_VALUE..=MAX_PRIORITY_VALUE).contains(&priority) {
            return Err(ErrorReturnCode::InvalidParam);
        }
        let mcp = self.mcp;
        let process = self.get_mut(slot)?;
        if priority >= i32::from(mcp) {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        if process.life == Life::Dormant {
            return Err(ErrorReturnCode::InvalidMode);
        }
        process.priority = priority as u8;
        Ok(process.thread)
    }

    /// GET_PROCESS_STATUS of `slot` as seen by `caller`.
    pub fn status(&self, slot: usize, caller: Option<usize>) -> Result<ApexProcessStatus> {
        let process = self.get(slot).ok_or(ErrorReturnCode::InvalidParam)?;
        let state = match process.life {
            Life::Dormant => ProcessState::Dormant,
            Life::Pending { .. } => ProcessState::Waiting,
            Life::Active if process.suspended || process.wait != Wait::None => {
                ProcessState::Waiting
            }
            Life::Active if caller == Some(slot) => ProcessState::Running,
            Life::Active => ProcessState::Ready,
        };
        let current_priority = if slot == ERROR_HANDLER_SLOT {
            MAX_PRIORITY_VALUE
        } else {
            i32::from(process.priority)
        };
        Ok(ApexProcessStatus {
            deadline_time: process
                .deadline
                .and_then(|d| i64::try_from(d).ok())
                .unwrap_or(INFINITE_TIME_VALUE),
            current_priority,
            process_state: state,
            attributes: process.attributes.clone(),
        })
    }

    /// The earliest pending deadline.
    pub fn earliest_deadline(&self) -> Option<u64> {
        self.slots
            .iter()
            .flatten()
            .filter(|p| p.life == Life::Active)
            .filter_map(|p| p.deadline)
            .min()
    }

    /// A process whose deadline passed at `now` (its deadline is cleared: one report per
    /// missed deadline; its next one is set at its next PERIODIC_WAIT or REPLENISH).
    pub fn take_missed(&mut self, now: u64) -> Option<usize> {
        let slot = (0..SLOTS).find(|&slot| {
            self.get(slot).is_some_and(|p| {
                p.life == Life::Active && p.deadline.is_some_and(|deadline| deadline <= now)
            })
        })?;
        self.slots[slot].as_mut()?.deadline = None;
        Some(slot)
    }

    fn queued_errors(&self) -> usize {
        self.errors.iter().flatten().count()
    }

    /// An error of process `from` (None: not a process): where it goes. Queued errors wait
    /// for GET_ERROR_STATUS.
    pub fn push_error(&mut self, error: PendingError, from: Option<usize>) -> Delivery {
        let Some(handler) = self.get(ERROR_HANDLER_SLOT) else {
            return Delivery::Monitor;
        };
        if !self.normal || from == Some(ERROR_HANDLER_SLOT) {
            return Delivery::Monitor;
        }
        let dormant = handler.life == Life::Dormant;
        let count = self.queued_errors();
        if count == ERROR_QUEUE {
            return Delivery::Monitor;
        }
        self.errors[(self.error_head + count) % ERROR_QUEUE] = Some(error);
        if dormant {
            Delivery::StartHandler
        } else {
            Delivery::Queued
        }
    }

    /// GET_ERROR_STATUS by `caller`: the oldest pending error.
    pub fn pop_error(&mut self, caller: Option<usize>) -> Result<PendingError> {
        if caller != Some(ERROR_HANDLER_SLOT) {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        let error = self.errors[self.error_head]
            .take()
            .ok_or(ErrorReturnCode::NoAction)?;
        self.error_head = (self.error_head + 1) % ERROR_QUEUE;
        Ok(error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codes::apex_name;

    extern "C" fn body() {}

    const MS: i64 = 1_000_000;
    const MCP: u8 = 100;

    fn attributes(name: &str, period: i64, capacity: i64, priority: i32) -> ApexProcessAttribute {
        ApexProcessAttribute {
            period,
            time_capacity: capacity,
            entry_point: body,
            stack_size: 8192,
            base_priority: priority,
            deadline: Deadline::Hard,
            name: apex_name(name),
        }
    }

    fn table() -> Table {
        Table::new(MCP, 10 * MS as u64, 1, 90, STACK_ARENA_SIZE)
    }

    #[test]
    fn create_checks_in_arinc_terms() {
        let mut t = table();
        let id = t.create(&attributes("a", 20 * MS, 5 * MS, 10)).unwrap();
        assert_eq!(id, 1);
        assert_eq!(t.find(b"a"), Ok(1));
        assert_eq!(t.find(b"b"), Err(ErrorReturnCode::InvalidConfig));
        assert_eq!(
            t.create(&attributes("a", -1, -1, 10)),
            Err(ErrorReturnCode::NoAction)
        );
        assert_eq!(
            t.create(&attributes("p", -1, -1, 0)),
            Err(ErrorReturnCode::InvalidParam)
        );
        assert_eq!(
            t.create(&attributes("p", -1, -1, i32::from(MCP))),
            Err(ErrorReturnCode::InvalidConfig)
        );
        assert_eq!(
            t.create(&attributes("p", 15 * MS, -1, 10)),
            Err(ErrorReturnCode::InvalidConfig)
        );
        let mut big = attributes("big", -1, -1, 10);
        big.stack_size = STACK_ARENA_SIZE as u32;
        assert_eq!(t.create(&big), Err(ErrorReturnCode::InvalidConfig));
        for i in 1..MAX_PROCESSES {
            let name = [b'p', b'0' + (i / 10) as u8, b'0' + (i % 10) as u8];
            let name = core::str::from_utf8(&name).unwrap();
            t.create(&attributes(name, -1, -1, 10)).unwrap();
        }
        assert_eq!(
            t.create(&attributes("full", -1, -1, 10)),
            Err(ErrorReturnCode::InvalidConfig)
        );
        t.begin_normal(0, 0);
        assert_eq!(
            t.create(&attributes("late", -1, -1, 10)),
            Err(ErrorReturnCode::InvalidMode)
        );
    }

    #[test]
    fn stacks_come_from_the_arena_as_asked() {
        let mut t = table();
        let mut big = attributes("big", -1, -1, 10);
        big.stack_size = 100_000;
        let first = t.create(&big).unwrap();
        let small = t.create(&attributes("small", -1, -1, 10)).unwrap();
        let at = |t: &Table, id| t.get(t.slot(id).unwrap()).unwrap().stack;
        // The size asked, rounded up to 16; a smaller ask still gets MIN_STACK.
        assert_eq!(
            at(&t, first),
            StackPlace {
                offset: 0,
                size: 100_000
            }
        );
        assert_eq!(
            at(&t, small),
            StackPlace {
                offset: 100_000,
                size: MIN_STACK
            }
        );
        big.stack_size = 1;
        big.name = apex_name("odd");
        assert_eq!(t.create(&big).map(|id| at(&t, id).size), Ok(MIN_STACK));
        // A stack beyond what is left is INVALID_CONFIG and takes nothing.
        let left = STACK_ARENA_SIZE - 100_000 - 2 * MIN_STACK;
        big.name = apex_name("huge");
        big.stack_size = left as u32 + 1;
        assert_eq!(t.create(&big), Err(ErrorReturnCode::InvalidConfig));
        big.stack_size = left as u32;
        let last = t.create(&big).unwrap();
        assert_eq!(at(&t, last).offset + at(&t, last).size, STACK_ARENA_SIZE);
        assert_eq!(
            t.create_error_handler(body, 0),
            Err(ErrorReturnCode::InvalidConfig)
        );
    }

    #[test]
    fn start_in_init_waits_for_normal_and_release_point() {
        let mut t = table();
        let periodic = t.create(&attributes("per", 20 * MS, 5 * MS, 10)).unwrap();
        let aperiodic = t.create(&attributes("ap", -1, -1, 20)).unwrap();
        let unstarted = t.create(&attributes("idle", -1, -1, 20)).unwrap();
        let s = t.check_start(periodic, 0).unwrap();
        t.make_pending(s, 0, 11).unwrap();
        let s = t.check_start(aperiodic, 3).unwrap();
        t.make_pending(s, 3, 12).unwrap();
        assert_eq!(t.check_start(periodic, 0), Err(ErrorReturnCode::NoAction));
        assert_eq!(
            t.status(0, None).unwrap().process_state,
            ProcessState::Waiting
        );
        let started = t.begin_normal(1_000, 5_000);
        assert_eq!(started, 0b11);
        let p = t.get(0).unwrap();
        assert_eq!(
            (p.release, p.deadline),
            (5_000, Some(5_000 + 5 * MS as u64))
        );
        let a = t.get(1).unwrap();
        assert_eq!((a.release, a.deadline), (1_003, None));
        assert_eq!(
            t.slot(unstarted).map(|s| t.get(s).unwrap().life),
            Ok(Life::Dormant)
        );
        assert_eq!(t.slot_of_thread(12), Some(1));
        assert_eq!(t.priority_of_thread(12), 20);
        assert_eq!(t.priority_of_thread(1), 90);
        assert_eq!(t.priority_of_thread(999), MCP);
    }

    #[test]
    fn start_delay_checks() {
        let mut t = table();
        let id = t.create(&attributes("per", 20 * MS, -1, 10)).unwrap();
        assert_eq!(t.check_start(id, -1), Err(ErrorReturnCode::InvalidParam));
        assert_eq!(
            t.check_start(id, 20 * MS),
            Err(ErrorReturnCode::InvalidParam)
        );
        assert_eq!(t.check_start(id, 19 * MS), Ok(0));
        assert_eq!(t.check_start(5, 0), Err(ErrorReturnCode::InvalidParam));
        assert_eq!(t.check_start(0, 0), Err(ErrorReturnCode::InvalidParam));
    }

    #[test]
    fn periodic_wait_moves_release_and_deadline() {
        let mut t = table();
        let id = t.create(&attributes("per", 20 * MS, 5 * MS, 10)).unwrap();
        let slot = t.check_start(id, 0).unwrap();
        t.begin_normal(0, 0);
        t.activate(slot, 100, 7).unwrap();
        t.released(slot);
        assert_eq!(
            t.status(slot, Some(slot)).unwrap().process_state,
            ProcessState::Running
        );
        assert_eq!(
            t.status(slot, None).unwrap().process_state,
            ProcessState::Ready
        );
        let next = t.periodic_wait(slot).unwrap();
        assert_eq!(next, 100 + 20 * MS as u64);
        assert_eq!(t.get(slot).unwrap().deadline, Some(next + 5 * MS as u64));
        assert_eq!(
            t.status(slot, Some(slot)).unwrap().process_state,
            ProcessState::Waiting
        );
        t.released(slot);
        assert_eq!(t.get(slot).unwrap().wait, Wait::None);
        // Aperiodic processes cannot PERIODIC_WAIT.
        let mut t = table();
        let ap = t.create(&attributes("ap", -1, -1, 10)).unwrap();
        let s = t.slot(ap).unwrap();
        assert_eq!(t.periodic_wait(s), Err(ErrorReturnCode::InvalidMode));
    }

    #[test]
    fn deadlines_are_reported_once() {
        let mut t = table();
        let id = t.create(&attributes("per", 20 * MS, 5 * MS, 10)).unwrap();
        let slot = t.slot(id).unwrap();
        t.begin_normal(0, 0);
        t.activate(slot, 1_000, 7).unwrap();
        let deadline = 1_000 + 5 * MS as u64;
        assert_eq!(t.earliest_deadline(), Some(deadline));
        assert!(t.needs_watchdog());
        assert_eq!(t.take_missed(deadline - 1), None);
        assert_eq!(t.take_missed(deadline), Some(slot));
        assert_eq!(t.take_missed(deadline + 1), None);
        assert_eq!(t.earliest_deadline(), None);
        // The next PERIODIC_WAIT sets the next job's deadline.
        let next = t.periodic_wait(slot).unwrap();
        assert_eq!(t.earliest_deadline(), Some(next + 5 * MS as u64));
    }

    #[test]
    fn replenish_rules() {
        let mut t = table();
        let id = t.create(&attributes("per", 20 * MS, 5 * MS, 10)).unwrap();
        let slot = t.slot(id).unwrap();
        assert_eq!(t.replenish(slot, MS, 0), Err(ErrorReturnCode::NoAction));
        t.begin_normal(0, 0);
        t.activate(slot, 0, 7).unwrap();
        assert_eq!(t.replenish(slot, 2 * MS, MS as u64), Ok(()));
        assert_eq!(t.get(slot).unwrap().deadline, Some(3 * MS as u64));
        assert_eq!(
            t.replenish(slot, 20 * MS, MS as u64),
            Err(ErrorReturnCode::InvalidMode)
        );
        assert_eq!(t.replenish(slot, -1, 0), Err(ErrorReturnCode::InvalidMode));
    }

    #[test]
    fn suspend_resume_stop() {
        let mut t = table();
        let a = t.create(&attributes("a", -1, -1, 10)).unwrap();
        let b = t.create(&attributes("b", -1, -1, 10)).unwrap();
        let (sa, sb) = (t.slot(a).unwrap(), t.slot(b).unwrap());
        t.begin_normal(0, 0);
        assert_eq!(t.suspend(sb, Some(sa)), Err(ErrorReturnCode::InvalidMode));
        assert_eq!(t.resume(sb), Err(ErrorReturnCode::InvalidMode));
        t.activate(sa, 0, 21).unwrap();
        t.activate(sb, 0, 22).unwrap();
        t.released(sb);
        assert_eq!(t.suspend(sa, Some(sa)), Err(ErrorReturnCode::InvalidParam));
        assert_eq!(t.suspend(sb, Some(sa)), Ok(22));
        assert_eq!(t.suspend(sb, Some(sa)), Err(ErrorReturnCode::NoAction));
        assert_eq!(
            t.status(sb, Some(sa)).unwrap().process_state,
            ProcessState::Waiting
        );
        assert_eq!(
            t.resume(sb),
            Ok(Resume {
                thread: 22,
                notify: false,
                kernel_resume: true
            })
        );
        assert_eq!(t.resume(sb), Err(ErrorReturnCode::NoAction));
        // SUSPEND_SELF with a time-out: RESUME wakes it by notification.
        assert_eq!(t.suspend_self(sb, 0), Ok(false));
        assert_eq!(t.suspend_self(sb, 5), Ok(true));
        let r = t.resume(sb).unwrap();
        assert!(r.notify && !r.kernel_resume);
        assert_eq!(t.suspend_self_end(sb, true), (Ok(()), false));
        // Timed out: TIMED_OUT.
        t.suspend_self(sb, 5).unwrap();
        assert_eq!(
            t.suspend_self_end(sb, false),
            (Err(ErrorReturnCode::TimedOut), false)
        );
        // Resumed just as it timed out: success, and a stale notification to consume.
        t.suspend_self(sb, 5).unwrap();
        t.resume(sb).unwrap();
        assert_eq!(t.suspend_self_end(sb, false), (Ok(()), true));
        // STOP.
        assert_eq!(t.stop(sb), Ok(Some(22)));
        assert_eq!(t.stop(sb), Err(ErrorReturnCode::NoAction));
        assert_eq!(t.slot_of_thread(22), None);
        assert_eq!(
            t.status(sb, None).unwrap().process_state,
            ProcessState::Dormant
        );
        assert_eq!(t.check_start(b, 0), Ok(sb));
    }

    #[test]
    fn set_priority_rules() {
        let mut t = table();
        let a = t.create(&attributes("a", -1, -1, 10)).unwrap();
        let s = t.slot(a).unwrap();
        assert_eq!(t.set_priority(s, 20), Err(ErrorReturnCode::InvalidMode));
        t.begin_normal(0, 0);
        t.activate(s, 0, 5).unwrap();
        assert_eq!(t.set_priority(s, 0), Err(ErrorReturnCode::InvalidParam));
        assert_eq!(
            t.set_priority(s, i32::from(MCP)),
            Err(ErrorReturnCode::InvalidConfig)
        );
        assert_eq!(t.set_priority(s, 42), Ok(Some(5)));
        assert_eq!(t.status(s, None).unwrap().current_priority, 42);
        assert_eq!(t.priority_of_thread(5), 42);
        // START resets the current priority to the base priority.
        t.stop(s).unwrap();
        t.activate(s, 0, 6).unwrap();
        assert_eq!(t.priority_of_thread(6), 10);
    }

    #[test]
    fn errors_go_to_the_handler_only_in_normal_mode() {
        let mut t = table();
        let a = t.create(&attributes("a", -1, -1, 10)).unwrap();
        let sa = t.slot(a).unwrap();
        let error = PendingError::new(ErrorCode::ApplicationError, a, b"boom");
        assert_eq!(t.push_error(error, Some(sa)), Delivery::Monitor);
        t.create_error_handler(body, 4096).unwrap();
        assert_eq!(
            t.create_error_handler(body, 4096),
            Err(ErrorReturnCode::NoAction)
        );
        assert_eq!(t.push_error(error, Some(sa)), Delivery::Monitor);
        t.begin_normal(0, 0);
        assert_eq!(
            t.create_error_handler(body, 4096),
            Err(ErrorReturnCode::InvalidMode)
        );
        assert_eq!(t.push_error(error, Some(sa)), Delivery::StartHandler);
        t.activate_error_handler(0, 99).unwrap();
        assert_eq!(t.priority_of_thread(99), MCP);
        assert_eq!(t.push_error(error, Some(sa)), Delivery::Queued);
        assert_eq!(
            t.push_error(error, Some(ERROR_HANDLER_SLOT)),
            Delivery::Monitor
        );
        assert_eq!(t.pop_error(Some(sa)), Err(ErrorReturnCode::InvalidConfig));
        let got = t.pop_error(Some(ERROR_HANDLER_SLOT)).unwrap();
        assert_eq!(
            (got.code, got.process, got.text()),
            (ErrorCode::ApplicationError, a, &b"boom"[..])
        );
        t.pop_error(Some(ERROR_HANDLER_SLOT)).unwrap();
        assert_eq!(
            t.pop_error(Some(ERROR_HANDLER_SLOT)),
            Err(ErrorReturnCode::NoAction)
        );
        for _ in 0..ERROR_QUEUE {
            assert_eq!(t.push_error(error, Some(sa)), Delivery::Queued);
        }
        assert_eq!(t.push_error(error, Some(sa)), Delivery::Monitor);
        assert_eq!(ERROR_HANDLER_SLOT, SLOTS - 1);
        assert_eq!(slot_of(id_of(ERROR_HANDLER_SLOT)), Some(ERROR_HANDLER_SLOT));
        assert_eq!(slot_of(0), None);
        assert_eq!(slot_of(-1), None);
        assert_eq!(slot_of(SLOTS as i64 + 1), None);
    }
}
