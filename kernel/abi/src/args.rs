//! Which register carries which argument of each system call: written once, here, and used
//! by the kernel to decode a call and by the user runtime (`user/rt/src/sys.rs`) to encode
//! one; the same for the results of each call ([`results`], encoded by the kernel and decoded
//! by the user runtime). The meaning of each argument, the results and the errors are documented with the
//! call numbers in [`crate::syscall::Call`].
//!
//! Decoding is total (any register values give the argument struct): range and right checks
//! stay in the kernel's handler of each call, in the order that decides which error a call
//! with several bad arguments gets.

use crate::syscall::{TaskId, ThreadId};

/// The six argument registers of the `syscall` convention (`rax` holds the call number);
/// results come back in the same registers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArgRegs {
    pub rdi: u64,
    pub rsi: u64,
    pub rdx: u64,
    pub r10: u64,
    pub r8: u64,
    pub r9: u64,
}

impl ArgRegs {
    /// In register order: rdi, rsi, rdx, r10, r8, r9.
    pub const fn from_array([rdi, rsi, rdx, r10, r8, r9]: [u64; 6]) -> Self {
        Self {
            rdi,
            rsi,
            rdx,
            r10,
            r8,
            r9,
        }
    }

    /// In register order: rdi, rsi, rdx, r10, r8, r9.
    pub const fn to_array(self) -> [u64; 6] {
        [self.rdi, self.rsi, self.rdx, self.r10, self.r8, self.r9]
    }
}

/// A value one register carries: a plain word, an object identifier, a flag. Conversions
/// are total (any register value decodes), like the argument structs.
pub trait Register: Copy {
    fn from_reg(value: u64) -> Self;
    fn to_reg(self) -> u64;
}

impl Register for u64 {
    #[inline(always)]
    fn from_reg(value: u64) -> Self {
        value
    }
    #[inline(always)]
    fn to_reg(self) -> u64 {
        self
    }
}

impl Register for bool {
    #[inline(always)]
    fn from_reg(value: u64) -> Self {
        value != 0
    }
    #[inline(always)]
    fn to_reg(self) -> u64 {
        self as u64
    }
}

impl Register for ThreadId {
    #[inline(always)]
    fn from_reg(value: u64) -> Self {
        Self(value)
    }
    #[inline(always)]
    fn to_reg(self) -> u64 {
        self.0
    }
}

impl Register for TaskId {
    #[inline(always)]
    fn from_reg(value: u64) -> Self {
        Self(value)
    }
    #[inline(always)]
    fn to_reg(self) -> u64 {
        self.0
    }
}

