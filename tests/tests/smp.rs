//! Multicore scenarios: the application processors beside the ordinary system.

use scenarios::{boot, check};

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
        o.line("smp: 4 of 4 CPUs online").is_some(),
        "the boot CPU did not count 4 CPUs online",
    );
    // Each AP's own local APIC timer beats 100 times a second (virtual time): a second of
    // beats logged, none more than a few periods after the one before.
    for cpu in 1..4 {
        let line = o.line(&format!("cpu {cpu}: heartbeat 100 "));
        eprintln!("smp_boot cpu {cpu}: {line:?}");
        check(
            &o,
            line.and_then(|l| field(l, "longest_gap_us="))
                .is_some_and(|gap| (9_000..=50_000).contains(&gap)),
            &format!("cpu {cpu} did not log a second of heartbeats 10 ms apart (at most 50 ms)"),
        );
    }
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    // The same bound as attack_map on one CPU (tests/tests/attack.rs): the waiting CPUs
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
