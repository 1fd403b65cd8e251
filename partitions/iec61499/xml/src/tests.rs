//! Reading types written as 4diac writes them, and every refusal with its position.

use super::*;
use proptest::prelude::*;

/// An up counter as a basic FB (written for this test from the standard's description of
/// E_CTU, in the layout 4diac IDE uses).
const COUNTER: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<!DOCTYPE FBType SYSTEM "http://www.holobloc.com/xml/LibraryElement.dtd">
<FBType Name="COUNT_UP" Comment="counts CU events up to PV">
  <Identification Standard="61499-1"/>
  <InterfaceList>
    <EventInputs>
      <Event Name="CU" Type="Event"><With Var="PV"/></Event>
      <Event Name="R" Type="Event"/>
    </EventInputs>
    <EventOutputs>
      <Event Name="CUO" Type="Event"><With Var="Q"/><With Var="CV"/></Event>
      <Event Name="RO" Type="Event"><With Var="Q"/><With Var="CV"/></Event>
    </EventOutputs>
    <InputVars>
      <VarDeclaration Name="PV" Type="UINT"/>
    </InputVars>
    <OutputVars>
      <VarDeclaration Name="Q" Type="BOOL"/>
      <VarDeclaration Name="CV" Type="UINT" InitialValue="0"/>
    </OutputVars>
  </InterfaceList>
  <BasicFB>
    <InternalVars>
      <VarDeclaration Name="HISTORY" Type="UINT" ArraySize="4"/>
    </InternalVars>
    <ECC>
      <ECState Name="START" x="0" y="0"/>
      <ECState Name="CU"><ECAction Algorithm="CU" Output="CUO"/></ECState>
      <ECState Name="R"><ECAction Algorithm="R" Output="RO"/></ECState>
      <ECTransition Source="START" Destination="CU" Condition="CU[CV &lt; 65535]"/>
      <ECTransition Source="START" Destination="R" Condition="R"/>
      <ECTransition Source="CU" Destination="START" Condition="1"/>
      <ECTransition Source="R" Destination="START" Condition="1"/>
    </ECC>
    <Algorithm Name="CU"><ST Text="CV := CV + 1;&#10;Q := (CV &gt;= PV);"/></Algorithm>
    <Algorithm Name="R"><ST><![CDATA[CV := 0;
Q := FALSE;]]></ST></Algorithm>
  </BasicFB>
</FBType>
"#;

const NETWORK: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="TWO_COUNTERS">
  <InterfaceList>
    <EventInputs><Event Name="REQ"/></EventInputs>
    <EventOutputs><Event Name="CNF"><With Var="N"/></Event></EventOutputs>
    <OutputVars><VarDeclaration Name="N" Type="UINT"/></OutputVars>
  </InterfaceList>
  <FBNetwork>
    <FB Name="A" Type="COUNT_UP"><Parameter Name="PV" Value="3"/></FB>
    <FB Name="B" Type="COUNT_UP"/>
    <EventConnections>
      <Connection Source="REQ" Destination="A.CU"/>
      <Connection Source="A.CUO" Destination="B.CU"/>
      <Connection Source="B.CUO" Destination="CNF"/>
    </EventConnections>
    <DataConnections>
      <Connection Source="B.CV" Destination="N"/>
    </DataConnections>
  </FBNetwork>
</FBType>
"#;

#[test]
fn a_basic_fb_is_read_whole() {
    let t = read_fbt("COUNT_UP.fbt", COUNTER).unwrap();
    assert_eq!(t.name, "COUNT_UP");
    assert_eq!(t.interface.event_inputs[0].with, ["PV"]);
    assert_eq!(t.interface.event_outputs[1].with, ["Q", "CV"]);
    assert_eq!(t.interface.outputs[1].initial.as_deref(), Some("0"));
    let Body::Basic(b) = &t.body else {
        panic!("basic")
    };
    assert_eq!(b.internals[0].array_size, Some(4));
    assert_eq!(
        b.states.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
        ["START", "CU", "R"]
    );
    assert_eq!(
        b.transitions[0].condition,
        Condition::When {
            event: Some("CU".into()),
            guard: Some(("CV < 65535".into(), Pos { line: 30, col: 67 })),
        }
    );
    assert_eq!(
        b.transitions[1].condition,
        Condition::When {
            event: Some("R".into()),
            guard: None
        }
    );
    assert_eq!(b.transitions[2].condition, Condition::Always);
    assert_eq!(b.algorithms[0].st, "CV := CV + 1;\nQ := (CV >= PV);");
    assert_eq!(b.algorithms[1].st, "CV := 0;\nQ := FALSE;");
    assert_eq!(b.algorithms[1].pos.line, 36);
    assert_eq!(b.states[1].actions[0].output.as_deref(), Some("CUO"));
}

#[test]
fn a_composite_fb_and_a_service_fb_are_read() {
    let t = read_fbt("TWO.fbt", NETWORK).unwrap();
    let Body::Composite(n) = &t.body else {
        panic!("composite")
    };
    assert_eq!(
        n.instances[0].parameters,
        [("PV".to_string(), "3".to_string())]
    );
    assert_eq!(n.event_connections.len(), 3);
    assert_eq!(
        n.event_connections[1].source,
        Endpoint {
            instance: Some("A".into()),
            port: "CUO".into()
        }
    );
    assert_eq!(
        n.data_connections[0].destination,
        Endpoint {
            instance: None,
            port: "N".into()
        }
    );
    let sifb = r#"<FBType Name="IX"><InterfaceList><EventInputs><Event Name="INIT"/></EventInputs></InterfaceList><Service/></FBType>"#;
    assert_eq!(read_fbt("IX.fbt", sifb).unwrap().body, Body::Service);
}

