//! `println!` for user mode: formats into a fixed stack buffer (no heap) and writes it as
//! one kernel-log line. Longer lines are cut at the buffer size.

use abi::syscall::DEBUG_WRITE_MAX;

pub struct LineBuffer {
    buf: [u8; DEBUG_WRITE_MAX as usize],
    len: usize,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self {
            buf: [0; DEBUG_WRITE_MAX as usize],
            len: 0,
        }
    }
}

impl LineBuffer {
    pub fn as_bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }

    pub fn as_str(&self) -> &str {
        // Only whole characters are ever written (see `write_str`).
        core::str::from_utf8(self.as_bytes()).unwrap_or("")
    }

    /// `args` formatted into a new buffer (cut at its size).
    pub fn format(args: core::fmt::Arguments) -> Self {
        let mut line = Self::default();
        let _ = core::fmt::Write::write_fmt(&mut line, args);
        line
    }
}

impl core::fmt::Write for LineBuffer {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        // Cut on a character boundary so the kernel always receives valid UTF-8.
        let room = self.buf.len() - self.len;
        let mut n = s.len().min(room);
        while !s.is_char_boundary(n) {
            n -= 1;
        }
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

pub fn print_line(args: core::fmt::Arguments) {
    let _ = crate::sys::debug_write(LineBuffer::format(args).as_bytes());
}

#[macro_export]
macro_rules! println {
    ($($arg:tt)*) => { $crate::print::print_line(format_args!($($arg)*)) };
}
