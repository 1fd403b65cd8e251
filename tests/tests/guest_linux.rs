//! The Linux-side checks (`tests/linux`, program `linux-tests`) in the paravirtualized guest
//! (configuration `tests/configs/guest_linux.toml`): each guest partition there runs
//! `/bin/linux-tests AREA...`, and its output must be exactly the areas' expected files
//! `tests/linux/expected/<area>.out` — the lines the same program prints on the host Linux
//! (`cargo xtask test` checks that on the host first). The areas the configuration runs
//! are those the guest passes; the others are listed there with what they wait for.

//! Scenario `guest_threads` runs the `threads` area the same way (configuration
//! `tests/configs/guest_threads.toml`), and `guest_threads_smp` the `threads` and
//! `memory` areas in a guest on two CPUs (`tests/configs/guest_threads_smp.toml`).

use scenarios::{boot, check, guest_stdout};

#[test]
fn guest_linux() {
    linux_tests("guest_linux", "tests/configs/guest_linux.toml");
}

#[test]
fn guest_threads() {
    linux_tests("guest_threads", "tests/configs/guest_threads.toml");
}

#[test]
fn guest_threads_smp() {
    linux_tests("guest_threads_smp", "tests/configs/guest_threads_smp.toml");
}

/// Boots scenario `scenario` (configuration `config`) and expects each guest partition
/// that runs `/bin/linux-tests AREA...` to print exactly its areas' expected files.
fn linux_tests(scenario: &str, config: &str) {
    let system = xtask::check_config::load(&xtask::workspace_root().join(config))
        .unwrap_or_else(|e| panic!("{e:#}"));
    let runs: Vec<(String, Vec<String>)> = system
        .partitions
        .iter()
        .filter_map(|p| {
            let init = &p.guest.as_ref()?.init;
            (init.first()? == "/bin/linux-tests").then(|| (p.name.clone(), init[1..].to_vec()))
        })
        .collect();
    assert!(!runs.is_empty(), "{config} runs no linux-tests");
    let o = boot(scenario);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the last guest's init ends the run",
    );
    for (partition, areas) in &runs {
        let mut expected = Vec::new();
        for area in areas {
            expected.extend(xtask::linux::expected(area).unwrap_or_else(|e| panic!("{e:#}")));
        }
        let got = guest_stdout(&o, partition);
        let diff = xtask::linux::differences(&expected, &got);
        check(
            &o,
            diff.is_empty(),
            &format!(
                "{partition} ({areas:?}) printed other lines:\n{}",
                diff.join("\n")
            ),
        );
        check(
            &o,
            o.line(&format!("[{partition}] guest: init exited with status 0"))
                .is_some(),
            &format!("{partition}: linux-tests did not exit with status 0"),
        );
    }
}
