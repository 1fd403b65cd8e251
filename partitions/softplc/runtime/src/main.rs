//! The soft-PLC partition program: reads its package (the partition's data entry, see
//! `softplc::package`), re-verifies the bytecode, creates the package's ports and the
//! partition's APEX processes, all released at window starts:
//! - one per IEC task ([`task_process`]), periodic with the task's INTERVAL (an event task:
//!   the partition's period, looking at its trigger), its priority by the task's IEC
//!   priority (`softplc::scan::Schedule::process_priorities`): at each release the first
//!   process to run begins it (inputs in, the other project's shared globals in), then the
//!   process runs one cycle of its task ([`softplc::scan::Runtime::run_task`]);
//! - the control process ([`control`]), below all of them, once per partition period:
//!   ends the release (shared globals out, outputs out), answers the waiting online
//!   requests ([`softplc::online::serve_pending`]), swaps in a downloaded program, logs the
//!   statistics.
//!
//! What they share (the program, its machine and runtime state, the ports and the process
//! image: a [`Life`]) lives in the control process's frame and is reached under one lock
//! ([`with_life`]); a process that finds it taken sleeps and looks again, so a task cycle
//! is never preempted by another task's: a higher-priority task released while a
//! lower-priority cycle outlasts its window starts when that cycle ends (its deadline or
//! instruction budget bounds it).
//!
//! - the communication process ([`comm`]), below the control process, once per period,
//!   when the configuration gives the PLC a network interface (`plc.net`): its own TCP/IP
//!   stack on the interface's frame ports and the Modbus/TCP server (`softplc::comm`); it
//!   never takes the life's lock: requests and answers pass through [`EXCHANGE`], which the
//!   control process serves between cycles when it finds it free (it never waits for it).
//! - the store process ([`disk::store_process`]), below the control process, once per
//!   period, when the configuration gives the PLC a persistent store (`plc.store`): it
//!   writes the boot project and RETAIN snapshots the control process copied between
//!   releases to the virtual disk; the control process never waits for it.
//!
//! Online download: the chunks are assembled in whichever of the two static image buffers
//! the running program does not use; a committed (verified) program then runs from the
//! next release over the other of the two static data buffers, which the running program
//! does not use either, after [`softplc::download::hand_over`] copied its RETAIN values and
//! forces from the old data. The swap is a new [`Life`] of the control process, so every
//! borrow of the old program ends with it; a downloaded program must keep the running
//! one's tasks (their processes were created at the start). A partition restart runs the configured program again (a
//! warm one keeps the RETAIN variables the two programs share).
//!
//! Log lines (on the serial log as `[<partition>] plc: ...`; an interface):
//! - `plc: program verified: <n> bytes, <t> task(s), <v> located variable(s), <p> port(s)`
//! - `plc: tier native (image <hash>, <n> bytes)` when the program runs on its native code
//!   (`plc.native`; the FNV-1a hash of the image, 16 hex digits), else `plc: tier
//!   interpreter`, with the reason in parentheses when native code was asked for
//!   (`softplc::tier::Tier`); for every program that starts (the configured one, a
//!   downloaded one);
//! - `plc: task <name> interval=<ms>ms every=<n> priority=<p> deadline=<us>us|none
//!   process_priority=<n>` per task, at start (`priority` is the IEC one), then
//!   `plc: control process_priority=<n>`;
//! - `plc: t=<ms>ms task=<name> cycles=<n> exec_us=<last>/<min>/<mean>/<max>
//!   jitter_us=<last>/<max> overruns=<n> faults=<n>` per task every [`STATS_EVERY_MS`];
//! - `plc: t=<ms>ms scan releases=<n> lateness_ns=<min>/<median>/<max>
//!   overhead_ns=<min>/<median>/<max> forced=<n>` with them: over all releases of the
//!   running program, the first start at a release after its window start and the
//!   runtime's own work per release besides the VM's (`softplc::histogram`: medians within
//!   1/64; what `cargo xtask bench` reports as `plc_release_jitter` and
//!   `plc_cycle_overhead`), and how many variables are forced now;
//! - `plc: t=<ms>ms watch <name>=<value> ...` with them: the package's watch list (values
//!   as IEC literals);
//! - `plc: t=<ms>ms period releases=<n> lateness_ns=<min>/<median>/<max>
//!   histogram_ns=<low>-<high>:<count>,...` after them: the lateness of the releases since
//!   the previous statistics line (each one's, where the line before is over all of them)
//!   and their histogram, the non-empty bins `[low, high)` in ns of
//!   [`softplc::scan::LATENESS_BITS`] significant bits (a bin is at most a quarter of its
//!   values wide); bins that do not fit a line follow on lines
//!   `plc: t=<ms>ms period histogram_ns=<low>-<high>:<count>,...` (`cargo xtask plot` draws
//!   them);
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
//! - `plc: net <address>/<prefix> mac <mac> connections=<n> buffer=<bytes>
//!   requests_per_second=<n>` and `plc: modbus on port <p> unit <u> writable=<areas>` at
//!   start (with `plc.net`, `plc.modbus`), and `plc: online on port <p>
//!   clients=<name>:<access>,...` (with `plc.online_tcp`); `plc: t=<ms>ms net open=<n>
//!   accepted=<n> refused=<n> malformed=<n> requests=<n> responses=<n> denied=<n>
//!   rejected=<n> published=<n> received=<n> frames_in=<n> frames_out=<n>` every
//!   [`STATS_EVERY_MS`] while something changed (`denied`: online handshakes refused,
//!   `rejected`: online sessions ended by a record that did not open, `published` and
//!   `received`: publish/subscribe datagrams);
//! - with `plc.publish` / `plc.subscribe`, at start `plc: publish to <ip>:<port>
//!   vars=<a>,<b>` and `plc: subscribe on port <p> [group=<ip>] vars=<a>,<b>
//!   valid=<variable|-> timeout_ms=<n>`,
//!   then `plc: subscription valid` and `plc: subscription lapsed: ...` when its validity
//!   changes, and `plc: t=<ms>ms subscription good=<n> bad=<n>` (messages taken, refused)
//!   every [`STATS_EVERY_MS`];
//! - `plc: online: <client> authenticated from <ip>:<port> (<access>)`, `plc: online:
//!   refused <ip>:<port>: <unknown name or wrong key|malformed handshake|no complete
//!   handshake in time>` and `plc: online: session of <client> from <ip>:<port> ended:
//!   <why>` (a tampered, replayed or oversized record), the last two at most
//!   [`EVENT_LINES`] per statistics interval;
//! - with `plc.store` (the store process and the load: [`disk`]), at a cold start (and
//!   the first line at a warm one too)
//!   `plc: store: boot project #<seq> loaded: <n> bytes, downloaded at release <r>`
//!   (followed by `plc: store: boot project #<seq> was saved watching <names>; the
//!   configured watch list is used` when the configuration's list changed since) or
//!   `plc: store: no boot project; the configured program runs`, `plc: store: RETAIN
//!   snapshot #<seq> loaded: <n> variable(s) of release <r>` or `plc: store: no RETAIN
//!   snapshot; initial values`, then `plc: store: <n> RETAIN variable(s) restored`;
//!   `plc: store: <boot project|RETAIN> slot <i> skipped: <why>` for a torn or corrupt
//!   slot and `plc: store: boot project #<seq> refused: <why>; the configured program
//!   runs` (both reported to the health monitor); `plc: store: boot project #<seq> saved
//!   (<n> bytes)` and `plc: store: RETAIN snapshot #<seq> saved (release <r>, <n> bytes, copied in <us>
//!   us, written in <us> us)`
//!   when a save is on the disk (`<seq>`: the record's sequence number; the copy is the
//!   control process's time for the snapshot between releases, the write the store
//!   process's from its first sector write to its last flush), `plc: store:
//!   <what> not saved: <why>` when not;
//! - `plc: first cycle done (release <r>)` once after the partition's start, when the
//!   control process first finds a task's cycle done (at the end of that release; the
//!   line's kernel timestamp is the boot time `cargo xtask bench --disk` reports);
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
use driver_link::tenant::TenantLink;
use plc_vm::image::Image;
use plc_vm::verify::VerifiedImage;
use plc_vm::vm::{CallFrame, Fault, Machine, Memory, TryFrame};
use protocol::{Direction, PortKind};
use softplc::download::{
    Program, Refusal, Running, Takeover, check_program, check_watch, fit_configuration, hand_over,
};
use softplc::online::Loader;
use softplc::package::{Package, PortMap, SharedLayout};
use softplc::scan::{Areas, PortIo, Runtime, SafeValues, Schedule};
use softplc::shared::SharedStats;
use softplc::tier::Tier;

