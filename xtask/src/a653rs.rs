//! `cargo xtask import-a653rs FILE.yaml`: a system description of DLR's a653rs-linux
//! hypervisor (its YAML: `major_frame`, `partitions` with `id`, `name`, `duration`,
//! `offset`, `period`, `image`, and `channel` with `!Sampling`/`!Queuing` entries) as a
//! Warden system description (TOML), checked by Warden's validator before it is written.
//!
//! The mapping: each partition gets the windows `offset + k·period` (`duration` long) for
//! every period in the major frame, as a653rs-linux schedules them; an APEX partition's
//! budget (memory, kernel memory, priorities, abilities) from [`PARTITION_DEFAULTS`];
//! each channel its source and destination ports with the channel's `msg_size` (and, for
//! queuing, `msg_num` as the depth); a sampling input's refresh period is the one given
//! with `--refresh PARTITION.PORT=DURATION`, else the destination partition's period (the
//! YAML does not carry it: a653rs-linux takes it from the program, and Warden's
//! CREATE_SAMPLING_PORT wants the configured one). What has no equivalent is an error naming its place: POSIX `sockets`,
//! `mounts`, health tables, messages above Warden's 64 KiB, names Warden does not take.

use anyhow::{Context, Result, bail};
use serde::Deserialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What an imported APEX partition gets besides its windows and ports.
pub const PARTITION_DEFAULTS: &str = "memory = \"4MiB\"\nkernel_memory = \"512KiB\"\nmax_priority = 100\nabilities = [\"debug_log\", \"create_thread\"]\n";

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    major_frame: String,
    #[serde(default)]
    cgroup: Option<String>,
    partitions: Vec<Partition>,
    #[serde(default)]
    channel: Vec<Channel>,
    #[serde(default)]
    hm_init_table: Option<serde_yaml_ng::Value>,
    #[serde(default)]
    hm_run_table: Option<serde_yaml_ng::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Partition {
    id: i64,
    name: String,
    duration: String,
    offset: String,
    period: String,
    image: PathBuf,
    #[serde(default)]
    hm_table: Option<serde_yaml_ng::Value>,
    #[serde(default)]
    mounts: Vec<serde_yaml_ng::Value>,
    #[serde(default)]
    sockets: Vec<serde_yaml_ng::Value>,
}

