//! Source files, spans and compiler diagnostics.
//!
//! Every error carries a [`Span`] (file + byte range). Rendering goes through ariadne so the
//! user sees `file:line:column`, the offending source line and a marker under it.

use std::fmt;

pub use crate::codes::Code;

/// A byte range inside one source file of a [`SourceMap`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Span {
    pub file: u32,
    pub start: u32,
    pub end: u32,
}

impl Span {
    pub fn new(file: u32, start: usize, end: usize) -> Span {
        Span {
            file,
            start: start as u32,
            end: end as u32,
        }
    }

    /// The smallest span covering both `self` and `other` (same file assumed).
    pub fn to(self, other: Span) -> Span {
        Span {
            file: self.file,
            start: self.start.min(other.start),
            end: self.end.max(other.end),
        }
    }
}

/// One loaded source file.
#[derive(Debug, Clone)]
pub struct SourceFile {
    pub name: String,
    pub text: String,
    /// Byte offsets at which each line starts (line 1 is index 0).
    line_starts: Vec<usize>,
}

impl SourceFile {
    pub fn new(name: impl Into<String>, text: impl Into<String>) -> SourceFile {
        let text = text.into();
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        SourceFile {
            name: name.into(),
            text,
            line_starts,
        }
    }

    /// 1-based line and column (column counted in characters) of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let line = match self.line_starts.binary_search(&offset) {
            Ok(i) => i,
            Err(i) => i - 1,
        };
        let start = self.line_starts[line];
        let col = self
            .text
            .get(start..offset)
            .map_or(offset - start, |s| s.chars().count());
        (line + 1, col + 1)
    }
}

/// All source files of one compilation; the prelude is one of them.
#[derive(Debug, Clone, Default)]
pub struct SourceMap {
    pub files: Vec<SourceFile>,
}

impl SourceMap {
    pub fn add(&mut self, name: impl Into<String>, text: impl Into<String>) -> u32 {
        self.files.push(SourceFile::new(name, text));
        (self.files.len() - 1) as u32
    }

    pub fn file(&self, id: u32) -> &SourceFile {
        &self.files[id as usize]
    }

    /// `file:line:column` of the start of a span.
    pub fn location(&self, span: Span) -> String {
        let file = self.file(span.file);
        let (line, col) = file.line_col(span.start as usize);
        format!("{}:{}:{}", file.name, line, col)
    }
}

/// One compile error.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnostic {
    /// The stable code of the kind of error ([`codes`](crate::codes)).
    pub code: Code,
    pub span: Span,
    pub message: String,
    /// Text attached to the marker under the source line.
    pub label: Option<String>,
}

impl Diagnostic {
    pub fn error(code: Code, span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            code,
            span,
            message: message.into(),
            label: None,
        }
    }

    pub fn with_label(mut self, label: impl Into<String>) -> Diagnostic {
        self.label = Some(label.into());
        self
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// Collects diagnostics so that analysis can keep going after the first error.
#[derive(Debug, Default)]
pub struct Diagnostics {
    pub list: Vec<Diagnostic>,
}

impl Diagnostics {
    pub fn push(&mut self, d: Diagnostic) {
        // Cascading errors at the very same place add noise, not information.
        if !self
            .list
            .iter()
            .any(|e| e.span == d.span && e.message == d.message)
        {
            self.list.push(d);
        }
    }

    pub fn error(&mut self, code: Code, span: Span, message: impl Into<String>) {
        self.push(Diagnostic::error(code, span, message));
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }
}

/// Renders diagnostics with ariadne. The first line of each report is `file:line:col: error[E0042]: msg`
/// so that tools (and the tests) can pick up the location without parsing the drawing.
pub fn render(sources: &SourceMap, diags: &[Diagnostic], color: bool) -> String {
    use ariadne::{Config, IndexType, Label, Report, ReportKind, Source};
    let mut out = String::new();
    for d in diags {
        let file = sources.file(d.span.file);
        let mut start = (d.span.start as usize).min(file.text.len());
        while !file.text.is_char_boundary(start) {
            start -= 1;
        }
        let mut end = (d.span.end as usize).clamp(start, file.text.len());
        while !file.text.is_char_boundary(end) {
            end += 1;
        }
        out.push_str(&format!(
            "{}: error[{}]: {}\n",
            sources.location(d.span),
            d.code,
            d.message
        ));
        let label = Label::new((file.name.clone(), start..end))
            .with_message(d.label.clone().unwrap_or_else(|| d.message.clone()));
        let report = Report::build(ReportKind::Error, (file.name.clone(), start..end))
            .with_config(
                Config::default()
                    .with_index_type(IndexType::Byte)
                    .with_color(color),
            )
            .with_code(d.code)
            .with_message(&d.message)
            .with_label(label)
            .finish();
        let mut buf = Vec::new();
        if report
            .write(
                (file.name.clone(), Source::from(file.text.as_str())),
                &mut buf,
            )
            .is_ok()
        {
            out.push_str(&String::from_utf8_lossy(&buf));
        }
    }
    out
}
