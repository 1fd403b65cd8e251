//! PLC-to-PLC publish/subscribe: variables of the program sent as one message in the
//! IEC 61499 FBDK ASN.1 encoding (crate `fbdk`, what 4diac FORTE's PUBLISH_n/SUBSCRIBE_n
//! put on the wire: a FORTE device can be either peer), and received ones written into the
//! program between releases, with a validity that lapses when messages stop.
//!
//! A publication is the configured variables' values, in their order, at the end of a
//! release. A received message is taken whole or not at all: every value must decode as
//! its variable's type, else nothing is written and the message counts as bad. The
//! subscription is valid while the last good message is younger than its timeout; when it
//! lapses the subscribed variables go to zero (FALSE, 0, 0.0, '') and the validity
//! variable, if configured, to FALSE, so the program sees the loss as it sees a stale
//! sampling port's validity bit. A PLC none of whose tasks runs publishes nothing: its
//! subscribers see it stop.
//!
//! [`Endpoint`] is the control process's part between releases; the datagrams themselves
//! are the communication process's ([`crate::comm`]).

use fbdk::{DecodeError, Reader, Type, Value as Wire, Writer};
use plc_vm::image::{Image, VarType};
use plc_vm::vm::Value;

/// The FBDK type of a variable type, for the types the encoding carries.
pub fn wire_type(ty: VarType) -> Option<Type> {
    Some(match ty {
        VarType::Bool => Type::Bool,
        VarType::SInt => Type::SInt,
        VarType::Int => Type::Int,
        VarType::DInt => Type::DInt,
        VarType::LInt => Type::LInt,
        VarType::USInt => Type::USInt,
        VarType::UInt => Type::UInt,
        VarType::UDInt => Type::UDInt,
        VarType::ULInt => Type::ULInt,
        VarType::Real => Type::Real,
        VarType::LReal => Type::LReal,
        VarType::Time => Type::Time,
        VarType::String => Type::String,
        VarType::Byte => Type::Byte,
        VarType::Word => Type::Word,
        VarType::DWord => Type::DWord,
        VarType::LWord => Type::LWord,
        _ => return None,
    })
}

/// Why a publication or subscription cannot be set up or a message was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PubSubError<'n> {
    /// The program has no variable of this name.
    Unknown(&'n str),
    /// The variable's type has no FBDK encoding.
    Type(&'n str),
    /// The message did not decode as the subscribed variables.
    Message(DecodeError),
    /// The message does not fit the output buffer.
    TooLong,
}

/// Checks that every name is a variable of `image` whose type the encoding carries.
pub fn check<'n>(image: &Image, names: &[&'n str]) -> Result<(), PubSubError<'n>> {
    for &name in names {
        let var = image.find_var(name).ok_or(PubSubError::Unknown(name))?;
        VarType::from_code(var.ty)
            .and_then(wire_type)
            .ok_or(PubSubError::Type(name))?;
    }
    Ok(())
}

/// Encodes the values of `names` (checked by [`check`]) in `data` into `out`; returns the
/// message's length.
pub fn publish<'n>(
    image: &Image,
    data: &[u8],
    names: &[&'n str],
    out: &mut [u8],
) -> Result<usize, PubSubError<'n>> {
    let mut w = Writer::new(out);
    for &name in names {
        let var = image.find_var(name).ok_or(PubSubError::Unknown(name))?;
        let ty = VarType::from_code(var.ty).ok_or(PubSubError::Type(name))?;
        let wire = wire_type(ty).ok_or(PubSubError::Type(name))?;
        let bytes = data
            .get(var.addr as usize..(var.addr + var.size) as usize)
            .ok_or(PubSubError::Unknown(name))?;
        let value = match Value::load(ty, bytes).ok_or(PubSubError::Type(name))? {
            Value::Bool(b) => Wire::bool(b),
            Value::Int(i) => Wire::Fixed(wire, i as u64),
            Value::UInt(u) => Wire::Fixed(wire, u),
            Value::Real(r) => Wire::Fixed(wire, u64::from(r.to_bits())),
            Value::LReal(r) => Wire::Fixed(wire, r.to_bits()),
            Value::Time(t) => Wire::Fixed(wire, t as u64),
            Value::String(s) => Wire::String(s),
            _ => return Err(PubSubError::Type(name)),
        };
        w.value(&value).map_err(|_| PubSubError::TooLong)?;
    }
    if names.is_empty() {
        w.null().map_err(|_| PubSubError::TooLong)?;
    }
    Ok(w.len())
}

