//! The soft-PLC partition program: reads its package (the partition's data entry, see
//! `softplc::package`), re-verifies the bytecode, creates the package's ports and one
//! periodic scan process released once per partition period (the major frame, so at its
//! window start), and runs [`softplc::scan::Runtime::scan`] at every release between the
//! copy-in and copy-out of its shared globals ([`softplc::shared`]), then answers the
//! waiting online requests ([`softplc::online::serve_pending`]).
//!
//! Online download: the chunks are assembled in whichever of the two static image buffers
//! the running program does not use; a committed (verified) program then runs from the
//! next release over the other of the two static data buffers, which the running program
//! does not use either, after [`softplc::download::hand_over`] copied its RETAIN values and
//! forces from the old data. The swap is a new "life" of the scan loop, so every borrow of
//! the old program ends with it. A partition restart runs the configured program again (a
//! warm one keeps the RETAIN variables the two programs share).
//!
//! Log lines (on the serial log as `[<partition>] plc: ...`; an interface):
//! - `plc: program verified: <n> bytes, <t> task(s), <v> located variable(s), <p> port(s)`
//! - `plc: task <name> interval=<ms>ms every=<n> priority=<p> deadline=<us>us|none` per
//!   task, at start;
//! - `plc: t=<ms>ms task=<name> cycles=<n> exec_us=<last>/<min>/<mean>/<max>
//!   jitter_us=<last>/<max> overruns=<n> faults=<n>` per task every [`STATS_EVERY_MS`];
//! - `plc: t=<ms>ms scan releases=<n> lateness_ns=<min>/<median>/<max>
//!   overhead_ns=<min>/<median>/<max>` with them: over all releases of the running program,
//!   the scan's start after its window start and the runtime's own work per release besides
//!   the VM's (`softplc::histogram`: medians to 0.5 us and 125 ns; what `cargo xtask bench`
//!   reports as `plc_release_jitter` and `plc_cycle_overhead`);
//! - `plc: t=<ms>ms watch <name>=<value> ...` with them: the package's watch list (values
//!   as IEC literals);
//! - `plc: task <name> stopped: <TRAP> at <file>:<line>:<col>; outputs safe` on a fault
//!   (a trap, the instruction budget WATCHDOG or the time DEADLINE), raised to the health
//!   monitor as the error `softplc::scan::health_error` names (NUMERIC_ERROR,
//!   DEADLINE_MISSED or APPLICATION_ERROR) with the detail `<name>: <TRAP> at
//!   <file>:<line>:<col>` (files as the configuration names them);
//! - `plc: shared globals: <w> written, <r> read through the segment at <address>` at
//!   start, and with the statistics (a project that reads shared globals)
//!   `plc: t=<ms>ms shared fresh=<n> unchanged=<n>
//!   stale=<n> not_yet=<n>`: cycles that took a new update of the other project's
//!   variables, found no new one, kept the previous values because the other project was
//!   mid-update at every attempt, or ran before its first update ([`softplc::shared`]);
//! - `plc: warm restart: <n> RETAIN variable(s) kept, the rest initialised`;
//! - `plc: task <name> stopped online; outputs safe` and `plc: task <name> started online`
//!   for STOP and START;
//! - `plc: download: <n> bytes verified, swapped in at release <r>, <k> RETAIN variable(s)
//!   kept` when a downloaded program takes over (release numbers count from the
//!   partition's start, 0 = the first);
//! - `plc: download refused: <reason>` when a committed download fails a check (the
//!   running program goes on);
//! - `plc: refusing the program: <reason>` when the package or bytecode is bad (the
//!   partition reports it and creates no process: it idles).
//!
//! Glue only: what a message, a package or the program means is decided in the library.
#![no_std]
#![no_main]

extern crate alloc;

