//! PCI functions a partition owns: bus addresses (`00:03.0`), what a function's
//! configuration header says (identity, base address registers and their sizes, interrupt
//! pin), the interrupt line its INTx reaches on QEMU's q35, and the record that tells a
//! partition what it was granted. Pure logic over a [`ConfigSpace`]; syssw runs it over the
//! kernel's `pci_config` call at boot, the tests over a fake configuration space.
//!
//! No partition ever reaches configuration space: the kernel keeps its ports
//! ([`CONFIG_PORTS`]) and never maps ECAM. A partition gets exactly its functions' BARs: I/O
//! BARs as I/O-port grants, memory BARs mapped uncached, and the INTx line.
#![no_std]

#[cfg(test)]
extern crate std;

/// The ports of configuration mechanism #1 (CONFIG_ADDRESS at 0xcf8, CONFIG_DATA at
/// 0xcfc..=0xcff); the kernel keeps all eight.
pub const CONFIG_PORTS: (u16, u16) = (0xcf8, 0xcff);

/// Registers of a type-0 configuration header.
pub const ID: u8 = 0x00;
pub const COMMAND: u8 = 0x04;
pub const CLASS: u8 = 0x08;
pub const HEADER: u8 = 0x0c;
pub const BAR0: u8 = 0x10;
pub const INTERRUPT: u8 = 0x3c;
/// The first capability's offset (low byte), valid when the status register says
/// [`STATUS_CAPABILITIES`].
pub const CAPABILITIES_POINTER: u8 = 0x34;
/// The status register's (high half of [`COMMAND`]) "capabilities list" bit.
pub const STATUS_CAPABILITIES: u32 = 1 << 20;
/// Where a type-0 header ends and the device-specific area (capabilities) begins.
pub const DEVICE_AREA: u8 = 0x40;
/// Bytes of the device-specific area (0x40..0x100) copied into a [`Record`].
pub const DEVICE_AREA_SIZE: usize = 256 - DEVICE_AREA as usize;

/// Command-register bits.
pub const COMMAND_IO: u32 = 1 << 0;
pub const COMMAND_MEMORY: u32 = 1 << 1;
pub const COMMAND_BUS_MASTER: u32 = 1 << 2;
pub const COMMAND_INTX_DISABLE: u32 = 1 << 10;

/// Base address registers of a type-0 header.
pub const BARS: usize = 6;
/// Memory BARs must be whole pages: a smaller one shares its page with other registers.
pub const PAGE: u64 = 4096;

/// A function's bus address: `bus:device.function`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Address {
    pub bus: u8,
    /// 0..32.
    pub device: u8,
    /// 0..8.
    pub function: u8,
}

/// Why a text is not a PCI address.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AddressError {
    /// Not `BB:DD.F` with hexadecimal digits.
    Form,
    /// A device number of 32 or more.
    Device(u8),
    /// A function number of 8 or more.
    Function(u8),
}

impl core::fmt::Display for AddressError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Form => write!(
                f,
                "expected BUS:DEVICE.FUNCTION in hexadecimal digits, such as \"00:03.0\""
            ),
            Self::Device(d) => write!(f, "device {d:#x} is beyond the 32 devices of a bus"),
            Self::Function(n) => write!(f, "function {n} is beyond the 8 functions of a device"),
        }
    }
}

impl Address {
    /// `BB:DD.F` (hex; an optional `0000:` segment in front, as `lspci -D` prints).
    pub fn parse(text: &str) -> Result<Self, AddressError> {
        let text = text.strip_prefix("0000:").unwrap_or(text);
        let hex = |s: &str| {
            (!s.is_empty() && s.len() <= 2 && s.bytes().all(|b| b.is_ascii_hexdigit()))
                .then(|| u8::from_str_radix(s, 16).ok())
                .flatten()
        };
        let (bus, rest) = text.split_once(':').ok_or(AddressError::Form)?;
        let (device, function) = rest.split_once('.').ok_or(AddressError::Form)?;
        let (Some(bus), Some(device), Some(function)) = (hex(bus), hex(device), hex(function))
        else {
            return Err(AddressError::Form);
        };
        if device >= 32 {
            return Err(AddressError::Device(device));
        }
        if function >= 8 {
            return Err(AddressError::Function(function));
        }
        Ok(Self {
            bus,
            device,
            function,
        })
    }

