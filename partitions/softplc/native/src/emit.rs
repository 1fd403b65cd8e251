//! Writes the Rust source of one analysed POU ([`crate::analysis::PouPlan`]).
//!
//! Every opcode is handled in exactly one place, [`Emitter::instruction`]: one arm per
//! opcode that writes what the interpreter does (`plc_vm::vm`, `Machine::step`) over the cell
//! locals `s0, s1, ...` (cell `k` of the activation's operand stack). An opcode without an
//! arm is a translation error ([`Error::UnsupportedOpcode`]), never a guess.
//!
//! The shape of a POU's function (see the crate documentation for why):
//!
//! ```text
//! fn pou_N(cx, d, base, sp0, cells) -> Result<[u64; RET], Unwind> {
//!     let [mut s0, mut s1, ..] = cells;            // the activation's operand stack
//!     let tw = if stack room < max depth { NB } else { 0 };   // checked twins only
//!     let mut block = tw;
//!     let live = 'fault: loop {
//!         let (trap, pc, depth) = 'raise: loop {
//!             match block {
//!                 0 => { if cx.fuel() < L { block = NB; continue } cx.burn(L); ..; block = 3; continue }
//!                 ..                                   // fast blocks 0..NB
//!                 NB => { cx.tick()?; insn; cx.tick()?; insn; ..; block = 3 + tw; continue }
//!                 ..                                   // checked twins NB..2*NB
//!             }
//!         };
//!         match cx.catch(trap, pc, me, sp0, depth) { Deliver => handler block, Outer => return, Fault => break }
//!     };
//!     cx.spill(sp0, &[s0, s1, ..], live);
//!     Err(Unwind::Fault)
//! }
//! ```

use crate::Error;
use crate::analysis::{Block, Insn, PouPlan};
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
    };
    format!("Trap::{name}")
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

fn hex(v: u64) -> String {
    format!("0x{v:x}u64")
}

