//! The partition runtime: start-up, the runtime lock, process threads and the deadline
//! watchdog (the bounded heap and its own lock: [`crate::heap`]). Everything here talks to
//! the kernel (`user_rt::sys`) or to syssw (`user_rt::service`); the decisions come from
//! [`crate::table`].
//!
//! # The runtime lock (priority ceiling)
//!
//! All runtime state (process table and intra-partition objects) lives behind one lock.
//! Threads of a task have fixed priorities without time slicing, so a spin lock held by a
//! preempted low-priority thread would make a higher-priority one spin for ever. A thread
//! therefore raises itself to the task's MCP before it takes the lock and drops back after:
//! no thread of the partition can preempt it meanwhile (the watchdog and error handler run
//! at the MCP too, and equal priorities do not preempt), and it never blocks while holding
//! it. On the single CPU the lock is thus never contended; finding it taken means its
//! holder died inside (a bug), which panics instead of spinning.

// The start record, the static thread stacks and IPC buffers and the threads' GS bases are
// raw memory: the reason for `unsafe` in this module.
#![allow(unsafe_code)]

use crate::codes;
use crate::heap;
use crate::intra::Intra;
use crate::table::{self, Delivery, ERROR_HANDLER_SLOT, MIN_STACK, PendingError, SLOTS, Table};
use crate::time;
use a653rs::bindings::{ErrorCode, ErrorReturnCode, ProcessId};
use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use protocol::{PartitionStatus, ReplyWords, Request};
use spin::mutex::{SpinMutex, SpinMutexGuard};
use user_rt::abi::ipc::IpcBuffer;
use user_rt::abi::syscall::{ThreadAttribute, ThreadId};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::partition::StartInfo;
use user_rt::service::{self, ReceiveError, Reply};
use user_rt::sys;

/// Bytes of the heap arena [`crate::partition_entry!`] gives a program that names none.
pub const HEAP_SIZE: usize = 64 * 1024;
/// Thread index of the initialisation (main) thread; 0..SLOTS are the process slots.
pub const MAIN: usize = SLOTS;
/// Thread index of the deadline watchdog.
pub const WATCHDOG: usize = SLOTS + 1;
const THREADS: usize = SLOTS + 2;
/// Notification bit that wakes the watchdog (an earlier deadline) or a SUSPEND_SELF
/// (RESUME).
pub const WAKE_BIT: u64 = 1;
/// Notification bit that ends a process's wait on an intra-partition object (its outcome
/// is decided in [`Intra`] by the waker).
pub const OBJECT_BIT: u64 = 2;
/// The notification bits the runtime uses; a program's own (interrupt lines, port
/// doorbells) must be others.
pub const RUNTIME_BITS: u64 = WAKE_BIT | OBJECT_BIT;

/// Warden's extension of queuing ports (not in ARINC 653): the calling process's thread is
/// notified with `bits` (`sys::notify_wait`) whenever messages arrive at the partition's
/// queuing destination port `port`; 0 ends it (syssw's PORT_DOORBELL). For a process that
/// waits for several ports and a device at once instead of polling them. Bits of
/// [`RUNTIME_BITS`] are INVALID_PARAM.
pub fn port_doorbell(
    port: a653rs::bindings::QueuingPortId,
    bits: u64,
) -> Result<(), ErrorReturnCode> {
    if bits & RUNTIME_BITS != 0 {
        return Err(ErrorReturnCode::InvalidParam);
    }
    let port = codes::id_word(port)?;
    request_code(&Request::PortDoorbell { port, bits }).map(drop)
}

/// The watchdog's stack (16-byte aligned as the SysV ABI wants).
#[repr(C, align(16))]
struct Stack([u8; MIN_STACK]);

// Stacks and IPC buffers are used only through their addresses (by the threads running on
// them and by the kernel), never through Rust references, so `static mut` with raw
// addresses is all they need.
static mut WATCHDOG_STACK: Stack = Stack([0; MIN_STACK]);
static mut IPC_BUFFERS: [IpcBuffer; THREADS] = [const { IpcBuffer::new() }; THREADS];

