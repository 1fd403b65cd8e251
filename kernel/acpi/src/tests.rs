//! Host tests of the ACPI table parsing, with synthetic tables.

extern crate std;

use super::*;
use abi::machine::MAX_CPUS;
use std::collections::BTreeMap;
use std::vec;
use std::vec::Vec;

/// Physical memory made of placed byte blobs.
#[derive(Default)]
struct Fake(BTreeMap<u64, Vec<u8>>);

impl PhysMemory for Fake {
    fn bytes(&self, phys: u64, len: usize) -> Option<&[u8]> {
        let (base, blob) = self.0.range(..=phys).next_back()?;
        let off = (phys - base) as usize;
        blob.get(off..off + len)
    }
}

fn seal(mut t: Vec<u8>) -> Vec<u8> {
    let sum = t.iter().fold(0u8, |s, b| s.wrapping_add(*b));
    t[9] = t[9].wrapping_sub(sum);
    t
}

fn sdt(signature: &[u8; 4], body: &[u8]) -> Vec<u8> {
    let mut t = vec![0u8; HEADER_LEN];
    t[0..4].copy_from_slice(signature);
    t[4..8].copy_from_slice(&((HEADER_LEN + body.len()) as u32).to_le_bytes());
    t.extend_from_slice(body);
    seal(t)
}

fn rsdp_v2(xsdt: u64) -> Vec<u8> {
    let mut r = vec![0u8; 36];
    r[0..8].copy_from_slice(b"RSD PTR ");
    r[15] = 2;
    r[24..32].copy_from_slice(&xsdt.to_le_bytes());
    let s1 = r[..20].iter().fold(0u8, |s, b| s.wrapping_add(*b));
    r[8] = r[8].wrapping_sub(s1);
    let s2 = r.iter().fold(0u8, |s, b| s.wrapping_add(*b));
    r[32] = r[32].wrapping_sub(s2);
    r
}

fn madt() -> Vec<u8> {
    let mut body = vec![0u8; 8];
    body[0..4].copy_from_slice(&0xfee0_0000u32.to_le_bytes());
    body.extend_from_slice(&[0, 8, 0, 0, 1, 0, 0, 0]); // CPU 0, enabled
    body.extend_from_slice(&[0, 8, 1, 1, 0, 0, 0, 0]); // CPU 1, disabled
    body.extend_from_slice(&[1, 12, 7, 0, 0, 0, 0xc0, 0xfe, 0, 0, 0, 0]); // IOAPIC 7
    body.extend_from_slice(&[2, 10, 0, 0, 2, 0, 0, 0, 0, 0]); // IRQ0 -> GSI2
    sdt(b"APIC", &body)
}

fn hpet() -> Vec<u8> {
    let mut body = vec![0u8; 20];
    body[4] = 0; // system memory
    body[8..16].copy_from_slice(&0xfed0_0000u64.to_le_bytes());
    sdt(b"HPET", &body)
}

fn system(tables: Vec<Vec<u8>>) -> Fake {
    let mut mem = Fake::default();
    let mut xsdt_body = Vec::new();
    for (i, t) in tables.into_iter().enumerate() {
        let at = 0x10_0000 + i as u64 * 0x1000;
        xsdt_body.extend_from_slice(&at.to_le_bytes());
        mem.0.insert(at, t);
    }
    mem.0.insert(0x9000, sdt(b"XSDT", &xsdt_body));
    mem.0.insert(0xe0000, rsdp_v2(0x9000));
    mem
}

#[test]
fn finds_interrupt_controllers_and_hpet() {
    let mem = system(vec![madt(), hpet()]);
    let info = parse(0xe0000, &mem).unwrap();
    assert_eq!(info.local_apic_address, 0xfee0_0000);
    assert_eq!(info.acpi_revision, 2);
    assert_eq!(info.cpu_apic_ids(), [0]);
    assert_eq!(
        info.io_apics(),
        [IoApicInfo {
            id: 7,
            address: 0xfec0_0000,
            gsi_base: 0
        }]
    );
    assert_eq!(
        info.overrides(),
        [InterruptOverride {
            isa_irq: 0,
            gsi: 2,
            flags: 0
        }]
    );
    assert_eq!(info.hpet_address, 0xfed0_0000);
    assert_eq!(info.entries_ignored, 0);
}

