//! Multicore scenarios: the application processors beside the ordinary system.

use scenarios::{boot, check, passes};

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
            w == Some(200) && m == Some(0) && d == Some(0) && max.is_some_and(|x| x <= 52_000)
        }),
        "the victim did not keep its 200 windows within 52 us on the boot CPU",
    );
}

#[test]
fn smp_windows() {
    passes(
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
            "the killed spinner ran no more on the other CPU",
            "the other CPU goes on with TP3 after the kill",
        ],
    );
}
