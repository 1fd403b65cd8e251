//! One test per verifier rejection reason (and the parser's structural errors).

use super::*;
use crate::image::{HEADER_LEN, ImageError, VarType};
use crate::isa::{MemType, Opcode};
use crate::verify::{MAX_POU_STACK, Reason, Site, VerifyError};
use alloc::string::ToString;

fn verdict(bytes: &[u8]) -> Result<(), VerifyError> {
    let image = Image::parse(bytes).expect("structurally valid");
    verify(&image).map(|_| ())
}

fn rejects(body: impl FnOnce(&mut ImageBuilder, PouId)) -> VerifyError {
    verdict(&program_with(100, body)).expect_err("must be rejected")
}

#[test]
fn accepts_a_well_formed_program() {
    assert_eq!(verdict(&program_with(100, |c, _| c.nop())), Ok(()));
}

#[test]
fn bad_opcode() {
    let e = rejects(|c, _| c.emit_raw(&[0xFF]));
    assert_eq!(
        e,
        VerifyError {
            site: Site::Code(0),
            reason: Reason::BadOpcode(0xFF)
        }
    );
    assert_eq!(e.to_string(), "at code offset 0: unknown opcode 0xff");
}

#[test]
fn truncated_instruction() {
    let mut b = ImageBuilder::new();
    b.emit_raw(&[Opcode::PushI64 as u8, 1, 2]);
    assert_eq!(
        verdict(&b.build().unwrap()).unwrap_err().reason,
        Reason::TruncatedInstruction
    );
}

#[test]
fn bad_type_width_mode_trap_operands() {
    let e = rejects(|c, _| c.emit_raw(&[Opcode::LdAbs as u8, 10, 0, 0, 0, 0, Opcode::Drop as u8]));
    assert_eq!(e.reason, Reason::BadType(10));
    let e = rejects(|c, _| c.emit_raw(&[Opcode::Sext as u8, 64]));
    assert_eq!(e.reason, Reason::BadWidth(64));
    let e = rejects(|c, _| c.emit_raw(&[Opcode::F64ToInt as u8, MemType::F32 as u8, 0]));
    assert_eq!(e.reason, Reason::BadType(MemType::F32 as u8));
    let e = rejects(|c, _| c.emit_raw(&[Opcode::F64ToInt as u8, MemType::I32 as u8, 7]));
    assert_eq!(e.reason, Reason::BadRoundMode(7));
    let e = rejects(|c, _| c.emit_raw(&[Opcode::Throw as u8, crate::isa::Trap::Watchdog.code()]));
    assert_eq!(e.reason, Reason::BadTrapCode(4));
    let e = rejects(|c, _| c.emit_raw(&[Opcode::Throw as u8, crate::isa::Trap::Deadline.code()]));
    assert_eq!(e.reason, Reason::BadTrapCode(9));
    let e = rejects(|c, _| c.emit_raw(&[Opcode::JumpIf as u8, Opcode::Add as u8, 0, 0, 0, 0]));
    assert_eq!(e.reason, Reason::BadComparison(Opcode::Add as u8));
}

#[test]
fn unknown_constant_pou_builtin() {
    assert_eq!(
        rejects(|c, _| c.push_const(0)).reason,
        Reason::UnknownConstant(0)
    );
    assert_eq!(
        rejects(|c, _| c.emit_raw(&[Opcode::Call as u8, 9, 0])).reason,
        Reason::UnknownPou(9)
    );
    assert_eq!(
        rejects(|c, _| c.emit_raw(&[Opcode::CallBuiltin as u8, 0, 0])).reason,
        Reason::UnknownBuiltin(0)
    );
}

#[test]
fn static_address_outside_data() {
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.st_abs(MemType::I32, DATA - 3);
    });
    assert_eq!(
        e.reason,
        Reason::AddressOutsideData {
            address: (DATA - 3) as u64,
            width: 4,
            data_size: DATA
        }
    );
    assert!(
        e.to_string()
            .starts_with("at code offset 5: access of 4 bytes at data address 509")
    );
}

