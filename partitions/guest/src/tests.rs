//! The personality end to end on the host: a program loaded from an initramfs into a model
//! of process memory, then the system calls a static C library and busybox make, as
//! exception messages.

use crate::cpio::{Archive, S_IFDIR, S_IFLNK, S_IFREG};
use crate::elf::tests::static_exe;
use crate::exec::{self, ExecError};
use crate::linux::{Errno, nr};
use crate::memory::{PAGE, Rights, STACK_TOP};
use crate::process::{Process, Stream};
use crate::syscall::{Host, Outcome, handle};
use abi::ipc::{ExceptionMessage, VECTOR_SYSCALL};
use std::collections::HashMap;

/// Process memory as the kernel would have it: backed pages with their rights.
#[derive(Default)]
struct Model {
    pages: HashMap<u64, (Vec<u8>, Rights)>,
    /// Pages the guest may still back.
    budget: u64,
    console: Vec<(u32, Stream, Vec<u8>)>,
    log: Vec<String>,
    now: u64,
}

impl Model {
    fn new(budget: u64) -> Self {
        Self {
            budget,
            ..Self::default()
        }
    }
    fn stdout(&self) -> String {
        let bytes: Vec<u8> = self
            .console
            .iter()
            .filter(|c| c.1 == Stream::Stdout)
            .flat_map(|c| c.2.clone())
            .collect();
        String::from_utf8(bytes).unwrap()
    }
    fn byte(&self, address: u64) -> Option<u8> {
        let (page, _) = self.pages.get(&(address & !(PAGE - 1)))?;
        Some(page[(address % PAGE) as usize])
    }
}

