//! The guest's terminal: the line discipline between the console device (COM2, driven by
//! the partition program) and the processes that read and write it. It keeps Linux's
//! terminal state — `struct termios` with Linux's layout and defaults, the window size,
//! the foreground process group — and the input queue, and does what Linux's `n_tty`
//! does with them:
//!
//! - **Input** ([`Tty::input`], one received byte at a time): `IGNCR`, `ICRNL`, `INLCR`,
//!   `ISTRIP`; with `ISIG` the characters `VINTR`, `VQUIT` and `VSUSP` flush the queue
//!   (unless `NOFLSH`) and are answered with the [`Signal`] to send to the foreground
//!   group; with `ICANON` the line in progress is edited (`VERASE`, `VKILL`, and with
//!   `IEXTEN` `VWERASE`, `VREPRINT`, `VLNEXT`) and becomes readable at a newline, `VEOL`,
//!   `VEOL2` or `VEOF` (which ends the line without being part of it: at the start of a
//!   line, the reader sees end of file). Without `ICANON` every byte is readable at once.
//!   `ECHO` (control characters as `^X` with `ECHOCTL`), `ECHOE`, `ECHOK`, `ECHOKE`,
//!   `ECHONL` decide the echo.
//! - **Reading** ([`Tty::read`]): canonical mode hands out at most one line per call;
//!   raw mode waits for `VMIN` bytes (or fewer when the caller asked for fewer; `VMIN =
//!   0` returns at once). `VTIME`'s timer is not kept: a raw read with `VMIN = 0` never
//!   waits, one with `VMIN > 0` waits for its bytes without a time limit.
//! - **Output** ([`Tty::write`]): with `OPOST`, `ONLCR` turns `\n` into `\r\n` and
//!   `OCRNL` `\r` into `\n`. Output never waits (the device takes every byte).
//!
//! It also knows the session it is the controlling terminal of ([`Tty::session`]): a
//! process of that session outside the foreground group that reads it gets `SIGTTIN`
//! (`crate::syscall`'s `read`). Not kept: flow control (`IXON`/`IXOFF`: `VSTART`/`VSTOP`
//! are data), parity and speed (`c_cflag` is stored and reported only), `SIGTTOU`
//! (`TOSTOP`), `SIGWINCH`. Tabs are erased as one column.
//!
//! This module is pure: it never touches the device or a process; it returns what to
//! echo through the caller's output function and the signals as values.

use crate::linux::Errno;
use crate::signal::{SIGINT, SIGQUIT, SIGTSTP};

/// Bytes the input queue holds (Linux's `N_TTY_BUF_SIZE`); a canonical line is at most
/// one less.
pub const INPUT_MAX: usize = 4096;

/// Bytes of Linux's kernel `struct termios` (`TCGETS`, `TCSETS*`).
pub const TERMIOS_SIZE: usize = 36;
/// Bytes of `struct winsize` (`TIOCGWINSZ`, `TIOCSWINSZ`).
pub const WINSIZE_SIZE: usize = 8;
/// Control characters of `struct termios` (`NCCS` of the kernel's structure).
pub const NCCS: usize = 19;

/// The terminal ioctls served (x86-64 request numbers).
pub mod ioctl {
    pub const TCGETS: u64 = 0x5401;
    pub const TCSETS: u64 = 0x5402;
    /// Like `TCSETS` after the output drained (it always has).
    pub const TCSETSW: u64 = 0x5403;
    /// Like `TCSETSW`, and the pending input is discarded.
    pub const TCSETSF: u64 = 0x5404;
    pub const TCXONC: u64 = 0x540a;
    pub const TCFLSH: u64 = 0x540b;
    pub const TIOCSCTTY: u64 = 0x540e;
    pub const TIOCGPGRP: u64 = 0x540f;
    pub const TIOCSPGRP: u64 = 0x5410;
    pub const TIOCGWINSZ: u64 = 0x5413;
    pub const TIOCSWINSZ: u64 = 0x5414;
    pub const FIONREAD: u64 = 0x541b;
    /// `TCFLSH`'s argument: the input (or both) is discarded.
    pub const TCIFLUSH: u64 = 0;
    pub const TCIOFLUSH: u64 = 2;
}

