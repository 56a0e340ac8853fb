//! Arcs (ARC_FEED with helix and turns), small-arc blends and dense polylines on curves:
//! limits on the interpolated trace, chord/blend tolerance, exact ends.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::canon::Plane;
use hytask::gcode::CanonCmd;
use hytask::motion::{plan, MotionConfig};
use motion_util::*;
use std::f64::consts::PI;

/// G2/G3 in XY from the current point to (x, y) around (cx, cy), ending at z.
fn arc(g: &mut Prog, x: f64, y: f64, cx: f64, cy: f64, rotation: i32, z: f64) {
    g.cmd(CanonCmd::ArcFeed {
        first_end: x,
        second_end: y,
        first_center: cx,
        second_center: cy,
        rotation,
        axis_end: z,
        plane: Plane::Xy,
        end: pose(x, y, z),
    });
}

/// Distance of a point from the ideal helix/circle (radial error in XY).
fn radial_error(p: &[f64; 9], cx: f64, cy: f64, r: f64) -> f64 {
    ((p[0] - cx).hypot(p[1] - cy) - r).abs()
}

#[test]
fn full_circle_with_turns_and_helix() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(2400.0).g64(0.02).g1(10.0, 0.0, 0.0);
    arc(&mut g, 10.0, 0.0, 0.0, 0.0, 2, -4.0); // two CCW turns, 4 mm down
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert_eq!(last(&tr), pose(10.0, 0.0, -4.0));
    // On the helix: radial error within the chord tolerance (after the lead-in line).
    // (Past the blend that joins the radial lead-in line, whose points are off the circle.)
    let on_arc: Vec<_> = tr.poses_mm.iter().filter(|q| q[2] < -0.05).collect();
    assert!(!on_arc.is_empty());
    let worst = on_arc
        .iter()
        .map(|q| radial_error(q, 0.0, 0.0, 10.0))
        .fold(0.0, f64::max);
    assert!(
        worst <= cfg.arc_chord_tolerance_mm + 1e-9,
        "radial error {worst}"
    );
    // Z falls linearly with the angle: length of the helix ≈ 2 turns.
    let expect = ((4.0 * PI * 10.0f64).powi(2) + 16.0).sqrt() + 10.0;
    assert!(
        (p.distance_mm - expect).abs() < 0.05,
        "{} vs {expect}",
        p.distance_mm
    );
}

#[test]
fn clockwise_arc_goes_the_short_way_round_the_right_side() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(1200.0).g1(10.0, 0.0, 0.0);
    arc(&mut g, 0.0, -10.0, 0.0, 0.0, -1, 0.0); // CW quarter: through (7.07, -7.07)
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert!(tr.poses_mm.iter().all(|q| q[1] <= 1e-9 && q[0] >= -1e-9));
    assert_eq!(last(&tr), pose(0.0, -10.0, 0.0));
    assert_within_limits(&tr, &cfg);
}

/// LinuxCNC issue #3773: tiny arcs between lines made the blend overshoot acceleration by
/// up to 8×. Here every blend is planned from the same S-curve, whatever the arc size.
#[test]
fn small_arc_blends_never_exceed_acceleration() {
    let cfg = MotionConfig::default();
    for r in [0.001, 0.01, 0.05, 0.2, 1.0] {
        let mut g = Prog::new();
        g.feed(3000.0).g64(0.05);
        let mut x = 0.0;
        let mut path = vec![pose(0.0, 0.0, 0.0)];
        for i in 0..10 {
            x += 5.0;
            let y = if i % 2 == 0 { 0.0 } else { 2.0 * r };
            g.g1(x, y, 0.0);
            path.push(pose(x, y, 0.0));
            // Half circle to the other side (a fillet-like tiny arc).
            let (ny, rot) = if i % 2 == 0 { (2.0 * r, 1) } else { (0.0, -1) };
            arc(&mut g, x, ny, x, r, rot, 0.0);
            path.push(pose(x + r, r, 0.0));
            path.push(pose(x, ny, 0.0));
        }
        let p = plan(&g.canon, &cfg).unwrap();
        let tr = run(&p, &cfg);
        assert_within_limits(&tr, &cfg);
        assert_eq!(last(&tr), p.end_mm, "r = {r}");
    }
}

#[test]
fn dense_polyline_on_a_curve_is_fast_and_within_tolerance() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(3000.0).g64(0.02);
    let mut path = vec![pose(0.0, 0.0, 0.0)];
    let r = 30.0;
    for i in 1..=1500 {
        // 0.1 mm chords on a circle of radius 30 mm, entered tangentially.
        let a = i as f64 * 0.1 / r;
        let (x, y) = (r * a.sin(), r * (1.0 - a.cos()));
        g.g1(x, y, 0.0);
        path.push(pose(x, y, 0.0));
    }
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    let dev = max_deviation(&tr, &path);
    assert!(dev <= 0.02 + 1e-9, "deviation {dev}");
    assert_eq!(last(&tr), p.end_mm);
    // Feed-limited bound: 150 mm at 50 mm/s = 3 s.
    assert!(p.duration_s < 1.2 * 3.0, "planned {} s", p.duration_s);
}

