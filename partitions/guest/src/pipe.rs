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
//!
//! A connected pair of `AF_UNIX` stream sockets (`socketpair`) is two pipes, one each
//! way ([`Pipes::pair`]), with each end's shut-down directions: the peer reads end of
//! file (after the buffered bytes) once an end closed or shut down writing, and writes to
//! an end that closed or shut down reading fail with `EPIPE`, as Linux's.

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

/// Most socket pairs open at once (two pipes each).
pub const MAX_PAIRS: usize = MAX_PIPES / 2;

/// A socket pair: `pipes[end]` carries what `end` writes to the other end.
#[derive(Clone, Copy, Debug)]
struct Pair {
    pipes: [usize; 2],
    /// Descriptors of each end.
    refs: [u32; 2],
    /// Each end's shut-down directions: it no longer reads, no longer writes.
    shut_read: [bool; 2],
    shut_write: [bool; 2],
}

/// How `shutdown` shuts an end down (`SHUT_RD`, `SHUT_WR`, `SHUT_RDWR`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shut {
    pub read: bool,
    pub write: bool,
}

/// The pipes of a guest, by index.
#[derive(Clone, Debug)]
pub struct Pipes {
    pipes: [Option<Pipe>; MAX_PIPES],
    pairs: [Option<Pair>; MAX_PAIRS],
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
            pairs: [None; MAX_PAIRS],
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

impl Pipes {
    /// A new socket pair with one descriptor at each end (0 and 1); `None` when the pairs
    /// or the pipes are all in use or the budget has no room.
    pub fn pair(&mut self) -> Option<usize> {
        let index = self.pairs.iter().position(Option::is_none)?;
        let first = self.open()?;
        let Some(second) = self.open() else {
            self.pipes[first] = None;
            return None;
        };
        self.pairs[index] = Some(Pair {
            pipes: [first, second],
            refs: [1, 1],
            shut_read: [false; 2],
            shut_write: [false; 2],
        });
        Some(index)
    }

    fn pair_at(&mut self, pair: usize) -> Option<&mut Pair> {
        self.pairs.get_mut(pair).and_then(Option::as_mut)
    }

    /// One more descriptor of end `end` of `pair` (`dup`, `fork`).
    pub fn share_pair(&mut self, pair: usize, end: usize) {
        if let Some(p) = self.pair_at(pair) {
            p.refs[end & 1] += 1;
        }
    }

    /// A descriptor of end `end` closed: with its last the end has shut down both ways
    /// and lets go of both pipes, and the pair goes with both ends.
    pub fn close_pair(&mut self, pair: usize, end: usize) {
        let end = end & 1;
        let Some(p) = self.pair_at(pair) else {
            return;
        };
        p.refs[end] = p.refs[end].saturating_sub(1);
        if p.refs[end] > 0 {
            return;
        }
        (p.shut_read[end], p.shut_write[end]) = (true, true);
        let (mine, theirs, gone) = (p.pipes[end], p.pipes[end ^ 1], p.refs == [0, 0]);
        self.close_end(mine, true);
        self.close_end(theirs, false);
        if gone {
            self.pairs[pair] = None;
        }
    }

    /// `shutdown` of end `end`, for every descriptor of it: after reading ends, it reads
    /// what was buffered, then end of file, and the peer's writes fail; after writing
    /// ends, its writes fail and the peer reads end of file after the buffered bytes.
    pub fn shutdown(&mut self, pair: usize, end: usize, how: Shut) {
        if let Some(p) = self.pair_at(pair) {
            p.shut_read[end & 1] |= how.read;
            p.shut_write[end & 1] |= how.write;
        }
    }

    /// Reads at end `end` what the peer wrote; end of file, once the buffer is empty,
    /// after the peer shut down writing or closed, or this end shut down reading.
    pub fn read_pair(&mut self, pair: usize, end: usize, buf: &mut [u8]) -> Transfer {
        let end = end & 1;
        let Some(p) = self.pair_at(pair) else {
            return Transfer::Done(0);
        };
        let (ended, theirs) = (p.shut_read[end] || p.shut_write[end ^ 1], p.pipes[end ^ 1]);
        match self.read(theirs, buf) {
            Transfer::WouldBlock if ended => Transfer::Done(0),
            done => done,
        }
    }

    /// Writes at end `end` for the peer to read; [`Transfer::Broken`] once this end shut
    /// down writing or the peer shut down reading or closed.
    pub fn write_pair(&mut self, pair: usize, end: usize, data: &[u8]) -> Transfer {
        let end = end & 1;
        let Some(p) = self.pair_at(pair) else {
            return Transfer::Broken;
        };
        if p.shut_write[end] || p.shut_read[end ^ 1] {
            return Transfer::Broken;
        }
        let mine = p.pipes[end];
        self.write(mine, data)
    }

