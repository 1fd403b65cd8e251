//! Validation of a block-device partition's tenants (`blk.tenants.<partition>`).

mod common;
use common::*;

/// A block-device partition `disk` with two tenants, `plc` and `linux`, each joined to it
/// by a pair of queuing channels.
const BLK: &str = r#"[system]
memory = "512MiB"

[[schedules]]
major_frame = "10ms"

[[schedules.windows]]
partition = "disk"
offset = "0ms"
duration = "4ms"

[partitions.disk]
image = "blk"
memory = "1MiB"
kernel_memory = "128KiB"
max_priority = 100
abilities = ["debug_log", "irq"]
devices = ["00:04.0"]
dma = "64KiB"
dma_unconfined = true
ports.plc-req = { kind = "queuing", direction = "in", size = 2072, depth = 2 }
ports.plc-resp = { kind = "queuing", direction = "out", size = 2064, depth = 2 }
ports.linux-req = { kind = "queuing", direction = "in", size = 2072, depth = 2 }
ports.linux-resp = { kind = "queuing", direction = "out", size = 2064, depth = 2 }
blk.tenants.plc = { from = "plc-req", to = "plc-resp", first_sector = 2048, sectors = 2048 }
blk.tenants.linux = { from = "linux-req", to = "linux-resp", first_sector = 4096, sectors = 65536 }

[partitions.plc]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 50
time = "background"
ports.req = { kind = "queuing", direction = "out", size = 2072, depth = 2 }
ports.resp = { kind = "queuing", direction = "in", size = 2064, depth = 2 }

[partitions.linux]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 50
time = "background"
ports.req = { kind = "queuing", direction = "out", size = 2072, depth = 2 }
ports.resp = { kind = "queuing", direction = "in", size = 2064, depth = 2 }

[[channels]]
kind = "queuing"
from = "plc.req"
to = "disk.plc-req"

[[channels]]
kind = "queuing"
from = "disk.plc-resp"
to = "plc.resp"

[[channels]]
kind = "queuing"
from = "linux.req"
to = "disk.linux-req"

[[channels]]
kind = "queuing"
from = "disk.linux-resp"
to = "linux.resp"
"#;

fn edited(edits: &[(&str, &str)]) -> String {
    edit(BLK, edits)
}

