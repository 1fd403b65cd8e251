//! A compiled basic FB type as bytes: what the host (or a helper in the Linux guest) sends
//! a device to add a type at run time, and the device checks whole before an instance
//! exists: its structure, the ECC against the interface ([`crate::basic::Ecc::verify`]),
//! the bytecode by the PLC verifier ([`crate::vmcode::VmCode::new`]). An interface, all
//! integers little-endian; decoding never panics.
//!
//! ```text
//! 0  4 magic "W61T"          4 2 version (2)            6 2 reserved (0)
//! 8  4 CRC-32 of the bytes from offset 12 to the end
//! 12 .. sections, each a count u16 then its records:
//!   name             1 record: name
//!   event inputs     per event: name, WITH count u8, WITH input indices u8 each
//!   event outputs    per event: name, WITH count u8, WITH output indices u8 each
//!   inputs, outputs, internals   per variable: name, type u8 (VarType), array u16 (0: scalar)
//!   adapters         per plug or socket: name, adapter type name, kind u8 (0 plug, 1 socket)
//!   states           per state: name, action count u8, per action: algorithm u8, output u8 (255: none)
//!   transitions      per transition: source u16, destination u16, event u8, guard u8 (255: none)
//!   code             1 record: algorithms u16, guards u16, image length u32, the image
//! a name is length u8 then UTF-8 bytes
//! ```

use crate::basic::{Action, Ecc, State, Transition};
use crate::fb::{AdapterSpec, EventSpec, Interface, VarSpec};
use crate::value::DataType;
use crate::vmcode::VmCode;
use alloc::string::{String, ToString};
use alloc::vec::Vec;

const MAGIC: &[u8; 4] = b"W61T";
const VERSION: u16 = 2;
const NONE: u8 = 255;

/// A decoded, checked type.
#[derive(Clone, Debug)]
pub struct TypePackage {
    pub name: String,
    pub interface: Interface,
    pub internals: Vec<VarSpec>,
    pub ecc: Ecc,
    pub code: VmCode,
}

impl TypePackage {
    /// A new instance of the type.
    pub fn instantiate(&self) -> alloc::boxed::Box<dyn crate::FunctionBlock> {
        match crate::basic::BasicFb::new(
            self.interface.clone(),
            self.ecc.clone(),
            self.internals.clone(),
            alloc::boxed::Box::new(self.code.clone()),
        ) {
            Ok(fb) => alloc::boxed::Box::new(fb),
            Err(e) => unreachable!("decode verified the ECC: {e}"),
        }
    }
}

/// Why a package was refused (nothing of it is used).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PackageError {
    Magic,
    Version(u16),
    Checksum,
    /// The bytes end inside the field at this offset.
    Truncated(usize),
    /// The field at this offset is not valid.
    Invalid(usize, &'static str),
    /// The ECC or the bytecode does not check.
    Rejected(String),
}

impl core::fmt::Display for PackageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PackageError::Magic => f.write_str("not an FB type package"),
            PackageError::Version(v) => {
                write!(f, "package version {v}, this device reads {VERSION}")
            }
            PackageError::Checksum => f.write_str("package checksum does not match (damaged)"),
            PackageError::Truncated(at) => write!(f, "package ends inside the field at byte {at}"),
            PackageError::Invalid(at, what) => write!(f, "package byte {at}: {what}"),
            PackageError::Rejected(why) => write!(f, "package refused: {why}"),
        }
    }
}

pub(crate) fn crc(bytes: &[u8]) -> u32 {
    let mut c = abi::crc32::Crc32::new();
    c.update(bytes);
    c.finish()
}

