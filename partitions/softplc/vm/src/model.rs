//! The executable reference model of the instruction semantics.
//!
//! Deliberately simple and written independently of [`crate::vm`]: the state is plain
//! `Vec`s (code, data memory, operand stack, call stack, try stack) plus registers, every
//! instruction is decoded from raw bytes in one big `match`, and the "a trapping instruction
//! has no effect" rule is implemented by working on a copy of the operand stack that is only
//! committed when the instruction succeeds. The STRING builtins are re-implemented here
//! with `Vec`s and `format!` ([`string_builtin`]); the model shares with the VM only the ISA
//! definitions, the table parser ([`Image`]), the math library ([`crate::fmath`], tested
//! against `std`) and the float formatting of `*_TO_STRING` (core's `Display`).
//!
//! Use it side by side with the VM: same image, same limits, then compare
//! [`Model::data`], [`Model::stack`], [`Model::pc`] and the cycle results.

use crate::image::Image;
use crate::isa::{Builtin, MemType, Opcode, RoundMode, Trap};
use alloc::format;
use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;

/// Outcome of a model cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelCycle {
    /// Completed after this many instructions, with this many caught traps.
    Completed {
        /// Instructions executed.
        instructions: u32,
        /// Traps caught.
        caught: u32,
    },
    /// Uncaught trap at a code offset.
    Faulted {
        /// The trap.
        trap: Trap,
        /// Code offset of the trapping instruction.
        pc: u32,
    },
    /// Refused: the task is faulted or does not exist.
    Refused,
}

/// The reference machine.
pub struct Model<'a> {
    image: Image<'a>,
    data: Vec<u8>,
    stack: Vec<u64>,
    calls: Vec<(u32, u32)>,
    tries: Vec<(u32, usize, usize, u32)>,
    pc: u32,
    base: u32,
    stack_limit: usize,
    call_limit: usize,
    try_limit: usize,
    faulted: Vec<bool>,
}

fn imm_u16(code: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([code[at], code[at + 1]])
}
fn imm_u32(code: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(code[at..at + 4].try_into().unwrap())
}
fn imm_u64(code: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(code[at..at + 8].try_into().unwrap())
}

impl<'a> Model<'a> {
    /// A model of a **verified** image with the given limits (the lengths of the VM's
    /// `Memory::stack`, `Memory::calls`, `Memory::tries`).
    pub fn new(
        image: &crate::verify::VerifiedImage<'a>,
        stack_limit: usize,
        call_limit: usize,
        try_limit: usize,
    ) -> Self {
        let image = *image.image();
        let mut data = vec![0u8; image.data_size() as usize];
        data[..image.init_data().len()].copy_from_slice(image.init_data());
        Model {
            data,
            stack: Vec::new(),
            calls: Vec::new(),
            tries: Vec::new(),
            pc: 0,
            base: 0,
            stack_limit,
            call_limit,
            try_limit,
            faulted: vec![false; image.task_count()],
            image,
        }
    }

    /// Data memory.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// Data memory, writable.
    pub fn data_mut(&mut self) -> &mut [u8] {
        &mut self.data
    }

    /// Operand stack (bottom first).
    pub fn stack(&self) -> &[u64] {
        &self.stack
    }

    /// Program counter.
    pub fn pc(&self) -> u32 {
        self.pc
    }

    /// Call depth.
    pub fn call_depth(&self) -> usize {
        self.calls.len()
    }

    /// Open try frames.
    pub fn try_depth(&self) -> usize {
        self.tries.len()
    }

    /// Clears a task's fault.
    pub fn reset_task(&mut self, task: usize) {
        if let Some(f) = self.faulted.get_mut(task) {
            *f = false;
        }
    }

    /// Runs one cycle of `task` at `now_ns` with an instruction budget (the task's unless overridden).
    pub fn run_cycle(
        &mut self,
        task: usize,
        now_ns: i64,
        budget_override: Option<u32>,
    ) -> ModelCycle {
        let Some(entry) = self.image.task(task) else {
            return ModelCycle::Refused;
        };
        if self.faulted[task] {
            return ModelCycle::Refused;
        }
        let budget = budget_override.unwrap_or(entry.budget());
        let pou = self.image.pou(entry.pou as usize).unwrap();
        self.stack.clear();
        self.tries.clear();
        self.calls = vec![(u32::MAX, 0)];
        self.base = entry.instance_base;
        self.pc = pou.code_start;
        let mut executed = 0u32;
        let mut caught = 0u32;
        loop {
            if executed == budget {
                self.faulted[task] = true;
                return ModelCycle::Faulted {
                    trap: Trap::Watchdog,
                    pc: self.pc,
                };
            }
            executed += 1;
            match self.execute(now_ns) {
                Ok(true) => {
                    return ModelCycle::Completed {
                        instructions: executed,
                        caught,
                    };
                }
                Ok(false) => {}
                Err(trap) => {
                    if self.handle(trap) {
                        caught += 1;
                    } else {
                        self.faulted[task] = true;
                        return ModelCycle::Faulted { trap, pc: self.pc };
                    }
                }
            }
        }
    }

