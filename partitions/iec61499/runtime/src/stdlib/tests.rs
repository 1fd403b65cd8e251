//! Every standard FB on event sequences, and the resource's execution semantics: fan-out
//! order, data sampled at send time, queue overflow and event loops as faults, timers on
//! absolute deadlines, restart and reset.

extern crate std;

use super::*;
use crate::fb::Restart;
use crate::resource::{DeployError, Fault, Limits, Resource};
use alloc::format;
use alloc::rc::Rc;
use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;
use core::cell::RefCell;
use proptest::prelude::*;

/// What a recorder saw: (time, event input, its inputs).
type Log = Rc<RefCell<Vec<(i64, usize, Vec<Value>)>>>;

/// A test FB: event inputs E0..E3, each WITH every data input; logs each delivery.
struct Recorder {
    interface: Interface,
    log: Log,
}

fn recorder(inputs: &[(&str, DataType)]) -> (Box<dyn FunctionBlock>, Log) {
    let names: Vec<&str> = inputs.iter().map(|(n, _)| *n).collect();
    let vars: Vec<VarDecl<'_>> = inputs.iter().map(|(n, t)| (*n, *t, None)).collect();
    let events: Vec<EventDecl<'_>> = ["E0", "E1", "E2", "E3"]
        .iter()
        .map(|e| (*e, &names[..]))
        .collect();
    let interface = Interface::build(&events, &[], &vars, &[]).unwrap();
    let log: Log = Rc::default();
    (
        Box::new(Recorder {
            interface,
            log: log.clone(),
        }),
        log,
    )
}

impl FunctionBlock for Recorder {
    fn interface(&self) -> &Interface {
        &self.interface
    }
    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        self.log
            .borrow_mut()
            .push((ctx.now(), event, inputs.to_vec()));
    }
    fn reset(&mut self) {}
}

/// A test FB that sets OUT to 1, sends EO, sets OUT to 2 and sends EO again in one reaction
/// (as an ECC passing two states would).
struct Twice(Interface);

impl FunctionBlock for Twice {
    fn interface(&self) -> &Interface {
        &self.0
    }
    fn event(&mut self, _: usize, _: &[Value], ctx: &mut Context<'_>) {
        ctx.set(0, Value::UInt(1));
        ctx.send(0);
        ctx.set(0, Value::UInt(2));
        ctx.send(0);
    }
    fn reset(&mut self) {}
}

/// A resource with `fb` of type `ty` and a recorder `REC` whose event Ek is fed by the FB's
/// k-th output event, and whose inputs take the FB's outputs.
fn harness(ty: &str) -> (Resource, Log) {
    let mut r = Resource::new(Limits::default());
    let fb = create(ty).unwrap();
    let outs: Vec<(String, DataType)> = fb
        .interface()
        .outputs
        .iter()
        .map(|v| (v.name.clone(), v.ty))
        .collect();
    let events: Vec<String> = fb
        .interface()
        .event_outputs
        .iter()
        .map(|e| e.name.clone())
        .collect();
    r.create("FB", fb).unwrap();
    let decl: Vec<(&str, DataType)> = outs.iter().map(|(n, t)| (n.as_str(), *t)).collect();
    let (rec, log) = recorder(&decl);
    r.create("REC", rec).unwrap();
    for (k, e) in events.iter().enumerate() {
        r.connect_event(&format!("FB.{e}"), &format!("REC.E{k}"))
            .unwrap();
    }
    for (n, _) in &outs {
        r.connect_data(&format!("FB.{n}"), &format!("REC.{n}"))
            .unwrap();
    }
    (r, log)
}

/// The output events seen (their indices), forgetting the log.
fn seen(log: &Log) -> Vec<usize> {
    log.borrow_mut().drain(..).map(|(_, e, _)| e).collect()
}

fn fire(r: &mut Resource, events: &[&str]) {
    for e in events {
        r.trigger(&format!("FB.{e}"), 0).unwrap();
    }
}

