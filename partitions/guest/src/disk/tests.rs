use super::*;
use alloc::vec;

/// A disk in memory that counts its requests and can be told to fail.
struct Memory {
    sectors: Vec<[u8; SECTOR]>,
    reads: u32,
    writes: u32,
    flushes: u32,
    /// Runs of sectors asked for in one call.
    runs: u32,
    /// Requests of this sector fail.
    bad: Option<u64>,
    /// Every request fails.
    dead: bool,
}

#[derive(Debug)]
struct Failed;

impl core::fmt::Display for Failed {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("the driver answered IoError")
    }
}

impl Memory {
    fn new(sectors: usize) -> Self {
        let mut m = Memory {
            sectors: vec![[0; SECTOR]; sectors],
            reads: 0,
            writes: 0,
            flushes: 0,
            runs: 0,
            bad: None,
            dead: false,
        };
        for (i, s) in m.sectors.iter_mut().enumerate() {
            s.fill(i as u8);
        }
        m
    }

    fn fails(&self, sector: u64) -> bool {
        self.dead || self.bad == Some(sector)
    }
}

impl slots::BlockDevice for Memory {
    type Error = Failed;
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), Failed> {
        self.reads += 1;
        if self.fails(sector) {
            return Err(Failed);
        }
        // Out of range panics: the disk never asks for a sector outside it.
        *buf = self.sectors[sector as usize];
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), Failed> {
        self.writes += 1;
        if self.fails(sector) {
            return Err(Failed);
        }
        self.sectors[sector as usize] = *data;
        Ok(())
    }
    fn flush(&mut self) -> Result<(), Failed> {
        self.flushes += 1;
        if self.dead {
            return Err(Failed);
        }
        Ok(())
    }
    fn read_sectors(&mut self, first: u64, buf: &mut [u8]) -> Result<(), Failed> {
        self.runs += 1;
        for (i, chunk) in buf.as_chunks_mut::<SECTOR>().0.iter_mut().enumerate() {
            self.read(first + i as u64, chunk)?;
        }
        Ok(())
    }
    fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Failed> {
        self.runs += 1;
        for (i, chunk) in data.as_chunks::<SECTOR>().0.iter().enumerate() {
            self.write(first + i as u64, chunk)?;
        }
        Ok(())
    }
}

std::thread_local! {
    static LOG: core::cell::RefCell<Vec<std::string::String>> = const { core::cell::RefCell::new(Vec::new()) };
}

fn log(line: core::fmt::Arguments) {
    LOG.with(|l| l.borrow_mut().push(std::format!("{line}")));
}

fn logged() -> Vec<std::string::String> {
    LOG.with(|l| l.borrow_mut().drain(..).collect())
}

fn disk(sectors: usize) -> Disk<Memory> {
    logged();
    Disk::new(Memory::new(sectors), sectors as u64, log)
}

/// The bytes `[from, from + len)` of a fresh [`Memory`] disk.
fn fresh(from: usize, len: usize) -> Vec<u8> {
    (from..from + len).map(|b| (b / SECTOR) as u8).collect()
}

#[test]
fn the_file_names_the_ports_and_the_size() {
    let f = parse_disk_file("request=vda-req\nresponse=vda-resp\nsectors=4096\n").unwrap();
    assert_eq!(
        f,
        DiskFile {
            request: "vda-req",
            response: "vda-resp",
            sectors: 4096
        }
    );
    assert_eq!(
        parse_disk_file("request=a\nresponse=b\n"),
        Err((2, "no sectors"))
    );
    assert_eq!(
        parse_disk_file("request=a\nsize=1\n"),
        Err((2, "unknown key"))
    );
    assert_eq!(
        parse_disk_file("request=a\nresponse=b\nsectors=0\n"),
        Err((3, "sectors is no number of sectors"))
    );
    assert_eq!(
        parse_disk_file("request=a\nresponse=b\nsectors=18446744073709551615\n"),
        Err((3, "sectors is no number of sectors"))
    );
    assert_eq!(parse_disk_file("oops"), Err((1, "expected key=value")));
}

#[test]
fn reads_at_any_offset_and_length_stop_at_the_end() {
    let mut d = disk(8);
    assert_eq!(d.size(), 4096);
    let mut buf = [0u8; 1500];
    assert_eq!(d.read(700, &mut buf), Ok(1500));
    assert_eq!(&buf[..], &fresh(700, 1500)[..]);
    // Sectors 1..=4 read once; read again, they come from the cache.
    assert_eq!(d.device_mut().reads, 4);
    assert_eq!(d.read(1024, &mut buf[..10]), Ok(10));
    assert_eq!(d.device_mut().reads, 4);
    // Across the end: up to it; at or past it: 0.
    assert_eq!(d.read(4000, &mut buf), Ok(96));
    assert_eq!(&buf[..96], &fresh(4000, 96)[..]);
    assert_eq!(d.read(4096, &mut buf), Ok(0));
    assert_eq!(d.read(u64::MAX, &mut buf), Ok(0));
    assert_eq!(d.read(0, &mut []), Ok(0));
}

