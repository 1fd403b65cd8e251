//! Attacks on the kernel and syssw by hostile partitions (`tests/programs/attack`): each is
//! contained, and a victim partition beside the attacker keeps every window.

use scenarios::{boot, check};

/// The victim's window-start lateness on virtual time with no attacker on a CPU to delay it
/// but the victim's own: the quiet case is about 2 us (the timer interrupt, the window
/// switch and the wake-up from `sleep_until`).
const QUIET_NS: u64 = 2_000;
/// What one kernel path may take, the margin the issue of bounded kernel paths allows a
/// partition to add to another's window start.
const KERNEL_PATH_NS: u64 = 50_000;
/// The bound asserted while an attacker runs on the victim's CPU in the window just
/// before its own: the attacker's kernel path in progress when the window ends. Measured
/// per attack: docs/isolation.md, "Isolation guarantees" (from 5.5 us after a spinning
/// partition to 39 us after a background restart loop).
pub(crate) const LATENESS_BOUND_NS: u64 = QUIET_NS + KERNEL_PATH_NS;
/// One turn of another CPU where QEMU runs the CPUs in turns (the kernel's turn clock,
/// docs/architecture.md, "Multicore"): the victim's CPU may wait that long for its next.
const TURN_NS: u64 = 20_000;

/// The bound on a multicore machine whose CPUs run in turns, with attackers on
/// `attacked_cpus` CPUs: one kernel path each (the victim's own CPU's path in progress, and
/// the kernel lock, which every other attacked CPU may hold for one path before the
/// victim's CPU gets it: the one big kernel lock of docs/architecture.md), and one turn.
const fn multicore_bound_ns(attacked_cpus: u64) -> u64 {
    QUIET_NS + attacked_cpus * KERNEL_PATH_NS + TURN_NS
}

/// The bound for a system whose partitions all run on CPU 0: [`LATENESS_BOUND_NS`] on a
/// machine of one CPU; on a machine of several (the suite's default: two), where QEMU
/// runs the CPUs in turns, one turn more ([`multicore_bound_ns`] with the victim's CPU
/// attacked): the other CPUs, idle, still follow the frame's boundaries (a CPU that sees
/// another's boundary pass interrupts it, which catches up under the kernel lock), and
/// the victim's CPU waiting for the lock or for an answer waits for the other's turn.
/// (Seen once in CI on two CPUs: 54.7 us in `attack_root_paths`, whose worst on one CPU
/// is 17.5 us.)
fn one_cpu_bound(o: &xtask::qemu::Outcome) -> u64 {
    if o.line("cpu 1 online").is_some() {
        multicore_bound_ns(1)
    } else {
        LATENESS_BOUND_NS
    }
}

/// `victim: windows=N missed=M drift=D late_ns max=X mean=Y last=Z` → (N, M, D, X).
fn victim_summary(line: &str) -> Option<(u64, u64, u64, u64)> {
    let field = |name: &str| {
        line.split_whitespace()
            .find_map(|w| w.strip_prefix(name))
            .and_then(|v| v.parse::<u64>().ok())
    };
    Some((
        field("windows=")?,
        field("missed=")?,
        field("drift=")?,
        field("max=")?,
    ))
}

#[test]
fn syscall_fuzz() {
    let o = boot("syscall_fuzz");
    kernel_held(&o);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    let done = o.line("fuzz: done: ");
    check(
        &o,
        done.is_some_and(|l| l.contains("1000000 calls")),
        "the fuzzer did not finish its 1,000,000 calls before the victim's last window",
    );
    // Every call returned (a histogram row per call number the fuzzer used) and the kernel
    // said no to most of them.
    check(
        &o,
        o.lines
            .iter()
            .filter(|l| l.contains("fuzz: ") && l.contains(" n="))
            .count()
            >= 30,
        "the histogram misses calls",
    );
    victim_kept_its_windows(&o, 1_000, one_cpu_bound(&o));
}

/// syscall_fuzz with a fuzzer on each of two CPUs: the kernel's lock and cross-CPU paths
/// under random calls from both at once.
#[test]
fn syscall_fuzz_smp() {
    let o = boot("syscall_fuzz_smp");
    kernel_held(&o);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    for fuzzer in ["fuzz-0", "fuzz-1"] {
        check(
            &o,
            o.lines.iter().any(|l| {
                l.contains(&format!("[{fuzzer}] fuzz: done: ")) && l.contains("1000000 calls")
            }),
            &format!("{fuzzer} did not finish its 1,000,000 calls before the victim's last window"),
        );
    }
    for line in o.lines.iter().filter(|l| l.contains("victim: windows=")) {
        eprintln!("{line}");
    }
    // Both CPUs attacked: measured 48 to 58 us late at most, mean 8 us (docs/isolation.md).
    victim_kept_its_windows(&o, 1_500, multicore_bound_ns(2));
}

