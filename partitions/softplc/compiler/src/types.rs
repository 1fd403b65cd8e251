//! The IEC 61131-3 type system as used by the compiler: elementary types, derived types,
//! memory layout (size/alignment in the VM's byte-addressed data memory) and the implicit
//! conversion / operator typing rules.

use std::fmt;
use std::rc::Rc;

/// Elementary types. Integers live sign- or zero-extended in 64-bit stack cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Elem {
    Bool,
    SInt,
    Int,
    DInt,
    LInt,
    USInt,
    UInt,
    UDInt,
    ULInt,
    Byte,
    Word,
    DWord,
    LWord,
    Real,
    LReal,
    Time,
    LTime,
    Date,
    LDate,
    Tod,
    LTod,
    Dt,
    LDt,
    Char,
    WChar,
}

impl Elem {
    pub const ALL: [Elem; 25] = [
        Elem::Bool,
        Elem::SInt,
        Elem::Int,
        Elem::DInt,
        Elem::LInt,
        Elem::USInt,
        Elem::UInt,
        Elem::UDInt,
        Elem::ULInt,
        Elem::Byte,
        Elem::Word,
        Elem::DWord,
        Elem::LWord,
        Elem::Real,
        Elem::LReal,
        Elem::Time,
        Elem::LTime,
        Elem::Date,
        Elem::LDate,
        Elem::Tod,
        Elem::LTod,
        Elem::Dt,
        Elem::LDt,
        Elem::Char,
        Elem::WChar,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Elem::Bool => "BOOL",
            Elem::SInt => "SINT",
            Elem::Int => "INT",
            Elem::DInt => "DINT",
            Elem::LInt => "LINT",
            Elem::USInt => "USINT",
            Elem::UInt => "UINT",
            Elem::UDInt => "UDINT",
            Elem::ULInt => "ULINT",
            Elem::Byte => "BYTE",
            Elem::Word => "WORD",
            Elem::DWord => "DWORD",
            Elem::LWord => "LWORD",
            Elem::Real => "REAL",
            Elem::LReal => "LREAL",
            Elem::Time => "TIME",
            Elem::LTime => "LTIME",
            Elem::Date => "DATE",
            Elem::LDate => "LDATE",
            Elem::Tod => "TOD",
            Elem::LTod => "LTOD",
            Elem::Dt => "DT",
            Elem::LDt => "LDT",
            Elem::Char => "CHAR",
            Elem::WChar => "WCHAR",
        }
    }

    /// The type named `upper` (IEC long names such as TIME_OF_DAY included).
    pub fn from_name(upper: &str) -> Option<Elem> {
        let canonical = match upper {
            "TIME_OF_DAY" => "TOD",
            "LTIME_OF_DAY" => "LTOD",
            "DATE_AND_TIME" => "DT",
            "LDATE_AND_TIME" => "LDT",
            other => other,
        };
        Elem::ALL.iter().copied().find(|e| e.name() == canonical)
    }

    pub fn size(self) -> u32 {
        match self {
            Elem::Bool | Elem::SInt | Elem::USInt | Elem::Byte | Elem::Char => 1,
            Elem::Int | Elem::UInt | Elem::Word | Elem::WChar => 2,
            Elem::DInt | Elem::UDInt | Elem::DWord | Elem::Real => 4,
            Elem::LInt | Elem::ULInt | Elem::LWord | Elem::LReal => 8,
            Elem::Time | Elem::LTime | Elem::Date | Elem::LDate | Elem::Tod | Elem::LTod => 8,
            Elem::Dt | Elem::LDt => 8,
        }
    }

    /// TIME and LTIME: durations (`i64` nanoseconds).
    pub fn is_duration(self) -> bool {
        matches!(self, Elem::Time | Elem::LTime)
    }

    /// DATE, TOD, DT and their long forms: points in time (`i64` nanoseconds since
    /// 1970-01-01, or since midnight for TOD).
    pub fn is_date_time(self) -> bool {
        matches!(
            self,
            Elem::Date | Elem::LDate | Elem::Tod | Elem::LTod | Elem::Dt | Elem::LDt
        )
    }

    /// Durations and points in time.
    pub fn is_temporal(self) -> bool {
        self.is_duration() || self.is_date_time()
    }

    /// CHAR and WCHAR.
    pub fn is_char(self) -> bool {
        matches!(self, Elem::Char | Elem::WChar)
    }

    /// The VM's name for a date/time type (the `kind` argument of its date/time builtins).
    pub fn time_kind(self) -> Option<plc_vm::TimeKind> {
        use plc_vm::TimeKind as K;
        Some(match self {
            Elem::Time => K::Time,
            Elem::LTime => K::LTime,
            Elem::Date => K::Date,
            Elem::LDate => K::LDate,
            Elem::Tod => K::Tod,
            Elem::LTod => K::LTod,
            Elem::Dt => K::Dt,
            Elem::LDt => K::LDt,
            _ => return None,
        })
    }

    /// The date/time family: DATE and LDATE are one, and so on (the long forms hold the
    /// same nanoseconds; they differ in their conversions to numbers).
    pub fn temporal_family(self) -> Option<Elem> {
        Some(match self {
            Elem::Time | Elem::LTime => Elem::Time,
            Elem::Date | Elem::LDate => Elem::Date,
            Elem::Tod | Elem::LTod => Elem::Tod,
            Elem::Dt | Elem::LDt => Elem::Dt,
            _ => return None,
        })
    }

    /// The long form of a date/time type (LTIME for TIME, ...).
    pub fn is_long_temporal(self) -> bool {
        matches!(self, Elem::LTime | Elem::LDate | Elem::LTod | Elem::LDt)
    }

    pub fn is_signed_int(self) -> bool {
        matches!(self, Elem::SInt | Elem::Int | Elem::DInt | Elem::LInt)
    }

    pub fn is_unsigned_int(self) -> bool {
        matches!(self, Elem::USInt | Elem::UInt | Elem::UDInt | Elem::ULInt)
    }

    pub fn is_bits(self) -> bool {
        matches!(self, Elem::Byte | Elem::Word | Elem::DWord | Elem::LWord)
    }

    /// Integers and bit strings (everything held as an integer that is not BOOL or TIME).
    pub fn is_integral(self) -> bool {
        self.is_signed_int() || self.is_unsigned_int() || self.is_bits()
    }

    pub fn is_real(self) -> bool {
        matches!(self, Elem::Real | Elem::LReal)
    }

    pub fn is_numeric(self) -> bool {
        self.is_integral() || self.is_real()
    }

    /// Whether cells of this type are sign-extended (vs zero-extended) from memory.
    pub fn signed_storage(self) -> bool {
        self.is_signed_int() || self.is_temporal()
    }

    /// Value range of an integral type.
    pub fn int_range(self) -> (i128, i128) {
        let bits = self.size() * 8;
        if self.signed_storage() {
            (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
        } else if self == Elem::Bool {
            (0, 1)
        } else {
            (0, (1i128 << bits) - 1)
        }
    }

    /// Rank for implicit widening between integers of the same family.
    fn rank(self) -> u32 {
        self.size()
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ArrayType {
    /// (lower, upper) bound of each dimension.
    pub dims: Vec<(i64, i64)>,
    pub elem: Type,
}

impl ArrayType {
    pub fn len(&self) -> u64 {
        self.dims
            .iter()
            .map(|(lo, hi)| (hi - lo + 1).max(0) as u64)
            .product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A (possibly derived) data type. Structs, enums and FB types refer to tables in
/// [`crate::sema::Program`] by index.
#[derive(Debug, Clone, PartialEq)]
pub enum Type {
    Elem(Elem),
    /// STRING with its maximum length in characters.
    String(u32),
    /// WSTRING with its maximum length in UTF-16 code units.
    WString(u32),
    Array(Rc<ArrayType>),
    Struct(usize),
    Enum(usize),
    /// Subrange of an integer type.
    Subrange(Elem, i64, i64),
    /// Instance of a function block.
    Fb(usize),
    /// `__EXCEPTION`: the trap code delivered to a `__CATCH` handler (held as a DINT).
    Exception,
    /// `REF_TO T` / CODESYS `POINTER TO T`: a checked reference (a 64-bit cell, see the VM's
    /// "References"); to a function block: the address of an instance.
    Ref(Box<Type>),
    /// CODESYS `REFERENCE TO T`: an alias of a `T`, dereferenced wherever it is used.
    Reference(Box<Type>),
    /// A variable of an INTERFACE type: the address of an instance implementing it (0: none).
    Interface(usize),
    /// The type of `NULL` (converts to every reference and interface type).
    Null,
    /// Result of something that has no value (a call of a function without result).
    Void,
    /// Type of an expression that already produced an error; accepted everywhere.
    Error,
}

pub const DEFAULT_STRING_LEN: u32 = 80;

impl Type {
    pub const BOOL: Type = Type::Elem(Elem::Bool);
    pub const INT: Type = Type::Elem(Elem::Int);
    pub const DINT: Type = Type::Elem(Elem::DInt);
    pub const LINT: Type = Type::Elem(Elem::LInt);
    pub const ULINT: Type = Type::Elem(Elem::ULInt);
    pub const REAL: Type = Type::Elem(Elem::Real);
    pub const LREAL: Type = Type::Elem(Elem::LReal);
    pub const TIME: Type = Type::Elem(Elem::Time);
    pub const LTIME: Type = Type::Elem(Elem::LTime);

    /// The elementary type values of this type are held as (subranges hold their base type,
    /// enums and exceptions a DINT).
    pub fn elem(&self) -> Option<Elem> {
        match self {
            Type::Elem(e) => Some(*e),
            Type::Subrange(e, ..) => Some(*e),
            Type::Enum(_) | Type::Exception => Some(Elem::DInt),
            _ => None,
        }
    }

    /// The elementary type a value of this type computes in: its own, or a subrange's base
    /// type; `None` for enumerations and exceptions (held as DINT, but no numbers) and for
    /// the types that are not elementary.
    pub fn value_elem(&self) -> Option<Elem> {
        match self {
            Type::Elem(e) | Type::Subrange(e, ..) => Some(*e),
            _ => None,
        }
    }

    /// Whether a value of this type is an integer or a bit string (a subrange's too; no
    /// enumeration value nor exception): what an array index, a partial access's or a
    /// string function's position and a shift's count take.
    pub fn is_integral(&self) -> bool {
        self.value_elem().is_some_and(Elem::is_integral)
    }

    pub fn is_error(&self) -> bool {
        matches!(self, Type::Error)
    }

    pub fn is_string(&self) -> bool {
        matches!(self, Type::String(_))
    }

    pub fn is_wstring(&self) -> bool {
        matches!(self, Type::WString(_))
    }

    /// References, interface values and `NULL`: 64-bit cells that are not numbers.
    pub fn is_pointer_like(&self) -> bool {
        matches!(self, Type::Ref(_) | Type::Interface(_) | Type::Null)
    }
}

/// Result type of an arithmetic operation on two elementary operands, `None` if the mix is
/// not allowed. Mixed integers widen to the larger type; integers mixed with reals give the real.
pub fn common_numeric(a: Elem, b: Elem) -> Option<Elem> {
    if a == b {
        return Some(a);
    }
    if a.is_temporal() || b.is_temporal() || a.is_char() || b.is_char() {
        // TIME with LTIME and so on: the long form; CHAR with WCHAR: WCHAR.
        return if implicit_ok(a, b) {
            Some(b)
        } else if implicit_ok(b, a) {
            Some(a)
        } else {
            None
        };
    }
    match (a.is_real(), b.is_real()) {
        (true, true) => return Some(Elem::LReal),
        (true, false) if b.is_integral() => return Some(a),
        (false, true) if a.is_integral() => return Some(b),
        _ => {}
    }
    if !(a.is_integral() && b.is_integral()) {
        return None;
    }
    let same_family = (a.is_signed_int() && b.is_signed_int())
        || (a.is_unsigned_int() && b.is_unsigned_int())
        || (a.is_bits() && b.is_bits());
    if same_family {
        return Some(if a.rank() >= b.rank() { a } else { b });
    }
    // Signed with unsigned/bits: a signed type that holds both if there is one.
    let (s, u) = if a.is_signed_int() {
        (a, b)
    } else if b.is_signed_int() {
        (b, a)
    } else {
        // unsigned with bits: the larger unsigned
        let size = a.size().max(b.size());
        return Some(unsigned_of_size(size));
    };
    let need = if s.size() > u.size() {
        s.size()
    } else {
        u.size() * 2
    };
    Some(signed_of_size(need.min(8)))
}

pub fn signed_of_size(size: u32) -> Elem {
    match size {
        1 => Elem::SInt,
        2 => Elem::Int,
        4 => Elem::DInt,
        _ => Elem::LInt,
    }
}

pub fn unsigned_of_size(size: u32) -> Elem {
    match size {
        1 => Elem::USInt,
        2 => Elem::UInt,
        4 => Elem::UDInt,
        _ => Elem::ULInt,
    }
}

/// Whether a value of `from` may be assigned to `to` without an explicit conversion
/// (IEC 61131-3 implicit widening: no value can be lost).
pub fn implicit_ok(from: Elem, to: Elem) -> bool {
    if from == to {
        return true;
    }
    if from.is_signed_int() && to.is_signed_int()
        || from.is_unsigned_int() && to.is_unsigned_int()
        || from.is_bits() && to.is_bits()
    {
        return to.size() >= from.size();
    }
    if from.is_unsigned_int() && to.is_signed_int() {
        return to.size() > from.size();
    }
    if from.is_unsigned_int() && to.is_bits() || from.is_bits() && to.is_unsigned_int() {
        return to.size() >= from.size();
    }
    if from == Elem::Real && to == Elem::LReal {
        return true;
    }
    // TIME -> LTIME, DATE -> LDATE, TOD -> LTOD, DT -> LDT (same nanoseconds), CHAR -> WCHAR.
    if from.is_temporal() || to.is_temporal() {
        return !from.is_long_temporal()
            && to.is_long_temporal()
            && from.temporal_family() == to.temporal_family();
    }
    if from.is_char() || to.is_char() {
        return from == Elem::Char && to == Elem::WChar;
    }
    // A bit string fits a larger signed integer (CODESYS converts BYTE to INT implicitly).
    if from.is_bits() && to.is_signed_int() {
        return to.size() > from.size();
    }
    if from.is_integral() && to.is_real() {
        // Exact in the mantissa: up to INT for REAL, up to DINT for LREAL. Also allowed is
        // DINT -> REAL which IEC permits although it may round.
        return from.size() <= 4 || to == Elem::LReal;
    }
    false
}

/// What assigning a value of type `from` where `to` is wanted takes ([`implicit_conversion`]
/// between types that are no references; the code generator decides the references').
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Implicit {
    /// Nothing: the same type, a string of the same kind, a subrange where its base type is
    /// wanted (or an error type, already reported).
    Nothing,
    /// The conversion of one elementary type to another.
    Convert(Elem, Elem),
    /// A reference's address (32 bits) zero-extended to the wider integer wanted.
    AddressToInteger,
}

/// Why a value of one type cannot stand where another is wanted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotImplicit {
    /// The types do not match at all.
    Mismatch,
    /// Both are elementary (of these types), but the conversion could lose a value.
    MayLose(Elem, Elem),
}

/// The implicit conversion of a value of type `from` where `to` is wanted (pointers,
/// references and interfaces aside): IEC 61131-3's widening that loses no value
/// ([`implicit_ok`]); enumerations and exceptions only as themselves.
pub fn implicit_conversion(from: &Type, to: &Type) -> Result<Implicit, NotImplicit> {
    if from.is_error() || to.is_error() || from == to {
        return Ok(Implicit::Nothing);
    }
    match (from, to) {
        (Type::String(_), Type::String(_)) | (Type::WString(_), Type::WString(_)) => {
            return Ok(Implicit::Nothing);
        }
        (Type::Subrange(a, ..), _) if to.value_elem() == Some(*a) => return Ok(Implicit::Nothing),
        _ => {}
    }
    let (Some(f), Some(t)) = (from.value_elem(), to.value_elem()) else {
        return Err(NotImplicit::Mismatch);
    };
    if implicit_ok(f, t) {
        Ok(Implicit::Convert(f, t))
    } else {
        Err(NotImplicit::MayLose(f, t))
    }
}

impl fmt::Display for Elem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening() {
        assert_eq!(common_numeric(Elem::Int, Elem::DInt), Some(Elem::DInt));
        assert_eq!(common_numeric(Elem::Int, Elem::Real), Some(Elem::Real));
        assert_eq!(common_numeric(Elem::USInt, Elem::Int), Some(Elem::Int));
        assert_eq!(common_numeric(Elem::Bool, Elem::Int), None);
        assert!(implicit_ok(Elem::Int, Elem::DInt));
        assert!(!implicit_ok(Elem::DInt, Elem::Int));
        assert!(implicit_ok(Elem::DInt, Elem::LReal));
    }

    #[test]
    fn integral_values_are_integers_and_bit_strings_only() {
        assert!(Type::Subrange(Elem::Int, 0, 9).is_integral());
        assert!(Type::Elem(Elem::Word).is_integral());
        assert!(!Type::Exception.is_integral(), "held as DINT, no number");
        assert!(!Type::Enum(0).is_integral());
        assert!(!Type::REAL.is_integral());
    }

    #[test]
    fn implicit_conversions_widen_and_keep_enumerations_apart() {
        let sub = Type::Subrange(Elem::Int, 0, 9);
        assert_eq!(implicit_conversion(&sub, &Type::INT), Ok(Implicit::Nothing));
        assert_eq!(
            implicit_conversion(&sub, &Type::DINT),
            Ok(Implicit::Convert(Elem::Int, Elem::DInt))
        );
        assert_eq!(
            implicit_conversion(&Type::String(8), &Type::String(80)),
            Ok(Implicit::Nothing)
        );
        assert_eq!(
            implicit_conversion(&Type::DINT, &Type::INT),
            Err(NotImplicit::MayLose(Elem::DInt, Elem::Int))
        );
        assert_eq!(
            implicit_conversion(&Type::TIME, &Type::Elem(Elem::Tod)),
            Err(NotImplicit::MayLose(Elem::Time, Elem::Tod))
        );
        assert_eq!(
            implicit_conversion(&Type::Exception, &Type::DINT),
            Err(NotImplicit::Mismatch),
            "held as DINT, but no number"
        );
        assert_eq!(
            implicit_conversion(&Type::String(8), &Type::WString(8)),
            Err(NotImplicit::Mismatch)
        );
    }
}
