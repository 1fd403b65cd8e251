//! System-call stubs and typed wrappers: call numbers and meanings in `abi::syscall`, which
//! register carries which argument in `abi::args` (used here to encode every call).

use abi::args::{self, ArgRegs, results};
use abi::ipc::MessageTag;
use abi::syscall::{Abilities, Call, Error, PageRights, TaskId, ThreadAttribute, ThreadId};
use core::arch::asm;

/// Raw call with all six argument registers: returns `rax` (the status) and the argument
/// registers as the kernel left them (a call's results).
#[inline(always)]
#[allow(unsafe_code)] // the `syscall` instruction
pub fn raw6(call: u64, a: [u64; 6]) -> (u64, ArgRegs) {
    let [mut rdi, mut rsi, mut rdx, mut r10, mut r8, mut r9] = a;
    let rax;
    // SAFETY: `syscall` transfers to the kernel, which changes only rax and the six
    // argument registers (declared in/out), rcx and r11 (clobbered, declared), and touches
    // no memory of ours except through pointers we passed for that purpose.
    unsafe {
        asm!(
            "syscall",
            inlateout("rax") call => rax,
            inlateout("rdi") rdi,
            inlateout("rsi") rsi,
            inlateout("rdx") rdx,
            inlateout("r10") r10,
            inlateout("r8") r8,
            inlateout("r9") r9,
            lateout("rcx") _,
            lateout("r11") _,
            options(nostack),
        );
    }
    (rax, ArgRegs::from_array([rdi, rsi, rdx, r10, r8, r9]))
}

/// Raw call: returns (`rax`, `rdi`, `rsi`, `rdx`) after the call.
#[inline(always)]
pub fn raw(call: u64, a0: u64, a1: u64, a2: u64, a3: u64) -> (u64, u64, u64, u64) {
    let (rax, r) = raw6(call, [a0, a1, a2, a3, 0, 0]);
    (rax, r.rdi, r.rsi, r.rdx)
}

/// `rax` as a result.
pub fn status(rax: u64) -> Result<(), Error> {
    match Error::from_code(rax) {
        Some(Error::Ok) => Ok(()),
        Some(e) => Err(e),
        None => Err(Error::InvalidCall),
    }
}

fn call(c: Call, a: ArgRegs) -> Result<ArgRegs, Error> {
    let (rax, r) = raw6(c as u64, a.to_array());
    status(rax).map(|()| r)
}

pub fn debug_write(text: &[u8]) -> Result<(), Error> {
    let a = args::DebugWrite {
        ptr: text.as_ptr() as u64,
        len: text.len() as u64,
    };
    call(Call::DebugWrite, a.encode()).map(drop)
}

/// Nanoseconds since boot.
pub fn clock() -> u64 {
    clock_results().ns
}

/// Everything `clock` returns.
fn clock_results() -> results::Clock {
    results::Clock::decode(&raw6(Call::Clock as u64, [0; 6]).1)
}

pub fn thread_exit() -> ! {
    raw(Call::ThreadExit as u64, 0, 0, 0, 0);
    unreachable!("thread_exit returned")
}

/// Ends the run (success or failure); returns only if the caller may not halt.
pub fn system_halt(success: bool) -> Result<(), Error> {
    let a = args::SystemHalt {
        outcome: if success { 0 } else { 1 },
    };
    call(Call::SystemHalt, a.encode()).map(drop)
}

pub fn yield_now() {
    raw(Call::Yield as u64, 0, 0, 0, 0);
}

pub fn task_create(abilities: Abilities, mcp: u8, rp: u64, name: &str) -> Result<TaskId, Error> {
    let a = args::TaskCreate {
        abilities: abilities.bits(),
        mcp: mcp as u64,
        rp,
        name_ptr: name.as_ptr() as u64,
        name_len: name.len() as u64,
    };
    call(Call::TaskCreate, a.encode()).map(|r| results::TaskCreate::decode(&r).task)
}

pub fn task_kill(task: TaskId) -> Result<(), Error> {
    call(Call::TaskKill, args::TaskKill { task }.encode()).map(drop)
}

