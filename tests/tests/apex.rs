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
            // Long messages, several IPC messages each, arrive whole: sampling ...
            "receiver: frame 1 image of 10000 bytes, intact true Valid",
            "receiver: frame 2 image of 10000 bytes, intact true Valid",
            "receiver: frame 3 image of 10000 bytes, intact true Valid",
            // ... and queuing, in order; one longer than the port is refused.
            "receiver: bulk message 1 of 20000 bytes, intact true",
            "receiver: bulk message 2 of 5000 bytes, intact true",
            "sender: a 20,001-byte message: Some(InvalidConfig)",
            // A receive that waited gets its long message when the sender sends it.
            "receiver: waited for bulk message 4 of 20000 bytes, intact true",
            // Stacks as large as asked, from the runtime's arena, as long as it has room.
            "sender: deep stack used 180000 bytes, sum 22946416",
            "sender: a 1 MiB stack: Some(InvalidConfig)",
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

#[test]
fn apex_intra() {
    let o = boot("apex_intra");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the driver's end is shutdown_success",
    );
    // Workers w1 (priority 10), w2 (30), w3 (20) arrive in the order w1, w2, w3: FIFO
    // serves 1 2 3, PRIORITY 2 3 1; wake-all services let them run by priority.
    expect_lines(
        &o,
        &[
            // INIT mode.
            "intra: init CREATE_SEMAPHORE again: Some(NoAction)",
            "intra: init CREATE_SEMAPHORE 4 of 3: Some(InvalidParam)",
            "intra: init CREATE_MUTEX at the MCP: Some(InvalidConfig)",
            "intra: init 8 mutexes, then CREATE_MUTEX: InvalidConfig",
            "intra: init WAIT_SEMAPHORE 5 ms outside a process: Some(InvalidMode)",
            // Wake order.
            "intra: semaphore FIFO waiting 3 woken 1 2 3",
            "intra: semaphore PRIORITY waiting 3 woken 2 3 1",
            "intra: buffer FIFO receivers got 1a 2b 3c",
            "intra: buffer PRIORITY receivers got 2a 3b 1c",
            "intra: buffer PRIORITY senders sent 2s 3s 1s",
            "intra: buffer PRIORITY 3 senders waited, received x y 2 3 1",
            "intra: DISPLAY_BLACKBOARD with 3 waiting woke 2g 3g 1g",
            "intra: SET_EVENT with 3 waiting woke 2 3 1",
            "intra: after RESET_EVENT WAIT_EVENT 0: Some(NotAvailable)",
            // Mutexes: the owner runs at the ceiling (60) and may not wait, so nobody waits
            // for it on one core; the workers take it after the release, by priority.
            "intra: mutex PRIORITY: the driver ran at 60, back at 5, 0 waiting",
            "intra: mutex PRIORITY owners 2@60 3@60 1@60",
            "intra: mutex FIFO: the driver ran at 60, back at 5, 0 waiting",
            "intra: mutex FIFO owners 2@60 3@60 1@60",
            "intra: worker priorities after the mutexes: 10 30 20",
            "intra: w3 owns mtx_fifo at priority 60; WAIT_SEMAPHORE while owning it: Some(InvalidMode)",
            "intra: w3 owning it: TIMED_WAIT Some(InvalidMode), SUSPEND_SELF Some(InvalidMode)",
            "intra: SUSPEND of the owner w3: Some(InvalidMode)",
            "intra: GET_PROCESS_MUTEX_STATE(w3) is mtx_fifo: true; status owner w3: true Owned lock count 1 priority 60",
            "intra: RELEASE_MUTEX not owner: Some(InvalidMode); RESET_MUTEX(w3): None; then Ok(Available), w3 at priority 20",
            "intra: w3 after the reset: RELEASE_MUTEX Some(InvalidMode), priority 20",
            // Time-outs: 0 is NOT_AVAILABLE, a finite one TIMED_OUT after it has passed.
            "intra: WAIT_SEMAPHORE 0: Some(NotAvailable); 10 ms: (Some(TimedOut), true); waiting after: 0",
            "intra: RECEIVE_BUFFER empty 0: Some(NotAvailable); 5 ms: (Some(TimedOut), true); SEND_BUFFER full 0: Some(NotAvailable); 5 ms: (Some(TimedOut), true)",
            "intra: READ_BLACKBOARD cleared 0: Some(NotAvailable); 5 ms: (Some(TimedOut), true); WAIT_EVENT 5 ms: (Some(TimedOut), true)",
            // NORMAL mode.
            "intra: CREATE in NORMAL: Some(InvalidMode) Some(InvalidMode) Some(InvalidMode) Some(InvalidMode) Some(InvalidMode)",
            "intra: SIGNAL_SEMAPHORE at its maximum: Some(NoAction); SEND_BUFFER too long: Some(InvalidParam); DISPLAY_BLACKBOARD too long: Some(InvalidParam)",
            "intra: unknown ids: Some(InvalidParam) Some(InvalidParam) Some(InvalidParam) Some(InvalidParam) Some(InvalidParam)",
            "intra: unknown names: Some(InvalidConfig) Some(InvalidConfig) Some(InvalidConfig) Some(InvalidConfig) Some(InvalidConfig)",
            "intra: ACQUIRE_MUTEX above its ceiling: Some(InvalidConfig); RELEASE_MUTEX not owned: Some(InvalidMode)",
            "intra: unknown process: RESET_MUTEX Some(InvalidParam); GET_PROCESS_MUTEX_STATE Some(InvalidParam); driver owns -2",
            "intra: STOP of a waiter: waiting 1 -> 0; SIGNAL_SEMAPHORE then leaves 1",
            // A SUSPENDed waiter leaves the queue when the event is set, but runs only
            // when RESUMEd.
            "intra: SUSPENDed waiter: 0 waiting after SET_EVENT, state Ok(Waiting)",
            "intra: SUSPENDed waiter after RESUME: woke 2",
            "intra: done",
        ],
    );
    check(
        &o,
        o.lines
            .iter()
            .all(|l| !l.contains("intra: w") || !l.contains(" phase ")),
        "a worker's wait failed",
    );
    check(
        &o,
        o.lines
            .iter()
            .any(|l| l.ends_with("intra: SUSPENDed waiter after SET_EVENT: woke")),
        "a SUSPENDed waiter must not run before RESUME",
    );
    check(
        &o,
        health(
            &o,
            "intra",
            "application_error",
            "\"intra",
            "shutdown_success",
        ) == 1,
        "the driver's final error is logged with its configured action",
    );
}

