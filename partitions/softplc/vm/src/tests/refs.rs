//! References (`REF_MAKE`, `REF_CHECK`, `REF_ADD`, `CHK_NULL`), dynamic dispatch
//! (`CALL_VIRT`, `VIRT_FRAME`) and the NUL-terminator string builtins: concrete results and
//! traps on the VM and the model, and the verifier's checks of the tables they use.

use super::*;
use crate::image::Section;
use crate::isa::{Builtin, MemType, Opcode, Trap};
use crate::verify::{Reason, Site};

/// Objects of the test programs: [16, 24), [24, 40) with the parts [24, 28) and
/// [28, 40) and in that [32, 36), and [64, 65). Records 1..=6 in that order.
fn objects(b: &mut ImageBuilder) {
    b.add_object(16, 8, None);
    let whole = b.add_object(24, 16, None);
    b.add_object(24, 4, Some(whole));
    let tail = b.add_object(28, 12, Some(whole));
    b.add_object(32, 4, Some(tail));
    b.add_object(64, 1, None);
}

fn reference(object: u64, address: u64) -> u64 {
    address | object << 32
}

#[test]
fn ref_make_names_the_smallest_object_containing_the_bytes() {
    for (address, size, expected) in [
        (16, 1, 1),
        (16, 8, 1),
        (23, 1, 1),
        (24, 16, 2),
        (24, 5, 2),
        (24, 4, 3),
        (26, 2, 3),
        (28, 1, 4),
        (28, 12, 4),
        (32, 4, 5),
        (33, 1, 5),
        (35, 2, 4),
        (36, 4, 4),
        (30, 8, 4),
        (27, 2, 2),
        (39, 1, 4),
        (64, 1, 6),
        (64, 0, 6),
    ] {
        let r = eval(|b| {
            objects(b);
            b.push_u32(address);
            b.ref_make(size);
        });
        assert_eq!(r, reference(expected, address as u64), "address {address}");
    }
    for (outside, size) in [
        (0u32, 1u32),
        (15, 1),
        (40, 1),
        (63, 1),
        (65, 1),
        (511, 1),
        (u32::MAX, 1),
        (20, 5),
        (39, 2),
        (64, 2),
    ] {
        let fault = trap_of(|b| {
            objects(b);
            b.push_u32(outside);
            b.ref_make(size);
            b.drop_();
        });
        assert_eq!(fault.trap, Trap::InvalidReference, "address {outside}");
    }
    // Above 32 bits nothing is an object either.
    let fault = trap_of(|b| {
        objects(b);
        b.push_i64(1 << 32 | 16);
        b.ref_make(1);
        b.drop_();
    });
    assert_eq!(fault.trap, Trap::InvalidReference);
}

#[test]
fn ref_check_admits_only_accesses_inside_the_object() {
    // Inside: the plain address comes out.
    for (r, size) in [
        (reference(1, 16), 8),
        (reference(1, 20), 4),
        (reference(1, 23), 1),
        (reference(2, 24), 16),
        (reference(6, 64), 1),
        (reference(5, 32), 4),
        (reference(1, 16), 0),
    ] {
        let got = eval(|b| {
            objects(b);
            b.push_i64(r as i64);
            b.ref_check(size);
        });
        assert_eq!(got, r & 0xFFFF_FFFF);
    }
    // Outside its own object (even when inside another one), NULL, unknown objects.
    for (r, size) in [
        (0, 1),
        (reference(0, 16), 1),
        (reference(1, 20), 5),
        (reference(1, 24), 1),
        (reference(1, 15), 1),
        (reference(2, 23), 2),
        (reference(6, 64), 2),
        (reference(5, 31), 2),
        (reference(3, 27), 2),
        (reference(7, 16), 1),
        (reference(u32::MAX as u64, 16), 1),
        (reference(1, u32::MAX as u64), 1),
    ] {
        let fault = trap_of(|b| {
            objects(b);
            b.push_i64(r as i64);
            b.ref_check(size);
            b.drop_();
        });
        assert_eq!(fault.trap, Trap::InvalidReference, "{r:#x} size {size}");
    }
}

