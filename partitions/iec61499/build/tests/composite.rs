//! Composite FB types from their XML on a device: flattened into their components when an
//! instance is created, nested composites included; their interface events and data wired
//! through (connections, parameters, triggers, READ, watches, forces); refusals with the
//! place in the `.fbt`.

use iec61499_build::{Compiled, compile_any};
use iec61499_mgmt::Device;
use iec61499_runtime::Limits;

/// Counts its REQ events (an E_CTU inside) and reports the count with CNF.
const COUNT: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="COUNT">
  <InterfaceList>
    <EventInputs><Event Name="REQ"><With Var="PV"/></Event></EventInputs>
    <EventOutputs><Event Name="CNF"><With Var="CV"/><With Var="Q"/></Event></EventOutputs>
    <InputVars><VarDeclaration Name="PV" Type="UINT"/></InputVars>
    <OutputVars>
      <VarDeclaration Name="CV" Type="UINT"/>
      <VarDeclaration Name="Q" Type="BOOL"/>
    </OutputVars>
  </InterfaceList>
  <FBNetwork>
    <FB Name="CTU" Type="E_CTU"/>
    <EventConnections>
      <Connection Source="REQ" Destination="CTU.CU"/>
      <Connection Source="CTU.CUO" Destination="CNF"/>
    </EventConnections>
    <DataConnections>
      <Connection Source="PV" Destination="CTU.PV"/>
      <Connection Source="CTU.CV" Destination="CV"/>
      <Connection Source="CTU.Q" Destination="Q"/>
    </DataConnections>
  </FBNetwork>
</FBType>
"#;

/// Two COUNTs behind an E_SPLIT: A counts up to PV (from the interface), B to 2 (its
/// parameter); CNF comes from A.
const TWO: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="TWO">
  <InterfaceList>
    <EventInputs><Event Name="REQ"><With Var="PV"/></Event></EventInputs>
    <EventOutputs><Event Name="CNF"><With Var="CV"/></Event></EventOutputs>
    <InputVars><VarDeclaration Name="PV" Type="UINT"/></InputVars>
    <OutputVars><VarDeclaration Name="CV" Type="UINT"/></OutputVars>
  </InterfaceList>
  <FBNetwork>
    <FB Name="SPLIT" Type="E_SPLIT"/>
    <FB Name="A" Type="COUNT"/>
    <FB Name="B" Type="COUNT">
      <Parameter Name="PV" Value="UINT#2"/>
    </FB>
    <EventConnections>
      <Connection Source="REQ" Destination="SPLIT.EI"/>
      <Connection Source="SPLIT.EO1" Destination="A.REQ"/>
      <Connection Source="SPLIT.EO2" Destination="B.REQ"/>
      <Connection Source="A.CNF" Destination="CNF"/>
    </EventConnections>
    <DataConnections>
      <Connection Source="PV" Destination="A.PV"/>
      <Connection Source="A.CV" Destination="CV"/>
    </DataConnections>
  </FBNetwork>
</FBType>
"#;

fn package(file: &str, text: &str) -> Vec<u8> {
    match compile_any(file, text, &[]) {
        Ok(Compiled::Composite(t)) => t.encode(),
        Ok(Compiled::Basic(t)) => panic!("{file}: {} is basic", t.name),
        Err(e) => panic!("{}", e.join("\n")),
    }
}

fn device(types: &[(&str, &str)]) -> Device {
    let mut d = Device::new(Limits::default(), 4);
    for (file, text) in types {
        d.add_type(&package(file, text)).unwrap();
    }
    d
}

fn request(action: &str, object: &str) -> String {
    format!("<Request ID=\"1\" Action=\"{action}\">{object}</Request>")
}

fn boot_lines(lines: &[(&str, &str, &str)]) -> String {
    lines
        .iter()
        .map(|(dst, action, object)| format!("{dst};{}\n", request(action, object)))
        .collect()
}

