//! Thread control blocks.

use crate::arch::idt::TrapFrame;
use crate::rp::Amount;
use crate::sched::TIME_PARTITIONS;
use crate::state::{Kernel, USER_CS, USER_RFLAGS, USER_SS, slot_of};
use crate::table::{Slot, TaskIdx, ThreadIdx};
use abi::args::ArgRegs;
use abi::syscall::{Error, ThreadId, USER_END, make_id};

/// No thread (end of an intrusive list).
pub const NIL: u16 = u16::MAX;
/// No deadline.
pub const NEVER: u64 = u64::MAX;

/// What a thread is doing. Only `Ready` threads that are not suspended are in a run queue.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    Free,
    /// Created, not yet started.
    Inactive,
    Ready,
    /// Queued on `to`'s send queue; a `call` (or an exception) then waits for the reply.
    Sending {
        to: ThreadIdx,
        call: bool,
    },
    WaitingReply {
        from: ThreadIdx,
    },
    Receiving {
        from: Option<ThreadIdx>,
    },
    WaitingNotify {
        mask: u64,
    },
    /// `sleep_until`: ends at the deadline, successfully.
    Sleeping,
}

/// A fault the thread is blocked on (delivered as an exception message).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fault {
    pub label: u32,
    pub vector: u64,
    pub error_code: u64,
    pub address: u64,
}

/// FXSAVE image (x87, MMX, SSE state).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
pub struct FpuState(pub [u8; 512]);

impl FpuState {
    /// The state after FNINIT with all SSE exceptions masked: FCW 0x037f, MXCSR 0x1f80.
    pub const fn initial() -> Self {
        let mut image = [0u8; 512];
        image[0] = 0x7f;
        image[1] = 0x03;
        image[24] = 0x80;
        image[25] = 0x1f;
        Self(image)
    }

    /// `image` with the MXCSR bits FXRSTOR refuses (#GP) cleared, so any 512 bytes from
    /// user space can be loaded: the processor's MXCSR_MASK as FXSAVE recorded it in this
    /// state, or 0xffbf (the architectural default) where it is 0.
    pub fn sanitized(&self, mut image: [u8; 512]) -> Self {
        let word = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let mask = match word(&self.0[28..32]) {
            0 => 0xffbf,
            m => m,
        };
        let mxcsr = word(&image[24..28]) & mask;
        image[24..28].copy_from_slice(&mxcsr.to_le_bytes());
        image[28..32].copy_from_slice(&self.0[28..32]);
        Self(image)
    }
}

#[derive(Clone, Copy)]
pub struct Thread {
    pub state: State,
    pub generation: u16,
    pub task: TaskIdx,
    pub priority: u8,
    pub time_partition: u8,
    pub suspended: bool,
    /// User registers while the thread is not running (the live copy is the entry frame).
    pub context: TrapFrame,
    pub fs_base: u64,
    pub gs_base: u64,
    pub fpu: FpuState,
    /// The exception handler ([`ThreadId::OWN`] = none), resolved at fault time.
    pub exception_handler: ThreadId,
    pub ipc_buffer: u64,
    /// Absolute time (ns since boot) at which a blocking call times out.
    pub deadline: u64,
    pub fault: Option<Fault>,
    /// Head of the queue of threads waiting to send to this one (by priority, then FIFO).
    pub senders: Option<ThreadIdx>,
    /// Link in the send queue this thread waits in.
    pub next_sender: Option<ThreadIdx>,
    pub notify_bits: u64,
}

pub const EMPTY_CONTEXT: TrapFrame = TrapFrame {
    r15: 0,
    r14: 0,
    r13: 0,
    r12: 0,
    r11: 0,
    r10: 0,
    r9: 0,
    r8: 0,
    rbp: 0,
    rdi: 0,
    rsi: 0,
    rdx: 0,
    rcx: 0,
    rbx: 0,
    rax: 0,
    vector: 0,
    error_code: 0,
    rip: 0,
    cs: 0,
    rflags: 0,
    rsp: 0,
    ss: 0,
};

impl Thread {
    pub const FREE: Self = Self {
        state: State::Free,
        generation: 0,
        task: TaskIdx::ROOT,
        priority: 0,
        time_partition: 0,
        suspended: false,
        context: EMPTY_CONTEXT,
        fs_base: 0,
        gs_base: 0,
        fpu: FpuState::initial(),
        exception_handler: ThreadId::OWN,
        ipc_buffer: 0,
        deadline: NEVER,
        fault: None,
        senders: None,
        next_sender: None,
        notify_bits: 0,
    };

