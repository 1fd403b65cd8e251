//! Which frame variables of a POU live in Rust locals (registers) while it runs, instead of
//! being loaded from and stored to data memory at every `LD_REL`/`ST_REL`.
//!
//! LLVM cannot keep them in registers itself: an array element is stored through a computed
//! address, which could be any byte of data memory as far as it knows. The translator knows
//! better: an abstract interpretation of the operand stack tracks which cells are addresses
//! of the frame (`LEA_REL off`, then `INDEX`/`ADD_IMM`) or absolute (`PUSH_U32 c`) and over
//! which range, so an indirect access can be shown to miss a variable. The POU's frame base
//! is known when every call site (and task) passes the same one (a FUNCTION's static frame, a
//! program instance), and then absolute accesses can be compared with the frame too.
//!
//! A variable is kept in a local ("promoted") when a loop of the POU uses it, no other
//! access of the POU overlaps it in a way the analysis cannot rule out, and no loop of the
//! POU contains an instruction that may touch memory the analysis cannot place (a CALL, a
//! STRING builtin, an indirect access through an address loaded from memory, ...). At every
//! such instruction outside loops, and at a trap and a RET, the locals are written back
//! (and read again after an instruction that may write), so data memory is exactly the
//! interpreter's wherever anything can observe it.

use crate::analysis::PouPlan;
use crate::structure::Structure;
use plc_vm::image::Image;
use plc_vm::isa::{Builtin, MemType, Opcode};
use std::collections::BTreeMap;

/// A stack cell as an address: frame-relative (`base + lo ..= base + hi`), absolute, or
/// anything.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Addr {
    Frame(i128, i128),
    Abs(i128, i128),
    Unknown,
}

impl Addr {
    fn join(self, other: Addr) -> Addr {
        match (self, other) {
            (Addr::Frame(a, b), Addr::Frame(c, d)) => Addr::Frame(a.min(c), b.max(d)),
            (Addr::Abs(a, b), Addr::Abs(c, d)) => Addr::Abs(a.min(c), b.max(d)),
            _ => Addr::Unknown,
        }
    }

    fn shift(self, lo: i128, hi: i128) -> Addr {
        let fits = |a: i128, b: i128| a >= 0 && b <= u64::MAX as i128;
        match self {
            Addr::Frame(a, b) if fits(a + lo, b + hi) => Addr::Frame(a + lo, b + hi),
            Addr::Abs(a, b) if fits(a + lo, b + hi) => Addr::Abs(a + lo, b + hi),
            _ => Addr::Unknown,
        }
    }
}

/// What happens around an instruction for the promoted variables.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sync {
    /// Nothing.
    None,
    /// Write them back before it (it may read them from memory).
    Flush,
    /// Write them back before it and read them again after it (it may write memory).
    FlushReload,
}

/// The promotion of one POU.
#[derive(Clone, Debug, Default)]
pub struct Promotion {
    /// The promoted variables: (frame offset, width in bytes); local `v<k>` is the k-th.
    pub vars: Vec<(u32, u8)>,
    /// Per instruction (index into `PouPlan::insns`).
    pub sync: Vec<Option<Sync>>,
}

impl Promotion {
    /// The local of a frame access, if it is promoted.
    pub fn var(&self, offset: u32, width: u8) -> Option<usize> {
        self.vars.iter().position(|&v| v == (offset, width))
    }

    /// What to do around instruction `i`.
    pub fn sync(&self, i: usize) -> Sync {
        if self.vars.is_empty() {
            return Sync::None;
        }
        self.sync.get(i).copied().flatten().unwrap_or(Sync::None)
    }
}

/// The memory an instruction touches, as far as the analysis can tell.
enum Touch {
    /// No data memory.
    Nothing,
    /// Bytes `[lo, hi)` relative to the frame base.
    Frame { lo: i128, hi: i128, write: bool },
    /// Unknown bytes (read and maybe written).
    Anything { write: bool },
}

