//! The store on a virtual disk: the layout, a fresh disk, saves found again at the next
//! start, a corrupt newest slot skipped and reported (the older record loaded), both slots
//! corrupt (nothing loaded, both reported).

use super::*;
use std::string::ToString;
use std::vec;
use std::vec::Vec;

fn compile(source: &str) -> Vec<u8> {
    let files = [("test.st".to_string(), source.to_string())];
    match plc_compiler::compile(&files, &plc_compiler::Options::default()) {
        Ok((c, _)) => c.image,
        Err((d, s)) => panic!("{}", plc_compiler::diagnostics::render(&s, &d, false)),
    }
}

struct Ram(Vec<[u8; slots::SECTOR]>);

impl BlockDevice for Ram {
    type Error = ();
    fn read(&mut self, sector: u64, buf: &mut [u8; slots::SECTOR]) -> Result<(), ()> {
        *buf = *self.0.get(sector as usize).ok_or(())?;
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; slots::SECTOR]) -> Result<(), ()> {
        *self.0.get_mut(sector as usize).ok_or(())? = *data;
        Ok(())
    }
    fn flush(&mut self) -> Result<(), ()> {
        Ok(())
    }
}

const PROGRAM: &str =
    "PROGRAM Main VAR RETAIN count : DINT; END_VAR count := count + 1; END_PROGRAM";

#[test]
fn the_layout_splits_the_virtual_disk() {
    assert_eq!(Layout::of(7), None);
    let l = Layout::of(2048).unwrap();
    assert_eq!((l.boot.first, l.boot.sectors), (0, 1536));
    assert_eq!((l.retain.first, l.retain.sectors), (1536, 512));
    let l = Layout::of(100_001).unwrap();
    assert_eq!(l.retain.sectors, RETAIN_MAX_SECTORS);
    assert_eq!(l.boot.sectors % 2, 0);
    assert!(l.retain.first + l.retain.sectors <= 100_001);
    let l = Layout::of(9).unwrap();
    assert!(l.boot.sectors >= 4 && l.retain.sectors >= 4);
    assert!(l.retain.first + l.retain.sectors <= 9);
}

#[test]
fn saves_are_found_at_the_next_start_and_a_corrupt_slot_is_skipped() {
    let layout = Layout::of(64).unwrap();
    let mut disk = Ram(vec![[0; slots::SECTOR]; 64]);
    let (mut boot_buf, mut retain_buf) = (vec![0u8; 8192], vec![0u8; 1024]);
    let (mut store, boot, retain) =
        load(&mut disk, layout, &mut boot_buf, &mut retain_buf).unwrap();
    assert_eq!((boot.loaded, retain.loaded), (None, None), "a fresh disk");
    assert_eq!(boot.skipped, [None, None]);

    let image = compile(PROGRAM);
    let parsed = Image::parse(&image).unwrap();
    let crc = plc_online::crc32(&image);
    let mut data = vec![0u8; parsed.data_size() as usize];
    let var = parsed.find_var("Main.count").unwrap();
    let mut buf = vec![0u8; 8192];
    store
        .save_boot(&mut disk, 10, &image, "Main.count", &mut buf)
        .unwrap();
    for (release, count) in [(11u64, 5i32), (12, 6)] {
        data[var.addr as usize..var.addr as usize + 4].copy_from_slice(&count.to_le_bytes());
        store
            .save_retain(&mut disk, &parsed, crc, &data, release, &mut buf)
            .unwrap();
    }

    let (_, boot, retain) = load(&mut disk, layout, &mut boot_buf, &mut retain_buf).unwrap();
    let b = boot.loaded.unwrap();
    let project = store::decode_boot(&boot_buf[..b.len]).unwrap();
    assert_eq!(
        (project.release, project.program, project.watch),
        (10, &image[..], "Main.count")
    );
    let r = retain.loaded.unwrap();
    let snapshot = store::decode_retain(&retain_buf[..r.len]).unwrap();
    assert_eq!(snapshot.release, 12, "the newest snapshot wins");
    let mut restored = vec![0u8; data.len()];
    assert_eq!(
        store::restore_retain(&snapshot, &parsed, crc, &mut restored),
        1
    );
    assert_eq!(
        restored[var.addr as usize..var.addr as usize + 4],
        6i32.to_le_bytes()
    );

    // The newest snapshot's payload damaged on the disk: skipped, reported, the older one
    // loaded.
    let newest_header = layout.retain.first + r.slot as u64 * (layout.retain.sectors / 2);
    disk.0[newest_header as usize + 1][30] ^= 0xff;
    let (_, _, retain) = load(&mut disk, layout, &mut boot_buf, &mut retain_buf).unwrap();
    let older = retain.loaded.unwrap();
    assert_eq!(older.sequence, r.sequence - 1);
    assert_eq!(
        store::decode_retain(&retain_buf[..older.len])
            .unwrap()
            .release,
        11
    );
    assert_eq!(
        retain.skipped[r.slot],
        Some((
            r.slot,
            Corruption::Payload {
                sequence: r.sequence
            }
        ))
    );

    // Both slots' headers damaged: nothing loaded, both reported; the next save still
    // numbers above them.
    let other_header = layout.retain.first + older.slot as u64 * (layout.retain.sectors / 2);
    disk.0[other_header as usize][9] ^= 1;
    disk.0[newest_header as usize][9] ^= 1;
    let (mut store, _, retain) = load(&mut disk, layout, &mut boot_buf, &mut retain_buf).unwrap();
    assert_eq!(retain.loaded, None);
    assert!(
        retain
            .skipped
            .iter()
            .all(|s| matches!(s, Some((_, Corruption::Header))))
    );
    let again = store
        .save_retain(&mut disk, &parsed, crc, &data, 13, &mut buf)
        .unwrap();
    let (_, _, retain) = load(&mut disk, layout, &mut boot_buf, &mut retain_buf).unwrap();
    assert_eq!(retain.loaded, Some(again));
}

#[test]
fn a_save_too_large_for_its_buffer_or_region_is_an_error_not_a_torn_record() {
    let layout = Layout::of(16).unwrap();
    let mut disk = Ram(vec![[0; slots::SECTOR]; 16]);
    let (mut a, mut b) = (vec![0u8; 8192], vec![0u8; 8192]);
    let (mut store, _, _) = load(&mut disk, layout, &mut a, &mut b).unwrap();
    let big = vec![0u8; 6000];
    let mut buf = vec![0u8; 8192];
    assert!(matches!(
        store.save_boot(&mut disk, 1, &big, "", &mut buf),
        Err(PersistError::Disk(slots::Error::TooLarge { .. }))
    ));
    assert!(matches!(
        store.save_boot(&mut disk, 1, &big, "", &mut buf[..100]),
        Err(PersistError::Encode(StoreError::TooSmall { .. }))
    ));
    let (_, boot, _) = load(&mut disk, layout, &mut a, &mut b).unwrap();
    assert_eq!(boot.loaded, None);
}

#[test]
fn the_retain_interval_is_whole_periods_rounded_up() {
    assert_eq!(retain_every_releases(1_000_000_000, 10_000_000), 100);
    assert_eq!(retain_every_releases(1_000_000_001, 10_000_000), 101);
    assert_eq!(retain_every_releases(1, 10_000_000), 1);
    assert_eq!(retain_every_releases(5, 0), 5);
}
