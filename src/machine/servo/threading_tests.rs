//! Spindle-synchronised motion through the machine on the stepped runtime (simulated time):
//! programs planned as a daemon job plans them, run by the machine, interpolator and axis
//! tasks with the simulated spindle. G33 passes lock to the spindle position, G76 finishes,
//! G33.1 reverses at depth and comes back out, and a spindle too fast for the axis stops
//! the job with an error naming the speeds.

use super::machine_task::MachineCmd;
use super::tests::Rig;
use super::{JobError, JobEvent, QueueItem, Setpoints};
use crate::gcode::NUM_AXES;
use crate::machine::api::JobSource;
use crate::machine::job;
use crate::rt::prelude::*;

/// Plans `program` from where the machine stands and starts it as job `job`.
fn start(r: &mut Rig, job: u32, program: &str) {
    let start = r.position();
    let src = JobSource {
        path: None,
        text: Some(program.into()),
        name: Some("thread.ngc".into()),
    };
    let opts = crate::gcode::InterpOptions::default();
    let prepared = job::prepare(&src, &opts, &r.motion_cfg, start).expect("plan");
    for &item in &prepared.plan.items {
        r.queue.try_push(QueueItem { job, item }).expect("room");
    }
    let items = prepared.plan.items.len() as u64;
    let h = r
        .built_machine
        .send(MachineCmd::Run {
            job,
            items,
            manual: false,
        })
        .expect("queue");
    r.rt.run_cycles(1);
    assert!(
        matches!(h.status(), CommandStatus::Accepted | CommandStatus::Done),
        "{:?}",
        h.status()
    );
}

/// Runs the job to its end (finished or not), calling `each` with every cycle's setpoints;
/// returns how it ended.
fn run_to_end(r: &mut Rig, max_cycles: u64, mut each: impl FnMut(&Setpoints)) -> JobEvent {
    for _ in 0..max_cycles {
        r.rt.run_cycles(1);
        let sp = r.sp.latest().expect("setpoints");
        each(&sp);
        while let Some(n) = r.jobs.pop() {
            if matches!(
                n.event,
                JobEvent::Finished { .. }
                    | JobEvent::Error { .. }
                    | JobEvent::Aborted { .. }
                    | JobEvent::Failed { .. }
            ) {
                return n.event;
            }
        }
    }
    panic!("job not over after {max_cycles} cycles");
}

fn frac(x: f64) -> f64 {
    x - x.floor()
}

/// Largest distance of the angles (rev) from the first one, wrapped around the revolution.
fn spread(a: &[f64]) -> f64 {
    a.iter()
        .map(|x| (frac(x - a[0] + 0.5) - 0.5).abs())
        .fold(0.0, f64::max)
}

#[test]
fn g33_passes_started_at_unrelated_spindle_angles_cross_mid_thread_at_the_same_angle() {
    let mut r = Rig::new();
    r.ready();
    // Four passes of a 1.5 mm thread along Z, with pauses of unrelated lengths between
    // them, so each pass starts at another spindle angle.
    let mut text = String::from("G21 G90 G18\nG0 X150 Y150 Z-5\nM3 S1000\n");
    for pause in ["0.1", "0.237", "0.419", "0.05"] {
        text.push_str(&format!(
            "G4 P{pause}\nG33 Z-35 K1.5\nG0 X155\nG0 Z-5\nG0 X150\n"
        ));
    }
    text.push_str("M5\nM2\n");
    start(&mut r, 1, &text);
    // Per pass (its line): the spindle angle in the cycle it started moving, and where
    // Z crossed -20 (the middle of the thread), interpolated within the cycle.
    let mut started: Vec<(u32, f64)> = Vec::new();
    let mut crossed: Vec<(u32, f64)> = Vec::new();
    let mut prev: Option<(f64, f64)> = None;
    let end = run_to_end(&mut r, 200_000, |sp| {
        let z = sp.pose_mm[2];
        let cutting = sp.line >= 5 && (sp.line - 5) % 5 == 0;
        if let (true, Some((z0, rev0))) = (cutting, prev) {
            if z < z0 && !started.iter().any(|s| s.0 == sp.line) {
                started.push((sp.line, rev0));
            }
            if z0 > -20.0 && z <= -20.0 {
                let k = (-20.0 - z0) / (z - z0);
                crossed.push((sp.line, rev0 + k * (sp.spindle_revs - rev0)));
            }
        }
        prev = Some((z, sp.spindle_revs));
    });
    assert!(matches!(end, JobEvent::Finished { .. }), "{end:?}");
    assert_eq!(crossed.len(), 4, "{crossed:?}");
    let at_mid: Vec<f64> = crossed.iter().map(|c| frac(c.1)).collect();
    let at_start: Vec<f64> = started.iter().map(|c| frac(c.1)).collect();
    // 0.002 rev is 3 µm along the thread.
    assert!(spread(&at_mid) < 0.002, "angles mid-thread: {at_mid:?}");
    // A velocity lock (start at once, pitch × speed) crosses the middle a fixed time after
    // the start: its angles there scatter as the start angles do.
    assert!(
        spread(&at_start) > 0.05,
        "the passes started at close angles: {at_start:?}"
    );
    assert!(r.position()[2] > -5.5, "back up: {:?}", r.position());
}

