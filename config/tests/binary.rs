//! The binary form: encode -> decode round trips, and the decoder's behaviour on damaged
//! or hostile blobs (it must reject them or decode something consistent, never panic).

mod common;
use abi::crc32::crc32;
use common::*;
use config::binary::{
    self, DecodeError, Table, attachment, channel, header, io_range, partition, port, schedule,
    window,
};
use config::model::{
    ChangeAction, ChangeActions, Direction, Discipline, ErrorCode, HealthAction, PortKind, Rights,
};
use config::{System, decode};
use proptest::prelude::*;

/// A system using every feature of the format.
const RICH: &str = r#"[system]
name = "rich"
memory = "1GiB"
cpus = 2

[[schedules]]
name = "normal"
major_frame = "10ms"
[[schedules.windows]]
partition = "ctl"
offset = "0ms"
duration = "2ms"
[[schedules.windows]]
partition = "io"
offset = "3ms"
duration = "500us"
[[schedules.windows]]
partition = "ctl"
offset = "5ms"
duration = "1ms"

[[schedules]]
name = "safe"
major_frame = "20ms"
change_actions = { ctl = "cold_start", guest = "idle" }
[[schedules.windows]]
partition = "io"
offset = "0ms"
duration = "1ms"

[[shared_memory]]
name = "frame"
size = "64KiB"

[[shared_memory]]
name = "code"
size = "8KiB"

[partitions.ctl]
image = "ctl"
memory = "8MiB"
kernel_memory = "256KiB"
stack = "128KiB"
kernel_threads = 8
kernel_tasks = 2
max_priority = 150
priority = 120
schedule_control = true
abilities = ["create_thread", "debug_log"]
shared = { frame = "rw", code = "rx" }
ports.level = { kind = "sampling", direction = "in", size = 16, refresh = "20ms" }
ports.cmd = { kind = "queuing", direction = "out", size = 64, depth = 8, discipline = "priority" }
health.deadline_missed = "warm_restart"
health.application_error = "shutdown_success"

[partitions.io]
image = "io"
memory = "4MiB"
kernel_memory = "128KiB"
max_priority = 140
abilities = ["io_ports", "irq"]
io_ports = ["0x60", "0x2f8-0x2ff", 0x378]
irqs = [3, 7]
devices = ["00:03.0", "00:04.0"]
dma = "64KiB"
dma_unconfined = true
shared = { frame = "r" }
ports.level = { kind = "sampling", direction = "out", size = 8 }
ports.cmd = { kind = "queuing", direction = "in", size = 128, depth = 4 }

[partitions.guest]
image = "guest"
memory = "64MiB"
kernel_memory = "1MiB"
max_priority = 10
native_syscalls = false
time = "background"
cpus = [1]
ports.level = { kind = "sampling", direction = "in", size = 8 }

[[channels]]
name = "level"
kind = "sampling"
from = "io.level"
to = ["ctl.level", "guest.level"]

[[channels]]
kind = "queuing"
from = "ctl.cmd"
to = "io.cmd"

[health]
power_fail = "shutdown"
memory_violation = "idle"
"#;

fn rich() -> System {
    load_ok(RICH)
}

/// Recomputes the checksum after a deliberate edit, so the test reaches the checks behind it.
fn reseal(blob: &mut [u8]) {
    let covered = header::TOTAL_SIZE.at;
    let total = (header::TOTAL_SIZE.get(blob) as usize).min(blob.len());
    if total >= covered {
        let crc = crc32(&blob[covered..total]);
        header::CRC.set(blob, u64::from(crc));
    }
}

/// Whatever decodes must be consistent: walking it never panics, and encoding its owned copy
/// gives back exactly the same bytes (the format has one encoding per system).
fn assert_consistent(blob: &[u8]) {
    if let Ok(view) = decode(blob) {
        let system = System::from_view(&view);
        for p in view.partitions() {
            let _ = (p.io_ports().count(), p.shared().count(), p.ports().count());
        }
        for c in view.channels() {
            let _ = c.destinations().count();
        }
        let again = binary::encode(&system);
        assert_eq!(again, view.as_bytes(), "re-encoding changed the blob");
        assert!(decode(&again).is_ok());
    }
}

