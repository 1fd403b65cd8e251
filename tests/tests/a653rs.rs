//! DLR's a653rs-linux example partitions on Warden (`xtask/src/a653rs_examples.rs`): their
//! sources, untouched but for the glue patch each test prints, their YAML imported by
//! `cargo xtask import-a653rs`. "The same behaviour as on Linux" is what a653rs-linux's own
//! CI checks of each example's log (`.github/workflows/rust.yml`): no `ERROR` and no
//! `panic`, and the example's success line; here also each program's start line.

use scenarios::{boot, check};
use xtask::a653rs_examples::{self, HOW_TO_GET};
use xtask::qemu::Outcome;

/// Whether the sources are there; if not, says how to get them (the test then passes
/// without running, as `cargo xtask test` skipped building it).
fn have_sources(scenario: &str) -> bool {
    if a653rs_examples::sources().is_some() {
        return true;
    }
    println!("{scenario}: skipped, no a653rs-linux checkout; {HOW_TO_GET}");
    false
}

/// Prints the patch of each program (what was changed in their source) and checks that it
/// touches only the glue: each removed line names a653rs-linux's hypervisor or logger or is
/// their `fn main`, each added line is its Warden counterpart or the prelude import.
fn show_patches(programs: &[&str]) {
    for p in programs {
        let path = a653rs_examples::work_dir().join(p).join("upstream.diff");
        let diff = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        println!("patch of {p}/src/main.rs:\n{diff}");
        for line in diff.lines() {
            let glue = if line.starts_with('-') {
                line.contains("a653rs_linux::partition::") || line.ends_with(" fn main() {")
            } else {
                line.contains("apex::Warden")
                    || line.contains("a653rs_compat::")
                    || line.ends_with(" pub fn main() {")
            };
            assert!(glue, "{p}: the patch changes more than the glue: {line}");
        }
    }
}

/// The log lines of `partition` (their text after the `[partition] ` prefix).
fn lines_of<'a>(o: &'a Outcome, partition: &str) -> Vec<&'a str> {
    let prefix = format!("[{partition}] ");
    o.lines
        .iter()
        .filter_map(|l| l.split_once(&prefix).map(|(_, rest)| rest))
        .collect()
}

/// a653rs-linux's checks: no ERROR, no panic in the examples' partitions (and, where its
/// CI asks that too, no WARN).
fn no_error_no_panic(o: &Outcome, partitions: &[&str]) {
    no_line_with(o, partitions, &["ERROR", "panic"]);
}

fn no_line_with(o: &Outcome, partitions: &[&str], words: &[&str]) {
    for p in partitions {
        for line in lines_of(o, p) {
            check(
                o,
                !words.iter().any(|w| line.contains(w)),
                &format!("{p}: {line}"),
            );
        }
    }
}

fn has(o: &Outcome, partition: &str, text: &str) {
    check(
        o,
        lines_of(o, partition).iter().any(|l| l.contains(text)),
        &format!("{partition}: no line with {text:?}"),
    );
}

#[test]
fn a653rs_examples_ping() {
    if !have_sources("a653rs_examples_ping") {
        return;
    }
    show_patches(&["ping-client", "ping-server"]);
    let o = boot("a653rs_examples_ping");
    no_error_no_panic(&o, &["ping_client", "ping_server"]);
    has(
        &o,
        "ping_client",
        "INFO  started periodic_ping_client process",
    );
    has(&o, "ping_client", "INFO  sending a request");
    has(&o, "ping_server", "INFO  started ping_server process");
    has(&o, "ping_server", "INFO  forwarding request as response");
    // The line a653rs-linux's CI looks for, and its multi-line report.
    has(&o, "ping_client", "INFO  received valid response:");
    has(&o, "ping_client", "INFO  \tround-trip ");
}

#[test]
fn a653rs_examples_ping_queue() {
    if !have_sources("a653rs_examples_ping_queue") {
        return;
    }
    show_patches(&["ping-queue-client", "ping-queue-server"]);
    let o = boot("a653rs_examples_ping_queue");
    no_error_no_panic(&o, &["pq_client", "pq_server"]);
    has(
        &o,
        "pq_client",
        "INFO  started periodic_ping_queue_client process",
    );
    has(&o, "pq_client", "INFO  Sending request took ");
    has(&o, "pq_server", "INFO  started ping_queue_server process");
    has(
        &o,
        "pq_server",
        "INFO  Forwarding request with timestamp as response",
    );
    // The line a653rs-linux's CI looks for.
    has(&o, "pq_client", "INFO  Received valid response: RTT=");
}

/// hello_part, with and without the partition macro: Foo sends a postcard-encoded
/// `CustomMessage` through a 10 KB sampling port (longer than one IPC message, so it goes
/// in parts), Bar decodes it; both processes of each partition run on 100 KB stacks.
fn hello_part(example: &str, program: &str) {
    let scenario = format!("a653rs_examples_{example}");
    if !have_sources(&scenario) {
        return;
    }
    show_patches(&[program]);
    let cuts = a653rs_examples::EXAMPLES
        .iter()
        .find(|e| e.name == example)
        .map_or(&[][..], |e| e.yaml_cuts);
    for (text, why) in cuts {
        println!("left out of {example}.yaml ({why}):\n{text}");
    }
    let o = boot(&scenario);
    no_line_with(&o, &["Foo", "Bar"], &["ERROR", "panic", "WARN"]);
    for p in ["Foo", "Bar"] {
        has(&o, p, "INFO  Start Aperiodic");
        has(&o, p, ": AP MSG ");
        has(&o, p, ": P MSG 5");
    }
    // The line a653rs-linux's CI looks for: the whole message arrived and decoded.
    has(
        &o,
        "Bar",
        "INFO  Received via Sampling Port: CustomMessage { msg: \"Sampling MSG 1\"",
    );
}

#[test]
fn a653rs_examples_hello_part() {
    hello_part("hello_part", "hello-part");
}

#[test]
fn a653rs_examples_hello_part_no_macros() {
    hello_part("hello_part_no_macros", "hello-part-no-macros");
}

#[test]
fn a653rs_examples_fuel_tank() {
    if !have_sources("a653rs_examples_fuel_tank") {
        return;
    }
    show_patches(&["fuel-tank-controller", "fuel-tank-simulation"]);
    let o = boot("a653rs_examples_fuel_tank");
    // a653rs-linux's CI: no ERROR, panic or WARN.
    no_line_with(
        &o,
        &["ft_simulation", "ft_controller"],
        &["ERROR", "panic", "WARN"],
    );
    has(&o, "ft_simulation", "INFO  Start Aperiodic");
    for p in ["ft_simulation", "ft_controller"] {
        check(
            &o,
            o.lines
                .iter()
                .any(|l| l.contains(&format!("syssw: partition {p}: NORMAL"))),
            &format!("{p} never reached NORMAL mode"),
        );
    }
    check(
        &o,
        !o.lines.iter().any(|l| l.starts_with("health:")),
        "a health-monitor event",
    );
}
