//! The instruction set: opcodes, operand encodings, memory/value types, traps and builtins.
//!
//! Every instruction is one opcode byte followed by fixed-size little-endian immediates
//! (see [`Operands`]). Code offsets in jump/handler operands are absolute offsets into the
//! code section. The operand stack holds 64-bit cells:
//!
//! * integers: two's complement `i64` (unsigned values zero-extended into the cell);
//! * `REAL` (f32): the f32 bit pattern in the low 32 bits, upper 32 bits zero;
//! * `LREAL` (f64): the f64 bit pattern (a NaN that `+ - * /` produce is the canonical
//!   quiet NaN, for REAL too: [`real_result`], [`lreal_result`]);
//! * `BOOL`: 0 or 1; `TIME`: `i64` nanoseconds; addresses: unsigned byte offsets into data memory.
//!
//! Stack effects are written `[before] -> [after]` with the top of stack on the right.
//! "May trap" lists the [`Trap`]s an instruction can raise; every data access may raise
//! [`Trap::InvalidAddress`] when its (dynamic) address is outside data memory, every push may
//! raise [`Trap::StackOverflow`] when the operand stack is full.
//!
//! # References
//!
//! A *reference* (IEC `REF_TO`, CODESYS `POINTER TO`) is a cell `address | object << 32`:
//! the low 32 bits are a data address, the high 32 bits name the variable (or the part of a
//! variable) the reference was taken from, as `1 +` the index of its record in the image's
//! `OBJECTS` section ([`crate::image::Image::object`]). The cell 0 is `NULL`.
//! `REF_MAKE n` turns an address into a reference to the smallest object containing the `n`
//! bytes there; `REF_ADD` moves a reference by a byte offset (only its address changes,
//! wrapping in 32 bits, so arithmetic can never make it name another object); `REF_CHECK n`
//! admits an access of `n` bytes at the reference's address only when it lies inside the
//! named object's bytes and leaves the plain address for `LD_IND`/`ST_IND`/`COPY`/builtins.
//! A reference therefore reaches the variable it was taken from and nothing else, whatever
//! arithmetic the program did on it; NULL, a reference moved outside its variable and a cell
//! that was never a reference all trap with [`Trap::InvalidReference`] at the access.
//!
//! # Classes and dynamic dispatch
//!
//! A function-block instance whose methods are called through `CALL_VIRT` holds its class id
//! (an index into the `CLASSES` section) as a `u32` at its first byte; references to such
//! instances (and interface values) are plain instance addresses, 0 being `NULL`.
//! `CALL_VIRT slot` reads the class of the instance on the stack, finds the class's
//! `DISPATCH` record for `slot` and calls its POU with the instance as frame base, exactly as
//! `CALL` would; `VIRT_FRAME slot` gives the data address of that method's parameter frame so
//! the caller can store the arguments first. Every dispatch target is a POU the verifier
//! checked (valid index, no argument or result cells), so the verifier still proves stack
//! depths; which method runs is decided by the instance's class at run time. A NULL
//! instance, an unknown class or a class without the slot trap with
//! [`Trap::InvalidReference`].
//!
//! # Fused instructions and superinstructions
//!
//! Some instructions exist only to cut dispatches: `INDEX`, `ADD_IMM`, `JUMP_IF`,
//! `JUMP_IF_NOT` and the superinstructions `0xC0..=0xD6` (array elements with and without a
//! frame variable as the index, `INC_*`, `SEL_IF`, comparisons and operators with an
//! immediate or frame/static operands, immediate jumps on a frame variable). Each one's
//! description names the plain sequence it is; it has exactly that sequence's effect, raises
//! the traps that sequence can raise in the same order, and never needs more operand stack
//! (it may need less: a fused push that would overflow is not there), but the watchdog
//! counts it as **one** instruction and a trap leaves the stack as it was before the fused
//! instruction (as before every trapping instruction). `ST_ELEM_*` reads its index and checks
//! it after the value is computed; the builder makes it (from `ELEM_*`, the value's code,
//! `ST_IND ty 0`) only when the value's code is pure (no memory write, no trap but
//! STACK_OVERFLOW), so nothing can tell. Element addresses are computed as `INDEX` does
//! (wrapping 64-bit arithmetic), then checked against data memory at the access.
//! `image::ImageBuilder` fuses the plain sequences as they are emitted (see its `op`); the
//! VM, the reference model ([`crate::model`]) and the native tier (`plc-native`) implement
//! every one.

/// Operand layout of an instruction (all immediates little-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Operands {
    /// No operands.
    None,
    /// `i32` immediate.
    I32,
    /// `u32` immediate.
    U32,
    /// `i64` immediate.
    I64,
    /// `u16` index (constant pool, POU table or builtin table).
    Index16,
    /// [`MemType`] byte then `u32` address/offset.
    TypeAddr,
    /// One width byte: 8, 16, 32 (and 64 for rotates).
    Width,
    /// [`MemType`] byte (an integer type) then [`RoundMode`] byte.
    TypeMode,
    /// `u32` absolute code offset (jump target or handler).
    Target,
    /// Two `i64` immediates: inclusive lower and upper bound.
    Range,
    /// One trap code byte.
    TrapCode,
    /// Two `i64` bounds (inclusive) then a `u32` element stride.
    IndexSpec,
    /// A comparison opcode byte (see [`Opcode::is_comparison`]) then a `u32` code target.
    CompareTarget,
    /// A `u32` address/offset, two `i64` bounds (inclusive), a `u32` element stride.
    AddrIndex,
    /// A [`MemType`] byte, a `u32` address/offset, two `i64` bounds (inclusive), a `u32`
    /// element stride.
    TypeAddrIndex,
    /// A [`MemType`] byte (an integer type), a `u32` address/offset, an `i32` immediate.
    TypeAddrImm,
    /// A comparison opcode byte.
    Compare,
    /// A comparison opcode byte, an `i32` immediate, a `u32` code target.
    CompareImmTarget,
    /// A binary-operator opcode byte (see [`Opcode::is_binary`]) then an `i32` immediate.
    OpImm,
    /// A binary-operator opcode byte, a [`MemType`] byte, a `u32` address/offset.
    OpTypeAddr,
    /// A binary-operator opcode byte, then two operands of a [`MemType`] byte and a `u32`
    /// offset each.
    OpTypeAddr2,
    /// A comparison opcode byte, a [`MemType`] byte, a `u32` offset, an `i32` immediate, a
    /// `u32` code target.
    CompareTypeAddrImmTarget,
    /// As [`Operands::AddrIndex`], then the index variable: a [`MemType`] byte and a `u32`
    /// frame offset.
    AddrIndexAt,
    /// As [`Operands::TypeAddrIndex`], then the index variable: a [`MemType`] byte and a
    /// `u32` frame offset.
    TypeAddrIndexAt,
}

impl Operands {
    /// Number of immediate bytes following the opcode byte.
    pub const fn len(self) -> usize {
        match self {
            Operands::None => 0,
            Operands::I32 | Operands::U32 | Operands::Target => 4,
            Operands::I64 => 8,
            Operands::Index16 | Operands::TypeMode => 2,
            Operands::TypeAddr => 5,
            Operands::Width | Operands::TrapCode => 1,
            Operands::Range => 16,
            Operands::IndexSpec => 20,
            Operands::CompareTarget => 5,
            Operands::AddrIndex => 24,
            Operands::TypeAddrIndex => 25,
            Operands::TypeAddrImm => 9,
            Operands::Compare => 1,
            Operands::CompareImmTarget => 9,
            Operands::OpImm => 5,
            Operands::OpTypeAddr => 6,
            Operands::OpTypeAddr2 => 11,
            Operands::CompareTypeAddrImmTarget => 14,
            Operands::AddrIndexAt => 29,
            Operands::TypeAddrIndexAt => 30,
        }
    }

    /// True when the instruction has no immediates.
    pub const fn is_empty(self) -> bool {
        self.len() == 0
    }
}

