//! Program stops (M0, M1, M60) on the stepped runtime, cycle by cycle: the machine holds at
//! the stop, `resume` goes on with the next line, and `step` runs exactly the next line.

use super::machine_task::MachineCmd;
use super::tests::Rig;
use super::QueueItem;
use crate::gcode::NUM_AXES;
use crate::machine::api::{JobSource, Mode};
use crate::machine::job;
use crate::rt::prelude::*;

/// Plans `program` from where the machine stands and starts it as job `job`.
fn run_program(r: &mut Rig, job: u32, program: &str) {
    let mut start = [0.0; NUM_AXES];
    for (i, s) in start.iter_mut().take(3).enumerate() {
        *s = r.feedback(i).actual;
    }
    let src = JobSource {
        path: None,
        text: Some(program.into()),
        name: Some("stops.ngc".into()),
    };
    let opts = crate::gcode::InterpOptions::default();
    let prepared = job::prepare(&src, &opts, &r.motion_cfg, start).expect("plan");
    for &item in &prepared.plan.items {
        r.queue.try_push(QueueItem { job, item }).expect("room");
    }
    let items = prepared.plan.items.len() as u64;
    r.send_until_accepted(MachineCmd::Run {
        job,
        items,
        manual: false,
    });
}

impl Rig {
    fn send_until_accepted(&mut self, cmd: MachineCmd) {
        let h = self.built_machine.send(cmd).expect("queue");
        self.rt.run_cycles(1);
        assert!(
            matches!(h.status(), CommandStatus::Accepted | CommandStatus::Done),
            "{cmd:?}: {:?}",
            h.status()
        );
    }

    /// Runs cycles until the machine is in `mode` with every axis at rest.
    fn until_at_rest_in(&mut self, mode: Mode, max_cycles: u64) {
        for _ in 0..max_cycles {
            self.rt.run_cycles(1);
            let rest = (0..3).all(|i| self.feedback(i).velocity.abs() < 1e-9);
            if rest && self.mode() == mode {
                return;
            }
        }
        panic!(
            "not at rest in {mode:?} after {max_cycles} cycles: {:?}",
            self.mode()
        );
    }

    fn line(&mut self) -> u32 {
        self.sp.latest().expect("setpoints").line
    }
}

const PROGRAM: &str =
    "G21 G90\nG0 X100 Y100 Z-5\nM0\nG1 X110 Y105 F1200\nG1 X120 Y100\nM1\nG0 X130\nM2\n";

#[test]
fn m0_holds_and_resume_goes_on_with_the_next_line() {
    let mut r = Rig::new();
    r.ready();
    run_program(&mut r, 1, PROGRAM);
    r.until_at_rest_in(Mode::Holding, 20_000);
    assert_eq!(r.line(), 3);
    assert!((r.feedback(0).actual - 100.0).abs() < 1e-6);
    r.send_until_accepted(MachineCmd::Resume);
    assert_eq!(r.mode(), Mode::Running);
    // M1 with optional stop off (the default) is passed over: the job runs to its end.
    r.until_at_rest_in(Mode::Idle, 20_000);
    assert!((r.feedback(0).actual - 130.0).abs() < 1e-3);
}

#[test]
fn step_at_an_m0_runs_the_next_line_then_holds() {
    let mut r = Rig::new();
    r.ready();
    r.send_until_accepted(MachineCmd::OptionalStop { on: true });
    run_program(&mut r, 1, PROGRAM);
    r.until_at_rest_in(Mode::Holding, 20_000);
    r.send_until_accepted(MachineCmd::Step);
    r.until_at_rest_in(Mode::Holding, 20_000);
    // Line 4 ran; the hold began with line 5 (blended at the corner: it stops on the way).
    assert_eq!(r.line(), 5, "held after line 5 began");
    let x = r.feedback(0).actual;
    assert!(x > 110.0 && x < 120.0 - 1e-3, "{x}");
    // Optional stop on: M1 holds like M0.
    r.send_until_accepted(MachineCmd::Resume);
    r.until_at_rest_in(Mode::Holding, 20_000);
    assert_eq!(r.line(), 6);
    assert!((r.feedback(0).actual - 120.0).abs() < 1e-3);
    r.send_until_accepted(MachineCmd::Resume);
    r.until_at_rest_in(Mode::Idle, 20_000);
    assert!((r.feedback(0).actual - 130.0).abs() < 1e-3);
}

/// `operation_index` picks the descriptor (and so the `next` policy) of each command.
#[test]
fn every_command_points_at_its_own_operation() {
    let cases = [
        (MachineCmd::Pause, "pause"),
        (MachineCmd::Resume, "resume"),
        (MachineCmd::Step, "step"),
        (MachineCmd::Continue { job: 1, items: 1 }, "continue"),
        (MachineCmd::OptionalStop { on: true }, "set_optional_stop"),
    ];
    for (cmd, name) in cases {
        assert_eq!(
            MachineCmd::operations()[cmd.operation_index()].name,
            name,
            "{cmd:?}"
        );
    }
}

/// The machine task serves a few commands at a time (`MAX_ACTIVE_COMMANDS`); aborts sent
/// during a deceleration all stay active until it ends. An e-stop request does not queue
/// behind them: it is taken in the next cycle.
#[test]
fn an_estop_request_is_taken_while_every_command_slot_is_busy() {
    use std::sync::atomic::Ordering;
    let mut r = Rig::new();
    r.ready();
    let x0 = r.feedback(0).actual;
    r.start_move(1, [x0 - 250.0, 100.0, -5.0], 6000.0);
    r.rt.run_cycles(1500);
    assert!(r.feedback(0).velocity.abs() > 50.0, "at speed");
    // The job's own `run` holds one slot; the aborts take the others.
    let aborts: Vec<_> = (1..crate::rt::runner::MAX_ACTIVE_COMMANDS)
        .map(|_| r.built_machine.send(MachineCmd::Abort).expect("queue"))
        .collect();
    let queued = r.built_machine.send(MachineCmd::Estop).expect("queue");
    r.rt.run_cycles(20);
    assert!(aborts.iter().all(|h| h.status() == CommandStatus::Accepted));
    assert_eq!(queued.status(), CommandStatus::Pending, "slots are busy");
    assert_ne!(r.mode(), Mode::Estop);
    r.estop_request.fetch_add(1, Ordering::AcqRel);
    r.rt.run_cycles(1);
    assert_eq!(r.mode(), Mode::Estop);
}
