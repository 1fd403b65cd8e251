//! The NIC partition's data entry: its tenant table (`nic.tenants`, already validated),
//! in the format of `nic_core::tenants`.

use config::System;
use nic_core::switch::Mac;
use nic_core::tenants::{PortSpec, RingSpec, Tenant};

/// Port `index` of driver partition `p` as its tenant table names it (`driver_table`; the
/// block-device partition's table too).
pub fn port_spec(p: &config::system::Partition, index: usize) -> PortSpec<'_> {
    let port = &p.ports[index];
    PortSpec {
        name: &port.name,
        size: port.size,
        depth: port.depth,
    }
}

/// `(partition name, tenant table)` for every NIC partition.
pub fn data_entries(system: &System) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for p in &system.partitions {
        let Some(nic) = &p.nic else { continue };
        let port = |index: usize| port_spec(p, index);
        let tenants: Vec<Tenant<'_>> = nic
            .tenants
            .iter()
            .map(|t| Tenant {
                partition: &system.partitions[t.partition].name,
                mac: Mac(t.mac),
                from: port(t.from),
                to: port(t.to),
                ring: t.ring.map(|r| RingSpec {
                    address: r.address,
                    size: r.size,
                }),
            })
            .collect();
        let mut table = Vec::new();
        nic_core::tenants::encode(&tenants, &mut table);
        out.push((p.name.clone(), table));
    }
    out
}
