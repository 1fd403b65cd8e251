//! The binary configuration: what `cargo xtask` stores as entry `config` of `system.img` and
//! syssw decodes at boot. This layout is an interface contract between the host tools and
//! syssw; any change bumps [`VERSION`].
//!
//! # Layout, version 5
//!
//! All integers are little-endian; no field is aligned (read them with `from_le_bytes`).
//! Names are fixed 32-byte fields of UTF-8, NUL-padded: non-empty, no NUL inside, only NULs
//! after the text (partition names use at most 15 of the bytes). Reserved bytes are zero.
//!
//! ```text
//! Header (96 bytes)
//! offset size field
//! 0      8    magic "WRDNCONF"
//! 8      4    version (5)
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
//! 82     1    CPUs the system uses (1..=8, MAX_CPUS): CPUs 0..this
//! 83     5    reserved
//! 88     8    module health table: byte e = action for error e (see below), 0 = not set
//! 96          the tables, in this order, back to back without padding:
//!
//! Schedule (48 bytes) x S
//! 0      32   name
//! 32     8    major frame (ns, MIN_WINDOW..=MAX_MAJOR_FRAME: 10 us to one hour)
//! 40     2    first window (index into the window table)
//! 42     2    window count (<= 32); the schedules' window ranges tile the window table in order
//! 44     4    change actions (`change_actions`, ARINC SCHEDULE_CHANGE_ACTION): 2 bits per
//!             partition, bits 2i..2i+2 for partition i: 0 ignore, 1 idle, 2 cold_start,
//!             3 warm_start; the bits above the last partition's are zero
//!
//! Window (24 bytes) x W; per schedule sorted by offset, those of one CPU disjoint (every
//! CPU has its own windows in the one major frame: windows of different CPUs may overlap),
//! duration > 0, offset + duration <= major frame
//! 0      8    offset in the major frame (ns)
//! 8      8    duration (ns, at least MIN_WINDOW: 10 us)
//! 16     1    time partition 1..=15 (one some partition of this CPU uses)
//! 17     1    CPU whose schedule it is in (< the system's CPUs)
//! 18     6    reserved
//!
//! Shared segment (40 bytes) x G
//! 0      32   name
//! 32     8    size in bytes (> 0, multiple of 4096)
//!
//! Partition (160 bytes) x P
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
//! 111    1    flags: bit 0 = may switch the module schedule (`schedule_control`); bit 1 =
//!             its devices may DMA without an IOMMU (`dma_unconfined`, only with a DMA
//!             region); others 0
//! 112    8    partition health table (as the module's)
//! 120    2    first I/O range,  122  2  I/O range count
//! 124    2    first attachment, 126  2  attachment count
//! 128    2    first port,       130  2  port count
//! 132    1    PCI device count (<= pci::MAX_PARTITION_DEVICES)
//! 133    1    CPUs its threads run on: bit n = CPU n (not none, < the system's CPUs)
//! 134    2    reserved
//! 136    16   PCI devices: routing ids (u16), the unused slots zero; none owned twice
//! 152    8    DMA region in bytes (`dma`; 0 = none; multiple of 4096, <= memory, only
//!             with PCI devices)
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
//! 32     4    message size in bytes (1..=65536, `MAX_MESSAGE_SIZE`)
//! 36     4    depth: queuing 1..=256 messages; sampling 0
//! 40     8    refresh period (ns) of a sampling input, 0 = none; 0 for every other port
//! 48     2    channel index
//! 50     1    kind: 1 = sampling, 2 = queuing
//! 51     1    direction: 1 = in (destination), 2 = out (source)
//! 52     1    queuing discipline: 0 = FIFO, 1 = PRIORITY; 0 for a sampling port
//! 53     3    reserved
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
pub use abi::layout::Field;
use abi::syscall::Abilities;

pub const MAGIC: [u8; 8] = *b"WRDNCONF";
pub const VERSION: u32 = 5;
pub const NAME_SIZE: usize = 32;
pub const HEADER_SIZE: usize = header::SIZE;
pub const SCHEDULE_SIZE: usize = schedule::SIZE;
pub const WINDOW_SIZE: usize = window::SIZE;
pub const SEGMENT_SIZE: usize = segment::SIZE;
pub const PARTITION_SIZE: usize = partition::SIZE;
pub const IO_RANGE_SIZE: usize = io_range::SIZE;
pub const ATTACHMENT_SIZE: usize = attachment::SIZE;
pub const PORT_SIZE: usize = port::SIZE;
pub const CHANNEL_SIZE: usize = channel::SIZE;
pub const DESTINATION_SIZE: usize = destination::SIZE;

/// Header fields.
pub mod header {
    use super::Field;
    pub const MAGIC: Field = Field::new(0, 8);
    pub const VERSION: Field = Field::new(8, 4);
    pub const CRC: Field = Field::new(12, 4);
    pub const TOTAL_SIZE: Field = Field::new(16, 4);
    pub const RESERVED_A: Field = Field::new(20, 4);
    pub const NAME: Field = Field::new(24, 32);
    pub const MEMORY: Field = Field::new(56, 8);
    /// Record count of table `i` (blob order), for `i` in 0..9.
    pub const fn count(i: usize) -> Field {
        Field::new(64 + 2 * i, 2)
    }
    /// CPUs the system uses (1..=`MAX_CPUS`).
    pub const CPUS: Field = Field::new(82, 1);
    pub const RESERVED_B: Field = Field::new(83, 5);
    pub const HEALTH: Field = Field::new(88, 8);
    pub const SIZE: usize = 96;
    /// Every field, in order (the counts as one run).
    pub const FIELDS: [Field; 11] = [
        MAGIC,
        VERSION,
        CRC,
        TOTAL_SIZE,
        RESERVED_A,
        NAME,
        MEMORY,
        Field::new(64, 18),
        CPUS,
        RESERVED_B,
        HEALTH,
    ];
}

/// Schedule record fields.
pub mod schedule {
    use super::Field;
    pub const NAME: Field = Field::new(0, 32);
    pub const MAJOR_FRAME: Field = Field::new(32, 8);
    pub const FIRST_WINDOW: Field = Field::new(40, 2);
    pub const WINDOW_COUNT: Field = Field::new(42, 2);
    pub const CHANGE_ACTIONS: Field = Field::new(44, 4);
    pub const SIZE: usize = 48;
    pub const FIELDS: [Field; 5] = [
        NAME,
        MAJOR_FRAME,
        FIRST_WINDOW,
        WINDOW_COUNT,
        CHANGE_ACTIONS,
    ];
}

