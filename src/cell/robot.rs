//! The robot task: the interpolator and supervisor of the servo thread, and the robot's
//! operation interface.
//!
//! It runs second on the servo thread (after the sensor, before the PID and the effector),
//! so the setpoint it writes is used in the same cycle. Operations (all
//! [`NextCommand::AfterAcceptance`], so that `emergency_stop` is taken within a cycle even
//! while a `move_to` runs; a second `move_to` while one runs is rejected as busy):
//!
//! | operation | accepted when | completes when |
//! |---|---|---|
//! | `switch_on` | off or idle, e-stop released | at once (loop closed) |
//! | `switch_off` | always | at once (braked; a running move fails) |
//! | `move_to(x_mm, y_mm, z_mm)` | idle, target in the workspace | position reached and settled |
//! | `reset` | always (not while the e-stop button is pressed) | at once (fault cleared, off) |
//! | `open_gripper` / `close_gripper` | not e-stopped | the end switch is reached |
//! | `emergency_stop` | always | at once (braked, gripper output kept) |
//!
//! Events: `position_reached`, `gripper_opened`, `gripper_closed`, `object_grabbed`,
//! `emergency_stop` (from the operation or the cell's e-stop button). The PID's
//! `tracking_error` and the sensor's `range_error` move a switched-on robot to `Fault`
//! (braked; a running move fails).

use super::names;
use super::profile::LineMove;
use super::types::{
    distance, Feedback, RangeError, RobotState, RobotStatus, Setpoint, TrackingError, Vec3,
};
use crate::rt::prelude::*;

/// Motion limits and tolerances of the robot.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Path speed, mm/s.
    #[serde(default = "default_vmax")]
    pub max_velocity_mm_s: f64,
    /// Path acceleration, mm/s².
    #[serde(default = "default_amax")]
    pub max_acceleration_mm_s2: f64,
    /// Distance from the target within which a move counts as reached, mm.
    #[serde(default = "default_tolerance")]
    pub tolerance_mm: f64,
    /// Servo cycles the position must stay within tolerance.
    #[serde(default = "default_settle")]
    pub settle_cycles: u32,
    /// Time the gripper may take before its command fails, ms.
    #[serde(default = "default_gripper_timeout")]
    pub gripper_timeout_ms: u64,
    /// Lowest reachable position per axis, mm.
    #[serde(default = "default_min")]
    pub min_mm: Vec3,
    /// Highest reachable position per axis, mm.
    #[serde(default = "default_max")]
    pub max_mm: Vec3,
}

fn default_vmax() -> f64 {
    1000.0
}
fn default_amax() -> f64 {
    5000.0
}
fn default_tolerance() -> f64 {
    0.5
}
fn default_settle() -> u32 {
    10
}
fn default_gripper_timeout() -> u64 {
    1000
}
fn default_min() -> Vec3 {
    [-10.0, -10.0, 0.0]
}
fn default_max() -> Vec3 {
    [400.0, 300.0, 150.0]
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            max_velocity_mm_s: default_vmax(),
            max_acceleration_mm_s2: default_amax(),
            tolerance_mm: default_tolerance(),
            settle_cycles: default_settle(),
            gripper_timeout_ms: default_gripper_timeout(),
            min_mm: default_min(),
            max_mm: default_max(),
        }
    }
}

/// The robot's operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobotCmd {
    /// Close the loop and enable the amplifiers.
    SwitchOn,
    /// Brake and disable.
    SwitchOff,
    /// Move in a straight line to the point, mm.
    MoveTo(Vec3),
    /// Clear a fault or an e-stop (the robot is off afterwards).
    Reset,
    /// Open the gripper.
    OpenGripper,
    /// Close the gripper.
    CloseGripper,
    /// Stop at once: brakes on, amplifiers off.
    EmergencyStop,
}

const XYZ: &[ParamDescriptor] = &[
    ParamDescriptor::new("x_mm", ArgType::Float),
    ParamDescriptor::new("y_mm", ArgType::Float),
    ParamDescriptor::new("z_mm", ArgType::Float),
];

/// Every operation (see the module's doc: `emergency_stop` is taken while a move runs).
const NEXT: NextCommand = NextCommand::AfterAcceptance;

type Op = OperationDescriptor;

const OPS: &[OperationDescriptor] = &[
    Op::new(
        "switch_on",
        "Close the position loop and enable the amplifiers.",
        &[],
        NEXT,
    ),
    Op::new(
        "switch_off",
        "Brake and disable the amplifiers; a running move fails.",
        &[],
        NEXT,
    ),
    Op::new(
        "move_to",
        "Straight move to (x, y, z); done when the position is reached and settled.",
        XYZ,
        NEXT,
    ),
    Op::new(
        "reset",
        "Clear a fault or an emergency stop; the robot is off afterwards.",
        &[],
        NEXT,
    ),
    Op::new(
        "open_gripper",
        "Open the gripper; done on its open switch.",
        &[],
        NEXT,
    ),
    Op::new(
        "close_gripper",
        "Close the gripper; done on its closed switch.",
        &[],
        NEXT,
    ),
    Op::new(
        "emergency_stop",
        "Brake and disable at once; reset to recover.",
        &[],
        NEXT,
    ),
];

