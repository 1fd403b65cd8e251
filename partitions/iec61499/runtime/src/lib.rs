//! The IEC 61499 execution core: a resource's function-block instances, their event and
//! data connections, its event queue and its timers. no_std with `alloc` (instances and
//! connections are created at deployment, from the partition's bounded heap); host-tested.
//!
//! # Execution semantics (an interface: what a deployed application may rely on)
//!
//! - **One event chain at a time per resource.** An external event (a service FB, a timer,
//!   a management trigger) starts a chain; the resource delivers queued events one by one,
//!   first in, first out, until the queue is empty, before it starts the next chain. An FB
//!   instance therefore never runs twice at once, and a chain's order is the order its events
//!   were sent.
//! - **Data travels with its event.** When an FB sends an output event, the values of the
//!   destination's WITH inputs are read from their connected sources at that moment and
//!   queued with the event; the destination gets exactly those values when the event is
//!   delivered. (FORTE reads them when the event is delivered, so a value changed by an
//!   event run in between is seen instead of the one sent.) An input that no input event
//!   carries is never read from its connection (as in FORTE): it keeps its initial value
//!   or parameter.
//! - **Adapters are connections.** A plug's or socket's ports are ports of its FB
//!   ([`fb::AdapterSpec`]); an adapter connection is the event and data connections
//!   between them (the device makes them: `iec61499_mgmt::flat`), so its events queue,
//!   carry their WITH data and fan out as any other.
//! - **Fan-out in a defined order.** An output event connected to several inputs is queued
//!   for them in the order the connections were created (the order of the `.fboot`/XML).
//!   (FORTE leaves it undefined.)
//! - **A full queue is an error, never a drop.** The queue holds [`Limits::queue`] events;
//!   an event that does not fit abandons the chain and faults the resource with
//!   [`Fault::QueueOverflow`] naming the sending FB and event, for the health monitor.
//!   (FORTE drops the event silently.) A chain that delivers more than
//!   [`Limits::chain_events`] events (an event loop) faults it the same way.
//! - **Time on absolute deadlines.** Timers (E_DELAY, E_CYCLE, E_TRAIN, ...) fire at
//!   absolute instants of the partition's clock: E_CYCLE's n-th event is due at start +
//!   n·DT whatever the lateness of the earlier ones, so the period does not drift. Due
//!   timers fire in deadline order, ties in the order they were armed, each starting a
//!   chain. (FORTE counts 1 ms ticks.)
//! - **A fault stops the resource**, its outputs stay as they were (the partition's
//!   process-image service FBs then write their safe values); other resources and
//!   partitions go on. A reset ([`Resource::reset`]) starts it anew.
//! - **Resources and priorities.** In the partition a resource may have an APEX process
//!   of its own at a configured priority, which runs its timers' chains and preempts the
//!   process serving the network and the management requests; the resources share the
//!   device under one mutex, so a chain is never interrupted by another resource's
//!   (`partitions/iec61499/partition/src/main.rs`). (FORTE runs each resource in a thread
//!   of its own, at one priority.)

#![no_std]

extern crate alloc;

pub mod basic;
pub mod composite;
pub mod fb;
pub mod functions;
pub mod package;
mod queue;
pub mod resource;
pub mod stdlib;
pub mod value;
pub mod vmcode;

pub use fb::{Context, EventSpec, FunctionBlock, Interface, VarSpec};
pub use resource::{Fault, Limits, Resource};
pub use value::{DataType, Value, type_named, widen, widens, zero};
