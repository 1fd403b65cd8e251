//! Validation of the IEC 61499 keys (`iec61499.*`) of a partition.

mod common;
use common::*;

/// Partition `b` with these extra lines.
fn with(lines: &str) -> String {
    doc(&[(
        "time = \"background\"",
        &format!("time = \"background\"\n{lines}"),
    )])
}

#[test]
fn an_iec61499_partition_is_valid() {
    let system = load_ok(&with(
        "iec61499.boot = \"tests/data/app.fboot\"\niec61499.types = [\"tests/data/counter.st\"]",
    ));
    let fb = system.partitions[1]
        .iec61499
        .as_ref()
        .expect("iec61499 keys");
    assert_eq!(fb.boot.name, "tests/data/app.fboot");
    assert_eq!(fb.types.len(), 1);
    assert!(system.partitions[0].iec61499.is_none());
    let system = load_ok(&with("iec61499.boot = \"tests/data/app.fboot\""));
    assert!(
        system.partitions[1]
            .iec61499
            .as_ref()
            .unwrap()
            .types
            .is_empty()
    );
}

#[test]
fn files_must_exist() {
    expect_some(
        &with("iec61499.boot = \"tests/data/nope.fboot\""),
        "\"tests/data/nope.fboot\"",
        0,
        "partitions.b.iec61499.boot",
        "no such file `tests/data/nope.fboot`",
    );
    expect_some(
        &with("iec61499.boot = \"tests/data/app.fboot\"\niec61499.types = [\"X.fbt\"]"),
        "\"X.fbt\"",
        0,
        "partitions.b.iec61499.types",
        "no such file `X.fbt`",
    );
}

#[test]
fn one_runtime_per_partition() {
    expect_some(
        &with(
            "iec61499.boot = \"tests/data/app.fboot\"\ndata.plc_image = [\"tests/data/counter.st\"]",
        ),
        "iec61499.boot",
        0,
        "partitions.b.iec61499",
        "a partition runs the IEC 61499 runtime (`iec61499`) or a `data` entry, not both",
    );
    let errors = load(&with("iec61499 = { types = [] }")).unwrap_err();
    assert!(
        errors.iter().any(|d| d.to_string().contains("boot")),
        "{errors:?}"
    );
}

#[test]
fn management_ports() {
    let ports = "ports.req = { kind = \"queuing\", direction = \"in\", size = 4096, depth = 4 }\nports.resp = { kind = \"queuing\", direction = \"out\", size = SIZE, depth = 4 }\niec61499.boot = \"tests/data/app.fboot\"\n";
    // The ports' channels are left out here, so only the iec61499 diagnostics matter.
    for access in ["monitor", "force", "download"] {
        let diags = load(&with(&format!(
            "{}iec61499.mgmt = {{ request = \"req\", response = \"resp\", access = \"{access}\" }}",
            ports.replace("SIZE", "4096")
        )))
        .unwrap_err();
        assert!(
            diags
                .iter()
                .all(|d| !d.key_path.starts_with("partitions.b.iec61499")),
            "{diags:?}"
        );
    }
    expect_some(
        &with(&format!(
            "{}iec61499.mgmt = {{ request = \"req\", response = \"resp\", access = \"force\" }}",
            ports.replace("SIZE", "256")
        )),
        "\"resp\"",
        0,
        "partitions.b.iec61499.mgmt.response",
        "`resp` must be a queuing `out` port of this partition with size = 4096",
    );
}

/// Partition `b` with frame ports `rx`/`tx` (queuing, 1514 bytes, looped back so their
/// channel is valid) and `iec61499.net = net`.
fn with_net(net: &str) -> String {
    with(&format!(
        "iec61499.boot = \"tests/data/app.fboot\"\nports.rx = {{ kind = \"queuing\", direction = \"in\", size = 1514, depth = 8 }}\nports.tx = {{ kind = \"queuing\", direction = \"out\", size = 1514, depth = 8 }}\niec61499.net = {net}"
    )) + "\n[[channels]]\nkind = \"queuing\"\nfrom = \"b.tx\"\nto = \"b.rx\"\n"
}

const NET: &str = "{ mac = \"52:54:00:12:34:58\", address = \"10.0.2.17/24\", gateway = \"10.0.2.2\", rx = \"rx\", tx = \"tx\" }";