#[test]
fn frame_offset_outside_frame() {
    let e = rejects(|c, _| {
        c.ld_rel(MemType::I64, MAIN_FRAME - 4);
        c.drop_();
    });
    assert_eq!(
        e.reason,
        Reason::OffsetOutsideFrame {
            offset: (MAIN_FRAME - 4) as u64,
            frame_size: MAIN_FRAME
        }
    );
    let e = rejects(|c, _| {
        c.lea_rel(MAIN_FRAME + 1);
        c.drop_();
    });
    assert!(matches!(e.reason, Reason::OffsetOutsideFrame { .. }));
}

#[test]
fn jump_targets() {
    let e = rejects(|c, _| c.emit_raw(&[Opcode::Jmp as u8, 0xFF, 0, 0, 0]));
    assert_eq!(e.reason, Reason::TargetOutsidePou(0xFF));
    // Into the middle of the PUSH_I32 at offset 0.
    let e = rejects(|c, _| {
        c.push_i32(0);
        c.drop_();
        c.emit_raw(&[Opcode::Jmp as u8, 2, 0, 0, 0]);
    });
    assert_eq!(
        e,
        VerifyError {
            site: Site::Code(6),
            reason: Reason::TargetInsideInstruction(2)
        }
    );
    // Handler outside the POU: a second POU's code.
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 0);
    let g = b.declare_pou("g", 0, 0, 0);
    b.begin_pou(f);
    b.ret();
    b.end_pou(f);
    b.begin_pou(g);
    b.emit_raw(&[Opcode::TryBegin as u8, 0, 0, 0, 0]);
    b.try_end();
    b.ret();
    b.end_pou(g);
    assert_eq!(
        verdict(&b.build().unwrap()).unwrap_err().reason,
        Reason::TargetOutsidePou(0)
    );
}

#[test]
fn stack_underflow_and_depth_limit() {
    let e = rejects(|c, _| c.op(Opcode::Add));
    assert_eq!(
        e.reason,
        Reason::StackUnderflow {
            depth: 0,
            needed: 2
        }
    );
    let e = rejects(|c, _| {
        for _ in 0..=MAX_POU_STACK {
            c.push_i32(0);
        }
    });
    assert_eq!(e.reason, Reason::StackTooDeep(MAX_POU_STACK + 1));
}

#[test]
fn stack_mismatch_at_merge() {
    let e = rejects(|c, _| {
        let join = c.new_label();
        c.push_i32(1);
        c.jz(join);
        c.push_i32(5);
        c.bind(join);
        c.drop_();
    });
    assert_eq!(
        e.reason,
        Reason::StackMismatch {
            expected: 0,
            found: 1
        }
    );
}

#[test]
fn try_nesting_rules() {
    let e = rejects(|c, _| c.try_end());
    assert_eq!(e.reason, Reason::TryEndWithoutTry);
    let e = rejects(|c, _| {
        let h = c.new_label();
        c.try_begin(h);
        c.bind(h);
        c.drop_();
    });
    // Fall-through path reaches the handler with 0 cells / 1 try; handler expects 1 cell / 0 tries.
    assert!(matches!(
        e.reason,
        Reason::StackMismatch { .. } | Reason::TryNestingMismatch { .. }
    ));
    let e = rejects(|c, _| {
        let h = c.new_label();
        let end = c.new_label();
        c.try_begin(h);
        c.jmp(end);
        c.bind(h);
        c.drop_();
        c.bind(end);
        c.jmp(end); // valid in any state: only the merge itself can fail
    });
    assert!(matches!(e.reason, Reason::TryNestingMismatch { .. }), "{e}");
    let e = rejects(|c, _| {
        let h = c.new_label();
        c.try_begin(h);
        c.ret();
        c.bind(h);
        c.drop_();
    });
    assert_eq!(e.reason, Reason::ReturnInsideTry);
    let e = rejects(|c, _| {
        for _ in 0..=crate::verify::MAX_TRY_NESTING {
            let h = c.new_label();
            c.try_begin(h);
            c.bind(h); // never reached: the verifier stops at the nesting limit first
        }
    });
    assert!(matches!(
        e.reason,
        Reason::TryTooDeep | Reason::StackMismatch { .. }
    ));
}

