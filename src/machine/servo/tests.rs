//! The machine's tasks on the stepped runtime with simulated time: deterministic, cycle-exact
//! checks of what the end-to-end tests can only see through a socket. E-stop quick-stops
//! every drive in the cycle the input is seen; an abort and a fault stop along the path
//! within every axis' velocity and acceleration limit.

use super::machine_task::MachineCmd;
use super::{ports, AxisFeedback, JobEvent, JobNews, MachineSnapshot, QueueItem, Setpoints};
use crate::gcode::{Canon, CanonCmd, SourceLoc, NUM_AXES};
use crate::machine::api::Mode;
use crate::machine::runtime::{build, Built};
use crate::motion::{self, InterpState};
use crate::rt::deploy::SteppedRuntime;
use crate::rt::prelude::*;
use hytask_hal::axis::DriveState;
use std::sync::Arc;

pub(super) struct Rig {
    pub(super) rt: SteppedRuntime,
    pub(super) built_machine: TaskHandle<MachineCmd>,
    pub(super) queue: BufferWriter<QueueItem>,
    pub(super) motion_cfg: motion::MotionConfig,
    pub(super) sim_io: Vec<Option<hytask_hal::sim::SimIoHandle>>,
    sim_axes: Vec<(char, hytask_hal::sim::SimAxisHandle)>,
    pub(super) snap: DataReader<MachineSnapshot>,
    pub(super) sp: DataReader<Setpoints>,
    fb: Vec<DataReader<AxisFeedback>>,
    /// The machine task's `job` events.
    pub(super) jobs: EventReceiver<JobNews>,
    /// E-stop requests to the machine task (what `Machine::estop` increments).
    pub(super) estop_request: Arc<std::sync::atomic::AtomicU32>,
}

impl Rig {
    pub(super) fn new() -> Rig {
        Rig::with_config(&Rig::config())
    }

    /// The fast-homing simulated mill of the end-to-end tests.
    pub(super) fn config() -> crate::config::MachineConfig {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
        crate::config::load(&path).expect("config")
    }

    pub(super) fn with_config(cfg: &crate::config::MachineConfig) -> Rig {
        let Built {
            mut app,
            machine,
            queue,
            motion_cfg,
            sim_io,
            sim_axes,
            estop_request,
            ..
        } = build(cfg).expect("build");
        app.configure().expect("topology");
        let jobs = app
            .event::<JobNews>("machine.job")
            .expect("job event")
            .subscribe(1024);
        let rt = app.start_stepped(SimClock::new(0)).expect("start");
        let snap = rt.reader(ports::SNAPSHOT).expect("snapshot");
        let sp = rt.reader(ports::SETPOINTS).expect("setpoints");
        let fb = ['X', 'Y', 'Z']
            .iter()
            .map(|&c| rt.reader(&ports::feedback(c)).expect("feedback"))
            .collect();
        Rig {
            rt,
            built_machine: machine,
            queue,
            motion_cfg,
            sim_io,
            sim_axes,
            snap,
            sp,
            fb,
            jobs,
            estop_request,
        }
    }

    pub(super) fn send_until_done(&mut self, cmd: MachineCmd, max_cycles: u64) {
        let h = self.built_machine.send(cmd).expect("queue");
        for _ in 0..max_cycles {
            self.rt.run_cycles(1);
            match h.status() {
                CommandStatus::Done => return,
                CommandStatus::Pending | CommandStatus::Accepted => {}
                other => panic!("{cmd:?}: {other:?}"),
            }
        }
        panic!("{cmd:?} not done after {max_cycles} cycles");
    }

    /// Fault-injection handle of a simulated drive.
    pub(super) fn sim_axis(&self, axis: char) -> hytask_hal::sim::SimAxisHandle {
        self.sim_axes
            .iter()
            .find(|(c, _)| *c == axis)
            .expect("axis")
            .1
            .clone()
    }

    pub(super) fn mode(&mut self) -> Mode {
        self.snap.latest().expect("snapshot").mode
    }

    pub(super) fn feedback(&mut self, axis: usize) -> AxisFeedback {
        self.fb[axis].latest().expect("feedback")
    }

    pub(super) fn ready(&mut self) {
        self.send_until_done(MachineCmd::EstopReset, 10);
        self.send_until_done(MachineCmd::On, 100);
        self.send_until_done(MachineCmd::Home { mask: 0 }, 20_000);
        assert_eq!(self.mode(), Mode::Idle);
    }

    /// Where the machine is: X Y Z from the drives' feedback, the other axes at 0.
    pub(super) fn position(&mut self) -> [f64; NUM_AXES] {
        let mut at = [0.0; NUM_AXES];
        for (i, s) in at.iter_mut().take(3).enumerate() {
            *s = self.feedback(i).actual;
        }
        at
    }

