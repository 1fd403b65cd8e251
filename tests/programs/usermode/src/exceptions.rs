//! Modes `exceptions` and `no-handler`: CPU exceptions and forwarded system calls as IPC.
//!
//! `exceptions`: a child thread whose handler is the root's main thread raises #UD, #PF,
//! #BP and #DE; the root checks each [`ExceptionMessage`] (vector, rip, fault address,
//! registers), edits registers and resumes the thread, which sees the edits. Also: rflags
//! sanitising, `REPLY_RESUME` without data (the thread retries the instruction),
//! `REPLY_KILL`, a handler thread in the faulting thread's own task, a `syscall` of a task
//! without `NATIVE_SYSCALLS` emulated by its handler, and a fault of a thread without
//! handler reported to the health monitor (`LABEL_FAULT_REPORT`).
//!
//! `no-handler`: a child thread faults with neither a handler nor a health monitor; the
//! kernel logs the fault and kills the thread, and the root goes on.

use crate::check::{expect, expect_eq, expect_err, expect_ok, fail, must};
use crate::child::{BASIC, BOGUS_ID, CHILD_MCP, LOW, Lab, MS, WAIT, Worker, worker};
use user_rt::abi::ipc::{
    EXCEPTION_MESSAGE_SIZE, ExceptionMessage, LABEL_EXCEPTION, LABEL_FAULT_REPORT, LABEL_SYSCALL,
    MessageTag, REPLY_KILL, REPLY_RESUME, VECTOR_SYSCALL,
};
use user_rt::abi::syscall::{Abilities, Call, Error, ThreadAttribute, ThreadId};
use user_rt::println;
use user_rt::sys::{self, Message};

// Fault routines. Each is an `extern "C"` function; labels mark the faulting instruction
// and where a handler resumes it. Register use: argument in rdi, result in rax.
core::arch::global_asm!(
    ".pushsection .text.warden_faults, \"ax\", @progbits",
    // u64 fault_ud2(u64 x): rax = x; ud2; return rax.
    ".globl wt_ud2",
    "wt_ud2:",
    "    mov rax, rdi",
    ".globl wt_ud2_insn",
    "wt_ud2_insn:",
    "    ud2",
    ".globl wt_ud2_resume",
    "wt_ud2_resume:",
    "    ret",
    // u64 wt_pf(u64 address): rax = *address (faults if unmapped).
    ".globl wt_pf",
    "wt_pf:",
    ".globl wt_pf_insn",
    "wt_pf_insn:",
    "    mov rax, qword ptr [rdi]",
    ".globl wt_pf_resume",
    "wt_pf_resume:",
    "    ret",
    // u64 wt_int3(u64 x): rax = x; int3 (a trap: rip after it); return rax.
    ".globl wt_int3",
    "wt_int3:",
    "    mov rax, rdi",
    "    int3",
    ".globl wt_int3_after",
    "wt_int3_after:",
    "    ret",
    // u64 wt_div0(u64 x): x / 0.
    ".globl wt_div0",
    "wt_div0:",
    "    mov rax, rdi",
    "    xor edx, edx",
    "    xor ecx, ecx",
    ".globl wt_div0_insn",
    "wt_div0_insn:",
    "    div rcx",
    ".globl wt_div0_resume",
    "wt_div0_resume:",
    "    ret",
    // u64 wt_flags(void): ud2, then return rflags as the thread sees them.
    ".globl wt_flags",
    "wt_flags:",
    ".globl wt_flags_insn",
    "wt_flags_insn:",
    "    ud2",
    "    pushfq",
    "    pop rax",
    "    ret",
    // u64 wt_syscall(u64 number, u64 arg, u64 *rdi_out): syscall with rax = number,
    // rdi = arg; stores rdi after it, returns rax.
    ".globl wt_syscall",
    "wt_syscall:",
    "    push rdx",
    "    mov rax, rdi",
    "    mov rdi, rsi",
    ".globl wt_syscall_insn",
    "wt_syscall_insn:",
    "    syscall",
    ".globl wt_syscall_after",
    "wt_syscall_after:",
    "    pop rdx",
    "    mov qword ptr [rdx], rdi",
    "    ret",
    ".popsection",
);

unsafe extern "C" {
    fn wt_ud2(x: u64) -> u64;
    fn wt_ud2_insn();
    fn wt_ud2_resume();
    fn wt_pf(address: u64) -> u64;
    fn wt_pf_insn();
    fn wt_pf_resume();
    fn wt_int3(x: u64) -> u64;
    fn wt_int3_after();
    fn wt_div0(x: u64) -> u64;
    fn wt_div0_insn();
    fn wt_div0_resume();
    fn wt_flags() -> u64;
    fn wt_flags_insn();
    fn wt_syscall(number: u64, arg: u64, rdi_out: *mut u64) -> u64;
    fn wt_syscall_after();
}

