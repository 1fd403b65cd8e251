//! The system-call ABI.
//!
//! Register convention (`syscall` instruction): `rax` = call number ([`Call`]); arguments in
//! `rdi`, `rsi`, `rdx`, `r10`, `r8`, `r9` (`r10` instead of `rcx`, which `syscall`
//! overwrites). On return `rax` = [`Error`] code (0 = success) and results, if any, in
//! `rdi`, `rsi`, `rdx`, `r10`, `r8`, `r9` (only the registers a call documents change).
//! `rcx` and `r11` are clobbered; all other registers, the FPU/SSE state and the FS/GS bases
//! are preserved.
//!
//! Every call lists the [`Abilities`] it needs; a caller lacking one gets
//! [`Error::AbilityDenied`] and nothing changes. Any call that fails changes nothing.
//! Objects are named by [`ThreadId`], [`TaskId`] and resource-partition numbers; `0` means
//! "the caller's own" where a call says so.
//!
//! **Control rights** flow down the task tree: a task may operate on itself and on its
//! descendants (children, grandchildren, ...), never on its ancestors or siblings.
//!
//! Root-task start convention: the kernel starts the first thread of the root task (syssw)
//! at its ELF entry with `rdi` = user address of the read-only mapped system image
//! ([`ROOT_SYSTEM_IMAGE_BASE`]), `rsi` = its size in bytes, `rdx` = address of the read-only
//! [`RootInfo`](crate::root::RootInfo) page ([`ROOT_INFO_BASE`]) and `rsp` =
//! [`ROOT_STACK_TOP`] - 8 (as if `call`ed, so the SysV stack alignment holds) in a
//! [`ROOT_STACK_SIZE`]-byte stack. It runs at priority [`ROOT_PRIORITY`] in time partition 0
//! with every ability, MCP [`MAX_PRIORITY`] and the root resource partition (number 1).

use bitflags::bitflags;

/// Where the kernel maps `system.img` (read-only) in the root task.
pub const ROOT_SYSTEM_IMAGE_BASE: u64 = 0x0000_7000_0000_0000;
/// Where the kernel maps the [`RootInfo`](crate::root::RootInfo) page in the root task.
pub const ROOT_INFO_BASE: u64 = 0x0000_6fff_ffff_f000;
/// Top of the root task's initial stack (exclusive).
pub const ROOT_STACK_TOP: u64 = 0x0000_7fff_ffff_0000;
pub const ROOT_STACK_SIZE: u64 = 256 * 1024;
/// Priority of the root task's first thread.
pub const ROOT_PRIORITY: u8 = 200;
/// Lowest address user mappings may use (page 0 stays unmapped to catch null pointers).
pub const USER_MIN: u64 = 0x1000;
/// One past the highest user address (the canonical lower half).
pub const USER_END: u64 = 0x0000_8000_0000_0000;
/// Priorities run from 0 (lowest) to this (highest).
pub const MAX_PRIORITY: u8 = 255;
/// Most pages one map/unmap/protect call handles: it bounds how long one call keeps the
/// kernel (not preemptible) and so how late it can make another partition's window start.
/// Scenario `attack_map` (virtual time) measured the worst window start after a neighbour's
/// map/protect/unmap calls: 198 us late with 512 pages a call, 58 us with 64, 26 us with
/// 32 (the bound is 50 us beyond the quiet 2 us).
pub const MAP_MAX_PAGES: u64 = 32;
/// Longest text one `debug_write` accepts.
pub const DEBUG_WRITE_MAX: u64 = 512;
/// Longest task name (bytes).
pub const TASK_NAME_MAX: u64 = 15;
/// `timeout` value meaning "wait forever"; `0` means "do not wait" (poll).
pub const TIMEOUT_INFINITE: u64 = u64::MAX;