#[test]
fn ref_add_moves_the_address_and_keeps_the_object() {
    let add = |r: u64, n: i64| {
        eval(|b| {
            b.disable_fusion();
            b.push_i64(r as i64);
            b.push_i64(n);
            b.ref_add();
        })
    };
    assert_eq!(add(reference(2, 24), 4), reference(2, 28));
    assert_eq!(add(reference(2, 24), -4), reference(2, 20));
    // Wrapping in 32 bits: the object never changes.
    assert_eq!(add(reference(2, 5), -6), reference(2, 0xFFFF_FFFF));
    assert_eq!(add(reference(2, 0xFFFF_FFFF), 1), reference(2, 0));
    assert_eq!(add(reference(2, 24), 1 << 32), reference(2, 24));
    assert_eq!(add(reference(2, 24), -(1 << 32)), reference(2, 24));
    assert_eq!(add(0, 8), 8);
    // A reference moved out of its object and back is valid again.
    let got = eval(|b| {
        objects(b);
        b.push_u32(24);
        b.ref_make(16);
        b.push_i32(-100);
        b.ref_add();
        b.push_i32(108);
        b.ref_add();
        b.ref_check(4);
    });
    assert_eq!(got, 32);
}

#[test]
fn loads_and_stores_through_checked_references() {
    // [16, 24) holds 0x1122334455667788; read a byte through REF_MAKE + REF_ADD + REF_CHECK.
    let out = run_both(
        &program_with(1000, |b, _| {
            objects(b);
            b.set_init(16, &0x1122_3344_5566_7788u64.to_le_bytes());
            b.push_u32(16);
            b.ref_make(1);
            b.push_i32(6);
            b.ref_add();
            b.ref_check(1);
            b.ld_ind(MemType::U8, 0);
            b.st_abs(MemType::U8, 0);
            // Store 0xAB at [24] through a reference, then try one byte past [16, 24).
            b.push_u32(24);
            b.ref_make(1);
            b.ref_check(1);
            b.push_i32(0xAB);
            b.st_ind(MemType::U8, 0);
            b.push_u32(16);
            b.ref_make(1);
            b.push_i32(8);
            b.ref_add();
            b.ref_check(1);
            b.push_i32(0xCD);
            b.st_ind(MemType::U8, 0);
        }),
        1,
    );
    assert_eq!(out.data[0], 0x22);
    assert_eq!(out.data[24], 0xAB);
    let fault = out.result.unwrap_err();
    assert_eq!(fault.trap, Trap::InvalidReference);
    // The trapping REF_CHECK left its operand on the stack (no effect).
    assert_eq!(out.stack, vec![reference(1, 24)]);
}

#[test]
fn chk_null_traps_only_on_zero() {
    assert_eq!(
        eval(|b| {
            b.push_i32(8);
            b.chk_null();
        }),
        8
    );
    let fault = trap_of(|b| {
        b.push_i32(0);
        b.chk_null();
        b.drop_();
    });
    assert_eq!(fault.trap, Trap::InvalidReference);
}

/// A program with two classes: class 0 runs `M0` for slot 3 and `M1` for slot 7, class 1
/// runs `M1` for slot 3 only. `M0` stores 100 + the parameter at frame 200 into its
/// instance's byte 4, `M1` stores 200 + the parameter. Instances: class 0 at 64, class 1 at
/// 80, an unknown class (9) at 96. `body` runs in Main.
fn dispatch_program(body: impl FnOnce(&mut ImageBuilder, [PouId; 2])) -> Vec<u8> {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let m0 = b.declare_pou("M0", 0, 0, 16);
    let m1 = b.declare_pou("M1", 0, 0, 16);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: MAIN_BASE,
        interval_ns: 10_000_000,
        watchdog_budget: 10_000,
    });
    assert_eq!(b.add_class("C0", &[(7, m1, 204), (3, m0, 200)]), 0);
    assert_eq!(b.add_class("C1", &[(3, m1, 204)]), 1);
    b.set_init(64, &0u32.to_le_bytes());
    b.set_init(80, &1u32.to_le_bytes());
    b.set_init(96, &9u32.to_le_bytes());
    for (pou, frame, plus) in [(m0, 200, 100), (m1, 204, 200)] {
        b.begin_pou(pou);
        b.ld_abs(MemType::U8, frame);
        b.push_i32(plus);
        b.op(Opcode::Add);
        b.st_rel(MemType::U8, 4);
        b.ret();
        b.end_pou(pou);
    }
    b.begin_pou(main);
    body(&mut b, [m0, m1]);
    b.ret();
    b.end_pou(main);
    b.build().expect("build")
}

