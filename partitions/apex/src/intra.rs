//! Intra-partition communication (ARINC 653 P1 3.7 and the mutexes of Supplement 5):
//! buffers, blackboards, semaphores, events and mutexes, with their wait queues (pure: no
//! system calls, host-tested).
//!
//! Everything is fixed-capacity: object tables of const size, message storage carved at
//! creation (which is only allowed while the partition initialises) from one byte pool of
//! [`POOL_SIZE`] bytes, and one mailbox per process slot for the message a waker hands
//! over. The runtime keeps one [`Intra`] in its static state, next to the process table.
//!
//! # Waiting
//!
//! A service that has to wait records the caller as a waiter of the object and returns
//! [`Step::Wait`]; the runtime blocks the caller's thread outside its lock. A service that
//! satisfies a waiter decides its outcome here (a message copied to its mailbox, a mutex
//! made its own, a semaphore unit taken) and marks its slot in [`Intra::take_woken`]; the
//! runtime signals those threads. The waiter collects its outcome with [`Intra::end_wait`],
//! which also removes it from the queue with TIMED_OUT once its time-out has expired: an
//! outcome decided before that wins, so a wake and a time-out never both happen.
//!
//! Queuing disciplines: FIFO serves waiters in the order they came; PRIORITY serves the
//! highest current priority (as it was when the process began to wait), FIFO among equal
//! priorities.
//!
//! # Mutexes
//!
//! Priority ceiling, as ARINC 653 Supplement 5 specifies: the owner of a mutex runs at the
//! mutex's priority while it holds it and gets its retained priority back when it releases
//! it (lock count 0) or the mutex is reset. A process owns at most one mutex at a time and
//! may not wait on anything else (other than with a zero time-out) while it owns one.
//!
//! # Preemption lock
//!
//! LOCK_PREEMPTION makes the caller the owner of the partition's preemption lock (ARINC's
//! PREEMPTION_LOCK_MUTEX) and counts the lock level up to MAX_LOCK_LEVEL; UNLOCK_PREEMPTION
//! counts it down. While the level is above 0 the owner runs at [`Intra::lock_priority`],
//! the partition's MCP: above every process, so no other process of the partition runs
//! until the level is back at 0 and the owner gets its retained priority back. The error
//! handler and the runtime's deadline watchdog share the MCP: they run when the owner
//! next calls a service (each critical section of the runtime requeues the caller at the
//! MCP). The lock is a mutex like the others: its owner owns no other mutex and may not
//! wait (INVALID_MODE for a non-zero time-out).

use crate::codes::name_bytes;
use crate::table::{ERROR_HANDLER_SLOT, SLOTS, id_of};
use a653rs::bindings::*;

type Result<T> = core::result::Result<T, ErrorReturnCode>;

/// Buffers a partition may create.
pub const MAX_BUFFERS: usize = 8;
/// Blackboards a partition may create.
pub const MAX_BLACKBOARDS: usize = 8;
/// Semaphores a partition may create.
pub const MAX_SEMAPHORES: usize = 16;
/// Events a partition may create.
pub const MAX_EVENTS: usize = 16;
/// Mutexes a partition may create.
pub const MAX_MUTEXES: usize = 8;
/// The largest message of a buffer or blackboard (bytes).
pub const MAX_MESSAGE_SIZE: usize = 256;
/// The largest MAX_NB_MESSAGE of a buffer.
pub const MAX_BUFFER_MESSAGES: usize = 128;
/// Message storage of all buffers and blackboards (bytes): a buffer takes
/// `max_nb_message * (max_message_size + 2)`, a blackboard `max_message_size`.
pub const POOL_SIZE: usize = 32 * 1024;
/// The largest semaphore value (ARINC's MAX_SEMAPHORE_VALUE).
pub const MAX_SEMAPHORE_VALUE: SemaphoreValue = 32767;

/// An object of a kind (a table of `Option<Self>` whose ids start at `BASE`).
trait Object: Copy {
    const BASE: i64;
    fn name(&self) -> &ApexName;
}

macro_rules! object {
    ($kind:ty, $base:expr) => {
        impl Object for $kind {
            const BASE: i64 = $base;
            fn name(&self) -> &ApexName {
                &self.name
            }
        }
    };
}

// Object ids: the kind in the hundreds, the index below (ids of different kinds never
// coincide, so a wrong kind of id is INVALID_PARAM).
object!(Buffer, 0x100);
object!(Blackboard, 0x200);
object!(Semaphore, 0x300);
object!(Event, 0x400);
object!(Mutex, 0x500);

/// The index of the object named `name`.
fn find_name<T: Object>(objects: &[Option<T>], name: &ApexName) -> Option<usize> {
    let wanted = name_bytes(name);
    objects
        .iter()
        .position(|o| o.as_ref().is_some_and(|o| name_bytes(o.name()) == wanted))
}

