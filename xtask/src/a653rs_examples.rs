//! DLR's a653rs-linux example partitions built for Warden without editing their sources
//! (scenarios `a653rs_examples_*`, `tests/tests/a653rs.rs`).
//!
//! Their code is never part of this repository: it is read from `$A653RS_LINUX` (a checkout
//! of github.com/DLR-FT/a653rs-linux), else from `target/a653rs-linux`. The crates it
//! publishes on crates.io (a653rs-linux, a653rs-linux-core 0.2.2) hold the libraries, not
//! the examples, so there is nothing to fetch from there; without a checkout the scenarios
//! say how to get one and skip.
//!
//! For each example program a crate is generated under `target/a653rs-examples/`:
//! `src/upstream.rs` is their `main.rs` after [`patch`] (the diff is written beside it as
//! `upstream.diff` and shown by the test), `src/main.rs` is ours: `#![no_std]`, `alloc`'s
//! macros, `a653rs-compat` standing in for `std`, the runtime's entry, then their `main`.
//! Their YAML becomes the scenario's system through `cargo xtask import-a653rs`'s
//! [`crate::a653rs::convert`], with the renames Warden's 15-byte names need and the refresh
//! periods their programs declare (`#[sampling_in(... refresh_period = ...)]`).

use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How to get the sources.
pub const HOW_TO_GET: &str = "get them with: git clone https://github.com/DLR-FT/a653rs-linux target/a653rs-linux (or point A653RS_LINUX at a checkout)";

/// An example: its directory under `examples/`, its YAML, its programs (directories with a
/// `Cargo.toml` and `src/main.rs`), the partition renames Warden's names need, what is
/// left out of its YAML before the import (the text, and why), and the refresh periods
/// (`PARTITION.PORT`, duration) its code passes to CREATE_SAMPLING_PORT where no
/// `#[sampling_in]` declares them.
pub struct Example {
    pub name: &'static str,
    pub yaml: &'static str,
    pub programs: &'static [&'static str],
    pub renames: &'static [(&'static str, &'static str)],
    pub yaml_cuts: &'static [(&'static str, &'static str)],
    pub refreshes: &'static [(&'static str, &'static str)],
}

/// hello_part's partition Bar has a UDP socket in its YAML that its program never opens;
/// a partition reaches the network only through the NIC partition, so the importer refuses
/// sockets, and this one is left out.
const UNUSED_SOCKET: (&str, &str) = (
    "    sockets:\n      - type: udp\n        address: 127.0.0.1:34256\n",
    "partition Bar's UDP socket, which the program never opens (POSIX sockets have no equivalent: a partition reaches the network through the NIC partition)",
);

/// The examples that run on Warden (what does not, and why: docs/apex-conformance.md).
pub const EXAMPLES: &[Example] = &[
    Example {
        name: "ping",
        yaml: "ping/ping.yaml",
        programs: &["ping/client", "ping/server"],
        renames: &[],
        yaml_cuts: &[],
        refreshes: &[],
    },
    Example {
        name: "ping_queue",
        yaml: "ping_queue/ping_queue.yaml",
        programs: &["ping_queue/client", "ping_queue/server"],
        renames: &[
            ("ping_queue_client", "pq_client"),
            ("ping_queue_server", "pq_server"),
        ],
        yaml_cuts: &[],
        refreshes: &[],
    },
    // 10 KB sampling messages (in parts: longer than one IPC message), 100 KB stacks,
    // `std::thread::sleep`, `humantime`, `String`, `format!`, postcard.
    Example {
        name: "hello_part",
        yaml: "hello_part/hello_part.yaml",
        programs: &["hello_part"],
        renames: &[],
        yaml_cuts: &[UNUSED_SOCKET],
        refreshes: &[],
    },
    Example {
        name: "hello_part_no_macros",
        yaml: "hello_part_no_macros/hello_part_no_macros.yaml",
        programs: &["hello_part_no_macros"],
        renames: &[],
        yaml_cuts: &[UNUSED_SOCKET],
        // `create_sampling_port_destination(port_name, 10_000, Duration::from_secs(1_000))`
        refreshes: &[("Bar.Hello", "1000s")],
    },
    Example {
        name: "fuel_tank",
        yaml: "fuel_tank/fuel_tank.yaml",
        programs: &["fuel_tank/controller", "fuel_tank/simulation"],
        renames: &[
            ("fuel_tank_simulation", "ft_simulation"),
            ("fuel_tank_controller", "ft_controller"),
        ],
        yaml_cuts: &[],
        refreshes: &[],
    },
];

