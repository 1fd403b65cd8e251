//! The PLC build step of `system.img`: for each partition with `plc.*` keys, compile its
//! ST sources with the compiler library (a compile error stops the build, printed exactly
//! as `plcc check` prints it), check its tasks against the partition's period and its watch
//! list against the program's variables, pair the shared globals of the (at most two) PLC
//! partitions of each `plc.shared` segment and lay the segment out (`softplc::shared::plan`),
//! and write each package (`softplc::package`) as the partition's data entry
//! `data/<partition>`; for each partition with `data.plc_image`, compile those sources the
//! same way and write the bytecode image itself (what `plcc build` writes) as its data
//! entry.

use anyhow::{Context, Result, bail};
use config::System;
use config::system::{DataEntry, Partition, PlcLink, PlcValue, SourceFile};
use plc_vm::image::{Image, VarType};
use softplc::package::{self, PortMap};

/// `(partition name, data entry)` for every partition that has one: a soft-PLC
/// partition's package, or the compiled image `data.plc_image` names.
pub fn data_entries(system: &System) -> Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    // Every program first: the shared globals pair across partitions.
    let mut programs = Vec::new();
    for (index, p) in system.partitions.iter().enumerate() {
        if let Some(DataEntry::PlcImage(files)) = &p.data {
            out.push((
                p.name.clone(),
                compile_sources(&format!("partition {}", p.name), files)?.image,
            ));
        }
        if let Some(plc) = &p.plc {
            programs.push((index, compile(system, index, p, plc)?));
        }
    }
    let mut shared = shared_plans(system, &programs)?;
    for (index, compiled) in &programs {
        let p = &system.partitions[*index];
        let plc = p.plc.as_ref().expect("a PLC partition");
        // Its virtual disk's size (`plc.store`: validated to be a tenant).
        let disk_sectors = system
            .partitions
            .iter()
            .filter_map(|b| b.blk.as_ref())
            .flat_map(|b| &b.tenants)
            .find(|t| t.partition == *index)
            .map(|t| t.sectors);
        out.push((
            p.name.clone(),
            package(
                p,
                plc,
                compiled,
                shared.remove(index).as_ref(),
                disk_sectors,
            )?,
        ));
    }
    Ok(out)
}