#[test]
fn a_network_interface_with_the_management_port() {
    let system = load_ok(&with_net(NET));
    let net = system.partitions[1]
        .iec61499
        .as_ref()
        .and_then(|f| f.net.clone())
        .expect("iec61499.net");
    assert_eq!(net.link.mac, [0x52, 0x54, 0, 0x12, 0x34, 0x58]);
    assert_eq!((net.link.address, net.link.prefix), ([10, 0, 2, 17], 24));
    assert_eq!((net.link.rx.as_str(), net.link.tx.as_str()), ("rx", "tx"));
    // 4diac's port, four clients, read-only unless the configuration says otherwise.
    assert_eq!((net.port, net.connections), (61499, 4));
    assert_eq!(net.access, plc_online::Access::Monitor);
    let given = NET.replace(
        " }",
        ", port = 4444, connections = 8, access = \"download\" }",
    );
    let net = load_ok(&with_net(&given)).partitions[1]
        .iec61499
        .as_ref()
        .and_then(|f| f.net.clone())
        .unwrap();
    assert_eq!((net.port, net.connections), (4444, 8));
    assert_eq!(net.access, plc_online::Access::Download);
}

#[test]
fn a_network_interface_is_checked() {
    let bad = |from: &str, to: &str| with_net(&NET.replace(from, to));
    expect_some(
        &bad("52:54:00:12:34:58", "01:00:5e:00:00:01"),
        "\"01:00:5e:00:00:01\"",
        0,
        "partitions.b.iec61499.net.mac",
        "no unicast MAC address",
    );
    expect_some(
        &bad("rx = \"rx\"", "rx = \"nowhere\""),
        "\"nowhere\"",
        0,
        "partitions.b.iec61499.net.rx",
        "no queuing `in` port",
    );
    expect_some(
        &bad(" }", ", port = 0 }"),
        "0 }",
        0,
        "partitions.b.iec61499.net.port",
        "0 is outside 1..=65535",
    );
    expect_some(
        &bad(" }", ", connections = 9 }"),
        "9 }",
        0,
        "partitions.b.iec61499.net.connections",
        "9 is outside 1..=8",
    );
    expect_some(
        &bad(" }", ", access = \"root\" }"),
        "\"root\"",
        0,
        "partitions.b.iec61499.net.access",
        "unknown access \"root\"",
    );
    expect_some(
        &bad(" }", ", speed = 1 }"),
        "speed",
        0,
        "partitions.b.iec61499.net.speed",
        "unknown field `speed`",
    );
}

#[test]
fn the_frame_ports_are_not_the_management_ports() {
    // Ports of the management protocol's size, which frames fit too.
    let source = with_net(NET).replace("size = 1514", "size = 4096").replace(
        "iec61499.net",
        "iec61499.mgmt = { request = \"rx\", response = \"tx\", access = \"monitor\" }\niec61499.net",
    );
    let diags = load(&source).expect_err("frame ports as management ports");
    assert!(
        diags
            .iter()
            .any(|d| d.key_path == "partitions.b.iec61499.net"
                && d.message.contains("cannot be the management ports")),
        "{diags:?}"
    );
}

#[test]
fn resources_with_their_own_process() {
    let boot = "iec61499.boot = \"tests/data/app.fboot\"\n";
    let system = load_ok(&with(&format!(
        "{boot}iec61499.resources = {{ SLOW = 30, CYCLE = 40 }}"
    )));
    let fb = system.partitions[1].iec61499.as_ref().unwrap();
    let named: Vec<(&str, u8)> = fb
        .resources
        .iter()
        .map(|r| (r.name.as_str(), r.priority))
        .collect();
    assert_eq!(named, [("CYCLE", 40), ("SLOW", 30)]);
    // Partition b's max_priority is 50: a resource process runs below it and above the
    // device process (at least priority 1).
    for priority in ["50", "1"] {
        expect_some(
            &with(&format!(
                "{boot}iec61499.resources = {{ FAST = {priority} }}"
            )),
            &format!("{priority} }}"),
            0,
            "partitions.b.iec61499.resources.FAST",
            &format!("priority {priority} is not in 2..=49"),
        );
    }
    expect_some(
        &with(&format!("{boot}iec61499.resources = {{ \"1X\" = 3 }}")),
        "\"1X\"",
        0,
        "partitions.b.iec61499.resources.1X",
        "\"1X\" is not a resource name",
    );
    expect_some(
        &with(&format!(
            "{boot}iec61499.resources = {{ A = 3, B = 3, C = 3, D = 3, E = 3 }}"
        )),
        "E =",
        0,
        "partitions.b.iec61499.resources",
        "5 resources with their own process: a device has at most 4",
    );
}
