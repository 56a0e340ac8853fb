//! The selection task: the pick-and-place sequence as a state machine over the paper's states
//! (section VII), written as plain Rust.
//!
//! The cell deploys the same machine written in the script language by default
//! (`config/scripts/selection.st`, hosted by [`super::scripted`]); this Rust one is the
//! reference, selected with `[cell.selection] kind = "rust"`, and `tests/cell_sort.rs` runs
//! both on the same seed. The tests drive the cell through the task's operations and events
//! only, so they hold for either.
//!
//! States and transitions (entry actions are robot / camera commands, done in order, each
//! waited for through its completion condition; a rejected or failed one is an error):
//!
//! ```text
//! initial ──(reset, switch on, open gripper, move home)──> homed
//! homed ──run(n)──> moving_without_object   (open gripper, above pick, down to pick)
//!   ──> taking_object                        (close gripper; wait robot.object_grabbed)
//!   ──> moving_with_object [requires object grabbed]  (up, to the camera)
//!   ──> detecting_object                     (camera.start_detection; wait a detection event)
//!   ──> moving_with_object [requires object grabbed]  (up, above the container, down)
//!   ──> releasing_object                     (open gripper, up; emit operation_n_done)
//!   ──> moving_without_object (runs left) | homed (move home)
//! any ──(precondition violated, command failed, timeout, robot e-stop or fault)──> error_detected
//!   (entry: robot.emergency_stop)  ──stop──> initial
//! ```
//!
//! Operations: `run(n)` (accepted when homed; done when the n objects are sorted and the
//! robot is home again; fails on error detected) and `stop` (no new object after the current
//! one; from error detected, recover through initial; done when homed).

use super::camera::CameraCmd;
use super::names;
use super::robot::RobotCmd;
use super::types::{Container, RobotState, RobotStatus, RunDone, Vec3};
use super::world::Layout;
use crate::rt::prelude::*;

/// The states of the selection (the paper's, plus the initial one that homes the robot).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SelectionState {
    /// Switching the robot on and moving it home.
    #[default]
    Initial,
    /// At home, waiting for `run(n)`.
    Homed,
    /// Going to the pick position with the gripper open.
    MovingWithoutObject,
    /// Closing the gripper, waiting for "object grabbed".
    TakingObject,
    /// Carrying the object (to the camera or to its container).
    MovingWithObject,
    /// Waiting for the camera's verdict.
    DetectingObject,
    /// Opening the gripper over the container.
    ReleasingObject,
    /// Something went wrong; the robot is stopped until `stop`.
    ErrorDetected,
}

impl SelectionState {
    /// Name as shown in status.
    pub fn name(self) -> &'static str {
        match self {
            Self::Initial => "initial",
            Self::Homed => "homed",
            Self::MovingWithoutObject => "moving_without_object",
            Self::TakingObject => "taking_object",
            Self::MovingWithObject => "moving_with_object",
            Self::DetectingObject => "detecting_object",
            Self::ReleasingObject => "releasing_object",
            Self::ErrorDetected => "error_detected",
        }
    }
}

/// The selection's status (data object [`names::SELECTION_STATUS`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SelectionStatus {
    /// Current state.
    pub state: SelectionState,
    /// Objects sorted in the current `run(n)`.
    pub runs_done: u32,
    /// `n` of the current `run(n)`.
    pub runs_asked: u32,
    /// Why `error_detected` was entered.
    pub error: Option<&'static str>,
    /// The state's entry actions are done (in `homed`: at home and ready for `run`).
    pub entered: bool,
}

/// Which implementation runs the selection.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SelectionKind {
    /// The state machine in the script language (`config/scripts/selection.st`), hosted by
    /// [`super::scripted::ScriptedSelection`]: the cell's default, as the paper has it.
    #[default]
    Script,
    /// This module's plain-Rust machine, kept as a reference for side-by-side tests.
    Rust,
}