/// The programs of this build on the native execution tier (`plc.native`): `cargo xtask`
/// translates them and builds the partition with the feature `native` and the generated
/// file in `PLC_NATIVE_PROGRAMS`.
#[cfg(feature = "native")]
mod native_programs {
    include!(env!("PLC_NATIVE_PROGRAMS"));
}

/// No native code in this build: every program runs on the interpreter.
#[cfg(not(feature = "native"))]
mod native_programs {
    pub static PROGRAMS: &[&plc_vm::native::NativeProgram] = &[];
}

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

mod disk;

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
/// The running program's runtime state and the VM's stack, call and try frames and the
/// shared-globals scratch: kept out of the control process's 32 KiB stack.
static RUNTIME: spin::Mutex<Runtime> = spin::Mutex::new(Runtime::idle());
/// The Modbus requests the communication process took and the control process's answers
/// (the control process only ever tries this lock).
static EXCHANGE: spin::Mutex<softplc::comm::Exchange> =
    spin::Mutex::new(softplc::comm::Exchange::new());
static WORKSPACE: spin::Mutex<Workspace> = spin::Mutex::new(Workspace {
    stack: [0; 256],
    calls: [CallFrame::EMPTY; 32],
    tries: [TryFrame::EMPTY; 16],
    shared_scratch: [0; softplc::shared::MAX_AREA_LEN],
});

