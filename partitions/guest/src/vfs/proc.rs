//! `/proc`: the files busybox reads about the processes and the system, made from the
//! process table when they are opened (a snapshot, as a single `read` of a small file on
//! Linux is). `/proc/self` (a link to the caller's directory), `/proc/<pid>/` with `exe`
//! (a link to the executable), `stat` (Linux's format, what `ps` parses; field 39 is the
//! thread's CPU), `status` (name, state, ids, size and the allowed CPUs as `Name:\t...`
//! lines) and `cmdline` (the arguments, each
//! NUL-terminated) and `fd/` (a link per open descriptor: to the file's path,
//! `/dev/console` or `pipe:[<n>]`; opening one opens what the descriptor has, even a pipe,
//! as Linux's magic links do: `/dev/fd` links here), `/proc/meminfo`, `/proc/uptime` and
//! `/proc/mounts`, `/proc/filesystems` (what `mount` without `-t` tries), `/proc/cpuinfo`
//! (a block per CPU of the guest: [`super::cpuinfo`]), `/proc/net/dev` and `/proc/net/route` (the interfaces and routes of
//! [`crate::net`]). Nothing here can be written, created or removed.
//!
//! The process table belongs to [`crate::system`]; the system calls see it through
//! [`ProcessTable`], read-only, as [`Procs`]: the caller and the others.

use super::{SliceWriter, Stat};
use crate::cpio::{S_IFDIR, S_IFLNK, S_IFREG};
use alloc::vec::Vec;
use core::fmt::Write;

/// A node of `/proc`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    /// `/proc` itself.
    Root,
    /// `/proc/self`.
    SelfLink,
    Meminfo,
    Uptime,
    Mounts,
    Filesystems,
    Cpuinfo,
    /// `/proc/<pid>`.
    Process(u32),
    /// `/proc/<pid>/<file>`.
    File(u32, File),
    /// `/proc/<pid>/fd`.
    Fds(u32),
    /// `/proc/<pid>/fd/<n>`: a link to what descriptor `n` has open.
    Fd(u32, u32),
    /// `/proc/net`, and its `dev` and `route`.
    Net,
    NetDev,
    NetRoute,
}

/// A file of `/proc/<pid>/`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum File {
    Exe,
    Stat,
    Status,
    Cmdline,
}

const PROCESS_FILES: [(&str, File); 4] = [
    ("exe", File::Exe),
    ("stat", File::Stat),
    ("status", File::Status),
    ("cmdline", File::Cmdline),
];
const SYSTEM_FILES: [(&str, Node); 7] = [
    ("self", Node::SelfLink),
    ("meminfo", Node::Meminfo),
    ("uptime", Node::Uptime),
    ("mounts", Node::Mounts),
    ("filesystems", Node::Filesystems),
    ("net", Node::Net),
    ("cpuinfo", Node::Cpuinfo),
];
const NET_FILES: [(&str, Node); 2] = [("dev", Node::NetDev), ("route", Node::NetRoute)];

/// What `/proc` shows of one process.
#[derive(Clone, Copy, Debug)]
pub struct ProcInfo<'s> {
    pub pid: u32,
    pub ppid: u32,
    /// `R` (running or ready), `S` (waiting in a call), `Z` (a zombie).
    pub state: u8,
    pub name: &'s str,
    /// Its arguments, each NUL-terminated.
    pub cmdline: &'s [u8],
    /// Its executable's absolute path.
    pub exe: &'s str,
    /// Bytes of its address space.
    pub size: u64,
    /// The CPU its thread runs on, and the CPUs its affinity allows (bit n: CPU n).
    pub cpu: u32,
    pub affinity: u64,
    /// Its descriptors.
    pub files: &'s [Option<crate::process::File>],
}

impl<'s> ProcInfo<'s> {
    /// What `/proc` shows of process `p` in `state`.
    pub fn of(p: &'s crate::process::Process, state: u8) -> Self {
        ProcInfo {
            pid: p.pid,
            ppid: p.ppid,
            state,
            name: p.name(),
            cmdline: &p.cmdline,
            exe: p.exe.as_str(),
            size: p.areas.iter().map(|a| a.end - a.start).sum(),
            cpu: p.cpu,
            affinity: p.affinity,
            files: &p.files,
        }
    }
}

