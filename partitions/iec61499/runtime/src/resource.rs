//! A resource: FB instances, connections, the event queue and the timers, executed as the
//! crate documentation says.

use crate::fb::{Context, FunctionBlock, Reaction, Restart, TimerRequest};
use crate::queue::{End, EventQueue};
use crate::value::{DataType, Value};
use alloc::boxed::Box;
use alloc::format;
use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;

/// The resource's limits, from the configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Events the queue holds.
    pub queue: usize,
    /// Events one chain may deliver.
    pub chain_events: usize,
    pub instances: usize,
    pub connections: usize,
    pub timers: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            queue: 256,
            chain_events: 10_000,
            instances: 256,
            connections: 1024,
            timers: 256,
        }
    }
}

/// Why the resource stopped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Fault {
    /// The queue was full when `fb` sent `event`.
    QueueOverflow { fb: String, event: String },
    /// A chain delivered more than [`Limits::chain_events`] events; the last was `event`
    /// to `fb`.
    ChainTooLong { fb: String, event: String },
    /// More timers armed than [`Limits::timers`]; `fb` armed the one too many.
    TooManyTimers { fb: String },
    /// `fb` failed while it reacted (an algorithm trapped), for `reason`.
    Trap { fb: String, reason: String },
}

impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Fault::QueueOverflow { fb, event } => {
                write!(f, "event queue full: {fb}.{event} could not be queued")
            }
            Fault::ChainTooLong { fb, event } => {
                write!(f, "event chain too long (an event loop?) at {fb}.{event}")
            }
            Fault::TooManyTimers { fb } => write!(f, "too many timers armed ({fb})"),
            Fault::Trap { fb, reason } => write!(f, "{fb} trapped: {reason}"),
        }
    }
}

/// Why a deployment request was refused (nothing was changed).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeployError {
    /// An instance of this name exists.
    Duplicate(String),
    /// No such instance or port (`FB.PORT`).
    NotFound(String),
    /// The endpoints do not fit (an output to an output, different types).
    Mismatch(String),
    /// A limit of [`Limits`] is reached.
    Limit(&'static str),
    /// An input with a data connection takes no parameter.
    Connected(String),
    /// The resource stopped on a fault and takes no events until it is restarted.
    Faulted(Fault),
}

impl core::fmt::Display for DeployError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DeployError::Duplicate(n) => write!(f, "an instance named {n} exists"),
            DeployError::NotFound(p) => write!(f, "no such instance or port: {p}"),
            DeployError::Mismatch(m) => write!(f, "cannot connect: {m}"),
            DeployError::Limit(what) => write!(f, "too many {what}"),
            DeployError::Connected(p) => write!(f, "{p} has a data connection"),
            DeployError::Faulted(fault) => write!(f, "the resource stopped on a fault: {fault}"),
        }
    }
}

struct Instance {
    /// Empty for a deleted instance's slot (reused by the next creation).
    name: String,
    fb: Box<dyn FunctionBlock>,
    inputs: Vec<Value>,
    outputs: Vec<Value>,
    /// The event connections from each of its output events: their destinations in
    /// creation order, the fan-out order.
    fanout: Vec<Vec<End>>,
    /// What a delivery of each of its input events samples: each WITH input that has a
    /// data connection, with the connection's source, in the connections' creation order
    /// (kept by [`Resource::plan_samples`] from the resource's data connections).
    samples: Vec<Vec<Sample>>,
}

/// One input an event samples: where from, and the type the value widens to on the way
/// (a connection may widen, UINT to DINT, ...), found once when the plan is made.
#[derive(Clone, Copy)]
struct Sample {
    input: usize,
    source: End,
    widen_to: Option<DataType>,
}

/// A forced input or output.
struct Force {
    end: End,
    output: bool,
    value: Value,
}

struct Timer {
    instance: usize,
    id: u8,
    at: i64,
    /// Arming order, for ties.
    seq: u64,
}

