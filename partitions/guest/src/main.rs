//! The guest partition program: reads its initramfs (its data entry), starts the first
//! Linux process (`/etc/guest/init`, from `guest.init`) in a child task without
//! `native_syscalls` whose thread has this thread as exception handler, and serves the
//! system calls and faults of it and of the processes it forks (each a task of its own)
//! with the library's process table ([`guest::system::System`]): it receives the exception
//! message of any process's thread and replies when the library says so, perhaps much
//! later (a call that waits). When init ends, the other processes end too, and it reports `init exited with status <n>` (or `killed by signal <n>`) to the
//! health monitor as an application error, as Linux panics when init ends: the
//! configuration's health table decides (restart the guest, or end a test run).
//!
//! Its memory pool (syssw maps it at `POOL_BASE`, read-write, and at `POOL_EXEC_BASE`,
//! read-execute) is cut into: its own IPC buffer, the backing table, the frames that back
//! the processes' pages (the backing table's key is the pid above the page address), and
//! at its end the heap ([`HEAP_SHARE`] of the pool). The heap holds the file system
//! ([`guest::vfs`]: written file data, names, the open file descriptions), whose byte
//! limit is half the heap: the other half absorbs what reallocation (a growing file's old
//! and new buffers), fragmentation and the tables around the data take, so a full file
//! system answers `ENOSPC` before an allocation can fail. Its stack holds the process
//! table (the configuration gives a guest at least 1 MiB).
//! This file is glue only: every decision about a Linux call is the library's.
#![no_std]
#![no_main]

use guest::backing::{Backing, ENTRY};
use guest::console::{LineBuffer, stream_name};
use guest::cpio::Archive;
use guest::linux::Errno;
use guest::memory::Areas;
use guest::memory::{PAGE, Rights};
use guest::pool::PagePool;
use guest::process::Stream;
use guest::syscall::{Host, Outcome};
use guest::system::{INIT_PID, Joined, MAX_PROCESSES, System, Tasks};
use guest::vfs::Fs;
use user_rt::abi::ipc::{
    EXCEPTION_MESSAGE_SIZE, ExceptionMessage, IPC_BUFFER_SIZE, LABEL_EXCEPTION, LABEL_SYSCALL,
    MessageTag, REPLY_RESUME,
};
use user_rt::abi::syscall::{
    Abilities, MAP_MAX_PAGES, PageRights, TIMEOUT_INFINITE, TaskId, ThreadAttribute, ThreadId,
};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::partition::{POOL_BASE, POOL_EXEC_BASE, StartInfo};
use user_rt::println;
use user_rt::protocol::{ErrorCode, Request};
use user_rt::sys::{self, Message};

user_rt::entry!(main);

/// Pages of the pool the IPC buffer takes (at its start).
const IPC_PAGES: u64 = (IPC_BUFFER_SIZE as u64).div_ceil(PAGE);
/// The part of the pool that is the heap (1/4: the processes' pages keep the rest; a
/// busybox shell session needs a few MiB of frames, its files far less).
const HEAP_SHARE: u64 = 4;

/// The global allocator over the heap part of the pool (the guest has one thread: the
/// lock is never contended).
struct GuestHeap(spin::mutex::SpinMutex<linked_list_allocator::Heap>);

#[allow(unsafe_code)]
// SAFETY: allocation and deallocation go to the one heap under its lock; a failed
// allocation returns null, as GlobalAlloc wants.
unsafe impl core::alloc::GlobalAlloc for GuestHeap {
    unsafe fn alloc(&self, layout: core::alloc::Layout) -> *mut u8 {
        self.0
            .lock()
            .allocate_first_fit(layout)
            .map_or(core::ptr::null_mut(), |p| p.as_ptr())
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: core::alloc::Layout) {
        if let Some(p) = core::ptr::NonNull::new(ptr) {
            #[allow(unsafe_code)]
            // SAFETY: `ptr` came from `alloc` with this layout (GlobalAlloc's contract).
            unsafe {
                self.0.lock().deallocate(p, layout)
            };
        }
    }
}

#[global_allocator]
static HEAP: GuestHeap = GuestHeap(spin::mutex::SpinMutex::new(
    linked_list_allocator::Heap::empty(),
));