    fn handle(&mut self, first: Trap) -> bool {
        let mut trap = first;
        while trap.is_catchable() {
            let Some((handler, depth, call_depth, base)) = self.tries.pop() else {
                return false;
            };
            self.stack.truncate(depth);
            self.calls.truncate(call_depth);
            self.base = base;
            if self.stack.len() < self.stack_limit {
                self.stack.push(trap as u64);
                self.pc = handler;
                return true;
            }
            trap = Trap::StackOverflow;
        }
        false
    }

    fn addr_ok(&self, address: u64, len: u64) -> bool {
        address
            .checked_add(len)
            .is_some_and(|end| end <= self.data.len() as u64)
    }

    fn read(&self, ty: MemType, address: u64) -> Result<u64, Trap> {
        let width = ty.width() as u64;
        if !self.addr_ok(address, width) {
            return Err(Trap::InvalidAddress);
        }
        let mut v: u64 = 0;
        for i in 0..width {
            v |= (self.data[(address + i) as usize] as u64) << (8 * i);
        }
        // sign extension for the signed narrow types
        Ok(match ty {
            MemType::I8 => v as i8 as i64 as u64,
            MemType::I16 => v as i16 as i64 as u64,
            MemType::I32 => v as i32 as i64 as u64,
            _ => v,
        })
    }

    fn write(&mut self, ty: MemType, address: u64, value: u64) -> Result<(), Trap> {
        let width = ty.width() as u64;
        if !self.addr_ok(address, width) {
            return Err(Trap::InvalidAddress);
        }
        for i in 0..width {
            self.data[(address + i) as usize] = (value >> (8 * i)) as u8;
        }
        Ok(())
    }

