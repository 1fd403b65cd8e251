//! The verifier: the only way to obtain a [`VerifiedImage`], the only thing the VM executes.
//!
//! Checks, in order: every instruction of the code section decodes (linear sweep from 0:
//! known opcode, complete operands, valid type/width/mode/trap bytes, comparison and
//! binary-operator operand bytes of the fused instructions, an integer type for `INC_*`,
//! existing constant, POU and builtin indices, absolute data operands inside `data_size`);
//! then per POU: its code range is inside the code and on instruction boundaries,
//! frame-relative operands (the superinstructions' frame variables and index variables
//! too) are inside its frame, jump and handler targets are instruction starts inside the same POU, and an
//! abstract interpretation over all paths finds, for every reachable instruction, one operand
//! stack depth and one try-nesting depth (equal at merge points, no underflow, at most
//! [`MAX_POU_STACK`] cells, at most [`MAX_TRY_NESTING`] try frames, `RET` with exactly
//! `ret_cells` cells and no open try frame, no fall-through past the POU's end); finally the
//! task table, variable map, located and shared variables, the object table (sorted, not
//! overlapping, inside data memory), the class and dispatch tables (every dispatch target a
//! POU taking and leaving no cells, so `CALL_VIRT` has the fixed stack effect `[inst] -> []`
//! whichever method it runs), the file table and the source-location table.
//!
//! The abstract interpretation visits every instruction once (a worklist) and needs two `u32`
//! of scratch per code byte (state + worklist); [`verify_with_scratch`]
//! takes it from the caller (no allocation), `verify` (feature `alloc`) allocates it.

use crate::image::{Image, MAX_OBJECT_DEPTH, Section, SharedDirection, TASK_RECORD, VarType};
use crate::isa::{
    Builtin, MemType, Opcode, Operands, RoundMode, Trap, read_u16, read_u32, stack_effect,
};

/// Operand-stack cells one POU activation may use (abstract depth limit).
pub const MAX_POU_STACK: u32 = 1024;
/// Try frames one POU may nest.
pub const MAX_TRY_NESTING: u32 = 64;
/// Maximum number of tasks in an image.
pub const MAX_TASKS: usize = 32;
/// Maximum code size (scratch state packs offsets into 31 bits).
pub const MAX_CODE_LEN: usize = 1 << 30;

/// An image that passed the verifier ([`verify_with_scratch`] or `verify`). Only this can be executed.
#[derive(Clone, Copy, Debug)]
pub struct VerifiedImage<'a> {
    image: Image<'a>,
}

impl<'a> VerifiedImage<'a> {
    /// The underlying image.
    pub fn image(&self) -> &Image<'a> {
        &self.image
    }
}

/// Where a verification error was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Site {
    /// A code offset.
    Code(u32),
    /// A POU table entry.
    Pou(usize),
    /// A task table entry.
    Task(usize),
    /// A variable-map entry.
    Var(usize),
    /// A source-location record.
    SrcLoc(usize),
    /// A file record.
    File(usize),
    /// A located-variable record.
    Located(usize),
    /// A shared-variable record.
    Shared(usize),
    /// An object record.
    Object(usize),
    /// A class record.
    Class(usize),
    /// A dispatch record.
    Dispatch(usize),
    /// The image as a whole.
    Image,
}