#[derive(Deserialize)]
enum Channel {
    Sampling(SamplingChannel),
    Queuing(QueuingChannel),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct End {
    partition: String,
    port: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SamplingChannel {
    #[serde(default)]
    name: Option<String>,
    msg_size: String,
    source: End,
    destination: Vec<End>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct QueuingChannel {
    #[serde(default)]
    name: Option<String>,
    msg_size: String,
    msg_num: usize,
    source: End,
    destination: End,
}

/// A problem with its place in the YAML.
struct Problem {
    line: usize,
    column: usize,
    message: String,
}

/// Where `needle` (a `key: value` as written) first appears at or after line `from`: the
/// place a problem with that value is reported at.
fn locate(source: &str, needle: &str, from: usize) -> (usize, usize) {
    for (i, line) in source.lines().enumerate().skip(from.saturating_sub(1)) {
        if let Some(col) = line.find(needle) {
            return (i + 1, col + 1);
        }
    }
    (from.max(1), 1)
}

/// A humantime duration ("1s", "30ms", "500us") in nanoseconds.
fn nanos(text: &str) -> Option<u64> {
    let text = text.trim();
    let split = text.find(|c: char| !c.is_ascii_digit())?;
    let (number, unit) = text.split_at(split);
    let n: u64 = number.parse().ok()?;
    let scale = match unit.trim() {
        "ns" => 1,
        "us" | "µs" => 1_000,
        "ms" => 1_000_000,
        "s" | "sec" => 1_000_000_000,
        "m" | "min" => 60_000_000_000,
        _ => return None,
    };
    n.checked_mul(scale)
}

/// A byte size as a653rs-linux writes it ("16B", "10KB" = 10,000, "1KiB" = 1,024).
fn bytes(text: &str) -> Option<u64> {
    let text = text.trim();
    let split = text
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    let n: u64 = number.parse().ok()?;
    let scale = match unit.trim() {
        "" | "B" => 1,
        "KB" | "kB" => 1_000,
        "KiB" => 1_024,
        "MB" => 1_000_000,
        "MiB" => 1 << 20,
        _ => return None,
    };
    n.checked_mul(scale)
}

/// Our duration text for `ns`.
fn duration(ns: u64) -> String {
    let d = Duration::from_nanos(ns);
    if ns.is_multiple_of(1_000_000) {
        format!("{}ms", d.as_millis())
    } else if ns.is_multiple_of(1_000) {
        format!("{}us", d.as_micros())
    } else {
        format!("{ns}ns")
    }
}

/// The largest port message Warden takes.
const MAX_MESSAGE: u64 = config::model::MAX_MESSAGE_SIZE as u64;

/// The sampling destination ports of the YAML `source`, as `partition.port` (before any
/// rename); empty if it does not parse (the conversion then says why).
pub fn sampling_destinations(source: &str) -> Vec<String> {
    let Ok(config) = serde_yaml_ng::from_str::<Config>(source) else {
        return Vec::new();
    };
    config
        .channel
        .iter()
        .filter_map(|c| match c {
            Channel::Sampling(s) => Some(&s.destination),
            Channel::Queuing(_) => None,
        })
        .flatten()
        .map(|d| format!("{}.{}", d.partition, d.port))
        .collect()
}

/// Converts the YAML `source` (named `file` in messages) to a Warden description, with the
/// partitions renamed by `renames` (`(old, new)`: a name Warden does not take gets one it
/// does).
pub fn convert(
    file: &str,
    source: &str,
    renames: &[(String, String)],
    refreshes: &[(String, String)],
) -> Result<String, Vec<String>> {
    let at = |p: Problem| format!("{file}:{}:{}: {}", p.line, p.column, p.message);
    let config: Config = serde_yaml_ng::from_str(source).map_err(|e| {
        let (line, column) = e.location().map_or((1, 1), |l| (l.line(), l.column()));
        vec![at(Problem {
            line,
            column,
            message: format!("not an a653rs-linux configuration: {e}"),
        })]
    })?;
    let mut config = config;
    let renamed = |name: &mut String| {
        if let Some((_, new)) = renames.iter().find(|(old, _)| old == name) {
            *name = new.clone();
        }
    };
    for p in &mut config.partitions {
        renamed(&mut p.name);
    }
    for c in &mut config.channel {
        match c {
            Channel::Sampling(s) => {
                renamed(&mut s.source.partition);
                s.destination
                    .iter_mut()
                    .for_each(|d| renamed(&mut d.partition));
            }
            Channel::Queuing(q) => {
                renamed(&mut q.source.partition);
                renamed(&mut q.destination.partition);
            }
        }
    }
    let mut problems = Vec::new();
    for (old, _) in renames {
        if !source.contains(&format!("name: {old}")) {
            problems.push(format!(
                "{file}: --rename {old}=...: no partition is named {old}"
            ));
        }
    }
    for (port, period) in refreshes {
        let known = config.channel.iter().any(|c| match c {
            Channel::Sampling(s) => s
                .destination
                .iter()
                .any(|d| format!("{}.{}", d.partition, d.port) == *port),
            Channel::Queuing(_) => false,
        });
        if !known {
            problems.push(format!(
                "{file}: --refresh {port}=...: no sampling destination port is named {port}"
            ));
        } else if nanos(period).is_none_or(|n| n == 0) {
            problems.push(format!(
                "{file}: --refresh {port}={period}: not a positive duration"
            ));
        }
    }
    // The line from which a problem's text is looked for (a channel's first line).
    let search_from = std::cell::Cell::new(1);
    let mut problem = |needle: &str, message: String| {
        let (line, column) = locate(source, needle, search_from.get());
        problems.push(at(Problem {
            line,
            column,
            message,
        }));
    };
    let frame = nanos(&config.major_frame);
    if frame.is_none() {
        problem(
            "major_frame",
            format!("major_frame `{}` is not a duration", config.major_frame),
        );
    }
    if config.cgroup.is_some() {
        problem("cgroup", "cgroup has no equivalent (partitions are Warden tasks, not Linux processes); remove it".into());
    }
    if config.hm_init_table.is_some() || config.hm_run_table.is_some() {
        problem(
            "hm_",
            "module health-monitor tables are not imported: write Warden's [health] table".into(),
        );
    }
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# Imported from {file} by `cargo xtask import-a653rs`.\n[system]\nmemory = \"512MiB\"\n"
    );
    let _ = writeln!(
        out,
        "[[schedules]]\nmajor_frame = \"{}\"",
        duration(frame.unwrap_or(0))
    );
    let mut windows: Vec<(u64, u64, &str)> = Vec::new();
    for p in &config.partitions {
        let needle = format!("name: {}", p.name);
        let valid_name = !p.name.is_empty()
            && p.name.len() <= 15
            && p.name.starts_with(|c: char| c.is_ascii_alphabetic())
            && p.name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !valid_name {
            problem(
                &needle,
                format!(
                    "partition name `{}`: Warden takes 1..=15 letters, digits, `_`, `-`, starting with a letter",
                    p.name
                ),
            );
        }
        if !p.sockets.is_empty() {
            problem(
                &needle,
                format!(
                    "partition {}: POSIX sockets have no equivalent (a partition reaches the network through the NIC partition)",
                    p.name
                ),
            );
        }
        if !p.mounts.is_empty() {
            problem(
                &needle,
                format!(
                    "partition {}: mounts have no equivalent (partitions have no file system)",
                    p.name
                ),
            );
        }
        if p.hm_table.is_some() {
            problem(
                &needle,
                format!(
                    "partition {}: its hm_table is not imported: write Warden's health table",
                    p.name
                ),
            );
        }
        let (Some(d), Some(o), Some(per), Some(f)) = (
            nanos(&p.duration),
            nanos(&p.offset),
            nanos(&p.period),
            frame,
        ) else {
            problem(
                &needle,
                format!(
                    "partition {}: duration, offset and period must be durations",
                    p.name
                ),
            );
            continue;
        };
        if per == 0 || f % per != 0 {
            problem(
                &needle,
                format!(
                    "partition {}: the major frame is not a whole number of periods",
                    p.name
                ),
            );
            continue;
        }
        for k in 0..f / per {
            windows.push((o + k * per, d, &p.name));
        }
    }
    windows.sort();
    for (offset, length, name) in &windows {
        let _ = writeln!(
            out,
            "\n[[schedules.windows]]\npartition = \"{name}\"\noffset = \"{}\"\nduration = \"{}\"",
            duration(*offset),
            duration(*length)
        );
    }
    // Ports by partition, from the channels.
    let mut ports: Vec<(String, String)> = Vec::new();
    let mut channels = String::new();
    let period_of = |name: &str| {
        config
            .partitions
            .iter()
            .find(|p| p.name == name)
            .and_then(|p| nanos(&p.period))
    };
    // The line each channel starts at (its `- !Sampling` / `- !Queuing`), to place problems.
    let anchors: Vec<usize> = source
        .lines()
        .enumerate()
        .filter(|(_, l)| l.trim_start().starts_with("- !"))
        .map(|(i, _)| i + 1)
        .collect();
    for (index, c) in config.channel.iter().enumerate() {
        search_from.set(anchors.get(index).copied().unwrap_or(1));
        let (kind, name, size, depth, source, destinations): (_, _, _, _, _, Vec<&End>) = match c {
            Channel::Sampling(s) => (
                "sampling",
                &s.name,
                &s.msg_size,
                None,
                &s.source,
                s.destination.iter().collect(),
            ),
            Channel::Queuing(q) => (
                "queuing",
                &q.name,
                &q.msg_size,
                Some(q.msg_num),
                &q.source,
                vec![&q.destination],
            ),
        };
        let Some(size) = bytes(size).filter(|s| (1..=MAX_MESSAGE).contains(s)) else {
            problem(
                &format!("msg_size: {size}"),
                format!(
                    "channel from {}.{}: msg_size {size} is not 1..={MAX_MESSAGE} bytes, Warden's largest port message",
                    source.partition, source.port
                ),
            );
            continue;
        };
        for end in std::iter::once(source).chain(destinations.iter().copied()) {
            if !config.partitions.iter().any(|p| p.name == end.partition) {
                problem(
                    &format!("partition: {}", end.partition),
                    format!(
                        "channel end {}.{}: no such partition",
                        end.partition, end.port
                    ),
                );
            }
        }
        let depth_text = depth.map_or(String::new(), |d| format!(", depth = {d}"));
        ports.push((source.partition.clone(), format!("ports.{} = {{ kind = \"{kind}\", direction = \"out\", size = {size}{depth_text} }}", source.port)));
        for d in &destinations {
            let given = refreshes
                .iter()
                .find(|(port, _)| *port == format!("{}.{}", d.partition, d.port))
                .and_then(|(_, period)| nanos(period));
            let refresh = if kind == "sampling" {
                format!(
                    ", refresh = \"{}\"",
                    duration(given.unwrap_or_else(|| {
                        period_of(&d.partition).unwrap_or(frame.unwrap_or(0))
                    }))
                )
            } else {
                String::new()
            };
            ports.push((d.partition.clone(), format!("ports.{} = {{ kind = \"{kind}\", direction = \"in\", size = {size}{depth_text}{refresh} }}", d.port)));
        }
        let to: Vec<String> = destinations
            .iter()
            .map(|d| format!("\"{}.{}\"", d.partition, d.port))
            .collect();
        let _ = write!(channels, "\n[[channels]]\n");
        if let Some(name) = name {
            let _ = writeln!(channels, "name = \"{name}\"");
        }
        let _ = writeln!(
            channels,
            "kind = \"{kind}\"\nfrom = \"{}.{}\"\nto = [{}]",
            source.partition,
            source.port,
            to.join(", ")
        );
    }
    for p in &config.partitions {
        let image = p
            .image
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().replace('_', "-"));
        let _ = write!(
            out,
            "\n[partitions.{}]\n# a653rs-linux partition id {}\nimage = \"{image}\"\n{PARTITION_DEFAULTS}",
            p.name, p.id
        );
        for (_, line) in ports.iter().filter(|(owner, _)| *owner == p.name) {
            let _ = writeln!(out, "{line}");
        }
    }
    out.push_str(&channels);
    if problems.is_empty() {
        Ok(out)
    } else {
        Err(problems)
    }
}

/// The command: converts `file`, validates the result (any image name accepted: the
/// images are the a653rs programs built for Warden), writes it to `output` or prints it.
pub fn run(
    file: &Path,
    output: Option<&Path>,
    renames: &[String],
    refreshes: &[String],
) -> Result<bool> {
    let pairs = |list: &[String], flag: &str, form: &str| -> Result<Vec<(String, String)>> {
        list.iter()
            .map(|r| {
                r.split_once('=')
                    .map(|(o, n)| (o.to_string(), n.to_string()))
                    .with_context(|| format!("--{flag} {r}: expected {form}"))
            })
            .collect()
    };
    let renames = pairs(renames, "rename", "OLD=NEW")?;
    let refreshes = pairs(refreshes, "refresh", "PARTITION.PORT=DURATION")?;
    let source =
        std::fs::read_to_string(file).with_context(|| format!("cannot read {}", file.display()))?;
    let name = file.display().to_string();
    let toml = match convert(&name, &source, &renames, &refreshes) {
        Ok(toml) => toml,
        Err(problems) => {
            for p in &problems {
                eprintln!("{p}");
            }
            eprintln!(
                "import-a653rs {name}: {} problem(s), nothing written",
                problems.len()
            );
            return Ok(false);
        }
    };
    let out_name = output.map_or("<imported>".to_string(), |p| p.display().to_string());
    if let Err(diagnostics) = config::load_with_warnings(&out_name, &toml, &|_| true) {
        let lines: Vec<String> = diagnostics.iter().map(|d| d.to_string()).collect();
        bail!(
            "the imported description does not validate (please report):\n{}\n{toml}",
            lines.join("\n")
        );
    }
    match output {
        Some(path) => {
            std::fs::write(path, &toml)
                .with_context(|| format!("cannot write {}", path.display()))?;
            eprintln!("import-a653rs: wrote {}", path.display());
        }
        None => print!("{toml}"),
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PING: &str = "major_frame: 1s
partitions:
  - id: 0
    name: ping_client
    duration: 30ms
    offset: 0ms
    period: 1s
    image: ping_client
  - id: 1
    name: ping_server
    duration: 30ms
    offset: 450ms
    period: 500ms
    image: ping_server
channel:
  - !Sampling
    msg_size: 16B
    source:
      partition: ping_client
      port: PingReq
    destination:
      - partition: ping_server
        port: ping_request
  - !Queuing
    msg_size: 32B
    msg_num: 4
    source:
      partition: ping_server
      port: ping_response
    destination:
      partition: ping_client
      port: PingRes
";

    #[test]
    fn a_configuration_imports_and_validates() {
        let toml = convert("ping.yaml", PING, &[], &[]).unwrap();
        let (system, _) = config::load_with_warnings("ping.toml", &toml, &|_| true).unwrap();
        assert_eq!(system.partitions.len(), 2);
        assert!(
            toml.contains("offset = \"450ms\"") && toml.contains("offset = \"950ms\""),
            "{toml}"
        );
        assert!(toml.contains("ports.ping_request = { kind = \"sampling\", direction = \"in\", size = 16, refresh = \"500ms\" }"), "{toml}");
        assert!(
            toml.contains(
                "ports.PingRes = { kind = \"queuing\", direction = \"in\", size = 32, depth = 4 }"
            ),
            "{toml}"
        );
        assert!(toml.contains("image = \"ping-client\""), "{toml}");
    }

    #[test]
    fn a_refresh_period_comes_from_the_program_when_given() {
        let given = [("ping_server.ping_request".to_string(), "10s".to_string())];
        let toml = convert("ping.yaml", PING, &[], &given).unwrap();
        assert!(toml.contains("ports.ping_request = { kind = \"sampling\", direction = \"in\", size = 16, refresh = \"10000ms\" }"), "{toml}");
        for (port, period, message) in [
            (
                "ping_server.nope",
                "10s",
                "no sampling destination port is named",
            ),
            (
                "ping_client.PingRes",
                "10s",
                "no sampling destination port is named",
            ),
            (
                "ping_server.ping_request",
                "soon",
                "not a positive duration",
            ),
        ] {
            let given = [(port.to_string(), period.to_string())];
            let problems = convert("p.yaml", PING, &[], &given).unwrap_err();
            assert!(problems[0].contains(message), "{problems:?}");
        }
    }

    #[test]
    fn long_names_import_renamed() {
        let yaml = PING.replace("ping_server", "ping_queue_server");
        assert!(convert("p.yaml", &yaml, &[], &[]).is_err());
        let renames = [("ping_queue_server".to_string(), "pq_server".to_string())];
        let toml = convert("p.yaml", &yaml, &renames, &[]).unwrap();
        assert!(
            toml.contains("[partitions.pq_server]")
                && toml.contains("to = [\"pq_server.ping_request\"]"),
            "{toml}"
        );
        let wrong = [("nobody".to_string(), "x".to_string())];
        assert!(
            convert("p.yaml", PING, &wrong, &[]).unwrap_err()[0]
                .contains("no partition is named nobody")
        );
    }

    #[test]
    fn what_has_no_equivalent_is_refused_with_its_place() {
        let cases = [
            (PING.replace("msg_size: 16B", "msg_size: 70KB"), 17, "70KB is not 1..=65536"),
            (PING.replace("name: ping_server", "name: a_name_much_too_long"), 10, "1..=15 letters"),
            (
                PING.replace("    image: ping_client\n", "    image: ping_client\n    sockets:\n      - type: udp\n        address: 127.0.0.1:34256\n"),
                4,
                "POSIX sockets",
            ),
            (PING.replace("period: 500ms", "period: 300ms"), 10, "whole number of periods"),
            (
                PING.replace("      partition: ping_client\n      port: PingReq", "      partition: nobody\n      port: PingReq"),
                19,
                "no such partition",
            ),
        ];
        for (yaml, line, message) in cases {
            let problems = convert("p.yaml", &yaml, &[], &[]).unwrap_err();
            assert!(
                problems
                    .iter()
                    .any(|p| p.starts_with(&format!("p.yaml:{line}:")) && p.contains(message)),
                "{problems:?}"
            );
        }
        let problems = convert(
            "p.yaml",
            "major_frame: 1s\npartitions:\n  - id: x\n",
            &[],
            &[],
        )
        .unwrap_err();
        assert!(
            problems[0].starts_with("p.yaml:3:") && problems[0].contains("not an a653rs-linux"),
            "{problems:?}"
        );
    }
}