/// Calls `slot` on `instance` with parameter `arg` (stored through VIRT_FRAME).
fn virtual_call(b: &mut ImageBuilder, instance: u32, slot: u16, arg: i32) {
    b.push_u32(instance);
    b.virt_frame(slot);
    b.push_i32(arg);
    b.st_ind(MemType::U8, 0);
    b.push_u32(instance);
    b.call_virt(slot);
}

#[test]
fn call_virt_runs_the_method_of_the_instance_class() {
    let out = run_both(
        &dispatch_program(|b, _| {
            virtual_call(b, 64, 3, 1); // class 0, slot 3: M0 -> 101
            virtual_call(b, 80, 3, 2); // class 1, slot 3: M1 -> 202
            virtual_call(b, 64, 7, 3); // class 0, slot 7: M1 -> 203 (overwrites 101)
            b.push_u32(80);
            b.virt_frame(3);
            b.st_abs(MemType::U32, 0);
        }),
        1,
    );
    assert!(out.result.is_ok(), "{:?}", out.result);
    assert_eq!((out.data[68], out.data[84]), (203, 202));
    assert_eq!(out.data[0..4], 204u32.to_le_bytes());
}

#[test]
fn call_virt_traps_on_null_unknown_class_and_missing_slot() {
    for (instance, slot) in [(0u32, 3u16), (96, 3), (80, 7), (64, 4), (DATA - 2, 3)] {
        for frame_only in [false, true] {
            let bytes = dispatch_program(|b, _| {
                b.push_u32(instance);
                if frame_only {
                    b.virt_frame(slot);
                    b.drop_();
                } else {
                    b.call_virt(slot);
                }
            });
            let fault = run_both(&bytes, 1).result.unwrap_err();
            assert_eq!(fault.trap, Trap::InvalidReference, "{instance} {slot}");
        }
    }
    // An instance whose frame does not fit in data memory: like CALL.
    let bytes = dispatch_program(|b, _| {
        b.set_init(DATA - 8, &0u32.to_le_bytes());
        b.push_u32(DATA - 8);
        b.call_virt(3);
    });
    assert_eq!(
        run_both(&bytes, 1).result.unwrap_err().trap,
        Trap::InvalidAddress
    );
}

#[test]
fn call_virt_respects_the_call_depth() {
    // M0 calls itself through CALL_VIRT on its own instance until CALL_DEPTH.
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let m = b.declare_pou("M", 0, 0, 16);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: MAIN_BASE,
        interval_ns: 1,
        watchdog_budget: 10_000,
    });
    b.add_class("C", &[(0, m, 0)]);
    b.begin_pou(m);
    b.lea_rel(0);
    b.call_virt(0);
    b.ret();
    b.end_pou(m);
    b.begin_pou(main);
    b.push_u32(64);
    b.call_virt(0);
    b.ret();
    b.end_pou(main);
    let out = run_both(&b.build().unwrap(), 1);
    assert_eq!(out.result.unwrap_err().trap, Trap::CallDepth);
}

