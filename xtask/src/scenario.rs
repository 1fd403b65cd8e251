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
//!                               # timeout then only bounds a run that never gets there;
//!                               # with a host part run by `boot_while`, QEMU stops when
//!                               # that part has returned and these texts have appeared)
//! console_input = ["echo hi\r", "\u0004"]   # optional: typed into COM2 (a guest's
//!                               # console) once its output shows `console_start`, each
//!                               # piece once the output grew and then stayed quiet for
//!                               # `qemu::QUIET` (a prompt came); the test reads COM2's
//!                               # output as `Outcome::console`
//! qemu_args = ["-device", "virtio-net-pci,addr=03.0,netdev=n", "-netdev", "user,id=n,restrict=on"]
//!                               # optional: more QEMU arguments (devices a partition owns);
//!                               # `{host_port0}`, `{host_port1}`, ... in them become the
//!                               # ports `host_ports` chose
//! host_ports = 1                # optional, default 0: this many ports on 127.0.0.1, free
//!                               # for both TCP and UDP when the scenario boots (scenarios
//!                               # run in parallel, so none is fixed), for `hostfwd`; the
//!                               # test gets them (`scenarios::boot_beside`)
//! a653rs_example = "ping"       # optional: the system is that example of DLR's
//!                               # a653rs-linux, its YAML imported and its programs built
//!                               # for Warden (`a653rs_examples`); without their sources
//!                               # the scenario is skipped
//! disk_sectors = 8192           # optional: a raw disk image of this many 512-byte sectors,
//!                               # `target/scenarios/NAME/disk.img`, zeroed when a test
//!                               # boots the scenario with `scenarios::boot`, kept as it is
//!                               # by `scenarios::boot_again` (a reset with the same disk);
//!                               # `{disk}` in `qemu_args` is its path
//! console_start = "built-in shell"   # with console_input: typing starts once the
//!                               # output shows this (the firmware and the loader write
//!                               # to COM2 first); default "": at the first quiet output
//! debian_packages = ["bash-static"]   # optional: Debian packages the image or the test
//!                               # takes files from, installed first when missing
//!                               # (`tools::install_packages`: as root, else the command)
//! prepare = ["sh", "tests/configs/guest/e2fsck-images.sh"]   # optional: a host command
//!                               # run in the workspace root before the image is
//!                               # assembled (files the configuration adds); it must succeed
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
    pub host_ports: usize,
    #[serde(default)]
    pub a653rs_example: Option<String>,
    #[serde(default)]
    pub debian_packages: Vec<String>,
    #[serde(default)]
    pub prepare: Vec<String>,
    #[serde(default)]
    pub disk_sectors: Option<u64>,
}

