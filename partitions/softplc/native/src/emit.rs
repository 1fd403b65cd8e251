//! Writes the Rust source of one analysed POU ([`crate::analysis::PouPlan`]).
//!
//! Every opcode is handled in exactly one place, `Emitter::instruction`: one arm per
//! opcode that writes what the interpreter does (`plc_vm::vm`, `Machine::step`) over the cell
//! locals `s0, s1, ...` (cell `k` of the activation's operand stack). An opcode without an
//! arm is a translation error ([`Error::UnsupportedOpcode`]), never a guess.
//!
//! The shape of a POU's function (see the crate documentation for why):
//!
//! ```text
//! fn pou_N(cx, d, base, sp0, cells) -> Result<[u64; RET], Unwind> {
//!     let [mut s0, mut s1, ..] = cells;           // the activation's operand stack
//!     let tight = stack room < largest depth;      // then every block runs checked
//!     let mut fuel = cx.fuel();                     // instructions before the next event
//!     let mut entry = 0;                            // the region to enter (0: the start)
//!     let live = 'run: loop {
//!         let site = 'raise: {
//!             match entry {
//!                 0 => { /* region 0, structured: */
//!                     'l3: loop { ..                    // a loop header
//!                         // every block:
//!                         if tight || fuel < L { tick; insn; tick; insn; .. }   // checked
//!                         else { fuel -= L; insn; insn; .. }                   // fast
//!                         if s2 == 0 { continue 'l3 } else { break 'b7 } ..   // its branch
//!                 } }
//!                 1 => { /* region 1: a try handler */ .. }
//!                 _ => break 'raise STRAY,
//!             }
//!         };                                            // a trap: its site's entry in SITES_N
//!         match cx.catch(trap, pc, ..) { Deliver => { entry = its handler's region }, Outer => return, Fault => break 'run live }
//!     };
//!     cx.spill(sp0, &[s0, s1, ..], live);
//!     Err(Unwind::Fault)
//! }
//! ```
//!
//! The regions and their nesting come from [`crate::structure`]; a trap anywhere leaves
//! through `'raise` with the number of its site (trap, code offset, stack depth, and the
//! count of the block's instructions after it, given back to `fuel`).

use crate::Error;
use crate::analysis::{Insn, PouPlan};
use crate::promote::{Promotion, Sync};
use crate::structure::Structure;
use plc_vm::image::Image;
use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode, Trap};
use std::cell::RefCell;
use std::fmt::Write;

/// Writes the functions of POUs.
pub struct Emitter<'i> {
    pub image: &'i Image<'i>,
    /// Cell locals of every POU (its largest stack depth), by POU index.
    pub cells: Vec<u32>,
    pub out: String,
    /// The frame variables of the POU being written that live in locals `v<k>`.
    pub promotion: Promotion,
}

/// How a block runs.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Counted once at its start, no stack-room checks.
    Fast,
    /// The twin: counted (and the events handled) instruction by instruction, every push
    /// checked against the stack room.
    Checked,
}

/// The function name of POU `index`.
pub fn pou_fn(index: usize) -> String {
    format!("pou_{index}")
}

fn cell(i: u32) -> String {
    format!("s{i}")
}

fn trap_path(trap: Trap) -> String {
    let name = match trap {
        Trap::DivisionByZero => "DivisionByZero",
        Trap::IndexOutOfBounds => "IndexOutOfBounds",
        Trap::SubrangeViolation => "SubrangeViolation",
        Trap::Watchdog => "Watchdog",
        Trap::CallDepth => "CallDepth",
        Trap::StackOverflow => "StackOverflow",
        Trap::NumericError => "NumericError",
        Trap::InvalidAddress => "InvalidAddress",
        Trap::Deadline => "Deadline",
        Trap::InvalidReference => "InvalidReference",
    };
    format!("Trap::{name}")
}

/// The [`MemType`] operand byte at `at` of `insn`.
fn type_at(insn: &Insn<'_>, at: usize) -> Result<MemType, Error> {
    MemType::from_code(insn.imm[at])
        .ok_or_else(|| Error::internal(format!("bad type at {}", insn.pc)))
}

/// The bits a store of `ty` keeps.
fn width_mask(ty: MemType) -> u64 {
    match ty.width() {
        8 => u64::MAX,
        w => (1u64 << (8 * w)) - 1,
    }
}

/// The comparison opcode byte `byte` (of SEL_IF and the immediate jumps).
fn comparison(byte: u8, pc: u32) -> Result<Opcode, Error> {
    Opcode::from_u8(byte)
        .filter(|c| c.is_comparison())
        .ok_or_else(|| Error::internal(format!("bad comparison at {pc}")))
}

/// Binary operator `op` (`Opcode::is_binary`) on the cells `a` and `b` (expressions) as the
/// interpreter computes it: the condition under which it traps DIVISION_BY_ZERO (if it can)
/// and the result.
fn binary(op: Opcode, a: &str, b: &str) -> (Option<String>, String) {
    use Opcode::*;
    let int_zero = Some(format!("{b} == 0"));
    match op {
        Add => (None, format!("{a}.wrapping_add({b})")),
        Sub => (None, format!("{a}.wrapping_sub({b})")),
        Mul => (None, format!("{a}.wrapping_mul({b})")),
        DivS => (
            int_zero,
            format!("({a} as i64).wrapping_div({b} as i64) as u64"),
        ),
        DivU => (int_zero, format!("{a} / {b}")),
        ModS => (
            int_zero,
            format!("({a} as i64).wrapping_rem({b} as i64) as u64"),
        ),
        ModU => (int_zero, format!("{a} % {b}")),
        And => (None, format!("{a} & {b}")),
        Or => (None, format!("{a} | {b}")),
        Xor => (None, format!("{a} ^ {b}")),
        Shl => (None, format!("ops::shl({a}, {b})")),
        ShrU => (None, format!("ops::shr_u({a}, {b})")),
        ShrS => (None, format!("ops::shr_s({a}, {b})")),
        AddF32 | SubF32 | MulF32 | DivF32 | AddF64 | SubF64 | MulF64 | DivF64 => {
            let (of, result) = if matches!(op, AddF32 | SubF32 | MulF32 | DivF32) {
                ("f32_of", "real_result")
            } else {
                ("f64_of", "lreal_result")
            };
            let sym = match op {
                AddF32 | AddF64 => "+",
                SubF32 | SubF64 => "-",
                MulF32 | MulF64 => "*",
                _ => "/",
            };
            (
                matches!(op, DivF32 | DivF64).then(|| format!("{of}({b}) == 0.0")),
                format!("ops::{result}({of}({a}) {sym} {of}({b}))"),
            )
        }
        cmp => (None, format!("compare(Opcode::{cmp:?}, {a}, {b}) as u64")),
    }
}

