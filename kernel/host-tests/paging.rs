//! Host tests of the page tables (`kernel/src/mem/paging.rs`); kept outside `src` so that the
//! ring-0 code budget counts only what runs in ring 0.

use super::*;
use crate::mem::test_arena;

const RW: PageRights = PageRights::WRITE;

#[test]
fn precount_matches_what_map_allocates() {
    let _arena = test_arena::init();
    let mut space = AddressSpace::new().unwrap();
    for (virt, pages) in [
        (0x40_0000u64, 3u64),
        (0x40_3000, 600),                    // crosses a 2 MiB boundary
        (0x7f_ffe0_0000, 4),                 // another 1 GiB and 512 GiB region
        (0x0000_7fff_ffff_f000 - 0x1000, 1), // top of user space
    ] {
        let needed = space.tables_needed(virt, pages).unwrap();
        let before = crate::mem::free_frames();
        for p in 0..pages {
            space.map(virt + p * PAGE_SIZE, 0x1000, RW).unwrap();
        }
        assert_eq!(before - crate::mem::free_frames(), needed, "at {virt:#x}");
        assert_eq!(space.tables_needed(virt, pages), None, "mapped already");
        // Beside the mapped pages, in the same tables: nothing to allocate.
        if virt == 0x40_0000 {
            assert_eq!(space.tables_needed(virt + 3 * PAGE_SIZE, 1), Some(0));
            assert_eq!(
                space.tables_needed(virt - PAGE_SIZE, 2),
                None,
                "one page mapped"
            );
        }
    }
    let freed = space.destroy_some(&mut { u64::MAX });
    assert!(freed > 5);
}

#[test]
fn destroying_in_small_steps_frees_every_table_once() {
    let _arena = test_arena::init();
    let before = crate::mem::free_frames();
    let mut space = AddressSpace::new().unwrap();
    for virt in [
        0x1000,
        0x40_0000,
        0x4000_0000,
        0x80_0000_0000,
        0x7fff_ffff_f000,
    ] {
        space.map(virt, 0x1000, RW).unwrap();
    }
    let tables = before - crate::mem::free_frames();
    for budget in [1, 7, 300] {
        let mut copy = AddressSpace::new().unwrap();
        copy.map(0x1000, 0x1000, RW).unwrap();
        let (mut freed, mut calls) = (0, 0);
        while !copy.is_destroyed() {
            let mut left = budget;
            freed += copy.destroy_some(&mut left);
            calls += 1;
            assert!(calls < 10_000, "no progress with budget {budget}");
        }
        assert_eq!(freed, 4, "budget {budget}");
    }
    let (mut freed, mut calls) = (0, 0);
    while !space.is_destroyed() {
        let mut left = 5;
        freed += space.destroy_some(&mut left);
        calls += 1;
    }
    assert_eq!(freed, tables);
    assert!(
        calls > 100,
        "{calls} calls of 5 entries for {tables} tables"
    );
    assert_eq!(crate::mem::free_frames(), before);
}

#[test]
fn rights_unmap_and_copies() {
    let _arena = test_arena::init();
    let mut space = AddressSpace::new().unwrap();
    let frame = crate::mem::alloc_zeroed_frame().unwrap();
    space.map(0x1000, frame, PageRights::empty()).unwrap();
    assert_eq!(space.map(0x1000, frame, RW), Err(MapError::AlreadyMapped));
    assert_eq!(
        space.map(0xffff_8000_0000_0000, frame, RW),
        Err(MapError::NotUserAddress)
    );
    assert!(!space.copy_to_user(0x1000, b"hi"), "read-only page");
    assert!(space.set_rights(0x1000, RW));
    assert!(space.copy_to_user(0x1ffe, b"hi"));
    let mut out = [0u8; 2];
    assert!(space.copy_from_user(0x1ffe, &mut out));
    assert_eq!(&out, b"hi");
    assert!(
        !space.copy_from_user(0x1fff, &mut out),
        "crosses into an unmapped page"
    );
    assert_eq!(space.unmap(0x1000), Some(frame));
    assert_eq!(space.translate(0x1000), None);
    assert_eq!(space.unmap(0x1000), None);
    space.destroy_some(&mut { u64::MAX });
    // SAFETY: allocated by this test and no longer mapped.
    unsafe { crate::mem::free_frame(frame) };
}

#[test]
fn user_range_check_rejects_kernel_and_overflow() {
    assert!(is_user_range(0x1000, 1));
    assert!(!is_user_range(0, 1));
    assert!(!is_user_range(0x1001, 1));
    assert!(!is_user_range(USER_END - 0x1000, 2));
    assert!(!is_user_range(0x1000, u64::MAX / 2));
}
