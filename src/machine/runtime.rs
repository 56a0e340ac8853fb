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
use super::feeder::feed;
use super::job::{self, PreparedJob};
use super::mode::{ModeMachine, Request};
use super::probing;
use super::safety::{AxisGuard, Trip};
use super::servo::axis_task::AxisTask;
use super::servo::can_bus::{CanRxTask, CanTxTask};
use super::servo::can_setup::CanSdo;
use super::servo::interp_task::InterpolatorTask;
use super::servo::io_task::{IoTask, SimPlate, SimSpindle};
use super::servo::machine_task::{MachineCmd, MachineSetup, MachineTask, SpindleIo};
use super::servo::monitor_task::MonitorTask;
use super::servo::status::StatusSnapshot;
use super::servo::{
    ports, FaultEvent, JobEvent, JobNews, MachineSnapshot, ModeEvent, QueueItem, Setpoints,
};
use crate::config::{ConfigError, IoKind, MachineConfig};
use crate::gcode::{InterpOptions, SourceLoc, NUM_AXES};
use crate::motion::{self, MotionConfig, AXIS_NAMES};
use crate::rt::deploy::Runtime;
use crate::rt::prelude::{
    buffer, BufferWriter, CommandHandle, CommandStatus, DataReader, Deployment, EventReceiver,
    FullPolicy, OverrunPolicy, Schedule, TaskHandle,
};
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
}

/// A probing job's persistent parameters from its live run, once its last piece is read.
type Measured = Arc<Mutex<Option<crate::gcode::VarFile>>>;

