//! What the translator knows about each POU of a verified image before it writes code: the
//! reachable instructions with their static operand-stack depth (the verifier's abstract
//! interpretation, redone here), the basic blocks, the largest depth (how many cell locals
//! the POU's function needs), the try-handler targets, and the one pattern the native tier
//! refuses (a try frame that could see cells a callee wrote, see `check_try_frames`).
//!
//! It never accepts an image the verifier has not accepted: [`crate::translate`] verifies
//! first, and every inconsistency found here is reported, never patched.

use crate::Error;
use plc_vm::image::{Image, Pou};
use plc_vm::isa::{self, Builtin, Opcode, stack_effect};
use std::collections::{BTreeMap, BTreeSet};

/// One reachable instruction.
#[derive(Clone, Debug)]
pub struct Insn<'a> {
    /// Code offset.
    pub pc: u32,
    pub op: Opcode,
    /// The immediate bytes.
    pub imm: &'a [u8],
    /// Operand-stack depth before it (cells of this activation).
    pub depth: u32,
    /// Cells popped and pushed.
    pub pops: u32,
    pub pushes: u32,
}

impl Insn<'_> {
    /// Depth after it (on the fall-through path).
    pub fn depth_after(&self) -> u32 {
        self.depth - self.pops + self.pushes
    }

    /// Code offset of the next instruction.
    pub fn next(&self) -> u32 {
        self.pc + self.op.size() as u32
    }

    pub fn u16_at(&self, at: usize) -> u16 {
        u16::from_le_bytes([self.imm[at], self.imm[at + 1]])
    }

    pub fn u32_at(&self, at: usize) -> u32 {
        u32::from_le_bytes(self.imm[at..at + 4].try_into().expect("4 bytes"))
    }

    pub fn u64_at(&self, at: usize) -> u64 {
        u64::from_le_bytes(self.imm[at..at + 8].try_into().expect("8 bytes"))
    }

    /// Jump target (JMP/JZ/JNZ/TRY_BEGIN) or the target of JUMP_IF/JUMP_IF_NOT and their
    /// immediate forms.
    pub fn target(&self) -> Option<u32> {
        match self.op {
            Opcode::Jmp | Opcode::Jz | Opcode::Jnz | Opcode::TryBegin => Some(self.u32_at(0)),
            Opcode::JumpIf | Opcode::JumpIfNot => Some(self.u32_at(1)),
            Opcode::JumpIfImm | Opcode::JumpIfNotImm => Some(self.u32_at(5)),
            Opcode::JumpIfRelImm | Opcode::JumpIfNotRelImm => Some(self.u32_at(10)),
            _ => None,
        }
    }

    /// Whether it ends a basic block: control goes elsewhere or to a callee, whose
    /// instructions count before the rest of this block.
    pub fn ends_block(&self) -> bool {
        matches!(
            self.op,
            Opcode::Jmp
                | Opcode::Jz
                | Opcode::Jnz
                | Opcode::JumpIf
                | Opcode::JumpIfNot
                | Opcode::JumpIfImm
                | Opcode::JumpIfNotImm
                | Opcode::JumpIfRelImm
                | Opcode::JumpIfNotRelImm
                | Opcode::Call
                | Opcode::CallVirt
                | Opcode::Ret
                | Opcode::Throw
        )
    }

    /// Whether execution can continue with the next instruction.
    pub fn falls_through(&self) -> bool {
        !matches!(self.op, Opcode::Jmp | Opcode::Ret | Opcode::Throw)
    }
}

/// A basic block: instructions `first..=last` (indices into [`PouPlan::insns`]).
#[derive(Clone, Debug)]
pub struct Block {
    pub first: usize,
    pub last: usize,
}

impl Block {
    /// Instructions in it (at least one).
    pub fn instructions(&self) -> u32 {
        (self.last - self.first + 1) as u32
    }
}

/// Everything the emitter needs about one POU.
#[derive(Clone, Debug)]
pub struct PouPlan<'a> {
    pub index: usize,
    pub pou: Pou<'a>,
    /// Reachable instructions in code order.
    pub insns: Vec<Insn<'a>>,
    pub blocks: Vec<Block>,
    /// Block index by the code offset of its first instruction.
    pub block_at: BTreeMap<u32, usize>,
    /// Largest operand-stack depth of an activation (its cell locals).
    pub max_depth: u32,
    /// Handler code offsets of its TRY_BEGINs.
    pub handlers: BTreeSet<u32>,
}

