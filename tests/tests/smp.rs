//! Multicore scenarios: the application processors beside the ordinary system.

use crate::attack::LATENESS_BOUND_NS;
use scenarios::{boot, check, guest_stdout, partition_lines, passes};

/// `name=<number>` in a summary line.
fn field(line: &str, name: &str) -> Option<u64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(name))
        .and_then(|v| v.parse().ok())
}

#[test]
fn smp_boot() {
    let o = boot("smp_boot");
    check(
        &o,
        o.line("KERNEL PANIC").is_none() && o.line("fatal exception").is_none(),
        "the kernel panicked or took an exception in kernel mode",
    );
    for cpu in 1..4 {
        check(
            &o,
            o.line(&format!("cpu {cpu} online (apic {cpu})")).is_some(),
            &format!("cpu {cpu} did not report itself online"),
        );
    }
    check(
        &o,
        o.line("smp: 4 of 4 CPUs online; each runs the threads put on it")
            .is_some(),
        "the boot CPU did not count 4 CPUs online",
    );
    // QEMU's deterministic time runs the CPUs in turns on one host thread, and xtask says
    // so (fw_cfg opt/warden/cpus-in-turns); with every thread on the boot CPU the clock
    // never starts, so the idle machine's time is skipped as on one CPU.
    check(
        &o,
        o.line("smp: the CPUs run in turns: PIT turn clock every 20 us once a thread is on another CPU than CPU 0")
            .is_some(),
        "the kernel did not announce the turn clock the host asked for",
    );
    check(
        &o,
        o.line("smp: PIT turn clock started").is_none(),
        "the turn clock started although no thread ran on another CPU",
    );
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    // The same bound as attack_map on one CPU (tests/tests/attack.rs): the idle CPUs
    // change nothing for the boot CPU's windows.
    let summary = o
        .lines
        .iter()
        .rev()
        .find(|l| l.contains("victim: windows="));
    let numbers = summary.map(|l| {
        (
            field(l, "windows="),
            field(l, "missed="),
            field(l, "drift="),
            field(l, "max="),
        )
    });
    eprintln!("smp_boot victim summary: {summary:?}");
    check(
        &o,
        numbers.is_some_and(|(w, m, d, max)| {
            w == Some(200)
                && m == Some(0)
                && d == Some(0)
                && max.is_some_and(|x| x <= LATENESS_BOUND_NS)
        }),
        &format!(
            "the victim did not keep its 200 windows within {LATENESS_BOUND_NS} ns on the boot CPU"
        ),
    );
}

#[test]
fn smp_windows() {
    let o = passes(
        "smp_windows",
        "smp",
        &[
            "thread_set Cpu to a CPU that is not online is InvalidArgument",
            "schedule_set with a window on a CPU that is not online is InvalidArgument",
            "schedule_set with overlapping windows on one CPU is InvalidArgument",
            "thread_set Cpu of a thread another CPU runs is NotPermitted",
            "each partition got its window's half of the time on its CPU (±10%), TP1 and TP2 at the same time",
            "every spinner ran",
            "every call on the same CPU got its answer",
            "every call across CPUs got its answer",
            "the server counted every call",
            "every call was answered on the caller's CPU (CPU 0: TP0 or TP1 active)",
            "the killed spinner ran no more on the other CPU",
            "the other CPU goes on with TP3 after the kill",
            "a task's granted port works on the other CPU",
            "a task without ports cannot use those of a task killed on that CPU (#GP)",
        ],
    );
    check(
        &o,
        o.line("smp: PIT turn clock started (a thread on CPU 1)")
            .is_some(),
        "the turn clock did not start when a thread went to CPU 1",
    );
    // The shares and round trips, for whoever runs it with --nocapture.
    for line in o.lines.iter().filter(|l| l.contains("] smp: ")) {
        eprintln!("{line}");
    }
}

