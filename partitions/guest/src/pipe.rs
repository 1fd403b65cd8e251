//! The guest's pipes: a table of byte rings on the guest's heap, each with the number of
//! open read and write descriptors (over all processes). Reading an empty pipe that still
//! has writers and writing a full pipe that still has readers *would block*: the caller then
//! defers its reply ([`crate::system`]); an empty pipe without writers reads end of file, a
//! pipe without readers refuses writes (`EPIPE`, `SIGPIPE`).
//!
//! A pipe buffers [`PIPE_CAPACITY`] bytes, as Linux's do by default, while the pipes'
//! buffers stay within the table's byte budget (a share of the heap); beyond it a new pipe
//! gets [`PIPE_BUF`] bytes, as Linux gives one page once a user's pipes exceed
//! `pipe-user-pages-soft`, and with no budget left `pipe` fails (`ENFILE`).

use alloc::vec::Vec;

/// Bytes a write of at most this many goes into a pipe in one piece (Linux's `PIPE_BUF`):
/// it waits until they all fit rather than split.
pub const PIPE_BUF: usize = 4096;
/// Bytes a pipe buffers (Linux's default pipe capacity, 16 pages).
pub const PIPE_CAPACITY: usize = 65536;
/// Most pipes open at once in a guest.
pub const MAX_PIPES: usize = 64;
/// The pipes' byte budget of [`Pipes::new`] (the partition program sets its own from its
/// heap).
pub const DEFAULT_BUDGET: usize = 1 << 20;

/// One pipe's ring and its open ends.
#[derive(Clone, Debug)]
struct Pipe {
    /// The ring: its length is the pipe's capacity.
    bytes: Vec<u8>,
    start: usize,
    len: usize,
    readers: u32,
    writers: u32,
}

impl Pipe {
    fn room(&self) -> usize {
        self.bytes.len() - self.len
    }
}

/// What a pipe operation did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transfer {
    /// This many bytes moved (0 on a read: end of file).
    Done(usize),
    /// Nothing can move yet: the caller waits.
    WouldBlock,
    /// A write to a pipe nobody reads.
    Broken,
}

/// The pipes of a guest, by index.
#[derive(Clone, Debug)]
pub struct Pipes {
    pipes: [Option<Pipe>; MAX_PIPES],
    /// Bytes the pipes' rings may take together.
    budget: usize,
}

impl Default for Pipes {
    fn default() -> Self {
        Self::new()
    }
}

impl Pipes {
    /// A table whose rings take at most [`DEFAULT_BUDGET`] bytes.
    pub const fn new() -> Self {
        Self::with_budget(DEFAULT_BUDGET)
    }

    /// A table whose rings take at most `budget` bytes.
    pub const fn with_budget(budget: usize) -> Self {
        Self {
            pipes: [const { None }; MAX_PIPES],
            budget,
        }
    }

    /// A new empty pipe with one reader and one writer; `None` when all are in use or the
    /// budget (or the heap) has no room for even [`PIPE_BUF`] bytes.
    pub fn open(&mut self) -> Option<usize> {
        let index = self.pipes.iter().position(Option::is_none)?;
        let used: usize = self.pipes.iter().flatten().map(|p| p.bytes.len()).sum();
        let left = self.budget.saturating_sub(used);
        let bytes = [PIPE_CAPACITY, PIPE_BUF]
            .into_iter()
            .filter(|&size| size <= left)
            .find_map(|size| {
                let mut bytes = Vec::new();
                bytes.try_reserve_exact(size).ok()?;
                bytes.resize(size, 0);
                Some(bytes)
            })?;
        self.pipes[index] = Some(Pipe {
            bytes,
            start: 0,
            len: 0,
            readers: 1,
            writers: 1,
        });
        Some(index)
    }

    /// How many pipes are open.
    pub fn open_count(&self) -> usize {
        self.pipes.iter().flatten().count()
    }

    /// Bytes buffered in pipe `index`.
    pub fn buffered(&self, index: usize) -> usize {
        self.pipes
            .get(index)
            .and_then(Option::as_ref)
            .map_or(0, |p| p.len)
    }

    /// The bytes pipe `index` buffers at most.
    pub fn capacity(&self, index: usize) -> usize {
        self.pipes
            .get(index)
            .and_then(Option::as_ref)
            .map_or(0, |p| p.bytes.len())
    }

