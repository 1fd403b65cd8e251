//! The binary configuration: what `cargo xtask` stores as entry `config` of `system.img` and
//! syssw decodes at boot. This layout is an interface contract between the host tools and
//! syssw; any change bumps [`VERSION`].
//!
//! # Layout, version 1
//!
//! All integers are little-endian; no field is aligned (read them with `from_le_bytes`).
//! Names are fixed 32-byte fields of UTF-8, NUL-padded: non-empty, no NUL inside, only NULs
//! after the text (partition names use at most 15 of the bytes). Reserved bytes are zero.
//!
//! ```text
//! Header (96 bytes)
//! offset size field
//! 0      8    magic "WRDNCONF"
//! 8      4    version (1)
//! 12     4    CRC-32 (IEEE, abi::crc32) of bytes [16, total size)
//! 16     4    total size in bytes = 96 + the sizes of all tables below
//! 20     4    reserved
//! 24     32   system name
//! 56     8    memory: RAM budget in bytes
//! 64     2    S  schedules          (<= 4, MAX_SCHEDULES; the first is the initial one)
//! 66     2    W  windows            (<= 128, all schedules together)
//! 68     2    G  shared segments    (<= 32)
//! 70     2    P  partitions         (<= 15)
//! 72     2    I  I/O port ranges    (<= 64)
//! 74     2    A  segment attachments (<= 128)
//! 76     2    T  ports              (<= 128)
//! 78     2    C  channels           (<= 128)
//! 80     2    D  channel destinations (<= 128)
//! 82     6    reserved
//! 88     8    module health table: byte e = action for error e (see below), 0 = not set
//! 96          the tables, in this order, back to back without padding:
//!
//! Schedule (48 bytes) x S
//! 0      32   name
//! 32     8    major frame (ns, > 0)
//! 40     2    first window (index into the window table)
//! 42     2    window count (<= 32); the schedules' window ranges tile the window table in order
//! 44     4    reserved
//!
//! Window (24 bytes) x W; per schedule sorted by offset, disjoint, duration > 0,
//! offset + duration <= major frame
//! 0      8    offset in the major frame (ns)
//! 8      8    duration (ns)
//! 16     1    time partition 1..=15 (one some partition uses)
//! 17     7    reserved
//!
//! Shared segment (40 bytes) x G
//! 0      32   name
//! 32     8    size in bytes (> 0, multiple of 4096)
//!
//! Partition (136 bytes) x P
//! 0      32   name (<= 15 bytes: it names the partition's task)
//! 32     32   image: system.img holds the ELF as entry "partition/<image>"
//! 64     8    memory in bytes (> 0, multiple of 4096; includes the stack)
//! 72     8    kernel memory quota in bytes (> 0, multiple of 4096)
//! 80     8    stack of the first thread in bytes (> 0, multiple of 4096, <= memory)
//! 88     8    abilities (abi::syscall::Abilities bits, within PARTITION_ABILITIES)
//! 96     4    kernel thread quota (>= 1)
//! 100    4    kernel task quota (>= 1)
//! 104    4    IRQ mask: bit n = ISA line n (never 0, 2, 4 or >= 24)
//! 108    1    MCP (1..=199)
//! 109    1    priority of the first thread (<= MCP)
//! 110    1    time partition (0 = background, else 1..=15)
//! 111    1    reserved
//! 112    8    partition health table (as the module's)
//! 120    2    first I/O range,  122  2  I/O range count
//! 124    2    first attachment, 126  2  attachment count
//! 128    2    first port,       130  2  port count
//! 132    4    reserved
//!              (the partitions' I/O-range, attachment and port ranges each tile their table
//!              in partition order)
//!
//! I/O port range (4 bytes) x I; inclusive; no kernel port (abi KERNEL_PORTS); no two overlap
//! 0      2    first port
//! 2      2    last port (>= first)
//!
//! Attachment (4 bytes) x A; a segment at most once per partition
//! 0      2    segment index
//! 2      1    rights: 1 = r, 2 = rw, 3 = rx
//! 3      1    reserved
//!
//! Port (56 bytes) x T; names unique within their partition
//! 0      32   name
//! 32     4    message size in bytes (1..=4096)
//! 36     4    depth: queuing 1..=256 messages; sampling 0
//! 40     8    refresh period (ns) of a sampling input, 0 = none; 0 for every other port
//! 48     2    channel index
//! 50     1    kind: 1 = sampling, 2 = queuing
//! 51     1    direction: 1 = in (destination), 2 = out (source)
//! 52     4    reserved
//!
//! Channel (40 bytes) x C
//! 0      32   name
//! 32     2    source port (global port index; direction out, same kind, its channel = this)
//! 34     2    first destination (index into the destination table)
//! 36     2    destination count (sampling >= 1, queuing exactly 1); the ranges tile the table
//! 38     1    kind: 1 = sampling, 2 = queuing
//! 39     1    reserved
//!
//! Destination (2 bytes) x D
//! 0      2    port index (direction in, same kind, its channel = this one, size >= the
//!             source's size, not twice in one channel); every port is in exactly one channel:
//!             T = C + D
//! ```
//!
//! Health errors (index into a health table): 0 deadline_missed, 1 application_error,
//! 2 numeric_error, 3 illegal_request, 4 stack_overflow, 5 memory_violation,
//! 6 hardware_fault, 7 power_fail. Actions: 0 not set, 1 ignore, 2 idle, 3 cold_restart,
//! 4 warm_restart, 5 shutdown, 6 shutdown_success ([`HealthTable::resolve`] says how unset
//! entries fall back).
//!
//! [`decode`] re-checks everything above plus the budgets (partition + segment memory within
//! [`user_memory_limit`], kernel quotas within [`kernel_memory_limit`], thread and task quotas
//! within the kernel's tables after syssw's share), so a damaged or hand-made blob is rejected
//! before syssw acts on it; after a successful decode no accessor can fail or panic.
//! The decoder allocates nothing and never copies the blob.