use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::bindings::ApexPartitionP4;
use apex::a653rs::prelude::*;
use apex::user_rt::print::LineBuffer;
use apex::user_rt::println;
use core::fmt::Write;
use core::str::FromStr;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use core::time::Duration;
use plc_vm::image::Image;
use plc_vm::verify::VerifiedImage;
use plc_vm::vm::{CallFrame, Fault, Machine, Memory, TryFrame};
use protocol::{Direction, PortKind};
use softplc::download::{
    Program, Refusal, Running, Takeover, check_program, fit_configuration, hand_over,
};
use softplc::online::Loader;
use softplc::package::{Package, PortMap, SharedLayout};
use softplc::scan::{Areas, PortIo, Runtime, SafeValues, Schedule};
use softplc::shared::SharedStats;

/// Data memory the program may use.
const MAX_DATA: usize = 256 * 1024;
/// Largest program an online download may bring.
const MAX_IMAGE: usize = 64 * 1024;
/// Verifier scratch (two cells per code byte: programs up to 64 KiB of code).
const MAX_SCRATCH: usize = 128 * 1024;
/// Partition time between statistics lines.
const STATS_EVERY_MS: u64 = 1_000;
/// Period if the partition has none (a background partition).
const DEFAULT_PERIOD: Duration = Duration::from_millis(10);

/// Formats into a [`LineBuffer`] (no heap: the target's `alloc::format!` would unwind).
macro_rules! text {
    ($($arg:tt)*) => { LineBuffer::format(format_args!($($arg)*)) };
}

/// Two data memories: the running program's and the one the next program (after a
/// download or a warm restart) starts in, taking RETAIN values from the other.
static DATA: spin::Mutex<[[u8; MAX_DATA]; 2]> = spin::Mutex::new([[0; MAX_DATA]; 2]);
/// Two image buffers for downloaded programs: the running one's and the one a download
/// is assembled in.
static IMAGES: spin::Mutex<[[u8; MAX_IMAGE]; 2]> = spin::Mutex::new([[0; MAX_IMAGE]; 2]);
/// Which program runs and in which data memory (kept over a warm restart, which carries
/// its RETAIN values to the configured program).
static RUNNING: spin::Mutex<Running> = spin::Mutex::new(Running::COLD);
/// This partition start was a warm one (memory kept by syssw).
static WARM: AtomicBool = AtomicBool::new(false);
static SCRATCH: spin::Mutex<[u32; MAX_SCRATCH]> = spin::Mutex::new([0; MAX_SCRATCH]);
static AREAS: spin::Mutex<Areas> = spin::Mutex::new(Areas::new());

fn name(text: &str) -> Option<Name> {
    Name::from_str(text).ok()
}

fn period() -> Duration {
    let status = <Warden as ApexPartitionP4>::get_partition_status();
    match u64::try_from(status.period) {
        Ok(ns) if ns > 0 => Duration::from_nanos(ns),
        _ => DEFAULT_PERIOD,
    }
}

fn now_ns() -> u64 {
    apex::user_rt::sys::clock()
}

/// Reports `text` to the health monitor and the log.
fn report(text: &str) {
    println!("plc: {text}");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(text.as_bytes());
}

/// The checked package, verified program and schedule, or why the program is refused.
fn load() -> Result<(Package<'static>, VerifiedImage<'static>, Schedule), Refusal> {
    let info = apex::runtime::start_info();
    let package = Package::parse(info.data()).map_err(Refusal::Package)?;
    let period = period().as_nanos() as u64;
    let mut scratch = SCRATCH.lock();
    let (verified, schedule) =
        check_program(package.program(), &mut scratch[..], MAX_DATA, period)?;
    let schedule = fit_configuration(verified.image(), schedule, &package)?;
    Ok((package, verified, schedule))
}

/// The shared-memory segment of a checked layout, as the words the copy protocol works on.
#[allow(unsafe_code)] // memory syssw mapped for this partition (and the other project's)
fn segment(layout: &SharedLayout) -> &'static [AtomicU32] {
    // SAFETY: `shared::check` accepted the layout, so the address is page-aligned, in the
    // shared-segment region and the size a whole number of words. The build computed it with
    // `protocol::layout::shared_address` from the configuration that also makes syssw map
    // the segment read-write at that address (`plc.shared` requires the "rw" attachment)
    // for the partition's whole life. `AtomicU32` has the layout of `u32`, and every access
    // through the slice is atomic, so the other partition writing its own area at the same
    // time is no data race.
    unsafe {
        core::slice::from_raw_parts(
            layout.segment_address as *const AtomicU32,
            layout.segment_size as usize / 4,
        )
    }
}

