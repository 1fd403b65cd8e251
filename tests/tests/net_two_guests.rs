//! Two guests on one Ethernet segment of queuing ports (configuration
//! `tests/configs/net_two_guests.toml`): httpd on guest `one`, wget on guest `two`.

use scenarios::{boot, check, guest_stdout};

/// What guest `two` prints, line by line.
const EXPECTED: &[&str] = &[
    "<h1>served by guest one</h1>",
    "cgi on guest one says from=two",
    "<h1>served by guest one</h1>",
    "20 more requests",
    "eth0 received frames",
    "done",
];

#[test]
fn net_two_guests() {
    let o = boot("net_two_guests");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        guest_stdout(&o, "one") == ["serving"],
        &format!("guest one printed {:?}", guest_stdout(&o, "one")),
    );
    let two = guest_stdout(&o, "two");
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
