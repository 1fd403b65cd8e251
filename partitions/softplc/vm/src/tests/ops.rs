//! One test per opcode family: each asserts concrete results (VM and model both).

use super::*;
use crate::isa::{MemType, Opcode, RoundMode};

fn bin(a: i64, b: i64, op: Opcode) -> i64 {
    eval(|c| {
        c.disable_fusion(); // test the plain opcode, not ADD_IMM
        c.push_int(a);
        c.push_int(b);
        c.op(op);
    }) as i64
}

fn fbin32(a: f32, b: f32, op: Opcode) -> u64 {
    eval(|c| {
        c.push_f32(a);
        c.push_f32(b);
        c.op(op);
    })
}

fn fbin64(a: f64, b: f64, op: Opcode) -> u64 {
    eval(|c| {
        c.push_f64(a);
        c.push_f64(b);
        c.op(op);
    })
}

#[test]
fn pushes_and_constants() {
    assert_eq!(eval(|c| c.push_i32(-5)) as i64, -5);
    assert_eq!(eval(|c| c.push_u32(0xFFFF_FFFF)), 0xFFFF_FFFF);
    assert_eq!(eval(|c| c.push_i64(i64::MIN)) as i64, i64::MIN);
    assert_eq!(
        eval(|c| {
            let k = c.add_const(0xDEAD_BEEF_0123_4567);
            c.push_const(k);
        }),
        0xDEAD_BEEF_0123_4567
    );
}

#[test]
fn stack_shuffles() {
    // 10 - 3 via SWAP: push 3, push 10, swap -> [10 3], sub = 7
    assert_eq!(
        eval(|c| {
            c.push_i32(3);
            c.push_i32(10);
            c.swap();
            c.op(Opcode::Sub);
        }),
        7
    );
    // OVER: [2 5] -> [2 5 2]; sub -> [2 3]; mul -> 6
    assert_eq!(
        eval(|c| {
            c.push_i32(2);
            c.push_i32(5);
            c.over();
            c.op(Opcode::Sub);
            c.op(Opcode::Mul);
        }),
        6
    );
    // DUP then DROP
    assert_eq!(
        eval(|c| {
            c.push_i32(4);
            c.dup();
            c.op(Opcode::Mul);
            c.push_i32(99);
            c.drop_();
        }),
        16
    );
}

#[test]
fn integer_arithmetic_wraps_and_divides() {
    assert_eq!(bin(2, 3, Opcode::Add), 5);
    assert_eq!(bin(i64::MAX, 1, Opcode::Add), i64::MIN);
    assert_eq!(bin(2, 3, Opcode::Sub), -1);
    assert_eq!(bin(-4, 3, Opcode::Mul), -12);
    assert_eq!(bin(-7, 2, Opcode::DivS), -3);
    assert_eq!(bin(-7, 2, Opcode::ModS), -1);
    assert_eq!(bin(i64::MIN, -1, Opcode::DivS), i64::MIN);
    assert_eq!(bin(i64::MIN, -1, Opcode::ModS), 0);
    assert_eq!(bin(-1, 2, Opcode::DivU), (u64::MAX / 2) as i64);
    assert_eq!(bin(-1, 10, Opcode::ModU), (u64::MAX % 10) as i64);
    assert_eq!(
        eval(|c| {
            c.push_i32(5);
            c.op(Opcode::Neg)
        }) as i64,
        -5
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(-5);
            c.op(Opcode::AbsS)
        }) as i64,
        5
    );
    assert_eq!(
        eval(|c| {
            c.push_i64(i64::MIN);
            c.op(Opcode::AbsS)
        }) as i64,
        i64::MIN
    );
}

#[test]
fn bit_operations_and_shifts() {
    assert_eq!(bin(0b1100, 0b1010, Opcode::And), 0b1000);
    assert_eq!(bin(0b1100, 0b1010, Opcode::Or), 0b1110);
    assert_eq!(bin(0b1100, 0b1010, Opcode::Xor), 0b0110);
    assert_eq!(
        eval(|c| {
            c.push_i32(0);
            c.op(Opcode::Not)
        }),
        u64::MAX
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(0);
            c.op(Opcode::NotBool)
        }),
        1
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(7);
            c.op(Opcode::NotBool)
        }),
        0
    );
    assert_eq!(bin(1, 4, Opcode::Shl), 16);
    assert_eq!(bin(1, 64, Opcode::Shl), 0);
    assert_eq!(bin(-16, 2, Opcode::ShrS), -4);
    assert_eq!(bin(-1, 100, Opcode::ShrS), -1);
    assert_eq!(bin(-16, 60, Opcode::ShrU), 15);
    assert_eq!(bin(-16, 64, Opcode::ShrU), 0);
    let rot = |a: i64, n: i64, w: u8, op: Opcode| {
        eval(|c| {
            c.push_int(a);
            c.push_int(n);
            c.op_width(op, w);
        })
    };
    assert_eq!(rot(0x81, 1, 8, Opcode::Rol), 0x03);
    assert_eq!(rot(0x81, 1, 8, Opcode::Ror), 0xC0);
    assert_eq!(rot(0x8001, 17, 16, Opcode::Rol), 0x0003);
    assert_eq!(rot(1, 1, 64, Opcode::Ror), 1 << 63);
    assert_eq!(rot(0x1_0000_0001, 4, 32, Opcode::Rol), 0x10);
}

