//! The native execution tier's run-time side: what code translated from a verified image
//! calls (the translator is the host crate `plc-native`, whose module documentation explains
//! the route), and the contract between such code and a [`Machine`](crate::vm::Machine)
//! ([`Machine::run_cycle_native`](crate::vm::Machine::run_cycle_native)).
//!
//! A translated program is a [`NativeProgram`]: the image it was translated from (byte for
//! byte) and one function that runs one cycle of a task over the machine's data memory. That
//! function keeps the operand-stack cells of every POU activation in Rust locals (the
//! verifier proved each instruction's stack depth static) and turns jumps into a state
//! machine of basic blocks; everything that is not specific to one image lives here, once:
//!
//! * **Counting** ([`Cycle::fuel`], [`Cycle::event`]): the cycle's instructions are counted
//!   as the interpreter counts them. `fuel` is the number of instructions that may run
//!   before the next *event*: the instruction budget (trap WATCHDOG) or a deadline check
//!   (every [`DEADLINE_CHECK_EVERY`] instructions the clock is asked, trap DEADLINE), at
//!   exactly the instruction where `Machine::run_cycle_until` asks. A basic block of `L`
//!   instructions runs straight through when `fuel >= L` (one compare per block); otherwise
//!   its *checked* copy runs it instruction by instruction and handles the event at its
//!   exact instruction. A trap inside a block gives back the fuel of the instructions after
//!   it.
//! * **Try frames and unwinding** ([`Cycle::try_begin`], [`Cycle::catch`]): the interpreter's
//!   try frames in the machine's try memory, with the same limits; a trap is delivered to the
//!   innermost frame (the stack cut back to the frame's depth, the trap code pushed), passed
//!   to the calling activation when the frame is an outer one ([`Unwind::Outer`]), or becomes
//!   the cycle's fault.
//! * **The state of a fault**: the activation that decides the fault and every activation
//!   below it write their live cells into the machine's operand stack ([`Cycle::spill`]), so
//!   the machine holds the stack, `pc`, call and try depth the interpreter would hold.
//! * **Value operations** whose exact semantics are the interpreter's (shifts, rotates,
//!   widths, memory access): [`ops`].
//!
//! This module must never execute anything itself or trust a program: the code only ever
//! comes from the translation of an image that passed the verifier, the runtime only runs it
//! for that image ([`NativeProgram::is_translation_of`]), and every dynamic data access is
//! checked here exactly as the interpreter checks it.

use crate::image::{Dispatch, Image};
use crate::isa::{MemType, Trap};
use crate::vm::{DEADLINE_CHECK_EVERY, TryFrame};

/// A program translated to native code (what the translator's generated module exports).
pub struct NativeProgram {
    /// The bytecode image the code was translated from.
    pub image: &'static [u8],
    /// A 64-bit FNV-1a hash of `image` (for log lines; [`image_hash`]).
    pub hash: u64,
    /// Runs one cycle of task `task` over data memory `data` (exactly the image's data size).
    /// `Ok` when the task's final `RET` ran; `Err` when the cycle faulted (the fault is in
    /// the [`Cycle`]).
    pub run: fn(&mut Cycle<'_>, &mut [u8], usize) -> Result<(), Unwind>,
}

impl NativeProgram {
    /// Whether this is the translation of exactly `image` (byte for byte).
    pub fn is_translation_of(&self, image: &[u8]) -> bool {
        self.image == image
    }
}

impl core::fmt::Debug for NativeProgram {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "NativeProgram({} bytes, hash {:016x})",
            self.image.len(),
            self.hash
        )
    }
}

/// The 64-bit FNV-1a hash of an image (what [`NativeProgram::hash`] records and the build and
/// the runtime print).
pub const fn image_hash(bytes: &[u8]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

/// Why a POU activation returns early.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unwind {
    /// A trap ([`Cycle::raised`]) goes to a try frame of a calling activation.
    Outer,
    /// The cycle faulted ([`Cycle::fault`]); every activation writes its live cells into the
    /// stack on its way out.
    Fault,
}

