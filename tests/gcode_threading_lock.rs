//! Position-locked threading (issue 13): a stepped machine (1 kHz servo period) made of the
//! simulated spindle (a speed ramp and a load ripple, so it never turns at exactly the
//! commanded speed) and the spindle-position follower of a synchronised move.
//!
//! Simulated time only: no wall clock, no threads.
#![allow(clippy::unwrap_used)]

use hytask::machine::sim_spindle::{SimSpindle, SimSpindleParams};
use hytask::motion::spindle_lock::{LockError, LockMode, LockPhase, SpindleLock, SpindleSample};

const DT: f64 = 0.001;
/// Axis limits along the move.
const VMAX: f64 = 50.0;
const AMAX: f64 = 500.0;

fn rippling_spindle() -> SimSpindle {
    SimSpindle::new(
        SimSpindleParams {
            accel_rps2: 40.0,
            ripple: 0.05,
            ripple_hz: 7.3,
        },
        0.137,
    )
}

/// Fractional part in [0, 1).
fn frac(x: f64) -> f64 {
    x - x.floor()
}

/// Runs one G33 pass of `length` mm at `pitch` mm/rev; returns the spindle angle (rev,
/// fractional) when the tool crosses `at` mm, the lag there, and the time the pass took.
fn pass(sp: &mut SimSpindle, rpm: f64, pitch: f64, length: f64, at: f64) -> (f64, f64, f64) {
    let mut lock = SpindleLock::new(LockMode::Thread, pitch, length, VMAX, AMAX);
    let mut seen = None;
    let mut prev = (0.0, sp.revs());
    let mut t = 0.0;
    loop {
        let s = sp.step(DT, rpm);
        let st = lock.step(DT, &s).unwrap();
        t += DT;
        if seen.is_none() && st.s >= at {
            // Spindle angle at the crossing, interpolated within the cycle.
            let k = (at - prev.0) / (st.s - prev.0);
            let revs = prev.1 + k * (s.revs - prev.1);
            seen = Some((frac(revs), lock.target(&s) - st.s));
        }
        prev = (st.s, s.revs);
        if st.done {
            let (angle, lag) = seen.unwrap();
            return (angle, lag, t);
        }
        assert!(t < 60.0, "pass never ended: {:?}", lock.phase());
    }
}

/// Retract, return and whatever the program does between passes: the spindle keeps
/// turning (and rippling) for `secs`.
fn idle(sp: &mut SimSpindle, rpm: f64, secs: f64) {
    for _ in 0..(secs / DT).round() as usize {
        sp.step(DT, rpm);
    }
}

#[test]
fn every_pass_of_a_thread_cuts_the_same_groove_although_the_spindle_speed_ripples() {
    let (rpm, pitch, length) = (600.0, 1.5, 20.0);
    let mut sp = rippling_spindle();
    // The first pass starts while the spindle is still ramping up; the others after waits
    // of unrelated lengths, so each starts at another spindle angle and ripple phase.
    let waits = [0.0, 0.373, 0.811, 1.129, 0.257];
    let mut angles = Vec::new();
    let mut velocity_locked = Vec::new();
    for w in waits {
        idle(&mut sp, rpm, w);
        // What a velocity lock (pitch × commanded speed from the moment the pass starts,
        // the former behaviour) would cut at 10 mm: the angle 10 mm / (pitch × rps) later.
        let mut probe = sp.clone();
        idle(&mut probe, rpm, 10.0 / (pitch * rpm / 60.0));
        velocity_locked.push(frac(probe.revs()));
        let (angle, lag, _) = pass(&mut sp, rpm, pitch, length, 10.0);
        // Within two servo periods of travel (15 µm each at 15 mm/s).
        assert!(lag.abs() < 0.03, "lag at 10 mm: {lag} mm");
        angles.push(angle);
    }
    let spread = |a: &[f64]| {
        // Angles near 0 and near 1 are close: measure against the first one, wrapped.
        a.iter()
            .map(|x| {
                let d = frac(x - a[0] + 0.5) - 0.5;
                d.abs()
            })
            .fold(0.0, f64::max)
    };
    // 0.002 rev is 3 µm of axial position at this pitch.
    assert!(spread(&angles) < 0.002, "angles at 10 mm: {angles:?}");
    // The check can fail: the velocity-locked passes land in different grooves.
    assert!(
        spread(&velocity_locked) > 0.05,
        "velocity-locked: {velocity_locked:?}"
    );
}

