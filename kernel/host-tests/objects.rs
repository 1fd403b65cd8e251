//! Host tests of the kernel's object logic, driven through the system-call dispatcher
//! exactly as user threads would drive it (registers in, registers out). Page tables and
//! "user memory" live in the host-test arena (`mem::test_arena`).

use crate::mem::{PAGE_SIZE, test_arena};
use crate::rp::{Amount, ResourcePartition};
use crate::state::{Kernel, Source};
use crate::syscall::{Outcome, on_syscall};
use crate::table::{RpIdx, Slot, TaskIdx, ThreadIdx};
use crate::task::Task;
use crate::thread::{Fault, State};
use abi::ipc::*;
use abi::root::PhysRegion;
use abi::syscall::{
    Abilities, Call, Error, PageRights, TIMEOUT_INFINITE, TaskId, ThreadAttribute, ThreadId,
};

struct Fixture {
    k: Box<Kernel>,
    next_user_frame: u64,
    _arena: std::sync::MutexGuard<'static, ()>,
}

const BUFFER_AT: u64 = 0x10_0000;
const ROOT: TaskIdx = TaskIdx::ROOT;

impl Fixture {
    fn new() -> Self {
        let arena = test_arena::init();
        let mut k = Box::new(Kernel::new());
        k.rps[RpIdx::ROOT] = ResourcePartition::new(
            ROOT,
            Amount {
                tasks: 64,
                threads: 256,
                pages: 1000,
            },
        );
        k.rps[RpIdx::ROOT].charge(Amount::tasks(1)).unwrap();
        let space = crate::mem::paging::AddressSpace::new().unwrap();
        k.tasks[ROOT] = Task::root(space, "root");
        k.user_memory[0] = PhysRegion {
            start: test_arena::USER_BASE,
            pages: test_arena::FRAMES / 2,
        };
        k.user_memory_count = 1;
        Self {
            k,
            next_user_frame: test_arena::USER_BASE,
            _arena: arena,
        }
    }

    /// A started thread of `task` with an IPC buffer (2 pages at BUFFER_AT + 16 KiB * n).
    fn thread(&mut self, task: TaskIdx, priority: u8) -> ThreadIdx {
        let t = self
            .k
            .create_thread(task, 0x1000, 0x2000, priority, 0, 0)
            .unwrap();
        self.k.set_state(t, State::Ready);
        let at = BUFFER_AT + t.position() as u64 * 0x4000;
        if self.k.tasks[task].space().translate(at).is_none() {
            self.give(task, at, 2, PageRights::WRITE);
        }
        self.k.threads[t].set_ipc_buffer(at);
        t
    }

    /// Maps `pages` fresh user frames into `task` at `at`.
    fn give(&mut self, task: TaskIdx, at: u64, pages: u64, rights: PageRights) {
        let frame = self.next_user_frame;
        self.next_user_frame += pages * PAGE_SIZE;
        self.k
            .map(ROOT, task, Source::Physical(frame), at, pages, rights)
            .unwrap();
    }

    fn task(&mut self, parent: TaskIdx, abilities: Abilities, mcp: u8) -> TaskIdx {
        self.k
            .create_task(parent, abilities, mcp, self.k.tasks[parent].rp(), "t")
            .unwrap()
    }

    /// Thread `t` makes system call `call`; returns `rax` (meaningful unless it blocked).
    /// A call that restarts itself (its `syscall` again: `rip` 2 bytes back) is made
    /// again, as the thread would.
    fn sys(&mut self, t: ThreadIdx, call: Call, a: [u64; 6]) -> u64 {
        let c = self.k.threads[t].context_mut();
        c.rax = call as u64;
        [c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9] = a;
        loop {
            let rip = self.k.threads[t].context().rip;
            let outcome = on_syscall(&mut self.k, t, || 0);
            assert!(matches!(outcome, Outcome::Continue | Outcome::SwitchTo(_)));
            if self.k.threads[t].is_free() || self.k.threads[t].context().rip != rip.wrapping_sub(2)
            {
                return self.k.threads[t].context().rax;
            }
            self.k.threads[t].context_mut().rip = rip;
        }
    }

    fn id(&self, t: ThreadIdx) -> u64 {
        self.k.thread_id(t).0
    }

    fn write(&self, t: ThreadIdx, at: u64, data: &[u8]) {
        let task = self.k.threads[t].task();
        assert!(self.k.tasks[task].space().copy_to_user(at, data));
    }

    fn read(&self, t: ThreadIdx, at: u64, len: usize) -> Vec<u8> {
        let task = self.k.threads[t].task();
        let mut out = vec![0; len];
        assert!(self.k.tasks[task].space().copy_from_user(at, &mut out));
        out
    }
}

/// The arena's frame allocator lives for the whole test run: a test gives its page tables
/// and bitmaps back, so that hundreds of generated cases fit.
impl Drop for Fixture {
    fn drop(&mut self) {
        for slot in TaskIdx::all() {
            if self.k.tasks[slot].in_use() {
                self.k.release_io_bitmap(slot);
                self.k.tasks[slot].destroy_space();
            }
        }
    }
}

const OK: u64 = Error::Ok as u64;

fn err(e: Error) -> u64 {
    e as u64
}

#[test]
fn abilities_and_mcp_bound_children() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let weak = f.task(ROOT, Abilities::DEBUG_LOG | Abilities::NATIVE_SYSCALLS, 100);
    let w = f.thread(weak, 50);
    // More abilities than the parent has.
    let bits = (Abilities::DEBUG_LOG | Abilities::MAP).bits();
    assert_eq!(
        f.sys(w, Call::TaskCreate, [bits, 10, 0, 0, 0, 0]),
        err(Error::AbilityDenied)
    );
    // The weak task lacks CREATE_THREAD and CREATE_TASK.
    assert_eq!(
        f.sys(w, Call::ThreadCreate, [0, 0x1000, 0x2000, 10, 0, 0]),
        err(Error::AbilityDenied)
    );
    // MCP: task above the parent's, thread above the task's, priority change above it.
    let all = Abilities::all().bits();
    let at = root_name(&mut f, root);
    assert_eq!(
        f.sys(root, Call::TaskCreate, [all, 256, 0, at, 1, 0]),
        err(Error::McpExceeded)
    );
    let wid = f.k.task_id(weak).0;
    assert_eq!(
        f.sys(root, Call::ThreadCreate, [wid, 0x1000, 0x2000, 101, 0, 0]),
        err(Error::McpExceeded)
    );
    assert_eq!(
        f.sys(root, Call::ThreadCreate, [wid, 0x1000, 0x2000, 100, 0, 0]),
        OK
    );
    let wt = f.id(w);
    let prio = ThreadAttribute::Priority as u64;
    assert_eq!(
        f.sys(root, Call::ThreadSet, [wt, prio, 101, 0, 0, 0]),
        err(Error::McpExceeded)
    );
    assert_eq!(f.sys(root, Call::ThreadSet, [wt, prio, 99, 0, 0, 0]), OK);
    assert_eq!(f.k.threads[w].priority(), 99);
    // Children cannot control their parent.
    let rt = f.id(root);
    assert_eq!(
        f.sys(w, Call::ThreadSuspend, [rt, 0, 0, 0, 0, 0]),
        err(Error::NotPermitted)
    );
}

/// Writes a one-byte task name into the root's buffer; returns its address.
fn root_name(f: &mut Fixture, root: ThreadIdx) -> u64 {
    let at = f.k.threads[root].ipc_buffer();
    f.write(root, at, b"c");
    at
}

