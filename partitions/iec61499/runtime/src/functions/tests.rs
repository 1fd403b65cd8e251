//! The function FBs: typing by connection and by binding, each operation on its types,
//! wrapping, refusals.

use super::*;
use crate::resource::{DeployError, Limits, Resource};
use crate::{Fault, stdlib};
use alloc::format;

fn resource(fbs: &[(&str, &str)]) -> Resource {
    let mut r = Resource::new(Limits::default());
    for (name, ty) in fbs {
        let fb = create(ty).or_else(|| stdlib::create(ty)).unwrap();
        r.create(name, fb).unwrap();
    }
    r
}

/// `F` of type `ty` bound to `dt`, run once on `inputs`; its OUT.
fn run(ty: &str, dt: DataType, inputs: &[(&str, Value)]) -> Value {
    let mut r = resource(&[("F", ty)]);
    let first = inputs.iter().find(|(n, _)| r.is_unbound(&format!("F.{n}")));
    if let Some((n, _)) = first {
        r.bind(&format!("F.{n}"), dt).unwrap();
    }
    for (n, v) in inputs {
        r.write(&format!("F.{n}"), v.clone()).unwrap();
    }
    r.trigger("F.REQ", 0).unwrap();
    assert_eq!(r.fault(), None);
    r.read("F.OUT").unwrap().clone()
}

#[test]
fn every_type_is_created_with_reg_and_cnf() {
    for ty in TYPES {
        let fb = create(ty).unwrap();
        let i = fb.interface();
        assert_eq!(
            (i.event_inputs.len(), i.event_outputs.len()),
            (1, 1),
            "{ty}"
        );
        assert_eq!(i.event_inputs[0].with.len(), i.inputs.len(), "{ty}");
        assert_eq!(i.outputs[0].name, "OUT", "{ty}");
    }
    assert!(create("F_NOPE").is_none());
}

#[test]
fn arithmetic_wraps_to_the_type() {
    use Value::*;
    let add = |dt, a, b| run("F_ADD", dt, &[("IN1", a), ("IN2", b)]);
    assert_eq!(
        add(DataType::DInt, Int(i32::MAX.into()), Int(1)),
        Int(i32::MIN.into())
    );
    assert_eq!(add(DataType::USInt, UInt(250), UInt(10)), UInt(4));
    assert_eq!(add(DataType::LReal, Real(0.5), Real(0.25)), Real(0.75));
    assert_eq!(
        run(
            "F_SUB",
            DataType::Time,
            &[("IN1", Time(5)), ("IN2", Time(7))]
        ),
        Time(-2)
    );
    assert_eq!(
        run(
            "F_MUL",
            DataType::Int,
            &[("IN1", Int(300)), ("IN2", Int(300))]
        ),
        Int(90_000 - 65_536)
    );
    assert_eq!(
        run(
            "F_DIV",
            DataType::DInt,
            &[("IN1", Int(-7)), ("IN2", Int(2))]
        ),
        Int(-3)
    );
    assert_eq!(
        run(
            "F_MOD",
            DataType::DInt,
            &[("IN1", Int(-7)), ("IN2", Int(2))]
        ),
        Int(-1)
    );
}

#[test]
fn an_integer_division_by_zero_stops_the_resource() {
    let mut r = resource(&[("F", "F_DIV")]);
    r.bind("F.OUT", DataType::DInt).unwrap();
    r.write("F.IN1", Value::Int(1)).unwrap();
    r.trigger("F.REQ", 0).unwrap();
    assert_eq!(
        r.fault(),
        Some(&Fault::Trap {
            fb: "F".into(),
            reason: "integer division by zero".into()
        })
    );
}

#[test]
fn comparisons_bits_and_selection() {
    use Value::*;
    for (ty, a, b, expected) in [
        ("F_EQ", Int(26), Int(26), true),
        ("F_NE", Int(26), Int(26), false),
        ("F_GT", Int(3), Int(-2), true),
        ("F_GE", Int(3), Int(3), true),
        ("F_LT", Int(3), Int(3), false),
        ("F_LE", Int(-3), Int(3), true),
    ] {
        let out = run(ty, DataType::DInt, &[("IN1", a), ("IN2", b)]);
        assert_eq!(out, Bool(expected), "{ty}");
    }
    assert_eq!(
        run(
            "F_LT",
            DataType::LReal,
            &[("IN1", Real(0.1)), ("IN2", Real(0.2))]
        ),
        Bool(true)
    );
    assert_eq!(
        run("F_NOT", DataType::Byte, &[("IN", UInt(0x0F))]),
        UInt(0xF0)
    );
    assert_eq!(
        run("F_NOT", DataType::Bool, &[("IN", Bool(false))]),
        Bool(true)
    );
    assert_eq!(
        run(
            "F_XOR",
            DataType::Word,
            &[("IN1", UInt(0xFF00)), ("IN2", UInt(0x0FF0))]
        ),
        UInt(0xF0F0)
    );
    assert_eq!(
        run(
            "F_AND",
            DataType::Bool,
            &[("IN1", Bool(true)), ("IN2", Bool(false))]
        ),
        Bool(false)
    );
    assert_eq!(
        run(
            "F_OR",
            DataType::Bool,
            &[("IN1", Bool(true)), ("IN2", Bool(false))]
        ),
        Bool(true)
    );
    assert_eq!(
        run(
            "F_SEL",
            DataType::DInt,
            &[("G", Bool(true)), ("IN0", Int(1)), ("IN1", Int(2))]
        ),
        Int(2)
    );
    assert_eq!(run("F_MOVE", DataType::DInt, &[("IN", Int(9))]), Int(9));
    assert_eq!(
        run(
            "F_MAX",
            DataType::DInt,
            &[("IN1", Int(-1)), ("IN2", Int(4))]
        ),
        Int(4)
    );
    assert_eq!(
        run(
            "F_MIN",
            DataType::DInt,
            &[("IN1", Int(-1)), ("IN2", Int(4))]
        ),
        Int(-1)
    );
}

