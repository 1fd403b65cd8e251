//! Host tests of the scan cycle with programs compiled by the real compiler.

use crate::package::{self, Package, PortMap};
use crate::scan::{Areas, LATENESS_BITS, PlanError, PortIo, Runtime, SafeValues, Schedule, Stop};
use plc_vm::image::Image;
use plc_vm::isa::Trap;
use plc_vm::verify::verify;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame, Value};
use protocol::{Direction, PortKind};
use std::string::ToString;
use std::vec::Vec;

const PERIOD: u64 = 10_000_000;

fn compile(source: &str) -> Vec<u8> {
    let files = [("test.st".to_string(), source.to_string())];
    match plc_compiler::compile(&files, &plc_compiler::Options::default()) {
        Ok((c, _)) => c.image,
        Err((diags, sources)) => panic!(
            "{}",
            plc_compiler::diagnostics::render(&sources, &diags, false)
        ),
    }
}

fn input(name: &'static str, at: u32, valid: (u32, u8)) -> PortMap<'static> {
    PortMap {
        name,
        kind: PortKind::Sampling,
        direction: Direction::In,
        size: 8,
        refresh_ns: 100_000_000,
        depth: 0,
        area_offset: at,
        valid: Some(valid),
    }
}

fn output(name: &'static str, at: u32) -> PortMap<'static> {
    PortMap {
        name,
        kind: PortKind::Sampling,
        direction: Direction::Out,
        size: 8,
        refresh_ns: 0,
        depth: 0,
        area_offset: at,
        valid: None,
    }
}

/// Ports as the test drives them: the next input message per port, what was sent.
#[derive(Default)]
struct Wires {
    inputs: Vec<Option<(Vec<u8>, bool)>>,
    sent: Vec<(usize, Vec<u8>)>,
}

impl PortIo for Wires {
    fn receive(&mut self, port: usize, buf: &mut [u8]) -> Option<(usize, bool)> {
        let (bytes, fresh) = self.inputs.get(port)?.as_ref()?;
        buf[..bytes.len()].copy_from_slice(bytes);
        Some((bytes.len(), *fresh))
    }
    fn send(&mut self, port: usize, message: &[u8]) {
        self.sent.push((port, message.to_vec()));
    }
}

/// A program, its package and everything one scan needs, run for `releases` releases.
struct Plc {
    bytes: Vec<u8>,
    data: Vec<u8>,
    /// How far the clock advances at each reading (ns).
    tick: u64,
}

impl Plc {
    fn new(source: &str, ports: &[PortMap]) -> Self {
        Self::with_deadlines(source, ports, &[])
    }

    fn with_deadlines(
        source: &str,
        ports: &[PortMap],
        deadlines: &[package::TaskDeadline],
    ) -> Self {
        let program = compile(source);
        let bytes = package::encode(ports, &program, &[], None, &[], None, deadlines);
        let image = Image::parse(Package::parse(&bytes).unwrap().program()).unwrap();
        let data = vec![0u8; image.data_size() as usize];
        Self {
            bytes,
            data,
            tick: 1_000,
        }
    }

    fn run(
        &mut self,
        releases: u64,
        wires: &mut Wires,
        areas: &mut Areas,
        mut each: impl FnMut(u64, &mut Wires, &Runtime, &Areas),
    ) -> Runtime {
        let package = Package::parse(&self.bytes).unwrap();
        let image = Image::parse(package.program()).unwrap();
        let verified = verify(&image).unwrap();
        let (mut stack, mut calls, mut tries) =
            ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
        let mut machine = Machine::new(
            verified,
            Memory {
                data: &mut self.data,
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        )
        .unwrap();
        let schedule = Schedule::new(&image, PERIOD)
            .unwrap()
            .with_deadlines(&image, &package);
        let mut rt = Runtime::new(schedule, PERIOD, SafeValues::of(&package));
        let mut now = 0u64;
        let tick = self.tick;
        for r in 0..releases {
            let release = r * PERIOD;
            now = now.max(release + 3_000);
            rt.scan(
                &mut machine,
                &image,
                &package,
                wires,
                areas,
                || {
                    now += tick;
                    now
                },
                release,
                |_, _| {},
            );
            each(r, wires, &rt, areas);
        }
        rt
    }
}

const CONTROLLER: &str = "
VAR_GLOBAL
  level AT %IL0 : LREAL;
  level_ok AT %IX16.0 : BOOL;
  valve AT %QL0 : LREAL;
  alarm AT %QX8.0 : BOOL;
  cycles AT %MD0 : UDINT;
END_VAR
PROGRAM Main
cycles := cycles + 1;
IF level_ok THEN
  valve := LIMIT(0.0, (1.0 - level) * 2.0, 1.0);
ELSE
  valve := 0.0;
END_IF;
alarm := level_ok AND level > 1.5;
END_PROGRAM
";

fn f64_of(bytes: &[u8]) -> f64 {
    f64::from_le_bytes(bytes.try_into().unwrap())
}

#[test]
fn read_execute_write_through_the_process_image() {
    let mut plc = Plc::new(
        CONTROLLER,
        &[
            input("level", 0, (16, 0)),
            output("valve", 0),
            output("alarm", 8),
        ],
    );
    let mut wires = Wires {
        inputs: vec![Some((0.75f64.to_le_bytes().to_vec(), true)), None, None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    plc.run(1, &mut wires, &mut areas, |_, _, _, _| {});
    assert_eq!(wires.sent.len(), 2, "both outputs every cycle");
    assert_eq!(wires.sent[0].0, 1);
    assert_eq!(f64_of(&wires.sent[0].1), 0.5);
    assert_eq!(wires.sent[1].1[0], 0, "no alarm");
    assert_eq!(u32::from_le_bytes(areas.memory[..4].try_into().unwrap()), 1);

    // A high level raises the alarm bit (bit 0 of %QB8) and closes the valve.
    wires.inputs[0] = Some((1.75f64.to_le_bytes().to_vec(), true));
    wires.sent.clear();
    plc.run(1, &mut wires, &mut areas, |_, _, _, _| {});
    assert_eq!(f64_of(&wires.sent[0].1), 0.0);
    assert_eq!(wires.sent[1].1[0], 1);
    // A new runtime (a restart) starts the marker from its initial value again.
    assert_eq!(u32::from_le_bytes(areas.memory[..4].try_into().unwrap()), 1);
}

#[test]
fn a_stale_input_is_flagged_never_fresh() {
    let mut plc = Plc::new(
        CONTROLLER,
        &[input("level", 0, (16, 0)), output("valve", 0)],
    );
    let mut wires = Wires {
        inputs: vec![Some((0.5f64.to_le_bytes().to_vec(), false)), None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    plc.run(1, &mut wires, &mut areas, |_, _, _, _| {});
    assert_eq!(areas.input[16] & 1, 0, "validity bit clear");
    assert_eq!(f64_of(&areas.input[..8]), 0.5, "bytes as last received");
    assert_eq!(
        f64_of(&wires.sent[0].1),
        0.0,
        "the program saw level_ok = FALSE"
    );
    // No message at all: also not valid.
    wires.inputs[0] = None;
    plc.run(1, &mut wires, &mut areas, |_, _, _, _| {});
    assert_eq!(areas.input[16] & 1, 0);
}

#[test]
fn tasks_run_at_their_interval_in_priority_order() {
    let source = "
VAR_GLOBAL trace AT %QL0 : LWORD; fast_n AT %MD0 : UDINT; slow_n AT %MD1 : UDINT; END_VAR
PROGRAM Fast fast_n := fast_n + 1; trace := SHL(trace, 4) OR 1; END_PROGRAM
PROGRAM Slow slow_n := slow_n + 1; trace := SHL(trace, 4) OR 2; END_PROGRAM
CONFIGURATION C
  TASK slow (INTERVAL := T#30ms, PRIORITY := 1);
  TASK fast (INTERVAL := T#10ms, PRIORITY := 5);
  PROGRAM s WITH slow : Slow;
  PROGRAM f WITH fast : Fast;
END_CONFIGURATION
";
    let mut plc = Plc::new(source, &[output("trace", 0)]);
    let mut wires = Wires {
        inputs: vec![None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let rt = plc.run(6, &mut wires, &mut areas, |_, _, _, _| {});
    let count = |at: usize| u32::from_le_bytes(areas.memory[at..at + 4].try_into().unwrap());
    assert_eq!(
        (count(0), count(4)),
        (6, 2),
        "fast every release, slow every third"
    );
    // Release 0 ran slow (priority 1) before fast: trace ends ...2,1; the last release (5)
    // ran only fast.
    let trace = u64::from_le_bytes(wires.sent[0].1.clone().try_into().unwrap());
    assert_eq!(trace & 0xff, 0x21);
    let trace = u64::from_le_bytes(wires.sent[5].1.clone().try_into().unwrap());
    assert_eq!(trace & 0xfff, 0x111);
    assert_eq!(rt.stats[0].count + rt.stats[1].count, 8);
    for s in &rt.stats[..2] {
        assert_eq!(s.last, 1_000, "each cycle reads the clock twice");
        assert_eq!(s.overruns, 0);
    }
    // A task's jitter is its start after the release (the clock moves 1 us per reading and
    // starts 3 us late): slow, first, starts after the release's input work (two readings);
    // fast, behind slow, after slow's three readings too.
    let by_name = |name: &str| {
        let image = Image::parse(Package::parse(&plc.bytes).unwrap().program()).unwrap();
        (0..2)
            .find(|&i| image.task(i).unwrap().name.starts_with(name))
            .unwrap()
    };
    assert_eq!(rt.stats[by_name("SLOW")].max_jitter, 6_000);
    assert_eq!(rt.stats[by_name("FAST")].max_jitter, 9_000);
}

#[test]
fn intervals_must_be_multiples_of_the_period() {
    let source = "
PROGRAM P VAR x : INT; END_VAR x := x + 1; END_PROGRAM
CONFIGURATION C
  TASK t (INTERVAL := T#15ms, PRIORITY := 1);
  PROGRAM p WITH t : P;
END_CONFIGURATION
";
    let program = compile(source);
    let image = Image::parse(&program).unwrap();
    assert_eq!(
        Schedule::new(&image, PERIOD),
        Err(PlanError::IntervalNotMultiple {
            task: 0,
            interval_ns: 15_000_000
        })
    );
    assert!(Schedule::new(&image, 5_000_000).is_ok());
}

#[test]
fn a_trapping_task_stops_with_safe_outputs_and_the_others_go_on() {
    let source = "
VAR_GLOBAL divisor AT %IW0 : INT; END_VAR
PROGRAM Bad
VAR out AT %QL0 : LREAL := 7.0; n : INT; END_VAR
n := 100 / divisor;
out := 3.0;
END_PROGRAM
PROGRAM Good
VAR beat AT %QD2 : UDINT; END_VAR
beat := beat + 1;
END_PROGRAM
CONFIGURATION C
  TASK a (INTERVAL := T#10ms, PRIORITY := 1);
  TASK b (INTERVAL := T#10ms, PRIORITY := 2);
  PROGRAM bad WITH a : Bad;
  PROGRAM good WITH b : Good;
END_CONFIGURATION
";
    let ports = [
        PortMap {
            size: 2,
            valid: None,
            ..input("divisor", 0, (0, 0))
        },
        PortMap {
            size: 12,
            ..output("out", 0)
        },
    ];
    let mut plc = Plc::new(source, &ports);
    let mut wires = Wires {
        inputs: vec![Some((5i16.to_le_bytes().to_vec(), true)), None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let rt = plc.run(2, &mut wires, &mut areas, |r, wires, _, _| {
        if r == 0 {
            wires.inputs[0] = Some((0i16.to_le_bytes().to_vec(), true));
        }
    });
    let out = |r: usize| f64_of(&wires.sent[r].1[..8]);
    let beat = |r: usize| u32::from_le_bytes(wires.sent[r].1[8..12].try_into().unwrap());
    assert_eq!((out(0), beat(0)), (3.0, 1));
    assert_eq!(out(1), 0.0, "safe value in the very cycle of the trap");
    assert_eq!(beat(1), 2, "the other task went on");
    let fault = rt.stopped[0].and_then(Stop::fault).expect("task a stopped");
    assert_eq!(fault.trap, Trap::DivisionByZero);
    assert_eq!(fault.location.map(|l| l.line), Some(5));
    assert_eq!(rt.stats[0].faults, 1);
    assert!(rt.stopped[1].is_none());
}

/// An endless loop is stopped at the task's time deadline (here configured at 2 ms for the
/// TASK, long before the instruction budget) with DEADLINE and safe outputs; a task
/// without a configured deadline has none, and goes on.
#[test]
fn a_task_past_its_deadline_stops_with_safe_outputs() {
    let source = "
PROGRAM Spin
VAR n : UDINT; out AT %QD0 : UDINT; END_VAR
n := n + 1;
out := 9;
IF n > 2 THEN
  WHILE TRUE DO n := n + 1; END_WHILE
END_IF
END_PROGRAM
PROGRAM Beat
VAR beat AT %QD1 : UDINT; END_VAR
beat := beat + 1;
END_PROGRAM
CONFIGURATION C
  TASK spin (INTERVAL := T#10ms, PRIORITY := 1);
  TASK beat (INTERVAL := T#20ms, PRIORITY := 2);
  PROGRAM s WITH spin : Spin;
  PROGRAM b WITH beat : Beat;
END_CONFIGURATION
";
    let ports = [PortMap {
        size: 8,
        ..output("out", 0)
    }];
    let deadline = package::TaskDeadline {
        task: "SPIN",
        deadline_ns: 2_000_000,
    };
    let mut plc = Plc::with_deadlines(source, &ports, &[deadline]);
    // A clock that moves 100 us per reading: 2 ms are 20 readings, 20,000 instructions.
    plc.tick = 100_000;
    let mut wires = Wires {
        inputs: vec![None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let mut schedule = None;
    let rt = plc.run(6, &mut wires, &mut areas, |r, _, rt, _| {
        if r == 0 {
            schedule = Some(rt.schedule.clone());
        }
    });
    let schedule = schedule.unwrap();
    assert_eq!(
        schedule.deadline[..2],
        [2_000_000, crate::scan::NO_DEADLINE]
    );
    let word = |r: usize, i: usize| {
        u32::from_le_bytes(wires.sent[r].1[4 * i..4 * i + 4].try_into().unwrap())
    };
    assert_eq!(word(1, 0), 9);
    assert_eq!(
        word(2, 0),
        0,
        "safe value in the cycle that passed its deadline"
    );
    let fault = rt.stopped[0]
        .and_then(|s| s.fault())
        .expect("task spin stopped");
    assert_eq!(fault.trap, Trap::Deadline);
    assert_eq!(
        crate::scan::health_error(fault.trap),
        protocol::ErrorCode::DeadlineMissed
    );
    assert_eq!(word(5, 0), 0, "stays stopped");
    assert_eq!(word(4, 1), 3, "the other task goes on at its interval");
    assert!(rt.stopped[1].is_none());
}

/// Every release after the first is late by what the clock says (here 4 us: the scan starts
/// 3 us after the release plus one clock tick); the overhead counts every release.
#[test]
fn release_lateness_and_overhead_are_kept_per_release() {
    let mut plc = Plc::new(
        "PROGRAM Main VAR n : UDINT; END_VAR n := n + 1; END_PROGRAM",
        &[],
    );
    let mut areas = Areas::new();
    let rt = plc.run(50, &mut Wires::default(), &mut areas, |_, _, _, _| {});
    assert_eq!(rt.lateness.count(), 49);
    assert_eq!(rt.lateness.summary(), Some((4_000, 4_000, 4_000)));
    // The same releases since the last statistics line, in the `period` line's bins.
    assert_eq!(
        rt.recent_lateness.bins(LATENESS_BITS).collect::<Vec<_>>(),
        [(3_584, 4_096, 49)]
    );
    assert_eq!(rt.overhead.count(), 50);
    let (min, _, max) = rt.overhead.summary().unwrap();
    assert!(min > 0 && max < 100_000, "{min}..{max}");
}

#[test]
fn traps_are_reported_as_the_fitting_arinc_error() {
    use crate::scan::{health_error, names_task};
    use protocol::ErrorCode;
    assert_eq!(health_error(Trap::DivisionByZero), ErrorCode::NumericError);
    assert_eq!(health_error(Trap::NumericError), ErrorCode::NumericError);
    assert_eq!(health_error(Trap::Watchdog), ErrorCode::DeadlineMissed);
    assert_eq!(health_error(Trap::Deadline), ErrorCode::DeadlineMissed);
    assert_eq!(
        health_error(Trap::IndexOutOfBounds),
        ErrorCode::ApplicationError
    );
    assert_eq!(
        health_error(Trap::InvalidReference),
        ErrorCode::ApplicationError
    );
    assert!(names_task("spin", "SPIN.s") && names_task("Spin.S", "SPIN.s"));
    assert!(!names_task("spi", "SPIN.s") && !names_task("s", "SPIN.s"));
}

/// The example controller (config/plc/tank.st) against the plant's model, release by
/// release as the two partitions run them (10 ms major frame): the level reaches the band
/// 1 m ± 10 % within 8 s and stays in it until the 20 s disturbance; the disturbance raises
/// the alarm; from 32 s on (through the 40-50 s leak) the level is in the band again.
#[test]
fn the_example_controller_holds_the_plants_level() {
    let source = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../config/plc/tank.st"
    ))
    .unwrap();
    let ports = [
        input("level", 0, (8, 0)),
        output("valve", 0),
        output("setpoint", 8),
    ];
    let mut plc = Plc::new(&source, &ports);
    let mut wires = Wires {
        inputs: vec![None, None, None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let mut sim = plant::Simulator::new();
    let steps = plant::steps_per_release(PERIOD);
    let (mut settled_by, mut alarm_seen, mut left_band) = (None, false, None);
    plc.run(60_000 / 10, &mut wires, &mut areas, |r, wires, _, areas| {
        let t_ms = (r + 1) * 10;
        let valve_msg = wires.sent.iter().rev().find(|(p, _)| *p == 1).unwrap();
        let command = f64_of(&valve_msg.1);
        sim.release(Some(command), None, steps);
        wires.inputs[0] = Some((plant::encode(sim.plant.level).to_vec(), true));
        wires.sent.clear();
        let level = sim.plant.level;
        let in_band = (level - 1.0).abs() <= 0.1;
        if settled_by.is_none() && in_band {
            settled_by = Some(t_ms);
        }
        let steady = (8_000..20_000).contains(&t_ms) || (32_000..60_000).contains(&t_ms);
        if steady && !in_band && left_band.is_none() {
            left_band = Some((t_ms, level));
        }
        alarm_seen |= areas.output[16] & 1 == 1 && (20_000..27_000).contains(&t_ms);
    });
    assert!(
        settled_by.is_some_and(|t| t <= 8_000),
        "settled at {settled_by:?} ms"
    );
    assert_eq!(left_band, None, "left the band (time ms, level)");
    assert!(alarm_seen, "the disturbance raised the alarm");
}

#[test]
fn retain_variables_are_carried_by_name_and_type() {
    let old = compile(
        "PROGRAM P VAR RETAIN kept : UDINT; moved : INT; gone : INT; END_VAR VAR plain : UDINT; END_VAR
         kept := 7; moved := 8; gone := 9; plain := 10; END_PROGRAM",
    );
    let new = compile(
        "PROGRAM P VAR RETAIN extra : LREAL; moved : INT; kept : UDINT; END_VAR VAR plain : UDINT; gone : INT; END_VAR
         plain := plain; END_PROGRAM",
    );
    let (old_image, new_image) = (Image::parse(&old).unwrap(), Image::parse(&new).unwrap());
    let mut old_data = vec![0u8; old_image.data_size() as usize];
    fn var<'a>(image: &Image<'a>, name: &str) -> plc_vm::image::Var<'a> {
        image.find_var(name).unwrap()
    }
    for (name, value) in [
        ("P.kept", 7u32),
        ("P.moved", 8),
        ("P.gone", 9),
        ("P.plain", 10),
    ] {
        let v = var(&old_image, name);
        let bytes = value.to_le_bytes();
        old_data[v.addr as usize..(v.addr + v.size) as usize]
            .copy_from_slice(&bytes[..v.size as usize]);
    }
    let mut new_data = vec![0u8; new_image.data_size() as usize];
    let carried = crate::scan::carry_retain(&old_image, &old_data, &new_image, &mut new_data);
    assert_eq!(
        carried, 2,
        "kept and moved (gone is no longer RETAIN, plain never was)"
    );
    let read = |name: &str| {
        let v = var(&new_image, name);
        let mut b = [0u8; 4];
        b[..v.size as usize]
            .copy_from_slice(&new_data[v.addr as usize..(v.addr + v.size) as usize]);
        u32::from_le_bytes(b)
    };
    assert_eq!((read("P.kept"), read("P.moved")), (7, 8));
    assert_eq!((read("P.plain"), read("P.gone")), (0, 0));
}

#[test]
fn online_requests_between_cycles() {
    use crate::online::{Loader, serve};
    use plc_online::{
        Access, MAX_MESSAGE, Op, Request, Status, decode_response, encode_request, read_stats,
    };
    let source = "
VAR_GLOBAL out AT %QD0 : DINT; limit : INT := 5; k : INT := 3; END_VAR
VAR_GLOBAL CONSTANT fixed : INT := 1; END_VAR
PROGRAM P VAR n : DINT; END_VAR n := n + 1; out := n * k; END_PROGRAM";
    let ports = [PortMap {
        size: 4,
        ..output("out", 0)
    }];
    let program = compile(source);
    let bytes = package::encode(&ports, &program, &[], None, &[], None, &[]);
    let package = Package::parse(&bytes).unwrap();
    let image = Image::parse(package.program()).unwrap();
    let mut data = vec![0u8; image.data_size() as usize];
    let (mut stack, mut calls, mut tries) =
        ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
    let mut machine = Machine::new(
        verify(&image).unwrap(),
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let mut rt = Runtime::new(
        Schedule::new(&image, PERIOD).unwrap(),
        PERIOD,
        SafeValues::of(&package),
    );
    let mut wires = Wires {
        inputs: vec![None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let mut cycle = |machine: &mut Machine, rt: &mut Runtime, wires: &mut Wires| {
        rt.scan(
            machine,
            &image,
            &package,
            wires,
            &mut areas,
            || 0,
            0,
            |_, _| {},
        );
        i32::from_le_bytes(wires.sent.last().unwrap().1.clone().try_into().unwrap())
    };
    let (mut buffer, mut scratch) = (vec![0u8; 4096], vec![0u32; 8192]);
    let mut loader = Loader::new(&mut buffer, &mut scratch, 4096, PERIOD, 0);
    let mut ask = |machine: &mut Machine, rt: &mut Runtime, access, r: Request| {
        let mut req = [0u8; MAX_MESSAGE];
        let n = encode_request(&r, 42, &mut req).unwrap();
        let mut out = [0u8; MAX_MESSAGE];
        let len = serve(
            &req[..n],
            access,
            &package,
            machine,
            &image,
            rt,
            &mut loader,
            &mut out,
        );
        out[..len].to_vec()
    };
    assert_eq!(cycle(&mut machine, &mut rt, &mut wires), 3);

    // LIST: every variable with its type, from an index.
    let reply = ask(
        &mut machine,
        &mut rt,
        Access::Monitor,
        Request::List { from: 0 },
    );
    let (op, seq, status, mut r) = decode_response(&reply).unwrap();
    assert_eq!((op, seq, status), (Op::List, 42, Status::Ok));
    let total = r.u16().unwrap();
    let count = r.u8().unwrap();
    assert_eq!(total as u8, count);
    let names: Vec<&str> = (0..count)
        .map(|_| {
            r.u8().unwrap();
            r.short_str().unwrap()
        })
        .collect();
    assert!(
        names.contains(&"out") && names.contains(&"P.n"),
        "{names:?}"
    );

    // READ, and a monitor-only client may not write.
    let reply = ask(
        &mut machine,
        &mut rt,
        Access::Monitor,
        Request::Read { name: "P.n" },
    );
    let (_, _, status, mut r) = decode_response(&reply).unwrap();
    assert_eq!((status, r.value()), (Status::Ok, Some(Value::Int(1))));
    let write = Request::Write {
        name: "k",
        value: Value::Int(10),
    };
    let reply = ask(&mut machine, &mut rt, Access::Monitor, write);
    assert_eq!(decode_response(&reply).unwrap().2, Status::Forbidden);
    assert_eq!(
        cycle(&mut machine, &mut rt, &mut wires),
        6,
        "nothing changed"
    );

    // WRITE once; FORCE holds a value the program overwrites; UNFORCE releases it.
    let reply = ask(&mut machine, &mut rt, Access::Force, write);
    assert_eq!(decode_response(&reply).unwrap().2, Status::Ok);
    assert_eq!(cycle(&mut machine, &mut rt, &mut wires), 30);
    let force = Request::Force {
        name: "out",
        value: Value::UInt(77),
    };
    let reply = ask(&mut machine, &mut rt, Access::Force, force);
    assert_eq!(decode_response(&reply).unwrap().2, Status::Ok);
    assert_eq!(
        cycle(&mut machine, &mut rt, &mut wires),
        77,
        "forced output"
    );
    assert_eq!(cycle(&mut machine, &mut rt, &mut wires), 77, "still forced");
    let reply = ask(
        &mut machine,
        &mut rt,
        Access::Force,
        Request::Unforce { name: "out" },
    );
    assert_eq!(decode_response(&reply).unwrap().2, Status::Ok);
    assert_eq!(cycle(&mut machine, &mut rt, &mut wires), 60);

    // Errors: unknown name, CONSTANT, wrong type, unknown task, malformed.
    let bad = |name, value| Request::Write { name, value };
    for (r, want) in [
        (bad("nope", Value::Int(1)), Status::UnknownName),
        (bad("fixed", Value::Int(2)), Status::Constant),
        (bad("limit", Value::LReal(2.0)), Status::TypeMismatch),
        (Request::Stats { task: 9 }, Status::NoSuchTask),
    ] {
        let reply = ask(&mut machine, &mut rt, Access::Force, r);
        assert_eq!(decode_response(&reply).unwrap().2, want, "{r:?}");
    }
    let reply = ask(
        &mut machine,
        &mut rt,
        Access::Force,
        Request::Read { name: "" },
    );
    assert_eq!(&reply, &[Op::Read.code(), 42, Status::Malformed.code()]);

    // STATS of task 0.
    let reply = ask(
        &mut machine,
        &mut rt,
        Access::Monitor,
        Request::Stats { task: 0 },
    );
    let (_, _, status, mut r) = decode_response(&reply).unwrap();
    assert_eq!(status, Status::Ok);
    let stats = read_stats(&mut r).unwrap();
    assert_eq!(
        (stats.stopped, stats.figures[0]),
        (false, 6),
        "six cycles so far"
    );
}

/// A program of the date/time types, CHAR, WCHAR, WSTRING and references, for the monitor
/// tests below.
const TYPED: &str = "
TYPE Pair : STRUCT a : INT; b : INT; END_STRUCT END_TYPE
PROGRAM P
VAR
  d : DATE := D#2024-06-15;
  t : TOD := TOD#12:30:00;
  dt : DT := DT#2024-06-15-12:30:00;
  lt : LTIME := LT#1ms500us;
  ld : LDATE := LD#2024-06-15;
  ltod : LTOD := LTOD#12:30:00.5;
  ldt : LDT := LDT#2024-06-15-00:00:00;
  c : CHAR := 'a';
  wc : WCHAR := WCHAR#\"€\";
  ws : WSTRING[10] := \"Grüße\";
  x : INT := 5;
  pair : Pair;
  p : REF_TO INT;
  q : POINTER TO INT;
  n : REF_TO INT;
  count : DINT;
END_VAR
p := REF(x);
q := ADR(pair.b);
count := count + 1;
END_PROGRAM";

#[test]
fn online_monitor_of_dates_characters_wide_strings_and_references() {
    use crate::online::{Loader, serve};
    use plc_online::{
        Access, MAX_MESSAGE, Op, PROTOCOL_VERSION, Request, Status, decode_response, encode_request,
    };
    use plc_vm::image::VarType;
    use plc_vm::literal;
    let program = compile(TYPED);
    let bytes = package::encode(&[], &program, &[], None, &[], None, &[]);
    let package = Package::parse(&bytes).unwrap();
    let image = Image::parse(package.program()).unwrap();
    let mut data = vec![0u8; image.data_size() as usize];
    let (mut stack, mut calls, mut tries) =
        ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
    let mut machine = Machine::new(
        verify(&image).unwrap(),
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let mut rt = Runtime::new(
        Schedule::new(&image, PERIOD).unwrap(),
        PERIOD,
        SafeValues::of(&package),
    );
    let mut wires = Wires::default();
    let mut areas = Areas::new();
    let (mut buffer, mut scratch) = (vec![0u8; 4096], vec![0u32; 8192]);
    let mut loader = Loader::new(&mut buffer, &mut scratch, 4096, PERIOD, 0);
    let mut ask = |machine: &mut Machine, rt: &mut Runtime, r: Request| {
        let mut req = [0u8; MAX_MESSAGE];
        let n = encode_request(&r, 5, &mut req).unwrap();
        let mut out = [0u8; MAX_MESSAGE];
        let len = serve(
            &req[..n],
            Access::Force,
            &package,
            machine,
            &image,
            rt,
            &mut loader,
            &mut out,
        );
        out[..len].to_vec()
    };
    rt.scan(
        &mut machine,
        &image,
        &package,
        &mut wires,
        &mut areas,
        || 0,
        0,
        |_, _| {},
    );
    // READ: each variable typed as it is declared, shown as its IEC literal.
    fn read(
        ask: &mut impl FnMut(&mut Machine, &mut Runtime, Request) -> Vec<u8>,
        machine: &mut Machine,
        rt: &mut Runtime,
        name: &str,
    ) -> (VarType, std::string::String) {
        let reply = ask(machine, rt, Request::Read { name });
        let (op, seq, status, mut r) = decode_response(&reply).unwrap();
        assert_eq!((op, seq, status), (Op::Read, 5, Status::Ok), "READ {name}");
        let (ty, value) = r.typed_value().unwrap();
        (ty, value.to_string())
    }
    for (name, ty, shown) in [
        ("P.d", VarType::Date, "D#2024-06-15"),
        ("P.t", VarType::Tod, "TOD#12:30:00"),
        ("P.dt", VarType::Dt, "DT#2024-06-15-12:30:00"),
        ("P.lt", VarType::LTime, "LT#1ms500us"),
        ("P.ld", VarType::LDate, "LD#2024-06-15"),
        ("P.ltod", VarType::LTod, "LTOD#12:30:00.5"),
        ("P.ldt", VarType::LDt, "LDT#2024-06-15-00:00:00"),
        ("P.c", VarType::Char, "'a'"),
        ("P.wc", VarType::WChar, "\"€\""),
        ("P.ws", VarType::WString, "\"Grüße\""),
        ("P.x", VarType::Int, "5"),
        ("P.count", VarType::DInt, "1"),
        ("P.p", VarType::Ref, "REF(P.x)"),
        ("P.q", VarType::Ref, "REF(P.pair.b)"),
        ("P.n", VarType::Ref, "NULL"),
    ] {
        assert_eq!(
            read(&mut ask, &mut machine, &mut rt, name),
            (ty, shown.into()),
            "{name}"
        );
    }

    // FORCE and WRITE values parsed from text as the variable's type (what plcctl does).
    for (force, name, ty, text) in [
        (true, "P.t", VarType::Tod, "TOD#06:00:00.25"),
        (true, "P.d", VarType::Date, "D#2000-02-29"),
        (false, "P.ldt", VarType::Dt, "DT#2024-12-24-18:00:00"),
        (true, "P.lt", VarType::Time, "T#2s"),
        (true, "P.c", VarType::Char, "'$41'"),
        (false, "P.wc", VarType::Char, "z"),
        (false, "P.ws", VarType::WString, "\"Zoë $N\""),
    ] {
        let mut text_buf = [0u8; 64];
        let value = literal::parse(text, ty, &mut text_buf).unwrap();
        let r = if force {
            Request::Force { name, value }
        } else {
            Request::Write { name, value }
        };
        let reply = ask(&mut machine, &mut rt, r);
        assert_eq!(decode_response(&reply).unwrap().2, Status::Ok, "{name}");
    }
    rt.scan(
        &mut machine,
        &image,
        &package,
        &mut wires,
        &mut areas,
        || 0,
        0,
        |_, _| {},
    );
    for (name, shown) in [
        ("P.t", "TOD#06:00:00.25"),
        ("P.d", "D#2000-02-29"),
        ("P.ldt", "LDT#2024-12-24-18:00:00"),
        ("P.lt", "LT#2s"),
        ("P.c", "'A'"),
        ("P.wc", "\"z\""),
        ("P.ws", "\"Zoë $N\""),
    ] {
        assert_eq!(
            read(&mut ask, &mut machine, &mut rt, name).1,
            shown,
            "{name}"
        );
    }

    // What does not fit the variable's type; a reference is never written.
    let tod = Value::Temporal(plc_vm::TimeKind::Tod, 0);
    let null = Value::Ref {
        address: None,
        target: None,
    };
    for (r, want) in [
        (
            Request::Force {
                name: "P.d",
                value: tod,
            },
            Status::TypeMismatch,
        ),
        (
            Request::Force {
                name: "P.t",
                value: Value::Time(0),
            },
            Status::TypeMismatch,
        ),
        (
            Request::Write {
                name: "P.c",
                value: Value::UInt(65),
            },
            Status::TypeMismatch,
        ),
        (
            Request::Force {
                name: "P.ws",
                value: Value::WString(b"a\0"),
            },
            Status::Unsupported,
        ),
        (
            Request::Force {
                name: "P.p",
                value: null,
            },
            Status::ReadOnly,
        ),
        (
            Request::Write {
                name: "P.p",
                value: Value::UInt(0),
            },
            Status::ReadOnly,
        ),
        (
            Request::Force {
                name: "P.q",
                value: Value::Int(4),
            },
            Status::ReadOnly,
        ),
    ] {
        let reply = ask(&mut machine, &mut rt, r);
        assert_eq!(decode_response(&reply).unwrap().2, want, "{r:?}");
    }
    assert_eq!(
        read(&mut ask, &mut machine, &mut rt, "P.p").1,
        "REF(P.x)",
        "unchanged"
    );

    // VERSION.
    let reply = ask(&mut machine, &mut rt, Request::Version);
    let (op, _, status, mut r) = decode_response(&reply).unwrap();
    assert_eq!(
        (op, status, r.u16()),
        (Op::Version, Status::Ok, Some(PROTOCOL_VERSION))
    );

    // STORE: what the persistent store loaded and saved (the store glue sets it).
    crate::persist::STATUS.cold_start();
    crate::persist::STATUS.boot_loaded(3);
    crate::persist::STATUS.retain_saved(17);
    let reply = ask(&mut machine, &mut rt, Request::Store);
    let (op, _, status, mut r) = decode_response(&reply).unwrap();
    assert_eq!((op, status), (Op::Store, Status::Ok));
    assert_eq!(
        plc_online::read_store_status(&mut r),
        Some(plc_online::StoreStatus {
            configured: true,
            boot_loaded: 3,
            retain_loaded: 0,
            boot_saved: 0,
            retain_saved: 17
        })
    );

    // LIST names every variable with its own type.
    let reply = ask(&mut machine, &mut rt, Request::List { from: 0 });
    let (_, _, _, mut r) = decode_response(&reply).unwrap();
    let (_, count) = (r.u16().unwrap(), r.u8().unwrap());
    let listed: Vec<(u8, &str)> = (0..count)
        .map(|_| (r.u8().unwrap(), r.short_str().unwrap()))
        .collect();
    for (ty, name) in [
        (VarType::Tod, "P.t"),
        (VarType::WString, "P.ws"),
        (VarType::Ref, "P.q"),
        (VarType::LDt, "P.ldt"),
    ] {
        assert!(listed.contains(&(ty.code(), name)), "{name} in {listed:?}");
    }
}

/// Sets the RETAIN flag of variable `name` in `image` (what the compiler never does for a
/// reference, but a hand-made image may).
fn mark_retain(image: &mut [u8], name: &str) {
    let parsed = Image::parse(image).unwrap();
    let index = (0..parsed.var_count())
        .find(|&i| parsed.var(i).unwrap().name == name)
        .unwrap();
    let vars = 16 + 5 * 8; // the VARS entry of the section table
    let at = u32::from_le_bytes(image[vars..vars + 4].try_into().unwrap()) as usize;
    image[at + index * plc_vm::image::VAR_RECORD + 7] |= plc_vm::image::VAR_FLAG_RETAIN;
}

/// RETAIN values of the new types go over to a downloaded program by name and type: the
/// dates and characters as they are, a WSTRING also into a larger or smaller one (its text
/// cut), a reference only within the same program.
#[test]
fn retain_dates_texts_and_references_are_handed_over() {
    // The compiler refuses RETAIN references; the runtime does not rely on it.
    let mut old = compile(
        "PROGRAM P VAR RETAIN t : TOD; d : DT; c : WCHAR; big : WSTRING[10]; small : WSTRING[10];
           x : INT; END_VAR VAR p : REF_TO INT; END_VAR
         t := TOD#01:02:03; d := DT#2024-06-15-12:30:00; c := WCHAR#\"€\"; big := \"Grüße\";
         small := \"Grüße\"; p := REF(x); END_PROGRAM",
    );
    let mut new = compile(
        "PROGRAM P VAR RETAIN x : INT; small : WSTRING[3]; big : WSTRING[40];
           c : WCHAR; d : DT; t : TOD; END_VAR VAR p : REF_TO INT; END_VAR
           x := x; p := REF(x); END_PROGRAM",
    );
    mark_retain(&mut old, "P.p");
    mark_retain(&mut new, "P.p");
    let (old_image, new_image) = (Image::parse(&old).unwrap(), Image::parse(&new).unwrap());
    let run_once = |image: &Image, data: &mut Vec<u8>| {
        let (mut stack, mut calls, mut tries) =
            ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
        let mut machine = Machine::new(
            verify(image).unwrap(),
            Memory {
                data,
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        )
        .unwrap();
        machine.run_cycle(0, 0).unwrap();
    };
    let mut old_data = vec![0u8; old_image.data_size() as usize];
    run_once(&old_image, &mut old_data);
    let shown = |image: &Image, data: &[u8], name: &str| {
        let v = image.find_var(name).unwrap();
        let ty = plc_vm::image::VarType::from_code(v.ty).unwrap();
        let value = Value::load(ty, &data[v.addr as usize..(v.addr + v.size) as usize]).unwrap();
        value.to_string()
    };
    // A download: a changed program.
    let mut new_data = vec![0u8; new_image.data_size() as usize];
    {
        // Initialised as Machine::new does.
        let init = new_image.init_data();
        new_data[..init.len()].copy_from_slice(init);
    }
    let carried = crate::scan::carry_retain(&old_image, &old_data, &new_image, &mut new_data);
    assert_eq!(carried, 6, "all but the reference");
    for (name, want) in [
        ("P.t", "TOD#01:02:03"),
        ("P.d", "DT#2024-06-15-12:30:00"),
        ("P.c", "\"€\""),
        ("P.big", "\"Grüße\""),
        ("P.small", "\"Grü\""),
        ("P.x", "0"),
        ("P.p", "NULL"),
    ] {
        assert_eq!(shown(&new_image, &new_data, name), want, "{name}");
    }
    // A warm restart: the same program keeps its reference too.
    let mut again = vec![0u8; old_image.data_size() as usize];
    let init = old_image.init_data();
    again[..init.len()].copy_from_slice(init);
    let carried = crate::scan::carry_retain(&old_image, &old_data, &old_image, &mut again);
    assert_eq!(carried, 7);
    assert_eq!(again, old_data);
}

#[test]
fn an_event_task_runs_on_the_rising_edge_of_its_trigger() {
    let source = "
VAR_GLOBAL go AT %IX0.0 : BOOL; fired AT %QD0 : UDINT; END_VAR
PROGRAM OnGo fired := fired + 1; END_PROGRAM
PROGRAM Idle VAR n : INT; END_VAR n := n + 1; END_PROGRAM
CONFIGURATION C
  TASK cyc (INTERVAL := T#10ms, PRIORITY := 2);
  TASK ev (SINGLE := go, PRIORITY := 1);
  PROGRAM i WITH cyc : Idle;
  PROGRAM o WITH ev : OnGo;
END_CONFIGURATION
";
    let ports = [
        PortMap {
            size: 1,
            valid: None,
            ..input("go", 0, (0, 0))
        },
        PortMap {
            size: 4,
            ..output("fired", 0)
        },
    ];
    let mut plc = Plc::new(source, &ports);
    let mut wires = Wires {
        inputs: vec![Some((vec![0], true)), None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let pattern = [1u8, 1, 0, 1, 0, 0];
    let mut fired = Vec::new();
    plc.run(7, &mut wires, &mut areas, |r, wires, _, _| {
        let out = &wires.sent.last().unwrap().1;
        fired.push(u32::from_le_bytes(out[..4].try_into().unwrap()));
        if let Some(&b) = pattern.get(r as usize) {
            wires.inputs[0] = Some((vec![b], true));
        }
    });
    // Releases see go = 0, 1, 1, 0, 1, 0, 0: edges at releases 1 and 4.
    assert_eq!(fired, [0, 1, 1, 1, 2, 2, 2]);
}

#[test]
fn a_fault_applies_the_configured_safe_values() {
    let source = "
VAR_GLOBAL divisor AT %IW0 : INT; valve AT %QL0 : LREAL; lamp AT %QX8.0 : BOOL; END_VAR
PROGRAM Bad VAR n : INT; END_VAR
valve := 0.75; lamp := FALSE;
n := 100 / divisor;
END_PROGRAM";
    let program = compile(source);
    let image = Image::parse(&program).unwrap();
    let address = |name: &str| image.find_var(name).unwrap().addr;
    let safe = [
        package::SafeValue {
            address: address("valve"),
            width: 8,
            value: 0.25f64.to_bits(),
        },
        package::SafeValue {
            address: address("lamp"),
            width: 1,
            value: 1,
        },
    ];
    let ports = [
        PortMap {
            size: 2,
            valid: None,
            ..input("divisor", 0, (0, 0))
        },
        PortMap {
            size: 9,
            ..output("out", 0)
        },
    ];
    let bytes = package::encode(&ports, &program, &[], None, &safe, None, &[]);
    let mut plc = Plc {
        data: vec![0u8; image.data_size() as usize],
        bytes,
        tick: 1_000,
    };
    let mut wires = Wires {
        inputs: vec![Some((4i16.to_le_bytes().to_vec(), true)), None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    plc.run(2, &mut wires, &mut areas, |r, wires, _, _| {
        if r == 0 {
            wires.inputs[0] = Some((0i16.to_le_bytes().to_vec(), true));
        }
    });
    let out = |r: usize| (f64_of(&wires.sent[r].1[..8]), wires.sent[r].1[8]);
    assert_eq!(out(0), (0.75, 0));
    assert_eq!(out(1), (0.25, 1), "the configured safe values, not zero");
}

/// Markers start from their initial values and keep their values from cycle to cycle
/// (copied out and in again).
#[test]
fn markers_keep_their_initial_values() {
    let source = "VAR_GLOBAL m AT %MW0 : UINT := 5; END_VAR PROGRAM P m := m + 1; END_PROGRAM";
    let mut plc = Plc::new(source, &[]);
    let mut wires = Wires::default();
    let mut areas = Areas::new();
    plc.run(2, &mut wires, &mut areas, |_, _, _, _| {});
    assert_eq!(u16::from_le_bytes([areas.memory[0], areas.memory[1]]), 7);
}

/// A Modbus write between releases reaches the program even when the control process,
/// behind after a cycle that outlasted its window, ends the same release a second time
/// before the next one begins: without [`crate::scan::take_written`] that second end
/// copies the variable's old value back over the written image.
#[test]
fn a_modbus_write_outlives_a_second_end_of_its_release() {
    use crate::comm::{Exchange, Service, SlotState, serve_modbus};
    let source = "VAR_GLOBAL sp AT %MW0 : INT := 1000; seen AT %MW1 : INT; END_VAR
PROGRAM P seen := sp; END_PROGRAM";
    let plc = Plc::new(source, &[]);
    let package = Package::parse(&plc.bytes).unwrap();
    let image = Image::parse(package.program()).unwrap();
    let modbus = package::Modbus {
        port: 502,
        unit: 1,
        write_outputs: false,
        write_markers: true,
    };
    // Holding register 0x3000 (%MW0) := 600.
    let write = [0, 1, 0, 0, 0, 6, 1, 6, 0x30, 0, 0x02, 0x58];
    for take in [true, false] {
        let mut data = vec![0u8; image.data_size() as usize];
        let (mut stack, mut calls, mut tries) =
            ([0u64; 64], [CallFrame::EMPTY; 8], [TryFrame::EMPTY; 4]);
        let mut machine = Machine::new(
            verify(&image).unwrap(),
            Memory {
                data: &mut data,
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        )
        .unwrap();
        let schedule = Schedule::new(&image, PERIOD).unwrap();
        let task = schedule.order[0];
        let mut rt = Runtime::new(schedule, PERIOD, SafeValues::new());
        let (mut wires, mut areas, mut exchange) =
            (Wires::default(), Areas::new(), Exchange::new());
        let mut now = 0u64;
        let mut clock = || {
            now += 1_000;
            now
        };
        // Release 0: the task's process begins it and runs the cycle, the control process
        // ends it and serves the write.
        assert!(rt.begin_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
            0
        ));
        rt.run_task(task, &mut machine, &image, &mut clock, 0, |_, _| {});
        rt.end_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
        );
        let slot = &mut exchange.slots[0];
        (slot.state, slot.service, slot.len) = (SlotState::Request, Service::Modbus, write.len());
        slot.bytes[..write.len()].copy_from_slice(&write);
        serve_modbus(
            &mut exchange,
            &modbus,
            true,
            &mut areas,
            |area, bytes, areas| {
                if take {
                    crate::scan::take_written(&image, area, bytes, areas, &mut machine)
                }
            },
        );
        assert_eq!(
            &exchange.slots[0].bytes[..write.len()],
            &write,
            "the echo of a write"
        );
        // The control process, behind, runs again before release 1 begins.
        assert!(!rt.begin_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
            0
        ));
        rt.end_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
        );
        // Release 1.
        assert!(rt.begin_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
            PERIOD
        ));
        rt.run_task(task, &mut machine, &image, &mut clock, PERIOD, |_, _| {});
        rt.end_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
        );
        let word = |i: usize| i16::from_le_bytes([areas.memory[2 * i], areas.memory[2 * i + 1]]);
        let expected = if take { 600 } else { 1000 };
        assert_eq!(
            (word(0), word(1)),
            (expected, expected),
            "taken over: {take}"
        );
    }
}

/// A PLC with online access driven like the partition does: scans, requests between them,
/// and the swap of a committed download (a new machine over other data memory, handed the
/// old one's RETAIN values and forces).
mod online_control {
    use super::*;
    use crate::download::hand_over;
    use crate::online::{Loader, serve};
    use plc_online::{Access, MAX_CHUNK, MAX_MESSAGE, Request, Status, crc32, decode_response};
    use plc_online::{encode_request, read_stats};
    use plc_vm::vm::Value;

    const OLD: &str = "
VAR_GLOBAL out AT %QD0 : DINT; END_VAR
VAR_GLOBAL RETAIN total : DINT; END_VAR
PROGRAM P VAR n : DINT; END_VAR n := n + 1; total := total + 1; out := n * 3; END_PROGRAM";
    /// Moves every variable (a new one first), keeps `total` RETAIN, changes the gain.
    const NEW: &str = "
VAR_GLOBAL version : LREAL := 2.5; out AT %QD0 : DINT; END_VAR
VAR_GLOBAL RETAIN total : DINT; END_VAR
PROGRAM P VAR n : DINT; END_VAR n := n + 1; total := total + 10; out := n * 5; END_PROGRAM";

    fn out_port() -> PortMap<'static> {
        PortMap {
            size: 4,
            ..output("out", 0)
        }
    }

    /// `(package bytes, program)` of OLD with a safe value of 99 for `out`.
    fn old_package() -> Vec<u8> {
        let program = compile(OLD);
        let image = Image::parse(&program).unwrap();
        let safe = package::SafeValue {
            address: image.find_var("out").unwrap().addr,
            width: 4,
            value: 99,
        };
        package::encode(
            &[out_port()],
            &program,
            &["total"],
            None,
            &[safe],
            None,
            &[],
        )
    }

    fn ask(
        r: Request,
        access: Access,
        package: &Package,
        machine: &mut Machine,
        rt: &mut Runtime,
        loader: &mut Loader,
    ) -> (Status, Vec<u8>) {
        let mut req = [0u8; MAX_MESSAGE];
        let n = encode_request(&r, 1, &mut req).unwrap();
        let mut out = [0u8; MAX_MESSAGE];
        let image = *machine.image();
        let len = serve(
            &req[..n],
            access,
            package,
            machine,
            &image,
            rt,
            loader,
            &mut out,
        );
        let (_, _, status, rest) = decode_response(&out[..len]).unwrap();
        let _ = rest;
        (status, out[3..len].to_vec())
    }

    /// Sends `image` as BEGIN (with `crc`), chunks, COMMIT; the statuses of BEGIN and
    /// COMMIT.
    fn download(
        image: &[u8],
        crc: u32,
        package: &Package,
        machine: &mut Machine,
        rt: &mut Runtime,
        loader: &mut Loader,
    ) -> (Status, Status) {
        let begin = Request::DownloadBegin {
            size: image.len() as u32,
            crc32: crc,
        };
        let (status, _) = ask(begin, Access::Download, package, machine, rt, loader);
        if status != Status::Ok {
            return (status, Status::NoDownload);
        }
        for (i, bytes) in image.chunks(MAX_CHUNK).enumerate() {
            let chunk = Request::DownloadChunk {
                offset: (i * MAX_CHUNK) as u32,
                bytes,
            };
            let (status, _) = ask(chunk, Access::Download, package, machine, rt, loader);
            assert_eq!(status, Status::Ok, "chunk {i}");
        }
        let commit = Request::DownloadCommit;
        let (status, _) = ask(commit, Access::Download, package, machine, rt, loader);
        (Status::Ok, status)
    }

    fn out_of(wires: &Wires) -> i32 {
        i32::from_le_bytes(wires.sent.last().unwrap().1.clone().try_into().unwrap())
    }

    #[test]
    fn stop_sets_the_outputs_safe_and_start_resumes_the_task() {
        let bytes = old_package();
        let package = Package::parse(&bytes).unwrap();
        let image = Image::parse(package.program()).unwrap();
        let mut data = vec![0u8; image.data_size() as usize];
        let (mut stack, mut calls, mut tries) =
            ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
        let memory = Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        };
        let mut machine = Machine::new(verify(&image).unwrap(), memory).unwrap();
        let schedule = Schedule::new(&image, PERIOD).unwrap();
        let mut rt = Runtime::new(schedule, PERIOD, SafeValues::of(&package));
        let (mut buffer, mut scratch) = (vec![0u8; 4096], vec![0u32; 8192]);
        let mut loader = Loader::new(&mut buffer, &mut scratch, 4096, PERIOD, 0);
        let mut wires = Wires::default();
        let mut areas = Areas::new();
        let mut cycle = |machine: &mut Machine, rt: &mut Runtime, wires: &mut Wires| {
            let image = *machine.image();
            rt.scan(
                machine,
                &image,
                &package,
                wires,
                &mut areas,
                || 0,
                0,
                |_, _| {},
            );
            out_of(wires)
        };
        assert_eq!(cycle(&mut machine, &mut rt, &mut wires), 3);
        let stats = |machine: &mut Machine, rt: &mut Runtime, loader: &mut Loader| {
            let r = Request::Stats { task: 0 };
            let (_, result) = ask(r, Access::Monitor, &package, machine, rt, loader);
            let mut reader = plc_online::Reader::new(&result);
            let s = read_stats(&mut reader).unwrap();
            (s.stopped, s.figures[0])
        };
        // A monitor-only client may not stop a task; an unknown task is NO_SUCH_TASK.
        let stop = Request::Stop { task: 0 };
        let (status, _) = ask(
            stop,
            Access::Monitor,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(status, Status::Forbidden);
        let (status, _) = ask(
            Request::Stop { task: 3 },
            Access::Force,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(status, Status::NoSuchTask);
        let (status, _) = ask(
            stop,
            Access::Force,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(status, Status::Ok);
        assert_eq!(stats(&mut machine, &mut rt, &mut loader), (true, 1));
        assert_eq!(
            cycle(&mut machine, &mut rt, &mut wires),
            99,
            "the configured safe value"
        );
        assert_eq!(
            cycle(&mut machine, &mut rt, &mut wires),
            99,
            "still stopped"
        );
        assert_eq!(stats(&mut machine, &mut rt, &mut loader), (true, 1));
        let start = Request::Start { task: 0 };
        let (status, _) = ask(
            start,
            Access::Force,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(status, Status::Ok);
        assert_eq!(
            cycle(&mut machine, &mut rt, &mut wires),
            6,
            "runs on from its own data"
        );
        assert_eq!(stats(&mut machine, &mut rt, &mut loader), (false, 2));
    }

    #[test]
    fn start_clears_a_trapped_task() {
        let source = "VAR_GLOBAL d AT %IW0 : INT; o AT %QW0 : INT; END_VAR
PROGRAM P o := 10 / d; END_PROGRAM";
        let ports = [
            PortMap {
                size: 2,
                valid: None,
                ..input("d", 0, (0, 0))
            },
            PortMap {
                size: 2,
                ..output("o", 0)
            },
        ];
        let program = compile(source);
        let bytes = package::encode(&ports, &program, &[], None, &[], None, &[]);
        let package = Package::parse(&bytes).unwrap();
        let image = Image::parse(package.program()).unwrap();
        let mut data = vec![0u8; image.data_size() as usize];
        let (mut stack, mut calls, mut tries) =
            ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
        let memory = Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        };
        let mut machine = Machine::new(verify(&image).unwrap(), memory).unwrap();
        let mut rt = Runtime::new(
            Schedule::new(&image, PERIOD).unwrap(),
            PERIOD,
            SafeValues::new(),
        );
        let mut wires = Wires {
            inputs: vec![Some((0i16.to_le_bytes().to_vec(), true)), None],
            ..Wires::default()
        };
        let mut areas = Areas::new();
        let mut scan = |machine: &mut Machine, rt: &mut Runtime, wires: &mut Wires| {
            rt.scan(
                machine,
                &image,
                &package,
                wires,
                &mut areas,
                || 0,
                0,
                |_, _| {},
            );
            i16::from_le_bytes(wires.sent.last().unwrap().1.clone().try_into().unwrap())
        };
        assert_eq!(scan(&mut machine, &mut rt, &mut wires), 0, "trapped");
        assert!(rt.stopped[0].and_then(Stop::fault).is_some());
        wires.inputs[0] = Some((2i16.to_le_bytes().to_vec(), true));
        assert_eq!(scan(&mut machine, &mut rt, &mut wires), 0, "stays stopped");
        assert!(rt.start_task(0, &mut machine));
        assert_eq!(scan(&mut machine, &mut rt, &mut wires), 5, "runs again");
    }

    #[test]
    fn a_download_swaps_in_keeping_retain_forces_and_safe_values() {
        let bytes = old_package();
        let package = Package::parse(&bytes).unwrap();
        let image = Image::parse(package.program()).unwrap();
        let new_program = compile(NEW);
        let mut data = vec![0u8; image.data_size() as usize];
        let (mut stack, mut calls, mut tries) =
            ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
        let memory = Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        };
        let mut machine = Machine::new(verify(&image).unwrap(), memory).unwrap();
        let mut rt = Runtime::new(
            Schedule::new(&image, PERIOD).unwrap(),
            PERIOD,
            SafeValues::of(&package),
        );
        let (mut buffer, mut scratch) = (vec![0u8; 8192], vec![0u32; 16384]);
        let mut loader = Loader::new(&mut buffer, &mut scratch, 4096, PERIOD, 100);
        let mut wires = Wires::default();
        let mut areas = Areas::new();
        for _ in 0..3 {
            rt.scan(
                &mut machine,
                &image,
                &package,
                &mut wires,
                &mut areas,
                || 0,
                0,
                |_, _| {},
            );
        }
        assert_eq!(machine.read_var("total"), Ok(Value::Int(3)));

        // Below `download` access: FORBIDDEN, nothing started.
        let begin = Request::DownloadBegin { size: 4, crc32: 0 };
        let (status, _) = ask(
            begin,
            Access::Force,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(status, Status::Forbidden);

        // Bad downloads: each refused, the running program untouched.
        let crc = crc32(&new_program);
        let (_, commit) = download(
            &new_program,
            crc ^ 1,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(commit, Status::ChecksumMismatch);
        let (begin, _) = download(&[0; 9000], 0, &package, &mut machine, &mut rt, &mut loader);
        assert_eq!(begin, Status::TooLarge);
        let mut bad = new_program.clone();
        bad[8..16].fill(0xff);
        let (_, commit) = download(
            &bad,
            crc32(&bad),
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(commit, Status::Refused);
        assert!(loader.refusal.take().is_some());
        let (_, commit) = download(
            &new_program[..100],
            crc32(&new_program[..100]),
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(commit, Status::Refused, "a truncated image");
        // Out of order, before a BEGIN, an incomplete commit.
        let mut send = |r| {
            ask(
                r,
                Access::Download,
                &package,
                &mut machine,
                &mut rt,
                &mut loader,
            )
            .0
        };
        assert_eq!(send(Request::DownloadCommit), Status::NoDownload);
        let begin = Request::DownloadBegin {
            size: new_program.len() as u32,
            crc32: crc,
        };
        assert_eq!(send(begin), Status::Ok);
        let chunk = |offset: usize| Request::DownloadChunk {
            offset: offset as u32,
            bytes: &new_program[offset..offset + 8],
        };
        assert_eq!(send(chunk(8)), Status::BadOffset);
        assert_eq!(send(chunk(0)), Status::Ok);
        assert_eq!(send(chunk(0)), Status::BadOffset, "a repeated chunk");
        assert_eq!(send(Request::DownloadCommit), Status::Incomplete);
        assert!(loader.committed.is_none());
        rt.scan(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            || 0,
            0,
            |_, _| {},
        );
        assert_eq!(out_of(&wires), 12, "the old program still runs");

        // A force of `out` and the good download.
        let force = Request::Force {
            name: "out",
            value: Value::Int(-7),
        };
        let (status, _) = ask(
            force,
            Access::Force,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(status, Status::Ok);
        let (_, commit) = download(
            &new_program,
            crc,
            &package,
            &mut machine,
            &mut rt,
            &mut loader,
        );
        assert_eq!(commit, Status::Ok);
        let (len, takeover) = loader.committed.take().unwrap();
        assert_eq!(&loader.buffer[..len], &new_program[..]);

        // The swap, as the partition makes it between two releases.
        let old_data = machine.data().to_vec();
        let new_image = Image::parse(&new_program).unwrap();
        let mut new_data = vec![0u8; new_image.data_size() as usize];
        let (mut stack, mut calls, mut tries) =
            ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
        let memory = Memory {
            data: &mut new_data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        };
        let mut machine = Machine::new(verify(&new_image).unwrap(), memory).unwrap();
        assert_eq!(hand_over(&takeover, &image, &old_data, &mut machine), 1);
        assert_eq!(machine.read_var("total"), Ok(Value::Int(4)), "RETAIN kept");
        let mut rt = Runtime::new(
            Schedule::new(&new_image, PERIOD).unwrap(),
            PERIOD,
            takeover.safe,
        );
        rt.scan(
            &mut machine,
            &new_image,
            &package,
            &mut wires,
            &mut areas,
            || 0,
            0,
            |_, _| {},
        );
        assert_eq!(out_of(&wires), -7, "the force followed `out`");
        assert_eq!(machine.read_var("total"), Ok(Value::Int(14)), "new code");
        assert_eq!(machine.read_var("version"), Ok(Value::LReal(2.5)));
        machine.unforce_var("out").unwrap();
        rt.scan(
            &mut machine,
            &new_image,
            &package,
            &mut wires,
            &mut areas,
            || 0,
            0,
            |_, _| {},
        );
        assert_eq!(out_of(&wires), 10, "the new gain");
        // The safe value moved with `out` to its new address.
        assert!(rt.stop_task(0, &mut machine));
        rt.scan(
            &mut machine,
            &new_image,
            &package,
            &mut wires,
            &mut areas,
            || 0,
            0,
            |_, _| {},
        );
        assert_eq!(out_of(&wires), 99);
    }

    #[test]
    fn a_download_that_cannot_take_over_is_refused() {
        let bytes = old_package();
        let package = Package::parse(&bytes).unwrap();
        let image = Image::parse(package.program()).unwrap();
        let safe = SafeValues::of(&package);
        let check = |source: &str, forced: &[(u32, &[u8])]| {
            let program = compile(source);
            let new = Image::parse(&program).unwrap();
            crate::download::take_over(&image, &new, &safe, forced.iter().copied(), package.watch())
                .map(|_| ())
                .map_err(|e| e.to_string())
        };
        assert_eq!(check(NEW, &[]), Ok(()));
        // `out` no longer an output: its safe value has nowhere to go.
        let e = check(
            "VAR_GLOBAL out : DINT; END_VAR VAR_GLOBAL RETAIN total : DINT; END_VAR
             PROGRAM P out := 1; END_PROGRAM",
            &[],
        )
        .unwrap_err();
        assert!(e.contains("`out` has a configured safe value"), "{e}");
        // `total` (watched) gone.
        let e = check(
            "VAR_GLOBAL out AT %QD0 : DINT; END_VAR PROGRAM P out := 1; END_PROGRAM",
            &[],
        )
        .unwrap_err();
        assert!(e.contains("`total` is on the watch list"), "{e}");
        // A forced `P.n` whose type changed.
        let n = image.find_var("P.n").unwrap().addr;
        let e = check(
            "VAR_GLOBAL out AT %QD0 : DINT; END_VAR VAR_GLOBAL RETAIN total : DINT; END_VAR
             PROGRAM P VAR n : INT; END_VAR n := 1; END_PROGRAM",
            &[(n, &[1, 0, 0, 0])],
        )
        .unwrap_err();
        assert!(e.contains("`P.n` is forced"), "{e}");
        // Tasks are processes created at the start: a changed task (here an interval) or
        // a task more is refused.
        let e = check(
            "VAR_GLOBAL out AT %QD0 : DINT; END_VAR VAR_GLOBAL RETAIN total : DINT; END_VAR
             PROGRAM P VAR n : DINT; END_VAR n := 1; END_PROGRAM
             CONFIGURATION C TASK t (INTERVAL := T#20ms, PRIORITY := 1); PROGRAM p WITH t : P;
             END_CONFIGURATION",
            &[],
        )
        .unwrap_err();
        assert!(e.contains("is not the same in the new program"), "{e}");
    }

    #[test]
    fn the_checks_at_start_refuse_what_does_not_fit() {
        use crate::download::{Refusal, check_program};
        let program = compile(OLD);
        let mut scratch = vec![0u32; 2 * program.len()];
        assert!(check_program(&program, &mut scratch, 4096, PERIOD).is_ok());
        assert!(matches!(
            check_program(&program, &mut scratch[..2], 4096, PERIOD),
            Err(Refusal::CodeTooLarge(..))
        ));
        assert!(matches!(
            check_program(&program, &mut scratch, 1, PERIOD),
            Err(Refusal::DataTooLarge(..))
        ));
        assert!(matches!(
            check_program(&program[..40], &mut scratch, 4096, PERIOD),
            Err(Refusal::Image(..))
        ));
        let slow = compile(
            "PROGRAM P END_PROGRAM CONFIGURATION C RESOURCE R ON PLC
             TASK t (INTERVAL := T#15ms, PRIORITY := 1); PROGRAM p WITH t : P;
             END_RESOURCE END_CONFIGURATION",
        );
        let mut scratch = vec![0u32; 2 * slow.len()];
        assert!(matches!(
            check_program(&slow, &mut scratch, 4096, PERIOD),
            Err(Refusal::Tasks(PlanError::IntervalNotMultiple { .. }))
        ));
    }
}

/// Each task's process releases only its own task: the first process at a release begins it
/// (inputs in) and nobody else does; a cyclic task runs whenever its process calls it, an
/// event task only after its trigger rose; the control process ends the release (outputs
/// out).
#[test]
fn task_processes_share_one_release() {
    let source = "
VAR_GLOBAL go AT %IX0.0 : BOOL; fired AT %QD0 : UDINT; beats AT %QD1 : UDINT; END_VAR
PROGRAM OnGo fired := fired + 1; END_PROGRAM
PROGRAM Beat beats := beats + 1; END_PROGRAM
CONFIGURATION C
  TASK cyc (INTERVAL := T#10ms, PRIORITY := 2);
  TASK ev (SINGLE := go, PRIORITY := 1);
  PROGRAM b WITH cyc : Beat;
  PROGRAM o WITH ev : OnGo;
END_CONFIGURATION
";
    let ports = [
        PortMap {
            size: 1,
            valid: None,
            ..input("go", 0, (0, 0))
        },
        PortMap {
            size: 8,
            ..output("out", 0)
        },
    ];
    let plc = Plc::new(source, &ports);
    let package = Package::parse(&plc.bytes).unwrap();
    let image = Image::parse(package.program()).unwrap();
    let mut data = vec![0u8; image.data_size() as usize];
    let (mut stack, mut calls, mut tries) =
        ([0u64; 64], [CallFrame::EMPTY; 8], [TryFrame::EMPTY; 4]);
    let mut machine = Machine::new(
        verify(&image).unwrap(),
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let schedule = Schedule::new(&image, PERIOD).unwrap();
    let (beat, ev) = (schedule.order[1], schedule.order[0]);
    assert_eq!(
        schedule.process_priorities(100),
        (
            {
                let mut p = [0u8; crate::scan::MAX_TASKS];
                p[ev] = 99;
                p[beat] = 98;
                p
            },
            97
        )
    );
    assert_eq!(schedule.process_period(beat, PERIOD), PERIOD);
    let mut rt = Runtime::new(schedule, PERIOD, SafeValues::new());
    let mut wires = Wires {
        inputs: vec![Some((vec![1], true)), None],
        ..Wires::default()
    };
    let mut areas = Areas::new();
    let (mut now, mut out) = (0u64, Vec::new());
    for release in [0, PERIOD, 2 * PERIOD] {
        let mut clock = || {
            now += 1_000;
            release + now % PERIOD
        };
        // The event task's process comes first (higher priority), then the cyclic one's:
        // only the first begins the release.
        assert!(rt.begin_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
            release
        ));
        rt.run_task(ev, &mut machine, &image, &mut clock, release, |_, _| {});
        assert!(!rt.begin_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
            release
        ));
        rt.run_task(beat, &mut machine, &image, &mut clock, release, |_, _| {});
        rt.end_release(
            &mut machine,
            &image,
            &package,
            &mut wires,
            &mut areas,
            &mut clock,
        );
        let sent = &wires.sent.last().unwrap().1;
        out.push((
            u32::from_le_bytes(sent[..4].try_into().unwrap()),
            u32::from_le_bytes(sent[4..8].try_into().unwrap()),
        ));
    }
    // `go` is TRUE from the first release on: one rising edge, one event cycle.
    assert_eq!(out, [(1, 1), (1, 2), (1, 3)]);
    assert_eq!(rt.releases, 3);
    assert_eq!(rt.overhead.count(), 3);
    assert_eq!(rt.lateness.count(), 2);
}

#[test]
fn a_partition_runs_at_most_fifteen_tasks() {
    let mut source = String::new();
    for i in 0..16 {
        source.push_str(&format!("PROGRAM P{i} END_PROGRAM\n"));
    }
    source.push_str("CONFIGURATION C\n");
    for i in 0..16 {
        source.push_str(&format!(
            "TASK t{i} (INTERVAL := T#10ms, PRIORITY := 1); PROGRAM p{i} WITH t{i} : P{i};\n"
        ));
    }
    source.push_str("END_CONFIGURATION\n");
    let program = compile(&source);
    let image = Image::parse(&program).unwrap();
    let e = Schedule::new(&image, PERIOD).unwrap_err();
    assert_eq!(e, PlanError::TooManyTasks { count: 16 });
    assert!(e.to_string().contains("at most 15"), "{e}");
}

/// The tier a program runs on (`plc.native`): native only for the package's own program
/// when the binary holds its exact translation.
#[test]
fn the_tier_follows_the_configuration_and_the_compiled_code() {
    use crate::tier::Tier;
    use plc_vm::native::{Cycle, NativeProgram, Unwind, image_hash};
    fn never(_: &mut Cycle<'_>, _: &mut [u8], _: usize) -> Result<(), Unwind> {
        unreachable!("not run")
    }
    let program = compile(CONTROLLER);
    let image: &'static [u8] = Box::leak(program.clone().into_boxed_slice());
    let native: &'static NativeProgram = Box::leak(Box::new(NativeProgram {
        image,
        hash: image_hash(image),
        run: never,
    }));
    let table: &'static [&'static NativeProgram] = Box::leak(Box::new([native]));
    let mut bytes = package::encode(&[], &program, &[], None, &[], None, &[]);
    let plain = Package::parse(&bytes).unwrap();
    assert!(matches!(
        Tier::select(&plain, &program, false, table),
        Tier::Interpreter
    ));
    package::request_native(&mut bytes);
    let asking = Package::parse(&bytes).unwrap();
    let tier = Tier::select(&asking, &program, false, table);
    assert!(tier.native().is_some_and(|p| core::ptr::eq(p, native)));
    assert_eq!(
        tier.to_string(),
        format!(
            "native (image {:016x}, {} bytes)",
            image_hash(&program),
            program.len()
        )
    );
    // Another image (a changed program), or no native code at all: the interpreter.
    let other = compile("PROGRAM P VAR x : INT; END_VAR x := x + 1; END_PROGRAM");
    for (program, table) in [(&other, table), (&program, &[][..])] {
        let tier = Tier::select(&asking, program, false, table);
        assert!(tier.native().is_none());
        assert_eq!(
            tier.to_string(),
            format!(
                "interpreter (plc.native: this build has no native code for image {:016x}, {} bytes)",
                image_hash(program),
                program.len()
            )
        );
    }
    // A downloaded program: the interpreter until the next build.
    let tier = Tier::select(&asking, &program, true, table);
    assert!(tier.native().is_none());
    assert!(
        tier.to_string()
            .contains("downloaded program runs on the interpreter")
    );
}

/// With native code set, `run_task` runs it (not the interpreter), and its fault stops the
/// task with safe outputs like an interpreted one.
#[test]
fn run_task_runs_the_native_code_and_handles_its_fault() {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use plc_vm::native::{Cycle, NativeProgram, Unwind, image_hash};
    // Stand-ins for translated code: one writes a marker into the variable `marker` and
    // completes, the other faults (as code for another image would).
    static MARKER: AtomicUsize = AtomicUsize::new(0);
    fn completes(cx: &mut Cycle<'_>, data: &mut [u8], _: usize) -> Result<(), Unwind> {
        data[MARKER.load(Ordering::Relaxed)] = 0xA5;
        cx.ret(0);
        Ok(())
    }
    fn faults(cx: &mut Cycle<'_>, _: &mut [u8], _: usize) -> Result<(), Unwind> {
        Err(cx.refuse(0))
    }
    let source = "
VAR_GLOBAL marker AT %QB0 : BYTE; END_VAR
PROGRAM P marker := 1; END_PROGRAM";
    let ports = [PortMap {
        size: 1,
        ..output("marker", 0)
    }];
    let program = compile(source);
    let bytes = package::encode(&ports, &program, &[], None, &[], None, &[]);
    let package = Package::parse(&bytes).unwrap();
    let image = Image::parse(package.program()).unwrap();
    let marker = image.find_var("marker").unwrap().addr as usize;
    MARKER.store(marker, Ordering::Relaxed);
    let leak = |run| -> &'static NativeProgram {
        let image: &'static [u8] = Box::leak(program.clone().into_boxed_slice());
        Box::leak(Box::new(NativeProgram {
            image,
            hash: image_hash(image),
            run,
        }))
    };
    let mut data = vec![0u8; image.data_size() as usize];
    let (mut stack, mut calls, mut tries) =
        ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
    let mut machine = Machine::new(
        verify(&image).unwrap(),
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let mut rt = Runtime::new(
        Schedule::new(&image, PERIOD).unwrap(),
        PERIOD,
        SafeValues::of(&package),
    );
    let mut faulted = Vec::new();
    rt.set_native(Some(leak(completes)));
    rt.run_task(
        0,
        &mut machine,
        &image,
        || 0,
        0,
        |t, f| faulted.push((t, *f)),
    );
    assert_eq!(machine.data()[marker], 0xA5, "the native code ran");
    assert_eq!((rt.stats[0].count, rt.stats[0].faults), (1, 0));
    rt.set_native(Some(leak(faults)));
    rt.run_task(
        0,
        &mut machine,
        &image,
        || 0,
        0,
        |t, f| faulted.push((t, *f)),
    );
    assert_eq!(faulted.len(), 1);
    assert_eq!(faulted[0].1.trap, Trap::InvalidAddress);
    assert!(matches!(rt.stopped[0], Some(Stop::Fault(_))));
    assert_eq!(machine.data()[marker], 0, "outputs safe");
    // Back on the interpreter after START.
    rt.set_native(None);
    rt.start_task(0, &mut machine);
    rt.run_task(
        0,
        &mut machine,
        &image,
        || 0,
        0,
        |t, f| faulted.push((t, *f)),
    );
    assert_eq!(machine.data()[marker], 1, "the interpreter ran");
}
