//! Differential test: thousands of random *verified* programs run on the VM and on the
//! reference model; the complete state (data memory, operand stack, pc, call and try depth,
//! cycle result) is compared after every cycle.
//!
//! The generator builds well-formed code through the builder: random expressions (all
//! arithmetic, bit, compare, float, conversion, check and math-builtin instructions; loads
//! and stores of every type and addressing mode, including wild indirect addresses), `if`s,
//! counted loops, nested try blocks with handlers that record or re-throw, calls with
//! arguments/results (including unbounded recursion), string builtins on real strings,
//! references made, moved and checked against an object table (valid, NULL, stale and wild),
//! dynamic dispatch on instances of two classes (and on NULL, unknown and overwritten ones),
//! explicit throws and the occasional endless loop. Small limits make every trap reachable.

use super::*;
use crate::image::VarType;
use crate::isa::{Builtin, MemType, Opcode, RoundMode, Trap};

/// Deterministic xorshift64* generator (no `rand` dependency).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    pub fn chance(&mut self, percent: u64) -> bool {
        self.below(100) < percent
    }
    pub fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len() as u64) as usize]
    }
}

const GLOBALS: u32 = 128; // absolute accesses in [0, 128)
const STR_A: u32 = 128; // STRING[16]
const STR_B: u32 = 148; // STRING[16]
const STR_LEN: u16 = 16;
const FUNC_FRAME: u32 = 32;
const FUNC_BASE: u32 = 400;
const AUX_BASE: u32 = 464;
const AUX_FRAME: u32 = 48;
/// Objects references may reach (inside the globals): (start, len, parent index).
const OBJECTS: [(u32, u32, Option<u32>); 6] = [
    (8, 16, None),
    (24, 16, None),
    (24, 4, Some(1)),
    (32, 8, Some(1)),
    (40, 1, None),
    (64, 24, None),
];
/// Instances of class 0 and 1 (their class id at their first byte, in the globals).
const INSTANCES: [u32; 2] = [88, 104];
/// Method frame size and parameter frames of the two methods.
const METHOD_FRAME: u32 = 16;
const METHOD_PARAMS: [u32; 2] = [336, 344];

struct Gen<'r> {
    rng: &'r mut Rng,
    b: ImageBuilder,
    funcs: [PouId; 2],
    /// In a method: no further dynamic calls (bounded depth apart from CALL_DEPTH tests).
    in_method: bool,
    frame: u32,
    budget_left: u32,
    no_endless_loops: bool,
}

const COMPARISONS: &[Opcode] = &[
    Opcode::Eq,
    Opcode::Ne,
    Opcode::LtS,
    Opcode::LeS,
    Opcode::GtS,
    Opcode::GeS,
    Opcode::LtU,
    Opcode::GeU,
    Opcode::LtF32,
    Opcode::GtF32,
    Opcode::EqF32,
    Opcode::LtF64,
    Opcode::GeF64,
];

const BINARY: &[Opcode] = &[
    Opcode::Add,
    Opcode::Sub,
    Opcode::Mul,
    Opcode::DivS,
    Opcode::DivU,
    Opcode::ModS,
    Opcode::ModU,
    Opcode::And,
    Opcode::Or,
    Opcode::Xor,
    Opcode::Shl,
    Opcode::ShrU,
    Opcode::ShrS,
    Opcode::Eq,
    Opcode::Ne,
    Opcode::LtS,
    Opcode::LeS,
    Opcode::GtS,
    Opcode::GeS,
    Opcode::LtU,
    Opcode::LeU,
    Opcode::GtU,
    Opcode::GeU,
    Opcode::AddF32,
    Opcode::SubF32,
    Opcode::MulF32,
    Opcode::DivF32,
    Opcode::EqF32,
    Opcode::NeF32,
    Opcode::LtF32,
    Opcode::LeF32,
    Opcode::GtF32,
    Opcode::GeF32,
    Opcode::AddF64,
    Opcode::SubF64,
    Opcode::MulF64,
    Opcode::DivF64,
    Opcode::EqF64,
    Opcode::NeF64,
    Opcode::LtF64,
    Opcode::LeF64,
    Opcode::GtF64,
    Opcode::GeF64,
];

