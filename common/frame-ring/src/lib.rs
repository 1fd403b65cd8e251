//! A frame link through shared memory: Ethernet frames between a NIC partition and one
//! of its tenants in a shared-memory segment the two map read-write (and nobody else:
//! the configuration tools check it). An interface (the segment's format); no_std, no
//! allocation. Each side trusts nothing the other writes: a bogus index or length costs
//! the side that wrote it its own frames, never the reader's memory or a panic.
//!
//! # Format
//!
//! The segment (a whole number of pages, at least [`MIN_SEGMENT`] bytes) is cut into two
//! rings of half its size each: the first carries the tenant's frames to the NIC
//! partition ("up"), the second the NIC partition's frames to the tenant ("down"). A ring
//! (offsets from its start, little-endian):
//!
//! | offset | field | written by |
//! |---|---|---|
//! | 0 | `produced` `u32`: frames published since the segment was zeroed (wrapping) | the producer |
//! | 64 | `consumed` `u32`: frames taken (wrapping) | the consumer |
//! | 72 | `waiter` `u64`: the kernel thread id the producer notifies (0: none, kick instead) | the consumer |
//! | 80 | `wake_bits` `u64`: the notification bits it sends that thread | the consumer |
//! | 128 | slot `i` at `128 + i * SLOT`: a length `u16` (1..=[`MTU`]), 2 bytes unused, the frame | the producer |
//!
//! There are as many slots as fit, rounded down to a power of two (at most
//! [`MAX_SLOTS`]); frame `n` is in slot `n % slots`. The producer owns a slot from the
//! moment the consumer has taken its last frame (`consumed` passed it) until it publishes
//! the next (`produced` passes it); the consumer owns it in between. The producer writes
//! the slot, then `produced`; the consumer reads `produced`, then the slot, then writes
//! `consumed`. Each side writes its index again whenever it looks at the ring (the
//! producer on every push, the consumer whenever it finds the ring empty), so an index the
//! other side overwrote costs that side its frames only until then.
//!
//! # Waking the consumer
//!
//! A side that waits needs a word from the other. The producer gives one when
//! [`Pushed::first`] says the consumer had taken every earlier frame, so it may be waiting:
//! a notification of the thread the consumer named in `waiter` with its `wake_bits`
//! ([`Consumer::wake_me`], [`Producer::waiter`]; syssw lets partitions that share a
//! segment notify each other), or, when it named none or the kernel refuses the
//! notification, a "kick", a message on the queuing port beside the ring, which rings the
//! waiting side's doorbell. The consumer, once woken, first drains its kicks (after a
//! notification there are none), then takes frames until the ring is empty: a frame
//! published after that was pushed into an empty ring and wakes it again. Both sides order
//! their index write before their read of the other's index ([`fence`]), so a frame is
//! never left in a ring whose consumer waits without a wake-up.
#![no_std]

use core::sync::atomic::{AtomicU32, AtomicU64, Ordering, fence};

/// The longest frame: an Ethernet frame without its FCS.
pub const MTU: usize = 1514;
/// Bytes a slot takes: the length, 2 bytes unused, the frame, rounded up.
pub const SLOT: usize = 1536;
/// Bytes before the first slot: the two indices, each on its own 64-byte line.
pub const HEADER: usize = 128;
/// The fewest slots a ring has.
pub const MIN_SLOTS: u32 = 4;
/// The most slots a ring uses (a larger segment's rest is unused).
pub const MAX_SLOTS: u32 = 1024;
/// The smallest segment: two rings of [`MIN_SLOTS`] slots, in whole 4 KiB pages.
pub const MIN_SEGMENT: usize = (2 * (HEADER + MIN_SLOTS as usize * SLOT)).div_ceil(4096) * 4096;

const PRODUCED: usize = 0;
const CONSUMED: usize = 64;
const WAITER: usize = 72;
const WAKE_BITS: usize = 80;

/// Which end of the link a side is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The tenant: produces on "up", consumes "down".
    Tenant,
    /// The NIC partition: produces on "down", consumes "up".
    Driver,
}

/// Why a segment cannot hold a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentError {
    /// Smaller than [`MIN_SEGMENT`] (its size).
    TooSmall(usize),
    /// Not 64-byte aligned (its address).
    Misaligned(usize),
}

impl core::fmt::Display for SegmentError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooSmall(size) => write!(
                f,
                "a frame ring's segment of {size} bytes is smaller than {MIN_SEGMENT}"
            ),
            Self::Misaligned(at) => write!(
                f,
                "a frame ring's segment at {at:#x} is not 64-byte aligned"
            ),
        }
    }
}

/// How many slots a ring of `len` bytes has.
pub const fn slots_in(len: usize) -> u32 {
    let fit = len.saturating_sub(HEADER) / SLOT;
    if fit < MIN_SLOTS as usize {
        return 0;
    }
    let fit = if fit > MAX_SLOTS as usize {
        MAX_SLOTS
    } else {
        fit as u32
    };
    1 << (31 - fit.leading_zeros())
}

