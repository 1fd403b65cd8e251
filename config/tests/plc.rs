//! Validation of the soft-PLC keys (`plc.*`) of a partition.

mod common;
use common::*;

const PLC: &str = r#"ports.in = { kind = "sampling", direction = "in", size = 8, refresh = "20ms" }
plc.program = ["tests/data/counter.st"]
plc.inputs.in = { at = "%IB0", valid = "%IX8.0" }
# b"#;

fn plc(edits: &[(&str, &str)]) -> String {
    let mut text = doc(&[("# b", PLC)]);
    for (pattern, replacement) in edits {
        assert!(text.contains(pattern), "test bug: {pattern:?}");
        text = text.replacen(pattern, replacement, 1);
    }
    text
}

#[test]
fn a_mapped_plc_partition_is_valid() {
    // Partition b's only port `in` is mapped; its program file exists (relative to the
    // description's directory: the crate root for "test.toml").
    let system = load_ok(&plc(&[(
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    )]));
    let b = &system.partitions[1];
    let p = b.plc.as_ref().expect("plc keys");
    assert_eq!(p.program.len(), 1);
    assert_eq!(p.program[0].name, "tests/data/counter.st");
    assert!(p.program[0].path.ends_with("tests/data/counter.st"));
    assert_eq!(p.inputs.len(), 1);
    assert_eq!((p.inputs[0].at, p.inputs[0].valid), (0, Some((8, 0))));
    assert!(p.outputs.is_empty());
}

#[test]
fn missing_program_file() {
    let src = plc(&[
        (
            "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
            "",
        ),
        ("tests/data/counter.st", "tests/data/nope.st"),
    ]);
    expect_some(
        &src,
        "\"tests/data/nope.st\"",
        0,
        "partitions.b.plc.program",
        "no such file `tests/data/nope.st`",
    );
}

#[test]
fn addresses_are_checked() {
    let base = [(
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    )];
    let src = plc(&[base[0], ("at = \"%IB0\"", "at = \"%QB0\"")]);
    expect_some(
        &src,
        "\"%QB0\"",
        0,
        "partitions.b.plc.inputs.in.at",
        "is not an input byte address",
    );
    let src = plc(&[base[0], ("at = \"%IB0\"", "at = \"IB0\"")]);
    expect_some(
        &src,
        "\"IB0\"",
        0,
        "partitions.b.plc.inputs.in.at",
        "starts with `%`",
    );
    let src = plc(&[base[0], ("at = \"%IB0\"", "at = \"%IB4092\"")]);
    expect_some(
        &src,
        "\"%IB4092\"",
        0,
        "partitions.b.plc.inputs.in.at",
        "beyond the 4096-byte area",
    );
    let src = plc(&[base[0], ("valid = \"%IX8.0\"", "valid = \"%IX8.9\"")]);
    expect_some(
        &src,
        "\"%IX8.9\"",
        0,
        "partitions.b.plc.inputs.in.valid",
        "a bit number is 0..=7",
    );
    let src = plc(&[base[0], ("valid = \"%IX8.0\"", "valid = \"%IX3.0\"")]);
    expect_some(
        &src,
        "\"%IX3.0\"",
        0,
        "partitions.b.plc.inputs.in.valid",
        "lies inside a mapped message",
    );
    let src = plc(&[base[0], (", valid = \"%IX8.0\"", "")]);
    expect_some(
        &src,
        "plc.inputs.^in",
        0,
        "partitions.b.plc.inputs.in",
        "a sampling input needs `valid`",
    );
}

#[test]
fn every_port_is_mapped_once_in_its_direction() {
    // An unknown port under inputs (and so `in` left unmapped), an unknown one under
    // outputs.
    let src = plc(&[
        (
            "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
            "",
        ),
        ("plc.inputs.in =", "plc.inputs.other ="),
    ]);
    expect_some(
        &src,
        "plc.inputs.^other",
        0,
        "partitions.b.plc.inputs.other",
        "no port `other`",
    );
    expect_some(
        &src,
        "plc.program",
        0,
        "partitions.b.plc",
        "port `in` is not in the process image",
    );
    let src = plc(&[
        (
            "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
            "",
        ),
        (
            "# b",
            "ports.o = { kind = \"sampling\", direction = \"out\", size = 8 }\nplc.outputs.o = { at = \"%QB0\" }\nplc.outputs.p = { at = \"%QB4\" }\n# b",
        ),
    ]);
    expect_some(
        &src,
        "plc.outputs.^p",
        0,
        "partitions.b.plc.outputs.p",
        "no port `p`",
    );
}