fn mem_type_path(ty: MemType) -> String {
    format!("MemType::{ty:?}")
}

fn width(ty: MemType) -> usize {
    ty.width()
}

/// The interpreter's conversion of `width` little-endian bytes `bytes` (an expression of
/// type `[u8; width]`) to a cell.
fn cell_from(ty: MemType, bytes: &str) -> String {
    match ty {
        MemType::I8 => format!("{bytes}[0] as i8 as i64 as u64"),
        MemType::U8 => format!("{bytes}[0] as u64"),
        MemType::I16 => format!("i16::from_le_bytes({bytes}) as i64 as u64"),
        MemType::U16 => format!("u16::from_le_bytes({bytes}) as u64"),
        MemType::I32 => format!("i32::from_le_bytes({bytes}) as i64 as u64"),
        MemType::U32 | MemType::F32 => format!("u32::from_le_bytes({bytes}) as u64"),
        MemType::I64 | MemType::U64 | MemType::F64 => format!("u64::from_le_bytes({bytes})"),
    }
}

/// The memory type of a promoted variable's raw bytes (`width` bytes, zero-extended).
fn raw_type(width: u8) -> &'static str {
    match width {
        1 => "MemType::U8",
        2 => "MemType::U16",
        4 => "MemType::U32",
        _ => "MemType::U64",
    }
}

/// The cell an `LD_REL` of type `ty` loads from a promoted variable's raw bytes `raw`.
fn from_raw(ty: MemType, raw: &str) -> String {
    match ty {
        MemType::I8 => format!("({raw} as u8 as i8 as i64 as u64)"),
        MemType::I16 => format!("({raw} as u16 as i16 as i64 as u64)"),
        MemType::I32 => format!("({raw} as u32 as i32 as i64 as u64)"),
        _ => raw.to_string(),
    }
}

/// Writes every promoted variable back to data memory (inside the frame, which the
/// function checked on entry).
fn flush_code(promotion: &Promotion) -> String {
    let mut o = String::new();
    for (k, &(off, w)) in promotion.vars.iter().enumerate() {
        writeln!(
            o,
            "let _ = ops::store(d, base as usize + {off}, {}, v{k});",
            raw_type(w)
        )
        .ok();
    }
    o
}

/// Reads every promoted variable again from data memory.
fn reload_code(promotion: &Promotion) -> String {
    let mut o = String::new();
    for (k, &(off, w)) in promotion.vars.iter().enumerate() {
        writeln!(
            o,
            "if let Some(v) = ops::load(d, base as usize + {off}, {}) {{ v{k} = v; }}",
            raw_type(w)
        )
        .ok();
    }
    o
}

fn hex(v: u64) -> String {
    format!("0x{v:x}u64")
}

