//! Build, image, run and test tooling for the whole system (host only).
//!
//! The library part is shared with the QEMU scenario tests (`tests/`): building the
//! bare-metal artifacts ([`artifacts`]), assembling an ESP folder with `system.img`
//! ([`esp`]), finding or installing QEMU and OVMF ([`tools`]), booting QEMU with a timeout
//! and capturing the serial log ([`qemu`]), reading scenario manifests ([`scenario`]), the
//! lint gate ([`lint`]), the Linux-side test programs ([`linux`]), the native Linux
//! reference of the guest benchmark ([`native`]), the network benchmark ([`netbench`]), the pictures of a run's serial log
//! ([`plot`], whose parser the scenarios use too), the OSCAT library check ([`oscat`]) and
//! the importer of a653rs-linux system descriptions ([`a653rs`]).

pub mod a653rs;
pub mod a653rs_examples;
pub mod artifacts;
pub mod bench;
pub mod blk;
pub mod check_config;
pub mod diskbench;
pub mod esp;
pub mod forte;
pub mod fortebench;
pub mod guest;
pub mod guestsmpbench;
pub mod iec61499;
pub mod lint;
pub mod linux;
pub mod native;
pub mod netbench;
pub mod nic;
pub mod oscat;
pub mod plc;
pub mod plcnetbench;
pub mod plot;
pub mod pubsubbench;
pub mod qemu;
pub mod scalingbench;
pub mod scenario;
pub mod tools;

use std::path::PathBuf;

/// The workspace root (xtask lives one level below it).
pub fn workspace_root() -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    manifest
        .parent()
        .expect("xtask lives inside the workspace")
        .to_path_buf()
}

/// `target/` of the workspace (honours CARGO_TARGET_DIR).
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"))
}