/// GET_*_ID: the id of the object named `name`, INVALID_CONFIG if there is none.
fn id_by_name<T: Object>(objects: &[Option<T>], name: &ApexName) -> Result<i64> {
    find_name(objects, name)
        .map(|i| T::BASE + i as i64)
        .ok_or(ErrorReturnCode::InvalidConfig)
}

/// The object of `id` and its index, INVALID_PARAM for an unknown id (or another kind's).
fn by_id<T: Object>(objects: &[Option<T>], id: i64) -> Result<(usize, T)> {
    let index = id
        .checked_sub(T::BASE)
        .and_then(|i| usize::try_from(i).ok())
        .filter(|&i| i < objects.len())
        .ok_or(ErrorReturnCode::InvalidParam)?;
    let object = objects[index].ok_or(ErrorReturnCode::InvalidParam)?;
    Ok((index, object))
}

/// CREATE_*: the free index for a new object named `name` (INVALID_MODE in NORMAL mode,
/// NO_ACTION if the name exists, INVALID_CONFIG if the table is full).
fn free_index<T: Object>(objects: &[Option<T>], normal: bool, name: &ApexName) -> Result<usize> {
    if normal {
        return Err(ErrorReturnCode::InvalidMode);
    }
    if find_name(objects, name).is_some() {
        return Err(ErrorReturnCode::NoAction);
    }
    objects
        .iter()
        .position(Option::is_none)
        .ok_or(ErrorReturnCode::InvalidConfig)
}

/// What an object waiter waits on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum On {
    /// A message to arrive (RECEIVE_BUFFER).
    BufferReceive(usize),
    /// Room for its message (SEND_BUFFER; the message is in its mailbox).
    BufferSend(usize),
    Blackboard(usize),
    Semaphore(usize),
    Event(usize),
    Mutex(usize),
}

#[derive(Clone, Copy, Debug)]
struct Waiter {
    on: On,
    seq: u64,
    priority: u8,
}

#[derive(Clone, Copy, Debug)]
struct Buffer {
    name: ApexName,
    max_size: usize,
    capacity: usize,
    discipline: QueuingDiscipline,
    /// Pool offset of its ring of `capacity` slots of `2 + max_size` bytes.
    start: usize,
    head: usize,
    count: usize,
}

impl Buffer {
    fn stride(&self) -> usize {
        2 + self.max_size
    }
    fn slot_offset(&self, n: usize) -> usize {
        self.start + ((self.head + n) % self.capacity) * self.stride()
    }
}

#[derive(Clone, Copy, Debug)]
struct Blackboard {
    name: ApexName,
    max_size: usize,
    start: usize,
    /// Length of the displayed message (None: empty).
    message: Option<usize>,
}

#[derive(Clone, Copy, Debug)]
struct Semaphore {
    name: ApexName,
    value: SemaphoreValue,
    max: SemaphoreValue,
    discipline: QueuingDiscipline,
}

#[derive(Clone, Copy, Debug)]
struct Event {
    name: ApexName,
    up: bool,
}

#[derive(Clone, Copy, Debug)]
struct Mutex {
    name: ApexName,
    /// The ceiling: its owner's priority while it owns it.
    priority: u8,
    discipline: QueuingDiscipline,
    owner: Option<usize>,
    lock_count: LockCount,
    /// The owner's priority before it acquired the mutex.
    retained: u8,
}

/// The preemption lock's owner (one process; nobody else runs while the level is above 0).
#[derive(Clone, Copy, Debug)]
struct PreemptionLock {
    owner: usize,
    level: LockLevel,
    /// The owner's priority before it locked.
    retained: u8,
}

/// The calling thread as the services see it.
#[derive(Clone, Copy, Debug)]
pub struct Caller {
    /// Its process slot (None: the initialisation thread, which is no process).
    pub slot: Option<usize>,
    /// Its current priority.
    pub priority: u8,
}

impl Caller {
    pub fn process(slot: usize, priority: u8) -> Self {
        Caller {
            slot: Some(slot),
            priority,
        }
    }
}

/// What a service that may wait did (its errors are the `Err` around it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step<T> {
    Done(T),
    /// The caller is queued; block it, then call [`Intra::end_wait`].
    Wait,
}