const UNARY: &[Opcode] = &[
    Opcode::Neg,
    Opcode::AbsS,
    Opcode::Not,
    Opcode::NotBool,
    Opcode::NegF32,
    Opcode::NegF64,
    Opcode::IToF32S,
    Opcode::IToF32U,
    Opcode::IToF64S,
    Opcode::IToF64U,
    Opcode::F32ToF64,
    Opcode::F64ToF32,
];

const MATH1: &[Builtin] = &[
    Builtin::SqrtF64,
    Builtin::LnF64,
    Builtin::LogF64,
    Builtin::ExpF64,
    Builtin::SinF64,
    Builtin::CosF64,
    Builtin::TanF64,
    Builtin::AsinF64,
    Builtin::AcosF64,
    Builtin::AtanF64,
    Builtin::AbsF64,
    Builtin::SqrtF32,
    Builtin::LnF32,
    Builtin::ExpF32,
    Builtin::SinF32,
    Builtin::AsinF32,
    Builtin::AbsF32,
];

const INTERESTING: &[i64] = &[
    0,
    1,
    -1,
    2,
    7,
    -8,
    63,
    64,
    127,
    128,
    255,
    256,
    32767,
    -32768,
    65535,
    i32::MAX as i64,
    i64::MIN,
    i64::MAX,
];

