//! The soft-PLC's native execution tier: translates a **verified** bytecode image (never the
//! ST source) to Rust source that, compiled into the PLC partition's binary, runs the
//! program with exactly the interpreter's semantics.
//!
//! # The route, and why
//!
//! The image is translated to Rust at system-build time and compiled by rustc into the
//! partition's read-only text, like MatIEC/OpenPLC translate ST to C — but from verified
//! bytecode, with every check of the interpreter kept:
//!
//! * **One semantics.** The input is what the verifier accepted and the VM runs, so the
//!   native code inherits the verifier's guarantees (every instruction decodes, one static
//!   stack depth per instruction, jump targets inside the POU, static addresses inside data
//!   memory) and cannot diverge from the interpreter through a second front end. Translating
//!   ST directly would be a second compiler with its own bugs.
//! * **No new target dependency, no writable code.** The output is plain Rust over
//!   `plc_vm` (its [`plc_vm::native`] module, the math library [`plc_vm::fmath`] and the
//!   STRING functions [`plc_vm::builtins`], the very functions the VM calls). Cranelift AOT
//!   would bring a code generator and an object-file loader into the build or the partition;
//!   a JIT would need writable-and-executable memory. Here rustc/LLVM optimise (register
//!   allocation, instruction selection) and the kernel maps the code read-only and
//!   executable like the rest of the binary.
//! * **Exactness is checkable.** The generated code is compared with the executable
//!   reference model on thousands of random verified images and random ST programs and the
//!   whole compiler corpus, after every cycle (`tests/differential.rs`), as the VM is.
//!
//! The price: a changed program needs a rebuild to run natively (an online download runs on
//! the interpreter until the next build), and the build compiles Rust (seconds per program).
//!
//! # What the generated code looks like
//!
//! One function per POU reachable from a task or a method dispatch ([`emit`] shows the
//! shape). The verifier proved every instruction's operand-stack depth static, so the cells
//! of an activation's stack are Rust locals `s0, s1, ...` (register-allocated by LLVM;
//! floats travel as bit patterns, as in the VM). Jumps become structured control flow
//! (labeled loops and blocks with `continue`/`break`, from the dominator tree: [`structure`]),
//! so LLVM sees direct branches; only the entries from outside (the try handlers) and
//! irreducible parts go through a small dispatch. CALL is a Rust call with the argument cells
//! that returns the result cells; CALL_VIRT a call of one of the methods the slot can run.
//! Data memory is the machine's own byte array (same layout, so the monitor's reads and
//! forces by name keep working), as `&mut [u8; DATA_SIZE]`: static addresses, which the
//! verifier proved inside it, need no run-time check; frame-relative and indirect accesses are
//! checked as the interpreter checks them. A POU whose activations all have the same frame
//! base (a program instance, a FUNCTION's static frame) gets it as a constant, and the frame
//! variables its loops use live in locals where an abstract interpretation of the addresses
//! shows that no other access can touch them ([`promote`]), written back wherever data memory
//! can be observed (a call, a trap, the return).
//!
//! The interpreter's observable behaviour is kept instruction for instruction:
//!
//! * the instruction budget (WATCHDOG) and the deadline checks (DEADLINE, the clock asked
//!   every 1,024 instructions, at the same instruction counts as `run_cycle_until`): a
//!   block of `L` instructions is counted once at its start when no event falls inside it,
//!   else its *checked* copy runs it counting instruction by instruction, so a watchdog or
//!   deadline stops the cycle before exactly the instruction the VM stops before, and a
//!   completed cycle reports the VM's instruction count (fused instructions count one, as
//!   decoded);
//! * every trap at the same instruction with the same state (a trapping instruction has no
//!   effect: values are computed and checked before any cell or byte is written); operand
//!   stack overflow and call depth against the machine's limits (an activation whose stack
//!   might not fit runs the checked copies, which check every push);
//! * `__TRY`/`__CATCH`: the VM's try frames in the machine's try memory; a trap goes to the
//!   innermost frame (stack cut back, code pushed), through the Rust call chain when the
//!   frame belongs to a caller, or ends the cycle; RETHROW as the VM;
//! * after a fault, the machine's stack, `pc`, call and try depth are the interpreter's (the
//!   activations write their live cells back on the way out).
//!
//! One pattern is refused ([`Error::TryFrameOverCall`]: the build stops and says so; without
//! `plc.native` the interpreter runs the image): a try frame whose stack depth lies above the
//! first cell of a POU called while the frame is open (see `analysis::check_try_frames`);
//! the compiler never produces it.
//!
//! # Interface
//!
//! [`translate`] gives the module of one image (it exports `PROGRAM`, a
//! [`plc_vm::native::NativeProgram`]); [`bundle`] puts several into one file with the
//! table `PROGRAMS` that the PLC partition is built with (`plc.native = true`, see
//! `cargo xtask`); [`translate_every_pou`] translates a library (no tasks) for checking.
//! [`harness`] writes and builds a stand-alone workspace around generated modules (the
//! differential tests and the benchmark use it). `cargo run -p plc-native --example
//! translate -- IMAGE.plcb` prints the module of an image.
//!
//! This crate must never accept an image the verifier rejects, emit code for an opcode or
//! builtin it does not know ([`Error::UnsupportedOpcode`], [`Error::UnsupportedBuiltin`]),
//! or emit `unsafe` code.

