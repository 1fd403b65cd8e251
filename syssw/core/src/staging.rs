//! Staging buffers: how port messages longer than one IPC message ([`PART_MAX`]) travel
//! between a partition and syssw, in parts (the service protocol's "long messages",
//! documented with the protocol in `syssw/protocol`).
//!
//! # Storage
//!
//! A partition with a port longer than [`PART_MAX`] gets buffers of its longest port's
//! size: [`STAGING_RUNNERS`] for threads in the middle of a transfer, and [`MAX_WAITERS`]
//! more for each of its queuing input ports longer than [`PART_MAX`] (every receiver that
//! may be parked on such a port has one reserved for the message that will complete it).
//! Other partitions have none. All buffers are carved from one caller-provided arena
//! ([`arena_size`] says how many bytes a system needs), each a record of a 16-byte header
//! (the owner's token `u64`, a length `u32`, a [`State`] byte, 3 reserved bytes) and the
//! buffer. A buffer belongs to one caller (its token, the IPC caller's thread id) from its
//! first use until the transfer ends.
//!
//! # Use
//!
//! - Sending: [`Staging::stage`] appends a part (STAGE_MESSAGE); [`Staging::assemble`]
//!   appends the request's last part and gives the whole message to send; the glue then
//!   [`Staging::release`]s the buffer.
//! - Receiving: [`Staging::reserve`] claims a buffer for the caller before the port
//!   operation (so a message is never taken from a port without a place to go);
//!   [`Staging::deliver`] then holds the received message there for [`Staging::fetch`]
//!   (FETCH_MESSAGE) when it is longer than one part, or frees the buffer. A parked
//!   receiver keeps its reservation until the message that completes it is delivered (or
//!   [`Staging::release_token`] drops it: it timed out).
//! - [`Staging::reset_partition`] empties a restarting partition's buffers.
//!
//! Return codes: a partition without buffers, a message longer than its buffers, or no
//! free buffer → [`ReturnCode::InvalidConfig`]; a part out of order, a staged count that is
//! not what the caller staged, or a fetch without a held message →
//! [`ReturnCode::InvalidParam`].

use crate::ports::MAX_WAITERS;
use config::binary::SystemView;
use config::model::{Direction, MAX_PARTITIONS, PortKind};
use protocol::{PART_MAX, ReturnCode, STAGING_RUNNERS};

/// Bytes of a buffer record's header.
const HEADER: usize = 16;

/// What a buffer holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum State {
    Free = 0,
    /// The first `len` bytes of a message its owner is sending.
    Staging = 1,
    /// Reserved for a receive of its owner (filled by the port operation or a delivery).
    Reserved = 2,
    /// A received message of `len` bytes its owner fetches.
    Holding = 3,
}

impl State {
    fn from_byte(byte: u8) -> Self {
        match byte {
            1 => Self::Staging,
            2 => Self::Reserved,
            3 => Self::Holding,
            _ => Self::Free,
        }
    }
}

/// One partition's buffers.
#[derive(Clone, Copy, Debug, Default)]
struct Plan {
    /// Arena offset of its first record.
    base: usize,
    count: usize,
    /// Bytes of each buffer (0: the partition has none).
    size: usize,
}

impl Plan {
    fn record(&self) -> usize {
        HEADER + self.size
    }
}

fn plans(system: &SystemView<'_>) -> [Plan; MAX_PARTITIONS] {
    let mut plans = [Plan::default(); MAX_PARTITIONS];
    let mut base = 0;
    for partition in system.partitions() {
        let ports = || system.ports().filter(|p| p.partition == partition.index);
        let size = ports().map(|p| p.size as usize).max().unwrap_or(0);
        if size <= PART_MAX {
            continue;
        }
        let long_inputs = ports()
            .filter(|p| {
                p.kind == PortKind::Queuing
                    && p.direction == Direction::In
                    && p.size as usize > PART_MAX
            })
            .count();
        let plan = Plan {
            base,
            count: STAGING_RUNNERS + MAX_WAITERS * long_inputs,
            size,
        };
        base += plan.count * plan.record();
        plans[partition.index] = plan;
    }
    plans
}

/// Exactly the arena bytes [`Staging::new`] needs for `system`.
pub fn arena_size(system: &SystemView<'_>) -> usize {
    plans(system)
        .iter()
        .map(|plan| plan.count * plan.record())
        .sum()
}