use crate::model::*;
use abi::crc32::crc32;
use abi::syscall::Abilities;

pub const MAGIC: [u8; 8] = *b"WRDNCONF";
pub const VERSION: u32 = 1;
pub const NAME_SIZE: usize = 32;
pub const HEADER_SIZE: usize = 96;
pub const SCHEDULE_SIZE: usize = 48;
pub const WINDOW_SIZE: usize = 24;
pub const SEGMENT_SIZE: usize = 40;
pub const PARTITION_SIZE: usize = 136;
pub const IO_RANGE_SIZE: usize = 4;
pub const ATTACHMENT_SIZE: usize = 4;
pub const PORT_SIZE: usize = 56;
pub const CHANNEL_SIZE: usize = 40;
pub const DESTINATION_SIZE: usize = 2;
/// Prefix of a partition image's entry name in `system.img` (`partition/<image>`).
pub const IMAGE_ENTRY_PREFIX: &str = "partition/";

/// The tables of the blob, in their order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Table {
    Header,
    Schedule,
    Window,
    Segment,
    Partition,
    IoRange,
    Attachment,
    Port,
    Channel,
    Destination,
}

/// (table, record size, most records) of the nine tables, in blob order.
const TABLES: [(Table, usize, usize); 9] = [
    (Table::Schedule, SCHEDULE_SIZE, MAX_SCHEDULES),
    (Table::Window, WINDOW_SIZE, MAX_SCHEDULES * MAX_WINDOWS),
    (Table::Segment, SEGMENT_SIZE, MAX_SEGMENTS),
    (Table::Partition, PARTITION_SIZE, MAX_PARTITIONS),
    (Table::IoRange, IO_RANGE_SIZE, MAX_IO_RANGES),
    (Table::Attachment, ATTACHMENT_SIZE, MAX_ATTACHMENTS),
    (Table::Port, PORT_SIZE, MAX_PORTS),
    (Table::Channel, CHANNEL_SIZE, MAX_CHANNELS),
    (Table::Destination, DESTINATION_SIZE, MAX_PORTS),
];

impl Table {
    const fn slot(self) -> usize {
        match self {
            Table::Header | Table::Schedule => 0,
            Table::Window => 1,
            Table::Segment => 2,
            Table::Partition => 3,
            Table::IoRange => 4,
            Table::Attachment => 5,
            Table::Port => 6,
            Table::Channel => 7,
            Table::Destination => 8,
        }
    }

    pub const fn name(self) -> &'static str {
        match self {
            Table::Header => "header",
            Table::Schedule => "schedule",
            Table::Window => "window",
            Table::Segment => "shared segment",
            Table::Partition => "partition",
            Table::IoRange => "I/O range",
            Table::Attachment => "attachment",
            Table::Port => "port",
            Table::Channel => "channel",
            Table::Destination => "channel destination",
        }
    }
}

/// Why a blob was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// Fewer bytes than the header or than the header's total size.
    TooShort {
        needed: usize,
        actual: usize,
    },
    BadMagic,
    UnsupportedVersion(u32),
    ChecksumMismatch {
        stored: u32,
        computed: u32,
    },
    /// A table holds more records than the format allows.
    TooMany {
        table: Table,
        count: usize,
        max: usize,
    },
    /// The header's total size disagrees with the table sizes.
    SizeMismatch {
        declared: usize,
        expected: usize,
    },
    /// Record `index` of `table` (0 for the header) breaks the rule `what`.
    Invalid {
        table: Table,
        index: usize,
        what: &'static str,
    },
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::TooShort { needed, actual } => write!(
                f,
                "binary configuration truncated: {actual} bytes, {needed} needed"
            ),
            Self::BadMagic => write!(f, "not a binary configuration (bad magic)"),
            Self::UnsupportedVersion(v) => write!(
                f,
                "binary configuration version {v} is not supported (expected {VERSION})"
            ),
            Self::ChecksumMismatch { stored, computed } => write!(
                f,
                "binary configuration damaged: checksum {computed:#010x}, stored {stored:#010x}"
            ),
            Self::TooMany { table, count, max } => write!(
                f,
                "binary configuration has {count} {} records (at most {max})",
                table.name()
            ),
            Self::SizeMismatch { declared, expected } => write!(
                f,
                "binary configuration says {declared} bytes but its tables need {expected}"
            ),
            Self::Invalid {
                table: Table::Header,
                what,
                ..
            } => write!(f, "binary configuration header: {what}"),
            Self::Invalid { table, index, what } => {
                write!(f, "binary configuration {} {index}: {what}", table.name())
            }
        }
    }
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut x = [0u8; 4];
    x.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(x)
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut x = [0u8; 8];
    x.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(x)
}

/// The text of a name field, if it is well-formed.
fn name_field(raw: &[u8]) -> Option<&str> {
    let len = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
    if len == 0 || raw[len..].iter().any(|&b| b != 0) {
        return None;
    }
    core::str::from_utf8(&raw[..len]).ok()
}

/// A validated binary configuration (zero-copy view of the blob). Cheap to copy.
#[derive(Clone, Copy, Debug)]
pub struct SystemView<'a> {
    bytes: &'a [u8],
    counts: [usize; 9],
    offsets: [usize; 9],
}