#[test]
fn round_trip() {
    let system = rich();
    let blob = binary::encode(&system);
    let view = decode(&blob).expect("a validated system decodes");
    assert_eq!(System::from_view(&view), system);

    // Spot checks of the view API syssw uses.
    assert_eq!(view.name(), "rich");
    assert_eq!(view.memory(), 1 << 30);
    assert_eq!(view.cpus(), 2);
    assert_eq!(view.schedule_count(), 2);
    let normal = view.schedule(0);
    assert_eq!(normal.name, "normal");
    assert_eq!(normal.major_frame, 10_000_000);
    let windows: Vec<_> = normal.windows().map(|w| w.spec()).collect();
    assert_eq!(windows.len(), 3);
    assert_eq!(
        (windows[1].offset, windows[1].duration, windows[1].partition),
        (3_000_000, 500_000, 2)
    );
    assert_eq!(normal.change_actions, ChangeActions::default());
    let safe = view.schedule(1).change_actions;
    let actions: Vec<_> = (0..4).map(|p| safe.get(p)).collect();
    assert_eq!(
        actions,
        [
            ChangeAction::ColdStart,
            ChangeAction::Ignore,
            ChangeAction::Idle,
            ChangeAction::Ignore
        ],
        "ctl, io, guest and no partition"
    );
    let ctl = view.find_partition("ctl").unwrap();
    assert_eq!((ctl.mcp, ctl.priority, ctl.time_partition), (150, 120, 1));
    assert_eq!(ctl.stack, 128 << 10);
    assert!(ctl.schedule_control);
    assert!(
        !view.find_partition("io").unwrap().schedule_control,
        "schedule_control is off unless the file says so"
    );
    assert!(ctl.is_image_entry("partition/ctl"));
    let shared: Vec<_> = ctl.shared().collect();
    let (io, guest) = (1, view.find_partition("guest").unwrap().index);
    assert!(view.share_memory(ctl.index, io) && view.share_memory(io, ctl.index));
    assert!(!view.share_memory(ctl.index, guest) && !view.share_memory(io, guest));
    assert!(!view.share_memory(ctl.index, ctl.index), "not with itself");
    assert_eq!(shared[0].rights, Rights::ReadWrite);
    assert_eq!(view.segment(shared[1].segment).name, "code");
    assert_eq!(
        ctl.health.get(ErrorCode::ApplicationError),
        Some(HealthAction::ShutdownSuccess)
    );
    let io = view.partition(1);
    let ranges: Vec<String> = io.io_ports().map(|r| r.to_string()).collect();
    assert_eq!(ranges, ["0x60", "0x2f8-0x2ff", "0x378"]);
    assert_eq!(io.irqs.lines().collect::<Vec<_>>(), [3, 7]);
    let guest = view.find_partition("guest").unwrap();
    assert_eq!((guest.time_partition, guest.cpu), (0, 1));
    assert_eq!(ctl.cpu, 0);
    assert!(guest.abilities.is_empty());
    let level = view.channel(0);
    assert_eq!(level.kind, PortKind::Sampling);
    let source = view.port(level.source);
    assert_eq!(
        (view.partition(source.partition).name, source.name),
        ("io", "level")
    );
    let targets: Vec<_> = level
        .destinations()
        .map(|d| {
            let p = view.port(d);
            (view.partition(p.partition).name, p.direction, p.channel)
        })
        .collect();
    assert_eq!(
        targets,
        [("ctl", Direction::In, 0), ("guest", Direction::In, 0)]
    );
    let cmd = ctl.find_port("cmd").unwrap();
    assert_eq!(
        (cmd.kind, cmd.depth, cmd.channel),
        (PortKind::Queuing, 8, 1)
    );
    assert_eq!(ctl.find_port("level").unwrap().refresh, 20_000_000);
    assert_eq!(cmd.discipline, Discipline::Priority);
    assert_eq!(
        ctl.find_port("level").unwrap().discipline,
        Discipline::Fifo,
        "a port without `discipline` is FIFO"
    );
    assert_eq!(
        view.health().get(ErrorCode::PowerFail),
        Some(HealthAction::Shutdown)
    );
}