/// Indexes of `c_cc`.
pub mod cc {
    pub const VINTR: usize = 0;
    pub const VQUIT: usize = 1;
    pub const VERASE: usize = 2;
    pub const VKILL: usize = 3;
    pub const VEOF: usize = 4;
    pub const VTIME: usize = 5;
    pub const VMIN: usize = 6;
    pub const VSTART: usize = 8;
    pub const VSTOP: usize = 9;
    pub const VSUSP: usize = 10;
    pub const VEOL: usize = 11;
    pub const VREPRINT: usize = 12;
    pub const VWERASE: usize = 14;
    pub const VLNEXT: usize = 15;
    pub const VEOL2: usize = 16;
}

// c_iflag
pub const ISTRIP: u32 = 0x20;
pub const INLCR: u32 = 0x40;
pub const IGNCR: u32 = 0x80;
pub const ICRNL: u32 = 0x100;
pub const IXON: u32 = 0x400;
pub const IUTF8: u32 = 0x4000;
// c_oflag
pub const OPOST: u32 = 0x1;
pub const ONLCR: u32 = 0x4;
pub const OCRNL: u32 = 0x8;
// c_cflag: B38400 | CS8 | CREAD | HUPCL, Linux's default.
pub const CFLAG_DEFAULT: u32 = 0xf | 0x30 | 0x80 | 0x400;
// c_lflag
pub const ISIG: u32 = 0x1;
pub const ICANON: u32 = 0x2;
pub const ECHO: u32 = 0x8;
pub const ECHOE: u32 = 0x10;
pub const ECHOK: u32 = 0x20;
pub const ECHONL: u32 = 0x40;
pub const NOFLSH: u32 = 0x80;
pub const ECHOCTL: u32 = 0x200;
pub const ECHOKE: u32 = 0x800;
pub const IEXTEN: u32 = 0x8000;

/// A marker in the input queue: a `VEOF` that ended a line (never handed to a reader).
const EOF_MARK: u16 = 0x100;

/// Linux's kernel `struct termios`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Termios {
    pub iflag: u32,
    pub oflag: u32,
    pub cflag: u32,
    pub lflag: u32,
    pub line: u8,
    pub cc: [u8; NCCS],
}

impl Default for Termios {
    /// Linux's `tty_std_termios` (cooked mode with echo, `^C` `^\` `DEL` `^U` `^D` ...).
    fn default() -> Self {
        Self {
            iflag: ICRNL | IXON,
            oflag: OPOST | ONLCR,
            cflag: CFLAG_DEFAULT,
            lflag: ISIG | ICANON | ECHO | ECHOE | ECHOK | ECHOCTL | ECHOKE | IEXTEN,
            line: 0,
            cc: [
                3, 0x1c, 0x7f, 0x15, 4, 0, 1, 0, 0x11, 0x13, 0x1a, 0, 0x12, 0x0f, 0x17, 0x16, 0, 0,
                0,
            ],
        }
    }
}

impl Termios {
    /// The structure as a process reads it (little-endian, no padding).
    pub fn to_bytes(&self) -> [u8; TERMIOS_SIZE] {
        let mut b = [0u8; TERMIOS_SIZE];
        for (i, v) in [self.iflag, self.oflag, self.cflag, self.lflag]
            .into_iter()
            .enumerate()
        {
            b[i * 4..i * 4 + 4].copy_from_slice(&v.to_le_bytes());
        }
        b[16] = self.line;
        b[17..].copy_from_slice(&self.cc);
        b
    }

    pub fn from_bytes(b: &[u8; TERMIOS_SIZE]) -> Self {
        let word = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let mut cc = [0u8; NCCS];
        cc.copy_from_slice(&b[17..]);
        Self {
            iflag: word(0),
            oflag: word(4),
            cflag: word(8),
            lflag: word(12),
            line: b[16],
            cc,
        }
    }

    fn local(&self, flag: u32) -> bool {
        self.lflag & flag != 0
    }

    /// Whether `byte` is control character `index` (a `0` entry is disabled, as
    /// `_POSIX_VDISABLE`).
    fn is(&self, byte: u8, index: usize) -> bool {
        self.cc[index] != 0 && self.cc[index] == byte
    }
}

/// `struct winsize`: rows, columns, and pixel sizes nobody uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Winsize {
    pub rows: u16,
    pub cols: u16,
    pub xpixel: u16,
    pub ypixel: u16,
}