/// Writes a received `message` into the variables `names` of `data`: all of them, or (a
/// message that does not decode as their types) none.
pub fn subscribe<'n>(
    image: &Image,
    data: &mut [u8],
    names: &[&'n str],
    message: &[u8],
) -> Result<(), PubSubError<'n>> {
    // First decode everything, writing nothing.
    let mut r = Reader::new(message);
    if names.is_empty() {
        return if r.is_null() {
            Ok(())
        } else {
            Err(PubSubError::Message(DecodeError::Trailing { at: 0 }))
        };
    }
    for &name in names {
        let var = image.find_var(name).ok_or(PubSubError::Unknown(name))?;
        let ty = VarType::from_code(var.ty)
            .and_then(wire_type)
            .ok_or(PubSubError::Type(name))?;
        r.value(ty).map_err(PubSubError::Message)?;
    }
    r.finish().map_err(PubSubError::Message)?;
    // Then write.
    let mut r = Reader::new(message);
    for &name in names {
        let var = image.find_var(name).ok_or(PubSubError::Unknown(name))?;
        let ty = VarType::from_code(var.ty).ok_or(PubSubError::Type(name))?;
        let wire = r
            .value(wire_type(ty).ok_or(PubSubError::Type(name))?)
            .map_err(PubSubError::Message)?;
        let value = match (ty, wire) {
            (_, Wire::Fixed(Type::Bool, b)) => Value::Bool(b != 0),
            (
                VarType::SInt | VarType::Int | VarType::DInt | VarType::LInt,
                Wire::Fixed(_, bits),
            ) => Value::Int(bits as i64),
            (VarType::Real, Wire::Fixed(_, bits)) => Value::Real(f32::from_bits(bits as u32)),
            (VarType::LReal, Wire::Fixed(_, bits)) => Value::LReal(f64::from_bits(bits)),
            (VarType::Time, Wire::Fixed(_, bits)) => Value::Time(bits as i64),
            (_, Wire::Fixed(_, bits)) => Value::UInt(bits),
            (_, Wire::String(s)) => Value::String(s),
            (_, Wire::WString(_)) => return Err(PubSubError::Type(name)),
        };
        let bytes = data
            .get_mut(var.addr as usize..(var.addr + var.size) as usize)
            .ok_or(PubSubError::Unknown(name))?;
        // A string longer than the variable is cut to its capacity, as an assignment does.
        value
            .store(ty, bytes)
            .map_err(|_| PubSubError::Type(name))?;
    }
    Ok(())
}

/// A subscription's validity: good while the last good message is younger than `timeout`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Validity {
    timeout_ns: i64,
    last_good: Option<i64>,
}

impl Validity {
    pub fn new(timeout_ns: i64) -> Self {
        Validity {
            timeout_ns,
            last_good: None,
        }
    }

    /// A good message arrived at `now`.
    pub fn received(&mut self, now: i64) {
        self.last_good = Some(now);
    }

    /// Whether the subscribed values are valid at `now`.
    pub fn valid(&self, now: i64) -> bool {
        self.last_good
            .is_some_and(|t| now.saturating_sub(t) < self.timeout_ns)
    }
}

/// Splits `\n`-separated names into `out`; returns how many (at most `out.len()`).
pub fn split_names<'n>(text: &'n str, out: &mut [&'n str]) -> usize {
    let mut n = 0;
    for (slot, name) in out.iter_mut().zip(text.split('\n')) {
        *slot = name;
        n += 1;
    }
    n
}