#[test]
fn width_wrapping() {
    assert_eq!(
        eval(|c| {
            c.push_i32(0x1FF);
            c.op_width(Opcode::Sext, 8)
        }) as i64,
        -1
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(32767 + 1);
            c.op_width(Opcode::Sext, 16)
        }) as i64,
        -32768
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(-1);
            c.op_width(Opcode::Zext, 16)
        }),
        0xFFFF
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(-1);
            c.op_width(Opcode::Zext, 32)
        }),
        0xFFFF_FFFF
    );
}

#[test]
fn comparisons_signed_unsigned_and_select() {
    assert_eq!(bin(-1, 1, Opcode::LtS), 1);
    assert_eq!(bin(-1, 1, Opcode::LtU), 0);
    assert_eq!(bin(3, 3, Opcode::LeS), 1);
    assert_eq!(bin(3, 3, Opcode::GtS), 0);
    assert_eq!(bin(-1, 1, Opcode::GtU), 1);
    assert_eq!(bin(3, 4, Opcode::GeS), 0);
    assert_eq!(bin(3, 4, Opcode::GeU), 0);
    assert_eq!(bin(4, 4, Opcode::LeU), 1);
    assert_eq!(bin(4, 4, Opcode::Eq), 1);
    assert_eq!(bin(4, 5, Opcode::Ne), 1);
    let sel = |g: i32| {
        eval(|c| {
            c.push_i32(g);
            c.push_i32(10);
            c.push_i32(20);
            c.op(Opcode::Sel);
        })
    };
    assert_eq!(sel(0), 10);
    assert_eq!(sel(1), 20);
}

#[test]
fn real_arithmetic_rounds_to_f32() {
    let r = |cell: u64| f32::from_bits(cell as u32);
    assert_eq!(r(fbin32(0.1, 0.2, Opcode::AddF32)), 0.1f32 + 0.2f32);
    assert_eq!(r(fbin32(1.0, 3.0, Opcode::DivF32)), 1.0f32 / 3.0);
    assert_eq!(r(fbin32(1.5, 4.0, Opcode::MulF32)), 6.0);
    assert_eq!(r(fbin32(1.5, 4.0, Opcode::SubF32)), -2.5);
    assert_eq!(
        fbin32(1.5, 4.0, Opcode::SubF32) >> 32,
        0,
        "upper half of a REAL cell is zero"
    );
    assert_eq!(
        r(eval(|c| {
            c.push_f32(2.0);
            c.op(Opcode::NegF32)
        })),
        -2.0
    );
    assert_eq!(fbin32(1.0, 2.0, Opcode::LtF32), 1);
    assert_eq!(fbin32(f32::NAN, f32::NAN, Opcode::EqF32), 0);
    assert_eq!(fbin32(f32::NAN, 1.0, Opcode::NeF32), 1);
    assert_eq!(fbin32(2.0, 2.0, Opcode::LeF32), 1);
    assert_eq!(fbin32(2.0, 2.0, Opcode::GtF32), 0);
    assert_eq!(fbin32(2.0, 2.0, Opcode::GeF32), 1);
}

#[test]
fn lreal_arithmetic() {
    let r = f64::from_bits;
    assert_eq!(r(fbin64(0.1, 0.2, Opcode::AddF64)), 0.1 + 0.2);
    assert_eq!(r(fbin64(1.0, 3.0, Opcode::DivF64)), 1.0 / 3.0);
    assert_eq!(r(fbin64(1.5, 4.0, Opcode::MulF64)), 6.0);
    assert_eq!(r(fbin64(1.5, 4.0, Opcode::SubF64)), -2.5);
    assert_eq!(
        r(eval(|c| {
            c.push_f64(2.0);
            c.op(Opcode::NegF64)
        })),
        -2.0
    );
    assert_eq!(fbin64(1.0, 2.0, Opcode::LtF64), 1);
    assert_eq!(fbin64(1.0, 1.0, Opcode::EqF64), 1);
    assert_eq!(fbin64(1.0, 1.0, Opcode::NeF64), 0);
    assert_eq!(fbin64(1.0, 2.0, Opcode::LeF64), 1);
    assert_eq!(fbin64(3.0, 2.0, Opcode::GtF64), 1);
    assert_eq!(fbin64(1.0, 2.0, Opcode::GeF64), 0);
}

#[test]
fn conversions() {
    let f32r = |cell: u64| f32::from_bits(cell as u32);
    assert_eq!(
        f32r(eval(|c| {
            c.push_i32(-3);
            c.op(Opcode::IToF32S)
        })),
        -3.0
    );
    assert_eq!(
        f32r(eval(|c| {
            c.push_i32(-1);
            c.op(Opcode::IToF32U)
        })),
        u64::MAX as f32
    );
    assert_eq!(
        f64::from_bits(eval(|c| {
            c.push_i32(-3);
            c.op(Opcode::IToF64S)
        })),
        -3.0
    );
    assert_eq!(
        f64::from_bits(eval(|c| {
            c.push_i32(-1);
            c.op(Opcode::IToF64U)
        })),
        u64::MAX as f64
    );
    assert_eq!(
        f64::from_bits(eval(|c| {
            c.push_f32(0.1);
            c.op(Opcode::F32ToF64)
        })),
        0.1f32 as f64
    );
    assert_eq!(
        f32r(eval(|c| {
            c.push_f64(0.1);
            c.op(Opcode::F64ToF32)
        })),
        0.1f32
    );
    let to_int = |x: f64, ty: MemType, mode: RoundMode| {
        eval(|c| {
            c.push_f64(x);
            c.float_to_int(Opcode::F64ToInt, ty, mode);
        }) as i64
    };
    assert_eq!(to_int(2.5, MemType::I16, RoundMode::NearestTiesAway), 3);
    assert_eq!(to_int(-2.5, MemType::I16, RoundMode::NearestTiesAway), -3);
    assert_eq!(to_int(2.4999, MemType::I16, RoundMode::NearestTiesAway), 2);
    assert_eq!(to_int(-2.7, MemType::I32, RoundMode::Truncate), -2);
    assert_eq!(to_int(255.4, MemType::U8, RoundMode::Truncate), 255);
    assert_eq!(
        to_int(-9.2e18, MemType::I64, RoundMode::Truncate),
        -9_200_000_000_000_000_000
    );
    let from_real = eval(|c| {
        c.push_f32(-1.5);
        c.float_to_int(Opcode::F32ToInt, MemType::I8, RoundMode::NearestTiesAway);
    });
    assert_eq!(from_real as i64, -2);
}