codes::code_enum! {
    /// System-call numbers.
    pub enum Call: u64 {
        /// `debug_write(ptr, len)`: writes `len` (<= [`DEBUG_WRITE_MAX`]) bytes of UTF-8 text
        /// as one line of the kernel log, prefixed with the caller's task name.
        /// Ability: `DEBUG_LOG`. Errors: `BadAddress` (buffer not readable user memory),
        /// `InvalidArgument` (too long).
        DebugWrite = 1 => "debug_write",
        /// `clock() -> rdi = ns, rsi = TSC frequency (Hz), rdx = TSC at boot, r10 = wall
        /// clock at boot`: nanoseconds since boot (monotonic); rsi and rdx let a program
        /// convert `rdtsc` readings to the same time base (ns = (tsc - boot) * 10^9 / Hz) for
        /// cycle-exact measurements; r10 is the Unix time in ns at boot from the firmware's
        /// real-time clock (UTC; 0 when there is none), so wall-clock time is r10 + rdi.
        /// Ability: none.
        Clock = 2 => "clock",
        /// `thread_exit()`: ends the calling thread (as `thread_kill` of itself); does not
        /// return. Ability: none.
        ThreadExit = 3 => "thread_exit",
        /// `system_halt(outcome)`: stops the machine; `outcome` 0 = success, 1 = failure (under
        /// QEMU: exit 33 / 35). Ability: `SYSTEM_HALT`. Errors: `InvalidArgument`.
        SystemHalt = 4 => "system_halt",
        /// `yield()`: moves the caller behind the other ready threads of its priority.
        /// Ability: none.
        Yield = 5 => "yield",
        /// `sleep_until(time)`: blocks until `clock()` >= `time` (ns since boot); returns at
        /// once for a past time. Ability: none.
        SleepUntil = 6 => "sleep_until",

        /// `task_create(abilities, mcp, rp, name_ptr, name_len) -> rdi = task`: a new child
        /// task of the caller with an empty address space and no threads. `rp` = resource
        /// partition it belongs to and is charged to (0 = the caller's; another one needs
        /// `PARTITION_CONTROL` and must have been created by the caller's task). Costs one task
        /// and one page (its top-level page table) of that partition's quota.
        /// Ability: `CREATE_TASK`. Errors: `AbilityDenied` (`abilities` not a subset of the
        /// caller's), `McpExceeded` (`mcp` above the caller's), `NoSuchObject` (`rp`),
        /// `NotPermitted` (`rp` not the caller's to use), `QuotaExceeded`, `BadAddress`,
        /// `InvalidArgument` (name too long or not UTF-8, unknown ability bits).
        TaskCreate = 10 => "task_create",
        /// `task_kill(task)`: destroys a descendant task, its threads and all its descendants;
        /// their kernel memory returns to their resource partitions. Threads waiting on them
        /// get `PeerGone`. At once, no thread of the subtree runs again and no other call can
        /// name its tasks; the rest is done a bounded piece at a time: until it is all done
        /// the call restarts itself (the caller executes the same `syscall` again, registers
        /// unchanged), so a large subtree never keeps the kernel from switching windows for
        /// long. Ability: `CREATE_TASK`. Errors: `NoSuchObject` (also when another
        /// `task_kill` finished destroying it meanwhile), `NotPermitted` (not a strict
        /// descendant).
        TaskKill = 11 => "task_kill",
        /// `task_stop(task)`: the first, bounded part of `task_kill` alone: no thread of the
        /// descendant task or its subtree runs again and no call but `task_kill` (which then
        /// destroys it) can name its tasks. For a caller that must not spend long in one
        /// place (syssw's server) and leaves the rest to a thread that may take its time.
        /// Ability: `CREATE_TASK`. Errors: as `task_kill`.
        TaskStop = 13 => "task_stop",
        /// `task_allow_send(from, to, notify_only)`: lets threads of task `from` send IPC and
        /// notifications to threads of task `to` (0 = the caller's task, for either), or only
        /// notifications (`notify_only` = 1: a wake-up between partitions that must not
        /// exchange messages). Both must be the caller's task or its descendants. By default a
        /// task may send to itself, its parent and its children only. Ability: `CREATE_TASK`.
        /// Errors: `NoSuchObject`, `NotPermitted`, `InvalidArgument` (`notify_only` above 1).
        TaskAllowSend = 12 => "task_allow_send",

        /// `thread_create(task, entry, stack, priority, arg) -> rdi = thread`: a new thread of
        /// `task` (0 = own task; else a descendant), inactive until `thread_start`; it will
        /// start at `entry` with `rsp` = `stack`, `rdi` = `arg`, in the creator's time
        /// partition and on the creator's CPU, without an exception handler. Costs one thread of the quota of the
        /// task's resource partition. Ability: `CREATE_THREAD`. Errors: `McpExceeded`
        /// (priority above the task's MCP), `NoSuchObject`, `NotPermitted`, `QuotaExceeded`,
        /// `InvalidArgument` (entry or stack outside user space).
        ThreadCreate = 20 => "thread_create",
        /// `thread_start(thread)`: makes an inactive thread ready. Ability: `CREATE_THREAD`.
        /// Errors: `NoSuchObject`, `NotPermitted`, `InvalidArgument` (already started).
        ThreadStart = 21 => "thread_start",
        /// `thread_suspend(thread)`: the thread stops being scheduled (an IPC it waits for
        /// still completes). Ability: none beyond control rights. Errors: `NoSuchObject`,
        /// `NotPermitted`.
        ThreadSuspend = 22 => "thread_suspend",
        /// `thread_resume(thread)`: undoes `thread_suspend`. Errors as `thread_suspend`.
        ThreadResume = 23 => "thread_resume",
        /// `thread_kill(thread)`: destroys a thread; its kernel memory returns to its resource
        /// partition. Killing oneself is `thread_exit`. Errors: `NoSuchObject`, `NotPermitted`.
        ThreadKill = 24 => "thread_kill",
        /// `thread_set(thread, attribute, value)`: sets one [`ThreadAttribute`] of a thread of
        /// the caller's task or of a descendant (0 = the calling thread).
        /// Errors: `NoSuchObject`, `NotPermitted`, `InvalidArgument` (unknown attribute, value
        /// out of range), and per attribute as documented there.
        ThreadSet = 25 => "thread_set",
        /// `thread_self() -> rdi = thread, rsi = task`. Ability: none.
        ThreadSelf = 26 => "thread_self",
        /// `thread_fpu(thread, buffer, write)`: copies the FPU/SSE state (the 512-byte
        /// FXSAVE image) of another thread of the caller's task or of a descendant to the
        /// caller's `buffer` (`write` = 0), or loads it from there (`write` = 1; reserved
        /// MXCSR bits are cleared, so no image can make the kernel fault). For a guest that
        /// saves and restores a process's FPU state around a signal handler. Ability: none
        /// beyond control rights. Errors: `NoSuchObject`, `NotPermitted`, `InvalidArgument`
        /// (the calling thread itself, `write` > 1), `BadAddress` (`buffer` not 512 bytes of
        /// readable, or for `write` = 0 writable, user memory).
        ThreadFpu = 27 => "thread_fpu",
        /// `thread_interrupt(thread) -> rdi = interrupted`: a thread of a descendant task
        /// that is running user code (ready) stops and sends its exception handler an
        /// exception message with vector [`VECTOR_INTERRUPT`](crate::ipc::VECTOR_INTERRUPT),
        /// as if it faulted at its next instruction: for a guest that delivers a signal to
        /// a process busy in user code. A thread in the kernel (waiting in IPC, sleeping,
        /// inactive) is left alone (`rdi` = 0): it reports when its call returns. Ability:
        /// none beyond control rights. Errors: `NoSuchObject`, `NotPermitted`,
        /// `InvalidArgument` (the calling thread, or a thread without exception handler).
        ThreadInterrupt = 28 => "thread_interrupt",

        /// `map(task, source, destination, pages, rights)`: maps `pages` pages starting at the
        /// caller's page `source` into `task` (0 = own; else a descendant) at `destination`,
        /// with `rights` ([`PageRights`]) that must not exceed the source pages' rights. Page
        /// tables are charged to `task`'s resource partition. All-or-nothing. Ability: `MAP`.
        /// Errors: `InvalidArgument` (unaligned, zero or more than [`MAP_MAX_PAGES`] pages,
        /// destination outside user space), `BadAddress` (a source page unmapped or with fewer
        /// rights), `AlreadyMapped`, `QuotaExceeded`, `NoSuchObject`, `NotPermitted`.
        Map = 30 => "map",
        /// `map_physical(task, physical, destination, pages, rights)`: like `map`, with
        /// physical frames as the source; they must lie in memory the kernel handed to the root
        /// task ([`RootInfo`](crate::root::RootInfo)). Ability: `PHYSICAL_MEMORY`. Errors as
        /// `map`, with `BadAddress` for frames outside the handed-out memory.
        MapPhysical = 31 => "map_physical",
        /// `map_device(task, physical, destination, pages, rights)`: like `map_physical`, for
        /// the registers of a device (a PCI memory BAR): frames that are no memory the
        /// firmware lists (RAM, firmware, ACPI, flash), not below 1 MiB and not the
        /// interrupt controllers' and timer's 0xfec00000..0xff000000. Mapped uncached (PCD and
        /// PWT: PAT entry 3, UC). Such a page is never the source of `map`, a map item or a
        /// buffer of any call (`BadAddress`): the kernel never touches device registers for
        /// user space. Ability: `PHYSICAL_MEMORY`. Errors as `map_physical`.
        MapDevice = 34 => "map_device",
        /// `unmap(task, address, pages)`: removes the mappings of `pages` pages (unmapped ones
        /// are skipped). Ability: `MAP`. Errors: `InvalidArgument`, `NoSuchObject`,
        /// `NotPermitted`.
        Unmap = 32 => "unmap",
        /// `protect(task, address, pages, rights)`: reduces the rights of mapped pages to
        /// `rights` (rights are never added: map again for that). Ability: `MAP`.
        /// Errors: `InvalidArgument`, `BadAddress` (a page unmapped), `NoSuchObject`,
        /// `NotPermitted`.
        Protect = 33 => "protect",

        /// `send(thread, timeout, tag, w0, w1, w2)`: waits until `thread` receives the message
        /// ([`ipc`](crate::ipc)): tag + three words in registers, `tag.len()` bytes and
        /// `tag.items()` map items from the caller's IPC buffer. Senders queue by priority
        /// (FIFO within one). Ability: none; the caller's task needs the right to send to the
        /// receiver's task. Errors: `NoSuchObject`, `NotPermitted` (no communication right),
        /// `TimedOut`, `PeerGone` (receiver killed), `BadAddress` (own IPC buffer), and for
        /// map items `InvalidArgument`/`BadAddress`/`AlreadyMapped`/`QuotaExceeded`.
        Send = 40 => "send",
        /// `receive(from, timeout) -> rdi = sender, rsi = sender's task, rdx = tag, r10/r8/r9 =
        /// words`: waits for a
        /// message from `from` (0 = anyone). The data and received map items are in the IPC
        /// buffer. If the sender used `call`, the receiver must answer with `reply` or
        /// `reply_wait`. Errors: `TimedOut`, `NoSuchObject` (`from`), `PeerGone`, `BadAddress`
        /// (no writable IPC buffer).
        Receive = 41 => "receive",
        /// `call(thread, timeout, tag, w0, w1, w2) -> as receive`: `send`, then waits for the
        /// reply of that thread, atomically; `timeout` bounds both phases together.
        /// Errors: those of `send` and `receive`.
        Call = 42 => "call",
        /// `reply_wait(caller, timeout, tag, w0, w1, w2) -> as receive`: replies to `caller`
        /// (0 = reply to no one) then receives from anyone. Errors: `NotWaiting` (the caller is
        /// not waiting for a reply from this thread; nothing is received then) and those of
        /// `receive`.
        ReplyWait = 43 => "reply_wait",
        /// `reply(caller, _, tag, w0, w1, w2)`: replies without waiting. Errors: `NotWaiting`.
        Reply = 44 => "reply",

        /// `notify_signal(thread, bits)`: sets notification bits of `thread`, waking it if it
        /// waits for any of them. Needs the right to send to the thread's task. Errors:
        /// `NoSuchObject`, `NotPermitted`.
        NotifySignal = 50 => "notify_signal",
        /// `notify_wait(mask, timeout) -> rdi = bits`: waits until one of `mask`'s bits is set
        /// (mask 0: just sleep for `timeout`), returns and clears the set bits of `mask`.
        /// Errors: `TimedOut`.
        NotifyWait = 51 => "notify_wait",

        /// `rp_create(tasks, threads, pages, cpus) -> rdi = rp`: a new resource partition with
        /// the given quota, carved out of the caller's partition's free quota, whose threads
        /// may run on the CPUs of mask `cpus` (bit n: CPU n), a non-empty subset of the
        /// caller's partition's (the root partition's: all 8). Ability: `PARTITION_CONTROL`.
        /// Errors: `QuotaExceeded`, `OutOfResources` (all partition slots used),
        /// `InvalidArgument` (`cpus` empty or not a subset).
        RpCreate = 60 => "rp_create",
        /// `rp_info(rp) -> rdi = pages used, rsi = pages quota, rdx = threads used | threads
        /// quota << 16 | tasks used << 32 | tasks quota << 48, r10 = its CPU mask (as
        /// `rp_create`'s)` (0 = the caller's partition).
        /// Errors: `NoSuchObject`.
        RpInfo = 61 => "rp_info",
        /// `set_health_monitor(thread)`: a thread of the root task that receives
        /// [`LABEL_FAULT_REPORT`](crate::ipc::LABEL_FAULT_REPORT) messages for faults of threads
        /// without an exception handler. Ability: `PARTITION_CONTROL`, caller in the root task.
        /// Errors: `NoSuchObject`, `NotPermitted` (not a root-task thread).
        SetHealthMonitor = 62 => "set_health_monitor",

        /// `schedule_set(slot, major_frame, windows, count)`: stores time schedule `slot`
        /// (< [`MAX_SCHEDULES`]): a major frame in ns ([`MIN_WINDOW`]..=[`MAX_MAJOR_FRAME`]) and `count`
        /// (<= [`MAX_WINDOWS`])
        /// [`WindowSpec`]s at user address `windows`, each on an online CPU, sorted by offset
        /// and disjoint among the windows of their CPU (the CPUs' windows may overlap each
        /// other: every CPU has its own schedule in the one major frame), inside the frame,
        /// each at least [`MIN_WINDOW`] long and for a time partition 1..[`TIME_PARTITIONS`]
        /// (0 is the background and has no windows). The running or pending schedule cannot
        /// be replaced. Ability: `SCHEDULING`. Errors: `InvalidArgument` (slot, frame,
        /// windows, a CPU not online), `BadAddress`, `NotPermitted` (slot in use).
        ScheduleSet = 70 => "schedule_set",
        /// `schedule_switch(slot) -> rdi = when it takes effect (ns since boot)`: runs
        /// schedule `slot`; the first schedule starts at once, later switches take effect at
        /// the next major-frame boundary of the running schedule, on every CPU at once (a
        /// later switch before it replaces the earlier one). Ability: `SCHEDULING`. Errors: `InvalidArgument`
        /// (empty slot).
        ScheduleSwitch = 71 => "schedule_switch",
        /// `partition_info(tp) -> rdi = active time partition of the caller's CPU (0 in a
        /// gap or without a schedule), rsi = start of tp's current or next window on any CPU
        /// (ns since boot; u64::MAX if it has none), rdx = that window's length
        /// (ns), r10 = CPU time threads of tp used on all CPUs (ns), r8 = time the caller's CPU
        /// was idle (ns), r9 = major frames started`. Ability: none. Errors:
        /// `InvalidArgument` (tp out of range).
        PartitionInfo = 72 => "partition_info",

        /// `io_grant(task, first_port, count)`: lets a descendant task use I/O ports
        /// `first_port..first_port + count` from ring 3 (enforced by the TSS I/O permission
        /// bitmap; any other port access raises #GP, delivered like every fault). The caller
        /// must hold the ports itself (the root task holds all except the kernel's:
        /// [`KERNEL_PORTS`]). The first grant to a task costs 2 pages of its partition's quota.
        /// Ability: `IO_PORTS`. Errors: `InvalidArgument` (empty range or beyond 0xffff),
        /// `NotPermitted` (not a strict descendant, or ports the caller does not hold),
        /// `QuotaExceeded`, `NoSuchObject`.
        IoGrant = 80 => "io_grant",
        /// `irq_grant(task, line)`: lets a descendant task attach interrupt line `line`
        /// (an IOAPIC input, < [`IRQ_LINES`]). The caller must hold the line itself (the root
        /// task holds all except [`KERNEL_IRQS`]). Ability: `IRQ`. Errors: `InvalidArgument`
        /// (line out of range), `NotPermitted` (not a strict descendant, or a line the caller
        /// does not hold), `NoSuchObject`.
        IrqGrant = 81 => "irq_grant",
        /// `irq_attach(line, bit)`: the calling thread receives interrupt line `line`: when it
        /// fires, the kernel masks it and sets notification bit `bit` (< 64) of the thread (so
        /// `irq_wait` or `notify_wait` sees it). The line is unmasked at once. Attaching a line
        /// the caller already has just changes the bit. A line is detached when its thread
        /// dies. Ability: `IRQ`. Errors: `InvalidArgument` (line or bit out of range),
        /// `NotPermitted` (the task does not hold the line, or another thread has it attached).
        IrqAttach = 82 => "irq_attach",
        /// `irq_wait(line, timeout)`: waits until the attached `line` has fired since the
        /// last wait (and clears that). An interrupt that arrives while the thread's time
        /// partition is not eligible is latched and seen when it runs again. The line stays
        /// masked until `irq_ack`. Errors: `NotPermitted` (line not attached to the caller),
        /// `InvalidArgument`, `TimedOut`.
        IrqWait = 83 => "irq_wait",
        /// `irq_ack(line)`: unmasks the attached `line` after its device was served.
        /// Errors: `NotPermitted` (not attached to the caller), `InvalidArgument`.
        IrqAck = 84 => "irq_ack",
        /// `irq_detach(line)`: masks the line and releases it. Errors: as `irq_ack`.
        IrqDetach = 85 => "irq_detach",

        /// `pci_config(address, value, write) -> rdi = value`: one dword of PCI
        /// configuration space through ports 0xcf8/0xcfc (which the kernel keeps, see
        /// [`KERNEL_PORTS`]): `address` = bus << 16 | device << 11 | function << 8 |
        /// register (dword-aligned, < 256); reads (`write` = 0) return the dword, writes
        /// (`write` = 1) store `value`. For syssw, which grants devices' BARs to partitions;
        /// nobody else may reach configuration space. Ability: `PHYSICAL_MEMORY`, caller in
        /// the root task. Errors: `NotPermitted` (not the root task), `InvalidArgument`
        /// (address beyond 24 bits or unaligned, `write` > 1, `value` beyond 32 bits).
        PciConfig = 86 => "pci_config",
        /// `dma_map(source, physical, pages) -> rdi = bus address`: lets PCI function
        /// `source` (bus << 8 | device << 3 | function) reach the `pages` (1..=
        /// [`MAP_MAX_PAGES`]) frames of user memory from `physical` by DMA, at bus
        /// addresses equal to their physical addresses (returned: `physical`), through the
        /// IOMMU; what it reached before stays, nothing else is reachable (a function never
        /// given frames reaches nothing). For syssw, which confines a partition's devices to
        /// its DMA region before turning their bus mastering on. Ability: `PHYSICAL_MEMORY`,
        /// caller in the root task. Errors: `NotPermitted` (not the root task),
        /// `NoSuchObject` (the machine has no IOMMU the kernel programs, or its DMAR does not
        /// list the function), `InvalidArgument`
        /// (source beyond 16 bits, unaligned, page count, beyond the unit's bus addresses),
        /// `BadAddress` (not user memory), `OutOfResources` (the remapping tables' frames,
        /// reserved at boot, or domain ids are used up; or the unit did not answer).
        DmaMap = 87 => "dma_map",
        /// `dma_fault() -> rdi = source, rsi = address, rdx = reason, r10 = write`: the
        /// oldest DMA request the IOMMU blocked that nobody took yet (requester as in
        /// `dma_map`, the page of the bus address, the VT-d fault reason, 1 for a write),
        /// taken from its fault records (a bounded look at them). For syssw's health
        /// monitor, which polls it. Ability: `PHYSICAL_MEMORY`, caller in the root task.
        /// Errors: `NotPermitted`, `NoSuchObject` (no IOMMU), `TimedOut` (none pending).
        DmaFault = 88 => "dma_fault",
    }
}

