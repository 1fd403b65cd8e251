//! The function FBs of 4diac's IEC 61131-3 library (`F_ADD`, `F_EQ`, `F_MUX_2`, ...), written
//! from IEC 61131-3's standard functions: REQ with the inputs, the function computed, CNF
//! with OUT. They are generic: an input or output declared `ANY_*` has no type until the
//! first data connection to a typed port or the first typed literal written to it
//! ([`Resource::connect_data`](crate::Resource::connect_data),
//! [`Resource::bind`](crate::Resource::bind)) gives it one, and with it every variable of
//! its group (F_ADD's IN1, IN2 and OUT are one group; F_MUX_2's K is a group of its own), as
//! 4diac's typed instances of the generic types. A type outside the variable's class
//! (ANY_BIT for F_AND, ANY_INT for F_MOD, ...) is refused.
//!
//! Arithmetic wraps to the type's width (IEC 61131-3 leaves overflow open); an integer
//! division or MOD by zero fails the FB (the resource stops with a trap, as an ST algorithm
//! dividing by zero does). F_MUX_2 with K out of range sends CNF with OUT unchanged (FORTE
//! logs an error and does the same). A REQ before the types are known computes nothing and
//! sends CNF.

use crate::fb::{Context, EventSpec, FunctionBlock, Interface, VarSpec};
use crate::value::{DataType, Value};
use alloc::boxed::Box;
use alloc::vec::Vec;
use core::cmp::Ordering;

/// The types this module provides.
pub const TYPES: [&str; 20] = [
    "F_ADD", "F_SUB", "F_MUL", "F_DIV", "F_MOD", "F_EQ", "F_NE", "F_GT", "F_GE", "F_LT", "F_LE",
    "F_AND", "F_OR", "F_XOR", "F_NOT", "F_MOVE", "F_SEL", "F_MUX_2", "F_MAX", "F_MIN",
];

/// The types a generic variable may take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Class {
    /// ANY, ANY_ELEMENTARY.
    Any,
    /// ANY_MAGNITUDE: numbers and TIME.
    Magnitude,
    /// ANY_INT.
    Int,
    /// ANY_BIT.
    Bit,
}

