//! Plugs, sockets and adapter connections: types with adapters compiled from XML, deployed
//! on a device and connected plug to socket as 4diac deploys them (`CREATE` of a
//! `Connection` between `FB.PLUG` and `FB.SOCKET`), events and their WITH data crossing
//! each way, the refusals, and the compile errors' places.

use iec61499_build::{AdapterType, compile_any, read_adp};
use iec61499_mgmt::Device;
use iec61499_runtime::Limits;

/// A request/response adapter: the socket sends REQ with IN1 (IN2 travels with PING
/// only), the plug answers CNF with OUT1 (OUT2 travels with ACK only).
const AREQ: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<AdapterType Name="AREQ">
  <InterfaceList>
    <EventInputs>
      <Event Name="REQ"><With Var="IN1"/></Event>
      <Event Name="PING"><With Var="IN2"/></Event>
    </EventInputs>
    <EventOutputs>
      <Event Name="CNF"><With Var="OUT1"/></Event>
      <Event Name="ACK"><With Var="OUT2"/></Event>
    </EventOutputs>
    <InputVars>
      <VarDeclaration Name="IN1" Type="INT"/>
      <VarDeclaration Name="IN2" Type="INT"/>
    </InputVars>
    <OutputVars>
      <VarDeclaration Name="OUT1" Type="INT"/>
      <VarDeclaration Name="OUT2" Type="INT"/>
    </OutputVars>
  </InterfaceList>
</AdapterType>"#;

/// Serves AREQ on its plug: OUT1 is twice IN1, OUT2 is IN2 plus one.
const DOUBLER: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="DOUBLER">
  <InterfaceList>
    <Plugs><AdapterDeclaration Name="srv" Type="AREQ"/></Plugs>
  </InterfaceList>
  <BasicFB>
    <ECC>
      <ECState Name="START"/>
      <ECState Name="RUN"><ECAction Algorithm="serve" Output="srv.CNF"/></ECState>
      <ECTransition Source="START" Destination="RUN" Condition="srv.REQ"/>
      <ECTransition Source="RUN" Destination="START" Condition="1"/>
    </ECC>
    <Algorithm Name="serve"><ST><![CDATA[
srv.OUT1 := 2 * srv.IN1;
srv.OUT2 := srv.IN2 + 1;
]]></ST></Algorithm>
  </BasicFB>
</FBType>"#;

/// Asks through its socket: ASK sends X (and 100 as IN2), the answer comes out as DONE.
const ASKER: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="ASKER">
  <InterfaceList>
    <EventInputs><Event Name="ASK"><With Var="X"/></Event></EventInputs>
    <EventOutputs><Event Name="DONE"><With Var="Y"/><With Var="Z"/></Event></EventOutputs>
    <InputVars><VarDeclaration Name="X" Type="INT"/></InputVars>
    <OutputVars>
      <VarDeclaration Name="Y" Type="INT"/>
      <VarDeclaration Name="Z" Type="INT"/>
    </OutputVars>
    <Sockets><AdapterDeclaration Name="cli" Type="AREQ"/></Sockets>
  </InterfaceList>
  <BasicFB>
    <ECC>
      <ECState Name="START"/>
      <ECState Name="SEND"><ECAction Algorithm="send" Output="cli.REQ"/></ECState>
      <ECState Name="GOT"><ECAction Algorithm="got" Output="DONE"/></ECState>
      <ECTransition Source="START" Destination="SEND" Condition="ASK"/>
      <ECTransition Source="SEND" Destination="START" Condition="1"/>
      <ECTransition Source="START" Destination="GOT" Condition="cli.CNF[cli.OUT1 &gt; 0]"/>
      <ECTransition Source="GOT" Destination="START" Condition="1"/>
    </ECC>
    <Algorithm Name="send"><ST><![CDATA[cli.IN1 := X; cli.IN2 := 100;]]></ST></Algorithm>
    <Algorithm Name="got"><ST><![CDATA[Y := cli.OUT1; Z := cli.OUT2;]]></ST></Algorithm>
  </BasicFB>
</FBType>"#;

fn adapters() -> Vec<AdapterType> {
    let other = AREQ.replace("Name=\"AREQ\"", "Name=\"AOTHER\"");
    vec![
        read_adp("AREQ.adp", AREQ).unwrap(),
        read_adp("AOTHER.adp", &other).unwrap(),
    ]
}

fn request(action: &str, object: &str) -> String {
    format!("<Request ID=\"1\" Action=\"{action}\">{object}</Request>")
}

fn connection(source: &str, destination: &str) -> String {
    format!("<Connection Source=\"{source}\" Destination=\"{destination}\"/>")
}