#[test]
fn try_too_deep_is_reported() {
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 0);
    b.begin_pou(f);
    let handlers: Vec<_> = (0..=crate::verify::MAX_TRY_NESTING)
        .map(|_| b.new_label())
        .collect();
    for h in &handlers {
        b.try_begin(*h);
    }
    b.ret();
    for (depth, h) in handlers.iter().enumerate() {
        b.bind(*h);
        b.drop_();
        for _ in 0..depth {
            b.try_end();
        }
        b.ret();
    }
    b.end_pou(f);
    assert_eq!(
        verdict(&b.build().unwrap()).unwrap_err().reason,
        Reason::TryTooDeep
    );
}

#[test]
fn return_depth_and_fall_off_end() {
    let e = rejects(|c, _| c.push_i32(1));
    assert_eq!(
        e.reason,
        Reason::ReturnDepth {
            expected: 0,
            found: 1
        }
    );
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 0);
    b.begin_pou(f);
    b.nop();
    b.end_pou(f);
    b.ret(); // outside the POU
    assert_eq!(
        verdict(&b.build().unwrap()).unwrap_err().reason,
        Reason::FallsOffEnd
    );
}

#[test]
fn pou_ranges() {
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 0);
    b.begin_pou(f);
    b.end_pou(f);
    b.ret();
    assert_eq!(
        verdict(&b.build().unwrap()).unwrap_err().reason,
        Reason::PouRangeOutsideCode
    );
    let mut bytes = program_with(100, |c, _| c.push_i32(0x0101_0101));
    // Patch POU 0's code_start (record at POUS offset + 8) to 1: inside PUSH_I32.
    let image = Image::parse(&bytes).unwrap();
    let _ = image;
    let pous_offset =
        u32::from_le_bytes(bytes[16 + 3 * 8..16 + 3 * 8 + 4].try_into().unwrap()) as usize;
    bytes[pous_offset + 8] = 1;
    bytes[pous_offset + 12] -= 1;
    assert_eq!(
        verdict(&bytes).unwrap_err().reason,
        Reason::PouRangeMisaligned
    );
}

fn task_with(pou_args: u8, base: u32) -> Vec<u8> {
    let mut b = ImageBuilder::new();
    b.reserve_data(64);
    let f = b.declare_pou("f", pou_args, 0, 32);
    b.add_task(&TaskDef {
        name: "t".into(),
        kind: TaskKind::Event,
        priority: 1,
        pou: f,
        instance_base: base,
        interval_ns: 0,
        watchdog_budget: 0,
    });
    b.begin_pou(f);
    for _ in 0..pou_args {
        b.drop_();
    }
    b.ret();
    b.end_pou(f);
    b.build().unwrap()
}