/// `[cell.selection]`: implementation, script and timeouts.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct SelectionConfig {
    /// `script` (default) or `rust`.
    #[serde(default)]
    pub kind: SelectionKind,
    /// The script's file; a relative path is relative to the configuration file. Absent:
    /// the shipped `config/scripts/selection.st`, built into the binary so a minimal cell
    /// file works from any directory.
    #[serde(default)]
    pub script: Option<std::path::PathBuf>,
    /// Longest wait for "object grabbed" after the gripper closed, ms.
    #[serde(default = "default_grab_timeout")]
    pub grab_timeout_ms: u64,
    /// Longest wait for a detection event, ms.
    #[serde(default = "default_detect_timeout")]
    pub detection_timeout_ms: u64,
}

fn default_grab_timeout() -> u64 {
    500
}
fn default_detect_timeout() -> u64 {
    2000
}

impl Default for SelectionConfig {
    fn default() -> Self {
        Self {
            kind: SelectionKind::default(),
            script: None,
            grab_timeout_ms: default_grab_timeout(),
            detection_timeout_ms: default_detect_timeout(),
        }
    }
}

/// Operations of the selection task.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SelectionCmd {
    /// Sort `n` objects.
    Run(u32),
    /// Finish the current object and go home; from an error, recover.
    Stop,
}

const OPS: &[OperationDescriptor] = &[
    OperationDescriptor::new(
        "run",
        "Sort n objects; done when they are sorted and the robot is home.",
        &[ParamDescriptor::new("n", ArgType::Int)],
        NextCommand::AfterAcceptance,
    ),
    OperationDescriptor::new(
        "stop",
        "No new object after the current one; from error_detected, recover. Done when homed.",
        &[],
        NextCommand::AfterAcceptance,
    ),
];

impl Commands for SelectionCmd {
    fn operations() -> &'static [OperationDescriptor] {
        OPS
    }
    fn operation_index(&self) -> usize {
        match self {
            Self::Run(_) => 0,
            Self::Stop => 1,
        }
    }
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(OPS, operation, args)?;
        Ok(match a.operation() {
            "run" => Self::Run(u32::try_from(a.int(0)?).unwrap_or(0)),
            _ => Self::Stop,
        })
    }
}

/// One entry action.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Action {
    Robot(RobotCmd),
    Detect,
}

/// Longest entry-action list.
const MAX_ACTIONS: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq)]
struct Plan {
    actions: [Option<Action>; MAX_ACTIONS],
    next: usize,
}

impl Plan {
    fn of(list: &[Action]) -> Self {
        let mut actions = [None; MAX_ACTIONS];
        for (slot, a) in actions.iter_mut().zip(list) {
            *slot = Some(*a);
        }
        Self { actions, next: 0 }
    }
    fn current(&self) -> Option<Action> {
        self.actions.get(self.next).copied().flatten()
    }
}

/// The ports of both selections (this one and the script's host): the robot's status in,
/// the selection's status out, the camera's verdicts and the task's two events.
#[derive(Default)]
pub(super) struct CommonPorts {
    pub(super) status_in: Option<DataReader<RobotStatus>>,
    pub(super) status_out: Option<DataWriter<SelectionStatus>>,
    a: Option<EventReceiver<u32>>,
    b: Option<EventReceiver<u32>>,
    none: Option<EventReceiver<u32>>,
    pub(super) done: Option<EventSource<RunDone>>,
    pub(super) error: Option<EventSource<()>>,
}

impl CommonPorts {
    pub(super) fn configure(&mut self, ctx: &mut Configure<'_>) {
        self.status_in = Some(ctx.input(names::ROBOT_STATUS));
        self.status_out = Some(ctx.output(names::SELECTION_STATUS));
        self.a = Some(ctx.subscribe(names::A_DETECTED_EVENT, 8));
        self.b = Some(ctx.subscribe(names::B_DETECTED_EVENT, 8));
        self.none = Some(ctx.subscribe(names::NONE_DETECTED_EVENT, 8));
        self.done = Some(ctx.event("operation_n_done"));
        self.error = Some(ctx.event("error_detected"));
    }

