//! A device: its resources, the requests carried out on them, watches, and the boot file.

use crate::fboot;
use crate::literal;
use crate::request::{Action, Object, Reason, Request, escape, response};
use crate::sifb;
use crate::types::{self, Report, SharedReport};
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use core::cell::Ref;
use iec61499_runtime::fb::Restart;
use iec61499_runtime::package::{self, PackageError, TypePackage};
use iec61499_runtime::resource::DeployError;
use iec61499_runtime::{Limits, Resource, stdlib};

/// The resource type of FORTE's embedded resource: a resource with an E_RESTART named START.
pub const EMB_RES: &str = "EMB_RES";

struct Res {
    name: String,
    resource: Resource,
    running: bool,
    /// Each instance's type name.
    types: Vec<(String, String)>,
    /// Watched ports (`FB.PORT`), in creation order.
    watches: Vec<String>,
}

/// An IEC 61499 device.
pub struct Device {
    limits: Limits,
    /// Basic FB types added at run time ([`Device::add_type`]), by name.
    types: Vec<TypePackage>,
    max_resources: usize,
    resources: Vec<Res>,
    report: SharedReport,
    /// A type package arriving in parts: its name and the bytes so far.
    staged: Option<(String, Vec<u8>)>,
    /// The partition's ports, for the process-image FBs ([`crate::sifb`]).
    io: sifb::Io,
}

/// The largest type package a device takes.
pub const MAX_TYPE_PACKAGE: usize = 256 * 1024;

fn deploy_reason(e: &DeployError) -> Reason {
    match e {
        DeployError::Duplicate(_) => Reason::InvalidState,
        DeployError::NotFound(_) => Reason::NoSuchObject,
        DeployError::Mismatch(_) => Reason::InvalidOperation,
        DeployError::Limit(_) => Reason::Overflow,
        DeployError::Connected(_) => Reason::InvalidOperation,
        DeployError::Faulted(_) => Reason::InvalidState,
    }
}

impl Device {
    /// A device of at most `max_resources` resources, each with `limits`.
    pub fn new(limits: Limits, max_resources: usize) -> Self {
        Device {
            limits,
            types: Vec::new(),
            max_resources,
            resources: Vec::new(),
            report: SharedReport::default(),
            staged: None,
            io: sifb::share(alloc::boxed::Box::new(sifb::NoPorts)),
        }
    }

    /// The ports the process-image FBs created from now on use (a new device has none).
    pub fn set_io(&mut self, io: alloc::boxed::Box<dyn sifb::ProcessIo>) {
        self.io = sifb::share(io);
    }