#[test]
fn loads_and_stores_extend_and_truncate() {
    // store 0x1FF as U8 -> 0xFF; load as I8 -> -1, as U8 -> 255
    let load_as = |ty: MemType| {
        eval(|c| {
            c.push_i32(0x1FF);
            c.st_abs(MemType::U16, 100);
            c.ld_abs(ty, 100);
        }) as i64
    };
    assert_eq!(load_as(MemType::I8), -1);
    assert_eq!(load_as(MemType::U8), 255);
    assert_eq!(load_as(MemType::U16), 0x1FF);
    assert_eq!(load_as(MemType::I16), 0x1FF);
    let wrap_int = eval(|c| {
        c.push_i32(32767);
        c.push_i32(1);
        c.op(Opcode::Add);
        c.st_abs(MemType::I16, 100);
        c.ld_abs(MemType::I16, 100);
    });
    assert_eq!(
        wrap_int as i64, -32768,
        "INT overflow wraps to the declared width"
    );
    for ty in MemType::ALL {
        let v = eval(|c| {
            c.push_i64(-2);
            c.st_abs(ty, 104);
            c.ld_abs(ty, 104);
        });
        let expected = match ty.width() {
            8 => -2i64 as u64,
            w => {
                let masked = (-2i64 as u64) & ((1u64 << (8 * w)) - 1);
                if matches!(ty, MemType::I8 | MemType::I16 | MemType::I32) {
                    -2i64 as u64
                } else {
                    masked
                }
            }
        };
        assert_eq!(v, expected, "{ty:?}");
    }
}

#[test]
fn frame_relative_and_indirect_addressing() {
    // ST_REL writes base + off; LEA_REL + LD_IND reads it back; LD_ABS sees it at MAIN_BASE + off.
    assert_eq!(
        eval(|c| {
            c.push_i32(1234);
            c.st_rel(MemType::I32, 8);
            c.lea_rel(8);
            c.ld_ind(MemType::I32, 0);
            c.ld_abs(MemType::I32, MAIN_BASE + 8);
            c.op(Opcode::Add);
        }),
        2468
    );
    // ST_IND with an offset, LD_REL reads it.
    assert_eq!(
        eval(|c| {
            c.push_u32(MAIN_BASE);
            c.push_i32(-7);
            c.st_ind(MemType::I16, 4);
            c.ld_rel(MemType::I16, 4);
        }) as i64,
        -7
    );
    // LEA_REL gives base + offset.
    assert_eq!(eval(|c| c.lea_rel(12)), (MAIN_BASE + 12) as u64);
}

#[test]
fn copy_moves_blocks_with_overlap() {
    let out = eval(|c| {
        c.push_i64(0x0807_0605_0403_0201);
        c.st_abs(MemType::U64, 200);
        c.push_u32(202);
        c.push_u32(200);
        c.copy(6);
        c.ld_abs(MemType::U64, 200);
    });
    assert_eq!(out, 0x0605_0403_0201_0201);
}

#[test]
fn now_is_the_cycle_time() {
    let bytes = program_with(1000, |c, _| {
        c.now();
        c.st_abs(MemType::I64, 0);
    });
    let out = run_both(&bytes, 3);
    assert_eq!(
        i64::from_le_bytes(out.data[0..8].try_into().unwrap()),
        20_000_000
    );
}

#[test]
fn jumps() {
    // sum 1..=5 with a loop: counter on the stack.
    let sum = eval(|c| {
        c.push_i32(0);
        c.st_abs(MemType::I64, 8);
        c.push_i32(5);
        let top = c.new_label();
        let done = c.new_label();
        c.bind(top);
        c.dup();
        c.jz(done);
        c.dup();
        c.ld_abs(MemType::I64, 8);
        c.op(Opcode::Add);
        c.st_abs(MemType::I64, 8);
        c.push_i32(1);
        c.op(Opcode::Sub);
        c.jmp(top);
        c.bind(done);
        c.drop_();
        c.ld_abs(MemType::I64, 8);
    });
    assert_eq!(sum, 15);
    let taken = eval(|c| {
        let skip = c.new_label();
        c.push_i32(1);
        c.push_i32(1);
        c.jnz(skip);
        c.drop_();
        c.push_i32(2);
        c.bind(skip);
    });
    assert_eq!(taken, 1);
}