/// Interrupt lines (IOAPIC inputs 0..24; line `n` uses vector `0x40 + n`).
pub const IRQ_LINES: u64 = 24;
/// Lines the kernel keeps: 0 and 2 (PIT: ISA IRQ 0 is usually wired to input 2) and 4
/// (COM1, the kernel log).
pub const KERNEL_IRQS: [u64; 3] = [0, 2, 4];

/// Port ranges the kernel keeps for itself (PIC, PIT, COM1 log, QEMU debug exit, PCI
/// configuration space). QEMU's isa-debug-exit device decodes 0xf4..=0xf7 (`iosize=0x04`):
/// a write to any of them ends the whole run, so all four are the kernel's. Whoever holds
/// 0xcf8..=0xcff can reprogram every PCI device (move BARs over another partition's
/// memory, turn on DMA): configuration space is reached only through `pci_config`.
pub const KERNEL_PORTS: [(u16, u16); 6] = [
    (0x20, 0x21),
    (0x40, 0x43),
    (0xa0, 0xa1),
    (0x3f8, 0x3ff),
    (0xf4, 0xf7),
    (0xcf8, 0xcff),
];

/// Number of time partitions (0 = background).
pub const TIME_PARTITIONS: u64 = 16;
/// Schedule slots and windows per schedule.
pub const MAX_SCHEDULES: u64 = 4;
pub const MAX_WINDOWS: u64 = 32;
/// Longest major frame (ns): one hour. Far beyond any real schedule, and small enough that
/// no sum of boundary times can overflow in the lifetime of a machine.
pub const MAX_MAJOR_FRAME: u64 = 3_600_000_000_000;
/// Shortest window and shortest major frame (ns): 10 us. Every window boundary is a timer
/// interrupt; with windows and frames at least this long, boundaries come at most twice per
/// 10 us, so no schedule can keep the CPU busy switching windows (a 16 ns frame did).
pub const MIN_WINDOW: u64 = 10_000;

