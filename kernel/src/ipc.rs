//! Synchronous IPC (send, receive, call, reply), notifications and exception messages.
//!
//! A message travels directly from the sender's registers and IPC buffer to the receiver's
//! (no kernel buffer, no allocation). Every transfer is checked completely before anything
//! changes, and a failure is blamed on one side: a sender-side problem fails the send and
//! leaves the receiver waiting; a receiver-side problem fails the receive and leaves the
//! sender queued.

use crate::mem::PAGE_SIZE;
use crate::mem::paging::is_user_range;
use crate::state::{Kernel, MAX_THREADS};
use crate::syscall::Outcome;
use crate::table::ThreadIdx;
use crate::thread::{Fault, NEVER, State};
use abi::args::results;
use abi::ipc::{
    EXCEPTION_MESSAGE_SIZE, EXCEPTION_MESSAGE_WORDS, ExceptionMessage, IPC_ITEMS_OFFSET,
    IPC_MAX_ITEMS, IPC_WINDOW_OFFSET, LABEL_FAULT_REPORT, MAP_ITEM_GRANT, MapItem, MessageTag,
    REPLY_KILL, REPLY_RESUME, ReceiveWindow,
};
use abi::syscall::{Error, MAP_MAX_PAGES, PageRights, TIMEOUT_INFINITE, ThreadId};

/// Which side of a transfer could not take part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Blame {
    Sender(Error),
    Receiver(Error),
}

/// Absolute deadline of a timeout starting now (0 = poll, handled by the callers). The
/// clock is only read for finite timeouts.
pub fn deadline(clock: fn() -> u64, timeout: u64) -> u64 {
    if timeout == TIMEOUT_INFINITE {
        NEVER
    } else {
        clock().saturating_add(timeout)
    }
}

fn read_struct<const N: usize>(k: &Kernel, t: ThreadIdx, at: u64) -> Option<[u8; N]> {
    let mut out = [0u8; N];
    let th = &k.threads[t];
    (th.ipc_buffer() != 0 && k.tasks[th.task()].space().copy_from_user(at, &mut out)).then_some(out)
}

impl Kernel {
    /// The exception message for thread `t` as its words (`ExceptionMessage::words`).
    pub fn exception_words(&self, t: ThreadIdx, fault: Fault) -> [u64; EXCEPTION_MESSAGE_WORDS] {
        let th = &self.threads[t];
        let (c, (fs, gs)) = (th.context(), th.bases());
        let (thread, task) = (self.thread_id(t).0, self.task_id(th.task()).0);
        let (vector, error, address) = (fault.vector, fault.error_code, fault.address);
        [
            vector, error, address, thread, task, c.rax, c.rbx, c.rcx, c.rdx, c.rsi, c.rdi, c.rbp,
            c.rsp, c.r8, c.r9, c.r10, c.r11, c.r12, c.r13, c.r14, c.r15, c.rip, c.rflags, fs, gs,
        ]
    }

    /// Moves the message of `from` (its registers, or its fault) to `to`.
    pub fn deliver(&mut self, from: ThreadIdx, to: ThreadIdx) -> Result<(), Blame> {
        let (tag, words);
        if let Some(fault) = self.threads[from].fault() {
            let message = self.exception_words(from, fault);
            let (buffer, receiver_task) = (self.threads[to].ipc_buffer(), self.threads[to].task());
            if buffer == 0
                || self.tasks[receiver_task]
                    .space()
                    .words(buffer, Some(&message))
                    .is_none()
            {
                return Err(Blame::Receiver(Error::BadAddress));
            }
            tag = MessageTag::new(fault.label, EXCEPTION_MESSAGE_SIZE, 0);
            words = [fault.vector, fault.error_code, fault.address];
        } else {
            let c = self.threads[from].context();
            tag = MessageTag(c.rdx);
            words = [c.r10, c.r8, c.r9];
            if !tag.is_valid() {
                return Err(Blame::Sender(Error::InvalidArgument));
            }
            self.transfer_payload(from, to, tag)?;
        }
        self.hand_over(from, to, tag, words);
        Ok(())
    }