/// What is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reason {
    /// Unassigned opcode byte.
    BadOpcode(u8),
    /// The instruction's operands run past the end of the code.
    TruncatedInstruction,
    /// Invalid [`MemType`] byte (or a float type where an integer type is needed).
    BadType(u8),
    /// Invalid width byte for ROL/ROR/SEXT/ZEXT.
    BadWidth(u8),
    /// Invalid rounding-mode byte.
    BadRoundMode(u8),
    /// THROW of something that is not a catchable trap code.
    BadTrapCode(u8),
    /// JUMP_IF/JUMP_IF_NOT/SEL_IF/JUMP_IF_IMM/JUMP_IF_NOT_IMM with an operand that is not a
    /// comparison opcode.
    BadComparison(u8),
    /// OP_IMM/OP_REL/OP_ABS with an operand that is not a binary operator.
    BadOperator(u8),
    /// PUSH_CONST index beyond the constant pool.
    UnknownConstant(u16),
    /// CALL of a POU index beyond the POU table.
    UnknownPou(u16),
    /// CALL_BUILTIN of an unknown id.
    UnknownBuiltin(u16),
    /// LD_ABS/ST_ABS outside data memory.
    AddressOutsideData {
        /// First byte accessed.
        address: u64,
        /// Bytes accessed.
        width: u32,
        /// Data size.
        data_size: u32,
    },
    /// LD_REL/ST_REL/LEA_REL outside the POU's frame.
    OffsetOutsideFrame {
        /// Frame offset.
        offset: u64,
        /// Frame size of the POU.
        frame_size: u32,
    },
    /// Jump or handler target outside the POU's code.
    TargetOutsidePou(u32),
    /// Jump or handler target in the middle of an instruction.
    TargetInsideInstruction(u32),
    /// Popping more cells than the stack holds.
    StackUnderflow {
        /// Depth before the instruction.
        depth: u32,
        /// Cells needed.
        needed: u32,
    },
    /// Stack deeper than [`MAX_POU_STACK`].
    StackTooDeep(u32),
    /// Two paths reach an instruction with different stack depths.
    StackMismatch {
        /// Depth recorded first.
        expected: u32,
        /// Depth on the other path.
        found: u32,
    },
    /// Two paths reach an instruction with different try nesting.
    TryNestingMismatch {
        /// Nesting recorded first.
        expected: u32,
        /// Nesting on the other path.
        found: u32,
    },
    /// TRY_END without an open try frame.
    TryEndWithoutTry,
    /// Try nesting beyond [`MAX_TRY_NESTING`].
    TryTooDeep,
    /// RET with a stack depth other than the POU's `ret_cells`.
    ReturnDepth {
        /// `ret_cells`.
        expected: u32,
        /// Actual depth.
        found: u32,
    },
    /// RET while a try frame of this POU is still open.
    ReturnInsideTry,
    /// Execution can run past the last instruction of the POU.
    FallsOffEnd,
    /// POU code range outside the code section or empty.
    PouRangeOutsideCode,
    /// POU code range does not start/end on an instruction boundary.
    PouRangeMisaligned,
    /// A name reference is outside the name blob or not UTF-8.
    BadName,
    /// More than [`MAX_TASKS`] tasks.
    TooManyTasks,
    /// Task POU index beyond the POU table.
    TaskUnknownPou(u16),
    /// Task POU takes arguments or returns results.
    TaskPouSignature,
    /// Task kind byte is not cyclic/event.
    BadTaskKind(u8),
    /// Instance frame `[base, base + frame_size)` outside data memory.
    FrameOutsideData,
    /// An event task's trigger variable lies outside data memory.
    TriggerOutsideData,
    /// Unknown variable type byte.
    BadVarType(u8),
    /// Variable outside data memory.
    VarOutsideData,
    /// Variable size does not fit its type.
    VarSizeMismatch,
    /// Located variable: unknown area or width code, a bit number on a non-bit or above 7,
    /// or an address beyond the area.
    BadLocation,
    /// Located variable outside data memory.
    LocatedOutsideData,
    /// Shared variable: unknown direction code, unknown variable record, a type that cannot
    /// be shared (STRING; a validity flag other than BOOL), or a declaration in an unknown
    /// file.
    BadShared,
    /// Shared variable named twice, overlapping another shared variable in data memory, or a
    /// second validity flag.
    SharedOverlap,
    /// Object record empty, outside data memory, not after the previous one (by start, then
    /// decreasing length), partly overlapping another record, naming a parent other than the
    /// smallest record containing it, or nested deeper than `MAX_OBJECT_DEPTH`.
    BadObject,
    /// Class record whose name is invalid or whose dispatch range lies outside the
    /// DISPATCH section.
    BadClass,
    /// Dispatch record of an unknown POU, of a POU that takes or leaves cells, with a frame
    /// outside data memory, or whose slot does not follow the previous one of its class.
    BadDispatch,
    /// Source-location table not sorted by code offset.
    SrcLocUnsorted,
    /// Source location beyond the code or naming an unknown file.
    SrcLocInvalid,
    /// Scratch buffer shorter than twice the code.
    ScratchTooSmall,
    /// Code larger than [`MAX_CODE_LEN`].
    CodeTooLarge,
}

/// A verification failure: where and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VerifyError {
    /// Where.
    pub site: Site,
    /// Why.
    pub reason: Reason,
}

impl core::fmt::Display for Site {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Site::Code(o) => write!(f, "at code offset {o}"),
            Site::Pou(i) => write!(f, "in POU table entry {i}"),
            Site::Task(i) => write!(f, "in task table entry {i}"),
            Site::Var(i) => write!(f, "in variable map entry {i}"),
            Site::SrcLoc(i) => write!(f, "in source-location entry {i}"),
            Site::File(i) => write!(f, "in file table entry {i}"),
            Site::Located(i) => write!(f, "in located-variable entry {i}"),
            Site::Shared(i) => write!(f, "in shared-variable entry {i}"),
            Site::Object(i) => write!(f, "in object entry {i}"),
            Site::Class(i) => write!(f, "in class entry {i}"),
            Site::Dispatch(i) => write!(f, "in dispatch entry {i}"),
            Site::Image => write!(f, "in image"),
        }
    }
}