/// The intra-partition objects of one partition run.
pub struct Intra {
    buffers: [Option<Buffer>; MAX_BUFFERS],
    blackboards: [Option<Blackboard>; MAX_BLACKBOARDS],
    semaphores: [Option<Semaphore>; MAX_SEMAPHORES],
    events: [Option<Event>; MAX_EVENTS],
    mutexes: [Option<Mutex>; MAX_MUTEXES],
    preemption: Option<PreemptionLock>,
    waiters: [Option<Waiter>; SLOTS],
    /// Outcomes decided for waiters (Ok(message length)).
    done: [Option<Result<usize>>; SLOTS],
    mail: [[u8; MAX_MESSAGE_SIZE]; SLOTS],
    mail_len: [usize; SLOTS],
    /// Current priorities the runtime must give processes (mutex ceilings and restores).
    priorities: [Option<u8>; SLOTS],
    woken: u32,
    seq: u64,
    pool: [u8; POOL_SIZE],
    pool_used: usize,
}

impl Intra {
    pub const EMPTY: Intra = Intra {
        buffers: [None; MAX_BUFFERS],
        blackboards: [None; MAX_BLACKBOARDS],
        semaphores: [None; MAX_SEMAPHORES],
        events: [None; MAX_EVENTS],
        mutexes: [None; MAX_MUTEXES],
        preemption: None,
        waiters: [None; SLOTS],
        done: [None; SLOTS],
        mail: [[0; MAX_MESSAGE_SIZE]; SLOTS],
        mail_len: [0; SLOTS],
        priorities: [None; SLOTS],
        woken: 0,
        seq: 0,
        pool: [0; POOL_SIZE],
        pool_used: 0,
    };

    /// A partition (re)start: no objects (in place: the pool is too big to move on a
    /// thread's stack).
    pub fn reset(&mut self) {
        self.buffers = [None; MAX_BUFFERS];
        self.blackboards = [None; MAX_BLACKBOARDS];
        self.semaphores = [None; MAX_SEMAPHORES];
        self.events = [None; MAX_EVENTS];
        self.mutexes = [None; MAX_MUTEXES];
        self.preemption = None;
        self.waiters = [None; SLOTS];
        self.done = [None; SLOTS];
        self.mail_len = [0; SLOTS];
        self.priorities = [None; SLOTS];
        self.woken = 0;
        self.seq = 0;
        self.pool_used = 0;
    }

    /// Slots whose waits have ended with an outcome since the last call (bit = slot).
    pub fn take_woken(&mut self) -> u32 {
        core::mem::take(&mut self.woken)
    }

    /// The priority `slot` must run at now, if a mutex service changed it.
    pub fn take_priority(&mut self, slot: usize) -> Option<u8> {
        self.priorities.get_mut(slot).and_then(Option::take)
    }

    /// The message handed to `slot` by the service that ended its wait.
    pub fn mail(&self, slot: usize) -> &[u8] {
        &self.mail[slot][..self.mail_len[slot]]
    }

    /// Objects waited on by `slot`.
    pub fn is_waiting(&self, slot: usize) -> bool {
        self.waiters.get(slot).is_some_and(Option::is_some)
    }

    // ------------------------------------------------------------ waiting

    /// Checks a caller that would wait with a non-zero `time_out`: processes only, not the
    /// error handler, not while owning a mutex or the preemption lock (INVALID_MODE).
    fn may_wait(&self, caller: Caller) -> Result<usize> {
        let slot = caller.slot.ok_or(ErrorReturnCode::InvalidMode)?;
        if slot == ERROR_HANDLER_SLOT || self.owns_a_mutex(slot) {
            return Err(ErrorReturnCode::InvalidMode);
        }
        Ok(slot)
    }

    /// The object cannot serve the caller now: NOT_AVAILABLE for a zero `time_out`, else
    /// the caller (if it may wait) is queued on `on` with `mail` (a waiting sender's
    /// message, else empty) in its mailbox.
    fn wait_on<T>(
        &mut self,
        caller: Caller,
        on: On,
        time_out: ApexSystemTime,
        mail: &[u8],
    ) -> Result<Step<T>> {
        if time_out == 0 {
            return Err(ErrorReturnCode::NotAvailable);
        }
        let slot = self.may_wait(caller)?;
        self.mail[slot][..mail.len()].copy_from_slice(mail);
        self.mail_len[slot] = mail.len();
        self.seq += 1;
        self.done[slot] = None;
        self.waiters[slot] = Some(Waiter {
            on,
            seq: self.seq,
            priority: caller.priority,
        });
        Ok(Step::Wait)
    }

    /// The waiter on `on` to serve next under `discipline`.
    fn next(&self, on: On, discipline: QueuingDiscipline) -> Option<usize> {
        let mut best: Option<(usize, Waiter)> = None;
        for (slot, waiter) in self.waiters.iter().enumerate() {
            let Some(w) = waiter.filter(|w| w.on == on) else {
                continue;
            };
            let better = match best {
                None => true,
                Some((_, b)) => match discipline {
                    QueuingDiscipline::Fifo => w.seq < b.seq,
                    QueuingDiscipline::Priority => {
                        w.priority > b.priority || (w.priority == b.priority && w.seq < b.seq)
                    }
                },
            };
            if better {
                best = Some((slot, w));
            }
        }
        best.map(|(slot, _)| slot)
    }

