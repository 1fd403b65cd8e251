//! The paravirtualized guest (`partitions/guest`) running Debian's static busybox
//! (configuration `tests/configs/guest_hello.toml`): partition `echo` runs
//! `/bin/busybox echo hello`, partition `cat` runs `/bin/cat /etc/passwd /etc/motd` (the
//! first written by `cargo xtask`, the second `tests/configs/guest/motd.txt` added with
//! `guest.files`), partition `ls` runs `/bin/ls /`, partition `segv` runs a shell function
//! that calls itself until its stack overflows, partition `shell` runs
//! `/bin/sh -c 'echo hello; echo world'`, partition `pipes` runs shell pipelines, a
//! subshell's exit status and a loop of 50 processes.

use scenarios::{boot, check, guest_stdout, partition_lines};

#[test]
fn guest_hello() {
    let o = boot("guest_hello");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the shell guest's init ends the run",
    );
    for (partition, command, output) in [
        ("echo", "/bin/busybox echo hello", &["hello"][..]),
        (
            "cat",
            "/bin/cat /etc/passwd /etc/motd",
            &[
                "root:x:0:0:root:/root:/bin/sh",
                "Welcome to the Warden guest.",
            ][..],
        ),
        // The initramfs's root (xtask/src/guest.rs), one name a line: stdout is no terminal.
        (
            "ls",
            "/bin/ls /",
            &[
                "bin", "dev", "etc", "init", "proc", "root", "sbin", "tmp", "usr",
            ][..],
        ),
        (
            "shell",
            "/bin/sh -c echo hello; echo world",
            &["hello", "world"][..],
        ),
    ] {
        let started = partition_lines(&o, partition, "started: ");
        check(
            &o,
            started == [format!("guest: process 1 (busybox) started: {command}")],
            &format!("{partition}: start line {started:?}"),
        );
        let printed = partition_lines(&o, partition, "guest: process 1 std");
        let expected: Vec<String> = output
            .iter()
            .map(|line| format!("guest: process 1 stdout: {line}"))
            .collect();
        check(
            &o,
            printed == expected,
            &format!("{partition}: printed {printed:?}, expected {expected:?}"),
        );
        let exits = partition_lines(&o, partition, "guest: process 1 exited");
        check(
            &o,
            exits == ["guest: process 1 exited with status 0"],
            &format!("{partition}: exit lines {exits:?}"),
        );
        let unsupported = partition_lines(&o, partition, "unsupported system call");
        check(
            &o,
            unsupported.is_empty(),
            &format!("{partition}: busybox needed calls the guest lacks: {unsupported:?}"),
        );
        check(
            &o,
            partition_lines(&o, partition, "killed by signal").is_empty(),
            &format!("{partition}: a process was killed"),
        );
    }
    // Processes and pipes: each line comes out of the pipeline's last process, in order;
    // the subshell's exit status reaches `$?`; the loop ran 50 processes, each forked and
    // executing /bin/true; no process is left (every one was reaped).
    let printed: Vec<String> = partition_lines(&o, "pipes", " stdout: ")
        .iter()
        .map(|l| {
            l.split_once(" stdout: ")
                .map(|(_, t)| t.to_string())
                .unwrap_or_default()
        })
        .collect();
    check(
        &o,
        printed == ["one", "two", "9", "status 3", "ran 50"],
        &format!("pipes: printed {printed:?}"),
    );
    let trues = partition_lines(&o, "pipes", "(busybox) started: /bin/true");
    check(
        &o,
        trues.len() == 50,
        &format!("pipes: {} /bin/true processes", trues.len()),
    );
    let forks = partition_lines(&o, "pipes", " forked from 1: ");
    check(
        &o,
        forks.len() >= 50 + 5,
        &format!("pipes: {} forks", forks.len()),
    );
    let subshell = partition_lines(&o, "pipes", "exited with status 3");
    check(
        &o,
        subshell.len() == 1 && !subshell[0].starts_with("guest: process 1 "),
        &format!("pipes: the subshell's exit {subshell:?}"),
    );
    for (needle, expected) in [
        (
            "guest: init ended with",
            "guest: init ended with 0 other processes left",
        ),
        ("guest: init exited", "guest: init exited with status 0"),
    ] {
        let lines = partition_lines(&o, "pipes", needle);
        check(&o, lines == [expected], &format!("pipes: {lines:?}"));
    }
    for needle in ["unsupported system call", "killed by signal", "cannot"] {
        let lines = partition_lines(&o, "pipes", needle);
        check(&o, lines.is_empty(), &format!("pipes: {lines:?}"));
    }
    // The overflowing stack: the page fault just below the process's stack kills it with
    // SIGSEGV (memory::STACK_TOP - STACK_SIZE = 0x7fff_ffec_0000), nothing else.
    let started = partition_lines(&o, "segv", "started: ");
    check(
        &o,
        started == ["guest: process 1 (busybox) started: /bin/sh -c f() { f; }; f"],
        &format!("segv: start line {started:?}"),
    );
    let killed = partition_lines(&o, "segv", "guest: process 1 (busybox) killed by signal");
    check(
        &o,
        killed.len() == 1
            && killed[0].starts_with(
                "guest: process 1 (busybox) killed by signal 11 (SIGSEGV): vector 14 error 0x6 address 0x7fffffebf",
            ),
        &format!("segv: {killed:?}"),
    );
    check(
        &o,
        partition_lines(&o, "segv", "guest: process 1 exited").is_empty(),
        "segv: a killed process has no exit status line",
    );
    check(
        &o,
        o.line("partition=segv error=application_error detail=\"init\\x20killed\\x20by\\x20signal\\x2011\"")
            .is_some(),
        "segv: no health report of its init's death",
    );
    // Each guest reported its init's end to the health monitor.
    for partition in ["echo", "cat", "pipes", "ls", "shell"] {
        check(
            &o,
            o.lines
                .iter()
                .any(|l| l.contains(&format!("partition={partition} error=application_error"))),
            &format!("no health report of {partition}'s init ending"),
        );
    }
}

