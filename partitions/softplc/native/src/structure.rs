//! Structured control flow for a POU's basic blocks, so that the generated Rust branches
//! directly (labeled `loop`s and blocks with `continue`/`break`) instead of through a
//! state variable, which LLVM would leave as one indirect jump per block.
//!
//! The method is Norman Ramsey's ("Beyond Relooper", ICFP 2022): with the dominator tree,
//! every loop header becomes a labeled `loop`, every merge node (a block with two or more
//! forward predecessors) the code after a labeled block its predecessors `break` out of,
//! every other block is written at its only predecessor's branch. It needs a reducible
//! graph with one entry; a POU has several entries (its start and its try handlers, which
//! the unwinding enters), so the graph is cut into *regions*: each entry, and each block
//! reached from two entries or only through a back edge from outside its dominator, heads
//! a region; a branch to another region's head goes through a small dispatch (`entry = k;
//! continue 'dispatch`). Compiler output has one region per entry; any verified image,
//! however irreducible, still translates (in the worst case every block heads a region).

use crate::analysis::PouPlan;
use std::collections::BTreeSet;

/// The structure the emitter follows.
#[derive(Clone, Debug)]
pub struct Structure {
    /// Successor blocks of each block (in branch order: taken target first).
    pub succ: Vec<Vec<usize>>,
    /// Region heads, in dispatch order (index = dispatch number); the POU start first.
    pub heads: Vec<usize>,
    /// Whether a block heads a region.
    pub is_head: Vec<bool>,
    /// Immediate dominator (`None` for heads).
    pub idom: Vec<Option<usize>>,
    /// Dominator-tree children.
    pub children: Vec<Vec<usize>>,
    /// Reverse-postorder number.
    pub rpo: Vec<usize>,
    /// Target of a back edge from a block it dominates.
    pub loop_header: Vec<bool>,
    /// Two or more forward predecessors inside its region.
    pub merge: Vec<bool>,
}

impl Structure {
    /// Whether `a` dominates `b` (both in one region; a block dominates itself).
    pub fn dominates(&self, a: usize, b: usize) -> bool {
        let mut x = Some(b);
        while let Some(n) = x {
            if n == a {
                return true;
            }
            x = self.idom[n];
        }
        false
    }

    /// The dispatch number of head `block`.
    pub fn head_number(&self, block: usize) -> usize {
        self.heads
            .iter()
            .position(|&h| h == block)
            .expect("a region head")
    }
}

/// The successors of block `b` of `plan`.
fn successors(plan: &PouPlan<'_>, b: usize) -> Vec<usize> {
    use plc_vm::Opcode;
    let last = &plan.insns[plan.blocks[b].last];
    let block_at = |pc: u32| plan.block_at.get(&pc).copied();
    let mut out = Vec::new();
    match last.op {
        Opcode::Jmp => out.extend(last.target().and_then(block_at)),
        Opcode::Jz
        | Opcode::Jnz
        | Opcode::JumpIf
        | Opcode::JumpIfNot
        | Opcode::JumpIfImm
        | Opcode::JumpIfNotImm
        | Opcode::JumpIfRelImm
        | Opcode::JumpIfNotRelImm => {
            out.extend(last.target().and_then(block_at));
            out.extend(block_at(last.next()));
        }
        Opcode::Ret | Opcode::Throw => {}
        _ => out.extend(block_at(last.next())),
    }
    out
}

/// Reverse postorder from a virtual root with an edge to every head (in order).
fn reverse_postorder(succ: &[Vec<usize>], heads: &[usize]) -> Vec<usize> {
    let n = succ.len();
    let mut seen = vec![false; n];
    let mut post = Vec::with_capacity(n);
    for &h in heads {
        if seen[h] {
            continue;
        }
        seen[h] = true;
        // Iterative DFS: (node, next successor index).
        let mut stack = vec![(h, 0usize)];
        while let Some((node, i)) = stack.pop() {
            if let Some(&s) = succ[node].get(i) {
                stack.push((node, i + 1));
                if !seen[s] {
                    seen[s] = true;
                    stack.push((s, 0));
                }
            } else {
                post.push(node);
            }
        }
    }
    post.reverse();
    post
}

