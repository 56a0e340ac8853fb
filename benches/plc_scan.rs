//! PLC scan time: a 2,000-statement Structured Text program (integer and REAL arithmetic,
//! boolean logic, comparisons, IF, TON timers, conversions, LIMIT) and the built-in mill's
//! program (config/plc/mill.st, with its bound process image), each against a natively
//! compiled Rust function of the same logic, in the same run. Prints p50/p99 of single
//! scans (timed one by one) before criterion's own measurement of both.

// criterion_group! generates an undocumented function.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};
use hytask::plc::{compile, Options, Program, Value};
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

/// IEC pulse timer, natively (as `stdfb`'s TP).
#[derive(Clone, Copy, Default)]
struct Tp {
    q: bool,
    start: i64,
    prev: bool,
}

impl Tp {
    #[inline]
    fn call(&mut self, input: bool, pt: i64, now: i64) {
        if !self.q && input && !self.prev {
            self.start = now;
            self.q = true;
        }
        if self.q {
            self.q = now - self.start < pt;
        }
        self.prev = input;
    }
}

/// The mill's inputs, in the order they are bound below.
const MILL_INPUTS: [&str; 13] = [
    "estop_button",
    "reset_button",
    "machine_reset",
    "door_open",
    "job_running",
    "spindle_cmd",
    "at_speed",
    "flood_cmd",
    "mist_cmd",
    "tool_request",
    "tool_number",
    "mcode_request",
    "mcode_number",
];
/// Its outputs.
const MILL_OUTPUTS: [&str; 10] = [
    "machine_estop",
    "feed_hold",
    "start_inhibit",
    "spindle_ready",
    "spindle_fault",
    "coolant_pump",
    "tool_done",
    "carousel_motor",
    "mcode_done",
    "lube_pump",
];

/// config/plc/mill.st, natively: inputs and outputs in the orders above.
#[derive(Default)]
struct NativeMill {
    started: bool,
    reset_prev: bool,
    chain: bool,
    was_at_speed: bool,
    spindle_fault: bool,
    changing: bool,
    pocket: i64,
    target: i64,
    step: Ton,
    lube_wait: Ton,
    lube: Tp,
    out: [bool; 10],
}

impl NativeMill {
    #[inline(never)]
    fn scan(&mut self, i: &[i64; 13], now: i64) {
        let b = |k: usize| i[k] != 0;
        let reset = b(1) || b(2);
        let edge = reset && !self.reset_prev;
        self.reset_prev = reset;
        let estop = b(0);
        // RS, reset dominant: Q1 := NOT R1 AND (S OR Q1), with S = (edge OR first) AND NOT estop.
        self.chain = !estop && (edge || !self.started || self.chain);
        self.started = true;
        let (spindle_cmd, at_speed) = (b(5), b(6));
        if !spindle_cmd {
            self.was_at_speed = false;
            self.spindle_fault = false;
        } else if at_speed {
            self.was_at_speed = true;
        } else if self.was_at_speed {
            self.spindle_fault = true;
        }
        let mut tool_done = false;
        if b(9) && !self.changing {
            self.target = i[10].rem_euclid(12);
            self.changing = i[10] >= 0 && i[10] < 12;
        }
        let motor = self.changing && self.pocket != self.target;
        let step_in = motor && !self.step.q;
        self.step.call(step_in, 100_000_000, now);
        if self.step.q {
            self.pocket = (self.pocket + 1) % 12;
        }
        if self.changing && self.pocket == self.target {
            tool_done = true;
            self.changing = false;
        }
        let lube_now = b(11) && i[12] == 100;
        let wait_in = b(4) && !self.lube_wait.q;
        self.lube_wait.call(wait_in, 60_000_000_000, now);
        self.lube
            .call(self.lube_wait.q || lube_now, 2_000_000_000, now);
        self.out = [
            !self.chain,
            b(3) && b(4),
            b(3),
            spindle_cmd && at_speed,
            self.spindle_fault,
            b(7) || b(8),
            tool_done,
            motor,
            lube_now,
            self.lube.q,
        ];
    }
}