enum Port {
    SamplingIn(SamplingPortDestination<Warden>),
    SamplingOut(SamplingPortSource<Warden>),
    QueuingIn(QueuingPortReceiver<Warden>),
    QueuingOut(QueuingPortSender<Warden>),
}

/// The package's ports, by package index (created at cold start).
struct ApexPorts(Vec<Option<Port>>);

impl ApexPorts {
    fn open(package: &Package) -> Self {
        let ports = package
            .ports()
            .map(|p| {
                let n = name(p.name)?;
                Some(match (p.kind, p.direction) {
                    (PortKind::Sampling, Direction::In) => {
                        Port::SamplingIn(SamplingPortDestination::from_name(n).ok()?)
                    }
                    (PortKind::Sampling, Direction::Out) => {
                        Port::SamplingOut(SamplingPortSource::from_name(n).ok()?)
                    }
                    (PortKind::Queuing, Direction::In) => {
                        Port::QueuingIn(QueuingPortReceiver::from_name(n).ok()?)
                    }
                    (PortKind::Queuing, Direction::Out) => {
                        Port::QueuingOut(QueuingPortSender::from_name(n).ok()?)
                    }
                })
            })
            .collect();
        Self(ports)
    }
}

impl PortIo for ApexPorts {
    fn receive(&mut self, port: usize, buf: &mut [u8]) -> Option<(usize, bool)> {
        match self.0.get(port)?.as_ref()? {
            Port::SamplingIn(p) => p
                .receive(buf)
                .ok()
                .map(|(validity, m)| (m.len(), validity == Validity::Valid)),
            Port::QueuingIn(p) => p
                .receive(buf, SystemTime::Normal(Duration::ZERO))
                .ok()
                .map(|(m, _)| (m.len(), true)),
            _ => None,
        }
    }

    fn send(&mut self, port: usize, message: &[u8]) {
        match self.0.get(port).and_then(|p| p.as_ref()) {
            Some(Port::SamplingOut(p)) => {
                let _ = p.send(message);
            }
            Some(Port::QueuingOut(p)) => {
                let _ = p.send(message, SystemTime::Normal(Duration::ZERO));
            }
            _ => {}
        }
    }
}

/// `<task>: <TRAP> at <file>:<line>:<col>` (short: the health monitor keeps 64 bytes).
fn fault_text(image: &Image, task: usize, fault: &Fault) -> LineBuffer {
    let mut text = LineBuffer::default();
    let task_name = image.task(task).map_or("?", |t| t.name);
    let _ = write!(text, "{task_name}: {}", fault.trap.name());
    if let Some(l) = fault.location {
        let file = image.file_name(l.file).unwrap_or("?");
        let _ = write!(text, " at {file}:{}:{}", l.line, l.column);
    }
    text
}

/// Logs a task's fault and reports it to the health monitor.
fn report_fault(image: &Image, task: usize, fault: &Fault) {
    let text = fault_text(image, task, fault);
    let task_name = image.task(task).map_or("?", |t| t.name);
    let what = text
        .as_str()
        .strip_prefix(task_name)
        .unwrap_or("")
        .trim_start_matches(": ");
    println!("plc: task {task_name} stopped: {what}; outputs safe");
    let error = apex::codes::apex_error_code(softplc::scan::health_error(fault.trap));
    let _ = apex::runtime::raise(error, apex::runtime::own_slot(), text.as_bytes());
}

