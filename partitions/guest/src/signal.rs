//! Linux signals as the guest delivers them: the numbers and their default actions, a
//! process's disposition of a signal (`struct sigaction`), the `siginfo` it gets, and the
//! signal frame (`struct rt_sigframe`, with the FPU state) written on the user stack before
//! a handler runs and read back by `rt_sigreturn`.
//!
//! Pure logic: which process gets a signal and when is the process table's
//! ([`crate::system`]); this module never touches memory or tasks itself.

use abi::ipc::{Registers, USER_RFLAGS_MASK};

pub const SIGHUP: u32 = 1;
pub const SIGINT: u32 = 2;
pub const SIGQUIT: u32 = 3;
pub const SIGILL: u32 = 4;
pub const SIGTRAP: u32 = 5;
pub const SIGABRT: u32 = 6;
pub const SIGBUS: u32 = 7;
pub const SIGFPE: u32 = 8;
pub const SIGKILL: u32 = 9;
pub const SIGUSR1: u32 = 10;
pub const SIGSEGV: u32 = 11;
pub const SIGUSR2: u32 = 12;
pub const SIGPIPE: u32 = 13;
pub const SIGALRM: u32 = 14;
pub const SIGTERM: u32 = 15;
pub const SIGSTKFLT: u32 = 16;
pub const SIGCHLD: u32 = 17;
pub const SIGCONT: u32 = 18;
pub const SIGSTOP: u32 = 19;
pub const SIGTSTP: u32 = 20;
pub const SIGTTIN: u32 = 21;
pub const SIGTTOU: u32 = 22;
pub const SIGURG: u32 = 23;
pub const SIGXCPU: u32 = 24;
pub const SIGXFSZ: u32 = 25;
pub const SIGVTALRM: u32 = 26;
pub const SIGPROF: u32 = 27;
pub const SIGWINCH: u32 = 28;
pub const SIGIO: u32 = 29;
pub const SIGPWR: u32 = 30;
pub const SIGSYS: u32 = 31;
/// Highest signal number (real-time signals are 32..=64).
pub const NSIG: u32 = 64;

/// `sa_handler` values that are no address.
pub const SIG_DFL: u64 = 0;
pub const SIG_IGN: u64 = 1;

/// `sa_flags`.
pub const SA_NOCLDSTOP: u64 = 1;
pub const SA_NOCLDWAIT: u64 = 2;
pub const SA_SIGINFO: u64 = 4;
pub const SA_RESTORER: u64 = 0x0400_0000;
pub const SA_ONSTACK: u64 = 0x0800_0000;
pub const SA_RESTART: u64 = 0x1000_0000;
pub const SA_NODEFER: u64 = 0x4000_0000;
pub const SA_RESETHAND: u64 = 0x8000_0000;

/// `si_code` values.
pub const SI_USER: i32 = 0;
/// `si_code` of a signal `tkill`/`tgkill` sent.
pub const SI_TKILL: i32 = -6;
pub const SI_KERNEL: i32 = 0x80;
pub const CLD_EXITED: i32 = 1;
pub const CLD_KILLED: i32 = 2;
pub const CLD_STOPPED: i32 = 5;
pub const CLD_CONTINUED: i32 = 6;
pub const SEGV_MAPERR: i32 = 1;
pub const SEGV_ACCERR: i32 = 2;
pub const ILL_ILLOPN: i32 = 2;
pub const FPE_INTDIV: i32 = 1;
pub const TRAP_BRKPT: i32 = 1;
pub const BUS_ADRALN: i32 = 1;
/// A page the guest could not back (out of memory).
pub const BUS_ADRERR: i32 = 2;

/// `sigaltstack`'s `ss_flags`.
pub const SS_ONSTACK: u32 = 1;
pub const SS_DISABLE: u32 = 2;
/// Smallest alternate stack `sigaltstack` accepts (`MINSIGSTKSZ`).
pub const MIN_ALT_STACK: u64 = 2048;

/// The bit of signal `signal` (1..=64) in a signal set.
pub const fn bit(signal: u32) -> u64 {
    1 << (signal - 1)
}

/// Signals no mask blocks and no handler catches.
pub const UNBLOCKABLE: u64 = bit(SIGKILL) | bit(SIGSTOP);
/// Signals that stop a process by default.
pub const STOP_SIGNALS: u64 = bit(SIGSTOP) | bit(SIGTSTP) | bit(SIGTTIN) | bit(SIGTTOU);

