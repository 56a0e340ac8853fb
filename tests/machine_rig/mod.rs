//! The machine on the stepped runtime, homed and idle, for the zero-allocation tests of the
//! servo cycle (sim, PLC and CANopen variants): one copy of the build, homing and job
//! queueing they all need.
#![allow(dead_code, clippy::unwrap_used)]

use hytask::config::MachineConfig;
use hytask::gcode::{Canon, CanonCmd, SourceLoc, NUM_AXES};
use hytask::machine::runtime::{build, Built};
use hytask::machine::servo::machine_task::MachineCmd;
use hytask::machine::servo::{ports, AxisFeedback, QueueItem};
use hytask::rt::deploy::{Deployment, SteppedRuntime};
use hytask::rt::prelude::*;
use std::sync::Arc;

/// Steps `rt` until command `h` is done (at most `max` cycles).
pub fn until_done(rt: &mut SteppedRuntime, h: &CommandHandle, max: u64) {
    for _ in 0..max {
        rt.run_cycles(1);
        if h.status() == CommandStatus::Done {
            return;
        }
    }
    panic!("not done: {:?}", h.status());
}

/// The machine, homed and idle.
pub struct Homed {
    pub rt: SteppedRuntime,
    pub machine: TaskHandle<MachineCmd>,
    pub queue: BufferWriter<QueueItem>,
    pub motion_cfg: hytask::motion::MotionConfig,
    pub sim_io: Vec<Option<hytask_hal::sim::SimIoHandle>>,
    pub fb: Vec<DataReader<AxisFeedback>>,
    /// Where the axes are after homing.
    pub start: [f64; NUM_AXES],
}

/// Builds `cfg` on the stepped runtime, lets `inspect` look at the configured deployment
/// (task order), then resets the e-stop, switches on and homes every axis.
pub fn homed_with(cfg: &MachineConfig, inspect: impl FnOnce(&Deployment)) -> Homed {
    let Built {
        mut app,
        machine,
        queue,
        motion_cfg,
        sim_io,
        ..
    } = build(cfg).unwrap();
    app.configure().unwrap();
    inspect(&app);
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    let mut fb: Vec<DataReader<AxisFeedback>> = ['X', 'Y', 'Z']
        .iter()
        .map(|&c| rt.reader(&ports::feedback(c)).unwrap())
        .collect();
    for cmd in [
        MachineCmd::EstopReset,
        MachineCmd::On,
        MachineCmd::Home { mask: 0 },
    ] {
        let h = machine.send(cmd).unwrap();
        until_done(&mut rt, &h, 40_000);
    }
    let mut start = [0.0; NUM_AXES];
    for (i, s) in start.iter_mut().take(3).enumerate() {
        *s = fb[i].latest().unwrap().actual;
    }
    Homed {
        rt,
        machine,
        queue,
        motion_cfg,
        sim_io,
        fb,
        start,
    }
}

/// [`homed_with`] without a look at the deployment.
pub fn homed(cfg: &MachineConfig) -> Homed {
    homed_with(cfg, |_| {})
}

impl Homed {
    /// Plans `cmds` (all on line 1) from `from`, queues the items as job `job` and returns
    /// the `Run` command that starts it.
    pub fn queue_job(&self, job: u32, from: [f64; NUM_AXES], cmds: &[CanonCmd]) -> MachineCmd {
        let loc = SourceLoc {
            file: Arc::from("t"),
            line: 1,
            col: 1,
        };
        let canon: Vec<Canon> = cmds
            .iter()
            .map(|cmd| Canon {
                loc: loc.clone(),
                cmd: cmd.clone(),
            })
            .collect();
        let plan = hytask::motion::plan_from(&canon, &self.motion_cfg, from).unwrap();
        for &item in &plan.items {
            self.queue.try_push(QueueItem { job, item }).unwrap();
        }
        MachineCmd::Run {
            job,
            items: plan.items.len() as u64,
            manual: false,
        }
    }
}

/// Plans the next piece of live job 1 from where the machine stopped (`stopped_mm`, after a
/// probe trip or an M66 answer) and queues it, off the realtime path, as the piece runner
/// does. Returns the `Continue` command that releases it.
pub fn queue_next_piece(
    queue: &BufferWriter<QueueItem>,
    motion_cfg: &hytask::motion::MotionConfig,
    canon: &[Canon],
    stopped_mm: [f64; NUM_AXES],
    state: hytask::motion::from_canon::FoldState,
) -> MachineCmd {
    let next = hytask::motion::plan_continue(canon, motion_cfg, stopped_mm, state).unwrap();
    for &item in &next.items {
        queue.try_push(QueueItem { job: 1, item }).unwrap();
    }
    MachineCmd::Continue {
        job: 1,
        items: next.items.len() as u64,
    }
}
