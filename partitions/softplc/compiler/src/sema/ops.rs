//! The operators' typing rules: what an operator does with operands of given types
//! (IEC 61131-3's tables of arithmetic, comparison, bit-string and time operations).
//!
//! The checker decides each operation once ([`binary_rule`], [`unary_rule`]) and records it
//! ([`crate::typed::Operations`]); emission reads the record and only chooses opcodes.
//! References and pointers (`REF_TO` arithmetic, comparisons with `NULL`) are decided before
//! these rules, by the reference checks.

use crate::ast::{BinOp, UnOp};
use crate::types::{Elem, Type, common_numeric, signed_of_size};

/// An operand as the rules see it: its type and the facts about its form they depend on.
#[derive(Debug, Clone, Copy)]
pub struct Operand<'t> {
    pub ty: &'t Type,
    /// Built only from untyped numeric literals: it adapts to its context.
    pub flexible: bool,
    /// A STRING literal (compared with a WSTRING it is a WSTRING literal).
    pub string_literal: bool,
    /// Holds a REAL literal (as a time factor an untyped literal is then an LREAL).
    pub real_literal: bool,
}

impl<'t> Operand<'t> {
    /// An operand of type `ty` that is no literal.
    pub fn plain(ty: &'t Type) -> Self {
        Operand {
            ty,
            flexible: false,
            string_literal: false,
            real_literal: false,
        }
    }
}

/// What an operation does, as the checker decided it.
#[derive(Debug, Clone, PartialEq)]
pub enum Operation {
    Binary(BinaryRule),
    Unary(UnaryRule),
}

/// What `-x` or `NOT x` does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UnaryRule {
    /// In the operand's own type.
    Same(Elem),
    /// `-x` of an unsigned integer or bit string narrower than 64 bits (as CODESYS allows):
    /// in the signed integer twice as wide, which holds it.
    NegateWidened(Elem),
}

impl UnaryRule {
    /// The type of the result.
    pub fn result(self) -> Elem {
        match self {
            UnaryRule::Same(e) | UnaryRule::NegateWidened(e) => e,
        }
    }
}

/// What a binary operation does, as the checker decided it.
#[derive(Debug, Clone, PartialEq)]
pub enum BinaryRule {
    /// A comparison of two STRINGs, or of two WSTRINGs (`wide`; a STRING literal adapts).
    StringCompare { wide: bool },
    /// A comparison of the operands at their own types: within one enumeration, of two
    /// characters, BOOL `=` and `<>`.
    Compare,
    /// AND, OR or XOR in BOOL or the common bit-string or integer type.
    Logic(Elem),
    /// Integer `**` integer: computed in LREAL, rounded back to the common type.
    IntegerPower(Elem),
    /// A comparison in the common numeric type.
    NumericCompare(Elem),
    /// `+ - * / MOD **` in the common numeric type.
    Arithmetic(Elem),
    /// Date and time `+`, `-` or a comparison: the operands keep their nanoseconds;
    /// `wraps`: a TIME_OF_DAY result wraps into its day.
    Temporal { result: Elem, wraps: bool },
    /// A duration times or divided by a number (`duration_first`: the duration is the left
    /// operand), at the type `number` (an untyped literal factor is LINT or LREAL).
    Scale {
        result: Elem,
        duration_first: bool,
        number: Type,
    },
}

impl BinaryRule {
    /// The type of the result.
    pub fn result(&self) -> Type {
        match self {
            BinaryRule::StringCompare { .. } | BinaryRule::Compare => Type::BOOL,
            BinaryRule::NumericCompare(_) => Type::BOOL,
            BinaryRule::Logic(t) | BinaryRule::IntegerPower(t) | BinaryRule::Arithmetic(t) => {
                Type::Elem(*t)
            }
            BinaryRule::Temporal { result, .. } | BinaryRule::Scale { result, .. } => {
                Type::Elem(*result)
            }
        }
    }
}

/// Why an operation is refused.
#[derive(Debug, Clone, PartialEq)]
pub enum OperatorError {
    /// The operator does not apply to operands of types `a` and `b`; `hint` says what
    /// would (or is empty).
    Types {
        a: Type,
        b: Type,
        hint: &'static str,
    },
    /// An untyped number used with a character.
    CharacterIsNoNumber,
    /// The unary operator does not apply to an operand of this type.
    Operand(Type),
}

/// What `op` does with an operand of type `t` (not the error type).
pub fn unary_rule(op: UnOp, t: &Type) -> Result<UnaryRule, OperatorError> {
    let refused = || Err(OperatorError::Operand(t.clone()));
    let Some(e) = t.value_elem() else {
        return refused();
    };
    match op {
        UnOp::Neg if e.is_real() || e.is_signed_int() || e.is_duration() => Ok(UnaryRule::Same(e)),
        UnOp::Neg if (e.is_unsigned_int() || e.is_bits()) && e.size() < 8 => {
            Ok(UnaryRule::NegateWidened(signed_of_size(e.size() * 2)))
        }
        UnOp::Not if e == Elem::Bool || e.is_integral() => Ok(UnaryRule::Same(e)),
        _ => refused(),
    }
}

