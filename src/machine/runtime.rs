//! A deployed, running machine: the realtime tasks on the servo thread, the segment queue
//! and its feeder, the event bridge, and the [`MachineApi`] operators use.
//!
//! Configuration flow ([`Machine::deploy`]): build the HAL backends from the config, create
//! the tasks (io → machine → interpolator → axes → monitor, one servo thread), configure
//! them, check the topology (the deployment refuses to start with any error, each naming
//! task and port), subscribe the non-realtime receivers, start the thread.
//!
//! The non-realtime side talks to the tasks only through commands (to the `machine` task),
//! the segment queue (a bounded lock-free buffer filled by a feeder thread, one per running
//! job) and data objects/events read here.

use super::api::*;
use super::devices;
use super::job::PreparedJob;
use super::job_cancel;
use super::safety::Trip;
use super::servo::can_setup::CanSdo;
use super::servo::machine_task::MachineCmd;
use super::servo::status::StatusSnapshot;
use super::servo::{FaultEvent, JobEvent, JobNews, ModeEvent, QueueItem, Setpoints};
use crate::config::{ConfigError, MachineConfig};
use crate::gcode::{InterpOptions, NUM_AXES};
use crate::motion::{MotionConfig, AXIS_NAMES};
use crate::rt::deploy::Runtime;
use crate::rt::prelude::{BufferWriter, DataReader, Deployment, EventReceiver, TaskHandle};
use hytask_hal::sim::{SimAxisHandle, SimIoHandle};
use serde_json::{json, Value};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

/// Segment queue capacity, items. Preallocated at deployment.
pub const QUEUE_CAPACITY: usize = 4096;
/// How long an operator call waits for the machine task to accept or reject.
const ACCEPT_TIMEOUT: Duration = Duration::from_secs(2);
/// Faults kept for `status`.
const FAULT_HISTORY: usize = 16;

