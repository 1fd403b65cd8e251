//! The boot property's host half: random valid descriptions (`config::generate`) are
//! accepted, encode to a blob the no_std decoder accepts, and decode to the same system; the
//! generated descriptions the QEMU scenarios `generated_boot_*` boot are what the generator
//! makes of their seeds.

mod common;
use common::*;
use config::{System, binary, decode, generate};
use std::path::PathBuf;

/// Seeds tried; each is one description.
const CASES: u64 = 2_000;
/// The image every generated partition runs (the heartbeat program of the scenarios).
const IMAGE: &str = "test-partition";

#[test]
fn generated_descriptions_are_accepted_and_round_trip() {
    let mut refused = Vec::new();
    let (mut partitions, mut windows, mut channels) = (0, 0, 0);
    for seed in 0..CASES {
        let text = generate::system(seed, IMAGE);
        let system = match config::load("generated.toml", &text, &any_image) {
            Ok(system) => system,
            Err(diags) => {
                refused.push((seed, diags));
                continue;
            }
        };
        partitions += system.partitions.len();
        windows += system
            .schedules
            .iter()
            .map(|s| s.windows.len())
            .sum::<usize>();
        channels += system.channels.len();
        let blob = binary::encode(&system);
        let view = decode(&blob)
            .unwrap_or_else(|e| panic!("seed {seed}: the decoder refuses the blob: {e}\n{text}"));
        assert_eq!(System::from_view(&view), system, "seed {seed}:\n{text}");
    }
    println!(
        "generated descriptions: {CASES}, refused by validation: {} ({partitions} partitions, {windows} windows, {channels} channels accepted)",
        refused.len()
    );
    for (seed, diags) in refused.iter().take(3) {
        let text = generate::system(*seed, IMAGE);
        let shown: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
        println!("seed {seed} refused:\n{}\n{text}", shown.join("\n"));
    }
    // The generator means to make valid text only: a refusal is a bug in it or in the
    // validator, and more than 1 in 100 would leave the property mostly untested.
    assert!(
        refused.len() as u64 * 100 <= CASES,
        "{} of {CASES} generated descriptions refused",
        refused.len()
    );
}

#[test]
fn the_generator_is_deterministic_and_varied() {
    assert_eq!(generate::system(7, IMAGE), generate::system(7, IMAGE));
    assert_ne!(generate::system(7, IMAGE), generate::system(8, IMAGE));
    // Over a few hundred seeds every part of the format shows up.
    let texts: Vec<String> = (0..300).map(|s| generate::system(s, IMAGE)).collect();
    for needle in [
        "time = \"background\"",
        "preempts_windows = true",
        "io_ports = [",
        "irqs = [",
        "shared = {",
        "kind = \"queuing\"",
        "kind = \"sampling\"",
        "refresh = ",
        "[health]",
        "health.",
        "major_frame = \"3600s\"",
        "name = \"s3\"",
        "[partitions.p14]",
    ] {
        assert!(
            texts.iter().any(|t| t.contains(needle)),
            "no generated description has {needle:?}"
        );
    }
}

/// The generated descriptions the QEMU scenarios boot: `tests/configs/generated_<seed>.toml`.
fn committed() -> Vec<(u64, PathBuf)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/configs");
    let mut found = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if let Some(seed) = name
            .strip_prefix("generated_")
            .and_then(|n| n.strip_suffix(".toml"))
        {
            found.push((seed.parse().expect("generated_<seed>.toml"), path));
        }
    }
    found
}

/// The committed text for `seed`: a header naming the seed, then the generator's output.
fn committed_text(seed: u64) -> String {
    format!(
        "# Scenario generated_boot_{seed} (tests/tests/syssw.rs): config::generate::system({seed}, \"{IMAGE}\").\n\
         # Do not edit: `cargo test -p warden-config` checks this file against the generator;\n\
         # WARDEN_REGENERATE=1 rewrites it.\n{}",
        generate::system(seed, IMAGE)
    )
}

#[test]
fn committed_generated_descriptions_match_the_generator() {
    let files = committed();
    assert!(files.len() >= 2, "no tests/configs/generated_<seed>.toml");
    let rewrite = std::env::var_os("WARDEN_REGENERATE").is_some();
    for (seed, path) in files {
        let want = committed_text(seed);
        if rewrite {
            std::fs::write(&path, &want).unwrap();
        }
        let have = std::fs::read_to_string(&path).unwrap();
        assert!(
            have == want,
            "{} differs from the generator's description for seed {seed}: run with WARDEN_REGENERATE=1",
            path.display()
        );
        load_ok(&have);
    }
}