/// Checks the whole blob (see the module documentation) and returns a view of it. `bytes`
/// may be longer than the blob (e.g. rounded up to pages); the rest is ignored.
pub fn decode(bytes: &[u8]) -> Result<SystemView<'_>, DecodeError> {
    if bytes.len() < HEADER_SIZE {
        return Err(DecodeError::TooShort {
            needed: HEADER_SIZE,
            actual: bytes.len(),
        });
    }
    if bytes[0..8] != MAGIC {
        return Err(DecodeError::BadMagic);
    }
    let version = u32_at(bytes, 8);
    if version != VERSION {
        return Err(DecodeError::UnsupportedVersion(version));
    }
    let total = u32_at(bytes, 16) as usize;
    if total < HEADER_SIZE {
        return Err(DecodeError::SizeMismatch {
            declared: total,
            expected: HEADER_SIZE,
        });
    }
    if total > bytes.len() {
        return Err(DecodeError::TooShort {
            needed: total,
            actual: bytes.len(),
        });
    }
    let bytes = &bytes[..total];
    let stored = u32_at(bytes, 12);
    let computed = crc32(&bytes[16..]);
    if stored != computed {
        return Err(DecodeError::ChecksumMismatch { stored, computed });
    }
    let mut counts = [0usize; 9];
    let mut offsets = [0usize; 9];
    let mut at = HEADER_SIZE;
    for (i, &(table, size, max)) in TABLES.iter().enumerate() {
        let count = u16_at(bytes, 64 + 2 * i) as usize;
        if count > max {
            return Err(DecodeError::TooMany { table, count, max });
        }
        counts[i] = count;
        offsets[i] = at;
        at += count * size;
    }
    if at != total {
        return Err(DecodeError::SizeMismatch {
            declared: total,
            expected: at,
        });
    }
    let view = SystemView {
        bytes,
        counts,
        offsets,
    };
    view.check()?;
    Ok(view)
}

fn invalid(table: Table, index: usize, what: &'static str) -> DecodeError {
    DecodeError::Invalid { table, index, what }
}

/// Checks that per-owner ranges `(first, count)` tile `0..total` in order.
fn tiles(ranges: impl Iterator<Item = (usize, usize)>, total: usize) -> Result<(), usize> {
    let mut next = 0;
    for (i, (first, count)) in ranges.enumerate() {
        if first != next {
            return Err(i);
        }
        next += count;
    }
    if next == total {
        Ok(())
    } else {
        Err(usize::MAX)
    }
}

fn zero(bytes: &[u8]) -> bool {
    bytes.iter().all(|&b| b == 0)
}