    /// Executes one instruction; Ok(true) when the cycle ended.
    fn execute(&mut self, now_ns: i64) -> Result<bool, Trap> {
        let code: &'a [u8] = self.image.code();
        let pc = self.pc as usize;
        let op = Opcode::from_u8(code[pc]).unwrap();
        let i = pc + 1;
        let mut next = (pc + 1 + op.operands().len()) as u32;
        // Work on a copy so that a trap leaves the stack untouched.
        let mut s = self.stack.clone();
        let limit = self.stack_limit;
        let push = |s: &mut Vec<u64>, v: u64| -> Result<(), Trap> {
            if s.len() >= limit {
                return Err(Trap::StackOverflow);
            }
            s.push(v);
            Ok(())
        };
        fn pop(s: &mut Vec<u64>) -> u64 {
            s.pop().unwrap()
        }
        let b2 = |x: bool| if x { 1u64 } else { 0 };
        let r32 = |c: u64| f32::from_bits(c as u32);
        let c32 = |f: f32| f.to_bits() as u64;
        let r64 = f64::from_bits;
        let mut ended = false;
        match op {
            Opcode::Nop => {}
            Opcode::PushI32 => push(&mut s, imm_u32(code, i) as i32 as i64 as u64)?,
            Opcode::PushU32 => push(&mut s, imm_u32(code, i) as u64)?,
            Opcode::PushI64 => push(&mut s, imm_u64(code, i))?,
            Opcode::PushConst => push(
                &mut s,
                self.image.constant(imm_u16(code, i) as usize).unwrap(),
            )?,
            Opcode::Drop => {
                pop(&mut s);
            }
            Opcode::Dup => {
                let a = *s.last().unwrap();
                push(&mut s, a)?;
            }
            Opcode::Swap => {
                let n = s.len();
                s.swap(n - 1, n - 2);
            }
            Opcode::Over => {
                let a = s[s.len() - 2];
                push(&mut s, a)?;
            }
            Opcode::LdAbs => {
                let v = self.read(
                    MemType::from_code(code[i]).unwrap(),
                    imm_u32(code, i + 1) as u64,
                )?;
                push(&mut s, v)?;
            }
            Opcode::StAbs => {
                let v = pop(&mut s);
                self.write(
                    MemType::from_code(code[i]).unwrap(),
                    imm_u32(code, i + 1) as u64,
                    v,
                )?;
            }
            Opcode::LdRel => {
                let a = self.base as u64 + imm_u32(code, i + 1) as u64;
                let v = self.read(MemType::from_code(code[i]).unwrap(), a)?;
                push(&mut s, v)?;
            }
            Opcode::StRel => {
                let v = pop(&mut s);
                let a = self.base as u64 + imm_u32(code, i + 1) as u64;
                self.write(MemType::from_code(code[i]).unwrap(), a, v)?;
            }
            Opcode::LdInd => {
                let a = pop(&mut s)
                    .checked_add(imm_u32(code, i + 1) as u64)
                    .ok_or(Trap::InvalidAddress)?;
                let v = self.read(MemType::from_code(code[i]).unwrap(), a)?;
                push(&mut s, v)?;
            }
            Opcode::StInd => {
                let v = pop(&mut s);
                let a = pop(&mut s)
                    .checked_add(imm_u32(code, i + 1) as u64)
                    .ok_or(Trap::InvalidAddress)?;
                self.write(MemType::from_code(code[i]).unwrap(), a, v)?;
            }
            Opcode::LeaRel => push(&mut s, self.base as u64 + imm_u32(code, i) as u64)?,
            Opcode::Copy => {
                let len = imm_u32(code, i) as u64;
                let src = pop(&mut s);
                let dst = pop(&mut s);
                if !self.addr_ok(src, len) || !self.addr_ok(dst, len) {
                    return Err(Trap::InvalidAddress);
                }
                let tmp: Vec<u8> = self.data[src as usize..(src + len) as usize].to_vec();
                self.data[dst as usize..(dst + len) as usize].copy_from_slice(&tmp);
            }
            Opcode::Now => push(&mut s, now_ns as u64)?,
            // The binary operators (`Opcode::is_binary`).
            Opcode::Add
            | Opcode::Sub
            | Opcode::Mul
            | Opcode::DivS
            | Opcode::DivU
            | Opcode::ModS
            | Opcode::ModU
            | Opcode::And
            | Opcode::Or
            | Opcode::Xor
            | Opcode::Shl
            | Opcode::ShrU
            | Opcode::ShrS
            | Opcode::Eq
            | Opcode::Ne
            | Opcode::LtS
            | Opcode::LeS
            | Opcode::GtS
            | Opcode::GeS
            | Opcode::LtU
            | Opcode::LeU
            | Opcode::GtU
            | Opcode::GeU
            | Opcode::AddF32
            | Opcode::SubF32
            | Opcode::MulF32
            | Opcode::DivF32
            | Opcode::EqF32
            | Opcode::NeF32
            | Opcode::LtF32
            | Opcode::LeF32
            | Opcode::GtF32
            | Opcode::GeF32
            | Opcode::AddF64
            | Opcode::SubF64
            | Opcode::MulF64
            | Opcode::DivF64
            | Opcode::EqF64
            | Opcode::NeF64
            | Opcode::LtF64
            | Opcode::LeF64
            | Opcode::GtF64
            | Opcode::GeF64 => {
                let b = pop(&mut s);
                let a = pop(&mut s);
                s.push(model_binary(op, a, b)?);
            }
            Opcode::Neg => {
                let a = pop(&mut s) as i64;
                s.push(0i64.wrapping_sub(a) as u64);
            }
            Opcode::AbsS => {
                let a = pop(&mut s) as i64;
                s.push(if a < 0 {
                    0i64.wrapping_sub(a) as u64
                } else {
                    a as u64
                });
            }
            Opcode::Not => {
                let a = pop(&mut s);
                s.push(a ^ u64::MAX);
            }
            Opcode::NotBool => {
                let a = pop(&mut s);
                s.push(b2(a == 0));
            }
            Opcode::Rol | Opcode::Ror => {
                let w = code[i] as u64;
                let n = pop(&mut s) % w;
                let a = pop(&mut s);
                let mask = if w == 64 { u64::MAX } else { (1u64 << w) - 1 };
                let mut v = a & mask;
                // rotate one bit at a time: obviously correct
                for _ in 0..n {
                    v = if op == Opcode::Rol {
                        ((v << 1) & mask) | (v >> (w - 1))
                    } else {
                        (v >> 1) | ((v & 1) << (w - 1))
                    };
                }
                s.push(v);
            }
            Opcode::Sext => {
                let a = pop(&mut s);
                s.push(match code[i] {
                    8 => a as u8 as i8 as i64 as u64,
                    16 => a as u16 as i16 as i64 as u64,
                    _ => a as u32 as i32 as i64 as u64,
                });
            }
            Opcode::Zext => {
                let a = pop(&mut s);
                s.push(match code[i] {
                    8 => a as u8 as u64,
                    16 => a as u16 as u64,
                    _ => a as u32 as u64,
                });
            }
            Opcode::Sel => {
                let b = pop(&mut s);
                let a = pop(&mut s);
                let g = pop(&mut s);
                s.push(if g == 0 { a } else { b });
            }
            Opcode::NegF32 => {
                let a = pop(&mut s);
                s.push(c32(-r32(a)));
            }
            Opcode::NegF64 => {
                let a = pop(&mut s);
                s.push((-r64(a)).to_bits());
            }
            Opcode::IToF32S => {
                let a = pop(&mut s);
                s.push(c32(a as i64 as f32));
            }
            Opcode::IToF32U => {
                let a = pop(&mut s);
                s.push(c32(a as f32));
            }
            Opcode::IToF64S => {
                let a = pop(&mut s);
                s.push((a as i64 as f64).to_bits());
            }
            Opcode::IToF64U => {
                let a = pop(&mut s);
                s.push((a as f64).to_bits());
            }
            Opcode::F32ToF64 => {
                let a = pop(&mut s);
                s.push((r32(a) as f64).to_bits());
            }
            Opcode::F64ToF32 => {
                let a = pop(&mut s);
                s.push(c32(r64(a) as f32));
            }
            Opcode::F32ToInt | Opcode::F64ToInt => {
                let a = pop(&mut s);
                let x = if op == Opcode::F32ToInt {
                    r32(a) as f64
                } else {
                    r64(a)
                };
                let ty = MemType::from_code(code[i]).unwrap();
                let mode = RoundMode::from_code(code[i + 1]).unwrap();
                s.push(model_float_to_int(x, ty, mode)?);
            }
            Opcode::Jmp => next = imm_u32(code, i),
            Opcode::Jz => {
                if pop(&mut s) == 0 {
                    next = imm_u32(code, i);
                }
            }
            Opcode::Jnz => {
                if pop(&mut s) != 0 {
                    next = imm_u32(code, i);
                }
            }
            Opcode::Call => {
                let callee = self.image.pou(imm_u16(code, i) as usize).unwrap();
                if self.calls.len() >= self.call_limit {
                    return Err(Trap::CallDepth);
                }
                let base = pop(&mut s);
                if !self.addr_ok(base, callee.frame_size as u64) {
                    return Err(Trap::InvalidAddress);
                }
                self.calls.push((next, self.base));
                self.base = base as u32;
                next = callee.code_start;
            }
            Opcode::Ret => {
                let (ret, base) = self.calls.pop().unwrap();
                if self.calls.is_empty() {
                    ended = true;
                    next = self.pc;
                } else {
                    next = ret;
                    self.base = base;
                }
            }
            Opcode::CallBuiltin => {
                let b = Builtin::from_u16(imm_u16(code, i)).unwrap();
                let args: Vec<u64> = s.split_off(s.len() - b.args());
                let result = if (b as u16) < 100 {
                    crate::builtins::call(b, &args, &mut self.data)?
                } else {
                    string_builtin(b, &args, &mut self.data)?
                };
                if let Some(r) = result {
                    s.push(r);
                }
            }
            Opcode::ChkIndex | Opcode::ChkRangeS => {
                let v = *s.last().unwrap() as i64;
                let lo = imm_u64(code, i) as i64;
                let hi = imm_u64(code, i + 8) as i64;
                if v < lo || v > hi {
                    return Err(if op == Opcode::ChkIndex {
                        Trap::IndexOutOfBounds
                    } else {
                        Trap::SubrangeViolation
                    });
                }
            }
            Opcode::ChkRangeU => {
                let v = *s.last().unwrap();
                if v < imm_u64(code, i) || v > imm_u64(code, i + 8) {
                    return Err(Trap::SubrangeViolation);
                }
            }
            Opcode::AddImm => {
                let a = pop(&mut s) as i64;
                s.push(a.wrapping_add(imm_u32(code, i) as i32 as i64) as u64);
            }
            Opcode::JumpIf | Opcode::JumpIfNot => {
                let b = pop(&mut s);
                let a = pop(&mut s);
                let holds = model_compare(code[i], a, b);
                if holds == (op == Opcode::JumpIf) {
                    next = imm_u32(code, i + 1);
                }
            }
            Opcode::Index => {
                let lo = imm_u64(code, i) as i64;
                let hi = imm_u64(code, i + 8) as i64;
                let stride = imm_u32(code, i + 16) as i64;
                let index = pop(&mut s) as i64;
                let base = pop(&mut s) as i64;
                if index < lo || index > hi {
                    return Err(Trap::IndexOutOfBounds);
                }
                s.push(base.wrapping_add(index.wrapping_sub(lo).wrapping_mul(stride)) as u64);
            }
            Opcode::ElemRel | Opcode::ElemAbs => {
                let i_ = pop(&mut s);
                let mut array = imm_u32(code, i) as u64;
                if op == Opcode::ElemRel {
                    array += self.base as u64;
                }
                let lo = imm_u64(code, i + 4);
                let hi = imm_u64(code, i + 12);
                let stride = imm_u32(code, i + 20);
                s.push(model_element(array, i_, lo, hi, stride)?);
            }
            Opcode::LdElemRel | Opcode::LdElemAbs => {
                let ty = MemType::from_code(code[i]).unwrap();
                let mut array = imm_u32(code, i + 1) as u64;
                if op == Opcode::LdElemRel {
                    array += self.base as u64;
                }
                let index = pop(&mut s);
                let address = model_element(
                    array,
                    index,
                    imm_u64(code, i + 5),
                    imm_u64(code, i + 13),
                    imm_u32(code, i + 21),
                )?;
                s.push(self.read(ty, address)?);
            }
            Opcode::StElemRel | Opcode::StElemAbs => {
                let ty = MemType::from_code(code[i]).unwrap();
                let mut array = imm_u32(code, i + 1) as u64;
                if op == Opcode::StElemRel {
                    array += self.base as u64;
                }
                let v = pop(&mut s);
                let index = pop(&mut s);
                let address = model_element(
                    array,
                    index,
                    imm_u64(code, i + 5),
                    imm_u64(code, i + 13),
                    imm_u32(code, i + 21),
                )?;
                self.write(ty, address, v)?;
            }
            Opcode::IncRel | Opcode::IncAbs => {
                let ty = MemType::from_code(code[i]).unwrap();
                let mut address = imm_u32(code, i + 1) as u64;
                if op == Opcode::IncRel {
                    address += self.base as u64;
                }
                let v = self.read(ty, address)? as i64;
                let k = imm_u32(code, i + 5) as i32 as i64;
                self.write(ty, address, v.wrapping_add(k) as u64)?;
            }
            Opcode::SelIf => {
                let b = pop(&mut s);
                let a = pop(&mut s);
                s.push(if model_compare(code[i], a, b) { b } else { a });
            }
            Opcode::JumpIfImm | Opcode::JumpIfNotImm => {
                let a = pop(&mut s);
                let k = imm_u32(code, i + 1) as i32 as i64 as u64;
                if model_compare(code[i], a, k) == (op == Opcode::JumpIfImm) {
                    next = imm_u32(code, i + 5);
                }
            }
            Opcode::OpImm => {
                let a = pop(&mut s);
                let k = imm_u32(code, i + 1) as i32 as i64 as u64;
                s.push(model_binary(Opcode::from_u8(code[i]).unwrap(), a, k)?);
            }
            Opcode::OpRel | Opcode::OpAbs => {
                let ty = MemType::from_code(code[i + 1]).unwrap();
                let mut address = imm_u32(code, i + 2) as u64;
                if op == Opcode::OpRel {
                    address += self.base as u64;
                }
                let v = self.read(ty, address)?;
                let a = pop(&mut s);
                s.push(model_binary(Opcode::from_u8(code[i]).unwrap(), a, v)?);
            }
            Opcode::TryBegin => {
                if self.tries.len() >= self.try_limit {
                    return Err(Trap::StackOverflow);
                }
                self.tries
                    .push((imm_u32(code, i), s.len(), self.calls.len(), self.base));
            }
            Opcode::TryEnd => {
                self.tries.pop();
            }
            Opcode::Throw => return Err(Trap::from_u64(code[i] as u64).unwrap()),
            Opcode::Rethrow => {
                let c = pop(&mut s);
                if c != 0 {
                    let trap = Trap::from_u64(c)
                        .filter(|t| t.is_catchable())
                        .unwrap_or(Trap::NumericError);
                    return Err(trap);
                }
            }
        }
        self.stack = s;
        self.pc = next;
        Ok(ended)
    }
}

