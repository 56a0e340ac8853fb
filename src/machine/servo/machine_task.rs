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

use super::plc_link::{PlcLink, PlcLinkSetup};
use super::{
    ports, AxisFeedback, DriveControl, FaultEvent, Inputs, JobError, JobEvent, JobNews,
    MachineSnapshot, ModeEvent, MonitorSnapshot, MotionControl, Outputs, Setpoints,
};
use crate::gcode::canon::{InputKind, SpindleDir, WaitKind};
use crate::gcode::NUM_AXES;
use crate::machine::api::Mode;
use crate::machine::mode::{Fact, ModeMachine, Request};
use crate::machine::safety::Trip;
use crate::motion::{AuxKind, InterpState};
use crate::plc::link::RequestKind;
use crate::rt::prelude::*;

/// The machine's operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MachineCmd {
    /// Trip the e-stop.
    Estop,
    /// Release the e-stop.
    EstopReset,
    /// Enable the drives.
    On,
    /// Stop, then disable the drives.
    Off,
    /// Home the axes in `mask` (bit i = axis i of the pose; 0 = every axis).
    Home {
        /// Axes to home.
        mask: u32,
    },
    /// Run queued job `job` of `items` queue items (jog and MDI are jobs too).
    Run {
        /// Job id stamped on its queue items.
        job: u32,
        /// Queue items of the job.
        items: u64,
        /// Manual (jog) rather than automatic (job, MDI).
        manual: bool,
    },
    /// Feed hold.
    Pause,
    /// Resume after a hold or an M0.
    Resume,
    /// Controlled stop; the rest of the job is dropped.
    Abort,
    /// Single block: run to the end of the current source line, then hold (resuming first
    /// if held). Watched in the servo cycle: the hold starts in the cycle the next line
    /// begins.
    Step,
    /// The next piece of a probing job (interpreted with the probe's result) is queued:
    /// `items` more queue items for job `job`, which waits at the end of its probe move.
    Continue {
        /// Job id.
        job: u32,
        /// Queue items added.
        items: u64,
    },
    /// Optional stop on or off: whether M1 stops the job (M0 always does).
    OptionalStop {
        /// On: M1 holds like M0.
        on: bool,
    },
    /// Overrides (fractions).
    Overrides {
        /// Feed, 0..=max.
        feed: f64,
        /// Rapid, 0..=1.
        rapid: f64,
        /// Spindle, 0..=2.
        spindle: f64,
    },
}

const NO_PARAMS: &[ParamDescriptor] = &[];

static OPERATIONS: [OperationDescriptor; 13] = [
    OperationDescriptor {
        name: "estop",
        doc: "Trip the e-stop: every drive quick-stops this cycle, outputs go safe.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "estop_reset",
        doc: "Release the e-stop (refused while the e-stop input is active).",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "machine_on",
        doc: "Enable the drives; done when every drive is operational.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "machine_off",
        doc: "Every output to its safe state, stop under control, then disable the drives.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "home",
        doc: "Home the axes in the bit mask (0 = all), group by group; done when homed.",
        params: &[ParamDescriptor {
            name: "axis_mask",
            ty: ArgType::Int,
        }],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "run",
        doc: "Run queued job `job` of `items` items; done at its end.",
        params: &[
            ParamDescriptor {
                name: "job",
                ty: ArgType::Int,
            },
            ParamDescriptor {
                name: "items",
                ty: ArgType::Int,
            },
            ParamDescriptor {
                name: "manual",
                ty: ArgType::Bool,
            },
        ],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "pause",
        doc: "Feed hold; done when motion has stopped on the path.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "resume",
        doc: "Resume after a feed hold or M0.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "abort",
        doc: "Controlled stop within the axis limits, spindle and coolant off (not for a \
              jog); the rest of the job is dropped.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "set_overrides",
        doc: "Feed (0..max), rapid (0..1) and spindle (0..2) overrides.",
        params: &[
            ParamDescriptor {
                name: "feed",
                ty: ArgType::Float,
            },
            ParamDescriptor {
                name: "rapid",
                ty: ArgType::Float,
            },
            ParamDescriptor {
                name: "spindle",
                ty: ArgType::Float,
            },
        ],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "step",
        doc: "Run to the end of the current source line, then hold (resumes a hold first).",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "continue",
        doc: "Job `job` waits after a probe move: `items` more queue items (the next piece \
              of the program, interpreted with the probe's result) are queued.",
        params: &[
            ParamDescriptor {
                name: "job",
                ty: ArgType::Int,
            },
            ParamDescriptor {
                name: "items",
                ty: ArgType::Int,
            },
        ],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "set_optional_stop",
        doc: "Optional stop on or off: whether M1 holds the job as M0 does (off at start).",
        params: &[ParamDescriptor {
            name: "on",
            ty: ArgType::Bool,
        }],
        next: NextCommand::AfterAcceptance,
    },
];

