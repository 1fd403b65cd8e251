//! A block-device partition's data entry: its tenant table (`blk.tenants`, already
//! validated), in the format of `blk_core::tenants`; and the disk image the scenarios and
//! `cargo xtask run` give QEMU's virtio-blk.

use blk_core::disk::VirtualDisk;
use blk_core::tenants::Tenant;
use config::System;

/// `(partition name, tenant table)` for every block-device partition.
pub fn data_entries(system: &System) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for p in &system.partitions {
        let Some(blk) = &p.blk else { continue };
        let port = |index: usize| crate::nic::port_spec(p, index);
        let tenants: Vec<Tenant<'_>> = blk
            .tenants
            .iter()
            .map(|t| Tenant {
                partition: &system.partitions[t.partition].name,
                from: port(t.from),
                to: port(t.to),
                disk: VirtualDisk {
                    first_sector: t.first_sector,
                    sectors: t.sectors,
                },
            })
            .collect();
        let mut table = Vec::new();
        blk_core::tenants::encode(&tenants, &mut table);
        out.push((p.name.clone(), table));
    }
    out
}