/// Two CPUs, each with its own windows: they overlap in time across the CPUs.
const SMP: &str = r#"[system]
memory = "512MiB"
cpus = 2

[[schedules]]
major_frame = "10ms"
[[schedules.windows]]
partition = "a"
offset = "0ms"
duration = "4ms"
[[schedules.windows]]
partition = "b"
offset = "1ms"
duration = "4ms"
[[schedules.windows]]
partition = "a"
offset = "5ms"
duration = "1ms"

[partitions.a]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 100

[partitions.b]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 100
cpus = [1]
"#;

#[test]
fn windows_of_two_cpus_round_trip() {
    let system = load_ok(SMP);
    let blob = binary::encode(&system);
    let view = decode(&blob).expect("a validated system decodes");
    assert_eq!(System::from_view(&view), system);
    let s = view.schedule(0);
    let all: Vec<(u64, u8, u8)> = s
        .windows()
        .map(|w| (w.offset, w.cpu, w.time_partition))
        .collect();
    assert_eq!(
        all,
        [(0, 0, 1), (1_000_000, 1, 2), (5_000_000, 0, 1)],
        "sorted by offset"
    );
    let specs: Vec<(u64, u64)> = s
        .windows_of(1)
        .map(|w| w.spec())
        .map(|w| (w.offset, w.cpu))
        .collect();
    assert_eq!(specs, [(1_000_000, 1)]);
    assert_eq!(s.windows_of(0).count(), 2);
    assert_eq!(view.partition(1).cpu, 1);

    let edit = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut b = blob.clone();
        edit(&mut b);
        reseal(&mut b);
        decode(&b).expect_err("damage accepted")
    };
    let w = |b: &Vec<u8>, i| record(b, Table::Window, i);
    // b's window moved to CPU 0 overlaps a's first window there.
    invalid(Table::Window, 1, "overlaps the previous window of its CPU")(edit(&|b| {
        let at = w(b, 1);
        window::CPU.set(&mut b[at..], 0);
    }));
    // Out of offset order.
    invalid(Table::Window, 1, "not sorted by offset")(edit(&|b| {
        let at = w(b, 1);
        window::OFFSET.set(&mut b[at..], 0);
        let at = w(b, 0);
        window::OFFSET.set(&mut b[at..], 2_000_000);
    }));
    // a bound to CPU 1: its windows on CPU 0 serve no partition there.
    invalid(Table::Window, 0, "used by no partition of its CPU")(edit(&|b| {
        let at = record(b, Table::Partition, 0);
        partition::CPUS.set(&mut b[at..], 0b10);
    }));
}

#[test]
fn empty_system_round_trips() {
    let system = load_ok("[system]\nmemory = \"64MiB\"\n");
    let blob = binary::encode(&system);
    assert_eq!(blob.len(), binary::HEADER_SIZE);
    assert_eq!(System::from_view(&decode(&blob).unwrap()), system);
}

#[test]
fn trailing_bytes_are_ignored() {
    let mut blob = binary::encode(&rich());
    let len = blob.len();
    blob.resize(len + 4096, 0xaa);
    assert_eq!(decode(&blob).unwrap().as_bytes().len(), len);
}

#[test]
fn every_truncation_is_rejected() {
    let blob = binary::encode(&rich());
    for len in 0..blob.len() {
        assert!(decode(&blob[..len]).is_err(), "accepted {len} bytes");
    }
}

#[test]
fn every_bit_flip_is_rejected() {
    let blob = binary::encode(&rich());
    for at in 0..blob.len() {
        for bit in 0..8 {
            let mut b = blob.clone();
            b[at] ^= 1 << bit;
            assert!(decode(&b).is_err(), "flip of bit {bit} at {at} accepted");
        }
    }
}

