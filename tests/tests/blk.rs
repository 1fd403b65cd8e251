//! The block-device partition and its tenants under QEMU.

use scenarios::{boot, check, disk_image};

#[test]
fn blk_tenants() {
    let o = boot("blk_tenants");
    check(
        &o,
        o.line("check FAILED").is_none(),
        "a check failed (see `check FAILED` in the log)",
    );
    for line in [
        "blk: virtio-blk 00:04.0 8192 sectors, flush yes, line ",
        "blk: tenant alpha sectors 2048+64 from alpha-req to alpha-resp",
        "blk: tenant beta sectors 4096+64 from beta-req to beta-resp",
        "blk: tenant alpha refused: sectors 64+1 are outside the virtual disk of 64 sectors",
        "blk-tenant: alpha done",
        "blk-tenant: beta done",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    for who in ["alpha", "beta"] {
        for what in [
            "a slot record written and read back",
            "sector 20 written, flushed and read back",
            "sector 64 is beyond its virtual disk",
            "a damaged request is refused and not written",
            "32 sectors written, flushed and read back",
        ] {
            let line = format!("check ok: {who}: {what}");
            check(&o, o.line(&line).is_some(), &format!("missing {line:?}"));
        }
    }
    for line in o
        .lines
        .iter()
        .filter(|l| l.contains("single-sector writes"))
    {
        println!("blk_tenants: {line}");
    }
    // On the disk image: each tenant's sector 20 at its range, the slot header at its
    // first sector, nothing between the ranges.
    let disk = std::fs::read(disk_image("blk_tenants")).expect("the disk image");
    let sector = |n: usize| &disk[n * 512..(n + 1) * 512];
    check(
        &o,
        sector(2048 + 20) == [b'a'; 512],
        "alpha's sector 20 on the disk",
    );
    check(
        &o,
        sector(4096 + 20) == [b'b'; 512],
        "beta's sector 20 on the disk",
    );
    check(
        &o,
        &sector(2048)[..4] == b"WSLT",
        "alpha's slot header on the disk",
    );
    check(
        &o,
        disk[(2048 + 64) * 512..4096 * 512].iter().all(|&b| b == 0)
            && disk[..2048 * 512].iter().all(|&b| b == 0),
        "nothing written outside the tenants' ranges",
    );
}
