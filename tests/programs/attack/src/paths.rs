//! The longest kernel paths a caller can ask for, without pause, so that a victim in the
//! next window measures how late they make its start (the kernel is not preemptible while
//! it serves one call):
//!
//! * [`flood_io`] (partition `flood-io*`): grants the whole I/O port range it holds
//!   ([`IO_FLOOD_FIRST`]..=0xffff, its configuration must give it exactly that) to a child
//!   task, twice, and kills the child again (the first grant allocates and fills the
//!   child's bitmap, every grant checks and sets one bit a port, the kill frees it);
//! * [`flood_kill`] (partition `flood-kill*`): gives a child task as many threads and page
//!   tables as its quota allows, then kills it with one `task_kill`;
//! * [`kill_loop`] (partition `kill-loop*`): the same tree at every start, then a fault
//!   (restarted cold: syssw kills the whole tree at each restart);
//! * [`root_paths`] (the root task, system-image entry `test/mode` = `paths`): installs
//!   the largest schedule, grants every port it holds to a child and kills a child with
//!   hundreds of threads and page tables, the worst of each that any caller can make, while
//!   a victim thread of its own logs its window starts in the next window.

use crate::scratch;
use user_rt::abi::syscall::{
    Abilities, MAX_WINDOWS, PageRights, TaskId, ThreadAttribute, WindowSpec,
};
use user_rt::partition::POOL_BASE;
use user_rt::println;
use user_rt::sys;

/// The first port of the range `flood-io` is configured with (it holds up to 0xffff).
pub const IO_FLOOD_FIRST: u16 = 0x1000;

/// Where the page-table floods map their pages: one page in each 512 GiB slot from here on
/// (each needs a new page-directory-pointer table, directory and page table, the most
/// tables a page can cost and the most entries a teardown has to look at).
const SPARSE_BASE: u64 = 0x0000_0100_0000_0000;
const SPARSE_STRIDE: u64 = 512 << 30;
/// 512 GiB slots between `SPARSE_BASE` and the top of user space, minus the last one
/// (stacks and start-up mappings live there).
const SPARSE_SLOTS: u64 = 253;

/// `flood-io`: see the module documentation.
pub fn flood_io() -> ! {
    let count = 0x1_0000 - u32::from(IO_FLOOD_FIRST);
    let mut rounds: u64 = 0;
    loop {
        let child = match sys::task_create(Abilities::empty(), 1, 0, "io child") {
            Ok(task) => task,
            Err(e) => fail("flood-io", "task_create", e),
        };
        for _ in 0..2 {
            if let Err(e) = sys::io_grant(child, IO_FLOOD_FIRST, count) {
                fail("flood-io", "io_grant", e);
            }
        }
        if let Err(e) = sys::task_kill(child) {
            fail("flood-io", "task_kill", e);
        }
        rounds += 1;
        if rounds.is_multiple_of(100) {
            println!("flood-io: {rounds} rounds of {count} ports");
        }
    }
}

/// Fills child task `child` with threads (never started) and sparse page tables until its
/// resource partition's quota or `max_threads`/`max_slots` says no; returns (threads,
/// pages mapped).
fn fill(child: TaskId, source: u64, max_threads: u64, max_slots: u64) -> (u64, u64) {
    let mut threads = 0;
    while threads < max_threads && sys::thread_create(Some(child), 0x1000, 0x2000, 1, 0).is_ok() {
        threads += 1;
    }
    let mut pages = 0;
    while pages < max_slots {
        let at = SPARSE_BASE + pages * SPARSE_STRIDE;
        if sys::map(Some(child), source, at, 1, PageRights::empty()).is_err() {
            break;
        }
        pages += 1;
    }
    (threads, pages)
}

/// `flood-kill`: see the module documentation.
pub fn flood_kill() -> ! {
    let mut rounds: u64 = 0;
    loop {
        let child = match sys::task_create(Abilities::empty(), 1, 0, "kill child") {
            Ok(task) => task,
            Err(e) => fail("flood-kill", "task_create", e),
        };
        let (threads, pages) = fill(child, POOL_BASE, u64::MAX, SPARSE_SLOTS);
        if let Err(e) = sys::task_kill(child) {
            fail("flood-kill", "task_kill", e);
        }
        rounds += 1;
        if rounds == 1 || rounds.is_multiple_of(10) {
            println!(
                "flood-kill: {rounds} rounds, each killing a task with {threads} threads and {} page tables",
                pages * 3 + 1
            );
        }
    }
}

