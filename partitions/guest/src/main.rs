//! The guest partition program: reads its initramfs (its data entry), starts the first
//! Linux process (`/etc/guest/init`, from `guest.init`) in a child task without
//! `native_syscalls` whose thread has this thread as exception handler, and serves the
//! system calls and faults of it and of the processes it forks (each a task of its own)
//! with the library's process table ([`guest::system::System`]): it receives the exception
//! message of any process's thread and replies when the library says so, perhaps much
//! later (a call that waits), with its next receive in one kernel call where it can.
//! When init ends, the other processes end too, and it reports `init exited with status <n>` (or `killed by signal <n>`) to the
//! health monitor as an application error, as Linux panics when init ends: the
//! configuration's health table decides (restart the guest, or end a test run).
//!
//! Its memory pool (syssw maps it at `POOL_BASE`, read-write, and at `POOL_EXEC_BASE`,
//! read-execute) is cut into: its own IPC buffer, the backing table, the frames that back
//! the processes' pages ([`guest::frames`]; a frame is mapped into a process from the
//! read-execute alias for executable pages, else from the read-write one), and at its end
//! the heap ([`HEAP_SHARE`] of the pool). The heap holds the file system ([`guest::vfs`]:
//! written file data, names, the open file descriptions), whose byte limit is half the
//! heap: the other half absorbs what reallocation (a growing file's old and new buffers),
//! fragmentation and the tables around the data take, so a full file system answers
//! `ENOSPC` before an allocation can fail. Its stack holds the process table (the
//! configuration gives a guest at least 1 MiB).
//! This file is glue only: every decision about a Linux call is the library's, and every
//! decision about which process runs is [`guest::sched`]'s (this loop tells it of each
//! message and answer, asks it at every turn and when it said a decision is due, and sets
//! the priorities it names with `thread_set`).
//!
//! The CPUs: the guest's are its resource partition's (`rp_info`); its own thread starts
//! on the lowest and, with several, follows its callers (`follows_callers`): it serves
//! each message on the CPU of the thread that sent it. The library places each new thread
//! ([`guest::system`]); this file moves it there with `thread_set` of its CPU before it
//! starts, and moves a thread later only while it waits for the guest (its message being
//! served or its call waiting): a thread that may be running elsewhere is interrupted and
//! moved at the message that brings. A one-CPU guest makes no such call.
//!
//! The console: with `guest.console = "com2"` (the initramfs's `/etc/guest/console`) the
//! processes' console is a terminal ([`guest::tty`]) on COM2 ([`com2`]); without it, their
//! output lines go to the log and reading the console gives end of file.
//!
//! The ARINC ports: the initramfs's port table (`/etc/guest/ports`, from the partition's
//! `ports.*`) becomes `/dev/arinc/<port>` ([`guest::arinc`]); [`ports`] creates the ports
//! through syssw before the first process starts. The doorbell thread ([`doorbell`])
//! tells the guest when messages arrive at its queuing destination ports, and the calls
//! that wait are served again then; a call waiting for a sampling port (or any port,
//! should the doorbell be refused) is served again every [`PORT_POLL_NS`].
//!
//! The block device: with `guest.disk` (the initramfs's `/etc/guest/disk`) the guest has
//! `/dev/vda` ([`guest::disk`]) over the link's client (`blk_core::client`) on two of its
//! ports ([`ports::DiskLink`]: one request at a time, the guest waiting for its response,
//! at most 2 s); those two ports have no device in `/dev/arinc`.
#![no_std]
#![no_main]

extern crate alloc;

mod com2;
mod doorbell;
mod ports;

use guest::backing::ENTRY;
use guest::console::{LineBuffer, stream_name};
use guest::cpio::Archive;
use guest::frames::{Frames, Mapper};
use guest::linux::Errno;
use guest::memory::Areas;
use guest::memory::{PAGE, Rights};
use guest::process::Stream;
use guest::sched::Scheduler;
use guest::syscall::{Host, Outcome};
use guest::system::{INIT_PID, Joined, MAX_PROCESSES, System, Tasks};
use guest::tty::Tty;
use guest::vfs::Fs;
use user_rt::abi::ipc::{
    EXCEPTION_MESSAGE_SIZE, ExceptionMessage, IPC_BUFFER_SIZE, LABEL_EXCEPTION, LABEL_SYSCALL,
    MessageTag, REPLY_RESUME,
};
use user_rt::abi::syscall::{
    Abilities, Error as SysError, MAP_MAX_PAGES, PageRights, TIMEOUT_INFINITE, TaskId,
    ThreadAttribute, ThreadId, syscall_answer,
};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::partition::{POOL_BASE, POOL_EXEC_BASE, StartInfo};
use user_rt::println;
use user_rt::protocol::{ErrorCode, Request};
use user_rt::sys::{self, Message};

user_rt::entry!(main);