impl Emitter<'_> {
    /// Writes POU `plan`'s function.
    pub fn pou(&mut self, plan: &PouPlan<'_>) -> Result<(), Error> {
        let m = plan.max_depth;
        let nb = plan.blocks.len() as u32;
        let rets = plan.pou.ret_cells as u32;
        let name = pou_fn(plan.index);
        let cells: Vec<String> = (0..m).map(cell).collect();
        let sites = RefCell::new(Vec::new());
        // The body first (it fills the site table).
        let body = std::mem::take(&mut self.out);
        for mode in [Mode::Fast, Mode::Checked] {
            for (b, block) in plan.blocks.iter().enumerate() {
                let id = b as u32 + if mode == Mode::Checked { nb } else { 0 };
                writeln!(self.out, "{id} => {{").ok();
                self.block(plan, b, block, mode, &sites)?;
                writeln!(self.out, "}}").ok();
            }
        }
        // Block numbers are produced by this function only; anything else is a bug here.
        let stray = Site {
            insn: &plan.insns[0],
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
        let arms = std::mem::replace(&mut self.out, body);
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
            "/// POU {} `{}`: code {}..{}, {} arg cell(s), {} result cell(s), frame {} bytes, {} stack cell(s), {} block(s).",
            plan.index,
            plan.pou.name.escape_debug(),
            plan.pou.code_start,
            plan.pou.code_start + plan.pou.code_len,
            plan.pou.arg_cells,
            rets,
            plan.pou.frame_size,
            m,
            nb
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
        writeln!(o, "let me = cx.call_depth();").ok();
        writeln!(o, "let room = cx.room(sp0);").ok();
        if m > 0 {
            writeln!(o, "let tw: u32 = if room < {m} {{ {nb} }} else {{ 0 }};").ok();
        } else {
            writeln!(o, "let tw: u32 = 0;").ok();
        }
        writeln!(o, "let mut block: u32 = tw;").ok();
        writeln!(o, "let (mut dt, mut dpc) = (Trap::InvalidAddress, 0u32);").ok();
        writeln!(o, "let live: u32 = 'fault: loop {{").ok();
        writeln!(o, "let site: u32 = 'raise: loop {{").ok();
        writeln!(o, "match block {{").ok();
        o.push_str(&arms);
        writeln!(o, "}}").ok(); // match
        writeln!(o, "}};").ok(); // 'raise
        // Unwinding.
        writeln!(
            o,
            "let (code, pc, depth, refund) = SITES_{}[site as usize];",
            plan.index
        )
        .ok();
        writeln!(o, "cx.refund(refund);").ok();
        writeln!(
            o,
            "match cx.catch(ops::site_trap(code, dt), if pc == u32::MAX {{ dpc }} else {{ pc }}, me, sp0, depth) {{"
        )
        .ok();
        if plan.handlers.is_empty() {
            writeln!(o, "Catch::Deliver {{ depth, .. }} => break 'fault depth,").ok();
        } else {
            writeln!(o, "Catch::Deliver {{ handler, depth, code }} => {{").ok();
            writeln!(o, "match depth {{").ok();
            for i in 0..m {
                writeln!(o, "{i} => s{i} = code,").ok();
            }
            writeln!(o, "_ => break 'fault depth,").ok();
            writeln!(o, "}}").ok();
            writeln!(o, "block = tw + match handler {{").ok();
            for &h in &plan.handlers {
                writeln!(o, "{h} => {},", plan.block_of(h)?).ok();
            }
            writeln!(o, "_ => break 'fault depth,").ok();
            writeln!(o, "}};").ok();
            writeln!(o, "}}").ok();
        }
        writeln!(o, "Catch::Outer => return Err(Unwind::Outer),").ok();
        writeln!(o, "Catch::Fault {{ depth }} => break 'fault depth,").ok();
        writeln!(o, "}}").ok(); // match catch
        writeln!(o, "}};").ok(); // 'fault
        writeln!(o, "cx.spill(sp0, &[{}], live);", cells.join(", ")).ok();
        writeln!(o, "Err(Unwind::Fault)").ok();
        writeln!(o, "}}\n").ok();
        Ok(())
    }

    fn block(
        &mut self,
        plan: &PouPlan<'_>,
        b: usize,
        block: &Block,
        mode: Mode,
        sites: &RefCell<Vec<SiteEntry>>,
    ) -> Result<(), Error> {
        let len = block.instructions();
        let nb = plan.blocks.len();
        if mode == Mode::Fast {
            writeln!(
                self.out,
                "if cx.fuel() < {len} {{ block = {}; continue; }}\ncx.burn({len});",
                b + nb
            )
            .ok();
        }
        for k in 0..len as usize {
            let insn = &plan.insns[block.first + k];
            let at = Site {
                insn,
                refund: len - k as u32 - 1,
                mode,
                sites,
            };
            if mode == Mode::Checked {
                writeln!(
                    self.out,
                    "if let Err(t) = cx.tick() {{ {} }}",
                    at.raise("t")
                )
                .ok();
            }
            self.instruction(plan, &at)?;
        }
        // Fall through into the next block.
        let last = &plan.insns[block.last];
        if last.falls_through() && !last.ends_block() {
            let next = plan.block_of(last.next())?;
            writeln!(self.out, "block = {}; continue;", successor(next, mode)).ok();
        }
        Ok(())
    }

    /// One instruction at `at`: the interpreter's `Machine::step` arm for its opcode.
    fn instruction(&mut self, plan: &PouPlan<'_>, at: &Site<'_, '_>) -> Result<(), Error> {
        use Opcode::*;
        let insn = at.insn;
        let d = insn.depth;
        let top = |k: u32| cell(d - k); // top(1) is the top cell
        let o = &mut self.out;
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
            Add | Sub | Mul | And | Or | Xor | Shl | ShrU | ShrS => {
                let (a, b) = (top(2), top(1));
                let r = match insn.op {
                    Add => format!("{a}.wrapping_add({b})"),
                    Sub => format!("{a}.wrapping_sub({b})"),
                    Mul => format!("{a}.wrapping_mul({b})"),
                    And => format!("{a} & {b}"),
                    Or => format!("{a} | {b}"),
                    Xor => format!("{a} ^ {b}"),
                    Shl => format!("ops::shl({a}, {b})"),
                    ShrU => format!("ops::shr_u({a}, {b})"),
                    _ => format!("ops::shr_s({a}, {b})"),
                };
                writeln!(o, "{a} = {r};").ok();
            }
            Eq | Ne | LtS | LeS | GtS | GeS | LtU | LeU | GtU | GeU | EqF32 | NeF32 | LtF32
            | LeF32 | GtF32 | GeF32 | EqF64 | NeF64 | LtF64 | LeF64 | GtF64 | GeF64 => {
                let (a, b) = (top(2), top(1));
                writeln!(o, "{a} = compare(Opcode::{:?}, {a}, {b}) as u64;", insn.op).ok();
            }
            DivS | DivU | ModS | ModU => {
                let (a, b) = (top(2), top(1));
                writeln!(o, "if {b} == 0 {{ {} }}", at.raise("Trap::DivisionByZero")).ok();
                let r = match insn.op {
                    DivS => format!("({a} as i64).wrapping_div({b} as i64) as u64"),
                    DivU => format!("{a} / {b}"),
                    ModS => format!("({a} as i64).wrapping_rem({b} as i64) as u64"),
                    _ => format!("{a} % {b}"),
                };
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
            AddF32 | SubF32 | MulF32 | DivF32 => {
                let (a, b) = (top(2), top(1));
                if insn.op == DivF32 {
                    writeln!(
                        o,
                        "if f32_of({b}) == 0.0 {{ {} }}",
                        at.raise("Trap::DivisionByZero")
                    )
                    .ok();
                }
                let sym = match insn.op {
                    AddF32 => "+",
                    SubF32 => "-",
                    MulF32 => "*",
                    _ => "/",
                };
                writeln!(o, "{a} = f32_cell(f32_of({a}) {sym} f32_of({b}));").ok();
            }
            AddF64 | SubF64 | MulF64 | DivF64 => {
                let (a, b) = (top(2), top(1));
                if insn.op == DivF64 {
                    writeln!(
                        o,
                        "if f64_of({b}) == 0.0 {{ {} }}",
                        at.raise("Trap::DivisionByZero")
                    )
                    .ok();
                }
                let sym = match insn.op {
                    AddF64 => "+",
                    SubF64 => "-",
                    MulF64 => "*",
                    _ => "/",
                };
                writeln!(o, "{a} = f64_cell(f64_of({a}) {sym} f64_of({b}));").ok();
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
            Jmp => {
                let t = plan.block_of(insn.u32_at(0))?;
                writeln!(o, "block = {}; continue;", successor(t, at.mode)).ok();
            }
            Jz | Jnz => {
                let t = plan.block_of(insn.u32_at(0))?;
                let f = plan.block_of(insn.next())?;
                let cmp = if insn.op == Jz { "==" } else { "!=" };
                writeln!(
                    o,
                    "block = if {} {cmp} 0 {{ {} }} else {{ {} }}; continue;",
                    top(1),
                    successor(t, at.mode),
                    successor(f, at.mode)
                )
                .ok();
            }
            JumpIf | JumpIfNot => {
                let cmp = Opcode::from_u8(insn.imm[0])
                    .filter(|c| c.is_comparison())
                    .ok_or_else(|| Error::internal(format!("bad comparison at {pc}")))?;
                let t = plan.block_of(insn.u32_at(1))?;
                let f = plan.block_of(insn.next())?;
                let not = if insn.op == JumpIfNot { "!" } else { "" };
                writeln!(
                    o,
                    "block = if {not}compare(Opcode::{cmp:?}, {}, {}) {{ {} }} else {{ {} }}; continue;",
                    top(2),
                    top(1),
                    successor(t, at.mode),
                    successor(f, at.mode)
                )
                .ok();
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
                writeln!(o, "cx.enter();").ok();
                writeln!(
                    o,
                    "match {}(cx, d, {} as u32, sp0 + {region}, [{}]) {{",
                    pou_fn(index),
                    top(1),
                    init.join(", ")
                )
                .ok();
                writeln!(o, "Ok([{}]) => {{ cx.leave();", results.join(", ")).ok();
                for i in 0..rets {
                    writeln!(o, "{} = r{i};", cell(region + i)).ok();
                }
                writeln!(o, "}}").ok();
                writeln!(
                    o,
                    "Err(Unwind::Outer) => {{ cx.resume_at(me); (dt, dpc) = cx.raised(); {} }}",
                    at.raise_from_callee()
                )
                .ok();
                writeln!(o, "Err(Unwind::Fault) => break 'fault {region},").ok();
                writeln!(o, "}}").ok();
                let next = plan.block_of(insn.next())?;
                writeln!(o, "block = {}; continue;", successor(next, at.mode)).ok();
            }
            Ret => {
                let rets = plan.pou.ret_cells as u32;
                let results: Vec<String> = (d - rets..d).map(cell).collect();
                writeln!(o, "cx.ret({pc});\nreturn Ok([{}]);", results.join(", ")).ok();
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
    )
    .then_some(b)
}

/// The block number of a successor: the fast block, or in a checked twin the fast block
/// plus `tw` (checked twins only when the activation's stack room is short).
fn successor(block: usize, mode: Mode) -> String {
    match mode {
        Mode::Fast => block.to_string(),
        Mode::Checked => format!("{block} + tw"),
    }
}

/// A place that raises a trap: `(trap code, 0 = dynamic; code offset, u32::MAX = dynamic;
/// stack depth; fuel to give back)`, an entry of a POU's site table.
type SiteEntry = (u8, u32, u32, u32);

/// Where an instruction stands in its block.
struct Site<'p, 'a> {
    insn: &'p Insn<'a>,
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
