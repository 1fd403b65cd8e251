//! Scenario guest_bash: Debian's bash-static, unmodified, runs tests/configs/guest/bash.sh in
//! the guest, and prints line for line what the same script prints on this machine.

use scenarios::{boot, check, guest_stdout, partition_lines};
use std::process::Command;

const BASH: &str = "/bin/bash-static";

#[test]
fn guest_bash() {
    // `cargo xtask test` installed it (the manifest's `debian_packages`).
    let script = xtask::workspace_root().join("tests/configs/guest/bash.sh");
    let host = Command::new(BASH)
        .arg(&script)
        .output()
        .unwrap_or_else(|e| panic!("running {BASH} {}: {e}", script.display()));
    assert!(
        host.status.success(),
        "the script failed on the host: {host:?}"
    );
    let expected: Vec<String> = String::from_utf8_lossy(&host.stdout)
        .lines()
        .map(str::to_string)
        .collect();

    let o = boot("guest_bash");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let printed = guest_stdout(&o, "bash");
    check(
        &o,
        printed == expected,
        &format!("the guest printed {printed:#?}, the host {expected:#?}"),
    );
    for needle in ["unsupported system call", "killed by signal", " stderr: "] {
        let found = partition_lines(&o, "bash", needle);
        check(&o, found.is_empty(), &format!("{needle:?}: {found:?}"));
    }
    check(
        &o,
        !partition_lines(&o, "bash", "guest: init exited with status 0").is_empty(),
        "bash did not exit with status 0",
    );
    check(&o, o.succeeded(), "expected success exit (33)");
}
