//! The image records the globals a program shares with another PLC project
//! (`{attribute 'shared'}`): name, type, size, data address, direction and declaration.

use plc_compiler::{Options, compile};
use plc_vm::image::{Image, SharedDirection, VarType};

#[test]
fn shared_globals_are_recorded_in_declaration_order() {
    let source = "VAR_GLOBAL\n  plain : INT;\n  {attribute 'shared' := 'write'}\n  count, total : DINT;\n  {attribute 'shared' := 'read'} level : LREAL;\nEND_VAR\nPROGRAM Main\ncount := count + 1;\nEND_PROGRAM\n";
    let (compiled, _) = compile(&[("a.st".into(), source.into())], &Options::default())
        .unwrap_or_else(|_| panic!("compiles"));
    let image = Image::parse(&compiled.image).unwrap();
    plc_vm::verify::verify(&image).unwrap();
    let shared: Vec<_> = image
        .shared_vars()
        .map(|s| {
            (
                s.var.name,
                VarType::from_code(s.var.ty).unwrap(),
                s.var.size,
                s.direction,
                image.file_name(s.location.file).unwrap(),
                s.location.line,
                s.location.column,
            )
        })
        .collect();
    assert_eq!(
        shared,
        [
            (
                "count",
                VarType::DInt,
                4,
                SharedDirection::Write,
                "a.st",
                4,
                3
            ),
            (
                "total",
                VarType::DInt,
                4,
                SharedDirection::Write,
                "a.st",
                4,
                10
            ),
            (
                "level",
                VarType::LReal,
                8,
                SharedDirection::Read,
                "a.st",
                5,
                34
            ),
        ]
    );
    // The records point at the variables' data.
    for s in image.shared_vars() {
        assert_eq!(Some(s.var), image.find_var(s.var.name));
    }
}
