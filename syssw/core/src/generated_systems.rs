//! The boot property's syssw half: for random valid descriptions (`config::generate`),
//! everything syssw computes from the decoded configuration before it starts a partition
//! accepts it: each partition's start budget fits its `memory` and `kernel_memory`
//! ([`crate::budget`]) and the port buffers are laid out ([`crate::ports`]). The QEMU
//! scenarios `generated_boot_*` boot a few of them.

use crate::budget::start_budget;
use crate::ports::{Ports, arena_size};
use crate::testsys::elf;
use std::vec;

/// Seeds tried (`config/tests/generated.rs` checks the same ones against the validator).
const CASES: u64 = 2_000;
/// A stand-in for the heartbeat program `test-partition`: one 256 KiB segment (the real
/// image is smaller; `cargo xtask check-config` checks the committed descriptions with it).
const IMAGE_BYTES: u64 = 256 * 1024;

#[test]
fn every_generated_system_passes_syssws_start_checks() {
    let image = elf(0x20_0000, IMAGE_BYTES);
    let (mut accepted, mut partitions) = (0, 0);
    for seed in 0..CASES {
        let text = config::generate::system(seed, "test-partition");
        // The validator's half is `config/tests/generated.rs`; a refused one is counted there.
        let Ok(blob) = config::compile("generated.toml", &text, &|_| true) else {
            continue;
        };
        let system = config::decode(&blob)
            .unwrap_or_else(|e| panic!("seed {seed}: the decoder refuses the blob: {e}"));
        for p in system.partitions() {
            let budget = start_budget(&system, &p, &image, 0)
                .unwrap_or_else(|e| panic!("seed {seed}: partition {}: {e:?}", p.name));
            assert!(
                budget.memory <= p.memory && budget.kernel_memory <= p.kernel_memory,
                "seed {seed}: partition {} needs {budget:?} of memory {} and kernel_memory {}:\n{text}",
                p.name,
                p.memory,
                p.kernel_memory
            );
            partitions += 1;
        }
        let mut arena = vec![0u8; arena_size(&system)];
        if let Err(e) = Ports::new(&system, &mut arena) {
            panic!("seed {seed}: ports: {e}\n{text}");
        }
        accepted += 1;
    }
    std::println!("{accepted} of {CASES} generated systems checked, {partitions} partitions");
    assert!(accepted * 100 >= CASES * 99, "too few valid systems");
}
