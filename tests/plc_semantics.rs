//! Semantics of the PLC against IEC 61131-3 ed.3 (2013), as a table. Each case is a program,
//! a scan period, and steps `(scan, sets, checks)`: before scan `n` (counted from 1, at PLC
//! time (n-1) * period) the `sets` are written; after it the `checks` must hold (values as
//! IEC literals). `cite` says where the expected behaviour comes from; where the standard
//! leaves it open (implementation-dependent), it says which CODESYS/TwinCAT practice we follow.
#![allow(clippy::unwrap_used)]

use hytask::plc::{compile, FaultKind, Options, Program};

struct Case {
    name: &'static str,
    cite: &'static str,
    /// VAR declarations and body of `PROGRAM T` (wrapped by the harness), or a whole file
    /// when it starts with `FILE`.
    src: &'static str,
    period_ms: i64,
    steps: &'static [(u64, &'static str, &'static str)],
}

fn program(src: &str) -> Program {
    let text = match src.strip_prefix("FILE") {
        Some(f) => f.to_string(),
        None => format!("PROGRAM T\n{src}\nEND_PROGRAM\n"),
    };
    match compile("case.st", &text, Options { budget: 100_000 }) {
        Ok(p) => p,
        Err(e) => panic!("does not compile:\n{e}\n{text}"),
    }
}

fn pairs(s: &str) -> impl Iterator<Item = (&str, &str)> {
    s.split(',')
        .map(str::trim)
        .filter(|x| !x.is_empty())
        .map(|kv| kv.split_once('=').unwrap())
}

fn run(case: &Case) {
    let mut p = program(case.src);
    let last = case.steps.iter().map(|s| s.0).max().unwrap_or(1);
    for n in 1..=last {
        for (_, sets, _) in case.steps.iter().filter(|s| s.0 == n) {
            for (var, val) in pairs(sets) {
                let id = p
                    .var(var)
                    .unwrap_or_else(|| panic!("{}: no {var}", case.name));
                let v = p.parse(id, val).unwrap();
                p.set(id, v).unwrap();
            }
        }
        let r = p.scan(&[], &mut [], (n as i64 - 1) * case.period_ms * 1_000_000);
        for (_, _, checks) in case.steps.iter().filter(|s| s.0 == n) {
            for (var, want) in pairs(checks) {
                if var == "FAULT" {
                    let f = r
                        .as_ref()
                        .err()
                        .map(|f| format!("{} line {}", f.kind, f.line));
                    assert_eq!(f.as_deref(), Some(want), "{}: scan {n}", case.name);
                    continue;
                }
                assert!(r.is_ok(), "{}: scan {n} faulted: {r:?}", case.name);
                let id = p
                    .var(var)
                    .unwrap_or_else(|| panic!("{}: no {var}", case.name));
                assert_eq!(
                    p.format(id),
                    want,
                    "{} ({}): {var} after scan {n}",
                    case.name,
                    case.cite
                );
            }
        }
    }
}