#[test]
fn calls_pass_arguments_results_and_bases() {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    // add3(x, y) with frame at 400: stores y into its frame, returns x + y + frame[0..4] (init 0)
    let add = b.declare_pou("add", 2, 1, 16);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: MAIN_BASE,
        interval_ns: 1,
        watchdog_budget: 0,
    });
    b.begin_pou(main);
    b.push_i32(1);
    b.st_rel(MemType::I32, 0); // Main's frame[0] = 1 (must survive the call: base restored)
    b.push_i32(40);
    b.push_i32(2);
    b.push_u32(400);
    b.call(add);
    b.st_abs(MemType::I64, 0);
    b.ld_rel(MemType::I32, 0);
    b.st_abs(MemType::I64, 8);
    b.ret();
    b.end_pou(main);
    b.begin_pou(add);
    b.dup();
    b.st_rel(MemType::I32, 4); // frame 400 + 4 = y
    b.op(Opcode::Add);
    b.ld_rel(MemType::I32, 0);
    b.op(Opcode::Add);
    b.ret();
    b.end_pou(add);
    let out = run_both(&b.build().unwrap(), 1);
    assert!(out.result.is_ok());
    assert_eq!(u64::from_le_bytes(out.data[0..8].try_into().unwrap()), 42);
    assert_eq!(u64::from_le_bytes(out.data[8..16].try_into().unwrap()), 1);
    assert_eq!(
        i32::from_le_bytes(out.data[404..408].try_into().unwrap()),
        2
    );
}

#[test]
fn index_computes_element_addresses() {
    // ARRAY[-2..5] OF DINT at 100: element 3 is at 100 + (3 - -2) * 4 = 120
    assert_eq!(
        eval(|c| {
            c.push_u32(100);
            c.push_i32(3);
            c.index(-2, 5, 4);
        }),
        120
    );
    assert_eq!(
        eval(|c| {
            c.push_u32(100);
            c.push_i32(-2);
            c.index(-2, 5, 4);
        }),
        100
    );
}

#[test]
fn checks_pass_values_in_range() {
    assert_eq!(
        eval(|c| {
            c.push_i32(3);
            c.chk_index(1, 3)
        }),
        3
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(-5);
            c.chk_range_s(-5, 5)
        }) as i64,
        -5
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(-1);
            c.chk_range_u(0, u64::MAX)
        }),
        u64::MAX
    );
}

#[test]
fn try_catch_delivers_the_trap_code() {
    use crate::isa::Trap;
    let code = eval(|c| {
        let handler = c.new_label();
        let end = c.new_label();
        c.push_i32(77); // below the try depth: must survive
        c.try_begin(handler);
        c.push_i32(1);
        c.push_i32(2);
        c.push_i32(0);
        c.op(Opcode::DivS);
        c.drop_();
        c.drop_();
        c.try_end();
        c.push_i32(0);
        c.jmp(end);
        c.bind(handler);
        c.bind(end);
        // [77 code] -> code * 1000 + 77
        c.push_i32(1000);
        c.op(Opcode::Mul);
        c.op(Opcode::Add);
    });
    assert_eq!(code, Trap::DivisionByZero.code() as u64 * 1000 + 77);
}

#[test]
fn try_catch_unwinds_calls_and_rethrow_reaches_outer_handler() {
    use crate::isa::Trap;
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let bad = b.declare_pou("bad", 0, 1, 8);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: MAIN_BASE,
        interval_ns: 1,
        watchdog_budget: 0,
    });
    b.begin_pou(main);
    let outer = b.new_label();
    let inner = b.new_label();
    let done = b.new_label();
    b.try_begin(outer);
    b.try_begin(inner);
    b.push_u32(480);
    b.call(bad);
    b.drop_();
    b.try_end();
    b.try_end();
    b.push_i32(0);
    b.jmp(done);
    b.bind(inner);
    // inner handler: record, then rethrow (FINALLY without CATCH)
    b.dup();
    b.st_abs(MemType::U8, 1);
    b.rethrow();
    b.try_end();
    b.push_i32(0);
    b.jmp(done);
    b.bind(outer);
    b.bind(done);
    b.st_abs(MemType::U8, 2);
    b.ld_rel(MemType::U8, 0);
    b.st_abs(MemType::U8, 3);
    b.ret();
    b.end_pou(main);
    b.begin_pou(bad);
    b.push_i32(9);
    b.chk_index(0, 3);
    b.ret();
    b.end_pou(bad);
    let out = run_both(&b.build().unwrap(), 2);
    assert!(out.result.is_ok());
    assert_eq!(out.data[1], Trap::IndexOutOfBounds.code());
    assert_eq!(out.data[2], Trap::IndexOutOfBounds.code());
}

#[test]
fn rethrow_of_zero_is_a_no_op() {
    assert_eq!(
        eval(|c| {
            c.push_i32(0);
            c.rethrow();
            c.push_i32(5);
        }),
        5
    );
}

/// Emits the compiler's unfused array-address sequence.
fn index_sequence(c: &mut ImageBuilder, lo: i64, hi: i64, stride: i64) {
    c.chk_index(lo, hi);
    if lo != 0 {
        c.push_int(lo);
        c.op(Opcode::Sub);
    }
    if stride != 1 {
        c.push_int(stride);
        c.op(Opcode::Mul);
    }
    c.op(Opcode::Add);
}