fn label(f: unsafe extern "C" fn()) -> u64 {
    f as *const () as usize as u64
}

/// An unmapped user address (nothing maps it in any task).
const UNMAPPED: u64 = 0x0000_0dea_d000;
const RFLAGS_CF: u64 = 1;
const RFLAGS_IF: u64 = 1 << 9;
const RFLAGS_IOPL: u64 = 3 << 12;

const MAGIC_UD: u64 = 0x0d0d_0001;
const MAGIC_PF: u64 = 0x0e0e_0002;
const MAGIC_BP: u64 = 0x0303_0003;
const MAGIC_DE: u64 = 0x0000_0004;
const MAGIC_RETRY: u64 = 0x0d0d_0005;

// Results of `faulter`.
const F_UD: usize = 0;
const F_PF: usize = 1;
const F_BP: usize = 2;
const F_DE: usize = 3;
const F_FLAGS: usize = 4;
const F_RETRY: usize = 5;
const F_AFTER_KILL: usize = 6;

worker!(
    /// Raises one exception after the other; the root handles each.
    fn faulter(b, ipc) {
        // Each routine touches only registers, the stack and the (unmapped, faulting)
        // address given; the handler resumes it at its label.
        // SAFETY: see above (#UD, resumed after the instruction).
        b.set_result(F_UD, unsafe { wt_ud2(0x1111) });
        b.set_step(1);
        // SAFETY: see above (#PF on an unmapped address, resumed after it).
        b.set_result(F_PF, unsafe { wt_pf(UNMAPPED) });
        b.set_step(2);
        // SAFETY: see above (#BP, resumed after int3).
        b.set_result(F_BP, unsafe { wt_int3(0x3333) });
        b.set_step(3);
        // SAFETY: see above (#DE, resumed after the division).
        b.set_result(F_DE, unsafe { wt_div0(7) });
        b.set_step(4);
        // SAFETY: see above (reads and returns the flags).
        b.set_result(F_FLAGS, unsafe { wt_flags() });
        b.set_step(5);
        // SAFETY: see above (#UD again, retried by the handler).
        b.set_result(F_RETRY, unsafe { wt_ud2(0x5555) });
        b.set_step(6);
        b.finish();
        // The handler kills the thread here.
        // SAFETY: see above.
        unsafe { wt_ud2(0x6666) };
        b.set_result(F_AFTER_KILL, 1);
    }
);

/// Receives the next exception message from `from` and returns it (from the IPC buffer).
pub(crate) fn next_exception(
    lab: &Lab,
    from: ThreadId,
    what: &str,
    label: u32,
) -> ExceptionMessage {
    let m = expect_ok(what, sys::receive(Some(from), WAIT));
    let tag = m.message.tag;
    if (m.sender, tag.label(), tag.len()) != (from, label, EXCEPTION_MESSAGE_SIZE) {
        fail(
            what,
            format_args!(
                ": got sender {:#x} label {:#x} length {}, expected {:#x} {label:#x} {}",
                m.sender.0,
                tag.label(),
                tag.len(),
                from.0,
                EXCEPTION_MESSAGE_SIZE
            ),
        );
    }
    lab.ipc.exception()
}

/// Replies `REPLY_RESUME` with the (edited) registers of `m`.
fn resume_with(lab: &Lab, thread: ThreadId, m: &ExceptionMessage) {
    lab.ipc.set_exception(m);
    must(
        "reply REPLY_RESUME with edited registers",
        sys::reply(
            thread,
            &Message {
                tag: MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0),
                words: [0; 3],
            },
        ),
    );
}

pub(crate) fn reply_plain(thread: ThreadId, label: u32) -> Result<(), Error> {
    sys::reply(
        thread,
        &Message {
            tag: MessageTag::new(label, 0, 0),
            words: [0; 3],
        },
    )
}

pub fn run() {
    let mut lab = Lab::new();
    round_trips(&mut lab);
    handler_in_own_task(&mut lab);
    forwarded_syscall(&mut lab);
    health_monitor(&mut lab);
    println!("all exceptions checks passed");
    let _ = sys::system_halt(true);
}

