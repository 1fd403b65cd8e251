//! Recursive-descent parser (Pratt for expressions) producing the [`ast`](crate::ast).
//!
//! Errors are reported into the diagnostic list and the parser resynchronises at the next
//! statement or declaration boundary, so one run reports several independent errors.

mod expr;
mod stmt;

use crate::ast::*;
use crate::codes;
use crate::diagnostics::{Diagnostic, Span};
use crate::lexer::{Tok, Token};

/// Marker: an error was reported, the caller should recover.
#[derive(Debug)]
struct Fail;
type PResult<T> = Result<T, Fail>;

/// Words that cannot be used as identifiers. The words that only a CONFIGURATION uses
/// (RESOURCE, TASK, WITH, ON) are not among them: CODESYS code names variables `ON` or
/// `TASK`.
const RESERVED: &[&str] = &[
    "PROGRAM",
    "END_PROGRAM",
    "FUNCTION",
    "END_FUNCTION",
    "FUNCTION_BLOCK",
    "END_FUNCTION_BLOCK",
    "VAR",
    "VAR_INPUT",
    "VAR_OUTPUT",
    "VAR_IN_OUT",
    "VAR_GLOBAL",
    "VAR_EXTERNAL",
    "VAR_TEMP",
    "END_VAR",
    "CONSTANT",
    "RETAIN",
    "TYPE",
    "END_TYPE",
    "STRUCT",
    "END_STRUCT",
    "ARRAY",
    "OF",
    "IF",
    "THEN",
    "ELSIF",
    "ELSE",
    "END_IF",
    "CASE",
    "END_CASE",
    "FOR",
    "TO",
    "BY",
    "DO",
    "END_FOR",
    "WHILE",
    "END_WHILE",
    "REPEAT",
    "UNTIL",
    "END_REPEAT",
    "EXIT",
    "RETURN",
    "AND",
    "OR",
    "XOR",
    "NOT",
    "MOD",
    "TRUE",
    "FALSE",
    "CONFIGURATION",
    "END_CONFIGURATION",
    "__TRY",
    "__CATCH",
    "__FINALLY",
    "__ENDTRY",
    "REF_TO",
    "NULL",
    "METHOD",
    "END_METHOD",
    "PROPERTY",
    "END_PROPERTY",
    "END_GET",
    "END_SET",
    "INTERFACE",
    "END_INTERFACE",
    "EXTENDS",
    "IMPLEMENTS",
    "ACTION",
    "END_ACTION",
    "ACTIONS",
    "END_ACTIONS",
    "CLASS",
    "END_CLASS",
    "NAMESPACE",
    "END_NAMESPACE",
    "THIS",
    "SUPER",
];

/// Keywords that end a statement list.
const STMT_END: &[&str] = &[
    "END_IF",
    "ELSIF",
    "ELSE",
    "END_CASE",
    "END_FOR",
    "END_WHILE",
    "UNTIL",
    "END_REPEAT",
    "END_PROGRAM",
    "END_FUNCTION",
    "END_FUNCTION_BLOCK",
    "__CATCH",
    "__FINALLY",
    "__ENDTRY",
    "METHOD",
    "END_METHOD",
    "PROPERTY",
    "END_PROPERTY",
    "END_GET",
    "END_SET",
    "ACTION",
    "END_ACTION",
    "END_ACTIONS",
    "END_CLASS",
    "END_INTERFACE",
    "END_NAMESPACE",
];

/// Keywords that start a top-level declaration (error recovery skips to one of them).
const TOP: &[&str] = &[
    "PROGRAM",
    "FUNCTION",
    "FUNCTION_BLOCK",
    "CLASS",
    "INTERFACE",
    "ACTIONS",
    "ACTION",
    "NAMESPACE",
    "END_NAMESPACE",
    "USING",
    "TYPE",
    "VAR_GLOBAL",
    "CONFIGURATION",
];

pub fn parse(tokens: Vec<Token>, diags: &mut Vec<Diagnostic>) -> Unit {
    // Attribute pragmas are not part of the grammar: they are set aside with the index of
    // the token they stand before, and `var_decl` takes the one before its first name.
    let mut toks = Vec::with_capacity(tokens.len());
    let mut attributes = Vec::new();
    for t in tokens {
        match t.tok {
            Tok::SharedAttribute(value) => attributes.push(PendingAttribute {
                before: toks.len(),
                safe: false,
                value,
                span: t.span,
                taken: false,
            }),
            Tok::SafeAttribute(value) => attributes.push(PendingAttribute {
                before: toks.len(),
                safe: true,
                value,
                span: t.span,
                taken: false,
            }),
            _ => toks.push(t),
        }
    }
    let mut p = Parser {
        toks,
        pos: 0,
        diags,
        in_case: 0,
        depth: 0,
        attributes,
    };
    let unit = p.unit();
    for a in p.attributes.iter().filter(|a| !a.taken) {
        p.diags.push(Diagnostic::error(codes::SAFE_ATTRIBUTE,
            a.span,
            if a.safe {
                "the attribute 'safe' must stand right before the declaration of a located output (`AT %Q...`)"
            } else {
                "the attribute 'shared' must stand right before a variable declaration in VAR_GLOBAL"
            },
        ));
    }
    unit
}

/// An `{attribute 'shared' ...}` or `{attribute 'safe' ...}` pragma waiting for its
/// declaration.
struct PendingAttribute {
    /// `'safe'` (else `'shared'`).
    safe: bool,
    /// Index of the token after it.
    before: usize,
    value: Option<String>,
    span: Span,
    /// A declaration took it (or reported it).
    taken: bool,
}

