//! The machine description the loader hands the kernel in [`crate::boot::BootInfo`]: what
//! the firmware's ACPI tables say about the CPUs, the interrupt controllers, the HPET and
//! the DMA remapping unit. The loader parses the tables (crate `acpi-tables`, length- and
//! checksum-checked, host-tested) while the firmware's services still run; the kernel only
//! reads this fixed-size block, so it parses no firmware table and needs no heap.
//!
//! Lists are arrays with a count; what does not fit is counted, never kept in part of a
//! slot. The accessors bound every count by its array, so a damaged block can shorten a
//! list but never make the kernel read past it.

/// CPUs the kernel brings up (the boot CPU included); `-smp` runs here use up to 4.
pub const MAX_CPUS: usize = 8;
/// IOAPICs listed (the kernel programs the one at GSI 0).
pub const MAX_IO_APICS: usize = 8;
/// Interrupt source overrides listed (one per ISA IRQ at most).
pub const MAX_OVERRIDES: usize = 16;
/// PCI functions a DMA remapping unit's device scopes may name.
pub const MAX_DMA_ENDPOINTS: usize = 32;

/// An IOAPIC of the MADT.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IoApicInfo {
    pub address: u64,
    pub gsi_base: u32,
    pub id: u8,
}

/// An ISA IRQ that the firmware wired to a different global system interrupt (MADT flags:
/// polarity bits 0-1, trigger bits 2-3).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InterruptOverride {
    pub gsi: u32,
    pub flags: u16,
    pub isa_irq: u8,
}

/// See the module documentation.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Machine {
    /// The RSDP's revision.
    pub acpi_revision: u32,
    /// Processor entries left out: beyond [`MAX_CPUS`], a repeated APIC ID, x2APIC-only
    /// (ID above 254, or 255, the broadcast ID) or of the wrong length (boot logs the
    /// count).
    pub cpus_ignored: u32,
    pub local_apic_address: u64,
    /// The first `cpu_count`: APIC IDs of enabled (or online-capable) processors, each
    /// once.
    pub cpu_apic_ids: [u8; MAX_CPUS],
    pub cpu_count: u32,
    pub io_apic_count: u32,
    pub io_apics: [IoApicInfo; MAX_IO_APICS],
    pub override_count: u32,
    /// IOAPIC and override entries beyond their arrays.
    pub entries_ignored: u32,
    pub overrides: [InterruptOverride; MAX_OVERRIDES],
    /// The HPET's register base; 0 without one (or one outside system memory).
    pub hpet_address: u64,
    /// The DMA remapping unit (DMAR)'s register base, when there is exactly one, on PCI
    /// segment 0, the only layout the kernel programs (QEMU's `intel-iommu`); 0 for none
    /// or any other layout (no usable IOMMU).
    pub dma_base: u64,
    /// Whether that unit translates every PCI function (INCLUDE_PCI_ALL, 1), else only
    /// `dma_endpoints` (0).
    pub dma_all: u32,
    pub dma_endpoint_count: u32,
    /// Routing ids (bus << 8 | device << 3 | function) of the unit's device scopes that
    /// name a function on the scope's bus (functions behind bridges count as not covered;
    /// more than [`MAX_DMA_ENDPOINTS`] too).
    pub dma_endpoints: [u16; MAX_DMA_ENDPOINTS],
}

impl Machine {
    /// A machine without anything (what the parser starts from).
    pub const EMPTY: Self = Self {
        acpi_revision: 0,
        cpus_ignored: 0,
        local_apic_address: 0,
        cpu_apic_ids: [0; MAX_CPUS],
        cpu_count: 0,
        io_apic_count: 0,
        io_apics: [IoApicInfo {
            address: 0,
            gsi_base: 0,
            id: 0,
        }; MAX_IO_APICS],
        override_count: 0,
        entries_ignored: 0,
        overrides: [InterruptOverride {
            gsi: 0,
            flags: 0,
            isa_irq: 0,
        }; MAX_OVERRIDES],
        hpet_address: 0,
        dma_base: 0,
        dma_all: 0,
        dma_endpoint_count: 0,
        dma_endpoints: [0; MAX_DMA_ENDPOINTS],
    };

    pub fn cpu_apic_ids(&self) -> &[u8] {
        &self.cpu_apic_ids[..(self.cpu_count as usize).min(MAX_CPUS)]
    }

    pub fn io_apics(&self) -> &[IoApicInfo] {
        &self.io_apics[..(self.io_apic_count as usize).min(MAX_IO_APICS)]
    }

    pub fn overrides(&self) -> &[InterruptOverride] {
        &self.overrides[..(self.override_count as usize).min(MAX_OVERRIDES)]
    }

    pub fn dma_endpoints(&self) -> &[u16] {
        &self.dma_endpoints[..(self.dma_endpoint_count as usize).min(MAX_DMA_ENDPOINTS)]
    }
}

impl Default for Machine {
    fn default() -> Self {
        Self::EMPTY
    }
}