impl PouPlan<'_> {
    /// The block that starts at code offset `pc`.
    pub fn block_of(&self, pc: u32) -> Result<usize, Error> {
        self.block_at
            .get(&pc)
            .copied()
            .ok_or_else(|| Error::internal(format!("no block starts at code offset {pc}")))
    }
}

/// `(pops, pushes)` of an instruction.
fn effect(image: &Image<'_>, insn_op: Opcode, imm: &[u8], pc: u32) -> Result<(u32, u32), Error> {
    Ok(match insn_op {
        Opcode::Call => {
            let index = u16::from_le_bytes([imm[0], imm[1]]);
            let callee = image
                .pou(index as usize)
                .ok_or_else(|| Error::internal(format!("CALL of unknown POU {index} at {pc}")))?;
            (1 + callee.arg_cells as u32, callee.ret_cells as u32)
        }
        Opcode::CallBuiltin => {
            let id = u16::from_le_bytes([imm[0], imm[1]]);
            let builtin = Builtin::from_u16(id).ok_or(Error::UnsupportedBuiltin { pc, id })?;
            (builtin.args() as u32, builtin.results() as u32)
        }
        Opcode::Ret => (0, 0),
        op => stack_effect(op).ok_or_else(|| Error::UnsupportedOpcode {
            pc,
            opcode: op as u8,
            mnemonic: op.mnemonic(),
        })?,
    })
}

/// Analyses POU `index` of a verified image.
pub fn plan<'a>(image: &Image<'a>, index: usize) -> Result<PouPlan<'a>, Error> {
    let code = image.code();
    let pou = image
        .pou(index)
        .ok_or_else(|| Error::internal(format!("POU {index} missing")))?;
    let start = pou.code_start;
    let end = pou.code_start + pou.code_len;
    // Depth before each reachable instruction, by abstract interpretation (a worklist;
    // the verifier guarantees one depth per instruction).
    let mut depth_at: BTreeMap<u32, u32> = BTreeMap::new();
    let mut work = vec![(start, pou.arg_cells as u32)];
    let mut handlers = BTreeSet::new();
    let mut decoded = BTreeMap::new();
    while let Some((pc, depth)) = work.pop() {
        if pc < start || pc >= end {
            return Err(Error::internal(format!(
                "control leaves POU {} at {pc}",
                pou.name
            )));
        }
        if let Some(&known) = depth_at.get(&pc) {
            if known != depth {
                return Err(Error::internal(format!(
                    "two stack depths at {pc} ({known}, {depth})"
                )));
            }
            continue;
        }
        depth_at.insert(pc, depth);
        let instruction = isa::decode(code, pc as usize)
            .ok_or_else(|| Error::internal(format!("undecodable instruction at {pc}")))?;
        let op = instruction.op;
        let imm = instruction.immediates;
        let (pops, pushes) = effect(image, op, imm, pc)?;
        if depth < pops {
            return Err(Error::internal(format!("stack underflow at {pc}")));
        }
        let insn = Insn {
            pc,
            op,
            imm,
            depth,
            pops,
            pushes,
        };
        let after = insn.depth_after();
        if let Some(target) = insn.target() {
            if op == Opcode::TryBegin {
                handlers.insert(target);
                work.push((target, after + 1));
            } else {
                work.push((target, after));
            }
        }
        if insn.falls_through() {
            work.push((insn.next(), after));
        }
        decoded.insert(pc, insn);
    }
    let insns: Vec<Insn<'a>> = decoded.into_values().collect();
    let mut max_depth = pou.arg_cells as u32;
    for insn in &insns {
        max_depth = max_depth.max(insn.depth).max(insn.depth_after());
    }
    for &h in &handlers {
        max_depth = max_depth.max(depth_at[&h]);
    }
    // Leaders: the entry, every jump and handler target, every instruction after one that
    // ends a block, every instruction whose code-order predecessor is not reachable.
    let mut leaders: BTreeSet<u32> = BTreeSet::new();
    leaders.insert(start);
    leaders.extend(handlers.iter().copied());
    for (i, insn) in insns.iter().enumerate() {
        if let Some(t) = insn.target()
            && insn.op != Opcode::TryBegin
        {
            leaders.insert(t);
        }
        if insn.ends_block() && insn.falls_through() {
            leaders.insert(insn.next());
        }
        if i > 0 && insns[i - 1].next() != insn.pc {
            leaders.insert(insn.pc);
        }
    }
    let mut blocks = Vec::new();
    let mut block_at = BTreeMap::new();
    let mut first = 0usize;
    for i in 0..insns.len() {
        let last_of_block = i + 1 == insns.len()
            || insns[i].ends_block()
            || leaders.contains(&insns[i + 1].pc)
            || !insns[i].falls_through();
        if last_of_block {
            block_at.insert(insns[first].pc, blocks.len());
            blocks.push(Block { first, last: i });
            first = i + 1;
        }
    }
    let plan = PouPlan {
        index,
        pou,
        insns,
        blocks,
        block_at,
        max_depth,
        handlers,
    };
    check_try_frames(image, &plan)?;
    Ok(plan)
}

