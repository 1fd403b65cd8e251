//! Standard functions on STRING and WSTRING: LEN, LEFT, RIGHT, MID, CONCAT, INSERT, DELETE,
//! REPLACE, FIND and their operands.

use super::stdfuncs::*;
use super::*;
use crate::sema::stdfuncs as rules;

impl Gen<'_> {
    /// String functions: LEN, LEFT/RIGHT, MID/DELETE, INSERT, REPLACE, FIND, CONCAT, on
    /// STRINGs or on WSTRINGs (the first string argument decides; STRING literals adapt).
    pub(super) fn std_string(&mut self, c: &StdArgs) -> Option<Type> {
        let Some(kind) = self.string_kind(c) else {
            return Some(Type::Error);
        };
        let wide = kind.is_wstring();
        let kind = |len: u32| {
            if wide {
                Type::WString(len)
            } else {
                Type::String(len)
            }
        };
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
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                self.string_arg_of(c.exprs[0], wide);
                self.emit(|b| b.call_builtin(pick(Builtin::StrLen)));
                Type::INT
            }
            "LEFT" | "RIGHT" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                let len = self.string_len_of(c.exprs[0]);
                let dst = self.temp_string_like(&kind(len));
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
                kind(len)
            }
            "MID" | "DELETE" => {
                if !self.arity(c, 3) {
                    return Some(Type::Error);
                }
                let len = self.string_len_of(c.exprs[0]);
                let dst = self.temp_string_like(&kind(len));
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
                kind(len)
            }
            "INSERT" | "REPLACE" => {
                let n = if c.name == "INSERT" { 3 } else { 4 };
                if !self.arity(c, n) {
                    return Some(Type::Error);
                }
                let len = (self.string_len_of(c.exprs[0]) + self.string_len_of(c.exprs[1]))
                    .min(MAX_TEMP_STRING);
                let dst = self.temp_string_like(&kind(len));
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
                kind(len)
            }
            "FIND" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                self.string_arg_of(c.exprs[0], wide);
                self.string_arg_of(c.exprs[1], wide);
                self.emit(|b| b.call_builtin(pick(Builtin::StrFind)));
                Type::INT
            }
            "CONCAT" => {
                if self.check_only && c.exprs.is_empty() {
                    self.error(codes::ARGUMENT_COUNT, c.span, "CONCAT needs arguments");
                    return Some(Type::Error);
                }
                let len = c
                    .exprs
                    .iter()
                    .map(|e| self.string_len_of(e))
                    .sum::<u32>()
                    .clamp(1, MAX_TEMP_STRING);
                let dst = self.temp_string_like(&kind(len));
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
                kind(len)
            }

            _ => unreachable!("std_string called for {}", c.name),
        };
        Some(t)
    }

    /// The kind of string (a STRING or WSTRING of the default length) the string function
    /// call `c` works on: the checking pass decides it by its first argument that is no
    /// STRING literal ([`rules::string_kind`]) and records it
    /// ([`crate::typed::GenericTypes`]); emission reads the record.
    fn string_kind(&mut self, c: &StdArgs) -> Option<Type> {
        if !self.check_only {
            return self.recorded_generic_type(c.id);
        }
        let first = c.exprs.iter().find(|e| !matches!(e.kind, ExprKind::Str(_)));
        let first = first.map(|e| self.infer(e));
        let kind = rules::string_kind(first.as_ref());
        self.record_generic_type(c.id, kind.clone());
        Some(kind)
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
        let t = self.expr(e, Some(&want));
        let fits = if wide { t.is_wstring() } else { t.is_string() };
        if self.check_only && !fits && !t.is_error() {
            let msg = format!(
                "expected a {}, found {}",
                if wide { "WSTRING" } else { "STRING" },
                self.tname(&t)
            );
            self.error(codes::TYPE_MISMATCH, e.span, msg);
        }
    }

    pub(super) fn int_arg(&mut self, e: &Expr) {
        let t = self.infer(e);
        if self.check_only && !t.is_integral() {
            if !t.is_error() {
                let msg = format!("expected an integer, found {}", self.tname(&t));
                self.error(codes::TYPE_MISMATCH, e.span, msg);
            }
            self.expr(e, None);
            return;
        }
        self.value_to_any(e, &t, &Type::LINT);
    }

    pub(super) fn string_len_of(&mut self, e: &Expr) -> u32 {
        match self.infer(e) {
            Type::String(n) | Type::WString(n) => n,
            _ => DEFAULT_STRING_LEN,
        }
    }
}