#[test]
fn event_routing_blocks() {
    let (mut r, log) = harness("E_SPLIT");
    fire(&mut r, &["EI"]);
    assert_eq!(seen(&log), [0, 1]);
    let (mut r, log) = harness("E_MERGE");
    fire(&mut r, &["EI1", "EI2"]);
    assert_eq!(seen(&log), [0, 0]);
    let (mut r, log) = harness("E_REND");
    fire(&mut r, &["EI1", "EI1", "EI2", "EI2", "R", "EI1", "EI2"]);
    assert_eq!(seen(&log), [0, 0]);
    let (mut r, log) = harness("E_PERMIT");
    fire(&mut r, &["EI"]);
    r.write("FB.PERMIT", Value::Bool(true)).unwrap();
    fire(&mut r, &["EI"]);
    assert_eq!(seen(&log), [0]);
    let (mut r, log) = harness("E_SELECT");
    fire(&mut r, &["EI0", "EI1"]);
    r.write("FB.G", Value::Bool(true)).unwrap();
    fire(&mut r, &["EI0", "EI1"]);
    assert_eq!(seen(&log), [0, 0]);
    let (mut r, log) = harness("E_SWITCH");
    fire(&mut r, &["EI"]);
    r.write("FB.G", Value::Bool(true)).unwrap();
    fire(&mut r, &["EI"]);
    assert_eq!(seen(&log), [0, 1]);
    let (mut r, log) = harness("E_DEMUX");
    for k in [0, 3, 4, 1, 2, 99] {
        r.write("FB.K", Value::UInt(k)).unwrap();
        fire(&mut r, &["EI"]);
    }
    assert_eq!(seen(&log), [0, 3, 1, 2]);
}

fn q_log(log: &Log) -> Vec<bool> {
    log.borrow_mut()
        .drain(..)
        .map(|(_, _, v)| v[0].as_bool())
        .collect()
}

#[test]
fn bistables_and_edges() {
    for ty in ["E_SR", "E_RS"] {
        let (mut r, log) = harness(ty);
        fire(&mut r, &["R", "R", "S", "S", "R"]);
        assert_eq!(
            q_log(&log),
            [true, false],
            "{ty}: R before any S does nothing"
        );
    }
    let (mut r, log) = harness("E_T_FF");
    fire(&mut r, &["CLK", "CLK", "CLK"]);
    assert_eq!(q_log(&log), [true, false, true]);
    let (mut r, log) = harness("E_D_FF");
    for d in [false, true, true, false, true] {
        r.write("FB.D", Value::Bool(d)).unwrap();
        fire(&mut r, &["CLK"]);
    }
    assert_eq!(q_log(&log), [true, false, true]);
    for (ty, expected) in [("E_R_TRIG", 2), ("E_F_TRIG", 1)] {
        let (mut r, log) = harness(ty);
        for qi in [false, true, true, false, false, true] {
            r.write("FB.QI", Value::Bool(qi)).unwrap();
            fire(&mut r, &["EI"]);
        }
        assert_eq!(seen(&log).len(), expected, "{ty}");
    }
}

fn counter_log(log: &Log) -> Vec<(usize, Vec<Value>)> {
    log.borrow_mut().drain(..).map(|(_, e, v)| (e, v)).collect()
}

