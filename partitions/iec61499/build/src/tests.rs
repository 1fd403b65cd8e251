//! Basic FB types compiled from XML run as the native standard FBs do: our own counter
//! type always, and, where 4diac's type library is present, every basic or simple event FB
//! of it that has a native twin, on random event sequences.

use super::*;
use iec61499_runtime::basic::Algorithms;
use iec61499_runtime::fb::Context;
use iec61499_runtime::resource::{Limits, Resource};
use iec61499_runtime::{DataType, Value, stdlib};
use proptest::prelude::*;
use proptest::test_runner::{Config as RunnerConfig, TestRunner};
use std::cell::RefCell;
use std::rc::Rc;

/// An up counter written for this test from the standard's description of E_CTU.
const COUNTER: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="E_CTU">
  <InterfaceList>
    <EventInputs>
      <Event Name="CU"><With Var="PV"/></Event>
      <Event Name="R"/>
    </EventInputs>
    <EventOutputs>
      <Event Name="CUO"><With Var="Q"/><With Var="CV"/></Event>
      <Event Name="RO"><With Var="Q"/><With Var="CV"/></Event>
    </EventOutputs>
    <InputVars><VarDeclaration Name="PV" Type="UINT"/></InputVars>
    <OutputVars>
      <VarDeclaration Name="Q" Type="BOOL"/>
      <VarDeclaration Name="CV" Type="UINT"/>
    </OutputVars>
  </InterfaceList>
  <BasicFB>
    <ECC>
      <ECState Name="START"/>
      <ECState Name="CU"><ECAction Algorithm="CU" Output="CUO"/></ECState>
      <ECState Name="R"><ECAction Algorithm="R" Output="RO"/></ECState>
      <ECTransition Source="START" Destination="CU" Condition="CU[CV &lt; 65535]"/>
      <ECTransition Source="CU" Destination="START" Condition="1"/>
      <ECTransition Source="START" Destination="R" Condition="R"/>
      <ECTransition Source="R" Destination="START" Condition="1"/>
    </ECC>
    <Algorithm Name="CU"><ST Text="CV := CV + 1;&#10;Q := (CV &gt;= PV);"/></Algorithm>
    <Algorithm Name="R"><ST><![CDATA[CV := 0;
Q := FALSE;]]></ST></Algorithm>
  </BasicFB>
</FBType>
"#;