impl Commands for MachineCmd {
    fn operations() -> &'static [OperationDescriptor] {
        &OPERATIONS
    }

    fn operation_index(&self) -> usize {
        match self {
            MachineCmd::Estop => 0,
            MachineCmd::EstopReset => 1,
            MachineCmd::On => 2,
            MachineCmd::Off => 3,
            MachineCmd::Home { .. } => 4,
            MachineCmd::Run { .. } => 5,
            MachineCmd::Pause => 6,
            MachineCmd::Resume => 7,
            MachineCmd::Abort => 8,
            MachineCmd::Overrides { .. } => 9,
            MachineCmd::Step => 10,
            MachineCmd::Continue { .. } => 11,
            MachineCmd::OptionalStop { .. } => 12,
        }
    }

    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), operation, args)?;
        Ok(match a.operation() {
            "estop" => MachineCmd::Estop,
            "estop_reset" => MachineCmd::EstopReset,
            "machine_on" => MachineCmd::On,
            "machine_off" => MachineCmd::Off,
            "home" => MachineCmd::Home {
                mask: a.int(0)? as u32,
            },
            "run" => MachineCmd::Run {
                job: a.int(0)? as u32,
                items: a.int(1)?.max(0) as u64,
                manual: a.bool(2)?,
            },
            "pause" => MachineCmd::Pause,
            "resume" => MachineCmd::Resume,
            "abort" => MachineCmd::Abort,
            "step" => MachineCmd::Step,
            "set_optional_stop" => MachineCmd::OptionalStop { on: a.bool(0)? },
            "continue" => MachineCmd::Continue {
                job: a.int(0)? as u32,
                items: a.int(1)?.max(0) as u64,
            },
            _ => MachineCmd::Overrides {
                feed: a.float(0)?,
                rapid: a.float(1)?,
                spindle: a.float(2)?,
            },
        })
    }
}

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
    Wait {
        index: u32,
        input: InputKind,
        kind: WaitKind,
        deadline: u64,
        last: bool,
    },
    /// M0 (or M1 with optional stop on): held until `resume`.
    ProgramStop,
    /// The end of a probe move: held until the next piece of the program is queued.
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

    /// Every output to its configured safe state, the spindle's commanded state with them
    /// (e-stop, machine off).
    fn outputs_safe(&mut self) {
        self.outputs = self.setup.safe_outputs;
        self.spindle_dir = None;
        self.snap.spindle_rpm = 0.0;
    }

    /// What LinuxCNC's task abort does besides stopping motion (its spindle abort, and the
    /// coolant off of its I/O abort): spindle and coolant off. The other outputs a program
    /// set (M62–M68) keep their state, as they do there.
    fn spindle_and_coolant_off(&mut self) {
        self.spindle_stop();
        self.coolant(self.setup.flood_output, self.setup.mist_output, false);
    }

    fn spindle_stop(&mut self) {
        self.spindle_dir = None;
        self.apply_spindle();
    }

    fn apply_spindle(&mut self) {
        let Some(sp) = self.setup.spindle else {
            return;
        };
        let rpm = (self.spindle_rpm * self.snap.spindle_override).clamp(0.0, sp.max_rpm);
        self.outputs.set_do(sp.enable, self.spindle_dir.is_some());
        if let Some(d) = sp.direction {
            self.outputs.set_do(
                d,
                (self.spindle_dir == Some(SpindleDir::CounterClockwise)) != self.spindle_reversed,
            );
        }
        if let Some(s) = sp.speed {
            if s < self.outputs.analog.len() {
                self.outputs.analog[s] = if self.spindle_dir.is_some() { rpm } else { 0.0 };
            }
        }
        self.snap.spindle_rpm = match self.spindle_dir {
            Some(SpindleDir::Clockwise) => rpm,
            Some(SpindleDir::CounterClockwise) => -rpm,
            None => 0.0,
        };
    }

    /// Runs an aux item the interpolator reached. Barriers hold the interpolator until
    /// `motion.aux_done_seq` moves on.
    fn run_aux(&mut self, kind: AuxKind, line: u32) {
        let mut done = true;
        match kind {
            AuxKind::SpindleSpeed { rpm } => {
                self.spindle_rpm = rpm;
                self.apply_spindle();
            }
            AuxKind::SpindleStart(dir) => {
                self.spindle_dir = Some(dir);
                self.apply_spindle();
                if self.setup.spindle.and_then(|s| s.at_speed).is_some() {
                    self.barrier = Barrier::SpindleAtSpeed { since: self.cycle };
                    done = false;
                }
            }
            AuxKind::SpindleStop => self.spindle_stop(),
            AuxKind::Flood(on) => self.coolant(self.setup.flood_output, self.setup.mist_output, on),
            AuxKind::Mist(on) => self.coolant(self.setup.mist_output, self.setup.flood_output, on),
            AuxKind::SelectTool(_) | AuxKind::StartToolChange => {}
            AuxKind::ChangeTool(t) if self.plc.as_ref().is_some_and(|p| p.setup.handles_m6) => {
                done = !self.plc_request(RequestKind::ToolChange, 6, t, 0.0, 0.0);
            }
            AuxKind::UserMcode { code, p, q }
                if self.plc.as_ref().is_some_and(|p| p.setup.handles_mcodes) =>
            {
                done = !self.plc_request(RequestKind::UserMcode, code, 0, p, q);
            }
            AuxKind::ChangeTool(t) | AuxKind::ChangeToolNumber(t) => self.snap.tool = t,
            AuxKind::DigitalOutput { index, on, .. } => self.outputs.set_do(index as usize, on),
            AuxKind::AnalogOutput { index, value, .. } => {
                if let Some(v) = self.outputs.analog.get_mut(index as usize) {
                    *v = value;
                }
            }
            AuxKind::Wait {
                index,
                input,
                kind,
                timeout_s,
            } => {
                let cycles = (timeout_s / self.setup.period_s).max(0.0) as u64;
                self.barrier = Barrier::Wait {
                    index,
                    input,
                    kind,
                    deadline: self.cycle + cycles,
                    last: self.input_level(index, input),
                };
                done = false;
            }
            AuxKind::Message { id } => self.emit_job(JobEvent::Message { id, line }),
            AuxKind::OverrideEnable { .. }
            | AuxKind::UserMcode { .. }
            | AuxKind::SpindleSyncEnd => {}
            // The interpolator task runs the move and goes on by itself.
            AuxKind::SpindleSync { .. } => done = false,
            AuxKind::ProgramStop => {
                self.program_stop(line);
                done = false;
            }
            AuxKind::OptionalProgramStop if self.snap.optional_stop => {
                self.program_stop(line);
                done = false;
            }
            AuxKind::OptionalProgramStop => {}
            AuxKind::ProgramEnd => self.spindle_and_coolant_off(),
            AuxKind::ProbeArm { kind } => {
                let error = match self.setup.probe_input {
                    None => Some(JobError::NoProbeInput),
                    Some(_) if kind.toward() && self.motion.probe_input => {
                        Some(JobError::ProbeAlreadyTripped(kind))
                    }
                    Some(_) if !kind.toward() && !self.motion.probe_input => {
                        Some(JobError::ProbeNotTripped(kind))
                    }
                    Some(_) => None,
                };
                if let Some(error) = error {
                    self.job_error(error, line);
                    return;
                }
            }
            AuxKind::ProbeEnd { kind } => {
                let tripped = self.setpoints.probe_tripped;
                if !tripped && kind.needs_contact() {
                    self.job_error(JobError::ProbeNoContact(kind), line);
                    return;
                }
                let stopped = self.setpoints.pose_mm;
                let p = &mut self.snap.probe;
                p.seq = p.seq.wrapping_add(1);
                p.job = self.job_id;
                p.line = line;
                p.tripped = tripped;
                p.probed_mm = if tripped {
                    self.setpoints.probe_pose_mm
                } else {
                    stopped
                };
                p.stopped_mm = stopped;
                p.waiting = true;
                self.barrier = Barrier::Probe;
                done = false;
            }
        }
        if done && kind.is_barrier() {
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        }
    }

    /// M7/M8 switch one coolant on; M9 (`on` false) switches both off, as LinuxCNC does.
    fn coolant(&mut self, this: Option<usize>, other: Option<usize>, on: bool) {
        if let Some(o) = this {
            self.outputs.set_do(o, on);
        }
        if let (Some(o), false) = (other, on) {
            self.outputs.set_do(o, false);
        }
    }

    fn input_level(&self, index: u32, input: InputKind) -> bool {
        // `[plc] m66_digital` / `m66_analog`: the PLC's variables.
        if let Some(v) = self.plc.as_ref().and_then(|p| p.m66_level(index, input)) {
            return v;
        }
        match input {
            InputKind::Digital => self.inputs.di(index as usize),
            InputKind::Analog => self
                .inputs
                .analog
                .get(index as usize)
                .is_some_and(|v| *v > 0.5),
        }
    }

    /// Progress of the current barrier; releases the interpolator when it is met.
    fn poll_barrier(&mut self) {
        let met = match self.barrier {
            Barrier::None | Barrier::ProgramStop | Barrier::Probe => false,
            Barrier::Plc { .. } => {
                self.poll_plc_barrier();
                return;
            }
            Barrier::SpindleAtSpeed { since } => {
                let at = self
                    .setup
                    .spindle
                    .and_then(|s| s.at_speed)
                    .is_none_or(|i| self.inputs.di(i));
                if !at && self.cycle - since > u64::from(self.setup.spindle_timeout_cycles) {
                    let line = self.setpoints.line;
                    self.on_trip(Trip::SpindleNotAtSpeed, line);
                    return;
                }
                at
            }
            Barrier::Wait {
                index,
                input,
                kind,
                deadline,
                last,
            } => {
                let now = self.input_level(index, input);
                let ok = match kind {
                    WaitKind::Immediate => true,
                    WaitKind::Rise => now && !last,
                    WaitKind::Fall => !now && last,
                    WaitKind::High => now,
                    WaitKind::Low => !now,
                };
                if let Barrier::Wait { last, .. } = &mut self.barrier {
                    *last = now;
                }
                // LinuxCNC semantics: a timeout is not an error, the program goes on.
                ok || self.cycle >= deadline
            }
        };
        if met {
            self.barrier = Barrier::None;
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        }
    }

    /// M0, M60 (and M1 with optional stop on): the interpolator waits at the barrier and the
    /// machine holds (mode and job "holding") until `resume` or `step` goes on with the next
    /// line, as LinuxCNC's pause and cycle start do.
    fn program_stop(&mut self, line: u32) {
        self.barrier = Barrier::ProgramStop;
        self.mode.fact(Fact::ProgramStop);
        self.emit_job(JobEvent::Held { line });
    }

    /// Leaves a feed hold or an M0 stop.
    fn resume_job(&mut self, homed: bool) -> Result<(), RejectReason> {
        self.mode
            .request(Request::Resume, homed)
            .map_err(RejectReason::Other)?;
        self.motion.hold = false;
        if self.barrier == Barrier::ProgramStop {
            self.barrier = Barrier::None;
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        }
        self.emit_job(JobEvent::Resumed);
        Ok(())
    }

    /// Single block: hold in the cycle a new source line starts executing.
    fn poll_step(&mut self) {
        let Some(from) = self.step_from else {
            return;
        };
        if self.mode.mode() != Mode::Running {
            if self.current == Motion::None {
                self.step_from = None;
            }
            return;
        }
        let line = self.setpoints.line;
        if from == 0 {
            let begun = line != 0 && line != self.step_skip;
            self.step_from = Some(if begun { line } else { 0 });
        } else if line != 0 && line != from {
            self.step_from = None;
            if self.mode.request(Request::Pause, true).is_ok() {
                self.motion.hold = true;
                self.emit_job(JobEvent::Held { line });
            }
        }
    }

    fn poll_homing(&mut self) {
        let Some(g) = self.homing_group else {
            return;
        };
        let group = self.setup.homing_groups.get(g).copied().unwrap_or(0) & self.homing_mask;
        let mut all = true;
        for k in 0..self.setup.axes.len() {
            let i = self.setup.axes[k].1;
            if group & (1 << i) == 0 {
                continue;
            }
            let fb = self.feedback[i];
            if fb.homing_failed {
                self.homing_group = None;
                self.on_trip(Trip::HomingFailed { axis: i }, 0);
                return;
            }
            all &= fb.homed && !fb.homing;
        }
        if all {
            self.start_homing_group(g + 1);
        }
    }

    fn start_homing_group(&mut self, g: usize) {
        let Some(&group) = self.setup.homing_groups.get(g) else {
            self.homing_group = None;
            self.mode.fact(Fact::HomingDone);
            return;
        };
        self.homing_group = Some(g);
        let group = group & self.homing_mask;
        for i in 0..NUM_AXES {
            if group & (1 << i) != 0 {
                self.drive.home_seq[i] = self.drive.home_seq[i].wrapping_add(1);
            }
        }
        if group == 0 {
            self.start_homing_group(g + 1);
        }
    }

    fn poll_stop(&mut self) {
        let Some(s) = self.stopping else {
            return;
        };
        if !self.stopped(s.abort_seq) {
            return;
        }
        self.stopping = None;
        self.motion.track_actual = true;
        self.motion.hold = false;
        if s.disable {
            self.drive.enable = false;
        }
        if let Some(e) = s.end {
            self.emit_job(e);
        }
        if matches!(
            self.mode.mode(),
            Mode::Running | Mode::Holding | Mode::Manual
        ) {
            self.mode.fact(Fact::MotionDone);
        }
        self.current = Motion::None;
    }

    fn poll_motion(&mut self) {
        let Motion::Job { job, items } = self.current else {
            return;
        };
        if self.stopping.is_some() {
            return;
        }
        let path_done = self.setpoints.job == job
            && self.setpoints.items_consumed >= items
            && matches!(self.setpoints.state, InterpState::Done | InterpState::Idle)
            && self.barrier == Barrier::None;
        if !path_done {
            self.settle_since = None;
            return;
        }
        // In position: every axis within the window, or the drives had their settling time.
        let since = *self.settle_since.get_or_insert(self.cycle);
        let in_position =
            self.setup.axes.iter().all(|&(_, i)| {
                self.monitor.following_error[i].abs() <= self.setup.in_position_window
            });
        if in_position || self.cycle - since >= u64::from(self.setup.settle_timeout_cycles) {
            self.current = Motion::None;
            self.motion.track_actual = true;
            self.mode.fact(Fact::MotionDone);
            let line = self.setpoints.line;
            self.emit_job(JobEvent::Finished { line });
        }
    }
}