/// A heap or stack arena: static memory of the partition program, `N` bytes, used by
/// nothing but the runtime's heap or its processes' stacks ([`crate::partition_entry!`]
/// defines one of each and passes them to [`start`]).
#[repr(C, align(16))]
pub struct Arena<const N: usize>(pub [u8; N]);

/// The arenas [`start`] was given: their addresses and sizes.
static HEAP_ARENA: SpinMutex<(usize, usize)> = SpinMutex::new((0, 0));
static STACK_ARENA: SpinMutex<(usize, usize)> = SpinMutex::new((0, 0));

struct State {
    table: Table,
    intra: Intra,
}

static STATE: SpinMutex<State> = SpinMutex::new(State {
    table: Table::EMPTY,
    intra: Intra::EMPTY,
});

/// Raw thread ids by thread index (0 = none), readable without the lock: how a thread
/// finds its own IPC buffer and slot. Each thread's GS base is the address of its entry
/// ([`thread_id`]).
static THREAD_IDS: [AtomicU64; THREADS] = [const { AtomicU64::new(0) }; THREADS];
/// The priority the runtime last gave each thread (by thread index) outside its critical
/// sections (the table's; [`own_priority`]).
static OWN_PRIORITIES: [AtomicU8; THREADS] = [const { AtomicU8::new(0) }; THREADS];
static MCP: AtomicU8 = AtomicU8::new(0);
static TIME_PARTITION: AtomicU64 = AtomicU64::new(0);
static PARTITION_INDEX: AtomicU64 = AtomicU64::new(0);

/// Whether CREATE_PROCESS reads a period of 0 as a653rs-linux does (see
/// [`read_zero_period_as_partition_period`]).
static ZERO_PERIOD_IS_PARTITION_PERIOD: AtomicBool = AtomicBool::new(false);

/// For programs written for DLR's a653rs-linux (`a653rs-compat` calls it before their
/// `main`): from now on CREATE_PROCESS takes a period of 0 as the partition's period
/// (a653rs-linux releases every process with a finite period once per partition period;
/// its examples say `period = "0ms"`), where ARINC 653 answers INVALID_PARAM
/// ([`time::a653rs_linux_period`]).
pub fn read_zero_period_as_partition_period() {
    ZERO_PERIOD_IS_PARTITION_PERIOD.store(true, Ordering::Relaxed);
}

/// See [`read_zero_period_as_partition_period`].
pub fn zero_period_is_partition_period() -> bool {
    ZERO_PERIOD_IS_PARTITION_PERIOD.load(Ordering::Relaxed)
}

/// The start record of the current run (a copy).
static START_INFO: SpinMutex<Option<StartInfo>> = SpinMutex::new(None);

/// The start record syssw gave this run of the partition (its name, index, time
/// partition, start condition, MCP).
pub fn start_info() -> StartInfo {
    START_INFO.lock().expect("the runtime has started")
}

pub fn mcp() -> u8 {
    MCP.load(Ordering::Relaxed)
}

/// The calling thread's id, without a system call: every thread of the partition has its
/// GS base at its entry of the thread ids (`start`, `create_thread`).
pub fn thread_id() -> u64 {
    let id: u64;
    // SAFETY: the thread's GS base is the address of its `THREAD_IDS` entry, a static
    // `AtomicU64` (8-aligned, so this load is one atomic read), set before the thread ran.
    unsafe {
        core::arch::asm!(
            "mov {}, qword ptr gs:[0]",
            out(reg) id,
            options(nostack, readonly, preserves_flags)
        )
    };
    id
}