struct Workspace {
    stack: [u64; 256],
    calls: [CallFrame; 32],
    tries: [TryFrame; 16],
    shared_scratch: [u8; softplc::shared::MAX_AREA_LEN],
}

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
    // `shared::check` accepted the layout, so the address is page-aligned, in the
    // shared-segment region and the size a whole number of words. The build computed it with
    // `protocol::layout::shared_address` from the configuration that also makes syssw map
    // the segment read-write at that address (`plc.shared` requires the "rw" attachment)
    // for the partition's whole life. `AtomicU32` has the layout of `u32`, and every access
    // through the slice is atomic, so the other partition writing its own area at the same
    // time is no data race.
    // SAFETY: mapped, aligned words for the partition's life, only accessed atomically.
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

/// How long a process sleeps before it looks at the PLC again while another process holds
/// it or no program is published (see [`with_life`]).
const LOCK_POLL_NS: u64 = 20_000;

/// What the partition's processes share while one program runs. The control process owns
/// it in its own frame and publishes it through [`LIFE`]; every access, its own included,
/// goes through [`with_life`].
struct Life<'l> {
    package: Package<'l>,
    image: Image<'l>,
    machine: Machine<'l, 'l>,
    rt: &'l mut Runtime,
    io: &'l mut ApexPorts,
    areas: &'l mut Areas,
    shared: Option<(SharedLayout<'l>, &'static [AtomicU32])>,
    shared_stats: &'l mut SharedStats,
    shared_scratch: &'l mut [u8; softplc::shared::MAX_AREA_LEN],
}

impl Life<'_> {
    /// The release this process runs at (its window start), begun if no process of the
    /// partition began it yet: inputs in, the other project's shared globals in.
    fn begin(&mut self) -> u64 {
        let release = current_release();
        let began = self.rt.begin_release(
            &mut self.machine,
            &self.image,
            &self.package,
            &mut *self.io,
            &mut *self.areas,
            now_ns,
            release,
        );
        if began
            && let Some((layout, words)) = &self.shared
            && layout.other.is_some()
        {
            let fetch = softplc::shared::copy_in(
                words,
                layout,
                self.machine.data_mut(),
                self.shared_scratch,
            );
            self.shared_stats.record(fetch);
        }
        release
    }

    /// The end of the release, after every task released at it: shared globals out,
    /// outputs out.
    fn end(&mut self) {
        if let Some((layout, words)) = &self.shared {
            softplc::shared::copy_out(words, layout, self.machine.data());
        }
        self.rt.end_release(
            &mut self.machine,
            &self.image,
            &self.package,
            &mut *self.io,
            &mut *self.areas,
            now_ns,
        );
    }
}

/// The published [`Life`], if any (a pointer into the control process's frame).
struct LifeSlot(Option<core::ptr::NonNull<()>>);

// SAFETY: the pointer is only dereferenced under `LIFE`'s lock ([`with_life`]); the
// partition's processes run on one CPU of one address space.
#[allow(unsafe_code)]
unsafe impl Send for LifeSlot {}

static LIFE: spin::Mutex<LifeSlot> = spin::Mutex::new(LifeSlot(None));

/// `LIFE`'s lock. A process that finds it held sleeps [`LOCK_POLL_NS`] and looks again,
/// so a lower-priority holder (a task cycle that outlasted its window) can finish: task
/// cycles do not preempt each other.
fn lock_life() -> spin::MutexGuard<'static, LifeSlot> {
    loop {
        if let Some(slot) = LIFE.try_lock() {
            return slot;
        }
        apex::user_rt::sys::sleep_until(now_ns() + LOCK_POLL_NS);
    }
}