/// Defines one struct per call (or per group of calls with the same registers) whose
/// fields say which register carries which value, and its `decode` (registers to struct)
/// and `encode` (struct to registers, unused ones 0).
macro_rules! register_structs {
    ($( $(#[$meta:meta])* $name:ident { $($field:ident: $ty:ty = $reg:ident),* $(,)? } )*) => {$(
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        pub struct $name {
            $(pub $field: $ty,)*
        }

        impl $name {
            /// The values in `regs` (total: any register values decode).
            #[inline(always)]
            pub fn decode(regs: &ArgRegs) -> Self {
                let _ = regs;
                Self { $($field: Register::from_reg(regs.$reg),)* }
            }

            /// The registers of these values (unused ones 0).
            #[inline(always)]
            pub fn encode(&self) -> ArgRegs {
                #[allow(unused_mut)]
                let mut regs = ArgRegs::default();
                self.encode_into(&mut regs);
                regs
            }

            /// Writes these values into their registers of `regs`, leaving the others.
            #[inline(always)]
            pub fn encode_into(&self, regs: &mut ArgRegs) {
                let _ = regs;
                $(regs.$reg = Register::to_reg(self.$field);)*
            }
        }
    )*};
}

/// The arguments of each call: `field: type = register`.
macro_rules! call_args {
    ($($body:tt)*) => { register_structs! { $($body)* } };
}

/// The results of each call that has any, in the argument registers after the call returned
/// `Ok` (`field: type = register`): the kernel encodes them into the caller's registers
/// (only those listed change), the user runtime decodes them.
macro_rules! call_results {
    ($($body:tt)*) => {
        /// Call results, named after the call that returns them.
        pub mod results {
            use super::*;
            register_structs! { $($body)* }
        }
    };
}

call_args! {
    /// `clock`, `thread_exit`, `yield`, `thread_self`.
    NoArgs {}
    /// `debug_write`.
    DebugWrite { ptr: u64 = rdi, len: u64 = rsi }
    /// `system_halt`.
    SystemHalt { outcome: u64 = rdi }
    /// `sleep_until`.
    SleepUntil { time: u64 = rdi }
    /// `task_create`.
    TaskCreate { abilities: u64 = rdi, mcp: u64 = rsi, rp: u64 = rdx, name_ptr: u64 = r10, name_len: u64 = r8 }
    /// `task_kill`, `task_stop`.
    TaskKill { task: TaskId = rdi }
    /// `task_allow_send`.
    TaskAllowSend { from: TaskId = rdi, to: TaskId = rsi, notify_only: u64 = rdx }
    /// `thread_create`.
    ThreadCreate { task: TaskId = rdi, entry: u64 = rsi, stack: u64 = rdx, priority: u64 = r10, arg: u64 = r8 }
    /// `thread_start`, `thread_suspend`, `thread_resume`, `thread_kill`, `thread_interrupt`.
    OnThread { thread: ThreadId = rdi }
    /// `thread_set`.
    ThreadSet { thread: ThreadId = rdi, attribute: u64 = rsi, value: u64 = rdx }
    /// `thread_fpu`.
    ThreadFpu { thread: ThreadId = rdi, buffer: u64 = rsi, write: u64 = rdx }
    /// `map` (`source` = a page of the caller), `map_physical` and `map_device` (`source` =
    /// a physical address).
    Map { task: TaskId = rdi, source: u64 = rsi, destination: u64 = rdx, pages: u64 = r10, rights: u64 = r8 }
    /// `unmap`.
    Unmap { task: TaskId = rdi, address: u64 = rsi, pages: u64 = rdx }
    /// `protect`.
    Protect { task: TaskId = rdi, address: u64 = rsi, pages: u64 = rdx, rights: u64 = r10 }
    /// `send`, `receive`, `call`, `reply_wait`, `reply`: the peer (destination, sender to
    /// receive from, or caller to reply to), the time-out and the message (tag + 3 words);
    /// the received message comes back in the same registers ([`results::Ipc`]).
    Ipc { peer: ThreadId = rdi, timeout: u64 = rsi, tag: u64 = rdx, word0: u64 = r10, word1: u64 = r8, word2: u64 = r9 }
    /// `notify_signal`.
    NotifySignal { thread: ThreadId = rdi, bits: u64 = rsi }
    /// `notify_wait`.
    NotifyWait { mask: u64 = rdi, timeout: u64 = rsi }
    /// `rp_create`.
    RpCreate { tasks: u64 = rdi, threads: u64 = rsi, pages: u64 = rdx, cpus: u64 = r10 }
    /// `rp_info`.
    RpInfo { rp: u64 = rdi }
    /// `set_health_monitor`.
    SetHealthMonitor { thread: ThreadId = rdi }
    /// `schedule_set`: `count` [`WindowSpec`](crate::syscall::WindowSpec)s at `windows`.
    ScheduleSet { slot: u64 = rdi, major_frame: u64 = rsi, windows: u64 = rdx, count: u64 = r10 }
    /// `schedule_switch`.
    ScheduleSwitch { slot: u64 = rdi }
    /// `partition_info`.
    PartitionInfo { partition: u64 = rdi }
    /// `io_grant`.
    IoGrant { task: TaskId = rdi, first: u64 = rsi, count: u64 = rdx }
    /// `irq_grant`.
    IrqGrant { task: TaskId = rdi, line: u64 = rsi }
    /// `irq_attach`.
    IrqAttach { line: u64 = rdi, bit: u64 = rsi }
    /// `irq_wait`.
    IrqWait { line: u64 = rdi, timeout: u64 = rsi }
    /// `irq_ack`, `irq_detach`.
    IrqLine { line: u64 = rdi }
    /// `pci_config`.
    PciConfig { address: u64 = rdi, value: u64 = rsi, write: u64 = rdx }
    /// `dma_map`.
    DmaMap { source: u64 = rdi, physical: u64 = rsi, pages: u64 = rdx }
}

/// Thread and task counts of a resource partition, 16 bits each in one register.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RpCounts {
    pub threads_used: u16,
    pub threads_quota: u16,
    pub tasks_used: u16,
    pub tasks_quota: u16,
}