/// Processes left when init ends that are listed, each with what it was doing.
const LEFT_LINES: usize = 16;
/// How often calls that wait are served again while one waits for a port (a sampling
/// port's message rings no doorbell).
const PORT_POLL_NS: u64 = 1_000_000;
/// The reply that resumes a process with the registers of the exception message in the
/// IPC buffer.
const RESUME: Message = Message {
    tag: MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0),
    words: [0; 3],
};
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
    // The backing table: four entries per frame it can hand out (1.5% of the pool): a
    // shared frame backs a page of each process that shares it (after a `fork`, or a
    // program's image for every process running it), and the image cache's entry.
    const ENTRIES_PER_FRAME: u64 = 4;
    let entry_bytes = ENTRIES_PER_FRAME * ENTRY as u64;
    let table_pages = (pool_pages * entry_bytes).div_ceil(PAGE + entry_bytes);
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
    // The CPUs its processes' threads may run on; this thread runs on the lowest (syssw
    // starts it there), so every thread it creates starts there too.
    let cpus = match sys::rp_info(0) {
        Ok(usage) if usage.cpus != 0 => u64::from(usage.cpus),
        other => {
            println!("guest: its partition's CPUs are unknown ({other:?}): one CPU");
            1
        }
    };
    let home = cpus.trailing_zeros();
    if let Err(e) = sys::thread_set(None, ThreadAttribute::IpcBuffer, ipc.address()) {
        println!("guest: cannot register its IPC buffer: {e:?}");
        return;
    }
    // With several CPUs it serves each call and fault on the CPU of the thread that made
    // it: the work is that CPU's time, and a call costs no interrupt between CPUs (about
    // three times the time of a short process's calls on two CPUs otherwise).
    if cpus.count_ones() > 1
        && let Err(e) = sys::thread_set(None, ThreadAttribute::FollowsCallers, 1)
    {
        println!("guest: serves every call on CPU {home}: follows_callers refused ({e:?})");
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
    // Only a guest with several CPUs has /sys: a one-CPU guest's file system stays as it
    // was (the C libraries then count the CPUs with `sched_getaffinity`).
    if cpus.count_ones() > 1
        && let Err(e) = fs.set_cpus(cpus)
    {
        println!(
            "guest: no room for /sys/devices/system/cpu: {}",
            e.describe()
        );
    }
    // The ARINC ports of the configuration: created through syssw, devices in /dev/arinc.
    let port_table = match archive
        .get(guest::arinc::PORTS_PATH)
        .map(|e| guest::arinc::parse(e.data))
    {
        None => alloc::vec::Vec::new(),
        Some(Ok(table)) => table,
        Some(Err(e)) => {
            let path = guest::arinc::PORTS_PATH;
            println!("guest: {path} line {}: {}; no ports", e.line, e.reason);
            alloc::vec::Vec::new()
        }
    };
    let mut net = network(&archive, &port_table);
    let ports = ports::Ports::create(ThreadId(info.server), ipc, &port_table);
    let disk = disk(&archive, &port_table, &ports);
    // The doorbell watches the queuing ports the guest polls; the disk's response port is
    // waited on by the guest itself.
    let disk_response = disk
        .as_ref()
        .and_then(|(_, _, response)| port_table.iter().position(|p| p.name == *response));
    let watched = ports.queuing_destinations(disk_response);
    let bell = match watched.is_empty() {
        true => None,
        false => match doorbell::start(me, ThreadId(info.server), info.priority as u8, &watched) {
            Ok(thread) => Some(thread),
            Err(e) => {
                println!("guest: cannot start the ports' doorbell: {e:?}; they are polled");
                None
            }
        },
    };
    if let Some(bell) = bell {
        net.wake_on_frames(bell.0, doorbell::RING_BIT);
    }
    if let Err(e) = fs.set_ports(port_table) {
        println!("guest: no room for the port devices: {}", e.describe());
    }
    if let Some((_, request, response)) = &disk {
        // Its link is the guest's own: no process reaches the driver but through /dev/vda.
        fs.hide_port(request);
        fs.hide_port(response);
    }
    if let Some((disk, _, _)) = disk
        && let Err(e) = fs.set_disk(alloc::boxed::Box::new(disk))
    {
        println!("guest: no room for /dev/vda: {}", e.describe());
    }

    let mcp = (info.priority as u8).saturating_sub(1).max(1);
    let mut host = GuestHost {
        frames: Frames::new(frames, table),
        first_frame: frames_page,
        current: INIT_PID,
        tasks: [const { None }; MAX_PROCESSES],
        mcp,
        handler: me,
        ipc,
        clock: sys::TscBase::get(),
        started: sys::clock(),
        wall_clock_at_boot: sys::wall_clock_at_boot(),
        seed: sys::rdtsc() | 1,
        tty: None,
        ports,
        port_waiting: false,
        sched: Scheduler::with_cpus(0, cpus),
        cpus,
        home,
        moves_pending: false,
        levels_set: 0,
        new_thread: true,
        deferred: None,
    };
    let wants_terminal = archive
        .get(guest::CONSOLE_PATH)
        .is_some_and(|e| e.data.trim_ascii() == b"com2");
    let mut reader = None;
    if wants_terminal && !com2::init() {
        println!("guest: console: no UART at COM2's ports, the console is the log");
    } else if wants_terminal {
        match com2::start_reader(me, info.priority as u8) {
            Ok(thread) => {
                reader = Some(thread);
                host.tty = Some(Tty::new(INIT_PID));
            }
            Err(e) => println!("guest: console: cannot start the COM2 reader: {e:?}"),
        }
    }
    let task = match sys::task_create(Abilities::empty(), mcp, 0, "init") {
        Ok(t) => t,
        Err(e) => {
            println!("guest: task_create failed: {e:?}");
            return;
        }
    };
    host.tasks[0] = Some(Task::new(INIT_PID, task, home));
    let argv = &args[..argc];
    let mut loaded =
        match guest::exec::load(&fs, &mut host, INIT_PID, 0, argv, &env[..envc], hwcap()) {
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
    loaded.process.cpu = home;
    match start_thread(task, loaded.entry, loaded.sp, mcp, me, None) {
        Ok((thread, _)) => {
            if let Some(t) = host.tasks[0].as_mut() {
                (t.thread, t.priority) = (thread, mcp);
            }
        }
        Err(e) => {
            println!("guest: cannot start the process's thread: {e:?}");
            host.release(INIT_PID);
            report(ipc, Outcome::Killed(guest::signal::SIGSEGV));
            return;
        }
    }

    let mut system = System::new(loaded.process, hwcap());
    // The pipes' rings may take an eighth of the heap (the file system takes at most half).
    system.pipes = guest::pipe::Pipes::with_budget(heap_size / 8);
    system.net = net;
    let outcome = loop {
        // The scheduling policy ([`guest::sched`]) makes the decisions due, and the
        // processes' threads get the priorities of their levels.
        let now = host.now_ns();
        let decision = host.sched.decide(now);
        host.set_levels();
        // Wait for a message, or until the next sleep or alarm is due (a due one first:
        // a busy guest must not starve its timers), or the policy's next decision.
        let timeout = match system.next_timer() {
            Some(at) if at <= now => {
                // The calls served again say anew whether they wait for a port.
                let ports = core::mem::take(&mut host.port_waiting);
                if let Some(ended) = system.tick(&mut fs, &mut host, ports) {
                    break ended;
                }
                continue;
            }
            Some(at) => at - now,
            None => TIMEOUT_INFINITE,
        };
        // A call waiting for a port is served again at least every PORT_POLL_NS (a
        // sampling port has no doorbell).
        let timeout = if host.port_waiting && system.any_blocked() {
            timeout.min(PORT_POLL_NS)
        } else {
            timeout
        };
        let timeout = match decision {
            Some(at) => timeout.min(at.saturating_sub(now).max(1)),
            None => timeout,
        };
        let received = match host.receive(timeout) {
            Ok(r) => r,
            Err(user_rt::abi::syscall::Error::TimedOut) => {
                let ports = core::mem::take(&mut host.port_waiting);
                if let Some(ended) = system.tick(&mut fs, &mut host, ports) {
                    break ended;
                }
                continue;
            }
            Err(e) => {
                println!("guest: receive failed: {e:?}");
                break Outcome::Killed(guest::signal::SIGSEGV);
            }
        };
        let tag = received.message.tag;
        if reader == Some(received.sender) && tag.label() == com2::LABEL_INPUT {
            if let Some(ended) = console_input(&mut system, &mut fs, &mut host, &received.message) {
                break ended;
            }
            continue;
        }
        if bell == Some(received.sender) && tag.label() == doorbell::LABEL_RUNG {
            // Messages came to a port (eth0's wake-ups are drained, the calls waiting for
            // a port served), or only frames to eth0's ring.
            host.sched.outside();
            let ended = if received.message.words[0] & doorbell::PORT_BIT != 0 {
                system.net.messages_came();
                host.port_waiting = false; // the calls served again say it anew
                system.tick(&mut fs, &mut host, true)
            } else {
                system.frames_came(&mut fs, &mut host)
            };
            if let Some(ended) = ended {
                break ended;
            }
            continue;
        }
        let from_kernel = matches!(tag.label(), LABEL_SYSCALL | LABEL_EXCEPTION)
            && tag.len() == EXCEPTION_MESSAGE_SIZE;
        let Some(pid) = host.pid_of(received.sender).filter(|_| from_kernel) else {
            continue;
        };
        host.sched.received(pid);
        if host.moves_pending {
            host.settle(pid);
        }
        if let Some(ended) = system.serve(pid, &mut fs, &mut host, ipc.exception()) {
            break ended;
        }
    };
    host.flush();
    let left = system.pids().filter(|&pid| pid != INIT_PID).count();
    println!("guest: init ended with {left} other processes left");
    println!(
        "guest: waiting calls served again: {} ({} finished)",
        system.served_again, system.finished_again
    );
    for pid in system
        .pids()
        .filter(|&pid| pid != INIT_PID)
        .take(LEFT_LINES)
    {
        if let Some(process) = system.describe(pid) {
            println!("guest: left: {process}");
        }
    }
    system.release_all(&mut fs, &mut host);
    // As a shutdown: the mounted file system written back and marked clean.
    if let Some(path) = fs.mount_info().map(|m| m.path()) {
        match fs.umount(guest::vfs::Node::Mounted(ext2::ROOT_INO)) {
            Ok(()) => println!("guest: {path:?} unmounted"),
            Err(e) => println!("guest: {path:?} not unmounted: {}", e.describe()),
        }
    }
    report(ipc, outcome);
}

/// The guest's network: `lo`, and `eth0` when the initramfs has its configuration
/// ([`guest::net::NET_PATH`], from `guest.net`) with ports of the port table.
fn network(archive: &Archive, ports: &[guest::arinc::Port]) -> guest::net::Net {
    use guest::net::{NET_PATH, Net, parse_net_file};
    let Some(entry) = archive.get(NET_PATH) else {
        return Net::new(None);
    };
    let text = core::str::from_utf8(entry.data).unwrap_or("");
    let file = match parse_net_file(text) {
        Ok(file) => file,
        Err((line, why)) => {
            println!("guest: {NET_PATH} line {line}: {why}; no eth0");
            return Net::new(None);
        }
    };
    let index = |name: &str| ports.iter().position(|p| p.name == name);
    let (Some(rx), Some(tx)) = (index(file.rx), index(file.tx)) else {
        println!(
            "guest: {NET_PATH}: no port {} or {}; no eth0",
            file.rx, file.tx
        );
        return Net::new(None);
    };
    let c = file.config;
    let (m, a) = (c.mac, c.address.octets());
    println!(
        "guest: eth0 {:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x} {}.{}.{}.{}/{} through ports {} and {}",
        m[0], m[1], m[2], m[3], m[4], m[5], a[0], a[1], a[2], a[3], c.prefix, file.rx, file.tx
    );
    let mut net = Net::new(Some(c));
    net.link(rx, tx);
    if let Some((address, size)) = file.ring {
        let at = address as *mut u8;
        #[allow(unsafe_code)]
        // SAFETY: a segment of this partition and its NIC partition only (the configuration
        // tools' check), mapped read-write for its life; the tenant side's one attach.
        let ring = unsafe { frame_ring::attach(at, size, frame_ring::Side::Tenant) };
        match ring {
            Ok(ring) => {
                println!(
                    "guest: eth0 frames in a ring of {} slots each way at {address:#x}",
                    ring.0.slots()
                );
                net.link_ring(ring);
            }
            Err(e) => println!("guest: {NET_PATH}: {e}; eth0's frames go through its ports"),
        }
    }
    net
}

/// `/dev/vda`'s disk over its client, when the initramfs has its configuration
/// ([`guest::disk::DISK_PATH`], from `guest.disk`) with ports syssw created; with the names
/// of its two ports.
fn disk(
    archive: &Archive,
    table: &[guest::arinc::Port],
    ports: &ports::Ports,
) -> Option<(Disk, alloc::string::String, alloc::string::String)> {
    use guest::disk::{DISK_PATH, parse_disk_file};
    let entry = archive.get(DISK_PATH)?;
    let text = core::str::from_utf8(entry.data).unwrap_or("");
    let file = match parse_disk_file(text) {
        Ok(file) => file,
        Err((line, why)) => {
            println!("guest: {DISK_PATH} line {line}: {why}; no /dev/vda");
            return None;
        }
    };
    let index = |name: &str| table.iter().position(|p| p.name == name);
    let link = index(file.request)
        .zip(index(file.response))
        .and_then(|(request, response)| ports.disk_link(request, response));
    let Some(link) = link else {
        println!(
            "guest: {DISK_PATH}: no port {} or {}; no /dev/vda",
            file.request, file.response
        );
        return None;
    };
    println!(
        "guest: /dev/vda {} sectors through ports {} and {}",
        file.sectors, file.request, file.response
    );
    let client = blk_core::client::Client::new(link);
    Some((
        guest::disk::Disk::new(client, file.sectors, log_line),
        file.request.into(),
        file.response.into(),
    ))
}

/// `/dev/vda`'s disk: the link's client under the sector cache.
type Disk = guest::disk::Disk<blk_core::client::Client<ports::DiskLink>>;

/// A line of the log.
fn log_line(line: core::fmt::Arguments) {
    println!("{line}");
}

/// Input from the console: through the line discipline (echo to COM2, signals of the
/// control characters), then the calls waiting for it are served again.
fn console_input(
    system: &mut System,
    fs: &mut Fs,
    host: &mut GuestHost,
    m: &Message,
) -> Option<Outcome> {
    let (bytes, n) = com2::decode(m);
    for &b in &bytes[..n] {
        let signal = host.tty.as_mut()?.input(b, &mut com2::put);
        if let Some(s) = signal
            && let Some(ended) = system.signal_group(s.group, s.signal, fs, host)
        {
            return Some(ended);
        }
    }
    system.retry_blocked(fs, host)
}

/// Creates the process's thread (the guest as its exception handler; it runs in the guest's
/// time partition, as every thread in its creator's), moves it to `cpu` if one is given
/// (before it starts: a running thread may be on its CPU when the guest asks; without, it
/// runs on the guest's CPU) and starts it; with how the move went (refused: it runs on the
/// guest's CPU).
fn start_thread(
    task: TaskId,
    entry: u64,
    sp: u64,
    priority: u8,
    handler: ThreadId,
    cpu: Option<u32>,
) -> Result<(ThreadId, Result<(), SysError>), SysError> {
    let thread = sys::thread_create(Some(task), entry, sp, priority, 0)?;
    let moved = cpu.map_or(Ok(()), |cpu| {
        sys::thread_set(Some(thread), ThreadAttribute::Cpu, u64::from(cpu))
    });
    let started = sys::thread_set(Some(thread), ThreadAttribute::ExceptionHandler, handler.0)
        .and_then(|()| sys::thread_start(thread));
    match started {
        Ok(()) => Ok((thread, moved)),
        Err(e) => {
            let _ = sys::thread_kill(thread);
            Err(e)
        }
    }
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
    /// The priority its thread has (set at creation, then by [`GuestHost::set_levels`]).
    priority: u8,
    /// The process whose memory (task and frames) it uses: itself, or for a vfork child
    /// its parent's until it executes.
    memory: u32,
    /// The process that forked it (0: none).
    parent: u32,
    /// What it and its children copied on write: its next fork copies them at once.
    fork_writes: guest::frames::ForkWrites,
    out: [LineBuffer; 2],
    /// The CPU its thread runs on, and the one it is to move to at its next message (it
    /// was running when [`Tasks::set_cpu`] asked).
    cpu: u32,
    pending_cpu: Option<u32>,
}

impl Task {
    fn new(pid: u32, task: TaskId, cpu: u32) -> Self {
        Self {
            pid,
            task,
            cpu,
            pending_cpu: None,
            thread: ThreadId(0),
            priority: 0,
            memory: pid,
            parent: 0,
            fork_writes: guest::frames::ForkWrites::default(),
            out: [LineBuffer::new(), LineBuffer::new()],
        }
    }
}

/// The kernel side of [`Mapper`]: `map`, `unmap` and `protect` on the processes' tasks.
struct Spaces<'t> {
    tasks: &'t [Option<Task>],
    /// The pool page of frame 0.
    first_frame: u64,
}