fn is_comparison(op: BinOp) -> bool {
    matches!(
        op,
        BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
    )
}

/// What `op` does with `a` and `b` (neither of the error type).
pub fn binary_rule(op: BinOp, a: Operand, b: Operand) -> Result<BinaryRule, OperatorError> {
    let (ta, tb) = (a.ty, b.ty);
    let mismatch = || OperatorError::Types {
        a: ta.clone(),
        b: tb.clone(),
        hint: "",
    };
    let is_cmp = is_comparison(op);
    // Strings: comparisons only (STRING with STRING, WSTRING with WSTRING).
    if ta.is_string() || tb.is_string() || ta.is_wstring() || tb.is_wstring() {
        let wide = ta.is_wstring() || tb.is_wstring();
        let same_kind = (ta.is_string() && tb.is_string()) || (ta.is_wstring() && tb.is_wstring());
        let adapts =
            wide && (a.string_literal && tb.is_wstring() || b.string_literal && ta.is_wstring());
        return if (same_kind || adapts) && is_cmp {
            Ok(BinaryRule::StringCompare { wide })
        } else {
            Err(mismatch())
        };
    }
    // Enumerations (and exceptions): equality and ordering within the same type.
    let enumish = |t: &Type| matches!(t, Type::Enum(_) | Type::Exception);
    if enumish(ta) || enumish(tb) {
        return if ta == tb && is_cmp {
            Ok(BinaryRule::Compare)
        } else {
            Err(mismatch())
        };
    }
    let (Some(ea), Some(eb)) = (ta.elem(), tb.elem()) else {
        return Err(mismatch());
    };
    if ea.is_temporal() || eb.is_temporal() {
        return temporal_rule(op, (a, ea), (b, eb));
    }
    // Characters: comparisons within CHAR/WCHAR.
    if ea.is_char() || eb.is_char() {
        if a.flexible || b.flexible {
            return Err(OperatorError::CharacterIsNoNumber);
        }
        return if is_cmp && ea.is_char() && eb.is_char() {
            Ok(BinaryRule::Compare)
        } else {
            Err(mismatch())
        };
    }
    // Booleans and bit strings: logic operators.
    if matches!(op, BinOp::And | BinOp::Or | BinOp::Xor) {
        if ea == Elem::Bool && eb == Elem::Bool {
            return Ok(BinaryRule::Logic(Elem::Bool));
        }
        return if ea.is_integral() && eb.is_integral() {
            common_numeric(ea, eb)
                .map(BinaryRule::Logic)
                .ok_or_else(mismatch)
        } else {
            Err(mismatch())
        };
    }
    if ea == Elem::Bool || eb == Elem::Bool {
        return if ea == eb && matches!(op, BinOp::Eq | BinOp::Ne) {
            Ok(BinaryRule::Compare)
        } else {
            Err(mismatch())
        };
    }
    let ct = common_numeric(ea, eb).ok_or_else(mismatch)?;
    match op {
        _ if is_cmp => Ok(BinaryRule::NumericCompare(ct)),
        BinOp::Pow if !ct.is_real() => Ok(BinaryRule::IntegerPower(ct)),
        BinOp::Add | BinOp::Sub | BinOp::Mul | BinOp::Div | BinOp::Pow => {
            Ok(BinaryRule::Arithmetic(ct))
        }
        BinOp::Mod if !ct.is_real() => Ok(BinaryRule::Arithmetic(ct)),
        _ => Err(mismatch()),
    }
}

