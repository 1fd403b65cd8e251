//! `cargo xtask check-config FILE`: validates a system description and compiles it to the
//! binary configuration that goes into `system.img` (see the `config` crate).
//!
//! Known images: a partition's `image` names a user program the workspace builds, i.e. a
//! workspace member whose manifest uses `user/link.rs` as its build script
//! (the freestanding user-mode binaries), by package name — the same name
//! [`crate::artifacts::build_user_programs`] takes and `target/user/<name>` carries. `syssw`
//! is excluded: it is the root task, never a partition.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// The user programs partitions may use as images (sorted package names).
pub fn known_images() -> Result<Vec<String>> {
    let root = crate::workspace_root();
    let manifest = std::fs::read_to_string(root.join("Cargo.toml"))
        .context("cannot read the workspace Cargo.toml")?;
    let manifest: toml::Table = toml::from_str(&manifest).context("workspace Cargo.toml")?;
    let members = manifest
        .get("workspace")
        .and_then(|w| w.get("members"))
        .and_then(|m| m.as_array())
        .context("workspace Cargo.toml has no workspace.members")?;
    let mut images = Vec::new();
    for member in members.iter().filter_map(|m| m.as_str()) {
        let path = root.join(member).join("Cargo.toml");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let member: toml::Table =
            toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
        let package = member.get("package");
        let build = package
            .and_then(|p| p.get("build"))
            .and_then(|b| b.as_str());
        let name = package.and_then(|p| p.get("name")).and_then(|n| n.as_str());
        if let (Some(build), Some(name)) = (build, name)
            && build.ends_with("user/link.rs")
            && name != "syssw"
        {
            images.push(name.to_string());
        }
    }
    images.sort();
    Ok(images)
}

/// `file` as given, or relative to the workspace root if it does not exist as given.
fn resolve(file: &Path) -> PathBuf {
    if file.exists() {
        file.to_path_buf()
    } else {
        crate::workspace_root().join(file)
    }
}

/// Validates `path` and returns its binary configuration; the error lists every diagnostic.
/// (For the image builder.)
pub fn compile(path: &Path) -> Result<Vec<u8>> {
    load(path).map(|system| config::binary::encode(&system))
}

/// The description `path` (as given, or relative to the workspace root) as bytes, with the
/// name its diagnostics use (also the base of relative paths in it: PLC programs).
fn read(path: &Path) -> Result<(String, Vec<u8>)> {
    let resolved = resolve(path);
    let bytes =
        std::fs::read(&resolved).with_context(|| format!("cannot read {}", path.display()))?;
    Ok((resolved.display().to_string(), bytes))
}

/// Validates `path` and returns the system it describes; the error lists every diagnostic.
pub fn load(path: &Path) -> Result<config::System> {
    let images = known_images()?;
    let (name, source) = read(path)?;
    let source = match config::text(&name, &source) {
        Ok(source) => source,
        Err(d) => bail!("configuration {name} is invalid:\n{d}"),
    };
    // Known: the workspace's user programs and the a653rs-linux example programs built.
    let known = |image: &str| {
        images.iter().any(|i| i == image) || crate::a653rs_examples::image(image).is_some()
    };
    match config::load_with_warnings(&name, source, &known) {
        Ok((system, warnings)) => {
            print_warnings(&warnings);
            Ok(system)
        }
        Err(diagnostics) => {
            let lines: Vec<String> = diagnostics.iter().map(|d| d.to_string()).collect();
            bail!("configuration {name} is invalid:\n{}", lines.join("\n"))
        }
    }
}

