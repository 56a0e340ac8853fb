//! Folding canonical commands: units, offsets, rotation, feed modes, auxiliary items in
//! order with motion, barriers vs commands that ride along (S must not flush lookahead).
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::canon::{FeedMode, LengthUnits, SpindleDir};
use hytask::gcode::CanonCmd;
use hytask::motion::{plan, AuxKind, InterpState, Item, MotionConfig, PlanError};
use motion_util::*;

fn peak_speed(tr: &hytask::motion::trace::Trace) -> f64 {
    tr.poses_mm
        .windows(2)
        .map(|w| {
            (0..3)
                .map(|i| (w[1][i] - w[0][i]).powi(2))
                .sum::<f64>()
                .sqrt()
                / tr.dt_s
        })
        .fold(0.0, f64::max)
}

#[test]
fn inches_offsets_rotation_and_tool_length() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.cmd(CanonCmd::UseLengthUnits(LengthUnits::Inches))
        .cmd(CanonCmd::SetG5xOffset {
            index: 1,
            offset: pose(1.0, 0.0, 0.0),
        }) // 25.4 mm
        .cmd(CanonCmd::SetG92Offset(pose(0.0, 0.0, 0.5))) // 12.7 mm
        .cmd(CanonCmd::SetXyRotation(90.0))
        .cmd(CanonCmd::UseToolLengthOffset(pose(0.0, 0.0, 0.1))) // 2.54 mm
        .feed(10.0)
        .g1(1.0, 0.0, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let e = p.end_mm;
    // rotate((25.4, 0) + g92) by 90° → (0, 25.4); + G5x (25.4, 0); z = 12.7 + 2.54.
    assert!(
        (e[0] - 25.4).abs() < 1e-9 && (e[1] - 25.4).abs() < 1e-9,
        "{e:?}"
    );
    assert!((e[2] - 15.24).abs() < 1e-9, "{e:?}");
    // F10 in/min = 254 mm/min.
    let tr = run(&p, &cfg);
    assert!((peak_speed(&tr) - 254.0 / 60.0).abs() < 1e-3);
}

#[test]
fn inverse_time_feed_sets_move_duration() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.cmd(CanonCmd::SetFeedMode(FeedMode::InverseTime))
        .feed(60.0)
        .g1(10.0, 0.0, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert!((peak_speed(&tr) - 10.0).abs() < 1e-3, "{}", peak_speed(&tr));
}

#[test]
fn feed_per_revolution_needs_a_spindle_speed() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.cmd(CanonCmd::SetFeedMode(FeedMode::UnitsPerRevolution))
        .feed(0.1)
        .g1(10.0, 0.0, 0.0);
    assert!(matches!(
        plan(&g.canon, &cfg),
        Err(PlanError::Unsupported { line: 3, .. })
    ));
    let mut g = Prog::new();
    g.cmd(CanonCmd::SetFeedMode(FeedMode::UnitsPerRevolution))
        .cmd(CanonCmd::SetSpindleSpeed(1000.0))
        .feed(0.1)
        .g1(10.0, 0.0, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert!((peak_speed(&tr) - 100.0 / 60.0).abs() < 1e-3);
}