/// Points the GS base of `thread` (None: the caller) at its entry of the thread ids.
fn set_thread_id_base(thread: Option<ThreadId>, index: usize) -> Result<(), ErrorReturnCode> {
    let entry = (&THREAD_IDS[index]) as *const AtomicU64 as u64;
    sys::thread_set(thread, ThreadAttribute::GsBase, entry)
        .map_err(|_| ErrorReturnCode::InvalidConfig)
}

/// The calling thread's index (MAIN, WATCHDOG or a process slot).
pub fn own_index() -> Option<usize> {
    index_of(thread_id())
}

fn index_of(thread: u64) -> Option<usize> {
    THREAD_IDS
        .iter()
        .position(|t| t.load(Ordering::Relaxed) == thread)
}

/// The priority the runtime last gave thread `index` to run at outside its critical
/// sections: what a thread lent a higher one drops back to.
pub fn own_priority(index: usize) -> u8 {
    OWN_PRIORITIES[index].load(Ordering::Relaxed)
}

/// Notes the priority thread `index` runs at outside critical sections from now on.
pub fn note_own_priority(index: usize, priority: u8) {
    OWN_PRIORITIES[index].store(priority, Ordering::Relaxed);
}

/// The calling thread's process slot, if it is a process.
pub fn own_slot() -> Option<usize> {
    own_index().filter(|&i| i < SLOTS)
}

fn ipc_address(index: usize) -> u64 {
    (&raw mut IPC_BUFFERS)
        .cast::<IpcBuffer>()
        .wrapping_add(index) as u64
}

/// The initial stack pointer of a stack of `size` bytes at `base` (16-byte aligned): as if
/// called, since the SysV ABI expects rsp + 8 to be 16-byte aligned at entry.
fn stack_top(base: u64, size: usize) -> u64 {
    base + size as u64 - 8
}

/// The initial stack pointer of process `slot`, on its stack in the stack arena.
fn process_stack_top(table: &Table, slot: usize) -> Result<u64, ErrorReturnCode> {
    let place = table.get(slot).ok_or(ErrorReturnCode::InvalidParam)?.stack;
    let (arena, size) = *STACK_ARENA.lock();
    // The table never places a stack beyond the arena it was given; checked all the same.
    if place.offset + place.size > size {
        return Err(ErrorReturnCode::InvalidConfig);
    }
    Ok(stack_top((arena + place.offset) as u64, place.size))
}

/// A critical section on the runtime state (see the module documentation).
pub struct Critical {
    guard: Option<SpinMutexGuard<'static, State>>,
    me: u64,
}

impl Critical {
    pub fn enter() -> Self {
        let me = thread_id();
        // Before `start` has read the MCP (0) nothing else of the partition runs.
        if mcp() != 0 {
            let _ = sys::thread_set(None, ThreadAttribute::Priority, u64::from(mcp()));
        }
        let Some(guard) = STATE.try_lock() else {
            panic!("APEX runtime lock held by a thread that died inside it");
        };
        Self {
            guard: Some(guard),
            me,
        }
    }

    pub fn table(&mut self) -> &mut Table {
        &mut self.guard.as_mut().expect("held until dropped").table
    }

    /// The process table and the intra-partition objects.
    pub fn parts(&mut self) -> (&mut Table, &mut Intra) {
        let state: &mut State = self.guard.as_mut().expect("held until dropped");
        (&mut state.table, &mut state.intra)
    }

    /// Leaves the section and ends the calling thread without dropping its priority first,
    /// so nothing of the partition runs between (e.g. START reusing its stack).
    pub fn exit(mut self) -> ! {
        drop(self.guard.take());
        core::mem::forget(self);
        sys::thread_exit()
    }
}

impl Drop for Critical {
    fn drop(&mut self) {
        if let Some(guard) = self.guard.take() {
            let priority = guard.table.priority_of_thread(self.me);
            drop(guard);
            if let Some(index) = index_of(self.me) {
                note_own_priority(index, priority);
            }
            if mcp() != 0 && priority != mcp() {
                let _ = sys::thread_set(None, ThreadAttribute::Priority, u64::from(priority));
            }
        }
    }
}

