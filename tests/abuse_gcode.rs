//! Abuse of the G-code path from outside, through interpreter, planner and interpolator as a
//! daemon job runs them: P/L/Q extremes and mutated real programs. Whatever the program:
//! an error naming its line (and for the interpreter file:line:col), or a plan that runs;
//! never a panic, a hang, an allocation the size of the request's numbers, and an abort
//! always stops what runs.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::{load_str, InterpOptions};
use hytask::motion::trace;
use hytask::motion::{plan, InterpState, MotionConfig};

fn canon(text: &str) -> Vec<hytask::gcode::Canon> {
    load_str("abuse.ngc", text, &InterpOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .canon
}

/// Found by `G2 X299 Y299 I-1 J0 F100 P2000000000` over MDI: the planner sized the chords of
/// an arc of two billion turns in one allocation (4.5 TB) and the daemon aborted. A turn
/// count is legal G-code; the plan must refuse it by line instead.
#[test]
fn an_arc_of_two_billion_turns_is_refused_by_line_not_allocated() {
    let c = canon("G21 G90 G17\nG0 X10 Y10\nG2 X10 Y10 I5 J0 F100 P2000000000\nM2\n");
    let e = plan(&c, &MotionConfig::default()).unwrap_err().to_string();
    assert!(e.contains("line 3"), "{e}");
    assert!(e.contains("turns") || e.contains("chords"), "{e}");
}

/// The chord bound is per arc and generous: real helices (thread milling, a deep spiral)
/// still plan.
#[test]
fn a_helix_of_a_thousand_turns_still_plans() {
    let c = canon("G21 G90 G17\nG0 X10 Y10 Z0\nG2 X10 Y10 Z-50 I5 J0 F600 P1000\nM2\n");
    let p = plan(&c, &MotionConfig::default()).unwrap();
    assert!(p.distance_mm > 1000.0 * 2.0 * std::f64::consts::PI * 5.0);
}

/// Found by `G4 P100` then `job.abort` over the socket: the abort was accepted, but the dwell
/// ran to its end (a `G4 P1e20` never ended; only an e-stop stopped the job). The tool is at
/// rest during a dwell, so an abort must end it at once.
#[test]
fn an_abort_ends_a_dwell_at_once() {
    let cfg = MotionConfig::default();
    let c = canon("G21 G90\nG1 X5 F600\nG4 P100000\nG1 X10\nM2\n");
    let p = plan(&c, &cfg).unwrap();
    let periods_per_s = (1.0 / cfg.servo_period_s) as usize;
    let mut abort_at = None;
    let tr = trace::run(&p, &cfg, 30 * periods_per_s, |n, it| {
        // Abort 1 s into the dwell (the move to X5 takes about half a second).
        if n == 2 * periods_per_s {
            abort_at = Some(n);
            it.abort();
        }
    });
    assert!(abort_at.is_some(), "the trace ended before the abort");
    let end = tr.states.len();
    assert_eq!(
        *tr.states.last().unwrap(),
        InterpState::Idle,
        "still dwelling"
    );
    assert!(
        end < 3 * periods_per_s,
        "the abort took {} periods",
        end - 2 * periods_per_s
    );
    assert_eq!(
        motion_util::last(&tr)[0],
        5.0,
        "stopped where the dwell was"
    );
}
