//! The `machine` task: the machine state machine on the servo thread.
//!
//! It serves the operator's commands (each accepted or rejected by [`ModeMachine`] with a
//! reason, then completed by its completion condition), and every cycle:
//! 1. reads the e-stop input: pressed (or unreadable) → e-stop in this very cycle: drives
//!    quick-stop, outputs go to their configured safe state, motion is dropped;
//! 2. executes the auxiliary command the interpolator reached (spindle, coolant, tool,
//!    I/O, M0/M1, M66 waits, messages) and tells the interpolator when a barrier is done;
//! 3. sequences homing group by group, in the configured order;
//! 4. finishes jobs, aborts and controlled stops, and disables the drives when a stop
//!    that asked for it has come to rest.
//!
//! Faults come from the monitor as `monitor.fault` events and overrun storms as the
//! thread's overrun event; both are handled at this task's safe point (deferred handlers,
//! step 6), so a fault found in cycle n starts the controlled stop in cycle n + 1.

use super::input_wait::InputWait;
use super::plc_link::PlcLink;
use super::{
    AxisFeedback, DriveControl, FaultEvent, Inputs, JobError, JobEvent, JobNews, MachineSnapshot,
    ModeEvent, MonitorSnapshot, MotionControl, Outputs, Setpoints,
};
use crate::gcode::canon::SpindleDir;
use crate::gcode::NUM_AXES;
use crate::machine::api::Mode;
use crate::machine::mode::{Fact, ModeMachine};
use crate::machine::safety::Trip;
use crate::motion::InterpState;
use crate::rt::prelude::*;

/// Fixed facts about the machine the task needs.
#[derive(Debug, Clone)]
pub struct MachineSetup {
    /// Axis letters in configuration order (`'X'`...), with their pose index.
    pub axes: Vec<(char, usize)>,
    /// Homing groups, in order, as pose-index masks.
    pub homing_groups: Vec<u32>,
    /// Machine-wide digital input index of the e-stop.
    pub estop_input: usize,
    /// Machine-wide digital input index of the probe (G38.x), if the machine has one.
    pub probe_input: Option<usize>,
    /// Spindle outputs (digital enable, digital direction, analog speed) and at-speed input.
    pub spindle: Option<SpindleIo>,
    /// Coolant outputs.
    pub flood_output: Option<usize>,
    /// Mist output.
    pub mist_output: Option<usize>,
    /// Every output in its configured safe state (e-stop, machine off, start-up).
    pub safe_outputs: Outputs,
    /// Highest feed override.
    pub max_feed_override: f64,
    /// Cycles an e-stop input may stay unreadable before it counts as pressed.
    pub max_stale_io_cycles: u32,
    /// Cycles allowed for drives to enable or disable.
    pub enable_timeout_cycles: u32,
    /// Cycles allowed for the spindle to reach speed.
    pub spindle_timeout_cycles: u32,
    /// Name of the servo thread's overrun-storm event.
    pub overrun_event: String,
    /// Servo period, s (turns M66 timeouts into cycles).
    pub period_s: f64,
    /// A job is done when every |following error| is within this window (mm)...
    pub in_position_window: f64,
    /// ... or after this many cycles of settling.
    pub settle_timeout_cycles: u32,
}

/// Spindle I/O, as machine-wide indices.
#[derive(Debug, Clone, Copy)]
pub struct SpindleIo {
    /// Enable output.
    pub enable: usize,
    /// Direction output (on = counter-clockwise).
    pub direction: Option<usize>,
    /// Speed reference output (rpm).
    pub speed: Option<usize>,
    /// At-speed input.
    pub at_speed: Option<usize>,
    /// Largest speed.
    pub max_rpm: f64,
}

/// A barrier the interpolator waits on while the machine carries it out.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Barrier {
    None,
    /// M3/M4 waits for the spindle to reach speed.
    SpindleAtSpeed {
        since: u64,
    },
    /// M66 waits for an input.
    Wait(InputWait),
    /// M0 (or M1 with optional stop on): held until `resume`.
    ProgramStop,
    /// The end of a probe move, or an M66 that answered a live job: held until the next
    /// piece of the program is queued.
    Probe,
    /// M6 or M100–M199 handled by the PLC: held until it answers request `seq`.
    Plc {
        seq: u32,
        mcode: u32,
        tool: u32,
        deadline: u64,
    },
}

/// What the current motion is, and how it should end.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    None,
    Job { job: u32, items: u64 },
}

