//! The machine's realtime tasks and the data they exchange.
//!
//! All of them run on the servo thread, in this start order (the paper's rule: periodic
//! tasks of one thread run in start order, so data between them needs no lock and each sees
//! this cycle's values of the tasks before it):
//!
//! 1. [`io_task::IoTask`] `io`: reads every input into [`Inputs`], writes the [`Outputs`]
//!    the machine task asked for in the previous cycle.
//! 2. [`machine_task::MachineTask`] `machine`: the machine state machine. Serves the
//!    operator's commands (e-stop, on/off, home, run, hold, ...), reacts to the e-stop input
//!    in the same cycle, executes the auxiliary commands of the job (spindle, coolant, I/O,
//!    M0, M66), and takes fault events from the monitor (deferred, at its safe point).
//! 3. [`interp_task::InterpolatorTask`] `interpolator`: turns the segment queue into
//!    [`Setpoints`]; follows the actual position whenever no motion is commanded.
//! 4. [`axis_task::AxisTask`] `axis.X`, `axis.Y`, ...: one per axis, writes the setpoint to
//!    its drive through the HAL and publishes [`AxisFeedback`]. With CANopen drives, the
//!    bus owner's `can.<iface>.rx` runs before `io` and `can.<iface>.tx` right after the
//!    axis tasks ([`can_bus`] explains).
//! 5. [`monitor_task::MonitorTask`] `monitor`: checks this cycle's setpoints against this
//!    cycle's feedback (following error, soft limits, drive faults, limit switches,
//!    communication) and emits a `fault` event; tracks the largest following errors.
//!    Last of all, it publishes the [`status::StatusSnapshot`] of the cycle: what every
//!    task above published in it, the one value `status` reads.
//!
//! Every value exchanged is a fixed-size `Copy` type in a data object, written by exactly
//! one task (the topology check enforces it).

pub mod axis_task;
pub mod can_bus;
pub mod can_delay;
pub mod can_pdo_names;
pub mod can_setup;
pub mod input_wait;
pub mod interp_task;
pub mod io_task;
pub mod json_views;
#[cfg(test)]
mod m66_tests;
pub mod machine_task;
pub mod monitor_task;
#[cfg(test)]
mod output_tests;
pub mod plc_link;
#[cfg(test)]
mod probe_tests;
#[cfg(test)]
mod program_stop_tests;
pub mod spindle_follow;
pub mod status;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod threading_tests;

use super::api::Mode;
use super::safety::Trip;
use crate::gcode::{ProbeKind, NUM_AXES};
use crate::motion::{AuxItem, InterpState};
use hytask_hal::axis::DriveState;
use hytask_hal::canopen::axis::LinkFault;

/// Most digital channels of each direction (bit masks are `u64`).
pub const MAX_DIGITAL: usize = 64;
/// Most analog channels of each direction.
pub const MAX_ANALOG: usize = 16;

/// Data object names (the topology check matches writers and readers by these).
pub mod ports {
    /// [`super::Inputs`], written by `io`.
    pub const INPUTS: &str = "io.inputs";
    /// [`super::Outputs`], written by `machine`.
    pub const OUTPUTS: &str = "machine.outputs";
    /// [`super::DriveControl`], written by `machine`.
    pub const DRIVE_CONTROL: &str = "machine.drive_control";
    /// [`super::MotionControl`], written by `machine`.
    pub const MOTION_CONTROL: &str = "machine.motion_control";
    /// [`super::MachineSnapshot`], written by `machine`.
    pub const SNAPSHOT: &str = "machine.snapshot";
    /// [`super::Setpoints`], written by `interpolator`.
    pub const SETPOINTS: &str = "interpolator.setpoints";
    /// [`super::MonitorSnapshot`], written by `monitor`.
    pub const MONITOR: &str = "monitor.snapshot";
    /// [`super::status::StatusSnapshot`], written by `monitor` at the end of the cycle.
    pub const STATUS: &str = "monitor.status";
    /// [`super::AxisFeedback`] of axis `i`, written by `axis.<name>`.
    pub fn feedback(axis: char) -> String {
        format!("axis.{axis}.feedback")
    }
}

/// Every input of the machine in one cycle, indexed in config order across I/O devices.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Inputs {
    /// Digital inputs, logical level (inversion applied), bit i = channel i.
    pub digital: u64,
    /// Analog inputs, engineering units.
    pub analog: [f64; MAX_ANALOG],
    /// False when an I/O device could not be read this cycle.
    pub link_ok: bool,
    /// Consecutive cycles an I/O device failed.
    pub stale_cycles: u32,
}

impl Inputs {
    /// Digital input `i`.
    pub fn di(&self, i: usize) -> bool {
        i < MAX_DIGITAL && self.digital & (1 << i) != 0
    }
}

