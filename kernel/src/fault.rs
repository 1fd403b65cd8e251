//! User faults: every CPU exception of a user thread (and every `syscall` of a task without
//! `NATIVE_SYSCALLS`) becomes an exception message to the thread's handler, or a fault
//! report to the root task's health monitor. With neither, the kernel logs the fault and
//! kills the thread; a fault of the root task itself then stops the system, since nobody
//! is left to decide.

use crate::arch::idt::exception_name;
use crate::kprintln;
use crate::state::Kernel;
use crate::syscall::Outcome;
use crate::table::{TaskIdx, ThreadIdx};
use crate::thread::Fault;
use abi::ipc::LABEL_EXCEPTION;

/// CPU exception `vector` of user thread `t` (registers saved in its context).
pub fn on_exception(
    k: &mut Kernel,
    t: ThreadIdx,
    vector: u64,
    error_code: u64,
    cr2: u64,
) -> Outcome {
    let fault = Fault {
        label: LABEL_EXCEPTION,
        vector,
        error_code,
        address: if vector == 14 { cr2 } else { 0 },
    };
    deliver_or_report(k, t, fault)
}

pub fn deliver_or_report(k: &mut Kernel, t: ThreadIdx, fault: Fault) -> Outcome {
    if k.raise_fault(t, fault) {
        return Outcome::Continue;
    }
    let task = k.threads[t].task();
    log_fault(k, t, &fault);
    if task == TaskIdx::ROOT {
        kprintln!("kernel: the root task faulted without a handler; halting with failure");
        return Outcome::Halt { success: false };
    }
    kprintln!(
        "kernel: thread {:#x} of task {} killed (no exception handler, no health monitor)",
        k.thread_id(t).0,
        k.tasks[task].name()
    );
    k.kill_thread(t);
    Outcome::Continue
}

fn log_fault(k: &Kernel, t: ThreadIdx, fault: &Fault) {
    let c = k.threads[t].context();
    let (mnemonic, description) = if fault.vector == abi::ipc::VECTOR_SYSCALL {
        ("SYSCALL", "forwarded system call")
    } else {
        exception_name(fault.vector)
    };
    kprintln!(
        "EXCEPTION {mnemonic} ({description}, vector {}) error={:#x} in user mode, task {}",
        fault.vector,
        fault.error_code,
        k.tasks[k.threads[t].task()].name()
    );
    kprintln!(
        "  rip={:#018x} rsp={:#018x} cr2={:#018x} rflags={:#x}",
        c.rip,
        c.rsp,
        fault.address,
        c.rflags
    );
    crate::arch::idt::log_registers(c);
}