    /// The 16-bit routing id (bus << 8 | device << 3 | function), as the binary
    /// configuration stores it.
    pub const fn id(self) -> u16 {
        (self.bus as u16) << 8 | (self.device as u16) << 3 | self.function as u16
    }

    pub const fn from_id(id: u16) -> Self {
        Self {
            bus: (id >> 8) as u8,
            device: (id >> 3) as u8 & 31,
            function: id as u8 & 7,
        }
    }

    /// The CONFIG_ADDRESS value of dword register `register` (mechanism #1).
    pub const fn config_address(self, register: u8) -> u32 {
        1 << 31 | (self.id() as u32) << 8 | (register & 0xfc) as u32
    }
}

impl core::fmt::Display for Address {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{:02x}:{:02x}.{:x}",
            self.bus, self.device, self.function
        )
    }
}

/// Dword access to configuration space (`register` dword-aligned, < 256).
pub trait ConfigSpace {
    fn read(&mut self, at: Address, register: u8) -> u32;
    fn write(&mut self, at: Address, register: u8, value: u32);
}

/// A decoded base address register.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bar {
    Io {
        port: u16,
        size: u16,
    },
    Memory {
        base: u64,
        size: u64,
        prefetchable: bool,
    },
}

/// What a function's configuration header says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Function {
    pub address: Address,
    pub vendor: u16,
    pub device: u16,
    /// class << 16 | subclass << 8 | programming interface.
    pub class: u32,
    /// INTx pin: 0 none, 1..=4 INTA..INTD.
    pub interrupt_pin: u8,
    pub bars: [Option<Bar>; BARS],
}

/// A read-only copy of a function's capability list: the first capability's offset (0:
/// none) and configuration space 0x40..0x100, where the list lives. A driver needs it to
/// find its registers (a virtio device's structures are located by vendor capabilities)
/// without ever reaching configuration space; syssw puts it in the device page
/// ([`capabilities`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capabilities {
    pub first: u8,
    pub area: [u8; DEVICE_AREA_SIZE],
}

impl Default for Capabilities {
    fn default() -> Self {
        Capabilities {
            first: 0,
            area: [0; DEVICE_AREA_SIZE],
        }
    }
}

/// One capability: its id and its bytes from its header to the end of configuration space
/// (its own length is capability-specific).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capability<'a> {
    pub id: u8,
    /// Its offset in configuration space.
    pub offset: u8,
    pub bytes: &'a [u8],
}

/// Most capabilities a list can hold (each at least 4 bytes in 0x40..0x100); bounds the walk
/// of a damaged, cyclic list.
const MAX_CAPABILITIES: usize = DEVICE_AREA_SIZE / 4;

impl Capabilities {
    /// The capabilities in list order; the walk stops at a pointer outside 0x40..0xfc, and
    /// after [`MAX_CAPABILITIES`] entries (a list that loops).
    pub fn iter(&self) -> impl Iterator<Item = Capability<'_>> + '_ {
        let mut next = self.first;
        let mut seen = 0;
        core::iter::from_fn(move || {
            if seen >= MAX_CAPABILITIES || !(DEVICE_AREA..=0xfc).contains(&next) {
                return None;
            }
            seen += 1;
            let offset = next & !3;
            let at = usize::from(offset - DEVICE_AREA);
            let bytes = &self.area[at..];
            next = bytes[1];
            Some(Capability {
                id: bytes[0],
                offset,
                bytes,
            })
        })
    }
}

/// Why a function cannot be given to a partition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeviceError {
    /// Nothing answers at the address.
    Absent,
    /// A bridge or other header type than a plain function (type 0).
    NotEndpoint { header_type: u8 },
    /// A memory BAR that is not whole, aligned pages.
    PartialPage { bar: usize, base: u64, size: u64 },
    /// An I/O BAR over the configuration ports.
    ConfigPorts { bar: usize },
    /// An INTx pin whose interrupt line is not known on this machine.
    UnroutedInterrupt { pin: u8 },
}