/// Every partition's staging buffers.
pub struct Staging<'a> {
    arena: &'a mut [u8],
    plans: [Plan; MAX_PARTITIONS],
}

/// The arena is smaller than [`arena_size`] says the system needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArenaTooSmall {
    pub needed: usize,
    pub given: usize,
}

impl core::fmt::Display for ArenaTooSmall {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "staging buffers need {} bytes, the arena has {}",
            self.needed, self.given
        )
    }
}

impl<'a> Staging<'a> {
    /// The buffers of `system`, all free, carved from `arena` (at least
    /// [`arena_size`]`(system)` bytes).
    pub fn new(system: &SystemView<'_>, arena: &'a mut [u8]) -> Result<Self, ArenaTooSmall> {
        let needed = arena_size(system);
        if arena.len() < needed {
            return Err(ArenaTooSmall {
                needed,
                given: arena.len(),
            });
        }
        let mut staging = Staging {
            arena,
            plans: plans(system),
        };
        for partition in 0..MAX_PARTITIONS {
            staging.reset_partition(partition);
        }
        Ok(staging)
    }

    /// Bytes of `partition`'s buffers (0: it has none; its ports fit one part).
    pub fn size(&self, partition: usize) -> usize {
        self.plans.get(partition).map_or(0, |p| p.size)
    }

    fn plan(&self, partition: usize) -> Plan {
        self.plans.get(partition).copied().unwrap_or_default()
    }

    /// Arena offset of record `k` of `partition`.
    fn at(&self, partition: usize, k: usize) -> usize {
        let plan = self.plan(partition);
        plan.base + k * plan.record()
    }

    fn token(&self, at: usize) -> u64 {
        let mut word = [0u8; 8];
        word.copy_from_slice(&self.arena[at..at + 8]);
        u64::from_le_bytes(word)
    }

    fn len(&self, at: usize) -> usize {
        let mut word = [0u8; 4];
        word.copy_from_slice(&self.arena[at + 8..at + 12]);
        u32::from_le_bytes(word) as usize
    }

    fn state(&self, at: usize) -> State {
        State::from_byte(self.arena[at + 12])
    }

    fn set(&mut self, at: usize, token: u64, len: usize, state: State) {
        self.arena[at..at + 8].copy_from_slice(&token.to_le_bytes());
        self.arena[at + 8..at + 12].copy_from_slice(&(len as u32).to_le_bytes());
        self.arena[at + 12] = state as u8;
    }

    /// The record `token` owns in `partition`, if any.
    fn owned(&self, partition: usize, token: u64) -> Option<usize> {
        (0..self.plan(partition).count)
            .map(|k| self.at(partition, k))
            .find(|&at| self.state(at) != State::Free && self.token(at) == token)
    }

    /// The record `token` owns, else a free one, now `token`'s (INVALID_CONFIG: none).
    fn claim(&mut self, partition: usize, token: u64, state: State) -> Result<usize, ReturnCode> {
        let at = self
            .owned(partition, token)
            .or_else(|| {
                (0..self.plan(partition).count)
                    .map(|k| self.at(partition, k))
                    .find(|&at| self.state(at) == State::Free)
            })
            .ok_or(ReturnCode::InvalidConfig)?;
        self.set(at, token, 0, state);
        Ok(at)
    }

    fn buffer(&mut self, partition: usize, at: usize) -> &mut [u8] {
        let size = self.plan(partition).size;
        &mut self.arena[at + HEADER..at + HEADER + size]
    }

    /// STAGE_MESSAGE: appends `part` at `offset` of the message `token` of `partition`
    /// sends (offset 0 starts a new one).
    pub fn stage(&mut self, partition: usize, token: u64, offset: u64, part: &[u8]) -> ReturnCode {
        if part.is_empty() {
            return ReturnCode::InvalidParam;
        }
        let at = if offset == 0 {
            match self.claim(partition, token, State::Staging) {
                Ok(at) => at,
                Err(code) => return code,
            }
        } else {
            match self.owned(partition, token) {
                Some(at) if self.state(at) == State::Staging && self.len(at) as u64 == offset => at,
                _ => return ReturnCode::InvalidParam,
            }
        };
        let from = offset as usize;
        let end = from + part.len();
        if end > self.plan(partition).size {
            self.set(at, 0, 0, State::Free);
            return ReturnCode::InvalidConfig;
        }
        self.buffer(partition, at)[from..end].copy_from_slice(part);
        self.set(at, token, end, State::Staging);
        ReturnCode::NoError
    }

