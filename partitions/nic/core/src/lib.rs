//! The NIC partition's logic that does not touch hardware: the Ethernet switch between the
//! physical port (the uplink) and the tenants' virtual interfaces, the virtio-net
//! transport's layout and queues, and the tenant table the partition gets from its
//! configuration. no_std, no allocation, host-tested; nothing a tenant, the wire or the
//! device sends can panic it.
#![no_std]

pub mod switch;
pub mod tenants;
pub mod virtio;