/// A binary operator (`[a b] -> [a op b]`, [`Opcode::is_binary`]): the plain instruction and
/// the right operand of OP_IMM, OP_REL and OP_ABS.
fn model_binary(op: Opcode, a: u64, b: u64) -> Result<u64, Trap> {
    let b2 = |x: bool| if x { 1u64 } else { 0 };
    let r32 = |c: u64| f32::from_bits(c as u32);
    let c32 = |f: f32| f.to_bits() as u64;
    let r64 = f64::from_bits;
    let (x, y) = (a as i64, b as i64);
    Ok(match op {
        Opcode::Add => x.wrapping_add(y) as u64,
        Opcode::Sub => x.wrapping_sub(y) as u64,
        Opcode::Mul => x.wrapping_mul(y) as u64,
        Opcode::DivS | Opcode::DivU | Opcode::ModS | Opcode::ModU if b == 0 => {
            return Err(Trap::DivisionByZero);
        }
        Opcode::DivS => {
            if x == i64::MIN && y == -1 {
                i64::MIN as u64
            } else {
                (x / y) as u64
            }
        }
        Opcode::ModS => {
            if y == -1 {
                0
            } else {
                (x % y) as u64
            }
        }
        Opcode::DivU => a / b,
        Opcode::ModU => a % b,
        Opcode::And => a & b,
        Opcode::Or => a | b,
        Opcode::Xor => a ^ b,
        Opcode::Shl => {
            if b >= 64 {
                0
            } else {
                a << b
            }
        }
        Opcode::ShrU => {
            if b >= 64 {
                0
            } else {
                a >> b
            }
        }
        Opcode::ShrS => {
            if b >= 64 {
                if x < 0 { u64::MAX } else { 0 }
            } else {
                (x >> b) as u64
            }
        }
        Opcode::AddF32 => c32(r32(a) + r32(b)),
        Opcode::SubF32 => c32(r32(a) - r32(b)),
        Opcode::MulF32 => c32(r32(a) * r32(b)),
        Opcode::DivF32 => {
            if r32(b) == 0.0 {
                return Err(Trap::DivisionByZero);
            }
            c32(r32(a) / r32(b))
        }
        Opcode::AddF64 => (r64(a) + r64(b)).to_bits(),
        Opcode::SubF64 => (r64(a) - r64(b)).to_bits(),
        Opcode::MulF64 => (r64(a) * r64(b)).to_bits(),
        Opcode::DivF64 => {
            if r64(b) == 0.0 {
                return Err(Trap::DivisionByZero);
            }
            (r64(a) / r64(b)).to_bits()
        }
        cmp => b2(model_compare(cmp as u8, a, b)),
    })
}