/// Runs `f` on the published life, waiting (see [`lock_life`]) while there is none: at
/// the partition's start and while a downloaded program is swapped in.
#[allow(unsafe_code)]
fn with_life<R>(f: impl FnOnce(&mut Life<'_>) -> R) -> R {
    loop {
        let slot = lock_life();
        if let Some(life) = slot.0 {
            // The control process publishes a pointer to the `Life` in its own frame
            // ([`Published`]) and withdraws it, under this lock, before that value changes or
            // goes away; while it is published nobody touches it but through this function.
            // SAFETY: a live `Life`, and under the lock this is the only reference to it.
            let life = unsafe { &mut *life.as_ptr().cast::<Life<'_>>() };
            return f(life);
        }
        drop(slot);
        apex::user_rt::sys::sleep_until(now_ns() + LOCK_POLL_NS);
    }
}

/// A published life: withdrawn when dropped.
struct Published;

impl Published {
    fn new(life: &mut Life<'_>) -> Self {
        lock_life().0 = Some(core::ptr::NonNull::from(life).cast());
        Published
    }
}

impl Drop for Published {
    fn drop(&mut self) {
        lock_life().0 = None;
    }
}

/// The start of the window the calling process runs in (its release time); now if the
/// partition has no window (background).
fn current_release() -> u64 {
    let tp = apex::runtime::start_info().time_partition;
    let window = apex::user_rt::sys::partition_info(tp)
        .map(|i| i.next_window_start)
        .unwrap_or(0);
    let now = now_ns();
    if window == u64::MAX || window > now {
        now
    } else {
        window
    }
}

/// The process id of each task's process (`task + 1` in the slot of the id; 0: none),
/// recorded when the partition starts.
static TASK_PROCESSES: [core::sync::atomic::AtomicI64; softplc::scan::MAX_TASK_PROCESSES] =
    [const { core::sync::atomic::AtomicI64::new(-1) }; softplc::scan::MAX_TASK_PROCESSES];

/// The task the calling process runs.
fn own_task() -> Option<usize> {
    let me = <Warden as apex::a653rs::bindings::ApexProcessP1>::get_my_id().ok()?;
    TASK_PROCESSES
        .iter()
        .position(|id| id.load(Ordering::Acquire) == me)
}

/// An IEC task's process: at every release (its INTERVAL, or the partition's period for an
/// event task) one cycle of its task.
extern "C" fn task_process() {
    let Some(task) = own_task() else {
        println!("plc: a task process without a task; stopping");
        return;
    };
    loop {
        with_life(|life| {
            let release = life.begin();
            let image = life.image;
            life.rt.run_task(
                task,
                &mut life.machine,
                &image,
                now_ns,
                release,
                |task, fault| report_fault(&image, task, fault),
            );
        });
        if <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
            println!("plc: PERIODIC_WAIT failed; stopping");
            return;
        }
    }
}

/// The control process, below every task process, once per partition period: ends the
/// release (outputs out), answers online requests, swaps in a downloaded program, logs
/// the statistics. It owns each program's [`Life`] (one per program, see the module
/// documentation).
extern "C" fn control() {
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
    let mut runtime = RUNTIME.lock();
    let mut workspace = WORKSPACE.lock();
    let Workspace {
        stack,
        calls,
        tries,
        shared_scratch,
    } = &mut *workspace;
    // A warm start carries the RETAIN values of what ran before it to the program it starts
    // (the boot project if the store holds one, else the configured program).
    let mut previous = WARM
        .load(Ordering::Acquire)
        .then(|| *RUNNING.lock())
        .map(|was| (was, None::<Takeover>));
    let mut running = previous.map_or(Running::COLD, |(was, _)| Running::warm_start(was));
    // A start runs the boot project if the store holds a valid one (`plc.store`): a cold
    // start with the newest RETAIN snapshot, a warm one with RAM's values of what ran.
    let was = previous.map(|(was, _)| was);
    let boot_buffer = Running::boot_buffer(was);
    let cold = was.is_none();
    if let Some(len) = disk::load(&package, cold, &mut images[boot_buffer], |program| {
        let (verified, schedule) = check_program(program, &mut scratch[..], MAX_DATA, period)?;
        // Saved with the watch list of its download, which was the configured one; a
        // changed configuration's list must name its variables, as for a download.
        check_watch(verified.image(), package.watch())?;
        fit_configuration(verified.image(), schedule, &package).map(drop)
    }) {
        running = running.boot_project(!cold, boot_buffer, len);
    }
    let shared = package.shared().map(|layout| (layout, segment(&layout)));
    let mut shared_stats = SharedStats::default();
    let started = now_ns();
    let mut next_stats = started + STATS_EVERY_MS * 1_000_000;
    let mut first_release = 0u64;
    // The first cycle after the partition's start is logged once.
    let mut first_cycle_logged = false;
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
                stack: &mut stack[..],
                calls: &mut calls[..],
                tries: &mut tries[..],
            },
        ) else {
            report("refusing the program: not enough VM memory");
            return;
        };
        let tier = Tier::select(
            &package,
            program,
            matches!(running.program, Program::Downloaded { .. }),
            native_programs::PROGRAMS,
        );
        println!("plc: tier {tier}");
        let mut safe = SafeValues::of(&package);
        let mut swapped = false;
        if let Some((was, takeover)) = previous.take() {
            let old_bytes: &[u8] = match was.program {
                Program::Configured => package.program(),
                Program::Downloaded { len, .. } => &staging[..len],
            };
            if let Ok(old) = Image::parse(old_bytes) {
                if let Some(takeover) = takeover {
                    let kept = hand_over(&takeover, &old, &other[..], &mut machine);
                    safe = takeover.safe;
                    swapped = true;
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
        }
        disk::start(
            program,
            &image,
            machine.data_mut(),
            swapped.then_some(first_release),
        );
        let mut loader = Loader::new(
            &mut staging[..],
            &mut scratch[..],
            MAX_DATA,
            period,
            first_release,
        );
        let mut life = Life {
            package,
            image,
            machine,
            rt: {
                runtime.restart(schedule, period, safe);
                runtime.set_native(tier.native());
                &mut runtime
            },
            io: &mut io,
            areas: &mut areas,
            shared,
            shared_stats: &mut shared_stats,
            shared_scratch,
        };
        // Publish/subscribe with this program's variables (a downloaded program may lack
        // them: then it is off until the next one).
        let mut endpoint = package.net().and_then(|n| n.pubsub).and_then(|pubsub| {
            match softplc::pubsub::Endpoint::new(&image, &pubsub) {
                Ok(endpoint) => Some(endpoint),
                Err(e) => {
                    println!("plc: publish/subscribe off: {e:?} in this program");
                    None
                }
            }
        });
        let published = Published::new(&mut life);
        // A new program starts at a release, never in the middle of one.
        if swapped && <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
            println!("plc: PERIODIC_WAIT failed; stopping");
            return;
        }
        loop {
            let committed = with_life(|life| {
                life.begin();
                life.end();
                if !first_cycle_logged
                    && life.rt.stats[..life.rt.schedule.count]
                        .iter()
                        .any(|s| s.count > 0)
                {
                    first_cycle_logged = true;
                    println!("plc: first cycle done (release {})", life.rt.releases);
                }
                let stopped_before = life.rt.stopped.map(|s| s.is_some());
                // Online requests from the ports and from TCP, then Modbus (which answers
                // exception 4 to a write once every task is stopped, this release too).
                softplc::online::serve_pending(
                    &life.package,
                    &mut *life.io,
                    &mut life.machine,
                    &life.image,
                    life.rt,
                    &mut loader,
                );
                if let Some(net) = life.package.net()
                    && let Some(mut exchange) = EXCHANGE.try_lock()
                {
                    if net.online.is_some() {
                        softplc::online::serve_exchange(
                            &mut exchange,
                            &life.package,
                            &mut life.machine,
                            &life.image,
                            life.rt,
                            &mut loader,
                        );
                    }
                    if let Some(modbus) = net.modbus {
                        let running = life.rt.any_task_running();
                        let (image, machine) = (&life.image, &mut life.machine);
                        softplc::comm::serve_modbus(
                            &mut exchange,
                            &modbus,
                            running,
                            life.areas,
                            |area, bytes, areas| {
                                softplc::scan::take_written(image, area, bytes, areas, machine)
                            },
                        );
                    }
                }
                let mut stopped_now = false;
                for &task in &life.rt.schedule.order[..life.rt.schedule.count] {
                    let name = life.image.task(task).map_or("?", |t| t.name);
                    match (stopped_before[task], life.rt.stopped[task].is_some()) {
                        (false, true) => {
                            stopped_now = true;
                            println!("plc: task {name} stopped online; outputs safe")
                        }
                        (true, false) => println!("plc: task {name} started online"),
                        _ => {}
                    }
                }
                let (data, release) = (life.machine.data(), life.rt.releases);
                disk::after_release(
                    &life.package,
                    program,
                    &life.image,
                    data,
                    release,
                    stopped_now,
                );
                if let Some(reason) = loader.refusal.take() {
                    println!("plc: download refused: {reason}");
                }
                if let Some(endpoint) = endpoint.as_mut() {
                    pubsub_between_releases(endpoint, life);
                }
                let now = now_ns();
                if now >= next_stats {
                    next_stats += STATS_EVERY_MS * 1_000_000;
                    let ms = (now - started) / 1_000_000;
                    if let Some(e) = &endpoint {
                        println!("plc: t={ms}ms subscription good={} bad={}", e.good, e.bad);
                    }
                    log_stats(life.rt, &life.image, &life.package, &life.machine, ms);
                    log_period(life.rt, ms);
                    if life
                        .shared
                        .is_some_and(|(layout, _)| layout.other.is_some())
                    {
                        let s = &life.shared_stats;
                        println!(
                            "plc: t={ms}ms shared fresh={} unchanged={} stale={} not_yet={}",
                            s.fresh, s.unchanged, s.stale, s.not_yet
                        );
                    }
                }
                loader
                    .committed
                    .take()
                    .map(|commit| (commit, life.rt.releases))
            });
            if let Some(((len, takeover), releases)) = committed {
                previous = Some((running, Some(takeover)));
                running = running.downloaded(staging_index, len);
                first_release += releases;
                break;
            }
            if <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
                println!("plc: PERIODIC_WAIT failed; stopping");
                return;
            }
        }
        // Withdrawn before the life's values go: the task processes wait for the next one.
        drop(published);
    }
}

