//! Data values of function-block inputs and outputs.

use alloc::string::String;
use alloc::vec::Vec;

/// The elementary types an interface declares: the PLC VM's variable types (one vocabulary
/// with the bytecode the algorithms will run on).
pub use plc_vm::image::VarType as DataType;

/// The type named `name` (case-insensitive, as 4diac writes `UINT` or `uint`).
pub fn type_named(name: &str) -> Option<DataType> {
    DataType::from_name(&name.to_ascii_uppercase())
}

/// The initial value of a variable of type `ty`.
pub fn zero(ty: DataType) -> Value {
    use DataType::*;
    match ty {
        Bool => Value::Bool(false),
        SInt | Int | DInt | LInt => Value::Int(0),
        Real | LReal => Value::Real(0.0),
        String | WString => Value::String(alloc::string::String::new()),
        Time | LTime | Date | LDate | Tod | LTod | Dt | LDt => Value::Time(0),
        _ => Value::UInt(0),
    }
}

/// Whether a value of type `from` converts to type `to` without loss, so a data connection
/// or a typed literal may carry it there (IEC 61131-3's implicit conversions): a wider
/// integer of the same signedness, an unsigned to a wider signed one, a wider bit string,
/// REAL to LREAL, and integers to a REAL (up to 16 bits) or LREAL (up to 32 bits).
pub fn widens(from: DataType, to: DataType) -> bool {
    use DataType::*;
    let signed = |t| match t {
        SInt => Some(8),
        Int => Some(16),
        DInt => Some(32),
        LInt => Some(64),
        _ => None,
    };
    let unsigned = |t| match t {
        USInt => Some(8),
        UInt => Some(16),
        UDInt => Some(32),
        ULInt => Some(64),
        _ => None,
    };
    let bits = |t| match t {
        Byte => Some(8),
        Word => Some(16),
        DWord => Some(32),
        LWord => Some(64),
        _ => None,
    };
    let int = |t| signed(t).or(unsigned(t));
    match (from, to) {
        _ if from == to => true,
        (Real, LReal) => true,
        (f, Real) => int(f).is_some_and(|b| b <= 16),
        (f, LReal) => int(f).is_some_and(|b| b <= 32),
        (f, t) if signed(f).is_some() => signed(f) < signed(t),
        (f, t) if unsigned(f).is_some() => {
            unsigned(f) < unsigned(t) || signed(t).is_some_and(|b| Some(b) > unsigned(f))
        }
        (f, t) => bits(f).is_some() && bits(f) < bits(t),
    }
}

/// `v`, a value of a type that [`widens`] to `to`, as a value of `to`.
pub fn widen(v: Value, to: DataType) -> Value {
    use DataType::*;
    match (v, to) {
        (Value::Int(i), Real | LReal) => Value::Real(i as f64),
        (Value::UInt(u), Real | LReal) => Value::Real(u as f64),
        (Value::UInt(u), SInt | Int | DInt | LInt) => Value::Int(u as i64),
        (v, _) => v,
    }
}

/// A value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Bool(bool),
    Int(i64),
    UInt(u64),
    Real(f64),
    /// Nanoseconds.
    Time(i64),
    String(String),
    Array(Vec<Value>),
}

/// FALSE: a value that owns nothing (the event queue's empty slots hold it).
impl Default for Value {
    fn default() -> Self {
        Value::Bool(false)
    }
}

impl Value {
    /// Whether the value is a scalar, which owns nothing.
    #[inline(always)]
    pub fn is_scalar(&self) -> bool {
        !matches!(self, Value::String(_) | Value::Array(_))
    }

    /// Stores `value` here: `*self = value`, but without a drop to run when the value
    /// replaced is a scalar (the usual case, and the resource's innermost loop).
    #[inline(always)]
    pub fn set(&mut self, value: Value) {
        if self.is_scalar() {
            // A scalar owns nothing: forgetting it leaks nothing.
            core::mem::forget(core::mem::replace(self, value));
        } else {
            *self = value;
        }
    }

    pub fn as_bool(&self) -> bool {
        match self {
            Value::Bool(b) => *b,
            Value::Int(i) => *i != 0,
            Value::UInt(u) => *u != 0,
            _ => false,
        }
    }

    /// The value as an unsigned count (negative and non-numeric values are 0).
    pub fn as_u64(&self) -> u64 {
        match self {
            Value::UInt(u) => *u,
            Value::Int(i) => (*i).max(0) as u64,
            Value::Bool(b) => u64::from(*b),
            _ => 0,
        }
    }

    /// The value as nanoseconds (0 for a value that is not a TIME).
    pub fn as_time(&self) -> i64 {
        match self {
            Value::Time(t) => *t,
            _ => 0,
        }
    }
}