impl<'a> SystemView<'a> {
    fn record(&self, table: Table, index: usize) -> &'a [u8] {
        let slot = table.slot();
        let size = TABLES[slot].1;
        let at = self.offsets[slot] + index * size;
        &self.bytes[at..at + size]
    }

    fn count(&self, table: Table) -> usize {
        self.counts[table.slot()]
    }

    /// Every rule of the module documentation, in table order.
    fn check(&self) -> Result<(), DecodeError> {
        use Table as T;
        let header = &self.bytes[..HEADER_SIZE];
        if !zero(&header[20..24]) || !zero(&header[82..88]) {
            return Err(invalid(T::Header, 0, "reserved bytes are not zero"));
        }
        if name_field(&header[24..56]).is_none() {
            return Err(invalid(T::Header, 0, "system name is empty or not UTF-8"));
        }
        let memory = u64_at(header, 56);
        if memory == 0 || !memory.is_multiple_of(PAGE_SIZE) {
            return Err(invalid(
                T::Header,
                0,
                "memory is zero or not a multiple of 4 KiB",
            ));
        }
        if HealthTable::from_bytes(&header[88..96]).is_none() {
            return Err(invalid(T::Header, 0, "unknown module health action"));
        }

        // Schedules and their windows.
        tiles(
            (0..self.count(T::Schedule)).map(|i| {
                let r = self.record(T::Schedule, i);
                (u16_at(r, 40) as usize, u16_at(r, 42) as usize)
            }),
            self.count(T::Window),
        )
        .map_err(|i| {
            invalid(
                T::Schedule,
                i.min(self.count(T::Schedule)),
                "window ranges do not tile the window table",
            )
        })?;
        for s in 0..self.count(T::Schedule) {
            let r = self.record(T::Schedule, s);
            if name_field(&r[..32]).is_none() {
                return Err(invalid(T::Schedule, s, "name is empty or not UTF-8"));
            }
            if (0..s).any(|o| self.record(T::Schedule, o)[..32] == r[..32]) {
                return Err(invalid(T::Schedule, s, "duplicate name"));
            }
            if !zero(&r[44..48]) {
                return Err(invalid(T::Schedule, s, "reserved bytes are not zero"));
            }
            let frame = u64_at(r, 32);
            if frame == 0 {
                return Err(invalid(T::Schedule, s, "major frame is zero"));
            }
            let (first, count) = (u16_at(r, 40) as usize, u16_at(r, 42) as usize);
            if count > MAX_WINDOWS {
                return Err(invalid(T::Schedule, s, "more than 32 windows"));
            }
            let mut previous_end = 0;
            for w in first..first + count {
                let r = self.record(T::Window, w);
                let (offset, duration, tp) = (u64_at(r, 0), u64_at(r, 8), r[16]);
                if !zero(&r[17..24]) {
                    return Err(invalid(T::Window, w, "reserved bytes are not zero"));
                }
                if duration == 0 {
                    return Err(invalid(T::Window, w, "duration is zero"));
                }
                if offset.checked_add(duration).is_none_or(|end| end > frame) {
                    return Err(invalid(T::Window, w, "ends after the major frame"));
                }
                if offset < previous_end {
                    return Err(invalid(
                        T::Window,
                        w,
                        "overlaps the previous window or is not sorted by offset",
                    ));
                }
                previous_end = offset + duration;
                if tp == 0 || tp >= TIME_PARTITIONS {
                    return Err(invalid(T::Window, w, "time partition not in 1..=15"));
                }
                if !(0..self.count(T::Partition)).any(|p| self.record(T::Partition, p)[110] == tp) {
                    return Err(invalid(T::Window, w, "time partition used by no partition"));
                }
            }
        }

        // Shared segments.
        let mut user_memory: u64 = 0;
        for g in 0..self.count(T::Segment) {
            let r = self.record(T::Segment, g);
            if name_field(&r[..32]).is_none() {
                return Err(invalid(T::Segment, g, "name is empty or not UTF-8"));
            }
            if (0..g).any(|o| self.record(T::Segment, o)[..32] == r[..32]) {
                return Err(invalid(T::Segment, g, "duplicate name"));
            }
            let size = u64_at(r, 32);
            if size == 0 || !size.is_multiple_of(PAGE_SIZE) {
                return Err(invalid(
                    T::Segment,
                    g,
                    "size is zero or not a multiple of 4 KiB",
                ));
            }
            user_memory =
                user_memory
                    .checked_add(size)
                    .ok_or(invalid(T::Segment, g, "sizes overflow"))?;
        }

        // Partitions.
        let partitions = self.count(T::Partition);
        let sub_range = |p: usize, at: usize| {
            let r = self.record(T::Partition, p);
            (u16_at(r, at) as usize, u16_at(r, at + 2) as usize)
        };
        for (table, at) in [(T::IoRange, 120), (T::Attachment, 124), (T::Port, 128)] {
            tiles((0..partitions).map(|p| sub_range(p, at)), self.count(table)).map_err(|i| {
                invalid(
                    T::Partition,
                    i.min(partitions),
                    "I/O-range, attachment or port ranges do not tile their tables",
                )
            })?;
        }
        let (mut kernel_memory, mut threads, mut tasks) = (0u64, 0u64, 0u64);
        for p in 0..partitions {
            let r = self.record(T::Partition, p);
            let name = name_field(&r[..32]);
            if name.is_none_or(|n| n.len() > PARTITION_NAME_MAX) {
                return Err(invalid(
                    T::Partition,
                    p,
                    "name is empty, not UTF-8 or longer than 15 bytes",
                ));
            }
            if (0..p).any(|o| self.record(T::Partition, o)[..32] == r[..32]) {
                return Err(invalid(T::Partition, p, "duplicate name"));
            }
            if name_field(&r[32..64]).is_none() {
                return Err(invalid(T::Partition, p, "image name is empty or not UTF-8"));
            }
            let (memory, kmem, stack) = (u64_at(r, 64), u64_at(r, 72), u64_at(r, 80));
            for size in [memory, kmem, stack] {
                if size == 0 || !size.is_multiple_of(PAGE_SIZE) {
                    return Err(invalid(
                        T::Partition,
                        p,
                        "memory, kernel memory or stack is zero or not a multiple of 4 KiB",
                    ));
                }
            }
            if stack > memory {
                return Err(invalid(T::Partition, p, "stack larger than memory"));
            }
            let abilities = Abilities::from_bits(u64_at(r, 88)).ok_or(invalid(
                T::Partition,
                p,
                "unknown ability bits",
            ))?;
            if !PARTITION_ABILITIES.contains(abilities) {
                return Err(invalid(T::Partition, p, "an ability reserved for syssw"));
            }
            let (kthreads, ktasks) = (u32_at(r, 96), u32_at(r, 100));
            if kthreads == 0 || ktasks == 0 {
                return Err(invalid(
                    T::Partition,
                    p,
                    "kernel thread or task quota is zero",
                ));
            }
            if u32_at(r, 104) & IrqMask::FORBIDDEN != 0 {
                return Err(invalid(
                    T::Partition,
                    p,
                    "IRQ line reserved by the kernel or beyond 23",
                ));
            }
            let (mcp, priority, tp) = (r[108], r[109], r[110]);
            if !(MCP_MIN..=MCP_MAX).contains(&mcp) {
                return Err(invalid(T::Partition, p, "MCP not in 1..=199"));
            }
            if priority > mcp {
                return Err(invalid(T::Partition, p, "priority above the MCP"));
            }
            if tp >= TIME_PARTITIONS {
                return Err(invalid(T::Partition, p, "time partition above 15"));
            }
            if r[111] != 0 || !zero(&r[132..136]) {
                return Err(invalid(T::Partition, p, "reserved bytes are not zero"));
            }
            if HealthTable::from_bytes(&r[112..120]).is_none() {
                return Err(invalid(T::Partition, p, "unknown health action"));
            }
            let overflow = invalid(T::Partition, p, "memory sizes overflow");
            user_memory = user_memory.checked_add(memory).ok_or(overflow)?;
            kernel_memory = kernel_memory.checked_add(kmem).ok_or(overflow)?;
            threads += u64::from(kthreads);
            tasks += u64::from(ktasks);
            // Attachments of this partition.
            let (first, count) = sub_range(p, 124);
            for a in first..first + count {
                let r = self.record(T::Attachment, a);
                if u16_at(r, 0) as usize >= self.count(T::Segment) {
                    return Err(invalid(T::Attachment, a, "segment index out of range"));
                }
                if Rights::from_code(r[2]).is_none() || r[3] != 0 {
                    return Err(invalid(T::Attachment, a, "unknown rights"));
                }
                if (first..a).any(|o| self.record(T::Attachment, o)[..2] == r[..2]) {
                    return Err(invalid(T::Attachment, a, "segment attached twice"));
                }
            }
            // Ports of this partition: names unique within it.
            let (first, count) = sub_range(p, 128);
            for t in first..first + count {
                let name = &self.record(T::Port, t)[..32];
                if (first..t).any(|o| &self.record(T::Port, o)[..32] == name) {
                    return Err(invalid(T::Port, t, "duplicate name in its partition"));
                }
            }
        }
        if user_memory > user_memory_limit(memory) {
            return Err(invalid(
                T::Header,
                0,
                "partition and segment memory exceed the budget",
            ));
        }
        if kernel_memory > kernel_memory_limit(memory) {
            return Err(invalid(
                T::Header,
                0,
                "kernel memory quotas exceed the kernel pool",
            ));
        }
        if threads > u64::from(KERNEL_THREADS - SYSSW_THREADS)
            || tasks > u64::from(KERNEL_TASKS - SYSSW_TASKS)
        {
            return Err(invalid(
                T::Header,
                0,
                "kernel thread or task quotas exceed the kernel's tables",
            ));
        }

        // I/O port ranges: well-formed, not the kernel's, disjoint.
        for i in 0..self.count(T::IoRange) {
            let range = self.io_range(i);
            if range.first > range.last {
                return Err(invalid(T::IoRange, i, "first port after last port"));
            }
            if range.kernel_conflict().is_some() {
                return Err(invalid(T::IoRange, i, "includes a port the kernel keeps"));
            }
            if (0..i).any(|o| self.io_range(o).overlaps(range)) {
                return Err(invalid(T::IoRange, i, "overlaps another range"));
            }
        }

        // Ports.
        let channels = self.count(T::Channel);
        for t in 0..self.count(T::Port) {
            let r = self.record(T::Port, t);
            if name_field(&r[..32]).is_none() {
                return Err(invalid(T::Port, t, "name is empty or not UTF-8"));
            }
            let (size, depth, refresh) = (u32_at(r, 32), u32_at(r, 36), u64_at(r, 40));
            let channel = u16_at(r, 48) as usize;
            let kind = PortKind::from_code(r[50]).ok_or(invalid(T::Port, t, "unknown kind"))?;
            let direction =
                Direction::from_code(r[51]).ok_or(invalid(T::Port, t, "unknown direction"))?;
            if !zero(&r[52..56]) {
                return Err(invalid(T::Port, t, "reserved bytes are not zero"));
            }
            if size == 0 || size > MAX_MESSAGE_SIZE {
                return Err(invalid(T::Port, t, "message size not in 1..=4096"));
            }
            let depth_ok = match kind {
                PortKind::Sampling => depth == 0,
                PortKind::Queuing => (1..=MAX_QUEUE_DEPTH).contains(&depth),
            };
            if !depth_ok {
                return Err(invalid(
                    T::Port,
                    t,
                    "depth not 1..=256 (queuing) or not 0 (sampling)",
                ));
            }
            if refresh != 0 && (kind, direction) != (PortKind::Sampling, Direction::In) {
                return Err(invalid(
                    T::Port,
                    t,
                    "refresh period on a port that is not a sampling input",
                ));
            }
            if channel >= channels {
                return Err(invalid(T::Port, t, "channel index out of range"));
            }
        }

        // Channels: every port in exactly one channel, consistent both ways.
        tiles(
            (0..channels).map(|c| {
                let r = self.record(T::Channel, c);
                (u16_at(r, 34) as usize, u16_at(r, 36) as usize)
            }),
            self.count(T::Destination),
        )
        .map_err(|i| {
            invalid(
                T::Channel,
                i.min(channels),
                "destination ranges do not tile the destination table",
            )
        })?;
        if self.count(T::Port) != channels + self.count(T::Destination) {
            return Err(invalid(
                T::Header,
                0,
                "ports and channel ends do not match one to one",
            ));
        }
        for c in 0..channels {
            let r = self.record(T::Channel, c);
            if name_field(&r[..32]).is_none() {
                return Err(invalid(T::Channel, c, "name is empty or not UTF-8"));
            }
            if (0..c).any(|o| self.record(T::Channel, o)[..32] == r[..32]) {
                return Err(invalid(T::Channel, c, "duplicate name"));
            }
            let kind = PortKind::from_code(r[38]).ok_or(invalid(T::Channel, c, "unknown kind"))?;
            if r[39] != 0 {
                return Err(invalid(T::Channel, c, "reserved bytes are not zero"));
            }
            let (source, first, count) = (
                u16_at(r, 32) as usize,
                u16_at(r, 34) as usize,
                u16_at(r, 36) as usize,
            );
            if source >= self.count(T::Port) {
                return Err(invalid(T::Channel, c, "source port out of range"));
            }
            let src = self.port(source);
            if src.direction != Direction::Out || src.kind != kind || src.channel != c {
                return Err(invalid(
                    T::Channel,
                    c,
                    "source is not an output port of this channel's kind and channel",
                ));
            }
            let count_ok = match kind {
                PortKind::Sampling => count >= 1,
                PortKind::Queuing => count == 1,
            };
            if !count_ok {
                return Err(invalid(
                    T::Channel,
                    c,
                    "sampling needs >= 1 destination, queuing exactly 1",
                ));
            }
            for d in first..first + count {
                let port = u16_at(self.record(T::Destination, d), 0) as usize;
                if port >= self.count(T::Port) {
                    return Err(invalid(T::Destination, d, "port index out of range"));
                }
                let dst = self.port(port);
                if dst.direction != Direction::In || dst.kind != kind || dst.channel != c {
                    return Err(invalid(
                        T::Destination,
                        d,
                        "not an input port of this channel's kind and channel",
                    ));
                }
                if dst.size < src.size {
                    return Err(invalid(
                        T::Destination,
                        d,
                        "message size smaller than the source's",
                    ));
                }
                if (first..d)
                    .any(|o| self.record(T::Destination, o) == self.record(T::Destination, d))
                {
                    return Err(invalid(T::Destination, d, "port listed twice"));
                }
            }
        }
        Ok(())
    }

    /// The whole blob.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    pub fn name(&self) -> &'a str {
        name_field(&self.bytes[24..56]).unwrap_or("")
    }

    /// RAM budget of the system (bytes).
    pub fn memory(&self) -> u64 {
        u64_at(self.bytes, 56)
    }

    /// The module health table.
    pub fn health(&self) -> HealthTable {
        HealthTable::from_bytes(&self.bytes[88..96]).unwrap_or_default()
    }

    pub fn schedule_count(&self) -> usize {
        self.count(Table::Schedule)
    }

    /// Schedule `i` (panics if `i >= schedule_count()`); schedule 0 is the initial one.
    pub fn schedule(&self, i: usize) -> ScheduleView<'a> {
        let r = self.record(Table::Schedule, i);
        ScheduleView {
            index: i,
            name: name_field(&r[..32]).unwrap_or(""),
            major_frame: u64_at(r, 32),
            first_window: u16_at(r, 40) as usize,
            window_count: u16_at(r, 42) as usize,
            sys: *self,
        }
    }

    pub fn schedules(&self) -> impl Iterator<Item = ScheduleView<'a>> + 'a {
        let sys = *self;
        (0..sys.schedule_count()).map(move |i| sys.schedule(i))
    }

    pub fn segment_count(&self) -> usize {
        self.count(Table::Segment)
    }

    /// Shared segment `i` (panics if out of range).
    pub fn segment(&self, i: usize) -> SegmentView<'a> {
        let r = self.record(Table::Segment, i);
        SegmentView {
            index: i,
            name: name_field(&r[..32]).unwrap_or(""),
            size: u64_at(r, 32),
        }
    }

    pub fn segments(&self) -> impl Iterator<Item = SegmentView<'a>> + 'a {
        let sys = *self;
        (0..sys.segment_count()).map(move |i| sys.segment(i))
    }

    pub fn partition_count(&self) -> usize {
        self.count(Table::Partition)
    }

    /// Partition `i` (panics if out of range).
    pub fn partition(&self, i: usize) -> PartitionView<'a> {
        let r = self.record(Table::Partition, i);
        PartitionView {
            index: i,
            name: name_field(&r[..32]).unwrap_or(""),
            image: name_field(&r[32..64]).unwrap_or(""),
            memory: u64_at(r, 64),
            kernel_memory: u64_at(r, 72),
            stack: u64_at(r, 80),
            abilities: Abilities::from_bits_truncate(u64_at(r, 88)),
            kernel_threads: u32_at(r, 96),
            kernel_tasks: u32_at(r, 100),
            irqs: IrqMask(u32_at(r, 104)),
            mcp: r[108],
            priority: r[109],
            time_partition: r[110],
            health: HealthTable::from_bytes(&r[112..120]).unwrap_or_default(),
            io: (u16_at(r, 120) as usize, u16_at(r, 122) as usize),
            attachments: (u16_at(r, 124) as usize, u16_at(r, 126) as usize),
            ports: (u16_at(r, 128) as usize, u16_at(r, 130) as usize),
            sys: *self,
        }
    }

    pub fn partitions(&self) -> impl Iterator<Item = PartitionView<'a>> + 'a {
        let sys = *self;
        (0..sys.partition_count()).map(move |i| sys.partition(i))
    }

    pub fn find_partition(&self, name: &str) -> Option<PartitionView<'a>> {
        self.partitions().find(|p| p.name == name)
    }

    fn io_range(&self, i: usize) -> IoRange {
        let r = self.record(Table::IoRange, i);
        IoRange {
            first: u16_at(r, 0),
            last: u16_at(r, 2),
        }
    }

    fn attachment(&self, i: usize) -> Attachment {
        let r = self.record(Table::Attachment, i);
        Attachment {
            segment: u16_at(r, 0) as usize,
            rights: Rights::from_code(r[2]).unwrap_or(Rights::Read),
        }
    }

    pub fn port_count(&self) -> usize {
        self.count(Table::Port)
    }

    /// Port `i` of the global port table (panics if out of range).
    pub fn port(&self, i: usize) -> PortView<'a> {
        let r = self.record(Table::Port, i);
        let partition = (0..self.partition_count())
            .find(|&p| {
                let r = self.record(Table::Partition, p);
                let first = u16_at(r, 128) as usize;
                (first..first + u16_at(r, 130) as usize).contains(&i)
            })
            .unwrap_or(0);
        PortView {
            index: i,
            partition,
            name: name_field(&r[..32]).unwrap_or(""),
            size: u32_at(r, 32),
            depth: u32_at(r, 36),
            refresh: u64_at(r, 40),
            channel: u16_at(r, 48) as usize,
            kind: PortKind::from_code(r[50]).unwrap_or(PortKind::Sampling),
            direction: Direction::from_code(r[51]).unwrap_or(Direction::In),
        }
    }

    pub fn ports(&self) -> impl Iterator<Item = PortView<'a>> + 'a {
        let sys = *self;
        (0..sys.port_count()).map(move |i| sys.port(i))
    }

    pub fn channel_count(&self) -> usize {
        self.count(Table::Channel)
    }

    /// Channel `i` (panics if out of range).
    pub fn channel(&self, i: usize) -> ChannelView<'a> {
        let r = self.record(Table::Channel, i);
        ChannelView {
            index: i,
            name: name_field(&r[..32]).unwrap_or(""),
            source: u16_at(r, 32) as usize,
            first_destination: u16_at(r, 34) as usize,
            destination_count: u16_at(r, 36) as usize,
            kind: PortKind::from_code(r[38]).unwrap_or(PortKind::Sampling),
            sys: *self,
        }
    }

    pub fn channels(&self) -> impl Iterator<Item = ChannelView<'a>> + 'a {
        let sys = *self;
        (0..sys.channel_count()).map(move |i| sys.channel(i))
    }
}

