//! A composite FB type: an interface and the network behind it (component instances with
//! their parameters, event and data connections), as a device is sent it. A device does not
//! run a composite instance as one FB: it flattens it into its component instances, named
//! `COMPOSITE.COMPONENT`, and their connections when the instance is created, so its events
//! go through the resource's one queue like any other (`iec61499_mgmt::device`). Each
//! component and connection keeps its place in the `.fbt` for the device's messages.
//!
//! The bytes, an interface (integers little-endian, decoding never panics):
//!
//! ```text
//! 0  4 magic "W61N"          4 2 version (2)            6 2 reserved (0)
//! 8  4 CRC-32 of the bytes from offset 12 to the end
//! 12 name, file (texts)
//!    event inputs, event outputs, data inputs, data outputs: each a count u16 and names
//!    (a port of the composite's own plug or socket is `ADAPTER.PORT`)
//!    adapters: count u16, per plug or socket: name, adapter type, kind u8 (0 plug, 1 socket)
//!    components: count u16, per component: name, type, line u32, col u32,
//!                parameter count u16, per parameter: input name, literal
//!    connections: count u16, per connection: kind u8 (1 event, 0 data), source component
//!                (empty: the interface), source port, destination component, destination
//!                port, line u32, col u32
//! a name or text is length u16 then UTF-8 bytes
//! ```

use crate::fb::AdapterSpec;
use crate::package::{self, PackageError, crc};
use alloc::string::String;
use alloc::vec::Vec;

pub const MAGIC: &[u8; 4] = b"W61N";
const VERSION: u16 = 2;

/// A component instance of the network.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Component {
    pub name: String,
    pub ty: String,
    /// `(input, literal)`.
    pub parameters: Vec<(String, String)>,
    /// Its place in the `.fbt`.
    pub line: u32,
    pub col: u32,
}

/// A connection end: a component's port, or the composite's own interface (`component`
/// `None`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct End {
    pub component: Option<String>,
    pub port: String,
}

/// A connection of the network.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Link {
    /// An event connection (else a data connection).
    pub event: bool,
    pub source: End,
    pub destination: End,
    pub line: u32,
    pub col: u32,
}

/// A composite FB type.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CompositeType {
    pub name: String,
    /// The `.fbt` it was read from, for messages.
    pub file: String,
    pub event_inputs: Vec<String>,
    pub event_outputs: Vec<String>,
    pub inputs: Vec<String>,
    pub outputs: Vec<String>,
    /// Its own plugs and sockets; their ports are among the interface's names.
    pub adapters: Vec<AdapterSpec>,
    pub components: Vec<Component>,
    pub links: Vec<Link>,
}

impl CompositeType {
    /// `file:line:col` of a component or connection, for a message.
    pub fn place(&self, line: u32, col: u32) -> String {
        alloc::format!("{}:{line}:{col}", self.file)
    }