    pub fn is_free(&self) -> bool {
        self.state == State::Free
    }

    /// Runnable: ready and not suspended.
    pub fn is_runnable(&self) -> bool {
        self.state == State::Ready && !self.suspended
    }

    /// The argument registers of its system call.
    #[inline(always)]
    pub fn arg_regs(&self) -> ArgRegs {
        let c = &self.context;
        ArgRegs::from_array([c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9])
    }

    /// Writes a call's results into its argument registers: `encode` (an `abi::args::results`
    /// struct's `encode_into`) sets those the results use, the others keep their values.
    #[inline(always)]
    pub fn set_results(&mut self, encode: impl FnOnce(&mut ArgRegs)) {
        let mut regs = self.arg_regs();
        encode(&mut regs);
        let c = &mut self.context;
        [c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9] = regs.to_array();
    }
}

impl Kernel {
    pub fn thread_id(&self, t: ThreadIdx) -> ThreadId {
        ThreadId(make_id(t.position(), self.threads[t].generation))
    }

    pub fn thread(&self, id: ThreadId) -> Result<ThreadIdx, Error> {
        slot_of(&self.threads, id.0, |t| {
            (!t.is_free()).then_some(t.generation)
        })
    }

    /// The thread named by `id` (0 = `caller_thread`), if the caller's task controls it.
    pub fn controlled_thread(
        &self,
        caller_thread: ThreadIdx,
        id: ThreadId,
    ) -> Result<ThreadIdx, Error> {
        let thread = match id.named() {
            None => caller_thread,
            Some(id) => self.thread(id)?,
        };
        let task = self.threads[thread].task;
        if self.tasks[task].dying {
            Err(Error::NoSuchObject)
        } else if self.is_within(task, self.threads[caller_thread].task) {
            Ok(thread)
        } else {
            Err(Error::NotPermitted)
        }
    }

    /// Changes a thread's state and keeps the run queues consistent with it.
    pub fn set_state(&mut self, t: ThreadIdx, state: State) {
        self.threads[t].state = state;
        self.requeue(t);
    }

    fn requeue(&mut self, t: ThreadIdx) {
        let th = &self.threads[t];
        if th.is_runnable() {
            self.run
                .enqueue(t.position(), th.priority, th.time_partition);
        } else {
            self.run.remove(t.position());
        }
    }

    /// Ends a blocking call of `t` with `result` in its `rax` and makes it ready.
    pub fn wake(&mut self, t: ThreadIdx, result: Error) {
        let th = &mut self.threads[t];
        th.context.rax = result as u64;
        th.deadline = NEVER;
        th.fault = None;
        self.set_state(t, State::Ready);
    }

    /// Blocks `t` in `state` until `deadline` (absolute ns; [`NEVER`] for none).
    pub fn block(&mut self, t: ThreadIdx, state: State, deadline: u64) {
        self.threads[t].deadline = deadline;
        if deadline < self.next_deadline {
            self.next_deadline = deadline;
            self.timer_dirty = true;
        }
        self.set_state(t, state);
    }

    /// A new inactive thread of `task` that will start at `entry` with `rsp` = `stack` and
    /// `rdi` = `arg`.
    pub fn create_thread(
        &mut self,
        task: TaskIdx,
        entry: u64,
        stack: u64,
        priority: u8,
        time_partition: u8,
        arg: u64,
    ) -> Result<ThreadIdx, Error> {
        if priority > self.tasks[task].mcp {
            return Err(Error::McpExceeded);
        }
        if entry >= USER_END || stack > USER_END || time_partition as usize >= TIME_PARTITIONS {
            return Err(Error::InvalidArgument);
        }
        let slot = self
            .threads
            .find(|t| t.is_free())
            .ok_or(Error::QuotaExceeded)?;
        self.rps[self.tasks[task].rp].charge(Amount::threads(1))?;
        let generation = self.threads[slot].generation;
        self.threads[slot] = Thread {
            state: State::Inactive,
            generation,
            task,
            priority,
            time_partition,
            context: crate::arch::idt::TrapFrame {
                rip: entry,
                rsp: stack,
                rdi: arg,
                cs: USER_CS,
                ss: USER_SS,
                rflags: USER_RFLAGS,
                ..EMPTY_CONTEXT
            },
            fpu: FpuState::initial(),
            ..Thread::FREE
        };
        Ok(slot)
    }