fn main(start: u64, _: u64) {
    #[allow(unsafe_code)]
    // SAFETY: syssw starts every partition with the start record's address in rdi.
    let Some(info) = (unsafe { StartInfo::from_start(start) }) else {
        println!("guest: no start record from syssw");
        return;
    };
    user_rt::service::set_server(ThreadId(info.server));
    let heap_pages = info.pool_len / PAGE / HEAP_SHARE;
    let pool_pages = info.pool_len / PAGE - heap_pages;
    // The backing table: one entry per frame it can hand out.
    let table_pages = (pool_pages * ENTRY as u64).div_ceil(PAGE + ENTRY as u64);
    if pool_pages < IPC_PAGES + table_pages + 1 || heap_pages == 0 {
        println!(
            "guest: no memory pool ({} KiB): give the partition the `map` ability and more `memory`",
            info.pool_len / 1024
        );
        return;
    }
    #[allow(unsafe_code)]
    // SAFETY: syssw mapped the pool read-write at POOL_BASE for this partition alone; its
    // first IPC_PAGES pages are used only through this IpcBufferRef.
    let ipc = unsafe { IpcBufferRef::new(POOL_BASE) };
    let (me, _) = sys::thread_self();
    if let Err(e) = sys::thread_set(None, ThreadAttribute::IpcBuffer, ipc.address()) {
        println!("guest: cannot register its IPC buffer: {e:?}");
        return;
    }
    let table_base = POOL_BASE + IPC_PAGES * PAGE;
    let frames_page = IPC_PAGES + table_pages;
    let frame_count = pool_pages - frames_page;
    #[allow(unsafe_code)]
    // SAFETY: the pool after the IPC buffer up to the heap, mapped read-write for this
    // partition alone and never unmapped while it runs; this is the only reference to it
    // (the read-execute alias is only ever a `map` source).
    let rest = unsafe {
        core::slice::from_raw_parts_mut(
            table_base as *mut u8,
            ((table_pages + frame_count) * PAGE) as usize,
        )
    };
    let (table, frames) = rest.split_at_mut((table_pages * PAGE) as usize);
    let heap_base = POOL_BASE + pool_pages * PAGE;
    let heap_size = (heap_pages * PAGE) as usize;
    #[allow(unsafe_code)]
    // SAFETY: the last heap_pages pages of the pool, mapped read-write for this partition
    // alone, lie after `rest` and are used by nothing else; the heap is set up once,
    // before anything allocates.
    unsafe {
        HEAP.0.lock().init(heap_base as *mut u8, heap_size)
    };

    let archive = match Archive::new(info.data()) {
        Ok(archive) => archive,
        Err(e) => {
            println!("guest: its initramfs (data entry) is unreadable: {e}");
            return;
        }
    };
    let mut args = [&b""[..]; guest::stack::MAX_STRINGS];
    let mut env = [&b""[..]; guest::stack::MAX_STRINGS];
    let argc = archive
        .get(guest::INIT_ARGS_PATH)
        .map_or(0, |e| guest::split_nul(e.data, &mut args));
    let envc = archive
        .get(guest::INIT_ENV_PATH)
        .map_or(0, |e| guest::split_nul(e.data, &mut env));
    let mut fs = match Fs::new(&archive, heap_size / 2) {
        Ok(fs) => fs,
        Err(e) => {
            println!(
                "guest: its initramfs does not fit its heap of {} KiB: {}",
                heap_size / 1024,
                e.describe()
            );
            return;
        }
    };
    fs.set_memory(info.pool_len);

    let mcp = (info.priority as u8).saturating_sub(1).max(1);
    let mut host = GuestHost {
        frames,
        first_frame: frames_page,
        pool: PagePool::new(frame_count as usize),
        backing: Backing::new(table),
        current: INIT_PID,
        tasks: [const { None }; MAX_PROCESSES],
        mcp,
        handler: me,
        ipc,
        started: sys::clock(),
        seed: sys::rdtsc() | 1,
    };
    let task = match sys::task_create(Abilities::empty(), mcp, 0, "init") {
        Ok(t) => t,
        Err(e) => {
            println!("guest: task_create failed: {e:?}");
            return;
        }
    };
    host.tasks[0] = Some(Task::new(INIT_PID, task));
    let argv = &args[..argc];
    let loaded = match guest::exec::load(&fs, &mut host, INIT_PID, 0, argv, &env[..envc], hwcap()) {
        Ok(l) => l,
        Err(e) => {
            let path = argv
                .first()
                .map_or("", |p| core::str::from_utf8(p).unwrap_or("?"));
            println!("guest: cannot start {path}: {e}");
            host.release(INIT_PID);
            report(ipc, Outcome::Exit(127));
            return;
        }
    };
    println!(
        "guest: process {} ({}) started: {}",
        loaded.process.pid,
        loaded.process.name(),
        Joined(argv)
    );
    match start_thread(task, loaded.entry, loaded.sp, mcp, me) {
        Ok(thread) => {
            if let Some(t) = host.tasks[0].as_mut() {
                t.thread = thread;
            }
        }
        Err(e) => {
            println!("guest: cannot start the process's thread: {e:?}");
            host.release(INIT_PID);
            report(ipc, Outcome::Killed(guest::linux::SIGSEGV));
            return;
        }
    }

    let mut system = System::new(loaded.process, hwcap());
    let outcome = loop {
        let received = match sys::receive(None, TIMEOUT_INFINITE) {
            Ok(r) => r,
            Err(e) => {
                println!("guest: receive failed: {e:?}");
                break Outcome::Killed(guest::linux::SIGSEGV);
            }
        };
        let tag = received.message.tag;
        let from_kernel = matches!(tag.label(), LABEL_SYSCALL | LABEL_EXCEPTION)
            && tag.len() == EXCEPTION_MESSAGE_SIZE;
        let Some(pid) = host.pid_of(received.sender).filter(|_| from_kernel) else {
            continue;
        };
        if let Some(ended) = system.serve(pid, &mut fs, &mut host, ipc.exception()) {
            break ended;
        }
    };
    let left = system.pids().filter(|&pid| pid != INIT_PID).count();
    println!("guest: init ended with {left} other processes left");
    system.release_all(&mut fs, &mut host);
    report(ipc, outcome);
}