/// Starts the runtime on the partition's first thread and runs `main` on it (what
/// [`crate::partition_entry!`] expands to), `heap` serving as the heap and `stacks` as the
/// processes' stacks. Ends the thread when `main` returns.
///
/// # Safety
/// `heap` and `stacks` are statics of the program that nothing else ever uses (the
/// macro's own).
pub unsafe fn start<const N: usize, const S: usize>(
    start_record: u64,
    main: fn(),
    heap: *mut Arena<N>,
    stacks: *mut Arena<S>,
) -> ! {
    *HEAP_ARENA.lock() = (heap as usize, N);
    *STACK_ARENA.lock() = (stacks as usize, S);
    // SAFETY: syssw starts every partition's first thread with the address of its start
    // record in rdi (`user_rt::partition`), which `_start` passes on unchanged.
    let Some(info) = (unsafe { StartInfo::from_start(start_record) }) else {
        user_rt::println!("apex: no start record from syssw");
        sys::thread_exit()
    };
    let me = sys::thread_self().0;
    *START_INFO.lock() = Some(*info);
    MCP.store(info.mcp.min(255) as u8, Ordering::Relaxed);
    TIME_PARTITION.store(info.time_partition, Ordering::Relaxed);
    PARTITION_INDEX.store(info.index, Ordering::Relaxed);
    if let Err(e) = sys::thread_set(None, ThreadAttribute::IpcBuffer, ipc_address(MAIN)) {
        panic!("apex: cannot register the IPC buffer: {e:?}");
    }
    service::set_server(ThreadId(info.server));
    for id in &THREAD_IDS {
        id.store(0, Ordering::Relaxed);
    }
    THREAD_IDS[MAIN].store(me.0, Ordering::Relaxed);
    if let Err(e) = set_thread_id_base(None, MAIN) {
        panic!("apex: cannot set the GS base: {e:?}");
    }
    note_own_priority(MAIN, info.priority.min(255) as u8);
    let partition_period = partition_status().map_or(0, |s| s.period_ns);
    reset_state(Table::new(
        mcp(),
        partition_period,
        me.0,
        info.priority.min(255) as u8,
        S,
    ));
    main();
    sys::thread_exit()
}

/// A (re)start: every other thread of the partition is gone. After a warm restart the
/// memory is as it was, so the lock may still be held by a thread that was stopped inside
/// it, and the heap may be mid-operation then.
fn reset_state(table: Table) {
    let was_locked = STATE.is_locked();
    if was_locked {
        // SAFETY: the only threads that could hold the lock belonged to the partition's
        // previous run and no longer exist; this is the only thread of the partition now.
        unsafe { STATE.force_unlock() };
    }
    let mut state = STATE.lock();
    state.table = table;
    state.intra.reset();
    drop(state);
    let (arena, size) = *HEAP_ARENA.lock();
    heap::restart(arena, size);
}

/// syssw's server and the calling thread's IPC buffer.
fn channel() -> Result<(ThreadId, IpcBufferRef), ErrorReturnCode> {
    let index = own_index().ok_or(ErrorReturnCode::InvalidMode)?;
    let server = service::server().ok_or(ErrorReturnCode::NotAvailable)?;
    // SAFETY: `ipc_address(index)` is the static IPC buffer registered for this thread
    // (IPC_BUFFER_SIZE bytes, 8-aligned, writable) and nothing takes references to it.
    let ipc = unsafe { IpcBufferRef::new(ipc_address(index)) };
    Ok((server, ipc))
}

/// Sends a protocol request from the calling thread's IPC buffer; reply data stays there.
pub fn request(request: &Request) -> Result<(Reply, IpcBufferRef), ErrorReturnCode> {
    let (server, ipc) = channel()?;
    let reply =
        service::request(server, ipc, request).map_err(|_| ErrorReturnCode::NotAvailable)?;
    Ok((reply, ipc))
}