#[test]
fn counters() {
    let (mut r, log) = harness("E_CTU");
    r.write("FB.PV", Value::UInt(2)).unwrap();
    fire(&mut r, &["CU", "CU", "CU", "R"]);
    let b = Value::Bool;
    assert_eq!(
        counter_log(&log),
        [
            (0, vec![b(false), Value::UInt(1)]),
            (0, vec![b(true), Value::UInt(2)]),
            (0, vec![b(true), Value::UInt(3)]),
            (1, vec![b(false), Value::UInt(0)]),
        ]
    );
    let (mut r, log) = harness("E_CTD");
    r.write("FB.PV", Value::UInt(1)).unwrap();
    fire(&mut r, &["CD", "LD", "CD", "CD"]);
    assert_eq!(
        counter_log(&log),
        [
            (1, vec![b(false), Value::UInt(1)]),
            (0, vec![b(true), Value::UInt(0)])
        ]
    );
    let (mut r, log) = harness("E_CTUD");
    r.write("FB.PV", Value::UInt(2)).unwrap();
    fire(&mut r, &["CD", "CU", "CU", "CD", "LD", "R"]);
    let at = |qu, qd, cv| vec![b(qu), b(qd), Value::UInt(cv)];
    assert_eq!(
        counter_log(&log),
        [
            (0, at(false, false, 1)),
            (0, at(true, false, 2)),
            (0, at(false, false, 1)),
            (2, at(true, false, 2)),
            (1, at(false, true, 0)),
        ]
    );
    // The count stops at 65,535.
    let (mut r, log) = harness("E_CTU");
    r.write("FB.PV", Value::UInt(65_535)).unwrap();
    for _ in 0..65_536 {
        fire(&mut r, &["CU"]);
    }
    assert_eq!(log.borrow().len(), 65_535);
    assert_eq!(r.read("FB.CV"), Some(&Value::UInt(65_535)));
}

const MS: i64 = 1_000_000;

/// Advances `r` to each instant of `at` and returns the times of the recorded events.
fn times(r: &mut Resource, log: &Log, until: i64) -> Vec<(i64, usize)> {
    let mut now = 0;
    while let Some(next) = r.next_deadline().filter(|n| *n <= until) {
        now = now.max(next);
        r.advance(now).unwrap();
    }
    log.borrow_mut().drain(..).map(|(t, e, _)| (t, e)).collect()
}

#[test]
fn delays() {
    let (mut r, log) = harness("E_DELAY");
    r.write("FB.DT", Value::Time(5 * MS)).unwrap();
    r.trigger("FB.START", 0).unwrap();
    r.trigger("FB.START", 2 * MS).unwrap(); // ignored while it runs
    assert_eq!(times(&mut r, &log, 100 * MS), [(5 * MS, 0)]);
    r.trigger("FB.START", 10 * MS).unwrap();
    r.trigger("FB.STOP", 12 * MS).unwrap();
    assert_eq!(times(&mut r, &log, 100 * MS), []);
    let (mut r, log) = harness("E_RDELAY");
    r.write("FB.DT", Value::Time(5 * MS)).unwrap();
    r.trigger("FB.START", 0).unwrap();
    r.trigger("FB.START", 2 * MS).unwrap(); // restarts
    assert_eq!(times(&mut r, &log, 100 * MS), [(7 * MS, 0)]);
}

#[test]
fn e_cycle_does_not_drift() {
    let (mut r, log) = harness("E_CYCLE");
    r.write("FB.DT", Value::Time(MS)).unwrap();
    r.trigger("FB.START", 3).unwrap();
    // The partition's clock reaches each deadline late by a varying amount.
    let mut fired = 0;
    let mut now = 3;
    while fired < 100_000 {
        now += MS + (fired as i64 * 7919 % 200_000);
        fired += r.advance(now).unwrap();
    }
    let events = log.borrow();
    assert!(events.len() >= 100_000);
    for (n, (t, _, _)) in events.iter().enumerate() {
        assert_eq!(*t, 3 + (n as i64 + 1) * MS, "event {n}");
    }
    drop(events);
    r.trigger("FB.STOP", now).unwrap();
    assert_eq!(r.next_deadline(), None);
    // A zero period sends nothing rather than loop.
    let (mut r, log) = harness("E_CYCLE");
    r.trigger("FB.START", 0).unwrap();
    assert_eq!(r.next_deadline(), None);
    assert!(log.borrow().is_empty());
}