    fn count_waiting(&self, on: impl Fn(On) -> bool) -> WaitingRange {
        self.waiters
            .iter()
            .filter(|w| w.is_some_and(|w| on(w.on)))
            .count() as WaitingRange
    }

    /// Ends `slot`'s wait with `outcome`.
    fn wake(&mut self, slot: usize, outcome: Result<usize>) {
        self.waiters[slot] = None;
        self.done[slot] = Some(outcome);
        self.woken |= 1 << slot;
    }

    /// After the thread of `slot` woke up (notified or not): its outcome, TIMED_OUT (it
    /// leaves the queue) if `expired` and no outcome was decided, or None: it was woken
    /// early without one and waits on.
    pub fn end_wait(&mut self, slot: usize, expired: bool) -> Option<Result<usize>> {
        if let Some(outcome) = self.done[slot].take() {
            return Some(outcome);
        }
        if self.waiters[slot].is_none() {
            // Nothing to wait for any more (e.g. its object's partition restarted).
            return Some(Err(ErrorReturnCode::TimedOut));
        }
        if expired {
            self.waiters[slot] = None;
            return Some(Err(ErrorReturnCode::TimedOut));
        }
        None
    }

    /// STOP of `slot` (or its thread's end): it leaves every queue and gives up its mutex
    /// (handed to the next waiter) and the preemption lock (lock level 0).
    pub fn forget(&mut self, slot: usize) {
        if slot >= SLOTS {
            return;
        }
        self.waiters[slot] = None;
        self.done[slot] = None;
        self.priorities[slot] = None;
        if let Some(m) = self.owned_by(slot) {
            self.hand_over(m);
        }
        if self.preemption.is_some_and(|l| l.owner == slot) {
            self.preemption = None;
        }
    }

    // ------------------------------------------------------------ storage