/// Inputs of scan `s`: a job with door openings, spindle, coolant, tool changes, M100.
fn mill_inputs(s: i64) -> [i64; 13] {
    let phase = s % 400;
    [
        (phase == 390) as i64,
        (phase == 395) as i64,
        0,
        (100..120).contains(&phase) as i64,
        (phase >= 10) as i64,
        (phase >= 20) as i64,
        (phase >= 40 && phase != 200) as i64,
        (phase >= 30) as i64,
        0,
        (50..80).contains(&phase) as i64,
        (s / 400) % 14,
        (phase == 300) as i64,
        100,
    ]
}

fn mill(c: &mut Criterion) {
    let mut p = compile(
        "config/plc/mill.st",
        hytask::config::BUILTIN_MILL_ST,
        Options::default(),
    )
    .expect("mill program");
    let ins: Vec<_> = MILL_INPUTS.iter().map(|n| p.var(n).expect(n)).collect();
    let outs: Vec<_> = MILL_OUTPUTS
        .iter()
        .map(|n| (p.var(n).expect(n), Value::Bool(false)))
        .collect();
    p.bind(&ins, &outs);
    let mut n = NativeMill::default();
    let mut in_vals = [Value::Bool(false); 13];
    let mut out_vals = [Value::Bool(false); 10];
    let set_inputs = |vals: &mut [Value; 13], raw: &[i64; 13]| {
        for (k, v) in vals.iter_mut().enumerate() {
            *v = if k == 10 || k == 12 {
                Value::Int(raw[k])
            } else {
                Value::Bool(raw[k] != 0)
            };
        }
    };
    // Same outputs from both over every phase, so they do the same work.
    for s in 0..6000 {
        let raw = mill_inputs(s);
        set_inputs(&mut in_vals, &raw);
        p.scan(&in_vals, &mut out_vals, s * 10_000_000)
            .expect("scan");
        n.scan(&raw, s * 10_000_000);
        let plc: Vec<bool> = out_vals.iter().map(|v| *v == Value::Bool(true)).collect();
        assert_eq!(plc, n.out, "mill outputs differ at scan {s}");
    }
    println!(
        "plc_scan mill: {} instructions, {} memory cells",
        p.code_len(),
        p.memory_cells()
    );
    let (mut tp, mut tn) = (Vec::new(), Vec::new());
    for s in 6000..46_000i64 {
        let raw = mill_inputs(s);
        set_inputs(&mut in_vals, &raw);
        let now = s * 10_000_000;
        let t0 = Instant::now();
        black_box(p.scan(&in_vals, &mut out_vals, now)).expect("scan");
        let t1 = Instant::now();
        n.scan(black_box(&raw), black_box(now));
        black_box(&n);
        let t2 = Instant::now();
        tp.push((t1 - t0).as_nanos() as u64);
        tn.push((t2 - t1).as_nanos() as u64);
    }
    let ((p50, p99), (n50, n99)) = (percentiles(tp), percentiles(tn));
    println!(
        "plc_scan mill: PLC p50 {p50} ns p99 {p99} ns | native p50 {n50} ns p99 {n99} ns | ratio p50 {:.1}x",
        p50 as f64 / n50.max(1) as f64
    );
    let mut g = c.benchmark_group("plc_scan_mill");
    g.sample_size(50);
    let raw = mill_inputs(70);
    set_inputs(&mut in_vals, &raw);
    g.bench_function("plc", |b| {
        let mut now = 0;
        b.iter(|| {
            now += 10_000_000;
            black_box(p.scan(&in_vals, &mut out_vals, now)).expect("scan");
        })
    });
    g.bench_function("native", |b| {
        let mut now = 0;
        b.iter(|| {
            now += 10_000_000;
            n.scan(black_box(&raw), black_box(now));
            black_box(&n);
        })
    });
    g.finish();
}

criterion_group!(benches, bench, mill);
criterion_main!(benches);
