//! Builds the bare-metal artifacts: the UEFI loader, the kernel and syssw, each for its target.

use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::process::Command;

/// What goes into an ESP besides the system image's other entries.
#[derive(Clone, Debug)]
pub struct Artifacts {
    pub loader: PathBuf,
    pub kernel: PathBuf,
    pub syssw: PathBuf,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelVariant {
    /// The image users run: no test code at all.
    Production,
    /// With `test-hooks` (scenario images only); built in its own target directory so the
    /// production kernel is never overwritten by it.
    TestHooks,
}

/// `cargo` (the one running xtask, if any) with the workspace root as working directory.
pub fn cargo() -> Command {
    let mut cmd = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cmd.current_dir(crate::workspace_root());
    cmd
}

fn run(mut cmd: Command, what: &str) -> Result<()> {
    let status = cmd
        .status()
        .with_context(|| format!("cannot run cargo to build {what}"))?;
    if !status.success() {
        bail!("building {what} failed ({status})");
    }
    Ok(())
}

pub fn build(release: bool, variant: KernelVariant) -> Result<Artifacts> {
    crate::tools::ensure_rust_targets()?;
    let profile = if release { "release" } else { "debug" };
    let target = crate::target_dir();

    let mut cmd = cargo();
    cmd.args([
        "build",
        "--quiet",
        "-p",
        "loader",
        "--target",
        "x86_64-unknown-uefi",
    ]);
    if release {
        cmd.arg("--release");
    }
    run(cmd, "the UEFI loader")?;

    let kernel_target = match variant {
        KernelVariant::Production => target.clone(),
        KernelVariant::TestHooks => target.join("test-hooks"),
    };
    let mut cmd = cargo();
    cmd.args([
        "build",
        "--quiet",
        "-p",
        "kernel",
        "--target",
        "x86_64-unknown-none",
        "--target-dir",
    ]);
    cmd.arg(&kernel_target);
    if release {
        cmd.arg("--release");
    }
    if variant == KernelVariant::TestHooks {
        cmd.args(["--features", "test-hooks"]);
    }
    run(cmd, "the kernel")?;

    let mut cmd = cargo();
    cmd.args(["build", "--quiet", "-p", "syssw", "--profile", "user"]);
    run(cmd, "syssw")?;

    Ok(Artifacts {
        loader: target
            .join("x86_64-unknown-uefi")
            .join(profile)
            .join("loader.efi"),
        kernel: kernel_target
            .join("x86_64-unknown-none")
            .join(profile)
            .join("kernel"),
        syssw: target.join("user").join("syssw"),
    })
}

/// Builds user-mode programs (syssw's kind of binary: freestanding static ELF, `user`
/// profile) by package name and returns their paths, in order.
pub fn build_user_programs(packages: &[String]) -> Result<Vec<PathBuf>> {
    if packages.is_empty() {
        return Ok(Vec::new());
    }
    let mut cmd = cargo();
    cmd.args(["build", "--quiet", "--profile", "user"]);
    for p in packages {
        cmd.args(["-p", p]);
    }
    run(cmd, &format!("user programs {}", packages.join(", ")))?;
    Ok(packages
        .iter()
        .map(|p| crate::target_dir().join("user").join(p))
        .collect())
}

/// Builds the soft-PLC partition program with the native execution tier: the feature
/// `native` and the generated programs file `programs` (see `plc::native_programs`), in its
/// own target directory (`target/plc-native/`, so the interpreter-only binary is never
/// overwritten); returns its path.
pub fn build_native_softplc(programs: &std::path::Path) -> Result<PathBuf> {
    let target = crate::target_dir().join("plc-native");
    let mut cmd = cargo();
    cmd.args([
        "build",
        "--quiet",
        "--profile",
        "user",
        "-p",
        crate::plc::SOFTPLC_IMAGE,
        "--features",
        "native",
        "--target-dir",
    ]);
    cmd.arg(&target).env("PLC_NATIVE_PROGRAMS", programs);
    run(cmd, "the soft-PLC partition with its native programs")?;
    Ok(target.join("user").join(crate::plc::SOFTPLC_IMAGE))
}
