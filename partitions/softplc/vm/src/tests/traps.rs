//! One test per trap, plus fault reporting, task faulting and reset.

use super::*;
use crate::isa::{Builtin, MemType, Opcode, RoundMode, Trap};

fn div_by_zero(op: Opcode, zero: impl Fn(&mut ImageBuilder)) -> Trap {
    trap_of(|c| {
        c.push_i32(1);
        zero(c);
        c.op(op);
        c.drop_();
    })
    .trap
}

#[test]
fn division_by_zero_integer_and_float() {
    for op in [Opcode::DivS, Opcode::DivU, Opcode::ModS, Opcode::ModU] {
        assert_eq!(
            div_by_zero(op, |c| c.push_i32(0)),
            Trap::DivisionByZero,
            "{op:?}"
        );
    }
    assert_eq!(
        div_by_zero(Opcode::DivF32, |c| c.push_f32(-0.0)),
        Trap::DivisionByZero
    );
    assert_eq!(
        div_by_zero(Opcode::DivF64, |c| c.push_f64(0.0)),
        Trap::DivisionByZero
    );
}

#[test]
fn index_out_of_bounds() {
    let fault = trap_of(|c| {
        c.push_i32(11);
        c.chk_index(1, 10);
        c.drop_();
    });
    assert_eq!(fault.trap, Trap::IndexOutOfBounds);
    let fault = trap_of(|c| {
        c.push_i32(0);
        c.chk_index(1, 10);
        c.drop_();
    });
    assert_eq!(fault.trap, Trap::IndexOutOfBounds);
    for bad in [-3, 6] {
        let bytes = program_with(100, |c, _| {
            c.push_u32(100);
            c.push_i32(bad);
            c.index(-2, 5, 4);
            c.drop_();
        });
        let out = run_both(&bytes, 1);
        assert_eq!(out.result.unwrap_err().trap, Trap::IndexOutOfBounds);
        assert_eq!(out.stack, [100, bad as u64], "INDEX trapped without effect");
    }
    // The element superinstructions: the fault is at the instruction, the stack as before
    // it (a store's value still there), data memory untouched.
    let element_ops: [fn(&mut ImageBuilder); 4] = [
        |c| c.elem_rel(0, -2, 5, 4),
        |c| c.elem_abs(100, -2, 5, 4),
        |c| c.ld_elem(true, MemType::I32, 0, -2, 5, 4),
        |c| c.ld_elem(false, MemType::U8, 100, -2, 5, 1),
    ];
    for (k, op) in element_ops.iter().enumerate() {
        for bad in [-3i64, 6] {
            let mut at = 0;
            let bytes = program_with(100, |c, _| {
                c.push_int(bad);
                at = c.code_offset();
                op(c);
                c.drop_();
            });
            let out = run_both(&bytes, 1);
            let fault = out.result.unwrap_err();
            assert_eq!(
                (fault.trap, fault.code_offset),
                (Trap::IndexOutOfBounds, at),
                "{k}"
            );
            assert_eq!(out.stack, [bad as u64]);
        }
    }
    for rel in [true, false] {
        let mut at = 0;
        let bytes = program_with(100, |c, _| {
            c.push_i32(8);
            c.push_i32(-1);
            at = c.code_offset();
            c.st_elem(rel, MemType::I16, 4, 0, 7, 2);
        });
        let out = run_both(&bytes, 1);
        let fault = out.result.unwrap_err();
        assert_eq!(
            (fault.trap, fault.code_offset),
            (Trap::IndexOutOfBounds, at)
        );
        assert_eq!(out.stack, [8, -1i64 as u64]);
        assert!(out.data.iter().all(|&b| b == 0));
    }
}

