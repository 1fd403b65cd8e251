//! Mode `tasks`: task and thread management — argument errors, abilities, maximum controlled
//! priority, control rights down the task tree, the thread life cycle (create, start,
//! suspend, resume, kill, set priority), scheduling by priority, and `task_kill` returning
//! kernel memory to the resource partition.

use crate::check::{expect, expect_eq, expect_err, expect_ok, must, status};
use crate::child::{
    BASIC, BOGUS_ID, CHILD_MCP, LOW, Lab, MS, WAIT, busy_wait, entry_address, sleeper, wait_until,
    worker,
};
use core::sync::atomic::Ordering;
use root_task::spawn::words_at;
use user_rt::abi::syscall::{
    Abilities, Call, Error, ROOT_PRIORITY, TaskId, ThreadAttribute, ThreadId,
};
use user_rt::{println, sys};

/// A user address used as the (never used) stack of threads that are never started.
const UNUSED_STACK: u64 = 0x1000_0000;
const KERNEL_ADDRESS: u64 = 0xffff_ffff_8000_0000;

pub fn run() {
    let mut lab = Lab::new();
    argument_errors(&lab);
    abilities_mcp_and_rights(&mut lab);
    life_cycle(&mut lab);
    scheduling(&mut lab);
    kill_returns_quota(&mut lab);
    kill_wakes_callers(&mut lab);
    println!("all tasks checks passed");
    let _ = sys::system_halt(true);
}

fn argument_errors(lab: &Lab) {
    let bogus_task = TaskId(BOGUS_ID);
    let bogus = ThreadId(BOGUS_ID);
    let park = entry_address(sleeper);
    expect_err(
        "task_create with a 16-byte name is InvalidArgument",
        sys::task_create(BASIC, 10, 0, "sixteen-bytes-xx"),
        Error::InvalidArgument,
    );
    let name = "x";
    let (rax, _) = sys::raw6(
        Call::TaskCreate as u64,
        [1 << 40, 10, 0, name.as_ptr() as u64, 1, 0],
    );
    expect_err(
        "task_create with unknown ability bits is InvalidArgument",
        status(rax),
        Error::InvalidArgument,
    );
    let (rax, _) = sys::raw6(Call::TaskCreate as u64, [BASIC.bits(), 10, 0, 0x10, 4, 0]);
    expect_err(
        "task_create with an unmapped name is BadAddress",
        status(rax),
        Error::BadAddress,
    );
    expect_err(
        "task_create in a nonexistent resource partition is NoSuchObject",
        sys::task_create(BASIC, 10, 0xfff0, "x"),
        Error::NoSuchObject,
    );
    expect_err(
        "task_kill of the caller's own task is NotPermitted",
        sys::task_kill(lab.task),
        Error::NotPermitted,
    );
    expect_err(
        "task_kill of a nonexistent task is NoSuchObject",
        sys::task_kill(bogus_task),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_create in a nonexistent task is NoSuchObject",
        sys::thread_create(Some(bogus_task), park, UNUSED_STACK, LOW, 0),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_create with a kernel entry address is InvalidArgument",
        sys::thread_create(None, KERNEL_ADDRESS, UNUSED_STACK, LOW, 0),
        Error::InvalidArgument,
    );
    expect_err(
        "thread_create with a kernel stack address is InvalidArgument",
        sys::thread_create(None, park, KERNEL_ADDRESS, LOW, 0),
        Error::InvalidArgument,
    );
    expect_err(
        "thread_start of a nonexistent thread is NoSuchObject",
        sys::thread_start(bogus),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_suspend of a nonexistent thread is NoSuchObject",
        sys::thread_suspend(bogus),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_resume of a nonexistent thread is NoSuchObject",
        sys::thread_resume(bogus),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_kill of a nonexistent thread is NoSuchObject",
        sys::thread_kill(bogus),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_set of a nonexistent thread is NoSuchObject",
        sys::thread_set(Some(bogus), ThreadAttribute::Priority, LOW as u64),
        Error::NoSuchObject,
    );
    let (rax, _) = sys::raw6(Call::ThreadSet as u64, [0, 99, 0, 0, 0, 0]);
    expect_err(
        "thread_set of an unknown attribute is InvalidArgument",
        status(rax),
        Error::InvalidArgument,
    );
    let (me, task) = sys::thread_self();
    expect(
        "thread_self names a thread and a task",
        me.0 != 0 && task.0 != 0 && me == lab.me,
    );
}

