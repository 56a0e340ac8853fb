//! The outputs through the simulated I/O device, on the stepped runtime: what the spindle and
//! coolant do on an abort (off, as LinuxCNC's task abort does), and what every output does on
//! machine off, e-stop and when the servo thread stops (its configured safe state).

use super::machine_task::MachineCmd;
use super::tests::Rig;
use crate::gcode::canon::SpindleDir;
use crate::gcode::{Canon, CanonCmd, SourceLoc};
use crate::machine::api::Mode;
use crate::motion;
use crate::rt::prelude::*;
use std::sync::Arc;

/// Channels of tests/fixtures/sim-fast.toml.
const SPINDLE_ON: usize = 0;
const SPINDLE_CCW: usize = 1;
const FLOOD: usize = 2;
const MIST: usize = 3;
const SPINDLE_SPEED: usize = 0;
const ESTOP_DI: usize = 0;

/// What the I/O device has been told: (spindle on, ccw, flood, mist), speed.
fn device(r: &Rig) -> ([bool; 4], f64) {
    let io = r.sim_io[0].as_ref().expect("sim io");
    let d = |i| io.digital_output(i).expect("output");
    (
        [d(SPINDLE_ON), d(SPINDLE_CCW), d(FLOOD), d(MIST)],
        io.analog_output(SPINDLE_SPEED).expect("output"),
    )
}

/// Starts job `job`: M3 S12000 M7 M8 (or the given aux commands), then a feed to `target`.
fn start_job(r: &mut Rig, job: u32, aux: &[CanonCmd], target: [f64; 3]) -> CommandHandle {
    let start = r.position();
    let mut end = start;
    end[..3].copy_from_slice(&target);
    let loc = SourceLoc {
        file: Arc::from("t"),
        line: 3,
        col: 1,
    };
    let canon: Vec<Canon> = aux
        .iter()
        .cloned()
        .chain([CanonCmd::SetFeedRate(3000.0), CanonCmd::StraightFeed(end)])
        .map(|cmd| Canon {
            loc: loc.clone(),
            cmd,
        })
        .collect();
    let plan = motion::plan_from(&canon, &r.motion_cfg, start).expect("plan");
    r.run_plan(job, &plan)
}

fn spindle_and_coolant() -> Vec<CanonCmd> {
    vec![
        CanonCmd::SetSpindleSpeed(12000.0),
        CanonCmd::StartSpindle(SpindleDir::CounterClockwise),
        CanonCmd::MistOn,
        CanonCmd::FloodOn,
    ]
}

/// Runs the job until the spindle is at speed and the axes move.
fn cutting(r: &mut Rig, target: [f64; 3]) -> CommandHandle {
    let run = start_job(r, 1, &spindle_and_coolant(), target);
    r.rt.run_cycles(1500);
    assert_eq!(r.mode(), Mode::Running);
    assert!(r.feedback(0).velocity.abs() > 1.0, "moving");
    assert_eq!(device(r), ([true, true, true, true], 12000.0));
    run
}

#[test]
fn an_abort_stops_the_spindle_and_the_coolant() {
    let mut r = Rig::new();
    r.ready();
    let run = cutting(&mut r, [100.0, 150.0, -30.0]);
    r.send_until_done(MachineCmd::Abort, 5000);
    assert_eq!(run.status(), CommandStatus::Failed("aborted"));
    assert_eq!(r.mode(), Mode::Idle);
    r.rt.run_cycles(2);
    assert_eq!(
        device(&r),
        ([false; 4], 0.0),
        "spindle and coolant after abort"
    );
    assert_eq!(r.snap.latest().expect("snapshot").spindle_rpm, 0.0);
}

