//! The health monitor's decisions: which ARINC 653 error a kernel fault report is
//! ([`classify`]), which action the configuration's health tables give an error
//! ([`decide`], by [`HealthTable::resolve`]), the event counters and recent-event ring
//! ([`HealthMonitor`]) and the one-line event log ([`write_log_line`]).
//!
//! # Fault reports → errors ([`classify`])
//!
//! A fault of a partition thread without its own handler reaches syssw as an
//! [`ExceptionMessage`] (vector 0..31, or [`VECTOR_SYSCALL`] for a `syscall` of a task
//! without NATIVE_SYSCALLS). ARINC 653 has no I/O or privilege error, so:
//!
//! | vector | error |
//! |---|---|
//! | #PF (14) | `stack_overflow` if the fault address (CR2) lies in the stack guard, else `memory_violation` |
//! | #SS (12) | `stack_overflow` if `rsp` lies in the stack guard, else `memory_violation` |
//! | #NP (11), #BR (5), #AC (17) | `memory_violation` |
//! | #DE (0), #OF (4), #MF (16), #XM (19) | `numeric_error` |
//! | #GP (13: privileged instruction, ungranted I/O port, non-canonical address), #UD (6), #DB (1), #BP (3), #NM (7), #TS (10), #CP (21), forwarded `syscall` | `illegal_request` |
//! | NMI (2), #DF (8), 9, 15, #MC (18), #VE (20), 22..=31, any other number | `hardware_fault` |
//!
//! #GP is `illegal_request` rather than `memory_violation` because its usual causes in
//! ring 3 are instructions the partition may not execute (`in`/`out` on a port it was not
//! granted, `cli`, `hlt`, ...); a bad pointer shows up as #PF.
//!
//! A DMA request of a partition's PCI device outside the partition's DMA region, which the
//! IOMMU blocked (the kernel's `dma_fault`), is a `memory_violation` of the partition that
//! owns the device ([`DmaFault`]).
//!
//! # Log line (an interface: scenario tests match it)
//!
//! ```text
//! health: t=<ms>.<us>ms partition=<name> error=<error> detail=<detail> action=<action>
//! ```
//!
//! - `<ms>.<us>`: the event time (ns since boot) as whole milliseconds, a dot and the
//!   microseconds within the millisecond as exactly 3 digits (`t=1234.005ms`);
//! - `<name>`: the partition's configured name, or `-` for a module-level error;
//! - `<error>` and `<action>`: the configuration's names (`memory_violation`,
//!   `warm_restart`, ...: [`ErrorCode::name`], [`HealthAction::name`]);
//! - `<detail>` never contains a space: `-` (none); `0x<hex>` (a code); for a CPU
//!   exception `<#XX>,error=0x<hex>,address=0x<hex>,rip=0x<hex>` where `<#XX>` is the
//!   mnemonic of [`vector_name`] (`#PF`, `NMI`, ...) or `vector=<decimal>` for a vector
//!   without one; for a forwarded system call `syscall,number=<decimal rax>,rip=0x<hex>`;
//!   for a blocked DMA request `dma,device=<BB:DD.F>,<read|write>,address=0x<hex>,reason=<decimal>`
//!   (the device, the page of the bus address, the VT-d fault reason);
//!   for a text `"<text>"` with `"` and `\` escaped by a backslash and every byte outside
//!   printable ASCII (and the space) written as `\xNN`.
//!
//! No trailing newline; the glue prints the line (it appears in the kernel log as
//! `[syssw] health: ...`). Example:
//! `health: t=12.345ms partition=plc error=memory_violation detail=#PF,error=0x6,address=0xdead0000,rip=0x401000 action=idle`
//!
//! This module decides and records; it never acts (stopping, restarting and halting are
//! the glue's, see [`crate::mode`]).

use config::binary::SystemView;
use config::model::{ErrorCode, HealthAction, HealthTable, MAX_PARTITIONS};
use core::fmt::{self, Write};
use core::ops::Range;

pub use abi::ipc::{ExceptionMessage, VECTOR_SYSCALL};

/// Longest text detail kept with an event (longer text is cut).
pub const DETAIL_TEXT_MAX: usize = 64;
/// Events the recent-event ring keeps.
pub const RECENT_EVENTS: usize = 16;

/// What the kernel reported about a fault (the parts the health monitor uses).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fault {
    /// CPU exception vector 0..=31, or [`VECTOR_SYSCALL`].
    pub vector: u64,
    pub error_code: u64,
    /// CR2 of a page fault, else 0.
    pub address: u64,
    pub rip: u64,
    pub rsp: u64,
    /// The system-call number of a forwarded `syscall`.
    pub rax: u64,
}

