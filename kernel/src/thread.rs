//! Thread control blocks.

use crate::arch::idt::TrapFrame;

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
        to: usize,
        call: bool,
    },
    WaitingReply {
        from: usize,
    },
    Receiving {
        from: Option<usize>,
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
}

#[derive(Clone, Copy)]
pub struct Thread {
    pub state: State,
    pub generation: u16,
    pub task: usize,
    pub priority: u8,
    pub time_partition: u8,
    pub suspended: bool,
    /// User registers while the thread is not running (the live copy is the entry frame).
    pub context: TrapFrame,
    pub fs_base: u64,
    pub gs_base: u64,
    pub fpu: FpuState,
    /// Raw thread identifier of the exception handler (0 = none), resolved at fault time.
    pub exception_handler: u64,
    pub ipc_buffer: u64,
    /// Absolute time (ns since boot) at which a blocking call times out.
    pub deadline: u64,
    pub fault: Option<Fault>,
    /// Head of the queue of threads waiting to send to this one (by priority, then FIFO).
    pub senders: u16,
    /// Link in the send queue this thread waits in.
    pub next_sender: u16,
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
        task: 0,
        priority: 0,
        time_partition: 0,
        suspended: false,
        context: EMPTY_CONTEXT,
        fs_base: 0,
        gs_base: 0,
        fpu: FpuState::initial(),
        exception_handler: 0,
        ipc_buffer: 0,
        deadline: NEVER,
        fault: None,
        senders: NIL,
        next_sender: NIL,
        notify_bits: 0,
    };

    pub fn is_free(&self) -> bool {
        self.state == State::Free
    }

    /// Runnable: ready and not suspended.
    pub fn is_runnable(&self) -> bool {
        self.state == State::Ready && !self.suspended
    }
}