fn round_trips(lab: &mut Lab) {
    let task = lab.task("x-faulter", BASIC, CHILD_MCP);
    let f = lab.worker(Some(task), faulter, LOW, &[]);
    expect_ok(
        "thread_set ExceptionHandler to a thread of an ancestor task",
        sys::thread_set(Some(f.id), ThreadAttribute::ExceptionHandler, lab.me.0),
    );
    f.start();

    let mut m = next_exception(
        lab,
        f.id,
        "#UD arrives as an exception message",
        LABEL_EXCEPTION,
    );
    expect_eq(
        "the #UD message names vector 6, the ud2 instruction, the thread and its task",
        (m.vector, m.registers.rip, m.thread, m.task),
        (6, label(wt_ud2_insn), f.id.0, task.0),
    );
    expect_eq(
        "the #UD message carries the thread's registers",
        (m.registers.rax, m.registers.rdi),
        (0x1111, 0x1111),
    );
    m.registers.rax = MAGIC_UD;
    m.registers.rip = label(wt_ud2_resume);
    resume_with(lab, f.id, &m);

    let mut m = next_exception(
        lab,
        f.id,
        "#PF arrives as an exception message",
        LABEL_EXCEPTION,
    );
    // Error code: not present (bit 0 clear), read (bit 1 clear), user (bit 2).
    expect_eq(
        "the #PF message names vector 14, the faulting load, the address and a user read",
        (m.vector, m.registers.rip, m.fault_address, m.error_code & 7),
        (14, label(wt_pf_insn), UNMAPPED, 4),
    );
    m.registers.rax = MAGIC_PF;
    m.registers.rip = label(wt_pf_resume);
    resume_with(lab, f.id, &m);

    let mut m = next_exception(
        lab,
        f.id,
        "#BP arrives as an exception message",
        LABEL_EXCEPTION,
    );
    expect_eq(
        "the #BP message names vector 3 and rip after the int3",
        (m.vector, m.registers.rip, m.registers.rax),
        (3, label(wt_int3_after), 0x3333),
    );
    m.registers.rax = MAGIC_BP;
    resume_with(lab, f.id, &m);

    let mut m = next_exception(
        lab,
        f.id,
        "#DE arrives as an exception message",
        LABEL_EXCEPTION,
    );
    expect_eq(
        "the #DE message names vector 0 and the div instruction",
        (m.vector, m.registers.rip, m.registers.rax),
        (0, label(wt_div0_insn), 7),
    );
    m.registers.rax = MAGIC_DE;
    m.registers.rip = label(wt_div0_resume);
    resume_with(lab, f.id, &m);

    let mut m = next_exception(lab, f.id, "#UD of the flags test", LABEL_EXCEPTION);
    expect_eq(
        "the flags test faults at its ud2",
        (m.vector, m.registers.rip),
        (6, label(wt_flags_insn)),
    );
    expect(
        "a user thread's rflags in the message have IF set and IOPL 0",
        m.registers.rflags & RFLAGS_IF != 0 && m.registers.rflags & RFLAGS_IOPL == 0,
    );
    m.registers.rflags = (m.registers.rflags | RFLAGS_CF | RFLAGS_IOPL) & !RFLAGS_IF;
    m.registers.rip += 2;
    resume_with(lab, f.id, &m);

    let m = next_exception(lab, f.id, "#UD of the retry test", LABEL_EXCEPTION);
    expect_eq(
        "the retry test faults at the ud2",
        m.registers.rip,
        label(wt_ud2_insn),
    );
    expect_ok(
        "reply REPLY_RESUME without data",
        reply_plain(f.id, REPLY_RESUME),
    );
    let mut again = next_exception(
        lab,
        f.id,
        "REPLY_RESUME without data resumes unchanged: the ud2 faults again",
        LABEL_EXCEPTION,
    );
    expect_eq(
        "the repeated fault has the same rip and registers",
        (again.vector, again.registers.rip, again.registers.rax),
        (6, m.registers.rip, 0x5555),
    );
    again.registers.rax = MAGIC_RETRY;
    again.registers.rip = label(wt_ud2_resume);
    resume_with(lab, f.id, &again);

    f.wait_done("faulting thread");
    let r = |i| f.block.result(i);
    expect_eq(
        "the thread resumed after #UD with the handler's rax",
        r(F_UD),
        MAGIC_UD,
    );
    expect_eq(
        "the thread resumed after #PF with the handler's rax",
        r(F_PF),
        MAGIC_PF,
    );
    expect_eq(
        "the thread resumed after #BP with the handler's rax",
        r(F_BP),
        MAGIC_BP,
    );
    expect_eq(
        "the thread resumed after #DE with the handler's rax and rip",
        r(F_DE),
        MAGIC_DE,
    );
    expect(
        "a handler may set CF but not clear IF or raise IOPL",
        r(F_FLAGS) & RFLAGS_CF != 0 && r(F_FLAGS) & RFLAGS_IF != 0 && r(F_FLAGS) & RFLAGS_IOPL == 0,
    );
    expect_eq(
        "the thread resumed after the retried #UD with the handler's rax",
        r(F_RETRY),
        MAGIC_RETRY,
    );

    next_exception(lab, f.id, "the last #UD arrives", LABEL_EXCEPTION);
    expect_ok("reply REPLY_KILL", reply_plain(f.id, REPLY_KILL));
    sys::sleep(5 * MS);
    expect_eq(
        "a thread whose handler replied REPLY_KILL does not continue",
        r(F_AFTER_KILL),
        0,
    );
    expect_err(
        "a thread whose handler replied REPLY_KILL is gone",
        sys::thread_kill(f.id),
        Error::NoSuchObject,
    );
    must("task_kill", sys::task_kill(task));
}