/// The abstract addresses of every reachable instruction's operand stack (its cells before
/// it runs), by instruction index.
pub fn addresses(image: &Image<'_>, plan: &PouPlan<'_>, st: &Structure) -> Vec<Vec<Addr>> {
    let n = plan.blocks.len();
    let mut entry: Vec<Option<Vec<Addr>>> = vec![None; n];
    let mut changes = vec![0u32; n];
    for &h in &st.heads {
        let depth = plan.insns[plan.blocks[h].first].depth as usize;
        entry[h] = Some(vec![Addr::Unknown; depth]);
    }
    entry[0] = Some(vec![Addr::Unknown; plan.pou.arg_cells as usize]);
    let mut at = vec![Vec::new(); plan.insns.len()];
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&b| st.rpo[b]);
    let mut changed = true;
    while changed {
        changed = false;
        for &b in &order {
            let Some(mut stack) = entry[b].clone() else {
                continue;
            };
            let block = &plan.blocks[b];
            for (slot, insn) in at[block.first..=block.last]
                .iter_mut()
                .zip(&plan.insns[block.first..=block.last])
            {
                *slot = stack.clone();
                step(image, insn, &mut stack);
            }
            // Region heads (the try handlers among them) start with unknown cells.
            for &s in &st.succ[b] {
                if st.is_head[s] {
                    continue;
                }
                let joined = match &entry[s] {
                    None => stack.clone(),
                    Some(old) => {
                        let mut j: Vec<Addr> =
                            old.iter().zip(&stack).map(|(a, b)| a.join(*b)).collect();
                        if changes[s] > 8 && &j != old {
                            // Widening: ranges that keep growing are anything.
                            for (x, o) in j.iter_mut().zip(old) {
                                if x != o {
                                    *x = Addr::Unknown;
                                }
                            }
                        }
                        j
                    }
                };
                if entry[s].as_ref() != Some(&joined) {
                    entry[s] = Some(joined);
                    changes[s] += 1;
                    changed = true;
                }
            }
        }
    }
    at
}

/// The abstract effect of one instruction on the operand stack.
fn step(image: &Image<'_>, insn: &crate::analysis::Insn<'_>, stack: &mut Vec<Addr>) {
    use Opcode::*;
    let d = stack.len();
    let top = |k: usize| stack[d - k];
    let result = match insn.op {
        PushI32 => Some(Addr::Abs(
            insn.u32_at(0) as i32 as i64 as u64 as i128,
            insn.u32_at(0) as i32 as i64 as u64 as i128,
        )),
        PushU32 => Some(Addr::Abs(insn.u32_at(0) as i128, insn.u32_at(0) as i128)),
        PushI64 => Some(Addr::Abs(insn.u64_at(0) as i128, insn.u64_at(0) as i128)),
        PushConst => image
            .constant(insn.u16_at(0) as usize)
            .map(|c| Addr::Abs(c as i128, c as i128)),
        LeaRel => Some(Addr::Frame(insn.u32_at(0) as i128, insn.u32_at(0) as i128)),
        Dup => Some(top(1)),
        Over => Some(top(2)),
        AddImm => Some(top(1).shift(insn.u32_at(0) as i32 as i128, insn.u32_at(0) as i32 as i128)),
        Index => {
            let (lo, hi) = (insn.u64_at(0) as i64 as i128, insn.u64_at(8) as i64 as i128);
            let stride = insn.u32_at(16) as i128;
            Some(if hi < lo {
                Addr::Unknown
            } else {
                top(2).shift(0, (hi - lo) * stride)
            })
        }
        ElemRel | ElemAbs | ElemRelAt | ElemAbsAt => {
            let (a, lo, hi) = (
                insn.u32_at(0) as i128,
                insn.u64_at(4) as i64 as i128,
                insn.u64_at(12) as i64 as i128,
            );
            let stride = insn.u32_at(20) as i128;
            Some(if hi < lo {
                Addr::Unknown
            } else if matches!(insn.op, ElemRel | ElemRelAt) {
                Addr::Frame(a, a + (hi - lo) * stride)
            } else {
                Addr::Abs(a, a + (hi - lo) * stride)
            })
        }
        Add => match (top(2), top(1)) {
            (a, Addr::Abs(c, e)) | (Addr::Abs(c, e), a) if matches!(a, Addr::Frame(..)) => {
                Some(a.shift(c, e))
            }
            _ => Some(Addr::Unknown),
        },
        _ => None,
    };
    match insn.op {
        Swap => stack.swap(d - 1, d - 2),
        Dup | Over => stack.push(result.unwrap_or(Addr::Unknown)),
        _ => {
            stack.truncate(d - insn.pops as usize);
            for _ in 0..insn.pushes {
                stack.push(Addr::Unknown);
            }
            if let (Some(r), Some(slot)) = (result, stack.last_mut())
                && insn.pushes == 1
            {
                *slot = r;
            }
        }
    }
}