/// Window record fields.
pub mod window {
    use super::Field;
    pub const OFFSET: Field = Field::new(0, 8);
    pub const DURATION: Field = Field::new(8, 8);
    pub const TIME_PARTITION: Field = Field::new(16, 1);
    /// The CPU whose schedule the window is in.
    pub const CPU: Field = Field::new(17, 1);
    pub const RESERVED: Field = Field::new(18, 6);
    pub const SIZE: usize = 24;
    pub const FIELDS: [Field; 5] = [OFFSET, DURATION, TIME_PARTITION, CPU, RESERVED];
}

/// Shared-segment record fields.
pub mod segment {
    use super::Field;
    pub const NAME: Field = Field::new(0, 32);
    pub const BYTES: Field = Field::new(32, 8);
    pub const SIZE: usize = 40;
    pub const FIELDS: [Field; 2] = [NAME, BYTES];
}

/// Partition record fields.
pub mod partition {
    use super::Field;
    pub const NAME: Field = Field::new(0, 32);
    pub const IMAGE: Field = Field::new(32, 32);
    pub const MEMORY: Field = Field::new(64, 8);
    pub const KERNEL_MEMORY: Field = Field::new(72, 8);
    pub const STACK: Field = Field::new(80, 8);
    pub const ABILITIES: Field = Field::new(88, 8);
    pub const KERNEL_THREADS: Field = Field::new(96, 4);
    pub const KERNEL_TASKS: Field = Field::new(100, 4);
    pub const IRQS: Field = Field::new(104, 4);
    pub const MCP: Field = Field::new(108, 1);
    pub const PRIORITY: Field = Field::new(109, 1);
    pub const TIME_PARTITION: Field = Field::new(110, 1);
    pub const FLAGS: Field = Field::new(111, 1);
    pub const HEALTH: Field = Field::new(112, 8);
    pub const FIRST_IO: Field = Field::new(120, 2);
    pub const IO_COUNT: Field = Field::new(122, 2);
    pub const FIRST_ATTACHMENT: Field = Field::new(124, 2);
    pub const ATTACHMENT_COUNT: Field = Field::new(126, 2);
    pub const FIRST_PORT: Field = Field::new(128, 2);
    pub const PORT_COUNT: Field = Field::new(130, 2);
    /// How many of `DEVICES` are used (at most `pci::MAX_PARTITION_DEVICES`).
    pub const DEVICE_COUNT: Field = Field::new(132, 1);
    /// The CPUs its threads run on: bit n = CPU n.
    pub const CPUS: Field = Field::new(133, 1);
    pub const RESERVED_B: Field = Field::new(134, 2);
    /// The PCI functions it owns: `DEVICE_COUNT` routing ids (`pci::Address::id`, u16 LE),
    /// the unused ones zero.
    pub const DEVICES: Field = Field::new(136, 16);
    /// Bytes of its DMA region (`dma`; 0: none).
    pub const DMA: Field = Field::new(152, 8);
    pub const SIZE: usize = 160;
    pub const FIELDS: [Field; 25] = [
        NAME,
        IMAGE,
        MEMORY,
        KERNEL_MEMORY,
        STACK,
        ABILITIES,
        KERNEL_THREADS,
        KERNEL_TASKS,
        IRQS,
        MCP,
        PRIORITY,
        TIME_PARTITION,
        FLAGS,
        HEALTH,
        FIRST_IO,
        IO_COUNT,
        FIRST_ATTACHMENT,
        ATTACHMENT_COUNT,
        FIRST_PORT,
        PORT_COUNT,
        DEVICE_COUNT,
        CPUS,
        RESERVED_B,
        DEVICES,
        DMA,
    ];
}

/// I/O port range record fields.
pub mod io_range {
    use super::Field;
    pub const FIRST: Field = Field::new(0, 2);
    pub const LAST: Field = Field::new(2, 2);
    pub const SIZE: usize = 4;
    pub const FIELDS: [Field; 2] = [FIRST, LAST];
}

/// Segment attachment record fields.
pub mod attachment {
    use super::Field;
    pub const SEGMENT: Field = Field::new(0, 2);
    pub const RIGHTS: Field = Field::new(2, 1);
    pub const RESERVED: Field = Field::new(3, 1);
    pub const SIZE: usize = 4;
    pub const FIELDS: [Field; 3] = [SEGMENT, RIGHTS, RESERVED];
}

/// Port record fields.
pub mod port {
    use super::Field;
    pub const NAME: Field = Field::new(0, 32);
    pub const MESSAGE_SIZE: Field = Field::new(32, 4);
    pub const DEPTH: Field = Field::new(36, 4);
    pub const REFRESH: Field = Field::new(40, 8);
    pub const CHANNEL: Field = Field::new(48, 2);
    pub const KIND: Field = Field::new(50, 1);
    pub const DIRECTION: Field = Field::new(51, 1);
    pub const DISCIPLINE: Field = Field::new(52, 1);
    pub const RESERVED: Field = Field::new(53, 3);
    pub const SIZE: usize = 56;
    pub const FIELDS: [Field; 9] = [
        NAME,
        MESSAGE_SIZE,
        DEPTH,
        REFRESH,
        CHANNEL,
        KIND,
        DIRECTION,
        DISCIPLINE,
        RESERVED,
    ];
}

/// Partition flag: the partition may switch the module schedule.
pub const FLAG_SCHEDULE_CONTROL: u8 = 1;
/// Partition flag: its devices may DMA into its DMA region without an IOMMU confining them
/// (`dma_unconfined`; only with a DMA region).
pub const FLAG_DMA_UNCONFINED: u8 = 2;

/// Channel record fields.
pub mod channel {
    use super::Field;
    pub const NAME: Field = Field::new(0, 32);
    pub const SOURCE: Field = Field::new(32, 2);
    pub const FIRST_DESTINATION: Field = Field::new(34, 2);
    pub const DESTINATION_COUNT: Field = Field::new(36, 2);
    pub const KIND: Field = Field::new(38, 1);
    pub const RESERVED: Field = Field::new(39, 1);
    pub const SIZE: usize = 40;
    pub const FIELDS: [Field; 6] = [
        NAME,
        SOURCE,
        FIRST_DESTINATION,
        DESTINATION_COUNT,
        KIND,
        RESERVED,
    ];
}