/// What changed in a subscription's validity at a release.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Change {
    /// The first good message, or the first after a lapse.
    Valid,
    /// No good message within the timeout: the variables went to zero.
    Lapsed,
}

/// The control process's publish/subscribe between releases: the publication of the
/// values the release left, the subscription's message written into the program and its
/// validity.
#[derive(Clone, Copy, Debug)]
pub struct Endpoint<'n> {
    publish: Option<([&'n str; MAX_VARS], usize)>,
    subscribe: Option<([&'n str; MAX_VARS], usize)>,
    valid_var: Option<&'n str>,
    validity: Validity,
    was_valid: bool,
    /// Good and refused messages taken.
    pub good: u64,
    pub bad: u64,
}

/// Most variables a publication or subscription carries (the package's limit).
pub const MAX_VARS: usize = crate::package::MAX_PUBSUB_VARS;

impl<'n> Endpoint<'n> {
    /// The endpoint of `pubsub`, its names checked against `image` (and the validity
    /// variable a BOOL).
    pub fn new(
        image: &Image,
        pubsub: &crate::package::PubSub<'n>,
    ) -> Result<Self, PubSubError<'n>> {
        let names = |text: &'n str| {
            let mut out = [""; MAX_VARS];
            let n = split_names(text, &mut out);
            (out, n)
        };
        let publish = pubsub.publish.map(|(_, _, text)| names(text));
        let subscribe = pubsub.subscribe.map(|s| names(s.names));
        for (list, n) in publish.iter().chain(subscribe.iter()) {
            check(image, &list[..*n])?;
        }
        let valid_var = pubsub.subscribe.and_then(|s| s.valid);
        if let Some(v) = valid_var {
            let var = image.find_var(v).ok_or(PubSubError::Unknown(v))?;
            if VarType::from_code(var.ty) != Some(VarType::Bool) {
                return Err(PubSubError::Type(v));
            }
        }
        Ok(Endpoint {
            publish,
            subscribe,
            valid_var,
            validity: Validity::new(pubsub.subscribe.map_or(0, |s| s.timeout_ns) as i64),
            was_valid: false,
            good: 0,
            bad: 0,
        })
    }

    /// Between releases at `now` (ns): the publication into `publication` (when `running`,
    /// whether a task of the program runs), a waiting `message` (taken) written into
    /// `data`, the validity variable set and, on a lapse, the subscribed variables zeroed.
    /// `publication`'s first byte count is returned (0: none).
    pub fn between_releases(
        &mut self,
        image: &Image,
        data: &mut [u8],
        now: i64,
        running: bool,
        message: Option<&[u8]>,
        publication: &mut [u8],
    ) -> (usize, Option<Change>) {
        let mut published = 0;
        if let Some((names, n)) = &self.publish
            && running
        {
            published = publish(image, data, &names[..*n], publication).unwrap_or(0);
        }
        let Some((names, n)) = &self.subscribe else {
            return (published, None);
        };
        if let Some(m) = message {
            match subscribe(image, data, &names[..*n], m) {
                Ok(()) => {
                    self.good += 1;
                    self.validity.received(now);
                }
                Err(_) => self.bad += 1,
            }
        }
        let valid = self.validity.valid(now);
        if let Some(v) = self.valid_var.and_then(|v| image.find_var(v))
            && let Some(bytes) = data.get_mut(v.addr as usize..(v.addr + v.size) as usize)
        {
            let _ = Value::Bool(valid).store(VarType::Bool, bytes);
        }
        let change = match (self.was_valid, valid) {
            (false, true) => Some(Change::Valid),
            (true, false) => {
                for var in names[..*n].iter().filter_map(|name| image.find_var(name)) {
                    if let Some(bytes) =
                        data.get_mut(var.addr as usize..(var.addr + var.size) as usize)
                    {
                        bytes.fill(0);
                    }
                }
                Some(Change::Lapsed)
            }
            _ => None,
        };
        self.was_valid = valid;
        (published, change)
    }
}

#[cfg(test)]
mod tests;
