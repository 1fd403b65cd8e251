//! The guest's event descriptors: `eventfd` counters, `timerfd` timers and `epoll`
//! instances, each a table of objects shared by the descriptors `dup` and `fork` made of
//! them (a reference count per object, as [`crate::pipe::Pipes`] counts pipe ends). This
//! module is the pure state: the system calls ([`crate::syscall::events`]) copy arguments
//! and results between it and the process, and say what a descriptor's readiness is
//! ([`crate::poll::file_events`]).
//!
//! Timers are kept on the guest's clock (ns since it started): an expiry is counted when
//! it is looked at ([`Timer::advance`]), and [`Events::next_expiry`] tells the guest when
//! to serve its waiting calls again so that a blocked `read`, `poll` or `epoll_wait`
//! wakes up when a timer expires.
//!
//! Epoll readiness is level-triggered by default; `EPOLLET` reports a readiness bit when
//! it appears (it was not ready, or it was consumed, when last looked at) and
//! `EPOLLONESHOT` disables an item after one report until `EPOLL_CTL_MOD` re-arms it.

use crate::linux::Errno;
use crate::poll::{POLLERR, POLLHUP, POLLIN, POLLOUT};
use crate::process::File;
use alloc::vec::Vec;

/// Most `eventfd` counters open at once in a guest (beyond: `ENFILE`).
pub const MAX_COUNTERS: usize = 64;
/// Most `timerfd` timers open at once in a guest (beyond: `ENFILE`).
pub const MAX_TIMERS: usize = 64;
/// Most epoll instances open at once in a guest (beyond: `ENFILE`).
pub const MAX_EPOLLS: usize = 32;
/// Most descriptors one epoll instance watches (Linux's `max_user_watches`: `ENOSPC`).
pub const MAX_WATCHED: usize = 1024;

/// The largest value an `eventfd` counter holds (a write that would pass it waits).
pub const COUNTER_MAX: u64 = u64::MAX - 1;

/// `epoll_event.events` bits the guest understands (the readiness ones are `poll`'s).
pub const EPOLLIN: u32 = POLLIN as u32;
pub const EPOLLOUT: u32 = POLLOUT as u32;
pub const EPOLLERR: u32 = POLLERR as u32;
pub const EPOLLHUP: u32 = POLLHUP as u32;
pub const EPOLLRDHUP: u32 = 0x2000;
pub const EPOLLEXCLUSIVE: u32 = 1 << 28;
pub const EPOLLWAKEUP: u32 = 1 << 29;
pub const EPOLLONESHOT: u32 = 1 << 30;
pub const EPOLLET: u32 = 1 << 31;

/// A call on the object has to wait (or fail with `EAGAIN` when non-blocking).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WouldBlock;

/// An `eventfd` counter.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Counter {
    value: u64,
    /// `EFD_SEMAPHORE`: a read takes 1 instead of everything.
    semaphore: bool,
    /// `EFD_NONBLOCK` / `O_NONBLOCK`: shared by every descriptor of it, as Linux's open file
    /// description.
    pub nonblock: bool,
    refs: u32,
}

impl Counter {
    /// A read: the value (or 1 in semaphore mode), taken off the counter; waits at 0.
    pub fn read(&mut self) -> Result<u64, WouldBlock> {
        if self.value == 0 {
            return Err(WouldBlock);
        }
        let taken = if self.semaphore { 1 } else { self.value };
        self.value -= taken;
        Ok(taken)
    }

    /// A write of `add`: `EINVAL` for `u64::MAX`; waits while the sum would pass
    /// [`COUNTER_MAX`].
    pub fn write(&mut self, add: u64) -> Result<Result<(), WouldBlock>, Errno> {
        if add == u64::MAX {
            return Err(Errno::EINVAL);
        }
        if COUNTER_MAX - self.value < add {
            return Ok(Err(WouldBlock));
        }
        self.value += add;
        Ok(Ok(()))
    }

    /// `POLLIN` while it is above 0, `POLLOUT` while a write of 1 would not wait.
    pub fn poll(&self) -> u16 {
        (if self.value > 0 { POLLIN } else { 0 })
            | if self.value < COUNTER_MAX { POLLOUT } else { 0 }
    }

    pub fn value(&self) -> u64 {
        self.value
    }
}