#[test]
fn task_table_entries() {
    assert_eq!(verdict(&task_with(0, 32)), Ok(()));
    assert_eq!(
        verdict(&task_with(1, 0)).unwrap_err(),
        VerifyError {
            site: Site::Task(0),
            reason: Reason::TaskPouSignature
        }
    );
    assert_eq!(
        verdict(&task_with(0, 33)).unwrap_err().reason,
        Reason::FrameOutsideData
    );
    let tasks_at = |bytes: &[u8]| {
        u32::from_le_bytes(bytes[16 + 4 * 8..16 + 4 * 8 + 4].try_into().unwrap()) as usize
    };
    let mut bytes = task_with(0, 0);
    let at = tasks_at(&bytes);
    bytes[at + 8] = 7; // POU index
    assert_eq!(
        verdict(&bytes).unwrap_err().reason,
        Reason::TaskUnknownPou(7)
    );
    let mut bytes = task_with(0, 0);
    let at = tasks_at(&bytes);
    bytes[at + 6] = 9; // kind
    assert_eq!(verdict(&bytes).unwrap_err().reason, Reason::BadTaskKind(9));
    let mut bytes = task_with(0, 0);
    let at = tasks_at(&bytes);
    bytes[at + 4] = 200; // name length beyond the blob
    assert_eq!(verdict(&bytes).unwrap_err().reason, Reason::BadName);
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 0);
    b.begin_pou(f);
    b.ret();
    b.end_pou(f);
    for _ in 0..=crate::verify::MAX_TASKS {
        b.add_task(&TaskDef {
            name: "t".into(),
            kind: TaskKind::Cyclic,
            priority: 0,
            pou: f,
            instance_base: 0,
            interval_ns: 1,
            watchdog_budget: 0,
        });
    }
    assert_eq!(
        verdict(&b.build().unwrap()).unwrap_err().reason,
        Reason::TooManyTasks
    );
}

fn var_image(ty: VarType, addr: u32, size: u32) -> Vec<u8> {
    program_with(10, |c, _| c.add_var("v", ty, 0, addr, size))
}

#[test]
fn variable_map_entries() {
    assert_eq!(verdict(&var_image(VarType::Int, 0, 2)), Ok(()));
    assert_eq!(verdict(&var_image(VarType::String, 0, 4 + 80)), Ok(()));
    assert_eq!(
        verdict(&var_image(VarType::Int, DATA - 1, 2))
            .unwrap_err()
            .reason,
        Reason::VarOutsideData
    );
    assert_eq!(
        verdict(&var_image(VarType::Int, 0, 4)).unwrap_err().reason,
        Reason::VarSizeMismatch
    );
    assert_eq!(
        verdict(&var_image(VarType::String, 0, 3))
            .unwrap_err()
            .reason,
        Reason::VarSizeMismatch
    );
    // The date/time types, characters, WSTRINGs and references: each size checked.
    for (ty, good, bad) in [
        (VarType::Date, 8, 4),
        (VarType::Tod, 8, 2),
        (VarType::LDt, 8, 16),
        (VarType::Char, 1, 2),
        (VarType::WChar, 2, 1),
        (VarType::WString, 4 + 2 * 10, 4 + 9),
        (VarType::WString, 4, 3),
        (VarType::Ref, 8, 4),
    ] {
        assert_eq!(verdict(&var_image(ty, 0, good)), Ok(()), "{ty:?}");
        assert_eq!(
            verdict(&var_image(ty, 0, bad)).unwrap_err().reason,
            Reason::VarSizeMismatch,
            "{ty:?} of {bad} bytes"
        );
    }
    let mut bytes = var_image(VarType::Int, 0, 2);
    let at = u32::from_le_bytes(bytes[16 + 5 * 8..16 + 5 * 8 + 4].try_into().unwrap()) as usize;
    bytes[at + 6] = 99;
    assert_eq!(verdict(&bytes).unwrap_err().reason, Reason::BadVarType(99));
    // The first code after the last known one is unknown, and says so.
    bytes[at + 6] = VarType::Ref.code() + 1;
    let error = verdict(&bytes).unwrap_err();
    assert_eq!(error.reason, Reason::BadVarType(28));
    assert!(
        error
            .to_string()
            .contains("unknown variable type code 28 (known: 0 to 27"),
        "{error}"
    );
    let names = u32::from_le_bytes(bytes[16 + 8 * 8..16 + 8 * 8 + 4].try_into().unwrap()) as usize;
    let mut bytes = var_image(VarType::Int, 0, 2);
    bytes[names] = 0xFF; // not UTF-8
    assert_eq!(verdict(&bytes).unwrap_err().reason, Reason::BadName);
}