#[test]
fn a_rigid_tap_reverses_at_depth_and_comes_out_along_the_same_helix() {
    let (rpm, pitch, depth) = (300.0, 1.0, 12.0);
    let mut sp = SimSpindle::new(
        SimSpindleParams {
            accel_rps2: 20.0,
            ripple: 0.05,
            ripple_hz: 7.3,
        },
        0.61,
    );
    idle(&mut sp, rpm, 0.6);
    let mut lock = SpindleLock::new(LockMode::RigidTap, pitch, depth, VMAX, AMAX);
    let mut cmd = rpm;
    let (mut deepest, mut reversed, mut t) = (0.0f64, false, 0.0);
    let mut worst_in = 0.0f64;
    let mut worst_out = 0.0f64;
    let mut rev0 = None;
    loop {
        let s = sp.step(DT, cmd);
        if s.index && rev0.is_none() {
            rev0 = Some(s.index_at);
        }
        let st = lock.step(DT, &s).unwrap();
        t += DT;
        assert!(t < 60.0, "tap never ended: {:?}", lock.phase());
        if st.reverse_spindle {
            assert!(!reversed, "reversal asked twice");
            reversed = true;
            cmd = -rpm;
        }
        deepest = deepest.max(st.s);
        // The helix: the tool's depth against the spindle angle since the index. Checked
        // once the axis has caught up with the spindle (1 mm in) until it leaves the
        // thread (1 mm from the top).
        if let Some(r0) = rev0 {
            let off = st.s - pitch * (s.revs - r0);
            if st.s > 1.0 {
                if reversed {
                    worst_out = worst_out.max(off.abs());
                } else {
                    worst_in = worst_in.max(off.abs());
                }
            }
        }
        if st.done {
            assert_eq!(st.s, 0.0, "back at the start");
            break;
        }
    }
    assert!(reversed);
    assert!(worst_in < 0.02, "off the helix going in: {worst_in} mm");
    assert!(worst_out < 0.02, "off the helix coming out: {worst_out} mm");
    // Overrun while the spindle stops: (5 rev/s)² / (2 × 20 rev/s²) = 0.625 rev, ±ripple.
    assert!(
        (depth + 0.5..depth + 0.8).contains(&deepest),
        "deepest {deepest}"
    );
}

#[test]
fn a_spindle_faster_than_the_axis_can_follow_stops_the_move_with_both_speeds() {
    let mut sp = rippling_spindle();
    idle(&mut sp, 2400.0, 1.5);
    let mut lock = SpindleLock::new(LockMode::Thread, 1.5, 20.0, VMAX, AMAX);
    let err = (0..2000)
        .find_map(|_| lock.step(DT, &sp.step(DT, 2400.0)).err())
        .unwrap();
    assert!(matches!(err, LockError::SpindleTooFast { .. }), "{err}");
    assert!(err.to_string().contains("50.00 mm/s"), "{err}");
}

#[test]
fn a_stopped_spindle_is_refused_instead_of_waiting_for_an_index_forever() {
    let mut lock = SpindleLock::new(LockMode::Thread, 1.5, 20.0, VMAX, AMAX);
    assert_eq!(lock.phase(), LockPhase::WaitIndex);
    assert_eq!(
        lock.step(DT, &SpindleSample::default()),
        Err(LockError::SpindleStopped)
    );
}
