//! The PCI functions a partition owns (`devices`): probed, checked and enabled once at
//! boot ([`prepare`], with `pci`'s logic over the kernel's `pci_config`), granted to every
//! instance of the partition ([`grant`]): its I/O BARs as I/O-port grants, its memory BARs
//! mapped uncached from `DEVICES_BASE` on, its INTx line, its DMA region (`dma`) at
//! `DMA_BASE`, and the read-only page of records that tells the partition what it got. A
//! function that cannot be granted alone (absent, a bridge, a BAR that shares its page, an
//! interrupt line another partition holds, DMA that nothing confines) stops only its
//! partition.
//!
//! DMA: a partition with a DMA region gets physically contiguous frames of its memory and
//! bus mastering for its functions; each function is confined to the region by the IOMMU
//! ([`confine`]) before bus mastering goes on. Without an IOMMU the partition is not
//! started, unless it says `dma_unconfined` (then a warning, and the bus address of the
//! region is its physical address).

use config::binary::PartitionView;
use pci::{
    Address, Bar, ConfigSpace, DMA_AT, DMA_SIZE, DeviceError, DmaRegion, Function, RECORD_SIZE,
    RECORDS_AT, Record,
};
use root_task::spawn::{SpawnError, Spawner};
use user_rt::abi::syscall::{Error, MAP_MAX_PAGES, PageRights, TaskId};
use user_rt::protocol::layout::{DEVICES_BASE, DMA_BASE};
use user_rt::sys;

const PAGE: u64 = 4096;

/// Configuration space through the kernel (only the root task may).
struct KernelConfigSpace;

impl ConfigSpace for KernelConfigSpace {
    fn read(&mut self, at: Address, register: u8) -> u32 {
        // An error cannot happen for the root task and an aligned register; read as absent.
        sys::pci_config(config_address(at, register), None).unwrap_or(!0)
    }

    fn write(&mut self, at: Address, register: u8, value: u32) {
        let _ = sys::pci_config(config_address(at, register), Some(value));
    }
}

fn config_address(at: Address, register: u8) -> u32 {
    pci::Address::config_address(at, register) & 0x00ff_ffff
}

/// Why a partition's devices cannot be granted.
#[derive(Debug)]
pub enum DeviceProblem {
    Function(Address, DeviceError),
    /// Its INTx line is another partition's (`irqs`) or another device's.
    SharedLine(Address, u8),
    Spawn(SpawnError),
    Kernel(&'static str, Error),
    /// It has a DMA region, no IOMMU confines the function (none, the DMAR does not list
    /// it, or its DMA passes the IOMMU by: `pci::dma_bypasses_iommu`), and it does not say
    /// `dma_unconfined`.
    Unconfined(Address),
}

impl core::fmt::Display for DeviceProblem {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Function(a, why) => write!(f, "PCI device {a}: {why}"),
            Self::SharedLine(a, line) => write!(
                f,
                "PCI device {a}: its interrupt line {line} is another partition's or another device's (a level-triggered line cannot be shared between partitions)"
            ),
            Self::Spawn(e) => write!(f, "PCI devices: out of memory or addresses: {e:?}"),
            Self::Kernel(call, e) => write!(f, "PCI devices: {call} failed: {e:?}"),
            Self::Unconfined(a) => write!(
                f,
                "PCI device {a}: no IOMMU confines its DMA to the partition's DMA region (none, or the ACPI DMAR does not list the device, or it is a transitional virtio device, whose DMA passes an IOMMU by; needs an IOMMU, e.g. QEMU's intel-iommu, or `dma_unconfined = true`)"
            ),
        }
    }
}

/// A partition's functions as granted at every start.
pub struct Devices {
    /// The frame of the records page.
    page: u64,
    functions: [Option<(Function, Record)>; pci::MAX_PARTITION_DEVICES],
    /// Its DMA region: first frame, and the region as the partition sees it.
    dma: Option<(u64, DmaRegion)>,
    /// Whether the IOMMU confines its DMA (false: `dma_unconfined` on a machine without).
    confined: bool,
}

