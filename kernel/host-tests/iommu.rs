//! Host tests of the DMA remapping tables (`kernel/src/mem/iommu.rs`); kept outside `src` so
//! that the ring-0 code budget counts only what runs in ring 0.

use super::*;
use crate::mem::test_arena;

/// What the remapping unit does with a request of `source` for bus address `iova`: walks
/// root, context and second-level tables as VT-d's legacy translation does.
fn translate(t: &DmaTables, source: u16, iova: u64) -> Option<u64> {
    let root = read(t.root(), 2 * u64::from(source >> 8));
    if root & PRESENT == 0 {
        return None;
    }
    let slot = 2 * u64::from(source & 0xff);
    let (low, high) = (read(root & ADDRESS, slot), read(root & ADDRESS, slot + 1));
    if low & PRESENT == 0 || low & 0b1100 != 0 || high & 7 != u64::from(t.levels - 2) {
        return None;
    }
    let mut table = low & ADDRESS;
    for level in (0..t.levels).rev() {
        let e = read(table, (iova >> (12 + 9 * level)) & 511);
        if e & READ_WRITE != READ_WRITE {
            return None;
        }
        table = e & ADDRESS;
    }
    Some(table | (iova & 0xfff))
}

const EDU: u16 = 4 << 3; // 00:04.0
const NIC: u16 = 3 << 3; // 00:03.0

#[test]
fn entries_are_encoded_as_vt_d_reads_them() {
    assert_eq!(root_entry(0x5000), 0x5001);
    // 3 levels = address width 39 bits (AW 1), domain 7 in bits 23:8, TT 0.
    assert_eq!(context_entry(0x9000, 7, 3), (0x9001, 0x701));
    assert_eq!(context_entry(0x9000, 1, 4).1, 0x102);
    assert_eq!(second_level_entry(0x1234_5000), 0x1234_5003);
}

#[test]
fn a_confined_function_reaches_exactly_its_region_at_its_physical_addresses() {
    let _arena = test_arena::init();
    let mut t = DmaTables::new(3, 256).unwrap();
    assert_eq!(translate(&t, EDU, 0x1000_0000), None, "nothing before");
    // 16 pages across a 2 MiB boundary.
    let region = 0x101f_8000;
    t.confine(EDU, region, 16).unwrap();
    for page in 0..16 {
        let at = region + page * PAGE_SIZE + 0x10;
        assert_eq!(translate(&t, EDU, at), Some(at));
    }
    assert_eq!(translate(&t, EDU, region - PAGE_SIZE), None, "below");
    assert_eq!(translate(&t, EDU, region + 16 * PAGE_SIZE), None, "above");
    assert_eq!(translate(&t, EDU, 0x10_0000), None, "the kernel's frames");
    assert_eq!(translate(&t, NIC, region), None, "another function");
    assert_eq!(
        translate(&t, EDU | 1, region),
        None,
        "another function of the device"
    );
    assert_eq!(translate(&t, 1 << 8 | EDU, region), None, "another bus");
    // A second function gets its own tree and domain; the first keeps what it had.
    t.confine(NIC, 0x2000_0000, 1).unwrap();
    assert_eq!(translate(&t, NIC, 0x2000_0000), Some(0x2000_0000));
    assert_eq!(translate(&t, NIC, region), None);
    assert_eq!(translate(&t, EDU, 0x2000_0000), None);
    assert_eq!(translate(&t, EDU, region), Some(region));
    let context = read(t.root(), 0) & ADDRESS;
    let domain = |source: u16| read(context, 2 * u64::from(source) + 1) >> 8 & 0xffff;
    assert_ne!(domain(EDU), domain(NIC));
    // Extending a region reuses its tables.
    let used = t.used;
    t.confine(EDU, region + 16 * PAGE_SIZE, 1).unwrap();
    assert_eq!(t.used, used);
    assert_eq!(
        translate(&t, EDU, region + 16 * PAGE_SIZE),
        Some(region + 16 * PAGE_SIZE)
    );
}

#[test]
fn bad_requests_are_refused_and_the_frames_are_bounded() {
    let _arena = test_arena::init();
    let mut t = DmaTables::new(3, 256).unwrap();
    for (physical, pages) in [
        (0x1000_0010, 1),      // unaligned
        (0x1000_0000, 0),      // nothing
        (0x1000_0000, 33),     // more than MAP_MAX_PAGES
        ((1 << 39) - 4096, 2), // beyond a 39-bit bus address
    ] {
        assert_eq!(
            t.confine(EDU, physical, pages),
            Err(Error::InvalidArgument),
            "{physical:#x} {pages}"
        );
    }
    assert_eq!(t.used, 1, "nothing built for a refused request");
    // Each 2 MiB span of a new function costs a top, middle and last-level table: the
    // reserved frames run out, then every request is refused.
    let mut refused = None;
    for i in 0..TABLE_FRAMES as u64 {
        if let Err(e) = t.confine(EDU, i << 30, 1) {
            refused = Some(e);
            break;
        }
    }
    assert_eq!(refused, Some(Error::OutOfResources));
    assert_eq!(t.used, TABLE_FRAMES);
    // Domain ids: as many as the unit has (0 is never used).
    let mut t = DmaTables::new(3, 3).unwrap();
    t.confine(EDU, 0x1000_0000, 1).unwrap();
    t.confine(NIC, 0x1000_0000, 1).unwrap();
    assert_eq!(
        t.confine(EDU | 1, 0x1000_0000, 1),
        Err(Error::OutOfResources)
    );
}

#[test]
fn fault_records_decode_as_qemu_writes_them() {
    // A write by 00:04.0 to 0xdead_b000, reason 5 (no write permission / not present).
    let high = 1 << 63 | 5 << 32 | u64::from(EDU);
    assert_eq!(
        DmaFault::decode(0xdead_b000, high),
        Some(DmaFault {
            source: EDU,
            address: 0xdead_b000,
            reason: 5,
            write: true
        })
    );
    let read_fault = DmaFault::decode(0x1234, high | 1 << 62).unwrap();
    assert!(!read_fault.write);
    assert_eq!(read_fault.address, 0x1000);
    assert_eq!(
        DmaFault::decode(0xdead_b000, high & !(1 << 63)),
        None,
        "F clear"
    );
}
