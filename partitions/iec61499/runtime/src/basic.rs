//! Basic function blocks: the execution control chart (ECC) as data this module interprets,
//! checked once ([`Ecc::verify`]) before an instance exists, and the algorithms and guards
//! as code behind [`Algorithms`] (the verified bytecode of the ST compiler in the
//! partition; closures in tests).
//!
//! # ECC operation (IEC 61499-1 §5.2.2)
//!
//! When an input event arrives (its data already sampled), the transitions leaving the
//! current state are evaluated in their declared order; the first whose event is the one
//! that arrived (or that names no event) and whose guard holds fires: the ECC enters the
//! destination and runs its actions in order (each: the algorithm, then the output event).
//! Then the transitions of the new state are evaluated again, with the event consumed (a
//! transition that names an event no longer fires), until none fires. At most
//! [`MAX_TRANSITIONS`] fire per event: more is a loop of always-true transitions, and the
//! reaction fails. An algorithm or guard that traps fails the reaction too; either way the
//! resource stops with the FB named.

use crate::fb::{Context, FunctionBlock, Interface, VarSpec};
use crate::value::Value;
use alloc::boxed::Box;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

/// Transitions that may fire for one input event.
pub const MAX_TRANSITIONS: usize = 1_000;

/// An action: run an algorithm, then send an output event (either may be absent).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Action {
    pub algorithm: Option<usize>,
    pub output: Option<usize>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct State {
    pub name: String,
    pub actions: Vec<Action>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Transition {
    pub source: usize,
    pub destination: usize,
    /// The input event it waits for; `None` fires on any evaluation.
    pub event: Option<usize>,
    /// The guard (an index into the guards of [`Algorithms`]); `None` is TRUE.
    pub guard: Option<usize>,
}

/// An ECC; state 0 is the initial state.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Ecc {
    pub states: Vec<State>,
    pub transitions: Vec<Transition>,
}

impl Ecc {
    /// Checks every index against the interface and the number of algorithms and guards.
    pub fn verify(
        &self,
        interface: &Interface,
        algorithms: usize,
        guards: usize,
    ) -> Result<(), String> {
        if self.states.is_empty() {
            return Err("the ECC has no state".into());
        }
        for s in &self.states {
            for a in &s.actions {
                if a.algorithm.is_some_and(|i| i >= algorithms) {
                    return Err(format!(
                        "state {}: an action names algorithm {:?} of {algorithms}",
                        s.name, a.algorithm
                    ));
                }
                if a.output.is_some_and(|o| o >= interface.event_outputs.len()) {
                    return Err(format!(
                        "state {}: an action sends output event {:?}, which does not exist",
                        s.name, a.output
                    ));
                }
            }
        }
        for (n, t) in self.transitions.iter().enumerate() {
            let states = self.states.len();
            if t.source >= states || t.destination >= states {
                return Err(format!(
                    "transition {n} connects state {} to {} of {states}",
                    t.source, t.destination
                ));
            }
            if t.event.is_some_and(|e| e >= interface.event_inputs.len()) {
                return Err(format!(
                    "transition {n} waits for input event {:?}, which does not exist",
                    t.event
                ));
            }
            if t.guard.is_some_and(|g| g >= guards) {
                return Err(format!(
                    "transition {n} has guard {:?} of {guards}",
                    t.guard
                ));
            }
        }
        Ok(())
    }
}

/// The variables an algorithm or guard works on.
pub struct Vars<'a> {
    pub inputs: &'a [Value],
    pub outputs: &'a mut [Value],
    pub internals: &'a mut [Value],
}

/// A basic FB type's algorithms and guards.
pub trait Algorithms {
    /// Runs algorithm `index`; an error is a trap with its reason.
    fn run(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<(), String>;
    /// Evaluates guard `index`.
    fn guard(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<bool, String>;
    /// How many of each there are.
    fn counts(&self) -> (usize, usize);
    /// Sets `internals` to the type's initial values where it declares them
    /// (`InitialValue`); the others keep their type's default.
    fn initialise(&mut self, internals: &mut [Value]) {
        let _ = internals;
    }
    /// The same for the interface's inputs and outputs.
    fn initialise_interface(&mut self, inputs: &mut [Value], outputs: &mut [Value]) {
        let _ = (inputs, outputs);
    }
}

/// An instance of a basic FB type.
pub struct BasicFb {
    interface: Interface,
    ecc: Ecc,
    internal_specs: Vec<VarSpec>,
    internals: Vec<Value>,
    state: usize,
    code: Box<dyn Algorithms>,
}

impl BasicFb {
    /// An instance; the ECC is verified against the interface and the code first.
    pub fn new(
        interface: Interface,
        ecc: Ecc,
        internals: Vec<VarSpec>,
        code: Box<dyn Algorithms>,
    ) -> Result<Self, String> {
        let (algorithms, guards) = code.counts();
        ecc.verify(&interface, algorithms, guards)?;
        let mut fb = BasicFb {
            interface,
            ecc,
            internals: Vec::new(),
            internal_specs: internals,
            state: 0,
            code,
        };
        fb.initialise();
        Ok(fb)
    }

    /// The internal variables as the type declares them.
    fn initialise(&mut self) {
        self.internals = self.internal_specs.iter().map(VarSpec::initial).collect();
        self.code.initialise(&mut self.internals);
    }

    /// The current ECC state's name.
    pub fn state(&self) -> &str {
        &self.ecc.states[self.state].name
    }

    fn react(
        &mut self,
        event: usize,
        inputs: &[Value],
        ctx: &mut Context<'_>,
    ) -> Result<(), String> {
        let mut pending = Some(event);
        for _ in 0..MAX_TRANSITIONS {
            let mut fired = None;
            for t in self
                .ecc
                .transitions
                .iter()
                .filter(|t| t.source == self.state)
            {
                if t.event.is_some() && t.event != pending {
                    continue;
                }
                let holds = match t.guard {
                    None => true,
                    Some(g) => {
                        let mut vars = Vars {
                            inputs,
                            outputs: ctx.outputs_mut(),
                            internals: &mut self.internals,
                        };
                        self.code.guard(g, &mut vars)?
                    }
                };
                if holds {
                    fired = Some(t.destination);
                    break;
                }
            }
            let Some(next) = fired else { return Ok(()) };
            pending = None;
            self.state = next;
            for a in self.ecc.states[next].actions.clone() {
                if let Some(alg) = a.algorithm {
                    let mut vars = Vars {
                        inputs,
                        outputs: ctx.outputs_mut(),
                        internals: &mut self.internals,
                    };
                    self.code.run(alg, &mut vars)?;
                }
                if let Some(out) = a.output {
                    ctx.send(out);
                }
            }
        }
        Err(format!(
            "more than {MAX_TRANSITIONS} ECC transitions for one event (a loop at state {})",
            self.ecc.states[self.state].name
        ))
    }
}

impl FunctionBlock for BasicFb {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        if let Err(reason) = self.react(event, inputs, ctx) {
            ctx.fail(reason);
        }
    }

    fn reset(&mut self) {
        self.state = 0;
        self.initialise();
    }

    fn initial(&mut self, inputs: &mut [Value], outputs: &mut [Value]) {
        self.code.initialise_interface(inputs, outputs);
    }
}

#[cfg(test)]
mod tests;
