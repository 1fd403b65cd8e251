//! Thread control blocks.

use crate::arch::idt::TrapFrame;
use crate::rp::Amount;
use crate::sched::TIME_PARTITIONS;
use crate::state::{Kernel, USER_CS, USER_RFLAGS, USER_SS, slot_of};
use crate::table::{Slot, TaskIdx, ThreadIdx};
use abi::args::ArgRegs;
use abi::ipc::{Registers, USER_RFLAGS_MASK};
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

/// A thread control block. Its fields change only here, through methods that keep them
/// consistent: the state with the run and send queues ([`Kernel::set_state`],
/// [`Kernel::block`], [`Kernel::wake`]), the priority within the task's MCP, the thread
/// quota of its resource partition ([`Kernel::create_thread`], [`Kernel::kill_thread`]),
/// user registers in user mode with interrupts on.
#[derive(Clone, Copy)]
pub struct Thread {
    state: State,
    generation: u16,
    task: TaskIdx,
    priority: u8,
    time_partition: u8,
    /// The CPU it runs on.
    cpu: u8,
    /// It moves to the CPU of each sender whose message it takes ([`Kernel::follow`]).
    pub follows_callers: bool,
    suspended: bool,
    /// User registers while the thread is not running (the live copy is the entry frame).
    context: TrapFrame,
    fs_base: u64,
    gs_base: u64,
    fpu: FpuState,
    /// The exception handler ([`ThreadId::OWN`] = none), resolved at fault time.
    exception_handler: ThreadId,
    ipc_buffer: u64,
    /// The forwarded system call it answers itself ([`abi::syscall::ThreadAttribute::SyscallAnswer`]).
    syscall_answer: u64,
    /// Absolute time (ns since boot) at which a blocking call times out.
    deadline: u64,
    fault: Option<Fault>,
    /// Head of the queue of threads waiting to send to this one (by priority, then FIFO).
    senders: Option<ThreadIdx>,
    /// Link in the send queue this thread waits in.
    next_sender: Option<ThreadIdx>,
    notify_bits: u64,
}