/// The frame variables an instruction reads or writes by offset, as `(offset, type byte)`:
/// LD_REL, ST_REL and the superinstructions with frame-relative operands (which the
/// emitter translates against a promoted variable's local as it does those two).
pub fn frame_variables(insn: &crate::analysis::Insn<'_>) -> Vec<(u32, u8)> {
    use Opcode::*;
    match insn.op {
        LdRel | StRel | IncRel => vec![(insn.u32_at(1), insn.imm[0])],
        OpRel | JumpIfRelImm | JumpIfNotRelImm => vec![(insn.u32_at(2), insn.imm[1])],
        OpRelRel => vec![(insn.u32_at(2), insn.imm[1]), (insn.u32_at(7), insn.imm[6])],
        // The index variable.
        ElemRelAt | ElemAbsAt => vec![(insn.u32_at(25), insn.imm[24])],
        LdElemRelAt | LdElemAbsAt | StElemRelAt | StElemAbsAt => {
            vec![(insn.u32_at(26), insn.imm[25])]
        }
        _ => Vec::new(),
    }
}

/// Bytes of an access through abstract address `a` plus `off`, `width` long, relative to
/// the frame base (`None`: cannot tell).
fn frame_bytes(a: Addr, off: i128, width: i128, base: Option<u32>) -> Option<(i128, i128)> {
    match a {
        Addr::Frame(lo, hi) => Some((lo + off, hi + off + width)),
        Addr::Abs(lo, hi) => base.map(|b| (lo + off - b as i128, hi + off + width - b as i128)),
        Addr::Unknown => None,
    }
}

