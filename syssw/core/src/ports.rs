//! ARINC 653 Part 1 inter-partition ports: sampling and queuing ports whose buffers syssw
//! owns, addressed by their global port index in the configuration
//! ([`config::binary::PortView::index`]).
//!
//! # Storage
//!
//! [`Ports`] keeps two fixed tables (one entry per configured port, one per channel, sized
//! by [`config::model::MAX_PORTS`] and [`MAX_CHANNELS`]) and carves every message buffer out
//! of one caller-provided byte arena. [`arena_size`] says exactly how many bytes a system
//! needs; nothing is allocated later. Per channel, in configuration order:
//!
//! - sampling: one message of the source port's size (its length and write time live in
//!   the table);
//! - queuing: a ring of `source depth + destination depth` slots of `4 + size` bytes (a
//!   little-endian `u32` length, then the message), then [`MAX_WAITERS`] waiter records of
//!   `24 + size` bytes (caller token `u64`, deadline `u64`, message length `u32`, the
//!   caller's priority `u8`, 3 reserved bytes, then the message of a parked sender).
//!
//! "size" is always the source port's size: the largest message the channel carries
//! (every destination's size is at least that, the configuration guarantees it).
//!
//! # Sampling ports
//!
//! - [`Ports::write_sampling`] by the source partition replaces the message and stamps it
//!   with `now`.
//! - [`Ports::read_sampling`] by a destination returns the latest message, its length and
//!   its validity: [`Validity::Valid`] if `now - write time <= refresh` of *that*
//!   destination port (a destination without a refresh period sees every message as
//!   valid), else [`Validity::Invalid`] with [`ReturnCode::NoError`] (ARINC: an old message
//!   is still returned). Before any write, or after the destination's partition was reset
//!   and nothing was written since, the read answers [`ReturnCode::NoAction`] with length 0.
//!
//! # Queuing ports
//!
//! A queuing channel connects one source port to one destination port. ARINC gives each
//! port its own queue of its configured depth, with messages moving on at once while the
//! destination's queue has room; syssw models that as one FIFO of
//! `source depth + destination depth` messages whose oldest `destination depth` messages
//! are "in the destination port" and the rest "still in the source port" (that is what the
//! two ports' [`QueuingStatus::nb_message`] report, and what a reset of either side drops).
//!
//! - [`Ports::send_queuing`]: a receiver is waiting → the message goes straight to the
//!   oldest receiver (reported as a [`Completion`] carrying the message) and the send is
//!   done; else room in the FIFO → appended, done; else full: time-out 0 →
//!   [`ReturnCode::NotAvailable`], otherwise the sender is parked with its message copied
//!   into a waiter record.
//! - [`Ports::receive_queuing`]: a message → the oldest is copied out and done, and if a
//!   sender is parked the oldest one's message enters the FIFO and that sender completes
//!   with [`ReturnCode::NoError`]; else empty: time-out 0 → [`ReturnCode::NotAvailable`],
//!   otherwise the receiver is parked.
//! - Waiting discipline: each queuing port has the configuration's `discipline`; the
//!   waiting port's decides (the source port's for parked senders, the destination's for
//!   parked receivers). FIFO serves waiters in the order they were parked; PRIORITY the
//!   highest [`Waiter::priority`] first, FIFO among equal priorities. The waiter list is
//!   kept in serving order (a PRIORITY waiter is inserted behind every waiter of its
//!   priority or above), so "the oldest" below means "the first to serve".
//! - Time-outs are in nanoseconds: 0 = do not wait, [`TIMEOUT_INFINITE`] = wait forever,
//!   else a deadline `now + timeout`. A waiter whose deadline is `<= now` completes with
//!   [`ReturnCode::TimedOut`] (a sender's message is discarded; a receiver gets length 0),
//!   either in [`Ports::expire`] or at the start of the next operation on its channel, so an
//!   overdue waiter is never served.
//! - Bound: at most [`MAX_WAITERS`] processes wait on one queuing channel. Only one side can
//!   be waiting at a time (senders wait only while the FIFO is full, receivers only while it
//!   is empty), so that is also the bound per port. A request that would have to wait while
//!   the list is full is refused with [`ReturnCode::InvalidConfig`] (the configuration asks
//!   for more waiting processes than the port supports); it is distinct from the
//!   [`ReturnCode::NotAvailable`] of a time-out-0 request.
//!
//! # Restarts, clears and cancels
//!
//! [`Ports::reset_partition`] is for a partition that is stopped or restarted: its waiting
//! processes are dropped without a completion (their threads are gone); each of its
//! sampling destination ports reads as empty until the next write; each queuing channel
//! whose destination it is loses the messages that were in the destination port, each
//! whose source it is loses the messages still in the source port (messages already
//! delivered stay: the other partition is alive). Senders of the other partition that now
//! fit are admitted. A sampling source's last message stays, ageing towards INVALID.
//! [`Ports::clear_queuing`] is ARINC's CLEAR_QUEUING_PORT (destination only).
//! [`Ports::cancel`] forgets one waiter (a thread that was stopped while waiting).
//!
//! # Doorbells
//!
//! A partition may ask to be told when a message arrives at one of its queuing
//! destination ports ([`Ports::set_doorbell`]: a thread token and notification bits), so
//! that a thread watching several ports and devices waits for a notification instead of
//! polling. Every message that enters the channel's FIFO (a send, or a parked sender
//! admitted) rings it; a message handed straight to a waiting receiver does not (the
//! receiver's reply is the news). [`Ports::take_rung`] reports each doorbell rung since
//! it was last called, once however many messages came; the glue then signals the thread.
//! A partition's doorbells end when it stops or restarts (its threads are gone).
//!
//! # Return codes (ARINC 653 Part 1 order of checks)
//!
//! Unknown port index, a port of another partition, or a port of the other kind →
//! [`ReturnCode::InvalidParam`]; message longer than the port's size →
//! [`ReturnCode::InvalidConfig`] (as ARINC's WRITE_SAMPLING_MESSAGE and
//! SEND_QUEUING_MESSAGE say); empty message → [`ReturnCode::InvalidParam`]; wrong
//! direction → [`ReturnCode::InvalidMode`]. Glue contract: a read/receive buffer shorter
//! than the port's size is [`ReturnCode::InvalidParam`] (a [`MAX_MESSAGE_SIZE`] buffer
//! always suffices).
//!
//! # How the glue uses it
//!
//! Every operation gets the caller's partition, `now`, and for waiting operations an opaque
//! `token` (the glue passes the IPC caller's thread id). It returns [`Outcome::Done`] (reply
//! now) or [`Outcome::Parked`] (reply later). Whenever an operation finishes *another*
//! waiter, the `done` callback is called with a [`Completion`] naming that waiter's token:
//! the glue replies to it then. [`Ports::expire`] returns the earliest remaining deadline,
//! for the glue's next receive time-out.
//!
//! [`MAX_MESSAGE_SIZE`]: config::model::MAX_MESSAGE_SIZE