/// One window of a schedule, as `schedule_set` reads it from user memory.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WindowSpec {
    /// Start within the major frame (ns).
    pub offset: u64,
    pub duration: u64,
    /// Time partition 1..TIME_PARTITIONS.
    pub partition: u64,
    /// The CPU whose schedule the window is in (0 = the boot CPU).
    pub cpu: u64,
}

impl WindowSpec {
    /// Its size in user memory (four `u64`, no padding).
    pub const SIZE: usize = 32;

    /// The spec as it lies in user memory (native byte order, as `repr(C)` lays it out).
    pub fn from_bytes(raw: &[u8; Self::SIZE]) -> Self {
        let word = |n: usize| u64::from_ne_bytes(raw[n * 8..n * 8 + 8].try_into().unwrap());
        Self {
            offset: word(0),
            duration: word(1),
            partition: word(2),
            cpu: word(3),
        }
    }
}

codes::code_enum! {
    /// Attributes `thread_set` can change.
    pub enum ThreadAttribute: u64 {
        /// Scheduling priority, at most the thread's task's MCP (else `McpExceeded`).
        Priority = 1 => "priority",
        /// The thread that receives this thread's exception messages (0 = none). Must belong
        /// to the same task or to an ancestor task.
        ExceptionHandler = 2 => "exception_handler",
        /// User address of the thread's [`IpcBuffer`](crate::ipc::IpcBuffer) (8-byte aligned,
        /// 0 = none); checked to be mapped writable when set and whenever IPC uses it.
        IpcBuffer = 3 => "ipc_buffer",
        /// FS base (a canonical user address), e.g. for a guest's `arch_prctl(ARCH_SET_FS)`.
        FsBase = 4 => "fs_base",
        /// GS base (a canonical user address).
        GsBase = 5 => "gs_base",
        /// Time partition (0 = background). Needs `SCHEDULING`.
        TimePartition = 6 => "time_partition",
        /// A forwarded system call (a `syscall` of a task without `NATIVE_SYSCALLS`) that
        /// the kernel answers itself, without an exception message: the thread's `syscall`
        /// with this number in `rax` returns at once with the result in `rax` (the other
        /// registers as they were). For a call whose result is fixed for the thread, as a
        /// guest's Linux `getpid`. Value: [`syscall_answer`]`(number, result)`, 0 = none;
        /// one number per thread.
        SyscallAnswer = 7 => "syscall_answer",
        /// The CPU the thread runs on: an online one (0 = the boot CPU; else
        /// `InvalidArgument`) of its task's resource partition's CPU mask (else
        /// `NotPermitted`). It moves at once, unless another CPU is running it
        /// (`NotPermitted`: set it while it waits, or from its own CPU). A new thread runs
        /// on its creator's CPU. Its time partition's windows are those of this CPU's
        /// schedule; the background runs on every CPU.
        Cpu = 8 => "cpu",
        /// 1: the thread moves to the CPU of each thread whose message it takes, so a
        /// server's work runs on its caller's CPU, in its caller's windows there, never in
        /// another CPU's; 0 (the default): it stays (other values: `InvalidArgument`). A
        /// move that [`Self::Cpu`] would refuse is not made (it follows its callers among its
        /// partition's CPUs only).
        FollowsCallers = 9 => "follows_callers",
    }
}