/// A resource of an IEC 61499 device.
pub struct Resource {
    limits: Limits,
    instances: Vec<Instance>,
    /// `(source output, destination input)`.
    data_connections: Vec<(End, End)>,
    /// Inputs set by [`Resource::write`], applied again by a reset.
    parameters: Vec<(End, Value)>,
    forces: Vec<Force>,
    queue: EventQueue,
    timers: Vec<Timer>,
    timer_seq: u64,
    fault: Option<Fault>,
    /// Events delivered since the resource was created (a statistic).
    delivered: u64,
    /// What the current reaction sends and asks (see [`Resource::react`]).
    reaction: Reaction,
}

impl Resource {
    pub fn new(limits: Limits) -> Self {
        Resource {
            limits,
            instances: Vec::new(),
            data_connections: Vec::new(),
            parameters: Vec::new(),
            forces: Vec::new(),
            queue: EventQueue::default(),
            timers: Vec::new(),
            timer_seq: 0,
            fault: None,
            delivered: 0,
            reaction: Reaction::default(),
        }
    }

    /// Creates instance `name` of `fb`; returns its index. A name may have several parts
    /// joined by `.` (a composite's component is `COMPOSITE.COMPONENT`); a port is then
    /// `COMPOSITE.COMPONENT.PORT`.
    pub fn create(
        &mut self,
        name: &str,
        mut fb: Box<dyn FunctionBlock>,
    ) -> Result<usize, DeployError> {
        if name.split('.').any(str::is_empty) {
            return Err(DeployError::NotFound(name.into()));
        }
        if self.instance(name).is_some() {
            return Err(DeployError::Duplicate(name.into()));
        }
        let free = self.instances.iter().position(|i| i.name.is_empty());
        if free.is_none() && self.instances.len() >= self.limits.instances {
            return Err(DeployError::Limit("instances"));
        }
        let interface = fb.interface();
        let mut inputs: Vec<Value> = interface.inputs.iter().map(|v| v.initial()).collect();
        let mut outputs: Vec<Value> = interface.outputs.iter().map(|v| v.initial()).collect();
        let fanout = vec![Vec::new(); interface.event_outputs.len()];
        let samples = vec![Vec::new(); interface.event_inputs.len()];
        fb.initial(&mut inputs, &mut outputs);
        let instance = Instance {
            name: name.into(),
            fb,
            inputs,
            outputs,
            fanout,
            samples,
        };
        Ok(match free {
            Some(slot) => {
                self.instances[slot] = instance;
                slot
            }
            None => {
                self.instances.push(instance);
                self.instances.len() - 1
            }
        })
    }

    fn instance(&self, name: &str) -> Option<usize> {
        if name.is_empty() {
            return None;
        }
        self.instances.iter().position(|i| i.name == name)
    }

    /// The instances' names and the interfaces of their types, in creation order.
    pub fn instances(&self) -> impl Iterator<Item = (&str, &crate::fb::Interface)> {
        self.instances
            .iter()
            .filter(|i| !i.name.is_empty())
            .map(|i| (i.name.as_str(), i.fb.interface()))
    }

    /// Deletes instance `name` with its connections, parameters, forces and timers.
    pub fn delete(&mut self, name: &str) -> Result<(), DeployError> {
        let i = self
            .instance(name)
            .ok_or_else(|| DeployError::NotFound(name.into()))?;
        for list in self.instances.iter_mut().flat_map(|inst| &mut inst.fanout) {
            list.retain(|d| d.0 != i);
        }
        self.instances[i].fanout.iter_mut().for_each(Vec::clear);
        self.data_connections.retain(|(s, d)| s.0 != i && d.0 != i);
        for instance in 0..self.instances.len() {
            self.plan_samples(instance);
        }
        self.parameters.retain(|((p, _), _)| *p != i);
        self.forces.retain(|f| f.end.0 != i);
        self.timers.retain(|t| t.instance != i);
        self.queue.forget(i);
        self.instances[i].name.clear();
        Ok(())
    }

