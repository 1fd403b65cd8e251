//! Deployment, monitoring and boot files as 4diac IDE and FORTE's system tests use them, and
//! hostile requests.

extern crate std;

use super::*;
use crate::literal;
use iec61499_runtime::{DataType, Value, VarSpec};
use proptest::prelude::*;
use std::string::ToString;

fn device() -> Device {
    Device::new(Limits::default(), 4)
}

/// Sends `request` (the `Request` element's content and action) to `dst`; returns the
/// response's reason, or "" when done.
fn send(d: &mut Device, dst: &str, action: &str, object: &str) -> String {
    let text = format!("<Request ID=\"7\" Action=\"{action}\">{object}</Request>");
    let answer = d.execute(dst, &text, 0);
    assert!(answer.starts_with("<Response ID=\"7\""), "{answer}");
    answer.split("Reason=\"").nth(1).map_or(String::new(), |r| {
        r.split('"').next().unwrap_or("").to_string()
    })
}

fn fb(name: &str, ty: &str) -> String {
    format!("<FB Name=\"{name}\" Type=\"{ty}\"/>")
}

fn conn(s: &str, d: &str) -> String {
    format!("<Connection Source=\"{s}\" Destination=\"{d}\"/>")
}

#[test]
fn deploy_run_watch_and_force() {
    let mut d = device();
    assert_eq!(send(&mut d, "", "CREATE", &fb("R", "EMB_RES")), "");
    for (name, ty) in [("C", "E_CTU"), ("SW", "E_SWITCH")] {
        assert_eq!(send(&mut d, "R", "CREATE", &fb(name, ty)), "");
    }
    assert_eq!(send(&mut d, "R", "CREATE", &conn("START.COLD", "C.R")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &conn("C.Q", "SW.G")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &conn("C.CUO", "SW.EI")), "");
    assert_eq!(send(&mut d, "R", "WRITE", &conn("UINT#2", "C.PV")), "");
    assert_eq!(
        send(
            &mut d,
            "R",
            "CREATE",
            "<Watch Source=\"C.CV\" Destination=\"*\"/>"
        ),
        ""
    );
    assert_eq!(
        send(
            &mut d,
            "R",
            "CREATE",
            "<Watch Source=\"SW.G\" Destination=\"*\"/>"
        ),
        ""
    );
    assert_eq!(send(&mut d, "R", "START", ""), "");
    for _ in 0..3 {
        assert_eq!(send(&mut d, "R", "WRITE", &conn("$e", "C.CU")), "");
    }
    let watches = d.execute(
        "R",
        "<Request ID=\"8\" Action=\"READ\"><Watch Source=\"*\" Destination=\"*\"/></Request>",
        0,
    );
    assert!(
        watches.contains("<FB name=\"C\"><Port name=\"CV\"><Data value=\"3\" forced=\"false\"/>"),
        "{watches}"
    );
    assert!(
        watches.contains("<Port name=\"G\"><Data value=\"TRUE\""),
        "{watches}"
    );
    assert_eq!(
        send(
            &mut d,
            "R",
            "WRITE",
            "<Connection Source=\"10\" Destination=\"C.CV\" force=\"true\"/>"
        ),
        ""
    );
    let watches = d.execute(
        "R",
        "<Request ID=\"9\" Action=\"READ\"><Watch Source=\"*\" Destination=\"*\"/></Request>",
        0,
    );
    assert!(
        watches.contains("<Data value=\"10\" forced=\"true\"/>"),
        "{watches}"
    );
    assert_eq!(
        send(
            &mut d,
            "R",
            "WRITE",
            "<Connection Source=\"10\" Destination=\"C.CV\" force=\"false\"/>"
        ),
        ""
    );
    let read = d.execute("R", "<Request ID=\"10\" Action=\"READ\"><Connection Source=\"C.Q\" Destination=\"\"/></Request>", 0);
    assert!(read.contains("Destination=\"TRUE\""), "{read}");
    let list = d.execute(
        "R",
        "<Request ID=\"11\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>",
        0,
    );
    assert!(
        list.contains("<FB Name=\"START\" Type=\"E_RESTART\" />")
            && list.contains("<FB Name=\"C\" Type=\"E_CTU\" />"),
        "{list}"
    );
}

