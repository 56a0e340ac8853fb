//! Script engine cost: one state-machine step and one program statement, each against the
//! same logic written as native Rust, in the same run. Prints ns per step / per statement
//! and the ratio (measured over many iterations) before criterion's own measurement.
//! Zero allocation per step is tested in tests/script_no_alloc.rs.

// criterion_group! generates an undocumented function.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};
use hytask::plc::Value;
use hytask::script::{compile, Bindings, Ctl, Engine, Limits};
use std::hint::black_box;
use std::time::Instant;

/// A two-state machine: RUN blocks with arithmetic, transitions on conditions, an ENTRY
/// block and a precondition.
const MACHINE: &str = r#"
STATE_MACHINE m
VAR
  k : DINT;
  x : DINT;
END_VAR
  INITIAL STATE a
    RUN
      k := k + 1;
      x := x + k MOD 3;
    END_RUN
    TRANSITION WHEN k MOD 4 = 3 TO b;
  END_STATE
  STATE b
    PRECONDITION k >= 0;
    ENTRY x := x - 1; END_ENTRY
    RUN k := k + 1; END_RUN
    TRANSITION WHEN k MOD 4 = 0 TO a;
  END_STATE
  FINAL STATE z
  END_STATE
END_STATE_MACHINE
"#;

#[derive(Clone, Copy, PartialEq)]
enum S {
    A,
    B,
}

/// The machine above, natively: same states, conditions, blocks and step rule (one
/// transition per step; a state entered runs its ENTRY in that step).
struct NativeMachine {
    s: S,
    k: i32,
    x: i32,
}

impl NativeMachine {
    #[inline(never)]
    fn step(&mut self) {
        match self.s {
            S::A => {
                if self.k % 4 == 3 {
                    self.s = S::B;
                    assert!(self.k >= 0, "precondition");
                    self.x -= 1;
                } else {
                    self.k += 1;
                    self.x += self.k % 3;
                }
            }
            S::B => {
                assert!(self.k >= 0, "precondition");
                if self.k % 4 == 0 {
                    self.s = S::A;
                } else {
                    self.k += 1;
                }
            }
        }
    }
}

/// Statements of the program (pairs of an assignment and an IF).
const PAIRS: usize = 32;

fn program() -> String {
    let mut s = String::from("PROGRAM p\nVAR\n  a : DINT; b : DINT := 7;\nEND_VAR\n");
    for _ in 0..PAIRS {
        s.push_str("  a := a + b * 3;\n  IF a > 1000 THEN a := a - 1000; END_IF;\n");
    }
    s.push_str("END_PROGRAM\n");
    s
}

#[inline(never)]
fn native_program(a: &mut i32, b: i32) {
    for _ in 0..PAIRS {
        *a += b * 3;
        if *a > 1000 {
            *a -= 1000;
        }
    }
}

fn engine(src: &str, item: &str) -> (Engine, usize) {
    let script = compile("bench.st", src).expect("bench script");
    let loaded = script.bind(&Bindings::default()).expect("bind");
    let mut e = Engine::new(Limits {
        ops_per_step: 256,
        max_scripts: 1,
    });
    let slot = e.load(loaded).expect("load");
    e.start(slot, item).expect("start");
    (e, slot)
}

fn ns_per_iter(n: u32, mut f: impl FnMut()) -> f64 {
    for _ in 0..n / 10 {
        f();
    }
    let t = Instant::now();
    for _ in 0..n {
        f();
    }
    t.elapsed().as_nanos() as f64 / f64::from(n)
}

fn bench(c: &mut Criterion) {
    // Same results from both, so they do the same work.
    let (mut e, slot) = engine(MACHINE, "m");
    let mut nm = NativeMachine {
        s: S::A,
        k: 0,
        x: 0,
    };
    for _ in 0..1000 {
        e.step_state_machines(0);
        nm.step();
    }
    assert_eq!(e.get(slot, "m.k").expect("k"), Value::Int(i64::from(nm.k)));
    assert_eq!(e.get(slot, "m.x").expect("x"), Value::Int(i64::from(nm.x)));
    assert_eq!(e.status(slot).expect("status")[0].transitions, 500);

    let (mut pe, pslot) = engine(&program(), "p");
    let (mut a, b) = (0i32, 7i32);
    for _ in 0..100 {
        pe.ctl(pslot, 0, Ctl::Start).expect("start");
        pe.step_programs(0);
        native_program(&mut a, b);
    }
    assert_eq!(pe.get(pslot, "p.a").expect("a"), Value::Int(i64::from(a)));

    let n = 200_000;
    let sm = ns_per_iter(n, || e.step_state_machines(black_box(0)));
    let sm_native = ns_per_iter(n, || nm.step());
    let pr = ns_per_iter(n / 10, || {
        pe.ctl(pslot, 0, Ctl::Start).expect("start");
        pe.step_programs(black_box(0));
    }) / (2 * PAIRS) as f64;
    let pr_native =
        ns_per_iter(n / 10, || native_program(&mut a, black_box(b))) / (2 * PAIRS) as f64;
    println!(
        "state-machine step: script {sm:.1} ns, native {sm_native:.1} ns, ratio {:.0}x",
        sm / sm_native
    );
    println!(
        "program statement: script {pr:.1} ns, native {pr_native:.2} ns, ratio {:.0}x",
        pr / pr_native
    );

    c.bench_function("script/state_machine_step", |bch| {
        bch.iter(|| e.step_state_machines(black_box(0)))
    });
    c.bench_function("native/state_machine_step", |bch| bch.iter(|| nm.step()));
    c.bench_function("script/program_64_statements", |bch| {
        bch.iter(|| {
            pe.ctl(pslot, 0, Ctl::Start).expect("start");
            pe.step_programs(black_box(0));
        })
    });
    c.bench_function("native/program_64_statements", |bch| {
        bch.iter(|| native_program(&mut a, black_box(b)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
