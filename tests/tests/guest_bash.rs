//! Scenario guest_bash: Debian's bash-static, unmodified, runs tests/configs/guest/bash.sh in
//! the guest, and prints line for line what the same script prints on this machine.

use scenarios::same_output_as_host;
use std::process::Command;

#[test]
fn guest_bash() {
    // `cargo xtask test` installed it (the manifest's `debian_packages`).
    let script = xtask::workspace_root().join("tests/configs/guest/bash.sh");
    same_output_as_host(
        "guest_bash",
        "bash",
        Command::new("/bin/bash-static").arg(&script),
    );
}
