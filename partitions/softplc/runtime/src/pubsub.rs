//! PLC-to-PLC publish/subscribe: variables of the program sent as one message in the
//! IEC 61499 FBDK ASN.1 encoding (crate `fbdk`, what 4diac FORTE's PUBLISH_n/SUBSCRIBE_n
//! put on the wire: a FORTE device can be either peer), and received ones written into the
//! program between releases, with a validity that lapses when messages stop.
//!
//! A publication is the configured variables' values, in their order, at the end of a
//! release. A received message is taken whole or not at all: every value must decode as
//! its variable's type, else nothing is written and the message counts as bad. The
//! subscription is valid while the last good message is younger than its timeout; when it
//! lapses the runtime writes the subscribed variables' safe values (the configuration's),
//! as it does for a stale sampling port.

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

#[cfg(test)]
mod tests;
