//! The kernel log on COM1. Serial line format (an interface, see README):
//! `[SSSS.UUUUUU] text` — seconds and microseconds since kernel entry, then the message.

use crate::arch::serial::{COM1, Uart};
#[cfg(not(test))]
use core::fmt::Write;
use spin::Mutex;

static SERIAL: Mutex<Uart> = Mutex::new(Uart::new(COM1));

pub fn init() {
    SERIAL.lock().init();
}

/// Lets a fatal path (panic, exception) print even if it interrupted a log write.
#[allow(unsafe_code)] // breaks the lock of an interrupted writer
pub fn force_unlock() {
    if SERIAL.is_locked() {
        // SAFETY: only called on the way to halting the machine; the interrupted writer
        // never resumes, so no two writers can use the UART at once afterwards.
        unsafe { SERIAL.force_unlock() };
    }
}

#[cfg(not(test))]
struct Writer<'a>(&'a Uart);

#[cfg(not(test))]
impl Write for Writer<'_> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for byte in s.bytes() {
            self.0.write_byte(byte);
        }
        Ok(())
    }
}

/// Splits nanoseconds into whole seconds and the microsecond remainder.
pub fn timestamp_parts(ns: u64) -> (u64, u64) {
    (ns / 1_000_000_000, (ns % 1_000_000_000) / 1_000)
}

#[cfg(test)]
pub fn print_line(args: core::fmt::Arguments) {
    std::println!("{args}");
}

#[cfg(not(test))]
pub fn print_line(args: core::fmt::Arguments) {
    let (secs, micros) = timestamp_parts(crate::time::since_boot_ns());
    let uart = SERIAL.lock();
    let mut w = Writer(&uart);
    let _ = write!(w, "[{secs:4}.{micros:06}] ");
    let _ = w.write_fmt(args);
    let _ = w.write_str("\n");
}

/// Prints one timestamped line on the kernel log.
#[macro_export]
macro_rules! kprintln {
    ($($arg:tt)*) => { $crate::log::print_line(format_args!($($arg)*)) };
}

#[cfg(test)]
mod tests {
    #[test]
    fn timestamp_splits_seconds_and_micros() {
        assert_eq!(super::timestamp_parts(0), (0, 0));
        assert_eq!(super::timestamp_parts(1_234_567_891), (1, 234_567));
        assert_eq!(super::timestamp_parts(999), (0, 0));
    }
}