#[test]
fn machine_off_puts_every_output_in_its_safe_state_while_moving_and_when_idle() {
    // While a job runs: stop under control, every output safe.
    let mut r = Rig::new();
    r.ready();
    cutting(&mut r, [100.0, 150.0, -30.0]);
    r.send_until_done(MachineCmd::Off, 5000);
    r.rt.run_cycles(2);
    assert_eq!(r.mode(), Mode::Off);
    assert_eq!(device(&r), ([false; 4], 0.0), "outputs after machine off");

    // A job that left the spindle and coolant on (no M5/M9/M2), then machine off when idle.
    let mut r = Rig::new();
    r.ready();
    let x = r.feedback(0).actual;
    let run = start_job(&mut r, 1, &spindle_and_coolant(), [x - 5.0, 290.0, -5.0]);
    for _ in 0..20_000 {
        r.rt.run_cycles(1);
        if run.status() == CommandStatus::Done {
            break;
        }
    }
    assert_eq!(run.status(), CommandStatus::Done);
    r.rt.run_cycles(2);
    assert_eq!(device(&r), ([true, true, true, true], 12000.0), "left on");
    r.send_until_done(MachineCmd::Off, 5000);
    r.rt.run_cycles(2);
    assert_eq!(device(&r), ([false; 4], 0.0), "outputs after machine off");
    assert_eq!(r.snap.latest().expect("snapshot").spindle_rpm, 0.0);
}

/// sim-fast with a configured safe state that is not "all off": the mist output is active
/// and the speed reference 150 in the safe state.
fn rig_with_safe_values() -> Rig {
    let mut cfg = Rig::config();
    cfg.io[0].digital_outputs[MIST].safe = Some(true);
    cfg.io[0].analog_outputs[SPINDLE_SPEED].safe = Some(150.0);
    Rig::with_config(&cfg)
}

#[test]
fn the_configured_safe_state_holds_at_start_up_and_after_the_estop_input() {
    let mut r = rig_with_safe_values();
    r.rt.run_cycles(3);
    assert_eq!(r.mode(), Mode::Estop);
    assert_eq!(
        device(&r),
        ([false, false, false, true], 150.0),
        "at start-up"
    );
    r.ready();
    let run = start_job(&mut r, 1, &spindle_and_coolant(), [100.0, 150.0, -30.0]);
    r.rt.run_cycles(1500);
    assert_eq!(device(&r), ([true, true, true, true], 12000.0));
    r.sim_io[0]
        .as_ref()
        .expect("sim io")
        .set_digital_input(ESTOP_DI, true)
        .expect("input");
    // Seen by the machine task in this cycle, written by the I/O task in the next.
    r.rt.run_cycles(2);
    assert_eq!(r.mode(), Mode::Estop);
    assert_eq!(
        run.status(),
        CommandStatus::Failed("stopped by a fault or e-stop")
    );
    assert_eq!(
        device(&r),
        ([false, false, false, true], 150.0),
        "after e-stop"
    );
    assert_eq!(r.snap.latest().expect("snapshot").spindle_rpm, 0.0);
}

#[test]
fn machine_off_uses_the_configured_safe_state() {
    let mut r = rig_with_safe_values();
    r.ready();
    start_job(&mut r, 1, &spindle_and_coolant(), [100.0, 150.0, -30.0]);
    r.rt.run_cycles(1500);
    r.send_until_done(MachineCmd::Off, 5000);
    r.rt.run_cycles(2);
    assert_eq!(device(&r), ([false, false, false, true], 150.0));
}

#[test]
fn a_stopped_servo_thread_leaves_every_output_in_its_safe_state() {
    // Shutdown stops the machine first; whatever the machine task asked last, the I/O task
    // writes the safe state as the servo thread stops.
    let mut r = rig_with_safe_values();
    r.ready();
    cutting(&mut r, [100.0, 150.0, -30.0]);
    let io = r.sim_io[0].clone().expect("sim io");
    let _deployment = r.rt.stop();
    assert_eq!(
        [0, 1, 2, 3].map(|i| io.digital_output(i).expect("output")),
        [false, false, false, true]
    );
    assert_eq!(io.analog_output(SPINDLE_SPEED).expect("output"), 150.0);
}

#[test]
fn a_fault_stops_the_spindle_and_the_coolant() {
    let mut r = Rig::new();
    r.ready();
    let run = cutting(&mut r, [100.0, 150.0, -30.0]);
    r.sim_axis('X').set_stalled(true);
    for _ in 0..5000 {
        r.rt.run_cycles(1);
        if r.mode() == Mode::Fault && !r.feedback(1).state.is_operational() {
            break;
        }
    }
    assert_eq!(r.mode(), Mode::Fault);
    assert_eq!(
        run.status(),
        CommandStatus::Failed("stopped by a fault or e-stop")
    );
    r.rt.run_cycles(2);
    assert_eq!(
        device(&r),
        ([false; 4], 0.0),
        "spindle and coolant after a fault"
    );
}