/// The scan process: one life of the scan loop per program (see the module documentation).
extern "C" fn scan() {
    // Cold start checked the package; a failure here cannot happen, and idles if it does.
    let Ok(package) = Package::parse(apex::runtime::start_info().data()) else {
        return;
    };
    let period = period().as_nanos() as u64;
    let mut data = DATA.lock();
    let mut images = IMAGES.lock();
    let mut scratch = SCRATCH.lock();
    let mut areas = AREAS.lock();
    let mut io = ApexPorts::open(&package);
    let (mut stack, mut calls, mut tries) =
        ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
    // A warm start carries the RETAIN values of what ran before it to the configured program.
    let mut previous = WARM
        .load(Ordering::Acquire)
        .then(|| *RUNNING.lock())
        .map(|was| (was, None::<Takeover>));
    let mut running = previous.map_or(Running::COLD, |(was, _)| Running::warm_start(was));
    let shared = package.shared().map(|layout| (layout, segment(&layout)));
    let mut shared_stats = SharedStats::default();
    let mut shared_scratch = [0u8; softplc::shared::MAX_AREA_LEN];
    let started = now_ns();
    let mut next_stats = started + STATS_EVERY_MS * 1_000_000;
    let mut first_release = 0u64;
    loop {
        *RUNNING.lock() = running;
        let staging_index = running.staging(previous.map(|(was, _)| was));
        let [image_a, image_b] = &mut *images;
        let (own, staging) = if staging_index == 0 {
            (image_b, image_a)
        } else {
            (image_a, image_b)
        };
        let program: &[u8] = match running.program {
            Program::Configured => package.program(),
            Program::Downloaded { len, .. } => &own[..len],
        };
        let checked = check_program(program, &mut scratch[..], MAX_DATA, period).and_then(
            |(verified, schedule)| {
                let schedule = fit_configuration(verified.image(), schedule, &package)?;
                Ok((verified, schedule))
            },
        );
        let (verified, schedule) = match checked {
            Ok(checked) => checked,
            Err(reason) => {
                report(text!("refusing the program: {reason}").as_str());
                return;
            }
        };
        let image = *verified.image();
        let [data_a, data_b] = &mut *data;
        let (mine, other) = if running.data != 1 {
            (data_a, data_b)
        } else {
            (data_b, data_a)
        };
        let Ok(mut machine) = Machine::new(
            verified,
            Memory {
                data: &mut mine[..],
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        ) else {
            report("refusing the program: not enough VM memory");
            return;
        };
        let mut safe = SafeValues::of(&package);
        if let Some((was, takeover)) = previous.take() {
            let old_bytes: &[u8] = match was.program {
                Program::Configured => package.program(),
                Program::Downloaded { len, .. } => &staging[..len],
            };
            if let Ok(old) = Image::parse(old_bytes) {
                if let Some(takeover) = takeover {
                    let kept = hand_over(&takeover, &old, &other[..], &mut machine);
                    safe = takeover.safe;
                    println!(
                        "plc: download: {} bytes verified, swapped in at release {first_release}, {kept} RETAIN variable(s) kept",
                        program.len()
                    );
                } else {
                    let kept =
                        softplc::scan::carry_retain(&old, &other[..], &image, machine.data_mut());
                    println!(
                        "plc: warm restart: {kept} RETAIN variable(s) kept, the rest initialised"
                    );
                }
            }
            // A new program starts at a release, never in the middle of one.
            if takeover.is_some() && <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
                println!("plc: PERIODIC_WAIT failed; stopping");
                return;
            }
        }
        let mut rt = Runtime::new(schedule, period, safe);
        let mut loader = Loader::new(
            &mut staging[..],
            &mut scratch[..],
            MAX_DATA,
            period,
            first_release,
        );
        let tp = apex::runtime::start_info().time_partition;
        loop {
            // The start of the window this release runs in (its release time).
            let window = apex::user_rt::sys::partition_info(tp)
                .map(|i| i.next_window_start)
                .unwrap_or(0);
            let release = if window == u64::MAX || window > now_ns() {
                now_ns()
            } else {
                window
            };
            if let Some((layout, words)) = &shared
                && layout.other.is_some()
            {
                let fetch = softplc::shared::copy_in(
                    words,
                    layout,
                    machine.data_mut(),
                    &mut shared_scratch,
                );
                shared_stats.record(fetch);
            }
            rt.scan(
                &mut machine,
                &image,
                &package,
                &mut io,
                &mut areas,
                now_ns,
                release,
                |task, fault| report_fault(&image, task, fault),
            );
            if let Some((layout, words)) = &shared {
                softplc::shared::copy_out(words, layout, machine.data());
            }
            let stopped_before = rt.stopped.map(|s| s.is_some());
            softplc::online::serve_pending(
                &package,
                &mut io,
                &mut machine,
                &image,
                &mut rt,
                &mut loader,
            );
            for &task in &rt.schedule.order[..rt.schedule.count] {
                let name = image.task(task).map_or("?", |t| t.name);
                match (stopped_before[task], rt.stopped[task].is_some()) {
                    (false, true) => println!("plc: task {name} stopped online; outputs safe"),
                    (true, false) => println!("plc: task {name} started online"),
                    _ => {}
                }
            }
            if let Some(reason) = loader.refusal.take() {
                println!("plc: download refused: {reason}");
            }
            if let Some((len, takeover)) = loader.committed.take() {
                previous = Some((running, Some(takeover)));
                running = running.downloaded(staging_index, len);
                first_release += rt.releases;
                break;
            }
            let now = now_ns();
            if now >= next_stats {
                next_stats += STATS_EVERY_MS * 1_000_000;
                let ms = (now - started) / 1_000_000;
                log_stats(&rt, &image, &package, &machine, ms);
                if shared.is_some_and(|(layout, _)| layout.other.is_some()) {
                    let s = &shared_stats;
                    println!(
                        "plc: t={ms}ms shared fresh={} unchanged={} stale={} not_yet={}",
                        s.fresh, s.unchanged, s.stale, s.not_yet
                    );
                }
            }
            if <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
                println!("plc: PERIODIC_WAIT failed; stopping");
                return;
            }
        }
    }
}