/// Creates the process's thread (the guest as its exception handler; it runs in the guest's
/// time partition, as every thread in its creator's) and starts it.
fn start_thread(
    task: TaskId,
    entry: u64,
    sp: u64,
    priority: u8,
    handler: ThreadId,
) -> Result<ThreadId, user_rt::abi::syscall::Error> {
    let thread = sys::thread_create(Some(task), entry, sp, priority, 0)?;
    sys::thread_set(Some(thread), ThreadAttribute::ExceptionHandler, handler.0)?;
    sys::thread_start(thread)?;
    Ok(thread)
}

/// Reports the end of init to the health monitor.
fn report(ipc: IpcBufferRef, outcome: Outcome) {
    let mut detail = [0u8; 64];
    let text = match outcome {
        Outcome::Killed(signal) => {
            format(&mut detail, format_args!("init killed by signal {signal}"))
        }
        Outcome::Exit(status) => format(
            &mut detail,
            format_args!("init exited with status {status}"),
        ),
        _ => "",
    };
    println!("guest: {text}");
    if let Some(server) = user_rt::service::server() {
        let request = Request::ReportError {
            error: ErrorCode::ApplicationError,
            detail: text.as_bytes(),
        };
        let _ = user_rt::service::request(server, ipc, &request);
    }
}

/// Formats into `buf` (cut at its end).
fn format<'b>(buf: &'b mut [u8], args: core::fmt::Arguments) -> &'b str {
    struct Cursor<'c> {
        buf: &'c mut [u8],
        len: usize,
    }
    impl core::fmt::Write for Cursor<'_> {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            let n = s.len().min(self.buf.len() - self.len);
            self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
            self.len += n;
            Ok(())
        }
    }
    let mut c = Cursor { buf, len: 0 };
    let _ = core::fmt::write(&mut c, args);
    let len = c.len;
    core::str::from_utf8(&buf[..len]).unwrap_or("")
}

