//! The values a monitor reads from and writes to a running program's variables, by the
//! variable map's types ([`VarType`]): how each type's bytes in data memory are a [`Value`]
//! ([`Value::load`]) and how a value goes back into them ([`Value::store`],
//! [`Value::to_cell`]), admitting only a value of the variable's type (or one IEC widens to
//! it) and never writing a reference. [`crate::vm::Machine`]'s monitor calls
//! (`read_var`, `write_var`, `force_var`), `plcc run --set` and the PLC's download hand-over
//! use it; [`crate::literal`] shows and parses the values. Never here: what a program's
//! instructions do to its data.

use crate::builtins::NS_PER_DAY;
use crate::image::{Storage, VarType};
use crate::isa::{TimeKind, read_u16, read_u64};

/// A typed variable value for the monitor API.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'s> {
    /// BOOL.
    Bool(bool),
    /// Signed integers (SINT..LINT).
    Int(i64),
    /// Unsigned integers and bit strings (USINT..ULINT, BYTE..LWORD).
    UInt(u64),
    /// REAL.
    Real(f32),
    /// LREAL.
    LReal(f64),
    /// TIME in nanoseconds.
    Time(i64),
    /// STRING bytes.
    String(&'s [u8]),
    /// LTIME, DATE, TOD, DT or a long form (never TIME, which is [`Value::Time`]): its kind
    /// and its nanoseconds (since 1970-01-01 for dates, since midnight for TOD).
    Temporal(TimeKind, i64),
    /// CHAR: its byte.
    Char(u8),
    /// WCHAR: its UTF-16 code unit.
    WChar(u16),
    /// WSTRING: its UTF-16 code units, two little-endian bytes each.
    WString(&'s [u8]),
    /// A reference: its target's data address (`None`: NULL) and, when the target is the
    /// first byte of a variable of the map, that variable's name. Never written online.
    Ref {
        /// The target's data address.
        address: Option<u32>,
        /// The variable the target is the start of.
        target: Option<&'s str>,
    },
}

impl<'s> Value<'s> {
    /// A date/time value of `kind` (TIME as [`Value::Time`]).
    pub const fn temporal(kind: TimeKind, ns: i64) -> Value<'static> {
        match kind {
            TimeKind::Time => Value::Time(ns),
            kind => Value::Temporal(kind, ns),
        }
    }

    /// The value a scalar variable of type `ty` has when its memory holds `cell` (loaded,
    /// i.e. sign- or zero-extended); `None` for STRING, WSTRING and references.
    pub fn of_cell(ty: VarType, cell: u64) -> Option<Value<'static>> {
        ty.mem_type()?;
        Some(match ty {
            VarType::Bool => Value::Bool(cell != 0),
            VarType::Real => Value::Real(f32::from_bits(cell as u32)),
            VarType::LReal => Value::LReal(f64::from_bits(cell)),
            VarType::Char => Value::Char(cell as u8),
            VarType::WChar => Value::WChar(cell as u16),
            ty if ty.is_signed_int() => Value::Int(cell as i64),
            ty => match ty.time_kind() {
                Some(kind) => Value::temporal(kind, cell as i64),
                None => Value::UInt(cell),
            },
        })
    }

    /// The value of a variable of type `ty` whose bytes (its whole record, as the variable
    /// map sizes it) are `bytes`; a STRING's or WSTRING's current length is clamped to its
    /// capacity; a reference's target is not named. `None` when the size does not fit the
    /// type.
    pub fn load(ty: VarType, bytes: &'s [u8]) -> Option<Value<'s>> {
        if !ty.size_fits(bytes.len() as u32) {
            return None;
        }
        // The current length of a text, clamped to its header's and its record's capacity.
        let text_len = |unit: usize| {
            (read_u16(bytes, 2) as usize)
                .min(read_u16(bytes, 0) as usize)
                .min((bytes.len() - 4) / unit)
        };
        Some(match ty.storage() {
            Storage::Scalar(mem) => Value::of_cell(ty, mem.cell_from_le(&bytes[..mem.width()]))?,
            Storage::String => Value::String(&bytes[4..4 + text_len(1)]),
            Storage::WString => Value::WString(&bytes[4..4 + 2 * text_len(2)]),
            Storage::Reference => Value::Ref {
                address: match read_u64(bytes, 0) {
                    0 => None,
                    cell => Some(cell as u32),
                },
                target: None,
            },
        })
    }

    /// The cell a scalar variable of type `ty` takes for this value (stored truncated to
    /// its width), or [`VarError::TypeMismatch`] when the value is not one of `ty`'s: any
    /// integer for the integer and bit-string types (and an integer for TIME, as protocol
    /// version 1 clients send it), otherwise the value's own type or one IEC widens to `ty`
    /// without a conversion (TIME to LTIME, DATE to LDATE, TOD to LTOD, DT to LDT, CHAR to
    /// WCHAR). A DATE must be a whole day and a TOD within a day. References are
    /// [`VarError::ReadOnly`], STRING and WSTRING [`VarError::NotForceable`].
    pub fn to_cell(&self, ty: VarType) -> Result<u64, VarError> {
        use TimeKind as K;
        match ty.storage() {
            Storage::Reference => return Err(VarError::ReadOnly),
            Storage::String | Storage::WString => return Err(VarError::NotForceable),
            Storage::Scalar(_) => {}
        }
        if let (Some(to), Value::Time(ns) | Value::Temporal(_, ns)) = (ty.time_kind(), *self) {
            let from = match *self {
                Value::Temporal(kind, _) => kind,
                _ => K::Time,
            };
            let widens = from == to
                || matches!(
                    (from, to),
                    (K::Time, K::LTime) | (K::Date, K::LDate) | (K::Tod, K::LTod) | (K::Dt, K::LDt)
                );
            let valid = match to {
                K::Date | K::LDate => ns.rem_euclid(NS_PER_DAY) == 0,
                K::Tod | K::LTod => (0..NS_PER_DAY).contains(&ns),
                _ => true,
            };
            return if widens && valid {
                Ok(ns as u64)
            } else {
                Err(VarError::TypeMismatch)
            };
        }
        let integer = ty.int_range().is_some() && !matches!(ty, VarType::Char | VarType::WChar);
        Ok(match (ty, *self) {
            (VarType::Bool, Value::Bool(b)) => b as u64,
            (VarType::Real, Value::Real(r)) => r.to_bits() as u64,
            (VarType::LReal, Value::LReal(r)) => r.to_bits(),
            (VarType::Char | VarType::WChar, Value::Char(c)) => c as u64,
            (VarType::WChar, Value::WChar(c)) => c as u64,
            (VarType::Time, Value::Int(t)) => t as u64,
            (_, Value::Int(i)) if integer => i as u64,
            (_, Value::UInt(u)) if integer => u,
            _ => return Err(VarError::TypeMismatch),
        })
    }

    /// Writes this value into the bytes of a variable of type `ty` (its whole record):
    /// a scalar as [`Value::to_cell`] admits it, truncated to its width; a STRING or WSTRING
    /// cut to its capacity (the smaller of its header's and its record's), a shorter STRING
    /// followed by the NUL the VM keeps; a reference never ([`VarError::ReadOnly`]).
    pub fn store(&self, ty: VarType, bytes: &mut [u8]) -> Result<(), VarError> {
        if !ty.size_fits(bytes.len() as u32) {
            return Err(VarError::TypeMismatch);
        }
        let (text, unit) = match (ty.storage(), *self) {
            (Storage::String, Value::String(text)) => (text, 1),
            (Storage::WString, Value::WString(text)) if text.len().is_multiple_of(2) => (text, 2),
            (Storage::String | Storage::WString, _) => return Err(VarError::TypeMismatch),
            (storage, _) => {
                let cell = self.to_cell(ty)?;
                if let Storage::Scalar(mem) = storage {
                    bytes[..mem.width()].copy_from_slice(&cell.to_le_bytes()[..mem.width()]);
                }
                return Ok(());
            }
        };
        let capacity = ((bytes.len() - 4) / unit).min(read_u16(bytes, 0) as usize);
        let len = (text.len() / unit).min(capacity);
        bytes[2..4].copy_from_slice(&(len as u16).to_le_bytes());
        bytes[4..4 + unit * len].copy_from_slice(&text[..unit * len]);
        if unit == 1 && len < capacity {
            bytes[4 + len] = 0;
        }
        Ok(())
    }
}

impl core::fmt::Display for Value<'_> {
    /// The IEC literal ([`crate::literal`]): `TRUE`, `-3`, `0.5`, `T#1s500ms`,
    /// `D#2024-06-15`, `'text'`, `"wide"`, `REF(Main.x)`, `NULL`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        crate::literal::write_value(f, self)
    }
}

/// Why a monitor access failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarError {
    /// No variable of that name.
    UnknownName,
    /// Value kind does not fit the variable type.
    TypeMismatch,
    /// The variable is CONSTANT.
    Constant,
    /// STRING and WSTRING variables can be written but not forced.
    NotForceable,
    /// All [`crate::vm::MAX_FORCES`] force slots are in use.
    TooManyForces,
    /// A reference: a monitor reads it but never writes or forces it (a written address
    /// could make the program reach another variable than the one it referenced, or trap).
    ReadOnly,
}