    /// The `poll` events of pipe `index`'s read or write end: readable when it buffers
    /// bytes, hung up when the other end is gone, writable while it has room for
    /// [`PIPE_BUF`] bytes (a page, as Linux's free buffer slot).
    pub fn poll(&self, index: usize, write: bool) -> u16 {
        use crate::poll::{POLLERR, POLLHUP, POLLIN, POLLOUT};
        let Some(Some(p)) = self.pipes.get(index) else {
            return POLLERR;
        };
        match write {
            false => {
                let data = if p.len > 0 { POLLIN } else { 0 };
                data | if p.writers == 0 { POLLHUP } else { 0 }
            }
            true if p.readers == 0 => POLLERR,
            true => {
                if p.room() >= PIPE_BUF {
                    POLLOUT
                } else {
                    0
                }
            }
        }
    }

    /// Whether pipe `index`'s read or write end still has a descriptor.
    pub fn end_open(&self, index: usize, write: bool) -> bool {
        self.pipes
            .get(index)
            .and_then(Option::as_ref)
            .is_some_and(|p| if write { p.writers > 0 } else { p.readers > 0 })
    }

    /// One more descriptor for an end (`dup`, `fork`).
    pub fn add_end(&mut self, index: usize, write: bool) {
        if let Some(Some(p)) = self.pipes.get_mut(index) {
            if write {
                p.writers += 1;
            } else {
                p.readers += 1;
            }
        }
    }

    /// A descriptor for an end closed; the pipe goes when no end is left.
    pub fn close_end(&mut self, index: usize, write: bool) {
        let Some(slot) = self.pipes.get_mut(index) else {
            return;
        };
        if let Some(p) = slot {
            if write {
                p.writers = p.writers.saturating_sub(1);
            } else {
                p.readers = p.readers.saturating_sub(1);
            }
            if p.readers == 0 && p.writers == 0 {
                *slot = None;
            }
        }
    }

    /// Moves up to `buf.len()` buffered bytes of pipe `index` into `buf`.
    pub fn read(&mut self, index: usize, buf: &mut [u8]) -> Transfer {
        let Some(Some(p)) = self.pipes.get_mut(index) else {
            return Transfer::Done(0);
        };
        if p.len == 0 {
            return if p.writers == 0 || buf.is_empty() {
                Transfer::Done(0)
            } else {
                Transfer::WouldBlock
            };
        }
        let n = buf.len().min(p.len);
        // At most two pieces: up to the ring's end, then from its start.
        let first = n.min(p.bytes.len() - p.start);
        buf[..first].copy_from_slice(&p.bytes[p.start..p.start + first]);
        buf[first..n].copy_from_slice(&p.bytes[..n - first]);
        p.start = (p.start + n) % p.bytes.len();
        p.len -= n;
        if p.len == 0 {
            p.start = 0; // the next writes go in one piece
        }
        Transfer::Done(n)
    }

