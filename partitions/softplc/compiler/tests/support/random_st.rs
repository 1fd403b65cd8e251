//! Random well-typed ST programs (integer, REAL, BOOL, arrays, bit access, dates and
//! times, references with pointer arithmetic, method calls through an interface on two
//! classes, IF/CASE/FOR/__TRY, possible traps) for differential tests: the compiler's
//! (`tests/random_programs.rs`, VM vs model) and the native tier's
//! (`partitions/softplc/native/tests/differential.rs`), which include this file.

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
            7 if self.rng.below(3) == 0 => match self.rng.below(3) {
                // Through a reference (NULL or moved off its variable: INVALID_REFERENCE).
                0 => "pa^".to_string(),
                1 => format!("BYTE_TO_DINT(pb^) + {}", self.dint(depth - 1)),
                // A dynamic call (through NULL: INVALID_REFERENCE).
                _ => format!("sh.Calc({})", self.dint(depth - 1)),
            },
            7 => match self.rng.below(5) {
                0 => "WORD_TO_DINT(w)".to_string(),
                1 => format!("BYTE_TO_DINT(w.%B{})", self.rng.below(2)),
                2 => "INT_TO_DINT(DAY_OF_WEEK(d1))".to_string(),
                3 => format!("TIME_TO_DINT({})", self.time(depth - 1)),
                _ => "DT_TO_DINT(dt1) MOD 100000".to_string(),
            },
            _ => {
                let op = self.rng.pick(&["+", "-", "*", "/", "MOD", "+", "-"]);
                format!("({} {op} {})", self.dint(depth - 1), self.dint(depth - 1))
            }
        }
    }

    /// A TIME expression (durations of days at most, so sums stay in range).
    fn time(&mut self, depth: u32) -> String {
        let r = if depth == 0 {
            self.rng.below(2)
        } else {
            self.rng.below(6)
        };
        match r {
            0 => "t".to_string(),
            1 => format!("T#{}ms", self.rng.below(100_000) as i64 - 50_000),
            2 => format!("DINT_TO_TIME({} MOD 1000000)", self.dint(depth - 1)),
            3 => "(tod1 - TOD#12:00:00)".to_string(),
            4 => format!("({} * {})", self.time(depth - 1), self.rng.below(5)),
            _ => {
                let op = self.rng.pick(&["+", "-"]);
                format!("({} {op} {})", self.time(depth - 1), self.time(depth - 1))
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
            5 => match self.rng.below(4) {
                0 => format!("w.{}", self.rng.below(16)),
                1 => format!("arr[{}].{}", self.rng.below(8), self.rng.below(32)),
                2 => format!("(dt1 < DT#2000-01-01-00:00:00 + {})", self.time(depth - 1)),
                _ => format!("(tod1 >= TOD#06:30:00 XOR {} > T#0s)", self.time(depth - 1)),
            },
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
            [0, 1, 2, 3, 4, 10, 11, 12][self.rng.below(8) as usize]
        } else {
            self.rng.below(13)
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
            10 => {
                let stmt = match self.rng.below(4) {
                    0 => format!("w.{} := {};\n", self.rng.below(16), self.boolean(d)),
                    1 => format!(
                        "w.%B{} := DINT_TO_BYTE({});\n",
                        self.rng.below(2),
                        self.dint(d)
                    ),
                    2 => {
                        // MOD 9 sometimes indexes one past the end: INDEX_OUT_OF_BOUNDS.
                        let i = self.dint(1);
                        format!(
                            "arr[ABS({i}) MOD 9].{} := {};\n",
                            self.rng.below(32),
                            self.boolean(d)
                        )
                    }
                    _ => format!("arr[{}].%W1 := w;\n", self.rng.below(8)),
                };
                self.out.push_str(&stmt);
            }
            11 => {
                let stmt = match self.rng.below(5) {
                    0 => format!("t := {};\n", self.time(d)),
                    1 => format!("dt1 := dt1 + {};\n", self.time(d)),
                    2 => format!("tod1 := tod1 - {};\n", self.time(d)),
                    3 => "d1 := DT_TO_DATE(dt1);\n".to_string(),
                    // Invalid months and days trap NUMERIC_ERROR.
                    _ => format!(
                        "d1 := CONCAT_DATE(2000 + ABS({}) MOD 50, ABS({}) MOD 13, ABS({}) MOD 32);\n",
                        self.dint(1),
                        self.dint(1),
                        self.dint(1)
                    ),
                };
                self.out.push_str(&stmt);
            }
            12 | 9 if self.rng.below(4) != 0 => {
                let stmt = match self.rng.below(9) {
                    0 => format!("pa := REF(arr[ABS({}) MOD 8]);\n", self.dint(1)),
                    1 => "pa := REF(c);\n".to_string(),
                    2 => "pa := NULL;\n".to_string(),
                    // Moving by whole elements; beyond the array the next access traps.
                    3 => format!("pa := pa + ({} MOD 5) * 4;\n", self.dint(1)),
                    4 => format!("pa^ := {};\n", self.dint(d)),
                    5 => "pb := ADR(arr);\n".to_string(),
                    6 => format!("pb := pb + {} MOD 40;\n", self.dint(1)),
                    7 => format!("pb^ := DINT_TO_BYTE({});\n", self.dint(d)),
                    _ => self
                        .rng
                        .pick(&["sh := ka;\n", "sh := kb;\n", "sh := NULL;\n"])
                        .to_string(),
                };
                self.out.push_str(&stmt);
            }
            12 if self.rng.below(2) == 0 => self
                .out
                .push_str("SPLIT_DT(dt1, YEAR => x, MONTH => y, DAY => i, HOUR => x);\n"),
            12 => {
                // WSTRING functions (results truncated to the capacity) and WCHAR.
                let stmt = match self.rng.below(5) {
                    0 => format!(
                        "ws := CONCAT(ws, \"{}\", 'é');\n",
                        self.rng.pick(&["ab", "€", "x"])
                    ),
                    1 => format!("ws := MID(ws, {}, {});\n", self.int(1), self.int(1)),
                    2 => format!(
                        "ws := REPLACE(ws, \"Zz\", {}, {});\n",
                        self.int(1),
                        self.int(1)
                    ),
                    3 => {
                        "x := LEN(ws) + FIND(ws, \"b\");\nwc := WSTRING_TO_WCHAR(ws);\n".to_string()
                    }
                    _ => "ws := STRING_TO_WSTRING(WSTRING_TO_STRING(ws));\np := ws < \"b\";\n"
                        .to_string(),
                };
                self.out.push_str(&stmt);
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
        "INTERFACE ICalc\n METHOD Calc : DINT\n  VAR_INPUT v : DINT; END_VAR\n END_METHOD\nEND_INTERFACE\n\
         FUNCTION_BLOCK KA IMPLEMENTS ICalc\nVAR state : DINT; END_VAR\n\
         METHOD Calc : DINT\n VAR_INPUT v : DINT; END_VAR\n state := state + 1;\n Calc := v * 2 + state;\nEND_METHOD\n\
         END_FUNCTION_BLOCK\n\
         FUNCTION_BLOCK KB EXTENDS KA\n\
         METHOD Calc : DINT\n VAR_INPUT v : DINT; END_VAR\n Calc := SUPER^.Calc(v) - 1000;\nEND_METHOD\n\
         END_FUNCTION_BLOCK\n",
    );
    g.out.push_str(
        "PROGRAM Main\nVAR\n pa : REF_TO DINT; pb : POINTER TO BYTE; sh : ICalc; ka : KA; kb : KB;\n a, b, c, cnt : DINT; x, y : INT; r, s : REAL; p, q : BOOL;\n \
         arr : ARRAY[0..7] OF DINT; i : INT; e : __EXCEPTION; w : WORD; t : TIME;\n          dt1 : DT := DT#2000-01-01-00:00:00; tod1 : TOD := TOD#12:00:00; d1 : DATE;\n \
         ws : WSTRING[6] := \"abc\"; wc : WCHAR;\nEND_VAR\n",
    );
    g.out
        .push_str("IF pa = NULL THEN pa := REF(b); pb := ADR(w); sh := ka; END_IF;\n");
    let n = 2 + g.rng.below(6);
    g.stmts(n, 3);
    g.out.push_str("END_PROGRAM\n");
    g.out
}