#[test]
fn tables_and_trains() {
    let dt = Value::Array([1, 2, 3, 4].iter().map(|m| Value::Time(m * MS)).collect());
    let (mut r, log) = harness("E_TABLE");
    r.write("FB.DT", dt.clone()).unwrap();
    r.write("FB.N", Value::UInt(3)).unwrap();
    r.trigger("FB.START", 0).unwrap();
    let got: Vec<(i64, u64)> = {
        let mut now = 0;
        while let Some(next) = r.next_deadline() {
            now = now.max(next);
            r.advance(now).unwrap();
        }
        log.borrow()
            .iter()
            .map(|(t, _, v)| (*t, v[0].as_u64()))
            .collect()
    };
    assert_eq!(got, [(MS, 0), (3 * MS, 1), (6 * MS, 2)]);
    let (mut r, log) = harness("E_N_TABLE");
    r.write("FB.DT", dt).unwrap();
    r.write("FB.N", Value::UInt(9)).unwrap();
    r.trigger("FB.START", 0).unwrap();
    assert_eq!(
        times(&mut r, &log, i64::MAX),
        [(MS, 0), (3 * MS, 1), (6 * MS, 2), (10 * MS, 3)]
    );
    let (mut r, log) = harness("E_TRAIN");
    r.write("FB.DT", Value::Time(2 * MS)).unwrap();
    r.write("FB.N", Value::UInt(3)).unwrap();
    r.trigger("FB.START", 0).unwrap();
    let mut now = 0;
    while let Some(next) = r.next_deadline() {
        now = now.max(next);
        r.advance(now).unwrap();
    }
    let got: Vec<(i64, u64)> = log
        .borrow()
        .iter()
        .map(|(t, _, v)| (*t, v[0].as_u64()))
        .collect();
    assert_eq!(got, [(2 * MS, 0), (4 * MS, 1), (6 * MS, 2)]);
}

#[test]
fn restart_events() {
    let (mut r, log) = harness("E_RESTART");
    r.restart(Restart::Cold, 0).unwrap();
    r.restart(Restart::Warm, 0).unwrap();
    r.restart(Restart::Stop, 0).unwrap();
    assert_eq!(seen(&log), [0, 1, 2]);
}

#[test]
fn fan_out_keeps_the_connection_order() {
    let mut r = Resource::new(Limits::default());
    r.create("S", create("E_SPLIT").unwrap()).unwrap();
    let (rec, log) = recorder(&[]);
    r.create("REC", rec).unwrap();
    for to in ["REC.E2", "REC.E0", "REC.E3"] {
        r.connect_event("S.EO1", to).unwrap();
    }
    r.connect_event("S.EO2", "REC.E1").unwrap();
    r.trigger("S.EI", 0).unwrap();
    assert_eq!(seen(&log), [2, 0, 3, 1]);
}

#[test]
fn data_travels_with_its_event() {
    // Two sends in one reaction carry the value each had when it was sent.
    let mut r = Resource::new(Limits::default());
    let twice = Interface::build(
        &[("REQ", &[])],
        &[("EO", &["OUT"])],
        &[],
        &[("OUT", DataType::UInt, None)],
    )
    .unwrap();
    r.create("T", Box::new(Twice(twice))).unwrap();
    let (rec, log) = recorder(&[("V", DataType::UInt)]);
    r.create("REC", rec).unwrap();
    r.connect_event("T.EO", "REC.E0").unwrap();
    r.connect_data("T.OUT", "REC.V").unwrap();
    r.trigger("T.REQ", 0).unwrap();
    let values: Vec<u64> = log.borrow().iter().map(|(_, _, v)| v[0].as_u64()).collect();
    assert_eq!(values, [1, 2]);

    // A value changed by an event delivered in between is not seen: the counter counts
    // before the recorder's event (queued second) is delivered, yet it gets the old count.
    let mut r = Resource::new(Limits::default());
    r.create("S", create("E_SPLIT").unwrap()).unwrap();
    r.create("C", create("E_CTU").unwrap()).unwrap();
    let (rec, log) = recorder(&[("CV", DataType::UInt)]);
    r.create("REC", rec).unwrap();
    r.connect_event("S.EO1", "C.CU").unwrap();
    r.connect_event("S.EO2", "REC.E0").unwrap();
    r.connect_data("C.CV", "REC.CV").unwrap();
    r.trigger("S.EI", 0).unwrap();
    r.trigger("S.EI", 0).unwrap();
    let values: Vec<u64> = log.borrow().iter().map(|(_, _, v)| v[0].as_u64()).collect();
    assert_eq!(
        values,
        [0, 1],
        "sampled when E_SPLIT sent, before E_CTU counted"
    );
    assert_eq!(r.read("C.CV"), Some(&Value::UInt(2)));
}

