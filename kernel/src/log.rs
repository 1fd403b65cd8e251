//! The kernel log on COM1. Serial line format (an interface, see docs/interfaces.md):
//! `[SSSS.UUUUUU] text` — seconds and microseconds since kernel entry, then the message.
//!
//! Writing the log never makes the kernel wait for the UART (at 115,200 baud a 512-byte
//! `debug_write` line takes 44 ms, with interrupts off): a line goes whole into a ring
//! buffer ([`Ring`]) and the UART takes only what it accepts at once (its FIFO, when
//! empty); the rest goes out at the next kernel exit ([`drain`]). A line the ring cannot
//! hold is dropped and counted, and the next line that fits is preceded by
//! `log: N lines dropped`. Only the way to halting ([`flush`]) waits for the UART.

use crate::arch::serial::{COM1, Uart};
#[cfg(not(test))]
use core::fmt::Write;
use spin::Mutex;

/// Bytes the ring holds: 100 of the longest `debug_write` lines (a host reading QEMU's
/// serial output slowly for a moment must not cost lines).
pub const LOG_BUFFER: usize = 64 * 1024;
/// Bytes the UART's transmit FIFO takes once it is empty (16550).
const UART_FIFO: usize = 16;
/// The longest line kept (longer ones are cut): a `debug_write` of 512 bytes, its task's
/// name and the time stamp fit.
#[cfg(not(test))]
const LINE_MAX: usize = 640;

/// Log lines on their way to the UART; see the module documentation.
pub struct Ring {
    bytes: [u8; LOG_BUFFER],
    start: usize,
    len: usize,
    /// Lines dropped since the last notice.
    pub dropped: u64,
}

impl Ring {
    pub const fn new() -> Self {
        Self {
            bytes: [0; LOG_BUFFER],
            start: 0,
            len: 0,
            dropped: 0,
        }
    }

    /// Appends `line` whole, or counts it as dropped (false) when it does not fit.
    pub fn push(&mut self, line: &[u8]) -> bool {
        if line.len() > LOG_BUFFER - self.len {
            self.dropped += 1;
            return false;
        }
        let at = (self.start + self.len) % LOG_BUFFER;
        let (head, tail) = line.split_at(line.len().min(LOG_BUFFER - at));
        self.bytes[at..at + head.len()].copy_from_slice(head);
        self.bytes[..tail.len()].copy_from_slice(tail);
        self.len += line.len();
        true
    }

    /// Gives `send` the oldest bytes, a FIFO's worth each time `ready` says the UART's
    /// FIFO is empty, until it is not or the ring is.
    pub fn drain(&mut self, ready: impl Fn() -> bool, mut send: impl FnMut(u8)) {
        while self.len > 0 && ready() {
            for _ in 0..UART_FIFO.min(self.len) {
                send(self.bytes[self.start]);
                self.start = (self.start + 1) % LOG_BUFFER;
                self.len -= 1;
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl Default for Ring {
    fn default() -> Self {
        Self::new()
    }
}

static LOG: Mutex<(Uart, Ring)> = Mutex::new((Uart::new(COM1), Ring::new()));

pub fn init() {
    LOG.lock().0.init();
}

/// Lets a fatal path (panic, exception) print even if it interrupted a log write.
#[allow(unsafe_code)] // breaks the lock of an interrupted writer
pub fn force_unlock() {
    if LOG.is_locked() {
        // SAFETY: only called on the way to halting the machine; the interrupted writer
        // never resumes, so no two writers can use the UART or the ring at once afterwards.
        unsafe { LOG.force_unlock() };
    }
}

/// Hands the UART what it takes without waiting (at every kernel exit).
pub fn drain() {
    let mut log = LOG.lock();
    if !log.1.is_empty() {
        let (uart, ring) = &mut *log;
        ring.drain(|| uart.ready(), |byte| uart.send(byte));
    }
}

/// Writes out everything still in the ring, waiting for the UART (before halting).
pub fn flush() {
    let (uart, ring) = &mut *LOG.lock();
    ring.drain(|| true, |byte| uart.write_byte(byte));
}

/// Splits nanoseconds into whole seconds and the microsecond remainder.
pub fn timestamp_parts(ns: u64) -> (u64, u64) {
    (ns / 1_000_000_000, (ns % 1_000_000_000) / 1_000)
}

#[cfg(test)]
pub fn print_line(args: core::fmt::Arguments) {
    std::println!("{args}");
}

/// One line being formatted (cut at [`LINE_MAX`] bytes).
#[cfg(not(test))]
struct Line {
    bytes: [u8; LINE_MAX],
    len: usize,
}

#[cfg(not(test))]
impl Write for Line {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let n = s.len().min(LINE_MAX - 1 - self.len);
        self.bytes[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

#[cfg(not(test))]
pub fn print_line(args: core::fmt::Arguments) {
    let (secs, micros) = timestamp_parts(crate::time::since_boot_ns());
    let mut line = Line {
        bytes: [0; LINE_MAX],
        len: 0,
    };
    let mut log = LOG.lock();
    let (uart, ring) = &mut *log;
    if ring.dropped > 0 {
        let _ = write!(
            line,
            "[{secs:4}.{micros:06}] log: {} lines dropped",
            ring.dropped
        );
        line.bytes[line.len] = b'\n';
        let dropped = ring.dropped;
        if ring.push(&line.bytes[..=line.len]) {
            ring.dropped = 0;
        } else {
            ring.dropped = dropped + 1;
        }
        line.len = 0;
    }
    let _ = write!(line, "[{secs:4}.{micros:06}] ");
    let _ = line.write_fmt(args);
    line.bytes[line.len] = b'\n';
    ring.push(&line.bytes[..=line.len]);
    ring.drain(|| uart.ready(), |byte| uart.send(byte));
}

/// Prints one timestamped line on the kernel log.
#[macro_export]
macro_rules! kprintln {
    ($($arg:tt)*) => { $crate::log::print_line(format_args!($($arg)*)) };
}

#[cfg(test)]
#[path = "../host-tests/log.rs"]
mod tests;
