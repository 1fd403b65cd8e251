//! The standard functions' typing rules: the type a REAL function, ABS or a shift or
//! rotation computes in, the kind of string a string function works on, the type a generic
//! conversion (`TO_INT`) converts from, which conversions between elementary types exist,
//! how a conversion's argument reaches its source type and what the date and time functions
//! take.
//!
//! The checker applies the rules once and records what it chose
//! ([`crate::typed::GenericTypes`], [`crate::typed::ConversionArguments`]); emission reads
//! the record.

use super::ops::Operand;
use crate::types::{DEFAULT_STRING_LEN, Elem, Type, implicit_ok};

/// The type a REAL function (SQRT, LN, LOG, EXP, SIN, COS, TAN, ASIN, ACOS, ATAN, EXPT,
/// ATAN2, TRUNC) without a typed form computes in for its argument `arg`: REAL for a REAL,
/// an integer of up to 16 bits (which REAL holds exactly) or an untyped literal where the
/// context wants a REAL (`real_context`); LREAL for every other number; `None` for what is
/// no number.
pub fn real_function_type(arg: Operand, real_context: bool) -> Option<Elem> {
    let number = arg.ty.value_elem().filter(|e| e.is_numeric())?;
    let small_integer = !arg.flexible && number.is_integral() && number.size() <= 2;
    if number == Elem::Real || arg.flexible && real_context || small_integer {
        Some(Elem::Real)
    } else {
        Some(Elem::LReal)
    }
}

/// The type ABS computes in for an argument of type `t`: its elementary type if that is a
/// number or a duration; `None` otherwise.
pub fn abs_type(t: &Type) -> Option<Elem> {
    t.value_elem()
        .filter(|e| e.is_real() || e.is_integral() || e.is_signed_int() || e.is_duration())
}

/// The type SHL, SHR, ROL and ROR shift in for a value of type `t`: its elementary type if
/// that is a bit string or an integer; `None` otherwise.
pub fn shift_type(t: &Type) -> Option<Elem> {
    t.value_elem().filter(|e| e.is_integral())
}

/// The kind of string LEN, LEFT, RIGHT, MID, DELETE, INSERT, REPLACE, FIND and CONCAT work
/// on (a STRING or WSTRING of the default length): a WSTRING's if the first argument that
/// is no STRING literal (of type `first`) is one, else a STRING's (a STRING literal adapts).
pub fn string_kind(first: Option<&Type>) -> Type {
    match first {
        Some(t) if t.is_wstring() => Type::WString(DEFAULT_STRING_LEN),
        _ => Type::String(DEFAULT_STRING_LEN),
    }
}

/// The type `TO_<target>(arg)` converts from (then as `<source>_TO_<target>`): a STRING, an
/// elementary type (a subrange's base type), LREAL for an untyped literal with a REAL in it
/// and LINT for another; `None` for what is no elementary value.
pub fn conversion_source(arg: Operand) -> Option<Type> {
    match arg.ty {
        Type::String(_) => Some(Type::String(DEFAULT_STRING_LEN)),
        Type::Subrange(e, ..) => Some(Type::Elem(*e)),
        t @ Type::Elem(_) if !arg.flexible => Some(t.clone()),
        _ if arg.flexible && arg.real_literal => Some(Type::LREAL),
        _ if arg.flexible => Some(Type::LINT),
        _ => None,
    }
}

/// Whether `<from>_TO_<to>` exists between two elementary types: among numbers and BOOL,
/// from a date or time to a date or time or a number and back, and between characters and
/// to and from integers and bit strings.
pub fn conversion_exists(from: Elem, to: Elem) -> bool {
    let number = |e: Elem| e.is_numeric() || e == Elem::Bool;
    number(from) && number(to)
        || from.is_temporal() && (to.is_temporal() || number(to))
        || to.is_temporal() && number(from)
        || from.is_char() && (to.is_char() || to.is_integral())
        || to.is_char() && from.is_integral()
}