// Results of `limited_probe`, in order.
const P_THREAD_CREATE: usize = 0;
const P_TASK_MORE_ABILITIES: usize = 1;
const P_TASK_MCP_ABOVE: usize = 2;
const P_TASK_OK: usize = 3;
const P_TASK_KILL_OWN_CHILD: usize = 4;
const P_KILL_ROOT: usize = 5;
const P_KILL_SIBLING: usize = 6;
const P_KILL_SELF: usize = 7;
const P_PRIORITY_ABOVE: usize = 8;
const P_PRIORITY_OK: usize = 9;
const P_SUSPEND_ROOT: usize = 10;
const P_KILL_ROOT_THREAD: usize = 11;
const P_TIME_PARTITION: usize = 12;
const P_SELF_THREAD: usize = 13;
const P_SELF_TASK: usize = 14;
const P_KEPT_CHILD: usize = 15;
const P_KEPT_CHILD_CODE: usize = 16;

worker!(
    /// Runs in a task with CREATE_TASK but without CREATE_THREAD, MAP or SCHEDULING, MCP
    /// `CHILD_MCP`. Args: root task, root main thread, sibling task, an entry address.
    fn limited_probe(b, ipc) {
        let (root_task, root_thread) = (TaskId(b.arg(0)), ThreadId(b.arg(1)));
        let sibling = TaskId(b.arg(2));
        let entry = b.arg(3);
        b.set_code(
            P_THREAD_CREATE,
            &sys::thread_create(None, entry, UNUSED_STACK, LOW, 0),
        );
        b.set_code(
            P_TASK_MORE_ABILITIES,
            &sys::task_create(Abilities::CREATE_TASK | Abilities::MAP, 10, 0, "sub"),
        );
        b.set_code(
            P_TASK_MCP_ABOVE,
            &sys::task_create(Abilities::CREATE_TASK, CHILD_MCP + 1, 0, "sub"),
        );
        let sub = sys::task_create(Abilities::DEBUG_LOG, CHILD_MCP, 0, "sub");
        b.set_code(P_TASK_OK, &sub);
        b.set_code(
            P_TASK_KILL_OWN_CHILD,
            &sub.and_then(sys::task_kill),
        );
        b.set_code(P_KILL_ROOT, &sys::task_kill(root_task));
        b.set_code(P_KILL_SIBLING, &sys::task_kill(sibling));
        let (me, my_task) = sys::thread_self();
        b.set_result(P_SELF_THREAD, me.0);
        b.set_result(P_SELF_TASK, my_task.0);
        b.set_code(P_KILL_SELF, &sys::task_kill(my_task));
        b.set_code(
            P_PRIORITY_ABOVE,
            &sys::thread_set(None, ThreadAttribute::Priority, CHILD_MCP as u64 + 1),
        );
        b.set_code(
            P_PRIORITY_OK,
            &sys::thread_set(None, ThreadAttribute::Priority, CHILD_MCP as u64),
        );
        b.set_code(P_SUSPEND_ROOT, &sys::thread_suspend(root_thread));
        b.set_code(P_KILL_ROOT_THREAD, &sys::thread_kill(root_thread));
        b.set_code(
            P_TIME_PARTITION,
            &sys::thread_set(None, ThreadAttribute::TimePartition, 0),
        );
        // A grandchild of the root that stays, to check control rights and cascading kills.
        let kept = sys::task_create(Abilities::DEBUG_LOG, CHILD_MCP, 0, "grandchild");
        b.set_code(P_KEPT_CHILD_CODE, &kept);
        b.set_result(P_KEPT_CHILD, kept.map_or(0, |t| t.0));
    }
);