/// What [`Cycle::catch`] decided for a trap.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Catch {
    /// Delivered to a frame of this activation: cut its stack back to `depth` cells, put
    /// `code` in cell `depth` and continue at code offset `handler`.
    Deliver {
        /// The handler's code offset.
        handler: u32,
        /// This activation's stack depth at the frame's TRY_BEGIN.
        depth: u32,
        /// The trap code the handler finds on top of the stack.
        code: u64,
    },
    /// A frame of a calling activation takes it: return [`Unwind::Outer`].
    Outer,
    /// Nothing catches it: this activation's cells `0..depth` are live; spill them and
    /// return [`Unwind::Fault`].
    Fault {
        /// Live cells of this activation.
        depth: u32,
    },
}

/// The state of a fault, as the interpreter would leave it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NativeFault {
    /// The trap.
    pub trap: Trap,
    /// Code offset of the trapping instruction.
    pub pc: u32,
    /// Operand-stack depth.
    pub sp: u32,
    /// Call depth.
    pub call_depth: u32,
}

/// What a cycle left behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CycleEnd {
    /// Instructions executed (as the interpreter counts them).
    pub executed: u32,
    /// Traps caught by try frames.
    pub caught: u32,
    /// Code offset of the last `RET` executed.
    pub ret_pc: u32,
    /// Open try frames.
    pub try_depth: u32,
    /// The fault, if the cycle faulted.
    pub fault: Option<NativeFault>,
}

/// The state of one native cycle: counting, limits, try frames, the fault.
pub struct Cycle<'c> {
    image: &'c Image<'c>,
    stack: &'c mut [u64],
    tries: &'c mut [TryFrame],
    expired: &'c mut dyn FnMut() -> bool,
    now: i64,
    stack_limit: u32,
    call_limit: u32,
    budget: u32,
    /// Instructions that may run before the next event.
    fuel: u32,
    /// Index (instructions executed before it) of the next event.
    event_at: u32,
    call_depth: u32,
    try_depth: u32,
    caught: u32,
    ret_pc: u32,
    raised: (Trap, u32),
    fault: Option<NativeFault>,
}

impl<'c> Cycle<'c> {
    /// A cycle at `now_ns` with `budget` instructions, over the machine's operand stack and
    /// try memory, `call_limit` call frames (the task's activation is the first) and the
    /// deadline check `expired`.
    #[inline]
    pub(crate) fn new(
        image: &'c Image<'c>,
        stack: &'c mut [u64],
        call_limit: usize,
        tries: &'c mut [TryFrame],
        expired: &'c mut dyn FnMut() -> bool,
        now_ns: i64,
        budget: u32,
    ) -> Self {
        let first_event = budget.min(DEADLINE_CHECK_EVERY - 1);
        Cycle {
            image,
            stack_limit: u32::try_from(stack.len()).unwrap_or(u32::MAX),
            stack,
            tries,
            expired,
            now: now_ns,
            call_limit: u32::try_from(call_limit).unwrap_or(u32::MAX),
            budget,
            fuel: first_event,
            event_at: first_event,
            call_depth: 1,
            try_depth: 0,
            caught: 0,
            ret_pc: 0,
            raised: (Trap::InvalidAddress, 0),
            fault: None,
        }
    }

    /// What the cycle left behind.
    #[inline]
    pub(crate) fn end(&self) -> CycleEnd {
        CycleEnd {
            executed: self.event_at - self.fuel,
            caught: self.caught,
            ret_pc: self.ret_pc,
            try_depth: self.try_depth,
            fault: self.fault,
        }
    }

    /// Instructions that may run before the next event (an activation keeps it in a local
    /// and hands it back with [`set_fuel`](Self::set_fuel) before a call, a trap, a return).
    #[inline(always)]
    pub fn fuel(&self) -> u32 {
        self.fuel
    }

    /// Records the instructions left before the next event.
    #[inline(always)]
    pub fn set_fuel(&mut self, fuel: u32) {
        self.fuel = fuel;
    }

