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
use alloc::sync::Arc;
use alloc::vec;
use alloc::vec::Vec;
use plc_vm::image::Image;
use plc_vm::monitor::Value as VmValue;
use plc_vm::verify::VerifiedBytes;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

/// `__SEL` of guard `k` is `GUARD_BASE + k`.
pub const GUARD_BASE: i64 = 1_000_000;
/// The program instance's name in the image's variable map.
pub const INSTANCE: &str = "FB";
/// The instruction budget of one algorithm or guard (the watchdog of a runaway loop).
pub const BUDGET: u32 = 1_000_000;

/// The compiled code of a basic FB type: verified once, shared by the type's instances
/// (cloning shares it), each instance with its own data memory.
#[derive(Clone, Debug)]
pub struct VmCode {
    code: Arc<Code>,
    data: Vec<u8>,
}

/// What every instance of a type shares: the verified image and where each FB variable
/// lies in it, looked up once.
#[derive(Debug)]
struct Code {
    image: VerifiedBytes,
    inputs: Vec<Slot>,
    outputs: Vec<Slot>,
    internals: Vec<Slot>,
    selector: usize,
    guard: usize,
    algorithms: usize,
    guards: usize,
}

/// An FB variable and the indexes of its entries in the image's variable map (one for a
/// scalar, one per element for an array).
#[derive(Debug)]
struct Slot {
    spec: VarSpec,
    entries: Vec<usize>,
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
        let image = VerifiedBytes::new(image).map_err(|e| match e {
            plc_vm::verify::OwnedImageError::Image(e) => format!("bytecode image: {e:?}"),
            plc_vm::verify::OwnedImageError::Verify(e) => format!("bytecode does not verify: {e}"),
        })?;
        let parsed = *image.image().image();
        if parsed.task(0).is_none() {
            return Err("bytecode image has no task".into());
        }
        let entry = |name: &str| {
            parsed
                .find_var_index(&format!("{INSTANCE}.{name}"))
                .ok_or_else(|| format!("bytecode image lacks variable {name}"))
        };
        let slots = |specs: Vec<VarSpec>| -> Result<Vec<Slot>, String> {
            specs
                .into_iter()
                .map(|spec| {
                    let entries = match spec.array {
                        None => vec![entry(&spec.name)?],
                        Some(n) => (0..n)
                            .map(|i| entry(&format!("{}[{i}]", spec.name)))
                            .collect::<Result<_, _>>()?,
                    };
                    Ok(Slot { spec, entries })
                })
                .collect()
        };
        let (inputs, outputs, internals) = (slots(inputs)?, slots(outputs)?, slots(internals)?);
        let (selector, guard) = (entry("__SEL")?, entry("__GUARD")?);
        let data = vec![0; parsed.data_size() as usize];
        let code = Code {
            image,
            inputs,
            outputs,
            internals,
            selector,
            guard,
            algorithms,
            guards,
        };
        Ok(VmCode {
            code: Arc::new(code),
            data,
        })
    }

    /// The bytecode image.
    pub fn image(&self) -> &[u8] {
        self.code.image.bytes()
    }

    /// Runs `f` on a machine over this instance's data, which [`Machine::new`] sets to the
    /// image's initial data.
    fn with_machine<R>(
        &mut self,
        f: impl FnOnce(&mut Machine<'_, '_>, &Image<'_>, &Code) -> Result<R, String>,
    ) -> Result<R, String> {
        let code = &*self.code;
        let verified = code.image.image();
        let image = *verified.image();
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
        f(&mut machine, &image, code)
    }

    /// Runs the code selected by `selector` on `vars`; returns `__GUARD`.
    fn call(&mut self, selector: i64, vars: &mut Vars<'_>) -> Result<bool, String> {
        self.with_machine(|machine, image, code| run(machine, image, code, selector, vars))
    }
}

