//! The peephole pass (superinstructions: three-address operations, compare-and-branch,
//! fused loads and stores, dropped jumps to the next instruction) changes how many
//! instructions a scan dispatches, never what it computes: every program of the corpus, the
//! shipped programs and targeted cases run scan by scan both as compiled and as the plain
//! code generator's output, with the same pseudo-random inputs, and every variable, every
//! fault (kind, line) and every output must agree.
#![allow(clippy::unwrap_used)]

use hytask::plc::compile::compile_unfused;
use hytask::plc::{compile, Options, Program, Ty, Value, VarKind};
use std::path::Path;

/// A small deterministic generator (xorshift), so failures reproduce.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

fn random_value(ty: Ty, rng: &mut Rng) -> Option<Value> {
    let r = rng.next();
    Some(match ty {
        Ty::Bool => Value::Bool(r & 1 == 1),
        Ty::Int(_) => Value::Int((r % 41) as i64 - 20),
        Ty::Real | Ty::LReal => Value::Real(((r % 4001) as f64 - 2000.0) / 7.0),
        Ty::Time => Value::Time((r % 200) as i64 * 1_000_000),
        _ => return None,
    })
}

/// Runs `scans` scans of both versions with the same inputs (every input, and every local
/// on a few scans, set at random) and compares all cells after each.
fn same_behaviour(name: &str, fused: &mut Program, plain: &mut Program, scans: i64) {
    assert_eq!(fused.vars(), plain.vars(), "{name}: same layout");
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for n in 0..scans {
        for (i, v) in plain.vars().to_vec().iter().enumerate() {
            let poke = v.kind == VarKind::Input || (n % 7 == 3 && !v.constant);
            if !poke || rng.next().is_multiple_of(3) {
                continue;
            }
            let Some(val) = random_value(v.ty, &mut rng) else {
                continue;
            };
            let id = hytask::plc::VarId(i as u32);
            if plain.set(id, val).is_ok() {
                fused.set(id, val).unwrap();
            }
        }
        let now = n * 10_000_000;
        let (a, b) = (fused.scan(&[], &mut [], now), plain.scan(&[], &mut [], now));
        assert_eq!(a, b, "{name}: scan {n} result");
        if a.is_err() {
            fused.reset_fault();
            plain.reset_fault();
        }
        for (i, v) in plain.vars().iter().enumerate() {
            let id = hytask::plc::VarId(i as u32);
            assert_eq!(
                fused.cell(id),
                plain.cell(id),
                "{name}: scan {n}: {} differs",
                v.name
            );
        }
    }
}

fn both(name: &str, src: &str) -> Option<(Program, Program)> {
    let opts = Options { budget: 20_000 };
    let fused = compile(name, src, opts).ok()?;
    let plain = compile_unfused(name, src, opts).unwrap();
    Some((fused, plain))
}

#[test]
fn corpus_and_shipped_programs_behave_the_same_fused() {
    let mut files = Vec::new();
    for dir in ["tests/plc/corpus", "config/plc"] {
        for e in std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(dir)).unwrap() {
            files.push(e.unwrap().path());
        }
    }
    files.sort();
    let mut ran = 0;
    for f in files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "st"))
    {
        let src = std::fs::read_to_string(f).unwrap();
        let name = f.display().to_string();
        if let Some((mut fused, mut plain)) = both(&name, &src) {
            same_behaviour(&name, &mut fused, &mut plain, 300);
            ran += 1;
        }
    }
    assert!(ran >= 10, "only {ran} programs compiled");
}