    /// The event due before the next instruction (the fuel is 0): at instruction index
    /// `event_at`, the budget (`Err(WATCHDOG)`) or a deadline check, which asks the clock
    /// (`Err(DEADLINE)` when it says the time is up; the instruction then does not run and is
    /// not counted), as the interpreter does at indices `k` with
    /// `k % DEADLINE_CHECK_EVERY == DEADLINE_CHECK_EVERY - 1`. `Ok` with the fuel up to the
    /// next event.
    #[cold]
    #[inline(never)]
    pub fn event(&mut self) -> Result<u32, Trap> {
        self.fuel = 0;
        if self.event_at >= self.budget {
            return Err(Trap::Watchdog);
        }
        if (self.expired)() {
            return Err(Trap::Deadline);
        }
        let next = self
            .event_at
            .saturating_add(DEADLINE_CHECK_EVERY)
            .min(self.budget);
        self.fuel = next - self.event_at;
        self.event_at = next;
        Ok(self.fuel)
    }

    /// Operand-stack cells left above absolute depth `sp0` (an activation's first cell).
    #[inline(always)]
    pub fn room(&self, sp0: u32) -> u32 {
        self.stack_limit.saturating_sub(sp0)
    }

    /// The cycle time (`NOW`).
    #[inline(always)]
    pub fn now(&self) -> u64 {
        self.now as u64
    }

    /// The current call depth (the task's activation is 1).
    #[inline(always)]
    pub fn call_depth(&self) -> u32 {
        self.call_depth
    }

    /// Whether a CALL finds a free call frame (else it traps CALL_DEPTH).
    #[inline(always)]
    pub fn can_enter(&self) -> bool {
        self.call_depth < self.call_limit
    }

    /// Enters a callee (after [`can_enter`](Self::can_enter)).
    #[inline(always)]
    pub fn enter(&mut self) {
        self.call_depth += 1;
    }

    /// Back from a callee (its `RET`).
    #[inline(always)]
    pub fn leave(&mut self) {
        self.call_depth -= 1;
    }

    /// Back in the activation at call depth `depth` after a callee unwound.
    #[inline(always)]
    pub fn resume_at(&mut self, depth: u32) {
        self.call_depth = depth;
    }

    /// Records the code offset of a `RET` (after the task's final one, the machine's `pc`).
    #[inline(always)]
    pub fn ret(&mut self, pc: u32) {
        self.ret_pc = pc;
    }

    /// TRY_BEGIN: opens a try frame of the activation at the current call depth whose stack
    /// holds `sp` cells in all (its first cell's absolute depth plus its own); `false` (trap
    /// STACK_OVERFLOW) when the try memory is full.
    #[inline]
    pub fn try_begin(&mut self, handler: u32, sp: u32, base: u32) -> bool {
        let Some(slot) = self.tries.get_mut(self.try_depth as usize) else {
            return false;
        };
        *slot = TryFrame {
            handler,
            stack_depth: sp,
            call_depth: self.call_depth,
            base,
        };
        self.try_depth += 1;
        true
    }

    /// TRY_END: closes the innermost try frame.
    #[inline(always)]
    pub fn try_end(&mut self) {
        self.try_depth = self.try_depth.saturating_sub(1);
    }

    /// The trap a callee passed on with [`Unwind::Outer`] and its code offset.
    #[inline(always)]
    pub fn raised(&self) -> (Trap, u32) {
        self.raised
    }

    /// The fault, once the cycle faulted.
    pub fn fault(&self) -> Option<NativeFault> {
        self.fault
    }

    /// Unwinds `trap`, raised at code offset `pc` in the activation at call depth `me` whose
    /// first cell is at absolute depth `sp0` and whose stack holds `depth` cells before the
    /// trapping instruction — the interpreter's `catch`: the innermost try frame takes it
    /// (stack cut back to the frame's depth, the code pushed; a trap raised by that push goes
    /// to the next frame), WATCHDOG and DEADLINE are never caught.
    #[cold]
    #[inline(never)]
    pub fn catch(&mut self, trap: Trap, pc: u32, me: u32, sp0: u32, depth: u32) -> Catch {
        let (mut trap, mut depth) = (trap, depth);
        loop {
            if !trap.is_catchable() || self.try_depth == 0 {
                self.fault = Some(NativeFault {
                    trap,
                    pc,
                    sp: sp0.saturating_add(depth),
                    call_depth: me,
                });
                return Catch::Fault { depth };
            }
            let frame = self.tries[self.try_depth as usize - 1];
            if frame.call_depth < me {
                self.raised = (trap, pc);
                return Catch::Outer;
            }
            self.try_depth -= 1;
            self.call_depth = me;
            depth = frame.stack_depth.saturating_sub(sp0);
            if frame.stack_depth >= self.stack_limit {
                trap = Trap::StackOverflow;
                continue;
            }
            self.caught += 1;
            return Catch::Deliver {
                handler: frame.handler,
                depth,
                code: trap.code() as u64,
            };
        }
    }