/// Channel destination record fields.
pub mod destination {
    use super::Field;
    pub const PORT: Field = Field::new(0, 2);
    pub const SIZE: usize = 2;
    pub const FIELDS: [Field; 1] = [PORT];
}

/// Prefix of a partition image's entry name in `system.img` (`partition/<image>`).
pub const IMAGE_ENTRY_PREFIX: &str = "partition/";
/// A partition's data entry in system.img is this prefix and its name (e.g. `data/plc`, a
/// soft-PLC's program package); syssw maps it read-only at `user_rt::partition::DATA_BASE`.
pub const DATA_ENTRY_PREFIX: &str = "data/";

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
    if header::MAGIC.bytes(bytes) != MAGIC {
        return Err(DecodeError::BadMagic);
    }
    let version = header::VERSION.u32(bytes);
    if version != VERSION {
        return Err(DecodeError::UnsupportedVersion(version));
    }
    let total = header::TOTAL_SIZE.u32(bytes) as usize;
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
    let stored = header::CRC.u32(bytes);
    let computed = crc32(&bytes[header::TOTAL_SIZE.at..]);
    if stored != computed {
        return Err(DecodeError::ChecksumMismatch { stored, computed });
    }
    let mut counts = [0usize; 9];
    let mut offsets = [0usize; 9];
    let mut at = HEADER_SIZE;
    for (i, &(table, size, max)) in TABLES.iter().enumerate() {
        let count = header::count(i).u16(bytes);
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

    /// Every rule of the module documentation, one validator per table, in table order.
    fn check(&self) -> Result<(), DecodeError> {
        self.check_header()?;
        self.check_schedules()?;
        let segment_memory = self.check_segments()?;
        self.check_partitions(segment_memory)?;
        self.check_io_ranges()?;
        self.check_ports()?;
        self.check_channels()
    }

    fn check_header(&self) -> Result<(), DecodeError> {
        let h = &self.bytes[..HEADER_SIZE];
        let fail = |what| Err(invalid(Table::Header, 0, what));
        if !header::RESERVED_A.is_zero(h) || !header::RESERVED_B.is_zero(h) {
            return fail("reserved bytes are not zero");
        }
        if header::NAME.name(h).is_none() {
            return fail("system name is empty or not UTF-8");
        }
        let memory = header::MEMORY.get(h);
        if memory == 0 || !memory.is_multiple_of(PAGE_SIZE) {
            return fail("memory is zero or not a multiple of 4 KiB");
        }
        if !(1..=MAX_CPUS).contains(&usize::from(header::CPUS.u8(h))) {
            return fail("CPU count not in 1..=8");
        }
        if HealthTable::from_bytes(header::HEALTH.bytes(h)).is_none() {
            return fail("unknown module health action");
        }
        Ok(())
    }

    /// Whether record `index` of `table` repeats the name of an earlier record.
    fn duplicate_name(&self, table: Table, index: usize, name: Field) -> bool {
        let own = name.bytes(self.record(table, index));
        (0..index).any(|o| name.bytes(self.record(table, o)) == own)
    }

    fn check_schedules(&self) -> Result<(), DecodeError> {
        use schedule as S;
        use window as W;
        let schedules = self.count(Table::Schedule);
        tiles(
            (0..schedules).map(|i| {
                let r = self.record(Table::Schedule, i);
                (S::FIRST_WINDOW.u16(r), S::WINDOW_COUNT.u16(r))
            }),
            self.count(Table::Window),
        )
        .map_err(|i| {
            invalid(
                Table::Schedule,
                i.min(schedules),
                "window ranges do not tile the window table",
            )
        })?;
        for s in 0..schedules {
            let r = self.record(Table::Schedule, s);
            let fail = |what| Err(invalid(Table::Schedule, s, what));
            if S::NAME.name(r).is_none() {
                return fail("name is empty or not UTF-8");
            }
            if self.duplicate_name(Table::Schedule, s, S::NAME) {
                return fail("duplicate name");
            }
            if !ChangeActions(S::CHANGE_ACTIONS.u32(r)).within(self.count(Table::Partition)) {
                return fail("a change action for a partition that does not exist");
            }
            let frame = S::MAJOR_FRAME.get(r);
            if !(MIN_WINDOW..=MAX_MAJOR_FRAME).contains(&frame) {
                return fail(
                    "major frame is shorter or longer than the kernel's limits (10 us, 1 h)",
                );
            }
            let (first, count) = (S::FIRST_WINDOW.u16(r), S::WINDOW_COUNT.u16(r));
            if count > MAX_WINDOWS {
                return fail("more than 32 windows");
            }
            // The end of the latest window of each CPU so far, and the latest offset.
            let mut previous_end = [0u64; MAX_CPUS];
            let mut previous_offset = 0;
            for w in first..first + count {
                let r = self.record(Table::Window, w);
                let fail = |what| Err(invalid(Table::Window, w, what));
                let (offset, duration) = (W::OFFSET.get(r), W::DURATION.get(r));
                let (tp, cpu) = (W::TIME_PARTITION.u8(r), W::CPU.u8(r));
                if !W::RESERVED.is_zero(r) {
                    return fail("reserved bytes are not zero");
                }
                if cpu >= self.cpus() {
                    return fail("CPU beyond the system's CPUs");
                }
                if duration < MIN_WINDOW {
                    return fail("shorter than the kernel's shortest window (10 us)");
                }
                if offset.checked_add(duration).is_none_or(|end| end > frame) {
                    return fail("ends after the major frame");
                }
                if offset < previous_offset {
                    return fail("not sorted by offset");
                }
                previous_offset = offset;
                let end = &mut previous_end[usize::from(cpu)];
                if offset < *end {
                    return fail("overlaps the previous window of its CPU");
                }
                *end = offset + duration;
                if tp == 0 || tp >= TIME_PARTITIONS {
                    return fail("time partition not in 1..=15");
                }
                let users = (0..self.count(Table::Partition))
                    .map(|p| self.record(Table::Partition, p))
                    .filter(|r| partition::TIME_PARTITION.u8(r) == tp);
                if users.clone().next().is_none() {
                    return fail("time partition used by no partition");
                }
                if !users
                    .into_iter()
                    .any(|r| partition::CPUS.u8(r) & 1 << cpu != 0)
                {
                    return fail("time partition used by no partition of its CPU");
                }
            }
        }
        Ok(())
    }

    /// Checks the shared segments and returns their total size.
    fn check_segments(&self) -> Result<u64, DecodeError> {
        let mut total: u64 = 0;
        for g in 0..self.count(Table::Segment) {
            let r = self.record(Table::Segment, g);
            let fail = |what| invalid(Table::Segment, g, what);
            if segment::NAME.name(r).is_none() {
                return Err(fail("name is empty or not UTF-8"));
            }
            if self.duplicate_name(Table::Segment, g, segment::NAME) {
                return Err(fail("duplicate name"));
            }
            let size = segment::BYTES.get(r);
            if size == 0 || !size.is_multiple_of(PAGE_SIZE) {
                return Err(fail("size is zero or not a multiple of 4 KiB"));
            }
            total = total.checked_add(size).ok_or(fail("sizes overflow"))?;
        }
        Ok(total)
    }

    /// Partition `p`'s range `(first, count)` of another table.
    fn sub_range(&self, p: usize, first: Field, count: Field) -> (usize, usize) {
        let r = self.record(Table::Partition, p);
        (first.u16(r), count.u16(r))
    }

    /// Checks the partitions (with their attachments and port names) and the budgets they
    /// add up to, with the shared segments' `segment_memory`.
    fn check_partitions(&self, segment_memory: u64) -> Result<(), DecodeError> {
        use partition as P;
        let partitions = self.count(Table::Partition);
        for (table, first, count) in [
            (Table::IoRange, P::FIRST_IO, P::IO_COUNT),
            (Table::Attachment, P::FIRST_ATTACHMENT, P::ATTACHMENT_COUNT),
            (Table::Port, P::FIRST_PORT, P::PORT_COUNT),
        ] {
            tiles(
                (0..partitions).map(|p| self.sub_range(p, first, count)),
                self.count(table),
            )
            .map_err(|i| {
                invalid(
                    Table::Partition,
                    i.min(partitions),
                    "I/O-range, attachment or port ranges do not tile their tables",
                )
            })?;
        }
        let mut user_memory = segment_memory;
        let (mut kernel_memory, mut threads, mut tasks) = (0u64, 0u64, 0u64);
        for p in 0..partitions {
            let r = self.record(Table::Partition, p);
            let fail = |what| invalid(Table::Partition, p, what);
            if P::NAME.name(r).is_none_or(|n| n.len() > PARTITION_NAME_MAX) {
                return Err(fail("name is empty, not UTF-8 or longer than 15 bytes"));
            }
            if self.duplicate_name(Table::Partition, p, P::NAME) {
                return Err(fail("duplicate name"));
            }
            if P::IMAGE.name(r).is_none() {
                return Err(fail("image name is empty or not UTF-8"));
            }
            let (memory, kmem, stack) =
                (P::MEMORY.get(r), P::KERNEL_MEMORY.get(r), P::STACK.get(r));
            for size in [memory, kmem, stack] {
                if size == 0 || !size.is_multiple_of(PAGE_SIZE) {
                    return Err(fail(
                        "memory, kernel memory or stack is zero or not a multiple of 4 KiB",
                    ));
                }
            }
            if stack > memory {
                return Err(fail("stack larger than memory"));
            }
            let abilities =
                Abilities::from_bits(P::ABILITIES.get(r)).ok_or(fail("unknown ability bits"))?;
            if !PARTITION_ABILITIES.contains(abilities) {
                return Err(fail("an ability reserved for syssw"));
            }
            let (kthreads, ktasks) = (P::KERNEL_THREADS.u32(r), P::KERNEL_TASKS.u32(r));
            if kthreads == 0 || ktasks == 0 {
                return Err(fail("kernel thread or task quota is zero"));
            }
            if P::IRQS.u32(r) & IrqMask::FORBIDDEN != 0 {
                return Err(fail("IRQ line reserved by the kernel or beyond 23"));
            }
            let (mcp, priority) = (P::MCP.u8(r), P::PRIORITY.u8(r));
            if !(MCP_MIN..=MCP_MAX).contains(&mcp) {
                return Err(fail("MCP not in 1..=199"));
            }
            if priority > mcp {
                return Err(fail("priority above the MCP"));
            }
            if P::TIME_PARTITION.u8(r) >= TIME_PARTITIONS {
                return Err(fail("time partition above 15"));
            }
            match P::CPUS.u8(r) {
                0 => return Err(fail("no CPU")),
                cpus if u32::from(cpus) >> self.cpus() != 0 => {
                    return Err(fail("CPU beyond the system's CPUs"));
                }
                _ => {}
            }
            if !P::RESERVED_B.is_zero(r) {
                return Err(fail("reserved bytes are not zero"));
            }
            let flags = P::FLAGS.u8(r);
            if flags & !(FLAG_SCHEDULE_CONTROL | FLAG_DMA_UNCONFINED) != 0 {
                return Err(fail("unknown flags"));
            }
            let dma = P::DMA.get(r);
            if !dma.is_multiple_of(PAGE_SIZE) || dma > memory {
                return Err(fail(
                    "DMA region not a multiple of 4 KiB or larger than the partition's memory",
                ));
            }
            if (dma != 0 && P::DEVICE_COUNT.u8(r) == 0)
                || (dma == 0 && flags & FLAG_DMA_UNCONFINED != 0)
            {
                return Err(fail(
                    "a DMA region without PCI devices, or dma_unconfined without a DMA region",
                ));
            }
            let devices = usize::from(P::DEVICE_COUNT.u8(r));
            if devices > pci::MAX_PARTITION_DEVICES
                || !P::DEVICES.bytes(r)[2 * devices..].iter().all(|&b| b == 0)
            {
                return Err(fail(
                    "more PCI devices than a partition may own, or unused device slots not zero",
                ));
            }
            let mine = self.partition_view_devices(p);
            let taken = (0..p).flat_map(|o| self.partition_view_devices(o));
            if taken.clone().any(|d| mine.clone().any(|m| m == d))
                || mine
                    .clone()
                    .enumerate()
                    .any(|(i, m)| mine.clone().take(i).any(|o| o == m))
            {
                return Err(fail("a PCI device owned twice"));
            }
            if HealthTable::from_bytes(P::HEALTH.bytes(r)).is_none() {
                return Err(fail("unknown health action"));
            }
            let overflow = fail("memory sizes overflow");
            user_memory = user_memory.checked_add(memory).ok_or(overflow)?;
            kernel_memory = kernel_memory.checked_add(kmem).ok_or(overflow)?;
            threads += u64::from(kthreads);
            tasks += u64::from(ktasks);
            self.check_attachments(p)?;
            // Ports of this partition: names unique within it.
            let (first, count) = self.sub_range(p, P::FIRST_PORT, P::PORT_COUNT);
            for t in first..first + count {
                let name = port::NAME.bytes(self.record(Table::Port, t));
                if (first..t).any(|o| port::NAME.bytes(self.record(Table::Port, o)) == name) {
                    return Err(invalid(Table::Port, t, "duplicate name in its partition"));
                }
            }
        }
        let memory = header::MEMORY.get(self.bytes);
        let fail = |what| Err(invalid(Table::Header, 0, what));
        if user_memory > user_memory_limit(memory) {
            return fail("partition and segment memory exceed the budget");
        }
        if kernel_memory > kernel_memory_limit(memory) {
            return fail("kernel memory quotas exceed the kernel pool");
        }
        if threads > u64::from(KERNEL_THREADS - SYSSW_THREADS)
            || tasks > u64::from(KERNEL_TASKS - SYSSW_TASKS)
        {
            return fail("kernel thread or task quotas exceed the kernel's tables");
        }
        Ok(())
    }

    /// Partition `p`'s segment attachments.
    fn check_attachments(&self, p: usize) -> Result<(), DecodeError> {
        use attachment as A;
        let (first, count) =
            self.sub_range(p, partition::FIRST_ATTACHMENT, partition::ATTACHMENT_COUNT);
        for a in first..first + count {
            let r = self.record(Table::Attachment, a);
            let fail = |what| Err(invalid(Table::Attachment, a, what));
            if A::SEGMENT.u16(r) >= self.count(Table::Segment) {
                return fail("segment index out of range");
            }
            if Rights::from_code(A::RIGHTS.u8(r)).is_none() || !A::RESERVED.is_zero(r) {
                return fail("unknown rights");
            }
            let segment = A::SEGMENT.bytes(r);
            if (first..a).any(|o| A::SEGMENT.bytes(self.record(Table::Attachment, o)) == segment) {
                return fail("segment attached twice");
            }
        }
        Ok(())
    }

    /// I/O port ranges: well-formed, not the kernel's, disjoint.
    fn check_io_ranges(&self) -> Result<(), DecodeError> {
        for i in 0..self.count(Table::IoRange) {
            let range = self.io_range(i);
            let fail = |what| Err(invalid(Table::IoRange, i, what));
            if range.first > range.last {
                return fail("first port after last port");
            }
            if range.kernel_conflict().is_some() {
                return fail("includes a port the kernel keeps");
            }
            if (0..i).any(|o| self.io_range(o).overlaps(range)) {
                return fail("overlaps another range");
            }
        }
        Ok(())
    }

    fn check_ports(&self) -> Result<(), DecodeError> {
        use port as T;
        let channels = self.count(Table::Channel);
        for t in 0..self.count(Table::Port) {
            let r = self.record(Table::Port, t);
            let fail = |what| invalid(Table::Port, t, what);
            if T::NAME.name(r).is_none() {
                return Err(fail("name is empty or not UTF-8"));
            }
            let (size, depth) = (T::MESSAGE_SIZE.u32(r), T::DEPTH.u32(r));
            let kind = PortKind::from_code(T::KIND.u8(r)).ok_or(fail("unknown kind"))?;
            let direction =
                Direction::from_code(T::DIRECTION.u8(r)).ok_or(fail("unknown direction"))?;
            if !T::RESERVED.is_zero(r) {
                return Err(fail("reserved bytes are not zero"));
            }
            if size == 0 || size > MAX_MESSAGE_SIZE {
                return Err(fail("message size not in 1..=MAX_MESSAGE_SIZE"));
            }
            let depth_ok = match kind {
                PortKind::Sampling => depth == 0,
                PortKind::Queuing => (1..=MAX_QUEUE_DEPTH).contains(&depth),
            };
            if !depth_ok {
                return Err(fail("depth not 1..=256 (queuing) or not 0 (sampling)"));
            }
            let discipline =
                Discipline::from_code(T::DISCIPLINE.u8(r)).ok_or(fail("unknown discipline"))?;
            if kind == PortKind::Sampling && discipline != Discipline::Fifo {
                return Err(fail("queuing discipline on a sampling port"));
            }
            if T::REFRESH.get(r) != 0 && (kind, direction) != (PortKind::Sampling, Direction::In) {
                return Err(fail(
                    "refresh period on a port that is not a sampling input",
                ));
            }
            if T::CHANNEL.u16(r) >= channels {
                return Err(fail("channel index out of range"));
            }
        }
        Ok(())
    }

    /// Channels: every port in exactly one channel, consistent both ways.
    fn check_channels(&self) -> Result<(), DecodeError> {
        use channel as C;
        let channels = self.count(Table::Channel);
        tiles(
            (0..channels).map(|c| {
                let r = self.record(Table::Channel, c);
                (C::FIRST_DESTINATION.u16(r), C::DESTINATION_COUNT.u16(r))
            }),
            self.count(Table::Destination),
        )
        .map_err(|i| {
            invalid(
                Table::Channel,
                i.min(channels),
                "destination ranges do not tile the destination table",
            )
        })?;
        if self.count(Table::Port) != channels + self.count(Table::Destination) {
            return Err(invalid(
                Table::Header,
                0,
                "ports and channel ends do not match one to one",
            ));
        }
        for c in 0..channels {
            let r = self.record(Table::Channel, c);
            let fail = |what| invalid(Table::Channel, c, what);
            if C::NAME.name(r).is_none() {
                return Err(fail("name is empty or not UTF-8"));
            }
            if self.duplicate_name(Table::Channel, c, C::NAME) {
                return Err(fail("duplicate name"));
            }
            let kind = PortKind::from_code(C::KIND.u8(r)).ok_or(fail("unknown kind"))?;
            if !C::RESERVED.is_zero(r) {
                return Err(fail("reserved bytes are not zero"));
            }
            let source = C::SOURCE.u16(r);
            let (first, count) = (C::FIRST_DESTINATION.u16(r), C::DESTINATION_COUNT.u16(r));
            if source >= self.count(Table::Port) {
                return Err(fail("source port out of range"));
            }
            let src = self.port(source);
            if src.direction != Direction::Out || src.kind != kind || src.channel != c {
                return Err(fail(
                    "source is not an output port of this channel's kind and channel",
                ));
            }
            let count_ok = match kind {
                PortKind::Sampling => count >= 1,
                PortKind::Queuing => count == 1,
            };
            if !count_ok {
                return Err(fail("sampling needs >= 1 destination, queuing exactly 1"));
            }
            for d in first..first + count {
                let fail = |what| Err(invalid(Table::Destination, d, what));
                let port = destination::PORT.u16(self.record(Table::Destination, d));
                if port >= self.count(Table::Port) {
                    return fail("port index out of range");
                }
                let dst = self.port(port);
                if dst.direction != Direction::In || dst.kind != kind || dst.channel != c {
                    return fail("not an input port of this channel's kind and channel");
                }
                if dst.size < src.size {
                    return fail("message size smaller than the source's");
                }
                if (first..d).any(|o| {
                    self.record(Table::Destination, o) == self.record(Table::Destination, d)
                }) {
                    return fail("port listed twice");
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
        header::NAME.name(self.bytes).unwrap_or("")
    }

    /// RAM budget of the system (bytes).
    pub fn memory(&self) -> u64 {
        header::MEMORY.get(self.bytes)
    }

    /// How many CPUs the system uses (1..=[`MAX_CPUS`]): CPUs 0..this.
    pub fn cpus(&self) -> u8 {
        header::CPUS.u8(self.bytes)
    }

    /// The module health table.
    pub fn health(&self) -> HealthTable {
        HealthTable::from_bytes(header::HEALTH.bytes(self.bytes)).unwrap_or_default()
    }

    pub fn schedule_count(&self) -> usize {
        self.count(Table::Schedule)
    }

    /// Schedule `i` (panics if `i >= schedule_count()`); schedule 0 is the initial one.
    pub fn schedule(&self, i: usize) -> ScheduleView<'a> {
        let r = self.record(Table::Schedule, i);
        ScheduleView {
            index: i,
            name: schedule::NAME.name(r).unwrap_or(""),
            major_frame: schedule::MAJOR_FRAME.get(r),
            first_window: schedule::FIRST_WINDOW.u16(r),
            window_count: schedule::WINDOW_COUNT.u16(r),
            change_actions: ChangeActions(schedule::CHANGE_ACTIONS.u32(r)),
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
            name: segment::NAME.name(r).unwrap_or(""),
            size: segment::BYTES.get(r),
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
        use partition as P;
        PartitionView {
            index: i,
            name: P::NAME.name(r).unwrap_or(""),
            image: P::IMAGE.name(r).unwrap_or(""),
            memory: P::MEMORY.get(r),
            kernel_memory: P::KERNEL_MEMORY.get(r),
            stack: P::STACK.get(r),
            abilities: Abilities::from_bits_truncate(P::ABILITIES.get(r)),
            kernel_threads: P::KERNEL_THREADS.u32(r),
            kernel_tasks: P::KERNEL_TASKS.u32(r),
            irqs: IrqMask(P::IRQS.u32(r)),
            mcp: P::MCP.u8(r),
            priority: P::PRIORITY.u8(r),
            time_partition: P::TIME_PARTITION.u8(r),
            cpu: P::CPUS.u8(r).trailing_zeros() as u8,
            cpus: P::CPUS.u8(r),
            schedule_control: P::FLAGS.u8(r) & FLAG_SCHEDULE_CONTROL != 0,
            dma: P::DMA.get(r),
            dma_unconfined: P::FLAGS.u8(r) & FLAG_DMA_UNCONFINED != 0,
            health: HealthTable::from_bytes(P::HEALTH.bytes(r)).unwrap_or_default(),
            io: self.sub_range(i, P::FIRST_IO, P::IO_COUNT),
            attachments: self.sub_range(i, P::FIRST_ATTACHMENT, P::ATTACHMENT_COUNT),
            ports: self.sub_range(i, P::FIRST_PORT, P::PORT_COUNT),
            sys: *self,
        }
    }

    /// The PCI functions partition `i` owns (its record's device slots).
    fn partition_view_devices(&self, i: usize) -> impl Iterator<Item = pci::Address> + Clone + 'a {
        use partition as P;
        let r = self.record(Table::Partition, i);
        let count = usize::from(P::DEVICE_COUNT.u8(r)).min(pci::MAX_PARTITION_DEVICES);
        P::DEVICES.bytes(r)[..2 * count]
            .chunks_exact(2)
            .map(|id| pci::Address::from_id(u16::from_le_bytes([id[0], id[1]])))
    }

    pub fn partitions(&self) -> impl Iterator<Item = PartitionView<'a>> + 'a {
        let sys = *self;
        (0..sys.partition_count()).map(move |i| sys.partition(i))
    }

    /// Whether partitions `a` and `b` (distinct) map a shared-memory segment both: syssw
    /// lets such partitions wake each other's threads (a notification, no message).
    pub fn share_memory(&self, a: usize, b: usize) -> bool {
        let theirs = self.partition(b);
        a != b
            && self
                .partition(a)
                .shared()
                .any(|x| theirs.shared().any(|y| y.segment == x.segment))
    }

    pub fn find_partition(&self, name: &str) -> Option<PartitionView<'a>> {
        self.partitions().find(|p| p.name == name)
    }

    fn io_range(&self, i: usize) -> IoRange {
        let r = self.record(Table::IoRange, i);
        IoRange {
            first: io_range::FIRST.get(r) as u16,
            last: io_range::LAST.get(r) as u16,
        }
    }

    fn attachment(&self, i: usize) -> Attachment {
        let r = self.record(Table::Attachment, i);
        Attachment {
            segment: attachment::SEGMENT.u16(r),
            rights: Rights::from_code(attachment::RIGHTS.u8(r)).unwrap_or(Rights::Read),
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
                let (first, count) =
                    self.sub_range(p, partition::FIRST_PORT, partition::PORT_COUNT);
                (first..first + count).contains(&i)
            })
            .unwrap_or(0);
        PortView {
            index: i,
            partition,
            name: port::NAME.name(r).unwrap_or(""),
            size: port::MESSAGE_SIZE.u32(r),
            depth: port::DEPTH.u32(r),
            refresh: port::REFRESH.get(r),
            channel: port::CHANNEL.u16(r),
            kind: PortKind::from_code(port::KIND.u8(r)).unwrap_or(PortKind::Sampling),
            direction: Direction::from_code(port::DIRECTION.u8(r)).unwrap_or(Direction::In),
            discipline: Discipline::from_code(port::DISCIPLINE.u8(r)).unwrap_or(Discipline::Fifo),
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
            name: channel::NAME.name(r).unwrap_or(""),
            source: channel::SOURCE.u16(r),
            first_destination: channel::FIRST_DESTINATION.u16(r),
            destination_count: channel::DESTINATION_COUNT.u16(r),
            kind: PortKind::from_code(channel::KIND.u8(r)).unwrap_or(PortKind::Sampling),
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
    /// What a switch to this schedule does to each partition.
    pub change_actions: ChangeActions,
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
            offset: window::OFFSET.get(r),
            duration: window::DURATION.get(r),
            time_partition: window::TIME_PARTITION.u8(r),
            cpu: window::CPU.u8(r),
        }
    }

    pub fn windows(&self) -> impl Iterator<Item = Window> + 'a {
        let s = *self;
        (0..s.window_count).map(move |i| s.window(i))
    }

    /// The windows of CPU `cpu`'s schedule (those a partition bound to it runs in), in
    /// offset order.
    pub fn windows_of(&self, cpu: u8) -> impl Iterator<Item = Window> + 'a {
        self.windows().filter(move |w| w.cpu == cpu)
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
    /// The first of `cpus`: where its first thread starts.
    pub cpu: u8,
    /// The CPUs its threads run on (bit n: CPU n), each in that CPU's windows of its time
    /// partition (or in that CPU's background).
    pub cpus: u8,
    /// May switch the module schedule (ARINC SET_MODULE_SCHEDULE).
    pub schedule_control: bool,
    /// Bytes of its DMA region (`dma`; 0: none): physically contiguous, part of `memory`.
    pub dma: u64,
    /// Its devices may DMA without an IOMMU confining them (`dma_unconfined`).
    pub dma_unconfined: bool,
    pub health: HealthTable,
    io: (usize, usize),
    attachments: (usize, usize),
    ports: (usize, usize),
    sys: SystemView<'a>,
}