    /// Puts the sender, the tag and the three words of a message in `to`'s result registers.
    fn hand_over(&mut self, from: ThreadIdx, to: ThreadIdx, tag: MessageTag, words: [u64; 3]) {
        let received = results::Ipc {
            sender: self.thread_id(from),
            sender_task: self.task_id(self.threads[from].task()),
            tag: tag.0,
            word0: words[0],
            word1: words[1],
            word2: words[2],
        };
        self.threads[to].set_results(|r| received.encode_into(r));
    }

    /// The fast path of a client and its server: `call` (`reply_wait` if not `call`) with a
    /// register-only message and no time-out, to a peer that already waits for it. It makes
    /// the general path's transitions ([`Kernel::send`]; [`Kernel::reply`], then
    /// [`Kernel::receive`]) with only the checks this case needs. `None`, with nothing
    /// changed, whenever the general path has more to decide: an error to report, a
    /// receiver not yet waiting, a fault to answer, queued senders, a time-out to arm.
    ///
    /// A call to a server of higher priority in the caller's time partition (or the
    /// background) switches to it directly: the caller was the scheduler's choice, so every
    /// other eligible thread is below the server, which the scheduler would choose too.
    pub fn fast_ipc(&mut self, t: ThreadIdx, call: bool) -> Option<Outcome> {
        let c = self.threads[t].context();
        let (peer, tag, timeout) = (ThreadId(c.rdi), MessageTag(c.rdx), c.rsi);
        let words = [c.r10, c.r8, c.r9];
        if !tag.is_registers_only() || timeout != TIMEOUT_INFINITE {
            return None;
        }
        let peer = self.thread(peer.named()?).ok()?;
        let (me, them) = (&self.threads[t], &self.threads[peer]);
        let (next, outcome) = if call {
            let waiting = matches!(them.state(),
                State::Receiving { from } if from.is_none_or(|f| f == t));
            if !waiting || !self.may_send(me.task(), them.task()) {
                return None;
            }
            self.follow(peer, t);
            let (me, them) = (&self.threads[t], &self.threads[peer]);
            let direct = them.priority() > me.priority()
                && them.cpu() == me.cpu()
                && (them.time_partition() == me.time_partition() || them.time_partition() == 0);
            let outcome = if direct {
                Outcome::SwitchTo(peer)
            } else {
                Outcome::Continue
            };
            (State::WaitingReply { from: peer }, outcome)
        } else {
            if them.state() != (State::WaitingReply { from: t })
                || them.fault().is_some()
                || self.first_sender(t, None).is_some()
            {
                return None;
            }
            (State::Receiving { from: None }, Outcome::Continue)
        };
        self.hand_over(t, peer, tag, words);
        self.wake(peer, Error::Ok);
        self.block(t, next, NEVER);
        Some(outcome)
    }

