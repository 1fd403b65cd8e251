//! Scenario guest_rust_std: the Rust std program `linux-rust-std` (tests/linux/rust-std,
//! static with musl) prints in the guest what it prints on this machine.

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