#[test]
fn syscall_fuzz_root() {
    let o = boot("syscall_fuzz_root");
    kernel_held(&o);
    check(
        &o,
        o.line("fuzz: done: 1000000 calls").is_some(),
        "the fuzzer did not finish its 1,000,000 calls",
    );
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the fuzzer ends the run",
    );
}

/// The kernel neither panicked nor took an exception in kernel mode.
fn kernel_held(o: &xtask::qemu::Outcome) {
    check(o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    check(
        o,
        o.line("fatal exception").is_none(),
        "an exception in kernel mode",
    );
}

/// The victim logged all its windows, missed none, each started within the bound, and the
/// kernel reported each window's start exactly on the ideal sequence (first start plus
/// whole major frames: no drift).
fn victim_kept_its_windows(o: &xtask::qemu::Outcome, windows: u64, bound_ns: u64) {
    let summaries: Vec<(u64, u64, u64, u64)> = o
        .lines
        .iter()
        .filter(|l| l.contains("victim: windows="))
        .filter_map(|l| victim_summary(l))
        .collect();
    let last = summaries.last().copied();
    check(
        o,
        o.line("victim: created a thread").is_some()
            && o.line(&format!("victim: created {windows} threads, 0 refused"))
                .is_some(),
        "the victim could not create a thread in each window and at its end",
    );
    check(
        o,
        last.is_some_and(|(logged, _, _, _)| logged == windows),
        &format!("the victim did not log its {windows} windows"),
    );
    for (windows, missed, drift, max) in summaries {
        check(
            o,
            missed == 0,
            &format!("the victim missed {missed} windows of {windows}"),
        );
        check(
            o,
            drift == 0,
            &format!("{drift} of {windows} window starts off the ideal sequence"),
        );
        check(
            o,
            max <= bound_ns,
            &format!("a victim window started {max} ns late (bound {bound_ns})"),
        );
    }
}

#[test]
fn attack_floods() {
    let o = boot("attack_floods");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    check(
        &o,
        o.lines
            .iter()
            .filter(|l| l.contains("[flood-log] LLLL"))
            .count()
            > 1_000,
        "the attacker did not flood the log",
    );
    // The hoarder got some of each object, then QuotaExceeded for each kind; the victim
    // still created a thread (checked with its windows below).
    let hoard = o.line("hoard: tasks=");
    check(
        &o,
        hoard.is_some_and(|l| {
            l.contains("then QuotaExceeded QuotaExceeded QuotaExceeded")
                && !l.contains("=0 ")
                && !l.contains("maps=0,")
        }),
        "the hoarder did not exhaust each kind of its quota",
    );
    // syssw answered every request for a port of another partition with an error.
    let forged = o
        .lines
        .iter()
        .rev()
        .filter_map(|l| l.split("forge: ").nth(1))
        .filter_map(|r| {
            let mut words = r.split_whitespace();
            let sent = words.next()?.parse::<u64>().ok()?;
            let accepted = words.nth(1)?.parse::<u64>().ok()?;
            Some((sent, accepted))
        })
        .next();
    check(
        &o,
        forged.is_some_and(|(sent, accepted)| sent >= 10_000 && accepted == 0),
        &format!("syssw accepted forged requests (sent, accepted) = {forged:?}"),
    );
    // Error reports and a mode change whose words name the victim are the forger's own:
    // each report is charged to it, and IDLE stops it, never the victim.
    let reports: Vec<&String> = o
        .lines
        .iter()
        .filter(|l| l.contains("health: ") && l.contains("error=application_error"))
        .collect();
    check(
        &o,
        reports.len() >= 4
            && reports
                .iter()
                .all(|l| l.contains("partition=forge ") && l.contains("action=ignore")),
        "the forged error reports were not all charged to the forger",
    );
    check(
        &o,
        o.line("syssw: partition forge: IDLE").is_some()
            && o.line("forge: still running after IDLE").is_none()
            && o.lines
                .iter()
                .all(|l| !l.contains("syssw: partition victim-200: IDLE")),
        "IDLE with words naming the victim did not stop the forger alone",
    );
    victim_kept_its_windows(&o, 200, one_cpu_bound(&o));
}

#[test]
fn attack_map() {
    let o = boot("attack_map");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    check(
        &o,
        o.line(&format!(
            "flood-map: 1000 rounds of {} pages",
            abi::syscall::MAP_MAX_PAGES
        ))
        .is_some()
            && o.line("flood-map: a call failed").is_none(),
        "the attacker did not map, protect and unmap the most pages a call takes",
    );
    victim_kept_its_windows(&o, 200, one_cpu_bound(&o));
}

#[test]
fn attack_partitions() {
    let o = boot("attack_partitions");
    kernel_held(&o);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    let health = |partition: &str, error: &str| {
        o.lines
            .iter()
            .filter(|l| {
                l.contains("health: ")
                    && l.contains(&format!("partition={partition} error={error} "))
            })
            .count()
    };
    // Each read and each write of a kernel port or an ungranted one faulted (24 warm
    // restarts), none was reached.
    check(
        &o,
        o.line("ports: all 24 accesses faulted").is_some() && o.line("did not fault").is_none(),
        "a kernel or ungranted port was reachable",
    );
    check(
        &o,
        health("ports", "illegal_request") == 24,
        "one illegal_request per port access",
    );
    check(
        &o,
        health("overflow", "stack_overflow") == 1 && o.line("overflow: returned").is_none(),
        "the stack overflow was not caught as stack_overflow",
    );
    // The fault loop under `ignore`: many threads faulted and were killed, each reported,
    // and the partition itself was never restarted.
    let ignored = health("fault-ignore", "illegal_request");
    check(
        &o,
        ignored >= 1_000
            && o.line("fault-ignore: 500 threads faulted").is_some()
            && o.lines
                .iter()
                .filter(|l| l.contains("partition=fault-ignore "))
                .all(|l| l.contains("action=ignore"))
            && o.lines.iter().all(|l| {
                !(l.contains("syssw: partition fault-ignore:") && l.contains("restart 1"))
            }),
        &format!("{ignored} ignored faults of fault-ignore, or it was restarted"),
    );
    // The restart loop really looped: one restart per window of it at least.
    let restarts = health("fault-loop", "illegal_request");
    check(
        &o,
        restarts >= 900,
        &format!("{restarts} restarts of fault-loop in 1,000 frames"),
    );
    victim_kept_its_windows(&o, 1_000, one_cpu_bound(&o));
}

#[test]
fn attack_io() {
    let o = boot("attack_io");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    check(
        &o,
        o.line("flood-io: 100 rounds of 61440 ports").is_some() && o.line(" failed: ").is_none(),
        "the attacker did not grant its whole port range again and again",
    );
    victim_kept_its_windows(&o, 200, one_cpu_bound(&o));
}

#[test]
fn attack_kill() {
    let o = boot("attack_kill");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    let line = o.line("flood-kill: 1 rounds, each killing a task with ");
    check(
        &o,
        line.is_some_and(|l| l.contains("with 127 threads and 760 page tables"))
            && o.line("flood-kill: 10 rounds").is_some()
            && o.line(" failed: ").is_none(),
        "the attacker did not kill a task with its whole thread quota and 760 page tables again and again",
    );
    victim_kept_its_windows(&o, 200, one_cpu_bound(&o));
}

#[test]
fn attack_root_paths() {
    let o = boot("attack_root_paths");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim thread ends the run",
    );
    check(
        &o,
        o.line("paths: 20 rounds: schedule of 32 windows, 62208 ports granted, a task with 200 threads and 760 page tables killed")
            .is_some()
            && o.line(" failed: ").is_none(),
        "the root task did not make each longest call again and again",
    );
    victim_kept_its_windows(&o, 200, one_cpu_bound(&o));
}

