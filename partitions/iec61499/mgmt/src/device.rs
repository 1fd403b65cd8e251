//! A device: its resources, the requests carried out on them, watches, and the boot file.

use crate::fboot;
use crate::flat::{Composites, Flat, FlatPort, PortKind, within};
use crate::literal;
use crate::request::{Action, Object, Reason, Request, escape, response};
use crate::sifb;
use crate::types::{self, Report, SharedReport};
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use core::cell::Ref;
use iec61499_runtime::composite::{self, CompositeType};
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
    /// The composite instances, flattened ([`crate::flat`]).
    composites: Composites,
}

impl Res {
    /// Whether an instance or composite instance named `name` exists.
    fn has(&self, name: &str) -> bool {
        self.composites.contains(name) || self.resource.instances().any(|(n, _)| n == name)
    }

    /// Deletes instance `name`, or composite instance `name` with all its components.
    fn delete_tree(&mut self, name: &str) -> Result<(), DeployError> {
        self.composites.forget_adapters(name);
        if !self.composites.contains(name) {
            return self.resource.delete(name);
        }
        let inside: Vec<String> = self
            .resource
            .instances()
            .map(|(n, _)| String::from(n))
            .filter(|n| within(n, name))
            .collect();
        for n in inside {
            self.resource.delete(&n)?;
        }
        self.composites.remove_tree(name);
        Ok(())
    }

    /// The value of `FB.PORT` (through a composite's port).
    fn read(&self, path: &str) -> Option<&iec61499_runtime::Value> {
        self.resource.read(&self.composites.data_port(path)?)
    }

    /// The ports `path` stands for as a data input, else as a data output (what a force
    /// is about).
    fn data_ends(&self, path: &str) -> Result<Vec<String>, DeployError> {
        self.composites
            .resolve(path, PortKind::DataIn)
            .filter(|ends| !ends.is_empty())
            .or_else(|| self.composites.resolve(path, PortKind::DataOut))
            .ok_or_else(|| DeployError::NotFound(path.into()))
    }

    /// Writes the literal `text` to input `to` (through a composite's port), as a
    /// parameter or, with `force`, as a force.
    fn write_literal(&mut self, text: &str, to: &str, force: bool) -> Result<(), Reason> {
        let ends = if force {
            self.data_ends(to).map_err(|e| deploy_reason(&e))?
        } else {
            self.composites
                .resolve(to, PortKind::DataIn)
                .ok_or(Reason::NoSuchObject)?
        };
        for end in ends {
            if self.resource.is_unbound(&end) {
                // A generic port takes the type the literal names.
                let ty = literal::type_of(text).ok_or(Reason::InvalidObject)?;
                self.resource
                    .bind(&end, ty)
                    .map_err(|e| deploy_reason(&e))?;
            }
            let spec = port_spec(&self.resource, &end).ok_or(Reason::NoSuchObject)?;
            let value = literal::parse(text, &spec).map_err(|_| Reason::InvalidObject)?;
            let done = if force {
                self.resource.force(&end, value)
            } else {
                self.resource.write(&end, value)
            };
            done.map_err(|e| deploy_reason(&e))?;
        }
        Ok(())
    }
}

/// How deep composites may nest (a composite that contains itself stops here).
pub const MAX_NESTING: usize = 8;

