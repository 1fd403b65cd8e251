//! The tenant tables of the driver partitions: `nic.tenants` (the partitions attached to a
//! NIC partition's switch) and `blk.tenants` (the virtual disks of a block-device
//! partition). What they share is checked once ([`Driver`]); a NIC tenant adds its MAC, a
//! disk tenant its sector range. After the channels, since a tenant's ports must lead to
//! the tenant.

use super::{Validator, in_source_order, start};
use crate::diagnostic::KeyPath;
use crate::model::*;
use crate::schema;
use crate::system::*;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec;
use toml::Spanned;

/// How one kind of driver partition differs in what the shared checks say.
struct Driver {
    /// The partition's key (`nic`, `blk`).
    key: &'static str,
    /// "a partition is {is} or runs ..."
    is: &'static str,
    /// Why it needs `devices` and `dma`.
    needs: &'static str,
    /// How a tenant entry is written, for an empty table.
    entry: &'static str,
    max_tenants: usize,
    /// "no partition `x` {attach}"
    attach: &'static str,
    own_tenant: &'static str,
    /// What a tenant's ports carry ("frames", "requests").
    carries: &'static str,
    /// The least message size of the `from` and the `to` port, and why.
    sizes: [(u32, &'static str); 2],
}

const NIC: Driver = Driver {
    key: "nic",
    is: "the NIC partition (`nic`)",
    needs: "the NIC partition needs `devices` (its virtio-net function) and `dma` (the region the device reads and writes frames in)",
    entry: "`nic.tenants.<partition> = { mac, from, to }`",
    max_tenants: nic_core::switch::MAX_TENANTS,
    attach: "to attach",
    own_tenant: "the NIC partition cannot be its own tenant",
    carries: "frames",
    sizes: [
        (
            nic_core::switch::MAX_FRAME as u32,
            "one Ethernet frame without FCS a message",
        ),
        (
            nic_core::switch::MAX_FRAME as u32,
            "one Ethernet frame without FCS a message",
        ),
    ],
};

const BLK: Driver = Driver {
    key: "blk",
    is: "a block-device partition (`blk`)",
    needs: "a block-device partition needs `devices` (its virtio-blk function) and `dma` (the region the device reads and writes sectors in)",
    entry: "`blk.tenants.<partition> = { from, to, first_sector, sectors }`",
    max_tenants: blk_core::tenants::MAX_TENANTS,
    attach: "to give a virtual disk",
    own_tenant: "the block-device partition cannot be its own tenant",
    carries: "requests",
    sizes: [
        (blk_core::link::MAX_REQUEST as u32, "the largest request"),
        (blk_core::link::MAX_RESPONSE as u32, "the largest response"),
    ],
};

/// A tenant's partition and its ports on the driver's side, as far as they are valid.
struct TenantEnds {
    partition: Option<usize>,
    ports: Option<(usize, usize)>,
}

/// The interface of a partition whose frames a NIC tenant entry carries, where its frame
/// ring is written down for it: a guest's `eth0`, a soft-PLC's or an IEC 61499 device's
/// interface (a partition program of its own finds the ring at its segment's address).
fn frame_link_mut(p: &mut Partition) -> Option<&mut GuestNet> {
    if let Some(net) = p.guest.as_mut().and_then(|g| g.net.as_mut()) {
        return Some(net);
    }
    if let Some(net) = p.plc.as_mut().and_then(|plc| plc.net.as_mut()) {
        return Some(&mut net.link);
    }
    p.iec61499
        .as_mut()
        .and_then(|f| f.net.as_mut())
        .map(|n| &mut n.link)
}

impl Validator<'_, '_> {
    /// `nic.tenants` (see the crate documentation).
    pub(super) fn nic(
        &mut self,
        doc: &schema::Document,
        partitions: &mut [Partition],
        channels: &[Channel],
        segments: &[(Segment, usize)],
    ) {
        for (key, raw) in in_source_order(&doc.partitions) {
            let Some(nic) = &raw.get_ref().nic else {
                continue;
            };
            let Some(me) = partitions.iter().position(|p| &p.name == key.get_ref()) else {
                continue;
            };
            let path = KeyPath::root()
                .key("partitions")
                .key(key.get_ref())
                .key("nic");
            let table = &nic.get_ref().tenants;
            self.driver_partition(&NIC, raw, start(nic), &path, &partitions[me], table.len());
            let mut tenants: Vec<NicTenant> = Vec::new();
            let mut ok = true;
            for (name, tenant) in in_source_order(table) {
                let at = path.key("tenants").key(name.get_ref());
                let t = tenant.get_ref();
                let taken: Vec<_> = tenants.iter().map(|o| (o.from, o.to)).collect();
                let ends = self.tenant(
                    &NIC,
                    (name, &t.from, &t.to),
                    &at,
                    me,
                    partitions,
                    channels,
                    &taken,
                );
                let mac = self.nic_mac(&t.mac, &at.key("mac"), &tenants);
                let ring = match (&t.ring, ends.partition) {
                    (None, _) => Some(None),
                    (Some(ring), Some(tenant)) => self
                        .nic_ring(ring, &at.key("ring"), [me, tenant], partitions, segments)
                        .map(Some),
                    (Some(_), None) => None,
                };
                match (ends.partition, mac, ends.ports, ring) {
                    (Some(partition), Some(mac), Some((from, to)), Some(ring)) => {
                        tenants.push(NicTenant {
                            partition,
                            mac,
                            from,
                            to,
                            ring,
                        })
                    }
                    _ => ok = false,
                }
            }
            if ok && !tenants.is_empty() && tenants.len() <= NIC.max_tenants {
                for t in &tenants {
                    if let Some(link) = frame_link_mut(&mut partitions[t.partition]) {
                        link.ring = t.ring;
                    }
                }
                partitions[me].nic = Some(Nic { tenants });
            }
        }
    }

    /// `blk.tenants` (see the crate documentation).
    pub(super) fn blk(
        &mut self,
        doc: &schema::Document,
        partitions: &mut [Partition],
        channels: &[Channel],
    ) {
        for (key, raw) in in_source_order(&doc.partitions) {
            let Some(blk) = &raw.get_ref().blk else {
                continue;
            };
            let Some(me) = partitions.iter().position(|p| &p.name == key.get_ref()) else {
                continue;
            };
            let path = KeyPath::root()
                .key("partitions")
                .key(key.get_ref())
                .key("blk");
            let table = &blk.get_ref().tenants;
            self.driver_partition(&BLK, raw, start(blk), &path, &partitions[me], table.len());
            let mut tenants: Vec<BlkTenant> = Vec::new();
            let mut ok = true;
            for (name, tenant) in in_source_order(table) {
                let at = path.key("tenants").key(name.get_ref());
                let t = tenant.get_ref();
                let taken: Vec<_> = tenants.iter().map(|o| (o.from, o.to)).collect();
                let ends = self.tenant(
                    &BLK,
                    (name, &t.from, &t.to),
                    &at,
                    me,
                    partitions,
                    channels,
                    &taken,
                );
                let disk = blk_core::disk::VirtualDisk {
                    first_sector: *t.first_sector.get_ref(),
                    sectors: *t.sectors.get_ref(),
                };
                let range_ok = self.disk_range(disk, &t.sectors, &at, &tenants, partitions);
                match (ends.partition, ends.ports) {
                    (Some(partition), Some((from, to))) if range_ok => {
                        tenants.push(BlkTenant {
                            partition,
                            from,
                            to,
                            first_sector: disk.first_sector,
                            sectors: disk.sectors,
                        });
                    }
                    _ => ok = false,
                }
            }
            if ok && !tenants.is_empty() && tenants.len() <= BLK.max_tenants {
                partitions[me].blk = Some(Blk { tenants });
            }
        }
    }

    /// What makes a partition a driver partition: nothing else uses its data entry, it
    /// owns a device and a DMA region, and it has 1 to `max_tenants` tenants.
    fn driver_partition(
        &mut self,
        d: &Driver,
        raw: &Spanned<schema::Partition>,
        at: usize,
        path: &KeyPath,
        me: &Partition,
        tenants: usize,
    ) {
        let r = raw.get_ref();
        let others = [
            (r.plc.is_some(), "plc", "the soft-PLC (`plc`)"),
            (r.guest.is_some(), "guest", "the guest (`guest`)"),
            (
                r.iec61499.is_some(),
                "iec61499",
                "the IEC 61499 runtime (`iec61499`)",
            ),
            (r.nic.is_some(), "nic", "the NIC (`nic`)"),
            (r.blk.is_some(), "blk", "a block device (`blk`)"),
            (r.data.is_some(), "data", "a `data` entry"),
        ];
        for (_, _, what) in others.iter().filter(|(has, key, _)| *has && *key != d.key) {
            self.error(
                at,
                path,
                format!(
                    "a partition is {} or runs {what}, not both: its data entry is its tenant table",
                    d.is
                ),
            );
        }
        if me.devices.is_empty() || r.dma.is_none() {
            self.error(at, path, d.needs);
        }
        if tenants == 0 || tenants > d.max_tenants {
            self.error(
                at,
                &path.key("tenants"),
                format!(
                    "{tenants} tenants: the partition has 1 to {} ({})",
                    d.max_tenants, d.entry
                ),
            );
        }
    }

    /// A tenant's partition (another one) and its two ports on the driver's side (`from`
    /// and `to` here): queuing, of the right direction and size, carrying no other
    /// tenant's messages (`taken`), and joined by their channels to the tenant.
    #[allow(clippy::too_many_arguments)]
    fn tenant(
        &mut self,
        d: &Driver,
        (name, from, to): (&Spanned<String>, &Spanned<String>, &Spanned<String>),
        at: &KeyPath,
        me: usize,
        partitions: &[Partition],
        channels: &[Channel],
        taken: &[(usize, usize)],
    ) -> TenantEnds {
        let partition = partitions.iter().position(|p| &p.name == name.get_ref());
        match partition {
            None => self.error(
                start(name),
                at,
                format!("no partition `{}` {}", name.get_ref(), d.attach),
            ),
            Some(p) if p == me => self.error(start(name), at, d.own_tenant),
            Some(_) => {}
        }
        let partition = partition.filter(|&p| p != me);
        let mut ends = [None, None];
        for (i, (text, key, direction)) in
            [(from, "from", Direction::In), (to, "to", Direction::Out)]
                .into_iter()
                .enumerate()
        {
            let (size, why) = d.sizes[i];
            let ports = &partitions[me].ports;
            let found = ports.iter().position(|p| &p.name == text.get_ref());
            let fits = found.is_some_and(|p| {
                let p = &ports[p];
                p.kind == PortKind::Queuing && p.direction == direction && p.size >= size
            });
            let Some(port) = found.filter(|_| fits) else {
                self.error(
                    start(text),
                    &at.key(key),
                    format!(
                        "`{}` must be a queuing `{}` port of this partition with size >= {size} ({why})",
                        text.get_ref(),
                        direction.name(),
                    ),
                );
                continue;
            };
            if taken.iter().any(|&(f, t)| f == port || t == port) {
                self.error(
                    start(text),
                    &at.key(key),
                    format!(
                        "port `{}` already carries another tenant's {}",
                        text.get_ref(),
                        d.carries
                    ),
                );
                continue;
            }
            ends[i] = Some(port);
            // Where the port's channel leads: the tenant's end must be the tenant's.
            let (Some(partition), Some(channel)) = (partition, channels.get(ports[port].channel))
            else {
                continue;
            };
            let other = if key == "from" {
                Some(channel.source)
            } else {
                channel.destinations.first().copied()
            };
            if let Some(other) = other.filter(|o| o.partition != partition) {
                self.error(
                    start(text),
                    &at.key(key),
                    format!(
                        "port `{}` is connected {key} `{}.{}`, not to the tenant `{}` (channel `{}`)",
                        text.get_ref(),
                        partitions[other.partition].name,
                        partitions[other.partition].ports[other.port].name,
                        name.get_ref(),
                        channel.name
                    ),
                );
                ends[i] = None;
            }
        }
        TenantEnds {
            partition,
            ports: ends[0].zip(ends[1]),
        }
    }

    /// A virtual disk: not empty, within a disk, overlapping no earlier tenant's.
    fn disk_range(
        &mut self,
        disk: blk_core::disk::VirtualDisk,
        sectors: &Spanned<u64>,
        at: &KeyPath,
        so_far: &[BlkTenant],
        partitions: &[Partition],
    ) -> bool {
        let earlier = so_far.iter().map(|o| blk_core::disk::VirtualDisk {
            first_sector: o.first_sector,
            sectors: o.sectors,
        });
        let Err(e) =
            blk_core::tenants::check_disks(earlier.chain(core::iter::once(disk)), u64::MAX)
        else {
            return true;
        };
        let why = match e {
            blk_core::tenants::TableError::Empty(_) => "has no sectors".to_string(),
            blk_core::tenants::TableError::Overlap(j, _) => format!(
                "overlaps the virtual disk of `{}`",
                partitions[so_far[j].partition].name
            ),
            _ => "ends past the last sector a disk can have".to_string(),
        };
        self.error(
            start(sectors),
            &at.key("sectors"),
            format!(
                "the virtual disk of sectors {}+{} {why}",
                disk.first_sector, disk.sectors
            ),
        );
        false
    }

    /// A tenant's frame ring: a segment of at least `frame_ring::MIN_SEGMENT` bytes that
    /// the NIC partition and its tenant (`ends`) both map read-write and no other
    /// partition maps.
    fn nic_ring(
        &mut self,
        text: &Spanned<String>,
        path: &KeyPath,
        ends: [usize; 2],
        partitions: &[Partition],
        segments: &[(Segment, usize)],
    ) -> Option<FrameRing> {
        let name = text.get_ref();
        let index = self.segment_named(text, path, segments)?;
        let mut ok = true;
        let size = segments[index].0.size;
        if size < frame_ring::MIN_SEGMENT as u64 {
            self.error(
                start(text),
                path,
                format!(
                    "segment `{name}` ({size} bytes) is too small for a frame ring: it needs at least {} bytes (4 frames each way)",
                    frame_ring::MIN_SEGMENT
                ),
            );
            ok = false;
        }
        for (n, p) in partitions.iter().enumerate() {
            let rights = p
                .shared
                .iter()
                .find(|a| a.segment == index)
                .map(|a| a.rights);
            let why = match (ends.contains(&n), rights) {
                (true, Some(Rights::ReadWrite)) | (false, None) => continue,
                (true, _) => "must map it read-write (`shared = { NAME = \"rw\" }`)",
                (false, Some(_)) => "maps it too, and only the NIC partition and the tenant may",
            };
            self.error(
                start(text),
                path,
                format!(
                    "frame ring `{name}`: partition `{}` {}",
                    p.name,
                    why.replace("NAME", name)
                ),
            );
            ok = false;
        }
        let sizes = segments[..index].iter().map(|(s, _)| s.size);
        ok.then(|| FrameRing {
            segment: index,
            address: protocol::layout::shared_address(sizes),
            size,
        })
    }

    /// A tenant's MAC: six hex octets, unicast, not all zero, unique among `so_far`.
    fn nic_mac(
        &mut self,
        text: &Spanned<String>,
        path: &KeyPath,
        so_far: &[NicTenant],
    ) -> Option<[u8; 6]> {
        let Some(mac) = nic_core::switch::Mac::parse(text.get_ref()) else {
            self.error(
                start(text),
                path,
                format!(
                    "`{}` is not a MAC address: six two-digit hex octets separated by colons, like \"52:54:00:12:34:56\"",
                    text.get_ref()
                ),
            );
            return None;
        };
        let why = if mac.is_group() {
            Some("a multicast (group) address: the first octet's lowest bit is set")
        } else if mac.0 == [0; 6] {
            Some("the all-zero address")
        } else if so_far.iter().any(|t| t.mac == mac.0) {
            Some("another tenant has it")
        } else {
            None
        };
        if let Some(why) = why {
            self.error(
                start(text),
                path,
                format!("MAC {mac} cannot be a tenant's: {why}"),
            );
            return None;
        }
        Some(mac.0)
    }
}