    /// The camera's verdict since the last call, if any (every detection event is drained
    /// so none piles up).
    pub(super) fn verdict(&mut self) -> Option<Container> {
        let seen = [
            (drained(&mut self.a), Container::A),
            (drained(&mut self.b), Container::B),
            (drained(&mut self.none), Container::Reject),
        ];
        seen.into_iter().find(|(s, _)| *s).map(|(_, c)| c)
    }
}

/// Whether `run(n)` can be accepted (both selections).
pub(super) fn check_run(n: u32, idle_at_home: bool) -> Result<(), RejectReason> {
    if n == 0 {
        return Err(RejectReason::BadParameters("n must be at least 1"));
    }
    if !idle_at_home {
        return Err(RejectReason::Busy);
    }
    Ok(())
}

/// Progress of `run` (fails once an error was detected after it started) and `stop`
/// (both done when idle at home), for both selections.
pub(super) fn op_progress(c: &SelectionCmd, error_since_run: bool, idle_at_home: bool) -> Progress {
    match *c {
        SelectionCmd::Run(_) if error_since_run => Progress::Failed("error detected"),
        _ if idle_at_home => Progress::Done,
        _ => Progress::Running,
    }
}

#[derive(Default)]
struct Ports {
    robot: Option<CommandSender<RobotCmd>>,
    camera: Option<CommandSender<CameraCmd>>,
    grabbed: Option<EventReceiver<()>>,
    estop: Option<EventReceiver<()>>,
    common: CommonPorts,
}

pub(super) fn drained<T: Send>(r: &mut Option<EventReceiver<T>>) -> bool {
    r.as_mut().is_some_and(|r| r.drain(|_| {}) > 0)
}

/// The selection task.
pub struct Selection {
    cfg: SelectionConfig,
    layout: Layout,
    ports: Ports,
    robot: RobotStatus,
    state: SelectionState,
    plan: Plan,
    pending: Option<CommandHandle>,
    /// The entry actions are done; the state waits for its event or goes on.
    entered: bool,
    waiting_since_ns: u64,
    destination: Option<Container>,
    runs_asked: u32,
    runs_done: u32,
    stop_requested: bool,
    run_started_ns: u64,
    error: Option<&'static str>,
    /// Bumped on every entry to `error_detected`, so a `run` that was active then fails.
    errors: u32,
    run_errors_at_start: u32,
}

impl Selection {
    /// A selection over `layout`.
    pub fn new(cfg: SelectionConfig, layout: Layout) -> Self {
        Self {
            cfg,
            layout,
            ports: Ports::default(),
            robot: RobotStatus::default(),
            state: SelectionState::Initial,
            plan: Plan::of(&[]),
            pending: None,
            entered: false,
            waiting_since_ns: 0,
            destination: None,
            runs_asked: 0,
            runs_done: 0,
            stop_requested: false,
            run_started_ns: 0,
            error: None,
            errors: 0,
            run_errors_at_start: 0,
        }
    }

    fn above(&self, p: Vec3) -> Action {
        Action::Robot(RobotCmd::MoveTo([p[0], p[1], self.layout.travel_z_mm]))
    }