impl Gen<'_> {
    fn constant(&mut self) {
        let r = self.rng.below(6);
        match r {
            0 => {
                let v = self.rng.pick(INTERESTING);
                self.b.push_int(v);
            }
            1 => {
                let v = self.rng.next() as i64;
                self.b.push_i64(v);
            }
            2 => {
                let v = [0.0f32, -0.0, 1.5, -2.25, 1e30, f32::NAN, f32::INFINITY, 0.1];
                let x = self.rng.pick(&v);
                self.b.push_f32(x);
            }
            3 => {
                let v = [0.0f64, 2.0, -3.5, 0.5, 1e300, -1e-300, f64::NAN, 1.0, 0.99];
                let x = self.rng.pick(&v);
                self.b.push_f64(x);
            }
            4 => {
                let v = self.rng.next();
                let k = self.b.add_const(v);
                self.b.push_const(k);
            }
            _ => {
                let v = self.rng.below(20) as i32 - 5;
                self.b.push_i32(v);
            }
        }
    }

    fn mem_type(&mut self) -> MemType {
        self.rng.pick(&MemType::ALL)
    }

    fn load(&mut self) {
        let ty = self.mem_type();
        match self.rng.below(4) {
            0 => {
                let addr = self.rng.below((GLOBALS - 8) as u64) as u32;
                self.b.ld_abs(ty, addr);
            }
            1 => {
                let off = self.rng.below((self.frame - 8) as u64) as u32;
                self.b.ld_rel(ty, off);
            }
            2 => {
                let off = self.rng.below((self.frame - 8) as u64) as u32;
                self.b.lea_rel(off);
                self.b.ld_ind(ty, self.rng.below(4) as u32);
            }
            3 if self.rng.chance(30) => {
                // through a reference: made from an address (sometimes outside every
                // object), moved, checked for the access's width
                self.reference();
                self.b.ref_check(ty.width() as u32);
                self.b.ld_ind(ty, 0);
            }
            3 if self.rng.chance(30) => {
                // array element: ARRAY[lo..lo+7] OF <8 bytes> in the globals
                let lo = self.rng.below(7) as i64 - 3;
                self.b.push_u32(self.rng.below(64) as u32);
                self.expr(0);
                self.b.index(lo, lo + 7, 8);
                self.b.ld_ind(ty, 0);
            }
            3 if self.rng.chance(60) => {
                // array element through ELEM (fused with LD_IND 0 into LD_ELEM)
                self.expr(0);
                self.element();
                let off = if self.rng.chance(80) {
                    0
                } else {
                    self.rng.below(4) as u32
                };
                self.b.ld_ind(ty, off);
            }
            _ => {
                // wild address: sometimes outside data
                let addr = self.rng.below(DATA as u64 + 16) as u32;
                self.b.push_u32(addr);
                self.b.ld_ind(ty, 0);
            }
        }
    }

    /// `[i] -> [address]` through ELEM_ABS or ELEM_REL: an array in the globals, in the
    /// frame, or (rarely) running past the end of data memory.
    fn element(&mut self) {
        let lo = self.rng.below(7) as i64 - 3;
        let count = 1 + self.rng.below(8) as i64;
        match self.rng.below(8) {
            0..=3 => {
                let addr = self.rng.below(GLOBALS as u64 / 2) as u32;
                self.b
                    .elem_abs(addr, lo, lo + count - 1, self.rng.pick(&[1, 2, 4, 8]));
            }
            4..=6 => {
                let off = self.rng.below((self.frame / 2) as u64) as u32;
                let stride = self.rng.pick(&[1, 2, 4]);
                self.b.elem_rel(off, lo, lo + count.min(4) - 1, stride);
            }
            _ => {
                let addr = DATA - self.rng.below(16) as u32;
                self.b.elem_abs(addr, lo, lo + count - 1, 64);
            }
        }
    }

    /// Pushes a reference cell: usually made by REF_MAKE from an address in or near an
    /// object and moved by REF_ADD, sometimes NULL or an arbitrary cell.
    fn reference(&mut self) {
        match self.rng.below(10) {
            0 => self.b.push_i32(0),
            1 => self.constant(),
            _ => {
                let (start, len, _) = self.rng.pick(&OBJECTS);
                let address = start + self.rng.below(len as u64 + 2) as u32;
                self.b.push_u32(address.saturating_sub(1));
                let size = self.rng.below(6) as u32;
                self.b.ref_make(size);
                if self.rng.chance(50) {
                    let n = self.rng.below(24) as i32 - 8;
                    self.b.push_i32(n);
                    self.b.ref_add();
                }
            }
        }
    }

    /// Pushes an instance address for a dynamic call: one of the two instances, NULL, or
    /// anything.
    fn instance(&mut self) {
        match self.rng.below(8) {
            0 => self.b.push_i32(0),
            1 => self.expr(0),
            2 => self.b.lea_rel(0),
            _ => {
                let i = self.rng.pick(&INSTANCES);
                self.b.push_u32(i);
            }
        }
    }

    /// Emits code pushing exactly one cell.
    fn expr(&mut self, depth: u32) {
        let leaf = depth == 0 || self.rng.chance(30);
        if leaf {
            match self.rng.below(4) {
                0 | 1 => self.constant(),
                2 => self.load(),
                _ => {
                    if self.rng.chance(50) {
                        self.b.now();
                    } else {
                        self.constant();
                    }
                }
            }
            return;
        }
        match self.rng.below(12) {
            0..=3 => {
                self.expr(depth - 1);
                self.expr(depth - 1);
                let op = self.rng.pick(BINARY);
                self.b.op(op);
            }
            4 => {
                self.expr(depth - 1);
                let op = self.rng.pick(UNARY);
                self.b.op(op);
            }
            5 => {
                self.expr(depth - 1);
                match self.rng.below(4) {
                    0 => {
                        let w = self.rng.pick(&[8, 16, 32]);
                        let op = self.rng.pick(&[Opcode::Sext, Opcode::Zext]);
                        self.b.op_width(op, w);
                    }
                    1 => {
                        let ty = self.rng.pick(&MemType::ALL[..8]);
                        let mode = self
                            .rng
                            .pick(&[RoundMode::Truncate, RoundMode::NearestTiesAway]);
                        let op = self.rng.pick(&[Opcode::F32ToInt, Opcode::F64ToInt]);
                        self.b.float_to_int(op, ty, mode);
                    }
                    2 => {
                        let lo = self.rng.below(10) as i64 - 5;
                        let hi = lo + self.rng.below(20) as i64;
                        match self.rng.below(3) {
                            0 => self.b.chk_index(lo, hi),
                            1 => self.b.chk_range_s(lo, hi),
                            _ => self
                                .b
                                .chk_range_u(lo.unsigned_abs(), hi.unsigned_abs() + 100),
                        }
                    }
                    _ => {
                        let f = self.rng.pick(MATH1);
                        self.b.call_builtin(f);
                    }
                }
            }
            6 => {
                self.expr(depth - 1);
                self.expr(depth - 1);
                let w = self.rng.pick(&[8, 16, 32, 64]);
                let op = self.rng.pick(&[Opcode::Rol, Opcode::Ror]);
                self.b.op_width(op, w);
            }
            7 if self.rng.chance(40) => {
                // MIN/MAX
                self.expr(depth - 1);
                self.expr(depth - 1);
                let cmp = self.rng.pick(COMPARISONS);
                self.b.sel_if(cmp);
            }
            7 => {
                self.expr(depth - 1);
                self.expr(depth - 1);
                self.expr(depth - 1);
                self.b.op(Opcode::Sel);
            }
            8 => {
                self.expr(depth - 1);
                match self.rng.below(3) {
                    0 => {
                        self.b.dup();
                        self.b.op(Opcode::Mul);
                    }
                    1 => {
                        self.expr(depth - 1);
                        self.b.over();
                        self.b.op(Opcode::Sub);
                        self.b.op(Opcode::Xor);
                    }
                    _ => {
                        self.expr(depth - 1);
                        self.b.swap();
                        self.b.op(Opcode::Sub);
                    }
                }
            }
            9 => {
                // call f0(x) -> y
                self.expr(depth - 1);
                let base = if self.rng.chance(5) {
                    DATA - 8
                } else {
                    FUNC_BASE
                };
                self.b.push_u32(base);
                self.b.call(self.funcs[0]);
            }
            10 => {
                let base = FUNC_BASE + FUNC_FRAME;
                self.b.push_u32(base);
                self.b.call(self.funcs[1]);
            }
            _ => match self.rng.below(5) {
                4 => {
                    self.reference();
                    if self.rng.chance(60) {
                        let size = self.rng.below(10) as u32;
                        self.b.ref_check(size);
                    }
                }
                0 => {
                    self.b.push_u32(STR_A);
                    self.b.call_builtin(Builtin::StrLen);
                }
                1 => {
                    self.b.push_u32(STR_A);
                    self.b.push_u32(STR_B);
                    self.b.call_builtin(Builtin::StrFind);
                }
                2 => {
                    self.b.push_u32(STR_A);
                    self.b.push_u32(STR_B);
                    self.b.call_builtin(Builtin::StrCompare);
                }
                _ => {
                    self.expr(depth - 1);
                    self.expr(depth - 1);
                    self.b.call_builtin(Builtin::ExptF64);
                }
            },
        }
    }

    fn store(&mut self) {
        let ty = self.mem_type();
        match self.rng.below(3) {
            0 => {
                let addr = self.rng.below((GLOBALS - 8) as u64) as u32;
                self.b.st_abs(ty, addr);
            }
            1 => {
                let off = self.rng.below((self.frame - 8) as u64) as u32;
                self.b.st_rel(ty, off);
            }
            _ => {
                // [value] -> address below it via SWAP
                let addr = if self.rng.chance(80) {
                    self.rng.below(GLOBALS as u64) as u32
                } else {
                    self.rng.below(DATA as u64 + 8) as u32
                };
                self.b.push_u32(addr);
                self.b.swap();
                self.b.st_ind(ty, 0);
            }
        }
    }

    /// Emits statements with net stack effect 0 and balanced try frames.
    fn block(&mut self, nesting: u32) {
        let count = 1 + self.rng.below(4);
        for _ in 0..count {
            if self.budget_left == 0 {
                return;
            }
            self.budget_left -= 1;
            self.statement(nesting);
        }
    }

    fn statement(&mut self, nesting: u32) {
        let compound = nesting > 0;
        match self.rng.below(if compound { 14 } else { 8 }) {
            0..=3 => {
                let d = 1 + self.rng.below(3) as u32;
                self.expr(d);
                self.store();
            }
            4 => {
                // COPY
                let dst = self.rng.below(GLOBALS as u64) as u32;
                let src = self.rng.below(DATA as u64) as u32;
                let len = self.rng.below(24) as u32;
                self.b.push_u32(dst);
                self.b.push_u32(src);
                self.b.copy(len);
            }
            5 => {
                // string builtin writing STR_A or STR_B
                let dst = self.rng.pick(&[STR_A, STR_B]);
                let other = self.rng.pick(&[STR_A, STR_B]);
                self.b.push_u32(dst);
                match self.rng.below(6) {
                    0 => {
                        self.b.push_u32(other);
                        self.b.push_u32(other);
                        self.b.call_builtin(Builtin::StrConcat);
                    }
                    1 => {
                        self.b.push_u32(other);
                        self.expr(1);
                        self.b.call_builtin(Builtin::StrLeft);
                    }
                    2 => {
                        self.b.push_u32(other);
                        self.expr(1);
                        self.expr(1);
                        self.b.call_builtin(Builtin::StrMid);
                    }
                    3 => {
                        self.expr(1);
                        self.b.call_builtin(Builtin::StrFromI64);
                    }
                    4 => {
                        self.b.push_u32(other);
                        self.b.push_u32(other);
                        self.expr(1);
                        self.expr(1);
                        self.b.call_builtin(Builtin::StrReplace);
                    }
                    _ => {
                        self.expr(1);
                        self.b.call_builtin(Builtin::StrFromF64);
                    }
                }
            }
            6 if !self.in_method && self.rng.chance(40) => {
                // dynamic call: store a parameter through VIRT_FRAME, then CALL_VIRT
                let slot = self.rng.below(3) as u16;
                if self.rng.chance(70) {
                    self.instance();
                    self.b.virt_frame(slot);
                    self.expr(1);
                    self.b.st_ind(MemType::U8, 0);
                }
                self.instance();
                self.b.call_virt(slot);
            }
            6 if self.rng.chance(25) => {
                // a store into an array element through ELEM (fused into ST_ELEM when the
                // value's code cannot trap)
                self.expr(0);
                self.element();
                let d = self.rng.below(3) as u32;
                self.expr(d);
                let ty = self.mem_type();
                let off = if self.rng.chance(85) { 0 } else { 1 };
                self.b.st_ind(ty, off);
            }
            6 if self.rng.chance(25) => {
                // x := x + k on an integer variable (fused into INC_REL/INC_ABS)
                let ty = self.rng.pick(&MemType::ALL[..8]);
                let k = self.rng.pick(&[1, -1, 2, 100, -32768, i32::MAX]);
                if self.rng.chance(50) {
                    let off = self.rng.below((self.frame - 8) as u64) as u32;
                    self.b.ld_rel(ty, off);
                    self.b.push_i32(k);
                    self.b.op(Opcode::Add);
                    self.b.st_rel(ty, off);
                } else {
                    let addr = self.rng.below((GLOBALS - 8) as u64) as u32;
                    self.b.ld_abs(ty, addr);
                    self.b.push_i32(k);
                    self.b.op(Opcode::Add);
                    self.b.st_abs(ty, addr);
                }
            }
            6 if self.rng.chance(20) => {
                // a store through a reference
                self.reference();
                let ty = self.mem_type();
                self.b.ref_check(ty.width() as u32);
                self.expr(1);
                self.b.st_ind(ty, 0);
            }
            6 => {
                if self.rng.chance(20) {
                    let trap = self.rng.pick(&[
                        Trap::DivisionByZero,
                        Trap::IndexOutOfBounds,
                        Trap::SubrangeViolation,
                        Trap::NumericError,
                        Trap::CallDepth,
                    ]);
                    self.b.throw(trap);
                } else {
                    self.b.nop();
                }
            }
            7 => {
                if !self.no_endless_loops && self.rng.chance(3) {
                    let top = self.b.new_label();
                    self.b.bind(top);
                    self.b.jmp(top); // endless loop -> WATCHDOG
                } else {
                    self.expr(1);
                    self.b.drop_();
                }
            }
            8 | 9 => {
                // if / else
                let other = self.b.new_label();
                let end = self.b.new_label();
                if self.rng.chance(30) {
                    // comparison with an immediate (JUMP_IF_IMM/JUMP_IF_NOT_IMM)
                    self.expr(1);
                    let k = self.rng.pick(INTERESTING);
                    self.b.push_i32(k as i32);
                    let cmp = self.rng.pick(COMPARISONS);
                    self.b.jump_if(self.rng.chance(50), cmp, other);
                } else {
                    self.expr(2);
                    if self.rng.chance(50) {
                        self.b.jz(other);
                    } else {
                        self.b.jnz(other);
                    }
                }
                self.block(nesting - 1);
                self.b.jmp(end);
                self.b.bind(other);
                self.block(nesting - 1);
                self.b.bind(end);
            }
            10 => {
                // counted loop with the counter on the stack
                let top = self.b.new_label();
                let done = self.b.new_label();
                let n = self.rng.below(5) as i32;
                self.b.push_i32(n);
                self.b.bind(top);
                self.b.dup();
                self.b.jz(done);
                self.block(nesting - 1);
                self.b.push_i32(1);
                self.b.op(Opcode::Sub);
                self.b.jmp(top);
                self.b.bind(done);
                self.b.drop_();
            }
            _ => {
                // try block; handler records the code or re-throws it
                let handler = self.b.new_label();
                let end = self.b.new_label();
                self.b.try_begin(handler);
                self.block(nesting - 1);
                self.b.try_end();
                self.b.jmp(end);
                self.b.bind(handler);
                if self.rng.chance(25) {
                    self.b.rethrow();
                } else {
                    let addr = self.rng.below(GLOBALS as u64) as u32;
                    self.b.st_abs(MemType::U8, addr);
                    if self.rng.chance(50) {
                        self.block(nesting - 1);
                    }
                }
                self.b.bind(end);
            }
        }
    }
}

