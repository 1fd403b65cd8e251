//! The suite's programs written by hand in plain Rust, each the same algorithm on the same
//! data types (REAL as `f32` rounded after each operation, INT as `i16`, DINT as `i32`, with
//! the ST program's wrap-around), with the state a PLC program keeps between cycles. What a
//! native compiler of the ST source could at best produce; `cycle` is never inlined into the
//! measuring loop (each call is one scan, as for the PLC).

use super::Reference;

#[derive(Default)]
pub struct Pid {
    sp: Vec<f32>,
    pv: Vec<f32>,
    integ: Vec<f32>,
    prev: Vec<f32>,
    out: Vec<f32>,
}

impl Reference for Pid {
    #[inline(never)]
    fn cycle(&mut self) {
        if self.sp.is_empty() {
            for v in [
                &mut self.sp,
                &mut self.pv,
                &mut self.integ,
                &mut self.prev,
                &mut self.out,
            ] {
                *v = vec![0.0; 100];
            }
        }
        let (kp, ki, kd) = (1.2f32, 0.05f32, 0.3f32);
        for i in 0..100 {
            self.sp[i] = 50.0;
            let err = self.sp[i] - self.pv[i];
            self.integ[i] = (self.integ[i] + err * ki).clamp(-100.0, 100.0);
            let d = err - self.prev[i];
            self.prev[i] = err;
            self.out[i] = kp * err + self.integ[i] + kd * d;
            self.pv[i] += self.out[i] * 0.01;
        }
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.out[0] as f64, self.pv[99] as f64, self.integ[5] as f64]
    }
}

pub struct BubbleSort {
    a: [i32; 100],
    seed: i32,
}

impl Default for BubbleSort {
    fn default() -> Self {
        BubbleSort {
            a: [0; 100],
            seed: 12345,
        }
    }
}

impl Reference for BubbleSort {
    #[inline(never)]
    fn cycle(&mut self) {
        for x in self.a.iter_mut() {
            self.seed = self.seed.wrapping_mul(1103515245).wrapping_add(12345);
            *x = self.seed % 10000;
        }
        for i in 0..99 {
            let mut swapped = false;
            for j in 0..99 - i {
                if self.a[j] > self.a[j + 1] {
                    self.a.swap(j, j + 1);
                    swapped = true;
                }
            }
            if !swapped {
                break;
            }
        }
    }

    fn outputs(&self) -> Vec<f64> {
        vec![
            self.a[0] as f64,
            self.a[50] as f64,
            self.a[99] as f64,
            self.seed as f64,
        ]
    }
}

#[derive(Default)]
pub struct StringBuild {
    s: String,
    n: i32,
}

impl Reference for StringBuild {
    #[inline(never)]
    fn cycle(&mut self) {
        self.s.clear();
        for i in 1..=20 {
            self.s.push_str(&i.to_string());
            self.s.push(',');
        }
        self.n = (self.s.len() + self.s.find("17").map_or(0, |p| p + 1)) as i32;
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.n as f64]
    }
}

pub struct Arithmetic {
    x: i16,
    y: i16,
    results: [i16; 5],
}

impl Default for Arithmetic {
    fn default() -> Self {
        Arithmetic {
            x: 20,
            y: 10,
            results: [0; 5],
        }
    }
}

impl Reference for Arithmetic {
    #[inline(never)]
    fn cycle(&mut self) {
        let (x, y) = (self.x, self.y);
        self.results = [
            x.wrapping_add(y),
            x.wrapping_sub(y),
            x.wrapping_mul(y),
            x.wrapping_div(y),
            x.wrapping_rem(y),
        ];
    }

    fn outputs(&self) -> Vec<f64> {
        self.results.iter().map(|&r| r as f64).collect()
    }
}

#[derive(Default)]
pub struct Blinky {
    lamp: bool,
}

impl Reference for Blinky {
    #[inline(never)]
    fn cycle(&mut self) {
        self.lamp = !self.lamp;
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.lamp as u8 as f64]
    }
}

#[derive(Default)]
pub struct CaseState {
    step: i16,
    outputs: [bool; 4],
}

impl Reference for CaseState {
    #[inline(never)]
    fn cycle(&mut self) {
        if let 0..=3 = self.step {
            let on = self.step as usize;
            self.outputs = [on == 0, on == 1, on == 2, on == 3];
            self.step = (self.step + 1) % 4;
        }
    }