#[test]
fn overlapping_outputs() {
    let src = plc(&[
        (
            "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
            "",
        ),
        (
            "# b",
            "ports.x = { kind = \"sampling\", direction = \"out\", size = 8 }\nports.y = { kind = \"sampling\", direction = \"out\", size = 8 }\nplc.outputs.x = { at = \"%QB0\" }\nplc.outputs.y = { at = \"%QW2\" }\n# b",
        ),
    ]);
    expect_some(
        &src,
        "\"%QW2\"",
        0,
        "partitions.b.plc.outputs.y.at",
        "bytes 4..12 overlap the mapping at line",
    );
}

#[test]
fn a_plc_needs_a_program() {
    let src = plc(&[
        (
            "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
            "",
        ),
        (
            "plc.program = [\"tests/data/counter.st\"]",
            "plc.program = []",
        ),
    ]);
    expect_some(
        &src,
        "plc.program",
        0,
        "partitions.b.plc.program",
        "at least one ST source file",
    );
}

#[test]
fn online_ports() {
    let online = "ports.cmd = { kind = \"queuing\", direction = \"in\", size = 256, depth = 2 }
ports.reply = { kind = \"queuing\", direction = \"out\", size = 256, depth = 2 }
plc.online = { request = \"cmd\", response = \"reply\", access = \"monitor\" }
# b";
    let base = (
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    );
    // The online ports need no process-image mapping (their channels are left out here, so
    // only the plc diagnostics matter).
    let src = plc(&[base, ("# b", online)]);
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .all(|d| !d.key_path.starts_with("partitions.b.plc")),
        "{diags:?}"
    );
    for level in ["force", "download"] {
        let src = plc(&[
            base,
            ("# b", online),
            ("access = \"monitor\"", &format!("access = \"{level}\"")),
        ]);
        let diags = load(&src).unwrap_err();
        assert!(
            diags
                .iter()
                .all(|d| !d.key_path.starts_with("partitions.b.plc")),
            "access {level}: {diags:?}"
        );
    }
    let src = plc(&[
        base,
        ("# b", online),
        ("access = \"monitor\"", "access = \"all\""),
    ]);
    expect_some(
        &src,
        "\"all\"",
        0,
        "partitions.b.plc.online.access",
        "unknown access \"all\"",
    );
    let src = plc(&[
        base,
        ("# b", online),
        ("request = \"cmd\"", "request = \"reply\""),
    ]);
    expect_some(
        &src,
        "request = ^\"reply\"",
        0,
        "partitions.b.plc.online.request",
        "must be a queuing `in` port of this partition with size = 256",
    );
    let src = plc(&[
        base,
        ("# b", online),
        (
            "direction = \"in\", size = 256",
            "direction = \"in\", size = 64",
        ),
    ]);
    expect_some(
        &src,
        "request = ^\"cmd\"",
        0,
        "partitions.b.plc.online.request",
        "size = 256",
    );
}

#[test]
fn task_deadlines() {
    let base = (
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    );
    let with = |deadline: &str| {
        plc(&[
            base,
            (
                "plc.inputs.in",
                &format!("plc.deadline = {{ {deadline} }}\nplc.inputs.in"),
            ),
        ])
    };
    let system = load_ok(&with("fast = \"2ms\", Slow = \"150us\""));
    let p = system.partitions[1].plc.as_ref().expect("plc keys");
    assert_eq!(
        p.deadlines,
        [
            ("Slow".to_string(), 150_000),
            ("fast".to_string(), 2_000_000)
        ]
    );
    expect_some(
        &with("fast = \"50us\""),
        "\"50us\"",
        0,
        "partitions.b.plc.deadline.fast",
        "a task deadline must lie between 100us and 3600s (it is 50us)",
    );
    expect_some(
        &with("fast = 5"),
        "5 }",
        0,
        "partitions.b.plc.deadline.fast",
        "invalid duration 5",
    );
    expect_some(
        &with("fast = \"7200s\""),
        "\"7200s\"",
        0,
        "partitions.b.plc.deadline.fast",
        "a task deadline must lie between",
    );
}

/// Partition b shares globals through segment `link` (its PLC block plus `extra`), and the
/// description ends with `tail`.
fn sharing(b_extra: &str, tail: &str) -> String {
    let text = plc(&[(
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    )]);
    let text = text.replacen("plc.program = [", &format!("{b_extra}\nplc.program = ["), 1);
    format!("{text}\n[[shared_memory]]\nname = \"link\"\nsize = \"4KiB\"\n{tail}")
}

/// A background PLC partition `name` sharing globals through `link`.
fn sharing_partition(name: &str) -> String {
    format!(
        "\n[partitions.{name}]\nimage = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 40\ntime = \"background\"\nshared = {{ link = \"rw\" }}\nplc.program = [\"tests/data/counter.st\"]\nplc.shared = \"link\"\n"
    )
}

#[test]
fn plc_shared_names_a_segment_the_partition_maps_read_write() {
    let system = load_ok(&sharing(
        "shared = { link = \"rw\" }\nplc.shared = \"link\"",
        "",
    ));
    assert_eq!(system.segments[0].name, "link");
    let p = system.partitions[1].plc.as_ref().expect("plc keys");
    assert_eq!(p.shared, Some(0));
    // Without the key the partition shares nothing.
    let system = load_ok(&sharing("shared = { link = \"rw\" }", ""));
    assert_eq!(system.partitions[1].plc.as_ref().unwrap().shared, None);
}

#[test]
fn plc_shared_is_checked() {
    let src = sharing("shared = { link = \"rw\" }\nplc.shared = \"lnk\"", "");
    expect_some(
        &src,
        "\"lnk\"",
        0,
        "partitions.b.plc.shared",
        "unknown shared memory segment `lnk`",
    );
    let src = sharing("plc.shared = \"link\"", "");
    expect_some(
        &src,
        "\"link\"",
        0,
        "partitions.b.plc.shared",
        "must map segment `link` read-write",
    );
    let src = sharing("shared = { link = \"r\" }\nplc.shared = \"link\"", "");
    expect_some(
        &src,
        "\"link\"",
        0,
        "partitions.b.plc.shared",
        "must map segment `link` read-write",
    );
    // Two projects per segment: the third is refused.
    let two = sharing(
        "shared = { link = \"rw\" }\nplc.shared = \"link\"",
        &sharing_partition("c"),
    );
    load_ok(&two);
    let three = format!("{two}{}", sharing_partition("d"));
    expect_some(
        &three,
        "plc.shared = ^\"link\"",
        2,
        "partitions.d.plc.shared",
        "already links the shared globals of b and c",
    );
}

#[test]
fn a_partition_gets_a_compiled_plc_image_as_its_data_entry() {
    let src = doc(&[("# a", "data.plc_image = [\"tests/data/counter.st\"]")]);
    let system = load_ok(&src);
    let Some(config::system::DataEntry::PlcImage(files)) = &system.partitions[0].data else {
        panic!("no data entry: {:?}", system.partitions[0].data);
    };
    assert_eq!(files.len(), 1);
    assert_eq!(files[0].name, "tests/data/counter.st");
    assert!(files[0].path.ends_with("tests/data/counter.st"));
    assert!(system.partitions[1].data.is_none());
}

#[test]
fn plc_image_data_entries_are_checked() {
    let src = doc(&[("# a", "data.plc_image = [\"tests/data/nope.st\"]")]);
    expect_one(
        &src,
        "\"tests/data/nope.st\"",
        0,
        "partitions.a.data.plc_image",
        "no such file `tests/data/nope.st`",
    );
    let src = doc(&[("# a", "data.plc_image = []")]);
    expect_one(
        &src,
        "data.plc_image",
        0,
        "partitions.a.data.plc_image",
        "at least one ST source file",
    );
    let src = doc(&[("# a", "data.file = \"x.bin\"")]);
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .any(|d| d.message.contains("unknown field `file`")),
        "{diags:?}"
    );
    // A PLC partition's data entry is its package.
    let src = plc(&[
        (
            "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
            "",
        ),
        ("# b", "data.plc_image = [\"tests/data/counter.st\"]"),
    ]);
    expect_one(
        &src,
        "data.plc_image",
        0,
        "partitions.b.data",
        "a PLC partition's data entry is its PLC package",
    );
}