use abi::syscall::TIMEOUT_INFINITE;
use config::binary::{ChannelView, SystemView};
use config::model::{Direction, Discipline, MAX_CHANNELS, MAX_PORTS, PortKind};
pub use protocol::{QueuingStatus, SamplingStatus};
use protocol::{ReturnCode, Validity};

/// Most processes waiting on one queuing channel (see the module documentation).
pub const MAX_WAITERS: usize = 8;
/// Deadline of a waiter that waits forever.
pub const NEVER: u64 = u64::MAX;

/// Bytes of the length prefix of a queue slot.
const LEN_BYTES: usize = 4;
/// Bytes of a waiter record's header (token, deadline, length, reserved).
const WAITER_HEADER: usize = 24;

/// A caller that may be parked: the token its completion names and its process priority
/// (its place among the waiters of a PRIORITY port). A bare token is a waiter of priority 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Waiter {
    pub token: u64,
    pub priority: u8,
}

impl From<u64> for Waiter {
    fn from(token: u64) -> Self {
        Waiter { token, priority: 0 }
    }
}

/// What [`Ports::read_sampling`] returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sample {
    pub code: ReturnCode,
    /// Bytes copied into the buffer (0 unless `code` is `NoError`).
    pub len: usize,
    pub validity: Validity,
}

/// What a queuing operation means for its caller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Finished: reply `code` now; after a receive with `NoError`, `len` bytes of the
    /// buffer are the message (else `len` is 0).
    Done { code: ReturnCode, len: usize },
    /// The caller waits; a [`Completion`] with its token comes later.
    Parked,
}

impl Outcome {
    const fn reply(code: ReturnCode) -> Self {
        Outcome::Done { code, len: 0 }
    }
}

/// A parked waiter that is finished; the glue replies to `token`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Completion<'m> {
    /// The token the waiter was parked with.
    pub token: u64,
    /// The port it waited on (global index).
    pub port: usize,
    /// `NoError` (sent, or received `message`) or `TimedOut`.
    pub code: ReturnCode,
    /// For a receiver completed with `NoError`: the message (valid during the callback);
    /// empty otherwise.
    pub message: &'m [u8],
}

/// Why [`Ports::new`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortsError {
    /// The arena is smaller than [`arena_size`] says the system needs.
    ArenaTooSmall { needed: usize, given: usize },
}