#[test]
fn string_results_keep_a_terminator_and_sync_reads_it() {
    // STRING[6] at 32 holding 'abcdef'.
    let out = run_both(
        &program_with(1000, |b, _| {
            b.init_string(32, 6, "abcdef");
            b.init_string(48, 6, "xy");
            // A shorter result leaves a NUL after it: 'xy' then 0 over 'c'.
            b.push_u32(32);
            b.push_u32(48);
            b.call_builtin(Builtin::StrAssign);
            // A pointer writes 'Q' over the NUL: no NUL is left, the text is 'xyQdef'.
            b.push_i32(b'Q' as i32);
            b.st_abs(MemType::U8, 38);
            b.push_u32(32);
            b.call_builtin(Builtin::StrSync);
            b.push_u32(32);
            b.call_builtin(Builtin::StrLen);
            b.st_abs(MemType::U8, 0);
            // A NUL written at 1: length 1.
            b.push_i32(0);
            b.st_abs(MemType::U8, 37);
            b.push_u32(32);
            b.call_builtin(Builtin::StrSync);
            b.push_u32(32);
            b.call_builtin(Builtin::StrLen);
            b.st_abs(MemType::U8, 1);
            // No NUL among the 6 text bytes: the length is max_len.
            for i in 0..6 {
                b.push_i32(b'a' as i32 + i);
                b.st_abs(MemType::U8, 36 + i as u32);
            }
            b.push_u32(32);
            b.call_builtin(Builtin::StrSync);
            b.push_u32(32);
            b.call_builtin(Builtin::StrLen);
            b.st_abs(MemType::U8, 2);
        }),
        1,
    );
    assert!(out.result.is_ok());
    assert_eq!(&out.data[0..3], &[6, 1, 6]);
    assert_eq!(&out.data[36..42], b"abcdef");
    // A full-length result writes no terminator (nothing beyond max_len is touched).
    let out = run_both(
        &program_with(1000, |b, _| {
            b.init_string(32, 2, "");
            b.set_init(38, &[0xEE]);
            b.init_string(48, 6, "xyz");
            b.push_u32(32);
            b.push_u32(48);
            b.call_builtin(Builtin::StrAssign);
        }),
        1,
    );
    assert_eq!(&out.data[36..39], &[b'x', b'y', 0xEE]);
}

/// The verifier's verdict on a program whose tables `tables` adds.
fn verdict(tables: impl FnOnce(&mut ImageBuilder, PouId, PouId)) -> Result<(), (Site, Reason)> {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    let f = b.declare_pou("F", 1, 1, 8);
    b.begin_pou(main);
    b.ret();
    b.end_pou(main);
    b.begin_pou(f);
    b.ret();
    b.end_pou(f);
    tables(&mut b, main, f);
    let bytes = b.build().unwrap();
    let image = Image::parse(&bytes).unwrap();
    verify(&image).map(|_| ()).map_err(|e| (e.site, e.reason))
}

#[test]
fn verifier_checks_objects_classes_and_dispatch() {
    assert_eq!(verdict(|b, _, _| objects(b)), Ok(()));
    let bad_object = |f: fn(&mut ImageBuilder)| verdict(|b, _, _| f(b)).unwrap_err();
    assert_eq!(
        bad_object(|b| {
            b.add_object(10, 0, None);
        }),
        (Site::Object(0), Reason::BadObject)
    );
    assert_eq!(
        bad_object(|b| {
            b.add_object(DATA - 4, 5, None);
        }),
        (Site::Object(0), Reason::BadObject)
    );
    // Partly overlapping.
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, None);
            b.add_object(23, 2, None);
        }),
        (Site::Object(1), Reason::BadObject)
    );
    // Out of order.
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, None);
            b.add_object(8, 1, None);
        }),
        (Site::Object(1), Reason::BadObject)
    );
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 4, None);
            b.add_object(16, 8, None);
        }),
        (Site::Object(1), Reason::BadObject)
    );
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, None);
            b.add_object(16, 8, Some(0));
        }),
        (Site::Object(1), Reason::BadObject)
    );
    // Wrong parents: none where there is one, one where there is none, not the smallest.
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, None);
            b.add_object(18, 2, None);
        }),
        (Site::Object(1), Reason::BadObject)
    );
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, None);
            b.add_object(30, 2, Some(0));
        }),
        (Site::Object(1), Reason::BadObject)
    );
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, None);
            b.add_object(16, 4, Some(0));
            b.add_object(17, 1, Some(0));
        }),
        (Site::Object(2), Reason::BadObject)
    );
    // A parent index that is not earlier.
    assert_eq!(
        bad_object(|b| {
            b.add_object(16, 8, Some(0));
        }),
        (Site::Object(0), Reason::BadObject)
    );
    // Nesting depth.
    assert_eq!(
        verdict(|b, _, _| {
            let mut parent = None;
            for level in 0..crate::image::MAX_OBJECT_DEPTH as u32 {
                parent = Some(b.add_object(16 + level, 64 - 2 * level, parent));
            }
        }),
        Ok(())
    );
    assert_eq!(
        bad_object(|b| {
            let mut parent = None;
            for level in 0..=crate::image::MAX_OBJECT_DEPTH as u32 {
                parent = Some(b.add_object(16 + level, 64 - 2 * level, parent));
            }
        }),
        (
            Site::Object(crate::image::MAX_OBJECT_DEPTH),
            Reason::BadObject
        )
    );
    // Siblings after a nested chain close the chain.
    assert_eq!(
        verdict(|b, _, _| {
            let a = b.add_object(16, 16, None);
            let c = b.add_object(16, 8, Some(a));
            b.add_object(18, 2, Some(c));
            b.add_object(24, 8, Some(a));
            b.add_object(40, 8, None);
        }),
        Ok(())
    );
    assert_eq!(
        verdict(|b, main, _| {
            b.add_class("A", &[(1, main, 0), (2, main, DATA - 1)]);
        }),
        Ok(())
    );
    // A method that takes cells would break the verifier's fixed stack effect of CALL_VIRT.
    assert_eq!(
        verdict(|b, _, f| {
            b.add_class("A", &[(1, f, 0)]);
        }),
        Err((Site::Dispatch(0), Reason::BadDispatch))
    );
    assert_eq!(
        verdict(|b, main, _| {
            b.add_class("A", &[(1, main, DATA)]);
        }),
        Err((Site::Dispatch(0), Reason::BadDispatch))
    );
    assert_eq!(
        verdict(|b, main, _| {
            b.add_class("A", &[(1, main, 0), (1, main, 4)]);
        }),
        Err((Site::Dispatch(1), Reason::BadDispatch))
    );
    assert_eq!(
        verdict(|b, main, _| {
            b.add_class("A", &[(1, PouId(main.0 + 7), 0)]);
        }),
        Err((Site::Dispatch(0), Reason::BadDispatch))
    );
}