/// The communication process: frames in from the NIC partition, the stack and its
/// services ([`softplc::comm::Comm`]), frames out, once per period (at most
/// [`softplc::comm::FRAMES_PER_RUN`] frames each way), through the frame ports or, when
/// the package names one, the frame ring ([`TenantLink`]).
extern "C" fn comm() {
    use softplc::comm::{Comm, FRAMES_PER_RUN};
    let info = apex::runtime::start_info();
    let Some(net) = Package::parse(info.data()).ok().and_then(|p| {
        let net = p.net()?;
        Some((net, p.port(net.rx)?.name, p.port(net.tx)?.name))
    }) else {
        return;
    };
    let (net, rx_name, tx_name) = net;
    #[allow(unsafe_code)]
    // SAFETY: the ring's segment is this partition's and its NIC partition's only (the
    // configuration tools' check), mapped read-write for its life; this process alone
    // attaches it.
    let link = unsafe { TenantLink::open(rx_name, tx_name, net.ring) };
    let mut link = match link {
        Ok(link) => link,
        Err(e) => {
            report(text!("net: the frame link: {e}").as_str());
            return;
        }
    };
    let started = now_ns();
    // The online handshake's nonces are seeded from the time-stamp counter (there is no
    // entropy device): see plc_online::session::NonceSource.
    let seed = apex::user_rt::sys::rdtsc();
    let mut comm = match Comm::new(&net, started, seed) {
        Ok(comm) => comm,
        Err(e) => {
            report(text!("net: the services cannot listen: {e:?}").as_str());
            return;
        }
    };
    let mut next_stats = started + STATS_EVERY_MS * 1_000_000;
    let mut logged = softplc::comm::CommStats::default();
    let mut event_lines = EVENT_LINES;
    loop {
        link.receive(FRAMES_PER_RUN, |frame| comm.stack.device.deliver(frame));
        let now = now_ns();
        comm.run(now, &mut EXCHANGE.lock());
        log_events(&mut comm, &mut event_lines);
        link.send(FRAMES_PER_RUN, || comm.stack.device.take());
        if now >= next_stats {
            next_stats += STATS_EVERY_MS * 1_000_000;
            event_lines = EVENT_LINES;
            let s = comm.stats;
            if s != logged {
                logged = s;
                println!(
                    "plc: t={}ms net open={} accepted={} refused={} malformed={} requests={} responses={} denied={} rejected={} published={} received={} frames_in={} frames_out={}",
                    (now - started) / 1_000_000,
                    comm.open(),
                    s.accepted,
                    s.refused,
                    s.malformed,
                    s.requests,
                    s.responses,
                    s.denied,
                    s.rejected,
                    s.published,
                    s.received,
                    link.frames_in,
                    link.frames_out
                );
            }
        }
        if <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
            println!("plc: net: PERIODIC_WAIT failed; stopping");
            return;
        }
    }
}