/// One schedule of a [`SystemView`].
#[derive(Clone, Copy, Debug)]
pub struct ScheduleView<'a> {
    /// Slot number for `schedule_set`/`schedule_switch`.
    pub index: usize,
    pub name: &'a str,
    /// Major frame (ns).
    pub major_frame: u64,
    first_window: usize,
    window_count: usize,
    sys: SystemView<'a>,
}

impl<'a> ScheduleView<'a> {
    pub fn window_count(&self) -> usize {
        self.window_count
    }

    /// Window `i` of this schedule (panics if `i >= window_count()`), in offset order.
    pub fn window(&self, i: usize) -> Window {
        assert!(i < self.window_count, "window index out of range");
        let r = self.sys.record(Table::Window, self.first_window + i);
        Window {
            offset: u64_at(r, 0),
            duration: u64_at(r, 8),
            time_partition: r[16],
        }
    }

    pub fn windows(&self) -> impl Iterator<Item = Window> + 'a {
        let s = *self;
        (0..s.window_count).map(move |i| s.window(i))
    }
}

/// One shared-memory segment of a [`SystemView`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SegmentView<'a> {
    pub index: usize,
    pub name: &'a str,
    /// Bytes (a multiple of 4 KiB).
    pub size: u64,
}

/// One partition of a [`SystemView`].
#[derive(Clone, Copy, Debug)]
pub struct PartitionView<'a> {
    pub index: usize,
    pub name: &'a str,
    /// The ELF is entry [`IMAGE_ENTRY_PREFIX`]`image` of system.img.
    pub image: &'a str,
    /// User memory (bytes, includes the stack).
    pub memory: u64,
    /// Page quota of its resource partition, in bytes.
    pub kernel_memory: u64,
    pub stack: u64,
    pub kernel_threads: u32,
    pub kernel_tasks: u32,
    pub abilities: Abilities,
    pub irqs: IrqMask,
    pub mcp: u8,
    pub priority: u8,
    /// 0 = background.
    pub time_partition: u8,
    pub health: HealthTable,
    io: (usize, usize),
    attachments: (usize, usize),
    ports: (usize, usize),
    sys: SystemView<'a>,
}