/// How the argument of `<from>_TO_<to>` between elementary types reaches `from`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConversionArgument {
    /// Implicitly: it is a `from` or converts to one implicitly, or is an untyped literal
    /// (which takes the type `from`).
    Implicit,
    /// Explicitly, from another number (as CODESYS takes a DINT for `INT_TO_BYTE`).
    FromNumber,
}

/// How the argument `arg` of `<from>_TO_<to>` reaches `from`; `None` when it cannot (an
/// enumeration value or an exception never does, though each is held as an integer).
pub fn conversion_argument(from: Elem, arg: Operand) -> Option<ConversionArgument> {
    match arg.ty.value_elem() {
        Some(a) if implicit_ok(a, from) => Some(ConversionArgument::Implicit),
        _ if arg.flexible => Some(ConversionArgument::Implicit),
        Some(a) if a.is_numeric() && from.is_numeric() => Some(ConversionArgument::FromNumber),
        _ => None,
    }
}

/// Whether `arg` fits the operand `want` of a date and time operator written as a function
/// (`ADD_TOD_TIME`, `MUL_TIME`, ...): a `want` or what converts to one implicitly; any
/// number, or an untyped literal, where the function takes a factor (`want` LREAL).
pub fn time_operand_fits(want: Elem, arg: Operand) -> bool {
    match arg.ty.value_elem() {
        Some(x) if want == Elem::LReal => x.is_numeric(),
        Some(x) => implicit_ok(x, want),
        None => want == Elem::LReal && arg.flexible,
    }
}

