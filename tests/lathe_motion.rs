//! Lathe programs through the planner and the interpolator: the feeds of G33 and of the
//! G76 passes advance their pitch per spindle revolution (the plan is velocity-locked to the
//! commanded spindle speed, each from rest to rest, between the markers that let a machine
//! with a spindle position run them position-locked instead), G33.1 goes in and back out,
//! and what cannot be executed is refused.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::{self, InterpOptions};
use hytask::motion::trace::{self, Trace};
use hytask::motion::{plan, AuxItem, AuxKind, Item, MotionConfig, Plan, PlanError};
use motion_util::*;

fn plan_text(text: &str) -> Result<(MotionConfig, Plan), PlanError> {
    let cfg = MotionConfig::default();
    let prog = gcode::load_str("lathe.ngc", text, &InterpOptions::default()).unwrap();
    plan(&prog.canon, &cfg).map(|p| (cfg, p))
}

fn run(p: &Plan, cfg: &MotionConfig) -> Trace {
    trace::run(p, cfg, max_periods(p, cfg), |_, _| {})
}

/// Z advance per spindle revolution over the periods of `line` that cut along -Z only (the
/// thread; G76's traverses go +Z back or move X alone) at their top speed (the cruise),
/// and how many such periods there were.
fn cruise_advance_per_rev(tr: &Trace, line: u32, rpm: f64) -> (f64, usize) {
    let mut speeds = Vec::new();
    for i in 1..tr.poses_mm.len() {
        if tr.lines[i] == line && tr.lines[i - 1] == line {
            let dz = tr.poses_mm[i][2] - tr.poses_mm[i - 1][2];
            let dx = tr.poses_mm[i][0] - tr.poses_mm[i - 1][0];
            if dz < 0.0 && dx == 0.0 {
                speeds.push(dz / tr.dt_s);
            }
        }
    }
    let top = speeds.iter().map(|s| s.abs()).fold(0.0, f64::max);
    let cruise: Vec<f64> = speeds
        .iter()
        .map(|s| s.abs())
        .filter(|s| (s - top).abs() < 1e-9 * top.max(1.0))
        .collect();
    let v = cruise.iter().sum::<f64>() / cruise.len().max(1) as f64;
    (v * 60.0 / rpm, cruise.len())
}

#[test]
fn g33_advances_its_pitch_per_revolution_and_stops_at_both_ends() {
    let (cfg, p) =
        plan_text("G21 G18 G90\nG0 X10 Z2\nM3 S600\nG33 Z-40 K1.5\nG0 X12\nM2\n").unwrap();
    let tr = run(&p, &cfg);
    let (per_rev, n) = cruise_advance_per_rev(&tr, 4, 600.0);
    assert!(n > 1000, "cruise of {n} periods");
    assert!(
        (per_rev - 1.5).abs() < 1e-9,
        "Z advance per revolution {per_rev}"
    );
    assert_within_limits(&tr, &cfg);
    // The synchronised move starts and ends at rest (exact stop on both sides).
    let idx: Vec<usize> = (0..tr.lines.len()).filter(|&i| tr.lines[i] == 4).collect();
    let (a, b) = (idx[0], *idx.last().unwrap());
    for i in [a, b] {
        let v = (tr.poses_mm[i][2] - tr.poses_mm[i - 1][2]).abs() / tr.dt_s;
        assert!(
            v < 0.05,
            "speed {v} mm/s at the end of the synchronised move"
        );
    }
    let end = last(&tr);
    assert!(
        (end[2] + 40.0).abs() < 1e-9 && (end[0] - 12.0).abs() < 1e-9,
        "{end:?}"
    );
}

#[test]
fn g76_passes_advance_the_pitch_per_revolution_in_inches_too() {
    // 16 threads per inch at 300 rpm: 1/16 in per revolution.
    let text = "G20 G18 G90\nG0 X0.5 Z0.1\nM3 S300\n\
                G76 P0.0625 Z-1.5 I-0.02 J0.005 K0.04 R2 Q29.5 H1 E0.05 L3\nM2\n";
    let (cfg, p) = plan_text(text).unwrap();
    let tr = run(&p, &cfg);
    let (per_rev_mm, n) = cruise_advance_per_rev(&tr, 4, 300.0);
    assert!(n > 100, "cruise of {n} periods");
    assert!(
        (per_rev_mm - 0.0625 * 25.4).abs() < 1e-9,
        "Z advance per revolution {per_rev_mm} mm"
    );
    assert_within_limits(&tr, &cfg);
    let end = last(&tr);
    assert!((end[2] + 1.5 * 25.4).abs() < 1e-9, "{end:?}");
}