/// The value of [`ThreadAttribute::SyscallAnswer`] that answers `number` with `result`
/// (zero-extended to 64 bits): the number in the upper half, the result in the lower.
pub const fn syscall_answer(number: u32, result: u32) -> u64 {
    (number as u64) << 32 | result as u64
}

codes::code_enum! {
    /// Error codes returned in `rax`.
    pub enum Error: u64 {
        Ok = 0 => "Ok",
        /// The call number does not exist.
        InvalidCall = 1 => "InvalidCall",
        /// The caller's task lacks the ability the call needs (or asked to give more abilities
        /// than it has).
        AbilityDenied = 2 => "AbilityDenied",
        /// An argument is out of range.
        InvalidArgument = 3 => "InvalidArgument",
        /// A buffer or page is not (entirely) mapped user memory with the rights the call needs.
        BadAddress = 4 => "BadAddress",
        /// No thread, task or resource partition has this identifier (any more).
        NoSuchObject = 5 => "NoSuchObject",
        /// The object exists but is not the caller's to use (control or communication right).
        NotPermitted = 6 => "NotPermitted",
        /// A priority above the maximum controlled priority.
        McpExceeded = 7 => "McpExceeded",
        /// The resource partition's kernel-memory quota is used up.
        QuotaExceeded = 8 => "QuotaExceeded",
        /// A destination page is already mapped.
        AlreadyMapped = 9 => "AlreadyMapped",
        /// The timeout expired (immediately, for a zero timeout) before the operation could
        /// happen.
        TimedOut = 10 => "TimedOut",
        /// The peer was killed while the caller waited for it.
        PeerGone = 11 => "PeerGone",
        /// A reply to a thread that is not waiting for one from the caller.
        NotWaiting = 12 => "NotWaiting",
        /// A fixed kernel table (e.g. resource-partition slots) is full.
        OutOfResources = 13 => "OutOfResources",
    }
}