    /// Copies the data bytes and maps the items of a message, all checks first.
    fn transfer_payload(
        &mut self,
        from: ThreadIdx,
        to: ThreadIdx,
        tag: MessageTag,
    ) -> Result<(), Blame> {
        let (s, r) = (&self.threads[from], &self.threads[to]);
        let (s_space, r_space) = (*self.tasks[s.task()].space(), *self.tasks[r.task()].space());
        let (s_buf, r_buf) = (s.ipc_buffer(), r.ipc_buffer());
        if tag.is_empty() && tag.items() == 0 {
            return Ok(());
        }
        if s_buf == 0 || !s_space.accessible(s_buf, tag.len(), false) {
            return Err(Blame::Sender(Error::BadAddress));
        }
        if r_buf == 0 || !r_space.accessible(r_buf, tag.len(), true) {
            return Err(Blame::Receiver(Error::BadAddress));
        }
        // Map items: read and check them all.
        let mut items = [MapItem::default(); IPC_MAX_ITEMS];
        let mut total = 0u64;
        if tag.items() > 0 {
            let raw: [u8; 16 * IPC_MAX_ITEMS] =
                read_struct(self, from, s_buf + IPC_ITEMS_OFFSET as u64)
                    .ok_or(Blame::Sender(Error::BadAddress))?;
            let window: [u8; 16] = read_struct(self, to, r_buf + IPC_WINDOW_OFFSET as u64)
                .ok_or(Blame::Receiver(Error::BadAddress))?;
            let window = ReceiveWindow {
                base: u64::from_ne_bytes(window[0..8].try_into().unwrap()),
                pages: u64::from_ne_bytes(window[8..16].try_into().unwrap()),
            };
            for (i, item) in items.iter_mut().take(tag.items()).enumerate() {
                *item = MapItem::from_bytes(raw[i * 16..i * 16 + 16].try_into().unwrap());
                let rights_bits = (item.flags & !MAP_ITEM_GRANT) as u64;
                if item.pages == 0
                    || !is_user_range(item.source, item.pages as u64)
                    || PageRights::from_bits(rights_bits).is_none()
                {
                    return Err(Blame::Sender(Error::InvalidArgument));
                }
                total += item.pages as u64;
            }
            if total > MAP_MAX_PAGES
                || total > window.pages
                || !is_user_range(window.base, window.pages.max(1))
            {
                return Err(Blame::Sender(Error::InvalidArgument));
            }
            for item in &items[..tag.items()] {
                let rights = PageRights::from_bits_truncate(item.flags as u64);
                for p in 0..item.pages as u64 {
                    match s_space.translate(item.source + p * PAGE_SIZE) {
                        Some((_, have)) if have.contains(rights) => {}
                        _ => return Err(Blame::Sender(Error::BadAddress)),
                    }
                }
            }
            self.charge_tables(r.task(), window.base, total)
                .map_err(Blame::Sender)?;
            // Commit the mappings.
            let (s_task, r_task) = (self.threads[from].task(), self.threads[to].task());
            let mut dest = window.base;
            for item in &items[..tag.items()] {
                let rights = PageRights::from_bits_truncate(item.flags as u64);
                for p in 0..item.pages as u64 {
                    let src = item.source + p * PAGE_SIZE;
                    let (frame, _) = self.tasks[s_task].space().translate(src).expect("checked");
                    self.tasks[r_task]
                        .map_page(dest, frame, rights)
                        .expect("checked and charged");
                    if item.flags & MAP_ITEM_GRANT != 0 {
                        self.tasks[s_task].unmap_page(src);
                    }
                    dest += PAGE_SIZE;
                }
            }
        }
        let copied = s_space.copy_to_space(s_buf, &r_space, r_buf, tag.len());
        debug_assert!(copied, "checked above");
        Ok(())
    }

    /// `send`/`call` from thread `t` to `dest` (rights already checked), or an exception
    /// message if `t` has a fault pending.
    pub fn send(&mut self, t: ThreadIdx, dest: ThreadIdx, call: bool, deadline: u64, poll: bool) {
        if let State::Receiving { from } = self.threads[dest].state()
            && from.is_none_or(|f| f == t)
        {
            match self.deliver(t, dest) {
                Ok(()) => {
                    self.follow(dest, t);
                    self.wake(dest, Error::Ok);
                    self.after_delivery(t, dest, call, deadline);
                    return;
                }
                Err(Blame::Sender(e)) => {
                    self.threads[t].set_status(e);
                    return;
                }
                Err(Blame::Receiver(e)) => self.wake(dest, e),
            }
        }
        if poll {
            self.threads[t].set_status(Error::TimedOut);
            return;
        }
        self.block(t, State::Sending { to: dest, call }, deadline);
        self.enqueue_sender(dest, t);
    }

    /// The sender's side once its message arrived: a call now waits for the reply.
    fn after_delivery(
        &mut self,
        sender: ThreadIdx,
        receiver: ThreadIdx,
        call: bool,
        deadline: u64,
    ) {
        if call {
            self.block(sender, State::WaitingReply { from: receiver }, deadline);
        } else {
            self.wake(sender, Error::Ok);
        }
    }

