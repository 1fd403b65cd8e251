//! Hand-written lexer for IEC 61131-3 Structured Text.
//!
//! Keywords and identifiers are case-insensitive; identifiers are kept upper-cased for lookup
//! and with their original spelling for messages. Typed literals (`INT#5`, `T#1s`, `16#FF`)
//! are recognised here so the parser sees one token per literal.

use crate::codes::{self, Code};
use crate::diagnostics::{Diagnostic, Span};
use crate::types::Elem;

#[derive(Debug, Clone, PartialEq)]
pub enum Tok {
    /// Identifier or keyword: (UPPER-CASED, original spelling).
    Ident(String, String),
    /// Integer literal (magnitude; a sign is a unary operator).
    Int(u128),
    Real(f64),
    /// Duration literal in nanoseconds.
    Time(i128),
    /// Other date/time literal (`LT#`, `D#`, `TOD#`, `DT#` and the long forms): its type and
    /// nanoseconds (since 1970-01-01, or since midnight for a time of day).
    Temporal(Elem, i128),
    Str(String),
    /// `"..."`: a WSTRING literal.
    WStr(String),
    /// `TYPE#` prefix of a typed literal such as `INT#5` or `Color#Red`.
    TypePrefix(String, String),
    /// Directly represented variable `%IX0.1`, `%QW4`, ...: the text after `%`, upper-cased
    /// (the parser checks its form).
    Direct(String),
    /// The pragma `{attribute 'shared' := 'VALUE'}` with its value as written (`None` for
    /// `{attribute 'shared'}`); the parser attaches it to the declaration after it. Every
    /// other pragma carries no meaning for this compiler and is skipped.
    SharedAttribute(Option<String>),
    /// The pragma `{attribute 'safe' := 'VALUE'}` before a located output: the value it
    /// takes when the runtime sets the outputs safe.
    SafeAttribute(Option<String>),
    Assign,   // :=
    Arrow,    // =>
    Colon,    // :
    Semi,     // ;
    Comma,    // ,
    Dot,      // .
    DotDot,   // ..
    LParen,   // (
    RParen,   // )
    LBracket, // [
    RBracket, // ]
    Plus,     // +
    Minus,    // -
    Star,     // *
    Slash,    // /
    Power,    // **
    Eq,       // =
    Ne,       // <>
    Lt,       // <
    Le,       // <=
    Gt,       // >
    Ge,       // >=
    Amp,      // &
    Caret,    // ^ (dereference)
    Eof,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    pub tok: Tok,
    pub span: Span,
}

/// Splits `text` into tokens. Lexical errors are reported and the offending character skipped,
/// so one bad character does not hide the errors after it.
pub fn lex(file: u32, text: &str, diags: &mut Vec<Diagnostic>) -> Vec<Token> {
    let mut lx = Lexer {
        file,
        src: text.as_bytes(),
        text,
        pos: 0,
        out: Vec::new(),
        diags,
    };
    lx.run();
    lx.out
}

/// The value of a CODESYS attribute pragma body `attribute 'NAME' := 'VALUE'` (or `None`
/// for `attribute 'NAME'`) when NAME is `wanted`; `None` outside for any other pragma.
fn attribute(body: &str, wanted: &str) -> Option<Option<String>> {
    let rest = body.trim_start();
    let keyword = rest.get(..9)?;
    if !keyword.eq_ignore_ascii_case("attribute") {
        return None;
    }
    let rest = rest[9..].trim_start().strip_prefix('\'')?;
    let (name, rest) = rest.split_once('\'')?;
    if !name.trim().eq_ignore_ascii_case(wanted) {
        return None;
    }
    let rest = rest.trim();
    if rest.is_empty() {
        return Some(None);
    }
    // Anything after the name other than `:= 'value'` is kept verbatim so the parser can
    // say what is wrong with it.
    let value = rest
        .strip_prefix(":=")
        .map(str::trim)
        .and_then(|v| v.strip_prefix('\'')?.strip_suffix('\''))
        .unwrap_or(rest);
    Some(Some(value.to_string()))
}

struct Lexer<'a> {
    file: u32,
    src: &'a [u8],
    text: &'a str,
    pos: usize,
    out: Vec<Token>,
    diags: &'a mut Vec<Diagnostic>,
}