impl core::fmt::Display for PortsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::ArenaTooSmall { needed, given } => {
                write!(f, "port buffers need {needed} bytes, the arena has {given}")
            }
        }
    }
}

/// One configured port.
#[derive(Clone, Copy, Debug)]
struct Port {
    partition: usize,
    channel: usize,
    kind: PortKind,
    direction: Direction,
    /// Largest message (bytes).
    size: usize,
    /// Queuing: configured depth; sampling: 0.
    depth: usize,
    /// Sampling destination: refresh period (ns), 0 = none.
    refresh: u64,
    /// Sampling destination: the channel's write count when the port was last reset (the
    /// port is empty while the count has not moved past it).
    seen: u64,
    last_validity: Validity,
}

const NO_PORT: Port = Port {
    partition: usize::MAX,
    channel: 0,
    kind: PortKind::Sampling,
    direction: Direction::In,
    size: 0,
    depth: 0,
    refresh: 0,
    seen: 0,
    last_validity: Validity::Invalid,
};

/// One configured channel and its buffer state.
#[derive(Clone, Copy, Debug)]
struct Channel {
    kind: PortKind,
    /// Largest message: the source port's size.
    size: usize,
    /// Offset of its buffers in the arena.
    base: usize,
    /// Global index of the source port.
    source: usize,
    /// Queuing: global index of the destination port.
    destination: usize,
    // Sampling state.
    /// Number of writes so far.
    seq: u64,
    len: usize,
    written_at: u64,
    // Queuing state.
    /// Depth of the destination port: the oldest this-many messages are "in" it.
    dest_depth: usize,
    /// Source depth + destination depth.
    capacity: usize,
    head: usize,
    count: usize,
    /// The source port's and the destination port's disciplines (parked senders, parked
    /// receivers).
    send_discipline: Discipline,
    receive_discipline: Discipline,
    /// The waiters are senders (else receivers); meaningful while `waiting > 0`.
    senders: bool,
    /// Waiter record numbers in serving order (`order[..waiting]`).
    order: [u8; MAX_WAITERS],
    waiting: usize,
    /// Queuing: the destination partition's doorbell (its index in [`Ports::bells`]), or
    /// [`NO_BELL`].
    bell: u8,
    /// A message entered the FIFO since the doorbell was last reported.
    rung: bool,
}

/// A channel without a doorbell.
const NO_BELL: u8 = u8::MAX;
/// Most doorbells set at a time in a system (a partition watches a few ports).
pub const MAX_DOORBELLS: usize = 32;

/// Whom a queuing destination port's doorbell notifies: a thread (the glue's token) with
/// notification bits (never 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Doorbell {
    pub token: u64,
    pub bits: u64,
}

const NO_CHANNEL: Channel = Channel {
    kind: PortKind::Sampling,
    size: 0,
    base: 0,
    source: 0,
    destination: 0,
    seq: 0,
    len: 0,
    written_at: 0,
    dest_depth: 0,
    capacity: 0,
    head: 0,
    count: 0,
    send_discipline: Discipline::Fifo,
    receive_discipline: Discipline::Fifo,
    senders: false,
    order: [0; MAX_WAITERS],
    waiting: 0,
    bell: NO_BELL,
    rung: false,
};

impl Channel {
    /// The channel as configured (buffers empty, `base` 0).
    fn plan(system: &SystemView<'_>, view: &ChannelView<'_>) -> Self {
        let source = system.port(view.source);
        let destination = view.destinations().next().unwrap_or(view.source);
        let dest_depth = system.port(destination).depth as usize;
        Channel {
            kind: view.kind,
            size: source.size as usize,
            source: view.source,
            destination,
            dest_depth,
            send_discipline: source.discipline,
            receive_discipline: system.port(destination).discipline,
            capacity: source.depth as usize + dest_depth,
            ..NO_CHANNEL
        }
    }

    /// Arena bytes of its buffers.
    fn bytes(&self) -> usize {
        match self.kind {
            PortKind::Sampling => self.size,
            PortKind::Queuing => {
                self.capacity * (LEN_BYTES + self.size) + MAX_WAITERS * (WAITER_HEADER + self.size)
            }
        }
    }
}

/// Exactly the arena bytes [`Ports::new`] needs for `system`.
pub fn arena_size(system: &SystemView<'_>) -> usize {
    system
        .channels()
        .map(|c| Channel::plan(system, &c).bytes())
        .sum()
}

/// The deadline of a wait of `timeout` ns starting at `now`.
fn deadline(now: u64, timeout: u64) -> u64 {
    if timeout == TIMEOUT_INFINITE {
        NEVER
    } else {
        now.saturating_add(timeout)
    }
}

fn get_u64(bytes: &[u8], at: usize) -> u64 {
    let mut word = [0u8; 8];
    word.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(word)
}