/// Publish/subscribe between releases ([`softplc::pubsub::Endpoint`]): the latest received
/// datagram taken from the exchange into the program, the publication put there, and a
/// change of the subscription's validity logged. Without the exchange's lock (the
/// communication process holds it) the release publishes nothing and the datagram waits.
fn pubsub_between_releases(endpoint: &mut softplc::pubsub::Endpoint, life: &mut Life) {
    use softplc::comm::MAX_DATAGRAM;
    use softplc::pubsub::Change;
    let running = life.rt.any_task_running();
    let mut exchange = EXCHANGE.try_lock();
    let message = exchange.as_mut().and_then(|x| {
        let d = x.subscription;
        x.subscription.len = 0;
        (d.len > 0).then_some(d)
    });
    let mut out = [0u8; MAX_DATAGRAM];
    let (n, change) = endpoint.between_releases(
        &life.image,
        life.machine.data_mut(),
        now_ns() as i64,
        running && exchange.is_some(),
        message.as_ref().map(|d| &d.bytes[..d.len]),
        &mut out,
    );
    if let Some(x) = exchange.as_mut()
        && n > 0
    {
        x.publication.bytes[..n].copy_from_slice(&out[..n]);
        x.publication.len = n;
    }
    drop(exchange);
    match change {
        Some(Change::Valid) => println!("plc: subscription valid"),
        Some(Change::Lapsed) => {
            println!(
                "plc: subscription lapsed: no good message within its timeout; its variables are zero"
            )
        }
        None => {}
    }
}

/// Refusal lines (`refused`, `ended`) the communication process writes per statistics
/// interval at most (a flood of refused clients must not keep it writing to the console);
/// the statistics line counts them all (`denied=`, `rejected=`).
const EVENT_LINES: u32 = 10;

