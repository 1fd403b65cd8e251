//! Scenarios guest_rust_std and guest_go: programs of other language runtimes print in the
//! guest what they print on this machine. `linux-rust-std` (tests/linux/rust-std) is a Rust
//! std program, static with musl; `go-hello` (tests/linux/go/hello.go) a Go program, static,
//! built by the manifest's `prepare` (tests/configs/guest/go-build.sh).

use scenarios::same_output_as_host;
use std::process::Command;

#[test]
fn guest_rust_std() {
    // `cargo xtask test` built it for the image (`guest.programs`).
    let program = xtask::linux::build("linux-rust-std").unwrap_or_else(|e| panic!("{e:#}"));
    same_output_as_host(
        "guest_rust_std",
        "rust",
        Command::new(&program).arg(std::env::temp_dir()),
    );
}

#[test]
fn guest_go() {
    // `cargo xtask test` built it before assembling the image (the manifest's `prepare`).
    let program = xtask::workspace_root().join("target/linux/go-hello");
    let (_, expected) = same_output_as_host(
        "guest_go",
        "go",
        Command::new(&program).arg(std::env::temp_dir()),
    );
    for line in ["workers: [0 1 2 3 4 5 6 7] total: 3200040000", "go: done"] {
        assert!(
            expected.iter().any(|l| l == line),
            "no {line:?} in {expected:#?}"
        );
    }
}