/// Element `i` of an array at `array` with bounds `lo..=hi` and element `stride`: its
/// address as INDEX computes it (wrapping), or INDEX_OUT_OF_BOUNDS.
fn model_element(array: u64, i: u64, lo: u64, hi: u64, stride: u32) -> Result<u64, Trap> {
    let (i, lo, hi) = (i as i64, lo as i64, hi as i64);
    if i < lo || i > hi {
        return Err(Trap::IndexOutOfBounds);
    }
    Ok((array as i64).wrapping_add(i.wrapping_sub(lo).wrapping_mul(stride as i64)) as u64)
}

/// A comparison opcode byte applied to two cells (the model's own table, not `isa::compare`).
fn model_compare(cmp: u8, a: u64, b: u64) -> bool {
    let (x, y) = (a as i64, b as i64);
    let (f, g) = (f32::from_bits(a as u32), f32::from_bits(b as u32));
    let (d, e) = (f64::from_bits(a), f64::from_bits(b));
    match Opcode::from_u8(cmp).unwrap() {
        Opcode::Eq => a == b,
        Opcode::Ne => a != b,
        Opcode::LtS => x < y,
        Opcode::LeS => x <= y,
        Opcode::GtS => x > y,
        Opcode::GeS => x >= y,
        Opcode::LtU => a < b,
        Opcode::LeU => a <= b,
        Opcode::GtU => a > b,
        Opcode::GeU => a >= b,
        Opcode::EqF32 => f == g,
        Opcode::NeF32 => f != g,
        Opcode::LtF32 => f < g,
        Opcode::LeF32 => f <= g,
        Opcode::GtF32 => f > g,
        Opcode::GeF32 => f >= g,
        Opcode::EqF64 => d == e,
        Opcode::NeF64 => d != e,
        Opcode::LtF64 => d < e,
        Opcode::LeF64 => d <= e,
        Opcode::GtF64 => d > e,
        Opcode::GeF64 => d >= e,
        other => unreachable!("verified comparison, got {other:?}"),
    }
}