type Log = Rc<RefCell<Vec<(&'static str, usize)>>>;

/// Logs which output event of `who` arrived.
struct Recorder {
    interface: Interface,
    who: &'static str,
    log: Log,
}

impl FunctionBlock for Recorder {
    fn interface(&self) -> &Interface {
        &self.interface
    }
    fn event(&mut self, event: usize, _: &[Value], _: &mut Context<'_>) {
        self.log.borrow_mut().push((self.who, event));
    }
    fn reset(&mut self) {}
}

fn recorder(who: &'static str, events: usize, log: &Log) -> Box<dyn FunctionBlock> {
    let names: Vec<String> = (0..events).map(|i| format!("E{i}")).collect();
    let decl: Vec<EventDecl<'_>> = names.iter().map(|n| (n.as_str(), &[][..])).collect();
    let interface = Interface::build(&decl, &[], &[], &[]).unwrap();
    Box::new(Recorder {
        interface,
        who,
        log: log.clone(),
    })
}

/// A random value for an input of type `ty`: small numbers, so counters reach their presets.
fn random_value(ty: DataType, seed: u64) -> Value {
    match ty {
        DataType::Bool => Value::Bool(seed % 2 == 1),
        DataType::SInt | DataType::Int | DataType::DInt | DataType::LInt => {
            Value::Int((seed % 7) as i64 - 2)
        }
        _ => Value::UInt(seed % 6),
    }
}

/// Runs `steps` (input event, a seed for the inputs' values) into the native type and the
/// compiled one side by side; returns the first difference.
fn compare(native: &str, compiled: &BasicType, steps: &[(usize, u64)]) -> Result<(), String> {
    let mut r = Resource::new(Limits::default());
    let log: Log = Rc::default();
    r.create("A", stdlib::create(native).unwrap()).unwrap();
    r.create("B", compiled.instantiate()).unwrap();
    let ifc = compiled.interface.clone();
    r.create("RA", recorder("A", ifc.event_outputs.len(), &log))
        .unwrap();
    r.create("RB", recorder("B", ifc.event_outputs.len(), &log))
        .unwrap();
    for (k, e) in ifc.event_outputs.iter().enumerate() {
        r.connect_event(&format!("A.{}", e.name), &format!("RA.E{k}"))
            .unwrap();
        r.connect_event(&format!("B.{}", e.name), &format!("RB.E{k}"))
            .unwrap();
    }
    for (n, &(event, seed)) in steps.iter().enumerate() {
        let event = event % ifc.event_inputs.len().max(1);
        for (i, v) in ifc.inputs.iter().enumerate() {
            let value = random_value(v.ty, seed.rotate_left(i as u32 * 7));
            r.write(&format!("A.{}", v.name), value.clone()).unwrap();
            r.write(&format!("B.{}", v.name), value).unwrap();
        }
        let name = &ifc.event_inputs[event].name;
        r.trigger(&format!("A.{name}"), 0).unwrap();
        r.trigger(&format!("B.{name}"), 0).unwrap();
        if let Some(fault) = r.fault() {
            return Err(format!("step {n}: {fault}"));
        }
        let events: Vec<(&str, usize)> = log.borrow_mut().drain(..).collect();
        let a: Vec<usize> = events
            .iter()
            .filter(|(w, _)| *w == "A")
            .map(|(_, e)| *e)
            .collect();
        let b: Vec<usize> = events
            .iter()
            .filter(|(w, _)| *w == "B")
            .map(|(_, e)| *e)
            .collect();
        if a != b {
            return Err(format!(
                "step {n} ({name}): native sent {a:?}, compiled sent {b:?}"
            ));
        }
        for o in &ifc.outputs {
            let (va, vb) = (
                r.read(&format!("A.{}", o.name)),
                r.read(&format!("B.{}", o.name)),
            );
            if va != vb {
                return Err(format!(
                    "step {n} ({name}): {} native {va:?}, compiled {vb:?}",
                    o.name
                ));
            }
        }
    }
    Ok(())
}

fn random_sequences(native: &str, compiled: &BasicType, cases: u32) -> Result<(), String> {
    let mut runner = TestRunner::new(RunnerConfig {
        cases,
        failure_persistence: None,
        ..RunnerConfig::default()
    });
    let steps = proptest::collection::vec((0usize..8, any::<u64>()), 1..40);
    runner
        .run(&steps, |steps| {
            compare(native, compiled, &steps).map_err(proptest::test_runner::TestCaseError::fail)
        })
        .map_err(|e| e.to_string())
}

#[test]
fn our_counter_type_runs_as_the_native_one() {
    let compiled = compile("E_CTU.fbt", COUNTER).unwrap();
    assert_eq!(compiled.code.counts(), (2, 1));
    random_sequences("E_CTU", &compiled, 100).unwrap();
}

#[test]
fn internal_initial_values_hold_at_start_and_after_a_reset() {
    // The type scenario iec61499_trap runs: Q := 300 / LEFT; LEFT := LEFT - 1 from LEFT = 3.
    let text = include_str!("../../../../tests/configs/iec61499/COUNTDOWN.fbt");
    let t = compile("COUNTDOWN.fbt", text).unwrap();
    let mut r = Resource::new(Limits::default());
    r.create("D", t.instantiate()).unwrap();
    for want in [100, 150, 300] {
        r.trigger("D.REQ", 0).unwrap();
        assert_eq!(r.read("D.Q"), Some(&Value::Int(want)));
    }
    r.trigger("D.REQ", 0).unwrap();
    assert!(
        matches!(r.fault(), Some(iec61499_runtime::resource::Fault::Trap { fb, reason }) if fb == "D" && reason == "DIVISION_BY_ZERO"),
        "{:?}",
        r.fault()
    );
    r.reset();
    r.trigger("D.REQ", 0).unwrap();
    assert_eq!(r.read("D.Q"), Some(&Value::Int(100)), "LEFT is 3 again");
}

#[test]
fn interface_initial_values_hold_at_start_and_after_a_reset() {
    // Inputs and outputs with an InitialValue start with it; a parameter overrides it
    // (and stays over a reset); the others start with their type's default.
    let text = r#"<FBType Name="START_VALUES"><InterfaceList>
      <EventInputs><Event Name="REQ"><With Var="GAIN"/></Event></EventInputs>
      <EventOutputs><Event Name="CNF"><With Var="OUT"/></Event></EventOutputs>
      <InputVars>
        <VarDeclaration Name="GAIN" Type="INT" InitialValue="5"/>
        <VarDeclaration Name="BIAS" Type="INT" InitialValue="-2"/>
        <VarDeclaration Name="PLAIN" Type="INT"/>
      </InputVars>
      <OutputVars>
        <VarDeclaration Name="OUT" Type="INT" InitialValue="7"/>
        <VarDeclaration Name="OK" Type="BOOL" InitialValue="TRUE"/>
      </OutputVars>
    </InterfaceList><SimpleFB>
      <Algorithm Name="REQ"><ST Text="OUT := GAIN * 10 + BIAS + PLAIN; OK := FALSE;"/></Algorithm>
    </SimpleFB></FBType>"#;
    let t = compile("START_VALUES.fbt", text).unwrap();
    let mut r = Resource::new(Limits::default());
    r.create("S", t.instantiate()).unwrap();
    let read = |r: &Resource, port: &str| r.read(&format!("S.{port}")).cloned();
    assert_eq!(read(&r, "GAIN"), Some(Value::Int(5)));
    assert_eq!(read(&r, "PLAIN"), Some(Value::Int(0)));
    assert_eq!(read(&r, "OUT"), Some(Value::Int(7)));
    assert_eq!(read(&r, "OK"), Some(Value::Bool(true)));
    r.trigger("S.REQ", 0).unwrap();
    assert_eq!(read(&r, "OUT"), Some(Value::Int(48)));
    r.write("S.BIAS", Value::Int(1)).unwrap();
    r.trigger("S.REQ", 0).unwrap();
    assert_eq!(read(&r, "OUT"), Some(Value::Int(51)));
    r.reset();
    assert_eq!(read(&r, "OUT"), Some(Value::Int(7)));
    assert_eq!(read(&r, "OK"), Some(Value::Bool(true)));
    r.trigger("S.REQ", 0).unwrap();
    assert_eq!(
        read(&r, "OUT"),
        Some(Value::Int(51)),
        "the parameter BIAS stays"
    );
}

#[test]
fn types_download_in_parts_and_a_bad_one_leaves_the_old_type_running() {
    use iec61499_mgmt::serve::{Access, serve, type_messages};
    let text = include_str!("../../../../tests/configs/iec61499/COUNTDOWN.fbt");
    let old = compile("COUNTDOWN.fbt", text).unwrap().package();
    let new = compile("COUNTDOWN.fbt", &text.replace("300 / LEFT", "600 / LEFT"))
        .unwrap()
        .package();
    let mut d = iec61499_mgmt::Device::new(Limits::default(), 4);
    let send =
        |d: &mut iec61499_mgmt::Device, m: &str| serve(d, m.as_bytes(), Access::Download, 4096, 0);
    let parts = type_messages("COUNTDOWN", &old, 1024, 10);
    assert!(
        parts.len() > 1 && parts.iter().all(|m| m.len() <= 1024),
        "{}",
        parts.len()
    );
    for m in &parts {
        assert!(!send(&mut d, m).contains("Reason"), "{m}");
    }
    assert_eq!(
        d.take_log(),
        [format!(
            "type COUNTDOWN added: {} bytes, checked",
            old.len()
        )]
    );
    for m in [
        ";<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>",
        "R;<Request ID=\"2\" Action=\"CREATE\"><FB Name=\"D\" Type=\"COUNTDOWN\"/></Request>",
        "R;<Request ID=\"3\" Action=\"START\"/>",
        "R;<Request ID=\"4\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"D.REQ\"/></Request>",
    ] {
        assert!(!send(&mut d, m).contains("Reason"), "{m}");
    }
    let q = "R;<Request ID=\"5\" Action=\"READ\"><Connection Source=\"D.Q\" Destination=\"\"/></Request>";
    assert!(send(&mut d, q).contains("100"), "{}", send(&mut d, q));
    // A damaged package: refused whole with its reason; the type in use stays.
    let mut damaged = new.clone();
    let at = damaged.len() / 2;
    damaged[at] ^= 0x55;
    let parts = type_messages("COUNTDOWN", &damaged, 1024, 20);
    let answers: Vec<String> = parts.iter().map(|m| send(&mut d, m)).collect();
    assert!(
        answers.last().unwrap().contains("INVALID_OBJECT"),
        "{answers:?}"
    );
    let log = d.take_log();
    assert!(log[0].starts_with("type COUNTDOWN refused: "), "{log:?}");
    // Parts out of order are refused and drop the unfinished package.
    let parts = type_messages("COUNTDOWN", &new, 1024, 30);
    assert!(send(&mut d, &parts[1]).contains("INVALID_STATE"));
    // The new type, whole: new instances are of it, the existing one keeps the old.
    for m in &parts {
        assert!(!send(&mut d, m).contains("Reason"), "{m}");
    }
    for m in [
        "R;<Request ID=\"6\" Action=\"STOP\"/>",
        "R;<Request ID=\"7\" Action=\"CREATE\"><FB Name=\"E\" Type=\"COUNTDOWN\"/></Request>",
        "R;<Request ID=\"8\" Action=\"START\"/>",
        "R;<Request ID=\"9\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"E.REQ\"/></Request>",
    ] {
        assert!(!send(&mut d, m).contains("Reason"), "{m}");
    }
    let q = "R;<Request ID=\"10\" Action=\"READ\"><Connection Source=\"E.Q\" Destination=\"\"/></Request>";
    assert!(send(&mut d, q).contains("200"), "{}", send(&mut d, q));
}

#[test]
fn st_errors_point_into_the_fbt() {
    let bad = COUNTER.replace("CV := CV + 1;", "CV := CV + ;");
    let errors = compile("C.fbt", &bad).unwrap_err();
    assert!(errors[0].starts_with("C.fbt:28:"), "{errors:?}");
    let bad = COUNTER.replace("CU[CV &lt; 65535]", "CU[CV &lt; NOPE]");
    let errors = compile("C.fbt", &bad).unwrap_err();
    assert!(
        errors[0].starts_with("C.fbt:23:") && errors[0].contains("NOPE"),
        "{errors:?}"
    );
    let bad = COUNTER.replace(
        "Type=\"UINT\"/></InputVars>",
        "Type=\"MOTOR\"/></InputVars>",
    );
    assert!(compile("C.fbt", &bad).unwrap_err()[0].contains("type MOTOR is not supported"));
}

#[test]
fn fourdiac_event_fbs_run_as_ours() {
    let Some(dir) = iec61499_xml::fourdiac_library() else {
        eprintln!("skipped: no 4diac type library (set FORDIAC_TYPELIB)");
        return;
    };
    let (mut same, mut problems) = (Vec::new(), Vec::new());
    for ty in stdlib::TYPES {
        let Some(file) = iec61499_xml::find_file(&dir, &format!("{ty}.fbt")) else {
            continue;
        };
        let text = std::fs::read_to_string(&file).unwrap();
        let fb = iec61499_xml::read_fbt(&file.display().to_string(), &text).unwrap();
        if !matches!(fb.body, Body::Basic(_) | Body::Simple(_)) {
            continue;
        }
        match compile_type(&format!("{ty}.fbt"), &fb, &[]) {
            Err(e) => problems.push(format!("{ty}: does not compile: {}", e.join("; "))),
            Ok(compiled) => match random_sequences(ty, &compiled, 50) {
                Ok(()) => same.push(ty),
                Err(e) => problems.push(format!("{ty}: differs: {e}")),
            },
        }
    }
    eprintln!(
        "4diac's basic event FBs compiled and run as ours: {} ({})",
        same.len(),
        same.join(", ")
    );
    for p in &problems {
        eprintln!("  {p}");
    }
    assert!(problems.is_empty(), "{problems:?}");
}

#[test]
fn packages_round_trip_and_refuse_damage() {
    use iec61499_runtime::package::{PackageError, decode};
    let t = compile("E_CTU.fbt", COUNTER).unwrap();
    let bytes = t.package();
    let p = decode(&bytes).unwrap();
    assert_eq!(
        (p.name.as_str(), &p.interface, &p.ecc),
        ("E_CTU", &t.interface, &t.ecc)
    );
    // The decoded type runs as the compiled one (and so as the native E_CTU).
    let from_package = BasicType {
        name: p.name.clone(),
        interface: p.interface.clone(),
        ecc: p.ecc.clone(),
        internals: p.internals.clone(),
        code: p.code.clone(),
    };
    random_sequences("E_CTU", &from_package, 20).unwrap();
    for cut in 0..bytes.len() {
        assert!(decode(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    for at in (0..bytes.len()).step_by(7) {
        let mut bad = bytes.clone();
        bad[at] ^= 0x20;
        assert!(decode(&bad).is_err(), "flip at {at}");
    }
    // Damage with a recomputed checksum: the ECC or the verifier refuses it.
    let reseal = |mut b: Vec<u8>| {
        let mut c = abi_crc();
        c.update(&b[12..]);
        let sum = c.finish().to_le_bytes();
        b[8..12].copy_from_slice(&sum);
        b
    };
    let image_at = bytes.len() - t.code.image().len();
    let mut bad = bytes.clone();
    bad[image_at + 40..].iter_mut().for_each(|b| *b = 0xFF);
    assert!(matches!(
        decode(&reseal(bad)),
        Err(PackageError::Rejected(_)) | Err(PackageError::Invalid(..))
    ));
}

fn abi_crc() -> abi::crc32::Crc32 {
    abi::crc32::Crc32::new()
}

#[test]
fn a_device_takes_a_type_package_and_runs_it() {
    use iec61499_mgmt::Device;
    let renamed = COUNTER.replace("Name=\"E_CTU\"", "Name=\"MY_COUNTER\"");
    let t = compile("MY_COUNTER.fbt", &renamed).unwrap();
    let bytes = t.package();
    let mut d = Device::new(Limits::default(), 2);
    let req = |action: &str, object: &str| {
        format!("<Request ID=\"1\" Action=\"{action}\">{object}</Request>")
    };
    assert!(
        d.execute("", &req("CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"), 0)
            .ends_with("\"1\" />")
    );
    let before = d.execute(
        "R",
        &req("CREATE", "<FB Name=\"C\" Type=\"MY_COUNTER\"/>"),
        0,
    );
    assert!(before.contains("UNSUPPORTED_TYPE"), "{before}");
    assert_eq!(d.add_type(&bytes), Ok("MY_COUNTER".to_string()));
    assert!(
        !d.execute(
            "R",
            &req("CREATE", "<FB Name=\"C\" Type=\"MY_COUNTER\"/>"),
            0
        )
        .contains("Reason")
    );
    d.execute(
        "R",
        &req("WRITE", "<Connection Source=\"2\" Destination=\"C.PV\"/>"),
        0,
    );
    d.execute("R", &req("START", ""), 0);
    for _ in 0..2 {
        d.execute(
            "R",
            &req("WRITE", "<Connection Source=\"$e\" Destination=\"C.CU\"/>"),
            0,
        );
    }
    let q = d.execute(
        "R",
        &req("READ", "<Connection Source=\"C.Q\" Destination=\"\"/>"),
        0,
    );
    assert!(q.contains("Destination=\"TRUE\""), "{q}");
    let mut damaged = bytes.clone();
    damaged[20] ^= 1;
    assert!(d.add_type(&damaged).is_err());
    let std_name =
        iec61499_runtime::package::encode("E_CTU", &t.interface, &t.internals, &t.ecc, &t.code);
    assert!(
        d.add_type(&std_name).is_err(),
        "a standard type is not replaced"
    );
}
