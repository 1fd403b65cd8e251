//! The console of the guest's processes when it has no terminal (no `guest.console`; the
//! terminal is [`crate::tty`]): their output is cut into lines, and each line is logged as
//! `guest: process <pid> <stdout|stderr>: <text>` (the kernel log then prefixes it with
//! the partition's name). A line longer than [`LINE_MAX`] bytes is cut there; what is left
//! without a newline when the process ends is logged with [`LineBuffer::flush`].

use crate::process::Stream;

/// Longest line logged in one piece.
pub const LINE_MAX: usize = 200;

/// One stream's pending partial line.
#[derive(Clone, Debug)]
pub struct LineBuffer {
    bytes: [u8; LINE_MAX],
    len: usize,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineBuffer {
    pub const fn new() -> Self {
        Self {
            bytes: [0; LINE_MAX],
            len: 0,
        }
    }

    /// Appends `data`; `line` gets every completed line (without its newline).
    pub fn write(&mut self, data: &[u8], mut line: impl FnMut(&[u8])) {
        for &b in data {
            if b == b'\n' {
                line(&self.bytes[..self.len]);
                self.len = 0;
                continue;
            }
            if self.len == LINE_MAX {
                line(&self.bytes[..self.len]);
                self.len = 0;
            }
            self.bytes[self.len] = b;
            self.len += 1;
        }
    }

    /// Hands out the partial line, if any.
    pub fn flush(&mut self, mut line: impl FnMut(&[u8])) {
        if self.len > 0 {
            line(&self.bytes[..self.len]);
            self.len = 0;
        }
    }
}

/// The name of a stream in the log line.
pub fn stream_name(stream: Stream) -> &'static str {
    match stream {
        Stream::Stdout => "stdout",
        Stream::Stderr => "stderr",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cuts_lines() {
        let mut b = LineBuffer::new();
        let mut lines: Vec<Vec<u8>> = Vec::new();
        b.write(b"hel", |l| lines.push(l.to_vec()));
        b.write(b"lo\nworld\n\npartial", |l| lines.push(l.to_vec()));
        assert_eq!(lines, [&b"hello"[..], b"world", b""]);
        b.flush(|l| lines.push(l.to_vec()));
        assert_eq!(lines.last().unwrap(), b"partial");
        lines.clear();
        b.flush(|l| lines.push(l.to_vec()));
        assert!(lines.is_empty());
        b.write(&[b'x'; LINE_MAX + 5], |l| lines.push(l.to_vec()));
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].len(), LINE_MAX);
    }
}