/// The process table as the system calls may read it: every process but the caller.
pub trait ProcessTable {
    fn find(&self, pid: u32) -> Option<ProcInfo<'_>>;
    /// Calls `f` with each pid.
    fn each_pid(&self, f: &mut dyn FnMut(u32));
}

/// A table without other processes.
impl ProcessTable for () {
    fn find(&self, _: u32) -> Option<ProcInfo<'_>> {
        None
    }
    fn each_pid(&self, _: &mut dyn FnMut(u32)) {}
}

/// The processes a call sees: its caller and the others.
pub struct Procs<'s> {
    /// The caller's process: `me.pid` is its thread group (`/proc/self`).
    pub me: ProcInfo<'s>,
    /// The calling thread's id: `/proc/<tid>` is the caller too (Linux keeps such an
    /// entry for each thread, unlisted), though the caller's own slot is not among
    /// `others`.
    pub tid: u32,
    pub others: &'s dyn ProcessTable,
    /// Nanoseconds since the guest started (`uptime`).
    pub now_ns: u64,
    /// The guest's CPUs (bit n: CPU n; `cpuinfo`, the affinities).
    pub cpus: u64,
    /// Bytes of the guest's memory pool, and of it in use by the file system
    /// (`meminfo`).
    pub memory: u64,
    pub fs_used: u64,
    /// The network interfaces and the default route (`net/dev`, `net/route`).
    pub interfaces: Vec<crate::net::Interface>,
    pub gateway: Option<crate::net::Ipv4Address>,
    /// The file system mounted from the disk (`mounts`).
    pub mount: Option<&'s super::mounted::Mount>,
}

impl<'s> Procs<'s> {
    /// What process `pid` sees with nothing known about itself or the others (paths
    /// only).
    pub fn alone(pid: u32) -> Self {
        Procs {
            me: ProcInfo {
                pid,
                ppid: 0,
                state: b'R',
                name: "",
                cmdline: b"",
                exe: "",
                size: 0,
                cpu: 0,
                affinity: u64::MAX,
                files: &[],
            },
            tid: pid,
            others: &(),
            now_ns: 0,
            cpus: 1,
            memory: 0,
            fs_used: 0,
            interfaces: Vec::new(),
            gateway: None,
            mount: None,
        }
    }

    pub fn find(&self, pid: u32) -> Option<ProcInfo<'_>> {
        if pid == self.me.pid {
            Some(self.me)
        } else if pid == self.tid {
            Some(ProcInfo { pid, ..self.me })
        } else {
            self.others.find(pid)
        }
    }

    /// Every pid, ascending.
    fn pids(&self) -> Vec<u32> {
        let mut pids = Vec::new();
        pids.push(self.me.pid);
        self.others.each_pid(&mut |pid| pids.push(pid));
        pids.sort_unstable();
        pids.dedup();
        pids
    }
}

fn parse_pid(name: &[u8]) -> Option<u32> {
    if name.is_empty() || name.len() > 9 || name[0] == b'0' {
        return None;
    }
    let text = core::str::from_utf8(name).ok()?;
    text.parse().ok()
}

/// What descriptor `fd` of process `pid` has open (`None`: closed, or no such process).
pub fn fd_file(procs: &Procs, pid: u32, fd: u32) -> Option<crate::process::File> {
    procs.find(pid)?.files.get(fd as usize).copied().flatten()
}

/// A descriptor number as `/proc/<pid>/fd` names it.
fn parse_fd(name: &[u8]) -> Option<u32> {
    match name {
        b"0" => Some(0),
        _ => parse_pid(name),
    }
}