/// What instruction `insn` (abstract stack `stack`) may touch.
fn touch(insn: &crate::analysis::Insn<'_>, stack: &[Addr], base: Option<u32>) -> Vec<Touch> {
    use Opcode::*;
    let d = stack.len();
    let width = |b: u8| MemType::from_code(b).map_or(8, |t| t.width()) as i128;
    let through = |a: Addr, off: i128, w: i128, write: bool| match frame_bytes(a, off, w, base) {
        Some((lo, hi)) => Touch::Frame { lo, hi, write },
        None => Touch::Anything { write },
    };
    match insn.op {
        LdAbs | StAbs => {
            let a = Addr::Abs(insn.u32_at(1) as i128, insn.u32_at(1) as i128);
            vec![through(a, 0, width(insn.imm[0]), insn.op == StAbs)]
        }
        LdInd => vec![through(
            stack[d - 1],
            insn.u32_at(1) as i128,
            width(insn.imm[0]),
            false,
        )],
        StInd => vec![through(
            stack[d - 2],
            insn.u32_at(1) as i128,
            width(insn.imm[0]),
            true,
        )],
        Copy => {
            let len = insn.u32_at(0) as i128;
            vec![
                through(stack[d - 2], 0, len, true),
                through(stack[d - 1], 0, len, false),
            ]
        }
        LdElemRel | LdElemAbs | StElemRel | StElemAbs | LdElemRelAt | LdElemAbsAt | StElemRelAt
        | StElemAbsAt => {
            let (a, lo, hi) = (
                insn.u32_at(1) as i128,
                insn.u64_at(5) as i64 as i128,
                insn.u64_at(13) as i64 as i128,
            );
            let stride = insn.u32_at(21) as i128;
            let write = matches!(insn.op, StElemRel | StElemAbs | StElemRelAt | StElemAbsAt);
            let array = if hi < lo {
                Addr::Unknown
            } else if matches!(insn.op, LdElemRel | StElemRel | LdElemRelAt | StElemRelAt) {
                Addr::Frame(a, a + (hi - lo) * stride)
            } else {
                Addr::Abs(a, a + (hi - lo) * stride)
            };
            vec![through(array, 0, width(insn.imm[0]), write)]
        }
        // A global read (and for INC written) in place. (Their frame-relative forms access
        // frame variables as LD_REL/ST_REL do: see `frame_variables`.)
        IncAbs | OpAbs => {
            let (ty, off) = match insn.op {
                IncAbs => (insn.imm[0], insn.u32_at(1)),
                _ => (insn.imm[1], insn.u32_at(2)),
            };
            let a = Addr::Abs(off as i128, off as i128);
            vec![through(a, 0, width(ty), insn.op == IncAbs)]
        }
        Call | CallVirt => vec![Touch::Anything { write: true }],
        // The class id of the instance.
        VirtFrame => vec![Touch::Anything { write: false }],
        CallBuiltin => match Builtin::from_u16(insn.u16_at(0)) {
            Some(b) if b.is_math() => vec![Touch::Nothing],
            _ => vec![Touch::Anything { write: true }],
        },
        _ => vec![Touch::Nothing],
    }
}

