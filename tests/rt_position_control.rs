//! The position-control example's tasks on the stepped activity: deterministic cycles,
//! `move_to` completes when the position is reached, a too-fast move raises the tracking-error
//! event, and bad parameters are rejected with a reason.
#![allow(clippy::unwrap_used)]

#[path = "../examples/position_control.rs"]
#[allow(dead_code)]
mod position_control;

use hytask::rt::prelude::*;
use position_control::{deploy, names, InterpolatorCmd, TrackingError};

#[test]
fn move_to_completes_when_position_reached_and_tracking_error_is_raised() {
    let (app, interp) = deploy(1_000_000, 80).unwrap();
    let mut errors = app
        .event::<TrackingError>(names::TRACKING_ERROR)
        .unwrap()
        .subscribe(16);
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    let mut position = rt.reader::<f64>(names::POSITION).unwrap();

    // 0.1 m at 0.2 m/s: 500 ms of ramp plus settling.
    let c = interp
        .send(InterpolatorCmd::MoveTo {
            target_m: 0.1,
            speed_m_s: 0.2,
        })
        .unwrap();
    rt.run_cycles(400);
    assert_eq!(c.status(), CommandStatus::Accepted, "still moving");
    let mut cycles = 400;
    while c.status() == CommandStatus::Accepted && cycles < 5_000 {
        rt.run_cycles(10);
        cycles += 10;
    }
    assert_eq!(c.status(), CommandStatus::Done, "after {cycles} cycles");
    let p = position.latest().unwrap();
    assert!((p - 0.1).abs() <= 1e-4, "position {p}");
    assert_eq!(
        errors.pop(),
        None,
        "a trackable move raises no tracking error"
    );

    // Determinism: the same run gives the same cycle count.
    let (app2, interp2) = deploy(1_000_000, 80).unwrap();
    let mut rt2 = app2.start_stepped(SimClock::new(0)).unwrap();
    let c2 = interp2
        .send(InterpolatorCmd::MoveTo {
            target_m: 0.1,
            speed_m_s: 0.2,
        })
        .unwrap();
    rt2.run_cycles(400);
    let mut cycles2 = 400;
    while c2.status() == CommandStatus::Accepted && cycles2 < 5_000 {
        rt2.run_cycles(10);
        cycles2 += 10;
    }
    assert_eq!(cycles, cycles2);

    // Too fast to track: the monitor raises the event, the command still completes.
    let fast = rt
        .task("interpolator")
        .unwrap()
        .commands()
        .send_args("move_to", &[ArgValue::Float(0.0), ArgValue::Int(20)])
        .unwrap();
    let mut cycles = 0;
    while fast.status() == CommandStatus::Accepted || cycles == 0 {
        rt.run_cycles(10);
        cycles += 10;
        assert!(cycles < 20_000, "fast move never settled");
    }
    let e = errors.pop().expect("tracking error event");
    assert!(e.error_m.abs() > 0.005, "{e:?}");
    assert_eq!(fast.status(), CommandStatus::Done);
    assert!(position.latest().unwrap().abs() <= 1e-4);

    let bad = interp
        .send(InterpolatorCmd::MoveTo {
            target_m: 1.0,
            speed_m_s: -1.0,
        })
        .unwrap();
    rt.run_cycles(1);
    assert_eq!(
        bad.status(),
        CommandStatus::Rejected(RejectReason::BadParameters("speed_m_s out of range"))
    );
    assert_eq!(rt.threads().len(), 1, "five tasks, one thread");
}