#[test]
fn elements_indexed_by_a_variable_trap_at_the_instruction() {
    for (k, ty) in [
        None,
        Some((MemType::I32, true)),
        Some((MemType::I32, false)),
    ]
    .into_iter()
    .enumerate()
    {
        for rel in [true, false] {
            let mut at = 0;
            let bytes = program_with(100, |c, _| {
                c.push_i32(9);
                c.st_rel(MemType::I16, 40);
                if ty.is_some_and(|(_, load)| !load) {
                    c.push_i32(77);
                }
                at = c.code_offset();
                c.elem_at(rel, ty, 0, 0, 7, 4, (MemType::I16, 40));
                if ty.is_none_or(|(_, load)| load) {
                    c.drop_();
                }
            });
            let out = run_both(&bytes, 1);
            let fault = out.result.unwrap_err();
            assert_eq!(
                (fault.trap, fault.code_offset),
                (Trap::IndexOutOfBounds, at),
                "{k}"
            );
        }
    }
}

#[test]
fn elements_outside_data_are_invalid_addresses() {
    // An array whose last elements lie past the end of data memory: the index is fine, the
    // access is not.
    let fault = trap_of(|c| {
        c.push_i32(3);
        c.ld_elem(false, MemType::I32, DATA - 8, 0, 3, 4);
        c.drop_();
    });
    assert_eq!(fault.trap, Trap::InvalidAddress);
    let fault = trap_of(|c| {
        c.push_i32(2);
        c.push_i32(7);
        c.st_elem(false, MemType::I64, DATA - 16, 0, 3, 8);
    });
    assert_eq!(fault.trap, Trap::InvalidAddress);
    // In range: fine.
    assert_eq!(
        eval(|c| {
            c.push_i32(1);
            c.ld_elem(false, MemType::I32, DATA - 8, 0, 3, 4);
        }),
        0
    );
}

#[test]
fn subrange_violation_signed_and_unsigned() {
    let signed = trap_of(|c| {
        c.push_i32(-6);
        c.chk_range_s(-5, 5);
        c.drop_();
    });
    assert_eq!(signed.trap, Trap::SubrangeViolation);
    // -1 is huge unsigned
    let unsigned = trap_of(|c| {
        c.push_i32(-1);
        c.chk_range_u(0, 100);
        c.drop_();
    });
    assert_eq!(unsigned.trap, Trap::SubrangeViolation);
}

#[test]
fn watchdog_stops_endless_loops_even_inside_try() {
    let fault = trap_of(|c| {
        let handler = c.new_label();
        let end = c.new_label();
        c.try_begin(handler);
        let top = c.new_label();
        c.bind(top);
        c.jmp(top);
        c.bind(handler);
        c.drop_();
        c.jmp(end);
        c.bind(end);
    });
    assert_eq!(fault.trap, Trap::Watchdog);
    // Budget is exact: a straight-line program of N instructions needs budget >= N.
    let bytes = program_with(3, |c, _| {
        c.nop();
        c.nop();
    });
    assert!(
        run_both(&bytes, 1).result.is_ok(),
        "3 instructions fit a budget of 3"
    );
    let bytes = program_with(2, |c, _| {
        c.nop();
        c.nop();
    });
    let fault = run_both(&bytes, 1).result.unwrap_err();
    assert_eq!((fault.trap, fault.code_offset), (Trap::Watchdog, 2));
}

#[test]
fn call_depth_on_unbounded_recursion() {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let rec = b.declare_pou("rec", 0, 0, 8);
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
    b.push_u32(0);
    b.call(rec);
    b.ret();
    b.end_pou(main);
    b.begin_pou(rec);
    b.push_u32(0);
    b.call(rec);
    b.ret();
    b.end_pou(rec);
    let out = run_both(&b.build().unwrap(), 1);
    let fault = out.result.unwrap_err();
    assert_eq!(fault.trap, Trap::CallDepth);
    assert_eq!(out.stack, [0], "the trapping CALL keeps its operand");
}

#[test]
fn stack_overflow() {
    let fault = trap_of(|c| {
        for _ in 0..=STACK {
            c.push_i32(1);
        }
        for _ in 0..=STACK {
            c.drop_();
        }
    });
    assert_eq!(fault.trap, Trap::StackOverflow);
    assert_eq!(
        fault.code_offset,
        (STACK * 5) as u32,
        "the push beyond the limit traps"
    );
}

