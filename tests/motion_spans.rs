//! One speed profile across tangent moves (issue 14, `motion::span`): a run of fitted arcs
//! speeds up and slows down as one S-curve instead of one per arc, every limit and the
//! tolerance hold on the servo-period trace, with feed override, hold and resume, and the
//! windowed segments join without a jump in pose or velocity.
#![allow(clippy::unwrap_used)]

mod motion_util;

#[path = "../benches/programs/gen.rs"]
mod gen;

use hytask::gcode::{load_str, InterpOptions};
use hytask::motion::trace;
use hytask::motion::{plan, InterpState, Item, MotionConfig, Plan, Segment};
use motion_util::*;

fn spiral_plan(cfg: &MotionConfig) -> (Plan, Vec<[f64; 9]>) {
    let prog = load_str(
        "spiral.ngc",
        &gen::spiral(3000, 0.1),
        &InterpOptions::default(),
    )
    .unwrap();
    // The programmed polyline: from the origin, the rapid's end, then every G1 end point.
    let mut path = vec![pose(0.0, 0.0, 0.0)];
    for c in &prog.canon {
        match &c.cmd {
            hytask::gcode::CanonCmd::StraightTraverse(p)
            | hytask::gcode::CanonCmd::StraightFeed(p) => path.push(*p),
            _ => {}
        }
    }
    (plan(&prog.canon, cfg).unwrap(), path)
}

fn segments(p: &Plan) -> Vec<&Segment> {
    p.items
        .iter()
        .filter_map(|i| match i {
            Item::Segment(s) => Some(s),
            _ => None,
        })
        .collect()
}

/// Time from the start of the spiral (the first feed segment) until the path speed first
/// reaches `v` on the servo-period trace.
fn time_to_reach(p: &Plan, cfg: &MotionConfig, v: f64) -> f64 {
    let tr = run(p, cfg);
    let start = segments(p)
        .iter()
        .take_while(|s| s.kind == hytask::motion::SegmentKind::Rapid)
        .map(|s| s.duration_s)
        .sum::<f64>();
    let dt = cfg.servo_period_s;
    let first = (start / dt).ceil() as usize;
    let speed = |n: usize| {
        let (a, b) = (&tr.poses_mm[n - 1], &tr.poses_mm[n]);
        (0..3).map(|i| (b[i] - a[i]).powi(2)).sum::<f64>().sqrt() / dt
    };
    let n = (first.max(1)..tr.poses_mm.len())
        .find(|&n| speed(n) >= v)
        .unwrap();
    (n - first) as f64 * dt
}

#[test]
fn a_speed_up_along_fitted_arcs_is_one_s_curve() {
    let on = MotionConfig::default();
    let off = MotionConfig {
        spans: false,
        ..MotionConfig::default()
    };
    let (p_on, path) = spiral_plan(&on);
    let (p_off, _) = spiral_plan(&off);
    assert!(
        segments(&p_on).iter().any(|s| s.window.is_some()),
        "no span was planned"
    );
    assert!(segments(&p_off).iter().all(|s| !s.window.is_some()));
    // On the spiral's circles (radius 7.5 mm and up) the normal acceleration at the feed
    // takes 333 of the 500 mm/s², which leaves the tangential speed-up at least 200 mm/s²
    // (the arcs' planning limit, `Limits::arc`, is about 270): one S-curve to 49 mm/s at
    // 200 mm/s² and 40,000 mm/s³ takes 49/200 + 200/40,000 s. An S-curve per arc, with the
    // acceleration back to zero at every arc's end, took more than twice as long as the span.
    let slowest_one_curve = 49.0 / 200.0 + 200.0 / 40_000.0;
    let t_on = time_to_reach(&p_on, &on, 49.0);
    let t_off = time_to_reach(&p_off, &off, 49.0);
    assert!(
        t_on <= slowest_one_curve,
        "{t_on} s against {slowest_one_curve} s"
    );
    assert!(t_off > 1.8 * t_on, "{t_off} s without spans, {t_on} s with");
    assert!(
        p_on.duration_s < 0.985 * p_off.duration_s,
        "{} s with spans, {} s without",
        p_on.duration_s,
        p_off.duration_s
    );
    let tr = run(&p_on, &on);
    assert_within_limits(&tr, &on);
    let dev = max_deviation(&tr, &path);
    assert!(dev <= 0.01 + 1e-9, "deviation {dev} mm over G64 P0.01");
    assert_eq!(last(&tr), p_on.end_mm);
}

