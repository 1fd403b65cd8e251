use super::*;
use crate::cpio::tests::archive;

fn bytes() -> Vec<u8> {
    archive(&[
        (".", S_IFDIR | 0o755, b""),
        ("bin", S_IFDIR | 0o755, b""),
        ("bin/busybox", S_IFREG | 0o755, b"ELF"),
        ("bin/sh", S_IFLNK | 0o777, b"busybox"),
        ("bin/abs", S_IFLNK | 0o777, b"/bin/sh"),
        ("bin/loop", S_IFLNK | 0o777, b"loop"),
        ("sbin", S_IFLNK | 0o777, b"bin"),
        ("etc", S_IFDIR | 0o755, b""),
        ("etc/passwd", S_IFREG | 0o644, b"root"),
    ])
}

const ROOT_NODE: Node = Node::Inode(ROOT);

fn path(fs: &Fs, node: Node) -> String {
    format!("/{}", fs.path_of(node).unwrap().as_str())
}

#[test]
fn resolves_paths_and_links() {
    let bytes = bytes();
    let fs = Fs::new(&Archive::new(&bytes).unwrap(), 1 << 16).unwrap();
    let procs = Procs::alone(1);
    let name = |p: &[u8], follow| {
        fs.lookup(&procs, ROOT_NODE, p, follow)
            .map(|n| path(&fs, n))
    };
    assert_eq!(name(b"/bin/sh", true), Ok("/bin/busybox".into()));
    assert_eq!(name(b"/bin/sh", false), Ok("/bin/sh".into()));
    assert_eq!(name(b"/bin/abs", true), Ok("/bin/busybox".into()));
    assert_eq!(name(b"/sbin/sh", true), Ok("/bin/busybox".into()));
    assert_eq!(name(b"bin/../etc/./passwd", true), Ok("/etc/passwd".into()));
    assert_eq!(name(b"/../../etc/passwd", true), Ok("/etc/passwd".into()));
    assert_eq!(name(b"/", true), Ok("/".into()));
    assert_eq!(name(b"/bin/", true), Ok("/bin".into()));
    assert_eq!(name(b"/etc/passwd/", true), Err(Errno::ENOTDIR));
    assert_eq!(name(b"/etc/passwd/x", true), Err(Errno::ENOTDIR));
    assert_eq!(name(b"/nope", true), Err(Errno::ENOENT));
    assert_eq!(name(b"", true), Err(Errno::ENOENT));
    assert_eq!(name(b"/bin/loop", true), Err(Errno::ELOOP));
    assert_eq!(name(&[b'a'; 5000], true), Err(Errno::ENAMETOOLONG));
    assert_eq!(name(b"/dev/null", true), Ok("/dev/null".into()));
    assert_eq!(name(b"/proc/self", true), Ok("/proc/1".into()));
    assert_eq!(name(b"/proc/2", true), Err(Errno::ENOENT));
}

fn names(fs: &Fs, dir: Node) -> Vec<String> {
    let Node::Inode(dir) = dir else {
        panic!("{dir:?} is not in memory")
    };
    let mut out = Vec::new();
    let mut after: Option<Vec<u8>> = None;
    while let Some((name, _)) = fs.next_entry(dir, after.as_deref()) {
        out.push(String::from_utf8(name.to_vec()).unwrap());
        after = Some(name.to_vec());
    }
    out
}

fn lookup(fs: &Fs, path: &str) -> Result<Node, Errno> {
    fs.lookup(&Procs::alone(1), ROOT_NODE, path.as_bytes(), false)
}

fn dir(fs: &Fs, path: &str) -> Node {
    let node = lookup(fs, path).unwrap();
    assert!(fs.is_dir(node), "{path}: {node:?}");
    node
}