impl Host for Model {
    fn read_user(&mut self, address: u64, buf: &mut [u8]) -> Result<(), Errno> {
        for (i, b) in buf.iter_mut().enumerate() {
            *b = self.byte(address + i as u64).ok_or(Errno::EFAULT)?;
        }
        Ok(())
    }
    fn write_user(&mut self, address: u64, data: &[u8]) -> Result<(), Errno> {
        for (i, b) in data.iter().enumerate() {
            let a = address + i as u64;
            let (page, _) = self
                .pages
                .get_mut(&(a & !(PAGE - 1)))
                .ok_or(Errno::EFAULT)?;
            page[(a % PAGE) as usize] = *b;
        }
        Ok(())
    }
    fn map_zeroed(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno> {
        if pages > self.budget {
            return Err(Errno::ENOMEM);
        }
        for i in 0..pages {
            let at = start + i * PAGE;
            assert!(!self.pages.contains_key(&at), "page {at:#x} mapped twice");
            self.pages.insert(at, (vec![0; PAGE as usize], rights));
        }
        self.budget -= pages;
        Ok(())
    }
    fn unmap(&mut self, start: u64, pages: u64) {
        for i in 0..pages {
            if self.pages.remove(&(start + i * PAGE)).is_some() {
                self.budget += 1;
            }
        }
    }
    fn protect(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno> {
        for i in 0..pages {
            let at = start + i * PAGE;
            match self.pages.get_mut(&at) {
                Some(p) => p.1 = rights,
                None => self.map_zeroed(at, 1, rights)?,
            }
        }
        Ok(())
    }
    fn console_write(&mut self, pid: u32, stream: Stream, bytes: &[u8]) {
        self.console.push((pid, stream, bytes.to_vec()));
    }
    fn now_ns(&mut self) -> u64 {
        self.now += 1_500_000_000;
        self.now
    }
    fn random(&mut self, buf: &mut [u8]) {
        buf.fill(0x5a);
    }
    fn log(&mut self, line: core::fmt::Arguments) {
        self.log.push(line.to_string());
    }
}

fn initramfs() -> Vec<u8> {
    let exe = static_exe();
    crate::cpio::tests::archive(&[
        (".", S_IFDIR | 0o755, b""),
        ("bin", S_IFDIR | 0o755, b""),
        ("bin/busybox", S_IFREG | 0o755, &exe),
        ("bin/sh", S_IFLNK | 0o777, b"busybox"),
        ("bin/data", S_IFREG | 0o644, &exe),
        ("etc", S_IFDIR | 0o755, b""),
        (
            "etc/passwd",
            S_IFREG | 0o644,
            b"root:x:0:0:root:/root:/bin/sh\n",
        ),
    ])
}

/// A loaded process, its memory and its file system, with a scratch page at
/// [`SCRATCH`] for call arguments.
struct World<'a> {
    fs: Archive<'a>,
    p: Process<'a>,
    pipes: crate::pipe::Pipes,
    host: Model,
    fs_base: u64,
}

const SCRATCH: u64 = 0x7000_0000;

impl<'a> World<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        let fs = Archive::new(bytes).unwrap();
        let mut host = Model::new(1000);
        let loaded = exec::load(
            &fs,
            &mut host,
            1,
            0,
            &[b"/bin/sh", b"-c", b"echo hello"],
            &[b"PATH=/bin"],
            0x1234,
        )
        .unwrap();
        let mut w = World {
            fs,
            p: loaded.process,
            pipes: crate::pipe::Pipes::new(),
            host,
            fs_base: 0,
        };
        let scratch = w.call(nr::mmap, [SCRATCH, PAGE, 3, 0x32, u64::MAX, 0]);
        assert_eq!(scratch, SCRATCH);
        w
    }

    fn message(number: u64, a: [u64; 6], fs_base: u64) -> ExceptionMessage {
        let mut m = ExceptionMessage {
            vector: VECTOR_SYSCALL,
            ..Default::default()
        };
        let r = &mut m.registers;
        (r.rax, r.rdi, r.rsi, r.rdx, r.r10, r.r8, r.r9) =
            (number, a[0], a[1], a[2], a[3], a[4], a[5]);
        r.rip = 0x40_1019;
        r.fs_base = fs_base;
        m
    }

    fn run(&mut self, number: u64, a: [u64; 6]) -> (Outcome, ExceptionMessage) {
        let mut m = Self::message(number, a, self.fs_base);
        let outcome = handle(
            &mut self.p,
            &mut self.pipes,
            &self.fs,
            &mut self.host,
            &mut m,
        );
        self.fs_base = m.registers.fs_base;
        (outcome, m)
    }

    /// A call that resumes; its `rax`.
    fn call(&mut self, number: u64, a: [u64; 6]) -> u64 {
        let (outcome, m) = self.run(number, a);
        assert_eq!(outcome, Outcome::Resume, "call {number}");
        assert_eq!(
            m.registers.rcx, m.registers.rip,
            "rcx = rip as after syscall"
        );
        m.registers.rax
    }

    fn put(&mut self, at: u64, bytes: &[u8]) {
        self.host.write_user(at, bytes).unwrap();
    }

    fn get(&mut self, at: u64, len: usize) -> Vec<u8> {
        let mut b = vec![0; len];
        self.host.read_user(at, &mut b).unwrap();
        b
    }

    fn word(&mut self, at: u64) -> u64 {
        u64::from_le_bytes(self.get(at, 8).try_into().unwrap())
    }

    fn path(&mut self, text: &str) -> u64 {
        let mut b = text.as_bytes().to_vec();
        b.push(0);
        self.put(SCRATCH + 0x800, &b);
        SCRATCH + 0x800
    }
}

fn err(e: Errno) -> u64 {
    e.result()
}

