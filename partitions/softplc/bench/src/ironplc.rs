//! The IronPLC leg: the suite's programs (the same ST source) compiled by IronPLC's compiler
//! `ironplcc` and timed on IronPLC's VM, the public interpreter the issue measures ours
//! against. Used only when the environment variable `IRONPLC` names an IronPLC checkout
//! (`git clone https://github.com/ironplc/ironplc`; the directory holding `compiler/`) or an
//! `ironplcc` built in one (`<checkout>/compiler/target/release/ironplcc`); nothing of
//! IronPLC is part of this repository or its build.
//!
//! How: `ironplcc compile` turns each program into a container (`.iplc`); a small harness
//! ([`HARNESS`], our code, built as a stand-alone crate under `target/plc-ironplc-bench/`
//! against the checkout's `ironplc-vm` and `ironplc-container` crates, release profile as
//! IronPLC's own) runs it exactly as `plc-bench` runs ours: `cycles` scan rounds of warm-up,
//! then the outputs (compared with the Rust reference's, as for our VM), then [`SAMPLES`]
//! batches of `cycles` rounds, each batch timed as a whole. A program `ironplcc` does not
//! accept is skipped with its first diagnostic.
//!
//! [`SAMPLES`]: crate::SAMPLES

use crate::Program;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The harness's source (see the module documentation).
pub const HARNESS: &str = include_str!("../ironplc/main.rs");

/// A usable IronPLC: its compiler and our harness around its VM.
pub struct IronPlc {
    ironplcc: PathBuf,
    harness: PathBuf,
    work: PathBuf,
}

/// A program's run on IronPLC's VM.
pub struct Run {
    /// The values of [`Program::outputs`] after the warm-up (NaN when IronPLC's variable
    /// map has no such variable).
    pub outputs: Vec<f64>,
    /// ns per scan round, one per batch.
    pub samples: Vec<f64>,
}

/// The repository's `target/` directory (honours CARGO_TARGET_DIR).
fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../..")
                .join("target")
        })
}

fn cargo() -> Command {
    let mut cargo = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    // The outer build's flags (coverage, another target) are not these builds'.
    cargo
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("CARGO_TARGET_DIR");
    cargo
}

