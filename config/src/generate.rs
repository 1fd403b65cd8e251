//! Random valid system descriptions, for the boot property: any description [`crate::load`]
//! accepts must encode, decode, pass syssw's start-up checks and boot to
//! `syssw: N partitions started`.
//!
//! [`system`] turns a seed into TOML text, deterministically (its own splitmix64 generator,
//! so a seed names the same text on every machine and toolchain). The text uses the whole
//! format except PLC, guest and data entries (they need host files): 1 to 15 partitions
//! with random `memory`, `kernel_memory`, `stack`, thread and task quotas, priorities and
//! abilities; windowed partitions and background ones (below every windowed partition's
//! floor, or with `preempts_windows`); 1 to 4 schedules whose windows lie in disjoint slots
//! of a major frame between 10 us (`MIN_WINDOW`) and 1 h (`MAX_MAJOR_FRAME`); shared-memory
//! segments, sampling and queuing channels, module and partition health tables, I/O port
//! ranges and IRQ lines outside the kernel's. Every partition runs `image`, has
//! `debug_log` and is named `p<index>`, so the heartbeat program `test-partition` (whose
//! role follows the name) can boot any of them.
//!
//! The generator aims at valid text only; a description [`crate::load`] refuses is a bug in
//! one or the other, which the property tests count (`config/tests/generated.rs`).

use crate::model::{
    ErrorCode, HealthAction, MAX_MAJOR_FRAME, MAX_PARTITIONS, MAX_SCHEDULES, MCP_MAX, MIN_WINDOW,
    RESERVED_IRQS,
};
use core::fmt::Write;
use std::string::{String, ToString};
use std::vec::Vec;
use std::{format, vec};

/// A small deterministic generator (splitmix64): the same seed, the same numbers (also the
/// power-cut test's delays).
pub struct Rng(pub u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A number in `lo..=hi`.
    pub fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next() % (hi - lo + 1)
    }

    /// True with probability `1/n`.
    fn one_in(&mut self, n: u64) -> bool {
        self.next().is_multiple_of(n)
    }

    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.next() as usize % items.len()]
    }
}

const KIB: u64 = 1024;
const MIB: u64 = 1024 * KIB;
const US: u64 = 1_000;
/// The lowest priority a windowed partition's threads keep to; background partitions
/// (without `preempts_windows`) stay below it.
const WINDOW_FLOOR: u64 = 31;
/// I/O ports handed out lie here: above the PICs, PIT and the exit device, below COM1.
const IO_FIRST: u64 = 0x100;
const IO_LAST: u64 = 0x3ef;

struct Partition {
    background: bool,
    ports: Vec<String>,
}

/// The description for `seed`; every partition runs `image`.
pub fn system(seed: u64, image: &str) -> String {
    let mut rng = Rng(seed);
    let mut out = String::new();
    let count = if rng.one_in(4) {
        rng.range(1, MAX_PARTITIONS as u64)
    } else {
        rng.range(1, 6)
    } as usize;
    // Partition 0 always has windows, so every system has a schedule.
    let mut parts: Vec<Partition> = (0..count)
        .map(|i| Partition {
            background: i > 0 && rng.one_in(4),
            ports: Vec::new(),
        })
        .collect();
    let _ = writeln!(
        out,
        "[system]\nname = \"generated-{seed}\"\nmemory = \"512MiB\"\n"
    );
    if rng.one_in(2) {
        out.push_str("[health]\n");
        health_entries(&mut rng, &mut out, "");
        out.push('\n');
    }
    schedules(&mut rng, &mut out, &parts);
    let segments: Vec<u64> = (0..rng.range(0, 3)).map(|_| rng.range(1, 64)).collect();
    for (i, pages) in segments.iter().enumerate() {
        let _ = writeln!(
            out,
            "[[shared_memory]]\nname = \"seg{i}\"\nsize = {}\n",
            size(&mut rng, pages * 4 * KIB)
        );
    }
    let channels = channels(&mut rng, &mut parts);
    let mut io_next = IO_FIRST;
    let mut irqs: Vec<u64> = (1..24)
        .filter(|l| !RESERVED_IRQS.contains(&(*l as u8)))
        .collect();
    for (i, p) in parts.iter().enumerate() {
        partition(
            &mut rng,
            &mut out,
            (i, p),
            image,
            segments.len(),
            &mut io_next,
            &mut irqs,
        );
    }
    out.push_str(&channels);
    out
}