/// `kill-loop`: fills a child task as `flood-kill` does, then faults, at every start: its
/// health table restarts it cold, and whoever kills the old task kills the whole tree.
pub fn kill_loop() -> ! {
    let child = match sys::task_create(Abilities::empty(), 1, 0, "loop child") {
        Ok(task) => task,
        Err(e) => fail("kill-loop", "task_create", e),
    };
    let (threads, pages) = fill(child, POOL_BASE, u64::MAX, SPARSE_SLOTS);
    println!(
        "kill-loop: a child with {threads} threads and {} page tables, faulting",
        pages * 3 + 1
    );
    #[allow(unsafe_code)]
    // SAFETY: ud2 only raises #UD.
    unsafe {
        core::arch::asm!("ud2", options(noreturn))
    }
}

fn fail(who: &str, what: &str, e: user_rt::abi::syscall::Error) -> ! {
    println!("{who}: {what} failed: {e:?}");
    sys::sleep_until(u64::MAX);
    loop {
        sys::yield_now();
    }
}

/// A stack for a thread of the root task.
#[repr(C, align(16))]
struct Stack([u8; 64 * 1024]);

static mut VICTIM_STACK: Stack = Stack([0; 64 * 1024]);
static mut ATTACKER_STACK: Stack = Stack([0; 64 * 1024]);

/// The stack pointer a thread starts with on `stack` (as if called: 16-byte aligned + 8).
fn top(stack: *mut Stack) -> u64 {
    stack as u64 + core::mem::size_of::<Stack>() as u64 - 8
}

const MS: u64 = 1_000_000;
/// The root task's schedule: the victim's window (time partition 1) first, then the
/// attacker's (2), which ends where the victim's next one begins.
const ROOT_FRAME: u64 = 5 * MS;
/// Windows the root task's victim logs before it ends the run.
pub const ROOT_VICTIM_WINDOWS: u64 = 200;

/// The root task's long paths: see the module documentation.
pub fn root_paths() {
    let windows = [
        WindowSpec {
            offset: 0,
            duration: MS,
            partition: 1,
            cpu: 0,
        },
        WindowSpec {
            offset: MS,
            duration: ROOT_FRAME - MS,
            partition: 2,
            cpu: 0,
        },
    ];
    if let Err(e) = sys::schedule_set(0, ROOT_FRAME, &windows).and(sys::schedule_switch(0)) {
        println!("paths: cannot install the schedule: {e:?}");
        let _ = sys::system_halt(false);
    }
    for (entry, stack, partition) in [
        (
            root_victim as extern "C" fn(u64) -> !,
            &raw mut VICTIM_STACK,
            1u64,
        ),
        (root_attacker, &raw mut ATTACKER_STACK, 2),
    ] {
        let started = sys::thread_create(None, entry as *const () as u64, top(stack), 150, 0)
            .and_then(|t| {
                sys::thread_set(Some(t), ThreadAttribute::TimePartition, partition)?;
                sys::thread_start(t)
            });
        if let Err(e) = started {
            println!("paths: cannot start a thread: {e:?}");
            let _ = sys::system_halt(false);
        }
    }
    sys::sleep_until(u64::MAX);
}

extern "C" fn root_victim(_: u64) -> ! {
    crate::victim(1, ROOT_VICTIM_WINDOWS);
    let _ = sys::system_halt(true);
    sys::thread_exit()
}

/// The root task's attacker: one of each longest call per round, for ever.
extern "C" fn root_attacker(_: u64) -> ! {
    // The largest schedule: every window the kernel takes, installed into an idle slot.
    let mut windows = [WindowSpec {
        offset: 0,
        duration: 0,
        partition: 0,
        cpu: 0,
    }; MAX_WINDOWS as usize];
    let step = ROOT_FRAME / MAX_WINDOWS;
    for (i, w) in windows.iter_mut().enumerate() {
        *w = WindowSpec {
            offset: i as u64 * step,
            duration: step,
            partition: 1 + i as u64 % 15,
            cpu: 0,
        };
    }
    // Every port above the kernel's last range (`KERNEL_PORTS`: the PCI configuration
    // ports 0xcf8..=0xcff).
    const FIRST: u16 = 0xd00;
    let count = 0x1_0000 - u32::from(FIRST);
    let mut rounds: u64 = 0;
    loop {
        if let Err(e) = sys::schedule_set(1, ROOT_FRAME, &windows) {
            fail("paths", "schedule_set", e);
        }
        let child = match sys::task_create(Abilities::empty(), 1, 0, "paths child") {
            Ok(task) => task,
            Err(e) => fail("paths", "task_create", e),
        };
        if let Err(e) = sys::io_grant(child, FIRST, count) {
            fail("paths", "io_grant", e);
        }
        let (threads, pages) = fill(child, scratch().start, 200, SPARSE_SLOTS);
        if let Err(e) = sys::task_kill(child) {
            fail("paths", "task_kill", e);
        }
        rounds += 1;
        if rounds == 1 || rounds.is_multiple_of(20) {
            println!(
                "paths: {rounds} rounds: schedule of {MAX_WINDOWS} windows, {count} ports granted, a task with {threads} threads and {} page tables killed",
                pages * 3 + 1
            );
        }
    }
}
