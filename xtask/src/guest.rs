//! The guest build step of `system.img`: for each partition with `guest.*` keys, its
//! initramfs, a cpio "newc" archive (written with the `cpio` crate) that becomes the
//! partition's data entry `data/<partition>`. It holds:
//!
//! | path | what |
//! |---|---|
//! | `/bin/busybox` | Debian's `busybox-static` (installed by [`crate::tools::ensure_busybox`]) |
//! | `/bin/*`, `/sbin/*`, `/usr/bin/*`, `/usr/sbin/*` | symbolic links to `busybox`, one per applet, where Debian's `busybox --install` puts them (the list is `busybox --list-full` of the host's binary; [`APPLETS`] if it cannot run) |
//! | `/etc/passwd`, `/etc/group` | root (0) only |
//! | `/etc/guest/init`, `/etc/guest/env` | `guest.init` and `guest.env`, each string NUL-terminated: what the guest starts (`guest::INIT_ARGS_PATH`) |
//! | `/etc/guest/net` | `guest.net` as `key=value` lines (`guest::net::NET_PATH`): the guest's `eth0` and its frames' ports |
//! | `/etc/guest/disk` | `guest.disk` as `key=value` lines (`guest::disk::DISK_PATH`): `request` and `response`, the ports of `/dev/vda`'s link, and `sectors`, its virtual disk's size (the tenant's in `blk.tenants`) |
//! | `/etc/hosts`, `/etc/resolv.conf`, `/etc/nsswitch.conf` | `localhost` (and with `guest.net` the guest as `guest`, its gateway as `gateway`), QEMU's name server 10.0.2.3 with `guest.net`, `hosts: files dns`; a `guest.files` path replaces them |
//! | `/etc/guest/console` | `com2` with `guest.console = "com2"` (`guest::CONSOLE_PATH`): the console is a terminal on COM2 |
//! | `/etc/guest/ports` | the partition's `ports.*`, one a line: `<name> <sampling\|queuing> <in\|out> <size> <refresh ns\|depth>` (`guest::arinc::PORTS_PATH`): the guest's devices `/dev/arinc/<name>` |
//! | `/init` | a shell script that `exec`s the same command (for a reader; the guest runs `/etc/guest/init`) |
//! | `/dev`, `/proc`, `/root`, `/tmp` | empty directories |
//! | each `guest.files` path | the host file, with its permission bits (missing directories are added); a `.st` file at a path ending in `.plcb` is compiled into its bytecode image (what `plcc build` writes, for `plcctl download`) |
//! | `/bin/<name>` of each `guest.programs` name | the Linux program built from `tests/linux` ([`crate::linux`]), or `plcctl` (a Rust program for `x86_64-unknown-linux-musl`, [`crate::linux::build`]) |
//!
//! Every entry belongs to root, has mtime 0 and a fixed inode number, so the archive only
//! changes when busybox or the keys do.

use anyhow::{Context, Result, bail};
use config::System;
use config::system::{Guest, Port};
use std::io::Cursor;
use std::path::Path;

/// `/etc/hosts`, `/etc/resolv.conf`, `/etc/nsswitch.conf` (where the added files may
/// replace them): `localhost` and, with `guest.net`, the guest's own address as `guest`
/// and the gateway as `gateway`; QEMU's DNS (10.0.2.3) for other names.
fn name_files(guest: &Guest) -> Vec<(String, u32, Vec<u8>)> {
    let given = |path: &str| guest.files.iter().any(|(p, _)| p == path);
    let mut hosts = String::from("127.0.0.1\tlocalhost\n");
    let mut resolv = String::from("# The guest has only its loopback: no name server.\n");
    if let Some(net) = &guest.net {
        let [a, b, c, d] = net.address;
        hosts += &format!("{a}.{b}.{c}.{d}\tguest\n");
        if let Some([a, b, c, d]) = net.gateway {
            hosts += &format!("{a}.{b}.{c}.{d}\tgateway\n");
        }
        resolv = "nameserver 10.0.2.3\n".into();
    }
    let mut out = Vec::new();
    for (path, text) in [
        ("/etc/hosts", hosts),
        ("/etc/resolv.conf", resolv),
        ("/etc/nsswitch.conf", "hosts: files dns\n".into()),
    ] {
        if !given(path) {
            out.push((path, text));
        }
    }
    out.into_iter()
        .map(|(path, text)| (path[1..].to_string(), S_IFREG | 0o644, text.into_bytes()))
        .collect()
}