    fn outputs(&self) -> Vec<f64> {
        let mut v = vec![self.step as f64];
        v.extend(self.outputs.iter().map(|&b| b as u8 as f64));
        v
    }
}

pub struct CounterUp {
    ticks: i16,
    limit: i16,
    wrapped: bool,
}

impl Default for CounterUp {
    fn default() -> Self {
        CounterUp {
            ticks: 0,
            limit: 1000,
            wrapped: false,
        }
    }
}

impl Reference for CounterUp {
    #[inline(never)]
    fn cycle(&mut self) {
        if self.ticks >= self.limit {
            self.ticks = 0;
            self.wrapped = true;
        } else {
            self.ticks = self.ticks.wrapping_add(1);
            self.wrapped = false;
        }
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.ticks as f64, self.wrapped as u8 as f64]
    }
}

#[derive(Default)]
pub struct ForLoop {
    total: i16,
}

impl Reference for ForLoop {
    #[inline(never)]
    fn cycle(&mut self) {
        self.total = 0;
        for k in 1..=100i16 {
            self.total = self.total.wrapping_add(k);
        }
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.total as f64]
    }
}

#[derive(Default)]
pub struct Binom {
    result: i32,
}

fn binomial(n: i16, mut k: i16) -> i32 {
    if k < 0 || k > n {
        return 0;
    }
    if k > n - k {
        k = n - k;
    }
    let mut acc: i32 = 1;
    for j in 1..=k {
        acc = acc.wrapping_mul((n - k + j) as i32) / j as i32;
    }
    acc
}

