//! Cutter radius compensation on the motion side: a G41/G42 profile interpreted, planned and
//! interpolated keeps the tool centre one tool radius from the programmed contour, and a
//! compensated job runs to its end on the simulated mill through the control socket.
//!
//! The trace comparisons with rs274 are in `gcode_differential.rs` (corpus `comp_*.ngc`);
//! these tests check the geometry the machine actually follows.
#![allow(clippy::unwrap_used)]

mod motion_util;
mod support;

use hytask::gcode::{load_str, InterpOptions};
use hytask::motion::{plan, trace, MotionConfig};
use serde_json::json;
use std::time::Duration;
use support::*;

/// Tool diameter given to G41.1/G42.1 (mm).
const DIAMETER: f64 = 6.0;
/// Cutting depth: every sample at this Z is on the compensated contour.
const CUT_Z: f64 = -1.0;

/// A 40 x 30 mm rectangle with its corner at (x0, y0), cut at `CUT_Z` with `comp` (G41.1,
/// inside, or G42.1, outside), counter-clockwise, in exact-path mode (no corner blending).
/// The entry is a slanted move onto the first edge from the side the tool stays on, so it
/// makes a concave corner whose intersection puts the tool on the offset path before the
/// plunge; the cut goes on along the first edge after closing the contour (the last move
/// before G40 ends square to its own end, as in LinuxCNC), then leaves above the stock.
fn profile(comp: &str, x0: f64, y0: f64) -> String {
    let (x1, y1) = (x0 + 40.0, y0 + 30.0);
    let entry_y = if comp.starts_with("G41") {
        y0 + 10.0
    } else {
        y0 - 10.0
    };
    format!(
        "G21 G90 G17 G61 F600\n\
         G0 X{} Y{entry_y} Z2\n\
         {comp} D{DIAMETER}\n\
         G1 X{} Y{y0}\n\
         G1 Z{CUT_Z}\n\
         G1 X{x1}\nG1 Y{y1}\nG1 X{x0}\nG1 Y{y0}\nG1 X{}\n\
         G1 Z2\n\
         G40 G0 X{} Y{}\n\
         M2\n",
        x0 + 10.0,
        x0 + 20.0,
        x0 + 30.0,
        x0 - 10.0,
        y0 - 10.0
    )
}

/// The programmed rectangle as a closed polyline at the cutting depth.
fn contour(x0: f64, y0: f64) -> Vec<[f64; 9]> {
    let (x1, y1) = (x0 + 40.0, y0 + 30.0);
    [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
        .iter()
        .map(|&(x, y)| motion_util::pose(x, y, CUT_Z))
        .collect()
}

/// Interprets, plans and interpolates `text`; returns the cutting samples' distances from
/// the programmed contour (min, max) and how many samples were at the cutting depth.
fn cutting_distances(text: &str) -> (f64, f64, usize) {
    let prog = load_str("comp.ngc", text, &InterpOptions::default()).unwrap();
    let cfg = MotionConfig::default();
    let p = plan(&prog.canon, &cfg).unwrap();
    let tr = motion_util::run(&p, &cfg);
    let path = contour(0.0, 0.0);
    let mut n = 0;
    let (mut lo, mut hi) = (f64::MAX, 0.0_f64);
    for pose in tr.poses_mm.iter().filter(|q| (q[2] - CUT_Z).abs() < 1e-9) {
        let d = trace::distance_to_polyline_mm(pose, &path);
        lo = lo.min(d);
        hi = hi.max(d);
        n += 1;
    }
    (lo, hi, n)
}

/// Asserts that every sample at the cutting depth of `program` lies one tool radius from the
/// programmed contour.
fn assert_one_radius_off_the_contour(program: &str) {
    let (lo, hi, n) = cutting_distances(program);
    assert!(n > 1000, "only {n} samples at the cutting depth");
    let r = DIAMETER / 2.0;
    assert!(
        (lo - r).abs() < 1e-3 && (hi - r).abs() < 1e-3,
        "distance {lo}..{hi}, want {r}"
    );
}

#[test]
fn g41_inside_a_counter_clockwise_rectangle_keeps_the_tool_one_radius_in() {
    // Left of a counter-clockwise contour is inside: straight offsets, concave corners met
    // by intersection, so every point is r from the nearest edge (within the interpolation's
    // sub-micron path error at the corners).
    assert_one_radius_off_the_contour(&profile("G41.1", 0.0, 0.0));
}

#[test]
fn g42_outside_the_rectangle_rounds_the_convex_corners_at_one_radius() {
    // Outside, the corners are convex: the tool goes round each on an arc of radius r
    // centred on the corner, so it never comes closer or goes farther than r (the arcs are
    // interpolated within the planner's tolerance).
    assert_one_radius_off_the_contour(&profile("G42.1", 0.0, 0.0));
}

#[test]
fn a_compensated_profile_job_runs_to_its_end_on_the_simulated_mill() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    // Work at X100 Y100, below the home position: clear at Z-1, cut at Z-4.
    let text = profile("G41.1", 100.0, 100.0)
        .replace(&format!("Z{CUT_Z}"), "Z-4")
        .replace("Z2", "Z-1");
    run_text(&mut c, &text, "comp-profile.ngc");
    let s = wait_job_end(
        &mut c,
        "the compensated job's end",
        Duration::from_secs(300),
    );
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    // After G40 the exit move goes to the programmed point, uncompensated.
    let x = axis(&s, "X")["actual"].as_f64().unwrap();
    let y = axis(&s, "Y")["actual"].as_f64().unwrap();
    assert!(
        (x - 90.0).abs() < 1e-3 && (y - 90.0).abs() < 1e-3,
        "X {x} Y {y}"
    );
}