impl Spaces<'_> {
    /// The task of the memory of `pid`.
    fn task(&self, pid: u32) -> Option<TaskId> {
        self.tasks
            .iter()
            .flatten()
            .find(|t| t.pid == pid && t.memory == pid)
            .map(|t| t.task)
    }
}

/// Calls `call(start, pages)` for `start..start + pages` in pieces the kernel takes.
fn in_pieces(start: u64, pages: u64, mut call: impl FnMut(u64, u64)) {
    let mut done = 0;
    while done < pages {
        let n = (pages - done).min(MAP_MAX_PAGES);
        call(start + done * PAGE, n);
        done += n;
    }
}

impl Mapper for Spaces<'_> {
    fn map(
        &mut self,
        pid: u32,
        frame: usize,
        start: u64,
        pages: u64,
        rights: Rights,
    ) -> Result<(), Errno> {
        let task = self.task(pid).ok_or(Errno::ENOMEM)?;
        let (base, kernel_rights) = if rights.contains(Rights::EXECUTE) {
            (POOL_EXEC_BASE, PageRights::EXECUTE)
        } else if rights.contains(Rights::WRITE) {
            (POOL_BASE, PageRights::WRITE)
        } else {
            (POOL_BASE, PageRights::empty())
        };
        let source = base + (self.first_frame + frame as u64) * PAGE;
        let mut result = Ok(());
        in_pieces(start, pages, |at, n| {
            if result.is_ok() {
                result = sys::map(Some(task), source + (at - start), at, n, kernel_rights)
                    .map_err(|_| Errno::ENOMEM);
            }
        });
        result
    }

    fn unmap(&mut self, pid: u32, start: u64, pages: u64) {
        if let Some(task) = self.task(pid) {
            in_pieces(start, pages, |at, n| {
                let _ = sys::unmap(Some(task), at, n);
            });
        }
    }

    fn write_protect(&mut self, pid: u32, start: u64, pages: u64) {
        if let Some(task) = self.task(pid) {
            in_pieces(start, pages, |at, n| {
                // Pages backed but not mapped make `protect` fail: unmapping does as well.
                if sys::protect(Some(task), at, n, PageRights::empty()).is_err() {
                    let _ = sys::unmap(Some(task), at, n);
                }
            });
        }
    }
}

