//! The personality end to end on the host: a program loaded from an initramfs into a model
//! of process memory, then the system calls a static C library and busybox make, as
//! exception messages.

use crate::cpio::{Archive, S_IFDIR, S_IFLNK, S_IFREG};
use crate::elf::tests::static_exe;
use crate::exec::{self, ExecError};
use crate::linux::{Errno, nr};
use crate::memory::{PAGE, PF_PRESENT, PF_USER, PF_WRITE, Rights, STACK_TOP};
use crate::process::{Process, Stream};
use crate::syscall::{Host, Outcome, handle};
use crate::system::{MAX_PROCESSES, State, System, Tasks};
use crate::tty::{self, Tty};
use crate::vfs::Fs;
use abi::ipc::{ExceptionMessage, VECTOR_SYSCALL};
use std::collections::HashMap;

/// Process memory as the kernel would have it: backed pages with the rights they are
/// mapped with (none: backed, not mapped).
#[derive(Default)]
struct Model {
    /// The pages of the selected process ([`Tasks::select`]).
    pages: HashMap<u64, (Vec<u8>, Rights)>,
    current: u32,
    /// The pages of the other processes.
    others: HashMap<u32, HashMap<u64, (Vec<u8>, Rights)>>,
    /// Replies sent: the process and its registers.
    resumed: Vec<(u32, ExceptionMessage)>,
    released: Vec<u32>,
    /// Pages the guest may still back.
    budget: u64,
    console: Vec<(u32, Stream, Vec<u8>)>,
    /// The console's terminal, if the guest has one.
    tty: Option<Tty>,
    log: Vec<String>,
    now: u64,
    /// FPU images by pid, and the processes suspended (stopped).
    fpu: HashMap<u32, [u8; 512]>,
    suspended: Vec<u32>,
    interrupted: Vec<u32>,
    /// Every process whose message the guest served (or served again), in order.
    selected: Vec<u32>,
    /// vfork children and the process whose memory they use.
    aliases: HashMap<u32, u32>,
    /// ARINC ports: the messages waiting at each destination (with their validity), and
    /// what the sources sent; a source holds at most [`PORT_ROOM`] messages.
    port_messages: HashMap<usize, std::collections::VecDeque<(Vec<u8>, bool)>>,
    port_sent: HashMap<usize, Vec<Vec<u8>>>,
    /// The notifications sent (thread, bits); the thread [`REFUSED_THREAD`] is refused.
    notified: Vec<(u64, u64)>,
    /// Calls that said they wait for a port ([`Host::port_wait`]).
    port_waits: usize,
    /// The kernel's answers asked for ([`Host::answer_always`]): thread, number, result.
    answers: Vec<(u32, u64, u32)>,
    /// The guest's CPUs ([`Host::cpus`]; 0: CPU 0 alone).
    cpus: u64,
    /// The CPU each thread was created on or moved to last ([`Tasks::fork`],
    /// [`Tasks::set_cpu`]), and the moves of threads that existed.
    cpu_of: HashMap<u32, u32>,
    moves: Vec<(u32, u32)>,
}

/// A disk in memory that counts its flushes; clones share it (the test keeps one while
/// the file system holds another).
#[derive(Clone, Default)]
struct Sectors(std::rc::Rc<std::cell::RefCell<SectorData>>);

#[derive(Default)]
struct SectorData {
    sectors: Vec<[u8; 512]>,
    flushes: u32,
}

impl Sectors {
    fn new(count: usize, fill: u8) -> Self {
        Sectors(std::rc::Rc::new(std::cell::RefCell::new(SectorData {
            sectors: vec![[fill; 512]; count],
            flushes: 0,
        })))
    }
    fn flushes(&self) -> u32 {
        self.0.borrow().flushes
    }
    fn sector(&self, i: usize) -> [u8; 512] {
        self.0.borrow().sectors[i]
    }
    /// `/dev/vda` over it, for [`crate::vfs::Fs::set_disk`].
    fn disk(&self) -> Box<dyn crate::disk::BlockFile> {
        let count = self.0.borrow().sectors.len() as u64;
        Box::new(crate::disk::Disk::new(self.clone(), count, |_| ()))
    }
}

impl slots::BlockDevice for Sectors {
    type Error = &'static str;
    fn read(&mut self, sector: u64, buf: &mut [u8; 512]) -> Result<(), &'static str> {
        *buf = *self
            .0
            .borrow()
            .sectors
            .get(sector as usize)
            .ok_or("out of range")?;
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; 512]) -> Result<(), &'static str> {
        *self
            .0
            .borrow_mut()
            .sectors
            .get_mut(sector as usize)
            .ok_or("out of range")? = *data;
        Ok(())
    }
    fn flush(&mut self) -> Result<(), &'static str> {
        self.0.borrow_mut().flushes += 1;
        Ok(())
    }
}

const PORT_ROOM: usize = 2;

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
    /// Backs `page` with a zeroed page mapped with `rights` (none: not mapped).
    fn back(&mut self, page: u64, rights: Rights) -> Result<(), Errno> {
        if self.budget == 0 {
            return Err(Errno::ENOMEM);
        }
        self.budget -= 1;
        self.pages.insert(page, (vec![0; PAGE as usize], rights));
        Ok(())
    }
    fn byte(&self, address: u64) -> Option<u8> {
        let (page, _) = self.pages.get(&(address & !(PAGE - 1)))?;
        Some(page[(address % PAGE) as usize])
    }
}

/// A thread the model's kernel refuses to notify.
const REFUSED_THREAD: u64 = 0xdead;

impl Host for Model {
    fn notify(&mut self, thread: u64, bits: u64) -> bool {
        self.notified.push((thread, bits));
        thread != REFUSED_THREAD
    }

    fn port_send(&mut self, port: usize, message: &[u8]) -> Result<(), Errno> {
        let sent = self.port_sent.entry(port).or_default();
        if sent.len() == PORT_ROOM {
            return Err(Errno::EAGAIN);
        }
        sent.push(message.to_vec());
        Ok(())
    }

    fn port_receive(
        &mut self,
        port: usize,
        buf: &mut [u8],
    ) -> Result<crate::arinc::Received, Errno> {
        let (m, valid) = self
            .port_messages
            .get_mut(&port)
            .and_then(|q| q.pop_front())
            .ok_or(Errno::EAGAIN)?;
        buf[..m.len()].copy_from_slice(&m);
        Ok(crate::arinc::Received {
            len: m.len(),
            valid,
        })
    }

    fn port_wait(&mut self) {
        self.port_waits += 1;
    }

    fn port_readiness(&mut self, port: usize) -> crate::arinc::Readiness {
        let first = self.port_messages.get(&port).and_then(|q| q.front());
        crate::arinc::Readiness {
            readable: first.is_some(),
            writable: self
                .port_sent
                .get(&port)
                .is_none_or(|s| s.len() < PORT_ROOM),
            valid: first.is_some_and(|m| m.1),
        }
    }

    fn read_user(&mut self, address: u64, buf: &mut [u8]) -> Result<(), Errno> {
        for (i, b) in buf.iter_mut().enumerate() {
            *b = self.byte(address + i as u64).unwrap_or(0);
        }
        Ok(())
    }
    fn write_user(&mut self, address: u64, data: &[u8]) -> Result<(), Errno> {
        for (i, b) in data.iter().enumerate() {
            let a = address + i as u64;
            let at = a & !(PAGE - 1);
            if !self.pages.contains_key(&at) {
                // Backed, not mapped until it faults.
                self.back(at, Rights::NONE)?;
            }
            let (page, _) = self.pages.get_mut(&at).ok_or(Errno::EFAULT)?;
            page[(a % PAGE) as usize] = *b;
        }
        Ok(())
    }
    fn map_image(
        &mut self,
        start: u64,
        pages: u64,
        rights: Rights,
        _: u32,
        fill: &mut dyn FnMut(u64, &mut [u8]),
    ) -> Result<(), Errno> {
        if pages > self.budget {
            return Err(Errno::ENOMEM);
        }
        for i in 0..pages {
            let at = start + i * PAGE;
            assert!(!self.pages.contains_key(&at), "page {at:#x} mapped twice");
            self.back(at, rights)?;
            if let Some(p) = self.pages.get_mut(&at) {
                p.0.fill(0xcc); // what a recycled frame may hold
                fill(at, &mut p.0);
            }
        }
        Ok(())
    }
    fn unmap(&mut self, start: u64, pages: u64) {
        for i in 0..pages {
            if self.pages.remove(&(start + i * PAGE)).is_some() {
                self.budget += 1;
            }
        }
    }
    fn protect(&mut self, start: u64, pages: u64, _: Rights) -> Result<(), Errno> {
        // Unmapped until the next fault.
        for i in 0..pages {
            if let Some(p) = self.pages.get_mut(&(start + i * PAGE)) {
                p.1 = Rights::NONE;
            }
        }
        Ok(())
    }
    fn move_pages(&mut self, from: u64, to: u64, pages: u64) {
        for i in 0..pages {
            if let Some((bytes, _)) = self.pages.remove(&(from + i * PAGE)) {
                self.pages.insert(to + i * PAGE, (bytes, Rights::NONE));
            }
        }
    }
    fn fill_in(&mut self, page: u64, fill: &mut dyn FnMut(&mut [u8])) -> Result<(), Errno> {
        if !self.pages.contains_key(&page) {
            self.back(page, Rights::NONE)?;
            if let Some(p) = self.pages.get_mut(&page) {
                fill(&mut p.0);
            }
        }
        Ok(())
    }
    fn fault_in(&mut self, page: u64, rights: Rights, _: bool) -> Result<(), Errno> {
        if !self.pages.contains_key(&page) {
            self.back(page, rights)?;
        }
        if let Some(p) = self.pages.get_mut(&page) {
            p.1 = rights;
        }
        Ok(())
    }
    fn console_write(&mut self, pid: u32, stream: Stream, bytes: &[u8]) {
        self.console.push((pid, stream, bytes.to_vec()));
    }
    fn tty(&mut self) -> Option<&mut Tty> {
        self.tty.as_mut()
    }
    fn now_ns(&mut self) -> u64 {
        self.now += 1_500_000_000;
        self.now
    }
    fn wall_clock_ns(&mut self) -> u64 {
        self.now_ns()
    }
    fn memory(&mut self) -> (u64, u64) {
        (100_000 * PAGE, self.budget * PAGE)
    }
    fn fpu(&mut self, image: &mut [u8; 512]) -> Result<(), Errno> {
        *image = self.fpu.get(&self.current).copied().unwrap_or([0x11; 512]);
        Ok(())
    }
    fn set_fpu(&mut self, image: &[u8; 512]) -> Result<(), Errno> {
        self.fpu.insert(self.current, *image);
        Ok(())
    }
    fn answer_always(&mut self, pid: u32, number: u64, result: u32) {
        self.answers.push((pid, number, result));
    }
    fn random(&mut self, buf: &mut [u8]) {
        buf.fill(0x5a);
    }
    fn cpus(&mut self) -> u64 {
        if self.cpus == 0 { 1 } else { self.cpus }
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
        ("etc/script", S_IFREG | 0o755, b"#!/bin/sh -e\nexit 1\n"),
    ])
}

/// A loaded process, its memory and its file system, with a scratch page at
/// [`SCRATCH`] for call arguments.
struct World<'a> {
    fs: Fs<'a>,
    p: Process,
    pipes: crate::pipe::Pipes,
    events: crate::events::Events,
    net: crate::net::Net,
    reported: crate::syscall::Reported,
    host: Model,
    fs_base: u64,
}

const SCRATCH: u64 = 0x7000_0000;

impl<'a> World<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        let fs = Fs::new(&Archive::new(bytes).unwrap(), 1 << 20).unwrap();
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
            events: crate::events::Events::new(),
            net: crate::net::Net::default(),
            reported: Default::default(),
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

    /// Serves message `m` of the process.
    fn handle(&mut self, m: &mut ExceptionMessage) -> Outcome {
        let files = crate::syscall::Files {
            pipes: &mut self.pipes,
            events: &mut self.events,
            net: &mut self.net,
            fs: &mut self.fs,
            others: &(),
        };
        handle(&mut self.p, files, &mut self.reported, &mut self.host, m)
    }

    /// A page fault of the process at `address` with `error` (the CPU's error code).
    fn fault(&mut self, error: u64, address: u64) -> Outcome {
        let mut m = ExceptionMessage {
            vector: crate::memory::VECTOR_PAGE_FAULT,
            error_code: error,
            fault_address: address,
            ..Default::default()
        };
        self.handle(&mut m)
    }

    fn run(&mut self, number: u64, a: [u64; 6]) -> (Outcome, ExceptionMessage) {
        let mut m = Self::message(number, a, self.fs_base);
        let outcome = self.handle(&mut m);
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
    let fs = Fs::new(&Archive::new(&bytes).unwrap(), 1 << 20).unwrap();
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
    let fs = Fs::new(&Archive::new(&bytes).unwrap(), 1 << 20).unwrap();
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
    // The same limits again are fine; a hard limit above the stack's size is not; the
    // descriptor limit lowered bounds new descriptors.
    assert_eq!(w.call(nr::prlimit64, [0, 3, SCRATCH, 0, 0, 0]), 0);
    w.put(SCRATCH + 8, &(1u64 << 30).to_le_bytes());
    assert_eq!(
        w.call(nr::prlimit64, [0, 3, SCRATCH, 0, 0, 0]),
        err(Errno::EPERM)
    );
    w.put(SCRATCH, &[4, 0, 0, 0, 0, 0, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(w.call(nr::prlimit64, [0, 7, SCRATCH, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::dup, [0, 0, 0, 0, 0, 0]), 3);
    assert_eq!(w.call(nr::dup, [0, 0, 0, 0, 0, 0]), err(Errno::EMFILE));
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
    // The console of a guest without a terminal (no COM2) is no terminal.
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
    let before = w.host.budget;
    let a = w.call(nr::mmap, [0, 3 * PAGE, 3, 0x22, u64::MAX, 0]);
    assert!(a >= crate::syscall::MMAP_BOTTOM && a.is_multiple_of(PAGE));
    assert_eq!(w.host.budget, before, "nothing backed before it is touched");
    // The first touch faults the page in with its area's rights.
    assert_eq!(
        w.fault(PF_USER | PF_WRITE, a + 2 * PAGE + 5),
        Outcome::Resume
    );
    assert_eq!(
        w.host.pages[&(a + 2 * PAGE)].1,
        Rights::READ | Rights::WRITE
    );
    w.put(a + 2 * PAGE, b"x");
    let b = w.call(nr::mmap, [0, 10, 3, 0x22, u64::MAX, 0]);
    assert_eq!(b + PAGE, a, "top-down, adjacent");
    // A hint that is free is taken.
    let hint = crate::syscall::MMAP_BOTTOM + 0x10_0000;
    assert_eq!(w.call(nr::mmap, [hint, PAGE, 3, 0x22, u64::MAX, 0]), hint);
    assert_ne!(w.call(nr::mmap, [hint, PAGE, 3, 0x22, u64::MAX, 0]), hint);
    // mprotect read-only: writes through the kernel fail with EFAULT, a write of the
    // process is SIGSEGV, a read faults the page in read-only.
    assert_eq!(w.call(nr::mprotect, [a, PAGE, 1, 0, 0, 0]), 0);
    assert_eq!(
        w.call(nr::getrandom, [a, 8, 0, 0, 0, 0]),
        err(Errno::EFAULT)
    );
    assert_eq!(
        w.fault(PF_USER | PF_WRITE, a),
        Outcome::Killed(crate::signal::SIGSEGV)
    );
    assert_eq!(w.fault(PF_USER, a), Outcome::Resume);
    assert_eq!(w.host.pages[&a].1, Rights::READ);
    assert_eq!(
        w.call(nr::mprotect, [a + 1, PAGE, 1, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mprotect, [0x1000, PAGE, 1, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    // munmap the middle page: a fault there is SIGSEGV.
    assert_eq!(w.call(nr::munmap, [a + PAGE, PAGE, 0, 0, 0, 0]), 0);
    assert!(w.host.byte(a + PAGE).is_none());
    assert_eq!(w.host.byte(a + 2 * PAGE), Some(b'x'));
    assert_eq!(
        w.fault(PF_USER, a + PAGE),
        Outcome::Killed(crate::signal::SIGSEGV)
    );
    // MAP_FIXED over existing pages replaces them; MAP_FIXED_NOREPLACE refuses.
    assert_eq!(w.call(nr::mmap, [a, 2 * PAGE, 3, 0x32, u64::MAX, 0]), a);
    assert!(w.host.byte(a).is_none(), "the old page went");
    assert_eq!(
        w.call(nr::mmap, [a, PAGE, 3, 0x10_0022, u64::MAX, 0]),
        err(Errno::EEXIST)
    );
    // PROT_NONE reserves: any access is SIGSEGV until mprotect allows it.
    let before = w.host.budget;
    let r = w.call(nr::mmap, [0, 4 * PAGE, 0, 0x22, u64::MAX, 0]);
    assert_eq!(w.fault(PF_USER, r), Outcome::Killed(crate::signal::SIGSEGV));
    assert_eq!(w.call(nr::mprotect, [r, PAGE, 3, 0, 0, 0]), 0);
    assert_eq!(w.host.budget, before);
    assert_eq!(w.fault(PF_USER | PF_WRITE, r), Outcome::Resume);
    assert_eq!(w.host.budget, before - 1);
    // mremap: shrink in place, grow in place, move with MREMAP_MAYMOVE.
    let m = w.call(nr::mmap, [0, 2 * PAGE, 3, 0x22, u64::MAX, 0]);
    w.put(m, b"moved");
    assert_eq!(w.call(nr::mremap, [m, 2 * PAGE, PAGE, 0, 0, 0]), m);
    assert!(w.p.areas.find(m + PAGE).is_none(), "shrunk");
    assert_eq!(
        w.call(nr::mremap, [m, PAGE, 2 * PAGE, 0, 0, 0]),
        m,
        "in place"
    );
    assert_eq!(
        w.call(nr::mremap, [m, 2 * PAGE, 64 * PAGE, 0, 0, 0]),
        err(Errno::ENOMEM),
        "an area above it, and no MREMAP_MAYMOVE"
    );
    let moved = w.call(nr::mremap, [m, 2 * PAGE, 64 * PAGE, 1, 0, 0]);
    assert_ne!(moved, m);
    assert_eq!(w.get(moved, 5), b"moved");
    assert!(w.p.areas.find(m).is_none());
    assert_eq!(w.p.areas.find(moved).unwrap().end, moved + 64 * PAGE);
    assert_eq!(
        w.call(nr::mremap, [moved + 1, PAGE, PAGE, 1, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mremap, [moved, PAGE, PAGE, 2, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mremap, [m, PAGE, PAGE, 1, 0, 0]),
        err(Errno::EFAULT)
    );
    // MADV_DONTNEED drops pages: the next touch reads zeros.
    w.put(r, b"dirty");
    assert_eq!(w.call(nr::madvise, [r, PAGE, 4, 0, 0, 0]), 0);
    assert!(w.host.byte(r).is_none());
    assert_eq!(w.get(r, 5), [0; 5]);
    assert_eq!(w.call(nr::madvise, [r, PAGE, 0, 0, 0, 0]), 0, "MADV_NORMAL");
    assert_eq!(
        w.call(nr::madvise, [r + 1, PAGE, 4, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::madvise, [0x1000, PAGE, 4, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    // Never writable and executable at once.
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 7, 0x22, u64::MAX, 0]),
        err(Errno::EACCES)
    );
    assert_eq!(
        w.call(nr::mprotect, [r, PAGE, 6, 0, 0, 0]),
        err(Errno::EACCES)
    );
    // Bad flags and exhaustion.
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 1, 0x02, 3, 0]),
        err(Errno::EBADF)
    );
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 1, 0x02, 1, 0]),
        err(Errno::ENODEV),
        "the console cannot be mapped"
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
    // The guest out of memory for a page a process touches: SIGBUS, for it alone.
    let big = w.call(nr::mmap, [0, 2000 * PAGE, 3, 0x22, u64::MAX, 0]);
    w.host.budget = 0;
    assert_eq!(
        w.fault(PF_USER | PF_WRITE, big),
        Outcome::Killed(crate::signal::SIGBUS)
    );
}

#[test]
fn file_mappings_are_filled_from_the_file_when_mapped() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let path = w.path("/etc/passwd");
    let fd = w.call(nr::openat, [(-100i64) as u64, path, 0, 0, 0, 0]);
    let at = w.call(nr::mmap, [0, 2 * PAGE, 1, 0x02, fd, 0]);
    assert!(at.is_multiple_of(PAGE) && at >= crate::syscall::MMAP_BOTTOM);
    // Backed with the file's bytes; mapped at the first touch.
    assert_eq!(w.host.byte(at), Some(b'r'));
    assert_eq!(w.fault(PF_USER, at + 4), Outcome::Resume);
    assert_eq!(w.host.pages[&at].1, Rights::READ);
    assert_eq!(
        w.host.byte(at + 30),
        Some(0),
        "zeros after the end of the file"
    );
    assert!(
        w.host.byte(at + PAGE).is_none(),
        "a page wholly past the file's end is backed when touched"
    );
    assert_eq!(w.fault(PF_USER, at + PAGE), Outcome::Resume);
    assert_eq!(
        w.fault(PF_USER | PF_WRITE, at),
        Outcome::Killed(crate::signal::SIGSEGV)
    );
    // A private writable mapping at a fixed address: a `write` of it to the console reads
    // the file's bytes; a `read` into it changes the copy, not the file.
    let fixed = crate::syscall::MMAP_BOTTOM;
    assert_eq!(w.call(nr::mmap, [fixed, PAGE, 3, 0x12, fd, 0]), fixed);
    assert_eq!(w.call(nr::write, [1, fixed, 5, 0, 0, 0]), 5);
    assert!(w.host.stdout().ends_with("root:"));
    assert_eq!(w.call(nr::lseek, [fd, 0, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::read, [fd, fixed + 1, 1, 0, 0, 0]), 1);
    assert_eq!(w.get(fixed, 5), b"rrot:");
    let again = w.call(nr::mmap, [0, PAGE, 1, 0x02, fd, 0]);
    assert_eq!(w.get(again, 5), b"root:");
    // MADV_DONTNEED keeps a file mapping's bytes.
    assert_eq!(w.call(nr::madvise, [again, PAGE, 4, 0, 0, 0]), 0);
    assert_eq!(w.get(again, 5), b"root:");
    assert_eq!(
        w.call(nr::mmap, [fixed, PAGE, 3, 0x02, fd, 1]),
        err(Errno::EINVAL),
        "unaligned offset"
    );
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 3, 0x01, fd, 0]),
        err(Errno::EACCES),
        "shared and writable"
    );
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 1, 0x02, 77, 0]),
        err(Errno::EBADF),
        "no such descriptor"
    );
    let root = w.path("/");
    let dir = w.call(nr::openat, [(-100i64) as u64, root, 0o200000, 0, 0, 0]);
    assert_eq!(
        w.call(nr::mmap, [0, PAGE, 1, 0x02, dir, 0]),
        err(Errno::ENODEV)
    );
    // Closing the descriptor keeps the mappings.
    assert_eq!(w.call(nr::close, [fd, 0, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::write, [1, at, 4, 0, 0, 0]), 4);
    // /dev/zero maps zeros.
    let zero = w.path("/dev/zero");
    let fd = w.call(nr::openat, [(-100i64) as u64, zero, 2, 0, 0, 0]);
    let z = w.call(nr::mmap, [0, PAGE, 3, 0x02, fd, 0]);
    assert_eq!(w.fault(PF_USER | PF_WRITE, z), Outcome::Resume);
    assert_eq!(w.host.byte(z), Some(0));
}

