//! PCI devices by configuration: a partition owns a virtio-net function (scenario
//! `pci_devices`, partitions of `tests/programs/pci-probe`).

use scenarios::{boot, check};

#[test]
fn pci_devices() {
    let o = boot("pci_devices");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): nic's #UD is configured as shutdown_success",
    );
    for line in [
        // The absent function stops only its partition, with the device named.
        "syssw: partition absent not started: PCI device 00:05.0: no such device at boot",
        "syssw: 3 partitions started",
        "syssw: partition edu: PCI device 00:04.0 [1234:11e8], memory 0x",
        "edu: device 00:04.0 id 0x010000ed, interrupt line 20",
        "edu: check ok: irq_attach of its line",
        "edu: check ok: no interrupt before the device raises one",
        "edu: check ok: the raised interrupt arrives",
        "edu: check ok: the line stays masked until irq_ack though the device still asserts it",
        "edu: check ok: irq_ack",
        "edu: check ok: after irq_ack the still-asserted level fires again",
        "edu: check ok: once the device is served and the line acknowledged, nothing more comes",
        "edu: done",
        // syssw's grant: the legacy I/O BAR, the memory BARs mapped, INTA on line 23.
        "syssw: partition nic: PCI device 00:03.0 [1af4:1000], I/O 0x",
        ", interrupt line 23 (level)",
        "nic: device 00:03.0 [1af4:1000] class 020000 pin 1 line Some(23)",
        "nic: legacy host features 0x",
        "(MAC yes), device status 0x0",
        "nic: modern device features 0..31 0x",
        "(MAC yes; selected and read through memory BAR4)",
        "nic: irq_attach of its line 23: Ok(())",
        "nic: irq_attach of line 16, not granted: Err(NotPermitted)",
        "nic: done",
        "cfg: reading port 0xcf8 (PCI CONFIG_ADDRESS)",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    check(
        &o,
        o.line(", memory 0x").is_some() && o.line("nic: BAR4 memory at 0x680000").is_some(),
        "memory BARs mapped at DEVICES_BASE and after",
    );
    check(&o, o.line("check FAILED").is_none(), "a check failed");
    check(
        &o,
        o.line("configuration space reached").is_none(),
        "port 0xcf8 must fault",
    );
    check(
        &o,
        o.line("absent: started").is_none(),
        "the partition with an absent device must not start",
    );
    check(
        &o,
        o.lines.iter().any(|l| {
            l.contains("health: t=")
                && l.contains("partition=cfg error=illegal_request detail=#GP,")
                && l.ends_with("action=idle")
        }),
        "the #GP of cfg at port 0xcf8 reaches the health monitor",
    );
}