/// The kernel side of the library's [`Host`] and [`Tasks`]: the processes' tasks, the
/// guest's frames and which of them back which process page.
struct GuestHost<'p> {
    frames: Frames<'p>,
    /// The pool page of frame 0.
    first_frame: u64,
    /// The process the memory calls act on.
    current: u32,
    tasks: [Option<Task>; MAX_PROCESSES],
    /// The processes' highest priority (their interactive level's).
    mcp: u8,
    /// This thread: the exception handler of the processes' threads.
    handler: ThreadId,
    ipc: IpcBufferRef,
    /// The kernel's clock, read without a system call (the guest reads it for every
    /// message it serves).
    clock: sys::TscBase,
    started: u64,
    /// Unix time in ns at boot (the firmware's clock), if the machine has one.
    wall_clock_at_boot: Option<u64>,
    seed: u64,
    /// The console's terminal (COM2), if the guest has one.
    tty: Option<Tty>,
    /// The ARINC ports of `/dev/arinc`.
    ports: ports::Ports,
    /// A call waited for a port when it was last served ([`Host::port_wait`]).
    port_waiting: bool,
    /// The scheduling policy: the level of each process's thread.
    sched: Scheduler,
    /// The guest's CPUs (bit n: CPU n), and the lowest, where its own thread starts.
    cpus: u64,
    home: u32,
    /// A thread is to move to another CPU at its next message ([`Task::pending_cpu`]).
    moves_pending: bool,
    /// The policy's generation the priorities were last set for.
    levels_set: u64,
    /// A thread was created (at `mcp`) since the priorities were last set.
    new_thread: bool,
    /// The reply [`Host::resume`] owes a process, sent with the next receive
    /// ([`GuestHost::receive`]: one kernel call for both) or before anything else acts on
    /// a process's thread ([`GuestHost::flush`]).
    deferred: Option<(ThreadId, u32, ExceptionMessage)>,
}

