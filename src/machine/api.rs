//! The machine's non-realtime facade: what an operator (the control socket, the CLI, a
//! test) can ask of a running machine, as one trait with typed requests and replies.
//!
//! Why a trait: the control socket depends on the *behaviour* of a machine, not on how it
//! is deployed. The real implementation ([`super::Machine`]) turns each call into commands
//! to realtime tasks and waits for them to be accepted or rejected; a test double can
//! implement the same trait to exercise the protocol alone. Every call is non-blocking in
//! the realtime sense: at worst it waits a few servo cycles for a command's acceptance.

use serde::{Deserialize, Serialize};

/// The machine's operating mode (the machine state machine's states).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// E-stop active: drives disabled, outputs safe, until `estop.reset`.
    Estop,
    /// E-stop released, machine off (drives disabled).
    Off,
    /// On and idle: accepts jobs, MDI, jog, home.
    Idle,
    /// Homing one or more axes.
    Homing,
    /// Jogging.
    Manual,
    /// Running a job or an MDI line.
    Running,
    /// Feed hold: decelerated to a stop on the path, resumable.
    Holding,
    /// A fault stopped the machine; `machine.on` after the cause is cleared.
    Fault,
}

/// Why a request could not be carried out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApiError {
    /// The machine refused in its current state (the reason says what would make it accept).
    #[error("rejected: {0}")]
    Rejected(String),
    /// A parameter is out of range or names nothing.
    #[error("invalid parameter: {0}")]
    InvalidParams(String),
    /// G-code that does not interpret; names file, line and column.
    #[error("{0}")]
    Gcode(String),
    /// Accepted, but the operation failed while running.
    #[error("failed: {0}")]
    Failed(String),
    /// No answer from the realtime side in time.
    #[error("timed out: {0}")]
    Timeout(String),
    /// The method does not exist on this machine (e.g. sim inputs on real hardware).
    #[error("not supported: {0}")]
    NotSupported(String),
}

/// A thread's timing statistics, for `status`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ThreadTiming {
    /// Thread name from the config.
    pub name: String,
    /// Configured period, µs.
    pub period_us: u64,
    /// SCHED_FIFO priority.
    pub priority: i32,
    /// Cycles run.
    pub cycles: u64,
    /// Wake-up latency, min/avg/max, µs.
    pub latency_us: MinAvgMax,
    /// Execution time of one cycle, min/avg/max, µs.
    pub exec_us: MinAvgMax,
    /// Cycles that overran their period.
    pub overruns: u64,
}

/// Min/avg/max triple.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MinAvgMax {
    /// Minimum.
    pub min: f64,
    /// Mean.
    pub avg: f64,
    /// Maximum.
    pub max: f64,
}

/// One axis in `status`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct AxisStatus {
    /// Axis letter.
    pub name: String,
    /// Commanded position, mm or deg.
    pub commanded: f64,
    /// Actual (feedback) position.
    pub actual: f64,
    /// Actual velocity, units/s.
    pub velocity: f64,
    /// commanded - actual.
    pub following_error: f64,
    /// Largest |following error| seen during the current/last job.
    pub max_following_error: f64,
    /// Homed since the machine was switched on.
    pub homed: bool,
    /// Drive state name (CiA 402 vocabulary).
    pub drive_state: String,
    /// Drive fault, if any.
    pub fault: Option<String>,
}

/// Job progress in `status` and progress events.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JobStatus {
    /// Job name (file name or "mdi").
    pub name: String,
    /// State: none, loaded, running, holding, done, aborted, failed. "holding" (as the
    /// machine's mode) while the job stands in a feed hold (`job.pause`), a single-block stop
    /// or an M0/M1 stop; "running" again after `job.resume`.
    pub state: String,
    /// Current source line.
    pub line: u32,
    /// Total lines in the program.
    pub total_lines: u32,
    /// Fraction of planned time elapsed, 0..1.
    pub progress: f64,
    /// Planned duration, s.
    pub planned_time_s: f64,
    /// Elapsed motion time, s.
    pub elapsed_s: f64,
    /// Path length of the job, mm.
    pub distance_mm: f64,
    /// Distance remaining, mm.
    pub distance_to_go_mm: f64,
    /// Why it ended, when it failed or was aborted.
    pub reason: Option<String>,
    /// The M66 the job waits at, while the machine waits for its input (issue 11).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_wait: Option<InputWaitStatus>,
}