/// Consecutive segments of a span meet at the same pose and the same velocity, and a
/// windowed segment's motion ends at its end pose.
#[test]
fn windowed_segments_join_without_a_jump() {
    let (p, _) = spiral_plan(&MotionConfig::default());
    let segs = segments(&p);
    let mut windowed = 0;
    for w in segs.windows(2) {
        let (a, b) = (w[0], w[1]);
        for i in 0..9 {
            assert!((a.end_mm[i] - b.start_mm[i]).abs() < 1e-9, "{a:?}\n{b:?}");
            assert!(
                (a.v1_mm_s[i] - b.v0_mm_s[i]).abs() < 1e-6,
                "velocity jump {a:?}\n{b:?}"
            );
        }
        if a.window.is_some() {
            windowed += 1;
            let end = a.integrated_end_mm();
            for (e, want) in end.iter().zip(&a.end_mm) {
                assert!((e - want).abs() < 1e-6, "{a:?}");
            }
            // The distance reported for distance-to-go covers the piece exactly.
            assert!(
                (a.travelled_mm(a.duration_s) - a.length_mm).abs() < 1e-9,
                "{a:?}"
            );
            // Speed along the piece rises or falls monotonically between its ends.
            let (s0, s1) = (a.speed_at(0.0), a.speed_at(a.duration_s));
            let mid = a.speed_at(0.5 * a.duration_s);
            assert!(mid >= s0.min(s1) - 1e-9 && mid <= s0.max(s1) + 1e-9);
        }
    }
    assert!(windowed >= 4, "{windowed} windowed segments");
}

/// Feed override to 200 %, back down, a hold and a resume on a span keep every limit and
/// the tolerance, and the run ends at the programmed end.
#[test]
fn override_and_hold_on_a_span_stay_within_limits() {
    let cfg = MotionConfig::default();
    let (p, path) = spiral_plan(&cfg);
    let mut held = false;
    let tr = trace::run(&p, &cfg, max_periods(&p, &cfg), |n, it| match n {
        // Within the speed-up along the spiral, across the windowed pieces.
        330 => it.set_feed_override(2.0),
        360 => it.set_feed_override(0.5),
        420 => it.hold(),
        900 => {
            held = it.output().state == InterpState::Holding;
            it.resume();
        }
        1000 => it.set_feed_override(1.5),
        _ => {}
    });
    assert!(held, "the hold did not stop");
    assert_within_limits(&tr, &cfg);
    let dev = max_deviation(&tr, &path);
    assert!(dev <= 0.01 + 1e-9, "deviation {dev} mm");
    assert_eq!(last(&tr), p.end_mm);
    // A hold requested anywhere in the speed-up stops within the limits (the plan without
    // its M2, which `hold_stops` would wait on for ever).
    let mut motion = p.clone();
    motion.items.retain(|i| matches!(i, Item::Segment(_)));
    let stops = hold_stops(&motion, &cfg, |n| (290..460).contains(&n) && n % 5 == 0);
    assert!(!stops.is_empty());
    for s in &stops {
        assert!(s.peak_ratio <= 1.0 + LIMIT_TOL, "{s:?}");
    }
}

/// Spans cross junctions capped below their cruise when their profile passes them slower
/// (`lookahead::group_speeds`): on the benchmark sine, some speed transition runs on across a
/// curvature step `Δκ` at which its top speed `v` would step the acceleration by `v²·|Δκ|`
/// more than any step budget allows (at most half the planning jerk over one servo period),
/// so the junction caps below the span's cruise; the trace stays within every limit, and the
/// windowed pieces pass every such junction with `v²·|Δκ|` within that bound.
#[test]
fn a_span_crosses_a_junction_it_passes_below_the_junction_cap() {
    let cfg = MotionConfig::default();
    let prog = load_str("sine.ngc", &gen::sine(3000, 0.1), &InterpOptions::default()).unwrap();
    let p = plan(&prog.canon, &cfg).unwrap();
    let speed = |v: &[f64; 9]| v.iter().map(|c| c * c).sum::<f64>().sqrt();
    // Upper bound of the step budget: half of the planning jerk over one servo period.
    let budget =
        0.5 * (1.0 - cfg.override_reserve) * cfg.axes[0].max_jerk_mm_s3 * cfg.servo_period_s;
    let segs = segments(&p);
    let mut crossed = 0;
    // Speed at the start of the transition the current pieces belong to.
    let mut s_start = 0.0;
    for w in segs.windows(2) {
        let (a, b) = (w[0], w[1]);
        if a.window.full_s > 0.0 && a.window.offset_s == 0.0 {
            s_start = speed(&a.v0_mm_s);
        }
        let same_transition = a.window.full_s > 0.0
            && a.window.full_s == b.window.full_s
            && a.window.dv_mm_s == b.window.dv_mm_s
            && (b.window.offset_s - (a.window.offset_s + a.duration_s)).abs() < 1e-9;
        let dk = (a.curvature_per_mm - b.curvature_per_mm).abs();
        if !same_transition || dk == 0.0 {
            continue;
        }
        let at_junction = speed(&a.v1_mm_s);
        let top = s_start.max(s_start + a.window.dv_mm_s);
        assert!(
            at_junction * at_junction * dk <= budget * (1.0 + 1e-9),
            "a span passes a curvature step too fast: {at_junction} mm/s at {dk} 1/mm"
        );
        if top * top * dk > budget {
            crossed += 1;
        }
    }
    assert!(
        crossed > 0,
        "no span crossed a junction capped below its cruise"
    );
    assert_within_limits(&trace::run_all(&p, &cfg), &cfg);
}
