//! Scenario guest_e2fsck: Debian's e2fsck.static, unmodified, checks read-only an ext4 image
//! made with mkfs.ext4 and a copy damaged with debugfs (a wrong link count, an allocated
//! block marked free; tests/configs/guest/e2fsck-images.sh), in the guest and on this
//! machine; both must print the same lines.

use scenarios::{boot, check, guest_stdout, partition_lines};
use std::process::Command;

const E2FSCK: &str = "/sbin/e2fsck.static";

#[test]
fn guest_e2fsck() {
    let root = xtask::workspace_root();
    // `cargo xtask test` made them (the manifest's `prepare`) and installed e2fsck.static.
    let images = root.join("target/guest-e2fsck");
    // The host runs the same script with e2fsck.static first in its PATH.
    let bin = images.join("bin");
    let _ = std::fs::remove_dir_all(&bin);
    std::fs::create_dir_all(&bin).expect("bin directory");
    std::os::unix::fs::symlink(E2FSCK, bin.join("e2fsck")).expect("e2fsck link");
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let script = root.join("tests/configs/guest/e2fsck.sh");
    let host = Command::new("sh")
        .arg(&script)
        .arg(&images)
        .env("PATH", path)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let expected: Vec<String> = String::from_utf8_lossy(&host.stdout)
        .lines()
        .map(str::to_string)
        .collect();
    for status in ["e2fsck clean.img: status 0", "e2fsck damaged.img: status 4"] {
        assert!(
            expected.iter().any(|l| l == status),
            "on the host: no {status:?} in {expected:#?}"
        );
    }

    let o = boot("guest_e2fsck");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let printed = guest_stdout(&o, "fsck");
    check(
        &o,
        printed == expected,
        &format!("the guest printed {printed:#?}, the host {expected:#?}"),
    );
    for needle in ["unsupported system call", "killed by signal"] {
        let found = partition_lines(&o, "fsck", needle);
        check(&o, found.is_empty(), &format!("{needle:?}: {found:?}"));
    }
    check(&o, o.succeeded(), "expected success exit (33)");
}
