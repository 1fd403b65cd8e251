//! Validation of the NIC partition's tenants (`nic.tenants.<partition>`).

mod common;
use common::*;

/// A NIC partition `nic` with two tenants, `echo` and `flood`, each joined to it by a
/// pair of queuing channels.
const NIC: &str = r#"[system]
memory = "512MiB"

[[schedules]]
major_frame = "10ms"

[[schedules.windows]]
partition = "nic"
offset = "0ms"
duration = "4ms"

[partitions.nic]
image = "nic"
memory = "2MiB"
kernel_memory = "128KiB"
max_priority = 100
abilities = ["debug_log", "irq"]
devices = ["00:03.0"]
dma = "512KiB"
dma_unconfined = true
ports.echo-tx = { kind = "queuing", direction = "in", size = 1514, depth = 16 }
ports.echo-rx = { kind = "queuing", direction = "out", size = 1514, depth = 16 }
ports.flood-tx = { kind = "queuing", direction = "in", size = 1514, depth = 16 }
ports.flood-rx = { kind = "queuing", direction = "out", size = 1514, depth = 16 }
nic.tenants.echo = { mac = "52:54:00:12:34:56", from = "echo-tx", to = "echo-rx" }
nic.tenants.flood = { mac = "52:54:00:12:34:57", from = "flood-tx", to = "flood-rx" }

[partitions.echo]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 50
time = "background"
ports.tx = { kind = "queuing", direction = "out", size = 1514, depth = 16 }
ports.rx = { kind = "queuing", direction = "in", size = 1514, depth = 16 }

[partitions.flood]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 50
time = "background"
ports.tx = { kind = "queuing", direction = "out", size = 1514, depth = 16 }
ports.rx = { kind = "queuing", direction = "in", size = 1514, depth = 16 }

[[channels]]
kind = "queuing"
from = "echo.tx"
to = "nic.echo-tx"

[[channels]]
kind = "queuing"
from = "nic.echo-rx"
to = "echo.rx"

[[channels]]
kind = "queuing"
from = "flood.tx"
to = "nic.flood-tx"

[[channels]]
kind = "queuing"
from = "nic.flood-rx"
to = "flood.rx"
"#;

fn edited(edits: &[(&str, &str)]) -> String {
    edit(NIC, edits)
}

#[test]
fn tenants_are_kept_in_order_with_their_ports() {
    let s = load_ok(NIC);
    let nic = s.partitions[0].nic.as_ref().expect("nic keys");
    let names: Vec<(&str, &str, &str)> = nic
        .tenants
        .iter()
        .map(|t| {
            let ports = &s.partitions[0].ports;
            (
                s.partitions[t.partition].name.as_str(),
                ports[t.from].name.as_str(),
                ports[t.to].name.as_str(),
            )
        })
        .collect();
    assert_eq!(
        names,
        [
            ("echo", "echo-tx", "echo-rx"),
            ("flood", "flood-tx", "flood-rx")
        ]
    );
    assert_eq!(nic.tenants[0].mac, [0x52, 0x54, 0, 0x12, 0x34, 0x56]);
    assert!(s.partitions[1].nic.is_none());
}

#[test]
fn macs_must_be_unicast_unique_and_well_formed() {
    expect_one(
        &edited(&[("52:54:00:12:34:57", "52:54:00:12:34:56")]),
        "\"52:54:00:12:34:56\"",
        1,
        "partitions.nic.nic.tenants.flood.mac",
        "MAC 52:54:00:12:34:56 cannot be a tenant's: another tenant has it",
    );
    expect_one(
        &edited(&[("52:54:00:12:34:57", "01:00:5e:00:00:01")]),
        "\"01:00:5e",
        0,
        "partitions.nic.nic.tenants.flood.mac",
        "a multicast (group) address",
    );
    expect_one(
        &edited(&[("52:54:00:12:34:57", "ff:ff:ff:ff:ff:ff")]),
        "\"ff:ff",
        0,
        "partitions.nic.nic.tenants.flood.mac",
        "a multicast (group) address",
    );
    expect_one(
        &edited(&[("52:54:00:12:34:57", "00:00:00:00:00:00")]),
        "\"00:00",
        0,
        "partitions.nic.nic.tenants.flood.mac",
        "the all-zero address",
    );
    expect_one(
        &edited(&[("52:54:00:12:34:57", "52-54-00-12-34-57")]),
        "\"52-54",
        0,
        "partitions.nic.nic.tenants.flood.mac",
        "`52-54-00-12-34-57` is not a MAC address",
    );
}

