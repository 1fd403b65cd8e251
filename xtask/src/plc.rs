//! The PLC build step of `system.img`: for each partition with `plc.*` keys, compile its
//! ST sources with the compiler library (a compile error stops the build, printed exactly
//! as `plcc check` prints it), check its tasks against the partition's period and its watch
//! list against the program's variables, and write its package (`softplc::package`) as the
//! partition's data entry `data/<partition>`.

use anyhow::{Context, Result, bail};
use config::System;
use config::system::{Partition, PlcLink};
use softplc::package::{self, PortMap};

/// `(partition name, package)` for every soft-PLC partition of `system`.
pub fn packages(system: &System) -> Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    for (index, p) in system.partitions.iter().enumerate() {
        let Some(plc) = &p.plc else {
            continue;
        };
        let sources = plc
            .program
            .iter()
            .map(|file| {
                std::fs::read_to_string(&file.path)
                    .map(|text| (file.name.clone(), text))
                    .with_context(|| format!("partition {}: cannot read {}", p.name, file.path))
            })
            .collect::<Result<Vec<_>>>()?;
        let compiled = match plc_compiler::compile(&sources, &plc_compiler::Options::default()) {
            Ok((compiled, _)) => compiled,
            Err((diagnostics, map)) => {
                eprint!(
                    "{}",
                    plc_compiler::diagnostics::render(&map, &diagnostics, false)
                );
                bail!(
                    "partition {}: its PLC program has {} error(s)",
                    p.name,
                    diagnostics.len()
                );
            }
        };
        check_tasks(system, index, p, &compiled.image)?;
        let image = plc_vm::image::Image::parse(&compiled.image)
            .map_err(|e| anyhow::anyhow!("partition {}: {e}", p.name))?;
        for name in &plc.watch {
            if image.find_var(name).is_none() {
                bail!(
                    "partition {}: plc.watch names `{name}`, which is not a variable of its program (globals by name, program variables as instance.variable)",
                    p.name
                );
            }
        }
        let mut ports: Vec<PortMap> = plc
            .inputs
            .iter()
            .chain(&plc.outputs)
            .map(|link| port_map(p, link))
            .collect();
        // The online ports follow the process-image ones (no bytes of the image).
        let online = plc.online.map(|o| {
            let at = ports.len();
            for port in [o.request, o.response] {
                let link = PlcLink {
                    port,
                    at: 0,
                    valid: None,
                };
                ports.push(port_map(p, &link));
            }
            package::Online {
                request: at,
                response: at + 1,
                access: o.access,
            }
        });
        let watch: Vec<&str> = plc.watch.iter().map(String::as_str).collect();
        out.push((
            p.name.clone(),
            package::encode(&ports, &compiled.image, &watch, online),
        ));
    }
    Ok(out)
}

fn port_map<'a>(p: &'a Partition, link: &PlcLink) -> PortMap<'a> {
    let port = &p.ports[link.port];
    PortMap {
        name: &port.name,
        kind: port.kind,
        direction: port.direction,
        size: port.size,
        refresh_ns: port.refresh,
        depth: port.depth,
        area_offset: link.at,
        valid: link.valid,
    }
}

/// Every cyclic task's INTERVAL must be a multiple of the partition's period (the major
/// frame of each schedule that gives it windows): the scan process is released once per
/// period at its window start.
fn check_tasks(system: &System, index: usize, p: &Partition, image: &[u8]) -> Result<()> {
    let image = plc_vm::image::Image::parse(image)
        .map_err(|e| anyhow::anyhow!("partition {}: {e}", p.name))?;
    for schedule in &system.schedules {
        let has_window = schedule
            .windows
            .iter()
            .any(|w| w.time_partition == system.partitions[index].time_partition);
        if !has_window {
            continue;
        }
        let frame = schedule.major_frame;
        for task in (0..image.task_count()).filter_map(|i| image.task(i)) {
            if task.kind == 0 && task.interval_ns % frame != 0 {
                bail!(
                    "partition {}: task {} has INTERVAL {} us, not a multiple of the major frame of schedule {} ({} us): the scan cycle is released once per major frame",
                    p.name,
                    task.name,
                    task.interval_ns / 1000,
                    schedule.name,
                    frame / 1000
                );
            }
        }
    }
    Ok(())
}
