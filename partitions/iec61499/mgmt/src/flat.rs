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

use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;
use iec61499_runtime::Resource;
use iec61499_runtime::resource::DeployError;

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
    pub ports: Vec<FlatPort>,
}

/// The composite instances of a resource.
#[derive(Default)]
pub struct Composites(pub Vec<Flat>);

impl Composites {
    /// Whether `name` is a composite instance.
    pub fn contains(&self, name: &str) -> bool {
        self.0.iter().any(|c| c.name == name)
    }

    /// The component ports `path` stands for as a port of `kind`: itself when it is no
    /// composite's port, `None` when it names a composite without such a port.
    pub fn resolve(&self, path: &str, kind: PortKind) -> Option<Vec<String>> {
        if let Some((fb, port)) = path.rsplit_once('.')
            && let Some(flat) = self.0.iter().find(|c| c.name == fb)
        {
            return flat
                .ports
                .iter()
                .find(|p| p.kind == kind && p.name == port)
                .map(|p| p.ends.clone());
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
        self.0
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

    /// Connects an event output to an event input, else (its ports are no events) a data
    /// output to a data input, through composite ports.
    pub fn connect(
        &self,
        resource: &mut Resource,
        source: &str,
        destination: &str,
    ) -> Result<(), DeployError> {
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
        event: fn(&mut Resource, &str, &str) -> Result<(), DeployError>,
        data: fn(&mut Resource, &str, &str) -> Result<(), DeployError>,
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

    /// Forgets composite `name` and the composites inside it.
    pub fn remove_tree(&mut self, name: &str) {
        self.0.retain(|c| !within(&c.name, name));
    }
}

/// Whether instance `path` is `name` or inside composite `name`.
pub fn within(path: &str, name: &str) -> bool {
    path == name
        || path
            .strip_prefix(name)
            .is_some_and(|rest| rest.starts_with('.'))
}