/// What a signal does when its handler is `SIG_DFL`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Default {
    Terminate,
    /// Terminate with a core dump (none is written: the status has no core bit, as on a
    /// Linux with `RLIMIT_CORE` 0).
    Core,
    Ignore,
    Stop,
    Continue,
}

/// Linux's default action of `signal` (`signal(7)`).
pub const fn default_action(signal: u32) -> Default {
    match signal {
        SIGQUIT | SIGILL | SIGTRAP | SIGABRT | SIGBUS | SIGFPE | SIGSEGV | SIGXCPU | SIGXFSZ
        | SIGSYS => Default::Core,
        SIGCHLD | SIGURG | SIGWINCH => Default::Ignore,
        SIGSTOP | SIGTSTP | SIGTTIN | SIGTTOU => Default::Stop,
        SIGCONT => Default::Continue,
        _ => Default::Terminate,
    }
}

/// The name of `signal` (`SIG...`), `"SIGRT"` for the real-time ones.
pub const fn name(signal: u32) -> &'static str {
    const NAMES: [&str; 32] = [
        "?",
        "SIGHUP",
        "SIGINT",
        "SIGQUIT",
        "SIGILL",
        "SIGTRAP",
        "SIGABRT",
        "SIGBUS",
        "SIGFPE",
        "SIGKILL",
        "SIGUSR1",
        "SIGSEGV",
        "SIGUSR2",
        "SIGPIPE",
        "SIGALRM",
        "SIGTERM",
        "SIGSTKFLT",
        "SIGCHLD",
        "SIGCONT",
        "SIGSTOP",
        "SIGTSTP",
        "SIGTTIN",
        "SIGTTOU",
        "SIGURG",
        "SIGXCPU",
        "SIGXFSZ",
        "SIGVTALRM",
        "SIGPROF",
        "SIGWINCH",
        "SIGIO",
        "SIGPWR",
        "SIGSYS",
    ];
    if signal < 32 {
        NAMES[signal as usize]
    } else {
        "SIGRT"
    }
}

/// A process's disposition of one signal: `struct sigaction` as the kernel ABI has it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Action {
    pub handler: u64,
    pub flags: u64,
    pub restorer: u64,
    pub mask: u64,
}

impl Action {
    pub const DEFAULT: Self = Self {
        handler: SIG_DFL,
        flags: 0,
        restorer: 0,
        mask: 0,
    };
    pub const IGNORE: Self = Self {
        handler: SIG_IGN,
        ..Self::DEFAULT
    };

    /// From the 32 bytes of a user `struct sigaction`.
    pub fn from_bytes(b: &[u8; 32]) -> Self {
        let w = |i: usize| u64::from_le_bytes(b[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8]));
        Self {
            handler: w(0),
            flags: w(1),
            restorer: w(2),
            mask: w(3),
        }
    }

    pub fn to_bytes(self) -> [u8; 32] {
        let mut b = [0u8; 32];
        for (i, w) in [self.handler, self.flags, self.restorer, self.mask]
            .into_iter()
            .enumerate()
        {
            b[i * 8..i * 8 + 8].copy_from_slice(&w.to_le_bytes());
        }
        b
    }

    /// Whether `signal` under this disposition does nothing at all (then Linux discards it
    /// when it is sent, unless it is blocked).
    pub fn ignores(self, signal: u32) -> bool {
        self.handler == SIG_IGN
            || (self.handler == SIG_DFL
                && matches!(default_action(signal), Default::Ignore | Default::Continue))
    }
}

/// What a signal's `siginfo` says.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Info {
    pub signal: u32,
    pub code: i32,
    /// Sender (`kill`), or the child (`SIGCHLD`).
    pub pid: u32,
    /// The child's exit code or signal (`SIGCHLD`).
    pub status: i32,
    /// The faulting address (`SIGSEGV`, `SIGBUS`, `SIGILL`, `SIGFPE`).
    pub address: u64,
}

/// Bytes of `siginfo_t`.
pub const INFO_SIZE: usize = 128;

impl Info {
    /// A signal sent by process `pid` (`kill`).
    pub const fn user(signal: u32, pid: u32) -> Self {
        Self {
            signal,
            code: SI_USER,
            pid,
            status: 0,
            address: 0,
        }
    }

    /// A signal the guest itself raises (`SIGPIPE`, a terminal's `SIGINT`...).
    pub const fn kernel(signal: u32) -> Self {
        Self {
            signal,
            code: SI_KERNEL,
            pid: 0,
            status: 0,
            address: 0,
        }
    }