/// `[partitions.p<i>]` with its keys.
fn partition(
    rng: &mut Rng,
    out: &mut String,
    (index, p): (usize, &Partition),
    image: &str,
    segments: usize,
    io_next: &mut u64,
    irqs: &mut Vec<u64>,
) {
    let _ = writeln!(out, "[partitions.p{index}]\nimage = \"{image}\"");
    let memory = rng.range(256, 4096) * 4 * KIB;
    let stack = rng.range(4, 64) * 4 * KIB;
    let _ = writeln!(out, "memory = {}", size(rng, memory));
    let kernel_memory = rng.range(64, 256) * 4 * KIB;
    let _ = writeln!(out, "kernel_memory = {}", size(rng, kernel_memory));
    if rng.one_in(2) {
        let _ = writeln!(out, "stack = {}", size(rng, stack));
    }
    if rng.one_in(2) {
        let _ = writeln!(out, "kernel_threads = {}", rng.range(2, 16));
    }
    if rng.one_in(3) {
        let _ = writeln!(out, "kernel_tasks = {}", rng.range(1, 3));
    }
    let preempts = p.background && rng.one_in(8);
    let mcp = match (p.background, preempts) {
        (false, _) => rng.range(WINDOW_FLOOR, u64::from(MCP_MAX)),
        (true, false) => rng.range(1, WINDOW_FLOOR - 1),
        (true, true) => rng.range(1, u64::from(MCP_MAX)),
    };
    let _ = writeln!(out, "max_priority = {mcp}");
    // A windowed partition's priority is its floor: at least WINDOW_FLOOR.
    if rng.one_in(2) {
        let low = if p.background { 1 } else { WINDOW_FLOOR };
        let _ = writeln!(out, "priority = {}", rng.range(low, mcp));
    }
    let mut abilities = vec!["debug_log"];
    for a in ["create_task", "create_thread", "map"] {
        if rng.one_in(3) {
            abilities.push(a);
        }
    }
    let lines: Vec<u64> = if !irqs.is_empty() && rng.one_in(6) {
        let n = rng.range(1, 2.min(irqs.len() as u64));
        (0..n)
            .map(|_| irqs.remove(rng.next() as usize % irqs.len()))
            .collect()
    } else {
        Vec::new()
    };
    if !lines.is_empty() {
        abilities.push("irq");
    }
    let quoted: Vec<String> = abilities.iter().map(|a| format!("\"{a}\"")).collect();
    let _ = writeln!(out, "abilities = [{}]", quoted.join(", "));
    if p.background {
        out.push_str("time = \"background\"\n");
        if preempts {
            out.push_str("preempts_windows = true\n");
        }
    }
    if rng.one_in(4) {
        let mut ranges = Vec::new();
        for _ in 0..rng.range(1, 3) {
            let first = *io_next + rng.range(0, 0x20);
            let last = first + rng.range(0, 15);
            if last > IO_LAST {
                break;
            }
            *io_next = last + 1;
            ranges.push(match (first == last, rng.one_in(2)) {
                (true, true) => format!("{first}"),
                (true, false) => format!("\"{first:#x}\""),
                (false, _) => format!("\"{first:#x}-{last:#x}\""),
            });
        }
        if !ranges.is_empty() {
            let _ = writeln!(out, "io_ports = [{}]", ranges.join(", "));
        }
    }
    if !lines.is_empty() {
        let shown: Vec<String> = lines.iter().map(u64::to_string).collect();
        let _ = writeln!(out, "irqs = [{}]", shown.join(", "));
    }
    let mut attached = Vec::new();
    for s in 0..segments {
        if rng.one_in(3) {
            attached.push(format!("seg{s} = \"{}\"", rng.pick(&["r", "rw", "rx"])));
        }
    }
    if !attached.is_empty() {
        let _ = writeln!(out, "shared = {{ {} }}", attached.join(", "));
    }
    for port in &p.ports {
        let _ = writeln!(out, "{port}");
    }
    if rng.one_in(3) {
        health_entries(rng, out, "health.");
    }
    out.push('\n');
}

/// 1 to 3 health-table entries, keys prefixed with `prefix`.
fn health_entries(rng: &mut Rng, out: &mut String, prefix: &str) {
    let mut errors: Vec<ErrorCode> = ErrorCode::ALL.to_vec();
    for _ in 0..rng.range(1, 3) {
        let error = errors.remove(rng.next() as usize % errors.len());
        let action = rng.pick(&HealthAction::ALL);
        let _ = writeln!(out, "{prefix}{} = \"{}\"", error.name(), action.name());
    }
}

