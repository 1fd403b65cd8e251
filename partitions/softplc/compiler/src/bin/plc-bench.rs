//! `plc-bench`: compiles representative ST programs, runs them on the VM and compares with
//! the same algorithm in plain Rust. Prints one line per metric:
//! `bench <name> median=<n> min=<n> max=<n> unit=<ns|ratio> samples=<n>`.

use std::hint::black_box;
use std::time::Instant;

use plc_compiler::run::{CALL_FRAMES, STACK_CELLS, TRY_FRAMES};
use plc_compiler::{Options, compile};
use plc_vm::image::Image;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

const SAMPLES: usize = 25;

const PID: &str = "
PROGRAM Main
VAR
  sp : ARRAY[0..99] OF REAL;
  pv : ARRAY[0..99] OF REAL;
  integ : ARRAY[0..99] OF REAL;
  prev : ARRAY[0..99] OF REAL;
  out : ARRAY[0..99] OF REAL;
  kp : REAL := 1.2; ki : REAL := 0.05; kd : REAL := 0.3;
  i : INT;
  err, d : REAL;
END_VAR
FOR i := 0 TO 99 DO
  sp[i] := 50.0;
  err := sp[i] - pv[i];
  integ[i] := LIMIT(-100.0, integ[i] + err * ki, 100.0);
  d := err - prev[i];
  prev[i] := err;
  out[i] := kp * err + integ[i] + kd * d;
  pv[i] := pv[i] + out[i] * 0.01;
END_FOR;
END_PROGRAM";

const BUBBLE: &str = "
PROGRAM Main
VAR
  a : ARRAY[0..99] OF DINT;
  seed : DINT := 12345;
  i, j : INT;
  t : DINT;
  swapped : BOOL;
END_VAR
FOR i := 0 TO 99 DO
  seed := seed * 1103515245 + 12345;
  a[i] := seed MOD 10000;
END_FOR;
FOR i := 0 TO 98 DO
  swapped := FALSE;
  FOR j := 0 TO 98 - i DO
    IF a[j] > a[j + 1] THEN
      t := a[j]; a[j] := a[j + 1]; a[j + 1] := t;
      swapped := TRUE;
    END_IF;
  END_FOR;
  IF NOT swapped THEN EXIT; END_IF;
END_FOR;
END_PROGRAM";

const STRING: &str = "
PROGRAM Main
VAR
  s : STRING[255];
  i : INT;
  n : DINT;
END_VAR
s := '';
FOR i := 1 TO 20 DO
  s := CONCAT(s, INT_TO_STRING(i));
  s := CONCAT(s, ',');
END_FOR;
n := LEN(s) + FIND(s, '17');
END_PROGRAM";

fn pid_native(st: &mut [[f32; 100]; 4], out: &mut [f32; 100]) {
    let (kp, ki, kd) = (1.2f32, 0.05f32, 0.3f32);
    for i in 0..100 {
        let sp = 50.0f32;
        let err = sp - st[0][i];
        st[1][i] = (st[1][i] + err * ki).clamp(-100.0, 100.0);
        let d = err - st[2][i];
        st[2][i] = err;
        out[i] = kp * err + st[1][i] + kd * d;
        st[0][i] += out[i] * 0.01;
    }
}

fn bubble_native(a: &mut [i32; 100], seed: &mut i32) {
    for x in a.iter_mut() {
        *seed = seed.wrapping_mul(1103515245).wrapping_add(12345);
        *x = *seed % 10000;
    }
    for i in 0..99 {
        let mut swapped = false;
        for j in 0..99 - i {
            if a[j] > a[j + 1] {
                a.swap(j, j + 1);
                swapped = true;
            }
        }
        if !swapped {
            break;
        }
    }
}

fn string_native(s: &mut String) -> usize {
    s.clear();
    for i in 1..=20 {
        s.push_str(&i.to_string());
        s.push(',');
    }
    s.len() + s.find("17").map_or(0, |p| p + 1)
}

/// ns per cycle for `samples` samples of `cycles` cycles each.
fn bench_vm(src: &str, cycles: u32) -> Vec<f64> {
    let (c, _) = match compile(
        &[("bench.st".to_string(), src.to_string())],
        &Options::default(),
    ) {
        Ok(c) => c,
        Err((d, map)) => panic!(
            "bench program does not compile:\n{}",
            plc_compiler::diagnostics::render(&map, &d, false)
        ),
    };
    let image = Image::parse(&c.image).expect("image");
    let verified = plc_vm::verify::verify(&image).expect("verified");
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
    let mut m = Machine::new(verified, memory).expect("machine");
    let mut now = 0i64;
    let mut samples = Vec::with_capacity(SAMPLES);
    let mut instructions = 0;
    for _ in 0..cycles {
        instructions = m.run_cycle(0, now).expect("warm-up cycle").instructions;
    }
    // Diagnostic only (stdout carries exactly the metric lines).
    eprintln!("plc-bench: {instructions} VM instructions per cycle");
    for _ in 0..SAMPLES {
        let t = Instant::now();
        for _ in 0..cycles {
            now += 10_000_000;
            m.run_cycle(0, black_box(now)).expect("cycle");
        }
        samples.push(t.elapsed().as_nanos() as f64 / cycles as f64);
    }
    samples
}

fn bench_native(mut f: impl FnMut(), cycles: u32) -> Vec<f64> {
    for _ in 0..cycles {
        f();
    }
    (0..SAMPLES)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..cycles {
                f();
            }
            t.elapsed().as_nanos() as f64 / cycles as f64
        })
        .collect()
}

fn stats(v: &[f64]) -> (f64, f64, f64) {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    (s[s.len() / 2], s[0], s[s.len() - 1])
}

fn report(name: &str, vm: &[f64], native: &[f64]) {
    let (med, min, max) = stats(vm);
    println!(
        "bench plc_vm_{name} median={med:.0} min={min:.0} max={max:.0} unit=ns samples={}",
        vm.len()
    );
    let ratios: Vec<f64> = vm
        .iter()
        .zip(native)
        .map(|(a, b)| a / b.max(0.001))
        .collect();
    let (med, min, max) = stats(&ratios);
    println!(
        "bench plc_vm_{name}_ratio median={med:.2} min={min:.2} max={max:.2} unit=ratio samples={}",
        ratios.len()
    );
}

fn main() {
    let vm = bench_vm(PID, 200);
    let mut st = [[0f32; 100]; 4];
    let mut out = [0f32; 100];
    let native = bench_native(
        || {
            pid_native(black_box(&mut st), black_box(&mut out));
        },
        200,
    );
    report("pid", &vm, &native);

    let vm = bench_vm(BUBBLE, 20);
    let mut a = [0i32; 100];
    let mut seed = 12345i32;
    let native = bench_native(
        || {
            bubble_native(black_box(&mut a), black_box(&mut seed));
        },
        20,
    );
    report("bubble_sort", &vm, &native);

    let vm = bench_vm(STRING, 200);
    let mut s = String::with_capacity(256);
    let native = bench_native(
        || {
            black_box(string_native(black_box(&mut s)));
        },
        200,
    );
    report("string", &vm, &native);
}