const TIMERS: &[Case] = &[
    Case {
        name: "TON: Q after PT of IN, ET capped at PT, reset when IN falls",
        cite: "ed.3 6.6.3.5.5 figure 15a; ET counts from the scan that saw IN rise",
        src: "VAR t : TON; in : BOOL; END_VAR t(IN := in, PT := T#30ms);",
        period_ms: 10,
        steps: &[
            (1, "in=TRUE", "t.Q=FALSE, t.ET=T#0ms"),
            (3, "", "t.Q=FALSE, t.ET=T#20ms"),
            (4, "", "t.Q=TRUE, t.ET=T#30ms"),
            (6, "", "t.Q=TRUE, t.ET=T#30ms"),
            (7, "in=FALSE", "t.Q=FALSE, t.ET=T#0ms"),
        ],
    },
    Case {
        name: "TON: an interrupted IN restarts the delay",
        cite: "ed.3 figure 15a",
        src: "VAR t : TON; in : BOOL; END_VAR t(IN := in, PT := T#30ms);",
        period_ms: 10,
        steps: &[
            (1, "in=TRUE", ""),
            (3, "in=FALSE", "t.ET=T#0ms"),
            (4, "in=TRUE", "t.ET=T#0ms"),
            (6, "", "t.Q=FALSE"),
            (7, "", "t.Q=TRUE"),
        ],
    },
    Case {
        name: "TOF: Q follows IN up, falls PT after IN falls, ET holds at PT",
        cite: "ed.3 figure 15b",
        src: "VAR t : TOF; in : BOOL; END_VAR t(IN := in, PT := T#20ms);",
        period_ms: 10,
        steps: &[
            (1, "", "t.Q=FALSE"),
            (2, "in=TRUE", "t.Q=TRUE, t.ET=T#0ms"),
            (3, "in=FALSE", "t.Q=TRUE, t.ET=T#0ms"),
            (4, "", "t.Q=TRUE, t.ET=T#10ms"),
            (5, "", "t.Q=FALSE, t.ET=T#20ms"),
            (8, "", "t.Q=FALSE, t.ET=T#20ms"),
            (9, "in=TRUE", "t.Q=TRUE, t.ET=T#0ms"),
        ],
    },
    Case {
        name: "TP: a pulse of PT, not retriggerable; ET stays at PT while IN is TRUE",
        cite: "ed.3 figure 15c",
        src: "VAR t : TP; in : BOOL; END_VAR t(IN := in, PT := T#30ms);",
        period_ms: 10,
        steps: &[
            (1, "in=TRUE", "t.Q=TRUE, t.ET=T#0ms"),
            (2, "in=FALSE", "t.Q=TRUE, t.ET=T#10ms"),
            (3, "in=TRUE", "t.Q=TRUE, t.ET=T#20ms"),
            (4, "", "t.Q=FALSE, t.ET=T#30ms"),
            (6, "", "t.Q=FALSE, t.ET=T#30ms"),
            (7, "in=FALSE", "t.Q=FALSE, t.ET=T#0ms"),
            (8, "in=TRUE", "t.Q=TRUE, t.ET=T#0ms"),
        ],
    },
    Case {
        name: "timers only advance when called (ET is sampled at the call)",
        cite: "ed.3 6.6.3.5.5: a timer is a function block, evaluated when invoked",
        src: "VAR t : TON; call : BOOL := TRUE; END_VAR IF call THEN t(IN := TRUE, PT := T#1s); END_IF;",
        period_ms: 100,
        steps: &[
            (2, "", "t.ET=T#100ms"),
            (3, "call=FALSE", "t.ET=T#100ms"),
            (9, "call=TRUE", "t.ET=T#800ms"),
        ],
    },
];

