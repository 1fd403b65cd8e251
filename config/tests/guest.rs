//! Validation of the guest keys (`guest.*`) of a partition.

mod common;
use common::*;

/// Partition `b` as a guest with these extra lines.
fn guest(lines: &str) -> String {
    doc(&[(
        "time = \"background\"",
        &format!(
            "time = \"background\"\nstack = \"1MiB\"\nabilities = [\"create_task\", \"create_thread\", \"map\"]\n{lines}"
        ),
    )])
}

#[test]
fn a_guest_partition_is_valid() {
    let system = load_ok(&guest(
        "guest.init = [\"/bin/busybox\", \"sh\", \"-c\", \"echo hello; echo world\"]",
    ));
    let g = system.partitions[1].guest.as_ref().expect("guest keys");
    assert_eq!(
        g.init,
        ["/bin/busybox", "sh", "-c", "echo hello; echo world"]
    );
    assert_eq!(g.env, config::system::GUEST_DEFAULT_ENV);
    let system = load_ok(&guest(
        "guest.init = [\"/bin/sh\"]\nguest.env = [\"PATH=/bin\", \"A=\"]",
    ));
    let g = system.partitions[1].guest.as_ref().unwrap();
    assert_eq!(g.env, ["PATH=/bin", "A="]);
    assert!(system.partitions[0].guest.is_none());
}

#[test]
fn init_must_name_an_absolute_program() {
    expect_some(
        &guest("guest.init = []"),
        "guest.init = []",
        0,
        "partitions.b.guest.init",
        "needs at least the program to run",
    );
    expect_some(
        &guest("guest.init = [\"busybox\", \"echo\"]"),
        "\"busybox\"",
        0,
        "partitions.b.guest.init[0]",
        "`busybox` is not an absolute path",
    );
}

#[test]
fn env_entries_are_name_value_pairs() {
    expect_some(
        &guest("guest.init = [\"/bin/sh\"]\nguest.env = [\"PATH=/bin\", \"oops\"]"),
        "\"oops\"",
        0,
        "partitions.b.guest.env[1]",
        "`oops` is not NAME=value",
    );
}

#[test]
fn strings_are_limited() {
    let many = vec!["\"x\""; 70].join(", ");
    let src = guest(&format!("guest.init = [\"/bin/sh\", {many}]"));
    let errors = load(&src).unwrap_err();
    assert!(
        errors
            .iter()
            .any(|d| d.to_string().contains("at most 64 strings")),
        "{errors:?}"
    );
    let long = "y".repeat(9000);
    let errors = load(&guest(&format!("guest.init = [\"/bin/sh\", \"{long}\"]"))).unwrap_err();
    assert!(
        errors.iter().any(|d| d.to_string().contains("8192 bytes")),
        "{errors:?}"
    );
}

#[test]
fn a_guest_needs_its_abilities_and_no_plc() {
    let src = doc(&[(
        "time = \"background\"",
        "time = \"background\"\nabilities = [\"create_task\"]\nguest.init = [\"/bin/sh\"]",
    )]);
    let errors = load(&src).unwrap_err();
    assert!(
        errors.iter().any(|d| {
            let t = d.to_string();
            t.contains("partitions.b.guest")
                && t.contains("`create_task`, `create_thread` and `map`")
        }),
        "{errors:?}"
    );
    let src = guest(
        "guest.init = [\"/bin/sh\"]\nplc.program = [\"tests/data/counter.st\"]\nplc.inputs.in = { at = \"%IB0\", valid = \"%IX8.0\" }",
    );
    let errors = load(&src).unwrap_err();
    assert!(
        errors
            .iter()
            .any(|d| d.to_string().contains("either the soft-PLC")),
        "{errors:?}"
    );
}

#[test]
fn unknown_guest_keys_are_errors() {
    let errors = load(&guest("guest.init = [\"/bin/sh\"]\nguest.files = []")).unwrap_err();
    assert!(
        errors.iter().any(|d| d.to_string().contains("files")),
        "{errors:?}"
    );
}

#[test]
fn files_are_added_from_the_host() {
    let system = load_ok(&guest(
        "guest.init = [\"/bin/cat\", \"/etc/motd\"]\nguest.files = { \"/etc/motd\" = \"tests/data/motd.txt\", \"/etc/passwd\" = \"tests/data/motd.txt\" }",
    ));
    let g = system.partitions[1].guest.as_ref().unwrap();
    let targets: Vec<&str> = g.files.iter().map(|(t, _)| t.as_str()).collect();
    assert_eq!(targets, ["/etc/motd", "/etc/passwd"]);
    assert_eq!(g.files[0].1.name, "tests/data/motd.txt");
    assert!(g.files[0].1.path.ends_with("tests/data/motd.txt"));
}

