//! Every description in config/systems/ must validate and survive the binary round trip.
//! Images are not checked here (any name passes): `cargo xtask check-config` checks them
//! against the user programs the workspace builds.

mod common;
use config::System;
use config::model::{ErrorCode, HealthAction, IoRange, PortKind};
use std::path::PathBuf;

fn systems_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("systems")
}

fn load_file(path: &std::path::Path) -> System {
    let source = std::fs::read_to_string(path).unwrap();
    let name = path.display().to_string();
    match config::load(&name, &source, &common::any_image) {
        Ok(system) => system,
        Err(diags) => {
            let all: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
            panic!("{name} is invalid:\n{}", all.join("\n"));
        }
    }
}

#[test]
fn every_system_validates_and_round_trips() {
    let mut count = 0;
    for entry in std::fs::read_dir(systems_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let system = load_file(&path);
        let blob = config::binary::encode(&system);
        let view = config::decode(&blob)
            .unwrap_or_else(|e| panic!("{}: the encoded form is rejected: {e}", path.display()));
        // The PLC mapping, other data entries, the guest's init, the IEC 61499 boot file and
        // the NIC's tenants travel in the partitions' data entries (PLC package, compiled
        // image, initramfs, device package, tenant table), not in the binary form.
        let mut without_data = system.clone();
        for p in &mut without_data.partitions {
            p.plc = None;
            p.data = None;
            p.guest = None;
            p.iec61499 = None;
            p.nic = None;
            p.blk = None;
        }
        assert_eq!(System::from_view(&view), without_data, "{}", path.display());
        count += 1;
    }
    assert!(count >= 1, "no system descriptions found");
}

#[test]
fn plc_guest_system() {
    let s = load_file(&systems_dir().join("plc-guest.toml"));
    let names: Vec<&str> = s.partitions.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["plc", "plant", "nic", "linux"]);
    let [plc, plant, nic, guest] = &s.partitions[..] else {
        unreachable!()
    };
    assert_eq!((plc.image.as_str(), plc.time_partition), ("softplc", 1));
    assert_eq!((plant.image.as_str(), plant.time_partition), ("plant", 2));
    assert_eq!((nic.image.as_str(), nic.time_partition), ("nic", 3));
    assert_eq!(nic.devices, [pci::Address::parse("00:03.0").unwrap()]);
    assert_eq!((nic.dma, nic.dma_unconfined), (512 * 1024, false));
    assert_eq!((guest.image.as_str(), guest.time_partition), ("guest", 0));
    assert_eq!(
        guest.io_ports,
        [IoRange {
            first: 0x2f8,
            last: 0x2ff
        }]
    );
    assert_eq!(guest.irqs.lines().collect::<Vec<_>>(), [3]);
    let normal = &s.schedules[0];
    assert_eq!(normal.major_frame, 10_000_000);
    assert_eq!(
        (
            normal.windows[0].offset,
            normal.windows[0].duration,
            normal.windows[0].time_partition
        ),
        (0, 3_000_000, 1)
    );
    // The PLC's valve and setpoint to the plant, the plant's level to the PLC; the guest
    // sees the level, the valve, the setpoint and the alarm (its HMI) and reaches the PLC's
    // online service; its eth0 and the
    // PLC's interface are the NIC partition's tenants.
    let links: Vec<(PortKind, String, Vec<String>)> = s
        .channels
        .iter()
        .map(|c| {
            let end = |r: config::system::PortRef| {
                let p = &s.partitions[r.partition];
                format!("{}.{}", p.name, p.ports[r.port].name)
            };
            let to = c.destinations.iter().map(|&d| end(d)).collect();
            (c.kind, end(c.source), to)
        })
        .collect();
    let link = |kind, from: &str, to: &[&str]| {
        (
            kind,
            from.to_string(),
            to.iter().map(|t| t.to_string()).collect::<Vec<_>>(),
        )
    };
    assert_eq!(
        links,
        [
            link(
                PortKind::Sampling,
                "plc.valve",
                &["plant.valve", "linux.valve"]
            ),
            link(
                PortKind::Sampling,
                "plc.setpoint",
                &["plant.setpoint", "linux.setpoint"]
            ),
            link(PortKind::Sampling, "plc.alarm", &["linux.alarm"]),
            link(
                PortKind::Sampling,
                "plant.level",
                &["plc.level", "linux.level"]
            ),
            link(PortKind::Queuing, "linux.plc-request", &["plc.cmd"]),
            link(PortKind::Queuing, "plc.reply", &["linux.plc-response"]),
            link(PortKind::Queuing, "linux.eth0-tx", &["nic.linux-tx"]),
            link(PortKind::Queuing, "nic.linux-rx", &["linux.eth0-rx"]),
            link(PortKind::Queuing, "plc.eth-tx", &["nic.plc-tx"]),
            link(PortKind::Queuing, "nic.plc-rx", &["plc.eth-rx"]),
        ]
    );
    // The PLC's own interface (10.0.2.16) with its read-only Modbus/TCP server.
    let p = plc.plc.as_ref().expect("the PLC's keys");
    let net = p.net.as_ref().expect("plc.net");
    assert_eq!((net.link.address, net.link.prefix), ([10, 0, 2, 16], 24));
    let modbus = p.modbus.expect("plc.modbus");
    assert_eq!(
        (modbus.port, modbus.write_outputs, modbus.write_markers),
        (502, false, false)
    );
    let g = guest.guest.as_ref().expect("the guest's keys");
    assert_eq!(g.programs, ["plcctl", "plcc"]);
    // The guest's frames and the PLC's go through rings, each in a segment only it and the
    // NIC partition map.
    let tenants = &nic.nic.as_ref().expect("the tenant table").tenants;
    let ring = tenants[0].ring.expect("the guest's frame ring");
    assert_eq!(s.segments[ring.segment].name, "linux-frames");
    assert_eq!(
        (ring.address, ring.size),
        (protocol::layout::shared_address(std::iter::empty()), 65536)
    );
    let net = g.net.as_ref().expect("guest.net");
    assert_eq!(net.ring, Some(ring));
    let plc_ring = tenants[1].ring.expect("the PLC's frame ring");
    assert_eq!(s.segments[plc_ring.segment].name, "plc-frames");
    assert_eq!(
        plc_ring.address,
        protocol::layout::shared_address([65536].into_iter())
    );
    let plc_net = plc.plc.as_ref().and_then(|p| p.net.as_ref());
    assert_eq!(plc_net.expect("plc.net").link.ring, Some(plc_ring));
    assert!(
        net.file().ends_with("ring=0x600000000000,65536\n"),
        "{}",
        net.file()
    );
    assert!(g.console_com2);
    assert_eq!(
        plc.health.get(ErrorCode::DeadlineMissed),
        Some(HealthAction::Ignore)
    );
    assert_eq!(
        guest.health.get(ErrorCode::ApplicationError),
        Some(HealthAction::ColdRestart)
    );
    assert_eq!(
        s.health.get(ErrorCode::MemoryViolation),
        Some(HealthAction::Idle)
    );
}