/// The entry `name` in directory `dir` (`None`: no such entry; not a directory: the
/// caller checked).
pub fn child(dir: Node, name: &[u8], procs: &Procs) -> Option<Node> {
    match dir {
        Node::Root => SYSTEM_FILES
            .iter()
            .find(|(n, _)| n.as_bytes() == name)
            .map(|&(_, node)| node)
            .or_else(|| {
                let pid = parse_pid(name)?;
                procs.find(pid).map(|_| Node::Process(pid))
            }),
        Node::Net => NET_FILES
            .iter()
            .find(|(n, _)| n.as_bytes() == name)
            .map(|&(_, node)| node),
        Node::Process(pid) if name == b"fd" => Some(Node::Fds(pid)),
        Node::Process(pid) => PROCESS_FILES
            .iter()
            .find(|(n, _)| n.as_bytes() == name)
            .map(|&(_, file)| Node::File(pid, file)),
        Node::Fds(pid) => {
            let fd = parse_fd(name)?;
            fd_file(procs, pid, fd).map(|_| Node::Fd(pid, fd))
        }
        _ => None,
    }
}

/// The directory above `node` (`None`: `/proc` itself, whose parent is the file system's).
pub fn parent(node: Node) -> Option<Node> {
    match node {
        Node::Root => None,
        Node::File(pid, _) | Node::Fds(pid) => Some(Node::Process(pid)),
        Node::Fd(pid, _) => Some(Node::Fds(pid)),
        Node::NetDev | Node::NetRoute => Some(Node::Net),
        _ => Some(Node::Root),
    }
}

pub fn is_dir(node: Node) -> bool {
    matches!(
        node,
        Node::Root | Node::Process(_) | Node::Fds(_) | Node::Net
    )
}

pub fn is_link(node: Node) -> bool {
    matches!(
        node,
        Node::SelfLink | Node::File(_, File::Exe) | Node::Fd(..)
    )
}

/// A link's target, written into `buf` (`None`: not a link, or its process is gone).
pub fn link<'b>(node: Node, procs: &Procs, buf: &'b mut [u8; 280]) -> Option<&'b [u8]> {
    let mut w = SliceWriter { buf, len: 0 };
    match node {
        Node::SelfLink => write!(w, "{}", procs.me.pid).ok()?,
        Node::File(pid, File::Exe) => write!(w, "/{}", procs.find(pid)?.exe).ok()?,
        // A file's path is the file system's ([`super::Fs::link_target`]).
        Node::Fd(pid, fd) => match fd_file(procs, pid, fd)? {
            crate::process::File::Console(_) => write!(w, "/dev/console").ok()?,
            crate::process::File::Pipe { pipe, .. } => {
                write!(w, "pipe:[{}]", PIPE_INO + pipe as u64).ok()?
            }
            crate::process::File::Socket(id) => {
                write!(w, "socket:[{}]", SOCKET_INO + id as u64).ok()?
            }
            crate::process::File::UnixSocket { pair, end, .. } => {
                write!(w, "socket:[{}]", unix_socket_ino(pair, end)).ok()?
            }
            crate::process::File::Event(_) => write!(w, "anon_inode:[eventfd]").ok()?,
            crate::process::File::Timer(_) => write!(w, "anon_inode:[timerfd]").ok()?,
            crate::process::File::Epoll(_) => write!(w, "anon_inode:[eventpoll]").ok()?,
            crate::process::File::Open(_) => return None,
        },
        _ => return None,
    }
    let len = w.len;
    Some(&buf[..len])
}

/// The inode number `pipe:[<n>]` gives pipe 0 (a range of its own).
const PIPE_INO: u64 = 0x3000_0000;
/// The inode number of socket 0 (`socket:[<n>]`, `fstat`).
pub const SOCKET_INO: u64 = 0x3800_0000;
/// The inode number of end 0 of socket pair 0 (end 1 is the next).
const UNIX_SOCKET_INO: u64 = SOCKET_INO + 0x1_0000;

/// The inode number of end `end` of socket pair `pair` (`socket:[<n>]`, `fstat`).
pub fn unix_socket_ino(pair: usize, end: usize) -> u64 {
    UNIX_SOCKET_INO + 2 * pair as u64 + (end & 1) as u64
}
/// The inode number of Linux's one anonymous inode (`eventfd`, `timerfd`, epoll).
pub const ANON_INO: u64 = 0x3c00_0000;

