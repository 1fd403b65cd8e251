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
        )
        .unwrap();
    assert_eq!(
        root.carve(TaskIdx::at(1), Amount::pages(81)).err(),
        Some(Error::QuotaExceeded),
        "only 80 pages left"
    );
    while a.charge(Amount::pages(1)).is_ok() {}
    assert_eq!(a.used.pages, 10);
    b.charge(Amount::pages(10)).unwrap();
    root.charge(Amount::pages(80)).unwrap();
    assert_eq!(root.charge(Amount::pages(1)), Err(Error::QuotaExceeded));
}