const EDGES_COUNTERS: &[Case] = &[
    Case {
        name: "R_TRIG: Q for exactly one scan per rising edge",
        cite: "ed.3 6.6.3.5.3 table 44",
        src: "VAR e : R_TRIG; c : BOOL; END_VAR e(CLK := c);",
        period_ms: 10,
        steps: &[
            (1, "", "e.Q=FALSE"),
            (2, "c=TRUE", "e.Q=TRUE"),
            (3, "", "e.Q=FALSE"),
            (4, "c=FALSE", "e.Q=FALSE"),
            (5, "c=TRUE", "e.Q=TRUE"),
        ],
    },
    Case {
        name: "F_TRIG: Q for one scan per falling edge, none on the first call with CLK FALSE",
        cite: "ed.3 table 44; ed.2's body (M initially FALSE) fires on the first call: we \
               follow the CODESYS/TwinCAT libraries, which do not",
        src: "VAR e : F_TRIG; c : BOOL; END_VAR e(CLK := c);",
        period_ms: 10,
        steps: &[
            (1, "", "e.Q=FALSE"),
            (2, "c=TRUE", "e.Q=FALSE"),
            (3, "c=FALSE", "e.Q=TRUE"),
            (4, "", "e.Q=FALSE"),
        ],
    },
    Case {
        name: "CTU: counts rising edges of CU, R resets, Q when CV >= PV",
        cite: "ed.3 6.6.3.5.4 table 45",
        src: "VAR c : CTU; cu, r : BOOL; END_VAR c(CU := cu, R := r, PV := 2);",
        period_ms: 10,
        steps: &[
            (1, "cu=TRUE", "c.CV=1, c.Q=FALSE"),
            (2, "", "c.CV=1"),
            (3, "cu=FALSE", "c.CV=1"),
            (4, "cu=TRUE", "c.CV=2, c.Q=TRUE"),
            (5, "r=TRUE, cu=FALSE", "c.CV=0, c.Q=FALSE"),
            (6, "cu=TRUE", "c.CV=0"),
        ],
    },
    Case {
        name: "CTU stops at the top of INT (CV < PVmax), no wrap",
        cite: "ed.3 table 45: IF CU AND (CV < PVmax) THEN CV := CV + 1",
        src: "VAR c : CTU; cu : BOOL; END_VAR c(CU := cu, PV := 1);",
        period_ms: 10,
        steps: &[
            (1, "c.CV=32766, cu=TRUE", "c.CV=32767"),
            (2, "cu=FALSE", ""),
            (3, "cu=TRUE", "c.CV=32767"),
        ],
    },
    Case {
        name: "CTD: LD loads PV, CD edges count down, Q when CV <= 0",
        cite: "ed.3 table 45",
        src: "VAR c : CTD; cd, ld : BOOL; END_VAR c(CD := cd, LD := ld, PV := 2);",
        period_ms: 10,
        steps: &[
            (1, "ld=TRUE", "c.CV=2, c.Q=FALSE"),
            (2, "ld=FALSE, cd=TRUE", "c.CV=1"),
            (3, "cd=FALSE", ""),
            (4, "cd=TRUE", "c.CV=0, c.Q=TRUE"),
        ],
    },
    Case {
        name: "CTUD: simultaneous up and down edges cancel; R wins over LD",
        cite: "ed.3 table 45 (IF NOT (CU AND CD) ...)",
        src: "VAR c : CTUD; cu, cd, r, ld : BOOL; END_VAR c(CU := cu, CD := cd, R := r, LD := ld, PV := 3);",
        period_ms: 10,
        steps: &[
            (1, "cu=TRUE", "c.CV=1, c.QD=FALSE"),
            (2, "cu=FALSE", ""),
            (3, "cu=TRUE, cd=TRUE", "c.CV=1"),
            (4, "cu=FALSE, cd=FALSE", ""),
            (5, "cd=TRUE", "c.CV=0, c.QD=TRUE"),
            (6, "ld=TRUE, r=TRUE", "c.CV=0"),
            (7, "r=FALSE", "c.CV=3, c.QU=TRUE"),
        ],
    },
    Case {
        name: "SR is set-dominant, RS reset-dominant",
        cite: "ed.3 6.6.3.5.2 table 43",
        src: "VAR a : SR; b : RS; s, r : BOOL; END_VAR a(S1 := s, R := r); b(S := s, R1 := r);",
        period_ms: 10,
        steps: &[
            (1, "s=TRUE, r=TRUE", "a.Q1=TRUE, b.Q1=FALSE"),
            (2, "r=FALSE", "a.Q1=TRUE, b.Q1=TRUE"),
            (3, "s=FALSE", "a.Q1=TRUE, b.Q1=TRUE"),
            (4, "r=TRUE", "a.Q1=FALSE, b.Q1=FALSE"),
        ],
    },
];

