//! Lines through the public API: plan → interpolate at the servo period → check limits,
//! path deviation, exact final positions, stops and refusals.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::canon::MotionControl;
use hytask::gcode::CanonCmd;
use hytask::motion::{plan, InterpState, MotionConfig, PlanError};
use motion_util::*;

fn square(p_tol: f64, mode: Option<MotionControl>) -> (Prog, Vec<[f64; 9]>) {
    let mut g = Prog::new();
    g.feed(3000.0).g64(p_tol);
    if let Some(m) = mode {
        g.cmd(CanonCmd::SetMotionControl(m));
    }
    let pts = [
        (20.0, 0.0),
        (20.0, 20.0),
        (0.0, 20.0),
        (0.0, 0.0),
        (30.0, 5.0),
    ];
    let mut path = vec![pose(0.0, 0.0, 0.0)];
    for (x, y) in pts {
        g.g1(x, y, 0.0);
        path.push(pose(x, y, 0.0));
    }
    (g, path)
}

#[test]
fn blended_square_within_limits_and_tolerance() {
    let cfg = MotionConfig::default();
    let (g, path) = square(0.05, None);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert!(
        max_deviation(&tr, &path) <= 0.05 + 1e-9,
        "deviation {}",
        max_deviation(&tr, &path)
    );
    assert_eq!(last(&tr), pose(30.0, 5.0, 0.0));
    assert_eq!(p.end_mm, pose(30.0, 5.0, 0.0));
    // Corners are blended: the tool never stops between the first and last move.
    let n = tr.poses_mm.len();
    let moving = tr
        .poses_mm
        .windows(2)
        .skip(5)
        .take(n - 20)
        .all(|w| w[0] != w[1]);
    assert!(moving, "the tool stopped at a blended corner");
    assert!((tr.duration_s() - p.duration_s).abs() < 0.01);
}

#[test]
fn exact_stop_stops_at_every_corner_and_never_leaves_the_path() {
    let cfg = MotionConfig::default();
    let (g, path) = square(0.05, Some(MotionControl::ExactStop));
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert!(max_deviation(&tr, &path) < 1e-9);
    let (gb, _) = square(0.05, None);
    let blended = plan(&gb.canon, &cfg).unwrap();
    assert!(p.duration_s > blended.duration_s);
}

#[test]
fn exact_path_stays_on_the_path() {
    let cfg = MotionConfig::default();
    let (g, path) = square(0.05, Some(MotionControl::ExactPath));
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert!(max_deviation(&tr, &path) <= cfg.exact_path_tolerance_mm + 1e-9);
}

#[test]
fn rapid_reaches_axis_limit_and_feed_is_respected() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.g0(100.0, 0.0, 0.0).feed(600.0).g1(100.0, 50.0, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    let pk = tr.peaks();
    assert!((pk.vel[0] - 50.0).abs() < 1e-6, "rapid at {}", pk.vel[0]);
    assert!((pk.vel[1] - 10.0).abs() < 1e-6, "feed at {}", pk.vel[1]);
    assert_within_limits(&tr, &cfg);
}