/// Float -> integer conversion written independently of `fmath::float_to_int`: compares
/// against the target range in f64 after rounding with the same (exact) rounding functions.
fn model_float_to_int(x: f64, ty: MemType, mode: RoundMode) -> Result<u64, Trap> {
    if x.is_nan() || x.is_infinite() {
        return Err(Trap::NumericError);
    }
    let r = match mode {
        RoundMode::Truncate => crate::fmath::trunc(x),
        RoundMode::NearestTiesAway => {
            let t = crate::fmath::trunc(x);
            let f = x - t;
            if f >= 0.5 {
                t + 1.0
            } else if f <= -0.5 {
                t - 1.0
            } else {
                t
            }
        }
    };
    let bits = ty.width() as i32 * 8;
    let signed = matches!(ty, MemType::I8 | MemType::I16 | MemType::I32 | MemType::I64);
    let two = |e: i32| {
        let mut v = 1.0f64;
        for _ in 0..e {
            v *= 2.0;
        }
        v
    };
    let (lo, hi) = if signed {
        (-two(bits - 1), two(bits - 1))
    } else {
        (0.0, two(bits))
    };
    if r < lo || r >= hi {
        return Err(Trap::NumericError);
    }
    Ok(if signed { r as i64 as u64 } else { r as u64 })
}