fn get_u32(bytes: &[u8], at: usize) -> u32 {
    let mut word = [0u8; 4];
    word.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(word)
}

fn put_u64(bytes: &mut [u8], at: usize, value: u64) {
    bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
}

/// One queuing channel with its part of the arena.
struct Queue<'x> {
    arena: &'x mut [u8],
    ch: &'x mut Channel,
    /// [`Ports::rung`].
    rung: &'x mut bool,
}

impl Queue<'_> {
    /// Arena offset of the `i`-th oldest message's slot.
    fn slot(&self, i: usize) -> usize {
        self.ch.base + (self.ch.head + i) % self.ch.capacity * (LEN_BYTES + self.ch.size)
    }

    fn slot_len(&self, at: usize) -> usize {
        get_u32(self.arena, at) as usize
    }

    /// Appends `msg` (the caller checked that there is room and it fits).
    fn push(&mut self, msg: &[u8]) {
        let at = self.slot(self.ch.count);
        self.arena[at..at + LEN_BYTES].copy_from_slice(&(msg.len() as u32).to_le_bytes());
        self.arena[at + LEN_BYTES..at + LEN_BYTES + msg.len()].copy_from_slice(msg);
        self.entered();
    }

    /// A message entered the FIFO at its end: it counts, and it rings the doorbell.
    fn entered(&mut self) {
        self.ch.count += 1;
        if self.ch.bell != NO_BELL {
            (self.ch.rung, *self.rung) = (true, true);
        }
    }

    /// Removes the oldest message into `buf` (which holds `size` bytes); its length.
    fn pop(&mut self, buf: &mut [u8]) -> usize {
        let at = self.slot(0);
        let len = self.slot_len(at);
        buf[..len].copy_from_slice(&self.arena[at + LEN_BYTES..at + LEN_BYTES + len]);
        self.drop_front(1);
        len
    }

    /// Discards the `n` oldest messages (`n <= count`).
    fn drop_front(&mut self, n: usize) {
        self.ch.head = (self.ch.head + n) % self.ch.capacity;
        self.ch.count -= n;
        if self.ch.count == 0 {
            self.ch.head = 0;
        }
    }

    /// Arena offset of waiter record `record`.
    fn record(&self, record: u8) -> usize {
        self.ch.base
            + self.ch.capacity * (LEN_BYTES + self.ch.size)
            + record as usize * (WAITER_HEADER + self.ch.size)
    }

    fn token(&self, k: usize) -> u64 {
        get_u64(self.arena, self.record(self.ch.order[k]))
    }

    fn deadline(&self, k: usize) -> u64 {
        get_u64(self.arena, self.record(self.ch.order[k]) + 8)
    }

    fn priority(&self, k: usize) -> u8 {
        self.arena[self.record(self.ch.order[k]) + 20]
    }

    /// The port the waiters wait on.
    fn waiting_port(&self) -> usize {
        if self.ch.senders {
            self.ch.source
        } else {
            self.ch.destination
        }
    }

    /// Parks a waiter in serving order: at the end (FIFO), or behind every waiter of its
    /// priority or above (PRIORITY). The caller checked there is a free record and that the
    /// list holds the same side or is empty. `msg` is empty for a receiver.
    fn park(&mut self, senders: bool, waiter: Waiter, deadline: u64, msg: &[u8]) {
        let used = &self.ch.order[..self.ch.waiting];
        let free = (0..MAX_WAITERS as u8)
            .find(|r| !used.contains(r))
            .unwrap_or(0);
        let at = self.record(free);
        put_u64(self.arena, at, waiter.token);
        put_u64(self.arena, at + 8, deadline);
        self.arena[at + 16..at + 20].copy_from_slice(&(msg.len() as u32).to_le_bytes());
        self.arena[at + 20] = waiter.priority;
        let data = at + WAITER_HEADER;
        self.arena[data..data + msg.len()].copy_from_slice(msg);
        let discipline = if senders {
            self.ch.send_discipline
        } else {
            self.ch.receive_discipline
        };
        let place = match discipline {
            Discipline::Fifo => self.ch.waiting,
            Discipline::Priority => (0..self.ch.waiting)
                .find(|&k| self.priority(k) < waiter.priority)
                .unwrap_or(self.ch.waiting),
        };
        self.ch.order.copy_within(place..self.ch.waiting, place + 1);
        self.ch.order[place] = free;
        self.ch.waiting += 1;
        self.ch.senders = senders;
    }

    /// Removes the `k`-th waiter from the list; its record number.
    fn unpark(&mut self, k: usize) -> u8 {
        let record = self.ch.order[k];
        self.ch.order.copy_within(k + 1..self.ch.waiting, k);
        self.ch.waiting -= 1;
        record
    }

    /// Moves parked senders' messages into the FIFO while there is room, in serving order.
    fn admit(&mut self, done: &mut dyn FnMut(Completion<'_>)) {
        while self.ch.senders && self.ch.waiting > 0 && self.ch.count < self.ch.capacity {
            let token = self.token(0);
            let record = self.unpark(0);
            let at = self.record(record);
            let len = get_u32(self.arena, at + 16) as usize;
            let to = self.slot(self.ch.count);
            self.arena[to..to + LEN_BYTES].copy_from_slice(&(len as u32).to_le_bytes());
            let from = at + WAITER_HEADER;
            self.arena.copy_within(from..from + len, to + LEN_BYTES);
            self.entered();
            done(Completion {
                token,
                port: self.ch.source,
                code: ReturnCode::NoError,
                message: &[],
            });
        }
    }

    /// Completes every waiter whose deadline is `<= now` with `TimedOut`; the earliest
    /// remaining finite deadline.
    fn expire(&mut self, now: u64, done: &mut dyn FnMut(Completion<'_>)) -> Option<u64> {
        let mut next: Option<u64> = None;
        let mut k = 0;
        while k < self.ch.waiting {
            let deadline = self.deadline(k);
            if deadline != NEVER && deadline <= now {
                let token = self.token(k);
                let port = self.waiting_port();
                self.unpark(k);
                done(Completion {
                    token,
                    port,
                    code: ReturnCode::TimedOut,
                    message: &[],
                });
            } else {
                if deadline != NEVER {
                    next = Some(next.map_or(deadline, |n| n.min(deadline)));
                }
                k += 1;
            }
        }
        next
    }
}

/// All ports and channels of a system, with their buffers in the arena.
pub struct Ports<'a> {
    arena: &'a mut [u8],
    ports: [Port; MAX_PORTS],
    port_count: usize,
    channels: [Channel; MAX_CHANNELS],
    channel_count: usize,
    /// Some channel's doorbell rang since [`Ports::take_rung`] last looked.
    rung: bool,
    /// The doorbells set; a free one has no bits.
    bells: [Doorbell; MAX_DOORBELLS],
}