#[test]
fn source_locations() {
    let with_locs = |bad_file: bool| {
        program_with(10, |c, _| {
            let file = c.add_file("a.st");
            c.source_location(if bad_file { file + 1 } else { file }, 1, 1);
            c.nop();
            c.source_location(file, 2, 1);
        })
    };
    assert_eq!(verdict(&with_locs(false)), Ok(()));
    assert_eq!(
        verdict(&with_locs(true)).unwrap_err().reason,
        Reason::SrcLocInvalid
    );
    let mut bytes = with_locs(false);
    let at = u32::from_le_bytes(bytes[16 + 6 * 8..16 + 6 * 8 + 4].try_into().unwrap()) as usize;
    bytes[at] = 2; // first record (offset 2 = end of code) after the second (offset 1)
    assert_eq!(verdict(&bytes).unwrap_err().reason, Reason::SrcLocUnsorted);
}

#[test]
fn scratch_too_small() {
    let bytes = program_with(10, |c, _| c.nop());
    let image = Image::parse(&bytes).unwrap();
    let mut scratch = [0u32; 1];
    assert_eq!(
        crate::verify::verify_with_scratch(&image, &mut scratch)
            .unwrap_err()
            .reason,
        Reason::ScratchTooSmall
    );
    let mut scratch = [0u32; 3];
    assert_eq!(
        crate::verify::verify_with_scratch(&image, &mut scratch)
            .unwrap_err()
            .reason,
        Reason::ScratchTooSmall,
        "two words per code byte"
    );
    let mut scratch = [0u32; 4];
    assert!(crate::verify::verify_with_scratch(&image, &mut scratch).is_ok());
}

#[test]
fn parser_structural_errors() {
    let good = program_with(10, |c, _| c.nop());
    assert_eq!(
        Image::parse(&good[..HEADER_LEN - 1]).unwrap_err(),
        ImageError::TooShort
    );
    let mut bad = good.clone();
    bad[0] = b'X';
    assert_eq!(Image::parse(&bad).unwrap_err(), ImageError::BadMagic);
    let mut bad = good.clone();
    bad[4] = 1;
    assert_eq!(
        Image::parse(&bad).unwrap_err(),
        ImageError::UnsupportedVersion(1)
    );
    let mut bad = good.clone();
    bad[6] = 1;
    assert!(matches!(
        Image::parse(&bad).unwrap_err(),
        ImageError::BadHeaderLength(_)
    ));
    let mut bad = good.clone();
    bad[20] = 0xFF; // code length
    assert!(matches!(
        Image::parse(&bad).unwrap_err(),
        ImageError::SectionOutOfBounds(_)
    ));
    let mut bad = good.clone();
    bad[16 + 3 * 8 + 4] += 1; // POU section length: ragged
    assert!(matches!(
        Image::parse(&bad),
        Err(ImageError::RaggedSection(_) | ImageError::SectionOutOfBounds(_))
    ));
    let mut bad = good.clone();
    bad[8..12].copy_from_slice(&0u32.to_le_bytes()); // data size 0 < init? (no init here) -> still fine
    let _ = Image::parse(&bad);
    let mut b = ImageBuilder::new();
    b.set_init(0, &[1, 2, 3]);
    let mut bytes = b.build().unwrap();
    bytes[8] = 2;
    assert_eq!(
        Image::parse(&bytes).unwrap_err(),
        ImageError::InitLargerThanData
    );
}

#[test]
fn verification_is_linear_on_long_backward_jump_chains() {
    // Each block jumps back to the previous one: a fixpoint of linear passes would need one
    // pass per block (quadratic); the worklist visits each instruction once.
    let blocks = 20_000;
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 0);
    b.begin_pou(f);
    let labels: Vec<_> = (0..=blocks).map(|_| b.new_label()).collect();
    b.jmp(labels[blocks]);
    b.bind(labels[0]);
    b.ret();
    for i in 1..=blocks {
        b.bind(labels[i]);
        b.jmp(labels[i - 1]);
    }
    b.end_pou(f);
    let bytes = b.build().unwrap();
    let start = std::time::Instant::now();
    assert_eq!(verdict(&bytes), Ok(()));
    assert!(
        start.elapsed() < std::time::Duration::from_secs(2),
        "took {:?}",
        start.elapsed()
    );
}