#[derive(Default)]
struct JobBook {
    loaded: Option<Arc<PreparedJob>>,
    active: Option<ActiveJob>,
    status: JobStatus,
    faults: VecDeque<String>,
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
mod remote_loss;
pub use events::describe_trip;
use events::{apply_progress, bridge_loop, internal_operation, Receivers};

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

/// Builds the backends and adds the machine's tasks to a new deployment, in start order
/// io → machine → interpolator → axis.* → monitor, all on the servo thread.
pub fn build(config: &MachineConfig) -> Result<Built, DeployError> {
    let devs = devices::build(config)?;
    let motion_cfg = job::motion_config(config);
    let servo = config
        .servo_thread()
        .ok_or_else(|| DeployError::Invalid("motion.servo_thread names no [[thread]]".into()))?
        .clone();
    let schedule = Schedule {
        priority: i32::from(servo.priority),
        period_ns: u64::from(servo.period_us) * 1000,
        cpu: servo.cpu.map(|c| c as usize),
    };
    let period_s = f64::from(servo.period_us) * 1e-6;
    let axes: Vec<(char, usize)> = config
        .axes
        .iter()
        .map(|a| (axis_letter(a.name as usize), a.name as usize))
        .collect();
    let di = |name: &str| devs.io_map.index(IoKind::DigitalInput, name);
    let dout = |name: &str| devs.io_map.index(IoKind::DigitalOutput, name);
    let aout = |name: &str| devs.io_map.index(IoKind::AnalogOutput, name);
    let estop_input = di(&config.safety.estop_input).ok_or_else(|| {
        DeployError::Invalid(format!(
            "safety.estop_input: no digital input '{}'",
            config.safety.estop_input
        ))
    })?;
    let spindle = config.spindle.as_ref().and_then(|s| {
        Some(SpindleIo {
            enable: dout(&s.enable_output)?,
            direction: s.direction_output.as_deref().and_then(dout),
            speed: s.speed_output.as_deref().and_then(aout),
            at_speed: s.at_speed_input.as_deref().and_then(di),
            max_rpm: s.max_rpm,
        })
    });
    // The simulated plant's spindle: at speed `spin_up_s` after enable, on sim I/O.
    let sim_spindle = config.spindle.as_ref().and_then(|s| {
        let name = s.at_speed_input.as_deref()?;
        let r = config.find_io(name)?;
        let handle = devs.sim_io.get(r.device)?.clone()?;
        let invert = config.io[r.device].digital_inputs[r.channel].invert;
        Some(SimSpindle::new(
            spindle?.enable,
            (handle, r.channel, invert),
            (s.spin_up_s / period_s).ceil() as u32,
        ))
    });
    // Simulated touch plates: the input follows the axis position.
    let plates: Vec<SimPlate> = config
        .io
        .iter()
        .enumerate()
        .filter_map(|(d, dev)| {
            let t = dev.touch_plate.as_ref()?;
            let r = config.find_io(&t.input)?;
            let handle = devs.sim_io.get(d)?.clone()?;
            let invert = dev.digital_inputs.get(r.channel)?.invert;
            Some(SimPlate::new(
                axis_letter(t.axis as usize),
                t.top,
                (handle, r.channel, invert),
            ))
        })
        .collect();
    let homing_groups: Vec<u32> = config
        .homing_order()
        .iter()
        .map(|g| g.iter().fold(0u32, |m, a| m | 1 << (*a as usize)))
        .collect();
    let setup = MachineSetup {
        axes: axes.clone(),
        homing_groups,
        estop_input,
        probe_input: config.motion.probe_input.as_deref().and_then(di),
        spindle,
        flood_output: config.coolant.flood_output.as_deref().and_then(dout),
        mist_output: config.coolant.mist_output.as_deref().and_then(dout),
        safe_outputs: devs.io_map.safe_outputs(),
        max_feed_override: config.motion.max_feed_override,
        max_stale_io_cycles: (0.02 / period_s).ceil() as u32,
        enable_timeout_cycles: (2.0 / period_s) as u32,
        spindle_timeout_cycles: (20.0 / period_s) as u32,
        overrun_event: format!("rt-p{}-{}us.overrun", servo.priority, servo.period_us),
        period_s,
        in_position_window: 0.001,
        settle_timeout_cycles: (1.0 / period_s) as u32,
    };

    let plc = crate::plc::deploy::prepare(config, &devs.io_map, period_s)
        .map_err(DeployError::Invalid)?;
    let (queue_w, queue_r) = buffer::<QueueItem>(QUEUE_CAPACITY, FullPolicy::DropNewest);
    let mut app = Deployment::new();
    app.set_overrun_policy(OverrunPolicy {
        storm_threshold: u64::from(config.safety.overrun_storm_count),
    });
    let devices::Devices {
        axes: axis_devices,
        io,
        io_map,
        sim_axes,
        sim_io,
        can,
        link_events,
    } = devs;
    let crate::machine::servo::can_setup::CanDrives {
        buses: can_buses,
        sdo: can_sdo,
        sim_buses: can_sim_buses,
        ..
    } = can;
    let mut can_tx = Vec::new();
    // CANopen bus owners: rx first of all, tx right after the axis tasks (cycle order).
    for b in can_buses {
        app.add_periodic(&format!("can.{}.rx", b.iface), CanRxTask(b.rx), schedule)?;
        can_tx.push((format!("can.{}.tx", b.iface), CanTxTask(b.tx)));
    }
    let overrun_injection = Arc::new(AtomicU32::new(0));
    let mut io_task = IoTask::new(io, io_map.clone(), sim_spindle).with_plates(plates);
    if sim_io.iter().all(Option::is_some) {
        io_task = io_task.with_overrun_injection(overrun_injection.clone());
    }
    app.add_periodic("io", io_task, schedule)?;
    let estop_request = Arc::new(AtomicU32::new(0));
    let mut machine_task = MachineTask::new(setup).with_estop_request(estop_request.clone());
    if let Some(p) = &plc {
        machine_task = machine_task.with_plc(p.link);
    }
    let machine = app.add_periodic("machine", machine_task, schedule)?;
    app.add_periodic(
        "interpolator",
        InterpolatorTask::new(motion_cfg.clone(), axes.clone(), queue_r),
        schedule,
    )?;
    let mut guards = Vec::new();
    let mut delays = Vec::new();
    for ((name, dev), cfg) in axis_devices.into_iter().zip(&config.axes) {
        let i = name as usize;
        if matches!(dev, devices::AxisDevice::Can(_)) {
            delays.push((i, crate::machine::servo::can_delay::CAN_FEEDBACK_DELAY));
        }
        let letter = axis_letter(i);
        let homing = cfg.home.params();
        app.add_periodic(
            &format!("axis.{letter}"),
            AxisTask::new(letter, i, dev, homing),
            schedule,
        )?;
        guards.push((
            letter,
            i,
            AxisGuard {
                min: cfg.min_limit,
                max: cfg.max_limit,
                following_error_limit: cfg.following_error_limit,
                max_stale_cycles: (0.01 / period_s).ceil() as u32,
            },
        ));
    }
    for (name, task) in can_tx {
        app.add_periodic(&name, task, schedule)?;
    }
    let monitor = delays
        .into_iter()
        .fold(MonitorTask::new(guards), |m, (i, d)| {
            m.with_feedback_delay(i, d)
        });
    app.add_periodic("monitor", monitor, schedule)?;
    // The PLC on its own thread, after the servo tasks (the servo thread stays first).
    let plc_stats = plc.as_ref().map(|p| p.stats.clone());
    let plc_online = plc.as_ref().map(|p| p.online.clone());
    if let Some(p) = plc {
        app.add_periodic("plc", p.task, p.schedule)?;
    }
    Ok(Built {
        plc_stats,
        plc_online,
        app,
        machine,
        queue: queue_w,
        motion_cfg,
        axes,
        sim_io,
        io_map,
        sim_axes: sim_axes
            .into_iter()
            .map(|(n, h)| (axis_letter(n as usize), h))
            .collect(),
        overrun_injection,
        estop_request,
        can_sdo,
        can_sim_buses,
        link_events,
    })
}

impl Machine {
    /// The interpreter options with the persistent parameters as they are now.
    fn interp_opts_now(&self) -> InterpOptions {
        let mut o = self.interp_opts.clone();
        o.parameters = self.params.as_ref().map(|p| p.snapshot());
        o
    }

