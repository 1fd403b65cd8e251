//! Two guests on one Ethernet segment of queuing ports (configuration
//! `tests/configs/net_two_guests.toml`): httpd on guest `one`, wget on guest `two`.

use scenarios::{boot, check};

/// What guest `two` prints, line by line.
const EXPECTED: &[&str] = &[
    "<h1>served by guest one</h1>",
    "cgi on guest one says from=two",
    "<h1>served by guest one</h1>",
    "20 more requests",
    "eth0 received frames",
    "done",
];

/// The stdout lines of guest `partition`.
fn printed(o: &xtask::qemu::Outcome, partition: &str) -> Vec<String> {
    let prefix = format!("[{partition}] guest: process ");
    o.lines
        .iter()
        .filter_map(|l| l.split_once(&prefix).map(|(_, text)| text))
        .filter_map(|text| text.split_once(" stdout: ").map(|(_, t)| t.to_string()))
        .collect()
}

#[test]
fn net_two_guests() {
    let o = boot("net_two_guests");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        printed(&o, "one") == ["serving"],
        &format!("guest one printed {:?}", printed(&o, "one")),
    );
    let two = printed(&o, "two");
    check(
        &o,
        two == EXPECTED,
        &format!("guest two printed {two:#?}, expected {EXPECTED:#?}"),
    );
    check(
        &o,
        o.line("[two] guest: init exited with status 0").is_some(),
        "guest two's script did not exit with status 0",
    );
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): guest two's init ends the run",
    );
}
