//! The scan cycle, as pure logic over a port interface ([`PortIo`]) and a clock, so the
//! whole behaviour is tested on the host; `main.rs` only supplies the APEX ports, time and
//! processes.
//!
//! Every IEC task runs in an APEX process of its own, released at window starts every
//! `INTERVAL / period` partition periods ([`Schedule`]; a program without a CONFIGURATION
//! every period; an event task, `SINGLE`, every period, running only after its trigger
//! rose), with a process priority by its IEC priority ([`Schedule::process_priorities`]).
//! One release (a window start) is:
//! 1. [`Runtime::begin_release`], by whichever process runs first at it: read every input
//!    port once into `%I` (with its validity bit), copy the `%I` and `%M` located variables
//!    in ([`plc_vm::located::copy_in`]) and sample the event tasks' triggers;
//! 2. [`Runtime::run_task`], by each task's process released at it, in priority order
//!    (IEC: the lowest PRIORITY number first; ties in declaration order): one cycle under
//!    two watchdogs, the VM's instruction budget (trap WATCHDOG) and, where the
//!    configuration gives the task one (`plc.deadline`, as CODESYS's task watchdog time),
//!    its time deadline (trap DEADLINE: the release time plus the deadline); on the
//!    interpreter or, when the program runs natively ([`Runtime::set_native`],
//!    [`crate::tier`]), on its native code, with the same semantics;
//! 3. [`Runtime::end_release`], by the control process after them: copy the `%Q` and `%M`
//!    located variables out and send every output port's bytes.
//!
//! [`Runtime::scan`] is all three for every due task, as the processes do them when they
//! are released together.
//!
//! A task that traps (or exhausts its budget: `WATCHDOG`, or passes its deadline:
//! `DEADLINE`) is stopped: its program instance's located `%Q` variables and the global
//! ones are set to their safe values (configured per variable, zero/FALSE otherwise;
//! [`safe_outputs`]) in the same cycle, before the outputs are sent; the other tasks go
//! on. The caller reports the fault to the health monitor as the ARINC error
//! [`health_error`] names. An online STOP stops a task the same way
//! ([`Runtime::stop_task`]); START ([`Runtime::start_task`]) lets a stopped task run again
//! from the next release, whatever stopped it.
//!
//! Per task the runtime keeps [`TaskStats`]: activations, execution time (last, min, max,
//! mean), release jitter (the cycle's start minus the release time, i.e. the window start),
//! overruns (an execution longer than the task's interval) and faults. Per release it keeps
//! histograms ([`Histogram`]) of the lateness (the release's first start minus the release
//! time) and of its own work: the time in steps 1-3 besides the VM's (ports, process
//! image, statistics). The first release, which follows the partition's start rather than
//! a window start, is left out of the lateness figures.

use crate::histogram::Histogram;
use crate::package::{Package, SafeValue};
use plc_vm::image::Image;
use plc_vm::isa::Trap;
use plc_vm::located::{self, Area, MAX_AREA};
use plc_vm::native::NativeProgram;
use plc_vm::vm::{Fault, Machine};
use protocol::{Direction, ErrorCode};

/// Most IEC tasks (the verifier's limit).
pub const MAX_TASKS: usize = plc_vm::verify::MAX_TASKS;

/// The process image: input, output and marker areas.
pub struct Areas {
    pub input: [u8; MAX_AREA as usize],
    pub output: [u8; MAX_AREA as usize],
    pub memory: [u8; MAX_AREA as usize],
}

impl Areas {
    pub const fn new() -> Self {
        Self {
            input: [0; MAX_AREA as usize],
            output: [0; MAX_AREA as usize],
            memory: [0; MAX_AREA as usize],
        }
    }

    /// The bytes of `area`.
    pub fn area(&self, area: Area) -> &[u8] {
        match area {
            Area::Input => &self.input,
            Area::Output => &self.output,
            Area::Memory => &self.memory,
        }
    }