#[test]
fn disassembly() {
    use crate::isa::{Builtin, Trap, instructions};
    use alloc::string::String;
    use core::fmt::Write;
    let mut b = ImageBuilder::new();
    let f = b.declare_pou("f", 0, 0, 16);
    b.begin_pou(f);
    let l = b.new_label();
    b.bind(l);
    b.push_i32(-3);
    b.st_rel(MemType::I16, 4);
    b.push_f64(2.0);
    b.call_builtin(Builtin::SqrtF64);
    b.drop_();
    b.throw(Trap::NumericError);
    b.jmp(l);
    b.end_pou(f);
    let bytes = b.build().unwrap();
    let image = Image::parse(&bytes).unwrap();
    let mut text = String::new();
    for insn in instructions(image.code()) {
        writeln!(text, "{:4} {insn}", insn.offset).unwrap();
    }
    assert_eq!(
        text,
        "   0 PUSH_I32 -3\n   5 ST_REL I16 4\n  11 PUSH_I64 4611686018427387904\n  20 CALL_BUILTIN SQRT_LREAL\n  23 DROP\n  24 THROW NUMERIC_ERROR\n  26 JMP @0\n"
    );
}

#[test]
fn located_records() {
    use crate::located::{Area, Located, Location, Width};
    let image_with = |v: Located| program_with(10, |b, _| b.add_located(&v));
    let good = Located {
        location: Location::parse("QW3").unwrap(),
        address: DATA - 2,
    };
    let bytes = image_with(good);
    assert_eq!(verdict(&bytes), Ok(()));
    let image = Image::parse(&bytes).unwrap();
    assert_eq!(image.located_vars().collect::<alloc::vec::Vec<_>>(), [good]);
    let located = |location: Location, address: u32, reason: Reason| {
        assert_eq!(
            verdict(&image_with(Located { location, address })),
            Err(VerifyError {
                site: Site::Located(0),
                reason
            })
        );
    };
    let word = good.location;
    located(word, DATA - 1, Reason::LocatedOutsideData);
    located(Location { bit: 1, ..word }, 0, Reason::BadLocation);
    let bit = Location {
        area: Area::Input,
        width: Width::Bit,
        byte: 0,
        bit: 8,
    };
    located(bit, 0, Reason::BadLocation);
    located(Location { byte: 4095, ..word }, 0, Reason::BadLocation);
    // An unknown area code: the record cannot be read, the verifier refuses it.
    let mut bytes = image_with(good);
    let located_section = crate::isa::read_u32(&bytes, 16 + 9 * 8) as usize;
    bytes[located_section + 8] = 7;
    assert_eq!(
        verdict(&bytes),
        Err(VerifyError {
            site: Site::Located(0),
            reason: Reason::BadLocation
        })
    );
}

#[test]
fn event_trigger_inside_data() {
    let good = program_with(10, |b, _| b.set_task_trigger(0, DATA - 1));
    assert_eq!(verdict(&good), Ok(()));
    assert_eq!(
        Image::parse(&good).unwrap().task(0).unwrap().trigger,
        Some(DATA - 1)
    );
    let bad = program_with(10, |b, _| b.set_task_trigger(0, DATA));
    assert_eq!(
        verdict(&bad),
        Err(VerifyError {
            site: Site::Task(0),
            reason: Reason::TriggerOutsideData
        })
    );
}