impl Winsize {
    pub fn to_bytes(&self) -> [u8; WINSIZE_SIZE] {
        let mut b = [0u8; WINSIZE_SIZE];
        for (i, v) in [self.rows, self.cols, self.xpixel, self.ypixel]
            .into_iter()
            .enumerate()
        {
            b[i * 2..i * 2 + 2].copy_from_slice(&v.to_le_bytes());
        }
        b
    }

    pub fn from_bytes(b: &[u8; WINSIZE_SIZE]) -> Self {
        let half = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        Self {
            rows: half(0),
            cols: half(2),
            xpixel: half(4),
            ypixel: half(6),
        }
    }
}

/// A signal a control character sends to a process group.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Signal {
    pub signal: u32,
    pub group: u32,
}

/// The terminal.
#[derive(Clone, Debug)]
pub struct Tty {
    termios: Termios,
    winsize: Winsize,
    /// The foreground process group (who gets the control characters' signals).
    foreground: u32,
    /// The session whose controlling terminal it is (its background groups get `SIGTTIN`
    /// when they read).
    session: u32,
    /// The input: bytes and [`EOF_MARK`]s; `queue[..ready]` can be read, the rest is the
    /// canonical line being edited.
    queue: [u16; INPUT_MAX],
    len: usize,
    ready: usize,
    /// The next byte is taken literally (`VLNEXT` came).
    literal: bool,
}

impl Tty {
    /// A terminal with Linux's defaults whose foreground group and session are
    /// `foreground` (the guest's first process: the console is its controlling terminal),
    /// 24 by 80.
    pub fn new(foreground: u32) -> Self {
        Self {
            termios: Termios::default(),
            winsize: Winsize {
                rows: 24,
                cols: 80,
                ..Winsize::default()
            },
            foreground,
            session: foreground,
            queue: [0; INPUT_MAX],
            len: 0,
            ready: 0,
            literal: false,
        }
    }

    pub fn termios(&self) -> Termios {
        self.termios
    }

    /// `TCSETS*`; `flush` (`TCSETSF`) discards the pending input first. Turning
    /// `ICANON` off makes the line being edited readable; turning it on makes what follows
    /// the last complete line a line being edited.
    pub fn set_termios(&mut self, termios: Termios, flush: bool) {
        if flush {
            self.flush_input();
        }
        self.termios = termios;
        if !termios.local(ICANON) {
            self.ready = self.len;
        } else {
            self.ready = self.queue[..self.len]
                .iter()
                .rposition(|&c| c == EOF_MARK || self.ends_line(c))
                .map_or(0, |i| i + 1);
        }
    }

    pub fn winsize(&self) -> Winsize {
        self.winsize
    }

    pub fn set_winsize(&mut self, winsize: Winsize) {
        self.winsize = winsize;
    }

    pub fn foreground(&self) -> u32 {
        self.foreground
    }

    pub fn session(&self) -> u32 {
        self.session
    }

    /// `TIOCSCTTY` of session leader `session`, in process group `group`: the terminal
    /// becomes its controlling terminal, with `group` in the foreground.
    pub fn set_session(&mut self, session: u32, group: u32) {
        self.session = session;
        self.foreground = group;
    }

    /// `TIOCSPGRP`: a group id must be positive (`EINVAL`).
    pub fn set_foreground(&mut self, group: i32) -> Result<(), Errno> {
        if group <= 0 {
            return Err(Errno::EINVAL);
        }
        self.foreground = group as u32;
        Ok(())
    }

    /// Discards the pending input (`TCFLSH`, `TCSETSF`, a signal character).
    pub fn flush_input(&mut self) {
        self.len = 0;
        self.ready = 0;
        self.literal = false;
    }

    /// Bytes a reader can take now (`FIONREAD`; end-of-file marks not counted).
    pub fn available(&self) -> usize {
        self.queue[..self.ready]
            .iter()
            .filter(|&&c| c != EOF_MARK)
            .count()
    }

    /// Whether a `read` would return now (data or end of file): for `poll`.
    pub fn readable(&self) -> bool {
        if self.termios.local(ICANON) {
            return self.ready > 0;
        }
        let min = self.termios.cc[cc::VMIN] as usize;
        self.available() >= min.max(1)
    }

