//! G38.x probe moves through the planner and the interpolator: the move stops on the probe
//! input's change inside the servo period, decelerates within every limit, stays on the
//! path, drops the rest of the probe move and reports its end as a barrier.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::{self, InterpOptions, ProbeKind};
use hytask::motion::trace::{self, Trace};
use hytask::motion::{plan, AuxKind, InterpState, MotionConfig, Plan};
use motion_util::*;

fn plan_text(text: &str) -> (MotionConfig, Plan) {
    let cfg = MotionConfig::default();
    let prog = gcode::load_str("probe.ngc", text, &InterpOptions::default()).unwrap();
    let p = plan(&prog.canon, &cfg).unwrap();
    (cfg, p)
}

/// Runs the plan with a probe input that is active while `touching(pose)`; returns the
/// trace and the interpolator's commanded trip pose, if it tripped.
fn run_with_surface(
    p: &Plan,
    cfg: &MotionConfig,
    touching: impl Fn(&[f64; 9]) -> bool,
) -> (Trace, Option<[f64; 9]>) {
    let mut tripped = None;
    let tr = trace::run(p, cfg, max_periods(p, cfg) + 2000, |_, it| {
        let out = *it.output();
        if out.probe_trip_now {
            tripped = Some(out.probe_pose_mm);
        }
        it.set_probe_input(touching(&out.pose_mm));
    });
    (tr, tripped)
}

fn aux_kinds(tr: &Trace) -> Vec<AuxKind> {
    tr.aux.iter().map(|(_, a)| a.kind).collect()
}

#[test]
fn g38_2_stops_at_the_surface_within_limits_and_ends_with_its_marker() {
    // Down from Z10 toward Z-20 at 600 mm/min; the surface is at Z-5.
    let (cfg, p) = plan_text("G21 G90\nG0 X0 Y0 Z10\nF600\nG38.2 Z-20\nM2\n");
    let (tr, trip) = run_with_surface(&p, &cfg, |q| q[2] <= -5.0);
    let trip = trip.expect("tripped");
    // The input shows the previous period's pose: the trip is recorded within one period
    // of travel past the surface (10 mm/s · 1 ms).
    assert!(trip[2] <= -5.0 && trip[2] >= -5.0 - 0.011, "{trip:?}");
    let end = last(&tr);
    assert!(end[2] < trip[2], "it decelerates past the trip point");
    assert!(
        trip[2] - end[2] < 0.5,
        "overtravel {} mm at 10 mm/s",
        trip[2] - end[2]
    );
    // The stop is the fastest jerk-limited one along the line (`motion::line_stop`):
    // `v·(v/A + A/J)/2` = 0.150 mm from 10 mm/s at 500 mm/s², 50,000 mm/s³ (README, known
    // gaps; braking by time scaling within the reserve took 0.48 mm).
    let (v, a, j) = (10.0, cfg.axes[2].max_acc_mm_s2, cfg.axes[2].max_jerk_mm_s3);
    let optimum = v * (v / a + a / j) / 2.0;
    assert!(
        (trip[2] - end[2] - optimum).abs() < 1e-6,
        "overtravel {} mm, the fastest stop {optimum} mm",
        trip[2] - end[2]
    );
    assert_eq!((end[0], end[1]), (0.0, 0.0), "stays on the path");
    assert_within_limits(&tr, &cfg);
    let kinds = aux_kinds(&tr);
    let arm = kinds
        .iter()
        .position(|k| {
            matches!(
                k,
                AuxKind::ProbeArm {
                    kind: ProbeKind::TowardErr
                }
            )
        })
        .expect("armed");
    let end_marker = kinds
        .iter()
        .position(|k| matches!(k, AuxKind::ProbeEnd { .. }))
        .expect("ProbeEnd reported after the trip");
    assert!(arm < end_marker);
    assert_eq!(*tr.states.last().unwrap(), InterpState::Done);
}

#[test]
fn a_probe_that_never_touches_runs_to_the_programmed_end() {
    let (cfg, p) = plan_text("G21 G90\nF900\nG38.3 X30\nM2\n");
    let (tr, trip) = run_with_surface(&p, &cfg, |_| false);
    assert_eq!(trip, None);
    assert_eq!(last(&tr)[0], 30.0);
    assert!(aux_kinds(&tr).iter().any(|k| matches!(
        k,
        AuxKind::ProbeEnd {
            kind: ProbeKind::Toward
        }
    )));
    assert_within_limits(&tr, &cfg);
}

