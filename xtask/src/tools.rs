//! Finds (or installs) what running the system needs: QEMU, OVMF, the Rust targets.
//! When something is missing it is installed when that is possible without asking
//! (root with apt-get); otherwise the error says the exact command to run.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

pub const APT_PACKAGES: &[&str] = &["qemu-system-x86", "ovmf"];
pub const RUST_TARGETS: &[&str] = &["x86_64-unknown-uefi", "x86_64-unknown-none"];

/// Paths of QEMU and the OVMF firmware pair.
#[derive(Clone, Debug)]
pub struct Qemu {
    pub binary: PathBuf,
    pub ovmf_code: PathBuf,
    pub ovmf_vars: PathBuf,
}

fn find_in_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| p.is_file())
}

/// (code, vars) pairs in the places Debian/Ubuntu/Fedora packages put them.
fn find_ovmf() -> Option<(PathBuf, PathBuf)> {
    const PAIRS: &[(&str, &str)] = &[
        (
            "/usr/share/OVMF/OVMF_CODE.fd",
            "/usr/share/OVMF/OVMF_VARS.fd",
        ),
        (
            "/usr/share/OVMF/OVMF_CODE_4M.fd",
            "/usr/share/OVMF/OVMF_VARS_4M.fd",
        ),
        (
            "/usr/share/edk2/ovmf/OVMF_CODE.fd",
            "/usr/share/edk2/ovmf/OVMF_VARS.fd",
        ),
        (
            "/usr/share/edk2-ovmf/x64/OVMF_CODE.fd",
            "/usr/share/edk2-ovmf/x64/OVMF_VARS.fd",
        ),
    ];
    PAIRS
        .iter()
        .map(|(c, v)| (Path::new(c), Path::new(v)))
        .find(|(c, v)| c.is_file() && v.is_file())
        .map(|(c, v)| (c.to_path_buf(), v.to_path_buf()))
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

fn install_packages() -> Result<()> {
    let install = format!("apt-get install -y {}", APT_PACKAGES.join(" "));
    if !is_root() || find_in_path("apt-get").is_none() {
        bail!(
            "QEMU and/or OVMF are missing. Install them with:\n    sudo apt-get update && sudo {install}\n(or your distribution's qemu-system-x86_64 and OVMF packages)"
        );
    }
    eprintln!("xtask: QEMU/OVMF missing; running apt-get update && {install}");
    let ok = Command::new("apt-get")
        .args(["update", "-qq"])
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
        && Command::new("apt-get")
            .args(["install", "-y", "-qq"])
            .args(APT_PACKAGES)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
    if !ok {
        bail!("installing QEMU/OVMF failed; run `apt-get update && {install}` yourself");
    }
    Ok(())
}

pub fn ensure_qemu() -> Result<Qemu> {
    if find_in_path("qemu-system-x86_64").is_none() || find_ovmf().is_none() {
        install_packages()?;
    }
    let binary =
        find_in_path("qemu-system-x86_64").context("qemu-system-x86_64 still not found in PATH")?;
    let (ovmf_code, ovmf_vars) =
        find_ovmf().context("OVMF firmware still not found (looked in /usr/share/OVMF)")?;
    Ok(Qemu {
        binary,
        ovmf_code,
        ovmf_vars,
    })
}

/// Makes sure rustup has the bare-metal targets (rust-toolchain.toml lists them, but
/// rustup does not always install them on its own, e.g. with RUSTUP_AUTO_INSTALL=0).
pub fn ensure_rust_targets() -> Result<()> {
    let Ok(out) = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .current_dir(crate::workspace_root())
        .output()
    else {
        return Ok(()); // no rustup: assume a toolchain that has the targets
    };
    let installed = String::from_utf8_lossy(&out.stdout);
    let missing: Vec<&str> = RUST_TARGETS
        .iter()
        .copied()
        .filter(|t| !installed.lines().any(|l| l.trim() == *t))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    eprintln!("xtask: installing Rust targets {}", missing.join(", "));
    let status = Command::new("rustup")
        .args(["target", "add"])
        .args(&missing)
        .current_dir(crate::workspace_root())
        .status()
        .context("cannot run rustup")?;
    if !status.success() {
        bail!("`rustup target add {}` failed", missing.join(" "));
    }
    Ok(())
}
