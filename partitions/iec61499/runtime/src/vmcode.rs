//! A basic FB type's algorithms and guards as verified PLC bytecode: one program whose
//! `__SEL` variable picks the algorithm (`0..n`) or the guard (`GUARD_BASE + k`, which
//! writes `__GUARD`), built from the type's ST by the host (`iec61499-build`) and verified
//! here before the first instance exists. A call copies the FB's variables into the
//! program, runs one cycle of its task, and copies the outputs and internal variables back;
//! a trap of the bytecode is the algorithm's trap ([`crate::Fault::Trap`]).

use crate::basic::{Algorithms, Vars};
use crate::fb::VarSpec;
use crate::value::{DataType, Value};
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec;
use alloc::vec::Vec;
use plc_vm::image::Image;
use plc_vm::monitor::Value as VmValue;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

/// `__SEL` of guard `k` is `GUARD_BASE + k`.
pub const GUARD_BASE: i64 = 1_000_000;
/// The program instance's name in the image's variable map.
pub const INSTANCE: &str = "FB";
/// The instruction budget of one algorithm or guard (the watchdog of a runaway loop).
pub const BUDGET: u32 = 1_000_000;

/// The compiled code of a basic FB type, shared by its instances.
#[derive(Clone, Debug)]
pub struct VmCode {
    image: Vec<u8>,
    /// Inputs, outputs and internals, in the order of [`Vars`]' three slices.
    inputs: Vec<VarSpec>,
    outputs: Vec<VarSpec>,
    internals: Vec<VarSpec>,
    algorithms: usize,
    guards: usize,
    data: Vec<u8>,
}

impl VmCode {
    /// Checks `image` (structure, verification, a task, the variables) for a type with
    /// these variables, `algorithms` algorithms and `guards` guards.
    pub fn new(
        image: Vec<u8>,
        inputs: Vec<VarSpec>,
        outputs: Vec<VarSpec>,
        internals: Vec<VarSpec>,
        algorithms: usize,
        guards: usize,
    ) -> Result<Self, String> {
        let parsed = Image::parse(&image).map_err(|e| format!("bytecode image: {e:?}"))?;
        plc_vm::verify::verify(&parsed).map_err(|e| format!("bytecode does not verify: {e:?}"))?;
        if parsed.task(0).is_none() {
            return Err("bytecode image has no task".into());
        }
        for var in inputs.iter().chain(&outputs).chain(&internals) {
            if var.array.is_none()
                && parsed
                    .find_var(&format!("{INSTANCE}.{}", var.name))
                    .is_none()
            {
                return Err(format!("bytecode image lacks variable {}", var.name));
            }
        }
        for name in ["__SEL", "__GUARD"] {
            if parsed.find_var(&format!("{INSTANCE}.{name}")).is_none() {
                return Err(format!("bytecode image lacks {name}"));
            }
        }
        let data = vec![0; parsed.data_size() as usize];
        Ok(VmCode {
            image,
            inputs,
            outputs,
            internals,
            algorithms,
            guards,
            data,
        })
    }

    /// The bytecode image.
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    /// Runs the code selected by `selector` on `vars`; returns `__GUARD`.
    fn call(&mut self, selector: i64, vars: &mut Vars<'_>) -> Result<bool, String> {
        let parsed = Image::parse(&self.image).map_err(|e| format!("{e:?}"))?;
        let verified = plc_vm::verify::verify(&parsed).map_err(|e| format!("{e:?}"))?;
        let mut stack = [0u64; 256];
        let mut calls = [CallFrame::EMPTY; 32];
        let mut tries = [TryFrame::EMPTY; 8];
        let memory = Memory {
            data: &mut self.data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        };
        let mut machine = Machine::new(verified, memory).map_err(|e| format!("{e:?}"))?;
        machine.set_watchdog_budget(0, Some(BUDGET));
        let sections: [(&[VarSpec], &[Value]); 3] = [
            (&self.inputs, vars.inputs),
            (&self.outputs, &*vars.outputs),
            (&self.internals, &*vars.internals),
        ];
        for (specs, values) in sections {
            for (spec, value) in specs.iter().zip(values) {
                store(&mut machine, spec, value)?;
            }
        }
        machine
            .write_var(&format!("{INSTANCE}.__SEL"), VmValue::Int(selector))
            .map_err(|e| format!("__SEL: {e:?}"))?;
        if let Err(fault) = machine.run_cycle(0, 0) {
            return Err(fault.trap.name().to_string());
        }
        for (specs, values) in [
            (&self.outputs, &mut *vars.outputs),
            (&self.internals, &mut *vars.internals),
        ] {
            for (spec, value) in specs.iter().zip(values.iter_mut()) {
                if let Some(v) = load(&machine, spec)? {
                    *value = v;
                }
            }
        }
        match machine.read_var(&format!("{INSTANCE}.__GUARD")) {
            Ok(VmValue::Bool(b)) => Ok(b),
            _ => Err("__GUARD is not a BOOL".into()),
        }
    }
}