/// Every output the machine asks for, in config order across I/O devices.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Outputs {
    /// Digital outputs, logical level, bit i = channel i.
    pub digital: u64,
    /// Analog outputs, engineering units.
    pub analog: [f64; MAX_ANALOG],
}

impl Outputs {
    /// Sets digital output `i`.
    pub fn set_do(&mut self, i: usize, on: bool) {
        if i < MAX_DIGITAL {
            if on {
                self.digital |= 1 << i;
            } else {
                self.digital &= !(1 << i);
            }
        }
    }
}

/// What the machine task asks of the drives.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveControl {
    /// Drives should be enabled (operation enabled).
    pub enable: bool,
    /// Quick stop now (e-stop): the drive brakes on its own ramp.
    pub quick_stop: bool,
    /// Incremented to request a fault reset on every drive.
    pub fault_reset_seq: u32,
    /// Incremented per axis to start homing that axis.
    pub home_seq: [u32; NUM_AXES],
    /// Incremented per axis to abort homing.
    pub home_abort_seq: u32,
}

/// What the machine task asks of the interpolator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionControl {
    /// Follow the actual position and discard queued items (no motion commanded).
    pub track_actual: bool,
    /// Feed hold.
    pub hold: bool,
    /// Incremented to abort (stop within limits, drop the rest).
    pub abort_seq: u32,
    /// Incremented when the aux command the interpolator waits for is done.
    pub aux_done_seq: u32,
    /// Feed override.
    pub feed_override: f64,
    /// Rapid override.
    pub rapid_override: f64,
    /// Job whose queue items to execute; items of older jobs are discarded.
    pub job: u32,
    /// The probe input is active this cycle (false when the machine has none).
    pub probe_input: bool,
    /// Commanded spindle speed, rpm (negative for M4, 0 when stopped): what the simulated
    /// spindle of spindle-synchronised moves follows.
    pub spindle_rpm: f64,
}

impl Default for MotionControl {
    fn default() -> Self {
        MotionControl {
            track_actual: true,
            hold: false,
            abort_seq: 0,
            aux_done_seq: 0,
            feed_override: 1.0,
            rapid_override: 1.0,
            job: 0,
            probe_input: false,
            spindle_rpm: 0.0,
        }
    }
}

/// The interpolator's output of one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoints {
    /// Commanded joint positions (identity kinematics: axis positions).
    pub joints: [f64; NUM_AXES],
    /// Commanded Cartesian pose.
    pub pose_mm: [f64; NUM_AXES],
    /// Source line being executed.
    pub line: u32,
    /// Interpolator state.
    pub state: InterpState,
    /// Distance left in the current move.
    pub distance_to_go_mm: f64,
    /// Aux item reached this cycle.
    pub aux: Option<AuxItem>,
    /// Incremented with every aux item reported (so a reader never misses or repeats one).
    pub aux_seq: u32,
    /// Planned time executed so far (Σ dt · time scale), s.
    pub planned_time_done_s: f64,
    /// Queue items consumed since the last track/abort.
    pub items_consumed: u64,
    /// True while following the actual position.
    pub tracking: bool,
    /// Time scale (1 = as planned, 0 = stopped).
    pub scale: f64,
    /// The last `MotionControl::abort_seq` acted on.
    pub abort_ack: u32,
    /// Job being executed.
    pub job: u32,
    /// The current or last G38 move tripped.
    pub probe_tripped: bool,
    /// Actual pose (forward kinematics of the axis feedback) in the cycle the probe
    /// tripped: LinuxCNC's probed position is the feedback position too.
    pub probe_pose_mm: [f64; NUM_AXES],
    /// Spindle position, revolutions (the simulated spindle's; 0 without one).
    pub spindle_revs: f64,
    /// Spindle speed measured, rev/s (signed).
    pub spindle_rps: f64,
    /// A rigid tap has reversed the spindle (until the tap is out).
    pub spindle_reversed: bool,
    /// The last spindle-synchronised move that failed, and why.
    pub sync_error: Option<crate::motion::spindle_lock::LockError>,
    /// Incremented with each `sync_error`.
    pub sync_error_seq: u32,
}

impl Default for Setpoints {
    fn default() -> Self {
        Setpoints {
            joints: [0.0; NUM_AXES],
            pose_mm: [0.0; NUM_AXES],
            line: 0,
            state: InterpState::Idle,
            distance_to_go_mm: 0.0,
            aux: None,
            aux_seq: 0,
            planned_time_done_s: 0.0,
            items_consumed: 0,
            tracking: true,
            scale: 0.0,
            abort_ack: 0,
            job: 0,
            probe_tripped: false,
            probe_pose_mm: [0.0; NUM_AXES],
            spindle_revs: 0.0,
            spindle_rps: 0.0,
            spindle_reversed: false,
            sync_error: None,
            sync_error_seq: 0,
        }
    }
}

