//! The selection task running the selection state machine written in the script language
//! (`config/scripts/selection.st`), the cell's default selection.
//!
//! The task embeds a [`ScriptHost`] and keeps the interface of the Rust reference
//! ([`super::selection`]): operations `run(n)` and `stop`, events `operation_n_done` and
//! `error_detected`, status data object `selection.status`. Around the script it does
//! only plumbing, every step and without allocation:
//! - before the machine's step it mirrors the peers' state the script reads into its
//!   globals (`grabbed`, `robot_ok` from `robot.status`, `detected` from the camera's
//!   events, `runs_asked` / `stop_requested` from the operations);
//! - after it, it turns the script's EMITs into the task's events (with the `RunDone`
//!   payload the script cannot build) and publishes the machine's state as
//!   `SelectionStatus`, so tests, the daemon and `hytask run-cell` see either
//!   implementation the same way.
//!
//! The script is compiled ([`read`]) and bound ([`bind`]) at deploy: errors name `file:line:col` and
//! refuse the deployment. Its [`ScriptControl`] is registered as a script host, so `hytask
//! script list|pause|step|...` and `hytask tasks` show and drive the running machine.
//! The task drives slot 0 with the globals resolved from the script read at deploy: after
//! `hytask script unload`, loading a script with other globals there is not supported
//! (restart the cell with the new file instead).

use super::names;
use super::selection::{
    check_run, op_progress, CommonPorts, SelectionCmd, SelectionConfig, SelectionState,
    SelectionStatus,
};
use super::types::{Container, RobotState, RobotStatus, RunDone};
use super::world::Layout;
use crate::plc::{Value, VarId};
use crate::rt::prelude::*;
use crate::script::{compile, Bindings, Ctl, Limits, RunStatus, ScriptControl, ScriptHost};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The shipped selection script, used when `[cell.selection] script` is absent.
pub const SHIPPED_SCRIPT: &str = include_str!("../../config/scripts/selection.st");
/// The name the shipped script's messages carry.
pub const SHIPPED_SCRIPT_FILE: &str = "config/scripts/selection.st";
/// The state machine the script must declare.
pub const MACHINE: &str = "selection";

/// Globals the host writes every step (inputs) or reads (outputs), resolved at load.
#[derive(Debug, Clone, Copy)]
struct Vars {
    grabbed: VarId,
    robot_ok: VarId,
    runs_asked: VarId,
    stop_requested: VarId,
    detected: VarId,
    runs_done: VarId,
    destination: VarId,
}

/// What [`read`] found in the script for the task: the script's handles and state names.
pub struct Prepared {
    vars: Vars,
    /// The script's state index -> the paper's state.
    states: Vec<SelectionState>,
    /// Index of the machine among the script's items.
    item: usize,
    done_flag: Arc<AtomicU64>,
    error_flag: Arc<AtomicU64>,
}

