//! The PLC online protocol: how a client (another partition, or `plcctl` in the Linux guest)
//! lists, reads, writes, forces and unforces the variables of a running PLC program, reads
//! its task statistics, stops and starts tasks and downloads a new program, over a pair of
//! queuing ports of the PLC partition (one request message in, one response message out).
//! An interface; no_std, no allocation, and decoding never panics: a malformed or truncated
//! message is an error value.
//!
//! # Versions
//!
//! This is version [`PROTOCOL_VERSION`] (3). Version 3 only adds the operation STORE to
//! version 2 (a version 2 PLC answers it MALFORMED). Version 2 only adds to version 1, whose
//! messages keep their bytes and meaning: the value types 17 to 27 (the date/time types,
//! CHAR, WCHAR, WSTRING, references), the status READ_ONLY, the operation VERSION, and a
//! READ answer names the variable's own type (SINT, UDINT, ...; version 1 said LINT for
//! every signed and ULINT for every unsigned integer, which decode to the same values). A
//! version 1 client keeps working with a version 2 PLC except where it meets what version 2
//! added; a version 2 client asks VERSION (a version 1 PLC answers MALFORMED) to know.
//! A client must expect further value types and statuses in later versions and show what
//! it does not know as such.
//!
//! # Messages (all integers little-endian)
//!
//! Request: `op u8, seq u8, payload`; the response echoes `op` and `seq`, then
//! `status u8` ([`Status`]) and, when the status is OK, the operation's result.
//!
//! | op | request payload | OK result |
//! |---|---|---|
//! | 1 LIST | `from u16` | `total u16, count u8`, then per variable `type u8, name_len u8, name` (from index `from`, as many as fit) |
//! | 2 READ | `name` (the rest of the message) | a value (below), typed as the variable is |
//! | 3 WRITE | a value, then `name` | none |
//! | 4 FORCE | a value, then `name` | none |
//! | 5 UNFORCE | `name` | none |
//! | 6 STATS | `task u8` | `stopped u8, name_len u8, name, count, last, min, mean, max, last_jitter, max_jitter, overruns, faults` (u64 each, times in ns) |
//! | 7 STOP | `task u8` | none |
//! | 8 START | `task u8` | none |
//! | 9 DOWNLOAD_BEGIN | `size u32, crc32 u32` | `max_chunk u16` |
//! | 10 DOWNLOAD_CHUNK | `offset u32`, then 1..=[`MAX_CHUNK`] bytes (the rest of the message) | none |
//! | 11 DOWNLOAD_COMMIT | none | `release u64` |
//! | 12 VERSION (v2) | none | `version u16` |
//! | 13 STORE (v3) | none | `configured u8`, then the sequence numbers (u64, 0 for none) of the boot project and the RETAIN snapshot loaded at the last cold start and of the last ones saved ([`StoreStatus`]) |
//!
//! Which access level ([`Access`], the configuration's `plc.online.access`) each operation
//! needs is [`Op::needs`]: LIST, READ, STATS, VERSION, STORE `monitor`; WRITE, FORCE, UNFORCE,
//! STOP, START `force`; the DOWNLOAD operations `download`. Below it the answer is FORBIDDEN.
//!
//! # Values
//!
//! A value is `type u8` (the variable map's [`VarType`] code, the one LIST shows) and its
//! bytes. A decoder refuses (MALFORMED) a value its type cannot hold.
//!
//! | type | bytes |
//! |---|---|
//! | 0 BOOL | 8: 0 or 1 |
//! | 1-4 SINT, INT, DINT, LINT | 8: the integer, two's complement, within the type's range |
//! | 5-8 USINT..ULINT, 13-16 BYTE..LWORD | 8: the integer, within the type's range |
//! | 9 REAL | 8: the f32 bits in the low half, the high half 0 |
//! | 10 LREAL | 8: the f64 bits |
//! | 11 TIME, 20 LTIME | 8: nanoseconds (`i64`) |
//! | 17 DATE, 21 LDATE (v2) | 8: nanoseconds since 1970-01-01 (`i64`), a whole number of days |
//! | 18 TOD, 22 LTOD (v2) | 8: nanoseconds since midnight, below one day |
//! | 19 DT, 23 LDT (v2) | 8: nanoseconds since 1970-01-01 (`i64`) |
//! | 24 CHAR, 25 WCHAR (v2) | 8: the byte (0..=255), the UTF-16 code unit (0..=65535) |
//! | 12 STRING | `len u16`, then `len` bytes |
//! | 26 WSTRING (v2) | `len u16` (code units), then `2 len` bytes (UTF-16 little-endian) |
//! | 27 REF_TO (v2) | 8: the target's data address, `u64::MAX` for NULL; then `name_len u8, name`: the variable whose first byte the target is (empty when none, or when it does not fit the message) |
//!
//! A client shows a value as its IEC literal ([`plc_vm::literal`]: `TRUE`, `-3`, `0.5`,
//! `T#1s500ms`, `LT#2ms`, `D#2024-06-15`, `TOD#12:30:00`, `DT#2024-06-15-12:30:00`, `'a'`,
//! `"€"`, `'text'`, `"text"`, `REF(Main.x)`, `16#0000012C`, `NULL`) and parses what a user
//! types for a variable the same way, as the variable's type (which READ tells).
//!
//! A WRITE or FORCE value must be of the variable's type or one IEC widens to it without a
//! conversion (TIME to LTIME, DATE to LDATE, TOD to LTOD, DT to LDT, CHAR to WCHAR); any
//! integer type fits an integer or bit-string variable (stored truncated to its width, as
//! version 1 did) and an integer fits TIME; otherwise TYPE_MISMATCH. STRINGs and WSTRINGs
//! may be written (cut to their capacity), not forced (UNSUPPORTED). A READ of a text
//! longer than a message is UNSUPPORTED rather than cut.
//!
//! **References are read-only** (READ_ONLY for WRITE and FORCE, whatever the value): a
//! written address could make the program write through the reference into another
//! variable than the one it referenced (each access is checked against the variable the
//! reference was taken from, so it could not leave the program's data, but the program's
//! logic would be bypassed), a written NULL or stale address would trap the program, an
//! instance reference steers method calls, and addresses mean nothing after a download.
//!
//! **STOP / START.** STOP takes a task out of the scan (an already stopped one stays
//! stopped): it runs no more and its outputs go to their safe values at once, as after a
//! fault; STATS shows it stopped. START lets it run again from the next release; it also
//! restarts a task a trap or the watchdog stopped (as a CODESYS reset of the task: the data
//! keeps its values, the fault is cleared).
//!
//! **Online download.** A new program (the bytecode image `plcc build` writes, `.plcb`)
//! goes over in pieces: DOWNLOAD_BEGIN announces its size and CRC-32 ([`crc32`]: IEEE,
//! reflected, as zlib) and discards any unfinished download; DOWNLOAD_CHUNKs carry its
//! bytes in order (each at the offset where the previous ended; BAD_OFFSET otherwise);
//! DOWNLOAD_COMMIT checks size and checksum, then makes the checks the PLC makes on its
//! configured program at start (image, verifier, tasks against the partition period) and
//! takes over what refers to the running program by address (configured safe values,
//! forces, the watch list) by name. When all of that holds the answer is OK with the
//! release from which the new program runs: it is swapped in between two scan cycles, its
//! RETAIN variables taking the running program's values by name and type (references
//! excepted: they keep the new program's initial value, since an address of the old
//! program means nothing in the new one), every task running and its statistics counted
//! anew (the rest of that batch of requests waits for the next cycle). Any refusal
//! (its reason is logged by the PLC) leaves the running program untouched and ends the
//! download.