#[test]
fn what_the_planner_cannot_lock_to_the_spindle_is_refused() {
    let refused = |text: &str| match plan_text(text) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("planned: {text}"),
    };
    let e = refused("G21 G18\nG96 S100 D2000 M3\nG33 Z-5 K1\nM2\n");
    assert!(e.contains("line 3") && e.contains("G96"), "{e}");
    let e = refused("G21 G18\nM3 S100\nG33 Z-5 K0\nM2\n");
    assert!(e.contains("line 3") && e.contains("pitch"), "{e}");
}

#[test]
fn g33_1_is_planned_in_and_back_out_between_the_synchronisation_markers() {
    let (cfg, p) = plan_text("G21 G18 G90\nG0 X0 Z2\nM3 S300\nG33.1 Z-10 K1.25\nM5\nM2\n").unwrap();
    let marks: Vec<&AuxKind> = p
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Aux(a) if a.line == 4 => Some(&a.kind),
            _ => None,
        })
        .collect();
    match marks.as_slice() {
        [AuxKind::SpindleSync {
            end_mm,
            pitch_mm,
            tap: true,
        }, AuxKind::SpindleSyncEnd] => {
            assert!((end_mm[2] + 10.0).abs() < 1e-12 && (pitch_mm - 1.25).abs() < 1e-12);
        }
        other => panic!("{other:?}"),
    }
    let tr = run(&p, &cfg);
    assert_within_limits(&tr, &cfg);
    let on_line: Vec<f64> = (0..tr.lines.len())
        .filter(|&i| tr.lines[i] == 4)
        .map(|i| tr.poses_mm[i][2])
        .collect();
    let deepest = on_line.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((deepest + 10.0).abs() < 1e-5, "deepest {deepest}"); // sampled once a period
    let end = last(&tr);
    assert!((end[2] - 2.0).abs() < 1e-9, "back at the start: {end:?}");
    // Inches: the pitch along the path is in mm.
    let (_, p) = plan_text("G20 G18 G90\nG0 X0 Z0.1\nM3 S300\nG33.1 Z-0.5 K0.05\nM2\n").unwrap();
    let pitch = p.items.iter().find_map(|i| match i {
        Item::Aux(AuxItem {
            kind: AuxKind::SpindleSync { pitch_mm, .. },
            ..
        }) => Some(*pitch_mm),
        _ => None,
    });
    assert_eq!(pitch, Some(0.05 * 25.4));
}

/// The spindle speeds the plan commands, in order.
fn spindle_speeds(p: &Plan) -> Vec<f64> {
    p.items
        .iter()
        .filter_map(|i| match i {
            Item::Aux(AuxItem {
                kind: AuxKind::SpindleSpeed { rpm },
                ..
            }) => Some(*rpm),
            _ => None,
        })
        .collect()
}

#[test]
fn g96_spindle_speed_follows_the_x_radius_up_to_the_d_limit() {
    // 100 m/min: 318.3 rpm at X50, 1591.5 at X10, capped at D3000 at X0; G97 back to S500.
    let text = "G21 G18 G90\nG0 X50 Z1\nG96 S100 D3000 M3\nG1 X10 F200\nG1 X0\nG0 X50\n\
                G97 S500\nG0 X10\nM2\n";
    let (_, p) = plan_text(text).unwrap();
    let rpm = |r: f64| 100_000.0 / (2.0 * std::f64::consts::PI * r);
    let want = [rpm(50.0), rpm(10.0), 3000.0, rpm(50.0), 500.0];
    let got = spindle_speeds(&p);
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-9, "{got:?}");
    }
    // G95 under G96 feeds per revolution of the spindle at the radius of the move.
    let text = "G21 G18 G90\nG0 X50 Z0\nG96 S100 D3000 M3\nG95 F0.2\nG1 X10 Z-1\nM2\n";
    let (cfg, p) = plan_text(text).unwrap();
    let tr = run(&p, &cfg);
    let idx: Vec<usize> = (1..tr.lines.len()).filter(|&i| tr.lines[i] == 5).collect();
    let top = idx
        .iter()
        .map(|&i| {
            let d: f64 = (0..3)
                .map(|a| (tr.poses_mm[i][a] - tr.poses_mm[i - 1][a]).powi(2))
                .sum();
            d.sqrt() / tr.dt_s
        })
        .fold(0.0, f64::max);
    let want = 0.2 * rpm(10.0) / 60.0;
    assert!(
        (top - want).abs() < 1e-6 * want,
        "G95 path speed {top} mm/s, want {want}"
    );
}
