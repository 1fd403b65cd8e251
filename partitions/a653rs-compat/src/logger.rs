//! `a653rs_linux::partition::ApexLogger` for Warden: `log` records become lines of the
//! partition's log (`LEVEL text`, one log line per line of the message, as a653rs-linux
//! sends one application message per line).

use core::fmt::Write as _;

/// The logger a653rs-linux programs install with `ApexLogger::install_logger(level)`.
pub struct ApexLogger;

/// The longest line written; a longer one ends in `..` (a653rs-linux cuts at its
/// application-message size, 128 bytes, which would lose most of a ping report).
pub const MAX_LINE: usize = 200;
/// The longest message text looked at (its lines are cut to [`MAX_LINE`] each).
const MAX_TEXT: usize = 4 * MAX_LINE;

#[cfg(feature = "runtime")]
static LOGGER: ApexLogger = ApexLogger;

#[cfg(feature = "runtime")]
impl ApexLogger {
    /// Makes [`ApexLogger`] the `log` crate's logger, passing records up to `level`.
    pub fn install_logger(level: log::LevelFilter) -> Result<(), log::SetLoggerError> {
        log::set_logger(&LOGGER)?;
        log::set_max_level(level);
        Ok(())
    }

    /// Nothing to install: Warden's runtime already writes a panic to the partition's log
    /// (`panic at FILE:LINE: message`) and reports it to the health monitor.
    pub fn install_panic_hook() {}
}

#[cfg(feature = "runtime")]
impl log::Log for ApexLogger {
    fn enabled(&self, _: &log::Metadata<'_>) -> bool {
        true
    }

    fn log(&self, record: &log::Record<'_>) {
        lines(record.level(), record.args(), &mut |line| {
            apex::user_rt::println!("{line}")
        });
    }

    fn flush(&self) {}
}

/// Text of at most `N` bytes, built without the heap; what does not fit is dropped.
struct Text<const N: usize> {
    bytes: [u8; N],
    len: usize,
    cut: bool,
}

impl<const N: usize> Text<N> {
    const fn new() -> Self {
        Text {
            bytes: [0; N],
            len: 0,
            cut: false,
        }
    }

    /// The text (up to the last whole character).
    fn as_str(&self) -> &str {
        let bytes = &self.bytes[..self.len];
        match core::str::from_utf8(bytes) {
            Ok(s) => s,
            Err(e) => core::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or_default(),
        }
    }
}

impl<const N: usize> core::fmt::Write for Text<N> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let room = N - self.len;
        let take = s.len().min(room);
        self.bytes[self.len..self.len + take].copy_from_slice(&s.as_bytes()[..take]);
        self.len += take;
        self.cut |= take < s.len();
        Ok(())
    }
}

/// Calls `emit` with each line of the message `args`, prefixed by `level` (padded to 5),
/// each at most [`MAX_LINE`] bytes (a longer one ends in `..`).
pub fn lines(level: log::Level, args: &core::fmt::Arguments<'_>, emit: &mut dyn FnMut(&str)) {
    let mut text = Text::<MAX_TEXT>::new();
    let _ = write!(text, "{args}");
    for line in text.as_str().lines() {
        let mut out = Text::<MAX_LINE>::new();
        let _ = write!(out, "{:<5} {line}", level.as_str());
        if out.cut {
            out.len = out.as_str().len().min(MAX_LINE - 2);
            let _ = out.write_str("..");
        }
        emit(out.as_str());
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::{String, ToString};
    use std::vec::Vec;

    fn collect(level: log::Level, args: core::fmt::Arguments<'_>) -> Vec<String> {
        let mut out = Vec::new();
        lines(level, &args, &mut |l| out.push(l.to_string()));
        out
    }

    #[test]
    fn each_line_of_a_message_is_a_log_line_with_the_level() {
        assert_eq!(
            collect(log::Level::Info, format_args!("sending a request")),
            ["INFO  sending a request"]
        );
        assert_eq!(
            collect(log::Level::Warn, format_args!("a\n\tb {}", 7)),
            ["WARN  a", "WARN  \tb 7"]
        );
    }

    #[test]
    fn a_long_line_is_cut_with_dots() {
        let long = "x".repeat(500);
        let out = collect(log::Level::Error, format_args!("{long}"));
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].len(), MAX_LINE);
        assert!(out[0].starts_with("ERROR xxx") && out[0].ends_with("x.."));
    }
}