#[test]
fn files_are_created_written_renamed_and_removed() {
    let bytes = bytes();
    let mut fs = Fs::new(&Archive::new(&bytes).unwrap(), 1 << 16).unwrap();
    assert_eq!(
        names(&fs, ROOT_NODE),
        ["bin", "dev", "etc", "proc", "sbin", "tmp"]
    );
    assert_eq!(
        names(&fs, dir(&fs, "/dev")),
        ["console", "fd", "null", "random", "tty", "urandom", "zero"]
    );
    let tmp = dir(&fs, "/tmp");
    let f = fs.create(tmp, b"f", 0o644, 7).unwrap();
    assert_eq!(fs.create(tmp, b"f", 0o644, 7), Err(Errno::EEXIST));
    assert_eq!(fs.write(f, 0, b"hello", 8), Ok(5));
    assert_eq!(fs.write(f, 8, b"!", 8), Ok(1));
    assert_eq!(fs.file_bytes(f).unwrap(), b"hello\0\0\0!");
    let st = fs.stat(f);
    assert_eq!(
        (st.size, st.mode, st.nlink, st.mtime),
        (9, S_IFREG | 0o644, 1, 8)
    );
    fs.truncate(f, 2, 9).unwrap();
    assert_eq!(fs.file_bytes(f).unwrap(), b"he");
    fs.truncate(f, 4, 9).unwrap();
    assert_eq!(fs.file_bytes(f).unwrap(), b"he\0\0");
    // Directories: made, renamed (not into themselves), removed when empty.
    let d = fs.mkdir(tmp, b"d", 0o755, 0).unwrap();
    assert_eq!(fs.stat(tmp).nlink, 3, "tmp, its entry and d's ..");
    fs.rename(tmp, b"f", d, b"g", false, 10).unwrap();
    assert_eq!(lookup(&fs, "/tmp/d/g"), Ok(f));
    assert_eq!(lookup(&fs, "/tmp/f"), Err(Errno::ENOENT));
    assert_eq!(fs.rename(tmp, b"d", d, b"x", false, 0), Err(Errno::EINVAL));
    assert_eq!(fs.remove(tmp, b"d", Remove::Dir, 0), Err(Errno::ENOTEMPTY));
    assert_eq!(fs.remove(tmp, b"d", Remove::File, 0), Err(Errno::EISDIR));
    assert_eq!(fs.remove(d, b"g", Remove::Dir, 0), Err(Errno::ENOTDIR));
    // Replacing: a file by a file, an empty directory by a directory.
    let h = fs.create(d, b"h", 0o600, 0).unwrap();
    assert_eq!(fs.rename(d, b"g", d, b"h", true, 0), Err(Errno::EEXIST));
    fs.rename(d, b"g", d, b"h", false, 0).unwrap();
    assert_eq!(lookup(&fs, "/tmp/d/h"), Ok(f));
    assert_ne!(lookup(&fs, "/tmp/d/h"), Ok(h));
    fs.mkdir(tmp, b"e", 0o755, 0).unwrap();
    assert_eq!(fs.rename(d, b"h", tmp, b"e", false, 0), Err(Errno::EISDIR));
    fs.rename(tmp, b"e", tmp, b"d2", false, 0).unwrap();
    assert_eq!(fs.rename(tmp, b"d", tmp, b"d2", false, 0), Ok(()));
    assert_eq!(names(&fs, tmp), ["d2"]);
    let d2 = dir(&fs, "/tmp/d2");
    assert_eq!(fs.parent(d2), tmp);
    assert_eq!(path(&fs, f), "/tmp/d2/h");
    // Links: symbolic and hard.
    fs.symlink(tmp, b"s", b"d2/h", 0).unwrap();
    assert_eq!(
        fs.lookup(&Procs::alone(1), ROOT_NODE, b"/tmp/s", true),
        Ok(f)
    );
    fs.link(f, tmp, b"hard", 0).unwrap();
    assert_eq!(fs.stat(f).nlink, 2);
    assert_eq!(fs.link(d2, tmp, b"x", 0), Err(Errno::EPERM));
    fs.remove(d2, b"h", Remove::File, 0).unwrap();
    assert_eq!(fs.file_bytes(f).unwrap(), b"he\0\0", "still linked");
    assert_eq!(
        fs.lookup(&Procs::alone(1), ROOT_NODE, b"/tmp/s", true),
        Err(Errno::ENOENT)
    );
    fs.remove(tmp, b"d2", Remove::Dir, 0).unwrap();
    assert_eq!(names(&fs, tmp), ["hard", "s"]);
    // /proc cannot go.
    assert_eq!(
        fs.remove(ROOT_NODE, b"proc", Remove::Dir, 0),
        Err(Errno::EBUSY)
    );
}

