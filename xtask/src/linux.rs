//! The Linux-side programs of `tests/linux`: static C programs built with `gcc -static`
//! (glibc), the same executables run on the host Linux and in the guest.
//!
//! - `linux-tests` (every `tests/linux/*.c` but `bench.c`): the system-call checks, one
//!   area a source file; `tests/linux/expected/<area>.out` is each area's expected output.
//!   [`host_check`] runs every area on the host and compares (part of `cargo xtask test`):
//!   the host run proves the checks themselves right, the scenario `guest_linux` runs the
//!   areas the guest passes and expects the same lines.
//! - `linux-bench` (`tests/linux/bench.c`): the guest benchmark of `cargo xtask bench`.
//! - `linux-probe` (`tests/linux/probe.c`): the faults and forbidden accesses of the
//!   scenarios `guest_faults` and `guest_isolation` (one per argument).
//! - `linux-arinc` (`tests/linux/arinc.c`, with the checks' common part `check.c`): the
//!   ARINC port devices `/dev/arinc/<port>` (scenario `system_devices`) and the port
//!   flood of the hostile guest (scenario `system_hostile_guest`).
//! - `linux-netserve` (`tests/linux/netserve.c`): the guest side of the network benchmark
//!   (`cargo xtask bench --net`, [`crate::netbench`]).
//! - `plcctl` (`partitions/guest/plcctl`): the PLC online tool, a Rust program built with
//!   cargo for [`MUSL_TARGET`] (static, profile `linux`) into
//!   `target/x86_64-unknown-linux-musl/linux/plcctl`.
//! - `plcc` (`partitions/softplc/compiler`): the Structured Text compiler, the same Rust
//!   binary as on the host built the same way, so a user can edit, compile and download a
//!   PLC program from the guest's shell.
//! - `fbctl` (`partitions/iec61499/fbctl`): the IEC 61499 management tool (deploy, monitor,
//!   force, compile and add FB types), built as `plcctl` is.
//! - `linux-rust-std` (`tests/linux/rust-std`): a Rust std program (threads, locks,
//!   channels, files, a child process) whose output in the guest must be its output on the
//!   host (scenario `guest_rust_std`), built as `plcctl` is.
//!
//! They are built into `target/linux/<name>` (only when a source is newer) and reach a
//! guest's initramfs as `/bin/<name>` through the partition key `guest.programs`
//! ([`config::system::GUEST_PROGRAMS`]). This module never installs a compiler: a missing
//! gcc or static C library is an error that says the apt command.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Debian packages of `gcc -static` with glibc.
pub const GCC_PACKAGES: &str = "gcc libc6-dev";
/// The target of the Rust programs for the guest (static executables with musl).
pub const MUSL_TARGET: &str = "x86_64-unknown-linux-musl";
/// The Rust programs: (program, the workspace package whose binary of that name it is).
const RUST_PROGRAMS: &[(&str, &str)] = &[
    ("plcctl", "plcctl"),
    ("plcc", "plc-compiler"),
    ("fbctl", "fbctl"),
    ("linux-rust-std", "linux-rust-std"),
];
/// The programs built from a main source file of their own (and the shared sources they
/// also need); `linux-tests` is every source that is no such main file.
const OWN_MAIN: &[(&str, &str, &[&str])] = &[
    ("linux-bench", "bench.c", &[]),
    ("linux-probe", "probe.c", &[]),
    ("linux-arinc", "arinc.c", &["check.c"]),
    ("linux-netserve", "netserve.c", &[]),
];
/// How every program is compiled.
const CFLAGS: &[&str] = &["-static", "-O2", "-Wall", "-Werror"];

/// `tests/linux`.
pub fn source_dir() -> PathBuf {
    crate::workspace_root().join("tests/linux")
}

/// Where program `name` is built.
pub fn output_path(name: &str) -> PathBuf {
    crate::target_dir().join("linux").join(name)
}

/// The C sources of program `name` (one of [`config::system::GUEST_PROGRAMS`]).
pub fn sources(name: &str) -> Result<Vec<PathBuf>> {
    let mut c_files: Vec<PathBuf> = std::fs::read_dir(source_dir())
        .with_context(|| format!("cannot list {}", source_dir().display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "c"))
        .collect();
    c_files.sort();
    let main_of_another = |p: &PathBuf| {
        OWN_MAIN
            .iter()
            .any(|(_, main, _)| p.file_name().is_some_and(|n| n == *main))
    };
    if name == "linux-tests" {
        return Ok(c_files
            .into_iter()
            .filter(|p| !main_of_another(p))
            .collect());
    }
    match OWN_MAIN.iter().find(|(program, _, _)| *program == name) {
        Some((_, main, shared)) => Ok(std::iter::once(main)
            .chain(shared.iter())
            .map(|file| source_dir().join(file))
            .collect()),
        None => bail!("no Linux program {name}"),
    }
}

fn modified(path: &Path) -> Option<std::time::SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// Builds the Rust program `name` for [`MUSL_TARGET`] (cargo decides whether anything
/// changed) and returns its path.
fn build_rust(name: &str, package: &str) -> Result<PathBuf> {
    crate::tools::ensure_rust_targets()?;
    let status = crate::artifacts::cargo()
        .args([
            "build",
            "--quiet",
            "--profile",
            "linux",
            "--target",
            MUSL_TARGET,
            "-p",
            package,
            "--bin",
            name,
        ])
        .status()
        .with_context(|| format!("cannot run cargo to build {name}"))?;
    if !status.success() {
        bail!("building {name} for {MUSL_TARGET} failed ({status})");
    }
    Ok(crate::target_dir()
        .join(MUSL_TARGET)
        .join("linux")
        .join(name))
}