#[test]
fn smp_partitions() {
    let o = boot("smp_partitions");
    check(
        &o,
        o.line("KERNEL PANIC").is_none() && o.line("panic at ").is_none(),
        "the kernel or a partition panicked",
    );
    for line in [
        "syssw: partition windows-a: TP1 on CPU 0, MCP 100, priority 100, memory ",
        "syssw: partition windows-b: TP2 on CPU 1, MCP 100, priority 100, memory ",
        "syssw: partition cpu0: background on CPU 0, MCP 10, priority 10, memory ",
        "syssw: partition hog1: background on CPU 1, MCP 10, priority 10, memory ",
        "windows-a: ran in 50 of its windows, 0 samples outside them",
        "syssw: partition windows-b: COLD_START (HM_PARTITION_RESTART, restart 2)",
        "hog1: spinning at 1 s",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    let count = |text: &str| o.lines.iter().filter(|l| l.contains(text)).count();
    check(
        &o,
        count("windows-b: ran in 50 of its windows, 0 samples outside them") >= 2,
        "windows-b did not run in 50 of its windows on CPU 1 before and after its restart",
    );
    check(
        &o,
        count("partition=windows-b error=illegal_request") >= 2
            && count("partition=windows-a error=illegal_request") == 1,
        "the #UDs were not handled: windows-b twice (restarted), windows-a once (idle)",
    );
    // At 2 s (the schedule runs from about 0.2 s): both CPUs' time is accounted, about
    // 1.8 s each (CPU 0's busy or idle, which cpu0 reads for its own CPU; CPU 1's busy,
    // hog1 leaves it no idle time); windows-b got 4 ms of each 10 ms frame on CPU 1 throughout,
    // restarts included (the worker moved there pays with its windows; 724, 696 and 676 ms
    // measured, 622 while each CPU's timer fired only at its own boundaries, so that CPU
    // 1 took its window starts only when CPU 0's turn under QEMU ended); windows-a its 50
    // windows of 4 ms on CPU 0 before it went idle.
    let line = o.line("cpu0: at 2 s CPU time us ");
    let us = |name: &str| line.and_then(|l| field(l, name));
    let times: Vec<u64> = ["TP0=", "TP1=", "TP2=", "idle="]
        .iter()
        .filter_map(|n| us(n))
        .collect();
    eprintln!("smp_partitions accounting: {line:?}");
    check(
        &o,
        times.len() == 4 && times.iter().sum::<u64>() >= 3_400_000,
        "the CPU time and idle time at 2 s do not cover two CPUs",
    );
    check(
        &o,
        times.len() == 4 && (660_000..=760_000).contains(&times[2]),
        "windows-b did not get 4 ms of each 10 ms frame on CPU 1",
    );
    check(
        &o,
        times.len() == 4 && (150_000..=220_000).contains(&times[1]),
        "windows-a did not get its 50 windows of 4 ms on CPU 0",
    );
}

/// A guest on two CPUs (`tests/configs/guest_smp.toml`, script `tests/configs/guest/smp.sh`):
/// every line the script prints, then its exit status.
#[test]
fn guest_smp() {
    const EXPECTED: &[&str] = &[
        "nproc 2",
        "cpuinfo 2",
        "mask 3",
        "pinned 0 0",
        "pinned 1 1",
        "no CPU 5: 1",
        "spread",
        "gzipped 8",
        "intact 8",
    ];
    let o = boot("guest_smp");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("syssw: partition shell: background on CPUs 0,1")
            .is_some(),
        "syssw did not start the guest on CPUs 0 and 1",
    );
    let printed = guest_stdout(&o, "shell");
    check(
        &o,
        printed == EXPECTED,
        &format!("printed {printed:#?}, expected {EXPECTED:#?}"),
    );
    let lines = partition_lines(&o, "shell", "");
    for needle in ["unsupported system call", "killed by signal"] {
        let found: Vec<&String> = lines.iter().filter(|l| l.contains(needle)).collect();
        check(&o, found.is_empty(), &format!("{needle:?}: {found:?}"));
    }
    check(
        &o,
        o.line("guest: init exited with status 7").is_some(),
        "the script did not end with its status 7",
    );
}