pub mod analysis;
pub mod emit;
pub mod harness;
pub mod promote;
pub mod structure;

use plc_vm::image::Image;
use std::collections::BTreeSet;
use std::fmt::Write;

/// Why an image cannot be translated.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Error {
    /// Not a well-formed image.
    Image(plc_vm::ImageError),
    /// The verifier rejects it.
    Verify(plc_vm::VerifyError),
    /// An opcode this translator does not know (newer than it).
    UnsupportedOpcode {
        pc: u32,
        opcode: u8,
        mnemonic: &'static str,
    },
    /// A builtin this translator does not know.
    UnsupportedBuiltin { pc: u32, id: u16 },
    /// A try frame of `pou` may cover cells of the POU called at `pc` (see the crate
    /// documentation).
    TryFrameOverCall { pou: String, pc: u32 },
    /// An inconsistency in a verified image (a bug in the verifier or here).
    Internal(String),
}

impl Error {
    pub(crate) fn internal(what: String) -> Self {
        Error::Internal(what)
    }
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::Image(e) => write!(f, "not a bytecode image: {e}"),
            Error::Verify(e) => write!(f, "the verifier rejects the image: {e}"),
            Error::UnsupportedOpcode {
                pc,
                opcode,
                mnemonic,
            } => write!(
                f,
                "code offset {pc}: opcode 0x{opcode:02x} ({mnemonic}) is not supported by the native tier"
            ),
            Error::UnsupportedBuiltin { pc, id } => write!(
                f,
                "code offset {pc}: builtin {id} is not supported by the native tier"
            ),
            Error::TryFrameOverCall { pou, pc } => write!(
                f,
                "POU {pou}, code offset {pc}: a try frame covers stack cells of the POU called here; the native tier keeps them apart (the interpreter runs this image)"
            ),
            Error::Internal(what) => write!(f, "internal error: {what}"),
        }
    }
}

impl std::error::Error for Error {}

/// The POUs of the image's dispatch records (the methods `CALL_VIRT` may run).
fn dispatch_targets(image: &Image<'_>) -> Vec<usize> {
    (0..image.dispatch_count())
        .filter_map(|i| image.dispatch(i))
        .map(|m| m.pou as usize)
        .collect()
}