#[test]
fn refusals_have_their_reasons_and_change_nothing() {
    let mut d = device();
    assert_eq!(send(&mut d, "", "CREATE", &fb("R", "EMB_RES")), "");
    assert_eq!(
        send(&mut d, "", "CREATE", &fb("R", "EMB_RES")),
        "INVALID_STATE"
    );
    assert_eq!(
        send(&mut d, "", "CREATE", &fb("X", "PANEL_RESOURCE")),
        "UNSUPPORTED_TYPE"
    );
    assert_eq!(
        send(&mut d, "NOPE", "CREATE", &fb("A", "E_CTU")),
        "INVALID_DST"
    );
    assert_eq!(
        send(&mut d, "R", "CREATE", &fb("A", "E_NOPE")),
        "UNSUPPORTED_TYPE"
    );
    assert_eq!(send(&mut d, "R", "CREATE", &fb("A", "E_CTU")), "");
    assert_eq!(
        send(&mut d, "R", "CREATE", &fb("A", "E_CTU")),
        "INVALID_STATE"
    );
    assert_eq!(
        send(&mut d, "R", "CREATE", &conn("A.CUO", "B.EI")),
        "NO_SUCH_OBJECT"
    );
    assert_eq!(send(&mut d, "R", "CREATE", &conn("A.CV", "A.PV")), "");
    assert_eq!(
        send(&mut d, "R", "CREATE", &conn("A.Q", "A.PV")),
        "INVALID_OPERATION"
    );
    assert_eq!(
        send(&mut d, "R", "WRITE", &conn("5", "A.PV")),
        "INVALID_OPERATION",
        "connected input"
    );
    assert_eq!(
        send(&mut d, "R", "WRITE", &conn("-1", "A.CV")),
        "INVALID_OBJECT",
        "UINT out of range"
    );
    assert_eq!(
        send(&mut d, "R", "WRITE", &conn("$e", "A.CU")),
        "INVALID_STATE",
        "not started"
    );
    assert_eq!(
        send(
            &mut d,
            "R",
            "DELETE",
            "<Watch Source=\"A.CV\" Destination=\"*\"/>"
        ),
        "NO_SUCH_OBJECT"
    );
    assert_eq!(send(&mut d, "R", "START", ""), "");
    assert_eq!(
        send(&mut d, "R", "DELETE", &fb("A", "E_CTU")),
        "INVALID_STATE",
        "running"
    );
    assert_eq!(send(&mut d, "R", "RESET", ""), "INVALID_STATE");
    assert_eq!(send(&mut d, "R", "STOP", ""), "");
    assert_eq!(send(&mut d, "R", "DELETE", &fb("A", "E_CTU")), "");
    assert_eq!(
        send(&mut d, "R", "READ", &conn("A.CV", "")),
        "NO_SUCH_OBJECT"
    );
    assert_eq!(send(&mut d, "R", "FROB", ""), "UNSUPPORTED_CMD");
    assert!(
        d.execute("R", "<Request ID=\"1\" Action=\"CREATE\"><FB Name=", 0)
            .contains("BAD_PARAMS")
    );
    assert!(d.execute("R", "not xml", 0).contains("BAD_PARAMS"));
}

#[test]
fn a_resource_stopped_by_a_fault_refuses_events_until_reset() {
    let mut d = device();
    assert_eq!(send(&mut d, "", "CREATE", &fb("R", "EMB_RES")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &fb("M", "E_MERGE")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &conn("M.EO", "M.EI1")), "");
    assert_eq!(send(&mut d, "R", "START", ""), "");
    // The event is taken; its chain loops until the chain limit stops the resource.
    assert_eq!(send(&mut d, "R", "WRITE", &conn("$e", "M.EI2")), "");
    assert_eq!(
        send(&mut d, "R", "WRITE", &conn("$e", "M.EI2")),
        "INVALID_STATE",
        "stopped by the fault"
    );
}