    /// Destroys a thread: whoever waits on it gets `PeerGone`, its slot is freed and its
    /// quota returned.
    pub fn kill_thread(&mut self, t: ThreadIdx) {
        if self.threads[t].is_free() {
            return;
        }
        // Leave any queue it is in.
        if let State::Sending { to, .. } = self.threads[t].state {
            self.unqueue_sender(to, t);
        }
        self.run.remove(t.position());
        self.release_irqs_of(t);
        let id = self.thread_id(t);
        // Everyone waiting for it: its senders, its callers, receivers waiting on it.
        for other in ThreadIdx::all() {
            if other == t {
                continue;
            }
            let waits_on_t = match self.threads[other].state {
                State::Sending { to, .. } => to == t,
                State::WaitingReply { from } => from == t,
                _ => false,
            };
            if waits_on_t && self.threads[other].fault.is_some() {
                // Its handler is gone: nobody can resolve the fault.
                self.kill_thread(other);
                continue;
            }
            match self.threads[other].state {
                State::Sending { to, .. } if to == t => {
                    self.unqueue_sender(t, other);
                    self.wake(other, Error::PeerGone);
                }
                State::WaitingReply { from } if from == t => self.wake(other, Error::PeerGone),
                State::Receiving { from: Some(f) } if f == t => self.wake(other, Error::PeerGone),
                _ => {}
            }
        }
        if self.health_monitor == id {
            self.health_monitor = ThreadId::OWN;
        }
        if self.current == Some(t) {
            self.current = None;
        }
        let rp = self.tasks[self.threads[t].task].rp;
        self.rps[rp].release(Amount::threads(1));
        let generation = self.threads[t].generation.wrapping_add(1);
        self.threads[t] = Thread {
            generation,
            ..Thread::FREE
        };
    }

    pub fn set_suspended(&mut self, t: ThreadIdx, suspended: bool) {
        self.threads[t].suspended = suspended;
        self.requeue(t);
    }

    pub fn set_priority(&mut self, t: ThreadIdx, priority: u8) -> Result<(), Error> {
        if priority > self.tasks[self.threads[t].task].mcp {
            return Err(Error::McpExceeded);
        }
        self.run.remove(t.position());
        self.threads[t].priority = priority;
        self.requeue(t);
        Ok(())
    }

    pub fn set_time_partition(&mut self, t: ThreadIdx, partition: u8) -> Result<(), Error> {
        if partition as usize >= TIME_PARTITIONS {
            return Err(Error::InvalidArgument);
        }
        self.run.remove(t.position());
        self.threads[t].time_partition = partition;
        self.requeue(t);
        Ok(())
    }

    /// Times out every blocked thread whose deadline is at or before `now` and recomputes
    /// the next deadline. Bounded by the thread table.
    pub fn expire_timeouts(&mut self, now: u64) {
        let mut next = NEVER;
        for t in ThreadIdx::all() {
            let deadline = self.threads[t].deadline;
            if deadline == NEVER {
                continue;
            }
            if deadline <= now {
                self.abort_wait(t, Error::TimedOut);
            } else {
                next = next.min(deadline);
            }
        }
        self.next_deadline = next;
        self.timer_dirty = true;
    }

    /// Ends whatever `t` waits for with `error` (timeout or peer gone).
    pub fn abort_wait(&mut self, t: ThreadIdx, error: Error) {
        match self.threads[t].state {
            State::Sending { to, .. } => {
                self.unqueue_sender(to, t);
                self.wake(t, error);
            }
            State::WaitingReply { .. } | State::Receiving { .. } | State::WaitingNotify { .. } => {
                self.wake(t, error)
            }
            State::Sleeping => self.wake(t, Error::Ok),
            State::Free | State::Inactive | State::Ready => self.threads[t].deadline = NEVER,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::FpuState;

    #[test]
    fn a_sanitized_fpu_image_keeps_writable_mxcsr_bits_only() {
        let mut current = FpuState::initial();
        let mut image = [0xffu8; 512];
        assert_eq!(
            &current.sanitized(image).0[24..32],
            &[0xbf, 0xff, 0, 0, 0, 0, 0, 0]
        );
        current.0[28..32].copy_from_slice(&0xffffu32.to_le_bytes());
        image[24..28].copy_from_slice(&0x1f80u32.to_le_bytes());
        let loaded = current.sanitized(image);
        assert_eq!(&loaded.0[24..32], &[0x80, 0x1f, 0, 0, 0xff, 0xff, 0, 0]);
        assert_eq!(loaded.0[0..24], image[0..24]);
    }
}
