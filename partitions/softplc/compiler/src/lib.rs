//! IEC 61131-3 Structured Text compiler (host): source -> verified plc-vm bytecode image.
#![forbid(unsafe_op_in_unsafe_fn)]
#![deny(unsafe_code)]