impl MachineTask {
    /// Publishes the outputs of this step. Called last in the step (after the command
    /// processor and the deferred handlers), so a command accepted in this cycle is visible
    /// to the tasks after this one in this cycle, and to status readers, at once.
    fn publish(&mut self) {
        self.snap.homed_mask = self.homed_mask();
        self.snap.mode = self.mode.mode();
        self.snap.feed_override = self.motion.feed_override;
        self.snap.rapid_override = self.motion.rapid_override;
        if self.snap.mode != self.last_mode {
            self.last_mode = self.snap.mode;
            if let Some(ev) = &mut self.mode_ev {
                ev.emit(ModeEvent {
                    mode: self.snap.mode,
                });
            }
        }
        let outputs = match &mut self.plc {
            Some(p) => {
                if !matches!(self.barrier, Barrier::Plc { .. }) {
                    p.withdraw();
                }
                p.publish(self.outputs, self.current == Motion::None)
            }
            None => self.outputs,
        };
        if let Some(w) = &mut self.outputs_out {
            w.set(outputs);
        }
        if let Some(w) = &mut self.drive_out {
            w.set(self.drive);
        }
        if let Some(w) = &mut self.motion_out {
            w.set(self.motion);
        }
        if let Some(w) = &mut self.snapshot_out {
            w.set(self.snap);
        }
    }
}

