//! ACPI table discovery: RSDP -> XSDT/RSDT -> MADT (local APIC, IOAPICs, interrupt source
//! overrides, CPUs), HPET and DMAR (the VT-d DMA remapping unit). Pure parsing over a [`PhysMemory`] view, so it is host-tested
//! with synthetic tables; every table is length- and checksum-checked before use.

extern crate alloc;

use alloc::vec::Vec;

/// Read access to physical memory (the direct map on the target).
pub trait PhysMemory {
    /// `len` bytes at physical address `phys`, or `None` if not mapped.
    fn bytes(&self, phys: u64, len: usize) -> Option<&[u8]>;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IoApicInfo {
    pub id: u8,
    pub address: u64,
    pub gsi_base: u32,
}

/// An ISA IRQ that the firmware wired to a different global system interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InterruptOverride {
    pub isa_irq: u8,
    pub gsi: u32,
    pub flags: u16,
}

/// Electrical properties of a global system interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Signal {
    pub active_low: bool,
    pub level_triggered: bool,
}

/// How input `gsi` is signalled: as an override (MADT flags: polarity bits 0-1, trigger
/// bits 2-3; 0b11 = active low / level, 0b00 = the bus default) says, else ISA inputs
/// (< 16) are edge-triggered active high and PCI inputs level-triggered active low.
pub fn signal_of(gsi: u32, overrides: &[InterruptOverride]) -> Signal {
    let isa = gsi < 16;
    let default = Signal {
        active_low: !isa,
        level_triggered: !isa,
    };
    match overrides.iter().find(|o| o.gsi == gsi) {
        None => default,
        Some(o) => Signal {
            active_low: match o.flags & 3 {
                0 => default.active_low,
                p => p == 3,
            },
            level_triggered: match (o.flags >> 2) & 3 {
                0 => default.level_triggered,
                t => t == 3,
            },
        },
    }
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AcpiInfo {
    pub revision: u8,
    pub local_apic_address: u64,
    /// APIC IDs of enabled (or online-capable) processors, at most [`MAX_CPUS`], each once.
    pub cpu_apic_ids: Vec<u8>,
    /// Processor entries left out: beyond [`MAX_CPUS`], a repeated APIC ID, x2APIC-only
    /// (ID above 254, or 255, the broadcast ID) or of the wrong length. Boot logs the count.
    pub cpus_ignored: usize,
    pub io_apics: Vec<IoApicInfo>,
    pub overrides: Vec<InterruptOverride>,
    pub hpet_address: Option<u64>,
    /// The DMA remapping unit (DMAR), when there is exactly one, on PCI segment 0: the
    /// only layout the kernel programs (QEMU's `intel-iommu`); any other means no usable
    /// IOMMU.
    pub dma_remapping: Option<DmaRemapping>,
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DmaRemapping {
    /// Its register base.
    pub base: u64,
    /// Whether it translates every PCI function (INCLUDE_PCI_ALL); else only `endpoints`:
    /// the routing ids (bus << 8 | device << 3 | function) of its device scopes that name
    /// a function on the scope's bus (functions behind bridges count as not covered).
    pub all: bool,
    pub endpoints: Vec<u16>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AcpiError {
    NoRsdp,
    BadRsdp(&'static str),
    Unmapped(u64),
    BadTable([u8; 4], &'static str),
    NoMadt,
}

impl core::fmt::Display for AcpiError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoRsdp => write!(f, "the firmware reported no ACPI RSDP"),
            Self::BadRsdp(why) => write!(f, "invalid RSDP: {why}"),
            Self::Unmapped(at) => write!(f, "ACPI table at {at:#x} is outside mapped memory"),
            Self::BadTable(sig, why) => {
                write!(
                    f,
                    "ACPI table {}: {why}",
                    core::str::from_utf8(sig).unwrap_or("????")
                )
            }
            Self::NoMadt => write!(
                f,
                "no MADT (APIC table): cannot find the interrupt controllers"
            ),
        }
    }
}

/// CPUs the kernel brings up (the boot CPU included); the machines have up to 4.
pub const MAX_CPUS: usize = 8;

fn checksum_ok(bytes: &[u8]) -> bool {
    bytes.iter().fold(0u8, |sum, b| sum.wrapping_add(*b)) == 0
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    (u32_at(b, at) as u64) | ((u32_at(b, at + 4) as u64) << 32)
}

const HEADER_LEN: usize = 36;

/// A checked system-description table (header + body).
fn table(mem: &impl PhysMemory, phys: u64) -> Result<([u8; 4], &[u8]), AcpiError> {
    let header = mem
        .bytes(phys, HEADER_LEN)
        .ok_or(AcpiError::Unmapped(phys))?;
    let mut signature = [0u8; 4];
    signature.copy_from_slice(&header[0..4]);
    let len = u32_at(header, 4) as usize;
    if len < HEADER_LEN {
        return Err(AcpiError::BadTable(
            signature,
            "length shorter than its header",
        ));
    }
    let bytes = mem.bytes(phys, len).ok_or(AcpiError::Unmapped(phys))?;
    if !checksum_ok(bytes) {
        return Err(AcpiError::BadTable(signature, "checksum mismatch"));
    }
    Ok((signature, bytes))
}

pub fn parse(rsdp: u64, mem: &impl PhysMemory) -> Result<AcpiInfo, AcpiError> {
    if rsdp == 0 {
        return Err(AcpiError::NoRsdp);
    }
    let v1 = mem.bytes(rsdp, 20).ok_or(AcpiError::Unmapped(rsdp))?;
    if &v1[0..8] != b"RSD PTR " {
        return Err(AcpiError::BadRsdp("bad signature"));
    }
    if !checksum_ok(v1) {
        return Err(AcpiError::BadRsdp("checksum mismatch"));
    }
    let revision = v1[15];
    // Revision 2+ has a 64-bit XSDT; otherwise use the 32-bit RSDT.
    let (root, entry_size) = if revision >= 2 {
        let v2 = mem.bytes(rsdp, 36).ok_or(AcpiError::Unmapped(rsdp))?;
        if !checksum_ok(v2) {
            return Err(AcpiError::BadRsdp("extended checksum mismatch"));
        }
        (u64_at(v2, 24), 8)
    } else {
        (u32_at(v1, 16) as u64, 4)
    };
    let (signature, root_table) = table(mem, root)?;
    if signature != *b"XSDT" && signature != *b"RSDT" {
        return Err(AcpiError::BadTable(
            signature,
            "root table is neither XSDT nor RSDT",
        ));
    }
    let mut info = AcpiInfo {
        revision,
        ..AcpiInfo::default()
    };
    let mut found_madt = false;
    for entry in root_table[HEADER_LEN..].chunks_exact(entry_size) {
        let phys = if entry_size == 8 {
            u64_at(entry, 0)
        } else {
            u32_at(entry, 0) as u64
        };
        let (signature, body) = table(mem, phys)?;
        match &signature {
            b"APIC" => {
                parse_madt(body, &mut info)?;
                found_madt = true;
            }
            b"DMAR" => info.dma_remapping = parse_dmar(body)?,
            b"HPET" => {
                if body.len() < 52 {
                    return Err(AcpiError::BadTable(signature, "too short"));
                }
                // Generic address structure at 40: space id 0 = system memory.
                if body[40] == 0 {
                    info.hpet_address = Some(u64_at(body, 44));
                }
            }
            _ => {}
        }
    }
    if !found_madt {
        return Err(AcpiError::NoMadt);
    }
    Ok(info)
}

/// The DMAR table's single remapping unit (see [`AcpiInfo::dma_remapping`]). Remapping
/// structures start at 48: type (u16), length (u16); type 0 (DRHD) has flags at 4 (bit 0
/// INCLUDE_PCI_ALL), the segment at 6, the register base at 8 and device scopes from 16:
/// type (1 = endpoint), length, 2 reserved, enumeration id, start bus, then (device,
/// function) path entries.
fn parse_dmar(dmar: &[u8]) -> Result<Option<DmaRemapping>, AcpiError> {
    const SIG: [u8; 4] = *b"DMAR";
    let bad = |why| Err(AcpiError::BadTable(SIG, why));
    if dmar.len() < 48 {
        return bad("too short");
    }
    let (mut units, mut found) = (0, None);
    let mut at = 48;
    while at + 4 <= dmar.len() {
        let (kind, len) = (u16_at(dmar, at), usize::from(u16_at(dmar, at + 2)));
        if len < 4 || at + len > dmar.len() {
            return bad("structure length runs past the table");
        }
        if kind == 0 {
            if len < 16 {
                return bad("DRHD shorter than 16 bytes");
            }
            units += 1;
            let mut unit = DmaRemapping {
                base: u64_at(dmar, at + 8),
                all: dmar[at + 4] & 1 != 0,
                endpoints: Vec::new(),
            };
            let mut scope = at + 16;
            while scope + 2 <= at + len {
                let end = scope + usize::from(dmar[scope + 1]);
                if end < scope + 6 || end > at + len {
                    return bad("device scope shorter than 6 bytes or past its DRHD");
                }
                let s = &dmar[scope..end];
                if s[0] == 1 && s.len() == 8 {
                    let id =
                        u16::from(s[5]) << 8 | u16::from(s[6] & 0x1f) << 3 | u16::from(s[7] & 7);
                    unit.endpoints.push(id);
                }
                scope += s.len();
            }
            found = (u16_at(dmar, at + 6) == 0).then_some(unit);
        }
        at += len;
    }
    Ok(if units == 1 { found } else { None })
}

fn parse_madt(madt: &[u8], info: &mut AcpiInfo) -> Result<(), AcpiError> {
    const SIG: [u8; 4] = *b"APIC";
    if madt.len() < 44 {
        return Err(AcpiError::BadTable(SIG, "too short"));
    }
    info.local_apic_address = u32_at(madt, 36) as u64;
    let mut at = 44;
    while at + 2 <= madt.len() {
        let (kind, len) = (madt[at], madt[at + 1] as usize);
        if len < 2 || at + len > madt.len() {
            return Err(AcpiError::BadTable(SIG, "entry length runs past the table"));
        }
        let e = &madt[at..at + len];
        match (kind, len) {
            // Processor local APIC: enabled (bit 0) or online capable (bit 1).
            (0, 8) if u32_at(e, 4) & 0b11 != 0 => {
                // 0xff is the xAPIC broadcast destination: an IPI to it would reach every CPU.
                let (id, ids) = (e[3], &info.cpu_apic_ids);
                if ids.len() == MAX_CPUS || ids.contains(&id) || id == 0xff {
                    info.cpus_ignored += 1;
                } else {
                    info.cpu_apic_ids.push(id);
                }
            }
            // A processor local x2APIC (enabled or online capable): its ID needs x2APIC mode.
            (9, 16) if u32_at(e, 8) & 0b11 != 0 => info.cpus_ignored += 1,
            // A processor entry of the wrong length.
            (0, _) | (9, _) if len != [8, 16][usize::from(kind == 9)] => info.cpus_ignored += 1,
            (1, 12) => info.io_apics.push(IoApicInfo {
                id: e[2],
                address: u32_at(e, 4) as u64,
                gsi_base: u32_at(e, 8),
            }),
            (2, 10) => info.overrides.push(InterruptOverride {
                isa_irq: e[3],
                gsi: u32_at(e, 4),
                flags: u16_at(e, 8),
            }),
            (5, 12) => info.local_apic_address = u64_at(e, 4),
            _ => {}
        }
        at += len;
    }
    Ok(())
}

#[cfg(test)]
#[path = "../host-tests/acpi.rs"]
mod tests;
