//! The paravirtualized guest (`partitions/guest`) running Debian's static busybox
//! (configuration `tests/configs/guest_hello.toml`): partition `echo` runs
//! `/bin/busybox echo hello`, partition `cat` runs `/bin/cat /etc/passwd /etc/motd` (the
//! first written by `cargo xtask`, the second `tests/configs/guest/motd.txt` added with
//! `guest.files`), partition `ls` runs `/bin/ls /`, partition `segv` runs a shell function
//! that calls itself until its stack overflows, partition `shell` runs
//! `/bin/sh -c 'echo hello; echo world'`, partition `pipes` runs shell pipelines, a
//! subshell's exit status and a loop of 50 processes.

use scenarios::{boot, check};

/// The text of the guest log lines of partition `partition` that contain `needle`, without
/// the kernel's time stamp and the partition prefix (in log order).
fn guest_lines(o: &xtask::qemu::Outcome, partition: &str, needle: &str) -> Vec<String> {
    let prefix = format!("[{partition}] ");
    o.lines
        .iter()
        .filter_map(|l| l.split_once(&prefix).map(|(_, text)| text.to_string()))
        .filter(|text| text.contains(needle))
        .collect()
}

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
        let started = guest_lines(&o, partition, "started: ");
        check(
            &o,
            started == [format!("guest: process 1 (busybox) started: {command}")],
            &format!("{partition}: start line {started:?}"),
        );
        let printed = guest_lines(&o, partition, "guest: process 1 std");
        let expected: Vec<String> = output
            .iter()
            .map(|line| format!("guest: process 1 stdout: {line}"))
            .collect();
        check(
            &o,
            printed == expected,
            &format!("{partition}: printed {printed:?}, expected {expected:?}"),
        );
        let exits = guest_lines(&o, partition, "guest: process 1 exited");
        check(
            &o,
            exits == ["guest: process 1 exited with status 0"],
            &format!("{partition}: exit lines {exits:?}"),
        );
        let unsupported = guest_lines(&o, partition, "unsupported system call");
        check(
            &o,
            unsupported.is_empty(),
            &format!("{partition}: busybox needed calls the guest lacks: {unsupported:?}"),
        );
        check(
            &o,
            guest_lines(&o, partition, "killed by signal").is_empty(),
            &format!("{partition}: a process was killed"),
        );
    }
    // Processes and pipes: each line comes out of the pipeline's last process, in order;
    // the subshell's exit status reaches `$?`; the loop ran 50 processes, each forked and
    // executing /bin/true; no process is left (every one was reaped).
    let printed: Vec<String> = guest_lines(&o, "pipes", " stdout: ")
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
    let trues = guest_lines(&o, "pipes", "(busybox) started: /bin/true");
    check(
        &o,
        trues.len() == 50,
        &format!("pipes: {} /bin/true processes", trues.len()),
    );
    let forks = guest_lines(&o, "pipes", " forked from 1: ");
    check(
        &o,
        forks.len() >= 50 + 5,
        &format!("pipes: {} forks", forks.len()),
    );
    let subshell = guest_lines(&o, "pipes", "exited with status 3");
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
        let lines = guest_lines(&o, "pipes", needle);
        check(&o, lines == [expected], &format!("pipes: {lines:?}"));
    }
    for needle in ["unsupported system call", "killed by signal", "cannot"] {
        let lines = guest_lines(&o, "pipes", needle);
        check(&o, lines.is_empty(), &format!("pipes: {lines:?}"));
    }
    // The overflowing stack: the page fault just below the process's stack kills it with
    // SIGSEGV (memory::STACK_TOP - STACK_SIZE = 0x7fff_ffec_0000), nothing else.
    let started = guest_lines(&o, "segv", "started: ");
    check(
        &o,
        started == ["guest: process 1 (busybox) started: /bin/sh -c f() { f; }; f"],
        &format!("segv: start line {started:?}"),
    );
    let killed = guest_lines(&o, "segv", "guest: process 1 (busybox) killed by signal");
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
        guest_lines(&o, "segv", "guest: process 1 exited").is_empty(),
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