/// Stops a descendant task and its subtree at once; `task_kill` destroys it later.
pub fn task_stop(task: TaskId) -> Result<(), Error> {
    call(Call::TaskStop, args::TaskKill { task }.encode()).map(drop)
}

/// Lets `from` send to `to` (`None` = the caller's task).
pub fn task_allow_send(from: Option<TaskId>, to: Option<TaskId>) -> Result<(), Error> {
    allow(from, to, 0)
}

/// Lets `from` notify `to`, and nothing else (`None` = the caller's task).
pub fn task_allow_notify(from: Option<TaskId>, to: Option<TaskId>) -> Result<(), Error> {
    allow(from, to, 1)
}

fn allow(from: Option<TaskId>, to: Option<TaskId>, notify_only: u64) -> Result<(), Error> {
    let a = args::TaskAllowSend {
        from: TaskId::or_own(from),
        to: TaskId::or_own(to),
        notify_only,
    };
    call(Call::TaskAllowSend, a.encode()).map(drop)
}

/// A new inactive thread in `task` (`None` = own task).
pub fn thread_create(
    task: Option<TaskId>,
    entry: u64,
    stack: u64,
    priority: u8,
    arg: u64,
) -> Result<ThreadId, Error> {
    let a = args::ThreadCreate {
        task: TaskId::or_own(task),
        entry,
        stack,
        priority: priority as u64,
        arg,
    };
    call(Call::ThreadCreate, a.encode()).map(|r| results::ThreadCreate::decode(&r).thread)
}

fn on_thread(c: Call, thread: ThreadId) -> Result<(), Error> {
    call(c, args::OnThread { thread }.encode()).map(drop)
}

pub fn thread_start(thread: ThreadId) -> Result<(), Error> {
    on_thread(Call::ThreadStart, thread)
}

pub fn thread_suspend(thread: ThreadId) -> Result<(), Error> {
    on_thread(Call::ThreadSuspend, thread)
}

pub fn thread_resume(thread: ThreadId) -> Result<(), Error> {
    on_thread(Call::ThreadResume, thread)
}

pub fn thread_kill(thread: ThreadId) -> Result<(), Error> {
    on_thread(Call::ThreadKill, thread)
}

/// Sets an attribute of `thread` (`None` = the calling thread).
pub fn thread_set(
    thread: Option<ThreadId>,
    attribute: ThreadAttribute,
    value: u64,
) -> Result<(), Error> {
    let a = args::ThreadSet {
        thread: ThreadId::or_own(thread),
        attribute: attribute as u64,
        value,
    };
    call(Call::ThreadSet, a.encode()).map(drop)
}

/// Copies the FPU/SSE state (FXSAVE image) of another thread (of a descendant task) into
/// `image` (`write` = false) or loads it from there (`write` = true).
pub fn thread_fpu(thread: ThreadId, image: &mut [u8; 512], write: bool) -> Result<(), Error> {
    let a = args::ThreadFpu {
        thread,
        buffer: image.as_mut_ptr() as u64,
        write: write as u64,
    };
    call(Call::ThreadFpu, a.encode()).map(drop)
}

/// Makes `thread` (of a descendant task), if it is running user code, report to its
/// exception handler now; whether it did.
pub fn thread_interrupt(thread: ThreadId) -> Result<bool, Error> {
    let a = args::OnThread { thread };
    call(Call::ThreadInterrupt, a.encode())
        .map(|r| results::ThreadInterrupt::decode(&r).interrupted)
}

/// The calling thread and its task.
pub fn thread_self() -> (ThreadId, TaskId) {
    let r = results::ThreadSelf::decode(&raw6(Call::ThreadSelf as u64, [0; 6]).1);
    (r.thread, r.task)
}

pub fn map(
    task: Option<TaskId>,
    source: u64,
    destination: u64,
    pages: u64,
    rights: PageRights,
) -> Result<(), Error> {
    map_from(Call::Map, task, source, destination, pages, rights)
}

pub fn map_physical(
    task: Option<TaskId>,
    physical: u64,
    destination: u64,
    pages: u64,
    rights: PageRights,
) -> Result<(), Error> {
    map_from(
        Call::MapPhysical,
        task,
        physical,
        destination,
        pages,
        rights,
    )
}

