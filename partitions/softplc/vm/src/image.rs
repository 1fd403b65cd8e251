//! The bytecode image format (version 4), its zero-copy parser and (feature `alloc`) a builder.
//!
//! All integers are little-endian. Layout:
//!
//! ```text
//! offset size  field
//! 0      4     magic "PLCB"
//! 4      2     version (= 4; version 1 had no LOCATED section, version 2 no SHARED section,
//!              version 3 no OBJECTS, CLASSES and DISPATCH sections)
//! 6      2     header length (= 128)
//! 8      4     data_size: bytes of data memory the program needs
//! 12     4     reserved (0)
//! 16     112   section table: 14 x (offset u32, length u32), offsets from the image start,
//!              in this order: CODE, CONSTS, INIT, POUS, TASKS, VARS, SRCLOCS, FILES, NAMES,
//!              LOCATED, SHARED, OBJECTS, CLASSES, DISPATCH
//! ```
//!
//! Sections:
//! * `CODE`: the instructions (see [`crate::isa`]), decodable linearly from offset 0.
//! * `CONSTS`: constant pool, `u64` cells (for `PUSH_CONST`).
//! * `INIT`: initial data memory bytes `0..len` (`len <= data_size`); the rest is zeroed.
//! * `POUS`: 20-byte records `name_off u32, name_len u16, arg_cells u8, ret_cells u8,
//!   code_start u32, code_len u32, frame_size u32`.
//! * `TASKS`: 32-byte records `name_off u32, name_len u16, kind u8 (0 cyclic, 1 event),
//!   priority u8, pou u16, reserved u16, instance_base u32, watchdog_budget u32 (instructions per
//!   cycle, 0 = [`DEFAULT_WATCHDOG_BUDGET`]), interval_ns u64, trigger u32` (event tasks:
//!   1 + the data address of the BOOL whose rising edge releases the task, 0 = none).
//! * `VARS`: 16-byte records `name_off u32, name_len u16, type u8 ([`VarType`]), flags u8
//!   ([`VAR_FLAG_RETAIN`], [`VAR_FLAG_CONSTANT`]), address u32, size u32` — the monitor map:
//!   every elementary variable, STRING, WSTRING and reference of the program by its full
//!   name, with its own type (each date/time type, CHAR and WCHAR have codes of their own
//!   since version 4). The verifier refuses an unknown type code and a size that does not
//!   fit the type ([`VarType::size_fits`]).
//! * `SRCLOCS`: 16-byte records `code_offset u32, line u32, column u32, file u16, reserved u16`,
//!   sorted by code offset; an entry covers code up to the next entry's offset.
//! * `FILES`: 8-byte records `name_off u32, name_len u16, reserved u16`.
//! * `NAMES`: UTF-8 string blob referenced by the `name_off/name_len` fields.
//! * `LOCATED`: 12-byte records `address u32` (the variable's data memory), `byte u32` (its
//!   first byte in the area), `area u8`, `width u8` ([`crate::located::Area`],
//!   [`crate::located::Width`]), `bit u8`, reserved u8 — the located variables, in declaration
//!   order (see [`crate::located`] for the copy semantics).
//! * `SHARED`: 16-byte records `var u32` (index of the variable's `VARS` record: name, type,
//!   data address, size), `direction u8` ([`SharedDirection`]: 0 written by this program,
//!   1 read from the other project, 2 the validity flag of the read ones), reserved u8,
//!   `file u16, line u32, column u32` (the declaration, for the build's cross-project
//!   diagnostics) — the global variables shared with another PLC project
//!   (`{attribute 'shared' := 'write' | 'read' | 'valid'}`), in declaration order. The
//!   verifier checks that each names a variable once, of an elementary type (BOOL to LREAL,
//!   TIME, the bit strings; no STRING), that no two overlap in data memory, that at most one
//!   is the validity flag and it is a BOOL, and that there are at most [`MAX_SHARED_VARS`].
//! * `OBJECTS`: 12-byte records `start u32, len u32, parent u32`: the variables (and parts of
//!   variables) a reference may reach (see "References" in [`crate::isa`]). Sorted by
//!   `start`, then by decreasing `len`; each inside data memory and at least one byte long;
//!   two records either do not overlap or one contains the other, and `parent` is 1 + the
//!   index of the smallest record containing this one (0 when none), at most
//!   [`MAX_OBJECT_DEPTH`] levels deep (the verifier checks all of it). A reference made by
//!   `REF_MAKE` names the smallest record containing the bytes it was made for; `REF_CHECK`
//!   admits an access only inside that record's bytes.
//! * `CLASSES`: 16-byte records `name_off u32, name_len u16, reserved u16, first u32,
//!   count u32`: the function-block classes whose instances are called through `CALL_VIRT`
//!   (see "Classes and dynamic dispatch" in [`crate::isa`]). An instance of class `k` holds
//!   `k` as a `u32` at its first byte; `first`/`count` are its range of `DISPATCH` records.
//! * `DISPATCH`: 8-byte records `slot u16, pou u16, frame u32`: within one class's range
//!   sorted by strictly increasing `slot`; `pou` is the method run for that slot (a POU
//!   taking and leaving 0 cells), `frame` the data address of that method's parameter frame
//!   (`VIRT_FRAME` gives it to the caller, which stores the arguments there).
//!
//! [`Image::parse`] checks only the structure (sizes, section bounds, record multiples); the
//! semantic checks are the verifier's job ([`mod@crate::verify`]).

use crate::isa::{read_u16, read_u32, read_u64};

/// Image magic.
pub const MAGIC: [u8; 4] = *b"PLCB";
/// Format version this crate reads and writes.
pub const VERSION: u16 = 4;
/// Number of sections in the section table.
pub const SECTION_COUNT: usize = 14;
/// Header length in bytes.
pub const HEADER_LEN: usize = 16 + SECTION_COUNT * 8;
/// POU record size.
pub const POU_RECORD: usize = 20;
/// Task record size.
pub const TASK_RECORD: usize = 32;
/// Variable record size.
pub const VAR_RECORD: usize = 16;
/// Source-location record size.
pub const SRCLOC_RECORD: usize = 16;
/// File record size.
pub const FILE_RECORD: usize = 8;
/// Located-variable record size.
pub const LOCATED_RECORD: usize = 12;
/// Shared-variable record size.
pub const SHARED_RECORD: usize = 16;
/// Object record size.
pub const OBJECT_RECORD: usize = 12;
/// Deepest nesting of object records (a variable, its members, their members, ...).
pub const MAX_OBJECT_DEPTH: usize = 16;
/// Class record size.
pub const CLASS_RECORD: usize = 16;
/// Dispatch record size.
pub const DISPATCH_RECORD: usize = 8;
/// Most shared-variable records an image may have.
pub const MAX_SHARED_VARS: usize = 256;
/// Watchdog budget (instructions per cycle) used when a task record says 0.
pub const DEFAULT_WATCHDOG_BUDGET: u32 = 1_000_000;
/// Variable flag: RETAIN.
pub const VAR_FLAG_RETAIN: u8 = 1;
/// Variable flag: CONSTANT (force is refused).
pub const VAR_FLAG_CONSTANT: u8 = 2;

/// Section indices in the section table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum Section {
    /// Instructions.
    Code = 0,
    /// Constant pool.
    Consts = 1,
    /// Initial data.
    Init = 2,
    /// POU table.
    Pous = 3,
    /// Task table.
    Tasks = 4,
    /// Variable map.
    Vars = 5,
    /// Source locations.
    SrcLocs = 6,
    /// Source file names.
    Files = 7,
    /// Name blob.
    Names = 8,
    /// Located variables.
    Located = 9,
    /// Variables shared with another PLC project.
    Shared = 10,
    /// The variables references may reach.
    Objects = 11,
    /// Function-block classes (dynamic dispatch).
    Classes = 12,
    /// The classes' method tables.
    Dispatch = 13,
}

/// Why [`Image::parse`] rejected the bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageError {
    /// Fewer bytes than the header.
    TooShort,
    /// Magic is not "PLCB".
    BadMagic,
    /// Unsupported version.
    UnsupportedVersion(u16),
    /// Header length field is not [`HEADER_LEN`].
    BadHeaderLength(u16),
    /// A section lies (partly) outside the image.
    SectionOutOfBounds(Section),
    /// A record section's length is not a multiple of its record size.
    RaggedSection(Section),
    /// The INIT section is longer than `data_size`.
    InitLargerThanData,
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ImageError::TooShort => write!(f, "image shorter than its {HEADER_LEN}-byte header"),
            ImageError::BadMagic => write!(f, "bad magic (expected \"PLCB\")"),
            ImageError::UnsupportedVersion(v) => {
                write!(f, "unsupported image version {v} (expected {VERSION})")
            }
            ImageError::BadHeaderLength(l) => {
                write!(f, "header length {l} (expected {HEADER_LEN})")
            }
            ImageError::SectionOutOfBounds(s) => write!(f, "section {s:?} lies outside the image"),
            ImageError::RaggedSection(s) => write!(
                f,
                "section {s:?} length is not a multiple of its record size"
            ),
            ImageError::InitLargerThanData => write!(f, "INIT section longer than data_size"),
        }
    }
}

codes::code_enum! {
    /// Monitor type of a variable-map entry.
    pub enum VarType: u8 {
        /// BOOL (1 byte, 0/1).
        Bool = 0 => "BOOL",
        /// SINT.
        SInt = 1 => "SINT",
        /// INT.
        Int = 2 => "INT",
        /// DINT.
        DInt = 3 => "DINT",
        /// LINT.
        LInt = 4 => "LINT",
        /// USINT.
        USInt = 5 => "USINT",
        /// UINT.
        UInt = 6 => "UINT",
        /// UDINT.
        UDInt = 7 => "UDINT",
        /// ULINT.
        ULInt = 8 => "ULINT",
        /// REAL.
        Real = 9 => "REAL",
        /// LREAL.
        LReal = 10 => "LREAL",
        /// TIME (i64 nanoseconds).
        Time = 11 => "TIME",
        /// STRING (header + bytes, see [`crate::isa::Builtin`]).
        String = 12 => "STRING",
        /// BYTE.
        Byte = 13 => "BYTE",
        /// WORD.
        Word = 14 => "WORD",
        /// DWORD.
        DWord = 15 => "DWORD",
        /// LWORD.
        LWord = 16 => "LWORD",
        /// DATE (i64 nanoseconds since 1970-01-01, a whole number of days).
        Date = 17 => "DATE",
        /// TIME_OF_DAY (i64 nanoseconds since midnight, below one day).
        Tod = 18 => "TOD",
        /// DATE_AND_TIME (i64 nanoseconds since 1970-01-01).
        Dt = 19 => "DT",
        /// LTIME (i64 nanoseconds).
        LTime = 20 => "LTIME",
        /// LDATE (as DATE).
        LDate = 21 => "LDATE",
        /// LTIME_OF_DAY (as TOD).
        LTod = 22 => "LTOD",
        /// LDATE_AND_TIME (as DT).
        LDt = 23 => "LDT",
        /// CHAR (1 byte).
        Char = 24 => "CHAR",
        /// WCHAR (a UTF-16 code unit, 2 bytes).
        WChar = 25 => "WCHAR",
        /// WSTRING (`max_len u16, cur_len u16, units[max_len] u16`, see [`crate::isa::Builtin`]).
        WString = 26 => "WSTRING",
        /// A reference (`REF_TO`, `POINTER TO`, `REFERENCE TO`, an interface or a reference
        /// to a function-block instance): a 64-bit cell whose low 32 bits are the data address
        /// of its target, 0 being NULL (see "References" in [`crate::isa`]). Read-only for a
        /// monitor: a written address could name another variable or trap the program.
        Ref = 27 => "REF_TO",
    }
}