#[test]
fn tenants_are_kept_in_order_with_their_ports_and_ranges() {
    let s = load_ok(BLK);
    let blk = s.partitions[0].blk.as_ref().expect("blk keys");
    let got: Vec<(&str, &str, &str, u64, u64)> = blk
        .tenants
        .iter()
        .map(|t| {
            let ports = &s.partitions[0].ports;
            (
                s.partitions[t.partition].name.as_str(),
                ports[t.from].name.as_str(),
                ports[t.to].name.as_str(),
                t.first_sector,
                t.sectors,
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            ("plc", "plc-req", "plc-resp", 2048, 2048),
            ("linux", "linux-req", "linux-resp", 4096, 65536)
        ]
    );
    assert!(s.partitions[1].blk.is_none());
}

#[test]
fn virtual_disks_must_not_overlap_or_be_empty() {
    expect_one(
        &edited(&[("first_sector = 4096", "first_sector = 4095")]),
        "65536",
        0,
        "partitions.disk.blk.tenants.linux.sectors",
        "the virtual disk of sectors 4095+65536 overlaps the virtual disk of `plc`",
    );
    expect_one(
        &edited(&[("sectors = 2048 }", "sectors = 0 }")]),
        "sectors = ^0",
        0,
        "partitions.disk.blk.tenants.plc.sectors",
        "has no sectors",
    );
    expect_one(
        &edited(&[("first_sector = 4096", "first_sector = 18446744073709551000")]),
        "65536",
        0,
        "partitions.disk.blk.tenants.linux.sectors",
        "ends past the last sector a disk can have",
    );
}

#[test]
fn ports_must_carry_a_whole_request_and_one_tenant() {
    expect_one(
        &edited(&[
            (
                "ports.plc-req = { kind = \"queuing\", direction = \"in\", size = 2072",
                "ports.plc-req = { kind = \"queuing\", direction = \"in\", size = 2071",
            ),
            (
                "direction = \"out\", size = 2072",
                "direction = \"out\", size = 2071",
            ),
        ]),
        "\"plc-req\", to",
        0,
        "partitions.disk.blk.tenants.plc.from",
        "size >= 2072 (the largest request)",
    );
    expect_one(
        &edited(&[("from = \"linux-req\"", "from = \"plc-req\"")]),
        "\"plc-req\", to",
        1,
        "partitions.disk.blk.tenants.linux.from",
        "already carries another tenant's requests",
    );
    expect_one(
        &edited(&[("to = \"plc-resp\"", "to = \"plc-req\"")]),
        "\"plc-req\", first",
        0,
        "partitions.disk.blk.tenants.plc.to",
        "must be a queuing `out` port",
    );
}

#[test]
fn ports_must_lead_to_their_tenant() {
    expect_some(
        &edited(&[("from = \"linux.req\"", "from = \"plc.req\"")]).replacen(
            "from = \"plc.req\"\nto = \"disk.plc-req\"",
            "from = \"linux.req\"\nto = \"disk.plc-req\"",
            1,
        ),
        "\"plc-req\", to",
        0,
        "partitions.disk.blk.tenants.plc.from",
        "port `plc-req` is connected from `linux.req`, not to the tenant `plc`",
    );
}

#[test]
fn a_tenant_must_be_another_partition_and_the_partition_needs_its_device() {
    expect_one(
        &edited(&[("blk.tenants.linux", "blk.tenants.ghost")]),
        "ghost",
        0,
        "partitions.disk.blk.tenants.ghost",
        "no partition `ghost`",
    );
    expect_one(
        &edited(&[("blk.tenants.linux", "blk.tenants.disk")]),
        "disk = {",
        0,
        "partitions.disk.blk.tenants.disk",
        "cannot be its own tenant",
    );
    expect_some(
        &edited(&[("dma = \"64KiB\"\n", "")]),
        "blk.tenants.plc",
        0,
        "partitions.disk.blk",
        "needs `devices` (its virtio-blk function) and `dma`",
    );
}

/// `plc` as a soft-PLC keeping its store on its virtual disk (`plc.store`).
fn with_store(store: &str) -> String {
    edited(&[
        (
            "[partitions.plc]\nimage = \"app\"",
            "[partitions.plc]\nimage = \"softplc\"",
        ),
        (
            "ports.resp = { kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }\n",
            &format!(
                "ports.resp = {{ kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }}\nplc.program = [\"tests/data/counter.st\"]\n{store}\n"
            ),
        ),
    ])
}

#[test]
fn a_plc_store_names_its_ports_and_needs_a_virtual_disk() {
    let s = load_ok(&with_store(
        "plc.store = { request = \"req\", response = \"resp\", retain_every = \"2s\" }",
    ));
    let store = s.partitions[1]
        .plc
        .as_ref()
        .and_then(|p| p.store)
        .expect("plc.store");
    let ports = &s.partitions[1].ports;
    assert_eq!(ports[store.request].name, "req");
    assert_eq!(ports[store.response].name, "resp");
    assert_eq!(store.retain_every_ns, 2_000_000_000);
    let default = load_ok(&with_store(
        "plc.store = { request = \"req\", response = \"resp\" }",
    ));
    assert_eq!(
        default.partitions[1]
            .plc
            .as_ref()
            .and_then(|p| p.store)
            .map(|s| s.retain_every_ns),
        Some(1_000_000_000)
    );
    expect_some(
        &with_store("plc.store = { request = \"resp\", response = \"resp\" }"),
        "request = ^\"resp\"",
        0,
        "partitions.plc.plc.store.request",
        "`resp` must be a queuing `out` port of this partition with size >= 2072",
    );
    expect_one(
        &with_store(
            "plc.store = { request = \"req\", response = \"resp\", retain_every = \"10ms\" }",
        ),
        "retain_every = ^\"10ms\"",
        0,
        "partitions.plc.plc.store.retain_every",
        "RETAIN is saved every 100ms to 3600s",
    );
    let no_disk = with_store("plc.store = { request = \"req\", response = \"resp\" }").replacen(
        "blk.tenants.plc = { from = \"plc-req\", to = \"plc-resp\", first_sector = 2048, sectors = 2048 }\n",
        "",
        1,
    );
    let diags = load(&no_disk).expect_err("no virtual disk");
    assert!(
        diags.iter().any(|d| d.key_path == "partitions.plc.plc.store"
            && d.to_string()
                .contains("partition `plc` has no virtual disk: give it one in a block-device partition's `blk.tenants.plc`")),
        "{diags:?}"
    );
}

/// The document with `linux` as a guest partition with these `guest.*` lines.
fn with_guest_disk(lines: &str) -> String {
    edited(&[
        (
            "[partitions.linux]\nimage = \"app\"\nmemory = \"1MiB\"",
            "[partitions.linux]\nimage = \"guest\"\nmemory = \"8MiB\"\nstack = \"1MiB\"\nabilities = [\"create_task\", \"create_thread\", \"map\"]",
        ),
        (
            "ports.req = { kind = \"queuing\", direction = \"out\", size = 2072, depth = 2 }\nports.resp = { kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }\n\n[[channels]]",
            &format!(
                "ports.req = {{ kind = \"queuing\", direction = \"out\", size = 2072, depth = 2 }}\nports.resp = {{ kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }}\nports.other = {{ kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }}\nguest.init = [\"/bin/sh\"]\n{lines}\n\n[[channels]]"
            ),
        ),
        (
            "ports.resp = { kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }\n\n[partitions.linux]",
            "ports.resp = { kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }\nports.spare = { kind = \"queuing\", direction = \"out\", size = 2064, depth = 2 }\n\n[partitions.linux]",
        ),
    ]) + "\n[[channels]]\nkind = \"queuing\"\nfrom = \"plc.spare\"\nto = \"linux.other\"\n"
}

#[test]
fn a_guest_disk_names_its_ports_and_needs_a_virtual_disk_joined_to_them() {
    let s = load_ok(&with_guest_disk(
        "guest.disk = { request = \"req\", response = \"resp\" }",
    ));
    let disk = s.partitions[2]
        .guest
        .as_ref()
        .and_then(|g| g.disk.clone())
        .expect("guest.disk");
    assert_eq!(
        (disk.request.as_str(), disk.response.as_str()),
        ("req", "resp")
    );
    assert_eq!(disk.sectors, 65536);
    assert_eq!(disk.file(), "request=req\nresponse=resp\nsectors=65536\n");
    expect_one(
        &with_guest_disk("guest.disk = { request = \"resp\", response = \"resp\" }"),
        "request = ^\"resp\"",
        0,
        "partitions.linux.guest.disk.request",
        "`resp` must be a queuing `out` port of this partition with size >= 2072 (the largest request of the block-device link)",
    );
    expect_some(
        &with_guest_disk("guest.disk = { request = \"req\", response = \"nothing\" }"),
        "\"nothing\"",
        0,
        "partitions.linux.guest.disk.response",
        "`nothing` must be a queuing `in` port of this partition with size >= 2064 (the largest response of the block-device link)",
    );
    // A port too small for a response (the channel from the driver's port is refused too).
    expect_some(
        &with_guest_disk("guest.disk = { request = \"req\", response = \"resp\" }").replace(
            "ports.resp = { kind = \"queuing\", direction = \"in\", size = 2064, depth = 2 }\nports.other",
            "ports.resp = { kind = \"queuing\", direction = \"in\", size = 2063, depth = 2 }\nports.other",
        ),
        "response = ^\"resp\"",
        0,
        "partitions.linux.guest.disk.response",
        "size >= 2064",
    );
    // A port of the guest that is not the one the tenant's channel reaches.
    expect_one(
        &with_guest_disk("guest.disk = { request = \"req\", response = \"other\" }"),
        "response = ^\"other\"",
        0,
        "partitions.linux.guest.disk.response",
        "`other` must be fed by port `disk.linux-resp`, the `to` port of this guest's virtual disk (`blk.tenants.linux`), through a channel",
    );
    let no_disk = with_guest_disk("guest.disk = { request = \"req\", response = \"resp\" }")
        .replacen(
            "blk.tenants.linux = { from = \"linux-req\", to = \"linux-resp\", first_sector = 4096, sectors = 65536 }\n",
            "",
            1,
        );
    let diags = load(&no_disk).expect_err("no virtual disk");
    assert!(
        diags.iter().any(|d| d.key_path == "partitions.linux.guest.disk"
            && d.to_string()
                .contains("partition `linux` has no virtual disk: give it one in a block-device partition's `blk.tenants.linux`")),
        "{diags:?}"
    );
}