/// The examples that neither run nor build here, and why.
pub const NOT_PORTED: &[(&str, &str)] = &[
    (
        "dev_random",
        "it reads /dev/random through std::fs and a mount: a partition has no file system",
    ),
    (
        "redirect_stdio",
        "it replaces stdin/stdout/stderr with mounted files (std::fs, nix's dup2): no file system, no file descriptors",
    ),
];

/// The a653rs-linux checkout: `$A653RS_LINUX`, else `target/a653rs-linux`, if it has the
/// examples.
pub fn sources() -> Option<PathBuf> {
    let candidates = [
        std::env::var_os("A653RS_LINUX")
            .filter(|v| !v.is_empty())
            .map(PathBuf::from),
        Some(crate::target_dir().join("a653rs-linux")),
    ];
    candidates
        .into_iter()
        .flatten()
        .find(|root| root.join("examples").join("ping").is_dir())
}

/// Where the generated crates, images and systems go.
pub fn work_dir() -> PathBuf {
    crate::target_dir().join("a653rs-examples")
}

/// One textual change of [`patch`]: every occurrence of `from` becomes `to`; it must occur.
struct Rewrite {
    from: &'static str,
    to: &'static str,
}

/// The glue a653rs-linux programs have and Warden's differs in, as literal rewrites.
const REWRITES: &[Rewrite] = &[
    // The hypervisor type the partition macro (or their alias) names.
    Rewrite {
        from: "a653rs_linux::partition::ApexLinuxPartition",
        to: "apex::Warden",
    },
    // The logger glue.
    Rewrite {
        from: "use a653rs_linux::partition::ApexLogger;",
        to: "use a653rs_compat::logger::ApexLogger;",
    },
    // Their `main` is called by ours (the runtime's entry), so it must be visible.
    Rewrite {
        from: "\nfn main() {",
        to: "\npub fn main() {",
    },
];

/// What each module of theirs gets first: the names std's prelude would give it.
const PRELUDE: &str = "#[allow(unused_imports)] use a653rs_compat::prelude::*;";

/// Their `main.rs` as built for Warden, and the diff (`-`/`+` lines with their numbers).
/// An error if a rewrite finds nothing (their glue changed: the patch needs a look).
pub fn patch(source: &str) -> Result<(String, String)> {
    let mut text = source.to_string();
    for r in REWRITES {
        if !text.contains(r.from) {
            bail!(
                "the example's source has no `{}`: a653rs-linux changed, the patch needs updating",
                r.from.trim()
            );
        }
        text = text.replace(r.from, r.to);
    }
    // The prelude goes after the leading inner doc comment and into each inline module.
    let mut out = Vec::new();
    let mut placed_top = false;
    for line in text.lines() {
        if !placed_top && !line.starts_with("//!") {
            out.push(PRELUDE.to_string());
            placed_top = true;
        }
        out.push(line.to_string());
        let t = line.trim();
        if t.starts_with("mod ") && t.ends_with('{') && !line.starts_with(' ') {
            out.push(format!("    {PRELUDE}"));
        }
    }
    let patched = out.join("\n") + "\n";
    Ok((patched.clone(), line_diff(source, &patched)))
}

/// A line diff of `old` to `new` where `new` only changes and inserts lines: each changed
/// line as `-N old` / `+M new`, each inserted one as `+M new`.
fn line_diff(old: &str, new: &str) -> String {
    let old: Vec<&str> = old.lines().collect();
    let new: Vec<&str> = new.lines().collect();
    let mut diff = String::new();
    let (mut i, mut j) = (0, 0);
    while j < new.len() {
        if i < old.len() && old[i] == new[j] {
            i += 1;
        } else if new[j].trim_start().starts_with(PRELUDE) {
            let _ = writeln!(diff, "+{} {}", j + 1, new[j]);
        } else {
            if i < old.len() {
                let _ = writeln!(diff, "-{} {}", i + 1, old[i]);
            }
            let _ = writeln!(diff, "+{} {}", j + 1, new[j]);
            i += 1;
        }
        j += 1;
    }
    diff
}

