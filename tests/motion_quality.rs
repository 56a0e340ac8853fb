//! Planner quality on CAM-style streams: planned job time against lower bounds (see
//! `motion::bounds`) and a stop-at-every-corner planner. Deterministic (no timing), so the
//! ratios are asserted; the speed of planning is measured in `benches/planner.rs`.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::Canon;
use hytask::motion::bounds::bounds;
use hytask::motion::{plan, MotionConfig};
use motion_util::*;

/// `n` chords of `step_mm` along y = 5·sin(2πx/40) (min radius of curvature ≈ 8.1 mm), at F.
pub fn sine_stream(n: usize, step_mm: f64, feed_mm_min: f64, tol_mm: f64) -> Vec<Canon> {
    let mut g = Prog::new();
    g.feed(feed_mm_min).g64(tol_mm);
    let (mut x, mut y) = (0.0f64, 0.0f64);
    let w = 2.0 * std::f64::consts::PI / 40.0;
    for _ in 0..n {
        // Advance by arc length step_mm along the curve.
        let slope = 5.0 * w * (w * x).cos();
        x += step_mm / (1.0 + slope * slope).sqrt();
        y = 5.0 * (w * x).sin();
        g.g1(x, y, 0.0);
    }
    let _ = y;
    g.canon
}

fn bench_cfg() -> MotionConfig {
    MotionConfig::default()
}

fn report(name: &str, canon: &[Canon], cfg: &MotionConfig) -> (f64, f64) {
    let p = plan(canon, cfg).unwrap();
    let b = bounds(canon, cfg).unwrap();
    let tr = run(&p, cfg);
    assert_within_limits(&tr, cfg);
    eprintln!(
        "{name}: planned {:.3} s (trace {:.3} s), feed bound {:.3} s ({:.3}x), corner estimate {:.3} s ({:.3}x), naive {:.3} s ({:.3}x)",
        p.duration_s,
        tr.duration_s(),
        b.feed_limited_s,
        p.duration_s / b.feed_limited_s,
        b.corner_estimate_s,
        p.duration_s / b.corner_estimate_s,
        b.naive_stop_s,
        p.duration_s / b.naive_stop_s
    );
    (
        p.duration_s / b.feed_limited_s,
        p.duration_s / b.corner_estimate_s,
    )
}

#[test]
fn cam_3000_segments_of_0_1_mm() {
    let canon = sine_stream(3000, 0.1, 3000.0, 0.05);
    let (feed, _accel) = report("3000 x 0.1 mm", &canon, &bench_cfg());
    assert!(feed <= 1.1, "{feed}");
}

#[test]
fn cam_10000_segments_of_0_02_mm() {
    let canon = sine_stream(10_000, 0.02, 3000.0, 0.05);
    let (feed, _accel) = report("10000 x 0.02 mm", &canon, &bench_cfg());
    assert!(feed <= 1.1, "{feed}");
}

/// The same streams without merging (pure corner blending), for the record: merging within
/// half the G64 tolerance is what lets jerk-limited blends keep speed on very short chords.
#[test]
fn without_merging_for_comparison() {
    let cfg = MotionConfig {
        merge_fraction: 0.0,
        ..bench_cfg()
    };
    let (_, a3) = report(
        "3000 x 0.1 mm, no merging",
        &sine_stream(3000, 0.1, 3000.0, 0.05),
        &cfg,
    );
    let (_, a10) = report(
        "10000 x 0.02 mm, no merging",
        &sine_stream(10_000, 0.02, 3000.0, 0.05),
        &cfg,
    );
    assert!(a3 < 5.0 && a10 < 10.0);
}

/// Tighter path tolerances cost time (smaller merges, gentler blends): recorded, loosely
/// bounded.
#[test]
fn tighter_tolerances_for_comparison() {
    for tol in [0.01, 0.005] {
        let (f3, _) = report(
            &format!("3000 x 0.1 mm, G64 P{tol}"),
            &sine_stream(3000, 0.1, 3000.0, tol),
            &bench_cfg(),
        );
        let (f10, _) = report(
            &format!("10000 x 0.02 mm, G64 P{tol}"),
            &sine_stream(10_000, 0.02, 3000.0, tol),
            &bench_cfg(),
        );
        assert!(f3 < 3.0 && f10 < 3.0);
    }
}
