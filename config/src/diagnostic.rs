//! Diagnostics: one problem of a description, located by file, line:column and dotted key
//! path, printed as `file:line:col: key.path: reason`.

use std::fmt;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Diagnostic {
    /// The file name the caller gave for messages.
    pub file: String,
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub column: usize,
    /// Dotted path of the key, e.g. `schedules[0].windows[2].offset` or
    /// `partitions.plc.ports.level.size`; empty where no key applies (some syntax errors).
    pub key_path: String,
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: ", self.file, self.line, self.column)?;
        if !self.key_path.is_empty() {
            write!(f, "{}: ", self.key_path)?;
        }
        f.write_str(&self.message)
    }
}

/// 1-based (line, column in characters) of byte `offset` of `source`.
pub fn line_column(source: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(source.len());
    while !source.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &source[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// The description `bytes` as text, or a diagnostic at the first byte that is not UTF-8
/// (a binary file given by mistake): descriptions are UTF-8 TOML.
pub fn text<'a>(file: &str, bytes: &'a [u8]) -> Result<&'a str, Diagnostic> {
    std::str::from_utf8(bytes).map_err(|e| {
        let valid = std::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or_default();
        let (line, column) = line_column(valid, valid.len());
        Diagnostic {
            file: file.to_string(),
            line,
            column,
            key_path: String::new(),
            message: format!(
                "not UTF-8 text (byte {:#04x} at offset {}): a description is a TOML file",
                bytes[e.valid_up_to()],
                e.valid_up_to()
            ),
        }
    })
}

impl Diagnostic {
    /// A diagnostic at the value of the key `keys` (e.g. `["partitions", "plc", "memory"]`)
    /// of the description `source`, for checks made after validation (the boot-time budget,
    /// which needs the built images); at the deepest of the keys that exists, or at the
    /// start of the file.
    pub fn at_key(file: &str, source: &str, keys: &[&str], message: impl fmt::Display) -> Self {
        let (tree, _) = DeTable::parse_recoverable(source);
        let mut at = 0;
        let mut table = Some(tree.get_ref());
        let mut path = KeyPath::root();
        for key in keys {
            let Some((found, value)) = table.and_then(|t| t.get_key_value(*key)) else {
                break;
            };
            path = path.key(key);
            at = found.span().start;
            table = match value.get_ref() {
                DeValue::Table(inner) => Some(inner),
                _ => {
                    at = value.span().start;
                    None
                }
            };
        }
        Reporter::new(file, source).at(at, &path, message)
    }
}

/// A dotted key path under construction (`a.b[2].c`; keys that are not bare TOML keys are
/// quoted).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct KeyPath(String);

impl KeyPath {
    pub fn root() -> Self {
        KeyPath(String::new())
    }

    /// A path already rendered as text.
    pub fn from_rendered(path: String) -> Self {
        KeyPath(path)
    }

    pub fn key(&self, key: &str) -> KeyPath {
        let bare = !key.is_empty()
            && key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        let mut path = self.0.clone();
        if !path.is_empty() {
            path.push('.');
        }
        if bare {
            path.push_str(key);
        } else {
            path.push_str(&format!("{key:?}"));
        }
        KeyPath(path)
    }

    pub fn index(&self, index: usize) -> KeyPath {
        KeyPath(format!("{}[{index}]", self.0))
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for KeyPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// The key path of the deepest key or value of `document` whose span holds `offset` (used for
/// errors that come with a span only: TOML syntax and shape errors).
pub fn key_path_at(document: &DeTable<'_>, offset: usize) -> String {
    let mut best = (0usize, KeyPath::root());
    search_table(document, offset, &KeyPath::root(), 1, &mut best);
    best.1.0
}

fn search_table(
    table: &DeTable<'_>,
    offset: usize,
    path: &KeyPath,
    depth: usize,
    best: &mut (usize, KeyPath),
) {
    for (key, value) in table.iter() {
        let here = path.key(key.get_ref());
        if key.span().contains(&offset) && depth > best.0 {
            *best = (depth, here.clone());
        }
        search_value(value, offset, &here, depth, best);
    }
}

fn search_value(
    value: &Spanned<DeValue<'_>>,
    offset: usize,
    path: &KeyPath,
    depth: usize,
    best: &mut (usize, KeyPath),
) {
    let span = value.span();
    if (span.contains(&offset) || span.start == offset) && depth > best.0 {
        *best = (depth, path.clone());
    }
    match value.get_ref() {
        DeValue::Table(table) => search_table(table, offset, path, depth + 1, best),
        DeValue::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                search_value(item, offset, &path.index(i), depth + 1, best);
            }
        }
        _ => {}
    }
}

