//! What the example partitions of DLR's a653rs-linux take from `std` and from a653rs-linux's
//! glue, on `alloc` and Warden's APEX runtime: how `cargo xtask a653rs-examples` builds
//! them for Warden without editing their sources (`xtask/src/a653rs_examples.rs`).
//!
//! A generated program crate is `#![no_std]` and names this crate `std`
//! (`extern crate a653rs_compat as std;`), so their `std::thread::sleep`, `std::time` or
//! `std::string` paths resolve here: `core`'s modules, `alloc`'s collections, and
//! [`thread::sleep`] as TIMED_WAIT. [`prelude`] holds the names std's prelude gives
//! (`String`, `ToString`, `Vec`, `Box`, `format!`), which the build's patch brings into
//! each of their modules. [`ApexLogger`] stands for `a653rs_linux::partition::ApexLogger`:
//! their `log` lines go to the partition's log, one line each.
//!
//! [`ApexLogger`]: logger::ApexLogger
#![no_std]

extern crate alloc;

pub use core::{
    any, array, cell, char, clone, cmp, convert, default, fmt, hash, hint, iter, marker, mem, num,
    ops, option, primitive, ptr, result, slice, str, sync, time,
};

pub use alloc::{borrow, boxed, collections, format, rc, string, vec};

pub mod logger;
#[cfg(feature = "runtime")]
pub mod thread;

/// The names std's prelude adds to `core`'s.
pub mod prelude {
    pub use alloc::borrow::ToOwned;
    pub use alloc::boxed::Box;
    pub use alloc::format;
    pub use alloc::string::{String, ToString};
    pub use alloc::vec;
    pub use alloc::vec::Vec;
}

/// What the generated program runs before their `main`: CREATE_PROCESS reads a period of 0
/// as a653rs-linux does, the partition's period
/// (`apex::runtime::read_zero_period_as_partition_period`).
#[cfg(feature = "runtime")]
pub fn start() {
    apex::runtime::read_zero_period_as_partition_period();
}
