//! Library check: compiles a library of POUs (e.g. OSCAT BASIC) as one project and one POU at
//! a time, and says for each POU that fails why, in one line a user understands.
//!
//! A library source is split into its top-level declarations ([`split`]): FUNCTIONs,
//! FUNCTION_BLOCKs, PROGRAMs, TYPE blocks, VAR_GLOBAL blocks (and the object declarations
//! INTERFACE, CLASS, NAMESPACE). One POU is compiled with the declarations it depends on,
//! found by name (every identifier of its text that another declaration declares, closed
//! transitively), in their order in the library; it *compiles* when that compilation has no
//! diagnostic. This is the measure peers use for "N % of the library compiles".
//!
//! The check never changes the library text; `cargo xtask oscat` prints the report and
//! writes it into the compiler's STATUS.md.

use std::collections::{BTreeSet, HashMap};

use crate::diagnostics::Diagnostic;
use crate::lexer::{Tok, Token, lex};
use crate::{Options, compile};

/// What a top-level declaration is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeclKind {
    Function,
    FunctionBlock,
    Program,
    Type,
    Globals,
    /// INTERFACE, CLASS, NAMESPACE, CONFIGURATION: compiled along, not counted.
    Other,
}

impl DeclKind {
    /// FUNCTION, FUNCTION_BLOCK and PROGRAM are the POUs the check counts.
    pub fn is_pou(self) -> bool {
        matches!(
            self,
            DeclKind::Function | DeclKind::FunctionBlock | DeclKind::Program
        )
    }

    pub fn keyword(self) -> &'static str {
        match self {
            DeclKind::Function => "FUNCTION",
            DeclKind::FunctionBlock => "FUNCTION_BLOCK",
            DeclKind::Program => "PROGRAM",
            DeclKind::Type => "TYPE",
            DeclKind::Globals => "VAR_GLOBAL",
            DeclKind::Other => "declaration",
        }
    }
}

/// One top-level declaration of a library text.
#[derive(Debug, Clone)]
pub struct Decl {
    pub kind: DeclKind,
    /// Its name as written (the first declared name of a TYPE or VAR_GLOBAL block).
    pub name: String,
    /// Upper-cased names it declares (POU name; type names and enumeration values of a TYPE
    /// block; variable names of a VAR_GLOBAL block).
    pub declares: Vec<String>,
    /// Upper-cased identifiers it uses (its own declared names excluded).
    pub uses: BTreeSet<String>,
    /// Byte range in the library text.
    pub start: usize,
    pub end: usize,
    /// 1-based line of its first token.
    pub line: usize,
}

/// Keywords that start a top-level declaration, with the keyword that ends it.
const STARTS: &[(&str, &str, DeclKind)] = &[
    ("FUNCTION", "END_FUNCTION", DeclKind::Function),
    (
        "FUNCTION_BLOCK",
        "END_FUNCTION_BLOCK",
        DeclKind::FunctionBlock,
    ),
    ("PROGRAM", "END_PROGRAM", DeclKind::Program),
    ("TYPE", "END_TYPE", DeclKind::Type),
    ("VAR_GLOBAL", "END_VAR", DeclKind::Globals),
    ("INTERFACE", "END_INTERFACE", DeclKind::Other),
    ("CLASS", "END_CLASS", DeclKind::Other),
    ("NAMESPACE", "END_NAMESPACE", DeclKind::Other),
    ("CONFIGURATION", "END_CONFIGURATION", DeclKind::Other),
];

fn word(t: &Tok) -> Option<&str> {
    match t {
        Tok::Ident(u, _) => Some(u.as_str()),
        _ => None,
    }
}