const CONTROL: &[Case] = &[
    Case {
        name: "CASE: single labels, lists, ranges, ELSE",
        cite: "ed.3 7.3.3.3.3 table 72",
        src: "VAR x, y : INT; END_VAR CASE x OF 1: y := 10; 2, 4: y := 20; 5..9, 12: y := 30; ELSE y := -1; END_CASE;",
        period_ms: 10,
        steps: &[
            (1, "x=1", "y=10"),
            (2, "x=4", "y=20"),
            (3, "x=7", "y=30"),
            (4, "x=12", "y=30"),
            (5, "x=10", "y=-1"),
            (6, "x=-3", "y=-1"),
        ],
    },
    Case {
        name: "CASE on an enumeration",
        cite: "ed.3 table 72 (selector of an enumerated type)",
        src: "FILE TYPE Mode : (Idle, Run := 5, Hold); END_TYPE
PROGRAM T VAR m : Mode; y : INT; END_VAR
CASE m OF Idle: y := 1; Run, Hold: y := 2; END_CASE;
END_PROGRAM",
        period_ms: 10,
        steps: &[(1, "", "y=1, m=Mode#Idle"), (2, "m=Hold", "y=2, m=Mode#Hold")],
    },
    Case {
        name: "EXIT leaves the innermost loop only",
        cite: "ed.3 7.3.3.4.5 (EXIT terminates the innermost loop)",
        src: "VAR i, j, n : INT; END_VAR n := 0; FOR i := 1 TO 3 DO FOR j := 1 TO 10 DO IF j > 2 THEN EXIT; END_IF; n := n + 1; END_FOR; END_FOR;",
        period_ms: 10,
        steps: &[(1, "", "n=6, i=4, j=3")],
    },
    Case {
        name: "FOR: bounds evaluated once, negative step, control variable after the loop",
        cite: "ed.3 7.3.3.4.2; the control variable's final value is implementation-dependent: \
               CODESYS/TwinCAT leave it at the first value past the end, as here",
        src: "VAR i, n, e : INT; END_VAR n := 0; e := 3; FOR i := e TO 1 BY -1 DO n := n * 10 + i; e := 100; END_FOR;",
        period_ms: 10,
        steps: &[(1, "", "n=321, i=0")],
    },
    Case {
        name: "WHILE tests first, REPEAT runs at least once, CONTINUE skips the rest",
        cite: "ed.3 7.3.3.4.3/4; CONTINUE is ed.3 7.3.3.4.6",
        src: "VAR a, b, c, i : INT; END_VAR a := 0; WHILE a > 0 DO a := a + 1; END_WHILE; b := 0; REPEAT b := b + 1; UNTIL TRUE END_REPEAT; c := 0; FOR i := 1 TO 5 DO IF i MOD 2 = 0 THEN CONTINUE; END_IF; c := c + i; END_FOR;",
        period_ms: 10,
        steps: &[(1, "", "a=0, b=1, c=9")],
    },
    Case {
        name: "RETURN ends the POU for this scan",
        cite: "ed.3 7.3.3.2",
        src: "VAR a : INT; stop : BOOL; END_VAR a := 1; IF stop THEN RETURN; END_IF; a := 2;",
        period_ms: 10,
        steps: &[(1, "", "a=2"), (2, "stop=TRUE", "a=1")],
    },
    Case {
        name: "an endless loop ends in a budget fault at its line, not a hang",
        cite: "hytask: per-scan instruction budget (the standard has no such limit)",
        src: "VAR a : INT; END_VAR\nWHILE TRUE DO\n  a := a + 1;\nEND_WHILE;",
        period_ms: 10,
        steps: &[(1, "", "FAULT=instruction budget exhausted line 3")],
    },
];