    /// What the test FBs reported.
    pub fn report(&self) -> Ref<'_, Report> {
        self.report.borrow()
    }

    /// Takes the log lines written since the last call (test FBs, faults).
    pub fn take_log(&mut self) -> Vec<String> {
        core::mem::take(&mut self.report.borrow_mut().log)
    }

    /// Carries out the request `text` addressed to `destination` (empty: the device) at
    /// instant `now` and returns the response.
    pub fn execute(&mut self, destination: &str, text: &str, now: i64) -> String {
        let request = match Request::parse(text) {
            Ok(r) => r,
            Err((id, reason)) => return response(&id, Some(reason), None),
        };
        let (reason, body) = if destination.is_empty() {
            (self.device_request(&request, now), None)
        } else {
            match self.resource_request(destination, &request, now) {
                Ok(body) => (None, body),
                Err(reason) => (Some(reason), None),
            }
        };
        self.note_faults();
        response(&request.id, reason, body.as_deref())
    }

    /// A part of a type package ([`Object::FbType`]): parts come in order, the first at
    /// offset 0 (which drops any unfinished package); the last one adds the type, or
    /// refuses it whole with its reason logged, the types in use staying as they were.
    fn type_part(&mut self, name: &str, offset: usize, size: usize, data: &[u8]) -> Option<Reason> {
        if size > MAX_TYPE_PACKAGE {
            return Some(Reason::Overflow);
        }
        if offset == 0 {
            self.staged = Some((name.into(), Vec::new()));
        }
        let fits = offset
            .checked_add(data.len())
            .is_some_and(|end| end <= size);
        let Some((_, bytes)) = self
            .staged
            .as_mut()
            .filter(|(n, b)| n == name && b.len() == offset && fits)
        else {
            self.staged = None;
            return Some(Reason::InvalidState);
        };
        bytes.extend_from_slice(data);
        if bytes.len() < size {
            return None;
        }
        let Some((_, bytes)) = self.staged.take() else {
            return Some(Reason::InvalidState);
        };
        let checked = package::decode(&bytes).and_then(|p| {
            if p.name == name {
                self.install(p)
            } else {
                Err(PackageError::Rejected(format!(
                    "the package holds type {}",
                    p.name
                )))
            }
        });
        let line = match checked {
            Ok(_) => {
                self.report
                    .borrow_mut()
                    .log
                    .push(format!("type {name} added: {} bytes, checked", bytes.len()));
                return None;
            }
            Err(e) => format!("type {name} refused: {e}"),
        };
        self.report.borrow_mut().log.push(line);
        Some(Reason::InvalidObject)
    }

    fn device_request(&mut self, request: &Request, now: i64) -> Option<Reason> {
        match (&request.action, &request.object) {
            (
                Action::Create,
                Object::FbType {
                    name,
                    offset,
                    size,
                    data,
                },
            ) => self.type_part(name, *offset, *size, data),
            (Action::Create, Object::Fb { name, ty }) => {
                if ty != EMB_RES {
                    return Some(Reason::UnsupportedType);
                }
                if self.resources.iter().any(|r| r.name == *name) {
                    return Some(Reason::InvalidState);
                }
                if self.resources.len() >= self.max_resources {
                    return Some(Reason::Overflow);
                }
                let mut resource = Resource::new(self.limits);
                let start = stdlib::create("E_RESTART")?;
                if resource.create("START", start).is_err() {
                    return Some(Reason::Overflow);
                }
                self.resources.push(Res {
                    name: name.clone(),
                    resource,
                    running: false,
                    types: alloc::vec![("START".into(), "E_RESTART".into())],
                    watches: Vec::new(),
                });
                None
            }
            (Action::Delete, Object::Fb { name, .. }) => {
                let before = self.resources.len();
                self.resources.retain(|r| r.name != *name || r.running);
                if before == self.resources.len() {
                    return Some(if self.resources.iter().any(|r| r.name == *name) {
                        Reason::InvalidState
                    } else {
                        Reason::NoSuchObject
                    });
                }
                None
            }
            (Action::Start, Object::None) => {
                for i in 0..self.resources.len() {
                    self.start(i, now);
                }
                None
            }
            (Action::Stop | Action::Kill, Object::None) => {
                for i in 0..self.resources.len() {
                    self.stop(i, request.action == Action::Stop, now);
                }
                None
            }
            _ => Some(Reason::UnsupportedCmd),
        }
    }

    fn start(&mut self, index: usize, now: i64) {
        let r = &mut self.resources[index];
        if !r.running {
            r.running = true;
            let _ = r.resource.restart(Restart::Cold, now);
        }
    }

    fn stop(&mut self, index: usize, with_event: bool, now: i64) {
        let r = &mut self.resources[index];
        if r.running {
            if with_event {
                let _ = r.resource.restart(Restart::Stop, now);
            }
            r.running = false;
        }
    }

    fn resource_request(
        &mut self,
        destination: &str,
        request: &Request,
        now: i64,
    ) -> Result<Option<String>, Reason> {
        let index = self
            .resources
            .iter()
            .position(|r| r.name == destination)
            .ok_or(Reason::InvalidDst)?;
        let report = self.report.clone();
        let io = self.io.clone();
        let r = &mut self.resources[index];
        let deploy = |e: DeployError| deploy_reason(&e);
        match (request.action, &request.object) {
            (Action::Create, Object::Fb { name, ty }) => {
                let added = self
                    .types
                    .iter()
                    .find(|t| t.name == *ty)
                    .map(TypePackage::instantiate);
                let r = &mut self.resources[index];
                let fb = added
                    .or_else(|| types::create(ty, destination, name, &report))
                    .or_else(|| sifb::create(ty, &io))
                    .ok_or(Reason::UnsupportedType)?;
                r.resource.create(name, fb).map_err(deploy)?;
                r.types.push((name.clone(), ty.clone()));
            }
            (
                Action::Create,
                Object::Connection {
                    source,
                    destination,
                    ..
                },
            ) => {
                // An event connection, else (its ports are no events) a data connection.
                match r.resource.connect_event(source, destination) {
                    Ok(()) => {}
                    Err(DeployError::NotFound(_)) => r
                        .resource
                        .connect_data(source, destination)
                        .map_err(deploy)?,
                    Err(other) => return Err(deploy(other)),
                }
            }
            (Action::Create, Object::Watch { source, .. }) => {
                r.resource.read(source).ok_or(Reason::NoSuchObject)?;
                if !r.watches.contains(source) {
                    r.watches.push(source.clone());
                }
            }
            (Action::Delete, Object::Fb { name, .. }) => {
                if r.running {
                    return Err(Reason::InvalidState);
                }
                r.resource.delete(name).map_err(deploy)?;
                r.types.retain(|(n, _)| n != name);
                r.watches
                    .retain(|w| w.split('.').next() != Some(name.as_str()));
            }
            (
                Action::Delete,
                Object::Connection {
                    source,
                    destination,
                    ..
                },
            ) => {
                if r.resource.disconnect_event(source, destination).is_err() {
                    r.resource
                        .disconnect_data(source, destination)
                        .map_err(deploy)?;
                }
            }
            (Action::Delete, Object::Watch { source, .. }) => {
                let before = r.watches.len();
                r.watches.retain(|w| w != source);
                if before == r.watches.len() {
                    return Err(Reason::NoSuchObject);
                }
            }
            (
                Action::Write,
                Object::Connection {
                    source,
                    destination,
                    force,
                },
            ) => {
                if source.eq_ignore_ascii_case("$e") {
                    if !r.running {
                        return Err(Reason::InvalidState);
                    }
                    r.resource.trigger(destination, now).map_err(deploy)?;
                    return Ok(None);
                }
                if *force == Some(false) {
                    r.resource.unforce(destination).map_err(deploy)?;
                    return Ok(None);
                }
                let spec = port_spec(&r.resource, destination).ok_or(Reason::NoSuchObject)?;
                let value = literal::parse(source, &spec).map_err(|_| Reason::InvalidObject)?;
                if *force == Some(true) {
                    r.resource.force(destination, value).map_err(deploy)?;
                } else {
                    r.resource.write(destination, value).map_err(deploy)?;
                }
            }
            (Action::Read, Object::Watch { .. }) => return Ok(Some(self.watches())),
            (
                Action::Read,
                Object::Connection {
                    source,
                    destination,
                    ..
                },
            ) => {
                let value = r.resource.read(source).ok_or(Reason::NoSuchObject)?;
                return Ok(Some(format!(
                    "<Connection Source=\"{}\" Destination=\"{}\" />",
                    escape(&literal::show(value)),
                    escape(destination)
                )));
            }
            (Action::Query, Object::Fb { .. }) => {
                let list: Vec<String> = r
                    .types
                    .iter()
                    .map(|(n, t)| format!("<FB Name=\"{}\" Type=\"{}\" />", escape(n), escape(t)))
                    .collect();
                return Ok(Some(format!(
                    "<FBList>\n    {}\n  </FBList>",
                    list.join("\n    ")
                )));
            }
            (Action::Start, Object::None) => self.start(index, now),
            (Action::Stop | Action::Kill, Object::None) => {
                self.stop(index, request.action == Action::Stop, now)
            }
            (Action::Reset, Object::None) => {
                if r.running {
                    return Err(Reason::InvalidState);
                }
                r.resource.reset();
            }
            _ => return Err(Reason::UnsupportedCmd),
        }
        Ok(None)
    }

    /// Every watched port's value, as READ of the watches answers.
    /// Every watched port as `RESOURCE.FB.PORT` and its value as an IEC literal (`?` for a
    /// port that is gone), in creation order.
    pub fn watched(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for r in &self.resources {
            for w in &r.watches {
                let value = r.resource.read(w).map_or(String::from("?"), literal::show);
                out.push((format!("{}.{w}", r.name), value));
            }
        }
        out
    }

    fn watches(&self) -> String {
        let mut out = String::from("<Watches>");
        for r in self.resources.iter().filter(|r| !r.watches.is_empty()) {
            out.push_str(&format!("<Resource name=\"{}\">", escape(&r.name)));
            let mut fbs: Vec<&str> = Vec::new();
            for w in &r.watches {
                let fb = w.split('.').next().unwrap_or("");
                if !fbs.contains(&fb) {
                    fbs.push(fb);
                }
            }
            for fb in fbs {
                out.push_str(&format!("<FB name=\"{}\">", escape(fb)));
                for w in r.watches.iter().filter(|w| w.split('.').next() == Some(fb)) {
                    let port = w.split_once('.').map_or("", |(_, p)| p);
                    let value = r.resource.read(w).map_or(String::from("?"), literal::show);
                    out.push_str(&format!(
                        "<Port name=\"{}\"><Data value=\"{}\" forced=\"{}\"/></Port>",
                        escape(port),
                        escape(&value),
                        r.resource.is_forced(w)
                    ));
                }
                out.push_str("</FB>");
            }
            out.push_str("</Resource>");
        }
        out.push_str("</Watches>");
        out
    }

    /// Logs each resource's new fault once.
    fn note_faults(&mut self) {
        for r in &mut self.resources {
            if let Some(fault) = r.resource.fault()
                && r.running
            {
                let line = format!("resource {} stopped: {fault}", r.name);
                let mut report = self.report.borrow_mut();
                report.log.push(line);
                report.faults += 1;
                r.running = false;
            }
        }
    }

    /// Adds (or replaces) a basic FB type from its package (compiled outside the real-time
    /// partition; checked whole here: structure, ECC, bytecode verification). New instances
    /// of the name are of this type; existing ones keep theirs. Returns the type's name.
    pub fn add_type(&mut self, bytes: &[u8]) -> Result<String, PackageError> {
        self.install(package::decode(bytes)?)
    }

    /// Adds (or replaces) a decoded, checked type.
    fn install(&mut self, package: TypePackage) -> Result<String, PackageError> {
        let name = package.name.clone();
        if stdlib::create(&name).is_some() {
            return Err(PackageError::Rejected(format!(
                "{name} is a standard type and cannot be replaced"
            )));
        }
        self.types.retain(|t| t.name != name);
        self.types.push(package);
        Ok(name)
    }

    /// The earliest timer of a running resource.
    pub fn next_deadline(&self) -> Option<i64> {
        self.resources
            .iter()
            .filter(|r| r.running)
            .filter_map(|r| r.resource.next_deadline())
            .min()
    }

    /// Fires the due timers of every running resource.
    pub fn advance(&mut self, now: i64) {
        for r in self.resources.iter_mut().filter(|r| r.running) {
            let _ = r.resource.advance(now);
        }
        self.note_faults();
    }

    /// Carries out a boot file at `now`; stops at the first refused request, with the
    /// line, the request and the reason.
    pub fn boot(&mut self, text: &str, now: i64) -> Result<usize, String> {
        let lines = fboot::lines(text)?;
        for line in &lines {
            let answer = self.execute(line.destination, line.request, now);
            if answer.contains("Reason=\"") {
                return Err(format!(
                    "boot file line {}: {} refused: {answer}",
                    line.number, line.request
                ));
            }
        }
        Ok(lines.len())
    }
}

/// The declaration of `FB.PORT` (an input, else an output).
fn port_spec(resource: &Resource, path: &str) -> Option<iec61499_runtime::VarSpec> {
    let (fb, port) = path.split_once('.')?;
    let (_, interface) = resource.instances().find(|(n, _)| *n == fb)?;
    interface
        .inputs
        .iter()
        .chain(&interface.outputs)
        .find(|v| v.name == port)
        .cloned()
}

#[cfg(test)]
mod tests;