#[test]
fn unlinked_files_live_while_open_and_the_limit_holds() {
    let bytes = bytes();
    let mut fs = Fs::new(&Archive::new(&bytes).unwrap(), 1 << 16).unwrap();
    let base = fs.usage().0;
    let tmp = dir(&fs, "/tmp");
    let f = fs.create(tmp, b"f", 0o644, 0).unwrap();
    fs.write(f, 0, b"data", 0).unwrap();
    let id = fs.open(f, 0, None).unwrap();
    fs.share(id);
    fs.remove(tmp, b"f", Remove::File, 0).unwrap();
    assert_eq!(fs.file_bytes(f).unwrap(), b"data", "open: still there");
    fs.release(id);
    assert_eq!(fs.file_bytes(f).unwrap(), b"data", "one reference left");
    fs.release(id);
    assert_eq!(fs.file_bytes(f), None, "gone with the last reference");
    assert_eq!(fs.open_count(), 0);
    assert_eq!(fs.usage().0, base, "everything given back");
    // The byte limit: ENOSPC, never more than the limit, and the space comes back.
    let g = fs.create(tmp, b"g", 0o644, 0).unwrap();
    let big = vec![7u8; 1 << 16];
    assert_eq!(fs.write(g, 0, &big, 0), Err(Errno::ENOSPC));
    let mut written = 0;
    while fs.write(g, written, &big[..1000], 0).is_ok() {
        written += 1000;
    }
    assert!(written > 30_000, "{written}");
    while fs.write(g, written, b"x", 0).is_ok() {
        written += 1;
    }
    let (used, limit) = fs.usage();
    assert_eq!(used, limit);
    assert_eq!(fs.create(tmp, b"h", 0o644, 0), Err(Errno::ENOSPC));
    fs.truncate(g, 0, 0).unwrap();
    fs.create(tmp, b"h", 0o644, 0).unwrap();
    assert_eq!(fs.write(g, 1 << 40, b"x", 0), Err(Errno::EFBIG));
    // The initramfs's data is borrowed until written: busybox costs nothing.
    let busybox = lookup(&fs, "/bin/busybox").unwrap();
    let before = fs.usage().0;
    assert_eq!(fs.file_bytes(busybox).unwrap(), b"ELF");
    fs.write(busybox, 3, b"!", 0).unwrap();
    assert!(fs.usage().0 > before);
    assert_eq!(fs.file_bytes(busybox).unwrap(), b"ELF!");
    assert_eq!(
        &bytes.windows(3).filter(|w| w == b"ELF").count(),
        &1,
        "archive unchanged"
    );
}

