//! Boot-foundation scenarios: the system boots, reports faults precisely, and has a timer.

use scenarios::{boot, check};
use xtask::qemu::{EXIT_FAILURE, Ending};

#[test]
fn boot_ready() {
    let o = boot("boot_ready");
    check(&o, o.succeeded(), "expected success exit (33)");
    for line in [
        "Warden partitioning microkernel",
        "memory: ",
        "acpi: revision",
        "timer: calibrated against",
        "timer: 10 interrupts at 1 kHz",
        "sysimg:   syssw",
        "kernel: ready",
    ] {
        check(
            &o,
            o.line(line).is_some(),
            &format!("missing serial line containing {line:?}"),
        );
    }
    // Every kernel line carries a timestamp "[SSSS.UUUUUU] ".
    let first = o.lines.iter().position(|l| l.contains("Warden")).unwrap();
    for line in &o.lines[first..] {
        let ok = line.len() > 14
            && line.starts_with('[')
            && line.as_bytes()[12] == b']'
            && line[1..12].trim().contains('.');
        check(&o, ok, &format!("kernel line without timestamp: {line:?}"));
    }
}

#[test]
fn kernel_page_fault() {
    let o = boot("kernel_page_fault");
    check(
        &o,
        o.ending == Ending::Exited(EXIT_FAILURE),
        "expected failure exit (35)",
    );
    let report = o.line("EXCEPTION ").unwrap_or_default();
    check(
        &o,
        report.contains("#PF (page fault, vector 14)"),
        "expected a #PF report with its vector",
    );
    check(
        &o,
        report.contains("in kernel mode"),
        "expected the fault to be attributed to kernel mode",
    );
    let regs = o.line("  rip=").unwrap_or_default();
    check(
        &o,
        regs.contains("cr2=0x00000deadbeef000"),
        "expected CR2 = the unmapped test address",
    );
    check(
        &o,
        regs.contains("rip=0xffffffff8"),
        "expected RIP inside the kernel image",
    );
    check(
        &o,
        o.line("kernel: ready").is_some(),
        "the fault must come after a complete boot",
    );
}

#[test]
fn timer_interrupts() {
    let o = boot("timer_interrupts");
    check(&o, o.succeeded(), "expected success exit (33)");
    let line = o
        .line("test: timer fired 200 times in ")
        .unwrap_or_default();
    let micros: u64 = line
        .split("in ")
        .nth(1)
        .and_then(|s| s.trim_end_matches(" us").parse().ok())
        .unwrap_or(0);
    // 200 periods of 1 ms cannot complete in less than ~200 ms if the timer is programmed
    // right (10% slack for calibration error); an upper bound would only measure the host.
    check(
        &o,
        micros >= 180_000,
        &format!("200 ticks at 1 kHz took only {micros} us"),
    );
}