/// One axis' feedback in one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisFeedback {
    /// Actual position.
    pub actual: f64,
    /// Actual velocity.
    pub velocity: f64,
    /// Drive state.
    pub state: DriveState,
    /// Drive fault code.
    pub fault: Option<u16>,
    /// Homed.
    pub homed: bool,
    /// Homing in progress.
    pub homing: bool,
    /// Homing failed (since the last request).
    pub homing_failed: bool,
    /// A limit switch is active.
    pub limit_switch: bool,
    /// Cycles since the drive last answered.
    pub stale_cycles: u32,
    /// The drive answered at least once (before that, positions are meaningless).
    pub valid: bool,
    /// Fieldbus fault of a CANopen drive: node and cause.
    pub link: Option<LinkFault>,
    /// Cycles the position is older than usual (a CANopen drive that answered SYNC late).
    pub age: u32,
}

impl Default for AxisFeedback {
    fn default() -> Self {
        AxisFeedback {
            actual: 0.0,
            velocity: 0.0,
            state: DriveState::NotReadyToSwitchOn,
            fault: None,
            homed: false,
            homing: false,
            homing_failed: false,
            limit_switch: false,
            stale_cycles: 0,
            valid: false,
            link: None,
            age: 0,
        }
    }
}

/// The machine task's view, for status and the non-realtime side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineSnapshot {
    /// Mode.
    pub mode: Mode,
    /// Homed axes, bit i = axis i.
    pub homed_mask: u32,
    /// Commanded spindle speed, rpm, signed (negative = counter-clockwise), 0 when stopped.
    pub spindle_rpm: f64,
    /// Feed override.
    pub feed_override: f64,
    /// Rapid override.
    pub rapid_override: f64,
    /// Spindle override.
    pub spindle_override: f64,
    /// Tool in the spindle.
    pub tool: u32,
    /// Number of trips since start.
    pub trips: u32,
    /// The last trip.
    pub last_trip: Option<Trip>,
    /// The last probe move's result.
    pub probe: ProbeSnapshot,
    /// Optional stop: M1 holds the job as M0 does.
    pub optional_stop: bool,
    /// The M66 in progress, or the last one's result.
    pub wait: InputWaitSnapshot,
}

/// M66 as the machine carries it out ([`input_wait`]). While `pending`, the machine waits
/// for input `index`; when the wait ends it sets `value` and, for a wait that ends a piece of
/// a live job, holds with `waiting` set until the next piece, interpreted with #5399 =
/// `value`, arrives (`MachineCmd::Continue`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InputWaitSnapshot {
    /// Incremented with every M66 that ended (met or timed out).
    pub seq: u32,
    /// Job of the M66 in progress or of the last one.
    pub job: u32,
    /// Its source line.
    pub line: u32,
    /// Its input number (`P` or `E` word).
    pub index: u32,
    /// An analog input (`E`), not a digital one (`P`).
    pub analog: bool,
    /// The `L` word (0 immediate, 1 rise, 2 fall, 3 high, 4 low).
    pub mode: u8,
    /// The machine waits for the input now.
    pub pending: bool,
    /// What the last M66 read (0/1 digital, the reading analog), -1 when it timed out.
    pub value: f64,
    /// The job holds after the M66 until its next piece is queued.
    pub waiting: bool,
    /// Commanded pose at rest at the M66: where the next piece starts.
    pub stopped_mm: [f64; NUM_AXES],
}

/// The result of the last G38 move, published when the machine reaches its end. While
/// `waiting`, the job stands still until the next piece of the program, interpreted with
/// this result, arrives (`MachineCmd::Continue`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ProbeSnapshot {
    /// Incremented with every probe move that ended.
    pub seq: u32,
    /// Job of that probe move.
    pub job: u32,
    /// Source line of the G38 block.
    pub line: u32,
    /// The probe input changed as the move expected.
    pub tripped: bool,
    /// Where it changed (actual pose), or where the move ended without a change.
    pub probed_mm: [f64; NUM_AXES],
    /// Commanded pose at rest after the move: where the next piece starts.
    pub stopped_mm: [f64; NUM_AXES],
    /// The job waits for its next piece.
    pub waiting: bool,
}

impl Default for MachineSnapshot {
    fn default() -> Self {
        MachineSnapshot {
            mode: Mode::Estop,
            homed_mask: 0,
            spindle_rpm: 0.0,
            feed_override: 1.0,
            rapid_override: 1.0,
            spindle_override: 1.0,
            tool: 0,
            trips: 0,
            last_trip: None,
            probe: ProbeSnapshot::default(),
            optional_stop: false,
            wait: InputWaitSnapshot::default(),
        }
    }
}