#[test]
fn proc_shows_the_processes() {
    struct Table;
    impl proc::ProcessTable for Table {
        fn find(&self, pid: u32) -> Option<proc::ProcInfo<'_>> {
            (pid == 7).then_some(proc::ProcInfo {
                pid: 7,
                ppid: 1,
                state: b'Z',
                name: "sleep",
                cmdline: b"sleep\x0010\x00",
                exe: "bin/busybox",
                size: 8192,
                cpu: 2,
                affinity: 0b1100,
                files: &[],
            })
        }
        fn each_pid(&self, f: &mut dyn FnMut(u32)) {
            f(7);
        }
    }
    let bytes = bytes();
    let fs = Fs::new(&Archive::new(&bytes).unwrap(), 1 << 16).unwrap();
    let mut procs = Procs::alone(1);
    procs.others = &Table;
    procs.now_ns = 12_340_000_000;
    procs.cpus = 0b110;
    let at = |p: &str, follow| fs.lookup(&procs, ROOT_NODE, p.as_bytes(), follow);
    let read = |p: &str| {
        let Node::Proc(n) = at(p, true).unwrap() else {
            panic!("{p}")
        };
        String::from_utf8(proc::contents(n, &procs).unwrap()).unwrap()
    };
    let listing: Vec<String> = proc::entries(proc::Node::Root, &procs)
        .into_iter()
        .map(|(n, _)| String::from_utf8(n).unwrap())
        .collect();
    assert_eq!(
        listing,
        [
            "self",
            "meminfo",
            "uptime",
            "mounts",
            "filesystems",
            "net",
            "cpuinfo",
            "1",
            "7"
        ]
    );
    assert_eq!(read("/proc/7/cmdline"), "sleep\x0010\x00");
    let status = read("/proc/7/status");
    assert!(
        status.starts_with("Name:\tsleep\nState:\tZ (zombie)\nTgid:\t7\nPid:\t7\nPPid:\t1\n"),
        "{status}"
    );
    // The allowed CPUs: its affinity (CPUs 2 and 3) and the guest's (1 and 2).
    assert!(
        status.ends_with(
            "Cpus_allowed:\t4\nCpus_allowed_list:\t2\nMems_allowed:\t1\nMems_allowed_list:\t0\n"
        ),
        "{status}"
    );
    let stat = read("/proc/7/stat");
    assert!(stat.starts_with("7 (sleep) Z 1 7 7 0 -1 "), "{stat}");
    assert_eq!(stat.split(' ').count(), 52, "{stat}");
    assert_eq!(
        stat.trim_end().split(' ').nth(38),
        Some("2"),
        "field 39: its CPU"
    );
    // A block per CPU of the guest, in Linux's format.
    let cpuinfo = read("/proc/cpuinfo");
    let processors: Vec<&str> = cpuinfo
        .lines()
        .filter(|l| l.starts_with("processor"))
        .collect();
    assert_eq!(
        processors,
        ["processor\t: 1", "processor\t: 2"],
        "{cpuinfo}"
    );
    let blocks: Vec<&str> = cpuinfo.split_terminator("\n\n").collect();
    assert_eq!(blocks.len(), 2, "{cpuinfo}");
    for (block, cpu) in blocks.iter().zip([1, 2]) {
        let field = |name: &str| {
            block
                .lines()
                .find_map(|l| l.split_once(':').filter(|(k, _)| k.trim_end() == name))
                .map(|(_, v)| v.trim().to_string())
        };
        assert_eq!(field("core id"), Some(cpu.to_string()), "{block}");
        assert_eq!(field("siblings"), Some("2".into()));
        for name in ["vendor_id", "model name", "cpu family", "model", "flags"] {
            assert!(field(name).is_some(), "{name} in {block}");
        }
        assert!(block.ends_with("power management:"), "{block}");
    }
    let mut list = String::new();
    for (mask, text) in [
        (0b110, "1-2"),
        (0b1010, "1,3"),
        (0b10_1111, "0-3,5"),
        (0, ""),
    ] {
        list.clear();
        proc::write_cpu_list(&mut list, mask).unwrap();
        assert_eq!(list, text);
    }
    assert_eq!(read("/proc/uptime"), "12.34 12.34\n");
    assert!(read("/proc/mounts").starts_with("rootfs / rootfs rw 0 0\n"));
    assert!(read("/proc/meminfo").starts_with("MemTotal:"));
    assert_eq!(
        at("/proc/self", false),
        Ok(Node::Proc(proc::Node::SelfLink))
    );
    assert_eq!(
        at("/proc/self", true),
        Ok(Node::Proc(proc::Node::Process(1)))
    );
    assert_eq!(at("/proc/self/..", true), Ok(Node::Proc(proc::Node::Root)));
    assert_eq!(at("/proc/..", true), Ok(ROOT_NODE));
    assert_eq!(
        at("/proc/7/exe", true).map(|n| path(&fs, n)),
        Ok("/bin/busybox".into())
    );
    assert_eq!(at("/proc/8", true), Err(Errno::ENOENT));
    assert_eq!(at("/proc/01", true), Err(Errno::ENOENT));
    assert_eq!(path(&fs, at("/proc/7", true).unwrap()), "/proc/7");
    assert_eq!(
        fs.lookup_parent(&procs, ROOT_NODE, b"/proc/new"),
        Err(Errno::EACCES)
    );
    assert!(fs.stat(at("/proc/7", true).unwrap()).is_dir());
}