/// Splits a library text into its top-level declarations (text outside them is ignored).
/// Works on tokens only, so a declaration the parser rejects is still delimited.
pub fn split(text: &str) -> Vec<Decl> {
    let mut ignored = Vec::new();
    let toks = lex(0, text, &mut ignored);
    let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
    let mut out = Vec::new();
    let mut i = 0;
    while i < toks.len() {
        let Some(&(start_kw, end_kw, kind)) =
            word(&toks[i].tok).and_then(|w| STARTS.iter().find(|(s, _, _)| *s == w))
        else {
            i += 1;
            continue;
        };
        // The declaration ends at its END keyword (plus a `;` after it), or, when that is
        // missing, before the next top-level start keyword.
        let first = i;
        let mut j = i + 1;
        let mut last = None;
        // NAMESPACEs nest.
        let mut depth = 0;
        while j < toks.len() && !matches!(toks[j].tok, Tok::Eof) {
            match word(&toks[j].tok) {
                Some(w) if w == start_kw && start_kw == "NAMESPACE" => depth += 1,
                Some(w) if w == end_kw => {
                    if depth == 0 {
                        last = Some(j);
                        break;
                    }
                    depth -= 1;
                }
                Some(w)
                    if kind != DeclKind::Globals
                        && start_kw != "NAMESPACE"
                        && w != "VAR_GLOBAL"
                        && STARTS.iter().any(|(s, _, _)| *s == w)
                        && !(start_kw == "CONFIGURATION" && w == "PROGRAM") =>
                {
                    break;
                }
                _ => {}
            }
            j += 1;
        }
        let mut end_tok = last.unwrap_or(j.saturating_sub(1).max(first));
        if matches!(toks.get(end_tok + 1).map(|t| &t.tok), Some(Tok::Semi)) {
            end_tok += 1;
        }
        let body = &toks[first..=end_tok];
        let declares = declared_names(kind, body);
        let name = match kind {
            DeclKind::Type | DeclKind::Globals => declares.first().cloned(),
            _ => body.get(1).and_then(|t| match &t.tok {
                Tok::Ident(_, o) => Some(o.clone()),
                _ => None,
            }),
        }
        .unwrap_or_else(|| {
            format!(
                "<{} at line {}>",
                kind.keyword(),
                line_of(toks[first].span.start as usize)
            )
        });
        let name_text = match kind {
            DeclKind::Type | DeclKind::Globals => original_spelling(body, &name),
            _ => name,
        };
        let locals = local_names(body);
        let uses = body
            .iter()
            .filter_map(|t| match &t.tok {
                Tok::Ident(u, _) | Tok::TypePrefix(u, _) => Some(u.clone()),
                _ => None,
            })
            .filter(|u| !declares.contains(u) && !locals.contains(u))
            .collect();
        let start = toks[first].span.start as usize;
        out.push(Decl {
            kind,
            name: name_text,
            declares,
            uses,
            start,
            end: toks[end_tok].span.end as usize,
            line: line_of(start),
        });
        i = end_tok + 1;
    }
    out
}

fn original_spelling(body: &[Token], upper: &str) -> String {
    body.iter()
        .find_map(|t| match &t.tok {
            Tok::Ident(u, o) if u == upper => Some(o.clone()),
            _ => None,
        })
        .unwrap_or_else(|| upper.to_string())
}

/// Names declared inside a declaration (variables of its VAR blocks, structure members):
/// they shadow, and are no use of, other declarations of the same name.
fn local_names(body: &[Token]) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut inside = false;
    for k in 0..body.len() {
        match word(&body[k].tok) {
            Some(w) if w.starts_with("VAR") || w == "STRUCT" => inside = true,
            Some("END_VAR") | Some("END_STRUCT") => inside = false,
            _ => {}
        }
        if inside
            && let Tok::Ident(u, _) = &body[k].tok
            && matches!(
                body.get(k + 1).map(|t| &t.tok),
                Some(Tok::Colon | Tok::Comma)
            )
        {
            out.insert(u.clone());
        }
    }
    out
}