bitflags! {
    /// What a task may ask of the kernel. A child's set is a subset of its parent's.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub struct Abilities: u64 {
        const CREATE_TASK = 1 << 0;
        const CREATE_THREAD = 1 << 1;
        const MAP = 1 << 2;
        const PHYSICAL_MEMORY = 1 << 3;
        const IRQ = 1 << 4;
        const IO_PORTS = 1 << 5;
        const SCHEDULING = 1 << 6;
        const PARTITION_CONTROL = 1 << 7;
        const SYSTEM_HALT = 1 << 8;
        const DEBUG_LOG = 1 << 9;
        /// `syscall` reaches the kernel; without it every `syscall` is delivered to the
        /// thread's exception handler (paravirtualized guests).
        const NATIVE_SYSCALLS = 1 << 10;
    }
}

bitflags! {
    /// Rights of a user page; every mapped page is readable.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub struct PageRights: u64 {
        const WRITE = 1 << 0;
        const EXECUTE = 1 << 1;
    }
}

/// A thread identifier: slot index in bits 0..16, generation in bits 16..32 (so a stale
/// identifier of a killed thread never names its successor in the slot). Never 0.
/// In arguments, 0 ([`ThreadId::OWN`]) means the caller (or no thread) where a call says so.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ThreadId(pub u64);