#![no_std]

pub mod session;

use plc_vm::builtins::NS_PER_DAY;
use plc_vm::image::VarType;
use plc_vm::isa::TimeKind;
use plc_vm::vm::Value;

/// The protocol version this crate speaks (see "Versions").
pub const PROTOCOL_VERSION: u16 = 3;

/// Largest message either way (a queuing port of the PLC must hold it).
pub const MAX_MESSAGE: usize = 256;

/// Most image bytes one DOWNLOAD_CHUNK carries (a message less its head and offset).
pub const MAX_CHUNK: usize = MAX_MESSAGE - 2 - 4;

codes::code_enum! {
    /// Operations.
    pub enum Op: u8 {
        List = 1 => "LIST",
        Read = 2 => "READ",
        Write = 3 => "WRITE",
        Force = 4 => "FORCE",
        Unforce = 5 => "UNFORCE",
        Stats = 6 => "STATS",
        Stop = 7 => "STOP",
        Start = 8 => "START",
        DownloadBegin = 9 => "DOWNLOAD_BEGIN",
        DownloadChunk = 10 => "DOWNLOAD_CHUNK",
        DownloadCommit = 11 => "DOWNLOAD_COMMIT",
        /// The PLC's protocol version (version 2).
        Version = 12 => "VERSION",
        /// What the persistent store loaded and saved (version 3).
        Store = 13 => "STORE",
    }
}

codes::code_enum! {
    /// Outcome of a request.
    pub enum Status: u8 {
        Ok = 0 => "OK",
        /// The message does not decode.
        Malformed = 1 => "MALFORMED",
        /// No variable of that name.
        UnknownName = 2 => "UNKNOWN_NAME",
        /// The value's type does not fit the variable.
        TypeMismatch = 3 => "TYPE_MISMATCH",
        /// The variable is CONSTANT.
        Constant = 4 => "CONSTANT",
        /// The configuration does not allow this client to do that (`plc.online.access`).
        Forbidden = 5 => "FORBIDDEN",
        /// Every force slot is in use.
        TooManyForces = 6 => "TOO_MANY_FORCES",
        /// No task of that number.
        NoSuchTask = 7 => "NO_SUCH_TASK",
        /// Not supported for this variable (e.g. forcing a STRING).
        Unsupported = 8 => "UNSUPPORTED",
        /// A download chunk not at the offset where the previous one ended, or beyond the
        /// announced size.
        BadOffset = 9 => "BAD_OFFSET",
        /// The announced image is larger than the PLC's download buffer.
        TooLarge = 10 => "TOO_LARGE",
        /// The assembled image's CRC-32 is not the announced one.
        ChecksumMismatch = 11 => "CHECKSUM_MISMATCH",
        /// The new program fails the PLC's checks or cannot take over from the running one
        /// (the PLC logs why).
        Refused = 12 => "REFUSED",
        /// A chunk or commit without a download in progress.
        NoDownload = 13 => "NO_DOWNLOAD",
        /// A commit before every announced byte arrived.
        Incomplete = 14 => "INCOMPLETE",
        /// The variable is never changed online: a reference (version 2).
        ReadOnly = 15 => "READ_ONLY",
    }
}

