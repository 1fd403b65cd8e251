//! Loader failures before the jump are reported clearly on the firmware console.

use scenarios::{boot, check};
use xtask::qemu::Ending;

#[test]
fn loader_missing_kernel() {
    let o = boot("loader_missing_kernel");
    check(
        &o,
        matches!(o.ending, Ending::Aborted(_)),
        "expected the harness to stop at the loader error",
    );
    check(
        &o,
        o.line("loader: error: kernel.elf not found on the ESP")
            .is_some(),
        "expected a clear missing-file error",
    );
    check(
        &o,
        o.line("kernel: ready").is_none(),
        "the kernel must not run",
    );
}

#[test]
fn loader_damaged_image() {
    let o = boot("loader_damaged_image");
    check(
        &o,
        matches!(o.ending, Ending::Aborted(_)),
        "expected the harness to stop at the loader error",
    );
    let line = o
        .line("loader: error: system.img is invalid")
        .unwrap_or_default();
    check(
        &o,
        line.contains("checksum mismatch"),
        "expected the checksum to be named",
    );
}