    /// The `poll` events of end `end`, as Linux's for a stream socket: readable with bytes
    /// or once its receiving ended (the peer shut down writing or closed, or it shut down
    /// reading), writable while its peer's buffer has room (even when a write would fail:
    /// the write says so), hung up once both its directions ended.
    pub fn poll_pair(&self, pair: usize, end: usize) -> u16 {
        use crate::poll::{POLLERR, POLLHUP, POLLIN, POLLOUT};
        let end = end & 1;
        let Some(Some(p)) = self.pairs.get(pair) else {
            return POLLERR;
        };
        let peer = end ^ 1;
        let receiving_ended = p.shut_read[end] || p.shut_write[peer];
        let sending_ended = p.shut_write[end] || p.shut_read[peer];
        let data = self.buffered(p.pipes[peer]) > 0;
        let full = self.poll(p.pipes[end], true) == 0;
        (if data || receiving_ended { POLLIN } else { 0 })
            | (if full { 0 } else { POLLOUT })
            | (if receiving_ended && sending_ended {
                POLLHUP
            } else {
                0
            })
    }

    /// Whether end `end` of `pair` still has a descriptor.
    pub fn pair_open(&self, pair: usize, end: usize) -> bool {
        self.pairs
            .get(pair)
            .and_then(Option::as_ref)
            .is_some_and(|p| p.refs[end & 1] > 0)
    }

    /// How many socket pairs are open.
    pub fn pair_count(&self) -> usize {
        self.pairs.iter().flatten().count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A socket pair both ways; `shutdown` of writing gives the peer end of file after the
    /// buffered bytes, of reading makes the peer's writes fail; `poll` as Linux's; the
    /// last descriptor of an end closes it (end of file and `EPIPE` for the peer), and the
    /// pair and its pipes go with both ends.
    #[test]
    fn a_socket_pair_talks_both_ways_and_shuts_down_as_linux() {
        use crate::poll::{POLLHUP, POLLIN, POLLOUT};
        let mut pipes = Pipes::new();
        let s = pipes.pair().unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(pipes.read_pair(s, 0, &mut buf), Transfer::WouldBlock);
        assert_eq!(pipes.poll_pair(s, 0), POLLOUT);
        assert_eq!(pipes.write_pair(s, 0, b"ping"), Transfer::Done(4));
        assert_eq!(pipes.write_pair(s, 1, b"pong"), Transfer::Done(4));
        assert_eq!(pipes.poll_pair(s, 1), POLLIN | POLLOUT);
        assert_eq!(pipes.read_pair(s, 1, &mut buf), Transfer::Done(4));
        assert_eq!(&buf[..4], b"ping");
        assert_eq!(pipes.read_pair(s, 0, &mut buf), Transfer::Done(4));
        assert_eq!(&buf[..4], b"pong");
        // End 0 stops writing: end 1 reads what was left, then end of file.
        assert_eq!(pipes.write_pair(s, 0, b"last"), Transfer::Done(4));
        let write_only = Shut {
            read: false,
            write: true,
        };
        pipes.shutdown(s, 0, write_only);
        assert_eq!(pipes.write_pair(s, 0, b"more"), Transfer::Broken);
        assert_eq!(pipes.read_pair(s, 1, &mut buf), Transfer::Done(4));
        assert_eq!(pipes.read_pair(s, 1, &mut buf), Transfer::Done(0));
        assert_eq!(pipes.poll_pair(s, 1), POLLIN | POLLOUT);
        // End 1 stops reading: end 0's writes fail from then on (they would anyway);
        // end 1 is not hung up, it still writes.
        let read_only = Shut {
            read: true,
            write: false,
        };
        pipes.shutdown(s, 1, read_only);
        assert_eq!(pipes.poll_pair(s, 1), POLLIN | POLLOUT);
        assert_eq!(pipes.poll_pair(s, 0), POLLOUT, "only its sending ended");
        // End 1 still writes to end 0.
        assert_eq!(pipes.write_pair(s, 1, b"bye"), Transfer::Done(3));
        // A second descriptor of end 1: closing one keeps it open.
        pipes.share_pair(s, 1);
        pipes.close_pair(s, 1);
        assert!(pipes.pair_open(s, 1));
        pipes.close_pair(s, 1);
        assert!(!pipes.pair_open(s, 1));
        // End 0 reads what end 1 wrote before it closed, then end of file; its writes fail.
        assert_eq!(pipes.read_pair(s, 0, &mut buf), Transfer::Done(3));
        assert_eq!(pipes.read_pair(s, 0, &mut buf), Transfer::Done(0));
        assert_eq!(pipes.poll_pair(s, 0) & (POLLIN | POLLHUP), POLLIN | POLLHUP);
        pipes.close_pair(s, 0);
        assert_eq!((pipes.pair_count(), pipes.open_count()), (0, 0));
        // A peer that closed with nothing shut down: its peer's writes break.
        let t = pipes.pair().unwrap();
        pipes.close_pair(t, 0);
        assert_eq!(pipes.write_pair(t, 1, b"x"), Transfer::Broken);
        assert_eq!(pipes.read_pair(t, 1, &mut buf), Transfer::Done(0));
    }

    #[test]
    fn socket_pairs_are_bounded_by_the_pipes() {
        let mut pipes = Pipes::with_budget(MAX_PIPES * PIPE_CAPACITY);
        let pairs: Vec<usize> = (0..MAX_PAIRS).map_while(|_| pipes.pair()).collect();
        assert_eq!(pairs.len(), MAX_PAIRS);
        assert_eq!(pipes.pair(), None);
        assert_eq!(pipes.open(), None, "every pipe is a pair's");
        pipes.close_pair(pairs[3], 0);
        pipes.close_pair(pairs[3], 1);
        assert!(pipes.pair().is_some(), "a freed pair is used again");
    }

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