    /// Deploys `config`: builds backends and tasks, checks the topology, starts the servo
    /// thread. The machine starts in e-stop.
    pub fn deploy(config: MachineConfig) -> Result<Arc<Machine>, DeployError> {
        // Exporters (the Zenoh bridge) read the servo tasks' ports and events as JSON.
        super::servo::json_views::register();
        let params = match &config.gcode.var_file {
            Some(p) => Some(Arc::new(
                crate::gcode::varfile::ParamStore::load(p)
                    .map_err(|e| DeployError::Invalid(format!("gcode.var_file: {e}")))?,
            )),
            None => None,
        };
        if crate::rt::system::lock_memory().is_err() {
            crate::rt::system::warn_not_realtime(
                "mlockall failed (no CAP_IPC_LOCK or RLIMIT_MEMLOCK too low)",
            );
        }
        let Built {
            mut app,
            machine,
            queue: queue_w,
            motion_cfg,
            axes: _,
            sim_io,
            io_map,
            sim_axes,
            overrun_injection,
            estop_request,
            can_sdo,
            can_sim_buses,
            link_events,
            plc_stats,
            plc_online,
        } = build(&config)?;
        let script_tasks = super::scripts::add(&mut app, &config)?;
        let report = app.configure()?;
        let scripts = script_tasks.bind(&app, io_map.clone())?;
        for w in &report.warnings {
            tracing::warn!("topology: {w}");
        }
        let mode_rx = app.event::<ModeEvent>("machine.mode")?.subscribe(256);
        let job_rx = app.event::<JobNews>("machine.job")?.subscribe(1024);
        let fault_rx = app.event::<FaultEvent>("machine.fault")?.subscribe(256);
        let plc_rx = match plc_stats {
            Some(_) => Some(
                app.event::<crate::plc::task::PlcFault>("plc.fault")?
                    .subscribe(16),
            ),
            None => None,
        };
        let readers = Readers {
            status: app.reader(ports::STATUS)?,
        };
        let runtime = match config.servo_thread() {
            Some(t) if t.clock == crate::config::ThreadClock::Simulated => {
                app.start_simulated(match t.sim_speed {
                    None | Some(0) => crate::rt::activity::SimPace::Unpaced,
                    Some(x) => crate::rt::activity::SimPace::Speed(f64::from(x)),
                })?
            }
            _ => app.start()?,
        };
        let servo_info = runtime
            .threads()
            .first()
            .cloned()
            .ok_or_else(|| DeployError::Invalid("no servo thread started".into()))?;
        let (events, _) = broadcast::channel(1024);
        let m = Arc::new(Machine {
            name: config.machine.name.clone(),
            interp_opts: job::interp_options(&config),
            params,
            motion_cfg,
            config,
            runtime: Mutex::new(Some(runtime)),
            machine,
            queue: queue_w,
            readers: Mutex::new(readers),
            book: Arc::new(Mutex::new(JobBook::default())),
            events,
            sim_io,
            io_map,
            overrun_injection,
            estop_request,
            sim_axes,
            can_sdo,
            can_sim_buses,
            next_job: AtomicU32::new(1),
            servo: servo_info,
            bridge_stop: Arc::new(AtomicBool::new(false)),
            bridge: Mutex::new(None),
            receivers: Mutex::new(Some(Receivers {
                mode: mode_rx,
                job: job_rx,
                fault: fault_rx,
                plc: plc_rx,
            })),
            link_events: Mutex::new(link_events),
            plc_stats,
            plc_online,
            scripts,
        });
        let api: std::sync::Weak<dyn MachineApi + Send + Sync> =
            Arc::downgrade(&m) as std::sync::Weak<Machine>;
        m.scripts.start(api).map_err(|e| {
            DeployError::Invalid(format!("cannot start the script operator worker: {e}"))
        })?;
        let weak = Arc::downgrade(&m);
        let stop = m.bridge_stop.clone();
        let bridge = std::thread::Builder::new()
            .name("event-bridge".into())
            .spawn(move || bridge_loop(weak, stop))
            .map_err(|e| DeployError::Invalid(format!("cannot start the event bridge: {e}")))?;
        *lock(&m.bridge) = Some(bridge);
        Ok(m)
    }

    /// The servo thread's shared information (timing statistics, realtime flag).
    pub fn servo_thread(&self) -> &Arc<crate::rt::activity::ThreadInfo> {
        &self.servo
    }

    /// Fault-injection handles of the simulated drives (tests, demos).
    pub fn sim_axis(&self, axis: char) -> Option<&SimAxisHandle> {
        self.sim_axes
            .iter()
            .find(|(c, _)| *c == axis)
            .map(|(_, h)| h)
    }

    /// Runtime SDO access to the CANopen drives (non-realtime; one request per interface
    /// at a time).
    pub fn can_sdo(&self) -> &CanSdo {
        &self.can_sdo
    }

    /// The in-memory bus of the `index`-th `sim` CAN interface (tests take it off).
    pub fn sim_can_bus(&self, index: usize) -> Option<&hytask_hal::sim::SimCanBus> {
        self.can_sim_buses.get(index)
    }

    /// The simulated I/O device `device` (config order), if it is simulated: what the
    /// outputs were told, for tests and demos.
    pub fn sim_io(&self, device: usize) -> Option<&SimIoHandle> {
        self.sim_io.get(device).and_then(Option::as_ref)
    }

