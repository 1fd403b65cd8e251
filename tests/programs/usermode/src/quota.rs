//! Mode `quota`: resource partitions. Two partitions A and B carved out of the root's; A's
//! thread and page quotas are exhausted (`thread_create` / `map` until `QuotaExceeded`)
//! while B keeps creating threads, mapping pages and running; killing A's task returns
//! everything; `rp_create` beyond the free quota fails.

use crate::check::{expect, expect_eq, expect_err, expect_ok, must, status};
use crate::child::{BASIC, BOGUS_ID, CHILD_MCP, LOW, Lab, entry_address, sleeper, worker};
use user_rt::abi::syscall::{Abilities, Error, PageRights, TaskId};
use user_rt::{println, sys};

const UNUSED_STACK: u64 = 0x1000_0000;
/// Where pages are mapped into partition A's task to use up its page quota: one page per
/// 2 MiB, so that every map needs a new page table.
const MAP_AREA: u64 = 0x0000_3000_0000_0000;
const TWO_MIB: u64 = 2 << 20;

const A_TASKS: u16 = 2;
const A_THREADS: u16 = 3;
const A_PAGES: u64 = 16;
const B_TASKS: u16 = 2;
const B_THREADS: u16 = 4;
const B_PAGES: u64 = 64;
/// The root task's partition may run on every CPU; so may the partitions it makes here.
const ALL_CPUS: u8 = u8::MAX;

pub fn run() {
    let mut lab = Lab::new();
    let info = root_task::root_info();
    let root = must("rp_info of the root partition", sys::rp_info(0));
    expect_eq(
        "the root partition's quota is the one RootInfo announces",
        (
            root.pages_quota,
            root.threads_quota as u64,
            root.tasks_quota as u64,
        ),
        (info.kernel_pages, info.kernel_threads, info.kernel_tasks),
    );
    expect_err(
        "rp_create with more pages than the caller's free quota is QuotaExceeded",
        sys::rp_create(1, 1, root.pages_quota + 1, ALL_CPUS),
        Error::QuotaExceeded,
    );
    if let Some(threads) = (root.threads_quota - root.threads_used).checked_add(1) {
        expect_err(
            "rp_create with more threads than the caller's free quota is QuotaExceeded",
            sys::rp_create(1, threads, 1, ALL_CPUS),
            Error::QuotaExceeded,
        );
    }
    expect_eq(
        "the root partition may run on every CPU",
        root.cpus,
        ALL_CPUS,
    );
    expect_err(
        "rp_create on no CPU is InvalidArgument",
        sys::rp_create(1, 1, 1, 0),
        Error::InvalidArgument,
    );
    expect_err(
        "rp_info of a nonexistent partition is NoSuchObject",
        sys::rp_info(BOGUS_ID),
        Error::NoSuchObject,
    );

    let a = expect_ok(
        "rp_create of partition A",
        sys::rp_create(A_TASKS, A_THREADS, A_PAGES, ALL_CPUS),
    );
    let b = expect_ok(
        "rp_create of partition B",
        sys::rp_create(B_TASKS, B_THREADS, B_PAGES, ALL_CPUS),
    );
    expect(
        "new partitions have their own numbers",
        a != b && a > 1 && b > 1,
    );
    let ia = must("rp_info(A)", sys::rp_info(a));
    expect_eq(
        "a new partition has the requested quota and nothing used",
        (
            ia.pages_used,
            ia.pages_quota,
            ia.threads_used,
            ia.threads_quota,
            ia.tasks_used,
            ia.tasks_quota,
        ),
        (0, A_PAGES, 0, A_THREADS, 0, A_TASKS),
    );
    // rp_info shows quota and use, not what was carved out: check that the carved pages
    // are gone from the root's free quota by asking for the old free quota minus them, plus
    // one page.
    let free_before = root.pages_quota - root.pages_used;
    expect_err(
        "carving partitions reduces the root's free quota",
        sys::rp_create(0, 0, free_before - A_PAGES - B_PAGES + 1, ALL_CPUS),
        Error::QuotaExceeded,
    );

    // Use up A.
    let ta = expect_ok(
        "task_create in partition A",
        sys::task_create(BASIC, CHILD_MCP, a, "q-a"),
    );
    let ia = must("rp_info(A)", sys::rp_info(a));
    expect_eq(
        "a task costs its partition one task and one page",
        (ia.tasks_used, ia.pages_used),
        (1, 1),
    );
    let park = entry_address(sleeper);
    let mut made = 0;
    let last = loop {
        match sys::thread_create(Some(ta), park, UNUSED_STACK, LOW, 0) {
            Ok(_) if made < 64 => made += 1,
            other => break other,
        }
    };
    expect_err(
        "thread_create beyond partition A's thread quota is QuotaExceeded",
        last,
        Error::QuotaExceeded,
    );
    expect_eq(
        "partition A held exactly its quota of threads",
        made,
        A_THREADS,
    );
    let source = lab.shared(None, 1);
    let mut mapped = 0;
    let last = loop {
        match sys::map(
            Some(ta),
            source,
            MAP_AREA + mapped * TWO_MIB,
            1,
            PageRights::empty(),
        ) {
            Ok(()) if mapped < 512 => mapped += 1,
            other => break other,
        }
    };
    expect_err(
        "map into a task whose partition has no pages left is QuotaExceeded",
        last,
        Error::QuotaExceeded,
    );
    let ia = must("rp_info(A)", sys::rp_info(a));
    expect_eq(
        "partition A's pages are all used",
        ia.pages_used,
        ia.pages_quota,
    );
    expect_err(
        "map into the exhausted partition fails again",
        sys::map(
            Some(ta),
            source,
            MAP_AREA + mapped * TWO_MIB,
            1,
            PageRights::empty(),
        ),
        Error::QuotaExceeded,
    );
    expect_eq(
        "a failed map changes nothing in the partition",
        must("rp_info(A)", sys::rp_info(a)).pages_used,
        ia.pages_used,
    );
    expect_err(
        "task_create in an exhausted partition is QuotaExceeded",
        sys::task_create(BASIC, CHILD_MCP, a, "q-a2"),
        Error::QuotaExceeded,
    );

    // B is not affected.
    let tb = lab.task_in("q-b", BASIC, CHILD_MCP, b);
    let w = lab.worker(Some(tb), b_probe, LOW, &[]);
    w.start();
    w.wait_done("thread in partition B");
    expect(
        "a task in partition B runs while partition A is exhausted",
        w.block.result(B_RAN) == 1,
    );
    expect_err(
        "rp_create without PARTITION_CONTROL is AbilityDenied",
        status(w.block.result(B_RP_CREATE)),
        Error::AbilityDenied,
    );
    expect_eq(
        "rp_info(0) in a child describes the child's own partition",
        (
            status(w.block.result(B_RP_INFO)),
            w.block.result(B_RP_PAGES_QUOTA),
        ),
        (Ok(()), B_PAGES),
    );
    expect_ok(
        "thread_create in partition B while A is exhausted",
        sys::thread_create(Some(tb), park, UNUSED_STACK, LOW, 0),
    );
    expect_ok(
        "map into partition B's task while A is exhausted",
        sys::map(Some(tb), source, MAP_AREA, 1, PageRights::empty()),
    );

    // Partitions are the creator's to hand out.
    let ctl = lab.task(
        "q-ctl",
        BASIC | Abilities::CREATE_TASK | Abilities::PARTITION_CONTROL,
        CHILD_MCP,
    );
    let w = lab.worker(Some(ctl), partition_user, LOW, &[a]);
    w.start();
    w.wait_done("child with PARTITION_CONTROL");
    let r = |i| status(w.block.result(i));
    expect_err(
        "task_create in a partition the caller did not create is NotPermitted",
        r(C_FOREIGN),
        Error::NotPermitted,
    );
    expect_eq(
        "a child with PARTITION_CONTROL carves a partition out of its own",
        r(C_CREATE),
        Ok(()),
    );
    expect_eq(
        "a child creates a task in a partition it created",
        r(C_TASK),
        Ok(()),
    );
    must("task_kill", sys::task_kill(ctl));

    // Killing A's task returns everything.
    expect_ok("task_kill of the task in partition A", sys::task_kill(ta));
    let ia = must("rp_info(A)", sys::rp_info(a));
    expect_eq(
        "killing the task returns all of partition A's quota",
        (ia.pages_used, ia.threads_used, ia.tasks_used),
        (0, 0, 0),
    );
    let again: Result<TaskId, Error> = sys::task_create(BASIC, CHILD_MCP, a, "q-a3");
    expect_ok(
        "task_create in partition A after its quota came back",
        again,
    );
    println!("all quota checks passed");
    let _ = sys::system_halt(true);
}