    pub fn to_bytes(self) -> [u8; INFO_SIZE] {
        let mut b = [0u8; INFO_SIZE];
        b[0..4].copy_from_slice(&self.signal.to_le_bytes());
        b[8..12].copy_from_slice(&self.code.to_le_bytes());
        if matches!(self.signal, SIGSEGV | SIGBUS | SIGILL | SIGFPE) && self.code > 0 {
            b[16..24].copy_from_slice(&self.address.to_le_bytes());
        } else {
            b[16..20].copy_from_slice(&self.pid.to_le_bytes());
            // si_uid 0 (everything runs as root) at 20; si_status at 24 for SIGCHLD.
            b[24..28].copy_from_slice(&self.status.to_le_bytes());
        }
        b
    }
}

/// A process's alternate signal stack (`sigaltstack`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AltStack {
    pub base: u64,
    pub size: u64,
    /// `SS_DISABLE` or 0 (`SS_ONSTACK` is computed, never stored).
    pub flags: u32,
}

impl AltStack {
    pub const NONE: Self = Self {
        base: 0,
        size: 0,
        flags: SS_DISABLE,
    };

    /// Whether stack pointer `sp` is on it.
    pub fn contains(&self, sp: u64) -> bool {
        self.flags & SS_DISABLE == 0 && sp > self.base && sp - self.base <= self.size
    }

    /// `stack_t` as user space sees it with the stack pointer at `sp`.
    pub fn to_bytes(self, sp: u64) -> [u8; 24] {
        let flags = if self.contains(sp) {
            SS_ONSTACK
        } else {
            self.flags
        };
        let mut b = [0u8; 24];
        b[0..8].copy_from_slice(&self.base.to_le_bytes());
        b[8..12].copy_from_slice(&flags.to_le_bytes());
        b[16..24].copy_from_slice(&self.size.to_le_bytes());
        b
    }
}

// The layout of `struct rt_sigframe` (x86-64): the return address (`sa_restorer`), the
// `struct ucontext` (flags, link, `stack_t`, `struct sigcontext`, the signal mask), then
// the `siginfo`. The FXSAVE image lies below it, 64-byte aligned, and `sigcontext.fpstate`
// points at it.
const UC: usize = 8;
const UC_STACK: usize = UC + 16;
const MCONTEXT: usize = UC + 40;
/// `struct sigcontext`: r8..r15, rdi, rsi, rbp, rbx, rdx, rax, rcx, rsp, rip, eflags, then
/// cs/gs/fs/ss (16 bits each), err, trapno, oldmask, cr2, fpstate, 8 reserved words.
const SC_CS: usize = MCONTEXT + 18 * 8;
const SC_ERR: usize = SC_CS + 8;
const SC_TRAPNO: usize = SC_ERR + 8;
const SC_OLDMASK: usize = SC_TRAPNO + 8;
const SC_CR2: usize = SC_OLDMASK + 8;
const SC_FPSTATE: usize = SC_CR2 + 8;
const UC_SIGMASK: usize = MCONTEXT + 256;
const INFO: usize = UC_SIGMASK + 8;
/// Bytes of the frame above the FPU image.
pub const FRAME_SIZE: usize = INFO + INFO_SIZE;
/// Bytes of the FPU image (FXSAVE).
pub const FPU_SIZE: usize = 512;
/// The red zone below the interrupted stack pointer that the frame must not overwrite.
const RED_ZONE: u64 = 128;
/// User code and stack selectors Linux reports in `sigcontext` (`__USER_CS`, `__USER_DS`).
const USER_CS: u16 = 0x33;
const USER_SS: u16 = 0x2b;

/// A signal frame ready to be written: `bytes` at `frame`, the FPU image at `fpu`, and the
/// registers the handler starts with.
pub struct Frame {
    pub frame: u64,
    pub fpu: u64,
    pub bytes: [u8; FRAME_SIZE],
    pub registers: Registers,
}

/// Where the interrupted code was, for the frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct Interrupted {
    pub registers: Registers,
    /// The mask to restore when the handler returns.
    pub mask: u64,
    /// CPU exception details for a fault (trap number, error code, CR2).
    pub trap: u64,
    pub error: u64,
    pub cr2: u64,
}

