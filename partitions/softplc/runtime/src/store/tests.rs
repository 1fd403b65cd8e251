//! Boot projects and RETAIN snapshots: round trips, the restore rules on a changed program,
//! every truncation of a payload, and power cuts during saves on the `slots` format.

use super::*;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame, Value};
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

fn crc(bytes: &[u8]) -> u32 {
    let mut c = abi::crc32::Crc32::new();
    c.update(bytes);
    c.finish()
}

const OLD: &str = "PROGRAM Main
VAR RETAIN
  count : DINT;
  name : STRING[20];
  level : LREAL;
  dropped : INT;
END_VAR
VAR
  scratch : INT;
END_VAR
count := count + 1;
END_PROGRAM";

/// The same variables, but `name` shorter, `level` now a REAL and `dropped` gone.
const NEW: &str = "PROGRAM Main
VAR RETAIN
  count : DINT;
  name : STRING[4];
  level : REAL;
  fresh : INT := 7;
END_VAR
count := count + 1;
END_PROGRAM";

/// Runs `f` on a machine of `image` with `data` as its memory.
fn with_machine<R>(image: &[u8], data: &mut Vec<u8>, f: impl FnOnce(&mut Machine) -> R) -> R {
    let image = Image::parse(image).unwrap();
    let verified = plc_vm::verify::verify(&image).unwrap();
    data.resize(image.data_size() as usize, 0);
    let (mut stack, mut calls, mut tries) =
        ([0u64; 64], [CallFrame::EMPTY; 8], [TryFrame::EMPTY; 4]);
    let memory = Memory {
        data,
        stack: &mut stack,
        calls: &mut calls,
        tries: &mut tries,
    };
    let mut m = Machine::new(verified, memory).unwrap();
    f(&mut m)
}

fn old_snapshot() -> (Vec<u8>, Vec<u8>) {
    let image = compile(OLD);
    let mut data = Vec::new();
    let data_bytes = with_machine(&image, &mut data, |m| {
        m.write_var("Main.count", Value::Int(41)).unwrap();
        m.write_var("Main.name", Value::String(b"pump seven"))
            .unwrap();
        m.write_var("Main.level", Value::LReal(1.25)).unwrap();
        m.write_var("Main.scratch", Value::Int(99)).unwrap();
        m.data().to_vec()
    });
    let parsed = Image::parse(&image).unwrap();
    let mut out = vec![0u8; 4096];
    let n = encode_retain(&parsed, crc(&image), &data_bytes, 1234, &mut out).unwrap();
    out.truncate(n);
    (image, out)
}

#[test]
fn a_snapshot_restores_into_the_same_program() {
    let (image, snapshot) = old_snapshot();
    let snap = decode_retain(&snapshot).unwrap();
    assert_eq!((snap.release, snap.count), (1234, 4));
    let names: Vec<&str> = snap.values().map(|v| v.name).collect();
    assert_eq!(
        names,
        ["Main.count", "Main.name", "Main.level", "Main.dropped"]
    );
    let mut data = Vec::new();
    with_machine(&image, &mut data, |_| ());
    let parsed = Image::parse(&image).unwrap();
    assert_eq!(restore_retain(&snap, &parsed, crc(&image), &mut data), 4);
    // A new machine starts from the image's initial data: give it the restored bytes.
    with_machine(&image, &mut Vec::new(), |m| {
        m.data_mut().copy_from_slice(&data);
        assert_eq!(m.read_var("Main.count").unwrap(), Value::Int(41));
        assert_eq!(
            m.read_var("Main.name").unwrap(),
            Value::String(b"pump seven")
        );
        assert_eq!(m.read_var("Main.level").unwrap(), Value::LReal(1.25));
        assert_eq!(
            m.read_var("Main.scratch").unwrap(),
            Value::Int(0),
            "not RETAIN"
        );
    });
}

#[test]
fn a_changed_program_keeps_what_matches_by_name_and_type() {
    let (_, snapshot) = old_snapshot();
    let snap = decode_retain(&snapshot).unwrap();
    let image = compile(NEW);
    let parsed = Image::parse(&image).unwrap();
    let mut data = Vec::new();
    let mut initial = Vec::new();
    with_machine(&image, &mut data, |m| initial = m.data().to_vec());
    let mut data = initial.clone();
    assert_eq!(
        restore_retain(&snap, &parsed, crc(&image), &mut data),
        2,
        "count and the cut name"
    );
    with_machine(&image, &mut Vec::new(), |m| {
        m.data_mut().copy_from_slice(&data);
        assert_eq!(m.read_var("Main.count").unwrap(), Value::Int(41));
        assert_eq!(m.read_var("Main.name").unwrap(), Value::String(b"pump"));
        assert_eq!(
            m.read_var("Main.level").unwrap(),
            Value::Real(0.0),
            "type changed: initial value"
        );
        assert_eq!(
            m.read_var("Main.fresh").unwrap(),
            Value::Int(7),
            "new: initial value"
        );
    });
}