    /// Queues `plan`'s items as job `job`; returns the handle of the `Run` that starts it.
    pub(super) fn run_plan(&mut self, job: u32, plan: &motion::Plan) -> CommandHandle {
        for &item in &plan.items {
            self.queue
                .try_push(QueueItem { job, item })
                .expect("queue room");
        }
        self.built_machine
            .send(MachineCmd::Run {
                job,
                items: plan.items.len() as u64,
                manual: false,
            })
            .expect("queue")
    }

    /// Plans a straight feed from where the machine is to `target` and starts it as `job`.
    pub(super) fn start_move(&mut self, job: u32, target: [f64; 3], feed_mm_min: f64) {
        let start = self.position();
        let mut end = start;
        end[..3].copy_from_slice(&target);
        let loc = SourceLoc {
            file: Arc::from("test"),
            line: 7,
            col: 1,
        };
        let plan = motion::plan_straight_feed(start, end, feed_mm_min, loc, &self.motion_cfg)
            .expect("plan");
        let h = self.run_plan(job, &plan);
        self.rt.run_cycles(1);
        assert_eq!(h.status(), CommandStatus::Accepted);
    }

    /// Runs `n` cycles recording the commanded joints of X Y Z while motion is commanded
    /// (once the interpolator tracks the actual position again, the drives are off or at
    /// rest and the commanded position is reset to the actual one: not a motion).
    fn record(&mut self, n: usize) -> Vec<[f64; 3]> {
        let mut trace = Vec::new();
        for _ in 0..n {
            self.rt.run_cycles(1);
            let sp = self.sp.latest().expect("setpoints");
            if !sp.tracking {
                trace.push([sp.joints[0], sp.joints[1], sp.joints[2]]);
            }
        }
        trace
    }
}

/// Largest |acceleration| per axis along a commanded trace sampled every `dt`.
fn peak_acc(trace: &[[f64; 3]], dt: f64) -> [f64; 3] {
    let mut peak = [0.0f64; 3];
    for w in trace.windows(3) {
        for i in 0..3 {
            let a = (w[2][i] - 2.0 * w[1][i] + w[0][i]) / (dt * dt);
            peak[i] = peak[i].max(a.abs());
        }
    }
    peak
}

#[test]
fn estop_input_quick_stops_every_drive_in_the_same_cycle() {
    let mut r = Rig::new();
    r.ready();
    r.start_move(1, [250.0, 200.0, -20.0], 3000.0);
    r.rt.run_cycles(600);
    assert!(
        r.feedback(0).velocity.abs() > 1.0,
        "moving before the e-stop"
    );
    let estop = r.sim_io[0].as_ref().expect("sim io");
    estop.set_digital_input(0, true).expect("input");
    r.rt.run_cycles(1);
    assert_eq!(r.mode(), Mode::Estop);
    for axis in 0..3 {
        let fb = r.feedback(axis);
        assert_ne!(
            fb.state,
            DriveState::OperationEnabled,
            "axis {axis} still enabled one cycle after the e-stop input"
        );
    }
    // The drives brake on their quick-stop ramp and end disabled; the outputs are safe.
    r.rt.run_cycles(300);
    for axis in 0..3 {
        let fb = r.feedback(axis);
        assert!(fb.velocity.abs() < 1e-9, "axis {axis}: {fb:?}");
        assert_eq!(fb.state, DriveState::SwitchOnDisabled, "axis {axis}");
    }
}

#[test]
fn an_abort_stops_on_the_path_within_the_acceleration_limits() {
    let mut r = Rig::new();
    r.ready();
    r.start_move(1, [250.0, 200.0, -20.0], 6000.0);
    let mut trace = r.record(700);
    let h = r.built_machine.send(MachineCmd::Abort).expect("queue");
    trace.extend(r.record(1500));
    assert_eq!(h.status(), CommandStatus::Done);
    assert_eq!(r.mode(), Mode::Idle);
    let sp = r.sp.latest().expect("setpoints");
    assert!(sp.tracking || sp.state == InterpState::Idle);
    let lim = r.motion_cfg.axes;
    let peak = peak_acc(&trace, 1e-3);
    for i in 0..3 {
        assert!(
            peak[i] <= lim[i].max_acc_mm_s2 * 1.001,
            "axis {i}: {} > {}",
            peak[i],
            lim[i].max_acc_mm_s2
        );
    }
    // Stopped short of the target (X runs from 300 down to 250), on the line.
    let last = trace.last().expect("trace");
    assert!(last[0] > 251.0, "{last:?}");
    let along = (300.0 - last[0]) / 50.0;
    assert!((last[1] - (300.0 - 100.0 * along)).abs() < 0.01, "{last:?}");
}