impl Reference for Binom {
    #[inline(never)]
    fn cycle(&mut self) {
        self.result = binomial(std::hint::black_box(10), std::hint::black_box(5));
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

#[derive(Default)]
pub struct Expn {
    result: f32,
}

fn power_int(base: f32, exponent: i16) -> f32 {
    let negative = exponent < 0;
    // A WORD, as the ST program.
    let mut e = exponent.wrapping_abs() as u16;
    let (mut acc, mut square) = (1.0f32, base);
    while e > 0 {
        if e & 1 == 1 {
            acc *= square;
        }
        square *= square;
        e >>= 1;
    }
    if negative { 1.0 / acc } else { acc }
}

impl Reference for Expn {
    #[inline(never)]
    fn cycle(&mut self) {
        self.result = power_int(std::hint::black_box(2.0), std::hint::black_box(10));
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

#[derive(Default)]
pub struct Fib {
    result: i32,
}

fn fibonacci(n: i16) -> i32 {
    if !(0..=46).contains(&n) {
        return -1;
    }
    if n == 0 {
        return 0;
    }
    let (mut previous, mut current) = (0i32, 1i32);
    for _ in 2..=n {
        let next = previous.wrapping_add(current);
        previous = current;
        current = next;
    }
    current
}

impl Reference for Fib {
    #[inline(never)]
    fn cycle(&mut self) {
        self.result = fibonacci(std::hint::black_box(20));
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

#[derive(Default)]
pub struct Gcd {
    result: i32,
}

fn binary_gcd(a: i32, b: i32) -> i32 {
    // DWORDs, as the ST program.
    let (mut u, mut v) = (a.wrapping_abs() as u32, b.wrapping_abs() as u32);
    if u == 0 {
        return v as i32;
    }
    if v == 0 {
        return u as i32;
    }
    let mut shift = 0;
    while (u | v) & 1 == 0 {
        u >>= 1;
        v >>= 1;
        shift += 1;
    }
    while u & 1 == 0 {
        u >>= 1;
    }
    loop {
        while v & 1 == 0 {
            v >>= 1;
        }
        if u > v {
            std::mem::swap(&mut u, &mut v);
        }
        v -= u;
        if v == 0 {
            break;
        }
    }
    (u << shift) as i32
}

impl Reference for Gcd {
    #[inline(never)]
    fn cycle(&mut self) {
        self.result = binary_gcd(std::hint::black_box(48), std::hint::black_box(36));
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

#[derive(Default)]
pub struct Lambert {
    result: i32,
}

fn lambert_w(x: f32) -> f32 {
    if x < -0.367_879_44 {
        return -1000.0;
    }
    if x == 0.0 {
        return 0.0;
    }
    let mut w = if x <= 500.0 {
        let l = (x + 1.0).ln();
        0.665 * (1.0 + 0.0195 * l) * l + 0.04
    } else {
        (x - 4.0).ln() - (1.0 - 1.0 / x.ln()) * x.ln().ln()
    };
    for _ in 1..=6 {
        let ew = w.exp();
        let f = w * ew - x;
        let step = f / ((w + 1.0) * ew - (w + 2.0) * f / (2.0 * w + 2.0));
        w -= step;
        if step.abs() <= 1.0e-7 * w.abs() {
            break;
        }
    }
    w
}

impl Reference for Lambert {
    #[inline(never)]
    fn cycle(&mut self) {
        self.result = (lambert_w(std::hint::black_box(1.0)) * 10000.0).round() as i32;
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

pub struct LinearInt {
    table: [[f32; 2]; 20],
    result: f32,
}

impl Default for LinearInt {
    fn default() -> Self {
        LinearInt {
            table: [[0.0; 2]; 20],
            result: 0.0,
        }
    }
}

/// `table` by value, as the ST function's VAR_INPUT.
fn interpolate(x: f32, table: [[f32; 2]; 20], count: i16) -> f32 {
    let count = count.min(20);
    let mut j = 2usize;
    while (j as i16) < count && table[j - 1][0] < x {
        j += 1;
    }
    let (lo, hi) = (table[j - 2], table[j - 1]);
    lo[1] + (x - lo[0]) * (hi[1] - lo[1]) / (hi[0] - lo[0])
}

impl Reference for LinearInt {
    #[inline(never)]
    fn cycle(&mut self) {
        for (i, point) in self.table.iter_mut().take(5).enumerate() {
            *point = [10.0 * i as f32, 100.0 * i as f32];
        }
        self.result = interpolate(std::hint::black_box(25.0), self.table, 5);
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

#[derive(Default)]
pub struct PolynomInt {
    table: [[f32; 2]; 5],
    result: f32,
}

/// The divided differences on a copy of `t` (the program sets its table anew every cycle).
fn newton(x: f32, mut t: [[f32; 2]; 5], count: i16) -> f32 {
    let count = count.min(5) as usize;
    for j in 1..count {
        for m in (j + 1..=count).rev() {
            t[m - 1][1] = (t[m - 1][1] - t[m - 2][1]) / (t[m - 1][0] - t[m - 1 - j][0]);
        }
    }
    let mut acc = 0.0f32;
    for m in (1..=count).rev() {
        acc = acc * (x - t[m - 1][0]) + t[m - 1][1];
    }
    acc
}

impl Reference for PolynomInt {
    #[inline(never)]
    fn cycle(&mut self) {
        for (i, point) in self.table.iter_mut().enumerate() {
            let x = (i + 1) as f32;
            *point = [x, x * x];
        }
        self.result = newton(std::hint::black_box(2.5), self.table, 5);
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.result as f64]
    }
}

#[derive(Default)]
pub struct RealToFrac {
    num: i32,
    den: i32,
}

fn to_fraction(x: f32, limit: i32) -> (i32, i32) {
    let negative = x < 0.0;
    let mut x = x.abs();
    let (mut h, mut h1, mut k, mut k1) = (1i32, 0i32, 0i32, 1i32);
    loop {
        let a = x.trunc() as i32;
        let t = a.wrapping_mul(h).wrapping_add(h1);
        if a.wrapping_mul(k).wrapping_add(k1) > limit {
            break;
        }
        h1 = h;
        h = t;
        let t = a.wrapping_mul(k).wrapping_add(k1);
        k1 = k;
        k = t;
        let rest = x - a as f32;
        if rest < 1.0e-6 {
            break;
        }
        x = 1.0 / rest;
        if k > limit {
            break;
        }
    }
    (if negative { -h } else { h }, k)
}

impl Reference for RealToFrac {
    #[inline(never)]
    fn cycle(&mut self) {
        // The ST program's literal 3.14159 (five places of pi, as the algorithm's test).
        #[allow(clippy::approx_constant)]
        let x = 3.14159;
        (self.num, self.den) = to_fraction(std::hint::black_box(x), std::hint::black_box(1000));
    }

    fn outputs(&self) -> Vec<f64> {
        vec![self.num as f64, self.den as f64]
    }
}