    /// The bytes of `area`, to write.
    pub fn area_mut(&mut self, area: Area) -> &mut [u8] {
        match area {
            Area::Input => &mut self.input,
            Area::Output => &mut self.output,
            Area::Memory => &mut self.memory,
        }
    }
}

impl Default for Areas {
    fn default() -> Self {
        Self::new()
    }
}

/// The partition's ports, by their index in the package.
pub trait PortIo {
    /// The next message of input port `port` into `buf`: its length and whether it is
    /// fresh (a sampling message within its refresh period, or a queued message), or
    /// `None` when there is none.
    fn receive(&mut self, port: usize, buf: &mut [u8]) -> Option<(usize, bool)>;
    /// Sends `message` on output port `port`.
    fn send(&mut self, port: usize, message: &[u8]);
}

/// Puts `bytes` of `area`, written between releases by a network service (a Modbus
/// write), into the located variables they overlap at once. The process image alone
/// would not do: when the control process is behind (a cycle outlasted the window), it
/// ends the same release a second time before the next one begins, and that end copies
/// the variables' old values back over the image.
pub fn take_written(
    image: &Image,
    area: Area,
    bytes: core::ops::Range<usize>,
    areas: &Areas,
    machine: &mut Machine,
) {
    let overlaps = |v: &located::Located| {
        let from = v.location.byte as usize;
        let width = v.location.width.bytes() as usize;
        v.location.area == area && from < bytes.end && bytes.start < from + width
    };
    located::copy_in(
        image.located_vars().filter(overlaps),
        area,
        areas.area(area),
        machine.data_mut(),
    );
}

/// Reads every input port into `%I` and sets its validity bit (cleared when the port gave
/// no fresh message; the bytes then stay as last received).
pub fn read_inputs(package: &Package, io: &mut impl PortIo, areas: &mut Areas) {
    for (i, port) in package.ports().enumerate() {
        if port.direction != Direction::In || !package.is_image_port(i) {
            continue;
        }
        let at = port.area_offset as usize;
        let slot = &mut areas.input[at..at + port.size as usize];
        let fresh = io.receive(i, slot).is_some_and(|(_, fresh)| fresh);
        if let Some((byte, bit)) = port.valid {
            let b = &mut areas.input[byte as usize];
            *b = if fresh {
                *b | 1 << bit
            } else {
                *b & !(1 << bit)
            };
        }
    }
}

/// Sends every output port's bytes of `%Q`.
pub fn write_outputs(package: &Package, io: &mut impl PortIo, areas: &Areas) {
    for (i, port) in package.ports().enumerate() {
        if port.direction == Direction::Out && package.is_image_port(i) {
            let at = port.area_offset as usize;
            io.send(i, &areas.output[at..at + port.size as usize]);
        }
    }
}

/// The ARINC 653 error a task's trap is reported as: arithmetic faults are
/// NUMERIC_ERROR, the two watchdogs (instruction budget, time deadline) DEADLINE_MISSED,
/// every other programming error APPLICATION_ERROR.
pub fn health_error(trap: Trap) -> ErrorCode {
    match trap {
        Trap::DivisionByZero | Trap::NumericError => ErrorCode::NumericError,
        Trap::Watchdog | Trap::Deadline => ErrorCode::DeadlineMissed,
        Trap::IndexOutOfBounds
        | Trap::SubrangeViolation
        | Trap::CallDepth
        | Trap::StackOverflow
        | Trap::InvalidAddress
        | Trap::InvalidReference => ErrorCode::ApplicationError,
    }
}

/// Whether a configured task name (`plc.deadline`) names the image's task `image_task`:
/// image tasks are `<TASK>.<program instance>` (one per program the TASK runs), and the
/// configuration may name the TASK (all its programs) or one of them, case-insensitively as
/// IEC identifiers are.
pub fn names_task(configured: &str, image_task: &str) -> bool {
    let task = image_task.split('.').next().unwrap_or(image_task);
    configured.eq_ignore_ascii_case(image_task) || configured.eq_ignore_ascii_case(task)
}