/// Probes, checks and enables partition `p`'s functions, lays out their memory BARs from
/// `DEVICES_BASE`, allocates its DMA region and confines the functions to it, and writes
/// the records page; `lines` holds the interrupt lines taken so far (gets the new ones).
/// `None` for a partition without devices.
pub fn prepare(
    spawner: &mut Spawner,
    p: &PartitionView,
    lines: &mut u32,
) -> Result<Option<Devices>, DeviceProblem> {
    let addresses = p.devices();
    let mut cs = KernelConfigSpace;
    let mut functions = [None; pci::MAX_PARTITION_DEVICES];
    let mut next = DEVICES_BASE + 2 * PAGE;
    let mut taken = *lines;
    let mut count = 0;
    for (slot, at) in functions.iter_mut().zip(addresses) {
        let fail = |why| DeviceProblem::Function(at, why);
        let f = pci::probe(&mut cs, at).map_err(fail)?;
        pci::check_bars(&f).map_err(fail)?;
        let line = match f.interrupt_pin {
            0 => None,
            pin => Some(
                pci::q35_interrupt_line(at, pin)
                    .ok_or(fail(DeviceError::UnroutedInterrupt { pin }))?,
            ),
        };
        if let Some(line) = line {
            if taken & (1 << line) != 0 {
                return Err(DeviceProblem::SharedLine(at, line));
            }
            taken |= 1 << line;
        }
        let mut bars = f.bars;
        for bar in bars.iter_mut() {
            if let Some(Bar::Memory { base, size, .. }) = bar {
                *base = next;
                next += *size + PAGE;
            }
        }
        *slot = Some((
            f,
            Record {
                address: at,
                vendor: f.vendor,
                device: f.device,
                interrupt_line: line,
                interrupt_pin: f.interrupt_pin,
                class: f.class,
                bars,
            },
        ));
        count += 1;
    }
    if count == 0 {
        return Ok(None);
    }
    let (dma, confined) = match p.dma / PAGE {
        0 => (None, true),
        pages => {
            let frames = spawner.frames(pages).map_err(DeviceProblem::Spawn)?;
            let mut bus_address = None;
            for (f, _) in functions.iter().flatten() {
                bus_address = if pci::dma_bypasses_iommu(f.vendor, f.device) {
                    None
                } else {
                    confine(f.address, frames, pages)?
                };
                if bus_address.is_none() && !p.dma_unconfined {
                    return Err(DeviceProblem::Unconfined(f.address));
                }
            }
            let region = DmaRegion {
                address: DMA_BASE,
                length: p.dma,
                // Unconfined, a device reaches physical memory as it is.
                bus_address: bus_address.unwrap_or(frames),
            };
            (Some((frames, region)), bus_address.is_some())
        }
    };
    let page = spawner
        .filled_frames(1, |chunk, offset| {
            if offset != 0 {
                return;
            }
            chunk[..8].copy_from_slice(&(count as u64).to_le_bytes());
            for (i, (_, record)) in functions.iter().flatten().enumerate() {
                let at = RECORDS_AT + i * RECORD_SIZE;
                chunk[at..at + RECORD_SIZE].copy_from_slice(&record.encode());
                let caps = pci::read_capabilities(&mut KernelConfigSpace, record.address);
                let at = pci::CAPABILITIES_AT + i * pci::CAPABILITIES_SIZE;
                chunk[at..at + pci::CAPABILITIES_SIZE].copy_from_slice(&caps.encode());
            }
            if let Some((_, region)) = dma {
                chunk[DMA_AT..DMA_AT + DMA_SIZE].copy_from_slice(&region.encode());
            }
        })
        .map_err(DeviceProblem::Spawn)?;
    for (f, _) in functions.iter().flatten() {
        pci::enable(&mut cs, f, dma.is_some());
    }
    *lines = taken;
    Ok(Some(Devices {
        page,
        functions,
        dma,
        confined,
    }))
}

/// Confines function `at`'s DMA to the `pages` frames from `frames` through the IOMMU:
/// the bus address of the first frame, or `None` when the machine has no IOMMU.
fn confine(at: Address, frames: u64, pages: u64) -> Result<Option<u64>, DeviceProblem> {
    let mut bus_address = None;
    let mut done = 0;
    while done < pages {
        let n = (pages - done).min(MAP_MAX_PAGES);
        match sys::dma_map(at.id(), frames + done * PAGE, n) {
            Ok(bus) => {
                bus_address.get_or_insert(bus);
            }
            Err(Error::NoSuchObject) => return Ok(None),
            Err(e) => return Err(DeviceProblem::Kernel("dma_map", e)),
        }
        done += n;
    }
    Ok(bus_address)
}

