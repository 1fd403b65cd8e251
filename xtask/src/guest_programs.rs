//! C test programs for a guest's initramfs: a `guest.files` source whose name ends in `.c`
//! is compiled with the host's `gcc -static` (glibc's static library, Debian's `libc6-dev`)
//! into `target/guest-programs/<name>`, and that executable goes into the initramfs in its
//! place, mode 0755. The compile is skipped when the executable is newer than its source.

use anyhow::{Context, Result, bail};
use std::path::Path;
use std::process::Command;

/// The bytes and permission bits `guest.files` puts in the initramfs for `source`: the file
/// itself (`None`: its own mode), or the program compiled from a `.c` source.
pub fn contents(source: &Path) -> Result<(Vec<u8>, Option<u32>)> {
    if source.extension().is_none_or(|e| e != "c") {
        let data = std::fs::read(source)
            .with_context(|| format!("guest.files: cannot read {}", source.display()))?;
        return Ok((data, None));
    }
    let dir = crate::target_dir().join("guest-programs");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let stem = source.file_stem().unwrap_or_default();
    let output = dir.join(stem);
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    let fresh = matches!((modified(&output), modified(source)), (Some(o), Some(s)) if o > s);
    if !fresh {
        let status = Command::new("gcc")
            .args(["-static", "-O1", "-Wall", "-o"])
            .arg(&output)
            .arg(source)
            .status()
            .context("guest.files: cannot run gcc (apt-get install -y gcc libc6-dev)")?;
        if !status.success() {
            bail!(
                "guest.files: gcc -static {} failed ({status})",
                source.display()
            );
        }
    }
    let data =
        std::fs::read(&output).with_context(|| format!("cannot read {}", output.display()))?;
    Ok((data, Some(0o755)))
}