impl<'a> PartitionView<'a> {
    /// The PCI functions it owns (`devices`), in configuration order.
    pub fn devices(&self) -> impl Iterator<Item = pci::Address> + 'a {
        self.sys.partition_view_devices(self.index)
    }

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

    /// True if system.img entry `entry` is this partition's data ([`DATA_ENTRY_PREFIX`]).
    pub fn is_data_entry(&self, entry: &str) -> bool {
        entry.strip_prefix(DATA_ENTRY_PREFIX) == Some(self.name)
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
    /// Queuing: the order waiting processes are served in; sampling: FIFO.
    pub discipline: Discipline,
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
            .map(move |d| destination::PORT.u16(sys.record(Table::Destination, d)))
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

    /// A partition's device slots: the routing ids, the rest zero.
    fn device_ids(devices: &[pci::Address]) -> [u8; 16] {
        let mut out = [0u8; 16];
        for (slot, d) in out.chunks_exact_mut(2).zip(devices) {
            slot.copy_from_slice(&d.id().to_le_bytes());
        }
        out
    }

    /// A record being written: zeroed (so reserved bytes are zero), fields set by name.
    struct Record<const N: usize>([u8; N]);

    impl<const N: usize> Record<N> {
        fn new() -> Self {
            Self([0; N])
        }

        fn set(mut self, field: Field, value: u64) -> Self {
            field.set(&mut self.0, value);
            self
        }

        /// A count or index (validated systems keep them within 16 bits).
        fn index(self, field: Field, value: usize) -> Self {
            let value = u16::try_from(value).expect("validated counts fit 16 bits");
            self.set(field, u64::from(value))
        }

        fn name(mut self, field: Field, text: &str) -> Self {
            field.bytes_mut(&mut self.0)[..text.len()].copy_from_slice(text.as_bytes());
            self
        }

        fn raw(mut self, field: Field, bytes: &[u8]) -> Self {
            field.bytes_mut(&mut self.0).copy_from_slice(bytes);
            self
        }

        fn write(self, out: &mut Vec<u8>) {
            out.extend_from_slice(&self.0);
        }
    }

    /// Writes the blob of a validated system (see the module documentation).
    /// Panics if `system` breaks the format's limits, which [`crate::load`] rules out.
    pub fn encode(system: &System) -> Vec<u8> {
        let mut out = Vec::new();
        let windows: usize = system.schedules.iter().map(|s| s.windows.len()).sum();
        let io: usize = system.partitions.iter().map(|p| p.io_ports.len()).sum();
        let attachments: usize = system.partitions.iter().map(|p| p.shared.len()).sum();
        let ports: usize = system.partitions.iter().map(|p| p.ports.len()).sum();
        let destinations: usize = system.channels.iter().map(|c| c.destinations.len()).sum();
        let mut head = Record::<{ header::SIZE }>::new()
            .raw(header::MAGIC, &MAGIC)
            .set(header::VERSION, u64::from(VERSION))
            .name(header::NAME, &system.name)
            .set(header::MEMORY, system.memory)
            .set(header::CPUS, u64::from(system.cpus))
            .raw(header::HEALTH, &system.health.to_bytes());
        let counts = [
            system.schedules.len(),
            windows,
            system.segments.len(),
            system.partitions.len(),
            io,
            attachments,
            ports,
            system.channels.len(),
            destinations,
        ];
        for (i, count) in counts.into_iter().enumerate() {
            head = head.index(header::count(i), count);
        }
        head.write(&mut out); // CRC and total size are set at the end

        let mut first = 0;
        for s in &system.schedules {
            use schedule as S;
            Record::<{ S::SIZE }>::new()
                .name(S::NAME, &s.name)
                .set(S::MAJOR_FRAME, s.major_frame)
                .index(S::FIRST_WINDOW, first)
                .index(S::WINDOW_COUNT, s.windows.len())
                .set(S::CHANGE_ACTIONS, u64::from(s.change_actions.0))
                .write(&mut out);
            first += s.windows.len();
        }
        for w in system.schedules.iter().flat_map(|s| &s.windows) {
            Record::<{ window::SIZE }>::new()
                .set(window::OFFSET, w.offset)
                .set(window::DURATION, w.duration)
                .set(window::TIME_PARTITION, u64::from(w.time_partition))
                .set(window::CPU, u64::from(w.cpu))
                .write(&mut out);
        }
        for g in &system.segments {
            Record::<{ segment::SIZE }>::new()
                .name(segment::NAME, &g.name)
                .set(segment::BYTES, g.size)
                .write(&mut out);
        }
        let (mut io_at, mut att_at, mut port_at) = (0, 0, 0);
        for p in &system.partitions {
            use partition as P;
            Record::<{ P::SIZE }>::new()
                .name(P::NAME, &p.name)
                .name(P::IMAGE, &p.image)
                .set(P::MEMORY, p.memory)
                .set(P::KERNEL_MEMORY, p.kernel_memory)
                .set(P::STACK, p.stack)
                .set(P::ABILITIES, p.abilities.bits())
                .set(P::KERNEL_THREADS, u64::from(p.kernel_threads))
                .set(P::KERNEL_TASKS, u64::from(p.kernel_tasks))
                .set(P::IRQS, u64::from(p.irqs.0))
                .set(P::MCP, u64::from(p.mcp))
                .set(P::PRIORITY, u64::from(p.priority))
                .set(P::TIME_PARTITION, u64::from(p.time_partition))
                .set(P::CPUS, u64::from(p.cpus))
                .set(
                    P::FLAGS,
                    u64::from(
                        if p.schedule_control {
                            FLAG_SCHEDULE_CONTROL
                        } else {
                            0
                        } | if p.dma_unconfined {
                            FLAG_DMA_UNCONFINED
                        } else {
                            0
                        },
                    ),
                )
                .set(P::DMA, p.dma)
                .set(P::DEVICE_COUNT, p.devices.len() as u64)
                .raw(P::DEVICES, &device_ids(&p.devices))
                .raw(P::HEALTH, &p.health.to_bytes())
                .index(P::FIRST_IO, io_at)
                .index(P::IO_COUNT, p.io_ports.len())
                .index(P::FIRST_ATTACHMENT, att_at)
                .index(P::ATTACHMENT_COUNT, p.shared.len())
                .index(P::FIRST_PORT, port_at)
                .index(P::PORT_COUNT, p.ports.len())
                .write(&mut out);
            io_at += p.io_ports.len();
            att_at += p.shared.len();
            port_at += p.ports.len();
        }
        for r in system.partitions.iter().flat_map(|p| &p.io_ports) {
            Record::<{ io_range::SIZE }>::new()
                .set(io_range::FIRST, u64::from(r.first))
                .set(io_range::LAST, u64::from(r.last))
                .write(&mut out);
        }
        for a in system.partitions.iter().flat_map(|p| &p.shared) {
            Record::<{ attachment::SIZE }>::new()
                .index(attachment::SEGMENT, a.segment)
                .set(attachment::RIGHTS, u64::from(a.rights.code()))
                .write(&mut out);
        }
        for t in system.partitions.iter().flat_map(|p| &p.ports) {
            use port as T;
            Record::<{ T::SIZE }>::new()
                .name(T::NAME, &t.name)
                .set(T::MESSAGE_SIZE, u64::from(t.size))
                .set(T::DEPTH, u64::from(t.depth))
                .set(T::REFRESH, t.refresh)
                .index(T::CHANNEL, t.channel)
                .set(T::KIND, u64::from(t.kind.code()))
                .set(T::DIRECTION, u64::from(t.direction.code()))
                .set(T::DISCIPLINE, u64::from(t.discipline.code()))
                .write(&mut out);
        }
        let mut first = 0;
        for c in &system.channels {
            use channel as C;
            Record::<{ C::SIZE }>::new()
                .name(C::NAME, &c.name)
                .index(C::SOURCE, system.global_port(c.source))
                .index(C::FIRST_DESTINATION, first)
                .index(C::DESTINATION_COUNT, c.destinations.len())
                .set(C::KIND, u64::from(c.kind.code()))
                .write(&mut out);
            first += c.destinations.len();
        }
        for &d in system.channels.iter().flat_map(|c| &c.destinations) {
            Record::<{ destination::SIZE }>::new()
                .index(destination::PORT, system.global_port(d))
                .write(&mut out);
        }
        let total = u32::try_from(out.len()).expect("a configuration is far below 4 GiB");
        header::TOTAL_SIZE.set(&mut out, u64::from(total));
        let crc = crc32(&out[header::TOTAL_SIZE.at..]);
        header::CRC.set(&mut out, u64::from(crc));
        out
    }
}