fn disassemble(bytes: &[u8]) -> Vec<Opcode> {
    let image = Image::parse(bytes).unwrap();
    crate::isa::instructions(image.code())
        .map(|i| i.op)
        .collect()
}

#[test]
fn builder_fuses_array_index_sequences_into_index() {
    for (lo, stride) in [(0, 1), (0, 4), (-3, 1), (5, 12)] {
        let bytes = program_with(100, |c, _| {
            c.push_u32(64);
            c.push_i32(6);
            index_sequence(c, lo, 10, stride);
            c.st_abs(MemType::U64, 0);
        });
        assert_eq!(
            disassemble(&bytes),
            [
                Opcode::PushU32,
                Opcode::PushI32,
                Opcode::Index,
                Opcode::StAbs,
                Opcode::Ret
            ],
            "lo {lo} stride {stride}"
        );
        let out = run_both(&bytes, 1);
        let address = u64::from_le_bytes(out.data[0..8].try_into().unwrap());
        assert_eq!(address as i64, 64 + (6 - lo) * stride);
    }
    // A label inside the sequence (a jump target) or a mismatching lower bound prevents it.
    let bytes = program_with(100, |c, _| {
        c.push_u32(64);
        c.push_i32(6);
        c.chk_index(0, 10);
        let l = c.new_label();
        c.bind(l);
        c.op(Opcode::Add);
        c.st_abs(MemType::U64, 0);
    });
    assert!(!disassemble(&bytes).contains(&Opcode::Index));
    let bytes = program_with(100, |c, _| {
        c.push_u32(64);
        c.push_i32(6);
        c.chk_index(1, 10);
        c.push_i32(2);
        c.op(Opcode::Sub);
        c.op(Opcode::Add);
        c.st_abs(MemType::U64, 0);
    });
    assert!(!disassemble(&bytes).contains(&Opcode::Index));
}

#[test]
fn fused_and_unfused_index_sequences_behave_the_same() {
    let mut rng = super::differential::Rng::new(3);
    for _ in 0..300 {
        let lo = rng.below(20) as i64 - 10;
        let hi = lo + rng.below(10) as i64;
        let stride = rng.pick(&[1i64, 2, 4, 8, 100, 0x1_0000]);
        let index = rng.pick(&[lo - 1, lo, hi, hi + 1, (lo + hi) / 2, i64::MIN, i64::MAX]);
        let base = rng.next() as i64;
        let run = |fuse: bool| {
            let bytes = program_with(100, |c, _| {
                if !fuse {
                    c.disable_fusion();
                }
                c.push_i64(base);
                c.push_i64(index);
                index_sequence(c, lo, hi, stride);
                c.st_abs(MemType::U64, 0);
            });
            let out = run_both(&bytes, 1);
            (
                out.result.map(|_| ()).map_err(|f| f.trap),
                out.data,
                out.stack,
            )
        };
        assert_eq!(
            run(true),
            run(false),
            "lo {lo} hi {hi} stride {stride} index {index}"
        );
    }
}

#[test]
fn add_immediate() {
    assert_eq!(
        eval(|c| {
            c.push_i32(40);
            c.add_imm(2)
        }),
        42
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(0);
            c.add_imm(-5)
        }) as i64,
        -5
    );
    assert_eq!(
        eval(|c| {
            c.push_i64(i64::MAX);
            c.add_imm(1)
        }) as i64,
        i64::MIN
    );
}

#[test]
fn fused_compare_and_jump() {
    use crate::isa::compare;
    let cases: [(Opcode, u64, u64); 8] = [
        (Opcode::LtS, -1i64 as u64, 1),
        (Opcode::LtU, -1i64 as u64, 1),
        (Opcode::GeS, 3, 3),
        (Opcode::Ne, 3, 3),
        (
            Opcode::LtF32,
            1.5f32.to_bits() as u64,
            2.5f32.to_bits() as u64,
        ),
        (Opcode::EqF64, f64::NAN.to_bits(), f64::NAN.to_bits()),
        (Opcode::GtF64, 2.0f64.to_bits(), 1.0f64.to_bits()),
        (Opcode::LeU, 7, 7),
    ];
    for (cmp, a, b) in cases {
        for when in [true, false] {
            let jumped = eval(|c| {
                let target = c.new_label();
                let end = c.new_label();
                c.push_i64(a as i64);
                c.push_i64(b as i64);
                c.jump_if(when, cmp, target);
                c.push_i32(0);
                c.jmp(end);
                c.bind(target);
                c.push_i32(1);
                c.bind(end);
            });
            assert_eq!(jumped == 1, compare(cmp, a, b) == when, "{cmp:?} {when}");
        }
    }
    // The builder fuses a comparison followed by JZ/JNZ.
    let bytes = program_with(100, |c, _| {
        let l = c.new_label();
        c.push_i32(1);
        c.push_i32(2);
        c.op(Opcode::LtS);
        c.jz(l);
        c.bind(l);
        c.ld_abs(MemType::I32, 0);
        c.push_i32(1);
        c.op(Opcode::Add);
        c.op_width(Opcode::Sext, 32);
        c.st_abs(MemType::I32, 0);
    });
    // `PUSH_I32 2; LT_S` is OP_IMM, which JZ turns into JUMP_IF_NOT_IMM; the load, ADD_IMM
    // and store of the same variable become INC_ABS (the SEXT before the store is dropped).
    assert_eq!(
        disassemble(&bytes),
        [
            Opcode::PushI32,
            Opcode::JumpIfNotImm,
            Opcode::IncAbs,
            Opcode::Ret
        ]
    );
    // Without an immediate: JUMP_IF_NOT.
    let bytes = program_with(100, |c, _| {
        let l = c.new_label();
        c.ld_abs(MemType::I32, 0);
        c.op(Opcode::Dup);
        c.op(Opcode::LtS);
        c.jz(l);
        c.bind(l);
    });
    assert_eq!(
        disassemble(&bytes),
        [Opcode::LdAbs, Opcode::Dup, Opcode::JumpIfNot, Opcode::Ret]
    );
}