/// One ring of a segment, as one side sees it.
#[derive(Debug)]
struct Ring {
    base: *mut u8,
    slots: u32,
}

// Every access goes through atomics or copies that tolerate a concurrent writer.
#[allow(unsafe_code)]
// SAFETY: a view of shared memory mapped for the partition's life (`attach`'s contract):
// moving it to another thread is sound.
unsafe impl Send for Ring {}

#[allow(unsafe_code)]
impl Ring {
    fn index(&self, offset: usize) -> &AtomicU32 {
        // SAFETY: `offset` is PRODUCED or CONSUMED, inside the ring's header, 4-byte
        // aligned (the ring is 64-byte aligned); `attach`'s contract keeps the memory valid
        // while `self` lives, and another side writing it is what an atomic is for.
        unsafe { &*(self.base.wrapping_add(offset) as *const AtomicU32) }
    }

    fn word(&self, offset: usize) -> &AtomicU64 {
        // SAFETY: `offset` is WAITER or WAKE_BITS, inside the ring's header, 8-byte aligned
        // (the ring is 64-byte aligned); as `index`.
        unsafe { &*(self.base.wrapping_add(offset) as *const AtomicU64) }
    }

    fn slot(&self, n: u32) -> *mut u8 {
        // `n % slots < slots`, and `slots` slots fit in the ring (`slots_in`).
        self.base
            .wrapping_add(HEADER + (n % self.slots) as usize * SLOT)
    }
}

/// The side's ring it writes frames into.
#[derive(Debug)]
pub struct Producer {
    ring: Ring,
    /// What this side published: the truth, whatever the shared word says now.
    produced: u32,
}

/// The side's ring it reads frames from.
#[derive(Debug)]
pub struct Consumer {
    ring: Ring,
    /// What this side took: the truth, whatever the shared word says now.
    consumed: u32,
    /// The thread and bits the producer is to notify ([`Consumer::wake_me`]): the truth,
    /// whatever the shared words say now.
    waiter: (u64, u64),
}

/// Views `segment` (`size` bytes) as `side`'s end of a link: its producer and its
/// consumer. Each takes its own index from the segment as it finds it (so a side that
/// restarts goes on where it stopped; a zeroed segment starts both rings empty).
///
/// # Safety
/// `segment..segment + size` must stay mapped readable and writable for as long as the
/// returned values live, and no one but this side and the one other side may write it
/// (another party writing it only corrupts the frames, not memory safety); at most one
/// `attach` per side.
#[allow(unsafe_code)]
pub unsafe fn attach(
    segment: *mut u8,
    size: usize,
    side: Side,
) -> Result<(Producer, Consumer), SegmentError> {
    if size < MIN_SEGMENT {
        return Err(SegmentError::TooSmall(size));
    }
    if !(segment as usize).is_multiple_of(64) {
        return Err(SegmentError::Misaligned(segment as usize));
    }
    let half = size / 2 / 64 * 64;
    let slots = slots_in(half);
    let up = Ring {
        base: segment,
        slots,
    };
    let down = Ring {
        // `half < size`: the second ring starts inside the segment.
        base: segment.wrapping_add(half),
        slots,
    };
    let (mine, theirs) = match side {
        Side::Tenant => (up, down),
        Side::Driver => (down, up),
    };
    let produced = mine.index(PRODUCED).load(Ordering::Acquire);
    let consumed = theirs.index(CONSUMED).load(Ordering::Acquire);
    Ok((
        Producer {
            ring: mine,
            produced,
        },
        Consumer {
            ring: theirs,
            consumed,
            waiter: (0, 0),
        },
    ))
}

/// A frame published.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pushed {
    /// The consumer had taken every earlier frame: it may be waiting, kick it.
    pub first: bool,
}

/// Why a frame was not published.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PushError {
    /// Every slot holds a frame the consumer has not taken (or its index is bogus).
    Full,
    /// Empty or longer than [`MTU`] (its length).
    Length(usize),
}

#[allow(unsafe_code)]
impl Producer {
    /// Slots of the ring.
    pub fn slots(&self) -> u32 {
        self.ring.slots
    }

    /// Frames published and not yet taken, as far as the consumer's index says (at most
    /// [`Producer::slots`]; a bogus index reads as a full ring).
    pub fn pending(&self) -> u32 {
        let consumed = self.ring.index(CONSUMED).load(Ordering::Acquire);
        let used = self.produced.wrapping_sub(consumed);
        used.min(self.ring.slots)
    }

    /// The thread to notify, with its bits, when [`Pushed::first`]: as the consumer named
    /// them ([`Consumer::wake_me`]); `None` when it named none (kick it instead). The
    /// other side writes these words: the kernel refuses a thread it may not notify.
    pub fn waiter(&self) -> Option<(u64, u64)> {
        let bits = self.ring.word(WAKE_BITS).load(Ordering::Acquire);
        let thread = self.ring.word(WAITER).load(Ordering::Acquire);
        (thread != 0 && bits != 0).then_some((thread, bits))
    }