    /// Whether a `write` would return now: always (output never waits).
    pub fn writable(&self) -> bool {
        true
    }

    /// Takes readable input into `buf`: `Some(n)` (0 at end of file, or from a raw read
    /// with `VMIN = 0`), `None` when the reader has to wait.
    pub fn read(&mut self, buf: &mut [u8]) -> Option<usize> {
        if buf.is_empty() {
            return Some(0);
        }
        let canonical = self.termios.local(ICANON);
        if canonical {
            if self.ready == 0 {
                return None;
            }
        } else {
            let min = (self.termios.cc[cc::VMIN] as usize).min(buf.len());
            if self.available() < min {
                return None;
            }
        }
        let mut n = 0;
        let mut taken = 0;
        while taken < self.ready && n < buf.len() {
            let c = self.queue[taken];
            taken += 1;
            if c == EOF_MARK {
                if canonical {
                    break; // ends the line: what came before it, or end of file
                }
                continue;
            }
            buf[n] = c as u8;
            n += 1;
            if canonical && self.ends_line(c) {
                break;
            }
        }
        self.queue.copy_within(taken..self.len, 0);
        self.len -= taken;
        self.ready -= taken;
        Some(n)
    }

    /// Output of a process: processed by `c_oflag`, each byte to `out`.
    pub fn write(&mut self, bytes: &[u8], out: &mut impl FnMut(u8)) {
        for &b in bytes {
            self.put(b, out);
        }
    }

    fn put(&self, b: u8, out: &mut impl FnMut(u8)) {
        let o = self.termios.oflag;
        if o & OPOST == 0 {
            return out(b);
        }
        match b {
            b'\n' if o & ONLCR != 0 => {
                out(b'\r');
                out(b'\n');
            }
            b'\r' if o & OCRNL != 0 => out(b'\n'),
            _ => out(b),
        }
    }

    fn ends_line(&self, c: u16) -> bool {
        let t = &self.termios;
        c == u16::from(b'\n')
            || (c < 0x100 && (t.is(c as u8, cc::VEOL) || t.is(c as u8, cc::VEOL2)))
    }

    /// Echoes `b` (a control character as `^X` with `ECHOCTL`, but tab and newline as
    /// they are).
    fn echo(&self, b: u8, out: &mut impl FnMut(u8)) {
        if self.termios.local(ECHOCTL) && (b < 0x20 || b == 0x7f) && b != b'\t' && b != b'\n' {
            self.put(b'^', out);
            self.put(b ^ 0x40, out);
        } else {
            self.put(b, out);
        }
    }

    /// Columns `b` took when echoed.
    fn width(&self, b: u16) -> usize {
        let b = b as u8;
        if self.termios.local(ECHOCTL) && (b < 0x20 || b == 0x7f) && b != b'\t' {
            2
        } else if self.termios.iflag & IUTF8 != 0 && (0x80..0xc0).contains(&b) {
            0 // a UTF-8 continuation byte: its character's first byte took the column
        } else {
            1
        }
    }

