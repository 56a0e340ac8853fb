//! G5/G5.1 splines from the G-code text to the interpolated trace: the machine follows the
//! Bézier curve within the path tolerance, ends exactly on the end point, keeps every axis
//! limit, and a G93 spline takes 1/F minutes.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::{load_str, InterpOptions};
use hytask::motion::{plan, MotionConfig};
use motion_util::*;

fn cubic(p: [[f64; 2]; 4], t: f64) -> [f64; 2] {
    let m = 1.0 - t;
    let c = [m * m * m, 3.0 * m * m * t, 3.0 * m * t * t, t * t * t];
    let mut out = [0.0; 2];
    for (w, q) in c.iter().zip(p) {
        out[0] += w * q[0];
        out[1] += w * q[1];
    }
    out
}

fn program(text: &str) -> Vec<hytask::gcode::Canon> {
    load_str("s.ngc", text, &InterpOptions::default())
        .unwrap()
        .canon
}

#[test]
fn a_g5_spline_is_followed_within_tolerance_and_ends_exactly() {
    let cfg = MotionConfig::default();
    let canon = program("G21 G90 G17 G64 P0.01 F3000\nG0 X0 Y0 Z0\nG5 I0 J20 P0 Q20 X20 Y0\nM2\n");
    let p = plan(&canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert_eq!(last(&tr), pose(20.0, 0.0, 0.0));
    // The ideal curve, densely sampled; every traced point is near it.
    let ctrl = [[0.0, 0.0], [0.0, 20.0], [20.0, 20.0], [20.0, 0.0]];
    let ideal: Vec<[f64; 9]> = (0..=2000)
        .map(|i| {
            let q = cubic(ctrl, f64::from(i) / 2000.0);
            pose(q[0], q[1], 0.0)
        })
        .collect();
    let worst = max_deviation(&tr, &ideal);
    // Chords within the chord tolerance, corners between them blended within G64 P.
    assert!(
        worst <= cfg.arc_chord_tolerance_mm + 0.01 + 0.02,
        "deviation {worst}"
    );
    // The top of the curve is reached (y = 15 at t = 0.5).
    let top = tr.poses_mm.iter().map(|q| q[1]).fold(f64::MIN, f64::max);
    assert!((top - 15.0).abs() < 0.05, "top {top}");
}

#[test]
fn a_g5_1_and_a_g93_spline_take_their_time() {
    let cfg = MotionConfig::default();
    // G5.1 at F600 along a parabola of length ~ 22.96 mm, then a G93 G5 with F60: 1 s.
    let canon = program(
        "G21 G90 G17 F600\nG0 X0 Y0\nG5.1 I10 J10 X20 Y0\nG93 G5 I0 J5 P0 Q5 X0 Y0 F60\nG94\nM2\n",
    );
    let p = plan(&canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert_eq!(last(&tr), pose(0.0, 0.0, 0.0));
    // Parabola length: integral of |B'(t)|, B' = (20, 20 - 40 t).
    let n = 10_000;
    let len: f64 = (0..n)
        .map(|i| {
            let t = (f64::from(i) + 0.5) / f64::from(n);
            20.0f64.hypot(20.0 - 40.0 * t) / f64::from(n)
        })
        .sum();
    let expect_s = len / 10.0 + 1.0; // 600 mm/min = 10 mm/s, then 1/60 min
    let took = tr.poses_mm.len() as f64 * tr.dt_s;
    assert!(
        took >= expect_s && took < expect_s + 1.0,
        "took {took} s, cruise time alone {expect_s} s"
    );
}

#[test]
fn a_weighted_g5_2_block_traces_an_exact_quarter_circle() {
    let cfg = MotionConfig::default();
    // Quadratic NURBS from (10, 0) through the corner (10, 10) weighted cos 45° to
    // (0, 10): a quarter of the circle of radius 10 around the origin.
    let canon = program(
        "G21 G90 G17 G64 P0.01 F1200\nG0 X10 Y0\nG5.2 X10 Y10 P0.70710678118 L3\nX0 Y10 P1\nG5.3\nM2\n",
    );
    let p = plan(&canon, &cfg).unwrap();
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    assert_eq!(last(&tr), pose(0.0, 10.0, 0.0));
    let worst = tr
        .poses_mm
        .iter()
        // Past the blend that joins the rapid lead-in at (10, 0).
        .filter(|q| q[1] > 0.2)
        .map(|q| (q[0].hypot(q[1]) - 10.0).abs())
        .fold(0.0, f64::max);
    assert!(
        worst <= cfg.arc_chord_tolerance_mm + 0.01 + 1e-6,
        "radial error {worst}"
    );
    // The rapid lead-in, then the quarter circle (not the corner): 10 + 5π.
    assert!(
        (p.distance_mm - 10.0 - 5.0 * std::f64::consts::PI).abs() < 0.01,
        "{}",
        p.distance_mm
    );
}
