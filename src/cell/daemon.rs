//! The cell served on the control socket: [`CellDaemon`] implements the daemon's
//! [`Deployed`] / [`MachineApi`] traits, so `hytask serve --config config/pickplace.toml` and
//! the embedded daemon of `hytask run-cell` serve a cell exactly as they serve a mill.
//!
//! What the operator API means for a cell: `status` reports the robot as three axes, the
//! selection as the job (state, runs done of runs asked, error), the gripper and e-stop as
//! inputs and the containers' counts as outputs (`container.A`, `container.B`,
//! `container.reject`, `floor`); `estop` / `estop.reset` / `machine.on` / `machine.off` map
//! to the robot's `emergency_stop` / `reset` / `switch_on` / `switch_off`; `tasks` and `call`
//! reach every task's operations (`call selection run {"n": 20}`). G-code, jog and homing
//! are not supported. The cell's events are pushed on topic `task`
//! (`{"event": "selection.operation_n_done", "run": 3, "of": 20, "container": "a", ...}`),
//! and `selection.error_detected` also on topic `fault`.

use super::config::CellFile;
use super::deploy::deploy_with;
use super::names;
use super::remote::RemoteCamera;
use super::robot::RobotCmd;
use super::selection::SelectionStatus;
use super::types::{Container, RobotState, RobotStatus, RunDone, Setpoint, WorldTally};
use crate::daemon::Deployed;
use crate::machine::api::*;
use crate::machine::task_api;
use crate::rt::deploy::Runtime;
use crate::rt::prelude::{
    CommandSender, CommandStatus, DataReader, DeployError, Deployment, EventReceiver,
};
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use tokio::sync::broadcast;

struct Readers {
    robot: DataReader<RobotStatus>,
    selection: DataReader<SelectionStatus>,
    tally: DataReader<WorldTally>,
    setpoint: DataReader<Setpoint>,
}

/// A deployed, running cell.
pub struct CellDaemon {
    name: String,
    runtime: Mutex<Option<Runtime>>,
    robot: CommandSender<RobotCmd>,
    readers: Mutex<Readers>,
    events: broadcast::Sender<MachineEvent>,
    stop_bridge: Arc<AtomicBool>,
    bridge: Mutex<Option<std::thread::JoinHandle<()>>>,
    /// The selection task's script host (empty with the Rust selection).
    scripts: crate::script::ScriptHosts,
    /// Threads on simulated time (never realtime).
    simulated: bool,
    /// The camera's peer process, if remote: kept open while the cell runs.
    _remote: Option<RemoteCamera>,
}

/// How long [`CellDaemon`]'s `realtime` waits for every thread's first cycle (a hang
/// guard: a thread's first cycle comes one period after the start).
const THREADS_REPORT: Duration = Duration::from_secs(5);