/// Whether a configured task name names some task of `image` (see [`names_task`]).
pub fn has_task(image: &Image, configured: &str) -> bool {
    (0..image.task_count())
        .filter_map(|i| image.task(i))
        .any(|t| names_task(configured, t.name))
}

/// [`Schedule::deadline`] of a task without a time deadline.
pub const NO_DEADLINE: u64 = u64::MAX;

/// Why a program cannot run in this partition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanError {
    /// A cyclic task's INTERVAL is not a positive multiple of the partition's period.
    IntervalNotMultiple { task: usize, interval_ns: u64 },
    /// An event (SINGLE) task whose image names no trigger variable.
    EventTask { task: usize },
    /// No cyclic task at all.
    NoTasks,
    /// More tasks than the partition has processes for.
    TooManyTasks { count: usize },
}

impl core::fmt::Display for PlanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PlanError::IntervalNotMultiple { task, interval_ns } => write!(
                f,
                "task {task}'s INTERVAL of {interval_ns} ns is not a positive multiple of the partition's period"
            ),
            PlanError::EventTask { task } => {
                write!(f, "event task {task} names no trigger variable")
            }
            PlanError::NoTasks => write!(f, "the program has no task"),
            PlanError::TooManyTasks { count } => write!(
                f,
                "{count} tasks, but a PLC partition runs at most {MAX_TASK_PROCESSES} (one APEX process each)"
            ),
        }
    }
}

/// Most IEC tasks a PLC partition runs: one APEX process each, beside the control process
/// (`apex::table::MAX_PROCESSES` in all).
pub const MAX_TASK_PROCESSES: usize = 15;

/// When each task runs: a cyclic one every `every[i]` releases of the partition (its process's period), an
/// event one (`every[i] == 0`) on a rising edge of the BOOL at `trigger[i]`; by when it must
/// be done: `deadline[i]` ns after its release ([`NO_DEADLINE`]: only the instruction
/// budget watches it).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Schedule {
    pub every: [u64; MAX_TASKS],
    pub trigger: [Option<u32>; MAX_TASKS],
    /// Time from the release to the task's deadline (ns), [`NO_DEADLINE`] without one.
    pub deadline: [u64; MAX_TASKS],
    /// Tasks in the order they run within a release.
    pub order: [usize; MAX_TASKS],
    pub count: usize,
}

impl Schedule {
    /// The schedule of `image`'s tasks for a partition released every `period_ns`.
    pub fn new(image: &Image, period_ns: u64) -> Result<Self, PlanError> {
        let count = image.task_count().min(MAX_TASKS);
        if count == 0 {
            return Err(PlanError::NoTasks);
        }
        if image.task_count() > MAX_TASK_PROCESSES {
            return Err(PlanError::TooManyTasks {
                count: image.task_count(),
            });
        }
        let mut every = [0u64; MAX_TASKS];
        let mut trigger = [None; MAX_TASKS];
        let mut order = [0usize; MAX_TASKS];
        for (i, slot) in every.iter_mut().enumerate().take(count) {
            let Some(task) = image.task(i) else {
                return Err(PlanError::NoTasks);
            };
            order[i] = i;
            if task.kind != 0 {
                trigger[i] = Some(task.trigger.ok_or(PlanError::EventTask { task: i })?);
                continue;
            }
            let interval = task.interval_ns;
            if period_ns == 0 || interval % period_ns != 0 {
                return Err(PlanError::IntervalNotMultiple {
                    task: i,
                    interval_ns: interval,
                });
            }
            // A program without a CONFIGURATION has one task of interval 0: every release.
            *slot = (interval / period_ns).max(1);
        }
        let priority = |i: usize| image.task(i).map_or(u8::MAX, |t| t.priority);
        order[..count].sort_unstable_by_key(|&i| (priority(i), i));
        Ok(Self {
            every,
            trigger,
            deadline: [NO_DEADLINE; MAX_TASKS],
            order,
            count,
        })
    }