#[test]
fn partial_sectors_are_read_changed_and_written() {
    let mut d = disk(8);
    assert_eq!(d.write(510, b"abcd"), Ok(4));
    let m = d.device_mut();
    assert_eq!((m.reads, m.writes), (2, 2));
    assert_eq!(&m.sectors[0][508..], &[0, 0, b'a', b'b']);
    assert_eq!(&m.sectors[1][..4], &[b'c', b'd', 1, 1]);
    // Whole sectors are written without reading them.
    let whole = [7u8; 1024];
    assert_eq!(d.write(2048, &whole), Ok(1024));
    assert_eq!((d.device_mut().reads, d.device_mut().writes), (2, 4));
    let mut back = [0u8; 1030];
    assert_eq!(d.read(2045, &mut back), Ok(1030));
    assert_eq!(&back[..3], &[3, 3, 3]);
    assert!(back[3..1027].iter().all(|&b| b == 7));
    assert_eq!(&back[1027..], &[6, 6, 6]);
    // Written sectors are in the cache: no read for them.
    assert_eq!(d.device_mut().reads, 4);
}

#[test]
fn writes_past_the_end_are_enospc_and_across_it_short() {
    let mut d = disk(2);
    assert_eq!(d.write(1020, &[9; 10]), Ok(4));
    assert_eq!(&d.device_mut().sectors[1][508..], &[9, 9, 9, 9]);
    assert_eq!(d.write(1024, &[9]), Err(Errno::ENOSPC));
    assert_eq!(d.write(u64::MAX, &[9]), Err(Errno::ENOSPC));
    assert_eq!(d.write(5000, &[]), Ok(0));
}

#[test]
fn one_call_moves_at_most_max_transfer() {
    let sectors = MAX_TRANSFER / SECTOR * 2;
    let mut d = disk(sectors);
    let mut buf = vec![0u8; MAX_TRANSFER * 2];
    assert_eq!(d.read(1, &mut buf), Ok(MAX_TRANSFER));
    assert_eq!(d.write(1, &buf), Ok(MAX_TRANSFER));
}

#[test]
fn the_cache_is_bounded_and_keeps_the_recent_sectors() {
    let sectors = CACHE_SECTORS * 2;
    let mut d = disk(sectors);
    assert_eq!(d.cached_sectors(), 0);
    let mut all = vec![0u8; sectors * SECTOR];
    assert_eq!(d.read(0, &mut all), Ok(sectors * SECTOR));
    assert_eq!(d.cached_sectors(), CACHE_SECTORS);
    let reads = d.device_mut().reads;
    // The last CACHE_SECTORS sectors are cached, the first are not.
    let mut one = [0u8; 1];
    d.read(((sectors - 1) * SECTOR) as u64, &mut one).unwrap();
    assert_eq!(d.device_mut().reads, reads);
    d.read(0, &mut one).unwrap();
    assert_eq!(d.device_mut().reads, reads + 1);
    assert_eq!(d.cached_sectors(), CACHE_SECTORS);
}

#[test]
fn sync_flushes_the_device_and_flsbuf_drops_the_cache() {
    let mut d = disk(4);
    d.write(0, &[1; 512]).unwrap();
    assert_eq!(d.sync(), Ok(()));
    assert_eq!(d.device_mut().flushes, 1);
    // Another writer changed the disk behind the cache (the host, between boots).
    d.device_mut().sectors[0] = [5; 512];
    let mut b = [0u8; 1];
    d.read(0, &mut b).unwrap();
    assert_eq!(b, [1]);
    assert_eq!(ioctl(BLKFLSBUF, d.size()), Ok(Answer::FlushBuffers));
    d.flush_buffers().unwrap();
    assert_eq!(d.device_mut().flushes, 2);
    assert_eq!(d.cached_sectors(), 0);
    d.read(0, &mut b).unwrap();
    assert_eq!(b, [5]);
}