/// Builds one random program from `seed`.
pub fn random_program(seed: u64) -> Vec<u8> {
    random_program_with(seed, true)
}

/// Builds one random program from `seed`, with or without the builder's peephole fusion.
pub fn random_program_with(seed: u64, fuse: bool) -> Vec<u8> {
    let mut rng = Rng::new(seed);
    let mut b = ImageBuilder::new();
    if !fuse {
        b.disable_fusion();
    }
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let f0 = b.declare_pou("f0", 1, 1, FUNC_FRAME);
    let f1 = b.declare_pou("f1", 0, 1, FUNC_FRAME);
    let aux = b.declare_pou("Aux", 0, 0, AUX_FRAME);
    let methods = [
        b.declare_pou("M0", 0, 0, METHOD_FRAME),
        b.declare_pou("M1", 0, 0, METHOD_FRAME),
    ];
    for (start, len, parent) in OBJECTS {
        b.add_object(start, len, parent);
    }
    // Class 0 runs M0 for slot 0 and M1 for slot 1; class 1 runs M1 for slots 0 and 2.
    b.add_class(
        "C0",
        &[
            (0, methods[0], METHOD_PARAMS[0]),
            (1, methods[1], METHOD_PARAMS[1]),
        ],
    );
    b.add_class(
        "C1",
        &[
            (0, methods[1], METHOD_PARAMS[1]),
            (2, methods[1], METHOD_PARAMS[1]),
        ],
    );
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: MAIN_BASE,
        interval_ns: 10,
        watchdog_budget: 600 + rng.below(1500) as u32,
    });
    b.add_task(&TaskDef {
        name: "T2".into(),
        kind: TaskKind::Event,
        priority: 1,
        pou: aux,
        instance_base: AUX_BASE,
        interval_ns: 0,
        watchdog_budget: 0, // the default budget: endless loops take 1e6 instructions
    });
    let mut init = [0u8; GLOBALS as usize];
    for byte in init.iter_mut() {
        *byte = rng.next() as u8;
    }
    b.set_init(0, &init);
    for (class, instance) in INSTANCES.iter().enumerate() {
        b.set_init(*instance, &(class as u32).to_le_bytes());
    }
    b.init_string(STR_A, STR_LEN, "hello");
    b.init_string(STR_B, STR_LEN, "lo");
    b.add_var("Main.a", VarType::String, 0, STR_A, 4 + STR_LEN as u32);
    let mut g = Gen {
        rng: &mut rng,
        b,
        funcs: [f0, f1],
        in_method: false,
        frame: MAIN_FRAME,
        budget_left: 12,
        no_endless_loops: false,
    };
    g.b.begin_pou(main);
    g.block(2);
    g.block(2);
    g.b.ret();
    g.b.end_pou(main);
    // f0(x): x op <expr>, sometimes recursive through f1
    g.frame = FUNC_FRAME;
    g.budget_left = 3;
    g.b.begin_pou(f0);
    g.block(1);
    g.expr(1);
    let op = g.rng.pick(BINARY);
    g.b.op(op);
    g.b.ret();
    g.b.end_pou(f0);
    g.budget_left = 2;
    g.b.begin_pou(f1);
    g.block(1);
    if g.rng.chance(30) {
        // f1 calls f0, which may call f1 again: bounded only by CALL_DEPTH / watchdog
        g.b.push_i32(1);
        g.b.push_u32(FUNC_BASE);
        g.b.call(f0);
    } else {
        g.expr(2);
    }
    g.b.ret();
    g.b.end_pou(f1);
    // The methods: a few statements on their instance, sometimes a dynamic call that may
    // come back to themselves (bounded only by CALL_DEPTH).
    g.frame = METHOD_FRAME;
    for (k, m) in methods.into_iter().enumerate() {
        g.budget_left = 2;
        g.in_method = true;
        g.b.begin_pou(m);
        g.b.ld_abs(MemType::U8, METHOD_PARAMS[k]);
        g.b.st_rel(MemType::U8, 4 + k as u32);
        g.block(1);
        if g.rng.chance(20) {
            g.instance();
            g.b.call_virt(g.rng.below(3) as u16);
        }
        g.b.ret();
        g.b.end_pou(m);
    }
    g.in_method = false;
    // Aux: a second program sharing the globals, with its own frame; no endless loops
    // (its watchdog budget is the large default).
    g.frame = AUX_FRAME;
    g.no_endless_loops = true;
    g.budget_left = 4;
    g.b.begin_pou(aux);
    g.block(1);
    g.b.ret();
    g.b.end_pou(aux);
    g.b.build().expect("build")
}