    /// Writes an activation's live cells (`cells[..live]`, its first cell at absolute depth
    /// `sp0`) into the machine's operand stack.
    #[cold]
    pub fn spill(&mut self, sp0: u32, cells: &[u64], live: u32) {
        let live = (live as usize).min(cells.len());
        let start = sp0 as usize;
        if let Some(slots) = self.stack.get_mut(start..start.saturating_add(live)) {
            slots.copy_from_slice(&cells[..live]);
        }
    }

    /// REF_MAKE: a reference to the smallest object holding the `size` bytes at `address`
    /// (`None`: INVALID_REFERENCE), as the interpreter makes it.
    #[inline]
    pub fn ref_make(&self, address: u64, size: u32) -> Option<u64> {
        let object = self.image.object_containing(address, size as u64)?;
        Some(address | ((object as u64 + 1) << 32))
    }

    /// REF_CHECK: the address of an access of `size` bytes through `reference` when it lies
    /// inside the object the reference names (`None`: INVALID_REFERENCE).
    #[inline]
    pub fn ref_check(&self, reference: u64, size: u32) -> Option<u64> {
        let address = reference & 0xFFFF_FFFF;
        let (start, len) = self
            .image
            .object(((reference >> 32).checked_sub(1)?) as usize)?;
        (start as u64 <= address && address + size as u64 <= start as u64 + len as u64)
            .then_some(address)
    }

    /// CALL_VIRT / VIRT_FRAME: the method the class of `instance` runs for `slot` (`None`:
    /// INVALID_REFERENCE: a NULL instance, a class id outside data memory, an unknown
    /// class or no method for the slot).
    #[inline]
    pub fn method(&self, data: &[u8], instance: u64, slot: u16) -> Option<Dispatch> {
        if instance == 0 {
            return None;
        }
        let class = ops::load(data, usize::try_from(instance).ok()?, MemType::U32)?;
        self.image.lookup_method(class, slot)
    }

    /// A fault before any instruction ran (data memory of the wrong size: the program is not
    /// this image's translation).
    pub fn refuse(&mut self, pc: u32) -> Unwind {
        self.fault = Some(NativeFault {
            trap: Trap::InvalidAddress,
            pc,
            sp: 0,
            call_depth: 1,
        });
        Unwind::Fault
    }
}

/// Value operations with the interpreter's exact semantics (`vm.rs`, `Machine::step`), for
/// the generated code. Loads and stores return `None` where the interpreter traps
/// INVALID_ADDRESS.
pub mod ops {
    use crate::isa::{MemType, Trap};

    /// SHL: `n >= 64` gives 0.
    #[inline(always)]
    pub fn shl(a: u64, n: u64) -> u64 {
        a.checked_shl(n.min(64) as u32).unwrap_or(0)
    }

    /// SHR_U: `n >= 64` gives 0.
    #[inline(always)]
    pub fn shr_u(a: u64, n: u64) -> u64 {
        a.checked_shr(n.min(64) as u32).unwrap_or(0)
    }

    /// SHR_S: `n >= 64` gives the sign fill.
    #[inline(always)]
    pub fn shr_s(a: u64, n: u64) -> u64 {
        ((a as i64) >> n.min(63)) as u64
    }

    /// ROL/ROR of the low `width` bits.
    #[inline(always)]
    pub fn rotate(a: u64, n: u64, width: u32, left: bool) -> u64 {
        crate::vm::rotate(a, n, width, left)
    }

    /// SEXT `width`.
    #[inline(always)]
    pub fn sext(a: u64, width: u32) -> u64 {
        let shift = 64 - width;
        (((a << shift) as i64) >> shift) as u64
    }