#[test]
fn a_following_error_fault_stops_the_other_axes_under_control_and_disables_the_drives() {
    let mut r = Rig::new();
    r.ready();
    r.start_move(1, [100.0, 100.0, -30.0], 6000.0);
    let mut trace = r.record(400);
    let x = r
        .sim_axes
        .iter()
        .find(|(c, _)| *c == 'X')
        .expect("X")
        .1
        .clone();
    x.set_stalled(true);
    trace.extend(r.record(3000));
    let snap = r.snap.latest().expect("snapshot");
    assert_eq!(snap.mode, Mode::Fault);
    assert!(
        matches!(
            snap.last_trip,
            Some(crate::machine::safety::Trip::FollowingError { axis: 0, .. })
        ),
        "{:?}",
        snap.last_trip
    );
    let lim = r.motion_cfg.axes;
    let peak = peak_acc(&trace, 1e-3);
    for i in 0..3 {
        assert!(
            peak[i] <= lim[i].max_acc_mm_s2 * 1.001,
            "axis {i}: {}",
            peak[i]
        );
    }
    for axis in 0..3 {
        assert!(
            !r.feedback(axis).state.is_operational(),
            "axis {axis} still enabled"
        );
    }
}

#[test]
fn single_block_holds_in_the_cycle_the_next_line_begins() {
    let mut r = Rig::new();
    r.ready();
    let start = r.position();
    // Three lines of a zigzag, 10 mm along -X each, blended.
    let canon: Vec<Canon> = (0..4)
        .map(|k| {
            let loc = SourceLoc {
                file: Arc::from("t"),
                line: 10 + k,
                col: 1,
            };
            let cmd = if k == 0 {
                CanonCmd::SetFeedRate(1200.0)
            } else {
                let mut p = start;
                p[0] -= 10.0 * f64::from(k);
                p[1] -= if k % 2 == 1 { 5.0 } else { 0.0 };
                CanonCmd::StraightFeed(p)
            };
            Canon { loc, cmd }
        })
        .collect();
    let plan = motion::plan_from(&canon, &r.motion_cfg, start).expect("plan");
    let run = r.run_plan(1, &plan);
    r.rt.run_cycles(100);
    assert_eq!(r.sp.latest().expect("sp").line, 11);
    // Step while running line 11: it holds as line 12 begins.
    r.send_until_done(MachineCmd::Step, 10);
    let mut held_line = None;
    for _ in 0..5000 {
        r.rt.run_cycles(1);
        let sp = r.sp.latest().expect("sp");
        if r.mode() == Mode::Holding {
            held_line.get_or_insert(sp.line);
        }
        if sp.state == InterpState::Holding {
            break;
        }
    }
    assert_eq!(held_line, Some(12), "held as line 12 began");
    let x_held = r.sp.latest().expect("sp").pose_mm[0];
    assert!(
        x_held < start[0] - 10.0 && x_held > start[0] - 20.0,
        "{x_held}"
    );
    r.rt.run_cycles(200);
    assert_eq!(r.sp.latest().expect("sp").pose_mm[0], x_held, "stays held");
    // Step from the hold: resumes, holds again when line 13 begins.
    r.send_until_done(MachineCmd::Step, 10);
    for _ in 0..5000 {
        r.rt.run_cycles(1);
        if r.sp.latest().expect("sp").state == InterpState::Holding {
            break;
        }
    }
    assert_eq!(r.mode(), Mode::Holding);
    assert_eq!(r.sp.latest().expect("sp").line, 13);
    // Resume runs to the end.
    r.send_until_done(MachineCmd::Resume, 10);
    for _ in 0..10_000 {
        r.rt.run_cycles(1);
        if run.status() == CommandStatus::Done {
            break;
        }
    }
    assert_eq!(run.status(), CommandStatus::Done);
    assert!((r.feedback(0).actual - (start[0] - 30.0)).abs() < 0.01);
}

#[test]
fn a_feed_hold_holds_the_job_and_resume_runs_it_again() {
    let mut r = Rig::new();
    r.ready();
    r.start_move(1, [250.0, 200.0, -20.0], 3000.0);
    r.rt.run_cycles(300);
    let mut events = Vec::new();
    while let Some(n) = r.jobs.pop() {
        events.push(n.event);
    }
    assert_eq!(events, [JobEvent::Started]);
    r.send_until_done(MachineCmd::Pause, 2000);
    assert_eq!(r.mode(), Mode::Holding);
    // A second pause while held is no second hold.
    r.send_until_done(MachineCmd::Pause, 10);
    r.send_until_done(MachineCmd::Resume, 10);
    while let Some(n) = r.jobs.pop() {
        events.push(n.event);
    }
    assert_eq!(
        events,
        [
            JobEvent::Started,
            JobEvent::Held { line: 7 },
            JobEvent::Resumed
        ]
    );
}
