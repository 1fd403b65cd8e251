//! The scan cycle, as pure logic over a port interface ([`PortIo`]) and a clock, so the
//! whole behaviour is tested on the host; `main.rs` only supplies the APEX ports and time.
//!
//! One release of the scan process (at its window start) is one call of [`Runtime::scan`]:
//! 1. read every input port once into `%I` (with its validity bit) and copy the `%I` and
//!    `%M` located variables in ([`plc_vm::located::copy_in`]);
//! 2. run each IEC task that is due at this release — a cyclic task every
//!    `INTERVAL / period` releases ([`Schedule`]; a program without a CONFIGURATION at
//!    every release), an event task (`SINGLE`) at the release after its trigger BOOL went
//!    from FALSE to TRUE (sampled once per release, after the inputs are in) — in priority
//!    order (IEC: the lowest PRIORITY number first; ties in declaration order), under two
//!    watchdogs: the VM's instruction budget (trap WATCHDOG) and, where the configuration
//!    gives the task one (`plc.deadline`, as CODESYS's task watchdog time), its time
//!    deadline (trap DEADLINE: the release time plus the deadline);
//! 3. copy the `%Q` and `%M` located variables out and send every output port's bytes.
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
//! mean), release jitter (scan start minus the release time, i.e. the window start),
//! overruns (an execution longer than the task's interval) and faults. Per release it keeps
//! histograms ([`Histogram`]) of the lateness (the same scan start minus release) and of
//! its own overhead: the scan's time besides the VM's (ports, process image, statistics).
//! The first release, which follows the partition's start rather than a window start, is
//! left out of the lateness figures.

use crate::histogram::Histogram;
use crate::package::{Package, SafeValue};
use plc_vm::image::Image;
use plc_vm::isa::Trap;
use plc_vm::located::{self, Area, MAX_AREA};
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
        | Trap::InvalidAddress => ErrorCode::ApplicationError,
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
}

/// When each task runs: a cyclic one every `every[i]` releases of the scan process, an
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
    /// The schedule of `image`'s tasks for a scan process released every `period_ns`.
    pub fn new(image: &Image, period_ns: u64) -> Result<Self, PlanError> {
        let count = image.task_count().min(MAX_TASKS);
        if count == 0 {
            return Err(PlanError::NoTasks);
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

/// What the runtime keeps between releases.
pub struct Runtime {
    pub schedule: Schedule,
    pub stats: [TaskStats; MAX_TASKS],
    /// Stopped tasks and why.
    pub stopped: [Option<Stop>; MAX_TASKS],
    /// The running program's safe values.
    pub safe: SafeValues,
    pub releases: u64,
    /// Release lateness: scan start minus release time (1 us buckets).
    pub lateness: Histogram,
    /// The scan's own work per release besides the VM's (250 ns buckets).
    pub overhead: Histogram,
    period_ns: u64,
    /// Each event task's trigger as sampled at the previous release.
    armed: [bool; MAX_TASKS],
}

impl Runtime {
    pub fn new(schedule: Schedule, period_ns: u64, safe: SafeValues) -> Self {
        Self {
            schedule,
            stats: [TaskStats::default(); MAX_TASKS],
            stopped: [None; MAX_TASKS],
            safe,
            releases: 0,
            lateness: Histogram::new(1_000),
            overhead: Histogram::new(250),
            period_ns,
            armed: [false; MAX_TASKS],
        }
    }

    /// One release (see the module documentation). `release_ns` is when it was due (its
    /// window start), `clock` the partition's time in ns (also the program's `NOW`).
    /// Calls `on_fault` for each task that faulted in this release.
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
        let start = clock();
        let jitter = start.saturating_sub(release_ns);
        read_inputs(package, io, areas);
        let vars = || image.located_vars();
        if self.releases == 0 {
            // The marker area starts with the markers' initial values, not zeros.
            located::copy_out(vars(), Area::Memory, machine.data(), &mut areas.memory);
        }
        located::copy_in(vars(), Area::Input, &areas.input, machine.data_mut());
        located::copy_in(vars(), Area::Memory, &areas.memory, machine.data_mut());
        let mut in_vm = 0u64;
        let mut due = [false; MAX_TASKS];
        for &task in &self.schedule.order[..self.schedule.count] {
            due[task] = match self.schedule.trigger[task] {
                Some(at) => {
                    let set = machine.data().get(at as usize).is_some_and(|&b| b != 0);
                    let edge = set && !self.armed[task];
                    self.armed[task] = set;
                    edge
                }
                None => self.schedule.due(task, self.releases),
            };
        }
        for &task in &self.schedule.order[..self.schedule.count] {
            if self.stopped[task].is_some() || !due[task] {
                continue;
            }
            let t0 = clock();
            // Deadlines count from the release, as ARINC process deadlines do: a task that
            // waited behind others has less of its time left.
            let deadline = release_ns.saturating_add(self.schedule.deadline[task]);
            let timed = self.schedule.deadline[task] != NO_DEADLINE;
            let result = machine.run_cycle_until(task, t0 as i64, || timed && clock() > deadline);
            let exec = clock().saturating_sub(t0);
            in_vm += exec;
            // An event task has no interval: it overruns when it outlasts the period.
            let interval = self.schedule.every[task]
                .max(1)
                .saturating_mul(self.period_ns);
            // The first release follows the partition's start (NORMAL mode), not a window
            // start: its lateness says nothing about the release path.
            let jitter = if self.releases == 0 { 0 } else { jitter };
            self.stats[task].record(exec, jitter, interval);
            if let Err(fault) = result {
                self.stats[task].faults += 1;
                self.stopped[task] = Some(Stop::Fault(fault));
                safe_outputs(image, &self.safe, task, machine.data_mut());
                on_fault(task, &fault);
            }
        }
        located::copy_out(vars(), Area::Output, machine.data(), &mut areas.output);
        located::copy_out(vars(), Area::Memory, machine.data(), &mut areas.memory);
        write_outputs(package, io, areas);
        if self.releases > 0 {
            self.lateness.record(jitter);
        }
        self.overhead
            .record(clock().saturating_sub(start).saturating_sub(in_vm));
        self.releases += 1;
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

/// Copies every RETAIN variable of `new_image` that `old_image` also has (same name, type
/// and size) from `old_data` into `new_data`: the values a warm restart (same image) or an
/// online download (a changed one) keeps. Returns how many were carried.
pub fn carry_retain(
    old_image: &Image,
    old_data: &[u8],
    new_image: &Image,
    new_data: &mut [u8],
) -> usize {
    use plc_vm::image::VAR_FLAG_RETAIN;
    let mut carried = 0;
    for i in 0..new_image.var_count() {
        let Some(new) = new_image.var(i).filter(|v| v.flags & VAR_FLAG_RETAIN != 0) else {
            continue;
        };
        let Some(old) = old_image
            .find_var(new.name)
            .filter(|o| o.flags & VAR_FLAG_RETAIN != 0 && o.ty == new.ty && o.size == new.size)
        else {
            continue;
        };
        let (from, to) = (old.addr as usize, new.addr as usize);
        let len = new.size as usize;
        if let (Some(src), Some(dst)) = (
            old_data.get(from..from + len),
            new_data.get_mut(to..to + len),
        ) {
            dst.copy_from_slice(src);
            carried += 1;
        }
    }
    carried
}
