//! The vocabulary shared by the TOML description, the validator and the binary form: limits,
//! health-monitoring errors and actions, port kinds and directions, shared-memory rights,
//! the abilities a partition may hold, and the naming rules. Everything here is `no_std` and
//! allocation-free, because syssw's decoder uses it too.

use abi::syscall::{self, Abilities, PageRights};

/// Bytes per page; every memory size of a partition or segment is a multiple of it.
pub const PAGE_SIZE: u64 = 4096;

/// Most partitions: the kernel has 16 resource partitions and syssw keeps one for itself.
pub const MAX_PARTITIONS: usize = 15;
/// Most schedules ([`abi::syscall::MAX_SCHEDULES`]); the first is the initial one.
pub const MAX_SCHEDULES: usize = syscall::MAX_SCHEDULES as usize;
/// Most windows per schedule ([`abi::syscall::MAX_WINDOWS`]).
pub const MAX_WINDOWS: usize = syscall::MAX_WINDOWS as usize;
/// Longest major frame the kernel accepts (ns).
pub const MAX_MAJOR_FRAME: u64 = syscall::MAX_MAJOR_FRAME;
/// Shortest window and major frame (ns; the kernel's limit, 10 us).
pub const MIN_WINDOW: u64 = syscall::MIN_WINDOW;
/// Shortest PLC task deadline (`plc.deadline`, ns): the runtime checks the clock every
/// thousand VM instructions, a few microseconds apart.
pub const MIN_TASK_DEADLINE: u64 = 100_000;
/// Most CPUs a system may use (`[system] cpus`; the machine description's
/// [`abi::machine::MAX_CPUS`]). CPU 0 is the boot CPU.
pub const MAX_CPUS: usize = abi::machine::MAX_CPUS;
/// Number of time partitions; 0 is the background, windows use 1..TIME_PARTITIONS.
pub const TIME_PARTITIONS: u8 = syscall::TIME_PARTITIONS as u8;
/// Most shared-memory segments.
pub const MAX_SEGMENTS: usize = 32;
/// Most I/O port ranges, shared-memory attachments, ports and channels in one system.
pub const MAX_IO_RANGES: usize = 64;
pub const MAX_ATTACHMENTS: usize = 128;
pub const MAX_PORTS: usize = 128;
pub const MAX_CHANNELS: usize = 128;

/// Longest name of a partition: syssw names the partition's task after it, and task names
/// hold at most [`abi::syscall::TASK_NAME_MAX`] bytes.
pub const PARTITION_NAME_MAX: usize = syscall::TASK_NAME_MAX as usize;
/// Longest name of anything else (system, schedule, image, port, channel, segment).
pub const NAME_MAX: usize = 31;

/// Largest message of a port (the service protocol's limit; a message longer than one IPC
/// message travels in parts).
pub const MAX_MESSAGE_SIZE: u32 = protocol::MAX_MESSAGE_SIZE;
/// The message size of an IEC 61499 runtime's management ports (`iec61499.mgmt`): one
/// request or answer of the management protocol, as `fbctl` and the runtime use it.
pub const MGMT_MESSAGE_SIZE: u32 = 4096;
/// Deepest queuing port (messages).
pub const MAX_QUEUE_DEPTH: u32 = 256;

/// Priority of syssw's own threads ([`abi::syscall::ROOT_PRIORITY`]).
pub const SYSSW_PRIORITY: u8 = syscall::ROOT_PRIORITY;
/// Allowed maximum controlled priorities of partitions: `MCP_MIN..=MCP_MAX`. Every partition
/// thread stays strictly below syssw, so the health monitor and the port service always
/// preempt partitions; 0 is excluded because a partition needs at least one priority above
/// the idle level to be told apart from an idle loop.
pub const MCP_MIN: u8 = 1;
pub const MCP_MAX: u8 = SYSSW_PRIORITY - 1;

/// Interrupt lines (IOAPIC inputs) a partition may name: `0..IRQ_LINES` (the kernel's).
pub const IRQ_LINES: u8 = abi::syscall::IRQ_LINES as u8;
/// Lines the kernel keeps (`abi::syscall::KERNEL_IRQS`): 0 and 2 (the PIT) and 4 (COM1).
pub const RESERVED_IRQS: [u8; 3] = [
    abi::syscall::KERNEL_IRQS[0] as u8,
    abi::syscall::KERNEL_IRQS[1] as u8,
    abi::syscall::KERNEL_IRQS[2] as u8,
];