/// Each fused form, including the ones that must not fuse (constants that do not fit 32
/// bits or single precision) and loops whose budget runs out at a fused backward branch.
const CASES: &[(&str, &str)] = &[
    (
        "first-order filters, REAL and LREAL, and the mixed forms that stay two instructions",
        "PROGRAM T\nVAR_INPUT a : INT; x : REAL; END_VAR\nVAR r, s : REAL; l : LREAL; END_VAR\n\
         r := r * 0.99 + INT_TO_REAL(a) * 0.01; l := l * 0.5 + INT_TO_LREAL(a) * 0.125;\n\
         s := x * 0.75 + INT_TO_REAL(a) * -3.5; r := r + INT_TO_REAL(a) * 0.25;\n\
         l := x * 0.5 + INT_TO_LREAL(a) * 0.1; s := r * 1.0E30 + INT_TO_REAL(a) * 1.0E30;\nEND_PROGRAM\n",
    ),
    (
        "three-address and compare-and-branch, INT",
        "PROGRAM T\nVAR_INPUT a, b : INT; END_VAR\nVAR c, d : INT; e : DINT; f : BOOL; END_VAR\n\
         c := a + b; d := a * 3; e := INT_TO_DINT(a) * 100000;\n\
         IF a > 5 THEN c := c - 1; END_IF;\n\
         IF a <= b THEN d := d + 2; ELSIF a = -3 THEN d := 7; ELSE d := 0; END_IF;\n\
         IF f THEN c := 0; END_IF; f := c > d;\n\
         IF e > 2000000000 THEN e := 1; END_IF;\n\
         IF e > 2000000000 THEN e := 1; END_IF;\nEND_PROGRAM\n",
    ),
    (
        "REAL and LREAL constants",
        "PROGRAM T\nVAR_INPUT x : REAL; y : LREAL; END_VAR\nVAR r : REAL; l : LREAL; b : BOOL; END_VAR\n\
         r := x * 0.99; r := r + 0.5; l := y * 0.1; l := l - 1.0E300;\n\
         IF x > 300.0 THEN r := 0.0; END_IF;\n\
         IF y < 0.1 THEN l := y; END_IF;\n\
         b := x >= 12.25; b := b AND (y <> 0.3);\n\
         r := MAX(r, 10.0); l := MIN(l, y);\nEND_PROGRAM\n",
    ),
    (
        "loops with fused backward branches",
        "PROGRAM T\nVAR_INPUT n : INT; END_VAR\nVAR i, s : INT; k : DINT; END_VAR\n\
         s := 0; i := 0;\n\
         WHILE i < n DO s := s + i; i := i + 1; END_WHILE;\n\
         REPEAT k := k + 1; UNTIL k > 3 END_REPEAT;\n\
         FOR i := 1 TO n BY 2 DO IF i = 9 THEN EXIT; END_IF; s := s - 1; END_FOR;\nEND_PROGRAM\n",
    ),
    (
        "a block's locals (base-relative) and globals",
        "VAR_GLOBAL g : INT; gb : BOOL; END_VAR\n\
         FUNCTION_BLOCK Acc\nVAR_INPUT in : INT; END_VAR\nVAR_OUTPUT sum : INT; END_VAR\n\
         VAR last : INT; END_VAR\n\
         IF in <> last THEN sum := sum + in; END_IF; last := in;\n\
         IF sum > 100 THEN sum := sum - 100; END_IF;\nEND_FUNCTION_BLOCK\n\
         PROGRAM T\nVAR_INPUT a : INT; END_VAR\nVAR acc : Acc; t : TON; q : BOOL; END_VAR\n\
         acc(in := a); g := acc.sum + g; IF g > 1000 THEN g := 0; END_IF;\n\
         t(IN := a > 0, PT := T#30ms); q := t.Q XOR gb; gb := NOT q;\nEND_PROGRAM\n",
    ),
    (
        "negated BOOL operands, constants on the left, INT_TO_REAL, x op (y op k)",
        "PROGRAM T\nVAR_INPUT a, b : INT; p, q : BOOL; u : UDINT; END_VAR\n\
         VAR c, d : INT; e, f, g : BOOL; r : REAL; l : LREAL; w : UDINT; END_VAR\n\
         e := p AND NOT q; f := p OR NOT q; g := (a > b) AND NOT e OR NOT f;\n\
         c := LIMIT(0, a, 9); d := 7 - a; d := d + 3 * b; c := MAX(-2, c);\n\
         IF 5 < a THEN c := c + 1; END_IF; IF 3 >= b THEN d := 100 / (d + 50); END_IF;\n\
         e := 4 = a; f := 2 <> b; g := 1 > u; w := 3 + u;\n\
         r := INT_TO_REAL(a) * 0.5 + INT_TO_REAL(b); l := INT_TO_LREAL(a) - 0.25;\n\
         c := c + b * 3; d := d * (a MOD 4); c := c - a * 2; d := (b + 1) - d;\n\
         w := w + u / 3; e := e XOR (a + 1 = 0); c := c + (b - 7);\nEND_PROGRAM\n",
    ),
    (
        "two operations in one: MOD-compare, op of a pair, INT_TO_REAL scaled, LIMIT, block inputs",
        "PROGRAM T\nVAR_INPUT a, b : INT; p, q : BOOL; n : DINT; u : UINT; END_VAR\n\
         VAR c, d : INT; e, f : BOOL; r : REAL; l : LREAL; t1, t2, t3 : TON; t4 : TP; k : DINT; w : UINT; END_VAR\n\
         e := (a MOD 7 = 0) OR (p AND NOT q); f := (b + 2 > 0) AND (a < b);\n\
         f := f XOR (a MOD 3 <> 1) XOR (c >= d);\n\
         c := c + b * 3; d := d * (a - 7) + 0; k := k + n * 40000; w := w + u * 7;\n\
         r := r * 0.99 + INT_TO_REAL(a) * 0.01; l := l - INT_TO_LREAL(b) * 0.5;\n\
         r := r - INT_TO_REAL(b) / 3.0; l := l * INT_TO_LREAL(a) + 0.1;\n\
         c := LIMIT(0, c, 500); d := LIMIT(-5, d, 5); k := LIMIT(-70000, k, 70000);\n\
         t1(IN := e, PT := T#30ms); t2(PT := T#50ms, IN := f); f := t1.Q OR t2.Q;\n\
         t3(PT := T#1d3ms, IN := e); t4(IN := p); e := t3.Q OR t4.Q;\n\
         IF t1.Q THEN c := 0; END_IF;\nEND_PROGRAM\n",
    ),
    (
        "remainders by constants multiplied out: every 16-bit kind, signs, wide dividends",
        "PROGRAM T\nVAR_INPUT a : INT; s : SINT; END_VAR\n\
         VAR u : UINT; us : USINT; w : WORD; n : DINT; i : INT; e, f, g, h : BOOL; END_VAR\n\
         u := u + 12345; us := us + 77; w := w + 4099; i := i * 3 - 20000; n := n + 70001;\n\
         e := (a MOD 7 = 0) OR (s MOD 3 = -1); f := (u MOD 1000 > 500) XOR (us MOD 9 < 4);\n\
         g := (w MOD 256 = 3) OR (i MOD 32767 < -100); h := (i MOD 12 >= 0) AND (n MOD 7 = 2);\n\
         IF (i MOD 5 = -2) OR (a MOD 2 <> 0) THEN u := u + 1; END_IF;\nEND_PROGRAM\n",
    ),
];