    /// Deletes the event connection `from` → `to`.
    pub fn disconnect_event(&mut self, from: &str, to: &str) -> Result<(), DeployError> {
        let source = self.port(from, |i, p| i.event_output(p))?;
        let destination = self.port(to, |i, p| i.event_input(p))?;
        let list = &mut self.instances[source.0].fanout[source.1];
        let before = list.len();
        list.retain(|d| *d != destination);
        if before == list.len() {
            return Err(DeployError::NotFound(format!("{from} -> {to}")));
        }
        Ok(())
    }

    /// Deletes the data connection `from` → `to`.
    pub fn disconnect_data(&mut self, from: &str, to: &str) -> Result<(), DeployError> {
        let source = self.port(from, |i, p| i.output(p))?;
        let destination = self.port(to, |i, p| i.input(p))?;
        let before = self.data_connections.len();
        self.data_connections
            .retain(|c| *c != (source, destination));
        if before == self.data_connections.len() {
            return Err(DeployError::NotFound(format!("{from} -> {to}")));
        }
        self.plan_samples(destination.0);
        Ok(())
    }

    /// Lists again what each input event of `instance` samples (after its data
    /// connections changed).
    fn plan_samples(&mut self, instance: usize) {
        let mut samples = core::mem::take(&mut self.instances[instance].samples);
        let interface = self.instances[instance].fb.interface();
        for (event, plan) in samples.iter_mut().enumerate() {
            let with = &interface.event_inputs[event].with;
            plan.clear();
            plan.extend(
                self.data_connections
                    .iter()
                    .filter(|(_, (i, var))| *i == instance && with.contains(var))
                    .map(|&(source, (_, input))| {
                        let from = self.instances[source.0].fb.interface().outputs[source.1].ty;
                        let to = interface.inputs[input].ty;
                        Sample {
                            input,
                            source,
                            widen_to: (from != to).then_some(to),
                        }
                    }),
            );
        }
        self.instances[instance].samples = samples;
    }

    /// Forces data input or output `path` (`FB.PORT`) to `value` until [`Resource::unforce`]:
    /// a forced input keeps it whatever its events deliver, a forced output whatever the FB
    /// writes (its receivers get the forced value).
    pub fn force(&mut self, path: &str, value: Value) -> Result<(), DeployError> {
        let (i, port) = self.split(path)?;
        let interface = self.instances[i].fb.interface();
        let (end, output) = match (interface.input(port), interface.output(port)) {
            (Some(n), _) => ((i, n), false),
            (None, Some(n)) => ((i, n), true),
            (None, None) => return Err(DeployError::NotFound(path.into())),
        };
        self.forces.retain(|f| (f.end, f.output) != (end, output));
        let inst = &mut self.instances[i];
        if output {
            inst.outputs[end.1] = value.clone();
        } else {
            inst.inputs[end.1] = value.clone();
        }
        self.forces.push(Force { end, output, value });
        Ok(())
    }

    /// Ends the force of `path`; it keeps the forced value until it is next written.
    pub fn unforce(&mut self, path: &str) -> Result<(), DeployError> {
        let (i, port) = self.split(path)?;
        let interface = self.instances[i].fb.interface();
        let ends = [
            interface.input(port).map(|n| ((i, n), false)),
            interface.output(port).map(|n| ((i, n), true)),
        ];
        let before = self.forces.len();
        self.forces
            .retain(|f| !ends.contains(&Some((f.end, f.output))));
        if before == self.forces.len() {
            return Err(DeployError::NotFound(path.into()));
        }
        Ok(())
    }