/// The files of the partitions of the validated description `path` (`described`, decoded:
/// `system`): each image the partitions name, built (by name; the soft-PLC one with the
/// native programs when a partition has `plc.native`), and each data entry (by partition:
/// PLC packages, guest initramfs images), after [`check_budgets`] found that every
/// partition fits at boot.
#[allow(clippy::type_complexity)]
pub fn partition_files(
    path: &Path,
    described: &config::System,
    system: &config::SystemView,
) -> Result<(Vec<(String, PathBuf)>, Vec<(String, Vec<u8>)>)> {
    let mut images: Vec<String> = described
        .partitions
        .iter()
        .map(|p| p.image.clone())
        .collect();
    images.sort();
    images.dedup();
    let mut packages = crate::plc::data_entries(described)?;
    // With `plc.native`, the soft-PLC binary is built with the translated programs.
    let native = crate::plc::native_programs(described, &packages)?;
    let (native_images, plain): (Vec<String>, Vec<String>) = images
        .into_iter()
        .partition(|image| native.is_some() && image == crate::plc::SOFTPLC_IMAGE);
    // The a653rs-linux example programs are built by `a653rs_examples::prepare`.
    let (examples, plain): (Vec<String>, Vec<String>) = plain
        .into_iter()
        .partition(|image| crate::a653rs_examples::image(image).is_some());
    let paths = crate::artifacts::build_user_programs(&plain)?;
    let mut built: Vec<(String, PathBuf)> = plain.into_iter().zip(paths).collect();
    built.extend(
        examples
            .into_iter()
            .filter_map(|i| crate::a653rs_examples::image(&i).map(|path| (i, path))),
    );
    if let (Some(programs), Some(image)) = (&native, native_images.first()) {
        built.push((
            image.clone(),
            crate::artifacts::build_native_softplc(programs)?,
        ));
    }
    packages.extend(crate::guest::initramfs_images(described)?);
    packages.extend(crate::iec61499::data_entries(described)?);
    packages.extend(crate::nic::data_entries(described));
    packages.extend(crate::blk::data_entries(described));
    check_budgets(path, system, &built, &packages)?;
    Ok((built, packages))
}

/// Checks that every partition of the validated description `path` (decoded: `system`) can
/// start: its image (`images`: built user programs by name), data entry (`packages`: by
/// partition name) and stack fit in its `memory`, and its page tables in its
/// `kernel_memory` quota — the budget syssw computes at boot (`syssw_core::budget`), so a
/// system that builds never fails there. The error lists one diagnostic per shortfall, at
/// the configuration key to raise.
pub fn check_budgets(
    path: &Path,
    system: &config::SystemView,
    images: &[(String, PathBuf)],
    packages: &[(String, Vec<u8>)],
) -> Result<()> {
    let (name, source) = read(path)?;
    let source = String::from_utf8_lossy(&source);
    let mut problems = Vec::new();
    for p in system.partitions() {
        let Some((_, elf_path)) = images.iter().find(|(image, _)| image == p.image) else {
            continue;
        };
        let elf = std::fs::read(elf_path)
            .with_context(|| format!("cannot read {}", elf_path.display()))?;
        let data_len = packages
            .iter()
            .find(|(partition, _)| partition == p.name)
            .map_or(0, |(_, package)| package.len() as u64);
        let budget = syssw_core::budget::start_budget(system, &p, &elf, data_len)
            .map_err(|e| anyhow::anyhow!("image {} of partition {}: {e:?}", p.image, p.name))?;
        let at = |key: &str, message: String| {
            config::Diagnostic::at_key(&name, &source, &["partitions", p.name, key], message)
        };
        if budget.memory > p.memory {
            problems.push(at(
                "memory",
                format!(
                    "partition `{}` needs {} KiB to start (image `{}`, data entry {} bytes, stack {} KiB) but has {} KiB",
                    p.name,
                    budget.memory.div_ceil(1024),
                    p.image,
                    data_len,
                    p.stack / 1024,
                    p.memory / 1024
                ),
            ));
        }
        if budget.kernel_memory > p.kernel_memory {
            problems.push(at(
                "kernel_memory",
                format!(
                    "partition `{}` needs {} KiB of kernel memory for the page tables of what syssw maps at its start, but its quota is {} KiB",
                    p.name,
                    budget.kernel_memory / 1024,
                    p.kernel_memory / 1024
                ),
            ));
        }
    }
    if problems.is_empty() {
        return Ok(());
    }
    let lines: Vec<String> = problems.iter().map(|d| d.to_string()).collect();
    Err(BudgetShortfall(format!(
        "configuration {name} cannot boot: syssw would refuse it\n{}",
        lines.join("\n")
    ))
    .into())
}

/// The error of [`check_budgets`]: partitions that do not fit at boot (one diagnostic a
/// line), told apart from failures to build.
#[derive(Debug)]
pub struct BudgetShortfall(String);