/// Its inode number (in a range of its own, apart from the file system's).
fn ino(node: Node) -> u64 {
    const BASE: u64 = 0x4000_0000;
    const FD_BASE: u64 = 0x8000_0000;
    match node {
        Node::Root => BASE,
        Node::SelfLink => BASE + 1,
        Node::Meminfo => BASE + 2,
        Node::Uptime => BASE + 3,
        Node::Mounts => BASE + 4,
        Node::Net => BASE + 5,
        Node::NetDev => BASE + 6,
        Node::NetRoute => BASE + 7,
        Node::Filesystems => BASE + 8,
        Node::Cpuinfo => BASE + 9,
        Node::Process(pid) => BASE + 16 * (pid as u64 + 1),
        Node::File(pid, f) => BASE + 16 * (pid as u64 + 1) + 1 + f as u64,
        Node::Fds(pid) => BASE + 16 * (pid as u64 + 1) + 8,
        Node::Fd(pid, fd) => {
            FD_BASE + (pid as u64) * (crate::process::MAX_FILES as u64) + fd as u64
        }
    }
}

pub fn stat(node: Node) -> Stat {
    let mode = if is_dir(node) {
        S_IFDIR | 0o555
    } else if is_link(node) {
        S_IFLNK | 0o777
    } else {
        S_IFREG | 0o444
    };
    Stat {
        ino: ino(node),
        nlink: if is_dir(node) { 2 } else { 1 },
        mode,
        ..Stat::default()
    }
}

/// The entries of directory `dir`: name, inode number and whether each is a directory
/// (`.` and `..` are the caller's).
pub fn entries(dir: Node, procs: &Procs) -> Vec<(Vec<u8>, Node)> {
    let mut out = Vec::new();
    match dir {
        Node::Root => {
            for (name, node) in SYSTEM_FILES {
                out.push((name.as_bytes().to_vec(), node));
            }
            for pid in procs.pids() {
                let mut name = Vec::new();
                let _ = write!(VecWriter(&mut name), "{pid}");
                out.push((name, Node::Process(pid)));
            }
        }
        Node::Net => {
            for (name, node) in NET_FILES {
                out.push((name.as_bytes().to_vec(), node));
            }
        }
        Node::Process(pid) => {
            for (name, file) in PROCESS_FILES {
                out.push((name.as_bytes().to_vec(), Node::File(pid, file)));
            }
            out.push((b"fd".to_vec(), Node::Fds(pid)));
        }
        Node::Fds(pid) => {
            let files = procs.find(pid).map_or(&[][..], |p| p.files);
            for (fd, _) in files.iter().enumerate().filter(|(_, f)| f.is_some()) {
                let mut name = Vec::new();
                let _ = write!(VecWriter(&mut name), "{fd}");
                out.push((name, Node::Fd(pid, fd as u32)));
            }
        }
        _ => {}
    }
    out
}

pub fn inode_number(node: Node) -> u64 {
    ino(node)
}