#[test]
fn arcs_in_other_planes_end_exactly() {
    let cfg = MotionConfig::default();
    for plane in [Plane::Xz, Plane::Yz] {
        let mut g = Prog::new();
        g.feed(1200.0);
        // Quarter circle of radius 5 in the plane, starting at the origin.
        let (i1, i2, _) = hytask::motion::arcs::plane_axes(plane);
        let mut end = [0.0; 9];
        end[i1] = 5.0;
        end[i2] = 5.0;
        g.cmd(CanonCmd::ArcFeed {
            first_end: 5.0,
            second_end: 5.0,
            first_center: 0.0,
            second_center: 5.0,
            rotation: 1,
            axis_end: 0.0,
            plane,
            end,
        });
        let p = plan(&g.canon, &cfg).unwrap();
        let tr = run(&p, &cfg);
        assert_eq!(last(&tr), end);
        assert_within_limits(&tr, &cfg);
    }
}

/// A CAM-like pocket: rapid in, plunge, rectangular passes with filleted corners (G3
/// arcs), an S change, M62 on the way, retract, rapid home, dwell and program end.
#[test]
fn cam_like_pocket_job() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.cmd(CanonCmd::SetSpindleSpeed(12000.0))
        .cmd(CanonCmd::StartSpindle(
            hytask::gcode::canon::SpindleDir::Clockwise,
        ))
        .g0(5.0, 0.0, 5.0)
        .feed(600.0)
        .g64(0.02)
        .g1(5.0, 0.0, -2.0)
        .feed(3000.0);
    for pass in 0..4 {
        let o = pass as f64 * 3.0; // inset
        let (x0, y0, x1, y1, r) = (o, o, 60.0 - o, 40.0 - o, 2.0);
        // Start on the bottom edge, go CCW with filleted corners.
        g.g1(x1 - r, y0, -2.0);
        arc(&mut g, x1, y0 + r, x1 - r, y0 + r, 1, -2.0);
        g.g1(x1, y1 - r, -2.0);
        arc(&mut g, x1 - r, y1, x1 - r, y1 - r, 1, -2.0);
        g.g1(x0 + r, y1, -2.0);
        if pass == 1 {
            g.cmd(CanonCmd::SetSpindleSpeed(15000.0));
            g.cmd(CanonCmd::DigitalOutput {
                index: 1,
                on: true,
                synced: true,
            });
        }
        arc(&mut g, x0, y1 - r, x0 + r, y1 - r, 1, -2.0);
        g.g1(x0, y0 + r, -2.0);
        arc(&mut g, x0 + r, y0, x0 + r, y0 + r, 1, -2.0);
        g.g1(x0 + 3.0 + r, y0 + 3.0, -2.0); // step in diagonally
    }
    g.g0(8.0, 9.0, 5.0)
        .g0(0.0, 0.0, 5.0)
        .cmd(CanonCmd::Dwell(0.2))
        .cmd(CanonCmd::ProgramEnd);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert_eq!(last(&tr), pose(0.0, 0.0, 5.0));
    let kinds: Vec<_> = tr.aux.iter().map(|(_, a)| a.line).collect();
    let mut sorted = kinds.clone();
    sorted.sort();
    assert_eq!(kinds, sorted, "aux items out of program order");
    assert_eq!(tr.aux.len(), 5);
    // Never below the cutting depth, never above the clearance plane.
    assert!(tr
        .poses_mm
        .iter()
        .all(|q| q[2] >= -2.0 - 1e-9 && q[2] <= 5.0 + 1e-9));
    // Inside the pocket while cutting (XY within the outline, tolerance 0.02).
    for q in tr.poses_mm.iter().filter(|q| q[2] < -1.999) {
        assert!(
            q[0] >= -0.02 && q[0] <= 60.02 && q[1] >= -0.02 && q[1] <= 40.02,
            "{q:?}"
        );
    }
}

/// G61 stops at the ends of each programmed move, never inside an arc (whose chords are an
/// implementation detail).
#[test]
fn exact_stop_does_not_stop_inside_an_arc() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(1200.0).cmd(CanonCmd::SetMotionControl(
        hytask::gcode::canon::MotionControl::ExactStop,
    ));
    g.g1(10.0, 0.0, 0.0);
    arc(&mut g, -10.0, 0.0, 0.0, 0.0, 1, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    // Periods on the arc where the tool stands still: none between its ends.
    let still = tr
        .poses_mm
        .windows(2)
        .filter(|w| w[0] == w[1] && w[0][1] > 0.5)
        .count();
    assert_eq!(still, 0);
    let worst = tr
        .poses_mm
        .iter()
        .filter(|q| q[1] > 1e-9)
        .map(|q| radial_error(q, 0.0, 0.0, 10.0))
        .fold(0.0, f64::max);
    assert!(worst <= cfg.arc_chord_tolerance_mm + 1e-9, "{worst}");
}

#[test]
fn streaming_measure_matches_the_stored_trace() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.feed(2400.0).g64(0.02).g1(10.0, 0.0, 0.0);
    arc(&mut g, 10.0, 0.0, 0.0, 0.0, 1, -2.0);
    g.g0(0.0, 0.0, 5.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    let m = hytask::motion::trace::measure(&p, &cfg, max_periods(&p, &cfg));
    assert_eq!(m.peaks, tr.peaks());
    assert_eq!(m.periods, tr.poses_mm.len());
    assert_eq!(m.duration_s, tr.duration_s());
}