#[test]
fn try_frames_overflow_is_stack_overflow_caught_by_the_innermost_frame() {
    let bytes = program_with(1000, |c, _| {
        let handlers: Vec<_> = (0..=TRIES).map(|_| c.new_label()).collect();
        let end = c.new_label();
        for h in &handlers {
            c.try_begin(*h);
        }
        for _ in &handlers {
            c.try_end();
        }
        c.push_i32(0);
        c.jmp(end);
        for (depth, h) in handlers.iter().enumerate() {
            c.bind(*h);
            c.st_abs(MemType::U8, 16 + depth as u32);
            for _ in 0..depth {
                c.try_end();
            }
            c.push_i32(0);
            c.jmp(end);
        }
        c.bind(end);
        c.drop_();
    });
    let out = run_both(&bytes, 1);
    assert!(out.result.is_ok());
    assert_eq!(
        out.data[16 + TRIES - 1],
        Trap::StackOverflow.code(),
        "frame {} caught it",
        TRIES - 1
    );
    assert_eq!(out.data[16 + TRIES], 0);
}

#[test]
fn numeric_errors() {
    let math = |builtin: Builtin, x: f64| {
        trap_of(|c| {
            c.push_f64(x);
            c.call_builtin(builtin);
            c.drop_();
        })
        .trap
    };
    assert_eq!(math(Builtin::SqrtF64, -1.0), Trap::NumericError);
    assert_eq!(math(Builtin::LnF64, 0.0), Trap::NumericError);
    assert_eq!(math(Builtin::LogF64, -2.0), Trap::NumericError);
    assert_eq!(math(Builtin::AsinF64, 1.5), Trap::NumericError);
    assert_eq!(math(Builtin::AcosF64, -1.01), Trap::NumericError);
    let real = trap_of(|c| {
        c.push_f32(-4.0);
        c.call_builtin(Builtin::SqrtF32);
        c.drop_();
    });
    assert_eq!(real.trap, Trap::NumericError);
    let conv = |x: f64, ty: MemType| {
        trap_of(|c| {
            c.push_f64(x);
            c.float_to_int(Opcode::F64ToInt, ty, RoundMode::NearestTiesAway);
            c.drop_();
        })
        .trap
    };
    assert_eq!(conv(f64::NAN, MemType::I32), Trap::NumericError);
    assert_eq!(conv(f64::INFINITY, MemType::I64), Trap::NumericError);
    assert_eq!(conv(32767.5, MemType::I16), Trap::NumericError);
    assert_eq!(conv(-0.5, MemType::U8), Trap::NumericError);
    assert_eq!(conv(9.3e18, MemType::I64), Trap::NumericError);
    let expt = trap_of(|c| {
        c.push_f64(-8.0);
        c.push_f64(0.5);
        c.call_builtin(Builtin::ExptF64);
        c.drop_();
    });
    assert_eq!(expt.trap, Trap::NumericError);
}

#[test]
fn invalid_dynamic_addresses() {
    let load = trap_of(|c| {
        c.push_u32(DATA - 2);
        c.ld_ind(MemType::I32, 0);
        c.drop_();
    });
    assert_eq!(load.trap, Trap::InvalidAddress);
    let store = trap_of(|c| {
        c.push_i64(-1);
        c.push_i32(0);
        c.st_ind(MemType::U8, 0);
    });
    assert_eq!(store.trap, Trap::InvalidAddress);
    let offset_overflow = trap_of(|c| {
        c.push_i64(-1);
        c.ld_ind(MemType::U8, 2);
        c.drop_();
    });
    assert_eq!(offset_overflow.trap, Trap::InvalidAddress);
    let copy = trap_of(|c| {
        c.push_u32(0);
        c.push_u32(DATA - 4);
        c.copy(8);
    });
    assert_eq!(copy.trap, Trap::InvalidAddress);
    let string = trap_of(|c| {
        c.push_u32(DATA);
        c.call_builtin(Builtin::StrLen);
        c.drop_();
    });
    assert_eq!(string.trap, Trap::InvalidAddress);
}