    fn enter(&mut self, state: SelectionState, ctx: &StepContext) {
        use Action::Robot as R;
        self.state = state;
        self.pending = None;
        self.entered = false;
        self.waiting_since_ns = ctx.now_ns;
        let l = self.layout;
        self.plan = match state {
            SelectionState::Initial => Plan::of(&[
                R(RobotCmd::Reset),
                R(RobotCmd::SwitchOn),
                R(RobotCmd::OpenGripper),
                R(RobotCmd::MoveTo(l.home_mm)),
            ]),
            SelectionState::Homed => Plan::of(&[R(RobotCmd::MoveTo(l.home_mm))]),
            SelectionState::MovingWithoutObject => Plan::of(&[
                R(RobotCmd::OpenGripper),
                self.above(l.pick_mm),
                R(RobotCmd::MoveTo(l.pick_mm)),
            ]),
            SelectionState::TakingObject => {
                self.run_started_ns = ctx.now_ns;
                Plan::of(&[R(RobotCmd::CloseGripper)])
            }
            SelectionState::MovingWithObject => match self.destination {
                None => Plan::of(&[self.above(l.pick_mm), R(RobotCmd::MoveTo(l.camera_mm))]),
                Some(c) => Plan::of(&[
                    self.above(l.camera_mm),
                    self.above(l.container(c)),
                    R(RobotCmd::MoveTo(l.container(c))),
                ]),
            },
            SelectionState::DetectingObject => Plan::of(&[Action::Detect]),
            SelectionState::ReleasingObject => {
                let c = self.destination.unwrap_or(Container::Reject);
                Plan::of(&[R(RobotCmd::OpenGripper), self.above(l.container(c))])
            }
            SelectionState::ErrorDetected => {
                self.errors += 1;
                if let Some(e) = &mut self.ports.common.error {
                    e.emit(());
                }
                Plan::of(&[R(RobotCmd::EmergencyStop)])
            }
        };
    }

    fn fail(&mut self, why: &'static str, ctx: &StepContext) {
        if self.state != SelectionState::ErrorDetected {
            self.error = Some(why);
            self.enter(SelectionState::ErrorDetected, ctx);
        }
    }

    /// Runs the entry actions one after the other; true once all are done.
    fn run_plan(&mut self, ctx: &StepContext) -> Result<bool, &'static str> {
        if let Some(h) = &self.pending {
            match h.status() {
                CommandStatus::Pending | CommandStatus::Accepted => return Ok(false),
                CommandStatus::Done => {
                    self.pending = None;
                    self.plan.next += 1;
                }
                CommandStatus::Rejected(_) => return Err("a command was rejected"),
                CommandStatus::Failed(_) => return Err("a command failed"),
            }
        }
        let Some(action) = self.plan.current() else {
            return Ok(true);
        };
        let sent = match action {
            Action::Robot(c) => self.ports.robot.as_ref().map(|s| s.send(c)),
            Action::Detect => self
                .ports
                .camera
                .as_ref()
                .map(|s| s.send(CameraCmd::StartDetection)),
        };
        match sent {
            Some(Ok(h)) => {
                self.pending = Some(h);
                self.waiting_since_ns = ctx.now_ns;
                Ok(false)
            }
            Some(Err(_)) => Err("a command queue is full"),
            None => Err("peer not connected"),
        }
    }

    fn timed_out(&self, ms: u64, ctx: &StepContext) -> bool {
        ctx.now_ns.saturating_sub(self.waiting_since_ns) > ms * 1_000_000
    }

    /// The state's transitions, once its entry actions are done.
    fn transitions(&mut self, ctx: &StepContext) {
        use SelectionState as S;
        match self.state {
            S::Initial => self.enter(S::Homed, ctx),
            S::Homed | S::ErrorDetected => {}
            S::MovingWithoutObject => self.enter(S::TakingObject, ctx),
            S::TakingObject => {
                if self.robot.object_present {
                    self.destination = None;
                    self.enter(S::MovingWithObject, ctx);
                } else if self.timed_out(self.cfg.grab_timeout_ms, ctx) {
                    self.fail("no object grabbed", ctx);
                }
            }
            S::MovingWithObject => match self.destination {
                None => self.enter(S::DetectingObject, ctx),
                Some(_) => self.enter(S::ReleasingObject, ctx),
            },
            S::DetectingObject => {
                if self.destination.is_some() {
                    self.enter(S::MovingWithObject, ctx);
                } else if self.timed_out(self.cfg.detection_timeout_ms, ctx) {
                    self.fail("no detection result", ctx);
                }
            }
            S::ReleasingObject => {
                self.runs_done += 1;
                if let Some(e) = &mut self.ports.common.done {
                    e.emit(RunDone {
                        run: self.runs_done,
                        of: self.runs_asked,
                        container: self.destination.unwrap_or(Container::Reject),
                        cycle_ms: ctx.now_ns.saturating_sub(self.run_started_ns) / 1_000_000,
                    });
                }
                self.destination = None;
                if self.runs_done < self.runs_asked && !self.stop_requested {
                    self.enter(S::MovingWithoutObject, ctx);
                } else {
                    self.enter(S::Homed, ctx);
                }
            }
        }
    }

    fn publish(&mut self) {
        if let Some(o) = &mut self.ports.common.status_out {
            o.set(SelectionStatus {
                state: self.state,
                runs_done: self.runs_done,
                runs_asked: self.runs_asked,
                error: self.error,
                entered: self.entered,
            });
        }
    }

    fn idle_at_home(&self) -> bool {
        self.state == SelectionState::Homed && self.entered
    }
}