/// Errors of loading the selection script.
#[derive(Debug, thiserror::Error)]
pub enum ScriptLoadError {
    /// The script file cannot be read.
    #[error("cannot read the selection script {path}: {source}")]
    Read {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Compiling or binding failed: `file:line:col: what` per error.
    #[error("{0}")]
    Compile(String),
    /// The script lacks what the host needs.
    #[error("{file}: {what}")]
    Interface {
        /// File.
        file: String,
        /// What is missing.
        what: String,
    },
}

/// Maps a script state's name to the paper's state (`choosing` is the detection's verdict,
/// `finished` is never reached while the cell runs).
fn paper_state(name: &str) -> SelectionState {
    use SelectionState as S;
    match name.to_ascii_lowercase().as_str() {
        "homed" | "finished" => S::Homed,
        "moving_without_object" => S::MovingWithoutObject,
        "taking_object" => S::TakingObject,
        "moving_with_object" => S::MovingWithObject,
        "detecting_object" | "choosing" => S::DetectingObject,
        "releasing_object" => S::ReleasingObject,
        "error_detected" => S::ErrorDetected,
        _ => S::Initial,
    }
}

/// The selection task hosting the script.
pub struct ScriptedSelection {
    host: ScriptHost,
    prepared: Option<Prepared>,
    slot: usize,
    ports: CommonPorts,
    robot: RobotStatus,
    /// Camera verdict: 0 none yet, 1 A, 2 B, 3 reject.
    detected: i64,
    runs_asked: u32,
    /// `runs_done` is reset in the script at the next step.
    reset_runs: bool,
    /// `run` accepted, the machine has not left `homed` yet.
    run_pending: bool,
    stop_requested: bool,
    /// (Re)start the machine at the next step (task start, recovery by `stop`).
    restart: bool,
    state: SelectionState,
    entered: bool,
    seen_done: u64,
    seen_errors: u64,
    errors: u32,
    run_errors_at_start: u32,
    error: Option<&'static str>,
    run_started_ns: u64,
}

impl ScriptedSelection {
    /// The task running `source` and the control half of its script host (the script is
    /// bound and queued by [`bind`] once the deployment is configured).
    pub fn new(source: &mut Source) -> (Self, ScriptControl) {
        let (host, control) = ScriptHost::new(names::SELECTION, Limits::default());
        let prepared = Prepared {
            vars: source.prepared.vars,
            states: std::mem::take(&mut source.prepared.states),
            item: source.prepared.item,
            done_flag: source.prepared.done_flag.clone(),
            error_flag: source.prepared.error_flag.clone(),
        };
        let task = Self {
            host,
            prepared: Some(prepared),
            slot: 0,
            ports: CommonPorts::default(),
            robot: RobotStatus::default(),
            detected: 0,
            runs_asked: 0,
            reset_runs: false,
            run_pending: false,
            stop_requested: false,
            restart: true,
            state: SelectionState::Initial,
            entered: false,
            seen_done: 0,
            seen_errors: 0,
            errors: 0,
            run_errors_at_start: 0,
            error: None,
            run_started_ns: 0,
        };
        (task, control)
    }

    fn idle_at_home(&self) -> bool {
        self.state == SelectionState::Homed && self.entered && !self.run_pending
    }

    fn why(&self, before: SelectionState) -> &'static str {
        if before == SelectionState::MovingWithObject && !self.robot.object_present {
            "object lost while moving (precondition 'object grabbed' violated)"
        } else if matches!(
            self.robot.state,
            RobotState::Fault | RobotState::EmergencyStop
        ) {
            "the robot stopped (fault or emergency stop)"
        } else if before == SelectionState::TakingObject {
            "no object grabbed"
        } else if before == SelectionState::DetectingObject {
            "no detection result"
        } else {
            "a command failed"
        }
    }

    /// Mirrors the inputs into the script's globals.
    fn write_inputs(&mut self, p: &Prepared) {
        let v = p.vars;
        let ok = !matches!(
            self.robot.state,
            RobotState::Fault | RobotState::EmergencyStop
        );
        let e = self.host.engine();
        let s = self.slot;
        e.set_id(s, v.grabbed, Value::Bool(self.robot.object_present));
        e.set_id(s, v.robot_ok, Value::Bool(ok));
        e.set_id(s, v.runs_asked, Value::Int(i64::from(self.runs_asked)));
        e.set_id(s, v.stop_requested, Value::Bool(self.stop_requested));
        e.set_id(s, v.detected, Value::Int(self.detected));
        if self.reset_runs {
            e.set_id(s, v.runs_done, Value::Int(0));
            self.reset_runs = false;
        }
    }