/// Maps device registers (a PCI memory BAR) uncached: see `Call::MapDevice`.
pub fn map_device(
    task: Option<TaskId>,
    physical: u64,
    destination: u64,
    pages: u64,
    rights: PageRights,
) -> Result<(), Error> {
    map_from(Call::MapDevice, task, physical, destination, pages, rights)
}

/// `map` and `map_physical` take the same arguments; `source` is a page of the caller or a
/// physical address.
fn map_from(
    call_number: Call,
    task: Option<TaskId>,
    source: u64,
    destination: u64,
    pages: u64,
    rights: PageRights,
) -> Result<(), Error> {
    let a = args::Map {
        task: TaskId::or_own(task),
        source,
        destination,
        pages,
        rights: rights.bits(),
    };
    call(call_number, a.encode()).map(drop)
}

pub fn unmap(task: Option<TaskId>, address: u64, pages: u64) -> Result<(), Error> {
    let a = args::Unmap {
        task: TaskId::or_own(task),
        address,
        pages,
    };
    call(Call::Unmap, a.encode()).map(drop)
}

pub fn protect(
    task: Option<TaskId>,
    address: u64,
    pages: u64,
    rights: PageRights,
) -> Result<(), Error> {
    let a = args::Protect {
        task: TaskId::or_own(task),
        address,
        pages,
        rights: rights.bits(),
    };
    call(Call::Protect, a.encode()).map(drop)
}

/// A message in registers: tag and three words.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Message {
    pub tag: MessageTag,
    pub words: [u64; 3],
}

impl Message {
    pub const fn new(label: u32, words: [u64; 3]) -> Self {
        Self {
            tag: MessageTag::new(label, 0, 0),
            words,
        }
    }
}

/// A received message and who sent it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    pub sender: ThreadId,
    /// The sender's task (set by the kernel: a server can trust it).
    pub sender_task: TaskId,
    pub message: Message,
}

fn ipc(c: Call, peer: ThreadId, timeout_ns: u64, m: &Message) -> Result<Received, Error> {
    let a = args::Ipc {
        peer,
        timeout: timeout_ns,
        tag: m.tag.0,
        word0: m.words[0],
        word1: m.words[1],
        word2: m.words[2],
    };
    call(c, a.encode()).map(|r| {
        let r = results::Ipc::decode(&r);
        Received {
            sender: r.sender,
            sender_task: r.sender_task,
            message: Message {
                tag: MessageTag(r.tag),
                words: [r.word0, r.word1, r.word2],
            },
        }
    })
}

/// Timeouts in ns; `abi::syscall::TIMEOUT_INFINITE` waits forever, 0 polls.
pub fn send(to: ThreadId, timeout_ns: u64, m: &Message) -> Result<(), Error> {
    ipc(Call::Send, to, timeout_ns, m).map(drop)
}

pub fn receive(from: Option<ThreadId>, timeout_ns: u64) -> Result<Received, Error> {
    ipc(
        Call::Receive,
        ThreadId::or_own(from),
        timeout_ns,
        &Message::default(),
    )
}

pub fn ipc_call(to: ThreadId, timeout_ns: u64, m: &Message) -> Result<Received, Error> {
    ipc(Call::Call, to, timeout_ns, m)
}

pub fn reply_wait(
    caller: Option<ThreadId>,
    timeout_ns: u64,
    m: &Message,
) -> Result<Received, Error> {
    ipc(Call::ReplyWait, ThreadId::or_own(caller), timeout_ns, m)
}

pub fn reply(caller: ThreadId, m: &Message) -> Result<(), Error> {
    ipc(Call::Reply, caller, 0, m).map(drop)
}

pub fn notify_signal(thread: ThreadId, bits: u64) -> Result<(), Error> {
    let a = args::NotifySignal { thread, bits };
    call(Call::NotifySignal, a.encode()).map(drop)
}

/// Waits for any bit of `mask`; returns (and clears) the bits of `mask` that were set.
pub fn notify_wait(mask: u64, timeout_ns: u64) -> Result<u64, Error> {
    let a = args::NotifyWait {
        mask,
        timeout: timeout_ns,
    };
    call(Call::NotifyWait, a.encode()).map(|r| results::NotifyWait::decode(&r).bits)
}

