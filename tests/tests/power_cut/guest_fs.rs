//! The guest's file system under power cuts: ext2 on its `/dev/vda` (sectors
//! [`FIRST_SECTOR`].. of the disk), mounted at `/data`, where the guest replaces one file by
//! write, fsync, rename and fsync in a loop, printing `power_cut: fs durable <v>` once
//! version `v` is on the disk.
//!
//! A version's file is `version <v>` and then the numbers 1 to 200 + `v` % 300, a line
//! each ([`contents`]): its length and bytes follow from its first line, so a torn or
//! mixed file shows.
//!
//! At each boot the guest does what a Linux system set to repair (Debian's `FSCKFIX=yes`)
//! does after an unclean shutdown before it mounts an ext2 file system: `e2fsck -y`. Its
//! exit status must be 0 or 1. Ext2 has no journal, so a cut in the middle of a write-back
//! may leave what Linux's ext2 leaves too: free counts, bitmaps, link counts, or an
//! unattached inode (the replaced version of the file, whose entry the rename had already
//! moved; `e2fsck -p` does not repair that without asking, `-y` puts it in `lost+found`).
//! Then it mounts and reads the file back (`power_cut: fs found <v> intact`).
//!
//! After each cut, on the host, on a copy of the guest's range of the disk image: `e2fsck
//! -fn` (tallied as clean, or by what needed repair), `e2fsck -fy` (its status at most 1),
//! `e2fsck -fn` again (clean), and `debugfs`'s `cat /f`: an intact version no older than
//! the last one the guest reported durable before the cut. The next boot must find the
//! same.

use super::Workload;
use std::path::{Path, PathBuf};
use std::process::Command;
use xtask::qemu::Outcome;

/// The guest's virtual disk in the configuration: sectors 4096..8192 of the disk.
const FIRST_SECTOR: usize = 4096;
const SECTORS: usize = 4096;
/// A version the guest finds may be this much newer than the last it reported durable
/// (its line still on the way when the power went).
const UNREPORTED: u64 = 2;

/// The file of version `v`.
pub fn contents(v: u64) -> String {
    let mut text = format!("version {v}\n");
    for n in 1..=200 + v % 300 {
        text.push_str(&format!("{n}\n"));
    }
    text
}

/// The version `text` is if it is one intact, else what is wrong.
fn version_of(text: &str) -> Result<u64, String> {
    let first = text.lines().next().unwrap_or("");
    let v = first
        .strip_prefix("version ")
        .and_then(|v| v.trim().parse::<u64>().ok())
        .ok_or_else(|| format!("no version line: {first:?}"))?;
    if text != contents(v) {
        return Err(format!(
            "version {v} damaged: {} bytes, {} expected",
            text.len(),
            contents(v).len()
        ));
    }
    Ok(v)
}

pub struct GuestFiles {
    /// The newest version the last boot reported durable (`None`: none yet).
    durable: Option<u64>,
    /// What the host found after the last cut.
    found: Option<u64>,
    /// Cuts after which the file system was not clean, and after which it was.
    unclean: u32,
    clean: u32,
    /// Versions made durable over the whole run.
    versions: u64,
    work: PathBuf,
}

impl GuestFiles {
    pub fn new(work: &Path) -> GuestFiles {
        GuestFiles {
            durable: None,
            found: None,
            unclean: 0,
            clean: 0,
            versions: 0,
            work: work.join("guest-fs"),
        }
    }

    /// `e2fsck` with `args` on `image`: its exit status and output.
    fn e2fsck(&self, args: &[&str], image: &Path) -> Result<(i32, String), String> {
        let ran = Command::new(tool("e2fsck"))
            .args(args)
            .arg(image)
            .output()
            .map_err(|e| format!("the host's e2fsck does not run: {e}"))?;
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&ran.stdout),
            String::from_utf8_lossy(&ran.stderr)
        );
        Ok((ran.status.code().unwrap_or(-1), text))
    }
}

/// e2fsprogs' `name` (in /sbin where PATH may lack it).
fn tool(name: &str) -> String {
    ["/sbin", "/usr/sbin"]
        .iter()
        .map(|dir| format!("{dir}/{name}"))
        .find(|p| Path::new(p).is_file())
        .unwrap_or_else(|| name.to_string())
}