/// The communication process's events as log lines (`plc: online: ...`), while `budget`
/// lasts. Log lines only: a client on the network must not be able to raise a
/// health-monitor error (whose configured action could restart the PLC).
fn log_events(comm: &mut softplc::comm::Comm, budget: &mut u32) {
    use plc_online::session::HandshakeError;
    use softplc::comm::Event;
    let mut events = [None; softplc::comm::MAX_EVENTS];
    for (slot, event) in events.iter_mut().zip(comm.take_events()) {
        *slot = Some(event);
    }
    for event in events.into_iter().flatten() {
        // Only a client that holds a key can authenticate: the budget is for the others.
        if !matches!(event, Event::Authenticated { .. }) {
            if *budget == 0 {
                continue;
            }
            *budget -= 1;
        }
        let name = |client| core::str::from_utf8(comm.client_name(client)).unwrap_or("?");
        match event {
            Event::Authenticated {
                client,
                access,
                peer,
            } => println!(
                "plc: online: {} authenticated from {}:{} ({})",
                name(client),
                peer.ip,
                peer.port,
                access.name()
            ),
            Event::Denied { peer, why } => println!(
                "plc: online: refused {}:{}: {}",
                peer.ip,
                peer.port,
                match why {
                    None => "no complete handshake in time",
                    Some(HandshakeError::Malformed) => "malformed handshake",
                    Some(HandshakeError::Refused) => "unknown name or wrong key",
                }
            ),
            Event::Rejected { client, peer, why } => println!(
                "plc: online: session of {} from {}:{} ended: {why}",
                name(client),
                peer.ip,
                peer.port
            ),
        }
    }
}