/// A `timerfd` timer on the guest's clock.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Timer {
    /// It counts `CLOCK_REALTIME` (an absolute time it is set to is wall-clock time).
    pub realtime: bool,
    /// When it expires next (guest's clock); `None`: disarmed.
    next_at: Option<u64>,
    /// Its period (0: one-shot).
    interval: u64,
    /// Expirations since the last read.
    expirations: u64,
    pub nonblock: bool,
    refs: u32,
}

impl Timer {
    /// Counts the expirations up to `now`; an interval timer moves on to its next one.
    pub fn advance(&mut self, now: u64) {
        let Some(at) = self.next_at else {
            return;
        };
        if now < at {
            return;
        }
        // One-shot (no interval): it expired once and is disarmed.
        let Some(periods) = (now - at).checked_div(self.interval) else {
            self.expirations = self.expirations.saturating_add(1);
            self.next_at = None;
            return;
        };
        let passed = periods.saturating_add(1);
        self.expirations = self.expirations.saturating_add(passed);
        // Past the end of the clock it never expires again.
        self.next_at = at.checked_add(passed.saturating_mul(self.interval));
    }

    /// Arms it to expire at `at` (guest's clock; `None` disarms), then every `interval` ns
    /// (0: once). The expirations not read yet are dropped, as on Linux.
    pub fn set(&mut self, at: Option<u64>, interval: u64) {
        self.next_at = at;
        self.interval = if at.is_some() { interval } else { 0 };
        self.expirations = 0;
    }

    /// What `timerfd_gettime` shows at `now`: the time to the next expiry (0: disarmed) and
    /// the interval.
    pub fn remaining(&mut self, now: u64) -> (u64, u64) {
        self.advance(now);
        let left = self.next_at.map_or(0, |at| at.saturating_sub(now).max(1));
        (left, self.interval)
    }

    /// A read at `now`: the expirations since the last read, then none; waits at none.
    pub fn read(&mut self, now: u64) -> Result<u64, WouldBlock> {
        self.advance(now);
        match core::mem::take(&mut self.expirations) {
            0 => Err(WouldBlock),
            n => Ok(n),
        }
    }

    /// `POLLIN` once it expired (at `now`).
    pub fn poll(&mut self, now: u64) -> u16 {
        self.advance(now);
        if self.expirations > 0 { POLLIN } else { 0 }
    }
}

/// One descriptor an epoll instance watches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Item {
    /// The descriptor it was added as (the key of `epoll_ctl`, with the file).
    pub fd: i32,
    /// What the descriptor referred to then (its readiness is this file's).
    pub file: File,
    /// The events asked for and the `EPOLLET`/`EPOLLONESHOT` flags.
    pub events: u32,
    /// The user's data word, given back with each report.
    pub data: u64,
    /// `EPOLLET`: the bits reported that have not gone since.
    reported: u32,
    /// `EPOLLONESHOT`: it reported once and waits for `EPOLL_CTL_MOD`.
    disabled: bool,
}

impl Item {
    /// A watched descriptor as `EPOLL_CTL_ADD` or `EPOLL_CTL_MOD` leaves it: nothing
    /// reported yet, enabled.
    fn armed(fd: i32, file: File, events: u32, data: u64) -> Self {
        Item {
            fd,
            file: identity(file),
            events,
            data,
            reported: 0,
            disabled: false,
        }
    }
}

/// An epoll instance: its interest list, and where the next scan starts (reports go round
/// the list so that a small `maxevents` starves no descriptor).
#[derive(Clone, Debug, Default)]
pub struct Epoll {
    items: Vec<Item>,
    cursor: usize,
    refs: u32,
}

/// One reported event: the ready bits and the item's data word.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ready {
    pub events: u32,
    pub data: u64,
}