#[test]
fn call_with_frame_outside_data_is_invalid_address() {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let f = b.declare_pou("f", 0, 0, 16);
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
    b.push_u32(DATA - 8);
    b.call(f);
    b.ret();
    b.end_pou(main);
    b.begin_pou(f);
    b.ret();
    b.end_pou(f);
    assert_eq!(
        run_both(&b.build().unwrap(), 1).result.unwrap_err().trap,
        Trap::InvalidAddress
    );
}

#[test]
fn throw_raises_the_given_trap() {
    assert_eq!(
        trap_of(|c| c.throw(Trap::SubrangeViolation)).trap,
        Trap::SubrangeViolation
    );
    let bad_code = trap_of(|c| {
        c.push_i32(200);
        c.rethrow();
    });
    assert_eq!(bad_code.trap, Trap::NumericError);
}

#[test]
fn fault_reports_location_and_the_task_stays_faulted_until_reset() {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let file = b.add_file("main.st");
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
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
    b.source_location(file, 3, 5);
    b.ld_abs(MemType::I32, 0);
    b.push_i32(1);
    b.op(Opcode::Add);
    b.st_abs(MemType::I32, 0);
    b.source_location(file, 4, 9);
    b.push_i32(1);
    // `LD_ABS; DIV_S` fuses into one OP_ABS where the load was.
    let div_at = b.code_offset();
    b.ld_abs(MemType::I32, 4);
    b.op(Opcode::DivS);
    b.st_abs(MemType::I32, 8);
    b.ret();
    b.end_pou(main);
    let bytes = b.build().unwrap();
    let image = Image::parse(&bytes).unwrap();
    let verified = verify(&image).unwrap();
    let mut data = [0u8; DATA as usize];
    let mut stack = [0u64; 8];
    let mut calls = [CallFrame::EMPTY; 2];
    let mut tries: [TryFrame; 0] = [];
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
    let fault = vm.run_cycle(0, 0).unwrap_err();
    assert_eq!(fault.trap, Trap::DivisionByZero);
    assert_eq!(fault.code_offset, div_at);
    let loc = fault.location.unwrap();
    assert_eq!(
        (image.file_name(loc.file), loc.line, loc.column),
        (Some("main.st"), 4, 9)
    );
    assert!(!fault.refused);
    assert_eq!(vm.task_fault(0), Some(fault));
    // Refused while faulted: data untouched.
    let refused = vm.run_cycle(0, 1).unwrap_err();
    assert!(refused.refused);
    assert_eq!(refused.trap, Trap::DivisionByZero);
    assert_eq!(vm.data()[0], 1);
    // Fix the divisor (as a monitor would) and reset the task.
    vm.data_mut()[4] = 2;
    vm.reset_task(0);
    assert!(vm.run_cycle(0, 2).is_ok());
    assert_eq!(vm.data()[0], 2);
    // Unknown task.
    assert!(vm.run_cycle(5, 0).unwrap_err().refused);
}

#[test]
fn watchdog_budget_override() {
    let bytes = program_with(100, |c, _| {
        for _ in 0..10 {
            c.nop();
        }
    });
    let image = Image::parse(&bytes).unwrap();
    let verified = verify(&image).unwrap();
    let mut data = [0u8; DATA as usize];
    let mut stack = [0u64; 8];
    let mut calls = [CallFrame::EMPTY; 2];
    let mut tries = [TryFrame::EMPTY; 1];
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
    assert_eq!(vm.run_cycle(0, 0).unwrap().instructions, 11);
    vm.set_watchdog_budget(0, Some(5));
    assert_eq!(vm.run_cycle(0, 0).unwrap_err().trap, Trap::Watchdog);
    vm.reset_task(0);
    vm.set_watchdog_budget(0, None);
    assert!(vm.run_cycle(0, 0).is_ok());
}

