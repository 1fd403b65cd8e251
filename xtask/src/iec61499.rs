//! The IEC 61499 build step of `system.img`: for each partition with `iec61499.*` keys,
//! read its adapter types (`.adp`) and compile its basic FB types (`iec61499_build`: an error names the `.fbt` file, line and
//! column and stops the build), pack them with the boot file into the partition's data
//! entry (`iec61499_mgmt::package`), and boot that package once on the host, so a boot
//! file the device would refuse stops the build with the line and the reason instead of
//! leaving a partition that refuses to start.

use anyhow::{Context, Result, bail};
use config::System;
use config::model::{Direction, PortKind};
use config::system::SourceFile;
use iec61499_mgmt::package::{
    DataQueue, DevicePackage, MgmtPorts, NetPorts, QueuingPort, ResourceProcess, SamplingPort,
};
use iec61499_mgmt::serve::Access;
use iec61499_mgmt::sifb::NoPorts;
use iec61499_runtime::Limits;

/// The partition program (`image = "iec61499"`).
pub const IMAGE: &str = "iec61499";

/// `(partition name, device package)` for every IEC 61499 partition.
pub fn data_entries(system: &System) -> Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    for p in &system.partitions {
        let Some(fb) = &p.iec61499 else { continue };
        let what = format!("partition {}", p.name);
        // The adapter types (`.adp`) the FB types' plugs and sockets are of.
        let is_adapter = |file: &&SourceFile| file.name.ends_with(".adp");
        let adapters = fb
            .types
            .iter()
            .filter(is_adapter)
            .map(|file| {
                iec61499_build::read_adp(&file.name, &read(&what, file)?)
                    .map_err(|e| anyhow::anyhow!("{what}: {e}"))
            })
            .collect::<Result<Vec<_>>>()?;
        let types = fb
            .types
            .iter()
            .filter(|file| !is_adapter(file))
            .map(|file| compile_type(&what, file, &adapters))
            .collect::<Result<Vec<_>>>()?;
        let boot = read(&what, &fb.boot)?;
        let limits = Limits::default();
        let mgmt = fb.mgmt.map(|m| MgmtPorts {
            access: Access::from_code(m.access as u8).expect("the same codes"),
            request: port(p, m.request),
            response: port(p, m.response),
        });
        let net = fb.net.as_ref().map(|n| NetPorts {
            mac: n.link.mac,
            address: n.link.address,
            prefix: n.link.prefix,
            gateway: n.link.gateway,
            port: n.port,
            connections: n.connections,
            access: Access::from_code(n.access as u8).expect("the same codes"),
            rx: named_port(p, &n.link.rx),
            tx: named_port(p, &n.link.tx),
            ring: n.link.ring.map(|r| (r.address, r.size)),
        });
        let ports = p
            .ports
            .iter()
            .filter(|port| port.kind == PortKind::Sampling)
            .map(|port| SamplingPort {
                name: &port.name,
                input: port.direction == Direction::In,
                size: port.size,
                refresh_ns: port.refresh,
            })
            .collect();
        // The queuing ports other than the management pair and the frame ports:
        // PUBLISH/SUBSCRIBE's.
        let mgmt_ports = fb.mgmt.map_or(Vec::new(), |m| vec![m.request, m.response]);
        let frame_ports = fb
            .net
            .as_ref()
            .map_or(Vec::new(), |n| vec![n.link.rx.as_str(), n.link.tx.as_str()]);
        let queues = p
            .ports
            .iter()
            .enumerate()
            .filter(|(i, port)| {
                port.kind == PortKind::Queuing
                    && !mgmt_ports.contains(i)
                    && !frame_ports.contains(&port.name.as_str())
            })
            .map(|(i, port)| DataQueue {
                port: self::port(p, i),
                input: port.direction == Direction::In,
            })
            .collect();
        let package = iec61499_mgmt::package::encode(&DevicePackage {
            types: types.iter().map(Vec::as_slice).collect(),
            boot: &boot,
            queue: limits.queue,
            chain_events: limits.chain_events,
            mgmt,
            net,
            ports,
            queues,
            processes: fb
                .resources
                .iter()
                .map(|r| ResourceProcess {
                    resource: &r.name,
                    priority: r.priority,
                })
                .collect(),
        });
        if let Err(reason) = iec61499_mgmt::package::boot(&package, Box::new(NoPorts), 0) {
            bail!("{what}: {}: {reason}", fb.boot.name);
        }
        out.push((p.name.clone(), package));
    }
    Ok(out)
}

/// Queuing port `index` of partition `p` as the partition creates it.
fn port(p: &config::system::Partition, index: usize) -> QueuingPort<'_> {
    let port = &p.ports[index];
    QueuingPort {
        name: &port.name,
        size: port.size,
        depth: port.depth,
    }
}

/// Queuing port `name` of partition `p` (the configuration checked it exists).
fn named_port<'a>(p: &'a config::system::Partition, name: &str) -> QueuingPort<'a> {
    let index = p
        .ports
        .iter()
        .position(|port| port.name == name)
        .expect("a port the configuration checked");
    port(p, index)
}

fn read(what: &str, file: &SourceFile) -> Result<String> {
    std::fs::read_to_string(&file.path)
        .with_context(|| format!("{what}: cannot read {}", file.path))
}

fn compile_type(
    what: &str,
    file: &SourceFile,
    adapters: &[iec61499_build::AdapterType],
) -> Result<Vec<u8>> {
    let text = read(what, file)?;
    match iec61499_build::compile_any(&file.name, &text, adapters) {
        Ok(t) => Ok(t.package()),
        Err(errors) => {
            for e in &errors {
                eprintln!("{e}");
            }
            bail!(
                "{what}: FB type {} has {} error(s)",
                file.name,
                errors.len()
            );
        }
    }
}
