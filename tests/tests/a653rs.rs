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

/// a653rs-linux's checks: no ERROR, no panic in the examples' partitions.
fn no_error_no_panic(o: &Outcome, partitions: &[&str]) {
    for p in partitions {
        for line in lines_of(o, p) {
            check(
                o,
                !line.contains("ERROR") && !line.contains("panic"),
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