codes::code_enum! {
    /// What a client may do (the configuration's `plc.online.access`), each level
    /// including the ones before it.
    pub enum Access: u8 {
        /// LIST, READ, STATS, VERSION.
        Monitor = 0 => "monitor",
        /// And WRITE, FORCE, UNFORCE, STOP, START.
        Force = 1 => "force",
        /// And the DOWNLOAD operations (a new program).
        Download = 2 => "download",
    }
}

impl Op {
    /// The access level this operation needs.
    pub fn needs(self) -> Access {
        match self {
            Op::List | Op::Read | Op::Stats | Op::Version | Op::Store => Access::Monitor,
            Op::Write | Op::Force | Op::Unforce | Op::Stop | Op::Start => Access::Force,
            Op::DownloadBegin | Op::DownloadChunk | Op::DownloadCommit => Access::Download,
        }
    }
}

/// A decoded request.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request<'a> {
    List { from: u16 },
    Read { name: &'a str },
    Write { name: &'a str, value: Value<'a> },
    Force { name: &'a str, value: Value<'a> },
    Unforce { name: &'a str },
    Stats { task: u8 },
    Stop { task: u8 },
    Start { task: u8 },
    DownloadBegin { size: u32, crc32: u32 },
    DownloadChunk { offset: u32, bytes: &'a [u8] },
    DownloadCommit,
    Version,
    Store,
}

impl Request<'_> {
    pub fn op(&self) -> Op {
        match self {
            Request::List { .. } => Op::List,
            Request::Read { .. } => Op::Read,
            Request::Write { .. } => Op::Write,
            Request::Force { .. } => Op::Force,
            Request::Unforce { .. } => Op::Unforce,
            Request::Stats { .. } => Op::Stats,
            Request::Stop { .. } => Op::Stop,
            Request::Start { .. } => Op::Start,
            Request::DownloadBegin { .. } => Op::DownloadBegin,
            Request::DownloadChunk { .. } => Op::DownloadChunk,
            Request::DownloadCommit => Op::DownloadCommit,
            Request::Version => Op::Version,
            Request::Store => Op::Store,
        }
    }
}

/// Task statistics as STATS returns them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TaskStats<'a> {
    pub name: &'a str,
    pub stopped: bool,
    /// count, last, min, mean, max, last_jitter, max_jitter, overruns, faults.
    pub figures: [u64; 9],
}

/// A writer into a message buffer; every `put` fails cleanly when the buffer is full.
pub struct Writer<'b> {
    buf: &'b mut [u8],
    len: usize,
}

impl<'b> Writer<'b> {
    pub fn new(buf: &'b mut [u8]) -> Self {
        Self { buf, len: 0 }
    }