#[test]
fn an_input_no_event_carries_is_not_sampled() {
    // REC's E0 carries V only; W, connected too, keeps its initial value (as in FORTE and
    // the 4diac compliance examples' "WITH at the outputs").
    let mut r = Resource::new(Limits::default());
    r.create("C", create("E_CTU").unwrap()).unwrap();
    let interface = Interface::build(
        &[("E0", &["V"])],
        &[],
        &[("V", DataType::UInt, None), ("W", DataType::UInt, None)],
        &[],
    )
    .unwrap();
    let log: Log = Rc::default();
    let rec = Recorder {
        interface,
        log: log.clone(),
    };
    r.create("REC", Box::new(rec)).unwrap();
    r.connect_event("C.CUO", "REC.E0").unwrap();
    r.connect_data("C.CV", "REC.V").unwrap();
    r.connect_data("C.CV", "REC.W").unwrap();
    r.trigger("C.CU", 0).unwrap();
    r.trigger("C.CU", 0).unwrap();
    let seen: Vec<Vec<u64>> = log
        .borrow()
        .iter()
        .map(|(_, _, v)| v.iter().map(Value::as_u64).collect())
        .collect();
    assert_eq!(seen, [[1, 0], [2, 0]]);
}

#[test]
fn a_full_queue_and_an_event_loop_are_faults() {
    let mut r = Resource::new(Limits {
        queue: 2,
        ..Limits::default()
    });
    r.create("S", create("E_SPLIT").unwrap()).unwrap();
    let (rec, log) = recorder(&[]);
    r.create("REC", rec).unwrap();
    for to in ["REC.E0", "REC.E1", "REC.E2"] {
        r.connect_event("S.EO1", to).unwrap();
    }
    r.trigger("S.EI", 0).unwrap();
    assert_eq!(
        r.fault(),
        Some(&Fault::QueueOverflow {
            fb: "S".into(),
            event: "EO1".into()
        })
    );
    assert!(log.borrow().is_empty(), "the chain was abandoned");
    assert_eq!(
        r.trigger("S.EI", 0),
        Err(DeployError::Faulted(Fault::QueueOverflow {
            fb: "S".into(),
            event: "EO1".into()
        })),
        "a faulted resource refuses events"
    );
    assert!(log.borrow().is_empty(), "a faulted resource runs nothing");
    r.reset();
    assert_eq!(r.fault(), None);

    let mut r = Resource::new(Limits {
        chain_events: 1000,
        ..Limits::default()
    });
    r.create("M", create("E_MERGE").unwrap()).unwrap();
    r.connect_event("M.EO", "M.EI1").unwrap();
    r.trigger("M.EI2", 0).unwrap();
    assert_eq!(
        r.fault(),
        Some(&Fault::ChainTooLong {
            fb: "M".into(),
            event: "EI1".into()
        })
    );
    assert_eq!(r.delivered(), 1000);
    let text = format!("{}", r.fault().unwrap());
    assert!(text.contains("M.EI1"), "{text}");
}

