//! The NIC partition's logic that does not touch hardware: the Ethernet switch between the
//! physical port (the uplink) and the tenants' virtual interfaces. no_std, no allocation,
//! host-tested; nothing a tenant or the wire sends can panic it.
#![no_std]

pub mod switch;
