//! APEX scenarios: partitions written against the a653rs traits (`tests/programs/apex-test`)
//! use syssw's ports and health monitor.

use scenarios::{boot, check};
use xtask::qemu::{Ending, Outcome};

/// A health-monitor event line of `partition` with `error`, `detail` (prefix) and `action`.
fn health(o: &Outcome, partition: &str, error: &str, detail: &str, action: &str) -> usize {
    o.lines
        .iter()
        .filter(|l| {
            l.contains("health: t=")
                && l.contains(&format!(
                    "partition={partition} error={error} detail={detail}"
                ))
                && l.ends_with(&format!(" action={action}"))
        })
        .count()
}

fn expect_lines(o: &Outcome, lines: &[&str]) {
    for line in lines {
        check(o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
}

#[test]
fn apex_ports() {
    let o = boot("apex_ports");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the receiver's end is shutdown_success",
    );
    expect_lines(
        &o,
        &[
            "sender: unknown port: Some(InvalidConfig)",
            // 2 in the source port + 4 in the destination, then the poll is refused ...
            "sender: queued 6 messages, then NotAvailable",
            // ... and a wait for room ends by its time-out (the receiver is not in its window).
            "sender: send with 1 ms time-out: Some(TimedOut)",
            // Sampling: the latest message, valid while younger than the 125 ms refresh period
            // (read 50 ms after each write; the last write is 150 ms old in frame 4).
            "receiver: frame 1 level 1 Valid",
            "receiver: frame 2 level 2 Valid",
            "receiver: frame 3 level 3 Valid",
            "receiver: frame 4 level 3 Invalid",
            // Queuing: FIFO order, then empty.
            "receiver: frame 1 got [0, 1, 2, 3, 4, 5], then NotAvailable",
            "receiver: receive with 2 ms time-out: Some(TimedOut)",
            "receiver: waited across windows for message 100",
        ],
    );
    check(
        &o,
        health(
            &o,
            "receiver",
            "application_error",
            "\"ports",
            "shutdown_success",
        ) == 1,
        "the receiver's final error is logged with its configured action",
    );
}

#[test]
fn apex_health() {
    let o = boot("apex_health");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.ending == Ending::Exited(35),
        "expected the failure exit (35): the victim's last error is configured as shutdown",
    );
    let at = |needle: &str| o.lines.iter().position(|l| l.contains(needle));

    // The intruder writes the board it may only read: #PF (present, write, user) at the
    // board's address, handled by its configured action; the victim keeps its windows.
    check(
        &o,
        health(
            &o,
            "intruder",
            "memory_violation",
            "#PF,error=0x7,address=0x600000000000,",
            "idle",
        ) == 1,
        "the intruder's write is a memory violation handled by idle",
    );
    check(
        &o,
        o.line("intruder: the write went through").is_none(),
        "the write must fault",
    );
    let stopped = at("syssw: partition intruder: IDLE").expect("the intruder is stopped");
    for frame in [10, 20, 30, 40] {
        let line = at(&format!("victim: frame {frame}"));
        check(
            &o,
            line.is_some_and(|l| l > stopped),
            &format!(
                "the victim must keep running its windows after the violation (frame {frame})"
            ),
        );
    }
    check(
        &o,
        o.lines
            .iter()
            .skip(stopped + 1)
            .all(|l| !l.contains("[intruder]")),
        "nothing of the intruder runs once it is IDLE",
    );

    // Warm restart keeps memory (the start counter goes on), cold restart reloads the
    // image (the counter starts again); the start conditions say why.
    let sequence = [
        "restarter: start 1 mode=ColdStart condition=NormalStart",
        "partition=restarter error=application_error detail=\"restart\\x20me\" action=warm_restart",
        "syssw: partition restarter: WARM_START (HM_PARTITION_RESTART, restart 1)",
        "restarter: start 2 mode=WarmStart condition=HmPartitionRestart",
        "restarter: asking for a cold start",
        "syssw: partition restarter: COLD_START (PARTITION_RESTART, restart 2)",
        "restarter: start 1 mode=ColdStart condition=PartitionRestart",
        "restarter: settled",
        "syssw: partition restarter: NORMAL (PARTITION_RESTART, restart 2)",
    ];
    let mut previous = 0;
    for line in sequence {
        let found = o.lines.iter().skip(previous).position(|l| l.contains(line));
        check(
            &o,
            found.is_some(),
            &format!("missing, or out of order: {line:?}"),
        );
        previous += found.unwrap_or(0) + 1;
    }
    check(
        &o,
        o.line("restarter: still running after the error").is_none(),
        "the warm restart stops the failing process",
    );

    // The overrunning process: DEADLINE_MISSED from the partition's deadline watchdog,
    // ignored as configured, and the process goes on.
    let misses = health(
        &o,
        "overrun",
        "deadline_missed",
        "\"process\\x20work\\x20deadline\"",
        "ignore",
    );
    check(
        &o,
        misses >= 3,
        &format!("jobs 20..=22 overrun: {misses} deadline misses"),
    );
    check(
        &o,
        o.line("overrun: job 25 done in time").is_some(),
        "the process keeps running",
    );

    // The end: the victim's error is configured as a module shutdown.
    check(
        &o,
        health(
            &o,
            "victim",
            "application_error",
            "\"victim\\x20done\"",
            "shutdown",
        ) == 1,
        "the victim's final error is logged with action shutdown",
    );
    check(
        &o,
        o.line("halt requested by user space (Failure)").is_some(),
        "the module halts",
    );
}

#[test]
fn forged_fault_report() {
    let o = boot("forged_fault_report");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the bystander's end is shutdown_success",
    );
    expect_lines(
        &o,
        &[
            "forger: forged fault reports refused: 64 calls, 64 sends",
            "bystander: frame 30",
        ],
    );
    // The health monitor heard of nothing but the bystander's planned end.
    let health: Vec<&String> = o.lines.iter().filter(|l| l.contains("health:")).collect();
    check(
        &o,
        health.len() == 1 && health[0].contains("partition=bystander error=application_error"),
        &format!("unexpected health events: {health:?}"),
    );
}