impl<'a> PartitionView<'a> {
    /// Its I/O port ranges (inclusive; for `io_grant(task, first, count())`).
    pub fn io_ports(&self) -> impl Iterator<Item = IoRange> + 'a {
        let sys = self.sys;
        (self.io.0..self.io.0 + self.io.1).map(move |i| sys.io_range(i))
    }

    /// The shared segments it maps, with its rights.
    pub fn shared(&self) -> impl Iterator<Item = Attachment> + 'a {
        let sys = self.sys;
        (self.attachments.0..self.attachments.0 + self.attachments.1)
            .map(move |i| sys.attachment(i))
    }

    /// Global indices of its ports.
    pub fn port_indices(&self) -> core::ops::Range<usize> {
        self.ports.0..self.ports.0 + self.ports.1
    }

    pub fn ports(&self) -> impl Iterator<Item = PortView<'a>> + 'a {
        let sys = self.sys;
        self.port_indices().map(move |i| sys.port(i))
    }

    pub fn find_port(&self, name: &str) -> Option<PortView<'a>> {
        self.ports().find(|p| p.name == name)
    }

    /// True if `entry` (a system.img entry name) is this partition's image.
    pub fn is_image_entry(&self, entry: &str) -> bool {
        entry.strip_prefix(IMAGE_ENTRY_PREFIX) == Some(self.image)
    }
}