    /// Publishes `frame`.
    pub fn push(&mut self, frame: &[u8]) -> Result<Pushed, PushError> {
        if frame.is_empty() || frame.len() > MTU {
            return Err(PushError::Length(frame.len()));
        }
        let before = self.produced;
        // Written again each time: a consumer that found a bogus `produced` (the other side
        // wrote it) resynchronises on the true one.
        self.ring.index(PRODUCED).store(before, Ordering::Release);
        if before.wrapping_sub(self.ring.index(CONSUMED).load(Ordering::Acquire)) >= self.ring.slots
        {
            return Err(PushError::Full);
        }
        let slot = self.ring.slot(before);
        let len = (frame.len() as u16).to_le_bytes();
        // SAFETY: the slot is inside the ring and is this side's until `produced` passes
        // it (the consumer has taken its previous frame: the check above).
        unsafe { core::ptr::copy_nonoverlapping(len.as_ptr(), slot, 2) };
        // SAFETY: as above; `frame` is at most MTU bytes, which fit after the 4-byte
        // length.
        unsafe {
            core::ptr::copy_nonoverlapping(frame.as_ptr(), slot.wrapping_add(4), frame.len())
        };
        self.produced = before.wrapping_add(1);
        self.ring
            .index(PRODUCED)
            .store(self.produced, Ordering::Release);
        fence(Ordering::SeqCst);
        let consumed = self.ring.index(CONSUMED).load(Ordering::Acquire);
        Ok(Pushed {
            first: consumed == before,
        })
    }
}

/// What the consumer found in a slot or an index instead of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bad {
    /// `produced` claims more frames than the ring has slots: the frames in it are
    /// skipped.
    Index,
    /// A slot's length is 0 or above [`MTU`] (the length): its frame is skipped.
    Length(usize),
}

#[allow(unsafe_code)]
impl Consumer {
    /// Slots of the ring.
    pub fn slots(&self) -> u32 {
        self.ring.slots
    }

    /// Asks the producer to notify `thread` with `bits` when a frame goes into the empty
    /// ring, instead of kicking this side through its port.
    pub fn wake_me(&mut self, thread: u64, bits: u64) {
        self.waiter = (thread, bits);
        self.publish_waiter();
    }

    fn publish_waiter(&self) {
        let (thread, bits) = self.waiter;
        self.ring.word(WAKE_BITS).store(bits, Ordering::Release);
        self.ring.word(WAITER).store(thread, Ordering::Release);
    }

    /// Whether the ring holds no frame for this side.
    pub fn is_empty(&self) -> bool {
        fence(Ordering::SeqCst);
        self.ring.index(PRODUCED).load(Ordering::Acquire) == self.consumed
    }

    /// Takes the next frame into `buf` (its length), `None` when the ring is empty.
    pub fn pop(&mut self, buf: &mut [u8; MTU]) -> Option<Result<usize, Bad>> {
        fence(Ordering::SeqCst);
        let produced = self.ring.index(PRODUCED).load(Ordering::Acquire);
        let available = produced.wrapping_sub(self.consumed);
        if available == 0 {
            // Written again while empty: a producer that found a bogus `consumed` (the
            // other side wrote it) and took its ring for full sees the true one, and
            // whom to wake.
            self.ring
                .index(CONSUMED)
                .store(self.consumed, Ordering::Release);
            if self.waiter != (0, 0) {
                self.publish_waiter();
            }
            return None;
        }
        if available > self.ring.slots {
            self.take(produced);
            return Some(Err(Bad::Index));
        }
        let slot = self.ring.slot(self.consumed);
        let mut len = [0u8; 2];
        // A producer that writes the slot anyway only changes the bytes copied out (any
        // bytes are a valid `u8`); the length is checked after it is copied (read once).
        // SAFETY: the slot is inside the ring and published (`produced` passed it): it is
        // this side's until `consumed` does.
        unsafe { core::ptr::copy_nonoverlapping(slot, len.as_mut_ptr(), 2) };
        let len = usize::from(u16::from_le_bytes(len));
        let result = if len == 0 || len > MTU {
            Err(Bad::Length(len))
        } else {
            // SAFETY: as above; `len <= MTU` bytes after the 4-byte length are inside the
            // slot and fit `buf`.
            unsafe { core::ptr::copy_nonoverlapping(slot.wrapping_add(4), buf.as_mut_ptr(), len) };
            Ok(len)
        };
        self.take(self.consumed.wrapping_add(1));
        Some(result)
    }

    fn take(&mut self, upto: u32) {
        self.consumed = upto;
        self.ring
            .index(CONSUMED)
            .store(self.consumed, Ordering::Release);
    }
}

#[cfg(test)]
#[allow(unsafe_code)]
mod tests;
