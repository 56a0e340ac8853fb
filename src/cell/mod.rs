//! The pick-and-place cell of the seed paper (section VII) on simulated hardware.
//!
//! A Cartesian gantry (X, Y, Z) with a pneumatic gripper picks objects arriving at a pick
//! position, shows each to a camera, and drops it into container A, B or reject. Why a
//! gantry rather than the SCARA of [`crate::motion::kinematics`]: the cell's subject is the
//! task structure (data flow on one servo thread, commands and events between tasks, a slow
//! detection task that must not disturb it, a state machine over them), and a gantry keeps
//! joint space equal to Cartesian space, so a straight move is a straight setpoint per axis
//! and the cell has no singularities or elbow choice to explain. The robot task is the only
//! place that would change for a SCARA (inverse kinematics of each setpoint).
//!
//! # Tasks and threads (start order = data-flow order on the servo thread)
//! | task | thread | role |
//! |---|---|---|
//! | `sensor` | servo (1 ms, highest priority) | encoders and inputs → `cell.sensed`; `range_error` |
//! | `robot` | servo | operations, interpolator, supervisor → `cell.setpoint`, `robot.status` |
//! | `pid` | servo | position loop → `cell.force`; `tracking_error` |
//! | `effector` | servo | force limits, enable, gripper output → `cell.drive` |
//! | `hw` | servo | the simulated world ([`world`]) → `cell.feedback`, `cell.scene`, `cell.world` |
//! | `selection` | selection (10 ms) | the state machine: the script ([`scripted`]) or the Rust reference ([`selection`]) |
//! | `camera` | selection (non-periodic, after the selection) | `start_detection` → detection events |
//!
//! [`deploy`] builds it from a [`config::CellConfig`]; [`daemon`] serves it on the control
//! socket like a machine (`hytask serve --config config/pickplace.toml`), and
//! `hytask run-cell` runs it on an embedded daemon.

pub mod camera;
pub mod config;
pub mod daemon;
pub mod deploy;
pub mod hw;
pub mod pid;
pub mod profile;
pub mod remote;
pub mod rng;
pub mod robot;
pub mod scripted;
pub mod selection;
pub mod sensor;
pub mod types;
pub mod world;

/// Names of the cell's tasks, data objects and events.
pub mod names {
    /// Sensor task.
    pub const SENSOR: &str = "sensor";
    /// Robot task (interpolator, supervisor, operations).
    pub const ROBOT: &str = "robot";
    /// PID task.
    pub const PID: &str = "pid";
    /// Effector task.
    pub const EFFECTOR: &str = "effector";
    /// Simulated hardware task.
    pub const HW: &str = "hw";
    /// Camera detection task.
    pub const CAMERA: &str = "camera";
    /// Selection task.
    pub const SELECTION: &str = "selection";

    /// Raw encoders and inputs (hw → sensor).
    pub const FEEDBACK: &str = "cell.feedback";
    /// Checked measurement (sensor → robot, pid).
    pub const SENSED: &str = "cell.sensed";
    /// Setpoint (robot → pid, effector).
    pub const SETPOINT: &str = "cell.setpoint";
    /// Forces (pid → effector).
    pub const FORCE: &str = "cell.force";
    /// Drive outputs (effector → hw).
    pub const DRIVE: &str = "cell.drive";
    /// What the camera sees (hw → camera).
    pub const SCENE: &str = "cell.scene";
    /// Tally of the simulated world.
    pub const WORLD: &str = "cell.world";
    /// The robot's status.
    pub const ROBOT_STATUS: &str = "robot.status";
    /// The selection's status.
    pub const SELECTION_STATUS: &str = "selection.status";

    /// PID tracking error event.
    pub const TRACKING_ERROR_EVENT: &str = "pid.tracking_error";
    /// Sensor range error event.
    pub const RANGE_ERROR_EVENT: &str = "sensor.range_error";
    /// Robot: position reached.
    pub const POSITION_REACHED_EVENT: &str = "robot.position_reached";
    /// Robot: gripper opened.
    pub const GRIPPER_OPENED_EVENT: &str = "robot.gripper_opened";
    /// Robot: gripper closed.
    pub const GRIPPER_CLOSED_EVENT: &str = "robot.gripper_closed";
    /// Robot: object grabbed.
    pub const OBJECT_GRABBED_EVENT: &str = "robot.object_grabbed";
    /// Robot: emergency stop.
    pub const ROBOT_ESTOP_EVENT: &str = "robot.emergency_stop";
    /// Camera: object A detected.
    pub const A_DETECTED_EVENT: &str = "camera.object_a_detected";
    /// Camera: object B detected.
    pub const B_DETECTED_EVENT: &str = "camera.object_b_detected";
    /// Camera: no (known) object detected.
    pub const NONE_DETECTED_EVENT: &str = "camera.no_object_detected";
    /// Selection: one object sorted.
    pub const RUN_DONE_EVENT: &str = "selection.operation_n_done";
    /// Selection: error detected.
    pub const ERROR_EVENT: &str = "selection.error_detected";
}