/// One port of a [`SystemView`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortView<'a> {
    /// Global port index.
    pub index: usize,
    /// Index of its partition.
    pub partition: usize,
    pub name: &'a str,
    pub kind: PortKind,
    pub direction: Direction,
    /// Largest message (bytes).
    pub size: u32,
    /// Queuing: capacity in messages; sampling: 0.
    pub depth: u32,
    /// Sampling input: validity period (ns), 0 = none.
    pub refresh: u64,
    /// Index of its channel.
    pub channel: usize,
}

/// One channel of a [`SystemView`].
#[derive(Clone, Copy, Debug)]
pub struct ChannelView<'a> {
    pub index: usize,
    pub name: &'a str,
    pub kind: PortKind,
    /// Global index of the output port.
    pub source: usize,
    first_destination: usize,
    destination_count: usize,
    sys: SystemView<'a>,
}

impl<'a> ChannelView<'a> {
    /// Global indices of the input ports.
    pub fn destinations(&self) -> impl Iterator<Item = usize> + 'a {
        let sys = self.sys;
        (self.first_destination..self.first_destination + self.destination_count)
            .map(move |d| u16_at(sys.record(Table::Destination, d), 0) as usize)
    }

    pub fn destination_count(&self) -> usize {
        self.destination_count
    }
}

