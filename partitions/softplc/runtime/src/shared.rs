//! Global variables shared between two PLC projects through a shared-memory segment: the
//! segment layout, the copy protocol (a sequence lock), and (feature `alloc`) the build-time
//! pairing that lays a segment out for two compiled programs. This module is the one place
//! the segment's format is written; it works on the segment as a slice of atomic words, so
//! the whole protocol is tested on the host. It must never let a torn record into data
//! memory, and never trust the other project's bytes beyond "some bit pattern of the
//! variable's type" (the only types that can be shared have no invalid bit patterns).
//!
//! # Segment layout
//!
//! Each project that writes shared globals owns one *area* of the segment (configuration
//! order of the partitions, the first at offset 0, each next one at the next multiple of
//! [`AREA_ALIGN`] so the two writers never share a cache line):
//!
//! ```text
//! offset size
//! 0      4    sequence (u32): 0 = never written, odd = an update is in progress,
//!             even = a complete update
//! 4      4    reserved (0)
//! 8      ...  the written variables in declaration order, each at the next multiple of its
//!             size (1, 2, 4 or 8 bytes), little-endian as in data memory
//! ```
//!
//! The area's length is rounded up to 8 bytes. Which variable lies where is decided when
//! `cargo xtask` builds the system ([`plan`]) and handed to each partition in its package
//! ([`crate::package::SharedLayout`]): a project knows its own area and the other's.
//!
//! # Protocol: a sequence lock
//!
//! After each scan cycle the writer copies its written variables out: it makes the sequence
//! odd, stores the bytes, and makes it even again (the next even number). Before each scan
//! cycle the reader copies the other project's variables in: it reads the sequence (odd:
//! an update is in progress, try again), copies the bytes into a scratch buffer, reads the
//! sequence again, and takes the copy into data memory only if the sequence did not change.
//! It tries [`MAX_ATTEMPTS`] times, and waits for an update in progress to end up to
//! [`MAX_WAIT_PAUSES`] pauses; if every attempt overlapped an update or the wait ran out,
//! the read variables keep their previous values and the cycle counts as *stale*
//! ([`Fetch::Busy`]).
//! A writer stopped in the middle of an update (its partition stopped or restarting) leaves
//! the sequence odd: the reader keeps the previous values until the writer's next complete
//! update. A program that declares a BOOL `{attribute 'shared' := 'valid'}` sees before each
//! cycle whether its read variables are a fresh copy (FALSE before the other project's first
//! update and on a stale cycle).
//!
//! Why a sequence lock rather than double buffering: the writer never waits and never
//! depends on the reader (a partition must not be able to stall another), the layout has one
//! copy of each variable, and a reader on its own core can only be delayed, never see a mix
//! of two updates. Double buffering without a reader acknowledgement (which would give the
//! reader a way to block the writer) can still tear when the writer laps the reader twice
//! during one copy; the sequence check catches exactly that.
//!
//! Memory ordering (the C++/Rust model; on x86 every fence below compiles to nothing but a
//! compiler barrier, the argument is what keeps the compiler and a weaker CPU honest):
//! - the writer: `seq.store(odd, Relaxed)`, `fence(Release)`, data stores (`Relaxed`
//!   atomics), `seq.store(odd + 1, Release)`;
//! - the reader: `s1 = seq.load(Acquire)`, data loads (`Relaxed`), `fence(Acquire)`,
//!   `s2 = seq.load(Relaxed)`, accept iff `s1 == s2` and `s1` even.
//!
//! If the reader's `s1` reads the even store ending update U (release/acquire), every data
//! store of U and before happens-before the reader's loads, so each load returns U's value or
//! a later one. If some load returned a value of a later update V, that store follows V's
//! release fence, which follows V's odd store; the reader's acquire fence after that load
//! then makes V's odd store happen-before the `s2` load, so `s2` is V's odd value or later,
//! never `s1`: the copy is refused. Hence an accepted copy is exactly U. All accesses to the
//! segment are atomic, so a concurrent writer is never a data race in the language's sense.
//! Only the owner writes its area (the configuration maps the segment writable to both, so
//! this is the build's layout plus each runtime keeping to it), which is why the writer may
//! update a word holding several small variables with a relaxed load and store. (The
//! sequence could only come back to `s1` after 2^31 updates during one copy.)

use crate::package::{SharedLayout, SharedVar};
use core::sync::atomic::{AtomicU32, Ordering, fence};
use plc_vm::image::{Image, SharedDirection};