impl core::fmt::Display for Reason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Reason::BadOpcode(b) => write!(f, "unknown opcode 0x{b:02x}"),
            Reason::TruncatedInstruction => {
                write!(f, "instruction operands run past the end of the code")
            }
            Reason::BadType(b) => write!(f, "invalid type operand {b}"),
            Reason::BadWidth(b) => write!(f, "invalid width operand {b}"),
            Reason::BadRoundMode(b) => write!(f, "invalid rounding mode {b}"),
            Reason::BadTrapCode(b) => write!(f, "invalid trap code {b}"),
            Reason::BadComparison(b) => write!(f, "operand 0x{b:02x} is not a comparison opcode"),
            Reason::BadOperator(b) => write!(f, "operand 0x{b:02x} is not a binary operator"),
            Reason::UnknownConstant(i) => write!(f, "constant {i} does not exist"),
            Reason::UnknownPou(i) => write!(f, "call of unknown POU {i}"),
            Reason::UnknownBuiltin(i) => write!(f, "call of unknown builtin {i}"),
            Reason::AddressOutsideData {
                address,
                width,
                data_size,
            } => {
                write!(
                    f,
                    "access of {width} bytes at data address {address} outside data memory of {data_size} bytes"
                )
            }
            Reason::OffsetOutsideFrame { offset, frame_size } => {
                write!(
                    f,
                    "frame offset {offset} outside the POU frame of {frame_size} bytes"
                )
            }
            Reason::TargetOutsidePou(t) => write!(f, "jump target {t} outside the POU"),
            Reason::TargetInsideInstruction(t) => {
                write!(f, "jump target {t} is inside an instruction")
            }
            Reason::StackUnderflow { depth, needed } => {
                write!(
                    f,
                    "stack underflow: needs {needed} cells, stack holds {depth}"
                )
            }
            Reason::StackTooDeep(d) => {
                write!(f, "stack depth {d} exceeds the limit {MAX_POU_STACK}")
            }
            Reason::StackMismatch { expected, found } => {
                write!(
                    f,
                    "stack depth {found} differs from {expected} on another path"
                )
            }
            Reason::TryNestingMismatch { expected, found } => {
                write!(
                    f,
                    "try nesting {found} differs from {expected} on another path"
                )
            }
            Reason::TryEndWithoutTry => write!(f, "TRY_END without open TRY_BEGIN"),
            Reason::TryTooDeep => write!(f, "try nesting exceeds the limit {MAX_TRY_NESTING}"),
            Reason::ReturnDepth { expected, found } => {
                write!(
                    f,
                    "RET with {found} cells on the stack, POU returns {expected}"
                )
            }
            Reason::ReturnInsideTry => write!(f, "RET inside an open try block"),
            Reason::FallsOffEnd => write!(f, "execution falls off the end of the POU"),
            Reason::PouRangeOutsideCode => write!(f, "POU code range empty or outside the code"),
            Reason::PouRangeMisaligned => write!(f, "POU code range not on instruction boundaries"),
            Reason::BadName => write!(f, "name reference invalid or not UTF-8"),
            Reason::TooManyTasks => write!(f, "more than {MAX_TASKS} tasks"),
            Reason::TaskUnknownPou(i) => write!(f, "task runs unknown POU {i}"),
            Reason::TaskPouSignature => {
                write!(f, "task POU must take 0 argument and 0 result cells")
            }
            Reason::BadTaskKind(k) => write!(f, "unknown task kind {k}"),
            Reason::TriggerOutsideData => write!(f, "event trigger outside data memory"),
            Reason::FrameOutsideData => write!(f, "instance frame outside data memory"),
            Reason::BadVarType(t) => write!(
                f,
                "unknown variable type code {t} (known: 0 to {}; an image of a newer compiler?)",
                VarType::ALL[VarType::COUNT - 1].code()
            ),
            Reason::VarOutsideData => write!(f, "variable outside data memory"),
            Reason::VarSizeMismatch => write!(f, "variable size does not match its type"),
            Reason::BadLocation => write!(f, "invalid located-variable address"),
            Reason::LocatedOutsideData => write!(f, "located variable outside data memory"),
            Reason::BadShared => write!(
                f,
                "invalid shared variable (direction, variable, type or declaration file)"
            ),
            Reason::SharedOverlap => {
                write!(f, "shared variable overlaps another shared variable")
            }
            Reason::BadObject => write!(
                f,
                "object empty, outside data memory, out of order, partly overlapping, with a wrong parent or nested too deeply"
            ),
            Reason::BadClass => write!(f, "class name invalid or dispatch range outside the table"),
            Reason::BadDispatch => write!(
                f,
                "dispatch entry: unknown POU, POU with argument or result cells, frame outside data memory, or slots not increasing"
            ),
            Reason::SrcLocUnsorted => write!(f, "source locations not sorted by code offset"),
            Reason::SrcLocInvalid => {
                write!(f, "source location beyond the code or with unknown file")
            }
            Reason::ScratchTooSmall => {
                write!(f, "verifier scratch buffer shorter than twice the code")
            }
            Reason::CodeTooLarge => write!(f, "code section too large"),
        }
    }
}