    /// Whether `path` is forced.
    pub fn is_forced(&self, path: &str) -> bool {
        let Ok((i, port)) = self.split(path) else {
            return false;
        };
        let interface = self.instances[i].fb.interface();
        self.forces.iter().any(|f| {
            f.end.0 == i
                && if f.output {
                    interface.output(port) == Some(f.end.1)
                } else {
                    interface.input(port) == Some(f.end.1)
                }
        })
    }

    /// Puts the forced values of `instance` back (inputs, or outputs). Inlined, so the
    /// usual case, nothing forced, costs a comparison per event and reaction.
    #[inline(always)]
    fn apply_forces(&mut self, instance: usize, outputs: bool) {
        if !self.forces.is_empty() {
            self.apply_forced(instance, outputs);
        }
    }

    fn apply_forced(&mut self, instance: usize, outputs: bool) {
        for f in &self.forces {
            if f.end.0 == instance && f.output == outputs {
                let inst = &mut self.instances[instance];
                let slot = if outputs {
                    &mut inst.outputs
                } else {
                    &mut inst.inputs
                };
                slot[f.end.1] = f.value.clone();
            }
        }
    }

    /// `FB.PORT` → (instance, name of the port).
    fn split<'p>(&self, path: &'p str) -> Result<(usize, &'p str), DeployError> {
        split_port(path, |fb| self.instance(fb).is_some())
            .and_then(|(fb, port)| Some((self.instance(fb)?, port)))
            .ok_or_else(|| DeployError::NotFound(path.into()))
    }

    /// The interface of the instance `FB.PORT` names, and `PORT` (not yet looked up in it).
    pub fn port_interface<'p>(&self, path: &'p str) -> Option<(&crate::fb::Interface, &'p str)> {
        let (i, port) = self.split(path).ok()?;
        Some((self.instances[i].fb.interface(), port))
    }

    fn port(
        &self,
        path: &str,
        find: impl Fn(&crate::fb::Interface, &str) -> Option<usize>,
    ) -> Result<End, DeployError> {
        let (i, port) = self.split(path)?;
        let index = find(self.instances[i].fb.interface(), port)
            .ok_or_else(|| DeployError::NotFound(path.into()))?;
        Ok((i, index))
    }

    fn connections(&self) -> usize {
        let event_connections: usize = self
            .instances
            .iter()
            .flat_map(|inst| &inst.fanout)
            .map(Vec::len)
            .sum();
        event_connections + self.data_connections.len()
    }

    /// Connects output event `from` (`FB.EO`) to input event `to` (`FB.EI`).
    pub fn connect_event(&mut self, from: &str, to: &str) -> Result<(), DeployError> {
        let source = self.port(from, |i, p| i.event_output(p))?;
        let destination = self.port(to, |i, p| i.event_input(p))?;
        if self.connections() >= self.limits.connections {
            return Err(DeployError::Limit("connections"));
        }
        self.instances[source.0].fanout[source.1].push(destination);
        Ok(())
    }

    /// Connects data output `from` (`FB.OUT`) to data input `to` (`FB.IN`; an input has at
    /// most one source) of the same type or one the output's widens to
    /// ([`crate::value::widens`]).
    pub fn connect_data(&mut self, from: &str, to: &str) -> Result<(), DeployError> {
        let source = self.port(from, |i, p| i.output(p))?;
        let destination = self.port(to, |i, p| i.input(p))?;
        // A generic end without a type takes the other end's.
        let generic = (
            self.instances[source.0].fb.untyped(true, source.1),
            self.instances[destination.0]
                .fb
                .untyped(false, destination.1),
        );
        match generic {
            (true, true) => {
                return Err(DeployError::Mismatch(format!(
                    "{from} and {to} are both generic without a type yet (write a typed literal, e.g. DINT#0, to one first)"
                )));
            }
            (true, false) => {
                let input = &self.instances[destination.0].fb.interface().inputs[destination.1];
                let ty = input.ty;
                self.bind_end(source, true, ty, from)?;
            }
            (false, true) => {
                let out = &self.instances[source.0].fb.interface().outputs[source.1];
                let ty = out.ty;
                self.bind_end(destination, false, ty, to)?;
            }
            (false, false) => {}
        }
        let out = &self.instances[source.0].fb.interface().outputs[source.1];
        let input = &self.instances[destination.0].fb.interface().inputs[destination.1];
        if out.array != input.array || !crate::value::widens(out.ty, input.ty) {
            return Err(DeployError::Mismatch(format!(
                "{from} is {:?}, {to} is {:?}",
                out.ty, input.ty
            )));
        }
        if self.data_connections.iter().any(|(_, d)| *d == destination) {
            return Err(DeployError::Mismatch(format!("{to} already has a source")));
        }
        if self.connections() >= self.limits.connections {
            return Err(DeployError::Limit("connections"));
        }
        self.data_connections.push((source, destination));
        self.plan_samples(destination.0);
        Ok(())
    }

    /// The plug or socket `path` (`FB.NAME`) of an instance.
    pub fn adapter(&self, path: &str) -> Option<&crate::fb::AdapterSpec> {
        let (i, name) = self.split(path).ok()?;
        self.instances[i].fb.interface().adapter(name)
    }

    /// Whether `FB.PORT` (an input, else an output) is generic without a type yet.
    pub fn is_unbound(&self, path: &str) -> bool {
        self.generic_end(path)
            .is_some_and(|(end, output)| self.instances[end.0].fb.untyped(output, end.1))
    }

    /// Gives the generic `FB.PORT` (an input, else an output) and its group the type `ty`.
    pub fn bind(&mut self, path: &str, ty: crate::DataType) -> Result<(), DeployError> {
        let (end, output) = self
            .generic_end(path)
            .ok_or_else(|| DeployError::NotFound(path.into()))?;
        self.bind_end(end, output, ty, path)
    }

    fn generic_end(&self, path: &str) -> Option<(End, bool)> {
        let (i, port) = self.split(path).ok()?;
        let interface = self.instances[i].fb.interface();
        match (interface.input(port), interface.output(port)) {
            (Some(n), _) => Some(((i, n), false)),
            (None, Some(n)) => Some(((i, n), true)),
            (None, None) => None,
        }
    }

    /// Binds a generic end; the instance's variables that got their type start from its
    /// initial value.
    fn bind_end(
        &mut self,
        end: End,
        output: bool,
        ty: crate::DataType,
        path: &str,
    ) -> Result<(), DeployError> {
        let inst = &mut self.instances[end.0];
        let before = inst.fb.interface().clone();
        if !inst.fb.bind_generic(output, end.1, ty) {
            return Err(DeployError::Mismatch(format!(
                "{path} cannot be {}",
                ty.name()
            )));
        }
        let after = inst.fb.interface();
        for (values, old, new) in [
            (&mut inst.inputs, &before.inputs, &after.inputs),
            (&mut inst.outputs, &before.outputs, &after.outputs),
        ] {
            for (k, (o, n)) in old.iter().zip(new).enumerate() {
                if o.ty != n.ty {
                    values[k] = n.initial();
                }
            }
        }
        Ok(())
    }

    /// Sets input `to` (`FB.IN`) as a parameter (an input without a data connection).
    pub fn write(&mut self, to: &str, value: Value) -> Result<(), DeployError> {
        let destination = self.port(to, |i, p| i.input(p))?;
        if self.data_connections.iter().any(|(_, d)| *d == destination) {
            return Err(DeployError::Connected(to.into()));
        }
        self.instances[destination.0].inputs[destination.1] = value.clone();
        self.apply_forces(destination.0, false);
        self.parameters.retain(|(end, _)| *end != destination);
        self.parameters.push((destination, value));
        Ok(())
    }

    /// The value of `FB.PORT`, an output or else an input.
    pub fn read(&self, path: &str) -> Option<&Value> {
        let (i, port) = self.split(path).ok()?;
        let inst = &self.instances[i];
        let interface = inst.fb.interface();
        if let Some(o) = interface.output(port) {
            return inst.outputs.get(o);
        }
        interface.input(port).and_then(|n| inst.inputs.get(n))
    }

    pub fn fault(&self) -> Option<&Fault> {
        self.fault.as_ref()
    }

    /// Events delivered so far.
    pub fn delivered(&self) -> u64 {
        self.delivered
    }

    /// Runs `react` on `instance`, then carries out what it asked: its timer requests and
    /// its output events, in order (see [`send`]).
    fn react(
        &mut self,
        instance: usize,
        now: i64,
        react: impl FnOnce(&mut dyn FunctionBlock, &[Value], &mut Context<'_>),
    ) -> Result<(), Fault> {
        // The reaction's buffers are kept between reactions (a reaction does not react
        // again), so their capacity is reused.
        self.reaction.start(now);
        let inst = &mut self.instances[instance];
        let mut ctx = Context {
            outputs: &mut inst.outputs,
            reaction: &mut self.reaction,
        };
        react(inst.fb.as_mut(), &inst.inputs, &mut ctx);
        let outputs = inst.outputs.len();
        if let Some(reason) = self.reaction.failed.take() {
            return Err(Fault::Trap {
                fb: self.instances[instance].name.clone(),
                reason,
            });
        }
        if !self.forces.is_empty() {
            self.force_sent(instance);
        }
        for k in 0..self.reaction.timers.len() {
            self.timer_request(instance, self.reaction.timers[k])?;
        }
        let reaction = &self.reaction;
        for &(event, start) in &reaction.sent {
            let copy =
                (start != Context::CURRENT).then(|| &reaction.sent_outputs[start..][..outputs]);
            send(
                &mut self.queue,
                self.limits.queue,
                &self.instances,
                instance,
                event,
                copy,
            )?;
        }
        Ok(())
    }

    /// After a reaction of `instance`: its forced outputs put back, in its outputs and in
    /// the copies its sent events carry.
    #[cold]
    fn force_sent(&mut self, instance: usize) {
        self.apply_forced(instance, true);
        // (The events that carry the outputs as they are got the forced values just now.)
        let copied = self
            .reaction
            .sent
            .iter()
            .filter(|(_, start)| *start != Context::CURRENT);
        for &(_, start) in copied {
            for f in self
                .forces
                .iter()
                .filter(|f| f.end.0 == instance && f.output)
            {
                self.reaction.sent_outputs[start + f.end.1] = f.value.clone();
            }
        }
    }

    fn timer_request(&mut self, instance: usize, request: TimerRequest) -> Result<(), Fault> {
        match request {
            TimerRequest::Disarm { id } => {
                self.timers.retain(|t| (t.instance, t.id) != (instance, id));
            }
            TimerRequest::Arm { id, at } => {
                self.timers.retain(|t| (t.instance, t.id) != (instance, id));
                if self.timers.len() >= self.limits.timers {
                    return Err(Fault::TooManyTimers {
                        fb: self.instances[instance].name.clone(),
                    });
                }
                self.timer_seq += 1;
                self.timers.push(Timer {
                    instance,
                    id,
                    at,
                    seq: self.timer_seq,
                });
            }
        }
        Ok(())
    }

    /// Delivers queued events until the queue is empty (one chain).
    fn run_chain(&mut self, now: i64) -> Result<(), Fault> {
        let last = self.delivered + self.limits.chain_events as u64;
        while let Some(((instance, event), carried)) = self.queue.pop() {
            if self.delivered == last {
                return Err(chain_too_long(&self.instances[instance], event));
            }
            self.delivered += 1;
            // (A fault abandons the chain and clears the queue: the values left behind
            // above go with it.)
            let inputs = &mut self.instances[instance].inputs;
            for _ in 0..carried {
                self.queue.deliver_value(inputs);
            }
            self.apply_forces(instance, false);
            self.react(instance, now, |fb, i, ctx| fb.event(event, i, ctx))?;
        }
        Ok(())
    }

    /// Runs `f` as a chain unless the resource is faulted; a fault abandons the chain.
    fn chain(
        &mut self,
        now: i64,
        f: impl FnOnce(&mut Self) -> Result<(), Fault>,
    ) -> Result<(), Fault> {
        if let Some(fault) = &self.fault {
            return Err(fault.clone());
        }
        let result = f(self).and_then(|()| self.run_chain(now));
        if let Err(fault) = &result {
            self.queue.clear();
            self.fault = Some(fault.clone());
        }
        result
    }

    /// An external event: input event `to` (`FB.EI`) at instant `now`, and its chain. A
    /// resource that has stopped on a fault refuses it; a fault of this event's own chain
    /// stops the resource (see [`Resource::fault`]) but the event was taken.
    pub fn trigger(&mut self, to: &str, now: i64) -> Result<(), DeployError> {
        let destination = self.port(to, |i, p| i.event_input(p))?;
        if let Some(fault) = &self.fault {
            return Err(DeployError::Faulted(fault.clone()));
        }
        let _ = self.chain(now, |r| {
            queue_sampled(
                &mut r.queue,
                r.limits.queue,
                &r.instances,
                destination,
                None,
            )
            .map_err(|()| Fault::QueueOverflow {
                fb: String::from("(external)"),
                event: to.into(),
            })
        });
        Ok(())
    }

    /// Starts (cold or warm) or stops the resource: every instance hears it (E_RESTART
    /// sends its COLD, WARM or STOP), in creation order, as one chain.
    pub fn restart(&mut self, kind: Restart, now: i64) -> Result<(), Fault> {
        self.chain(now, |r| {
            for i in 0..r.instances.len() {
                if !r.instances[i].name.is_empty() {
                    r.react(i, now, |fb, _, ctx| fb.restart(kind, ctx))?;
                }
            }
            Ok(())
        })
    }

    /// Whether some instance takes events from outside ([`FunctionBlock::polls`]).
    pub fn polls(&self) -> bool {
        self.instances
            .iter()
            .any(|i| !i.name.is_empty() && i.fb.polls())
    }

    /// Lets every instance that takes events from outside take them, in creation order,
    /// each as its own chain at instant `now`.
    pub fn poll(&mut self, now: i64) -> Result<(), Fault> {
        for i in 0..self.instances.len() {
            if !self.instances[i].name.is_empty() && self.instances[i].fb.polls() {
                self.chain(now, |r| {
                    r.react(i, now, |fb, inputs, ctx| fb.poll(inputs, ctx))
                })?;
            }
        }
        Ok(())
    }

    /// The earliest armed timer's deadline.
    pub fn next_deadline(&self) -> Option<i64> {
        self.timers.iter().map(|t| t.at).min()
    }

    /// Fires every timer due at `now` (and those they arm that are due too), each at its
    /// own deadline and as its own chain; returns how many fired. At most
    /// [`Limits::chain_events`] fire in one call, so a zero-period timer cannot hang it.
    pub fn advance(&mut self, now: i64) -> Result<usize, Fault> {
        let mut fired = 0;
        while fired < self.limits.chain_events {
            let Some(next) = self
                .timers
                .iter()
                .enumerate()
                .filter(|(_, t)| t.at <= now)
                .min_by_key(|(_, t)| (t.at, t.seq))
                .map(|(i, _)| i)
            else {
                break;
            };
            let timer = self.timers.swap_remove(next);
            fired += 1;
            let (instance, id, at) = (timer.instance, timer.id, timer.at);
            self.chain(at, |r| {
                r.react(instance, at, |fb, i, ctx| fb.timer(id, i, ctx))
            })?;
        }
        Ok(fired)
    }

    /// Clears the fault, the queue and the timers, puts every instance back to its
    /// initial state and every variable to its initial value or parameter; instances,
    /// connections and parameters stay.
    pub fn reset(&mut self) {
        self.fault = None;
        self.queue.clear();
        self.timers.clear();
        for inst in self.instances.iter_mut().filter(|i| !i.name.is_empty()) {
            inst.fb.reset();
            let interface = inst.fb.interface();
            inst.inputs = interface.inputs.iter().map(|v| v.initial()).collect();
            inst.outputs = interface.outputs.iter().map(|v| v.initial()).collect();
            inst.fb.initial(&mut inst.inputs, &mut inst.outputs);
        }
        for ((i, var), value) in &self.parameters {
            self.instances[*i].inputs[*var] = value.clone();
        }
        for i in 0..self.instances.len() {
            self.apply_forces(i, false);
            self.apply_forces(i, true);
        }
    }
}