struct Parser<'a> {
    toks: Vec<Token>,
    pos: usize,
    diags: &'a mut Vec<Diagnostic>,
    /// Depth of CASE bodies: there a `label :` ends the current statement list.
    in_case: u32,
    /// Current nesting of expressions and statements (bounded so that no input can
    /// exhaust the native stack of the compiler).
    depth: u32,
    /// The `{attribute 'shared'}` and `{attribute 'safe'}` pragmas of this file, in order.
    attributes: Vec<PendingAttribute>,
}

/// Maximum nesting of expressions/statements.
const MAX_DEPTH: u32 = 150;

fn describe(t: &Tok) -> String {
    match t {
        Tok::Ident(u, o) if RESERVED.contains(&u.as_str()) => format!("keyword `{o}`"),
        Tok::Ident(_, o) => format!("`{o}`"),
        Tok::Int(v) => format!("number `{v}`"),
        Tok::Real(v) => format!("number `{v}`"),
        Tok::Time(_) => "duration literal".into(),
        Tok::Temporal(e, _) => format!("{e} literal"),
        Tok::Str(_) => "string literal".into(),
        Tok::WStr(_) => "WSTRING literal".into(),
        Tok::TypePrefix(_, o) => format!("`{o}#`"),
        Tok::Direct(text) => format!("`%{text}`"),
        Tok::SharedAttribute(_) => "`{attribute 'shared'}`".into(),
        Tok::SafeAttribute(_) => "`{attribute 'safe'}`".into(),
        Tok::Eof => "end of file".into(),
        other => format!("`{}`", punct_text(other)),
    }
}

fn punct_text(t: &Tok) -> &'static str {
    match t {
        Tok::Assign => ":=",
        Tok::Arrow => "=>",
        Tok::Colon => ":",
        Tok::Semi => ";",
        Tok::Comma => ",",
        Tok::Dot => ".",
        Tok::DotDot => "..",
        Tok::LParen => "(",
        Tok::RParen => ")",
        Tok::LBracket => "[",
        Tok::RBracket => "]",
        Tok::Plus => "+",
        Tok::Minus => "-",
        Tok::Star => "*",
        Tok::Slash => "/",
        Tok::Power => "**",
        Tok::Eq => "=",
        Tok::Ne => "<>",
        Tok::Lt => "<",
        Tok::Le => "<=",
        Tok::Gt => ">",
        Tok::Ge => ">=",
        Tok::Amp => "&",
        Tok::Caret => "^",
        _ => "?",
    }
}