#[test]
fn elements_are_addressed_loaded_and_stored() {
    // ARRAY[-2..5] OF INT at absolute 40: ELEM_ABS gives the address of element 3.
    assert_eq!(
        eval(|c| {
            c.push_i32(3);
            c.elem_abs(40, -2, 5, 2);
        }),
        50
    );
    // Frame-relative: base (MAIN_BASE) + offset + (i - lo) * stride.
    assert_eq!(
        eval(|c| {
            c.push_i32(1);
            c.elem_rel(8, 0, 3, 4);
        }),
        (MAIN_BASE + 12) as u64
    );
    // LD_ELEM extends as its type; ST_ELEM truncates.
    assert_eq!(
        eval(|c| {
            c.push_i32(2);
            c.push_i32(-5);
            c.st_elem(false, MemType::I16, 40, 1, 4, 2);
            c.push_i32(2);
            c.ld_elem(false, MemType::I16, 40, 1, 4, 2);
        }) as i64,
        -5
    );
    assert_eq!(
        eval(|c| {
            c.push_i32(0);
            c.push_u32(0x1_0000_00FF_u64 as u32);
            c.st_elem(true, MemType::U8, 16, 0, 7, 1);
            c.push_i32(0);
            c.ld_elem(true, MemType::U8, 16, 0, 7, 1);
        }),
        0xFF
    );
    let f = eval(|c| {
        c.push_i32(7);
        c.push_f32(2.5);
        c.st_elem(true, MemType::F32, 0, 5, 9, 4);
        c.push_i32(7);
        c.ld_elem(true, MemType::F32, 0, 5, 9, 4);
    });
    assert_eq!(f32::from_bits(f as u32), 2.5);
    // Indexed by a frame variable (an INT at offset 60).
    for rel in [true, false] {
        let array = if rel { 8 } else { 40 };
        let v = eval(|c| {
            c.push_i32(-2);
            c.st_rel(MemType::I16, 60);
            c.push_i32(-300);
            c.elem_at(
                rel,
                Some((MemType::I16, false)),
                array,
                -3,
                0,
                2,
                (MemType::I16, 60),
            );
            c.elem_at(rel, None, array, -3, 0, 2, (MemType::I16, 60));
            c.ld_ind(MemType::I16, 0);
            c.elem_at(
                rel,
                Some((MemType::I16, true)),
                array,
                -3,
                0,
                2,
                (MemType::I16, 60),
            );
            c.op(Opcode::Add);
        });
        assert_eq!(v as i64, -600);
    }
}

#[test]
fn increments_wrap_to_the_type() {
    let inc = |ty: MemType, start: i64, k: i32, rel: bool| {
        eval(|c| {
            c.push_int(start);
            if rel {
                c.st_rel(ty, 8);
                c.inc(true, ty, 8, k);
                c.ld_rel(ty, 8);
            } else {
                c.st_abs(ty, 40);
                c.inc(false, ty, 40, k);
                c.ld_abs(ty, 40);
            }
        }) as i64
    };
    assert_eq!(inc(MemType::I16, 5, 1, true), 6);
    assert_eq!(inc(MemType::I8, 127, 1, true), -128);
    assert_eq!(inc(MemType::U8, 255, 1, false), 0);
    assert_eq!(inc(MemType::U16, 0, -1, false), 65535);
    assert_eq!(inc(MemType::I64, i64::MAX, 1, true), i64::MIN);
    assert_eq!(
        inc(MemType::I32, -10, -2_000_000_000, false),
        -2_000_000_010
    );
}

#[test]
fn sel_if_is_min_and_max() {
    let sel = |cmp: Opcode, a: u64, b: u64| {
        eval(|c| {
            c.push_i64(a as i64);
            c.push_i64(b as i64);
            c.sel_if(cmp);
        })
    };
    // MAX = SEL_IF LT, MIN = SEL_IF GT, in the type's order.
    assert_eq!(sel(Opcode::LtS, -3i64 as u64, 2), 2);
    assert_eq!(sel(Opcode::GtS, -3i64 as u64, 2), -3i64 as u64);
    assert_eq!(sel(Opcode::LtU, -3i64 as u64, 2), -3i64 as u64);
    let f = |x: f32| x.to_bits() as u64;
    assert_eq!(sel(Opcode::LtF32, f(1.5), f(-0.5)), f(1.5));
    assert_eq!(sel(Opcode::GtF32, f(1.5), f(-0.5)), f(-0.5));
    // NaN compares false: the first operand stays.
    assert_eq!(sel(Opcode::LtF32, f(f32::NAN), f(1.0)), f(f32::NAN));
    assert_eq!(sel(Opcode::LtF32, f(1.0), f(f32::NAN)), f(1.0));
    let d = |x: f64| x.to_bits();
    assert_eq!(sel(Opcode::GtF64, d(3.0), d(2.0)), d(2.0));
}