/// Default stack of a partition's first thread.
pub const DEFAULT_STACK: u64 = 64 * 1024;
/// Default kernel-object quota of a partition's resource partition.
pub const DEFAULT_KERNEL_THREADS: u32 = 16;
pub const DEFAULT_KERNEL_TASKS: u32 = 1;

/// The kernel's fixed object tables (kernel/src/state.rs): threads and tasks all partitions'
/// quotas together may not exceed, after syssw's own share (`SYSSW_THREADS`, `SYSSW_TASKS`).
pub const KERNEL_THREADS: u32 = 256;
pub const KERNEL_TASKS: u32 = 64;
pub const SYSSW_THREADS: u32 = 16;
pub const SYSSW_TASKS: u32 = 1;

/// Memory kept out of the partitions' budget: the kernel image, firmware holes, the system
/// image and syssw itself.
pub const SYSTEM_RESERVE: u64 = 32 * 1024 * 1024;
/// Kernel memory syssw's own resource partition keeps (its page tables and objects).
pub const SYSSW_KERNEL_RESERVE: u64 = 1024 * 1024;

/// The kernel's page-table pool for a machine with `memory` bytes of RAM: 1/8 of it, at least
/// 16 MiB and at most 128 MiB (kernel/src/boot.rs). Every resource partition's
/// `kernel_memory` quota is carved out of this pool; the rest of RAM is user memory.
pub const fn kernel_pool(memory: u64) -> u64 {
    let pool = memory / 8 / PAGE_SIZE * PAGE_SIZE;
    if pool < 16 << 20 {
        16 << 20
    } else if pool > 128 << 20 {
        128 << 20
    } else {
        pool
    }
}

/// Abilities a partition may hold. The others (system halt, physical memory, scheduling,
/// partition control) belong to syssw alone: with any of them a partition could break the
/// isolation of the others.
pub const PARTITION_ABILITIES: Abilities = Abilities::CREATE_TASK
    .union(Abilities::CREATE_THREAD)
    .union(Abilities::MAP)
    .union(Abilities::IRQ)
    .union(Abilities::IO_PORTS)
    .union(Abilities::DEBUG_LOG)
    .union(Abilities::NATIVE_SYSCALLS);

/// The configuration names of the abilities (`abilities = [...]`).
pub const ABILITY_NAMES: [(&str, Abilities); 11] = [
    ("create_task", Abilities::CREATE_TASK),
    ("create_thread", Abilities::CREATE_THREAD),
    ("map", Abilities::MAP),
    ("physical_memory", Abilities::PHYSICAL_MEMORY),
    ("irq", Abilities::IRQ),
    ("io_ports", Abilities::IO_PORTS),
    ("scheduling", Abilities::SCHEDULING),
    ("partition_control", Abilities::PARTITION_CONTROL),
    ("system_halt", Abilities::SYSTEM_HALT),
    ("debug_log", Abilities::DEBUG_LOG),
    ("native_syscalls", Abilities::NATIVE_SYSCALLS),
];

/// The ability called `name` in a configuration.
pub fn ability_by_name(name: &str) -> Option<Abilities> {
    ABILITY_NAMES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|&(_, a)| a)
}

/// The errors the health monitor handles, the port kinds and directions: the service
/// protocol's code tables (one definition for the configuration, syssw and the partitions).
pub use protocol::{Direction, Discipline, ErrorCode, PortKind};

codes::code_enum! {
    /// What the health monitor does about an error (binary code 0 means "not set").
    pub enum HealthAction: u8 {
        /// Log it and carry on.
        Ignore = 1 => "ignore",
        /// Stop the partition (its threads are suspended; the others run on).
        Idle = 2 => "idle",
        /// Restart the partition from its image with fresh memory.
        ColdRestart = 3 => "cold_restart",
        /// Restart the partition's threads, keeping its memory.
        WarmRestart = 4 => "warm_restart",
        /// Stop the whole module with the failure outcome (QEMU exit 35).
        Shutdown = 5 => "shutdown",
        /// Stop the whole module with the success outcome (QEMU exit 33): the expected end of
        /// a test scenario, e.g. a test partition raising `application_error` when it is done.
        ShutdownSuccess = 6 => "shutdown_success",
    }
}