/// Zeroes the DMA region (a cold restart must not see the last instance's data).
pub fn clear_dma(spawner: &mut Spawner, devices: &Devices) -> Result<(), DeviceProblem> {
    match devices.dma {
        Some((frames, region)) => spawner
            .refill_frames(frames, region.length / PAGE, |_, _| ())
            .map_err(DeviceProblem::Spawn),
        None => Ok(()),
    }
}

/// Grants `devices` to a new instance's `task`.
pub fn grant(devices: &Devices, task: TaskId) -> Result<(), DeviceProblem> {
    let kernel = |call, r: Result<(), Error>| r.map_err(|e| DeviceProblem::Kernel(call, e));
    kernel(
        "map_physical",
        sys::map_physical(
            Some(task),
            devices.page,
            DEVICES_BASE,
            1,
            PageRights::empty(),
        ),
    )?;
    for (f, record) in devices.functions.iter().flatten() {
        for (bar, granted) in f.bars.iter().zip(&record.bars) {
            match (*bar, *granted) {
                (Some(Bar::Io { port, size }), _) => {
                    kernel("io_grant", sys::io_grant(task, port, u32::from(size)))?;
                }
                (Some(Bar::Memory { base, size, .. }), Some(Bar::Memory { base: at, .. })) => {
                    let pages = size / PAGE;
                    let mut done = 0;
                    while done < pages {
                        let n = (pages - done).min(MAP_MAX_PAGES);
                        let (from, to) = (base + done * PAGE, at + done * PAGE);
                        kernel(
                            "map_device",
                            sys::map_device(Some(task), from, to, n, PageRights::WRITE),
                        )?;
                        done += n;
                    }
                }
                _ => {}
            }
        }
        if let Some(line) = record.interrupt_line {
            kernel("irq_grant", sys::irq_grant(task, u64::from(line)))?;
        }
    }
    if let Some((frames, region)) = devices.dma {
        root_task::spawn::map_physical_chunked(
            Some(task),
            frames,
            region.address,
            region.length / PAGE,
            PageRights::WRITE,
        )
        .map_err(DeviceProblem::Spawn)?;
    }
    Ok(())
}

/// One log line per function: what the partition got.
pub fn log(partition: &str, devices: &Devices) {
    use core::fmt::Write;
    for (f, record) in devices.functions.iter().flatten() {
        let mut line = user_rt::print::LineBuffer::default();
        let _ = write!(
            line,
            "syssw: partition {partition}: PCI device {} [{:04x}:{:04x}]",
            f.address, f.vendor, f.device
        );
        for (bar, granted) in f.bars.iter().zip(&record.bars) {
            let _ = match (*bar, *granted) {
                (Some(Bar::Io { port, size }), _) => write!(line, ", I/O {port:#x}+{size}"),
                (Some(Bar::Memory { base, size, .. }), Some(Bar::Memory { base: at, .. })) => {
                    write!(line, ", memory {base:#x}+{size:#x} at {at:#x}")
                }
                _ => Ok(()),
            };
        }
        let _ = match record.interrupt_line {
            Some(line_no) => write!(line, ", interrupt line {line_no} (level)"),
            None => write!(line, ", no interrupt"),
        };
        let _ = sys::debug_write(line.as_bytes());
    }
    if let Some((frames, region)) = devices.dma {
        let mut line = user_rt::print::LineBuffer::default();
        let _ = write!(
            line,
            "syssw: partition {partition}: DMA region {} KiB at {:#x} (physical {frames:#x}, bus address {:#x}), ",
            region.length / 1024,
            region.address,
            region.bus_address
        );
        let _ = if devices.confined {
            write!(line, "its devices confined to it by the IOMMU")
        } else {
            write!(
                line,
                "WARNING: no IOMMU, its devices' DMA is not confined (dma_unconfined)"
            )
        };
        let _ = sys::debug_write(line.as_bytes());
    }
}