/// The forms of the third generation of fusion fire on the code that needs them (a test
/// that fails if a rule stops matching).
#[test]
fn operand_negation_swaps_conversions_and_reordering_fire() {
    use hytask::plc::vm::{Bin, Op};
    let has = |src: &str, want: &dyn Fn(&Op) -> bool| {
        let p = compile("t.st", src, Options::default()).unwrap();
        assert!(p.code().iter().any(want), "{src}: {:?}", p.code());
    };
    let head = "PROGRAM T\nVAR a, b, c : INT; p, q, e : BOOL; r : REAL; END_VAR\n";
    has(&format!("{head}e := p AND NOT q;\nEND_PROGRAM\n"), &|op| {
        matches!(op, Op::PushLL(Bin::AndN, ..) | Op::BinLL(Bin::AndN, ..))
    });
    has(&format!("{head}e := p OR NOT q;\nEND_PROGRAM\n"), &|op| {
        matches!(op, Op::BinLL(Bin::OrN, ..))
    });
    has(
        &format!("{head}IF 5 < a THEN a := 0; END_IF;\nEND_PROGRAM\n"),
        &|op| matches!(op, Op::JfLI(Bin::CmpI(hytask::plc::vm::Cmp::Gt), _, 5, _)),
    );
    has(
        &format!("{head}r := INT_TO_REAL(a) * 0.5;\nEND_PROGRAM\n"),
        &|op| matches!(op, Op::LoadIToF(..)),
    );
    has(&format!("{head}a := a + b * 3;\nEND_PROGRAM\n"), &|op| {
        // The fourth pass makes one instruction of the two (`BinLIL`).
        matches!(
            op,
            Op::BinLS(Bin::Add(_), 0, 0) | Op::BinLIL(Bin::Mul(_), Bin::Add(_), 1, 0, 0, 3)
        )
    });
}

