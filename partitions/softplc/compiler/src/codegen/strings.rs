//! Standard functions on STRING and WSTRING: LEN, LEFT, RIGHT, MID, CONCAT, INSERT, DELETE,
//! REPLACE, FIND and their operands.

use super::stdfuncs::*;
use super::*;

impl Gen<'_> {
    /// String functions: LEN, LEFT/RIGHT, MID/DELETE, INSERT, REPLACE, FIND, CONCAT, on
    /// STRINGs or on WSTRINGs (the first string argument decides; STRING literals adapt).
    pub(super) fn std_string(&mut self, c: &StdArgs) -> Option<Type> {
        let Some(kind) = self.string_kind(c) else {
            return Some(Type::Error);
        };
        let wide = kind.is_wstring();
        // The builtin of the string kind.
        let pick = |narrow: Builtin| -> Builtin {
            if !wide {
                return narrow;
            }
            match narrow {
                Builtin::StrLen => Builtin::WStrLen,
                Builtin::StrAssign => Builtin::WStrAssign,
                Builtin::StrConcat => Builtin::WStrConcat,
                Builtin::StrLeft => Builtin::WStrLeft,
                Builtin::StrRight => Builtin::WStrRight,
                Builtin::StrMid => Builtin::WStrMid,
                Builtin::StrInsert => Builtin::WStrInsert,
                Builtin::StrDelete => Builtin::WStrDelete,
                Builtin::StrReplace => Builtin::WStrReplace,
                _ => Builtin::WStrFind,
            }
        };
        let t = match c.name {
            "LEN" => {
                self.string_arg_of(c.exprs[0], wide);
                self.emit(|b| b.call_builtin(pick(Builtin::StrLen)));
                Type::INT
            }
            "LEFT" | "RIGHT" => {
                let result = self.string_result(c, wide);
                let dst = self.temp_string_like(&result);
                self.emit(|b| b.push_u32(dst));
                self.string_arg_of(c.exprs[0], wide);
                self.int_arg(c.exprs[1]);
                let builtin = pick(if c.name == "LEFT" {
                    Builtin::StrLeft
                } else {
                    Builtin::StrRight
                });
                self.emit(|b| {
                    b.call_builtin(builtin);
                    b.push_u32(dst);
                });
                result
            }
            "MID" | "DELETE" => {
                let result = self.string_result(c, wide);
                let dst = self.temp_string_like(&result);
                self.emit(|b| b.push_u32(dst));
                self.string_arg_of(c.exprs[0], wide);
                self.int_arg(c.exprs[1]);
                self.int_arg(c.exprs[2]);
                let builtin = pick(if c.name == "MID" {
                    Builtin::StrMid
                } else {
                    Builtin::StrDelete
                });
                self.emit(|b| {
                    b.call_builtin(builtin);
                    b.push_u32(dst);
                });
                result
            }
            "INSERT" | "REPLACE" => {
                let result = self.string_result(c, wide);
                let dst = self.temp_string_like(&result);
                self.emit(|b| b.push_u32(dst));
                self.string_arg_of(c.exprs[0], wide);
                self.string_arg_of(c.exprs[1], wide);
                for e in &c.exprs[2..] {
                    self.int_arg(e);
                }
                let builtin = pick(if c.name == "INSERT" {
                    Builtin::StrInsert
                } else {
                    Builtin::StrReplace
                });
                self.emit(|b| {
                    b.call_builtin(builtin);
                    b.push_u32(dst);
                });
                result
            }
            "FIND" => {
                self.string_arg_of(c.exprs[0], wide);
                self.string_arg_of(c.exprs[1], wide);
                self.emit(|b| b.call_builtin(pick(Builtin::StrFind)));
                Type::INT
            }
            "CONCAT" => {
                let result = self.string_result(c, wide);
                let dst = self.temp_string_like(&result);
                // dst := first; then dst := CONCAT(dst, next) for the rest.
                self.emit(|b| b.push_u32(dst));
                self.string_arg_of(c.exprs[0], wide);
                self.emit(|b| b.call_builtin(pick(Builtin::StrAssign)));
                for x in &c.exprs[1..] {
                    self.emit(|b| {
                        b.push_u32(dst);
                        b.push_u32(dst);
                    });
                    self.string_arg_of(x, wide);
                    self.emit(|b| b.call_builtin(pick(Builtin::StrConcat)));
                }
                self.emit(|b| b.push_u32(dst));
                result
            }

            _ => unreachable!("std_string called for {}", c.name),
        };
        Some(t)
    }

    /// The kind of string (a STRING or WSTRING of the default length) the string function
    /// call `c` works on, as the checker decided it ([`crate::typed::GenericTypes`]).
    fn string_kind(&mut self, c: &StdArgs) -> Option<Type> {
        self.recorded_generic_type(c.id)
    }

    /// The type of the string function call `c` on STRINGs (or, `wide`, WSTRINGs): INT for
    /// LEN and FIND, else a string as long as its result may be.
    pub(crate) fn string_result(&mut self, c: &StdArgs, wide: bool) -> Type {
        let kind = |len: u32| {
            if wide {
                Type::WString(len)
            } else {
                Type::String(len)
            }
        };
        match c.name {
            "LEN" | "FIND" => Type::INT,
            "INSERT" | "REPLACE" => kind(
                (self.string_len_of(c.exprs[0]) + self.string_len_of(c.exprs[1]))
                    .min(MAX_TEMP_STRING),
            ),
            "CONCAT" => kind(
                c.exprs
                    .iter()
                    .map(|e| self.string_len_of(e))
                    .sum::<u32>()
                    .clamp(1, MAX_TEMP_STRING),
            ),
            _ => kind(self.string_len_of(c.exprs[0])),
        }
    }

    pub(super) fn string_arg(&mut self, e: &Expr) {
        self.string_arg_of(e, false);
    }

    /// A STRING (or, `wide`, a WSTRING; a STRING literal then is one) argument.
    pub(super) fn string_arg_of(&mut self, e: &Expr, wide: bool) {
        let want = if wide {
            Type::WString(DEFAULT_STRING_LEN)
        } else {
            Type::String(DEFAULT_STRING_LEN)
        };
        self.expr(e, Some(&want));
    }

    /// An integer argument (of any integer type), as LINT.
    pub(super) fn int_arg(&mut self, e: &Expr) {
        let t = self.infer(e);
        self.value_to_any(e, &t, &Type::LINT);
    }

    /// The length of the string `e` (the default length for anything else).
    pub(crate) fn string_len_of(&mut self, e: &Expr) -> u32 {
        match self.infer(e) {
            Type::String(n) | Type::WString(n) => n,
            _ => DEFAULT_STRING_LEN,
        }
    }
}