/// CPUID leaf 1's EDX: what Linux passes as `AT_HWCAP` on x86-64.
fn hwcap() -> u64 {
    core::arch::x86_64::__cpuid(1).edx as u64
}

/// Bytes shown as text, invalid UTF-8 as `\x..` escapes.
struct Lossy<'a>(&'a [u8]);

impl core::fmt::Display for Lossy<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for chunk in self.0.utf8_chunks() {
            f.write_str(chunk.valid())?;
            for b in chunk.invalid() {
                write!(f, "\\x{b:02x}")?;
            }
        }
        Ok(())
    }
}

/// A process's kernel objects and its console lines in progress.
struct Task {
    pid: u32,
    task: TaskId,
    thread: ThreadId,
    out: [LineBuffer; 2],
}

impl Task {
    fn new(pid: u32, task: TaskId) -> Self {
        Self {
            pid,
            task,
            thread: ThreadId(0),
            out: [LineBuffer::new(), LineBuffer::new()],
        }
    }
}

/// The backing table's key of page `page` of process `pid` (user addresses are below
/// 2^47: the pid takes the bits above).
fn key(pid: u32, page: u64) -> u64 {
    (pid as u64) << 48 | page
}

/// The kernel side of the library's [`Host`] and [`Tasks`]: the processes' tasks, the
/// guest's frames and which of them back which process page.
struct GuestHost<'p> {
    /// The frames (pool pages from `first_frame` on), read-write.
    frames: &'p mut [u8],
    first_frame: u64,
    pool: PagePool,
    backing: Backing<'p>,
    /// The process the memory calls act on.
    current: u32,
    tasks: [Option<Task>; MAX_PROCESSES],
    /// Priority of the processes' threads.
    mcp: u8,
    /// This thread: the exception handler of the processes' threads.
    handler: ThreadId,
    ipc: IpcBufferRef,
    started: u64,
    seed: u64,
}