/// An M66 in progress: the machine stands at `line`, waiting for input `index`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct InputWaitStatus {
    /// Source line of the M66.
    pub line: u32,
    /// "digital" (`P` word) or "analog" (`E` word).
    pub input: String,
    /// Input number.
    pub index: u32,
    /// What it waits for (`L` word): "immediate", "rise", "fall", "high" or "low".
    pub until: String,
}

/// Overrides in effect.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Overrides {
    /// Feed override, 0..=2.
    pub feed: f64,
    /// Rapid override, 0..=1.
    pub rapid: f64,
    /// Spindle override, 0..=2.
    pub spindle: f64,
}

impl Default for Overrides {
    fn default() -> Self {
        Overrides {
            feed: 1.0,
            rapid: 1.0,
            spindle: 1.0,
        }
    }
}

/// The last probe move's result (G38.x), as LinuxCNC reports it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ProbeStatus {
    /// Probe moves completed since start.
    pub count: u32,
    /// Source line of the last one.
    pub line: u32,
    /// The last one tripped.
    pub tripped: bool,
    /// Where it tripped (or ended), machine frame, by axis letter.
    pub position: std::collections::BTreeMap<String, f64>,
}

/// The answer to `status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Machine name from the config.
    pub machine: String,
    /// Operating mode.
    pub mode: Mode,
    /// Whether threads run with SCHED_FIFO and locked memory.
    pub realtime: bool,
    /// The servo cycle this status was sampled in: the mode, axes, job line and progress,
    /// spindle, overrides, inputs, outputs and probe result all belong to this one cycle.
    #[serde(default)]
    pub servo_cycle: u64,
    /// Axes.
    pub axes: Vec<AxisStatus>,
    /// Current or last job.
    pub job: JobStatus,
    /// Overrides.
    pub overrides: Overrides,
    /// Spindle speed commanded, rpm (signed: negative is counter-clockwise).
    pub spindle_rpm: f64,
    /// Active faults, newest last.
    pub faults: Vec<String>,
    /// Realtime thread timing.
    pub threads: Vec<ThreadTiming>,
    /// Inputs by name (logical state: 1 = active; analog in engineering units).
    pub inputs: std::collections::BTreeMap<String, f64>,
    /// Outputs by name, as the machine commands them.
    pub outputs: std::collections::BTreeMap<String, f64>,
    /// The last probe result.
    #[serde(default)]
    pub probe: ProbeStatus,
    /// Optional stop: M1 holds the job as M0 does (`job.optional_stop`; off at start).
    #[serde(default)]
    pub optional_stop: bool,
    /// The PLC task's scan statistics (absent without `[plc]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plc: Option<PlcStatus>,
}

/// Scan statistics of the PLC task, in `status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlcStatus {
    /// Scans run.
    pub scans: u64,
    /// Median scan time, µs (upper bound of its power-of-two bucket).
    pub p50_us: f64,
    /// Longest scan, µs.
    pub max_us: f64,
    /// Scans longer than the PLC thread's period.
    pub overruns: u64,
    /// The PLC is in fault (outputs at their safe values).
    pub fault: bool,
    /// Variables forced online (`plc.force`).
    #[serde(default)]
    pub forced: u64,
    /// Program versions loaded online (`plc.load`) since start.
    #[serde(default)]
    pub reloads: u64,
}

/// A fault to inject into a simulated machine (`sim.fault`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimFault {
    /// `drive_fault`, `stall`, `disconnect` (per axis) or `overrun` (servo thread).
    pub kind: String,
    /// Axis letter, for the per-axis kinds.
    #[serde(default)]
    pub axis: Option<String>,
    /// Switch a lasting condition (stall, disconnect) on or off; default on.
    #[serde(default)]
    pub on: Option<bool>,
    /// Fault code for `drive_fault` (default 0x2310, over-current).
    #[serde(default)]
    pub code: Option<u16>,
    /// Servo cycles to overrun, for `overrun` (default 5).
    #[serde(default)]
    pub cycles: Option<u32>,
}

/// Jog request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JogRequest {
    /// Axis letter.
    pub axis: String,
    /// Signed velocity, units/s.
    pub velocity: f64,
    /// Incremental distance (unsigned; the sign comes from the velocity). Absent: continuous
    /// jog until `jog.stop` or the soft limit.
    #[serde(default)]
    pub distance: Option<f64>,
}