    /// The whole message of a WRITE_SAMPLING or SEND_QUEUING that says `staged` bytes were
    /// staged before its data `tail` (`staged > 0`). The buffer stays `token`'s until
    /// [`Staging::release`].
    pub fn assemble(
        &mut self,
        partition: usize,
        token: u64,
        staged: u64,
        tail: &[u8],
    ) -> Result<&[u8], ReturnCode> {
        let at = match self.owned(partition, token) {
            Some(at) if self.state(at) == State::Staging && self.len(at) as u64 == staged => at,
            _ => return Err(ReturnCode::InvalidParam),
        };
        let from = staged as usize;
        let end = from + tail.len();
        if end > self.plan(partition).size {
            self.set(at, 0, 0, State::Free);
            return Err(ReturnCode::InvalidConfig);
        }
        let buffer = self.buffer(partition, at);
        buffer[from..end].copy_from_slice(tail);
        Ok(&buffer[..end])
    }

    /// Frees the buffer `token` owns in `partition` (if any).
    pub fn release(&mut self, partition: usize, token: u64) {
        if let Some(at) = self.owned(partition, token) {
            self.set(at, 0, 0, State::Free);
        }
    }

    /// Claims a buffer for a receive by `token` (its own, or a free one).
    pub fn reserve(&mut self, partition: usize, token: u64) -> Result<(), ReturnCode> {
        self.claim(partition, token, State::Reserved).map(|_| ())
    }

    /// Holds the message of `len` bytes in `token`'s buffer for fetching when it is longer
    /// than one part, else frees the buffer. Returns whether it holds it.
    fn keep(&mut self, partition: usize, token: u64, len: usize) -> bool {
        let Some(at) = self.owned(partition, token) else {
            return false;
        };
        if len > PART_MAX && len <= self.plan(partition).size {
            self.set(at, token, len, State::Holding);
            true
        } else {
            self.set(at, 0, 0, State::Free);
            false
        }
    }

    /// The message received by `token` (at once, or completing it after it was parked),
    /// into its reservation in whichever partition it is: held for fetching when longer
    /// than one part, else the reservation is freed. Returns whether it is held.
    pub fn deliver(&mut self, token: u64, message: &[u8]) -> bool {
        for partition in 0..MAX_PARTITIONS {
            if let Some(at) = self.owned(partition, token)
                && self.state(at) == State::Reserved
            {
                if message.len() > self.plan(partition).size {
                    return false;
                }
                self.buffer(partition, at)[..message.len()].copy_from_slice(message);
                return self.keep(partition, token, message.len());
            }
        }
        false
    }

    /// Frees `token`'s reservation, whatever partition it is in (a parked receiver that
    /// completed without a long message).
    pub fn release_token(&mut self, token: u64) {
        for partition in 0..MAX_PARTITIONS {
            self.release(partition, token);
        }
    }

    /// FETCH_MESSAGE: copies the part at `offset` of the message `token` holds into `out`
    /// (at most [`PART_MAX`] bytes, and at most `out.len()`); returns the bytes copied and
    /// the bytes after them. The buffer is freed once a fetch reaches the message's end.
    pub fn fetch(
        &mut self,
        partition: usize,
        token: u64,
        offset: u64,
        out: &mut [u8],
    ) -> Result<(usize, u64), ReturnCode> {
        let at = match self.owned(partition, token) {
            Some(at) if self.state(at) == State::Holding => at,
            _ => return Err(ReturnCode::InvalidParam),
        };
        let len = self.len(at);
        let from = usize::try_from(offset).map_err(|_| ReturnCode::InvalidParam)?;
        if from > len {
            return Err(ReturnCode::InvalidParam);
        }
        let end = len.min(from + PART_MAX.min(out.len()));
        out[..end - from].copy_from_slice(&self.buffer(partition, at)[from..end]);
        if end == len {
            self.set(at, 0, 0, State::Free);
        }
        Ok((end - from, (len - end) as u64))
    }

    /// Empties every buffer of `partition` (it is stopped or restarted).
    pub fn reset_partition(&mut self, partition: usize) {
        for k in 0..self.plan(partition).count {
            let at = self.at(partition, k);
            self.set(at, 0, 0, State::Free);
        }
    }
}

#[cfg(test)]
mod tests;