/// The shared-globals block of each partition (by index) that shares through a segment.
fn shared_plans(
    system: &System,
    programs: &[(usize, plc_compiler::Compiled)],
) -> Result<std::collections::HashMap<usize, package::SharedPlan>> {
    let mut plans = std::collections::HashMap::new();
    for (index, compiled) in programs {
        let p = &system.partitions[*index];
        let image = Image::parse(&compiled.image).map_err(|e| anyhow::anyhow!("{e}"))?;
        let segment = p.plc.as_ref().and_then(|plc| plc.shared);
        if segment.is_none() && image.shared_count() > 0 {
            let first = image.shared(0).expect("counted");
            bail!(
                "{}:{}:{}: partition {}'s program shares `{}` with another project, but the partition names no segment: add plc.shared = \"<segment>\" (a [[shared_memory]] segment it maps \"rw\")",
                image.file_name(first.location.file).unwrap_or("?"),
                first.location.line,
                first.location.column,
                p.name,
                first.var.name
            );
        }
    }
    for (seg_index, segment) in system.segments.iter().enumerate() {
        let users: Vec<&(usize, plc_compiler::Compiled)> = programs
            .iter()
            .filter(|(i, _)| {
                system.partitions[*i]
                    .plc
                    .as_ref()
                    .is_some_and(|plc| plc.shared == Some(seg_index))
            })
            .collect();
        if users.is_empty() {
            continue;
        }
        let projects = users
            .iter()
            .map(|(i, compiled)| {
                Ok(softplc::shared::Project {
                    partition: &system.partitions[*i].name,
                    image: Image::parse(&compiled.image).map_err(|e| anyhow::anyhow!("{e}"))?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let address =
            protocol::layout::shared_address(system.segments[..seg_index].iter().map(|s| s.size));
        let size = u32::try_from(segment.size).unwrap_or(u32::MAX);
        match softplc::shared::plan(&segment.name, address, size, &projects) {
            Ok(segment_plans) => {
                for ((i, _), plan) in users.iter().zip(segment_plans) {
                    if plan.own.is_some() || plan.other.is_some() {
                        plans.insert(*i, plan);
                    }
                }
            }
            Err(errors) => {
                for e in &errors {
                    eprintln!("error: {e}");
                }
                bail!(
                    "shared memory segment {}: {} error(s) pairing the shared globals of its PLC partitions",
                    segment.name,
                    errors.len()
                );
            }
        }
    }
    Ok(plans)
}

/// Compiles a PLC partition's program and checks its tasks and watch list.
fn compile(
    system: &System,
    index: usize,
    p: &Partition,
    plc: &config::system::Plc,
) -> Result<plc_compiler::Compiled> {
    let compiled = compile_sources(&format!("partition {}", p.name), &plc.program)?;
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
    Ok(compiled)
}

/// The compiled ST sources `files` of partition `p` (a compile error is printed as
/// `plcc check` prints it and stops the build).
/// The bytecode image (what `plcc build` writes) of ST source `file` (a guest's
/// `guest.files` entry `*.plcb` made from a `.st` file); `what` names it in errors.
pub fn image_of(what: &str, file: &SourceFile) -> Result<Vec<u8>> {
    Ok(compile_sources(what, std::slice::from_ref(file))?.image)
}

/// Compiles `files`; `what` (`partition NAME`) names them in errors.
fn compile_sources(what: &str, files: &[SourceFile]) -> Result<plc_compiler::Compiled> {
    let sources = files
        .iter()
        .map(|file| {
            std::fs::read_to_string(&file.path)
                .map(|text| (file.name.clone(), text))
                .with_context(|| format!("{what}: cannot read {}", file.path))
        })
        .collect::<Result<Vec<_>>>()?;
    match plc_compiler::compile(&sources, &plc_compiler::Options::default()) {
        Ok((compiled, _)) => Ok(compiled),
        Err((diagnostics, map)) => {
            eprint!(
                "{}",
                plc_compiler::diagnostics::render(&map, &diagnostics, false)
            );
            bail!("{what}: its PLC program has {} error(s)", diagnostics.len());
        }
    }
}

/// A PLC partition's package: its ports, program, watch list, safe values, shared
/// globals, network interface and store (on a virtual disk of `disk_sectors`).
fn package(
    p: &Partition,
    plc: &config::system::Plc,
    compiled: &plc_compiler::Compiled,
    shared: Option<&package::SharedPlan>,
    disk_sectors: Option<u64>,
) -> Result<Vec<u8>> {
    let image = plc_vm::image::Image::parse(&compiled.image)
        .map_err(|e| anyhow::anyhow!("partition {}: {e}", p.name))?;
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
    // The client records of `plc.online_tcp` (validated: names and keys within limits).
    let online_records = plc.online_tcp.as_ref().map(|o| {
        let clients: Vec<_> = o
            .clients
            .iter()
            .map(|c| package::ClientKey {
                name: c.name.as_bytes(),
                secret: &c.key,
                access: c.access,
            })
            .collect();
        (o.port, package::OnlineTcp::records(&clients))
    });
    // Publish/subscribe (`plc.publish`, `plc.subscribe`): names checked against the program.
    let published = plc.publish.as_ref().map(|p| p.vars.join("\n"));
    let subscribed = plc.subscribe.as_ref().map(|s| s.vars.join("\n"));
    let pubsub = (plc.publish.is_some() || plc.subscribe.is_some()).then(|| package::PubSub {
        publish: plc
            .publish
            .as_ref()
            .zip(published.as_deref())
            .map(|(p, names)| (p.to.0, p.to.1, names)),
        subscribe: plc
            .subscribe
            .as_ref()
            .zip(subscribed.as_deref())
            .map(|(s, names)| package::Subscription {
                port: s.port,
                group: s.group,
                timeout_ns: s.timeout_ns,
                names,
                valid: s.valid.as_deref(),
            }),
    });
    if let Some(pubsub) = &pubsub
        && let Err(e) = softplc::pubsub::Endpoint::new(&image, pubsub)
    {
        bail!(
            "partition {}: plc.publish/plc.subscribe: {}",
            p.name,
            pubsub_error(&e)
        );
    }
    // The frame ports of `plc.net` follow (no bytes of the image either).
    let net = plc.net.as_ref().map(|n| {
        let at = ports.len();
        for port in [&n.link.rx, &n.link.tx] {
            let index = p
                .ports
                .iter()
                .position(|q| &q.name == port)
                .expect("validated: plc.net names ports of the partition");
            let link = PlcLink {
                port: index,
                at: 0,
                valid: None,
            };
            ports.push(port_map(p, &link));
        }
        package::Net {
            mac: n.link.mac,
            address: n.link.address,
            prefix: n.link.prefix,
            gateway: n.link.gateway,
            rx: at,
            tx: at + 1,
            connections: n.connections,
            buffer: n.buffer,
            requests_per_second: n.requests_per_second,
            modbus: plc.modbus.map(|m| package::Modbus {
                port: m.port,
                unit: m.unit,
                write_outputs: m.write_outputs,
                write_markers: m.write_markers,
            }),
            online: online_records
                .as_ref()
                .and_then(|(port, records)| package::OnlineTcp::new(*port, records)),
            pubsub,
            ring: n.link.ring.map(|r| (r.address, r.size)),
        }
    });
    // Then the store's ports (`plc.store`).
    let store = match (plc.store, disk_sectors) {
        (Some(st), Some(sectors)) => {
            let at = ports.len();
            for port in [st.request, st.response] {
                let link = PlcLink {
                    port,
                    at: 0,
                    valid: None,
                };
                ports.push(port_map(p, &link));
            }
            Some(package::Store {
                request: at,
                response: at + 1,
                sectors,
                retain_every_ns: st.retain_every_ns,
            })
        }
        (Some(_), None) => bail!(
            "partition {}: plc.store needs a virtual disk (`blk.tenants.{}`)",
            p.name,
            p.name
        ),
        (None, _) => None,
    };
    let watch: Vec<&str> = plc.watch.iter().map(String::as_str).collect();
    let configured = plc
        .safe
        .iter()
        .map(|(name, value)| safe_value(&image, name, *value))
        .collect::<Result<Vec<_>, String>>()
        .map_err(|e| anyhow::anyhow!("partition {}: plc.safe: {e}", p.name))?;
    let safe = merge_safe_values(&compiled.safe, configured);
    if safe.len() > softplc::scan::MAX_SAFE_VALUES {
        bail!(
            "partition {}: plc.safe gives {} values, at most {} are kept",
            p.name,
            safe.len(),
            softplc::scan::MAX_SAFE_VALUES
        );
    }
    let deadlines = plc
        .deadlines
        .iter()
        .map(|(task, ns)| {
            if !softplc::scan::has_task(&image, task) {
                bail!(
                    "partition {}: plc.deadline names `{task}`, which is not a TASK of its program",
                    p.name
                );
            }
            Ok(package::TaskDeadline {
                task,
                deadline_ns: *ns,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let mut bytes = package::encode(
        &ports,
        &compiled.image,
        &watch,
        online,
        &safe,
        shared,
        &deadlines,
    );
    if plc.native {
        package::request_native(&mut bytes);
    }
    if let Some(net) = &net {
        package::attach_net(&mut bytes, net);
    }
    if let Some(store) = &store {
        package::attach_store(&mut bytes, store);
    }
    Ok(bytes)
}

/// The image name of the soft-PLC partition program (what `plc.native` rebuilds).
pub const SOFTPLC_IMAGE: &str = "softplc";

/// The native tier's code for the partitions with `plc.native = true`: each one's program
/// (from its package in `packages`) translated by `plc-native`, written with the images as
/// one file under `target/plc-native/programs/` (only rewritten when it changes), for the
/// soft-PLC binary's build (`artifacts::build_native_softplc`); `None` when no partition
/// asks for it. A program the translator refuses stops the build.
pub fn native_programs(
    system: &System,
    packages: &[(String, Vec<u8>)],
) -> Result<Option<std::path::PathBuf>> {
    native_programs_in(
        system,
        packages,
        &crate::target_dir().join("plc-native").join("programs"),
    )
}

/// [`native_programs`], written under `dir`.
fn native_programs_in(
    system: &System,
    packages: &[(String, Vec<u8>)],
    dir: &std::path::Path,
) -> Result<Option<std::path::PathBuf>> {
    let mut modules: Vec<(String, String)> = Vec::new();
    let mut seen: Vec<Vec<u8>> = Vec::new();
    for p in &system.partitions {
        if !p.plc.as_ref().is_some_and(|plc| plc.native) {
            continue;
        }
        if p.image != SOFTPLC_IMAGE {
            bail!(
                "partition {}: plc.native needs the soft-PLC image (image = \"{SOFTPLC_IMAGE}\"), not {:?}",
                p.name,
                p.image
            );
        }
        let bytes = packages
            .iter()
            .find(|(name, _)| *name == p.name)
            .map(|(_, bytes)| bytes)
            .with_context(|| format!("partition {}: no PLC package", p.name))?;
        let program = package::Package::parse(bytes)
            .map_err(|e| anyhow::anyhow!("partition {}: {e}", p.name))?
            .program()
            .to_vec();
        if seen.contains(&program) {
            continue;
        }
        let module = plc_native::module_name(&p.name);
        let image_file = dir.join(format!("{module}.plcb"));
        plc_native::harness::write_file(&image_file, &program).map_err(anyhow::Error::msg)?;
        let source = plc_native::ImageSource::File(image_file.display().to_string());
        let code = plc_native::translate_with(&program, &source).map_err(|e| {
            anyhow::anyhow!(
                "partition {}: plc.native: the native tier cannot run its program: {e} (remove plc.native to run it on the interpreter)",
                p.name
            )
        })?;
        eprintln!(
            "xtask: partition {}: program translated for the native tier (image {:016x}, {} bytes, {} KiB of Rust)",
            p.name,
            plc_vm::native::image_hash(&program),
            program.len(),
            code.len() / 1024
        );
        modules.push((module, code));
        seen.push(program);
    }
    if modules.is_empty() {
        return Ok(None);
    }
    let file = dir.join("programs.rs");
    plc_native::harness::write_file(&file, plc_native::bundle(&modules).as_bytes())
        .map_err(anyhow::Error::msg)?;
    Ok(Some(file))
}

/// The safe values of the outputs: those the program's `{attribute 'safe'}` pragmas give,
/// replaced or completed by the configuration's `plc.safe` (the system integrator's word
/// wins).
fn merge_safe_values(
    pragmas: &[plc_compiler::SafeOutput],
    configured: Vec<package::SafeValue>,
) -> Vec<package::SafeValue> {
    let mut safe: Vec<package::SafeValue> = pragmas
        .iter()
        .filter(|s| !configured.iter().any(|c| c.address == s.address))
        .map(|s| package::SafeValue {
            address: s.address,
            width: s.width,
            value: s.value,
        })
        .collect();
    safe.extend(configured);
    safe
}

/// The safe value of `%Q` variable `name`: it must be a located output of the program and
/// the value must fit its type (a boolean for BOOL, an integer in range for the integer and
/// bit-string types, a number for REAL/LREAL).
fn safe_value(image: &Image, name: &str, value: PlcValue) -> Result<package::SafeValue, String> {
    let var = image
        .find_var(name)
        .ok_or_else(|| format!("`{name}` is not a variable of the program"))?;
    let located = image
        .located_vars()
        .find(|l| l.address == var.addr && l.location.area == plc_vm::located::Area::Output)
        .ok_or_else(|| format!("`{name}` is not a located output (%Q) variable"))?;
    let width = located.location.width.bytes() as u8;
    let ty = VarType::from_code(var.ty).ok_or_else(|| format!("`{name}` has no plain type"))?;
    let bad = || format!("{value:?} does not fit `{name}`, a {}", ty.name());
    let bits = match (ty, value) {
        (VarType::Bool, PlcValue::Bool(b)) => b as u64,
        (VarType::Real, PlcValue::Float(f)) => (f64::from_bits(f) as f32).to_bits() as u64,
        (VarType::Real, PlcValue::Int(i)) => (i as f32).to_bits() as u64,
        (VarType::LReal, PlcValue::Float(f)) => f,
        (VarType::LReal, PlcValue::Int(i)) => (i as f64).to_bits(),
        (VarType::Bool | VarType::Real | VarType::LReal, _) => return Err(bad()),
        (ty, _) if ty.mem_type().is_none() => return Err(bad()),
        (_, PlcValue::Int(i)) => {
            // The date/time types are signed nanoseconds.
            let signed = ty.is_signed_int() || ty.time_kind().is_some();
            let bits = u32::from(width) * 8;
            let fits = if bits == 64 {
                signed || i >= 0
            } else if signed {
                (-(1i64 << (bits - 1))..(1i64 << (bits - 1))).contains(&i)
            } else {
                (0..(1i64 << bits)).contains(&i)
            };
            if !fits {
                return Err(bad());
            }
            if bits == 64 {
                i as u64
            } else {
                (i as u64) & ((1u64 << bits) - 1)
            }
        }
        _ => return Err(bad()),
    };
    Ok(package::SafeValue {
        address: var.addr,
        width,
        value: bits,
    })
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
/// frame of each schedule that gives it windows, on its CPU): the task processes are
/// released at window starts.
fn check_tasks(system: &System, index: usize, p: &Partition, image: &[u8]) -> Result<()> {
    let image = plc_vm::image::Image::parse(image)
        .map_err(|e| anyhow::anyhow!("partition {}: {e}", p.name))?;
    let own = &system.partitions[index];
    for schedule in &system.schedules {
        let has_window = schedule
            .windows
            .iter()
            .any(|w| w.time_partition == own.time_partition && w.cpu == own.cpu);
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

/// What is wrong with a publication's or subscription's variable, for the build's error.
fn pubsub_error(e: &softplc::pubsub::PubSubError<'_>) -> String {
    use softplc::pubsub::PubSubError;
    match e {
        PubSubError::Unknown(name) => format!("`{name}` is no variable of the program"),
        PubSubError::Type(name) => format!(
            "`{name}` has a type the FBDK encoding does not carry, or is the validity variable and no BOOL"
        ),
        PubSubError::Message(e) => format!("{e:?}"),
        PubSubError::TooLong => "too long for one datagram".to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scenario plc_shared's description, with `edit` applied, written next to its ST files.
    fn shared_system(edit: (&str, &str)) -> Result<System> {
        let configs = crate::workspace_root().join("tests/configs");
        let text = std::fs::read_to_string(configs.join("plc_shared.toml"))?;
        assert!(text.contains(edit.0), "test bug: {edit:?}");
        let text = text.replacen(edit.0, edit.1, 1);
        // Only the name is used (program paths are relative to its directory).
        let path = configs.join("plc_shared_edited.toml");
        config::load(&path.to_string_lossy(), &text, &|_| true).map_err(|d| {
            anyhow::anyhow!(
                "{}",
                d.iter()
                    .map(|d| d.to_string())
                    .collect::<Vec<_>>()
                    .join("\n")
            )
        })
    }

    /// Scenario plc_native's description: three partitions with `plc.native`.
    #[test]
    fn native_partitions_get_translated_programs_and_the_flag() {
        let configs = crate::workspace_root().join("tests/configs");
        let path = configs.join("plc_native.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let mut system = config::load(&path.to_string_lossy(), &text, &|_| true).unwrap();
        let packages = data_entries(&system).unwrap();
        for (name, bytes) in &packages {
            let native = package::Package::parse(bytes).unwrap().native();
            assert_eq!(
                native,
                ["plc", "trap", "loop"].contains(&name.as_str()),
                "{name}"
            );
        }
        let dir = crate::target_dir().join("tmp/xtask-native-programs");
        let file = native_programs_in(&system, &packages, &dir)
            .unwrap()
            .expect("three native partitions");
        let programs = std::fs::read_to_string(&file).unwrap();
        for module in ["program_plc", "program_trap", "program_loop"] {
            assert!(
                programs.contains(&format!("pub mod {module} {{")),
                "{module}"
            );
            assert!(dir.join(format!("{module}.plcb")).is_file());
        }
        assert!(programs.contains(
            "PROGRAMS: &[&plc_vm::native::NativeProgram] = &[&program_plc::PROGRAM, &program_trap::PROGRAM, &program_loop::PROGRAM];"
        ));
        // Without plc.native: nothing to build; on another image: a clear error.
        let plain: Vec<_> = packages.clone();
        for p in &mut system.partitions {
            if let Some(plc) = &mut p.plc {
                plc.native = false;
            }
        }
        assert!(native_programs_in(&system, &plain, &dir).unwrap().is_none());
        let p = system
            .partitions
            .iter_mut()
            .find(|p| p.name == "trap")
            .unwrap();
        p.plc.as_mut().unwrap().native = true;
        p.image = "other".into();
        let e = native_programs_in(&system, &plain, &dir).unwrap_err();
        assert!(
            e.to_string()
                .contains("plc.native needs the soft-PLC image"),
            "{e}"
        );
    }

    #[test]
    fn shared_globals_pair_across_the_packages_of_a_segment() {
        let system = shared_system(("", "")).unwrap();
        let packages = data_entries(&system).unwrap();
        let layout = |name: &str| {
            let (_, bytes) = packages.iter().find(|(n, _)| n == name).unwrap();
            let package = package::Package::parse(bytes).unwrap();
            let image = Image::parse(package.program()).unwrap();
            let shared = package.shared().unwrap();
            softplc::shared::check(&shared, &image).unwrap();
            let names: Vec<(String, package::SharedVar)> = image
                .shared_vars()
                .filter(|s| s.direction != plc_vm::image::SharedDirection::Valid)
                .map(|s| {
                    let mut records = match s.direction {
                        plc_vm::image::SharedDirection::Write => shared.written(),
                        _ => shared.read(),
                    };
                    let record = records.find(|v| v.address == s.var.addr).unwrap();
                    (s.var.name.to_string(), record)
                })
                .collect();
            let flag = image
                .shared_vars()
                .find(|s| s.direction == plc_vm::image::SharedDirection::Valid)
                .map(|s| s.var.addr);
            assert_eq!(shared.valid_flag, flag, "{name}");
            (shared.segment_address, shared.own, shared.other, names)
        };
        let (writer_at, writer_own, writer_other, written) = layout("writer");
        let (reader_at, reader_own, reader_other, read) = layout("reader");
        // The segment's address is where syssw maps the first segment.
        assert_eq!(
            (writer_at, reader_at),
            (protocol::layout::SHARED_BASE, protocol::layout::SHARED_BASE)
        );
        // seq u32 at 8, a i32 at 12, level f64 at 16, small u16 at 24, odd at 26, check at 28.
        assert_eq!((writer_own, writer_other), (Some((0, 32)), None));
        assert_eq!((reader_own, reader_other), (None, Some((0, 32))));
        let offsets = |vars: &[(String, package::SharedVar)]| {
            let mut v: Vec<(String, u32, u32)> = vars
                .iter()
                .map(|(n, r)| (n.clone(), r.offset, r.size))
                .collect();
            v.sort();
            v
        };
        assert_eq!(offsets(&written), offsets(&read));
        assert_eq!(
            offsets(&written)
                .iter()
                .map(|(_, o, _)| *o)
                .collect::<Vec<_>>(),
            [12, 28, 16, 26, 8, 24]
        );
    }

    #[test]
    fn shared_globals_without_a_segment_are_a_build_error() {
        let system = shared_system((
            "plc.program = [\"plc/shared_reader.st\"]\nplc.shared = \"link\"",
            "plc.program = [\"plc/shared_reader.st\"]",
        ))
        .unwrap();
        let e = data_entries(&system).unwrap_err().to_string();
        assert!(
            e.contains("plc/shared_reader.st:7:3: partition reader's program shares `seq`")
                && e.contains("names no segment"),
            "{e}"
        );
    }

    fn image_of(source: &str) -> Vec<u8> {
        let files = [("t.st".to_string(), source.to_string())];
        plc_compiler::compile(&files, &plc_compiler::Options::default())
            .map(|(c, _)| c.image)
            .unwrap_or_else(|_| panic!("does not compile"))
    }

    #[test]
    fn pragma_safe_values_yield_to_the_configuration() {
        let files = [(
            "t.st".to_string(),
            "VAR_GLOBAL
               {attribute 'safe' := '0.25'} v AT %QL0 : LREAL;
               {attribute 'safe' := 'TRUE'} b AT %QX8.0 : BOOL;
             END_VAR
             PROGRAM P VAR {attribute 'safe' := '-1'} s AT %QB9 : SINT; END_VAR s := 1; END_PROGRAM"
                .to_string(),
        )];
        let (compiled, _) = plc_compiler::compile(&files, &plc_compiler::Options::default())
            .unwrap_or_else(|_| panic!("does not compile"));
        let names: Vec<(&str, u8, u64)> = compiled
            .safe
            .iter()
            .map(|s| (s.name.as_str(), s.width, s.value))
            .collect();
        assert_eq!(
            names,
            [("v", 8, 0.25f64.to_bits()), ("b", 1, 1), ("P.s", 1, 0xff)]
        );
        let image = Image::parse(&compiled.image).unwrap();
        let configured = vec![safe_value(&image, "b", PlcValue::Bool(false)).unwrap()];
        let merged = merge_safe_values(&compiled.safe, configured);
        let values: Vec<(u32, u64)> = merged.iter().map(|s| (s.address, s.value)).collect();
        let address = |name: &str| {
            compiled
                .safe
                .iter()
                .find(|s| s.name == name)
                .unwrap()
                .address
        };
        assert_eq!(
            values,
            [
                (address("v"), 0.25f64.to_bits()),
                (address("P.s"), 0xff),
                (address("b"), 0)
            ]
        );
    }

    #[test]
    fn safe_values_fit_their_variables() {
        let bytes = image_of(
            "VAR_GLOBAL v AT %QL0 : LREAL; b AT %QX8.0 : BOOL; s AT %QB9 : SINT; plain : INT; END_VAR
             PROGRAM P plain := 1; END_PROGRAM",
        );
        let image = Image::parse(&bytes).unwrap();
        let v = safe_value(&image, "v", PlcValue::Float(0.5f64.to_bits())).unwrap();
        assert_eq!((v.width, v.value), (8, 0.5f64.to_bits()));
        assert_eq!(
            safe_value(&image, "b", PlcValue::Bool(true)).unwrap().value,
            1
        );
        assert_eq!(
            safe_value(&image, "s", PlcValue::Int(-1)).unwrap().value,
            0xff
        );
        for (name, value, why) in [
            ("s", PlcValue::Int(200), "does not fit"),
            ("b", PlcValue::Int(1), "does not fit"),
            ("plain", PlcValue::Int(0), "not a located output"),
            ("nope", PlcValue::Int(0), "not a variable"),
        ] {
            let e = safe_value(&image, name, value).unwrap_err();
            assert!(e.contains(why), "{name}: {e}");
        }
    }
}
