//! Finds (or installs) what running the system needs: QEMU, OVMF, the Rust targets, and
//! for guest partitions Debian's static busybox.
//! When something is missing it is installed when that is possible without asking
//! (root with apt-get); otherwise the error says the exact command to run.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

pub const APT_PACKAGES: &[&str] = &["qemu-system-x86", "ovmf"];
/// The package of the static busybox a guest's initramfs holds.
pub const BUSYBOX_PACKAGE: &str = "busybox-static";
/// Where Debian's `busybox-static` installs it.
pub const BUSYBOX_PATHS: &[&str] = &["/bin/busybox", "/usr/bin/busybox"];
pub const RUST_TARGETS: &[&str] = &[
    "x86_64-unknown-uefi",
    "x86_64-unknown-none",
    crate::linux::MUSL_TARGET,
];

/// The oldest QEMU whose deterministic time (`-icount`, the scenarios' and benchmarks')
/// is fair to several CPUs: from 8.1 its round robin splits the time to the next timer
/// deadline among the CPUs, before (7.2 is Debian 12's own) the CPU whose turn it is keeps
/// all of it, so a busy CPU 1 made the PLC on CPU 0 release up to 175 us late.
pub const QEMU_DETERMINISTIC_MIN: (u32, u32) = (8, 1);
/// Where Debian 12 gets a newer QEMU.
const BACKPORTS_LIST: &str = "/etc/apt/sources.list.d/bookworm-backports.list";
const BACKPORTS_LINE: &str = "deb http://deb.debian.org/debian bookworm-backports main";

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

/// Installs `packages` with apt-get when running as root; otherwise (or if that fails) the
/// error says the exact command (`what` names what is missing).
pub fn install_packages(packages: &[&str], what: &str) -> Result<()> {
    let install = format!("apt-get install -y {}", packages.join(" "));
    if !is_root() || find_in_path("apt-get").is_none() {
        bail!(
            "{what} missing. Install with:\n    sudo apt-get update && sudo {install}\n(or your distribution's equivalent)"
        );
    }
    eprintln!("xtask: {what} missing; running apt-get update && {install}");
    let ok = Command::new("apt-get")
        .args(["update", "-qq"])
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
        && Command::new("apt-get")
            .args(["install", "-y", "-qq"])
            .args(packages)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
    if !ok {
        bail!("installing {what} failed; run `apt-get update && {install}` yourself");
    }
    Ok(())
}

/// Debian's static bash, which the guest benchmark system puts at the guest's `/bin/bash`
/// (installing `bash-static` first if it is missing).
pub fn ensure_bash_static() -> Result<PathBuf> {
    let path = Path::new("/bin/bash-static");
    if !path.is_file() {
        install_packages(&["bash-static"], "bash (Debian package bash-static)")?;
    }
    anyhow::ensure!(path.is_file(), "{} still not found", path.display());
    Ok(path.to_path_buf())
}

/// The static busybox for guest initramfs images (installing `busybox-static` first if
/// it is missing, as for QEMU).
pub fn ensure_busybox() -> Result<PathBuf> {
    let find = || {
        BUSYBOX_PATHS
            .iter()
            .map(Path::new)
            .find(|p| p.is_file())
            .map(Path::to_path_buf)
    };
    if let Some(path) = find() {
        return Ok(path);
    }
    install_packages(
        &[BUSYBOX_PACKAGE],
        "busybox (Debian package busybox-static)",
    )?;
    find().context("busybox still not found in /bin or /usr/bin")
}

pub fn ensure_qemu() -> Result<Qemu> {
    if find_in_path("qemu-system-x86_64").is_none() || find_ovmf().is_none() {
        install_packages(APT_PACKAGES, "QEMU and/or OVMF are")?;
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

/// [`ensure_qemu`], and a QEMU of at least [`QEMU_DETERMINISTIC_MIN`]: as root on Debian 12
/// it comes from bookworm-backports (added to apt's sources), otherwise the error says
/// how to get it.
pub fn ensure_qemu_deterministic() -> Result<Qemu> {
    let qemu = ensure_qemu()?;
    let Some(version) = qemu_version(&qemu.binary) else {
        bail!(
            "cannot read the version of {} (`--version`)",
            qemu.binary.display()
        );
    };
    if version >= QEMU_DETERMINISTIC_MIN {
        return Ok(qemu);
    }
    let (major, minor) = QEMU_DETERMINISTIC_MIN;
    let what = format!(
        "QEMU {}.{} is older than {major}.{minor}, which the scenarios' deterministic time \
         with several CPUs needs (docs/architecture.md, \"Multicore\")",
        version.0, version.1
    );
    let install = "apt-get install -y -t bookworm-backports qemu-system-x86";
    let bookworm = std::fs::read_to_string("/etc/os-release")
        .is_ok_and(|s| s.lines().any(|l| l == "VERSION_CODENAME=bookworm"));
    if !bookworm || !is_root() || find_in_path("apt-get").is_none() {
        bail!(
            "{what}. On Debian 12:\n    echo '{BACKPORTS_LINE}' | sudo tee {BACKPORTS_LIST}\n    \
             sudo apt-get update && sudo {install}\n(elsewhere: your distribution's QEMU 8.1 or later)"
        );
    }
    std::fs::write(BACKPORTS_LIST, format!("{BACKPORTS_LINE}\n"))
        .with_context(|| format!("cannot write {BACKPORTS_LIST}"))?;
    install_packages(
        &["-t", "bookworm-backports", "qemu-system-x86"],
        &format!("{what}; a newer QEMU from bookworm-backports is"),
    )?;
    if qemu_version(&qemu.binary).is_none_or(|v| v < QEMU_DETERMINISTIC_MIN) {
        bail!(
            "bookworm-backports' QEMU is still older than {major}.{minor}; run `apt-get update && {install}` yourself"
        );
    }
    Ok(qemu)
}

/// (major, minor) of `qemu-system-x86_64 --version`.
fn qemu_version(binary: &Path) -> Option<(u32, u32)> {
    let out = Command::new(binary).arg("--version").output().ok()?;
    parse_qemu_version(&String::from_utf8_lossy(&out.stdout))
}

/// (major, minor) of "QEMU emulator version 10.0.2 (Debian ...)".
fn parse_qemu_version(text: &str) -> Option<(u32, u32)> {
    let version = text
        .split_whitespace()
        .skip_while(|w| *w != "version")
        .nth(1)?;
    let mut parts = version.split('.').map(|p| p.parse::<u32>().ok());
    Some((parts.next()??, parts.next()??))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qemu_versions() {
        let debian = "QEMU emulator version 7.2.19 (Debian 1:7.2+dfsg-7+deb12u18+b3)\nCopyright";
        assert_eq!(parse_qemu_version(debian), Some((7, 2)));
        let backports = "QEMU emulator version 10.0.2 (Debian 1:10.0.2+ds-2+deb13u1~bpo12+1)";
        assert_eq!(parse_qemu_version(backports), Some((10, 0)));
        assert!(parse_qemu_version(debian).unwrap() < QEMU_DETERMINISTIC_MIN);
        assert!(parse_qemu_version(backports).unwrap() >= QEMU_DETERMINISTIC_MIN);
        assert_eq!(
            parse_qemu_version("qemu-system-x86_64: unknown option"),
            None
        );
        assert_eq!(parse_qemu_version("QEMU emulator version x.y"), None);
    }
}