macro_rules! opcodes {
    ($( $(#[doc = $doc:literal])* $name:ident = $val:literal, $mnemonic:literal, $operands:ident; )*) => {
        /// An instruction opcode (the first byte of every instruction).
        #[repr(u8)]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum Opcode {
            $( $(#[doc = $doc])* $name = $val, )*
        }

        impl Opcode {
            /// Every opcode, in numeric order.
            pub const ALL: &'static [Opcode] = &[$(Opcode::$name),*];

            /// Decodes an opcode byte; `None` for unassigned values.
            #[inline(always)]
            pub const fn from_u8(byte: u8) -> Option<Opcode> {
                DECODE[byte as usize]
            }

            const fn decode_slow(byte: u8) -> Option<Opcode> {
                match byte {
                    $( $val => Some(Opcode::$name), )*
                    _ => None,
                }
            }

            /// The operand layout that follows the opcode byte.
            pub const fn operands(self) -> Operands {
                match self {
                    $( Opcode::$name => Operands::$operands, )*
                }
            }

            /// The assembler mnemonic (e.g. `"LD_ABS"`).
            pub const fn mnemonic(self) -> &'static str {
                match self {
                    $( Opcode::$name => $mnemonic, )*
                }
            }

            /// Total encoded size of the instruction in bytes.
            #[inline(always)]
            pub const fn size(self) -> usize {
                SIZES[self as usize] as usize
            }
        }

        /// Each opcode's byte as a constant, for `match`ing on raw code bytes (the
        /// interpreter's dispatch).
        #[allow(non_upper_case_globals)]
        pub mod byte {
            $( #[doc = concat!("`", $mnemonic, "`.")] pub const $name: u8 = $val; )*
        }

        /// Opcode byte -> opcode (the interpreter's decode is one table load).
        const DECODE: [Option<Opcode>; 256] = {
            let mut table = [None; 256];
            let mut byte = 0;
            while byte < 256 {
                table[byte] = Opcode::decode_slow(byte as u8);
                byte += 1;
            }
            table
        };

        /// Opcode byte -> instruction size (0 for unassigned bytes).
        const SIZES: [u8; 256] = {
            let mut table = [0u8; 256];
            let mut byte = 0;
            while byte < 256 {
                if let Some(op) = Opcode::decode_slow(byte as u8) {
                    table[byte] = 1 + op.operands().len() as u8;
                }
                byte += 1;
            }
            table
        };
    };
}

opcodes! {
    /// `[] -> []`. Does nothing.
    Nop = 0x00, "NOP", None;
    /// `[] -> [imm]`: pushes the `i32` immediate sign-extended to 64 bits.
    PushI32 = 0x01, "PUSH_I32", I32;
    /// `[] -> [imm]`: pushes the `u32` immediate zero-extended (also used for REAL bit patterns).
    PushU32 = 0x02, "PUSH_U32", U32;
    /// `[] -> [imm]`: pushes the 64-bit immediate (also used for LREAL bit patterns).
    PushI64 = 0x03, "PUSH_I64", I64;
    /// `[] -> [const[idx]]`: pushes constant-pool cell `idx` (verified to exist).
    PushConst = 0x04, "PUSH_CONST", Index16;
    /// `[a] -> []`.
    Drop = 0x05, "DROP", None;
    /// `[a] -> [a a]`.
    Dup = 0x06, "DUP", None;
    /// `[a b] -> [b a]`.
    Swap = 0x07, "SWAP", None;
    /// `[a b] -> [a b a]`.
    Over = 0x08, "OVER", None;

    /// `[] -> [v]`: loads a value of the given type from absolute address `addr` (sign/zero
    /// extension per type). The verifier checks `addr + width <= data_size`.
    LdAbs = 0x10, "LD_ABS", TypeAddr;
    /// `[v] -> []`: stores `v` truncated to the type's width at absolute address `addr`.
    StAbs = 0x11, "ST_ABS", TypeAddr;
    /// `[] -> [v]`: loads from `base + off` (frame-relative; the verifier checks
    /// `off + width <= frame_size` of the enclosing POU, CALL checks the frame fits in data).
    LdRel = 0x12, "LD_REL", TypeAddr;
    /// `[v] -> []`: stores to `base + off`.
    StRel = 0x13, "ST_REL", TypeAddr;
    /// `[addr] -> [v]`: loads from `addr + off`. May trap: INVALID_ADDRESS.
    LdInd = 0x14, "LD_IND", TypeAddr;
    /// `[addr v] -> []`: stores `v` at `addr + off`. May trap: INVALID_ADDRESS.
    StInd = 0x15, "ST_IND", TypeAddr;
    /// `[] -> [base + off]`: address of a frame variable (VAR_IN_OUT arguments, arrays in FBs).
    LeaRel = 0x16, "LEA_REL", U32;
    /// `[dst src] -> []`: copies `len` bytes (memmove semantics; struct/array assignment).
    /// May trap: INVALID_ADDRESS.
    Copy = 0x17, "COPY", U32;
    /// `[] -> [now]`: the cycle time in nanoseconds (constant during a cycle).
    Now = 0x18, "NOW", None;

    /// `[a b] -> [a + b]` wrapping 64-bit.
    Add = 0x20, "ADD", None;
    /// `[a b] -> [a - b]` wrapping.
    Sub = 0x21, "SUB", None;
    /// `[a b] -> [a * b]` wrapping.
    Mul = 0x22, "MUL", None;
    /// `[a b] -> [a / b]` signed, truncating; `i64::MIN / -1` wraps. May trap: DIVISION_BY_ZERO.
    DivS = 0x23, "DIV_S", None;
    /// `[a b] -> [a / b]` unsigned. May trap: DIVISION_BY_ZERO.
    DivU = 0x24, "DIV_U", None;
    /// `[a b] -> [a rem b]` signed (sign of the dividend, `MIN mod -1 = 0`). May trap: DIVISION_BY_ZERO.
    ModS = 0x25, "MOD_S", None;
    /// `[a b] -> [a rem b]` unsigned. May trap: DIVISION_BY_ZERO.
    ModU = 0x26, "MOD_U", None;
    /// `[a] -> [-a]` wrapping.
    Neg = 0x27, "NEG", None;
    /// `[a] -> [|a|]` signed, wrapping (`|MIN| = MIN`).
    AbsS = 0x28, "ABS_S", None;
    /// `[a b] -> [a & b]`.
    And = 0x29, "AND", None;
    /// `[a b] -> [a | b]`.
    Or = 0x2A, "OR", None;
    /// `[a b] -> [a ^ b]`.
    Xor = 0x2B, "XOR", None;
    /// `[a] -> [!a]` bitwise complement (stores truncate it to the declared width).
    Not = 0x2C, "NOT", None;
    /// `[a] -> [a == 0]`: boolean negation (result 0 or 1).
    NotBool = 0x2D, "NOT_BOOL", None;
    /// `[a n] -> [a << n]`; `n` is taken unsigned, `n >= 64` gives 0.
    Shl = 0x2E, "SHL", None;
    /// `[a n] -> [a >> n]` logical; `n >= 64` gives 0.
    ShrU = 0x2F, "SHR_U", None;
    /// `[a n] -> [a >> n]` arithmetic; `n >= 64` gives the sign fill.
    ShrS = 0x30, "SHR_S", None;
    /// `[a n] -> [rotl_w(a, n mod w)]`: rotates the low `w` bits (w = 8/16/32/64); result zero-extended.
    Rol = 0x31, "ROL", Width;
    /// `[a n] -> [rotr_w(a, n mod w)]`.
    Ror = 0x32, "ROR", Width;
    /// `[a] -> [sign_extend_w(a)]` for w = 8/16/32: wraps a value to a signed declared width.
    Sext = 0x33, "SEXT", Width;
    /// `[a] -> [a & (2^w - 1)]` for w = 8/16/32: wraps a value to an unsigned declared width.
    Zext = 0x34, "ZEXT", Width;

    /// `[a b] -> [a == b]` (0/1), integer/bit-pattern equality.
    Eq = 0x38, "EQ", None;
    /// `[a b] -> [a != b]`.
    Ne = 0x39, "NE", None;
    /// `[a b] -> [a < b]` signed.
    LtS = 0x3A, "LT_S", None;
    /// `[a b] -> [a <= b]` signed.
    LeS = 0x3B, "LE_S", None;
    /// `[a b] -> [a > b]` signed.
    GtS = 0x3C, "GT_S", None;
    /// `[a b] -> [a >= b]` signed.
    GeS = 0x3D, "GE_S", None;
    /// `[a b] -> [a < b]` unsigned.
    LtU = 0x3E, "LT_U", None;
    /// `[a b] -> [a <= b]` unsigned.
    LeU = 0x3F, "LE_U", None;
    /// `[a b] -> [a > b]` unsigned.
    GtU = 0x40, "GT_U", None;
    /// `[a b] -> [a >= b]` unsigned.
    GeU = 0x41, "GE_U", None;
    /// `[g a b] -> [if g != 0 { b } else { a }]` (IEC SEL).
    Sel = 0x42, "SEL", None;

    /// `[a b] -> [a + b]` in f32.
    AddF32 = 0x50, "ADD_F32", None;
    /// `[a b] -> [a - b]` in f32.
    SubF32 = 0x51, "SUB_F32", None;
    /// `[a b] -> [a * b]` in f32.
    MulF32 = 0x52, "MUL_F32", None;
    /// `[a b] -> [a / b]` in f32. May trap: DIVISION_BY_ZERO when `b == 0.0`.
    DivF32 = 0x53, "DIV_F32", None;
    /// `[a] -> [-a]` in f32.
    NegF32 = 0x54, "NEG_F32", None;
    /// `[a b] -> [a == b]` f32 (IEEE: NaN is unequal to everything).
    EqF32 = 0x55, "EQ_F32", None;
    /// `[a b] -> [a != b]` f32.
    NeF32 = 0x56, "NE_F32", None;
    /// `[a b] -> [a < b]` f32.
    LtF32 = 0x57, "LT_F32", None;
    /// `[a b] -> [a <= b]` f32.
    LeF32 = 0x58, "LE_F32", None;
    /// `[a b] -> [a > b]` f32.
    GtF32 = 0x59, "GT_F32", None;
    /// `[a b] -> [a >= b]` f32.
    GeF32 = 0x5A, "GE_F32", None;
    /// `[a b] -> [a + b]` in f64.
    AddF64 = 0x60, "ADD_F64", None;
    /// `[a b] -> [a - b]` in f64.
    SubF64 = 0x61, "SUB_F64", None;
    /// `[a b] -> [a * b]` in f64.
    MulF64 = 0x62, "MUL_F64", None;
    /// `[a b] -> [a / b]` in f64. May trap: DIVISION_BY_ZERO when `b == 0.0`.
    DivF64 = 0x63, "DIV_F64", None;
    /// `[a] -> [-a]` in f64.
    NegF64 = 0x64, "NEG_F64", None;
    /// `[a b] -> [a == b]` f64.
    EqF64 = 0x65, "EQ_F64", None;
    /// `[a b] -> [a != b]` f64.
    NeF64 = 0x66, "NE_F64", None;
    /// `[a b] -> [a < b]` f64.
    LtF64 = 0x67, "LT_F64", None;
    /// `[a b] -> [a <= b]` f64.
    LeF64 = 0x68, "LE_F64", None;
    /// `[a b] -> [a > b]` f64.
    GtF64 = 0x69, "GT_F64", None;
    /// `[a b] -> [a >= b]` f64.
    GeF64 = 0x6A, "GE_F64", None;

    /// `[i] -> [f32(i)]` from signed integer (round to nearest).
    IToF32S = 0x70, "I_TO_F32_S", None;
    /// `[i] -> [f32(i)]` from unsigned integer.
    IToF32U = 0x71, "I_TO_F32_U", None;
    /// `[i] -> [f64(i)]` from signed integer.
    IToF64S = 0x72, "I_TO_F64_S", None;
    /// `[i] -> [f64(i)]` from unsigned integer.
    IToF64U = 0x73, "I_TO_F64_U", None;
    /// `[f32] -> [f64]` (exact).
    F32ToF64 = 0x74, "F32_TO_F64", None;
    /// `[f64] -> [f32]` (round to nearest even; overflow gives infinity).
    F64ToF32 = 0x75, "F64_TO_F32", None;
    /// `[f32] -> [int]`: converts to the integer [`MemType`] operand using the [`RoundMode`]
    /// operand. May trap: NUMERIC_ERROR for NaN, infinities and results outside the target type.
    F32ToInt = 0x76, "F32_TO_INT", TypeMode;
    /// `[f64] -> [int]`: as [`Opcode::F32ToInt`] from f64.
    F64ToInt = 0x77, "F64_TO_INT", TypeMode;

    /// `[] -> []`: jumps to the absolute code offset (same POU, instruction start).
    Jmp = 0x80, "JMP", Target;
    /// `[c] -> []`: jumps when `c == 0`.
    Jz = 0x81, "JZ", Target;
    /// `[c] -> []`: jumps when `c != 0`.
    Jnz = 0x82, "JNZ", Target;
    /// `[args.. base] -> [results..]`: calls POU `idx` with data frame base `base`; the
    /// `arg_cells` cells below `base` become the callee's initial stack, the callee's
    /// `ret_cells` are left on return. May trap: CALL_DEPTH, INVALID_ADDRESS (frame outside data).
    Call = 0x83, "CALL", Index16;
    /// Returns from the current POU (the stack must hold exactly `ret_cells` cells of this
    /// frame, checked by the verifier). Returning from the task's POU ends the cycle.
    Ret = 0x84, "RET", None;
    /// `[args..] -> [results..]`: calls builtin `id` (see [`Builtin`] for cell counts and traps).
    CallBuiltin = 0x85, "CALL_BUILTIN", Index16;
    /// `[i] -> [i]`: traps INDEX_OUT_OF_BOUNDS unless `lo <= i <= hi` (signed).
    ChkIndex = 0x88, "CHK_INDEX", Range;
    /// `[v] -> [v]`: traps SUBRANGE_VIOLATION unless `lo <= v <= hi` (signed).
    ChkRangeS = 0x89, "CHK_RANGE_S", Range;
    /// `[v] -> [v]`: traps SUBRANGE_VIOLATION unless `lo <= v <= hi` (bounds and value unsigned).
    ChkRangeU = 0x8A, "CHK_RANGE_U", Range;
    /// `[base i] -> [base + (i - lo) * stride]` (wrapping): array element address in one
    /// instruction, the fused form of `CHK_INDEX lo hi; PUSH lo; SUB; PUSH stride; MUL; ADD`.
    /// May trap: INDEX_OUT_OF_BOUNDS unless `lo <= i <= hi` (signed).
    Index = 0x8B, "INDEX", IndexSpec;
    /// `[a] -> [a + imm]` wrapping: the fused form of `PUSH_I32 imm; ADD` (and of
    /// `PUSH_I32 -imm; SUB`).
    AddImm = 0x8C, "ADD_IMM", I32;
    /// `[a b] -> []`: jumps when the comparison `cmp` (an integer or float comparison opcode,
    /// e.g. `LT_S`) of `a` and `b` is **false**: the fused form of `<cmp>; JZ target`.
    JumpIfNot = 0x8D, "JUMP_IF_NOT", CompareTarget;
    /// `[a b] -> []`: jumps when the comparison is **true**: the fused form of `<cmp>; JNZ target`.
    JumpIf = 0x8E, "JUMP_IF", CompareTarget;

    /// `[addr] -> [ref]`: a reference to the smallest object (`OBJECTS` record) containing
    /// the `n` (the operand) bytes at `addr`: `addr | (index + 1) << 32` (see "References").
    /// May trap: INVALID_REFERENCE when no object contains them.
    RefMake = 0xB0, "REF_MAKE", U32;
    /// `[ref] -> [addr]`: checks an access of `n` (the operand) bytes through a reference and
    /// leaves its address (the low 32 bits). May trap: INVALID_REFERENCE unless the object
    /// the reference names exists and `start <= addr` and `addr + n <= start + len`.
    RefCheck = 0xB1, "REF_CHECK", U32;
    /// `[ref n] -> [ref']`: pointer arithmetic: adds `n` (wrapping) to the low 32 bits (the
    /// address) and keeps the high 32 bits (the object): `ref' = (ref & !0xFFFF_FFFF) |
    /// (ref as u32).wrapping_add(n as u32)`.
    RefAdd = 0xB2, "REF_ADD", None;
    /// `[a] -> [a]`: a reference to a function-block instance or an interface value must
    /// not be NULL. May trap: INVALID_REFERENCE when `a == 0`.
    ChkNull = 0xB3, "CHK_NULL", None;
    /// `[inst] -> []`: dynamic dispatch (see "Classes and dynamic dispatch"): calls the method
    /// the class of instance `inst` runs for `slot` (the operand), with `inst` as frame base,
    /// as `CALL` does. May trap: INVALID_REFERENCE (NULL instance, class id unreadable or
    /// unknown, no method for the slot), then CALL_DEPTH and INVALID_ADDRESS like `CALL`.
    CallVirt = 0xB4, "CALL_VIRT", Index16;
    /// `[inst] -> [frame]`: the data address of the parameter frame of the method `CALL_VIRT
    /// slot` would call for `inst`. May trap: INVALID_REFERENCE like `CALL_VIRT`.
    VirtFrame = 0xB5, "VIRT_FRAME", Index16;

    /// `[] -> []`: pushes a try frame (handler, stack depth, call depth). On a catchable trap
    /// the VM restores the stack to the recorded depth, pushes the trap code and jumps to
    /// `handler` (same POU; stack depth at handler = depth at TRY_BEGIN + 1). May trap:
    /// STACK_OVERFLOW when the try-frame store is full.
    TryBegin = 0x90, "TRY_BEGIN", Target;
    /// `[] -> []`: pops the innermost try frame (the verifier checks pairing per POU).
    TryEnd = 0x91, "TRY_END", None;
    /// `[] -> []`: raises trap `code` (any catchable trap code).
    Throw = 0x92, "THROW", TrapCode;
    /// `[code] -> []`: re-raises a caught trap code; 0 does nothing (no exception); a code
    /// that is not a catchable trap raises NUMERIC_ERROR.
    Rethrow = 0x93, "RETHROW", None;

    // ---- Superinstructions (0xC0..=0xDF): each is exactly the plain sequence named in its
    // description (same result, same traps, checked in the same order), counted as one
    // instruction by the watchdog, and never needs more operand stack than that sequence.
    // The compiler and the builder's fusion produce them; the VM, the reference model and
    // the native tier implement each one. Element addresses are computed as INDEX does
    // (wrapping 64-bit arithmetic, then checked against data memory when accessed).

    /// `[i] -> [base + off + (i - lo) * stride]`: the address of element `i` of a
    /// frame-relative array: `LEA_REL off; SWAP; INDEX lo hi stride` (the index is pushed
    /// first). May trap: INDEX_OUT_OF_BOUNDS unless `lo <= i <= hi` (signed).
    ElemRel = 0xC0, "ELEM_REL", AddrIndex;
    /// `[i] -> [addr + (i - lo) * stride]`: the address of element `i` of an array at
    /// absolute address `addr`: `PUSH_U32 addr; SWAP; INDEX lo hi stride`. May trap:
    /// INDEX_OUT_OF_BOUNDS.
    ElemAbs = 0xC1, "ELEM_ABS", AddrIndex;
    /// `[i] -> [v]`: loads element `i` of a frame-relative array: `ELEM_REL off lo hi stride;
    /// LD_IND ty 0`. May trap: INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    LdElemRel = 0xC2, "LD_ELEM_REL", TypeAddrIndex;
    /// `[i] -> [v]`: `ELEM_ABS addr lo hi stride; LD_IND ty 0`. May trap:
    /// INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    LdElemAbs = 0xC3, "LD_ELEM_ABS", TypeAddrIndex;
    /// `[i v] -> []`: stores `v` into element `i` of a frame-relative array: `SWAP; ELEM_REL
    /// off lo hi stride; SWAP; ST_IND ty 0`. May trap: INDEX_OUT_OF_BOUNDS, then
    /// INVALID_ADDRESS.
    StElemRel = 0xC4, "ST_ELEM_REL", TypeAddrIndex;
    /// `[i v] -> []`: `SWAP; ELEM_ABS addr lo hi stride; SWAP; ST_IND ty 0`. May trap:
    /// INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    StElemAbs = 0xC5, "ST_ELEM_ABS", TypeAddrIndex;
    /// `[] -> []`: adds `imm` to the integer variable at `base + off`: `LD_REL ty off; ADD_IMM
    /// imm; ST_REL ty off` (wrapping, the store truncates to the type). The verifier checks
    /// the type is an integer type and the variable lies in the frame, as for LD_REL.
    IncRel = 0xC6, "INC_REL", TypeAddrImm;
    /// `[] -> []`: `LD_ABS ty addr; ADD_IMM imm; ST_ABS ty addr` (integer type; the verifier
    /// checks the address as for LD_ABS).
    IncAbs = 0xC7, "INC_ABS", TypeAddrImm;
    /// `[a b] -> [if cmp(a, b) { b } else { a }]` for a comparison opcode `cmp`: MAX is
    /// `SEL_IF LT_x`, MIN is `SEL_IF GT_x` (NaN compares false: the first operand is kept).
    SelIf = 0xC8, "SEL_IF", Compare;
    /// `[a] -> []`: jumps to `target` when `cmp(a, imm)` holds, `imm` sign-extended to a cell:
    /// `PUSH_I32 imm; JUMP_IF cmp target`.
    JumpIfImm = 0xC9, "JUMP_IF_IMM", CompareImmTarget;
    /// `[a] -> []`: jumps when `cmp(a, imm)` does **not** hold: `PUSH_I32 imm; JUMP_IF_NOT cmp
    /// target`.
    JumpIfNotImm = 0xCA, "JUMP_IF_NOT_IMM", CompareImmTarget;
    /// `[a] -> [a op imm]`: a binary operator `op` (see [`Opcode::is_binary`]) with an
    /// immediate right operand sign-extended to a cell: `PUSH_I32 imm; op`. May trap as `op`
    /// (DIVISION_BY_ZERO for a division by 0).
    OpImm = 0xCB, "OP_IMM", OpImm;
    /// `[a] -> [a op v]`: a binary operator whose right operand is the frame variable at
    /// `base + off`: `LD_REL ty off; op` (the verifier checks the variable as for LD_REL).
    /// May trap as `op`.
    OpRel = 0xCC, "OP_REL", OpTypeAddr;
    /// `[a] -> [a op v]`: `LD_ABS ty addr; op` (the verifier checks the address as for
    /// LD_ABS). May trap as `op`.
    OpAbs = 0xCD, "OP_ABS", OpTypeAddr;
    /// `[] -> [a op b]`: a binary operator on two frame variables, `a` the `ty1` variable at
    /// `base + off1`, `b` the `ty2` one at `base + off2`: `LD_REL ty1 off1; LD_REL ty2 off2;
    /// op` (the verifier checks both as for LD_REL). May trap: STACK_OVERFLOW (checked
    /// first, as the first load would), then as `op`.
    OpRelRel = 0xCE, "OP_REL_REL", OpTypeAddr2;
    /// `[] -> []`: jumps to `target` when `cmp(v, imm)` holds for the `ty` frame variable `v`
    /// at `base + off`: `LD_REL ty off; JUMP_IF_IMM cmp imm target`.
    JumpIfRelImm = 0xCF, "JUMP_IF_REL_IMM", CompareTypeAddrImmTarget;
    /// `[] -> []`: jumps when `cmp(v, imm)` does **not** hold: `LD_REL ty off;
    /// JUMP_IF_NOT_IMM cmp imm target`.
    JumpIfNotRelImm = 0xD0, "JUMP_IF_NOT_REL_IMM", CompareTypeAddrImmTarget;
    /// `[] -> [address]`: ELEM_REL with the index read from the `ity` frame variable at
    /// `base + ioff`: `LD_REL ity ioff; ELEM_REL off lo hi stride` (the verifier checks the
    /// index variable as for LD_REL). May trap: STACK_OVERFLOW (checked first, as the load
    /// would), then INDEX_OUT_OF_BOUNDS.
    ElemRelAt = 0xD1, "ELEM_REL_AT", AddrIndexAt;
    /// `[] -> [address]`: `LD_REL ity ioff; ELEM_ABS addr lo hi stride`. May trap:
    /// STACK_OVERFLOW, then INDEX_OUT_OF_BOUNDS.
    ElemAbsAt = 0xD2, "ELEM_ABS_AT", AddrIndexAt;
    /// `[] -> [v]`: `LD_REL ity ioff; LD_ELEM_REL ty off lo hi stride`. May trap:
    /// STACK_OVERFLOW, then INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    LdElemRelAt = 0xD3, "LD_ELEM_REL_AT", TypeAddrIndexAt;
    /// `[] -> [v]`: `LD_REL ity ioff; LD_ELEM_ABS ty addr lo hi stride`. May trap:
    /// STACK_OVERFLOW, then INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    LdElemAbsAt = 0xD4, "LD_ELEM_ABS_AT", TypeAddrIndexAt;
    /// `[v] -> []`: `LD_REL ity ioff; SWAP; ST_ELEM_REL ty off lo hi stride` (the index is
    /// read when the store runs). May trap: INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    StElemRelAt = 0xD5, "ST_ELEM_REL_AT", TypeAddrIndexAt;
    /// `[v] -> []`: `LD_REL ity ioff; SWAP; ST_ELEM_ABS ty addr lo hi stride`. May trap:
    /// INDEX_OUT_OF_BOUNDS, then INVALID_ADDRESS.
    StElemAbsAt = 0xD6, "ST_ELEM_ABS_AT", TypeAddrIndexAt;
}

impl Opcode {
    /// True for the binary operators `[a b] -> [a op b]` without operands (integer and float
    /// arithmetic, bit operations, shifts and comparisons) that OP_IMM, OP_REL, OP_ABS and
    /// OP_REL_REL accept.
    pub const fn is_binary(self) -> bool {
        use Opcode::*;
        self.is_comparison()
            || matches!(
                self,
                Add | Sub
                    | Mul
                    | DivS
                    | DivU
                    | ModS
                    | ModU
                    | And
                    | Or
                    | Xor
                    | Shl
                    | ShrU
                    | ShrS
                    | AddF32
                    | SubF32
                    | MulF32
                    | DivF32
                    | AddF64
                    | SubF64
                    | MulF64
                    | DivF64
            )
    }

    /// True for the comparison opcodes (integer and float) that JUMP_IF/JUMP_IF_NOT accept.
    pub const fn is_comparison(self) -> bool {
        use Opcode::*;
        matches!(
            self,
            Eq | Ne
                | LtS
                | LeS
                | GtS
                | GeS
                | LtU
                | LeU
                | GtU
                | GeU
                | EqF32
                | NeF32
                | LtF32
                | LeF32
                | GtF32
                | GeF32
                | EqF64
                | NeF64
                | LtF64
                | LeF64
                | GtF64
                | GeF64
        )
    }
}

/// The bits every REAL arithmetic result that is NaN has (a quiet NaN).
pub const CANONICAL_NAN_F32: u32 = 0x7FC0_0000;
/// The bits every LREAL arithmetic result that is NaN has (a quiet NaN).
pub const CANONICAL_NAN_F64: u64 = 0x7FF8_0000_0000_0000;

/// The cell of a REAL result of `+ - * /` (`ADD_F32` .. `DIV_F32`, also inside the fused
/// operators): its bits, a NaN as [`CANONICAL_NAN_F32`]. Which NaN operand's payload the
/// hardware passes on depends on the machine code's operand order, which the compiler is
/// free to choose; a canonical NaN keeps every execution tier bit-identical.
#[inline(always)]
pub fn real_result(v: f32) -> u64 {
    if v.is_nan() {
        CANONICAL_NAN_F32 as u64
    } else {
        v.to_bits() as u64
    }
}

/// The cell of an LREAL result of `+ - * /`: its bits, a NaN as [`CANONICAL_NAN_F64`].
#[inline(always)]
pub fn lreal_result(v: f64) -> u64 {
    if v.is_nan() {
        CANONICAL_NAN_F64
    } else {
        v.to_bits()
    }
}

/// Evaluates comparison opcode `cmp` on two cells (`false` for non-comparison opcodes).
#[inline(always)]
pub fn compare(cmp: Opcode, a: u64, b: u64) -> bool {
    use Opcode::*;
    let (sa, sb) = (a as i64, b as i64);
    let (fa, fb) = (f32::from_bits(a as u32), f32::from_bits(b as u32));
    let (da, db) = (f64::from_bits(a), f64::from_bits(b));
    match cmp {
        Eq => a == b,
        Ne => a != b,
        LtS => sa < sb,
        LeS => sa <= sb,
        GtS => sa > sb,
        GeS => sa >= sb,
        LtU => a < b,
        LeU => a <= b,
        GtU => a > b,
        GeU => a >= b,
        EqF32 => fa == fb,
        NeF32 => fa != fb,
        LtF32 => fa < fb,
        LeF32 => fa <= fb,
        GtF32 => fa > fb,
        GeF32 => fa >= fb,
        EqF64 => da == db,
        NeF64 => da != db,
        LtF64 => da < db,
        LeF64 => da <= db,
        GtF64 => da > db,
        GeF64 => da >= db,
        _ => false,
    }
}

codes::code_enum! {
    /// Typed data-memory access width and extension rule for loads/stores and float->int targets.
    pub enum MemType: u8 {
        /// 8-bit signed (SINT).
        I8 = 0 => "I8",
        /// 16-bit signed (INT).
        I16 = 1 => "I16",
        /// 32-bit signed (DINT).
        I32 = 2 => "I32",
        /// 64-bit signed (LINT, TIME).
        I64 = 3 => "I64",
        /// 8-bit unsigned (USINT, BYTE, BOOL).
        U8 = 4 => "U8",
        /// 16-bit unsigned (UINT, WORD).
        U16 = 5 => "U16",
        /// 32-bit unsigned (UDINT, DWORD).
        U32 = 6 => "U32",
        /// 64-bit unsigned (ULINT, LWORD).
        U64 = 7 => "U64",
        /// REAL (f32 bits, zero-extended into the cell).
        F32 = 8 => "F32",
        /// LREAL (f64 bits).
        F64 = 9 => "F64",
    }
}

/// Each [`MemType`]'s code byte as a constant, for `match`ing on raw operand bytes.
pub mod mem_type_byte {
    use super::MemType;
    /// [`MemType::I8`].
    pub const I8: u8 = MemType::I8 as u8;
    /// [`MemType::I16`].
    pub const I16: u8 = MemType::I16 as u8;
    /// [`MemType::I32`].
    pub const I32: u8 = MemType::I32 as u8;
    /// [`MemType::I64`].
    pub const I64: u8 = MemType::I64 as u8;
    /// [`MemType::U8`].
    pub const U8: u8 = MemType::U8 as u8;
    /// [`MemType::U16`].
    pub const U16: u8 = MemType::U16 as u8;
    /// [`MemType::U32`].
    pub const U32: u8 = MemType::U32 as u8;
    /// [`MemType::U64`].
    pub const U64: u8 = MemType::U64 as u8;
    /// [`MemType::F32`].
    pub const F32: u8 = MemType::F32 as u8;
    /// [`MemType::F64`].
    pub const F64: u8 = MemType::F64 as u8;
}

impl MemType {
    /// Every type, in numeric order.
    /// Width in bytes.
    #[inline(always)]
    pub const fn width(self) -> usize {
        match self {
            MemType::I8 | MemType::U8 => 1,
            MemType::I16 | MemType::U16 => 2,
            MemType::I32 | MemType::U32 | MemType::F32 => 4,
            MemType::I64 | MemType::U64 | MemType::F64 => 8,
        }
    }

    /// True for the eight integer types (valid float->int conversion targets).
    pub const fn is_integer(self) -> bool {
        !matches!(self, MemType::F32 | MemType::F64)
    }

    /// Converts little-endian bytes (exactly `width()` of them) into a cell, sign- or
    /// zero-extending as the type demands.
    #[inline(always)]
    pub fn cell_from_le(self, bytes: &[u8]) -> u64 {
        fn get<const N: usize>(bytes: &[u8]) -> [u8; N] {
            // Fixed-size copy (no memcpy call); a short slice reads as zero-padded.
            let mut raw = [0u8; N];
            match bytes.get(..N) {
                Some(exact) => raw.copy_from_slice(exact),
                None => raw[..bytes.len()].copy_from_slice(bytes),
            }
            raw
        }
        match self {
            MemType::I8 => get::<1>(bytes)[0] as i8 as i64 as u64,
            MemType::U8 => get::<1>(bytes)[0] as u64,
            MemType::I16 => i16::from_le_bytes(get(bytes)) as i64 as u64,
            MemType::U16 => u16::from_le_bytes(get(bytes)) as u64,
            MemType::I32 => i32::from_le_bytes(get(bytes)) as i64 as u64,
            MemType::U32 | MemType::F32 => u32::from_le_bytes(get(bytes)) as u64,
            MemType::I64 | MemType::U64 | MemType::F64 => u64::from_le_bytes(get(bytes)),
        }
    }

    /// The low `width()` bytes of a cell, little-endian (the store truncation).
    pub fn cell_to_le(self, cell: u64) -> [u8; 8] {
        cell.to_le_bytes()
    }
}

codes::code_enum! {
    /// The date/time type a `kind` argument of the date/time builtins means.
    pub enum TimeKind: u8 {
        /// TIME (a duration).
        Time = 0 => "TIME",
        /// LTIME.
        LTime = 1 => "LTIME",
        /// DATE.
        Date = 2 => "DATE",
        /// LDATE.
        LDate = 3 => "LDATE",
        /// TIME_OF_DAY.
        Tod = 4 => "TOD",
        /// LTIME_OF_DAY.
        LTod = 5 => "LTOD",
        /// DATE_AND_TIME.
        Dt = 6 => "DT",
        /// LDATE_AND_TIME.
        LDt = 7 => "LDT",
    }
}

impl TimeKind {
    /// The literal prefix printed by DATE_TIME_TO_STRING (`T#`, `LD#`, ...).
    pub const fn prefix(self) -> &'static str {
        match self {
            TimeKind::Time => "T#",
            TimeKind::LTime => "LT#",
            TimeKind::Date => "D#",
            TimeKind::LDate => "LD#",
            TimeKind::Tod => "TOD#",
            TimeKind::LTod => "LTOD#",
            TimeKind::Dt => "DT#",
            TimeKind::LDt => "LDT#",
        }
    }
}

codes::code_enum! {
    /// Rounding rule of float->integer conversions.
    pub enum RoundMode: u8 {
        /// Toward zero (IEC `TRUNC`).
        Truncate = 0 => "truncate",
        /// To nearest, ties away from zero (IEC `REAL_TO_INT`: 2.5 -> 3, -2.5 -> -3).
        NearestTiesAway = 1 => "nearest_ties_away",
    }
}

codes::code_enum! {
    /// A run-time error detected by the VM. Codes are stable (they are the values an
    /// `e : __EXCEPTION` variable receives); 0 means "no exception".
    pub enum Trap: u8 {
        /// Integer (or float) division or modulo by zero.
        DivisionByZero = 1 => "DIVISION_BY_ZERO",
        /// CHK_INDEX failed: array index outside its declared bounds.
        IndexOutOfBounds = 2 => "INDEX_OUT_OF_BOUNDS",
        /// CHK_RANGE_* failed: value outside a subrange type.
        SubrangeViolation = 3 => "SUBRANGE_VIOLATION",
        /// The cycle's instruction budget is exhausted. Not catchable: it always ends the cycle.
        Watchdog = 4 => "WATCHDOG",
        /// CALL would exceed the call-frame capacity.
        CallDepth = 5 => "CALL_DEPTH",
        /// The operand stack (or try-frame store) is full.
        StackOverflow = 6 => "STACK_OVERFLOW",
        /// Math domain error: SQRT of a negative, LN/LOG of <= 0, ASIN/ACOS outside [-1, 1],
        /// EXPT of 0 to a negative or of a negative to a non-integer power, float->integer
        /// conversion of NaN/infinity/out-of-range, STRING_TO_* of a malformed string.
        NumericError = 7 => "NUMERIC_ERROR",
        /// A dynamic data address (indirect access, CALL frame, string operand) is outside data memory.
        InvalidAddress = 8 => "INVALID_ADDRESS",
        /// The task's time deadline passed while it ran (the runtime's clock check, see
        /// `Machine::run_cycle_until`). Not catchable, like WATCHDOG.
        Deadline = 9 => "DEADLINE",
        /// A dereference through NULL or through a reference outside the variable it was
        /// taken from (`REF_MAKE`, `REF_CHECK`), or a method call through a NULL instance, an
        /// instance of unknown class or a class without that method (`CHK_NULL`,
        /// `CALL_VIRT`, `VIRT_FRAME`).
        InvalidReference = 10 => "INVALID_REFERENCE",
    }
}

impl Trap {
    /// Whether a try frame can catch this trap (everything but WATCHDOG and DEADLINE, which
    /// must terminate the cycle so that an endless loop inside `__TRY` cannot hang the task).
    pub const fn is_catchable(self) -> bool {
        !matches!(self, Trap::Watchdog | Trap::Deadline)
    }
}

macro_rules! builtins {
    ($( $(#[doc = $doc:literal])* $name:ident = $val:literal, $mnemonic:literal, $args:literal, $results:literal; )*) => {
        /// Standard functions reachable through `CALL_BUILTIN id`. Argument cells are pushed
        /// left to right (first argument deepest); `args()`/`results()` give the stack effect.
        ///
        /// String arguments are **addresses** of string variables in data memory, laid out as
        /// `max_len: u16 LE, cur_len: u16 LE, bytes[max_len]` (so a `STRING[n]` occupies
        /// at least `4 + n` bytes and its initial value must have `max_len = n`). Results
        /// written to a `dst` string are truncated to its `max_len`, and a result shorter than
        /// `max_len` is followed by a NUL byte (CODESYS code reads strings through pointers up
        /// to that terminator); `dst` may alias an argument. Length and
        /// position arguments are clamped (negative counts as 0, positions beyond the string
        /// to its end) instead of trapping; positions are 1-based as in IEC.
        #[repr(u16)]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum Builtin {
            $( $(#[doc = $doc])* $name = $val, )*
        }

        impl Builtin {
            /// Every builtin.
            pub const ALL: &'static [Builtin] = &[$(Builtin::$name),*];

            /// Decodes a builtin id.
            pub const fn from_u16(id: u16) -> Option<Builtin> {
                match id {
                    $( $val => Some(Builtin::$name), )*
                    _ => None,
                }
            }

            /// Number of argument cells popped.
            pub const fn args(self) -> usize {
                match self { $( Builtin::$name => $args, )* }
            }

            /// Number of result cells pushed.
            pub const fn results(self) -> usize {
                match self { $( Builtin::$name => $results, )* }
            }

            /// The IEC-ish name.
            pub const fn mnemonic(self) -> &'static str {
                match self { $( Builtin::$name => $mnemonic, )* }
            }
        }
    };
}

builtins! {
    /// LREAL SQRT. NUMERIC_ERROR for x < 0.
    SqrtF64 = 1, "SQRT_LREAL", 1, 1;
    /// LREAL LN. NUMERIC_ERROR for x <= 0.
    LnF64 = 2, "LN_LREAL", 1, 1;
    /// LREAL LOG (base 10). NUMERIC_ERROR for x <= 0.
    LogF64 = 3, "LOG_LREAL", 1, 1;
    /// LREAL EXP (overflow gives +inf).
    ExpF64 = 4, "EXP_LREAL", 1, 1;
    /// LREAL SIN (radians).
    SinF64 = 5, "SIN_LREAL", 1, 1;
    /// LREAL COS.
    CosF64 = 6, "COS_LREAL", 1, 1;
    /// LREAL TAN.
    TanF64 = 7, "TAN_LREAL", 1, 1;
    /// LREAL ASIN. NUMERIC_ERROR outside [-1, 1].
    AsinF64 = 8, "ASIN_LREAL", 1, 1;
    /// LREAL ACOS. NUMERIC_ERROR outside [-1, 1].
    AcosF64 = 9, "ACOS_LREAL", 1, 1;
    /// LREAL ATAN.
    AtanF64 = 10, "ATAN_LREAL", 1, 1;
    /// `[base exp] -> [base ** exp]` LREAL. NUMERIC_ERROR for 0 ** negative and negative ** non-integer.
    ExptF64 = 11, "EXPT_LREAL", 2, 1;
    /// LREAL ABS.
    AbsF64 = 12, "ABS_LREAL", 1, 1;
    /// REAL SQRT (computed in f64, rounded to f32). NUMERIC_ERROR for x < 0.
    SqrtF32 = 33, "SQRT_REAL", 1, 1;
    /// REAL LN.
    LnF32 = 34, "LN_REAL", 1, 1;
    /// REAL LOG.
    LogF32 = 35, "LOG_REAL", 1, 1;
    /// REAL EXP.
    ExpF32 = 36, "EXP_REAL", 1, 1;
    /// REAL SIN.
    SinF32 = 37, "SIN_REAL", 1, 1;
    /// REAL COS.
    CosF32 = 38, "COS_REAL", 1, 1;
    /// REAL TAN.
    TanF32 = 39, "TAN_REAL", 1, 1;
    /// REAL ASIN.
    AsinF32 = 40, "ASIN_REAL", 1, 1;
    /// REAL ACOS.
    AcosF32 = 41, "ACOS_REAL", 1, 1;
    /// REAL ATAN.
    AtanF32 = 42, "ATAN_REAL", 1, 1;
    /// REAL EXPT.
    ExptF32 = 43, "EXPT_REAL", 2, 1;
    /// REAL ABS.
    AbsF32 = 44, "ABS_REAL", 1, 1;
    /// `[y x] -> [atan2(y, x)]` LREAL: the angle of the point (x, y) in [-pi, pi].
    Atan2F64 = 128, "ATAN2_LREAL", 2, 1;
    /// `[y x] -> [atan2(y, x)]` REAL (computed in f64, rounded to f32).
    Atan2F32 = 129, "ATAN2_REAL", 2, 1;

    // Date and time. Every date/time type is an `i64` count of nanoseconds: TIME/LTIME a
    // duration, TOD/LTOD since midnight, DATE/LDATE and DT/LDT since 1970-01-01 00:00
    // (proleptic Gregorian calendar, no leap seconds). `kind` arguments are [`TimeKind`] codes.

    /// `[year month day] -> [date]`: IEC CONCAT_DATE. NUMERIC_ERROR unless month is 1..=12,
    /// day 1..=days of that month and the date lies in 1678..=2261 (the `i64` range).
    DateFromParts = 130, "CONCAT_DATE", 3, 1;
    /// `[date] -> [year << 16 | month << 8 | day]` (year signed): IEC SPLIT_DATE packed in
    /// one cell; a value that is not midnight counts as its day.
    DateSplit = 131, "SPLIT_DATE", 1, 1;
    /// `[dt] -> [date]`: the midnight starting the day of `dt` (rounds toward minus
    /// infinity). NUMERIC_ERROR when that midnight lies before the `i64` range.
    DateOf = 132, "DT_TO_DATE", 1, 1;
    /// `[dt] -> [tod]`: the time since that midnight, `0 <= tod < 24 h` (also wraps a TOD
    /// that left its day after TOD +/- TIME).
    TodOf = 133, "DT_TO_TOD", 1, 1;
    /// `[date] -> [weekday]`: IEC DAY_OF_WEEK, 0 = Sunday .. 6 = Saturday.
    DayOfWeek = 134, "DAY_OF_WEEK", 1, 1;
    /// `[dst v kind] -> []`: the IEC literal of a date/time value: `T#1h2s`, `LT#5ns`,
    /// `D#2024-02-29`, `TOD#13:05:00.25`, `DT#2024-02-29-13:05:00` (`LD#`, `LTOD#`, `LDT#`
    /// for the long types; fractions of a second only when not zero).
    StrFromDateTime = 135, "DATE_TIME_TO_STRING", 3, 0;
    /// `[s kind] -> [v]`: parses a date/time literal of that kind, with or without its
    /// prefix (`'D#2024-02-29'`, `'2024-02-29'`, `'12:30'`, `'T#1s500ms'`, `'1.5s'`).
    /// After trimming blanks and an optional prefix of the kind's family (case-insensitive:
    /// `T#`, `TIME#`, `LT#`, `LTIME#`; `D#`, `DATE#`, `LD#`, `LDATE#`; `TOD#`,
    /// `TIME_OF_DAY#`, `LTOD#`, `LTIME_OF_DAY#`; `DT#`, `DATE_AND_TIME#`, `LDT#`,
    /// `LDATE_AND_TIME#`) the text is: a date `Y-M-D`; a time of day `H:M`, `H:M:S` or
    /// `H:M:S.F` (H < 24, M and S < 60, F one or more digits, cut to nanoseconds); a date
    /// and time `Y-M-D-` then a time of day; a duration `[-]` then components `N[.F]unit`
    /// (unit `d h m s ms us ns`, any case; `_` between components; fractions rounded to the
    /// nearest nanosecond, halves away from zero). Numbers are 1 to 18 digits. NUMERIC_ERROR when
    /// malformed, not a valid date or time of day, or outside the `i64` range.
    StrToDateTime = 136, "STRING_TO_DATE_TIME", 2, 1;
    /// `[hour minute second millisecond] -> [tod]`: IEC CONCAT_TOD. NUMERIC_ERROR unless
    /// hour is 0..=23, minute and second 0..=59, millisecond 0..=999.
    TodFromParts = 137, "CONCAT_TOD", 4, 1;

    // WSTRING: the STRING builtins for strings of UTF-16 code units, laid out as
    // `max_len: u16 LE, cur_len: u16 LE, units[max_len]: u16 LE` (a `WSTRING[n]` occupies
    // `4 + 2n` bytes). Lengths and positions count code units; the same clamping rules as
    // for STRING; results are at most [`crate::builtins::MAX_STRING_LEN`] units.

    /// `[s] -> [len]`.
    WStrLen = 140, "LEN_WSTRING", 1, 1;
    /// `[dst src] -> []`.
    WStrAssign = 141, "WSTRING_ASSIGN", 2, 0;
    /// `[dst a b] -> []`.
    WStrConcat = 142, "CONCAT_WSTRING", 3, 0;
    /// `[dst a n] -> []`.
    WStrLeft = 143, "LEFT_WSTRING", 3, 0;
    /// `[dst a n] -> []`.
    WStrRight = 144, "RIGHT_WSTRING", 3, 0;
    /// `[dst a n p] -> []`.
    WStrMid = 145, "MID_WSTRING", 4, 0;
    /// `[dst a b p] -> []`.
    WStrInsert = 146, "INSERT_WSTRING", 4, 0;
    /// `[dst a n p] -> []`.
    WStrDelete = 147, "DELETE_WSTRING", 4, 0;
    /// `[dst a b n p] -> []`.
    WStrReplace = 148, "REPLACE_WSTRING", 5, 0;
    /// `[a b] -> [pos]`.
    WStrFind = 149, "FIND_WSTRING", 2, 1;
    /// `[a b] -> [-1|0|1]`: lexicographic comparison of the code units.
    WStrCompare = 150, "WSTRING_COMPARE", 2, 1;
    /// `[dst s] -> []`: the WSTRING `dst` from the STRING `s`, whose bytes are read as
    /// UTF-8 (a byte that is not part of a valid UTF-8 sequence is the character of that
    /// code, Latin-1); characters beyond U+FFFF take two units (a surrogate pair).
    WStrFromStr = 151, "STRING_TO_WSTRING", 2, 0;
    /// `[dst ws] -> []`: the STRING `dst` from the WSTRING `ws`, in UTF-8 (an unpaired
    /// surrogate is U+FFFD), cut after the last whole character that fits.
    StrFromWStr = 152, "WSTRING_TO_STRING", 2, 0;

    /// `[s] -> [len]`.
    StrLen = 100, "LEN", 1, 1;
    /// `[dst src] -> []`: string assignment (truncating).
    StrAssign = 101, "STRING_ASSIGN", 2, 0;
    /// `[dst a b] -> []`: dst := CONCAT(a, b).
    StrConcat = 102, "CONCAT", 3, 0;
    /// `[dst a n] -> []`: dst := LEFT(a, n).
    StrLeft = 103, "LEFT", 3, 0;
    /// `[dst a n] -> []`: dst := RIGHT(a, n).
    StrRight = 104, "RIGHT", 3, 0;
    /// `[dst a n p] -> []`: dst := MID(a, n, p) (n characters from position p).
    StrMid = 105, "MID", 4, 0;
    /// `[dst a b p] -> []`: dst := INSERT(a, b, p) (b inserted after position p).
    StrInsert = 106, "INSERT", 4, 0;
    /// `[dst a n p] -> []`: dst := DELETE(a, n, p) (n characters deleted from position p).
    StrDelete = 107, "DELETE", 4, 0;
    /// `[dst a b n p] -> []`: dst := REPLACE(a, b, n, p) (n characters from p replaced by b).
    StrReplace = 108, "REPLACE", 5, 0;
    /// `[a b] -> [pos]`: FIND(a, b), 1-based position of the first b in a, 0 if none.
    StrFind = 109, "FIND", 2, 1;
    /// `[a b] -> [-1|0|1]`: lexicographic byte comparison of a and b.
    StrCompare = 110, "STRING_COMPARE", 2, 1;
    /// `[dst v] -> []`: decimal text of a signed integer.
    StrFromI64 = 111, "INT_TO_STRING", 2, 0;
    /// `[dst v] -> []`: decimal text of an unsigned integer.
    StrFromU64 = 112, "UINT_TO_STRING", 2, 0;
    /// `[dst v] -> []`: shortest round-trip text of a REAL, always with a '.' (e.g. `4.0`).
    StrFromF32 = 113, "REAL_TO_STRING", 2, 0;
    /// `[dst v] -> []`: shortest round-trip text of an LREAL.
    StrFromF64 = 114, "LREAL_TO_STRING", 2, 0;
    /// `[dst v] -> []`: `TRUE` / `FALSE`.
    StrFromBool = 115, "BOOL_TO_STRING", 2, 0;
    /// `[dst v] -> []`: TIME literal such as `T#1s500ms` (`T#0s` for zero).
    StrFromTime = 116, "TIME_TO_STRING", 2, 0;
    /// `[s] -> [v]`: parses a decimal integer (optional sign, surrounding spaces allowed).
    /// NUMERIC_ERROR when malformed or outside i64.
    StrToI64 = 117, "STRING_TO_INT", 1, 1;
    /// `[s] -> [f64]`: parses a real number. NUMERIC_ERROR when malformed.
    StrToF64 = 118, "STRING_TO_LREAL", 1, 1;
    /// `[s] -> []`: takes the text's length from its terminator: `cur_len` becomes the index
    /// of the first NUL among the `max_len` text bytes (`max_len` when there is none), as after
    /// CODESYS code wrote the string's bytes through a pointer. Every builtin writing a string
    /// (and the monitor's write) leaves a NUL right after a text shorter than `max_len`, so
    /// the length survives this whatever wrote the string last. INVALID_ADDRESS when the
    /// `4 + max_len` bytes are not all in data memory.
    StrSync = 193, "STRING_SYNC", 1, 0;
}

impl Builtin {
    /// The numeric builtins ([`crate::fmath`]: ids below 100 and the ATAN2 pair), which the
    /// reference model shares with the VM; it re-implements every other builtin.
    pub const fn is_math(self) -> bool {
        (self as u16) < 100 || matches!(self, Builtin::Atan2F64 | Builtin::Atan2F32)
    }
}

/// Reads `N` bytes at `at` (caller guarantees bounds; one bounds check).
#[inline(always)]
fn read_array<const N: usize>(bytes: &[u8], at: usize) -> [u8; N] {
    let mut raw = [0u8; N];
    raw.copy_from_slice(&bytes[at..at + N]);
    raw
}

/// Reads a little-endian `u16` at `at` (caller guarantees bounds).
#[inline(always)]
pub(crate) fn read_u16(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(read_array(bytes, at))
}

/// Reads a little-endian `u32` at `at` (caller guarantees bounds).
#[inline(always)]
pub(crate) fn read_u32(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(read_array(bytes, at))
}

/// Reads a little-endian `u64` at `at` (caller guarantees bounds).
#[inline(always)]
pub(crate) fn read_u64(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(read_array(bytes, at))
}

/// Fixed stack effect `(pops, pushes)` of an opcode; `None` for CALL, RET and CALL_BUILTIN,
/// whose effect depends on the POU/builtin table.
pub const fn stack_effect(op: Opcode) -> Option<(u32, u32)> {
    use Opcode::*;
    Some(match op {
        Nop | Jmp | TryBegin | TryEnd | Throw => (0, 0),
        PushI32 | PushU32 | PushI64 | PushConst | LdAbs | LdRel | LeaRel | Now => (0, 1),
        Drop | StAbs | StRel | Jz | Jnz | Rethrow => (1, 0),
        Dup => (1, 2),
        Swap => (2, 2),
        Over => (2, 3),
        LdInd | Neg | AbsS | Not | NotBool | Sext | Zext | NegF32 | NegF64 | IToF32S | IToF32U
        | IToF64S | IToF64U | F32ToF64 | F64ToF32 | F32ToInt | F64ToInt | ChkIndex | ChkRangeS
        | ChkRangeU => (1, 1),
        StInd | Copy => (2, 0),
        Index => (2, 1),
        AddImm => (1, 1),
        JumpIf | JumpIfNot => (2, 0),
        ElemRel | ElemAbs | LdElemRel | LdElemAbs | OpImm | OpRel | OpAbs => (1, 1),
        StElemRel | StElemAbs => (2, 0),
        IncRel | IncAbs => (0, 0),
        SelIf => (2, 1),
        JumpIfImm | JumpIfNotImm => (1, 0),
        OpRelRel | ElemRelAt | ElemAbsAt | LdElemRelAt | LdElemAbsAt => (0, 1),
        StElemRelAt | StElemAbsAt => (1, 0),
        JumpIfRelImm | JumpIfNotRelImm => (0, 0),
        RefMake | RefCheck | ChkNull | VirtFrame => (1, 1),
        RefAdd => (2, 1),
        CallVirt => (1, 0),
        Add | Sub | Mul | DivS | DivU | ModS | ModU | And | Or | Xor | Shl | ShrU | ShrS | Rol
        | Ror | Eq | Ne | LtS | LeS | GtS | GeS | LtU | LeU | GtU | GeU | AddF32 | SubF32
        | MulF32 | DivF32 | EqF32 | NeF32 | LtF32 | LeF32 | GtF32 | GeF32 | AddF64 | SubF64
        | MulF64 | DivF64 | EqF64 | NeF64 | LtF64 | LeF64 | GtF64 | GeF64 => (2, 1),
        Sel => (3, 1),
        Call | Ret | CallBuiltin => return None,
    })
}

/// One decoded instruction (for disassemblers, monitors and fault reports).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Instruction<'c> {
    /// Code offset.
    pub offset: u32,
    /// Opcode.
    pub op: Opcode,
    /// The immediate bytes (`op.operands().len()` of them).
    pub immediates: &'c [u8],
}

/// Decodes the instruction at `offset`; `None` for an unknown opcode or truncated operands.
pub fn decode(code: &[u8], offset: usize) -> Option<Instruction<'_>> {
    let op = Opcode::from_u8(*code.get(offset)?)?;
    let immediates = code.get(offset + 1..offset + op.size())?;
    Some(Instruction {
        offset: offset as u32,
        op,
        immediates,
    })
}

/// Iterates over the instructions of `code` from offset 0, stopping at the first undecodable
/// byte.
pub fn instructions(code: &[u8]) -> impl Iterator<Item = Instruction<'_>> {
    let mut offset = 0usize;
    core::iter::from_fn(move || {
        let insn = decode(code, offset)?;
        offset += insn.op.size();
        Some(insn)
    })
}

impl core::fmt::Display for Instruction<'_> {
    /// Assembler syntax, e.g. `LD_ABS I32 100`, `JZ @42`, `CALL_BUILTIN SQRT_LREAL`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let imm = self.immediates;
        f.write_str(self.op.mnemonic())?;
        let ty = |b: u8| MemType::from_code(b).map_or("?", |t| t.name());
        let opname = |b: u8| Opcode::from_u8(b).map_or("?", |op| op.mnemonic());
        match self.op.operands() {
            Operands::None => Ok(()),
            Operands::I32 => write!(f, " {}", read_u32(imm, 0) as i32),
            Operands::U32 => write!(f, " {}", read_u32(imm, 0)),
            Operands::I64 => write!(f, " {}", read_u64(imm, 0) as i64),
            Operands::Index16 => match self.op {
                Opcode::CallBuiltin => match Builtin::from_u16(read_u16(imm, 0)) {
                    Some(b) => write!(f, " {}", b.mnemonic()),
                    None => write!(f, " #{}", read_u16(imm, 0)),
                },
                _ => write!(f, " {}", read_u16(imm, 0)),
            },
            Operands::TypeAddr => write!(f, " {} {}", ty(imm[0]), read_u32(imm, 1)),
            Operands::Width => write!(f, " {}", imm[0]),
            Operands::TypeMode => {
                let mode = match RoundMode::from_code(imm[1]) {
                    Some(RoundMode::Truncate) => "TRUNC",
                    Some(RoundMode::NearestTiesAway) => "ROUND",
                    None => "?",
                };
                write!(f, " {} {mode}", ty(imm[0]))
            }
            Operands::Target => write!(f, " @{}", read_u32(imm, 0)),
            Operands::Range => write!(
                f,
                " {} {}",
                read_u64(imm, 0) as i64,
                read_u64(imm, 8) as i64
            ),
            Operands::TrapCode => match Trap::from_u64(imm[0] as u64) {
                Some(t) => write!(f, " {}", t.name()),
                None => write!(f, " #{}", imm[0]),
            },
            Operands::CompareTarget => write!(f, " {} @{}", opname(imm[0]), read_u32(imm, 1)),
            Operands::IndexSpec => write!(
                f,
                " {} {} {}",
                read_u64(imm, 0) as i64,
                read_u64(imm, 8) as i64,
                read_u32(imm, 16)
            ),
            Operands::AddrIndex => write!(
                f,
                " {} {} {} {}",
                read_u32(imm, 0),
                read_u64(imm, 4) as i64,
                read_u64(imm, 12) as i64,
                read_u32(imm, 20)
            ),
            Operands::TypeAddrIndex => write!(
                f,
                " {} {} {} {} {}",
                ty(imm[0]),
                read_u32(imm, 1),
                read_u64(imm, 5) as i64,
                read_u64(imm, 13) as i64,
                read_u32(imm, 21)
            ),
            Operands::TypeAddrImm => write!(
                f,
                " {} {} {}",
                ty(imm[0]),
                read_u32(imm, 1),
                read_u32(imm, 5) as i32
            ),
            Operands::Compare => write!(f, " {}", opname(imm[0])),
            Operands::CompareImmTarget => write!(
                f,
                " {} {} @{}",
                opname(imm[0]),
                read_u32(imm, 1) as i32,
                read_u32(imm, 5)
            ),
            Operands::OpImm => write!(f, " {} {}", opname(imm[0]), read_u32(imm, 1) as i32),
            Operands::AddrIndexAt => write!(
                f,
                " {} {} {} {} [{} {}]",
                read_u32(imm, 0),
                read_u64(imm, 4) as i64,
                read_u64(imm, 12) as i64,
                read_u32(imm, 20),
                ty(imm[24]),
                read_u32(imm, 25)
            ),
            Operands::TypeAddrIndexAt => write!(
                f,
                " {} {} {} {} {} [{} {}]",
                ty(imm[0]),
                read_u32(imm, 1),
                read_u64(imm, 5) as i64,
                read_u64(imm, 13) as i64,
                read_u32(imm, 21),
                ty(imm[25]),
                read_u32(imm, 26)
            ),
            Operands::OpTypeAddr2 => write!(
                f,
                " {} {} {} {} {}",
                opname(imm[0]),
                ty(imm[1]),
                read_u32(imm, 2),
                ty(imm[6]),
                read_u32(imm, 7)
            ),
            Operands::CompareTypeAddrImmTarget => write!(
                f,
                " {} {} {} {} @{}",
                opname(imm[0]),
                ty(imm[1]),
                read_u32(imm, 2),
                read_u32(imm, 6) as i32,
                read_u32(imm, 10)
            ),
            Operands::OpTypeAddr => {
                write!(f, " {} {} {}", opname(imm[0]), ty(imm[1]), read_u32(imm, 2))
            }
        }
    }
}
