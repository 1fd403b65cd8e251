//! Conversion functions: `X_TO_Y`, `TO_Y` and the typed truncations, between elementary types
//! and to and from STRING.

use super::stdfuncs::*;
use super::*;
use crate::sema::stdfuncs::ConversionArgument;

impl Gen<'_> {
    /// `A_TO_B` conversions (and `TO_B` is not supported). Between numbers and bit strings
    /// any argument of those is taken (converted to A first, as CODESYS does: `INT_TO_BYTE`
    /// of a DINT); the date/time types convert among themselves and to and from numbers;
    /// CHAR and WCHAR to and from integers and bit strings; everything to and from STRING.
    pub(super) fn conversion(
        &mut self,
        name: &str,
        id: &Ident,
        exprs: &[&Expr],
        span: Span,
    ) -> Option<Type> {
        let (from, to) = name.split_once("_TO_")?;
        let (Some(ft), Some(tt)) = (Self::conversion_type(from), Self::conversion_type(to)) else {
            return None;
        };
        let &[arg] = exprs else {
            self.missing_record(span, "passed a conversion without one argument");
            return Some(Type::Error);
        };
        match (&ft, &tt) {
            (Type::String(_), Type::String(_)) => {
                self.string_arg(arg);
                Some(Type::String(DEFAULT_STRING_LEN))
            }
            (Type::WString(_), Type::WString(_)) => {
                self.string_arg_of(arg, true);
                Some(Type::WString(DEFAULT_STRING_LEN))
            }
            (Type::String(_), Type::WString(_)) => {
                let len = self.string_len_of(arg);
                let dst = self.temp_wstring(len);
                self.emit(|b| b.push_u32(dst));
                self.string_arg(arg);
                self.emit(|b| {
                    b.call_builtin(Builtin::WStrFromStr);
                    b.push_u32(dst);
                });
                Some(Type::WString(len))
            }
            (Type::WString(_), Type::String(_)) => {
                // Up to three UTF-8 bytes a unit.
                let len = (self.string_len_of(arg) * 3).min(MAX_TEMP_STRING);
                let dst = self.temp_string(len);
                self.emit(|b| b.push_u32(dst));
                self.string_arg_of(arg, true);
                self.emit(|b| {
                    b.call_builtin(Builtin::StrFromWStr);
                    b.push_u32(dst);
                });
                Some(Type::String(len))
            }
            (Type::WString(_), Type::Elem(Elem::WChar)) => {
                // The first unit, or 0 for an empty string.
                self.string_arg_of(arg, true);
                self.emit(|b| {
                    b.dup();
                    b.ld_ind(MemType::U16, 2);
                    b.push_i32(0);
                    b.op(Opcode::Ne);
                    b.swap();
                    b.ld_ind(MemType::U16, 4);
                    b.op(Opcode::Mul);
                });
                Some(tt)
            }
            (Type::Elem(Elem::WChar), Type::WString(_)) => {
                let dst = self.temp_wstring(1);
                self.value_to(arg, &ft);
                self.emit(|b| {
                    b.st_abs(MemType::U16, dst + 4);
                    b.push_i32(1);
                    b.st_abs(MemType::U16, dst + 2);
                    b.push_u32(dst);
                });
                Some(Type::WString(1))
            }
            // Other WSTRING conversions go through STRING.
            (Type::WString(_), Type::Elem(_)) => {
                let len = (self.string_len_of(arg) * 3).min(MAX_TEMP_STRING);
                let text = self.temp_string(len);
                self.emit(|b| b.push_u32(text));
                self.string_arg_of(arg, true);
                self.emit(|b| {
                    b.call_builtin(Builtin::StrFromWStr);
                    b.push_u32(text);
                });
                self.convert_string_on_stack(match tt {
                    Type::Elem(t) => t,
                    _ => Elem::DInt,
                });
                Some(tt)
            }
            (Type::Elem(_), Type::WString(_)) => {
                let text = self.conversion(&format!("{from}_TO_STRING"), id, exprs, span)?;
                let dst = self.temp_wstring(40);
                self.emit(|b| {
                    b.push_u32(dst);
                    b.swap();
                    b.call_builtin(Builtin::WStrFromStr);
                    b.push_u32(dst);
                });
                Some(if text.is_error() {
                    text
                } else {
                    Type::WString(40)
                })
            }
            (Type::String(_), Type::Elem(t)) => {
                self.string_arg(arg);
                self.convert_string_on_stack(*t);
                Some(tt)
            }
            _ => self.conversion_elem((ft, tt), id, exprs),
        }
    }

    /// The type a conversion's name calls `name` (`INT` of `INT_TO_REAL`).
    pub(crate) fn conversion_type(name: &str) -> Option<Type> {
        match name {
            "STRING" => Some(Type::String(DEFAULT_STRING_LEN)),
            "WSTRING" => Some(Type::WString(DEFAULT_STRING_LEN)),
            _ => Elem::from_name(name).map(Type::Elem),
        }
    }

    /// Converts the STRING whose address is on the stack to `t` (STRING_TO_*).
    pub(super) fn convert_string_on_stack(&mut self, t: Elem) {
        if t.is_real() {
            self.emit(|b| b.call_builtin(Builtin::StrToF64));
            self.convert(Elem::LReal, t);
        } else if let Some(kind) = t.time_kind() {
            self.emit(|b| {
                b.push_int(kind.code() as i64);
                b.call_builtin(Builtin::StrToDateTime);
            });
        } else if t.is_char() {
            // The first character, or 0 for an empty string.
            self.emit(|b| {
                b.dup();
                b.ld_ind(MemType::U16, 2);
                b.push_i32(0);
                b.op(Opcode::Ne);
                b.swap();
                b.ld_ind(MemType::U8, 4);
                b.op(Opcode::Mul);
            });
        } else {
            self.emit(|b| b.call_builtin(Builtin::StrToI64));
            if t == Elem::Bool {
                self.convert(Elem::LInt, Elem::Bool);
            } else {
                self.wrap(t);
            }
        }
    }

    /// The rest of [`Self::conversion`]: elementary types to STRING and among themselves.
    pub(super) fn conversion_elem(
        &mut self,
        (ft, tt): (Type, Type),
        id: &Ident,
        exprs: &[&Expr],
    ) -> Option<Type> {
        let arg = exprs[0];
        match (&ft, &tt) {
            (Type::Elem(f), Type::String(_)) => {
                let f = *f;
                if f.is_char() {
                    // A string of that one character.
                    let dst = self.temp_string(1);
                    self.value_to(arg, &ft);
                    self.emit(|b| {
                        b.st_abs(MemType::U8, dst + 4);
                        b.push_i32(1);
                        b.st_abs(MemType::U16, dst + 2);
                        b.push_u32(dst);
                    });
                    return Some(Type::String(1));
                }
                let dst = self.temp_string(40);
                self.emit(|b| b.push_u32(dst));
                self.value_to(arg, &ft);
                let bi = match f {
                    Elem::Real => Builtin::StrFromF32,
                    Elem::LReal => Builtin::StrFromF64,
                    Elem::Bool => Builtin::StrFromBool,
                    Elem::Time => Builtin::StrFromTime,
                    e if e.is_temporal() => {
                        let kind = e.time_kind().map_or(0, |k| k.code());
                        self.push_int(kind as i64);
                        Builtin::StrFromDateTime
                    }
                    e if e.is_signed_int() => Builtin::StrFromI64,
                    _ => Builtin::StrFromU64,
                };
                self.emit(|b| {
                    b.call_builtin(bi);
                    b.push_u32(dst);
                });
                Some(Type::String(40))
            }
            (Type::Elem(f), Type::Elem(t)) => {
                let (f, t) = (*f, *t);
                let Some(route) = self.conversion_argument(id) else {
                    return Some(Type::Error);
                };
                match route {
                    ConversionArgument::Implicit => self.value_to(arg, &ft),
                    ConversionArgument::FromNumber => {
                        let at = self.infer(arg);
                        self.value_to_any(arg, &at, &ft);
                    }
                }
                self.convert(f, t);
                Some(tt)
            }
            _ => None,
        }
    }

    /// How the argument of the conversion `id` reaches its source type, as the checker
    /// decided it ([`crate::typed::ConversionArguments`]).
    fn conversion_argument(&mut self, id: &Ident) -> Option<ConversionArgument> {
        let route = self.conversion_arguments.of(self.cur, id).copied();
        if route.is_none() {
            self.missing_record(id.span, "decided no conversion for this argument");
        }
        route
    }
}