impl core::fmt::Display for DeviceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Absent => write!(f, "no such device at boot"),
            Self::NotEndpoint { header_type } => write!(
                f,
                "header type {header_type:#x} is not a plain function (bridges cannot be granted)"
            ),
            Self::PartialPage { bar, base, size } => write!(
                f,
                "memory BAR{bar} ({base:#x}, {size:#x} bytes) is not whole 4 KiB pages, which cannot be mapped without the registers beside it"
            ),
            Self::ConfigPorts { bar } => {
                write!(f, "I/O BAR{bar} covers the configuration ports 0xcf8-0xcff")
            }
            Self::UnroutedInterrupt { pin } => write!(
                f,
                "its INT{} pin has no known interrupt line (only bus 0, devices 0..24 are routed)",
                (b'A' + pin.saturating_sub(1)) as char
            ),
        }
    }
}

/// Copies function `at`'s capability list (none when its status register says it has no
/// list).
pub fn read_capabilities(cs: &mut impl ConfigSpace, at: Address) -> Capabilities {
    let mut capabilities = Capabilities::default();
    if cs.read(at, COMMAND) & STATUS_CAPABILITIES != 0 {
        capabilities.first = cs.read(at, CAPABILITIES_POINTER) as u8;
        for (i, word) in capabilities.area.chunks_exact_mut(4).enumerate() {
            word.copy_from_slice(&cs.read(at, DEVICE_AREA + 4 * i as u8).to_le_bytes());
        }
    }
    capabilities
}

/// Reads function `at`'s header and sizes its BARs (decoding is off meanwhile and the
/// command register restored after). Only plain functions (header type 0) are accepted.
pub fn probe(cs: &mut impl ConfigSpace, at: Address) -> Result<Function, DeviceError> {
    let id = cs.read(at, ID);
    if id & 0xffff == 0xffff || id & 0xffff == 0 {
        return Err(DeviceError::Absent);
    }
    let header_type = (cs.read(at, HEADER) >> 16) as u8 & 0x7f;
    if header_type != 0 {
        return Err(DeviceError::NotEndpoint { header_type });
    }
    let command = cs.read(at, COMMAND) & 0xffff;
    cs.write(at, COMMAND, command & !(COMMAND_IO | COMMAND_MEMORY));
    let mut bars = [None; BARS];
    let mut i = 0;
    while i < BARS {
        let (bar, wide) = size_bar(cs, at, i);
        bars[i] = bar;
        i += if wide { 2 } else { 1 };
    }
    cs.write(at, COMMAND, command);
    Ok(Function {
        address: at,
        vendor: id as u16,
        device: (id >> 16) as u16,
        class: cs.read(at, CLASS) >> 8,
        interrupt_pin: (cs.read(at, INTERRUPT) >> 8) as u8,
        bars,
    })
}

/// BAR `i` of `at`, sized by writing all ones and reading back; whether it took two
/// registers (a 64-bit memory BAR).
fn size_bar(cs: &mut impl ConfigSpace, at: Address, i: usize) -> (Option<Bar>, bool) {
    let register = BAR0 + 4 * i as u8;
    let original = cs.read(at, register);
    cs.write(at, register, !0);
    let mask = cs.read(at, register);
    cs.write(at, register, original);
    if original & 1 == 1 {
        let mask = mask & 0xffff_fffc & 0xffff;
        if mask == 0 {
            return (None, false);
        }
        let size = (!mask).wrapping_add(1) as u16;
        let port = (original & 0xfffc) as u16;
        return (Some(Bar::Io { port, size }), false);
    }
    let wide = (original >> 1) & 3 == 2 && i + 1 < BARS;
    let (mut base, mut mask) = (u64::from(original & !0xf), u64::from(mask & !0xf));
    if wide {
        let high = register + 4;
        let original_high = cs.read(at, high);
        cs.write(at, high, !0);
        let mask_high = cs.read(at, high);
        cs.write(at, high, original_high);
        base |= u64::from(original_high) << 32;
        mask |= u64::from(mask_high) << 32;
    } else if mask != 0 {
        // A 32-bit BAR decodes nothing above 4 GiB.
        mask |= 0xffff_ffff_0000_0000;
    }
    if mask == 0 {
        return (None, wide);
    }
    let size = (!mask).wrapping_add(1);
    let prefetchable = original & 8 != 0;
    (
        Some(Bar::Memory {
            base,
            size,
            prefetchable,
        }),
        wide,
    )
}