/// Collects the diagnostics of one file.
pub struct Reporter<'s> {
    file: String,
    source: &'s str,
    pub diagnostics: Vec<Diagnostic>,
    /// What is valid but probably not meant (the description says it is).
    pub warnings: Vec<Diagnostic>,
}

impl<'s> Reporter<'s> {
    /// The file name messages carry.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// Line and column of a source offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        line_column(self.source, offset)
    }

    pub fn new(file: &str, source: &'s str) -> Self {
        Reporter {
            file: file.to_string(),
            source,
            diagnostics: Vec::new(),
            warnings: Vec::new(),
        }
    }

    fn at(&self, offset: usize, path: &KeyPath, message: impl fmt::Display) -> Diagnostic {
        let (line, column) = line_column(self.source, offset);
        Diagnostic {
            file: self.file.clone(),
            line,
            column,
            key_path: path.0.clone(),
            message: message.to_string(),
        }
    }

    /// Records a problem at byte `offset` of the source.
    pub fn error(&mut self, offset: usize, path: &KeyPath, message: impl fmt::Display) {
        let diagnostic = self.at(offset, path, message);
        self.diagnostics.push(diagnostic);
    }

    /// Records a warning at byte `offset` of the source: valid, but worth a second look.
    pub fn warning(&mut self, offset: usize, path: &KeyPath, message: impl fmt::Display) {
        let diagnostic = self.at(offset, path, message);
        self.warnings.push(diagnostic);
    }

    /// 1-based line of byte `offset` (for "defined at line N" notes).
    pub fn line_of(&self, offset: usize) -> usize {
        line_column(self.source, offset).0
    }

    /// The diagnostics in source order.
    pub fn finish(mut self) -> Vec<Diagnostic> {
        self.diagnostics.sort_by_key(|d| (d.line, d.column));
        self.diagnostics
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions() {
        let s = "ab\ncdé\nf";
        assert_eq!(line_column(s, 0), (1, 1));
        assert_eq!(line_column(s, 3), (2, 1));
        assert_eq!(line_column(s, 7), (2, 4)); // after the 2-byte é
        assert_eq!(line_column(s, 100), (3, 2));
    }

    #[test]
    fn paths() {
        let p = KeyPath::root()
            .key("schedules")
            .index(0)
            .key("windows")
            .index(2);
        assert_eq!(p.key("offset").as_str(), "schedules[0].windows[2].offset");
        assert_eq!(KeyPath::root().key("a.b").as_str(), "\"a.b\"");
    }

    #[test]
    fn display() {
        let d = Diagnostic {
            file: "f.toml".into(),
            line: 3,
            column: 7,
            key_path: "system.memory".into(),
            message: "bad".into(),
        };
        assert_eq!(d.to_string(), "f.toml:3:7: system.memory: bad");
    }

    #[test]
    fn at_key_points_at_the_value_or_the_deepest_key() {
        let src = "[system]\nmemory = \"1MiB\"\n\n[partitions.plc]\nimage = \"softplc\"\nkernel_memory = \"64KiB\"\n";
        let d = Diagnostic::at_key("f", src, &["partitions", "plc", "kernel_memory"], "low");
        assert_eq!((d.line, d.column), (6, 17));
        assert_eq!(d.key_path, "partitions.plc.kernel_memory");
        // A key the file leaves out (a default): the deepest existing key.
        let d = Diagnostic::at_key("f", src, &["partitions", "plc", "memory"], "low");
        assert_eq!((d.line, d.key_path.as_str()), (4, "partitions.plc"));
    }
}