    /// `receive` by thread `t` (from `from` only, if given).
    pub fn receive(&mut self, t: ThreadIdx, from: Option<ThreadIdx>, deadline: u64, poll: bool) {
        // Bounded: each failed sender leaves the queue.
        for _ in 0..MAX_THREADS {
            let Some(s) = self.first_sender(t, from) else {
                break;
            };
            match self.deliver(s, t) {
                Ok(()) => {
                    self.unqueue_sender(t, s);
                    self.follow(t, s);
                    let call = matches!(self.threads[s].state(), State::Sending { call: true, .. });
                    let s_deadline = self.threads[s].deadline();
                    self.after_delivery(s, t, call, s_deadline);
                    self.threads[t].set_status(Error::Ok);
                    return;
                }
                Err(Blame::Sender(e)) => {
                    self.unqueue_sender(t, s);
                    self.wake(s, e);
                }
                Err(Blame::Receiver(e)) => {
                    self.threads[t].set_status(e);
                    return;
                }
            }
        }
        if poll {
            self.threads[t].set_status(Error::TimedOut);
            return;
        }
        self.block(t, State::Receiving { from }, deadline);
    }

    /// `reply` from thread `t` to `caller`. On success `t`'s `rax` is `Ok`.
    pub fn reply(&mut self, t: ThreadIdx, caller: ThreadIdx) -> Result<(), Error> {
        if self.threads[caller].state() != (State::WaitingReply { from: t }) {
            return Err(Error::NotWaiting);
        }
        if self.threads[caller].fault().is_some() {
            return self.answer_fault(t, caller);
        }
        match self.deliver(t, caller) {
            Ok(()) => self.wake(caller, Error::Ok),
            Err(Blame::Sender(e)) => return Err(e),
            Err(Blame::Receiver(e)) => self.wake(caller, e),
        }
        Ok(())
    }

    /// The handler `t` answers the exception message of `faulted`: resume (with the
    /// registers of the reply, if it carries them) or kill.
    fn answer_fault(&mut self, t: ThreadIdx, faulted: ThreadIdx) -> Result<(), Error> {
        let tag = MessageTag(self.threads[t].context().rdx);
        match tag.label() {
            REPLY_KILL => {
                self.kill_thread(faulted);
                Ok(())
            }
            REPLY_RESUME => {
                if tag.len() >= EXCEPTION_MESSAGE_SIZE {
                    let (buffer, task) = (self.threads[t].ipc_buffer(), self.threads[t].task());
                    let space = self.tasks[task].space();
                    let words = space.words(buffer, None).filter(|_| buffer != 0);
                    let m = ExceptionMessage::from_words(&words.ok_or(Error::BadAddress)?);
                    self.threads[faulted].load_registers(&m.registers)?;
                }
                self.resume(faulted);
                Ok(())
            }
            _ => Err(Error::InvalidArgument),
        }
    }

    /// A fault of thread `t`: blocks it on an exception message to its handler, or to the
    /// health monitor. `false` if there is neither (the caller decides what then).
    pub fn raise_fault(&mut self, t: ThreadIdx, mut fault: Fault) -> bool {
        let handler = match self.thread(self.threads[t].exception_handler()) {
            Ok(h) if h != t => h,
            _ => match self.thread(self.health_monitor) {
                Ok(h) if h != t => {
                    fault.label = LABEL_FAULT_REPORT;
                    h
                }
                _ => return false,
            },
        };
        self.threads[t].set_fault(fault);
        self.send(t, handler, true, NEVER, false);
        true
    }

    /// `notify_signal` (rights already checked).
    pub fn signal(&mut self, target: ThreadIdx, bits: u64) {
        let th = &mut self.threads[target];
        th.add_notify_bits(bits);
        if let State::WaitingNotify { mask } = th.state() {
            let bits = th.take_notify_bits(mask);
            if bits != 0 {
                th.set_results(|r| results::NotifyWait { bits }.encode_into(r));
                self.wake(target, Error::Ok);
            }
        }
    }

    /// `notify_wait` by thread `t`.
    pub fn wait_notify(&mut self, t: ThreadIdx, mask: u64, deadline: u64, poll: bool) {
        let th = &mut self.threads[t];
        let got = th.take_notify_bits(mask);
        if got != 0 {
            th.set_results(|r| results::NotifyWait { bits: got }.encode_into(r));
            th.set_status(Error::Ok);
        } else if poll {
            th.set_status(Error::TimedOut);
        } else {
            self.block(t, State::WaitingNotify { mask }, deadline);
        }
    }
}
