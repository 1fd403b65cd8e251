//! `cargo run -p plc-native --example translate -- IMAGE.plcb`: prints the Rust module the
//! native tier makes of a bytecode image (what `plcc build` writes).
fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: translate IMAGE.plcb");
        std::process::exit(2);
    };
    let bytes = std::fs::read(&path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
    match plc_native::translate(&bytes) {
        Ok(module) => print!("{module}"),
        Err(e) => {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        }
    }
}
