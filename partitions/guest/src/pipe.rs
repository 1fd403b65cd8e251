//! The guest's pipes: a fixed table of byte rings, each with the number of open read and
//! write descriptors (over all processes). Reading an empty pipe that still has writers
//! and writing a full pipe that still has readers *would block*: the caller then defers
//! its reply ([`crate::system`]); an empty pipe without writers reads end of file, a pipe
//! without readers refuses writes (`EPIPE`, `SIGPIPE`).

/// Bytes a pipe buffers (Linux's `PIPE_BUF`: writes up to it are atomic).
pub const PIPE_SIZE: usize = 4096;
/// Most pipes open at once in a guest.
pub const MAX_PIPES: usize = 16;

/// One pipe's ring and its open ends.
#[derive(Clone, Debug)]
struct Pipe {
    bytes: [u8; PIPE_SIZE],
    start: usize,
    len: usize,
    readers: u32,
    writers: u32,
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
}

impl Default for Pipes {
    fn default() -> Self {
        Self::new()
    }
}

impl Pipes {
    pub const fn new() -> Self {
        Self {
            pipes: [const { None }; MAX_PIPES],
        }
    }

    /// A new empty pipe with one reader and one writer; `None` when all are in use.
    pub fn open(&mut self) -> Option<usize> {
        let index = self.pipes.iter().position(Option::is_none)?;
        self.pipes[index] = Some(Pipe {
            bytes: [0; PIPE_SIZE],
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

    /// The `poll` events of pipe `index`'s read or write end: readable when it buffers
    /// bytes, hung up when the other end is gone, writable while it has room.
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
                if p.len < PIPE_SIZE {
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
        for (i, b) in buf[..n].iter_mut().enumerate() {
            *b = p.bytes[(p.start + i) % PIPE_SIZE];
        }
        p.start = (p.start + n) % PIPE_SIZE;
        p.len -= n;
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
        let room = PIPE_SIZE - p.len;
        // Up to PIPE_SIZE bytes go in one piece or wait (POSIX atomicity).
        if data.is_empty() {
            return Transfer::Done(0);
        }
        if room == 0 || (data.len() <= PIPE_SIZE && room < data.len()) {
            return Transfer::WouldBlock;
        }
        let n = data.len().min(room);
        for (i, &b) in data[..n].iter().enumerate() {
            p.bytes[(p.start + p.len + i) % PIPE_SIZE] = b;
        }
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
        let mut pipes = Pipes::new();
        let p = pipes.open().unwrap();
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
        for _ in 0..MAX_PIPES - 1 {
            assert!(pipes.open().is_some());
        }
        assert_eq!(pipes.open(), None, "all pipes in use");
    }
}