/// Checks that every BAR of `f` can be granted alone: memory BARs whole, aligned pages,
/// no I/O BAR over the configuration ports.
pub fn check_bars(f: &Function) -> Result<(), DeviceError> {
    for (bar, b) in f.bars.iter().enumerate() {
        match *b {
            Some(Bar::Memory { base, size, .. })
                if size < PAGE || base % PAGE != 0 || size % PAGE != 0 =>
            {
                return Err(DeviceError::PartialPage { bar, base, size });
            }
            Some(Bar::Io { port, size })
                if u32::from(port) <= u32::from(CONFIG_PORTS.1)
                    && u32::from(CONFIG_PORTS.0) < u32::from(port) + u32::from(size) =>
            {
                return Err(DeviceError::ConfigPorts { bar });
            }
            _ => {}
        }
    }
    Ok(())
}

/// The IOAPIC input the INTx pin `pin` (1..=4) of `at` reaches on QEMU's q35 (ICH9): a
/// device `d` < 25 on bus 0 has INTA..INTD on PIRQ E..H, rotated by `d`
/// (`(d + pin - 1) % 4 + 4`), and PIRQ n is IOAPIC input 16 + n (QEMU's `ich9_cc_init` and the ACPI `_PRT` it
/// builds). Level-triggered, shared by every function wired to the same PIRQ. `None` for
/// no pin or a device QEMU routes otherwise (devices 25..31 through chipset registers,
/// functions behind bridges).
pub fn q35_interrupt_line(at: Address, pin: u8) -> Option<u8> {
    if !(1..=4).contains(&pin) || at.bus != 0 || at.device >= 25 {
        return None;
    }
    Some(16 + (at.device + pin - 1) % 4 + 4)
}

/// Turns decoding on for the kinds of BARs `f` has and lets it raise INTx; bus mastering
/// (DMA) only with `bus_master` (a partition with a DMA region).
pub fn enable(cs: &mut impl ConfigSpace, f: &Function, bus_master: bool) {
    let mut command = cs.read(f.address, COMMAND) & 0xffff;
    for bar in f.bars.iter().flatten() {
        command |= match bar {
            Bar::Io { .. } => COMMAND_IO,
            Bar::Memory { .. } => COMMAND_MEMORY,
        };
    }
    command &= !(COMMAND_INTX_DISABLE | COMMAND_BUS_MASTER);
    if bus_master {
        command |= COMMAND_BUS_MASTER;
    }
    // The status half is write-one-to-clear: writing zeros there changes nothing.
    cs.write(f.address, COMMAND, command);
}

/// What a partition learns about one of its functions: the page syssw maps read-only at
/// `protocol::layout::DEVICES_BASE` holds a little-endian `u64` count, then one
/// [`RECORD_SIZE`]-byte record per function in configuration order:
///
/// | offset | size | field |
/// |---|---|---|
/// | 0 | 2 | routing id ([`Address::id`]) |
/// | 2 | 2 | vendor id |
/// | 4 | 2 | device id |
/// | 6 | 1 | interrupt line granted (IOAPIC input; 0xff: none) |
/// | 7 | 1 | interrupt pin (0 none, 1..=4 INTA..INTD) |
/// | 8 | 4 | class << 16 \| subclass << 8 \| programming interface |
/// | 16 + 16·i | 8 | BAR i: the first port (I/O) or the address it is mapped at (memory) |
/// | 24 + 16·i | 4 | BAR i: size in bytes |
/// | 28 + 16·i | 4 | BAR i: kind (0 none, 1 I/O, 2 memory) |
///
/// From [`CAPABILITIES_AT`], one [`CAPABILITIES_SIZE`]-byte copy of each function's
/// capability list in the same order: the first capability's offset (0: none), then
/// configuration space 0x40..0x100 ([`capabilities`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    pub address: Address,
    pub vendor: u16,
    pub device: u16,
    pub interrupt_line: Option<u8>,
    pub interrupt_pin: u8,
    pub class: u32,
    /// Memory BARs with the partition's address of their first byte as `base`.
    pub bars: [Option<Bar>; BARS],
}