const ARITHMETIC: &[Case] = &[
    Case {
        name: "integer overflow wraps (two's complement) in the declared width",
        cite: "ed.3 leaves overflow implementation-dependent; CODESYS/TwinCAT wrap",
        src: "VAR i : INT := 32767; s : SINT := -128; u : UINT; b : BYTE := 255; d : DINT := 2147483647; END_VAR i := i + 1; s := s - 1; u := u - 1; b := b + 1; d := d * 2;",
        period_ms: 10,
        steps: &[(1, "", "i=-32768, s=127, u=65535, b=16#0, d=-2")],
    },
    Case {
        name: "integer division truncates toward zero; MOD has the sign of the dividend",
        cite: "ed.3 table 29 (MOD: IN1 - (IN1 / IN2) * IN2), truncation as CODESYS/C",
        src: "VAR a, b, c, d : INT; END_VAR a := -7 / 2; b := -7 MOD 2; c := 7 MOD -2; d := 7 / -2;",
        period_ms: 10,
        steps: &[(1, "", "a=-3, b=-1, c=1, d=-3")],
    },
    Case {
        name: "the most negative value divided by -1 wraps in its width; MOD -1 is 0",
        cite: "ed.3 leaves overflow implementation-dependent; CODESYS/TwinCAT wrap (also checks the 32-bit division the VM uses for kinds of 32 bits or fewer)",
        src: "VAR a : DINT := -2147483648; m : DINT := -1; q, r : DINT; u : UDINT := 4294967295; v : UDINT; l : LINT := -2147483648; lq, lr : LINT; i : INT := -32768; im : INT := -1; iq : INT; END_VAR q := a / m; r := a MOD m; v := u / 7; lq := l / -1; lr := l MOD m; iq := i / im;",
        period_ms: 10,
        steps: &[(1, "", "q=-2147483648, r=0, v=613566756, lq=2147483648, lr=0, iq=-32768")],
    },
    Case {
        name: "integer division by zero is a runtime fault with its line",
        cite: "ed.3 leaves it implementation-dependent (an error); CODESYS raises an exception",
        src: "VAR a, z : DINT; END_VAR\na := 1;\na := a / z;",
        period_ms: 10,
        steps: &[(1, "", "FAULT=division by zero line 4")],
    },
    Case {
        name: "MOD by zero faults too",
        cite: "as division",
        src: "VAR a, z : DINT; END_VAR\na := 5 MOD z;",
        period_ms: 10,
        steps: &[(1, "", "FAULT=division by zero line 3")],
    },
    Case {
        name: "REAL division by zero follows IEEE 754 (no fault)",
        cite: "ed.3 defers REAL to IEC 60559; CODESYS/TwinCAT yield inf",
        src: "VAR r, z : REAL; n : LREAL; END_VAR r := 1.0 / z; n := -1.0 / z;",
        period_ms: 10,
        steps: &[(1, "", "r=inf, n=-inf")],
    },
    Case {
        name: "array index out of range is a runtime fault",
        cite: "ed.3 6.4.4.1: subscripts outside the declared range are an error",
        src: "VAR a : ARRAY[1..3] OF INT; i : INT := 3; END_VAR\na[i] := 1;\ni := i + 1;\na[i] := 2;",
        period_ms: 10,
        steps: &[(1, "", "FAULT=array index out of range line 5")],
    },
    Case {
        name: "MUX selects IN0..INn, outside is a fault",
        cite: "ed.3 table 46 (MUX); out of range is implementation-dependent",
        src: "VAR k, y : INT; END_VAR\ny := MUX(k, 10, 20, 30);",
        period_ms: 10,
        steps: &[(1, "k=2", "y=30"), (2, "k=3", "FAULT=MUX selector out of range line 3")],
    },
    Case {
        name: "MIN, MAX, LIMIT, SEL, ABS",
        cite: "ed.3 tables 32 and 46",
        src: "VAR a, b, c, d, e : INT; r : REAL; END_VAR a := MIN(4, -2, 9); b := MAX(4, -2, 9); c := LIMIT(0, 120, 100); d := SEL(TRUE, 1, 2); e := ABS(-5); r := ABS(REAL#-1.5);",
        period_ms: 10,
        steps: &[(1, "", "a=-2, b=9, c=100, d=2, e=5, r=1.5")],
    },
    Case {
        name: "bit access and bit-string operations",
        cite: "ed.3 6.4.2 (partial access .n), table 36 (SHL, ROL)",
        src: "VAR w : WORD := 16#00F0; b, c : BOOL; s, r, n : WORD; END_VAR b := w.4; c := w.0; w.0 := TRUE; w.4 := FALSE; s := SHL(w, 4); r := ROL(WORD#16#8001, 1); n := NOT w;",
        period_ms: 10,
        steps: &[(1, "", "b=TRUE, c=FALSE, w=16#E1, s=16#E10, r=16#3, n=16#FF1E")],
    },
];