    /// Sends a command and waits until the machine task accepted or rejected it.
    fn command(&self, cmd: MachineCmd) -> Result<CommandHandle, ApiError> {
        let h = self
            .machine
            .send(cmd)
            .map_err(|e| ApiError::Rejected(e.to_string()))?;
        let status = h.wait_accepted(ACCEPT_TIMEOUT);
        self.wait_for_cycle_end();
        match status {
            CommandStatus::Rejected(r) => Err(ApiError::Rejected(r.to_string())),
            CommandStatus::Failed(why) => Err(ApiError::Failed(why.into())),
            CommandStatus::Pending => Err(ApiError::Timeout(
                "the machine task did not take the command".into(),
            )),
            _ => Ok(h),
        }
    }

    /// Waits until the servo cycle running now has finished (the next one has started). A
    /// command is accepted in the middle of a cycle and the machine task publishes its state
    /// at the end of it: waiting makes a command's effect visible in `status` by the time
    /// the operator's call returns. At most one servo period.
    fn wait_for_cycle_end(&self) {
        let now = self.servo.stats.wakeup.summary().count;
        let t0 = Instant::now();
        while self.servo.stats.wakeup.summary().count <= now
            && self.servo.running()
            && t0.elapsed() < Duration::from_millis(100)
        {
            std::thread::sleep(Duration::from_micros(100));
        }
    }

    /// Sends a command and waits for its completion condition.
    fn command_done(&self, cmd: MachineCmd, timeout: Duration) -> Result<(), ApiError> {
        let h = self.command(cmd)?;
        match h.wait(timeout) {
            CommandStatus::Done => Ok(()),
            CommandStatus::Failed(why) => Err(ApiError::Failed(why.into())),
            CommandStatus::Rejected(r) => Err(ApiError::Rejected(r.to_string())),
            _ => Err(ApiError::Timeout("the command did not complete".into())),
        }
    }

    /// What the realtime side published, all of it from one servo cycle.
    fn snapshot(&self) -> StatusSnapshot {
        lock(&self.readers).status.latest().unwrap_or_default()
    }

    /// The machine's actual pose (machine frame).
    fn actual_pose(&self) -> [f64; NUM_AXES] {
        let st = self.snapshot();
        let mut pose = st.setpoints.pose_mm;
        for (_, i) in self.axes() {
            if st.feedback[i].valid {
                pose[i] = st.feedback[i].actual;
            }
        }
        pose
    }

    /// The probe input as the last servo cycle saw it (`None`: the machine has none).
    fn probe_active(&self) -> Option<bool> {
        let name = self.config.motion.probe_input.as_deref()?;
        let i = self.io_map.di.iter().position(|c| c.point.name == name)?;
        Some(self.snapshot().inputs.di(i))
    }

    /// Refuses a run or jog the machine cannot take now (e-stop, off, fault, not homed,
    /// busy), with the machine task's own reason: checked before anything about the job, so
    /// that the operator hears about the e-stop, not about a job planned elsewhere.
    fn check_can_run(&self, manual: bool) -> Result<(), ApiError> {
        let snap = self.snapshot().machine;
        let all = self.axes().iter().fold(0u32, |m, &(_, i)| m | 1 << i);
        let homed = snap.homed_mask & all == all;
        let req = if manual { Request::Jog } else { Request::Run };
        ModeMachine::check(snap.mode, req, homed || manual)
            .map_err(|why| ApiError::Rejected(why.into()))
    }

    /// Starts a prepared job (or jog/MDI) as job `id`: feeder first, then the `run` command.
    fn start_job(&self, job: Arc<PreparedJob>, manual: bool) -> Result<(), ApiError> {
        self.check_can_run(manual)?;
        // The end of the previous job may still wait in the event queue (the machine task
        // emits it in the cycle whose snapshot said idle). Applying it now, while that job
        // is still the active one, publishes its end and joins its feeder before this job
        // replaces it. (Events carry their job id, so a late one could not end this job
        // either: that was the benchmark's hung `mdi M8`.)
        self.pump_events();
        probing::check_probe_start(&job, self.probe_active())?;
        let pose = self.actual_pose();
        for &(c, i) in self.axes().iter() {
            if (job.plan.start_mm[i] - pose[i]).abs() > 0.01 {
                return Err(ApiError::Rejected(format!(
                    "axis {c} is at {:.4}, the job was planned from {:.4}: load it again",
                    pose[i], job.plan.start_mm[i]
                )));
            }
        }
        let id = self.next_job.fetch_add(1, Ordering::Relaxed);
        let cancel = Arc::new(AtomicBool::new(false));
        let messages = Arc::new(Mutex::new(Vec::new()));
        let measured = Arc::new(Mutex::new(None));
        let (feeder, items) = match &job.probing {
            None => {
                lock(&messages).clone_from(&job.plan.messages);
                let queue = self.queue.clone();
                let items = job.clone();
                let cancel = cancel.clone();
                let (book, machine) = (self.book.clone(), self.machine.clone());
                let servo = self.servo.clone();
                let feeder = std::thread::Builder::new()
                    .name(format!("feeder-{id}"))
                    .spawn(move || match &items.replay {
                        None => {
                            feed(&queue, &items.plan.items, id, &cancel, &servo);
                        }
                        // A large job is planned again as it runs (see `job`).
                        Some(replay) => {
                            let run = replay
                                .run_ahead(&mut |batch| feed(&queue, batch, id, &cancel, &servo));
                            if let Err(msg) = run {
                                tracing::error!("job {id}: {msg}");
                                if let Some(a) = lock(&book).active.as_mut().filter(|a| a.id == id)
                                {
                                    a.error = Some(msg);
                                }
                                if let Ok(h) = machine.send(MachineCmd::Abort) {
                                    let _ = h.wait_accepted(ACCEPT_TIMEOUT);
                                }
                            }
                        }
                    })
                    .map_err(|e| ApiError::Failed(format!("cannot start the feeder: {e}")))?;
                (feeder, job.item_count())
            }
            Some(src) => self.start_piece_runner(src, &job, id, &cancel, (&messages, &measured))?,
        };
        let mut book = lock(&self.book);
        book.status = JobStatus {
            name: job.name.clone(),
            state: "running".into(),
            line: 0,
            total_lines: job.total_lines,
            progress: 0.0,
            planned_time_s: job.plan.duration_s,
            elapsed_s: 0.0,
            distance_mm: job.plan.distance_mm,
            distance_to_go_mm: job.plan.distance_mm,
            reason: None,
        };
        let previous = book.active.replace(ActiveJob {
            id,
            job,
            cancel: cancel.clone(),
            feeder: Some(feeder),
            started: Instant::now(),
            manual,
            messages,
            error: None,
            measured,
        });
        drop(book);
        if let Some(mut p) = previous {
            p.cancel.store(true, Ordering::Release);
            if let Some(f) = p.feeder.take() {
                let _ = f.join();
            }
        }
        match self.command(MachineCmd::Run {
            job: id,
            items,
            manual,
        }) {
            Ok(_) => Ok(()),
            Err(e) => {
                cancel.store(true, Ordering::Release);
                let mut book = lock(&self.book);
                if let Some(mut a) = book.active.take() {
                    if let Some(f) = a.feeder.take() {
                        drop(book);
                        let _ = f.join();
                        book = lock(&self.book);
                    }
                }
                book.status.state = "none".into();
                Err(e)
            }
        }
    }