#[test]
fn the_stack_is_paged_in_on_demand_and_guarded_below() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let low = STACK_TOP - crate::memory::STACK_SIZE;
    assert!(w.host.byte(low).is_none(), "its low pages are not backed");
    assert_eq!(w.fault(PF_USER | PF_WRITE, low + 8), Outcome::Resume);
    assert_eq!(
        w.fault(PF_USER | PF_WRITE, low - 8),
        Outcome::Killed(crate::signal::SIGSEGV)
    );
    assert!(
        w.host
            .log
            .last()
            .unwrap()
            .contains("killed by signal 11 (SIGSEGV)")
    );
    // Kernel addresses, other exceptions.
    assert_eq!(
        w.fault(PF_USER | PF_PRESENT, 0xffff_8000_0000_0000),
        Outcome::Killed(crate::signal::SIGSEGV)
    );
    let mut m = World::message(0, [0; 6], 0);
    m.vector = 0;
    let outcome = w.handle(&mut m);
    assert_eq!(outcome, Outcome::Killed(crate::signal::SIGFPE));
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
    // Writable files; missing files (O_CREAT makes them); directories.
    let fd = w.call(nr::openat, [(-100i64) as u64, path, 1, 0, 0, 0]);
    assert_eq!(w.call(nr::close, [fd, 0, 0, 0, 0, 0]), 0);
    let missing = w.path("/etc/shadow");
    assert_eq!(
        w.call(nr::open, [missing, 0, 0, 0, 0, 0]),
        err(Errno::ENOENT)
    );
    let fd = w.call(nr::open, [missing, 0o101, 0o644, 0, 0, 0]);
    assert_eq!(w.call(nr::close, [fd, 0, 0, 0, 0, 0]), 0);
    assert_eq!(
        w.call(nr::open, [missing, 0o301, 0o644, 0, 0, 0]),
        err(Errno::EEXIST),
        "O_EXCL"
    );
    assert_eq!(w.call(nr::unlink, [missing, 0, 0, 0, 0, 0]), 0);
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
        [(".", 4), ("..", 4), ("busybox", 8), ("data", 8), ("sh", 10)]
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
    assert_eq!(names, [".", "..", "bin", "dev", "etc", "proc", "tmp"]);
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
    assert_eq!(w.call(nr::access, [passwd, 2, 0, 0, 0, 0]), 0);
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
    // Descriptors run out at the soft RLIMIT_NOFILE (1024, as on Linux).
    let passwd = w.path("/etc/passwd");
    let opened: Vec<u64> = (0..crate::process::DEFAULT_FILES)
        .map(|_| w.call(nr::open, [passwd, 0, 0, 0, 0, 0]))
        .take_while(|&fd| fd != err(Errno::EMFILE))
        .collect();
    assert_eq!(opened.last(), Some(&1023));
    assert_eq!(
        w.call(nr::open, [passwd, 0, 0, 0, 0, 0]),
        err(Errno::EMFILE)
    );
}