impl Commands for RobotCmd {
    fn operations() -> &'static [OperationDescriptor] {
        OPS
    }
    fn operation_index(&self) -> usize {
        match self {
            Self::SwitchOn => 0,
            Self::SwitchOff => 1,
            Self::MoveTo(_) => 2,
            Self::Reset => 3,
            Self::OpenGripper => 4,
            Self::CloseGripper => 5,
            Self::EmergencyStop => 6,
        }
    }
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(OPS, operation, args)?;
        Ok(match a.operation() {
            "switch_on" => Self::SwitchOn,
            "switch_off" => Self::SwitchOff,
            "move_to" => Self::MoveTo([a.float(0)?, a.float(1)?, a.float(2)?]),
            "reset" => Self::Reset,
            "open_gripper" => Self::OpenGripper,
            "close_gripper" => Self::CloseGripper,
            _ => Self::EmergencyStop,
        })
    }
}

#[derive(Default)]
struct Ports {
    sensed: Option<DataReader<Feedback>>,
    setpoint: Option<DataWriter<Setpoint>>,
    status: Option<DataWriter<RobotStatus>>,
    tracking: Option<EventReceiver<TrackingError>>,
    range: Option<EventReceiver<RangeError>>,
    position_reached: Option<EventSource<Vec3>>,
    gripper_opened: Option<EventSource<()>>,
    gripper_closed: Option<EventSource<()>>,
    object_grabbed: Option<EventSource<()>>,
    emergency_stop: Option<EventSource<()>>,
}

fn emit<T: Clone + Send + 'static>(ev: &mut Option<EventSource<T>>, v: T) {
    if let Some(e) = ev {
        e.emit(v);
    }
}

/// The robot task.
pub struct Robot {
    cfg: RobotConfig,
    ports: Ports,
    sensed: Feedback,
    prev: Feedback,
    state: RobotState,
    setpoint: Setpoint,
    motion: Option<LineMove>,
    settled: u32,
    /// Cycle at which the current gripper command was accepted.
    gripper_since_ns: u64,
}

impl Robot {
    /// A robot with `cfg`.
    pub fn new(cfg: RobotConfig) -> Self {
        Self {
            cfg,
            ports: Ports::default(),
            sensed: Feedback::default(),
            prev: Feedback::default(),
            state: RobotState::Off,
            setpoint: Setpoint::default(),
            motion: None,
            settled: 0,
            gripper_since_ns: 0,
        }
    }

    /// Brakes, opens the loop and ends any move; `state` says why.
    fn stop_in(&mut self, state: RobotState) {
        self.state = state;
        self.motion = None;
        self.setpoint.enabled = false;
        self.hold_here();
    }

    /// Setpoint = measured position, at rest.
    fn hold_here(&mut self) {
        self.setpoint.position_mm = self.sensed.position_mm;
        self.setpoint.velocity_mm_s = [0.0; 3];
        self.setpoint.acceleration_mm_s2 = [0.0; 3];
    }

    fn emergency_stop(&mut self) {
        if self.state != RobotState::EmergencyStop {
            self.stop_in(RobotState::EmergencyStop);
            emit(&mut self.ports.emergency_stop, ());
        }
    }

    fn in_workspace(&self, p: &Vec3) -> bool {
        p.iter()
            .enumerate()
            .all(|(i, v)| v.is_finite() && (self.cfg.min_mm[i]..=self.cfg.max_mm[i]).contains(v))
    }

    fn gripper_edges(&mut self) {
        let (now, was) = (self.sensed, self.prev);
        if now.gripper_open && !was.gripper_open {
            emit(&mut self.ports.gripper_opened, ());
        }
        if now.gripper_closed && !was.gripper_closed {
            emit(&mut self.ports.gripper_closed, ());
        }
        if now.object_present && !was.object_present {
            emit(&mut self.ports.object_grabbed, ());
        }
        if now.estop_pressed && !was.estop_pressed {
            self.emergency_stop();
        }
    }

    fn gripper_progress(&self, done: bool, ctx: &StepContext) -> Progress {
        if done {
            Progress::Done
        } else if ctx.now_ns.saturating_sub(self.gripper_since_ns)
            > self.cfg.gripper_timeout_ms * 1_000_000
        {
            Progress::Failed("the gripper did not reach its end switch in time")
        } else {
            Progress::Running
        }
    }
}