impl Emitter<'_> {
    /// Writes POU `plan`'s function, structured by `st` (the POU start its first entry), with
    /// the frame variables of `promotion` in locals, its frame base fixed to `base` if that is
    /// known.
    pub fn pou(
        &mut self,
        plan: &PouPlan<'_>,
        st: &Structure,
        promotion: &Promotion,
        base: Option<u32>,
    ) -> Result<(), Error> {
        let st = st.clone();
        self.promotion = promotion.clone();
        let m = plan.max_depth;
        let rets = plan.pou.ret_cells as u32;
        let name = pou_fn(plan.index);
        let cells: Vec<String> = (0..m).map(cell).collect();
        let sites = RefCell::new(Vec::new());
        // The regions first (they fill the site table).
        let outer = std::mem::take(&mut self.out);
        for (number, &head) in st.heads.iter().enumerate() {
            writeln!(self.out, "{number} => {{").ok();
            let mut context = Vec::new();
            self.tree(plan, &st, head, &mut context, &sites)?;
            writeln!(self.out, "}}").ok();
        }
        // Region numbers are produced here only; anything else is a bug here.
        let stray = Site {
            insn: &plan.insns[0],
            index: 0,
            refund: 0,
            mode: Mode::Checked,
            sites: &sites,
        };
        writeln!(
            self.out,
            "_ => {{ {} }}",
            stray.raise("Trap::InvalidAddress")
        )
        .ok();
        let regions = std::mem::replace(&mut self.out, outer);
        let o = &mut self.out;
        let table: Vec<String> = sites
            .borrow()
            .iter()
            .map(|(code, pc, depth, refund)| format!("({code}, {pc}, {depth}, {refund})"))
            .collect();
        writeln!(
            o,
            "/// Where the traps of `{name}` are raised: (trap code, 0 = the one in `dt`; code offset, u32::MAX = the one in `dpc`; stack depth; instructions of the block after it)."
        )
        .ok();
        writeln!(
            o,
            "static SITES_{}: [(u8, u32, u32, u32); {}] = [{}];",
            plan.index,
            table.len(),
            table.join(", ")
        )
        .ok();
        writeln!(
            o,
            "/// POU {} `{}`: code {}..{}, {} arg cell(s), {} result cell(s), frame {} bytes, {} stack cell(s), {} block(s), {} region(s).",
            plan.index,
            plan.pou.name.escape_debug(),
            plan.pou.code_start,
            plan.pou.code_start + plan.pou.code_len,
            plan.pou.arg_cells,
            rets,
            plan.pou.frame_size,
            m,
            plan.blocks.len(),
            st.heads.len()
        )
        .ok();
        writeln!(o, "#[inline]").ok();
        writeln!(
            o,
            "fn {name}(cx: &mut Cycle<'_>, d: &mut [u8; DATA], base: u32, sp0: u32, cells: [u64; {m}]) -> Result<[u64; {rets}], Unwind> {{"
        )
        .ok();
        writeln!(
            o,
            "let [{}] = cells;",
            cells
                .iter()
                .map(|c| format!("mut {c}"))
                .collect::<Vec<_>>()
                .join(", ")
        )
        .ok();
        if let Some(b) = base {
            writeln!(o, "// Every activation has this frame base (its tasks and calls).\nlet base: u32 = {b};").ok();
        }
        if !promotion.vars.is_empty() {
            writeln!(
                o,
                "// The frame is inside data memory (CALL and the verifier checked it); its promoted variables:\nif base as usize + {} > DATA {{ return Err(cx.refuse({})); }}",
                plan.pou.frame_size, plan.pou.code_start
            )
            .ok();
            for (k, &(off, w)) in promotion.vars.iter().enumerate() {
                writeln!(
                    o,
                    "let mut v{k}: u64 = ops::load(d, base as usize + {off}, {}).unwrap_or(0);",
                    raw_type(w)
                )
                .ok();
            }
        }
        writeln!(o, "let me = cx.call_depth();").ok();
        writeln!(o, "let room = cx.room(sp0);").ok();
        writeln!(o, "let tight = room < {m};").ok();
        writeln!(o, "let mut fuel = cx.fuel();").ok();
        writeln!(o, "let mut entry: u32 = 0;").ok();
        writeln!(o, "let (mut dt, mut dpc) = (Trap::InvalidAddress, 0u32);").ok();
        writeln!(o, "let live: u32 = 'run: loop {{").ok();
        writeln!(o, "let site: u32 = 'raise: {{").ok();
        writeln!(o, "match entry {{").ok();
        o.push_str(&regions);
        writeln!(o, "}}").ok(); // match
        writeln!(o, "}};").ok(); // 'raise
        // Unwinding.
        writeln!(
            o,
            "let (code, pc, depth, refund) = SITES_{}[site as usize];",
            plan.index
        )
        .ok();
        o.push_str(&flush_code(promotion));
        writeln!(o, "fuel += refund;\ncx.set_fuel(fuel);").ok();
        writeln!(
            o,
            "match cx.catch(ops::site_trap(code, dt), if pc == u32::MAX {{ dpc }} else {{ pc }}, me, sp0, depth) {{"
        )
        .ok();
        if plan.handlers.is_empty() {
            writeln!(o, "Catch::Deliver {{ depth, .. }} => break 'run depth,").ok();
        } else {
            writeln!(o, "Catch::Deliver {{ handler, depth, code }} => {{").ok();
            writeln!(o, "match depth {{").ok();
            for i in 0..m {
                writeln!(o, "{i} => s{i} = code,").ok();
            }
            writeln!(o, "_ => break 'run depth,").ok();
            writeln!(o, "}}").ok();
            writeln!(o, "entry = match handler {{").ok();
            for &h in &plan.handlers {
                writeln!(o, "{h} => {},", st.head_number(plan.block_of(h)?)).ok();
            }
            writeln!(o, "_ => break 'run depth,").ok();
            writeln!(o, "}};").ok();
            writeln!(o, "fuel = cx.fuel();").ok();
            writeln!(o, "}}").ok();
        }
        writeln!(o, "Catch::Outer => return Err(Unwind::Outer),").ok();
        writeln!(o, "Catch::Fault {{ depth }} => break 'run depth,").ok();
        writeln!(o, "}}").ok(); // match catch
        writeln!(o, "}};").ok(); // 'run
        writeln!(o, "cx.spill(sp0, &[{}], live);", cells.join(", ")).ok();
        writeln!(o, "Err(Unwind::Fault)").ok();
        writeln!(o, "}}\n").ok();
        Ok(())
    }

    /// Ramsey's `doTree`: block `x` and the blocks it dominates that are merge nodes.
    fn tree(
        &mut self,
        plan: &PouPlan<'_>,
        st: &Structure,
        x: usize,
        context: &mut Vec<Frame>,
        sites: &RefCell<Vec<SiteEntry>>,
    ) -> Result<(), Error> {
        let mut merges: Vec<usize> = st.children[x]
            .iter()
            .copied()
            .filter(|&c| st.merge[c])
            .collect();
        merges.sort_by_key(|&c| std::cmp::Reverse(st.rpo[c]));
        if st.loop_header[x] {
            writeln!(self.out, "'l{x}: loop {{").ok();
            context.push(Frame::Loop(x));
            self.within(plan, st, x, &merges, context, sites)?;
            context.pop();
            writeln!(self.out, "}}").ok();
        } else {
            self.within(plan, st, x, &merges, context, sites)?;
        }
        Ok(())
    }

    /// Ramsey's `nodeWithin`: block `x` inside labeled blocks that its merge children
    /// follow (`merges`, the latest in reverse postorder first, so the earliest is nearest).
    fn within(
        &mut self,
        plan: &PouPlan<'_>,
        st: &Structure,
        x: usize,
        merges: &[usize],
        context: &mut Vec<Frame>,
        sites: &RefCell<Vec<SiteEntry>>,
    ) -> Result<(), Error> {
        match merges.split_first() {
            Some((&y, rest)) => {
                writeln!(self.out, "'b{y}: {{").ok();
                context.push(Frame::Block(y));
                self.within(plan, st, x, rest, context, sites)?;
                context.pop();
                writeln!(self.out, "}}").ok();
                self.tree(plan, st, y, context, sites)
            }
            None => self.block(plan, st, x, context, sites),
        }
    }

    /// Ramsey's `doBranch`: control goes from block `from` to block `to`.
    fn branch(
        &mut self,
        plan: &PouPlan<'_>,
        st: &Structure,
        from: usize,
        to: usize,
        context: &mut Vec<Frame>,
        sites: &RefCell<Vec<SiteEntry>>,
    ) -> Result<(), Error> {
        if st.dominates(to, from) && context.contains(&Frame::Loop(to)) {
            writeln!(self.out, "continue 'l{to};").ok();
        } else if st.is_head[to] {
            writeln!(self.out, "entry = {};\ncontinue 'run;", st.head_number(to)).ok();
        } else if st.merge[to] {
            if !context.contains(&Frame::Block(to)) {
                return Err(Error::internal(format!(
                    "POU {}: merge block {to} outside its labeled block",
                    plan.pou.name
                )));
            }
            writeln!(self.out, "break 'b{to};").ok();
        } else {
            self.tree(plan, st, to, context, sites)?;
        }
        Ok(())
    }

    /// Block `b`: its instructions, checked or fast (see the module documentation), then its
    /// branch.
    fn block(
        &mut self,
        plan: &PouPlan<'_>,
        st: &Structure,
        b: usize,
        context: &mut Vec<Frame>,
        sites: &RefCell<Vec<SiteEntry>>,
    ) -> Result<(), Error> {
        let block = &plan.blocks[b];
        let len = block.instructions();
        let last = &plan.insns[block.last];
        let control = matches!(
            last.op,
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
        );
        let body = if control {
            block.first..block.last
        } else {
            block.first..block.last + 1
        };
        writeln!(self.out, "if tight || fuel < {len} {{").ok();
        for i in block.first..=block.last {
            let insn = &plan.insns[i];
            let at = Site {
                insn,
                index: i,
                refund: 0,
                mode: Mode::Checked,
                sites,
            };
            writeln!(
                self.out,
                "if fuel == 0 {{ match cx.event() {{ Ok(f) => fuel = f, Err(t) => {} }} }}\nfuel -= 1;",
                at.raise("t")
            )
            .ok();
            if body.contains(&i) {
                self.instruction(plan, &at)?;
            }
        }
        writeln!(self.out, "}} else {{\nfuel -= {len};").ok();
        for (k, i) in body.clone().enumerate() {
            let at = Site {
                insn: &plan.insns[i],
                index: i,
                refund: len - k as u32 - 1,
                mode: Mode::Fast,
                sites,
            };
            self.instruction(plan, &at)?;
        }
        writeln!(self.out, "}}").ok();
        if control {
            // The same in both modes: it is the block's last instruction.
            let at = Site {
                insn: last,
                index: block.last,
                refund: 0,
                mode: Mode::Fast,
                sites,
            };
            self.instruction(plan, &at)?;
        }
        // Its branch.
        let d = last.depth;
        let cell_of = |k: u32| cell(d - k);
        match last.op {
            Opcode::Ret | Opcode::Throw => {}
            Opcode::Jz
            | Opcode::Jnz
            | Opcode::JumpIf
            | Opcode::JumpIfNot
            | Opcode::JumpIfImm
            | Opcode::JumpIfNotImm
            | Opcode::JumpIfRelImm
            | Opcode::JumpIfNotRelImm => {
                let cond = match last.op {
                    op @ (Opcode::JumpIfRelImm | Opcode::JumpIfNotRelImm) => {
                        // The variable was loaded into `rv` by the instruction's translation.
                        let cmp = comparison(last.imm[0], last.pc)?;
                        let not = if op == Opcode::JumpIfNotRelImm {
                            "!"
                        } else {
                            ""
                        };
                        format!(
                            "{not}compare(Opcode::{cmp:?}, rv, {})",
                            hex(last.u32_at(6) as i32 as i64 as u64)
                        )
                    }
                    Opcode::Jz => format!("{} == 0", cell_of(1)),
                    Opcode::Jnz => format!("{} != 0", cell_of(1)),
                    op @ (Opcode::JumpIfImm | Opcode::JumpIfNotImm) => {
                        let cmp = Opcode::from_u8(last.imm[0])
                            .filter(|c| c.is_comparison())
                            .ok_or_else(|| {
                                Error::internal(format!("bad comparison at {}", last.pc))
                            })?;
                        let not = if op == Opcode::JumpIfNotImm { "!" } else { "" };
                        format!(
                            "{not}compare(Opcode::{cmp:?}, {}, {})",
                            cell_of(1),
                            hex(last.u32_at(1) as i32 as i64 as u64)
                        )
                    }
                    op => {
                        let cmp = Opcode::from_u8(last.imm[0])
                            .filter(|c| c.is_comparison())
                            .ok_or_else(|| {
                                Error::internal(format!("bad comparison at {}", last.pc))
                            })?;
                        let not = if op == Opcode::JumpIfNot { "!" } else { "" };
                        format!(
                            "{not}compare(Opcode::{cmp:?}, {}, {})",
                            cell_of(2),
                            cell_of(1)
                        )
                    }
                };
                let (taken, next) = (st.succ[b][0], st.succ[b][1]);
                writeln!(self.out, "if {cond} {{").ok();
                self.branch(plan, st, b, taken, context, sites)?;
                writeln!(self.out, "}} else {{").ok();
                self.branch(plan, st, b, next, context, sites)?;
                writeln!(self.out, "}}").ok();
            }
            _ => {
                let next = *st.succ[b].first().ok_or_else(|| {
                    Error::internal(format!("block {b} of {} has no successor", plan.pou.name))
                })?;
                self.branch(plan, st, b, next, context, sites)?;
            }
        }
        Ok(())
    }

    /// One instruction at `at`: the interpreter's `Machine::step` arm for its opcode.
    fn instruction(&mut self, plan: &PouPlan<'_>, at: &Site<'_, '_>) -> Result<(), Error> {
        use Opcode::*;
        let insn = at.insn;
        let d = insn.depth;
        let top = |k: u32| cell(d - k); // top(1) is the top cell
        // Promoted variables: written back before an instruction that may read them from
        // memory, read again after one that may write it (a CALL: in its result arms).
        let sync = self.promotion.sync(at.index);
        let flush = flush_code(&self.promotion);
        let reload = reload_code(&self.promotion);
        let after = if sync == Sync::FlushReload && !matches!(insn.op, Call | CallVirt) {
            reload.clone()
        } else {
            String::new()
        };
        let promoted = |off: u32, ty: MemType| self.promotion.var(off, ty.width() as u8);
        let o = &mut self.out;
        if sync != Sync::None {
            o.push_str(&flush);
        }
        let pc = insn.pc;
        match insn.op {
            Nop => {}
            PushI32 => {
                let v = insn.u32_at(0) as i32 as i64 as u64;
                at.push_check(o);
                writeln!(o, "{} = {};", cell(d), hex(v)).ok();
            }
            PushU32 => {
                at.push_check(o);
                writeln!(o, "{} = {};", cell(d), hex(insn.u32_at(0) as u64)).ok();
            }
            PushI64 => {
                at.push_check(o);
                writeln!(o, "{} = {};", cell(d), hex(insn.u64_at(0))).ok();
            }
            PushConst => {
                let index = insn.u16_at(0) as usize;
                let v = self
                    .image
                    .constant(index)
                    .ok_or_else(|| Error::internal(format!("constant {index} missing")))?;
                at.push_check(o);
                writeln!(o, "{} = {};", cell(d), hex(v)).ok();
            }
            Drop => {}
            Dup => {
                at.push_check(o);
                writeln!(o, "{} = {};", cell(d), top(1)).ok();
            }
            Swap => {
                writeln!(o, "core::mem::swap(&mut {}, &mut {});", top(2), top(1)).ok();
            }
            Over => {
                at.push_check(o);
                writeln!(o, "{} = {};", cell(d), top(2)).ok();
            }
            LdAbs | StAbs | LdRel | StRel | LdInd | StInd => {
                let ty = MemType::from_code(insn.imm[0])
                    .ok_or_else(|| Error::internal(format!("bad type at {pc}")))?;
                let off = insn.u32_at(1);
                let w = width(ty);
                match insn.op {
                    LdAbs => {
                        // The verifier proved `off + width <= data size`.
                        at.push_check(o);
                        let bytes = format!("ld::<DATA, {w}>(d, {off})");
                        writeln!(o, "{} = {};", cell(d), cell_from(ty, &bytes)).ok();
                    }
                    StAbs => {
                        writeln!(o, "st::<DATA, {w}>(d, {off}, {});", top(1)).ok();
                    }
                    LdRel if promoted(off, ty).is_some() => {
                        let k = promoted(off, ty).unwrap_or(0);
                        at.push_check(o);
                        writeln!(o, "{} = {};", cell(d), from_raw(ty, &format!("v{k}"))).ok();
                    }
                    StRel if promoted(off, ty).is_some() => {
                        let k = promoted(off, ty).unwrap_or(0);
                        let mask = if w == 8 {
                            u64::MAX
                        } else {
                            (1u64 << (8 * w)) - 1
                        };
                        writeln!(o, "v{k} = {} & {};", top(1), hex(mask)).ok();
                    }
                    LdRel => {
                        writeln!(
                            o,
                            "let Some(v) = ops::load(d, base as usize + {off}, {}) else {{ {} }};",
                            mem_type_path(ty),
                            at.raise("Trap::InvalidAddress")
                        )
                        .ok();
                        at.push_check(o);
                        writeln!(o, "{} = v;", cell(d)).ok();
                    }
                    StRel => {
                        writeln!(
                            o,
                            "if ops::store(d, base as usize + {off}, {}, {}).is_none() {{ {} }}",
                            mem_type_path(ty),
                            top(1),
                            at.raise("Trap::InvalidAddress")
                        )
                        .ok();
                    }
                    LdInd => {
                        writeln!(
                            o,
                            "let Some(v) = ops::load_at(d, {}, {off}, {}) else {{ {} }};",
                            top(1),
                            mem_type_path(ty),
                            at.raise("Trap::InvalidAddress")
                        )
                        .ok();
                        writeln!(o, "{} = v;", top(1)).ok();
                    }
                    _ => {
                        writeln!(
                            o,
                            "if ops::store_at(d, {}, {off}, {}, {}).is_none() {{ {} }}",
                            top(2),
                            mem_type_path(ty),
                            top(1),
                            at.raise("Trap::InvalidAddress")
                        )
                        .ok();
                    }
                }
            }
            LeaRel => {
                at.push_check(o);
                writeln!(o, "{} = base as u64 + {};", cell(d), insn.u32_at(0)).ok();
            }
            Copy => {
                writeln!(
                    o,
                    "if ops::copy(d, {}, {}, {}).is_none() {{ {} }}",
                    top(2),
                    top(1),
                    insn.u32_at(0),
                    at.raise("Trap::InvalidAddress")
                )
                .ok();
            }
            Now => {
                at.push_check(o);
                writeln!(o, "{} = cx.now();", cell(d)).ok();
            }
            op if op.is_binary() => {
                let (a, b) = (top(2), top(1));
                let (traps, r) = binary(op, &a, &b);
                if let Some(zero) = traps {
                    writeln!(o, "if {zero} {{ {} }}", at.raise("Trap::DivisionByZero")).ok();
                }
                writeln!(o, "{a} = {r};").ok();
            }
            Neg | AbsS | Not | NotBool => {
                let a = top(1);
                let r = match insn.op {
                    Neg => format!("({a} as i64).wrapping_neg() as u64"),
                    AbsS => format!("({a} as i64).wrapping_abs() as u64"),
                    Not => format!("!{a}"),
                    _ => format!("({a} == 0) as u64"),
                };
                writeln!(o, "{a} = {r};").ok();
            }
            Rol | Ror => {
                let (a, b) = (top(2), top(1));
                writeln!(
                    o,
                    "{a} = ops::rotate({a}, {b}, {}, {});",
                    insn.imm[0],
                    insn.op == Rol
                )
                .ok();
            }
            Sext | Zext => {
                let a = top(1);
                let f = if insn.op == Sext { "sext" } else { "zext" };
                writeln!(o, "{a} = ops::{f}({a}, {});", insn.imm[0]).ok();
            }
            Sel => {
                let (g, a, b) = (top(3), top(2), top(1));
                writeln!(o, "{g} = if {g} != 0 {{ {b} }} else {{ {a} }};").ok();
            }
            NegF32 => {
                let a = top(1);
                writeln!(o, "{a} = f32_cell(-f32_of({a}));").ok();
            }
            NegF64 => {
                let a = top(1);
                writeln!(o, "{a} = f64_cell(-f64_of({a}));").ok();
            }
            IToF32S | IToF32U | IToF64S | IToF64U | F32ToF64 | F64ToF32 => {
                let a = top(1);
                let r = match insn.op {
                    IToF32S => format!("f32_cell({a} as i64 as f32)"),
                    IToF32U => format!("f32_cell({a} as f32)"),
                    IToF64S => format!("f64_cell({a} as i64 as f64)"),
                    IToF64U => format!("f64_cell({a} as f64)"),
                    F32ToF64 => format!("f64_cell(f32_of({a}) as f64)"),
                    _ => format!("f32_cell(f64_of({a}) as f32)"),
                };
                writeln!(o, "{a} = {r};").ok();
            }
            F32ToInt | F64ToInt => {
                let a = top(1);
                let ty = MemType::from_code(insn.imm[0])
                    .ok_or_else(|| Error::internal(format!("bad type at {pc}")))?;
                let mode = RoundMode::from_code(insn.imm[1])
                    .ok_or_else(|| Error::internal(format!("bad rounding at {pc}")))?;
                let x = if insn.op == F32ToInt {
                    format!("f32_of({a}) as f64")
                } else {
                    format!("f64_of({a})")
                };
                writeln!(
                    o,
                    "let Some(v) = float_to_int({x}, {}, RoundMode::{mode:?}) else {{ {} }};\n{a} = v;",
                    mem_type_path(ty),
                    at.raise("Trap::NumericError")
                )
                .ok();
            }
            // Their branches are the block's, written by `Emitter::block`.
            Jmp | Jz | Jnz | JumpIf | JumpIfNot | JumpIfImm | JumpIfNotImm => {}
            JumpIfRelImm | JumpIfNotRelImm => {
                // Load the variable (its test is the block's branch).
                let ty = type_at(insn, 1)?;
                let off = insn.u32_at(2);
                match promoted(off, ty) {
                    Some(k) => writeln!(o, "let rv = {};", from_raw(ty, &format!("v{k}"))),
                    None => writeln!(
                        o,
                        "let Some(rv) = ops::load(d, base as usize + {off}, {}) else {{ {} }};",
                        mem_type_path(ty),
                        at.raise("Trap::InvalidAddress")
                    ),
                }
                .ok();
            }
            OpRelRel => {
                let op = Opcode::from_u8(insn.imm[0])
                    .filter(|op| op.is_binary())
                    .ok_or_else(|| Error::internal(format!("bad operator at {pc}")))?;
                at.push_check(o);
                for (name, at_type) in [("a", 1usize), ("b", 6)] {
                    let ty = type_at(insn, at_type)?;
                    let off = insn.u32_at(at_type + 1);
                    match promoted(off, ty) {
                        Some(k) => writeln!(o, "let {name} = {};", from_raw(ty, &format!("v{k}"))),
                        None => writeln!(
                            o,
                            "let Some({name}) = ops::load(d, base as usize + {off}, {}) else {{ {} }};",
                            mem_type_path(ty),
                            at.raise("Trap::InvalidAddress")
                        ),
                    }
                    .ok();
                }
                let (check, result) = binary(op, "a", "b");
                if let Some(condition) = check {
                    writeln!(
                        o,
                        "if {condition} {{ {} }}",
                        at.raise("Trap::DivisionByZero")
                    )
                    .ok();
                }
                writeln!(o, "{} = {result};", cell(d)).ok();
            }
            ElemRel | ElemAbs | LdElemRel | LdElemAbs | StElemRel | StElemAbs | ElemRelAt
            | ElemAbsAt | LdElemRelAt | LdElemAbsAt | StElemRelAt | StElemAbsAt => {
                // The element's address as ELEM_REL/ELEM_ABS computes it (INDEX's arithmetic);
                // the _AT forms read the index from a frame variable and push their result.
                let op = insn.op;
                let indexed_at = matches!(
                    op,
                    ElemRelAt | ElemAbsAt | LdElemRelAt | LdElemAbsAt | StElemRelAt | StElemAbsAt
                );
                let address_only = matches!(op, ElemRel | ElemAbs | ElemRelAt | ElemAbsAt);
                let store = matches!(op, StElemRel | StElemAbs | StElemRelAt | StElemAbsAt);
                let rel = matches!(
                    op,
                    ElemRel | LdElemRel | StElemRel | ElemRelAt | LdElemRelAt | StElemRelAt
                );
                let spec = usize::from(!address_only);
                let array = insn.u32_at(spec);
                let (lo, hi) = (insn.u64_at(spec + 4) as i64, insn.u64_at(spec + 12) as i64);
                let stride = insn.u32_at(spec + 20);
                let index = if indexed_at {
                    if !store {
                        at.push_check(o);
                    }
                    let ity = type_at(insn, spec + 24)?;
                    let ioff = insn.u32_at(spec + 25);
                    match promoted(ioff, ity) {
                        Some(k) => writeln!(o, "let ix = {};", from_raw(ity, &format!("v{k}"))),
                        None => writeln!(
                            o,
                            "let Some(ix) = ops::load(d, base as usize + {ioff}, {}) else {{ {} }};",
                            mem_type_path(ity),
                            at.raise("Trap::InvalidAddress")
                        ),
                    }
                    .ok();
                    "ix".to_string()
                } else if store {
                    top(2)
                } else {
                    top(1)
                };
                // Where a pushed result goes: the new cell, or the index's.
                let result = if indexed_at { cell(d) } else { top(1) };
                let start = if rel {
                    format!("base as u64 + {array}")
                } else {
                    format!("{array}u64")
                };
                writeln!(
                    o,
                    "if ({index} as i64) < {lo}i64 || ({index} as i64) > {hi}i64 {{ {} }}",
                    at.raise("Trap::IndexOutOfBounds")
                )
                .ok();
                writeln!(
                    o,
                    "let a = ({start}).wrapping_add((({index} as i64).wrapping_sub({lo}i64) as u64).wrapping_mul({stride}));"
                )
                .ok();
                if address_only {
                    writeln!(o, "{result} = a;").ok();
                } else if store {
                    writeln!(
                        o,
                        "if ops::store_at(d, a, 0, {}, {}).is_none() {{ {} }}",
                        mem_type_path(type_at(insn, 0)?),
                        top(1),
                        at.raise("Trap::InvalidAddress")
                    )
                    .ok();
                } else {
                    writeln!(
                        o,
                        "let Some(v) = ops::load_at(d, a, 0, {}) else {{ {} }};\n{result} = v;",
                        mem_type_path(type_at(insn, 0)?),
                        at.raise("Trap::InvalidAddress")
                    )
                    .ok();
                }
            }
            IncRel if promoted(insn.u32_at(1), type_at(insn, 0)?).is_some() => {
                let ty = type_at(insn, 0)?;
                let k = promoted(insn.u32_at(1), ty).unwrap_or(0);
                let imm = insn.u32_at(5) as i32 as i64 as u64;
                writeln!(
                    o,
                    "v{k} = {}.wrapping_add({}) & {};",
                    from_raw(ty, &format!("v{k}")),
                    hex(imm),
                    hex(width_mask(ty))
                )
                .ok();
            }
            IncRel | IncAbs => {
                let ty = MemType::from_code(insn.imm[0])
                    .ok_or_else(|| Error::internal(format!("bad type at {pc}")))?;
                let off = insn.u32_at(1);
                let imm = insn.u32_at(5) as i32 as i64 as u64;
                let at_expr = if insn.op == IncRel {
                    format!("base as usize + {off}")
                } else {
                    format!("{off}usize")
                };
                writeln!(
                    o,
                    "let Some(v) = ops::load(d, {at_expr}, {}) else {{ {} }};",
                    mem_type_path(ty),
                    at.raise("Trap::InvalidAddress")
                )
                .ok();
                writeln!(
                    o,
                    "if ops::store(d, {at_expr}, {}, v.wrapping_add({})).is_none() {{ {} }}",
                    mem_type_path(ty),
                    hex(imm),
                    at.raise("Trap::InvalidAddress")
                )
                .ok();
            }
            SelIf => {
                let cmp = comparison(insn.imm[0], pc)?;
                let (a, b) = (top(2), top(1));
                writeln!(
                    o,
                    "{a} = if compare(Opcode::{cmp:?}, {a}, {b}) {{ {b} }} else {{ {a} }};"
                )
                .ok();
            }
            OpImm | OpRel | OpAbs => {
                let op = Opcode::from_u8(insn.imm[0])
                    .filter(|op| op.is_binary())
                    .ok_or_else(|| Error::internal(format!("bad operator at {pc}")))?;
                let a = top(1);
                let b = match insn.op {
                    OpImm => hex(insn.u32_at(1) as i32 as i64 as u64),
                    OpRel if promoted(insn.u32_at(2), type_at(insn, 1)?).is_some() => {
                        let ty = type_at(insn, 1)?;
                        let k = promoted(insn.u32_at(2), ty).unwrap_or(0);
                        from_raw(ty, &format!("v{k}"))
                    }
                    _ => {
                        let ty = MemType::from_code(insn.imm[1])
                            .ok_or_else(|| Error::internal(format!("bad type at {pc}")))?;
                        let off = insn.u32_at(2);
                        let at_expr = if insn.op == OpRel {
                            format!("base as usize + {off}")
                        } else {
                            format!("{off}usize")
                        };
                        writeln!(
                            o,
                            "let Some(b) = ops::load(d, {at_expr}, {}) else {{ {} }};",
                            mem_type_path(ty),
                            at.raise("Trap::InvalidAddress")
                        )
                        .ok();
                        "b".to_string()
                    }
                };
                let (check, result) = binary(op, &a, &b);
                if let Some(condition) = check {
                    writeln!(
                        o,
                        "if {condition} {{ {} }}",
                        at.raise("Trap::DivisionByZero")
                    )
                    .ok();
                }
                writeln!(o, "{a} = {result};").ok();
            }
            Call => {
                let index = insn.u16_at(0) as usize;
                let callee = self
                    .image
                    .pou(index)
                    .ok_or_else(|| Error::internal(format!("CALL of unknown POU at {pc}")))?;
                let args = callee.arg_cells as u32;
                let rets = callee.ret_cells as u32;
                let region = d - 1 - args;
                let data = self.image.data_size() as u64;
                let frame = callee.frame_size as u64;
                let frame_outside = match data.checked_sub(frame) {
                    Some(limit) => format!("{} > {limit}", top(1)),
                    None => "true".to_string(),
                };
                let callee_cells = self.cells[index];
                let mut init: Vec<String> = (region..region + args).map(cell).collect();
                init.resize(callee_cells as usize, "0".to_string());
                let results: Vec<String> = (0..rets).map(|i| format!("r{i}")).collect();
                writeln!(
                    o,
                    "if !cx.can_enter() {{ {} }}",
                    at.raise("Trap::CallDepth")
                )
                .ok();
                writeln!(
                    o,
                    "if {frame_outside} {{ {} }}",
                    at.raise("Trap::InvalidAddress")
                )
                .ok();
                writeln!(o, "cx.enter();\ncx.set_fuel(fuel);").ok();
                writeln!(
                    o,
                    "let r = {}(cx, d, {} as u32, sp0 + {region}, [{}]);\nfuel = cx.fuel();\nmatch r {{",
                    pou_fn(index),
                    top(1),
                    init.join(", ")
                )
                .ok();
                writeln!(
                    o,
                    "Ok([{}]) => {{ cx.leave();\n{reload}",
                    results.join(", ")
                )
                .ok();
                for i in 0..rets {
                    writeln!(o, "{} = r{i};", cell(region + i)).ok();
                }
                writeln!(o, "}}").ok();
                writeln!(
                    o,
                    "Err(Unwind::Outer) => {{ {reload}cx.resume_at(me); (dt, dpc) = cx.raised(); {} }}",
                    at.raise_from_callee()
                )
                .ok();
                writeln!(o, "Err(Unwind::Fault) => break 'run {region},").ok();
                writeln!(o, "}}").ok();
            }
            RefMake | RefCheck => {
                let a = top(1);
                let f = if insn.op == RefMake {
                    "ref_make"
                } else {
                    "ref_check"
                };
                writeln!(
                    o,
                    "let Some(v) = cx.{f}({a}, {}) else {{ {} }};\n{a} = v;",
                    insn.u32_at(0),
                    at.raise("Trap::InvalidReference")
                )
                .ok();
            }
            RefAdd => {
                let (r, n) = (top(2), top(1));
                writeln!(
                    o,
                    "{r} = ({r} & !0xFFFF_FFFFu64) | ({r} as u32).wrapping_add({n} as u32) as u64;"
                )
                .ok();
            }
            ChkNull => {
                writeln!(
                    o,
                    "if {} == 0 {{ {} }}",
                    top(1),
                    at.raise("Trap::InvalidReference")
                )
                .ok();
            }
            VirtFrame => {
                let a = top(1);
                writeln!(
                    o,
                    "let Some(m) = cx.method(d, {a}, {}) else {{ {} }};\n{a} = m.frame as u64;",
                    insn.u16_at(0),
                    at.raise("Trap::InvalidReference")
                )
                .ok();
            }
            CallVirt => {
                // The class of the instance decides the POU: one arm per method any class
                // runs for this slot; each as CALL does (no argument or result cells).
                let slot = insn.u16_at(0);
                let inst = top(1);
                let region = d - 1;
                let mut targets: Vec<usize> = (0..self.image.dispatch_count())
                    .filter_map(|i| self.image.dispatch(i))
                    .filter(|m| m.slot == slot)
                    .map(|m| m.pou as usize)
                    .collect();
                targets.sort_unstable();
                targets.dedup();
                writeln!(
                    o,
                    "let Some(m) = cx.method(d, {inst}, {slot}) else {{ {} }};",
                    at.raise("Trap::InvalidReference")
                )
                .ok();
                writeln!(
                    o,
                    "if !cx.can_enter() {{ {} }}",
                    at.raise("Trap::CallDepth")
                )
                .ok();
                writeln!(o, "match m.pou {{").ok();
                let data = self.image.data_size() as u64;
                for pou in targets {
                    let callee = self.image.pou(pou).ok_or_else(|| {
                        Error::internal(format!("dispatch to unknown POU {pou} at {pc}"))
                    })?;
                    if callee.arg_cells != 0 || callee.ret_cells != 0 {
                        return Err(Error::internal(format!(
                            "dispatch target {} has argument or result cells",
                            callee.name
                        )));
                    }
                    let frame_outside = match data.checked_sub(callee.frame_size as u64) {
                        Some(limit) => format!("{inst} > {limit}"),
                        None => "true".to_string(),
                    };
                    writeln!(o, "{pou} => {{").ok();
                    writeln!(
                        o,
                        "if {frame_outside} {{ {} }}",
                        at.raise("Trap::InvalidAddress")
                    )
                    .ok();
                    writeln!(o, "cx.enter();\ncx.set_fuel(fuel);").ok();
                    writeln!(
                        o,
                        "let r = {}(cx, d, {inst} as u32, sp0 + {region}, [0; {}]);\nfuel = cx.fuel();\nmatch r {{",
                        pou_fn(pou),
                        self.cells[pou]
                    )
                    .ok();
                    writeln!(o, "Ok([]) => {{ cx.leave();\n{reload}}}").ok();
                    writeln!(
                        o,
                        "Err(Unwind::Outer) => {{ {reload}cx.resume_at(me); (dt, dpc) = cx.raised(); {} }}",
                        at.raise_from_callee()
                    )
                    .ok();
                    writeln!(o, "Err(Unwind::Fault) => break 'run {region},").ok();
                    writeln!(o, "}}\n}}").ok();
                }
                writeln!(o, "_ => {{ {} }}", at.raise("Trap::InvalidReference")).ok();
                writeln!(o, "}}").ok();
            }
            Ret => {
                let rets = plan.pou.ret_cells as u32;
                let results: Vec<String> = (d - rets..d).map(cell).collect();
                writeln!(
                    o,
                    "{flush}cx.set_fuel(fuel);\ncx.ret({pc});\nreturn Ok([{}]);",
                    results.join(", ")
                )
                .ok();
            }
            CallBuiltin => {
                let id = insn.u16_at(0);
                let builtin = known_builtin(id).ok_or(Error::UnsupportedBuiltin { pc, id })?;
                let args = builtin.args() as u32;
                let results = builtin.results() as u32;
                let argv: Vec<String> = (d - args..d).map(cell).collect();
                writeln!(
                    o,
                    "let r = match builtins::call(Builtin::{builtin:?}, &[{}], d) {{ Ok(r) => r, Err(t) => {{ {} }} }};",
                    argv.join(", "),
                    at.raise("t")
                )
                .ok();
                if results == 1 {
                    at.push_check(o);
                    writeln!(o, "{} = r.unwrap_or(0);", cell(d - args)).ok();
                } else {
                    writeln!(o, "let _ = r;").ok();
                }
            }
            ChkIndex | ChkRangeS | ChkRangeU => {
                let (lo, hi) = (insn.u64_at(0), insn.u64_at(8));
                let v = top(1);
                let (ok, trap) = match insn.op {
                    ChkRangeU => (
                        format!("{} <= {v} && {v} <= {}", hex(lo), hex(hi)),
                        "Trap::SubrangeViolation",
                    ),
                    op => (
                        format!(
                            "{}i64 <= {v} as i64 && {v} as i64 <= {}i64",
                            lo as i64, hi as i64
                        ),
                        if op == ChkIndex {
                            "Trap::IndexOutOfBounds"
                        } else {
                            "Trap::SubrangeViolation"
                        },
                    ),
                };
                writeln!(o, "if !({ok}) {{ {} }}", at.raise(trap)).ok();
            }
            AddImm => {
                let a = top(1);
                let imm = insn.u32_at(0) as i32 as i64 as u64;
                writeln!(o, "{a} = {a}.wrapping_add({});", hex(imm)).ok();
            }
            Index => {
                let (lo, hi) = (insn.u64_at(0) as i64, insn.u64_at(8) as i64);
                let stride = insn.u32_at(16);
                let (b, i) = (top(2), top(1));
                writeln!(
                    o,
                    "if ({i} as i64) < {lo}i64 || ({i} as i64) > {hi}i64 {{ {} }}",
                    at.raise("Trap::IndexOutOfBounds")
                )
                .ok();
                writeln!(
                    o,
                    "{b} = {b}.wrapping_add((({i} as i64).wrapping_sub({lo}i64) as u64).wrapping_mul({stride}));"
                )
                .ok();
            }
            TryBegin => {
                writeln!(
                    o,
                    "if !cx.try_begin({}, sp0 + {d}, base) {{ {} }}",
                    insn.u32_at(0),
                    at.raise("Trap::StackOverflow")
                )
                .ok();
            }
            TryEnd => {
                writeln!(o, "cx.try_end();").ok();
            }
            Throw => {
                let trap = Trap::from_u64(insn.imm[0] as u64)
                    .ok_or_else(|| Error::internal(format!("bad trap code at {pc}")))?;
                writeln!(o, "{}", at.raise(&trap_path(trap))).ok();
            }
            Rethrow => {
                let c = top(1);
                writeln!(
                    o,
                    "if {c} != 0 {{ let t = ops::rethrown({c}); {} }}",
                    at.raise("t")
                )
                .ok();
            }
            #[allow(unreachable_patterns)] // opcodes added to the ISA after this translator
            other => {
                return Err(Error::UnsupportedOpcode {
                    pc,
                    opcode: other as u8,
                    mnemonic: other.mnemonic(),
                });
            }
        }
        o.push_str(&after);
        Ok(())
    }
}

