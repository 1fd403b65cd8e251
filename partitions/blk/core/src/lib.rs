//! The block-device partition's logic that does not touch hardware: the request link
//! between a tenant and the driver ([`link`]: read, write, flush, a CRC-32 over every
//! request and response), the tenants' virtual disks (fixed sector ranges of the disk,
//! [`disk`]: every request checked against its tenant's range), the tenant table the
//! partition gets from its configuration ([`tenants`]), and virtio-blk's request header
//! and status ([`virtio_blk`]); the driver's answer to a request ([`driver::serve`]) and
//! a tenant's virtual disk as a `slots::BlockDevice` over the link ([`client`]). no_std, no allocation, host-tested; nothing a tenant or
//! the device sends can panic it.
#![no_std]

pub mod client;
pub mod disk;
pub mod driver;
pub mod link;
pub mod tenants;
pub mod virtio_blk;

/// Bytes of a sector (the unit of the link, the virtual disks and virtio-blk).
pub const SECTOR: usize = 512;