/// Runs `command`; its stderr on failure.
fn run(mut command: Command, what: &str) -> Result<std::process::Output, String> {
    let out = command
        .output()
        .map_err(|e| format!("cannot run {what}: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "{what} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(out)
}

/// The checkout holding `path` (a checkout, or a file inside one such as its ironplcc).
fn checkout_of(path: &Path) -> Option<PathBuf> {
    path.ancestors()
        .find(|dir| dir.join("compiler/vm/Cargo.toml").is_file())
        .map(Path::to_path_buf)
}

impl IronPlc {
    /// From `IRONPLC`: `Ok(None)` when it is not set; builds what is missing (ironplcc when
    /// a checkout is given, the harness always; cargo skips what is up to date).
    pub fn from_env() -> Result<Option<IronPlc>, String> {
        let Some(given) = std::env::var_os("IRONPLC").map(PathBuf::from) else {
            return Ok(None);
        };
        let checkout = checkout_of(&given).ok_or_else(|| {
            format!(
                "IRONPLC={}: not an IronPLC checkout (no compiler/vm/Cargo.toml) or a file in one",
                given.display()
            )
        })?;
        let compiler = checkout.join("compiler");
        let ironplcc = if given.is_file() {
            given
        } else {
            let mut build = cargo();
            build
                .args(["build", "--release", "--quiet", "-p", "ironplc-cli"])
                .current_dir(&compiler);
            run(build, "building ironplcc")?;
            compiler.join("target/release/ironplcc")
        };
        let work = target_dir().join("plc-ironplc-bench");
        let harness = build_harness(&work, &compiler)?;
        Ok(Some(IronPlc {
            ironplcc,
            harness,
            work,
        }))
    }

    /// `program` compiled by ironplcc; `Err` with its first diagnostic when it refuses it.
    pub fn compile(&self, program: &Program) -> Result<PathBuf, String> {
        let dir = self.work.join("programs");
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let source = dir.join(program.file);
        std::fs::write(&source, program.source)
            .map_err(|e| format!("{}: {e}", source.display()))?;
        let container = dir.join(format!("{}.iplc", program.name));
        let out = Command::new(&self.ironplcc)
            .arg("compile")
            .arg(&source)
            .arg("-o")
            .arg(&container)
            .env("NO_COLOR", "1")
            .output()
            .map_err(|e| format!("cannot run {}: {e}", self.ironplcc.display()))?;
        if out.status.success() {
            return Ok(container);
        }
        let text = String::from_utf8_lossy(&out.stderr).into_owned()
            + &String::from_utf8_lossy(&out.stdout);
        let first = text
            .lines()
            .map(strip_ansi)
            .find(|line| line.contains("error"))
            .unwrap_or_else(|| "ironplcc failed".to_string());
        Err(format!("ironplcc does not accept it: {}", first.trim()))
    }

    /// Runs `container` (`program`'s) on IronPLC's VM: outputs after `program.cycles`
    /// rounds, then [`crate::samples`] timed batches of as many rounds.
    pub fn run(&self, container: &Path, program: &Program) -> Result<Run, String> {
        let mut command = Command::new(&self.harness);
        command
            .arg(container)
            .arg(program.cycles.to_string())
            .arg(crate::samples().to_string());
        // Our monitor names (`Pid.out[0]`) without the program's name (`out[0]`).
        for name in program.outputs {
            command.arg(name.split_once('.').map_or(*name, |(_, var)| var));
        }
        let out = command
            .output()
            .map_err(|e| format!("cannot run {}: {e}", self.harness.display()))?;
        if !out.status.success() {
            let text = String::from_utf8_lossy(&out.stderr);
            return Err(
                match text.lines().find_map(|l| l.strip_prefix("harness: trap ")) {
                    Some(trap) => format!("IronPLC's VM stops it with the trap {trap}"),
                    None => format!("the IronPLC harness failed: {}", text.trim()),
                },
            );
        }
        let text = String::from_utf8_lossy(&out.stdout);
        let numbers = |key: &str| -> Result<Vec<f64>, String> {
            let line = text
                .lines()
                .find_map(|l| l.strip_prefix(key))
                .ok_or_else(|| format!("the IronPLC harness printed no `{key}` line"))?;
            line.split_whitespace()
                .map(|w| w.parse::<f64>().map_err(|e| format!("`{w}`: {e}")))
                .collect()
        };
        Ok(Run {
            outputs: numbers("outputs")?,
            samples: numbers("samples")?,
        })
    }
}

/// Writes the harness crate under `work` (only files that changed) and builds it.
fn build_harness(work: &Path, compiler: &Path) -> Result<PathBuf, String> {
    let dir = work.join("harness");
    let manifest = format!(
        "# Generated by plc-bench-suite (src/ironplc.rs); stand-alone, not part of the repository.\n\
         [package]\nname = \"plc-ironplc-harness\"\nversion = \"0.0.0\"\nedition = \"2021\"\npublish = false\n\n\
         [dependencies]\nironplc-vm = {{ path = \"{0}/vm\" }}\nironplc-container = {{ path = \"{0}/container\" }}\n\n\
         [workspace]\n\n[profile.release]\ndebug = false\n",
        compiler.display()
    );
    for (path, contents) in [
        (dir.join("Cargo.toml"), manifest.as_str()),
        (dir.join("src/main.rs"), HARNESS),
    ] {
        if std::fs::read_to_string(&path).is_ok_and(|old| old == contents) {
            continue;
        }
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        std::fs::write(&path, contents).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    let mut build = cargo();
    build
        .args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(work.join("target"));
    run(build, "building the IronPLC harness")?;
    Ok(work.join("target/release/plc-ironplc-harness"))
}

/// `line` without ANSI colour sequences.
fn strip_ansi(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            // CSI: ESC [ parameters final-byte.
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_colours_and_finds_checkouts() {
        assert_eq!(
            strip_ansi("\u{1b}[1m\u{1b}[38;5;9merror[P4026]\u{1b}[0m: x"),
            "error[P4026]: x"
        );
        assert_eq!(checkout_of(Path::new("/nonexistent/ironplc")), None);
    }
}