impl Fault {
    pub fn from_message(m: &ExceptionMessage) -> Self {
        Fault {
            vector: m.vector,
            error_code: m.error_code,
            address: m.fault_address,
            rip: m.registers.rip,
            rsp: m.registers.rsp,
            rax: m.registers.rax,
        }
    }
}

/// The mnemonic of a CPU exception vector (`#PF`, `NMI`, ...) or `syscall` for
/// [`VECTOR_SYSCALL`]; `None` for reserved and unknown numbers.
pub fn vector_name(vector: u64) -> Option<&'static str> {
    Some(match vector {
        0 => "#DE",
        1 => "#DB",
        2 => "NMI",
        3 => "#BP",
        4 => "#OF",
        5 => "#BR",
        6 => "#UD",
        7 => "#NM",
        8 => "#DF",
        10 => "#TS",
        11 => "#NP",
        12 => "#SS",
        13 => "#GP",
        14 => "#PF",
        16 => "#MF",
        17 => "#AC",
        18 => "#MC",
        19 => "#XM",
        20 => "#VE",
        21 => "#CP",
        28 => "#HV",
        29 => "#VC",
        30 => "#SX",
        VECTOR_SYSCALL => "syscall",
        _ => return None,
    })
}

/// The ARINC 653 error a fault is (see the table in the module documentation).
/// `stack_guard` is the faulting partition's stack guard range (unmapped pages below its
/// stack); an empty range if it has none.
pub fn classify(fault: &Fault, stack_guard: Range<u64>) -> ErrorCode {
    use ErrorCode as E;
    match fault.vector {
        14 if stack_guard.contains(&fault.address) => E::StackOverflow,
        12 if stack_guard.contains(&fault.rsp) => E::StackOverflow,
        5 | 11 | 12 | 14 | 17 => E::MemoryViolation,
        0 | 4 | 16 | 19 => E::NumericError,
        1 | 3 | 6 | 7 | 10 | 13 | 21 | VECTOR_SYSCALL => E::IllegalRequest,
        _ => E::HardwareFault,
    }
}

/// The action for `error` of `partition` (`None`: outside any partition) under the
/// system's health tables. A partition index the system does not have counts as
/// module-level (fail safe).
pub fn decide(system: &SystemView<'_>, partition: Option<usize>, error: ErrorCode) -> HealthAction {
    let module = system.health();
    match partition.filter(|&p| p < system.partition_count()) {
        Some(p) => HealthTable::resolve(Some(&system.partition(p).health), &module, error),
        None => HealthTable::resolve(None, &module, error),
    }
}

/// A short text kept with an event (at most [`DETAIL_TEXT_MAX`] bytes; any bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Text {
    bytes: [u8; DETAIL_TEXT_MAX],
    len: u8,
}

impl Text {
    /// The first [`DETAIL_TEXT_MAX`] bytes of `text`.
    pub fn new(text: &[u8]) -> Self {
        let len = text.len().min(DETAIL_TEXT_MAX);
        let mut bytes = [0u8; DETAIL_TEXT_MAX];
        bytes[..len].copy_from_slice(&text[..len]);
        Text {
            bytes,
            len: len as u8,
        }
    }

    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len as usize]
    }
}

/// What else is known about an error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detail {
    None,
    /// A number (e.g. an application's error code).
    Code(u64),
    /// A kernel fault report.
    Fault(Fault),
    /// A message (e.g. RAISE_APPLICATION_ERROR's).
    Text(Text),
    /// A DMA request the IOMMU blocked.
    Dma(DmaFault),
}

/// A DMA request of a device outside its partition's DMA region, blocked by the IOMMU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DmaFault {
    /// The device's routing id: bus << 8 | device << 3 | function.
    pub source: u16,
    /// The page of the bus address it asked for.
    pub address: u64,
    pub write: bool,
    /// The VT-d fault reason.
    pub reason: u8,
}