pub const RECORD_SIZE: usize = 112;
/// Where the capability lists start in the device page, and the size of each.
pub const CAPABILITIES_AT: usize = 2048;
pub const CAPABILITIES_SIZE: usize = 1 + DEVICE_AREA_SIZE;
/// Functions one partition may own (the records fit in one page).
pub const MAX_PARTITION_DEVICES: usize = 8;
/// Where the first record starts in the device page.
pub const RECORDS_AT: usize = 16;

impl Record {
    pub fn encode(&self) -> [u8; RECORD_SIZE] {
        let mut out = [0u8; RECORD_SIZE];
        out[0..2].copy_from_slice(&self.address.id().to_le_bytes());
        out[2..4].copy_from_slice(&self.vendor.to_le_bytes());
        out[4..6].copy_from_slice(&self.device.to_le_bytes());
        out[6] = self.interrupt_line.unwrap_or(0xff);
        out[7] = self.interrupt_pin;
        out[8..12].copy_from_slice(&self.class.to_le_bytes());
        for (i, bar) in self.bars.iter().enumerate() {
            let (base, size, kind) = match *bar {
                None => (0, 0, 0u32),
                Some(Bar::Io { port, size }) => (u64::from(port), u32::from(size), 1),
                Some(Bar::Memory { base, size, .. }) => (base, size.min(u32::MAX.into()) as u32, 2),
            };
            let at = 16 + 16 * i;
            out[at..at + 8].copy_from_slice(&base.to_le_bytes());
            out[at + 8..at + 12].copy_from_slice(&size.to_le_bytes());
            out[at + 12..at + 16].copy_from_slice(&kind.to_le_bytes());
        }
        out
    }

    /// The record in `bytes`; `None` for an unknown BAR kind.
    pub fn decode(bytes: &[u8; RECORD_SIZE]) -> Option<Self> {
        let u16_at = |at: usize| u16::from_le_bytes([bytes[at], bytes[at + 1]]);
        let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        let mut bars = [None; BARS];
        for (i, bar) in bars.iter_mut().enumerate() {
            let at = 16 + 16 * i;
            let base = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
            let size = u32_at(at + 8);
            *bar = match u32_at(at + 12) {
                0 => None,
                1 => Some(Bar::Io {
                    port: base as u16,
                    size: size as u16,
                }),
                2 => Some(Bar::Memory {
                    base,
                    size: size.into(),
                    prefetchable: false,
                }),
                _ => return None,
            };
        }
        Some(Self {
            address: Address::from_id(u16_at(0)),
            vendor: u16_at(2),
            device: u16_at(4),
            interrupt_line: (bytes[6] != 0xff).then_some(bytes[6]),
            interrupt_pin: bytes[7],
            class: u32_at(8),
            bars,
        })
    }
}

/// Whether the function's DMA would pass an IOMMU by: a transitional virtio device (vendor
/// 0x1af4, device 0x1000..=0x103f) cannot offer VIRTIO_F_ACCESS_PLATFORM, and without it
/// QEMU gives a virtio device physical memory directly. (A modern one, 0x1040.., is
/// translated only with QEMU's `iommu_platform=on`, which configuration space does not
/// show.)
pub fn dma_bypasses_iommu(vendor: u16, device: u16) -> bool {
    vendor == 0x1af4 && (0x1000..=0x103f).contains(&device)
}

/// Where the device page describes the partition's DMA region (after the records).
pub const DMA_AT: usize = RECORDS_AT + MAX_PARTITION_DEVICES * RECORD_SIZE;
/// Bytes of that description.
pub const DMA_SIZE: usize = 24;

/// The partition's DMA region (`dma`): physically contiguous memory of the partition that
/// its devices may reach, mapped read-write at `address` in the partition for `length`
/// bytes. A device must be given `bus_address + offset` for the byte at `address +
/// offset` (with an IOMMU the kernel translates exactly this range to the region and
/// nothing else; see docs/isolation.md). In the device page at [`DMA_AT`]: the address,
/// the length and the bus address as little-endian `u64`s, a length of 0 for none.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DmaRegion {
    pub address: u64,
    pub length: u64,
    pub bus_address: u64,
}

impl DmaRegion {
    pub fn encode(&self) -> [u8; DMA_SIZE] {
        let mut out = [0u8; DMA_SIZE];
        out[0..8].copy_from_slice(&self.address.to_le_bytes());
        out[8..16].copy_from_slice(&self.length.to_le_bytes());
        out[16..24].copy_from_slice(&self.bus_address.to_le_bytes());
        out
    }