#[test]
fn link_errors_are_eio_logged_a_bounded_number_of_times() {
    let mut d = disk(4);
    d.device_mut().bad = Some(1);
    let mut buf = [0u8; 1024];
    // The first sector reads, the second fails: what was read counts.
    assert_eq!(d.read(0, &mut buf), Ok(512));
    assert_eq!(d.read(512, &mut buf), Err(Errno::EIO));
    assert_eq!(d.write(512, &[1; 512]), Err(Errno::EIO));
    assert_eq!(
        logged(),
        [
            "guest: /dev/vda: read of sector 1 failed: the driver answered IoError",
            "guest: /dev/vda: read of sector 1 failed: the driver answered IoError",
            "guest: /dev/vda: write of sector 1 failed: the driver answered IoError",
        ]
    );
    // A failed write leaves the cache: the sector is read from the device again.
    d.device_mut().bad = None;
    d.write(0, &[2; 512]).unwrap();
    d.device_mut().bad = Some(0);
    assert_eq!(d.write(0, &[3; 512]), Err(Errno::EIO));
    d.device_mut().bad = None;
    let reads = d.device_mut().reads;
    d.read(0, &mut buf[..1]).unwrap();
    assert_eq!(d.device_mut().reads, reads + 1);
    logged();
    d.device_mut().dead = true;
    assert_eq!(d.sync(), Err(Errno::EIO));
    for _ in 0..100 {
        let _ = d.write(2048 - 1, &[0; 1]);
    }
    let lines = logged();
    assert_eq!(lines.len() as u32, MAX_LOGGED - 4 + 1, "{lines:#?}");
    assert_eq!(
        lines.last().unwrap(),
        "guest: /dev/vda: more requests failed, not logged"
    );
}

#[test]
fn ioctls_answer_the_size_and_the_sector_size() {
    let size = 4096 * 512;
    assert_eq!(ioctl(BLKGETSIZE64, size), Ok(Answer::U64(size)));
    assert_eq!(ioctl(BLKGETSIZE, size), Ok(Answer::U64(4096)));
    assert_eq!(ioctl(BLKSSZGET, size), Ok(Answer::U32(512)));
    assert_eq!(ioctl(BLKPBSZGET, size), Ok(Answer::U32(512)));
    assert_eq!(ioctl(BLKROGET, size), Ok(Answer::U32(0)));
    assert_eq!(ioctl(BLKDISCARDZEROES, size), Ok(Answer::U32(0)));
    assert_eq!(ioctl(0x5401, size), Err(Errno::ENOTTY)); // TCGETS
}

#[test]
fn seeking_stays_inside_the_disk() {
    assert_eq!(seek(0, 0, 2, 4096), Ok(4096));
    assert_eq!(seek(0, -1, 2, 4096), Ok(4095));
    assert_eq!(seek(100, 10, 1, 4096), Ok(110));
    assert_eq!(seek(0, 4097, 0, 4096), Err(Errno::EINVAL));
    assert_eq!(seek(0, -1, 0, 4096), Err(Errno::EINVAL));
    assert_eq!(seek(10, i64::MAX, 1, 4096), Err(Errno::EINVAL));
    assert_eq!(seek(0, 0, 3, 4096), Err(Errno::EINVAL));
}

/// Whole sectors of a call go to the device as one run (the link moves several a request);
/// only a partial first or last sector goes alone, read and written back.
#[test]
fn whole_sectors_go_as_one_run() {
    let mut d = disk(32);
    let data = vec![7u8; 8 * SECTOR];
    assert_eq!(d.write(0, &data), Ok(8 * SECTOR));
    assert_eq!((d.device_mut().runs, d.device_mut().writes), (1, 8));
    // 100 bytes into sector 8, through sector 11, ending 100 bytes into sector 12.
    let data = vec![9u8; 4 * SECTOR];
    assert_eq!(d.write(8 * SECTOR as u64 + 100, &data), Ok(4 * SECTOR));
    let m = d.device_mut();
    // A partial sector is a run of one read and one written; the 3 whole ones one run.
    assert_eq!(
        (m.runs, m.writes, m.reads),
        (6, 13, 2),
        "partial, run of 3, partial"
    );
    assert_eq!(m.sectors[8][..100], [8; 100]);
    assert_eq!(m.sectors[8][100..], [9; 412]);
    assert_eq!(m.sectors[12][..100], [9; 100]);
    assert_eq!(m.sectors[12][100..], [12; 412]);
    // Reading sectors 16..24 (not cached): one run.
    let mut back = vec![0u8; 8 * SECTOR];
    assert_eq!(d.read(16 * SECTOR as u64, &mut back), Ok(8 * SECTOR));
    assert_eq!(d.device_mut().runs, 7);
    assert!(
        back.chunks(SECTOR)
            .enumerate()
            .all(|(i, s)| s == [16 + i as u8; SECTOR])
    );
}
