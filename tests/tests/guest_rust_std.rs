//! Scenario guest_rust_std: the Rust std program `linux-rust-std` (tests/linux/rust-std,
//! static with musl) prints in the guest what it prints on this machine.

use scenarios::{boot, check, guest_stdout, partition_lines};
use std::process::Command;

#[test]
fn guest_rust_std() {
    // `cargo xtask test` built it for the image (`guest.programs`).
    let program = xtask::linux::build("linux-rust-std").unwrap_or_else(|e| panic!("{e:#}"));
    let host = Command::new(&program)
        .arg(std::env::temp_dir())
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", program.display()));
    assert!(host.status.success(), "on the host: {host:?}");
    let expected: Vec<String> = String::from_utf8_lossy(&host.stdout)
        .lines()
        .map(str::to_string)
        .collect();

    let o = boot("guest_rust_std");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let printed = guest_stdout(&o, "rust");
    check(
        &o,
        printed == expected,
        &format!("the guest printed {printed:#?}, the host {expected:#?}"),
    );
    for needle in ["unsupported system call", "killed by signal", " stderr: "] {
        let found = partition_lines(&o, "rust", needle);
        check(&o, found.is_empty(), &format!("{needle:?}: {found:?}"));
    }
    check(
        &o,
        !partition_lines(&o, "rust", "guest: init exited with status 0").is_empty(),
        "the program did not exit with status 0",
    );
    check(&o, o.succeeded(), "expected success exit (33)");
}