/// Bytes of an area's header (the sequence and a reserved word).
pub const AREA_HEADER: usize = 8;
/// Areas start at multiples of this (a cache line: the two writers never share one).
pub const AREA_ALIGN: u32 = 64;
/// Longest area (header included): the reader's scratch buffer.
pub const MAX_AREA_LEN: usize = 4096;
/// How often a reader tries to take a consistent copy before it keeps the previous values.
pub const MAX_ATTEMPTS: u32 = 4;
/// How long, in pauses, a reader waits in all for an update in progress to end (the
/// sequence is odd) before it keeps the previous values. A writer running on another CPU
/// ends its update within a microsecond; this bounds what a writer stopped in the middle
/// of one (its window ended, it was stopped or restarted) costs the reader: some 256
/// `pause`s, about 10 us on current x86.
pub const MAX_WAIT_PAUSES: u32 = 256;

/// The byte at `offset` of the segment.
fn load_byte(segment: &[AtomicU32], offset: usize) -> u8 {
    let word = segment[offset / 4].load(Ordering::Relaxed);
    (word >> (8 * (offset % 4))) as u8
}

/// Stores the byte at `offset` (only the area's owner writes its words, so the word may be
/// rewritten whole).
fn store_byte(segment: &[AtomicU32], offset: usize, value: u8) {
    let shift = 8 * (offset % 4);
    let word = &segment[offset / 4];
    let old = word.load(Ordering::Relaxed);
    word.store(
        (old & !(0xff << shift)) | (u32::from(value) << shift),
        Ordering::Relaxed,
    );
}

/// Starts an update of the area at `area` (byte offset): makes its sequence odd and returns
/// that odd value for [`end_write`]. A sequence left odd by a writer that died mid-update
/// stays odd until this update ends.
pub fn begin_write(segment: &[AtomicU32], area: usize) -> u32 {
    let sequence = &segment[area / 4];
    let odd = sequence.load(Ordering::Relaxed) | 1;
    sequence.store(odd, Ordering::Relaxed);
    // Orders the odd sequence before every data store of this update.
    fence(Ordering::Release);
    odd
}

/// Stores variable `v`'s bytes from data memory into its place in the area at `area`.
pub fn write_var(segment: &[AtomicU32], area: usize, v: SharedVar, data: &[u8]) {
    let from = v.address as usize;
    for (i, &byte) in data[from..from + v.size as usize].iter().enumerate() {
        store_byte(segment, area + v.offset as usize + i, byte);
    }
}

/// Ends the update begun with `odd`: the next even sequence, published with release order
/// (0 is skipped when the counter wraps: it means "never written").
pub fn end_write(segment: &[AtomicU32], area: usize, odd: u32) {
    segment[area / 4].store(odd.wrapping_add(1).max(2), Ordering::Release);
}

/// Starts a read of the area at `area`: its sequence if no update is in progress (`None`
/// while one is).
pub fn read_begin(segment: &[AtomicU32], area: usize) -> Option<u32> {
    let sequence = segment[area / 4].load(Ordering::Acquire);
    sequence.is_multiple_of(2).then_some(sequence)
}

/// Copies variable `v`'s bytes from the area at `area` into `scratch` (indexed like the
/// area).
pub fn read_var(segment: &[AtomicU32], area: usize, v: SharedVar, scratch: &mut [u8]) {
    let at = v.offset as usize;
    for (i, byte) in scratch[at..at + v.size as usize].iter_mut().enumerate() {
        *byte = load_byte(segment, area + at + i);
    }
}

/// Whether the copy taken since [`read_begin`] returned `sequence` is consistent (no
/// update overlapped it).
pub fn read_validate(segment: &[AtomicU32], area: usize, sequence: u32) -> bool {
    // Orders the data loads before the second sequence load.
    fence(Ordering::Acquire);
    segment[area / 4].load(Ordering::Relaxed) == sequence
}

/// What one copy-in found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fetch {
    /// A consistent copy of the update with this (even) sequence is in data memory.
    Fresh(u32),
    /// The other project has not completed an update yet: the read variables keep their
    /// initial values.
    NotYetWritten,
    /// Every attempt overlapped an update: the read variables keep their previous values.
    Busy,
}

/// Copies this project's written variables from `data` into its area (post-cycle).
pub fn copy_out(segment: &[AtomicU32], layout: &SharedLayout, data: &[u8]) {
    let Some((area, _)) = layout.own else {
        return;
    };
    let area = area as usize;
    let odd = begin_write(segment, area);
    for v in layout.written() {
        write_var(segment, area, v, data);
    }
    end_write(segment, area, odd);
}

/// Copies the other project's variables from its area into `data` (pre-cycle), through
/// `scratch` (at least the area's length), only if a consistent copy is taken within
/// [`MAX_ATTEMPTS`], and sets the program's validity flag, if it has one, to whether it was.
pub fn copy_in(
    segment: &[AtomicU32],
    layout: &SharedLayout,
    data: &mut [u8],
    scratch: &mut [u8],
) -> Fetch {
    let fetch = take(segment, layout, data, scratch);
    if let Some(flag) = layout.valid_flag {
        data[flag as usize] = u8::from(matches!(fetch, Fetch::Fresh(_)));
    }
    fetch
}