/// Sleeps for `ns` nanoseconds.
pub fn sleep(ns: u64) {
    let _ = notify_wait(0, ns);
}

/// A resource partition with the quota given whose threads may run on the CPUs of mask
/// `cpus` (some of the caller's partition's: [`RpUsage::cpus`]).
pub fn rp_create(tasks: u16, threads: u16, pages: u64, cpus: u8) -> Result<u64, Error> {
    let a = args::RpCreate {
        tasks: tasks as u64,
        threads: threads as u64,
        pages,
        cpus: cpus.into(),
    };
    call(Call::RpCreate, a.encode()).map(|r| results::RpCreate::decode(&r).rp)
}

/// Usage of a resource partition (0 = the caller's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RpUsage {
    pub pages_used: u64,
    pub pages_quota: u64,
    pub threads_used: u16,
    pub threads_quota: u16,
    pub tasks_used: u16,
    pub tasks_quota: u16,
    /// Bit n: its threads may run on CPU n.
    pub cpus: u8,
}

pub fn rp_info(rp: u64) -> Result<RpUsage, Error> {
    call(Call::RpInfo, args::RpInfo { rp }.encode()).map(|r| {
        let r = results::RpInfo::decode(&r);
        RpUsage {
            pages_used: r.pages_used,
            pages_quota: r.pages_quota,
            threads_used: r.counts.threads_used,
            threads_quota: r.counts.threads_quota,
            tasks_used: r.counts.tasks_used,
            tasks_quota: r.counts.tasks_quota,
            cpus: r.cpus as u8,
        }
    })
}

pub fn set_health_monitor(thread: ThreadId) -> Result<(), Error> {
    let a = args::SetHealthMonitor { thread };
    call(Call::SetHealthMonitor, a.encode()).map(drop)
}

/// Blocks until `clock()` >= `time` (ns since boot).
pub fn sleep_until(time: u64) {
    let _ = call(Call::SleepUntil, args::SleepUntil { time }.encode());
}

/// Stores time schedule `slot`.
pub fn schedule_set(
    slot: u64,
    major_frame_ns: u64,
    windows: &[abi::syscall::WindowSpec],
) -> Result<(), Error> {
    let a = args::ScheduleSet {
        slot,
        major_frame: major_frame_ns,
        windows: windows.as_ptr() as u64,
        count: windows.len() as u64,
    };
    call(Call::ScheduleSet, a.encode()).map(drop)
}

/// Returns when the switch takes effect (ns since boot).
pub fn schedule_switch(slot: u64) -> Result<u64, Error> {
    call(Call::ScheduleSwitch, args::ScheduleSwitch { slot }.encode())
        .map(|r| results::ScheduleSwitch::decode(&r).at)
}

/// What `partition_info` reports (see `abi::syscall::Call::PartitionInfo`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartitionInfo {
    pub active: u64,
    pub next_window_start: u64,
    pub window_length: u64,
    pub cpu_ns: u64,
    pub idle_ns: u64,
    pub frames: u64,
}

pub fn partition_info(tp: u64) -> Result<PartitionInfo, Error> {
    let a = args::PartitionInfo { partition: tp };
    call(Call::PartitionInfo, a.encode()).map(|r| {
        let r = results::PartitionInfo::decode(&r);
        PartitionInfo {
            active: r.active,
            next_window_start: r.window_start,
            window_length: r.window_length,
            cpu_ns: r.cpu_ns,
            idle_ns: r.idle_ns,
            frames: r.frames,
        }
    })
}

/// Grants I/O ports `first..first + count` to a descendant task.
pub fn io_grant(task: TaskId, first: u16, count: u32) -> Result<(), Error> {
    let a = args::IoGrant {
        task,
        first: first as u64,
        count: count as u64,
    };
    call(Call::IoGrant, a.encode()).map(drop)
}

/// One dword of PCI configuration space (root task only): `address` = bus << 16 |
/// device << 11 | function << 8 | register; `Some(value)` writes it (and returns 0).
pub fn pci_config(address: u32, write: Option<u32>) -> Result<u32, Error> {
    let a = args::PciConfig {
        address: u64::from(address),
        value: u64::from(write.unwrap_or(0)),
        write: u64::from(write.is_some()),
    };
    call(Call::PciConfig, a.encode()).map(|r| results::PciConfig::decode(&r).value as u32)
}