/// The two-CPU example of the scenarios' systems: on each CPU a window (overlapping the
/// other's in part) and background partitions.
#[test]
fn smp_partitions_system() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/configs/smp_partitions.toml");
    let s = load_file(&path);
    assert_eq!(s.cpus, 2);
    let partitions: Vec<(&str, u8, u8)> = s
        .partitions
        .iter()
        .map(|p| (p.name.as_str(), p.cpu, p.time_partition))
        .collect();
    assert_eq!(
        partitions,
        [
            ("windows-a", 0, 1),
            ("windows-b", 1, 2),
            ("cpu0", 0, 0),
            ("hog1", 1, 0),
            ("hog0", 0, 0)
        ]
    );
    let windows: Vec<(u64, u8, u8)> = s.schedules[0]
        .windows
        .iter()
        .map(|w| (w.offset, w.cpu, w.time_partition))
        .collect();
    assert_eq!(windows, [(0, 0, 1), (2_000_000, 1, 2)]);
    let blob = config::binary::encode(&s);
    let view = config::decode(&blob).expect("the encoded form decodes");
    assert_eq!(System::from_view(&view), s);
    let beta = view.find_partition("windows-b").unwrap();
    let theirs: Vec<u64> = view
        .schedule(0)
        .windows_of(beta.cpu)
        .map(|w| w.spec().cpu)
        .collect();
    assert_eq!(theirs, [1]);

    // Both windows on CPU 0 (windows-b bound to it): they overlap.
    let source = std::fs::read_to_string(&path).unwrap();
    let one_cpu = common::edit(
        &source,
        &[
            ("cpu = 1\n", "cpu = 0\n"),
            (
                "cpus = [1]\nhealth.illegal_request",
                "cpus = [0]\nhealth.illegal_request",
            ),
        ],
    );
    common::expect_one(
        &one_cpu,
        "\"2ms\"",
        0,
        "schedules[0].windows[1].offset",
        "the window 2ms..6ms overlaps window 0 (0ns..4ms), both on CPU 0 (the windows of one CPU must not overlap; those of different CPUs may)",
    );
    // windows-b's window on CPU 0 while windows-b runs on CPU 1.
    let elsewhere = common::edit(&source, &[("cpu = 1\n", "cpu = 0\n")]);
    common::expect_one(
        &elsewhere,
        "cpu = ^0",
        1,
        "schedules[0].windows[1].cpu",
        "partition `windows-b` runs on CPU 1; this window is on CPU 0",
    );
}