    /// ZEXT `width`.
    #[inline(always)]
    pub fn zext(a: u64, width: u32) -> u64 {
        let shift = 64 - width;
        (a << shift) >> shift
    }

    /// The f32 in a cell.
    #[inline(always)]
    pub fn f32_of(cell: u64) -> f32 {
        f32::from_bits(cell as u32)
    }

    /// A cell holding an f32.
    #[inline(always)]
    pub fn f32_cell(v: f32) -> u64 {
        v.to_bits() as u64
    }

    /// The cell of a REAL `+ - * /` result (a NaN canonical, as in the interpreter).
    pub use crate::isa::real_result;

    /// The cell of an LREAL `+ - * /` result (a NaN canonical, as in the interpreter).
    pub use crate::isa::lreal_result;

    /// The f64 in a cell.
    #[inline(always)]
    pub fn f64_of(cell: u64) -> f64 {
        f64::from_bits(cell)
    }

    /// A cell holding an f64.
    #[inline(always)]
    pub fn f64_cell(v: f64) -> u64 {
        v.to_bits()
    }

    /// Loads a cell of type `ty` from `data[at..]`; `None` outside data memory.
    #[inline(always)]
    pub fn load(data: &[u8], at: usize, ty: MemType) -> Option<u64> {
        Some(match ty {
            MemType::I8 => *data.get(at)? as i8 as i64 as u64,
            MemType::U8 => *data.get(at)? as u64,
            MemType::I16 => i16::from_le_bytes(bytes(data, at)?) as i64 as u64,
            MemType::U16 => u16::from_le_bytes(bytes(data, at)?) as u64,
            MemType::I32 => i32::from_le_bytes(bytes(data, at)?) as i64 as u64,
            MemType::U32 | MemType::F32 => u32::from_le_bytes(bytes(data, at)?) as u64,
            MemType::I64 | MemType::U64 | MemType::F64 => u64::from_le_bytes(bytes(data, at)?),
        })
    }

    /// Stores the low bytes of `value` (the type's width) at `data[at..]`; `None` (nothing
    /// written) outside data memory.
    #[inline(always)]
    pub fn store(data: &mut [u8], at: usize, ty: MemType, value: u64) -> Option<()> {
        let raw = value.to_le_bytes();
        match ty.width() {
            1 => *data.get_mut(at)? = raw[0],
            2 => data
                .get_mut(at..at.checked_add(2)?)?
                .copy_from_slice(&raw[..2]),
            4 => data
                .get_mut(at..at.checked_add(4)?)?
                .copy_from_slice(&raw[..4]),
            _ => data.get_mut(at..at.checked_add(8)?)?.copy_from_slice(&raw),
        }
        Some(())
    }

    /// LD_IND/ST_IND's address: `addr + off`, `None` where the interpreter traps.
    #[inline(always)]
    fn address(addr: u64, off: u32) -> Option<usize> {
        usize::try_from(addr.checked_add(off as u64)?).ok()
    }

    /// LD_IND: loads from `addr + off`.
    #[inline(always)]
    pub fn load_at(data: &[u8], addr: u64, off: u32, ty: MemType) -> Option<u64> {
        load(data, address(addr, off)?, ty)
    }

    /// ST_IND: stores at `addr + off`.
    #[inline(always)]
    pub fn store_at(data: &mut [u8], addr: u64, off: u32, ty: MemType, value: u64) -> Option<()> {
        store(data, address(addr, off)?, ty, value)
    }

    /// The `W` bytes at static address `at`, which the verifier proved inside the `N` bytes
    /// of data memory (LD_ABS).
    #[inline(always)]
    pub fn ld<const N: usize, const W: usize>(data: &[u8; N], at: usize) -> [u8; W] {
        let mut raw = [0u8; W];
        raw.copy_from_slice(&data[at..at + W]);
        raw
    }

    /// Stores the low `W` bytes of `value` at static address `at`, which the verifier
    /// proved inside the `N` bytes of data memory (ST_ABS).
    #[inline(always)]
    pub fn st<const N: usize, const W: usize>(data: &mut [u8; N], at: usize, value: u64) {
        data[at..at + W].copy_from_slice(&value.to_le_bytes()[..W]);
    }