    /// One received byte. Returns the signal to send when it is a signal character.
    pub fn input(&mut self, byte: u8, out: &mut impl FnMut(u8)) -> Option<Signal> {
        let t = self.termios;
        let mut b = byte;
        if t.iflag & ISTRIP != 0 {
            b &= 0x7f;
        }
        if self.literal {
            self.literal = false;
            self.push(b, out);
            return None;
        }
        if b == b'\r' {
            if t.iflag & IGNCR != 0 {
                return None;
            }
            if t.iflag & ICRNL != 0 {
                b = b'\n';
            }
        } else if b == b'\n' && t.iflag & INLCR != 0 {
            b = b'\r';
        }
        if t.local(ISIG) {
            let signal = [
                (cc::VINTR, SIGINT),
                (cc::VQUIT, SIGQUIT),
                (cc::VSUSP, SIGTSTP),
            ]
            .into_iter()
            .find(|&(i, _)| t.is(b, i))
            .map(|(_, s)| s);
            if let Some(signal) = signal {
                if !t.local(NOFLSH) {
                    self.flush_input();
                }
                if t.local(ECHO) {
                    self.echo(b, out);
                }
                return Some(Signal {
                    signal,
                    group: self.foreground,
                });
            }
        }
        if !t.local(ICANON) {
            self.push(b, out);
            self.ready = self.len;
            return None;
        }
        let extended = t.local(IEXTEN);
        if t.is(b, cc::VERASE) {
            self.erase(false, out);
        } else if extended && t.is(b, cc::VWERASE) {
            self.erase(true, out);
        } else if t.is(b, cc::VKILL) {
            self.kill(b, out);
        } else if extended && t.is(b, cc::VLNEXT) {
            self.literal = true;
            if t.local(ECHO) && t.local(ECHOCTL) {
                self.put(b'^', out);
                self.put(b'\x08', out);
            }
        } else if extended && t.is(b, cc::VREPRINT) {
            if t.local(ECHO) {
                self.echo(b, out);
                self.put(b'\n', out);
                for i in self.ready..self.len {
                    self.echo(self.queue[i] as u8, out);
                }
            }
        } else if t.is(b, cc::VEOF) {
            if self.len < INPUT_MAX {
                self.queue[self.len] = EOF_MARK;
                self.len += 1;
                self.ready = self.len;
            }
        } else if self.ends_line(u16::from(b)) {
            if self.len < INPUT_MAX {
                self.queue[self.len] = u16::from(b);
                self.len += 1;
                self.ready = self.len;
                if t.local(ECHO) || (b == b'\n' && t.local(ECHONL)) {
                    self.echo(b, out);
                }
            }
        } else if self.len < INPUT_MAX - 1 {
            self.push(b, out);
        }
        None
    }

    /// Queues `b` (when there is room) and echoes it.
    fn push(&mut self, b: u8, out: &mut impl FnMut(u8)) {
        if self.len == INPUT_MAX {
            return;
        }
        self.queue[self.len] = u16::from(b);
        self.len += 1;
        if self.termios.local(ECHO) {
            self.echo(b, out);
        } else if b == b'\n' && self.termios.local(ECHONL) {
            self.put(b, out);
        }
    }

    /// Removes the last character of the line being edited (a UTF-8 character whole with
    /// `IUTF8`), or with `word` the last word and the blanks after it.
    fn erase(&mut self, word: bool, out: &mut impl FnMut(u8)) {
        let mut in_word = false;
        while self.len > self.ready {
            let c = self.queue[self.len - 1];
            let blank = c == u16::from(b' ') || c == u16::from(b'\t');
            if word && blank && in_word {
                break;
            }
            in_word |= !blank;
            self.len -= 1;
            self.rub_out(c, out);
            let continuation = self.termios.iflag & IUTF8 != 0 && (0x80..0xc0).contains(&c);
            if !word && !continuation {
                break;
            }
        }
    }

    /// `VKILL`: the whole line being edited goes.
    fn kill(&mut self, b: u8, out: &mut impl FnMut(u8)) {
        let t = self.termios;
        if t.local(ECHO) && t.local(ECHOK) && !t.local(ECHOKE) {
            self.echo(b, out);
            self.put(b'\n', out);
            self.len = self.ready;
            return;
        }
        while self.len > self.ready {
            self.len -= 1;
            self.rub_out(self.queue[self.len], out);
        }
    }

