//! The IEC 61499-1 Annex A event function blocks, written from the standard's ECCs and
//! service sequences (4diac names for events and variables, so 4diac applications connect
//! to them unchanged). Timers run on absolute deadlines (see the crate documentation).
//!
//! Where the standard leaves a choice: a START of E_DELAY, E_CYCLE or E_TRAIN while it runs
//! is ignored (E_RDELAY restarts); E_CYCLE with DT ≤ 0 sends nothing (a zero period would
//! be an endless chain at one instant); E_TABLE and E_N_TABLE take at most the 4 entries of
//! DT. Where the standard defines an FB by a network (E_TRAIN, E_TABLE), ours do what the
//! network does, checked against 4diac's networks flattened on our device
//! (`iec61499-build`'s test `composite`): CV counts an event once it went out (the event
//! carries the count before it); a START of E_TABLE while it runs starts again at entry 0
//! but keeps the pending entry's time. Except for N = 0: there the network of E_TRAIN sends
//! one event (its counter's reset clears Q whatever N) and ours none.

use crate::fb::{Context, EventDecl, FunctionBlock, Interface, Restart, VarDecl};
use crate::value::{DataType, Value};
use alloc::boxed::Box;

/// The types this module provides.
pub const TYPES: [&str; 23] = [
    "E_SPLIT",
    "E_MERGE",
    "E_REND",
    "E_PERMIT",
    "E_SELECT",
    "E_SWITCH",
    "E_SR",
    "E_RS",
    "E_CTU",
    "E_CTD",
    "E_CTUD",
    "E_D_FF",
    "E_T_FF",
    "E_R_TRIG",
    "E_F_TRIG",
    "E_DEMUX",
    "E_DELAY",
    "E_RDELAY",
    "E_CYCLE",
    "E_RESTART",
    "E_TABLE",
    "E_N_TABLE",
    "E_TRAIN",
];

/// A new instance of standard type `name`.
pub fn create(name: &str) -> Option<Box<dyn FunctionBlock>> {
    let index = TYPES.iter().position(|t| *t == name)?;
    Some(NEW[index]())
}

/// A new instance of `ALL[K]`: each type is its own monomorphic [`Standard`], so an event
/// reaches its type's code through its own vtable, in a function holding only that code
/// (the event loops' innermost call).
fn new<const K: usize>() -> Box<dyn FunctionBlock> {
    Box::new(Standard::<K> {
        interface: Standard::<K>::KIND.interface(),
        state: State::default(),
    })
}

/// [`new`] of each of [`ALL`].
const NEW: [fn() -> Box<dyn FunctionBlock>; 23] = [
    new::<0>, new::<1>, new::<2>, new::<3>, new::<4>, new::<5>, new::<6>, new::<7>, new::<8>,
    new::<9>, new::<10>, new::<11>, new::<12>, new::<13>, new::<14>, new::<15>, new::<16>,
    new::<17>, new::<18>, new::<19>, new::<20>, new::<21>, new::<22>,
];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Split,
    Merge,
    Rend,
    Permit,
    Select,
    Switch,
    Sr,
    Rs,
    Ctu,
    Ctd,
    Ctud,
    DFf,
    TFf,
    RTrig,
    FTrig,
    Demux,
    Delay,
    RDelay,
    Cycle,
    Restart,
    Table,
    NTable,
    Train,
}

const ALL: [Kind; 23] = [
    Kind::Split,
    Kind::Merge,
    Kind::Rend,
    Kind::Permit,
    Kind::Select,
    Kind::Switch,
    Kind::Sr,
    Kind::Rs,
    Kind::Ctu,
    Kind::Ctd,
    Kind::Ctud,
    Kind::DFf,
    Kind::TFf,
    Kind::RTrig,
    Kind::FTrig,
    Kind::Demux,
    Kind::Delay,
    Kind::RDelay,
    Kind::Cycle,
    Kind::Restart,
    Kind::Table,
    Kind::NTable,
    Kind::Train,
];

use DataType::{Bool, Time, UInt};

