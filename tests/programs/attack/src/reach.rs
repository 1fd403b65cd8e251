//! Attempts to reach what belongs to others (scenario `attack_reach`):
//!
//! * [`peek`] (partition `peek*`): at each start touches the next of [`PEEKS`] — the
//!   kernel's image, the kernel's direct map of all physical memory (where every other
//!   partition's memory lies), a user address its task has no mapping at, its own code —
//!   each of which must fault (the scenario restarts it warm, so a counter in its memory
//!   survives); after the last it tries to map a page into every task id and to map
//!   physical memory, which must all be refused, prints `peek: all <n> accesses faulted;
//!   <m> maps into other tasks refused, <k> accepted` and sleeps;
//! * [`ipc_flood`] (partition `ipc-flood*`): sends messages and notifications to every
//!   thread id but its own and syssw's server, and calls syssw with labels no request has,
//!   as fast as it can, printing `ipc-flood: <n> to other threads, <a> accepted; <s> to
//!   syssw; taken by <ids>` every [`IPC_REPORT_EVERY`] rounds (the threads that took a
//!   message or notification: only syssw's, its parent's, may);
//! * [`spin`] (partitions `spin*`, windowed or in the background): raises its thread to
//!   its partition's maximum priority and spins.

use core::sync::atomic::{AtomicUsize, Ordering};
use user_rt::abi::boot::KERNEL_BASE;
use user_rt::abi::ipc::MessageTag;
use user_rt::abi::syscall::{PageRights, TaskId, ThreadAttribute, ThreadId, make_id};
use user_rt::partition::{POOL_BASE, StartInfo};
use user_rt::println;
use user_rt::protocol::OperatingMode;
use user_rt::sys::{self, Message};

/// A read or a write of one byte at an address the partition must not reach.
#[derive(Clone, Copy)]
enum Peek {
    Read(u64),
    Write(u64),
}

/// The direct map of physical memory (kernel only); 16 MiB in, where other partitions'
/// memory and the kernel's frames lie.
const DIRECT_MAP: u64 = 0xffff_8000_0000_0000 + (16 << 20);
/// A user address no partition is given (the root task's system image lies here).
const UNMAPPED: u64 = 0x0000_7000_0000_0000;

/// What [`peek`] touches, one per start.
const PEEKS: [Peek; 7] = [
    Peek::Read(KERNEL_BASE),
    Peek::Write(KERNEL_BASE),
    Peek::Read(DIRECT_MAP),
    Peek::Write(DIRECT_MAP),
    Peek::Read(UNMAPPED),
    Peek::Write(UNMAPPED),
    // Its own code, which is mapped read-execute only.
    Peek::Write(0),
];

/// How many of [`PEEKS`] were touched (kept across warm restarts).
static PEEKED: AtomicUsize = AtomicUsize::new(0);

/// `peek`: see the module documentation.
pub fn peek(info: &StartInfo) -> ! {
    // NORMAL mode first: only an initialised partition can be restarted warm (ARINC 653).
    let _ = crate::request(
        ThreadId(info.server),
        user_rt::protocol::Request::SetPartitionMode {
            mode: OperatingMode::Normal,
        },
    );
    let next = PEEKED.fetch_add(1, Ordering::Relaxed);
    if let Some(&target) = PEEKS.get(next) {
        let own_code = peek as *const () as u64;
        match target {
            Peek::Read(at) => {
                println!("peek: reading {at:#x}");
                #[allow(unsafe_code)]
                // SAFETY: deliberately invalid: the address is outside what this task may
                // read, so the access faults and never happens.
                let value = unsafe { core::ptr::read_volatile(at as *const u8) };
                println!("peek: read {value:#x} at {at:#x}: did not fault");
            }
            Peek::Write(at) => {
                let at = if at == 0 { own_code } else { at };
                println!("peek: writing {at:#x}");
                #[allow(unsafe_code)]
                // SAFETY: deliberately invalid: the address is outside what this task may
                // write (or read-only), so the access faults and never happens.
                unsafe {
                    core::ptr::write_volatile(at as *mut u8, 0x5a)
                };
                println!("peek: wrote at {at:#x}: did not fault");
            }
        }
    }
    // Every access faulted: mapping into other tasks and physical memory must be refused.
    let (mut refused, mut accepted) = (0u64, 0u64);
    let (_, own) = sys::thread_self();
    for slot in 0..64 {
        for generation in 0..4 {
            let task = make_id(slot, generation);
            if task == own.0 {
                continue;
            }
            match sys::map(
                Some(TaskId(task)),
                POOL_BASE,
                0x4000_0000,
                1,
                PageRights::WRITE,
            ) {
                Ok(()) => accepted += 1,
                Err(_) => refused += 1,
            }
        }
    }
    for physical in [0, 0x10_0000, 16 << 20] {
        match sys::map_physical(None, physical, 0x5000_0000, 1, PageRights::WRITE) {
            Ok(()) => accepted += 1,
            Err(_) => refused += 1,
        }
    }
    println!(
        "peek: all {} accesses faulted; {refused} maps into other tasks refused, {accepted} accepted",
        PEEKS.len()
    );
    sys::sleep_until(u64::MAX);
    loop {
        sys::yield_now();
    }
}

/// Rounds (one message to each thread id) between two reports of [`ipc_flood`].
pub const IPC_REPORT_EVERY: u64 = 20;

/// `ipc-flood`: see the module documentation.
pub fn ipc_flood(info: &StartInfo) -> ! {
    let (own, _) = sys::thread_self();
    let server = ThreadId(info.server);
    let (mut sent, mut accepted, mut to_syssw) = (0u64, 0u64, 0u64);
    let mut rounds = 0u64;
    // Threads that took something (the kernel lets a partition reach its own task and
    // syssw's, nothing else).
    let mut takers = [0u64; 4];
    loop {
        for slot in 0..256 {
            for generation in 0..2 {
                let thread = ThreadId(make_id(slot, generation));
                if thread == own || thread == server {
                    continue;
                }
                let m = Message {
                    tag: MessageTag::new(0x0ff1, 0, 0),
                    words: [slot as u64, generation as u64, 0xdead],
                };
                for ok in [
                    sys::send(thread, 0, &m).is_ok(),
                    sys::notify_signal(thread, u64::MAX).is_ok(),
                ] {
                    sent += 1;
                    if ok {
                        accepted += 1;
                        if !takers.contains(&thread.0) {
                            takers[accepted as usize % takers.len()] = thread.0;
                        }
                    }
                }
            }
            // A call syssw must refuse: a label no request has, random words.
            let m = Message {
                tag: MessageTag::new(0x7000 + slot as u32, 0, 0),
                words: [u64::MAX, slot as u64, 0],
            };
            let _ = sys::ipc_call(server, 1_000_000, &m);
            to_syssw += 1;
        }
        rounds += 1;
        if rounds.is_multiple_of(IPC_REPORT_EVERY) {
            let [a, b, c, d] = takers;
            println!(
                "ipc-flood: {sent} to other threads, {accepted} accepted; {to_syssw} to syssw; taken by {a:#x} {b:#x} {c:#x} {d:#x}"
            );
        }
    }
}

/// `spin`: see the module documentation.
pub fn spin(info: &StartInfo) -> ! {
    let raised = sys::thread_set(None, ThreadAttribute::Priority, info.mcp);
    println!(
        "spin: spinning at priority {} (its maximum){}",
        info.mcp,
        if raised.is_ok() { "" } else { ", not raised" }
    );
    loop {
        core::hint::spin_loop();
    }
}