fn read(d: &mut Device, path: &str) -> String {
    let answer = d.execute(
        "R",
        &request(
            "READ",
            &format!("<Connection Source=\"{path}\" Destination=\"\"/>"),
        ),
        0,
    );
    answer
        .split("Destination=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap_or(&answer)
        .to_string()
}

/// A boot file with a nested composite: START.COLD counts once, then each trigger of
/// `T.REQ` once more; the outside E_CTU `OUT` counts `T.CNF`.
fn booted() -> Device {
    let mut d = device(&[("COUNT.fbt", COUNT), ("TWO.fbt", TWO)]);
    let boot = boot_lines(&[
        ("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        ("R", "CREATE", "<FB Name=\"T\" Type=\"TWO\"/>"),
        ("R", "CREATE", "<FB Name=\"OUT\" Type=\"E_CTU\"/>"),
        (
            "R",
            "WRITE",
            "<Connection Source=\"UINT#3\" Destination=\"T.PV\"/>",
        ),
        (
            "R",
            "CREATE",
            "<Connection Source=\"START.COLD\" Destination=\"T.REQ\"/>",
        ),
        (
            "R",
            "CREATE",
            "<Connection Source=\"T.CNF\" Destination=\"OUT.CU\"/>",
        ),
        (
            "R",
            "CREATE",
            "<Connection Source=\"T.CV\" Destination=\"OUT.PV\"/>",
        ),
        ("R", "CREATE", "<Watch Source=\"T.CV\" Destination=\"*\"/>"),
        ("R", "START", ""),
    ]);
    d.boot(&boot, 0).unwrap();
    d
}

#[test]
fn a_nested_composite_runs_from_a_boot_file() {
    let mut d = booted();
    assert_eq!(read(&mut d, "T.CV"), "1");
    assert_eq!(read(&mut d, "OUT.CV"), "1");
    // Data through the interface: T.CV reached OUT.PV with T.CNF.
    assert_eq!(read(&mut d, "OUT.PV"), "1");
    // The parameter reached A's counter two composites deep, B's own parameter B's.
    assert_eq!(read(&mut d, "T.A.CTU.PV"), "3");
    assert_eq!(read(&mut d, "T.B.CTU.PV"), "2");
    for n in 2..=4 {
        let answer = d.execute(
            "R",
            &request("WRITE", "<Connection Source=\"$e\" Destination=\"T.REQ\"/>"),
            0,
        );
        assert!(!answer.contains("Reason"), "{answer}");
        assert_eq!(read(&mut d, "OUT.CV"), n.to_string());
    }
    // A stops at PV = 3 (E_CTU counts while CV < 65535, Q tells CV >= PV), B at 2.
    assert_eq!(read(&mut d, "T.A.Q"), "TRUE");
    assert_eq!(read(&mut d, "T.B.CV"), "4");
    assert_eq!(d.watched(), vec![("R.T.CV".to_string(), "4".to_string())]);
    // The FB list shows the composite, not its components.
    let list = d.execute("R", &request("QUERY", "<FB Name=\"*\" Type=\"*\"/>"), 0);
    assert!(list.contains("<FB Name=\"T\" Type=\"TWO\" />"), "{list}");
    assert!(!list.contains("SPLIT"), "{list}");
}

#[test]
fn a_composite_port_is_forced_and_deleted_with_its_components() {
    let mut d = booted();
    let answer = d.execute(
        "R",
        &request(
            "WRITE",
            "<Connection Source=\"UINT#9\" Destination=\"T.CV\" force=\"true\"/>",
        ),
        0,
    );
    assert!(!answer.contains("Reason"), "{answer}");
    assert_eq!(read(&mut d, "T.CV"), "9");
    let watches = d.execute(
        "R",
        &request("READ", "<Watch Source=\"*\" Destination=\"*\"/>"),
        0,
    );
    assert!(watches.contains("value=\"9\" forced=\"true\""), "{watches}");
    // Deleting needs a stopped resource; then the composite and its components are gone
    // and its name is free again.
    assert!(!d.execute("R", &request("STOP", ""), 0).contains("Reason"));
    let answer = d.execute("R", &request("DELETE", "<FB Name=\"T\" Type=\"TWO\"/>"), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    assert!(read(&mut d, "T.A.CTU.CV").contains("NO_SUCH_OBJECT"));
    let answer = d.execute(
        "R",
        &request("CREATE", "<FB Name=\"T\" Type=\"COUNT\"/>"),
        0,
    );
    assert!(!answer.contains("Reason"), "{answer}");
    // A dotted name is a component's, never one a client gives.
    let answer = d.execute(
        "R",
        &request("CREATE", "<FB Name=\"T.X\" Type=\"E_CTU\"/>"),
        0,
    );
    assert!(answer.contains("INVALID_OBJECT"), "{answer}");
}

/// The boot error of a device with `types` booting one instance of `ty`.
fn refusal(types: &[(&str, &str)], ty: &str) -> String {
    let mut d = device(types);
    let boot = boot_lines(&[
        ("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        ("R", "CREATE", &format!("<FB Name=\"X\" Type=\"{ty}\"/>")),
    ]);
    let e = d.boot(&boot, 0).unwrap_err();
    // Nothing of the refused instance is left behind.
    let list = d.execute("R", &request("QUERY", "<FB Name=\"*\" Type=\"*\"/>"), 0);
    assert!(!list.contains("X"), "{list}");
    e
}

#[test]
fn refusals_name_the_place_in_the_fbt() {
    // A component of a type the device does not have.
    let e = refusal(&[("TWO.fbt", TWO)], "TWO");
    assert!(
        e.contains("line 2")
            && e.contains("TWO.fbt:11:5: component A of type COUNT refused: UNSUPPORTED_TYPE"),
        "{e}"
    );
    // A connection to a port the component's type does not have.
    let bad = COUNT.replace(
        "CTU.CUO\" Destination=\"CNF",
        "CTU.NOPE\" Destination=\"CNF",
    );
    let e = refusal(&[("COUNT.fbt", &bad)], "COUNT");
    assert!(
        e.contains("COUNT.fbt:16:7: connection refused: no such output: NOPE"),
        "{e}"
    );
    // A bad parameter literal.
    let bad = TWO.replace("UINT#2", "UINT#x");
    let e = refusal(&[("COUNT.fbt", COUNT), ("TWO.fbt", &bad)], "TWO");
    assert!(
        e.contains("TWO.fbt:12:5: parameter B.PV = UINT#x refused: INVALID_OBJECT"),
        "{e}"
    );
    // A composite that contains itself.
    let looping = COUNT.replace("Type=\"E_CTU\"", "Type=\"COUNT\"");
    let e = refusal(&[("COUNT.fbt", &looping)], "COUNT");
    assert!(e.contains("nested more than 8 deep"), "{e}");
    // What the XML alone shows is refused when it is read, with the place.
    let bad = COUNT.replace("Destination=\"CTU.CU\"", "Destination=\"NOBODY.CU\"");
    let e = compile_any("COUNT.fbt", &bad, &[]).unwrap_err().join("\n");
    assert!(e.starts_with("COUNT.fbt:15:7:"), "{e}");
    let straight = COUNT.replace("Destination=\"CTU.CU\"", "Destination=\"CNF\"");
    let e = refusal(&[("COUNT.fbt", &straight)], "COUNT");
    assert!(e.contains("COUNT.fbt:15:7: connection refused: a connection from the interface straight to the interface"), "{e}");
}

/// A literal for an input of type `ty` from `seed`: small numbers, so counters reach their
/// presets and timers fire within the steps.
fn literal(ty: iec61499_runtime::DataType, seed: u64) -> Option<String> {
    use iec61499_runtime::DataType as T;
    Some(match ty {
        T::Bool => if seed % 2 == 1 { "TRUE" } else { "FALSE" }.into(),
        T::Time => format!("T#{}ms", 1 + seed % 40),
        // From 1: with N = 0 the standard's E_TRAIN network sends one event, ours none
        // (the stdlib documents it).
        T::USInt | T::UInt | T::UDInt | T::ULInt => (1 + seed % 4).to_string(),
        _ => return None,
    })
}

/// Runs native type `ty` (instance `A`) and 4diac's composite of it (instance `B`, type
/// `composite`) side by side on one device through `steps` (an input event with random
/// inputs, or time passing); returns the first difference in the output events (each
/// counted by an E_CTU) or data outputs.
fn compare_on_device(
    d: &mut Device,
    ty: &str,
    composite: &str,
    steps: &[(u8, u64)],
) -> Result<(), String> {
    let ifc = iec61499_runtime::stdlib::create(ty)
        .unwrap()
        .interface()
        .clone();
    let mut run = |dst: &str, action: &str, object: &str, now: i64| {
        let answer = d.execute(dst, &request(action, object), now);
        match answer.split("Reason=\"").nth(1) {
            Some(r) => Err(format!(
                "{action} {object}: {}",
                r.split('"').next().unwrap()
            )),
            None => Ok(answer),
        }
    };
    run("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>", 0)?;
    run("R", "CREATE", &format!("<FB Name=\"A\" Type=\"{ty}\"/>"), 0)?;
    run(
        "R",
        "CREATE",
        &format!("<FB Name=\"B\" Type=\"{composite}\"/>"),
        0,
    )?;
    for (k, e) in ifc.event_outputs.iter().enumerate() {
        for fb in ["A", "B"] {
            let counter = format!("{fb}{k}");
            run(
                "R",
                "CREATE",
                &format!("<FB Name=\"{counter}\" Type=\"E_CTU\"/>"),
                0,
            )?;
            let c = format!(
                "<Connection Source=\"{fb}.{}\" Destination=\"{counter}.CU\"/>",
                e.name
            );
            run("R", "CREATE", &c, 0)?;
        }
    }
    run("R", "START", "", 0)?;
    let mut now = 0i64;
    // The value a READ answers (the whole answer when it is a refusal).
    let read = |d: &mut Device, path: &str| {
        let object = format!("<Connection Source=\"{path}\" Destination=\"\"/>");
        let answer = d.execute("R", &request("READ", &object), 0);
        match answer.split("Destination=\"").nth(1) {
            Some(value) => value.split('"').next().unwrap_or("").to_string(),
            None => answer,
        }
    };
    for (n, &(kind, seed)) in steps.iter().enumerate() {
        let what = if kind % 4 == 0 {
            now += 1_000_000 * (seed % 60) as i64;
            while let Some(at) = d.next_deadline().filter(|at| *at <= now) {
                d.advance(at);
            }
            format!("time to {} ms", now / 1_000_000)
        } else {
            let event = &ifc.event_inputs[seed as usize % ifc.event_inputs.len()].name;
            for (i, v) in ifc.inputs.iter().enumerate() {
                let seed = seed.rotate_left(7 * i as u32 + 3);
                let text = match v.array {
                    None => literal(v.ty, seed),
                    Some(n) => (0..n)
                        .map(|k| literal(v.ty, seed.rotate_left(11 * k as u32)))
                        .collect::<Option<Vec<_>>>()
                        .map(|items| format!("[{}]", items.join(","))),
                };
                if let Some(text) = text {
                    for fb in ["A", "B"] {
                        let w = format!(
                            "<Connection Source=\"{text}\" Destination=\"{fb}.{}\"/>",
                            v.name
                        );
                        let mut run = |o: &str| d.execute("R", &request("WRITE", o), now);
                        let answer = run(&w);
                        if answer.contains("Reason") {
                            return Err(format!("{w}: {answer}"));
                        }
                    }
                }
            }
            for fb in ["A", "B"] {
                let t = format!("<Connection Source=\"$e\" Destination=\"{fb}.{event}\"/>");
                d.execute("R", &request("WRITE", &t), now);
            }
            event.to_string()
        };
        let log = d.take_log();
        if let Some(fault) = log.iter().find(|l| l.contains("stopped")) {
            return Err(format!("step {n} ({what}): {fault}"));
        }
        let mut ports: Vec<String> = ifc.outputs.iter().map(|o| o.name.clone()).collect();
        let counters = (0..ifc.event_outputs.len()).map(|k| k.to_string());
        for (a, b) in ports
            .drain(..)
            .map(|p| (format!("A.{p}"), format!("B.{p}")))
            .chain(counters.map(|k| (format!("A{k}.CV"), format!("B{k}.CV"))))
        {
            let (va, vb) = (read(d, &a), read(d, &b));
            if va != vb {
                return Err(format!("step {n} ({what}): {a} {va}, {b} {vb}"));
            }
        }
    }
    Ok(())
}

/// 4diac's composite event FBs (its type library, where present), flattened on our device,
/// against our native FBs of the same name on random event sequences with time passing.
#[test]
fn fourdiac_composite_event_fbs_run_as_ours() {
    use proptest::prelude::*;
    use proptest::test_runner::{Config, TestRunner};
    let Some(dir) = iec61499_xml::fourdiac_library() else {
        eprintln!("skipped: no 4diac type library (set FORDIAC_TYPELIB)");
        return;
    };
    let (mut same, mut problems) = (Vec::new(), Vec::new());
    for ty in iec61499_runtime::stdlib::TYPES {
        let Some(file) = iec61499_xml::find_file(&dir, &format!("{ty}.fbt")) else {
            continue;
        };
        let text = std::fs::read_to_string(&file).unwrap();
        let mut fb = iec61499_xml::read_fbt(&format!("{ty}.fbt"), &text).unwrap();
        let iec61499_xml::Body::Composite(net) = &fb.body else {
            continue;
        };
        let native = iec61499_runtime::stdlib::create(ty).unwrap();
        let theirs = iec61499_build::interface_of_xml(&format!("{ty}.fbt"), &fb);
        if theirs.as_ref().ok() != Some(native.interface()) {
            eprintln!("  {ty}: its interface is not ours, not compared");
            continue;
        }
        // Component types of 4diac's library that are not ours (E_TABLE_CTRL): compiled.
        let mut extra = Vec::new();
        for i in &net.instances {
            if iec61499_runtime::stdlib::create(&i.ty).is_none()
                && let Some(f) = iec61499_xml::find_file(&dir, &format!("{}.fbt", i.ty))
            {
                match compile_any(
                    &format!("{}.fbt", i.ty),
                    &std::fs::read_to_string(f).unwrap(),
                    &[],
                ) {
                    Ok(t) => extra.push(t.package()),
                    Err(e) => problems.push(format!("{ty}: component {}: {}", i.ty, e.join("; "))),
                }
            }
        }
        let renamed = format!("FORDIAC_{ty}");
        fb.name = renamed.clone();
        let t = match iec61499_build::composite_of(&format!("{ty}.fbt"), &fb, &[]) {
            Ok(t) => t,
            Err(e) => {
                problems.push(format!("{ty}: {}", e.join("; ")));
                continue;
            }
        };
        let mut runner = TestRunner::new(Config {
            cases: 30,
            failure_persistence: None,
            ..Config::default()
        });
        let steps = proptest::collection::vec((any::<u8>(), any::<u64>()), 1..30);
        let result = runner.run(&steps, |steps| {
            let mut d = Device::new(Limits::default(), 2);
            for p in &extra {
                d.add_type(p).unwrap();
            }
            d.add_type(&t.encode()).unwrap();
            compare_on_device(&mut d, ty, &renamed, &steps)
                .map_err(proptest::test_runner::TestCaseError::fail)
        });
        match result {
            Ok(()) => same.push(ty),
            Err(e) => problems.push(format!("{ty}: differs: {e}")),
        }
    }
    eprintln!(
        "4diac's composite event FBs flattened and run as ours: {} ({})",
        same.len(),
        same.join(", ")
    );
    for p in &problems {
        eprintln!("  {p}");
    }
    assert!(problems.is_empty(), "{problems:?}");
}