impl Parser<'_> {
    fn tok(&self) -> &Tok {
        &self.toks[self.pos.min(self.toks.len() - 1)].tok
    }

    fn tok_at(&self, ahead: usize) -> &Tok {
        &self.toks[(self.pos + ahead).min(self.toks.len() - 1)].tok
    }

    fn span(&self) -> Span {
        self.toks[self.pos.min(self.toks.len() - 1)].span
    }

    fn prev_span(&self) -> Span {
        self.toks[self.pos.saturating_sub(1).min(self.toks.len() - 1)].span
    }

    fn bump(&mut self) {
        if self.pos < self.toks.len() - 1 {
            self.pos += 1;
        }
    }

    fn at_eof(&self) -> bool {
        matches!(self.tok(), Tok::Eof)
    }

    fn is_kw(&self, kw: &str) -> bool {
        matches!(self.tok(), Tok::Ident(u, _) if u == kw)
    }

    fn eat_kw(&mut self, kw: &str) -> bool {
        if self.is_kw(kw) {
            self.bump();
            true
        } else {
            false
        }
    }

    fn eat(&mut self, t: &Tok) -> bool {
        if self.tok() == t {
            self.bump();
            true
        } else {
            false
        }
    }

    fn error_here(&mut self, expected: &str) -> Fail {
        let msg = format!("expected {expected}, found {}", describe(self.tok()));
        let span = self.span();
        self.diags.push(
            Diagnostic::error(codes::SYNTAX, span, msg).with_label(format!("expected {expected}")),
        );
        Fail
    }

    fn expect_kw(&mut self, kw: &str) -> PResult<()> {
        if self.eat_kw(kw) {
            Ok(())
        } else {
            Err(self.error_here(&format!("`{kw}`")))
        }
    }

    fn expect(&mut self, t: Tok) -> PResult<()> {
        if self.eat(&t) {
            Ok(())
        } else {
            Err(self.error_here(&format!("`{}`", punct_text(&t))))
        }
    }

    fn ident(&mut self) -> PResult<Ident> {
        if let Tok::Ident(u, o) = self.tok().clone()
            && !RESERVED.contains(&u.as_str())
        {
            let span = self.span();
            self.bump();
            return Ok(Ident {
                name: u,
                text: o,
                span,
            });
        }
        Err(self.error_here("an identifier"))
    }

    /// Skips tokens until just after a `;` or before one of `stops` (or EOF).
    fn recover(&mut self, stops: &[&str]) {
        loop {
            match self.tok() {
                Tok::Eof => return,
                Tok::Semi => {
                    self.bump();
                    return;
                }
                Tok::Ident(u, _) if stops.contains(&u.as_str()) => return,
                _ => self.bump(),
            }
        }
    }

    // ----- top level -------------------------------------------------------------------

    fn unit(&mut self) -> Unit {
        let mut unit = Unit::default();
        self.items(&mut unit, None);
        unit
    }

    /// Top-level declarations until the end (or, inside a NAMESPACE, `END_NAMESPACE`).
    fn items(&mut self, unit: &mut Unit, namespace: Option<&str>) {
        while !self.at_eof() {
            if namespace.is_some() && self.is_kw("END_NAMESPACE") {
                return;
            }
            let start = self.pos;
            let ok = if self.is_kw("PROGRAM")
                || self.is_kw("FUNCTION")
                || self.is_kw("FUNCTION_BLOCK")
                || self.is_kw("CLASS")
            {
                self.pou().map(|p| unit.pous.push(p))
            } else if self.is_kw("INTERFACE") {
                self.interface().map(|i| unit.interfaces.push(i))
            } else if self.is_kw("ACTIONS") {
                self.actions_block(unit)
            } else if self.is_kw("ACTION") {
                self.qualified_action(unit)
            } else if self.is_kw("TYPE") {
                self.type_block(&mut unit.types)
            } else if self.is_kw("VAR_GLOBAL") {
                self.var_block().map(|b| unit.globals.push(b))
            } else if self.is_kw("CONFIGURATION") {
                self.configuration(unit)
            } else if self.is_kw("NAMESPACE") {
                self.namespace(unit)
            } else if self.is_kw("USING") {
                // Names are found with or without their namespace (see `sema`), so USING
                // needs no bookkeeping.
                self.bump();
                self.qualified_ident().and_then(|_| {
                    while self.eat(&Tok::Comma) {
                        self.qualified_ident()?;
                    }
                    self.expect(Tok::Semi)
                })
            } else {
                Err(self.error_here(
                    "PROGRAM, FUNCTION, FUNCTION_BLOCK, INTERFACE, TYPE, VAR_GLOBAL or CONFIGURATION",
                ))
            };
            if ok.is_err() {
                // Skip to the next top-level keyword.
                if self.pos == start {
                    self.bump();
                }
                while !self.at_eof() && !TOP.iter().any(|k| self.is_kw(k)) {
                    self.bump();
                }
            }
        }
    }

    /// `NAMESPACE N ... END_NAMESPACE`: the POUs, types and interfaces declared inside are
    /// named `N.name`.
    fn namespace(&mut self, unit: &mut Unit) -> PResult<()> {
        self.expect_kw("NAMESPACE")?;
        let name = self.qualified_ident()?;
        let mut inner = Unit::default();
        self.items(&mut inner, Some(&name.name));
        self.expect_kw("END_NAMESPACE")?;
        self.eat(&Tok::Semi);
        let qualify = |id: &mut Ident| {
            id.name = format!("{}.{}", name.name, id.name);
            id.text = format!("{}.{}", name.text, id.text);
        };
        for mut p in inner.pous {
            qualify(&mut p.name);
            unit.pous.push(p);
        }
        for mut t in inner.types {
            qualify(&mut t.name);
            unit.types.push(t);
        }
        for mut i in inner.interfaces {
            qualify(&mut i.name);
            unit.interfaces.push(i);
        }
        for (mut p, a) in inner.actions {
            qualify(&mut p);
            unit.actions.push((p, a));
        }
        unit.globals.extend(inner.globals);
        unit.configs.extend(inner.configs);
        Ok(())
    }

    fn pou(&mut self) -> PResult<Pou> {
        let start = self.span();
        let (kind, end_kw, is_class) = if self.eat_kw("PROGRAM") {
            (PouKind::Program, "END_PROGRAM", false)
        } else if self.eat_kw("FUNCTION_BLOCK") {
            (PouKind::FunctionBlock, "END_FUNCTION_BLOCK", false)
        } else if self.eat_kw("CLASS") {
            (PouKind::FunctionBlock, "END_CLASS", true)
        } else {
            self.expect_kw("FUNCTION")?;
            (PouKind::Function, "END_FUNCTION", false)
        };
        let modifiers = self.modifiers();
        let name = self.ident()?;
        let mut extends = None;
        let mut implements = Vec::new();
        loop {
            if self.is_kw("EXTENDS") {
                let at = self.span();
                self.bump();
                let base = self.qualified_ident()?;
                if kind != PouKind::FunctionBlock {
                    self.diags.push(Diagnostic::error(
                        codes::MISPLACED_POU_ELEMENT,
                        at,
                        "only a FUNCTION_BLOCK can extend another one",
                    ));
                } else if extends.is_some() {
                    self.diags.push(Diagnostic::error(
                        codes::MISPLACED_POU_ELEMENT,
                        at,
                        "a function block extends at most one function block",
                    ));
                }
                extends = Some(base);
            } else if self.is_kw("IMPLEMENTS") {
                let at = self.span();
                self.bump();
                if kind != PouKind::FunctionBlock {
                    self.diags.push(Diagnostic::error(
                        codes::MISPLACED_POU_ELEMENT,
                        at,
                        "only a FUNCTION_BLOCK can implement interfaces",
                    ));
                }
                loop {
                    implements.push(self.qualified_ident()?);
                    if !self.eat(&Tok::Comma) {
                        break;
                    }
                }
            } else {
                break;
            }
        }
        let mut return_type = None;
        if kind == PouKind::Function {
            if self.eat(&Tok::Colon) {
                return_type = Some(self.type_ref()?);
            } else {
                return Err(self.error_here("`:` and the function's return type"));
            }
        }
        let var_blocks = self.var_blocks(end_kw);
        // The body and the methods, properties and actions, in any order.
        let mut body = Vec::new();
        let mut methods = Vec::new();
        let mut properties = Vec::new();
        let mut actions = Vec::new();
        loop {
            let before = self.pos;
            if self.is_kw("METHOD") {
                match self.method(false) {
                    Ok(m) => methods.push(m),
                    Err(Fail) => self.skip_past("END_METHOD", end_kw),
                }
            } else if self.is_kw("PROPERTY") {
                match self.property(false) {
                    Ok(p) => properties.push(p),
                    Err(Fail) => self.skip_past("END_PROPERTY", end_kw),
                }
            } else if self.is_kw("ACTION") {
                match self.action() {
                    Ok(a) => actions.push(a),
                    Err(Fail) => self.skip_past("END_ACTION", end_kw),
                }
            } else if self.is_kw(end_kw) || self.at_eof() {
                break;
            } else {
                body.extend(self.stmt_list());
            }
            if self.pos == before {
                break;
            }
        }
        if is_class && !body.is_empty() {
            self.diags.push(Diagnostic::error(
                codes::MISPLACED_POU_ELEMENT,
                body[0].span,
                "a CLASS has no body: write its code in methods",
            ));
        }
        if kind != PouKind::FunctionBlock && kind != PouKind::Program {
            if let Some(m) = methods.first() {
                self.diags.push(Diagnostic::error(
                    codes::MISPLACED_POU_ELEMENT,
                    m.name.span,
                    "methods belong to a FUNCTION_BLOCK or a PROGRAM",
                ));
            }
            if let Some(a) = actions.first() {
                self.diags.push(Diagnostic::error(
                    codes::MISPLACED_POU_ELEMENT,
                    a.name.span,
                    "actions belong to a FUNCTION_BLOCK or a PROGRAM",
                ));
            }
        }
        if !self.eat_kw(end_kw) {
            let f = self.error_here(&format!("`{end_kw}`"));
            // Leave the offending token for the top-level loop only if it starts a new unit.
            if !TOP.iter().any(|k| self.is_kw(k)) {
                self.bump();
            }
            let _ = f;
        }
        self.eat(&Tok::Semi);
        Ok(Pou {
            kind,
            name,
            return_type,
            var_blocks,
            body,
            span: start.to(self.prev_span()),
            modifiers,
            extends,
            implements,
            methods,
            properties,
            actions,
            is_class,
        })
    }

    /// `ABSTRACT`, `FINAL`, `OVERRIDE` and an access specifier, in any order.
    fn modifiers(&mut self) -> Modifiers {
        let mut m = Modifiers::default();
        loop {
            if self.eat_kw("ABSTRACT") {
                m.is_abstract = true;
            } else if self.eat_kw("FINAL") {
                m.is_final = true;
            } else if self.eat_kw("OVERRIDE") {
                m.is_override = true;
            } else if self.eat_kw("PUBLIC") {
                m.access = Access::Public;
            } else if self.eat_kw("PRIVATE") {
                m.access = Access::Private;
            } else if self.eat_kw("PROTECTED") {
                m.access = Access::Protected;
            } else if self.eat_kw("INTERNAL") {
                m.access = Access::Internal;
            } else {
                return m;
            }
        }
    }

    /// An identifier, possibly qualified by namespaces (`Lib.Name`), as one name.
    fn qualified_ident(&mut self) -> PResult<Ident> {
        let mut id = self.ident()?;
        while matches!(self.tok(), Tok::Dot) && matches!(self.tok_at(1), Tok::Ident(..)) {
            self.bump();
            let next = self.ident()?;
            id.name = format!("{}.{}", id.name, next.name);
            id.text = format!("{}.{}", id.text, next.text);
            id.span = id.span.to(next.span);
        }
        Ok(id)
    }

    /// Variable blocks until something else (errors recover to END_VAR or `end_kw`).
    fn var_blocks(&mut self, end_kw: &str) -> Vec<VarBlock> {
        let mut var_blocks = Vec::new();
        while self.is_var_block_start() {
            match self.var_block() {
                Ok(b) => var_blocks.push(b),
                Err(Fail) => {
                    while !self.at_eof() && !self.is_kw("END_VAR") && !self.is_kw(end_kw) {
                        self.bump();
                    }
                    self.eat_kw("END_VAR");
                }
            }
        }
        var_blocks
    }

    /// Error recovery inside a POU: skips to after `end` (or stops before `outer`).
    fn skip_past(&mut self, end: &str, outer: &str) {
        while !self.at_eof() && !self.is_kw(end) && !self.is_kw(outer) {
            self.bump();
        }
        if self.eat_kw(end) {
            self.eat(&Tok::Semi);
        }
    }

    /// `METHOD [modifiers] name [: type] var-blocks [body] END_METHOD` (no body in an
    /// INTERFACE).
    fn method(&mut self, declaration_only: bool) -> PResult<Method> {
        let start = self.span();
        self.expect_kw("METHOD")?;
        let modifiers = self.modifiers();
        let name = self.ident()?;
        let return_type = if self.eat(&Tok::Colon) {
            Some(self.type_ref()?)
        } else {
            None
        };
        self.eat(&Tok::Semi);
        let var_blocks = self.var_blocks("END_METHOD");
        let body = self.stmt_list();
        if declaration_only && let Some(first) = body.first() {
            self.diags.push(Diagnostic::error(
                codes::INTERFACE_CONTENT,
                first.span,
                "an interface method has no implementation",
            ));
        }
        self.expect_kw("END_METHOD")?;
        self.eat(&Tok::Semi);
        Ok(Method {
            name,
            modifiers,
            return_type,
            var_blocks,
            body,
            span: start.to(self.prev_span()),
        })
    }

    /// `PROPERTY [modifiers] name : type [GET ... END_GET] [SET ... END_SET] END_PROPERTY`.
    fn property(&mut self, declaration_only: bool) -> PResult<Property> {
        let start = self.span();
        self.expect_kw("PROPERTY")?;
        let modifiers = self.modifiers();
        let name = self.ident()?;
        self.expect(Tok::Colon)?;
        let ty = self.type_ref()?;
        self.eat(&Tok::Semi);
        let mut get = None;
        let mut set = None;
        loop {
            let which = if self.is_kw("GET") {
                "END_GET"
            } else if self.is_kw("SET") {
                "END_SET"
            } else {
                break;
            };
            let at = self.span();
            self.bump();
            self.eat(&Tok::Semi);
            let var_blocks = self.var_blocks("END_PROPERTY");
            let body = self.stmt_list();
            if declaration_only && let Some(first) = body.first() {
                self.diags.push(Diagnostic::error(
                    codes::INTERFACE_CONTENT,
                    first.span,
                    "an interface property has no implementation",
                ));
            }
            self.expect_kw(which)?;
            self.eat(&Tok::Semi);
            let accessor = Accessor {
                var_blocks,
                body,
                span: at.to(self.prev_span()),
            };
            if which == "END_GET" {
                get = Some(accessor);
            } else {
                set = Some(accessor);
            }
        }
        self.expect_kw("END_PROPERTY")?;
        self.eat(&Tok::Semi);
        if get.is_none() && set.is_none() {
            if !declaration_only {
                return Err({
                    let span = start;
                    self.diags.push(Diagnostic::error(
                        codes::PROPERTY_WITHOUT_ACCESSOR,
                        span,
                        "a property needs a GET or a SET accessor",
                    ));
                    Fail
                });
            }
            // An interface property declared without accessors has both.
            let empty = || Accessor {
                var_blocks: Vec::new(),
                body: Vec::new(),
                span: start,
            };
            get = Some(empty());
            set = Some(empty());
        }
        Ok(Property {
            name,
            modifiers,
            ty,
            get,
            set,
            span: start.to(self.prev_span()),
        })
    }

    /// `ACTION name [:] statements END_ACTION`.
    fn action(&mut self) -> PResult<Action> {
        let start = self.span();
        self.expect_kw("ACTION")?;
        let name = self.ident()?;
        self.eat(&Tok::Colon);
        let body = self.stmt_list();
        self.expect_kw("END_ACTION")?;
        self.eat(&Tok::Semi);
        Ok(Action {
            name,
            body,
            span: start.to(self.prev_span()),
        })
    }

    /// `ACTIONS pou ACTION a ... END_ACTION ... END_ACTIONS` (the form RuSTy writes).
    fn actions_block(&mut self, unit: &mut Unit) -> PResult<()> {
        self.expect_kw("ACTIONS")?;
        let pou = self.qualified_ident()?;
        while self.is_kw("ACTION") {
            let a = self.action()?;
            unit.actions.push((pou.clone(), a));
        }
        self.expect_kw("END_ACTIONS")?;
        self.eat(&Tok::Semi);
        Ok(())
    }

    /// `ACTION pou.a [:] statements END_ACTION` outside its POU.
    fn qualified_action(&mut self, unit: &mut Unit) -> PResult<()> {
        let start = self.span();
        self.expect_kw("ACTION")?;
        let full = self.qualified_ident()?;
        let Some((pou, name)) = full.name.rsplit_once('.') else {
            self.diags.push(Diagnostic::error(
                codes::MISPLACED_POU_ELEMENT,
                full.span,
                "an ACTION outside its POU is written `ACTION Pou.Action`",
            ));
            return Err(Fail);
        };
        let (pou_text, name_text) = full.text.rsplit_once('.').unwrap_or((&full.text, ""));
        let pou = Ident {
            name: pou.to_string(),
            text: pou_text.to_string(),
            span: full.span,
        };
        let name = Ident {
            name: name.to_string(),
            text: name_text.to_string(),
            span: full.span,
        };
        self.eat(&Tok::Colon);
        let body = self.stmt_list();
        self.expect_kw("END_ACTION")?;
        self.eat(&Tok::Semi);
        unit.actions.push((
            pou,
            Action {
                name,
                body,
                span: start.to(self.prev_span()),
            },
        ));
        Ok(())
    }

    /// `INTERFACE name [EXTENDS i, ...] methods and properties END_INTERFACE`.
    fn interface(&mut self) -> PResult<Interface> {
        let start = self.span();
        self.expect_kw("INTERFACE")?;
        let name = self.ident()?;
        let mut extends = Vec::new();
        if self.eat_kw("EXTENDS") {
            loop {
                extends.push(self.qualified_ident()?);
                if !self.eat(&Tok::Comma) {
                    break;
                }
            }
        }
        let mut methods = Vec::new();
        let mut properties = Vec::new();
        loop {
            if self.is_kw("METHOD") {
                match self.method(true) {
                    Ok(m) => methods.push(m),
                    Err(Fail) => self.skip_past("END_METHOD", "END_INTERFACE"),
                }
            } else if self.is_kw("PROPERTY") {
                match self.property(true) {
                    Ok(p) => properties.push(p),
                    Err(Fail) => self.skip_past("END_PROPERTY", "END_INTERFACE"),
                }
            } else if self.is_var_block_start() {
                // CODESYS writes an empty `VAR END_VAR` into interfaces.
                let blocks = self.var_blocks("END_INTERFACE");
                if let Some(d) = blocks.iter().flat_map(|b| &b.decls).next() {
                    self.diags.push(Diagnostic::error(
                        codes::INTERFACE_CONTENT,
                        d.span,
                        "an interface declares methods and properties, not variables",
                    ));
                }
            } else {
                break;
            }
        }
        self.expect_kw("END_INTERFACE")?;
        self.eat(&Tok::Semi);
        Ok(Interface {
            name,
            extends,
            methods,
            properties,
            span: start.to(self.prev_span()),
        })
    }

    fn is_var_block_start(&self) -> bool {
        [
            "VAR",
            "VAR_INPUT",
            "VAR_OUTPUT",
            "VAR_IN_OUT",
            "VAR_GLOBAL",
            "VAR_EXTERNAL",
            "VAR_TEMP",
        ]
        .iter()
        .any(|k| self.is_kw(k))
    }

    fn var_block(&mut self) -> PResult<VarBlock> {
        let start = self.span();
        let kind = match self.tok() {
            Tok::Ident(u, _) => match u.as_str() {
                "VAR" => VarKind::Local,
                "VAR_INPUT" => VarKind::Input,
                "VAR_OUTPUT" => VarKind::Output,
                "VAR_IN_OUT" => VarKind::InOut,
                "VAR_GLOBAL" => VarKind::Global,
                "VAR_EXTERNAL" => VarKind::External,
                "VAR_TEMP" => VarKind::Temp,
                _ => return Err(self.error_here("a VAR block")),
            },
            _ => return Err(self.error_here("a VAR block")),
        };
        self.bump();
        let mut constant = false;
        let mut retain = false;
        loop {
            if self.eat_kw("CONSTANT") {
                constant = true;
            } else if self.eat_kw("RETAIN") {
                retain = true;
            } else if self.eat_kw("NON_RETAIN") {
            } else {
                break;
            }
        }
        let mut decls = Vec::new();
        while !self.is_kw("END_VAR") && !self.at_eof() {
            if self.is_var_block_start()
                || self.is_kw("END_PROGRAM")
                || self.is_kw("END_FUNCTION_BLOCK")
                || self.is_kw("END_FUNCTION")
            {
                return Err(self.error_here("`END_VAR`"));
            }
            let before = self.pos;
            match self.var_decl() {
                Ok(d) => decls.push(d),
                Err(Fail) => self.recover(&["END_VAR"]),
            }
            if self.pos == before {
                self.bump();
            }
        }
        self.expect_kw("END_VAR")?;
        Ok(VarBlock {
            kind,
            constant,
            retain,
            decls,
            span: start.to(self.prev_span()),
        })
    }

    /// The direction of the `{attribute 'shared'}` pragma right before the current token,
    /// if there is one (a pragma with a bad value is reported here and ignored).
    fn shared_attribute(&mut self) -> Option<SharedAttr> {
        let pos = self.pos;
        let a = self
            .attributes
            .iter_mut()
            .rev()
            .find(|a| a.before == pos && !a.taken && !a.safe)?;
        a.taken = true;
        let span = a.span;
        let value = a.value.clone();
        let direction = value
            .as_deref()
            .and_then(|v| plc_vm::image::SharedDirection::from_name(&v.to_ascii_lowercase()));
        if direction.is_none() {
            let what = match &value {
                Some(v) => format!("unknown value '{v}' of the attribute 'shared'"),
                None => "the attribute 'shared' needs a value".into(),
            };
            self.diags.push(Diagnostic::error(codes::SHARED_ATTRIBUTE,
                span,
                format!("{what}: write `{{attribute 'shared' := 'write'}}` (this project writes it), `{{attribute 'shared' := 'read'}}` (it reads it from the other project) or `{{attribute 'shared' := 'valid'}}` (a BOOL: the read ones are a fresh copy)"),
            ));
        }
        // Several pragmas before one declaration: the others are reported as misplaced.
        Some(SharedAttr {
            direction: direction?,
            span,
        })
    }

    /// The value of the `{attribute 'safe' := 'VALUE'}` pragma right before the current
    /// token, if there is one (checked against the declaration by sema).
    fn safe_attribute(&mut self) -> Option<(String, Span)> {
        let pos = self.pos;
        let a = self
            .attributes
            .iter_mut()
            .rev()
            .find(|a| a.before == pos && !a.taken && a.safe)?;
        a.taken = true;
        let span = a.span;
        match a.value.clone() {
            Some(v) => Some((v, span)),
            None => {
                self.diags.push(Diagnostic::error(
                    codes::SAFE_ATTRIBUTE,
                    span,
                    "the attribute 'safe' needs the value: `{attribute 'safe' := '0.0'}`",
                ));
                None
            }
        }
    }

    fn var_decl(&mut self) -> PResult<VarDecl> {
        let shared = self.shared_attribute();
        let safe = self.safe_attribute();
        let start = self.span();
        let mut names = vec![self.ident()?];
        while self.eat(&Tok::Comma) {
            names.push(self.ident()?);
        }
        let at = if self.eat_kw("AT") {
            match self.tok().clone() {
                Tok::Direct(text) => {
                    let span = self.span();
                    self.bump();
                    Some((text, span))
                }
                _ => return Err(self.error_here("a direct address such as `%IX0.0` or `%QW2`")),
            }
        } else {
            None
        };
        self.expect(Tok::Colon)?;
        let ty = self.type_ref()?;
        let init = if self.eat(&Tok::Assign) {
            Some(self.init()?)
        } else {
            None
        };
        self.expect(Tok::Semi)?;
        Ok(VarDecl {
            names,
            at,
            ty,
            init,
            span: start.to(self.prev_span()),
            shared,
            safe,
        })
    }

    fn type_block(&mut self, out: &mut Vec<TypeDecl>) -> PResult<()> {
        self.expect_kw("TYPE")?;
        while !self.is_kw("END_TYPE") && !self.at_eof() {
            let r = (|| -> PResult<TypeDecl> {
                let name = self.ident()?;
                self.expect(Tok::Colon)?;
                let ty = self.type_ref()?;
                let init = if self.eat(&Tok::Assign) {
                    Some(self.init()?)
                } else {
                    None
                };
                // CODESYS leaves out the `;` after END_STRUCT.
                if !self.eat(&Tok::Semi) && !matches!(ty, TypeRef::Struct { .. }) {
                    self.expect(Tok::Semi)?;
                }
                Ok(TypeDecl { name, ty, init })
            })();
            match r {
                Ok(d) => out.push(d),
                Err(Fail) => {
                    // A broken STRUCT must be skipped as a whole.
                    let mut depth = 0;
                    while !self.at_eof() && !self.is_kw("END_TYPE") {
                        if self.is_kw("STRUCT") {
                            depth += 1;
                        } else if self.is_kw("END_STRUCT") {
                            depth -= 1;
                        } else if depth <= 0 && matches!(self.tok(), Tok::Semi) {
                            self.bump();
                            break;
                        }
                        self.bump();
                    }
                }
            }
        }
        self.expect_kw("END_TYPE")?;
        // CODESYS accepts (and some libraries write) `END_TYPE;`.
        self.eat(&Tok::Semi);
        Ok(())
    }

    fn type_ref(&mut self) -> PResult<TypeRef> {
        self.guarded("types", |p| p.type_ref_inner())
    }

    /// Runs `f` one nesting level deeper, failing with "`what` nested too deeply" once
    /// [`MAX_DEPTH`] is exceeded.
    fn guarded<T>(&mut self, what: &str, f: impl FnOnce(&mut Self) -> PResult<T>) -> PResult<T> {
        self.depth += 1;
        let r = if self.depth > MAX_DEPTH {
            let span = self.span();
            self.diags.push(Diagnostic::error(
                codes::NESTED_TOO_DEEPLY,
                span,
                format!("{what} nested too deeply"),
            ));
            Err(Fail)
        } else {
            f(self)
        };
        self.depth -= 1;
        r
    }

    fn type_ref_inner(&mut self) -> PResult<TypeRef> {
        let start = self.span();
        // REF_TO T, POINTER TO T, REFERENCE TO T (the last two are CODESYS; POINTER and
        // REFERENCE are keywords only before TO).
        let ref_kind = if self.is_kw("REF_TO") {
            Some(RefKind::RefTo)
        } else if self.is_kw("POINTER") && matches!(self.tok_at(1), Tok::Ident(u, _) if u == "TO") {
            Some(RefKind::Pointer)
        } else if self.is_kw("REFERENCE") && matches!(self.tok_at(1), Tok::Ident(u, _) if u == "TO")
        {
            Some(RefKind::Reference)
        } else {
            None
        };
        if let Some(kind) = ref_kind {
            self.bump();
            if kind != RefKind::RefTo {
                self.bump();
            }
            let target = self.type_ref()?;
            return Ok(TypeRef::Ref {
                kind,
                target: Box::new(target),
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_kw("ARRAY") {
            self.expect(Tok::LBracket)?;
            let mut dims = Vec::new();
            loop {
                let lo = self.expr()?;
                self.expect(Tok::DotDot)?;
                let hi = self.expr()?;
                dims.push((lo, hi));
                if !self.eat(&Tok::Comma) {
                    break;
                }
            }
            self.expect(Tok::RBracket)?;
            self.expect_kw("OF")?;
            let elem = self.type_ref()?;
            return Ok(TypeRef::Array {
                dims,
                elem: Box::new(elem),
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_kw("STRUCT") {
            let mut members = Vec::new();
            while !self.is_kw("END_STRUCT") && !self.at_eof() {
                if self.is_kw("END_TYPE") {
                    break;
                }
                let before = self.pos;
                match self.var_decl() {
                    Ok(d) => members.push(d),
                    Err(Fail) => self.recover(&["END_STRUCT", "END_TYPE"]),
                }
                if self.pos == before {
                    self.bump();
                }
            }
            self.expect_kw("END_STRUCT")?;
            return Ok(TypeRef::Struct {
                members,
                span: start.to(self.prev_span()),
            });
        }
        if self.eat(&Tok::LParen) {
            let mut values = Vec::new();
            loop {
                let id = self.ident()?;
                let v = if self.eat(&Tok::Assign) {
                    Some(self.expr()?)
                } else {
                    None
                };
                values.push((id, v));
                if !self.eat(&Tok::Comma) {
                    break;
                }
            }
            self.expect(Tok::RParen)?;
            return Ok(TypeRef::Enum {
                values,
                span: start.to(self.prev_span()),
            });
        }
        if self.is_kw("STRING") || self.is_kw("WSTRING") {
            let wide = self.is_kw("WSTRING");
            self.bump();
            let len = if self.eat(&Tok::LBracket) {
                let e = self.expr()?;
                self.expect(Tok::RBracket)?;
                Some(Box::new(e))
            } else if self.eat(&Tok::LParen) {
                let e = self.expr()?;
                self.expect(Tok::RParen)?;
                Some(Box::new(e))
            } else {
                None
            };
            return Ok(TypeRef::String(len, start.to(self.prev_span()), wide));
        }
        let base = self.qualified_ident()?;
        if self.eat(&Tok::LParen) {
            let lo = self.expr()?;
            self.expect(Tok::DotDot)?;
            let hi = self.expr()?;
            self.expect(Tok::RParen)?;
            return Ok(TypeRef::Subrange {
                base,
                lo: Box::new(lo),
                hi: Box::new(hi),
                span: start.to(self.prev_span()),
            });
        }
        Ok(TypeRef::Named(base))
    }

    fn init(&mut self) -> PResult<Init> {
        self.guarded("initialisers", |p| p.init_inner())
    }

    fn init_inner(&mut self) -> PResult<Init> {
        let start = self.span();
        if self.eat(&Tok::LBracket) {
            let mut items = Vec::new();
            if !matches!(self.tok(), Tok::RBracket) {
                loop {
                    // `n(value)` repeats value n times; `n()` repeats the default.
                    if let (Tok::Int(n), Tok::LParen) = (self.tok().clone(), self.tok_at(1).clone())
                    {
                        self.bump();
                        self.bump();
                        let value = if matches!(self.tok(), Tok::RParen) {
                            None
                        } else {
                            Some(self.init()?)
                        };
                        self.expect(Tok::RParen)?;
                        items.push(ArrayInitItem {
                            repeat: n.min(1 << 24) as u64,
                            value,
                        });
                    } else {
                        items.push(ArrayInitItem {
                            repeat: 1,
                            value: Some(self.init()?),
                        });
                    }
                    if !self.eat(&Tok::Comma) {
                        break;
                    }
                }
            }
            self.expect(Tok::RBracket)?;
            return Ok(Init::Array(items, start.to(self.prev_span())));
        }
        if matches!(self.tok(), Tok::LParen)
            && matches!(self.tok_at(1), Tok::Ident(..))
            && matches!(self.tok_at(2), Tok::Assign)
        {
            self.bump();
            let mut fields = Vec::new();
            loop {
                let name = self.ident()?;
                self.expect(Tok::Assign)?;
                let v = self.init()?;
                fields.push((name, v));
                if !self.eat(&Tok::Comma) {
                    break;
                }
            }
            self.expect(Tok::RParen)?;
            return Ok(Init::Struct(fields, start.to(self.prev_span())));
        }
        Ok(Init::Expr(self.expr()?))
    }

    fn configuration(&mut self, unit: &mut Unit) -> PResult<()> {
        self.expect_kw("CONFIGURATION")?;
        let name = self.ident()?;
        let mut config = Configuration {
            name,
            resources: Vec::new(),
        };
        // Tasks and programs declared directly in the configuration form an implicit resource.
        let mut implicit = Resource {
            name: config.name.clone(),
            tasks: Vec::new(),
            programs: Vec::new(),
        };
        while !self.is_kw("END_CONFIGURATION") && !self.at_eof() {
            if self.is_kw("VAR_GLOBAL") {
                let b = self.var_block()?;
                unit.globals.push(b);
            } else if self.eat_kw("RESOURCE") {
                let rname = self.ident()?;
                if self.eat_kw("ON") {
                    self.ident()?;
                }
                let mut res = Resource {
                    name: rname,
                    tasks: Vec::new(),
                    programs: Vec::new(),
                };
                while !self.is_kw("END_RESOURCE")
                    && !self.at_eof()
                    && !self.is_kw("END_CONFIGURATION")
                {
                    let before = self.pos;
                    if self.is_kw("VAR_GLOBAL") {
                        let b = self.var_block()?;
                        unit.globals.push(b);
                    } else if self.resource_item(&mut res).is_err() {
                        self.recover(&["END_RESOURCE", "TASK", "PROGRAM"]);
                    }
                    if self.pos == before {
                        self.bump();
                    }
                }
                self.expect_kw("END_RESOURCE")?;
                config.resources.push(res);
            } else {
                let before = self.pos;
                if self.resource_item(&mut implicit).is_err() {
                    self.recover(&["END_CONFIGURATION", "TASK", "PROGRAM", "RESOURCE"]);
                }
                if self.pos == before {
                    self.bump();
                }
            }
        }
        self.expect_kw("END_CONFIGURATION")?;
        if !implicit.tasks.is_empty() || !implicit.programs.is_empty() {
            config.resources.push(implicit);
        }
        unit.configs.push(config);
        Ok(())
    }

    fn resource_item(&mut self, res: &mut Resource) -> PResult<()> {
        if self.eat_kw("TASK") {
            let name = self.ident()?;
            let mut task = TaskDecl {
                name,
                interval: None,
                single: None,
                priority: None,
            };
            self.expect(Tok::LParen)?;
            loop {
                let key = self.ident()?;
                self.expect(Tok::Assign)?;
                let v = self.expr()?;
                match key.name.as_str() {
                    "INTERVAL" => task.interval = Some(v),
                    "SINGLE" => task.single = Some(v),
                    "PRIORITY" => task.priority = Some(v),
                    _ => {
                        self.diags.push(Diagnostic::error(codes::UNKNOWN_TASK_PROPERTY,
                            key.span,
                            format!("unknown task property `{}` (expected INTERVAL, SINGLE or PRIORITY)", key.text),
                        ));
                    }
                }
                if !self.eat(&Tok::Comma) {
                    break;
                }
            }
            self.expect(Tok::RParen)?;
            self.expect(Tok::Semi)?;
            res.tasks.push(task);
            Ok(())
        } else if self.eat_kw("PROGRAM") {
            let instance = self.ident()?;
            let task = if self.eat_kw("WITH") {
                Some(self.ident()?)
            } else {
                None
            };
            self.expect(Tok::Colon)?;
            let program_type = self.qualified_ident()?;
            if self.eat(&Tok::LParen) {
                // Parameter connections to globals are not supported; skip them.
                while !matches!(self.tok(), Tok::RParen | Tok::Eof | Tok::Semi) {
                    self.bump();
                }
                self.expect(Tok::RParen)?;
            }
            self.expect(Tok::Semi)?;
            res.programs.push(ProgramBinding {
                instance,
                task,
                program_type,
            });
            Ok(())
        } else {
            Err(self.error_here("TASK, PROGRAM, RESOURCE or END_CONFIGURATION"))
        }
    }
}

#[cfg(test)]
mod tests;
