//! Test systems: TOML text -> validated `System` -> binary blob, which the tests decode with
//! the same no_std decoder syssw uses.

use std::string::{String, ToString};
use std::vec::Vec;

/// The binary configuration of `source` (panics with every diagnostic if it is invalid).
pub fn blob(source: &str) -> Vec<u8> {
    match config::compile("test.toml", source, &|_| true) {
        Ok(blob) => blob,
        Err(diags) => {
            let all: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
            panic!("test system is invalid:\n{}", all.join("\n"));
        }
    }
}

/// Two partitions: `a` (window in time partition 1) and `b` (background). `# a`, `# b` and
/// `# tail` mark where extra lines go (see [`with`]).
pub const TWO: &str = r#"[system]
memory = "512MiB"

[[schedules]]
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
# a

[partitions.b]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 50
time = "background"
# b

# tail
"#;

/// `TWO` with each `(marker, text)` inserted after its marker.
pub fn with(edits: &[(&str, &str)]) -> String {
    let mut text = TWO.to_string();
    for (marker, extra) in edits {
        assert!(text.contains(marker), "test bug: no {marker:?}");
        text = text.replacen(marker, &std::format!("{marker}\n{extra}"), 1);
    }
    text
}