#[cfg(feature = "host")]
pub use encode::encode;

#[cfg(test)]
mod tests {
    use super::*;

    /// Each record's field table covers it exactly: in order, no gap, no overlap, up to
    /// its size.
    #[test]
    fn fields_tile_their_records() {
        let tables: [(&str, &[Field], usize); 10] = [
            ("header", &header::FIELDS, header::SIZE),
            ("schedule", &schedule::FIELDS, schedule::SIZE),
            ("window", &window::FIELDS, window::SIZE),
            ("segment", &segment::FIELDS, segment::SIZE),
            ("partition", &partition::FIELDS, partition::SIZE),
            ("I/O range", &io_range::FIELDS, io_range::SIZE),
            ("attachment", &attachment::FIELDS, attachment::SIZE),
            ("port", &port::FIELDS, port::SIZE),
            ("channel", &channel::FIELDS, channel::SIZE),
            ("destination", &destination::FIELDS, destination::SIZE),
        ];
        for (name, fields, size) in tables {
            assert_eq!(abi::layout::tiles(fields, size), Ok(()), "{name}");
        }
        for (i, (_, size, _)) in TABLES.iter().enumerate() {
            let count = header::count(i);
            assert!(count.at + count.len <= header::RESERVED_B.at, "{size}");
        }
    }
}
