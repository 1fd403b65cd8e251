//! What a function-block type is to the resource: its interface and how it reacts to an
//! input event or a timer.

use crate::value::{DataType, Value};
use alloc::string::String;
use alloc::vec::Vec;

/// An event of an interface with the variables it carries (indices into the inputs for an
/// input event, into the outputs for an output event).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EventSpec {
    pub name: String,
    pub with: Vec<usize>,
}

/// A data input or output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VarSpec {
    pub name: String,
    pub ty: DataType,
    /// Elements of an array, `None` for a scalar.
    pub array: Option<usize>,
}

impl VarSpec {
    /// The variable's initial value.
    pub fn initial(&self) -> Value {
        match self.array {
            Some(n) => Value::Array((0..n).map(|_| crate::value::zero(self.ty)).collect()),
            None => crate::value::zero(self.ty),
        }
    }
}

/// A plug or socket of an interface. Its ports are events and variables of the interface
/// named `NAME.PORT` (a plug's as the adapter type declares them, a socket's mirrored);
/// an adapter connection from a plug to a socket of the same adapter type is the event
/// and data connections between those ports, each way.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AdapterSpec {
    pub name: String,
    /// The adapter type's name.
    pub ty: String,
    pub plug: bool,
}

/// `PORT` of a port named `ADAPTER.PORT` of the plug or socket named `adapter`; `None` when
/// the port is not one of that adapter's.
pub fn adapter_port<'n>(name: &'n str, adapter: &str) -> Option<&'n str> {
    name.strip_prefix(adapter)?.strip_prefix('.')
}

impl AdapterSpec {
    /// `plug` or `socket`, for messages.
    pub fn kind(&self) -> &'static str {
        if self.plug { "plug" } else { "socket" }
    }
}

/// The interface of a function-block type.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Interface {
    pub event_inputs: Vec<EventSpec>,
    pub event_outputs: Vec<EventSpec>,
    pub inputs: Vec<VarSpec>,
    pub outputs: Vec<VarSpec>,
    pub adapters: Vec<AdapterSpec>,
}

/// `(name, WITH names)` of an event, as [`Interface::build`] takes it.
pub type EventDecl<'a> = (&'a str, &'a [&'a str]);
/// `(name, type, array elements)` of a variable.
pub type VarDecl<'a> = (&'a str, DataType, Option<usize>);

impl Interface {
    /// An interface from names; WITH names that are not variables of the event's
    /// direction are an error naming them.
    pub fn build(
        event_inputs: &[EventDecl<'_>],
        event_outputs: &[EventDecl<'_>],
        inputs: &[VarDecl<'_>],
        outputs: &[VarDecl<'_>],
    ) -> Result<Self, String> {
        let vars = |list: &[VarDecl<'_>]| -> Vec<VarSpec> {
            list.iter()
                .map(|(name, ty, array)| VarSpec {
                    name: (*name).into(),
                    ty: *ty,
                    array: *array,
                })
                .collect()
        };
        let (inputs, outputs) = (vars(inputs), vars(outputs));
        let events = |list: &[EventDecl<'_>], vars: &[VarSpec]| -> Result<Vec<EventSpec>, String> {
            list.iter()
                .map(|(name, with)| {
                    let with = with
                        .iter()
                        .map(|w| {
                            vars.iter().position(|v| v.name == *w).ok_or_else(|| {
                                alloc::format!("event {name}: WITH `{w}` is no variable")
                            })
                        })
                        .collect::<Result<_, _>>()?;
                    Ok(EventSpec {
                        name: (*name).into(),
                        with,
                    })
                })
                .collect()
        };
        Ok(Interface {
            event_inputs: events(event_inputs, &inputs)?,
            event_outputs: events(event_outputs, &outputs)?,
            inputs,
            outputs,
            adapters: Vec::new(),
        })
    }

    pub fn event_input(&self, name: &str) -> Option<usize> {
        self.event_inputs.iter().position(|e| e.name == name)
    }

    pub fn event_output(&self, name: &str) -> Option<usize> {
        self.event_outputs.iter().position(|e| e.name == name)
    }

    pub fn input(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|v| v.name == name)
    }

    pub fn output(&self, name: &str) -> Option<usize> {
        self.outputs.iter().position(|v| v.name == name)
    }

    pub fn adapter(&self, name: &str) -> Option<&AdapterSpec> {
        self.adapters.iter().find(|a| a.name == name)
    }
}

/// A timer request of an FB: arm timer `id` for the absolute instant `at` (ns), or disarm it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimerRequest {
    Arm { id: u8, at: i64 },
    Disarm { id: u8 },
}

/// What an FB may do while it reacts: set its outputs, send output events (in order; each
/// carries the outputs as they are when it is sent), arm and disarm its timers, read the
/// time.
pub struct Context<'a> {
    pub(crate) outputs: &'a mut [Value],
    pub(crate) reaction: &'a mut Reaction,
}

/// What a reaction asked, for the resource to carry out after it: kept by the resource
/// between reactions (cleared by [`Reaction::start`]), so that a reaction allocates
/// nothing once its buffers have grown.
#[derive(Default)]
pub(crate) struct Reaction {
    /// The instant the chain runs for.
    pub(crate) now: i64,
    /// Output events sent: each event and where the outputs as they were when it was sent
    /// start in `sent_outputs` (all of them, one after the other), or [`Context::CURRENT`]
    /// while no output has changed since (the usual case: nothing is copied).
    pub(crate) sent: Vec<(usize, usize)>,
    pub(crate) sent_outputs: Vec<Value>,
    pub(crate) timers: Vec<TimerRequest>,
    /// Why the reaction failed (a trapping algorithm), if it did.
    pub(crate) failed: Option<String>,
}

impl Reaction {
    /// Empty, for a reaction at instant `now`.
    #[inline(always)]
    pub(crate) fn start(&mut self, now: i64) {
        self.now = now;
        self.sent.clear();
        self.sent_outputs.clear();
        self.timers.clear();
        self.failed = None;
    }
}

impl Context<'_> {
    /// In [`Reaction::sent`]: the event carries the outputs as they are at the reaction's
    /// end.
    pub(crate) const CURRENT: usize = usize::MAX;