impl Task for MachineTask {
    type Command = MachineCmd;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.inputs_in = Some(ctx.input(ports::INPUTS));
        self.setpoints_in = Some(ctx.input(ports::SETPOINTS));
        self.monitor_in = Some(ctx.input(ports::MONITOR));
        self.feedback_in = self
            .setup
            .axes
            .iter()
            .map(|&(name, _)| ctx.input(&ports::feedback(name)))
            .collect();
        self.outputs_out = Some(ctx.output(ports::OUTPUTS));
        self.drive_out = Some(ctx.output(ports::DRIVE_CONTROL));
        self.motion_out = Some(ctx.output(ports::MOTION_CONTROL));
        self.snapshot_out = Some(ctx.output(ports::SNAPSHOT));
        self.faults_in = Some(ctx.subscribe("monitor.fault", 64));
        self.overruns_in = Some(ctx.subscribe(&self.setup.overrun_event, 16));
        self.mode_ev = Some(ctx.event("mode"));
        self.fault_ev = Some(ctx.event("fault"));
        self.job_ev = Some(ctx.event("job"));
        if let Some(p) = &mut self.plc {
            p.configure(ctx);
        }
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        if let Some(r) = &mut self.inputs_in {
            r.get(&mut self.inputs);
        }
        if let Some(r) = &mut self.setpoints_in {
            r.get(&mut self.setpoints);
        }
        for (k, r) in self.feedback_in.iter_mut().enumerate() {
            if let Some(&(_, i)) = self.setup.axes.get(k) {
                r.get(&mut self.feedback[i]);
            }
        }
        if let Some(r) = &mut self.monitor_in {
            r.get(&mut self.monitor);
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.cycle = ctx.cycle;
        // 1. E-stop: pressed, or unreadable for too long.
        let stale = self.inputs.stale_cycles > self.setup.max_stale_io_cycles;
        let pressed = self.inputs.di(self.setup.estop_input) || stale;
        if pressed && self.mode.mode() != Mode::Estop {
            self.enter_estop(if stale {
                Trip::CommunicationLost { axis: usize::MAX }
            } else {
                Trip::Estop
            });
        }
        self.mode.set_estop_input(pressed);
        let requests = self.estop_request.as_ref().map_or(self.estop_seen, |r| {
            r.load(std::sync::atomic::Ordering::Acquire)
        });
        if requests != self.estop_seen {
            self.estop_seen = requests;
            if self.mode.mode() != Mode::Estop {
                self.enter_estop(Trip::Estop);
            }
        }
        self.poll_plc();
        self.motion.probe_input = self.setup.probe_input.is_some_and(|i| self.inputs.di(i));
        self.motion.spindle_rpm = self.snap.spindle_rpm;
        if self.setpoints.spindle_reversed != self.spindle_reversed {
            self.spindle_reversed = self.setpoints.spindle_reversed;
            self.apply_spindle();
        }
        if let Some(e) = self.sync_errors.take(&self.setpoints) {
            if self.current != Motion::None && self.stopping.is_none() {
                self.job_error(JobError::SpindleSync(e), self.setpoints.line);
            }
        }
        if self.mode.mode() == Mode::Estop {
            // The quick stop is requested until the drives are off.
            self.drive.quick_stop = self
                .setup
                .axes
                .iter()
                .any(|&(_, i)| self.feedback[i].state.is_operational());
        }
        // 2. Aux items reached by the interpolator (one per cycle at most).
        if self.setpoints.aux_seq != self.last_aux_seq {
            self.last_aux_seq = self.setpoints.aux_seq;
            if let Some(aux) = self.setpoints.aux {
                if self.current != Motion::None && self.stopping.is_none() {
                    self.run_aux(aux.kind, aux.line);
                }
            }
        }
        self.poll_step();
        self.poll_barrier();
        self.poll_homing();
        self.poll_motion();
        self.poll_stop();
        Ok(())
    }