/// POUs reachable from the tasks through CALLs (and every method dispatch may run).
fn reachable_pous(image: &Image<'_>) -> BTreeSet<usize> {
    let mut seen = BTreeSet::new();
    let mut work: Vec<usize> = (0..image.task_count())
        .filter_map(|t| image.task(t))
        .map(|t| t.pou as usize)
        .chain(dispatch_targets(image))
        .collect();
    while let Some(index) = work.pop() {
        if !seen.insert(index) {
            continue;
        }
        let Some(pou) = image.pou(index) else {
            continue;
        };
        let code = image.code();
        let (start, end) = (
            pou.code_start as usize,
            (pou.code_start + pou.code_len) as usize,
        );
        let mut pc = start;
        while pc < end {
            let Some(insn) = plc_vm::isa::decode(code, pc) else {
                break;
            };
            if insn.op == plc_vm::Opcode::Call {
                work.push(u16::from_le_bytes([insn.immediates[0], insn.immediates[1]]) as usize);
            }
            pc += insn.op.size();
        }
    }
    seen
}

/// Where the generated module finds the image it was translated from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ImageSource {
    /// In the module, as a byte-string literal.
    Inline,
    /// In this file (an absolute path; `include_bytes!`), which holds exactly the image.
    File(String),
}

/// The Rust module (its items) that runs `image` natively: `pub static PROGRAM:
/// plc_vm::native::NativeProgram` and the functions behind it. The image must pass the
/// verifier.
pub fn translate(image_bytes: &[u8]) -> Result<String, Error> {
    translate_with(image_bytes, &ImageSource::Inline)
}

/// [`translate`], with the image embedded from `source`.
pub fn translate_with(image_bytes: &[u8], source: &ImageSource) -> Result<String, Error> {
    translate_pous(image_bytes, source, false)
}

/// [`translate`] of every POU of the image, reachable from a task or not: for checking
/// that a library (which has no tasks) translates.
pub fn translate_every_pou(image_bytes: &[u8]) -> Result<String, Error> {
    translate_pous(image_bytes, &ImageSource::Inline, true)
}

fn translate_pous(image_bytes: &[u8], source: &ImageSource, every: bool) -> Result<String, Error> {
    let image = Image::parse(image_bytes).map_err(Error::Image)?;
    plc_vm::verify::verify(&image).map_err(Error::Verify)?;
    let pous = if every {
        (0..image.pou_count()).collect()
    } else {
        reachable_pous(&image)
    };
    let mut plans = Vec::new();
    let mut cells = vec![0u32; image.pou_count()];
    for &index in &pous {
        let plan = analysis::plan(&image, index)?;
        cells[index] = plan.max_depth;
        let mut entries = vec![0usize];
        for &h in &plan.handlers {
            entries.push(plan.block_of(h)?);
        }
        let st = structure::structure(&plan, &entries);
        let stacks = promote::addresses(&image, &plan, &st);
        plans.push((plan, st, stacks));
    }
    let bases = fixed_bases(&image, &plans);
    let mut out = String::new();
    let hash = plc_vm::native::image_hash(image_bytes);
    writeln!(
        out,
        "// Generated by plc-native from a verified image of {} bytes (FNV-1a {hash:016x}); do not edit.",
        image_bytes.len()
    )
    .ok();
    out.push_str(
        "use plc_vm::builtins;\n\
         use plc_vm::fmath::float_to_int;\n\
         use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode, Trap, compare};\n\
         use plc_vm::native::ops::{self, f32_cell, f32_of, f64_cell, f64_of, ld, st};\n\
         use plc_vm::native::{Catch, Cycle, NativeProgram, Unwind};\n\n",
    );
    writeln!(out, "/// The image this module is the translation of.").ok();
    match source {
        ImageSource::Inline => writeln!(
            out,
            "pub static IMAGE: &[u8] = b\"{}\";",
            byte_string(image_bytes)
        ),
        ImageSource::File(path) => {
            writeln!(out, "pub static IMAGE: &[u8] = include_bytes!({path:?});")
        }
    }
    .ok();
    writeln!(out, "/// Bytes of data memory.").ok();
    writeln!(out, "const DATA: usize = {};", image.data_size()).ok();
    writeln!(
        out,
        "/// The program: run a task's cycle natively.\npub static PROGRAM: NativeProgram = NativeProgram {{ image: IMAGE, hash: 0x{hash:016x}, run }};\n"
    )
    .ok();
    writeln!(
        out,
        "fn run(cx: &mut Cycle<'_>, data: &mut [u8], task: usize) -> Result<(), Unwind> {{"
    )
    .ok();
    writeln!(
        out,
        "let Ok(d) = <&mut [u8; DATA]>::try_from(data) else {{ return Err(cx.refuse(0)); }};"
    )
    .ok();
    writeln!(out, "match task {{").ok();
    for t in 0..image.task_count() {
        let task = image
            .task(t)
            .ok_or_else(|| Error::internal(format!("task {t} missing")))?;
        let pou = task.pou as usize;
        writeln!(
            out,
            "{t} => {}(cx, d, {}, 0, [0; {}]).map(drop),",
            emit::pou_fn(pou),
            task.instance_base,
            cells[pou]
        )
        .ok();
    }
    writeln!(out, "_ => Err(cx.refuse(0)),\n}}\n}}\n").ok();
    let mut emitter = emit::Emitter {
        image: &image,
        cells,
        out,
        promotion: promote::Promotion::default(),
    };
    for (plan, st, stacks) in &plans {
        let base = bases[plan.index];
        let promotion = promote::promote(plan, st, stacks, base);
        emitter.pou(plan, st, &promotion, base)?;
    }
    Ok(emitter.out)
}

