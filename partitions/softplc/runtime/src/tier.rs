//! Which execution tier runs the program: the interpreter (`plc_vm::vm`), or the native
//! code the build compiled into this binary (`plc.native`, `plc_vm::native`).
//!
//! Native code runs only for exactly the image it was translated from (compared byte for
//! byte), and only for the configured program: a program downloaded online runs on the
//! interpreter until the next build. Everything else (the monitor, forces, statistics,
//! faults and safe outputs) is the same on both tiers.

use crate::package::Package;
use plc_vm::native::{NativeProgram, image_hash};

/// The tier a program runs on, and why (the start's log line, [`core::fmt::Display`]).
#[derive(Clone, Copy, Debug)]
pub enum Tier {
    /// The native code of the program (`image` bytes, FNV-1a `hash`).
    Native(&'static NativeProgram),
    /// The interpreter: the configuration does not ask for native code.
    Interpreter,
    /// The interpreter, although the configuration asks for native code: this binary holds
    /// none for the program (`hash`, `len`: the program's image).
    NoNativeCode { hash: u64, len: usize },
    /// The interpreter: the program was downloaded online.
    Downloaded,
}

impl Tier {
    /// The program's tier: native when `package` asks for it, `program` is the package's
    /// own (not `downloaded`) and `compiled` holds its translation.
    pub fn select(
        package: &Package,
        program: &[u8],
        downloaded: bool,
        compiled: &'static [&'static NativeProgram],
    ) -> Tier {
        if downloaded {
            return Tier::Downloaded;
        }
        if !package.native() {
            return Tier::Interpreter;
        }
        match compiled.iter().find(|p| p.is_translation_of(program)) {
            Some(native) => Tier::Native(native),
            None => Tier::NoNativeCode {
                hash: image_hash(program),
                len: program.len(),
            },
        }
    }

    /// The native code to run, if any.
    pub fn native(&self) -> Option<&'static NativeProgram> {
        match *self {
            Tier::Native(p) => Some(p),
            _ => None,
        }
    }
}

impl core::fmt::Display for Tier {
    /// The text after `plc: tier ` (an interface: scenarios read it).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Tier::Native(p) => write!(f, "native (image {:016x}, {} bytes)", p.hash, p.image.len()),
            Tier::Interpreter => write!(f, "interpreter"),
            Tier::NoNativeCode { hash, len } => write!(
                f,
                "interpreter (plc.native: this build has no native code for image {hash:016x}, {len} bytes)"
            ),
            Tier::Downloaded => write!(
                f,
                "interpreter (a downloaded program runs on the interpreter until the next build)"
            ),
        }
    }
}