/// `COUNTER` with `from` replaced by `to`, read; the error's text and line.
fn refused(from: &str, to: &str) -> (String, u32) {
    assert!(COUNTER.contains(from), "{from}");
    let e = read_fbt("C.fbt", &COUNTER.replacen(from, to, 1)).unwrap_err();
    assert!(e.to_string().starts_with(&format!("C.fbt:{}:", e.pos.line)));
    (e.message, e.pos.line)
}

#[test]
fn every_refusal_names_its_place() {
    let cases: &[(&str, &str, &str, u32)] = &[
        (
            r#"<With Var="PV"/>"#,
            r#"<With Var="Q"/>"#,
            "WITH `Q`, which is no input variable",
            7,
        ),
        (
            r#"Name="R" Type="Event"/>"#,
            r#"Name="PV" Type="Event"/>"#,
            "`PV` is declared twice",
            15,
        ),
        (
            r#"Algorithm="R" Output"#,
            r#"Algorithm="X" Output"#,
            "algorithm `X`, which is not declared",
            29,
        ),
        (
            r#"Output="RO""#,
            r#"Output="R""#,
            "`R`, which is no output event",
            29,
        ),
        (
            r#"Destination="R" Condition="R"/>"#,
            r#"Destination="Z" Condition="R"/>"#,
            "state `Z`, which is not declared",
            31,
        ),
        (
            r#"Condition="R"/>"#,
            r#"Condition="X[TRUE]"/>"#,
            "names `X`, which is no input event",
            31,
        ),
        (
            r#"Condition="CU[CV &lt; 65535]""#,
            r#"Condition="CU[CV &lt; 65535""#,
            "must close the condition",
            30,
        ),
        (
            r#"Condition="CU[CV &lt; 65535]""#,
            r#"Condition="CU[]""#,
            "empty guard",
            30,
        ),
        (
            r#"ArraySize="4""#,
            r#"ArraySize="four""#,
            "ArraySize `four`",
            24,
        ),
        (
            r#"<ST Text="CV := CV + 1;"#,
            r#"<FBD Text="CV := CV + 1;"#,
            "only Structured Text",
            35,
        ),
        (
            r#"<ECState Name="CU">"#,
            r#"<ECState Name="START">"#,
            "`START` is declared twice",
            28,
        ),
        (
            r#"<VarDeclaration Name="PV" Type="UINT"/>"#,
            r#"<VarDeclaration Name="PV"/>"#,
            "needs the attribute Type",
            15,
        ),
        ("</FBType>", "</FBTyp>", "not well-formed XML", 39),
    ];
    for (from, to, message, line) in cases {
        let (got, at) = refused(from, to);
        assert!(got.contains(message), "{from} -> {to}: {got}");
        assert_eq!(at, *line, "{from} -> {to}: {got}");
    }
    let e = read_fbt(
        "N.fbt",
        &NETWORK.replace(r#"Destination="B.CU""#, r#"Destination="C.CU""#),
    )
    .unwrap_err();
    assert_eq!((e.pos.line, e.message.contains("`C.CU`")), (13, true));
    let e = read_fbt("S.fbt", "<SubAppType Name=\"X\"/>").unwrap_err();
    assert!(e.message.contains("expected an <FBType>"), "{}", e.message);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    /// Mangled files: a type or an error with a position, never a panic.
    #[test]
    fn mangled_files_never_panic(cut in 0usize..COUNTER.len(), junk in "[<>/=\"a-zA-Z \\[\\]&;#]{0,12}") {
        let mut text = COUNTER.as_bytes()[..cut].to_vec();
        text.extend_from_slice(junk.as_bytes());
        text.extend_from_slice(&COUNTER.as_bytes()[cut..]);
        if let Ok(text) = std::str::from_utf8(&text)
            && let Err(e) = read_fbt("M.fbt", text)
        {
            prop_assert!(e.pos.line >= 1);
        }
    }
}

#[test]
fn simple_fbs_and_adapters_are_read() {
    let simple = r#"<FBType Name="DOUBLE"><InterfaceList>
      <EventInputs><Event Name="REQ"><With Var="IN"/></Event></EventInputs>
      <EventOutputs><Event Name="CNF"><With Var="OUT"/></Event></EventOutputs>
      <InputVars><VarDeclaration Name="IN" Type="INT"/></InputVars>
      <OutputVars><VarDeclaration Name="OUT" Type="INT"/></OutputVars>
    </InterfaceList><SimpleFB><Algorithm Name="REQ"><ST Text="OUT := 2 * IN;"/></Algorithm></SimpleFB></FBType>"#;
    let Body::Simple(s) = read_fbt("D.fbt", simple).unwrap().body else {
        panic!("simple")
    };
    assert_eq!(s.algorithms[0].st, "OUT := 2 * IN;");
    let e = read_fbt(
        "D.fbt",
        &simple.replace(r#"Algorithm Name="REQ""#, r#"Algorithm Name="RUN""#),
    )
    .unwrap_err();
    assert!(
        e.message.contains("input event REQ has no algorithm"),
        "{}",
        e.message
    );

    let adapted = r#"<FBType Name="T"><InterfaceList>
      <Sockets><AdapterDeclaration Name="S" Type="ATimeOut"/></Sockets>
    </InterfaceList><FBNetwork><FB Name="D" Type="E_DELAY"/>
      <EventConnections><Connection Source="S.START" Destination="D.START"/></EventConnections>
    </FBNetwork></FBType>"#;
    let t = read_fbt("T.fbt", adapted).unwrap();
    assert_eq!(t.interface.sockets[0].ty, "ATimeOut");
    let e = read_fbt("T.fbt", &adapted.replace("S.START", "X.START")).unwrap_err();
    assert!(e.message.contains("`X.START`"), "{}", e.message);
}