/// The forms of the fourth generation (two operations in one instruction) fire on the code
/// that needs them, and a cell beyond a 16-bit offset keeps the unfused pair (and the same
/// behaviour).
#[test]
fn two_operation_forms_fire_and_far_cells_stay_unfused() {
    use hytask::plc::vm::Op;
    let code = |src: &str| {
        compile("t.st", src, Options::default())
            .unwrap()
            .code()
            .to_vec()
    };
    let head =
        "PROGRAM T\nVAR a, b, c : INT; p, q, e : BOOL; r : REAL; l : LREAL; t : TON; n : DINT; s : SINT; u : UINT; END_VAR\n";
    type Want = dyn Fn(&Op) -> bool;
    let cases: [(&str, &Want); 14] = [
        // A remainder of a 16-bit (or narrower) cell by a constant is multiplied out.
        (
            "e := (a MOD 7 = 0) OR q;",
            &|op| matches!(op, Op::PushModC(_, _, 7, m, 0) if *m == hytask::plc::op::mod_magic(7)),
        ),
        ("e := (s MOD 3 <> 1) OR q;", &|op| {
            matches!(op, Op::PushModC(_, _, 3, _, 1))
        }),
        // A 32-bit cell, a divisor of 1 or beyond 15 bits keep the divide.
        ("e := (n MOD 7 = 0) OR q;", &|op| {
            matches!(op, Op::PushLIC(..))
        }),
        ("e := (a MOD 1 = 0) OR q;", &|op| {
            matches!(op, Op::PushLIC(..))
        }),
        ("e := (u MOD 40000 = 0) OR q;", &|op| {
            matches!(op, Op::PushLIC(..))
        }),
        ("e := (a > b) OR (p AND NOT q);", &|op| {
            matches!(op, Op::BinSLL(..))
        }),
        ("a := a + b * 3;", &|op| matches!(op, Op::BinLIL(..))),
        ("r := r + INT_TO_REAL(a) * 0.25;", &|op| {
            matches!(op, Op::BinSIToF(..))
        }),
        ("r := r * 0.5 + INT_TO_REAL(a) * 0.25;", &|op| {
            matches!(op, Op::FilterF(true, _, _, _, 0.5, 0.25))
        }),
        ("l := l * 0.5 + INT_TO_LREAL(a) * 0.25;", &|op| {
            matches!(op, Op::FilterF(false, _, _, _, 0.5, 0.25))
        }),
        ("c := LIMIT(0, a, 500);", &|op| {
            matches!(op, Op::ClampI(_, _, 0, 500))
        }),
        ("t(IN := e, PT := T#5s);", &|op| {
            matches!(
                op,
                Op::StdSetMov {
                    k: 9_765_625,
                    sh: 9,
                    ..
                }
            )
        }),
        ("t(PT := T#5s, IN := e);", &|op| {
            matches!(op, Op::StdSetMov { .. })
        }),
        // A constant that is not a 32-bit value shifted keeps its own store.
        ("t(PT := T#1d3ms, IN := e);", &|op| {
            matches!(op, Op::StdMov { .. })
        }),
    ];
    for (stmt, want) in cases {
        let ops = code(&format!("{head}{stmt}\nEND_PROGRAM\n"));
        assert!(ops.iter().any(want), "{stmt}: {ops:?}");
    }
    // The same statements on cells more than 65,535 cells from the base.
    let far = "PROGRAM T\nVAR pad : ARRAY[0..70000] OF INT; a, b, c : INT; e, q : BOOL; r : REAL; END_VAR\n\
               e := (a MOD 7 = 0) OR q; a := a + b * 3; r := r * 0.5 + INT_TO_REAL(a) * 0.25;\n\
               c := LIMIT(0, a, 500); e := (a > b) OR (q AND NOT e);\nEND_PROGRAM\n";
    let ops = code(far);
    let two = |op: &Op| {
        matches!(
            op,
            Op::PushLIC(..)
                | Op::PushModC(..)
                | Op::BinSLL(..)
                | Op::BinLIL(..)
                | Op::BinSIToF(..)
                | Op::FilterF(..)
                | Op::ClampI(..)
        )
    };
    assert!(!ops.iter().any(two), "{ops:?}");
    let (mut fused, mut plain) = both("far.st", far).unwrap();
    same_behaviour("far", &mut fused, &mut plain, 6);
}