impl<'p> GuestHost<'p> {
    fn task(&self, pid: u32) -> Option<&Task> {
        self.tasks.iter().flatten().find(|t| t.pid == pid)
    }

    /// The process whose memory `pid` uses (its own, or a vfork parent's).
    fn memory_of(&self, pid: u32) -> u32 {
        self.task(pid).map_or(pid, |t| t.memory)
    }

    fn pid_of(&self, thread: ThreadId) -> Option<u32> {
        self.tasks
            .iter()
            .flatten()
            .find(|t| t.thread == thread)
            .map(|t| t.pid)
    }

    /// Creates and starts a process's thread in `task` on `cpu` (see [`start_thread`]);
    /// with the CPU it got. A CPU the kernel refuses (not online; syssw checked them all
    /// at start, so this is a defence) is logged and left out of the guest's from then on,
    /// and the thread stays where the guest's thread made it, taken to be the lowest.
    fn start_on(&mut self, task: TaskId, cpu: u32) -> Result<(ThreadId, u32), Errno> {
        // With several CPUs every thread is put on its CPU, not trusting where it starts.
        let wanted = (self.cpus.count_ones() > 1 || cpu != self.home).then_some(cpu);
        let (thread, moved) =
            start_thread(task, 0, 0, self.mcp, self.handler, wanted).map_err(|_| Errno::EAGAIN)?;
        if let Err(e) = moved {
            let home = self.home;
            println!("guest: CPU {cpu} refused ({e:?}): threads go to CPU {home} instead");
            self.cpus &= !(1u64 << cpu);
            return Ok((thread, home));
        }
        Ok((thread, cpu))
    }