fn abilities_mcp_and_rights(lab: &mut Lab) {
    let sibling = lab.task("t-sibling", BASIC, CHILD_MCP);
    let limited = lab.task("t-limited", BASIC | Abilities::CREATE_TASK, CHILD_MCP);
    let park = entry_address(sleeper);

    // Root-side MCP checks on the child task.
    expect_err(
        "thread_create above the task's MCP is McpExceeded",
        sys::thread_create(Some(limited), park, UNUSED_STACK, CHILD_MCP + 1, 0),
        Error::McpExceeded,
    );
    let at_mcp = expect_ok(
        "thread_create at exactly the task's MCP",
        sys::thread_create(Some(limited), park, UNUSED_STACK, CHILD_MCP, 0),
    );
    expect_ok(
        "thread_kill of a never started thread",
        sys::thread_kill(at_mcp),
    );

    let probe = lab.worker(
        Some(limited),
        limited_probe,
        LOW,
        &[lab.task.0, lab.me.0, sibling.0, park],
    );
    expect_err(
        "thread_set Priority above the task's MCP is McpExceeded",
        sys::thread_set(
            Some(probe.id),
            ThreadAttribute::Priority,
            CHILD_MCP as u64 + 1,
        ),
        Error::McpExceeded,
    );
    expect_ok(
        "thread_set Priority of a child's thread within its MCP",
        sys::thread_set(Some(probe.id), ThreadAttribute::Priority, LOW as u64 - 10),
    );
    probe.start();
    probe.wait_done("probe in a task without CREATE_THREAD");
    let b = probe.block;
    let r = |i| status(b.result(i));
    expect_err(
        "thread_create without CREATE_THREAD is AbilityDenied",
        r(P_THREAD_CREATE),
        Error::AbilityDenied,
    );
    expect_err(
        "task_create with abilities beyond the caller's is AbilityDenied",
        r(P_TASK_MORE_ABILITIES),
        Error::AbilityDenied,
    );
    expect_err(
        "task_create with an MCP above the caller's is McpExceeded",
        r(P_TASK_MCP_ABOVE),
        Error::McpExceeded,
    );
    expect_eq(
        "task_create of a subset of abilities at the caller's MCP succeeds",
        r(P_TASK_OK),
        Ok(()),
    );
    expect_eq(
        "task_kill of the caller's own child succeeds",
        r(P_TASK_KILL_OWN_CHILD),
        Ok(()),
    );
    expect_err(
        "task_kill of an ancestor is NotPermitted",
        r(P_KILL_ROOT),
        Error::NotPermitted,
    );
    expect_err(
        "task_kill of a sibling is NotPermitted",
        r(P_KILL_SIBLING),
        Error::NotPermitted,
    );
    expect_err(
        "task_kill of the caller's own task from a child is NotPermitted",
        r(P_KILL_SELF),
        Error::NotPermitted,
    );
    expect_err(
        "thread_set of the own Priority above the MCP is McpExceeded",
        r(P_PRIORITY_ABOVE),
        Error::McpExceeded,
    );
    expect_eq(
        "thread_set of the own Priority up to the MCP succeeds",
        r(P_PRIORITY_OK),
        Ok(()),
    );
    expect_err(
        "thread_suspend of an ancestor's thread is NotPermitted",
        r(P_SUSPEND_ROOT),
        Error::NotPermitted,
    );
    expect_err(
        "thread_kill of an ancestor's thread is NotPermitted",
        r(P_KILL_ROOT_THREAD),
        Error::NotPermitted,
    );
    expect_err(
        "thread_set TimePartition without SCHEDULING is AbilityDenied",
        r(P_TIME_PARTITION),
        Error::AbilityDenied,
    );
    expect_eq(
        "thread_self in a child names the ids its creator got",
        (b.result(P_SELF_THREAD), b.result(P_SELF_TASK)),
        (probe.id.0, limited.0),
    );

    // Control rights reach grandchildren, and killing a task kills its descendants.
    expect_eq(
        "a child creates a grandchild task",
        r(P_KEPT_CHILD_CODE),
        Ok(()),
    );
    let grandchild = TaskId(b.result(P_KEPT_CHILD));
    let in_grandchild = expect_ok(
        "thread_create in a grandchild task",
        sys::thread_create(Some(grandchild), park, UNUSED_STACK, 10, 0),
    );
    expect_ok(
        "task_kill of a child with a grandchild",
        sys::task_kill(limited),
    );
    expect_err(
        "task_kill also destroyed the grandchild",
        sys::task_kill(grandchild),
        Error::NoSuchObject,
    );
    expect_err(
        "task_kill also destroyed the grandchild's threads",
        sys::thread_start(in_grandchild),
        Error::NoSuchObject,
    );
    must("task_kill of the sibling", sys::task_kill(sibling));
}