impl Epoll {
    /// The files it watches, in list order (what [`Epoll::collect`] wants readiness of).
    pub fn files(&self) -> impl Iterator<Item = File> + '_ {
        self.items.iter().map(|i| i.file)
    }

    pub fn len(&self) -> usize {
        self.items.len()
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    fn find(&self, fd: i32, file: File) -> Option<usize> {
        let file = identity(file);
        self.items.iter().position(|i| i.fd == fd && i.file == file)
    }

    /// `EPOLL_CTL_ADD`: `EEXIST` when it watches the descriptor already, `ENOSPC` beyond
    /// [`MAX_WATCHED`].
    pub fn add(&mut self, fd: i32, file: File, events: u32, data: u64) -> Result<(), Errno> {
        if self.find(fd, file).is_some() {
            return Err(Errno::EEXIST);
        }
        if self.items.len() >= MAX_WATCHED {
            return Err(Errno::ENOSPC);
        }
        self.items.try_reserve(1).map_err(|_| Errno::ENOMEM)?;
        self.items.push(Item::armed(fd, file, events, data));
        Ok(())
    }

    /// `EPOLL_CTL_MOD`: new events and data, re-armed (`ENOENT` when not watched).
    pub fn modify(&mut self, fd: i32, file: File, events: u32, data: u64) -> Result<(), Errno> {
        let i = self.find(fd, file).ok_or(Errno::ENOENT)?;
        self.items[i] = Item::armed(fd, file, events, data);
        Ok(())
    }

    /// `EPOLL_CTL_DEL` (`ENOENT` when not watched).
    pub fn remove(&mut self, fd: i32, file: File) -> Result<(), Errno> {
        let i = self.find(fd, file).ok_or(Errno::ENOENT)?;
        self.items.remove(i);
        Ok(())
    }

    /// Drops every item of `file` (its last descriptor closed).
    pub fn forget(&mut self, file: File) {
        let file = identity(file);
        self.items.retain(|i| i.file != file);
    }

    /// Whether an item is ready at level (for `poll` on the epoll descriptor itself), its
    /// files' readiness being `ready` (in [`Epoll::files`] order).
    pub fn any_ready(&self, ready: &[u16]) -> bool {
        self.items
            .iter()
            .zip(ready)
            .any(|(i, &r)| !i.disabled && reportable(i.events, r) != 0)
    }

    /// The reports of an `epoll_wait` (at most `max`), its files' readiness being `ready`
    /// (in [`Epoll::files`] order): level-triggered items report while ready,
    /// edge-triggered ones when a bit appears, one-shot ones once.
    pub fn collect(&mut self, ready: &[u16], max: usize, out: &mut Vec<Ready>) {
        let len = self.items.len().min(ready.len());
        if len == 0 {
            return;
        }
        let start = self.cursor % len;
        for step in 0..len {
            if out.len() >= max {
                break;
            }
            let index = (start + step) % len;
            let item = &mut self.items[index];
            if item.disabled {
                continue;
            }
            let got = reportable(item.events, ready[index]);
            if item.events & EPOLLET != 0 {
                let appeared = got & !item.reported;
                // Bits that went are reported again when they come back.
                item.reported = got;
                if appeared == 0 {
                    continue;
                }
            } else if got == 0 {
                continue;
            }
            if item.events & EPOLLONESHOT != 0 {
                item.disabled = true;
            }
            out.push(Ready {
                events: got,
                data: item.data,
            });
            self.cursor = index + 1;
        }
    }

    /// `EPOLLET`: the readiness bits `bits` of `file` were used up (a read or write of it
    /// had to wait), so their next appearance is reported even if no scan saw them go.
    pub fn consumed(&mut self, file: File, bits: u32) {
        let file = identity(file);
        for i in self.items.iter_mut().filter(|i| i.file == file) {
            i.reported &= !bits;
        }
    }
}

/// What an interest list keys `file` by: the open file behind it, without the
/// descriptor's own flags (a pipe end's or socket pair end's `O_NONBLOCK` is the
/// descriptor's, and `F_SETFL` or a `dup` must not make it another file).
pub fn identity(file: File) -> File {
    file.with_nonblock(false)
}

/// The bits of readiness `ready` an item asking for `events` reports (`EPOLLERR` and
/// `EPOLLHUP` always).
fn reportable(events: u32, ready: u16) -> u32 {
    u32::from(ready) & (events | EPOLLERR | EPOLLHUP)
}

/// The guest's counters, timers and epoll instances, by index.
#[derive(Clone, Debug)]
pub struct Events {
    counters: [Option<Counter>; MAX_COUNTERS],
    timers: [Option<Timer>; MAX_TIMERS],
    epolls: [Option<Epoll>; MAX_EPOLLS],
}

impl Default for Events {
    fn default() -> Self {
        Self::new()
    }
}

/// Puts `value` in the first free slot of `table` (`ENFILE`: all in use).
fn open_in<T>(table: &mut [Option<T>], value: T) -> Result<usize, Errno> {
    let index = table
        .iter()
        .position(Option::is_none)
        .ok_or(Errno::ENFILE)?;
    table[index] = Some(value);
    Ok(index)
}