#[test]
fn g38_4_stops_when_contact_is_lost() {
    // Starting on the surface (input active) and moving away: stops when it releases.
    let (cfg, p) = plan_text("G21 G90\nF300\nG38.4 Z5\nM2\n");
    let (tr, trip) = run_with_surface(&p, &cfg, |q| q[2] < 1.0);
    let trip = trip.expect("released");
    assert!(trip[2] >= 1.0 && trip[2] < 1.01, "{trip:?}");
    assert!(last(&tr)[2] < 5.0);
    assert_within_limits(&tr, &cfg);
}

#[test]
fn a_fast_probe_stop_is_within_the_jerk_and_acceleration_limits() {
    // 3000 mm/min toward a surface reached mid-cruise, and one reached while accelerating.
    for surface in [-30.0, -0.3] {
        let (cfg, p) = plan_text("G21 G90\nF3000\nG38.2 Z-80\nM2\n");
        let (tr, trip) = run_with_surface(&p, &cfg, |q| q[2] <= surface);
        assert!(trip.is_some(), "surface {surface}");
        assert_within_limits(&tr, &cfg);
        assert!(last(&tr)[2] > -80.0);
    }
}

#[test]
fn abort_during_a_probe_move_drops_it_and_forgets_the_probe() {
    let (cfg, p) = plan_text("G21 G90\nF600\nG38.2 Z-20\nM2\n");
    let mut aborted = false;
    let tr = trace::run(&p, &cfg, max_periods(&p, &cfg) + 2000, |n, it| {
        if n == 300 {
            it.abort();
            aborted = true;
        }
        // The input comes on after the abort: it must not count as a trip any more.
        it.set_probe_input(aborted && n > 1500);
        assert!(
            !it.output().probe_trip_now,
            "tripped after abort at period {n}"
        );
    });
    assert_eq!(*tr.states.last().unwrap(), InterpState::Idle);
    assert!(last(&tr)[2] > -20.0);
    assert_within_limits(&tr, &cfg);
}

#[test]
fn the_piece_after_a_trip_starts_where_the_tool_stopped_without_a_jump() {
    use hytask::motion::{Interpolator, Item};
    use std::collections::VecDeque;
    let cfg = MotionConfig::default();
    let mut session = gcode::Session::open_str(
        "p.ngc",
        "G21 G90 F1200\nG38.2 Z-20\nG1 X[#5063 * -2] F3000\nM2\n",
        &InterpOptions::default(),
    )
    .unwrap();
    let (canon, _) = session.next_piece().unwrap();
    let first = hytask::motion::plan(&canon, &cfg).unwrap();
    let mut queue: VecDeque<Item> = first.items.iter().copied().collect();
    let mut it = Interpolator::new(&cfg, first.start_mm);
    let mut tr = Trace {
        dt_s: cfg.servo_period_s,
        poses_mm: vec![first.start_mm],
        ..Trace::default()
    };
    let mut second = None;
    for _ in 0..20_000 {
        it.set_probe_input(it.output().pose_mm[2] <= -4.0);
        let out = *it.step(&mut queue);
        tr.poses_mm.push(out.pose_mm);
        if matches!(out.aux.map(|a| a.kind), Some(AuxKind::ProbeEnd { .. })) {
            let stop = out.pose_mm;
            let trip = out.probe_pose_mm;
            let z = |p: [f64; 9]| [p[0], p[1], p[2], p[3], p[4], p[5]];
            session.probe_result(&gcode::ProbeResult {
                tripped: out.probe_tripped,
                probed: z(trip),
                stopped: z(stop),
            });
            let (canon, _) = session.next_piece().unwrap();
            let p =
                hytask::motion::plan_continue(&canon, &cfg, stop, first.end_state.clone()).unwrap();
            queue.extend(p.items.iter().copied());
            second = Some((p, trip));
        }
        if out.state == InterpState::Waiting {
            it.aux_done();
        }
        if out.state == InterpState::Done && second.is_some() && queue.is_empty() {
            break;
        }
    }
    let (p, trip) = second.expect("probe ended");
    assert_within_limits(&tr, &cfg);
    let end = last(&tr);
    assert_eq!(end, p.end_mm);
    assert!((end[0] - trip[2] * -2.0).abs() < 1e-9, "X = -2 · #5063");
    assert!(end[2] < -4.0 && end[2] > -20.0);
}