impl ThreadId {
    /// 0: the calling thread, or none, where a call says so.
    pub const OWN: Self = Self(0);

    /// `id`, or [`Self::OWN`] for none.
    pub const fn or_own(id: Option<Self>) -> Self {
        match id {
            Some(id) => id,
            None => Self::OWN,
        }
    }

    /// `None` for [`Self::OWN`].
    pub const fn named(self) -> Option<Self> {
        if self.0 == 0 { None } else { Some(self) }
    }
}

/// A task identifier, encoded like [`ThreadId`]. Never 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct TaskId(pub u64);

impl TaskId {
    /// 0: the caller's task, where a call says so.
    pub const OWN: Self = Self(0);

    /// `id`, or [`Self::OWN`] for none.
    pub const fn or_own(id: Option<Self>) -> Self {
        match id {
            Some(id) => id,
            None => Self::OWN,
        }
    }

    /// `None` for [`Self::OWN`].
    pub const fn named(self) -> Option<Self> {
        if self.0 == 0 { None } else { Some(self) }
    }
}

/// Packs a slot index and generation into an identifier (shared by threads and tasks).
pub const fn make_id(index: usize, generation: u16) -> u64 {
    ((generation as u64) << 16) | (index as u64 + 1)
}

/// Splits an identifier into (slot index, generation); `None` for 0 or stray high bits.
pub const fn split_id(id: u64) -> Option<(usize, u16)> {
    if id == 0 || id >> 32 != 0 || id & 0xffff == 0 {
        return None;
    }
    Some(((id & 0xffff) as usize - 1, (id >> 16) as u16))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kernel_port(port: u16) -> bool {
        KERNEL_PORTS
            .iter()
            .any(|&(lo, hi)| (lo..=hi).contains(&port))
    }

    #[test]
    fn the_whole_exit_device_is_the_kernels() {
        // QEMU's isa-debug-exit (iobase 0xf4, iosize 4): any of its ports ends the run.
        assert!((0xf4..=0xf7).all(kernel_port));
        assert!(!kernel_port(0xf3) && !kernel_port(0xf8));
    }

    #[test]
    fn a_window_spec_decodes_from_its_memory_layout() {
        assert_eq!(core::mem::size_of::<WindowSpec>(), WindowSpec::SIZE);
        let mut raw = [0u8; WindowSpec::SIZE];
        for (n, v) in [7u64, 8, 9, 1].iter().enumerate() {
            raw[n * 8..n * 8 + 8].copy_from_slice(&v.to_ne_bytes());
        }
        let w = WindowSpec::from_bytes(&raw);
        assert_eq!((w.offset, w.duration, w.partition, w.cpu), (7, 8, 9, 1));
    }

    #[test]
    fn ids_round_trip_and_reject_stray_bits() {
        assert_eq!(split_id(make_id(5, 7)), Some((5, 7)));
        assert_eq!(split_id(0), None);
        assert_eq!(split_id(1 << 40 | 1), None);
    }
}