const CONVERSIONS: &[Case] = &[
    Case {
        name: "REAL to integer rounds to nearest, halves away from zero; TRUNC truncates",
        cite: "ed.3 6.6.2.5.6 table 22 (rounding; ties implementation-dependent), \
               CODESYS/TwinCAT round half away from zero",
        src: "VAR a, b, c, d, e : INT; t : DINT; END_VAR a := REAL_TO_INT(2.5); b := REAL_TO_INT(-2.5); c := REAL_TO_INT(1.4); d := LREAL_TO_INT(1.6); e := REAL_TO_INT(-0.4); t := TRUNC(-2.7);",
        period_ms: 10,
        steps: &[(1, "", "a=3, b=-3, c=1, d=2, e=0, t=-2")],
    },
    Case {
        name: "narrowing integer conversions keep the low bits",
        cite: "ed.3 leaves out-of-range conversion implementation-dependent; CODESYS truncates bits",
        src: "VAR a : SINT; b : INT; c : UINT; d : BYTE; END_VAR a := INT_TO_SINT(300); b := DINT_TO_INT(-40000); c := INT_TO_UINT(-1); d := WORD_TO_BYTE(16#1234);",
        period_ms: 10,
        steps: &[(1, "", "a=44, b=25536, c=65535, d=16#34")],
    },
    Case {
        name: "BOOL, TIME and integers",
        cite: "ed.3 table 22; TIME <-> integer in milliseconds as CODESYS/TwinCAT",
        src: "VAR a : INT; b : BOOL; ms : DINT; t : TIME; r : REAL; END_VAR a := BOOL_TO_INT(TRUE); b := INT_TO_BOOL(5); ms := TIME_TO_DINT(T#1s500ms); t := DINT_TO_TIME(250); r := TIME_TO_REAL(T#1.5ms);",
        period_ms: 10,
        steps: &[(1, "", "a=1, b=TRUE, ms=1500, t=T#250ms, r=1.5")],
    },
    Case {
        name: "implicit widening: INT into DINT and REAL, SINT+USINT in INT",
        cite: "ed.3 6.4.2 table 11 (implicit conversions)",
        src: "VAR i : INT := -3; s : SINT := -1; u : USINT := 200; d : DINT; r : REAL; x : INT; END_VAR d := i; r := i; x := s + u;",
        period_ms: 10,
        steps: &[(1, "", "d=-3, r=-3.0, x=199")],
    },
    Case {
        name: "REAL keeps single precision at every step, LREAL double",
        cite: "ed.3 6.4.2 table 10: REAL is IEC 60559 single, LREAL double",
        src: "VAR a, b : REAL; c, d : LREAL; e : LREAL; f : REAL; END_VAR a := 0.1; b := 16777216.0 + 1.0; c := 0.1 + 0.2; d := 16777216.0 + 1.0; e := REAL_TO_LREAL(a); f := LREAL_TO_REAL(0.1);",
        period_ms: 10,
        steps: &[(
            1,
            "",
            "a=0.1, b=16777216.0, c=0.30000000000000004, d=16777217.0, e=0.10000000149011612, f=0.1",
        )],
    },
    Case {
        name: "TIME arithmetic",
        cite: "ed.3 table 30 (TIME + TIME, TIME * ANY_NUM, TIME / ANY_NUM)",
        src: "VAR a, b, c, d : TIME; END_VAR a := T#1s + T#250ms; b := a * 2; c := a / 5; d := T#1s * 1.5;",
        period_ms: 10,
        steps: &[(1, "", "a=T#1s250ms, b=T#2s500ms, c=T#250ms, d=T#1s500ms")],
    },
];

const POUS: &[Case] = &[
    Case {
        name: "function locals restart from their initial values on every call",
        cite: "ed.3 6.6.2.2: function variables are not retained between calls",
        src: "FILE FUNCTION F : INT VAR_INPUT x : INT; END_VAR VAR acc : INT := 10; END_VAR acc := acc + x; F := acc; END_FUNCTION
PROGRAM T VAR a, b : INT; END_VAR a := F(1); b := F(x := 2); END_PROGRAM",
        period_ms: 10,
        steps: &[(1, "", "a=11, b=12"), (2, "", "a=11, b=12")],
    },
    Case {
        name: "function block instances keep their state; VAR_IN_OUT is by reference",
        cite: "ed.3 6.6.3 (instances), 6.5.2.2 (VAR_IN_OUT)",
        src: "FILE FUNCTION_BLOCK Acc VAR_INPUT x : INT; END_VAR VAR_IN_OUT total : INT; END_VAR VAR_OUTPUT n : INT; END_VAR n := n + 1; total := total + x; END_FUNCTION_BLOCK
PROGRAM T VAR a, b : Acc; sum : INT; na : INT; END_VAR a(x := 1, total := sum); a(x := 2, total := sum, n => na); b(x := 10, total := sum); END_PROGRAM",
        period_ms: 10,
        steps: &[(1, "", "sum=13, na=2, a.n=2, b.n=1"), (2, "", "sum=26, a.n=4")],
    },
    Case {
        name: "arrays of block instances with a run-time index; structures",
        cite: "ed.3 6.5.2.3 (arrays of FB instances), 6.4.4.2 (structures)",
        src: "FILE TYPE P : STRUCT x : INT; y : INT := 5; END_STRUCT END_TYPE
PROGRAM T VAR e : ARRAY[0..2] OF R_TRIG; i : INT; q : ARRAY[0..2] OF BOOL; p, r : P; END_VAR
FOR i := 0 TO 2 DO e[i](CLK := i <> 1); q[i] := e[i].Q; END_FOR; p.x := p.x + 1; r := p; END_PROGRAM",
        period_ms: 10,
        steps: &[(1, "", "q[0]=TRUE, q[1]=FALSE, q[2]=TRUE, r.x=1, r.y=5"), (2, "", "q[0]=FALSE, r.x=2")],
    },
];