#[test]
fn literals() {
    let spec = |ty, array| VarSpec {
        name: "X".into(),
        ty,
        array,
    };
    let ok = [
        ("TRUE", spec(DataType::Bool, None), Value::Bool(true)),
        ("false", spec(DataType::Bool, None), Value::Bool(false)),
        ("BOOL#1", spec(DataType::Bool, None), Value::Bool(true)),
        ("UINT#2", spec(DataType::UInt, None), Value::UInt(2)),
        ("16#FF", spec(DataType::Byte, None), Value::UInt(255)),
        ("2#1010_1010", spec(DataType::Byte, None), Value::UInt(170)),
        ("DINT#-26", spec(DataType::DInt, None), Value::Int(-26)),
        ("-1.5E3", spec(DataType::LReal, None), Value::Real(-1500.0)),
        (
            "T#500ms",
            spec(DataType::Time, None),
            Value::Time(500_000_000),
        ),
        (
            "TIME#1h2m3s4ms5us6ns",
            spec(DataType::Time, None),
            Value::Time(3_723_004_005_006),
        ),
        (
            "t#1.5s",
            spec(DataType::Time, None),
            Value::Time(1_500_000_000),
        ),
        (
            "T#-250ms",
            spec(DataType::Time, None),
            Value::Time(-250_000_000),
        ),
        (
            "'a$'b$$c$N$41'",
            spec(DataType::String, None),
            Value::String("a'b$c\nA".into()),
        ),
        (
            "239.192.0.2:61499",
            spec(DataType::String, None),
            Value::String("239.192.0.2:61499".into()),
        ),
        (
            "[T#1s, T#2s]",
            spec(DataType::Time, Some(3)),
            Value::Array(std::vec![
                Value::Time(1_000_000_000),
                Value::Time(2_000_000_000),
                Value::Time(0)
            ]),
        ),
    ];
    for (text, spec, value) in ok {
        assert_eq!(literal::parse(text, &spec), Ok(value.clone()), "{text}");
        if !matches!(value, Value::Array(_) | Value::Real(_)) && !text.contains(':') {
            assert_eq!(
                literal::parse(&literal::show(&value), &spec),
                Ok(value),
                "round trip of {text}"
            );
        }
    }
    let bad = [
        ("maybe", spec(DataType::Bool, None)),
        ("256", spec(DataType::USInt, None)),
        ("-1", spec(DataType::UInt, None)),
        ("INT#5", spec(DataType::UInt, None)),
        ("T#5", spec(DataType::Time, None)),
        ("T#5x", spec(DataType::Time, None)),
        ("'open", spec(DataType::String, None)),
        ("[1, 2, 3]", spec(DataType::Int, Some(2))),
        ("1, 2", spec(DataType::Int, Some(2))),
        ("16#", spec(DataType::Int, None)),
    ];
    for (text, spec) in bad {
        assert!(literal::parse(text, &spec).is_err(), "{text} accepted");
    }
}

/// A boot file in FORTE's system-test style, written for this test.
const PASS: &str = ";<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"T\" Type=\"EMB_RES\" /></Request>
T;<Request ID=\"2\" Action=\"CREATE\"><FB Name=\"END\" Type=\"STEST_END\" /></Request>
T;<Request ID=\"3\" Action=\"CREATE\"><FB Name=\"CHECK\" Type=\"TEST_CONDITION\" /></Request>
T;<Request ID=\"4\" Action=\"CREATE\"><FB Name=\"B\" Type=\"BOOL2BOOL\" /></Request>
T;<Request ID=\"5\" Action=\"WRITE\"><Connection Source=\"true\" Destination=\"B.IN\" /></Request>
T;<Request ID=\"6\" Action=\"CREATE\"><Connection Source=\"CHECK.CNF\" Destination=\"END.REQ\" /></Request>
T;<Request ID=\"7\" Action=\"CREATE\"><Connection Source=\"B.CNF\" Destination=\"CHECK.REQ\" /></Request>
T;<Request ID=\"8\" Action=\"CREATE\"><Connection Source=\"START.COLD\" Destination=\"B.REQ\" /></Request>
T;<Request ID=\"9\" Action=\"CREATE\"><Connection Source=\"B.OUT\" Destination=\"CHECK.check\" /></Request>
T;<Request ID=\"10\" Action=\"START\"/>
";