/// How a variable of a [`VarType`] is held in data memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// A number, bit string, BOOL, date/time or character of this memory type.
    Scalar(crate::isa::MemType),
    /// A STRING: `max_len u16, cur_len u16, bytes[max_len]` (record size `4 + max_len`).
    String,
    /// A WSTRING: `max_len u16, cur_len u16, units[max_len] u16` (record size `4 + 2 max_len`).
    WString,
    /// A reference cell (`u64`, record size 8).
    Reference,
}

impl VarType {
    /// How a variable of this type is held.
    pub const fn storage(self) -> Storage {
        use crate::isa::MemType as M;
        use VarType::*;
        Storage::Scalar(match self {
            Bool | USInt | Byte | Char => M::U8,
            SInt => M::I8,
            Int => M::I16,
            DInt => M::I32,
            LInt | Time | LTime | Date | LDate | Tod | LTod | Dt | LDt => M::I64,
            UInt | Word | WChar => M::U16,
            UDInt | DWord => M::U32,
            ULInt | LWord => M::U64,
            Real => M::F32,
            LReal => M::F64,
            String => return Storage::String,
            WString => return Storage::WString,
            Ref => return Storage::Reference,
        })
    }

    /// The storage type of a scalar: a number, bit string, BOOL, date/time or character
    /// (`None` for STRING, WSTRING and references).
    pub const fn mem_type(self) -> Option<crate::isa::MemType> {
        match self.storage() {
            Storage::Scalar(mem) => Some(mem),
            _ => None,
        }
    }

    /// Whether the record size `size` fits a variable of this type.
    pub const fn size_fits(self, size: u32) -> bool {
        match self.storage() {
            Storage::Scalar(mem) => size as usize == mem.width(),
            Storage::String => size >= 4 && size - 4 <= u16::MAX as u32,
            Storage::WString => {
                size >= 4 && (size - 4).is_multiple_of(2) && (size - 4) / 2 <= u16::MAX as u32
            }
            Storage::Reference => size == 8,
        }
    }

    /// SINT, INT, DINT, LINT: the integers whose values are signed.
    pub const fn is_signed_int(self) -> bool {
        matches!(
            self,
            VarType::SInt | VarType::Int | VarType::DInt | VarType::LInt
        )
    }

    /// The date/time kind of TIME, LTIME, DATE, TOD, DT and the long forms.
    pub const fn time_kind(self) -> Option<crate::isa::TimeKind> {
        use crate::isa::TimeKind as K;
        Some(match self {
            VarType::Time => K::Time,
            VarType::LTime => K::LTime,
            VarType::Date => K::Date,
            VarType::LDate => K::LDate,
            VarType::Tod => K::Tod,
            VarType::LTod => K::LTod,
            VarType::Dt => K::Dt,
            VarType::LDt => K::LDt,
            _ => return None,
        })
    }

    /// The variable type of a date/time kind.
    pub const fn of_time_kind(kind: crate::isa::TimeKind) -> VarType {
        use crate::isa::TimeKind as K;
        match kind {
            K::Time => VarType::Time,
            K::LTime => VarType::LTime,
            K::Date => VarType::Date,
            K::LDate => VarType::LDate,
            K::Tod => VarType::Tod,
            K::LTod => VarType::LTod,
            K::Dt => VarType::Dt,
            K::LDt => VarType::LDt,
        }
    }

    /// The inclusive range of an integer, bit-string or character type's values (as
    /// `i128`, to hold both LINT's and ULINT's); `None` for the other types.
    pub const fn int_range(self) -> Option<(i128, i128)> {
        use VarType::*;
        Some(match self {
            SInt => (i8::MIN as i128, i8::MAX as i128),
            Int => (i16::MIN as i128, i16::MAX as i128),
            DInt => (i32::MIN as i128, i32::MAX as i128),
            LInt => (i64::MIN as i128, i64::MAX as i128),
            USInt | Byte | Char => (0, u8::MAX as i128),
            UInt | Word | WChar => (0, u16::MAX as i128),
            UDInt | DWord => (0, u32::MAX as i128),
            ULInt | LWord => (0, u64::MAX as i128),
            _ => return None,
        })
    }
}

/// A POU table entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pou<'a> {
    /// Name ("" when the name reference is invalid; the verifier rejects such images).
    pub name: &'a str,
    /// Cells the callee receives on its stack.
    pub arg_cells: u8,
    /// Cells the callee leaves on return.
    pub ret_cells: u8,
    /// First code offset.
    pub code_start: u32,
    /// Code length in bytes.
    pub code_len: u32,
    /// Bytes of the data frame addressed by LD_REL/ST_REL/LEA_REL.
    pub frame_size: u32,
}

/// Task activation kind.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskKind {
    /// Runs every `interval_ns`.
    Cyclic = 0,
    /// Runs on an event (SINGLE).
    Event = 1,
}

/// A task table entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Task<'a> {
    /// Task name.
    pub name: &'a str,
    /// Raw kind byte (see [`TaskKind`]).
    pub kind: u8,
    /// IEC priority (lower runs first).
    pub priority: u8,
    /// POU run each cycle (arg_cells = ret_cells = 0).
    pub pou: u16,
    /// Frame base for the POU (the program instance's data block).
    pub instance_base: u32,
    /// Instruction budget per cycle (0 = [`DEFAULT_WATCHDOG_BUDGET`]).
    pub watchdog_budget: u32,
    /// Cycle interval in nanoseconds (cyclic tasks).
    pub interval_ns: u64,
    /// Event tasks: the data address of the BOOL whose rising edge releases the task.
    pub trigger: Option<u32>,
}

impl Task<'_> {
    /// The effective instruction budget.
    pub fn budget(&self) -> u32 {
        if self.watchdog_budget == 0 {
            DEFAULT_WATCHDOG_BUDGET
        } else {
            self.watchdog_budget
        }
    }
}

/// A variable-map entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Var<'a> {
    /// Full name, e.g. `Main.x`, `pf.n`, `g`.
    pub name: &'a str,
    /// Raw type byte (see [`VarType`]).
    pub ty: u8,
    /// Flags ([`VAR_FLAG_RETAIN`], [`VAR_FLAG_CONSTANT`]).
    pub flags: u8,
    /// Absolute data address.
    pub addr: u32,
    /// Size in bytes (for STRING: 4 + max length).
    pub size: u32,
}

codes::code_enum! {
    /// Which side of a shared global variable a program is on.
    pub enum SharedDirection: u8 {
        /// This program writes it (`{attribute 'shared' := 'write'}`).
        Write = 0 => "write",
        /// This program reads it from the other project (`{attribute 'shared' := 'read'}`).
        Read = 1 => "read",
        /// A BOOL the runtime sets before each cycle: whether the read variables hold a
        /// consistent copy of the other project's latest update, taken for this cycle
        /// (`{attribute 'shared' := 'valid'}`).
        Valid = 2 => "valid",
    }
}

/// A shared-variable record: the variable (its `VARS` record), its direction and where it is
/// declared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shared<'a> {
    /// Index of its `VARS` record.
    pub var_index: usize,
    /// Its `VARS` record (name, type, address, size).
    pub var: Var<'a>,
    /// Written here or read from the other project.
    pub direction: SharedDirection,
    /// The declaration.
    pub location: SourceLocation,
}

/// A source location (file index into the FILES section, 1-based line and column).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SourceLocation {
    /// Index into the file table.
    pub file: u16,
    /// Line (1-based).
    pub line: u32,
    /// Column (1-based).
    pub column: u32,
}

/// A class record: a function-block type whose instances are called through `CALL_VIRT`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Class<'a> {
    /// Its name ("" when the name reference is invalid; the verifier rejects such images).
    pub name: &'a str,
    /// Index of its first `DISPATCH` record.
    pub first: u32,
    /// Number of its `DISPATCH` records.
    pub count: u32,
}

/// A dispatch record: the method a class runs for a slot and that method's parameter frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dispatch {
    /// The slot (the operand of `CALL_VIRT` / `VIRT_FRAME`).
    pub slot: u16,
    /// The method's POU.
    pub pou: u16,
    /// Data address of the method's parameter frame.
    pub frame: u32,
}

/// A parsed image: borrowed views of the sections (no copies, no allocation).
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    data_size: u32,
    sections: [&'a [u8]; SECTION_COUNT],
}

impl<'a> Image<'a> {
    /// Parses and structurally checks an image.
    pub fn parse(bytes: &'a [u8]) -> Result<Image<'a>, ImageError> {
        if bytes.len() < HEADER_LEN {
            return Err(ImageError::TooShort);
        }
        if bytes[0..4] != MAGIC {
            return Err(ImageError::BadMagic);
        }
        let version = read_u16(bytes, 4);
        if version != VERSION {
            return Err(ImageError::UnsupportedVersion(version));
        }
        let header_len = read_u16(bytes, 6);
        if header_len as usize != HEADER_LEN {
            return Err(ImageError::BadHeaderLength(header_len));
        }
        let data_size = read_u32(bytes, 8);
        const KINDS: [Section; SECTION_COUNT] = [
            Section::Code,
            Section::Consts,
            Section::Init,
            Section::Pous,
            Section::Tasks,
            Section::Vars,
            Section::SrcLocs,
            Section::Files,
            Section::Names,
            Section::Located,
            Section::Shared,
            Section::Objects,
            Section::Classes,
            Section::Dispatch,
        ];
        let mut sections: [&'a [u8]; SECTION_COUNT] = [&[]; SECTION_COUNT];
        for (i, kind) in KINDS.iter().enumerate() {
            let offset = read_u32(bytes, 16 + i * 8) as usize;
            let len = read_u32(bytes, 20 + i * 8) as usize;
            let end = offset
                .checked_add(len)
                .ok_or(ImageError::SectionOutOfBounds(*kind))?;
            let section = bytes
                .get(offset..end)
                .ok_or(ImageError::SectionOutOfBounds(*kind))?;
            let record = match kind {
                Section::Consts => 8,
                Section::Pous => POU_RECORD,
                Section::Tasks => TASK_RECORD,
                Section::Vars => VAR_RECORD,
                Section::SrcLocs => SRCLOC_RECORD,
                Section::Files => FILE_RECORD,
                Section::Located => LOCATED_RECORD,
                Section::Shared => SHARED_RECORD,
                Section::Objects => OBJECT_RECORD,
                Section::Classes => CLASS_RECORD,
                Section::Dispatch => DISPATCH_RECORD,
                _ => 1,
            };
            if section.len() % record != 0 {
                return Err(ImageError::RaggedSection(*kind));
            }
            sections[i] = section;
        }
        if sections[Section::Init as usize].len() > data_size as usize {
            return Err(ImageError::InitLargerThanData);
        }
        Ok(Image {
            data_size,
            sections,
        })
    }

    /// Whether `other` is the same program: the same data size and sections, byte for byte
    /// (so a data address means the same variable in both).
    pub fn same_program(&self, other: &Image) -> bool {
        self.data_size == other.data_size && self.sections == other.sections
    }

    fn section(&self, section: Section) -> &'a [u8] {
        self.sections[section as usize]
    }

    /// Bytes of data memory the program needs.
    pub fn data_size(&self) -> u32 {
        self.data_size
    }

    /// The code section.
    pub fn code(&self) -> &'a [u8] {
        self.section(Section::Code)
    }