/// Sends the request `build(staged, last part)` makes for a port message of any length
/// (`user_rt::service::request_with_message`).
pub fn request_message<'m>(
    message: &'m [u8],
    build: impl FnOnce(u64, &'m [u8]) -> Request<'m>,
) -> Result<Reply, ErrorReturnCode> {
    let (server, ipc) = channel()?;
    service::request_with_message(server, ipc, message, build)
        .map_err(|_| ErrorReturnCode::NotAvailable)
}

/// Copies the message of `len` bytes a reply announced into `out`, fetching what did not
/// fit the reply: INVALID_PARAM if `out` is shorter (the message is dropped),
/// NOT_AVAILABLE if the service failed.
pub fn receive_message(len: usize, out: &mut [u8]) -> Result<(), ErrorReturnCode> {
    let (server, ipc) = channel()?;
    service::receive_message(server, ipc, len, out).map_err(|e| match e {
        ReceiveError::TooLong => ErrorReturnCode::InvalidParam,
        ReceiveError::Failed => ErrorReturnCode::NotAvailable,
    })
}

/// Runs `f`, the transfer of a message longer than one request (`long`), at the
/// partition's MCP: no process of the partition but one at the MCP (the error handler)
/// runs in the middle of it, which bounds the staging buffers the partition's transfers
/// hold in syssw at once (`protocol::STAGING_RUNNERS`). A receive that waits, waits at the
/// MCP and fetches its message as soon as it comes.
pub fn long_transfer<R>(long: bool, f: impl FnOnce() -> R) -> R {
    if !long || mcp() == 0 {
        return f();
    }
    let _ = sys::thread_set(None, ThreadAttribute::Priority, u64::from(mcp()));
    let result = f();
    // Leaving a critical section drops the thread back to its own priority.
    drop(Critical::enter());
    result
}

/// A request whose reply carries only a code.
pub fn request_code(request: &Request) -> Result<Reply, ErrorReturnCode> {
    let (reply, _) = self::request(request)?;
    codes::from_reply(reply.label)?;
    Ok(reply)
}

/// The reply words of a request, decoded as `R` (words syssw should never send are
/// NOT_AVAILABLE: the service could not be performed).
pub fn request_words<R: ReplyWords>(request: &Request) -> Result<R, ErrorReturnCode> {
    let reply = request_code(request)?;
    R::from_words(reply.words).map_err(|_| ErrorReturnCode::NotAvailable)
}

pub fn partition_status() -> Result<PartitionStatus, ErrorReturnCode> {
    request_words(&Request::PartitionStatus)
}

pub fn partition_index() -> u64 {
    PARTITION_INDEX.load(Ordering::Relaxed)
}

/// The partition's next release point at or after `now`.
pub fn release_point(now: u64, partition_period: u64) -> u64 {
    let tp = TIME_PARTITION.load(Ordering::Relaxed);
    if tp == 0 {
        return now;
    }
    let window = sys::partition_info(tp).map_or(u64::MAX, |i| i.next_window_start);
    time::next_release_point(now, window, partition_period)
}

/// Creates the (inactive) thread of thread index `index` running `entry(index)` on the
/// stack whose initial pointer is `stack`.
pub fn create_thread(
    index: usize,
    entry: extern "C" fn(u64) -> !,
    stack: u64,
    priority: u8,
) -> Result<u64, ErrorReturnCode> {
    let thread = sys::thread_create(None, entry as usize as u64, stack, priority, index as u64)
        .map_err(|_| ErrorReturnCode::InvalidConfig)?;
    if sys::thread_set(Some(thread), ThreadAttribute::IpcBuffer, ipc_address(index)).is_err()
        || set_thread_id_base(Some(thread), index).is_err()
    {
        let _ = sys::thread_kill(thread);
        return Err(ErrorReturnCode::InvalidConfig);
    }
    THREAD_IDS[index].store(thread.0, Ordering::Relaxed);
    note_own_priority(index, priority);
    Ok(thread.0)
}

