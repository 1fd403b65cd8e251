//! Host runner behind `plcc run`: simulated clock, task scheduling, `--set`/`--print`, trap
//! reporting. Also used by the corpus tests and the differential test against the VM's
//! reference model (which share [`Scheduler`]).

use plc_vm::image::Image;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

use crate::Compiled;
use crate::monitor::{self, MonitorVar};

/// Operand stack cells given to the VM.
pub const STACK_CELLS: usize = 256;
/// Call frames (including the task's own activation).
pub const CALL_FRAMES: usize = 32;
/// Simultaneously open `__TRY` blocks.
pub const TRY_FRAMES: usize = 16;
/// Exit code of a run that ended with an uncaught trap.
pub const EXIT_TRAP: i32 = 3;

/// Options of `plcc run`.
#[derive(Debug, Clone)]
pub struct RunConfig {
    pub cycles: u64,
    /// Cycle interval without a CONFIGURATION (ns).
    pub interval_ns: i64,
    pub print: Vec<String>,
    /// `NAME=VALUE` pairs applied once, before the first cycle.
    pub set: Vec<(String, String)>,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            cycles: 1,
            interval_ns: 10_000_000,
            print: Vec::new(),
            set: Vec::new(),
        }
    }
}

/// What a run printed and how it ended.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOutput {
    pub stdout: String,
    pub stderr: String,
    pub exit_code: i32,
}

fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// Decides which image tasks run at each base tick.
#[derive(Debug, Clone)]
pub struct Scheduler {
    pub tick_ns: i64,
    /// Task indices (into `Compiled::tasks`) in execution order: priority, then declaration.
    order: Vec<usize>,
    /// Last sampled value of each event task's trigger.
    prev_trigger: Vec<bool>,
}

impl Scheduler {
    pub fn new(c: &Compiled, default_interval_ns: i64) -> Scheduler {
        let tick = c
            .tasks
            .iter()
            .map(|t| t.interval_ns)
            .filter(|&i| i > 0)
            .fold(0, gcd);
        let tick_ns = if !c.has_configuration || tick == 0 {
            default_interval_ns.max(1)
        } else {
            tick
        };
        let mut order: Vec<usize> = (0..c.tasks.len()).collect();
        order.sort_by_key(|&i| (c.tasks[i].priority, i));
        Scheduler {
            tick_ns,
            order,
            prev_trigger: vec![false; c.tasks.len()],
        }
    }

    /// Simulated time of cycle `k` (1-based): starts at 0, one tick per cycle.
    pub fn now(&self, k: u64) -> i64 {
        (k as i64 - 1).saturating_mul(self.tick_ns)
    }

    /// Image task indices due at cycle `k`, in the order they must run.
    pub fn due(&mut self, c: &Compiled, k: u64, data: &[u8]) -> Vec<usize> {
        let now = self.now(k);
        let mut out = Vec::new();
        for &ti in &self.order {
            let t = &c.tasks[ti];
            let due = match t.single_addr {
                Some(addr) => {
                    let v = data.get(addr as usize).is_some_and(|b| *b != 0);
                    let edge = v && !self.prev_trigger[ti];
                    self.prev_trigger[ti] = v;
                    edge
                }
                None => t.interval_ns <= 0 || now % t.interval_ns == 0,
            };
            if due {
                out.extend(t.image_tasks.iter().copied());
            }
        }
        out
    }
}

/// Resolves `--print` names; unknown names are an error message.
pub fn resolve_prints<'c>(
    c: &'c Compiled,
    names: &[String],
) -> Result<Vec<(&'c MonitorVar, String)>, String> {
    names
        .iter()
        .map(|n| match monitor::find(&c.vars, n) {
            Some(v) => Ok((v, n.clone())),
            None => Err(format!("unknown variable `{n}` in --print (names look like Main.x, pf.n, g, Main.s.a, Main.arr[2])")),
        })
        .collect()
}

/// Applies `--set` values to data memory.
pub fn apply_sets(c: &Compiled, sets: &[(String, String)], data: &mut [u8]) -> Result<(), String> {
    for (name, value) in sets {
        let v = monitor::find(&c.vars, name)
            .ok_or_else(|| format!("unknown variable `{name}` in --set"))?;
        monitor::write_value(v, value, data).map_err(|e| format!("--set {name}: {e}"))?;
    }
    Ok(())
}

/// One output line for cycle `k` (`vars`: the whole variable map, to name references).
pub fn cycle_line(
    k: u64,
    prints: &[(&MonitorVar, String)],
    vars: &[MonitorVar],
    data: &[u8],
) -> String {
    let mut line = format!("cycle {k}:");
    for (v, name) in prints {
        line.push_str(&format!(
            " {}={}",
            name,
            monitor::format_value(v, vars, data)
        ));
    }
    line
}

/// Runs a compiled program on the host VM as `plcc run` does.
pub fn run(c: &Compiled, cfg: &RunConfig) -> RunOutput {
    let mut out = RunOutput {
        stdout: String::new(),
        stderr: String::new(),
        exit_code: 0,
    };
    let fail = |mut out: RunOutput, msg: String, code: i32| {
        out.stderr.push_str(&msg);
        out.stderr.push('\n');
        out.exit_code = code;
        out
    };
    let prints = match resolve_prints(c, &cfg.print) {
        Ok(p) => p,
        Err(e) => return fail(out, e, 2),
    };
    let image = match Image::parse(&c.image) {
        Ok(i) => i,
        Err(e) => return fail(out, format!("invalid image: {e}"), 1),
    };
    let verified = match plc_vm::verify::verify(&image) {
        Ok(v) => v,
        Err(e) => return fail(out, format!("image rejected by the verifier: {e}"), 1),
    };
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = vec![0u64; STACK_CELLS];
    let mut calls = vec![CallFrame::EMPTY; CALL_FRAMES];
    let mut tries = vec![TryFrame::EMPTY; TRY_FRAMES];
    let memory = Memory {
        data: &mut data,
        stack: &mut stack,
        calls: &mut calls,
        tries: &mut tries,
    };
    let mut m = match Machine::new(verified, memory) {
        Ok(m) => m,
        Err(e) => return fail(out, format!("cannot start the VM: {e:?}"), 1),
    };
    if let Err(e) = apply_sets(c, &cfg.set, m.data_mut()) {
        return fail(out, e, 2);
    }
    let mut sched = Scheduler::new(c, cfg.interval_ns);
    for k in 1..=cfg.cycles {
        let now = sched.now(k);
        let due = sched.due(c, k, m.data());
        for task in due {
            if let Err(fault) = m.run_cycle(task, now) {
                out.stdout
                    .push_str(&format!("cycle {k}: trap {}\n", fault.trap.name()));
                let loc = match fault.location {
                    Some(l) => format!(
                        "{}:{}:{}",
                        image.file_name(l.file).unwrap_or("?"),
                        l.line,
                        l.column
                    ),
                    None => format!("code offset {}", fault.code_offset),
                };
                let task_name = image.task(task).map_or("?", |t| t.name);
                out.stderr.push_str(&format!(
                    "{loc}: run-time error: trap {} in task {task_name} (cycle {k}, time {})\n",
                    fault.trap.name(),
                    monitor::format_time(now)
                ));
                out.exit_code = EXIT_TRAP;
                return out;
            }
        }
        out.stdout
            .push_str(&cycle_line(k, &prints, &c.vars, m.data()));
        out.stdout.push('\n');
    }
    out
}