impl Thread {
    pub const FREE: Self = Self {
        state: State::Free,
        generation: 0,
        task: TaskIdx::ROOT,
        priority: 0,
        time_partition: 0,
        cpu: 0,
        follows_callers: false,
        suspended: false,
        context: TrapFrame::ZERO,
        fs_base: 0,
        gs_base: 0,
        fpu: FpuState::initial(),
        exception_handler: ThreadId::OWN,
        ipc_buffer: 0,
        syscall_answer: 0,
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

    #[inline(always)]
    pub fn state(&self) -> State {
        self.state
    }

    #[inline(always)]
    pub fn task(&self) -> TaskIdx {
        self.task
    }

    #[inline(always)]
    pub fn priority(&self) -> u8 {
        self.priority
    }

    #[inline(always)]
    pub fn time_partition(&self) -> u8 {
        self.time_partition
    }

    #[inline(always)]
    pub fn cpu(&self) -> usize {
        self.cpu as usize
    }

    /// Its user registers as saved when it left user mode.
    #[inline(always)]
    pub fn context(&self) -> &TrapFrame {
        &self.context
    }

    #[inline(always)]
    pub fn bases(&self) -> (u64, u64) {
        (self.fs_base, self.gs_base)
    }

    #[inline(always)]
    pub fn fpu(&self) -> &FpuState {
        &self.fpu
    }

    #[inline(always)]
    pub fn exception_handler(&self) -> ThreadId {
        self.exception_handler
    }

    #[inline(always)]
    pub fn ipc_buffer(&self) -> u64 {
        self.ipc_buffer
    }

    #[inline(always)]
    pub fn deadline(&self) -> u64 {
        self.deadline
    }

    #[inline(always)]
    pub fn fault(&self) -> Option<Fault> {
        self.fault
    }

    #[inline(always)]
    pub fn is_suspended(&self) -> bool {
        self.suspended
    }

    /// The first thread in its send queue.
    #[inline(always)]
    pub fn senders(&self) -> Option<ThreadIdx> {
        self.senders
    }

    /// The thread behind it in the send queue it waits in.
    #[inline(always)]
    pub fn next_sender(&self) -> Option<ThreadIdx> {
        self.next_sender
    }

    /// Saves the registers of the entry frame when it leaves user mode.
    #[inline(always)]
    /// Where its registers are saved: the frame the entry stubs use while it runs.
    pub fn context_ptr(&mut self) -> *mut TrapFrame {
        &mut self.context
    }

    /// Where the processor saves its FPU state when it stops running.
    #[inline(always)]
    pub fn fpu_save_area(&mut self) -> &mut FpuState {
        &mut self.fpu
    }

    /// Loads an FPU image from user space, without the MXCSR bits FXRSTOR refuses.
    pub fn load_fpu(&mut self, image: [u8; 512]) {
        self.fpu = self.fpu.sanitized(image);
    }

    /// A system call's status in `rax`.
    #[inline(always)]
    pub fn set_status(&mut self, status: Error) {
        self.context.rax = status as u64;
    }

    /// Makes it execute its `syscall` (`len` bytes) again when it runs.
    pub fn rewind(&mut self, len: u64) {
        self.context.rip = self.context.rip.wrapping_sub(len);
    }

    /// `rsi` and `rdx` of a thread that has not started (the root task's start convention).
    pub fn set_start_registers(&mut self, rsi: u64, rdx: u64) {
        (self.context.rsi, self.context.rdx) = (rsi, rdx);
    }

    /// FS or GS base (a user address, checked by the caller).
    pub fn set_base(&mut self, fs: bool, value: u64) {
        if fs {
            self.fs_base = value;
        } else {
            self.gs_base = value;
        }
    }

    /// The exception handler (a thread allowed to be one, checked by the caller).
    pub fn set_exception_handler(&mut self, handler: ThreadId) {
        self.exception_handler = handler;
    }

    /// The IPC buffer (checked by the caller: aligned and writable, or 0).
    pub fn set_ipc_buffer(&mut self, at: u64) {
        self.ipc_buffer = at;
    }

    /// The forwarded system call it answers itself (checked by the caller: any value).
    pub fn set_syscall_answer(&mut self, answer: u64) {
        self.syscall_answer = answer;
    }

    /// Answers its forwarded `syscall` itself if that is the call its
    /// [`abi::syscall::ThreadAttribute::SyscallAnswer`] names; true if it did.
    pub fn answered(&mut self) -> bool {
        let answer = self.syscall_answer;
        let named = answer != 0 && answer >> 32 == self.context.rax;
        if named {
            self.context.rax = answer & u64::from(u32::MAX);
        }
        named
    }

    /// The fault it reports (an exception message is sent for it next).
    pub fn set_fault(&mut self, fault: Fault) {
        self.fault = Some(fault);
    }

    /// Sets notification bits.
    pub fn add_notify_bits(&mut self, bits: u64) {
        self.notify_bits |= bits;
    }

    /// Takes (clears and returns) the set notification bits of `mask`.
    pub fn take_notify_bits(&mut self, mask: u64) -> u64 {
        let got = self.notify_bits & mask;
        self.notify_bits &= !mask;
        got
    }

    /// Loads edited registers (an exception handler's reply), keeping it in user mode with
    /// interrupts on.
    pub fn load_registers(&mut self, r: &Registers) -> Result<(), Error> {
        if r.rip >= USER_END || r.fs_base >= USER_END || r.gs_base >= USER_END {
            return Err(Error::InvalidArgument);
        }
        let c = &mut self.context;
        (c.rax, c.rbx, c.rcx, c.rdx) = (r.rax, r.rbx, r.rcx, r.rdx);
        (c.rsi, c.rdi, c.rbp, c.rsp) = (r.rsi, r.rdi, r.rbp, r.rsp);
        (c.r8, c.r9, c.r10, c.r11) = (r.r8, r.r9, r.r10, r.r11);
        (c.r12, c.r13, c.r14, c.r15) = (r.r12, r.r13, r.r14, r.r15);
        c.rip = r.rip;
        c.rflags = (r.rflags & USER_RFLAGS_MASK) | USER_RFLAGS;
        (self.fs_base, self.gs_base) = (r.fs_base, r.gs_base);
        Ok(())
    }

    /// Its user registers, for host tests that play a thread's part.
    #[cfg(test)]
    pub fn context_mut(&mut self) -> &mut TrapFrame {
        &mut self.context
    }

    /// The argument registers of its system call.
    #[inline(always)]
    pub fn arg_regs(&self) -> ArgRegs {
        let c = &self.context;
        ArgRegs::from_array([c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9])
    }

    /// Makes its `syscall`, which it entered but did not make, run again when it resumes
    /// (the instruction is two bytes long; every register is as it entered).
    pub fn restart_syscall(&mut self) {
        self.context.rip = self.context.rip.wrapping_sub(2);
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
        if self.tasks[task].is_dying() {
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
            let place = crate::sched::Place {
                priority: th.priority,
                partition: th.time_partition,
                cpu: th.cpu,
            };
            self.run.enqueue(t.position(), place);
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

    /// Resumes `t` after its fault was answered (its registers as the handler left them).
    pub fn resume(&mut self, t: ThreadIdx) {
        let th = &mut self.threads[t];
        th.fault = None;
        th.deadline = NEVER;
        self.set_state(t, State::Ready);
    }

    /// Blocks `t` in `state` until `deadline` (absolute ns; [`NEVER`] for none).
    pub fn block(&mut self, t: ThreadIdx, state: State, deadline: u64) {
        self.threads[t].deadline = deadline;
        // Its CPU's timer serves its time-out (`Kernel::next_event`).
        let core = &mut self.cores[self.threads[t].cpu as usize];
        if deadline < core.next_deadline {
            (core.next_deadline, core.timer_dirty) = (deadline, true);
        }
        self.set_state(t, state);
    }

    /// A new inactive thread of `task` that will start at `entry` with `rsp` = `stack` and
    /// `rdi` = `arg`, on the CPU that entered the kernel (its creator's).
    pub fn create_thread(
        &mut self,
        task: TaskIdx,
        entry: u64,
        stack: u64,
        priority: u8,
        time_partition: u8,
        arg: u64,
    ) -> Result<ThreadIdx, Error> {
        if priority > self.tasks[task].mcp() {
            return Err(Error::McpExceeded);
        }
        if entry >= USER_END || stack > USER_END || time_partition as usize >= TIME_PARTITIONS {
            return Err(Error::InvalidArgument);
        }
        let slot = self.free_thread_slot().ok_or(Error::QuotaExceeded)?;
        self.rps[self.tasks[task].rp()].charge(Amount::threads(1))?;
        let generation = self.threads[slot].generation;
        self.threads[slot] = Thread {
            state: State::Inactive,
            generation,
            task,
            priority,
            time_partition,
            cpu: self.cpu as u8,
            follows_callers: false,
            context: TrapFrame {
                rip: entry,
                rsp: stack,
                rdi: arg,
                cs: USER_CS,
                ss: USER_SS,
                rflags: USER_RFLAGS,
                ..TrapFrame::ZERO
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
        // Another CPU running it is sent an interrupt (`Kernel::cpus_to_kick`); until it
        // takes it, the slot stays its `current` and is not reused.
        if self.core().current == Some(t) {
            self.core_mut().current = None;
        }
        let rp = self.tasks[self.threads[t].task].rp();
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
        if priority > self.tasks[self.threads[t].task].mcp() {
            return Err(Error::McpExceeded);
        }
        self.run.remove(t.position());
        self.threads[t].priority = priority;
        self.requeue(t);
        Ok(())
    }

    /// A free thread slot no CPU still holds as its current thread (a thread killed while
    /// another CPU ran it: that CPU saves its registers there when it takes its interrupt).
    pub fn free_thread_slot(&self) -> Option<ThreadIdx> {
        ThreadIdx::all()
            .find(|&t| self.threads[t].is_free() && self.cores.iter().all(|c| c.current != Some(t)))
    }

    /// Moves `t` to `cpu` (an online one), unless another CPU runs it: two CPUs must never
    /// run one thread, and only the CPU running it has its FPU state (a CPU saves it
    /// when it switches away or idles). The caller's own thread may move: its CPU saves
    /// its state before it lets go of the kernel lock.
    pub fn set_cpu(&mut self, t: ThreadIdx, cpu: u64) -> Result<(), Error> {
        if cpu >= self.online as u64 {
            return Err(Error::InvalidArgument);
        }
        let allowed = self.rps[self.tasks[self.threads[t].task()].rp()].cpus;
        let elsewhere =
            |(c, core): (usize, &crate::state::Core)| c != self.cpu && core.current == Some(t);
        if allowed & 1 << cpu == 0 || self.cores.iter().enumerate().any(elsewhere) {
            return Err(Error::NotPermitted);
        }
        self.run.remove(t.position());
        self.threads[t].cpu = cpu as u8;
        self.requeue(t);
        crate::arch::pit::start_turn_clock(cpu as u8);
        Ok(())
    }

    /// A receiver that follows its callers moves to `sender`'s CPU (if it may).
    pub fn follow(&mut self, receiver: ThreadIdx, sender: ThreadIdx) {
        let cpu = self.threads[sender].cpu;
        if self.threads[receiver].follows_callers && self.threads[receiver].cpu != cpu {
            let _ = self.set_cpu(receiver, cpu as u64);
        }
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

    /// Times out every blocked thread whose deadline is at or before `now` (of any CPU: a
    /// thread may have moved since it blocked) and recomputes each CPU's next deadline.
    /// Bounded by the thread table.
    pub fn expire_timeouts(&mut self, now: u64) {
        let mut next = [NEVER; abi::machine::MAX_CPUS];
        for t in ThreadIdx::all() {
            let (deadline, cpu) = (self.threads[t].deadline, self.threads[t].cpu as usize);
            if deadline <= now {
                self.abort_wait(t, Error::TimedOut);
            } else if deadline != NEVER {
                next[cpu] = next[cpu].min(deadline);
            }
        }
        for (core, next) in self.cores.iter_mut().zip(next) {
            core.timer_dirty |= core.next_deadline != next;
            core.next_deadline = next;
        }
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

impl Kernel {
    pub fn enqueue_sender(&mut self, receiver: ThreadIdx, sender: ThreadIdx) {
        let priority = self.threads[sender].priority;
        // Insert before the first queued sender of lower priority.
        let mut prev = None;
        let mut at = self.threads[receiver].senders;
        while let Some(a) = at
            && self.threads[a].priority >= priority
        {
            prev = at;
            at = self.threads[a].next_sender;
        }
        self.threads[sender].next_sender = at;
        match prev {
            None => self.threads[receiver].senders = Some(sender),
            Some(p) => self.threads[p].next_sender = Some(sender),
        }
    }

    pub fn unqueue_sender(&mut self, receiver: ThreadIdx, sender: ThreadIdx) {
        let mut prev = None;
        let mut at = self.threads[receiver].senders;
        while let Some(a) = at {
            if a == sender {
                let next = self.threads[sender].next_sender.take();
                match prev {
                    None => self.threads[receiver].senders = next,
                    Some(p) => self.threads[p].next_sender = next,
                }
                return;
            }
            prev = at;
            at = self.threads[a].next_sender;
        }
    }

    /// The first queued sender to `receiver` (from `from` only, if given).
    pub fn first_sender(&self, receiver: ThreadIdx, from: Option<ThreadIdx>) -> Option<ThreadIdx> {
        let mut at = self.threads[receiver].senders;
        while let Some(a) = at {
            if from.is_none_or(|f| f == a) {
                return Some(a);
            }
            at = self.threads[a].next_sender;
        }
        None
    }
}

#[cfg(test)]
#[path = "../host-tests/thread.rs"]
mod tests;