#[test]
fn resealed_damage_never_panics() {
    // With a valid checksum the structural checks are all that stand between a damaged blob
    // and syssw: every single-byte change must be rejected or decode consistently.
    let blob = binary::encode(&rich());
    for at in 12..blob.len() {
        for value in [0x00, 0x01, 0x02, 0x0f, 0x10, 0x7f, 0x80, 0xff] {
            let mut b = blob.clone();
            b[at] = value;
            b[at] ^= if value == blob[at] { 1 } else { 0 };
            reseal(&mut b);
            assert_consistent(&b);
        }
    }
}

/// The byte offset of record `index` of a table in `blob` (tables follow the header in the
/// documented order).
fn record(blob: &[u8], table: Table, index: usize) -> usize {
    let count = |i: usize| header::count(i).get(blob) as usize;
    let sizes = [
        binary::SCHEDULE_SIZE,
        binary::WINDOW_SIZE,
        binary::SEGMENT_SIZE,
        binary::PARTITION_SIZE,
        binary::IO_RANGE_SIZE,
        binary::ATTACHMENT_SIZE,
        binary::PORT_SIZE,
        binary::CHANNEL_SIZE,
        binary::DESTINATION_SIZE,
    ];
    let order = [
        Table::Schedule,
        Table::Window,
        Table::Segment,
        Table::Partition,
        Table::IoRange,
        Table::Attachment,
        Table::Port,
        Table::Channel,
        Table::Destination,
    ];
    let slot = order.iter().position(|&t| t == table).unwrap();
    let before: usize = (0..slot).map(|i| count(i) * sizes[i]).sum();
    binary::HEADER_SIZE + before + index * sizes[slot]
}

fn damaged(edit: impl Fn(&mut Vec<u8>)) -> DecodeError {
    let mut blob = binary::encode(&rich());
    edit(&mut blob);
    reseal(&mut blob);
    decode(&blob).expect_err("damage accepted")
}

fn invalid(table: Table, index: usize, what: &str) -> impl Fn(DecodeError) {
    let what = what.to_string();
    move |e| match e {
        DecodeError::Invalid {
            table: t,
            index: i,
            what: w,
        } => {
            assert_eq!((t, i), (table, index), "{e}");
            assert!(w.contains(&what), "{e}");
        }
        other => panic!("expected {table:?} {index} {what:?}, got {other:?}"),
    }
}

#[test]
fn header_damage() {
    let blob = binary::encode(&rich());
    let mut b = blob.clone();
    header::MAGIC.bytes_mut(&mut b)[0] = b'X';
    assert_eq!(decode(&b).unwrap_err(), DecodeError::BadMagic);
    let mut b = blob.clone();
    header::VERSION.set(&mut b, 2);
    assert_eq!(decode(&b).unwrap_err(), DecodeError::UnsupportedVersion(2));
    let mut b = blob.clone();
    let last = b.len() - 1;
    b[last] ^= 0x40;
    assert!(matches!(
        decode(&b).unwrap_err(),
        DecodeError::ChecksumMismatch { .. }
    ));
    let e = damaged(|b| {
        let total = b.len() as u32 + 1;
        header::TOTAL_SIZE.set(b, u64::from(total));
    });
    assert!(matches!(e, DecodeError::TooShort { .. }), "{e:?}");
    let e = damaged(|b| header::count(0).set(b, 5));
    assert_eq!(
        e,
        DecodeError::TooMany {
            table: Table::Schedule,
            count: 5,
            max: 4
        }
    );
    let e = damaged(|b| header::count(2).set(b, 1));
    assert!(matches!(e, DecodeError::SizeMismatch { .. }), "{e:?}");
    invalid(Table::Header, 0, "reserved")(damaged(|b| header::RESERVED_B.bytes_mut(b)[2] = 1));
    invalid(Table::Header, 0, "CPU count")(damaged(|b| header::CPUS.set(b, 0)));
    invalid(Table::Header, 0, "CPU count")(damaged(|b| header::CPUS.set(b, 9)));
    invalid(Table::Header, 0, "module health")(damaged(|b| header::HEALTH.bytes_mut(b)[0] = 9));
}

