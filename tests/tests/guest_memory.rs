//! The guest's memory and faults in QEMU: `guest_faults` (configuration
//! `tests/configs/guest_faults.toml`) and `guest_isolation` (`guest_isolation.toml`), both
//! running the static C program `linux-probe` (`tests/linux/probe.c`) as Linux processes.

use scenarios::{boot, check, guest_stdout, partition_lines};
use xtask::qemu::Outcome;

/// Each probe (`linux-probe <name>`, one process each) was killed by its signal in the CPU
/// exception `vector`, and the shell saw `128 + signal`, in `partition`.
fn killed(o: &Outcome, partition: &str, probes: &[(&str, u32, &str, u64)]) {
    let printed = guest_stdout(o, partition);
    for (probe, signal, name, vector) in probes {
        let started = partition_lines(o, partition, &format!("started: /bin/linux-probe {probe}"));
        let pid = started.first().and_then(|l| {
            l.strip_prefix("guest: process ")
                .and_then(|rest| rest.split_once(' '))
                .map(|(pid, _)| pid.to_string())
        });
        check(
            o,
            pid.is_some(),
            &format!("{partition}: probe {probe} did not start"),
        );
        let kills = partition_lines(
            o,
            partition,
            &format!(
                "process {} (linux-probe) killed by signal",
                pid.unwrap_or_default()
            ),
        );
        check(
            o,
            kills.len() == 1
                && kills[0].contains(&format!(
                    "killed by signal {signal} ({name}): vector {vector} "
                )),
            &format!("{partition}: probe {probe}: {kills:?}"),
        );
        let status = format!("{probe}: status {}", 128 + signal);
        check(
            o,
            printed.contains(&status),
            &format!("{partition}: no {status:?} in {printed:?}"),
        );
    }
}

#[test]
fn guest_faults() {
    let o = boot("guest_faults");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the second guest ends the run",
    );
    killed(
        &o,
        "faults",
        &[
            ("segv", 11, "SIGSEGV", 14),
            ("ill", 4, "SIGILL", 6),
            ("div", 8, "SIGFPE", 0),
            ("stack", 11, "SIGSEGV", 14),
        ],
    );
    let printed = guest_stdout(&o, "faults");
    check(
        &o,
        printed
            .iter()
            .all(|l| !l.contains("FAILED") && !l.contains("not contained")),
        &format!("faults: {printed:?}"),
    );
    for line in [
        "memory: mmap of 64 MiB (backed on demand) ok",
        "memory: the child saw its own copy ok",
        "memory: the parent kept its pages ok",
        "memory: a write to it is SIGSEGV ok",
        "memory: a read there is SIGSEGV ok",
        "memory: MAP_FIXED_NOREPLACE refused (EEXIST) ok",
        "memory: MADV_DONTNEED gives zeros ok",
        "memory: mremap kept the contents ok",
        "memory: mmap of /etc/passwd ok",
        "memory: all checks passed",
        "memory: status 0",
    ] {
        check(
            &o,
            printed.iter().any(|l| l == line),
            &format!("faults: missing {line:?}"),
        );
    }
    for (needle, expected) in [
        (
            "guest: init ended with",
            "guest: init ended with 0 other processes left",
        ),
        ("guest: init exited", "guest: init exited with status 0"),
    ] {
        let lines = partition_lines(&o, "faults", needle);
        check(&o, lines == [expected], &format!("faults: {lines:?}"));
    }
    // Six processes made the call the guest lacks: one line names it.
    let unsupported = partition_lines(&o, "faults", "unsupported system call");
    check(
        &o,
        unsupported.len() == 1
            && unsupported[0].ends_with(
                "(linux-probe): unsupported system call 425 (io_uring_setup), returning ENOSYS",
            ),
        &format!("faults: calls the guest lacks: {unsupported:?}"),
    );
    let enosys = printed.iter().filter(|l| *l == "enosys: ENOSYS").count();
    check(
        &o,
        enosys == 6,
        &format!("faults: {enosys} of 6 enosys lines"),
    );
    // The next guest ran after it.
    check(
        &o,
        partition_lines(&o, "after", "guest: process 1 stdout: after").len() == 1,
        "after: did not run",
    );
}

#[test]
fn guest_isolation() {
    let o = boot("guest_isolation");
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    // Page faults outside the process's memory; #GP (vector 13) for the ports and `cli`.
    killed(
        &o,
        "probes",
        &[
            ("kernel", 11, "SIGSEGV", 14),
            ("pool", 11, "SIGSEGV", 14),
            ("data", 11, "SIGSEGV", 14),
            ("port", 11, "SIGSEGV", 13),
            ("console", 11, "SIGSEGV", 13),
            ("exit", 11, "SIGSEGV", 13),
            ("cli", 11, "SIGSEGV", 13),
        ],
    );
    check(
        &o,
        o.line("not contained").is_none(),
        "a probe was not contained",
    );
    check(
        &o,
        partition_lines(&o, "probes", "guest: init exited with status 0").len() == 1,
        "probes: the shell did not finish",
    );
    // The victim logged its windows: none missed, none off the ideal sequence.
    let summaries: Vec<&String> = o
        .lines
        .iter()
        .filter(|l| l.contains("victim: windows="))
        .collect();
    check(
        &o,
        summaries
            .last()
            .is_some_and(|l| l.contains("victim: windows=500 ")),
        "the victim did not log its 500 windows",
    );
    for line in summaries {
        check(
            &o,
            line.contains(" missed=0 ") && line.contains(" drift=0 "),
            &format!("the victim missed windows: {line}"),
        );
    }
}