impl Manifest {
    /// Installs the Debian packages the scenario needs and runs its `prepare` command.
    pub fn prepare(&self, name: &str) -> Result<()> {
        let missing: Vec<&str> = self
            .debian_packages
            .iter()
            .map(String::as_str)
            .filter(|p| {
                !std::process::Command::new("dpkg")
                    .args(["-s", p])
                    .output()
                    .is_ok_and(|o| o.status.success())
            })
            .collect();
        if !missing.is_empty() {
            crate::tools::install_packages(
                &missing,
                &format!("scenario {name}: the Debian package(s) {missing:?} are"),
            )?;
        }
        if let Some((program, args)) = self.prepare.split_first() {
            let status = std::process::Command::new(program)
                .args(args)
                .current_dir(crate::workspace_root())
                .status()
                .with_context(|| format!("scenario {name}: cannot run {:?}", self.prepare))?;
            anyhow::ensure!(
                status.success(),
                "scenario {name}: {:?} failed ({status})",
                self.prepare
            );
        }
        Ok(())
    }

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

/// `{disk}` in `args` replaced by `disk`, the scenario's disk image.
pub fn with_disk(args: &[String], disk: &Path) -> Vec<String> {
    let disk = disk.display().to_string();
    args.iter()
        .map(|arg| arg.replace("{disk}", &disk))
        .collect()
}

/// `{host_port<i>}` in `args` replaced by `ports[i]`.
pub fn with_host_ports(args: &[String], ports: &[u16]) -> Vec<String> {
    args.iter()
        .map(|arg| {
            let mut arg = arg.clone();
            for (i, port) in ports.iter().enumerate() {
                arg = arg.replace(&format!("{{host_port{i}}}"), &port.to_string());
            }
            arg
        })
        .collect()
}

/// `n` distinct ports on 127.0.0.1 that are free for both TCP and UDP now (each bound to
/// both until all are found, so they differ; QEMU binds them moments later).
pub fn free_host_ports(n: usize) -> Result<Vec<u16>> {
    let mut held = Vec::new();
    for _ in 0..n * 20 {
        if held.len() == n {
            break;
        }
        let tcp =
            std::net::TcpListener::bind(("127.0.0.1", 0)).context("cannot bind a TCP port")?;
        let port = tcp.local_addr()?.port();
        if let Ok(udp) = std::net::UdpSocket::bind(("127.0.0.1", port)) {
            held.push((port, tcp, udp));
        }
    }
    if held.len() < n {
        anyhow::bail!("cannot find {n} ports free for both TCP and UDP on 127.0.0.1");
    }
    Ok(held.into_iter().map(|(port, _, _)| port).collect())
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
    let placeholders = with_host_ports(&manifest.qemu_args, &vec![0; manifest.host_ports]);
    if let Some(arg) = placeholders.iter().find(|a| a.contains("{host_port")) {
        anyhow::bail!(
            "scenario manifest {}: `{arg}` names a host port beyond host_ports = {}",
            path.display(),
            manifest.host_ports
        );
    }
    if manifest.disk_sectors.is_none() && manifest.qemu_args.iter().any(|a| a.contains("{disk}")) {
        anyhow::bail!(
            "scenario manifest {}: `{{disk}}` in qemu_args needs disk_sectors",
            path.display()
        );
    }
    let name = path
        .file_stem()
        .context("scenario file without a name")?
        .to_string_lossy()
        .into_owned();
    Ok(Scenario { name, manifest })
}

/// The scenarios, sorted by name, whose name contains one of `filters` (all of them without a filter).
pub fn all(filters: &[String]) -> Result<Vec<Scenario>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(scenarios_dir()).context("cannot list tests/scenarios")? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "toml") {
            let scenario = load(&path)?;
            if filters.is_empty() || filters.iter().any(|f| scenario.name.contains(f.as_str())) {
                out.push(scenario);
            }
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_port_placeholders_are_filled_in_order() {
        let args = vec![
            "-netdev".to_string(),
            "user,id=n0,hostfwd=udp:127.0.0.1:{host_port0}-:7,hostfwd=tcp:127.0.0.1:{host_port1}-:80"
                .to_string(),
        ];
        assert_eq!(
            with_host_ports(&args, &[4000, 4001])[1],
            "user,id=n0,hostfwd=udp:127.0.0.1:4000-:7,hostfwd=tcp:127.0.0.1:4001-:80"
        );
    }

    #[test]
    fn free_host_ports_are_distinct_and_bindable_for_both_protocols() {
        let ports = free_host_ports(3).unwrap();
        assert_eq!(ports.len(), 3);
        assert!(ports[0] != ports[1] && ports[1] != ports[2] && ports[0] != ports[2]);
        for port in ports {
            let _tcp = std::net::TcpListener::bind(("127.0.0.1", port)).unwrap();
            let _udp = std::net::UdpSocket::bind(("127.0.0.1", port)).unwrap();
        }
    }

    #[test]
    fn a_placeholder_beyond_host_ports_is_refused() {
        let dir = std::env::temp_dir().join(format!("warden-scenario-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("net_x.toml");
        std::fs::write(
            &path,
            "description = \"x\"\nhost_ports = 1\nqemu_args = [\"hostfwd=udp:127.0.0.1:{host_port1}-:7\"]\n",
        )
        .unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("names a host port beyond host_ports = 1"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