#[test]
fn trap_names_and_codes_are_stable() {
    let expected = [
        (1, "DIVISION_BY_ZERO"),
        (2, "INDEX_OUT_OF_BOUNDS"),
        (3, "SUBRANGE_VIOLATION"),
        (4, "WATCHDOG"),
        (5, "CALL_DEPTH"),
        (6, "STACK_OVERFLOW"),
        (7, "NUMERIC_ERROR"),
        (8, "INVALID_ADDRESS"),
        (9, "DEADLINE"),
        (10, "INVALID_REFERENCE"),
    ];
    for (trap, (code, name)) in Trap::ALL.iter().zip(expected) {
        assert_eq!((trap.code(), trap.name()), (code, name));
        assert_eq!(Trap::from_u64(code as u64), Some(*trap));
    }
    assert_eq!(Trap::from_u64(0), None);
    assert_eq!(Trap::from_u64(16), None);
}

#[test]
fn deadline_stops_an_endless_loop_inside_try_and_is_not_caught() {
    let bytes = program_with(u32::MAX, |c, _| {
        let handler = c.new_label();
        c.try_begin(handler);
        let top = c.new_label();
        c.bind(top);
        c.jmp(top);
        c.bind(handler);
        c.drop_();
    });
    let mut memory = VmMemory::for_image(&bytes);
    let mut vm = memory.machine(&bytes);
    // The clock is asked once per DEADLINE_CHECK_EVERY instructions; it "expires" at the
    // third question.
    let mut asked = 0;
    let fault = vm
        .run_cycle_until(0, 0, || {
            asked += 1;
            asked == 3
        })
        .unwrap_err();
    assert_eq!((fault.trap, asked), (Trap::Deadline, 3));
    assert_eq!(vm.task_fault(0).map(|f| f.trap), Some(Trap::Deadline));
    assert!(!Trap::Deadline.is_catchable());
}

#[test]
fn a_cycle_shorter_than_the_check_interval_never_reads_the_clock() {
    let bytes = program_with(100, |c, _| c.nop());
    let mut memory = VmMemory::for_image(&bytes);
    let mut vm = memory.machine(&bytes);
    assert!(
        vm.run_cycle_until(0, 0, || panic!("asked the clock"))
            .is_ok()
    );
}

#[test]
fn watchdog_and_deadline_stop_before_exactly_the_counted_instruction() {
    // 3,000 NOPs: instruction k (0-based) is at code offset k.
    let nops = |budget: u32| {
        program_with(budget, |c, _| {
            for _ in 0..3000 {
                c.nop();
            }
        })
    };
    // The watchdog: after exactly `budget` instructions (VM and model agree on the pc).
    for budget in [1, 1022, 1023, 1024, 2047, 2999] {
        let out = run_both(&nops(budget), 1);
        let fault = out.result.unwrap_err();
        assert_eq!((fault.trap, fault.code_offset), (Trap::Watchdog, budget));
    }
    // A budget that the cycle needs exactly.
    assert_eq!(run_both(&nops(3001), 1).result.unwrap().instructions, 3001);
    // The clock is asked before instructions 1023, 2047, ...: expiring at the second
    // question stops the cycle before instruction 2047.
    let bytes = nops(u32::MAX);
    let mut memory = VmMemory::for_image(&bytes);
    let mut vm = memory.machine(&bytes);
    let mut asked = 0;
    let fault = vm
        .run_cycle_until(0, 0, || {
            asked += 1;
            asked == 2
        })
        .unwrap_err();
    assert_eq!((fault.trap, fault.code_offset), (Trap::Deadline, 2047));
    // Where the budget and a check point coincide, the watchdog comes first.
    let bytes = nops(1023);
    let mut memory = VmMemory::for_image(&bytes);
    let mut vm = memory.machine(&bytes);
    let fault = vm.run_cycle_until(0, 0, || true).unwrap_err();
    assert_eq!((fault.trap, fault.code_offset), (Trap::Watchdog, 1023));
}