/// Queues the destinations of output `event` of `instance`, in connection order, with
/// the outputs it had when it sent the event: `copy`, or (none needed: no output changed
/// since) its outputs as they are.
#[inline(always)]
fn send(
    queue: &mut EventQueue,
    limit: usize,
    instances: &[Instance],
    instance: usize,
    event: usize,
    copy: Option<&[Value]>,
) -> Result<(), Fault> {
    let sender = copy.map(|outputs| (instance, outputs));
    for &to in &instances[instance].fanout[event] {
        if queue_sampled(queue, limit, instances, to, sender).is_err() {
            return Err(overflow(&instances[instance], event));
        }
    }
    Ok(())
}

/// The fault of a chain that was to deliver one event more than the limit, to `inst`'s
/// input event `event`.
#[cold]
#[inline(never)]
fn chain_too_long(inst: &Instance, event: usize) -> Fault {
    Fault::ChainTooLong {
        fb: inst.name.clone(),
        event: inst.fb.interface().event_inputs[event].name.clone(),
    }
}

/// The fault of a full queue when `inst` sent output event `event`.
#[cold]
#[inline(never)]
fn overflow(inst: &Instance, event: usize) -> Fault {
    Fault::QueueOverflow {
        fb: inst.name.clone(),
        event: inst.fb.interface().event_outputs[event].name.clone(),
    }
}