    /// A probing job: plans its first piece now (from the machine's position) and starts
    /// the thread that queues it and the pieces after each probe. Returns the thread and the
    /// first piece's item count.
    fn start_piece_runner(
        &self,
        src: &probing::ProbingSource,
        job: &PreparedJob,
        id: u32,
        cancel: &Arc<AtomicBool>,
        (messages, measured): (&Arc<Mutex<Vec<String>>>, &Measured),
    ) -> Result<(std::thread::JoinHandle<()>, u64), ApiError> {
        if self.config.motion.probe_input.is_none() {
            let line = job::first_probe_line_of(job).unwrap_or(0);
            return Err(ApiError::Rejected(format!(
                "{}: line {line} probes (G38.x) but the machine has no probe input \
                 (set motion.probe_input)",
                job.name
            )));
        }
        let mut first = probing::first_piece(src, &self.motion_cfg, job.plan.start_mm)?;
        probing::append_messages(&mut first.plan, messages);
        let items = first.plan.items.len() as u64;
        let snapshot = lock(&self.runtime)
            .as_ref()
            .ok_or_else(|| ApiError::Failed("the machine is shutting down".into()))?
            .reader::<MachineSnapshot>(ports::SNAPSHOT)
            .map_err(|e| ApiError::Failed(e.to_string()))?;
        let runner = probing::PieceRunner {
            queue: self.queue.clone(),
            machine: self.machine.clone(),
            snapshot,
            cfg: self.motion_cfg.clone(),
            job: id,
            name: job.name.clone(),
            cancel: cancel.clone(),
            seen_probe_seq: self.snapshot().machine.probe.seq,
            servo: self.servo.clone(),
            messages: messages.clone(),
            parameters: measured.clone(),
        };
        let book = self.book.clone();
        let machine = self.machine.clone();
        let thread = std::thread::Builder::new()
            .name(format!("pieces-{id}"))
            .spawn(move || {
                if let probing::RunnerEnd::Failed(msg) = runner.run(first) {
                    tracing::error!("job {id}: {msg}");
                    if let Some(a) = lock(&book).active.as_mut().filter(|a| a.id == id) {
                        a.error = Some(msg);
                    }
                    if let Ok(h) = machine.send(MachineCmd::Abort) {
                        let _ = h.wait_accepted(ACCEPT_TIMEOUT);
                    }
                }
            })
            .map_err(|e| ApiError::Failed(format!("cannot start the job thread: {e}")))?;
        Ok((thread, items))
    }

    fn axes(&self) -> Vec<(char, usize)> {
        self.config
            .axes
            .iter()
            .map(|a| (axis_letter(a.name as usize), a.name as usize))
            .collect()
    }

    fn publish(&self, topic: &str, data: Value) {
        let _ = self.events.send(MachineEvent {
            topic: topic.into(),
            data,
        });
    }
}

impl MachineApi for Machine {
    fn plc(&self) -> Option<&crate::plc::online::PlcOnline> {
        self.plc_online.as_deref()
    }

    fn scripts(&self) -> Option<&crate::script::ScriptHosts> {
        Some(self.scripts.hosts())
    }