#[test]
fn immediate_jumps_compare_with_a_sign_extended_immediate() {
    let cases = [
        (Opcode::LeS, 99i64, 99),
        (Opcode::LeS, 100, 99),
        (Opcode::Eq, 0, 0),
        (Opcode::LtU, 5, -1),
        (Opcode::GtS, -2, -3),
    ];
    for (cmp, a, k) in cases {
        for when in [true, false] {
            let jumped = eval(|c| {
                let target = c.new_label();
                let end = c.new_label();
                c.push_int(a);
                c.jump_if_imm(when, cmp, k, target);
                c.push_i32(0);
                c.jmp(end);
                c.bind(target);
                c.push_i32(1);
                c.bind(end);
            });
            let holds = crate::isa::compare(cmp, a as u64, k as i64 as u64);
            assert_eq!(jumped == 1, holds == when, "{cmp:?} {a} {k} {when}");
            // The frame-variable form: LD_REL fused into JUMP_IF_REL_IMM.
            let bytes = program_with(100, |c, _| {
                let target = c.new_label();
                let end = c.new_label();
                c.push_int(a);
                c.st_rel(MemType::I64, 8);
                c.ld_rel(MemType::I64, 8);
                c.jump_if_imm(when, cmp, k, target);
                c.push_i32(0);
                c.jmp(end);
                c.bind(target);
                c.push_i32(1);
                c.bind(end);
                c.st_abs(MemType::U64, RESULT);
            });
            let fused = if when {
                Opcode::JumpIfRelImm
            } else {
                Opcode::JumpIfNotRelImm
            };
            assert!(disassemble(&bytes).contains(&fused));
            let out = run_both(&bytes, 1);
            assert_eq!(out.data[RESULT as usize] == 1, holds == when);
        }
    }
}

#[test]
fn operator_forms_compute_as_the_plain_operators() {
    let operands: [(i64, i32); 5] = [(7, 3), (-7, 2), (i64::MIN, -1), (0x7FFF_FFFF, 1), (5, 64)];
    for &op in Opcode::ALL.iter().filter(|op| op.is_binary()) {
        for (a, k) in operands {
            let plain = eval(|c| {
                c.disable_fusion();
                c.push_int(a);
                c.push_i32(k);
                c.op(op);
            });
            let imm = eval(|c| {
                c.push_int(a);
                c.op_imm(op, k);
            });
            let rel = eval(|c| {
                c.push_i32(k);
                c.st_rel(MemType::I32, 4);
                c.push_int(a);
                c.op_at(true, op, MemType::I32, 4);
            });
            let abs = eval(|c| {
                c.push_i32(k);
                c.st_abs(MemType::I64, 48);
                c.push_int(a);
                c.op_at(false, op, MemType::I64, 48);
            });
            let rel_rel = eval(|c| {
                c.push_int(a);
                c.st_rel(MemType::I64, 16);
                c.push_i32(k);
                c.st_rel(MemType::I32, 4);
                c.op_rel_rel(op, (MemType::I64, 16), (MemType::I32, 4));
            });
            assert_eq!(
                (imm, rel, abs, rel_rel),
                (plain, plain, plain, plain),
                "{op:?} {a} {k}"
            );
        }
    }
    // A division by zero traps as the plain division does.
    for op in [Opcode::DivS, Opcode::ModU, Opcode::DivF32, Opcode::DivF64] {
        let fault = trap_of(|c| {
            c.push_i32(3);
            c.op_imm(op, 0);
            c.drop_();
        });
        assert_eq!(fault.trap, crate::isa::Trap::DivisionByZero);
    }
}