/// Date and time arithmetic (IEC 61131-3 table of time operations): TIME +/- TIME,
/// TOD +/- TIME (wrapping within the day), DT +/- TIME, DATE - DATE, TOD - TOD, DT - DT
/// (giving TIME), TIME * and / numbers, comparisons within one family. The long forms
/// follow the same rules; an operation with a long operand gives the long result.
fn temporal_rule(
    op: BinOp,
    (a, ea): (Operand, Elem),
    (b, eb): (Operand, Elem),
) -> Result<BinaryRule, OperatorError> {
    // A literal factor is a number, not a duration (`T#1s * 2`).
    let factor = |o: &Operand, e: Elem, is_factor: bool| match (is_factor && o.flexible, o) {
        (true, o) if o.real_literal => (Type::LREAL, Elem::LReal),
        (true, _) => (Type::LINT, Elem::LInt),
        (false, o) => (o.ty.clone(), e),
    };
    let (ta, ea) = factor(&a, ea, op == BinOp::Mul);
    let (tb, eb) = factor(&b, eb, matches!(op, BinOp::Mul | BinOp::Div));
    let fa = ea.temporal_family();
    let fb = eb.temporal_family();
    let long = ea.is_long_temporal() || eb.is_long_temporal();
    let pick = |short: Elem| -> Elem {
        match (short, long) {
            (Elem::Time, true) => Elem::LTime,
            (Elem::Tod, true) => Elem::LTod,
            (Elem::Dt, true) => Elem::LDt,
            (Elem::Date, true) => Elem::LDate,
            (e, _) => e,
        }
    };
    let time = Some(Elem::Time);
    let (tod, dt) = (Some(Elem::Tod), Some(Elem::Dt));
    let temporal = |result, wraps| Ok(BinaryRule::Temporal { result, wraps });
    match op {
        _ if is_comparison(op) && fa == fb => temporal(Elem::Bool, false),
        BinOp::Add if fa == time && fb == time => temporal(pick(Elem::Time), false),
        BinOp::Add if fa == tod && fb == time || fa == time && fb == tod => {
            temporal(pick(Elem::Tod), true)
        }
        BinOp::Add if fa == dt && fb == time || fa == time && fb == dt => {
            temporal(pick(Elem::Dt), false)
        }
        // TIME - TIME, DATE - DATE, TOD - TOD, DT - DT
        BinOp::Sub if fa == fb => temporal(pick(Elem::Time), false),
        BinOp::Sub if fa == tod && fb == time => temporal(pick(Elem::Tod), true),
        BinOp::Sub if fa == dt && fb == time => temporal(pick(Elem::Dt), false),
        BinOp::Mul | BinOp::Div
            if fa == time && eb.is_numeric()
                || op == BinOp::Mul && fb == time && ea.is_numeric() =>
        {
            let duration_first = fa == time;
            Ok(BinaryRule::Scale {
                result: if duration_first { ea } else { eb },
                duration_first,
                number: if duration_first { tb } else { ta },
            })
        }
        _ => {
            let hint = match (op, fa, fb) {
                (BinOp::Add | BinOp::Sub, Some(Elem::Date), Some(Elem::Time)) => {
                    " (a DATE is a day: use DATE_TO_DT or CONCAT_DATE_TOD for a point in time)"
                }
                (BinOp::Add, Some(x), Some(y)) if x == y && x != Elem::Time => {
                    " (two points in time cannot be added; subtract them for a TIME)"
                }
                _ => "",
            };
            Err(OperatorError::Types { a: ta, b: tb, hint })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule(op: BinOp, a: &Type, b: &Type) -> Result<BinaryRule, OperatorError> {
        binary_rule(op, Operand::plain(a), Operand::plain(b))
    }

    const ARITHMETIC: [BinOp; 6] = [
        BinOp::Add,
        BinOp::Sub,
        BinOp::Mul,
        BinOp::Div,
        BinOp::Mod,
        BinOp::Pow,
    ];

    #[test]
    fn numbers_meet_in_their_common_type() {
        let (int, dint, real) = (Type::Elem(Elem::Int), Type::DINT, Type::LREAL);
        assert_eq!(
            rule(BinOp::Add, &int, &dint),
            Ok(BinaryRule::Arithmetic(Elem::DInt))
        );
        assert_eq!(
            rule(BinOp::Lt, &int, &real),
            Ok(BinaryRule::NumericCompare(Elem::LReal))
        );
        assert_eq!(
            rule(BinOp::Pow, &int, &dint),
            Ok(BinaryRule::IntegerPower(Elem::DInt))
        );
        assert_eq!(
            rule(BinOp::Pow, &real, &int),
            Ok(BinaryRule::Arithmetic(Elem::LReal))
        );
        assert!(rule(BinOp::Mod, &real, &int).is_err(), "no MOD of reals");
        assert_eq!(
            rule(BinOp::Mod, &int, &int),
            Ok(BinaryRule::Arithmetic(Elem::Int))
        );
    }

    #[test]
    fn booleans_take_logic_and_equality_only() {
        let b = Type::BOOL;
        assert_eq!(rule(BinOp::Xor, &b, &b), Ok(BinaryRule::Logic(Elem::Bool)));
        assert_eq!(rule(BinOp::Ne, &b, &b), Ok(BinaryRule::Compare));
        for op in ARITHMETIC.into_iter().chain([BinOp::Lt]) {
            assert!(rule(op, &b, &b).is_err(), "{op:?}");
        }
        let word = Type::Elem(Elem::Word);
        assert_eq!(
            rule(BinOp::And, &word, &Type::Elem(Elem::Byte)),
            Ok(BinaryRule::Logic(Elem::Word))
        );
        assert!(rule(BinOp::And, &b, &word).is_err());
        assert!(rule(BinOp::Or, &Type::LREAL, &Type::LREAL).is_err());
    }

    #[test]
    fn strings_and_characters_are_compared_not_computed() {
        let (s, w) = (Type::String(80), Type::WString(80));
        assert_eq!(
            rule(BinOp::Eq, &s, &s),
            Ok(BinaryRule::StringCompare { wide: false })
        );
        assert!(rule(BinOp::Add, &s, &s).is_err());
        assert!(rule(BinOp::Eq, &s, &w).is_err(), "a STRING variable");
        let literal = Operand {
            string_literal: true,
            ..Operand::plain(&s)
        };
        assert_eq!(
            binary_rule(BinOp::Eq, literal, Operand::plain(&w)),
            Ok(BinaryRule::StringCompare { wide: true }),
            "a STRING literal adapts"
        );
        let c = Type::Elem(Elem::Char);
        assert_eq!(rule(BinOp::Lt, &c, &c), Ok(BinaryRule::Compare));
        assert!(rule(BinOp::Add, &c, &c).is_err());
        let number = Operand {
            flexible: true,
            ..Operand::plain(&Type::LINT)
        };
        assert_eq!(
            binary_rule(BinOp::Eq, Operand::plain(&c), number),
            Err(OperatorError::CharacterIsNoNumber)
        );
    }

    #[test]
    fn negation_and_not_keep_the_type_but_for_narrow_unsigned_negation() {
        let neg = |t: &Type| unary_rule(UnOp::Neg, t);
        assert_eq!(neg(&Type::REAL), Ok(UnaryRule::Same(Elem::Real)));
        assert_eq!(neg(&Type::TIME), Ok(UnaryRule::Same(Elem::Time)));
        assert_eq!(
            neg(&Type::Elem(Elem::Byte)),
            Ok(UnaryRule::NegateWidened(Elem::Int))
        );
        assert_eq!(
            neg(&Type::Elem(Elem::UDInt)),
            Ok(UnaryRule::NegateWidened(Elem::LInt))
        );
        assert!(neg(&Type::ULINT).is_err(), "no wider signed integer");
        assert!(neg(&Type::BOOL).is_err());
        assert!(neg(&Type::String(80)).is_err());
        let not = |t: &Type| unary_rule(UnOp::Not, t);
        assert_eq!(not(&Type::BOOL), Ok(UnaryRule::Same(Elem::Bool)));
        assert_eq!(not(&Type::DINT), Ok(UnaryRule::Same(Elem::DInt)));
        assert!(not(&Type::LREAL).is_err());
        assert!(not(&Type::Exception).is_err());
    }

    #[test]
    fn time_follows_the_standards_table() {
        let (time, ltime) = (Type::Elem(Elem::Time), Type::Elem(Elem::LTime));
        let (tod, date, dt) = (
            Type::Elem(Elem::Tod),
            Type::Elem(Elem::Date),
            Type::Elem(Elem::Dt),
        );
        let temporal = |result, wraps| Ok(BinaryRule::Temporal { result, wraps });
        assert_eq!(
            rule(BinOp::Add, &time, &ltime),
            temporal(Elem::LTime, false)
        );
        assert_eq!(rule(BinOp::Add, &time, &tod), temporal(Elem::Tod, true));
        assert_eq!(rule(BinOp::Sub, &dt, &dt), temporal(Elem::Time, false));
        assert_eq!(rule(BinOp::Sub, &date, &date), temporal(Elem::Time, false));
        assert_eq!(rule(BinOp::Ge, &tod, &tod), temporal(Elem::Bool, false));
        let Err(OperatorError::Types { hint, .. }) = rule(BinOp::Add, &date, &time) else {
            panic!("DATE + TIME");
        };
        assert!(hint.contains("DATE_TO_DT"));
        let Err(OperatorError::Types { hint, .. }) = rule(BinOp::Add, &dt, &dt) else {
            panic!("DT + DT");
        };
        assert!(hint.contains("subtract"));
        // A literal factor is a number: LREAL with a REAL literal in it, else LINT.
        let two = Operand {
            flexible: true,
            ..Operand::plain(&time)
        };
        assert_eq!(
            binary_rule(BinOp::Mul, two, Operand::plain(&time)),
            Ok(BinaryRule::Scale {
                result: Elem::Time,
                duration_first: false,
                number: Type::LINT
            })
        );
        let half = Operand {
            real_literal: true,
            ..two
        };
        assert_eq!(
            binary_rule(BinOp::Div, Operand::plain(&ltime), half),
            Ok(BinaryRule::Scale {
                result: Elem::LTime,
                duration_first: true,
                number: Type::LREAL
            })
        );
        assert!(
            rule(BinOp::Div, &Type::DINT, &time).is_err(),
            "no number / TIME"
        );
    }
}