const B_RAN: usize = 0;
const B_RP_CREATE: usize = 1;
const B_RP_INFO: usize = 2;
const B_RP_PAGES_QUOTA: usize = 3;

worker!(
    /// Runs in partition B (no PARTITION_CONTROL).
    fn b_probe(b, ipc) {
        b.set_result(B_RAN, 1);
        b.set_code(B_RP_CREATE, &sys::rp_create(1, 1, 1, ALL_CPUS));
        let info = sys::rp_info(0);
        b.set_code(B_RP_INFO, &info);
        b.set_result(B_RP_PAGES_QUOTA, info.map_or(0, |i| i.pages_quota));
    }
);

const C_FOREIGN: usize = 0;
const C_CREATE: usize = 1;
const C_TASK: usize = 2;

worker!(
    /// Runs in a child with CREATE_TASK and PARTITION_CONTROL. Arg 0: a partition the root
    /// created.
    fn partition_user(b, ipc) {
        b.set_code(
            C_FOREIGN,
            &sys::task_create(Abilities::DEBUG_LOG, 10, b.arg(0), "foreign"),
        );
        let own = sys::rp_create(1, 1, 4, ALL_CPUS);
        b.set_code(C_CREATE, &own);
        if let Ok(rp) = own {
            let t = sys::task_create(Abilities::DEBUG_LOG, 10, rp, "own");
            b.set_code(C_TASK, &t);
        } else {
            b.set_result(C_TASK, Error::NoSuchObject as u64);
        }
    }
);