#[test]
fn schedule_damage() {
    // A frame the kernel would refuse (and whose boundary sums could overflow).
    invalid(Table::Schedule, 0, "longer than the kernel's limits")(damaged(|b| {
        let at = record(b, Table::Schedule, 0);
        schedule::MAJOR_FRAME.set(&mut b[at..], u64::MAX);
    }));
    // A frame so short that window-boundary interrupts would take all the time.
    invalid(
        Table::Schedule,
        0,
        "shorter or longer than the kernel's limits",
    )(damaged(|b| {
        let at = record(b, Table::Schedule, 0);
        schedule::MAJOR_FRAME.set(&mut b[at..], 16);
    }));
    // A change action for a fourth partition of a system of three.
    invalid(Table::Schedule, 1, "partition that does not exist")(damaged(|b| {
        let at = record(b, Table::Schedule, 1);
        schedule::CHANGE_ACTIONS.set(&mut b[at..], 0b10 << 6);
    }));
}

#[test]
fn window_damage() {
    let w = |b: &Vec<u8>, i| record(b, Table::Window, i);
    // Time partition 0 and 16.
    invalid(Table::Window, 0, "not in 1..=15")(damaged(|b| {
        let at = w(b, 0);
        window::TIME_PARTITION.set(&mut b[at..], 0);
    }));
    invalid(Table::Window, 0, "used by no partition")(damaged(|b| {
        let at = w(b, 0);
        window::TIME_PARTITION.set(&mut b[at..], 9);
    }));
    // Window 1 (3ms..3.5ms) moved to start at 1ms overlaps window 0 (0..2ms).
    invalid(Table::Window, 1, "overlaps")(damaged(|b| {
        let at = w(b, 1);
        window::OFFSET.set(&mut b[at..], 1_000_000);
    }));
    invalid(Table::Window, 1, "CPU beyond the system's CPUs")(damaged(|b| {
        let at = w(b, 1);
        window::CPU.set(&mut b[at..], 2);
    }));
    // io's time partition has no partition on CPU 1.
    invalid(Table::Window, 1, "used by no partition of its CPU")(damaged(|b| {
        let at = w(b, 1);
        window::CPU.set(&mut b[at..], 1);
    }));
    invalid(Table::Window, 0, "reserved bytes")(damaged(|b| {
        let at = w(b, 0);
        window::RESERVED.bytes_mut(&mut b[at..])[0] = 1;
    }));
    invalid(Table::Window, 2, "ends after the major frame")(damaged(|b| {
        let at = w(b, 2);
        window::DURATION.set(&mut b[at..], u64::MAX);
    }));
    invalid(
        Table::Window,
        0,
        "shorter than the kernel's shortest window",
    )(damaged(|b| {
        let at = w(b, 0);
        window::DURATION.set(&mut b[at..], 0);
    }));
    invalid(
        Table::Window,
        0,
        "shorter than the kernel's shortest window",
    )(damaged(|b| {
        let at = w(b, 0);
        window::DURATION.set(&mut b[at..], config::model::MIN_WINDOW - 1);
    }));
}