/// Where a job's G-code comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobSource {
    /// Path of a G-code file on the daemon's host.
    #[serde(default)]
    pub path: Option<String>,
    /// Inline program text.
    #[serde(default)]
    pub text: Option<String>,
    /// Display name for inline programs.
    #[serde(default)]
    pub name: Option<String>,
}

/// The answer to `job.load`: the job was interpreted and planned in full.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobInfo {
    /// Name.
    pub name: String,
    /// Source lines.
    pub lines: u32,
    /// Canonical commands.
    pub commands: usize,
    /// Planned duration, s.
    pub planned_time_s: f64,
    /// Path length, mm.
    pub distance_mm: f64,
}

/// Override request (absent fields keep their value).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OverrideRequest {
    /// Feed override 0..=2.
    #[serde(default)]
    pub feed: Option<f64>,
    /// Rapid override 0..=1.
    #[serde(default)]
    pub rapid: Option<f64>,
    /// Spindle override 0..=2.
    #[serde(default)]
    pub spindle: Option<f64>,
}

/// A task as data: its operations, events and ports (the paper's task interface).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskInfo {
    /// Task name.
    pub name: String,
    /// Lifecycle state.
    pub state: String,
    /// Thread it runs on.
    pub thread: String,
    /// Operations: name, doc, parameters.
    pub operations: Vec<OperationInfo>,
    /// Events it emits.
    pub events: Vec<String>,
    /// Ports: name and direction.
    pub ports: Vec<String>,
    /// Execution time of the task's step, min/avg/max, µs.
    pub exec_us: MinAvgMax,
}

/// An operation as data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperationInfo {
    /// Name.
    pub name: String,
    /// What it does.
    pub doc: String,
    /// Parameters as `name: type`.
    pub params: Vec<String>,
}

/// An event pushed to subscribers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MachineEvent {
    /// Topic: `mode`, `fault`, `progress`, `job`, `message`, `task`, `io`.
    pub topic: String,
    /// Event data.
    pub data: serde_json::Value,
}

