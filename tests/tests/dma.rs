//! DMA regions (`dma`, `dma_unconfined`): scenario `dma_regions` (no IOMMU), partitions of
//! `tests/programs/pci-probe`.

// The victim's window-start bound on virtual time: the one-CPU attack bound.
use crate::attack::LATENESS_BOUND_NS;
use scenarios::{boot, check};

#[test]
fn dma_regions() {
    let o = boot("dma_regions");
    for line in [
        "syssw: partition confined not started: PCI device 00:03.0: no IOMMU confines its DMA",
        "syssw: 2 partitions started",
        "syssw: partition dma: DMA region 64 KiB at 0x6c0000000000 (physical 0x",
        "WARNING: no IOMMU, its devices' DMA is not confined (dma_unconfined)",
        "dma: device 00:04.0, DMA region at 0x6c0000000000, 64 KiB, bus address 0x",
        "dma: check ok: edu copied 256 bytes from its DMA region",
        "dma: done",
        "plain: started",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    check(&o, o.line("check FAILED").is_none(), "a check failed");
    check(
        &o,
        o.line("confined: started").is_none(),
        "a partition whose DMA nothing confines must not start",
    );
    // Unconfined, the bus address is the region's physical address.
    let physical = o
        .line("syssw: partition dma: DMA region")
        .and_then(|l| l.split("(physical ").nth(1))
        .and_then(|s| s.split(',').next());
    let bus = o
        .line("dma: device 00:04.0, DMA region")
        .and_then(|l| l.split("bus address ").nth(1));
    check(
        &o,
        physical.is_some() && physical == bus,
        "unconfined, the bus address is the physical address",
    );
}

#[test]
fn attack_dma() {
    let o = boot("attack_dma");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the victim ends the run",
    );
    check(&o, o.line("KERNEL PANIC").is_none(), "the kernel panicked");
    for line in [
        "iommu: DMA remapping on (VT-d at 0xfed90000, 3-level tables, bus address = physical",
        "its devices confined to it by the IOMMU",
        "dma-attack: check ok: edu copied 256 bytes from its DMA region",
        "dma-attack: check ok: the device got none of that partition's bytes",
        "dma-attack: its own region still works after the blocked writes",
        "dma-attack: done",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    check(&o, o.line("check FAILED").is_none(), "a check failed");
    // The region's bus address is its physical address; the page below it is the victim's.
    let own = o
        .line("dma-attack: DMA region")
        .and_then(|l| l.split("(physical ").nth(1))
        .and_then(|s| s.split(',').next())
        .and_then(|s| u64::from_str_radix(s.trim_start_matches("0x"), 16).ok());
    check(&o, own.is_some(), "syssw did not log the DMA region");
    let own = own.unwrap_or(0);
    // Each blocked write (and the read) is the attacker's memory violation, the device and
    // the bus address named.
    for (target, access) in [
        (0x10_0000, "write"),
        (own - 4096, "write"),
        (0x7f_ffff_f000, "write"),
        (own - 4096, "read"),
    ] {
        let detail = format!(
            "partition=dma-attack error=memory_violation detail=dma,device=00:04.0,{access},address={target:#x},"
        );
        check(
            &o,
            o.lines.iter().any(|l| {
                l.contains("health: t=") && l.contains(&detail) && l.ends_with("action=ignore")
            }),
            &format!("no health report {detail:?}"),
        );
    }
    check(
        &o,
        o.lines
            .iter()
            .filter(|l| l.contains("error=memory_violation"))
            .count()
            == 4,
        "exactly the four blocked accesses are reported (the positive controls fault nothing)",
    );
    // The victim kept every window, each on time.
    let last = o
        .lines
        .iter()
        .rev()
        .find(|l| l.contains("victim: windows="))
        .cloned()
        .unwrap_or_default();
    let field = |name: &str| {
        last.split_whitespace()
            .find_map(|w| w.strip_prefix(name))
            .and_then(|v| v.parse::<u64>().ok())
    };
    check(
        &o,
        field("windows=") == Some(600)
            && field("missed=") == Some(0)
            && field("drift=") == Some(0)
            && field("max=").is_some_and(|max| max <= LATENESS_BOUND_NS),
        &format!("the victim did not keep its windows within {LATENESS_BOUND_NS} ns: {last:?}"),
    );
}