    /// The type as bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::new();
        let text = |w: &mut Vec<u8>, s: &str| {
            let s = &s.as_bytes()[..s.len().min(u16::MAX as usize)];
            w.extend_from_slice(&(s.len() as u16).to_le_bytes());
            w.extend_from_slice(s);
        };
        let count = |w: &mut Vec<u8>, n: usize| w.extend_from_slice(&(n as u16).to_le_bytes());
        text(&mut w, &self.name);
        text(&mut w, &self.file);
        for names in [
            &self.event_inputs,
            &self.event_outputs,
            &self.inputs,
            &self.outputs,
        ] {
            count(&mut w, names.len());
            for n in names {
                text(&mut w, n);
            }
        }
        count(&mut w, self.adapters.len());
        for a in &self.adapters {
            text(&mut w, &a.name);
            text(&mut w, &a.ty);
            w.push(u8::from(!a.plug));
        }
        count(&mut w, self.components.len());
        for c in &self.components {
            text(&mut w, &c.name);
            text(&mut w, &c.ty);
            w.extend_from_slice(&c.line.to_le_bytes());
            w.extend_from_slice(&c.col.to_le_bytes());
            count(&mut w, c.parameters.len());
            for (input, literal) in &c.parameters {
                text(&mut w, input);
                text(&mut w, literal);
            }
        }
        count(&mut w, self.links.len());
        for l in &self.links {
            w.push(u8::from(l.event));
            for end in [&l.source, &l.destination] {
                text(&mut w, end.component.as_deref().unwrap_or(""));
                text(&mut w, &end.port);
            }
            w.extend_from_slice(&l.line.to_le_bytes());
            w.extend_from_slice(&l.col.to_le_bytes());
        }
        let mut out = Vec::with_capacity(12 + w.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&[0, 0]);
        out.extend_from_slice(&crc(&w).to_le_bytes());
        out.extend_from_slice(&w);
        out
    }

    /// Reads and checks the bytes of a composite type: its structure, and that every
    /// connection end names a component or a port of the interface of the right direction
    /// (what the component types make of it is checked when an instance is created).
    pub fn decode(bytes: &[u8]) -> Result<CompositeType, PackageError> {
        let mut r = package::open(bytes, MAGIC, VERSION)?;
        let mut t = CompositeType {
            name: r.text()?,
            file: r.text()?,
            ..CompositeType::default()
        };
        for names in [
            &mut t.event_inputs,
            &mut t.event_outputs,
            &mut t.inputs,
            &mut t.outputs,
        ] {
            for _ in 0..r.count(None)? {
                names.push(r.text()?);
            }
        }
        for _ in 0..r.count(None)? {
            let (name, ty) = (r.text()?, r.text()?);
            let at = r.at;
            let plug = match r.u8()? {
                0 => true,
                1 => false,
                _ => return Err(PackageError::Invalid(at, "adapter kind")),
            };
            t.adapters.push(AdapterSpec { name, ty, plug });
        }
        for _ in 0..r.count(None)? {
            let (name, ty) = (r.text()?, r.text()?);
            let (line, col) = (r.u32()?, r.u32()?);
            let mut parameters = Vec::new();
            for _ in 0..r.count(None)? {
                parameters.push((r.text()?, r.text()?));
            }
            t.components.push(Component {
                name,
                ty,
                parameters,
                line,
                col,
            });
        }
        for _ in 0..r.count(None)? {
            let at = r.at;
            let event = match r.u8()? {
                0 => false,
                1 => true,
                _ => return Err(PackageError::Invalid(at, "connection kind")),
            };
            let mut ends = [None, None];
            for end in &mut ends {
                let component = r.text()?;
                *end = Some(End {
                    component: (!component.is_empty()).then_some(component),
                    port: r.text()?,
                });
            }
            let [Some(source), Some(destination)] = ends else {
                return Err(PackageError::Invalid(at, "connection ends"));
            };
            t.links.push(Link {
                event,
                source,
                destination,
                line: r.u32()?,
                col: r.u32()?,
            });
        }
        if r.at != bytes.len() {
            return Err(PackageError::Invalid(r.at, "bytes after the connections"));
        }
        t.check().map_err(PackageError::Rejected)?;
        Ok(t)
    }

    /// Names valid and unique, connection ends declared with the right direction.
    fn check(&self) -> Result<(), String> {
        let valid = |n: &str| !n.is_empty() && !n.contains('.');
        // A port of an own plug or socket is `ADAPTER.PORT`.
        let port = |n: &str| {
            valid(n)
                || n.split_once('.')
                    .is_some_and(|(a, p)| valid(p) && self.adapters.iter().any(|x| x.name == a))
        };
        let mut seen: Vec<&str> = Vec::new();
        for a in &self.adapters {
            if !valid(&a.name) || seen.contains(&a.name.as_str()) {
                return Err(alloc::format!("{}: adapter name `{}`", self.name, a.name));
            }
            seen.push(&a.name);
        }
        for n in self
            .event_inputs
            .iter()
            .chain(&self.event_outputs)
            .chain(&self.inputs)
            .chain(&self.outputs)
        {
            if !port(n) || seen.contains(&n.as_str()) {
                return Err(alloc::format!("{}: interface name `{n}`", self.name));
            }
            seen.push(n);
        }
        let mut seen: Vec<&str> = Vec::new();
        for c in &self.components {
            if !valid(&c.name) || seen.contains(&c.name.as_str()) {
                return Err(alloc::format!(
                    "{}: component name `{}`",
                    self.place(c.line, c.col),
                    c.name
                ));
            }
            seen.push(&c.name);
        }
        for l in &self.links {
            for (end, source) in [(&l.source, true), (&l.destination, false)] {
                let known = match &end.component {
                    Some(c) => self.components.iter().any(|x| x.name == *c),
                    // The interface: a source is an input of the composite, a destination
                    // an output.
                    None => match (l.event, source) {
                        (true, true) => self.event_inputs.contains(&end.port),
                        (true, false) => self.event_outputs.contains(&end.port),
                        (false, true) => self.inputs.contains(&end.port),
                        (false, false) => self.outputs.contains(&end.port),
                    },
                };
                if !known {
                    return Err(alloc::format!(
                        "{}: connection end `{}` is neither a component nor an {} of the interface",
                        self.place(l.line, l.col),
                        end.port,
                        if source { "input" } else { "output" }
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString;
    use alloc::vec;

    fn sample() -> CompositeType {
        CompositeType {
            name: "C".into(),
            file: "C.fbt".into(),
            event_inputs: vec!["REQ".into()],
            event_outputs: vec!["CNF".into()],
            inputs: vec!["IN".into()],
            outputs: vec!["OUT".into(), "S.DT".into()],
            adapters: vec![AdapterSpec {
                name: "S".into(),
                ty: "ATimeOut".into(),
                plug: false,
            }],
            components: vec![Component {
                name: "X".into(),
                ty: "DINT2DINT".into(),
                parameters: vec![("IN".into(), "DINT#1".into())],
                line: 3,
                col: 5,
            }],
            links: vec![Link {
                event: true,
                source: End {
                    component: None,
                    port: "REQ".into(),
                },
                destination: End {
                    component: Some("X".into()),
                    port: "REQ".into(),
                },
                line: 7,
                col: 9,
            }],
        }
    }

    #[test]
    fn round_trip_and_refusals() {
        let t = sample();
        let bytes = t.encode();
        assert_eq!(CompositeType::decode(&bytes), Ok(t.clone()));
        let mut damaged = bytes.clone();
        *damaged.last_mut().unwrap() ^= 1;
        assert_eq!(CompositeType::decode(&damaged), Err(PackageError::Checksum));
        for n in 0..bytes.len() {
            assert!(CompositeType::decode(&bytes[..n]).is_err());
        }
        let mut wrong = t.clone();
        wrong.links[0].source.port = "CNF".into();
        let e = CompositeType::decode(&wrong.encode())
            .unwrap_err()
            .to_string();
        assert!(e.contains("C.fbt:7:9") && e.contains("`CNF`"), "{e}");
        let mut twice = t;
        twice.components.push(twice.components[0].clone());
        let e = CompositeType::decode(&twice.encode())
            .unwrap_err()
            .to_string();
        assert!(e.contains("C.fbt:3:5: component name `X`"), "{e}");
        // A dotted port name needs an own adapter of that name.
        let mut stray = sample();
        stray.outputs.push("T.DT".into());
        let e = CompositeType::decode(&stray.encode())
            .unwrap_err()
            .to_string();
        assert!(e.contains("interface name `T.DT`"), "{e}");
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(tail in proptest::collection::vec(proptest::num::u8::ANY, 0..200)) {
            let mut bytes = sample().encode()[..12].to_vec();
            bytes.extend_from_slice(&tail);
            let sum = crc(&bytes[12..]);
            bytes[8..12].copy_from_slice(&sum.to_le_bytes());
            let _ = CompositeType::decode(&bytes);
        }
    }
}