    pub fn put(&mut self, bytes: &[u8]) -> Option<()> {
        let end = self.len.checked_add(bytes.len())?;
        self.buf.get_mut(self.len..end)?.copy_from_slice(bytes);
        self.len = end;
        Some(())
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Room left.
    pub fn room(&self) -> usize {
        self.buf.len() - self.len
    }

    /// Writes `value` typed by its kind (an `Int` as LINT, a `UInt` as ULINT).
    pub fn value(&mut self, value: &Value) -> Option<()> {
        self.typed_value(natural_type(value), value)
    }

    /// Writes `value` typed as `ty`, the type of the variable it is the value of (as a READ
    /// answers); by its kind when `ty` cannot hold that kind of value.
    pub fn typed_value(&mut self, ty: VarType, value: &Value) -> Option<()> {
        let ty = if holds(ty, value) {
            ty
        } else {
            natural_type(value)
        };
        let bits = match *value {
            Value::Bool(b) => b as u64,
            Value::Int(v) | Value::Time(v) | Value::Temporal(_, v) => v as u64,
            Value::UInt(v) => v,
            Value::Real(v) => v.to_bits() as u64,
            Value::LReal(v) => v.to_bits(),
            Value::Char(c) => c as u64,
            Value::WChar(c) => c as u64,
            Value::String(text) | Value::WString(text) => {
                let unit = if ty == VarType::WString { 2 } else { 1 };
                let units = text.len() / unit;
                self.put(&[ty.code()])?;
                self.put(&u16::try_from(units).ok()?.to_le_bytes())?;
                return self.put(&text[..units * unit]);
            }
            Value::Ref { address, target } => {
                self.put(&[ty.code()])?;
                self.put(&address.map_or(u64::MAX, u64::from).to_le_bytes())?;
                // The name only when it fits whole.
                let name = target
                    .filter(|n| n.len() <= u8::MAX as usize && self.room() > n.len())
                    .unwrap_or("");
                self.put(&[name.len() as u8])?;
                return self.put(name.as_bytes());
            }
        };
        self.put(&[ty.code()])?;
        self.put(&bits.to_le_bytes())
    }
}

/// The type a value is written as when no variable types it.
fn natural_type(value: &Value) -> VarType {
    match *value {
        Value::Bool(_) => VarType::Bool,
        Value::Int(_) => VarType::LInt,
        Value::UInt(_) => VarType::ULInt,
        Value::Real(_) => VarType::Real,
        Value::LReal(_) => VarType::LReal,
        Value::Time(_) => VarType::Time,
        Value::Temporal(kind, _) => VarType::of_time_kind(kind),
        Value::String(_) => VarType::String,
        Value::Char(_) => VarType::Char,
        Value::WChar(_) => VarType::WChar,
        Value::WString(_) => VarType::WString,
        Value::Ref { .. } => VarType::Ref,
    }
}

/// Whether type code `ty` carries `value` (so the decoder gives it back): its kind, and an
/// integer within the type's range.
fn holds(ty: VarType, value: &Value) -> bool {
    let in_range = |v: i128| {
        ty.int_range()
            .is_some_and(|(lo, hi)| (lo..=hi).contains(&v))
    };
    match *value {
        Value::Int(v) => ty.is_signed_int() && in_range(v as i128),
        // CHAR and WCHAR carry `Char` and `WChar`.
        Value::UInt(v) => {
            !ty.is_signed_int()
                && !matches!(ty, VarType::Char | VarType::WChar)
                && in_range(v as i128)
        }
        _ => natural_type(value) == ty,
    }
}

/// A reader over a received message.
pub struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes }
    }

    pub fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let (head, rest) = self.bytes.split_at_checked(n)?;
        self.bytes = rest;
        Some(head)
    }

    pub fn u8(&mut self) -> Option<u8> {
        self.take(1).map(|b| b[0])
    }

    pub fn u16(&mut self) -> Option<u16> {
        self.take(2).map(|b| u16::from_le_bytes([b[0], b[1]]))
    }

    pub fn u32(&mut self) -> Option<u32> {
        self.take(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub fn u64(&mut self) -> Option<u64> {
        self.take(8)
            .map(|b| u64::from_le_bytes(core::array::from_fn(|i| b[i])))
    }

    /// The rest as a name (non-empty UTF-8).
    pub fn name(&mut self) -> Option<&'a str> {
        let rest = core::mem::take(&mut self.bytes);
        core::str::from_utf8(rest).ok().filter(|n| !n.is_empty())
    }

    /// `len u8, bytes` as UTF-8.
    pub fn short_str(&mut self) -> Option<&'a str> {
        let n = self.u8()? as usize;
        core::str::from_utf8(self.take(n)?).ok()
    }

    /// A value (see "Values"), `None` when malformed.
    pub fn value(&mut self) -> Option<Value<'a>> {
        self.typed_value().map(|(_, value)| value)
    }

    /// A value and the type it came as.
    pub fn typed_value(&mut self) -> Option<(VarType, Value<'a>)> {
        let ty = VarType::from_code(self.u8()?)?;
        match ty {
            VarType::String => {
                let n = self.u16()? as usize;
                return self.take(n).map(|text| (ty, Value::String(text)));
            }
            VarType::WString => {
                let n = self.u16()? as usize;
                return self.take(2 * n).map(|text| (ty, Value::WString(text)));
            }
            _ => {}
        }
        let bits = self.u64()?;
        let value = match ty {
            VarType::Bool => Value::Bool(match bits {
                0 => false,
                1 => true,
                _ => return None,
            }),
            VarType::Real => Value::Real(f32::from_bits(u32::try_from(bits).ok()?)),
            VarType::LReal => Value::LReal(f64::from_bits(bits)),
            VarType::Char => Value::Char(u8::try_from(bits).ok()?),
            VarType::WChar => Value::WChar(u16::try_from(bits).ok()?),
            VarType::Ref => {
                let address = match bits {
                    u64::MAX => None,
                    address => Some(u32::try_from(address).ok()?),
                };
                let name = self.short_str()?;
                let target = (!name.is_empty()).then_some(name);
                if address.is_none() && target.is_some() {
                    return None;
                }
                Value::Ref { address, target }
            }
            ty => match (ty.time_kind(), ty.int_range()) {
                (Some(kind), _) => {
                    let ns = bits as i64;
                    let valid = match kind {
                        TimeKind::Date | TimeKind::LDate => ns.rem_euclid(NS_PER_DAY) == 0,
                        TimeKind::Tod | TimeKind::LTod => (0..NS_PER_DAY).contains(&ns),
                        _ => true,
                    };
                    if !valid {
                        return None;
                    }
                    Value::temporal(kind, ns)
                }
                (None, Some((lo, hi))) => {
                    let v = if ty.is_signed_int() {
                        bits as i64 as i128
                    } else {
                        bits as i128
                    };
                    if v < lo || v > hi {
                        return None;
                    }
                    if ty.is_signed_int() {
                        Value::Int(v as i64)
                    } else {
                        Value::UInt(v as u64)
                    }
                }
                (None, None) => return None,
            },
        };
        Some((ty, value))
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
}

/// Writes request `r` with sequence number `seq`; `None` if it does not fit `buf`.
pub fn encode_request(r: &Request, seq: u8, buf: &mut [u8]) -> Option<usize> {
    let mut w = Writer::new(buf);
    w.put(&[r.op().code(), seq])?;
    match r {
        Request::List { from } => w.put(&from.to_le_bytes())?,
        Request::Read { name } | Request::Unforce { name } => w.put(name.as_bytes())?,
        Request::Write { name, value } | Request::Force { name, value } => {
            w.value(value)?;
            w.put(name.as_bytes())?
        }
        Request::Stats { task } | Request::Stop { task } | Request::Start { task } => {
            w.put(&[*task])?
        }
        Request::DownloadBegin { size, crc32 } => {
            w.put(&size.to_le_bytes())?;
            w.put(&crc32.to_le_bytes())?
        }
        Request::DownloadChunk { offset, bytes } => {
            if bytes.is_empty() || bytes.len() > MAX_CHUNK {
                return None;
            }
            w.put(&offset.to_le_bytes())?;
            w.put(bytes)?
        }
        Request::DownloadCommit | Request::Version | Request::Store => {}
    }
    Some(w.len())
}