/// The contents of file `node` now (`None`: a directory or link, or its process is gone).
pub fn contents(node: Node, procs: &Procs) -> Option<Vec<u8>> {
    let mut text = Vec::new();
    let mut w = VecWriter(&mut text);
    match node {
        Node::Meminfo => {
            let total = procs.memory / 1024;
            let mut used = procs.fs_used;
            for pid in procs.pids() {
                used += procs.find(pid).map_or(0, |p| p.size);
            }
            let free = total.saturating_sub(used / 1024);
            let _ = write!(
                w,
                "MemTotal:       {total:8} kB\nMemFree:        {free:8} kB\nMemAvailable:   {free:8} kB\nBuffers:               0 kB\nCached:                0 kB\nSwapTotal:             0 kB\nSwapFree:              0 kB\n"
            );
        }
        Node::Uptime => {
            let centis = procs.now_ns / 10_000_000;
            let _ = writeln!(
                w,
                "{}.{:02} {}.{:02}",
                centis / 100,
                centis % 100,
                centis / 100,
                centis % 100
            );
        }
        Node::Mounts => {
            let _ = write!(w, "rootfs / rootfs rw 0 0\nproc /proc proc rw 0 0\n");
            if let Some(m) = procs.mount {
                let _ = m.describe(&mut w);
            }
        }
        Node::Filesystems => {
            let _ = write!(w, "nodev\trootfs\nnodev\tproc\n\text2\n");
        }
        Node::NetDev => crate::net::proc_net_dev(&procs.interfaces, &mut w),
        Node::NetRoute => crate::net::proc_net_route(&procs.interfaces, procs.gateway, &mut w),
        Node::File(pid, File::Stat) => {
            let p = procs.find(pid)?;
            // pid (comm) state ppid pgrp session tty_nr tpgid flags minflt cminflt majflt
            // cmajflt utime stime cutime cstime priority nice num_threads itrealvalue
            // starttime vsize rss, then 28 more fields (25..=52) of which only 39, the
            // processor (`ps -o psr`, `top`'s last CPU), says something here.
            let _ = write!(
                w,
                "{} ({}) {} {} {} {} 0 -1 4194560 0 0 0 0 0 0 0 0 20 0 1 0 0 {} {}",
                p.pid,
                p.name,
                p.state as char,
                p.ppid,
                p.pid,
                p.pid,
                p.size,
                p.size / 4096
            );
            for field in 25..=52 {
                let _ = match field {
                    39 => write!(w, " {}", p.cpu),
                    _ => w.write_str(" 0"),
                };
            }
            let _ = w.write_str("\n");
        }
        Node::File(pid, File::Status) => {
            let p = procs.find(pid)?;
            let state = match p.state {
                b'R' => "R (running)",
                b'S' => "S (sleeping)",
                _ => "Z (zombie)",
            };
            let _ = write!(
                w,
                "Name:\t{}\nState:\t{state}\nTgid:\t{}\nPid:\t{}\nPPid:\t{}\nUid:\t0\t0\t0\t0\nGid:\t0\t0\t0\t0\nVmSize:\t{} kB\nThreads:\t1\n",
                p.name,
                p.pid,
                p.pid,
                p.ppid,
                p.size / 1024
            );
            // The mask as Linux prints it: hex digits for the CPUs up to the guest's
            // highest (`nr_cpu_ids`), and as a list.
            let allowed = p.affinity & procs.cpus;
            let digits = (64 - procs.cpus.leading_zeros()).div_ceil(4).max(1) as usize;
            let _ = write!(
                w,
                "Cpus_allowed:\t{allowed:0digits$x}\nCpus_allowed_list:\t"
            );
            let _ = write_cpu_list(&mut w, allowed);
            let _ = w.write_str("\nMems_allowed:\t1\nMems_allowed_list:\t0\n");
        }
        Node::Cpuinfo => super::cpuinfo::write(&mut w, procs.cpus, &super::cpuinfo::CpuId::read()),
        Node::File(pid, File::Cmdline) => {
            let p = procs.find(pid)?;
            text.extend_from_slice(p.cmdline);
        }
        _ => return None,
    }
    Some(text)
}

/// CPU mask `mask` as Linux's lists say it: ascending ranges, `1-2` or `0,3-5`.
pub fn write_cpu_list(w: &mut impl Write, mask: u64) -> core::fmt::Result {
    let mut cpu = 0;
    let mut first = true;
    while cpu < 64 {
        if mask >> cpu & 1 == 0 {
            cpu += 1;
            continue;
        }
        let start = cpu;
        while cpu < 64 && mask >> cpu & 1 != 0 {
            cpu += 1;
        }
        if !first {
            w.write_str(",")?;
        }
        first = false;
        match cpu - 1 - start {
            0 => write!(w, "{start}")?,
            _ => write!(w, "{start}-{}", cpu - 1)?,
        }
    }
    Ok(())
}

struct VecWriter<'v>(&'v mut Vec<u8>);

impl Write for VecWriter<'_> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.0.extend_from_slice(s.as_bytes());
        Ok(())
    }
}
