//! Host tests of `kernel/src/rp.rs` (a child module of it: `super` is that module).

use super::*;
use crate::table::Slot;

#[test]
fn charges_within_quota_only() {
    let mut rp = ResourcePartition::new(
        TaskIdx::ROOT,
        Amount {
            tasks: 1,
            threads: 2,
            pages: 3,
        },
    );
    rp.charge(Amount::threads(2)).unwrap();
    assert_eq!(rp.charge(Amount::threads(1)), Err(Error::QuotaExceeded));
    assert_eq!(
        rp.charge(Amount {
            tasks: 1,
            threads: 0,
            pages: 4
        }),
        Err(Error::QuotaExceeded),
        "all or nothing"
    );
    assert_eq!(rp.used, Amount::threads(2));
    rp.release(Amount::threads(1));
    rp.charge(Amount::threads(1)).unwrap();
}

#[test]
fn carving_isolates_partitions() {
    let mut root = ResourcePartition::new(
        TaskIdx::ROOT,
        Amount {
            tasks: 4,
            threads: 8,
            pages: 100,
        },
    );
    let mut a = root
        .carve(
            TaskIdx::at(1),
            Amount {
                tasks: 1,
                threads: 2,
                pages: 10,
            },
            u8::MAX.into(),
        )
        .unwrap();
    let mut b = root
        .carve(
            TaskIdx::at(1),
            Amount {
                tasks: 1,
                threads: 2,
                pages: 10,
            },
            u8::MAX.into(),
        )
        .unwrap();
    assert_eq!(
        root.carve(TaskIdx::at(1), Amount::pages(81), 1).err(),
        Some(Error::QuotaExceeded),
        "only 80 pages left"
    );
    while a.charge(Amount::pages(1)).is_ok() {}
    assert_eq!(a.used.pages, 10);
    b.charge(Amount::pages(10)).unwrap();
    root.charge(Amount::pages(80)).unwrap();
    assert_eq!(root.charge(Amount::pages(1)), Err(Error::QuotaExceeded));
}

#[test]
fn a_partition_runs_on_some_of_its_creators_cpus() {
    let mut root = ResourcePartition::new(TaskIdx::ROOT, Amount::pages(10));
    assert_eq!(root.cpus, u8::MAX, "the root partition runs everywhere");
    let mut pair = root.carve(TaskIdx::at(1), Amount::pages(4), 0b110).unwrap();
    assert_eq!(pair.cpus, 0b110);
    for refused in [0, 0b1, 0b1010, 0x100, u64::MAX] {
        assert_eq!(
            pair.carve(TaskIdx::at(2), Amount::pages(1), refused).err(),
            Some(Error::InvalidArgument),
            "CPU mask {refused:#x} is empty or not within 0b110"
        );
    }
    assert_eq!(
        pair.carve(TaskIdx::at(2), Amount::pages(1), 0b100)
            .unwrap()
            .cpus,
        0b100
    );
    assert_eq!(
        pair.carved,
        Amount::pages(1),
        "a refused carve takes nothing"
    );
    assert_eq!(root.carved, Amount::pages(4));
}