impl core::fmt::Display for VerifyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}: {}", self.site, self.reason)
    }
}

fn err<T>(site: Site, reason: Reason) -> Result<T, VerifyError> {
    Err(VerifyError { site, reason })
}

/// Verifies an image, allocating the scratch buffer.
#[cfg(any(feature = "alloc", test))]
pub fn verify<'a>(image: &Image<'a>) -> Result<VerifiedImage<'a>, VerifyError> {
    let mut scratch = alloc::vec![0u32; 2 * image.code().len()];
    verify_with_scratch(image, &mut scratch)
}

/// An owned image verified once and run many times (an IEC 61499 type's algorithms, called
/// at every event): the bytes never change after [`VerifiedBytes::new`] verified them, so
/// [`VerifiedBytes::image`] only parses the section table again and never re-verifies.
#[cfg(any(feature = "alloc", test))]
#[derive(Clone, Debug)]
pub struct VerifiedBytes {
    bytes: alloc::boxed::Box<[u8]>,
}

/// Why [`VerifiedBytes::new`] refused an image.
#[cfg(any(feature = "alloc", test))]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OwnedImageError {
    /// The image does not parse.
    Image(crate::image::ImageError),
    /// The image parses but does not verify.
    Verify(VerifyError),
}

#[cfg(any(feature = "alloc", test))]
impl VerifiedBytes {
    /// Parses and verifies `bytes`, keeping them.
    pub fn new(bytes: alloc::vec::Vec<u8>) -> Result<Self, OwnedImageError> {
        let image = Image::parse(&bytes).map_err(OwnedImageError::Image)?;
        verify(&image).map_err(OwnedImageError::Verify)?;
        Ok(VerifiedBytes {
            bytes: bytes.into_boxed_slice(),
        })
    }

    /// The image's bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The verified image (the section table parsed again; the code is not re-verified).
    pub fn image(&self) -> VerifiedImage<'_> {
        match Image::parse(&self.bytes) {
            Ok(image) => VerifiedImage { image },
            Err(e) => unreachable!("immutable bytes parsed when they were verified: {e:?}"),
        }
    }
}

// Scratch encoding per code byte: bit 31 = instruction start; bit 30 = state known;
// bits 0..16 = stack depth; bits 16..24 = try nesting.
const INSN_START: u32 = 1 << 31;
const KNOWN: u32 = 1 << 30;

fn pack(depth: u32, tries: u32) -> u32 {
    KNOWN | depth | (tries << 16)
}

/// Verifies an image using caller-provided scratch (`scratch.len() >= 2 * code length`).
pub fn verify_with_scratch<'a>(
    image: &Image<'a>,
    scratch: &mut [u32],
) -> Result<VerifiedImage<'a>, VerifyError> {
    let code = image.code();
    if code.len() > MAX_CODE_LEN {
        return err(Site::Image, Reason::CodeTooLarge);
    }
    if scratch.len() < 2 * code.len() {
        return err(Site::Image, Reason::ScratchTooSmall);
    }
    let (states, worklist) = scratch[..2 * code.len()].split_at_mut(code.len());
    states.fill(0);
    sweep_code(image, states)?;
    for index in 0..image.pou_count() {
        check_pou(image, index, states, worklist)?;
    }
    check_tables(image)?;
    Ok(VerifiedImage { image: *image })
}