/// [`copy_in`] without the flag.
fn take(
    segment: &[AtomicU32],
    layout: &SharedLayout,
    data: &mut [u8],
    scratch: &mut [u8],
) -> Fetch {
    let Some((area, _)) = layout.other else {
        return Fetch::NotYetWritten;
    };
    let area = area as usize;
    let (mut attempts, mut pauses) = (0, 0);
    while attempts < MAX_ATTEMPTS {
        let Some(sequence) = read_begin(segment, area) else {
            if pauses == MAX_WAIT_PAUSES {
                break;
            }
            pauses += 1;
            core::hint::spin_loop();
            continue;
        };
        attempts += 1;
        if sequence == 0 {
            return Fetch::NotYetWritten;
        }
        for v in layout.read() {
            read_var(segment, area, v, scratch);
        }
        if read_validate(segment, area, sequence) {
            for v in layout.read() {
                let (from, to) = (v.offset as usize, v.address as usize);
                data[to..to + v.size as usize]
                    .copy_from_slice(&scratch[from..from + v.size as usize]);
            }
            return Fetch::Fresh(sequence);
        }
    }
    Fetch::Busy
}

/// Counts of what the copy-ins found, and the last sequence taken.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SharedStats {
    /// Cycles that took a new update.
    pub fresh: u64,
    /// Cycles whose copy was consistent but the other project had not published since
    /// (its values were kept: they are still its latest).
    pub unchanged: u64,
    /// Cycles that kept the previous values because every attempt overlapped an update.
    pub stale: u64,
    /// Cycles before the other project's first update.
    pub not_yet: u64,
    /// The sequence of the last update taken.
    pub sequence: u32,
}

impl SharedStats {
    /// Counts one copy-in.
    pub fn record(&mut self, fetch: Fetch) {
        match fetch {
            Fetch::Fresh(s) if s == self.sequence => self.unchanged += 1,
            Fetch::Fresh(s) => {
                self.fresh += 1;
                self.sequence = s;
            }
            Fetch::NotYetWritten => self.not_yet += 1,
            Fetch::Busy => self.stale += 1,
        }
    }
}

/// Why a package's shared layout does not fit its program.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SharedError {
    /// The segment is not where syssw maps shared segments or not a whole number of words,
    /// or an area is longer than [`MAX_AREA_LEN`].
    BadSegment,
    /// A record is not one of the program's shared variables of that direction (address
    /// and size), a shared variable has no record, or the validity flag is not the
    /// program's.
    Mismatch,
}

impl core::fmt::Display for SharedError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadSegment => write!(f, "the shared segment or an area has a bad size"),
            Self::Mismatch => write!(
                f,
                "the shared-globals layout does not match the program's shared variables"
            ),
        }
    }
}

/// Checks that `layout` describes exactly the program's shared variables (each written and
/// read one once, at its data address with its size) and that its areas fit the scratch
/// buffer, so the copies touch nothing else of data memory.
pub fn check(layout: &SharedLayout, image: &Image) -> Result<(), SharedError> {
    let too_long =
        |area: Option<(u32, u32)>| area.is_some_and(|(_, len)| len as usize > MAX_AREA_LEN);
    // Where syssw maps shared segments (not the program, data entry or stack).
    let end = layout
        .segment_address
        .checked_add(u64::from(layout.segment_size));
    let placed = layout.segment_address >= protocol::layout::SHARED_BASE
        && end.is_some_and(|end| end <= protocol::layout::STACK_TOP);
    if !placed
        || !layout.segment_size.is_multiple_of(4)
        || too_long(layout.own)
        || too_long(layout.other)
    {
        return Err(SharedError::BadSegment);
    }
    let flag = image
        .shared_vars()
        .find(|s| s.direction == SharedDirection::Valid)
        .map(|s| s.var.addr);
    if flag != layout.valid_flag {
        return Err(SharedError::Mismatch);
    }
    // The image's shared variables are disjoint (the verifier checks it), so equal counts
    // and a record for each variable make the records exactly the variables.
    for (direction, layout_vars) in [
        (SharedDirection::Write, layout.written()),
        (SharedDirection::Read, layout.read()),
    ] {
        let program = || {
            image
                .shared_vars()
                .filter(move |s| s.direction == direction)
        };
        let matched = program().all(|s| {
            layout_vars
                .clone()
                .any(|v| v.address == s.var.addr && v.size == s.var.size)
        });
        if !matched || program().count() != layout_vars.count() {
            return Err(SharedError::Mismatch);
        }
    }
    Ok(())
}