#[test]
fn boot_projects_round_trip() {
    let image = compile(OLD);
    let mut out = vec![0u8; 8192];
    let n = encode_boot(77, &image, "Main.count\nMain.level", &mut out).unwrap();
    let boot = decode_boot(&out[..n]).unwrap();
    assert_eq!(
        (boot.release, boot.program, boot.watch),
        (77, &image[..], "Main.count\nMain.level")
    );
    assert_eq!(
        encode_boot(1, &image, "", &mut [0u8; 10]),
        Err(StoreError::TooSmall {
            needed: 24 + image.len()
        })
    );
}

#[test]
fn every_truncation_and_damage_is_an_error() {
    let (image, snapshot) = old_snapshot();
    for cut in 0..snapshot.len() {
        assert!(decode_retain(&snapshot[..cut]).is_err(), "cut at {cut}");
    }
    let mut boot = vec![0u8; 8192];
    let n = encode_boot(3, &image, "w", &mut boot).unwrap();
    for cut in 0..n {
        assert!(decode_boot(&boot[..cut]).is_err(), "cut at {cut}");
    }
    let mut longer = snapshot.clone();
    longer.push(0);
    assert!(matches!(
        decode_retain(&longer),
        Err(StoreError::Invalid { .. })
    ));
    let mut other = snapshot.clone();
    other[0] = b'X';
    assert_eq!(decode_retain(&other), Err(StoreError::Magic));
    other[0] = b'W';
    other[4] = 9;
    assert_eq!(decode_retain(&other), Err(StoreError::Version(9)));
    let mut bad_type = snapshot.clone();
    bad_type[20] = 250;
    assert!(matches!(
        decode_retain(&bad_type),
        Err(StoreError::Invalid { at: 20, .. })
    ));
    assert_eq!(decode_boot(&snapshot), Err(StoreError::Magic));
}

#[test]
fn the_schedule_saves_at_its_interval_and_when_forced() {
    let mut s = RetainSchedule::new(100);
    assert!(!s.due(50));
    assert!(s.due(100));
    s.saved(100);
    assert!(!s.due(150));
    s.force();
    assert!(s.due(151));
    s.saved(151);
    assert!(!s.due(200) && s.due(251));
}

/// A disk that applies only the first `keep` sector writes of the next save (a power cut).
struct CutDisk {
    sectors: Vec<[u8; slots::SECTOR]>,
    keep: Option<usize>,
    written: usize,
}

impl slots::BlockDevice for CutDisk {
    type Error = ();
    fn read(&mut self, sector: u64, buf: &mut [u8; slots::SECTOR]) -> Result<(), ()> {
        *buf = *self.sectors.get(sector as usize).ok_or(())?;
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; slots::SECTOR]) -> Result<(), ()> {
        self.written += 1;
        if self.keep.is_some_and(|k| self.written > k) {
            return Ok(());
        }
        *self.sectors.get_mut(sector as usize).ok_or(())? = *data;
        Ok(())
    }
    fn flush(&mut self) -> Result<(), ()> {
        Ok(())
    }
}

#[test]
fn a_power_cut_during_a_save_leaves_a_whole_snapshot() {
    let region = slots::Region {
        first: 0,
        sectors: 16,
        kind: 2,
    };
    let image = compile(OLD);
    let parsed = Image::parse(&image).unwrap();
    let snapshot_of = |count: i64| {
        let mut data = Vec::new();
        let bytes = with_machine(&image, &mut data, |m| {
            m.write_var("Main.count", Value::Int(count)).unwrap();
            m.data().to_vec()
        });
        let mut out = vec![0u8; 4096];
        let n = encode_retain(&parsed, crc(&image), &bytes, count as u64, &mut out).unwrap();
        out.truncate(n);
        out
    };
    let mut disk = CutDisk {
        sectors: vec![[0; slots::SECTOR]; 16],
        keep: None,
        written: 0,
    };
    let scan = slots::scan(&mut disk, &region).unwrap();
    slots::write(&mut disk, &region, &scan, &snapshot_of(1)).unwrap();
    let total = {
        let mut probe = CutDisk {
            sectors: disk.sectors.clone(),
            keep: None,
            written: 0,
        };
        let scan = slots::scan(&mut probe, &region).unwrap();
        slots::write(&mut probe, &region, &scan, &snapshot_of(2)).unwrap();
        probe.written
    };
    for keep in 0..=total {
        let mut cut = CutDisk {
            sectors: disk.sectors.clone(),
            keep: Some(keep),
            written: 0,
        };
        let scan = slots::scan(&mut cut, &region).unwrap();
        let _ = slots::write(&mut cut, &region, &scan, &snapshot_of(2));
        let scan = slots::scan(&mut cut, &region).unwrap();
        let record = scan.newest().expect("a snapshot survives");
        let mut payload = vec![0u8; record.len];
        slots::read(&mut cut, &region, &record, &mut payload).unwrap();
        let snap = decode_retain(&payload).expect("whole");
        assert!(
            snap.release == 1 || (snap.release == 2 && keep == total),
            "cut after {keep} writes: release {}",
            snap.release
        );
    }
}