    fn status(&self) -> Status {
        // One read: every value below belongs to servo cycle `st.cycle`.
        let st = self.snapshot();
        let (snap, sp, mon) = (&st.machine, &st.setpoints, &st.monitor);
        self.pump_events();
        let axes = self
            .axes()
            .into_iter()
            .map(|(c, i)| {
                let f = st.feedback[i];
                AxisStatus {
                    name: c.to_string(),
                    commanded: sp.joints[i],
                    actual: f.actual,
                    velocity: f.velocity,
                    following_error: mon.following_error[i],
                    max_following_error: mon.max_following_error[i],
                    homed: f.homed,
                    drive_state: f.state.to_string(),
                    fault: f.fault.map(|c| format!("0x{c:04X}")),
                }
            })
            .collect();
        let threads = lock(&self.runtime)
            .as_ref()
            .map(|rt| super::task_api::thread_timings(&rt.threads()))
            .unwrap_or_default();
        let (inputs, outputs) = (st.inputs, st.outputs);
        let map = &self.io_map;
        let mut in_map = std::collections::BTreeMap::new();
        for (i, c) in map.di.iter().enumerate() {
            in_map.insert(c.point.name.clone(), f64::from(u8::from(inputs.di(i))));
        }
        for (i, c) in map.ai.iter().enumerate() {
            in_map.insert(c.point.name.clone(), inputs.analog[i]);
        }
        let mut out_map = std::collections::BTreeMap::new();
        for (i, c) in map.dout.iter().enumerate() {
            let on = outputs.digital & (1 << i) != 0;
            out_map.insert(c.point.name.clone(), f64::from(u8::from(on)));
        }
        for (i, c) in map.ao.iter().enumerate() {
            out_map.insert(c.point.name.clone(), outputs.analog[i]);
        }
        let book = lock(&self.book);
        let mut job = book.status.clone();
        if let Some(a) = &book.active {
            apply_progress(&mut job, a, sp);
        }
        let mut faults: Vec<String> = book.faults.iter().cloned().collect();
        if matches!(snap.mode, Mode::Fault | Mode::Estop) {
            if let Some(t) = snap.last_trip {
                let msg = describe_trip(&t, 0);
                if !faults.iter().any(|f| f.starts_with(&msg)) {
                    faults.push(msg);
                }
            }
        } else {
            faults.clear();
        }
        Status {
            machine: self.name.clone(),
            mode: snap.mode,
            realtime: self.servo.realtime(),
            servo_cycle: st.cycle,
            axes,
            job,
            overrides: Overrides {
                feed: snap.feed_override,
                rapid: snap.rapid_override,
                spindle: snap.spindle_override,
            },
            spindle_rpm: snap.spindle_rpm,
            faults,
            threads,
            inputs: in_map,
            outputs: out_map,
            probe: ProbeStatus {
                count: snap.probe.seq,
                line: snap.probe.line,
                tripped: snap.probe.tripped,
                position: self
                    .axes()
                    .iter()
                    .map(|&(c, i)| (c.to_string(), snap.probe.probed_mm[i]))
                    .collect(),
            },
            optional_stop: snap.optional_stop,
            plc: self
                .plc_stats
                .as_deref()
                .map(crate::plc::task::PlcStats::status),
        }
    }

    /// Not a queued command: the machine task reads the request counter every cycle, so an
    /// e-stop is taken in the next cycle even when its command slots are all busy.
    fn estop(&self) -> Result<(), ApiError> {
        self.estop_request.fetch_add(1, Ordering::AcqRel);
        let t0 = Instant::now();
        loop {
            self.wait_for_cycle_end();
            if self.snapshot().machine.mode == Mode::Estop {
                return Ok(());
            }
            if !self.servo.running() || t0.elapsed() > ACCEPT_TIMEOUT {
                return Err(ApiError::Timeout(
                    "the machine task did not enter e-stop".into(),
                ));
            }
        }
    }

    fn estop_reset(&self) -> Result<(), ApiError> {
        lock(&self.book).faults.clear();
        self.command_done(MachineCmd::EstopReset, ACCEPT_TIMEOUT)
    }

    fn machine_on(&self) -> Result<(), ApiError> {
        lock(&self.book).faults.clear();
        self.command_done(MachineCmd::On, Duration::from_secs(5))
    }

    fn machine_off(&self) -> Result<(), ApiError> {
        self.command_done(MachineCmd::Off, Duration::from_secs(30))
    }

    fn home(&self, axis: Option<&str>) -> Result<(), ApiError> {
        let mask = match axis {
            None => 0,
            Some(a) => {
                let up = a.to_ascii_uppercase();
                let (_, i) = self
                    .axes()
                    .into_iter()
                    .find(|(c, _)| up.len() == 1 && up.starts_with(*c))
                    .ok_or_else(|| ApiError::InvalidParams(format!("no axis '{a}'")))?;
                1u32 << i
            }
        };
        self.command(MachineCmd::Home { mask }).map(|_| ())
    }