    /// Appends as much of `data` as fits into pipe `index`.
    pub fn write(&mut self, index: usize, data: &[u8]) -> Transfer {
        let Some(Some(p)) = self.pipes.get_mut(index) else {
            return Transfer::Broken;
        };
        if p.readers == 0 {
            return Transfer::Broken;
        }
        let room = p.room();
        // Up to PIPE_BUF bytes go in one piece or wait (POSIX atomicity).
        if data.is_empty() {
            return Transfer::Done(0);
        }
        if room == 0 || (data.len() <= PIPE_BUF && room < data.len()) {
            return Transfer::WouldBlock;
        }
        let n = data.len().min(room);
        let size = p.bytes.len();
        let end = (p.start + p.len) % size;
        let first = n.min(size - end);
        p.bytes[end..end + first].copy_from_slice(&data[..first]);
        p.bytes[..n - first].copy_from_slice(&data[first..n]);
        p.len += n;
        Transfer::Done(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_what_was_written_then_end_of_file_without_writers() {
        let mut pipes = Pipes::new();
        let p = pipes.open().unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(pipes.read(p, &mut buf), Transfer::WouldBlock);
        assert_eq!(pipes.write(p, b"hello"), Transfer::Done(5));
        assert_eq!(pipes.read(p, &mut buf[..3]), Transfer::Done(3));
        assert_eq!(&buf[..3], b"hel");
        assert_eq!(pipes.write(p, b" world"), Transfer::Done(6));
        assert_eq!(pipes.read(p, &mut buf), Transfer::Done(8));
        assert_eq!(&buf, b"lo world");
        pipes.add_end(p, true); // a second writer (dup)
        pipes.close_end(p, true);
        assert_eq!(pipes.read(p, &mut buf), Transfer::WouldBlock);
        pipes.close_end(p, true);
        assert_eq!(pipes.read(p, &mut buf), Transfer::Done(0), "end of file");
        pipes.close_end(p, false);
        assert_eq!(pipes.open_count(), 0, "no end left: freed");
    }

    #[test]
    fn full_pipes_block_small_writes_whole_and_readerless_pipes_break() {
        // A budget of one small pipe: PIPE_BUF bytes.
        let mut pipes = Pipes::with_budget(PIPE_BUF);
        let p = pipes.open().unwrap();
        assert_eq!(pipes.capacity(p), PIPE_BUF);
        assert_eq!(pipes.open(), None, "no budget left");
        const PIPE_SIZE: usize = PIPE_BUF;
        assert_eq!(
            pipes.write(p, &[1; PIPE_SIZE - 2]),
            Transfer::Done(PIPE_SIZE - 2)
        );
        // Three bytes do not fit in two: an atomic write waits rather than splits.
        assert_eq!(pipes.write(p, &[2; 3]), Transfer::WouldBlock);
        assert_eq!(pipes.write(p, &[2; 2]), Transfer::Done(2));
        assert_eq!(pipes.write(p, &[3; 1]), Transfer::WouldBlock);
        let mut buf = [0u8; PIPE_SIZE];
        assert_eq!(pipes.read(p, &mut buf[..10]), Transfer::Done(10));
        // A write larger than the pipe goes in pieces.
        assert_eq!(pipes.write(p, &[4; PIPE_SIZE + 1]), Transfer::Done(10));
        assert_eq!(pipes.read(p, &mut buf), Transfer::Done(PIPE_SIZE));
        assert_eq!(buf[PIPE_SIZE - 1], 4, "the ring wrapped in order");
        pipes.close_end(p, false);
        assert_eq!(pipes.write(p, b"x"), Transfer::Broken);
    }

    #[test]
    fn pipes_buffer_64_kib_within_their_budget_then_a_page_then_none() {
        let mut pipes = Pipes::with_budget(2 * PIPE_CAPACITY + 3 * PIPE_BUF);
        let big: Vec<usize> = (0..2).map(|_| pipes.open().unwrap()).collect();
        assert!(big.iter().all(|&p| pipes.capacity(p) == PIPE_CAPACITY));
        let small: Vec<usize> = (0..3).map(|_| pipes.open().unwrap()).collect();
        assert!(small.iter().all(|&p| pipes.capacity(p) == PIPE_BUF));
        assert_eq!(pipes.open(), None, "the budget is spent");
        // A closed pipe gives its bytes back.
        pipes.close_end(big[0], true);
        pipes.close_end(big[0], false);
        let again = pipes.open().unwrap();
        assert_eq!(pipes.capacity(again), PIPE_CAPACITY);
        // 64 KiB go in without a reader taking any; writable while a page is free.
        let p = big[1];
        let data: Vec<u8> = (0..PIPE_CAPACITY).map(|i| (i * 7) as u8).collect();
        assert_eq!(pipes.write(p, &data[..1000]), Transfer::Done(1000));
        assert_eq!(
            pipes.write(p, &data[1000..]),
            Transfer::Done(PIPE_CAPACITY - 1000)
        );
        assert_eq!(pipes.poll(p, true) & crate::poll::POLLOUT, 0);
        let mut out = alloc::vec![0u8; PIPE_CAPACITY];
        assert_eq!(
            pipes.read(p, &mut out[..PIPE_BUF]),
            Transfer::Done(PIPE_BUF)
        );
        assert_ne!(pipes.poll(p, true) & crate::poll::POLLOUT, 0);
        // The ring wraps: what comes out is what went in, in order.
        assert_eq!(pipes.write(p, &data[..PIPE_BUF]), Transfer::Done(PIPE_BUF));
        assert_eq!(pipes.read(p, &mut out), Transfer::Done(PIPE_CAPACITY));
        assert_eq!(&out[..PIPE_CAPACITY - PIPE_BUF], &data[PIPE_BUF..]);
        assert_eq!(&out[PIPE_CAPACITY - PIPE_BUF..], &data[..PIPE_BUF]);
        // Every slot in use: none more.
        let mut pipes = Pipes::with_budget(usize::MAX);
        for _ in 0..MAX_PIPES {
            assert!(pipes.open().is_some());
        }
        assert_eq!(pipes.open(), None, "all pipes in use");
    }
}