codes::code_enum! {
    /// ARINC 653 Part 2 SCHEDULE_CHANGE_ACTION: what a switch to a module schedule does to a
    /// partition when it takes effect (at the major-frame boundary). The binary code is the
    /// partition's 2 bits in [`ChangeActions`].
    pub enum ChangeAction: u8 {
        /// Nothing (ARINC IGNORE): the partition runs on in its new windows.
        Ignore = 0 => "ignore",
        /// Stop the partition for good (ARINC STOP), as SET_PARTITION_MODE(IDLE).
        Idle = 1 => "idle",
        /// Restart it from its image (ARINC COLD_START).
        ColdStart = 2 => "cold_start",
        /// Restart it keeping its memory (ARINC WARM_START).
        WarmStart = 3 => "warm_start",
    }
}

/// A schedule's change actions, 2 bits per partition index (bits 2i..2i+2: partition i's
/// [`ChangeAction`] code); every partition not named is `ignore` (0).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ChangeActions(pub u32);

impl ChangeActions {
    /// Partition `partition`'s action (`ignore` beyond [`MAX_PARTITIONS`]).
    pub fn get(self, partition: usize) -> ChangeAction {
        if partition >= MAX_PARTITIONS {
            return ChangeAction::Ignore;
        }
        let code = (self.0 >> (2 * partition)) & 0b11;
        ChangeAction::from_code(code as u8).unwrap_or(ChangeAction::Ignore)
    }

    /// Sets partition `partition`'s action (`partition` < [`MAX_PARTITIONS`]).
    pub fn set(&mut self, partition: usize, action: ChangeAction) {
        debug_assert!(partition < MAX_PARTITIONS);
        let shift = 2 * partition as u32;
        self.0 = (self.0 & !(0b11 << shift)) | (u32::from(action.code()) << shift);
    }

    /// Whether only the first `partitions` partitions have an action other than `ignore`.
    pub fn within(self, partitions: usize) -> bool {
        partitions >= 16 || self.0 >> (2 * partitions) == 0
    }
}

/// One health-monitoring table: an optional action per error kind.
///
/// Resolution rule (syssw applies it, [`HealthTable::resolve`] implements it): an error of a
/// partition takes the partition's entry, else the module table's entry, else
/// [`HealthAction::Idle`] (a faulty partition is stopped and never hurts the others). An error
/// outside any partition takes the module table's entry, else [`HealthAction::Shutdown`];
/// partition actions (`idle`, `cold_restart`, `warm_restart`) mean `shutdown` there.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct HealthTable(pub [Option<HealthAction>; ErrorCode::COUNT]);

impl HealthTable {
    pub fn get(&self, error: ErrorCode) -> Option<HealthAction> {
        self.0[error as usize]
    }

    pub fn set(&mut self, error: ErrorCode, action: HealthAction) {
        self.0[error as usize] = Some(action);
    }

    /// The action for `error` of a partition with table `partition` (`None` for an error
    /// outside any partition) under module table `module`.
    pub fn resolve(
        partition: Option<&HealthTable>,
        module: &HealthTable,
        error: ErrorCode,
    ) -> HealthAction {
        match partition {
            Some(table) => table
                .get(error)
                .or(module.get(error))
                .unwrap_or(HealthAction::Idle),
            None => match module.get(error) {
                Some(
                    HealthAction::Idle | HealthAction::ColdRestart | HealthAction::WarmRestart,
                )
                | None => HealthAction::Shutdown,
                Some(action) => action,
            },
        }
    }

    /// The 8 action bytes of the binary form (0 = not set).
    pub fn to_bytes(&self) -> [u8; ErrorCode::COUNT] {
        let mut out = [0u8; ErrorCode::COUNT];
        for (byte, action) in out.iter_mut().zip(self.0) {
            *byte = action.map_or(0, |a| a as u8);
        }
        out
    }

    /// Parses the 8 action bytes; `None` for an unknown code.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        let mut table = HealthTable::default();
        if bytes.len() != ErrorCode::COUNT {
            return None;
        }
        for (slot, &code) in table.0.iter_mut().zip(bytes) {
            *slot = match code {
                0 => None,
                code => Some(HealthAction::from_code(code)?),
            };
        }
        Some(table)
    }
}

codes::code_enum! {
    /// Rights of a partition on a shared-memory segment (never writable and executable at
    /// once).
    pub enum Rights: u8 {
        Read = 1 => "r",
        ReadWrite = 2 => "rw",
        ReadExecute = 3 => "rx",
    }
}

