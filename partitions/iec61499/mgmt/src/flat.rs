//! Composite FB instances in a resource, flattened: a composite instance `C` is no FB of the
//! resource but its components are (`C.X`, recursively `C.Y.Z` for a nested composite), with
//! their connections; what remains of `C` is a table saying, for each port of its interface,
//! which component ports it stands for. A request naming `C.PORT` is carried out on those:
//! a connection to input event `C.REQ` connects to every component input it reaches, one
//! from output event `C.CNF` from every component output that reaches it, a parameter of
//! `C.IN` is written to every component input it feeds, a READ of `C.OUT` reads the component
//! output behind it.
//!
//! Why flattened: the components' events go through the resource's one FIFO queue like
//! any other, so the semantics of the runtime (one chain at a time, data sampled at send,
//! fan-out order, overflow as a fault) hold inside a composite unchanged, and a crossing of
//! its boundary costs nothing. Where it differs from FORTE: a component samples its data
//! inputs with its own WITH associations, not the composite's.
//!
//! Adapter connections are made here too, for instances and composite instances alike: a
//! plug's or socket's ports are ports of its FB or composite (`FB.ADAPTER.PORT`), and an
//! adapter connection is the event and data connections between them
//! ([`Composites::connect`]); the table of adapter connections keeps each plug and socket
//! to one.

use alloc::format;
use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;
use iec61499_runtime::fb::{AdapterSpec, adapter_port};
use iec61499_runtime::resource::DeployError;
use iec61499_runtime::{EventSpec, Resource, VarSpec};

/// A change of the connections of a resource between two paths.
type Link = fn(&mut Resource, &str, &str) -> Result<(), DeployError>;

/// The direction and kind of a port of a composite's interface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortKind {
    EventIn,
    EventOut,
    DataIn,
    DataOut,
}

/// A port of a composite instance and the component ports (flat paths, `C.X.PORT`) it
/// stands for: for an input its destinations, for an output its sources (a data output
/// has at most one).
#[derive(Clone, Debug)]
pub struct FlatPort {
    pub name: String,
    pub kind: PortKind,
    pub ends: Vec<String>,
}

/// A composite instance.
#[derive(Clone, Debug)]
pub struct Flat {
    /// Its full name (`C`, or `C.Y` for a nested one).
    pub name: String,
    /// Its interface's ports; those of its own plugs and sockets are `ADAPTER.PORT`.
    pub ports: Vec<FlatPort>,
    pub adapters: Vec<AdapterSpec>,
}

/// The composite instances of a resource, and its adapter connections.
#[derive(Default)]
pub struct Composites {
    flats: Vec<Flat>,
    /// `(plug, socket)` of each adapter connection, as `FB.ADAPTER` paths.
    adapter_links: Vec<(String, String)>,
}

impl Composites {
    /// Whether `name` is a composite instance.
    pub fn contains(&self, name: &str) -> bool {
        self.flats.iter().any(|c| c.name == name)
    }

    pub fn add(&mut self, flat: Flat) {
        self.flats.push(flat);
    }

    /// The component ports `path` stands for as a port of `kind`: itself when it is no
    /// composite's port, `None` when it names a composite without such a port.
    pub fn resolve(&self, path: &str, kind: PortKind) -> Option<Vec<String>> {
        // The longest composite name `path` starts with whose port the rest is (a port of
        // an own adapter, `C.ADAPTER.PORT`, has a dot; so has a component's, `C.X.PORT`).
        for (at, _) in path.rmatch_indices('.') {
            let (fb, port) = (&path[..at], &path[at + 1..]);
            if let Some(flat) = self.flats.iter().find(|c| c.name == fb) {
                if let Some(p) = flat.ports.iter().find(|p| p.kind == kind && p.name == port) {
                    return Some(p.ends.clone());
                }
                if !port.contains('.') {
                    return None;
                }
            }
        }
        Some(vec![path.into()])
    }

    /// The first component port `path` stands for as a data output, else as a data input
    /// (what a READ, a watch or a force of `path` is about).
    pub fn data_port(&self, path: &str) -> Option<String> {
        [PortKind::DataOut, PortKind::DataIn]
            .into_iter()
            .filter_map(|k| self.resolve(path, k))
            .find_map(|ends| ends.into_iter().next())
    }

