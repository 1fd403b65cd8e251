//! The system-call ABI.
//!
//! Register convention (`syscall` instruction): `rax` = call number ([`Call`]); arguments in
//! `rdi`, `rsi`, `rdx`, `r10`, `r8`, `r9` (`r10` instead of `rcx`, which `syscall`
//! overwrites). On return `rax` = [`Error`] code (0 = success) and results, if any, in
//! `rdi`, `rsi`, `rdx`. `rcx` and `r11` are clobbered; all other registers, including the
//! FPU/SSE state, are preserved.
//!
//! Every call lists the [`Abilities`] it needs; a caller lacking one gets
//! [`Error::AbilityDenied`] and nothing changes.
//!
//! Root-task start convention: the kernel starts the first thread of the root task (syssw)
//! at its ELF entry with `rdi` = user address of the read-only mapped system image
//! ([`ROOT_SYSTEM_IMAGE_BASE`]), `rsi` = its size in bytes, and `rsp` =
//! [`ROOT_STACK_TOP`] - 8 (as if `call`ed, so the SysV stack alignment holds) in a
//! [`ROOT_STACK_SIZE`]-byte stack.

use bitflags::bitflags;

/// Where the kernel maps `system.img` (read-only) in the root task.
pub const ROOT_SYSTEM_IMAGE_BASE: u64 = 0x0000_7000_0000_0000;
/// Top of the root task's initial stack (exclusive).
pub const ROOT_STACK_TOP: u64 = 0x0000_7fff_ffff_0000;
pub const ROOT_STACK_SIZE: u64 = 64 * 1024;
/// Lowest address user mappings may use (page 0 stays unmapped to catch null pointers).
pub const USER_MIN: u64 = 0x1000;
/// One past the highest user address (the canonical lower half).
pub const USER_END: u64 = 0x0000_8000_0000_0000;

/// System-call numbers.
#[repr(u64)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Call {
    /// `debug_write(ptr, len)`: writes `len` (<= [`DEBUG_WRITE_MAX`]) bytes of UTF-8 text
    /// as one line of the kernel log, prefixed with the caller's task name.
    /// Ability: `DEBUG_LOG`. Errors: `BadAddress` (buffer not readable user memory),
    /// `InvalidArgument` (too long).
    DebugWrite = 1,
    /// `clock() -> ns`: nanoseconds since boot (monotonic) in `rdi`. Ability: none.
    Clock = 2,
    /// `thread_exit()`: ends the calling thread; does not return. Ability: none.
    ThreadExit = 3,
    /// `system_halt(outcome)`: stops the machine; `outcome` 0 = success, 1 = failure (under
    /// QEMU: exit 33 / 35). Ability: `SYSTEM_HALT`. Errors: `InvalidArgument`.
    SystemHalt = 4,
}

impl Call {
    pub fn from_raw(raw: u64) -> Option<Self> {
        Some(match raw {
            1 => Self::DebugWrite,
            2 => Self::Clock,
            3 => Self::ThreadExit,
            4 => Self::SystemHalt,
            _ => return None,
        })
    }
}

/// Longest text one `debug_write` accepts.
pub const DEBUG_WRITE_MAX: u64 = 512;

/// Error codes returned in `rax`.
#[repr(u64)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    Ok = 0,
    /// The call number does not exist.
    InvalidCall = 1,
    /// The caller's task lacks the ability the call needs.
    AbilityDenied = 2,
    /// An argument is out of range.
    InvalidArgument = 3,
    /// A buffer is not (entirely) mapped user memory with the rights the call needs.
    BadAddress = 4,
}

impl Error {
    pub fn from_raw(raw: u64) -> Option<Self> {
        Some(match raw {
            0 => Self::Ok,
            1 => Self::InvalidCall,
            2 => Self::AbilityDenied,
            3 => Self::InvalidArgument,
            4 => Self::BadAddress,
            _ => return None,
        })
    }
}

bitflags! {
    /// What a task may ask of the kernel. A child's set is a subset of its parent's.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub struct Abilities: u64 {
        const CREATE_TASK = 1 << 0;
        const CREATE_THREAD = 1 << 1;
        const MAP = 1 << 2;
        const PHYSICAL_MEMORY = 1 << 3;
        const IRQ = 1 << 4;
        const IO_PORTS = 1 << 5;
        const SCHEDULING = 1 << 6;
        const PARTITION_CONTROL = 1 << 7;
        const SYSTEM_HALT = 1 << 8;
        const DEBUG_LOG = 1 << 9;
        /// `syscall` reaches the kernel; without it every `syscall` is delivered to the
        /// thread's exception handler (paravirtualized guests).
        const NATIVE_SYSCALLS = 1 << 10;
    }
}