    /// The instant the chain runs for: the external event's time, or a timer's deadline.
    pub fn now(&self) -> i64 {
        self.reaction.now
    }

    /// Output `index` as it is now.
    pub fn output(&self, index: usize) -> &Value {
        &self.outputs[index]
    }

    #[inline(always)]
    pub fn set(&mut self, index: usize, value: Value) {
        self.keep_sent();
        self.outputs[index].set(value);
    }

    /// All outputs, for code that writes several.
    pub fn outputs_mut(&mut self) -> &mut [Value] {
        self.keep_sent();
        self.outputs
    }

    /// Before an output changes: the events sent since the last change get a copy of the
    /// outputs as they are (one copy for all of them).
    #[inline(always)]
    fn keep_sent(&mut self) {
        if self
            .reaction
            .sent
            .last()
            .is_some_and(|&(_, at)| at == Self::CURRENT)
        {
            self.copy_sent();
        }
    }

    #[cold]
    fn copy_sent(&mut self) {
        let r = &mut *self.reaction;
        let start = r.sent_outputs.len();
        r.sent_outputs.extend(self.outputs.iter().cloned());
        for (_, at) in r.sent.iter_mut().rev() {
            if *at != Self::CURRENT {
                break;
            }
            *at = start;
        }
    }

    /// The reaction failed (an algorithm trapped): the resource stops with
    /// [`crate::Fault::Trap`] naming the FB and `reason`; the events this reaction sent
    /// before are not delivered.
    pub fn fail(&mut self, reason: String) {
        if self.reaction.failed.is_none() {
            self.reaction.failed = Some(reason);
        }
    }

    /// Sends output event `output`; its receivers get the outputs as they are now.
    #[inline]
    pub fn send(&mut self, output: usize) {
        self.reaction.sent.push((output, Self::CURRENT));
    }

    /// Arms timer `id` for the absolute instant `at` (re-arming replaces the deadline).
    pub fn arm(&mut self, id: u8, at: i64) {
        self.reaction.timers.push(TimerRequest::Arm { id, at });
    }

    pub fn disarm(&mut self, id: u8) {
        self.reaction.timers.push(TimerRequest::Disarm { id });
    }
}

/// Why the resource calls [`FunctionBlock::restart`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Restart {
    Cold,
    Warm,
    Stop,
}

/// A function-block instance's behaviour.
pub trait FunctionBlock {
    fn interface(&self) -> &Interface;

    /// Input event `event` arrived; `inputs` hold the values delivered with it.
    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>);

    /// Timer `id` is due (at `ctx.now()`, its deadline).
    fn timer(&mut self, _id: u8, _inputs: &[Value], _ctx: &mut Context<'_>) {}

    /// The resource starts (cold or warm) or stops.
    fn restart(&mut self, _kind: Restart, _ctx: &mut Context<'_>) {}

    /// Back to the state of a new instance (the resource's reset).
    fn reset(&mut self);

    /// Sets the inputs and outputs an instance starts with (when created and at a reset)
    /// to the values its type declares (`InitialValue`); the others keep their type's
    /// default, which they hold when this is called.
    fn initial(&mut self, _inputs: &mut [Value], _outputs: &mut [Value]) {}

    /// Whether the FB takes events from outside (a SUBSCRIBE's messages): the resource
    /// then calls [`FunctionBlock::poll`] when it is polled.
    fn polls(&self) -> bool {
        false
    }

    /// Takes what arrived from outside and sends the events it makes (each its own chain
    /// of the resource's poll).
    fn poll(&mut self, _inputs: &[Value], _ctx: &mut Context<'_>) {}

    /// Whether input (or, with `output`, output) `index` is generic and has no type yet
    /// (`crate::functions`).
    fn untyped(&self, _output: bool, _index: usize) -> bool {
        false
    }

    /// Gives the unbound generic variable `index` (and its group) the type `ty`; false when
    /// it is not unbound or `ty` is outside its class.
    fn bind_generic(&mut self, _output: bool, _index: usize, _ty: DataType) -> bool {
        false
    }
}
