//! Kernel object scenarios: the root task (`tests/programs/usermode`, mode from the system
//! image entry `test/mode`) exercises tasks, threads, resource partitions, memory mapping,
//! IPC and exceptions, printing `check ok: ...` per check and `all <mode> checks passed`.

use scenarios::{check, passes};

#[test]
fn kernel_tasks() {
    passes(
        "kernel_tasks",
        "tasks",
        &[
            "task_create with a 16-byte name is InvalidArgument",
            "task_kill of the caller's own task is NotPermitted",
            "thread_create above the task's MCP is McpExceeded",
            "thread_set Priority above the task's MCP is McpExceeded",
            "thread_create without CREATE_THREAD is AbilityDenied",
            "task_create with abilities beyond the caller's is AbilityDenied",
            "task_create with an MCP above the caller's is McpExceeded",
            "task_kill of an ancestor is NotPermitted",
            "task_kill of a sibling is NotPermitted",
            "thread_set of the own Priority above the MCP is McpExceeded",
            "thread_self in a child names the ids its creator got",
            "task_kill also destroyed the grandchild",
            "an inactive (never started) thread does not run",
            "a started lower-priority thread runs while the root sleeps",
            "thread_start of a started thread is InvalidArgument",
            "a suspended thread does not run",
            "a resumed thread runs again",
            "a killed thread does not run",
            "thread_kill returns the thread to the partition's quota",
            "thread_start of a killed thread is NoSuchObject",
            "a ready lower-priority thread does not run while the root computes",
            "a thread raised above the root runs before the root continues",
            "yield runs the other threads of the same priority first, in FIFO order",
            "task_kill returns the task's pages, threads and task to the partition",
            "a caller waits for the reply of a thread that received its call",
            "a thread calling into a killed task gets PeerGone",
        ],
    );
}

#[test]
fn kernel_quota() {
    passes(
        "kernel_quota",
        "quota",
        &[
            "the root partition's quota is the one RootInfo announces",
            "rp_create with more pages than the caller's free quota is QuotaExceeded",
            "carving partitions reduces the root's free quota",
            "a new partition has the requested quota and nothing used",
            "thread_create beyond partition A's thread quota is QuotaExceeded",
            "partition A held exactly its quota of threads",
            "map into a task whose partition has no pages left is QuotaExceeded",
            "partition A's pages are all used",
            "a failed map changes nothing in the partition",
            "task_create in an exhausted partition is QuotaExceeded",
            "a task in partition B runs while partition A is exhausted",
            "thread_create in partition B while A is exhausted",
            "map into partition B's task while A is exhausted",
            "rp_create without PARTITION_CONTROL is AbilityDenied",
            "task_create in a partition the caller did not create is NotPermitted",
            "killing the task returns all of partition A's quota",
        ],
    );
}

#[test]
fn kernel_memory() {
    passes(
        "kernel_memory",
        "memory",
        &[
            "map_physical of two frames of RootInfo memory",
            "data written through one mapping is visible through the second",
            "map_physical onto a mapped page is AlreadyMapped",
            "a map that fails maps nothing (its first page stays unmapped)",
            "map from an unmapped source page is BadAddress",
            "unmapped pages are gone",
            "map with an unaligned source is InvalidArgument",
            "map of zero pages is InvalidArgument",
            "map of more than MAP_MAX_PAGES pages is InvalidArgument",
            "map to a kernel address is InvalidArgument",
            "map_physical of exactly MAP_MAX_PAGES pages",
            "map_physical of a frame outside RootInfo memory is BadAddress",
            "map with WRITE from a read-only page (RootInfo) is BadAddress",
            "a page protected read-only cannot be mapped writable any more",
            "protect cannot add rights (the page stays read-only)",
            "protect of an unmapped page is BadAddress",
            "map without the MAP ability is AbilityDenied",
            "map into an ancestor task is NotPermitted",
            "a child reads what the root wrote to a shared page",
            "the root reads what the child wrote to a shared page",
            "it is a page fault on that page: user write to a present page",
            "the faulting write did not happen and the thread did not continue",
        ],
    );
}

#[test]
fn kernel_ipc() {
    passes(
        "kernel_ipc",
        "ipc",
        &[
            "call to a server thread in a child task",
            "the reply comes from the server with its label and words",
            "a second call is served by the reply_wait loop",
            "the server received all 4096 data bytes intact",
            "the reply's 4096 data bytes arrived intact",
            "a map item shares the page: the receiver reads the sender's data",
            "the receiver sees the sender's later writes to the shared page",
            "a grant item moves the page: the receiver reads its data",
            "a grant item unmaps the page from the sender",
            "receive with timeout 0 and no sender is TimedOut",
            "receive with a 20 ms timeout waited at least 20 ms",
            "call with a 20 ms timeout waited at least 20 ms",
            "receive with an infinite timeout gets a message sent 20 ms later",
            "the receiver got the sender, the label and the words",
            "receive from one thread takes its message, not the first queued",
            "senders are received highest priority first, FIFO within a priority",
            "reply to a thread that is not calling is NotWaiting",
            "a caller waiting for a killed thread's reply gets PeerGone",
            "receive of a data message without an IPC buffer is BadAddress",
            "send to a sibling task's thread is NotPermitted by default",
            "after task_allow_send the sibling's send succeeds",
            "the reverse direction stays NotPermitted (send)",
            "notify_wait returns the signalled bits of its mask",
            "notify_wait with a 10 ms timeout waited at least 10 ms",
            "a waiting thread wakes with the signalled bits of its mask",
        ],
    );
}

#[test]
fn kernel_exceptions() {
    passes(
        "kernel_exceptions",
        "exceptions",
        &[
            "the #UD message names vector 6, the ud2 instruction, the thread and its task",
            "the #PF message names vector 14, the faulting load, the address and a user read",
            "the #BP message names vector 3 and rip after the int3",
            "the #DE message names vector 0 and the div instruction",
            "the thread resumed after #UD with the handler's rax",
            "the thread resumed after #PF with the handler's rax",
            "a handler may set CF but not clear IF or raise IOPL",
            "the repeated fault has the same rip and registers",
            "a thread whose handler replied REPLY_KILL is gone",
            "a handler in the same task gets the exception message",
            "the forwarded syscall has vector VECTOR_SYSCALL, the call registers and rip after the instruction",
            "the emulated syscall returned the handler's rax and rdi",
            "set_health_monitor of a child task's thread is NotPermitted",
            "the fault report names the #PF, the address, the thread and its task",
            "the reported thread is gone",
        ],
    );
}

#[test]
fn kernel_no_handler() {
    let o = passes(
        "kernel_no_handler",
        "no-handler",
        &[
            "a thread faulting without handler or health monitor does not continue",
            "the kernel killed the thread that faulted without handler or health monitor",
            "its task lives on (a new thread can be created and started in it)",
        ],
    );
    check(
        &o,
        o.lines
            .iter()
            .any(|l| l.contains("EXCEPTION #UD") && l.contains("task x-orphan")),
        "the kernel must log the unhandled #UD of task x-orphan",
    );
    check(
        &o,
        o.lines.iter().any(|l| {
            l.contains("of task x-orphan killed (no exception handler, no health monitor)")
        }),
        "the kernel must log that it killed the thread",
    );
}
