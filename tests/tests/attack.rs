//! Attacks on the kernel and syssw by hostile partitions (`tests/programs/attack`): each is
//! contained, and a victim partition beside the attacker keeps every window.

use scenarios::{boot, check};

/// The victim's window-start lateness asserted while an attacker runs in the window just
/// before its own, on virtual time: the quiet case is about 2 us (the timer interrupt, the
/// window switch and the wake-up from `sleep_until`); the margin is what the issue of
/// bounded kernel paths allows any partition to add (50 us). Measured under the fuzzer:
/// at most 6.5 us.
const LATENESS_BOUND_NS: u64 = 52_000;

/// `victim: windows=N missed=M late_ns max=X mean=Y last=Z` → (N, M, X).
fn victim_summary(line: &str) -> Option<(u64, u64, u64)> {
    let field = |name: &str| {
        line.split_whitespace()
            .find_map(|w| w.strip_prefix(name))
            .and_then(|v| v.parse::<u64>().ok())
    };
    Some((field("windows=")?, field("missed=")?, field("max=")?))
}

#[test]
fn syscall_fuzz() {
    let o = boot("syscall_fuzz");
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    check(
        &o,
        o.line("fatal exception").is_none(),
        "an exception in kernel mode",
    );
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
    victim_kept_its_windows(&o, 1_000);
}

#[test]
fn syscall_fuzz_root() {
    let o = boot("syscall_fuzz_root");
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    check(
        &o,
        o.line("fatal exception").is_none(),
        "an exception in kernel mode",
    );
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

/// The victim logged all its windows, missed none, and each started within the bound.
fn victim_kept_its_windows(o: &xtask::qemu::Outcome, windows: u64) {
    let summaries: Vec<(u64, u64, u64)> = o
        .lines
        .iter()
        .filter(|l| l.contains("victim: windows="))
        .filter_map(|l| victim_summary(l))
        .collect();
    let last = summaries.last().copied();
    check(
        o,
        last.is_some_and(|(logged, _, _)| logged == windows),
        &format!("the victim did not log its {windows} windows"),
    );
    for (windows, missed, max) in summaries {
        check(
            o,
            missed == 0,
            &format!("the victim missed {missed} windows of {windows}"),
        );
        check(
            o,
            max <= LATENESS_BOUND_NS,
            &format!("a victim window started {max} ns late (bound {LATENESS_BOUND_NS})"),
        );
    }
}

#[test]
fn attack_log_flood() {
    let o = boot("attack_log_flood");
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
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
    victim_kept_its_windows(&o, 200);
}