/// Why a machine could not be deployed.
#[derive(Debug, thiserror::Error)]
pub enum DeployError {
    /// The configuration is invalid or names unavailable backends.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The realtime core refused the topology or could not start a thread.
    #[error("realtime deployment: {0}")]
    Rt(#[from] crate::rt::deploy::DeployError),
    /// Something the configuration implies is missing.
    #[error("{0}")]
    Invalid(String),
}

/// Non-realtime readers of the tasks' data objects: one, the status snapshot the monitor
/// publishes at the end of each servo cycle, so that everything read together belongs to
/// one cycle.
struct Readers {
    status: DataReader<StatusSnapshot>,
}

/// A job that is running, and its feeder.
struct ActiveJob {
    id: u32,
    job: Arc<PreparedJob>,
    cancel: Arc<AtomicBool>,
    feeder: Option<std::thread::JoinHandle<()>>,
    started: Instant,
    manual: bool,
    /// Texts of its `(MSG, …)` items (a probing job's grow piece by piece).
    messages: Arc<Mutex<Vec<String>>>,
    /// Why the job failed off the realtime path (a piece after a probe did not interpret
    /// or plan); the machine task only sees the abort this causes.
    error: Option<String>,
    /// A probing job's persistent parameters from its live run (see `probing`).
    measured: Measured,
    /// The file its log comments write (see `job_log`).
    log: job_log::JobLog,
}

/// A probing job's persistent parameters from its live run, once its last piece is read.
type Measured = Arc<Mutex<Option<crate::gcode::VarFile>>>;

#[derive(Default)]
struct JobBook {
    loaded: Option<Arc<PreparedJob>>,
    active: Option<ActiveJob>,
    status: JobStatus,
    faults: VecDeque<String>,
    /// Servo cycle of the newest job event applied to `status` (see `Machine::status`).
    news_cycle: u64,
}

/// A running machine.
pub struct Machine {
    name: String,
    config: MachineConfig,
    motion_cfg: MotionConfig,
    interp_opts: InterpOptions,
    /// `[gcode] var_file`: persistent parameters, committed when a job has run to its end.
    pub(super) params: Option<Arc<crate::gcode::varfile::ParamStore>>,
    runtime: Mutex<Option<Runtime>>,
    machine: TaskHandle<MachineCmd>,
    queue: BufferWriter<QueueItem>,
    readers: Mutex<Readers>,
    book: Arc<Mutex<JobBook>>,
    events: broadcast::Sender<MachineEvent>,
    sim_io: Vec<Option<SimIoHandle>>,
    io_map: devices::IoMap,
    overrun_injection: Arc<AtomicU32>,
    estop_request: Arc<AtomicU32>,
    sim_axes: Vec<(char, SimAxisHandle)>,
    can_sdo: CanSdo,
    can_sim_buses: Vec<hytask_hal::sim::SimCanBus>,
    next_job: AtomicU32,
    servo: Arc<crate::rt::activity::ThreadInfo>,
    bridge_stop: Arc<AtomicBool>,
    bridge: Mutex<Option<std::thread::JoinHandle<()>>>,
    receivers: Mutex<Option<Receivers>>,
    /// Modbus link events, published as topic `io` by the bridge.
    link_events: Mutex<Option<std::sync::mpsc::Receiver<crate::modbus::LinkEvent>>>,
    /// Scan statistics of the PLC task.
    plc_stats: Option<Arc<crate::plc::task::PlcStats>>,
    /// Online access to the PLC (`plc.*` methods).
    plc_online: Option<Arc<crate::plc::online::PlcOnline>>,
    /// The script host (tasks `cnc` and `scripts`) and its operator worker.
    scripts: super::scripts::Scripts,
}

mod events;
mod job_log;
mod remote_loss;
pub use events::describe_trip;
use events::Receivers;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn axis_letter(i: usize) -> char {
    AXIS_NAMES.get(i).copied().unwrap_or('?')
}

fn sdo_error(e: crate::machine::servo::can_setup::SdoError) -> ApiError {
    match e {
        crate::machine::servo::can_setup::SdoError::UnknownDrive(_) => {
            ApiError::InvalidParams(e.to_string())
        }
        crate::machine::servo::can_setup::SdoError::Transfer(m) => ApiError::Failed(m),
    }
}

/// The machine's tasks, added to a deployment that is not configured yet, with the handles
/// the non-realtime side needs. [`Machine::deploy`] configures and starts it on real threads;
/// tests start it on the stepped runtime with simulated time.
pub struct Built {
    /// The deployment (tasks added, not configured).
    pub app: Deployment,
    /// The machine task's command sender.
    pub machine: TaskHandle<MachineCmd>,
    /// Producer side of the segment queue.
    pub queue: BufferWriter<QueueItem>,
    /// The planner's configuration.
    pub motion_cfg: MotionConfig,
    /// Axis letters and pose indices, in configuration order.
    pub axes: Vec<(char, usize)>,
    /// Input handles of simulated I/O devices.
    pub sim_io: Vec<Option<SimIoHandle>>,
    /// Machine-wide channel numbering.
    pub io_map: devices::IoMap,
    /// Fault-injection handles of simulated drives.
    pub sim_axes: Vec<(char, SimAxisHandle)>,
    /// Overrun injection counter (simulated machines).
    pub overrun_injection: Arc<AtomicU32>,
    /// E-stop requests to the machine task (see [`MachineTask::with_estop_request`]).
    pub estop_request: Arc<AtomicU32>,
    /// Runtime SDO access to CANopen drives.
    pub can_sdo: CanSdo,
    /// In-memory buses of `sim` CAN interfaces.
    pub can_sim_buses: Vec<hytask_hal::sim::SimCanBus>,
    /// Modbus link events (`None` without Modbus devices).
    pub link_events: Option<std::sync::mpsc::Receiver<crate::modbus::LinkEvent>>,
    /// Scan statistics of the PLC task (`None` without `[plc]`).
    pub plc_stats: Option<Arc<crate::plc::task::PlcStats>>,
    /// Online access to the PLC (`None` without `[plc]`).
    pub plc_online: Option<Arc<crate::plc::online::PlcOnline>>,
}

mod build;
mod commands;
mod deploy;
mod machine_api;
mod shutdown;

pub use build::build;