impl Kind {
    fn interface(self) -> Interface {
        let (ei, eo, di, dout): (
            &[EventDecl<'_>],
            &[EventDecl<'_>],
            &[VarDecl<'_>],
            &[VarDecl<'_>],
        ) = match self {
            Kind::Split => (&[("EI", &[])], &[("EO1", &[]), ("EO2", &[])], &[], &[]),
            Kind::Merge => (&[("EI1", &[]), ("EI2", &[])], &[("EO", &[])], &[], &[]),
            Kind::Rend => (
                &[("EI1", &[]), ("EI2", &[]), ("R", &[])],
                &[("EO", &[])],
                &[],
                &[],
            ),
            Kind::Permit => (
                &[("EI", &["PERMIT"])],
                &[("EO", &[])],
                &[("PERMIT", Bool, None)],
                &[],
            ),
            Kind::Select => (
                &[("EI0", &["G"]), ("EI1", &["G"])],
                &[("EO", &[])],
                &[("G", Bool, None)],
                &[],
            ),
            Kind::Switch => (
                &[("EI", &["G"])],
                &[("EO0", &[]), ("EO1", &[])],
                &[("G", Bool, None)],
                &[],
            ),
            Kind::Sr => (
                &[("S", &[]), ("R", &[])],
                &[("EO", &["Q"])],
                &[],
                &[("Q", Bool, None)],
            ),
            Kind::Rs => (
                &[("R", &[]), ("S", &[])],
                &[("EO", &["Q"])],
                &[],
                &[("Q", Bool, None)],
            ),
            Kind::Ctu => (
                &[("CU", &["PV"]), ("R", &[])],
                &[("CUO", &["Q", "CV"]), ("RO", &["Q", "CV"])],
                &[("PV", UInt, None)],
                &[("Q", Bool, None), ("CV", UInt, None)],
            ),
            Kind::Ctd => (
                &[("CD", &[]), ("LD", &["PV"])],
                &[("CDO", &["Q", "CV"]), ("LDO", &["Q", "CV"])],
                &[("PV", UInt, None)],
                &[("Q", Bool, None), ("CV", UInt, None)],
            ),
            Kind::Ctud => (
                &[("CU", &["PV"]), ("CD", &[]), ("R", &[]), ("LD", &["PV"])],
                &[
                    ("CO", &["QU", "CV", "QD"]),
                    ("RO", &["QU", "CV", "QD"]),
                    ("LDO", &["QU", "QD", "CV"]),
                ],
                &[("PV", UInt, None)],
                &[("QU", Bool, None), ("QD", Bool, None), ("CV", UInt, None)],
            ),
            Kind::DFf => (
                &[("CLK", &["D"])],
                &[("EO", &["Q"])],
                &[("D", Bool, None)],
                &[("Q", Bool, None)],
            ),
            Kind::TFf => (
                &[("CLK", &[])],
                &[("EO", &["Q"])],
                &[],
                &[("Q", Bool, None)],
            ),
            Kind::RTrig | Kind::FTrig => (
                &[("EI", &["QI"])],
                &[("EO", &[])],
                &[("QI", Bool, None)],
                &[],
            ),
            Kind::Demux => (
                &[("EI", &["K"])],
                &[("EO0", &[]), ("EO1", &[]), ("EO2", &[]), ("EO3", &[])],
                &[("K", UInt, None)],
                &[],
            ),
            Kind::Delay | Kind::RDelay | Kind::Cycle => (
                &[("START", &["DT"]), ("STOP", &[])],
                &[("EO", &[])],
                &[("DT", Time, None)],
                &[],
            ),
            Kind::Restart => (
                &[],
                &[("COLD", &[]), ("WARM", &[]), ("STOP", &[])],
                &[],
                &[],
            ),
            Kind::Table => (
                &[("START", &["DT", "N"]), ("STOP", &[])],
                &[("EO", &["CV"])],
                &[("DT", Time, Some(4)), ("N", UInt, None)],
                &[("CV", UInt, None)],
            ),
            Kind::NTable => (
                &[("START", &["DT", "N"]), ("STOP", &[])],
                &[("EO0", &[]), ("EO1", &[]), ("EO2", &[]), ("EO3", &[])],
                &[("DT", Time, Some(4)), ("N", UInt, None)],
                &[],
            ),
            Kind::Train => (
                &[("START", &["DT"]), ("STOP", &["DT"])],
                &[("EO", &["CV"])],
                &[("DT", Time, None), ("N", UInt, None)],
                &[("CV", UInt, None)],
            ),
        };
        match Interface::build(ei, eo, di, dout) {
            Ok(interface) => interface,
            Err(e) => unreachable!("the standard interfaces are well-formed: {e}"),
        }
    }
}

/// The state every standard FB keeps (each uses a part).
#[derive(Clone, Copy, Debug, Default)]
struct State {
    /// E_SR, E_RS, E_D_FF, E_T_FF, E_R_TRIG, E_F_TRIG: Q (`None`: FALSE, as initially).
    q: Option<bool>,
    /// E_REND: which of EI1, EI2 arrived.
    got: [bool; 2],
    /// The timer FBs: whether the timer runs.
    active: bool,
    /// E_CYCLE, E_TABLE, E_TRAIN: the deadline of the last event (the next is relative to it).
    deadline: i64,
    /// E_TABLE, E_N_TABLE: the next entry; E_TRAIN: events sent.
    step: u64,
    /// E_TABLE, E_N_TABLE: entries in this run.
    steps: u64,
}

const TIMER: u8 = 0;
const MAX_COUNT: u64 = 65_535;

/// An instance of standard type `ALL[K]`.
struct Standard<const K: usize> {
    interface: Interface,
    state: State,
}

impl<const K: usize> Standard<K> {
    const KIND: Kind = ALL[K];
}

fn table_entry(inputs: &[Value], step: u64) -> i64 {
    match &inputs[0] {
        Value::Array(dt) => dt.get(step as usize).map_or(0, Value::as_time),
        other => other.as_time(),
    }
}

/// E_CTUD's outputs QU and QD from CV and PV.
fn counter_update(inputs: &[Value], ctx: &mut Context<'_>) {
    let (cv, pv) = (ctx.output(2).as_u64(), inputs[0].as_u64());
    ctx.set(0, Value::Bool(cv >= pv));
    ctx.set(1, Value::Bool(cv == 0));
}

impl<const K: usize> FunctionBlock for Standard<K> {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn reset(&mut self) {
        self.state = State::default();
    }

    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        let s = &mut self.state;
        match Self::KIND {
            Kind::Split => {
                ctx.send(0);
                ctx.send(1);
            }
            Kind::Merge => ctx.send(0),
            Kind::Rend => match event {
                2 => s.got = [false; 2],
                e => {
                    s.got[e] = true;
                    if s.got == [true; 2] {
                        s.got = [false; 2];
                        ctx.send(0);
                    }
                }
            },
            Kind::Permit => {
                if inputs[0].as_bool() {
                    ctx.send(0);
                }
            }
            Kind::Select => {
                if inputs[0].as_bool() == (event == 1) {
                    ctx.send(0);
                }
            }
            Kind::Switch => ctx.send(usize::from(inputs[0].as_bool())),
            Kind::Sr | Kind::Rs => {
                // Annex A's ECC: the initial state is RESET's (Q FALSE): R there does nothing.
                let set = (event == 0) == (Self::KIND == Kind::Sr);
                if s.q.unwrap_or(false) != set {
                    s.q = Some(set);
                    ctx.set(0, Value::Bool(set));
                    ctx.send(0);
                }
            }
            Kind::Ctu => match event {
                0 => {
                    let cv = ctx.output(1).as_u64();
                    if cv < MAX_COUNT {
                        ctx.set(1, Value::UInt(cv + 1));
                        ctx.set(0, Value::Bool(cv + 1 >= inputs[0].as_u64()));
                        ctx.send(0);
                    }
                }
                _ => {
                    ctx.set(1, Value::UInt(0));
                    ctx.set(0, Value::Bool(false));
                    ctx.send(1);
                }
            },
            Kind::Ctd => match event {
                0 => {
                    let cv = ctx.output(1).as_u64();
                    if cv > 0 {
                        ctx.set(1, Value::UInt(cv - 1));
                        ctx.set(0, Value::Bool(cv - 1 == 0));
                        ctx.send(0);
                    }
                }
                _ => {
                    let pv = inputs[0].as_u64();
                    ctx.set(1, Value::UInt(pv));
                    ctx.set(0, Value::Bool(pv == 0));
                    ctx.send(1);
                }
            },
            Kind::Ctud => {
                let cv = ctx.output(2).as_u64();
                let (value, out) = match event {
                    0 if cv < MAX_COUNT => (cv + 1, 0),
                    1 if cv > 0 => (cv - 1, 0),
                    2 => (0, 1),
                    3 => (inputs[0].as_u64(), 2),
                    _ => return,
                };
                ctx.set(2, Value::UInt(value));
                counter_update(inputs, ctx);
                ctx.send(out);
            }
            Kind::DFf => {
                let d = inputs[0].as_bool();
                if s.q.unwrap_or(false) != d {
                    s.q = Some(d);
                    ctx.set(0, Value::Bool(d));
                    ctx.send(0);
                }
            }
            Kind::TFf => {
                let q = !s.q.unwrap_or(false);
                s.q = Some(q);
                ctx.set(0, Value::Bool(q));
                ctx.send(0);
            }
            Kind::RTrig | Kind::FTrig => {
                let (qi, before) = (inputs[0].as_bool(), s.q.unwrap_or(false));
                s.q = Some(qi);
                if qi != before && qi == (Self::KIND == Kind::RTrig) {
                    ctx.send(0);
                }
            }
            Kind::Demux => {
                let k = inputs[0].as_u64();
                if k <= 3 {
                    ctx.send(k as usize);
                }
            }
            Kind::Delay | Kind::RDelay => match event {
                0 if !s.active || Self::KIND == Kind::RDelay => {
                    s.active = true;
                    ctx.arm(TIMER, ctx.now().saturating_add(inputs[0].as_time().max(0)));
                }
                0 => {}
                _ => {
                    s.active = false;
                    ctx.disarm(TIMER);
                }
            },
            Kind::Cycle => match event {
                0 if !s.active && inputs[0].as_time() > 0 => {
                    s.active = true;
                    s.deadline = ctx.now().saturating_add(inputs[0].as_time());
                    ctx.arm(TIMER, s.deadline);
                }
                0 => {}
                _ => {
                    s.active = false;
                    ctx.disarm(TIMER);
                }
            },
            Kind::Restart => {}
            Kind::Table | Kind::NTable => match event {
                0 => {
                    s.step = 0;
                    s.steps = inputs[1].as_u64().min(4);
                    if Self::KIND == Kind::Table {
                        ctx.set(0, Value::UInt(0));
                    }
                    let restart = s.active && s.steps > 0;
                    s.active = s.steps > 0;
                    if restart {
                        // As the standard's network: its E_DELAY ignores the START, so the
                        // pending entry's time stands and the table goes on from entry 0.
                    } else if s.active {
                        s.deadline = ctx.now().saturating_add(table_entry(inputs, 0).max(0));
                        ctx.arm(TIMER, s.deadline);
                    } else {
                        ctx.disarm(TIMER);
                    }
                }
                _ => {
                    s.active = false;
                    ctx.disarm(TIMER);
                }
            },
            Kind::Train => match event {
                0 => {
                    s.step = 0;
                    ctx.set(0, Value::UInt(0));
                    if !s.active && inputs[1].as_u64() > 0 {
                        s.active = true;
                        s.deadline = ctx.now().saturating_add(inputs[0].as_time().max(0));
                        ctx.arm(TIMER, s.deadline);
                    }
                }
                _ => {
                    s.active = false;
                    ctx.disarm(TIMER);
                }
            },
        }
    }

    fn timer(&mut self, _id: u8, inputs: &[Value], ctx: &mut Context<'_>) {
        let s = &mut self.state;
        match Self::KIND {
            Kind::Delay | Kind::RDelay => {
                s.active = false;
                ctx.send(0);
            }
            Kind::Cycle => {
                ctx.send(0);
                let period = inputs[0].as_time();
                if period > 0 {
                    s.deadline = s.deadline.saturating_add(period);
                    ctx.arm(TIMER, s.deadline);
                } else {
                    s.active = false;
                }
            }
            Kind::Table | Kind::NTable => {
                if Self::KIND == Kind::Table {
                    ctx.set(0, Value::UInt(s.step));
                    ctx.send(0);
                } else {
                    ctx.send(s.step as usize);
                }
                s.step += 1;
                if s.step < s.steps {
                    if Self::KIND == Kind::Table {
                        // As the standard's network (E_TABLE_CTRL steps CV after EO went
                        // out): the event carries this entry, CV then names the next.
                        ctx.set(0, Value::UInt(s.step));
                    }
                    s.deadline = s
                        .deadline
                        .saturating_add(table_entry(inputs, s.step).max(0));
                    ctx.arm(TIMER, s.deadline);
                } else {
                    s.active = false;
                }
            }
            Kind::Train => {
                ctx.set(0, Value::UInt(s.step));
                ctx.send(0);
                s.step += 1;
                // As the standard's network (its E_CTU counts EO after EO went out): the
                // event carries the events sent before it, CV then counts it too.
                ctx.set(0, Value::UInt(s.step));
                if s.step < inputs[1].as_u64() {
                    s.deadline = s.deadline.saturating_add(inputs[0].as_time().max(0));
                    ctx.arm(TIMER, s.deadline);
                } else {
                    s.active = false;
                }
            }
            _ => {}
        }
    }

    fn restart(&mut self, kind: Restart, ctx: &mut Context<'_>) {
        if Self::KIND == Kind::Restart {
            ctx.send(match kind {
                Restart::Cold => 0,
                Restart::Warm => 1,
                Restart::Stop => 2,
            });
        }
    }
}

#[cfg(test)]
mod tests;