#[test]
fn builder_fuses_superinstructions() {
    // Element load and store; the store only when computing the value cannot trap. With
    // the index a frame variable: the _AT forms.
    for index_in_frame in [false, true] {
        let bytes = program_with(100, |c, _| {
            let index = |c: &mut ImageBuilder| {
                if index_in_frame {
                    c.ld_rel(MemType::I16, 0);
                } else {
                    c.ld_abs(MemType::I16, 0);
                }
            };
            index(c);
            c.elem_rel(8, 0, 3, 4);
            c.ld_ind(MemType::F32, 0);
            c.st_rel(MemType::F32, 24);
            index(c);
            c.elem_abs(40, 1, 4, 4);
            c.ld_rel(MemType::F32, 24);
            c.push_f32(2.0);
            c.op(Opcode::MulF32);
            c.st_ind(MemType::F32, 0);
        });
        let expected: &[Opcode] = if index_in_frame {
            &[
                Opcode::LdElemRelAt,
                Opcode::StRel,
                Opcode::LdRel,
                Opcode::OpImm,
                Opcode::StElemAbsAt,
                Opcode::Ret,
            ]
        } else {
            &[
                Opcode::LdAbs,
                Opcode::LdElemRel,
                Opcode::StRel,
                Opcode::LdAbs,
                Opcode::LdRel,
                Opcode::OpImm,
                Opcode::StElemAbs,
                Opcode::Ret,
            ]
        };
        assert_eq!(disassemble(&bytes), expected);
    }
    // A value that may trap (a division, another element) keeps ELEM and ST_IND; so does
    // a value that reads the address (DUP) and a store at an offset.
    for value in [
        |c: &mut ImageBuilder| {
            c.ld_rel(MemType::I32, 4);
            c.ld_rel(MemType::I32, 8);
            c.op(Opcode::DivS);
        },
        |c: &mut ImageBuilder| {
            c.push_i32(9);
            c.elem_abs(40, 1, 4, 4);
            c.ld_ind(MemType::I32, 0);
        },
        |c: &mut ImageBuilder| c.dup(),
    ] {
        let bytes = program_with(100, |c, _| {
            c.push_i32(1);
            c.elem_abs(40, 1, 4, 4);
            value(c);
            c.st_ind(MemType::I32, 0);
        });
        let ops = disassemble(&bytes);
        assert!(ops.contains(&Opcode::ElemAbs), "{ops:?}");
        assert!(ops.contains(&Opcode::StInd), "{ops:?}");
    }
    // x := x + k, an operand pushed by a load, NEG of a constant.
    let bytes = program_with(100, |c, _| {
        c.ld_rel(MemType::I16, 2);
        c.push_i32(1);
        c.op(Opcode::Add);
        c.op_width(Opcode::Sext, 16);
        c.st_rel(MemType::I16, 2);
        c.ld_abs(MemType::I32, 0);
        c.ld_abs(MemType::I32, 4);
        c.op(Opcode::Sub);
        c.push_f32(100.0);
        c.op(Opcode::NegF32);
        c.op(Opcode::Drop);
        c.st_abs(MemType::I32, 8);
    });
    assert_eq!(
        disassemble(&bytes),
        [
            Opcode::IncRel,
            Opcode::LdAbs,
            Opcode::OpAbs,
            Opcode::PushU32,
            Opcode::Drop,
            Opcode::StAbs,
            Opcode::Ret
        ]
    );
    let image = Image::parse(&bytes).unwrap();
    let push = crate::isa::instructions(image.code()).nth(3).unwrap();
    assert_eq!(push.immediates, (-100.0f32).to_bits().to_le_bytes());
}

#[test]
fn superinstructions_disassemble() {
    let bytes = program_with(100, |c, _| {
        let l = c.new_label();
        c.push_i32(1);
        c.ld_elem(true, MemType::F32, 800, 0, 99, 4);
        c.push_i32(1);
        c.sel_if(Opcode::LtF32);
        c.op_imm(Opcode::MulF32, 7);
        c.op_at(true, Opcode::Add, MemType::I16, 6);
        c.jump_if_imm(false, Opcode::LeS, 99, l);
        c.inc(true, MemType::I16, 2, -1);
        c.op_rel_rel(Opcode::SubF32, (MemType::F32, 4), (MemType::F32, 8));
        c.drop_();
        c.ld_rel(MemType::I16, 2);
        c.jump_if_imm(true, Opcode::GtS, -5, l);
        c.bind(l);
    });
    let image = Image::parse(&bytes).unwrap();
    let text: Vec<alloc::string::String> = crate::isa::instructions(image.code())
        .map(|i| alloc::format!("{i}"))
        .collect();
    assert_eq!(
        text,
        [
            "PUSH_I32 1",
            "LD_ELEM_REL F32 800 0 99 4",
            "PUSH_I32 1",
            "SEL_IF LT_F32",
            "OP_IMM MUL_F32 7",
            "OP_REL ADD I16 6",
            "JUMP_IF_NOT_IMM LE_S 99 @99",
            "INC_REL I16 2 -1",
            "OP_REL_REL SUB_F32 F32 4 F32 8",
            "DROP",
            "JUMP_IF_REL_IMM GT_S I16 2 -5 @99",
            "RET"
        ]
    );
}

#[test]
fn arithmetic_nans_are_canonical() {
    use crate::isa::{CANONICAL_NAN_F32, CANONICAL_NAN_F64};
    // Two NaNs with different payloads (and a NaN from an invalid operation): whichever the
    // hardware would pass on, the result is the canonical NaN, in every form.
    let (n1, n2) = (0x7FA0_1234u32, 0xFFAB_CDEFu32);
    for op in [
        Opcode::AddF32,
        Opcode::SubF32,
        Opcode::MulF32,
        Opcode::DivF32,
    ] {
        let plain = eval(|c| {
            c.disable_fusion();
            c.push_u32(n1);
            c.push_u32(n2);
            c.op(op);
        });
        let fused = eval(|c| {
            c.push_u32(n1);
            c.op_imm(op, n2 as i32);
        });
        assert_eq!(
            (plain, fused),
            (CANONICAL_NAN_F32 as u64, CANONICAL_NAN_F32 as u64)
        );
    }
    let (d1, d2) = (0x7FF4_0000_0000_0001u64, 0xFFF8_0000_DEAD_BEEFu64);
    for op in [
        Opcode::AddF64,
        Opcode::SubF64,
        Opcode::MulF64,
        Opcode::DivF64,
    ] {
        let v = eval(|c| {
            c.push_i64(d1 as i64);
            c.push_i64(d2 as i64);
            c.op(op);
        });
        assert_eq!(v, CANONICAL_NAN_F64);
    }
    assert_eq!(
        eval(|c| {
            c.push_f64(f64::INFINITY);
            c.push_f64(f64::INFINITY);
            c.op(Opcode::SubF64);
        }),
        CANONICAL_NAN_F64
    );
    // NEG only flips the sign bit, of a NaN too.
    assert_eq!(
        eval(|c| {
            c.disable_fusion();
            c.push_u32(n1);
            c.op(Opcode::NegF32);
        }),
        (n1 ^ 0x8000_0000) as u64
    );
}