pub fn forget_thread(index: usize) {
    THREAD_IDS[index].store(0, Ordering::Relaxed);
}

/// Wakes the watchdog if `table`'s earliest deadline is before the time it sleeps until.
pub fn poke_watchdog(table: &mut Table) {
    if let (Some(deadline), Some(watchdog)) = (table.earliest_deadline(), table.watchdog_thread)
        && deadline < table.watchdog_armed
    {
        table.watchdog_armed = deadline;
        let _ = sys::notify_signal(ThreadId(watchdog), WAKE_BIT);
    }
}

/// Starts the watchdog thread if the table needs one and it does not run yet.
pub fn ensure_watchdog(table: &mut Table) -> Result<(), ErrorReturnCode> {
    if table.watchdog_thread.is_some() || !table.needs_watchdog() {
        return Ok(());
    }
    let stack = stack_top((&raw mut WATCHDOG_STACK) as u64, MIN_STACK);
    let thread = create_thread(WATCHDOG, watchdog_main, stack, table.mcp)?;
    table.watchdog_thread = Some(thread);
    let _ = sys::thread_start(ThreadId(thread));
    Ok(())
}

/// The body of every process thread: wait for the release point, run the entry point,
/// and become dormant when it returns (as STOP_SELF).
extern "C" fn process_main(slot: u64) -> ! {
    let slot = slot as usize;
    let (entry, release) = {
        let mut critical = Critical::enter();
        let process = critical.table().get(slot).expect("a started process");
        (process.attributes.entry_point, process.release)
    };
    sys::sleep_until(release);
    Critical::enter().table().released(slot);
    entry();
    stop_self()
}

/// Creates, registers and starts the thread of process `slot`, released at `release`.
pub fn launch(table: &mut Table, slot: usize, release: u64) -> Result<(), ErrorReturnCode> {
    let priority = if slot == ERROR_HANDLER_SLOT {
        table.mcp
    } else {
        table
            .get(slot)
            .map_or(1, |p| p.attributes.base_priority as u8)
    };
    let stack = process_stack_top(table, slot)?;
    let thread = create_thread(slot, process_main, stack, priority)?;
    if slot == ERROR_HANDLER_SLOT {
        table.activate_error_handler(release, thread)?;
    } else {
        table.activate(slot, release, thread)?;
    }
    let _ = sys::thread_start(ThreadId(thread));
    poke_watchdog(table);
    Ok(())
}

/// Creates the inactive thread of a process STARTed during initialisation.
pub fn prepare(table: &mut Table, slot: usize, delay: u64) -> Result<(), ErrorReturnCode> {
    let priority = table
        .get(slot)
        .map_or(1, |p| p.attributes.base_priority as u8);
    let stack = process_stack_top(table, slot)?;
    let thread = create_thread(slot, process_main, stack, priority)?;
    table.make_pending(slot, delay, thread)
}

/// NORMAL mode was granted: releases the processes STARTed during initialisation and
/// starts the watchdog. The caller then ends the initialisation thread.
pub fn begin_normal(table: &mut Table) {
    let now = sys::clock();
    let point = release_point(now, table.partition_period);
    let released = table.begin_normal(now, point);
    if ensure_watchdog(table).is_err() {
        user_rt::println!("apex: no thread for the deadline watchdog; deadlines unchecked");
    }
    for slot in 0..SLOTS {
        if released & (1 << slot) != 0
            && let Some(thread) = table.get(slot).and_then(|p| p.thread)
        {
            let _ = sys::thread_start(ThreadId(thread));
        }
    }
    poke_watchdog(table);
}