/// A device with resource R holding D (DOUBLER), A (ASKER) and O (a DOUBLER of AOTHER).
fn device() -> Device {
    let adapters = adapters();
    let mut d = Device::new(Limits::default(), 2);
    let other = DOUBLER
        .replace("Name=\"DOUBLER\"", "Name=\"DOUBLER_OTHER\"")
        .replace("Type=\"AREQ\"", "Type=\"AOTHER\"");
    for (file, text) in [
        ("DOUBLER.fbt", DOUBLER),
        ("ASKER.fbt", ASKER),
        ("DOUBLER_OTHER.fbt", other.as_str()),
    ] {
        let t = compile_any(file, text, &adapters).unwrap_or_else(|e| panic!("{e:?}"));
        d.add_type(&t.package()).unwrap();
    }
    d.execute(
        "",
        &request("CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        0,
    );
    for (name, ty) in [("D", "DOUBLER"), ("A", "ASKER"), ("O", "DOUBLER_OTHER")] {
        let answer = d.execute(
            "R",
            &request("CREATE", &format!("<FB Name=\"{name}\" Type=\"{ty}\"/>")),
            0,
        );
        assert!(!answer.contains("Reason"), "{answer}");
    }
    d
}

fn read(d: &mut Device, port: &str) -> String {
    let answer = d.execute("R", &request("READ", &connection(port, "")), 0);
    answer
        .split("Destination=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap_or_else(|| panic!("READ {port}: {answer}"))
        .to_string()
}

fn ask(d: &mut Device, x: i16) {
    d.execute(
        "R",
        &request("WRITE", &connection(&x.to_string(), "A.X")),
        0,
    );
    let answer = d.execute("R", &request("WRITE", &connection("$e", "A.ASK")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
}

#[test]
fn events_and_their_data_cross_an_adapter_connection_each_way() {
    let mut d = device();
    let answer = d.execute("R", &request("CREATE", &connection("D.srv", "A.cli")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    d.execute("R", &request("START", ""), 0);
    ask(&mut d, 21);
    // REQ carried IN1 (21) to the plug, not IN2; CNF carried OUT1 (42) back, not OUT2.
    assert_eq!(read(&mut d, "D.srv.IN1"), "21");
    assert_eq!(read(&mut d, "D.srv.IN2"), "0");
    assert_eq!(read(&mut d, "D.srv.OUT2"), "1");
    assert_eq!(read(&mut d, "A.cli.OUT1"), "42");
    assert_eq!(read(&mut d, "A.cli.OUT2"), "0");
    assert_eq!(
        (read(&mut d, "A.Y"), read(&mut d, "A.Z")),
        ("42".into(), "0".into())
    );
    // An adapter's input, connected, takes no parameter, as any input.
    let answer = d.execute("R", &request("WRITE", &connection("9", "D.srv.IN2")), 0);
    assert!(answer.contains("INVALID_OPERATION"), "{answer}");
    // The guard on the adapter's event: no answer of 0 reaches DONE.
    ask(&mut d, 0);
    assert_eq!(read(&mut d, "A.Y"), "42");

    // Deleted, the connection carries nothing.
    d.execute("R", &request("STOP", ""), 0);
    let answer = d.execute("R", &request("DELETE", &connection("D.srv", "A.cli")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    let again = d.execute("R", &request("DELETE", &connection("D.srv", "A.cli")), 0);
    assert!(again.contains("Reason"), "{again}");
    let answer = d.execute("R", &request("WRITE", &connection("9", "D.srv.IN2")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    assert_eq!(read(&mut d, "D.srv.IN2"), "9");
    d.execute("R", &request("START", ""), 0);
    ask(&mut d, 5);
    assert_eq!(read(&mut d, "A.Y"), "42");
    assert_ne!(read(&mut d, "D.srv.IN1"), "5");
}

#[test]
fn wrong_adapter_connections_are_refused_and_change_nothing() {
    let mut d = device();
    let refused = |d: &mut Device, source: &str, destination: &str| {
        let answer = d.execute("R", &request("CREATE", &connection(source, destination)), 0);
        assert!(
            answer.contains("Reason"),
            "{source} -> {destination}: {answer}"
        );
    };
    // A socket to a plug, another adapter type, no such adapter.
    refused(&mut d, "A.cli", "D.srv");
    refused(&mut d, "O.srv", "A.cli");
    refused(&mut d, "D.nope", "A.cli");
    // A plug takes one connection, a socket one.
    let answer = d.execute("R", &request("CREATE", &connection("D.srv", "A.cli")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    refused(&mut d, "D.srv", "A.cli");
    // Nothing was left behind by the refusals: one answer per question.
    d.execute("R", &request("START", ""), 0);
    ask(&mut d, 4);
    assert_eq!(read(&mut d, "A.Y"), "8");
}

#[test]
fn adapters_survive_the_package_and_their_errors_have_places() {
    let adapters = adapters();
    let t = compile_any("ASKER.fbt", ASKER, &adapters).unwrap();
    let decoded = iec61499_runtime::package::decode(&t.package()).unwrap();
    let a = &decoded.interface.adapters[0];
    assert_eq!(
        (a.name.as_str(), a.ty.as_str(), a.plug),
        ("cli", "AREQ", false)
    );
    // The socket's ports: the adapter type's outputs are its inputs.
    assert!(decoded.interface.event_input("cli.CNF").is_some());
    assert!(decoded.interface.event_output("cli.REQ").is_some());
    assert!(decoded.interface.input("cli.OUT1").is_some());
    assert!(decoded.interface.output("cli.IN2").is_some());

    let errors = |file: &str, text: &str, adapters: &[AdapterType]| {
        compile_any(file, text, adapters).unwrap_err().join("\n")
    };
    let e = errors("ASKER.fbt", ASKER, &[]);
    assert!(
        e.starts_with("ASKER.fbt:11:") && e.contains("adapter type AREQ is unknown"),
        "{e}"
    );
    let e = errors(
        "ASKER.fbt",
        &ASKER.replace("Condition=\"cli.CNF[", "Condition=\"cli.NOPE["),
        &adapters,
    );
    assert!(
        e.starts_with("ASKER.fbt:20:") && e.contains("`cli.NOPE` is no input event"),
        "{e}"
    );
    let e = errors(
        "ASKER.fbt",
        &ASKER.replace("Output=\"cli.REQ\"", "Output=\"cli.CNF\""),
        &adapters,
    );
    assert!(e.contains("`cli.CNF` is no output event"), "{e}");
    let e = errors(
        "DOUBLER.fbt",
        &DOUBLER.replace("srv.OUT2 := srv.IN2 + 1;", "srv.OUT3 := 1;"),
        &adapters,
    );
    assert!(e.starts_with("DOUBLER.fbt:15:"), "{e}");
    let e = read_adp("A.adp", "<FBType Name=\"X\"/>").unwrap_err();
    assert!(e.message.contains("expected an <AdapterType>"), "{e}");
}

/// ASKER and DOUBLER inside a composite, joined by an adapter connection of its network.
const PAIR: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<FBType Name="PAIR">
  <InterfaceList>
    <EventInputs><Event Name="ASK"><With Var="X"/></Event></EventInputs>
    <EventOutputs><Event Name="DONE"><With Var="Y"/></Event></EventOutputs>
    <InputVars><VarDeclaration Name="X" Type="INT"/></InputVars>
    <OutputVars><VarDeclaration Name="Y" Type="INT"/></OutputVars>
  </InterfaceList>
  <FBNetwork>
    <FB Name="A" Type="ASKER"/>
    <FB Name="D" Type="DOUBLER"/>
    <EventConnections>
      <Connection Source="ASK" Destination="A.ASK"/>
      <Connection Source="A.DONE" Destination="DONE"/>
    </EventConnections>
    <DataConnections>
      <Connection Source="X" Destination="A.X"/>
      <Connection Source="A.Y" Destination="Y"/>
    </DataConnections>
    <AdapterConnections>
      <Connection Source="D.srv" Destination="A.cli"/>
    </AdapterConnections>
  </FBNetwork>
</FBType>"#;

#[test]
fn a_composite_joins_its_components_by_an_adapter_connection() {
    let mut d = device();
    let pair = compile_any("PAIR.fbt", PAIR, &adapters()).unwrap();
    d.add_type(&pair.package()).unwrap();
    let answer = d.execute("R", &request("CREATE", "<FB Name=\"P\" Type=\"PAIR\"/>"), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    d.execute("R", &request("START", ""), 0);
    d.execute("R", &request("WRITE", &connection("7", "P.X")), 0);
    let answer = d.execute("R", &request("WRITE", &connection("$e", "P.ASK")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    assert_eq!(read(&mut d, "P.Y"), "14");
    assert_eq!(read(&mut d, "P.D.srv.IN1"), "7");

    // An adapter connection to the composite's own socket (rather than from its ports)
    // is refused with its place.
    let own = PAIR
        .replace(
            "</InterfaceList>",
            "<Sockets><AdapterDeclaration Name=\"s\" Type=\"AREQ\"/></Sockets></InterfaceList>",
        )
        .replace("Destination=\"A.cli\"", "Destination=\"s\"");
    let e = compile_any("PAIR.fbt", &own, &adapters())
        .unwrap_err()
        .join("\n");
    assert!(e.starts_with("PAIR.fbt:21:"), "{e}");
}

/// A time-out service's adapter as 4diac's ATimeOut is shaped (written here): the plug
/// sends START with DT and STOP, the socket answers TimeOut.
const ADELAY: &str = r#"<AdapterType Name="ADELAY"><InterfaceList>
  <EventInputs><Event Name="TimeOut"/></EventInputs>
  <EventOutputs><Event Name="START"><With Var="DT"/></Event><Event Name="STOP"/></EventOutputs>
  <OutputVars><VarDeclaration Name="DT" Type="TIME"/></OutputVars>
</InterfaceList></AdapterType>"#;

/// A composite serving ADELAY on its own socket with an E_DELAY.
const TIMEOUT: &str = r#"<FBType Name="TIMEOUT"><InterfaceList>
  <Sockets><AdapterDeclaration Name="s" Type="ADELAY"/></Sockets>
</InterfaceList><FBNetwork>
  <FB Name="DLY" Type="E_DELAY"/>
  <EventConnections>
    <Connection Source="s.START" Destination="DLY.START"/>
    <Connection Source="s.STOP" Destination="DLY.STOP"/>
    <Connection Source="DLY.EO" Destination="s.TimeOut"/>
  </EventConnections>
  <DataConnections><Connection Source="s.DT" Destination="DLY.DT"/></DataConnections>
</FBNetwork></FBType>"#;

/// Counts the time-outs it asked for on its plug.
const WATCH: &str = r#"<FBType Name="WATCH"><InterfaceList>
  <EventInputs><Event Name="GO"/></EventInputs>
  <OutputVars><VarDeclaration Name="N" Type="INT"/></OutputVars>
  <Plugs><AdapterDeclaration Name="tmo" Type="ADELAY"/></Plugs>
</InterfaceList><BasicFB><ECC>
  <ECState Name="START"/>
  <ECState Name="ARM"><ECAction Algorithm="arm" Output="tmo.START"/></ECState>
  <ECState Name="EXPIRED"><ECAction Algorithm="count"/></ECState>
  <ECTransition Source="START" Destination="ARM" Condition="GO"/>
  <ECTransition Source="ARM" Destination="START" Condition="1"/>
  <ECTransition Source="START" Destination="EXPIRED" Condition="tmo.TimeOut"/>
  <ECTransition Source="EXPIRED" Destination="START" Condition="1"/>
</ECC>
<Algorithm Name="arm"><ST><![CDATA[tmo.DT := T#100ms;]]></ST></Algorithm>
<Algorithm Name="count"><ST><![CDATA[N := N + 1;]]></ST></Algorithm>
</BasicFB></FBType>"#;

#[test]
fn a_composite_serves_an_adapter_on_its_own_socket() {
    let adapters = [read_adp("ADELAY.adp", ADELAY).unwrap()];
    let mut d = Device::new(Limits::default(), 2);
    for (file, text) in [("TIMEOUT.fbt", TIMEOUT), ("WATCH.fbt", WATCH)] {
        let t = compile_any(file, text, &adapters).unwrap_or_else(|e| panic!("{e:?}"));
        d.add_type(&t.package()).unwrap();
    }
    d.execute(
        "",
        &request("CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        0,
    );
    for (name, ty) in [("W", "WATCH"), ("T", "TIMEOUT")] {
        let answer = d.execute(
            "R",
            &request("CREATE", &format!("<FB Name=\"{name}\" Type=\"{ty}\"/>")),
            0,
        );
        assert!(!answer.contains("Reason"), "{answer}");
    }
    let answer = d.execute("R", &request("CREATE", &connection("W.tmo", "T.s")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    let again = d.execute("R", &request("CREATE", &connection("W.tmo", "T.s")), 0);
    assert!(
        again.contains("Reason"),
        "a socket takes one connection: {again}"
    );
    d.execute("R", &request("START", ""), 0);
    d.execute("R", &request("WRITE", &connection("$e", "W.GO")), 0);
    // The composite's socket port reaches the E_DELAY inside.
    assert_eq!(read(&mut d, "T.DLY.DT"), "T#100ms");
    d.advance(99_000_000);
    assert_eq!(read(&mut d, "W.N"), "0");
    d.advance(100_000_000);
    assert_eq!(read(&mut d, "W.N"), "1");

    // Deleting the composite takes its adapter connection with it.
    d.execute("R", &request("STOP", ""), 0);
    let answer = d.execute("R", &request("DELETE", "<FB Name=\"T\" Type=\"\"/>"), 0);
    assert!(!answer.contains("Reason"), "{answer}");
    let answer = d.execute(
        "R",
        &request("CREATE", "<FB Name=\"T\" Type=\"TIMEOUT\"/>"),
        0,
    );
    assert!(!answer.contains("Reason"), "{answer}");
    let answer = d.execute("R", &request("CREATE", &connection("W.tmo", "T.s")), 0);
    assert!(!answer.contains("Reason"), "{answer}");
}