    /// The bus address of the byte at partition address `at`, if `at` lies in the region.
    pub fn bus_address_of(&self, at: u64) -> Option<u64> {
        let offset = at.checked_sub(self.address)?;
        (offset < self.length).then(|| self.bus_address + offset)
    }
}

/// The DMA region a device page describes; `None` for a partition without `dma` (or a page
/// too short to hold the description).
pub fn dma_region(page: &[u8]) -> Option<DmaRegion> {
    let bytes = page.get(DMA_AT..DMA_AT + DMA_SIZE)?;
    let at = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().unwrap());
    let region = DmaRegion {
        address: at(0),
        length: at(8),
        bus_address: at(16),
    };
    (region.length != 0).then_some(region)
}

/// The records of a device page (as many as its count says, at most
/// [`MAX_PARTITION_DEVICES`]).
pub fn records(page: &[u8]) -> impl Iterator<Item = Record> + '_ {
    let count = page
        .get(..8)
        .map_or(0, |c| u64::from_le_bytes(c.try_into().unwrap()) as usize)
        .min(MAX_PARTITION_DEVICES);
    (0..count).filter_map(move |i| {
        let at = RECORDS_AT + i * RECORD_SIZE;
        page.get(at..at + RECORD_SIZE)
            .and_then(|b| Record::decode(b.try_into().unwrap()))
    })
}

impl Capabilities {
    /// Its bytes in the device page.
    pub fn encode(&self) -> [u8; CAPABILITIES_SIZE] {
        let mut out = [0u8; CAPABILITIES_SIZE];
        out[0] = self.first;
        out[1..].copy_from_slice(&self.area);
        out
    }
}

/// The capability list of the device page's function `index` (an empty list past the
/// page's functions or its end).
pub fn capabilities(page: &[u8], index: usize) -> Capabilities {
    let at = CAPABILITIES_AT + index * CAPABILITIES_SIZE;
    let mut c = Capabilities::default();
    if index < MAX_PARTITION_DEVICES
        && let Some(bytes) = page.get(at..at + CAPABILITIES_SIZE)
    {
        c.first = bytes[0];
        c.area.copy_from_slice(&bytes[1..]);
    }
    c
}

/// What a driver partition takes from its device page to drive one function: the record
/// and capabilities of the first function with the vendor and one of the device ids, its
/// interrupt line, and the partition's DMA region.
#[derive(Clone, Debug)]
pub struct Claim {
    pub record: Record,
    pub capabilities: Capabilities,
    pub line: u8,
    pub region: DmaRegion,
}

/// Why a driver partition cannot drive the function it looks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClaimError {
    /// None of the partition's `devices` has the vendor and a device id.
    NoFunction,
    /// The function has no interrupt line (the configuration gives it none).
    NoInterruptLine(Address),
    /// The partition has no `dma` (or, without an IOMMU, no `dma_unconfined = true`).
    NoDmaRegion,
}

impl core::fmt::Display for ClaimError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoFunction => f.write_str("no such function among the partition's devices"),
            Self::NoInterruptLine(at) => write!(f, "{at} has no interrupt line"),
            Self::NoDmaRegion => f.write_str(
                "no DMA region (the partition needs `dma`, and `dma_unconfined = true` without an IOMMU)",
            ),
        }
    }
}

/// The first function of the device page with `vendor` and one of `devices`, with what a
/// driver needs besides (see [`Claim`]).
pub fn claim(page: &[u8], vendor: u16, devices: &[u16]) -> Result<Claim, ClaimError> {
    let (index, record) = records(page)
        .enumerate()
        .find(|(_, r)| r.vendor == vendor && devices.contains(&r.device))
        .ok_or(ClaimError::NoFunction)?;
    let line = record
        .interrupt_line
        .ok_or(ClaimError::NoInterruptLine(record.address))?;
    let region = dma_region(page).ok_or(ClaimError::NoDmaRegion)?;
    Ok(Claim {
        capabilities: capabilities(page, index),
        record,
        line,
        region,
    })
}

#[cfg(test)]
mod tests;