#[test]
fn vm_matches_model_on_random_programs() {
    let programs = 10_000u64;
    let mut traps = [0usize; 16];
    let mut completed = 0usize;
    for seed in 0..programs {
        let bytes = random_program(seed);
        let image = Image::parse(&bytes).expect("parse");
        let verified = verify(&image)
            .unwrap_or_else(|e| panic!("seed {seed}: generated program rejected: {e}"));
        let mut data = vec![0u8; image.data_size() as usize];
        let mut stack = [0u64; STACK];
        let mut calls = [CallFrame::EMPTY; CALLS];
        let mut tries = [TryFrame::EMPTY; TRIES];
        let mut vm = Machine::new(
            verified,
            Memory {
                data: &mut data,
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        )
        .unwrap();
        let mut model = Model::new(&verified, STACK, CALLS, TRIES);
        for cycle in 0..5i64 {
            // Task 0 every cycle, the event task every other cycle.
            let task = if cycle % 2 == 1 { 1 } else { 0 };
            let result = vm.run_cycle(task, cycle * 7_000_000);
            let expected = model.run_cycle(task, cycle * 7_000_000, None);
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                compare(&vm, &model, &result, &expected);
            }));
            if outcome.is_err() {
                panic!("seed {seed}, cycle {cycle}: VM {result:?} vs model {expected:?}");
            }
            match result {
                Ok(_) => completed += 1,
                Err(fault) if !fault.refused => {
                    traps[fault.trap.code() as usize] += 1;
                    // restart the task on both sides, as a runtime would after safe outputs
                    vm.reset_task(task);
                    model.reset_task(task);
                }
                Err(_) => {}
            }
        }
    }
    // The generator must actually reach the interesting behaviour.
    std::println!("completed cycles {completed}, traps by code {traps:?}");
    assert!(completed > 10_000);
    // DEADLINE comes from the runtime's clock, never from a program: the model has no time.
    for trap in Trap::ALL.iter().filter(|t| **t != Trap::Deadline) {
        assert!(
            traps[trap.code() as usize] > 0,
            "no uncaught {trap} in {programs} programs"
        );
    }
}