#[test]
fn apex_preemption() {
    let o = boot("apex_preemption");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the holder's end is shutdown_success",
    );
    // The holder (priority 10) locks; the rival (50) readied meanwhile runs only at level 0.
    expect_lines(
        &o,
        &[
            "preempt: init LOCK_PREEMPTION: Some(NoAction)",
            "preempt: LOCK_PREEMPTION Ok(1) Ok(2); partition lock level 2; priority 100",
            "preempt: rival readied, 3 ms later it ran 0 times",
            "preempt: locked: TIMED_WAIT Some(InvalidMode); WAIT_SEMAPHORE 5 ms Some(InvalidMode), 0 Some(NotAvailable); SUSPEND_SELF 5 ms Some(InvalidMode); ACQUIRE_MUTEX Some(InvalidMode); GET_PROCESS_MUTEX_STATE is PREEMPTION_LOCK_MUTEX: true",
            "preempt: locked up to 16 (MAX_LOCK_LEVEL 16), then Some(InvalidConfig)",
            "preempt: unlocked to 1: rival ran 0 times, priority 100",
            "preempt: UNLOCK_PREEMPTION Ok(0): rival ran 1 times, priority 20; again Some(NoAction)",
            "preempt: unlocked: TIMED_WAIT 1 ms None",
            "preempt: done",
        ],
    );
    check(
        &o,
        health(
            &o,
            "preempt",
            "application_error",
            "\"preempt",
            "shutdown_success",
        ) == 1,
        "the holder's final error is logged with its configured action",
    );
}