impl Register for RpCounts {
    #[inline(always)]
    fn from_reg(v: u64) -> Self {
        Self {
            threads_used: v as u16,
            threads_quota: (v >> 16) as u16,
            tasks_used: (v >> 32) as u16,
            tasks_quota: (v >> 48) as u16,
        }
    }
    #[inline(always)]
    fn to_reg(self) -> u64 {
        self.threads_used as u64
            | (self.threads_quota as u64) << 16
            | (self.tasks_used as u64) << 32
            | (self.tasks_quota as u64) << 48
    }
}

call_results! {
    /// `clock`: ns since boot, the TSC frequency (Hz), the TSC at boot and the wall clock
    /// (Unix ns) at boot (0 = unknown).
    Clock { ns: u64 = rdi, tsc_hz: u64 = rsi, boot_tsc: u64 = rdx, wall_clock_at_boot: u64 = r10 }
    /// `task_create`: the new task.
    TaskCreate { task: TaskId = rdi }
    /// `thread_create`: the new thread.
    ThreadCreate { thread: ThreadId = rdi }
    /// `thread_interrupt`: whether the thread was interrupted.
    ThreadInterrupt { interrupted: bool = rdi }
    /// `thread_self`: the calling thread and its task.
    ThreadSelf { thread: ThreadId = rdi, task: TaskId = rsi }
    /// `receive`, `call`, `reply_wait`: the sender, its task (set by the kernel) and the
    /// message (tag + 3 words).
    Ipc { sender: ThreadId = rdi, sender_task: TaskId = rsi, tag: u64 = rdx, word0: u64 = r10, word1: u64 = r8, word2: u64 = r9 }
    /// `notify_wait`: the bits of the mask that were set (now cleared).
    NotifyWait { bits: u64 = rdi }
    /// `rp_create`: the new resource partition's number.
    RpCreate { rp: u64 = rdi }
    /// `rp_info`: page use and quota, thread and task counts, CPU mask.
    RpInfo { pages_used: u64 = rdi, pages_quota: u64 = rsi, counts: RpCounts = rdx, cpus: u64 = r10 }
    /// `schedule_switch`: when the schedule takes effect (ns since boot).
    ScheduleSwitch { at: u64 = rdi }
    /// `partition_info`: see [`Call::PartitionInfo`](crate::syscall::Call::PartitionInfo).
    PartitionInfo { active: u64 = rdi, window_start: u64 = rsi, window_length: u64 = rdx, cpu_ns: u64 = r10, idle_ns: u64 = r8, frames: u64 = r9 }
    /// `pci_config`: the dword read (0 after a write).
    PciConfig { value: u64 = rdi }
    /// `dma_map`: the bus address of the first frame.
    DmaMap { bus_address: u64 = rdi }
    /// `dma_fault`: see [`Call::DmaFault`](crate::syscall::Call::DmaFault).
    DmaFault { source: u64 = rdi, address: u64 = rsi, reason: u64 = rdx, write: u64 = r10 }
}

#[cfg(test)]
mod tests {
    use super::*;

    const REGS: ArgRegs = ArgRegs::from_array([1, 2, 3, 4, 5, 6]);

    #[test]
    fn fields_take_distinct_registers_in_order() {
        assert_eq!(REGS.to_array(), [1, 2, 3, 4, 5, 6]);
        let a = TaskCreate::decode(&REGS);
        assert_eq!(
            [a.abilities, a.mcp, a.rp, a.name_ptr, a.name_len],
            [1, 2, 3, 4, 5]
        );
        let m = Ipc::decode(&REGS);
        assert_eq!(
            [m.peer.0, m.timeout, m.tag, m.word0, m.word1, m.word2],
            [1, 2, 3, 4, 5, 6]
        );
        let s = ScheduleSet::decode(&REGS);
        assert_eq!([s.slot, s.major_frame, s.windows, s.count], [1, 2, 3, 4]);
    }