#[test]
fn shared_records() {
    use crate::image::{SharedDirection, SourceLocation};
    let at = |line| SourceLocation {
        file: 0,
        line,
        column: 5,
    };
    // Variables: 0 = a DINT at 0, 1 = a LREAL at 8, 2 = a STRING at 16, 3 = a DINT at 2
    // (overlapping variable 0), 4 and 5 = BOOLs at 40 and 41.
    let image_with = |records: &[(u32, SharedDirection, SourceLocation)]| {
        program_with(10, |b, _| {
            b.add_file("a.st");
            b.add_var("count", VarType::DInt, 0, 0, 4);
            b.add_var("level", VarType::LReal, 0, 8, 8);
            b.add_var("text", VarType::String, 0, 16, 12);
            b.add_var("odd", VarType::DInt, 0, 2, 4);
            b.add_var("ok", VarType::Bool, 0, 40, 1);
            b.add_var("ok2", VarType::Bool, 0, 41, 1);
            for &(var, direction, location) in records {
                b.add_shared(var, direction, location);
            }
        })
    };
    let good = image_with(&[
        (0, SharedDirection::Write, at(3)),
        (1, SharedDirection::Read, at(4)),
    ]);
    assert_eq!(verdict(&good), Ok(()));
    let image = Image::parse(&good).unwrap();
    let shared: alloc::vec::Vec<_> = image.shared_vars().collect();
    assert_eq!(shared.len(), 2);
    assert_eq!(
        (shared[0].var.name, shared[0].direction, shared[0].location),
        ("count", SharedDirection::Write, at(3))
    );
    assert_eq!(
        (shared[1].var.name, shared[1].var.addr, shared[1].direction),
        ("level", 8, SharedDirection::Read)
    );
    let refused = |records: &[(u32, SharedDirection, SourceLocation)], index, reason| {
        assert_eq!(
            verdict(&image_with(records)),
            Err(VerifyError {
                site: Site::Shared(index),
                reason
            })
        );
    };
    let w = SharedDirection::Write;
    // An unknown variable record, a STRING, a declaration in an unknown file.
    refused(&[(9, w, at(1))], 0, Reason::BadShared);
    refused(&[(2, w, at(1))], 0, Reason::BadShared);
    refused(
        &[(0, w, SourceLocation { file: 3, ..at(1) })],
        0,
        Reason::BadShared,
    );
    // The same variable twice, two variables sharing bytes.
    refused(
        &[(0, w, at(1)), (0, SharedDirection::Read, at(2))],
        1,
        Reason::SharedOverlap,
    );
    refused(&[(0, w, at(1)), (3, w, at(2))], 1, Reason::SharedOverlap);
    // A validity flag must be a BOOL, and there is at most one.
    let v = SharedDirection::Valid;
    assert_eq!(
        verdict(&image_with(&[
            (4, v, at(1)),
            (1, SharedDirection::Read, at(2))
        ])),
        Ok(())
    );
    refused(&[(0, v, at(1))], 0, Reason::BadShared);
    refused(&[(4, v, at(1)), (5, v, at(2))], 1, Reason::SharedOverlap);
    // An unknown direction code.
    let mut bytes = image_with(&[(0, w, at(1))]);
    let section = crate::isa::read_u32(&bytes, 16 + 10 * 8) as usize;
    bytes[section + 4] = 3;
    assert_eq!(
        verdict(&bytes),
        Err(VerifyError {
            site: Site::Shared(0),
            reason: Reason::BadShared
        })
    );
    // Too many records.
    let many: alloc::vec::Vec<_> = (0..=crate::image::MAX_SHARED_VARS)
        .map(|i| (0, w, at(i as u32)))
        .collect();
    assert_eq!(
        verdict(&image_with(&many)),
        Err(VerifyError {
            site: Site::Image,
            reason: Reason::BadShared
        })
    );
}