/// A type as package bytes.
pub fn encode(
    name: &str,
    interface: &Interface,
    internals: &[VarSpec],
    ecc: &Ecc,
    code: &VmCode,
) -> Vec<u8> {
    let mut w = Vec::new();
    let name_of = |w: &mut Vec<u8>, n: &str| {
        let n = &n.as_bytes()[..n.len().min(255)];
        w.push(n.len() as u8);
        w.extend_from_slice(n);
    };
    let count = |w: &mut Vec<u8>, n: usize| w.extend_from_slice(&(n as u16).to_le_bytes());
    count(&mut w, 1);
    name_of(&mut w, name);
    for events in [&interface.event_inputs, &interface.event_outputs] {
        count(&mut w, events.len());
        for e in events {
            name_of(&mut w, &e.name);
            w.push(e.with.len() as u8);
            w.extend(e.with.iter().map(|&i| i as u8));
        }
    }
    for vars in [&interface.inputs[..], &interface.outputs[..], internals] {
        count(&mut w, vars.len());
        for v in vars {
            name_of(&mut w, &v.name);
            w.push(v.ty.code());
            w.extend_from_slice(&(v.array.unwrap_or(0) as u16).to_le_bytes());
        }
    }
    count(&mut w, interface.adapters.len());
    for a in &interface.adapters {
        name_of(&mut w, &a.name);
        name_of(&mut w, &a.ty);
        w.push(u8::from(!a.plug));
    }
    count(&mut w, ecc.states.len());
    for s in &ecc.states {
        name_of(&mut w, &s.name);
        w.push(s.actions.len() as u8);
        for a in &s.actions {
            w.push(a.algorithm.map_or(NONE, |i| i as u8));
            w.push(a.output.map_or(NONE, |i| i as u8));
        }
    }
    count(&mut w, ecc.transitions.len());
    for t in &ecc.transitions {
        w.extend_from_slice(&(t.source as u16).to_le_bytes());
        w.extend_from_slice(&(t.destination as u16).to_le_bytes());
        w.push(t.event.map_or(NONE, |i| i as u8));
        w.push(t.guard.map_or(NONE, |i| i as u8));
    }
    count(&mut w, 1);
    let (algorithms, guards) = crate::basic::Algorithms::counts(code);
    w.extend_from_slice(&(algorithms as u16).to_le_bytes());
    w.extend_from_slice(&(guards as u16).to_le_bytes());
    w.extend_from_slice(&(code.image().len() as u32).to_le_bytes());
    w.extend_from_slice(code.image());
    let mut out = Vec::with_capacity(12 + w.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(&crc(&w).to_le_bytes());
    out.extend_from_slice(&w);
    out
}

pub(crate) struct Reader<'a> {
    pub(crate) b: &'a [u8],
    pub(crate) at: usize,
}

impl<'a> Reader<'a> {
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], PackageError> {
        let s = self
            .b
            .get(self.at..self.at + n)
            .ok_or(PackageError::Truncated(self.at))?;
        self.at += n;
        Ok(s)
    }
    pub(crate) fn u8(&mut self) -> Result<u8, PackageError> {
        Ok(self.take(1)?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, PackageError> {
        let s = self.take(2)?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, PackageError> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    pub(crate) fn name(&mut self) -> Result<String, PackageError> {
        let at = self.at;
        let n = self.u8()? as usize;
        let s = self.take(n)?;
        core::str::from_utf8(s)
            .map(ToString::to_string)
            .map_err(|_| PackageError::Invalid(at, "name is not UTF-8"))
    }
    pub(crate) fn count(&mut self, expected: Option<u16>) -> Result<usize, PackageError> {
        let at = self.at;
        let n = self.u16()?;
        if expected.is_some_and(|e| e != n) {
            return Err(PackageError::Invalid(at, "section count"));
        }
        Ok(n as usize)
    }
    /// A text of up to 65,535 bytes: length u16 then UTF-8.
    pub(crate) fn text(&mut self) -> Result<String, PackageError> {
        let at = self.at;
        let n = self.u16()? as usize;
        let s = self.take(n)?;
        core::str::from_utf8(s)
            .map(ToString::to_string)
            .map_err(|_| PackageError::Invalid(at, "text is not UTF-8"))
    }
    fn optional(&mut self) -> Result<Option<usize>, PackageError> {
        Ok(match self.u8()? {
            NONE => None,
            i => Some(i as usize),
        })
    }
}

/// Checks the 12-byte header every package kind shares (`magic`, `version`, two reserved
/// zero bytes, the CRC-32 of what follows) and returns a reader at the body.
pub(crate) fn open<'a>(
    bytes: &'a [u8],
    magic: &[u8; 4],
    version: u16,
) -> Result<Reader<'a>, PackageError> {
    if bytes.get(..4) != Some(&magic[..]) {
        return Err(if bytes.len() < 4 {
            PackageError::Truncated(0)
        } else {
            PackageError::Magic
        });
    }
    let mut r = Reader { b: bytes, at: 4 };
    let found = r.u16()?;
    if found != version {
        return Err(PackageError::Version(found));
    }
    if r.u16()? != 0 {
        return Err(PackageError::Invalid(6, "reserved bytes are not 0"));
    }
    let sum = r.u32()?;
    if crc(&bytes[12..]) != sum {
        return Err(PackageError::Checksum);
    }
    Ok(r)
}

