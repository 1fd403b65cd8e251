//! Prints an image: header, tables and disassembled code per POU.
//! Run: `cargo run -p plc-vm --example disasm -- IMAGE`.

use plc_vm::image::Image;
use plc_vm::isa::instructions;

fn main() {
    let path = std::env::args().nth(1).expect("usage: disasm IMAGE");
    let bytes = std::fs::read(&path).expect("read image");
    let image = match Image::parse(&bytes) {
        Ok(image) => image,
        Err(e) => return eprintln!("{path}: {e}"),
    };
    if let Err(e) =
        plc_vm::verify::verify_with_scratch(&image, &mut vec![0; 2 * image.code().len()])
    {
        println!("; does NOT verify: {e}");
    }
    println!(
        "; data_size {} code {} bytes, {} constants",
        image.data_size(),
        image.code().len(),
        image.const_count()
    );
    for i in 0..image.task_count() {
        println!("; task {i}: {:?}", image.task(i).unwrap());
    }
    for i in 0..image.var_count() {
        println!("; var {:?}", image.var(i).unwrap());
    }
    for i in 0..image.object_count() {
        let (start, len) = image.object(i).unwrap();
        println!("; object {}: [{start}, {})", i + 1, start + len);
    }
    for i in 0..image.class_count() {
        let class = image.class(i).unwrap();
        let methods: Vec<String> = (class.first..class.first + class.count)
            .filter_map(|d| image.dispatch(d as usize))
            .map(|d| format!("slot {} -> POU {} (frame {})", d.slot, d.pou, d.frame))
            .collect();
        println!("; class {i} {}: {}", class.name, methods.join(", "));
    }
    let pous: Vec<_> = (0..image.pou_count())
        .filter_map(|i| image.pou(i))
        .collect();
    for insn in instructions(image.code()) {
        for (i, pou) in pous.iter().enumerate() {
            if pou.code_start == insn.offset {
                println!(
                    "\n{} (POU {i}, args {}, results {}, frame {}):",
                    pou.name, pou.arg_cells, pou.ret_cells, pou.frame_size
                );
            }
        }
        let loc = image
            .source_location(insn.offset)
            .map(|l| format!("  ; {}:{}", l.line, l.column))
            .unwrap_or_default();
        println!("{:6}  {insn}{loc}", insn.offset);
    }
}
