//! DMA regions (`dma`, `dma_unconfined`): scenario `dma_regions` (no IOMMU), partitions of
//! `tests/programs/pci-probe`.

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