/// The applets linked in `/bin` when the host cannot run busybox to list them.
pub const APPLETS: &[&str] = &["sh", "echo", "cat", "ls", "wc", "true"];

/// Where each applet of the busybox at `path` goes (`bin/ls`, `usr/bin/awk`): its
/// `--list-full`, or [`APPLETS`] in `/bin` if it cannot run here.
fn applet_paths(path: &Path) -> Vec<String> {
    let listed = std::process::Command::new(path)
        .arg("--list-full")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned());
    let mut paths: Vec<String> = match listed {
        Some(text) => text
            .lines()
            .map(str::trim)
            // Applets in a directory only (not `linuxrc`), and not busybox itself.
            .filter(|l| l.contains('/') && !l.ends_with('/') && *l != "bin/busybox")
            .filter(|l| l.split('/').all(|part| !part.is_empty() && part != ".."))
            .map(str::to_string)
            .collect(),
        None => APPLETS.iter().map(|a| format!("bin/{a}")).collect(),
    };
    paths.sort();
    paths.dedup();
    paths
}

pub const S_IFREG: u32 = 0o100000;
pub const S_IFDIR: u32 = 0o040000;
const S_IFLNK: u32 = 0o120000;

/// An initramfs entry: its path (no leading `/`), mode (file type and permission bits) and
/// contents (a symbolic link's target).
pub type Entry = (String, u32, Vec<u8>);

/// Debian's static busybox (installed if missing, refused if dynamic) and the paths of its
/// applet links.
pub fn busybox() -> Result<(Vec<u8>, Vec<String>)> {
    let path = crate::tools::ensure_busybox()?;
    let bytes = std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
    check_static(&path, &bytes)?;
    Ok((bytes, applet_paths(&path)))
}

/// `(partition name, initramfs)` for every guest partition of `system`.
pub fn initramfs_images(system: &System) -> Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    let mut busybox_and_applets = None;
    for p in &system.partitions {
        let Some(guest) = &p.guest else {
            continue;
        };
        if busybox_and_applets.is_none() {
            busybox_and_applets = Some(busybox()?);
        }
        let (busybox, applets) = busybox_and_applets.as_ref().expect("just read");
        let archive = initramfs(busybox, applets, guest, &p.ports)
            .with_context(|| format!("partition {}: cannot write its initramfs", p.name))?;
        out.push((p.name.clone(), archive));
    }
    Ok(out)
}

/// Refuses a busybox the guest cannot run (Debian's dynamically linked `busybox` package
/// installs the same path as `busybox-static`).
fn check_static(path: &Path, elf: &[u8]) -> Result<()> {
    if let Err(e) = guest::elf::LoadPlan::new(elf) {
        bail!(
            "{} cannot run in the guest: {e}. Install the static one: apt-get install -y {}",
            path.display(),
            crate::tools::BUSYBOX_PACKAGE
        );
    }
    Ok(())
}

/// The permission bits of a host file (0644 where the platform has none).
fn file_mode(path: &Path) -> u32 {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if let Ok(meta) = std::fs::metadata(path) {
            return meta.permissions().mode() & 0o7777;
        }
    }
    let _ = path;
    0o644
}

/// Each string followed by a NUL.
fn nul_terminated(strings: &[String]) -> Vec<u8> {
    strings.iter().flat_map(|s| s.bytes().chain([0])).collect()
}

/// `s` quoted for the shell.
pub fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// The port table of `/etc/guest/ports` (see the module's table).
fn port_table(ports: &[Port]) -> Vec<u8> {
    let mut text = String::new();
    for p in ports {
        let refresh_or_depth = match p.kind {
            config::model::PortKind::Sampling => p.refresh,
            config::model::PortKind::Queuing => u64::from(p.depth),
        };
        text += &format!(
            "{} {} {} {} {refresh_or_depth}\n",
            p.name,
            p.kind.name(),
            p.direction.name(),
            p.size
        );
    }
    text.into_bytes()
}

/// The initramfs of a guest whose first process is `guest` and whose ARINC ports are
/// `ports`, with `busybox` as `/bin/busybox` and a link to it at each of `applets`
/// (`bin/ls`, `usr/bin/awk`).
pub fn initramfs(
    busybox: &[u8],
    applets: &[String],
    guest: &Guest,
    ports: &[Port],
) -> Result<Vec<u8>> {
    archive(entries(busybox, applets, guest, ports)?)
}