fn run_table(cases: &[Case]) {
    for c in cases {
        run(c);
    }
}

#[test]
fn timers() {
    run_table(TIMERS);
}

#[test]
fn edges_counters_bistables() {
    run_table(EDGES_COUNTERS);
}

#[test]
fn control_statements() {
    run_table(CONTROL);
}

#[test]
fn arithmetic() {
    run_table(ARITHMETIC);
}

#[test]
fn conversions() {
    run_table(CONVERSIONS);
}

#[test]
fn pous() {
    run_table(POUS);
}

/// Programs the compiler must refuse, with the message (and line) it must give.
#[test]
fn compile_errors() {
    let cases: &[(&str, &str)] = &[
        (
            "VAR a : INT; d : DINT := 5; END_VAR\na := d;",
            "2:6: type mismatch: expected INT, found DINT (convert explicitly with DINT_TO_INT)",
        ),
        (
            "VAR a : INT; END_VAR\na := 40000;",
            "2:6: 40000 is out of the range of INT",
        ),
        (
            "VAR c : INT := 1; END_VAR\nEXIT;",
            "2:1: EXIT outside a loop",
        ),
        (
            "VAR CONSTANT k : INT := 1; END_VAR\nk := 2;",
            "2:1: cannot assign to k",
        ),
        (
            "VAR t : TON; END_VAR\nt.Q := TRUE;",
            "2:1: cannot assign to t.Q",
        ),
        (
            "VAR t : TON; END_VAR\nt(IN := TRUE, XX := 1);",
            "2:15: TON has no parameter XX",
        ),
        (
            "VAR a : ARRAY[0..3] OF INT; END_VAR\na[4] := 1;",
            "2:3: index 4 is outside 0..3",
        ),
        (
            "VAR x : INT; END_VAR\nCASE x OF 1..5: x := 1; 3: x := 2; END_CASE;",
            "2:25: CASE label overlaps the label at line 3",
        ),
        (
            "VAR w : WORD; END_VAR\nw.16 := TRUE;",
            "2:1: bit 16 is outside WORD (16 bits)",
        ),
        ("VAR s : STRING; END_VAR", "1:9: STRING is not supported"),
    ];
    for (src, want) in cases {
        let text = format!("PROGRAM T\n{src}\nEND_PROGRAM\n");
        let err = compile("e.st", &text, Options::default())
            .unwrap_err()
            .to_string();
        // Line numbers in `want` are relative to the case; the wrapper adds one.
        let (pos, msg) = want.split_once(": ").unwrap();
        let (l, c) = pos.split_once(':').unwrap();
        let want = format!("e.st:{}:{c}: {msg}", l.parse::<u32>().unwrap() + 1);
        assert!(err.contains(&want), "want {want:?}, got:\n{err}");
    }
    let recursive = "FUNCTION F : INT VAR_INPUT x : INT; END_VAR F := F(x); END_FUNCTION\nPROGRAM T VAR a : INT; END_VAR a := F(1); END_PROGRAM";
    let err = compile("r.st", recursive, Options::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("F calls itself"), "{err}");
}