    /// Moves `pid`'s thread to the CPU it was to move to while it ran, now that its
    /// message arrived (it waits for the answer, so the kernel lets it move).
    fn settle(&mut self, pid: u32) {
        let pending = self.task(pid).and_then(|t| t.pending_cpu);
        if let Some(cpu) = pending {
            self.set_cpu(pid, cpu);
        }
        self.moves_pending = self.tasks.iter().flatten().any(|t| t.pending_cpu.is_some());
    }

    /// Gives each process's thread the priority of its level in [`GuestHost::sched`]
    /// (`mcp`, one or two below), where it has another, if a level may have changed or a
    /// thread is new.
    fn set_levels(&mut self) {
        let generation = self.sched.generation();
        if generation == self.levels_set && !self.new_thread {
            return;
        }
        (self.levels_set, self.new_thread) = (generation, false);
        for t in self.tasks.iter_mut().flatten() {
            let priority = self.mcp.saturating_sub(self.sched.level(t.pid).below_top());
            if t.thread != ThreadId(0)
                && t.priority != priority
                && sys::thread_set(Some(t.thread), ThreadAttribute::Priority, priority as u64)
                    .is_ok()
            {
                t.priority = priority;
            }
        }
    }

    /// The next message, after the reply [`Host::resume`] deferred if there is one: the
    /// reply and the receive in one kernel call (`reply_wait`). A reply that fails (its
    /// process's thread is gone) is logged, and the message is then received alone.
    fn receive(&mut self, timeout: u64) -> Result<sys::Received, user_rt::abi::syscall::Error> {
        let Some((thread, pid, m)) = self.deferred.take() else {
            return sys::receive(None, timeout);
        };
        self.ipc.set_exception(&m);
        match sys::reply_wait(Some(thread), timeout, &RESUME) {
            Err(e) if e != user_rt::abi::syscall::Error::TimedOut => {
                println!("guest: cannot resume process {pid}: {e:?}");
                sys::receive(None, timeout)
            }
            received => received,
        }
    }

    /// Sends the deferred reply now: before the guest acts on a process's thread or task
    /// otherwise, so that each sees its calls' replies in the order they were given.
    fn flush(&mut self) {
        let Some((thread, pid, m)) = self.deferred.take() else {
            return;
        };
        self.ipc.set_exception(&m);
        if let Err(e) = sys::reply(thread, &RESUME) {
            println!("guest: cannot resume process {pid}: {e:?}");
        }
    }

    /// The frames and the kernel calls that map them.
    fn memory(&mut self) -> (&mut Frames<'p>, Spaces<'_>, u32) {
        let spaces = Spaces {
            tasks: &self.tasks,
            first_frame: self.first_frame,
        };
        let owner = self.memory_of(self.current);
        (&mut self.frames, spaces, owner)
    }
}