impl Class {
    fn admits(self, ty: DataType) -> bool {
        use DataType::*;
        let int = matches!(ty, SInt | Int | DInt | LInt | USInt | UInt | UDInt | ULInt);
        match self {
            Class::Any => true,
            Class::Magnitude => int || matches!(ty, Real | LReal | Time),
            Class::Int => int,
            Class::Bit => matches!(ty, Bool | Byte | Word | DWord | LWord),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    Add,
    Sub,
    Mul,
    Div,
    Mod,
    /// A comparison: true when the order of IN1 to IN2 is one of these.
    Cmp([Option<Ordering>; 2]),
    And,
    Or,
    Xor,
    Not,
    Move,
    Sel,
    Mux2,
    Max,
    Min,
}

/// A variable of the interface: its name and, for a generic one, its group and class.
type Decl = (&'static str, Option<(usize, Class)>);

/// The placeholder type of a variable whose type is not known yet.
const UNBOUND: DataType = DataType::LWord;

/// A generic function FB.
struct Function {
    op: Op,
    interface: Interface,
    /// Per input, then per output: the generic group and class, `None` for a fixed type.
    generic: Vec<Option<(usize, Class)>>,
    /// Each group's type once bound.
    groups: [Option<DataType>; 2],
}

/// A new instance of function FB `ty`, or `None` for a name this module does not have.
pub fn create(ty: &str) -> Option<Box<dyn FunctionBlock>> {
    use Class::*;
    const G: Option<(usize, Class)> = Some((0, Any));
    let two = |class| -> (Vec<Decl>, Vec<Decl>) {
        let g = Some((0, class));
        (vec_of(&[("IN1", g), ("IN2", g)]), vec_of(&[("OUT", g)]))
    };
    let compare = || (vec_of(&[("IN1", G), ("IN2", G)]), vec_of(&[("OUT", None)]));
    let (op, (inputs, outputs)) = match ty {
        "F_ADD" => (Op::Add, two(Magnitude)),
        "F_SUB" => (Op::Sub, two(Magnitude)),
        "F_MUL" => (Op::Mul, two(Magnitude)),
        "F_DIV" => (Op::Div, two(Magnitude)),
        "F_MOD" => (Op::Mod, two(Int)),
        "F_EQ" => (Op::Cmp([Some(Ordering::Equal), None]), compare()),
        "F_NE" => (
            Op::Cmp([Some(Ordering::Less), Some(Ordering::Greater)]),
            compare(),
        ),
        "F_GT" => (Op::Cmp([Some(Ordering::Greater), None]), compare()),
        "F_GE" => (
            Op::Cmp([Some(Ordering::Greater), Some(Ordering::Equal)]),
            compare(),
        ),
        "F_LT" => (Op::Cmp([Some(Ordering::Less), None]), compare()),
        "F_LE" => (
            Op::Cmp([Some(Ordering::Less), Some(Ordering::Equal)]),
            compare(),
        ),
        "F_AND" => (Op::And, two(Bit)),
        "F_OR" => (Op::Or, two(Bit)),
        "F_XOR" => (Op::Xor, two(Bit)),
        "F_NOT" => (
            Op::Not,
            (
                vec_of(&[("IN", Some((0, Bit)))]),
                vec_of(&[("OUT", Some((0, Bit)))]),
            ),
        ),
        "F_MOVE" => (Op::Move, (vec_of(&[("IN", G)]), vec_of(&[("OUT", G)]))),
        "F_SEL" => (
            Op::Sel,
            (
                vec_of(&[("G", None), ("IN0", G), ("IN1", G)]),
                vec_of(&[("OUT", G)]),
            ),
        ),
        "F_MUX_2" => (
            Op::Mux2,
            (
                vec_of(&[("K", Some((1, Int))), ("IN1", G), ("IN2", G)]),
                vec_of(&[("OUT", G)]),
            ),
        ),
        "F_MAX" => (Op::Max, two(Any)),
        "F_MIN" => (Op::Min, two(Any)),
        _ => return None,
    };
    // Fixed types: F_SEL's G and the comparisons' OUT are BOOL.
    let spec = |(name, generic): &Decl| VarSpec {
        name: (*name).into(),
        ty: if generic.is_some() {
            UNBOUND
        } else {
            DataType::Bool
        },
        array: None,
    };
    let input_with: Vec<usize> = (0..inputs.len()).collect();
    let interface = Interface {
        event_inputs: alloc::vec![EventSpec {
            name: "REQ".into(),
            with: input_with,
        }],
        event_outputs: alloc::vec![EventSpec {
            name: "CNF".into(),
            with: alloc::vec![0],
        }],
        inputs: inputs.iter().map(spec).collect(),
        outputs: outputs.iter().map(spec).collect(),
        adapters: Vec::new(),
    };
    Some(Box::new(Function {
        op,
        interface,
        generic: inputs.iter().chain(&outputs).map(|(_, g)| *g).collect(),
        groups: [None, None],
    }))
}

fn vec_of(decls: &[Decl]) -> Vec<Decl> {
    decls.to_vec()
}

/// Bits of an integer or bit-string type.
fn bits(ty: DataType) -> u32 {
    use DataType::*;
    match ty {
        SInt | USInt | Byte => 8,
        Int | UInt | Word => 16,
        DInt | UDInt | DWord => 32,
        _ => 64,
    }
}

/// `v` wrapped to the width of integer type `ty`, as its value.
fn wrap(ty: DataType, v: i128) -> Value {
    use DataType::*;
    let b = bits(ty);
    if matches!(ty, SInt | Int | DInt | LInt) {
        let shift = 128 - b;
        Value::Int(((v << shift) >> shift) as i64)
    } else {
        let mask = if b == 64 { u64::MAX } else { (1u64 << b) - 1 };
        Value::UInt((v as u64) & mask)
    }
}

fn int(v: &Value) -> i128 {
    match v {
        Value::Int(i) => i128::from(*i),
        Value::UInt(u) => i128::from(*u),
        Value::Bool(b) => i128::from(*b),
        Value::Time(t) => i128::from(*t),
        _ => 0,
    }
}

fn real(v: &Value) -> f64 {
    match v {
        Value::Real(r) => *r,
        other => int(other) as f64,
    }
}

/// The order of two values of one type.
fn order(a: &Value, b: &Value) -> Ordering {
    match (a, b) {
        (Value::Real(x), Value::Real(y)) => x.partial_cmp(y).unwrap_or(Ordering::Equal),
        (Value::String(x), Value::String(y)) => x.cmp(y),
        _ => int(a).cmp(&int(b)),
    }
}

/// `a op b` for arithmetic on type `ty`; `Err` for a division by zero.
fn arithmetic(op: Op, ty: DataType, a: &Value, b: &Value) -> Result<Value, &'static str> {
    if matches!(ty, DataType::Real | DataType::LReal) {
        let (x, y) = (real(a), real(b));
        let r = match op {
            Op::Add => x + y,
            Op::Sub => x - y,
            Op::Mul => x * y,
            _ => x / y,
        };
        return Ok(Value::Real(if ty == DataType::Real {
            f64::from(r as f32)
        } else {
            r
        }));
    }
    let (x, y) = (int(a), int(b));
    if matches!(op, Op::Div | Op::Mod) && y == 0 {
        return Err("integer division by zero");
    }
    let r = match op {
        Op::Add => x.wrapping_add(y),
        Op::Sub => x.wrapping_sub(y),
        Op::Mul => x.wrapping_mul(y),
        Op::Div => x / y,
        _ => x % y,
    };
    Ok(match ty {
        DataType::Time => Value::Time(r as i64),
        _ => wrap(ty, r),
    })
}

/// A bitwise operation on type `ty` (`b` unused for NOT).
fn bitwise(op: Op, ty: DataType, a: &Value, b: &Value) -> Value {
    if ty == DataType::Bool {
        let (x, y) = (a.as_bool(), b.as_bool());
        return Value::Bool(match op {
            Op::And => x & y,
            Op::Or => x | y,
            Op::Xor => x ^ y,
            _ => !x,
        });
    }
    let (x, y) = (int(a), int(b));
    wrap(
        ty,
        match op {
            Op::And => x & y,
            Op::Or => x | y,
            Op::Xor => x ^ y,
            _ => !x,
        },
    )
}

impl Function {
    fn slot(&self, output: bool, index: usize) -> usize {
        if output {
            self.interface.inputs.len() + index
        } else {
            index
        }
    }
}

impl FunctionBlock for Function {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn untyped(&self, output: bool, index: usize) -> bool {
        let slot = self.slot(output, index);
        matches!(self.generic.get(slot), Some(Some((g, _))) if self.groups[*g].is_none())
    }

    fn bind_generic(&mut self, output: bool, index: usize, ty: DataType) -> bool {
        let slot = self.slot(output, index);
        let Some(Some((group, class))) = self.generic.get(slot).copied() else {
            return false;
        };
        if self.groups[group].is_some() || !class.admits(ty) {
            return false;
        }
        self.groups[group] = Some(ty);
        let inputs = self.interface.inputs.len();
        for (slot, g) in self.generic.iter().enumerate() {
            if matches!(g, Some((x, _)) if *x == group) {
                let var = if slot < inputs {
                    &mut self.interface.inputs[slot]
                } else {
                    &mut self.interface.outputs[slot - inputs]
                };
                var.ty = ty;
            }
        }
        true
    }

    fn event(&mut self, _: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        let Some(ty) = self.groups[0] else {
            ctx.send(0);
            return;
        };
        let out = match self.op {
            Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Mod => {
                match arithmetic(self.op, ty, &inputs[0], &inputs[1]) {
                    Ok(v) => Some(v),
                    Err(why) => {
                        ctx.fail(why.into());
                        return;
                    }
                }
            }
            Op::Cmp(holds) => Some(Value::Bool(
                holds.contains(&Some(order(&inputs[0], &inputs[1]))),
            )),
            Op::And | Op::Or | Op::Xor | Op::Not => Some(bitwise(
                self.op,
                ty,
                &inputs[0],
                inputs.get(1).unwrap_or(&inputs[0]),
            )),
            Op::Move => Some(inputs[0].clone()),
            Op::Sel => Some(inputs[if inputs[0].as_bool() { 2 } else { 1 }].clone()),
            Op::Mux2 => match int(&inputs[0]) {
                0 => Some(inputs[1].clone()),
                1 => Some(inputs[2].clone()),
                _ => None,
            },
            Op::Max | Op::Min => {
                let first = order(&inputs[0], &inputs[1]).is_ge() == (self.op == Op::Max);
                Some(inputs[if first { 0 } else { 1 }].clone())
            }
        };
        if let Some(v) = out {
            ctx.set(0, v);
        }
        ctx.send(0);
    }

    fn reset(&mut self) {}
}

#[cfg(test)]
mod tests;