#[test]
fn attack_reach() {
    let o = boot("attack_reach");
    kernel_held(&o);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    // Every read and write of memory not its own faulted as a memory violation.
    let violations = o
        .lines
        .iter()
        .filter(|l| l.contains("health: ") && l.contains("partition=peek "))
        .collect::<Vec<_>>();
    check(
        &o,
        violations.len() == 7
            && violations
                .iter()
                .all(|l| l.contains("error=memory_violation") && l.contains("action=warm_restart"))
            && o.line("did not fault").is_none(),
        "an access to the kernel's or another partition's memory was not a memory violation",
    );
    let maps = o
        .line("peek: all 7 accesses faulted; ")
        .and_then(|l| l.split("faulted; ").nth(1))
        .map(|r| r.split_whitespace().map(str::to_string).collect::<Vec<_>>());
    check(
        &o,
        maps.as_ref().is_some_and(|w| {
            w.len() >= 7 && w[0].parse::<u64>().is_ok_and(|n| n >= 258) && w[6] == "0"
        }),
        &format!("a map into another task or of physical memory was accepted: {maps:?}"),
    );
    // Messages and notifications to every thread id: only syssw's threads (the partition's
    // parent) took any, never the victim's; syssw answered every junk call.
    let flood = o
        .lines
        .iter()
        .rev()
        .find_map(|l| l.split("ipc-flood: ").nth(1))
        .map(|r| r.split_whitespace().map(str::to_string).collect::<Vec<_>>());
    let victim = o
        .line("victim: thread ")
        .and_then(|l| l.split("victim: thread ").nth(1))
        .unwrap_or("?")
        .to_string();
    let taken_by = o
        .lines
        .iter()
        .rev()
        .find_map(|l| l.split("taken by ").nth(1))
        .unwrap_or("");
    check(
        &o,
        flood.as_ref().is_some_and(|w| {
            w.len() >= 7
                && w[0].parse::<u64>().is_ok_and(|n| n >= 20_000)
                && w[6].parse::<u64>().is_ok_and(|n| n >= 5_000)
        }) && victim.starts_with("0x")
            && !taken_by.split_whitespace().any(|id| id == victim),
        &format!("the IPC flood reached the victim ({victim}) or did not run: {flood:?}"),
    );
    check(
        &o,
        o.lines
            .iter()
            .filter(|l| l.contains("spin: spinning at priority"))
            .count()
            == 2,
        "the spinners did not raise themselves to their maximum priority",
    );
    // Spinning and refused IPC are no errors: the health monitor has nothing to say.
    check(
        &o,
        o.lines.iter().all(|l| {
            !(l.contains("health: ")
                && ["spin", "spin-bg", "ipc-flood"]
                    .iter()
                    .any(|p| l.contains(&format!("partition={p} "))))
        }),
        "a health monitor line for a spinner or the IPC flood",
    );
    victim_kept_its_windows(&o, 300, one_cpu_bound(&o));
}