#[test]
fn rejects_bad_checksums_and_missing_tables() {
    assert_eq!(parse(0, &Fake::default()), Err(AcpiError::NoRsdp));
    let mut mem = system(vec![madt()]);
    mem.0.get_mut(&0x10_0000).unwrap()[40] ^= 0xff;
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadTable(*b"APIC", "checksum mismatch"))
    );
    let mem = system(vec![hpet()]);
    assert_eq!(parse(0xe0000, &mem), Err(AcpiError::NoMadt));
    let mut mem = system(vec![madt()]);
    mem.0.get_mut(&0xe0000).unwrap()[0] = b'X';
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadRsdp("bad signature"))
    );
}

#[test]
fn truncated_madt_entry_is_an_error_not_a_panic() {
    let mut body = vec![0u8; 8];
    body.extend_from_slice(&[1, 40, 0, 0]); // claims 40 bytes, has 4
    let mem = system(vec![sdt(b"APIC", &body)]);
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadTable(
            *b"APIC",
            "entry length runs past the table"
        ))
    );
}

/// A DMAR table (host address width 39 bits) with one DRHD per `(flags, segment, base)`,
/// each listing an IOAPIC and the endpoints 00:03.0 and 00:1f.2 and a function behind a
/// bridge (two path entries), as QEMU's `intel-iommu` lists the functions it translates.
fn dmar(units: &[(u8, u16, u64)]) -> Vec<u8> {
    let mut body = vec![0u8; 12];
    body[0] = 38; // host address width - 1
    for &(flags, segment, base) in units {
        let mut drhd = vec![0u8; 16];
        drhd[2..4].copy_from_slice(&50u16.to_le_bytes());
        drhd[4] = flags;
        drhd[6..8].copy_from_slice(&segment.to_le_bytes());
        drhd[8..16].copy_from_slice(&base.to_le_bytes());
        drhd.extend_from_slice(&[3, 8, 0, 0, 0, 0xff, 0, 0]); // IOAPIC
        drhd.extend_from_slice(&[1, 8, 0, 0, 0, 0, 3, 0]); // endpoint 00:03.0
        drhd.extend_from_slice(&[1, 8, 0, 0, 0, 0, 0x1f, 2]); // endpoint 00:1f.2
        drhd.extend_from_slice(&[1, 10, 0, 0, 0, 0, 1, 0, 0, 0]); // behind the bridge 00:01.0
        body.extend_from_slice(&drhd);
    }
    // A reserved-memory structure (type 1), which the kernel skips.
    body.extend_from_slice(&[1, 0, 8, 0, 0, 0, 0, 0]);
    sdt(b"DMAR", &body)
}

#[test]
fn finds_the_one_dma_remapping_unit_and_the_functions_it_translates() {
    let info = parse(0xe0000, &system(vec![madt()])).unwrap();
    assert_eq!(info.dma_base, 0, "no DMAR: no IOMMU");
    let mem = system(vec![madt(), dmar(&[(0, 0, 0xfed9_0000)])]);
    let info = parse(0xe0000, &mem).unwrap();
    assert_eq!((info.dma_base, info.dma_all), (0xfed9_0000, 0));
    assert_eq!(info.dma_endpoints(), [3 << 3, 0x1f << 3 | 2]);
    let mem = system(vec![madt(), dmar(&[(1, 0, 0xfed9_0000)])]);
    assert_eq!(parse(0xe0000, &mem).unwrap().dma_all, 1);
    // Layouts the kernel does not program mean no usable IOMMU, never a wrong one.
    for units in [
        &[(1, 1, 0xfed9_0000)][..],                  // another PCI segment
        &[(1, 0, 0xfed9_0000), (0, 0, 0xfed9_1000)], // two units
    ] {
        let info = parse(0xe0000, &system(vec![madt(), dmar(units)])).unwrap();
        assert_eq!(
            (info.dma_base, info.dma_endpoints()),
            (0, &[][..]),
            "{units:?}"
        );
    }
}

#[test]
fn damaged_dmar_structures_are_errors_not_panics() {
    let mut body = vec![0u8; 12];
    body.extend_from_slice(&[0, 0, 40, 0]); // claims 40 bytes, has 4
    let mem = system(vec![madt(), sdt(b"DMAR", &body)]);
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadTable(
            *b"DMAR",
            "structure length runs past the table"
        ))
    );
    let mut body = vec![0u8; 12];
    body.extend_from_slice(&[0, 0, 8, 0, 1, 0, 0, 0]); // a DRHD of 8 bytes
    let mem = system(vec![madt(), sdt(b"DMAR", &body)]);
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadTable(*b"DMAR", "DRHD shorter than 16 bytes"))
    );
    // A device scope claiming more bytes than its DRHD has, and one of length 0.
    for scope in [[1u8, 40, 0, 0, 0, 0, 3, 0], [1, 0, 0, 0, 0, 0, 3, 0]] {
        let mut body = vec![0u8; 12];
        body.extend_from_slice(&[0, 0, 24, 0, 0, 0, 0, 0]);
        body.extend_from_slice(&0xfed9_0000u64.to_le_bytes());
        body.extend_from_slice(&scope);
        let mem = system(vec![madt(), sdt(b"DMAR", &body)]);
        assert_eq!(
            parse(0xe0000, &mem),
            Err(AcpiError::BadTable(
                *b"DMAR",
                "device scope shorter than 6 bytes or past its DRHD"
            )),
            "{scope:?}"
        );
    }
    let mem = system(vec![madt(), sdt(b"DMAR", &[0u8; 4])]);
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadTable(*b"DMAR", "too short"))
    );
}