#[test]
fn loads_the_program_its_stack_and_its_areas() {
    let bytes = initramfs();
    let fs = Archive::new(&bytes).unwrap();
    let mut host = Model::new(1000);
    let l = exec::load(
        &fs,
        &mut host,
        7,
        1,
        &[b"/bin/sh", b"-c", b"x"],
        &[b"A=b"],
        0x1234,
    )
    .unwrap();
    assert_eq!(l.entry, 0x40_1010);
    assert_eq!((l.process.pid, l.process.name()), (7, "busybox"));
    assert_eq!(l.process.exe.as_str(), "bin/busybox");
    // The code is where the entry point is, read-only and executable.
    assert_eq!(host.byte(0x40_1010), Some(0xb8));
    assert_eq!(host.pages[&0x40_1000].1, Rights::READ | Rights::EXECUTE);
    assert_eq!(&host.pages[&0x40_2000].0[0xf00..0xf08], b"DATADATA");
    assert_eq!(l.sp % 16, 0);
    assert!(l.sp < STACK_TOP && l.sp > STACK_TOP - 4096);
    let mut argc = [0u8; 8];
    host.read_user(l.sp, &mut argc).unwrap();
    assert_eq!(u64::from_le_bytes(argc), 3);
    assert_eq!(l.process.brk_start, 0x40_5000);
}

#[test]
fn what_cannot_start_says_why() {
    let bytes = initramfs();
    let fs = Archive::new(&bytes).unwrap();
    let mut host = Model::new(1000);
    let load = |argv: &[&[u8]], host: &mut Model| {
        exec::load(&fs, host, 1, 0, argv, &[], 0).map(|l| l.entry)
    };
    assert_eq!(
        load(&[b"/bin/nothing"], &mut host),
        Err(ExecError::Lookup(Errno::ENOENT))
    );
    assert_eq!(load(&[b"/etc"], &mut host), Err(ExecError::NotAFile));
    assert_eq!(
        load(&[b"/etc/passwd"], &mut host),
        Err(ExecError::NotExecutable)
    );
    assert_eq!(load(&[], &mut host), Err(ExecError::NoArguments));
    assert_eq!(
        ExecError::Lookup(Errno::ENOENT).to_string(),
        "ENOENT (no such file or directory) (errno 2)"
    );
    let mut tiny = Model::new(3);
    assert_eq!(
        load(&[b"/bin/busybox"], &mut tiny),
        Err(ExecError::Memory(Errno::ENOMEM))
    );
}