/// The builtins whose semantics `plc_vm::builtins::call` gives completely (arguments in,
/// at most one result out, data memory): the translator calls that very function. A
/// builtin added later must be listed here once it is known to fit.
fn known_builtin(id: u16) -> Option<Builtin> {
    use Builtin::*;
    let b = Builtin::from_u16(id)?;
    matches!(
        b,
        SqrtF64
            | LnF64
            | LogF64
            | ExpF64
            | SinF64
            | CosF64
            | TanF64
            | AsinF64
            | AcosF64
            | AtanF64
            | ExptF64
            | AbsF64
            | SqrtF32
            | LnF32
            | LogF32
            | ExpF32
            | SinF32
            | CosF32
            | TanF32
            | AsinF32
            | AcosF32
            | AtanF32
            | ExptF32
            | AbsF32
            | StrLen
            | StrAssign
            | StrConcat
            | StrLeft
            | StrRight
            | StrMid
            | StrInsert
            | StrDelete
            | StrReplace
            | StrFind
            | StrCompare
            | StrFromI64
            | StrFromU64
            | StrFromF32
            | StrFromF64
            | StrFromBool
            | StrFromTime
            | StrToI64
            | StrToF64
            | Atan2F64
            | Atan2F32
            | DateFromParts
            | DateSplit
            | DateOf
            | TodOf
            | DayOfWeek
            | StrFromDateTime
            | StrToDateTime
            | TodFromParts
            | WStrLen
            | WStrAssign
            | WStrConcat
            | WStrLeft
            | WStrRight
            | WStrMid
            | WStrInsert
            | WStrDelete
            | WStrReplace
            | WStrFind
            | WStrCompare
            | WStrFromStr
            | StrFromWStr
            | StrSync
    )
    .then_some(b)
}