const COUNT: usize = 0;

worker!(
    /// Counts as fast as it can, forever (never blocks).
    fn counter(b, ipc) {
        loop {
            b.add_result(COUNT, 1);
        }
    }
);

fn life_cycle(lab: &mut Lab) {
    let task = lab.task("t-counter", BASIC, CHILD_MCP);
    let w = lab.worker(Some(task), counter, LOW, &[]);
    let count = || w.block.result(COUNT);
    sys::sleep(5 * MS);
    expect(
        "an inactive (never started) thread does not run",
        count() == 0,
    );
    expect_ok("thread_start of a new thread", sys::thread_start(w.id));
    expect(
        "a started lower-priority thread runs while the root sleeps",
        wait_until(WAIT, || count() > 0),
    );
    expect_err(
        "thread_start of a started thread is InvalidArgument",
        sys::thread_start(w.id),
        Error::InvalidArgument,
    );
    expect_ok(
        "thread_suspend of a running thread",
        sys::thread_suspend(w.id),
    );
    let c1 = count();
    sys::sleep(5 * MS);
    expect_eq("a suspended thread does not run", count(), c1);
    expect_ok(
        "thread_resume of a suspended thread",
        sys::thread_resume(w.id),
    );
    expect(
        "a resumed thread runs again",
        wait_until(WAIT, || count() > c1),
    );
    expect_ok(
        "thread_set Priority of a running thread",
        sys::thread_set(Some(w.id), ThreadAttribute::Priority, LOW as u64 - 1),
    );
    let before = must("rp_info", sys::rp_info(0));
    expect_ok("thread_kill of a running thread", sys::thread_kill(w.id));
    let c2 = count();
    sys::sleep(5 * MS);
    expect_eq("a killed thread does not run", count(), c2);
    let after = must("rp_info", sys::rp_info(0));
    expect_eq(
        "thread_kill returns the thread to the partition's quota",
        after.threads_used + 1,
        before.threads_used,
    );
    expect_err(
        "thread_start of a killed thread is NoSuchObject",
        sys::thread_start(w.id),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_suspend of a killed thread is NoSuchObject",
        sys::thread_suspend(w.id),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_resume of a killed thread is NoSuchObject",
        sys::thread_resume(w.id),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_kill of a killed thread is NoSuchObject",
        sys::thread_kill(w.id),
        Error::NoSuchObject,
    );
    expect_err(
        "thread_set of a killed thread is NoSuchObject",
        sys::thread_set(Some(w.id), ThreadAttribute::Priority, 1),
        Error::NoSuchObject,
    );
    must("task_kill of the counter task", sys::task_kill(task));
}

worker!(
    /// Notes that it ran.
    fn flag(b, ipc) {
        b.set_result(0, 1);
    }
);

worker!(
    /// Takes a ticket from the shared counter at arg 0 and records it.
    fn ticket(b, ipc) {
        // SAFETY: arg 0 is a word of memory the root shares with this (root-task) thread,
        // mapped for good and used only atomically.
        let counter = unsafe { &words_at(b.arg(0), 1)[0] };
        let n = counter.fetch_add(1, Ordering::AcqRel) + 1;
        b.set_result(0, n);
    }
);