/// A probe move is a move of its own between two barriers (arm, end), from rest to rest,
/// at the programmed feed.
#[test]
fn a_probe_is_a_move_between_its_arm_and_end_markers() {
    use hytask::gcode::canon::ProbeKind;
    use hytask::motion::{AuxKind, Item};
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(600.0).g1(10.0, 0.0, 0.0);
    g.cmd(CanonCmd::StraightProbe {
        end: pose(10.0, 0.0, -5.0),
        kind: ProbeKind::TowardErr,
    });
    g.g1(20.0, 0.0, -5.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let arm = p
        .items
        .iter()
        .position(|i| matches!(i, Item::Aux(a) if matches!(a.kind, AuxKind::ProbeArm { kind: ProbeKind::TowardErr })))
        .expect("arm marker");
    let end = p
        .items
        .iter()
        .position(|i| matches!(i, Item::Aux(a) if matches!(a.kind, AuxKind::ProbeEnd { .. })))
        .expect("end marker");
    let segs: Vec<_> = p.items[arm + 1..end]
        .iter()
        .map(|i| match i {
            Item::Segment(s) => *s,
            other => panic!("{other:?} inside the probe move"),
        })
        .collect();
    assert!(segs.first().unwrap().v0_mm_s.iter().all(|v| *v == 0.0));
    assert!(segs.last().unwrap().v1_mm_s.iter().all(|v| *v == 0.0));
    assert_eq!(segs.last().unwrap().end_mm[2], -5.0);
    let peak = segs.iter().map(|s| s.peaks()[2][0]).fold(0.0, f64::max);
    assert!((peak - 10.0).abs() < 1e-9, "F600 = 10 mm/s, got {peak}");
    assert!(matches!(p.items[arm - 1], Item::Segment(s) if s.v1_mm_s.iter().all(|v| *v == 0.0)));
}

/// LinuxCNC issue #1813: an S word between moves must not stop motion.
#[test]
fn spindle_speed_change_does_not_flush_lookahead() {
    let cfg = MotionConfig::default();
    let build = |with_s: bool| {
        let mut g = Prog::new();
        g.feed(2000.0).g1(20.0, 0.0, 0.0);
        if with_s {
            g.cmd(CanonCmd::SetSpindleSpeed(12000.0));
        }
        g.g1(40.0, 1.0, 0.0).g1(60.0, 0.0, 0.0);
        g
    };
    let with = plan(&build(true).canon, &cfg).unwrap();
    let without = plan(&build(false).canon, &cfg).unwrap();
    assert!((with.duration_s - without.duration_s).abs() < 1e-12);
    let tr = run(&with, &cfg);
    let (n, a) = tr.aux[0];
    assert!(matches!(a.kind, AuxKind::SpindleSpeed { rpm } if rpm == 12000.0));
    assert_eq!(a.line, 3);
    assert_ne!(
        tr.poses_mm[n],
        tr.poses_mm[n - 1],
        "motion stopped at the S word"
    );
}

#[test]
fn aux_items_arrive_in_order_and_barriers_stop_motion() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(2000.0)
        .g1(10.0, 0.0, 0.0)
        .cmd(CanonCmd::FloodOn)
        .g1(20.0, 0.0, 0.0)
        .cmd(CanonCmd::StartSpindle(SpindleDir::Clockwise))
        .g1(30.0, 5.0, 0.0)
        .cmd(CanonCmd::DigitalOutput {
            index: 2,
            on: true,
            synced: true,
        })
        .g1(40.0, 0.0, 0.0)
        .cmd(CanonCmd::Message("hello".into()))
        .cmd(CanonCmd::Dwell(0.5))
        .cmd(CanonCmd::ProgramEnd);
    let p = plan(&g.canon, &cfg).unwrap();
    let kinds: Vec<AuxKind> = p
        .items
        .iter()
        .filter_map(|i| {
            if let Item::Aux(a) = i {
                Some(a.kind)
            } else {
                None
            }
        })
        .collect();
    assert_eq!(kinds.len(), 5);
    let tr = run(&p, &cfg);
    let got: Vec<AuxKind> = tr.aux.iter().map(|(_, a)| a.kind).collect();
    assert_eq!(got, kinds);
    assert!(matches!(got[3], AuxKind::Message { id: 0 }));
    assert_eq!(p.messages, vec!["hello".to_string()]);
    // M3 is a barrier: the tool stands at (20, 0) when it is reported.
    let (n, a) = tr.aux[1];
    assert_eq!(a.line, 5);
    assert_eq!(tr.poses_mm[n], pose(20.0, 0.0, 0.0));
    // ... having come to rest there (the last period before moved less than a micron).
    assert!((tr.poses_mm[n - 1][0] - 20.0).abs() < 1e-3);
    assert!(tr.states.contains(&InterpState::Waiting));
    // The dwell holds the tool for 0.5 s before the end.
    let still = tr
        .poses_mm
        .iter()
        .filter(|q| **q == pose(40.0, 0.0, 0.0))
        .count();
    assert!(still >= 500, "{still}");
    assert_within_limits(&tr, &cfg);
}

#[test]
fn rotary_feed_is_degrees_per_minute_even_in_inches() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    let mut a = [0.0; 9];
    a[3] = 90.0;
    g.cmd(CanonCmd::UseLengthUnits(LengthUnits::Inches))
        .feed(1800.0)
        .cmd(CanonCmd::StraightFeed(a));
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    let pk = tr.peaks();
    assert!((pk.vel[3] - 30.0).abs() < 1e-6, "{}", pk.vel[3]);
    assert_eq!(p.end_mm[3], 90.0);
}