/// Checks what every guest scenario script must show: success, no panic, no call the guest
/// lacks, init exited with status 0 leaving no process.
fn script_ran(o: &xtask::qemu::Outcome, partition: &str) {
    check(o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        o,
        o.succeeded(),
        "expected success exit (33): the script's end ends the run",
    );
    let unsupported = partition_lines(o, partition, "unsupported system call");
    check(
        o,
        unsupported.is_empty(),
        &format!("calls the guest lacks: {unsupported:?}"),
    );
    for (needle, expected) in [
        (
            "guest: init ended with",
            "guest: init ended with 0 other processes left",
        ),
        ("guest: init exited", "guest: init exited with status 0"),
    ] {
        let lines = partition_lines(o, partition, needle);
        check(o, lines == [expected], &format!("{partition}: {lines:?}"));
    }
}

#[test]
fn guest_signals() {
    let o = boot("guest_signals");
    script_ran(&o, "signals");
    let printed = guest_stdout(&o, "signals");
    let expected = [
        "caught USR1",
        "after trap",
        "slept",
        "self-kill status 143",
        "child caught INT",
        "child goes on",
        "sleep killed status 143",
        "stopped then killed status 137",
        "y",
        "y",
        "pipeline status 0",
        "alarm rang",
        "after alarm",
        "busy loop interrupted",
        "busy status 3",
        "done",
    ];
    check(&o, printed == expected, &format!("printed {printed:?}"));
    for (signal, count) in [("15 (SIGTERM)", 2), ("9 (SIGKILL)", 1), ("13 (SIGPIPE)", 1)] {
        let killed = partition_lines(&o, "signals", &format!("killed by signal {signal}"));
        check(&o, killed.len() == count, &format!("{signal}: {killed:?}"));
    }
}

#[test]
fn guest_processes() {
    let o = boot("guest_processes");
    script_ran(&o, "processes");
    let printed = guest_stdout(&o, "processes");
    let expected = [
        "ran 200 processes",
        "more than forty at once",
        "forty in parallel reaped",
        "orphan started",
        "its parent is gone",
        "ran 20 processes beside a busy one",
        "the busy one ended with 143",
        "done",
    ];
    check(&o, printed == expected, &format!("printed {printed:?}"));
    let trues = partition_lines(&o, "processes", "(busybox) started: /bin/true");
    check(
        &o,
        trues.len() == 221,
        &format!("{} /bin/true processes", trues.len()),
    );
    let killed = partition_lines(&o, "processes", "killed by signal");
    check(
        &o,
        killed.len() == 1 && killed[0].ends_with("killed by signal 15 (SIGTERM)"),
        &format!("only the busy process is killed: {killed:?}"),
    );
}