/// The frame for handler `action` of `info.signal`: on the alternate stack when the action
/// asks for it and the process is not on it already, else below the red zone; `None` when
/// the addresses wrap (the process then dies with SIGSEGV, as on Linux).
pub fn frame(action: &Action, info: &Info, at: &Interrupted, alt: &AltStack) -> Option<Frame> {
    let r = &at.registers;
    let mut sp =
        if action.flags & SA_ONSTACK != 0 && alt.flags & SS_DISABLE == 0 && !alt.contains(r.rsp) {
            alt.base.checked_add(alt.size)?
        } else {
            r.rsp.checked_sub(RED_ZONE)?
        };
    sp = sp.checked_sub(FPU_SIZE as u64)? & !63;
    let fpu = sp;
    // As after a `call`: the return address at a 16-byte boundary minus 8.
    let frame = (sp.checked_sub(FRAME_SIZE as u64)? & !15).checked_sub(8)?;

    let mut b = [0u8; FRAME_SIZE];
    let mut put = |at: usize, v: u64| b[at..at + 8].copy_from_slice(&v.to_le_bytes());
    put(0, action.restorer);
    put(UC_STACK, alt.base);
    put(UC_STACK + 16, alt.size);
    let general = [
        r.r8, r.r9, r.r10, r.r11, r.r12, r.r13, r.r14, r.r15, r.rdi, r.rsi, r.rbp, r.rbx, r.rdx,
        r.rax, r.rcx, r.rsp, r.rip, r.rflags,
    ];
    for (i, v) in general.into_iter().enumerate() {
        put(MCONTEXT + i * 8, v);
    }
    put(SC_ERR, at.error);
    put(SC_TRAPNO, at.trap);
    put(SC_OLDMASK, at.mask);
    put(SC_CR2, at.cr2);
    put(SC_FPSTATE, fpu);
    put(UC_SIGMASK, at.mask);
    b[UC_STACK + 8..UC_STACK + 12].copy_from_slice(&alt.to_bytes(r.rsp)[8..12]);
    b[SC_CS..SC_CS + 2].copy_from_slice(&USER_CS.to_le_bytes());
    b[SC_CS + 6..SC_CS + 8].copy_from_slice(&USER_SS.to_le_bytes());
    b[INFO..INFO + INFO_SIZE].copy_from_slice(&info.to_bytes());

    let registers = Registers {
        rip: action.handler,
        rsp: frame,
        rdi: info.signal as u64,
        rsi: frame + INFO as u64,
        rdx: frame + UC as u64,
        rax: 0,
        // Direction and trap flags cleared, as Linux enters a handler.
        rflags: r.rflags & !(1 << 10 | 1 << 8),
        ..*r
    };
    Some(Frame {
        frame,
        fpu,
        bytes: b,
        registers,
    })
}

/// What `rt_sigreturn` restores from a frame.
pub struct Restored {
    pub registers: Registers,
    pub mask: u64,
    /// Where the FPU image is (0: none to restore).
    pub fpu: u64,
}