    /// Initial data bytes (prefix of data memory; the rest starts zeroed).
    pub fn init_data(&self) -> &'a [u8] {
        self.section(Section::Init)
    }

    /// Number of constant-pool cells.
    pub fn const_count(&self) -> usize {
        self.section(Section::Consts).len() / 8
    }

    /// Constant-pool cell `index`.
    pub fn constant(&self, index: usize) -> Option<u64> {
        (index < self.const_count()).then(|| read_u64(self.section(Section::Consts), index * 8))
    }

    /// Resolves a name reference; `None` when out of the blob or not UTF-8.
    pub fn name_at(&self, offset: u32, len: u16) -> Option<&'a str> {
        let start = offset as usize;
        let bytes = self
            .section(Section::Names)
            .get(start..start.checked_add(len as usize)?)?;
        core::str::from_utf8(bytes).ok()
    }

    fn record(&self, section: Section, size: usize, index: usize) -> Option<&'a [u8]> {
        let start = index.checked_mul(size)?;
        self.section(section).get(start..start.checked_add(size)?)
    }

    /// Raw name reference of a record (offset 0: name_off u32, offset 4: name_len u16).
    pub(crate) fn record_name_ref(&self, section: Section, index: usize) -> Option<(u32, u16)> {
        let size = match section {
            Section::Pous => POU_RECORD,
            Section::Tasks => TASK_RECORD,
            Section::Vars => VAR_RECORD,
            Section::Files => FILE_RECORD,
            Section::Classes => CLASS_RECORD,
            _ => return None,
        };
        let r = self.record(section, size, index)?;
        Some((read_u32(r, 0), read_u16(r, 4)))
    }

    /// Number of POUs.
    pub fn pou_count(&self) -> usize {
        self.section(Section::Pous).len() / POU_RECORD
    }

    /// POU `index`'s code start and frame size (what a CALL needs; no name lookup).
    #[inline(always)]
    pub(crate) fn pou_entry(&self, index: usize) -> Option<(u32, u32)> {
        let r = self.record(Section::Pous, POU_RECORD, index)?;
        Some((read_u32(r, 8), read_u32(r, 16)))
    }

    /// POU `index`.
    pub fn pou(&self, index: usize) -> Option<Pou<'a>> {
        let r = self.record(Section::Pous, POU_RECORD, index)?;
        Some(Pou {
            name: self.name_at(read_u32(r, 0), read_u16(r, 4)).unwrap_or(""),
            arg_cells: r[6],
            ret_cells: r[7],
            code_start: read_u32(r, 8),
            code_len: read_u32(r, 12),
            frame_size: read_u32(r, 16),
        })
    }

    /// Number of tasks.
    pub fn task_count(&self) -> usize {
        self.section(Section::Tasks).len() / TASK_RECORD
    }

    /// Task `index`.
    pub fn task(&self, index: usize) -> Option<Task<'a>> {
        let r = self.record(Section::Tasks, TASK_RECORD, index)?;
        Some(Task {
            name: self.name_at(read_u32(r, 0), read_u16(r, 4)).unwrap_or(""),
            kind: r[6],
            priority: r[7],
            pou: read_u16(r, 8),
            instance_base: read_u32(r, 12),
            watchdog_budget: read_u32(r, 16),
            interval_ns: read_u64(r, 20),
            trigger: read_u32(r, 28).checked_sub(1),
        })
    }

    /// Number of variable-map entries.
    pub fn var_count(&self) -> usize {
        self.section(Section::Vars).len() / VAR_RECORD
    }

    /// Variable-map entry `index`.
    pub fn var(&self, index: usize) -> Option<Var<'a>> {
        let r = self.record(Section::Vars, VAR_RECORD, index)?;
        Some(Var {
            name: self.name_at(read_u32(r, 0), read_u16(r, 4)).unwrap_or(""),
            ty: r[6],
            flags: r[7],
            addr: read_u32(r, 8),
            size: read_u32(r, 12),
        })
    }

    /// Number of located variables.
    pub fn located_count(&self) -> usize {
        self.section(Section::Located).len() / LOCATED_RECORD
    }

    /// Located variable `index`; `None` if out of range or its area/width code is unknown
    /// (the verifier refuses such an image).
    pub fn located(&self, index: usize) -> Option<crate::located::Located> {
        use crate::located::{Area, Located, Location, Width};
        let r = self.record(Section::Located, LOCATED_RECORD, index)?;
        Some(Located {
            address: read_u32(r, 0),
            location: Location {
                byte: read_u32(r, 4),
                area: Area::from_code(r[8])?,
                width: Width::from_code(r[9])?,
                bit: r[10],
            },
        })
    }

    /// Every located variable, in declaration order.
    pub fn located_vars(&self) -> impl Iterator<Item = crate::located::Located> + '_ {
        (0..self.located_count()).filter_map(|i| self.located(i))
    }

    /// Number of shared-variable records.
    pub fn shared_count(&self) -> usize {
        self.section(Section::Shared).len() / SHARED_RECORD
    }

    /// Shared-variable record `index`; `None` if out of range, its direction code is
    /// unknown or its variable record does not exist (the verifier refuses such an image).
    pub fn shared(&self, index: usize) -> Option<Shared<'a>> {
        let r = self.record(Section::Shared, SHARED_RECORD, index)?;
        let var_index = read_u32(r, 0) as usize;
        Some(Shared {
            var_index,
            var: self.var(var_index)?,
            direction: SharedDirection::from_code(r[4])?,
            location: SourceLocation {
                file: read_u16(r, 6),
                line: read_u32(r, 8),
                column: read_u32(r, 12),
            },
        })
    }

    /// Every shared variable, in declaration order.
    pub fn shared_vars(&self) -> impl Iterator<Item = Shared<'a>> + '_ {
        (0..self.shared_count()).filter_map(|i| self.shared(i))
    }

    /// Number of object records.
    pub fn object_count(&self) -> usize {
        self.section(Section::Objects).len() / OBJECT_RECORD
    }

    /// Object record `index` as `(start, len)`.
    #[inline(always)]
    pub fn object(&self, index: usize) -> Option<(u32, u32)> {
        let r = self.record(Section::Objects, OBJECT_RECORD, index)?;
        Some((read_u32(r, 0), read_u32(r, 4)))
    }

    /// The index of object record `index`'s parent (the smallest record containing it).
    pub fn object_parent(&self, index: usize) -> Option<usize> {
        let r = self.record(Section::Objects, OBJECT_RECORD, index)?;
        (read_u32(r, 8) as usize).checked_sub(1)
    }

    /// The index of the smallest object record containing the `size` bytes at `address`:
    /// a binary search for the last record starting at or before `address`, then up its
    /// parents (every record containing `address` is that record or one of its ancestors,
    /// since records nest and are sorted by start, then by decreasing length). At most
    /// [`MAX_OBJECT_DEPTH`] steps up in a verified image.
    pub fn object_containing(&self, address: u64, size: u64) -> Option<usize> {
        let (mut lo, mut hi) = (0usize, self.object_count());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            match self.object(mid) {
                Some((start, _)) if start as u64 <= address => lo = mid + 1,
                _ => hi = mid,
            }
        }
        let mut index = lo.checked_sub(1)?;
        for _ in 0..=MAX_OBJECT_DEPTH {
            let (start, len) = self.object(index)?;
            if address >= start as u64 && address + size <= start as u64 + len as u64 {
                return Some(index);
            }
            index = self.object_parent(index)?;
        }
        None
    }

    /// Number of class records.
    pub fn class_count(&self) -> usize {
        self.section(Section::Classes).len() / CLASS_RECORD
    }

    /// Class record `index`.
    pub fn class(&self, index: usize) -> Option<Class<'a>> {
        let r = self.record(Section::Classes, CLASS_RECORD, index)?;
        Some(Class {
            name: self.name_at(read_u32(r, 0), read_u16(r, 4)).unwrap_or(""),
            first: read_u32(r, 8),
            count: read_u32(r, 12),
        })
    }

    /// Number of dispatch records.
    pub fn dispatch_count(&self) -> usize {
        self.section(Section::Dispatch).len() / DISPATCH_RECORD
    }

    /// Dispatch record `index`.
    pub fn dispatch(&self, index: usize) -> Option<Dispatch> {
        let r = self.record(Section::Dispatch, DISPATCH_RECORD, index)?;
        Some(Dispatch {
            slot: read_u16(r, 0),
            pou: read_u16(r, 2),
            frame: read_u32(r, 4),
        })
    }

    /// The method class `class` runs for `slot` (binary search in the class's sorted range);
    /// `None` when the class does not exist or has no method for the slot.
    pub fn lookup_method(&self, class: u64, slot: u16) -> Option<Dispatch> {
        let c = self.class(usize::try_from(class).ok()?)?;
        let (mut lo, mut hi) = (c.first as usize, c.first as usize + c.count as usize);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            let d = self.dispatch(mid)?;
            match d.slot.cmp(&slot) {
                core::cmp::Ordering::Equal => return Some(d),
                core::cmp::Ordering::Less => lo = mid + 1,
                core::cmp::Ordering::Greater => hi = mid,
            }
        }
        None
    }

    /// Looks a variable up by exact name (linear scan; monitors are not hot paths).
    pub fn find_var(&self, name: &str) -> Option<Var<'a>> {
        self.find_var_index(name).and_then(|i| self.var(i))
    }

    /// The index in the variable map of the variable named exactly `name` (for callers that
    /// look a name up once and then reach it by [`Image::var`]).
    pub fn find_var_index(&self, name: &str) -> Option<usize> {
        (0..self.var_count()).find(|&i| self.var(i).is_some_and(|v| v.name == name))
    }

    /// The first variable of the map whose first byte is at data address `address` (what a
    /// monitor names a reference's target by; a linear scan).
    pub fn var_at(&self, address: u32) -> Option<Var<'a>> {
        (0..self.var_count())
            .filter_map(|i| self.var(i))
            .find(|v| v.addr == address)
    }

    /// Number of source-location records.
    pub fn srcloc_count(&self) -> usize {
        self.section(Section::SrcLocs).len() / SRCLOC_RECORD
    }

    /// Source-location record `index` as (code offset, location).
    pub fn srcloc(&self, index: usize) -> Option<(u32, SourceLocation)> {
        let r = self.record(Section::SrcLocs, SRCLOC_RECORD, index)?;
        Some((
            read_u32(r, 0),
            SourceLocation {
                line: read_u32(r, 4),
                column: read_u32(r, 8),
                file: read_u16(r, 12),
            },
        ))
    }

    /// The source location covering `code_offset` (the last record at or before it).
    pub fn source_location(&self, code_offset: u32) -> Option<SourceLocation> {
        // Binary search for the number of records with offset <= code_offset.
        let (mut lo, mut hi) = (0usize, self.srcloc_count());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            match self.srcloc(mid) {
                Some((offset, _)) if offset <= code_offset => lo = mid + 1,
                _ => hi = mid,
            }
        }
        lo.checked_sub(1)
            .and_then(|i| self.srcloc(i))
            .map(|(_, loc)| loc)
    }

    /// Number of source files.
    pub fn file_count(&self) -> usize {
        self.section(Section::Files).len() / FILE_RECORD
    }

    /// Name of source file `index`.
    pub fn file_name(&self, index: u16) -> Option<&'a str> {
        let (off, len) = self.record_name_ref(Section::Files, index as usize)?;
        self.name_at(off, len)
    }
}

