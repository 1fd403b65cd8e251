//! Rough interpreter speed check: bubble sort of 100 DINTs in hand-written bytecode versus
//! the same algorithm in Rust. Run: `cargo run --release -p plc-vm --features alloc --example vm_speed`.
//! With an image path argument, times task 0 of that image instead.

use plc_vm::image::{Image, ImageBuilder, TaskDef, TaskKind};
use plc_vm::isa::{MemType, Opcode};
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};
use std::time::Instant;

const N: u32 = 100;
const ARR: u32 = 16; // DINT array at 16..16+4N; i at 0, j at 4, seed at 8

fn build() -> Vec<u8> {
    let mut b = ImageBuilder::new();
    b.reserve_data(ARR + 4 * N);
    let main = b.declare_pou("Main", 0, 0, 0);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: 0,
        interval_ns: 1,
        watchdog_budget: u32::MAX,
    });
    b.begin_pou(main);
    // fill: arr[k] := (k * 7919) MOD 1000 reversed-ish
    b.push_i32(0);
    b.st_abs(MemType::I32, 0);
    let fill = b.new_label();
    let filled = b.new_label();
    b.bind(fill);
    b.ld_abs(MemType::I32, 0);
    b.push_int(N as i64);
    b.op(Opcode::GeS);
    b.jnz(filled);
    b.ld_abs(MemType::I32, 0);
    b.push_i32(4);
    b.op(Opcode::Mul);
    b.push_int(ARR as i64);
    b.op(Opcode::Add);
    b.ld_abs(MemType::I32, 0);
    b.push_i32(7919);
    b.op(Opcode::Mul);
    b.push_i32(1000);
    b.op(Opcode::ModS);
    b.st_ind(MemType::I32, 0);
    b.ld_abs(MemType::I32, 0);
    b.push_i32(1);
    b.op(Opcode::Add);
    b.st_abs(MemType::I32, 0);
    b.jmp(fill);
    b.bind(filled);
    // for i in 0..N-1 { for j in 0..N-1-i { if a[j] > a[j+1] swap } }
    let outer = b.new_label();
    let outer_end = b.new_label();
    let inner = b.new_label();
    let inner_end = b.new_label();
    let no_swap = b.new_label();
    b.push_i32(0);
    b.st_abs(MemType::I32, 0);
    b.bind(outer);
    b.ld_abs(MemType::I32, 0);
    b.push_int(N as i64 - 1);
    b.op(Opcode::GeS);
    b.jnz(outer_end);
    b.push_i32(0);
    b.st_abs(MemType::I32, 4);
    b.bind(inner);
    b.ld_abs(MemType::I32, 4);
    b.push_int(N as i64 - 1);
    b.ld_abs(MemType::I32, 0);
    b.op(Opcode::Sub);
    b.op(Opcode::GeS);
    b.jnz(inner_end);
    // address of a[j]
    b.ld_abs(MemType::I32, 4);
    b.push_i32(4);
    b.op(Opcode::Mul);
    b.push_int(ARR as i64);
    b.op(Opcode::Add);
    b.dup();
    b.ld_ind(MemType::I32, 0);
    b.over();
    b.ld_ind(MemType::I32, 4);
    b.op(Opcode::GtS);
    b.jz(no_swap);
    // [addr] swap a[j], a[j+1]
    b.dup();
    b.ld_ind(MemType::I32, 0);
    b.st_abs(MemType::I32, 8);
    b.dup();
    b.dup();
    b.ld_ind(MemType::I32, 4);
    b.st_ind(MemType::I32, 0);
    b.ld_abs(MemType::I32, 8);
    b.st_ind(MemType::I32, 4);
    b.push_i32(0);
    b.bind(no_swap);
    b.drop_();
    b.ld_abs(MemType::I32, 4);
    b.push_i32(1);
    b.op(Opcode::Add);
    b.st_abs(MemType::I32, 4);
    b.jmp(inner);
    b.bind(inner_end);
    b.ld_abs(MemType::I32, 0);
    b.push_i32(1);
    b.op(Opcode::Add);
    b.st_abs(MemType::I32, 0);
    b.jmp(outer);
    b.bind(outer_end);
    b.ret();
    b.end_pou(main);
    b.build().unwrap()
}

fn native(arr: &mut [i32; N as usize]) {
    for (k, v) in arr.iter_mut().enumerate() {
        *v = (k as i32 * 7919) % 1000;
    }
    for i in 0..N as usize - 1 {
        for j in 0..N as usize - 1 - i {
            if arr[j] > arr[j + 1] {
                arr.swap(j, j + 1);
            }
        }
    }
}

fn time_image(path: &str) {
    let bytes = std::fs::read(path).expect("read image");
    let image = Image::parse(&bytes).unwrap();
    let verified = plc_vm::verify::verify(&image).unwrap();
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = [0u64; 256];
    let mut calls = [CallFrame::EMPTY; 32];
    let mut tries = [TryFrame::EMPTY; 16];
    let mut vm = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    vm.set_watchdog_budget(0, Some(u32::MAX));
    let cycles = 200;
    let start = Instant::now();
    let mut instructions = 0u64;
    for k in 0..cycles {
        instructions += vm.run_cycle(0, k * 10_000_000).unwrap().instructions as u64;
    }
    let ns = start.elapsed().as_nanos() as f64 / cycles as f64;
    println!(
        "{path}: {ns:.0} ns/cycle, {} instructions/cycle",
        instructions / cycles as u64
    );
}

fn main() {
    if let Some(path) = std::env::args().nth(1) {
        return time_image(&path);
    }
    let bytes = build();
    let image = Image::parse(&bytes).unwrap();
    let verified = plc_vm::verify::verify(&image).unwrap();
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = [0u64; 64];
    let mut calls = [CallFrame::EMPTY; 8];
    let mut tries = [TryFrame::EMPTY; 4];
    let mut vm = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let cycles = 200;
    let start = Instant::now();
    let mut instructions = 0u64;
    for _ in 0..cycles {
        instructions += vm.run_cycle(0, 0).unwrap().instructions as u64;
    }
    let vm_ns = start.elapsed().as_nanos() as f64 / cycles as f64;
    let sorted: Vec<i32> = (0..N)
        .map(|k| i32::from_le_bytes(vm.data()[(ARR + 4 * k) as usize..][..4].try_into().unwrap()))
        .collect();
    assert!(sorted.windows(2).all(|w| w[0] <= w[1]));
    let mut arr = [0i32; N as usize];
    let start = Instant::now();
    let native_cycles = 2000;
    for _ in 0..native_cycles {
        native(std::hint::black_box(&mut arr));
    }
    let native_ns = start.elapsed().as_nanos() as f64 / native_cycles as f64;
    println!(
        "bubble sort 100: vm {vm_ns:.0} ns/cycle ({:.2} ns/instr, {} instr), native {native_ns:.0} ns, ratio {:.1}",
        vm_ns / (instructions / cycles) as f64,
        instructions / cycles,
        vm_ns / native_ns
    );
}
