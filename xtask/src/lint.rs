//! `cargo xtask lint`: the lint gate CI runs before the tests. Formatting (`cargo fmt
//! --check`) and clippy with every warning an error, on each kind of code the workspace
//! builds: the host crates (with their tests), the host-tested libraries of the kernel, the
//! APEX runtime, the plant, the PLC runtime and the guest, the kernel for `x86_64-unknown-none`, the loader for
//! `x86_64-unknown-uefi`, and syssw and every user program for the user target. The lint
//! policy itself lives once, in `[workspace.lints]` of the root `Cargo.toml`; this only runs
//! it everywhere.

use anyhow::Result;

/// Runs every check (all of them, even after a failure, so one run shows everything) and
/// returns whether all passed.
pub fn run() -> Result<bool> {
    crate::tools::ensure_rust_targets()?;
    let mut user: Vec<String> = vec!["syssw".into()];
    user.extend(crate::check_config::known_images()?);
    let user_args: Vec<&str> = user.iter().flat_map(|p| ["-p", p.as_str()]).collect();

    let mut checks: Vec<Vec<&str>> = vec![
        vec!["fmt", "--all", "--", "--check"],
        // The host crates: the workspace's default members and the scenario harness.
        vec!["clippy", "--all-targets"],
        vec!["clippy", "-p", "scenarios", "--all-targets"],
        // Pure logic of the bare-metal crates, as `cargo xtask test` builds it on the host.
        vec!["clippy", "-p", "kernel", "--lib", "--tests"],
        vec![
            "clippy",
            "-p",
            "apex",
            "--no-default-features",
            "--lib",
            "--tests",
        ],
        vec![
            "clippy",
            "-p",
            "plant",
            "--no-default-features",
            "--lib",
            "--tests",
        ],
        vec![
            "clippy",
            "-p",
            "softplc",
            "--no-default-features",
            "--lib",
            "--tests",
        ],
        vec![
            "clippy",
            "-p",
            "guest",
            "--no-default-features",
            "--lib",
            "--tests",
        ],
        // The targets that run under QEMU.
        vec!["clippy", "-p", "kernel", "--target", "x86_64-unknown-none"],
        vec!["clippy", "-p", "loader", "--target", "x86_64-unknown-uefi"],
    ];
    let mut user_check = vec!["clippy", "--profile", "user"];
    user_check.extend(user_args);
    checks.push(user_check);

    let mut ok = true;
    for mut args in checks {
        if args[0] == "clippy" {
            args.extend(["--", "-D", "warnings"]);
        }
        eprintln!("xtask: cargo {}", args.join(" "));
        let status = crate::artifacts::cargo().args(&args).status()?;
        if !status.success() {
            eprintln!("xtask: lint FAILED: cargo {}", args.join(" "));
            ok = false;
        }
    }
    Ok(ok)
}