/// The statistics lines and the watch line at partition time `ms`.
fn log_stats(rt: &Runtime, image: &Image, package: &Package, machine: &Machine, ms: u64) {
    for &task in &rt.schedule.order[..rt.schedule.count] {
        let s = &rt.stats[task];
        println!(
            "plc: t={}ms task={} cycles={} exec_us={}/{}/{}/{} jitter_us={}/{} overruns={} faults={}",
            ms,
            image.task(task).map_or("?", |t| t.name),
            s.count,
            s.last / 1000,
            s.min / 1000,
            s.mean() / 1000,
            s.max / 1000,
            s.last_jitter / 1000,
            s.max_jitter / 1000,
            s.overruns,
            s.faults
        );
    }
    if let (Some(l), Some(o)) = (rt.lateness.summary(), rt.overhead.summary()) {
        println!(
            "plc: t={ms}ms scan releases={} lateness_ns={}/{}/{} overhead_ns={}/{}/{}",
            rt.releases, l.0, l.1, l.2, o.0, o.1, o.2
        );
    }
    let mut line = text!("plc: t={}ms watch", ms);
    for name in package.watch() {
        match machine.read_var(name) {
            Ok(value) => {
                let _ = write!(line, " {name}={value}");
            }
            Err(_) => {
                let _ = write!(line, " {name}=?");
            }
        }
    }
    if package.watch().next().is_some() {
        println!("{}", line.as_str());
    }
}

fn create_port(ctx: &mut StartContext<Warden>, p: &PortMap) -> Result<(), Error> {
    let n = name(p.name).ok_or(Error::InvalidParam)?;
    let refresh = Duration::from_nanos(p.refresh_ns);
    match (p.kind, p.direction) {
        (PortKind::Sampling, Direction::In) => ctx
            .create_sampling_port_destination(n, p.size, refresh)
            .map(drop),
        (PortKind::Sampling, Direction::Out) => {
            ctx.create_sampling_port_source(n, p.size).map(drop)
        }
        (PortKind::Queuing, Direction::In) => ctx
            .create_queuing_port_receiver(n, p.size, p.depth, QueuingDiscipline::Fifo)
            .map(drop),
        (PortKind::Queuing, Direction::Out) => ctx
            .create_queuing_port_sender(n, p.size, p.depth, QueuingDiscipline::Fifo)
            .map(drop),
    }
}

