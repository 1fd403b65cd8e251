//! Assembles an ESP folder for QEMU's `fat:rw:DIR` drive:
//! `EFI/BOOT/BOOTX64.EFI` (loader), `kernel.elf`, `system.img`.

use crate::artifacts::Artifacts;
use abi::sysimg::builder::SystemImageBuilder;
use anyhow::{Context, Result, anyhow};
use std::fs;
use std::path::{Path, PathBuf};

/// One entry of the system image to be, read from a file or given inline.
pub enum ImageEntry {
    File { name: String, path: PathBuf },
    Bytes { name: String, data: Vec<u8> },
}

pub fn build_system_image(entries: &[ImageEntry]) -> Result<Vec<u8>> {
    let mut builder = SystemImageBuilder::new();
    for entry in entries {
        let (name, data) = match entry {
            ImageEntry::File { name, path } => {
                let data = fs::read(path).with_context(|| {
                    format!(
                        "cannot read {} for system image entry {name:?}",
                        path.display()
                    )
                })?;
                (name, data)
            }
            ImageEntry::Bytes { name, data } => (name, data.clone()),
        };
        builder.add(name, data).map_err(|e| anyhow!(e))?;
    }
    Ok(builder.build())
}

/// Writes the ESP folder `dir` (emptied first) and returns it.
pub fn assemble(dir: &Path, artifacts: &Artifacts, entries: &[ImageEntry]) -> Result<PathBuf> {
    if dir.exists() {
        fs::remove_dir_all(dir).with_context(|| format!("cannot clear {}", dir.display()))?;
    }
    let boot = dir.join("EFI").join("BOOT");
    fs::create_dir_all(&boot).with_context(|| format!("cannot create {}", boot.display()))?;
    fs::copy(&artifacts.loader, boot.join("BOOTX64.EFI"))
        .with_context(|| format!("cannot copy the loader {}", artifacts.loader.display()))?;
    fs::copy(&artifacts.kernel, dir.join("kernel.elf"))
        .with_context(|| format!("cannot copy the kernel {}", artifacts.kernel.display()))?;
    let image = build_system_image(entries)?;
    fs::write(dir.join("system.img"), image).context("cannot write system.img")?;
    Ok(dir.to_path_buf())
}

/// The standard entries: syssw, and for a system description its binary form (`config`,
/// validated first: an invalid one stops the build with its diagnostics) and the image of
/// every partition (`partition/<image>`, built here).
pub fn standard_entries(artifacts: &Artifacts, config: Option<&Path>) -> Result<Vec<ImageEntry>> {
    let mut entries = vec![ImageEntry::File {
        name: "syssw".into(),
        path: artifacts.syssw.clone(),
    }];
    if let Some(config) = config {
        let described = crate::check_config::load(config)?;
        let blob = config::binary::encode(&described);
        let system = config::decode(&blob).map_err(|e| anyhow!("{e}"))?;
        let (built, packages) = crate::check_config::partition_files(config, &described, &system)?;
        for (image, path) in built {
            entries.push(ImageEntry::File {
                name: format!("partition/{image}"),
                path,
            });
        }
        for (partition, package) in packages {
            entries.push(ImageEntry::Bytes {
                name: format!("{}{partition}", config::binary::DATA_ENTRY_PREFIX),
                data: package,
            });
        }
        entries.push(ImageEntry::Bytes {
            name: "config".into(),
            data: blob,
        });
    }
    Ok(entries)
}