#[test]
fn superinstruction_operands() {
    // SEL_IF and the immediate jumps need a comparison, OP_* a binary operator.
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.push_i32(2);
        c.emit_raw(&[Opcode::SelIf as u8, Opcode::Add as u8, Opcode::Drop as u8]);
    });
    assert_eq!(e.reason, Reason::BadComparison(Opcode::Add as u8));
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.emit_raw(&[Opcode::OpImm as u8, Opcode::Neg as u8, 1, 0, 0, 0]);
        c.drop_();
    });
    assert_eq!(e.reason, Reason::BadOperator(Opcode::Neg as u8));
    assert_eq!(
        e.to_string(),
        "at code offset 5: operand 0x27 is not a binary operator"
    );
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.emit_raw(&[Opcode::OpRel as u8, Opcode::Add as u8, 12, 0, 0, 0, 0]);
        c.drop_();
    });
    assert_eq!(e.reason, Reason::BadType(12));
    // INC needs an integer type.
    let e = rejects(|c, _| c.inc(true, MemType::F32, 0, 1));
    assert_eq!(e.reason, Reason::BadType(MemType::F32 as u8));
    let e = rejects(|c, _| {
        c.push_i32(0);
        c.emit_raw(&[Opcode::LdElemRel as u8, 10]);
        c.emit_raw(&[0; 24]);
        c.drop_();
    });
    assert_eq!(e.reason, Reason::BadType(10));
}

#[test]
fn superinstruction_addresses() {
    // Static addresses: as LD_ABS (data) and LD_REL (frame).
    let e = rejects(|c, _| c.inc(false, MemType::I32, DATA - 2, 1));
    assert!(matches!(e.reason, Reason::AddressOutsideData { .. }));
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.op_at(false, Opcode::Add, MemType::I64, DATA - 4);
        c.drop_();
    });
    assert!(matches!(e.reason, Reason::AddressOutsideData { .. }));
    let e = rejects(|c, _| c.inc(true, MemType::I16, MAIN_FRAME - 1, 1));
    assert!(matches!(e.reason, Reason::OffsetOutsideFrame { .. }));
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.op_at(true, Opcode::Mul, MemType::U32, MAIN_FRAME);
        c.drop_();
    });
    assert!(matches!(e.reason, Reason::OffsetOutsideFrame { .. }));
    let e = rejects(|c, _| {
        c.op_rel_rel(
            Opcode::Add,
            (MemType::I32, 0),
            (MemType::I64, MAIN_FRAME - 4),
        );
        c.drop_();
    });
    assert!(matches!(e.reason, Reason::OffsetOutsideFrame { .. }));
    let e = rejects(|c, _| {
        let l = c.new_label();
        c.push_i32(0);
        c.st_rel(MemType::I32, 0);
        c.ld_rel(MemType::I32, MAIN_FRAME - 2);
        c.jump_if_imm(true, Opcode::Eq, 0, l);
        c.bind(l);
    });
    assert!(matches!(e.reason, Reason::OffsetOutsideFrame { .. }));
    // The index variable of the _AT forms lies in the frame and has a valid type.
    let e = rejects(|c, _| {
        c.elem_at(true, None, 0, 0, 3, 4, (MemType::I16, MAIN_FRAME - 1));
        c.drop_();
    });
    assert!(matches!(e.reason, Reason::OffsetOutsideFrame { .. }));
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.emit_raw(&[Opcode::StElemAbsAt as u8, MemType::I8 as u8]);
        c.emit_raw(&[0; 24]);
        c.emit_raw(&[11, 0, 0, 0, 0]);
    });
    assert_eq!(e.reason, Reason::BadType(11));
    // Immediate jumps: targets and stack depths as JUMP_IF.
    let e = rejects(|c, _| {
        c.push_i32(1);
        c.emit_raw(&[
            Opcode::JumpIfImm as u8,
            Opcode::Eq as u8,
            0,
            0,
            0,
            0,
            1,
            0,
            0,
            0,
        ]);
    });
    assert_eq!(e.reason, Reason::TargetInsideInstruction(1));
    let e = rejects(|c, _| {
        let l = c.new_label();
        c.jump_if_imm(true, Opcode::Eq, 0, l);
        c.bind(l);
    });
    assert_eq!(
        e.reason,
        Reason::StackUnderflow {
            depth: 0,
            needed: 1
        }
    );
}