fn scheduling(lab: &mut Lab) {
    let f = lab.worker(None, flag, LOW, &[]);
    f.start();
    busy_wait(3 * MS);
    expect(
        "a ready lower-priority thread does not run while the root computes",
        f.block.result(0) == 0,
    );
    expect_ok(
        "thread_set Priority of a root-task thread above the root's",
        sys::thread_set(
            Some(f.id),
            ThreadAttribute::Priority,
            ROOT_PRIORITY as u64 + 10,
        ),
    );
    sys::yield_now();
    expect(
        "a thread raised above the root runs before the root continues",
        f.block.result(0) == 1,
    );

    let counter = lab.shared(None, 1);
    let a = lab.worker(None, ticket, ROOT_PRIORITY, &[counter]);
    let b = lab.worker(None, ticket, ROOT_PRIORITY, &[counter]);
    a.start();
    b.start();
    expect(
        "started threads of the root's priority wait while the root runs",
        a.block.result(0) == 0 && b.block.result(0) == 0,
    );
    sys::yield_now();
    expect_eq(
        "yield runs the other threads of the same priority first, in FIFO order",
        (a.block.result(0), b.block.result(0)),
        (1, 2),
    );
}

worker!(
    /// Calls thread arg 0 and reports the outcome.
    fn caller(b, ipc) {
        let r = sys::ipc_call(
            ThreadId(b.arg(0)),
            2 * WAIT,
            &sys::Message::new(1, [0; 3]),
        );
        b.set_code(0, &r);
    }
);

worker!(
    /// Receives one message, then never replies.
    fn silent(b, ipc) {
        b.set_code(0, &sys::receive(None, WAIT));
        b.set_step(1);
        loop {
            let _ = sys::notify_wait(0, user_rt::abi::syscall::TIMEOUT_INFINITE);
        }
    }
);

fn kill_returns_quota(lab: &mut Lab) {
    let before = must("rp_info", sys::rp_info(0));
    let doomed = lab.task("t-doomed", BASIC, CHILD_MCP);
    let mut threads = [ThreadId(0); 3];
    for t in threads.iter_mut() {
        // Threads with their stacks in the doomed task only: nothing is mapped into the
        // root between the snapshots, so the root partition's use changes only by what the
        // doomed task costs.
        *t = must(
            "setup: thread in the doomed task",
            lab.spawner.thread(Some(doomed), sleeper, LOW, 0, 2),
        )
        .id;
        must("thread_start", sys::thread_start(*t));
    }
    let during = must("rp_info", sys::rp_info(0));
    expect_eq(
        "a child task and its threads are charged to its partition (tasks, threads)",
        (during.tasks_used, during.threads_used),
        (before.tasks_used + 1, before.threads_used + 3),
    );
    expect(
        "a child task's page tables are charged to its partition (pages)",
        during.pages_used > before.pages_used,
    );
    expect_ok(
        "task_kill of a child task with threads",
        sys::task_kill(doomed),
    );
    let after = must("rp_info", sys::rp_info(0));
    expect_eq(
        "task_kill returns the task's pages, threads and task to the partition",
        (after.pages_used, after.threads_used, after.tasks_used),
        (before.pages_used, before.threads_used, before.tasks_used),
    );
    expect_err(
        "thread ids of a killed task are stale",
        sys::thread_suspend(threads[1]),
        Error::NoSuchObject,
    );
    expect_err(
        "task_kill of a killed task is NoSuchObject",
        sys::task_kill(doomed),
        Error::NoSuchObject,
    );
}

fn kill_wakes_callers(lab: &mut Lab) {
    let task = lab.task("t-callee", BASIC, CHILD_MCP);
    let k = lab.worker(Some(task), silent, LOW, &[]);
    let h = lab.worker(None, caller, 150, &[k.id.0]);
    k.start();
    h.start();
    // Once the callee received the call, the caller waits for the reply.
    k.wait_step(1, "callee received the call");
    expect(
        "a caller waits for the reply of a thread that received its call",
        status(k.block.result(0)).is_ok() && !h.block.is_done(),
    );
    expect_ok("task_kill of the callee's task", sys::task_kill(task));
    h.wait_done("caller into the killed task");
    expect_err(
        "a thread calling into a killed task gets PeerGone",
        status(h.block.result(0)),
        Error::PeerGone,
    );
}