/// Builds program `name` unless it is newer than its sources and headers; returns its path.
pub fn build(name: &str) -> Result<PathBuf> {
    if let Some(&(_, package)) = RUST_PROGRAMS.iter().find(|(program, _)| *program == name) {
        return build_rust(name, package);
    }
    let sources = sources(name)?;
    let out = output_path(name);
    let headers: Vec<PathBuf> = std::fs::read_dir(source_dir())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "h"))
        .collect();
    let built = modified(&out);
    if built.is_some()
        && sources
            .iter()
            .chain(&headers)
            .all(|s| modified(s).is_some_and(|m| Some(m) <= built))
    {
        return Ok(out);
    }
    let missing = || {
        format!(
            "building the Linux test programs needs gcc and the static C library. Install with:\n    sudo apt-get install -y {GCC_PACKAGES}"
        )
    };
    std::fs::create_dir_all(out.parent().unwrap_or(Path::new(".")))?;
    let output = Command::new("gcc")
        .args(CFLAGS)
        .arg("-o")
        .arg(&out)
        .args(&sources)
        .output();
    let output = match output {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!("{}", missing()),
        Err(e) => return Err(e).context("cannot run gcc"),
    };
    if !output.status.success() {
        let text = String::from_utf8_lossy(&output.stderr);
        if text.contains("cannot find -lc") {
            bail!("{}\n{text}", missing());
        }
        bail!("gcc could not build {name}:\n{text}");
    }
    Ok(out)
}

/// The areas of `linux-tests`, from the expected-output files, sorted.
pub fn areas() -> Result<Vec<String>> {
    let dir = source_dir().join("expected");
    let mut areas: Vec<String> = std::fs::read_dir(&dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            e.file_name()
                .to_str()?
                .strip_suffix(".out")
                .map(str::to_string)
        })
        .collect();
    areas.sort();
    Ok(areas)
}

/// The expected output of `area`, one string a line.
pub fn expected(area: &str) -> Result<Vec<String>> {
    let path = source_dir().join("expected").join(format!("{area}.out"));
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    Ok(text.lines().map(str::to_string).collect())
}

/// What differs between the `expected` and the `got` lines of an area (empty when equal):
/// each line as `-expected` or `+got`, in order of the expected lines.
pub fn differences(expected: &[String], got: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    for line in expected {
        if !got.contains(line) {
            out.push(format!("-{line}"));
        }
    }
    for line in got {
        if !expected.contains(line) {
            out.push(format!("+{line}"));
        }
    }
    if out.is_empty() && expected != got {
        out.push("(the same lines, in another order or number)".to_string());
    }
    out
}

/// Builds `linux-tests`, runs each area on the host (from `/`) and compares its output with
/// the expected file; prints what differs. `Ok(false)` when an area differs or fails.
pub fn host_check() -> Result<bool> {
    let program = build("linux-tests")?;
    let mut ok = true;
    for area in areas()? {
        let out = Command::new(&program)
            .arg(&area)
            .current_dir("/")
            .output()
            .with_context(|| format!("cannot run {}", program.display()))?;
        let got: Vec<String> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(str::to_string)
            .collect();
        let diff = differences(&expected(&area)?, &got);
        if diff.is_empty() && out.status.success() {
            eprintln!(
                "xtask: linux-tests {area} on the host: {} lines as expected",
                got.len()
            );
        } else {
            ok = false;
            eprintln!(
                "xtask: FAILED: linux-tests {area} on the host ({}) differs from tests/linux/expected/{area}.out:\n{}",
                out.status,
                diff.join("\n")
            );
        }
    }
    Ok(ok)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_guest_program_has_sources() {
        for name in config::system::GUEST_PROGRAMS {
            if RUST_PROGRAMS.iter().any(|(program, _)| program == name) {
                continue;
            }
            assert!(!sources(name).unwrap().is_empty(), "{name}");
        }
        assert!(sources("other").is_err());
        let tests = sources("linux-tests").unwrap();
        assert!(tests.iter().any(|p| p.ends_with("main.c")));
        assert!(!tests.iter().any(|p| p.ends_with("bench.c")));
        assert!(!tests.iter().any(|p| p.ends_with("arinc.c")));
        assert!(tests.iter().any(|p| p.ends_with("check.c")));
        let arinc = sources("linux-arinc").unwrap();
        assert!(arinc.iter().any(|p| p.ends_with("check.c")) && arinc.len() == 2);
    }

    #[test]
    fn every_area_has_its_source_and_a_final_line() {
        for area in areas().unwrap() {
            assert!(source_dir().join(format!("{area}.c")).is_file(), "{area}");
            let lines = expected(&area).unwrap();
            assert_eq!(
                lines.last().map(String::as_str),
                Some(format!("area {area}: all checks passed").as_str())
            );
            assert!(
                lines[..lines.len() - 1]
                    .iter()
                    .all(|l| l.starts_with("ok "))
            );
        }
    }

    #[test]
    fn differences_name_missing_and_extra_lines() {
        let lines = |s: &[&str]| s.iter().map(|l| l.to_string()).collect::<Vec<_>>();
        let want = lines(&["ok a", "ok b", "area x: all checks passed"]);
        assert!(differences(&want, &want).is_empty());
        let got = lines(&[
            "ok a",
            "FAIL b: expected 1 got 2",
            "area x: 1 checks failed",
        ]);
        assert_eq!(
            differences(&want, &got),
            [
                "-ok b",
                "-area x: all checks passed",
                "+FAIL b: expected 1 got 2",
                "+area x: 1 checks failed"
            ]
        );
        let swapped = lines(&["ok b", "ok a", "area x: all checks passed"]);
        assert_eq!(differences(&want, &swapped).len(), 1);
    }
}