impl<'a> Ports<'a> {
    /// Sets up every port and channel of `system` (a decoded, hence validated,
    /// configuration) with empty buffers carved from `arena`, which must hold at least
    /// [`arena_size`]`(system)` bytes (the rest is left alone).
    pub fn new(system: &SystemView<'_>, arena: &'a mut [u8]) -> Result<Self, PortsError> {
        let needed = arena_size(system);
        if arena.len() < needed {
            return Err(PortsError::ArenaTooSmall {
                needed,
                given: arena.len(),
            });
        }
        let mut ports = [NO_PORT; MAX_PORTS];
        let port_count = system.port_count().min(MAX_PORTS);
        for (slot, view) in ports.iter_mut().zip(system.ports()) {
            *slot = Port {
                partition: view.partition,
                channel: view.channel,
                kind: view.kind,
                direction: view.direction,
                size: view.size as usize,
                depth: view.depth as usize,
                refresh: view.refresh,
                ..NO_PORT
            };
        }
        let mut channels = [NO_CHANNEL; MAX_CHANNELS];
        let channel_count = system.channel_count().min(MAX_CHANNELS);
        let mut base = 0;
        for (slot, view) in channels.iter_mut().zip(system.channels()) {
            *slot = Channel {
                base,
                ..Channel::plan(system, &view)
            };
            base += slot.bytes();
        }
        Ok(Ports {
            arena,
            ports,
            port_count,
            channels,
            channel_count,
            rung: false,
            bells: [Doorbell { token: 0, bits: 0 }; MAX_DOORBELLS],
        })
    }

    /// Number of configured ports (valid indices are `0..port_count()`).
    pub fn port_count(&self) -> usize {
        self.port_count
    }

    /// Port `port` if it exists, belongs to `partition` and is of `kind`.
    fn lookup(&self, partition: usize, port: usize, kind: PortKind) -> Result<Port, ReturnCode> {
        match self.ports[..self.port_count].get(port) {
            Some(p) if p.partition == partition && p.kind == kind => Ok(*p),
            _ => Err(ReturnCode::InvalidParam),
        }
    }

    /// Port `port` if it is a queuing destination port of `partition`.
    fn queuing_destination(&self, partition: usize, port: usize) -> Result<Port, ReturnCode> {
        let p = self.lookup(partition, port, PortKind::Queuing)?;
        if p.direction != Direction::In {
            return Err(ReturnCode::InvalidMode);
        }
        Ok(p)
    }

