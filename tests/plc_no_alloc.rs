//! A PLC scan allocates nothing: the whole program (timers, counters, user blocks and
//! functions, loops, dynamic array indexing, the bound process image) runs many scans under
//! the counting allocator after one warm-up scan, and so does the faulting path.
#![allow(clippy::unwrap_used)]

use hytask::plc::{compile, Options, Value};

mod counting_alloc;

use counting_alloc::during as allocations;

const SRC: &str = r#"
TYPE Axis : STRUCT pos : LREAL; homed : BOOL; END_STRUCT END_TYPE
FUNCTION Clamp : DINT
VAR_INPUT x, lo, hi : DINT; END_VAR
Clamp := LIMIT(lo, x, hi);
END_FUNCTION
FUNCTION_BLOCK Debounce
VAR_INPUT raw : BOOL; t : TIME := T#30ms; END_VAR
VAR_OUTPUT q : BOOL; END_VAR
VAR on : TON; off : TOF; END_VAR
on(IN := raw, PT := t);
off(IN := on.Q, PT := t);
q := off.Q;
END_FUNCTION_BLOCK
PROGRAM Main
VAR_INPUT button : BOOL; divisor : INT := 1; END_VAR
VAR_OUTPUT lamp : BOOL; count : INT; END_VAR
VAR
  db : Debounce;
  ctr : CTU;
  hist : ARRAY[0..15] OF DINT;
  i, k : DINT;
  axes : ARRAY[1..3] OF Axis;
  trig : ARRAY[0..3] OF R_TRIG;
  w : WORD;
  q : INT;
END_VAR
db(raw := button);
ctr(CU := db.q, R := count > 100, PV := 10);
count := ctr.CV;
lamp := ctr.Q OR db.q;
k := (k + 1) MOD 16;
hist[k] := Clamp(x := count * 3, lo := 0, hi := 200);
FOR i := 0 TO 15 DO
  IF hist[i] > 100 THEN EXIT; END_IF;
  axes[i MOD 3 + 1].pos := axes[i MOD 3 + 1].pos + 0.5;
END_FOR;
trig[k MOD 4](CLK := button);
w.3 := trig[k MOD 4].Q;
q := 100 / divisor;
END_PROGRAM
"#;

#[test]
fn scans_do_not_allocate() {
    let mut p = compile("alloc.st", SRC, Options::default()).unwrap();
    let button = p.var("button").unwrap();
    let lamp = p.var("Main.lamp").unwrap();
    let count = p.var("count").unwrap();
    p.bind(
        &[button],
        &[(lamp, Value::Bool(false)), (count, Value::Int(0))],
    );
    let mut outs = [Value::Bool(false), Value::Int(0)];
    p.scan(&[Value::Bool(false)], &mut outs, 0).unwrap();
    let mut presses = 0;
    let n = allocations(|| {
        for s in 1..20_000i64 {
            let pressed = s % 20 < 10;
            presses += (s % 20 == 0) as u32;
            p.scan(&[Value::Bool(pressed)], &mut outs, s * 10_000_000)
                .unwrap();
        }
    });
    assert_eq!(n, 0, "allocations during 20,000 scans");
    assert!(
        presses > 0 && outs[1] != Value::Int(0),
        "the program did work: {outs:?}"
    );
}

#[test]
fn a_faulting_scan_does_not_allocate() {
    let mut p = compile("alloc.st", SRC, Options::default()).unwrap();
    let divisor = p.var("divisor").unwrap();
    let lamp = p.var("lamp").unwrap();
    p.bind(&[divisor], &[(lamp, Value::Bool(false))]);
    let mut outs = [Value::Bool(true)];
    p.scan(&[Value::Int(1)], &mut outs, 0).unwrap();
    let mut faults = 0;
    let n = allocations(|| {
        for s in 1..1000i64 {
            if p.scan(&[Value::Int(0)], &mut outs, s).is_err() {
                faults += 1;
            }
            p.reset_fault();
        }
    });
    assert_eq!(n, 0);
    assert_eq!(faults, 999);
    assert_eq!(outs[0], Value::Bool(false), "outputs at their safe values");
}