#[test]
fn partition_damage() {
    let p = |b: &Vec<u8>, i| record(b, Table::Partition, i);
    invalid(Table::Partition, 0, "MCP")(damaged(|b| {
        let at = p(b, 0);
        partition::MCP.set(&mut b[at..], 200);
    }));
    invalid(Table::Partition, 0, "unknown flags")(damaged(|b| {
        let at = p(b, 0);
        partition::FLAGS.set(&mut b[at..], 4);
    }));
    invalid(Table::Partition, 2, "CPU beyond the system's CPUs")(damaged(|b| {
        let at = p(b, 2);
        partition::CPUS.set(&mut b[at..], 0b101);
    }));
    invalid(Table::Partition, 2, "no CPU")(damaged(|b| {
        let at = p(b, 2);
        partition::CPUS.set(&mut b[at..], 0);
    }));
    invalid(Table::Partition, 0, "priority above the MCP")(damaged(|b| {
        let at = p(b, 0);
        partition::PRIORITY.set(&mut b[at..], 151);
    }));
    invalid(Table::Partition, 1, "reserved for syssw")(damaged(|b| {
        let at = p(b, 1);
        partition::ABILITIES.bytes_mut(&mut b[at..])[1] |= 1; // bit 8: SYSTEM_HALT
    }));
    invalid(Table::Partition, 1, "IRQ line")(damaged(|b| {
        let at = p(b, 1);
        partition::IRQS.bytes_mut(&mut b[at..])[0] |= 1 << 4;
    }));
    invalid(Table::Partition, 0, "stack larger than memory")(damaged(|b| {
        let at = p(b, 0);
        partition::STACK.set(&mut b[at..], 16 << 20);
    }));
    invalid(Table::Partition, 2, "duplicate name")(damaged(|b| {
        let (from, to) = (p(b, 0), p(b, 2));
        let name: Vec<u8> = partition::NAME.bytes(&b[from..]).to_vec();
        partition::NAME
            .bytes_mut(&mut b[to..])
            .copy_from_slice(&name);
    }));
    invalid(Table::Partition, 0, "not UTF-8")(damaged(|b| {
        let at = p(b, 0);
        partition::NAME.bytes_mut(&mut b[at..])[0] = 0xff;
    }));
    invalid(Table::Partition, 1, "do not tile")(damaged(|b| {
        let at = p(b, 1);
        partition::FIRST_PORT.bytes_mut(&mut b[at..])[0] += 1;
    }));
    invalid(Table::Partition, 2, "a PCI device owned twice")(damaged(|b| {
        let (from, to) = (p(b, 1), p(b, 2));
        let ids: Vec<u8> = partition::DEVICES.bytes(&b[from..])[..2].to_vec();
        partition::DEVICES.bytes_mut(&mut b[to..])[..2].copy_from_slice(&ids);
        partition::DEVICE_COUNT.set(&mut b[to..], 1);
    }));
    invalid(Table::Partition, 1, "a PCI device owned twice")(damaged(|b| {
        let at = p(b, 1);
        partition::DEVICES.bytes_mut(&mut b[at..])[2] = 0x18; // 00:03.0 twice
    }));
    invalid(Table::Partition, 1, "more PCI devices")(damaged(|b| {
        let at = p(b, 1);
        partition::DEVICE_COUNT.set(&mut b[at..], 9);
    }));
    invalid(Table::Partition, 1, "unused device slots not zero")(damaged(|b| {
        let at = p(b, 1);
        partition::DEVICES.bytes_mut(&mut b[at..])[15] = 1;
    }));
    invalid(Table::Partition, 1, "DMA region not a multiple of 4 KiB")(damaged(|b| {
        let at = p(b, 1);
        partition::DMA.set(&mut b[at..], 4097);
    }));
    invalid(Table::Partition, 1, "larger than the partition's memory")(damaged(|b| {
        let at = p(b, 1);
        partition::DMA.set(&mut b[at..], 1 << 40);
    }));
    invalid(Table::Partition, 2, "a DMA region without PCI devices")(damaged(|b| {
        let at = p(b, 2);
        partition::DMA.set(&mut b[at..], 4096);
    }));
    invalid(Table::Partition, 1, "dma_unconfined without a DMA region")(damaged(|b| {
        let at = p(b, 1);
        partition::DMA.set(&mut b[at..], 0);
    }));
    invalid(Table::Header, 0, "exceed the budget")(damaged(|b| {
        let at = p(b, 2);
        partition::MEMORY.set(&mut b[at..], 1 << 30);
    }));
}

