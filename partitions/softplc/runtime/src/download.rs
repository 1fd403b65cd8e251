//! Online download (protocol in `plc-online`): a new program arrives in chunks, is checked
//! like the configured program at start, and replaces the running one between two scan
//! cycles, taking over what it can by name.
//!
//! The pieces, all pure logic the partition program (`main.rs`) glues together:
//! - [`check_program`]: the checks every program passes before it runs, the configured one
//!   at start and a downloaded one at DOWNLOAD_COMMIT: it parses as an image, fits the
//!   verifier's scratch and the data memory, passes the verifier, and its tasks fit the
//!   partition's period ([`Schedule::new`]); [`fit_configuration`]: what ties it to the
//!   partition's configuration (the package) fits too — every configured task deadline
//!   names one of its tasks, and its shared globals are the ones the build laid out.
//! - [`Download`]: assembles the chunks in a buffer the partition owns (in order, within
//!   the announced size) and checks size and CRC-32 at the commit.
//! - [`take_over`]: the new program must have the running one's tasks (name, kind, interval,
//!   priority: each is an APEX process created at the partition's start); what refers to
//!   the running program by data address, re-resolved by name for the new one — the safe values (a `%Q` variable of the same name, type and
//!   width), the forces (a variable of the same name and type) and the watch list (names
//!   that must exist) — or the reason the new program cannot take over.
//! - [`hand_over`]: at the swap, the new machine gets the RETAIN values of the old data
//!   ([`carry_retain`]: by name and type; a STRING or WSTRING whose capacity changed keeps
//!   its text cut to fit; a reference keeps the new program's initial value) and the forces.
//! - [`Running`]: which program runs from which of the partition's two image buffers and
//!   two data memories, so that a download never overwrites the running program or its
//!   data, and the old ones stay intact until the handover.
//!
//! Nothing here touches the running program: a refused or half download leaves it as it
//! was. The process image's port map is in `%I`/`%Q` byte offsets, which a new program's
//! located variables address directly, so it needs no re-resolution.

use crate::package::{Package, PackageError, SafeValue};
use crate::scan::{PlanError, SafeValues, Schedule, carry_retain, has_task};
use crate::shared::SharedError;
use plc_online::Status;
use plc_vm::image::{Image, ImageError, Var, VarType};
use plc_vm::located::Area;
use plc_vm::verify::{VerifiedImage, VerifyError};
use plc_vm::vm::{MAX_FORCES, Machine};

/// A variable name kept for a message (cut at [`VarName::MAX`] bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VarName {
    bytes: [u8; VarName::MAX],
    len: u8,
}

impl VarName {
    pub const MAX: usize = 64;

    fn of(name: &str) -> Self {
        let mut end = name.len().min(Self::MAX);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0; Self::MAX];
        bytes[..end].copy_from_slice(&name.as_bytes()[..end]);
        Self {
            bytes,
            len: end as u8,
        }
    }

    pub fn as_str(&self) -> &str {
        core::str::from_utf8(&self.bytes[..self.len as usize]).unwrap_or("?")
    }
}

/// Why a program may not run: the configured one at start, or a downloaded one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    Package(PackageError),
    Image(ImageError),
    /// Code bytes, and the most the verifier's scratch allows.
    CodeTooLarge(usize, usize),
    Verifier(VerifyError),
    /// Data bytes, and the partition's data memory.
    DataTooLarge(u32, usize),
    Tasks(PlanError),
    /// A configured safe value's `%Q` variable is not a located output of the same type
    /// and width in the new program.
    SafeValue(VarName),
    /// A forced variable is not in the new program with the same type.
    Forced(VarName),
    /// A watch-list name is not a variable of the new program.
    Watch(VarName),
    /// A downloaded program's task differs from the running program's (each task is an
    /// APEX process created at the partition's start).
    TaskChanged(VarName),
    /// A configured task deadline (`plc.deadline`) names no task of the program.
    Deadline(VarName),
    /// The shared globals the build laid out (`plc.shared`) are not the program's.
    Shared(SharedError),
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Refusal::Package(e) => write!(f, "package: {e}"),
            Refusal::Image(e) => write!(f, "bytecode image: {e}"),
            Refusal::CodeTooLarge(n, max) => write!(f, "code of {n} bytes exceeds {max} bytes"),
            Refusal::Verifier(e) => write!(f, "bytecode rejected by the verifier: {e}"),
            Refusal::DataTooLarge(n, max) => write!(f, "data memory of {n} bytes exceeds {max}"),
            Refusal::Tasks(e) => write!(f, "tasks: {e}"),
            Refusal::TaskChanged(n) => write!(
                f,
                "task `{}` is not the same in the new program (name, kind, interval and priority must stay: the partition runs one process per task; change tasks with the configuration)",
                n.as_str()
            ),
            Refusal::SafeValue(n) => write!(
                f,
                "`{}` has a configured safe value but is no located %Q variable of the same type in the new program",
                n.as_str()
            ),
            Refusal::Forced(n) => write!(
                f,
                "`{}` is forced but has no variable of the same type in the new program (unforce it first)",
                n.as_str()
            ),
            Refusal::Watch(n) => write!(
                f,
                "`{}` is on the watch list but not a variable of the new program",
                n.as_str()
            ),
            Refusal::Deadline(n) => write!(
                f,
                "plc.deadline names `{}`, which is not a task of the program",
                n.as_str()
            ),
            Refusal::Shared(e) => write!(f, "shared globals: {e}"),
        }
    }
}