/// The entries of [`initramfs`], in archive order.
pub fn entries(
    busybox: &[u8],
    applets: &[String],
    guest: &Guest,
    ports: &[Port],
) -> Result<Vec<Entry>> {
    let dir = |name: &str| (name.to_string(), S_IFDIR | 0o755, Vec::new());
    let file = |name: &str, mode: u32, data: Vec<u8>| (name.to_string(), S_IFREG | mode, data);
    let mut entries = vec![
        dir("."),
        dir("bin"),
        file("bin/busybox", 0o755, busybox.to_vec()),
    ];
    for dir in ["sbin", "usr", "usr/bin", "usr/sbin"] {
        if applets.iter().any(|a| a.starts_with(&format!("{dir}/"))) {
            entries.push((dir.to_string(), S_IFDIR | 0o755, Vec::new()));
        }
    }
    for applet in applets {
        let target: &[u8] = if applet.starts_with("bin/") {
            b"busybox"
        } else {
            b"/bin/busybox"
        };
        entries.push((applet.clone(), S_IFLNK | 0o777, target.to_vec()));
    }
    let command: Vec<String> = guest.init.iter().map(|s| quote(s)).collect();
    entries.extend([
        dir("dev"),
        dir("etc"),
        file(
            "etc/passwd",
            0o644,
            b"root:x:0:0:root:/root:/bin/sh\n".to_vec(),
        ),
        file("etc/group", 0o644, b"root:x:0:\n".to_vec()),
        dir("etc/guest"),
        file("etc/guest/init", 0o644, nul_terminated(&guest.init)),
        file("etc/guest/env", 0o644, nul_terminated(&guest.env)),
    ]);
    if guest.console_com2 {
        entries.push(file("etc/guest/console", 0o644, b"com2\n".to_vec()));
    }
    if let Some(net) = &guest.net {
        entries.push(file("etc/guest/net", 0o644, net.file().into_bytes()));
    }
    if let Some(disk) = &guest.disk {
        entries.push(file("etc/guest/disk", 0o644, disk.file().into_bytes()));
    }
    entries.extend(name_files(guest));
    if !ports.is_empty() {
        entries.push(file("etc/guest/ports", 0o644, port_table(ports)));
    }
    entries.extend([
        file(
            "init",
            0o755,
            format!("#!/bin/sh\nexec {}\n", command.join(" ")).into_bytes(),
        ),
        dir("proc"),
        dir("root"),
        dir("tmp"),
    ]);
    for name in &guest.programs {
        let path = crate::linux::build(name)?;
        let data =
            std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
        entries.push((format!("bin/{name}"), S_IFREG | 0o755, data));
    }
    for (target, source) in &guest.files {
        let data = if target.ends_with(".plcb") && source.path.ends_with(".st") {
            crate::plc::image_of(&format!("guest.files {target}"), source)?
        } else {
            std::fs::read(&source.path)
                .with_context(|| format!("guest.files: cannot read {}", source.path))?
        };
        let mode = file_mode(Path::new(&source.path));
        let name = target.trim_start_matches('/');
        if let Some(existing) = entries.iter_mut().find(|e| e.0 == name) {
            // /etc/passwd or /etc/group (the validator refuses the others).
            *existing = (name.to_string(), S_IFREG | mode, data);
            continue;
        }
        let mut dir = String::new();
        for part in name.split('/').take(name.split('/').count() - 1) {
            if !dir.is_empty() {
                dir.push('/');
            }
            dir.push_str(part);
            if !entries.iter().any(|e| e.0 == dir) {
                entries.push((dir.clone(), S_IFDIR | 0o755, Vec::new()));
            }
        }
        entries.push((name.to_string(), S_IFREG | mode, data));
    }
    Ok(entries)
}

