//! The firmware's ACPI tables as the loader reads them before it starts the kernel: RSDP ->
//! XSDT/RSDT -> MADT (local APIC, IOAPICs, interrupt source overrides, CPUs), HPET and
//! DMAR (the VT-d DMA remapping unit), into the fixed-size [`Machine`] block the kernel
//! reads (`abi::machine`). Pure parsing over a [`PhysMemory`] view, host-tested with
//! synthetic tables; every table is length- and checksum-checked before use, and a damaged
//! table is an [`AcpiError`], never a panic.
#![no_std]

use abi::machine::{InterruptOverride, IoApicInfo, Machine};

/// Read access to physical memory (the firmware's identity map in the loader).
pub trait PhysMemory {
    /// `len` bytes at physical address `phys`, or `None` if not mapped.
    fn bytes(&self, phys: u64, len: usize) -> Option<&[u8]>;
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
                let name = core::str::from_utf8(sig).unwrap_or("????");
                write!(f, "ACPI table {name}: {why}")
            }
            Self::NoMadt => write!(
                f,
                "no MADT (APIC table): cannot find the interrupt controllers"
            ),
        }
    }
}

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

/// The machine the tables at `rsdp` describe.
pub fn parse(rsdp: u64, mem: &impl PhysMemory) -> Result<Machine, AcpiError> {
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
    let mut machine = Machine {
        acpi_revision: revision.into(),
        ..Machine::EMPTY
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
                parse_madt(body, &mut machine)?;
                found_madt = true;
            }
            b"DMAR" => parse_dmar(body, &mut machine)?,
            b"HPET" => {
                if body.len() < 52 {
                    return Err(AcpiError::BadTable(signature, "too short"));
                }
                // Generic address structure at 40: space id 0 = system memory.
                if body[40] == 0 {
                    machine.hpet_address = u64_at(body, 44);
                }
            }
            _ => {}
        }
    }
    if !found_madt {
        return Err(AcpiError::NoMadt);
    }
    Ok(machine)
}

/// The DMAR table's single remapping unit (see [`Machine::dma_base`]). Remapping
/// structures start at 48: type (u16), length (u16); type 0 (DRHD) has flags at 4 (bit 0
/// INCLUDE_PCI_ALL), the segment at 6, the register base at 8 and device scopes from 16:
/// type (1 = endpoint), length, 2 reserved, enumeration id, start bus, then (device,
/// function) path entries.
fn parse_dmar(dmar: &[u8], machine: &mut Machine) -> Result<(), AcpiError> {
    const SIG: [u8; 4] = *b"DMAR";
    let bad = |why| Err(AcpiError::BadTable(SIG, why));
    if dmar.len() < 48 {
        return bad("too short");
    }
    let (mut units, mut usable) = (0, false);
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
            machine.dma_base = u64_at(dmar, at + 8);
            machine.dma_all = u32::from(dmar[at + 4] & 1);
            machine.dma_endpoint_count = 0;
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
                    // Beyond the array a function counts as not covered (no DMA for it).
                    let (slots, count) =
                        (&mut machine.dma_endpoints, &mut machine.dma_endpoint_count);
                    push(slots, count, &mut 0, id);
                }
                scope += s.len();
            }
            usable = u16_at(dmar, at + 6) == 0;
        }
        at += len;
    }
    if units != 1 || !usable {
        (
            machine.dma_base,
            machine.dma_all,
            machine.dma_endpoint_count,
        ) = (0, 0, 0);
    }
    Ok(())
}

fn parse_madt(madt: &[u8], machine: &mut Machine) -> Result<(), AcpiError> {
    const SIG: [u8; 4] = *b"APIC";
    if madt.len() < 44 {
        return Err(AcpiError::BadTable(SIG, "too short"));
    }
    machine.local_apic_address = u32_at(madt, 36) as u64;
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
                let id = e[3];
                if machine.cpu_apic_ids().contains(&id) || id == 0xff {
                    machine.cpus_ignored += 1;
                } else {
                    push(
                        &mut machine.cpu_apic_ids,
                        &mut machine.cpu_count,
                        &mut machine.cpus_ignored,
                        id,
                    );
                }
            }
            // A processor local x2APIC (enabled or online capable): its ID needs x2APIC mode.
            (9, 16) if u32_at(e, 8) & 0b11 != 0 => machine.cpus_ignored += 1,
            // A processor entry of the wrong length.
            (0, _) | (9, _) if len != [8, 16][usize::from(kind == 9)] => machine.cpus_ignored += 1,
            (1, 12) => {
                let io_apic = IoApicInfo {
                    id: e[2],
                    address: u32_at(e, 4) as u64,
                    gsi_base: u32_at(e, 8),
                };
                push(
                    &mut machine.io_apics,
                    &mut machine.io_apic_count,
                    &mut machine.entries_ignored,
                    io_apic,
                );
            }
            (2, 10) => {
                let entry = InterruptOverride {
                    isa_irq: e[3],
                    gsi: u32_at(e, 4),
                    flags: u16_at(e, 8),
                };
                push(
                    &mut machine.overrides,
                    &mut machine.override_count,
                    &mut machine.entries_ignored,
                    entry,
                );
            }
            (5, 12) => machine.local_apic_address = u64_at(e, 4),
            _ => {}
        }
        at += len;
    }
    Ok(())
}

/// Puts `value` in the next free one of `slots` (`count` in use), or counts it in
/// `ignored` when all are.
fn push<T>(slots: &mut [T], count: &mut u32, ignored: &mut u32, value: T) {
    match slots.get_mut(*count as usize) {
        Some(slot) => (*slot, *count) = (value, *count + 1),
        None => *ignored += 1,
    }
}

#[cfg(test)]
mod tests;