worker!(
    /// Faults once (#UD with rdi 1) and reports the returned rax.
    fn faults_once(b, ipc) {
        // SAFETY: wt_ud2 touches only registers; its handler resumes it.
        b.set_result(0, unsafe { wt_ud2(1) });
    }
);

worker!(
    /// Handles one exception of thread arg 0: records vector and rip, sets rax to 0x77 and
    /// rip past the 2-byte instruction, resumes.
    fn local_handler(b, ipc) {
        let r = sys::receive(Some(ThreadId(b.arg(0))), WAIT);
        b.set_code(0, &r);
        if let Ok(m) = r {
            b.set_result(1, m.message.tag.label() as u64);
            let mut e = ipc.exception();
            b.set_result(2, e.vector);
            b.set_result(3, e.registers.rip);
            e.registers.rax = 0x77;
            e.registers.rip += 2;
            ipc.set_exception(&e);
            b.set_code(
                4,
                &sys::reply(
                    m.sender,
                    &Message {
                        tag: MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0),
                        words: [0; 3],
                    },
                ),
            );
        }
    }
);

fn handler_in_own_task(lab: &mut Lab) {
    let task = lab.task("x-local", BASIC, CHILD_MCP);
    let f = lab.worker(Some(task), faults_once, LOW, &[]);
    let h = lab.worker(Some(task), local_handler, LOW + 1, &[f.id.0]);
    expect_ok(
        "thread_set ExceptionHandler to a thread of the same task",
        sys::thread_set(Some(f.id), ThreadAttribute::ExceptionHandler, h.id.0),
    );
    h.start();
    f.start();
    h.wait_done("handler in the faulting thread's task");
    f.wait_done("thread with a handler in its own task");
    expect_eq(
        "a handler in the same task gets the exception message",
        (
            h.block.result(0),
            h.block.result(1),
            h.block.result(2),
            h.block.result(3),
        ),
        (0, LABEL_EXCEPTION as u64, 6, label(wt_ud2_insn)),
    );
    expect_eq(
        "its REPLY_RESUME succeeds and the thread continues with its edits",
        (h.block.result(4), f.block.result(0)),
        (0, 0x77),
    );
    must("task_kill", sys::task_kill(task));
}

/// An emulated call number (nothing the kernel knows).
const EMULATED_CALL: u64 = 0x1234;

worker!(
    /// In a task without NATIVE_SYSCALLS: every `syscall` goes to the handler.
    fn guest(b, ipc) {
        let mut rdi = 0;
        // SAFETY: wt_syscall only uses registers, the stack and `rdi`; the handler emulates
        // the call and resumes after it.
        let rax = unsafe { wt_syscall(EMULATED_CALL, 21, &mut rdi) };
        b.set_result(0, rax);
        b.set_result(1, rdi);
        b.finish();
        // thread_exit is forwarded too; the handler kills the thread.
        let mut ignored = 0;
        // SAFETY: as above.
        unsafe { wt_syscall(Call::ThreadExit as u64, 0, &mut ignored) };
        b.set_result(2, 1);
    }
);