impl Events {
    pub const fn new() -> Self {
        Self {
            counters: [const { None }; MAX_COUNTERS],
            timers: [const { None }; MAX_TIMERS],
            epolls: [const { None }; MAX_EPOLLS],
        }
    }

    /// A new counter at `value` with one descriptor.
    pub fn open_counter(
        &mut self,
        value: u64,
        semaphore: bool,
        nonblock: bool,
    ) -> Result<usize, Errno> {
        open_in(
            &mut self.counters,
            Counter {
                value,
                semaphore,
                nonblock,
                refs: 1,
            },
        )
    }

    /// A new disarmed timer with one descriptor.
    pub fn open_timer(&mut self, realtime: bool, nonblock: bool) -> Result<usize, Errno> {
        open_in(
            &mut self.timers,
            Timer {
                realtime,
                next_at: None,
                interval: 0,
                expirations: 0,
                nonblock,
                refs: 1,
            },
        )
    }

    /// A new empty epoll instance with one descriptor.
    pub fn open_epoll(&mut self) -> Result<usize, Errno> {
        open_in(
            &mut self.epolls,
            Epoll {
                refs: 1,
                ..Epoll::default()
            },
        )
    }

    pub fn counter(&mut self, index: usize) -> Option<&mut Counter> {
        self.counters.get_mut(index)?.as_mut()
    }

    pub fn timer(&mut self, index: usize) -> Option<&mut Timer> {
        self.timers.get_mut(index)?.as_mut()
    }

    pub fn epoll(&mut self, index: usize) -> Option<&mut Epoll> {
        self.epolls.get_mut(index)?.as_mut()
    }

    /// The reference count of what `file` refers to, if it is one of these objects.
    fn refs(&mut self, file: File) -> Option<&mut u32> {
        match file {
            File::Event(i) => self.counter(i).map(|c| &mut c.refs),
            File::Timer(i) => self.timer(i).map(|t| &mut t.refs),
            File::Epoll(i) => self.epoll(i).map(|e| &mut e.refs),
            _ => None,
        }
    }

    /// One more descriptor of `file` (`dup`, `fork`); other kinds are not these tables'.
    pub fn share(&mut self, file: File) {
        if let Some(r) = self.refs(file) {
            *r += 1;
        }
    }

    /// A descriptor of `file` closed: the object goes with its last, and leaves every
    /// interest list then (returns whether it went).
    pub fn release(&mut self, file: File) -> bool {
        let Some(r) = self.refs(file) else {
            return false;
        };
        *r = r.saturating_sub(1);
        if *r > 0 {
            return false;
        }
        match file {
            File::Event(i) => self.counters[i] = None,
            File::Timer(i) => self.timers[i] = None,
            File::Epoll(i) => self.epolls[i] = None,
            _ => {}
        }
        self.forget(file);
        true
    }

    /// `file`'s last descriptor closed: it leaves every interest list (Linux drops an item
    /// when its open file description goes).
    pub fn forget(&mut self, file: File) {
        for e in self.epolls.iter_mut().flatten() {
            e.forget(file);
        }
    }

    /// Whether an epoll instance watches `file`.
    pub fn watched_by_epoll(&self, file: File) -> bool {
        let file = identity(file);
        self.epolls
            .iter()
            .flatten()
            .any(|e| e.items.iter().any(|i| i.file == file))
    }

    /// `EPOLLET`: see [`Epoll::consumed`], for every instance.
    pub fn consumed(&mut self, file: File, bits: u32) {
        for e in self.epolls.iter_mut().flatten() {
            e.consumed(file, bits);
        }
    }

    /// When the next armed timer expires (guest's clock): the time the guest serves its
    /// waiting calls again (after [`Events::advance_timers`], a future time).
    pub fn next_expiry(&self) -> Option<u64> {
        self.timers.iter().flatten().filter_map(|t| t.next_at).min()
    }

    /// Counts every timer's expirations up to `now` (the time [`Events::next_expiry`]
    /// named came), so that none is due any more.
    pub fn advance_timers(&mut self, now: u64) {
        for t in self.timers.iter_mut().flatten() {
            t.advance(now);
        }
    }