#[test]
fn files_need_a_host_file_and_a_free_absolute_path() {
    let with = |files: &str| {
        guest(&format!(
            "guest.init = [\"/bin/sh\"]\nguest.files = {{ {files} }}"
        ))
    };
    expect_some(
        &with("\"/etc/motd\" = \"tests/data/nope.txt\""),
        "\"tests/data/nope.txt\"",
        0,
        "partitions.b.guest.files.\"/etc/motd\"",
        "no such file `tests/data/nope.txt`",
    );
    for bad in ["etc/motd", "/etc/../motd", "/etc/", "/etc//motd", "/./motd"] {
        let src = with(&format!("\"{bad}\" = \"tests/data/motd.txt\""));
        let errors = load(&src).unwrap_err();
        assert!(
            errors
                .iter()
                .any(|d| d.to_string().contains("is not a normalised absolute path")),
            "{bad}: {errors:?}"
        );
    }
    let errors = load(&with("\"/bin/busybox\" = \"tests/data/motd.txt\"")).unwrap_err();
    assert!(
        errors.iter().any(|d| d
            .to_string()
            .contains("`/bin/busybox` is written by the image builder")),
        "{errors:?}"
    );
}

#[test]
fn a_guest_has_no_other_data_entry() {
    expect_some(
        &guest("guest.init = [\"/bin/sh\"]\ndata.plc_image = [\"tests/data/counter.st\"]"),
        "data.plc_image",
        0,
        "partitions.b.data",
        "a guest partition's data entry is its initramfs",
    );
}

#[test]
fn a_guest_port_message_fits_one_read() {
    expect_some(
        &guest(
            "guest.init = [\"/bin/sh\"]\nports.q = { kind = \"queuing\", direction = \"in\", size = \"8KiB\", depth = 2 }",
        ),
        "\"8KiB\"",
        0,
        "partitions.b.ports.q.size",
        "a guest's port devices move at most 4096 bytes a message",
    );
}

#[test]
fn a_guest_port_is_fifo() {
    expect_some(
        &guest(
            "guest.init = [\"/bin/sh\"]\nports.q = { kind = \"queuing\", direction = \"in\", size = 8, depth = 2, discipline = \"priority\" }",
        ),
        "\"priority\"",
        0,
        "partitions.b.ports.q.discipline",
        "a guest never waits on a port",
    );
}

#[test]
fn a_guest_needs_a_stack_for_its_process_table() {
    let src = guest("guest.init = [\"/bin/sh\"]").replace("stack = \"1MiB\"", "stack = \"256KiB\"");
    expect_some(
        &src,
        "\"256KiB\"",
        0,
        "partitions.b.stack",
        "a guest partition needs a `stack` of at least 1MiB (its process table lives there), not 256KiB",
    );
    // Without `stack`: the default 64 KiB, reported at the guest keys.
    let src = guest("guest.init = [\"/bin/sh\"]").replace("stack = \"1MiB\"\n", "");
    expect_some(&src, "guest.init", 0, "partitions.b.guest", "not 64KiB");
}

#[test]
fn a_console_on_com2_needs_its_ports_and_interrupt() {
    let with = |device: &str| {
        doc(&[(
            "time = \"background\"",
            &format!(
                "time = \"background\"\nstack = \"1MiB\"\nabilities = [\"create_task\", \"create_thread\", \"map\", \"irq\"]\n{device}\nguest.init = [\"/bin/sh\"]\nguest.console = \"com2\""
            ),
        )])
    };
    let system = load_ok(&with("io_ports = [\"0x2f8-0x2ff\"]\nirqs = [3]"));
    assert!(system.partitions[1].guest.as_ref().unwrap().console_com2);
    let system = load_ok(&guest("guest.init = [\"/bin/sh\"]"));
    assert!(!system.partitions[1].guest.as_ref().unwrap().console_com2);
    for device in [
        "io_ports = [\"0x2f8-0x2ff\"]",
        "irqs = [3]",
        "io_ports = [\"0x2f8-0x2fb\"]\nirqs = [3]",
    ] {
        expect_some(
            &with(device),
            "\"com2\"",
            0,
            "partitions.b.guest.console",
            "needs its ports and interrupt",
        );
    }
    expect_some(
        &guest("guest.init = [\"/bin/sh\"]\nguest.console = \"com1\""),
        "\"com1\"",
        0,
        "partitions.b.guest.console",
        "`com1` is no console device",
    );
}