    /// Takes an erased character off the screen (`ECHOE`): back, blank, back per column.
    fn rub_out(&self, c: u16, out: &mut impl FnMut(u8)) {
        let t = self.termios;
        if !t.local(ECHO) {
            return;
        }
        if !t.local(ECHOE) {
            return self.echo(t.cc[cc::VERASE], out);
        }
        for _ in 0..self.width(c) {
            for b in *b"\x08 \x08" {
                self.put(b, out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds `bytes`; returns the echo and the signals.
    fn feed(tty: &mut Tty, bytes: &[u8]) -> (Vec<u8>, Vec<Signal>) {
        let mut echo = Vec::new();
        let mut signals = Vec::new();
        for &b in bytes {
            if let Some(s) = tty.input(b, &mut |o| echo.push(o)) {
                signals.push(s);
            }
        }
        (echo, signals)
    }

    fn read(tty: &mut Tty, n: usize) -> Option<Vec<u8>> {
        let mut buf = vec![0; n];
        tty.read(&mut buf).map(|k| buf[..k].to_vec())
    }

    fn raw(tty: &mut Tty, vmin: u8) {
        let mut t = tty.termios();
        t.lflag &= !(ICANON | ECHO | ISIG);
        t.cc[cc::VMIN] = vmin;
        tty.set_termios(t, false);
    }

    #[test]
    fn termios_has_linux_layout_and_defaults() {
        let t = Termios::default();
        let b = t.to_bytes();
        // What `stty -g` shows on a fresh Linux console: 500:5:4bf:8a3b:3:1c:7f:15:4:0:1:0...
        assert_eq!(&b[..4], &0x500u32.to_le_bytes());
        assert_eq!(&b[4..8], &5u32.to_le_bytes());
        assert_eq!(&b[8..12], &0x4bfu32.to_le_bytes());
        assert_eq!(&b[12..16], &0x8a3bu32.to_le_bytes());
        assert_eq!(&b[17..24], &[3, 0x1c, 0x7f, 0x15, 4, 0, 1]);
        assert_eq!(Termios::from_bytes(&b), t);
        let w = Winsize {
            rows: 50,
            cols: 132,
            xpixel: 1,
            ypixel: 2,
        };
        assert_eq!(Winsize::from_bytes(&w.to_bytes()), w);
    }

    #[test]
    fn canonical_lines_with_echo_and_erase() {
        let mut tty = Tty::new(1);
        let (echo, _) = feed(&mut tty, b"ls -x\x7fl\r");
        assert_eq!(echo, b"ls -x\x08 \x08l\r\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"ls -l\n");
        assert_eq!(read(&mut tty, 100), None, "no line: the reader waits");
        // A partial line is not readable; a short read takes part of a line.
        feed(&mut tty, b"abc");
        assert!(!tty.readable());
        assert_eq!(read(&mut tty, 10), None);
        feed(&mut tty, b"def\n");
        assert!(tty.readable());
        assert_eq!(tty.available(), 7);
        assert_eq!(read(&mut tty, 4).unwrap(), b"abcd");
        assert_eq!(read(&mut tty, 100).unwrap(), b"ef\n");
        // One line per read.
        feed(&mut tty, b"one\ntwo\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"one\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"two\n");
        // Erase stops at the start of the line; control characters take two columns.
        let (echo, _) = feed(&mut tty, b"\x01\x7f\x7f");
        assert_eq!(echo, b"^A\x08 \x08\x08 \x08");
        assert_eq!(read(&mut tty, 100), None);
    }

    #[test]
    fn kill_word_erase_literal_and_reprint() {
        let mut tty = Tty::new(1);
        let (echo, _) = feed(&mut tty, b"ab\x15");
        assert_eq!(echo, b"ab\x08 \x08\x08 \x08");
        feed(&mut tty, b"echo  one two\x17\x17x\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"echo  x\n");
        feed(&mut tty, b"a\x16\x7fb\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"a\x7fb\n");
        let (echo, _) = feed(&mut tty, b"xy\x12");
        assert_eq!(echo, b"xy^R\r\nxy");
        // ECHOK without ECHOKE: the kill character, then a new line.
        let mut t = tty.termios();
        t.lflag &= !ECHOKE;
        tty.set_termios(t, true);
        let (echo, _) = feed(&mut tty, b"zz\x15w\n");
        assert_eq!(echo, b"zz^U\r\nw\r\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"w\n");
    }

    #[test]
    fn utf8_characters_are_erased_whole() {
        let mut tty = Tty::new(1);
        let mut t = tty.termios();
        t.iflag |= IUTF8;
        tty.set_termios(t, false);
        let (echo, _) = feed(&mut tty, "aé\x7f\n".as_bytes());
        assert_eq!(&echo[3..], b"\x08 \x08\r\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"a\n");
    }

    #[test]
    fn end_of_file() {
        let mut tty = Tty::new(1);
        feed(&mut tty, b"abc\x04");
        assert_eq!(read(&mut tty, 100).unwrap(), b"abc", "VEOF ends the line");
        assert_eq!(read(&mut tty, 100), None);
        let (echo, _) = feed(&mut tty, b"\x04");
        assert!(echo.is_empty());
        assert!(tty.readable());
        assert_eq!(read(&mut tty, 100).unwrap(), b"", "end of file");
        assert_eq!(read(&mut tty, 100), None, "once");
        assert_eq!(tty.available(), 0);
    }

    #[test]
    fn signal_characters() {
        let mut tty = Tty::new(1);
        tty.set_foreground(7).unwrap();
        let (echo, signals) = feed(&mut tty, b"sleep\x03");
        assert_eq!(echo, b"sleep^C");
        assert_eq!(
            signals,
            [Signal {
                signal: SIGINT,
                group: 7
            }]
        );
        assert_eq!(read(&mut tty, 100), None, "the line was flushed");
        let (_, signals) = feed(&mut tty, b"\x1c\x1a");
        let numbers: Vec<u32> = signals.iter().map(|s| s.signal).collect();
        assert_eq!(numbers, [SIGQUIT, SIGTSTP]);
        // Without ISIG they are data.
        raw(&mut tty, 1);
        let (echo, signals) = feed(&mut tty, b"\x03");
        assert!(echo.is_empty() && signals.is_empty());
        assert_eq!(read(&mut tty, 100).unwrap(), b"\x03");
        assert_eq!(tty.set_foreground(0), Err(Errno::EINVAL));
        assert_eq!(tty.set_foreground(-3), Err(Errno::EINVAL));
        assert_eq!(tty.foreground(), 7);
    }

    #[test]
    fn raw_mode_and_vmin() {
        let mut tty = Tty::new(1);
        feed(&mut tty, b"half");
        raw(&mut tty, 1);
        assert_eq!(
            read(&mut tty, 2).unwrap(),
            b"ha",
            "the line in progress is readable"
        );
        assert_eq!(read(&mut tty, 100).unwrap(), b"lf");
        assert_eq!(read(&mut tty, 100), None);
        let (echo, _) = feed(&mut tty, b"\r\x7f");
        assert!(echo.is_empty(), "no echo");
        assert_eq!(
            read(&mut tty, 100).unwrap(),
            b"\n\x7f",
            "ICRNL still applies"
        );
        raw(&mut tty, 3);
        feed(&mut tty, b"ab");
        assert!(!tty.readable());
        assert_eq!(read(&mut tty, 100), None);
        assert_eq!(
            read(&mut tty, 2).unwrap(),
            b"ab",
            "fewer asked for than VMIN"
        );
        raw(&mut tty, 0);
        assert_eq!(read(&mut tty, 100).unwrap(), b"", "VMIN 0 never waits");
        // Back to canonical: bytes after the last line end are a line being edited.
        feed(&mut tty, b"x\ny");
        let mut t = tty.termios();
        t.lflag |= ICANON;
        tty.set_termios(t, false);
        assert_eq!(read(&mut tty, 100).unwrap(), b"x\n");
        assert_eq!(read(&mut tty, 100), None);
        // TCSETSF discards.
        tty.set_termios(t, true);
        feed(&mut tty, b"\n");
        assert_eq!(read(&mut tty, 100).unwrap(), b"\n");
    }

    #[test]
    fn output_processing() {
        let mut tty = Tty::new(1);
        let mut out = Vec::new();
        tty.write(b"a\nb\r", &mut |b| out.push(b));
        assert_eq!(out, b"a\r\nb\r");
        let mut t = tty.termios();
        t.oflag |= OCRNL;
        tty.set_termios(t, false);
        out.clear();
        tty.write(b"\r", &mut |b| out.push(b));
        assert_eq!(out, b"\n");
        t.oflag &= !OPOST;
        tty.set_termios(t, false);
        out.clear();
        tty.write(b"a\n", &mut |b| out.push(b));
        assert_eq!(out, b"a\n");
        assert!(tty.writable());
    }

    #[test]
    fn a_full_queue_keeps_room_for_the_line_end() {
        let mut tty = Tty::new(1);
        let (echo, _) = feed(&mut tty, &[b'x'; INPUT_MAX + 10]);
        assert_eq!(echo.len(), INPUT_MAX - 1);
        feed(&mut tty, b"\n");
        let line = read(&mut tty, INPUT_MAX * 2).unwrap();
        assert_eq!(line.len(), INPUT_MAX);
        assert_eq!(line.last(), Some(&b'\n'));
        // Raw mode: the queue fills up and drops the rest.
        raw(&mut tty, 1);
        feed(&mut tty, &[b'y'; INPUT_MAX + 10]);
        assert_eq!(tty.available(), INPUT_MAX);
    }
}