/// The checks a program passes before it runs (see the module documentation), with the
/// verifier's `scratch` (two cells per code byte), `max_data` bytes of data memory and a
/// partition released every `period_ns`.
pub fn check_program<'a>(
    bytes: &'a [u8],
    scratch: &mut [u32],
    max_data: usize,
    period_ns: u64,
) -> Result<(VerifiedImage<'a>, Schedule), Refusal> {
    let image = Image::parse(bytes).map_err(Refusal::Image)?;
    let code = image.code().len();
    let room = scratch.len();
    let scratch = scratch
        .get_mut(..2 * code)
        .ok_or(Refusal::CodeTooLarge(code, room / 2))?;
    let verified =
        plc_vm::verify::verify_with_scratch(&image, scratch).map_err(Refusal::Verifier)?;
    if image.data_size() as usize > max_data {
        return Err(Refusal::DataTooLarge(image.data_size(), max_data));
    }
    let schedule = Schedule::new(&image, period_ns).map_err(Refusal::Tasks)?;
    Ok((verified, schedule))
}

/// The checks that tie a checked program to its partition's configuration (see the module
/// documentation); its schedule with the configured task deadlines.
pub fn fit_configuration(
    image: &Image,
    schedule: Schedule,
    package: &Package,
) -> Result<Schedule, Refusal> {
    if let Some(d) = package.deadlines().find(|d| !has_task(image, d.task)) {
        return Err(Refusal::Deadline(VarName::of(d.task)));
    }
    if let Some(layout) = package.shared() {
        crate::shared::check(&layout, image).map_err(Refusal::Shared)?;
    }
    Ok(schedule.with_deadlines(image, package))
}

/// A download in progress: what BEGIN announced and how far the chunks got.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Download {
    size: u32,
    crc32: u32,
    received: u32,
    open: bool,
}

impl Download {
    pub const fn new() -> Self {
        Self {
            size: 0,
            crc32: 0,
            received: 0,
            open: false,
        }
    }

    /// DOWNLOAD_BEGIN into a buffer of `capacity` bytes: drops any unfinished download.
    pub fn begin(&mut self, size: u32, crc32: u32, capacity: usize) -> Result<(), Status> {
        *self = Self::new();
        if size == 0 {
            return Err(Status::Malformed);
        }
        if size as usize > capacity {
            return Err(Status::TooLarge);
        }
        *self = Self {
            size,
            crc32,
            received: 0,
            open: true,
        };
        Ok(())
    }

    /// DOWNLOAD_CHUNK: `bytes` at `offset`, which must be where the previous chunk ended
    /// (a repeated or skipped chunk is BAD_OFFSET and changes nothing; the download stays
    /// open so the client can go on from the right offset).
    pub fn chunk(&mut self, buffer: &mut [u8], offset: u32, bytes: &[u8]) -> Result<(), Status> {
        if !self.open {
            return Err(Status::NoDownload);
        }
        let end = (offset as usize).checked_add(bytes.len());
        let fits = end.is_some_and(|end| end <= self.size as usize);
        let slot = end.and_then(|end| buffer.get_mut(offset as usize..end));
        match slot {
            Some(slot) if offset == self.received && fits => {
                slot.copy_from_slice(bytes);
                self.received += bytes.len() as u32;
                Ok(())
            }
            _ => Err(Status::BadOffset),
        }
    }