    #[test]
    fn encode_and_decode_agree() {
        // Every struct: decoding what it encoded gives it back, and encoding what was decoded
        // keeps exactly the registers it uses.
        fn check<T: Copy + PartialEq + core::fmt::Debug>(
            decode: fn(&ArgRegs) -> T,
            encode: fn(&T) -> ArgRegs,
        ) {
            let value = decode(&REGS);
            assert_eq!(decode(&encode(&value)), value);
            let used = encode(&value).to_array();
            for (register, (&got, want)) in used.iter().zip(REGS.to_array()).enumerate() {
                assert!(got == 0 || got == want, "register {register}");
            }
        }
        check(NoArgs::decode, NoArgs::encode);
        check(DebugWrite::decode, DebugWrite::encode);
        check(SystemHalt::decode, SystemHalt::encode);
        check(SleepUntil::decode, SleepUntil::encode);
        check(TaskCreate::decode, TaskCreate::encode);
        check(TaskKill::decode, TaskKill::encode);
        check(TaskAllowSend::decode, TaskAllowSend::encode);
        check(ThreadCreate::decode, ThreadCreate::encode);
        check(OnThread::decode, OnThread::encode);
        check(ThreadSet::decode, ThreadSet::encode);
        check(ThreadFpu::decode, ThreadFpu::encode);
        check(Map::decode, Map::encode);
        check(Unmap::decode, Unmap::encode);
        check(Protect::decode, Protect::encode);
        check(Ipc::decode, Ipc::encode);
        check(NotifySignal::decode, NotifySignal::encode);
        check(NotifyWait::decode, NotifyWait::encode);
        check(RpCreate::decode, RpCreate::encode);
        check(RpInfo::decode, RpInfo::encode);
        check(SetHealthMonitor::decode, SetHealthMonitor::encode);
        check(ScheduleSet::decode, ScheduleSet::encode);
        check(ScheduleSwitch::decode, ScheduleSwitch::encode);
        check(PartitionInfo::decode, PartitionInfo::encode);
        check(IoGrant::decode, IoGrant::encode);
        check(IrqGrant::decode, IrqGrant::encode);
        check(IrqAttach::decode, IrqAttach::encode);
        check(IrqWait::decode, IrqWait::encode);
        check(IrqLine::decode, IrqLine::encode);
        check(results::Clock::decode, results::Clock::encode);
        check(results::TaskCreate::decode, results::TaskCreate::encode);
        check(results::ThreadCreate::decode, results::ThreadCreate::encode);
        check(results::ThreadSelf::decode, results::ThreadSelf::encode);
        check(
            results::ThreadInterrupt::decode,
            results::ThreadInterrupt::encode,
        );
        check(results::Ipc::decode, results::Ipc::encode);
        check(results::NotifyWait::decode, results::NotifyWait::encode);
        check(results::RpCreate::decode, results::RpCreate::encode);
        check(results::RpInfo::decode, results::RpInfo::encode);
        check(
            results::ScheduleSwitch::decode,
            results::ScheduleSwitch::encode,
        );
        check(
            results::PartitionInfo::decode,
            results::PartitionInfo::encode,
        );
    }

    #[test]
    fn results_change_only_their_registers() {
        let mut regs = REGS;
        results::ThreadSelf {
            thread: ThreadId(10),
            task: TaskId(20),
        }
        .encode_into(&mut regs);
        assert_eq!(regs.to_array(), [10, 20, 3, 4, 5, 6]);
        let counts = RpCounts {
            threads_used: 1,
            threads_quota: 2,
            tasks_used: 3,
            tasks_quota: 4,
        };
        assert_eq!(counts.to_reg(), 1 | 2 << 16 | 3 << 32 | 4 << 48);
        assert_eq!(RpCounts::from_reg(counts.to_reg()), counts);
    }
}