/// A MADT with the given processor entries (type, length, bytes after the 2-byte header).
fn madt_with(entries: &[Vec<u8>]) -> Fake {
    let mut body = vec![0u8; 8];
    body[0..4].copy_from_slice(&0xfee0_0000u32.to_le_bytes());
    for e in entries {
        body.extend_from_slice(e);
    }
    system(vec![sdt(b"APIC", &body)])
}

fn local_apic(id: u8, flags: u32) -> Vec<u8> {
    let mut e = vec![0, 8, id, id];
    e.extend_from_slice(&flags.to_le_bytes());
    e
}

#[test]
fn processors_beyond_the_supported_count_are_counted_not_kept() {
    let entries: Vec<_> = (0..20).map(|id| local_apic(id, 1)).collect();
    let info = parse(0xe0000, &madt_with(&entries)).unwrap();
    assert_eq!(info.cpu_apic_ids(), (0..MAX_CPUS as u8).collect::<Vec<_>>());
    assert_eq!(info.cpus_ignored as usize, 20 - MAX_CPUS);
}

#[test]
fn repeated_x2apic_only_and_wrong_length_processors_are_ignored() {
    let mut x2apic = vec![9, 16, 0, 0];
    x2apic.extend_from_slice(&300u32.to_le_bytes());
    x2apic.extend_from_slice(&1u32.to_le_bytes());
    x2apic.extend_from_slice(&300u32.to_le_bytes());
    let entries = vec![
        local_apic(0, 1),
        local_apic(0, 1),                    // the same APIC ID again
        local_apic(2, 2),                    // online capable
        local_apic(3, 0),                    // disabled: neither kept nor ignored
        local_apic(0xff, 1),                 // the broadcast ID: an IPI would reach every CPU
        vec![0, 6, 4, 4, 1, 0],              // too short for a local APIC
        vec![0, 10, 5, 5, 1, 0, 0, 0, 0, 0], // too long
        x2apic,
    ];
    let info = parse(0xe0000, &madt_with(&entries)).unwrap();
    assert_eq!(info.cpu_apic_ids(), [0, 2]);
    assert_eq!(info.cpus_ignored, 5);
}

#[test]
fn a_processor_entry_running_past_the_madt_is_an_error() {
    let mut body = vec![0u8; 8];
    body.extend_from_slice(&[0, 8, 1, 1, 1]); // 8 claimed, 5 present
    let mem = system(vec![sdt(b"APIC", &body)]);
    assert_eq!(
        parse(0xe0000, &mem),
        Err(AcpiError::BadTable(
            *b"APIC",
            "entry length runs past the table"
        ))
    );
    let mut body = vec![0u8; 8];
    body.extend_from_slice(&[0, 0, 1, 1]); // zero length would loop for ever
    let mem = system(vec![sdt(b"APIC", &body)]);
    assert!(parse(0xe0000, &mem).is_err());
}

#[test]
fn ioapics_and_overrides_beyond_their_arrays_are_counted_not_kept() {
    use abi::machine::{MAX_IO_APICS, MAX_OVERRIDES};
    let mut entries = Vec::new();
    for id in 0..MAX_IO_APICS as u8 + 2 {
        entries.push(vec![1, 12, id, 0, 0, 0, 0xc0, 0xfe, 0, 0, 0, 0]);
    }
    for irq in 0..MAX_OVERRIDES as u8 + 3 {
        entries.push(vec![2, 10, 0, irq, irq, 0, 0, 0, 0, 0]);
    }
    let info = parse(0xe0000, &madt_with(&entries)).unwrap();
    assert_eq!(info.io_apics().len(), MAX_IO_APICS);
    assert_eq!(info.overrides().len(), MAX_OVERRIDES);
    assert_eq!(
        info.overrides()[MAX_OVERRIDES - 1].isa_irq,
        MAX_OVERRIDES as u8 - 1
    );
    assert_eq!(info.entries_ignored, 5);
}