    fn queue(&mut self, channel: usize) -> Queue<'_> {
        Queue {
            arena: self.arena,
            ch: &mut self.channels[channel],
            rung: &mut self.rung,
        }
    }

    /// ARINC WRITE_SAMPLING_MESSAGE: `partition` writes `msg` to its sampling source port
    /// `port` at time `now`.
    pub fn write_sampling(
        &mut self,
        partition: usize,
        port: usize,
        msg: &[u8],
        now: u64,
    ) -> ReturnCode {
        let p = match self.lookup(partition, port, PortKind::Sampling) {
            Ok(p) => p,
            Err(code) => return code,
        };
        if msg.len() > p.size {
            return ReturnCode::InvalidConfig;
        }
        if msg.is_empty() {
            return ReturnCode::InvalidParam;
        }
        if p.direction != Direction::Out {
            return ReturnCode::InvalidMode;
        }
        let ch = &mut self.channels[p.channel];
        self.arena[ch.base..ch.base + msg.len()].copy_from_slice(msg);
        ch.len = msg.len();
        ch.written_at = now;
        ch.seq += 1;
        ReturnCode::NoError
    }

    /// ARINC READ_SAMPLING_MESSAGE: `partition` reads its sampling destination port `port`
    /// at time `now` into `buf` (at least the port's size).
    pub fn read_sampling(
        &mut self,
        partition: usize,
        port: usize,
        now: u64,
        buf: &mut [u8],
    ) -> Sample {
        let empty = |code| Sample {
            code,
            len: 0,
            validity: Validity::Invalid,
        };
        let p = match self.lookup(partition, port, PortKind::Sampling) {
            Ok(p) => p,
            Err(code) => return empty(code),
        };
        if p.direction != Direction::In {
            return empty(ReturnCode::InvalidMode);
        }
        if buf.len() < p.size {
            return empty(ReturnCode::InvalidParam);
        }
        let ch = &self.channels[p.channel];
        if ch.seq == p.seen {
            return empty(ReturnCode::NoAction);
        }
        buf[..ch.len].copy_from_slice(&self.arena[ch.base..ch.base + ch.len]);
        let age = now.saturating_sub(ch.written_at);
        let validity = if p.refresh == 0 || age <= p.refresh {
            Validity::Valid
        } else {
            Validity::Invalid
        };
        self.ports[port].last_validity = validity;
        Sample {
            code: ReturnCode::NoError,
            len: ch.len,
            validity,
        }
    }

    /// ARINC GET_SAMPLING_PORT_STATUS of `partition`'s port `port`.
    pub fn sampling_status(
        &self,
        partition: usize,
        port: usize,
    ) -> Result<SamplingStatus, ReturnCode> {
        let p = self.lookup(partition, port, PortKind::Sampling)?;
        Ok(SamplingStatus {
            max_message_size: p.size as u32,
            direction: p.direction,
            refresh_period: p.refresh,
            last_msg_validity: p.last_validity,
        })
    }

    /// ARINC SEND_QUEUING_MESSAGE: `partition` sends `msg` on its queuing source port
    /// `port` at `now`, waiting at most `timeout` ns (0: not at all; [`TIMEOUT_INFINITE`]:
    /// forever) as `waiter`. Other waiters this finishes go to `done`.
    #[allow(clippy::too_many_arguments)]
    pub fn send_queuing(
        &mut self,
        partition: usize,
        port: usize,
        msg: &[u8],
        now: u64,
        timeout: u64,
        waiter: impl Into<Waiter>,
        mut done: impl FnMut(Completion<'_>),
    ) -> Outcome {
        let p = match self.lookup(partition, port, PortKind::Queuing) {
            Ok(p) => p,
            Err(code) => return Outcome::reply(code),
        };
        if msg.len() > p.size {
            return Outcome::reply(ReturnCode::InvalidConfig);
        }
        if msg.is_empty() {
            return Outcome::reply(ReturnCode::InvalidParam);
        }
        if p.direction != Direction::Out {
            return Outcome::reply(ReturnCode::InvalidMode);
        }
        let mut q = self.queue(p.channel);
        q.expire(now, &mut done);
        if q.ch.waiting > 0 && !q.ch.senders {
            // Receivers wait only on an empty FIFO: hand the message to the first.
            let token = q.token(0);
            q.unpark(0);
            done(Completion {
                token,
                port: q.ch.destination,
                code: ReturnCode::NoError,
                message: msg,
            });
            return Outcome::reply(ReturnCode::NoError);
        }
        if q.ch.waiting == 0 && q.ch.count < q.ch.capacity {
            q.push(msg);
            return Outcome::reply(ReturnCode::NoError);
        }
        if timeout == 0 {
            return Outcome::reply(ReturnCode::NotAvailable);
        }
        if q.ch.waiting == MAX_WAITERS {
            return Outcome::reply(ReturnCode::InvalidConfig);
        }
        q.park(true, waiter.into(), deadline(now, timeout), msg);
        Outcome::Parked
    }

    /// ARINC RECEIVE_QUEUING_MESSAGE: `partition` receives from its queuing destination
    /// port `port` at `now` into `buf` (at least the port's size), waiting at most `timeout`
    /// ns as `waiter`. Other waiters this finishes go to `done`.
    #[allow(clippy::too_many_arguments)]
    pub fn receive_queuing(
        &mut self,
        partition: usize,
        port: usize,
        now: u64,
        timeout: u64,
        waiter: impl Into<Waiter>,
        buf: &mut [u8],
        mut done: impl FnMut(Completion<'_>),
    ) -> Outcome {
        let p = match self.queuing_destination(partition, port) {
            Ok(p) => p,
            Err(code) => return Outcome::reply(code),
        };
        if buf.len() < p.size {
            return Outcome::reply(ReturnCode::InvalidParam);
        }
        let mut q = self.queue(p.channel);
        q.expire(now, &mut done);
        if q.ch.count > 0 {
            let len = q.pop(buf);
            q.admit(&mut done);
            return Outcome::Done {
                code: ReturnCode::NoError,
                len,
            };
        }
        if timeout == 0 {
            return Outcome::reply(ReturnCode::NotAvailable);
        }
        if q.ch.waiting == MAX_WAITERS {
            return Outcome::reply(ReturnCode::InvalidConfig);
        }
        q.park(false, waiter.into(), deadline(now, timeout), &[]);
        Outcome::Parked
    }

    /// ARINC CLEAR_QUEUING_PORT: `partition` discards the messages in its queuing
    /// destination port `port` (messages still in the source port move in, parked senders
    /// that now fit are admitted and reported to `done`).
    pub fn clear_queuing(
        &mut self,
        partition: usize,
        port: usize,
        now: u64,
        mut done: impl FnMut(Completion<'_>),
    ) -> ReturnCode {
        let p = match self.queuing_destination(partition, port) {
            Ok(p) => p,
            Err(code) => return code,
        };
        let mut q = self.queue(p.channel);
        q.expire(now, &mut done);
        let n = q.ch.count.min(q.ch.dest_depth);
        q.drop_front(n);
        q.admit(&mut done);
        ReturnCode::NoError
    }

    /// ARINC GET_QUEUING_PORT_STATUS of `partition`'s port `port`.
    pub fn queuing_status(
        &self,
        partition: usize,
        port: usize,
    ) -> Result<QueuingStatus, ReturnCode> {
        let p = self.lookup(partition, port, PortKind::Queuing)?;
        let ch = &self.channels[p.channel];
        let (nb, senders) = match p.direction {
            Direction::Out => (ch.count.saturating_sub(ch.dest_depth), true),
            Direction::In => (ch.count.min(ch.dest_depth), false),
        };
        let waiting = if ch.senders == senders { ch.waiting } else { 0 };
        Ok(QueuingStatus {
            nb_message: nb as u32,
            max_nb_message: p.depth as u32,
            max_message_size: p.size as u32,
            direction: p.direction,
            waiting_processes: waiting as u32,
        })
    }

    /// Completes every waiter whose deadline is `<= now` with `TimedOut` (reported to
    /// `done`); the earliest remaining finite deadline, if any (the glue's next wake-up).
    pub fn expire(&mut self, now: u64, mut done: impl FnMut(Completion<'_>)) -> Option<u64> {
        let mut next: Option<u64> = None;
        for c in 0..self.channel_count {
            if self.channels[c].kind != PortKind::Queuing {
                continue;
            }
            if let Some(d) = self.queue(c).expire(now, &mut done) {
                next = Some(next.map_or(d, |n| n.min(d)));
            }
        }
        next
    }

    /// The earliest finite deadline of any waiter (without expiring anything).
    pub fn next_deadline(&self) -> Option<u64> {
        let mut next: Option<u64> = None;
        for ch in &self.channels[..self.channel_count] {
            if ch.kind != PortKind::Queuing {
                continue;
            }
            let records = ch.base + ch.capacity * (LEN_BYTES + ch.size);
            for &r in &ch.order[..ch.waiting] {
                let d = get_u64(
                    self.arena,
                    records + r as usize * (WAITER_HEADER + ch.size) + 8,
                );
                if d != NEVER {
                    next = Some(next.map_or(d, |n| n.min(d)));
                }
            }
        }
        next
    }

    /// Drops the waiter parked with `token`, without a completion (its thread was stopped
    /// or killed). True if there was one.
    pub fn cancel(&mut self, token: u64) -> bool {
        let mut found = false;
        for c in 0..self.channel_count {
            if self.channels[c].kind != PortKind::Queuing {
                continue;
            }
            let mut q = self.queue(c);
            let mut k = 0;
            while k < q.ch.waiting {
                if q.token(k) == token {
                    q.unpark(k);
                    found = true;
                } else {
                    k += 1;
                }
            }
        }
        found
    }

    /// Sets (`bits` not 0) or removes the doorbell of `partition`'s queuing destination
    /// port `port`: thread `token` is to be signalled `bits` when a message arrives (see
    /// the module documentation). A message already waiting rings it at once. More than
    /// [`MAX_DOORBELLS`] in the system at a time are INVALID_CONFIG.
    pub fn set_doorbell(
        &mut self,
        partition: usize,
        port: usize,
        token: u64,
        bits: u64,
    ) -> ReturnCode {
        let p = match self.queuing_destination(partition, port) {
            Ok(p) => p,
            Err(code) => return code,
        };
        let ch = &mut self.channels[p.channel];
        if ch.bell != NO_BELL {
            self.bells[ch.bell as usize].bits = 0;
            (ch.bell, ch.rung) = (NO_BELL, false);
        }
        if bits == 0 {
            return ReturnCode::NoError;
        }
        let Some(free) = self.bells.iter().position(|b| b.bits == 0) else {
            return ReturnCode::InvalidConfig;
        };
        self.bells[free] = Doorbell { token, bits };
        (ch.bell, ch.rung) = (free as u8, ch.count > 0);
        self.rung |= ch.rung;
        ReturnCode::NoError
    }

    /// Reports to `ring` each doorbell rung since the last call (see the module
    /// documentation).
    pub fn take_rung(&mut self, mut ring: impl FnMut(Doorbell)) {
        if !core::mem::take(&mut self.rung) {
            return;
        }
        for ch in &mut self.channels[..self.channel_count] {
            if core::mem::take(&mut ch.rung) && ch.bell != NO_BELL {
                ring(self.bells[ch.bell as usize]);
            }
        }
    }

    /// Resets every port of `partition` for a stop or restart (see the module
    /// documentation); senders of other partitions this admits are reported to `done`.
    pub fn reset_partition(&mut self, partition: usize, mut done: impl FnMut(Completion<'_>)) {
        for i in 0..self.port_count {
            let p = &mut self.ports[i];
            if p.partition == partition {
                p.seen = self.channels[p.channel].seq;
                p.last_validity = Validity::Invalid;
            }
        }
        for c in 0..self.channel_count {
            let ch = &self.channels[c];
            if ch.kind != PortKind::Queuing {
                continue;
            }
            let source = self.ports[ch.source].partition == partition;
            let destination = self.ports[ch.destination].partition == partition;
            let mut q = self.queue(c);
            if q.ch.waiting > 0 && (if q.ch.senders { source } else { destination }) {
                q.ch.waiting = 0;
            }
            if source {
                q.ch.count = q.ch.count.min(q.ch.dest_depth);
            }
            if destination {
                let n = q.ch.count.min(q.ch.dest_depth);
                q.drop_front(n);
            }
            q.admit(&mut done);
            let ch = &mut self.channels[c];
            if destination && ch.bell != NO_BELL {
                self.bells[ch.bell as usize].bits = 0;
                (ch.bell, ch.rung) = (NO_BELL, false);
            }
        }
    }

    /// Checks the queue invariants (tests only).
    #[cfg(test)]
    fn check_invariants(&self) {
        for ch in &self.channels[..self.channel_count] {
            if ch.kind != PortKind::Queuing {
                continue;
            }
            assert!(ch.count <= ch.capacity);
            assert!(ch.waiting <= MAX_WAITERS);
            if ch.waiting > 0 {
                if ch.senders {
                    assert_eq!(ch.count, ch.capacity, "senders wait only on a full FIFO");
                } else {
                    assert_eq!(ch.count, 0, "receivers wait only on an empty FIFO");
                }
            }
            let used = &ch.order[..ch.waiting];
            for (i, r) in used.iter().enumerate() {
                assert!((*r as usize) < MAX_WAITERS);
                assert!(!used[i + 1..].contains(r), "a record is used twice");
            }
            let discipline = if ch.senders {
                ch.send_discipline
            } else {
                ch.receive_discipline
            };
            if discipline == Discipline::Priority {
                let records = ch.base + ch.capacity * (LEN_BYTES + ch.size);
                let priority =
                    |r: u8| self.arena[records + r as usize * (WAITER_HEADER + ch.size) + 20];
                assert!(
                    used.windows(2).all(|w| priority(w[0]) >= priority(w[1])),
                    "PRIORITY waiters out of order"
                );
            }
        }
    }
}

#[cfg(test)]
mod tests;