/// Reads and checks a package.
pub fn decode(bytes: &[u8]) -> Result<TypePackage, PackageError> {
    let mut r = open(bytes, MAGIC, VERSION)?;
    r.count(Some(1))?;
    let name = r.name()?;
    let mut event_sets = Vec::new();
    for _ in 0..2 {
        let n = r.count(None)?;
        let mut events = Vec::new();
        for _ in 0..n {
            let name = r.name()?;
            let k = r.u8()? as usize;
            let with = r.take(k)?.iter().map(|&i| i as usize).collect();
            events.push(EventSpec { name, with });
        }
        event_sets.push(events);
    }
    let mut var_sets = Vec::new();
    for _ in 0..3 {
        let n = r.count(None)?;
        let mut vars = Vec::new();
        for _ in 0..n {
            let name = r.name()?;
            let at = r.at;
            let ty =
                DataType::from_code(r.u8()?).ok_or(PackageError::Invalid(at, "unknown type"))?;
            let array = match r.u16()? {
                0 => None,
                n => Some(n as usize),
            };
            vars.push(VarSpec { name, ty, array });
        }
        var_sets.push(vars);
    }
    let mut adapters = Vec::new();
    for _ in 0..r.count(None)? {
        let name = r.name()?;
        let ty = r.name()?;
        let at = r.at;
        let plug = match r.u8()? {
            0 => true,
            1 => false,
            _ => {
                return Err(PackageError::Invalid(
                    at,
                    "adapter kind is neither plug nor socket",
                ));
            }
        };
        if adapters.iter().any(|a: &AdapterSpec| a.name == name) {
            return Err(PackageError::Invalid(at, "adapter declared twice"));
        }
        adapters.push(AdapterSpec { name, ty, plug });
    }
    let mut states = Vec::new();
    for _ in 0..r.count(None)? {
        let name = r.name()?;
        let mut actions = Vec::new();
        for _ in 0..r.u8()? {
            actions.push(Action {
                algorithm: r.optional()?,
                output: r.optional()?,
            });
        }
        states.push(State { name, actions });
    }
    let mut transitions = Vec::new();
    for _ in 0..r.count(None)? {
        transitions.push(Transition {
            source: r.u16()? as usize,
            destination: r.u16()? as usize,
            event: r.optional()?,
            guard: r.optional()?,
        });
    }
    r.count(Some(1))?;
    let (algorithms, guards) = (r.u16()? as usize, r.u16()? as usize);
    let len = r.u32()? as usize;
    let image = r.take(len)?.to_vec();
    if r.at != bytes.len() {
        return Err(PackageError::Invalid(r.at, "bytes after the code"));
    }
    let internals = var_sets.pop().unwrap_or_default();
    let outputs = var_sets.pop().unwrap_or_default();
    let inputs = var_sets.pop().unwrap_or_default();
    let event_outputs = event_sets.pop().unwrap_or_default();
    let event_inputs = event_sets.pop().unwrap_or_default();
    for (events, vars) in [(&event_inputs, &inputs), (&event_outputs, &outputs)] {
        if events
            .iter()
            .any(|e| e.with.iter().any(|&w| w >= vars.len()))
        {
            return Err(PackageError::Rejected(
                "an event carries a variable that does not exist".into(),
            ));
        }
    }
    let interface = Interface {
        event_inputs,
        event_outputs,
        inputs,
        outputs,
        adapters,
    };
    let ecc = Ecc {
        states,
        transitions,
    };
    ecc.verify(&interface, algorithms, guards)
        .map_err(PackageError::Rejected)?;
    let code = VmCode::new(
        image,
        interface.inputs.clone(),
        interface.outputs.clone(),
        internals.clone(),
        algorithms,
        guards,
    )
    .map_err(PackageError::Rejected)?;
    Ok(TypePackage {
        name,
        interface,
        internals,
        ecc,
        code,
    })
}