/// Reads back a frame `rt_sigreturn` found (the frame's bytes, as the handler may have
/// changed them), keeping `current`'s flags outside what user code may change.
pub fn restore(b: &[u8; FRAME_SIZE], current: &Registers) -> Restored {
    let get = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap_or([0; 8]));
    let g = |i: usize| get(MCONTEXT + i * 8);
    let rflags = (current.rflags & !USER_RFLAGS_MASK) | (g(17) & USER_RFLAGS_MASK);
    Restored {
        registers: Registers {
            r8: g(0),
            r9: g(1),
            r10: g(2),
            r11: g(3),
            r12: g(4),
            r13: g(5),
            r14: g(6),
            r15: g(7),
            rdi: g(8),
            rsi: g(9),
            rbp: g(10),
            rbx: g(11),
            rdx: g(12),
            rax: g(13),
            rcx: g(14),
            rsp: g(15),
            rip: g(16),
            rflags,
            ..*current
        },
        mask: get(UC_SIGMASK) & !UNBLOCKABLE,
        fpu: get(SC_FPSTATE),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn registers() -> Registers {
        Registers {
            rax: 1,
            rbx: 2,
            rcx: 3,
            rdx: 4,
            rsi: 5,
            rdi: 6,
            rbp: 7,
            rsp: 0x7fff_f000_0123,
            r8: 8,
            r9: 9,
            r10: 10,
            r11: 11,
            r12: 12,
            r13: 13,
            r14: 14,
            r15: 15,
            rip: 0x40_1000,
            rflags: 0x246 | 1 << 10,
            fs_base: 0x1000,
            gs_base: 0,
        }
    }

    #[test]
    fn the_frame_sits_below_the_red_zone_aligned_as_after_a_call() {
        let action = Action {
            handler: 0x40_2000,
            flags: SA_SIGINFO | SA_RESTORER,
            restorer: 0x40_3000,
            mask: 0,
        };
        let at = Interrupted {
            registers: registers(),
            mask: 0x55,
            ..Interrupted::default()
        };
        let f = frame(&action, &Info::user(SIGUSR1, 7), &at, &AltStack::NONE).unwrap();
        assert!(f.fpu + FPU_SIZE as u64 <= at.registers.rsp - RED_ZONE);
        assert_eq!(f.fpu % 64, 0);
        assert_eq!((f.frame + 8) % 16, 0);
        assert!(f.frame + FRAME_SIZE as u64 <= f.fpu);
        let r = &f.registers;
        assert_eq!((r.rip, r.rsp, r.rdi), (0x40_2000, f.frame, SIGUSR1 as u64));
        assert_eq!(r.rsi, f.frame + 312);
        assert_eq!(r.rdx, f.frame + 8);
        assert_eq!(r.rflags & 1 << 10, 0);
        assert_eq!(&f.bytes[0..8], &0x40_3000u64.to_le_bytes());
        assert_eq!(&f.bytes[312..316], &SIGUSR1.to_le_bytes());
        assert_eq!(&f.bytes[312 + 16..312 + 20], &7u32.to_le_bytes());
    }

    #[test]
    fn sigreturn_restores_what_the_frame_saved() {
        let at = Interrupted {
            registers: registers(),
            mask: 0x1234 | UNBLOCKABLE,
            ..Interrupted::default()
        };
        let action = Action {
            handler: 1 << 20,
            ..Action::DEFAULT
        };
        let f = frame(&action, &Info::kernel(SIGINT), &at, &AltStack::NONE).unwrap();
        let handler_state = Registers {
            rflags: 0x202 | 1 << 21,
            ..f.registers
        };
        let back = restore(&f.bytes, &handler_state);
        let expected = Registers {
            // DF comes back; bits outside the user mask stay as they are.
            rflags: (0x202 | 1 << 21) & !USER_RFLAGS_MASK | (0x246 | 1 << 10) & USER_RFLAGS_MASK,
            ..at.registers
        };
        assert_eq!(back.registers, expected);
        assert_eq!(back.mask, 0x1234);
        assert_eq!(back.fpu, f.fpu);
    }

    #[test]
    fn an_alternate_stack_is_used_once() {
        let alt = AltStack {
            base: 0x10_0000,
            size: 0x4000,
            flags: 0,
        };
        let action = Action {
            handler: 0x1000,
            flags: SA_ONSTACK,
            ..Action::DEFAULT
        };
        let mut at = Interrupted {
            registers: registers(),
            ..Interrupted::default()
        };
        let f = frame(&action, &Info::kernel(SIGSEGV), &at, &alt).unwrap();
        assert!(f.frame > alt.base && f.fpu + 512 <= alt.base + alt.size);
        assert_eq!(
            alt.to_bytes(f.registers.rsp)[8..12],
            SS_ONSTACK.to_le_bytes()
        );
        // A nested signal on the alternate stack goes below the current position.
        at.registers.rsp = f.registers.rsp;
        let nested = frame(&action, &Info::kernel(SIGSEGV), &at, &alt).unwrap();
        assert!(nested.fpu + 512 <= f.frame - RED_ZONE + 8);
    }

    #[test]
    fn a_frame_that_would_wrap_is_refused() {
        let mut at = Interrupted::default();
        at.registers.rsp = 100;
        assert!(
            frame(
                &Action::DEFAULT,
                &Info::kernel(SIGINT),
                &at,
                &AltStack::NONE
            )
            .is_none()
        );
    }

    #[test]
    fn defaults_follow_signal_7() {
        assert_eq!(default_action(SIGCHLD), Default::Ignore);
        assert_eq!(default_action(SIGSEGV), Default::Core);
        assert_eq!(default_action(SIGTSTP), Default::Stop);
        assert_eq!(default_action(SIGCONT), Default::Continue);
        assert_eq!(default_action(SIGTERM), Default::Terminate);
        assert_eq!(default_action(40), Default::Terminate);
        assert!(Action::DEFAULT.ignores(SIGWINCH));
        assert!(!Action::DEFAULT.ignores(SIGINT));
        assert!(Action::IGNORE.ignores(SIGINT));
        assert_eq!(name(SIGPIPE), "SIGPIPE");
    }
}
