//! The cell's error paths on simulated time: the gripper loses the object while it is carried
//! (injected at a given grab, and on demand through the `hw` task's `drop_object`), and an
//! emergency stop (the robot's operation and the cell's e-stop button). Each one must take
//! the selection to `error_detected`, fail the running `run`, and leave the robot stopped;
//! `stop` then recovers to `homed`.
#![allow(clippy::unwrap_used)]

mod cell_support;

use cell_support::{Rig, SECOND};
use hytask::cell::config::CellConfig;
use hytask::cell::hw::HwCmd;
use hytask::cell::names;
use hytask::cell::robot::RobotCmd;
use hytask::cell::selection::{SelectionCmd, SelectionState};
use hytask::cell::types::{RobotState, RobotStatus};
use hytask::rt::prelude::*;

fn robot_state(rig: &mut Rig) -> RobotStatus {
    rig.rt
        .reader::<RobotStatus>(names::ROBOT_STATUS)
        .unwrap()
        .latest()
        .unwrap()
}

/// Runs the cell until the running `run` fails; checks error detected, robot stopped and
/// standing still, then recovers with `stop`.
fn expect_error_then_recover(rig: &mut Rig, run: &CommandHandle, why: &str) {
    let n = rig.run_until(60 * SECOND, |_| run.status().is_final());
    assert_eq!(
        run.status(),
        CommandStatus::Failed("error detected"),
        "after {n} cycles"
    );
    let s = rig.state();
    assert_eq!(s.state, SelectionState::ErrorDetected);
    assert!(s.error.is_some_and(|e| e.contains(why)), "{:?}", s.error);
    rig.rt.run_cycles(100);
    let r0 = robot_state(rig);
    assert_eq!(r0.state, RobotState::EmergencyStop, "the robot is stopped");
    rig.rt.run_cycles(500);
    let r1 = robot_state(rig);
    assert_eq!(r1.position_mm, r0.position_mm, "and stands still");
    // A move is refused while stopped.
    let m = rig
        .robot
        .send(RobotCmd::MoveTo([100.0, 100.0, 100.0]))
        .unwrap();
    rig.rt.run_cycles(5);
    assert!(
        matches!(m.status(), CommandStatus::Rejected(_)),
        "{:?}",
        m.status()
    );

    let stop = rig.cell_selection.send(SelectionCmd::Stop).unwrap();
    rig.run_until(20 * SECOND, |_| stop.status().is_final());
    assert_eq!(stop.status(), CommandStatus::Done);
    assert_eq!(rig.state().state, SelectionState::Homed);
    assert_eq!(robot_state(rig).state, RobotState::Idle);
}

#[test]
fn object_lost_while_moving_goes_to_error_detected_and_stops_the_robot() {
    let mut cfg = CellConfig::with_seed(42);
    cfg.world.faults.drop_on_grab = Some(3);
    let mut rig = Rig::start(&cfg);
    rig.until_homed();
    let run = rig.cell_selection.send(SelectionCmd::Run(5)).unwrap();
    expect_error_then_recover(&mut rig, &run, "object lost");
    assert_eq!(
        rig.state().runs_done,
        2,
        "the first two objects were sorted"
    );
    let t = rig.tally();
    assert_eq!((t.on_floor, t.in_container.iter().sum::<u32>()), (1, 2));

    // After recovery the cell sorts again.
    let again = rig.cell_selection.send(SelectionCmd::Run(2)).unwrap();
    rig.run_until(30 * SECOND, |_| again.status().is_final());
    assert_eq!(again.status(), CommandStatus::Done);
}

#[test]
fn drop_object_injected_on_demand_is_detected() {
    let mut rig = Rig::start(&CellConfig::with_seed(5));
    rig.until_homed();
    let run = rig.cell_selection.send(SelectionCmd::Run(3)).unwrap();
    let n = rig.run_until(20 * SECOND, |r| {
        r.state().state == SelectionState::MovingWithObject
    });
    assert!(n < 20 * SECOND);
    rig.rt.run_cycles(50);
    let drop = rig.hw.send(HwCmd::DropObject).unwrap();
    rig.rt.run_cycles(2);
    assert_eq!(drop.status(), CommandStatus::Done);
    expect_error_then_recover(&mut rig, &run, "object lost");
}