    fn accept(&mut self, c: &MachineCmd, ctx: &StepContext) -> Result<(), RejectReason> {
        let homed = self.all_homed();
        let reject = RejectReason::Other;
        match *c {
            MachineCmd::Estop => {
                self.mode.request(Request::Estop, homed).map_err(reject)?;
                self.enter_estop(Trip::Estop);
            }
            MachineCmd::EstopReset => {
                self.mode
                    .request(Request::EstopReset, homed)
                    .map_err(reject)?;
                self.drive.quick_stop = false;
                self.drive.fault_reset_seq = self.drive.fault_reset_seq.wrapping_add(1);
                if let Some(p) = &mut self.plc {
                    p.estop_reset();
                }
            }
            MachineCmd::On => {
                self.mode.request(Request::On, homed).map_err(reject)?;
                self.drive.fault_reset_seq = self.drive.fault_reset_seq.wrapping_add(1);
                self.drive.enable = true;
                self.drive.quick_stop = false;
                self.motion.track_actual = true;
                self.enable_since = ctx.cycle;
            }
            MachineCmd::Off => {
                let moving = self.current != Motion::None || self.homing_group.is_some();
                self.mode.request(Request::Off, homed).map_err(reject)?;
                self.outputs_safe();
                if moving {
                    let line = self.setpoints.line;
                    self.current = Motion::None;
                    self.controlled_stop(true, Some(JobEvent::Aborted { line }));
                    self.drive.home_abort_seq = self.drive.home_abort_seq.wrapping_add(1);
                } else {
                    self.drive.enable = false;
                }
            }
            MachineCmd::Home { mask } => {
                let mask = if mask == 0 { self.axes_mask() } else { mask };
                if mask & !self.axes_mask() != 0 {
                    return Err(RejectReason::BadParameters("no such axis"));
                }
                self.mode.request(Request::Home, homed).map_err(reject)?;
                self.homing_mask = mask;
                self.motion.track_actual = true;
                self.start_homing_group(0);
            }
            MachineCmd::Run { job, items, manual } => {
                let req = if manual { Request::Jog } else { Request::Run };
                if !manual {
                    self.refuse_if_plc_inhibits()?;
                }
                // Jogging is allowed before homing (that is how a machine is brought home by
                // hand); soft limits apply only to homed axes, checked by the planner.
                self.mode.request(req, homed || manual).map_err(reject)?;
                self.current = Motion::Job { job, items };
                self.job_id = job;
                self.ended = None;
                self.motion.job = job;
                self.motion.track_actual = false;
                self.motion.hold = false;
                self.emit_job(JobEvent::Started);
            }
            MachineCmd::Pause => {
                let running = self.mode.mode() == Mode::Running;
                self.mode.request(Request::Pause, homed).map_err(reject)?;
                self.motion.hold = true;
                // The job holds too (`job.state` "holding" until `Resumed`), as on an M0.
                if running {
                    let line = self.setpoints.line;
                    self.emit_job(JobEvent::Held { line });
                }
            }
            MachineCmd::Step => {
                // At a program stop the stop's own line is done: the step runs the next one.
                let at_stop = self.barrier == Barrier::ProgramStop;
                match self.mode.mode() {
                    Mode::Holding => self.resume_job(homed)?,
                    Mode::Running => {}
                    _ => return Err(RejectReason::Other("no job is running")),
                }
                self.step_skip = if at_stop { self.setpoints.line } else { 0 };
                self.step_from = Some(if at_stop { 0 } else { self.setpoints.line });
            }
            MachineCmd::Resume => {
                self.refuse_if_plc_inhibits()?;
                self.resume_job(homed)?;
                self.step_from = None;
            }
            MachineCmd::Abort => {
                let jog = self.mode.mode() == Mode::Manual;
                self.mode.request(Request::Abort, homed).map_err(reject)?;
                self.step_from = None;
                // A jog's stop is an abort too here, but stopping a jog leaves the spindle
                // and coolant alone (in LinuxCNC it is a jog stop, not a task abort).
                if !jog {
                    self.spindle_and_coolant_off();
                }
                let line = self.setpoints.line;
                if self.homing_group.is_some() {
                    self.drive.home_abort_seq = self.drive.home_abort_seq.wrapping_add(1);
                    self.homing_group = None;
                    self.mode.fact(Fact::HomingDone);
                } else {
                    self.current = Motion::None;
                    self.controlled_stop(false, Some(JobEvent::Aborted { line }));
                }
            }
            MachineCmd::Continue { job, items } => {
                let waiting = self.barrier == Barrier::Probe && self.snap.probe.job == job;
                let Motion::Job {
                    job: current,
                    items: total,
                } = self.current
                else {
                    return Err(RejectReason::Other("no job is running"));
                };
                if current != job || !waiting {
                    return Err(RejectReason::Other("the job is not waiting after a probe"));
                }
                self.current = Motion::Job {
                    job,
                    items: total + items,
                };
                self.barrier = Barrier::None;
                self.snap.probe.waiting = false;
                self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
            }
            MachineCmd::OptionalStop { on } => self.snap.optional_stop = on,
            MachineCmd::Overrides {
                feed,
                rapid,
                spindle,
            } => {
                let ok = |v: f64, max: f64| v.is_finite() && (0.0..=max).contains(&v);
                if !ok(feed, self.setup.max_feed_override) || !ok(rapid, 1.0) || !ok(spindle, 2.0) {
                    return Err(RejectReason::BadParameters("override out of range"));
                }
                self.motion.feed_override = feed;
                self.motion.rapid_override = rapid;
                self.snap.spindle_override = spindle;
                self.apply_spindle();
            }
        }
        Ok(())
    }