/// Copies `vars` in, runs one cycle with `__SEL = selector`, copies the outputs and
/// internals out; returns `__GUARD`.
fn run(
    machine: &mut Machine<'_, '_>,
    image: &Image<'_>,
    code: &Code,
    selector: i64,
    vars: &mut Vars<'_>,
) -> Result<bool, String> {
    let sections: [(&[Slot], &[Value]); 3] = [
        (&code.inputs, vars.inputs),
        (&code.outputs, &*vars.outputs),
        (&code.internals, &*vars.internals),
    ];
    for (slots, values) in sections {
        for (slot, value) in slots.iter().zip(values) {
            store(machine, image, slot, value)?;
        }
    }
    let selector = VmValue::Int(selector);
    write(machine, image, code.selector, selector, "__SEL")?;
    if let Err(fault) = machine.run_cycle(0, 0) {
        return Err(fault.trap.name().to_string());
    }
    for (slots, values) in [
        (&code.outputs, &mut *vars.outputs),
        (&code.internals, &mut *vars.internals),
    ] {
        load_into(machine, image, slots, values);
    }
    match image.var(code.guard).map(|var| machine.read_entry(&var)) {
        Some(VmValue::Bool(b)) => Ok(b),
        _ => Err("__GUARD is not a BOOL".into()),
    }
}

/// Sets each of `values` to its slot's value in the machine (one whose type the FB values
/// do not represent keeps its value).
fn load_into(machine: &Machine<'_, '_>, image: &Image<'_>, slots: &[Slot], values: &mut [Value]) {
    for (slot, value) in slots.iter().zip(values.iter_mut()) {
        if let Some(v) = load(machine, image, slot) {
            *value = v;
        }
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

fn write(
    machine: &mut Machine<'_, '_>,
    image: &Image<'_>,
    entry: usize,
    value: VmValue<'_>,
    what: &str,
) -> Result<(), String> {
    let var = image
        .var(entry)
        .ok_or_else(|| format!("{what}: no variable-map entry {entry}"))?;
    machine
        .write_entry(&var, value)
        .map_err(|e| format!("{}: {e:?}", var.name))
}

fn store(
    machine: &mut Machine<'_, '_>,
    image: &Image<'_>,
    slot: &Slot,
    value: &Value,
) -> Result<(), String> {
    let elements: Vec<&Value> = match value {
        Value::Array(items) => items.iter().collect(),
        single => vec![single],
    };
    for (&entry, element) in slot.entries.iter().zip(elements) {
        let v = to_vm(slot.spec.ty, element)
            .ok_or_else(|| format!("{}: nested arrays are not supported", slot.spec.name))?;
        write(machine, image, entry, v, &slot.spec.name)?;
    }
    Ok(())
}

/// The value of `slot` after a call, or `None` if one of its entries has a type the FB
/// values do not represent (left as it was).
fn load(machine: &Machine<'_, '_>, image: &Image<'_>, slot: &Slot) -> Option<Value> {
    let mut values = Vec::with_capacity(slot.entries.len());
    for &entry in &slot.entries {
        values.push(from_vm(machine.read_entry(&image.var(entry)?))?);
    }
    Some(match slot.spec.array {
        None => values.pop()?,
        Some(_) => Value::Array(values),
    })
}

impl Algorithms for VmCode {
    fn run(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<(), String> {
        self.call(index as i64, vars).map(|_| ())
    }

    fn guard(&mut self, index: usize, vars: &mut Vars<'_>) -> Result<bool, String> {
        self.call(GUARD_BASE + index as i64, vars)
    }

    fn counts(&self) -> (usize, usize) {
        (self.code.algorithms, self.code.guards)
    }

    fn initialise(&mut self, internals: &mut [Value]) {
        // A fresh machine holds the image's initial data: the declared initial values.
        let _ = self.with_machine(|machine, image, code| {
            load_into(machine, image, &code.internals, internals);
            Ok(())
        });
    }

    fn initialise_interface(&mut self, inputs: &mut [Value], outputs: &mut [Value]) {
        let _ = self.with_machine(|machine, image, code| {
            load_into(machine, image, &code.inputs, inputs);
            load_into(machine, image, &code.outputs, outputs);
            Ok(())
        });
    }
}