impl Lexer<'_> {
    fn peek(&self, ahead: usize) -> u8 {
        self.src.get(self.pos + ahead).copied().unwrap_or(0)
    }

    fn span(&self, start: usize) -> Span {
        Span::new(self.file, start, self.pos)
    }

    fn error(&mut self, code: Code, start: usize, msg: impl Into<String>) {
        let mut end = self.pos.max(start + 1).min(self.src.len().max(start));
        while !self.text.is_char_boundary(end) {
            end += 1;
        }
        let span = Span::new(self.file, start, end);
        self.diags.push(Diagnostic::error(code, span, msg));
    }

    fn push(&mut self, tok: Tok, start: usize) {
        let span = self.span(start);
        self.out.push(Token { tok, span });
    }

    fn run(&mut self) {
        while self.pos < self.src.len() {
            let c = self.peek(0);
            let start = self.pos;
            match c {
                b' ' | b'\t' | b'\r' | b'\n' | 0x0c => self.pos += 1,
                b'(' if self.peek(1) == b'*' => self.block_comment(b'(', b'*', b')'),
                b'/' if self.peek(1) == b'*' => self.block_comment(b'/', b'*', b'/'),
                b'/' if self.peek(1) == b'/' => {
                    while self.pos < self.src.len() && self.peek(0) != b'\n' {
                        self.pos += 1;
                    }
                }
                b'{' => {
                    while self.pos < self.src.len() && self.peek(0) != b'}' {
                        self.pos += 1;
                    }
                    if self.pos >= self.src.len() {
                        self.error(
                            codes::UNTERMINATED_COMMENT,
                            start,
                            "unterminated pragma `{`",
                        );
                    } else {
                        self.pos += 1;
                        let body = &self.text[start + 1..self.pos - 1];
                        if let Some(value) = attribute(body, "shared") {
                            self.push(Tok::SharedAttribute(value), start);
                        } else if let Some(value) = attribute(body, "safe") {
                            self.push(Tok::SafeAttribute(value), start);
                        }
                    }
                }
                b'\'' => self.string(b'\''),
                b'"' => self.string(b'"'),
                b'%' => {
                    self.pos += 1;
                    // `%IX0.1` has dots; a partial access `x.%B1.%X2` ends at one.
                    let partial = matches!(self.out.last().map(|t| &t.tok), Some(Tok::Dot));
                    while self.peek(0).is_ascii_alphanumeric() || self.peek(0) == b'.' && !partial {
                        self.pos += 1;
                    }
                    let text = self.text[start + 1..self.pos].to_ascii_uppercase();
                    self.push(Tok::Direct(text), start);
                }
                b'0'..=b'9' => self.number(),
                c if c == b'_' || c.is_ascii_alphabetic() => self.ident(),
                _ => self.punct(),
            }
        }
        let end = self.src.len();
        self.out.push(Token {
            tok: Tok::Eof,
            span: Span::new(self.file, end, end),
        });
    }

    fn block_comment(&mut self, open0: u8, open1: u8, close: u8) {
        let start = self.pos;
        self.pos += 2;
        let mut depth = 1;
        while self.pos < self.src.len() {
            if self.peek(0) == open0 && self.peek(1) == open1 {
                depth += 1;
                self.pos += 2;
            } else if self.peek(0) == open1 && self.peek(1) == close {
                depth -= 1;
                self.pos += 2;
                if depth == 0 {
                    return;
                }
            } else {
                self.pos += 1;
            }
        }
        self.pos = start + 2;
        self.error(codes::UNTERMINATED_COMMENT, start, "unterminated comment");
        self.pos = self.src.len();
    }

    /// A STRING literal `'...'` (`$NN` is a byte) or a WSTRING literal `"..."` (`$NNNN` is a
    /// UTF-16 code unit).
    fn string(&mut self, quote: u8) {
        let start = self.pos;
        self.pos += 1;
        let wide = quote == b'"';
        let mut value = String::new();
        loop {
            if self.pos >= self.src.len() || self.peek(0) == b'\n' {
                self.error(
                    codes::UNTERMINATED_STRING,
                    start,
                    "unterminated string literal",
                );
                return;
            }
            let c = self.peek(0);
            if c == quote {
                self.pos += 1;
                break;
            }
            if c == b'$' && wide {
                let digits = &self.src[self.pos + 1..(self.pos + 5).min(self.src.len())];
                if digits.len() == 4 && digits.iter().all(u8::is_ascii_hexdigit) {
                    let hex = std::str::from_utf8(digits).unwrap_or("0");
                    let unit = u32::from_str_radix(hex, 16).unwrap_or(0);
                    value.push(char::from_u32(unit).unwrap_or(char::REPLACEMENT_CHARACTER));
                    self.pos += 5;
                    continue;
                }
            }
            if c == b'$' {
                let at = self.pos;
                let e = self.text[self.pos + 1..].chars().next().unwrap_or('\0');
                self.pos += 1 + e.len_utf8().min(self.src.len() - self.pos - 1);
                match e.to_ascii_uppercase() {
                    '$' => value.push('$'),
                    '\'' => value.push('\''),
                    '"' => value.push('"'),
                    'L' | 'N' => value.push('\n'),
                    'P' => value.push('\x0c'),
                    'R' => value.push('\r'),
                    'T' => value.push('\t'),
                    h if !wide && h.is_ascii_hexdigit() && self.peek(0).is_ascii_hexdigit() => {
                        let hex = [h as u8, self.peek(0)];
                        self.pos += 1;
                        let s = std::str::from_utf8(&hex).unwrap_or("0");
                        value.push(u8::from_str_radix(s, 16).unwrap_or(0) as char);
                    }
                    _ => {
                        self.diags.push(Diagnostic::error(
                            codes::INVALID_ESCAPE,
                            Span::new(self.file, at, self.pos),
                            "invalid escape sequence in string literal",
                        ));
                    }
                }
                continue;
            }
            // Copy one whole UTF-8 character.
            let ch = self.text[self.pos..].chars().next().unwrap_or('?');
            value.push(ch);
            self.pos += ch.len_utf8();
        }
        self.push(
            if wide {
                Tok::WStr(value)
            } else {
                Tok::Str(value)
            },
            start,
        );
    }

    /// Digits with `_` separators in the given radix; returns the digit text without separators.
    fn digits(&mut self, radix: u32) -> String {
        let mut s = String::new();
        while self.pos < self.src.len() {
            let c = self.peek(0);
            if c == b'_' {
                self.pos += 1;
            } else if (c as char).is_digit(radix) {
                s.push(c as char);
                self.pos += 1;
            } else {
                break;
            }
        }
        s
    }

    fn number(&mut self) {
        let start = self.pos;
        let int = self.digits(10);
        if self.peek(0) == b'#' {
            // Based integer: 2#1010, 8#17, 16#FF.
            self.pos += 1;
            let radix: u32 = int.parse().unwrap_or(0);
            if ![2, 8, 16].contains(&radix) {
                self.error(
                    codes::INVALID_BASED_LITERAL,
                    start,
                    format!("unsupported number base {radix} (use 2, 8 or 16)"),
                );
                self.digits(16);
                self.push(Tok::Int(0), start);
                return;
            }
            let d = self.digits(radix);
            match u128::from_str_radix(&d, radix) {
                Ok(v) if !d.is_empty() => self.push(Tok::Int(v), start),
                _ => {
                    self.error(
                        codes::INVALID_BASED_LITERAL,
                        start,
                        "invalid based integer literal",
                    );
                    self.push(Tok::Int(0), start);
                }
            }
            return;
        }
        let mut is_real = false;
        let mut text = int;
        if self.peek(0) == b'.' && self.peek(1).is_ascii_digit() {
            is_real = true;
            self.pos += 1;
            text.push('.');
            text.push_str(&self.digits(10));
        }
        if matches!(self.peek(0), b'e' | b'E')
            && (self.peek(1).is_ascii_digit()
                || (matches!(self.peek(1), b'+' | b'-') && self.peek(2).is_ascii_digit()))
        {
            is_real = true;
            text.push('e');
            self.pos += 1;
            if matches!(self.peek(0), b'+' | b'-') {
                text.push(self.peek(0) as char);
                self.pos += 1;
            }
            text.push_str(&self.digits(10));
        }
        if is_real {
            let v = text.parse::<f64>().unwrap_or(0.0);
            self.push(Tok::Real(v), start);
        } else {
            match text.parse::<u128>() {
                Ok(v) => self.push(Tok::Int(v), start),
                Err(_) => {
                    self.error(codes::INTEGER_TOO_LARGE, start, "integer literal too large");
                    self.push(Tok::Int(0), start);
                }
            }
        }
    }

    fn ident(&mut self) {
        let start = self.pos;
        while self.pos < self.src.len()
            && (self.peek(0) == b'_' || self.peek(0).is_ascii_alphanumeric())
        {
            self.pos += 1;
        }
        let orig = self.text[start..self.pos].to_string();
        let upper = orig.to_ascii_uppercase();
        if self.peek(0) == b'#' {
            self.pos += 1;
            let elem = match upper.as_str() {
                "T" | "TIME" => Some(Elem::Time),
                "LT" | "LTIME" => Some(Elem::LTime),
                "D" | "DATE" => Some(Elem::Date),
                "LD" | "LDATE" => Some(Elem::LDate),
                "TOD" | "TIME_OF_DAY" => Some(Elem::Tod),
                "LTOD" | "LTIME_OF_DAY" => Some(Elem::LTod),
                "DT" | "DATE_AND_TIME" => Some(Elem::Dt),
                "LDT" | "LDATE_AND_TIME" => Some(Elem::LDt),
                _ => None,
            };
            match elem {
                Some(e) if e.is_duration() => self.duration(start, e),
                Some(e) => self.date_time(start, e),
                None => self.push(Tok::TypePrefix(upper, orig), start),
            }
            return;
        }
        self.push(Tok::Ident(upper, orig), start);
    }

    /// A date (`D#2024-02-29`), time of day (`TOD#12:30:00.5`, seconds optional) or date
    /// and time (`DT#2024-02-29-12:30:00`) after its `#`.
    fn date_time(&mut self, start: usize, elem: Elem) {
        let body_start = self.pos;
        while matches!(self.peek(0), b'0'..=b'9' | b':' | b'.' | b'-') {
            self.pos += 1;
        }
        let body = &self.src[body_start..self.pos];
        let kind = elem.time_kind().expect("a date/time type");
        let value = plc_vm::builtins::parse_date_time(body, kind);
        if value.is_none() {
            let example = match elem.temporal_family() {
                Some(Elem::Date) => "D#2024-02-29",
                Some(Elem::Tod) => "TOD#13:05:00 or TOD#13:05:00.250",
                _ => "DT#2024-02-29-13:05:00",
            };
            self.error(
                codes::MALFORMED_LITERAL,
                start,
                format!(
                    "malformed or invalid {} literal (expected e.g. {example})",
                    elem.name()
                ),
            );
        }
        self.push(Tok::Temporal(elem, value.unwrap_or(0) as i128), start);
    }

    /// Duration after `T#` (or `LT#`): `[-]` then components like `1d2h3m4s5ms6us7ns`, each
    /// optionally fractional (`1.5s`), with `_` separators.
    fn duration(&mut self, start: usize, elem: Elem) {
        let negative = if self.peek(0) == b'-' {
            self.pos += 1;
            true
        } else {
            false
        };
        let mut total: f64 = 0.0;
        let mut exact: i128 = 0;
        let mut any = false;
        loop {
            if self.peek(0) == b'_' {
                self.pos += 1;
                continue;
            }
            if !self.peek(0).is_ascii_digit() {
                break;
            }
            let int = self.digits(10);
            let mut frac = String::new();
            if self.peek(0) == b'.' && self.peek(1).is_ascii_digit() {
                self.pos += 1;
                frac = self.digits(10);
            }
            let ustart = self.pos;
            while self.peek(0).is_ascii_alphabetic() {
                self.pos += 1;
            }
            let unit = self.text[ustart..self.pos].to_ascii_lowercase();
            let scale: i128 = match unit.as_str() {
                "d" => 86_400_000_000_000,
                "h" => 3_600_000_000_000,
                "m" => 60_000_000_000,
                "s" => 1_000_000_000,
                "ms" => 1_000_000,
                "us" => 1_000,
                "ns" => 1,
                _ => {
                    self.error(
                        codes::MALFORMED_DURATION,
                        ustart,
                        format!("unknown time unit `{unit}` (use d, h, m, s, ms, us, ns)"),
                    );
                    0
                }
            };
            let whole: i128 = int.parse::<i128>().unwrap_or(i128::MAX / 2);
            exact = exact.saturating_add(whole.saturating_mul(scale));
            if !frac.is_empty() {
                let f: f64 = format!("0.{frac}").parse().unwrap_or(0.0);
                total += f * scale as f64;
            }
            any = true;
        }
        if !any {
            self.error(
                codes::MALFORMED_DURATION,
                start,
                "malformed duration literal (expected e.g. T#1s500ms)",
            );
        }
        let mut ns = exact.saturating_add(total.round() as i128);
        if negative {
            ns = -ns;
        }
        if ns > i64::MAX as i128 || ns < i64::MIN as i128 {
            self.error(
                codes::MALFORMED_DURATION,
                start,
                "duration literal out of range",
            );
            ns = 0;
        }
        if elem == Elem::Time {
            self.push(Tok::Time(ns), start);
        } else {
            self.push(Tok::Temporal(elem, ns), start);
        }
    }

    fn punct(&mut self) {
        let start = self.pos;
        let two = [self.peek(0), self.peek(1)];
        let tok2 = match &two {
            b":=" => Some(Tok::Assign),
            b"=>" => Some(Tok::Arrow),
            b".." => Some(Tok::DotDot),
            b"**" => Some(Tok::Power),
            b"<>" => Some(Tok::Ne),
            b"<=" => Some(Tok::Le),
            b">=" => Some(Tok::Ge),
            _ => None,
        };
        if let Some(t) = tok2 {
            self.pos += 2;
            self.push(t, start);
            return;
        }
        let tok = match two[0] {
            b':' => Tok::Colon,
            b';' => Tok::Semi,
            b',' => Tok::Comma,
            b'.' => Tok::Dot,
            b'(' => Tok::LParen,
            b')' => Tok::RParen,
            b'[' => Tok::LBracket,
            b']' => Tok::RBracket,
            b'+' => Tok::Plus,
            b'-' => Tok::Minus,
            b'*' => Tok::Star,
            b'/' => Tok::Slash,
            b'=' => Tok::Eq,
            b'<' => Tok::Lt,
            b'>' => Tok::Gt,
            b'&' => Tok::Amp,
            b'^' => Tok::Caret,
            _ => {
                let ch = self.text[self.pos..].chars().next().unwrap_or('?');
                self.pos += ch.len_utf8();
                self.error(
                    codes::UNEXPECTED_CHARACTER,
                    start,
                    format!("unexpected character `{ch}`"),
                );
                return;
            }
        };
        self.pos += 1;
        self.push(tok, start);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toks(s: &str) -> Vec<Tok> {
        let mut d = Vec::new();
        let t = lex(0, s, &mut d);
        assert!(d.is_empty(), "{d:?}");
        t.into_iter().map(|t| t.tok).collect()
    }

    #[test]
    fn literals() {
        assert_eq!(toks("16#FF")[0], Tok::Int(255));
        assert_eq!(toks("2#1010_1010")[0], Tok::Int(170));
        assert_eq!(toks("1.5E3")[0], Tok::Real(1500.0));
        assert_eq!(toks("T#1s500ms")[0], Tok::Time(1_500_000_000));
        assert_eq!(toks("t#-1.5s")[0], Tok::Time(-1_500_000_000));
        assert_eq!(toks("'a$'b$N'")[0], Tok::Str("a'b\n".into()));
        assert_eq!(toks("\"a$\"b$20AC'\"")[0], Tok::WStr("a\"b€'".into()));
        assert_eq!(
            toks("INT#5")[0],
            Tok::TypePrefix("INT".into(), "INT".into())
        );
        assert_eq!(toks("x (* c (* n *) *) := 1")[1], Tok::Assign);
        assert_eq!(toks("LT#1ms")[0], Tok::Temporal(Elem::LTime, 1_000_000));
        assert_eq!(
            toks("D#1970-01-02")[0],
            Tok::Temporal(Elem::Date, 86_400_000_000_000)
        );
        assert_eq!(
            toks("time_of_day#00:00:01.5")[0],
            Tok::Temporal(Elem::Tod, 1_500_000_000)
        );
        assert_eq!(
            toks("LDT#1970-01-01-00:01 - x")[0..2],
            [Tok::Temporal(Elem::LDt, 60_000_000_000), Tok::Minus]
        );
    }
}
