//! Data values of function-block inputs and outputs.

use alloc::string::String;
use alloc::vec::Vec;

/// The elementary types an interface declares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataType {
    Bool,
    SInt,
    Int,
    DInt,
    LInt,
    USInt,
    UInt,
    UDInt,
    ULInt,
    Byte,
    Word,
    DWord,
    LWord,
    Real,
    LReal,
    Time,
    String,
}

impl DataType {
    /// The type of an IEC name (`UINT`, `TIME`, ...).
    pub fn from_name(name: &str) -> Option<Self> {
        use DataType::*;
        Some(match name.to_ascii_uppercase().as_str() {
            "BOOL" => Bool,
            "SINT" => SInt,
            "INT" => Int,
            "DINT" => DInt,
            "LINT" => LInt,
            "USINT" => USInt,
            "UINT" => UInt,
            "UDINT" => UDInt,
            "ULINT" => ULInt,
            "BYTE" => Byte,
            "WORD" => Word,
            "DWORD" => DWord,
            "LWORD" => LWord,
            "REAL" => Real,
            "LREAL" => LReal,
            "TIME" => Time,
            "STRING" => String,
            _ => return None,
        })
    }

    /// The initial value of a variable of this type.
    pub fn zero(self) -> Value {
        use DataType::*;
        match self {
            Bool => Value::Bool(false),
            SInt | Int | DInt | LInt => Value::Int(0),
            USInt | UInt | UDInt | ULInt | Byte | Word | DWord | LWord => Value::UInt(0),
            Real | LReal => Value::Real(0.0),
            Time => Value::Time(0),
            String => Value::String(alloc::string::String::new()),
        }
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