/// Whether DAY_OF_WEEK takes a value of type `t`: a DATE or an LDATE.
pub fn is_date(t: &Type) -> bool {
    t.value_elem()
        .is_some_and(|e| e.temporal_family() == Some(Elem::Date))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_functions_compute_in_real_only_where_it_holds_the_argument() {
        let real = |t: &Type| real_function_type(Operand::plain(t), false);
        assert_eq!(real(&Type::REAL), Some(Elem::Real));
        assert_eq!(real(&Type::INT), Some(Elem::Real), "REAL holds every INT");
        assert_eq!(real(&Type::Elem(Elem::Word)), Some(Elem::Real));
        assert_eq!(real(&Type::DINT), Some(Elem::LReal));
        assert_eq!(real(&Type::LREAL), Some(Elem::LReal));
        assert_eq!(real(&Type::BOOL), None);
        assert_eq!(real(&Type::TIME), None);
        assert_eq!(real(&Type::Exception), None);
        let literal = Operand {
            flexible: true,
            ..Operand::plain(&Type::LINT)
        };
        assert_eq!(real_function_type(literal, false), Some(Elem::LReal));
        assert_eq!(
            real_function_type(literal, true),
            Some(Elem::Real),
            "a literal where a REAL is wanted"
        );
    }

    #[test]
    fn abs_takes_numbers_and_durations_shifts_bit_strings_and_integers() {
        assert_eq!(abs_type(&Type::LREAL), Some(Elem::LReal));
        assert_eq!(abs_type(&Type::Subrange(Elem::Int, -5, 5)), Some(Elem::Int));
        assert_eq!(abs_type(&Type::LTIME), Some(Elem::LTime));
        assert_eq!(abs_type(&Type::Exception), None, "held as DINT, no number");
        assert_eq!(abs_type(&Type::Elem(Elem::Tod)), None);
        assert_eq!(shift_type(&Type::Elem(Elem::Word)), Some(Elem::Word));
        assert_eq!(shift_type(&Type::DINT), Some(Elem::DInt));
        assert_eq!(shift_type(&Type::REAL), None);
        assert_eq!(shift_type(&Type::String(8)), None);
    }

    #[test]
    fn a_string_function_works_on_wstrings_when_its_first_variable_argument_is_one() {
        let wide = Type::WString(DEFAULT_STRING_LEN);
        assert_eq!(string_kind(Some(&Type::WString(5))), wide);
        assert!(string_kind(Some(&Type::String(5))).is_string());
        assert!(string_kind(Some(&Type::INT)).is_string(), "refused later");
        assert!(string_kind(None).is_string(), "literals only");
    }

    #[test]
    fn conversions_exist_within_numbers_times_and_characters() {
        use Elem::*;
        for (from, to) in [
            (Bool, LReal),
            (Real, Word),
            (Time, LInt),
            (DInt, Tod),
            (Date, Dt),
        ] {
            assert!(conversion_exists(from, to), "{from}_TO_{to}");
        }
        for (from, to) in [(Char, WChar), (Byte, Char), (WChar, UInt)] {
            assert!(conversion_exists(from, to), "{from}_TO_{to}");
        }
        for (from, to) in [(Char, Real), (LReal, WChar), (Char, Time), (Tod, Char)] {
            assert!(!conversion_exists(from, to), "{from}_TO_{to}");
        }
    }

    #[test]
    fn a_generic_conversion_converts_from_the_arguments_type() {
        let source = |t: &Type| conversion_source(Operand::plain(t));
        assert_eq!(
            source(&Type::String(10)),
            Some(Type::String(DEFAULT_STRING_LEN))
        );
        assert_eq!(source(&Type::Subrange(Elem::Int, 0, 9)), Some(Type::INT));
        assert_eq!(source(&Type::TIME), Some(Type::TIME));
        assert_eq!(source(&Type::WString(10)), None);
        assert_eq!(source(&Type::Exception), None);
        let literal = Operand {
            flexible: true,
            ..Operand::plain(&Type::DINT)
        };
        assert_eq!(conversion_source(literal), Some(Type::LINT));
        let real = Operand {
            real_literal: true,
            ..literal
        };
        assert_eq!(conversion_source(real), Some(Type::LREAL));
    }

    #[test]
    fn a_conversions_argument_is_taken_implicitly_or_from_another_number() {
        use ConversionArgument::*;
        let route = |from: Elem, t: &Type| conversion_argument(from, Operand::plain(t));
        assert_eq!(route(Elem::DInt, &Type::INT), Some(Implicit));
        assert_eq!(
            route(Elem::Int, &Type::Subrange(Elem::Int, 0, 9)),
            Some(Implicit)
        );
        assert_eq!(route(Elem::Int, &Type::DINT), Some(FromNumber));
        assert_eq!(route(Elem::Byte, &Type::LREAL), Some(FromNumber));
        assert_eq!(route(Elem::Int, &Type::TIME), None);
        assert_eq!(
            route(Elem::DInt, &Type::Exception),
            None,
            "held as DINT, no number"
        );
        assert_eq!(route(Elem::Int, &Type::String(4)), None);
        let literal = Operand {
            flexible: true,
            ..Operand::plain(&Type::LINT)
        };
        assert_eq!(conversion_argument(Elem::Time, literal), Some(Implicit));
    }

    #[test]
    fn date_and_time_functions_take_their_operands_and_dates() {
        let fits = |want, t: &Type| time_operand_fits(want, Operand::plain(t));
        assert!(fits(Elem::Tod, &Type::Elem(Elem::Tod)));
        assert!(fits(Elem::LTime, &Type::TIME), "TIME widens to LTIME");
        assert!(!fits(Elem::Time, &Type::LTIME));
        assert!(!fits(Elem::Time, &Type::DINT));
        assert!(fits(Elem::LReal, &Type::DINT), "a factor may be any number");
        assert!(!fits(Elem::LReal, &Type::TIME));
        assert!(!fits(Elem::LReal, &Type::Exception));
        assert!(is_date(&Type::Elem(Elem::LDate)));
        assert!(!is_date(&Type::Elem(Elem::Dt)));
    }
}