/// What encloses the code being written: a labeled loop (`'l<block>`, its header) or a
/// labeled block (`'b<block>`, the merge block that follows it).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Frame {
    Loop(usize),
    Block(usize),
}

/// A place that raises a trap: `(trap code, 0 = dynamic; code offset, u32::MAX = dynamic;
/// stack depth; fuel to give back)`, an entry of a POU's site table.
type SiteEntry = (u8, u32, u32, u32);

/// Where an instruction stands in its block.
struct Site<'p, 'a> {
    insn: &'p Insn<'a>,
    /// Its index in `PouPlan::insns`.
    index: usize,
    /// Instructions of the block after this one (their count is given back on a trap).
    refund: u32,
    mode: Mode,
    sites: &'p RefCell<Vec<SiteEntry>>,
}

impl Site<'_, '_> {
    fn site(&self, code: u8, pc: u32) -> String {
        let refund = match self.mode {
            Mode::Fast => self.refund,
            Mode::Checked => 0,
        };
        let mut sites = self.sites.borrow_mut();
        sites.push((code, pc, self.insn.depth, refund));
        format!("break 'raise {};", sites.len() - 1)
    }

    /// Code that raises `trap` at this instruction: `Trap::<Name>`, or the name of a local
    /// of type `Trap`.
    fn raise(&self, trap: &str) -> String {
        match Trap::ALL.iter().find(|t| trap_path(**t) == trap) {
            Some(t) => self.site(t.code(), self.insn.pc),
            None => format!("{{ dt = {trap}; {} }}", self.site(0, self.insn.pc)),
        }
    }

    /// Code that raises the trap a callee passed on (in `dt`, at code offset `dpc`).
    fn raise_from_callee(&self) -> String {
        self.site(0, u32::MAX)
    }

    /// In a checked block: STACK_OVERFLOW when the instruction's push does not fit (written
    /// right before the push, after the instruction's other checks, as the interpreter
    /// pushes last).
    fn push_check(&self, o: &mut String) {
        let after = self.insn.depth_after();
        if self.mode == Mode::Checked && after > self.insn.depth {
            writeln!(
                o,
                "if room < {after} {{ {} }}",
                self.raise("Trap::StackOverflow")
            )
            .ok();
        }
    }
}