/// `entries` as a cpio "newc" archive: each belongs to root, has mtime 0 and its position as
/// inode number.
pub fn archive(entries: Vec<Entry>) -> Result<Vec<u8>> {
    let inputs = entries
        .into_iter()
        .enumerate()
        .map(|(i, (name, mode, data))| {
            (
                cpio::newc::Builder::new(&name)
                    .ino(i as u32 + 1)
                    .mode(mode)
                    .uid(0)
                    .gid(0)
                    .nlink(if mode & S_IFDIR != 0 { 2 } else { 1 })
                    .mtime(0),
                Cursor::new(data),
            )
        });
    let out = cpio::write_cpio(inputs, Cursor::new(Vec::new()))?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use guest::cpio::Archive;

    fn applets() -> Vec<String> {
        ["bin/sh", "bin/ls", "usr/bin/awk"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    }

    fn hello() -> Guest {
        Guest {
            init: vec!["/bin/busybox".into(), "echo".into(), "it's".into()],
            env: vec!["PATH=/bin".into()],
            files: Vec::new(),
            console_com2: false,
            programs: Vec::new(),
            net: None,
            disk: None,
        }
    }

    #[test]
    fn files_are_added_with_their_directories() {
        let dir = std::env::temp_dir().join(format!("xtask-guest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let source = |name: &str, text: &str| {
            let path = dir.join(name);
            std::fs::write(&path, text).unwrap();
            config::system::SourceFile {
                name: name.into(),
                path: path.to_string_lossy().into_owned(),
            }
        };
        let mut g = hello();
        g.files = vec![
            (
                "/etc/passwd".into(),
                source("passwd", "root:x:0:0::/:/bin/sh\n"),
            ),
            ("/opt/app/run.sh".into(), source("run.sh", "echo hi\n")),
        ];
        let bytes = initramfs(b"ELF", &applets(), &g, &[]).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        assert_eq!(
            fs.get("/etc/passwd").unwrap().data,
            b"root:x:0:0::/:/bin/sh\n"
        );
        assert_eq!(fs.entries().filter(|e| e.path() == "etc/passwd").count(), 1);
        assert!(fs.get("/opt").unwrap().is_dir());
        assert!(fs.get("/opt/app").unwrap().is_dir());
        let run = fs.get("/opt/app/run.sh").unwrap();
        assert_eq!(run.data, b"echo hi\n");
        assert!(run.is_file());
        g.files = vec![(
            "/etc/motd".into(),
            config::system::SourceFile {
                name: "gone".into(),
                path: dir.join("gone").to_string_lossy().into_owned(),
            },
        )];
        let err = initramfs(b"ELF", &applets(), &g, &[]).unwrap_err();
        assert!(format!("{err:#}").contains("cannot read"), "{err:#}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn programs_are_built_into_bin() {
        let mut g = hello();
        g.programs = vec!["linux-tests".into()];
        let bytes = initramfs(b"ELF", &applets(), &g, &[]).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        let program = fs.get("/bin/linux-tests").unwrap();
        assert!(program.data.starts_with(b"\x7fELF"));
        assert_eq!(program.mode, S_IFREG | 0o755);
        guest::elf::LoadPlan::new(program.data).unwrap();
    }

    #[test]
    fn the_guest_reads_the_initramfs_it_gets() {
        let bytes = initramfs(b"\x7fELF-busybox", &applets(), &hello(), &[]).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        let files = guest::vfs::Fs::new(&fs, 1 << 20).unwrap();
        for applet in applets() {
            let found = guest::exec::find(&files, 1, guest::vfs::Node::Inode(0), applet.as_bytes())
                .unwrap();
            assert_eq!(found.exe.as_str(), "bin/busybox", "{applet}");
            assert_eq!(found.bytes, b"\x7fELF-busybox");
        }
        assert_eq!(fs.get("/bin/busybox").unwrap().mode, S_IFREG | 0o755);
        assert!(fs.get("/usr/bin").unwrap().is_dir());
        assert!(fs.get("/sbin").is_none(), "no applet there");
        let args = fs.get(guest::INIT_ARGS_PATH).unwrap();
        assert_eq!(args.data, b"/bin/busybox\0echo\0it's\0");
        assert_eq!(fs.get(guest::INIT_ENV_PATH).unwrap().data, b"PATH=/bin\0");
        assert_eq!(
            fs.get("/init").unwrap().data,
            b"#!/bin/sh\nexec '/bin/busybox' 'echo' 'it'\\''s'\n"
        );
        assert!(
            fs.get("/etc/passwd")
                .unwrap()
                .data
                .starts_with(b"root:x:0:0:")
        );
        assert!(fs.get("/etc/group").unwrap().is_file());
        assert!(fs.get("/tmp").unwrap().is_dir());
        assert!(
            fs.get(guest::CONSOLE_PATH).is_none(),
            "the console is the log"
        );
        let mut g = hello();
        g.console_com2 = true;
        let with_console = initramfs(b"\x7fELF-busybox", &applets(), &g, &[]).unwrap();
        let console = Archive::new(&with_console).unwrap();
        assert_eq!(console.get(guest::CONSOLE_PATH).unwrap().data, b"com2\n");
        // Deterministic.
        assert_eq!(
            bytes,
            initramfs(b"\x7fELF-busybox", &applets(), &hello(), &[]).unwrap()
        );
    }

    #[test]
    fn a_structured_text_file_becomes_its_bytecode_image() {
        let st = crate::workspace_root().join("tests/configs/plc/counter.st");
        let mut g = hello();
        g.files = vec![(
            "/root/counter.plcb".into(),
            config::system::SourceFile {
                name: "counter.st".into(),
                path: st.to_string_lossy().into_owned(),
            },
        )];
        let bytes = initramfs(b"ELF", &applets(), &g, &[]).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        let image = fs.get("/root/counter.plcb").unwrap().data;
        assert!(image.starts_with(b"PLCB"), "{:?}", &image[..8]);
    }

    #[test]
    fn the_port_table_is_what_the_guest_reads() {
        use config::model::{Direction, Discipline, PortKind};
        let port = |name: &str, kind, direction, size, depth, refresh| Port {
            name: name.into(),
            kind,
            direction,
            size,
            depth,
            refresh,
            discipline: Discipline::Fifo,
            channel: 0,
        };
        let ports = [
            port(
                "level",
                PortKind::Sampling,
                Direction::In,
                8,
                0,
                100_000_000,
            ),
            port("plc-request", PortKind::Queuing, Direction::Out, 256, 4, 0),
        ];
        let bytes = initramfs(b"ELF", &applets(), &hello(), &ports).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        let table = fs.get(guest::arinc::PORTS_PATH).unwrap().data;
        assert_eq!(
            table,
            b"level sampling in 8 100000000\nplc-request queuing out 256 4\n"
        );
        let read = guest::arinc::parse(table).unwrap();
        assert_eq!(read[1].name, "plc-request");
        assert_eq!(read[1].refresh_or_depth, 4);
        let none = initramfs(b"ELF", &applets(), &hello(), &[]).unwrap();
        assert!(
            Archive::new(&none)
                .unwrap()
                .get(guest::arinc::PORTS_PATH)
                .is_none()
        );
    }

    #[test]
    fn the_disk_file_is_what_the_guest_reads() {
        let mut g = hello();
        g.disk = Some(config::system::GuestDisk {
            request: "vda-req".into(),
            response: "vda-resp".into(),
            sectors: 4096,
        });
        let bytes = initramfs(b"ELF", &applets(), &g, &[]).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        let text = fs.get(guest::disk::DISK_PATH).unwrap().data;
        assert_eq!(text, b"request=vda-req\nresponse=vda-resp\nsectors=4096\n");
        let read = guest::disk::parse_disk_file(std::str::from_utf8(text).unwrap()).unwrap();
        assert_eq!(
            (read.request, read.response, read.sectors),
            ("vda-req", "vda-resp", 4096)
        );
        let none = initramfs(b"ELF", &applets(), &hello(), &[]).unwrap();
        assert!(
            Archive::new(&none)
                .unwrap()
                .get(guest::disk::DISK_PATH)
                .is_none()
        );
    }

    #[test]
    fn applets_are_listed_by_the_busybox_itself() {
        let Some(path) = crate::tools::BUSYBOX_PATHS
            .iter()
            .map(Path::new)
            .find(|p| p.is_file())
        else {
            return; // no busybox on this host: the fallback list is used
        };
        let paths = applet_paths(path);
        assert!(paths.contains(&"bin/sh".to_string()), "{paths:?}");
        assert!(!paths.contains(&"bin/busybox".to_string()));
        assert!(paths.iter().all(|p| p.contains('/')));
        let missing = Path::new("/nonexistent/busybox");
        assert_eq!(applet_paths(missing).len(), APPLETS.len());
    }

    #[test]
    fn a_dynamic_busybox_is_refused_with_the_fix() {
        let err = check_static(Path::new("/bin/busybox"), b"#!/bin/sh\n").unwrap_err();
        let text = err.to_string();
        assert!(text.contains("apt-get install -y busybox-static"), "{text}");
    }
}