/// The native tier keeps each activation's cells in its own locals, so a try frame must
/// never cover cells that a callee writes: when a trap cuts the stack back to a frame's
/// depth, the interpreter's cells below that depth are the activation's own, unless the
/// activation popped below the frame's depth and then called a POU (whose cells start
/// there). The compiler never does this (a `__TRY` body is statements, which keep the
/// stack), but a verified image may; it is refused here (the interpreter runs it).
///
/// For every instruction the depths at the TRY_BEGINs of the frames that may be open are
/// computed (per nesting level, the largest over all paths); a CALL whose callee's first
/// cell lies below one of them is refused.
fn check_try_frames(image: &Image<'_>, plan: &PouPlan<'_>) -> Result<(), Error> {
    if plan.handlers.is_empty() {
        return Ok(());
    }
    let index_of: BTreeMap<u32, usize> = plan
        .insns
        .iter()
        .enumerate()
        .map(|(i, insn)| (insn.pc, i))
        .collect();
    let mut open: Vec<Option<Vec<u32>>> = vec![None; plan.insns.len()];
    let mut work = vec![(plan.pou.code_start, Vec::<u32>::new())];
    let merge = |pc: u32, frames: Vec<u32>, work: &mut Vec<(u32, Vec<u32>)>| {
        work.push((pc, frames));
    };
    while let Some((pc, frames)) = work.pop() {
        let Some(&i) = index_of.get(&pc) else {
            continue;
        };
        let merged = match &open[i] {
            None => frames,
            Some(known) if known.len() == frames.len() => {
                let max: Vec<u32> = known.iter().zip(&frames).map(|(a, b)| *a.max(b)).collect();
                if &max == known {
                    continue;
                }
                max
            }
            Some(_) => {
                return Err(Error::internal(format!("try nesting differs at {pc}")));
            }
        };
        open[i] = Some(merged.clone());
        let insn = &plan.insns[i];
        match insn.op {
            Opcode::TryBegin => {
                let mut inner = merged.clone();
                inner.push(insn.depth);
                merge(insn.next(), inner, &mut work);
                merge(insn.u32_at(0), merged.clone(), &mut work);
            }
            Opcode::TryEnd => {
                let mut outer = merged.clone();
                outer.pop();
                merge(insn.next(), outer, &mut work);
            }
            Opcode::Call | Opcode::CallVirt => {
                let args = match insn.op {
                    Opcode::Call => {
                        image
                            .pou(insn.u16_at(0) as usize)
                            .ok_or_else(|| Error::internal("CALL of unknown POU".into()))?
                            .arg_cells as u32
                    }
                    _ => 0,
                };
                let region = insn.depth - 1 - args;
                if merged.iter().any(|&d| d > region) {
                    return Err(Error::TryFrameOverCall {
                        pou: plan.pou.name.to_string(),
                        pc,
                    });
                }
                merge(insn.next(), merged.clone(), &mut work);
            }
            _ => {
                if let Some(t) = insn.target() {
                    merge(t, merged.clone(), &mut work);
                }
                if insn.falls_through() {
                    merge(insn.next(), merged.clone(), &mut work);
                }
            }
        }
    }
    Ok(())
}