#[test]
fn apex_port_priority() {
    let o = boot("apex_port_priority");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the last receiver's end is shutdown_success",
    );
    // Waiters of priorities 10 (1), 30 (2), 20 (3) arrive in the order 1, 2, 3.
    expect_lines(
        &o,
        &[
            "prio_rx: CREATE_QUEUING_PORT req as FIFO: Some(InvalidConfig)",
            "prio_tx: back full: Some(NotAvailable)",
            "prio_tx: back waiting senders: 3",
            // Senders on the PRIORITY source port enter the channel 2, 3, 1.
            "prio_rx: req waiting receivers: 3; back got x y 2 3 1",
            "prio_tx: sent a b c",
            // Receivers on the PRIORITY destination port are served 2, 3, 1.
            "prio_rx: PRIORITY receivers got r1=c r2=a r3=b",
        ],
    );
    check(
        &o,
        o.lines.iter().all(|l| !l.contains(" failed: ")),
        "a waiter's send or receive failed",
    );
}

#[test]
fn apex_schedule_switch() {
    let o = boot("apex_schedule_switch");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): sched's end is shutdown_success",
    );
    expect_lines(
        &o,
        &[
            "sched: status current 0 next 0 last switch none",
            "sched: GET_MODULE_SCHEDULE_ID second Ok(1), nonesuch Some(InvalidConfig); SET_MODULE_SCHEDULE 7 Some(InvalidParam)",
            "sched: SET_MODULE_SCHEDULE second None",
            "sched: status current 0 next 1 last switch none",
            "sched: status current 1 next 1 last switch set",
            "plain: GET_MODULE_SCHEDULE_ID first Ok(0); SET_MODULE_SCHEDULE second Some(InvalidConfig), first Some(InvalidConfig)",
            "sched: done",
        ],
    );
    // The switch lands exactly on the end of the 50 ms frame in which it was asked for,
    // and sched's next window is the new schedule's, 20 ms after the boundary.
    let line = o.line("sched: asked ").expect("the switch's timing line");
    check(
        &o,
        line.ends_with("the switch came 50000 us after that window's frame began"),
        &format!("switch not on the frame boundary: {line}"),
    );
    let after = o
        .line("sched: its window under second begins ")
        .expect("the window line");
    let ran: u64 = after
        .rsplit("it ran ")
        .next()
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    check(
        &o,
        after.contains("begins 20000 us after the switch") && (20_000..21_000).contains(&ran),
        &format!("sched did not run in second's window: {after}"),
    );
    check(
        &o,
        o.lines.iter().any(|l| {
            l.contains("schedule: t=") && l.contains("partition=sched asks for schedule second")
        }),
        "syssw logs the requested switch",
    );
}

