//! PLC scan time: a 2,000-statement Structured Text program (integer and REAL arithmetic,
//! boolean logic, comparisons, IF, TON timers, conversions, LIMIT) against a natively
//! compiled Rust function of the same logic, in the same run. Prints p50/p99 of single
//! scans (timed one by one) before criterion's own measurement of both.

// criterion_group! generates an undocumented function.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};
use hytask::plc::{compile, Options, Program};
use std::hint::black_box;
use std::time::Instant;

/// Repetitions of the 10-statement pattern.
const REPS: usize = 200;

/// The ST program: `REPS` copies of a 10-statement pattern on distinct array elements
/// (constant indexes, so every access is a direct variable access).
fn source() -> String {
    let mut s = format!(
        "PROGRAM Bench\nVAR\n  a, b, cnt, y : ARRAY[0..{n}] OF INT;\n  x, q, flag : ARRAY[0..{n}] OF BOOL;\n  r : ARRAY[0..{n}] OF REAL;\n  t : ARRAY[0..{n}] OF TON;\nEND_VAR\n",
        n = REPS - 1
    );
    for k in 0..REPS {
        s.push_str(&format!(
            "a[{k}] := a[{k}] + b[{k}] * 3;\n\
             IF a[{k}] > 1000 THEN\n  a[{k}] := a[{k}] - 1000;\nEND_IF;\n\
             x[{k}] := (a[{k}] MOD 7 = 0) OR (flag[{k}] AND NOT x[{k}]);\n\
             t[{k}](IN := x[{k}], PT := T#50ms);\n\
             q[{k}] := t[{k}].Q XOR flag[{k}];\n\
             r[{k}] := r[{k}] * 0.99 + INT_TO_REAL(a[{k}]) * 0.01;\n\
             cnt[{k}] := cnt[{k}] + BOOL_TO_INT(q[{k}]);\n\
             y[{k}] := LIMIT(0, cnt[{k}], 500);\n\
             flag[{k}] := r[{k}] > 300.0;\n"
        ));
    }
    s.push_str("END_PROGRAM\n");
    s
}

/// IEC on-delay timer, natively.
#[derive(Clone, Copy, Default)]
struct Ton {
    q: bool,
    start: i64,
    prev: bool,
}

impl Ton {
    #[inline]
    fn call(&mut self, input: bool, pt: i64, now: i64) {
        if !input {
            self.q = false;
        } else {
            if !self.prev {
                self.start = now;
            }
            self.q = now - self.start >= pt;
        }
        self.prev = input;
    }
}

/// The same logic as `source()`, natively.
struct Native {
    a: [i16; REPS],
    b: [i16; REPS],
    cnt: [i16; REPS],
    y: [i16; REPS],
    x: [bool; REPS],
    q: [bool; REPS],
    flag: [bool; REPS],
    r: [f32; REPS],
    t: [Ton; REPS],
}

impl Native {
    fn new() -> Self {
        Native {
            a: [0; REPS],
            b: [0; REPS],
            cnt: [0; REPS],
            y: [0; REPS],
            x: [false; REPS],
            q: [false; REPS],
            flag: [false; REPS],
            r: [0.0; REPS],
            t: [Ton::default(); REPS],
        }
    }

    #[inline(never)]
    fn scan(&mut self, now: i64) {
        for k in 0..REPS {
            self.a[k] = self.a[k].wrapping_add(self.b[k].wrapping_mul(3));
            if self.a[k] > 1000 {
                self.a[k] = self.a[k].wrapping_sub(1000);
            }
            self.x[k] = (self.a[k] % 7 == 0) || (self.flag[k] && !self.x[k]);
            self.t[k].call(self.x[k], 50_000_000, now);
            self.q[k] = self.t[k].q ^ self.flag[k];
            self.r[k] = self.r[k] * 0.99 + self.a[k] as f32 * 0.01;
            self.cnt[k] = self.cnt[k].wrapping_add(self.q[k] as i16);
            self.y[k] = self.cnt[k].clamp(0, 500);
            self.flag[k] = self.r[k] > 300.0;
        }
    }
}

fn setup() -> (Program, Native) {
    let mut p = compile("bench.st", &source(), Options::default()).expect("bench program");
    let mut n = Native::new();
    for k in 0..REPS {
        let b = (k % 13) as i64 + 1;
        let id = p.var(&format!("Bench.b[{k}]")).expect("b");
        p.set(id, hytask::plc::Value::Int(b)).expect("set");
        n.b[k] = b as i16;
    }
    (p, n)
}

fn percentiles(mut v: Vec<u64>) -> (u64, u64) {
    v.sort_unstable();
    (v[v.len() / 2], v[v.len() * 99 / 100])
}

fn bench(c: &mut Criterion) {
    let (mut p, mut n) = setup();
    // Same results from both, so they do the same work.
    for s in 0..500 {
        p.scan(&[], &mut [], s * 10_000_000).expect("scan");
        n.scan(s * 10_000_000);
    }
    for k in [0, 7, REPS - 1] {
        let cnt = p.get(p.var(&format!("Bench.cnt[{k}]")).expect("cnt"));
        assert_eq!(cnt, hytask::plc::Value::Int(n.cnt[k] as i64), "cnt[{k}]");
        let r = p.get(p.var(&format!("Bench.r[{k}]")).expect("r"));
        assert_eq!(r, hytask::plc::Value::Real(n.r[k] as f64), "r[{k}]");
    }
    println!(
        "plc_scan: {} statements, {} instructions, {} memory cells",
        REPS * 10,
        p.code_len(),
        p.memory_cells()
    );
    // Per-scan percentiles, interleaved so both see the same machine load.
    let (mut tp, mut tn) = (Vec::new(), Vec::new());
    let mut now = 0i64;
    for _ in 0..20_000 {
        now += 10_000_000;
        let t0 = Instant::now();
        black_box(p.scan(&[], &mut [], now)).expect("scan");
        let t1 = Instant::now();
        n.scan(black_box(now));
        black_box(&n);
        let t2 = Instant::now();
        tp.push((t1 - t0).as_nanos() as u64);
        tn.push((t2 - t1).as_nanos() as u64);
    }
    let ((p50, p99), (n50, n99)) = (percentiles(tp), percentiles(tn));
    println!(
        "plc_scan: PLC p50 {:.1} us p99 {:.1} us | native p50 {:.1} us p99 {:.1} us | ratio p50 {:.1}x",
        p50 as f64 / 1e3,
        p99 as f64 / 1e3,
        n50 as f64 / 1e3,
        n99 as f64 / 1e3,
        p50 as f64 / n50.max(1) as f64
    );
    let mut g = c.benchmark_group("plc_scan_2000");
    g.sample_size(50);
    g.bench_function("plc", |b| {
        let mut now = 0;
        b.iter(|| {
            now += 10_000_000;
            black_box(p.scan(&[], &mut [], now)).expect("scan");
        })
    });
    g.bench_function("native", |b| {
        let mut now = 0;
        b.iter(|| {
            now += 10_000_000;
            n.scan(black_box(now));
            black_box(&n);
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