/// The refresh periods their programs declare: (`port`, `duration`) of each
/// `#[sampling_in(name = "port", ..., refresh_period = "duration")]`.
pub fn declared_refreshes(source: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for attr in source.split("#[sampling_in(").skip(1) {
        let attr = attr.split(")]").next().unwrap_or("");
        let value = |key: &str| {
            let rest = attr.split(&format!("{key} = \"")).nth(1)?;
            Some(rest.split('"').next()?.to_string())
        };
        if let (Some(port), Some(period)) = (value("name"), value("refresh_period")) {
            out.push((port, period));
        }
    }
    out
}

/// The package name of a program (their `Cargo.toml`'s, `_` as `-`): the image name the
/// importer gives a partition whose YAML `image` is that program.
fn package_name(manifest: &str) -> Option<String> {
    manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("name = \""))
        .and_then(|rest| rest.split('"').next())
        .map(|n| n.replace('_', "-"))
}

/// The generated `main.rs` around their patched source.
fn wrapper(package: &str) -> String {
    format!(
        "//! Generated by xtask (xtask/src/a653rs_examples.rs): the a653rs-linux example program
//! `{package}` built for Warden. `upstream.rs` is their main.rs, patched as upstream.diff shows.
#![no_std]
#![no_main]

#[allow(unused_imports)]
#[macro_use]
extern crate alloc;
extern crate a653rs_compat as std;

#[path = \"upstream.rs\"]
#[allow(clippy::all)]
mod upstream;

fn entry() {{
    a653rs_compat::start();
    upstream::main();
}}

apex::partition_entry!(entry);
"
    )
}

/// Generates the crate of each program of `example` from the checkout `root`, builds them
/// and imports the YAML; returns the system description's path.
pub fn prepare(root: &Path, example: &Example) -> Result<PathBuf> {
    let work = work_dir();
    let examples = root.join("examples");
    let programs = generate_and_build(root, example.programs)?;

    // The system: their YAML through the importer.
    let yaml_path = examples.join(example.yaml);
    let mut yaml = std::fs::read_to_string(&yaml_path)
        .with_context(|| format!("cannot read {}", yaml_path.display()))?;
    for (cut, why) in example.yaml_cuts {
        if !yaml.contains(cut) {
            bail!(
                "{} has no {cut:?} any more: a653rs-linux changed, the cut ({why}) needs a look",
                yaml_path.display()
            );
        }
        yaml = yaml.replace(cut, "");
    }
    let renames: Vec<(String, String)> = example
        .renames
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    let mut refreshes = refreshes_by_partition(&yaml, &renames, &programs);
    refreshes.extend(
        example
            .refreshes
            .iter()
            .map(|(port, period)| (port.to_string(), period.to_string())),
    );
    let toml = crate::a653rs::convert(
        &yaml_path.display().to_string(),
        &yaml,
        &renames,
        &refreshes,
    )
    .map_err(|problems| anyhow::anyhow!("{}", problems.join("\n")))?;
    let system = work.join(format!("{}.toml", example.name));
    std::fs::write(&system, toml)?;
    Ok(system)
}

/// The extra dependency lines of a program whose manifest (`theirs`) names these crates:
/// their no_std forms, or ours.
fn extra_dependencies(theirs: &str, path: &dyn Fn(&str) -> String) -> String {
    let mut out = String::new();
    let names = |dep: &str| theirs.lines().any(|l| l.trim_start().starts_with(dep));
    if names("a653rs-postcard") {
        out.push_str("a653rs-postcard = { version = \"0.4\", default-features = false, features = [\"alloc\"] }\n");
    }
    if names("serde") {
        out.push_str("serde = { version = \"1\", default-features = false, features = [\"derive\", \"alloc\"] }\n");
    }
    if names("humantime") {
        let _ = writeln!(
            out,
            "humantime = {{ path = \"{}\", package = \"humantime-alloc\" }}",
            path("partitions/a653rs-compat/humantime")
        );
    }
    if names("once_cell") {
        let _ = writeln!(
            out,
            "once_cell = {{ path = \"{}\", package = \"once-cell-spin\" }}",
            path("partitions/a653rs-compat/once_cell")
        );
    }
    out
}