    /// The APEX process priorities of the partition's processes, for a partition whose MCP
    /// is `mcp`: each task's by its place in [`Schedule::order`] (IEC priority, then
    /// declaration order), from just below the MCP down, one step per task, so that tasks
    /// released together run in that order; and the control process's, below all of them.
    /// None goes below 2 (the control process below 1).
    pub fn process_priorities(&self, mcp: u8) -> ([u8; MAX_TASKS], u8) {
        let top = mcp.saturating_sub(1).max(2);
        let mut priority = [0u8; MAX_TASKS];
        let mut lowest = top;
        for (rank, &task) in self.order[..self.count].iter().enumerate() {
            let p = top.saturating_sub(rank.min(u8::MAX as usize) as u8).max(2);
            priority[task] = p;
            lowest = lowest.min(p);
        }
        (priority, lowest.saturating_sub(1).max(1))
    }

    /// The period of task `task`'s process: its INTERVAL (a multiple of the partition's
    /// period), or the partition's period for an event task (it looks at its trigger at
    /// every release).
    pub fn process_period(&self, task: usize, period_ns: u64) -> u64 {
        self.every[task].max(1).saturating_mul(period_ns)
    }

    /// The schedule with the package's configured task deadlines (see [`names_task`]).
    pub fn with_deadlines(mut self, image: &Image, package: &Package) -> Self {
        for (i, slot) in self.deadline.iter_mut().enumerate().take(self.count) {
            let Some(task) = image.task(i) else { continue };
            if let Some(d) = package.deadlines().find(|d| names_task(d.task, task.name)) {
                *slot = d.deadline_ns;
            }
        }
        self
    }

    /// Whether cyclic task `task` runs at release number `release` (0 = the first).
    pub fn due(&self, task: usize, release: u64) -> bool {
        self.every[task] != 0 && release.is_multiple_of(self.every[task])
    }
}

/// Statistics of one task (times in ns).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TaskStats {
    pub count: u64,
    pub last: u64,
    pub min: u64,
    pub max: u64,
    pub total: u64,
    pub last_jitter: u64,
    pub max_jitter: u64,
    pub overruns: u64,
    pub faults: u64,
}

impl TaskStats {
    /// No activation yet.
    pub const ZERO: TaskStats = TaskStats {
        count: 0,
        last: 0,
        min: 0,
        max: 0,
        total: 0,
        last_jitter: 0,
        max_jitter: 0,
        overruns: 0,
        faults: 0,
    };

    fn record(&mut self, exec: u64, jitter: u64, interval: u64) {
        self.min = if self.count == 0 {
            exec
        } else {
            self.min.min(exec)
        };
        self.count += 1;
        self.last = exec;
        self.max = self.max.max(exec);
        self.total = self.total.saturating_add(exec);
        self.last_jitter = jitter;
        self.max_jitter = self.max_jitter.max(jitter);
        if exec > interval {
            self.overruns += 1;
        }
    }

    /// Mean execution time.
    pub fn mean(&self) -> u64 {
        self.total.checked_div(self.count).unwrap_or(0)
    }
}

/// Most configured safe values (`plc.safe`) a package may hold.
pub const MAX_SAFE_VALUES: usize = 64;

/// The safe values of the running program's `%Q` variables (by data address): the
/// package's for the configured program, re-resolved by name for a downloaded one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SafeValues {
    values: [SafeValue; MAX_SAFE_VALUES],
    count: usize,
}

impl SafeValues {
    pub const fn new() -> Self {
        Self {
            values: [SafeValue {
                address: 0,
                width: 0,
                value: 0,
            }; MAX_SAFE_VALUES],
            count: 0,
        }
    }