impl Rights {
    /// The page rights `map` takes for this (every mapped page is readable).
    pub const fn page_rights(self) -> PageRights {
        match self {
            Self::Read => PageRights::empty(),
            Self::ReadWrite => PageRights::WRITE,
            Self::ReadExecute => PageRights::EXECUTE,
        }
    }
}

/// An inclusive range of I/O ports `first..=last`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct IoRange {
    pub first: u16,
    pub last: u16,
}

impl IoRange {
    /// Number of ports (what `io_grant` takes as `count`).
    pub const fn count(self) -> u32 {
        self.last as u32 - self.first as u32 + 1
    }

    pub const fn overlaps(self, other: IoRange) -> bool {
        self.first <= other.last && other.first <= self.last
    }

    /// The first kernel port range ([`abi::syscall::KERNEL_PORTS`]) this range touches.
    pub fn kernel_conflict(self) -> Option<IoRange> {
        syscall::KERNEL_PORTS
            .iter()
            .map(|&(first, last)| IoRange { first, last })
            .find(|&k| self.overlaps(k))
    }
}

impl core::fmt::Display for IoRange {
    /// `0x2f8-0x2ff`, or `0x60` for a single port.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.first == self.last {
            write!(f, "{:#x}", self.first)
        } else {
            write!(f, "{:#x}-{:#x}", self.first, self.last)
        }
    }
}

/// What the kernel uses the port range `range` (one of [`abi::syscall::KERNEL_PORTS`]) for.
pub fn kernel_port_use(range: IoRange) -> &'static str {
    match range.first {
        0x20 => "the master PIC",
        0x40 => "the PIT",
        0xa0 => "the slave PIC",
        0x3f8 => "COM1, the kernel log",
        0xf4 => "QEMU's isa-debug-exit",
        0xcf8 => {
            "PCI configuration space (no partition ever gets it; its devices are granted by `devices`)"
        }
        _ => "the kernel",
    }
}

/// What the kernel uses a reserved IRQ line for.
pub fn reserved_irq_use(line: u8) -> &'static str {
    match line {
        0 => "the PIT timer",
        2 => "the PIT timer (wired to IOAPIC input 2; the PIC cascade)",
        4 => "COM1, the kernel log",
        _ => "the kernel",
    }
}

/// A set of ISA interrupt lines (bit n = line n).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct IrqMask(pub u32);

impl IrqMask {
    /// Lines a partition may never hold: reserved ones and those beyond [`IRQ_LINES`].
    pub const FORBIDDEN: u32 = !((1u32 << IRQ_LINES) - 1)
        | (1 << RESERVED_IRQS[0])
        | (1 << RESERVED_IRQS[1])
        | (1 << RESERVED_IRQS[2]);

    pub const fn contains(self, line: u8) -> bool {
        line < 32 && self.0 & (1 << line) != 0
    }

    pub fn lines(self) -> impl Iterator<Item = u8> {
        (0..32u8).filter(move |&l| self.contains(l))
    }
}

/// True if `line` is an ISA line (< [`IRQ_LINES`]) the kernel does not keep.
pub fn irq_allowed(line: u8) -> bool {
    line < IRQ_LINES && !RESERVED_IRQS.contains(&line)
}

/// One window of a schedule.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Window {
    /// Start within the major frame (ns).
    pub offset: u64,
    /// Length (ns, > 0).
    pub duration: u64,
    /// Time partition 1..[`TIME_PARTITIONS`].
    pub time_partition: u8,
    /// The CPU whose schedule it is in (the CPU of the partition it names; 0 = the boot
    /// CPU). Every CPU has its own windows in the one major frame.
    pub cpu: u8,
}

impl Window {
    pub const fn end(self) -> u64 {
        self.offset + self.duration
    }

    /// The record `schedule_set` reads.
    pub const fn spec(self) -> syscall::WindowSpec {
        syscall::WindowSpec {
            offset: self.offset,
            duration: self.duration,
            partition: self.time_partition as u64,
            cpu: self.cpu as u64,
        }
    }
}

/// A partition's attachment of a shared-memory segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Attachment {
    /// Index of the segment.
    pub segment: usize,
    pub rights: Rights,
}