/// An IEC 61499 device.
pub struct Device {
    limits: Limits,
    /// Basic FB types added at run time ([`Device::add_type`]), by name.
    types: Vec<TypePackage>,
    /// Composite FB types added the same way.
    composites: Vec<CompositeType>,
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
            composites: Vec::new(),
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
        match Request::parse(text) {
            Ok(request) => self.carry_out(destination, &request, now),
            Err((id, reason)) => response(&id, Some(reason), None),
        }
    }

    /// [`Device::execute`] of a request already read.
    pub fn carry_out(&mut self, destination: &str, request: &Request, now: i64) -> String {
        let (reason, body) = if destination.is_empty() {
            (self.device_request(request, now), None)
        } else {
            match self.resource_request(destination, request, now) {
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
        let checked = self.install_bytes(&bytes, Some(name));
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
                    composites: Composites::default(),
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
        let r = &mut self.resources[index];
        let deploy = |e: DeployError| deploy_reason(&e);
        match (request.action, &request.object) {
            (Action::Create, Object::Fb { name, ty }) => {
                if name.contains('.') {
                    return Err(Reason::InvalidObject);
                }
                self.create_instance(index, name, ty, 0)?;
                self.resources[index].types.push((name.clone(), ty.clone()));
            }
            (
                Action::Create,
                Object::Connection {
                    source,
                    destination,
                    ..
                },
            ) => r
                .composites
                .connect(&mut r.resource, source, destination)
                .map_err(deploy)?,
            (Action::Create, Object::Watch { source, .. }) => {
                r.read(source).ok_or(Reason::NoSuchObject)?;
                if !r.watches.contains(source) {
                    r.watches.push(source.clone());
                }
            }
            (Action::Delete, Object::Fb { name, .. }) => {
                if r.running {
                    return Err(Reason::InvalidState);
                }
                r.delete_tree(name).map_err(deploy)?;
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
            ) => r
                .composites
                .disconnect(&mut r.resource, source, destination)
                .map_err(deploy)?,
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
                    let ends = r
                        .composites
                        .resolve(destination, PortKind::EventIn)
                        .ok_or(Reason::NoSuchObject)?;
                    for end in ends {
                        r.resource.trigger(&end, now).map_err(deploy)?;
                    }
                    return Ok(None);
                }
                if *force == Some(false) {
                    for end in r.data_ends(destination).map_err(deploy)? {
                        r.resource.unforce(&end).map_err(deploy)?;
                    }
                    return Ok(None);
                }
                r.write_literal(source, destination, *force == Some(true))?;
            }
            (Action::Read, Object::Watch { .. }) => return Ok(Some(self.watches())),
            (Action::Read, Object::Connection { source, .. }) => {
                // As FORTE's DEV_MGR answers: the port as the source, its value as the
                // destination.
                let value = r.read(source).ok_or(Reason::NoSuchObject)?;
                return Ok(Some(format!(
                    "<Connection Source=\"{}\" Destination=\"{}\" />",
                    escape(source),
                    escape(&literal::show(value))
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
                let value = r.read(w).map_or(String::from("?"), literal::show);
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
                    let value = r.read(w).map_or(String::from("?"), literal::show);
                    let forced = r
                        .composites
                        .data_port(w)
                        .is_some_and(|p| r.resource.is_forced(&p));
                    out.push_str(&format!(
                        "<Port name=\"{}\"><Data value=\"{}\" forced=\"{}\"/></Port>",
                        escape(port),
                        escape(&value),
                        forced
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
    /// A composite type's package ([`iec61499_runtime::composite`]) is checked for its
    /// structure here and for its components when an instance is created.
    pub fn add_type(&mut self, bytes: &[u8]) -> Result<String, PackageError> {
        self.install_bytes(bytes, None)
    }

    /// Decodes, checks and adds (or replaces) a basic or composite type; with `expected`,
    /// only a type of that name.
    fn install_bytes(
        &mut self,
        bytes: &[u8],
        expected: Option<&str>,
    ) -> Result<String, PackageError> {
        let (name, kind) = if bytes.starts_with(composite::MAGIC) {
            let t = CompositeType::decode(bytes)?;
            (t.name.clone(), Err(t))
        } else {
            let p = package::decode(bytes)?;
            (p.name.clone(), Ok(p))
        };
        if let Some(expected) = expected
            && name != expected
        {
            return Err(PackageError::Rejected(format!(
                "the package holds type {name}"
            )));
        }
        if stdlib::create(&name).is_some() {
            return Err(PackageError::Rejected(format!(
                "{name} is a standard type and cannot be replaced"
            )));
        }
        self.types.retain(|t| t.name != name);
        self.composites.retain(|t| t.name != name);
        match kind {
            Ok(basic) => self.types.push(basic),
            Err(composite) => self.composites.push(composite),
        }
        Ok(name)
    }

    /// Logs `line` (a refusal's details).
    fn log(&self, line: String) {
        self.report.borrow_mut().log.push(line);
    }

    /// Creates instance `name` of type `ty` in resource `index`: a composite flattened into
    /// its components ([`crate::flat`]), `depth` composites deep. A refusal inside a
    /// composite is logged with its place in the composite's `.fbt`, and leaves nothing of
    /// the instance behind.
    fn create_instance(
        &mut self,
        index: usize,
        name: &str,
        ty: &str,
        depth: usize,
    ) -> Result<(), Reason> {
        // An unknown type before a taken name, as FORTE answers.
        let composite = self.composites.iter().find(|t| t.name == ty).cloned();
        let resource = self.resources[index].name.clone();
        let fb = match composite {
            Some(_) => None,
            None => Some(
                self.types
                    .iter()
                    .find(|t| t.name == ty)
                    .map(TypePackage::instantiate)
                    .or_else(|| types::create(ty, &resource, name, &self.report, &self.io))
                    .or_else(|| sifb::create(ty, &self.io))
                    .or_else(|| crate::pubsub::create(ty, &self.io))
                    .or_else(|| crate::clientserver::create(ty, &self.io))
                    .ok_or(Reason::UnsupportedType)?,
            ),
        };
        if self.resources[index].has(name) {
            return Err(Reason::InvalidState);
        }
        if let Some(t) = composite {
            if depth >= MAX_NESTING {
                self.log(format!(
                    "{name}: composites nested more than {MAX_NESTING} deep (does {ty} contain itself?)"
                ));
                return Err(Reason::Overflow);
            }
            let ports = [
                (PortKind::EventIn, &t.event_inputs),
                (PortKind::EventOut, &t.event_outputs),
                (PortKind::DataIn, &t.inputs),
                (PortKind::DataOut, &t.outputs),
            ]
            .into_iter()
            .flat_map(|(kind, names)| {
                names.iter().map(move |n| FlatPort {
                    name: n.clone(),
                    kind,
                    ends: Vec::new(),
                })
            })
            .collect();
            self.resources[index].composites.add(Flat {
                name: name.into(),
                ports,
                adapters: t.adapters.clone(),
            });
            let built = self.flatten(index, name, &t, depth);
            if built.is_err() {
                let _ = self.resources[index].delete_tree(name);
            }
            return built;
        }
        let Some(fb) = fb else {
            return Err(Reason::UnsupportedType);
        };
        self.resources[index]
            .resource
            .create(name, fb)
            .map_err(|e| deploy_reason(&e))?;
        Ok(())
    }

    /// Creates the components of composite instance `name` of type `t`, their parameters
    /// and connections, and fills in what its ports stand for.
    fn flatten(
        &mut self,
        index: usize,
        name: &str,
        t: &CompositeType,
        depth: usize,
    ) -> Result<(), Reason> {
        for c in &t.components {
            let path = format!("{name}.{}", c.name);
            let place = t.place(c.line, c.col);
            self.create_instance(index, &path, &c.ty, depth + 1)
                .inspect_err(|reason| {
                    self.log(format!(
                        "{place}: component {} of type {} refused: {}",
                        c.name,
                        c.ty,
                        reason.name()
                    ))
                })?;
            for (input, text) in &c.parameters {
                self.resources[index]
                    .write_literal(text, &format!("{path}.{input}"), false)
                    .inspect_err(|reason| {
                        self.log(format!(
                            "{place}: parameter {}.{input} = {text} refused: {}",
                            c.name,
                            reason.name()
                        ))
                    })?;
            }
        }
        for l in &t.links {
            let place = t.place(l.line, l.col);
            let end = |e: &composite::End| {
                e.component
                    .as_ref()
                    .map(|c| format!("{name}.{c}.{}", e.port))
            };
            let (input, output) = if l.event {
                (PortKind::EventIn, PortKind::EventOut)
            } else {
                (PortKind::DataIn, PortKind::DataOut)
            };
            let r = &mut self.resources[index];
            let refused = match (end(&l.source), end(&l.destination)) {
                (None, None) => Some(String::from(
                    "a connection from the interface straight to the interface is not supported",
                )),
                (None, Some(to)) => match r.composites.resolve(&to, input) {
                    Some(ends) if ends.iter().all(|e| port_exists(&r.resource, e, input)) => {
                        if let Some(p) = r.composites.port_mut(name, &l.source.port, input) {
                            p.ends.extend(ends);
                        }
                        None
                    }
                    _ => Some(format!("no such input: {}", l.destination.port)),
                },
                (Some(from), None) => match r.composites.resolve(&from, output) {
                    Some(ends) if ends.iter().all(|e| port_exists(&r.resource, e, output)) => {
                        match r.composites.port_mut(name, &l.destination.port, output) {
                            Some(p) if !l.event && p.ends.len() + ends.len() > 1 => Some(format!(
                                "data output {} has two sources",
                                l.destination.port
                            )),
                            Some(p) => {
                                p.ends.extend(ends);
                                None
                            }
                            None => None,
                        }
                    }
                    _ => Some(format!("no such output: {}", l.source.port)),
                },
                (Some(from), Some(to)) => r
                    .composites
                    .connect(&mut r.resource, &from, &to)
                    .err()
                    .map(|e| format!("{e}")),
            };
            if let Some(why) = refused {
                self.log(format!("{place}: connection refused: {why}"));
                return Err(Reason::InvalidObject);
            }
        }
        Ok(())
    }

    /// The earliest timer of a running resource.
    pub fn next_deadline(&self) -> Option<i64> {
        self.next_deadline_of(|_| true)
    }

    /// The earliest timer of a running resource whose name `serves` accepts (a process
    /// of the partition that runs those resources' timers).
    pub fn next_deadline_of(&self, serves: impl Fn(&str) -> bool) -> Option<i64> {
        self.resources
            .iter()
            .filter(|r| r.running && serves(&r.name))
            .filter_map(|r| r.resource.next_deadline())
            .min()
    }

    /// Whether a running resource takes events from outside (a SUBSCRIBE): the partition
    /// then polls it ([`Device::poll`]) however far the next timer is.
    pub fn polls(&self) -> bool {
        self.resources
            .iter()
            .any(|r| r.running && r.resource.polls())
    }

    /// Lets the running resources take what arrived on their ports (SUBSCRIBE's messages).
    pub fn poll(&mut self, now: i64) {
        for r in self.resources.iter_mut().filter(|r| r.running) {
            let _ = r.resource.poll(now);
        }
        self.note_faults();
    }

    /// Fires the due timers of every running resource.
    pub fn advance(&mut self, now: i64) {
        self.advance_of(now, |_| true)
    }

    /// Fires the due timers of every running resource whose name `serves` accepts.
    pub fn advance_of(&mut self, now: i64, serves: impl Fn(&str) -> bool) {
        for r in self
            .resources
            .iter_mut()
            .filter(|r| r.running && serves(&r.name))
        {
            let _ = r.resource.advance(now);
        }
        self.note_faults();
    }

    /// Carries out a boot file at `now`; stops at the first refused request, with the
    /// line, the request and the reason.
    pub fn boot(&mut self, text: &str, now: i64) -> Result<usize, String> {
        let lines = fboot::lines(text)?;
        for line in &lines {
            let logged = self.report.borrow().log.len();
            let answer = self.execute(line.destination, line.request, now);
            if answer.contains("Reason=\"") {
                let details: Vec<String> = self.report.borrow().log[logged..].to_vec();
                let details = if details.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", details.join("; "))
                };
                return Err(format!(
                    "boot file line {}: {} refused: {answer}{details}",
                    line.number, line.request
                ));
            }
        }
        Ok(lines.len())
    }
}

/// Whether `FB.PORT` is a port of `kind` of an instance of `resource`.
fn port_exists(resource: &Resource, path: &str, kind: PortKind) -> bool {
    resource
        .port_interface(path)
        .is_some_and(|(i, port)| match kind {
            PortKind::EventIn => i.event_input(port).is_some(),
            PortKind::EventOut => i.event_output(port).is_some(),
            PortKind::DataIn => i.input(port).is_some(),
            PortKind::DataOut => i.output(port).is_some(),
        })
}

/// The declaration of `FB.PORT` (an input, else an output).
fn port_spec(resource: &Resource, path: &str) -> Option<iec61499_runtime::VarSpec> {
    let (interface, port) = resource.port_interface(path)?;
    interface
        .inputs
        .iter()
        .chain(&interface.outputs)
        .find(|v| v.name == port)
        .cloned()
}

#[cfg(test)]
mod tests;