    /// The package's safe values (a checked package holds at most [`MAX_SAFE_VALUES`]).
    pub fn of(package: &Package) -> Self {
        let mut out = Self::new();
        for v in package.safe_values() {
            out.push(v);
        }
        out
    }

    /// Adds one; `false` when full.
    pub fn push(&mut self, value: SafeValue) -> bool {
        let Some(slot) = self.values.get_mut(self.count) else {
            return false;
        };
        *slot = value;
        self.count += 1;
        true
    }

    pub fn iter(&self) -> impl Iterator<Item = SafeValue> + '_ {
        self.values[..self.count].iter().copied()
    }
}

impl Default for SafeValues {
    fn default() -> Self {
        Self::new()
    }
}

/// Why a task is stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// It trapped or its watchdog expired.
    Fault(Fault),
    /// An online STOP.
    Requested,
}

impl Stop {
    /// The fault, if a fault stopped the task.
    pub fn fault(self) -> Option<Fault> {
        match self {
            Stop::Fault(f) => Some(f),
            Stop::Requested => None,
        }
    }
}

/// Significant bits of the release-lateness histogram the `period` log line carries
/// ([`Histogram::bins`]): bins a quarter of their values wide.
pub const LATENESS_BITS: u32 = 3;

/// What the runtime keeps between releases.
pub struct Runtime {
    pub schedule: Schedule,
    pub stats: [TaskStats; MAX_TASKS],
    /// Stopped tasks and why.
    pub stopped: [Option<Stop>; MAX_TASKS],
    /// The running program's safe values.
    pub safe: SafeValues,
    /// Release instants begun ([`Runtime::begin_release`]).
    pub releases: u64,
    /// Release lateness: the first start at an instant minus its release time.
    pub lateness: Histogram,
    /// The same since the last statistics line (whoever prints that line clears it).
    pub recent_lateness: Histogram,
    /// The runtime's own work per release instant besides the VM's.
    pub overhead: Histogram,
    period_ns: u64,
    /// Each event task's trigger as sampled at the previous release.
    armed: [bool; MAX_TASKS],
    /// Event tasks whose trigger rose at the current release, until they ran.
    triggered: [bool; MAX_TASKS],
    /// The current release instant.
    instant: Option<u64>,
    /// The runtime's own work at the current instant so far (ns).
    own_work: u64,
    /// The running program's native code (`None`: the interpreter runs it).
    native: Option<&'static NativeProgram>,
}

impl Runtime {
    pub fn new(schedule: Schedule, period_ns: u64, safe: SafeValues) -> Self {
        let mut rt = Self::idle();
        rt.restart(schedule, period_ns, safe);
        rt
    }

    /// A runtime with no task (a static's initial value).
    pub const fn idle() -> Self {
        Self {
            schedule: Schedule {
                every: [0; MAX_TASKS],
                trigger: [None; MAX_TASKS],
                deadline: [NO_DEADLINE; MAX_TASKS],
                order: [0; MAX_TASKS],
                count: 0,
            },
            stats: [TaskStats::ZERO; MAX_TASKS],
            stopped: [None; MAX_TASKS],
            safe: SafeValues::new(),
            releases: 0,
            lateness: Histogram::new(),
            recent_lateness: Histogram::new(),
            overhead: Histogram::new(),
            period_ns: 0,
            armed: [false; MAX_TASKS],
            triggered: [false; MAX_TASKS],
            instant: None,
            own_work: 0,
            native: None,
        }
    }

    /// Starts over with a program's schedule and safe values, in place (a runtime is large
    /// for a partition's process stacks).
    pub fn restart(&mut self, schedule: Schedule, period_ns: u64, safe: SafeValues) {
        self.schedule = schedule;
        self.stats.fill(TaskStats::ZERO);
        self.stopped.fill(None);
        self.safe = safe;
        self.releases = 0;
        self.lateness.clear();
        self.recent_lateness.clear();
        self.overhead.clear();
        self.period_ns = period_ns;
        self.armed.fill(false);
        self.triggered.fill(false);
        self.instant = None;
        self.own_work = 0;
        self.native = None;
    }