#[test]
fn programs_are_known_once_and_not_also_files() {
    let system = load_ok(&guest(
        "guest.init = [\"/bin/linux-tests\"]\nguest.programs = [\"linux-tests\", \"linux-bench\"]",
    ));
    let g = system.partitions[1].guest.as_ref().unwrap();
    assert_eq!(g.programs, ["linux-tests", "linux-bench"]);
    let none = load_ok(&guest("guest.init = [\"/bin/sh\"]"));
    assert!(
        none.partitions[1]
            .guest
            .as_ref()
            .unwrap()
            .programs
            .is_empty()
    );
    expect_some(
        &guest("guest.init = [\"/bin/sh\"]\nguest.programs = [\"gcc\"]"),
        "\"gcc\"",
        0,
        "partitions.b.guest.programs[0]",
        "`gcc` is no program cargo xtask builds (known: linux-tests, linux-bench, linux-probe, linux-arinc, linux-netserve, plcctl, plcc, fbctl, linux-rust-std)",
    );
    expect_some(
        &guest("guest.init = [\"/bin/sh\"]\nguest.programs = [\"linux-tests\", \"linux-tests\"]"),
        "\"linux-tests\"",
        1,
        "partitions.b.guest.programs[1]",
        "`linux-tests` is listed twice",
    );
    let errors = load(&guest(
        "guest.init = [\"/bin/sh\"]\nguest.programs = [\"linux-tests\"]\nguest.files = { \"/bin/linux-tests\" = \"tests/data/motd.txt\" }",
    ))
    .unwrap_err();
    assert!(
        errors.iter().any(|d| d
            .to_string()
            .contains("`/bin/linux-tests` is also a `guest.files` path")),
        "{errors:?}"
    );
}

/// A guest with `eth0` through ports `rx`/`tx` (queuing, 1514 bytes) and `net` as given.
fn with_net(net: &str, rx_size: u32) -> String {
    guest(&format!(
        "guest.init = [\"/bin/sh\"]\nports.rx = {{ kind = \"queuing\", direction = \"in\", size = {rx_size}, depth = 8 }}\nports.tx = {{ kind = \"queuing\", direction = \"out\", size = 1514, depth = 8 }}\nguest.net = {net}"
    )) + "\n[[channels]]\nkind = \"queuing\"\nfrom = \"b.tx\"\nto = \"b.rx\"\n"
}

#[test]
fn a_guest_network_interface() {
    let system = load_ok(&with_net(
        "{ mac = \"52:54:00:12:34:56\", address = \"10.0.2.15/24\", gateway = \"10.0.2.2\", rx = \"rx\", tx = \"tx\" }",
        1514,
    ));
    let net = system.partitions[1]
        .guest
        .as_ref()
        .unwrap()
        .net
        .clone()
        .unwrap();
    assert_eq!(net.mac, [0x52, 0x54, 0, 0x12, 0x34, 0x56]);
    assert_eq!((net.address, net.prefix), ([10, 0, 2, 15], 24));
    assert_eq!(net.gateway, Some([10, 0, 2, 2]));
    assert_eq!(
        net.file(),
        "mac=52:54:00:12:34:56\naddress=10.0.2.15/24\ngateway=10.0.2.2\nrx=rx\ntx=tx\n"
    );
    let system = load_ok(&guest("guest.init = [\"/bin/sh\"]"));
    assert!(
        system.partitions[1].guest.as_ref().unwrap().net.is_none(),
        "lo alone"
    );
}

#[test]
fn a_guest_network_interface_is_checked() {
    let good = "{ mac = \"52:54:00:12:34:56\", address = \"10.0.2.15/24\", gateway = \"10.0.2.2\", rx = \"rx\", tx = \"tx\" }";
    expect_some(
        &with_net(
            &good.replace("52:54:00:12:34:56", "01:00:5e:00:00:01"),
            1514,
        ),
        "\"01:00:5e:00:00:01\"",
        0,
        "partitions.b.guest.net.mac",
        "no unicast MAC address",
    );
    expect_some(
        &with_net(&good.replace("10.0.2.15/24", "10.0.2.15"), 1514),
        "\"10.0.2.15\"",
        0,
        "partitions.b.guest.net.address",
        "prefix length of 1 to 30",
    );
    expect_some(
        &with_net(&good.replace("10.0.2.2\"", "192.168.1.1\""), 1514),
        "\"192.168.1.1\"",
        0,
        "partitions.b.guest.net.gateway",
        "of the guest's subnet",
    );
    expect_some(
        &with_net(good, 1500),
        "\"rx\"",
        0,
        "partitions.b.guest.net.rx",
        "size` of at least 1514",
    );
    expect_some(
        &with_net(&good.replace("tx = \"tx\"", "tx = \"rx\""), 1514),
        "\"rx\"",
        1,
        "partitions.b.guest.net.tx",
        "no queuing `out` port",
    );
    expect_some(
        &with_net(&good.replace("rx = \"rx\"", "rx = \"nowhere\""), 1514),
        "\"nowhere\"",
        0,
        "partitions.b.guest.net.rx",
        "no queuing `in` port",
    );
}