/// Reads the string variable at `address`: (capacity, text).
fn read_string(data: &[u8], address: u64) -> Result<(usize, Vec<u8>), Trap> {
    if address >= data.len() as u64 || data.len() as u64 - address < 4 {
        return Err(Trap::InvalidAddress);
    }
    let a = address as usize;
    let capacity = u16::from_le_bytes([data[a], data[a + 1]]) as usize;
    let current = u16::from_le_bytes([data[a + 2], data[a + 3]]) as usize;
    if a + 4 + capacity > data.len() {
        return Err(Trap::InvalidAddress);
    }
    let len = if current > capacity {
        capacity
    } else {
        current
    };
    Ok((capacity, data[a + 4..a + 4 + len].to_vec()))
}

/// Clamps a signed cell into `lo..=hi`.
fn clamp(cell: u64, lo: usize, hi: usize) -> usize {
    let v = cell as i64;
    if v < lo as i64 {
        lo
    } else if v > hi as i64 {
        hi
    } else {
        v as usize
    }
}

fn decimal_with_point(text: String) -> String {
    if text.contains('.') || text.contains("inf") || text.contains("NaN") {
        text
    } else {
        text + ".0"
    }
}

fn time_literal(ns: i64) -> String {
    if ns == 0 {
        return "T#0s".into();
    }
    let mut out = String::from(if ns < 0 { "T#-" } else { "T#" });
    let mut rest = ns.unsigned_abs();
    let units: [(&str, u64); 7] = [
        ("d", 24 * 3600 * 1_000_000_000),
        ("h", 3600 * 1_000_000_000),
        ("m", 60 * 1_000_000_000),
        ("s", 1_000_000_000),
        ("ms", 1_000_000),
        ("us", 1_000),
        ("ns", 1),
    ];
    for (unit, size) in units {
        if rest >= size {
            out += &format!("{}{unit}", rest / size);
            rest %= size;
        }
    }
    out
}

fn parse_integer(text: &[u8]) -> Option<i64> {
    let t = core::str::from_utf8(text).ok()?.trim();
    let (negative, body) = match (t.strip_prefix('-'), t.strip_prefix('+')) {
        (Some(rest), _) => (true, rest),
        (None, Some(rest)) => (false, rest),
        _ => (false, t),
    };
    if body.is_empty()
        || body.starts_with('_')
        || body.ends_with('_')
        || !body.chars().all(|c| c.is_ascii_digit() || c == '_')
    {
        return None;
    }
    let digits: String = body.chars().filter(|c| *c != '_').collect();
    let signed = if negative {
        format!("-{digits}")
    } else {
        digits
    };
    signed.parse::<i64>().ok()
}