#[test]
fn ports_must_be_queuing_frame_sized_and_point_the_right_way() {
    let small = edited(&[(
        "ports.echo-tx = { kind = \"queuing\", direction = \"in\", size = 1514",
        "ports.echo-tx = { kind = \"queuing\", direction = \"in\", size = 1500",
    )]);
    expect_some(
        &small,
        "\"echo-tx\", to",
        0,
        "partitions.nic.nic.tenants.echo.from",
        "`echo-tx` must be a queuing `in` port of this partition with size >= 1514",
    );
    // `from` naming the NIC's output, `to` its input.
    let swapped = edited(&[(
        "from = \"echo-tx\", to = \"echo-rx\"",
        "from = \"echo-rx\", to = \"echo-tx\"",
    )]);
    expect_some(
        &swapped,
        "\"echo-rx\", to",
        0,
        "partitions.nic.nic.tenants.echo.from",
        "must be a queuing `in` port",
    );
    expect_some(
        &edited(&[("from = \"echo-tx\"", "from = \"nope\"")]),
        "\"nope\"",
        0,
        "partitions.nic.nic.tenants.echo.from",
        "`nope` must be a queuing `in` port",
    );
    // Tenant echo's `from` carrying flood's frames.
    let crossed = edited(&[
        ("from = \"flood-tx\"", "from = \"echo-tx\""),
        (
            "from = \"echo-tx\", to = \"echo-rx\"",
            "from = \"flood-tx\", to = \"echo-rx\"",
        ),
    ]);
    expect_some(
        &crossed,
        "\"flood-tx\", to = \"echo-rx\"",
        0,
        "partitions.nic.nic.tenants.echo.from",
        "port `flood-tx` is connected from `flood.tx`, not to the tenant `echo`",
    );
    let shared = edited(&[("from = \"flood-tx\"", "from = \"echo-tx\"")]);
    expect_some(
        &shared,
        "\"echo-tx\", to = \"flood-rx\"",
        0,
        "partitions.nic.nic.tenants.flood.from",
        "port `echo-tx` already carries another tenant's frames",
    );
}

#[test]
fn tenants_must_be_other_partitions() {
    expect_some(
        &edited(&[("nic.tenants.flood", "nic.tenants.ghost")]),
        "ghost",
        0,
        "partitions.nic.nic.tenants.ghost",
        "no partition `ghost` to attach",
    );
    expect_some(
        &edited(&[("nic.tenants.flood", "nic.tenants.nic")]),
        "tenants.^nic",
        0,
        "partitions.nic.nic.tenants.nic",
        "the NIC partition cannot be its own tenant",
    );
}

#[test]
fn the_nic_partition_needs_its_device_and_a_dma_region() {
    let without = edited(&[("dma = \"512KiB\"\ndma_unconfined = true\n", "")]);
    expect_one(
        &without,
        "nic.tenants.echo",
        0,
        "partitions.nic.nic",
        "the NIC partition needs `devices` (its virtio-net function) and `dma`",
    );
}

#[test]
fn the_nic_partition_runs_nothing_else() {
    let src = edited(&[(
        "nic.tenants.echo",
        "data.plc_image = [\"tests/data/counter.st\"]\nnic.tenants.echo",
    )]);
    expect_some(
        &src,
        "nic.tenants.echo",
        0,
        "partitions.nic.nic",
        "a partition is the NIC partition (`nic`) or runs a `data` entry, not both",
    );
}

#[test]
fn a_frame_ring_is_a_segment_only_the_nic_and_its_tenant_map_read_write() {
    let ring = |size: &str, nic: &str, echo: &str, flood: &str| {
        let mut doc = edited(&[
            (
                "to = \"echo-rx\" }",
                "to = \"echo-rx\", ring = \"frames\" }",
            ),
            (
                "[partitions.nic]",
                "[[shared_memory]]\nname = \"frames\"\nsize = \"SIZE\"\n\n[partitions.nic]",
            ),
            ("dma_unconfined = true", "dma_unconfined = true\nNIC"),
        ]);
        doc = doc.replace("SIZE", size).replace("NIC", nic);
        let mut parts = doc.splitn(3, "time = \"background\"");
        let (head, echo_part, rest) = (
            parts.next().unwrap(),
            parts.next().unwrap(),
            parts.next().unwrap(),
        );
        format!(
            "{head}time = \"background\"\n{echo}{echo_part}time = \"background\"\n{flood}{rest}"
        )
    };
    let at = "partitions.nic.nic.tenants.echo.ring";
    let rw = "shared = { frames = \"rw\" }";
    // A plain partition may take one (its program finds the segment at its address).
    let s = load_ok(&ring("64KiB", rw, rw, ""));
    let ring_of = s.partitions[0].nic.as_ref().expect("nic keys").tenants[0].ring;
    assert_eq!(ring_of.map(|r| (r.segment, r.size)), Some((0, 65536)));
    expect_some(
        &ring("8KiB", rw, rw, ""),
        "\"frames\" }",
        0,
        at,
        "segment `frames` (8192 bytes) is too small for a frame ring: it needs at least 16384 bytes",
    );
    expect_some(
        &ring("64KiB", "shared = { frames = \"r\" }", rw, ""),
        "\"frames\" }",
        0,
        at,
        "frame ring `frames`: partition `nic` must map it read-write (`shared = { frames = \"rw\" }`)",
    );
    expect_some(
        &ring("64KiB", rw, "", ""),
        "\"frames\" }",
        0,
        at,
        "frame ring `frames`: partition `echo` must map it read-write",
    );
    expect_some(
        &ring("64KiB", rw, rw, rw),
        "\"frames\" }",
        0,
        at,
        "frame ring `frames`: partition `flood` maps it too, and only the NIC partition and the tenant may",
    );
    expect_some(
        &edited(&[("to = \"echo-rx\" }", "to = \"echo-rx\", ring = \"nope\" }")]),
        "\"nope\" }",
        0,
        at,
        "unknown shared memory segment `nope` (define it in [[shared_memory]])",
    );
}
