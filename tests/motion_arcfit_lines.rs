//! Line numbers over fitted arcs (issue 14): when `motion::arcfit` replaces a run of short G1
//! lines by arcs, the executing line the interpolator reports (status `line`, job progress)
//! advances through the run's source lines as the tool passes each original vertex, instead
//! of staying on one line for the whole arc.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::motion::trace;
use hytask::motion::{plan, Item, MotionConfig};
use motion_util::*;

/// Distance from `p` to the segment `a`–`b` in XY.
fn dist_to_chord(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// A run of `n` chords of about `step` mm on a spiral, rounded to 3 decimals like CAM output,
/// under G64 P`tol` at `feed` mm/min; returns the program, the chord end points and the line
/// of each chord (chord k ends at `pts[k + 1]`).
fn spiral_run(n: usize, step: f64, tol: f64, feed: f64) -> (Prog, Vec<[f64; 2]>, Vec<u32>) {
    let r0 = 10.0;
    let point = |s: f64| {
        let r = r0 + 0.02 * s;
        let a = s / r0;
        let round = |v: f64| (v * 1000.0).round() / 1000.0;
        [round(r * a.cos()), round(r * a.sin())]
    };
    let mut g = Prog::new();
    let p0 = point(0.0);
    g.g0(p0[0], p0[1], 0.0).feed(feed).g64(tol);
    let mut pts = vec![p0];
    let mut lines = Vec::with_capacity(n);
    for k in 1..=n {
        let p = point(k as f64 * step);
        g.g1(p[0], p[1], 0.0);
        pts.push(p);
        lines.push(g.line());
    }
    (g, pts, lines)
}

/// Every period of the trace reports a line of the run whose chord the tool is on (within the
/// tolerance, and a few µm of quantisation along the path), the lines come in program order,
/// and every line of the run is reported.
fn check_lines(n: usize, step: f64, tol: f64, feed: f64) {
    let cfg = MotionConfig::default();
    let (g, pts, lines) = spiral_run(n, step, tol, feed);
    let p = plan(&g.canon, &cfg).unwrap();
    let arcs = p
        .items
        .iter()
        .filter(|it| matches!(it, Item::Segment(s) if s.curvature_per_mm != 0.0))
        .count();
    assert!(arcs > 0, "the run was not fitted");
    assert!(arcs < n / 2, "{arcs} arcs for {n} chords: not a fitted run");
    let tr = trace::run_all(&p, &cfg);
    let (first, last) = (lines[0], lines[n - 1]);
    let mut seen = Vec::new();
    for (pose, &line) in tr.poses_mm.iter().zip(&tr.lines) {
        if line < first || line > last {
            continue;
        }
        let k = (line - first) as usize;
        let d = dist_to_chord([pose[0], pose[1]], pts[k], pts[k + 1]);
        assert!(
            d <= tol + 0.01,
            "line {line} reported {d} mm away from its chord at ({}, {})",
            pose[0],
            pose[1]
        );
        if seen.last() != Some(&line) {
            seen.push(line);
        }
    }
    assert_eq!(seen, lines, "lines not reported one by one in order");
}

#[test]
fn a_fitted_run_reports_each_line_in_order() {
    // 0.1 mm chords at 25 mm/s: four servo periods per chord.
    check_lines(400, 0.1, 0.01, 1500.0);
}

#[test]
fn long_chords_and_full_feed_report_each_line_in_order() {
    // 0.25 mm chords at 50 mm/s (five periods per chord), looser tolerance: long arcs.
    check_lines(300, 0.25, 0.05, 3000.0);
}