/// Blocks that lie on a cycle of the POU's control flow (Tarjan's strongly connected
/// components with more than one block, or a block branching to itself).
fn in_loops(st: &Structure) -> Vec<bool> {
    let n = st.succ.len();
    let mut index = vec![usize::MAX; n];
    let mut low = vec![0usize; n];
    let mut on_stack = vec![false; n];
    let mut stack = Vec::new();
    let mut next = 0usize;
    let mut result = vec![false; n];
    for root in 0..n {
        if index[root] != usize::MAX {
            continue;
        }
        // Iterative Tarjan: (node, successor position).
        let mut work = vec![(root, 0usize)];
        index[root] = next;
        low[root] = next;
        next += 1;
        stack.push(root);
        on_stack[root] = true;
        while let Some(&mut (v, ref mut i)) = work.last_mut() {
            if let Some(&w) = st.succ[v].get(*i) {
                *i += 1;
                if index[w] == usize::MAX {
                    index[w] = next;
                    low[w] = next;
                    next += 1;
                    stack.push(w);
                    on_stack[w] = true;
                    work.push((w, 0));
                } else if on_stack[w] {
                    low[v] = low[v].min(index[w]);
                }
                continue;
            }
            work.pop();
            if let Some(&(parent, _)) = work.last() {
                low[parent] = low[parent].min(low[v]);
            }
            if low[v] == index[v] {
                let mut component = Vec::new();
                while let Some(w) = stack.pop() {
                    on_stack[w] = false;
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                let cyclic = component.len() > 1 || st.succ[v].contains(&v);
                for w in component {
                    result[w] = cyclic;
                }
            }
        }
    }
    result
}

/// The absolute frame base each CALL of `plan` passes (`(callee, base)`; `None`: cannot
/// tell), given the POU's own base (`base`, if fixed) and its abstract stacks.
pub fn call_bases(
    plan: &PouPlan<'_>,
    stacks: &[Vec<Addr>],
    base: Option<u32>,
) -> Vec<(usize, Option<u64>)> {
    plan.insns
        .iter()
        .enumerate()
        .filter(|(_, insn)| insn.op == Opcode::Call)
        .map(|(i, insn)| {
            let cell = stacks[i].last().copied().unwrap_or(Addr::Unknown);
            let absolute = match (cell, base) {
                (Addr::Abs(lo, hi), _) if lo == hi => u64::try_from(lo).ok(),
                (Addr::Frame(lo, hi), Some(b)) if lo == hi => u64::try_from(lo + b as i128).ok(),
                _ => None,
            };
            (insn.u16_at(0) as usize, absolute)
        })
        .collect()
}

/// The promotion of POU `plan` (abstract stacks `stacks`) whose frame base is `base` at
/// every call, if known.
pub fn promote(
    plan: &PouPlan<'_>,
    st: &Structure,
    stacks: &[Vec<Addr>],
    base: Option<u32>,
) -> Promotion {
    let none = Promotion::default();
    let looping = in_loops(st);
    if !looping.iter().any(|&l| l)
        || stacks.len() != plan.insns.len()
        || stacks
            .iter()
            .zip(&plan.insns)
            .any(|(s, insn)| s.len() != insn.depth as usize)
    {
        return none;
    }
    let mut block_of = vec![0usize; plan.insns.len()];
    for (b, block) in plan.blocks.iter().enumerate() {
        for slot in &mut block_of[block.first..=block.last] {
            *slot = b;
        }
    }
    // Candidates: frame variables as (offset, width), used in a loop.
    let mut groups: BTreeMap<(u32, u8), bool> = BTreeMap::new();
    for (i, insn) in plan.insns.iter().enumerate() {
        for (off, ty) in frame_variables(insn) {
            let Some(ty) = MemType::from_code(ty) else {
                return none;
            };
            let key = (off, ty.width() as u8);
            *groups.entry(key).or_default() |= looping[block_of[i]];
        }
    }
    let mut candidates: Vec<(u32, u8)> = groups
        .iter()
        .filter(|&(_, &in_loop)| in_loop)
        .map(|(&k, _)| k)
        .collect();
    let overlaps =
        |(o, w): (u32, u8), lo: i128, hi: i128| (o as i128) < hi && lo < o as i128 + w as i128;
    // Variables overlapping another frame access of another width or offset are left alone.
    let all: Vec<(u32, u8)> = groups.keys().copied().collect();
    candidates.retain(|&c| {
        all.iter()
            .filter(|&&g| g != c)
            .all(|&(o, w)| !overlaps(c, o as i128, o as i128 + w as i128))
    });
    // Inside a loop: an access that may overlap a variable keeps it in memory, one that may
    // touch anything keeps all of them there. Outside loops: the variables are written back
    // before it and read again after it (when it may write).
    let mut sync = vec![None; plan.insns.len()];
    for (i, insn) in plan.insns.iter().enumerate() {
        let in_loop = looping[block_of[i]];
        for t in touch(insn, &stacks[i], base) {
            let write = match t {
                Touch::Nothing => continue,
                Touch::Frame { lo, hi, write } => {
                    if in_loop {
                        candidates.retain(|&c| !overlaps(c, lo, hi));
                        continue;
                    }
                    if !candidates.iter().any(|&c| overlaps(c, lo, hi)) {
                        continue;
                    }
                    write
                }
                Touch::Anything { write } => {
                    if in_loop {
                        return none;
                    }
                    write
                }
            };
            let s = if write {
                Sync::FlushReload
            } else {
                Sync::Flush
            };
            sync[i] = Some(match sync[i] {
                Some(Sync::FlushReload) => Sync::FlushReload,
                _ => s,
            });
        }
    }
    if candidates.is_empty() {
        return none;
    }
    Promotion {
        vars: candidates,
        sync,
    }
}