/// The frame base of each POU when every activation has the same one (its tasks' instance
/// base, the base every CALL of it passes), found from the task table down the call graph.
fn fixed_bases(
    image: &Image<'_>,
    plans: &[(
        analysis::PouPlan<'_>,
        structure::Structure,
        Vec<Vec<promote::Addr>>,
    )],
) -> Vec<Option<u32>> {
    let n = image.pou_count();
    let mut bases: Vec<Option<u32>> = vec![None; n];
    // Each round settles at least one more level of the call graph; a disagreement (which
    // should not happen) ends in no fixed bases rather than a guess.
    for _ in 0..n + 2 {
        // Every way into each POU: Some(base) when known, None when not.
        let mut seen: Vec<Vec<Option<u64>>> = vec![Vec::new(); n];
        for task in (0..image.task_count()).filter_map(|t| image.task(t)) {
            if let Some(ways) = seen.get_mut(task.pou as usize) {
                ways.push(Some(task.instance_base as u64));
            }
        }
        // A method runs on whatever instance is dispatched to.
        for pou in dispatch_targets(image) {
            if let Some(ways) = seen.get_mut(pou) {
                ways.push(None);
            }
        }
        for (plan, _, stacks) in plans {
            for (callee, base) in promote::call_bases(plan, stacks, bases[plan.index]) {
                if let Some(ways) = seen.get_mut(callee) {
                    ways.push(base);
                }
            }
        }
        let next: Vec<Option<u32>> = seen
            .iter()
            .map(|ways| match ways.first() {
                Some(Some(b)) if ways.iter().all(|w| *w == Some(*b)) => u32::try_from(*b).ok(),
                _ => None,
            })
            .collect();
        if next == bases {
            return bases;
        }
        bases = next;
    }
    vec![None; n]
}

/// `bytes` as the inside of a Rust byte-string literal.
fn byte_string(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 4);
    for b in bytes {
        write!(s, "\\x{b:02x}").ok();
    }
    s
}

/// The lints a generated module is exempt from (it is correct by construction, not written
/// for reading: unused cells, assignments overwritten on every path, long functions).
pub const GENERATED_ALLOWS: &str = "#[allow(dead_code, unused_mut, unused_variables, unused_assignments, unused_imports, unused_comparisons, unreachable_code, unused_labels, clippy::all)]";