    fn progress(&mut self, c: &MachineCmd, ctx: &StepContext) -> Progress {
        let mode = self.mode.mode();
        match *c {
            MachineCmd::On => {
                if mode != Mode::Idle {
                    return Progress::Failed("the machine left the idle mode while enabling");
                }
                let all_on = self
                    .setup
                    .axes
                    .iter()
                    .all(|&(_, i)| self.feedback[i].state.is_operational());
                if all_on {
                    Progress::Done
                } else if ctx.cycle - self.enable_since
                    > u64::from(self.setup.enable_timeout_cycles)
                {
                    self.drive.enable = false;
                    self.mode.fact(Fact::Faulted);
                    Progress::Failed("a drive did not reach operation enabled")
                } else {
                    Progress::Running
                }
            }
            MachineCmd::Off => {
                if self.stopping.is_some()
                    || self
                        .setup
                        .axes
                        .iter()
                        .any(|&(_, i)| self.feedback[i].state.is_operational())
                {
                    Progress::Running
                } else {
                    Progress::Done
                }
            }
            MachineCmd::Home { .. } => match mode {
                Mode::Homing => Progress::Running,
                Mode::Idle if self.homed_mask() & self.homing_mask == self.homing_mask => {
                    Progress::Done
                }
                Mode::Idle => Progress::Failed("homing was aborted"),
                _ => Progress::Failed("homing stopped by a fault or e-stop"),
            },
            MachineCmd::Run { job, .. } => match self.ended {
                Some((j, JobEvent::Finished { .. })) if j == job => Progress::Done,
                Some((j, JobEvent::Aborted { .. })) if j == job => Progress::Failed("aborted"),
                Some((j, JobEvent::Failed { .. })) if j == job => {
                    Progress::Failed("stopped by a fault or e-stop")
                }
                Some((j, JobEvent::Error { .. })) if j == job => {
                    Progress::Failed("stopped by a program error")
                }
                _ => Progress::Running,
            },
            // Done once nothing moves: held on the path, or standing at a barrier (M0, M66,
            // spindle at speed), where the interpolator waits and never reports `Holding`.
            // A pause that stayed active there kept one of the task's few command slots;
            // enough of them and the task took no command at all, e-stop included.
            MachineCmd::Pause => {
                if mode != Mode::Holding
                    || matches!(
                        self.setpoints.state,
                        InterpState::Holding
                            | InterpState::Waiting
                            | InterpState::Done
                            | InterpState::Idle
                    )
                {
                    Progress::Done
                } else {
                    Progress::Running
                }
            }
            MachineCmd::Abort => {
                if self.stopping.is_some() {
                    Progress::Running
                } else {
                    Progress::Done
                }
            }
            MachineCmd::Estop
            | MachineCmd::EstopReset
            | MachineCmd::Resume
            | MachineCmd::Continue { .. }
            | MachineCmd::Step
            | MachineCmd::OptionalStop { .. }
            | MachineCmd::Overrides { .. } => Progress::Done,
        }
    }