    /// The trap of a generated site table entry: the trap with `code`, or `dynamic` for 0.
    #[inline]
    pub fn site_trap(code: u8, dynamic: Trap) -> Trap {
        Trap::from_u64(code as u64).unwrap_or(dynamic)
    }

    /// The trap RETHROW raises for a nonzero code: the code's trap if it is a catchable
    /// one, else NUMERIC_ERROR.
    #[inline]
    pub fn rethrown(code: u64) -> Trap {
        match Trap::from_u64(code) {
            Some(trap) if trap.is_catchable() => trap,
            _ => Trap::NumericError,
        }
    }

    #[inline(always)]
    fn bytes<const N: usize>(data: &[u8], at: usize) -> Option<[u8; N]> {
        let mut raw = [0u8; N];
        raw.copy_from_slice(data.get(at..at.checked_add(N)?)?);
        Some(raw)
    }

    /// COPY: `len` bytes from `src` to `dst` (memmove); `None` (nothing copied) when either
    /// range leaves data memory.
    #[inline]
    pub fn copy(data: &mut [u8], dst: u64, src: u64, len: u32) -> Option<()> {
        let len = len as u64;
        let end = data.len() as u64;
        if dst.checked_add(len)? > end || src.checked_add(len)? > end {
            return None;
        }
        let (dst, src, len) = (dst as usize, src as usize, len as usize);
        data.copy_within(src..src + len, dst);
        Some(())
    }
}

#[cfg(test)]
mod tests {
    //! The machine's side of a native cycle, with stand-ins for translated code (the
    //! translations themselves are checked against the model by `plc-native`'s tests).
    use super::*;
    use crate::image::{Image, VarType};
    use crate::tests::program_with;
    use crate::verify::verify;
    use crate::vm::{CallFrame, Machine, Memory, TryFrame, Value};
    use alloc::vec;
    use core::sync::atomic::{AtomicU8, Ordering};

    /// What the stand-in saw in `x` when it ran.
    static SEEN: AtomicU8 = AtomicU8::new(0);

    /// Records `x` (data byte 8) and writes 7 into it, as the program `x := 7` would.
    fn writes_seven(cx: &mut Cycle<'_>, data: &mut [u8], _: usize) -> Result<(), Unwind> {
        SEEN.store(data[8], Ordering::Relaxed);
        data[8] = 7;
        cx.ret(42);
        Ok(())
    }

    #[test]
    fn forces_apply_around_a_native_cycle_and_the_monitor_reads_its_data() {
        let bytes = program_with(100, |b, _| {
            b.push_i32(7);
            b.st_abs(MemType::U8, 8);
            b.add_var("x", VarType::USInt, 0, 8, 1);
        });
        let image = Image::parse(&bytes).unwrap();
        let program = NativeProgram {
            image: alloc::boxed::Box::leak(bytes.clone().into_boxed_slice()),
            hash: image_hash(&bytes),
            run: writes_seven,
        };
        assert!(program.is_translation_of(&bytes));
        let mut data = vec![0u8; image.data_size() as usize];
        let (mut stack, mut calls, mut tries) =
            ([0u64; 8], [CallFrame::EMPTY; 4], [TryFrame::EMPTY; 2]);
        let mut m = Machine::new(
            verify(&image).unwrap(),
            Memory {
                data: &mut data,
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        )
        .unwrap();
        let stats = m.run_cycle_native(0, 0, || false, &program).unwrap();
        assert_eq!(m.read_var("x"), Ok(Value::UInt(7)));
        assert_eq!((m.pc(), m.call_depth(), m.stack().len()), (42, 0, 0));
        assert_eq!(stats.caught_traps, 0);
        m.force_var("x", Value::UInt(3)).unwrap();
        m.run_cycle_native(0, 0, || false, &program).unwrap();
        assert_eq!(SEEN.load(Ordering::Relaxed), 3, "forced before the cycle");
        assert_eq!(m.read_var("x"), Ok(Value::UInt(3)), "and after it");
        m.unforce_var("x").unwrap();
        m.run_cycle_native(0, 0, || false, &program).unwrap();
        assert_eq!(m.read_var("x"), Ok(Value::UInt(7)));
    }
}