#[test]
fn emergency_stop_operation_stops_robot_and_selection() {
    let mut rig = Rig::start(&CellConfig::with_seed(9));
    rig.until_homed();
    let run = rig.cell_selection.send(SelectionCmd::Run(3)).unwrap();
    rig.run_until(20 * SECOND, |r| {
        r.state().state == SelectionState::MovingWithoutObject
    });
    rig.rt.run_cycles(150);
    assert_eq!(robot_state(&mut rig).state, RobotState::Moving);
    let e = rig.robot.send(RobotCmd::EmergencyStop).unwrap();
    rig.rt.run_cycles(2);
    assert_eq!(e.status(), CommandStatus::Done);
    assert_eq!(robot_state(&mut rig).state, RobotState::EmergencyStop);
    expect_error_then_recover(&mut rig, &run, "");
}

#[test]
fn estop_button_stops_the_robot_and_blocks_recovery_until_released() {
    let mut rig = Rig::start(&CellConfig::with_seed(11));
    rig.until_homed();
    let run = rig.cell_selection.send(SelectionCmd::Run(3)).unwrap();
    rig.run_until(20 * SECOND, |r| {
        r.state().state == SelectionState::MovingWithObject
    });
    rig.hw.send(HwCmd::PressEstop).unwrap();
    rig.run_until(10 * SECOND, |_| run.status().is_final());
    assert_eq!(run.status(), CommandStatus::Failed("error detected"));
    assert_eq!(robot_state(&mut rig).state, RobotState::EmergencyStop);
    // Reset is refused while the button is pressed.
    let reset = rig.robot.send(RobotCmd::Reset).unwrap();
    rig.rt.run_cycles(5);
    assert!(matches!(reset.status(), CommandStatus::Rejected(_)));
    rig.hw.send(HwCmd::ReleaseEstop).unwrap();
    rig.rt.run_cycles(5);
    let stop = rig.cell_selection.send(SelectionCmd::Stop).unwrap();
    rig.run_until(20 * SECOND, |_| stop.status().is_final());
    assert_eq!(stop.status(), CommandStatus::Done);
    assert_eq!(rig.state().state, SelectionState::Homed);
}

#[test]
fn move_outside_workspace_is_rejected() {
    let mut rig = Rig::start(&CellConfig::with_seed(2));
    rig.until_homed();
    let bad = rig.robot.send(RobotCmd::MoveTo([1e4, 0.0, 0.0])).unwrap();
    rig.rt.run_cycles(5);
    assert_eq!(
        bad.status(),
        CommandStatus::Rejected(RejectReason::BadParameters("target outside the workspace"))
    );
}

#[test]
fn tracking_error_faults_the_robot_and_the_selection_detects_it() {
    let mut cfg = CellConfig::with_seed(3);
    // Amplifiers too weak for the programmed acceleration: the axes lag their setpoint.
    cfg.pid.max_force_n = 3.0;
    let mut rig = Rig::start(&cfg);
    let mut tracking =
        rig.subscribe::<hytask::cell::types::TrackingError>(names::TRACKING_ERROR_EVENT);
    rig.until_homed();
    let run = rig.cell_selection.send(SelectionCmd::Run(1)).unwrap();
    rig.run_until(20 * SECOND, |_| run.status().is_final());
    assert_eq!(run.status(), CommandStatus::Failed("error detected"));
    assert!(tracking.pop().is_some(), "pid.tracking_error was raised");
    assert_eq!(robot_state(&mut rig).state, RobotState::EmergencyStop);
    assert!(
        rig.state()
            .error
            .is_some_and(|e| e.contains("robot stopped")),
        "{:?}",
        rig.state()
    );
}

#[test]
fn sensor_range_error_faults_the_robot_and_the_selection_detects_it() {
    let mut rig = Rig::start(&CellConfig::with_seed(11));
    let mut range = rig.subscribe::<hytask::cell::types::RangeError>(names::RANGE_ERROR_EVENT);
    rig.until_homed();
    assert!(range.pop().is_none(), "no range error while homing");
    let run = rig.cell_selection.send(SelectionCmd::Run(3)).unwrap();
    rig.run_until(20 * SECOND, |r| {
        r.state().state == SelectionState::MovingWithoutObject
    });
    rig.rt.run_cycles(100);
    let glitch = rig.hw.send(HwCmd::EncoderGlitch).unwrap();
    rig.rt.run_cycles(3);
    assert_eq!(glitch.status(), CommandStatus::Done);
    let e = range.pop().expect("sensor.range_error was raised");
    assert_eq!(e.axis, 0);
    assert_eq!(e.position_mm, hytask::cell::hw::GLITCH_MM);
    assert!(range.pop().is_none(), "once per excursion");
    expect_error_then_recover(&mut rig, &run, "robot stopped");
}