    /// The port `port` of composite `composite`, to add what it stands for.
    pub fn port_mut(
        &mut self,
        composite: &str,
        port: &str,
        kind: PortKind,
    ) -> Option<&mut FlatPort> {
        self.flats
            .iter_mut()
            .find(|c| c.name == composite)?
            .ports
            .iter_mut()
            .find(|p| p.kind == kind && p.name == port)
    }

    /// Applies `f` to every pair of resolved source and destination.
    fn each_pair(
        resource: &mut Resource,
        from: &[String],
        to: &[String],
        f: impl Fn(&mut Resource, &str, &str) -> Result<(), DeployError>,
    ) -> Result<(), DeployError> {
        for s in from {
            for d in to {
                f(resource, s, d)?;
            }
        }
        Ok(())
    }

    /// Connects a plug to a socket ([`Composites::connect_adapter`]), else an event output
    /// to an event input, else (its ports are no events) a data output to a data input,
    /// through composite ports.
    pub fn connect(
        &mut self,
        resource: &mut Resource,
        source: &str,
        destination: &str,
    ) -> Result<(), DeployError> {
        if self.between_adapters(resource, source, destination) {
            return self.connect_adapter(resource, source, destination);
        }
        self.link(
            resource,
            source,
            destination,
            Resource::connect_event,
            Resource::connect_data,
        )
    }

    /// The reverse of [`Composites::connect`].
    pub fn disconnect(
        &mut self,
        resource: &mut Resource,
        source: &str,
        destination: &str,
    ) -> Result<(), DeployError> {
        if self.between_adapters(resource, source, destination) {
            let at = self
                .adapter_links
                .iter()
                .position(|(p, s)| p == source && s == destination)
                .ok_or_else(|| DeployError::NotFound(format!("{source} -> {destination}")))?;
            self.adapter_links.remove(at);
            for (from, to) in self.adapter_pairs(resource, source, destination)? {
                let _ = self.unlink(resource, &from, &to);
            }
            return Ok(());
        }
        self.unlink(resource, source, destination)
    }

    fn unlink(
        &self,
        resource: &mut Resource,
        source: &str,
        destination: &str,
    ) -> Result<(), DeployError> {
        self.link(
            resource,
            source,
            destination,
            Resource::disconnect_event,
            Resource::disconnect_data,
        )
    }

    fn link(
        &self,
        resource: &mut Resource,
        source: &str,
        destination: &str,
        event: Link,
        data: Link,
    ) -> Result<(), DeployError> {
        if let (Some(from), Some(to)) = (
            self.resolve(source, PortKind::EventOut),
            self.resolve(destination, PortKind::EventIn),
        ) {
            match Self::each_pair(resource, &from, &to, event) {
                Err(DeployError::NotFound(_)) => {}
                done => return done,
            }
        }
        let from = self
            .resolve(source, PortKind::DataOut)
            .ok_or_else(|| DeployError::NotFound(source.into()))?;
        let to = self
            .resolve(destination, PortKind::DataIn)
            .ok_or_else(|| DeployError::NotFound(destination.into()))?;
        Self::each_pair(resource, &from, &to, data)
    }

    /// The plug or socket `path` (`FB.NAME`) of an instance or a composite instance.
    fn adapter(&self, resource: &Resource, path: &str) -> Option<AdapterSpec> {
        if let Some((fb, name)) = path.rsplit_once('.')
            && let Some(flat) = self.flats.iter().find(|c| c.name == fb)
        {
            return flat.adapters.iter().find(|a| a.name == name).cloned();
        }
        resource.adapter(path).cloned()
    }

    /// Whether both ends of a connection are plugs or sockets (an adapter connection).
    fn between_adapters(&self, resource: &Resource, source: &str, destination: &str) -> bool {
        [source, destination]
            .iter()
            .all(|path| self.adapter(resource, path).is_some())
    }