/// Linear sweep: decodes every instruction, checks operands that need no POU context and
/// marks instruction starts.
fn sweep_code(image: &Image<'_>, scratch: &mut [u32]) -> Result<(), VerifyError> {
    let code = image.code();
    let data_size = image.data_size();
    let mut pc = 0usize;
    while pc < code.len() {
        let site = Site::Code(pc as u32);
        let Some(op) = Opcode::from_u8(code[pc]) else {
            return err(site, Reason::BadOpcode(code[pc]));
        };
        if pc + op.size() > code.len() {
            return err(site, Reason::TruncatedInstruction);
        }
        scratch[pc] = INSN_START;
        let imm = pc + 1;
        match op.operands() {
            Operands::TypeAddr => {
                let ty = MemType::from_code(code[imm]).ok_or(VerifyError {
                    site,
                    reason: Reason::BadType(code[imm]),
                })?;
                if matches!(op, Opcode::LdAbs | Opcode::StAbs) {
                    check_abs(site, read_u32(code, imm + 1), ty, data_size)?;
                }
            }
            Operands::Width => {
                let width = code[imm];
                let ok = match op {
                    Opcode::Rol | Opcode::Ror => matches!(width, 8 | 16 | 32 | 64),
                    _ => matches!(width, 8 | 16 | 32),
                };
                if !ok {
                    return err(site, Reason::BadWidth(width));
                }
            }
            Operands::TypeMode => {
                match MemType::from_code(code[imm]) {
                    Some(ty) if ty.is_integer() => {}
                    _ => return err(site, Reason::BadType(code[imm])),
                }
                if RoundMode::from_code(code[imm + 1]).is_none() {
                    return err(site, Reason::BadRoundMode(code[imm + 1]));
                }
            }
            Operands::CompareTarget | Operands::Compare | Operands::CompareImmTarget => {
                match Opcode::from_u8(code[imm]) {
                    Some(cmp) if cmp.is_comparison() => {}
                    _ => return err(site, Reason::BadComparison(code[imm])),
                }
            }
            Operands::CompareTypeAddrImmTarget => {
                match Opcode::from_u8(code[imm]) {
                    Some(cmp) if cmp.is_comparison() => {}
                    _ => return err(site, Reason::BadComparison(code[imm])),
                }
                if MemType::from_code(code[imm + 1]).is_none() {
                    return err(site, Reason::BadType(code[imm + 1]));
                }
            }
            Operands::OpTypeAddr2 => {
                match Opcode::from_u8(code[imm]) {
                    Some(op) if op.is_binary() => {}
                    _ => return err(site, Reason::BadOperator(code[imm])),
                }
                for at in [imm + 1, imm + 6] {
                    if MemType::from_code(code[at]).is_none() {
                        return err(site, Reason::BadType(code[at]));
                    }
                }
            }
            Operands::OpImm | Operands::OpTypeAddr => {
                match Opcode::from_u8(code[imm]) {
                    Some(op) if op.is_binary() => {}
                    _ => return err(site, Reason::BadOperator(code[imm])),
                }
                if op != Opcode::OpImm {
                    let ty = MemType::from_code(code[imm + 1]).ok_or(VerifyError {
                        site,
                        reason: Reason::BadType(code[imm + 1]),
                    })?;
                    if op == Opcode::OpAbs {
                        check_abs(site, read_u32(code, imm + 2), ty, data_size)?;
                    }
                }
            }
            Operands::TypeAddrIndex if MemType::from_code(code[imm]).is_none() => {
                return err(site, Reason::BadType(code[imm]));
            }
            Operands::AddrIndexAt | Operands::TypeAddrIndexAt => {
                let index_type = if op.operands() == Operands::AddrIndexAt {
                    imm + 24
                } else {
                    if MemType::from_code(code[imm]).is_none() {
                        return err(site, Reason::BadType(code[imm]));
                    }
                    imm + 25
                };
                if MemType::from_code(code[index_type]).is_none() {
                    return err(site, Reason::BadType(code[index_type]));
                }
            }
            Operands::TypeAddrImm => {
                let ty = match MemType::from_code(code[imm]) {
                    Some(ty) if ty.is_integer() => ty,
                    _ => return err(site, Reason::BadType(code[imm])),
                };
                if op == Opcode::IncAbs {
                    check_abs(site, read_u32(code, imm + 1), ty, data_size)?;
                }
            }
            Operands::TrapCode => match Trap::from_u64(code[imm] as u64) {
                Some(trap) if trap.is_catchable() => {}
                _ => return err(site, Reason::BadTrapCode(code[imm])),
            },
            Operands::Index16 => {
                let index = read_u16(code, imm);
                match op {
                    Opcode::PushConst if index as usize >= image.const_count() => {
                        return err(site, Reason::UnknownConstant(index));
                    }
                    Opcode::Call if index as usize >= image.pou_count() => {
                        return err(site, Reason::UnknownPou(index));
                    }
                    Opcode::CallBuiltin if Builtin::from_u16(index).is_none() => {
                        return err(site, Reason::UnknownBuiltin(index));
                    }
                    _ => {}
                }
            }
            _ => {}
        }
        pc += op.size();
    }
    Ok(())
}

/// An absolute access of a `ty` value at `address` must lie inside data memory.
fn check_abs(site: Site, address: u32, ty: MemType, data_size: u32) -> Result<(), VerifyError> {
    let address = address as u64;
    if address + ty.width() as u64 > data_size as u64 {
        return err(
            site,
            Reason::AddressOutsideData {
                address,
                width: ty.width() as u32,
                data_size,
            },
        );
    }
    Ok(())
}