    /// Reads the machine's state and EMIT counters after its step.
    fn read_outputs(&mut self, p: &Prepared, ctx: &StepContext) {
        let before = self.state;
        let e = self.host.engine();
        let runs_done = match e.get_id(self.slot, p.vars.runs_done) {
            Some(Value::Int(n)) => u32::try_from(n).unwrap_or(0),
            _ => 0,
        };
        let destination = match e.get_id(self.slot, p.vars.destination) {
            Some(Value::Int(1)) => Container::A,
            Some(Value::Int(2)) => Container::B,
            _ => Container::Reject,
        };
        if let Some((status, idx, entered)) = e.machine_state(self.slot, p.item) {
            self.state = match status {
                RunStatus::Idle => SelectionState::Initial,
                RunStatus::Error => SelectionState::ErrorDetected,
                _ => p
                    .states
                    .get(idx as usize)
                    .copied()
                    .unwrap_or(SelectionState::Initial),
            };
            self.entered = entered && status != RunStatus::Idle;
            if status == RunStatus::Error && before != SelectionState::ErrorDetected {
                // A runtime error (outside the machine's error state) is an error too.
                self.errors += 1;
                self.error = Some(self.why(before));
                if let Some(ev) = &mut self.ports.error {
                    ev.emit(());
                }
            }
        }
        if self.state != SelectionState::Homed {
            self.run_pending = false;
        }
        if self.state == SelectionState::TakingObject && before != self.state {
            self.run_started_ns = ctx.now_ns;
        }
        if matches!(
            self.state,
            SelectionState::MovingWithoutObject | SelectionState::TakingObject
        ) {
            self.detected = 0;
        }
        let done = p.done_flag.load(Ordering::Acquire);
        if done != self.seen_done {
            self.seen_done = done;
            if let Some(ev) = &mut self.ports.done {
                ev.emit(RunDone {
                    run: runs_done,
                    of: self.runs_asked,
                    container: destination,
                    cycle_ms: ctx.now_ns.saturating_sub(self.run_started_ns) / 1_000_000,
                });
            }
        }
        let errors = p.error_flag.load(Ordering::Acquire);
        if errors != self.seen_errors {
            self.seen_errors = errors;
            self.errors += 1;
            self.error = Some(self.why(before));
            if let Some(ev) = &mut self.ports.error {
                ev.emit(());
            }
        }
        if let Some(o) = &mut self.ports.status_out {
            o.set(SelectionStatus {
                state: self.state,
                runs_done,
                runs_asked: self.runs_asked,
                error: self.error,
                entered: self.entered,
            });
        }
    }
}

impl Task for ScriptedSelection {
    type Command = SelectionCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.ports.configure(ctx);
        Ok(())
    }
    fn start(&mut self) -> Result<(), TaskError> {
        self.restart = true;
        self.state = SelectionState::Initial;
        self.entered = false;
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.ports.status_in {
            r.get(&mut self.robot);
        }
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn state_machines(&mut self, ctx: &StepContext) {
        let Some(p) = self.prepared.take() else {
            return;
        };
        self.write_inputs(&p);
        // Applies the control half's queued requests (the load, at the first step).
        self.host.state_machines(ctx.now_ns);
        let status = self.host.engine().machine_state(self.slot, p.item);
        if self.restart && status.is_some() {
            self.restart = false;
            self.error = None;
            let _ = self.host.engine().ctl(self.slot, p.item, Ctl::Start);
            // The machine's first step runs now, not a period later.
            self.host.engine().step_state_machines(ctx.now_ns);
        }
        self.read_outputs(&p, ctx);
        self.prepared = Some(p);
    }
    fn programs(&mut self, ctx: &StepContext) {
        self.host.programs(ctx.now_ns);
    }
    fn stop(&mut self) {
        self.host.stop();
    }
    fn accept(&mut self, c: &SelectionCmd, _: &StepContext) -> Result<(), RejectReason> {
        match *c {
            SelectionCmd::Run(n) => {
                check_run(n, self.idle_at_home())?;
                self.runs_asked = n;
                self.reset_runs = true;
                self.run_pending = true;
                self.stop_requested = false;
                self.error = None;
                self.run_errors_at_start = self.errors;
            }
            SelectionCmd::Stop => {
                self.stop_requested = true;
                if self.state == SelectionState::ErrorDetected {
                    self.restart = true;
                    self.entered = false;
                    self.state = SelectionState::Initial;
                }
            }
        }
        Ok(())
    }
    fn progress(&mut self, c: &SelectionCmd, _: &StepContext) -> Progress {
        op_progress(
            c,
            self.errors != self.run_errors_at_start,
            self.idle_at_home(),
        )
    }
    fn process_events(&mut self, _: &StepContext) {
        let verdict = self.ports.verdict();
        if let (SelectionState::DetectingObject, Some(c)) = (self.state, verdict) {
            // The script's encoding: 1 A, 2 B, 3 reject.
            self.detected = match c {
                Container::A => 1,
                Container::B => 2,
                Container::Reject => 3,
            };
        }
    }
}

/// The names the selection script may use: the robot's and camera's operations, the
/// robot's "object grabbed" event, and its two EMITs.
pub fn bindings(
    deployment: &Deployment,
    robot: &TaskInfo,
    camera: &TaskInfo,
    done: &Arc<AtomicU64>,
    error: &Arc<AtomicU64>,
) -> Result<Bindings, DeployError> {
    let mut b = Bindings::default();
    b.peer_task(robot).peer_task(camera);
    let grabbed = names::OBJECT_GRABBED_EVENT;
    b.event(grabbed, deployment.event::<()>(grabbed)?.counter());
    b.emit("operation_n_done", done.clone());
    b.emit("error_detected", error.clone());
    Ok(b)
}