/// Host-side writer.
#[cfg(feature = "host")]
mod encode {
    use super::*;
    use crate::system::System;
    use std::vec::Vec;

    fn name(out: &mut Vec<u8>, text: &str) {
        let mut field = [0u8; NAME_SIZE];
        field[..text.len()].copy_from_slice(text.as_bytes());
        out.extend_from_slice(&field);
    }

    fn u16_of(value: usize) -> [u8; 2] {
        u16::try_from(value)
            .expect("validated counts fit 16 bits")
            .to_le_bytes()
    }

    /// Writes the version-1 blob of a validated system (see the module documentation).
    /// Panics if `system` breaks the format's limits, which [`crate::load`] rules out.
    pub fn encode(system: &System) -> Vec<u8> {
        let mut out = Vec::new();
        let windows: usize = system.schedules.iter().map(|s| s.windows.len()).sum();
        let io: usize = system.partitions.iter().map(|p| p.io_ports.len()).sum();
        let attachments: usize = system.partitions.iter().map(|p| p.shared.len()).sum();
        let ports: usize = system.partitions.iter().map(|p| p.ports.len()).sum();
        let destinations: usize = system.channels.iter().map(|c| c.destinations.len()).sum();
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&[0; 4]); // CRC, below
        out.extend_from_slice(&[0; 4]); // total size, below
        out.extend_from_slice(&[0; 4]);
        name(&mut out, &system.name);
        out.extend_from_slice(&system.memory.to_le_bytes());
        for count in [
            system.schedules.len(),
            windows,
            system.segments.len(),
            system.partitions.len(),
            io,
            attachments,
            ports,
            system.channels.len(),
            destinations,
        ] {
            out.extend_from_slice(&u16_of(count));
        }
        out.extend_from_slice(&[0; 6]);
        out.extend_from_slice(&system.health.to_bytes());
        debug_assert_eq!(out.len(), HEADER_SIZE);

        let mut first = 0;
        for s in &system.schedules {
            name(&mut out, &s.name);
            out.extend_from_slice(&s.major_frame.to_le_bytes());
            out.extend_from_slice(&u16_of(first));
            out.extend_from_slice(&u16_of(s.windows.len()));
            out.extend_from_slice(&[0; 4]);
            first += s.windows.len();
        }
        for w in system.schedules.iter().flat_map(|s| &s.windows) {
            out.extend_from_slice(&w.offset.to_le_bytes());
            out.extend_from_slice(&w.duration.to_le_bytes());
            out.push(w.time_partition);
            out.extend_from_slice(&[0; 7]);
        }
        for g in &system.segments {
            name(&mut out, &g.name);
            out.extend_from_slice(&g.size.to_le_bytes());
        }
        let (mut io_at, mut att_at, mut port_at) = (0, 0, 0);
        for p in &system.partitions {
            name(&mut out, &p.name);
            name(&mut out, &p.image);
            out.extend_from_slice(&p.memory.to_le_bytes());
            out.extend_from_slice(&p.kernel_memory.to_le_bytes());
            out.extend_from_slice(&p.stack.to_le_bytes());
            out.extend_from_slice(&p.abilities.bits().to_le_bytes());
            out.extend_from_slice(&p.kernel_threads.to_le_bytes());
            out.extend_from_slice(&p.kernel_tasks.to_le_bytes());
            out.extend_from_slice(&p.irqs.0.to_le_bytes());
            out.extend_from_slice(&[p.mcp, p.priority, p.time_partition, 0]);
            out.extend_from_slice(&p.health.to_bytes());
            for (at, count) in [
                (&mut io_at, p.io_ports.len()),
                (&mut att_at, p.shared.len()),
                (&mut port_at, p.ports.len()),
            ] {
                out.extend_from_slice(&u16_of(*at));
                out.extend_from_slice(&u16_of(count));
                *at += count;
            }
            out.extend_from_slice(&[0; 4]);
        }
        for r in system.partitions.iter().flat_map(|p| &p.io_ports) {
            out.extend_from_slice(&r.first.to_le_bytes());
            out.extend_from_slice(&r.last.to_le_bytes());
        }
        for a in system.partitions.iter().flat_map(|p| &p.shared) {
            out.extend_from_slice(&u16_of(a.segment));
            out.extend_from_slice(&[a.rights as u8, 0]);
        }
        for t in system.partitions.iter().flat_map(|p| &p.ports) {
            name(&mut out, &t.name);
            out.extend_from_slice(&t.size.to_le_bytes());
            out.extend_from_slice(&t.depth.to_le_bytes());
            out.extend_from_slice(&t.refresh.to_le_bytes());
            out.extend_from_slice(&u16_of(t.channel));
            out.extend_from_slice(&[t.kind as u8, t.direction as u8, 0, 0, 0, 0]);
        }
        let mut first = 0;
        for c in &system.channels {
            name(&mut out, &c.name);
            out.extend_from_slice(&u16_of(system.global_port(c.source)));
            out.extend_from_slice(&u16_of(first));
            out.extend_from_slice(&u16_of(c.destinations.len()));
            out.extend_from_slice(&[c.kind as u8, 0]);
            first += c.destinations.len();
        }
        for &d in system.channels.iter().flat_map(|c| &c.destinations) {
            out.extend_from_slice(&u16_of(system.global_port(d)));
        }
        let total = u32::try_from(out.len()).expect("a configuration is far below 4 GiB");
        out[16..20].copy_from_slice(&total.to_le_bytes());
        let crc = crc32(&out[16..]);
        out[12..16].copy_from_slice(&crc.to_le_bytes());
        out
    }
}

#[cfg(feature = "host")]
pub use encode::encode;