#[test]
fn deployment_errors_change_nothing() {
    let mut r = Resource::new(Limits {
        instances: 2,
        ..Limits::default()
    });
    r.create("A", create("E_CTU").unwrap()).unwrap();
    assert_eq!(
        r.create("A", create("E_CTU").unwrap()),
        Err(DeployError::Duplicate("A".into()))
    );
    r.create("B", create("E_SWITCH").unwrap()).unwrap();
    assert_eq!(
        r.create("C", create("E_CTU").unwrap()),
        Err(DeployError::Limit("instances"))
    );
    assert!(matches!(
        r.connect_event("A.CUO", "B.NOPE"),
        Err(DeployError::NotFound(_))
    ));
    assert!(
        matches!(
            r.connect_event("A.CU", "B.EI"),
            Err(DeployError::NotFound(_))
        ),
        "an input as a source"
    );
    assert!(
        matches!(r.connect_data("A.CV", "B.G"), Err(DeployError::Mismatch(_))),
        "UINT to BOOL"
    );
    r.connect_data("A.Q", "B.G").unwrap();
    assert!(
        matches!(r.connect_data("A.Q", "B.G"), Err(DeployError::Mismatch(_))),
        "two sources"
    );
    assert_eq!(
        r.write("B.G", Value::Bool(true)),
        Err(DeployError::Connected("B.G".into()))
    );
    assert!(matches!(
        r.trigger("Z.EI", 0),
        Err(DeployError::NotFound(_))
    ));
    assert!(create("E_NOPE").is_none());
    for ty in TYPES {
        assert!(create(ty).is_some(), "{ty}");
    }
}

#[test]
fn reset_keeps_parameters() {
    let (mut r, log) = harness("E_CTU");
    r.write("FB.PV", Value::UInt(1)).unwrap();
    fire(&mut r, &["CU", "CU"]);
    r.reset();
    assert_eq!(r.read("FB.CV"), Some(&Value::UInt(0)));
    assert_eq!(r.read("FB.PV"), Some(&Value::UInt(1)));
    log.borrow_mut().clear();
    fire(&mut r, &["CU"]);
    assert_eq!(r.read("FB.Q"), Some(&Value::Bool(true)));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// Random networks of standard FBs driven by random events and times: faults are
    /// values, never panics, and every call is bounded.
    #[test]
    fn random_networks_never_panic(
        types in proptest::collection::vec(0usize..23, 1..8),
        links in proptest::collection::vec((0usize..8, 0usize..4, 0usize..8, 0usize..4), 0..24),
        drive in proptest::collection::vec((0usize..8, 0usize..4, 0i64..10_000_000), 1..40),
    ) {
        let mut r = Resource::new(Limits { queue: 64, chain_events: 2_000, ..Limits::default() });
        let mut names = Vec::new();
        for (i, t) in types.iter().enumerate() {
            let name = format!("F{i}");
            r.create(&name, create(TYPES[*t]).unwrap()).unwrap();
            r.write(&format!("{name}.DT"), Value::Time(1_000_000)).ok();
            r.write(&format!("{name}.N"), Value::UInt(3)).ok();
            names.push((name, create(TYPES[*t]).unwrap()));
        }
        let n = names.len();
        for (a, eo, b, ei) in links {
            let (fa, fb) = (&names[a % n], &names[b % n]);
            let (ia, ib) = (fa.1.interface(), fb.1.interface());
            if let (Some(o), Some(i)) = (ia.event_outputs.get(eo), ib.event_inputs.get(ei)) {
                r.connect_event(&format!("{}.{}", fa.0, o.name), &format!("{}.{}", fb.0, i.name)).unwrap();
            }
        }
        let mut now = 0;
        for (f, ei, dt) in drive {
            let (name, fb) = &names[f % n];
            now += dt;
            if let Some(e) = fb.interface().event_inputs.get(ei) {
                match r.trigger(&format!("{name}.{}", e.name), now) {
                    Ok(()) => {}
                    Err(DeployError::Faulted(_)) => prop_assert!(r.fault().is_some()),
                    Err(other) => prop_assert!(false, "{other}"),
                }
            }
            let _ = r.advance(now);
        }
    }
}

