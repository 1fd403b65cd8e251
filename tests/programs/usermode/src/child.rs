//! Support for tests that run code in extra threads and child tasks.
//!
//! The root task (this program) is the *lab*: it creates child tasks running this same
//! binary (`user_rt::spawn`: code shared read-only at the same addresses, writable data
//! private) and *workers*: threads in the root task or a child that run an entry defined with
//! [`worker!`] and get a [`Block`], one page shared with the root at the same address in
//! both tasks. The root writes a worker's arguments there before starting it; the worker
//! writes results (raw error codes, values), a progress step and a done flag, all atomics.
//! Workers never decide a check themselves (children may not halt the machine): the root
//! reads their results and checks them. Waits are bounded ([`WAIT`]) so a kernel that never
//! wakes someone fails a check instead of hanging the run.
//!
//! Every address the lab hands out is unique across all tasks, so an address shared with a
//! child means the same memory in both.

use crate::check::{fail, must};
use core::sync::atomic::{AtomicU64, Ordering};
use root_task::spawn::{AddressRange, FramePool, SpawnError, Spawner, ThreadEntry, words_at};
use user_rt::abi::syscall::{Abilities, Error, PageRights, TaskId, ThreadId};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::sys;

/// The longest the root waits for anything a worker should do promptly (ns).
pub const WAIT: u64 = 2_000_000_000;
pub const MS: u64 = 1_000_000;
/// Where the lab's addresses come from (in every task).
const LAB_BASE: u64 = 0x0000_1000_0000_0000;
const LAB_END: u64 = 0x0000_2000_0000_0000;
/// Stack of a worker (32 KiB: `println!` formats on the stack).
pub const STACK_PAGES: u64 = 8;
/// Usual priority of workers: below the root's (200), so they run only while the root
/// waits, and the root's checks never race with them.
pub const LOW: u8 = 100;
/// Usual MCP of child tasks.
pub const CHILD_MCP: u8 = 150;
/// Abilities of an ordinary child: it may log (panics and traces are visible) and make
/// system calls.
pub const BASIC: Abilities = Abilities::DEBUG_LOG.union(Abilities::NATIVE_SYSCALLS);

/// Word layout of a block (one page, 512 words).
const W_IPC: usize = 0;
const W_SELF: usize = 1;
const W_ARGS: usize = 8;
const ARGS: usize = 24;
const W_RESULTS: usize = 32;
/// Results a worker can report.
pub const RESULTS: usize = 448;
const W_STEP: usize = 510;
const W_DONE: usize = 511;
const BLOCK_WORDS: usize = 512;

