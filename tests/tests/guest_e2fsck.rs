//! Scenario guest_e2fsck: Debian's e2fsck.static, unmodified, checks read-only an ext4 image
//! made with mkfs.ext4 and a copy damaged with debugfs (a wrong link count, an allocated
//! block marked free; tests/configs/guest/e2fsck-images.sh), in the guest and on this
//! machine; both must print the same lines.

use scenarios::same_output_as_host;
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
    let (_, expected) = same_output_as_host(
        "guest_e2fsck",
        "fsck",
        Command::new("sh")
            .arg(&script)
            .arg(&images)
            .env("PATH", path),
    );
    for status in ["e2fsck clean.img: status 0", "e2fsck damaged.img: status 4"] {
        assert!(
            expected.iter().any(|l| l == status),
            "no {status:?} in {expected:#?}"
        );
    }
}
