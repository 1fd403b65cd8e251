//! The soft-PLC runtime: runs a verified IEC 61131-3 program (plc-vm bytecode) in a
//! partition, its scan cycle released at the partition's window start, its process image
//! (`%I`, `%Q`, `%M`) connected to ARINC 653 ports.
//!
//! This library is the runtime's whole behaviour and is tested on the host: the package
//! format the build writes ([`package`]), one scan cycle ([`scan`]: inputs, due tasks,
//! statistics, faults and safe outputs, outputs), the latency statistics ([`histogram`]),
//! the online services ([`online`]) and online download ([`download`]: chunk assembly,
//! checks, takeover by name), the globals shared with another project ([`shared`]) and
//! which execution tier runs the program ([`tier`]: the interpreter or native code) and the
//! records kept across a power cut ([`store`]: boot project, RETAIN snapshots; [`persist`]:
//! where they live on the PLC's virtual disk, start and saves), the variables published to
//! and subscribed from other controllers ([`pubsub`]), and the communication process's
//! network services ([`comm`]: its TCP/IP stack, Modbus/TCP, the online protocol on TCP).
//! The partition program (`main.rs`) only re-verifies the program, creates the ports and
//! the processes (one per IEC task and a control process) and moves bytes between them and
//! this library. It must never trust the package: every structure is checked and
//! the bytecode re-verified before anything runs.
#![cfg_attr(not(test), no_std)]

#[cfg(any(feature = "alloc", feature = "net", test))]
extern crate alloc;

#[cfg(any(feature = "net", test))]
pub mod comm;

pub mod download;
pub use histogram;
pub mod online;
pub mod package;
pub mod persist;
pub mod pubsub;
pub mod scan;
pub mod shared;
pub mod store;
pub mod tier;

#[cfg(test)]
mod tests;