fn check_pou(
    image: &Image<'_>,
    index: usize,
    scratch: &mut [u32],
    worklist: &mut [u32],
) -> Result<(), VerifyError> {
    let code = image.code();
    let pou = image.pou(index).ok_or(VerifyError {
        site: Site::Pou(index),
        reason: Reason::PouRangeOutsideCode,
    })?;
    let (off, len) = image
        .record_name_ref(Section::Pous, index)
        .unwrap_or((u32::MAX, 0));
    if image.name_at(off, len).is_none() {
        return err(Site::Pou(index), Reason::BadName);
    }
    let start = pou.code_start as usize;
    let end = start.saturating_add(pou.code_len as usize);
    if pou.code_len == 0 || end > code.len() {
        return err(Site::Pou(index), Reason::PouRangeOutsideCode);
    }
    if scratch[start] & INSN_START == 0 || (end < code.len() && scratch[end] & INSN_START == 0) {
        return err(Site::Pou(index), Reason::PouRangeMisaligned);
    }
    for cell in &mut scratch[start..end] {
        *cell &= INSN_START;
    }
    scratch[start] |= pack(pou.arg_cells as u32, 0);
    // Worklist: an instruction is pushed when its state becomes known, which happens once,
    // so every reachable instruction is checked exactly once and the list never holds more
    // entries than there are instructions.
    worklist[0] = start as u32;
    let mut pending = 1usize;
    while pending > 0 {
        pending -= 1;
        let pc = worklist[pending] as usize;
        let op = Opcode::from_u8(code[pc]).expect("swept");
        let state = scratch[pc];
        let depth = state & 0xFFFF;
        let tries = (state >> 16) & 0xFF;
        for target in step(image, &pou, pc, op, depth, tries, start, end, scratch)?
            .into_iter()
            .flatten()
        {
            worklist[pending] = target as u32;
            pending += 1;
        }
    }
    Ok(())
}

/// Checks one instruction in abstract state (depth, tries) and merges its successors' states.
#[allow(clippy::too_many_arguments)]
fn step(
    image: &Image<'_>,
    pou: &crate::image::Pou<'_>,
    pc: usize,
    op: Opcode,
    depth: u32,
    tries: u32,
    start: usize,
    end: usize,
    scratch: &mut [u32],
) -> Result<[Option<usize>; 2], VerifyError> {
    let code = image.code();
    let site = Site::Code(pc as u32);
    let imm = pc + 1;
    // Frame-relative operands must lie inside this POU's frame.
    match op {
        Opcode::LdRel
        | Opcode::StRel
        | Opcode::IncRel
        | Opcode::OpRel
        | Opcode::OpRelRel
        | Opcode::JumpIfRelImm
        | Opcode::JumpIfNotRelImm
        | Opcode::ElemRelAt
        | Opcode::ElemAbsAt
        | Opcode::LdElemRelAt
        | Opcode::LdElemAbsAt
        | Opcode::StElemRelAt
        | Opcode::StElemAbsAt => {
            // Where each (type byte, offset) operand is.
            let operands: &[usize] = match op {
                Opcode::OpRel | Opcode::JumpIfRelImm | Opcode::JumpIfNotRelImm => &[1],
                Opcode::OpRelRel => &[1, 6],
                Opcode::ElemRelAt | Opcode::ElemAbsAt => &[24],
                Opcode::LdElemRelAt
                | Opcode::LdElemAbsAt
                | Opcode::StElemRelAt
                | Opcode::StElemAbsAt => &[25],
                _ => &[0],
            };
            for &at in operands {
                let ty = MemType::from_code(code[imm + at]).expect("swept");
                let offset = read_u32(code, imm + at + 1) as u64;
                if offset + ty.width() as u64 > pou.frame_size as u64 {
                    return err(
                        site,
                        Reason::OffsetOutsideFrame {
                            offset,
                            frame_size: pou.frame_size,
                        },
                    );
                }
            }
        }
        Opcode::LeaRel => {
            let offset = read_u32(code, imm) as u64;
            if offset > pou.frame_size as u64 {
                return err(
                    site,
                    Reason::OffsetOutsideFrame {
                        offset,
                        frame_size: pou.frame_size,
                    },
                );
            }
        }
        _ => {}
    }
    let (pops, pushes) = match op {
        Opcode::Call => {
            let callee = image.pou(read_u16(code, imm) as usize).expect("swept");
            (1 + callee.arg_cells as u32, callee.ret_cells as u32)
        }
        Opcode::CallBuiltin => {
            let builtin = Builtin::from_u16(read_u16(code, imm)).expect("swept");
            (builtin.args() as u32, builtin.results() as u32)
        }
        Opcode::Ret => {
            if tries != 0 {
                return err(site, Reason::ReturnInsideTry);
            }
            if depth != pou.ret_cells as u32 {
                return err(
                    site,
                    Reason::ReturnDepth {
                        expected: pou.ret_cells as u32,
                        found: depth,
                    },
                );
            }
            return Ok([None, None]);
        }
        _ => stack_effect(op).expect("fixed effect"),
    };
    if depth < pops {
        return err(
            site,
            Reason::StackUnderflow {
                depth,
                needed: pops,
            },
        );
    }
    let after = depth - pops + pushes;
    if after > MAX_POU_STACK {
        return err(site, Reason::StackTooDeep(after));
    }
    let mut discovered = [None, None];
    let mut flow = |target: usize, depth: u32, tries: u32, jump: bool| -> Result<(), VerifyError> {
        if target >= end || target < start {
            return if jump {
                err(site, Reason::TargetOutsidePou(target as u32))
            } else {
                err(site, Reason::FallsOffEnd)
            };
        }
        if scratch[target] & INSN_START == 0 {
            return err(site, Reason::TargetInsideInstruction(target as u32));
        }
        let known = scratch[target];
        if known & KNOWN == 0 {
            scratch[target] |= pack(depth, tries);
            let slot = if discovered[0].is_none() { 0 } else { 1 };
            discovered[slot] = Some(target);
            return Ok(());
        }
        let (expected_depth, expected_tries) = (known & 0xFFFF, (known >> 16) & 0xFF);
        if expected_depth != depth {
            return err(
                site,
                Reason::StackMismatch {
                    expected: expected_depth,
                    found: depth,
                },
            );
        }
        if expected_tries != tries {
            return err(
                site,
                Reason::TryNestingMismatch {
                    expected: expected_tries,
                    found: tries,
                },
            );
        }
        Ok(())
    };
    let next = pc + op.size();
    match op {
        Opcode::Jmp => flow(read_u32(code, imm) as usize, after, tries, true)?,
        Opcode::Jz | Opcode::Jnz => {
            flow(read_u32(code, imm) as usize, after, tries, true)?;
            flow(next, after, tries, false)?;
        }
        Opcode::JumpIf | Opcode::JumpIfNot => {
            flow(read_u32(code, imm + 1) as usize, after, tries, true)?;
            flow(next, after, tries, false)?;
        }
        Opcode::JumpIfImm | Opcode::JumpIfNotImm => {
            flow(read_u32(code, imm + 5) as usize, after, tries, true)?;
            flow(next, after, tries, false)?;
        }
        Opcode::JumpIfRelImm | Opcode::JumpIfNotRelImm => {
            flow(read_u32(code, imm + 10) as usize, after, tries, true)?;
            flow(next, after, tries, false)?;
        }
        Opcode::TryBegin => {
            if tries + 1 > MAX_TRY_NESTING {
                return err(site, Reason::TryTooDeep);
            }
            // The handler runs with the try frame popped and the trap code pushed.
            if after + 1 > MAX_POU_STACK {
                return err(site, Reason::StackTooDeep(after + 1));
            }
            flow(read_u32(code, imm) as usize, after + 1, tries, true)?;
            flow(next, after, tries + 1, false)?;
        }
        Opcode::TryEnd => {
            if tries == 0 {
                return err(site, Reason::TryEndWithoutTry);
            }
            flow(next, after, tries - 1, false)?;
        }
        Opcode::Throw => {}
        _ => flow(next, after, tries, false)?,
    }
    Ok(discovered)
}