/// The upper-cased names a declaration introduces.
fn declared_names(kind: DeclKind, body: &[Token]) -> Vec<String> {
    let mut out = Vec::new();
    match kind {
        DeclKind::Type => {
            // `Name :` after TYPE, a `;` or an END_STRUCT (at structure depth 0); the values
            // of an enumeration `Name : (A, B := 2, C)`.
            let mut depth = 0i32;
            for k in 1..body.len() {
                match word(&body[k].tok) {
                    Some("STRUCT") | Some("UNION") => depth += 1,
                    Some("END_STRUCT") | Some("END_UNION") => depth -= 1,
                    _ => {}
                }
                let (Tok::Ident(u, _), Some(Tok::Colon)) =
                    (&body[k].tok, body.get(k + 1).map(|t| &t.tok))
                else {
                    continue;
                };
                let prev = &body[k - 1].tok;
                let at_top = depth == 0
                    && (matches!(prev, Tok::Semi)
                        || matches!(word(prev), Some("TYPE") | Some("END_STRUCT")));
                if !at_top {
                    continue;
                }
                out.push(u.clone());
                if matches!(body.get(k + 2).map(|t| &t.tok), Some(Tok::LParen)) {
                    let mut m = k + 3;
                    while let Some(t) = body.get(m) {
                        match &t.tok {
                            Tok::RParen => break,
                            Tok::Ident(v, _)
                                if matches!(
                                    body.get(m + 1).map(|t| &t.tok),
                                    Some(Tok::Comma | Tok::RParen | Tok::Assign)
                                ) =>
                            {
                                out.push(v.clone())
                            }
                            _ => {}
                        }
                        m += 1;
                    }
                }
            }
        }
        DeclKind::Globals => {
            for k in 1..body.len() {
                if let Tok::Ident(u, _) = &body[k].tok
                    && matches!(
                        body.get(k + 1).map(|t| &t.tok),
                        Some(Tok::Colon | Tok::Comma)
                    )
                {
                    out.push(u.clone());
                }
            }
        }
        _ => {
            if let Some(Tok::Ident(u, _)) = body.get(1).map(|t| &t.tok) {
                out.push(u.clone());
            }
        }
    }
    out
}

/// The outcome of one POU.
#[derive(Debug, Clone)]
pub struct PouResult {
    pub kind: DeclKind,
    pub name: String,
    pub line: usize,
    /// `None` when it compiles; otherwise why not, in one line.
    pub failure: Option<String>,
}

/// The outcome of a whole library check.
#[derive(Debug, Clone)]
pub struct Report {
    /// Each POU (FUNCTION, FUNCTION_BLOCK, PROGRAM) compiled with its dependencies, in
    /// library order.
    pub pous: Vec<PouResult>,
    /// TYPE and VAR_GLOBAL blocks compiled alone (with what they use).
    pub others: Vec<PouResult>,
    /// Diagnostics of the whole library compiled as one project.
    pub project_errors: usize,
    /// POUs (and other declarations) the one-project diagnostics point into.
    pub project_failing_decls: usize,
    /// The first diagnostics of the one-project compilation, one line each.
    pub project_first: Vec<String>,
}

impl Report {
    pub fn compiled(&self) -> usize {
        self.pous.iter().filter(|p| p.failure.is_none()).count()
    }

    /// Percentage of POUs that compile, to one decimal.
    pub fn percent(&self) -> f64 {
        if self.pous.is_empty() {
            return 0.0;
        }
        (self.compiled() as f64 * 1000.0 / self.pous.len() as f64).round() / 10.0
    }
}