    fn process_events(&mut self, _ctx: &StepContext) {
        while let Some(f) = self.faults_in.as_mut().and_then(EventReceiver::pop) {
            self.on_trip(f.trip, f.line);
        }
        while let Some(o) = self.overruns_in.as_mut().and_then(EventReceiver::pop) {
            let line = self.setpoints.line;
            self.on_trip(
                Trip::OverrunStorm {
                    consecutive: o.consecutive as u32,
                },
                line,
            );
        }
        self.publish();
    }
}

/// The PLC's part of the machine task (the link itself is in `plc_link`).
impl MachineTask {
    /// Links the machine task to a PLC task (`[plc]`): M6 and M100–M199 wait for it as
    /// configured, its feed hold, start inhibit, e-stop and fault act on the machine.
    pub fn with_plc(mut self, setup: PlcLinkSetup) -> Self {
        self.plc = Some(PlcLink::new(setup));
        self
    }

    /// Posts a request to the PLC and holds the interpolator at a barrier until it answers.
    /// Returns false when there is no PLC to ask.
    fn plc_request(&mut self, kind: RequestKind, mcode: u32, tool: u32, p: f64, q: f64) -> bool {
        let Some(link) = &mut self.plc else {
            return false;
        };
        let seq = link.post(kind, tool, mcode, p, q);
        let timeout = if kind == RequestKind::ToolChange {
            link.setup.tool_change_timeout_cycles
        } else {
            link.setup.mcode_timeout_cycles
        };
        self.barrier = Barrier::Plc {
            seq,
            mcode,
            tool,
            deadline: self.cycle + timeout,
        };
        true
    }