/// The number after `key` in `line` (up to the next space or `ms`/`.`).
fn number_after(line: &str, key: &str) -> Option<u64> {
    let rest = &line[line.find(key)? + key.len()..];
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// The `at t=N ms` times of the lines that contain `prefix`.
fn times(o: &Outcome, prefix: &str) -> Vec<u64> {
    o.lines
        .iter()
        .filter(|l| l.contains(prefix))
        .filter_map(|l| number_after(l, "at t="))
        .collect()
}

#[test]
fn apex_schedule_actions() {
    let o = boot("apex_schedule_actions");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): switcher's end is shutdown_success",
    );
    expect_lines(
        &o,
        &[
            "switcher: SET_MODULE_SCHEDULE second None",
            "reborn: start 1 mode=ColdStart condition=NormalStart",
            // Reloaded: its count of starts begins again.
            "reborn: start 1 mode=ColdStart condition=PartitionRestart",
            "syssw: partition reborn: COLD_START (PARTITION_RESTART, restart 1)",
            "warm: start 1 mode=ColdStart condition=NormalStart",
            // Its memory kept: the count goes on.
            "warm: start 2 mode=WarmStart condition=PartitionRestart",
            "syssw: partition warm: WARM_START (PARTITION_RESTART, restart 1)",
            "syssw: partition stopped: IDLE",
            "switcher: current 1 last switch",
        ],
    );
    // syssw says why, with the time of the switch: one line per partition acted on.
    let why = |partition: &str, action: &str| {
        o.lines.iter().find(|l| {
            l.contains("schedule: t=")
                && l.contains(&format!(
                    "partition={partition} change action {action} of schedule second"
                ))
        })
    };
    let reborn = why("reborn", "cold_start").expect("syssw's line for reborn");
    let stopped = why("stopped", "idle").expect("syssw's line for stopped");
    check(
        &o,
        why("warm", "warm_start").is_some(),
        "syssw's line for warm",
    );
    check(
        &o,
        o.lines
            .iter()
            .all(|l| !l.contains("partition=keeper change action")),
        "keeper (ignore) is left alone",
    );
    let switch = number_after(reborn, "(switch at t=").expect("the switch's time");
    check(
        &o,
        number_after(stopped, "(switch at t=") == Some(switch),
        "one switch",
    );
    let done = o
        .line("switcher: current 1 last switch at t=")
        .unwrap_or("");
    check(
        &o,
        number_after(done, "last switch at t=") == Some(switch),
        &format!("GET_MODULE_SCHEDULE_STATUS names the switch at {switch} ms: {done}"),
    );
    // reborn starts again in its first window under second (10-15 ms into the frame).
    let starts = times(&o, "reborn: start ");
    check(
        &o,
        starts.len() == 2 && (switch + 10..switch + 15).contains(&starts[1]),
        &format!("reborn's starts {starts:?}, switch at {switch} ms"),
    );
    // warm in its first window under second (5-10 ms into the frame).
    let warm_starts = times(&o, "warm: start ");
    check(
        &o,
        warm_starts.len() == 2 && (switch + 5..switch + 10).contains(&warm_starts[1]),
        &format!("warm's starts {warm_starts:?}, switch at {switch} ms"),
    );
    let reborn_ticks = times(&o, "reborn: tick ");
    check(
        &o,
        reborn_ticks.iter().any(|&t| t > switch) && reborn_ticks.iter().any(|&t| t < switch),
        &format!("reborn ticks before and after its restart: {reborn_ticks:?}"),
    );
    // stopped ticks only before the switch; keeper in every frame on both sides of it.
    let stopped_ticks = times(&o, "stopped: tick ");
    check(
        &o,
        !stopped_ticks.is_empty() && stopped_ticks.iter().all(|&t| t < switch),
        &format!("stopped ticks {stopped_ticks:?}, switch at {switch} ms"),
    );
    let keeper_ticks = times(&o, "keeper: tick ");
    check(
        &o,
        keeper_ticks.iter().filter(|&&t| t > switch).count() >= 3
            && keeper_ticks
                .windows(2)
                .all(|w| (39..=41).contains(&(w[1] - w[0]))),
        &format!("keeper ticks once per frame throughout: {keeper_ticks:?}"),
    );
}

#[test]
fn apex_error_handler() {
    let o = boot("apex_error_handler");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the handler's own error is shutdown_success",
    );
    expect_lines(
        &o,
        &[
            "handled: init CREATE_ERROR_HANDLER again: Some(NoAction)",
            "handled: faulty: GET_ERROR_STATUS Some(InvalidConfig); RAISE_APPLICATION_ERROR with a 129-byte message Some(InvalidParam), as DEADLINE_MISSED Some(InvalidParam)",
            "handled: handler: ApplicationError from faulty message \"first\"",
            "handled: handler: LOCK_PREEMPTION Some(NoAction); TIMED_WAIT Some(InvalidMode); GET_MY_ID true",
            "handled: handler: GET_ERROR_STATUS then NoAction",
            "handled: faulty: RAISE_APPLICATION_ERROR first None, handled 1",
            "handled: handler: ApplicationError from faulty message \"end\"",
        ],
    );
    // Only the handler's own error reaches the health monitor.
    let health: Vec<&String> = o
        .lines
        .iter()
        .filter(|l| l.contains("health: t="))
        .collect();
    check(
        &o,
        health.len() == 1
            && health[0].contains("partition=handled error=application_error detail=\"handler")
            && health[0].ends_with("action=shutdown_success"),
        &format!("unexpected health events: {health:?}"),
    );
}

#[test]
fn apex_heap() {
    let o = boot("apex_heap");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): burst's end is shutdown_success",
    );
    expect_lines(
        &o,
        &[
            "heap: churn ran > 1000 allocations, burst woke > 1000 times, suspended churn > 50 times, stopped it: Ok(()); a block after: 4096 bytes; damaged 0; heap found taken more than once",
        ],
    );
}