/// Queues an event to `to` with the values its delivery carries, unless the queue holds
/// `limit` events already: the destination's WITH inputs, each from its connected source
/// now, or, for a source that is the `sender`, from the sender's outputs as they were
/// when it sent.
#[inline(always)]
fn queue_sampled(
    queue: &mut EventQueue,
    limit: usize,
    instances: &[Instance],
    to: End,
    sender: Option<(usize, &[Value])>,
) -> Result<(), ()> {
    if queue.len() >= limit {
        return Err(());
    }
    let plan = &instances[to.0].samples[to.1];
    for sample in plan {
        let (si, so) = sample.source;
        let value = match sender {
            Some((s, outputs)) if s == si => &outputs[so],
            _ => &instances[si].outputs[so],
        };
        let queued = queue.push_value(sample.input, value.clone());
        if let Some(to) = sample.widen_to {
            *queued = crate::value::widen(core::mem::take(queued), to);
        }
    }
    queue.push_event(to, plan.len());
    Ok(())
}

/// `FB.PORT` → (`FB`, `PORT`), where `FB` is the longest leading part of `path` that
/// `is_instance` knows: an instance's name may have several parts (a composite's component
/// is `COMPOSITE.COMPONENT`) and so may a port (a plug's or socket's is `ADAPTER.PORT`).
pub fn split_port(path: &str, is_instance: impl Fn(&str) -> bool) -> Option<(&str, &str)> {
    path.rmatch_indices('.')
        .map(|(at, _)| (&path[..at], &path[at + 1..]))
        .find(|(fb, port)| !port.is_empty() && is_instance(fb))
}
