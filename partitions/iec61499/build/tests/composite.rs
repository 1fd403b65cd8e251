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
    match compile_any(file, text) {
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
        .split("Source=\"")
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
    let e = compile_any("COUNT.fbt", &bad).unwrap_err().join("\n");
    assert!(e.starts_with("COUNT.fbt:15:7:"), "{e}");
    let straight = COUNT.replace("Destination=\"CTU.CU\"", "Destination=\"CNF\"");
    let e = refusal(&[("COUNT.fbt", &straight)], "COUNT");
    assert!(e.contains("COUNT.fbt:15:7: connection refused: a connection from the interface straight to the interface"), "{e}");
}