#[test]
fn g76_runs_its_passes_locked_to_the_spindle_and_finishes() {
    let mut r = Rig::new();
    r.ready();
    let text = "G21 G90 G18\nG0 X150 Y150 Z-5\nM3 S1000\n\
                G76 P1.5 Z-30 I-1 J0.2 K1 R2 Q29.5 H1 E1 L3\nM5\nM2\n";
    let mut reversed = false;
    let mut deepest = 0.0f64;
    start(&mut r, 1, text);
    let end = run_to_end(&mut r, 400_000, |sp| {
        reversed |= sp.spindle_reversed;
        deepest = deepest.min(sp.pose_mm[2]);
    });
    assert!(matches!(end, JobEvent::Finished { .. }), "{end:?}");
    assert!(!reversed);
    assert!((deepest + 30.0).abs() < 1e-6, "deepest Z {deepest}");
}

#[test]
fn a_rigid_tap_reverses_at_depth_and_returns_to_its_start() {
    let mut r = Rig::new();
    r.ready();
    let text = "G21 G90\nG0 X100 Y100 Z-5\nM3 S600\nG33.1 Z-20 K1\nM5\nM2\n";
    start(&mut r, 1, text);
    let (mut deepest, mut reversed, mut lowest_rps) = (0.0f64, false, 0.0f64);
    let mut at_tap_end = None;
    let end = run_to_end(&mut r, 100_000, |sp| {
        if sp.line == 4 {
            deepest = deepest.min(sp.pose_mm[2]);
            reversed |= sp.spindle_reversed;
            lowest_rps = lowest_rps.min(sp.spindle_rps);
        }
        if sp.line == 5 && at_tap_end.is_none() {
            at_tap_end = Some(sp.pose_mm);
        }
    });
    assert!(matches!(end, JobEvent::Finished { .. }), "{end:?}");
    assert!(reversed, "the spindle was never reversed");
    assert!(
        lowest_rps < -9.0,
        "the spindle turned back at {lowest_rps} rev/s"
    );
    // The tap overruns the depth by what the spindle turns while it reverses (a short
    // ramp on this spindle) and no more than a revolution.
    assert!((-21.0..-20.0).contains(&deepest), "deepest Z {deepest}");
    let back = at_tap_end.expect("line 5 reached");
    let want = {
        let mut p = [0.0; NUM_AXES];
        (p[0], p[1], p[2]) = (100.0, 100.0, -5.0);
        p
    };
    for a in 0..3 {
        assert!((back[a] - want[a]).abs() < 1e-6, "after the tap: {back:?}");
    }
}

#[test]
fn a_spindle_too_fast_for_the_axis_stops_the_job_with_an_error_naming_the_speeds() {
    let mut r = Rig::new();
    r.ready();
    // 2400 rpm × 1.5 mm = 60 mm/s along Z, which allows 50.
    let text = "G21 G90 G18\nG0 X150 Y150 Z-5\nM3 S2400\nG33 Z-35 K1.5\nM5\nM2\n";
    start(&mut r, 1, text);
    let mut z_min = 0.0f64;
    let end = run_to_end(&mut r, 100_000, |sp| z_min = z_min.min(sp.pose_mm[2]));
    let JobEvent::Error { line, error } = end else {
        panic!("{end:?}");
    };
    assert_eq!(line, 4);
    assert!(matches!(error, JobError::SpindleSync(_)), "{error:?}");
    let text = error.to_string();
    assert!(
        text.contains("2400 rpm") && text.contains("60.00 mm/s") && text.contains("50.00 mm/s"),
        "{text}"
    );
    // Stopped at the start: the axis never tried to follow.
    assert!(z_min > -5.0 - 1e-9, "Z went to {z_min}");
}

#[test]
fn feed_override_and_feed_hold_do_not_act_on_a_synchronised_move() {
    let mut r = Rig::new();
    r.ready();
    r.send_until_done(
        MachineCmd::Overrides {
            feed: 0.5,
            rapid: 1.0,
            spindle: 1.0,
        },
        10,
    );
    let text = "G21 G90 G18\nG0 X150 Y150 Z-5\nM3 S1000\nG33 Z-35 K1.5\nG0 Z-5\nM5\nM2\n";
    start(&mut r, 1, text);
    // Through the thread: a hold is asked for in its middle.
    let (mut top, mut prev_z, mut paused) = (0.0f64, None, None);
    let dt = r.motion_cfg.servo_period_s;
    let mut held_at = None;
    for _ in 0..100_000 {
        r.rt.run_cycles(1);
        let sp = r.sp.latest().expect("setpoints");
        let z = sp.pose_mm[2];
        if sp.line == 4 {
            // Past the catch-up after the index, before the run-out.
            if let (Some(p), true) = (prev_z, (-30.0..-12.0).contains(&z)) {
                top = top.max((p - z) / dt);
            }
            if z < -15.0 && paused.is_none() {
                paused = Some(r.built_machine.send(MachineCmd::Pause).expect("queue"));
            }
        }
        prev_z = Some(z);
        while let Some(n) = r.jobs.pop() {
            assert!(
                !matches!(
                    n.event,
                    JobEvent::Error { .. } | JobEvent::Failed { .. } | JobEvent::Aborted { .. }
                ),
                "{n:?}"
            );
        }
        if paused
            .as_ref()
            .is_some_and(|h| h.status() == CommandStatus::Done)
        {
            held_at = Some(z);
            break;
        }
    }
    // The thread ran at pitch × speed (25 mm/s), not at half of it, and the hold took
    // effect only at its end.
    assert!(
        (top - 25.0).abs() < 0.25,
        "top speed along the thread {top} mm/s"
    );
    let held_at = held_at.expect("the hold never took effect");
    assert!((held_at + 35.0).abs() < 1e-6, "held at Z {held_at}");
    r.send_until_done(MachineCmd::Resume, 10);
    let end = run_to_end(&mut r, 100_000, |_| {});
    assert!(matches!(end, JobEvent::Finished { .. }), "{end:?}");
}