/// Immediate dominators over the virtual root (Cooper, Harvey, Kennedy: "A Simple, Fast
/// Dominance Algorithm"); `None` = the root (a head, or a block two heads reach).
fn dominators(succ: &[Vec<usize>], heads: &BTreeSet<usize>, order: &[usize]) -> Vec<Option<usize>> {
    let n = succ.len();
    let root = n;
    let mut rpo = vec![usize::MAX; n + 1];
    rpo[root] = 0;
    for (i, &b) in order.iter().enumerate() {
        rpo[b] = i + 1;
    }
    let mut preds: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (b, ss) in succ.iter().enumerate() {
        for &s in ss {
            preds[s].push(b);
        }
    }
    for &h in heads {
        preds[h].push(root);
    }
    let mut idom = vec![usize::MAX; n + 1];
    idom[root] = root;
    let intersect = |idom: &[usize], mut a: usize, mut b: usize| {
        while a != b {
            while rpo[a] > rpo[b] {
                a = idom[a];
            }
            while rpo[b] > rpo[a] {
                b = idom[b];
            }
        }
        a
    };
    let mut changed = true;
    while changed {
        changed = false;
        for &b in order {
            let mut new = usize::MAX;
            for &p in &preds[b] {
                if idom[p] == usize::MAX {
                    continue;
                }
                new = if new == usize::MAX {
                    p
                } else {
                    intersect(&idom, p, new)
                };
            }
            if new != usize::MAX && idom[b] != new {
                idom[b] = new;
                changed = true;
            }
        }
    }
    (0..n)
        .map(|b| (idom[b] != root && idom[b] != usize::MAX).then_some(idom[b]))
        .collect()
}

/// The structure of `plan`'s blocks; `entries` are the blocks control enters from outside
/// (the POU start first, then the try handlers).
pub fn structure(plan: &PouPlan<'_>, entries: &[usize]) -> Structure {
    let n = plan.blocks.len();
    let succ: Vec<Vec<usize>> = (0..n).map(|b| successors(plan, b)).collect();
    let mut heads: BTreeSet<usize> = entries.iter().copied().collect();
    let (order, idom) = loop {
        let ordered_heads: Vec<usize> = entries
            .iter()
            .copied()
            .chain(heads.iter().copied())
            .collect();
        let order = reverse_postorder(&succ, &ordered_heads);
        let idom = dominators(&succ, &heads, &order);
        let position: Vec<usize> = {
            let mut p = vec![0; n];
            for (i, &b) in order.iter().enumerate() {
                p[b] = i;
            }
            p
        };
        let dominates = |a: usize, b: usize| {
            let mut x = Some(b);
            while let Some(node) = x {
                if node == a {
                    return true;
                }
                x = idom[node];
            }
            false
        };
        let mut more = BTreeSet::new();
        for &b in &order {
            // Reached from two regions: a region of its own.
            if idom[b].is_none() && !heads.contains(&b) {
                more.insert(b);
            }
            // A retreating edge to a block that does not dominate its source: irreducible.
            for &s in &succ[b] {
                if position[s] <= position[b] && !dominates(s, b) && !heads.contains(&s) {
                    more.insert(s);
                }
            }
        }
        if more.is_empty() {
            break (order, idom);
        }
        heads.extend(more);
    };
    let mut rpo = vec![0; n];
    for (i, &b) in order.iter().enumerate() {
        rpo[b] = i;
    }
    let mut children = vec![Vec::new(); n];
    for (b, dominator) in idom.iter().enumerate() {
        if let Some(d) = *dominator {
            children[d].push(b);
        }
    }
    let is_head: Vec<bool> = (0..n).map(|b| heads.contains(&b)).collect();
    let mut structure = Structure {
        succ,
        heads: entries
            .iter()
            .copied()
            .chain(heads.iter().copied().filter(|h| !entries.contains(h)))
            .collect(),
        is_head,
        idom,
        children,
        rpo,
        loop_header: vec![false; n],
        merge: vec![false; n],
    };
    let mut forward_preds = vec![0usize; n];
    for b in 0..n {
        for &s in &structure.succ[b].clone() {
            if structure.is_head[s] && !structure.dominates(s, b) {
                continue; // a branch to another region: dispatched
            }
            if structure.dominates(s, b) {
                structure.loop_header[s] = true;
            } else {
                forward_preds[s] += 1;
            }
        }
    }
    for (b, &preds) in forward_preds.iter().enumerate() {
        structure.merge[b] = !structure.is_head[b] && preds >= 2;
    }
    structure
}
