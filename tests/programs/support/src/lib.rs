//! What the user-mode test programs (and the kernel benchmark) share beyond the runtime:
//! measurements that only tests need. Never linked into syssw or a product partition.
#![no_std]

pub mod window;