/// A compiled (not yet bound) selection script: its text and what the task needs of it.
pub struct Source {
    /// File name in messages.
    pub file: String,
    /// The text.
    pub src: String,
    prepared: Prepared,
}

/// Reads the script (`path`, or the shipped one), compiles it and checks the globals and
/// machine the host needs. Binding needs the configured deployment: [`bind`].
pub fn read(path: Option<&Path>) -> Result<Source, ScriptLoadError> {
    let (file, src) = match path {
        Some(p) => {
            let file = p.display().to_string();
            let src = std::fs::read_to_string(p).map_err(|source| ScriptLoadError::Read {
                path: file.clone(),
                source,
            })?;
            (file, src)
        }
        None => (SHIPPED_SCRIPT_FILE.to_owned(), SHIPPED_SCRIPT.to_owned()),
    };
    let s = compile(&file, &src).map_err(|e| ScriptLoadError::Compile(e.to_string()))?;
    let interface = |what: String| ScriptLoadError::Interface {
        file: file.clone(),
        what,
    };
    let item = s
        .items()
        .position(|(n, machine)| machine && n.eq_ignore_ascii_case(MACHINE))
        .ok_or_else(|| interface(format!("no STATE_MACHINE {MACHINE}")))?;
    let var = |name: &str| {
        s.program
            .var(name)
            .ok_or_else(|| interface(format!("no VAR_GLOBAL {name}")))
    };
    let vars = Vars {
        grabbed: var("grabbed")?,
        robot_ok: var("robot_ok")?,
        runs_asked: var("runs_asked")?,
        stop_requested: var("stop_requested")?,
        detected: var("detected")?,
        runs_done: var("runs_done")?,
        destination: var("destination")?,
    };
    let states = s.state_names()[item]
        .iter()
        .map(|n| paper_state(n))
        .collect();
    let prepared = Prepared {
        vars,
        states,
        item,
        done_flag: Arc::new(AtomicU64::new(0)),
        error_flag: Arc::new(AtomicU64::new(0)),
    };
    Ok(Source {
        file,
        src,
        prepared,
    })
}

impl Source {
    /// The EMIT flags the bindings must use: (`operation_n_done`, `error_detected`).
    pub fn flags(&self) -> (&Arc<AtomicU64>, &Arc<AtomicU64>) {
        (&self.prepared.done_flag, &self.prepared.error_flag)
    }
}

/// Binds the script to the configured deployment and queues it (with the layout's
/// positions and the timeouts in its globals) on `control`; the task runs it from its first step.
pub fn bind(
    file: &str,
    src: &str,
    control: &ScriptControl,
    b: &Bindings,
    layout: &Layout,
    timeouts: &SelectionConfig,
) -> Result<(), ScriptLoadError> {
    let err = |e: crate::script::ControlError| ScriptLoadError::Compile(e.to_string());
    let slot = control.load(file, src, b).map_err(err)?;
    if slot != 0 {
        return Err(ScriptLoadError::Interface {
            file: file.to_owned(),
            what: format!("loaded in slot {slot}, the selection task runs slot 0"),
        });
    }
    let points = [
        ("home", layout.home_mm),
        ("pick", layout.pick_mm),
        ("cam", layout.camera_mm),
        ("a", layout.container(Container::A)),
        ("b", layout.container(Container::B)),
        ("r", layout.container(Container::Reject)),
    ];
    for (name, p) in points {
        for (axis, v) in ["x", "y", "z"].iter().zip(p) {
            control
                .set(slot, &format!("{name}_{axis}"), Value::Real(v))
                .map_err(err)?;
        }
    }
    control
        .set(slot, "travel_z", Value::Real(layout.travel_z_mm))
        .map_err(err)?;
    let ns = |ms: u64| Value::Time(i64::try_from(ms.saturating_mul(1_000_000)).unwrap_or(i64::MAX));
    let t = [
        ("grab_timeout", timeouts.grab_timeout_ms),
        ("detection_timeout", timeouts.detection_timeout_ms),
    ];
    for (name, ms) in t {
        control.set(slot, name, ns(ms)).map_err(err)?;
    }
    Ok(())
}