    /// The ports of plug or socket `path` (named `ADAPTER.PORT`): their kinds and `PORT`s.
    fn adapter_ports(&self, resource: &Resource, path: &str) -> Vec<(PortKind, String)> {
        let Some((fb, name)) = path.rsplit_once('.') else {
            return Vec::new();
        };
        let ours = |n: &str| adapter_port(n, name).map(String::from);
        if let Some(flat) = self.flats.iter().find(|c| c.name == fb) {
            return flat
                .ports
                .iter()
                .filter_map(|p| Some((p.kind, ours(&p.name)?)))
                .collect();
        }
        let Some((_, ifc)) = resource.instances().find(|(n, _)| *n == fb) else {
            return Vec::new();
        };
        let events = |list: &[EventSpec], kind| {
            list.iter()
                .filter_map(|e| Some((kind, ours(&e.name)?)))
                .collect::<Vec<_>>()
        };
        let vars = |list: &[VarSpec], kind| {
            list.iter()
                .filter_map(|v| Some((kind, ours(&v.name)?)))
                .collect::<Vec<_>>()
        };
        [
            events(&ifc.event_inputs, PortKind::EventIn),
            events(&ifc.event_outputs, PortKind::EventOut),
            vars(&ifc.inputs, PortKind::DataIn),
            vars(&ifc.outputs, PortKind::DataOut),
        ]
        .concat()
    }

    /// The connections an adapter connection from `plug` to `socket` stands for, checked
    /// (a plug, a socket, the same adapter type): each output event and variable of the
    /// one's ports to the input of the same name of the other's.
    fn adapter_pairs(
        &self,
        resource: &Resource,
        plug: &str,
        socket: &str,
    ) -> Result<Vec<(String, String)>, DeployError> {
        let spec = |path: &str| {
            self.adapter(resource, path)
                .ok_or_else(|| DeployError::NotFound(path.into()))
        };
        let (p, s) = (spec(plug)?, spec(socket)?);
        if !p.plug || s.plug {
            return Err(DeployError::Mismatch(format!(
                "an adapter connection goes from a plug to a socket; {plug} is a {}, {socket} a {}",
                p.kind(),
                s.kind()
            )));
        }
        if p.ty != s.ty {
            return Err(DeployError::Mismatch(format!(
                "{plug} is a plug of {}, {socket} a socket of {}",
                p.ty, s.ty
            )));
        }
        let mut pairs = Vec::new();
        for (from, to) in [(plug, socket), (socket, plug)] {
            for (kind, port) in self.adapter_ports(resource, from) {
                if matches!(kind, PortKind::EventOut | PortKind::DataOut) {
                    pairs.push((format!("{from}.{port}"), format!("{to}.{port}")));
                }
            }
        }
        Ok(pairs)
    }

    /// Connects plug `plug` (`FB.PLUG`) to socket `socket` (`FB.SOCKET`) of the same
    /// adapter type, of instances or composite instances: the event and data connections
    /// of [`Composites::adapter_pairs`], in the order the interfaces declare the ports, so
    /// the adapter's events queue, carry their WITH data and fan out as any other. A plug
    /// or socket takes one adapter connection. Nothing is connected when any of it is
    /// refused.
    fn connect_adapter(
        &mut self,
        resource: &mut Resource,
        plug: &str,
        socket: &str,
    ) -> Result<(), DeployError> {
        let pairs = self.adapter_pairs(resource, plug, socket)?;
        for path in [plug, socket] {
            if self
                .adapter_links
                .iter()
                .any(|(p, s)| p == path || s == path)
            {
                return Err(DeployError::Mismatch(format!(
                    "{path} has an adapter connection"
                )));
            }
        }
        for (k, (from, to)) in pairs.iter().enumerate() {
            let done = self.link(
                resource,
                from,
                to,
                Resource::connect_event,
                Resource::connect_data,
            );
            if let Err(e) = done {
                for (from, to) in &pairs[..k] {
                    let _ = self.unlink(resource, from, to);
                }
                return Err(e);
            }
        }
        self.adapter_links.push((plug.into(), socket.into()));
        Ok(())
    }

    /// Forgets composite `name` and the composites inside it.
    pub fn remove_tree(&mut self, name: &str) {
        self.flats.retain(|c| !within(&c.name, name));
    }

    /// Forgets the adapter connections of instance or composite instance `name` (deleted
    /// with their connections).
    pub fn forget_adapters(&mut self, name: &str) {
        self.adapter_links
            .retain(|(p, s)| !within(p, name) && !within(s, name));
    }
}

/// Whether instance `path` is `name` or inside composite `name`.
pub fn within(path: &str, name: &str) -> bool {
    path == name
        || path
            .strip_prefix(name)
            .is_some_and(|rest| rest.starts_with('.'))
}