/// The monitor's view: following errors and their maxima.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MonitorSnapshot {
    /// commanded - actual, per axis.
    pub following_error: [f64; NUM_AXES],
    /// Largest |following error| since the last reset (job start).
    pub max_following_error: [f64; NUM_AXES],
}

/// A fault found by the monitor (event `monitor.fault`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultEvent {
    /// What tripped.
    pub trip: Trip,
    /// Source line being executed.
    pub line: u32,
}

/// One job's news on event `machine.job`: the event and the id of the job it belongs to.
///
/// Why the id: the API applies these events to its active job when it drains them, which can
/// be after the next job started; a job's end must never end another job.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobNews {
    /// Id of the job (as in `MachineCmd::Run`).
    pub job: u32,
    /// What happened.
    pub event: JobEvent,
    /// The servo cycle it happened in: a status shows it only with a snapshot of that cycle
    /// or a later one, so a job never reads "holding" beside the mode and position of a
    /// cycle before the hold.
    pub cycle: u64,
}

/// Job life, from the machine task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JobEvent {
    /// Motion started.
    Started,
    /// Feed hold reached (or M0).
    Held {
        /// Line.
        line: u32,
    },
    /// Resumed.
    Resumed,
    /// Reached the end.
    Finished {
        /// The last line executed (status shows it, not the last progress sample's).
        line: u32,
    },
    /// Aborted by the operator; stopped under control.
    Aborted {
        /// Line at the abort.
        line: u32,
    },
    /// Stopped by a fault.
    Failed {
        /// Line at the fault.
        line: u32,
        /// The fault.
        trip: Trip,
    },
    /// Stopped by an error of the program's execution (not a machine fault: the drives stay
    /// enabled), e.g. a G38.2 that made no contact.
    Error {
        /// Line of the error.
        line: u32,
        /// What went wrong.
        error: JobError,
    },
    /// An `(MSG, …)` was reached: text `messages[id]` of the plan.
    Message {
        /// Index into the plan's messages.
        id: u32,
        /// Line.
        line: u32,
    },
    /// A log comment was reached: file name or line `messages[id]` of the plan.
    Log {
        /// Index into the plan's messages.
        id: u32,
        /// Open, append, write or close.
        kind: crate::gcode::canon::LogKind,
        /// Line.
        line: u32,
    },
}

/// Errors that end a job without faulting the machine (LinuxCNC reports them and stops the
/// program).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JobError {
    /// G38.2/G38.3 started with the probe already active.
    ProbeAlreadyTripped(ProbeKind),
    /// G38.4/G38.5 started with the probe not active.
    ProbeNotTripped(ProbeKind),
    /// G38.2/G38.4 reached the end of the move without the expected change.
    ProbeNoContact(ProbeKind),
    /// The program probes but the machine has no probe input (`motion.probe_input`).
    NoProbeInput,
    /// The PLC did not finish M6 (`mcode` 6) or an M100–M199 within its timeout.
    PlcTimeout {
        /// The M code.
        mcode: u32,
    },
    /// A spindle-synchronised move (G33, G76, G33.1) could not follow the spindle.
    SpindleSync(crate::motion::spindle_lock::LockError),
}

impl std::fmt::Display for JobError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            JobError::ProbeAlreadyTripped(_) => {
                f.write_str("probe is already tripped when starting G38.2 or G38.3 move")
            }
            JobError::ProbeNotTripped(_) => {
                f.write_str("probe is not tripped when starting G38.4 or G38.5 move")
            }
            JobError::ProbeNoContact(k) => write!(
                f,
                "{} move finished without {} the probe",
                k.gcode(),
                if k.toward() { "tripping" } else { "releasing" }
            ),
            JobError::PlcTimeout { mcode: 6 } => f.write_str(
                "M6: the PLC did not finish the tool change within plc.tool_change_timeout_s",
            ),
            JobError::PlcTimeout { mcode } => write!(
                f,
                "M{mcode}: the PLC did not finish it within plc.mcode_timeout_s"
            ),
            JobError::SpindleSync(e) => write!(f, "{e}"),
            JobError::NoProbeInput => {
                f.write_str("the program probes (G38.x) but the machine has no probe input: set motion.probe_input")
            }
        }
    }
}

/// An item of the segment queue, stamped with its job so that the leftovers of an aborted
/// job can never run as part of the next one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueueItem {
    /// Job id.
    pub job: u32,
    /// The item.
    pub item: crate::motion::Item,
}

/// Mode changes (event `machine.mode`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeEvent {
    /// The new mode.
    pub mode: Mode,
}
