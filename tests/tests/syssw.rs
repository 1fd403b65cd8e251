//! System-software scenarios: syssw builds the partitions a configuration describes.

use scenarios::{boot, check};

#[test]
fn syssw_partitions() {
    let o = boot("syssw_partitions");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): windows-b's #UD is configured as shutdown_success",
    );
    for line in [
        "syssw: partition ports-a: TP1, MCP 100, priority 100, memory ",
        "syssw: partition windows-b: TP2, MCP 100, priority 100, memory ",
        "syssw: partition background: background, MCP 10, priority 10, memory ",
        "1 I/O range(s)",
        "syssw: 3 partitions started, schedule default (major frame 10000 us, 2 windows)",
        "ports-a: started as partition 0 in TP1",
        "windows-b: started as partition 1 in TP2",
        "background: started as partition 2 in TP0",
        "ports-a: granted port 0x2ff reads back 0x5a",
        "ports-a: touching port 0x80, which is not granted",
        "windows-b: ran in 50 of its windows, 0 samples outside them",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    check(
        &o,
        o.line("port 0x80 did not fault").is_none(),
        "an ungranted port must fault",
    );
    let health = |partition: &str, error: &str, action: &str| {
        o.lines.iter().any(|l| {
            l.contains("health: t=")
                && l.contains(&format!("partition={partition} error={error} "))
                && l.ends_with(&format!("action={action}"))
        })
    };
    check(
        &o,
        health("ports-a", "illegal_request", "idle"),
        "the #GP of ports-a must be handled as illegal_request with its configured action idle",
    );
    check(
        &o,
        o.line("detail=#GP,error=0x0,").is_some(),
        "the event names the exception",
    );
    check(
        &o,
        o.line("syssw: partition ports-a: IDLE (NORMAL_START, restart 0)")
            .is_some(),
        "the stopped partition's mode change is logged",
    );
    check(
        &o,
        health("windows-b", "illegal_request", "shutdown_success"),
        "the #UD of windows-b must be handled as illegal_request with action shutdown_success",
    );
}

/// Boot property: a description `check-config` accepts boots. `tests/configs/generated_<seed>.toml`
/// is `config::generate`'s description for the seed (checked by `cargo test -p warden-config`),
/// every partition the heartbeat program: syssw starts them all, each reports it started and
/// then a heartbeat, and the kernel neither panics nor faults in kernel mode.
fn generated_boot(seed: u64) {
    let name = format!("generated_boot_{seed}");
    let text = std::fs::read_to_string(
        xtask::workspace_root().join(format!("tests/configs/generated_{seed}.toml")),
    )
    .unwrap();
    let partitions = text.matches("\n[partitions.").count();
    let o = boot(&name);
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    check(
        &o,
        o.line("fatal exception").is_none(),
        "an exception in kernel mode",
    );
    let started = format!("syssw: {partitions} partitions started");
    check(
        &o,
        o.line(&started).is_some(),
        &format!("missing {started:?}"),
    );
    for i in 0..partitions {
        for line in [
            format!("p{i}: started as partition {i} in TP"),
            format!("p{i}: alive at "),
        ] {
            check(&o, o.line(&line).is_some(), &format!("missing {line:?}"));
        }
    }
}

#[test]
fn generated_boot_1() {
    generated_boot(1);
}

#[test]
fn generated_boot_2() {
    generated_boot(2);
}

#[test]
fn generated_boot_3() {
    generated_boot(3);
}

/// How long any service request of the victim may wait while another partition restarts,
/// on virtual time: one major frame of the scenario. A request that waited behind a
/// restart would wait until the restarted partition's next window at least (about a
/// frame); answered at once it takes microseconds.
const RESTART_LOOP_WAIT_BOUND_NS: u64 = 10_000_000;

/// `port-victim: round=N wait_ns=W ...` → (N, W).
fn victim_round(line: &str) -> Option<(u64, u64)> {
    let rest = line.split("port-victim: round=").nth(1)?;
    let mut words = rest.split_whitespace();
    let round = words.next()?.parse().ok()?;
    let wait = words.next()?.strip_prefix("wait_ns=")?.parse().ok()?;
    Some((round, wait))
}

#[test]
fn syssw_restart_loop() {
    let o = boot("syssw_restart_loop");
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    check(&o, o.line("panic at ").is_none(), "a panic");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    check(
        &o,
        o.line("port-victim: done rounds=300 ")
            .is_some_and(|l| l.ends_with(" lost=0")),
        "the victim did not finish its 300 round trips, each message back unchanged",
    );
    let rounds: Vec<(usize, u64, u64)> = o
        .lines
        .iter()
        .enumerate()
        .filter_map(|(at, l)| victim_round(l).map(|(round, wait)| (at, round, wait)))
        .collect();
    check(&o, rounds.len() == 300, "the victim logged 300 rounds");
    for &(_, round, wait) in &rounds {
        check(
            &o,
            wait <= RESTART_LOOP_WAIT_BOUND_NS,
            &format!(
                "round {round}: a request waited {wait} ns (bound {RESTART_LOOP_WAIT_BOUND_NS})"
            ),
        );
    }
    // Both restart loops ran all along: restarts between the victim's first and last
    // rounds, the background partition's queued behind the big one's.
    let (first, last) = (rounds[0].0, rounds[rounds.len() - 1].0);
    let restarts = |partition: &str| {
        let line = format!("syssw: partition {partition}: COLD_START (HM_PARTITION_RESTART");
        o.lines[first..last]
            .iter()
            .filter(|l| l.contains(&line))
            .count()
    };
    for partition in ["fault-loop", "fault-loop-bg"] {
        let n = restarts(partition);
        check(
            &o,
            n >= 10,
            &format!("only {n} restarts of {partition} during the victim's 300 rounds"),
        );
    }
    check(
        &o,
        o.line("restart failed").is_none() && o.line("fault report for unknown task").is_none(),
        "a restart failed, or a fault of a restarting partition went astray",
    );
    let restarts = restarts("fault-loop");
    let max = rounds.iter().map(|r| r.2).max().unwrap_or(0);
    eprintln!("syssw_restart_loop: {restarts} restarts, longest wait {max} ns");
}