impl fmt::Display for Detail {
    /// The `<detail>` field of the log line (see the module documentation).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Detail::None => f.write_char('-'),
            Detail::Code(code) => write!(f, "{code:#x}"),
            Detail::Fault(fault) if fault.vector == VECTOR_SYSCALL => {
                write!(f, "syscall,number={},rip={:#x}", fault.rax, fault.rip)
            }
            Detail::Fault(fault) => {
                match vector_name(fault.vector) {
                    Some(name) => f.write_str(name)?,
                    None => write!(f, "vector={}", fault.vector)?,
                }
                write!(
                    f,
                    ",error={:#x},address={:#x},rip={:#x}",
                    fault.error_code, fault.address, fault.rip
                )
            }
            Detail::Dma(d) => write!(
                f,
                "dma,device={:02x}:{:02x}.{},{},address={:#x},reason={}",
                d.source >> 8,
                (d.source >> 3) & 0x1f,
                d.source & 7,
                if d.write { "write" } else { "read" },
                d.address,
                d.reason
            ),
            Detail::Text(text) => {
                f.write_char('"')?;
                for &b in text.as_bytes() {
                    match b {
                        b'"' | b'\\' => {
                            f.write_char('\\')?;
                            f.write_char(b as char)?;
                        }
                        0x21..=0x7e => f.write_char(b as char)?,
                        _ => write!(f, "\\x{b:02x}")?,
                    }
                }
                f.write_char('"')
            }
        }
    }
}

/// An error reported to the health monitor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ErrorEvent {
    /// The partition (index in the configuration), `None` for a module-level error.
    pub partition: Option<usize>,
    pub error: ErrorCode,
    pub detail: Detail,
}

/// A handled event: what happened, when, and what was decided.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// ns since boot.
    pub time: u64,
    /// `None` for a module-level error.
    pub partition: Option<usize>,
    pub error: ErrorCode,
    pub detail: Detail,
    pub action: HealthAction,
}

/// Counters and the recent-event ring (fixed size, no allocation).
#[derive(Clone, Debug)]
pub struct HealthMonitor {
    counts: [u32; MAX_PARTITIONS],
    module_count: u32,
    total: u64,
    recent: [Option<Record>; RECENT_EVENTS],
    next: usize,
}

impl Default for HealthMonitor {
    fn default() -> Self {
        Self::new()
    }
}

impl HealthMonitor {
    pub const fn new() -> Self {
        HealthMonitor {
            counts: [0; MAX_PARTITIONS],
            module_count: 0,
            total: 0,
            recent: [None; RECENT_EVENTS],
            next: 0,
        }
    }

    /// Handles `event` at time `now`: decides its action ([`decide`]), counts it, keeps it
    /// in the ring and returns the record (for [`write_log_line`] and for acting on
    /// `record.action`). A partition index the system does not have is recorded as a
    /// module-level error.
    pub fn report(&mut self, system: &SystemView<'_>, now: u64, event: ErrorEvent) -> Record {
        let partition = event.partition.filter(|&p| p < system.partition_count());
        let record = Record {
            time: now,
            partition,
            error: event.error,
            detail: event.detail,
            action: decide(system, partition, event.error),
        };
        let counter = match partition.and_then(|p| self.counts.get_mut(p)) {
            Some(c) => c,
            None => &mut self.module_count,
        };
        *counter = counter.saturating_add(1);
        self.total = self.total.saturating_add(1);
        self.recent[self.next] = Some(record);
        self.next = (self.next + 1) % RECENT_EVENTS;
        record
    }

    /// Events of `partition` (`None`: module-level) so far (saturating).
    pub fn count(&self, partition: Option<usize>) -> u32 {
        match partition {
            Some(p) => self.counts.get(p).copied().unwrap_or(0),
            None => self.module_count,
        }
    }

    /// All events so far (saturating).
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The last [`RECENT_EVENTS`] events, oldest first.
    pub fn recent(&self) -> impl Iterator<Item = &Record> + '_ {
        (0..RECENT_EVENTS)
            .filter_map(move |k| self.recent[(self.next + k) % RECENT_EVENTS].as_ref())
    }

    /// The newest event of `partition` still in the ring (GET_ERROR_STATUS-like).
    pub fn last(&self, partition: Option<usize>) -> Option<&Record> {
        self.recent().filter(|r| r.partition == partition).last()
    }
}

/// Writes the log line of `record` (format in the module documentation; no newline).
pub fn write_log_line(
    out: &mut impl Write,
    system: &SystemView<'_>,
    record: &Record,
) -> fmt::Result {
    let name = match record.partition {
        Some(p) if p < system.partition_count() => system.partition(p).name,
        _ => "-",
    };
    write!(
        out,
        "health: t={}.{:03}ms partition={} error={} detail={} action={}",
        record.time / 1_000_000,
        record.time / 1_000 % 1_000,
        name,
        record.error.name(),
        record.detail,
        record.action.name()
    )
}

#[cfg(test)]
mod tests;
