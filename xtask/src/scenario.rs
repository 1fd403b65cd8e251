//! QEMU scenarios: `tests/scenarios/NAME.toml` says what to put in the image; the Rust test
//! of the same name in `tests/` says what must happen. Format:
//!
//! ```toml
//! description = "boot reaches ready and exits with success"
//! hook = "exit-on-ready"        # kernel test hook (system image entry `test/hook`)
//! config = "config/systems/default.toml"   # optional, relative to the workspace root
//! timeout_secs = 60             # optional, default 60
//! root_task = "test-usermode"   # optional: a test program (package under tests/programs)
//!                               # replaces syssw as the root task
//! entries = { "test/mode" = "kernel-read" }   # optional extra system-image entries (text)
//! remove_files = ["kernel.elf"] # optional: ESP files to delete (loader error tests)
//! corrupt_system_image = true   # optional: flip a byte of system.img after building it
//! deterministic_time = true     # optional: QEMU on virtual time (-icount), for scenarios
//!                               # that assert kernel timing, not measure QEMU's
//! done_when = ["p0: alive at "] # optional: stop QEMU as soon as the log has shown each of
//!                               # these texts (for systems that run for ever; the
//!                               # timeout then only bounds a run that never gets there)
//! console_input = ["echo hi\r", "\u0004"]   # optional: typed into COM2 (a guest's
//!                               # console) once its output shows `console_start`, each
//!                               # piece once the output grew and then stayed quiet for
//!                               # `qemu::QUIET` (a prompt came); the test reads COM2's
//!                               # output as `Outcome::console`
//! qemu_args = ["-device", "virtio-net-pci,addr=03.0,netdev=n", "-netdev", "user,id=n,restrict=on"]
//!                               # optional: more QEMU arguments (devices a partition owns)
//! a653rs_example = "ping"       # optional: the system is that example of DLR's
//!                               # a653rs-linux, its YAML imported and its programs built
//!                               # for Warden (`a653rs_examples`); without their sources
//!                               # the scenario is skipped
//! console_start = "built-in shell"   # with console_input: typing starts once the
//!                               # output shows this (the firmware and the loader write
//!                               # to COM2 first); default "": at the first quiet output
//! ```

use anyhow::{Context, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub description: String,
    #[serde(default)]
    pub hook: Option<String>,
    #[serde(default)]
    pub config: Option<PathBuf>,
    #[serde(default = "default_timeout")]
    pub timeout_secs: u64,
    #[serde(default)]
    pub root_task: Option<String>,
    #[serde(default)]
    pub entries: std::collections::BTreeMap<String, String>,
    #[serde(default)]
    pub remove_files: Vec<PathBuf>,
    #[serde(default)]
    pub corrupt_system_image: bool,
    #[serde(default)]
    pub deterministic_time: bool,
    #[serde(default)]
    pub done_when: Vec<String>,
    #[serde(default)]
    pub console_input: Vec<String>,
    #[serde(default)]
    pub console_start: String,
    #[serde(default)]
    pub qemu_args: Vec<String>,
    #[serde(default)]
    pub a653rs_example: Option<String>,
}

impl Manifest {
    /// Applies the deliberate damage the manifest asks for to an assembled ESP.
    pub fn damage(&self, esp: &Path) -> Result<()> {
        for file in &self.remove_files {
            std::fs::remove_file(esp.join(file))
                .with_context(|| format!("cannot remove {} from the ESP", file.display()))?;
        }
        if self.corrupt_system_image {
            let path = esp.join("system.img");
            let mut bytes = std::fs::read(&path)?;
            let last = bytes.len() - 1;
            bytes[last] ^= 0xff;
            std::fs::write(&path, bytes)?;
        }
        Ok(())
    }
}

fn default_timeout() -> u64 {
    60
}

#[derive(Clone, Debug)]
pub struct Scenario {
    pub name: String,
    pub manifest: Manifest,
}

pub fn scenarios_dir() -> PathBuf {
    crate::workspace_root().join("tests").join("scenarios")
}

/// Where `cargo xtask test` puts each scenario's ESP and run files.
pub fn output_dir() -> PathBuf {
    crate::target_dir().join("scenarios")
}

pub fn load(path: &Path) -> Result<Scenario> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let manifest: Manifest = toml::from_str(&text)
        .with_context(|| format!("invalid scenario manifest {}", path.display()))?;
    let name = path
        .file_stem()
        .context("scenario file without a name")?
        .to_string_lossy()
        .into_owned();
    Ok(Scenario { name, manifest })
}

/// All scenarios, sorted by name, whose name contains `filter`.
pub fn all(filter: Option<&str>) -> Result<Vec<Scenario>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(scenarios_dir()).context("cannot list tests/scenarios")? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "toml") {
            let scenario = load(&path)?;
            if filter.is_none_or(|f| scenario.name.contains(f)) {
                out.push(scenario);
            }
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}