/// Scenario guest_console (`tests/configs/guest_console.toml`): the console of guest
/// `linux` is a terminal on COM2 running an interactive `/bin/sh`; the scenario types
/// commands into it: two `echo`s (one with erased characters), `cat` with a line and a
/// Ctrl-D, `cat` with a Ctrl-C, `cat` with a Ctrl-Z then `fg`, a line and a Ctrl-D, `cat &`
/// then `fg`, a line and a Ctrl-D, a Ctrl-D at the prompt.
#[test]
fn guest_console() {
    let o = boot("guest_console");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the shell's end ends the run",
    );
    let lines = o.console_lines();
    let has = |text: &str| lines.contains(&text);
    // The shell's line editor erased two characters of "typo" before "pe".
    for expected in ["hello from the console", "type"] {
        check(&o, has(expected), &format!("console: no line {expected:?}"));
    }
    // `cat` read through the canonical line discipline: the terminal echoed what was
    // typed, erase included, then cat wrote the edited line.
    check(
        &o,
        o.console.contains("one tw\x08 \x08o\r\none to\r\n"),
        "console: cat's echoed and edited line",
    );
    check(
        &o,
        !has("typo"),
        "console: the erased characters reached the shell",
    );
    // The Ctrl-C: the shell had made the second `cat` the foreground process group.
    check(
        &o,
        partition_lines(&o, "linux", "killed by signal")
            == ["guest: process 3 (busybox) killed by signal 2 (SIGINT)"],
        "the Ctrl-C killed the second cat",
    );
    check(&o, o.console.contains("^C"), "console: the echoed ^C");
    // The Ctrl-Z stopped the third `cat` (SIGTSTP), `fg` made it the foreground again and
    // continued it: it read a line and ended at its Ctrl-D.
    check(
        &o,
        o.console
            .contains("^Z[1]+  Stopped                    cat\r\n"),
        "console: the shell's job report of the stopped cat",
    );
    check(
        &o,
        o.console.contains("back\r\nback\r\n"),
        "console: the continued cat's echoed and copied line",
    );
    check(
        &o,
        partition_lines(&o, "linux", "guest: process 4 exited with status 0").len() == 1,
        "the continued cat ended",
    );
    // `cat &` read the terminal in the background: SIGTTIN stopped it (the shell's job
    // report at a later prompt) until `fg` brought it to the foreground.
    check(
        &o,
        o.console
            .contains("[1]+  Stopped (tty input)        cat\r\n"),
        "console: the background cat stopped by SIGTTIN",
    );
    check(
        &o,
        o.console
            .contains("from the background\r\nfrom the background\r\n"),
        "console: the foreground cat's echoed and copied line",
    );
    check(
        &o,
        partition_lines(&o, "linux", "guest: process 5 exited with status 0").len() == 1,
        "the background cat ended",
    );
    check(
        &o,
        partition_lines(&o, "linux", "guest: init exited with status 0").len() == 1,
        "the shell ended at the Ctrl-D",
    );
    check(
        &o,
        partition_lines(&o, "linux", "guest: process 1 stdout").is_empty(),
        "the console's output went to COM2, not the log",
    );
}

/// Scenario guest_restart (`tests/configs/guest_restart.toml`): guest `reboot`'s init
/// prints `booted` and exits; the health monitor cold-restarts the guest each time.
#[test]
fn guest_restart() {
    let o = boot("guest_restart");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): guest `timer` ends the run",
    );
    let boots = guest_stdout(&o, "reboot");
    check(
        &o,
        boots.len() >= 3 && boots.iter().all(|l| l == "booted"),
        &format!("reboot: {boots:?}"),
    );
    let exits = partition_lines(&o, "reboot", "guest: init exited with status 1");
    check(&o, exits.len() >= 3, &format!("reboot: {exits:?}"));
    let restarts: Vec<&String> = o
        .lines
        .iter()
        .filter(|l| l.contains("syssw: partition reboot: ") && l.contains("restart "))
        .collect();
    check(
        &o,
        restarts.len() >= 3,
        &format!("the health monitor's restarts: {restarts:?}"),
    );
    check(
        &o,
        guest_stdout(&o, "timer") == ["time is up"],
        "the other guest ran on",
    );
    check(
        &o,
        o.lines
            .iter()
            .filter(|l| l.contains("ticker: alive"))
            .count()
            >= 3,
        "the windowed partition kept its windows",
    );
}