impl Task for Selection {
    type Command = SelectionCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        let p = &mut self.ports;
        p.robot = ctx.peer_commands(names::ROBOT);
        p.camera = ctx.peer_commands(names::CAMERA);
        p.grabbed = Some(ctx.subscribe(names::OBJECT_GRABBED_EVENT, 8));
        p.estop = Some(ctx.subscribe(names::ROBOT_ESTOP_EVENT, 8));
        p.common.configure(ctx);
        Ok(())
    }
    fn start(&mut self) -> Result<(), TaskError> {
        self.state = SelectionState::Initial;
        self.entered = false;
        self.pending = None;
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.ports.common.status_in {
            r.get(&mut self.robot);
        }
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    /// The state machine, after the inputs were read (the runner's step 3).
    fn state_machines(&mut self, ctx: &StepContext) {
        use SelectionState as S;
        if self.state == S::Initial
            && !self.entered
            && self.pending.is_none()
            && self.plan.next == 0
        {
            self.enter(S::Initial, ctx);
        }
        // Precondition of "moving with object": the object is grabbed.
        if self.state == S::MovingWithObject && !self.robot.object_present {
            self.fail(
                "object lost while moving (precondition 'object grabbed' violated)",
                ctx,
            );
        }
        if matches!(
            self.robot.state,
            RobotState::Fault | RobotState::EmergencyStop
        ) && !matches!(self.state, S::ErrorDetected | S::Initial)
        {
            self.fail("the robot stopped (fault or emergency stop)", ctx);
        }
        if !self.entered {
            match self.run_plan(ctx) {
                Ok(true) => {
                    self.entered = true;
                    self.waiting_since_ns = ctx.now_ns;
                }
                Ok(false) => {}
                Err(why) if self.state == S::ErrorDetected => {
                    // Stopping failed too: nothing more to do than report it.
                    self.error = Some(why);
                    self.entered = true;
                }
                Err(why) => self.fail(why, ctx),
            }
        }
        if self.entered {
            self.transitions(ctx);
        }
        self.publish();
    }
    fn accept(&mut self, c: &SelectionCmd, ctx: &StepContext) -> Result<(), RejectReason> {
        match *c {
            SelectionCmd::Run(n) => {
                check_run(n, self.idle_at_home())?;
                self.runs_asked = n;
                self.runs_done = 0;
                self.stop_requested = false;
                self.error = None;
                self.run_errors_at_start = self.errors;
                self.enter(SelectionState::MovingWithoutObject, ctx);
            }
            SelectionCmd::Stop => {
                self.stop_requested = true;
                if self.state == SelectionState::ErrorDetected {
                    self.enter(SelectionState::Initial, ctx);
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
    fn process_events(&mut self, ctx: &StepContext) {
        // "object grabbed" is also visible in the robot's status; the event is drained so it
        // does not pile up, and the status (sampled every cycle) decides.
        drained(&mut self.ports.grabbed);
        if drained(&mut self.ports.estop) {
            self.fail("emergency stop", ctx);
        }
        let verdict = self.ports.common.verdict();
        if self.state == SelectionState::DetectingObject && verdict.is_some() {
            self.destination = verdict;
        }
    }
}