    fn jog(&self, req: &JogRequest) -> Result<(), ApiError> {
        self.check_can_run(true)?;
        let up = req.axis.to_ascii_uppercase();
        let (_, i) = self
            .axes()
            .into_iter()
            .find(|(c, _)| up.len() == 1 && up.starts_with(*c))
            .ok_or_else(|| ApiError::InvalidParams(format!("no axis '{}'", req.axis)))?;
        let lim = self.motion_cfg.axes[i];
        let speed = req.velocity.abs().min(lim.max_vel_mm_s);
        let start = self.actual_pose();
        let mut end = start;
        end[i] = match req.distance {
            Some(d) => start[i] + d.copysign(req.velocity),
            None if req.velocity > 0.0 => lim.max_mm,
            None => lim.min_mm,
        };
        if (end[i] - start[i]).abs() < 1e-9 {
            return Err(ApiError::Rejected(format!(
                "axis {} is already at its soft limit",
                up
            )));
        }
        let loc = SourceLoc {
            file: Arc::from("jog"),
            line: 1,
            col: 1,
        };
        let plan = motion::plan_straight_feed(start, end, speed * 60.0, loc, &self.motion_cfg)
            .map_err(|e| ApiError::Rejected(format!("jog: {e}")))?;
        let job = Arc::new(PreparedJob {
            name: "jog".into(),
            total_lines: 1,
            commands: 2, // SetFeedRate + StraightFeed
            plan,
            probing: None,
            replay: None,
            parameters: None,
        });
        self.start_job(job, true)
    }

    fn jog_stop(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Abort).map(|_| ())
    }

    fn mdi(&self, line: &str) -> Result<(), ApiError> {
        self.check_can_run(false)?;
        let job = job::prepare_mdi(
            line,
            &self.interp_opts_now(),
            &self.motion_cfg,
            self.actual_pose(),
        )?;
        self.start_job(Arc::new(job), false)
    }

    fn job_load(&self, src: &JobSource) -> Result<JobInfo, ApiError> {
        let opts = self.interp_opts_now();
        let job = job::prepare(src, &opts, &self.motion_cfg, self.actual_pose())?;
        let info = JobInfo {
            name: job.name.clone(),
            lines: job.total_lines,
            commands: job.commands,
            planned_time_s: job.plan.duration_s,
            distance_mm: job.plan.distance_mm,
        };
        let mut book = lock(&self.book);
        if book.active.is_none() {
            book.status = JobStatus {
                name: job.name.clone(),
                state: "loaded".into(),
                total_lines: job.total_lines,
                planned_time_s: job.plan.duration_s,
                distance_mm: job.plan.distance_mm,
                distance_to_go_mm: job.plan.distance_mm,
                ..JobStatus::default()
            };
        }
        book.loaded = Some(Arc::new(job));
        Ok(info)
    }

    fn job_run(&self) -> Result<(), ApiError> {
        self.check_can_run(false)?;
        let job = lock(&self.book)
            .loaded
            .clone()
            .ok_or_else(|| ApiError::Rejected("no job loaded".into()))?;
        self.start_job(job, false)
    }