/// Decodes a request: its sequence number, and the request or why it is malformed
/// (`Err` carries the op byte and sequence number when there were any, for the answer).
pub fn decode_request(bytes: &[u8]) -> Result<(u8, Request<'_>), (u8, u8)> {
    let mut r = Reader::new(bytes);
    let (Some(op), Some(seq)) = (r.u8(), r.u8()) else {
        return Err((bytes.first().copied().unwrap_or(0), 0));
    };
    let fail = (op, seq);
    let kind = Op::from_code(op).ok_or(fail)?;
    let request = match kind {
        Op::List => {
            let from = r.u16().ok_or(fail)?;
            (r.is_empty())
                .then_some(Request::List { from })
                .ok_or(fail)?
        }
        Op::Read => Request::Read {
            name: r.name().ok_or(fail)?,
        },
        Op::Unforce => Request::Unforce {
            name: r.name().ok_or(fail)?,
        },
        Op::Write | Op::Force => {
            let value = r.value().ok_or(fail)?;
            let name = r.name().ok_or(fail)?;
            if kind == Op::Write {
                Request::Write { name, value }
            } else {
                Request::Force { name, value }
            }
        }
        Op::Stats | Op::Stop | Op::Start => {
            let task = r.u8().ok_or(fail)?;
            if !r.is_empty() {
                return Err(fail);
            }
            match kind {
                Op::Stop => Request::Stop { task },
                Op::Start => Request::Start { task },
                _ => Request::Stats { task },
            }
        }
        Op::DownloadBegin => {
            let size = r.u32().ok_or(fail)?;
            let crc32 = r.u32().ok_or(fail)?;
            (r.is_empty())
                .then_some(Request::DownloadBegin { size, crc32 })
                .ok_or(fail)?
        }
        Op::DownloadChunk => {
            let offset = r.u32().ok_or(fail)?;
            let bytes = core::mem::take(&mut r.bytes);
            if bytes.is_empty() || bytes.len() > MAX_CHUNK {
                return Err(fail);
            }
            Request::DownloadChunk { offset, bytes }
        }
        Op::DownloadCommit => r
            .is_empty()
            .then_some(Request::DownloadCommit)
            .ok_or(fail)?,
        Op::Version => r.is_empty().then_some(Request::Version).ok_or(fail)?,
        Op::Store => r.is_empty().then_some(Request::Store).ok_or(fail)?,
    };
    Ok((seq, request))
}

/// Starts a response: `op, seq, status`; the caller appends the result when OK.
pub fn begin_response<'b>(op: u8, seq: u8, status: Status, buf: &'b mut [u8]) -> Writer<'b> {
    let mut w = Writer::new(buf);
    // A response buffer always holds its three-byte head.
    let _ = w.put(&[op, seq, status.code()]);
    w
}

/// A response's head: op, seq, status, and a reader over its result.
pub fn decode_response(bytes: &[u8]) -> Option<(Op, u8, Status, Reader<'_>)> {
    let mut r = Reader::new(bytes);
    let op = Op::from_code(r.u8()?)?;
    let seq = r.u8()?;
    let status = Status::from_code(r.u8()?)?;
    Some((op, seq, status, r))
}

/// Writes a STATS result.
pub fn put_stats(w: &mut Writer, s: &TaskStats) -> Option<()> {
    let name = &s.name.as_bytes()[..s.name.len().min(u8::MAX as usize)];
    w.put(&[s.stopped as u8, name.len() as u8])?;
    w.put(name)?;
    for f in s.figures {
        w.put(&f.to_le_bytes())?;
    }
    Some(())
}

/// What the PLC's persistent store (`plc.store`) loaded at the last cold start and saved
/// since, as STORE returns it: sequence numbers of the store's records, 0 for none.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoreStatus {
    /// The PLC has a store (without one every number is 0).
    pub configured: bool,
    /// The boot project that runs instead of the configured program (0: the configured one).
    pub boot_loaded: u64,
    /// The RETAIN snapshot the program started with (0: initial values).
    pub retain_loaded: u64,
    pub boot_saved: u64,
    pub retain_saved: u64,
}

/// Appends a STORE result.
pub fn put_store_status(w: &mut Writer, s: &StoreStatus) -> Option<()> {
    w.put(&[s.configured as u8])?;
    for n in [s.boot_loaded, s.retain_loaded, s.boot_saved, s.retain_saved] {
        w.put(&n.to_le_bytes())?;
    }
    Some(())
}

/// Reads a STORE result.
pub fn read_store_status(r: &mut Reader) -> Option<StoreStatus> {
    Some(StoreStatus {
        configured: r.u8()? != 0,
        boot_loaded: r.u64()?,
        retain_loaded: r.u64()?,
        boot_saved: r.u64()?,
        retain_saved: r.u64()?,
    })
}

/// Reads a STATS result.
pub fn read_stats<'a>(r: &mut Reader<'a>) -> Option<TaskStats<'a>> {
    let stopped = r.u8()? != 0;
    let name = r.short_str()?;
    let mut figures = [0u64; 9];
    for f in &mut figures {
        *f = r.u64()?;
    }
    Some(TaskStats {
        name,
        stopped,
        figures,
    })
}

