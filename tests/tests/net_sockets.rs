//! Unmodified busybox networking applets in the paravirtualized guest (configuration
//! `tests/configs/net_sockets.toml`, script `tests/configs/guest/net.sh`): `nc` both
//! ways, `httpd` with a CGI script and `wget`, a refused connection, `ifconfig` and
//! `route -n`; every line the script prints, in order.

use scenarios::{boot, check, guest_stdout, partition_lines};

/// What the script prints, line by line.
const EXPECTED: &[&str] = &[
    "nc server exit 0",
    "hello over tcp",
    "from the server",
    "<h1>static page</h1>",
    "cgi says x=42",
    "<h1>static page</h1>",
    "wget of a missing page 1",
    "nc to a closed port 1",
    "inet addr:127.0.0.1  Mask:255.0.0.0",
    "UP LOOPBACK RUNNING  MTU:65536",
    "HWaddr 52:54:00:12:34:56",
    "inet addr:10.0.2.15  Bcast:10.0.2.255  Mask:255.255.255.0",
    "UP BROADCAST RUNNING MULTICAST  MTU:1500",
    "eth0 received frames",
    "eth0 sent frames",
    // busybox lists the interfaces it knows from /proc/net/dev last-first.
    "eth0",
    "lo",
    "Kernel IP routing table",
    "Destination     Gateway         Genmask         Flags Metric Ref    Use Iface",
    "0.0.0.0         10.0.2.2        0.0.0.0         UG    0      0        0 eth0",
    "10.0.2.0        0.0.0.0         255.255.255.0   U     0      0        0 eth0",
    "4",
    "done",
];

#[test]
fn net_sockets() {
    let o = boot("net_sockets");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let lines = partition_lines(&o, "net", "");
    let printed = guest_stdout(&o, "net");
    check(
        &o,
        printed == EXPECTED,
        &format!("printed {printed:#?}, expected {EXPECTED:#?}"),
    );
    let unsupported: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("unsupported system call"))
        .collect();
    check(&o, unsupported.is_empty(), &format!("{unsupported:?}"));
    check(
        &o,
        lines
            .iter()
            .any(|l| l == "guest: init exited with status 0"),
        "the script did not exit with status 0",
    );
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the guest's init ends the run",
    );
}