/// Object record `index` against the ones before it: inside data memory, not empty, after
/// the previous record in (start, decreasing length) order, overlapping only the records
/// that contain it, with `parent` naming the smallest of those, at most
/// [`MAX_OBJECT_DEPTH`] deep. The walk from the previous record up its parents passes only
/// records that end before this one starts; they are never walked again (they cannot contain
/// a later record either), so checking all records takes linear time.
fn check_object(image: &Image<'_>, index: usize) -> Result<(), VerifyError> {
    let bad = || err(Site::Object(index), Reason::BadObject);
    let (start, len) = image.object(index).expect("counted");
    let (start, end) = (start as u64, start as u64 + len as u64);
    if len == 0 || end > image.data_size() as u64 {
        return bad();
    }
    let contains = |k: usize| {
        let (s, l) = image.object(k).expect("earlier record");
        s as u64 <= start && end <= s as u64 + l as u64
    };
    if let Some(previous) = index.checked_sub(1) {
        let (ps, pl) = image.object(previous).expect("earlier record");
        if (ps as u64, u64::MAX - pl as u64) >= (start, u64::MAX - len as u64) {
            return bad();
        }
    }
    let mut enclosing = index.checked_sub(1);
    while let Some(k) = enclosing {
        if contains(k) {
            break;
        }
        let (s, l) = image.object(k).expect("earlier record");
        if s as u64 + l as u64 > start {
            return bad();
        }
        enclosing = image.object_parent(k);
    }
    if image.object_parent(index) != enclosing {
        return bad();
    }
    let mut depth = 0;
    let mut up = enclosing;
    while let Some(k) = up {
        depth += 1;
        if depth >= MAX_OBJECT_DEPTH {
            return bad();
        }
        up = image.object_parent(k);
    }
    Ok(())
}