/// Lets PCI function `source` (its routing id) reach `pages` frames from `physical` by DMA
/// through the IOMMU (root task only): the bus address of the first frame; see
/// `Call::DmaMap`.
pub fn dma_map(source: u16, physical: u64, pages: u64) -> Result<u64, Error> {
    let a = args::DmaMap {
        source: u64::from(source),
        physical,
        pages,
    };
    call(Call::DmaMap, a.encode()).map(|r| results::DmaMap::decode(&r).bus_address)
}

/// A DMA request the IOMMU blocked (see `Call::DmaFault`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DmaFault {
    pub source: u16,
    pub address: u64,
    pub reason: u8,
    pub write: bool,
}

/// The oldest blocked DMA request nobody took yet (root task only); `Err(TimedOut)` when
/// there is none.
pub fn dma_fault() -> Result<DmaFault, Error> {
    call(Call::DmaFault, args::ArgRegs::default()).map(|r| {
        let f = results::DmaFault::decode(&r);
        DmaFault {
            source: f.source as u16,
            address: f.address,
            reason: f.reason as u8,
            write: f.write != 0,
        }
    })
}

/// Lets a descendant task attach interrupt line `line`.
pub fn irq_grant(task: TaskId, line: u64) -> Result<(), Error> {
    let a = args::IrqGrant { task, line };
    call(Call::IrqGrant, a.encode()).map(drop)
}

/// Attaches interrupt line `line` to the calling thread; it fires as notification `bit`.
pub fn irq_attach(line: u64, bit: u64) -> Result<(), Error> {
    call(Call::IrqAttach, args::IrqAttach { line, bit }.encode()).map(drop)
}

/// Waits until the attached line fired (`TimedOut` after `timeout_ns`; 0 = poll).
pub fn irq_wait(line: u64, timeout_ns: u64) -> Result<(), Error> {
    let a = args::IrqWait {
        line,
        timeout: timeout_ns,
    };
    call(Call::IrqWait, a.encode()).map(drop)
}

/// Unmasks the attached line after its device was served.
pub fn irq_ack(line: u64) -> Result<(), Error> {
    call(Call::IrqAck, args::IrqLine { line }.encode()).map(drop)
}

pub fn irq_detach(line: u64) -> Result<(), Error> {
    call(Call::IrqDetach, args::IrqLine { line }.encode()).map(drop)
}

/// The Unix time in ns at boot, from the firmware's real-time clock (`None` without one):
/// the wall-clock time is this plus [`clock`].
pub fn wall_clock_at_boot() -> Option<u64> {
    Some(clock_results().wall_clock_at_boot).filter(|&ns| ns != 0)
}

/// The TSC time base: converts `rdtsc` readings to `clock()` nanoseconds and back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TscBase {
    pub hz: u64,
    pub at_boot: u64,
}

impl TscBase {
    pub fn get() -> Self {
        let r = clock_results();
        Self {
            hz: r.tsc_hz,
            at_boot: r.boot_tsc,
        }
    }

    /// The TSC value at `ns` since boot (rounded up, as the kernel's timer is).
    pub fn tsc_at(&self, ns: u64) -> u64 {
        self.at_boot + (ns as u128 * self.hz as u128).div_ceil(1_000_000_000) as u64
    }

    /// TSC ticks as nanoseconds.
    pub fn ns(&self, ticks: u64) -> u64 {
        (ticks as u128 * 1_000_000_000 / self.hz.max(1) as u128) as u64
    }

    /// What [`clock`] returns now, computed as the kernel does, without a system call.
    pub fn now_ns(&self) -> u64 {
        self.ns(rdtsc().wrapping_sub(self.at_boot))
    }
}

/// Reads the time-stamp counter (allowed in ring 3).
pub fn rdtsc() -> u64 {
    // SAFETY: RDTSC only reads the counter.
    #[allow(unsafe_code)]
    unsafe {
        core::arch::x86_64::_rdtsc()
    }
}
