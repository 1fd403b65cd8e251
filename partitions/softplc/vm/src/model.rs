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
                let result = if b.is_math() {
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
            Opcode::OpRelRel => {
                if s.len() >= limit {
                    return Err(Trap::StackOverflow);
                }
                let a = self.read(
                    MemType::from_code(code[i + 1]).unwrap(),
                    self.base as u64 + imm_u32(code, i + 2) as u64,
                )?;
                let b = self.read(
                    MemType::from_code(code[i + 6]).unwrap(),
                    self.base as u64 + imm_u32(code, i + 7) as u64,
                )?;
                let r = model_binary(Opcode::from_u8(code[i]).unwrap(), a, b)?;
                push(&mut s, r)?;
            }
            Opcode::JumpIfRelImm | Opcode::JumpIfNotRelImm => {
                let v = self.read(
                    MemType::from_code(code[i + 1]).unwrap(),
                    self.base as u64 + imm_u32(code, i + 2) as u64,
                )?;
                let k = imm_u32(code, i + 6) as i32 as i64 as u64;
                if model_compare(code[i], v, k) == (op == Opcode::JumpIfRelImm) {
                    next = imm_u32(code, i + 10);
                }
            }
            Opcode::ElemRelAt
            | Opcode::ElemAbsAt
            | Opcode::LdElemRelAt
            | Opcode::LdElemAbsAt
            | Opcode::StElemRelAt
            | Opcode::StElemAbsAt => {
                // The operands after the opcode: [ty] addr lo hi stride ity ioff.
                let typed = !matches!(op, Opcode::ElemRelAt | Opcode::ElemAbsAt);
                let o = i + typed as usize;
                let pushes = !matches!(op, Opcode::StElemRelAt | Opcode::StElemAbsAt);
                if pushes && s.len() >= limit {
                    return Err(Trap::StackOverflow);
                }
                let index = self.read(
                    MemType::from_code(code[o + 24]).unwrap(),
                    self.base as u64 + imm_u32(code, o + 25) as u64,
                )?;
                let mut array = imm_u32(code, o) as u64;
                if matches!(
                    op,
                    Opcode::ElemRelAt | Opcode::LdElemRelAt | Opcode::StElemRelAt
                ) {
                    array += self.base as u64;
                }
                let address = model_element(
                    array,
                    index,
                    imm_u64(code, o + 4),
                    imm_u64(code, o + 12),
                    imm_u32(code, o + 20),
                )?;
                match op {
                    Opcode::ElemRelAt | Opcode::ElemAbsAt => s.push(address),
                    Opcode::LdElemRelAt | Opcode::LdElemAbsAt => {
                        let v = self.read(MemType::from_code(code[i]).unwrap(), address)?;
                        s.push(v);
                    }
                    _ => {
                        let v = pop(&mut s);
                        self.write(MemType::from_code(code[i]).unwrap(), address, v)?;
                    }
                }
            }
            Opcode::RefMake => {
                let a = pop(&mut s);
                let size = imm_u32(code, i) as u64;
                // The shortest record containing the bytes, by a linear scan (the VM
                // binary-searches and walks up parents).
                let found = (0..self.image.object_count())
                    .filter(|&k| {
                        let (start, len) = self.image.object(k).unwrap();
                        a >= start as u64 && a + size <= start as u64 + len as u64
                    })
                    .min_by_key(|&k| self.image.object(k).unwrap().1);
                let Some(k) = found else {
                    return Err(Trap::InvalidReference);
                };
                s.push(a + (((k + 1) as u64) << 32));
            }
            Opcode::RefCheck => {
                let r = pop(&mut s);
                let object = r >> 32;
                let address = r % (1u64 << 32);
                let size = imm_u32(code, i) as u64;
                if object == 0 || object > self.image.object_count() as u64 {
                    return Err(Trap::InvalidReference);
                }
                let (start, len) = self.image.object(object as usize - 1).unwrap();
                if address < start as u64 || address + size > start as u64 + len as u64 {
                    return Err(Trap::InvalidReference);
                }
                s.push(address);
            }
            Opcode::RefAdd => {
                let n = pop(&mut s);
                let r = pop(&mut s);
                let low = (r % (1u64 << 32) + n % (1u64 << 32)) % (1u64 << 32);
                s.push((r >> 32 << 32) + low);
            }
            Opcode::ChkNull => {
                if *s.last().unwrap() == 0 {
                    return Err(Trap::InvalidReference);
                }
            }
            Opcode::CallVirt | Opcode::VirtFrame => {
                let instance = pop(&mut s);
                let slot = imm_u16(code, i);
                if instance == 0 || !self.addr_ok(instance, 4) {
                    return Err(Trap::InvalidReference);
                }
                let class = self.read(MemType::U32, instance)? as usize;
                if class >= self.image.class_count() {
                    return Err(Trap::InvalidReference);
                }
                let c = self.image.class(class).unwrap();
                // Linear scan of the class's methods (the VM binary-searches).
                let Some(d) = (c.first..c.first + c.count)
                    .map(|k| self.image.dispatch(k as usize).unwrap())
                    .find(|d| d.slot == slot)
                else {
                    return Err(Trap::InvalidReference);
                };
                if op == Opcode::VirtFrame {
                    s.push(d.frame as u64);
                } else {
                    let callee = self.image.pou(d.pou as usize).unwrap();
                    if self.calls.len() >= self.call_limit {
                        return Err(Trap::CallDepth);
                    }
                    if !self.addr_ok(instance, callee.frame_size as u64) {
                        return Err(Trap::InvalidAddress);
                    }
                    self.calls.push((next, self.base));
                    self.base = instance as u32;
                    next = callee.code_start;
                }
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
    // Arithmetic results: a NaN is the canonical one (`isa::CANONICAL_NAN_F32`/`_F64`).
    let c32 = |f: f32| {
        if f.is_nan() {
            crate::isa::CANONICAL_NAN_F32 as u64
        } else {
            f.to_bits() as u64
        }
    };
    let c64 = |f: f64| {
        if f.is_nan() {
            crate::isa::CANONICAL_NAN_F64
        } else {
            f.to_bits()
        }
    };
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
        Opcode::AddF64 => c64(r64(a) + r64(b)),
        Opcode::SubF64 => c64(r64(a) - r64(b)),
        Opcode::MulF64 => c64(r64(a) * r64(b)),
        Opcode::DivF64 => {
            if r64(b) == 0.0 {
                return Err(Trap::DivisionByZero);
            }
            c64(r64(a) / r64(b))
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

/// A code unit of a string variable: a STRING's byte or a WSTRING's UTF-16 unit. The
/// builtins that both types have are written once over it ([`text_builtin`]).
trait Unit: Copy + Ord {
    /// Bytes per unit in data memory.
    const SIZE: usize;
    fn from_le(bytes: &[u8]) -> Self;
    fn put_le(self, out: &mut [u8]);
    /// Whether a result shorter than its capacity ends with a NUL (STRING's does).
    const NUL_TERMINATED: bool;
}

impl Unit for u8 {
    const SIZE: usize = 1;
    const NUL_TERMINATED: bool = true;
    fn from_le(bytes: &[u8]) -> Self {
        bytes[0]
    }
    fn put_le(self, out: &mut [u8]) {
        out[0] = self;
    }
}

impl Unit for u16 {
    const SIZE: usize = 2;
    const NUL_TERMINATED: bool = false;
    fn from_le(bytes: &[u8]) -> Self {
        u16::from_le_bytes([bytes[0], bytes[1]])
    }
    fn put_le(self, out: &mut [u8]) {
        out[..2].copy_from_slice(&self.to_le_bytes());
    }
}

/// Reads the string variable of unit `U` at `address`: (capacity, units).
fn read_text<U: Unit>(data: &[u8], address: u64) -> Result<(usize, Vec<U>), Trap> {
    if address >= data.len() as u64 || data.len() as u64 - address < 4 {
        return Err(Trap::InvalidAddress);
    }
    let a = address as usize;
    let capacity = u16::from_le_bytes([data[a], data[a + 1]]) as usize;
    let current = u16::from_le_bytes([data[a + 2], data[a + 3]]) as usize;
    if a + 4 + U::SIZE * capacity > data.len() {
        return Err(Trap::InvalidAddress);
    }
    let len = current.min(capacity);
    let units = data[a + 4..a + 4 + U::SIZE * len].chunks_exact(U::SIZE);
    Ok((capacity, units.map(U::from_le).collect()))
}

/// Reads the STRING variable at `address`: (capacity, bytes).
fn read_string(data: &[u8], address: u64) -> Result<(usize, Vec<u8>), Trap> {
    read_text(data, address)
}

/// Reads the WSTRING variable at `address`: (capacity, code units).
fn read_wstring(data: &[u8], address: u64) -> Result<(usize, Vec<u16>), Trap> {
    read_text(data, address)
}

/// Stores `result` into the string variable of unit `U` at `address` (checked by the
/// caller's read of its capacity), cut to the capacity and to the longest string.
fn store_text<U: Unit>(data: &mut [u8], address: u64, mut result: Vec<U>) -> Result<(), Trap> {
    let (capacity, _) = read_text::<U>(data, address)?;
    result.truncate(crate::builtins::MAX_STRING_LEN.min(capacity));
    let a = address as usize;
    data[a + 2..a + 4].copy_from_slice(&(result.len() as u16).to_le_bytes());
    for (i, unit) in result.iter().enumerate() {
        unit.put_le(&mut data[a + 4 + U::SIZE * i..]);
    }
    if U::NUL_TERMINATED && result.len() < capacity {
        data[a + 4 + U::SIZE * result.len()] = 0;
    }
    Ok(())
}

/// The builtins STRING and WSTRING both have, by what they do.
#[derive(Clone, Copy)]
enum TextOp {
    Len,
    Find,
    Compare,
    Assign,
    Concat,
    Left,
    Right,
    Mid,
    Insert,
    Delete,
    Replace,
}

/// `builtin` as a [`TextOp`] and whether it works on WSTRING.
fn text_op(builtin: Builtin) -> Option<(TextOp, bool)> {
    use Builtin::*;
    Some(match builtin {
        StrLen => (TextOp::Len, false),
        StrFind => (TextOp::Find, false),
        StrCompare => (TextOp::Compare, false),
        StrAssign => (TextOp::Assign, false),
        StrConcat => (TextOp::Concat, false),
        StrLeft => (TextOp::Left, false),
        StrRight => (TextOp::Right, false),
        StrMid => (TextOp::Mid, false),
        StrInsert => (TextOp::Insert, false),
        StrDelete => (TextOp::Delete, false),
        StrReplace => (TextOp::Replace, false),
        WStrLen => (TextOp::Len, true),
        WStrFind => (TextOp::Find, true),
        WStrCompare => (TextOp::Compare, true),
        WStrAssign => (TextOp::Assign, true),
        WStrConcat => (TextOp::Concat, true),
        WStrLeft => (TextOp::Left, true),
        WStrRight => (TextOp::Right, true),
        WStrMid => (TextOp::Mid, true),
        WStrInsert => (TextOp::Insert, true),
        WStrDelete => (TextOp::Delete, true),
        WStrReplace => (TextOp::Replace, true),
        _ => return None,
    })
}

/// A builtin that STRING and WSTRING share, on strings of unit `U`, from the builtins'
/// documentation: LEN, FIND (1-based, 0 when absent or the pattern is empty), the
/// three-way compare, and the edits whose result goes to the string at `args[0]`.
fn text_builtin<U: Unit>(op: TextOp, args: &[u64], data: &mut [u8]) -> Result<Option<u64>, Trap> {
    let text = |i: usize| read_text::<U>(data, args[i]).map(|(_, units)| units);
    let result = match op {
        TextOp::Len => return Ok(Some(text(0)?.len() as u64)),
        TextOp::Find => {
            let (a, b) = (text(0)?, text(1)?);
            let found = if b.is_empty() || b.len() > a.len() {
                0
            } else {
                (0..=a.len() - b.len())
                    .find(|&at| a[at..at + b.len()] == b[..])
                    .map_or(0, |at| at + 1)
            };
            return Ok(Some(found as u64));
        }
        TextOp::Compare => {
            let order = text(0)?.cmp(&text(1)?);
            return Ok(Some(order as i8 as i64 as u64));
        }
        TextOp::Assign => text(1)?,
        TextOp::Concat => {
            let mut a = text(1)?;
            a.extend(text(2)?);
            a
        }
        TextOp::Left => left(&text(1)?, args[2]),
        TextOp::Right => right(&text(1)?, args[2]),
        TextOp::Mid => mid(&text(1)?, args[2], args[3]),
        TextOp::Insert => insert(&text(1)?, &text(2)?, args[3]),
        TextOp::Delete => replace(&text(1)?, &[], args[2], args[3]),
        TextOp::Replace => replace(&text(1)?, &text(2)?, args[3], args[4]),
    };
    store_text(data, args[0], result)?;
    Ok(None)
}

/// The conversions between STRING and WSTRING (ids 151, 152).
fn wstring_conversion(
    builtin: Builtin,
    args: &[u64],
    data: &mut [u8],
) -> Result<Option<u64>, Trap> {
    if builtin == Builtin::StrFromWStr {
        let (capacity, _) = read_string(data, args[0])?;
        let (_, units) = read_wstring(data, args[1])?;
        let text = String::from_utf16_lossy(&units);
        let room = capacity.min(crate::builtins::MAX_STRING_LEN);
        // Whole characters only: a character that does not fit ends the text.
        let mut out: Vec<u8> = Vec::new();
        for c in text.chars() {
            let mut utf8 = [0u8; 4];
            let bytes = c.encode_utf8(&mut utf8).as_bytes();
            if out.len() + bytes.len() > room {
                break;
            }
            out.extend_from_slice(bytes);
        }
        store_text(data, args[0], out)?;
        return Ok(None);
    }
    // STRING_TO_WSTRING: UTF-8 where valid, every other byte its Latin-1 character.
    let (_, bytes) = read_string(data, args[1])?;
    let mut out = Vec::new();
    let mut rest = &bytes[..];
    while !rest.is_empty() {
        match core::str::from_utf8(rest) {
            Ok(text) => {
                out.extend(text.encode_utf16());
                break;
            }
            Err(e) => {
                let (valid, after) = rest.split_at(e.valid_up_to());
                out.extend(core::str::from_utf8(valid).unwrap_or("").encode_utf16());
                let bad = e.error_len().unwrap_or(after.len());
                out.extend(after[..bad].iter().map(|&b| b as u16));
                rest = &after[bad..];
            }
        }
    }
    store_text(data, args[0], out)?;
    Ok(None)
}

/// Clamps a signed cell into `lo..=hi`.
/// LEFT of a STRING's bytes or a WSTRING's UTF-16 units: the first `n` (clamped).
fn left<T: Copy>(a: &[T], n: u64) -> Vec<T> {
    a[..clamp(n, 0, a.len())].to_vec()
}

/// RIGHT: the last `n` (clamped).
fn right<T: Copy>(a: &[T], n: u64) -> Vec<T> {
    a[a.len() - clamp(n, 0, a.len())..].to_vec()
}

/// MID: `n` from position `p` (1-based; both clamped).
fn mid<T: Copy>(a: &[T], n: u64, p: u64) -> Vec<T> {
    let p = clamp(p, 1, a.len() + 1);
    let n = clamp(n, 0, a.len() + 1 - p);
    a[p - 1..p - 1 + n].to_vec()
}

/// INSERT: `b` after the first `p` of `a` (clamped).
fn insert<T: Copy>(a: &[T], b: &[T], p: u64) -> Vec<T> {
    let p = clamp(p, 0, a.len());
    [&a[..p], b, &a[p..]].concat()
}

/// REPLACE (DELETE: an empty `b`): `n` of `a` from position `p` (1-based) replaced by `b`.
fn replace<T: Copy>(a: &[T], b: &[T], n: u64, p: u64) -> Vec<T> {
    let p = clamp(p, 1, a.len() + 1);
    let n = clamp(n, 0, a.len() + 1 - p);
    [&a[..p - 1], b, &a[p - 1 + n..]].concat()
}

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

// ---- dates: counted with loops over years and months (the library uses era arithmetic) ----

const DAY_NS: i64 = 86_400 * 1_000_000_000;

fn leap_year(year: i64) -> bool {
    year.rem_euclid(4) == 0 && (year.rem_euclid(100) != 0 || year.rem_euclid(400) == 0)
}

fn month_length(year: i64, month: i64) -> i64 {
    const LENGTHS: [i64; 12] = [31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    LENGTHS[(month - 1) as usize] + (month == 2 && leap_year(year)) as i64
}

/// Days from 1970-01-01: whole 400-year cycles (146097 days each), then year by year and
/// month by month.
fn model_days(year: i64, month: i64, day: i64) -> i64 {
    let cycles = (year - 1970).div_euclid(400);
    let mut days = cycles * 146_097;
    for y in 1970 + cycles * 400..year {
        days += 365 + leap_year(y) as i64;
    }
    for m in 1..month {
        days += month_length(year, m);
    }
    days + day - 1
}

fn model_civil(days: i64) -> (i64, i64, i64) {
    let cycles = days.div_euclid(146_097);
    let mut rest = days - cycles * 146_097;
    let mut year = 1970 + cycles * 400;
    while rest >= 365 + leap_year(year) as i64 {
        rest -= 365 + leap_year(year) as i64;
        year += 1;
    }
    let mut month = 1;
    while rest >= month_length(year, month) {
        rest -= month_length(year, month);
        month += 1;
    }
    (year, month, rest + 1)
}

fn model_date(year: i64, month: i64, day: i64) -> Option<i64> {
    if !(-1_000_000..=1_000_000).contains(&year) || !(1..=12).contains(&month) {
        return None;
    }
    if day < 1 || day > month_length(year, month) {
        return None;
    }
    model_days(year, month, day).checked_mul(DAY_NS)
}

fn model_time_kind(cell: u64) -> Result<crate::isa::TimeKind, Trap> {
    crate::isa::TimeKind::from_u64(cell).ok_or(Trap::NumericError)
}

fn model_date_time_literal(kind: crate::isa::TimeKind, ns: i64) -> String {
    use crate::isa::TimeKind::*;
    let prefix = kind.prefix();
    let days = ns.div_euclid(DAY_NS);
    let tod = ns.rem_euclid(DAY_NS);
    let date = || {
        let (y, m, d) = model_civil(days);
        format!("{y:04}-{m:02}-{d:02}")
    };
    let time_of_day = || {
        let s = tod / 1_000_000_000;
        let fraction = format!("{:09}", tod % 1_000_000_000);
        let fraction = fraction.trim_end_matches('0');
        let mut text = format!("{:02}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60);
        if !fraction.is_empty() {
            text = format!("{text}.{fraction}");
        }
        text
    };
    match kind {
        Time | LTime => format!("{prefix}{}", &time_literal(ns)[2..]),
        Date | LDate => format!("{prefix}{}", date()),
        Tod | LTod => format!("{prefix}{}", time_of_day()),
        Dt | LDt => format!("{prefix}{}-{}", date(), time_of_day()),
    }
}

/// A number of 1 to 18 decimal digits.
fn model_number(text: &str) -> Option<i64> {
    if text.is_empty() || text.len() > 18 || !text.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

fn model_parse_tod(text: &str) -> Option<i64> {
    let parts: Vec<&str> = text.split(':').collect();
    let (hour, minute, seconds) = match parts[..] {
        [h, m] => (h, m, "0"),
        [h, m, s] => (h, m, s),
        _ => return None,
    };
    let (second, fraction) = match seconds.split_once('.') {
        Some((s, f)) => {
            if f.is_empty() || !f.bytes().all(|c| c.is_ascii_digit()) {
                return None;
            }
            let nine: String = f.chars().chain("000000000".chars()).take(9).collect();
            (s, nine.parse::<i64>().ok()?)
        }
        None => (seconds, 0),
    };
    let (h, m, s) = (
        model_number(hour)?,
        model_number(minute)?,
        model_number(second)?,
    );
    if h >= 24 || m >= 60 || s >= 60 {
        return None;
    }
    Some(h * 3_600_000_000_000 + m * 60_000_000_000 + s * 1_000_000_000 + fraction)
}

fn model_parse_duration(text: &str) -> Option<i64> {
    let (negative, mut rest) = match text.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, text),
    };
    let mut total: i128 = 0;
    let mut components = 0;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix('_') {
            rest = r;
            continue;
        }
        let end = rest
            .find(|c: char| !c.is_ascii_digit())
            .unwrap_or(rest.len());
        let whole = model_number(&rest[..end])? as i128;
        rest = &rest[end..];
        let mut fraction = (0i128, 1i128);
        if let Some(r) = rest.strip_prefix('.') {
            let end = r.find(|c: char| !c.is_ascii_digit()).unwrap_or(r.len());
            fraction = (model_number(&r[..end])? as i128, 10i128.pow(end as u32));
            rest = &r[end..];
        }
        let end = rest
            .find(|c: char| !c.is_ascii_alphabetic())
            .unwrap_or(rest.len());
        let scale: i128 = match rest[..end].to_ascii_lowercase().as_str() {
            "d" => 86_400_000_000_000,
            "h" => 3_600_000_000_000,
            "m" => 60_000_000_000,
            "s" => 1_000_000_000,
            "ms" => 1_000_000,
            "us" => 1_000,
            "ns" => 1,
            _ => return None,
        };
        rest = &rest[end..];
        // Round half up: floor(x + 1/2).
        let (f, denominator) = fraction;
        total += whole * scale + (2 * f * scale + denominator) / (2 * denominator);
        components += 1;
    }
    if components == 0 {
        return None;
    }
    i64::try_from(if negative { -total } else { total }).ok()
}

fn model_parse_date(text: &str) -> Option<i64> {
    match text.split('-').collect::<Vec<_>>()[..] {
        [y, m, d] => model_date(model_number(y)?, model_number(m)?, model_number(d)?),
        _ => None,
    }
}

fn model_parse_date_time(text: &[u8], kind: crate::isa::TimeKind) -> Option<i64> {
    use crate::isa::TimeKind::*;
    let text = core::str::from_utf8(text)
        .ok()?
        .trim_matches(|c: char| c.is_ascii_whitespace());
    let family: &[&str] = match kind {
        Time | LTime => &["T#", "TIME#", "LT#", "LTIME#"],
        Date | LDate => &["D#", "DATE#", "LD#", "LDATE#"],
        Tod | LTod => &["TOD#", "TIME_OF_DAY#", "LTOD#", "LTIME_OF_DAY#"],
        Dt | LDt => &["DT#", "DATE_AND_TIME#", "LDT#", "LDATE_AND_TIME#"],
    };
    let upper = text.to_ascii_uppercase();
    let body = family
        .iter()
        .find(|p| upper.starts_with(*p))
        .map_or(text, |p| &text[p.len()..]);
    match kind {
        Time | LTime => model_parse_duration(body),
        Date | LDate => model_parse_date(body),
        Tod | LTod => model_parse_tod(body),
        Dt | LDt => {
            let mut parts = body.splitn(4, '-');
            let (y, m, d) = (parts.next()?, parts.next()?, parts.next()?);
            let date = model_parse_date(&format!("{y}-{m}-{d}"))?;
            date.checked_add(model_parse_tod(parts.next()?)?)
        }
    }
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

/// Independent implementation of the non-math builtins (STRING and date), written from the
/// documentation of [`Builtin`].
pub fn string_builtin(
    builtin: Builtin,
    args: &[u64],
    data: &mut [u8],
) -> Result<Option<u64>, Trap> {
    use Builtin::*;
    match text_op(builtin) {
        Some((op, false)) => return text_builtin::<u8>(op, args, data),
        Some((op, true)) => return text_builtin::<u16>(op, args, data),
        None => {}
    }
    if matches!(builtin, StrFromWStr | WStrFromStr) {
        return wstring_conversion(builtin, args, data);
    }
    match builtin {
        StrToI64 => {
            let (_, a) = read_string(data, args[0])?;
            return parse_integer(&a)
                .map(|v| Some(v as u64))
                .ok_or(Trap::NumericError);
        }
        DateFromParts => {
            let [y, m, d] = [args[0], args[1], args[2]].map(|c| c as i64);
            return model_date(y, m, d)
                .map(|v| Some(v as u64))
                .ok_or(Trap::NumericError);
        }
        TodFromParts => {
            let [h, m, s, ms] = [args[0], args[1], args[2], args[3]].map(|c| c as i64);
            let ok = (0..24).contains(&h)
                && (0..60).contains(&m)
                && (0..60).contains(&s)
                && (0..1000).contains(&ms);
            if !ok {
                return Err(Trap::NumericError);
            }
            return Ok(Some(
                (((h * 60 + m) * 60 + s) * 1000 + ms) as u64 * 1_000_000,
            ));
        }
        DateSplit => {
            let (y, m, d) = model_civil((args[0] as i64).div_euclid(DAY_NS));
            return Ok(Some(((y as u64) << 16) + ((m as u64) << 8) + d as u64));
        }
        DateOf => {
            let ns = args[0] as i64;
            let midnight = (ns as i128) - (ns as i128).rem_euclid(DAY_NS as i128);
            return i64::try_from(midnight)
                .map(|v| Some(v as u64))
                .map_err(|_| Trap::NumericError);
        }
        TodOf => return Ok(Some((args[0] as i64).rem_euclid(DAY_NS) as u64)),
        DayOfWeek => {
            // 1970-01-01 was a Thursday (4).
            let days = (args[0] as i64).div_euclid(DAY_NS);
            return Ok(Some((days % 7 + 7 + 4) as u64 % 7));
        }
        StrToDateTime => {
            let (_, a) = read_string(data, args[0])?;
            let kind = model_time_kind(args[1])?;
            return model_parse_date_time(&a, kind)
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
        StrSync => {
            let (capacity, _) = read_string(data, args[0])?;
            let a = args[0] as usize;
            let mut len = 0;
            while len < capacity && data[a + 4 + len] != 0 {
                len += 1;
            }
            data[a + 2..a + 4].copy_from_slice(&(len as u16).to_le_bytes());
            return Ok(None);
        }
        _ => {}
    }
    // The target is checked before the value is made (a bad target traps first).
    read_string(data, args[0])?;
    let result: Vec<u8> = match builtin {
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
        StrFromDateTime => {
            model_date_time_literal(model_time_kind(args[2])?, args[1] as i64).into_bytes()
        }
        _ => unreachable!("math builtins are not string builtins"),
    };
    store_text(data, args[0], result)?;
    Ok(None)
}
