//! User-mode scenarios: the root task runs in ring 3 and talks to the kernel by `syscall`.

use scenarios::{boot, check};
use xtask::qemu::{EXIT_FAILURE, Ending};

#[test]
fn syssw_starts() {
    let o = boot("syssw_starts");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33) once syssw's thread ended",
    );
    check(
        &o,
        o.line("task: root task 'syssw' loaded").is_some(),
        "root task not loaded",
    );
    let started = o
        .line("[syssw] syssw: root task started; system image")
        .unwrap_or_default();
    check(
        &o,
        started.contains("2 entries"),
        "syssw must see syssw and test/hook",
    );
    check(
        &o,
        o.line("syssw: no configuration in the system image; nothing to start")
            .is_some(),
        "syssw must say that it has nothing to start",
    );
    check(
        &o,
        o.line("kernel: thread of task syssw exited").is_some(),
        "thread exit not reported",
    );
}

#[test]
fn user_mode() {
    let o = boot("user_mode");
    check(&o, o.succeeded(), "expected success exit (33)");
    check(
        &o,
        o.line("check FAILED").is_none(),
        "a user-mode check failed",
    );
    for what in [
        "[syssw] hello from ring 3",
        "check ok: clock is monotonic and running",
        "check ok: debug_write of a kernel address is BadAddress",
        "check ok: debug_write of a null pointer is BadAddress",
        "check ok: debug_write longer than the limit is InvalidArgument",
        "check ok: unknown call number is InvalidCall",
        "check ok: system_halt with a bad outcome is InvalidArgument",
        "check ok: floating point works and survives a syscall",
        "all user-mode checks passed",
        "kernel: halt requested by user space (Success)",
    ] {
        check(&o, o.line(what).is_some(), &format!("missing {what:?}"));
    }
}

#[test]
fn user_kernel_access() {
    let o = boot("user_kernel_access");
    check(
        &o,
        o.ending == Ending::Exited(EXIT_FAILURE),
        "expected failure exit (35)",
    );
    let report = o.line("EXCEPTION ").unwrap_or_default();
    check(
        &o,
        report.contains("#PF (page fault, vector 14)") && report.contains("in user mode"),
        "expected a user-mode #PF",
    );
    // Error code bit 0 = protection violation (page present), bit 2 = user access.
    check(
        &o,
        report.contains("error=0x5"),
        "expected error code 0x5 (present page, user read)",
    );
    let regs = o.line("  rip=").unwrap_or_default();
    check(
        &o,
        regs.contains("cr2=0xffffffff80000000"),
        "expected CR2 = the kernel address",
    );
}