impl Task for Robot {
    type Command = RobotCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        let p = &mut self.ports;
        p.sensed = Some(ctx.input(names::SENSED));
        p.setpoint = Some(ctx.output(names::SETPOINT));
        p.status = Some(ctx.output(names::ROBOT_STATUS));
        p.tracking = Some(ctx.subscribe(names::TRACKING_ERROR_EVENT, 8));
        p.range = Some(ctx.subscribe(names::RANGE_ERROR_EVENT, 8));
        p.position_reached = Some(ctx.event("position_reached"));
        p.gripper_opened = Some(ctx.event("gripper_opened"));
        p.gripper_closed = Some(ctx.event("gripper_closed"));
        p.object_grabbed = Some(ctx.event("object_grabbed"));
        p.emergency_stop = Some(ctx.event("emergency_stop"));
        Ok(())
    }
    fn start(&mut self) -> Result<(), TaskError> {
        self.state = RobotState::Off;
        self.motion = None;
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        self.prev = self.sensed;
        if let Some(r) = &mut self.ports.sensed {
            r.get(&mut self.sensed);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.gripper_edges();
        let dt = ctx.period_ns as f64 * 1e-9;
        match (&mut self.motion, self.state) {
            (Some(m), RobotState::Moving) => {
                let s = m.advance(dt);
                self.setpoint.position_mm = s.position_mm;
                self.setpoint.velocity_mm_s = s.velocity_mm_s;
                self.setpoint.acceleration_mm_s2 = s.acceleration_mm_s2;
            }
            (_, RobotState::Idle | RobotState::Moving) => {}
            // Off, faulted or e-stopped: the setpoint follows the braked axes, so that
            // switching on does not jump.
            _ => self.hold_here(),
        }
        if let Some(o) = &mut self.ports.setpoint {
            o.set(self.setpoint);
        }
        if let Some(o) = &mut self.ports.status {
            o.set(RobotStatus {
                state: self.state,
                position_mm: self.sensed.position_mm,
                gripper_closed: self.sensed.gripper_closed,
                gripper_open: self.sensed.gripper_open,
                object_present: self.sensed.object_present,
            });
        }
        Ok(())
    }
    fn accept(&mut self, c: &RobotCmd, ctx: &StepContext) -> Result<(), RejectReason> {
        use RobotState as S;
        let stopped = matches!(self.state, S::Fault | S::EmergencyStop);
        match *c {
            RobotCmd::SwitchOn => {
                if stopped {
                    return Err(RejectReason::Other("fault or emergency stop: reset first"));
                }
                if self.sensed.estop_pressed {
                    return Err(RejectReason::Other("the e-stop button is pressed"));
                }
                if self.state == S::Off {
                    self.hold_here();
                    self.state = S::Idle;
                    self.setpoint.enabled = true;
                }
            }
            RobotCmd::SwitchOff => {
                if !stopped {
                    self.stop_in(S::Off);
                }
            }
            RobotCmd::MoveTo(target) => {
                match self.state {
                    S::Idle => {}
                    S::Moving => return Err(RejectReason::Busy),
                    _ => return Err(RejectReason::Other("the robot is not switched on")),
                }
                if !self.in_workspace(&target) {
                    return Err(RejectReason::BadParameters("target outside the workspace"));
                }
                self.motion = Some(LineMove::new(
                    self.setpoint.position_mm,
                    target,
                    self.cfg.max_velocity_mm_s,
                    self.cfg.max_acceleration_mm_s2,
                ));
                self.settled = 0;
                self.state = S::Moving;
            }
            RobotCmd::Reset => {
                if self.sensed.estop_pressed {
                    return Err(RejectReason::Other("the e-stop button is pressed"));
                }
                if stopped {
                    self.stop_in(S::Off);
                }
            }
            RobotCmd::OpenGripper | RobotCmd::CloseGripper => {
                if self.state == S::EmergencyStop {
                    return Err(RejectReason::WrongState(TaskState::Running));
                }
                self.setpoint.gripper_close = *c == RobotCmd::CloseGripper;
                self.gripper_since_ns = ctx.now_ns;
            }
            RobotCmd::EmergencyStop => self.emergency_stop(),
        }
        Ok(())
    }
    fn progress(&mut self, c: &RobotCmd, ctx: &StepContext) -> Progress {
        match *c {
            RobotCmd::MoveTo(target) => {
                if self.state != RobotState::Moving {
                    return Progress::Failed("the robot stopped before reaching the target");
                }
                let finished = self.motion.is_some_and(|m| m.finished());
                if finished && distance(&self.sensed.position_mm, &target) <= self.cfg.tolerance_mm
                {
                    self.settled += 1;
                } else {
                    self.settled = 0;
                }
                if self.settled >= self.cfg.settle_cycles {
                    self.motion = None;
                    self.state = RobotState::Idle;
                    self.setpoint.position_mm = target;
                    self.setpoint.velocity_mm_s = [0.0; 3];
                    self.setpoint.acceleration_mm_s2 = [0.0; 3];
                    emit(&mut self.ports.position_reached, target);
                    Progress::Done
                } else {
                    Progress::Running
                }
            }
            RobotCmd::OpenGripper => self.gripper_progress(self.sensed.gripper_open, ctx),
            RobotCmd::CloseGripper => self.gripper_progress(self.sensed.gripper_closed, ctx),
            _ => Progress::Done,
        }
    }
    fn process_events(&mut self, _: &StepContext) {
        let mut fault = false;
        if let Some(r) = &mut self.ports.tracking {
            fault |= r.drain(|_| {}) > 0;
        }
        if let Some(r) = &mut self.ports.range {
            fault |= r.drain(|_| {}) > 0;
        }
        if fault && matches!(self.state, RobotState::Idle | RobotState::Moving) {
            self.stop_in(RobotState::Fault);
        }
    }
}
