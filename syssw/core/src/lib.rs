//! The pure logic of Warden's system software (syssw, the root task): ARINC 653
//! inter-partition ports ([`ports`]) and the staging buffers of their long messages
//! ([`staging`]), the health monitor's decisions and its event log
//! ([`health`]), the partitions' operating modes ([`mode`]) and what a partition needs of
//! its memory and kernel-memory quota to start ([`budget`]), the queue of partition
//! restarts its restart worker carries out ([`restart`]), the error reports left for their
//! partition's next window ([`deferred`]) and the module schedule the partitions see
//! ([`schedule`]); the codes they answer with
//! and the requests they serve are the service protocol's (`syssw/protocol`).
//!
//! syssw itself (`syssw/src`) is thin glue: it receives the partitions' requests and the
//! kernel's fault reports over IPC, calls into this crate with the caller's partition and
//! the current time, and carries out what comes back (reply to a thread, restart or stop a
//! partition, halt the module). Everything here is a plain function of its inputs so that it
//! can be tested on the host.
//!
//! What this crate must never do:
//! - allocate (no `alloc`): all storage is fixed tables sized by the configuration crate's
//!   limits, plus caller-provided memory for message buffers ([`ports::arena_size`]);
//! - make a system call, block, spin or read a clock: time is always an argument
//!   (nanoseconds since boot, as the kernel's `clock` returns it);
//! - trust a partition: every port index, length and mode code a partition sends is checked
//!   and answered with a [`ReturnCode`], never with a panic;
//! - loop without a bound: every loop runs over a fixed table, a configured count or a
//!   message length.
#![cfg_attr(not(test), no_std)]

pub mod budget;
pub mod deferred;
pub mod health;
pub mod mode;
pub mod ports;
pub mod restart;
pub mod schedule;
pub mod staging;

#[cfg(test)]
mod generated_systems;
#[cfg(test)]
mod testsys;

pub use protocol::ReturnCode;
