//! Random well-typed ST programs (integer, REAL, BOOL, arrays, IF/CASE/FOR/__TRY, possible
//! traps) for differential tests: the compiler's (`tests/random_programs.rs`, VM vs model)
//! and the native tier's (`partitions/softplc/native/tests/differential.rs`), which include
//! this file.

/// xorshift64*: deterministic, dependency-free.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn pick<'a>(&mut self, xs: &[&'a str]) -> &'a str {
        xs[self.below(xs.len() as u64) as usize]
    }
}

struct Gen {
    rng: Rng,
    out: String,
}

impl Gen {
    fn dint(&mut self, depth: u32) -> String {
        let r = if depth == 0 {
            self.rng.below(3)
        } else {
            self.rng.below(10)
        };
        match r {
            0 => self.rng.pick(&["a", "b", "c", "cnt"]).to_string(),
            1 => format!("{}", self.rng.below(200) as i64 - 100),
            2 => format!("INT_TO_DINT({})", self.int(depth.saturating_sub(1))),
            3 => format!("arr[ABS({}) MOD 8]", self.dint(depth - 1)),
            4 => format!("ABS({})", self.dint(depth - 1)),
            5 => format!("MAX({}, {})", self.dint(depth - 1), self.dint(depth - 1)),
            6 => format!("REAL_TO_DINT({})", self.real(depth - 1)),
            _ => {
                let op = self.rng.pick(&["+", "-", "*", "/", "MOD", "+", "-"]);
                format!("({} {op} {})", self.dint(depth - 1), self.dint(depth - 1))
            }
        }
    }

    fn int(&mut self, depth: u32) -> String {
        let r = if depth == 0 {
            self.rng.below(2)
        } else {
            self.rng.below(5)
        };
        match r {
            0 => self.rng.pick(&["x", "y"]).to_string(),
            1 => format!("{}", self.rng.below(60000) as i64 - 30000),
            2 => format!("DINT_TO_INT({})", self.dint(depth - 1)),
            _ => {
                let op = self.rng.pick(&["+", "-", "*"]);
                format!("({} {op} {})", self.int(depth - 1), self.int(depth - 1))
            }
        }
    }

    fn real(&mut self, depth: u32) -> String {
        let r = if depth == 0 {
            self.rng.below(2)
        } else {
            self.rng.below(7)
        };
        match r {
            0 => self.rng.pick(&["r", "s"]).to_string(),
            1 => format!("{}.{}", self.rng.below(100), self.rng.below(10)),
            2 => format!("DINT_TO_REAL({})", self.dint(depth - 1)),
            3 => format!("SQRT(ABS({}))", self.real(depth - 1)),
            _ => {
                let op = self.rng.pick(&["+", "-", "*", "/"]);
                format!("({} {op} {})", self.real(depth - 1), self.real(depth - 1))
            }
        }
    }

    fn boolean(&mut self, depth: u32) -> String {
        let r = if depth == 0 {
            self.rng.below(2)
        } else {
            self.rng.below(6)
        };
        match r {
            0 => self.rng.pick(&["p", "q"]).to_string(),
            1 => self.rng.pick(&["TRUE", "FALSE"]).to_string(),
            2 => {
                let op = self.rng.pick(&["<", ">", "=", "<>", "<=", ">="]);
                format!("({} {op} {})", self.dint(depth - 1), self.dint(depth - 1))
            }
            3 => format!("({} < {})", self.real(depth - 1), self.real(depth - 1)),
            4 => format!("NOT {}", self.boolean(depth - 1)),
            _ => {
                let op = self.rng.pick(&["AND", "OR", "XOR"]);
                format!(
                    "({} {op} {})",
                    self.boolean(depth - 1),
                    self.boolean(depth - 1)
                )
            }
        }
    }

    fn stmts(&mut self, n: u64, depth: u32) {
        for _ in 0..n {
            self.stmt(depth);
        }
    }

    fn stmt(&mut self, depth: u32) {
        let r = if depth == 0 {
            self.rng.below(5)
        } else {
            self.rng.below(10)
        };
        let d = 2;
        match r {
            0 => {
                let v = self.rng.pick(&["a", "b", "c"]);
                let e = self.dint(d);
                self.out.push_str(&format!("{v} := {e};\n"));
            }
            1 => {
                let v = self.rng.pick(&["x", "y"]);
                let e = self.int(d);
                self.out.push_str(&format!("{v} := {e};\n"));
            }
            2 => {
                let v = self.rng.pick(&["r", "s"]);
                let e = self.real(d);
                self.out.push_str(&format!("{v} := {e};\n"));
            }
            3 => {
                let v = self.rng.pick(&["p", "q"]);
                let e = self.boolean(d);
                self.out.push_str(&format!("{v} := {e};\n"));
            }
            4 => {
                let i = self.dint(1);
                let e = self.dint(d);
                // MOD 9 sometimes indexes one past the end: INDEX_OUT_OF_BOUNDS.
                self.out.push_str(&format!("arr[ABS({i}) MOD 9] := {e};\n"));
            }
            5 => {
                let c = self.boolean(d);
                self.out.push_str(&format!("IF {c} THEN\n"));
                {
                    let n = 1 + self.rng.below(2);
                    self.stmts(n, depth - 1);
                }
                self.out.push_str("ELSE\n");
                {
                    let n = self.rng.below(2);
                    self.stmts(n, depth - 1);
                }
                self.out.push_str("END_IF;\n");
            }
            6 => {
                let n = self.rng.below(8);
                self.out.push_str(&format!("FOR i := 0 TO {n} DO\n"));
                {
                    let n = 1 + self.rng.below(2);
                    self.stmts(n, depth - 1);
                }
                self.out.push_str("END_FOR;\n");
            }
            7 => {
                let sel = self.dint(1);
                self.out.push_str(&format!("CASE {sel} MOD 4 OF\n0: "));
                self.stmts(1, depth - 1);
                self.out.push_str("1, 2: ");
                self.stmts(1, depth - 1);
                self.out.push_str("ELSE\n");
                self.stmts(1, depth - 1);
                self.out.push_str("END_CASE;\n");
            }
            8 => {
                self.out.push_str("__TRY\n");
                {
                    let n = 1 + self.rng.below(2);
                    self.stmts(n, depth - 1);
                }
                self.out
                    .push_str("__CATCH(e)\n cnt := cnt + 1;\n__ENDTRY;\n");
            }
            _ => {
                self.out.push_str("cnt := cnt + 1;\n");
            }
        }
    }
}

/// The generated program of `seed` (deterministic).
pub fn program(seed: u64) -> String {
    let mut g = Gen {
        rng: Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1),
        out: String::new(),
    };
    g.out.push_str(
        "PROGRAM Main\nVAR\n a, b, c, cnt : DINT; x, y : INT; r, s : REAL; p, q : BOOL;\n \
         arr : ARRAY[0..7] OF DINT; i : INT; e : __EXCEPTION;\nEND_VAR\n",
    );
    let n = 2 + g.rng.below(6);
    g.stmts(n, 3);
    g.out.push_str("END_PROGRAM\n");
    g.out
}
