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