#[test]
fn boot_files_run_and_report() {
    let mut d = device();
    assert_eq!(d.boot(PASS, 0), Ok(10));
    let report = d.report().clone();
    assert_eq!((report.executed, report.failed, report.ended), (1, 0, true));
    assert_eq!(report.log, ["TEST_CONDITION_PASSED T.CHECK passed"]);

    let mut d = device();
    d.boot(&PASS.replace("Source=\"true\"", "Source=\"false\""), 0)
        .unwrap();
    assert_eq!((d.report().executed, d.report().failed), (1, 1));

    let mut d = device();
    let err = d
        .boot(
            &PASS.replace("T;<Request ID=\"4\"", "T<Request ID=\"4\""),
            0,
        )
        .unwrap_err();
    assert!(err.contains("line 4: no ';'"), "{err}");
    let err = device()
        .boot(&PASS.replace("BOOL2BOOL", "BOOL2BOOLUnknown"), 0)
        .unwrap_err();
    assert!(
        err.contains("line 4") && err.contains("UNSUPPORTED_TYPE"),
        "{err}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    /// Mangled requests: always a response with a reason or none, never a panic.
    #[test]
    fn hostile_requests(cut in 0usize..PASS.len(), junk in "[<>/=\"A-Za-z#$. ]{0,16}", dst in "(|T|X)") {
        let mut d = device();
        d.boot(PASS, 0).unwrap();
        let mut text = PASS.as_bytes()[..cut].to_vec();
        text.extend_from_slice(junk.as_bytes());
        text.extend_from_slice(&PASS.as_bytes()[cut..]);
        if let Ok(text) = std::str::from_utf8(&text) {
            for line in text.lines() {
                let request = line.split_once(';').map_or(line, |(_, r)| r);
                let answer = d.execute(&dst, request, 0);
                prop_assert!(answer.starts_with("<Response ID=\""));
            }
        }
    }
}

#[test]
fn a_generic_function_fb_takes_its_type_from_a_typed_literal_or_a_connection() {
    let mut d = device();
    assert_eq!(send(&mut d, "", "CREATE", &fb("R", "EMB_RES")), "");
    for (name, ty) in [("EQ", "F_EQ"), ("ADD", "F_ADD"), ("CNV", "DINT2DINT")] {
        assert_eq!(send(&mut d, "R", "CREATE", &fb(name, ty)), "");
    }
    // An untyped number gives a generic port no type.
    assert_eq!(
        send(&mut d, "R", "WRITE", &conn("5", "ADD.IN1")),
        "INVALID_OBJECT"
    );
    // As in FORTE's system tests: the literal types IN2 (and with it IN1), the connection
    // from a DINT fits.
    assert_eq!(send(&mut d, "R", "WRITE", &conn("DINT#26", "EQ.IN2")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &conn("CNV.OUT", "EQ.IN1")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &conn("CNV.CNF", "EQ.REQ")), "");
    // ADD takes DINT from the connection to its output.
    assert_eq!(send(&mut d, "R", "CREATE", &conn("ADD.OUT", "CNV.IN")), "");
    assert_eq!(send(&mut d, "R", "WRITE", &conn("20", "ADD.IN1")), "");
    assert_eq!(send(&mut d, "R", "WRITE", &conn("6", "ADD.IN2")), "");
    assert_eq!(send(&mut d, "R", "CREATE", &conn("ADD.CNF", "CNV.REQ")), "");
    assert_eq!(send(&mut d, "R", "START", ""), "");
    assert_eq!(send(&mut d, "R", "WRITE", &conn("$e", "ADD.REQ")), "");
    let answer = d.execute(
        "R",
        "<Request ID=\"7\" Action=\"READ\"><Connection Source=\"EQ.OUT\" Destination=\"\"/></Request>",
        0,
    );
    assert!(answer.contains("Destination=\"TRUE\""), "{answer}");
    // A type outside the class: F_ADD takes no STRING.
    assert_eq!(send(&mut d, "R", "CREATE", &fb("ADD2", "F_ADD")), "");
    assert_eq!(
        send(&mut d, "R", "WRITE", &conn("'text'", "ADD2.IN1")),
        "INVALID_OPERATION"
    );
}

/// A partition whose clock advances 1 us at every reading.
struct Ticking(core::cell::Cell<i64>);

impl crate::sifb::ProcessIo for Ticking {
    fn clock(&self) -> Option<i64> {
        let now = self.0.get() + 1_000;
        self.0.set(now);
        Some(now)
    }
}

/// Reads `path` of resource R as the READ answer's value text.
fn read_value(d: &mut Device, path: &str) -> String {
    let answer = d.execute(
        "R",
        &format!(
            "<Request ID=\"7\" Action=\"READ\">{}</Request>",
            conn(path, "")
        ),
        0,
    );
    answer
        .split("Destination=\"")
        .nth(1)
        .and_then(|v| v.split('"').next())
        .unwrap_or_else(|| panic!("no value: {answer}"))
        .to_string()
}

#[test]
fn a_stopwatch_measures_the_partition_clock_inside_a_chain_and_the_chain_instants_without_one() {
    // S.EO1 starts the watch and S.EO2 stops it in the same chain; C counts its EO.
    let deploy = |d: &mut Device| {
        assert_eq!(send(d, "", "CREATE", &fb("R", "EMB_RES")), "");
        for (name, ty) in [("S", "E_SPLIT"), ("W", "E_STOPWATCH"), ("C", "E_CTU")] {
            assert_eq!(send(d, "R", "CREATE", &fb(name, ty)), "");
        }
        for (from, to) in [("S.EO1", "W.START"), ("S.EO2", "W.STOP"), ("W.EO", "C.CU")] {
            assert_eq!(send(d, "R", "CREATE", &conn(from, to)), "");
        }
        assert_eq!(send(d, "R", "WRITE", &conn("100", "C.PV")), "");
        assert_eq!(send(d, "R", "START", ""), "");
    };
    let mut d = device();
    d.set_io(alloc::boxed::Box::new(Ticking(core::cell::Cell::new(0))));
    deploy(&mut d);
    assert_eq!(send(&mut d, "R", "WRITE", &conn("$e", "S.EI")), "");
    // One reading at START, the next at STOP.
    assert_eq!(read_value(&mut d, "W.TD"), "T#1000ns");
    assert_eq!(read_value(&mut d, "C.CV"), "1");

    // Without a clock: the chains' instants. A STOP of a stopped watch does nothing, nor
    // does a START of a running one.
    let mut d = device();
    deploy(&mut d);
    let at = |d: &mut Device, path: &str, now: i64| {
        let text = format!(
            "<Request ID=\"7\" Action=\"WRITE\">{}</Request>",
            conn("$e", path)
        );
        assert!(!d.execute("R", &text, now).contains("Reason"));
    };
    at(&mut d, "W.STOP", 1_000);
    assert_eq!(read_value(&mut d, "C.CV"), "0");
    at(&mut d, "W.START", 5_000_000);
    at(&mut d, "W.START", 6_000_000);
    at(&mut d, "W.STOP", 12_000_000);
    assert_eq!(read_value(&mut d, "W.TD"), "T#7ms");
    assert_eq!(read_value(&mut d, "C.CV"), "1");
}

/// A process of the partition that runs some resources' timers sees and fires only theirs.
#[test]
fn timers_of_chosen_resources() {
    let mut d = device();
    for (res, dt) in [("FAST", "T#1ms"), ("SLOW", "T#5ms")] {
        assert_eq!(send(&mut d, "", "CREATE", &fb(res, "EMB_RES")), "");
        assert_eq!(send(&mut d, res, "CREATE", &fb("CY", "E_CYCLE")), "");
        assert_eq!(send(&mut d, res, "CREATE", &fb("N", "E_CTU")), "");
        assert_eq!(send(&mut d, res, "WRITE", &conn(dt, "CY.DT")), "");
        assert_eq!(send(&mut d, res, "WRITE", &conn("UINT#1000", "N.PV")), "");
        assert_eq!(
            send(&mut d, res, "CREATE", &conn("START.COLD", "CY.START")),
            ""
        );
        assert_eq!(send(&mut d, res, "CREATE", &conn("CY.EO", "N.CU")), "");
        assert_eq!(send(&mut d, res, "START", ""), "");
    }
    let fast = |name: &str| name == "FAST";
    let slow = |name: &str| name != "FAST";
    assert_eq!(d.next_deadline_of(fast), Some(1_000_000));
    assert_eq!(d.next_deadline_of(slow), Some(5_000_000));
    assert_eq!(d.next_deadline(), Some(1_000_000));
    for ms in 1..=5 {
        d.advance_of(ms * 1_000_000, fast);
    }
    let count = |d: &Device, res: &str| {
        d.resources
            .iter()
            .find(|r| r.name == res)
            .and_then(|r| r.read("N.CV").cloned())
    };
    assert_eq!(count(&d, "FAST"), Some(Value::UInt(5)));
    assert_eq!(count(&d, "SLOW"), Some(Value::UInt(0)));
    assert_eq!(d.next_deadline_of(slow), Some(5_000_000));
    d.advance_of(5_000_000, slow);
    assert_eq!(count(&d, "SLOW"), Some(Value::UInt(1)));
    assert_eq!(d.next_deadline_of(|_| false), None);
}
