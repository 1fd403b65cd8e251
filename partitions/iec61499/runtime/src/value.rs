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

impl Value {
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