/// The `period` line (and, when its histogram does not fit one line, more): the release
/// lateness since the previous statistics line, which then starts over.
fn log_period(rt: &mut Runtime, ms: u64) {
    /// Longest text of a line (the kernel's limit less room for its prefix).
    const LINE_MAX: usize = 480;
    let recent = &rt.recent_lateness;
    if let Some((min, median, max)) = recent.summary() {
        let mut line = text!(
            "plc: t={ms}ms period releases={} lateness_ns={min}/{median}/{max} histogram_ns=",
            recent.count()
        );
        let mut separator = "";
        for (low, high, count) in recent.bins(softplc::scan::LATENESS_BITS) {
            let bin = text!("{separator}{low}-{high}:{count}");
            if line.as_bytes().len() + bin.as_bytes().len() > LINE_MAX {
                println!("{}", line.as_str());
                line = text!("plc: t={ms}ms period histogram_ns={low}-{high}:{count}");
            } else {
                let _ = line.write_str(bin.as_str());
            }
            separator = ",";
        }
        println!("{}", line.as_str());
    }
    rt.recent_lateness.clear();
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
            "plc: t={ms}ms scan releases={} lateness_ns={}/{}/{} overhead_ns={}/{}/{} forced={}",
            rt.releases,
            l.0,
            l.1,
            l.2,
            o.0,
            o.1,
            o.2,
            machine.forced().count()
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

/// After a restart the previous life's processes may have died holding these locks.
fn release_previous_locks() {
    /// Opens `lock` if a dead thread left it locked.
    #[allow(unsafe_code)] // forcing a spin lock open
    fn force_open<T>(lock: &spin::Mutex<T>) {
        if lock.is_locked() {
            // SAFETY: runs on the initialisation thread of a (re)started partition before
            // any process exists; every thread of the previous life died with its task, so
            // no guard of this lock is alive.
            unsafe { lock.force_unlock() };
        }
    }
    force_open(&DATA);
    force_open(&IMAGES);
    force_open(&RUNNING);
    force_open(&AREAS);
    force_open(&SCRATCH);
    force_open(&RUNTIME);
    force_open(&WORKSPACE);
    force_open(&EXCHANGE);
    *EXCHANGE.lock() = softplc::comm::Exchange::new();
    force_open(&LIFE);
    // The previous life's control process is gone with its frame.
    LIFE.lock().0 = None;
    disk::release_locks();
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
        // The processes' priorities start just below the MCP (processes must stay under
        // it): above any background partition whose MCP is lower, so the tasks start at the
        // window start whatever TP0 does.
        let (priorities, control_priority) = schedule.process_priorities(apex::runtime::mcp());
        for &task in &schedule.order[..schedule.count] {
            if let Some(t) = image.task(task) {
                let mut deadline = LineBuffer::default();
                let _ = match schedule.deadline[task] {
                    softplc::scan::NO_DEADLINE => write!(deadline, "none"),
                    ns => write!(deadline, "{}us", ns / 1_000),
                };
                println!(
                    "plc: task {} interval={}ms every={} priority={} deadline={} process_priority={}",
                    t.name,
                    schedule.every[task] * period_ns / 1_000_000,
                    schedule.every[task],
                    t.priority,
                    deadline.as_str(),
                    priorities[task]
                );
            }
        }
        println!("plc: control process_priority={control_priority}");
        for p in package.ports() {
            if let Err(e) = create_port(ctx, &p) {
                report(text!("refusing the program: port {}: {e:?}", p.name).as_str());
                return;
            }
        }
        for id in &TASK_PROCESSES {
            id.store(-1, Ordering::Release);
        }
        for &task in &schedule.order[..schedule.count] {
            let task_name = image.task(task).map_or("?", |t| t.name);
            let period = Duration::from_nanos(schedule.process_period(task, period_ns));
            let Some(id) = spawn(ctx, task_name, task_process, period, priorities[task]) else {
                return;
            };
            TASK_PROCESSES[task].store(id, Ordering::Release);
        }
        // The VM's stack and call frames, the online buffers and the life live in its stack.
        spawn(ctx, "control", control, period(), control_priority);
        if package.store().is_some() {
            // Below the control process: it writes while the PLC runs.
            spawn(
                ctx,
                "store",
                disk::store_process,
                period(),
                control_priority.saturating_sub(1).max(1),
            );
        }
        if let Some(net) = package.net() {
            let [a, b, c, d] = net.address;
            let m = net.mac;
            println!(
                "plc: net {a}.{b}.{c}.{d}/{} mac {:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x} connections={} buffer={} requests_per_second={}",
                net.prefix,
                m[0],
                m[1],
                m[2],
                m[3],
                m[4],
                m[5],
                net.connections,
                net.buffer,
                net.requests_per_second
            );
            if let Some(modbus) = net.modbus {
                let writable = match (modbus.write_outputs, modbus.write_markers) {
                    (true, true) => "outputs,markers",
                    (true, false) => "outputs",
                    (false, true) => "markers",
                    (false, false) => "none",
                };
                println!(
                    "plc: modbus on port {} unit {} writable={writable}",
                    modbus.port, modbus.unit
                );
            }
            if let Some(pubsub) = net.pubsub {
                if let Some(([a, b, c, d], port, names)) = pubsub.publish {
                    let mut line = text!("plc: publish to {a}.{b}.{c}.{d}:{port} vars=");
                    write_names(&mut line, names);
                    println!("{}", line.as_str());
                }
                if let Some(sub) = pubsub.subscribe {
                    let mut line = text!("plc: subscribe on port {}", sub.port);
                    if let Some([a, b, c, d]) = sub.group {
                        let _ = write!(line, " group={a}.{b}.{c}.{d}");
                    }
                    let _ = write!(line, " vars=");
                    write_names(&mut line, sub.names);
                    let _ = write!(
                        line,
                        " valid={} timeout_ms={}",
                        sub.valid.unwrap_or("-"),
                        sub.timeout_ns / 1_000_000
                    );
                    println!("{}", line.as_str());
                }
            }
            if let Some(online) = net.online {
                let mut line = text!("plc: online on port {} clients=", online.port);
                for (i, c) in online.clients().enumerate() {
                    let name = core::str::from_utf8(c.name).unwrap_or("?");
                    let comma = if i == 0 { "" } else { "," };
                    let _ = write!(line, "{comma}{name}:{}", c.access.name());
                }
                println!("{}", line.as_str());
            }
            // Below everything else of the PLC: it takes only the window's idle time.
            let priority = control_priority.saturating_sub(1).max(1);
            spawn(ctx, "comm", comm, period(), priority);
        }
    }
}

/// Writes the package's newline-separated `names` comma-separated (the start lines' lists).
fn write_names(line: &mut impl Write, names: &str) {
    for (i, name) in names.split('\n').enumerate() {
        let _ = write!(line, "{}{name}", if i == 0 { "" } else { "," });
    }
}

/// Creates and starts a periodic process (32 KiB of stack, soft deadline); its id, or
/// `None` after reporting why not.
fn spawn(
    ctx: &mut StartContext<Warden>,
    process_name: &str,
    entry_point: extern "C" fn(),
    period: Duration,
    priority: u8,
) -> Option<ProcessId> {
    let attributes = ProcessAttribute {
        period: SystemTime::Normal(period),
        time_capacity: SystemTime::Infinite,
        entry_point,
        stack_size: 32 * 1024,
        base_priority: i32::from(priority),
        deadline: Deadline::Soft,
        name: name(process_name)?,
    };
    match ctx.create_process(attributes) {
        Ok(process) => match process.start() {
            Ok(()) => Some(process.id()),
            Err(e) => {
                report(text!("START {process_name} failed: {e:?}").as_str());
                None
            }
        },
        Err(e) => {
            report(text!("CREATE_PROCESS {process_name} failed: {e:?}").as_str());
            None
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

// The communication process's stack and its connections' buffers live in the heap.
apex::partition_entry!(main, heap = 512 * 1024);