    /// Releases the PLC barrier when the PLC answered; a timeout ends the job with its line.
    fn poll_plc_barrier(&mut self) {
        let Barrier::Plc {
            seq,
            mcode,
            tool,
            deadline,
        } = self.barrier
        else {
            return;
        };
        let Some(link) = &mut self.plc else {
            return;
        };
        if link.done(seq) {
            link.withdraw();
            if mcode == 6 {
                self.snap.tool = tool;
            }
            self.barrier = Barrier::None;
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        } else if self.cycle >= deadline {
            link.withdraw();
            self.barrier = Barrier::None;
            let line = self.setpoints.line;
            self.job_error(JobError::PlcTimeout { mcode }, line);
        }
    }

    /// Acts on what the PLC asks: e-stop on its rising e-stop output, a controlled stop on
    /// its fault (when safety relevant), a feed hold while it holds feed.
    fn poll_plc(&mut self) {
        let Some(link) = &mut self.plc else {
            return;
        };
        let d = link.read();
        if d.estop && self.mode.mode() != Mode::Estop {
            self.enter_estop(Trip::Estop);
        }
        if d.fault {
            let line = self.setpoints.line;
            self.on_trip(Trip::PlcFault, line);
        }
        if d.feed_hold
            && self.mode.mode() == Mode::Running
            && self.mode.request(Request::Pause, true).is_ok()
        {
            self.motion.hold = true;
            let line = self.setpoints.line;
            self.emit_job(JobEvent::Held { line });
        }
    }

    /// Cycle start and resume are refused while the PLC inhibits them (e.g. guard door).
    fn refuse_if_plc_inhibits(&self) -> Result<(), RejectReason> {
        match &self.plc {
            Some(p) if p.start_inhibited() => Err(RejectReason::Other(
                "the PLC inhibits cycle start (machine.start_inhibit)",
            )),
            _ => Ok(()),
        }
    }
}