/// A scalar's name in the image; array elements as `NAME[i]`.
fn names(spec: &VarSpec) -> Vec<String> {
    match spec.array {
        None => vec![format!("{INSTANCE}.{}", spec.name)],
        Some(n) => (0..n)
            .map(|i| format!("{INSTANCE}.{}[{i}]", spec.name))
            .collect(),
    }
}

fn to_vm(ty: DataType, value: &Value) -> Option<VmValue<'_>> {
    Some(match (ty, value) {
        (_, Value::Bool(b)) => VmValue::Bool(*b),
        (DataType::Real, Value::Real(r)) => VmValue::Real(*r as f32),
        (_, Value::Real(r)) => VmValue::LReal(*r),
        (_, Value::Int(i)) => VmValue::Int(*i),
        (_, Value::UInt(u)) => VmValue::UInt(*u),
        (_, Value::Time(t)) => VmValue::Time(*t),
        (_, Value::String(s)) => VmValue::String(s.as_bytes()),
        (_, Value::Array(_)) => return None,
    })
}

fn from_vm(value: VmValue<'_>) -> Option<Value> {
    Some(match value {
        VmValue::Bool(b) => Value::Bool(b),
        VmValue::Int(i) => Value::Int(i),
        VmValue::UInt(u) => Value::UInt(u),
        VmValue::Real(r) => Value::Real(f64::from(r)),
        VmValue::LReal(r) => Value::Real(r),
        VmValue::Time(t) => Value::Time(t),
        VmValue::String(s) => Value::String(String::from_utf8_lossy(s).into_owned()),
        _ => return None,
    })
}

fn store(machine: &mut Machine<'_, '_>, spec: &VarSpec, value: &Value) -> Result<(), String> {
    let elements: Vec<&Value> = match value {
        Value::Array(items) => items.iter().collect(),
        single => vec![single],
    };
    for (name, element) in names(spec).iter().zip(elements) {
        let v = to_vm(spec.ty, element)
            .ok_or_else(|| format!("{name}: nested arrays are not supported"))?;
        machine
            .write_var(name, v)
            .map_err(|e| format!("{name}: {e:?}"))?;
    }
    Ok(())
}

fn load(machine: &Machine<'_, '_>, spec: &VarSpec) -> Result<Option<Value>, String> {
    let mut values = Vec::new();
    for name in names(spec) {
        let v = machine
            .read_var(&name)
            .map_err(|e| format!("{name}: {e:?}"))?;
        match from_vm(v) {
            Some(v) => values.push(v),
            None => return Ok(None),
        }
    }
    Ok(Some(match spec.array {
        None => values.pop().unwrap_or(Value::Bool(false)),
        Some(_) => Value::Array(values),
    }))
}

impl Algorithms for VmCode {
    fn run(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<(), String> {
        self.call(index as i64, vars).map(|_| ())
    }

    fn guard(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<bool, String> {
        self.call(GUARD_BASE + index as i64, vars)
    }

    fn counts(&self) -> (usize, usize) {
        (self.algorithms, self.guards)
    }
}