/// A worker's page shared with the root; see the module documentation.
#[derive(Clone, Copy)]
pub struct Block(&'static [AtomicU64]);

impl Block {
    /// # Safety
    /// `arg` must be the argument the lab started this worker with ([`Lab::worker`]).
    pub unsafe fn from_arg(arg: u64) -> Self {
        // SAFETY: the lab passes the address of a block it mapped (writable, never
        // unmapped) into the worker's task; the caller guarantees that is what `arg` is.
        Self(unsafe { words_at(arg, BLOCK_WORDS) })
    }

    /// The worker's own IPC buffer.
    ///
    /// # Safety
    /// Only the block's worker thread may call this (the buffer is mapped in its task only).
    pub unsafe fn own_ipc(&self) -> IpcBufferRef {
        // SAFETY: the lab stored here the address of the IPC buffer it mapped for this
        // worker in the worker's task; the caller is that worker.
        unsafe { IpcBufferRef::new(self.0[W_IPC].load(Ordering::Acquire)) }
    }

    /// The block's address (the same in the root and in the worker's task).
    pub fn address(&self) -> u64 {
        self.0.as_ptr() as u64
    }

    pub fn arg(&self, i: usize) -> u64 {
        assert!(i < ARGS);
        self.0[W_ARGS + i].load(Ordering::Acquire)
    }

    pub fn set_arg(&self, i: usize, value: u64) {
        assert!(i < ARGS);
        self.0[W_ARGS + i].store(value, Ordering::Release);
    }

    pub fn result(&self, i: usize) -> u64 {
        assert!(i < RESULTS);
        self.0[W_RESULTS + i].load(Ordering::Acquire)
    }

    pub fn set_result(&self, i: usize, value: u64) {
        assert!(i < RESULTS);
        self.0[W_RESULTS + i].store(value, Ordering::Release);
    }

    /// Stores a call's outcome as its raw error code (0 = success).
    pub fn set_code<T>(&self, i: usize, result: &Result<T, Error>) {
        self.set_result(i, crate::check::code(result));
    }

    /// Atomically adds to a result (counters).
    pub fn add_result(&self, i: usize, value: u64) -> u64 {
        assert!(i < RESULTS);
        self.0[W_RESULTS + i].fetch_add(value, Ordering::AcqRel)
    }

    pub fn step(&self) -> u64 {
        self.0[W_STEP].load(Ordering::Acquire)
    }

    pub fn set_step(&self, step: u64) {
        self.0[W_STEP].store(step, Ordering::Release);
    }

    pub fn finish(&self) {
        self.0[W_DONE].store(1, Ordering::Release);
    }

    pub fn is_done(&self) -> bool {
        self.0[W_DONE].load(Ordering::Acquire) != 0
    }
}

/// Defines a worker entry: `worker!(fn name(block, ipc) { ... })` makes
/// `extern "C" fn name(arg: u64) -> !` that binds the worker's [`Block`] and own IPC buffer,
/// runs the body, marks the block done and ends the thread.
macro_rules! worker {
    ($(#[$meta:meta])* fn $name:ident($block:ident, $ipc:ident) $body:block) => {
        $(#[$meta])*
        #[allow(unreachable_code, unused_variables)]
        pub extern "C" fn $name(arg: u64) -> ! {
            // SAFETY: worker entries are only started by `Lab::worker`, which passes the
            // block's address; this code runs in the worker thread itself.
            let ($block, $ipc) = unsafe {
                let block = $crate::child::Block::from_arg(arg);
                (block, block.own_ipc())
            };
            $body
            $block.finish();
            user_rt::sys::thread_exit()
        }
    };
}
pub(crate) use worker;

/// A thread made by [`Lab::worker`] (inactive until [`Worker::start`]).
#[derive(Clone, Copy)]
pub struct Worker {
    pub id: ThreadId,
    pub block: Block,
}

impl Worker {
    pub fn start(&self) {
        must("thread_start of a worker", sys::thread_start(self.id));
    }

    /// Waits (sleeping, so lower-priority threads run) until the worker is done; fails the
    /// run if it is not done within [`WAIT`].
    pub fn wait_done(&self, what: &str) {
        if !wait_until(WAIT, || self.block.is_done()) {
            fail(
                what,
                format_args!(
                    ": worker {:#x} not done within {} ms (step {})",
                    self.id.0,
                    WAIT / MS,
                    self.block.step()
                ),
            );
        }
    }

    /// Waits until the worker reached `step`.
    pub fn wait_step(&self, step: u64, what: &str) {
        if !wait_until(WAIT, || self.block.step() >= step) {
            fail(
                what,
                format_args!(
                    ": worker {:#x} did not reach step {step} within {} ms (step {})",
                    self.id.0,
                    WAIT / MS,
                    self.block.step()
                ),
            );
        }
    }
}

/// Polls `cond` every 200 µs (sleeping in between) for up to `timeout_ns`.
pub fn wait_until(timeout_ns: u64, cond: impl Fn() -> bool) -> bool {
    let deadline = sys::clock() + timeout_ns;
    loop {
        if cond() {
            return true;
        }
        if sys::clock() > deadline {
            return cond();
        }
        sys::sleep(200_000);
    }
}

/// Spins (without blocking) for `ns` nanoseconds.
pub fn busy_wait(ns: u64) {
    let end = sys::clock() + ns;
    while sys::clock() < end {
        core::hint::spin_loop();
    }
}

fn setup<T>(what: &str, r: Result<T, SpawnError>) -> T {
    must(what, r)
}

/// The root task's test bench; see the module documentation.
pub struct Lab {
    pub spawner: Spawner,
    /// The root's main thread and task.
    pub me: ThreadId,
    pub task: TaskId,
    /// The main thread's IPC buffer.
    pub ipc: IpcBufferRef,
    /// A page address kept free, for [`Lab::is_mapped`].
    probe: u64,
}

impl Lab {
    /// Sets up the frame pool and the main thread's IPC buffer.
    pub fn new() -> Self {
        let mut spawner = setup(
            "setup: spawner",
            Spawner::new(
                FramePool::from_root_info(),
                AddressRange::new(LAB_BASE, LAB_END),
            ),
        );
        let ipc = setup("setup: root IPC buffer", spawner.own_ipc_buffer());
        let probe = setup("setup: probe address", spawner.addresses(1));
        let (me, task) = sys::thread_self();
        Self {
            spawner,
            me,
            task,
            ipc,
            probe,
        }
    }

    /// A child task of the root running this binary, charged to resource partition `rp`
    /// (0 = the root's).
    pub fn task_in(&mut self, name: &str, abilities: Abilities, mcp: u8, rp: u64) -> TaskId {
        setup(
            "setup: child task",
            self.spawner.create_task(abilities, mcp, rp, name),
        )
    }

    pub fn task(&mut self, name: &str, abilities: Abilities, mcp: u8) -> TaskId {
        self.task_in(name, abilities, mcp, 0)
    }

    /// An inactive worker in `task` (`None` = the root task) running `entry` at
    /// `priority`, with `args` in its block.
    pub fn worker(
        &mut self,
        task: Option<TaskId>,
        entry: ThreadEntry,
        priority: u8,
        args: &[u64],
    ) -> Worker {
        let words = setup(
            "setup: worker block",
            self.spawner.shared_words(task, BLOCK_WORDS),
        );
        let block = Block(words);
        for (i, a) in args.iter().enumerate() {
            block.set_arg(i, *a);
        }
        let arg = words.as_ptr() as u64;
        let thread = setup(
            "setup: worker thread",
            self.spawner.thread(task, entry, priority, arg, STACK_PAGES),
        );
        block.0[W_IPC].store(thread.ipc_buffer, Ordering::Release);
        block.0[W_SELF].store(thread.id.0, Ordering::Release);
        Worker {
            id: thread.id,
            block,
        }
    }

    /// `pages` zeroed pages mapped writable at the same fresh address in the root and in
    /// `task` (`None`: the root only).
    pub fn shared(&mut self, task: Option<TaskId>, pages: u64) -> u64 {
        setup(
            "setup: shared memory",
            self.spawner.memory(task, pages, PageRights::WRITE, true),
        )
    }

    /// `pages` zeroed, physically contiguous frames (not mapped anywhere).
    pub fn frames(&mut self, pages: u64) -> u64 {
        setup("setup: frames", self.spawner.frames(pages))
    }

    /// A fresh, unmapped address range of `pages` pages (followed by a guard page).
    pub fn address(&mut self, pages: u64) -> u64 {
        setup("setup: address range", self.spawner.addresses(pages))
    }

    /// Whether the root has page `va` mapped, found out without touching it: `map` of an
    /// unmapped source page is `BadAddress`.
    pub fn is_mapped(&self, va: u64) -> bool {
        match sys::map(None, va, self.probe, 1, PageRights::empty()) {
            Ok(()) => {
                must("unmap of the probe page", sys::unmap(None, self.probe, 1));
                true
            }
            Err(Error::BadAddress) => false,
            Err(e) => fail(
                "probing a mapping",
                format_args!(": map of {va:#x} gave {e:?}"),
            ),
        }
    }
}

/// Reads a `u64` the root or a worker shares at `address` (volatile: another thread or
/// task may write it).
///
/// # Safety
/// `address` must be 8-aligned and mapped readable in the calling task.
pub unsafe fn peek(address: u64) -> u64 {
    // SAFETY: the caller guarantees the address is mapped readable and aligned.
    unsafe { core::ptr::read_volatile(address as *const u64) }
}

/// Writes a `u64` at `address` (volatile).
///
/// # Safety
/// `address` must be 8-aligned and mapped writable in the calling task, and not be memory
/// Rust code holds references to.
pub unsafe fn poke(address: u64, value: u64) {
    // SAFETY: the caller guarantees the address is mapped writable, aligned and unaliased.
    unsafe { core::ptr::write_volatile(address as *mut u64, value) }
}

worker!(
    /// Sleeps for good (a thread that exists but never does anything).
    fn park(block, ipc) {
        loop {
            let _ = sys::notify_wait(0, user_rt::abi::syscall::TIMEOUT_INFINITE);
        }
    }
);

/// Sleeps for good, without a block (for threads made with `Spawner::thread` directly).
pub extern "C" fn sleeper(_: u64) -> ! {
    loop {
        let _ = sys::notify_wait(0, user_rt::abi::syscall::TIMEOUT_INFINITE);
    }
}

/// The address of a thread entry, as `thread_create` takes it.
pub fn entry_address(entry: ThreadEntry) -> u64 {
    entry as *const () as usize as u64
}

/// A well-formed identifier (slot 0xfff0, generation 0x7654) that names no thread, task or
/// partition.
pub const BOGUS_ID: u64 = user_rt::abi::syscall::make_id(0xfff0, 0x7654);