/// STOP_SELF of the calling thread (any thread: a non-process just ends).
pub fn stop_self() -> ! {
    let slot = own_slot();
    let mut critical = Critical::enter();
    if let Some(slot) = slot {
        let (table, intra) = critical.parts();
        let _ = table.stop(slot);
        intra.forget(slot);
        apply_intra(table, intra, Some(slot));
        forget_thread(slot);
    }
    critical.exit()
}

/// Carries out what intra-partition services decided for other threads: priorities
/// (mutex ceilings and restores) and the wakes of waiters whose outcome is decided. The
/// caller's own priority is set by its table entry when it leaves the critical section.
pub fn apply_intra(table: &mut Table, intra: &mut Intra, caller: Option<usize>) {
    for slot in 0..SLOTS {
        if let Some(priority) = intra.take_priority(slot)
            && let Some(thread) = table.set_current_priority(slot, priority)
            && Some(slot) != caller
        {
            note_own_priority(slot, priority);
            let _ = sys::thread_set(
                Some(ThreadId(thread)),
                ThreadAttribute::Priority,
                u64::from(priority),
            );
        }
    }
    let woken = intra.take_woken();
    for slot in 0..SLOTS {
        if woken & (1 << slot) != 0
            && let Some(thread) = table.get(slot).and_then(|p| p.thread)
        {
            let _ = sys::notify_signal(ThreadId(thread), OBJECT_BIT);
        }
    }
}

/// Sends an error where it belongs: the error handler (started if dormant) or syssw's
/// health monitor (REPORT_ERROR with `text` as detail).
pub fn raise(code: ErrorCode, process: Option<usize>, text: &[u8]) -> Result<(), ErrorReturnCode> {
    let id: ProcessId = process.map_or(0, table::id_of);
    let error = PendingError::new(code, id, text);
    let delivery = {
        let mut critical = Critical::enter();
        let table = critical.table();
        let mut delivery = table.push_error(error, process);
        if delivery == Delivery::StartHandler
            && launch(table, ERROR_HANDLER_SLOT, sys::clock()).is_err()
        {
            // Without its thread the handler cannot take the error: drop it from the
            // queue by handing it to the health monitor as well.
            delivery = Delivery::Monitor;
        }
        delivery
    };
    if delivery == Delivery::Monitor {
        let error = Request::ReportError {
            error: codes::error_code(code).ok_or(ErrorReturnCode::InvalidParam)?,
            detail: error.text(),
        };
        request_code(&error)?;
    }
    Ok(())
}

/// The deadline watchdog: sleeps until the earliest pending deadline; a process that has
/// not reached its next PERIODIC_WAIT (or REPLENISHed) by then missed it.
extern "C" fn watchdog_main(_: u64) -> ! {
    let mut text = [0u8; 64];
    loop {
        let (missed, sleep_until) = {
            let mut critical = Critical::enter();
            let table = critical.table();
            let now = sys::clock();
            let missed = table.take_missed(now).map(|slot| {
                let name = table
                    .get(slot)
                    .map_or(&[][..], |p| codes::name_bytes(&p.attributes.name));
                (slot, deadline_text(&mut text, name))
            });
            let earliest = table.earliest_deadline().unwrap_or(u64::MAX);
            table.watchdog_armed = earliest;
            (missed, earliest)
        };
        if let Some((slot, length)) = missed {
            let _ = raise(ErrorCode::DeadlineMissed, Some(slot), &text[..length]);
            continue;
        }
        let timeout = match sleep_until {
            u64::MAX => time::PROTOCOL_FOREVER,
            at => at.saturating_sub(sys::clock()),
        };
        let _ = sys::notify_wait(WAKE_BIT, timeout);
    }
}

/// `process NAME deadline` into `out`; its length.
fn deadline_text(out: &mut [u8; 64], name: &[u8]) -> usize {
    let mut length = 0;
    for part in [&b"process "[..], name, b" deadline"] {
        let n = part.len().min(out.len() - length);
        out[length..length + n].copy_from_slice(&part[..n]);
        length += n;
    }
    length
}