/// Whether every thread of `threads` runs realtime, read once each has reported. A thread
/// sets its flag in its own setup, before its first cycle: read right after `start`, it
/// said `false` for threads that had not run yet (`hytask run-cell` as root printed "not
/// realtime"). A counted wake-up means the setup is over.
pub fn threads_realtime(
    threads: &[Arc<crate::rt::activity::ThreadInfo>],
    timeout: Duration,
) -> bool {
    let t0 = std::time::Instant::now();
    while threads.iter().any(|t| t.stats.summary().wakeup.count == 0) && t0.elapsed() < timeout {
        std::thread::sleep(Duration::from_millis(1));
    }
    threads.iter().all(|t| t.realtime())
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The event receivers the bridge drains, subscribed before start.
struct Bridge {
    done: EventReceiver<RunDone>,
    error: EventReceiver<()>,
    plain: Vec<EventReceiver<()>>,
    detections: Vec<EventReceiver<u32>>,
}

impl Bridge {
    fn subscribe(app: &Deployment) -> Result<Self, DeployError> {
        let plain = [
            names::ROBOT_ESTOP_EVENT,
            names::OBJECT_GRABBED_EVENT,
            names::GRIPPER_OPENED_EVENT,
            names::GRIPPER_CLOSED_EVENT,
        ]
        .iter()
        .map(|n| Ok(app.event::<()>(n)?.subscribe(64)))
        .collect::<Result<_, DeployError>>()?;
        let detections = [
            names::A_DETECTED_EVENT,
            names::B_DETECTED_EVENT,
            names::NONE_DETECTED_EVENT,
        ]
        .iter()
        .map(|n| Ok(app.event::<u32>(n)?.subscribe(64)))
        .collect::<Result<_, DeployError>>()?;
        Ok(Self {
            done: app.event::<RunDone>(names::RUN_DONE_EVENT)?.subscribe(256),
            error: app.event::<()>(names::ERROR_EVENT)?.subscribe(16),
            plain,
            detections,
        })
    }

    /// Forwards what arrived; `status` gives the selection's error text.
    fn pump(&mut self, tx: &broadcast::Sender<MachineEvent>, status: impl Fn() -> SelectionStatus) {
        let send = |topic: &str, data: Value| {
            let _ = tx.send(MachineEvent {
                topic: topic.into(),
                data,
            });
        };
        self.done.drain(|d| {
            send(
                "task",
                json!({"event": names::RUN_DONE_EVENT, "run": d.run, "of": d.of,
                       "container": d.container, "cycle_ms": d.cycle_ms}),
            );
        });
        for r in &mut self.plain {
            let name = r.name().to_owned();
            r.drain(|()| send("task", json!({ "event": name })));
        }
        for r in &mut self.detections {
            let name = r.name().to_owned();
            r.drain(|n| send("task", json!({"event": name, "detection": n})));
        }
        if self.error.drain(|()| {}) > 0 {
            let why = status().error.unwrap_or("error detected");
            send("task", json!({"event": names::ERROR_EVENT, "error": why}));
            send("fault", json!({"message": format!("selection: {why}")}));
        }
    }
}

impl CellDaemon {
    /// Deploys and starts the cell of `file` (real-time threads, or simulated time at
    /// `cell.sim_speed`).
    pub fn deploy(file: &CellFile) -> anyhow::Result<Arc<CellDaemon>> {
        let cfg = &file.cell;
        if cfg.sim_speed.is_none() && crate::rt::system::lock_memory().is_err() {
            crate::rt::system::warn_not_realtime(
                "mlockall failed (no CAP_IPC_LOCK or RLIMIT_MEMLOCK too low)",
            );
        }
        // A camera in another process (`[peers] camera`): reached before anything starts.
        let remote = match &file.peers.camera {
            Some(r) => Some(RemoteCamera::connect(
                r,
                &file.remote,
                file.zenoh.as_ref(),
                &cfg.name,
            )?),
            None => None,
        };
        let cell = deploy_with(cfg, remote.as_ref().map(RemoteCamera::proxy).transpose()?)?;
        let app = cell.deployment;
        let mut bridge = Bridge::subscribe(&app)?;
        let runtime = match cfg.sim_speed {
            Some(speed) => app.start_simulated(crate::rt::activity::SimPace::Speed(speed))?,
            None => app.start()?,
        };
        let readers = Readers {
            robot: runtime.reader(names::ROBOT_STATUS)?,
            selection: runtime.reader(names::SELECTION_STATUS)?,
            tally: runtime.reader(names::WORLD)?,
            setpoint: runtime.reader(names::SETPOINT)?,
        };
        let (events, _) = broadcast::channel(1024);
        if let Some(r) = &remote {
            r.watch(events.clone(), cell.robot.sender().clone());
        }
        let stop_bridge = Arc::new(AtomicBool::new(false));
        let mut selection_status = runtime.reader::<SelectionStatus>(names::SELECTION_STATUS)?;
        let (tx, stop) = (events.clone(), stop_bridge.clone());
        let thread = std::thread::Builder::new()
            .name("cell-bridge".into())
            .spawn(move || {
                while !stop.load(Ordering::Acquire) {
                    let s = selection_status.latest().unwrap_or_default();
                    bridge.pump(&tx, || s);
                    std::thread::sleep(Duration::from_millis(5));
                }
            })?;
        Ok(Arc::new(CellDaemon {
            name: cfg.name.clone(),
            runtime: Mutex::new(Some(runtime)),
            robot: cell.robot.sender().clone(),
            readers: Mutex::new(readers),
            events,
            stop_bridge,
            bridge: Mutex::new(Some(thread)),
            scripts: cell.scripts,
            simulated: cfg.sim_speed.is_some(),
            _remote: remote,
        }))
    }

    fn robot_call(&self, c: RobotCmd) -> Result<(), ApiError> {
        let h = self
            .robot
            .send(c)
            .map_err(|e| ApiError::Failed(e.to_string()))?;
        task_api::call_reply(&h, names::ROBOT).map(|_| ())
    }
}

fn mode_of(robot: RobotState, selection: &SelectionStatus) -> Mode {
    use super::selection::SelectionState as S;
    match (robot, selection.state) {
        (RobotState::EmergencyStop, _) => Mode::Estop,
        (RobotState::Fault, _) | (_, S::ErrorDetected) => Mode::Fault,
        (RobotState::Off, _) => Mode::Off,
        (_, S::Homed) => Mode::Idle,
        _ => Mode::Running,
    }
}

impl MachineApi for CellDaemon {
    fn not_a_machine(&self) -> &'static str {
        "this is a pick-and-place cell; use `call` on its tasks"
    }
    fn status(&self) -> Status {
        let (robot, sel, tally, sp) = {
            let mut r = lock(&self.readers);
            (
                r.robot.latest().unwrap_or_default(),
                r.selection.latest().unwrap_or_default(),
                r.tally.latest().unwrap_or_default(),
                r.setpoint.latest().unwrap_or_default(),
            )
        };
        let (threads, servo_cycle, realtime) = match lock(&self.runtime).as_ref() {
            Some(rt) => {
                let t = task_api::thread_timings(&rt.threads());
                let cycles = t.first().map_or(0, |t| t.cycles);
                (t, cycles, rt.realtime())
            }
            None => (Vec::new(), 0, false),
        };
        let state = serde_json::to_value(robot.state)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        let axes = ["X", "Y", "Z"]
            .iter()
            .enumerate()
            .map(|(i, n)| AxisStatus {
                name: (*n).into(),
                commanded: sp.position_mm[i],
                actual: robot.position_mm[i],
                velocity: sp.velocity_mm_s[i],
                following_error: sp.position_mm[i] - robot.position_mm[i],
                homed: true,
                drive_state: state.clone(),
                ..AxisStatus::default()
            })
            .collect();
        let flag = |b: bool| if b { 1.0 } else { 0.0 };
        let inputs = [
            ("gripper_open", flag(robot.gripper_open)),
            ("gripper_closed", flag(robot.gripper_closed)),
            ("object_present", flag(robot.object_present)),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        let mut outputs: std::collections::BTreeMap<String, f64> = Container::ALL
            .iter()
            .map(|c| {
                (
                    format!("container.{}", c.name()),
                    f64::from(tally.in_container[c.index()]),
                )
            })
            .collect();
        outputs.insert("floor".into(), f64::from(tally.on_floor));
        outputs.insert("missorted".into(), f64::from(tally.missorted));
        outputs.insert("objects_spawned".into(), f64::from(tally.spawned));
        Status {
            machine: self.name.clone(),
            mode: mode_of(robot.state, &sel),
            realtime,
            servo_cycle,
            axes,
            job: JobStatus {
                name: names::SELECTION.into(),
                // "homed" only once at home and ready for `run`.
                state: if sel.state == super::selection::SelectionState::Homed && !sel.entered {
                    "homing".into()
                } else {
                    sel.state.name().into()
                },
                line: sel.runs_done,
                total_lines: sel.runs_asked,
                progress: if sel.runs_asked > 0 {
                    f64::from(sel.runs_done) / f64::from(sel.runs_asked)
                } else {
                    0.0
                },
                reason: sel.error.map(str::to_owned),
                ..JobStatus::default()
            },
            overrides: Overrides::default(),
            spindle_rpm: 0.0,
            faults: sel.error.map(str::to_owned).into_iter().collect(),
            threads,
            inputs,
            outputs,
            probe: ProbeStatus::default(),
            optional_stop: false,
            plc: None,
        }
    }
    fn scripts(&self) -> Option<&crate::script::ScriptHosts> {
        Some(&self.scripts)
    }
    fn estop(&self) -> Result<(), ApiError> {
        self.robot_call(RobotCmd::EmergencyStop)
    }
    fn estop_reset(&self) -> Result<(), ApiError> {
        self.robot_call(RobotCmd::Reset)
    }
    fn machine_on(&self) -> Result<(), ApiError> {
        self.robot_call(RobotCmd::SwitchOn)
    }
    fn machine_off(&self) -> Result<(), ApiError> {
        self.robot_call(RobotCmd::SwitchOff)
    }
    fn home(&self, _: Option<&str>) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("home (the selection homes the robot: call selection stop)"))
    }
    fn tasks(&self) -> Vec<TaskInfo> {
        task_api::runtime_task_infos(&self.runtime)
    }
    /// As the machine's `call`, except that `selection.run` answers once accepted (it runs
    /// for minutes; follow it through the `task` events and `status`).
    fn call(&self, task: &str, operation: &str, args: &Value) -> Result<Value, ApiError> {
        let handle = {
            let rt = lock(&self.runtime);
            let rt = rt
                .as_ref()
                .ok_or_else(|| ApiError::Rejected("the cell is stopped".into()))?;
            task_api::send_call(rt.tasks(), task, operation, args)?
        };
        if (task, operation) == (names::SELECTION, "run")
            && handle.wait_accepted(Duration::from_secs(5)) == CommandStatus::Accepted
        {
            return Ok(json!({"status": "accepted"}));
        }
        task_api::call_reply(&handle, task)
    }
    fn set_sim_input(&self, _: &str, _: f64) -> Result<(), ApiError> {
        Err(self
            .not_a_machine_error("sim.input (call hw press_estop / release_estop / drop_object)"))
    }
    fn sim_fault(&self, _: &SimFault) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("sim.fault (call hw drop_object)"))
    }
    fn subscribe(&self) -> broadcast::Receiver<MachineEvent> {
        self.events.subscribe()
    }
}

impl Deployed for CellDaemon {
    fn name(&self) -> String {
        self.name.clone()
    }
    fn realtime(&self) -> bool {
        if self.simulated {
            return false;
        }
        let threads = lock(&self.runtime).as_ref().map(Runtime::threads);
        threads.is_some_and(|t| threads_realtime(&t, THREADS_REPORT))
    }
    fn servo_cycles(&self) -> u64 {
        lock(&self.runtime).as_ref().map_or(0, |rt| {
            rt.threads()
                .first()
                .map_or(0, |t| t.stats.summary().wakeup.count)
        })
    }
    /// Stops the robot (amplifiers off, brakes on), then the threads.
    fn shutdown(&self) -> anyhow::Result<()> {
        let _ = self
            .robot
            .send(RobotCmd::SwitchOff)
            .map(|h| h.wait(Duration::from_secs(1)));
        if let Some(rt) = lock(&self.runtime).take() {
            rt.stop();
        }
        self.stop_bridge.store(true, Ordering::Release);
        if let Some(t) = lock(&self.bridge).take() {
            let _ = t.join();
        }
        Ok(())
    }
}