#[test]
fn soft_limit_is_refused_with_line_before_motion() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(1000.0).g1(10.0, 0.0, 0.0).g1(10.0, 1500.0, 0.0);
    let err = plan(&g.canon, &cfg).unwrap_err();
    assert!(
        matches!(
            err,
            PlanError::SoftLimit {
                line: 3,
                axis: 'Y',
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn zero_feed_is_refused() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.g1(10.0, 0.0, 0.0);
    assert!(matches!(
        plan(&g.canon, &cfg),
        Err(PlanError::Invalid { line: 1, .. })
    ));
}

#[test]
fn final_position_is_exact_after_many_short_moves() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(3000.0).g64(0.01);
    let mut x = 0.0;
    for i in 0..500 {
        x += 0.1;
        g.g1(x, (i as f64 * 0.05).sin() * 3.0, 0.0);
    }
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_eq!(last(&tr), p.end_mm);
    assert_within_limits(&tr, &cfg);
    assert_eq!(*tr.states.last().unwrap(), InterpState::Done);
}

#[test]
fn short_lookahead_window_is_slower_but_within_limits() {
    let mut g = Prog::new();
    g.feed(3000.0).g64(0.05);
    for i in 1..=400 {
        g.g1(i as f64 * 0.5, (i as f64 * 0.02).sin(), 0.0);
    }
    let long = MotionConfig::default();
    // Chord by chord (no arc fitting, no merging): a window of 4 chords of 0.5 mm is shorter
    // than a stop from full feed.
    let short = MotionConfig {
        lookahead_moves: 4,
        merge_fraction: 0.0,
        fit_arcs: false,
        ..Default::default()
    };
    let long_nomerge = MotionConfig {
        merge_fraction: 0.0,
        fit_arcs: false,
        ..Default::default()
    };
    let pl = plan(&g.canon, &long_nomerge).unwrap();
    let ps = plan(&g.canon, &short).unwrap();
    assert!(
        ps.duration_s > 1.2 * pl.duration_s,
        "{} vs {}",
        ps.duration_s,
        pl.duration_s
    );
    let tr = run(&ps, &short);
    assert_within_limits(&tr, &short);
    assert_eq!(last(&tr), ps.end_mm);
    assert!(plan(&g.canon, &long).unwrap().duration_s <= pl.duration_s);
}

#[test]
fn g64_q_merges_collinear_short_moves_within_tolerance() {
    let cfg = MotionConfig {
        merge_fraction: 0.0,
        ..Default::default()
    };
    let mut g = Prog::new();
    g.feed(3000.0)
        .g64(0.02)
        .cmd(CanonCmd::SetNaivecamTolerance(0.01));
    let mut path = vec![pose(0.0, 0.0, 0.0)];
    for i in 1..=200 {
        // Nearly straight, jittering by ±5 µm.
        let (x, y) = (i as f64 * 0.1, if i % 2 == 0 { 0.005 } else { -0.005 });
        g.g1(x, y, 0.0);
        path.push(pose(x, y, 0.0));
    }
    let p = plan(&g.canon, &cfg).unwrap();
    assert!(p.segment_count <= 5, "{} segments", p.segment_count);
    let tr = run(&p, &cfg);
    assert!(max_deviation(&tr, &path) <= 0.02 + 0.01 + 1e-9);
    assert_eq!(last(&tr), *path.last().unwrap());
    // Without Q and without automatic merging, every move is planned.
    let mut g2 = Prog::new();
    g2.feed(3000.0).g64(0.02);
    for p in &path[1..] {
        g2.g1(p[0], p[1], 0.0);
    }
    assert!(plan(&g2.canon, &cfg).unwrap().segment_count >= 200);
}

#[test]
fn rotary_only_move_uses_degrees_per_minute_and_rotary_limits() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    let mut a = [0.0; 9];
    a[3] = 720.0;
    g.feed(3600.0).cmd(CanonCmd::StraightFeed(a)); // 60 deg/s
    a[3] = 0.0;
    g.cmd(CanonCmd::StraightTraverse(a)); // rapid back at the A limit, 90 deg/s
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    let pk = tr.peaks();
    assert!((pk.vel[3] - 90.0).abs() < 1e-6, "{}", pk.vel[3]);
    assert_within_limits(&tr, &cfg);
    assert_eq!(last(&tr)[3], 0.0);
}

#[test]
fn reports_line_and_distance_to_go() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(1200.0)
        .cmd(CanonCmd::SetMotionControl(MotionControl::ExactStop))
        .g1(10.0, 0.0, 0.0)
        .g1(10.0, 5.0, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let mut it = hytask::motion::Interpolator::new(&cfg, p.start_mm);
    let mut src = hytask::motion::SliceSource::new(&p.items);
    let mut seen = Vec::new();
    let mut last_dtg = f64::INFINITY;
    for _ in 0..10_000 {
        let out = *it.step(&mut src);
        if out.state == InterpState::Done {
            break;
        }
        if seen.last() != Some(&out.line) {
            seen.push(out.line);
            last_dtg = f64::INFINITY;
        }
        // Distance to go falls monotonically within a move and matches the geometry.
        assert!(out.distance_to_go_mm <= last_dtg + 1e-9);
        last_dtg = out.distance_to_go_mm;
        if out.line == 3 {
            assert!((out.distance_to_go_mm - (10.0 - out.pose_mm[0])).abs() < 1e-6);
        }
    }
    assert_eq!(seen, vec![3, 4]);
}