#[test]
fn mux_selects_by_k_and_keeps_out_for_a_k_out_of_range() {
    let mut r = resource(&[("M", "F_MUX_2"), ("C", "E_CTU")]);
    r.bind("M.K", DataType::UInt).unwrap();
    r.bind("M.IN1", DataType::DInt).unwrap();
    r.connect_event("M.CNF", "C.CU").unwrap();
    r.write("M.IN1", Value::Int(5)).unwrap();
    r.write("M.IN2", Value::Int(6)).unwrap();
    for (k, out) in [(0, 5), (1, 6), (2, 6), (0, 5)] {
        r.write("M.K", Value::UInt(k)).unwrap();
        r.trigger("M.REQ", 0).unwrap();
        assert_eq!(r.read("M.OUT"), Some(&Value::Int(out)), "K = {k}");
    }
    // CNF every time, also for K out of range.
    assert_eq!(r.read("C.CV"), Some(&Value::UInt(4)));
}

#[test]
fn a_connection_types_a_generic_end_and_a_class_refuses_a_type() {
    let mut r = resource(&[
        ("C", "E_CTU"),
        ("EQ", "F_EQ"),
        ("N", "F_NOT"),
        ("A", "F_ADD"),
    ]);
    assert!(r.is_unbound("EQ.IN1") && r.is_unbound("EQ.IN2"));
    r.connect_data("C.CV", "EQ.IN1").unwrap();
    // The group took UINT: IN2 too.
    assert!(!r.is_unbound("EQ.IN2"));
    assert_eq!(r.read("EQ.IN2"), Some(&Value::UInt(0)));
    assert!(matches!(
        r.connect_data("C.Q", "EQ.IN2"),
        Err(DeployError::Mismatch(_))
    ));
    // ANY_BIT takes no REAL, ANY_MAGNITUDE no BOOL.
    assert!(matches!(
        r.bind("N.IN", DataType::Real),
        Err(DeployError::Mismatch(_))
    ));
    assert!(matches!(
        r.connect_data("C.Q", "A.IN1"),
        Err(DeployError::Mismatch(_))
    ));
    // Two untyped ends: refused with what to do.
    let e = r.connect_data("A.OUT", "N.IN").unwrap_err();
    assert!(format!("{e}").contains("typed literal"), "{e}");
    // A fixed-type port is no generic one.
    assert!(!r.is_unbound("EQ.OUT"));
    assert!(matches!(
        r.bind("EQ.OUT", DataType::DInt),
        Err(DeployError::Mismatch(_))
    ));
    // A REQ before the types are known: CNF, nothing computed.
    r.connect_event("A.CNF", "C.CU").unwrap();
    r.trigger("A.REQ", 0).unwrap();
    assert_eq!(r.read("C.CV"), Some(&Value::UInt(1)));
}

#[test]
fn a_connection_widens_without_loss_and_refuses_the_rest() {
    use crate::value::widens;
    use DataType::*;
    for (from, to) in [
        (SInt, LInt),
        (USInt, Int),
        (UInt, UDInt),
        (UDInt, LInt),
        (Byte, LWord),
        (Real, LReal),
        (UInt, Real),
        (DInt, LReal),
    ] {
        assert!(widens(from, to), "{from:?} to {to:?}");
    }
    for (from, to) in [
        (UInt, Int),
        (Int, UInt),
        (DInt, Real),
        (LReal, Real),
        (Word, UInt),
        (Bool, Byte),
        (Time, LInt),
    ] {
        assert!(!widens(from, to), "{from:?} to {to:?}");
    }
    // E_CTU's CV (UINT) into an LREAL and a DINT input: the values arrive converted.
    let mut r = resource(&[("C", "E_CTU"), ("X", "F_MOVE"), ("Y", "F_MOVE")]);
    r.bind("X.IN", LReal).unwrap();
    r.bind("Y.IN", DInt).unwrap();
    r.connect_data("C.CV", "X.IN").unwrap();
    r.connect_data("C.CV", "Y.IN").unwrap();
    r.connect_event("C.CUO", "X.REQ").unwrap();
    r.connect_event("C.CUO", "Y.REQ").unwrap();
    r.trigger("C.CU", 0).unwrap();
    assert_eq!(r.read("X.OUT"), Some(&Value::Real(1.0)));
    assert_eq!(r.read("Y.OUT"), Some(&Value::Int(1)));
    // A narrowing connection is refused.
    let mut r = resource(&[("C", "E_CTU"), ("Z", "F_MOVE")]);
    r.bind("Z.IN", SInt).unwrap();
    assert!(matches!(
        r.connect_data("C.CV", "Z.IN"),
        Err(DeployError::Mismatch(_))
    ));
}