#[test]
fn thread_lifecycle_and_stale_ids() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    assert_eq!(
        f.sys(root, Call::ThreadCreate, [0, 0x1000, 0x2000, 10, 7, 0]),
        OK
    );
    let id = f.k.threads[root].context().rdi;
    let t = f.k.thread(ThreadId(id)).unwrap();
    assert_eq!(f.k.threads[t].state(), State::Inactive);
    assert_eq!(f.k.threads[t].context().rdi, 7, "argument in rdi");
    assert_eq!(f.sys(root, Call::ThreadStart, [id, 0, 0, 0, 0, 0]), OK);
    assert_eq!(
        f.sys(root, Call::ThreadStart, [id, 0, 0, 0, 0, 0]),
        err(Error::InvalidArgument)
    );
    assert!(f.k.run.is_queued(t.position()));
    assert_eq!(f.sys(root, Call::ThreadSuspend, [id, 0, 0, 0, 0, 0]), OK);
    assert!(!f.k.run.is_queued(t.position()));
    assert_eq!(f.sys(root, Call::ThreadResume, [id, 0, 0, 0, 0, 0]), OK);
    assert!(f.k.run.is_queued(t.position()));
    let used = f.k.rps[RpIdx::ROOT].used.threads;
    assert_eq!(f.sys(root, Call::ThreadKill, [id, 0, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.rps[RpIdx::ROOT].used.threads, used - 1);
    assert_eq!(
        f.sys(root, Call::ThreadStart, [id, 0, 0, 0, 0, 0]),
        err(Error::NoSuchObject)
    );
    assert_eq!(
        f.sys(root, Call::ThreadKill, [0xdead_0000, 0, 0, 0, 0, 0]),
        err(Error::NoSuchObject)
    );
}

#[test]
fn a_partitions_threads_move_only_to_its_online_cpus() {
    let mut f = Fixture::new();
    f.k.online = 3;
    let root = f.thread(ROOT, 200);
    assert_eq!(f.sys(root, Call::RpCreate, [2, 4, 16, 0b110, 0, 0]), OK);
    let rp = f.k.threads[root].context().rdi;
    assert_eq!(f.sys(root, Call::RpInfo, [rp, 0, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.threads[root].context().r10, 0b110);
    let rp = f.k.resource_partition(ROOT, rp).unwrap();
    let task =
        f.k.create_task(ROOT, Abilities::NATIVE_SYSCALLS, 100, rp, "p")
            .unwrap();
    let t = f.thread(task, 50);
    let cpu = |n| [0, ThreadAttribute::Cpu as u64, n, 0, 0, 0];
    assert_eq!(f.sys(t, Call::ThreadSet, cpu(2)), OK, "its own CPU 2");
    assert_eq!(f.k.threads[t].cpu(), 2);
    assert_eq!(
        f.sys(t, Call::ThreadSet, cpu(0)),
        err(Error::NotPermitted),
        "not its CPU"
    );
    assert_eq!(
        f.sys(t, Call::ThreadSet, cpu(3)),
        err(Error::InvalidArgument),
        "offline"
    );
    assert_eq!(
        f.k.threads[t].cpu(),
        2,
        "a refused move leaves it where it was"
    );
    assert_eq!(
        f.sys(
            root,
            Call::ThreadSet,
            [f.id(t), ThreadAttribute::Cpu as u64, 0, 0, 0, 0]
        ),
        err(Error::NotPermitted),
        "not even its creator moves it off its partition's CPUs"
    );
    assert_eq!(
        f.sys(root, Call::RpCreate, [1, 1, 1, 0, 0, 0]),
        err(Error::InvalidArgument)
    );
}

#[test]
fn exhausting_one_partition_leaves_the_other_working() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let quota = |threads, pages| [2, threads, pages, 0xff, 0, 0];
    assert_eq!(f.sys(root, Call::RpCreate, quota(2, 8)), OK);
    let a = f.k.threads[root].context().rdi;
    assert_eq!(f.sys(root, Call::RpCreate, quota(2, 8)), OK);
    let b = f.k.threads[root].context().rdi;
    assert_eq!(
        f.sys(root, Call::RpCreate, quota(1000, 8)),
        err(Error::QuotaExceeded)
    );
    let at = root_name(&mut f, root);
    let all = Abilities::all().bits();
    assert_eq!(f.sys(root, Call::TaskCreate, [all, 100, a, at, 1, 0]), OK);
    let ta = f.k.threads[root].context().rdi;
    assert_eq!(f.sys(root, Call::TaskCreate, [all, 100, b, at, 1, 0]), OK);
    let tb = f.k.threads[root].context().rdi;
    let create = |task| [task, 0x1000, 0x2000, 10, 0, 0];
    assert_eq!(f.sys(root, Call::ThreadCreate, create(ta)), OK);
    assert_eq!(f.sys(root, Call::ThreadCreate, create(ta)), OK);
    assert_eq!(
        f.sys(root, Call::ThreadCreate, create(ta)),
        err(Error::QuotaExceeded)
    );
    // Page tables: the first page of a fresh space needs 3 tables; 8 - 1 (PML4) = 7 left.
    let (ita, itb) = (f.k.task(TaskId(ta)).unwrap(), f.k.task(TaskId(tb)).unwrap());
    let phys = test_arena::USER_BASE;
    let map = |task, at| [task, phys, at, 1, 0, 0];
    assert_eq!(f.sys(root, Call::MapPhysical, map(ta, 0x1000)), OK);
    assert_eq!(
        f.sys(root, Call::MapPhysical, map(ta, 0x4000_0000)),
        OK,
        "2 more tables"
    );
    assert_eq!(
        f.sys(root, Call::MapPhysical, map(ta, 0x80_0000_0000)),
        err(Error::QuotaExceeded)
    );
    assert_eq!(
        f.k.tasks[ita].space().translate(0x80_0000_0000),
        None,
        "nothing changed"
    );
    // B is untouched by A's exhaustion.
    assert_eq!(f.sys(root, Call::ThreadCreate, create(tb)), OK);
    assert_eq!(f.sys(root, Call::MapPhysical, map(tb, 0x1000)), OK);
    assert!(f.k.tasks[itb].space().translate(0x1000).is_some());
    // Killing A returns everything.
    assert_eq!(f.sys(root, Call::TaskKill, [ta, 0, 0, 0, 0, 0]), OK);
    let rp_a = f.k.rps.slot(a as usize - 1).unwrap();
    assert_eq!(f.k.rps[rp_a].used, Amount::default());
}

#[test]
fn map_protect_unmap_rules() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let child = f.task(ROOT, Abilities::all(), 100);
    let cid = f.k.task_id(child).0;
    let ro = PageRights::empty().bits();
    let rw = PageRights::WRITE.bits();
    f.give(ROOT, 0x50_0000, 2, PageRights::empty());
    // More rights than the source has.
    assert_eq!(
        f.sys(root, Call::Map, [cid, 0x50_0000, 0x60_0000, 2, rw, 0]),
        err(Error::BadAddress)
    );
    assert_eq!(
        f.sys(root, Call::Map, [cid, 0x50_0000, 0x60_0001, 2, ro, 0]),
        err(Error::InvalidArgument)
    );
    assert_eq!(
        f.sys(root, Call::Map, [cid, 0x50_0000, 0x60_0000, 0, ro, 0]),
        err(Error::InvalidArgument)
    );
    assert_eq!(
        f.sys(
            root,
            Call::Map,
            [cid, 0x50_0000, 0xffff_8000_0000_0000, 1, ro, 0]
        ),
        err(Error::InvalidArgument)
    );
    assert_eq!(
        f.sys(root, Call::Map, [cid, 0x50_0000, 0x60_0000, 3, ro, 0]),
        err(Error::BadAddress),
        "third page unmapped"
    );
    assert_eq!(
        f.sys(root, Call::Map, [cid, 0x50_0000, 0x60_0000, 2, ro, 0]),
        OK
    );
    assert_eq!(
        f.sys(root, Call::Map, [cid, 0x50_0000, 0x60_1000, 1, ro, 0]),
        err(Error::AlreadyMapped)
    );
    // Physical memory outside what the root was given (the kernel pool) is refused.
    assert_eq!(
        f.sys(root, Call::MapPhysical, [cid, 0x1000, 0x70_0000, 1, rw, 0]),
        err(Error::BadAddress)
    );
    // Protect only removes rights.
    f.give(ROOT, 0x51_0000, 1, PageRights::WRITE);
    assert_eq!(
        f.sys(
            root,
            Call::Protect,
            [
                0,
                0x51_0000,
                1,
                (PageRights::WRITE | PageRights::EXECUTE).bits(),
                0,
                0
            ]
        ),
        err(Error::BadAddress)
    );
    assert_eq!(f.sys(root, Call::Protect, [0, 0x51_0000, 1, ro, 0, 0]), OK);
    assert_eq!(
        f.k.tasks[ROOT].space().translate(0x51_0000).unwrap().1,
        PageRights::empty()
    );
    assert_eq!(f.sys(root, Call::Unmap, [cid, 0x60_0000, 2, 0, 0, 0]), OK);
    assert_eq!(f.k.tasks[child].space().translate(0x60_0000), None);
    // No MAP ability, no map.
    let weak = f.task(ROOT, Abilities::NATIVE_SYSCALLS, 10);
    let w = f.thread(weak, 5);
    assert_eq!(
        f.sys(w, Call::Unmap, [0, 0x60_0000, 1, 0, 0, 0]),
        err(Error::AbilityDenied)
    );
}

#[test]
fn call_reply_with_data_and_words() {
    let mut f = Fixture::new();
    let client = f.thread(ROOT, 100);
    let server_task = f.task(ROOT, Abilities::all(), 200);
    let server = f.thread(server_task, 150);
    // The server waits first.
    f.sys(server, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    assert_eq!(f.k.threads[server].state(), State::Receiving { from: None });
    let (cbuf, sbuf) = (
        f.k.threads[client].ipc_buffer(),
        f.k.threads[server].ipc_buffer(),
    );
    f.write(client, cbuf, b"hello server");
    let tag = MessageTag::new(7, 12, 0).0;
    let sid = f.id(server);
    f.sys(client, Call::Call, [sid, TIMEOUT_INFINITE, tag, 1, 2, 3]);
    assert_eq!(
        f.k.threads[client].state(),
        State::WaitingReply { from: server }
    );
    let c = f.k.threads[server].context();
    assert_eq!(
        (c.rax, c.rdi, c.rdx, c.r10, c.r8, c.r9),
        (OK, f.id(client), tag, 1, 2, 3)
    );
    let client_task = f.k.task_id(f.k.threads[client].task()).0;
    assert_eq!(
        c.rsi, client_task,
        "the sender's task, for the server to trust"
    );
    assert_eq!(f.read(server, sbuf, 12), b"hello server");
    // Reply and wait for the next request.
    f.write(server, sbuf, b"ok");
    let cid = f.id(client);
    f.sys(
        server,
        Call::ReplyWait,
        [cid, TIMEOUT_INFINITE, MessageTag::new(9, 2, 0).0, 4, 5, 6],
    );
    assert_eq!(f.k.threads[server].state(), State::Receiving { from: None });
    let c = f.k.threads[client].context();
    assert_eq!(
        (c.rax, c.rdx, c.r10, c.r8, c.r9),
        (OK, MessageTag::new(9, 2, 0).0, 4, 5, 6)
    );
    assert_eq!(f.read(client, cbuf, 2), b"ok");
    assert_eq!(f.k.threads[client].state(), State::Ready);
    // A reply to a thread not waiting for one.
    assert_eq!(
        f.sys(client, Call::Reply, [sid, 0, 0, 0, 0, 0]),
        err(Error::NotWaiting)
    );
}

#[test]
fn register_only_round_trips_take_the_fast_path() {
    let mut f = Fixture::new();
    let client = f.thread(ROOT, 100);
    let server_task = f.task(ROOT, Abilities::all(), 200);
    let (server, low_server) = (f.thread(server_task, 150), f.thread(server_task, 50));
    for s in [server, low_server] {
        f.sys(s, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    }
    let (cid, sid, low_sid) = (f.id(client), f.id(server), f.id(low_server));
    let call = |f: &mut Fixture, to: u64| {
        let c = f.k.threads[client].context_mut();
        (c.rax, c.rdi, c.rsi, c.rdx) = (Call::Call as u64, to, TIMEOUT_INFINITE, 7);
        (c.r10, c.r8, c.r9) = (1, 2, 3);
        on_syscall(&mut f.k, client, || 0)
    };
    // A server above the caller runs next, directly, with the general path's results.
    assert_eq!(call(&mut f, sid), Outcome::SwitchTo(server));
    assert_eq!(
        f.k.threads[client].state(),
        State::WaitingReply { from: server }
    );
    let c = f.k.threads[server].context();
    let client_task = f.k.task_id(f.k.threads[client].task()).0;
    assert_eq!(
        (c.rax, c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9),
        (OK, cid, client_task, 7, 1, 2, 3)
    );
    f.sys(server, Call::ReplyWait, [cid, TIMEOUT_INFINITE, 9, 4, 5, 6]);
    assert_eq!(f.k.threads[server].state(), State::Receiving { from: None });
    let c = f.k.threads[client].context();
    assert_eq!(
        (c.rax, c.rdi, c.rdx, c.r10, c.r8, c.r9),
        (OK, sid, 9, 4, 5, 6)
    );
    assert_eq!(f.k.threads[client].state(), State::Ready);
    // One below it: the scheduler decides.
    assert_eq!(call(&mut f, low_sid), Outcome::Continue);
    assert_eq!(f.k.threads[low_server].context().r8, 2);
    // A kernel label, a finite time-out: the general path, with its answers.
    f.sys(
        low_server,
        Call::ReplyWait,
        [cid, TIMEOUT_INFINITE, 0, 0, 0, 0],
    );
    let kernel_label = MessageTag::new(abi::ipc::KERNEL_LABELS, 0, 0).0;
    assert_eq!(
        f.sys(
            client,
            Call::Call,
            [sid, TIMEOUT_INFINITE, kernel_label, 0, 0, 0]
        ),
        err(Error::InvalidArgument)
    );
    f.sys(client, Call::Call, [sid, 1_000, 0, 0, 0, 0]);
    assert_eq!(f.k.threads[client].deadline(), 1_000);
}

#[test]
fn senders_queue_by_priority_then_fifo() {
    let mut f = Fixture::new();
    let receiver = f.thread(ROOT, 10);
    let rid = f.id(receiver);
    let senders: Vec<ThreadIdx> = [30, 50, 30, 40]
        .iter()
        .map(|&p| f.thread(ROOT, p))
        .collect();
    for (i, &s) in senders.iter().enumerate() {
        f.sys(s, Call::Send, [rid, TIMEOUT_INFINITE, 0, i as u64, 0, 0]);
        assert!(matches!(f.k.threads[s].state(), State::Sending { .. }));
    }
    let mut order = vec![];
    for _ in 0..4 {
        assert_eq!(f.sys(receiver, Call::Receive, [0, 0, 0, 0, 0, 0]), OK);
        order.push(f.k.threads[receiver].context().r10);
    }
    assert_eq!(
        order,
        vec![1, 3, 0, 2],
        "50, 40, then the two 30s in arrival order"
    );
    assert_eq!(
        f.sys(receiver, Call::Receive, [0, 0, 0, 0, 0, 0]),
        err(Error::TimedOut),
        "poll"
    );
    for s in senders {
        assert_eq!(f.k.threads[s].context().rax, OK);
    }
}

#[test]
fn each_cpus_timer_serves_its_own_threads_time_outs() {
    use crate::thread::NEVER;
    let mut f = Fixture::new();
    f.k.online = 2;
    let (a, b) = (f.thread(ROOT, 10), f.thread(ROOT, 10));
    f.k.set_cpu(b, 1).unwrap();
    f.sys(a, Call::NotifyWait, [1, 700, 0, 0, 0, 0]);
    f.sys(b, Call::NotifyWait, [1, 300, 0, 0, 0, 0]);
    let deadlines = |f: &Fixture| (f.k.cores[0].next_deadline, f.k.cores[1].next_deadline);
    assert_eq!(
        deadlines(&f),
        (700, 300),
        "CPU 0 is not woken for CPU 1's time-out"
    );
    assert_eq!(
        f.k.next_event(0),
        700,
        "CPU 0's timer: its own time-out (no windows)"
    );
    // A thread that moved while it waited times out at its deadline all the same.
    f.k.set_cpu(a, 1).unwrap();
    f.k.expire_timeouts(300);
    assert_eq!(f.k.threads[b].state(), State::Ready);
    assert_eq!(
        deadlines(&f),
        (NEVER, 700),
        "each CPU's deadlines recomputed"
    );
    f.k.expire_timeouts(700);
    assert_eq!(f.k.threads[a].context().rax, err(Error::TimedOut));
    assert_eq!(deadlines(&f), (NEVER, NEVER));
}

#[test]
fn timeouts_expire_at_their_deadline() {
    let mut f = Fixture::new();
    let a = f.thread(ROOT, 10);
    let b = f.thread(ROOT, 10);
    f.sys(a, Call::Receive, [0, 1000, 0, 0, 0, 0]);
    let bid = f.id(b);
    f.sys(b, Call::NotifyWait, [1, 500, 0, 0, 0, 0]);
    assert_eq!(f.k.cores[0].next_deadline, 500);
    f.k.expire_timeouts(499);
    assert_eq!(f.k.threads[a].state(), State::Receiving { from: None });
    f.k.expire_timeouts(500);
    assert_eq!(f.k.threads[b].state(), State::Ready);
    assert_eq!(f.k.threads[b].context().rax, err(Error::TimedOut));
    assert_eq!(f.k.cores[0].next_deadline, 1000);
    f.k.expire_timeouts(1000);
    assert_eq!(f.k.threads[a].context().rax, err(Error::TimedOut));
    // A queued sender times out and leaves the queue.
    let aid = f.id(a);
    f.sys(b, Call::Send, [aid, 10, 0, 0, 0, 0]);
    f.k.expire_timeouts(10);
    assert_eq!(f.k.threads[b].context().rax, err(Error::TimedOut));
    assert_eq!(f.k.first_sender(a, None), None);
    let _ = bid;
}

#[test]
fn communication_rights_restrict_senders() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let x = f.task(ROOT, Abilities::all(), 100);
    let y = f.task(ROOT, Abilities::all(), 100);
    let tx = f.thread(x, 50);
    let ty = f.thread(y, 50);
    let yid = f.id(ty);
    assert_eq!(
        f.sys(tx, Call::Send, [yid, 0, 0, 0, 0, 0]),
        err(Error::NotPermitted)
    );
    assert_eq!(
        f.sys(tx, Call::NotifySignal, [yid, 1, 0, 0, 0, 0]),
        err(Error::NotPermitted)
    );
    let (xid, yid_task) = (f.k.task_id(x).0, f.k.task_id(y).0);
    assert_eq!(
        f.sys(tx, Call::TaskAllowSend, [0, yid_task, 0, 0, 0, 0]),
        err(Error::NotPermitted),
        "not its own to grant"
    );
    // A notify-only right: notifications, no message, one way.
    assert_eq!(
        f.sys(root, Call::TaskAllowSend, [xid, yid_task, 2, 0, 0, 0]),
        err(Error::InvalidArgument)
    );
    assert_eq!(
        f.sys(root, Call::TaskAllowSend, [xid, yid_task, 1, 0, 0, 0]),
        OK
    );
    assert_eq!(f.sys(tx, Call::NotifySignal, [yid, 0b10, 0, 0, 0, 0]), OK);
    assert_eq!(f.sys(ty, Call::NotifyWait, [0b10, 0, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.threads[ty].context().rdi, 0b10);
    for call in [Call::Send, Call::Call] {
        assert_eq!(
            f.sys(tx, call, [yid, 0, 0, 0, 0, 0]),
            err(Error::NotPermitted),
            "{call:?}: a notification is all it may send"
        );
    }
    let xid_thread = f.id(tx);
    assert_eq!(
        f.sys(ty, Call::NotifySignal, [xid_thread, 1, 0, 0, 0, 0]),
        err(Error::NotPermitted),
        "one way only"
    );
    // The full right.
    assert_eq!(
        f.sys(root, Call::TaskAllowSend, [xid, yid_task, 0, 0, 0, 0]),
        OK
    );
    assert_eq!(
        f.sys(tx, Call::Send, [yid, 0, 0, 0, 0, 0]),
        err(Error::TimedOut),
        "allowed now; nobody receives"
    );
    assert_eq!(f.sys(tx, Call::NotifySignal, [yid, 0b100, 0, 0, 0, 0]), OK);
    assert_eq!(f.sys(ty, Call::NotifyWait, [0b110, 0, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.threads[ty].context().rdi, 0b100);
}

#[test]
fn map_and_grant_items() {
    let mut f = Fixture::new();
    let sender = f.thread(ROOT, 10);
    let rtask = f.task(ROOT, Abilities::all(), 100);
    let receiver = f.thread(rtask, 10);
    f.give(ROOT, 0x70_0000, 2, PageRights::WRITE);
    f.write(sender, 0x70_0000, b"shared");
    // Window in the receiver's buffer; items in the sender's.
    let window = BUFFER_AT + receiver.position() as u64 * 0x4000 + IPC_WINDOW_OFFSET as u64;
    let mut w = 0x90_0000u64.to_ne_bytes().to_vec();
    w.extend(4u64.to_ne_bytes());
    f.write(receiver, window, &w);
    let items = BUFFER_AT + sender.position() as u64 * 0x4000 + IPC_ITEMS_OFFSET as u64;
    let mut it = 0x70_0000u64.to_ne_bytes().to_vec();
    it.extend(1u32.to_ne_bytes());
    it.extend((PageRights::WRITE.bits() as u32).to_ne_bytes());
    it.extend(0x70_1000u64.to_ne_bytes());
    it.extend(1u32.to_ne_bytes());
    it.extend(MAP_ITEM_GRANT.to_ne_bytes());
    f.write(sender, items, &it);
    f.sys(receiver, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    let rid = f.id(receiver);
    assert_eq!(
        f.sys(
            sender,
            Call::Send,
            [rid, 0, MessageTag::new(1, 0, 2).0, 0, 0, 0]
        ),
        OK
    );
    assert_eq!(f.read(receiver, 0x90_0000, 6), b"shared");
    assert!(
        f.k.tasks[ROOT].space().translate(0x70_0000).is_some(),
        "mapped: sender keeps it"
    );
    assert!(
        f.k.tasks[ROOT].space().translate(0x70_1000).is_none(),
        "granted: sender lost it"
    );
    assert_eq!(
        f.k.tasks[rtask].space().translate(0x90_1000).unwrap().1,
        PageRights::empty()
    );
    // Mapping into occupied window pages fails for the sender; the receiver keeps waiting.
    f.sys(receiver, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    assert_eq!(
        f.sys(
            sender,
            Call::Send,
            [rid, 0, MessageTag::new(1, 0, 1).0, 0, 0, 0]
        ),
        err(Error::AlreadyMapped)
    );
    assert_eq!(
        f.k.threads[receiver].state(),
        State::Receiving { from: None }
    );
}

#[test]
fn exception_round_trip_with_edited_registers() {
    let mut f = Fixture::new();
    let handler = f.thread(ROOT, 200);
    let child = f.task(ROOT, Abilities::all(), 100);
    let t = f.thread(child, 50);
    let handler_id = ThreadId(f.id(handler));
    f.k.threads[t].set_exception_handler(handler_id);
    f.k.threads[t].context_mut().rip = 0x40_1000;
    f.sys(handler, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    let fault = Fault {
        label: LABEL_EXCEPTION,
        vector: 6,
        error_code: 0,
        address: 0,
    };
    assert!(f.k.raise_fault(t, fault));
    assert_eq!(
        f.k.threads[t].state(),
        State::WaitingReply { from: handler }
    );
    let c = f.k.threads[handler].context();
    assert_eq!(MessageTag(c.rdx).label(), LABEL_EXCEPTION);
    let bytes = f.read(
        handler,
        BUFFER_AT + handler.position() as u64 * 0x4000,
        EXCEPTION_MESSAGE_SIZE,
    );
    let mut m = ExceptionMessage::from_bytes(&bytes).unwrap();
    assert_eq!(
        (m.vector, m.registers.rip, m.thread),
        (6, 0x40_1000, f.id(t))
    );
    m.registers.rip += 2;
    m.registers.rax = 0x1234;
    m.registers.rflags = u64::MAX; // IOPL and friends must not get through
    f.write(
        handler,
        BUFFER_AT + handler.position() as u64 * 0x4000,
        &m.to_bytes(),
    );
    let tid = f.id(t);
    let tag = MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0).0;
    assert_eq!(f.sys(handler, Call::Reply, [tid, 0, tag, 0, 0, 0]), OK);
    let c = f.k.threads[t].context();
    assert_eq!((c.rip, c.rax), (0x40_1002, 0x1234));
    assert_eq!(c.rflags & !USER_RFLAGS_MASK, 0x202, "IF on, IOPL 0");
    assert_eq!(f.k.threads[t].state(), State::Ready);
    // Second fault: kill.
    assert!(f.k.raise_fault(t, fault));
    f.sys(handler, Call::Receive, [0, 0, 0, 0, 0, 0]);
    let kill = MessageTag::new(REPLY_KILL, 0, 0).0;
    assert_eq!(f.sys(handler, Call::Reply, [tid, 0, kill, 0, 0, 0]), OK);
    assert!(f.k.threads[t].is_free());
}

#[test]
fn an_exception_message_across_a_page_boundary_goes_both_ways() {
    let mut f = Fixture::new();
    let handler = f.thread(ROOT, 200);
    let t = f.thread(ROOT, 50);
    // The buffer's message starts 64 bytes before the end of its first page.
    let buffer = BUFFER_AT + handler.position() as u64 * 0x4000 + 0x1000 - 64;
    f.k.threads[handler].set_ipc_buffer(buffer);
    let handler_id = ThreadId(f.id(handler));
    f.k.threads[t].set_exception_handler(handler_id);
    f.k.threads[t].context_mut().rip = 0x40_1000;
    f.sys(handler, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    let fault = Fault {
        label: LABEL_EXCEPTION,
        vector: 13,
        error_code: 8,
        address: 0,
    };
    assert!(f.k.raise_fault(t, fault));
    let bytes = f.read(handler, buffer, EXCEPTION_MESSAGE_SIZE);
    let mut m = ExceptionMessage::from_bytes(&bytes).unwrap();
    assert_eq!(
        (m.vector, m.error_code, m.registers.rip, m.thread),
        (13, 8, 0x40_1000, f.id(t))
    );
    m.registers.rip += 2;
    m.registers.r15 = 0x5678;
    f.write(handler, buffer, &m.to_bytes());
    let tag = MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0).0;
    let tid = f.id(t);
    assert_eq!(f.sys(handler, Call::Reply, [tid, 0, tag, 0, 0, 0]), OK);
    let c = f.k.threads[t].context();
    assert_eq!((c.rip, c.r15), (0x40_1002, 0x5678));
}

#[test]
fn thread_interrupt_stops_a_running_thread_with_an_exception_message() {
    let mut f = Fixture::new();
    let handler = f.thread(ROOT, 200);
    let guest = f.task(ROOT, Abilities::DEBUG_LOG, 100);
    let t = f.thread(guest, 50);
    let tid = f.id(t);
    f.k.threads[t].context_mut().rip = 0x40_2000;
    // Without a handler there is nobody to tell.
    let interrupt = |f: &mut Fixture| f.sys(handler, Call::ThreadInterrupt, [tid, 0, 0, 0, 0, 0]);
    assert_eq!(interrupt(&mut f), err(Error::InvalidArgument));
    let handler_id = ThreadId(f.id(handler));
    f.k.threads[t].set_exception_handler(handler_id);
    assert_eq!(f.k.threads[t].state(), State::Ready);
    assert_eq!(interrupt(&mut f), OK);
    assert_eq!(f.k.threads[handler].context().rdi, 1);
    assert_eq!(
        f.k.threads[t].state(),
        State::Sending {
            to: handler,
            call: true
        }
    );
    f.sys(handler, Call::Receive, [0, 0, 0, 0, 0, 0]);
    let bytes = f.read(
        handler,
        BUFFER_AT + handler.position() as u64 * 0x4000,
        EXCEPTION_MESSAGE_SIZE,
    );
    let m = ExceptionMessage::from_bytes(&bytes).unwrap();
    assert_eq!((m.vector, m.registers.rip), (VECTOR_INTERRUPT, 0x40_2000));
    // Now it waits for the reply (in the kernel): left alone.
    assert_eq!(interrupt(&mut f), OK);
    assert_eq!(f.k.threads[handler].context().rdi, 0);
    assert_eq!(
        f.sys(handler, Call::ThreadInterrupt, [0, 0, 0, 0, 0, 0]),
        err(Error::InvalidArgument)
    );
}

#[test]
fn syscalls_of_non_native_tasks_go_to_the_handler() {
    let mut f = Fixture::new();
    let handler = f.thread(ROOT, 200);
    let guest = f.task(ROOT, Abilities::DEBUG_LOG, 100);
    let t = f.thread(guest, 50);
    let handler_id = ThreadId(f.id(handler));
    f.k.threads[t].set_exception_handler(handler_id);
    f.sys(handler, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    f.sys(t, Call::Clock, [0; 6]);
    assert_eq!(
        f.k.threads[t].state(),
        State::WaitingReply { from: handler }
    );
    let c = f.k.threads[handler].context();
    assert_eq!(MessageTag(c.rdx).label(), LABEL_SYSCALL);
    assert_eq!(c.r10, VECTOR_SYSCALL);
}

#[test]
fn faults_without_handler_go_to_the_health_monitor_or_kill() {
    let mut f = Fixture::new();
    let monitor = f.thread(ROOT, 200);
    let child = f.task(ROOT, Abilities::all(), 100);
    let t = f.thread(child, 50);
    let fault = Fault {
        label: LABEL_EXCEPTION,
        vector: 14,
        error_code: 4,
        address: 0xdead,
    };
    assert_eq!(
        crate::fault::on_exception(&mut f.k, t, 14, 4, 0xdead),
        Outcome::Continue
    );
    assert!(f.k.threads[t].is_free(), "no handler, no monitor: killed");
    let t = f.thread(child, 50);
    let root = monitor;
    let mid = f.id(monitor);
    assert_eq!(
        f.sys(root, Call::SetHealthMonitor, [mid, 0, 0, 0, 0, 0]),
        OK
    );
    f.sys(monitor, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    assert!(f.k.raise_fault(t, fault));
    let c = f.k.threads[monitor].context();
    assert_eq!(MessageTag(c.rdx).label(), LABEL_FAULT_REPORT);
    assert_eq!((c.r10, c.r8, c.r9), (14, 4, 0xdead));
}

#[test]
fn killing_a_server_releases_its_clients() {
    let mut f = Fixture::new();
    let server = f.thread(ROOT, 10);
    let queued = f.thread(ROOT, 20);
    let waiting = f.thread(ROOT, 20);
    let sid = f.id(server);
    f.sys(server, Call::Receive, [0, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    f.sys(waiting, Call::Call, [sid, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    f.sys(queued, Call::Send, [sid, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    assert_eq!(
        f.k.threads[waiting].state(),
        State::WaitingReply { from: server }
    );
    assert!(matches!(f.k.threads[queued].state(), State::Sending { .. }));
    f.k.kill_thread(server);
    assert_eq!(f.k.threads[waiting].context().rax, err(Error::PeerGone));
    assert_eq!(f.k.threads[queued].context().rax, err(Error::PeerGone));
}

#[test]
fn io_ports_are_granted_down_the_tree_only() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let before = f.k.rps[RpIdx::ROOT].used.pages;
    let child = f.task(ROOT, Abilities::all(), 100);
    let grandchild = f.task(child, Abilities::all(), 100);
    let c = f.thread(child, 50);
    let (cid, gid) = (f.k.task_id(child).0, f.k.task_id(grandchild).0);
    assert_eq!(
        f.sys(root, Call::IoGrant, [cid, 0x3f8, 8, 0, 0, 0]),
        err(Error::NotPermitted),
        "COM1 is the kernel's"
    );
    assert_eq!(
        f.sys(root, Call::IoGrant, [cid, 0xfff0, 0x20, 0, 0, 0]),
        err(Error::InvalidArgument)
    );
    let pages = f.k.rps[RpIdx::ROOT].used.pages;
    assert_eq!(f.sys(root, Call::IoGrant, [cid, 0x2f8, 8, 0, 0, 0]), OK);
    assert_eq!(f.k.rps[RpIdx::ROOT].used.pages, pages + 2, "bitmap charged");
    let holds = |f: &Fixture, task, port: u64| f.k.holds_ports(task, port, port + 1);
    assert!(holds(&f, child, 0x2f8) && holds(&f, child, 0x2ff));
    assert!(!holds(&f, child, 0x300) && !holds(&f, child, 0x2f7));
    assert_eq!(
        f.sys(c, Call::IoGrant, [gid, 0x2f8, 9, 0, 0, 0]),
        err(Error::NotPermitted),
        "0x300 not held"
    );
    assert_eq!(f.sys(c, Call::IoGrant, [gid, 0x2fc, 4, 0, 0, 0]), OK);
    assert!(holds(&f, grandchild, 0x2fc) && !holds(&f, grandchild, 0x2f8));
    let rt = f.k.task_id(ROOT).0;
    assert_eq!(
        f.sys(c, Call::IoGrant, [rt, 0x2f8, 1, 0, 0, 0]),
        err(Error::NotPermitted),
        "not upwards"
    );
    f.k.destroy_task(child, u64::MAX);
    assert_eq!(
        f.k.rps[RpIdx::ROOT].used.pages,
        before,
        "bitmaps and tables returned"
    );
}

#[test]
fn io_grants_work_a_word_of_ports_at_a_time() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let child = f.task(ROOT, Abilities::all(), 100);
    let grandchild = f.task(child, Abilities::all(), 100);
    let c = f.thread(child, 50);
    let (cid, gid) = (f.k.task_id(child).0, f.k.task_id(grandchild).0);
    // The whole space above COM1 but for PCI configuration (the kernel's), and the edges
    // of 64-port words.
    assert_eq!(
        f.sys(root, Call::IoGrant, [cid, 0x400, 0xcf8 - 0x400, 0, 0, 0]),
        OK
    );
    assert_eq!(
        f.sys(root, Call::IoGrant, [cid, 0xcf8, 1, 0, 0, 0]),
        err(Error::NotPermitted),
        "configuration space is the kernel's"
    );
    assert_eq!(
        f.sys(root, Call::IoGrant, [cid, 0xd00, 0x1_0000 - 0xd00, 0, 0, 0]),
        OK
    );
    assert!(f.k.holds_ports(child, 0x400, 0xcf8) && f.k.holds_ports(child, 0xd00, 0x1_0000));
    assert!(!f.k.holds_ports(child, 0x3ff, 0x401));
    assert!(!f.k.holds_ports(child, 0xcf0, 0xd00));
    for (first, count) in [
        (0x43f, 2),
        (0x480, 64),
        (0x4c1, 63),
        (0xffff, 1),
        (0x500, 129),
    ] {
        assert_eq!(
            f.sys(c, Call::IoGrant, [gid, first, count, 0, 0, 0]),
            OK,
            "{first:#x}+{count}"
        );
    }
    let granted = |port: u64| {
        [
            (0x43f, 2),
            (0x480, 64),
            (0x4c1, 63),
            (0xffff, 1),
            (0x500, 129),
        ]
        .iter()
        .any(|&(first, count)| (first..first + count).contains(&port))
    };
    for port in (0x400..0xcf8).chain(0xd00..0x1_0000) {
        assert_eq!(
            f.k.holds_ports(grandchild, port, port + 1),
            granted(port),
            "port {port:#x}"
        );
    }
    assert!(f.k.holds_ports(grandchild, 0x4c1, 0x581));
    assert!(
        !f.k.holds_ports(grandchild, 0x480, 0x581),
        "0x4c0 is not granted"
    );
    assert!(!f.k.holds_ports(grandchild, 0x43e, 0x440));
    assert_eq!(
        f.sys(c, Call::IoGrant, [gid, 0x3c0, 0x41, 0, 0, 0]),
        err(Error::NotPermitted),
        "one port of the range not held"
    );
}

#[test]
fn killing_a_large_subtree_takes_bounded_steps() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let before = (
        f.k.rps[RpIdx::ROOT].used,
        f.k.tasks.iter().filter(|(_, t)| t.in_use()).count(),
    );
    // A chain of tasks, each with threads, page tables far apart and an I/O bitmap.
    let top = f.task(ROOT, Abilities::all(), 100);
    let mut task = top;
    let mut chain = vec![top];
    for depth in 0..6 {
        for i in 0..4u64 {
            f.give(
                task,
                0x0000_0100_0000_0000 + (depth * 4 + i) * (512 << 30),
                1,
                PageRights::empty(),
            );
            f.k.create_thread(task, 0x1000, 0x2000, 10, 0, 0).unwrap();
        }
        let id = f.k.task_id(task).0;
        assert_eq!(f.sys(root, Call::IoGrant, [id, 0x2f8, 8, 0, 0, 0]), OK);
        task = f.task(task, Abilities::all(), 100);
        chain.push(task);
    }
    let ready = f.k.create_thread(task, 0x1000, 0x2000, 10, 0, 0).unwrap();
    f.k.set_state(ready, State::Ready);
    let (tid, other) = (f.k.task_id(top).0, f.task(ROOT, Abilities::all(), 100));
    let mut calls = 0;
    loop {
        calls += 1;
        let c = f.k.threads[root].context_mut();
        (c.rax, c.rdi, c.rip) = (Call::TaskKill as u64, tid, 0x1002);
        assert_eq!(on_syscall(&mut f.k, root, || 0), Outcome::Continue);
        let c = &f.k.threads[root].context();
        if c.rip == 0x1002 {
            assert_eq!(c.rax, OK);
            break;
        }
        // Not done: the call restarts itself at its `syscall`, registers untouched.
        assert_eq!((c.rip, c.rax, c.rdi), (0x1000, Call::TaskKill as u64, tid));
        // Meanwhile the subtree is stopped and out of reach; the rest goes on.
        assert!(!f.k.run.is_queued(ready.position()) || f.k.threads[ready].is_free());
        assert_eq!(f.k.task(TaskId(tid)), Err(Error::NoSuchObject));
        assert_eq!(f.k.task(TaskId(f.k.task_id(other).0)), Ok(other));
        invariants(&f.k).unwrap();
        assert!(calls < 1_000, "no progress");
    }
    assert!(calls > 3, "{calls} calls: the work was not split");
    assert!(chain.iter().all(|&t| !f.k.tasks[t].in_use()));
    f.k.destroy_task(other, u64::MAX);
    assert_eq!(
        (
            f.k.rps[RpIdx::ROOT].used,
            f.k.tasks.iter().filter(|(_, t)| t.in_use()).count()
        ),
        before,
        "every task, thread, table and bitmap returned"
    );
}

#[test]
fn irq_lines_are_granted_attached_masked_until_acknowledged() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let child = f.task(ROOT, Abilities::all(), 100);
    let cid = f.k.task_id(child).0;
    let c = f.thread(child, 50);
    let c2 = f.thread(child, 50);
    assert_eq!(
        f.sys(root, Call::IrqGrant, [cid, 4, 0, 0, 0, 0]),
        err(Error::NotPermitted),
        "COM1 is the kernel's"
    );
    assert_eq!(
        f.sys(root, Call::IrqGrant, [cid, 24, 0, 0, 0, 0]),
        err(Error::InvalidArgument)
    );
    assert_eq!(
        f.sys(c, Call::IrqAttach, [3, 5, 0, 0, 0, 0]),
        err(Error::NotPermitted),
        "not granted yet"
    );
    assert_eq!(f.sys(root, Call::IrqGrant, [cid, 3, 0, 0, 0, 0]), OK);
    assert_eq!(
        f.sys(c, Call::IrqAttach, [3, 64, 0, 0, 0, 0]),
        err(Error::InvalidArgument),
        "bit 64"
    );
    assert_eq!(f.sys(c, Call::IrqAttach, [3, 5, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.irqs.unmasked, 1 << 3, "attached lines open");
    assert_eq!(
        f.sys(c2, Call::IrqAttach, [3, 5, 0, 0, 0, 0]),
        err(Error::NotPermitted),
        "one thread per line"
    );
    assert_eq!(
        f.sys(c2, Call::IrqAck, [3, 0, 0, 0, 0, 0]),
        err(Error::NotPermitted)
    );
    assert_eq!(
        f.sys(c, Call::IrqWait, [3, 0, 0, 0, 0, 0]),
        err(Error::TimedOut),
        "poll: nothing yet"
    );

    // Waiting, then the line fires: it closes and the waiter wakes.
    f.sys(c, Call::IrqWait, [3, TIMEOUT_INFINITE, 0, 0, 0, 0]);
    assert!(matches!(
        f.k.threads[c].state(),
        State::WaitingNotify { .. }
    ));
    f.k.irq_fired(3);
    assert_eq!(f.k.threads[c].state(), State::Ready);
    assert_eq!(f.k.threads[c].context().rax, OK);
    assert_eq!(f.k.irqs.unmasked, 0, "masked until acknowledged");
    // A second interrupt before the next wait is latched.
    f.k.irq_fired(3);
    assert_eq!(f.sys(c, Call::IrqWait, [3, 0, 0, 0, 0, 0]), OK, "latched");
    assert_eq!(f.sys(c, Call::IrqAck, [3, 0, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.irqs.unmasked, 1 << 3);

    // Without the IRQ ability nothing works.
    let plain = f.task(ROOT, Abilities::NATIVE_SYSCALLS, 100);
    let p = f.thread(plain, 50);
    assert_eq!(
        f.sys(p, Call::IrqAttach, [3, 1, 0, 0, 0, 0]),
        err(Error::AbilityDenied)
    );

    // Detach, and death of the thread, release and mask the line.
    assert_eq!(f.sys(c, Call::IrqDetach, [3, 0, 0, 0, 0, 0]), OK);
    assert_eq!(f.k.irqs.unmasked, 0);
    assert_eq!(
        f.sys(c2, Call::IrqAttach, [3, 7, 0, 0, 0, 0]),
        OK,
        "free again"
    );
    f.k.kill_thread(c2);
    assert_eq!(f.k.irqs.unmasked, 0);
    assert_eq!(f.k.irqs.lines[3].thread, None);
    f.k.irq_fired(3); // nobody attached: ignored
}

#[test]
fn an_early_timer_interrupt_rearms_the_timer() {
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let windows = [abi::syscall::WindowSpec {
        offset: 0,
        duration: 1_000_000,
        partition: 1,
        cpu: 0,
    }];
    f.write(root, BUFFER_AT, window_bytes(&windows));
    assert_eq!(
        f.sys(root, Call::ScheduleSet, [0, 4_000_000, BUFFER_AT, 1, 0, 0]),
        OK
    );
    assert_eq!(f.sys(root, Call::ScheduleSwitch, [0, 0, 0, 0, 0, 0]), OK);
    f.k.core_mut().timer_dirty = false;
    // The one-shot count is rounded down, so it may fire just before the boundary: nothing
    // changes, but the timer must be programmed again or the boundary would be missed.
    f.k.on_timer(f.k.core().next_boundary - 1);
    assert_eq!(f.k.core().active_partition, Some(1));
    assert!(f.k.core().timer_dirty);
    assert_eq!(f.k.next_event(f.k.core().next_boundary - 1), 1_000_000);
}

/// The bytes of a slice of plain-old-data window specs, as user space passes them.
#[allow(unsafe_code)] // a view of plain-old-data structs as bytes
fn window_bytes(windows: &[abi::syscall::WindowSpec]) -> &[u8] {
    // SAFETY: WindowSpec is repr(C) of four u64 (no padding); the slice is alive.
    unsafe { std::slice::from_raw_parts(windows.as_ptr().cast(), std::mem::size_of_val(windows)) }
}

proptest::proptest! {
    /// Windows, priorities and TP0 together, through the kernel's own timer path: for a
    /// generated schedule and generated ready threads, at generated instants the thread the
    /// kernel chooses is the model's: the highest priority among TP0 and the partition whose
    /// window contains the instant (the window's partition on a tie, FIFO within each).
    #[test]
    fn the_kernel_runs_what_the_window_model_says(
        gaps in proptest::collection::vec((0u64..3, 1u64..4, 1u64..4), 1..5),
        threads in proptest::collection::vec((0u8..5, 0u8..4), 1..12),
        steps in proptest::collection::vec(1u64..7, 1..60),
    ) {
        let mut f = Fixture::new();
        let root = f.thread(ROOT, 255);
        // Windows in ms: a gap, then a window of the given length for the given partition.
        let mut windows = Vec::new();
        let mut at = 0;
        for &(gap, length, partition) in &gaps {
            at += gap * 1_000_000;
            windows.push(abi::syscall::WindowSpec { offset: at, duration: length * 1_000_000, partition, cpu: 0 });
            at += length * 1_000_000;
        }
        let major = at + 1_000_000;
        f.write(root, BUFFER_AT, window_bytes(&windows));
        let count = windows.len() as u64;
        proptest::prop_assert_eq!(f.sys(root, Call::ScheduleSet, [0, major, BUFFER_AT, count, 0, 0]), OK);
        proptest::prop_assert_eq!(f.sys(root, Call::ScheduleSwitch, [0, 0, 0, 0, 0, 0]), OK);
        // The root leaves the stage; the generated threads are ready in creation order.
        f.k.set_state(root, State::Sleeping);
        let task = f.task(ROOT, Abilities::all(), 255);
        let made: Vec<(ThreadIdx, u8, u8)> = threads
            .iter()
            .map(|&(tp, priority)| {
                let priority = 10 + priority * 10;
                let t = f.k.create_thread(task, 0x1000, 0x2000, priority, 0, 0).unwrap();
                f.k.set_time_partition(t, tp).unwrap();
                f.k.set_state(t, State::Ready);
                (t, tp, priority)
            })
            .collect();
        let mut now = 0;
        for step in steps {
            now += step * 500_000;
            f.k.on_timer(now);
            let phase = now % major;
            let active = windows
                .iter()
                .find(|w| (w.offset..w.offset + w.duration).contains(&phase))
                .map(|w| w.partition as u8);
            let eligible = |&&(_, tp, _): &&(ThreadIdx, u8, u8)| tp == 0 || Some(tp) == active;
            let best = made.iter().filter(eligible).map(|&(_, _, p)| p).max();
            let expected = best.and_then(|p| {
                let at_best = |tp: u8| made.iter().find(|&&(_, t, q)| q == p && t == tp).map(|&(t, ..)| t);
                active.filter(|&a| a != 0).and_then(at_best).or_else(|| at_best(0))
            });
            proptest::prop_assert_eq!(f.k.core().active_partition.filter(|&p| p != 0), active, "active window at {}", now);
            proptest::prop_assert_eq!(f.k.choose(), expected, "chosen thread at {}", now);
        }
    }
}

/// The page tables and user pages of a task's address space (`root`: its top table):
/// calls `table` with each table frame and `page` with each mapped user page's frame and
/// whether it is writable.
#[allow(unsafe_code)] // reads page tables in the host-test arena
fn walk(root: u64, level: u32, table: &mut impl FnMut(u64), page: &mut impl FnMut(u64, bool)) {
    table(root);
    // SAFETY: a page-table frame of a live space in the arena (8-byte aligned, 4 KiB).
    let entries = unsafe { &*(crate::mem::phys_to_virt(root) as *const [u64; 512]) };
    let user = if level == 3 { 256 } else { 512 };
    for &entry in entries[..user].iter().filter(|&&e| e & 1 != 0) {
        let frame = entry & 0x000f_ffff_ffff_f000;
        if level == 0 {
            page(frame, entry & 2 != 0);
        } else {
            walk(frame, level - 1, table, page);
        }
    }
}

/// A task, the frames the kernel keeps for it (page tables, I/O bitmap) and its user
/// pages (frame, writable).
type TaskFrames = (TaskIdx, Vec<u64>, Vec<(u64, bool)>);

/// The frames of each live task.
fn frames_of(k: &Kernel) -> Vec<TaskFrames> {
    k.tasks
        .iter()
        .filter(|(_, t)| t.in_use() && t.space().root_frame() != 0)
        .map(|(slot, t)| {
            let (mut tables, mut pages) = (Vec::new(), Vec::new());
            walk(
                t.space().root_frame(),
                3,
                &mut |f| tables.push(f),
                &mut |f, w| pages.push((f, w)),
            );
            tables.extend(t.io_bitmap().iter().filter(|&&f| f != 0));
            (slot, tables, pages)
        })
        .collect()
}

/// What must hold after every system call, whatever the arguments were.
fn invariants(k: &Kernel) -> Result<(), String> {
    // Send queues: a thread is in at most one, exactly when it is sending to its owner.
    let mut queued = vec![0u32; crate::state::MAX_THREADS];
    for (receiver, r) in k.threads.iter() {
        let mut at = r.senders();
        let mut steps = 0;
        while let Some(s) = at {
            queued[s.position()] += 1;
            if !matches!(k.threads[s].state(), State::Sending { to, .. } if to == receiver) {
                return Err(format!(
                    "{s:?} is queued on {receiver:?} but {:?}",
                    k.threads[s].state()
                ));
            }
            steps += 1;
            if steps > crate::state::MAX_THREADS {
                return Err(format!("the send queue of {receiver:?} loops"));
            }
            at = k.threads[s].next_sender();
        }
    }
    for (slot, t) in k.threads.iter() {
        let sending = matches!(t.state(), State::Sending { .. });
        if queued[slot.position()] != u32::from(sending) {
            return Err(format!(
                "{slot:?} ({:?}) is in {} send queues",
                t.state(),
                queued[slot.position()]
            ));
        }
    }
    // No kernel frame (page table, I/O bitmap) is a user page or belongs to two tasks.
    let frames = frames_of(k);
    let mut kernel_frames = std::collections::HashMap::new();
    for (task, tables, _) in &frames {
        for &f in tables {
            if let Some(other) = kernel_frames.insert(f, *task) {
                return Err(format!(
                    "table or bitmap frame {f:#x} of {task:?} and {other:?}"
                ));
            }
        }
    }
    for (task, _, pages) in &frames {
        if let Some((f, _)) = pages.iter().find(|(f, _)| kernel_frames.contains_key(f)) {
            return Err(format!("{task:?} maps the kernel's frame {f:#x}"));
        }
    }
    for (rp, r) in k.rps.iter().filter(|(_, r)| r.in_use) {
        let tasks: Vec<&Task> = k
            .tasks
            .iter()
            .filter(|(_, t)| t.in_use() && t.rp() == rp)
            .map(|(_, t)| t)
            .collect();
        let pages: u64 = tasks.iter().map(|t| t.pages_charged()).sum();
        let threads = k
            .threads
            .iter()
            .filter(|(_, t)| !t.is_free() && k.tasks[t.task()].rp() == rp)
            .count() as u64;
        let counted = Amount {
            tasks: tasks.len() as u64,
            threads,
            pages,
        };
        if r.used != counted {
            return Err(format!("{rp:?}: charged {:?}, objects {counted:?}", r.used));
        }
        let committed = (
            r.used.tasks + r.carved.tasks,
            r.used.threads + r.carved.threads,
            r.used.pages + r.carved.pages,
        );
        if committed.0 > r.quota.tasks
            || committed.1 > r.quota.threads
            || committed.2 > r.quota.pages
        {
            return Err(format!(
                "{rp:?}: {committed:?} beyond its quota {:?}",
                r.quota
            ));
        }
    }
    for (slot, t) in k.tasks.iter().filter(|(_, t)| t.in_use()) {
        if let Some(parent) = t.parent() {
            let p = &k.tasks[parent];
            if !p.in_use() {
                return Err(format!("{slot:?}: its parent {parent:?} is gone"));
            }
            if !p.abilities().contains(t.abilities()) || t.mcp() > p.mcp() {
                return Err(format!("{slot:?}: more abilities or MCP than its parent"));
            }
        }
    }
    for (slot, t) in k.threads.iter().filter(|(_, t)| !t.is_free()) {
        let task = &k.tasks[t.task()];
        if !task.in_use() {
            return Err(format!("{slot:?}: its task {:?} is gone", t.task()));
        }
        if t.priority() > task.mcp() {
            return Err(format!("{slot:?}: priority {} above its MCP", t.priority()));
        }
        let runnable = t.state() == State::Ready && !t.is_suspended();
        if k.run.is_queued(slot.position()) != runnable {
            return Err(format!(
                "{slot:?}: {:?} but queued: {}",
                t.state(),
                !runnable
            ));
        }
    }
    Ok(())
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

    /// Random system calls with random arguments (edge values, live ids, random words) by
    /// random runnable threads of the root task and of a child task in its own resource
    /// partition: after each call the kernel's invariants hold (quota accounting adds up,
    /// abilities and MCP only shrink down the tree, priorities within MCP, a thread is in a
    /// run queue exactly when it can run).
    #[test]
    fn random_calls_keep_the_kernel_consistent(
        calls in proptest::collection::vec(
            (0usize..8, 0usize..64, proptest::collection::vec((0usize..24, proptest::prelude::any::<u64>()), 6)),
            1..150,
        ),
    ) {
        let mut f = Fixture::new();
        f.thread(ROOT, 200);
        let rp = f.k.rp_create(ROOT, Amount { tasks: 4, threads: 8, pages: 64 }, u8::MAX.into()).unwrap();
        let child = f
            .k
            .create_task(ROOT, Abilities::CREATE_THREAD | Abilities::CREATE_TASK | Abilities::MAP, 100, rp, "c")
            .unwrap();
        f.thread(child, 90);
        let numbers: Vec<u64> = Call::ALL.iter().map(|c| c.code()).chain([0, 7, 99, u64::MAX]).collect();
        for (caller, call, args) in calls {
            // Only a runnable thread makes calls; end of the sequence if none is left.
            let runnable: Vec<ThreadIdx> = f
                .k
                .threads
                .iter()
                .filter(|(_, t)| t.state() == State::Ready && !t.is_suspended())
                .map(|(slot, _)| slot)
                .collect();
            if runnable.is_empty() {
                break;
            }
            let t = runnable[caller % runnable.len()];
            let number = numbers[call % numbers.len()];
            if number == Call::SystemHalt.code() {
                continue;
            }
            let mut ids: Vec<u64> = f.k.threads.iter().filter(|(_, x)| !x.is_free()).map(|(s, _)| f.k.thread_id(s).0).collect();
            ids.extend(f.k.tasks.iter().filter(|(_, x)| x.in_use()).map(|(s, _)| f.k.task_id(s).0));
            let pick = |(kind, raw): (usize, u64)| -> u64 {
                match kind {
                    0..=7 => ids[raw as usize % ids.len()],
                    8 => 0,
                    9 => 1,
                    10 => 512,
                    11 => 513,
                    12 => BUFFER_AT,
                    13 => BUFFER_AT + raw % 0x10000,
                    14 => u64::MAX,
                    15 => 0xffff_8000_0000_0000,
                    16 => 0x0000_8000_0000_0000,
                    17 => raw % 300,
                    18 => raw % 4,
                    _ => raw,
                }
            };
            let a: Vec<u64> = args.into_iter().map(pick).collect();
            let c = f.k.threads[t].context_mut();
            c.rax = number;
            [c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9] = [a[0], a[1], a[2], a[3], a[4], a[5]];
            let _ = on_syscall(&mut f.k, t, || 0);
            if let Err(broken) = invariants(&f.k) {
                proptest::prop_assert!(false, "after call {} by {:?} with {:x?}: {}", number, t, a, broken);
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]

    /// Two partitions (sibling tasks of the root, each in its own resource partition, with
    /// every ability a partition may have and pages of their own) make random calls with
    /// random arguments, the other's ids among them; the root makes none. After each call
    /// the kernel's invariants hold and no frame is mapped in both partitions' task trees:
    /// neither can reach the other's memory (only the root could share a frame).
    #[test]
    fn two_partitions_never_share_a_frame(
        calls in proptest::collection::vec(
            (0usize..8, 0usize..128, proptest::collection::vec((0usize..20, proptest::prelude::any::<u64>()), 6)),
            1..150,
        ),
    ) {
        let mut f = Fixture::new();
        f.thread(ROOT, 200);
        let partition = Abilities::CREATE_THREAD | Abilities::CREATE_TASK | Abilities::MAP | Abilities::DEBUG_LOG | Abilities::NATIVE_SYSCALLS;
        let mut tops = Vec::new();
        for i in 0..2u64 {
            let rp = f.k.rp_create(ROOT, Amount { tasks: 4, threads: 6, pages: 64 }, u8::MAX.into()).unwrap();
            let top = f.k.create_task(ROOT, partition, 100, rp, "p").unwrap();
            f.give(top, 0x40_0000, 8, PageRights::WRITE);
            f.give(top, 0x80_0000 + i * 0x10_0000, 4, PageRights::WRITE | PageRights::EXECUTE);
            f.thread(top, 90);
            f.thread(top, 80);
            tops.push(top);
        }
        // Half the calls are the ones that move memory and make objects, with arguments
        // in the shapes they take (the other partition's ids among them); the rest random.
        let focus = [Call::Map, Call::Unmap, Call::Protect, Call::TaskCreate, Call::ThreadCreate, Call::TaskKill, Call::TaskAllowSend, Call::Send, Call::Call];
        let numbers: Vec<u64> = focus.iter().chain(Call::ALL.iter()).map(|c| c.code()).collect();
        for (caller, call, args) in calls {
            let runnable: Vec<ThreadIdx> = f
                .k
                .threads
                .iter()
                .filter(|(_, t)| t.state() == State::Ready && !t.is_suspended() && t.task() != ROOT)
                .map(|(slot, _)| slot)
                .collect();
            if runnable.is_empty() {
                break;
            }
            let t = runnable[caller % runnable.len()];
            let number = if call % 2 == 0 { focus[call / 2 % focus.len()].code() } else { numbers[call / 2 % numbers.len()] };
            let mut ids: Vec<u64> = f.k.threads.iter().filter(|(_, x)| !x.is_free()).map(|(s, _)| f.k.thread_id(s).0).collect();
            ids.extend(f.k.tasks.iter().filter(|(_, x)| x.in_use()).map(|(s, _)| f.k.task_id(s).0));
            let page = |raw: u64| match raw % 3 {
                0 => 0x40_0000 + (raw / 3 % 8) * 0x1000,
                1 => 0x80_0000 + (raw / 3 % 0x200) * 0x1000,
                _ => 0x4000_0000 + (raw / 3 % 16) * 0x1000,
            };
            let pick = |(position, (kind, raw)): (usize, (usize, u64))| -> u64 {
                match (kind, position) {
                    (0..=9, 0) => ids[raw as usize % ids.len()],
                    (0..=9, 1 | 2) => page(raw),
                    (0..=9, _) => raw % 4,
                    (10..=12, _) => ids[raw as usize % ids.len()],
                    (13, _) => 0,
                    (14, _) => test_arena::USER_BASE + (raw % 64) * 0x1000,
                    (15, _) => 0xffff_8000_0000_0000 + (raw % 64) * 0x1000,
                    (16, _) => BUFFER_AT,
                    _ => raw,
                }
            };
            let a: Vec<u64> = args.into_iter().enumerate().map(pick).collect();
            let c = f.k.threads[t].context_mut();
            c.rax = number;
            [c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9] = [a[0], a[1], a[2], a[3], a[4], a[5]];
            let _ = on_syscall(&mut f.k, t, || 0);
            if let Err(broken) = invariants(&f.k) {
                proptest::prop_assert!(false, "after call {} by {:?} with {:x?}: {}", number, t, a, broken);
            }
            let frames = frames_of(&f.k);
            let pages_under = |top: TaskIdx| -> std::collections::HashSet<u64> {
                frames
                    .iter()
                    .filter(|(task, _, _)| f.k.is_within(*task, top))
                    .flat_map(|(_, _, pages)| pages.iter().map(|&(frame, _)| frame))
                    .collect()
            };
            let (a, b) = (pages_under(tops[0]), pages_under(tops[1]));
            proptest::prop_assert!(a.is_disjoint(&b), "after call {}: shared frames {:x?}", number, a.intersection(&b).collect::<Vec<_>>());
        }
    }
}

#[test]
fn device_registers_are_mapped_uncached_and_never_touched_by_the_kernel() {
    use abi::boot::{MemoryKind, MemoryRegion};
    static MAP: [MemoryRegion; 1] = [MemoryRegion {
        start: 0,
        pages: 0x2_0000, // 512 MiB of RAM
        kind: MemoryKind::USABLE,
        _reserved: 0,
    }];
    crate::mem::MEMORY_MAP.call_once(|| &MAP);
    let mut f = Fixture::new();
    let root = f.thread(ROOT, 200);
    let child = f.task(ROOT, Abilities::all(), 100);
    let c = f.thread(child, 50);
    let cid = f.k.task_id(child).0;
    let rw = PageRights::WRITE.bits();
    for (physical, why) in [
        (0x1000_0000, "RAM the firmware lists"),
        (0x8_0000, "the first MiB"),
        (0xfee0_0000, "the local APIC"),
        (0xfec0_0000, "the IOAPIC"),
    ] {
        assert_eq!(
            f.sys(root, Call::MapDevice, [cid, physical, 0x60_0000, 1, rw, 0]),
            err(Error::BadAddress),
            "{why}"
        );
    }
    assert_eq!(
        f.sys(
            root,
            Call::MapDevice,
            [cid, 0xc000_0000, 0x60_0000, 2, rw, 0]
        ),
        OK
    );
    let leaf = f.k.tasks[child].space().translate(0x60_0000);
    assert_eq!(leaf, None, "invisible to the kernel's user-memory accesses");
    // Neither a source of another mapping nor a buffer of a call.
    let grandchild = f.task(child, Abilities::all(), 90);
    let gid = f.k.task_id(grandchild).0;
    assert_eq!(
        f.sys(c, Call::Map, [gid, 0x60_0000, 0x70_0000, 1, 0, 0]),
        err(Error::BadAddress)
    );
    assert_eq!(
        f.sys(c, Call::DebugWrite, [0x60_0000, 8, 0, 0, 0, 0]),
        err(Error::BadAddress)
    );
    // The same frames again: the destination is taken.
    assert_eq!(
        f.sys(
            root,
            Call::MapDevice,
            [cid, 0xc000_0000, 0x60_1000, 1, rw, 0]
        ),
        err(Error::AlreadyMapped)
    );
    // Only the root task reaches configuration space (host tests have no bus: all ones).
    assert_eq!(
        f.sys(c, Call::PciConfig, [0x1800, 0, 0, 0, 0, 0]),
        err(Error::NotPermitted)
    );
    assert_eq!(
        f.sys(root, Call::PciConfig, [0x1802, 0, 0, 0, 0, 0]),
        err(Error::InvalidArgument),
        "unaligned"
    );
    assert_eq!(f.sys(root, Call::PciConfig, [0x1800, 0, 0, 0, 0, 0]), OK);
    // So does the IOMMU; host tests have none (the kernel found no DMAR).
    for call in [Call::DmaMap, Call::DmaFault] {
        let a = [4 << 3, 0x10_0000, 1, 0, 0, 0];
        assert_eq!(f.sys(c, call, a), err(Error::NotPermitted), "{call:?}");
        assert_eq!(f.sys(root, call, a), err(Error::NoSuchObject), "{call:?}");
    }
    f.k.destroy_task(child, u64::MAX);
}