/// FNV-1a (64 bits) of a text: identifies the library text a report was measured on.
pub fn fingerprint(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Marks the start of the generated section in STATUS.md.
pub const STATUS_BEGIN: &str =
    "<!-- library-check:begin (generated by `cargo xtask oscat --write-status`) -->";
/// Marks its end.
pub const STATUS_END: &str = "<!-- library-check:end -->";

impl Report {
    /// The Markdown of the generated STATUS.md section: `source` says which text was
    /// measured (its origin and version), `fingerprint` its [`fingerprint`].
    pub fn markdown(&self, source: &str, fingerprint: u64) -> String {
        let mut out = String::new();
        out.push_str(STATUS_BEGIN);
        out.push('\n');
        out.push_str(&format!(
            "Measured on {source} (fingerprint `{fingerprint:016x}`).\n\n"
        ));
        out.push_str(&format!(
            "* **One POU at a time: {} of {} POUs compile ({:.1} %)** (each FUNCTION, FUNCTION_BLOCK and PROGRAM with the TYPEs and POUs it uses).\n",
            self.compiled(),
            self.pous.len(),
            self.percent()
        ));
        let types_ok = self.others.iter().filter(|o| o.failure.is_none()).count();
        out.push_str(&format!(
            "* TYPE and VAR_GLOBAL blocks: {types_ok} of {} compile.\n",
            self.others.len()
        ));
        if self.project_errors == 0 {
            out.push_str("* As one project: compiles.\n");
        } else {
            out.push_str(&format!(
                "* As one project: {} error(s), in {} declaration(s).\n",
                self.project_errors, self.project_failing_decls
            ));
        }
        let failing: Vec<&PouResult> = self
            .pous
            .iter()
            .chain(&self.others)
            .filter(|p| p.failure.is_some())
            .collect();
        if !failing.is_empty() {
            out.push_str("\nWhat does not compile, and why (the first diagnostic):\n\n");
            for p in failing {
                let mut why = p.failure.clone().unwrap_or_default();
                // A shortened message may have lost a closing backtick.
                if why.matches('`').count() % 2 == 1 {
                    why.push('`');
                }
                out.push_str(&format!(
                    "* {} `{}` (line {}): {why}\n",
                    p.kind.keyword(),
                    p.name,
                    p.line,
                ));
            }
        }
        out.push_str(STATUS_END);
        out.push('\n');
        out
    }
}

/// Longest failure reason printed.
const MAX_REASON: usize = 110;

fn shorten(message: &str) -> String {
    let line = message.lines().next().unwrap_or("").trim();
    if line.chars().count() <= MAX_REASON {
        return line.to_string();
    }
    let cut: String = line.chars().take(MAX_REASON - 1).collect();
    format!("{cut}…")
}

/// Checks `text` (named `file` in messages): as one project, and each POU with its
/// dependencies.
pub fn check(file: &str, text: &str) -> Report {
    let decls = split(text);
    let opts = Options {
        library: true,
        ..Options::default()
    };
    let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
    let by_name: HashMap<&str, usize> = decls
        .iter()
        .enumerate()
        .flat_map(|(i, d)| d.declares.iter().map(move |n| (n.as_str(), i)))
        .collect();

    // (a) One project.
    let (project_errors, project_failing_decls, project_first) =
        match compile(&[(file.to_string(), text.to_string())], &opts) {
            Ok(_) => (0, 0, Vec::new()),
            Err((diags, _)) => {
                let own: Vec<&Diagnostic> = diags.iter().filter(|d| d.span.file == 0).collect();
                let failing: BTreeSet<usize> = own
                    .iter()
                    .filter_map(|d| {
                        let at = d.span.start as usize;
                        decls
                            .iter()
                            .position(|x| x.start <= at && at < x.end.max(x.start + 1))
                    })
                    .collect();
                let first = own
                    .iter()
                    .take(10)
                    .map(|d| {
                        format!(
                            "{file}:{}: {}",
                            line_of(d.span.start as usize),
                            shorten(&d.message)
                        )
                    })
                    .collect();
                (diags.len(), failing.len(), first)
            }
        };

    // (b) One declaration at a time, with its dependencies.
    let closure = |root: usize| -> Vec<usize> {
        let mut seen = BTreeSet::from([root]);
        let mut work = vec![root];
        while let Some(d) = work.pop() {
            for u in &decls[d].uses {
                if let Some(&dep) = by_name.get(u.as_str())
                    && seen.insert(dep)
                {
                    work.push(dep);
                }
            }
        }
        seen.into_iter().collect()
    };
    let mut own_failure: Vec<Option<Option<String>>> = vec![None; decls.len()];
    let mut results: Vec<PouResult> = Vec::new();
    for root in 0..decls.len() {
        let members = closure(root);
        let files: Vec<(String, String)> = members
            .iter()
            .map(|&m| {
                (
                    file.to_string(),
                    text[decls[m].start..decls[m].end].to_string(),
                )
            })
            .collect();
        let root_file = members.iter().position(|&m| m == root).unwrap_or(0) as u32;
        let failure = match compile(&files, &opts) {
            Ok(_) => None,
            Err((diags, _)) => Some(reason(file, &decls, &members, root_file, &diags, &line_of)),
        };
        own_failure[root] = Some(failure.clone());
        results.push(PouResult {
            kind: decls[root].kind,
            name: decls[root].name.clone(),
            line: decls[root].line,
            failure,
        });
    }
    let (pous, others) = results.into_iter().partition(|r| r.kind.is_pou());
    Report {
        pous,
        others: others
            .into_iter()
            .filter(|r: &PouResult| r.kind != DeclKind::Other)
            .collect(),
        project_errors,
        project_failing_decls,
        project_first,
    }
}

/// One line saying why a declaration compiled with its dependencies failed: the first
/// diagnostic in its own text, else the first dependency that has one.
fn reason(
    file: &str,
    decls: &[Decl],
    members: &[usize],
    root_file: u32,
    diags: &[Diagnostic],
    line_of: &dyn Fn(usize) -> usize,
) -> String {
    let at = |d: &Diagnostic| -> Option<(usize, usize)> {
        let m = *members.get(d.span.file as usize)?;
        Some((m, decls[m].start + d.span.start as usize))
    };
    if let Some(d) = diags.iter().find(|d| d.span.file == root_file) {
        let line = at(d).map_or(0, |(_, off)| line_of(off));
        return format!("{file}:{line}: {}", shorten(&d.message));
    }
    match diags.iter().find_map(|d| at(d).map(|(m, off)| (m, off, d))) {
        Some((m, off, d)) => format!(
            "needs {} `{}`, which does not compile ({file}:{}: {})",
            decls[m].kind.keyword(),
            decls[m].name,
            line_of(off),
            shorten(&d.message)
        ),
        None => diags
            .first()
            .map(|d| shorten(&d.message))
            .unwrap_or_else(|| "unknown failure".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIB: &str = "
TYPE Color : (Red, Green); END_TYPE
TYPE Pt : STRUCT x, y : INT; END_STRUCT END_TYPE
FUNCTION Twice : INT VAR_INPUT a : INT; END_VAR Twice := a * 2; END_FUNCTION
FUNCTION UsesTwice : INT VAR_INPUT p : Pt; END_VAR UsesTwice := Twice(p.x); END_FUNCTION
FUNCTION Broken : INT Broken := nope; END_FUNCTION
FUNCTION NeedsBroken : INT NeedsBroken := Broken(); END_FUNCTION
FUNCTION_BLOCK Fb VAR c : Color := Green; END_VAR c := Red; END_FUNCTION_BLOCK
";

    #[test]
    fn splits_and_finds_dependencies() {
        let d = split(LIB);
        let names: Vec<&str> = d.iter().map(|d| d.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "Color",
                "Pt",
                "Twice",
                "UsesTwice",
                "Broken",
                "NeedsBroken",
                "Fb"
            ]
        );
        assert_eq!(d[0].declares, ["COLOR", "RED", "GREEN"]);
        assert!(d[3].uses.contains("TWICE") && d[3].uses.contains("PT"));
    }

    #[test]
    fn reports_each_pou() {
        let r = check("lib.st", LIB);
        let failures: Vec<(&str, &str)> = r
            .pous
            .iter()
            .filter_map(|p| Some((p.name.as_str(), p.failure.as_deref()?)))
            .collect();
        assert_eq!(r.pous.len(), 5);
        assert_eq!(r.compiled(), 3, "{failures:?}");
        assert_eq!(failures[0].0, "Broken");
        assert!(
            failures[0].1.contains("lib.st:6: unknown variable `nope`"),
            "{failures:?}"
        );
        assert!(
            failures[1].1.starts_with("needs FUNCTION `Broken`"),
            "{failures:?}"
        );
        assert_eq!(r.project_failing_decls, 1);
        assert_eq!(r.percent(), 60.0);
    }
}