impl std::fmt::Display for BudgetShortfall {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BudgetShortfall {}

/// Warnings of a valid description on stderr, `warning: file:line:col: key: reason`.
fn print_warnings(warnings: &[config::Diagnostic]) {
    for w in warnings {
        eprintln!("warning: {w}");
    }
}

/// The command: diagnostics on stderr, one per line, then `config FILE: ok (...)` on stdout
/// or `config FILE: N errors` on stderr. Returns whether the file is valid. A valid file's
/// images are built and every partition's start budget checked ([`check_budgets`]). With
/// `any_image`, image names and budgets are not checked (for descriptions of programs not
/// written yet).
pub fn run(file: &Path, any_image: bool) -> Result<bool> {
    let images = if any_image {
        Vec::new()
    } else {
        known_images()?
    };
    let (name, source) = read(file)?;
    let source = match config::text(&name, &source) {
        Ok(source) => source,
        Err(d) => {
            eprintln!("{d}");
            eprintln!("config {name}: 1 error");
            return Ok(false);
        }
    };
    let known = |image: &str| any_image || images.iter().any(|i| i == image);
    match config::load_with_warnings(&name, source, &known) {
        Ok((system, warnings)) => {
            print_warnings(&warnings);
            // The encoder's output must pass the decoder's own checks.
            let blob = config::binary::encode(&system);
            let view = match config::decode(&blob) {
                Ok(view) => view,
                Err(e) => {
                    bail!("internal error: {name} validated but its binary form is rejected: {e}")
                }
            };
            // The budget syssw computes at boot needs the images (and PLC packages): build
            // them as the image builder does.
            if !any_image && let Err(e) = partition_files(file, &system, &view) {
                let Some(shortfall) = e.downcast_ref::<BudgetShortfall>() else {
                    return Err(e);
                };
                eprintln!("{shortfall}");
                eprintln!("config {name}: does not fit at boot");
                return Ok(false);
            }
            println!(
                "config {name}: ok ({} partitions, {} windows, {} channels)",
                system.partitions.len(),
                system.window_count(),
                system.channels.len()
            );
            Ok(true)
        }
        Err(diagnostics) => {
            for d in &diagnostics {
                eprintln!("{d}");
            }
            if diagnostics
                .iter()
                .any(|d| d.message.starts_with("unknown image"))
            {
                eprintln!(
                    "note: known images (user programs of the workspace): {}",
                    images.join(", ")
                );
            }
            let n = diagnostics.len();
            eprintln!("config {name}: {n} error{}", if n == 1 { "" } else { "s" });
            Ok(false)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_images_are_the_user_programs() {
        let images = known_images().unwrap();
        assert!(images.iter().any(|i| i == "test-usermode"), "{images:?}");
        assert!(!images.iter().any(|i| i == "syssw" || i == "xtask"));
    }

    #[test]
    fn hostile_files_are_refused_without_a_panic() {
        let dir = crate::target_dir().join("check-config-test");
        std::fs::create_dir_all(&dir).unwrap();
        let mut x: u64 = 0x5eed;
        let garbage: Vec<u8> = (0..65_536)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u8
            })
            .collect();
        let files: [(&str, Vec<u8>); 5] = [
            ("empty", Vec::new()),
            ("binary", garbage),
            (
                "latin1",
                b"[system]\nmemory = \"512MiB\"\nname = \"caf\xe9\"\n".to_vec(),
            ),
            (
                "nested",
                format!("x = {}{}", "[".repeat(100_000), "]".repeat(100_000)).into_bytes(),
            ),
            ("nul", b"[system]\nmemory = \"512MiB\0\"\n".to_vec()),
        ];
        for (name, bytes) in files {
            let file = dir.join(format!("{name}.toml"));
            std::fs::write(&file, bytes).unwrap();
            assert!(!run(&file, true).unwrap(), "{name} accepted");
        }
    }

    #[test]
    fn compile_reports_every_diagnostic() {
        let dir = crate::target_dir().join("check-config-test");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bad.toml");
        std::fs::write(
            &file,
            "[system]\nmemory = \"64MB\"\n[partitions.p]\nimage = \"nope\"\nmemory = \"1MiB\"\nkernel_memory = \"4KiB\"\nmax_priority = 1\ntime = \"background\"\n",
        )
        .unwrap();
        let error = format!("{:#}", compile(&file).unwrap_err());
        assert!(error.contains("system.memory"), "{error}");
        assert!(error.contains("unknown image `nope`"), "{error}");
        let good = dir.join("good.toml");
        std::fs::write(&good, "[system]\nmemory = \"64MiB\"\n").unwrap();
        assert!(config::decode(&compile(&good).unwrap()).is_ok());
    }
}
