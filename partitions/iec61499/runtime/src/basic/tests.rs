//! The ECC interpreter: E_CTU and E_D_FF written as basic FBs the way 4diac's library
//! defines them (ECC and algorithms), run side by side with the native standard FBs on the
//! same event sequences; ECC verification; loops and traps as faults.

extern crate std;

use super::*;
use crate::fb::Interface;
use crate::resource::{Fault, Limits, Resource};
use crate::stdlib;
use crate::value::DataType;
use alloc::vec;
use proptest::prelude::*;

/// Algorithms and guards as Rust closures over the variables.
type Alg = fn(&mut Vars<'_>) -> Result<(), String>;
type Guard = fn(&mut Vars<'_>) -> Result<bool, String>;

struct Closures(Vec<Alg>, Vec<Guard>);

impl Algorithms for Closures {
    fn run(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<(), String> {
        (self.0[index])(vars)
    }
    fn guard(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<bool, String> {
        (self.1[index])(vars)
    }
    fn counts(&self) -> (usize, usize) {
        (self.0.len(), self.1.len())
    }
}

fn state(name: &str, actions: &[(Option<usize>, Option<usize>)]) -> State {
    State {
        name: name.into(),
        actions: actions
            .iter()
            .map(|&(algorithm, output)| Action { algorithm, output })
            .collect(),
    }
}

fn tr(source: usize, destination: usize, event: Option<usize>, guard: Option<usize>) -> Transition {
    Transition {
        source,
        destination,
        event,
        guard,
    }
}

/// E_CTU as 4diac's E_CTU.fbt defines it: START -CU[CV < 65535]-> CU (alg CU, CUO) -1->
/// START; START -R-> R (alg R, RO) -1-> START.
fn basic_ctu() -> BasicFb {
    let interface = stdlib::create("E_CTU").unwrap().interface().clone();
    let ecc = Ecc {
        states: vec![
            state("START", &[]),
            state("CU", &[(Some(0), Some(0))]),
            state("R", &[(Some(1), Some(1))]),
        ],
        transitions: vec![
            tr(0, 1, Some(0), Some(0)),
            tr(1, 0, None, None),
            tr(0, 2, Some(1), None),
            tr(2, 0, None, None),
        ],
    };
    let cu: Alg = |v| {
        let cv = v.outputs[1].as_u64() + 1;
        v.outputs[1] = Value::UInt(cv);
        v.outputs[0] = Value::Bool(cv >= v.inputs[0].as_u64());
        Ok(())
    };
    let r: Alg = |v| {
        v.outputs[1] = Value::UInt(0);
        v.outputs[0] = Value::Bool(false);
        Ok(())
    };
    let below_max: Guard = |v| Ok(v.outputs[1].as_u64() < 65_535);
    BasicFb::new(
        interface,
        ecc,
        vec![],
        Box::new(Closures(vec![cu, r], vec![below_max])),
    )
    .unwrap()
}

/// E_D_FF as 4diac's: START -CLK[D]-> SET (LATCH, EO); SET -CLK[NOT D]-> RESET (LATCH, EO);
/// RESET -CLK[D]-> SET.
fn basic_d_ff() -> BasicFb {
    let interface = stdlib::create("E_D_FF").unwrap().interface().clone();
    let ecc = Ecc {
        states: vec![
            state("START", &[]),
            state("SET", &[(Some(0), Some(0))]),
            state("RESET", &[(Some(0), Some(0))]),
        ],
        transitions: vec![
            tr(0, 1, Some(0), Some(0)),
            tr(1, 2, Some(0), Some(1)),
            tr(2, 1, Some(0), Some(0)),
        ],
    };
    let latch: Alg = |v| {
        v.outputs[0] = v.inputs[0].clone();
        Ok(())
    };
    let d: Guard = |v| Ok(v.inputs[0].as_bool());
    let not_d: Guard = |v| Ok(!v.inputs[0].as_bool());
    BasicFb::new(
        interface,
        ecc,
        vec![],
        Box::new(Closures(vec![latch], vec![d, not_d])),
    )
    .unwrap()
}

/// Runs the same input sequence into a native and a basic instance (`A` and `B`, their
/// outputs recorded after every event) and returns both traces.
fn side_by_side(
    basic: BasicFb,
    ty: &str,
    steps: &[(usize, Vec<(usize, Value)>)],
) -> (Vec<Vec<Value>>, Vec<Vec<Value>>) {
    let mut r = Resource::new(Limits::default());
    r.create("A", stdlib::create(ty).unwrap()).unwrap();
    r.create("B", Box::new(basic)).unwrap();
    let interface = stdlib::create(ty).unwrap().interface().clone();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for (event, params) in steps {
        for (var, value) in params {
            let name = &interface.inputs[*var].name;
            r.write(&format!("A.{name}"), value.clone()).unwrap();
            r.write(&format!("B.{name}"), value.clone()).unwrap();
        }
        let e = &interface.event_inputs[*event].name;
        r.trigger(&format!("A.{e}"), 0).unwrap();
        r.trigger(&format!("B.{e}"), 0).unwrap();
        let outs = |fb: &str| {
            interface
                .outputs
                .iter()
                .map(|o| r.read(&format!("{fb}.{}", o.name)).unwrap().clone())
                .collect::<Vec<_>>()
        };
        a.push(outs("A"));
        b.push(outs("B"));
    }
    (a, b)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn basic_and_native_e_ctu_agree(steps in proptest::collection::vec((0usize..2, 0u64..6), 1..60)) {
        let steps: Vec<_> = steps.into_iter().map(|(e, pv)| (e, vec![(0, Value::UInt(pv))])).collect();
        let (native, basic) = side_by_side(basic_ctu(), "E_CTU", &steps);
        prop_assert_eq!(native, basic);
    }

    #[test]
    fn basic_and_native_e_d_ff_agree(ds in proptest::collection::vec(any::<bool>(), 1..60)) {
        let steps: Vec<_> = ds.into_iter().map(|d| (0, vec![(0, Value::Bool(d))])).collect();
        let (native, basic) = side_by_side(basic_d_ff(), "E_D_FF", &steps);
        prop_assert_eq!(native, basic);
    }
}

#[test]
fn the_ecc_is_verified() {
    let interface = Interface::build(
        &[("REQ", &[])],
        &[("CNF", &[])],
        &[],
        &[("N", DataType::Int, None)],
    )
    .unwrap();
    let code = || Box::new(Closures(vec![|_| Ok(())], vec![])) as Box<dyn Algorithms>;
    let bad = [
        (Ecc::default(), "no state"),
        (
            Ecc {
                states: vec![state("S", &[(Some(1), None)])],
                transitions: vec![],
            },
            "algorithm",
        ),
        (
            Ecc {
                states: vec![state("S", &[(None, Some(1))])],
                transitions: vec![],
            },
            "output event",
        ),
        (
            Ecc {
                states: vec![state("S", &[])],
                transitions: vec![tr(0, 1, None, None)],
            },
            "connects state",
        ),
        (
            Ecc {
                states: vec![state("S", &[])],
                transitions: vec![tr(0, 0, Some(3), None)],
            },
            "input event",
        ),
        (
            Ecc {
                states: vec![state("S", &[])],
                transitions: vec![tr(0, 0, None, Some(0))],
            },
            "guard",
        ),
    ];
    for (ecc, message) in bad {
        let e = BasicFb::new(interface.clone(), ecc, vec![], code())
            .err()
            .unwrap();
        assert!(e.contains(message), "{e}");
    }
}

#[test]
fn an_ecc_loop_and_a_trapping_algorithm_stop_the_resource() {
    let interface = Interface::build(
        &[("REQ", &[])],
        &[("CNF", &[])],
        &[],
        &[("N", DataType::Int, None)],
    )
    .unwrap();
    let looping = Ecc {
        states: vec![state("A", &[]), state("B", &[])],
        transitions: vec![tr(0, 1, None, None), tr(1, 0, None, None)],
    };
    let fb = BasicFb::new(
        interface.clone(),
        looping,
        vec![],
        Box::new(Closures(vec![], vec![])),
    )
    .unwrap();
    let mut r = Resource::new(Limits::default());
    r.create("L", Box::new(fb)).unwrap();
    r.trigger("L.REQ", 0).unwrap();
    assert!(
        matches!(r.fault(), Some(Fault::Trap { fb, reason }) if fb == "L" && reason.contains("loop"))
    );

    let trapping = Ecc {
        states: vec![state("START", &[]), state("RUN", &[(Some(0), Some(0))])],
        transitions: vec![tr(0, 1, Some(0), None), tr(1, 0, None, None)],
    };
    let div: Alg = |_| Err("DIVISION_BY_ZERO".into());
    let fb = BasicFb::new(
        interface,
        trapping,
        vec![],
        Box::new(Closures(vec![div], vec![])),
    )
    .unwrap();
    let mut r = Resource::new(Limits::default());
    r.create("T", Box::new(fb)).unwrap();
    r.create("M", stdlib::create("E_MERGE").unwrap()).unwrap();
    r.connect_event("T.CNF", "M.EI1").unwrap();
    r.trigger("T.REQ", 0).unwrap();
    assert_eq!(
        r.fault(),
        Some(&Fault::Trap {
            fb: "T".into(),
            reason: "DIVISION_BY_ZERO".into()
        })
    );
    assert_eq!(r.delivered(), 1, "CNF was not delivered");
}