    /// Runs the program's task cycles on its native code (`None`: on the interpreter), from
    /// the next cycle on; see [`crate::tier`].
    pub fn set_native(&mut self, native: Option<&'static NativeProgram>) {
        self.native = native;
    }

    /// One release of every due task in priority order, as the task processes run it when
    /// they are released together: [`begin_release`](Self::begin_release), each due task's
    /// [`run_task`](Self::run_task), [`end_release`](Self::end_release). `release_ns` is
    /// when it was due (its window start), `clock` the partition's time in ns (also the
    /// program's `NOW`). Calls `on_fault` for each task that faulted in this release.
    // One release touches everything the cycle involves; a bundle would only rename them.
    #[allow(clippy::too_many_arguments)]
    pub fn scan(
        &mut self,
        machine: &mut Machine,
        image: &Image,
        package: &Package,
        io: &mut impl PortIo,
        areas: &mut Areas,
        mut clock: impl FnMut() -> u64,
        release_ns: u64,
        mut on_fault: impl FnMut(usize, &Fault),
    ) {
        // Always a new instant, even at the same release time.
        self.instant = None;
        self.begin_release(machine, image, package, io, areas, &mut clock, release_ns);
        let instant = self.releases - 1;
        for i in 0..self.schedule.count {
            let task = self.schedule.order[i];
            if self.schedule.trigger[task].is_some() || self.schedule.due(task, instant) {
                self.run_task(task, machine, image, &mut clock, release_ns, &mut on_fault);
            }
        }
        self.end_release(machine, image, package, io, areas, &mut clock);
    }

    /// The start of the release instant `release_ns` (a window start), by whichever process
    /// of the partition runs first at it; nothing when it has begun already: every input
    /// port's message into `%I` with its validity bit, the `%I` and `%M` variables into the
    /// program's data, the event tasks' triggers sampled (after the inputs are in), the
    /// lateness recorded. True when it began the instant.
    #[allow(clippy::too_many_arguments)]
    pub fn begin_release(
        &mut self,
        machine: &mut Machine,
        image: &Image,
        package: &Package,
        io: &mut impl PortIo,
        areas: &mut Areas,
        mut clock: impl FnMut() -> u64,
        release_ns: u64,
    ) -> bool {
        if self.instant == Some(release_ns) {
            return false;
        }
        let start = clock();
        // The first release follows the partition's start (NORMAL mode), not a window
        // start: its lateness says nothing about the release path.
        if self.releases > 0 {
            self.lateness.record(start.saturating_sub(release_ns));
            self.recent_lateness
                .record(start.saturating_sub(release_ns));
        }
        read_inputs(package, io, areas);
        let vars = || image.located_vars();
        if self.releases == 0 {
            // The marker area starts with the markers' initial values, not zeros.
            located::copy_out(vars(), Area::Memory, machine.data(), &mut areas.memory);
        }
        located::copy_in(vars(), Area::Input, &areas.input, machine.data_mut());
        located::copy_in(vars(), Area::Memory, &areas.memory, machine.data_mut());
        for &task in &self.schedule.order[..self.schedule.count] {
            if let Some(at) = self.schedule.trigger[task] {
                let set = machine.data().get(at as usize).is_some_and(|&b| b != 0);
                self.triggered[task] |= set && !self.armed[task];
                self.armed[task] = set;
            }
        }
        self.instant = Some(release_ns);
        self.releases += 1;
        self.own_work = clock().saturating_sub(start);
        true
    }

