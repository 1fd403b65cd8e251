//! The paravirtualized guest's file system and `/proc` under a busybox shell script
//! (configuration `tests/configs/guest_busybox.toml`, script
//! `tests/configs/guest/busybox.sh`): every line the script prints, in order, from
//! whichever process printed it, then its exit status.

use scenarios::{boot, check, guest_stdout, partition_lines};

/// What the script prints, line by line.
const EXPECTED: &[&str] = &[
    "/tmp",
    "date",
    "4",
    "1:banana",
    "bAnAnA",
    "Apple",
    "chars 21",
    "count 3",
    "for one",
    "for two",
    "while 3",
    "test ok",
    "deep",
    "c",
    "moved",
    "a",
    "a/b",
    "a/b/c",
    "a/b/moved",
    "a/link",
    "b/c/file",
    "fruits",
    "src/",
    "src/1.txt",
    "src/sub/",
    "src/sub/numbers",
    "one",
    "100",
    "banana",
    "-rw-r--r-- 1.txt",
    "drwxr-xr-x sub",
    "/bin/busybox",
    "rootfs / rootfs rw 0 0",
    "/bin/sh",
    "/etc/busybox.sh",
    "PID COMMAND",
    // The process name is the executable's (Linux's would be `sh`, the name it was
    // started by: busybox's ps shows the difference in braces).
    "root {busybox} /bin/sh",
    // 13 MB do not fit the file system's 8 MiB or so (half of the heap, a quarter of the
    // pool of a 64 MiB partition).
    "dd 1",
    "again",
    "false 1",
    "subshell 7",
    "sh 3",
];

#[test]
fn guest_busybox() {
    let o = boot("guest_busybox");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let lines = partition_lines(&o, "shell", "");
    let printed = guest_stdout(&o, "shell");
    check(
        &o,
        printed == EXPECTED,
        &format!("printed {printed:#?}, expected {EXPECTED:#?}"),
    );
    for needle in [
        " stderr: ",
        "unsupported system call",
        "killed by signal",
        "cannot",
    ] {
        let found: Vec<&String> = lines.iter().filter(|l| l.contains(needle)).collect();
        check(&o, found.is_empty(), &format!("{needle:?}: {found:?}"));
    }
    for expected in [
        "guest: process 1 exited with status 5",
        "guest: init ended with 0 other processes left",
        "guest: init exited with status 5",
    ] {
        check(
            &o,
            lines.iter().any(|l| l == expected),
            &format!("no line {expected:?}"),
        );
    }
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the guest's init ends the run",
    );
}