#[test]
fn resource_damage() {
    invalid(Table::IoRange, 1, "the kernel keeps")(damaged(|b| {
        let at = record(b, Table::IoRange, 1);
        io_range::FIRST.set(&mut b[at..], 0x3f8);
        io_range::LAST.set(&mut b[at..], 0x3f8);
    }));
    invalid(Table::IoRange, 2, "overlaps")(damaged(|b| {
        let at = record(b, Table::IoRange, 2);
        io_range::FIRST.set(&mut b[at..], 0x2f9);
        io_range::LAST.set(&mut b[at..], 0x2f9);
    }));
    invalid(Table::Attachment, 0, "segment index out of range")(damaged(|b| {
        let at = record(b, Table::Attachment, 0);
        attachment::SEGMENT.set(&mut b[at..], 7);
    }));
    invalid(Table::Attachment, 1, "unknown rights")(damaged(|b| {
        let at = record(b, Table::Attachment, 1);
        attachment::RIGHTS.set(&mut b[at..], 4);
    }));
}

#[test]
fn port_and_channel_damage() {
    let t = |b: &Vec<u8>, i| record(b, Table::Port, i);
    invalid(Table::Port, 0, "channel index out of range")(damaged(|b| {
        let at = t(b, 0);
        port::CHANNEL.set(&mut b[at..], 99);
    }));
    invalid(Table::Port, 1, "depth")(damaged(|b| {
        let at = t(b, 1);
        port::DEPTH.set(&mut b[at..], 0);
    }));
    invalid(Table::Port, 0, "queuing discipline on a sampling port")(damaged(|b| {
        let at = t(b, 0);
        port::DISCIPLINE.set(&mut b[at..], 1);
    }));
    invalid(Table::Port, 1, "unknown discipline")(damaged(|b| {
        let at = t(b, 1);
        port::DISCIPLINE.set(&mut b[at..], 2);
    }));
    invalid(Table::Port, 0, "refresh period on a port")(damaged(|b| {
        // ctl.level becomes an output: refresh no longer allowed.
        let at = t(b, 0);
        port::DIRECTION.set(&mut b[at..], 2);
    }));
    invalid(Table::Channel, 0, "source is not an output port")(damaged(|b| {
        let at = record(b, Table::Channel, 0);
        channel::SOURCE.set(&mut b[at..], 0); // ctl.level, an input
    }));
    invalid(Table::Destination, 0, "smaller than the source")(damaged(|b| {
        let at = t(b, 0);
        port::MESSAGE_SIZE.set(&mut b[at..], 4);
    }));
    invalid(Table::Channel, 1, "queuing exactly 1")(damaged(|b| {
        // Move the guest's destination from channel 0 to channel 1.
        let c0 = record(b, Table::Channel, 0);
        channel::DESTINATION_COUNT.set(&mut b[c0..], 1);
        let c1 = record(b, Table::Channel, 1);
        channel::FIRST_DESTINATION.set(&mut b[c1..], 1);
        channel::DESTINATION_COUNT.set(&mut b[c1..], 2);
    }));
}

#[test]
fn errors_read_well() {
    let e = DecodeError::Invalid {
        table: Table::Window,
        index: 3,
        what: "duration is zero",
    };
    assert_eq!(
        e.to_string(),
        "binary configuration window 3: duration is zero"
    );
    assert_eq!(
        DecodeError::TooShort {
            needed: 96,
            actual: 3
        }
        .to_string(),
        "binary configuration truncated: 3 bytes, 96 needed"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = decode(&bytes);
        // With a valid header and checksum the structure checks run too.
        let mut b = binary::encode(&rich());
        let covered = header::TOTAL_SIZE.at; // everything the checksum covers
        let n = bytes.len().min(b.len() - covered);
        b[covered..covered + n].copy_from_slice(&bytes[..n]);
        reseal(&mut b);
        assert_consistent(&b);
    }

    #[test]
    fn resealed_mutations_decode_consistently(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6)
    ) {
        let mut b = binary::encode(&rich());
        let len = b.len();
        for (at, value) in edits {
            let covered = header::TOTAL_SIZE.at;
            let at = covered + at.index(len - covered);
            b[at] = value;
        }
        reseal(&mut b);
        assert_consistent(&b);
    }
}