    /// One cycle of `task`, released at `release_ns` (a cyclic task is due whenever its
    /// process is released; an event task only when its trigger rose since it last ran):
    /// run under its watchdogs, its statistics kept; a task that faults is stopped, its
    /// outputs set safe at once and `on_fault` called. Nothing for a stopped task.
    pub fn run_task(
        &mut self,
        task: usize,
        machine: &mut Machine,
        image: &Image,
        mut clock: impl FnMut() -> u64,
        release_ns: u64,
        mut on_fault: impl FnMut(usize, &Fault),
    ) {
        if task >= self.schedule.count || self.stopped[task].is_some() {
            return;
        }
        if self.schedule.trigger[task].is_some() && !core::mem::take(&mut self.triggered[task]) {
            return;
        }
        let t0 = clock();
        // Deadlines count from the release, as ARINC process deadlines do: a task that
        // waited behind others has less of its time left.
        let deadline = release_ns.saturating_add(self.schedule.deadline[task]);
        let timed = self.schedule.deadline[task] != NO_DEADLINE;
        let expired = || timed && clock() > deadline;
        let result = match self.native {
            Some(program) => machine.run_cycle_native(task, t0 as i64, expired, program),
            None => machine.run_cycle_until(task, t0 as i64, expired),
        };
        let t1 = clock();
        let exec = t1.saturating_sub(t0);
        // An event task has no interval: it overruns when it outlasts the period.
        let interval = self.schedule.every[task]
            .max(1)
            .saturating_mul(self.period_ns);
        let jitter = if self.releases > 1 {
            t0.saturating_sub(release_ns)
        } else {
            0
        };
        self.stats[task].record(exec, jitter, interval);
        if let Err(fault) = result {
            self.stats[task].faults += 1;
            self.stopped[task] = Some(Stop::Fault(fault));
            safe_outputs(image, &self.safe, task, machine.data_mut());
            on_fault(task, &fault);
        }
        self.own_work += clock().saturating_sub(t1);
    }

    /// The end of the current release instant, by the lowest-priority process after every
    /// task released at it: the `%Q` and `%M` variables out and every output port's bytes
    /// sent; the runtime's own work at this instant recorded.
    pub fn end_release(
        &mut self,
        machine: &mut Machine,
        image: &Image,
        package: &Package,
        io: &mut impl PortIo,
        areas: &mut Areas,
        mut clock: impl FnMut() -> u64,
    ) {
        let start = clock();
        let vars = || image.located_vars();
        located::copy_out(vars(), Area::Output, machine.data(), &mut areas.output);
        located::copy_out(vars(), Area::Memory, machine.data(), &mut areas.memory);
        write_outputs(package, io, areas);
        if self.instant.is_some() {
            let own = self.own_work + clock().saturating_sub(start);
            self.overhead.record(own);
            self.own_work = 0;
        }
    }

    /// Whether some task runs (is not stopped): the PLC is in RUN for its network
    /// services (Modbus answers exception 4 when none does; a publication goes out only
    /// while one does).
    pub fn any_task_running(&self) -> bool {
        self.stopped[..self.schedule.count]
            .iter()
            .any(|stop| stop.is_none())
    }

    /// Online STOP: `task` runs no more and its outputs go to their safe values now (the
    /// process image takes them at the end of the next release, as after a fault). `false`
    /// when there is no such task. Stopping a stopped task keeps why it stopped.
    pub fn stop_task(&mut self, task: usize, machine: &mut Machine) -> bool {
        if task >= self.schedule.count {
            return false;
        }
        if self.stopped[task].is_none() {
            self.stopped[task] = Some(Stop::Requested);
        }
        let image = *machine.image();
        safe_outputs(&image, &self.safe, task, machine.data_mut());
        true
    }

    /// Online START: a stopped task (by STOP, a trap or its watchdog) runs again from the
    /// next release that is due for it; its data keeps its values (a CODESYS task reset).
    /// `false` when there is no such task.
    pub fn start_task(&mut self, task: usize, machine: &mut Machine) -> bool {
        if task >= self.schedule.count {
            return false;
        }
        self.stopped[task] = None;
        machine.reset_task(task);
        true
    }
}