/// One file with the modules `programs` (`(module name, translate() output)`) and the table
/// `pub static PROGRAMS: &[&plc_vm::native::NativeProgram]` in that order (what the PLC
/// partition is built with).
pub fn bundle(programs: &[(String, String)]) -> String {
    let mut out = String::from("// Generated by plc-native; do not edit.\n\n");
    for (name, module) in programs {
        writeln!(out, "{GENERATED_ALLOWS}\npub mod {name} {{\n{module}\n}}\n").ok();
    }
    let table: Vec<String> = programs
        .iter()
        .map(|(name, _)| format!("&{name}::PROGRAM"))
        .collect();
    writeln!(
        out,
        "/// The natively compiled programs of this build.\n#[allow(dead_code)]\npub static PROGRAMS: &[&plc_vm::native::NativeProgram] = &[{}];",
        table.join(", ")
    )
    .ok();
    out
}

/// A Rust identifier for `name` (a partition name): ASCII alphanumerics and `_` kept, the
/// rest `_`, prefixed so it never starts with a digit or is a keyword.
pub fn module_name(name: &str) -> String {
    let body: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    format!("program_{body}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use plc_vm::image::{ImageBuilder, TaskDef, TaskKind};

    /// Main (with `body`) run by one task, and a POU `f` without cells it may call.
    fn image(body: impl FnOnce(&mut ImageBuilder, plc_vm::image::PouId)) -> Vec<u8> {
        let mut b = ImageBuilder::new();
        b.reserve_data(64);
        let main = b.declare_pou("Main", 0, 0, 8);
        let f = b.declare_pou("f", 0, 0, 8);
        b.add_task(&TaskDef {
            name: "T".into(),
            kind: TaskKind::Cyclic,
            priority: 0,
            pou: main,
            instance_base: 0,
            interval_ns: 0,
            watchdog_budget: 0,
        });
        b.begin_pou(f);
        b.ret();
        b.end_pou(f);
        b.begin_pou(main);
        body(&mut b, f);
        b.end_pou(main);
        b.build().expect("build")
    }

    #[test]
    fn a_try_frame_over_a_callee_s_cells_is_refused() {
        // TRY_BEGIN at depth 2, the stack emptied, then a call: the callee's cells would be
        // the ones a trap cuts the stack back to.
        let bytes = image(|b, f| {
            let (handler, end) = (b.new_label(), b.new_label());
            b.push_i32(1);
            b.push_i32(2);
            b.try_begin(handler);
            b.drop_();
            b.drop_();
            b.push_u32(16);
            b.call(f);
            b.push_i32(3);
            b.push_i32(4);
            b.try_end();
            b.drop_();
            b.drop_();
            b.jmp(end);
            b.bind(handler);
            b.drop_();
            b.drop_();
            b.drop_();
            b.bind(end);
            b.ret();
        });
        assert!(matches!(
            translate(&bytes),
            Err(Error::TryFrameOverCall { ref pou, .. }) if pou == "Main"
        ));
        // The same with the call above the frame's cells translates.
        let fine = image(|b, f| {
            let (handler, end) = (b.new_label(), b.new_label());
            b.try_begin(handler);
            b.push_u32(16);
            b.call(f);
            b.try_end();
            b.jmp(end);
            b.bind(handler);
            b.drop_();
            b.bind(end);
            b.ret();
        });
        assert!(translate(&fine).is_ok());
    }

    #[test]
    fn an_image_the_verifier_rejects_is_not_translated() {
        let mut bytes = image(|b, _| b.ret());
        assert!(matches!(translate(&bytes[..10]), Err(Error::Image(_))));
        // Corrupt the only RET of Main into an unassigned opcode.
        let code_at = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
        let main_ret = code_at + 1; // f's RET comes first
        bytes[main_ret] = 0xFF;
        assert!(matches!(translate(&bytes), Err(Error::Verify(_))));
    }
}
