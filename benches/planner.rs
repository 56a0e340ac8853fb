//! Planner benchmarks: planning throughput (segments per second) on dense CAM-style streams
//! and interpolator cost per servo period. Planner *quality* (job time against lower bounds
//! and a stop-at-every-corner planner) is printed once at start-up; see benches/README.md,
//! section "Planner".
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use hytask::gcode::canon::MotionControl;
use hytask::gcode::{Canon, CanonCmd, SourceLoc};
use hytask::motion::bounds::bounds;
use hytask::motion::{plan, trace, Interpolator, MotionConfig, SliceSource};
use std::hint::black_box;

/// `n` chords of `step_mm` (arc length) along y = 5·sin(2πx/40) at F3000, G64 P0.05.
fn sine_stream(n: usize, step_mm: f64) -> Vec<Canon> {
    let loc = |line| SourceLoc {
        file: "bench.ngc".into(),
        line,
        col: 1,
    };
    let mut c = vec![
        Canon {
            loc: loc(1),
            cmd: CanonCmd::SetFeedRate(3000.0),
        },
        Canon {
            loc: loc(2),
            cmd: CanonCmd::SetMotionControl(MotionControl::Continuous { tolerance: 0.05 }),
        },
    ];
    let w = 2.0 * std::f64::consts::PI / 40.0;
    let mut x = 0.0f64;
    for i in 0..n {
        let slope = 5.0 * w * (w * x).cos();
        x += step_mm / (1.0 + slope * slope).sqrt();
        let mut p = [0.0; 9];
        p[0] = x;
        p[1] = 5.0 * (w * x).sin();
        c.push(Canon {
            loc: loc(3 + i as u32),
            cmd: CanonCmd::StraightFeed(p),
        });
    }
    c
}

fn cases() -> Vec<(&'static str, Vec<Canon>)> {
    vec![
        ("3000x0.1mm", sine_stream(3000, 0.1)),
        ("10000x0.02mm", sine_stream(10_000, 0.02)),
    ]
}

fn report_quality(cfg: &MotionConfig, variant: &str) {
    for (name, canon) in cases() {
        let p = plan(&canon, cfg).unwrap();
        let b = bounds(&canon, cfg).unwrap();
        let tr = trace::run(&p, cfg, 10_000_000, |_, _| {});
        eprintln!(
            "quality {name} [{variant}]: planned {:.3} s, trace {:.3} s, {} segments; feed bound {:.3} s -> {:.3}x; \
             corner estimate {:.3} s -> {:.3}x; stop-at-corners {:.3} s -> {:.3}x; worst peak/limit {:.4}",
            p.duration_s,
            tr.duration_s(),
            p.segment_count,
            b.feed_limited_s,
            p.duration_s / b.feed_limited_s,
            b.corner_estimate_s,
            p.duration_s / b.corner_estimate_s,
            b.naive_stop_s,
            p.duration_s / b.naive_stop_s,
            tr.peaks().worst_ratio(cfg)
        );
    }
}

fn planner(c: &mut Criterion) {
    let cfg = MotionConfig::default();
    report_quality(
        &cfg,
        "defaults: J 50000 mm/s³, 20% override reserve, merge 1/2 of P",
    );
    report_quality(
        &MotionConfig {
            merge_fraction: 0.0,
            ..cfg.clone()
        },
        "no merging",
    );
    report_quality(
        &cfg.clone().with_xyz_limits(50.0, 500.0, 5.0e6),
        "J 5e6 mm/s³ (~accel-only, like LinuxCNC 2.9)",
    );
    report_quality(
        &MotionConfig {
            override_reserve: 0.05,
            ..cfg.clone()
        },
        "5% override reserve",
    );
    let mut g = c.benchmark_group("plan");
    g.sample_size(20);
    for (name, canon) in cases() {
        g.throughput(Throughput::Elements((canon.len() - 2) as u64));
        g.bench_with_input(BenchmarkId::from_parameter(name), &canon, |b, canon| {
            b.iter(|| plan(black_box(canon), &cfg).unwrap())
        });
    }
    g.finish();
}

/// One servo period of the interpolator, side by side on the same run: the 10,000-chord plan
/// (merged lines and corner blends), the 3,000-chord plan (fitted arcs in spans: windowed
/// pieces of one speed profile, issue 14), and the same 3,000 chords with spans off (every
/// arc its own S-curves), so the cost of the windows shows as a ratio.
fn interpolator(c: &mut Criterion) {
    let cfg = MotionConfig::default();
    let no_spans = MotionConfig {
        spans: false,
        ..cfg.clone()
    };
    let [(_, fitted), (_, chords)]: [(&str, Vec<Canon>); 2] = cases().try_into().unwrap();
    let mut g = c.benchmark_group("interpolate");
    g.sample_size(20);
    for (name, canon, cfg) in [
        ("10000x0.02mm servo periods", &chords, &cfg),
        ("3000x0.1mm arcs, spans, servo periods", &fitted, &cfg),
        (
            "3000x0.1mm arcs, no spans, servo periods",
            &fitted,
            &no_spans,
        ),
    ] {
        let p = plan(canon, cfg).unwrap();
        let periods = (p.duration_s / cfg.servo_period_s) as u64 + 1;
        g.throughput(Throughput::Elements(periods));
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut it = Interpolator::new(cfg, p.start_mm);
                let mut src = SliceSource::new(&p.items);
                for _ in 0..periods {
                    black_box(it.step(&mut src));
                }
            })
        });
    }
    g.finish();
}

/// The servo periods of feed holds on the 10,000-chord plan (a corner blend every 0.5 mm:
/// the path stop runs through them, re-planned every period), side by side with the same
/// number of periods running on from the same states: the ratio is what a stop costs a
/// period. Holds requested every 97 periods of a nominal run, each stepped to rest.
fn hold_periods(c: &mut Criterion) {
    use hytask::motion::InterpState;
    let cfg = MotionConfig::default();
    let [_, (_, chords)]: [(&str, Vec<Canon>); 2] = cases().try_into().unwrap();
    let p = plan(&chords, &cfg).unwrap();
    // Interpolator states in cruise (cloned with their queue position), and the periods
    // each hold takes to rest.
    let mut starts = Vec::new();
    let mut it = Interpolator::new(&cfg, p.start_mm);
    let mut src = SliceSource::new(&p.items);
    for n in 0.. {
        if it.step(&mut src).state == InterpState::Done {
            break;
        }
        if n % 97 == 50 {
            let (mut h, mut hs) = (it.clone(), src.clone());
            h.hold();
            let mut periods = 0u64;
            while h.step(&mut hs).state == InterpState::Running {
                periods += 1;
            }
            starts.push((it.clone(), src.clone(), periods));
        }
    }
    let total: u64 = starts.iter().map(|s| s.2).sum();
    let mut g = c.benchmark_group("hold");
    g.sample_size(20);
    g.throughput(Throughput::Elements(total));
    g.bench_function("10000x0.02mm hold periods", |b| {
        b.iter(|| {
            for (it, src, periods) in &starts {
                let (mut h, mut hs) = (it.clone(), src.clone());
                h.hold();
                for _ in 0..*periods {
                    black_box(h.step(&mut hs));
                }
            }
        })
    });
    g.bench_function("10000x0.02mm running periods", |b| {
        b.iter(|| {
            for (it, src, periods) in &starts {
                let (mut h, mut hs) = (it.clone(), src.clone());
                for _ in 0..*periods {
                    black_box(h.step(&mut hs));
                }
            }
        })
    });
    g.finish();
}

criterion_group!(benches, planner, interpolator, hold_periods);
criterion_main!(benches);