/// The machine task.
pub struct MachineTask {
    setup: MachineSetup,
    mode: ModeMachine,
    // ports
    inputs_in: Option<DataReader<Inputs>>,
    setpoints_in: Option<DataReader<Setpoints>>,
    feedback_in: Vec<DataReader<AxisFeedback>>,
    monitor_in: Option<DataReader<MonitorSnapshot>>,
    outputs_out: Option<DataWriter<Outputs>>,
    drive_out: Option<DataWriter<DriveControl>>,
    motion_out: Option<DataWriter<MotionControl>>,
    snapshot_out: Option<DataWriter<MachineSnapshot>>,
    faults_in: Option<EventReceiver<FaultEvent>>,
    overruns_in: Option<EventReceiver<Overrun>>,
    mode_ev: Option<EventSource<ModeEvent>>,
    job_ev: Option<EventSource<JobNews>>,
    fault_ev: Option<EventSource<FaultEvent>>,
    // working copies
    inputs: Inputs,
    monitor: MonitorSnapshot,
    setpoints: Setpoints,
    feedback: [AxisFeedback; NUM_AXES],
    outputs: Outputs,
    drive: DriveControl,
    motion: MotionControl,
    snap: MachineSnapshot,
    cycle: u64,
    last_aux_seq: u32,
    barrier: Barrier,
    current: Motion,
    /// A stop was requested; when motion has come to rest: disable drives (if set), emit
    /// the end event.
    stopping: Option<Stopping>,
    homing_group: Option<usize>,
    homing_mask: u32,
    enable_since: u64,
    last_mode: Mode,
    spindle_dir: Option<SpindleDir>,
    spindle_rpm: f64,
    /// Errors of spindle-synchronised moves, seen once each.
    sync_errors: super::spindle_follow::SyncErrors,
    /// The spindle direction output is reversed (a rigid tap coming out).
    spindle_reversed: bool,
    /// Cycle at which the path of the current job was complete (settling since).
    settle_since: Option<u64>,
    /// Job id of the current or last motion, and how it ended.
    job_id: u32,
    ended: Option<(u32, JobEvent)>,
    /// Single block in progress: the line the step began on (0 until motion shows one).
    step_from: Option<u32>,
    /// A step from a program stop: the stop's line, which does not count as the step's line.
    step_skip: u32,
    /// E-stop requests from the non-realtime side, counted: read every cycle, outside the
    /// command queue, so that an e-stop is taken even when every command slot is busy.
    estop_request: Option<std::sync::Arc<std::sync::atomic::AtomicU32>>,
    estop_seen: u32,
    /// The PLC, when `[plc]` is configured.
    plc: Option<PlcLink>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Stopping {
    abort_seq: u32,
    disable: bool,
    end: Option<JobEvent>,
}

impl MachineTask {
    /// A machine task for `setup`; it starts in e-stop.
    pub fn new(setup: MachineSetup) -> Self {
        let motion = MotionControl::default();
        MachineTask {
            mode: ModeMachine::new(),
            inputs_in: None,
            setpoints_in: None,
            feedback_in: Vec::new(),
            monitor_in: None,
            outputs_out: None,
            drive_out: None,
            motion_out: None,
            snapshot_out: None,
            faults_in: None,
            overruns_in: None,
            mode_ev: None,
            job_ev: None,
            fault_ev: None,
            inputs: Inputs::default(),
            monitor: MonitorSnapshot::default(),
            setpoints: Setpoints::default(),
            feedback: [AxisFeedback::default(); NUM_AXES],
            outputs: setup.safe_outputs,
            drive: DriveControl::default(),
            motion,
            snap: MachineSnapshot::default(),
            cycle: 0,
            last_aux_seq: 0,
            barrier: Barrier::None,
            current: Motion::None,
            stopping: None,
            homing_group: None,
            homing_mask: 0,
            enable_since: 0,
            last_mode: Mode::Estop,
            spindle_dir: None,
            spindle_rpm: 0.0,
            sync_errors: Default::default(),
            spindle_reversed: false,
            settle_since: None,
            job_id: 0,
            ended: None,
            step_from: None,
            step_skip: 0,
            estop_request: None,
            estop_seen: 0,
            plc: None,
            setup,
        }
    }

    /// Takes e-stop requests from `counter` (each increment is one request), read every
    /// cycle: the command queue serves a few commands at a time and may be busy.
    pub fn with_estop_request(
        mut self,
        counter: std::sync::Arc<std::sync::atomic::AtomicU32>,
    ) -> Self {
        self.estop_seen = counter.load(std::sync::atomic::Ordering::Acquire);
        self.estop_request = Some(counter);
        self
    }