#[test]
fn attack_restart() {
    let o = boot("attack_restart");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    let restarts = o
        .lines
        .iter()
        .filter(|l| {
            l.contains("health: ")
                && l.contains("partition=kill-loop error=illegal_request ")
                && l.contains("action=cold_restart")
        })
        .count();
    check(
        &o,
        restarts >= 20
            && o.line("kill-loop: a child with 127 threads and 760 page tables, faulting")
                .is_some(),
        &format!("{restarts} restarts of kill-loop with its whole tree"),
    );
    victim_kept_its_windows(&o, 200, one_cpu_bound(&o));
}

#[test]
fn attack_late_faults() {
    let o = boot("attack_late_faults");
    kernel_held(&o);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): a victim ends the run",
    );
    let health = |partition: &str, error: &str, action: &str| {
        o.lines
            .iter()
            .filter(|l| {
                l.contains("health: ")
                    && l.contains(&format!("partition={partition} error={error} "))
                    && l.contains(&format!("action={action}"))
            })
            .count()
    };
    // A fault at the end of nearly every window of each: 300 frames.
    let (ud2, reads) = (
        health("late-fault", "illegal_request", "ignore"),
        health("late-fault", "memory_violation", "ignore"),
    );
    check(
        &o,
        ud2 >= 140 && reads >= 140 && o.line("late-fault: 200 faults").is_some(),
        &format!("{ud2} ud2 and {reads} kernel reads of late-fault reported"),
    );
    let restarts = health("late-restart", "illegal_request", "cold_restart");
    check(
        &o,
        restarts >= 250,
        &format!("{restarts} restarts of late-restart in 300 frames"),
    );
    victim_kept_its_windows(&o, 300, one_cpu_bound(&o));
}

/// A victim alone on CPU 0 keeps its windows within the bound for one attacked CPU while
/// the attacks of `attack_floods` and `attack_partitions` run on CPU 1 in windows
/// overlapping its own (`tests/configs/smp_isolation.toml`).
#[test]
fn smp_isolation() {
    let o = boot("smp_isolation");
    kernel_held(&o);
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    for line in o.lines.iter().filter(|l| l.contains("victim: windows=")) {
        eprintln!("{line}");
    }
    // Only CPU 1 attacked: measured 33 us late at most (docs/isolation.md).
    victim_kept_its_windows(&o, 1_000, multicore_bound_ns(1));
}