#[test]
fn targeted_cases_behave_the_same_fused() {
    for (name, src) in CASES {
        let (mut fused, mut plain) = both(name, src).unwrap_or_else(|| panic!("{name}"));
        assert!(
            fused.code().len() < plain.code().len(),
            "{name}: nothing fused"
        );
        same_behaviour(name, &mut fused, &mut plain, 400);
    }
}

/// A loop that never ends faults at the same line fused and plain: the budget is charged at
/// the backward branch, in the instructions the loop body dispatches (fewer when fused, so
/// the fault comes after more iterations, but at the same place).
#[test]
fn an_endless_loop_faults_at_its_line_fused() {
    let src = "PROGRAM T\nVAR i : INT; END_VAR\n\
               WHILE i >= 0 DO\n  i := i + 1;\n  IF i > 100 THEN i := 0; END_IF;\nEND_WHILE;\nEND_PROGRAM\n";
    let (mut fused, mut plain) = both("loop.st", src).unwrap();
    let a = fused.scan(&[], &mut [], 0).unwrap_err();
    let b = plain.scan(&[], &mut [], 0).unwrap_err();
    assert_eq!((a.kind, a.line), (b.kind, b.line));
    assert_eq!(a.line, 3, "the WHILE's line");
}

/// The benchmark's 10-statement pattern: what the superinstructions buy, as a bound that
/// fails if the peephole pass stops firing.
#[test]
fn the_bench_pattern_shrinks() {
    let src = "PROGRAM B\nVAR a, b, cnt, y : INT; x, q, flag : BOOL; r : REAL; t : TON; END_VAR\n\
               a := a + b * 3;\nIF a > 1000 THEN\n  a := a - 1000;\nEND_IF;\n\
               x := (a MOD 7 = 0) OR (flag AND NOT x);\nt(IN := x, PT := T#50ms);\n\
               q := t.Q XOR flag;\nr := r * 0.99 + INT_TO_REAL(a) * 0.01;\n\
               cnt := cnt + BOOL_TO_INT(q);\ny := LIMIT(0, cnt, 500);\nflag := r > 300.0;\nEND_PROGRAM\n";
    let (mut fused, mut plain) = both("bench.st", src).unwrap();
    let (f, p) = (fused.code().len(), plain.code().len());
    assert!(
        f * 2 <= p,
        "fused {f} instructions, plain {p}: {:?}",
        fused.code()
    );
    same_behaviour("bench", &mut fused, &mut plain, 300);
}

/// Superinstructions carry their constants in 32 bits so that an instruction stays 16 bytes:
/// the code of a 2,000-statement program stays in cache.
#[test]
fn an_instruction_is_16_bytes() {
    assert_eq!(std::mem::size_of::<hytask::plc::vm::Op>(), 16);
}