/// Runs `cycles` cycles alternating the two tasks with a large stack and budget; returns the
/// observable outcome per cycle (trap kind or completion, data, stack), or `None` when a
/// watchdog fired (instruction counts legitimately differ between fused and unfused code).
/// What one cycle looked like from outside: uncaught trap (if any), data memory, stack.
type Observation = (Option<Trap>, Vec<u8>, Vec<u64>);

fn observe(bytes: &[u8], cycles: i64) -> Option<Vec<Observation>> {
    let image = Image::parse(bytes).unwrap();
    let verified = verify(&image).unwrap();
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = vec![0u64; 1024];
    let mut calls = [CallFrame::EMPTY; CALLS];
    let mut tries = [TryFrame::EMPTY; TRIES];
    let mut vm = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let mut seen = Vec::new();
    for cycle in 0..cycles {
        let task = (cycle % 2) as usize;
        vm.set_watchdog_budget(task, Some(20_000));
        let result = vm.run_cycle(task, cycle * 1000);
        let trap = match result {
            Ok(_) => None,
            Err(fault) if fault.trap == Trap::Watchdog => return None,
            Err(fault) => {
                vm.reset_task(task);
                Some(fault.trap)
            }
        };
        // After an uncaught trap the operand stack is as before the trapping instruction,
        // which for a fused instruction is before the whole fused sequence: not compared.
        let stack = if trap.is_none() {
            vm.stack().to_vec()
        } else {
            Vec::new()
        };
        seen.push((trap, vm.data().to_vec(), stack));
    }
    Some(seen)
}

