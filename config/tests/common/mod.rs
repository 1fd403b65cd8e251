//! Helpers shared by the integration tests.
#![allow(dead_code)]

use config::{Diagnostic, System};

/// A small valid system. Tests edit it with [`doc`]: `# a`, `# b` and `# tail` mark where
/// extra lines for partition `a`, partition `b` and the end of the file go.
pub const BASE: &str = r#"[system]
memory = "512MiB"

[[schedules]]
name = "main"
major_frame = "10ms"

[[schedules.windows]]
partition = "a"
offset = "0ms"
duration = "2ms"

[partitions.a]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 100
ports.out = { kind = "sampling", direction = "out", size = 8 }
# a

[partitions.b]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 50
time = "background"
ports.in = { kind = "sampling", direction = "in", size = 8 }
# b

[[channels]]
kind = "sampling"
from = "a.out"
to = ["b.in"]
# tail
"#;

/// `BASE` with each `(pattern, replacement)` applied once (the pattern must occur).
pub fn doc(edits: &[(&str, &str)]) -> String {
    edit(BASE, edits)
}

/// `base` with each `(pattern, replacement)` applied once (the pattern must occur).
pub fn edit(base: &str, edits: &[(&str, &str)]) -> String {
    let mut text = base.to_string();
    for (pattern, replacement) in edits {
        assert!(
            text.contains(pattern),
            "test bug: {pattern:?} not in the document"
        );
        text = text.replacen(pattern, replacement, 1);
    }
    text
}

pub fn any_image(_: &str) -> bool {
    true
}

pub fn load(source: &str) -> Result<System, Vec<Diagnostic>> {
    config::load("test.toml", source, &any_image)
}

pub fn load_ok(source: &str) -> System {
    match load(source) {
        Ok(s) => s,
        Err(diags) => {
            let all: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
            panic!("expected a valid system, got:\n{}", all.join("\n"));
        }
    }
}

/// 1-based line and column of the `nth` occurrence (0 = first) of `needle` in `source`.
/// A `^` in the needle marks the exact point (`"memory = ^0"` is the position of the `0`);
/// without one, the needle's start.
pub fn position(source: &str, needle: &str, nth: usize) -> (usize, usize) {
    let (prefix, rest) = needle.split_once('^').unwrap_or(("", needle));
    let text = format!("{prefix}{rest}");
    let at = source
        .match_indices(&text)
        .nth(nth)
        .unwrap_or_else(|| panic!("test bug: {text:?} #{nth} not in the source"))
        .0
        + prefix.len();
    let before = &source[..at];
    let line = before.matches('\n').count() + 1;
    let column = before[before.rfind('\n').map_or(0, |i| i + 1)..]
        .chars()
        .count()
        + 1;
    (line, column)
}

/// Asserts that loading `source` fails with exactly one diagnostic, at the `nth` occurrence
/// of `needle`, with `key_path`, whose message contains `message`.
pub fn expect_one(source: &str, needle: &str, nth: usize, key_path: &str, message: &str) {
    let diags = load(source).expect_err("expected a diagnostic");
    let all: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
    assert_eq!(
        diags.len(),
        1,
        "expected one diagnostic, got:\n{}",
        all.join("\n")
    );
    check(&diags[0], source, needle, nth, key_path, message);
}

/// Asserts that some diagnostic of `source` matches (for files with several problems).
pub fn expect_some(source: &str, needle: &str, nth: usize, key_path: &str, message: &str) {
    let diags = load(source).expect_err("expected a diagnostic");
    let all: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
    let found = diags
        .iter()
        .find(|d| d.key_path == key_path && d.message.contains(message));
    let Some(d) = found else {
        panic!(
            "no diagnostic at {key_path} containing {message:?}; got:\n{}",
            all.join("\n")
        );
    };
    check(d, source, needle, nth, key_path, message);
}

fn check(d: &Diagnostic, source: &str, needle: &str, nth: usize, key_path: &str, message: &str) {
    let (line, column) = position(source, needle, nth);
    assert_eq!(d.file, "test.toml");
    assert_eq!(d.key_path, key_path, "key path of {d}");
    assert!(
        d.message.contains(message),
        "message of {d} lacks {message:?}"
    );
    assert_eq!(
        (d.line, d.column),
        (line, column),
        "position of {d} (expected at {needle:?})"
    );
}
