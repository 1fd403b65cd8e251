//! `cargo xtask lint`: the lint gate CI runs before the tests. Formatting (`cargo fmt
//! --check`) and clippy with every warning an error, on each kind of code the workspace
//! builds: the host crates (with their tests), the host-tested libraries of the kernel, the
//! APEX runtime, the plant, the PLC runtime and the guest, the kernel for `x86_64-unknown-none`, the loader for
//! `x86_64-unknown-uefi`, and syssw and every user program for the user target. The lint
//! policy itself lives once, in `[workspace.lints]` of the root `Cargo.toml`; this only runs
//! it everywhere. It also holds the kernel to its size budget: [`KERNEL_CODE_LINES`] code
//! lines in `kernel/src` (what everyone must trust stays small enough to read).

use anyhow::{Context, Result};
use std::path::Path;

/// The most code lines `kernel/src` may have: lines that are neither blank nor only a
/// comment, without the host-test modules (`#[cfg(test)] mod ...` to the end of a file).
/// What the shipped kernel does not contain lives outside `kernel/src` and is not counted:
/// the host tests (`kernel/host-tests`) and the scenario images' test hooks
/// (`kernel/test-hooks.rs`, feature `test-hooks`).
pub const KERNEL_CODE_LINES: usize = 6_000;

/// Runs every check (all of them, even after a failure, so one run shows everything) and
/// returns whether all passed.
pub fn run() -> Result<bool> {
    crate::tools::ensure_rust_targets()?;
    // syssw, the user programs, and the libraries only the a653rs-linux examples link.
    let mut user: Vec<String> = vec!["syssw".into(), "a653rs-compat".into()];
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
        vec!["clippy", "-p", "user-rt", "--lib", "--tests"],
        vec![
            "clippy",
            "-p",
            "a653rs-compat",
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
    let kernel = kernel_code_lines(&crate::workspace_root().join("kernel/src"))?;
    if kernel > KERNEL_CODE_LINES {
        eprintln!(
            "xtask: lint FAILED: kernel/src has {kernel} code lines, more than its budget of {KERNEL_CODE_LINES}: move policy to syssw or a partition"
        );
        ok = false;
    } else {
        eprintln!("xtask: kernel/src has {kernel} code lines (budget {KERNEL_CODE_LINES})");
    }
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

/// Code lines of the Rust files below `dir` (see [`KERNEL_CODE_LINES`]).
pub fn kernel_code_lines(dir: &Path) -> Result<usize> {
    let mut total = 0;
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))? {
        let path = entry?.path();
        if path.is_dir() {
            total += kernel_code_lines(&path)?;
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            total += code_lines(&text);
        }
    }
    Ok(total)
}

/// Lines of `text` that are neither blank nor only a comment, up to a `#[cfg(test)]` that
/// opens a module (host tests, which the kernel binary does not contain).
fn code_lines(text: &str) -> usize {
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let mut count = 0;
    while let Some(line) = lines.next() {
        if line == "#[cfg(test)]" {
            if lines
                .clone()
                .next()
                .is_some_and(|next| next.starts_with("mod "))
            {
                break;
            }
        } else if line.starts_with("//") {
            continue;
        }
        count += 1;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn code_lines_skip_blanks_comments_and_test_modules() {
        let text = "//! doc\n\nfn a() {\n    // why\n    b();\n}\n#[cfg(test)]\nfn helper() {}\n\n#[cfg(test)]\nmod tests {\n    fn t() {}\n}\n";
        // fn a, b(), }, #[cfg(test)], fn helper
        assert_eq!(code_lines(text), 5);
    }

    #[test]
    fn the_kernel_is_within_its_budget() {
        let lines = kernel_code_lines(&crate::workspace_root().join("kernel/src")).unwrap();
        assert!(lines > 1_000, "counted {lines}: the walk missed the kernel");
        assert!(
            lines <= KERNEL_CODE_LINES,
            "kernel/src has {lines} code lines, budget {KERNEL_CODE_LINES}"
        );
    }
}