    /// Counters, timers and epoll instances open (for tests and accounting).
    pub fn open_count(&self) -> usize {
        self.counters.iter().flatten().count()
            + self.timers.iter().flatten().count()
            + self.epolls.iter().flatten().count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_add_take_and_wait() {
        let mut e = Events::new();
        let i = e.open_counter(3, false, false).unwrap();
        let c = e.counter(i).unwrap();
        assert_eq!(c.poll(), POLLIN | POLLOUT);
        assert_eq!(c.read(), Ok(3));
        assert_eq!(c.read(), Err(WouldBlock), "empty: waits");
        assert_eq!(c.poll(), POLLOUT);
        assert_eq!(c.write(u64::MAX), Err(Errno::EINVAL));
        assert_eq!(c.write(COUNTER_MAX), Ok(Ok(())));
        assert_eq!(c.poll(), POLLIN, "full: a write of 1 would wait");
        assert_eq!(c.write(1), Ok(Err(WouldBlock)));
        assert_eq!(c.read(), Ok(COUNTER_MAX));
        let s = e.open_counter(2, true, true).unwrap();
        let c = e.counter(s).unwrap();
        assert_eq!(
            (c.read(), c.read(), c.read()),
            (Ok(1), Ok(1), Err(WouldBlock))
        );
    }

    #[test]
    fn counters_are_shared_and_freed_with_their_last_descriptor() {
        let mut e = Events::new();
        let i = e.open_counter(0, false, false).unwrap();
        e.share(File::Event(i));
        assert!(!e.release(File::Event(i)));
        assert!(e.counter(i).is_some());
        assert!(e.release(File::Event(i)));
        assert!(e.counter(i).is_none());
        assert!(
            !e.release(File::Event(i)),
            "a stale release changes nothing"
        );
        for _ in 0..MAX_COUNTERS {
            e.open_counter(0, false, false).unwrap();
        }
        assert_eq!(e.open_counter(0, false, false), Err(Errno::ENFILE));
    }

    #[test]
    fn timers_count_expirations_and_rearm() {
        let mut e = Events::new();
        let i = e.open_timer(false, false).unwrap();
        let t = e.timer(i).unwrap();
        assert_eq!(t.read(100), Err(WouldBlock), "disarmed");
        t.set(Some(1_000), 0);
        assert_eq!(t.remaining(400), (600, 0));
        assert_eq!(t.poll(999), 0);
        assert_eq!(t.poll(1_000), POLLIN);
        assert_eq!(t.read(5_000), Ok(1), "one-shot: once");
        assert_eq!(t.read(9_000), Err(WouldBlock));
        assert_eq!(t.remaining(9_000), (0, 0));
        t.set(Some(10_000), 100);
        assert_eq!(t.read(10_250), Ok(3), "at 10000, 10100, 10200");
        assert_eq!(t.remaining(10_250), (50, 100));
        e.advance_timers(10_250);
        assert_eq!(e.next_expiry(), Some(10_300));
        let t = e.timer(i).unwrap();
        t.set(Some(20_000), 100);
        t.set(None, 100);
        assert_eq!(t.remaining(30_000), (0, 0), "disarmed: no interval either");
        e.advance_timers(30_000);
        assert_eq!(e.next_expiry(), None);
    }

    #[test]
    fn huge_intervals_and_times_do_not_overflow() {
        let mut e = Events::new();
        let i = e.open_timer(true, false).unwrap();
        let t = e.timer(i).unwrap();
        t.set(Some(u64::MAX - 1), u64::MAX);
        assert_eq!(t.read(u64::MAX), Ok(1));
        t.set(Some(0), 1);
        assert_eq!(t.read(u64::MAX), Ok(u64::MAX));
    }

    fn pipe(n: usize) -> File {
        File::Pipe {
            pipe: n,
            write: false,
            nonblock: false,
        }
    }

    #[test]
    fn epoll_interest_list_errors() {
        let mut e = Events::new();
        let i = e.open_epoll().unwrap();
        let ep = e.epoll(i).unwrap();
        assert_eq!(ep.add(3, pipe(0), EPOLLIN, 7), Ok(()));
        assert_eq!(ep.add(3, pipe(0), EPOLLIN, 7), Err(Errno::EEXIST));
        assert_eq!(ep.modify(4, pipe(1), EPOLLIN, 7), Err(Errno::ENOENT));
        assert_eq!(ep.remove(4, pipe(1)), Err(Errno::ENOENT));
        assert_eq!(ep.remove(3, pipe(0)), Ok(()));
        for fd in 0..MAX_WATCHED as i32 {
            ep.add(fd, pipe(fd as usize), EPOLLIN, 0).unwrap();
        }
        assert_eq!(ep.add(-5, pipe(9999), EPOLLIN, 0), Err(Errno::ENOSPC));
        e.forget(pipe(5));
        assert_eq!(e.epoll(i).unwrap().len(), MAX_WATCHED - 1);
        // A descriptor's O_NONBLOCK does not make its pipe end another file.
        let nonblocking = File::Pipe {
            pipe: 6,
            write: false,
            nonblock: true,
        };
        let ep = e.epoll(i).unwrap();
        assert_eq!(ep.modify(6, nonblocking, EPOLLOUT, 1), Ok(()));
        assert_eq!(ep.remove(6, nonblocking), Ok(()));
        e.forget(nonblocking);
        e.forget(File::Pipe {
            pipe: 7,
            write: false,
            nonblock: true,
        });
        assert_eq!(e.epoll(i).unwrap().len(), MAX_WATCHED - 3);
    }

    #[test]
    fn level_edge_and_oneshot_reports() {
        let mut e = Events::new();
        let i = e.open_epoll().unwrap();
        let ep = e.epoll(i).unwrap();
        ep.add(3, pipe(0), EPOLLIN, 30).unwrap();
        ep.add(4, pipe(1), EPOLLIN | EPOLLET, 40).unwrap();
        ep.add(5, pipe(2), EPOLLIN | EPOLLONESHOT, 50).unwrap();
        let mut out = Vec::new();
        let all = [POLLIN; 3];
        ep.collect(&all, 10, &mut out);
        let data: Vec<u64> = out.iter().map(|r| r.data).collect();
        assert_eq!(data, [30, 40, 50]);
        assert!(out.iter().all(|r| r.events == EPOLLIN));
        out.clear();
        ep.collect(&all, 10, &mut out);
        assert_eq!(
            out,
            [Ready {
                events: EPOLLIN,
                data: 30
            }],
            "level only"
        );
        // The edge item's data went and came back; then it was consumed without a scan.
        out.clear();
        ep.collect(&[0, 0, 0], 10, &mut out);
        ep.collect(&all, 10, &mut out);
        assert_eq!(out.len(), 2);
        out.clear();
        ep.consumed(pipe(1), EPOLLIN);
        ep.collect(&all, 10, &mut out);
        assert_eq!(out.len(), 2);
        // MOD re-arms the one-shot item; hang-ups are reported unasked.
        ep.modify(5, pipe(2), EPOLLOUT | EPOLLONESHOT, 51).unwrap();
        out.clear();
        ep.collect(&[0, 0, POLLHUP], 10, &mut out);
        assert_eq!(
            out,
            [Ready {
                events: EPOLLHUP,
                data: 51
            }]
        );
        assert!(!ep.any_ready(&[0, 0, POLLHUP]), "disabled");
        assert!(ep.any_ready(&[POLLIN, 0, 0]));
    }

    #[test]
    fn small_maxevents_goes_round_the_list() {
        let mut e = Events::new();
        let i = e.open_epoll().unwrap();
        let ep = e.epoll(i).unwrap();
        for fd in 0..3 {
            ep.add(fd, pipe(fd as usize), EPOLLIN, fd as u64).unwrap();
        }
        let mut seen = Vec::new();
        for _ in 0..3 {
            let mut out = Vec::new();
            ep.collect(&[POLLIN; 3], 1, &mut out);
            seen.push(out[0].data);
        }
        assert_eq!(seen, [0, 1, 2]);
        // Readiness shorter than the list (a hostile race cannot happen, but no panic).
        let mut out = Vec::new();
        ep.collect(&[POLLIN], 5, &mut out);
        assert!(out.len() <= 1);
    }

    #[test]
    fn closing_the_last_descriptor_leaves_interest_lists() {
        let mut e = Events::new();
        let ep = e.open_epoll().unwrap();
        let c = e.open_counter(1, false, false).unwrap();
        e.epoll(ep)
            .unwrap()
            .add(4, File::Event(c), EPOLLIN, 0)
            .unwrap();
        e.share(File::Event(c));
        e.release(File::Event(c));
        assert_eq!(e.epoll(ep).unwrap().len(), 1, "a descriptor is left");
        e.release(File::Event(c));
        assert!(e.epoll(ep).unwrap().is_empty());
        assert!(e.release(File::Epoll(ep)));
        assert_eq!(e.open_count(), 0);
    }
}