/// Sets the outputs of a faulted task safe: every located `%Q` variable of its program
/// instance and every global one (globals may be shared with tasks that still run; those
/// write them again in their next cycles) gets its configured safe value, zero/FALSE
/// without one.
pub fn safe_outputs(image: &Image, safe: &SafeValues, task: usize, data: &mut [u8]) {
    let Some(t) = image.task(task) else {
        return;
    };
    let span = |t: &plc_vm::image::Task| {
        let frame = image.pou(t.pou as usize).map_or(0, |p| p.frame_size);
        t.instance_base as u64..t.instance_base as u64 + frame as u64
    };
    let own = span(&t);
    let in_some_instance = |a: u64| {
        (0..image.task_count())
            .filter_map(|i| image.task(i))
            .any(|t| span(&t).contains(&a))
    };
    for v in image.located_vars() {
        let address = v.address as u64;
        let global = !in_some_instance(address);
        if v.location.area != Area::Output || !(own.contains(&address) || global) {
            continue;
        }
        let width = v.location.width.bytes() as usize;
        let value = safe
            .iter()
            .find(|s| s.address == v.address)
            .map_or(0, |s| s.value);
        let at = v.address as usize;
        if let Some(bytes) = data.get_mut(at..at + width) {
            bytes.copy_from_slice(&value.to_le_bytes()[..width]);
        }
    }
}

/// Copies every RETAIN variable of `new_image` that `old_image` also has (same name and
/// type) from `old_data` into `new_data`: the values a warm restart (same image) or an
/// online download (a changed one) keeps. Same size: the bytes; a STRING or WSTRING whose
/// capacity changed: its text, cut to the new capacity. A reference only into the same
/// program (an address of another program means nothing in this one): otherwise it keeps
/// the new program's initial value. Returns how many were carried.
pub fn carry_retain(
    old_image: &Image,
    old_data: &[u8],
    new_image: &Image,
    new_data: &mut [u8],
) -> usize {
    use plc_vm::image::{VAR_FLAG_RETAIN, VarType};
    let same_program = old_image.same_program(new_image);
    let mut carried = 0;
    for i in 0..new_image.var_count() {
        let Some(new) = new_image.var(i).filter(|v| v.flags & VAR_FLAG_RETAIN != 0) else {
            continue;
        };
        let Some(old) = old_image
            .find_var(new.name)
            .filter(|o| o.flags & VAR_FLAG_RETAIN != 0 && o.ty == new.ty)
        else {
            continue;
        };
        let Some(ty) = VarType::from_code(new.ty) else {
            continue;
        };
        let (from, to) = (old.addr as usize, new.addr as usize);
        let (Some(src), Some(dst)) = (
            old_data.get(from..from + old.size as usize),
            new_data.get_mut(to..to + new.size as usize),
        ) else {
            continue;
        };
        carried += carry_value(ty, same_program, src, dst) as usize;
    }
    carried
}

/// Carries one RETAIN value of type `ty` from its old bytes `src` into `dst` (the rules of
/// [`carry_retain`]: same size, the bytes; a STRING or WSTRING of another capacity, its
/// text cut to the new one; a reference only within the same program). Whether it did.
pub fn carry_value(
    ty: plc_vm::image::VarType,
    same_program: bool,
    src: &[u8],
    dst: &mut [u8],
) -> bool {
    use plc_vm::image::Storage;
    use plc_vm::vm::Value;
    match ty.storage() {
        Storage::Reference if !same_program => false,
        _ if src.len() == dst.len() => {
            dst.copy_from_slice(src);
            true
        }
        Storage::String | Storage::WString => {
            Value::load(ty, src).is_some_and(|text| text.store(ty, dst).is_ok())
        }
        _ => false,
    }
}