#[test]
fn builder_fusion_preserves_behaviour() {
    let mut compared = 0;
    for seed in 0..10_000u64 {
        let fused = random_program_with(seed, true);
        let plain = random_program_with(seed, false);
        // Fusion never adds an instruction (its instructions may be longer).
        let count =
            |bytes: &[u8]| crate::isa::instructions(Image::parse(bytes).unwrap().code()).count();
        assert!(count(&fused) <= count(&plain), "seed {seed}");
        if let (Some(a), Some(b)) = (observe(&fused, 4), observe(&plain, 4)) {
            assert_eq!(a, b, "seed {seed}: fused and unfused programs differ");
            compared += 1;
        }
    }
    assert!(compared > 7500, "only {compared} programs compared");
}

#[test]
fn random_programs_use_every_superinstruction() {
    let mut seen = [false; 256];
    for seed in 0..600u64 {
        let bytes = random_program(seed);
        let image = Image::parse(&bytes).unwrap();
        for insn in crate::isa::instructions(image.code()) {
            seen[insn.op as usize] = true;
        }
    }
    let missing: Vec<&str> = Opcode::ALL
        .iter()
        .filter(|op| (0xC0..=0xDF).contains(&(**op as u8)) && !seen[**op as usize])
        .map(|op| op.mnemonic())
        .collect();
    assert!(missing.is_empty(), "never generated: {missing:?}");
}