impl Host for GuestHost<'_> {
    fn read_user(&mut self, address: u64, buf: &mut [u8]) -> Result<(), Errno> {
        self.frames.read(self.memory_of(self.current), address, buf);
        Ok(())
    }

    fn write_user(&mut self, address: u64, data: &[u8]) -> Result<(), Errno> {
        let (frames, mut spaces, pid) = self.memory();
        frames.write(&mut spaces, pid, address, data)
    }

    fn map_image(
        &mut self,
        start: u64,
        pages: u64,
        rights: Rights,
        image: u32,
        fill: &mut dyn FnMut(u64, &mut [u8]),
    ) -> Result<(), Errno> {
        if rights.writable_and_executable() {
            // The pool's two aliases are read-write and read-execute: no source for it.
            return Err(Errno::EACCES);
        }
        let (frames, mut spaces, pid) = self.memory();
        let result = frames.back_image(&mut spaces, pid, start, pages, rights, image, fill);
        if result.is_err() {
            frames.release(&mut spaces, pid, start, pages);
        }
        result
    }

    fn unmap(&mut self, start: u64, pages: u64) {
        let (frames, mut spaces, pid) = self.memory();
        frames.release(&mut spaces, pid, start, pages);
        if let Some(t) = self.tasks.iter_mut().flatten().find(|t| t.pid == pid) {
            t.fork_writes.forget(start, start + pages * PAGE);
        }
    }

    fn protect(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno> {
        if rights.writable_and_executable() {
            return Err(Errno::EACCES);
        }
        let (frames, mut spaces, pid) = self.memory();
        frames.unmap(&mut spaces, pid, start, pages);
        Ok(())
    }

    fn move_pages(&mut self, from: u64, to: u64, pages: u64) {
        let (frames, mut spaces, pid) = self.memory();
        frames.move_pages(&mut spaces, pid, from, to, pages);
    }

    fn fill_in(&mut self, page: u64, fill: &mut dyn FnMut(&mut [u8])) -> Result<(), Errno> {
        let owner = self.memory_of(self.current);
        self.frames.fill_in(owner, page, fill)
    }

    fn fault_in(&mut self, page: u64, rights: Rights, write: bool) -> Result<(), Errno> {
        let (frames, mut spaces, pid) = self.memory();
        let Some(copied) = frames.fault_in(&mut spaces, pid, page, rights, write)? else {
            return Ok(());
        };
        let tasks = self.tasks.iter().flatten();
        let parent = tasks.clone().find(|t| t.pid == pid).map(|t| t.parent);
        let children = tasks
            .filter(|t| t.parent == pid && t.memory == t.pid)
            .map(|t| t.pid);
        let foreseers =
            self.frames
                .foreseers(pid, page, copied, parent.filter(|&p| p != 0), children);
        for t in self.tasks.iter_mut().flatten() {
            if foreseers.contains(&Some(t.pid)) {
                t.fork_writes.record(page);
            }
        }
        Ok(())
    }

    fn console_write(&mut self, pid: u32, stream: Stream, bytes: &[u8]) {
        if let Some(tty) = self.tty.as_mut() {
            return tty.write(bytes, &mut com2::put);
        }
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

    fn tty(&mut self) -> Option<&mut Tty> {
        self.tty.as_mut()
    }

    fn now_ns(&mut self) -> u64 {
        self.clock.now_ns().saturating_sub(self.started)
    }

    fn wall_clock_ns(&mut self) -> u64 {
        match self.wall_clock_at_boot {
            Some(at_boot) => at_boot.saturating_add(self.clock.now_ns()),
            None => self.now_ns(),
        }
    }

    fn memory(&mut self) -> (u64, u64) {
        let total = self.frames.total_frames() as u64;
        (total * PAGE, self.frames.free_frames() as u64 * PAGE)
    }

    fn fpu(&mut self, image: &mut [u8; 512]) -> Result<(), Errno> {
        let thread = self.task(self.current).ok_or(Errno::ESRCH)?.thread;
        sys::thread_fpu(thread, image, false).map_err(|_| Errno::EFAULT)
    }

    fn set_fpu(&mut self, image: &[u8; 512]) -> Result<(), Errno> {
        let thread = self.task(self.current).ok_or(Errno::ESRCH)?.thread;
        let mut copy = *image;
        sys::thread_fpu(thread, &mut copy, true).map_err(|_| Errno::EFAULT)
    }

    fn answer_always(&mut self, pid: u32, number: u64, result: u32) {
        let (Some(task), Ok(number)) = (self.task(pid), u32::try_from(number)) else {
            return;
        };
        // Should the kernel refuse, the guest goes on serving the call itself.
        let answer = syscall_answer(number, result);
        let _ = sys::thread_set(Some(task.thread), ThreadAttribute::SyscallAnswer, answer);
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

    fn port_send(&mut self, port: usize, message: &[u8]) -> Result<(), Errno> {
        self.ports.send(port, message)
    }

    fn port_receive(
        &mut self,
        port: usize,
        buf: &mut [u8],
    ) -> Result<guest::arinc::Received, Errno> {
        self.ports.receive(port, buf)
    }

    fn notify(&mut self, thread: u64, bits: u64) -> bool {
        sys::notify_signal(ThreadId(thread), bits).is_ok()
    }

    fn port_wait(&mut self) {
        self.port_waiting = true;
    }

    fn port_readiness(&mut self, port: usize) -> guest::arinc::Readiness {
        self.ports.readiness(port)
    }

    fn cpus(&mut self) -> u64 {
        self.cpus
    }
}

impl Tasks for GuestHost<'_> {
    fn select(&mut self, pid: u32) {
        self.current = pid;
    }

    fn fork(&mut self, child: u32, areas: &Areas, cpu: u32) -> Result<u64, Errno> {
        let slot = self
            .tasks
            .iter()
            .position(Option::is_none)
            .ok_or(Errno::EAGAIN)?;
        let task = sys::task_create(Abilities::empty(), self.mcp, 0, "process")
            .map_err(|_| Errno::EAGAIN)?;
        let parent = self.memory_of(self.current);
        let foreseen = self.task(parent).map(|t| t.fork_writes.clone());
        self.tasks[slot] = Some(Task {
            parent,
            ..Task::new(child, task, self.home)
        });
        let (frames, mut spaces, parent) = self.memory();
        let rights = |page| areas.find(page).map(|a| a.rights);
        let foreseen = foreseen.as_ref().map_or(&[][..], |w| w.pages());
        let copied = frames.share(&mut spaces, parent, child, rights, foreseen);
        // The thread starts at address 0: its fetch fault asks the guest for the registers.
        let thread = copied.and_then(|_| self.start_on(task, cpu));
        match thread {
            Ok((thread, cpu)) => {
                if let Some(t) = self.tasks[slot].as_mut() {
                    (t.thread, t.priority, t.cpu) = (thread, self.mcp, cpu);
                }
                self.sched.set_cpu(child, cpu);
                self.new_thread = true;
                copied
            }
            Err(e) => {
                self.release(child);
                Err(e)
            }
        }
    }

    fn borrow(&mut self, child: u32, parent: u32, cpu: u32) -> Result<(), Errno> {
        let slot = self
            .tasks
            .iter()
            .position(Option::is_none)
            .ok_or(Errno::EAGAIN)?;
        let owner = self.task(parent).ok_or(Errno::ESRCH)?;
        let (task, memory) = (owner.task, owner.memory);
        // The thread starts at address 0: its fetch fault asks the guest for the registers.
        let (thread, cpu) = self.start_on(task, cpu)?;
        self.tasks[slot] = Some(Task {
            thread,
            priority: self.mcp,
            memory,
            ..Task::new(child, task, cpu)
        });
        self.sched.set_cpu(child, cpu);
        self.new_thread = true;
        Ok(())
    }

    fn own(&mut self, pid: u32, cpu: u32) -> Result<bool, Errno> {
        let Some(slot) = self
            .tasks
            .iter()
            .position(|t| t.as_ref().is_some_and(|t| t.pid == pid && t.memory != pid))
        else {
            return Ok(false);
        };
        let task = sys::task_create(Abilities::empty(), self.mcp, 0, "process")
            .map_err(|_| Errno::EAGAIN)?;
        let (thread, cpu) = match self.start_on(task, cpu) {
            Ok(started) => started,
            Err(e) => {
                let _ = sys::task_kill(task);
                return Err(e);
            }
        };
        if let Some(t) = self.tasks[slot].as_mut() {
            let _ = sys::thread_kill(t.thread);
            (t.task, t.thread, t.priority, t.memory) = (task, thread, self.mcp, pid);
            (t.cpu, t.pending_cpu) = (cpu, None);
        }
        self.sched.set_cpu(pid, cpu);
        self.new_thread = true;
        Ok(true)
    }

    fn release(&mut self, pid: u32) {
        self.flush();
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
        if task.memory != pid {
            // A vfork child: only its thread is its own.
            let _ = sys::thread_kill(task.thread);
        } else {
            let _ = sys::task_kill(task.task);
        }
        for (i, stream) in [Stream::Stdout, Stream::Stderr].into_iter().enumerate() {
            task.out[i].flush(|line| {
                println!(
                    "guest: process {pid} {}: {}",
                    stream_name(stream),
                    Lossy(line)
                )
            });
        }
        // The task's mappings went with it: only its references to frames are left.
        self.frames.release_all(pid);
        self.sched.forget(pid);
    }

    fn interrupt(&mut self, pid: u32) {
        self.flush();
        if let Some(thread) = self.task(pid).map(|t| t.thread) {
            let _ = sys::thread_interrupt(thread);
        }
    }

    fn suspend(&mut self, pid: u32, stop: bool) {
        self.flush();
        let Some(thread) = self.task(pid).map(|t| t.thread) else {
            return;
        };
        let _ = if stop {
            sys::thread_suspend(thread)
        } else {
            sys::thread_resume(thread)
        };
        self.sched.stopped(pid, stop);
    }

    /// At once for a thread that waits for the guest (the kernel moves a thread no CPU
    /// runs); one that runs (`sched_setaffinity` of another thread) is interrupted, and
    /// moves at the message that brings ([`GuestHost::settle`]). Not flushed first: the
    /// deferred reply may be this thread's, which must not run before it moved.
    fn set_cpu(&mut self, pid: u32, cpu: u32) {
        let Some(t) = self.tasks.iter_mut().flatten().find(|t| t.pid == pid) else {
            return;
        };
        t.pending_cpu = None;
        if t.cpu == cpu || t.thread == ThreadId(0) {
            return;
        }
        match sys::thread_set(Some(t.thread), ThreadAttribute::Cpu, u64::from(cpu)) {
            Ok(()) => {
                t.cpu = cpu;
                self.sched.set_cpu(pid, cpu);
            }
            Err(user_rt::abi::syscall::Error::NotPermitted) => {
                t.pending_cpu = Some(cpu);
                self.moves_pending = true;
                let _ = sys::thread_interrupt(t.thread);
            }
            Err(e) => println!("guest: cannot move process {pid} to CPU {cpu}: {e:?}"),
        }
    }

    /// Deferred to the next receive ([`GuestHost::receive`]), which replies and waits in
    /// one kernel call.
    fn resume(&mut self, pid: u32, m: &ExceptionMessage) {
        self.flush();
        let Some(thread) = self.task(pid).map(|t| t.thread) else {
            return;
        };
        self.deferred = Some((thread, pid, *m));
        self.sched.replied(pid);
    }
}
