//! The values the cell's tasks exchange: data objects between the servo tasks, the robot's
//! status, and the payloads of its events. All `Copy` and fixed-size, so that writing a data
//! object or emitting an event inside a servo step never allocates.

/// Number of axes of the gantry (X, Y, Z).
pub const AXES: usize = 3;

/// A position or a per-axis quantity, mm (or mm/s, N, per the name of the field).
pub type Vec3 = [f64; AXES];

/// Euclidean distance between two points, mm.
pub fn distance(a: &Vec3, b: &Vec3) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f64>()
        .sqrt()
}

/// What the simulated hardware reports each servo cycle (the encoders and the digital
/// inputs): written by the `hw` task, read by the sensor task one cycle later, like a real
/// encoder read at the start of a cycle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Feedback {
    /// Encoder positions, mm.
    pub position_mm: Vec3,
    /// Digital input: the gripper's "open" end switch.
    pub gripper_open: bool,
    /// Digital input: the gripper's "closed" end switch (closed on an object or on nothing).
    pub gripper_closed: bool,
    /// Digital input: the "object present" sensor between the fingers.
    pub object_present: bool,
    /// Digital input: the e-stop button of the cell (true = pressed).
    pub estop_pressed: bool,
}

/// What the effector drives: the amplifiers' force commands and enable, and the gripper's
/// digital output.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DriveOutput {
    /// Force per axis, N (0 while disabled).
    pub force_n: Vec3,
    /// Amplifiers enabled (disabled axes are held by their brakes).
    pub enabled: bool,
    /// Digital output: close the gripper (false = open).
    pub gripper_close: bool,
}

/// The robot task's setpoint for the PID: where the axes should be this cycle, the setpoint's
/// velocity and acceleration for feed-forward, and whether the loop is closed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Setpoint {
    /// Position, mm.
    pub position_mm: Vec3,
    /// Velocity, mm/s.
    pub velocity_mm_s: Vec3,
    /// Acceleration, mm/s².
    pub acceleration_mm_s2: Vec3,
    /// Loop closed and amplifiers enabled.
    pub enabled: bool,
    /// Gripper output wanted (true = closed).
    pub gripper_close: bool,
}

/// The robot's supervisory state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RobotState {
    /// Amplifiers off, axes braked.
    #[default]
    Off,
    /// On, holding position.
    Idle,
    /// On, moving.
    Moving,
    /// A tracking or range error stopped it; `reset` then `switch_on`.
    Fault,
    /// Emergency-stopped; `reset` then `switch_on`.
    EmergencyStop,
}

/// The robot's status as published every servo cycle (data object [`names::ROBOT_STATUS`]).
///
/// [`names::ROBOT_STATUS`]: super::names::ROBOT_STATUS
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobotStatus {
    /// Supervisory state.
    pub state: RobotState,
    /// Measured position, mm.
    pub position_mm: Vec3,
    /// Gripper closed (end switch).
    pub gripper_closed: bool,
    /// Gripper open (end switch).
    pub gripper_open: bool,
    /// An object is between the fingers.
    pub object_present: bool,
}

/// Kind of an object arriving at the pick position.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum ObjectKind {
    /// Belongs in container A.
    #[default]
    A,
    /// Belongs in container B.
    B,
    /// Neither: goes to the reject container.
    Unknown,
}

impl ObjectKind {
    /// Where an object of this kind belongs.
    pub fn container(self) -> Container {
        match self {
            Self::A => Container::A,
            Self::B => Container::B,
            Self::Unknown => Container::Reject,
        }
    }
}

/// A destination of the selection.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Container {
    /// Container A.
    #[default]
    A,
    /// Container B.
    B,
    /// The reject container.
    Reject,
}

impl Container {
    /// All containers, in report order.
    pub const ALL: [Container; 3] = [Container::A, Container::B, Container::Reject];

    /// Index into per-container arrays.
    pub fn index(self) -> usize {
        match self {
            Self::A => 0,
            Self::B => 1,
            Self::Reject => 2,
        }
    }

    /// Name as printed.
    pub fn name(self) -> &'static str {
        match self {
            Self::A => "A",
            Self::B => "B",
            Self::Reject => "reject",
        }
    }
}

/// The simulated world's tally, published by the `hw` task every cycle (data object
/// [`names::WORLD`]): objects that appeared, where they ended.
///
/// [`names::WORLD`]: super::names::WORLD
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct WorldTally {
    /// Objects that appeared at the pick position.
    pub spawned: u32,
    /// Objects that landed in containers A, B, reject.
    pub in_container: [u32; 3],
    /// Objects whose kind did not match the container they landed in.
    pub missorted: u32,
    /// Objects that fell anywhere else (lost while moving, released off target).
    pub on_floor: u32,
}

/// What the camera sees at the camera position: the kind of the object held there, if any.
/// Written by the `hw` task (the scene), read by the camera task when it grabs a frame.
/// Serde: a remote camera receives it over Zenoh (`cell::remote`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CameraScene {
    /// The object in view, if one is held within the camera's field.
    pub object: Option<ObjectKind>,
}

/// Payload of the PID's tracking-error event.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrackingError {
    /// Axis index (0 = X).
    pub axis: usize,
    /// Setpoint − position when raised, mm.
    pub error_mm: f64,
}

/// Payload of the sensor's range-error event.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RangeError {
    /// Axis index (0 = X).
    pub axis: usize,
    /// Measured position out of range, mm.
    pub position_mm: f64,
}

/// Payload of the selection task's `operation_n_done` event: one object sorted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RunDone {
    /// Run number within the current `run(n)`, from 1.
    pub run: u32,
    /// Runs asked for by `run(n)`.
    pub of: u32,
    /// Where the object went.
    pub container: Container,
    /// Selection time of this run (pick to release), ms.
    pub cycle_ms: u64,
}