/// What a running machine offers its operators. Methods return once the realtime side has
/// accepted or rejected the request (or, for queries, with a consistent snapshot).
pub trait MachineApi: Send + Sync + 'static {
    /// A snapshot of the whole machine.
    fn status(&self) -> Status;
    /// Why this host refuses the motion, job and simulation methods when it is not a machine
    /// (the pick-and-place cell, a peer process): their default implementations answer
    /// "`<method>`: `<this>`", so such hosts implement only what they really offer.
    fn not_a_machine(&self) -> &'static str {
        "not supported by this host"
    }
    /// The error of a method this host does not offer (see [`MachineApi::not_a_machine`]).
    fn not_a_machine_error(&self, what: &str) -> ApiError {
        ApiError::NotSupported(format!("{what}: {}", self.not_a_machine()))
    }
    /// Trip the e-stop: all axes quick-stop within one servo cycle.
    fn estop(&self) -> Result<(), ApiError>;
    /// Release the e-stop (the machine goes to `Off`).
    fn estop_reset(&self) -> Result<(), ApiError>;
    /// Enable drives (`Off`/`Fault` → `Idle`).
    fn machine_on(&self) -> Result<(), ApiError>;
    /// Disable drives after a controlled stop.
    fn machine_off(&self) -> Result<(), ApiError>;
    /// Home one axis (`Some("X")`) or all axes in order.
    fn home(&self, axis: Option<&str>) -> Result<(), ApiError> {
        let _ = axis;
        Err(self.not_a_machine_error("home"))
    }
    /// Jog an axis.
    fn jog(&self, req: &JogRequest) -> Result<(), ApiError> {
        let _ = req;
        Err(self.not_a_machine_error("jog"))
    }
    /// Stop a continuous jog with a controlled deceleration.
    fn jog_stop(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("jog"))
    }
    /// Execute one line of G-code.
    fn mdi(&self, line: &str) -> Result<(), ApiError> {
        let _ = line;
        Err(self.not_a_machine_error("mdi"))
    }
    /// Interpret and plan a job in full; refused as a whole on any error.
    fn job_load(&self, src: &JobSource) -> Result<JobInfo, ApiError> {
        let _ = src;
        Err(self.not_a_machine_error("job.load"))
    }
    /// Start the loaded job.
    fn job_run(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("job.run"))
    }
    /// Feed hold.
    fn job_pause(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("job.pause"))
    }
    /// Resume after a feed hold.
    fn job_resume(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("job.resume"))
    }
    /// Abort with a controlled stop.
    fn job_abort(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("job.abort"))
    }
    /// Run until the next source line, then hold.
    fn job_step(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("job.step"))
    }
    /// A remote peer this host watches (`[[remote]]`) was lost, as `message` says: report
    /// it, and stop safely when `critical`. Default: nothing runs that a loss could stop.
    fn remote_lost(&self, message: &str, critical: bool) {
        tracing::error!("{message} (critical: {critical})");
    }
    /// Optional stop on or off (whether M1 holds the job as M0 does); returns the new state.
    /// A machine without program stops does not support it.
    fn set_optional_stop(&self, on: bool) -> Result<bool, ApiError> {
        let _ = on;
        Err(ApiError::NotSupported("optional stop".into()))
    }
    /// Change overrides.
    fn set_overrides(&self, req: &OverrideRequest) -> Result<Overrides, ApiError> {
        let _ = req;
        Err(self.not_a_machine_error("override"))
    }
    /// The tasks with their interfaces.
    fn tasks(&self) -> Vec<TaskInfo>;
    /// Call a task operation by name with JSON arguments; returns its final status.
    fn call(
        &self,
        task: &str,
        operation: &str,
        args: &serde_json::Value,
    ) -> Result<serde_json::Value, ApiError>;
    /// Set a simulated input (sim backends only).
    fn set_sim_input(&self, name: &str, value: f64) -> Result<(), ApiError> {
        let _ = (name, value);
        Err(self.not_a_machine_error("sim.input"))
    }
    /// Inject a fault into a simulated drive or the servo thread (sim backends only).
    fn sim_fault(&self, fault: &SimFault) -> Result<(), ApiError> {
        let _ = fault;
        Err(self.not_a_machine_error("sim.fault"))
    }
    /// A receiver of machine events (for `subscribe`).
    fn subscribe(&self) -> tokio::sync::broadcast::Receiver<MachineEvent>;
    /// A JSON reader of data object `name` (exporters such as the Zenoh bridge; the reader
    /// is an ordinary lock-free data-object reader, used off the realtime threads).
    fn port_json(&self, name: &str) -> Result<Box<dyn crate::rt::json::JsonPortReader>, ApiError> {
        Err(ApiError::NotSupported(format!(
            "no exportable port '{name}'"
        )))
    }
    /// A JSON subscription to realtime event `name` (`task.event`), queueing up to
    /// `capacity` events (a deferred subscription: the emitter never waits for it).
    fn event_json(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn crate::rt::json::JsonEventReceiver>, ApiError> {
        let _ = capacity;
        Err(ApiError::NotSupported(format!(
            "no exportable event '{name}'"
        )))
    }
    /// Buffer `name`'s items as an ordered JSON stream; the caller becomes the buffer's single
    /// consumer, so only a buffer no task consumes can be had (and only once).
    fn buffer_json(
        &self,
        name: &str,
    ) -> Result<Box<dyn crate::rt::json::JsonEventReceiver>, ApiError> {
        Err(ApiError::NotSupported(format!(
            "no exportable buffer '{name}'"
        )))
    }
    /// The machine's script hosts (programs and state machines), if it deploys any.
    fn scripts(&self) -> Option<&crate::script::ScriptHosts> {
        None
    }
    /// Online access to the machine's PLC, if it has one (`plc.*` methods).
    fn plc(&self) -> Option<&crate::plc::online::PlcOnline> {
        None
    }
    /// Reads object `index:sub` of CANopen drive `drive` by SDO (non-realtime path).
    fn sdo_read(&self, drive: &str, index: u16, sub: u8) -> Result<Vec<u8>, ApiError> {
        let _ = (index, sub);
        Err(ApiError::NotSupported(format!(
            "no CANopen drive '{drive}'"
        )))
    }
    /// Writes `data` to object `index:sub` of CANopen drive `drive` by SDO.
    fn sdo_write(&self, drive: &str, index: u16, sub: u8, data: &[u8]) -> Result<(), ApiError> {
        let _ = (index, sub, data);
        Err(ApiError::NotSupported(format!(
            "no CANopen drive '{drive}'"
        )))
    }
}