#[test]
fn verifier_rejects_a_class_range_outside_the_dispatch_table() {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    b.begin_pou(main);
    b.ret();
    b.end_pou(main);
    b.add_class("A", &[(1, main, 0)]);
    let mut bytes = b.build().unwrap();
    // Patch the class record's count from 1 to 2.
    let image = Image::parse(&bytes).unwrap();
    let classes = image.class(0).unwrap();
    assert_eq!(classes.count, 1);
    let table = 16 + Section::Classes as usize * 8;
    let at = u32::from_le_bytes(bytes[table..table + 4].try_into().unwrap()) as usize;
    bytes[at + 12] = 2;
    let image = Image::parse(&bytes).unwrap();
    assert_eq!(
        verify(&image).map(|_| ()).map_err(|e| (e.site, e.reason)),
        Err((Site::Class(0), Reason::BadClass))
    );
}

#[test]
fn new_instructions_have_their_stack_effects_checked() {
    // REF_ADD needs two cells.
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    b.begin_pou(main);
    b.push_i32(1);
    b.ref_add();
    b.drop_();
    b.ret();
    b.end_pou(main);
    let bytes = b.build().unwrap();
    let e = verify(&Image::parse(&bytes).unwrap())
        .map(|_| ())
        .unwrap_err();
    assert!(matches!(
        e.reason,
        Reason::StackUnderflow {
            depth: 1,
            needed: 2
        }
    ));
    // CALL_VIRT pops the instance and pushes nothing: a RET right after a lone instance
    // returns with an empty stack.
    for op in [Opcode::CallVirt, Opcode::VirtFrame] {
        let mut b = ImageBuilder::new();
        b.reserve_data(DATA);
        let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
        b.begin_pou(main);
        b.push_i32(64);
        if op == Opcode::CallVirt {
            b.call_virt(0);
        } else {
            b.virt_frame(0);
        }
        b.ret();
        b.end_pou(main);
        let bytes = b.build().unwrap();
        let r = verify(&Image::parse(&bytes).unwrap()).map(|_| ());
        if op == Opcode::CallVirt {
            assert!(r.is_ok());
        } else {
            assert!(matches!(
                r.unwrap_err().reason,
                Reason::ReturnDepth {
                    expected: 0,
                    found: 1
                }
            ));
        }
    }
}