    fn job_pause(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Pause).map(|_| ())
    }

    fn job_resume(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Resume).map(|_| ())
    }

    fn job_abort(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Abort).map(|_| ())
    }

    fn remote_lost(&self, message: &str, critical: bool) {
        self.stop_for_lost_remote(message, critical);
    }

    fn job_step(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Step).map(|_| ())
    }

    fn set_optional_stop(&self, on: bool) -> Result<bool, ApiError> {
        self.command(MachineCmd::OptionalStop { on })?;
        Ok(self.snapshot().machine.optional_stop)
    }

    fn set_overrides(&self, req: &OverrideRequest) -> Result<Overrides, ApiError> {
        let snap = self.snapshot().machine;
        let feed = req.feed.unwrap_or(snap.feed_override);
        if feed > self.config.motion.max_feed_override {
            return Err(ApiError::InvalidParams(format!(
                "feed override above this machine's maximum {}",
                self.config.motion.max_feed_override
            )));
        }
        let cmd = MachineCmd::Overrides {
            feed,
            rapid: req.rapid.unwrap_or(snap.rapid_override),
            spindle: req.spindle.unwrap_or(snap.spindle_override),
        };
        self.command(cmd)?;
        Ok(Overrides {
            feed,
            rapid: req.rapid.unwrap_or(snap.rapid_override),
            spindle: req.spindle.unwrap_or(snap.spindle_override),
        })
    }

    fn tasks(&self) -> Vec<TaskInfo> {
        lock(&self.runtime)
            .as_ref()
            .map(|rt| super::task_api::task_infos(rt.tasks()))
            .unwrap_or_default()
    }

    fn port_json(&self, name: &str) -> Result<Box<dyn crate::rt::json::JsonPortReader>, ApiError> {
        let rt = lock(&self.runtime);
        let rt = rt
            .as_ref()
            .ok_or_else(|| ApiError::Rejected("the machine is stopped".into()))?;
        rt.json_reader(name)
            .map_err(|e| ApiError::InvalidParams(e.to_string()))
    }

    fn event_json(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn crate::rt::json::JsonEventReceiver>, ApiError> {
        let rt = lock(&self.runtime);
        let rt = rt
            .as_ref()
            .ok_or_else(|| ApiError::Rejected("the machine is stopped".into()))?;
        rt.json_events(name, capacity)
            .map_err(|e| ApiError::InvalidParams(e.to_string()))
    }

    fn sdo_read(&self, drive: &str, index: u16, sub: u8) -> Result<Vec<u8>, ApiError> {
        self.can_sdo.read(drive, index, sub).map_err(sdo_error)
    }

    fn sdo_write(&self, drive: &str, index: u16, sub: u8, data: &[u8]) -> Result<(), ApiError> {
        self.can_sdo
            .write(drive, index, sub, data)
            .map_err(sdo_error)
    }

    fn call(&self, task: &str, operation: &str, args: &Value) -> Result<Value, ApiError> {
        if let Some(instead) = internal_operation(task, operation) {
            return Err(ApiError::Rejected(format!(
                "{task}.{operation} is the job machinery's own operation (it refers to queue \
                 items only a running job has): use {instead}"
            )));
        }
        let handle = {
            let rt = lock(&self.runtime);
            let rt = rt
                .as_ref()
                .ok_or_else(|| ApiError::Rejected("the machine is stopped".into()))?;
            super::task_api::send_call(rt.tasks(), task, operation, args)?
        };
        super::task_api::call_reply(&handle, task)
    }

    fn set_sim_input(&self, name: &str, value: f64) -> Result<(), ApiError> {
        let r = self
            .config
            .find_io(name)
            .ok_or_else(|| ApiError::InvalidParams(format!("no I/O channel '{name}'")))?;
        let handle = self
            .sim_io
            .get(r.device)
            .and_then(Option::as_ref)
            .ok_or_else(|| {
                ApiError::NotSupported(format!("'{name}' is not on a simulated device"))
            })?;
        let dev = &self.config.io[r.device];
        let res = match r.kind {
            IoKind::DigitalInput => {
                let level = dev.digital_inputs[r.channel].level(value != 0.0);
                handle.set_digital_input(r.channel, level)
            }
            IoKind::AnalogInput => {
                let raw = dev.analog_inputs[r.channel].to_raw(value);
                handle.set_analog_input(r.channel, raw)
            }
            _ => {
                return Err(ApiError::InvalidParams(format!(
                    "'{name}' is an output, not an input"
                )))
            }
        };
        res.map_err(|e| ApiError::Failed(e.to_string()))
    }

    fn sim_fault(&self, f: &SimFault) -> Result<(), ApiError> {
        if f.kind == "overrun" {
            if self.sim_io.iter().any(Option::is_none) {
                return Err(ApiError::NotSupported(
                    "overrun injection needs an all-simulated machine".into(),
                ));
            }
            let cycles = f.cycles.unwrap_or(5).clamp(1, 1000);
            self.overrun_injection.store(cycles, Ordering::Release);
            return Ok(());
        }
        let axis = f
            .axis
            .as_deref()
            .ok_or_else(|| ApiError::InvalidParams(format!("'{}' needs an axis", f.kind)))?;
        let letter = axis.to_ascii_uppercase().chars().next().unwrap_or('?');
        let h = self.sim_axis(letter).ok_or_else(|| {
            ApiError::NotSupported(format!("axis '{axis}' is not a simulated drive"))
        })?;
        let on = f.on.unwrap_or(true);
        match f.kind.as_str() {
            "drive_fault" => h.inject_fault(hytask_hal::axis::FaultCode(f.code.unwrap_or(0x2310))),
            "stall" => h.set_stalled(on),
            "disconnect" => h.set_disconnected(on),
            other => {
                return Err(ApiError::InvalidParams(format!(
                    "unknown fault kind '{other}' (drive_fault, stall, disconnect, overrun)"
                )))
            }
        }
        Ok(())
    }

    fn subscribe(&self) -> broadcast::Receiver<MachineEvent> {
        self.events.subscribe()
    }
}

impl crate::daemon::Deployed for Machine {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn realtime(&self) -> bool {
        // The servo thread sets its flag when it starts: wait for that, briefly.
        let t0 = Instant::now();
        while !self.servo.running() && t0.elapsed() < Duration::from_secs(1) {
            std::thread::sleep(Duration::from_millis(1));
        }
        self.servo.realtime()
    }

    fn servo_cycles(&self) -> u64 {
        self.servo.stats.summary().wakeup.count
    }

    fn shutdown(&self) -> anyhow::Result<()> {
        // No script command is carried out once the machine goes down.
        self.scripts.stop();
        // A controlled stop of whatever moves, then drives off, then threads down.
        let snap = self.snapshot().machine;
        if snap.mode == Mode::Fault {
            // A fault has already stopped the axes under control and disabled the drives; the
            // machine does not take `Off` in that mode, so waiting for it would outlast
            // systemd's stop timeout. The e-stop puts the outputs in their safe state at once.
            let _ = self.command(MachineCmd::Estop);
            std::thread::sleep(Duration::from_millis(200));
        } else if !matches!(snap.mode, Mode::Estop | Mode::Off) {
            if let Err(e) = self.command_done(MachineCmd::Off, Duration::from_secs(30)) {
                tracing::warn!("controlled stop at shutdown: {e}; tripping the e-stop");
                let _ = self.command(MachineCmd::Estop);
                std::thread::sleep(Duration::from_millis(200));
            }
        }
        self.bridge_stop.store(true, Ordering::Release);
        if let Some(b) = lock(&self.bridge).take() {
            let _ = b.join();
        }
        if let Some(rt) = lock(&self.runtime).take() {
            let _ = rt.stop();
        }
        if let Some(p) = &self.params {
            if let Err(e) = p.save() {
                tracing::warn!("saving {}: {e}", p.path().display());
            }
        }
        Ok(())
    }
}
