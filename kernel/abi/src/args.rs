//! Which register carries which argument of each system call: written once, here, and used
//! by the kernel to decode a call and by the user runtime (`user/rt/src/sys.rs`) to encode
//! one. The meaning of each argument, the results and the errors are documented with the
//! call numbers in [`crate::syscall::Call`].
//!
//! Decoding is total (any register values give the argument struct): range and right checks
//! stay in the kernel's handler of each call, in the order that decides which error a call
//! with several bad arguments gets.

/// The six argument registers of the `syscall` convention (`rax` holds the call number).
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

macro_rules! call_args {
    ($( $(#[$meta:meta])* $name:ident { $($field:ident: $reg:ident),* $(,)? } )*) => {$(
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        pub struct $name {
            $(pub $field: u64,)*
        }

        impl $name {
            /// The arguments in `regs` (total: any register values decode).
            #[inline(always)]
            pub const fn decode(regs: &ArgRegs) -> Self {
                let _ = regs;
                Self { $($field: regs.$reg,)* }
            }

            /// The argument registers of this call (unused ones 0).
            #[inline(always)]
            pub const fn encode(&self) -> ArgRegs {
                #[allow(unused_mut)]
                let mut regs = ArgRegs { rdi: 0, rsi: 0, rdx: 0, r10: 0, r8: 0, r9: 0 };
                $(regs.$reg = self.$field;)*
                regs
            }
        }
    )*};
}

call_args! {
    /// `clock`, `thread_exit`, `yield`, `thread_self`.
    NoArgs {}
    /// `debug_write`.
    DebugWrite { ptr: rdi, len: rsi }
    /// `system_halt`.
    SystemHalt { outcome: rdi }
    /// `sleep_until`.
    SleepUntil { time: rdi }
    /// `task_create`.
    TaskCreate { abilities: rdi, mcp: rsi, rp: rdx, name_ptr: r10, name_len: r8 }
    /// `task_kill`, `task_stop`.
    TaskKill { task: rdi }
    /// `task_allow_send`.
    TaskAllowSend { from: rdi, to: rsi }
    /// `thread_create`.
    ThreadCreate { task: rdi, entry: rsi, stack: rdx, priority: r10, arg: r8 }
    /// `thread_start`, `thread_suspend`, `thread_resume`, `thread_kill`.
    OnThread { thread: rdi }
    /// `thread_set`.
    ThreadSet { thread: rdi, attribute: rsi, value: rdx }
    /// `thread_fpu`.
    ThreadFpu { thread: rdi, buffer: rsi, write: rdx }
    /// `map` (`source` = a page of the caller) and `map_physical` (`source` = a physical
    /// address).
    Map { task: rdi, source: rsi, destination: rdx, pages: r10, rights: r8 }
    /// `unmap`.
    Unmap { task: rdi, address: rsi, pages: rdx }
    /// `protect`.
    Protect { task: rdi, address: rsi, pages: rdx, rights: r10 }
    /// `send`, `receive`, `call`, `reply_wait`, `reply`: the peer (destination, sender to
    /// receive from, or caller to reply to), the time-out and the message (tag + 3 words);
    /// the received message comes back in the same registers.
    Ipc { peer: rdi, timeout: rsi, tag: rdx, word0: r10, word1: r8, word2: r9 }
    /// `notify_signal`.
    NotifySignal { thread: rdi, bits: rsi }
    /// `notify_wait`.
    NotifyWait { mask: rdi, timeout: rsi }
    /// `rp_create`.
    RpCreate { tasks: rdi, threads: rsi, pages: rdx }
    /// `rp_info`.
    RpInfo { rp: rdi }
    /// `set_health_monitor`.
    SetHealthMonitor { thread: rdi }
    /// `schedule_set`.
    ScheduleSet { slot: rdi, major_frame: rsi, windows: rdx, count: r10 }
    /// `schedule_switch`.
    ScheduleSwitch { slot: rdi }
    /// `partition_info`.
    PartitionInfo { partition: rdi }
    /// `io_grant`.
    IoGrant { task: rdi, first: rsi, count: rdx }
    /// `irq_grant`.
    IrqGrant { task: rdi, line: rsi }
    /// `irq_attach`.
    IrqAttach { line: rdi, bit: rsi }
    /// `irq_wait`.
    IrqWait { line: rdi, timeout: rsi }
    /// `irq_ack`, `irq_detach`.
    IrqLine { line: rdi }
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
            [m.peer, m.timeout, m.tag, m.word0, m.word1, m.word2],
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
    }
}