#[test]
fn faults_stop_the_program_until_reset() {
    let mut p = program("VAR z : INT; a, b : INT; END_VAR a := a + 1; b := 1 / z;");
    let f = p.scan(&[], &mut [], 0).unwrap_err();
    assert_eq!(f.kind, FaultKind::DivisionByZero);
    assert_eq!(
        f.to_string(),
        format!("case.st:{}:{}: PLC fault: division by zero", f.line, f.col)
    );
    let a = p.var("a").unwrap();
    assert_eq!(p.format(a), "1");
    assert!(p.scan(&[], &mut [], 1).is_err(), "stays in fault");
    assert_eq!(p.format(a), "1", "a faulted program does not run");
    p.set(p.var("z").unwrap(), hytask::plc::Value::Int(1))
        .unwrap();
    p.reset_fault();
    p.scan(&[], &mut [], 2).unwrap();
    assert_eq!(p.format(a), "2");
}

/// The example programs shipped in config/plc/ compile and do their job.
#[test]
fn example_programs() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/config/plc");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let path = e.unwrap().path();
        if path.extension().is_some_and(|x| x == "st") {
            hytask::plc::load_file(&path, Options::default())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            n += 1;
        }
    }
    assert!(n >= 2);
    let src = std::fs::read_to_string(format!("{dir}/lubrication.st")).unwrap();
    let mut p = compile("lubrication.st", &src, Options::default()).unwrap();
    let moving = p.var("moving").unwrap();
    let pump = p.var("pump").unwrap();
    let fault = p.var("fault").unwrap();
    let pressure = p.var("pressure_ok").unwrap();
    p.set(moving, hytask::plc::Value::Bool(true)).unwrap();
    let mut first_pump = None;
    let mut t = 0i64;
    // 10 minutes of motion in 10 ms scans: the pump starts once, runs 5 s.
    for scan in 0..61_000 {
        p.set(pressure, hytask::plc::Value::Bool(p.format(pump) == "TRUE"))
            .unwrap();
        p.scan(&[], &mut [], t).unwrap();
        if first_pump.is_none() && p.format(pump) == "TRUE" {
            first_pump = Some(scan);
        }
        t += 10_000_000;
    }
    assert_eq!(first_pump, Some(59_999), "interval of 10 min of motion");
    assert_eq!(p.format(p.var("pulses").unwrap()), "1");
    assert_eq!(p.format(fault), "FALSE");
    // Without pressure the next pulse raises the fault after 3 s.
    for _ in 0..61_000 {
        p.scan(&[], &mut [], t).unwrap();
        t += 10_000_000;
    }
    assert_eq!(p.format(fault), "TRUE");
}

/// The mill's lubrication (config/plc/mill.st, issue 11): a 2 s pulse of the way-oil pump
/// every 60 s of job time, none while no job runs, in PLC time (10 ms scans). The M100 pulse
/// is driven end to end in plc_machine; the 60 s interval is too long for the daemon tests.
#[test]
fn mill_lubricates_every_60_s_of_job_time() {
    use hytask::plc::Value;
    let src = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/plc/mill.st"))
        .unwrap();
    let mut p = compile("mill.st", &src, Options::default()).unwrap();
    let (job, pump) = (p.var("job_running").unwrap(), p.var("lube_pump").unwrap());
    let mut rises = Vec::new();
    let mut falls = Vec::new();
    let mut on = false;
    // 10 s idle, then 130 s of job, then 70 s idle.
    for scan in 0..21_000i64 {
        let running = (1_000..14_000).contains(&scan);
        p.set(job, Value::Bool(running)).unwrap();
        p.scan(&[], &mut [], scan * 10_000_000).unwrap();
        let now_on = p.get(pump) == Value::Bool(true);
        if now_on && !on {
            rises.push(scan);
        } else if on && !now_on {
            falls.push(scan);
        }
        on = now_on;
    }
    // The job starts at scan 1,000 (10 s): pulses at 70 s and 130 s (the interval timer
    // restarts the scan after it fires), 2 s each.
    assert_eq!(rises.len(), 2, "rises {rises:?} falls {falls:?}");
    assert_eq!(falls.len(), 2, "rises {rises:?} falls {falls:?}");
    for (r, want) in rises.iter().zip([7_000, 13_000]) {
        assert!(
            (r - want).abs() <= 3,
            "pulse at scan {r}, want ~{want}: {rises:?}"
        );
    }
    for (r, f) in rises.iter().zip(&falls) {
        assert!((f - r - 200).abs() <= 1, "a 2 s pulse: {r}..{f}");
    }
}