/// The download checksum: CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`), the one the
/// system image and the binary configuration use.
pub use abi::crc32::crc32;

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::string::ToString;

    #[test]
    fn every_request_round_trips() {
        let requests = [
            Request::List { from: 513 },
            Request::Read {
                name: "tank.pid.integral",
            },
            Request::Write {
                name: "tank.setpoint",
                value: Value::LReal(1.25),
            },
            Request::Force {
                name: "alarm",
                value: Value::Bool(true),
            },
            Request::Force {
                name: "n",
                value: Value::Int(-5),
            },
            Request::Unforce { name: "alarm" },
            Request::Stats { task: 3 },
            Request::Stop { task: 0 },
            Request::Start { task: 7 },
            Request::DownloadBegin {
                size: 70_000,
                crc32: 0xcbf4_3926,
            },
            Request::DownloadChunk {
                offset: 512,
                bytes: &[1, 2, 3],
            },
            Request::DownloadChunk {
                offset: 0,
                bytes: &[0xaa; MAX_CHUNK],
            },
            Request::DownloadCommit,
        ];
        for (seq, r) in requests.iter().enumerate() {
            let mut buf = [0u8; MAX_MESSAGE];
            let n = encode_request(r, seq as u8, &mut buf).unwrap();
            assert_eq!(decode_request(&buf[..n]), Ok((seq as u8, *r)));
        }
    }

    #[test]
    fn responses_round_trip() {
        let mut buf = [0u8; MAX_MESSAGE];
        let mut w = begin_response(Op::Read.code(), 9, Status::Ok, &mut buf);
        w.value(&Value::Real(0.5)).unwrap();
        let n = w.len();
        let (op, seq, status, mut r) = decode_response(&buf[..n]).unwrap();
        assert_eq!((op, seq, status), (Op::Read, 9, Status::Ok));
        assert_eq!(r.value(), Some(Value::Real(0.5)));
        let stats = TaskStats {
            name: "CYCLE.tank",
            stopped: true,
            figures: [1, 2, 3, 4, 5, 6, 7, 8, 9],
        };
        let mut w = begin_response(Op::Stats.code(), 1, Status::Ok, &mut buf);
        put_stats(&mut w, &stats).unwrap();
        let n = w.len();
        let (_, _, _, mut r) = decode_response(&buf[..n]).unwrap();
        assert_eq!(read_stats(&mut r), Some(stats));
        let mut w = begin_response(Op::Read.code(), 2, Status::Ok, &mut buf);
        w.value(&Value::String(b"abc")).unwrap();
        let n = w.len();
        let (_, _, _, mut r) = decode_response(&buf[..n]).unwrap();
        assert_eq!(r.value(), Some(Value::String(b"abc")));
    }

    #[test]
    fn hostile_requests_are_errors_never_panics() {
        assert_eq!(decode_request(&[]), Err((0, 0)));
        assert_eq!(decode_request(&[2]), Err((2, 0)));
        assert_eq!(decode_request(&[99, 4]), Err((99, 4)));
        assert_eq!(decode_request(&[2, 1]), Err((2, 1)), "READ without a name");
        assert_eq!(decode_request(&[2, 1, 0xff]), Err((2, 1)), "name not UTF-8");
        assert_eq!(decode_request(&[1, 1, 0]), Err((1, 1)), "LIST truncated");
        assert_eq!(decode_request(&[6, 1, 0, 0]), Err((6, 1)), "STATS too long");
        assert_eq!(
            decode_request(&[3, 1, VarType::Bool.code(), 2, 0, 0, 0, 0, 0, 0, 0, b'x']),
            Err((3, 1)),
            "a BOOL of 2"
        );
        assert_eq!(decode_request(&[3, 1, 200, 0]), Err((3, 1)), "unknown type");
        // Every byte pattern of short messages, and every truncation of a long one.
        for a in 0..=255u8 {
            for b in [0u8, 1, 2, 255] {
                let _ = decode_request(&[a, b]);
                let _ = decode_request(&[a, 0, b, 1, 2, 3]);
                let _ = decode_response(&[a, 0, b]);
            }
        }
        let mut buf = [0u8; MAX_MESSAGE];
        let r = Request::Force {
            name: "x",
            value: Value::LReal(2.0),
        };
        let n = encode_request(&r, 7, &mut buf).unwrap();
        for cut in 0..n {
            assert!(decode_request(&buf[..cut]).is_err(), "cut at {cut}");
        }
        assert!(
            encode_request(&r, 7, &mut buf[..5]).is_none(),
            "too small a buffer"
        );
    }

    #[test]
    fn hostile_control_and_download_requests_are_errors() {
        let (stop, start) = (Op::Stop.code(), Op::Start.code());
        let (begin, chunk, commit) = (
            Op::DownloadBegin.code(),
            Op::DownloadChunk.code(),
            Op::DownloadCommit.code(),
        );
        for (bytes, why) in [
            (&[stop, 1][..], "STOP without a task"),
            (&[stop, 1, 0, 0], "STOP too long"),
            (&[start, 1], "START without a task"),
            (&[start, 1, 0, 9], "START too long"),
            (&[begin, 1, 0, 1, 0, 0, 1, 2, 3], "BEGIN truncated"),
            (&[begin, 1, 0, 1, 0, 0, 1, 2, 3, 4, 5], "BEGIN too long"),
            (&[chunk, 1, 0, 0, 0], "CHUNK offset truncated"),
            (&[chunk, 1, 0, 0, 0, 0], "CHUNK without bytes"),
            (&[commit, 1, 0], "COMMIT with a payload"),
        ] {
            assert_eq!(decode_request(bytes), Err((bytes[0], 1)), "{why}");
        }
        let mut long = [0u8; MAX_MESSAGE + 1];
        long[0] = chunk;
        assert!(decode_request(&long).is_err(), "a chunk beyond MAX_CHUNK");
        let mut buf = [0u8; MAX_MESSAGE];
        let too_big = Request::DownloadChunk {
            offset: 0,
            bytes: &[0; MAX_CHUNK + 1],
        };
        assert!(encode_request(&too_big, 1, &mut buf).is_none());
        let empty = Request::DownloadChunk {
            offset: 0,
            bytes: &[],
        };
        assert!(encode_request(&empty, 1, &mut buf).is_none());
        // Every truncation of each new request is an error, never a panic.
        for r in [
            Request::Stop { task: 1 },
            Request::DownloadBegin { size: 9, crc32: 7 },
            Request::DownloadChunk {
                offset: 3,
                bytes: &[1],
            },
        ] {
            let n = encode_request(&r, 5, &mut buf).unwrap();
            for cut in 0..n {
                assert!(decode_request(&buf[..cut]).is_err(), "{r:?} cut at {cut}");
            }
        }
    }

    /// Every value type through a READ answer typed as its variable, and through WRITE and
    /// FORCE requests: the same type and value come out, shown as its IEC literal.
    #[test]
    fn every_value_type_round_trips() {
        let date = plc_vm::builtins::date_from_parts(2024, 6, 15).unwrap();
        let tod = (12 * 3600 + 30 * 60) * 1_000_000_000;
        let wide = [b'W', 0, 0xac, 0x20]; // "W€"
        let cases = [
            (VarType::Bool, Value::Bool(true), "TRUE"),
            (VarType::SInt, Value::Int(-128), "-128"),
            (VarType::DInt, Value::Int(70_000), "70000"),
            (VarType::USInt, Value::UInt(255), "255"),
            (
                VarType::LWord,
                Value::UInt(u64::MAX),
                "18446744073709551615",
            ),
            (VarType::Real, Value::Real(0.5), "0.5"),
            (VarType::LReal, Value::LReal(1.0), "1.0"),
            (VarType::Time, Value::Time(1_500_000_000), "T#1s500ms"),
            (
                VarType::LTime,
                Value::Temporal(TimeKind::LTime, 2_000_001),
                "LT#2ms1ns",
            ),
            (
                VarType::Date,
                Value::Temporal(TimeKind::Date, date),
                "D#2024-06-15",
            ),
            (
                VarType::LDate,
                Value::Temporal(TimeKind::LDate, date),
                "LD#2024-06-15",
            ),
            (
                VarType::Tod,
                Value::Temporal(TimeKind::Tod, tod),
                "TOD#12:30:00",
            ),
            (
                VarType::LTod,
                Value::Temporal(TimeKind::LTod, tod + 1),
                "LTOD#12:30:00.000000001",
            ),
            (
                VarType::Dt,
                Value::Temporal(TimeKind::Dt, date + tod),
                "DT#2024-06-15-12:30:00",
            ),
            (
                VarType::LDt,
                Value::Temporal(TimeKind::LDt, -1),
                "LDT#1969-12-31-23:59:59.999999999",
            ),
            (VarType::Char, Value::Char(b'a'), "'a'"),
            (VarType::WChar, Value::WChar(0x20ac), "\"€\""),
            (VarType::String, Value::String(b"it's"), "'it$'s'"),
            (VarType::WString, Value::WString(&wide), "\"W€\""),
            (
                VarType::Ref,
                Value::Ref {
                    address: Some(16),
                    target: Some("Main.x"),
                },
                "REF(Main.x)",
            ),
            (
                VarType::Ref,
                Value::Ref {
                    address: Some(0x12c),
                    target: None,
                },
                "16#0000012C",
            ),
            (
                VarType::Ref,
                Value::Ref {
                    address: None,
                    target: None,
                },
                "NULL",
            ),
        ];
        for (ty, value, shown) in cases {
            let mut buf = [0u8; MAX_MESSAGE];
            let mut w = begin_response(Op::Read.code(), 3, Status::Ok, &mut buf);
            w.typed_value(ty, &value).unwrap();
            let n = w.len();
            let (_, _, _, mut r) = decode_response(&buf[..n]).unwrap();
            assert_eq!(r.typed_value(), Some((ty, value)), "{ty:?}");
            assert!(r.is_empty());
            assert_eq!(std::format!("{value}"), shown);
            for cut in 3..n {
                let (_, _, _, mut r) = decode_response(&buf[..cut]).unwrap();
                assert_eq!(r.typed_value(), None, "{ty:?} cut at {cut}");
            }
            if ty == VarType::Ref {
                continue;
            }
            let force = Request::Force { name: "v", value };
            let n = encode_request(&force, 4, &mut buf).unwrap();
            assert_eq!(decode_request(&buf[..n]), Ok((4, force)), "{ty:?}");
        }
        // Untyped, an integer is a LINT or ULINT, as in version 1.
        let mut buf = [0u8; MAX_MESSAGE];
        let mut w = Writer::new(&mut buf);
        w.value(&Value::Int(-1)).unwrap();
        w.value(&Value::UInt(1)).unwrap();
        assert_eq!(buf[0], VarType::LInt.code());
        assert_eq!(buf[9], VarType::ULInt.code());
        // A type that cannot hold the value is not used.
        let mut w = Writer::new(&mut buf);
        w.typed_value(VarType::Char, &Value::UInt(7)).unwrap();
        w.typed_value(VarType::SInt, &Value::Int(300)).unwrap();
        assert_eq!(buf[0], VarType::ULInt.code());
        assert_eq!(buf[9], VarType::LInt.code());
    }

    #[test]
    fn values_a_type_cannot_hold_are_malformed() {
        let value = |ty: VarType, bits: u64| {
            let mut bytes = std::vec![ty.code()];
            bytes.extend_from_slice(&bits.to_le_bytes());
            Reader::new(&bytes).value().is_some()
        };
        let day = NS_PER_DAY as u64;
        assert!(value(VarType::Date, 3 * day));
        assert!(!value(VarType::Date, 3 * day + 1), "a date within a day");
        assert!(!value(VarType::LDate, 1));
        assert!(value(VarType::Tod, day - 1));
        assert!(!value(VarType::Tod, day), "a time of day of 24 h");
        assert!(!value(VarType::LTod, -1i64 as u64));
        assert!(value(VarType::Dt, -1i64 as u64));
        assert!(!value(VarType::Char, 256));
        assert!(!value(VarType::WChar, 0x1_0000));
        assert!(!value(VarType::SInt, 128));
        assert!(value(VarType::SInt, -128i64 as u64));
        assert!(!value(VarType::UInt, 65_536));
        assert!(!value(VarType::Real, 1 << 32));
        assert!(!value(VarType::Bool, 2));
        // A reference: an address beyond 32 bits, a name on NULL, a missing name length.
        let reference = |bits: u64, name: &[u8]| {
            let mut bytes = std::vec![VarType::Ref.code()];
            bytes.extend_from_slice(&bits.to_le_bytes());
            bytes.extend_from_slice(name);
            Reader::new(&bytes).value().map(|v| v.to_string())
        };
        assert!(reference(1 << 32, &[0]).is_none());
        assert!(reference(u64::MAX, &[1, b'x']).is_none());
        assert!(reference(8, &[]).is_none());
        assert!(reference(8, &[1, 0xff]).is_none(), "a name not UTF-8");
        assert_eq!(reference(8, &[0]).as_deref(), Some("16#00000008"));
        assert_eq!(reference(8, &[1, b'g']).as_deref(), Some("REF(g)"));
        // A WSTRING of 2 units with 3 bytes.
        let wide = [VarType::WString.code(), 2, 0, b'a', 0, b'b'];
        assert!(Reader::new(&wide).value().is_none());
        // The first unknown type code.
        assert!(Reader::new(&[28, 0, 0, 0, 0, 0, 0, 0, 0]).value().is_none());
    }

    #[test]
    fn a_reference_target_is_named_only_when_it_fits() {
        let long = "x".repeat(200);
        let long = long.as_str();
        let value = Value::Ref {
            address: Some(4),
            target: Some(long),
        };
        let mut buf = [0u8; MAX_MESSAGE];
        let mut w = begin_response(Op::Read.code(), 1, Status::Ok, &mut buf);
        w.put(&[0; 60]).unwrap();
        w.typed_value(VarType::Ref, &value).unwrap();
        let n = w.len();
        let (_, _, _, mut r) = decode_response(&buf[..n]).unwrap();
        r.take(60).unwrap();
        assert_eq!(
            r.value(),
            Some(Value::Ref {
                address: Some(4),
                target: None
            })
        );
    }

    #[test]
    fn version_is_asked_without_a_payload() {
        let mut buf = [0u8; MAX_MESSAGE];
        let n = encode_request(&Request::Store, 9, &mut buf).unwrap();
        assert_eq!(decode_request(&buf[..n]), Ok((9, Request::Store)));
        assert_eq!(Op::Store.needs(), Access::Monitor);
        let status = StoreStatus {
            configured: true,
            boot_loaded: 3,
            retain_loaded: 41,
            boot_saved: 4,
            retain_saved: 1 << 40,
        };
        let mut w = begin_response(Op::Store.code(), 9, Status::Ok, &mut buf);
        put_store_status(&mut w, &status).unwrap();
        let n = w.len();
        let (_, _, _, mut r) = decode_response(&buf[..n]).unwrap();
        assert_eq!(read_store_status(&mut r), Some(status));
        assert_eq!(
            read_store_status(&mut decode_response(&buf[..n - 1]).unwrap().3),
            None
        );
        let n = encode_request(&Request::Version, 9, &mut buf).unwrap();
        assert_eq!(&buf[..n], &[12, 9]);
        assert_eq!(decode_request(&buf[..n]), Ok((9, Request::Version)));
        assert_eq!(decode_request(&[12, 9, 0]), Err((12, 9)), "with a payload");
        assert_eq!(Op::Version.needs(), Access::Monitor);
    }

    #[test]
    fn access_levels_include_the_ones_below() {
        assert_eq!(Op::Stop.needs(), Access::Force);
        assert_eq!(Op::Start.needs(), Access::Force);
        for op in [Op::DownloadBegin, Op::DownloadChunk, Op::DownloadCommit] {
            assert_eq!(op.needs(), Access::Download);
        }
        assert!(Access::Monitor.code() < Access::Force.code());
        assert!(Access::Force.code() < Access::Download.code());
        // The old codes are an interface: unchanged.
        assert_eq!(Op::Stats.code(), 6);
        assert_eq!(Status::Unsupported.code(), 8);
        assert_eq!(Access::Force.code(), 1);
        // Version 2's additions, and version 1's value types, are codes for good.
        assert_eq!(Op::Version.code(), 12);
        assert_eq!(Status::ReadOnly.code(), 15);
        assert_eq!(VarType::Time.code(), 11);
        assert_eq!((VarType::Date.code(), VarType::Ref.code()), (17, 27));
    }

    #[test]
    fn crc32_is_zlibs() {
        assert_eq!(crc32(b""), 0);
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
    }
}