fn check_tables(image: &Image<'_>) -> Result<(), VerifyError> {
    let data_size = image.data_size() as u64;
    if image.task_count() > MAX_TASKS {
        return err(Site::Image, Reason::TooManyTasks);
    }
    for index in 0..image.task_count() {
        let site = Site::Task(index);
        let task = image.task(index).expect("counted");
        let (off, len) = image
            .record_name_ref(Section::Tasks, index)
            .expect("counted");
        if image.name_at(off, len).is_none() {
            return err(site, Reason::BadName);
        }
        if task.kind > 1 {
            return err(site, Reason::BadTaskKind(task.kind));
        }
        let pou = image.pou(task.pou as usize).ok_or(VerifyError {
            site,
            reason: Reason::TaskUnknownPou(task.pou),
        })?;
        if pou.arg_cells != 0 || pou.ret_cells != 0 {
            return err(site, Reason::TaskPouSignature);
        }
        if task.instance_base as u64 + pou.frame_size as u64 > data_size {
            return err(site, Reason::FrameOutsideData);
        }
        if task.trigger.is_some_and(|t| t as u64 >= data_size) {
            return err(site, Reason::TriggerOutsideData);
        }
    }
    debug_assert_eq!(TASK_RECORD, 32);
    for index in 0..image.var_count() {
        let site = Site::Var(index);
        let var = image.var(index).expect("counted");
        let (off, len) = image
            .record_name_ref(Section::Vars, index)
            .expect("counted");
        if image.name_at(off, len).is_none() {
            return err(site, Reason::BadName);
        }
        let ty = VarType::from_code(var.ty).ok_or(VerifyError {
            site,
            reason: Reason::BadVarType(var.ty),
        })?;
        if var.addr as u64 + var.size as u64 > data_size {
            return err(site, Reason::VarOutsideData);
        }
        if !ty.size_fits(var.size) {
            return err(site, Reason::VarSizeMismatch);
        }
    }
    for index in 0..image.located_count() {
        use crate::located::{MAX_AREA, Width};
        let site = Site::Located(index);
        let Some(v) = image.located(index) else {
            return err(site, Reason::BadLocation);
        };
        let l = v.location;
        let bit_ok = l.bit == 0 || (l.width == Width::Bit && l.bit <= 7);
        if !bit_ok || l.byte.saturating_add(l.width.bytes()) > MAX_AREA {
            return err(site, Reason::BadLocation);
        }
        if v.address as u64 + l.width.bytes() as u64 > data_size {
            return err(site, Reason::LocatedOutsideData);
        }
    }
    if image.shared_count() > crate::image::MAX_SHARED_VARS {
        return err(Site::Image, Reason::BadShared);
    }
    for index in 0..image.shared_count() {
        let site = Site::Shared(index);
        // `shared` checks the direction code and the variable record, whose address and
        // size the loop over the variable map checked above.
        let Some(s) = image.shared(index) else {
            return err(site, Reason::BadShared);
        };
        let ty = VarType::from_code(s.var.ty);
        let shareable = match s.direction {
            SharedDirection::Valid => ty == Some(VarType::Bool),
            _ => ty.is_some_and(|t| t.mem_type().is_some()),
        };
        if !shareable || s.location.file as usize >= image.file_count() {
            return err(site, Reason::BadShared);
        }
        let (lo, hi) = (s.var.addr, s.var.addr + s.var.size);
        // Quadratic, but bounded by MAX_SHARED_VARS; a copy-in must never write
        // over another shared variable.
        let clash = (0..index).filter_map(|i| image.shared(i)).any(|o| {
            o.var_index == s.var_index
                || (lo < o.var.addr + o.var.size && o.var.addr < hi)
                || (o.direction == SharedDirection::Valid && s.direction == SharedDirection::Valid)
        });
        if clash {
            return err(site, Reason::SharedOverlap);
        }
    }
    for index in 0..image.object_count() {
        check_object(image, index)?;
    }
    for index in 0..image.class_count() {
        let site = Site::Class(index);
        let class = image.class(index).expect("counted");
        let (off, len) = image
            .record_name_ref(Section::Classes, index)
            .expect("counted");
        let last = class.first as u64 + class.count as u64;
        if image.name_at(off, len).is_none() || last > image.dispatch_count() as u64 {
            return err(site, Reason::BadClass);
        }
        let mut previous: Option<u16> = None;
        for d in class.first as usize..last as usize {
            let entry = image.dispatch(d).expect("counted");
            let pou_ok = image
                .pou(entry.pou as usize)
                .is_some_and(|p| p.arg_cells == 0 && p.ret_cells == 0);
            if !pou_ok
                || entry.frame as u64 >= data_size
                || previous.is_some_and(|p| p >= entry.slot)
            {
                return err(Site::Dispatch(d), Reason::BadDispatch);
            }
            previous = Some(entry.slot);
        }
    }
    for index in 0..image.file_count() {
        if image.file_name(index as u16).is_none() {
            return err(Site::File(index), Reason::BadName);
        }
    }
    let mut previous = 0u32;
    for index in 0..image.srcloc_count() {
        let (offset, loc) = image.srcloc(index).expect("counted");
        if offset < previous {
            return err(Site::SrcLoc(index), Reason::SrcLocUnsorted);
        }
        previous = offset;
        if offset as usize > image.code().len() || loc.file as usize >= image.file_count() {
            return err(Site::SrcLoc(index), Reason::SrcLocInvalid);
        }
    }
    Ok(())
}