/// After a restart the previous life's scan process may have died holding these locks.
#[allow(unsafe_code)] // forcing spin locks open
fn release_previous_locks() {
    if DATA.is_locked() {
        // SAFETY: runs on the initialisation thread of a (re)started partition before any
        // process exists; every thread of the previous life died with its task, so no guard
        // of this lock is alive.
        unsafe { DATA.force_unlock() };
    }
    if IMAGES.is_locked() {
        // SAFETY: as above.
        unsafe { IMAGES.force_unlock() };
    }
    if RUNNING.is_locked() {
        // SAFETY: as above.
        unsafe { RUNNING.force_unlock() };
    }
    if AREAS.is_locked() {
        // SAFETY: as above.
        unsafe { AREAS.force_unlock() };
    }
    if SCRATCH.is_locked() {
        // SAFETY: as above.
        unsafe { SCRATCH.force_unlock() };
    }
}

struct PlcPartition;

impl PlcPartition {
    /// Both starts: a warm one (memory kept) carries the RETAIN variables over; a cold one
    /// (memory reloaded by syssw) initialises everything.
    fn start(&self, ctx: &mut StartContext<Warden>, warm: bool) {
        release_previous_locks();
        WARM.store(warm, Ordering::Release);
        {
            // In place: an `Areas` value is too big for the initialisation thread's stack.
            let mut areas = AREAS.lock();
            areas.input.fill(0);
            areas.output.fill(0);
            areas.memory.fill(0);
        }
        let (package, verified, schedule) = match load() {
            Ok(loaded) => loaded,
            Err(reason) => {
                report(text!("refusing the program: {reason}").as_str());
                return;
            }
        };
        let image = verified.image();
        println!(
            "plc: program verified: {} bytes, {} task(s), {} located variable(s), {} port(s)",
            package.program().len(),
            schedule.count,
            image.located_count(),
            package.port_count()
        );
        if let Some(layout) = package.shared() {
            println!(
                "plc: shared globals: {} written, {} read through the segment at {:#x}",
                layout.written().count(),
                layout.read().count(),
                layout.segment_address
            );
        }
        let period_ns = period().as_nanos() as u64;
        for &task in &schedule.order[..schedule.count] {
            if let Some(t) = image.task(task) {
                let mut deadline = LineBuffer::default();
                let _ = match schedule.deadline[task] {
                    softplc::scan::NO_DEADLINE => write!(deadline, "none"),
                    ns => write!(deadline, "{}us", ns / 1_000),
                };
                println!(
                    "plc: task {} interval={}ms every={} priority={} deadline={}",
                    t.name,
                    schedule.every[task] * period_ns / 1_000_000,
                    schedule.every[task],
                    t.priority,
                    deadline.as_str()
                );
            }
        }
        for p in package.ports() {
            if let Err(e) = create_port(ctx, &p) {
                report(text!("refusing the program: port {}: {e:?}", p.name).as_str());
                return;
            }
        }
        let Some(process_name) = name("scan") else {
            return;
        };
        let attributes = ProcessAttribute {
            period: SystemTime::Normal(period()),
            time_capacity: SystemTime::Infinite,
            entry_point: scan,
            // The VM stack and call frames, the statistics and the online buffers live here.
            stack_size: 32 * 1024,
            // Just below the MCP (processes must stay under it): above any background partition
            // whose MCP is lower, so the scan starts at the window start whatever TP0 does.
            base_priority: i32::from(apex::runtime::mcp()).saturating_sub(1).max(1),
            deadline: Deadline::Soft,
            name: process_name,
        };
        match ctx.create_process(attributes) {
            Ok(process) => {
                if let Err(e) = process.start() {
                    report(text!("START scan failed: {e:?}").as_str());
                }
            }
            Err(e) => report(text!("CREATE_PROCESS scan failed: {e:?}").as_str()),
        }
    }
}

impl Partition<Warden> for PlcPartition {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        self.start(ctx, false)
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.start(ctx, true)
    }
}

fn main() {
    PlcPartition.run()
}

apex::partition_entry!(main);
