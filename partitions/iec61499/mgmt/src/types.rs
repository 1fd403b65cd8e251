//! The FB types a device can create: the standard event FBs, the generic function FBs
//! (`iec61499_runtime::functions`), the same-type conversion FBs
//! of 4diac's library (`BOOL2BOOL`, `DINT2DINT`, ...), 4diac's `E_STOPWATCH` (below), and
//! the test FBs FORTE's system tests report with: `TEST_CONDITION` (REQ with `check`:
//! counts a passed or failed test, logs it, CNF) and `STEST_END` (REQ: the test is over).
//!
//! `E_STOPWATCH` as 4diac's utility library defines it: START takes the time unless the
//! watch runs already; STOP of a running watch sets TD to the time since its START and
//! sends EO with it (a STOP of a stopped watch, a START of a running one: nothing). The time
//! is the partition's clock as it runs ([`crate::sifb::ProcessIo::clock`]), where 4diac's
//! reads `NOW_MONOTONIC()`: it measures what happens inside a chain, which the chain's own
//! instant does not (it stays the same through the chain); without a clock, the chains'
//! instants.

use alloc::boxed::Box;
use alloc::format;
use alloc::rc::Rc;
use alloc::string::String;
use alloc::vec::Vec;
use core::cell::RefCell;
use iec61499_runtime::fb::EventDecl;
use iec61499_runtime::{Context, DataType, FunctionBlock, Interface, Value, functions, stdlib};

/// What the test FBs tell the device.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Report {
    pub executed: u32,
    pub failed: u32,
    /// A STEST_END received its REQ.
    pub ended: bool,
    /// Lines for the partition's log.
    pub log: Vec<String>,
    /// Resources stopped by a fault so far (each also a log line).
    pub faults: u32,
}

pub type SharedReport = Rc<RefCell<Report>>;

/// The data types of the conversion FBs (`X2X`).
const CONVERTIBLE: [&str; 17] = [
    "BOOL", "SINT", "INT", "DINT", "LINT", "USINT", "UINT", "UDINT", "ULINT", "BYTE", "WORD",
    "DWORD", "LWORD", "REAL", "LREAL", "TIME", "STRING",
];

/// A new instance of type `ty` named `name` in resource `resource`, or `None` for a type
/// this device does not have.
pub fn create(
    ty: &str,
    resource: &str,
    name: &str,
    report: &SharedReport,
    io: &crate::sifb::Io,
) -> Option<Box<dyn FunctionBlock>> {
    if let Some(fb) = stdlib::create(ty).or_else(|| functions::create(ty)) {
        return Some(fb);
    }
    match ty {
        "TEST_CONDITION" => {
            let interface = build(
                &[("REQ", &["check"])],
                &[("CNF", &[])],
                &[("check", DataType::Bool)],
                &[],
            );
            Some(Box::new(TestCondition {
                interface,
                label: format!("{resource}.{name}"),
                report: report.clone(),
            }))
        }
        "E_STOPWATCH" => Some(Box::new(Stopwatch {
            interface: build(
                &[("START", &[]), ("STOP", &[])],
                &[("EO", &["TD"])],
                &[],
                &[("TD", DataType::Time)],
            ),
            io: io.clone(),
            started: None,
        })),
        "STEST_END" => Some(Box::new(TestEnd {
            interface: build(&[("REQ", &[])], &[], &[], &[]),
            report: report.clone(),
        })),
        _ => {
            let (from, to) = ty.split_once('2')?;
            if from != to || !CONVERTIBLE.contains(&from) {
                return None;
            }
            let dt = iec61499_runtime::type_named(from)?;
            let interface = build(
                &[("REQ", &["IN"])],
                &[("CNF", &["OUT"])],
                &[("IN", dt)],
                &[("OUT", dt)],
            );
            Some(Box::new(Convert { interface }))
        }
    }
}

fn build(
    ei: &[EventDecl<'_>],
    eo: &[EventDecl<'_>],
    inputs: &[(&str, DataType)],
    outputs: &[(&str, DataType)],
) -> Interface {
    let ins: Vec<_> = inputs.iter().map(|(n, t)| (*n, *t, None)).collect();
    let outs: Vec<_> = outputs.iter().map(|(n, t)| (*n, *t, None)).collect();
    match Interface::build(ei, eo, &ins, &outs) {
        Ok(i) => i,
        Err(e) => unreachable!("the built-in interfaces are well-formed: {e}"),
    }
}

struct TestCondition {
    interface: Interface,
    label: String,
    report: SharedReport,
}

impl FunctionBlock for TestCondition {
    fn interface(&self) -> &Interface {
        &self.interface
    }
    fn event(&mut self, _: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        let mut report = self.report.borrow_mut();
        report.executed += 1;
        let line = if inputs[0].as_bool() {
            format!("TEST_CONDITION_PASSED {} passed", self.label)
        } else {
            report.failed += 1;
            format!("TEST_CONDITION_FAILED {} failed", self.label)
        };
        report.log.push(line);
        ctx.send(0);
    }
    fn reset(&mut self) {}
}

struct Stopwatch {
    interface: Interface,
    io: crate::sifb::Io,
    /// When the running watch started.
    started: Option<i64>,
}

impl FunctionBlock for Stopwatch {
    fn interface(&self) -> &Interface {
        &self.interface
    }
    fn event(&mut self, event: usize, _: &[Value], ctx: &mut Context<'_>) {
        const START: usize = 0;
        let now = self.io.borrow().io.clock().unwrap_or_else(|| ctx.now());
        match self.started {
            None if event == START => self.started = Some(now),
            Some(start) if event != START => {
                self.started = None;
                ctx.set(0, Value::Time(now.saturating_sub(start)));
                ctx.send(0);
            }
            _ => {}
        }
    }
    fn reset(&mut self) {
        self.started = None;
    }
}

struct TestEnd {
    interface: Interface,
    report: SharedReport,
}

impl FunctionBlock for TestEnd {
    fn interface(&self) -> &Interface {
        &self.interface
    }
    fn event(&mut self, _: usize, _: &[Value], _: &mut Context<'_>) {
        self.report.borrow_mut().ended = true;
    }
    fn reset(&mut self) {}
}

struct Convert {
    interface: Interface,
}

impl FunctionBlock for Convert {
    fn interface(&self) -> &Interface {
        &self.interface
    }
    fn event(&mut self, _: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        ctx.set(0, inputs[0].clone());
        ctx.send(0);
    }
    fn reset(&mut self) {}
}
