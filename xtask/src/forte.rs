//! 4diac FORTE, the IEC 61499 reference runtime of Eclipse 4diac, as a peer on the host for
//! the tests that check the soft-PLC's publish/subscribe against the real thing (test
//! `net_pubsub_forte`), and statically linked as the other leg of the IEC 61499 benchmark
//! (`crate::fortebench`). Its sources are never committed: a checkout in
//! `target/4diac-forte/src` (or the directory `FORTE_SRC` names) is built here once, with
//! CMake and the host's C++ compiler, into `target/4diac-forte/build` (about two minutes
//! on two cores; the static one into `build-static`); `FORTE` may name a built `forte`
//! binary instead (for the tests).
//!
//! The build: the POSIX architecture with the Ethernet and FBDK communication layers (UDP
//! PUBLISH_n/SUBSCRIBE_n in the FBDK ASN.1 encoding) and the IEC 61131-3, conversion and
//! utility function blocks; FORTE's own tests off.

use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::process::Command;

/// How to get FORTE when it is missing.
pub const HOW_TO_GET: &str = "get its sources with: git clone https://github.com/eclipse-4diac/4diac-forte target/4diac-forte/src (CMake and a C++ compiler build them; apt-get install cmake g++), or point FORTE at a built forte binary";

/// FORTE's CMake options for this build.
const OPTIONS: [&str; 10] = [
    "-DCMAKE_BUILD_TYPE=Release",
    "-DFORTE_ARCHITECTURE=Posix",
    "-DFORTE_COM_ETH=ON",
    "-DFORTE_COM_FBDK=ON",
    "-DFORTE_COM_LOCAL=ON",
    "-DFORTE_MODULE_CONVERT=ON",
    "-DFORTE_MODULE_IEC61131=ON",
    "-DFORTE_MODULE_UTILS=ON",
    "-DFORTE_TESTS=OFF",
    "-DFORTE_LOGLEVEL=LOGINFO",
];

/// The `forte` binary: `FORTE`, an earlier build, or a build of the sources now; `None`
/// when there are no sources (then [`HOW_TO_GET`] says what to do); an error when the
/// build fails.
pub fn binary() -> Result<Option<PathBuf>> {
    if let Some(path) = std::env::var_os("FORTE") {
        let path = PathBuf::from(path);
        if !path.is_file() {
            bail!("FORTE={}: no such file", path.display());
        }
        return Ok(Some(path));
    }
    build("build", &[])
}

/// A statically linked `forte` (the same options, into `target/4diac-forte/build-static`):
/// what the IEC 61499 benchmark runs on Debian's stock kernel, whose initramfs has no C++
/// library. `None` and an error as [`binary`].
pub fn static_binary() -> Result<Option<PathBuf>> {
    build("build-static", &["-DCMAKE_EXE_LINKER_FLAGS=-static"])
}

/// `forte` built from the sources into `target/4diac-forte/<dir>` with [`OPTIONS`] and
/// `extra`, unless it is there already.
fn build(dir: &str, extra: &[&str]) -> Result<Option<PathBuf>> {
    let root = crate::target_dir().join("4diac-forte");
    let build = root.join(dir);
    let built = build.join("src").join("forte");
    if built.is_file() {
        return Ok(Some(built));
    }
    let src = std::env::var_os("FORTE_SRC")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("src"));
    if !src.join("CMakeLists.txt").is_file() {
        return Ok(None);
    }
    eprintln!(
        "xtask: building 4diac FORTE from {} into {}",
        src.display(),
        build.display()
    );
    let run = |command: &mut Command, what: &str| -> Result<()> {
        let status = command
            .status()
            .with_context(|| format!("cannot run {what} (apt-get install cmake g++)"))?;
        if !status.success() {
            bail!(
                "{what} failed ({status}) building FORTE from {}",
                src.display()
            );
        }
        Ok(())
    };
    run(
        Command::new("cmake")
            .arg("-S")
            .arg(&src)
            .arg("-B")
            .arg(&build)
            .args(OPTIONS)
            .args(extra),
        "cmake",
    )?;
    run(
        Command::new("cmake")
            .arg("--build")
            .arg(&build)
            .args(["--parallel", "2"]),
        "cmake --build",
    )?;
    if !built.is_file() {
        bail!("the FORTE build made no {}", built.display());
    }
    Ok(Some(built))
}