#[test]
fn plc_native_selects_the_native_tier() {
    let base = |extra: &str| {
        plc(&[
            (
                "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
                "",
            ),
            ("plc.inputs.in", &format!("{extra}plc.inputs.in")),
        ])
    };
    let tier = |text: &str| {
        load_ok(text).partitions[1]
            .plc
            .as_ref()
            .expect("plc")
            .native
    };
    assert!(!tier(&base("")), "the interpreter is the default");
    assert!(tier(&base("plc.native = true\n")));
    assert!(!tier(&base("plc.native = false\n")));
    expect_some(
        &base("plc.native = \"yes\"\n"),
        "\"yes\"",
        0,
        "partitions.b.plc.native",
        "",
    );
}

#[test]
fn a_plc_network_interface_and_modbus_server_are_checked() {
    let net = "ports.rx = { kind = \"queuing\", direction = \"in\", size = 1514, depth = 8 }
ports.tx = { kind = \"queuing\", direction = \"out\", size = 1514, depth = 8 }
plc.net = { mac = \"52:54:00:12:34:57\", address = \"10.0.2.16/24\", gateway = \"10.0.2.2\", rx = \"rx\", tx = \"tx\", connections = 4, buffer = 1024, requests_per_second = 50 }
plc.modbus = { port = 1502, unit = 3, writable = [\"markers\", \"outputs\"] }
# b";
    let base = (
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    );
    // The frame ports need no process-image mapping (their channels are left out here, so
    // only the plc diagnostics matter).
    let src = plc(&[base, ("# b", net)]);
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .all(|d| !d.key_path.starts_with("partitions.b.plc")),
        "{diags:?}"
    );
    for (from, to, needle, key, message) in [
        (
            "52:54:00:12:34:57",
            "01:00:5e:00:00:01",
            "\"01:00:5e:00:00:01\"",
            "partitions.b.plc.net.mac",
            "no unicast MAC address",
        ),
        (
            "rx = \"rx\"",
            "rx = \"in\"",
            "rx = ^\"in\"",
            "partitions.b.plc.net.rx",
            "size` of at least 1514",
        ),
        (
            "connections = 4",
            "connections = 33",
            "connections = ^33",
            "partitions.b.plc.net.connections",
            "33 is outside 1..=32",
        ),
        (
            "buffer = 1024",
            "buffer = 100",
            "buffer = ^100",
            "partitions.b.plc.net.buffer",
            "outside 512..=65536",
        ),
        (
            "requests_per_second = 50",
            "requests_per_second = 0",
            "requests_per_second = ^0",
            "partitions.b.plc.net.requests_per_second",
            "outside 1..=100000",
        ),
        (
            "port = 1502",
            "port = 70000",
            "port = ^70000",
            "partitions.b.plc.modbus.port",
            "outside 1..=65535",
        ),
        (
            "\"markers\", \"outputs\"",
            "\"inputs\"",
            "[^\"inputs\"",
            "partitions.b.plc.modbus.writable",
            "no writable area",
        ),
    ] {
        let src = plc(&[base, ("# b", net), (from, to)]);
        expect_some(&src, needle, 0, key, message);
    }
    let src = plc(&[base, ("# b", net), ("plc.net = {", "plc.other = {")]);
    assert!(load(&src).is_err(), "an unknown key");
    let no_net = "plc.modbus = { port = 502 }\n# b";
    let src = plc(&[base, ("# b", no_net)]);
    expect_some(
        &src,
        "{ port",
        0,
        "partitions.b.plc.modbus",
        "needs the PLC's network interface",
    );
}

#[test]
fn the_online_protocol_on_tcp_is_checked() {
    let net = "ports.rx = { kind = \"queuing\", direction = \"in\", size = 1514, depth = 8 }
ports.tx = { kind = \"queuing\", direction = \"out\", size = 1514, depth = 8 }
plc.net = { mac = \"52:54:00:12:34:57\", address = \"10.0.2.16/24\", rx = \"rx\", tx = \"tx\" }
plc.modbus = { port = 502 }
plc.online_tcp = { port = 1202, clients.eng = { key = \"tests/data/engineering.key\", access = \"download\" }, clients.hmi = { key = \"tests/data/engineering.key\", access = \"monitor\" } }
# b";
    let base = (
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    );
    let src = plc(&[base, ("# b", net)]);
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .all(|d| !d.key_path.starts_with("partitions.b.plc")),
        "{diags:?}"
    );
    for (from, to, needle, key, message) in [
        (
            "port = 1202",
            "port = 502",
            "{ port = 502, clients",
            "partitions.b.plc.online_tcp.port",
            "the Modbus/TCP server's",
        ),
        (
            "access = \"monitor\"",
            "access = \"admin\"",
            "\"admin\"",
            "partitions.b.plc.online_tcp.clients.hmi.access",
            "unknown access \"admin\"",
        ),
        (
            "clients.hmi = { key = \"tests/data/engineering.key\"",
            "clients.hmi = { key = \"tests/data/bad.key\"",
            "\"tests/data/bad.key\"",
            "partitions.b.plc.online_tcp.clients.hmi.key",
            "holds 'n', which is no hex digit",
        ),
        (
            "clients.hmi = { key = \"tests/data/engineering.key\"",
            "clients.hmi = { key = \"tests/data/none.key\"",
            "\"tests/data/none.key\"",
            "partitions.b.plc.online_tcp.clients.hmi.key",
            "cannot be read",
        ),
        (
            "clients.hmi",
            "clients.\"h m i\"",
            "\"h m i\"",
            "partitions.b.plc.online_tcp.clients.\"h m i\"",
            "without spaces",
        ),
    ] {
        let src = plc(&[base, ("# b", net), (from, to)]);
        expect_some(&src, needle, 0, key, message);
    }
    let no_net = "plc.online_tcp = { clients.eng = { key = \"tests/data/engineering.key\", access = \"force\" } }\n# b";
    let src = plc(&[base, ("# b", no_net)]);
    expect_some(
        &src,
        "{ clients",
        0,
        "partitions.b.plc.online_tcp",
        "needs the PLC's network interface",
    );
}

#[test]
fn publish_and_subscribe_are_checked() {
    let net = "ports.rx = { kind = \"queuing\", direction = \"in\", size = 1514, depth = 8 }
ports.tx = { kind = \"queuing\", direction = \"out\", size = 1514, depth = 8 }
plc.net = { mac = \"52:54:00:12:34:57\", address = \"10.0.2.16/24\", rx = \"rx\", tx = \"tx\" }
plc.modbus = { port = 502 }
plc.publish = { to = \"10.0.2.17:61499\", vars = [\"a\", \"b\"] }
plc.subscribe = { port = 61499, group = \"239.0.0.1\", vars = [\"c\"], valid = \"ok\", timeout = \"50ms\" }
# b";
    let base = (
        "ports.in = { kind = \"sampling\", direction = \"in\", size = 8 }\n",
        "",
    );
    let src = plc(&[base, ("# b", net)]);
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .all(|d| !d.key_path.starts_with("partitions.b.plc")),
        "{diags:?}"
    );
    for (from, to, needle, key, message) in [
        (
            "10.0.2.17:61499",
            "10.0.2.17",
            "\"10.0.2.17\"",
            "partitions.b.plc.publish.to",
            "no IPv4 address and UDP port",
        ),
        (
            "vars = [\"a\", \"b\"]",
            "vars = [\"a\", \"a\"]",
            "\"a\"]",
            "partitions.b.plc.publish.vars",
            "`a` is named twice",
        ),
        (
            "vars = [\"c\"]",
            "vars = []",
            "{ port = 61499",
            "partitions.b.plc.subscribe.vars",
            "0 variables: 1..=16",
        ),
        (
            "timeout = \"50ms\"",
            "timeout = \"4000s\"",
            "\"4000s\"",
            "partitions.b.plc.subscribe.timeout",
            "1 ms to 3600 s",
        ),
        (
            "port = 61499, group",
            "port = 502, group",
            "{ port = 502, group",
            "partitions.b.plc.subscribe.port",
            "also a TCP service's port",
        ),
        (
            "group = \"239.0.0.1\"",
            "group = \"10.0.0.1\"",
            "\"10.0.0.1\"",
            "partitions.b.plc.subscribe.group",
            "no IPv4 multicast group",
        ),
    ] {
        let src = plc(&[base, ("# b", net), (from, to)]);
        expect_some(&src, needle, 0, key, message);
    }
    let no_net = "plc.publish = { to = \"10.0.2.17:61499\", vars = [\"a\"] }\n# b";
    let src = plc(&[base, ("# b", no_net)]);
    expect_some(
        &src,
        "{ to",
        0,
        "partitions.b.plc.publish",
        "needs the PLC's network interface",
    );
}