    fn carve(&mut self, bytes: usize) -> Result<usize> {
        let start = self.pool_used;
        if bytes > POOL_SIZE - start {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        self.pool_used += bytes;
        Ok(start)
    }

    fn size_param(size: MessageSize) -> Result<usize> {
        let size = size as usize;
        if size == 0 || size > MAX_MESSAGE_SIZE {
            return Err(ErrorReturnCode::InvalidParam);
        }
        Ok(size)
    }

    /// Hands `message` to the waiting `slot` (its mailbox) and ends its wait.
    fn deliver(&mut self, slot: usize, message: &[u8]) {
        self.mail[slot][..message.len()].copy_from_slice(message);
        self.mail_len[slot] = message.len();
        self.wake(slot, Ok(message.len()));
    }

    // ------------------------------------------------------------ buffers (3.7.2.1)

    pub fn create_buffer(
        &mut self,
        normal: bool,
        name: ApexName,
        max_message_size: MessageSize,
        max_nb_message: MessageRange,
        discipline: QueuingDiscipline,
    ) -> Result<BufferId> {
        let index = free_index(&self.buffers, normal, &name)?;
        let max_size = Self::size_param(max_message_size)?;
        let capacity = max_nb_message as usize;
        if capacity == 0 || capacity > MAX_BUFFER_MESSAGES {
            return Err(ErrorReturnCode::InvalidParam);
        }
        let start = self.carve(capacity * (2 + max_size))?;
        self.buffers[index] = Some(Buffer {
            name,
            max_size,
            capacity,
            discipline,
            start,
            head: 0,
            count: 0,
        });
        Ok(Buffer::BASE + index as i64)
    }

    fn push_message(&mut self, index: usize, message: &[u8]) {
        let buffer = self.buffers[index].as_mut().expect("exists");
        let at = buffer.slot_offset(buffer.count);
        buffer.count += 1;
        let length = message.len();
        self.pool[at..at + 2].copy_from_slice(&(length as u16).to_le_bytes());
        self.pool[at + 2..at + 2 + length].copy_from_slice(message);
    }

    /// SEND_BUFFER. A waiting sender's message waits in its mailbox.
    pub fn send_buffer(
        &mut self,
        caller: Caller,
        id: BufferId,
        message: &[u8],
        time_out: ApexSystemTime,
    ) -> Result<Step<()>> {
        let (index, buffer) = by_id(&self.buffers, id)?;
        if message.is_empty() || message.len() > buffer.max_size {
            return Err(ErrorReturnCode::InvalidParam);
        }
        if buffer.count == buffer.capacity {
            return self.wait_on(caller, On::BufferSend(index), time_out, message);
        }
        // Not full: a waiting receiver (the buffer is empty then) gets it directly.
        match self.next(On::BufferReceive(index), buffer.discipline) {
            Some(receiver) => self.deliver(receiver, message),
            None => self.push_message(index, message),
        }
        Ok(Step::Done(()))
    }

    /// RECEIVE_BUFFER into `out` (at least the buffer's MAX_MESSAGE_SIZE long, else
    /// INVALID_PARAM: no message is ever cut); Ok(length). A waiting receiver's message is
    /// in its mailbox when its wait ends.
    pub fn receive_buffer(
        &mut self,
        caller: Caller,
        id: BufferId,
        time_out: ApexSystemTime,
        out: &mut [u8],
    ) -> Result<Step<usize>> {
        let (index, buffer) = by_id(&self.buffers, id)?;
        if out.len() < buffer.max_size {
            return Err(ErrorReturnCode::InvalidParam);
        }
        if buffer.count == 0 {
            return self.wait_on(caller, On::BufferReceive(index), time_out, &[]);
        }
        let at = buffer.slot_offset(0);
        let length = usize::from(u16::from_le_bytes([self.pool[at], self.pool[at + 1]]));
        out[..length].copy_from_slice(&self.pool[at + 2..at + 2 + length]);
        {
            let b = self.buffers[index].as_mut().expect("exists");
            b.head = (b.head + 1) % b.capacity;
            b.count -= 1;
        }
        // Room now: the next waiting sender's message goes in.
        if let Some(sender) = self.next(On::BufferSend(index), buffer.discipline) {
            let mut message = [0u8; MAX_MESSAGE_SIZE];
            let n = self.mail_len[sender];
            message[..n].copy_from_slice(&self.mail[sender][..n]);
            self.push_message(index, &message[..n]);
            self.mail_len[sender] = 0;
            self.wake(sender, Ok(0));
        }
        Ok(Step::Done(length))
    }

    pub fn get_buffer_id(&self, name: &ApexName) -> Result<BufferId> {
        id_by_name(&self.buffers, name)
    }

    pub fn get_buffer_status(&self, id: BufferId) -> Result<BufferStatus> {
        let (index, b) = by_id(&self.buffers, id)?;
        Ok(BufferStatus {
            nb_message: b.count as MessageRange,
            max_nb_message: b.capacity as MessageRange,
            max_message_size: b.max_size as MessageSize,
            waiting_processes: self
                .count_waiting(|on| on == On::BufferSend(index) || on == On::BufferReceive(index)),
        })
    }

    // ------------------------------------------------------------ blackboards (3.7.2.2)

    pub fn create_blackboard(
        &mut self,
        normal: bool,
        name: ApexName,
        max_message_size: MessageSize,
    ) -> Result<BlackboardId> {
        let index = free_index(&self.blackboards, normal, &name)?;
        let max_size = Self::size_param(max_message_size)?;
        let start = self.carve(max_size)?;
        self.blackboards[index] = Some(Blackboard {
            name,
            max_size,
            start,
            message: None,
        });
        Ok(Blackboard::BASE + index as i64)
    }

    /// DISPLAY_BLACKBOARD: every waiting reader gets the message.
    pub fn display_blackboard(&mut self, id: BlackboardId, message: &[u8]) -> Result<()> {
        let (index, b) = by_id(&self.blackboards, id)?;
        if message.is_empty() || message.len() > b.max_size {
            return Err(ErrorReturnCode::InvalidParam);
        }
        self.pool[b.start..b.start + message.len()].copy_from_slice(message);
        if let Some(b) = self.blackboards[index].as_mut() {
            b.message = Some(message.len());
        }
        for slot in 0..SLOTS {
            if self.waiters[slot].is_some_and(|w| w.on == On::Blackboard(index)) {
                self.deliver(slot, message);
            }
        }
        Ok(())
    }

    /// READ_BLACKBOARD into `out` (at least MAX_MESSAGE_SIZE of the blackboard).
    pub fn read_blackboard(
        &mut self,
        caller: Caller,
        id: BlackboardId,
        time_out: ApexSystemTime,
        out: &mut [u8],
    ) -> Result<Step<usize>> {
        let (index, b) = by_id(&self.blackboards, id)?;
        if out.len() < b.max_size {
            return Err(ErrorReturnCode::InvalidParam);
        }
        let Some(length) = b.message else {
            return self.wait_on(caller, On::Blackboard(index), time_out, &[]);
        };
        out[..length].copy_from_slice(&self.pool[b.start..b.start + length]);
        Ok(Step::Done(length))
    }

    pub fn clear_blackboard(&mut self, id: BlackboardId) -> Result<()> {
        let (index, _) = by_id(&self.blackboards, id)?;
        if let Some(b) = self.blackboards[index].as_mut() {
            b.message = None;
        }
        Ok(())
    }

    pub fn get_blackboard_id(&self, name: &ApexName) -> Result<BlackboardId> {
        id_by_name(&self.blackboards, name)
    }

    pub fn get_blackboard_status(&self, id: BlackboardId) -> Result<BlackboardStatus> {
        let (index, b) = by_id(&self.blackboards, id)?;
        Ok(BlackboardStatus {
            empty_indicator: if b.message.is_some() {
                EmptyIndicator::Occupied
            } else {
                EmptyIndicator::Empty
            },
            max_message_size: b.max_size as MessageSize,
            waiting_processes: self.count_waiting(|on| on == On::Blackboard(index)),
        })
    }

    // ------------------------------------------------------------ semaphores (3.7.2.3)

    pub fn create_semaphore(
        &mut self,
        normal: bool,
        name: ApexName,
        current_value: SemaphoreValue,
        maximum_value: SemaphoreValue,
        discipline: QueuingDiscipline,
    ) -> Result<SemaphoreId> {
        let index = free_index(&self.semaphores, normal, &name)?;
        if !(0..=MAX_SEMAPHORE_VALUE).contains(&maximum_value)
            || !(0..=maximum_value).contains(&current_value)
        {
            return Err(ErrorReturnCode::InvalidParam);
        }
        self.semaphores[index] = Some(Semaphore {
            name,
            value: current_value,
            max: maximum_value,
            discipline,
        });
        Ok(Semaphore::BASE + index as i64)
    }

    pub fn wait_semaphore(
        &mut self,
        caller: Caller,
        id: SemaphoreId,
        time_out: ApexSystemTime,
    ) -> Result<Step<()>> {
        let (index, s) = by_id(&self.semaphores, id)?;
        if s.value == 0 {
            return self.wait_on(caller, On::Semaphore(index), time_out, &[]);
        }
        if let Some(s) = self.semaphores[index].as_mut() {
            s.value -= 1;
        }
        Ok(Step::Done(()))
    }

    /// SIGNAL_SEMAPHORE: a waiter takes the unit, else the value goes up (NO_ACTION at its
    /// maximum).
    pub fn signal_semaphore(&mut self, id: SemaphoreId) -> Result<()> {
        let (index, s) = by_id(&self.semaphores, id)?;
        if let Some(waiter) = self.next(On::Semaphore(index), s.discipline) {
            self.wake(waiter, Ok(0));
            return Ok(());
        }
        if s.value >= s.max {
            return Err(ErrorReturnCode::NoAction);
        }
        if let Some(s) = self.semaphores[index].as_mut() {
            s.value += 1;
        }
        Ok(())
    }

    pub fn get_semaphore_id(&self, name: &ApexName) -> Result<SemaphoreId> {
        id_by_name(&self.semaphores, name)
    }

    pub fn get_semaphore_status(&self, id: SemaphoreId) -> Result<SemaphoreStatus> {
        let (index, s) = by_id(&self.semaphores, id)?;
        Ok(SemaphoreStatus {
            current_value: s.value,
            maximum_value: s.max,
            waiting_processes: self.count_waiting(|on| on == On::Semaphore(index)),
        })
    }

    // ------------------------------------------------------------ events (3.7.2.4)

    pub fn create_event(&mut self, normal: bool, name: ApexName) -> Result<EventId> {
        let index = free_index(&self.events, normal, &name)?;
        self.events[index] = Some(Event { name, up: false });
        Ok(Event::BASE + index as i64)
    }

    /// SET_EVENT: UP, and every waiter goes on.
    pub fn set_event(&mut self, id: EventId) -> Result<()> {
        let (index, _) = by_id(&self.events, id)?;
        if let Some(e) = self.events[index].as_mut() {
            e.up = true;
        }
        for slot in 0..SLOTS {
            if self.waiters[slot].is_some_and(|w| w.on == On::Event(index)) {
                self.wake(slot, Ok(0));
            }
        }
        Ok(())
    }

    pub fn reset_event(&mut self, id: EventId) -> Result<()> {
        let (index, _) = by_id(&self.events, id)?;
        if let Some(e) = self.events[index].as_mut() {
            e.up = false;
        }
        Ok(())
    }

    pub fn wait_event(
        &mut self,
        caller: Caller,
        id: EventId,
        time_out: ApexSystemTime,
    ) -> Result<Step<()>> {
        let (index, e) = by_id(&self.events, id)?;
        if e.up {
            return Ok(Step::Done(()));
        }
        self.wait_on(caller, On::Event(index), time_out, &[])
    }

    pub fn get_event_id(&self, name: &ApexName) -> Result<EventId> {
        id_by_name(&self.events, name)
    }

    pub fn get_event_status(&self, id: EventId) -> Result<EventStatus> {
        let (index, e) = by_id(&self.events, id)?;
        Ok(EventStatus {
            event_state: if e.up {
                EventState::Up
            } else {
                EventState::Down
            },
            waiting_processes: self.count_waiting(|on| on == On::Event(index)),
        })
    }

    // ------------------------------------------------------------ mutexes (Supplement 5)

    /// CREATE_MUTEX: `mcp` is the partition's top priority, which processes never reach
    /// (a ceiling at or above it is INVALID_CONFIG).
    pub fn create_mutex(
        &mut self,
        normal: bool,
        mcp: u8,
        name: ApexName,
        priority: Priority,
        discipline: QueuingDiscipline,
    ) -> Result<MutexId> {
        let index = free_index(&self.mutexes, normal, &name)?;
        if !(MIN_PRIORITY_VALUE..=MAX_PRIORITY_VALUE).contains(&priority) {
            return Err(ErrorReturnCode::InvalidParam);
        }
        if priority >= i32::from(mcp) {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        self.mutexes[index] = Some(Mutex {
            name,
            priority: priority as u8,
            discipline,
            owner: None,
            lock_count: 0,
            retained: 0,
        });
        Ok(Mutex::BASE + index as i64)
    }

    /// The mutex `slot` owns.
    fn owned_by(&self, slot: usize) -> Option<usize> {
        self.mutexes
            .iter()
            .position(|m| m.is_some_and(|m| m.owner == Some(slot)))
    }

    fn take_mutex(&mut self, index: usize, slot: usize, priority: u8) {
        let m = self.mutexes[index].as_mut().expect("exists");
        m.owner = Some(slot);
        m.lock_count = 1;
        m.retained = priority;
        self.priorities[slot] = Some(m.priority);
    }

    /// The mutex is free: the next waiter owns it (or nobody). The old owner gets its
    /// retained priority back.
    fn hand_over(&mut self, index: usize) {
        let m = self.mutexes[index].expect("exists");
        if let Some(owner) = m.owner {
            self.priorities[owner] = Some(m.retained);
        }
        let m = self.mutexes[index].as_mut().expect("exists");
        m.owner = None;
        m.lock_count = 0;
        let discipline = m.discipline;
        if let Some(next) = self.next(On::Mutex(index), discipline) {
            let priority = self.waiters[next].map_or(0, |w| w.priority);
            self.take_mutex(index, next, priority);
            self.wake(next, Ok(0));
        }
    }

    pub fn acquire_mutex(
        &mut self,
        caller: Caller,
        id: MutexId,
        time_out: ApexSystemTime,
    ) -> Result<Step<()>> {
        let (index, m) = by_id(&self.mutexes, id)?;
        let slot = caller
            .slot
            .filter(|&s| s != ERROR_HANDLER_SLOT)
            .ok_or(ErrorReturnCode::InvalidMode)?;
        if self.owned_by(slot).is_some_and(|owned| owned != index) || self.holds_lock(slot) {
            return Err(ErrorReturnCode::InvalidMode);
        }
        if m.owner == Some(slot) {
            if m.lock_count >= MAX_LOCK_LEVEL {
                return Err(ErrorReturnCode::InvalidConfig);
            }
            if let Some(m) = self.mutexes[index].as_mut() {
                m.lock_count += 1;
            }
            return Ok(Step::Done(()));
        }
        if caller.priority > m.priority {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        if m.owner.is_some() {
            return self.wait_on(caller, On::Mutex(index), time_out, &[]);
        }
        self.take_mutex(index, slot, caller.priority);
        Ok(Step::Done(()))
    }

    pub fn release_mutex(&mut self, caller: Caller, id: MutexId) -> Result<()> {
        let (index, m) = by_id(&self.mutexes, id)?;
        if caller.slot.is_none() || m.owner != caller.slot {
            return Err(ErrorReturnCode::InvalidMode);
        }
        if m.lock_count > 1 {
            if let Some(m) = self.mutexes[index].as_mut() {
                m.lock_count -= 1;
            }
            return Ok(());
        }
        self.hand_over(index);
        Ok(())
    }

    /// RESET_MUTEX: `process` (a slot the caller checked exists) loses the mutex whatever
    /// its lock count.
    pub fn reset_mutex(&mut self, id: MutexId, process: usize) -> Result<()> {
        let (index, m) = by_id(&self.mutexes, id)?;
        if m.owner != Some(process) {
            return Err(ErrorReturnCode::InvalidMode);
        }
        self.hand_over(index);
        Ok(())
    }

    pub fn get_mutex_id(&self, name: &ApexName) -> Result<MutexId> {
        id_by_name(&self.mutexes, name)
    }

    pub fn get_mutex_status(&self, id: MutexId) -> Result<MutexStatus> {
        let (index, m) = by_id(&self.mutexes, id)?;
        Ok(MutexStatus {
            mutex_owner: m.owner.map_or(NULL_PROCESS_ID, id_of),
            mutex_state: if m.owner.is_some() {
                MutexState::Owned
            } else {
                MutexState::Available
            },
            mutex_priority: Priority::from(m.priority),
            lock_count: m.lock_count,
            waiting_processes: self.count_waiting(|on| on == On::Mutex(index)),
        })
    }

    /// GET_PROCESS_MUTEX_STATE of `slot` (a process the caller checked exists).
    pub fn process_mutex_state(&self, slot: usize) -> MutexId {
        if self.holds_lock(slot) {
            return PREEMPTION_LOCK_MUTEX;
        }
        self.owned_by(slot)
            .map_or(NO_MUTEX_OWNED, |i| Mutex::BASE + i as i64)
    }

    /// SET_PRIORITY of a mutex owner (or of the preemption lock's) changes only the
    /// priority it gets back on release. Returns whether `slot` owns one (then its current
    /// priority stays).
    pub fn set_retained_priority(&mut self, slot: usize, priority: u8) -> bool {
        if let Some(lock) = self.preemption.as_mut().filter(|l| l.owner == slot) {
            lock.retained = priority;
            return true;
        }
        match self.owned_by(slot) {
            Some(index) => {
                if let Some(m) = self.mutexes[index].as_mut() {
                    m.retained = priority;
                }
                true
            }
            None => false,
        }
    }

    // ------------------------------------------------------------ preemption (3.3.2.7-8)

    /// Whether `slot` holds the preemption lock (lock level above 0).
    pub fn holds_lock(&self, slot: usize) -> bool {
        self.preemption.is_some_and(|l| l.owner == slot)
    }

    /// Whether `slot` owns a mutex or the preemption lock. ARINC 653 (Supplement 5) lets
    /// such a process not wait: its TIMED_WAIT, PERIODIC_WAIT, SUSPEND_SELF and its waits
    /// with a time-out on objects and ports are INVALID_MODE, and so is a SUSPEND of it.
    pub fn owns_a_mutex(&self, slot: usize) -> bool {
        self.holds_lock(slot) || self.owned_by(slot).is_some()
    }

    /// The partition's lock level (GET_PARTITION_STATUS).
    pub fn lock_level(&self) -> LockLevel {
        self.preemption.map_or(0, |l| l.level)
    }

    /// The priority the preemption lock's owner runs at: the MCP, which no process reaches
    /// (at MCP - 1 a process of that priority would overtake it after each critical
    /// section of the runtime, which requeues the caller at the tail of its level).
    pub fn lock_priority(mcp: u8) -> u8 {
        mcp
    }

    /// LOCK_PREEMPTION: the new lock level. NO_ACTION outside NORMAL mode and for the error
    /// handler (or the initialisation thread); INVALID_CONFIG at MAX_LOCK_LEVEL; INVALID_MODE
    /// for an owner of another mutex (a process owns one mutex at a time).
    pub fn lock_preemption(&mut self, caller: Caller, normal: bool, mcp: u8) -> Result<LockLevel> {
        let slot = caller
            .slot
            .filter(|&s| normal && s != ERROR_HANDLER_SLOT)
            .ok_or(ErrorReturnCode::NoAction)?;
        match self.preemption.as_mut() {
            Some(lock) if lock.owner == slot => {
                if lock.level >= MAX_LOCK_LEVEL {
                    return Err(ErrorReturnCode::InvalidConfig);
                }
                lock.level += 1;
                Ok(lock.level)
            }
            // Another process holds it: only possible while that one is stopped by the
            // error handler's SUSPEND; the lock is not shared.
            Some(_) => Err(ErrorReturnCode::InvalidMode),
            None => {
                if self.owned_by(slot).is_some() {
                    return Err(ErrorReturnCode::InvalidMode);
                }
                self.preemption = Some(PreemptionLock {
                    owner: slot,
                    level: 1,
                    retained: caller.priority,
                });
                self.priorities[slot] = Some(Self::lock_priority(mcp));
                Ok(1)
            }
        }
    }

    /// UNLOCK_PREEMPTION: the new lock level; at 0 the owner gets its retained priority back
    /// (and other processes may run again). NO_ACTION outside NORMAL mode, for the error
    /// handler, and for a caller that does not hold the lock (level 0).
    pub fn unlock_preemption(&mut self, caller: Caller, normal: bool) -> Result<LockLevel> {
        let slot = caller
            .slot
            .filter(|&s| normal && s != ERROR_HANDLER_SLOT && self.holds_lock(s))
            .ok_or(ErrorReturnCode::NoAction)?;
        let lock = self.preemption.as_mut().expect("held");
        lock.level -= 1;
        let level = lock.level;
        if level == 0 {
            self.priorities[slot] = Some(lock.retained);
            self.preemption = None;
        }
        Ok(level)
    }
}

#[cfg(test)]
mod tests;