impl GuestHost<'_> {
    fn task(&self, pid: u32) -> Option<&Task> {
        self.tasks.iter().flatten().find(|t| t.pid == pid)
    }

    fn pid_of(&self, thread: ThreadId) -> Option<u32> {
        self.tasks
            .iter()
            .flatten()
            .find(|t| t.thread == thread)
            .map(|t| t.pid)
    }

    fn frame(&mut self, index: usize) -> &mut [u8] {
        let at = index * PAGE as usize;
        &mut self.frames[at..at + PAGE as usize]
    }

    /// Maps frames `index..index + pages` at `start` in process `pid` with `rights`.
    fn map_frames(
        &self,
        pid: u32,
        index: usize,
        start: u64,
        pages: u64,
        rights: Rights,
    ) -> Result<(), Errno> {
        let task = self.task(pid).ok_or(Errno::ENOMEM)?.task;
        let (base, kernel_rights) = if rights.contains(Rights::EXECUTE) {
            (POOL_EXEC_BASE, PageRights::EXECUTE)
        } else if rights.contains(Rights::WRITE) {
            (POOL_BASE, PageRights::WRITE)
        } else {
            (POOL_BASE, PageRights::empty())
        };
        let mut done = 0;
        while done < pages {
            let n = (pages - done).min(MAP_MAX_PAGES);
            let source = base + (self.first_frame + index as u64 + done) * PAGE;
            sys::map(Some(task), source, start + done * PAGE, n, kernel_rights)
                .map_err(|_| Errno::ENOMEM)?;
            done += n;
        }
        Ok(())
    }

    /// Backs and maps one run of pages with fresh frames (one contiguous run if the pool has
    /// one, else page by page).
    fn back(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno> {
        let pid = self.current;
        if let Some(index) = self.pool.alloc(pages as usize) {
            for i in 0..pages as usize {
                self.frame(index + i).fill(0);
            }
            for i in 0..pages {
                if self
                    .backing
                    .insert(key(pid, start + i * PAGE), index + i as usize)
                    .is_err()
                {
                    for j in i..pages {
                        self.pool.free(index + j as usize);
                    }
                    return Err(Errno::ENOMEM);
                }
            }
            return self.map_frames(pid, index, start, pages, rights);
        }
        for i in 0..pages {
            let index = self.pool.alloc(1).ok_or(Errno::ENOMEM)?;
            self.frame(index).fill(0);
            let page = start + i * PAGE;
            if self.backing.insert(key(pid, page), index).is_err() {
                self.pool.free(index);
                return Err(Errno::ENOMEM);
            }
            self.map_frames(pid, index, page, 1, rights)?;
        }
        Ok(())
    }

    /// The frame bytes behind address `address` of the current process and how many of
    /// them lie in its page.
    fn locate(&self, address: u64) -> Option<(usize, usize)> {
        let page = address & !(PAGE - 1);
        let index = self.backing.get(key(self.current, page))?;
        let offset = (address - page) as usize;
        Some((index * PAGE as usize + offset, PAGE as usize - offset))
    }

    /// Copies the current process's backed pages into process `child` (whose task
    /// exists); returns how many. Each run of backed pages in one area goes into one run of
    /// frames where the pool has one, mapped with one call.
    fn copy_pages(&mut self, child: u32, areas: &Areas) -> Result<u64, Errno> {
        let parent = self.current;
        let size = PAGE as usize;
        let mut copied = 0;
        let mut at = key(parent, 0);
        while let Some((k, _)) = self.backing.first_from(at)
            && k < key(parent + 1, 0)
        {
            let start = k - key(parent, 0);
            let area = areas.find(start);
            let area_end = area.map_or(start + PAGE, |a| a.end);
            let mut pages = 1;
            while start + pages * PAGE < area_end && self.backing.get(k + pages * PAGE).is_some() {
                pages += 1;
            }
            let run = match self.pool.alloc(pages as usize) {
                Some(run) => run,
                None => {
                    pages = 1;
                    self.pool.alloc(1).ok_or(Errno::ENOMEM)?
                }
            };
            for i in 0..pages {
                let to = run + i as usize;
                let Some(from) = self.backing.get(k + i * PAGE) else {
                    self.pool.free(to);
                    continue;
                };
                self.frames
                    .copy_within(from * size..(from + 1) * size, to * size);
                if self
                    .backing
                    .insert(key(child, start + i * PAGE), to)
                    .is_err()
                {
                    for j in i..pages {
                        self.pool.free(run + j as usize);
                    }
                    return Err(Errno::ENOMEM);
                }
            }
            if let Some(area) = area
                && area.rights.accessible()
            {
                self.map_frames(child, run, start, pages, area.rights)?;
            }
            copied += pages;
            at = k + pages * PAGE;
        }
        Ok(copied)
    }
}