#[cfg(any(feature = "alloc", test))]
pub use planner::*;

#[cfg(any(feature = "alloc", test))]
mod planner {
    //! [`plan`]: the build-time pairing of two projects' shared globals and the segment
    //! layout.
    use super::*;
    use crate::package::SharedPlan;
    use alloc::format;
    use alloc::string::String;
    use alloc::vec::Vec;

    /// One project sharing the segment: its partition and compiled program.
    pub struct Project<'a> {
        pub partition: &'a str,
        pub image: Image<'a>,
    }

    /// `file:line:col` of a shared declaration (file names as the configuration gives them).
    fn at(image: &Image, s: &plc_vm::image::Shared) -> String {
        let file = image.file_name(s.location.file).unwrap_or("?");
        format!("{file}:{}:{}", s.location.line, s.location.column)
    }

    fn type_name(ty: u8) -> &'static str {
        plc_vm::image::VarType::from_code(ty).map_or("?", |t| t.name())
    }

    /// Lays out segment `segment` (`size` bytes at `address`) for `projects` (in
    /// configuration order) and pairs their variables: each project's package block, or
    /// every problem found (a variable written by two projects, a read variable nobody else
    /// writes or whose type differs from the writer's, areas beyond the segment), each
    /// naming the declaration(s) as `file:line:col`.
    pub fn plan(
        segment: &str,
        address: u64,
        size: u32,
        projects: &[Project],
    ) -> Result<Vec<SharedPlan>, Vec<String>> {
        let mut errors = Vec::new();
        // Own areas: (offset, length) and each written variable's offset in it.
        let mut areas: Vec<Option<(u32, u32)>> = Vec::new();
        let mut offsets: Vec<Vec<u32>> = Vec::new();
        let mut cursor = 0u32;
        for p in projects {
            let mut end = AREA_HEADER as u32;
            let mut own = Vec::new();
            for s in p
                .image
                .shared_vars()
                .filter(|s| s.direction == SharedDirection::Write)
            {
                let offset = end.next_multiple_of(s.var.size);
                own.push(offset);
                end = offset + s.var.size;
            }
            let len = end.next_multiple_of(8);
            if own.is_empty() {
                areas.push(None);
            } else {
                let offset = cursor.next_multiple_of(AREA_ALIGN);
                areas.push(Some((offset, len)));
                cursor = offset + len;
                if len as usize > MAX_AREA_LEN {
                    errors.push(format!(
                        "partition {}: its shared variables need {len} bytes, more than an area's {MAX_AREA_LEN}",
                        p.partition
                    ));
                }
            }
            offsets.push(own);
        }
        if cursor > size {
            errors.push(format!(
                "shared memory segment `{segment}` has {size} bytes, but the shared variables of {} need {cursor}",
                projects.iter().map(|p| p.partition).collect::<Vec<_>>().join(" and ")
            ));
        }
        // A variable written by two projects.
        for (i, p) in projects.iter().enumerate() {
            for s in p
                .image
                .shared_vars()
                .filter(|s| s.direction == SharedDirection::Write)
            {
                for q in &projects[..i] {
                    let twin = q.image.shared_vars().find(|o| {
                        o.direction == SharedDirection::Write
                            && o.var.name.eq_ignore_ascii_case(s.var.name)
                    });
                    if let Some(o) = twin {
                        errors.push(format!(
                            "{}: shared variable `{}` is written by partition {} and by partition {} ({}): one project writes it, the other reads it",
                            at(&p.image, &s),
                            s.var.name,
                            p.partition,
                            q.partition,
                            at(&q.image, &o)
                        ));
                    }
                }
            }
        }
        let mut plans = Vec::new();
        for (i, p) in projects.iter().enumerate() {
            let mut plan = SharedPlan {
                segment_address: address,
                segment_size: size,
                own: areas[i],
                other: None,
                valid_flag: None,
                written: Vec::new(),
                read: Vec::new(),
            };
            let written = p
                .image
                .shared_vars()
                .filter(|s| s.direction == SharedDirection::Write);
            for (s, &offset) in written.zip(&offsets[i]) {
                plan.written.push(SharedVar {
                    address: s.var.addr,
                    offset,
                    size: s.var.size,
                });
            }
            for s in p
                .image
                .shared_vars()
                .filter(|s| s.direction == SharedDirection::Read)
            {
                let writer = projects
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .find_map(|(j, q)| {
                        q.image
                            .shared_vars()
                            .filter(|o| o.direction == SharedDirection::Write)
                            .zip(&offsets[j])
                            .find(|(o, _)| o.var.name.eq_ignore_ascii_case(s.var.name))
                            .map(|(o, &offset)| (j, q, o, offset))
                    });
                let Some((j, q, o, offset)) = writer else {
                    errors.push(format!(
                        "{}: shared variable `{}` is read by partition {} but no other project sharing segment `{segment}` writes it (declare it with {{attribute 'shared' := 'write'}} there)",
                        at(&p.image, &s),
                        s.var.name,
                        p.partition
                    ));
                    continue;
                };
                if o.var.ty != s.var.ty || o.var.size != s.var.size {
                    errors.push(format!(
                        "{}: shared variable `{}` is read as {} by partition {}, but partition {} writes it as {} ({})",
                        at(&p.image, &s),
                        s.var.name,
                        type_name(s.var.ty),
                        p.partition,
                        q.partition,
                        type_name(o.var.ty),
                        at(&q.image, &o)
                    ));
                    continue;
                }
                if plan.other.is_some_and(|a| Some(a) != areas[j]) {
                    errors.push(format!(
                        "{}: partition {} reads from more than one other project",
                        at(&p.image, &s),
                        p.partition
                    ));
                    continue;
                }
                plan.other = areas[j];
                plan.read.push(SharedVar {
                    address: s.var.addr,
                    offset,
                    size: s.var.size,
                });
            }
            if let Some(flag) = p
                .image
                .shared_vars()
                .find(|s| s.direction == SharedDirection::Valid)
            {
                if plan.read.is_empty() {
                    errors.push(format!(
                        "{}: partition {} has a validity flag `{}` but reads no shared variable",
                        at(&p.image, &flag),
                        p.partition,
                        flag.var.name
                    ));
                }
                plan.valid_flag = Some(flag.var.addr);
            }
            plans.push(plan);
        }
        if errors.is_empty() {
            Ok(plans)
        } else {
            Err(errors)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::package::{SharedPlan, SharedVar};
    use alloc::string::{String, ToString};
    use alloc::vec::Vec;
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;

    fn compile(file: &str, source: &str) -> Vec<u8> {
        let files = [(file.to_string(), source.to_string())];
        plc_compiler::compile(&files, &plc_compiler::Options::default())
            .map(|(c, _)| c.image)
            .unwrap_or_else(|(d, map)| {
                panic!("{}", plc_compiler::diagnostics::render(&map, &d, false))
            })
    }

    const WRITER: &str = "VAR_GLOBAL\n  {attribute 'shared' := 'write'}\n  counter : DINT;\n  {attribute 'shared' := 'write'}\n  flag : BOOL;\n  {attribute 'shared' := 'write'}\n  level : LREAL;\nEND_VAR\nPROGRAM Main\ncounter := counter + 1;\nEND_PROGRAM\n";
    const READER: &str = "VAR_GLOBAL\n  {attribute 'shared' := 'read'}\n  level : LREAL := 7.0;\n  {attribute 'shared' := 'read'}\n  COUNTER : DINT := -1;\n  {attribute 'shared' := 'valid'}\n  fresh : BOOL := TRUE;\nEND_VAR\nPROGRAM Main\nEND_PROGRAM\n";

    fn plan_of(sources: &[(&str, &str, &str)], size: u32) -> Result<Vec<SharedPlan>, Vec<String>> {
        let images: Vec<Vec<u8>> = sources.iter().map(|(_, f, s)| compile(f, s)).collect();
        let projects: Vec<Project> = sources
            .iter()
            .zip(&images)
            .map(|((partition, _, _), image)| Project {
                partition,
                image: Image::parse(image).unwrap(),
            })
            .collect();
        plan("link", 0x6000_0000_0000, size, &projects)
    }

    /// Both sides of a paired writer and reader: (plan, image) each.
    fn pair() -> [(SharedPlan, Vec<u8>); 2] {
        let plans = plan_of(&[("a", "w.st", WRITER), ("b", "r.st", READER)], 4096).unwrap();
        let mut plans = plans.into_iter();
        [
            (plans.next().unwrap(), compile("w.st", WRITER)),
            (plans.next().unwrap(), compile("r.st", READER)),
        ]
    }

    fn layout(plan: &SharedPlan) -> Vec<u8> {
        plan.encode()
    }

    fn parse(block: &[u8]) -> SharedLayout<'_> {
        let bytes = crate::package::encode(&[], b"", &[], None, &[], None, &[]);
        // Parse the block through a whole package so the real checks run.
        let mut package = bytes;
        let at = package.len() as u32;
        package[40..44].copy_from_slice(&at.to_le_bytes());
        package[44..48].copy_from_slice(&(block.len() as u32).to_le_bytes());
        package.extend_from_slice(block);
        let leaked: &'static [u8] = Vec::leak(package);
        crate::package::Package::parse(leaked)
            .unwrap()
            .shared()
            .unwrap()
    }

    fn segment(words: usize) -> Vec<AtomicU32> {
        (0..words).map(|_| AtomicU32::new(0)).collect()
    }

    /// Data memory of a program with its initial values.
    fn data_of(image: &[u8]) -> Vec<u8> {
        let image = Image::parse(image).unwrap();
        let mut data = alloc::vec![0u8; image.data_size() as usize];
        data[..image.init_data().len()].copy_from_slice(image.init_data());
        data
    }

    fn var(image: &[u8], data: &[u8], name: &str) -> Vec<u8> {
        let v = Image::parse(image).unwrap().find_var(name).unwrap();
        data[v.addr as usize..(v.addr + v.size) as usize].to_vec()
    }

    fn set(image: &[u8], data: &mut [u8], name: &str, bytes: &[u8]) {
        let v = Image::parse(image).unwrap().find_var(name).unwrap();
        data[v.addr as usize..(v.addr + v.size) as usize].copy_from_slice(bytes);
    }

    #[test]
    fn the_plan_lays_out_areas_and_pairs_variables_by_name() {
        let [(w, _), (r, _)] = pair();
        // The writer's area: header, counter at 8, flag at 12, level at 16; 24 bytes.
        assert_eq!(w.own, Some((0, 24)));
        assert_eq!(
            w.written
                .iter()
                .map(|v| (v.offset, v.size))
                .collect::<Vec<_>>(),
            [(8, 4), (12, 1), (16, 8)]
        );
        assert_eq!((w.other, w.read.len()), (None, 0));
        // The reader reads from it (names are case-insensitive), in its own order.
        assert_eq!((r.own, r.other), (None, Some((0, 24))));
        assert_eq!(
            r.read
                .iter()
                .map(|v| (v.offset, v.size))
                .collect::<Vec<_>>(),
            [(16, 8), (8, 4)]
        );
        // Two writers: the second area starts on the next cache line.
        let plans = plan_of(
            &[("a", "w.st", WRITER), ("b", "x.st", "VAR_GLOBAL {attribute 'shared' := 'write'} x : INT; END_VAR PROGRAM P END_PROGRAM")],
            4096,
        )
        .unwrap();
        assert_eq!(plans[1].own, Some((64, 16)));
    }

    #[test]
    fn the_plan_refuses_bad_pairings_naming_the_declarations() {
        let errors =
            |sources: &[(&str, &str, &str)], size| plan_of(sources, size).unwrap_err().join("\n");
        let twice = errors(&[("a", "w.st", WRITER), ("b", "v.st", WRITER)], 4096);
        assert!(
            twice.contains("v.st:3:3: shared variable `counter` is written by partition b and by partition a (w.st:3:3)"),
            "{twice}"
        );
        let nobody = errors(&[("b", "r.st", READER)], 4096);
        assert!(
            nobody.contains(
                "r.st:3:3: shared variable `level` is read by partition b but no other project"
            ),
            "{nobody}"
        );
        let other_type =
            "VAR_GLOBAL {attribute 'shared' := 'read'} level : REAL; END_VAR PROGRAM P END_PROGRAM";
        let mismatch = errors(&[("a", "w.st", WRITER), ("b", "t.st", other_type)], 4096);
        assert!(
            mismatch.contains("t.st:1:43: shared variable `level` is read as REAL by partition b, but partition a writes it as LREAL (w.st:7:3)"),
            "{mismatch}"
        );
        let lonely =
            "VAR_GLOBAL {attribute 'shared' := 'valid'} ok : BOOL; END_VAR PROGRAM P END_PROGRAM";
        let flag = errors(&[("a", "w.st", WRITER), ("c", "f.st", lonely)], 4096);
        assert!(
            flag.contains(
                "f.st:1:44: partition c has a validity flag `ok` but reads no shared variable"
            ),
            "{flag}"
        );
        let small = errors(&[("a", "w.st", WRITER), ("b", "r.st", READER)], 16);
        assert!(
            small.contains(
                "segment `link` has 16 bytes, but the shared variables of a and b need 24"
            ),
            "{small}"
        );
    }

    #[test]
    fn copy_out_then_copy_in_moves_the_values() {
        let [(w, wimage), (r, rimage)] = pair();
        let (wblock, rblock) = (layout(&w), layout(&r));
        let (wl, rl) = (parse(&wblock), parse(&rblock));
        check(&wl, &Image::parse(&wimage).unwrap()).unwrap();
        check(&rl, &Image::parse(&rimage).unwrap()).unwrap();
        let seg = segment(1024);
        let mut wdata = data_of(&wimage);
        let mut rdata = data_of(&rimage);
        let mut scratch = [0u8; MAX_AREA_LEN];
        // Before the first update the reader keeps its initial values, not valid ones.
        assert_eq!(var(&rimage, &rdata, "fresh"), [1]);
        assert_eq!(
            copy_in(&seg, &rl, &mut rdata, &mut scratch),
            Fetch::NotYetWritten
        );
        assert_eq!(var(&rimage, &rdata, "level"), 7.0f64.to_le_bytes());
        assert_eq!(var(&rimage, &rdata, "fresh"), [0]);
        set(&wimage, &mut wdata, "counter", &41i32.to_le_bytes());
        set(&wimage, &mut wdata, "level", &2.5f64.to_le_bytes());
        copy_out(&seg, &wl, &wdata);
        assert_eq!(
            copy_in(&seg, &rl, &mut rdata, &mut scratch),
            Fetch::Fresh(2)
        );
        assert_eq!(var(&rimage, &rdata, "COUNTER"), 41i32.to_le_bytes());
        assert_eq!(var(&rimage, &rdata, "level"), 2.5f64.to_le_bytes());
        assert_eq!(var(&rimage, &rdata, "fresh"), [1]);
        copy_out(&seg, &wl, &wdata);
        assert_eq!(
            copy_in(&seg, &rl, &mut rdata, &mut scratch),
            Fetch::Fresh(4)
        );
        // The layout and the program must agree.
        assert_eq!(
            check(&rl, &Image::parse(&wimage).unwrap()),
            Err(SharedError::Mismatch)
        );
        assert_eq!(
            check(&wl, &Image::parse(&rimage).unwrap()),
            Err(SharedError::Mismatch)
        );
    }

    #[test]
    fn a_reader_never_takes_an_update_in_progress() {
        let [(w, wimage), (r, rimage)] = pair();
        let (wblock, rblock) = (layout(&w), layout(&r));
        let (wl, rl) = (parse(&wblock), parse(&rblock));
        let seg = segment(1024);
        let mut wdata = data_of(&wimage);
        let mut rdata = data_of(&rimage);
        let mut scratch = [0u8; MAX_AREA_LEN];
        set(&wimage, &mut wdata, "counter", &1i32.to_le_bytes());
        set(&wimage, &mut wdata, "level", &1.0f64.to_le_bytes());
        copy_out(&seg, &wl, &wdata);
        assert_eq!(
            copy_in(&seg, &rl, &mut rdata, &mut scratch),
            Fetch::Fresh(2)
        );
        // The writer stops half-way (e.g. its window ends): counter written, level not.
        set(&wimage, &mut wdata, "counter", &2i32.to_le_bytes());
        set(&wimage, &mut wdata, "level", &2.0f64.to_le_bytes());
        let odd = begin_write(&seg, 0);
        write_var(&seg, 0, wl.written().next().unwrap(), &wdata);
        assert_eq!(copy_in(&seg, &rl, &mut rdata, &mut scratch), Fetch::Busy);
        assert_eq!(
            var(&rimage, &rdata, "fresh"),
            [0],
            "stale values are flagged"
        );
        assert_eq!(
            var(&rimage, &rdata, "COUNTER"),
            1i32.to_le_bytes(),
            "previous values kept"
        );
        assert_eq!(var(&rimage, &rdata, "level"), 1.0f64.to_le_bytes());
        for v in wl.written().skip(1) {
            write_var(&seg, 0, v, &wdata);
        }
        end_write(&seg, 0, odd);
        assert_eq!(
            copy_in(&seg, &rl, &mut rdata, &mut scratch),
            Fetch::Fresh(4)
        );
        assert_eq!(var(&rimage, &rdata, "COUNTER"), 2i32.to_le_bytes());
        assert_eq!(var(&rimage, &rdata, "level"), 2.0f64.to_le_bytes());
    }

    #[test]
    fn an_update_during_the_copy_is_detected() {
        let [(w, wimage), (r, _)] = pair();
        let (wblock, rblock) = (layout(&w), layout(&r));
        let (wl, rl) = (parse(&wblock), parse(&rblock));
        let seg = segment(1024);
        let mut wdata = data_of(&wimage);
        copy_out(&seg, &wl, &wdata);
        let mut scratch = [0u8; MAX_AREA_LEN];
        // The reader copies the first variable, then a whole update lands, then it copies
        // the second: a mix of two updates, which the sequence check refuses.
        let sequence = read_begin(&seg, 0).unwrap();
        let mut vars = rl.read();
        read_var(&seg, 0, vars.next().unwrap(), &mut scratch);
        set(&wimage, &mut wdata, "counter", &9i32.to_le_bytes());
        copy_out(&seg, &wl, &wdata);
        read_var(&seg, 0, vars.next().unwrap(), &mut scratch);
        assert!(!read_validate(&seg, 0, sequence));
        // Without the update it validates.
        let sequence = read_begin(&seg, 0).unwrap();
        for v in rl.read() {
            read_var(&seg, 0, v, &mut scratch);
        }
        assert!(read_validate(&seg, 0, sequence));
    }

    #[test]
    fn the_sequence_never_returns_to_zero() {
        let seg = segment(2);
        seg[0].store(u32::MAX - 1, Ordering::Relaxed);
        let odd = begin_write(&seg, 0);
        assert_eq!(odd, u32::MAX);
        end_write(&seg, 0, odd);
        assert_eq!(read_begin(&seg, 0), Some(2));
        // A sequence left odd by a writer that died mid-update: the next update ends it.
        seg[0].store(7, Ordering::Relaxed);
        assert_eq!(read_begin(&seg, 0), None);
        let odd = begin_write(&seg, 0);
        end_write(&seg, 0, odd);
        assert_eq!(read_begin(&seg, 0), Some(8));
    }

    #[test]
    fn stats_tell_fresh_from_unchanged_and_stale() {
        let mut stats = SharedStats::default();
        for f in [
            Fetch::NotYetWritten,
            Fetch::Fresh(2),
            Fetch::Fresh(2),
            Fetch::Busy,
            Fetch::Fresh(4),
        ] {
            stats.record(f);
        }
        assert_eq!(
            stats,
            SharedStats {
                fresh: 2,
                unchanged: 1,
                stale: 1,
                not_yet: 1,
                sequence: 4
            }
        );
    }

    /// A writer and a reader on two threads (two cores where the host has them), 10^6
    /// updates: every record the reader takes is consistent (its checksum matches) and
    /// never older than the one before, whatever the interleaving.
    #[test]
    fn concurrent_writer_and_reader_never_tear() {
        const UPDATES: u64 = 1_000_000;
        let vars = |n: u32| -> Vec<SharedVar> {
            (0..n)
                .map(|i| SharedVar {
                    address: 8 * i,
                    offset: 8 + 8 * i,
                    size: 8,
                })
                .collect()
        };
        let writer = SharedPlan {
            segment_address: 0x1000,
            segment_size: 4096,
            own: Some((0, 8 + 8 * 6)),
            written: vars(6),
            ..SharedPlan::default()
        };
        let reader = SharedPlan {
            segment_address: 0x1000,
            segment_size: 4096,
            other: Some((0, 8 + 8 * 6)),
            read: vars(6),
            ..SharedPlan::default()
        };
        let seg: Arc<Vec<AtomicU32>> = Arc::new(segment(1024));
        let done = Arc::new(AtomicBool::new(false));
        let (wblock, rblock) = (writer.encode(), reader.encode());
        let writer_thread = {
            let (seg, done) = (seg.clone(), done.clone());
            std::thread::spawn(move || {
                let layout = parse(&wblock);
                let mut data = [0u8; 48];
                for counter in 1..=UPDATES {
                    // The counter, four values derived from it, and a checksum over them.
                    let values = [counter, counter * 3, !counter, counter.rotate_left(17)];
                    let sum = values
                        .iter()
                        .fold(counter, |a, v| a.wrapping_mul(31).wrapping_add(*v));
                    let record = [counter, values[1], values[2], values[3], values[0], sum];
                    for (i, v) in record.iter().enumerate() {
                        data[8 * i..8 * i + 8].copy_from_slice(&v.to_le_bytes());
                    }
                    copy_out(&seg, &layout, &data);
                }
                done.store(true, Ordering::Release);
            })
        };
        let layout = parse(&rblock);
        let mut data = [0u8; 48];
        let mut scratch = [0u8; MAX_AREA_LEN];
        let (mut torn, mut fresh, mut last) = (0u64, 0u64, 0u64);
        let word = |d: &[u8], i: usize| u64::from_le_bytes(d[8 * i..8 * i + 8].try_into().unwrap());
        while !done.load(Ordering::Acquire) || fresh == 0 {
            if let Fetch::Fresh(_) = copy_in(&seg, &layout, &mut data, &mut scratch) {
                let counter = word(&data, 0);
                let values = [
                    word(&data, 4),
                    word(&data, 1),
                    word(&data, 2),
                    word(&data, 3),
                ];
                let sum = values
                    .iter()
                    .fold(counter, |a, v| a.wrapping_mul(31).wrapping_add(*v));
                if sum != word(&data, 5) || values[1] != counter * 3 || counter < last {
                    torn += 1;
                }
                last = counter;
                fresh += 1;
            }
        }
        writer_thread.join().unwrap();
        assert_eq!(torn, 0, "torn records taken");
        assert!(fresh > 0);
        // After the writer's last update the reader takes exactly it.
        assert_eq!(
            copy_in(&seg, &layout, &mut data, &mut scratch),
            Fetch::Fresh(2 * UPDATES as u32)
        );
        assert_eq!(word(&data, 0), UPDATES);
    }
}