/// The schedules: the first gives every windowed partition a window, the others a random
/// subset; each window lies in its own slot of the frame.
fn schedules(rng: &mut Rng, out: &mut String, parts: &[Partition]) {
    let windowed: Vec<usize> = (0..parts.len()).filter(|&i| !parts[i].background).collect();
    for s in 0..rng.range(1, MAX_SCHEDULES as u64) {
        let mut owners: Vec<usize> = if s == 0 {
            windowed.clone()
        } else {
            windowed.iter().copied().filter(|_| rng.one_in(2)).collect()
        };
        for _ in 0..rng.range(0, 6) {
            owners.push(*rng.pick(&windowed));
        }
        if owners.is_empty() {
            owners.push(windowed[0]);
        }
        // Shuffle (Fisher-Yates).
        for i in (1..owners.len()).rev() {
            owners.swap(i, rng.next() as usize % (i + 1));
        }
        let k = owners.len() as u64;
        let shortest = k * 2 * MIN_WINDOW / US;
        let frame_us = match rng.range(0, 19) {
            0 => MAX_MAJOR_FRAME / US,
            1..=6 => rng.range(shortest, shortest.max(2_000)),
            7..=14 => rng.range(shortest.max(2_000), 20_000),
            _ => rng.range(20_000, 200_000),
        };
        out.push_str("[[schedules]]\n");
        if s > 0 || rng.one_in(2) {
            let _ = writeln!(out, "name = \"s{s}\"");
        }
        let slot = frame_us / k;
        let mut last_end = 0;
        let mut windows = String::new();
        for (j, owner) in owners.iter().enumerate() {
            let duration = rng.range(MIN_WINDOW / US, slot);
            let offset = j as u64 * slot + rng.range(0, slot - duration);
            last_end = offset + duration;
            let _ = writeln!(
                windows,
                "[[schedules.windows]]\npartition = \"p{owner}\"\noffset = \"{}\"\nduration = \"{}\"",
                duration_text(offset),
                duration_text(duration)
            );
        }
        // Without `major_frame` the frame ends with the last window.
        if rng.range(0, 3) > 0 || last_end < MIN_WINDOW / US {
            let _ = writeln!(out, "major_frame = \"{}\"", duration_text(frame_us));
        }
        out.push_str(&windows);
        out.push('\n');
    }
}

/// The channels as `[[channels]]` text; their ports are added to the partitions.
fn channels(rng: &mut Rng, parts: &mut [Partition]) -> String {
    let mut out = String::new();
    if parts.len() < 2 {
        return out;
    }
    for c in 0..rng.range(0, 8) {
        let from = rng.next() as usize % parts.len();
        let queuing = rng.one_in(2);
        let mut others: Vec<usize> = (0..parts.len()).filter(|&i| i != from).collect();
        let fanout = if queuing {
            1
        } else {
            rng.range(1, 3.min(others.len() as u64))
        };
        let to: Vec<usize> = (0..fanout)
            .map(|_| others.remove(rng.next() as usize % others.len()))
            .collect();
        let size = if rng.one_in(4) {
            rng.range(1, 4096)
        } else {
            rng.range(1, 64)
        };
        let kind = if queuing { "queuing" } else { "sampling" };
        let port = |rng: &mut Rng, direction: &str, size: u64| {
            let mut text = format!("kind = \"{kind}\", direction = \"{direction}\", size = {size}");
            if queuing {
                let _ = write!(text, ", depth = {}", rng.range(1, 32));
            } else if direction == "in" && rng.one_in(2) {
                let _ = write!(
                    text,
                    ", refresh = \"{}\"",
                    duration_text(rng.range(1, 1_000) * 1_000)
                );
            }
            text
        };
        let text = port(rng, "out", size);
        parts[from]
            .ports
            .push(format!("ports.c{c}o = {{ {text} }}"));
        for &d in &to {
            let in_size = rng.range(size, size.max(64));
            let text = port(rng, "in", in_size);
            parts[d].ports.push(format!("ports.c{c}i = {{ {text} }}"));
        }
        out.push_str("[[channels]]\n");
        if rng.one_in(2) {
            let _ = writeln!(out, "name = \"ch{c}\"");
        }
        let _ = writeln!(out, "kind = \"{kind}\"\nfrom = \"p{from}.c{c}o\"");
        let dests: Vec<String> = to.iter().map(|d| format!("\"p{d}.c{c}i\"")).collect();
        if dests.len() == 1 && rng.one_in(2) {
            let _ = writeln!(out, "to = {}\n", dests[0]);
        } else {
            let _ = writeln!(out, "to = [{}]\n", dests.join(", "));
        }
    }
    out
}

/// A size in one of the accepted spellings.
fn size(rng: &mut Rng, bytes: u64) -> String {
    match rng.range(0, 2) {
        0 if bytes.is_multiple_of(MIB) => format!("\"{}MiB\"", bytes / MIB),
        0 | 1 => format!("\"{}KiB\"", bytes / KIB),
        _ => format!("{bytes}"),
    }
}

/// Microseconds in the largest unit that shows them exactly.
fn duration_text(us: u64) -> String {
    if us.is_multiple_of(1_000_000) && us > 0 {
        format!("{}s", us / 1_000_000)
    } else if us.is_multiple_of(1_000) && us > 0 {
        format!("{}ms", us / 1_000)
    } else {
        format!("{us}us")
    }
}