/// The kernel's time stamp of the guest's log line of partition `partition` that holds
/// `stdout: <text>`, in ns.
fn stamp_ns(o: &xtask::qemu::Outcome, partition: &str, text: &str) -> Option<u64> {
    let prefix = format!("[{partition}] ");
    let needle = format!(" stdout: {text}");
    let line = o
        .lines
        .iter()
        .find(|l| l.contains(&prefix) && l.ends_with(&needle))?;
    let seconds: f64 = line
        .strip_prefix('[')?
        .split_once(']')?
        .0
        .trim()
        .parse()
        .ok()?;
    Some((seconds * 1e9) as u64)
}

/// Scenario guest_sched (`tests/configs/guest_sched.toml`, virtual time): the guest's
/// scheduling policy (`partitions/guest/src/sched.rs`). Beside a process spinning in user
/// code, 2,000 system calls take about twice as long as alone (the caller is CPU-bound
/// too and shares the CPU in turns; with every process at one priority they took 41 s
/// instead of 0.12 s alone: one call per time slice) and a loop of 20 short processes
/// about as long as alone (21.5 s before); two counters beside the spinner get a third of
/// the CPU each and finish together; a counter beside a busy pipe finishes (aging).
#[test]
fn guest_sched() {
    /// The guest's time slice and how long a CPU-bound process may wait for its turn
    /// while interactive ones keep the CPU (`guest::sched`), in ms.
    const SLICE: f64 = 10.0;
    const STARVATION: f64 = 100.0;
    let o = boot("guest_sched");
    script_ran(&o, "sched");
    let at = |text: &str| {
        let t = stamp_ns(&o, "sched", &format!("sched: {text}"));
        check(&o, t.is_some(), &format!("no line `sched: {text}`"));
        t.unwrap_or(0)
    };
    let ms = |from: u64, to: u64| to.saturating_sub(from) as f64 / 1e6;
    let counter_alone = ms(at("counter alone"), at("counter 0 done"));
    let calls_alone = ms(at("calls alone"), at("calls alone done"));
    let processes_alone = ms(at("calls alone done"), at("processes alone done"));
    let calls_hog = ms(at("calls beside a hog"), at("calls beside a hog done"));
    let processes_hog = ms(
        at("calls beside a hog done"),
        at("processes beside a hog done"),
    );
    let counters = at("counters");
    let (first, second) = (
        ms(counters, at("counter 1 done")),
        ms(counters, at("counter 2 done")),
    );
    let beside_pipe = ms(at("counter beside a busy pipe"), at("counter 3 done"));
    println!(
        "guest_sched (virtual ms): a counter alone {counter_alone:.1}; 2000 calls alone {calls_alone:.1}, beside a hog {calls_hog:.1}; 20 processes alone {processes_alone:.1}, beside a hog {processes_hog:.1}; two counters beside a hog {first:.1} and {second:.1}; a counter beside a busy pipe {beside_pipe:.1}"
    );
    // The calls: interactive for a slice, then in turns with the spinner (which had a
    // slice of its own when it started).
    check(
        &o,
        calls_hog <= 2.0 * calls_alone + 4.0 * SLICE,
        &format!("2000 calls beside a hog took {calls_hog:.1} ms, alone {calls_alone:.1} ms"),
    );
    // The processes wait for their children: interactive, but the spinner ages into a
    // slice after STARVATION of waiting.
    check(
        &o,
        processes_hog <= processes_alone * (1.0 + SLICE / STARVATION) + 2.0 * SLICE,
        &format!(
            "20 processes beside a hog took {processes_hog:.1} ms, alone {processes_alone:.1} ms"
        ),
    );
    // Three CPU-bound processes in turns: a third of the CPU each, together.
    for took in [first, second] {
        check(
            &o,
            took >= 2.0 * counter_alone && took <= 3.0 * counter_alone + 3.0 * SLICE,
            &format!(
                "a counter beside a hog and another took {took:.1} ms, alone {counter_alone:.1} ms"
            ),
        );
    }
    check(
        &o,
        (first - second).abs() <= 2.0 * SLICE,
        &format!("the counters finished {first:.1} and {second:.1} ms after they started"),
    );
    // At least a slice in every STARVATION + SLICE, however busy the pipe.
    let bound = ((counter_alone / SLICE).ceil() + 1.0) * (STARVATION + SLICE);
    check(
        &o,
        beside_pipe <= bound,
        &format!(
            "a counter beside a busy pipe took {beside_pipe:.1} ms (alone {counter_alone:.1} ms)"
        ),
    );
}