    /// DOWNLOAD_COMMIT: the assembled image if every byte arrived and its CRC-32 is the
    /// announced one. A checksum mismatch ends the download; an incomplete one stays open.
    pub fn finish<'b>(&mut self, buffer: &'b [u8]) -> Result<&'b [u8], Status> {
        if !self.open {
            return Err(Status::NoDownload);
        }
        if self.received != self.size {
            return Err(Status::Incomplete);
        }
        self.open = false;
        let image = buffer.get(..self.size as usize).ok_or(Status::Incomplete)?;
        if plc_online::crc32(image) != self.crc32 {
            return Err(Status::ChecksumMismatch);
        }
        Ok(image)
    }

    /// Whether a download is in progress.
    pub fn is_open(&self) -> bool {
        self.open
    }
}

/// A force carried to the new program: its variable there and the forced bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct CarriedForce {
    var: usize,
    bytes: [u8; 8],
    len: u8,
}

/// What a downloaded program takes over from the running one (see [`take_over`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Takeover {
    /// The safe values, at the new program's addresses.
    pub safe: SafeValues,
    forces: [Option<CarriedForce>; MAX_FORCES],
}

/// The first variable of `image` at data address `addr` that `keep` accepts.
fn var_at<'a>(image: &Image<'a>, addr: u32, keep: impl Fn(&Var) -> bool) -> Option<Var<'a>> {
    (0..image.var_count())
        .filter_map(|i| image.var(i))
        .find(|v| v.addr == addr && keep(v))
}

/// The located `%Q` variable of `image` at `addr`, with its width in bytes.
fn output_at(image: &Image, addr: u32) -> Option<u8> {
    image
        .located_vars()
        .find(|l| l.address == addr && l.location.area == Area::Output)
        .map(|l| l.location.width.bytes() as u8)
}

/// Re-resolves by name, for program `new`, what refers to the running program `old` by
/// data address: its safe values `safe`, the forced variables `forced` (address and forced
/// bytes, [`Machine::forced`]) and the names on `watch`. Refuses with the first name the
/// new program does not have (with the same type; for a safe value, as a located `%Q`
/// variable of the same width).
pub fn take_over<'f, 'w>(
    old: &Image,
    new: &Image,
    safe: &SafeValues,
    forced: impl Iterator<Item = (u32, &'f [u8])>,
    watch: impl Iterator<Item = &'w str>,
) -> Result<Takeover, Refusal> {
    for i in 0..old.task_count().max(new.task_count()) {
        let same = match (old.task(i), new.task(i)) {
            (Some(a), Some(b)) => {
                (a.name, a.kind, a.priority, a.interval_ns)
                    == (b.name, b.kind, b.priority, b.interval_ns)
            }
            _ => false,
        };
        if !same {
            let name = old.task(i).or(new.task(i)).map_or("?", |t| t.name);
            return Err(Refusal::TaskChanged(VarName::of(name)));
        }
    }
    let mut takeover = Takeover {
        safe: SafeValues::new(),
        forces: [None; MAX_FORCES],
    };
    for s in safe.iter() {
        let Some(was) = var_at(old, s.address, |v| output_at(old, v.addr).is_some()) else {
            // Not a %Q variable of the running program either: nothing it applies to.
            continue;
        };
        let moved = new
            .find_var(was.name)
            .filter(|v| v.ty == was.ty && output_at(new, v.addr) == Some(s.width));
        let Some(now) = moved else {
            return Err(Refusal::SafeValue(VarName::of(was.name)));
        };
        takeover.safe.push(SafeValue {
            address: now.addr,
            ..s
        });
    }
    for (slot, (addr, bytes)) in takeover.forces.iter_mut().zip(forced) {
        let scalar = |v: &Var| {
            VarType::from_code(v.ty)
                .and_then(VarType::mem_type)
                .is_some_and(|m| m.width() == bytes.len())
        };
        let Some(was) = var_at(old, addr, scalar) else {
            continue;
        };
        let index = (0..new.var_count()).find(|&i| {
            new.var(i)
                .is_some_and(|v| v.name == was.name && v.ty == was.ty)
        });
        let Some(var) = index else {
            return Err(Refusal::Forced(VarName::of(was.name)));
        };
        let mut cell = [0u8; 8];
        let len = bytes.len().min(8);
        cell[..len].copy_from_slice(&bytes[..len]);
        *slot = Some(CarriedForce {
            var,
            bytes: cell,
            len: len as u8,
        });
    }
    check_watch(new, watch)?;
    Ok(takeover)
}

/// Refuses program `new` if a name on `watch` (the configured watch list) is not one of
/// its variables: a download, and a boot project saved with another configuration.
pub fn check_watch<'w>(
    new: &Image,
    mut watch: impl Iterator<Item = &'w str>,
) -> Result<(), Refusal> {
    match watch.find(|name| new.find_var(name).is_none()) {
        Some(missing) => Err(Refusal::Watch(VarName::of(missing))),
        None => Ok(()),
    }
}