fn forwarded_syscall(lab: &mut Lab) {
    let task = lab.task("x-guest", Abilities::DEBUG_LOG, CHILD_MCP);
    let g = lab.worker(Some(task), guest, LOW, &[]);
    must(
        "thread_set ExceptionHandler",
        sys::thread_set(Some(g.id), ThreadAttribute::ExceptionHandler, lab.me.0),
    );
    g.start();
    let mut m = next_exception(
        lab,
        g.id,
        "a syscall without NATIVE_SYSCALLS arrives at the handler as LABEL_SYSCALL",
        LABEL_SYSCALL,
    );
    expect_eq(
        "the forwarded syscall has vector VECTOR_SYSCALL, the call registers and rip after the instruction",
        (m.vector, m.registers.rax, m.registers.rdi, m.registers.rip),
        (VECTOR_SYSCALL, EMULATED_CALL, 21, label(wt_syscall_after)),
    );
    m.registers.rax = 42;
    m.registers.rdi = 43;
    resume_with(lab, g.id, &m);
    let m = next_exception(
        lab,
        g.id,
        "the guest's thread_exit is forwarded too",
        LABEL_SYSCALL,
    );
    expect_eq(
        "the forwarded thread_exit carries its call number",
        m.registers.rax,
        Call::ThreadExit as u64,
    );
    expect_ok(
        "reply REPLY_KILL to a forwarded syscall",
        reply_plain(g.id, REPLY_KILL),
    );
    g.wait_done("guest thread");
    expect_eq(
        "the emulated syscall returned the handler's rax and rdi",
        (g.block.result(0), g.block.result(1)),
        (42, 43),
    );
    sys::sleep(5 * MS);
    expect_eq(
        "the killed guest thread did not continue",
        g.block.result(2),
        0,
    );
    must("task_kill", sys::task_kill(task));
}

worker!(
    /// Reads an unmapped address (no handler).
    fn stray(b, ipc) {
        b.set_step(1);
        // SAFETY: wt_pf only loads from the given (unmapped) address, which faults.
        let v = unsafe { wt_pf(UNMAPPED) };
        b.set_result(0, v | 1);
    }
);

fn health_monitor(lab: &mut Lab) {
    let task = lab.task("x-stray", BASIC, CHILD_MCP);
    let x = lab.worker(Some(task), stray, LOW, &[]);
    expect_err(
        "set_health_monitor of a nonexistent thread is NoSuchObject",
        sys::set_health_monitor(ThreadId(BOGUS_ID)),
        Error::NoSuchObject,
    );
    expect_err(
        "set_health_monitor of a child task's thread is NotPermitted",
        sys::set_health_monitor(x.id),
        Error::NotPermitted,
    );
    expect_ok(
        "set_health_monitor of the root's main thread",
        sys::set_health_monitor(lab.me),
    );
    x.start();
    let m = next_exception(
        lab,
        x.id,
        "a fault of a thread without handler reaches the health monitor as LABEL_FAULT_REPORT",
        LABEL_FAULT_REPORT,
    );
    expect_eq(
        "the fault report names the #PF, the address, the thread and its task",
        (m.vector, m.fault_address, m.thread, m.task),
        (14, UNMAPPED, x.id.0, task.0),
    );
    expect_ok(
        "reply REPLY_KILL to a fault report",
        reply_plain(x.id, REPLY_KILL),
    );
    sys::sleep(5 * MS);
    expect_eq("the reported thread did not continue", x.block.result(0), 0);
    expect_err(
        "the reported thread is gone",
        sys::thread_kill(x.id),
        Error::NoSuchObject,
    );
    must("task_kill", sys::task_kill(task));
}

/// Mode `no-handler`.
pub fn run_no_handler() {
    let mut lab = Lab::new();
    let task = lab.task("x-orphan", BASIC, CHILD_MCP);
    let x: Worker = lab.worker(Some(task), orphan, LOW, &[]);
    x.start();
    x.wait_step(1, "orphan thread started");
    sys::sleep(20 * MS);
    expect_eq(
        "a thread faulting without handler or health monitor does not continue",
        x.block.result(0),
        0,
    );
    expect_err(
        "the kernel killed the thread that faulted without handler or health monitor",
        sys::thread_kill(x.id),
        Error::NoSuchObject,
    );
    let y = lab.worker(Some(task), crate::child::park, LOW, &[]);
    expect_eq(
        "its task lives on (a new thread can be created and started in it)",
        sys::thread_start(y.id),
        Ok(()),
    );
    expect_ok("task_kill of the orphan's task", sys::task_kill(task));
    println!("all no-handler checks passed");
    let _ = sys::system_halt(true);
}

worker!(
    /// Executes ud2 with no handler and no health monitor.
    fn orphan(b, ipc) {
        b.set_step(1);
        // SAFETY: wt_ud2 touches only registers; it faults and never returns here.
        let v = unsafe { wt_ud2(9) };
        b.set_result(0, v | 1);
    }
);