#[test]
fn delete_and_disconnect() {
    let mut r = Resource::new(Limits {
        instances: 2,
        ..Limits::default()
    });
    r.create("S", create("E_SPLIT").unwrap()).unwrap();
    let (rec, log) = recorder(&[]);
    r.create("REC", rec).unwrap();
    r.connect_event("S.EO1", "REC.E0").unwrap();
    r.connect_event("S.EO2", "REC.E1").unwrap();
    r.disconnect_event("S.EO1", "REC.E0").unwrap();
    assert!(matches!(
        r.disconnect_event("S.EO1", "REC.E0"),
        Err(DeployError::NotFound(_))
    ));
    r.trigger("S.EI", 0).unwrap();
    assert_eq!(seen(&log), [1]);
    r.delete("S").unwrap();
    assert!(matches!(
        r.trigger("S.EI", 0),
        Err(DeployError::NotFound(_))
    ));
    // The slot is reused; the old connections are gone with it.
    r.create("S", create("E_SPLIT").unwrap()).unwrap();
    r.trigger("S.EI", 0).unwrap();
    assert_eq!(seen(&log), []);
    assert_eq!(
        r.instances().map(|(n, _)| n).collect::<Vec<_>>(),
        ["S", "REC"]
    );
}

#[test]
fn deleting_a_destination_drops_the_connections_into_it() {
    let mut r = Resource::new(Limits {
        instances: 2,
        connections: 2,
        ..Limits::default()
    });
    r.create("S", create("E_SPLIT").unwrap()).unwrap();
    let (rec, _) = recorder(&[]);
    r.create("REC", rec).unwrap();
    r.connect_event("S.EO1", "REC.E0").unwrap();
    r.connect_event("S.EO2", "REC.E1").unwrap();
    assert!(matches!(
        r.connect_event("S.EO1", "REC.E1"),
        Err(DeployError::Limit("connections"))
    ));
    r.delete("REC").unwrap();
    // REC's slot is reused: nothing of S reaches the new instance, and both connections
    // count no more.
    let (rec, log) = recorder(&[]);
    r.create("REC", rec).unwrap();
    r.trigger("S.EI", 0).unwrap();
    assert_eq!(seen(&log), []);
    r.connect_event("S.EO2", "REC.E0").unwrap();
    r.connect_event("S.EO1", "REC.E1").unwrap();
    r.trigger("S.EI", 0).unwrap();
    assert_eq!(seen(&log), [1, 0], "in the order S sends EO1 and EO2");
}

#[test]
fn forced_inputs_and_outputs_hold() {
    let (mut r, log) = harness("E_CTU");
    r.write("FB.PV", Value::UInt(5)).unwrap();
    r.force("FB.CV", Value::UInt(40)).unwrap();
    fire(&mut r, &["CU"]);
    // The counter counts on from the forced 40 (Q: 41 >= 5), but its CV stays forced.
    assert_eq!(
        counter_log(&log),
        [(0, vec![Value::Bool(true), Value::UInt(40)])]
    );
    assert!(r.is_forced("FB.CV"));
    r.force("FB.PV", Value::UInt(0)).unwrap();
    r.write("FB.PV", Value::UInt(9)).unwrap();
    assert_eq!(
        r.read("FB.PV"),
        Some(&Value::UInt(0)),
        "a forced input keeps its value"
    );
    r.unforce("FB.CV").unwrap();
    r.unforce("FB.PV").unwrap();
    assert!(!r.is_forced("FB.CV"));
    assert!(matches!(r.unforce("FB.CV"), Err(DeployError::NotFound(_))));
    assert!(matches!(
        r.force("FB.NOPE", Value::UInt(0)),
        Err(DeployError::NotFound(_))
    ));
}