/// Starts the new program's machine `new` (just created, its data initialised) from the
/// old program's last data: its RETAIN variables by name and type, and the forces the
/// takeover carries. Returns how many RETAIN variables were kept.
pub fn hand_over(takeover: &Takeover, old: &Image, old_data: &[u8], new: &mut Machine) -> usize {
    let image = *new.image();
    let kept = carry_retain(old, old_data, &image, new.data_mut());
    for f in takeover.forces.iter().flatten() {
        if let Some(var) = image.var(f.var) {
            // Resolved against this image with the same type and width: cannot fail.
            let _ = new.force_bytes(var.name, &f.bytes[..f.len as usize]);
        }
    }
    kept
}

/// A program the partition runs: the configured one (in its package) or a downloaded one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Program {
    Configured,
    /// In image buffer `buffer` (0 or 1), `len` bytes.
    Downloaded {
        buffer: usize,
        len: usize,
    },
}

/// Which program runs and in which of the two data memories (0 or 1); the partition keeps
/// it over a warm restart to carry the RETAIN values of whatever ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Running {
    pub program: Program,
    pub data: usize,
}

impl Running {
    /// After a cold start: the configured program in data memory 0.
    pub const COLD: Running = Running {
        program: Program::Configured,
        data: 0,
    };

    /// After a warm start, when `was` ran: the configured program in the other data memory
    /// (`was`'s keeps the values to carry).
    pub fn warm_start(was: Running) -> Running {
        Running {
            program: Program::Configured,
            data: 1 - was.data.min(1),
        }
    }

    /// The image buffer a download is assembled in while this program runs, `previous`
    /// having run before it: never this program's, and while the configured program runs
    /// after a downloaded one, that one's (its bytes are needed until the handover, and a
    /// download may only begin after it).
    pub fn staging(self, previous: Option<Running>) -> usize {
        match (self.program, previous.map(|p| p.program)) {
            (Program::Downloaded { buffer, .. }, _) => 1 - buffer.min(1),
            (Program::Configured, Some(Program::Downloaded { buffer, .. })) => buffer.min(1),
            (Program::Configured, _) => 0,
        }
    }

    /// The image buffer a start loads the boot project into, `was` having run before a warm
    /// start (`None`: a cold start): never the one holding `was`'s program, whose RETAIN
    /// values are carried over from it.
    pub fn boot_buffer(was: Option<Running>) -> usize {
        match was.map(|w| w.program) {
            Some(Program::Downloaded { buffer, .. }) => 1 - buffer.min(1),
            _ => 0,
        }
    }

    /// What runs when this start (cold: [`Running::COLD`], warm: [`Running::warm_start`])
    /// found a boot project of `len` bytes in image buffer `buffer`
    /// ([`Running::boot_buffer`]): at a cold start it takes the configured program's place
    /// as a download would; at a warm start it runs in this start's data memory, the
    /// values of what ran carried over to it as they would be to the configured program.
    pub fn boot_project(self, warm: bool, buffer: usize, len: usize) -> Running {
        if !warm {
            return self.downloaded(buffer, len);
        }
        Running {
            program: Program::Downloaded {
                buffer: buffer.min(1),
                len,
            },
            data: self.data,
        }
    }

