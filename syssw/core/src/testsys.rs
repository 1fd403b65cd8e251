//! Test systems: TOML text -> validated `System` -> binary blob, which the tests decode with
//! the same no_std decoder syssw uses.

use std::string::{String, ToString};
use std::vec;
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

/// A minimal static ELF with one loadable segment of `mem_size` bytes at `vaddr`.
pub fn elf(vaddr: u64, mem_size: u64) -> Vec<u8> {
    let mut e = vec![0u8; 64 + 56];
    e[..4].copy_from_slice(b"\x7fELF");
    e[4] = 2; // 64-bit
    e[5] = 1; // little-endian
    e[6] = 1; // version
    e[16..18].copy_from_slice(&2u16.to_le_bytes()); // ET_EXEC
    e[18..20].copy_from_slice(&62u16.to_le_bytes()); // x86_64
    e[20..24].copy_from_slice(&1u32.to_le_bytes());
    e[24..32].copy_from_slice(&vaddr.to_le_bytes()); // entry
    e[32..40].copy_from_slice(&64u64.to_le_bytes()); // program headers
    e[52..54].copy_from_slice(&64u16.to_le_bytes());
    e[54..56].copy_from_slice(&56u16.to_le_bytes());
    e[56..58].copy_from_slice(&1u16.to_le_bytes());
    e[58..60].copy_from_slice(&64u16.to_le_bytes());
    let ph = &mut e[64..];
    ph[..4].copy_from_slice(&1u32.to_le_bytes()); // PT_LOAD
    ph[4..8].copy_from_slice(&6u32.to_le_bytes()); // RW
    ph[16..24].copy_from_slice(&vaddr.to_le_bytes());
    ph[24..32].copy_from_slice(&vaddr.to_le_bytes());
    ph[40..48].copy_from_slice(&mem_size.to_le_bytes());
    ph[48..56].copy_from_slice(&4096u64.to_le_bytes());
    e
}