impl Host for GuestHost<'_> {
    fn read_user(&mut self, address: u64, buf: &mut [u8]) -> Result<(), Errno> {
        let mut done = 0;
        while done < buf.len() {
            let (at, room) = self.locate(address + done as u64).ok_or(Errno::EFAULT)?;
            let n = room.min(buf.len() - done);
            buf[done..done + n].copy_from_slice(&self.frames[at..at + n]);
            done += n;
        }
        Ok(())
    }

    fn write_user(&mut self, address: u64, data: &[u8]) -> Result<(), Errno> {
        let mut done = 0;
        while done < data.len() {
            let (at, room) = self.locate(address + done as u64).ok_or(Errno::EFAULT)?;
            let n = room.min(data.len() - done);
            self.frames[at..at + n].copy_from_slice(&data[done..done + n]);
            done += n;
        }
        Ok(())
    }

    fn map_zeroed(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno> {
        if rights.writable_and_executable() {
            // The pool's two aliases are read-write and read-execute: no source for it.
            return Err(Errno::EACCES);
        }
        let result = self.back(start, pages, rights);
        if result.is_err() {
            self.unmap(start, pages);
        }
        result
    }

    fn unmap(&mut self, start: u64, pages: u64) {
        let Some(task) = self.task(self.current).map(|t| t.task) else {
            return;
        };
        for i in 0..pages {
            let page = start + i * PAGE;
            if let Some(index) = self.backing.remove(key(self.current, page)) {
                let _ = sys::unmap(Some(task), page, 1);
                self.pool.free(index);
            }
        }
    }

    fn protect(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno> {
        if rights.writable_and_executable() {
            return Err(Errno::EACCES);
        }
        let pid = self.current;
        let task = self.task(pid).ok_or(Errno::ENOMEM)?.task;
        for i in 0..pages {
            let page = start + i * PAGE;
            match self.backing.get(key(pid, page)) {
                Some(index) => {
                    let _ = sys::unmap(Some(task), page, 1);
                    if rights.accessible() {
                        self.map_frames(pid, index, page, 1, rights)?;
                    }
                }
                None if rights.accessible() => self.back(page, 1, rights)?,
                None => {}
            }
        }
        Ok(())
    }

    fn console_write(&mut self, pid: u32, stream: Stream, bytes: &[u8]) {
        let Some(task) = self.tasks.iter_mut().flatten().find(|t| t.pid == pid) else {
            return;
        };
        let buffer = match stream {
            Stream::Stdout => &mut task.out[0],
            Stream::Stderr => &mut task.out[1],
        };
        buffer.write(bytes, |line| {
            println!(
                "guest: process {pid} {}: {}",
                stream_name(stream),
                Lossy(line)
            )
        });
    }

    fn now_ns(&mut self) -> u64 {
        sys::clock().saturating_sub(self.started)
    }

    /// Not cryptographically strong yet: xorshift64* seeded from the time-stamp counter.
    fn random(&mut self, buf: &mut [u8]) {
        for chunk in buf.chunks_mut(8) {
            self.seed ^= sys::rdtsc();
            self.seed ^= self.seed >> 12;
            self.seed ^= self.seed << 25;
            self.seed ^= self.seed >> 27;
            let word = self.seed.wrapping_mul(0x2545_f491_4f6c_dd1d).to_le_bytes();
            chunk.copy_from_slice(&word[..chunk.len()]);
        }
    }

    fn log(&mut self, line: core::fmt::Arguments) {
        println!("{line}");
    }
}

impl Tasks for GuestHost<'_> {
    fn select(&mut self, pid: u32) {
        self.current = pid;
    }

    fn fork(&mut self, child: u32, areas: &Areas) -> Result<u64, Errno> {
        let slot = self
            .tasks
            .iter()
            .position(Option::is_none)
            .ok_or(Errno::EAGAIN)?;
        let task = sys::task_create(Abilities::empty(), self.mcp, 0, "process")
            .map_err(|_| Errno::EAGAIN)?;
        self.tasks[slot] = Some(Task::new(child, task));
        let copied = self.copy_pages(child, areas);
        // The thread starts at address 0: its fetch fault asks the guest for the registers.
        let thread = copied.and_then(|_| {
            start_thread(task, 0, 0, self.mcp, self.handler).map_err(|_| Errno::EAGAIN)
        });
        match thread {
            Ok(thread) => {
                if let Some(t) = self.tasks[slot].as_mut() {
                    t.thread = thread;
                }
                copied
            }
            Err(e) => {
                self.release(child);
                Err(e)
            }
        }
    }

    fn release(&mut self, pid: u32) {
        let Some(slot) = self
            .tasks
            .iter()
            .position(|t| t.as_ref().is_some_and(|t| t.pid == pid))
        else {
            return;
        };
        let Some(mut task) = self.tasks[slot].take() else {
            return;
        };
        let _ = sys::task_kill(task.task);
        for (i, stream) in [Stream::Stdout, Stream::Stderr].into_iter().enumerate() {
            task.out[i].flush(|line| {
                println!(
                    "guest: process {pid} {}: {}",
                    stream_name(stream),
                    Lossy(line)
                )
            });
        }
        // The task's mappings went with it: only the frames are left to free.
        let mut at = key(pid, 0);
        while let Some((k, index)) = self.backing.first_from(at)
            && k < key(pid + 1, 0)
        {
            self.backing.remove(k);
            self.pool.free(index);
            at = k;
        }
    }

    fn resume(&mut self, pid: u32, m: &ExceptionMessage) {
        let Some(thread) = self.task(pid).map(|t| t.thread) else {
            return;
        };
        self.ipc.set_exception(m);
        let resume = Message {
            tag: MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0),
            words: [0; 3],
        };
        if let Err(e) = sys::reply(thread, &resume) {
            println!("guest: cannot resume process {pid}: {e:?}");
        }
    }
}