/// Generates and builds the crates of `dirs` (program directories under `examples/`);
/// returns each one's package (image) name and the refresh periods it declares.
#[allow(clippy::type_complexity)]
fn generate_and_build(root: &Path, dirs: &[&str]) -> Result<Vec<(String, Vec<(String, String)>)>> {
    let repo = crate::workspace_root();
    let work = work_dir();
    let examples = root.join("examples");
    let mut members = Vec::new();
    // (partition image name, declared refreshes)
    let mut programs = Vec::new();
    for program in dirs {
        let dir = examples.join(program);
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml"))
            .with_context(|| format!("cannot read {}/Cargo.toml", dir.display()))?;
        let package = package_name(&manifest)
            .with_context(|| format!("{}/Cargo.toml names no package", dir.display()))?;
        let main = dir.join("src").join("main.rs");
        let source = std::fs::read_to_string(&main)
            .with_context(|| format!("cannot read {}", main.display()))?;
        let (patched, diff) = patch(&source).with_context(|| main.display().to_string())?;
        let out = work.join(&package);
        std::fs::create_dir_all(out.join("src"))?;
        let path = |p: &str| repo.join(p).display().to_string();
        std::fs::write(
            out.join("Cargo.toml"),
            format!(
                "# Generated by xtask (xtask/src/a653rs_examples.rs) from {}.
[package]
name = \"{package}\"
version = \"0.1.0\"
edition = \"2021\"
build = \"{}\"

[[bin]]
name = \"{package}\"
path = \"src/main.rs\"
test = false
bench = false

[dependencies]
a653rs = {{ version = \"0.6.1\", default-features = false, features = [\"bindings\", \"macros\"] }}
apex = {{ path = \"{}\" }}
a653rs-compat = {{ path = \"{}\" }}
log = {{ version = \"0.4\", default-features = false }}
{}",
                dir.display(),
                path("user/link.rs"),
                path("partitions/apex"),
                path("partitions/a653rs-compat"),
                extra_dependencies(&manifest, &path),
            ),
        )?;
        std::fs::write(out.join("src").join("upstream.rs"), &patched)?;
        std::fs::write(out.join("src").join("main.rs"), wrapper(&package))?;
        std::fs::write(out.join("upstream.diff"), &diff)?;
        members.push(package.clone());
        programs.push((package, declared_refreshes(&source)));
    }
    write_workspace(&work)?;
    build(&work, &members)?;
    Ok(programs)
}

/// `cargo xtask a653rs-examples`: builds every example program that can be built for
/// Warden, imports the YAML of those that run, and reports what ports (exit 0; "skipped"
/// without a checkout).
pub fn run() -> Result<bool> {
    let Some(root) = sources() else {
        println!("a653rs-examples: no a653rs-linux checkout ($A653RS_LINUX, target/a653rs-linux)");
        println!("a653rs-examples: {HOW_TO_GET}");
        println!("a653rs-examples: skipped");
        return Ok(true);
    };
    println!("a653rs-examples: sources {}", root.display());
    for example in EXAMPLES {
        let system = prepare(&root, example)?;
        println!(
            "a653rs-examples: {}: runs (scenario a653rs_examples_{}; system {})",
            example.name,
            example.name,
            system.display()
        );
        for (_, why) in example.yaml_cuts {
            println!(
                "a653rs-examples: {}: left out of its YAML: {why}",
                example.name
            );
        }
    }
    for (example, why) in NOT_PORTED {
        println!("a653rs-examples: {example}: not ported: {why}");
    }
    println!(
        "a653rs-examples: generated crates and their patches (upstream.diff) in {}",
        work_dir().display()
    );
    Ok(true)
}

/// `PARTITION.PORT = period` for each sampling input a program declares, by the partitions
/// whose YAML `image` is that program and whose YAML makes that port a sampling
/// destination (partitions running one program may use different ports of it).
fn refreshes_by_partition(
    yaml: &str,
    renames: &[(String, String)],
    programs: &[(String, Vec<(String, String)>)],
) -> Vec<(String, String)> {
    let destinations = crate::a653rs::sampling_destinations(yaml);
    let mut out = Vec::new();
    let mut name = None;
    for line in yaml.lines() {
        let t = line.trim().trim_start_matches("- ");
        if let Some(n) = t.strip_prefix("name: ") {
            name = Some(n.trim().to_string());
        }
        if let (Some(image), Some(partition)) = (t.strip_prefix("image: "), &name) {
            let image = Path::new(image.trim())
                .file_name()
                .map(|f| f.to_string_lossy().replace('_', "-"))
                .unwrap_or_default();
            let renamed = renames
                .iter()
                .find(|(old, _)| old == partition)
                .map_or(partition.clone(), |(_, new)| new.clone());
            for (_, declared) in programs.iter().filter(|(p, _)| *p == image) {
                for (port, period) in declared {
                    if destinations.contains(&format!("{partition}.{port}")) {
                        out.push((format!("{renamed}.{port}"), period.clone()));
                    }
                }
            }
        }
    }
    out
}

/// The workspace of the generated crates (every program generated so far), with the
/// `user` profile of Warden's user-mode programs and Warden's lock file as the start.
fn write_workspace(work: &Path) -> Result<()> {
    let mut members: Vec<String> = std::fs::read_dir(work)?
        .filter_map(|e| e.ok())
        .filter(|e| e.path().join("src").join("upstream.rs").is_file())
        .map(|e| format!("\"{}\"", e.file_name().to_string_lossy()))
        .collect();
    members.sort();
    std::fs::write(
        work.join("Cargo.toml"),
        format!(
            "# Generated by xtask (xtask/src/a653rs_examples.rs).
[workspace]
resolver = \"2\"
members = [{}]

[profile.user]
inherits = \"release\"
panic = \"abort\"
debug = false

[profile.release]
panic = \"abort\"
",
            members.join(", ")
        ),
    )?;
    let lock = work.join("Cargo.lock");
    if !lock.exists() {
        std::fs::copy(crate::workspace_root().join("Cargo.lock"), &lock)?;
    }
    Ok(())
}

fn build(work: &Path, packages: &[String]) -> Result<()> {
    let mut cmd =
        std::process::Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cmd.current_dir(work)
        .args(["build", "--quiet", "--profile", "user", "--target-dir"])
        .arg(work.join("target"));
    for p in packages {
        cmd.args(["-p", p]);
    }
    let status = cmd.status().context("cannot run cargo")?;
    if !status.success() {
        bail!(
            "building the a653rs-linux example programs {} failed",
            packages.join(", ")
        );
    }
    Ok(())
}

/// The built image of an example program, if it was built (by [`prepare`]).
pub fn image(name: &str) -> Option<PathBuf> {
    let path = work_dir().join("target").join("user").join(name);
    (work_dir().join(name).join("upstream.diff").is_file() && path.is_file()).then_some(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = "//! doc
use a653rs_linux::partition::ApexLogger;

fn main() {
    ApexLogger::install_logger(LevelFilter::Trace).unwrap();
}

#[partition(a653rs_linux::partition::ApexLinuxPartition)]
mod ping_server {
    #[sampling_in(name = \"ping_request\", msg_size = \"16B\", refresh_period = \"10s\")]
    struct PingRequest;
}
";

    #[test]
    fn the_patch_swaps_the_glue_and_adds_the_prelude() {
        let (patched, diff) = patch(SOURCE).unwrap();
        assert!(patched.contains("#[partition(apex::Warden)]"), "{patched}");
        assert!(patched.contains("use a653rs_compat::logger::ApexLogger;"));
        assert!(patched.contains("\npub fn main() {"));
        assert!(
            patched
                .starts_with("//! doc\n#[allow(unused_imports)] use a653rs_compat::prelude::*;\n")
        );
        assert!(patched.contains("mod ping_server {\n    #[allow(unused_imports)]"));
        assert!(diff.contains("-2 use a653rs_linux::partition::ApexLogger;\n+3 use a653rs_compat::logger::ApexLogger;"), "{diff}");
        assert!(diff.contains("+2 #[allow"), "{diff}");
        assert!(patch("fn main() {}").is_err());
    }

    #[test]
    fn refresh_periods_come_from_the_program() {
        assert_eq!(
            declared_refreshes(SOURCE),
            [("ping_request".to_string(), "10s".to_string())]
        );
        let yaml = "major_frame: 1s\npartitions:\n  - id: 1\n    name: ping_queue_server\n    duration: 10ms\n    offset: 0ms\n    period: 1s\n    image: ping_server\nchannel:\n  - !Sampling\n    msg_size: 16B\n    source:\n      partition: ping_queue_client\n      port: ping_request\n    destination:\n      - partition: ping_queue_server\n        port: ping_request\n";
        let renames = [("ping_queue_server".to_string(), "pq".to_string())];
        let programs = [("ping-server".to_string(), declared_refreshes(SOURCE))];
        assert_eq!(
            refreshes_by_partition(yaml, &renames, &programs),
            [("pq.ping_request".to_string(), "10s".to_string())]
        );
    }
}