    /// What runs after a download of `len` bytes committed in image buffer `staging`: that
    /// program, in the other data memory.
    pub fn downloaded(self, staging: usize, len: usize) -> Running {
        Running {
            program: Program::Downloaded {
                buffer: staging.min(1),
                len,
            },
            data: 1 - self.data.min(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_download_never_touches_what_runs_or_what_is_handed_over() {
        // Cold start, two downloads (the second into buffer 1), a warm restart, two more.
        let mut previous = None;
        let mut running = Running::COLD;
        let mut seen = Vec::new();
        for step in ["download", "download", "warm", "download", "download"] {
            let staging = running.staging(previous);
            if let Program::Downloaded { buffer, .. } = running.program {
                assert_ne!(staging, buffer, "{step}: staging over the running program");
            }
            if let Some(Running {
                program: Program::Downloaded { buffer, .. },
                ..
            }) = previous
                && running.program == Program::Configured
            {
                assert_eq!(
                    staging, buffer,
                    "{step}: the old program's buffer stays put"
                );
            }
            let next = match step {
                "warm" => Running::warm_start(running),
                _ => running.downloaded(staging, 100 + seen.len()),
            };
            assert_ne!(next.data, running.data, "{step}: data memory reused");
            if let Program::Downloaded { buffer, .. } = next.program {
                assert_eq!(buffer, staging, "{step}: runs where it was assembled");
            }
            seen.push(next);
            previous = Some(running);
            running = next;
        }
        assert_eq!(
            seen[2],
            Running {
                program: Program::Configured,
                data: 1
            }
        );
        assert_eq!(
            seen[3].program,
            Program::Downloaded {
                buffer: 1,
                len: 103
            },
            "assembled in the buffer the warm restart left alone"
        );
    }

    /// A warm start with a boot project: it loads where the program that ran is not, runs
    /// in the other data memory than that program's, and the next download is assembled
    /// where the old program was (after the handover).
    #[test]
    fn a_warm_start_runs_the_boot_project_beside_what_ran() {
        for was in [
            Running::COLD,
            Running {
                program: Program::Downloaded { buffer: 0, len: 9 },
                data: 1,
            },
            Running {
                program: Program::Downloaded { buffer: 1, len: 9 },
                data: 0,
            },
        ] {
            let buffer = Running::boot_buffer(Some(was));
            if let Program::Downloaded { buffer: old, .. } = was.program {
                assert_ne!(buffer, old, "{was:?}: loaded over the program that ran");
            }
            let next = Running::warm_start(was).boot_project(true, buffer, 50);
            assert_eq!(next.program, Program::Downloaded { buffer, len: 50 });
            assert_ne!(next.data, was.data, "{was:?}: data memory reused");
            let staging = next.staging(Some(was));
            assert_ne!(staging, buffer, "{was:?}: staging over the boot project");
        }
        // A cold start: as a download of the boot project.
        let buffer = Running::boot_buffer(None);
        assert_eq!(
            Running::COLD.boot_project(false, buffer, 50),
            Running::COLD.downloaded(0, 50)
        );
    }

    #[test]
    fn chunks_assemble_in_order_within_the_announced_size() {
        let image = [7u8; 10];
        let mut buffer = [0u8; 16];
        let mut d = Download::new();
        assert_eq!(d.chunk(&mut buffer, 0, &image), Err(Status::NoDownload));
        assert_eq!(d.finish(&buffer), Err(Status::NoDownload));
        assert_eq!(d.begin(17, 0, buffer.len()), Err(Status::TooLarge));
        assert_eq!(d.begin(0, 0, buffer.len()), Err(Status::Malformed));
        assert!(!d.is_open());
        d.begin(10, plc_online::crc32(&image), buffer.len())
            .unwrap();
        assert_eq!(d.chunk(&mut buffer, 0, &[7; 11]), Err(Status::BadOffset));
        assert_eq!(d.chunk(&mut buffer, 4, &image[4..]), Err(Status::BadOffset));
        assert_eq!(
            d.chunk(&mut buffer, u32::MAX, &[1]),
            Err(Status::BadOffset),
            "no overflow"
        );
        d.chunk(&mut buffer, 0, &image[..4]).unwrap();
        assert_eq!(d.finish(&buffer), Err(Status::Incomplete));
        assert!(d.is_open(), "an early commit leaves the download open");
        assert_eq!(d.chunk(&mut buffer, 8, &image[8..]), Err(Status::BadOffset));
        d.chunk(&mut buffer, 4, &image[4..]).unwrap();
        assert_eq!(d.chunk(&mut buffer, 10, &[1]), Err(Status::BadOffset));
        assert_eq!(d.finish(&buffer), Ok(&image[..]));
        assert!(!d.is_open());
        assert_eq!(d.finish(&buffer), Err(Status::NoDownload));
    }

    #[test]
    fn a_wrong_checksum_ends_the_download_and_begin_starts_over() {
        let mut buffer = [0u8; 8];
        let mut d = Download::new();
        d.begin(4, 1234, buffer.len()).unwrap();
        d.chunk(&mut buffer, 0, &[1, 2]).unwrap();
        // BEGIN again: the unfinished download is dropped.
        d.begin(4, 1234, buffer.len()).unwrap();
        assert_eq!(d.chunk(&mut buffer, 2, &[3, 4]), Err(Status::BadOffset));
        d.chunk(&mut buffer, 0, &[1, 2, 3, 4]).unwrap();
        assert_eq!(d.finish(&buffer), Err(Status::ChecksumMismatch));
        assert_eq!(d.chunk(&mut buffer, 0, &[1]), Err(Status::NoDownload));
    }

    #[test]
    fn names_are_cut_on_a_character_boundary() {
        let long = "ä".repeat(40);
        let name = VarName::of(&long);
        assert!(name.as_str().len() <= VarName::MAX);
        assert!(long.starts_with(name.as_str()));
    }
}