#[test]
fn a_c_library_start_and_hello() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    // brk(0), then grow by 0x21000 (as glibc's TLS setup does), then shrink.
    let start = w.call(nr::brk, [0; 6]);
    assert_eq!(start, 0x40_5000);
    assert_eq!(
        w.call(nr::brk, [start + 0x21000, 0, 0, 0, 0, 0]),
        start + 0x21000
    );
    w.put(start + 0x20ff8, b"heap!");
    assert_eq!(
        w.call(nr::brk, [start + 0x1000, 0, 0, 0, 0, 0]),
        start + 0x1000
    );
    assert!(
        w.host.byte(start + 0x20ff8).is_none(),
        "shrunk heap unmapped"
    );
    assert_eq!(
        w.call(nr::brk, [1 << 40, 0, 0, 0, 0, 0]),
        start + 0x1000,
        "too far"
    );
    // arch_prctl(ARCH_SET_FS) sets the FS base the reply carries.
    assert_eq!(w.call(nr::arch_prctl, [0x1002, 0x4f_0000, 0, 0, 0, 0]), 0);
    assert_eq!(w.fs_base, 0x4f_0000);
    assert_eq!(w.call(nr::arch_prctl, [0x1003, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(w.word(SCRATCH), 0x4f_0000);
    assert_eq!(
        w.call(nr::arch_prctl, [0x1002, 1 << 47, 0, 0, 0, 0]),
        err(Errno::EPERM)
    );
    assert_eq!(w.call(nr::set_tid_address, [SCRATCH, 0, 0, 0, 0, 0]), 1);
    assert_eq!(w.call(nr::set_robust_list, [SCRATCH, 24, 0, 0, 0, 0]), 0);
    assert_eq!(
        w.call(nr::set_robust_list, [SCRATCH, 23, 0, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::rseq, [SCRATCH, 32, 0, 0x53053053, 0, 0]),
        err(Errno::ENOSYS)
    );
    assert!(
        w.host.log.is_empty(),
        "rseq is expected, not logged: {:?}",
        w.host.log
    );
    // prlimit64(0, RLIMIT_STACK, NULL, &old)
    assert_eq!(w.call(nr::prlimit64, [0, 3, 0, SCRATCH, 0, 0]), 0);
    assert_eq!(w.word(SCRATCH), 256 * 1024);
    assert_eq!(
        w.call(nr::prlimit64, [0, 3, SCRATCH, 0, 0, 0]),
        err(Errno::EPERM)
    );
    assert_eq!(
        w.call(nr::prlimit64, [99, 3, 0, SCRATCH, 0, 0]),
        err(Errno::ESRCH)
    );
    // readlink("/proc/self/exe")
    let path = w.path("/proc/self/exe");
    assert_eq!(w.call(nr::readlink, [path, SCRATCH, 64, 0, 0, 0]), 12);
    assert_eq!(w.get(SCRATCH, 12), b"/bin/busybox");
    assert_eq!(
        w.call(nr::readlink, [path, SCRATCH, 4, 0, 0, 0]),
        4,
        "truncated"
    );
    // getrandom
    assert_eq!(w.call(nr::getrandom, [SCRATCH, 8, 0, 0, 0, 0]), 8);
    assert_eq!(w.word(SCRATCH), 0x5a5a_5a5a_5a5a_5a5a);
    // The console: not a terminal yet.
    assert_eq!(
        w.call(nr::ioctl, [1, 0x5401, SCRATCH, 0, 0, 0]),
        err(Errno::ENOTTY)
    );
    assert_eq!(
        w.call(nr::ioctl, [9, 0x5401, SCRATCH, 0, 0, 0]),
        err(Errno::EBADF)
    );
    // write and writev
    w.put(SCRATCH, b"hello\nworld\n");
    assert_eq!(w.call(nr::write, [1, SCRATCH, 6, 0, 0, 0]), 6);
    let iov: Vec<u8> = [SCRATCH + 6, 3, SCRATCH + 9, 3]
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    w.put(SCRATCH + 0x100, &iov);
    assert_eq!(w.call(nr::writev, [1, SCRATCH + 0x100, 2, 0, 0, 0]), 6);
    assert_eq!(w.host.stdout(), "hello\nworld\n");
    assert_eq!(w.call(nr::write, [1, 0x10, 6, 0, 0, 0]), err(Errno::EFAULT));
    assert_eq!(
        w.call(nr::write, [5, SCRATCH, 6, 0, 0, 0]),
        err(Errno::EBADF)
    );
    // exit_group(3)
    let (outcome, _) = w.run(nr::exit_group, [3 | 0x100, 0, 0, 0, 0, 0]);
    assert_eq!(outcome, Outcome::Exit(3));
    assert_eq!(w.host.log, ["guest: process 1 exited with status 3"]);
}

#[test]
fn identity_time_and_signals() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(w.call(nr::getpid, [0; 6]), 1);
    assert_eq!(w.call(nr::getppid, [0; 6]), 0);
    assert_eq!(w.call(nr::gettid, [0; 6]), 1);
    for n in [nr::getuid, nr::geteuid, nr::getgid, nr::getegid] {
        assert_eq!(w.call(n, [0; 6]), 0);
    }
    assert_eq!(w.call(nr::uname, [SCRATCH, 0, 0, 0, 0, 0]), 0);
    assert_eq!(&w.get(SCRATCH, 6), b"Linux\0");
    assert_eq!(&w.get(SCRATCH + 4 * 65, 7), b"x86_64\0");
    assert_eq!(w.call(nr::clock_gettime, [1, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!((w.word(SCRATCH), w.word(SCRATCH + 8)), (1, 500_000_000));
    assert_eq!(
        w.call(nr::clock_gettime, [99, SCRATCH, 0, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    // rt_sigaction(SIGINT, &act, &old, 8) records; SIGKILL cannot be changed.
    let act: Vec<u8> = [0x40_1234u64, 0x0400_0000, 0x40_5678, 0]
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    w.put(SCRATCH, &act);
    assert_eq!(w.call(nr::rt_sigaction, [2, SCRATCH, 0, 8, 0, 0]), 0);
    assert_eq!(w.call(nr::rt_sigaction, [2, 0, SCRATCH + 64, 8, 0, 0]), 0);
    assert_eq!(w.word(SCRATCH + 64), 0x40_1234);
    assert_eq!(
        w.call(nr::rt_sigaction, [9, SCRATCH, 0, 8, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::rt_sigaction, [2, SCRATCH, 0, 16, 0, 0]),
        err(Errno::EINVAL)
    );
    // rt_sigprocmask(SIG_BLOCK, {SIGINT, SIGKILL}, &old, 8)
    w.put(SCRATCH, &(1u64 << 1 | 1 << 8).to_le_bytes());
    assert_eq!(
        w.call(nr::rt_sigprocmask, [0, SCRATCH, SCRATCH + 8, 8, 0, 0]),
        0
    );
    assert_eq!(w.word(SCRATCH + 8), 0);
    assert_eq!(w.p.sigmask, 1 << 1, "SIGKILL cannot be blocked");
    // prctl(PR_SET_NAME) renames the process, PR_GET_NAME reads it back.
    let name = w.path("a-very-long-process-name");
    assert_eq!(w.call(nr::prctl, [15, name, 0, 0, 0, 0]), 0);
    assert_eq!(w.p.name(), "a-very-long-pro");
    assert_eq!(w.call(nr::prctl, [16, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(w.get(SCRATCH, 16), b"a-very-long-pro\0");
    assert_eq!(w.call(nr::prctl, [38, 1, 0, 0, 0, 0]), err(Errno::EINVAL));
    assert_eq!(
        w.host.log,
        ["guest: process 1 (a-very-long-pro): unsupported prctl option 38, returning EINVAL"]
    );
}

#[test]
fn anonymous_memory() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let a = w.call(nr::mmap, [0, 3 * PAGE, 3, 0x22, u64::MAX, 0]);
    assert!(a >= crate::syscall::MMAP_BOTTOM && a.is_multiple_of(PAGE));
    w.put(a + 2 * PAGE, b"x");
    let b = w.call(nr::mmap, [0, 10, 3, 0x22, u64::MAX, 0]);
    assert_eq!(b + PAGE, a, "top-down, adjacent");
    // mprotect read-only, then writes through the kernel fail with EFAULT.
    assert_eq!(w.call(nr::mprotect, [a, PAGE, 1, 0, 0, 0]), 0);
    assert_eq!(w.host.pages[&a].1, Rights::READ);
    assert_eq!(
        w.call(nr::getrandom, [a, 8, 0, 0, 0, 0]),
        err(Errno::EFAULT)
    );
    assert_eq!(
        w.call(nr::mprotect, [a + 1, PAGE, 1, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mprotect, [0x1000, PAGE, 1, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    // munmap the middle page.
    assert_eq!(w.call(nr::munmap, [a + PAGE, PAGE, 0, 0, 0, 0]), 0);
    assert!(w.host.byte(a + PAGE).is_none());
    assert_eq!(w.host.byte(a + 2 * PAGE), Some(b'x'));
    // MAP_FIXED over existing pages replaces them; MAP_FIXED_NOREPLACE refuses.
    assert_eq!(w.call(nr::mmap, [a, 2 * PAGE, 3, 0x32, u64::MAX, 0]), a);
    assert_eq!(
        w.call(nr::mmap, [a, PAGE, 3, 0x10_0022, u64::MAX, 0]),
        err(Errno::EEXIST)
    );
    // PROT_NONE reserves without backing; mprotect later backs it.
    let before = w.host.budget;
    let r = w.call(nr::mmap, [0, 4 * PAGE, 0, 0x22, u64::MAX, 0]);
    assert_eq!(w.host.budget, before);
    assert_eq!(w.call(nr::mprotect, [r, PAGE, 3, 0, 0, 0]), 0);
    assert_eq!(w.host.budget, before - 1);
    // Never writable and executable at once.
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 7, 0x22, u64::MAX, 0]),
        err(Errno::EACCES)
    );
    assert_eq!(
        w.call(nr::mprotect, [r, PAGE, 6, 0, 0, 0]),
        err(Errno::EACCES)
    );
    // File mappings, bad flags and exhaustion.
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 1, 0x02, 3, 0]),
        err(Errno::ENODEV)
    );
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 1, 0x20, u64::MAX, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mmap, [0, 0, 1, 0x22, u64::MAX, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 8, 0x22, u64::MAX, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mmap, [0, u64::MAX, 3, 0x22, u64::MAX, 0]),
        err(Errno::ENOMEM)
    );
    assert_eq!(
        w.call(nr::mmap, [0, 2000 * PAGE, 3, 0x22, u64::MAX, 0]),
        err(Errno::ENOMEM)
    );
    assert_eq!(w.host.budget, before - 1, "a failed mmap backs nothing");
}

#[test]
fn files_of_the_initramfs() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let path = w.path("/etc/passwd");
    let fd = w.call(nr::openat, [(-100i64) as u64, path, 0, 0, 0, 0]);
    assert_eq!(fd, 3);
    assert_eq!(w.call(nr::read, [fd, SCRATCH, 4, 0, 0, 0]), 4);
    assert_eq!(w.get(SCRATCH, 4), b"root");
    assert_eq!(w.call(nr::lseek, [fd, (-2i64) as u64, 2, 0, 0, 0]), 28);
    assert_eq!(w.call(nr::read, [fd, SCRATCH, 100, 0, 0, 0]), 2);
    assert_eq!(w.call(nr::read, [fd, SCRATCH, 100, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::fstat, [fd, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(w.word(SCRATCH + 48), 30, "st_size");
    assert_eq!(w.get(SCRATCH + 24, 4), (S_IFREG | 0o644).to_le_bytes());
    assert_eq!(
        w.call(nr::write, [fd, SCRATCH, 1, 0, 0, 0]),
        err(Errno::EBADF)
    );
    // sendfile to the console: from the file offset (advancing it), or from *offset.
    assert_eq!(w.call(nr::lseek, [fd, 0, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::sendfile, [1, fd, 0, 5, 0, 0]), 5);
    assert_eq!(w.call(nr::lseek, [fd, 0, 1, 0, 0, 0]), 5);
    w.put(SCRATCH, &2u64.to_le_bytes());
    assert_eq!(w.call(nr::sendfile, [1, fd, SCRATCH, 100, 0, 0]), 28);
    assert_eq!(w.word(SCRATCH), 30);
    assert_eq!(w.call(nr::sendfile, [1, fd, 0, 100, 0, 0]), 25);
    assert_eq!(
        w.call(nr::sendfile, [1, fd, 0, 100, 0, 0]),
        0,
        "end of file"
    );
    assert_eq!(
        w.call(nr::sendfile, [fd, 1, 0, 100, 0, 0]),
        err(Errno::EBADF)
    );
    assert_eq!(
        w.call(nr::sendfile, [1, 0, 0, 100, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.host.stdout(),
        "root:ot:x:0:0:root:/root:/bin/sh\nx:0:0:root:/root:/bin/sh\n"
    );
    assert_eq!(w.call(nr::close, [fd, 0, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::close, [fd, 0, 0, 0, 0, 0]), err(Errno::EBADF));
    // Read-only file system; missing files; directories.
    assert_eq!(
        w.call(nr::openat, [(-100i64) as u64, path, 1, 0, 0, 0]),
        err(Errno::EROFS)
    );
    let missing = w.path("/etc/shadow");
    assert_eq!(
        w.call(nr::open, [missing, 0, 0, 0, 0, 0]),
        err(Errno::ENOENT)
    );
    assert_eq!(
        w.call(nr::open, [missing, 0o101, 0o644, 0, 0, 0]),
        err(Errno::EROFS)
    );
    let dir = w.path("/etc");
    let fd = w.call(nr::open, [dir, 0o200000, 0, 0, 0, 0]);
    assert_eq!(
        w.call(nr::read, [fd, SCRATCH, 1, 0, 0, 0]),
        err(Errno::EISDIR)
    );
    // getdents64 lists ".", "..", then the directory's entries; small buffers continue.
    let bin = w.path("/bin");
    let fd = w.call(nr::open, [bin, 0o200000, 0, 0, 0, 0]);
    let n = w.call(nr::getdents64, [fd, SCRATCH, 4096, 0, 0, 0]);
    let names = dirents(&w.get(SCRATCH, n as usize));
    assert_eq!(
        names,
        [(".", 4), ("..", 4), ("busybox", 8), ("sh", 10), ("data", 8)]
    );
    assert_eq!(
        w.call(nr::getdents64, [fd, SCRATCH, 4096, 0, 0, 0]),
        0,
        "at the end"
    );
    assert_eq!(w.call(nr::lseek, [fd, 0, 0, 0, 0, 0]), 0);
    let n = w.call(nr::getdents64, [fd, SCRATCH, 60, 0, 0, 0]);
    assert_eq!(dirents(&w.get(SCRATCH, n as usize)), [(".", 4), ("..", 4)]);
    assert_eq!(
        w.call(nr::getdents64, [fd, SCRATCH, 10, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    let n = w.call(nr::getdents64, [fd, SCRATCH, 4096, 0, 0, 0]);
    assert_eq!(dirents(&w.get(SCRATCH, n as usize)).len(), 3);
    let passwd = w.path("/etc/passwd");
    let file = w.call(nr::open, [passwd, 0, 0, 0, 0, 0]);
    assert_eq!(
        w.call(nr::getdents64, [file, SCRATCH, 4096, 0, 0, 0]),
        err(Errno::ENOTDIR)
    );
    assert_eq!(
        w.call(nr::getdents64, [1, SCRATCH, 4096, 0, 0, 0]),
        err(Errno::ENOTDIR)
    );
    let root = w.path("/");
    let fd = w.call(nr::open, [root, 0o200000, 0, 0, 0, 0]);
    let n = w.call(nr::getdents64, [fd, SCRATCH, 4096, 0, 0, 0]);
    let names: Vec<&str> = dirents(&w.get(SCRATCH, n as usize))
        .iter()
        .map(|d| d.0)
        .collect();
    assert_eq!(names, [".", "..", "bin", "etc"]);
    // stat follows links, lstat does not; newfstatat with AT_EMPTY_PATH is fstat.
    let sh = w.path("/bin/sh");
    assert_eq!(w.call(nr::stat, [sh, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(w.get(SCRATCH + 24, 4), (S_IFREG | 0o755).to_le_bytes());
    assert_eq!(w.call(nr::lstat, [sh, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(w.get(SCRATCH + 24, 4), (S_IFLNK | 0o777).to_le_bytes());
    let empty = w.path("");
    assert_eq!(w.call(nr::newfstatat, [1, empty, SCRATCH, 0x1000, 0, 0]), 0);
    assert_eq!(w.word(SCRATCH + 40), 5 << 8 | 1, "the console's rdev");
    let sh = w.path("/bin/sh");
    assert_eq!(w.call(nr::readlink, [sh, SCRATCH, 64, 0, 0, 0]), 7);
    assert_eq!(w.get(SCRATCH, 7), b"busybox");
    let passwd = w.path("/etc/passwd");
    assert_eq!(
        w.call(nr::readlink, [passwd, SCRATCH, 64, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(w.call(nr::access, [passwd, 4, 0, 0, 0, 0]), 0);
    assert_eq!(
        w.call(nr::access, [passwd, 2, 0, 0, 0, 0]),
        err(Errno::EROFS)
    );
    assert_eq!(
        w.call(nr::access, [passwd, 1, 0, 0, 0, 0]),
        err(Errno::EACCES)
    );
    assert_eq!(w.call(nr::getcwd, [SCRATCH, 100, 0, 0, 0, 0]), 2);
    assert_eq!(w.get(SCRATCH, 2), b"/\0");
    // Bad pointers are EFAULT, never a panic.
    assert_eq!(w.call(nr::open, [0x10, 0, 0, 0, 0, 0]), err(Errno::EFAULT));
    assert_eq!(
        w.call(nr::open, [u64::MAX - 2, 0, 0, 0, 0, 0]),
        err(Errno::EFAULT)
    );
    // Descriptors run out at MAX_FILES.
    let passwd = w.path("/etc/passwd");
    let mut last = 0;
    for _ in 0..crate::process::MAX_FILES {
        last = w.call(nr::open, [passwd, 0, 0, 0, 0, 0]);
    }
    assert_eq!(last, err(Errno::EMFILE));
}

/// The (name, type) of each `linux_dirent64` record in `bytes`.
fn dirents(bytes: &[u8]) -> Vec<(&'static str, u8)> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let length = u16::from_le_bytes([bytes[at + 16], bytes[at + 17]]) as usize;
        assert_eq!(length % 8, 0);
        let name = &bytes[at + 19..at + length];
        let name = &name[..name.iter().position(|&b| b == 0).unwrap()];
        out.push((
            &*String::from_utf8(name.to_vec()).unwrap().leak(),
            bytes[at + 18],
        ));
        at += length;
    }
    out
}

#[test]
fn unsupported_calls_and_faults() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(w.call(nr::kill, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(w.call(nr::kill, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(w.call(5000, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(w.call(6000, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(
        w.host.log,
        [
            "guest: process 1 (busybox): unsupported system call 62 (kill), returning ENOSYS",
            "guest: process 1 (busybox): unsupported system call 5000 (unknown), returning ENOSYS",
        ]
    );
    let mut m = ExceptionMessage {
        vector: 14,
        error_code: 6,
        fault_address: 0xdead_0000,
        ..Default::default()
    };
    m.registers.rip = 0x40_1010;
    let outcome = handle(&mut w.p, &mut w.pipes, &w.fs, &mut w.host, &mut m);
    assert_eq!(outcome, Outcome::Killed(11));
    assert_eq!(
        w.host.log.last().unwrap(),
        "guest: process 1 (busybox) killed by signal 11 (SIGSEGV): vector 14 error 0x6 address 0xdead0000 rip 0x401010"
    );
    m.vector = 6;
    assert_eq!(
        handle(&mut w.p, &mut w.pipes, &w.fs, &mut w.host, &mut m),
        Outcome::Killed(4)
    );
}

/// Random system calls with arguments from edge values never panic and keep the process's
/// areas sorted and disjoint.
#[test]
fn random_calls_never_panic() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let edges = [
        0,
        1,
        8,
        24,
        PAGE,
        PAGE + 1,
        SCRATCH,
        SCRATCH + PAGE - 4,
        0x40_1000,
        u64::MAX,
        u64::MAX - 7,
        1 << 47,
        (-100i64) as u64,
        0x22,
        0x32,
        0x1002,
    ];
    let mut seed = 0x1234_5678_9abc_def0u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for _ in 0..20_000 {
        let number = next() % 340;
        if number == nr::exit || number == nr::exit_group {
            continue;
        }
        let mut a = [0u64; 6];
        for x in &mut a {
            let r = next();
            *x = if r % 3 == 0 {
                r
            } else {
                edges[(r % edges.len() as u64) as usize]
            };
        }
        let _ = w.run(number, a);
        let areas: Vec<_> = w.p.areas.iter().map(|a| (a.start, a.end)).collect();
        assert!(areas.windows(2).all(|p| p[0].1 <= p[1].0), "{areas:x?}");
    }
}

#[test]
fn split_nul_keeps_empty_arguments() {
    let mut out = [&b""[..]; 4];
    assert_eq!(crate::split_nul(b"/bin/busybox\0echo\0\0", &mut out), 3);
    assert_eq!(out[..3], [&b"/bin/busybox"[..], b"echo", b""]);
    assert_eq!(crate::split_nul(b"a\0b", &mut out), 2);
    assert_eq!(crate::split_nul(b"", &mut out), 0);
}
