//! syssw's restart worker: a second thread of syssw that builds restarted partitions'
//! new instances (reload and zero their memory, create the task, map everything, create
//! the first thread), so that the server thread (`crate::server`) never waits for that and
//! keeps answering every other partition. The queue, the protocol between the two threads
//! and why it is built this way are in `syssw_core::restart`.
//!
//! Ownership: the worker owns the [`Loader`] (frame allocator, scratch window, placements)
//! from its start on; the server thread never touches it again after start-up. It is handed
//! over once through [`HANDOVER`]; after that the two threads share only IPC messages (job
//! and report words) and the health records of [`HEALTH_RECORDS`], each passed from the
//! server to the worker with its job.
//!
//! Where the time goes: the server moves the worker into the restarted partition's time
//! partition before it hands over a job, so the kill of the old task and the health line
//! (when the server left them to the worker), the reload and the mapping run in that
//! partition's windows and never take time from another partition's window. There it runs
//! at syssw's priority ([`config::model::SYSSW_PRIORITY`], above every partition thread, one
//! below the server thread's [`SERVER_PRIORITY`], so the server still answers at once); a
//! background partition's restart runs at that partition's priority (it competes as the
//! partition itself would). On a machine of several CPUs the worker moves to the restarted
//! partition's CPU too (`syssw_core::restart::worker_place`); the server stays on CPU 0.
//!
//! Log lines (an interface): the health monitor's line the server handed over and the
//! restart's mode-change line (`crate::server`) when it starts;
//! `syssw: partition NAME: restart failed: REASON; it stays IDLE`;
//! `syssw: restart worker: WHAT` before a failure halt (a bug of syssw).

use crate::partitions::{Loader, Start};
use crate::server::{LogLine, log_mode_change};
use config::model::MAX_PARTITIONS;
use root_task::spawn::{SpawnError, Thread};
use syssw_core::health::Record;
use syssw_core::mode::OperatingMode;
use syssw_core::restart::{Job, Kind, Report};
use user_rt::abi::ipc::MessageTag;
use user_rt::abi::syscall::{TIMEOUT_INFINITE, TaskId, ThreadId};
use user_rt::println;
use user_rt::sys::{self, Message};

/// The server thread's priority: above the worker's, so that requests never wait for it.
pub const SERVER_PRIORITY: u8 = config::model::SYSSW_PRIORITY + 1;

/// Pages of the worker's stack (`instantiate` keeps a start record and a few arrays of
/// segments on it).
const STACK_PAGES: u64 = 16;

/// The loader on its way from the server thread to the worker. A static is the only place
/// both threads can name without `unsafe` (a new thread gets one word of argument); the
/// lock is taken exactly twice, by the server before it starts the worker and by the worker
/// when it starts, so it never spins. Its acquire/release ordering (and the `thread_start`
/// system call in between) makes the server's writes to the loader visible to the worker.
static HANDOVER: spin::Mutex<Option<Loader>> = spin::Mutex::new(None);

/// Per partition, the health record of the error that caused its restart, for the worker to
/// print in the partition's window (formatting and printing it is most of what a fault
/// report costs the server thread). The server fills a partition's slot only right before
/// it hands that partition's job to the worker, and the worker empties it when it runs the
/// job; the partition has no task in between, so no second record for it can come, and the
/// two never want a slot at once. Both only `try_lock`, never spin: the server outranks the
/// worker, so it could never wait for a lock a preempted worker holds (should its try fail,
/// it prints the line itself); the server holds a slot only while it writes it, so the
/// worker, which cannot run meanwhile, always gets it. Acquire/release of the lock (and the
/// `reply` in between) make the record the server wrote visible to the worker.
static HEALTH_RECORDS: [spin::Mutex<Option<Record>>; MAX_PARTITIONS] =
    [const { spin::Mutex::new(None) }; MAX_PARTITIONS];

/// Leaves `record` for the worker to print with partition `index`'s job (which the caller
/// hands over next). False if it cannot: the caller prints it.
pub fn hand_over_record(index: usize, record: Record) -> bool {
    match HEALTH_RECORDS.get(index).and_then(|slot| slot.try_lock()) {
        Some(mut slot) => {
            *slot = Some(record);
            true
        }
        None => false,
    }
}

/// Creates the worker (inactive) with the loader's spawner and hands the loader over; start
/// it with `thread_start`. It first asks `server` for a job at syssw's priority.
pub fn create_worker(mut loader: Loader, server: ThreadId) -> Result<Thread, SpawnError> {
    let thread = loader.spawner().thread(
        None,
        worker,
        config::model::SYSSW_PRIORITY,
        server.0,
        STACK_PAGES,
    )?;
    *HANDOVER.lock() = Some(loader);
    Ok(thread)
}

/// The worker thread: asks the server for a job, runs it, reports it with its next call.
extern "C" fn worker(server: u64) -> ! {
    let server = ThreadId(server);
    let Some(mut loader) = HANDOVER.lock().take() else {
        fatal(format_args!("started without its loader"))
    };
    let mut report = Report::Ready;
    loop {
        let (label, words) = report.encode();
        let call = Message {
            tag: MessageTag::new(label, 0, 0),
            words,
        };
        // The server answers when a restart is queued; it never goes away, so a failed
        // call is a bug of syssw: no partition could ever be restarted again.
        let reply = match sys::ipc_call(server, TIMEOUT_INFINITE, &call) {
            Ok(reply) => reply,
            Err(e) => fatal(format_args!("call to the server failed: {e:?}")),
        };
        let Some(job) = Job::from_words(reply.message.words) else {
            fatal(format_args!("a reply that is no job"))
        };
        report = run(&mut loader, job);
    }
}

/// A bug of syssw's own: the module cannot go on safely.
fn fatal(what: core::fmt::Arguments) -> ! {
    println!("syssw: restart worker: {what}");
    let _ = sys::system_halt(false);
    sys::thread_exit()
}

fn run(loader: &mut Loader, job: Job) -> Report {
    if let Some(task) = job.kill {
        let _ = sys::task_kill(TaskId(task));
    }
    // The health monitor's line about the error that caused this restart, if the server
    // left it to be printed here.
    let record = HEALTH_RECORDS[job.partition]
        .try_lock()
        .and_then(|mut slot| slot.take());
    if let Some(record) = record {
        println!("{}", LogLine(&loader.system, &record));
    }
    let (start, mode) = match job.kind {
        Kind::Cold => (Start::Cold, OperatingMode::ColdStart),
        Kind::Warm => (Start::Warm, OperatingMode::WarmStart),
    };
    let name = loader.system.partition(job.partition).name;
    log_mode_change(name, mode, job.condition, job.restarts);
    match loader.instantiate(job.partition, start, job.condition as u64) {
        Ok(instance) => Report::Done {
            partition: job.partition,
            task: instance.task.0,
            thread: instance.thread.0,
        },
        Err(e) => {
            println!("syssw: partition {name}: restart failed: {e}; it stays IDLE");
            Report::Failed {
                partition: job.partition,
            }
        }
    }
}