/// `close_range` closes the open descriptors of a range (the closed ones and those beyond
/// the table are skipped), or marks them close-on-exec; bad flags or a reversed range are
/// EINVAL.
#[test]
fn close_range() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let passwd = w.path("/etc/passwd");
    let fds: Vec<u64> = (0..6)
        .map(|_| w.call(nr::open, [passwd, 0, 0, 0, 0, 0]))
        .collect();
    assert_eq!(fds, [3, 4, 5, 6, 7, 8]);
    assert_eq!(w.call(nr::close, [5, 0, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::close_range, [4, 6, 0, 0, 0, 0]), 0);
    for fd in 4..=6 {
        assert!(w.p.file(fd).is_none(), "fd {fd}");
    }
    assert!(w.p.file(3).is_some() && w.p.file(7).is_some());
    // CLOSE_RANGE_CLOEXEC (4), with CLOSE_RANGE_UNSHARE (2): open stays, close-on-exec set.
    assert_eq!(w.call(nr::close_range, [7, u32::MAX as u64, 6, 0, 0, 0]), 0);
    assert!(w.p.file(7).is_some() && w.p.is_cloexec(7) && w.p.is_cloexec(8));
    assert!(!w.p.is_cloexec(3));
    assert_eq!(
        w.call(nr::close_range, [3, 2, 0, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::close_range, [3, 3, 1, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    // Everything from 3 up, as closefrom(3) asks.
    assert_eq!(w.call(nr::close_range, [3, u32::MAX as u64, 0, 0, 0, 0]), 0);
    assert!((3..64).all(|fd| w.p.file(fd).is_none()));
    assert!(w.p.file(0).is_some());
}

/// The memory locks as for a process without `CAP_IPC_LOCK`: small locks succeed within
/// `RLIMIT_MEMLOCK` (8 MiB), a lock of unmapped memory or beyond the limit is ENOMEM, a
/// limit of 0 EPERM; a range locked twice counts once; `munmap` unlocks.
#[test]
fn memory_locks() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(
        w.p.limits[crate::linux::RLIMIT_MEMLOCK as usize].soft,
        8 << 20
    );
    let map = |w: &mut World, len: u64| w.call(nr::mmap, [0, len, 3, 0x22, u64::MAX, 0]);
    let a = map(&mut w, 6 << 20);
    assert_eq!(w.call(nr::mlock, [a + 10, 2 * PAGE, 0, 0, 0, 0]), 0);
    assert_eq!(w.p.locks.bytes(), 3 * PAGE); // the pages it touches
    assert_eq!(w.call(nr::mlock, [a, 6 << 20, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::mlock, [a, 6 << 20, 0, 0, 0, 0]), 0);
    assert_eq!(w.p.locks.bytes(), 6 << 20);
    let b = map(&mut w, 4 << 20);
    assert_eq!(
        w.call(nr::mlock, [b, 4 << 20, 0, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    assert_eq!(w.call(nr::mlock2, [b, 2 << 20, 1, 0, 0, 0]), 0);
    assert_eq!(
        w.call(nr::mlock2, [b, PAGE, 2, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::mlock, [b + (2 << 20), PAGE, 0, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    // munlock of part of a range, munmap of another part: both free their bytes.
    assert_eq!(w.call(nr::munlock, [a, 1 << 20, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::munmap, [a + (5 << 20), 1 << 20, 0, 0, 0, 0]), 0);
    assert_eq!(w.p.locks.bytes(), 6 << 20);
    assert_eq!(
        w.call(nr::munlock, [a + (5 << 20), PAGE, 0, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    assert_eq!(
        w.call(nr::mlock, [0x1000, PAGE, 0, 0, 0, 0]),
        err(Errno::ENOMEM)
    );
    // mlockall: the process has more than 8 MiB mapped.
    assert_eq!(w.call(nr::mlockall, [1, 0, 0, 0, 0, 0]), err(Errno::ENOMEM));
    assert_eq!(w.call(nr::mlockall, [0, 0, 0, 0, 0, 0]), err(Errno::EINVAL));
    assert_eq!(w.call(nr::mlockall, [4, 0, 0, 0, 0, 0]), err(Errno::EINVAL));
    assert_eq!(w.call(nr::mlockall, [2, 0, 0, 0, 0, 0]), 0);
    assert!(w.p.lock_future);
    assert_eq!(w.call(nr::munlockall, [0; 6]), 0);
    assert_eq!((w.p.locks.bytes(), w.p.lock_future), (0, false));
    assert_eq!(w.call(nr::munmap, [b, 4 << 20, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::munmap, [a, 5 << 20, 0, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::mlockall, [1, 0, 0, 0, 0, 0]), 0);
    let mapped: u64 = w.p.areas.iter().map(|a| a.end - a.start).sum();
    assert_eq!(w.p.locks.bytes(), mapped);
    // RLIMIT_MEMLOCK 0: nothing may be locked; root may raise it beyond 8 MiB.
    w.put(SCRATCH, &[0; 16]);
    assert_eq!(w.call(nr::setrlimit, [8, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(
        w.call(nr::mlock, [SCRATCH, PAGE, 0, 0, 0, 0]),
        err(Errno::EPERM)
    );
    assert_eq!(w.call(nr::mlockall, [1, 0, 0, 0, 0, 0]), err(Errno::EPERM));
    let mut limit = [0u8; 16];
    limit[..8].copy_from_slice(&(1u64 << 30).to_le_bytes());
    limit[8..].copy_from_slice(&(1u64 << 30).to_le_bytes());
    w.put(SCRATCH, &limit);
    assert_eq!(w.call(nr::setrlimit, [8, SCRATCH, 0, 0, 0, 0]), 0);
}

/// [`crate::memory::Locks`] joins touching and overlapping ranges and cuts them.
#[test]
fn lock_ranges() {
    let mut l = crate::memory::Locks::default();
    l.lock(0x1000, 0x3000).unwrap();
    l.lock(0x3000, 0x4000).unwrap();
    l.lock(0x2000, 0x5000).unwrap();
    assert_eq!(l.bytes(), 0x4000);
    assert_eq!(l.unlocked_in(0x0, 0x6000), 0x2000);
    l.unlock(0x2000, 0x3000).unwrap();
    assert_eq!(l.bytes(), 0x3000);
    assert_eq!(l.unlocked_in(0x1000, 0x5000), 0x1000);
    for i in 0..crate::memory::MAX_AREAS as u64 - 2 {
        l.lock(0x10_0000 + i * 0x2000, 0x10_1000 + i * 0x2000)
            .unwrap();
    }
    // Full: a range apart does not fit, one joining others does; cutting one in two not.
    assert!(l.lock(0x9000_0000, 0x9000_1000).is_err());
    l.lock(0x10_0000, 0x10_3000).unwrap();
    l.unlock(0x10_0800, 0x10_1000).unwrap();
    assert!(l.unlock(0x10_1800, 0x10_2000).is_err());
    assert_eq!(l.bytes(), 0x3000 + 0x2800 + 0x1000 * 60);
}

/// A process may have as many descriptors as its soft `RLIMIT_NOFILE` says (1024 at
/// first, up to [`crate::process::MAX_FILES`]); the table grows with the highest in use
/// and shrinks when it is closed; `poll` and `select` watch them all.
#[test]
fn descriptors_up_to_the_nofile_limit() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let limit = |w: &mut World, soft: u64, hard: u64| {
        let mut b = [0u8; 16];
        b[..8].copy_from_slice(&soft.to_le_bytes());
        b[8..].copy_from_slice(&hard.to_le_bytes());
        w.put(SCRATCH, &b);
        w.call(nr::setrlimit, [7, SCRATCH, 0, 0, 0, 0])
    };
    assert_eq!(w.call(nr::dup2, [1, 1023, 0, 0, 0, 0]), 1023);
    assert_eq!(w.call(nr::dup2, [1, 1024, 0, 0, 0, 0]), err(Errno::EBADF));
    let max = crate::process::MAX_FILES as u64;
    assert_eq!(limit(&mut w, max + 1, max + 1), err(Errno::EPERM));
    assert_eq!(limit(&mut w, 3000, max), 0);
    assert_eq!(w.call(nr::dup2, [1, 2999, 0, 0, 0, 0]), 2999);
    assert_eq!(w.call(nr::fcntl, [1, 1030, 2000, 0, 0, 0]), 2000); // F_DUPFD_CLOEXEC
    assert!(w.p.is_cloexec(2000) && !w.p.is_cloexec(2999));
    assert_eq!(w.p.files.len(), 3000);
    // poll and select see a high descriptor.
    let mut pollfd = [0u8; 8];
    pollfd[..4].copy_from_slice(&2999i32.to_le_bytes());
    pollfd[4..6].copy_from_slice(&4u16.to_le_bytes()); // POLLOUT
    w.put(SCRATCH + 0x100, &pollfd);
    assert_eq!(w.call(nr::poll, [SCRATCH + 0x100, 1, 0, 0, 0, 0]), 1);
    assert_eq!(
        w.call(nr::poll, [SCRATCH + 0x100, 3001, 0, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    let mut set = [0u8; 384];
    set[2000 / 8] |= 1 << (2000 % 8);
    w.put(SCRATCH + 0x200, &set);
    w.put(SCRATCH + 0x180, &[0; 16]); // no wait
    assert_eq!(
        w.call(
            nr::select,
            [2001, 0, SCRATCH + 0x200, 0, SCRATCH + 0x180, 0]
        ),
        1
    );
    assert_eq!(w.get(SCRATCH + 0x200, 251)[250], 1);
    // Closing the highest shrinks the table; a lower limit keeps what is open.
    assert_eq!(w.call(nr::close, [2999, 0, 0, 0, 0, 0]), 0);
    assert_eq!(w.p.files.len(), 2001);
    assert_eq!(limit(&mut w, 100, max), 0);
    assert_eq!(w.call(nr::dup, [0, 0, 0, 0, 0, 0]), 3);
    assert!(w.p.file(2000).is_some());
    assert_eq!(w.call(nr::dup2, [1, 100, 0, 0, 0, 0]), err(Errno::EBADF));
    assert_eq!(w.call(nr::close_range, [3, u32::MAX as u64, 0, 0, 0, 0]), 0);
    assert_eq!(w.p.files.len(), 3);
}

/// `/proc/self/fd` lists the open descriptors as links (a file's path, a pipe, the
/// console); opening one, or `/dev/fd/<n>`, opens what it has: a pipe's end (bash's
/// process substitution), a file anew (its own offset), even an unlinked one.
#[test]
fn descriptors_in_proc_and_dev_fd() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(w.call(nr::pipe, [SCRATCH + 0x100, 0, 0, 0, 0, 0]), 0);
    let ends = w.get(SCRATCH + 0x100, 8);
    let (r, wr) = (ends[0] as u64, ends[4] as u64);
    assert_eq!((r, wr), (3, 4));
    let passwd = w.path("/etc/passwd");
    assert_eq!(w.call(nr::open, [passwd, 0, 0, 0, 0, 0]), 5);
    assert_eq!(w.call(nr::read, [5, SCRATCH, 4, 0, 0, 0]), 4);
    let readlink = |w: &mut World, path: &str| {
        let at = w.path(path);
        let n = w.call(nr::readlink, [at, SCRATCH + 0x200, 100, 0, 0, 0]);
        String::from_utf8(w.get(SCRATCH + 0x200, n as usize)).unwrap()
    };
    assert_eq!(readlink(&mut w, "/proc/self/fd/5"), "/etc/passwd");
    assert_eq!(readlink(&mut w, "/proc/self/fd/0"), "/dev/console");
    assert!(readlink(&mut w, "/proc/self/fd/3").starts_with("pipe:["));
    assert_eq!(readlink(&mut w, "/dev/fd"), "/proc/self/fd");
    let dir = w.path("/proc/self/fd");
    let dir = w.call(nr::open, [dir, 0o200000, 0, 0, 0, 0]);
    let n = w.call(nr::getdents64, [dir, SCRATCH + 0x400, 0x400, 0, 0, 0]);
    let names: Vec<&str> = dirents(&w.get(SCRATCH + 0x400, n as usize))
        .into_iter()
        .map(|(name, _)| name)
        .collect();
    assert_eq!(names, [".", "..", "0", "1", "2", "3", "4", "5", "6"]);
    assert_eq!(w.call(nr::close, [dir, 0, 0, 0, 0, 0]), 0);
    // The pipe's read end through /dev/fd, the write end through /proc/self/fd.
    let path = w.path("/dev/fd/4");
    let writer = w.call(nr::open, [path, 1, 0, 0, 0, 0]);
    w.put(SCRATCH, b"hi");
    assert_eq!(w.call(nr::write, [writer, SCRATCH, 2, 0, 0, 0]), 2);
    let path = w.path("/dev/fd/3");
    let reader = w.call(nr::open, [path, 0, 0, 0, 0, 0]);
    assert_eq!(w.call(nr::read, [reader, SCRATCH + 0x10, 8, 0, 0, 0]), 2);
    assert_eq!(w.get(SCRATCH + 0x10, 2), b"hi");
    // A file opened anew starts at offset 0, even once unlinked.
    let path = w.path("/proc/self/fd/5");
    let again = w.call(nr::open, [path, 0, 0, 0, 0, 0]);
    assert_eq!(w.call(nr::lseek, [again, 0, 1, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::lseek, [5, 0, 1, 0, 0, 0]), 4);
    let tmp = w.path("/tmp/gone");
    let gone = w.call(nr::open, [tmp, 0o102, 0o600, 0, 0, 0]);
    let tmp = w.path("/tmp/gone");
    assert_eq!(w.call(nr::unlink, [tmp, 0, 0, 0, 0, 0]), 0);
    let path = w.path(&format!("/dev/fd/{gone}"));
    assert!(w.call(nr::open, [path, 2, 0, 0, 0, 0]) < 100);
    let path = w.path("/dev/fd/0");
    assert!(w.call(nr::open, [path, 2, 0, 0, 0, 0]) < 100);
    let path = w.path("/dev/fd/99");
    assert_eq!(w.call(nr::open, [path, 0, 0, 0, 0, 0]), err(Errno::ENOENT));
    let path = w.path("/dev/fd/3/x");
    assert_eq!(w.call(nr::open, [path, 0, 0, 0, 0, 0]), err(Errno::ENOTDIR));
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

/// Every number of the dispatch table reaches the handler of its line (the call it names,
/// never the unsupported path); every other number answers `ENOSYS`, logged once.
#[test]
fn dispatch_table() {
    use crate::syscall::table::{NUMBERS, lookup};
    let bytes = initramfs();
    let mut lines = std::collections::BTreeSet::new();
    for &number in NUMBERS {
        assert!(lines.insert(number), "call {number} has two lines");
        let entry = lookup::<Model>(number).expect("a line of the table");
        assert_eq!(Some(entry.name), crate::linux::syscall_name(number));
        let mut w = World::new(&bytes);
        let (outcome, m) = w.run(number, [0; 6]);
        let logged_unsupported = w
            .host
            .log
            .iter()
            .any(|l| l.contains("unsupported system call"));
        assert!(!logged_unsupported, "{} ({number})", entry.name);
        let process_table = matches!(outcome, Outcome::Process(_));
        let handler_is_process_tables = [
            "exit",
            "clone",
            "fork",
            "vfork",
            "execve",
            "wait4",
            "waitid",
            "kill",
            "tkill",
            "tgkill",
            "setpgid",
            "getpgid",
            "setsid",
            "getsid",
            "sysinfo",
            "futex",
            "sched_setaffinity",
        ]
        .contains(&entry.handler_name);
        // The process table's calls reach it (kill and exit whatever their arguments;
        // tkill and tgkill of pid 0 fail before).
        if !matches!(entry.handler_name, "exit" | "tkill" | "tgkill") {
            assert_eq!(process_table, handler_is_process_tables, "{}", entry.name);
        }
        // rseq is the one served call that answers ENOSYS (as on kernels without it).
        if outcome == Outcome::Resume && m.registers.rax == Errno::ENOSYS.result() {
            assert_eq!(entry.handler_name, "no_rseq", "{}", entry.name);
        }
    }
    let mut w = World::new(&bytes);
    let unknown: Vec<u64> = (0..=600)
        .chain([1000, 5000, 1 << 32, u64::MAX])
        .filter(|n| !NUMBERS.contains(n))
        .collect();
    for _ in 0..2 {
        for &number in &unknown {
            assert!(lookup::<Model>(number).is_none());
            assert_eq!(w.call(number, [0; 6]), err(Errno::ENOSYS), "call {number}");
        }
    }
    // Once per number; the numbers from 511 up share one record.
    let below = unknown.iter().filter(|&&n| n < 511).count();
    assert_eq!(w.host.log.len(), below + 1);
    for (line, number) in w.host.log.iter().zip(&unknown) {
        let name = crate::linux::syscall_name(*number).unwrap_or("unknown");
        assert_eq!(
            *line,
            format!(
                "guest: process 1 (busybox): unsupported system call {number} ({name}), returning ENOSYS"
            )
        );
    }
}

/// An unsupported call is logged by its Linux name once per guest: a process started after
/// another made it (a loop starting processes) adds no line. Every number of the 64-bit
/// ABI has its name.
#[test]
fn unsupported_calls_logged_once_per_guest() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(w.call(nr::swapon, [2, 1, 0, 0, 0, 0]), err(Errno::ENOSYS));
    for pid in 2..50 {
        let mut next = crate::process::Process::new(pid, 1, w.p.exe);
        next.areas = w.p.areas.clone();
        w.p = next;
        assert_eq!(w.call(nr::swapon, [2, 1, 0, 0, 0, 0]), err(Errno::ENOSYS));
        assert_eq!(w.call(nr::io_uring_setup, [0; 6]), err(Errno::ENOSYS));
    }
    assert_eq!(
        w.host.log,
        [
            "guest: process 1 (busybox): unsupported system call 167 (swapon), returning ENOSYS",
            "guest: process 2 (busybox): unsupported system call 425 (io_uring_setup), returning ENOSYS",
        ]
    );
    let unnamed: Vec<u64> = (0..=466)
        .filter(|&n| !(336..424).contains(&n))
        .filter(|&n| crate::linux::syscall_name(n).is_none())
        .collect();
    assert!(unnamed.is_empty(), "{unnamed:?}");
    assert_eq!(
        crate::linux::syscall_name(nr::close_range),
        Some("close_range")
    );
    assert_eq!(crate::linux::syscall_name(149), Some("mlock"));
}

#[test]
fn unsupported_calls_and_faults() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(w.call(nr::swapon, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(w.call(nr::swapon, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(w.call(5000, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(w.call(6000, [0; 6]), err(Errno::ENOSYS));
    assert_eq!(
        w.host.log,
        [
            "guest: process 1 (busybox): unsupported system call 167 (swapon), returning ENOSYS",
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
    let outcome = w.handle(&mut m);
    assert_eq!(outcome, Outcome::Killed(11));
    assert_eq!(
        w.host.log.last().unwrap(),
        "guest: process 1 (busybox) killed by signal 11 (SIGSEGV): vector 14 error 0x6 address 0xdead0000 rip 0x401010"
    );
    m.vector = 6;
    assert_eq!(
        handle(
            &mut w.p,
            crate::syscall::Files {
                pipes: &mut w.pipes,
                events: &mut w.events,
                net: &mut w.net,
                fs: &mut w.fs,
                others: &(),
            },
            &mut w.reported,
            &mut w.host,
            &mut m,
        ),
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

impl Tasks for Model {
    fn select(&mut self, pid: u32) {
        self.selected.push(pid);
        // A vfork child's memory is its parent's.
        let pid = self.aliases.get(&pid).copied().unwrap_or(pid);
        if pid != self.current {
            let pages = std::mem::take(&mut self.pages);
            self.others.insert(self.current, pages);
            self.pages = self.others.remove(&pid).unwrap_or_default();
            self.current = pid;
        }
    }
    fn borrow(&mut self, child: u32, parent: u32, cpu: u32) -> Result<(), Errno> {
        let owner = self.aliases.get(&parent).copied().unwrap_or(parent);
        self.aliases.insert(child, owner);
        self.cpu_of.insert(child, cpu);
        Ok(())
    }
    fn own(&mut self, pid: u32, cpu: u32) -> Result<bool, Errno> {
        let borrowed = self.aliases.remove(&pid).is_some();
        if borrowed {
            self.select(pid);
            self.cpu_of.insert(pid, cpu);
        }
        Ok(borrowed)
    }
    fn set_cpu(&mut self, pid: u32, cpu: u32) {
        self.moves.push((pid, cpu));
        self.cpu_of.insert(pid, cpu);
    }
    fn fork(&mut self, child: u32, _: &crate::memory::Areas, cpu: u32) -> Result<u64, Errno> {
        self.cpu_of.insert(child, cpu);
        let n = self.pages.len() as u64;
        if n > self.budget {
            return Err(Errno::ENOMEM);
        }
        self.budget -= n;
        self.others.insert(child, self.pages.clone());
        Ok(n)
    }
    fn release(&mut self, pid: u32) {
        if self.aliases.remove(&pid).is_some() {
            self.released.push(pid);
            return;
        }
        let pages = if pid == self.current {
            std::mem::take(&mut self.pages)
        } else {
            self.others.remove(&pid).unwrap_or_default()
        };
        self.budget += pages.len() as u64;
        self.released.push(pid);
    }
    fn resume(&mut self, pid: u32, m: &ExceptionMessage) {
        self.resumed.push((pid, *m));
    }
    fn interrupt(&mut self, pid: u32) {
        self.interrupted.push(pid);
    }
    fn suspend(&mut self, pid: u32, stop: bool) {
        self.suspended.retain(|&p| p != pid);
        if stop {
            self.suspended.push(pid);
        }
    }
}

/// A guest with several processes: init loaded as pid 1, with a scratch page.
struct Guest<'a> {
    fs: Fs<'a>,
    system: System,
    host: Model,
}

const WNOHANG: u64 = 1;

impl<'a> Guest<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self::with_cpus(bytes, 1)
    }

    /// A guest on CPUs `cpus` (bit n: CPU n), init on the lowest, as syssw starts it.
    fn with_cpus(bytes: &'a [u8], cpus: u64) -> Self {
        let fs = Fs::new(&Archive::new(bytes).unwrap(), 1 << 20).unwrap();
        let mut host = Model::new(100_000);
        host.current = 1;
        host.cpus = cpus;
        let mut loaded = exec::load(&fs, &mut host, 1, 0, &[b"/bin/sh"], &[], 0).unwrap();
        loaded.process.cpu = cpus.trailing_zeros();
        let mut g = Guest {
            fs,
            system: System::new(loaded.process, 0),
            host,
        };
        assert_eq!(
            g.call(1, nr::mmap, [SCRATCH, PAGE, 3, 0x32, u64::MAX, 0]),
            Some(SCRATCH)
        );
        g
    }

    /// Serves message `m` of `pid`: the replies it caused, by pid with `rax`.
    fn serve(&mut self, pid: u32, m: ExceptionMessage) -> Vec<(u32, u64)> {
        self.host.resumed.clear();
        let ended = self.system.serve(pid, &mut self.fs, &mut self.host, m);
        assert_eq!(ended, None, "init ended");
        self.host
            .resumed
            .iter()
            .map(|(pid, m)| (*pid, m.registers.rax))
            .collect()
    }

    /// System call `number` of `pid`: its result if it completed at once.
    fn call(&mut self, pid: u32, number: u64, a: [u64; 6]) -> Option<u64> {
        let replies = self.serve(pid, World::message(number, a, 0));
        replies.iter().find(|r| r.0 == pid).map(|r| r.1)
    }

    /// `fork` of `parent`, and the child's first message (its fetch fault at 0), which
    /// resumes it with the parent's registers and `rax = 0`.
    fn fork(&mut self, parent: u32) -> u32 {
        let child = self.call(parent, nr::fork, [0; 6]).unwrap() as u32;
        assert!(matches!(self.system.state(child), Some(State::Starting(_))));
        let fault = ExceptionMessage {
            vector: 14,
            error_code: 0x14,
            ..Default::default()
        };
        self.host.resumed.clear();
        let _ = self
            .system
            .serve(child, &mut self.fs, &mut self.host, fault);
        let (pid, m) = self.host.resumed[0];
        assert_eq!(pid, child);
        assert_eq!((m.registers.rax, m.registers.rip), (0, 0x40_1019));
        assert_eq!(self.system.state(child), Some(State::Running));
        child
    }

    fn put(&mut self, pid: u32, at: u64, bytes: &[u8]) {
        self.host.select(pid);
        self.host.write_user(at, bytes).unwrap();
    }

    fn get(&mut self, pid: u32, at: u64, len: usize) -> Vec<u8> {
        self.host.select(pid);
        let mut b = vec![0; len];
        self.host.read_user(at, &mut b).unwrap();
        b
    }

    fn word(&mut self, pid: u32, at: u64) -> u32 {
        u32::from_le_bytes(self.get(pid, at, 4).try_into().unwrap())
    }

    fn pids(&self) -> Vec<u32> {
        let mut pids: Vec<u32> = self.system.pids().collect();
        pids.sort();
        pids
    }
}

/// A message that changes only its sender (a page fault, `getpid`, `mmap`) serves no
/// blocked call again; any other does (each retry is a whole call), and a wait it ends
/// ends.
#[test]
fn only_what_may_end_a_wait_serves_the_blocked_calls_again() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    assert_eq!(g.call(child, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let w = g.word(child, SCRATCH + 4) as u64;
    let status = SCRATCH + 0x100;
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]), None);
    g.host.selected.clear();
    assert_eq!(g.call(child, nr::getpid, [0; 6]), Some(u64::from(child)));
    assert_eq!(
        g.call(child, nr::mmap, [0, PAGE, 3, 0x22, u64::MAX, 0])
            .map(|a| a > 0),
        Some(true)
    );
    let write_fault = ExceptionMessage {
        vector: crate::memory::VECTOR_PAGE_FAULT,
        error_code: 0x7,
        fault_address: SCRATCH,
        ..Default::default()
    };
    assert_eq!(g.serve(child, write_fault), [(child, 0)]);
    assert_eq!(
        g.host.selected,
        [child, child, child],
        "init's wait4 stays as it was"
    );
    // Closing no descriptor changes nothing; closing a pipe's end may end a wait (its
    // last writer's): init's wait4 is served again.
    assert_eq!(
        g.call(child, nr::close, [99, 0, 0, 0, 0, 0]),
        Some(err(Errno::EBADF))
    );
    assert_eq!(g.host.selected, [child, child, child, child]);
    // Nor does a new process (nobody waits for a child not yet made).
    let grandchild = g.fork(child);
    assert!(
        !g.host.selected.contains(&1),
        "init's wait4 stays after a fork"
    );
    assert_eq!(
        g.serve(grandchild, World::message(nr::exit_group, [0; 6], 0)),
        []
    );
    g.host.selected.clear();
    assert_eq!(g.call(child, nr::close, [w, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.host.selected, [child, 1]);
    assert!(matches!(g.system.state(1), Some(State::Blocked(_))));
    assert_eq!(
        g.serve(child, World::message(nr::exit_group, [0; 6], 0)),
        [(1, u64::from(child))]
    );
    // Every call that changes only its caller is one the guest serves, none of the process
    // table's.
    use crate::syscall::table::{CALLER_ONLY, NUMBERS, caller_only};
    for number in 0..1024 {
        assert_eq!(
            caller_only(number),
            CALLER_ONLY.contains(&number),
            "{number}"
        );
    }
    assert!(!caller_only(u64::MAX));
    for &number in CALLER_ONLY {
        assert!(NUMBERS.contains(&number), "{number}");
        let mut w = World::new(&bytes);
        assert!(
            !matches!(w.run(number, [0; 6]).0, Outcome::Process(_)),
            "{number}"
        );
    }
}

/// Process `pid` sends the datagram "ping" from a new UDP socket to the `struct
/// sockaddr_in` at `to` in its memory; the `sendto`'s result.
fn send_ping(g: &mut Guest, pid: u32, to: u64) -> Option<u64> {
    let out = g.call(pid, nr::socket, [2, 2, 0, 0, 0, 0]).unwrap();
    let ping = SCRATCH + 0x600;
    g.put(pid, ping, b"ping");
    g.call(pid, nr::sendto, [out, ping, 4, 0, to, 16])
}

/// The `struct sockaddr_in` of 127.0.0.1:`port`.
fn loopback(port: u16) -> [u8; 16] {
    let [hi, lo] = port.to_be_bytes();
    [2, 0, hi, lo, 127, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0]
}

/// Where [`bound_socket`] leaves the socket's address, in the process's memory.
const BOUND_ADDR: u64 = SCRATCH + 0x200;

/// A socket of process `pid` (`SOCK_STREAM` 1 or `SOCK_DGRAM` 2 as `ty`) bound to
/// 127.0.0.1:`port`, its address left at [`BOUND_ADDR`].
fn bound_socket(g: &mut Guest, pid: u32, ty: u64, port: u16) -> u64 {
    g.put(pid, BOUND_ADDR, &loopback(port));
    let fd = g.call(pid, nr::socket, [2, ty, 0, 0, 0, 0]).unwrap();
    assert_eq!(
        g.call(pid, nr::bind, [fd, BOUND_ADDR, 16, 0, 0, 0]),
        Some(0)
    );
    fd
}

/// A wake-up for `eth0`'s frames serves the blocked calls again only when the stack took
/// frames in or a socket may have changed: one for frames an earlier run already took
/// serves none (each retry is a whole call), nor does a tick for the stack's timers
/// alone, while one for the ports' news serves them all.
#[test]
fn frames_that_changed_nothing_serve_no_blocked_call_again() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    let status = SCRATCH + 0x100;
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]), None);
    // A listener on the loopback: the stack exists, with nothing to do.
    let l = bound_socket(&mut g, child, 1, 8080);
    assert_eq!(g.call(child, nr::listen, [l, 2, 0, 0, 0, 0]), Some(0));
    g.host.selected.clear();
    assert_eq!(g.system.frames_came(&mut g.fs, &mut g.host), None);
    assert_eq!(g.host.selected, [], "init's wait4 stays as it was");
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    assert_eq!(
        g.host.selected,
        [],
        "so on a tick with no timer of a process due"
    );
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, true), None);
    assert_eq!(
        g.host.selected,
        [1],
        "a tick for the ports' news serves it again"
    );
    assert!(matches!(g.system.state(1), Some(State::Blocked(_))));
}

/// After a change of the stack's sockets alone, only the calls waiting on a socket that
/// changed are served again: a datagram to one socket answers its reader's `recvfrom`,
/// while another socket's reader and init's `wait4` stay as they were until a timer of a
/// process is due.
#[test]
fn a_socket_change_serves_only_the_calls_waiting_on_that_socket() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let (reader, other, sender) = (g.fork(1), g.fork(1), g.fork(1));
    let status = SCRATCH + 0x100;
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]), None);
    let mine = bound_socket(&mut g, reader, 2, 7001);
    let theirs = bound_socket(&mut g, other, 2, 7002);
    let buf = SCRATCH + 0x400;
    assert_eq!(g.call(reader, nr::recvfrom, [mine, buf, 64, 0, 0, 0]), None);
    assert_eq!(
        g.call(other, nr::recvfrom, [theirs, buf, 64, 0, 0, 0]),
        None
    );
    let out = bound_socket(&mut g, sender, 2, 7003);
    g.put(sender, SCRATCH + 0x300, &loopback(7001));
    g.put(sender, buf, b"ping");
    g.host.selected.clear();
    let sendto = [out, buf, 4, 0, SCRATCH + 0x300, 16];
    assert_eq!(g.call(sender, nr::sendto, sendto), Some(4));
    assert!(
        g.host.selected.contains(&reader),
        "the datagram's reader is served"
    );
    assert!(
        !g.host.selected.contains(&other),
        "the other socket's reader is not"
    );
    assert!(!g.host.selected.contains(&1), "nor init's wait4");
    assert_eq!(g.system.state(reader), Some(State::Running));
    g.host.selected.clear();
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    assert_eq!(g.host.selected, [], "a tick with no timer of a process due");
    // A sleep's end is a process's timer: every waiting call is served again.
    let sleep = SCRATCH + 0x500;
    g.put(sender, sleep, &100u64.to_le_bytes());
    g.put(sender, sleep + 8, &[0; 8]);
    let nanosleep = on_stack(nr::nanosleep, [sleep, 0, 0, 0, 0, 0]);
    assert!(g.serve(sender, nanosleep).is_empty());
    g.host.now += 100_000_000_000;
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    for pid in [sender, other, 1] {
        assert!(g.host.selected.contains(&pid), "{pid} served again");
    }
    assert_eq!(
        g.system.state(sender),
        Some(State::Running),
        "its sleep ended"
    );
    assert!(matches!(g.system.state(other), Some(State::Blocked(_))));
}

/// A call that waits changed nothing: no other waiting call is served again for it, nor
/// the calls waiting on its own socket (its own included).
#[test]
fn a_call_that_waits_serves_no_waiting_call_again() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let (reader, piper, sender) = (g.fork(1), g.fork(1), g.fork(1));
    let status = SCRATCH + 0x100;
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]), None);
    let socket = bound_socket(&mut g, reader, 2, 7001);
    let thread = 0x3d0f00; // pthread_create's clone
    let tid = g.call(
        reader,
        nr::clone,
        [
            thread,
            SCRATCH + 0x800,
            SCRATCH + 0x10,
            SCRATCH + 0x14,
            0,
            0,
        ],
    );
    let second = u32::try_from(tid.unwrap()).unwrap();
    let _ = g
        .system
        .serve(second, &mut g.fs, &mut g.host, ExceptionMessage::default());
    let buf = SCRATCH + 0x400;
    assert_eq!(
        g.call(reader, nr::recvfrom, [socket, buf, 64, 0, 0, 0]),
        None
    );
    assert_eq!(g.call(piper, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let r = g.word(piper, SCRATCH) as u64;
    let before = g.system.served_again;
    g.host.selected.clear();
    // A read of an empty pipe (another process's table's call) and a second wait on the
    // same socket.
    assert_eq!(g.call(piper, nr::read, [r, buf, 16, 0, 0, 0]), None);
    assert!(
        !g.host.selected.contains(&1) && !g.host.selected.contains(&reader),
        "init's wait4 and the reader stay as they are"
    );
    g.host.selected.clear();
    assert_eq!(
        g.call(second, nr::recvfrom, [socket, buf, 64, 0, 0, 0]),
        None
    );
    assert!(
        !g.host.selected.contains(&reader),
        "the first reader is not served again"
    );
    assert_eq!(g.system.served_again, before);
    // A datagram for the socket still serves its waiting calls.
    g.put(sender, SCRATCH + 0x300, &loopback(7001));
    assert_eq!(send_ping(&mut g, sender, SCRATCH + 0x300), Some(4));
    assert!(g.system.served_again > before);
    assert_eq!(
        g.system.state(reader),
        Some(State::Running),
        "its recvfrom finished"
    );
}

/// A blocking write that moved part of its bytes into a pipe before it had to wait
/// changed the pipe: the reader waiting on it is served and reads, and the writer goes on
/// as the reader makes room.
#[test]
fn a_write_that_waits_after_filling_a_pipe_serves_its_reader() {
    use crate::pipe::PIPE_CAPACITY;
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    assert_eq!(g.call(1, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let (r, w) = (g.word(1, SCRATCH) as u64, g.word(1, SCRATCH + 4) as u64);
    let reader = g.fork(1);
    let buf = SCRATCH + 0x100;
    assert_eq!(g.call(reader, nr::read, [r, buf, 16, 0, 0, 0]), None);
    let total = (PIPE_CAPACITY + 4096) as u64;
    let data = g
        .call(1, nr::mmap, [0, total, 3, 0x22, u64::MAX, 0])
        .unwrap();
    g.put(1, data, b"first");
    let replies = g.serve(1, World::message(nr::write, [w, data, total, 0, 0, 0], 0));
    assert_eq!(replies, [(reader, 16)], "the reader took the first bytes");
    assert_eq!(g.get(reader, buf, 5), b"first");
    // The reader drains the pipe; the writer's last bytes go in and its write returns.
    let mut finished = false;
    for _ in 0..32 {
        let replies = g.serve(reader, World::message(nr::read, [r, buf, 3000, 0, 0, 0], 0));
        if replies.contains(&(1, total)) {
            finished = true;
            break;
        }
    }
    assert!(finished, "the whole write returned");
}

/// A thread waiting on a socket is served again when the socket changes: what it waits
/// on is read in its process's descriptor table (the first thread's).
#[test]
fn a_thread_waiting_on_a_socket_is_served_when_it_changes() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let flags = 0x3d0f00; // pthread_create's clone
    let tid = g.call(
        1,
        nr::clone,
        [flags, SCRATCH + 0x800, SCRATCH + 0x10, SCRATCH + 0x14, 0, 0],
    );
    let thread = u32::try_from(tid.unwrap()).unwrap();
    let _ = g
        .system
        .serve(thread, &mut g.fs, &mut g.host, ExceptionMessage::default());
    // The thread's memory is its process's: init sends to the address it bound.
    let u = bound_socket(&mut g, thread, 2, 7001);
    let buf = SCRATCH + 0x400;
    assert_eq!(g.call(thread, nr::recvfrom, [u, buf, 64, 0, 0, 0]), None);
    assert_eq!(send_ping(&mut g, 1, BOUND_ADDR), Some(4));
    assert_eq!(
        g.system.state(thread),
        Some(State::Running),
        "its recvfrom finished"
    );
}

#[test]
fn fork_copies_the_process_and_wait_reaps_it() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    g.put(1, SCRATCH, b"parent");
    let child = g.fork(1);
    assert_eq!(child, 2);
    assert_eq!(g.system.process(2).unwrap().ppid, 1);
    assert_eq!(g.call(2, nr::getppid, [0; 6]), Some(1));
    // A copy: the child's writes stay its own.
    assert_eq!(g.get(2, SCRATCH, 6), b"parent");
    g.put(2, SCRATCH, b"child!");
    assert_eq!(g.get(1, SCRATCH, 6), b"parent");
    let status = SCRATCH + 0x100;
    assert_eq!(
        g.call(1, nr::wait4, [u64::MAX, status, WNOHANG, 0, 0, 0]),
        Some(0)
    );
    // A blocking wait4 defers init's reply: the child goes on meanwhile.
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]), None);
    assert!(matches!(g.system.state(1), Some(State::Blocked(_))));
    assert_eq!(g.call(2, nr::getpid, [0; 6]), Some(2));
    // The child's exit answers the wait: its pid, exit code << 8, and it is gone.
    assert_eq!(
        g.serve(2, World::message(nr::exit_group, [3, 0, 0, 0, 0, 0], 0)),
        [(1, 2)]
    );
    assert_eq!(g.word(1, status), 3 << 8);
    assert_eq!(g.pids(), [1]);
    assert_eq!(g.host.released, [2]);
    assert_eq!(
        g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]),
        Some(err(Errno::ECHILD))
    );
    // vfork: a fork whose parent waits until the child ends or executes.
    assert_eq!(g.call(1, nr::vfork, [0; 6]), None);
    assert!(matches!(
        g.system.state(1),
        Some(State::Vforked { child: 3, .. })
    ));
    let fault = ExceptionMessage::default();
    assert_eq!(g.serve(3, fault), [(3, 0)]);
    // It runs in its parent's memory: what it writes, the parent sees.
    g.put(3, SCRATCH + 0xf00, b"shared");
    assert_eq!(g.get(1, SCRATCH + 0xf00, 6), b"shared");
    assert_eq!(g.serve(3, World::message(nr::exit, [0; 6], 0)), [(1, 3)]);
    assert_eq!(g.system.state(3), Some(State::Zombie(0)), "not reaped yet");
    // clone(CLONE_VM | CLONE_VFORK): the same; the child's execve lets the parent go on.
    assert_eq!(g.call(1, nr::clone, [0x4111, 0, 0, 0, 0, 0]), None);
    assert_eq!(g.serve(4, fault), [(4, 0)]);
    g.put(4, SCRATCH + 0xe00, b"/bin/sh\0");
    let argv = put_strings(&mut g, 4, SCRATCH + 0x400, &["sh"]);
    let execve = World::message(nr::execve, [SCRATCH + 0xe00, argv, 0, 0, 0, 0], 0);
    // The child leaves its parent's memory for a task of its own, whose new thread reports
    // first; the parent goes on at once.
    assert_eq!(g.serve(4, execve), [(1, 4)]);
    assert!(matches!(g.system.state(4), Some(State::Starting(_))));
    g.host.resumed.clear();
    let _ = g.system.serve(4, &mut g.fs, &mut g.host, fault);
    assert_eq!(g.host.resumed[0].1.registers.rip, 0x40_1010, "its entry");
    assert_eq!(
        g.get(1, SCRATCH + 0xf00, 6),
        b"shared",
        "the parent's memory stays"
    );
    // A thread shares memory, descriptors and dispositions, or is refused.
    assert_eq!(
        g.call(1, nr::clone, [0x10100, 0, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
    // A child's exit before anyone waits left a zombie, reaped by pid.
    assert_eq!(g.call(1, nr::wait4, [3, status, WNOHANG, 0, 0, 0]), Some(3));
    assert_eq!(
        g.call(1, nr::wait4, [3, status, WNOHANG, 0, 0, 0]),
        Some(err(Errno::ECHILD))
    );
    assert_eq!(g.pids(), [1, 4]);
    // A parent that ignores SIGCHLD has no zombies: wait4 waits until no child is left.
    g.put(1, SCRATCH + 0x600, &[1, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(
        g.call(1, nr::rt_sigaction, [17, SCRATCH + 0x600, 0, 8, 0, 0]),
        Some(0)
    );
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, 0, 0, 0, 0, 0]), None);
    assert_eq!(
        g.serve(4, World::message(nr::exit, [0; 6], 0)),
        [(1, err(Errno::ECHILD))]
    );
    assert_eq!(g.pids(), [1]);
}

#[test]
fn orphans_go_to_init_killed_children_report_their_signal_and_the_table_is_bounded() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    let grandchild = g.fork(child);
    assert_eq!(g.system.process(grandchild).unwrap().ppid, child);
    // As the log's `guest: left:` lines say them.
    let described = |g: &Guest, pid| g.system.describe(pid).map(|d| d.to_string());
    assert_eq!(described(&g, 99), None);
    assert_eq!(
        described(&g, child).as_deref(),
        Some(format!("{child} (busybox) running").as_str())
    );
    let _ = g.serve(child, World::message(nr::exit_group, [0; 6], 0));
    assert_eq!(
        described(&g, child).as_deref(),
        Some(format!("{child} (busybox) zombie 0x0").as_str())
    );
    assert_eq!(g.system.process(grandchild).unwrap().ppid, 1, "re-parented");
    let status = SCRATCH + 0x100;
    assert_eq!(
        g.call(1, nr::wait4, [child as u64, status, 0, 0, 0, 0]),
        Some(child as u64)
    );
    // A fault kills the grandchild: its wait status is the signal number.
    let fault = ExceptionMessage {
        vector: 14,
        fault_address: 0xdead_0000,
        ..Default::default()
    };
    assert_eq!(g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]), None);
    assert_eq!(g.serve(grandchild, fault), [(1, grandchild as u64)]);
    assert_eq!(g.word(1, status), 11);
    // At most MAX_PROCESSES processes, zombies included: then EAGAIN, and nothing broke.
    for _ in 1..MAX_PROCESSES {
        g.fork(1);
    }
    assert_eq!(g.call(1, nr::fork, [0; 6]), Some(err(Errno::EAGAIN)));
    assert_eq!(g.pids().len(), MAX_PROCESSES);
    let refused = |g: &Guest| {
        g.host
            .log
            .iter()
            .filter(|l| l.starts_with("guest: fork by 1 (busybox) refused: no task"))
            .count()
    };
    assert_eq!(
        refused(&g),
        1,
        "the refusal is logged: {:?}",
        g.host.log.last()
    );
    for _ in 0..2 * crate::system::REFUSALS_LOGGED {
        assert_eq!(g.call(1, nr::fork, [0; 6]), Some(err(Errno::EAGAIN)));
    }
    assert_eq!(
        refused(&g),
        crate::system::REFUSALS_LOGGED as usize,
        "the first few only"
    );
    let budget = g.host.budget;
    for pid in g.pids().into_iter().skip(1) {
        let _ = g.serve(pid, World::message(nr::exit_group, [0; 6], 0));
    }
    assert!(g.host.budget > budget, "the children's memory came back");
    for _ in 1..MAX_PROCESSES {
        assert!(g.call(1, nr::wait4, [u64::MAX, 0, 0, 0, 0, 0]).unwrap() > 1);
    }
    assert_eq!(g.pids(), [1]);
    // Out of memory: the fork fails with ENOMEM, no child is left.
    g.host.budget = 0;
    assert_eq!(g.call(1, nr::fork, [0; 6]), Some(err(Errno::ENOMEM)));
    assert_eq!(g.pids(), [1]);
}

#[test]
fn event_descriptors_wake_waiters_are_shared_by_fork_and_go_with_their_last_descriptor() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let efd = g.call(1, nr::eventfd2, [0, 0, 0, 0, 0, 0]).unwrap();
    let ep = g.call(1, nr::epoll_create1, [0, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!((efd, ep), (3, 4));
    assert_eq!(
        g.call(1, nr::epoll_create1, [1, 0, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
    // struct epoll_event, packed: EPOLLIN and the data word.
    let mut event = [0u8; 12];
    event[..4].copy_from_slice(&1u32.to_le_bytes());
    event[4..].copy_from_slice(&0xfeed_u64.to_le_bytes());
    g.put(1, SCRATCH, &event);
    assert_eq!(
        g.call(1, nr::epoll_ctl, [ep, 1, efd, SCRATCH, 0, 0]),
        Some(0)
    );
    assert_eq!(
        g.call(1, nr::epoll_ctl, [ep, 1, efd, SCRATCH, 0, 0]),
        Some(err(Errno::EEXIST))
    );
    assert_eq!(
        g.call(1, nr::epoll_wait, [ep, SCRATCH + 0x100, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL)),
        "maxevents 0"
    );
    let child = g.fork(1);
    // The parent waits forever; the child's write (to the counter fork shared) ends it.
    let out = SCRATCH + 0x100;
    assert_eq!(
        g.call(1, nr::epoll_wait, [ep, out, 8, u64::MAX, 0, 0]),
        None
    );
    g.put(child, SCRATCH + 0x200, &5u64.to_le_bytes());
    let replies = g.serve(
        child,
        World::message(nr::write, [efd, SCRATCH + 0x200, 8, 0, 0, 0], 0),
    );
    assert_eq!(replies, [(child, 8), (1, 1)]);
    assert_eq!(g.get(1, out, 12), event);
    // A short read is EINVAL; a read takes the count.
    assert_eq!(
        g.call(1, nr::read, [efd, SCRATCH + 0x300, 4, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
    assert_eq!(
        g.call(1, nr::read, [efd, SCRATCH + 0x300, 8, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(g.word(1, SCRATCH + 0x300), 5);
    // A blocked read of an empty counter waits for the write.
    assert_eq!(
        g.call(1, nr::read, [efd, SCRATCH + 0x300, 8, 0, 0, 0]),
        None
    );
    let replies = g.serve(
        child,
        World::message(nr::write, [efd, SCRATCH + 0x200, 8, 0, 0, 0], 0),
    );
    assert_eq!(replies, [(child, 8), (1, 8)]);
    // A timer: the guest's next timer is its expiry while a read of it waits.
    let tfd = g.call(1, nr::timerfd_create, [1, 0, 0, 0, 0, 0]).unwrap();
    let mut spec = [0u8; 32];
    spec[16..24].copy_from_slice(&1000u64.to_le_bytes()); // it_value: 1000 s
    g.put(1, SCRATCH + 0x400, &spec);
    assert_eq!(
        g.call(1, nr::timerfd_settime, [tfd, 0, SCRATCH + 0x400, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(
        g.call(1, nr::read, [tfd, SCRATCH + 0x300, 8, 0, 0, 0]),
        None
    );
    let due = g.system.next_timer().expect("the timer wakes the guest");
    g.host.now = due;
    g.host.resumed.clear();
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    assert!(
        g.host
            .resumed
            .iter()
            .any(|(pid, m)| *pid == 1 && m.registers.rax == 8)
    );
    assert_eq!(g.word(1, SCRATCH + 0x300), 1, "one expiration");
    // The child's copies go when it ends; the parent's close frees them and the counter
    // leaves the interest list.
    g.serve(child, World::message(nr::exit_group, [0; 6], 0));
    assert_eq!(g.system.events.open_count(), 3);
    assert_eq!(g.call(1, nr::close, [efd, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::close, [tfd, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.system.events.open_count(), 1);
    assert_eq!(
        g.call(1, nr::epoll_wait, [ep, out, 8, 0, 0, 0]),
        Some(0),
        "the closed counter left the list"
    );
    assert_eq!(g.call(1, nr::close, [ep, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.system.events.open_count(), 0);
}

#[test]
fn pipes_block_readers_until_data_or_end_of_file_and_kill_writers_without_readers() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    assert_eq!(g.call(1, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let (r, w) = (g.word(1, SCRATCH) as u64, g.word(1, SCRATCH + 4) as u64);
    assert_eq!((r, w), (3, 4));
    let child = g.fork(1);
    assert_eq!(g.call(1, nr::close, [w, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(child, nr::close, [r, 0, 0, 0, 0, 0]), Some(0));
    // The reader waits; the writer's write answers both.
    let buf = SCRATCH + 0x200;
    assert_eq!(g.call(1, nr::read, [r, buf, 100, 0, 0, 0]), None);
    g.put(child, SCRATCH + 0x300, b"hi");
    let replies = g.serve(
        child,
        World::message(nr::write, [w, SCRATCH + 0x300, 2, 0, 0, 0], 0),
    );
    assert_eq!(replies, [(child, 2), (1, 2)]);
    assert_eq!(g.get(1, buf, 2), b"hi");
    // dup2 onto stdout and F_DUPFD: more writers; the reader sees end of file only when
    // the last one closes.
    assert_eq!(g.call(child, nr::dup2, [w, 1, 0, 0, 0, 0]), Some(1));
    assert_eq!(g.call(child, nr::fcntl, [w, 1030, 10, 0, 0, 0]), Some(10));
    assert_eq!(
        g.call(child, nr::fcntl, [10, 1, 0, 0, 0, 0]),
        Some(1),
        "FD_CLOEXEC"
    );
    assert_eq!(
        g.call(child, nr::fcntl, [1, 3, 0, 0, 0, 0]),
        Some(1),
        "O_WRONLY"
    );
    assert_eq!(g.call(1, nr::read, [r, buf, 100, 0, 0, 0]), None);
    for fd in [w, 10] {
        assert_eq!(g.call(child, nr::close, [fd, 0, 0, 0, 0, 0]), Some(0));
    }
    assert!(matches!(g.system.state(1), Some(State::Blocked(_))));
    assert_eq!(
        g.serve(child, World::message(nr::close, [1, 0, 0, 0, 0, 0], 0)),
        [(child, 0), (1, 0)]
    );
    // Writing to a pipe nobody reads kills the writer with SIGPIPE.
    assert_eq!(g.call(child, nr::pipe, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let (r2, w2) = (
        g.word(child, SCRATCH) as u64,
        g.word(child, SCRATCH + 4) as u64,
    );
    assert_eq!(g.call(child, nr::close, [r2, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(child, nr::write, [w2, SCRATCH, 1, 0, 0, 0]), None);
    assert_eq!(g.system.state(child), Some(State::Zombie(13)));
    assert!(
        g.host
            .log
            .last()
            .unwrap()
            .contains("killed by signal 13 (SIGPIPE)")
    );
    assert_eq!(
        g.system.pipes.open_count(),
        1,
        "the child's ends closed when it ended"
    );
    assert_eq!(g.call(1, nr::close, [r, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.system.pipes.open_count(), 0);
    // O_NONBLOCK: EAGAIN instead of waiting, until F_SETFL clears it.
    let o_nonblock = 0o4000;
    assert_eq!(
        g.call(1, nr::pipe2, [SCRATCH, o_nonblock, 0, 0, 0, 0]),
        Some(0)
    );
    let r = g.word(1, SCRATCH) as u64;
    assert_eq!(g.call(1, nr::fcntl, [r, 3, 0, 0, 0, 0]), Some(o_nonblock));
    assert_eq!(
        g.call(1, nr::read, [r, buf, 1, 0, 0, 0]),
        Some(err(Errno::EAGAIN))
    );
    assert_eq!(g.call(1, nr::fcntl, [r, 4, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::fcntl, [r, 3, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::read, [r, buf, 1, 0, 0, 0]), None, "waits");
}

/// Puts `strings` as a NULL-terminated pointer array with its strings at `at`.
fn put_strings(g: &mut Guest, pid: u32, at: u64, strings: &[&str]) -> u64 {
    let mut text = at + 0x100;
    let mut pointers = Vec::new();
    for s in strings {
        let mut b = s.as_bytes().to_vec();
        b.push(0);
        g.put(pid, text, &b);
        pointers.extend_from_slice(&text.to_le_bytes());
        text += b.len() as u64;
    }
    pointers.extend_from_slice(&0u64.to_le_bytes());
    g.put(pid, at, &pointers);
    at
}

#[test]
fn execve_replaces_the_image_keeps_the_files_and_closes_close_on_exec() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    g.put(1, SCRATCH + 0xf00, b"/etc/passwd\0");
    let passwd = SCRATCH + 0xf00;
    assert_eq!(
        g.call(1, nr::open, [passwd, 0o2000000, 0, 0, 0, 0]),
        Some(3)
    );
    assert_eq!(g.call(1, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let argv = put_strings(&mut g, 1, SCRATCH + 0x400, &["sh", "-c", "x"]);
    let envp = put_strings(&mut g, 1, SCRATCH + 0x800, &["A=1"]);
    g.put(1, SCRATCH + 0xe00, b"/nothing\0");
    assert_eq!(
        g.call(1, nr::execve, [SCRATCH + 0xe00, argv, envp, 0, 0, 0]),
        Some(err(Errno::ENOENT))
    );
    assert_eq!(
        g.call(1, nr::execve, [passwd, argv, envp, 0, 0, 0]),
        Some(err(Errno::EACCES)),
        "no execute permission"
    );
    g.put(1, SCRATCH + 0xe00, b"/bin/sh\0");
    g.host.resumed.clear();
    let _ = g.system.serve(
        1,
        &mut g.fs,
        &mut g.host,
        World::message(nr::execve, [SCRATCH + 0xe00, argv, envp, 0, 0, 0], 0),
    );
    let (pid, m) = g.host.resumed[0];
    assert_eq!(pid, 1);
    assert_eq!(m.registers.rip, 0x40_1010, "the new image's entry");
    assert!(m.registers.rsp < STACK_TOP && m.registers.rsp > STACK_TOP - 0x1000);
    assert_eq!((m.registers.rax, m.registers.fs_base), (0, 0));
    assert_eq!(
        g.host.log.last().unwrap(),
        "guest: process 1 (busybox) started: sh -c x"
    );
    let p = g.system.process(1).unwrap();
    assert!(p.files[3].is_none(), "close-on-exec");
    assert!(
        p.files[4].is_some() && p.files[5].is_some(),
        "the pipe stays open"
    );
    assert!(
        p.areas.find(SCRATCH).is_none(),
        "the old image's memory is gone"
    );
    assert_eq!(g.system.pipes.open_count(), 1);
    // A `#!` script runs its interpreter with its argument and the script's path.
    assert_eq!(
        g.call(1, nr::mmap, [SCRATCH, PAGE, 3, 0x32, u64::MAX, 0]),
        Some(SCRATCH)
    );
    g.put(1, SCRATCH + 0xe00, b"/etc/script\0");
    let argv = put_strings(&mut g, 1, SCRATCH + 0x400, &["script", "arg"]);
    let _ = g.serve(
        1,
        World::message(nr::execve, [SCRATCH + 0xe00, argv, 0, 0, 0, 0], 0),
    );
    assert_eq!(
        g.host.log.last().unwrap(),
        "guest: process 1 (busybox) started: /bin/sh -e /etc/script arg"
    );
}

/// Random calls of random processes (forks, waits, pipes, execs among them) with edge
/// arguments never panic, and the table stays consistent: every parent is in it, pipe ends
/// are counted right (all pipes close with the processes).
#[test]
fn random_process_calls_never_panic() {
    let bytes = initramfs();
    for round in 0..100 {
        random_process_calls(&bytes, 0x9e37_79b9_7f4a_7c15 ^ round);
    }
}

fn random_process_calls(bytes: &[u8], mut seed: u64) {
    let mut g = Guest::new(bytes);
    let argv = put_strings(&mut g, 1, SCRATCH + 0x400, &["sh"]);
    g.put(1, SCRATCH + 0xe00, b"/bin/sh\0");
    let calls = [
        nr::fork,
        nr::vfork,
        nr::clone,
        nr::wait4,
        nr::pipe2,
        nr::pipe,
        nr::dup,
        nr::dup2,
        nr::dup3,
        nr::close,
        nr::read,
        nr::write,
        nr::fcntl,
        nr::execve,
        nr::exit,
        nr::getpid,
    ];
    let edges = [
        0,
        1,
        3,
        4,
        5,
        63,
        64,
        u64::MAX,
        SCRATCH,
        SCRATCH + 0xe00,
        argv,
        0x4111,
        0x11,
        1030,
        u64::MAX - 7,
    ];
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for _ in 0..2_000 {
        let pids: Vec<u32> = g
            .pids()
            .into_iter()
            .filter(|&p| matches!(g.system.state(p), Some(State::Running | State::Starting(_))))
            .collect();
        if pids.is_empty() {
            break; // they all wait on each other, as processes can
        }
        let pid = pids[(next() % pids.len() as u64) as usize];
        let m = match g.system.state(pid) {
            Some(State::Starting(_)) => ExceptionMessage::default(),
            Some(State::Running) => {
                let number = calls[(next() % calls.len() as u64) as usize];
                // init's end would end the guest: it does not exit.
                if pid == 1 && number == nr::exit {
                    continue;
                }
                let mut a = [0u64; 6];
                for x in &mut a {
                    *x = edges[(next() % edges.len() as u64) as usize];
                }
                World::message(number, a, 0)
            }
            _ => continue,
        };
        g.host.resumed.clear();
        if g.system.serve(pid, &mut g.fs, &mut g.host, m).is_some() {
            return; // init died (SIGPIPE, a failed execve): the guest ends
        }
        let pids = g.pids();
        for &p in &pids {
            let ppid = g.system.process(p).unwrap().ppid;
            assert!(p == 1 || pids.contains(&ppid), "{p}'s parent {ppid}");
        }
    }
    let mut end = g.host.released.len();
    for pid in g.pids().into_iter().skip(1) {
        if g.system.state(pid) == Some(State::Running) {
            let _ = g.serve(pid, World::message(nr::exit, [0; 6], 0));
            end += 1;
        }
    }
    assert!(g.host.released.len() >= end);
    let _ = g.call(1, nr::close_range, [0, u32::MAX as u64, 0, 0, 0, 0]);
    let blocked_or_starting = g
        .pids()
        .into_iter()
        .any(|p| !matches!(g.system.state(p), Some(State::Running | State::Zombie(_))));
    if !blocked_or_starting {
        assert_eq!(g.system.pipes.open_count(), 0, "every pipe end was closed");
    }
}

/// A system call of `pid` whose stack pointer is the top of the scratch page (room for a
/// signal frame).
fn on_stack(number: u64, a: [u64; 6]) -> ExceptionMessage {
    let mut m = World::message(number, a, 0);
    m.registers.rsp = SCRATCH + PAGE;
    m
}

const HANDLER: u64 = 0x40_2000;
const RESTORER: u64 = 0x40_3000;

/// Installs a handler for `signal` in `pid` with `flags` (`SA_RESTORER` added).
fn catch(g: &mut Guest, pid: u32, signal: u32, flags: u64) {
    let action = crate::signal::Action {
        handler: HANDLER,
        flags: flags | crate::signal::SA_RESTORER,
        restorer: RESTORER,
        mask: 0,
    };
    g.put(pid, SCRATCH + 0x100, &action.to_bytes());
    assert_eq!(
        g.call(
            pid,
            nr::rt_sigaction,
            [signal as u64, SCRATCH + 0x100, 0, 8, 0, 0]
        ),
        Some(0)
    );
}

/// The handler's `rt_sigreturn` (its `ret` popped the restorer address): the registers the
/// process resumes with.
fn sigreturn(g: &mut Guest, pid: u32, frame: u64) -> ExceptionMessage {
    let mut m = World::message(nr::rt_sigreturn, [0; 6], 0);
    m.registers.rsp = frame + 8;
    g.host.resumed.clear();
    assert_eq!(g.system.serve(pid, &mut g.fs, &mut g.host, m), None);
    let (p, m) = g.host.resumed[0];
    assert_eq!(p, pid);
    m
}

#[test]
fn a_caught_signal_runs_its_handler_on_a_frame_and_returns() {
    use crate::signal::{SA_SIGINFO, SIGUSR1};
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    catch(&mut g, child, SIGUSR1, SA_SIGINFO);
    // The child runs user code: the signal waits for its next system call.
    assert_eq!(
        g.call(1, nr::kill, [child as u64, SIGUSR1 as u64, 0, 0, 0, 0]),
        Some(0)
    );
    g.host.fpu.insert(child, [0x22; 512]);
    g.host.resumed.clear();
    let _ = g
        .system
        .serve(child, &mut g.fs, &mut g.host, on_stack(nr::getpid, [0; 6]));
    let (pid, m) = g.host.resumed[0];
    let r = m.registers;
    assert_eq!((pid, r.rip, r.rdi), (child, HANDLER, SIGUSR1 as u64));
    assert_eq!((r.rsp + 8) % 16, 0);
    assert!(r.rsp < SCRATCH + PAGE - 128 - 512);
    assert_eq!(g.get(child, r.rsp, 8), RESTORER.to_le_bytes());
    // siginfo: the signal and the sender.
    assert_eq!(g.word(child, r.rsi), SIGUSR1);
    assert_eq!(g.word(child, r.rsi + 16), 1);
    // The handler changes its FPU state; rt_sigreturn brings the saved one back, with the
    // registers of the interrupted call (its result in rax) and the mask.
    g.host.fpu.insert(child, [0x33; 512]);
    let back = sigreturn(&mut g, child, r.rsp);
    assert_eq!(back.registers.rax, child as u64);
    assert_eq!(back.registers.rip, 0x40_1019);
    assert_eq!(back.registers.rsp, SCRATCH + PAGE);
    assert_eq!(g.host.fpu[&child], [0x22; 512]);
    assert_eq!(g.system.process(child).unwrap().sigmask, 0);
}

#[test]
fn default_actions_end_stop_and_continue_processes() {
    use crate::signal::{SIGCONT, SIGSTOP, SIGTERM, SIGWINCH};
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    // Ignored by default: nothing happens.
    assert_eq!(
        g.call(1, nr::kill, [child as u64, SIGWINCH as u64, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.system.state(child), Some(State::Running));
    // Stop: its thread is suspended; the parent sees it with WUNTRACED, once.
    assert_eq!(
        g.call(1, nr::kill, [child as u64, SIGSTOP as u64, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.host.suspended, [child]);
    let wuntraced = 2;
    assert_eq!(
        g.call(
            1,
            nr::wait4,
            [child as u64, SCRATCH, wuntraced | WNOHANG, 0, 0, 0]
        ),
        Some(child as u64)
    );
    assert_eq!(g.word(1, SCRATCH), 0x7f | SIGSTOP << 8);
    assert_eq!(
        g.call(
            1,
            nr::wait4,
            [child as u64, SCRATCH, wuntraced | WNOHANG, 0, 0, 0]
        ),
        Some(0)
    );
    // Continue: resumed, reported with WCONTINUED.
    assert_eq!(
        g.call(1, nr::kill, [child as u64, SIGCONT as u64, 0, 0, 0, 0]),
        Some(0)
    );
    assert!(g.host.suspended.is_empty());
    assert_eq!(
        g.call(1, nr::wait4, [child as u64, SCRATCH, 8 | WNOHANG, 0, 0, 0]),
        Some(child as u64)
    );
    assert_eq!(g.word(1, SCRATCH), 0xffff);
    // Terminate: the running child ends at once; its status is the signal.
    assert_eq!(
        g.call(1, nr::kill, [child as u64, SIGTERM as u64, 0, 0, 0, 0]),
        Some(0)
    );
    assert!(g.host.released.contains(&child));
    assert!(
        g.host
            .log
            .last()
            .unwrap()
            .contains("killed by signal 15 (SIGTERM)")
    );
    assert_eq!(
        g.call(1, nr::wait4, [u64::MAX, SCRATCH, 0, 0, 0, 0]),
        Some(child as u64)
    );
    assert_eq!(g.word(1, SCRATCH), SIGTERM);
    // Init is protected from signals it does not catch; unknown targets are ESRCH.
    assert_eq!(
        g.call(1, nr::kill, [1, SIGTERM as u64, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.system.state(1), Some(State::Running));
    assert_eq!(
        g.call(1, nr::kill, [99, 0, 0, 0, 0, 0]),
        Some(err(Errno::ESRCH))
    );
    assert_eq!(
        g.call(1, nr::kill, [1, 65, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
}

#[test]
fn signals_interrupt_waiting_calls_or_restart_them() {
    use crate::signal::{SA_RESTART, SIGUSR1, SIGUSR2};
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    assert_eq!(g.call(1, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let r = g.word(1, SCRATCH) as u64;
    let child = g.fork(1);
    catch(&mut g, child, SIGUSR1, 0);
    catch(&mut g, child, SIGUSR2, SA_RESTART);
    // A read from the empty pipe waits; SIGUSR1 (no SA_RESTART) ends it with EINTR after
    // the handler.
    let read = on_stack(nr::read, [r, SCRATCH + 0x200, 10, 0, 0, 0]);
    assert!(g.serve(child, read).is_empty());
    let replies = g.serve(
        1,
        World::message(nr::kill, [child as u64, SIGUSR1 as u64, 0, 0, 0, 0], 0),
    );
    assert_eq!(replies[0], (1, 0));
    let (_, m) = g.host.resumed[1];
    assert_eq!(m.registers.rip, HANDLER);
    let back = sigreturn(&mut g, child, m.registers.rsp);
    assert_eq!(back.registers.rax, err(Errno::EINTR));
    // With SA_RESTART the thread goes back to its `syscall` instruction.
    assert!(g.serve(child, read).is_empty());
    g.serve(
        1,
        World::message(nr::kill, [child as u64, SIGUSR2 as u64, 0, 0, 0, 0], 0),
    );
    let (_, m) = g.host.resumed[1];
    let back = sigreturn(&mut g, child, m.registers.rsp);
    assert_eq!(
        (back.registers.rax, back.registers.rip),
        (nr::read, 0x40_1017)
    );
    // A signal that ends the process ends a waiting one too.
    assert!(g.serve(child, read).is_empty());
    g.serve(
        1,
        World::message(nr::kill, [child as u64, 9, 0, 0, 0, 0], 0),
    );
    assert_eq!(g.system.state(child), Some(State::Zombie(9)));
}

#[test]
fn sleeps_end_when_their_time_comes_or_with_eintr() {
    use crate::signal::SIGALRM;
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    // 2 s: the model's clock advances 1.5 s per reading.
    g.put(
        child,
        SCRATCH,
        &[2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    );
    assert!(
        g.serve(child, on_stack(nr::nanosleep, [SCRATCH, 0, 0, 0, 0, 0]))
            .is_empty()
    );
    let due = g.system.next_timer().unwrap();
    assert!(due > 0);
    // The main loop ticks once the sleep is due.
    g.host.now = g.host.now.max(due);
    g.host.resumed.clear();
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    assert_eq!(g.host.resumed.len(), 1, "slept long enough");
    assert_eq!(g.host.resumed[0].1.registers.rax, 0);
    // An alarm interrupts a sleep: SIGALRM ends the process by default.
    assert_eq!(g.call(child, nr::alarm, [1, 0, 0, 0, 0, 0]), Some(0));
    g.put(
        child,
        SCRATCH,
        &[100, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    );
    assert!(
        g.serve(child, on_stack(nr::nanosleep, [SCRATCH, 0, 0, 0, 0, 0]))
            .is_empty()
    );
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    assert_eq!(g.system.state(child), Some(State::Zombie(SIGALRM)));
    // Bad times are EINVAL.
    g.put(
        1,
        SCRATCH,
        &[0, 0, 0, 0, 0, 0, 0, 0, 0, 0xca, 0x9a, 0x3b, 0, 0, 0, 0],
    );
    assert_eq!(
        g.call(1, nr::nanosleep, [SCRATCH, 0, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
}

#[test]
fn process_groups_sessions_and_group_signals() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let a = g.fork(1);
    let b = g.fork(1);
    assert_eq!(g.call(a, nr::getpgrp, [0; 6]), Some(1));
    // A new group led by a; b joins it (its parent moves it).
    assert_eq!(g.call(a, nr::setpgid, [0, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(
        g.call(1, nr::setpgid, [b as u64, a as u64, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.call(b, nr::getpgid, [0; 6]), Some(a as u64));
    assert_eq!(
        g.call(1, nr::setpgid, [b as u64, 77, 0, 0, 0, 0]),
        Some(err(Errno::EPERM))
    );
    assert_eq!(
        g.call(a, nr::setpgid, [1, 0, 0, 0, 0, 0]),
        Some(err(Errno::ESRCH))
    );
    // A group leader cannot start a session; b can.
    assert_eq!(g.call(a, nr::setsid, [0; 6]), Some(err(Errno::EPERM)));
    assert_eq!(g.call(b, nr::setsid, [0; 6]), Some(b as u64));
    assert_eq!(
        g.call(1, nr::getsid, [b as u64, 0, 0, 0, 0, 0]),
        Some(b as u64)
    );
    assert_eq!(
        g.call(1, nr::setpgid, [b as u64, 0, 0, 0, 0, 0]),
        Some(err(Errno::EPERM))
    );
    // kill(-pgid) reaches the group.
    assert_eq!(
        g.call(1, nr::kill, [(-(a as i64)) as u64, 15, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.system.state(a), Some(State::Zombie(15)));
    assert_eq!(g.system.state(b), Some(State::Running));
    // waitid reports the child as a siginfo.
    assert_eq!(
        g.call(1, nr::waitid, [1, a as u64, SCRATCH, 4, 0, 0]),
        Some(0)
    );
    assert_eq!(g.word(1, SCRATCH), crate::signal::SIGCHLD);
    assert_eq!(g.word(1, SCRATCH + 8), crate::signal::CLD_KILLED as u32);
    assert_eq!(g.word(1, SCRATCH + 16), a);
    assert_eq!(g.word(1, SCRATCH + 24), 15);
}

#[test]
fn a_fault_goes_to_its_handler_with_the_address() {
    use crate::signal::{SA_SIGINFO, SIGSEGV};
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    catch(&mut g, child, SIGSEGV, SA_SIGINFO);
    let mut m = on_stack(0, [0; 6]);
    (m.vector, m.error_code, m.fault_address) = (14, 6, 0xdead_0000);
    g.host.resumed.clear();
    let _ = g.system.serve(child, &mut g.fs, &mut g.host, m);
    let (_, r) = g.host.resumed[0];
    assert_eq!(r.registers.rip, HANDLER);
    let info = r.registers.rsi;
    assert_eq!(g.word(child, info + 8), crate::signal::SEGV_MAPERR as u32);
    assert_eq!(g.get(child, info + 16, 8), 0xdead_0000u64.to_le_bytes());
    // While the handler runs SIGSEGV is blocked: a second fault kills.
    let _ = g.system.serve(child, &mut g.fs, &mut g.host, m);
    assert_eq!(g.system.state(child), Some(State::Zombie(SIGSEGV)));
}

#[test]
fn poll_and_select_wait_for_a_pipe_or_their_timeout() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    assert_eq!(g.call(1, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    let (r, w) = (g.word(1, SCRATCH) as u64, g.word(1, SCRATCH + 4));
    let child = g.fork(1);
    // pollfd {r, POLLIN}, {w, POLLOUT}: the write end is ready at once.
    let table = |g: &mut Guest, pid: u32| {
        let mut t = Vec::new();
        t.extend_from_slice(&(r as i32).to_le_bytes());
        t.extend_from_slice(&1u16.to_le_bytes());
        t.extend_from_slice(&0u16.to_le_bytes());
        t.extend_from_slice(&(w as i32).to_le_bytes());
        t.extend_from_slice(&4u16.to_le_bytes());
        t.extend_from_slice(&0u16.to_le_bytes());
        g.put(pid, SCRATCH + 0x400, &t);
    };
    table(&mut g, child);
    assert_eq!(
        g.call(child, nr::poll, [SCRATCH + 0x400, 2, 0, 0, 0, 0]),
        Some(1)
    );
    assert_eq!(g.get(child, SCRATCH + 0x406, 2), 0u16.to_le_bytes());
    assert_eq!(g.get(child, SCRATCH + 0x40e, 2), 4u16.to_le_bytes());
    // Only the read end, forever: waits until the parent writes.
    assert_eq!(
        g.call(child, nr::poll, [SCRATCH + 0x400, 1, u64::MAX, 0, 0, 0]),
        None
    );
    g.put(1, SCRATCH + 0x300, b"x");
    let replies = g.serve(
        1,
        World::message(nr::write, [w as u64, SCRATCH + 0x300, 1, 0, 0, 0], 0),
    );
    assert_eq!(replies, [(1, 1), (child, 1)]);
    assert_eq!(g.get(child, SCRATCH + 0x406, 2), 1u16.to_le_bytes());
    // select on the read end: readable; after reading it, a timeout ends it with 0.
    g.put(child, SCRATCH + 0x500, &(1u64 << r).to_le_bytes());
    assert_eq!(
        g.call(child, nr::select, [r + 1, SCRATCH + 0x500, 0, 0, 0, 0]),
        Some(1)
    );
    assert_eq!(
        g.call(child, nr::read, [r, SCRATCH + 0x600, 1, 0, 0, 0]),
        Some(1)
    );
    // (10 s: the model's clock advances 1.5 s per reading.)
    g.put(
        child,
        SCRATCH + 0x510,
        &[10, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    );
    assert_eq!(
        g.call(
            child,
            nr::select,
            [r + 1, SCRATCH + 0x500, 0, 0, SCRATCH + 0x510, 0]
        ),
        None
    );
    g.host.resumed.clear();
    for _ in 0..10 {
        assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    }
    assert_eq!(g.host.resumed.len(), 1);
    assert_eq!(g.host.resumed[0].1.registers.rax, 0);
    assert_eq!(g.get(child, SCRATCH + 0x500, 8), 0u64.to_le_bytes());
    // A closed descriptor: POLLNVAL for poll, EBADF for select.
    g.put(child, SCRATCH + 0x500, &(1u64 << 20).to_le_bytes());
    assert_eq!(
        g.call(child, nr::select, [21, SCRATCH + 0x500, 0, 0, 0, 0]),
        Some(err(Errno::EBADF))
    );
}

#[test]
fn identity_resources_and_futex_of_a_single_threaded_root_process() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    assert_eq!(g.call(1, nr::setuid, [0; 6]), Some(0));
    assert_eq!(
        g.call(1, nr::setuid, [1000, 0, 0, 0, 0, 0]),
        Some(err(Errno::EPERM))
    );
    assert_eq!(
        g.call(1, nr::setresgid, [u64::MAX, 0, u64::MAX, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.call(1, nr::getgroups, [0; 6]), Some(0));
    assert_eq!(
        g.call(1, nr::sched_getaffinity, [0, 128, SCRATCH, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(g.get(1, SCRATCH, 8), 1u64.to_le_bytes());
    assert_eq!(
        g.call(1, nr::getrusage, [5, SCRATCH, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
    assert_eq!(g.call(1, nr::sysinfo, [SCRATCH, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.get(1, SCRATCH + 80, 2), 1u16.to_le_bytes(), "one process");
    assert_eq!(g.get(1, SCRATCH + 32, 8), (100_000 * PAGE).to_le_bytes());
    // A futex wait on a changed word is EAGAIN; on the same word it waits (nobody else can
    // wake it) until its timeout.
    g.put(1, SCRATCH, &7u32.to_le_bytes());
    assert_eq!(
        g.call(1, nr::futex, [SCRATCH, 128, 8, 0, 0, 0]),
        Some(err(Errno::EAGAIN))
    );
    assert_eq!(
        g.call(1, nr::futex, [SCRATCH, 129, 1, 0, 0, 0]),
        Some(0),
        "wake"
    );
    g.put(
        1,
        SCRATCH + 16,
        &[10, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    );
    assert_eq!(
        g.call(1, nr::futex, [SCRATCH, 128, 7, SCRATCH + 16, 0, 0]),
        None
    );
    g.host.resumed.clear();
    for _ in 0..10 {
        assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    }
    assert_eq!(g.host.resumed[0].1.registers.rax, err(Errno::ETIMEDOUT));
}

/// Types `bytes` on the console of `host` (its echo is dropped).
fn type_in(host: &mut Model, bytes: &[u8]) {
    let tty = host.tty.as_mut().unwrap();
    for &b in bytes {
        tty.input(b, &mut |_| {});
    }
}

#[test]
fn the_console_terminal_answers_its_ioctls() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    assert_eq!(
        w.call(nr::read, [0, SCRATCH, 10, 0, 0, 0]),
        0,
        "without a terminal: end of file"
    );
    w.host.tty = Some(Tty::new(1));
    // isatty: TCGETS gives Linux's defaults.
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TCGETS, SCRATCH, 0, 0, 0]),
        0
    );
    let termios = tty::Termios::from_bytes(&w.get(SCRATCH, 36).try_into().unwrap());
    assert_eq!(termios, tty::Termios::default());
    // Raw mode, as a line editor sets it.
    let mut raw = termios;
    raw.lflag &= !(tty::ICANON | tty::ECHO);
    w.put(SCRATCH, &raw.to_bytes());
    assert_eq!(
        w.call(nr::ioctl, [2, tty::ioctl::TCSETSW, SCRATCH, 0, 0, 0]),
        0
    );
    assert_eq!(w.host.tty.as_ref().unwrap().termios(), raw);
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TIOCGWINSZ, SCRATCH, 0, 0, 0]),
        0
    );
    assert_eq!(w.get(SCRATCH, 4), [24, 0, 80, 0]);
    w.put(SCRATCH, &[50, 0, 132, 0, 0, 0, 0, 0]);
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TIOCSWINSZ, SCRATCH, 0, 0, 0]),
        0
    );
    assert_eq!(w.host.tty.as_ref().unwrap().winsize().cols, 132);
    // The foreground process group.
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TIOCGPGRP, SCRATCH, 0, 0, 0]),
        0
    );
    assert_eq!(w.get(SCRATCH, 4), 1u32.to_le_bytes());
    w.put(SCRATCH, &5u32.to_le_bytes());
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TIOCSPGRP, SCRATCH, 0, 0, 0]),
        0
    );
    assert_eq!(w.host.tty.as_ref().unwrap().foreground(), 5);
    w.put(SCRATCH, &(-1i32).to_le_bytes());
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TIOCSPGRP, SCRATCH, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(w.call(nr::ioctl, [0, tty::ioctl::TIOCSCTTY, 0, 0, 0, 0]), 0);
    // Bad requests and addresses.
    assert_eq!(
        w.call(nr::ioctl, [0, 0x1234, SCRATCH, 0, 0, 0]),
        err(Errno::ENOTTY)
    );
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TCGETS, 8, 0, 0, 0]),
        err(Errno::EFAULT)
    );
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::TCFLSH, 7, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    // Reading: waits while there is nothing, then takes the input.
    let (outcome, _) = w.run(nr::read, [0, SCRATCH, 10, 0, 0, 0]);
    assert_eq!(outcome, Outcome::Block);
    type_in(&mut w.host, b"ab");
    assert_eq!(
        w.call(nr::ioctl, [0, tty::ioctl::FIONREAD, SCRATCH + 64, 0, 0, 0]),
        0
    );
    assert_eq!(w.get(SCRATCH + 64, 4), 2u32.to_le_bytes());
    assert_eq!(w.call(nr::read, [0, SCRATCH, 1, 0, 0, 0]), 1);
    assert_eq!(w.get(SCRATCH, 1), b"a");
    assert_eq!(w.call(nr::read, [0, 8, 10, 0, 0, 0]), err(Errno::EFAULT));
    assert_eq!(
        w.call(nr::read, [0, SCRATCH, 10, 0, 0, 0]),
        1,
        "nothing lost"
    );
    // A pipe is no terminal.
    w.put(SCRATCH, &[0; 8]);
    assert_eq!(w.call(nr::pipe, [SCRATCH, 0, 0, 0, 0, 0]), 0);
    let fd = w.get(SCRATCH, 4)[0] as u64;
    assert_eq!(
        w.call(nr::ioctl, [fd, tty::ioctl::TCGETS, SCRATCH, 0, 0, 0]),
        err(Errno::ENOTTY)
    );
}

#[test]
fn a_reader_of_the_console_waits_without_stopping_the_others() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    g.host.tty = Some(Tty::new(1));
    let child = g.fork(1);
    assert_eq!(g.call(child, nr::read, [0, SCRATCH, 100, 0, 0, 0]), None);
    assert!(matches!(g.system.state(child), Some(State::Blocked(_))));
    // The others go on meanwhile.
    assert_eq!(g.call(1, nr::getpid, [0; 6]), Some(1));
    // A line without its end wakes nobody; the end of the line does.
    type_in(&mut g.host, b"ls\x7fs");
    g.host.resumed.clear();
    assert_eq!(g.system.retry_blocked(&mut g.fs, &mut g.host), None);
    assert!(g.host.resumed.is_empty());
    type_in(&mut g.host, b"\r");
    assert_eq!(g.system.retry_blocked(&mut g.fs, &mut g.host), None);
    let replies: Vec<(u32, u64)> = g
        .host
        .resumed
        .iter()
        .map(|(p, m)| (*p, m.registers.rax))
        .collect();
    assert_eq!(replies, [(child, 3)]);
    assert_eq!(g.get(child, SCRATCH, 3), b"ls\n");
    assert_eq!(g.system.state(child), Some(State::Running));
}

#[test]
fn poll_waits_for_the_console_terminal() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let pollfd = |fd: i32, events: u16| {
        let mut b = fd.to_le_bytes().to_vec();
        b.extend_from_slice(&events.to_le_bytes());
        b.extend_from_slice(&[0xff, 0xff]);
        b
    };
    // Without a terminal the console reads end of file: always readable.
    w.put(SCRATCH, &[pollfd(0, 1), pollfd(1, 4)].concat());
    assert_eq!(w.call(nr::poll, [SCRATCH, 2, 0, 0, 0, 0]), 2);
    // With one: readable once a line came; always writable.
    w.host.tty = Some(Tty::new(1));
    assert_eq!(w.call(nr::poll, [SCRATCH, 2, 0, 0, 0, 0]), 1);
    assert_eq!(w.get(SCRATCH + 6, 2), [0, 0]);
    assert_eq!(w.get(SCRATCH + 14, 2), [4, 0], "POLLOUT");
    w.put(SCRATCH, &pollfd(0, 1));
    let (outcome, _) = w.run(nr::poll, [SCRATCH, 1, -1i64 as u64, 0, 0, 0]);
    assert_eq!(outcome, Outcome::Block, "no timeout: it waits");
    type_in(&mut w.host, b"x");
    let (outcome, _) = w.run(nr::poll, [SCRATCH, 1, -1i64 as u64, 0, 0, 0]);
    assert_eq!(
        outcome,
        Outcome::Block,
        "a line in progress is not input yet"
    );
    type_in(&mut w.host, b"\r");
    assert_eq!(w.call(nr::poll, [SCRATCH, 1, -1i64 as u64, 0, 0, 0]), 1);
    assert_eq!(w.get(SCRATCH + 6, 2), [1, 0], "POLLIN");
}

#[test]
fn a_background_reader_of_the_terminal_is_stopped_until_it_is_in_the_foreground() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    g.host.tty = Some(Tty::new(1));
    let child = g.fork(1);
    // The child in a process group of its own, not the terminal's foreground one.
    assert_eq!(g.call(child, nr::setpgid, [0, 0, 0, 0, 0, 0]), Some(0));
    type_in(&mut g.host, b"typed\r");
    // Its read stops it (its thread is suspended) and is set to run again (rip back at
    // the `syscall` instruction, rax the call's number).
    g.host.resumed.clear();
    let _ = g.system.serve(
        child,
        &mut g.fs,
        &mut g.host,
        World::message(nr::read, [0, SCRATCH, 100, 0, 0, 0], 0),
    );
    assert_eq!(g.host.suspended, [child], "SIGTTIN stopped it");
    let (pid, m) = g.host.resumed[0];
    assert_eq!(
        (pid, m.registers.rax, m.registers.rip),
        (child, nr::read, 0x40_1019 - 2)
    );
    // In the foreground and continued, the read again takes the line.
    g.host
        .tty
        .as_mut()
        .unwrap()
        .set_foreground(child as i32)
        .unwrap();
    assert_eq!(g.call(1, nr::kill, [child as u64, 18, 0, 0, 0, 0]), Some(0));
    assert!(g.host.suspended.is_empty());
    assert_eq!(g.call(child, nr::read, [0, SCRATCH, 100, 0, 0, 0]), Some(6));
    assert_eq!(g.get(child, SCRATCH, 6), b"typed\n");
    // One that ignores SIGTTIN reads EIO.
    g.host.tty.as_mut().unwrap().set_foreground(1).unwrap();
    g.put(child, SCRATCH, &[1, 0, 0, 0, 0, 0, 0, 0]);
    g.put(child, SCRATCH + 8, &[0; 24]);
    assert_eq!(
        g.call(child, nr::rt_sigaction, [21, SCRATCH, 0, 8, 0, 0]),
        Some(0)
    );
    assert_eq!(
        g.call(child, nr::read, [0, SCRATCH, 100, 0, 0, 0]),
        Some(err(Errno::EIO))
    );
}
impl Guest<'_> {
    /// Puts `text` NUL-terminated at `at` of `pid`.
    fn text(&mut self, pid: u32, at: u64, text: &str) -> u64 {
        let mut b = text.as_bytes().to_vec();
        b.push(0);
        self.put(pid, at, &b);
        at
    }
}

const AT_FDCWD: u64 = (-100i64) as u64;

#[test]
fn open_files_share_their_offset_across_dup_and_fork() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let path = g.text(1, SCRATCH + 0x800, "/tmp/log");
    let fd = g
        .call(1, nr::openat, [AT_FDCWD, path, 0o2 | 0o100, 0o644, 0, 0])
        .unwrap();
    let copy = g.call(1, nr::dup, [fd, 0, 0, 0, 0, 0]).unwrap();
    g.put(1, SCRATCH, b"abc");
    assert_eq!(g.call(1, nr::write, [fd, SCRATCH, 3, 0, 0, 0]), Some(3));
    assert_eq!(g.call(1, nr::write, [copy, SCRATCH, 2, 0, 0, 0]), Some(2));
    let child = g.fork(1);
    assert_eq!(
        g.call(child, nr::write, [fd, SCRATCH + 2, 1, 0, 0, 0]),
        Some(1)
    );
    assert_eq!(
        g.call(1, nr::lseek, [copy, 0, 1, 0, 0, 0]),
        Some(6),
        "the child's write moved the parent's offset"
    );
    assert_eq!(g.call(child, nr::exit_group, [0; 6]), None);
    // pread does not move it; O_APPEND writes at the end.
    assert_eq!(
        g.call(1, nr::pread64, [fd, SCRATCH + 0x100, 10, 1, 0, 0]),
        Some(5)
    );
    assert_eq!(g.get(1, SCRATCH + 0x100, 5), b"bcabc");
    assert_eq!(g.call(1, nr::lseek, [fd, 0, 1, 0, 0, 0]), Some(6));
    assert_eq!(g.call(1, nr::fcntl, [fd, 4, 0o2000, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::lseek, [fd, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::write, [copy, SCRATCH, 1, 0, 0, 0]), Some(1));
    assert_eq!(
        g.call(1, nr::fstat, [fd, SCRATCH + 0x200, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.get(1, SCRATCH + 0x200 + 48, 1), [7], "st_size");
    // Unlinked while open: still readable, gone with the last descriptor.
    assert_eq!(g.call(1, nr::unlink, [path, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(
        g.call(1, nr::pread64, [copy, SCRATCH + 0x100, 10, 0, 0, 0]),
        Some(7)
    );
    assert_eq!(g.get(1, SCRATCH + 0x100, 7), b"abcabca");
    let opened = g.fs.open_count();
    g.call(1, nr::close, [fd, 0, 0, 0, 0, 0]);
    assert_eq!(g.fs.open_count(), opened, "one descriptor left");
    g.call(1, nr::close, [copy, 0, 0, 0, 0, 0]);
    assert_eq!(g.fs.open_count(), opened - 1);
}

#[test]
fn directories_names_and_the_working_directory() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let buf = SCRATCH + 0x400;
    let call = |g: &mut Guest, n: u64, a: [u64; 6]| g.call(1, n, a).unwrap();
    let d = g.text(1, SCRATCH + 0x800, "/tmp/d");
    assert_eq!(call(&mut g, nr::mkdir, [d, 0o777, 0, 0, 0, 0]), 0);
    assert_eq!(
        call(&mut g, nr::mkdir, [d, 0o777, 0, 0, 0, 0]),
        err(Errno::EEXIST)
    );
    assert_eq!(call(&mut g, nr::stat, [d, buf, 0, 0, 0, 0]), 0);
    assert_eq!(
        g.get(1, buf + 24, 4),
        (S_IFDIR | 0o755).to_le_bytes(),
        "umask 022"
    );
    // `mkdir -p` asks for each existing parent with its slash.
    let slashed = g.text(1, SCRATCH + 0x800, "/tmp/");
    assert_eq!(
        call(&mut g, nr::mkdir, [slashed, 0o777, 0, 0, 0, 0]),
        err(Errno::EEXIST)
    );
    assert_eq!(call(&mut g, nr::stat, [slashed, buf, 0, 0, 0, 0]), 0);
    let d = g.text(1, SCRATCH + 0x800, "/tmp/d");
    assert_eq!(call(&mut g, nr::chdir, [d, 0, 0, 0, 0, 0]), 0);
    assert_eq!(call(&mut g, nr::getcwd, [buf, 100, 0, 0, 0, 0]), 7);
    assert_eq!(g.get(1, buf, 7), b"/tmp/d\0");
    assert_eq!(
        call(&mut g, nr::getcwd, [buf, 5, 0, 0, 0, 0]),
        err(Errno::ERANGE)
    );
    // Relative names start at the working directory.
    let f = g.text(1, SCRATCH + 0x800, "f");
    let fd = call(&mut g, nr::creat, [f, 0o600, 0, 0, 0, 0]);
    g.put(1, SCRATCH, b"0123456789");
    assert_eq!(call(&mut g, nr::write, [fd, SCRATCH, 10, 0, 0, 0]), 10);
    assert_eq!(call(&mut g, nr::ftruncate, [fd, 4, 0, 0, 0, 0]), 0);
    let abs = g.text(1, SCRATCH + 0x800, "/tmp/d/f");
    assert_eq!(call(&mut g, nr::stat, [abs, buf, 0, 0, 0, 0]), 0);
    assert_eq!(g.get(1, buf + 48, 1), [4]);
    let target = g.text(1, SCRATCH + 0x900, "f");
    let link = g.text(1, SCRATCH + 0x800, "../l");
    assert_eq!(call(&mut g, nr::symlink, [target, link, 0, 0, 0, 0]), 0);
    assert_eq!(call(&mut g, nr::readlink, [link, buf, 64, 0, 0, 0]), 1);
    let from = g.text(1, SCRATCH + 0x800, "f");
    let to = g.text(1, SCRATCH + 0x900, "/tmp/g");
    assert_eq!(call(&mut g, nr::rename, [from, to, 0, 0, 0, 0]), 0);
    let dot = g.text(1, SCRATCH + 0x800, "..");
    let dir = call(&mut g, nr::open, [dot, 0o200000, 0, 0, 0, 0]);
    let n = call(&mut g, nr::getdents64, [dir, buf, 4096, 0, 0, 0]);
    let names: Vec<&str> = dirents(&g.get(1, buf, n as usize))
        .iter()
        .map(|d| d.0)
        .collect();
    assert_eq!(names, [".", "..", "d", "g", "l"]);
    // An *at call from a directory descriptor; rmdir of a full, then empty, directory.
    let name = g.text(1, SCRATCH + 0x800, "g");
    assert_eq!(call(&mut g, nr::unlinkat, [dir, name, 0, 0, 0, 0]), 0);
    let dot = g.text(1, SCRATCH + 0x800, "..");
    assert_eq!(call(&mut g, nr::chdir, [dot, 0, 0, 0, 0, 0]), 0);
    let d = g.text(1, SCRATCH + 0x800, "d");
    assert_eq!(call(&mut g, nr::rmdir, [d, 0, 0, 0, 0, 0]), 0);
    assert_eq!(
        call(&mut g, nr::rmdir, [d, 0, 0, 0, 0, 0]),
        err(Errno::ENOENT)
    );
    // /dev/null, /dev/zero.
    let null = g.text(1, SCRATCH + 0x800, "/dev/null");
    let fd = call(&mut g, nr::open, [null, 2, 0, 0, 0, 0]);
    assert_eq!(call(&mut g, nr::write, [fd, SCRATCH, 10, 0, 0, 0]), 10);
    assert_eq!(call(&mut g, nr::read, [fd, SCRATCH, 10, 0, 0, 0]), 0);
    let zero = g.text(1, SCRATCH + 0x800, "/dev/zero");
    let fd = call(&mut g, nr::open, [zero, 0, 0, 0, 0, 0]);
    assert_eq!(call(&mut g, nr::read, [fd, SCRATCH, 10, 0, 0, 0]), 10);
    assert_eq!(g.get(1, SCRATCH, 10), [0; 10]);
    assert_eq!(
        call(&mut g, nr::read, [fd, SCRATCH, PAGE, 0, 0, 0]),
        PAGE,
        "a whole read, not one step"
    );
    let tty = g.text(1, SCRATCH + 0x800, "/dev/tty");
    let fd = call(&mut g, nr::open, [tty, 1, 0, 0, 0, 0]);
    g.put(1, SCRATCH, b"on the console\n");
    assert_eq!(call(&mut g, nr::write, [fd, SCRATCH, 15, 0, 0, 0]), 15);
    assert_eq!(g.host.stdout(), "on the console\n");
}

#[test]
fn proc_files_of_the_processes() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let child = g.fork(1);
    let path = g.text(1, SCRATCH + 0x800, &format!("/proc/{child}/stat"));
    let fd = g.call(1, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    let n = g.call(1, nr::read, [fd, SCRATCH, 512, 0, 0, 0]).unwrap();
    let stat = String::from_utf8(g.get(1, SCRATCH, n as usize)).unwrap();
    assert!(
        stat.starts_with(&format!("{child} (busybox) R 1 ")),
        "{stat}"
    );
    let path = g.text(1, SCRATCH + 0x800, "/proc/self/cmdline");
    let fd = g.call(1, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    let n = g.call(1, nr::read, [fd, SCRATCH, 512, 0, 0, 0]).unwrap();
    assert_eq!(g.get(1, SCRATCH, n as usize), b"/bin/sh\0");
    let exe = g.text(1, SCRATCH + 0x800, "/proc/self/exe");
    assert_eq!(
        g.call(1, nr::readlink, [exe, SCRATCH, 64, 0, 0, 0]),
        Some(12)
    );
    assert_eq!(g.get(1, SCRATCH, 12), b"/bin/busybox");
    let path = g.text(1, SCRATCH + 0x800, "/proc/self/cmdline");
    assert_eq!(
        g.call(1, nr::open, [path, 1, 0, 0, 0, 0]),
        Some(err(Errno::EACCES)),
        "read-only"
    );
    let dir = g.text(1, SCRATCH + 0x800, "/proc");
    let fd = g.call(1, nr::open, [dir, 0o200000, 0, 0, 0, 0]).unwrap();
    let n = g
        .call(1, nr::getdents64, [fd, SCRATCH, 4096, 0, 0, 0])
        .unwrap();
    let names: Vec<&str> = dirents(&g.get(1, SCRATCH, n as usize))
        .iter()
        .map(|d| d.0)
        .collect();
    let child_name = child.to_string();
    assert_eq!(
        names,
        [
            ".",
            "..",
            "self",
            "meminfo",
            "uptime",
            "mounts",
            "filesystems",
            "net",
            "cpuinfo",
            "1",
            child_name.as_str()
        ]
    );
}

#[test]
fn a_removed_working_directory_stays_until_left() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let d = g.text(1, SCRATCH + 0x800, "/tmp/gone");
    assert_eq!(g.call(1, nr::mkdir, [d, 0o755, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::chdir, [d, 0, 0, 0, 0, 0]), Some(0));
    let child = g.fork(1);
    assert_eq!(g.call(1, nr::rmdir, [d, 0, 0, 0, 0, 0]), Some(0));
    // Not reused by a new directory while a process is in it.
    let e = g.text(1, SCRATCH + 0x800, "/tmp/new");
    assert_eq!(g.call(1, nr::mkdir, [e, 0o755, 0, 0, 0, 0]), Some(0));
    let f = g.text(child, SCRATCH + 0x800, "f");
    assert_eq!(
        g.call(child, nr::open, [f, 0o101, 0o644, 0, 0, 0]),
        Some(err(Errno::ENOENT)),
        "nothing can be made in a removed directory"
    );
    let e = g.text(child, SCRATCH + 0x800, "/tmp/new");
    assert_eq!(g.call(child, nr::chdir, [e, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(
        g.call(child, nr::getcwd, [SCRATCH, 64, 0, 0, 0, 0]),
        Some(9)
    );
}

#[test]
fn listing_while_removing_copying_and_status() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let call = |g: &mut Guest, n: u64, a: [u64; 6]| g.call(1, n, a).unwrap();
    for name in ["/tmp/a", "/tmp/b", "/tmp/c", "/tmp/d"] {
        let p = g.text(1, SCRATCH + 0x800, name);
        let fd = call(&mut g, nr::creat, [p, 0o644, 0, 0, 0, 0]);
        call(&mut g, nr::close, [fd, 0, 0, 0, 0, 0]);
    }
    // Entries removed between two getdents64 calls make none of the others skipped.
    let tmp = g.text(1, SCRATCH + 0x800, "/tmp");
    let dir = call(&mut g, nr::open, [tmp, 0o200000, 0, 0, 0, 0]);
    let n = call(&mut g, nr::getdents64, [dir, SCRATCH, 72, 0, 0, 0]);
    let first: Vec<&str> = dirents(&g.get(1, SCRATCH, n as usize))
        .iter()
        .map(|d| d.0)
        .collect();
    assert_eq!(first, [".", "..", "a"]);
    for name in ["/tmp/a", "/tmp/b"] {
        let p = g.text(1, SCRATCH + 0x800, name);
        assert_eq!(call(&mut g, nr::unlink, [p, 0, 0, 0, 0, 0]), 0);
    }
    let n = call(&mut g, nr::getdents64, [dir, SCRATCH, 4096, 0, 0, 0]);
    let rest: Vec<&str> = dirents(&g.get(1, SCRATCH, n as usize))
        .iter()
        .map(|d| d.0)
        .collect();
    assert_eq!(rest, ["c", "d"]);
    // sendfile from a file to a file and to a pipe.
    let passwd = g.text(1, SCRATCH + 0x800, "/etc/passwd");
    let from = call(&mut g, nr::open, [passwd, 0, 0, 0, 0, 0]);
    let c = g.text(1, SCRATCH + 0x800, "/tmp/c");
    let to = call(&mut g, nr::open, [c, 1, 0, 0, 0, 0]);
    assert_eq!(call(&mut g, nr::sendfile, [to, from, 0, 100, 0, 0]), 30);
    assert_eq!(call(&mut g, nr::sendfile, [to, from, 0, 100, 0, 0]), 0);
    assert_eq!(call(&mut g, nr::pipe2, [SCRATCH, 0, 0, 0, 0, 0]), 0);
    let ends = g.get(1, SCRATCH, 8);
    let write_end = u32::from_le_bytes(ends[4..8].try_into().unwrap()) as u64;
    g.put(1, SCRATCH + 0x100, &5u64.to_le_bytes());
    assert_eq!(
        call(
            &mut g,
            nr::sendfile,
            [write_end, from, SCRATCH + 0x100, 4, 0, 0]
        ),
        4
    );
    assert_eq!(
        u64::from_le_bytes(g.get(1, SCRATCH + 0x100, 8).try_into().unwrap()),
        9
    );
    assert_eq!(
        call(&mut g, nr::sendfile, [from, to, 0, 4, 0, 0]),
        err(Errno::EBADF),
        "into a read-only file"
    );
    // statx and statfs.
    assert_eq!(
        call(&mut g, nr::statx, [AT_FDCWD, c, 0, 0x7ff, SCRATCH, 0]),
        0
    );
    let statx = g.get(1, SCRATCH, 256);
    assert_eq!(
        u16::from_le_bytes([statx[28], statx[29]]) as u32,
        S_IFREG | 0o644
    );
    assert_eq!(statx[40], 30, "stx_size");
    assert_eq!(call(&mut g, nr::statfs, [c, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(g.get(1, SCRATCH, 8), 0x0102_1994u64.to_le_bytes(), "tmpfs");
    // chmod and utimensat change what stat shows.
    assert_eq!(call(&mut g, nr::chmod, [c, 0o600, 0, 0, 0, 0]), 0);
    let mut times = [0u8; 32];
    times[16..24].copy_from_slice(&1234u64.to_le_bytes());
    g.put(1, SCRATCH + 0x200, &times);
    assert_eq!(
        call(
            &mut g,
            nr::utimensat,
            [AT_FDCWD, c, SCRATCH + 0x200, 0, 0, 0]
        ),
        0
    );
    assert_eq!(call(&mut g, nr::stat, [c, SCRATCH, 0, 0, 0, 0]), 0);
    assert_eq!(g.get(1, SCRATCH + 24, 4), (S_IFREG | 0o600).to_le_bytes());
    assert_eq!(g.get(1, SCRATCH + 88, 8), 1234u64.to_le_bytes(), "st_mtime");
}

#[test]
fn the_block_device_reads_writes_seeks_and_syncs_as_linux_s() {
    use crate::disk;
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let open = |g: &mut Guest, path: &str, flags: u64| {
        let at = g.text(1, SCRATCH + 0x800, path);
        g.call(1, nr::openat, [AT_FDCWD, at, flags, 0, 0, 0])
            .unwrap()
    };
    // Without `guest.disk` there is no /dev/vda.
    assert_eq!(open(&mut g, "/dev/vda", 2), err(Errno::ENOENT));
    // Its link's ports have no devices.
    let table = b"vda-req queuing out 2072 2\nvda-resp queuing in 2064 2\nother queuing in 16 2\n";
    g.fs.set_ports(crate::arinc::parse(table).unwrap()).unwrap();
    g.fs.hide_port("vda-req");
    g.fs.hide_port("vda-resp");
    assert_eq!(open(&mut g, "/dev/arinc/vda-req", 1), err(Errno::ENOENT));
    assert_eq!(open(&mut g, "/dev/arinc/vda-resp", 0), err(Errno::ENOENT));
    assert!((open(&mut g, "/dev/arinc/other", 0) as i64) >= 0);
    let device = Sectors::new(8, 0);
    g.fs.set_disk(device.disk()).unwrap();
    let vda = open(&mut g, "/dev/vda", 2); // O_RDWR
    // A block device of size 0 (as stat shows one on Linux), 254:0.
    assert_eq!(
        g.call(1, nr::fstat, [vda, SCRATCH + 0x100, 0, 0, 0, 0]),
        Some(0)
    );
    let st = g.get(1, SCRATCH + 0x100, 144);
    assert_eq!(st[24..28], (crate::cpio::S_IFBLK | 0o660).to_le_bytes());
    assert_eq!(st[40..48], (254u64 << 8).to_le_bytes(), "st_rdev");
    assert_eq!(st[48..56], 0u64.to_le_bytes(), "st_size");
    // lseek: the end is the disk's size, past it EINVAL.
    let seek = |g: &mut Guest, at: i64, whence: u64| {
        g.call(1, nr::lseek, [vda, at as u64, whence, 0, 0, 0])
            .unwrap()
    };
    assert_eq!(seek(&mut g, 0, 2), 4096);
    assert_eq!(seek(&mut g, 1, 2), err(Errno::EINVAL));
    assert_eq!(seek(&mut g, 4097, 0), err(Errno::EINVAL));
    // pwrite across a sector boundary, pread around it.
    g.put(1, SCRATCH, b"hello");
    let pwrite = |g: &mut Guest, n: u64, at: u64| {
        g.call(1, nr::pwrite64, [vda, SCRATCH, n, at, 0, 0])
            .unwrap()
    };
    assert_eq!(pwrite(&mut g, 5, 510), 5);
    assert_eq!(
        g.call(1, nr::pread64, [vda, SCRATCH + 0x200, 9, 508, 0, 0]),
        Some(9)
    );
    assert_eq!(g.get(1, SCRATCH + 0x200, 9), b"\0\0hello\0\0");
    assert_eq!(&device.sector(0)[510..], b"he");
    assert_eq!(&device.sector(1)[..3], b"llo");
    // write at the offset: across the end short, at the end ENOSPC; read there 0.
    assert_eq!(seek(&mut g, 4094, 0), 4094);
    assert_eq!(g.call(1, nr::write, [vda, SCRATCH, 5, 0, 0, 0]), Some(2));
    assert_eq!(
        g.call(1, nr::write, [vda, SCRATCH, 5, 0, 0, 0]),
        Some(err(Errno::ENOSPC))
    );
    assert_eq!(g.call(1, nr::read, [vda, SCRATCH, 5, 0, 0, 0]), Some(0));
    assert_eq!(seek(&mut g, -2, 2), 4094);
    assert_eq!(
        g.call(1, nr::read, [vda, SCRATCH + 0x200, 5, 0, 0, 0]),
        Some(2)
    );
    assert_eq!(g.get(1, SCRATCH + 0x200, 2), b"he");
    // The ioctls mke2fs and e2fsck use.
    let ioctl = |g: &mut Guest, request: u64| {
        let r = g
            .call(1, nr::ioctl, [vda, request, SCRATCH + 0x300, 0, 0, 0])
            .unwrap();
        let v = g.get(1, SCRATCH + 0x300, 8);
        (r, u64::from_le_bytes(v.try_into().unwrap()))
    };
    g.put(1, SCRATCH + 0x300, &[0xff; 8]);
    assert_eq!(ioctl(&mut g, disk::BLKGETSIZE64), (0, 4096));
    assert_eq!(ioctl(&mut g, disk::BLKGETSIZE), (0, 8));
    g.put(1, SCRATCH + 0x300, &[0; 8]);
    assert_eq!(ioctl(&mut g, disk::BLKSSZGET), (0, 512));
    assert_eq!(ioctl(&mut g, 0x5401).0, err(Errno::ENOTTY)); // TCGETS
    // fsync, fdatasync, syncfs and sync flush the device; fsync of another file does not.
    let flushes = |_: &mut Guest| device.flushes();
    assert_eq!(g.call(1, nr::fsync, [vda, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::fdatasync, [vda, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(flushes(&mut g), 2);
    let file = open(&mut g, "/tmp/f", 0o100 | 2); // O_CREAT | O_RDWR
    assert_eq!(g.call(1, nr::fsync, [file, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(flushes(&mut g), 2);
    assert_eq!(g.call(1, nr::syncfs, [file, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::sync, [0; 6]), Some(0));
    assert_eq!(ioctl(&mut g, disk::BLKFLSBUF).0, 0);
    assert_eq!(flushes(&mut g), 5);
    // One call moves at most disk::MAX_TRANSFER bytes.
    let big = 16 * 1024 * 1024 / 512;
    g.fs.set_disk(Sectors::new(big, 1).disk()).unwrap();
    let area = 0x7100_0000;
    assert_eq!(
        g.call(1, nr::mmap, [area, 1 << 20, 3, 0x32, u64::MAX, 0]),
        Some(area)
    );
    assert_eq!(
        g.call(1, nr::pread64, [vda, area, 1 << 20, 0, 0, 0]),
        Some(disk::MAX_TRANSFER as u64)
    );
}

/// `mount`: the disk's ext2 at /data serves the file calls (create, write, fsync, rename,
/// list, stat, statfs, unlink of an open file, getcwd), covers the directory, keeps
/// `/dev/vda` busy, refuses to leave while used, and what it wrote is there at the next
/// mount and on the disk, marked clean.
#[test]
fn the_disk_s_ext2_mounts_at_data_and_serves_the_file_calls() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let device = Sectors::new(4096, 0);
    let options = ext2::FormatOptions {
        block_size: 1024,
        inode_size: 128,
        ..Default::default()
    };
    ext2::format(&mut device.clone(), 4096, &options).unwrap();
    g.fs.set_disk(device.disk()).unwrap();
    let path = |g: &mut Guest, at: u64, p: &str| g.text(1, SCRATCH + at, p);
    let open = |g: &mut Guest, p: &str, flags: u64| {
        let at = path(g, 0x800, p);
        g.call(1, nr::openat, [AT_FDCWD, at, flags, 0o644, 0, 0])
            .unwrap()
    };
    let mount = |g: &mut Guest, source: &str, target: &str, kind: &str, flags: u64| {
        let (s, t, k) = (
            path(g, 0x900, source),
            path(g, 0xa00, target),
            path(g, 0xb00, kind),
        );
        g.call(1, nr::mount, [s, t, k, flags, 0, 0]).unwrap()
    };
    let umount = |g: &mut Guest, target: &str| {
        let t = path(g, 0xa00, target);
        g.call(1, nr::umount2, [t, 0, 0, 0, 0, 0]).unwrap()
    };
    let d = path(&mut g, 0x800, "/data");
    assert_eq!(g.call(1, nr::mkdir, [d, 0o755, 0, 0, 0, 0]), Some(0));
    // Refusals: another type, no block device, no directory, flags not supported.
    assert_eq!(
        mount(&mut g, "/dev/vda", "/data", "xfs", 0),
        err(Errno::ENODEV)
    );
    assert_eq!(
        mount(&mut g, "/tmp", "/data", "ext2", 0),
        err(Errno::ENOTBLK)
    );
    assert_eq!(mount(&mut g, "/dev/vda", "/", "ext2", 0), err(Errno::EBUSY));
    assert_eq!(
        mount(&mut g, "/dev/vda", "/data", "ext2", 32),
        err(Errno::EINVAL)
    ); // MS_REMOUNT
    assert_eq!(umount(&mut g, "/data"), err(Errno::EINVAL));
    assert_eq!(mount(&mut g, "/dev/vda", "/data", "ext2", 0xc0ed_0000), 0);
    assert_eq!(
        mount(&mut g, "/dev/vda", "/tmp", "ext2", 0),
        err(Errno::EBUSY)
    );
    // The raw device is the file system's now; its size still answers.
    let vda = open(&mut g, "/dev/vda", 0);
    assert_eq!(
        g.call(1, nr::read, [vda, SCRATCH, 512, 0, 0, 0]),
        Some(err(Errno::EBUSY))
    );
    assert_eq!(g.call(1, nr::lseek, [vda, 0, 2, 0, 0, 0]), Some(4096 * 512));
    assert_eq!(g.call(1, nr::close, [vda, 0, 0, 0, 0, 0]), Some(0));
    // A file written, synced and renamed.
    let f = open(&mut g, "/data/new", 0o100 | 2); // O_CREAT | O_RDWR
    g.put(1, SCRATCH, b"hello, disk");
    assert_eq!(g.call(1, nr::write, [f, SCRATCH, 11, 0, 0, 0]), Some(11));
    let flushes = device.flushes();
    assert_eq!(g.call(1, nr::fsync, [f, 0, 0, 0, 0, 0]), Some(0));
    assert!(device.flushes() > flushes, "fsync flushes the disk");
    let (from, to) = (
        path(&mut g, 0x900, "/data/new"),
        path(&mut g, 0xa00, "/data/kept"),
    );
    assert_eq!(g.call(1, nr::rename, [from, to, 0, 0, 0, 0]), Some(0));
    assert_eq!(
        g.call(1, nr::pread64, [f, SCRATCH + 0x100, 64, 7, 0, 0]),
        Some(4)
    );
    assert_eq!(g.get(1, SCRATCH + 0x100, 4), b"disk");
    // stat: ext2's inode, the disk's device number; statfs: ext2's figures.
    let kept = path(&mut g, 0x900, "/data/kept");
    assert_eq!(
        g.call(1, nr::stat, [kept, SCRATCH + 0x100, 0, 0, 0, 0]),
        Some(0)
    );
    let st = g.get(1, SCRATCH + 0x100, 144);
    assert_eq!(st[0..8], (254u64 << 8).to_le_bytes(), "st_dev");
    assert_eq!(st[48..56], 11u64.to_le_bytes(), "st_size");
    assert_eq!(st[64..72], 2u64.to_le_bytes(), "st_blocks: one 1 KiB block");
    assert_eq!(
        g.call(1, nr::statfs, [kept, SCRATCH + 0x200, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(
        g.get(1, SCRATCH + 0x200, 16),
        [0xef53u64.to_le_bytes(), 1024u64.to_le_bytes()].concat()
    );
    // Across file systems: EXDEV.
    let tmp = open(&mut g, "/tmp/t", 0o100 | 2);
    assert_eq!(g.call(1, nr::close, [tmp, 0, 0, 0, 0, 0]), Some(0));
    let (from, to) = (
        path(&mut g, 0x900, "/tmp/t"),
        path(&mut g, 0xa00, "/data/t"),
    );
    assert_eq!(
        g.call(1, nr::rename, [from, to, 0, 0, 0, 0]),
        Some(err(Errno::EXDEV))
    );
    assert_eq!(
        g.call(1, nr::link, [from, to, 0, 0, 0, 0]),
        Some(err(Errno::EXDEV))
    );
    // The listing: what ext2 stores, `.`, `..` and lost+found among it.
    let dir = open(&mut g, "/data", 0o200000); // O_DIRECTORY
    let n = g
        .call(1, nr::getdents64, [dir, SCRATCH + 0xc00, 0x300, 0, 0, 0])
        .unwrap() as usize;
    assert!((n as i64) > 0, "getdents64: {}", n as i64);
    let listing = g.get(1, SCRATCH + 0xc00, n);
    let mut names = Vec::new();
    let mut at = 0;
    while at < n {
        let len = u16::from_le_bytes([listing[at + 16], listing[at + 17]]) as usize;
        let name = &listing[at + 19..at + len];
        let end = name.iter().position(|&b| b == 0).unwrap();
        names.push(String::from_utf8(name[..end].to_vec()).unwrap());
        at += len;
    }
    names.sort();
    assert_eq!(names, [".", "..", "kept", "lost+found"]);
    assert_eq!(
        g.call(1, nr::getdents64, [dir, SCRATCH + 0xc00, 0x300, 0, 0, 0]),
        Some(0)
    );
    // A working directory below it, named by getcwd; `..` leaves it at its root.
    let sub = path(&mut g, 0x900, "/data/sub");
    assert_eq!(g.call(1, nr::mkdir, [sub, 0o755, 0, 0, 0, 0]), Some(0));
    assert_eq!(g.call(1, nr::chdir, [sub, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(
        g.call(1, nr::getcwd, [SCRATCH + 0x300, 64, 0, 0, 0, 0]),
        Some(10)
    );
    assert_eq!(g.get(1, SCRATCH + 0x300, 10), b"/data/sub\0");
    let up = path(&mut g, 0x900, "../../tmp/t");
    assert_eq!(
        g.call(1, nr::stat, [up, SCRATCH + 0x100, 0, 0, 0, 0]),
        Some(0)
    );
    // Busy while used: the working directory, then open descriptors.
    assert_eq!(umount(&mut g, "/data"), err(Errno::EBUSY));
    let root = path(&mut g, 0x900, "/");
    assert_eq!(g.call(1, nr::chdir, [root, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(umount(&mut g, "/data"), err(Errno::EBUSY));
    assert_eq!(g.call(1, nr::close, [dir, 0, 0, 0, 0, 0]), Some(0));
    // The covered directory cannot go; /proc/mounts shows the mount.
    let data = path(&mut g, 0x900, "/data");
    assert_eq!(
        g.call(1, nr::rmdir, [data, 0, 0, 0, 0, 0]),
        Some(err(Errno::EBUSY))
    );
    let mounts = open(&mut g, "/proc/mounts", 0);
    let n = g
        .call(1, nr::read, [mounts, SCRATCH + 0xc00, 512, 0, 0, 0])
        .unwrap() as usize;
    let text = String::from_utf8(g.get(1, SCRATCH + 0xc00, n)).unwrap();
    assert!(text.contains("/dev/vda /data ext2 rw"), "{text}");
    assert_eq!(g.call(1, nr::close, [mounts, 0, 0, 0, 0, 0]), Some(0));
    // An unlinked open file stays readable; its inode goes at the close.
    let free_inodes = |g: &mut Guest| {
        let kept = path(g, 0x900, "/data");
        g.call(1, nr::statfs, [kept, SCRATCH + 0x200, 0, 0, 0, 0]);
        u64::from_le_bytes(g.get(1, SCRATCH + 0x200 + 48, 8).try_into().unwrap())
    };
    let before = free_inodes(&mut g);
    let kept = path(&mut g, 0x900, "/data/kept");
    assert_eq!(g.call(1, nr::unlink, [kept, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(
        g.call(1, nr::pread64, [f, SCRATCH + 0x100, 5, 0, 0, 0]),
        Some(5)
    );
    assert_eq!(g.get(1, SCRATCH + 0x100, 5), b"hello");
    assert_eq!(free_inodes(&mut g), before);
    assert_eq!(g.call(1, nr::close, [f, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(free_inodes(&mut g), before + 1);
    // A last file, then umount: the directory is the in-memory one again.
    let f = open(&mut g, "/data/last", 0o100 | 1);
    g.put(1, SCRATCH, b"bye");
    assert_eq!(g.call(1, nr::write, [f, SCRATCH, 3, 0, 0, 0]), Some(3));
    assert_eq!(g.call(1, nr::close, [f, 0, 0, 0, 0, 0]), Some(0));
    assert_eq!(umount(&mut g, "/data"), 0);
    assert_eq!(open(&mut g, "/data/last", 0), err(Errno::ENOENT));
    // On the disk: clean, with the file.
    let mut fs = ext2::Ext2::mount_read_only(device.clone()).unwrap();
    let ino = fs.lookup(ext2::ROOT_INO, b"last").unwrap().unwrap();
    let mut buf = [0u8; 8];
    assert_eq!(fs.read(ino, 0, &mut buf), Ok(3));
    assert_eq!(&buf[..3], b"bye");
    assert_eq!(fs.lookup(ext2::ROOT_INO, b"kept"), Ok(None));
    // Mounted again (read-only): there, and no change allowed.
    assert_eq!(mount(&mut g, "/dev/vda", "/data", "ext2", 1), 0);
    let f = open(&mut g, "/data/last", 0);
    assert_eq!(g.call(1, nr::read, [f, SCRATCH, 8, 0, 0, 0]), Some(3));
    assert_eq!(open(&mut g, "/data/x", 0o100 | 1), err(Errno::EROFS));
}

#[test]
fn arinc_ports_are_devices_that_move_one_message_a_call() {
    use crate::arinc;
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    let table = b"level sampling in 8 100000000\ncmd queuing out 16 4\nreply queuing in 16 4\n";
    g.fs.set_ports(arinc::parse(table).unwrap()).unwrap();
    let open = |g: &mut Guest, path: &str, flags: u64| {
        let at = g.text(1, SCRATCH + 0x800, path);
        g.call(1, nr::openat, [AT_FDCWD, at, flags, 0, 0, 0])
            .unwrap()
    };
    let (level, cmd, reply) = (
        open(&mut g, "/dev/arinc/level", 0),
        open(&mut g, "/dev/arinc/cmd", 1),
        open(&mut g, "/dev/arinc/reply", 0o4000), // O_NONBLOCK
    );
    // Device numbers: MAJOR, index.
    g.call(1, nr::fstat, [reply, SCRATCH + 0x100, 0, 0, 0, 0]);
    let rdev = u64::from_le_bytes(g.get(1, SCRATCH + 0x128, 8).try_into().unwrap());
    assert_eq!(rdev, arinc::MAJOR << 8 | 2);
    // A sampling message: one read takes it (8 bytes of a 64-byte read), its validity
    // by ioctl; a buffer smaller than the port's size is EMSGSIZE.
    g.host
        .port_messages
        .entry(0)
        .or_default()
        .extend([(b"12345678".to_vec(), false), (b"abcdefgh".to_vec(), true)]);
    let validity = |g: &mut Guest| {
        let r = g.call(
            1,
            nr::ioctl,
            [level, arinc::IOCTL_VALIDITY, SCRATCH + 0x200, 0, 0, 0],
        );
        (r, g.word(1, SCRATCH + 0x200))
    };
    assert_eq!(validity(&mut g), (Some(0), 0));
    let read = |g: &mut Guest, fd: u64, n: u64| g.call(1, nr::read, [fd, SCRATCH, n, 0, 0, 0]);
    assert_eq!(read(&mut g, level, 7), Some(err(Errno::EMSGSIZE)));
    assert_eq!(read(&mut g, level, 64), Some(8));
    assert_eq!(g.get(1, SCRATCH, 8), b"12345678");
    assert_eq!(validity(&mut g), (Some(0), 1));
    assert_eq!(read(&mut g, level, 8), Some(8));
    assert_eq!(g.get(1, SCRATCH, 8), b"abcdefgh");
    // The ioctl on a queuing port, or another request: ENOTTY.
    let r = g.call(
        1,
        nr::ioctl,
        [reply, arinc::IOCTL_VALIDITY, SCRATCH, 0, 0, 0],
    );
    assert_eq!(r, Some(err(Errno::ENOTTY)));
    let r = g.call(1, nr::ioctl, [level, 0x5401, SCRATCH, 0, 0, 0]);
    assert_eq!(r, Some(err(Errno::ENOTTY)));
    // Nothing there: O_NONBLOCK gives EAGAIN, a blocking read waits.
    assert_eq!(read(&mut g, reply, 16), Some(err(Errno::EAGAIN)));
    assert_eq!(g.host.port_waits, 0);
    assert_eq!(read(&mut g, level, 8), None);
    assert!(
        g.host.port_waits > 0,
        "the host learns that a call waits for a port"
    );
    assert_eq!(
        g.system.state(1).map(|s| matches!(s, State::Blocked(_))),
        Some(true)
    );
    g.host
        .port_messages
        .entry(0)
        .or_default()
        .push_back((b"zzzzzzzz".to_vec(), true));
    g.host.resumed.clear();
    assert_eq!(g.system.retry_blocked(&mut g.fs, &mut g.host), None);
    assert_eq!(g.host.resumed[0].1.registers.rax, 8);
    // Writing: one message a call; too long is EMSGSIZE, 0 bytes send nothing; reading a
    // source or writing a destination is EINVAL (EBADF by the open mode first).
    g.put(1, SCRATCH, &[7; 32]);
    let write = |g: &mut Guest, fd: u64, n: u64| g.call(1, nr::write, [fd, SCRATCH, n, 0, 0, 0]);
    assert_eq!(write(&mut g, cmd, 17), Some(err(Errno::EMSGSIZE)));
    // Longer than a step of a write (not cut into messages): EMSGSIZE too.
    assert_eq!(write(&mut g, cmd, 5000), Some(err(Errno::EMSGSIZE)));
    assert_eq!(write(&mut g, cmd, 0), Some(0));
    assert_eq!(write(&mut g, cmd, 3), Some(3));
    assert_eq!(write(&mut g, cmd, 16), Some(16));
    assert_eq!(g.host.port_sent[&1], [vec![7; 3], vec![7; 16]]);
    assert_eq!(read(&mut g, cmd, 16), Some(err(Errno::EBADF)));
    let cmd_rw = open(&mut g, "/dev/arinc/cmd", 2);
    assert_eq!(read(&mut g, cmd_rw, 16), Some(err(Errno::EINVAL)));
    let level_rw = open(&mut g, "/dev/arinc/level", 2);
    assert_eq!(write(&mut g, level_rw, 8), Some(err(Errno::EINVAL)));
    // poll: the full source is not writable, the empty queue not readable, the sampling
    // port is (a message is there).
    g.host
        .port_messages
        .entry(0)
        .or_default()
        .push_back((b"00000000".to_vec(), true));
    let mut t = Vec::new();
    for (fd, events) in [(cmd, 4u16), (reply, 1), (level, 1)] {
        t.extend_from_slice(&(fd as i32).to_le_bytes());
        t.extend_from_slice(&events.to_le_bytes());
        t.extend_from_slice(&0u16.to_le_bytes());
    }
    g.put(1, SCRATCH + 0x400, &t);
    assert_eq!(
        g.call(1, nr::poll, [SCRATCH + 0x400, 3, 0, 0, 0, 0]),
        Some(1)
    );
    assert_eq!(g.get(1, SCRATCH + 0x406, 2), 0u16.to_le_bytes());
    assert_eq!(g.get(1, SCRATCH + 0x40e, 2), 0u16.to_le_bytes());
    assert_eq!(g.get(1, SCRATCH + 0x416, 2), 1u16.to_le_bytes());
    // A full source with O_NONBLOCK: EAGAIN.
    let cmd_nb = open(&mut g, "/dev/arinc/cmd", 1 | 0o4000);
    assert_eq!(write(&mut g, cmd_nb, 1), Some(err(Errno::EAGAIN)));
    // pread on a port: ESPIPE.
    let r = g.call(1, nr::pread64, [level, SCRATCH, 8, 0, 0, 0]);
    assert_eq!(r, Some(err(Errno::ESPIPE)));
}

#[test]
fn the_arinc_port_table_is_read_line_by_line_and_bad_lines_are_named() {
    use crate::arinc::{Direction, Kind, parse};
    let ports = parse(b"level sampling in 8 100000000\n\nplc-request queuing out 256 4\n").unwrap();
    assert_eq!(ports.len(), 2);
    assert_eq!(
        (
            ports[1].name.as_str(),
            ports[1].kind,
            ports[1].direction,
            ports[1].size
        ),
        ("plc-request", Kind::Queuing, Direction::Out, 256)
    );
    assert_eq!(ports[0].refresh_or_depth, 100_000_000);
    for (text, line) in [
        (&b"a sampling in 8\n"[..], 1),
        (b"a sampling in 8 0\nb fifo in 8 0\n", 2),
        (b"a sampling up 8 0\n", 1),
        (b"a sampling in 0 0\n", 1),
        (b"a sampling in 5000 0\n", 1),
        (b"a/b sampling in 8 0\n", 1),
        (b"a sampling in 8 0\na queuing in 8 1\n", 2),
        (b"a sampling in 8 0 9\n", 1),
        (b"\xff sampling in 8 0\n", 1),
    ] {
        assert_eq!(parse(text).unwrap_err().line, line, "{text:?}");
    }
}

/// Sockets through the system calls, on the loopback: a listener on 127.0.0.1, a
/// non-blocking connect to it (EINPROGRESS), `accept4` with the peer's address, bytes
/// across, EAGAIN and a blocking read that waits, and the errors of another family and of
/// a file that is no socket; closing every descriptor closes the sockets.
#[test]
fn sockets_on_the_loopback_through_the_calls() {
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let (addr, len, data) = (SCRATCH + 0x100, SCRATCH + 0x200, SCRATCH + 0x300);
    let l = w.call(nr::socket, [2, 1, 0, 0, 0, 0]);
    w.put(addr, &loopback(8080));
    assert_eq!(w.call(nr::bind, [l, addr, 16, 0, 0, 0]), 0);
    assert_eq!(w.call(nr::listen, [l, 2, 0, 0, 0, 0]), 0);
    let c = w.call(nr::socket, [2, 1 | 0o4000, 0, 0, 0, 0]);
    assert_eq!(w.call(nr::connect, [c, addr, 16, 0, 0, 0]), err(Errno(115)));
    let now = w.host.now_ns();
    w.net.poll(now);
    w.put(len, &16u32.to_le_bytes());
    let s = w.call(nr::accept4, [l, addr, len, 0o4000, 0, 0]);
    assert!(s < 1024, "accept4: {s:#x}");
    assert_eq!(&w.get(addr, 8)[4..8], &[127, 0, 0, 1], "the peer's address");
    w.put(data, b"hello");
    assert_eq!(w.call(nr::write, [c, data, 5, 0, 0, 0]), 5);
    let now = w.host.now_ns();
    w.net.poll(now);
    assert_eq!(w.call(nr::read, [s, data + 64, 64, 0, 0, 0]), 5);
    assert_eq!(w.get(data + 64, 5), b"hello");
    assert_eq!(w.call(nr::read, [s, data, 64, 0, 0, 0]), err(Errno::EAGAIN));
    assert_eq!(
        w.call(nr::fcntl, [s, 4, 0, 0, 0, 0]),
        0,
        "F_SETFL: blocking"
    );
    assert_eq!(w.run(nr::read, [s, data, 64, 0, 0, 0]).0, Outcome::Block);
    assert_eq!(
        w.call(nr::socket, [10, 1, 0, 0, 0, 0]),
        err(Errno::EAFNOSUPPORT)
    );
    assert_eq!(
        w.call(nr::socket, [1, 1, 0, 0, 0, 0]),
        err(Errno::EAFNOSUPPORT)
    );
    assert_eq!(
        w.call(nr::bind, [0, addr, 16, 0, 0, 0]),
        err(Errno::ENOTSOCK)
    );
    assert_eq!(
        w.call(nr::bind, [l, addr, 200, 0, 0, 0]),
        err(Errno::EINVAL)
    );
    for fd in [s, c, l] {
        assert_eq!(w.call(nr::close, [fd, 0, 0, 0, 0, 0]), 0);
    }
    assert_eq!(w.net.open_count(), 0);
}

/// A guest's network with `eth0` at 10.0.2.`ip` (MAC 02:00:00:00:00:`mac`), linked to
/// ports 0 (received frames) and 1 (frames to send).
fn eth0(mac: u8, ip: u8) -> crate::net::Net {
    use crate::net::{Net, NetConfig};
    let mut net = Net::new(Some(NetConfig {
        mac: [2, 0, 0, 0, 0, mac],
        address: netstack::Ipv4Address::new(10, 0, 2, ip),
        prefix: 24,
        gateway: None,
    }));
    net.link(0, 1);
    net
}

/// Guest `a` (10.0.2.15) and guest `b` (10.0.2.16), each with its [`eth0`] and its model.
fn two_eth0s() -> ((crate::net::Net, Model), (crate::net::Net, Model)) {
    ((eth0(1, 15), Model::new(0)), (eth0(2, 16), Model::new(0)))
}

/// `a` connects to port 80 of `b`, `step` carrying the frames between them: the client's
/// socket and the one `b` accepted.
fn connect_to_b(
    a: &mut (crate::net::Net, Model),
    b: &mut (crate::net::Net, Model),
    mut step: impl FnMut(&mut (crate::net::Net, Model), &mut (crate::net::Net, Model)),
) -> (netstack::SocketId, netstack::SocketId) {
    use netstack::{Error, Ipv4Address, SocketAddr};
    let l = b.0.stack(0).socket(2, 1, 0).unwrap();
    let any = SocketAddr::new(Ipv4Address::UNSPECIFIED, 80);
    b.0.stack(0).bind(l, any).unwrap();
    b.0.stack(0).listen(l, 1).unwrap();
    let c = a.0.stack(0).socket(2, 1, 0).unwrap();
    let server = SocketAddr::new(Ipv4Address::new(10, 0, 2, 16), 80);
    assert_eq!(a.0.stack(0).connect(c, server), Err(Error::WouldBlock));
    for _ in 0..20 {
        step(a, b);
    }
    assert_eq!(a.0.stack(0).connect_result(c), Ok(()), "connected");
    let (s, peer) = b.0.stack(0).accept(l).unwrap();
    assert_eq!(peer.ip, Ipv4Address::new(10, 0, 2, 15));
    (c, s)
}

/// IPv4 multicast through the calls: a process's UDP socket on guest `a` joins group
/// 239.1.2.3 (`IP_ADD_MEMBERSHIP`) and receives what guest `b` sends to it; after
/// `IP_DROP_MEMBERSHIP`, and after a second socket's membership ends with its close, the
/// group's datagrams no longer arrive; the errors Linux gives for a bad request.
#[test]
fn a_socket_joins_and_leaves_a_multicast_group() {
    use netstack::{Ipv4Address, SocketAddr};
    let bytes = initramfs();
    let mut w = World::new(&bytes);
    let ((net, model), mut b) = two_eth0s();
    (w.net, w.host.port_messages) = (net, model.port_messages);
    let (rx, tx) = (0, 1);
    let step = |w: &mut World, b: &mut (crate::net::Net, Model)| {
        w.net.run(&mut w.host);
        b.0.run(&mut b.1);
        for frame in w.host.port_sent.remove(&tx).unwrap_or_default() {
            b.1.port_messages
                .entry(rx)
                .or_default()
                .push_back((frame, true));
        }
        for frame in b.1.port_sent.remove(&tx).unwrap_or_default() {
            w.host
                .port_messages
                .entry(rx)
                .or_default()
                .push_back((frame, true));
        }
    };
    let (addr, mreq, data) = (SCRATCH + 0x100, SCRATCH + 0x200, SCRATCH + 0x300);
    let s = w.call(nr::socket, [2, 2 | 0o4000, 0, 0, 0, 0]);
    w.put(
        addr,
        &[2, 0, 0x13, 0x88, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    );
    assert_eq!(w.call(nr::bind, [s, addr, 16, 0, 0, 0]), 0);
    let (join, drop) = (35, 36);
    w.put(mreq, &[239, 1, 2, 3, 0, 0, 0, 0]);
    assert_eq!(w.call(nr::setsockopt, [s, 0, join, mreq, 8, 0]), 0);
    let sender = b.0.stack(0).socket(2, 2, 0).unwrap();
    let group = SocketAddr::new(Ipv4Address::new(239, 1, 2, 3), 5000);
    let send = |w: &mut World, b: &mut (crate::net::Net, Model), text: &[u8]| {
        assert_eq!(b.0.stack(0).send(sender, text, Some(group)), Ok(text.len()));
        for _ in 0..5 {
            step(w, b);
        }
    };
    send(&mut w, &mut b, b"first");
    assert_eq!(w.call(nr::read, [s, data, 64, 0, 0, 0]), 5);
    assert_eq!(w.get(data, 5), b"first");
    // The errors: in the group already, an address that is no group, another interface,
    // a short request, leaving a group it is not in.
    assert_eq!(
        w.call(nr::setsockopt, [s, 0, join, mreq, 8, 0]),
        err(Errno::EADDRINUSE)
    );
    w.put(mreq + 16, &[10, 0, 2, 99, 0, 0, 0, 0]);
    assert_eq!(
        w.call(nr::setsockopt, [s, 0, join, mreq + 16, 8, 0]),
        err(Errno::EINVAL)
    );
    w.put(mreq + 32, &[239, 9, 9, 9, 0, 0, 0, 0, 7, 0, 0, 0]);
    assert_eq!(
        w.call(nr::setsockopt, [s, 0, join, mreq + 32, 12, 0]),
        err(Errno::ENODEV)
    );
    assert_eq!(
        w.call(nr::setsockopt, [s, 0, join, mreq, 4, 0]),
        err(Errno::EINVAL)
    );
    assert_eq!(
        w.call(nr::setsockopt, [s, 0, drop, mreq + 32, 8, 0]),
        err(Errno::EADDRNOTAVAIL)
    );
    // A second socket in the group keeps the interface in it when the first leaves.
    let t = w.call(nr::socket, [2, 2, 0, 0, 0, 0]);
    assert_eq!(w.call(nr::setsockopt, [t, 0, join, mreq, 8, 0]), 0);
    assert_eq!(w.call(nr::setsockopt, [s, 0, drop, mreq, 8, 0]), 0);
    send(&mut w, &mut b, b"second");
    assert_eq!(w.call(nr::read, [s, data, 64, 0, 0, 0]), 6, "still joined");
    // Its close ends the last membership: the group's datagrams stop there.
    assert_eq!(w.call(nr::close, [t, 0, 0, 0, 0, 0]), 0);
    send(&mut w, &mut b, b"third");
    assert_eq!(
        w.call(nr::read, [s, data, 64, 0, 0, 0]),
        err(Errno::EAGAIN),
        "no longer joined"
    );
}

/// Two guests' `eth0` joined through their frame ports, as two tenants of the NIC
/// partition's switch would be: each guest's stack sends and receives frames only through
/// the port calls (a port holds 2 frames: what does not fit is lost and sent again);
/// ARP, a TCP connection from one to the other, bytes both ways.
#[test]
fn two_guests_talk_through_their_frame_ports() {
    use crate::net::Net;
    let (rx, tx) = (0, 1);
    let (mut a, mut b) = two_eth0s();
    // Both run, then the wire carries what each sent to the other's rx port.
    let carry = |from: &mut Model, to: &mut Model| {
        for frame in from.port_sent.remove(&tx).unwrap_or_default() {
            let queue = to.port_messages.entry(rx).or_default();
            queue.push_back((frame, true));
        }
    };
    let step = |a: &mut (Net, Model), b: &mut (Net, Model)| {
        a.0.run(&mut a.1);
        b.0.run(&mut b.1);
        carry(&mut a.1, &mut b.1);
        carry(&mut b.1, &mut a.1);
    };
    let (c, s) = connect_to_b(&mut a, &mut b, step);
    let data: Vec<u8> = (0..20_000u32).map(|i| (i * 7) as u8).collect();
    let (mut sent, mut got) = (0, Vec::new());
    for _ in 0..400 {
        if sent < data.len() {
            sent += a.0.stack(0).send(c, &data[sent..], None).unwrap_or(0);
        }
        step(&mut a, &mut b);
        let mut buf = [0u8; 4096];
        while let Ok((n, _)) = b.0.stack(0).recv(s, &mut buf) {
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        if got.len() == data.len() {
            break;
        }
    }
    assert_eq!(got, data, "20,000 bytes across, in order");
    assert_eq!(b.0.stack(0).send(s, b"thanks", None), Ok(6));
    for _ in 0..5 {
        step(&mut a, &mut b);
    }
    let mut buf = [0u8; 16];
    assert_eq!(a.0.stack(0).recv(c, &mut buf).map(|r| r.0), Ok(6));
    let eth = a.0.interfaces()[1];
    assert!(
        eth.counters.tx_frames > 10 && eth.counters.rx_frames > 5,
        "{eth:?}"
    );
}

/// A guest's `eth0` through a frame ring, the test playing the NIC partition's side of
/// the ring and carrying frames to and from a second guest on ports: a TCP connection and
/// 20,000 bytes each way; the guest's `tx` port carries only one-byte wake-ups, fewer than
/// the frames, and it drains the wake-ups the "NIC" sends when its doorbell rang.
#[test]
fn a_guest_talks_through_its_frame_ring() {
    talk_through_a_frame_ring(None);
}

/// As [`a_guest_talks_through_its_frame_ring`], each side having named a thread to
/// notify in the ring: the guest notifies the "NIC" (no wake-up on its `tx` port) and is
/// notified (no wake-up on its `rx` port, nothing to drain); a thread the kernel refuses
/// to notify gets the port's wake-ups as before.
#[test]
fn a_guest_notifies_the_thread_its_ring_names_and_kicks_when_the_kernel_refuses() {
    talk_through_a_frame_ring(Some(7));
    talk_through_a_frame_ring(Some(REFUSED_THREAD));
}

/// A segment in the test's memory, cache-line aligned as a shared segment is.
#[repr(C, align(64))]
#[derive(Clone, Copy)]
struct Line([u8; 64]);

type RingEnds = (frame_ring::Producer, frame_ring::Consumer);

/// A frame ring in a fresh segment of `size` bytes: the segment (keep it for as long as
/// the ends live), the tenant's ends and the NIC partition's.
#[allow(unsafe_code)]
fn frame_ring_segment(size: usize) -> (Vec<Line>, RingEnds, RingEnds) {
    let mut segment = vec![Line([0; 64]); size / 64];
    let at = segment.as_mut_ptr() as *mut u8;
    // SAFETY: the caller keeps the segment (its heap block does not move with the Vec)
    // while the ends live, and only they write it.
    let tenant = unsafe { frame_ring::attach(at, size, frame_ring::Side::Tenant) }.unwrap();
    // SAFETY: as above.
    let driver = unsafe { frame_ring::attach(at, size, frame_ring::Side::Driver) }.unwrap();
    (segment, tenant, driver)
}

fn talk_through_a_frame_ring(nic_thread: Option<u64>) {
    use crate::net::Net;
    let (_segment, tenant, (mut nic_to, mut nic_from)) = frame_ring_segment(64 * 1024);
    let (rx, tx) = (0, 1);
    let (mut a, mut b) = two_eth0s();
    a.0.link_ring(tenant);
    const NIC_BITS: u64 = 1 << 24;
    if let Some(thread) = nic_thread {
        nic_from.wake_me(thread, NIC_BITS);
        a.0.wake_on_frames(3, 2);
    }
    let (mut frames_up, mut wakeups_up, mut notified_down) = (0, 0, 0);
    let mut buf = [0u8; frame_ring::MTU];
    let mut step = |a: &mut (Net, Model), b: &mut (Net, Model)| {
        a.0.run(&mut a.1);
        b.0.run(&mut b.1);
        // The NIC's side: the wake-ups from `a`, its frames to `b`, `b`'s frames into the
        // ring (a wake-up for `a` when one goes into an empty ring: its doorbell).
        for kick in a.1.port_sent.remove(&tx).unwrap_or_default() {
            assert_eq!(kick, [0], "only wake-ups on the tx port");
            wakeups_up += 1;
        }
        while let Some(frame) = nic_from.pop(&mut buf) {
            let len = frame.unwrap();
            frames_up += 1;
            let queue = b.1.port_messages.entry(rx).or_default();
            queue.push_back((buf[..len].to_vec(), true));
        }
        for frame in b.1.port_sent.remove(&tx).unwrap_or_default() {
            if !nic_to.push(&frame).unwrap().first {
                continue;
            }
            match nic_to.waiter() {
                Some(waiter) => {
                    assert_eq!(waiter, (3, 2), "the guest's doorbell thread and bit");
                    notified_down += 1;
                }
                None => {
                    a.1.port_messages
                        .entry(rx)
                        .or_default()
                        .push_back((vec![0], true));
                    a.0.messages_came();
                }
            }
        }
    };
    let (c, s) = connect_to_b(&mut a, &mut b, &mut step);
    let data: Vec<u8> = (0..20_000u32).map(|i| (i * 7) as u8).collect();
    let (mut sent, mut back, mut got, mut got_back) = (0, 0, Vec::new(), Vec::new());
    let mut chunk = [0u8; 4096];
    for _ in 0..600 {
        if sent < data.len() {
            sent += a.0.stack(0).send(c, &data[sent..], None).unwrap_or(0);
        }
        if back < data.len() {
            back += b.0.stack(0).send(s, &data[back..], None).unwrap_or(0);
        }
        step(&mut a, &mut b);
        while let Ok((n @ 1.., _)) = b.0.stack(0).recv(s, &mut chunk) {
            got.extend_from_slice(&chunk[..n]);
        }
        while let Ok((n @ 1.., _)) = a.0.stack(0).recv(c, &mut chunk) {
            got_back.extend_from_slice(&chunk[..n]);
        }
        if got.len() == data.len() && got_back.len() == data.len() {
            break;
        }
    }
    assert_eq!(got, data, "20,000 bytes up through the ring, in order");
    assert_eq!(
        got_back, data,
        "20,000 bytes down through the ring, in order"
    );
    let notified_up = a.1.notified.len();
    match nic_thread {
        Some(7) => {
            assert_eq!(wakeups_up, 0, "no wake-up on the port");
            assert!(notified_up > 0 && notified_up < frames_up);
            assert!(a.1.notified.iter().all(|&n| n == (7, NIC_BITS)));
            assert!(notified_down > 0);
        }
        _ => assert!(
            wakeups_up > 0 && wakeups_up < frames_up,
            "{wakeups_up} wake-ups for {frames_up} frames"
        ),
    }
    assert!(
        a.1.port_messages.get(&rx).is_none_or(|q| q.len() <= 1),
        "the wake-ups are drained"
    );
    assert_eq!((a.0.tx_dropped, a.0.rx_bad), (0, 0));
}

/// A guest told of the frames in its ring (its doorbell thread named in the ring) sets
/// no timer to look at the ring: an idle stack leaves it waiting. Without that it looks
/// again RX_POLL_NS after its last run, as at its `rx` port.
#[test]
fn only_a_ring_that_does_not_ring_is_looked_at_on_a_timer() {
    use crate::net::RX_POLL_NS;
    use netstack::{Ipv4Address, SocketAddr};
    for rings in [true, false] {
        let (_segment, tenant, _driver) = frame_ring_segment(64 * 1024);
        let mut net = eth0(1, 15);
        net.link_ring(tenant);
        if rings {
            net.wake_on_frames(3, 2);
        }
        let listener = net.stack(0).socket(2, 1, 0).unwrap();
        let any = SocketAddr::new(Ipv4Address::UNSPECIFIED, 80);
        net.stack(0).bind(listener, any).unwrap();
        net.stack(0).listen(listener, 4).unwrap();
        let mut host = Model::new(0);
        net.run(&mut host);
        let expected = (!rings).then_some(host.now + RX_POLL_NS);
        assert_eq!(net.poll_at_ns(), expected, "told of frames: {rings}");
    }
}

/// A run takes at most LIMITS.frames from the ring; the NIC partition notifies only when
/// a frame goes into an empty ring, so for what a run left the next run is due at once
/// (at the stack's floor), and once the ring is empty nothing is.
#[test]
fn frames_a_run_left_in_the_ring_are_due_at_once() {
    use crate::net::{LIMITS, MIN_POLL_GAP_NS};
    let (_segment, tenant, (mut nic_to, _)) = frame_ring_segment(512 * 1024);
    let mut net = eth0(1, 15);
    net.link_ring(tenant);
    net.wake_on_frames(3, 2);
    let mut host = Model::new(0);
    net.run(&mut host);
    assert_eq!(net.poll_at_ns(), None, "nothing to do");
    // Broadcasts of another host's, more than a run takes.
    let mut frame = [0u8; 60];
    frame[..6].fill(0xff);
    frame[6..12].copy_from_slice(&[2, 0, 0, 0, 0, 9]);
    assert!(nic_to.slots() as usize > LIMITS.frames + 5);
    for _ in 0..LIMITS.frames + 5 {
        nic_to.push(&frame).unwrap();
    }
    net.run(&mut host);
    assert_eq!(net.poll_at_ns(), Some(host.now + MIN_POLL_GAP_NS));
    net.run(&mut host);
    assert_eq!(net.poll_at_ns(), None, "the ring is empty");
}

#[test]
fn threads_share_their_process_and_futexes_wake_them() {
    let bytes = initramfs();
    let mut g = Guest::new(&bytes);
    // pthread_create's clone: shares all, TLS, parent tid word, child tid cleared at exit.
    let flags = 0x3d0f00;
    let (stack, parent_tid, child_tid) = (SCRATCH + 0x800, SCRATCH + 0x10, SCRATCH + 0x14);
    let tid = g.call(
        1,
        nr::clone,
        [flags, stack, parent_tid, child_tid, 0x7000, 0],
    );
    assert_eq!(tid, Some(2));
    assert_eq!(g.word(1, parent_tid), 2);
    let fault = ExceptionMessage::default();
    g.host.resumed.clear();
    let _ = g.system.serve(2, &mut g.fs, &mut g.host, fault);
    let (pid, m) = g.host.resumed[0];
    assert_eq!(pid, 2);
    assert_eq!((m.registers.rax, m.registers.rsp), (0, stack));
    assert_eq!(m.registers.fs_base, 0x7000, "CLONE_SETTLS");
    assert_eq!(g.call(2, nr::getpid, [0; 6]), Some(1));
    assert_eq!(
        g.host.answers,
        [(2, nr::getpid, 1)],
        "the kernel answers the thread's next getpid with its process's id"
    );
    assert_eq!(g.call(2, nr::gettid, [0; 6]), Some(2));
    assert_eq!(g.call(1, nr::gettid, [0; 6]), Some(1));
    // /proc/self is the process (the thread group), not the thread, as on Linux.
    let path = g.text(2, SCRATCH + 0x800, "/proc/self");
    assert_eq!(
        g.call(2, nr::readlink, [path, SCRATCH + 0x400, 16, 0, 0, 0]),
        Some(1)
    );
    assert_eq!(g.get(2, SCRATCH + 0x400, 1), b"1");
    let path = g.text(2, SCRATCH + 0x800, "/proc/self/stat");
    let fd = g.call(2, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    // Read below the stack and clear of the words the checks below use.
    let n = g
        .call(2, nr::read, [fd, SCRATCH + 0x400, 0x300, 0, 0, 0])
        .unwrap();
    let stat = String::from_utf8(g.get(2, SCRATCH + 0x400, n as usize)).unwrap();
    assert!(stat.starts_with("1 ("), "{stat}");
    assert_eq!(g.call(2, nr::close, [fd, 0, 0, 0, 0, 0]), Some(0));
    // Its own /proc/<tid> is there too (Linux's unlisted thread entry).
    let path = g.text(2, SCRATCH + 0x800, "/proc/2/stat");
    let fd = g.call(2, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    let n = g
        .call(2, nr::read, [fd, SCRATCH + 0x400, 0x300, 0, 0, 0])
        .unwrap();
    let stat = String::from_utf8(g.get(2, SCRATCH + 0x400, n as usize)).unwrap();
    assert!(stat.starts_with("2 ("), "{stat}");
    assert_eq!(g.call(2, nr::close, [fd, 0, 0, 0, 0, 0]), Some(0));
    // PR_SET_NAME names only the calling thread (Linux's per-thread comm).
    let first = g.system.process(1).unwrap().name().to_string();
    g.put(2, SCRATCH + 0x40, b"worker\0");
    assert_eq!(
        g.call(2, nr::prctl, [15, SCRATCH + 0x40, 0, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.system.process(2).unwrap().name(), "worker");
    assert_eq!(g.system.process(1).unwrap().name(), first);
    // One memory: what the thread maps and writes, the process has.
    let mapped = g
        .call(2, nr::mmap, [0, PAGE, 3, 0x22, u64::MAX, 0])
        .unwrap();
    assert!(g.system.process(1).unwrap().areas.find(mapped).is_some());
    g.put(2, SCRATCH + 0x20, b"thread");
    assert_eq!(g.get(1, SCRATCH + 0x20, 6), b"thread");
    // A futex wait blocks until a wake of the same word; the wake counts it.
    let word = SCRATCH + 0x30;
    assert_eq!(
        g.call(1, nr::futex, [word, 128, 1, 0, 0, 0]),
        Some(err(Errno::EAGAIN)),
        "the word is 0"
    );
    assert_eq!(g.call(1, nr::futex, [word, 128, 0, 0, 0, 0]), None);
    assert_eq!(g.call(2, nr::futex, [word + 4, 129, 1, 0, 0, 0]), Some(0));
    assert!(matches!(g.system.state(1), Some(State::Blocked(_))));
    let replies = g.serve(2, World::message(nr::futex, [word, 129, 5, 0, 0, 0], 0));
    assert!(
        replies.contains(&(2, 1)) && replies.contains(&(1, 0)),
        "{replies:?}"
    );
    // The thread's exit clears its tid word and wakes the joiner; the process goes on.
    g.put(1, child_tid, &2u32.to_le_bytes());
    assert_eq!(g.call(1, nr::futex, [child_tid, 128, 2, 0, 0, 0]), None);
    let replies = g.serve(2, World::message(nr::exit, [0; 6], 0));
    assert_eq!(replies, [(1, 0)]);
    assert_eq!(g.word(1, child_tid), 0);
    assert_eq!(g.pids(), [1]);
    assert!(g.host.released.contains(&2));
    // A thread that does not share everything is refused.
    assert_eq!(
        g.call(1, nr::clone, [0x10900, stack, 0, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
}

/// A guest on CPUs 1 and 2: new processes go to the CPU with fewer runnable threads (the
/// creator not counted; of equals, the creator's), `sched_setaffinity` moves them and is
/// inherited, a woken thread moves to a less loaded CPU, and `getcpu`,
/// `sched_getaffinity`, `/proc` and `/sys` say so.
#[test]
fn threads_are_placed_on_the_guests_cpus() {
    let bytes = initramfs();
    let mut g = Guest::with_cpus(&bytes, 0b110);
    let mask =
        |g: &mut Guest, pid: u32| u64::from_le_bytes(g.get(pid, SCRATCH, 8).try_into().unwrap());
    let getcpu = |g: &mut Guest, pid: u32| {
        g.put(pid, SCRATCH, &[0xff; 8]);
        assert_eq!(
            g.call(pid, nr::getcpu, [SCRATCH, SCRATCH + 4, 0, 0, 0, 0]),
            Some(0)
        );
        let b = g.get(pid, SCRATCH, 8);
        assert_eq!(b[4..], [0; 4], "node 0");
        u32::from_le_bytes(b[..4].try_into().unwrap())
    };
    assert_eq!(getcpu(&mut g, 1), 1, "init: the guest's first CPU");
    assert_eq!(g.call(1, nr::getcpu, [0; 6]), Some(0), "null pointers");
    assert_eq!(
        g.call(1, nr::sched_getaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(mask(&mut g, 1), 0b110);
    for len in [0, 4, 12] {
        assert_eq!(
            g.call(1, nr::sched_getaffinity, [0, len, SCRATCH, 0, 0, 0]),
            Some(err(Errno::EINVAL)),
            "{len}"
        );
    }
    assert_eq!(
        g.call(1, nr::sched_getaffinity, [999, 8, SCRATCH, 0, 0, 0]),
        Some(err(Errno::ESRCH))
    );
    // `xargs -P2`: the first child on the parent's CPU, the second on the other one.
    let a = g.fork(1);
    let b = g.fork(1);
    assert_eq!((g.host.cpu_of[&a], g.host.cpu_of[&b]), (1, 2));
    assert_eq!((getcpu(&mut g, a), getcpu(&mut g, b)), (1, 2));
    assert_eq!(
        g.call(1, nr::sched_getaffinity, [b.into(), 8, SCRATCH, 0, 0, 0]),
        Some(8),
        "another process's"
    );
    assert_eq!(mask(&mut g, 1), 0b110);
    // Its own affinity: CPU 1 only (a 4-byte mask); it moves there at once.
    g.put(b, SCRATCH, &0b10u32.to_le_bytes());
    assert_eq!(
        g.call(b, nr::sched_setaffinity, [0, 4, SCRATCH, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.host.moves.last(), Some(&(b, 1)));
    assert_eq!(getcpu(&mut g, b), 1);
    assert_eq!(
        g.call(b, nr::sched_getaffinity, [0, 16, SCRATCH, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(mask(&mut g, b), 0b10);
    // A mask without any of the guest's CPUs, a thread that does not exist.
    g.put(b, SCRATCH, &0b1001u64.to_le_bytes());
    assert_eq!(
        g.call(b, nr::sched_setaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(err(Errno::EINVAL))
    );
    g.put(b, SCRATCH, &0b110u64.to_le_bytes());
    assert_eq!(
        g.call(b, nr::sched_setaffinity, [999, 8, SCRATCH, 0, 0, 0]),
        Some(err(Errno::ESRCH))
    );
    // Inherited by fork: b's child may only run on CPU 1.
    let c = g.fork(b);
    assert_eq!(g.host.cpu_of[&c], 1);
    assert_eq!(
        g.call(c, nr::sched_getaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(mask(&mut g, c), 0b10);
    // /proc says where they are and may run.
    let path = g.text(1, SCRATCH + 0x800, &format!("/proc/{b}/status"));
    let fd = g.call(1, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    let n = g.call(1, nr::read, [fd, SCRATCH, 4096, 0, 0, 0]).unwrap();
    let status = String::from_utf8(g.get(1, SCRATCH, n as usize)).unwrap();
    assert!(
        status.contains("Cpus_allowed:\t2\nCpus_allowed_list:\t1\n"),
        "{status}"
    );
    assert_eq!(g.call(1, nr::close, [fd, 0, 0, 0, 0, 0]), Some(0));
    let path = g.text(1, SCRATCH + 0x800, &format!("/proc/{a}/stat"));
    let fd = g.call(1, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    let n = g.call(1, nr::read, [fd, SCRATCH, 4096, 0, 0, 0]).unwrap();
    let stat = String::from_utf8(g.get(1, SCRATCH, n as usize)).unwrap();
    assert_eq!(stat.split(' ').nth(38), Some("1"), "{stat}");
    assert_eq!(g.call(1, nr::close, [fd, 0, 0, 0, 0, 0]), Some(0));
    // Init moves a (on CPU 1) to CPU 2 by its pid; then all of b, c and init are on CPU 1,
    // a alone on CPU 2.
    g.put(1, SCRATCH, &0b100u64.to_le_bytes());
    assert_eq!(
        g.call(1, nr::sched_setaffinity, [a.into(), 8, SCRATCH, 0, 0, 0]),
        Some(0)
    );
    assert_eq!(g.host.moves.last(), Some(&(a, 2)));
    assert_eq!(getcpu(&mut g, a), 2);
    g.put(b, SCRATCH, &0b110u64.to_le_bytes());
    assert_eq!(
        g.call(b, nr::sched_setaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(0),
        "CPU 1 still allowed: no move"
    );
    assert_eq!(g.host.moves.last(), Some(&(a, 2)));
    // a ends; init waits for its children, c sleeps: b runs alone on CPU 1. When c
    // wakes, CPU 2 has nobody: it moves there before its reply.
    assert_eq!(g.serve(a, World::message(nr::exit_group, [0; 6], 0)), []);
    let status = SCRATCH + 0x100;
    let _ = g.call(1, nr::wait4, [a.into(), status, 0, 0, 0, 0]);
    assert_eq!(
        g.call(1, nr::wait4, [u64::MAX, status, 0, 0, 0, 0]),
        None,
        "waits"
    );
    g.put(c, SCRATCH, &0b110u64.to_le_bytes());
    assert_eq!(
        g.call(c, nr::sched_setaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(0)
    );
    // 2 s: the model's clock advances 1.5 s per reading.
    g.put(
        c,
        SCRATCH,
        &[2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    );
    assert!(
        g.serve(c, on_stack(nr::nanosleep, [SCRATCH, 0, 0, 0, 0, 0]))
            .is_empty()
    );
    g.host.now = g.host.now.max(g.system.next_timer().unwrap());
    assert_eq!(g.system.tick(&mut g.fs, &mut g.host, false), None);
    assert_eq!(
        g.host.moves.last(),
        Some(&(c, 2)),
        "woken onto the idle CPU"
    );
    assert_eq!(getcpu(&mut g, c), 2);
    // execve keeps the CPU and the affinity.
    let path = g.text(c, SCRATCH + 0x800, "/bin/sh");
    assert!(g.call(c, nr::execve, [path, 0, 0, 0, 0, 0]).is_some());
    assert_eq!(
        g.call(c, nr::mmap, [SCRATCH, PAGE, 3, 0x32, u64::MAX, 0]),
        Some(SCRATCH),
        "the new image's scratch page"
    );
    assert_eq!(getcpu(&mut g, c), 2);
    assert_eq!(
        g.call(c, nr::sched_getaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(mask(&mut g, c), 0b110);

    // The C libraries' and `nproc --all`'s view: sysfs's lists and a directory per CPU
    // (asked by b: init waits).
    g.fs.set_cpus(0b110).unwrap();
    let path = g.text(b, SCRATCH + 0x800, "/sys/devices/system/cpu/online");
    let fd = g.call(b, nr::open, [path, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!(g.call(b, nr::read, [fd, SCRATCH, 64, 0, 0, 0]), Some(4));
    assert_eq!(g.get(b, SCRATCH, 4), b"1-2\n");
    for dir in ["cpu1", "cpu2"] {
        let path = g.text(
            b,
            SCRATCH + 0x800,
            &format!("/sys/devices/system/cpu/{dir}"),
        );
        assert_eq!(
            g.call(b, nr::access, [path, 0, 0, 0, 0, 0]),
            Some(0),
            "{dir}"
        );
    }
}

/// A one-CPU guest places nothing and moves nothing, wherever its CPU is.
#[test]
fn a_one_cpu_guest_keeps_every_thread_on_its_cpu() {
    let bytes = initramfs();
    let mut g = Guest::with_cpus(&bytes, 0b10);
    let a = g.fork(1);
    let b = g.fork(a);
    assert_eq!((g.host.cpu_of[&a], g.host.cpu_of[&b]), (1, 1));
    assert_eq!(
        g.call(b, nr::sched_getaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(8)
    );
    assert_eq!(g.get(b, SCRATCH, 8), 0b10u64.to_le_bytes());
    g.put(b, SCRATCH, &1u64.to_le_bytes());
    assert_eq!(
        g.call(b, nr::sched_setaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(err(Errno::EINVAL)),
        "CPU 0 is not the guest's"
    );
    g.put(b, SCRATCH, &u64::MAX.to_le_bytes());
    assert_eq!(
        g.call(b, nr::sched_setaffinity, [0, 8, SCRATCH, 0, 0, 0]),
        Some(0)
    );
    assert!(g.host.moves.is_empty());
}