    fn all_homed(&self) -> bool {
        self.setup.axes.iter().all(|&(_, i)| self.feedback[i].homed)
    }

    /// Homed axes as of this cycle's feedback.
    fn homed_mask(&self) -> u32 {
        self.setup
            .axes
            .iter()
            .filter(|&&(_, i)| self.feedback[i].homed)
            .fold(0, |m, &(_, i)| m | 1 << i)
    }

    fn axes_mask(&self) -> u32 {
        self.setup.axes.iter().fold(0, |m, &(_, i)| m | 1 << i)
    }

    fn emit_job(&mut self, e: JobEvent) {
        if matches!(
            e,
            JobEvent::Finished { .. }
                | JobEvent::Aborted { .. }
                | JobEvent::Failed { .. }
                | JobEvent::Error { .. }
        ) {
            self.ended = Some((self.job_id, e));
        }
        if let Some(ev) = &mut self.job_ev {
            ev.emit(JobNews {
                job: self.job_id,
                event: e,
                cycle: self.cycle,
            });
        }
    }

    /// Motion at rest after the stop with `abort_seq`.
    fn stopped(&self, abort_seq: u32) -> bool {
        self.setpoints.abort_ack == abort_seq
            && matches!(self.setpoints.state, InterpState::Idle | InterpState::Done)
            || self.setpoints.tracking
    }

    /// Starts a controlled stop of whatever moves; `disable` drives once at rest.
    fn controlled_stop(&mut self, disable: bool, end: Option<JobEvent>) {
        self.motion.abort_seq = self.motion.abort_seq.wrapping_add(1);
        self.motion.hold = false;
        self.barrier = Barrier::None;
        self.homing_group = None;
        self.stopping = Some(Stopping {
            abort_seq: self.motion.abort_seq,
            disable,
            end,
        });
    }

    /// Reports a trip the machine acts on (event `machine.fault`).
    fn report(&mut self, trip: Trip, line: u32) {
        self.snap.last_trip = Some(trip);
        self.snap.trips = self.snap.trips.wrapping_add(1);
        if let Some(ev) = &mut self.fault_ev {
            ev.emit(FaultEvent { trip, line });
        }
    }

    /// E-stop: in this very cycle.
    fn enter_estop(&mut self, trip: Trip) {
        let line = self.setpoints.line;
        self.report(trip, line);
        let was_moving = self.current != Motion::None;
        self.mode.fact(Fact::EstopInput);
        self.drive.enable = false;
        self.drive.quick_stop = true;
        self.drive.home_abort_seq = self.drive.home_abort_seq.wrapping_add(1);
        self.motion.track_actual = true;
        self.motion.abort_seq = self.motion.abort_seq.wrapping_add(1);
        self.motion.hold = false;
        self.outputs_safe();
        self.barrier = Barrier::None;
        self.homing_group = None;
        self.stopping = None;
        self.current = Motion::None;
        if was_moving {
            self.emit_job(JobEvent::Failed { line, trip });
        }
    }

    fn on_trip(&mut self, trip: Trip, line: u32) {
        match self.mode.mode() {
            Mode::Estop | Mode::Off => {
                // Nothing moves to stop, but a fieldbus fault (EMCY, drive fault, heartbeat
                // loss, bus failure) is still reported: the operator learns of it now, not
                // from a refused machine-on.
                if matches!(trip, Trip::Fieldbus { .. }) {
                    self.report(trip, line);
                }
                return;
            }
            Mode::Fault if self.stopping.is_some() => return,
            _ => {}
        }
        self.report(trip, line);
        let end = (self.current != Motion::None).then_some(JobEvent::Failed { line, trip });
        self.current = Motion::None;
        self.mode.fact(Fact::Faulted);
        self.spindle_and_coolant_off();
        self.drive.home_abort_seq = self.drive.home_abort_seq.wrapping_add(1);
        self.controlled_stop(true, end);
    }

    /// Ends the job with a program error: stop under control, drives stay enabled.
    /// Spindle and coolant go off, as on an abort (LinuxCNC aborts on a program error).
    fn job_error(&mut self, error: JobError, line: u32) {
        self.spindle_and_coolant_off();
        self.current = Motion::None;
        self.snap.probe.waiting = false;
        self.controlled_stop(false, Some(JobEvent::Error { line, error }));
    }
}

mod aux;
mod commands;
mod plc;
mod sequencing;
mod spindle_sync;
mod task_hooks;

pub use commands::MachineCmd;