/// Independent implementation of the STRING builtins (ids >= 100), written from the
/// documentation of [`Builtin`].
pub fn string_builtin(
    builtin: Builtin,
    args: &[u64],
    data: &mut [u8],
) -> Result<Option<u64>, Trap> {
    use Builtin::*;
    match builtin {
        StrLen => return Ok(Some(read_string(data, args[0])?.1.len() as u64)),
        StrFind => {
            let (_, a) = read_string(data, args[0])?;
            let (_, b) = read_string(data, args[1])?;
            let mut found = 0;
            if !b.is_empty() && b.len() <= a.len() {
                for start in 0..=a.len() - b.len() {
                    if a[start..start + b.len()] == b[..] {
                        found = start + 1;
                        break;
                    }
                }
            }
            return Ok(Some(found as u64));
        }
        StrCompare => {
            let (_, a) = read_string(data, args[0])?;
            let (_, b) = read_string(data, args[1])?;
            let r: i64 = if a < b {
                -1
            } else if a > b {
                1
            } else {
                0
            };
            return Ok(Some(r as u64));
        }
        StrToI64 => {
            let (_, a) = read_string(data, args[0])?;
            return parse_integer(&a)
                .map(|v| Some(v as u64))
                .ok_or(Trap::NumericError);
        }
        StrToF64 => {
            let (_, a) = read_string(data, args[0])?;
            let text = core::str::from_utf8(&a).map_err(|_| Trap::NumericError)?;
            return text
                .trim()
                .parse::<f64>()
                .map(|v| Some(v.to_bits()))
                .map_err(|_| Trap::NumericError);
        }
        _ => {}
    }
    let (capacity, _) = read_string(data, args[0])?;
    let mut result: Vec<u8> = match builtin {
        StrAssign => read_string(data, args[1])?.1,
        StrConcat => {
            let mut a = read_string(data, args[1])?.1;
            a.extend(read_string(data, args[2])?.1);
            a
        }
        StrLeft => {
            let a = read_string(data, args[1])?.1;
            let n = clamp(args[2], 0, a.len());
            a[..n].to_vec()
        }
        StrRight => {
            let a = read_string(data, args[1])?.1;
            let n = clamp(args[2], 0, a.len());
            a[a.len() - n..].to_vec()
        }
        StrMid => {
            let a = read_string(data, args[1])?.1;
            let p = clamp(args[3], 1, a.len() + 1);
            let n = clamp(args[2], 0, a.len() + 1 - p);
            a[p - 1..p - 1 + n].to_vec()
        }
        StrInsert => {
            let a = read_string(data, args[1])?.1;
            let b = read_string(data, args[2])?.1;
            let p = clamp(args[3], 0, a.len());
            [&a[..p], &b[..], &a[p..]].concat()
        }
        StrDelete | StrReplace => {
            let a = read_string(data, args[1])?.1;
            let (b, n_cell, p_cell) = if builtin == StrReplace {
                (read_string(data, args[2])?.1, args[3], args[4])
            } else {
                (Vec::new(), args[2], args[3])
            };
            let p = clamp(p_cell, 1, a.len() + 1);
            let n = clamp(n_cell, 0, a.len() + 1 - p);
            [&a[..p - 1], &b[..], &a[p - 1 + n..]].concat()
        }
        StrFromI64 => format!("{}", args[1] as i64).into_bytes(),
        StrFromU64 => format!("{}", args[1]).into_bytes(),
        StrFromF32 => {
            decimal_with_point(format!("{}", f32::from_bits(args[1] as u32))).into_bytes()
        }
        StrFromF64 => decimal_with_point(format!("{}", f64::from_bits(args[1]))).into_bytes(),
        StrFromBool => (if args[1] == 0 { "FALSE" } else { "TRUE" })
            .as_bytes()
            .to_vec(),
        StrFromTime => time_literal(args[1] as i64).into_bytes(),
        _ => unreachable!("math builtins are not string builtins"),
    };
    result.truncate(crate::builtins::MAX_STRING_LEN.min(capacity));
    let a = args[0] as usize;
    data[a + 2..a + 4].copy_from_slice(&(result.len() as u16).to_le_bytes());
    data[a + 4..a + 4 + result.len()].copy_from_slice(&result);
    Ok(None)
}