#[cfg(any(feature = "alloc", test))]
pub use builder::*;

#[cfg(any(feature = "alloc", test))]
mod builder {
    //! [`ImageBuilder`]: emit code with labels and fix-ups, then serialize an image.
    use super::*;
    use crate::isa::{Builtin, MemType, Opcode, RoundMode, Trap};
    use alloc::string::String;
    use alloc::vec::Vec;

    /// A forward-referenceable code position.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub struct Label(u32);

    /// A POU declared in the builder (index into the POU table).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub struct PouId(pub u16);

    /// Why [`ImageBuilder::build`] failed.
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub enum BuildError {
        /// A label was used but never bound.
        UnboundLabel(u32),
        /// A declared POU was never given code (`begin_pou`/`end_pou`).
        PouWithoutCode(String),
        /// A section or the image exceeds u32 sizes.
        TooLarge,
    }

    impl core::fmt::Display for BuildError {
        fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            match self {
                BuildError::UnboundLabel(l) => write!(f, "label {l} used but never bound"),
                BuildError::PouWithoutCode(n) => write!(f, "POU {n} declared but has no code"),
                BuildError::TooLarge => write!(f, "image too large"),
            }
        }
    }

    /// Task parameters for [`ImageBuilder::add_task`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct TaskDef {
        /// Task name.
        pub name: String,
        /// Activation kind.
        pub kind: TaskKind,
        /// IEC priority (lower runs first).
        pub priority: u8,
        /// Program POU (must have 0 arg and 0 result cells).
        pub pou: PouId,
        /// Frame base of the program instance.
        pub instance_base: u32,
        /// Cycle interval in ns.
        pub interval_ns: u64,
        /// Instruction budget per cycle (0 = default).
        pub watchdog_budget: u32,
    }

    struct PouDef {
        name: String,
        arg_cells: u8,
        ret_cells: u8,
        frame_size: u32,
        code_start: Option<u32>,
        code_end: Option<u32>,
    }

    /// Builds an image. Emit helpers append one instruction each at the current code offset.
    #[derive(Default)]
    pub struct ImageBuilder {
        code: Vec<u8>,
        consts: Vec<u64>,
        init: Vec<u8>,
        data_size: u32,
        pous: Vec<PouDef>,
        tasks: Vec<u8>,
        vars: Vec<u8>,
        srclocs: Vec<u8>,
        files: Vec<u8>,
        names: Vec<u8>,
        located: Vec<u8>,
        shared: Vec<u8>,
        objects: Vec<u8>,
        classes: Vec<u8>,
        dispatch: Vec<u8>,
        labels: Vec<Option<u32>>,
        fixups: Vec<(usize, Label)>,
        /// Start offsets of the emitted instructions (for the peephole fusion).
        insn_starts: Vec<u32>,
        /// Code before this offset may not be rewritten (labels, source locations, raw bytes).
        barrier: u32,
        no_fusion: bool,
    }

    /// Whether `insn` is pure: it writes no memory and can raise no trap but STACK_OVERFLOW
    /// (for the store fusion): loads of verified static addresses, constants, stack
    /// shuffles, integer and float arithmetic but division (also with an immediate or a
    /// static operand), bit operations, comparisons, selections, conversions that cannot
    /// fail.
    fn pure(insn: &crate::isa::Instruction<'_>) -> bool {
        use Opcode::*;
        let op = insn.op;
        if matches!(op, OpImm | OpRel | OpAbs | OpRelRel) {
            return !matches!(
                Opcode::from_u8(insn.immediates[0]),
                Some(DivS | DivU | ModS | ModU | DivF32 | DivF64)
            );
        }
        matches!(
            op,
            Nop | PushI32
                | PushU32
                | PushI64
                | PushConst
                | Dup
                | Swap
                | Over
                | Drop
                | LdAbs
                | LdRel
                | LeaRel
                | Now
                | Add
                | Sub
                | Mul
                | Neg
                | AbsS
                | And
                | Or
                | Xor
                | Not
                | NotBool
                | Shl
                | ShrU
                | ShrS
                | Rol
                | Ror
                | Sext
                | Zext
                | Sel
                | SelIf
                | AddImm
                | AddF32
                | SubF32
                | MulF32
                | NegF32
                | AddF64
                | SubF64
                | MulF64
                | NegF64
                | IToF32S
                | IToF32U
                | IToF64S
                | IToF64U
                | F32ToF64
                | F64ToF32
        ) || op.is_comparison()
    }

    impl ImageBuilder {
        /// An empty builder.
        pub fn new() -> Self {
            Self::default()
        }

        /// Disables the peephole fusion (see [`ImageBuilder::op`]); for tests and debugging.
        pub fn disable_fusion(&mut self) {
            self.no_fusion = true;
        }

        /// Records an instruction start and emits its opcode byte.
        fn start(&mut self, op: Opcode) {
            self.insn_starts.push(self.code.len() as u32);
            self.code.push(op as u8);
        }

        /// The instruction at `insn_starts[i]`.
        fn insn_at(&self, i: usize) -> Option<crate::isa::Instruction<'_>> {
            crate::isa::decode(&self.code, *self.insn_starts.get(i)? as usize)
        }

        /// The value pushed by instruction `i` if it is a PUSH_I32/PUSH_U32/PUSH_I64.
        fn pushed_value(&self, i: usize) -> Option<i64> {
            let d = self.insn_at(i)?;
            Some(match d.op {
                Opcode::PushI32 => read_u32(d.immediates, 0) as i32 as i64,
                Opcode::PushU32 => read_u32(d.immediates, 0) as i64,
                Opcode::PushI64 => read_u64(d.immediates, 0) as i64,
                _ => return None,
            })
        }

        /// Whether the instructions from index `first` on may be rewritten: fusion is on and no
        /// label, source location or raw bytes lie inside them (only at their start).
        fn rewritable_from(&self, first: usize) -> bool {
            !self.no_fusion
                && first < self.insn_starts.len()
                && self.insn_starts[first] >= self.barrier
        }

        /// Removes the instructions from index `first` on.
        fn drop_from(&mut self, first: usize) {
            self.code.truncate(self.insn_starts[first] as usize);
            self.insn_starts.truncate(first);
        }

        /// Peephole fusion after emitting `ADD` or `SUB` (index `n - 1`): the array-address
        /// sequence `CHK_INDEX lo hi; [PUSH lo; SUB | ADD_IMM -lo]; [PUSH s; MUL]; ADD` becomes
        /// `INDEX lo hi s` (same effect, same trap at the same offset), and `PUSH_I32 k; ADD`
        /// / `PUSH_I32 k; SUB` become `ADD_IMM k` / `ADD_IMM -k`.
        fn fuse_arithmetic(&mut self, op: Opcode) -> bool {
            let n = self.insn_starts.len();
            if op == Opcode::Add && n >= 2 {
                let mut i = n - 1;
                let mut stride = 1u32;
                if i >= 2
                    && self.insn_at(i - 1).map(|d| d.op) == Some(Opcode::Mul)
                    && let Some(s) = self.pushed_value(i - 2).and_then(|v| u32::try_from(v).ok())
                {
                    stride = s;
                    i -= 2;
                } else if i >= 1
                    && let Some(s) = self.insn_at(i - 1).and_then(|d| {
                        (d.op == Opcode::OpImm && d.immediates[0] == Opcode::Mul as u8)
                            .then(|| read_u32(d.immediates, 1))
                            .filter(|&k| k as i32 >= 0)
                    })
                {
                    stride = s;
                    i -= 1;
                }
                let mut subtracted = 0i64;
                let before = if i >= 1 {
                    self.insn_at(i - 1).map(|d| (d.op, d.immediates))
                } else {
                    None
                };
                match before {
                    Some((Opcode::AddImm, imm)) => {
                        subtracted = -(read_u32(imm, 0) as i32 as i64);
                        i -= 1;
                    }
                    Some((Opcode::Sub, _)) if i >= 2 => {
                        if let Some(v) = self.pushed_value(i - 2) {
                            subtracted = v;
                            i -= 2;
                        }
                    }
                    _ => {}
                }
                if i >= 1
                    && self.rewritable_from(i - 1)
                    && let Some(chk) = self.insn_at(i - 1).filter(|d| d.op == Opcode::ChkIndex)
                {
                    let lo = read_u64(chk.immediates, 0) as i64;
                    let hi = read_u64(chk.immediates, 8) as i64;
                    if lo == subtracted {
                        self.drop_from(i - 1);
                        self.index(lo, hi, stride);
                        return true;
                    }
                }
            }
            if n >= 2
                && self.rewritable_from(n - 2)
                && let Some(d) = self.insn_at(n - 2).filter(|d| d.op == Opcode::PushI32)
            {
                let k = read_u32(d.immediates, 0) as i32;
                let imm = if op == Opcode::Add {
                    Some(k)
                } else {
                    k.checked_neg()
                };
                if let Some(imm) = imm {
                    self.drop_from(n - 2);
                    self.add_imm(imm);
                    return true;
                }
            }
            false
        }

        /// Before NEG_F32/NEG_F64: a directly preceding push of a REAL (PUSH_U32) or LREAL
        /// (PUSH_I64) constant gets its sign bit flipped instead (what the negation does);
        /// true when folded.
        fn fold_negation(&mut self, op: Opcode) -> bool {
            let n = self.insn_starts.len();
            if n == 0 || !self.rewritable_from(n - 1) {
                return false;
            }
            let at = self.insn_starts[n - 1] as usize;
            match (op, Opcode::from_u8(self.code[at])) {
                (Opcode::NegF32, Some(Opcode::PushU32)) => self.code[at + 4] ^= 0x80,
                (Opcode::NegF64, Some(Opcode::PushI64)) => self.code[at + 8] ^= 0x80,
                _ => return false,
            }
            true
        }

        /// Peephole fusion after emitting a binary operator (index `n - 1`) whose right
        /// operand was pushed by the instruction before it: `PUSH_I32 k; op` → `OP_IMM op k`
        /// (also `PUSH_U32 k` when the cell is the same, or when `op` is a REAL operator,
        /// which reads only the low 32 bits), `LD_REL ty o; op` → `OP_REL op ty o`, `LD_ABS
        /// ty a; op` → `OP_ABS op ty a`.
        fn fuse_operand(&mut self, op: Opcode) {
            let n = self.insn_starts.len();
            if n < 2 || !self.rewritable_from(n - 2) {
                return;
            }
            let Some(d) = self.insn_at(n - 2) else { return };
            let reads_low_32 = matches!(
                op,
                Opcode::AddF32
                    | Opcode::SubF32
                    | Opcode::MulF32
                    | Opcode::DivF32
                    | Opcode::EqF32
                    | Opcode::NeF32
                    | Opcode::LtF32
                    | Opcode::LeF32
                    | Opcode::GtF32
                    | Opcode::GeF32
            );
            match d.op {
                Opcode::PushI32 | Opcode::PushU32 => {
                    let k = read_u32(d.immediates, 0);
                    if d.op == Opcode::PushU32 && k > i32::MAX as u32 && !reads_low_32 {
                        return;
                    }
                    self.drop_from(n - 2);
                    self.op_imm(op, k as i32);
                }
                Opcode::LdRel | Opcode::LdAbs => {
                    let (ty, addr) = (d.immediates[0], read_u32(d.immediates, 1));
                    let (Some(ty), rel) = (MemType::from_code(ty), d.op == Opcode::LdRel) else {
                        return;
                    };
                    // Both operands frame variables: OP_REL_REL.
                    if rel
                        && n >= 3
                        && self.rewritable_from(n - 3)
                        && let Some((ty1, off1)) = self
                            .insn_at(n - 3)
                            .filter(|d| d.op == Opcode::LdRel)
                            .and_then(|d| {
                                Some((
                                    MemType::from_code(d.immediates[0])?,
                                    read_u32(d.immediates, 1),
                                ))
                            })
                    {
                        self.drop_from(n - 3);
                        self.op_rel_rel(op, (ty1, off1), (ty, addr));
                        return;
                    }
                    self.drop_from(n - 2);
                    self.op_at(rel, op, ty, addr);
                }
                _ => {}
            }
        }

        /// Before a store of `ty` to `addr` (ST_REL/ST_ABS, `load` the matching load): `LD ty
        /// addr; ADD_IMM k` directly before it becomes `INC_REL`/`INC_ABS ty addr k`; true
        /// when fused (the store is then not emitted).
        fn fuse_increment(&mut self, load: Opcode, ty: MemType, addr: u32) -> bool {
            let n = self.insn_starts.len();
            if n < 2 || !self.rewritable_from(n - 2) || !ty.is_integer() {
                return false;
            }
            let (Some(ld), Some(add)) = (self.insn_at(n - 2), self.insn_at(n - 1)) else {
                return false;
            };
            if ld.op != load
                || ld.immediates[0] != ty as u8
                || read_u32(ld.immediates, 1) != addr
                || add.op != Opcode::AddImm
            {
                return false;
            }
            let k = read_u32(add.immediates, 0) as i32;
            self.drop_from(n - 2);
            self.inc(load == Opcode::LdRel, ty, addr, k);
            true
        }

        /// Before `LD_IND ty 0`: a directly preceding ELEM_REL/ELEM_ABS becomes
        /// `LD_ELEM_REL`/`LD_ELEM_ABS ty`; true when fused.
        fn fuse_element_load(&mut self, ty: MemType) -> bool {
            let n = self.insn_starts.len();
            if n < 1 || !self.rewritable_from(n - 1) {
                return false;
            }
            let Some(elem) = self.insn_at(n - 1) else {
                return false;
            };
            let fused = match elem.op {
                Opcode::ElemRel => Opcode::LdElemRel,
                Opcode::ElemAbs => Opcode::LdElemAbs,
                Opcode::ElemRelAt => Opcode::LdElemRelAt,
                Opcode::ElemAbsAt => Opcode::LdElemAbsAt,
                _ => return false,
            };
            let spec: Vec<u8> = elem.immediates.to_vec();
            self.drop_from(n - 1);
            self.start(fused);
            self.code.push(ty as u8);
            self.code.extend_from_slice(&spec);
            true
        }

        /// Before `ST_IND ty 0`: when the value was computed, right after an ELEM_REL/ELEM_ABS
        /// that gave the address, by instructions that cannot trap (loads of verified static
        /// addresses, pushes, integer and REAL/LREAL arithmetic but division, comparisons,
        /// conversions that cannot fail), the ELEM is removed and the store becomes
        /// `ST_ELEM_REL`/`ST_ELEM_ABS ty`: the index is then checked after the value is
        /// computed, which nothing can observe (but a full operand stack, where the value's
        /// push then traps STACK_OVERFLOW before a bad index would trap). True when fused.
        fn fuse_element_store(&mut self, ty: MemType) -> bool {
            let n = self.insn_starts.len();
            // Walk back over the value's instructions: `need` cells still to be accounted for.
            let mut need = 1i64;
            let mut k = n;
            while need > 0 {
                if k == 0 {
                    return false;
                }
                k -= 1;
                let Some(d) = self.insn_at(k) else {
                    return false;
                };
                if !pure(&d) {
                    return false;
                }
                let Some((pops, pushes)) = crate::isa::stack_effect(d.op) else {
                    return false;
                };
                need += pops as i64 - pushes as i64;
            }
            if need != 0 || k == 0 || !self.rewritable_from(k - 1) {
                return false;
            }
            // The value's code must not read the address under it (e.g. `DUP`).
            let mut depth = 0u32;
            for j in k..n {
                let Some((pops, pushes)) =
                    self.insn_at(j).and_then(|d| crate::isa::stack_effect(d.op))
                else {
                    return false;
                };
                if pops > depth {
                    return false;
                }
                depth = depth - pops + pushes;
            }
            let Some(elem) = self.insn_at(k - 1) else {
                return false;
            };
            let fused = match elem.op {
                Opcode::ElemRel => Opcode::StElemRel,
                Opcode::ElemAbs => Opcode::StElemAbs,
                // The index variable is then read after the value is computed, which pure
                // code cannot change.
                Opcode::ElemRelAt => Opcode::StElemRelAt,
                Opcode::ElemAbsAt => Opcode::StElemAbsAt,
                _ => return false,
            };
            let spec: Vec<u8> = elem.immediates.to_vec();
            // Remove the ELEM: the value's code moves down by its size.
            let (from, size) = (self.insn_starts[k - 1] as usize, elem.op.size());
            self.code.drain(from..from + size);
            self.insn_starts.remove(k - 1);
            for start in &mut self.insn_starts[k - 1..] {
                *start -= size as u32;
            }
            self.start(fused);
            self.code.push(ty as u8);
            self.code.extend_from_slice(&spec);
            true
        }

        /// Before a JZ/JNZ: a directly preceding comparison is fused into JUMP_IF_NOT/JUMP_IF,
        /// a comparison with an immediate (OP_IMM) into JUMP_IF_NOT_IMM/JUMP_IF_IMM: the
        /// comparison and the immediate (if any).
        fn take_comparison(&mut self) -> Option<(Opcode, Option<u32>)> {
            let n = self.insn_starts.len();
            if n == 0 || !self.rewritable_from(n - 1) {
                return None;
            }
            let d = self.insn_at(n - 1)?;
            let taken = if d.op.is_comparison() {
                (d.op, None)
            } else if d.op == Opcode::OpImm
                && let Some(cmp) = Opcode::from_u8(d.immediates[0]).filter(|c| c.is_comparison())
            {
                (cmp, Some(read_u32(d.immediates, 1)))
            } else {
                return None;
            };
            self.drop_from(n - 1);
            Some(taken)
        }

        fn jump_on(&mut self, when: bool, taken: (Opcode, Option<u32>), target: Label) {
            match taken {
                (cmp, None) => self.jump_if(when, cmp, target),
                (cmp, Some(k)) => {
                    // A frame variable compared with the immediate: JUMP_IF(_NOT)_REL_IMM.
                    let n = self.insn_starts.len();
                    if n >= 1
                        && self.rewritable_from(n - 1)
                        && let Some((ty, off)) = self
                            .insn_at(n - 1)
                            .filter(|d| d.op == Opcode::LdRel)
                            .map(|d| (d.immediates[0], read_u32(d.immediates, 1)))
                    {
                        self.drop_from(n - 1);
                        self.start(if when {
                            Opcode::JumpIfRelImm
                        } else {
                            Opcode::JumpIfNotRelImm
                        });
                        self.code.push(cmp as u8);
                        self.code.push(ty);
                        self.code.extend_from_slice(&off.to_le_bytes());
                        self.code.extend_from_slice(&k.to_le_bytes());
                        self.fixups.push((self.code.len(), target));
                        self.code.extend_from_slice(&0u32.to_le_bytes());
                        return;
                    }
                    self.start(if when {
                        Opcode::JumpIfImm
                    } else {
                        Opcode::JumpIfNotImm
                    });
                    self.code.push(cmp as u8);
                    self.code.extend_from_slice(&k.to_le_bytes());
                    self.fixups.push((self.code.len(), target));
                    self.code.extend_from_slice(&0u32.to_le_bytes());
                }
            }
        }

        /// Before a store of `width` bytes: a directly preceding SEXT/ZEXT to at least that
        /// width is redundant (the store truncates) and is dropped.
        fn drop_redundant_extension(&mut self, width: usize) {
            let n = self.insn_starts.len();
            if n == 0 || !self.rewritable_from(n - 1) {
                return;
            }
            if let Some(d) = self.insn_at(n - 1)
                && matches!(d.op, Opcode::Sext | Opcode::Zext)
                && d.immediates[0] as usize >= 8 * width
            {
                self.drop_from(n - 1);
            }
        }

        fn name_ref(&mut self, name: &str) -> (u32, u16) {
            let off = self.names.len() as u32;
            let len = name.len().min(u16::MAX as usize);
            self.names.extend_from_slice(&name.as_bytes()[..len]);
            (off, len as u16)
        }

        // ---- data ----

        /// Ensures data memory is at least `size` bytes.
        pub fn reserve_data(&mut self, size: u32) {
            self.data_size = self.data_size.max(size);
        }

        /// Current data size.
        pub fn data_size(&self) -> u32 {
            self.data_size
        }

        /// Bump-allocates `size` bytes aligned to `align` (a power of two) and returns the address.
        pub fn alloc_data(&mut self, size: u32, align: u32) -> u32 {
            let align = align.max(1);
            let addr = self.data_size.div_ceil(align) * align;
            self.data_size = addr + size;
            addr
        }

        /// Sets initial bytes at `addr` (grows data memory if needed).
        pub fn set_init(&mut self, addr: u32, bytes: &[u8]) {
            let end = addr as usize + bytes.len();
            if self.init.len() < end {
                self.init.resize(end, 0);
            }
            self.init[addr as usize..end].copy_from_slice(bytes);
            self.reserve_data(end as u32);
        }

        /// Writes the initial header of a `STRING[max_len]` at `addr` with initial text `text`
        /// (truncated to `max_len`).
        pub fn init_string(&mut self, addr: u32, max_len: u16, text: &str) {
            let len = text.len().min(max_len as usize);
            let mut bytes = Vec::with_capacity(4 + max_len as usize);
            bytes.extend_from_slice(&max_len.to_le_bytes());
            bytes.extend_from_slice(&(len as u16).to_le_bytes());
            bytes.extend_from_slice(&text.as_bytes()[..len]);
            bytes.resize(4 + max_len as usize, 0);
            self.set_init(addr, &bytes);
        }

        /// Adds a constant-pool cell (deduplicated) and returns its index.
        pub fn add_const(&mut self, cell: u64) -> u16 {
            if let Some(i) = self.consts.iter().position(|&c| c == cell) {
                return i as u16;
            }
            self.consts.push(cell);
            (self.consts.len() - 1) as u16
        }

        // ---- tables ----

        /// Declares a POU (so calls can be emitted before its body).
        pub fn declare_pou(
            &mut self,
            name: &str,
            arg_cells: u8,
            ret_cells: u8,
            frame_size: u32,
        ) -> PouId {
            self.pous.push(PouDef {
                name: name.into(),
                arg_cells,
                ret_cells,
                frame_size,
                code_start: None,
                code_end: None,
            });
            PouId((self.pous.len() - 1) as u16)
        }

        /// Changes a declared POU's frame size (e.g. once its layout is known).
        pub fn set_frame_size(&mut self, pou: PouId, frame_size: u32) {
            self.pous[pou.0 as usize].frame_size = frame_size;
        }

        /// Starts the POU's code at the current offset.
        pub fn begin_pou(&mut self, pou: PouId) {
            self.pous[pou.0 as usize].code_start = Some(self.code.len() as u32);
        }

        /// Ends the POU's code at the current offset (its last instruction should be RET or JMP).
        pub fn end_pou(&mut self, pou: PouId) {
            self.pous[pou.0 as usize].code_end = Some(self.code.len() as u32);
        }

        /// Adds a task and returns its index.
        pub fn add_task(&mut self, task: &TaskDef) -> usize {
            let (off, len) = self.name_ref(&task.name);
            let r = &mut self.tasks;
            r.extend_from_slice(&off.to_le_bytes());
            r.extend_from_slice(&len.to_le_bytes());
            r.push(task.kind as u8);
            r.push(task.priority);
            r.extend_from_slice(&task.pou.0.to_le_bytes());
            r.extend_from_slice(&0u16.to_le_bytes());
            r.extend_from_slice(&task.instance_base.to_le_bytes());
            r.extend_from_slice(&task.watchdog_budget.to_le_bytes());
            r.extend_from_slice(&task.interval_ns.to_le_bytes());
            r.extend_from_slice(&0u32.to_le_bytes());
            self.tasks.len() / TASK_RECORD - 1
        }

        /// Makes task `task` (an index from [`ImageBuilder::add_task`]) an event task released
        /// by the rising edge of the BOOL at data address `addr`.
        pub fn set_task_trigger(&mut self, task: usize, addr: u32) {
            let at = task * TASK_RECORD + 28;
            self.tasks[at..at + 4].copy_from_slice(&addr.saturating_add(1).to_le_bytes());
        }

        /// Adds a variable-map entry (`size` = width for scalars, 4 + max_len for STRING).
        pub fn add_var(&mut self, name: &str, ty: VarType, flags: u8, addr: u32, size: u32) {
            let (off, len) = self.name_ref(name);
            let r = &mut self.vars;
            r.extend_from_slice(&off.to_le_bytes());
            r.extend_from_slice(&len.to_le_bytes());
            r.push(ty as u8);
            r.push(flags);
            r.extend_from_slice(&addr.to_le_bytes());
            r.extend_from_slice(&size.to_le_bytes());
        }

        /// Adds a located variable (see [`crate::located`]).
        pub fn add_located(&mut self, v: &crate::located::Located) {
            let r = &mut self.located;
            r.extend_from_slice(&v.address.to_le_bytes());
            r.extend_from_slice(&v.location.byte.to_le_bytes());
            r.push(v.location.area.code());
            r.push(v.location.width.code());
            r.push(v.location.bit);
            r.push(0);
        }

        /// Adds an object record (see [`Image::object`]); `parent` is the index of the
        /// smallest record added before that contains it. Returns the new record's index.
        pub fn add_object(&mut self, start: u32, len: u32, parent: Option<u32>) -> u32 {
            self.objects.extend_from_slice(&start.to_le_bytes());
            self.objects.extend_from_slice(&len.to_le_bytes());
            self.objects
                .extend_from_slice(&parent.map_or(0, |p| p + 1).to_le_bytes());
            self.object_count() - 1
        }

        /// Number of object records added so far.
        pub fn object_count(&self) -> u32 {
            (self.objects.len() / OBJECT_RECORD) as u32
        }

        /// Adds a class whose methods are `(slot, pou, parameter frame)` (any order; stored
        /// sorted by slot) and returns its class id (the value its instances hold at their
        /// first byte).
        pub fn add_class(&mut self, name: &str, methods: &[(u16, PouId, u32)]) -> u32 {
            let (off, len) = self.name_ref(name);
            let first = (self.dispatch.len() / DISPATCH_RECORD) as u32;
            let mut sorted = methods.to_vec();
            sorted.sort_by_key(|m| m.0);
            for (slot, pou, frame) in &sorted {
                self.dispatch.extend_from_slice(&slot.to_le_bytes());
                self.dispatch.extend_from_slice(&pou.0.to_le_bytes());
                self.dispatch.extend_from_slice(&frame.to_le_bytes());
            }
            let r = &mut self.classes;
            r.extend_from_slice(&off.to_le_bytes());
            r.extend_from_slice(&len.to_le_bytes());
            r.extend_from_slice(&0u16.to_le_bytes());
            r.extend_from_slice(&first.to_le_bytes());
            r.extend_from_slice(&(sorted.len() as u32).to_le_bytes());
            (self.classes.len() / CLASS_RECORD - 1) as u32
        }

        /// Adds a shared-variable record for variable record `var` (see [`Image::shared`]).
        pub fn add_shared(
            &mut self,
            var: u32,
            direction: SharedDirection,
            location: SourceLocation,
        ) {
            let r = &mut self.shared;
            r.extend_from_slice(&var.to_le_bytes());
            r.push(direction.code());
            r.push(0);
            r.extend_from_slice(&location.file.to_le_bytes());
            r.extend_from_slice(&location.line.to_le_bytes());
            r.extend_from_slice(&location.column.to_le_bytes());
        }

        /// Number of variable records added so far (the next one's index).
        pub fn var_count(&self) -> u32 {
            (self.vars.len() / VAR_RECORD) as u32
        }

        /// Adds a source file name and returns its index.
        pub fn add_file(&mut self, name: &str) -> u16 {
            let (off, len) = self.name_ref(name);
            self.files.extend_from_slice(&off.to_le_bytes());
            self.files.extend_from_slice(&len.to_le_bytes());
            self.files.extend_from_slice(&0u16.to_le_bytes());
            (self.files.len() / FILE_RECORD - 1) as u16
        }

        /// Records that code emitted from now on comes from `file:line:column`.
        pub fn source_location(&mut self, file: u16, line: u32, column: u32) {
            let offset = self.code.len() as u32;
            self.barrier = offset;
            // Replace a record at the same offset so the table stays strictly sorted.
            if self.srclocs.len() >= SRCLOC_RECORD {
                let last = self.srclocs.len() - SRCLOC_RECORD;
                if read_u32(&self.srclocs, last) == offset {
                    self.srclocs.truncate(last);
                }
            }
            let r = &mut self.srclocs;
            r.extend_from_slice(&offset.to_le_bytes());
            r.extend_from_slice(&line.to_le_bytes());
            r.extend_from_slice(&column.to_le_bytes());
            r.extend_from_slice(&file.to_le_bytes());
            r.extend_from_slice(&0u16.to_le_bytes());
        }

        // ---- labels ----

        /// A new unbound label.
        pub fn new_label(&mut self) -> Label {
            self.labels.push(None);
            Label((self.labels.len() - 1) as u32)
        }

        /// Binds `label` to the current code offset.
        pub fn bind(&mut self, label: Label) {
            self.barrier = self.code.len() as u32;
            self.labels[label.0 as usize] = Some(self.code.len() as u32);
        }

        /// The current code offset.
        pub fn code_offset(&self) -> u32 {
            self.code.len() as u32
        }

        // ---- emission ----

        /// Appends raw bytes (for tests of the verifier).
        pub fn emit_raw(&mut self, bytes: &[u8]) {
            self.code.extend_from_slice(bytes);
            self.barrier = self.code.len() as u32;
        }

        /// Emits an instruction without operands (panics in debug if `op` has operands).
        ///
        /// The builder fuses common sequences as they are emitted (same effect, fewer
        /// dispatches, never more stack; see [`ImageBuilder::disable_fusion`] and the ISA's
        /// "Fused instructions and superinstructions"):
        ///
        /// * array addressing `CHK_INDEX; [PUSH lo; SUB]; [PUSH s; MUL]; ADD` → `INDEX`;
        ///   `LD_REL i; ELEM_*` → `ELEM_*_AT`; `ELEM_*[_AT]; LD_IND ty 0` → `LD_ELEM_*[_AT]`;
        ///   `ELEM_*[_AT]; <pure value>; ST_IND ty 0` → `<pure value>; ST_ELEM_*[_AT]`;
        /// * `PUSH_I32 k; ADD|SUB` → `ADD_IMM`; `PUSH_I32 k; op` → `OP_IMM` (also `PUSH_U32`
        ///   where the cell is the same); `LD_REL|LD_ABS; op` → `OP_REL|OP_ABS`; `LD_REL a;
        ///   LD_REL b; op` → `OP_REL_REL`; `LD ty x; ADD_IMM k; ST ty x` → `INC_*`;
        /// * `<comparison>; JZ|JNZ` → `JUMP_IF_NOT|JUMP_IF`, with an immediate operand →
        ///   `JUMP_IF_NOT_IMM|JUMP_IF_IMM`, on a frame variable → `JUMP_IF_NOT_REL_IMM|
        ///   JUMP_IF_REL_IMM` (also `LD_REL x; JZ|JNZ`, a test against 0); `NOT_BOOL; JZ` →
        ///   `JNZ` (and the reverse);
        /// * `PUSH_U32|PUSH_I64 c; NEG_F32|NEG_F64` → the negated constant; a `SEXT`/`ZEXT`
        ///   directly before a store that truncates anyway is dropped.
        ///
        /// Fusion never crosses a bound label, a source location or raw bytes.
        pub fn op(&mut self, op: Opcode) {
            debug_assert!(op.operands().is_empty(), "{} needs operands", op.mnemonic());
            if matches!(op, Opcode::NegF32 | Opcode::NegF64) && self.fold_negation(op) {
                return;
            }
            self.start(op);
            if matches!(op, Opcode::Add | Opcode::Sub) && self.fuse_arithmetic(op) {
                return;
            }
            if op.is_binary() {
                self.fuse_operand(op);
            }
        }

        fn op_target(&mut self, op: Opcode, target: Label) {
            self.start(op);
            self.fixups.push((self.code.len(), target));
            self.code.extend_from_slice(&0u32.to_le_bytes());
        }

        fn op_type_addr(&mut self, op: Opcode, ty: MemType, addr: u32) {
            if matches!(op, Opcode::StAbs | Opcode::StRel | Opcode::StInd) {
                self.drop_redundant_extension(ty.width());
            }
            let fused = match op {
                Opcode::StRel => self.fuse_increment(Opcode::LdRel, ty, addr),
                Opcode::StAbs => self.fuse_increment(Opcode::LdAbs, ty, addr),
                Opcode::LdInd if addr == 0 => self.fuse_element_load(ty),
                Opcode::StInd if addr == 0 => self.fuse_element_store(ty),
                _ => false,
            };
            if fused {
                return;
            }
            self.start(op);
            self.code.push(ty as u8);
            self.code.extend_from_slice(&addr.to_le_bytes());
        }

        /// NOP.
        pub fn nop(&mut self) {
            self.op(Opcode::Nop);
        }
        /// PUSH_I32 (sign-extended).
        pub fn push_i32(&mut self, v: i32) {
            self.start(Opcode::PushI32);
            self.code.extend_from_slice(&v.to_le_bytes());
        }
        /// PUSH_U32 (zero-extended).
        pub fn push_u32(&mut self, v: u32) {
            self.start(Opcode::PushU32);
            self.code.extend_from_slice(&v.to_le_bytes());
        }
        /// PUSH_I64.
        pub fn push_i64(&mut self, v: i64) {
            self.start(Opcode::PushI64);
            self.code.extend_from_slice(&v.to_le_bytes());
        }
        /// Pushes an integer with the shortest encoding.
        pub fn push_int(&mut self, v: i64) {
            if let Ok(small) = i32::try_from(v) {
                self.push_i32(small);
            } else if let Ok(small) = u32::try_from(v) {
                self.push_u32(small);
            } else {
                self.push_i64(v);
            }
        }
        /// Pushes a REAL.
        pub fn push_f32(&mut self, v: f32) {
            self.push_u32(v.to_bits());
        }
        /// Pushes an LREAL.
        pub fn push_f64(&mut self, v: f64) {
            self.push_i64(v.to_bits() as i64);
        }
        /// PUSH_CONST.
        pub fn push_const(&mut self, index: u16) {
            self.start(Opcode::PushConst);
            self.code.extend_from_slice(&index.to_le_bytes());
        }
        /// DROP.
        pub fn drop_(&mut self) {
            self.op(Opcode::Drop);
        }
        /// DUP.
        pub fn dup(&mut self) {
            self.op(Opcode::Dup);
        }
        /// SWAP.
        pub fn swap(&mut self) {
            self.op(Opcode::Swap);
        }
        /// OVER.
        pub fn over(&mut self) {
            self.op(Opcode::Over);
        }
        /// LD_ABS.
        pub fn ld_abs(&mut self, ty: MemType, addr: u32) {
            self.op_type_addr(Opcode::LdAbs, ty, addr);
        }
        /// ST_ABS.
        pub fn st_abs(&mut self, ty: MemType, addr: u32) {
            self.op_type_addr(Opcode::StAbs, ty, addr);
        }
        /// LD_REL.
        pub fn ld_rel(&mut self, ty: MemType, offset: u32) {
            self.op_type_addr(Opcode::LdRel, ty, offset);
        }
        /// ST_REL.
        pub fn st_rel(&mut self, ty: MemType, offset: u32) {
            self.op_type_addr(Opcode::StRel, ty, offset);
        }
        /// LD_IND.
        pub fn ld_ind(&mut self, ty: MemType, offset: u32) {
            self.op_type_addr(Opcode::LdInd, ty, offset);
        }
        /// ST_IND.
        pub fn st_ind(&mut self, ty: MemType, offset: u32) {
            self.op_type_addr(Opcode::StInd, ty, offset);
        }
        /// LEA_REL.
        pub fn lea_rel(&mut self, offset: u32) {
            self.start(Opcode::LeaRel);
            self.code.extend_from_slice(&offset.to_le_bytes());
        }
        /// COPY.
        pub fn copy(&mut self, len: u32) {
            self.start(Opcode::Copy);
            self.code.extend_from_slice(&len.to_le_bytes());
        }
        /// NOW.
        pub fn now(&mut self) {
            self.op(Opcode::Now);
        }
        /// ROL/ROR/SEXT/ZEXT with a width operand.
        pub fn op_width(&mut self, op: Opcode, width: u8) {
            debug_assert!(matches!(
                op,
                Opcode::Rol | Opcode::Ror | Opcode::Sext | Opcode::Zext
            ));
            self.start(op);
            self.code.push(width);
        }
        /// F32_TO_INT / F64_TO_INT.
        pub fn float_to_int(&mut self, op: Opcode, target: MemType, mode: RoundMode) {
            debug_assert!(matches!(op, Opcode::F32ToInt | Opcode::F64ToInt));
            self.start(op);
            self.code.push(target as u8);
            self.code.push(mode as u8);
        }
        /// JMP.
        pub fn jmp(&mut self, target: Label) {
            self.op_target(Opcode::Jmp, target);
        }
        /// JZ (fused with a preceding comparison into JUMP_IF_NOT or JUMP_IF_NOT_IMM; after
        /// NOT_BOOL it is JNZ; a frame variable tested directly becomes JUMP_IF_REL_IMM).
        pub fn jz(&mut self, target: Label) {
            self.jump_on_zero(true, target);
        }
        /// JNZ (fused as [`ImageBuilder::jz`] is, with the opposite sense).
        pub fn jnz(&mut self, target: Label) {
            self.jump_on_zero(false, target);
        }
        /// JZ (`zero`) or JNZ, fused with what computed the tested cell.
        fn jump_on_zero(&mut self, mut zero: bool, target: Label) {
            let n = self.insn_starts.len();
            // NOT_BOOL then JZ is JNZ (and the reverse).
            if n >= 1
                && self.rewritable_from(n - 1)
                && self.insn_at(n - 1).map(|d| d.op) == Some(Opcode::NotBool)
            {
                self.drop_from(n - 1);
                zero = !zero;
            }
            if let Some(taken) = self.take_comparison() {
                self.jump_on(!zero, taken, target);
                return;
            }
            let n = self.insn_starts.len();
            if !self.no_fusion
                && n >= 1
                && self.rewritable_from(n - 1)
                && self.insn_at(n - 1).map(|d| d.op) == Some(Opcode::LdRel)
            {
                // `LD_REL; JZ` is a frame variable compared with 0.
                self.jump_on(
                    false,
                    (if zero { Opcode::Ne } else { Opcode::Eq }, Some(0)),
                    target,
                );
                return;
            }
            self.op_target(if zero { Opcode::Jz } else { Opcode::Jnz }, target);
        }
        /// JUMP_IF (`when = true`) / JUMP_IF_NOT: compare the two top cells with `cmp` and jump
        /// (fused with a directly preceding `PUSH_I32 k` into JUMP_IF_IMM/JUMP_IF_NOT_IMM).
        pub fn jump_if(&mut self, when: bool, cmp: Opcode, target: Label) {
            debug_assert!(cmp.is_comparison());
            let n = self.insn_starts.len();
            if n >= 1
                && self.rewritable_from(n - 1)
                && let Some(k) = self
                    .insn_at(n - 1)
                    .filter(|d| d.op == Opcode::PushI32)
                    .map(|d| read_u32(d.immediates, 0))
            {
                self.drop_from(n - 1);
                self.jump_on(when, (cmp, Some(k)), target);
                return;
            }
            self.start(if when {
                Opcode::JumpIf
            } else {
                Opcode::JumpIfNot
            });
            self.code.push(cmp as u8);
            self.fixups.push((self.code.len(), target));
            self.code.extend_from_slice(&0u32.to_le_bytes());
        }
        /// ADD_IMM.
        pub fn add_imm(&mut self, imm: i32) {
            self.start(Opcode::AddImm);
            self.code.extend_from_slice(&imm.to_le_bytes());
        }
        /// CALL.
        pub fn call(&mut self, pou: PouId) {
            self.start(Opcode::Call);
            self.code.extend_from_slice(&pou.0.to_le_bytes());
        }
        /// RET.
        pub fn ret(&mut self) {
            self.op(Opcode::Ret);
        }
        /// CALL_BUILTIN.
        pub fn call_builtin(&mut self, builtin: Builtin) {
            self.start(Opcode::CallBuiltin);
            self.code.extend_from_slice(&(builtin as u16).to_le_bytes());
        }
        fn op_range(&mut self, op: Opcode, lo: u64, hi: u64) {
            self.start(op);
            self.code.extend_from_slice(&lo.to_le_bytes());
            self.code.extend_from_slice(&hi.to_le_bytes());
        }
        /// CHK_INDEX.
        pub fn chk_index(&mut self, lo: i64, hi: i64) {
            self.op_range(Opcode::ChkIndex, lo as u64, hi as u64);
        }
        /// CHK_RANGE_S.
        pub fn chk_range_s(&mut self, lo: i64, hi: i64) {
            self.op_range(Opcode::ChkRangeS, lo as u64, hi as u64);
        }
        /// CHK_RANGE_U.
        pub fn chk_range_u(&mut self, lo: u64, hi: u64) {
            self.op_range(Opcode::ChkRangeU, lo, hi);
        }
        /// INDEX: `[base i] -> [base + (i - lo) * stride]`, trapping unless `lo <= i <= hi`.
        pub fn index(&mut self, lo: i64, hi: i64, stride: u32) {
            self.op_range(Opcode::Index, lo as u64, hi as u64);
            self.code.extend_from_slice(&stride.to_le_bytes());
        }
        fn elem(&mut self, op: Opcode, addr: u32, lo: i64, hi: i64, stride: u32) {
            // The index just loaded from a frame variable: ELEM_REL_AT/ELEM_ABS_AT.
            let n = self.insn_starts.len();
            if n >= 1
                && self.rewritable_from(n - 1)
                && let Some((ity, ioff)) = self
                    .insn_at(n - 1)
                    .filter(|d| d.op == Opcode::LdRel)
                    .map(|d| (d.immediates[0], read_u32(d.immediates, 1)))
            {
                self.drop_from(n - 1);
                self.start(if op == Opcode::ElemRel {
                    Opcode::ElemRelAt
                } else {
                    Opcode::ElemAbsAt
                });
                self.elem_spec(addr, lo, hi, stride);
                self.code.push(ity);
                self.code.extend_from_slice(&ioff.to_le_bytes());
                return;
            }
            self.start(op);
            self.elem_spec(addr, lo, hi, stride);
        }
        fn elem_spec(&mut self, addr: u32, lo: i64, hi: i64, stride: u32) {
            self.code.extend_from_slice(&addr.to_le_bytes());
            self.code.extend_from_slice(&lo.to_le_bytes());
            self.code.extend_from_slice(&hi.to_le_bytes());
            self.code.extend_from_slice(&stride.to_le_bytes());
        }
        /// An element access indexed by the `index` frame variable `(type, offset)`:
        /// ELEM_*_AT (`ty` None), LD_ELEM_*_AT (`load`) or ST_ELEM_*_AT.
        #[allow(clippy::too_many_arguments)]
        pub fn elem_at(
            &mut self,
            rel: bool,
            ty: Option<(MemType, bool)>,
            addr: u32,
            lo: i64,
            hi: i64,
            stride: u32,
            index: (MemType, u32),
        ) {
            let op = match (rel, ty) {
                (true, None) => Opcode::ElemRelAt,
                (false, None) => Opcode::ElemAbsAt,
                (true, Some((_, true))) => Opcode::LdElemRelAt,
                (false, Some((_, true))) => Opcode::LdElemAbsAt,
                (true, Some((_, false))) => Opcode::StElemRelAt,
                (false, Some((_, false))) => Opcode::StElemAbsAt,
            };
            self.start(op);
            if let Some((ty, _)) = ty {
                self.code.push(ty as u8);
            }
            self.elem_spec(addr, lo, hi, stride);
            self.code.push(index.0 as u8);
            self.code.extend_from_slice(&index.1.to_le_bytes());
        }
        /// ELEM_REL: `[i] -> [base + off + (i - lo) * stride]` (a following `LD_IND ty 0` fuses
        /// into LD_ELEM_REL, a following trap-free value and `ST_IND ty 0` into ST_ELEM_REL).
        pub fn elem_rel(&mut self, off: u32, lo: i64, hi: i64, stride: u32) {
            self.elem(Opcode::ElemRel, off, lo, hi, stride);
        }
        /// ELEM_ABS: `[i] -> [addr + (i - lo) * stride]` (fuses as ELEM_REL does).
        pub fn elem_abs(&mut self, addr: u32, lo: i64, hi: i64, stride: u32) {
            self.elem(Opcode::ElemAbs, addr, lo, hi, stride);
        }
        fn elem_access(
            &mut self,
            op: Opcode,
            ty: MemType,
            addr: u32,
            lo: i64,
            hi: i64,
            stride: u32,
        ) {
            self.start(op);
            self.code.push(ty as u8);
            self.code.extend_from_slice(&addr.to_le_bytes());
            self.code.extend_from_slice(&lo.to_le_bytes());
            self.code.extend_from_slice(&hi.to_le_bytes());
            self.code.extend_from_slice(&stride.to_le_bytes());
        }
        /// LD_ELEM_REL (`rel`) or LD_ELEM_ABS: `[i] -> [v]` (what the builder makes of ELEM
        /// and `LD_IND ty 0`).
        pub fn ld_elem(
            &mut self,
            rel: bool,
            ty: MemType,
            addr: u32,
            lo: i64,
            hi: i64,
            stride: u32,
        ) {
            let op = if rel {
                Opcode::LdElemRel
            } else {
                Opcode::LdElemAbs
            };
            self.elem_access(op, ty, addr, lo, hi, stride);
        }
        /// ST_ELEM_REL (`rel`) or ST_ELEM_ABS: `[i v] -> []`.
        pub fn st_elem(
            &mut self,
            rel: bool,
            ty: MemType,
            addr: u32,
            lo: i64,
            hi: i64,
            stride: u32,
        ) {
            let op = if rel {
                Opcode::StElemRel
            } else {
                Opcode::StElemAbs
            };
            self.elem_access(op, ty, addr, lo, hi, stride);
        }
        /// INC_REL (`rel`) or INC_ABS: adds `imm` to an integer variable in place.
        pub fn inc(&mut self, rel: bool, ty: MemType, addr: u32, imm: i32) {
            self.start(if rel { Opcode::IncRel } else { Opcode::IncAbs });
            self.code.push(ty as u8);
            self.code.extend_from_slice(&addr.to_le_bytes());
            self.code.extend_from_slice(&imm.to_le_bytes());
        }
        /// OP_IMM: `[a] -> [a op imm]` for a binary operator `op`.
        pub fn op_imm(&mut self, op: Opcode, imm: i32) {
            debug_assert!(op.is_binary());
            self.start(Opcode::OpImm);
            self.code.push(op as u8);
            self.code.extend_from_slice(&imm.to_le_bytes());
        }
        /// OP_REL (`rel`) or OP_ABS: `[a] -> [a op v]`, `v` the `ty` variable at `addr`.
        pub fn op_at(&mut self, rel: bool, op: Opcode, ty: MemType, addr: u32) {
            debug_assert!(op.is_binary());
            self.start(if rel { Opcode::OpRel } else { Opcode::OpAbs });
            self.code.push(op as u8);
            self.code.push(ty as u8);
            self.code.extend_from_slice(&addr.to_le_bytes());
        }
        /// OP_REL_REL: `[] -> [a op b]` for two frame variables `(type, offset)`.
        pub fn op_rel_rel(&mut self, op: Opcode, a: (MemType, u32), b: (MemType, u32)) {
            debug_assert!(op.is_binary());
            self.start(Opcode::OpRelRel);
            self.code.push(op as u8);
            self.code.push(a.0 as u8);
            self.code.extend_from_slice(&a.1.to_le_bytes());
            self.code.push(b.0 as u8);
            self.code.extend_from_slice(&b.1.to_le_bytes());
        }
        /// JUMP_IF_IMM (`when`) / JUMP_IF_NOT_IMM: `[a] -> []`, jumps on `cmp(a, imm)` (fused
        /// with a directly preceding LD_REL into JUMP_IF_REL_IMM/JUMP_IF_NOT_REL_IMM).
        pub fn jump_if_imm(&mut self, when: bool, cmp: Opcode, imm: i32, target: Label) {
            debug_assert!(cmp.is_comparison());
            self.jump_on(when, (cmp, Some(imm as u32)), target);
        }
        /// SEL_IF: `[a b] -> [if cmp(a, b) { b } else { a }]` (MAX: `LT_x`, MIN: `GT_x`).
        pub fn sel_if(&mut self, cmp: Opcode) {
            debug_assert!(cmp.is_comparison());
            self.start(Opcode::SelIf);
            self.code.push(cmp as u8);
        }
        /// REF_MAKE for `size` bytes.
        pub fn ref_make(&mut self, size: u32) {
            self.start(Opcode::RefMake);
            self.code.extend_from_slice(&size.to_le_bytes());
        }
        /// REF_CHECK of an access of `size` bytes.
        pub fn ref_check(&mut self, size: u32) {
            self.start(Opcode::RefCheck);
            self.code.extend_from_slice(&size.to_le_bytes());
        }
        /// REF_ADD.
        pub fn ref_add(&mut self) {
            self.op(Opcode::RefAdd);
        }
        /// CHK_NULL.
        pub fn chk_null(&mut self) {
            self.op(Opcode::ChkNull);
        }
        /// CALL_VIRT of `slot`.
        pub fn call_virt(&mut self, slot: u16) {
            self.start(Opcode::CallVirt);
            self.code.extend_from_slice(&slot.to_le_bytes());
        }
        /// VIRT_FRAME of `slot`.
        pub fn virt_frame(&mut self, slot: u16) {
            self.start(Opcode::VirtFrame);
            self.code.extend_from_slice(&slot.to_le_bytes());
        }
        /// TRY_BEGIN with its handler label.
        pub fn try_begin(&mut self, handler: Label) {
            self.op_target(Opcode::TryBegin, handler);
        }
        /// TRY_END.
        pub fn try_end(&mut self) {
            self.op(Opcode::TryEnd);
        }
        /// THROW.
        pub fn throw(&mut self, trap: Trap) {
            self.start(Opcode::Throw);
            self.code.push(trap.code());
        }
        /// RETHROW.
        pub fn rethrow(&mut self) {
            self.op(Opcode::Rethrow);
        }

        /// Resolves labels and serializes the image.
        pub fn build(&self) -> Result<Vec<u8>, BuildError> {
            let mut code = self.code.clone();
            for &(at, label) in &self.fixups {
                let target =
                    self.labels[label.0 as usize].ok_or(BuildError::UnboundLabel(label.0))?;
                code[at..at + 4].copy_from_slice(&target.to_le_bytes());
            }
            let mut names = self.names.clone();
            let mut pous = Vec::with_capacity(self.pous.len() * POU_RECORD);
            for pou in &self.pous {
                let (Some(start), Some(end)) = (pou.code_start, pou.code_end) else {
                    return Err(BuildError::PouWithoutCode(pou.name.clone()));
                };
                let off = names.len() as u32;
                let len = pou.name.len().min(u16::MAX as usize);
                names.extend_from_slice(&pou.name.as_bytes()[..len]);
                pous.extend_from_slice(&off.to_le_bytes());
                pous.extend_from_slice(&(len as u16).to_le_bytes());
                pous.push(pou.arg_cells);
                pous.push(pou.ret_cells);
                pous.extend_from_slice(&start.to_le_bytes());
                pous.extend_from_slice(&end.saturating_sub(start).to_le_bytes());
                pous.extend_from_slice(&pou.frame_size.to_le_bytes());
            }
            let consts: Vec<u8> = self.consts.iter().flat_map(|c| c.to_le_bytes()).collect();
            let sections: [&[u8]; SECTION_COUNT] = [
                &code,
                &consts,
                &self.init,
                &pous,
                &self.tasks,
                &self.vars,
                &self.srclocs,
                &self.files,
                &names,
                &self.located,
                &self.shared,
                &self.objects,
                &self.classes,
                &self.dispatch,
            ];
            let total: usize = HEADER_LEN + sections.iter().map(|s| s.len()).sum::<usize>();
            if total > u32::MAX as usize {
                return Err(BuildError::TooLarge);
            }
            let mut out = Vec::with_capacity(total);
            out.extend_from_slice(&MAGIC);
            out.extend_from_slice(&VERSION.to_le_bytes());
            out.extend_from_slice(&(HEADER_LEN as u16).to_le_bytes());
            out.extend_from_slice(&self.data_size.to_le_bytes());
            out.extend_from_slice(&0u32.to_le_bytes());
            let mut offset = HEADER_LEN as u32;
            for s in sections {
                out.extend_from_slice(&offset.to_le_bytes());
                out.extend_from_slice(&(s.len() as u32).to_le_bytes());
                offset += s.len() as u32;
            }
            for s in sections {
                out.extend_from_slice(s);
            }
            Ok(out)
        }
    }
}