impl Workload for GuestFiles {
    fn name(&self) -> &'static str {
        "guest fs"
    }

    fn check_boot(&mut self, boot: &Outcome) -> Result<(), String> {
        let out = scenarios::guest_output(boot);
        let field = |prefix: &str| {
            out.iter()
                .find_map(|l| l.strip_prefix(prefix))
                .map(str::to_string)
        };
        if let Some(fsck) = field("power_cut: fsck ") {
            let status: i32 = fsck.trim().parse().map_err(|_| format!("fsck {fsck:?}"))?;
            if status > 1 {
                return Err(format!("e2fsck -y in the guest ended {status}: {out:#?}"));
            }
        }
        if out.iter().any(|l| l == "power_cut: mount failed") {
            return Err(format!("the guest could not mount /data: {out:#?}"));
        }
        match (field("power_cut: fs found "), self.found) {
            (None, None) => {}
            (Some(found), Some(host)) => {
                let v: u64 = found
                    .split_whitespace()
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| format!("fs found {found:?}"))?;
                if v != host || !found.ends_with(" intact") {
                    return Err(format!(
                        "the guest found {found:?}, the host version {host} intact"
                    ));
                }
            }
            (found, host) => {
                return Err(format!(
                    "the guest found {found:?}, the host {host:?} after the cut"
                ));
            }
        }
        let durable: Vec<u64> = out
            .iter()
            .filter_map(|l| {
                l.strip_prefix("power_cut: fs durable ")?
                    .trim()
                    .parse()
                    .ok()
            })
            .collect();
        if durable.windows(2).any(|w| w[1] != w[0] + 1) {
            return Err(format!("versions not one after another: {durable:?}"));
        }
        self.versions += durable.len() as u64;
        if let Some(&last) = durable.last() {
            self.durable = Some(last);
        }
        Ok(())
    }

    fn after_cut(&mut self, image: &[u8]) -> Result<(Vec<&'static str>, String), String> {
        std::fs::create_dir_all(&self.work).map_err(|e| e.to_string())?;
        let range = image
            .get(FIRST_SECTOR * 512..(FIRST_SECTOR + SECTORS) * 512)
            .ok_or("the guest's range is beyond the disk image")?;
        let copy = self.work.join("vda.img");
        std::fs::write(&copy, range).map_err(|e| e.to_string())?;
        let (status, found) = self.e2fsck(&["-fn"], &copy)?;
        let tag = if status == 0 {
            self.clean += 1;
            "fs clean"
        } else if found.contains("Unattached inode") {
            self.unclean += 1;
            "fs repaired: an unattached inode"
        } else {
            self.unclean += 1;
            "fs repaired"
        };
        let (status, text) = self.e2fsck(&["-fy"], &copy)?;
        if status > 1 {
            return Err(format!("e2fsck -fy ended {status}:\n{text}"));
        }
        let (status, text) = self.e2fsck(&["-fn"], &copy)?;
        if status != 0 {
            return Err(format!("not clean after e2fsck -fy ({status}):\n{text}"));
        }
        let cat = Command::new(tool("debugfs"))
            .args(["-R", "cat /f"])
            .arg(&copy)
            .output()
            .map_err(|e| format!("the host's debugfs does not run: {e}"))?;
        let text = String::from_utf8_lossy(&cat.stdout);
        if text.is_empty() && self.durable.is_none() {
            // Cut before the first version was made durable: no file yet is right.
            self.found = None;
            return Ok((vec![tag], "no file yet".into()));
        }
        let version = version_of(&text)?;
        if let Some(durable) = self.durable
            && (version < durable || version > durable + UNREPORTED)
        {
            return Err(format!(
                "version {version} on the disk; {durable} was reported durable"
            ));
        }
        self.found = Some(version);
        Ok((
            vec![tag],
            format!(
                "version {version} ({} reported durable){}",
                self.durable.map_or("none".into(), |d| d.to_string()),
                if tag == "fs clean" {
                    ""
                } else {
                    ", repaired by e2fsck -y"
                }
            ),
        ))
    }

    fn finish(&self) -> Result<String, String> {
        if self.versions == 0 {
            return Err("no version was ever made durable: the cuts missed the loop".into());
        }
        Ok(format!(
            "{} versions made durable; after the cuts the file system was clean {} times, repaired by e2fsck -y {} times, the newest durable version always there",
            self.versions, self.clean, self.unclean
        ))
    }
}

#[test]
fn every_version_reads_back_and_a_damaged_one_is_refused() {
    for v in [0, 1, 299, 300, 12_345] {
        assert_eq!(version_of(&contents(v)), Ok(v));
    }
    let mut torn = contents(7);
    torn.truncate(torn.len() - 3);
    assert!(version_of(&torn).is_err());
    assert!(version_of("").is_err());
}