/// Most bytes of user memory all partitions and shared segments together may use on a machine
/// with `memory` bytes: RAM minus the kernel pool ([`kernel_pool`]) minus [`SYSTEM_RESERVE`].
pub const fn user_memory_limit(memory: u64) -> u64 {
    memory
        .saturating_sub(kernel_pool(memory))
        .saturating_sub(SYSTEM_RESERVE)
}

/// Most bytes of kernel memory all partitions' `kernel_memory` quotas together may use: the
/// kernel pool minus what syssw's own resource partition keeps ([`SYSSW_KERNEL_RESERVE`]).
pub const fn kernel_memory_limit(memory: u64) -> u64 {
    kernel_pool(memory).saturating_sub(SYSSW_KERNEL_RESERVE)
}

/// Why a name is not acceptable (see [`check_name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NameError {
    Empty,
    TooLong { max: usize },
    BadCharacter(char),
    BadStart(char),
}

impl core::fmt::Display for NameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Empty => write!(f, "is empty"),
            Self::TooLong { max } => write!(f, "is longer than {max} bytes"),
            Self::BadCharacter(c) => write!(
                f,
                "contains {c:?} (allowed: ASCII letters, digits, `_` and `-`)"
            ),
            Self::BadStart(c) => write!(f, "starts with {c:?} (it must start with a letter)"),
        }
    }
}

/// Names of everything in a configuration: 1..=`max` bytes, an ASCII letter followed by
/// ASCII letters, digits, `_` or `-`.
pub fn check_name(name: &str, max: usize) -> Result<(), NameError> {
    let mut chars = name.chars();
    let first = chars.next().ok_or(NameError::Empty)?;
    if !first.is_ascii_alphabetic() {
        return Err(NameError::BadStart(first));
    }
    if let Some(c) = chars.find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-')) {
        return Err(NameError::BadCharacter(c));
    }
    if name.len() > max {
        return Err(NameError::TooLong { max });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_pool_follows_the_kernel() {
        assert_eq!(kernel_pool(512 << 20), 64 << 20);
        assert_eq!(kernel_pool(64 << 20), 16 << 20);
        assert_eq!(kernel_pool(4 << 30), 128 << 20);
    }

    #[test]
    fn health_resolution() {
        let mut module = HealthTable::default();
        let mut part = HealthTable::default();
        let e = ErrorCode::DeadlineMissed;
        assert_eq!(
            HealthTable::resolve(Some(&part), &module, e),
            HealthAction::Idle
        );
        assert_eq!(
            HealthTable::resolve(None, &module, e),
            HealthAction::Shutdown
        );
        module.set(e, HealthAction::WarmRestart);
        assert_eq!(
            HealthTable::resolve(Some(&part), &module, e),
            HealthAction::WarmRestart
        );
        assert_eq!(
            HealthTable::resolve(None, &module, e),
            HealthAction::Shutdown
        );
        part.set(e, HealthAction::Ignore);
        assert_eq!(
            HealthTable::resolve(Some(&part), &module, e),
            HealthAction::Ignore
        );
        module.set(e, HealthAction::ShutdownSuccess);
        assert_eq!(
            HealthTable::resolve(None, &module, e),
            HealthAction::ShutdownSuccess
        );
        assert_eq!(HealthTable::from_bytes(&part.to_bytes()), Some(part));
        assert_eq!(HealthTable::from_bytes(&[7, 0, 0, 0, 0, 0, 0, 0]), None);
    }

    #[test]
    fn names() {
        assert!(check_name("plc_1-a", 15).is_ok());
        assert_eq!(check_name("", 15), Err(NameError::Empty));
        assert_eq!(check_name("1a", 15), Err(NameError::BadStart('1')));
        assert_eq!(check_name("a.b", 15), Err(NameError::BadCharacter('.')));
        assert_eq!(
            check_name("abcdefghijklmnop", 15),
            Err(NameError::TooLong { max: 15 })
        );
    }

    #[test]
    fn irq_rules() {
        assert!(irq_allowed(3));
        assert!(!irq_allowed(0) && !irq_allowed(2) && !irq_allowed(4) && !irq_allowed(24));
        assert_eq!(IrqMask::FORBIDDEN & (1 << 3), 0);
        assert_ne!(IrqMask::FORBIDDEN & (1 << 4), 0);
        assert_ne!(IrqMask::FORBIDDEN & (1 << 24), 0);
        let mut lines = IrqMask(0b1010).lines();
        assert_eq!(
            (lines.next(), lines.next(), lines.next()),
            (Some(1), Some(3), None)
        );
    }
}
