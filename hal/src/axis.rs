//! Axis capabilities: the drive's power state machine and cyclic position targets
//! ([`AxisDrive`]), what the drive reports back ([`AxisFeedback`]), and drive-side homing
//! ([`Homing`]).
//!
//! The model is CiA 402 (the CANopen drive profile) in cyclic synchronous position (CSP)
//! mode: the controller sends a new target position every servo cycle and the drive's own
//! position loop follows it. Positions are in machine units (mm, or degrees for rotary
//! axes); the backend converts to encoder counts. A simulator and a CANopen drive behave the
//! same through these traits, so the drive task and the monitor are written once.
//!
//! All methods are called from the servo thread: implementations must be non-blocking and
//! bounded (no allocation, no lock held across I/O). Commands that need several cycles
//! (enabling walks the CiA 402 state machine) are *requests*: they return at once and the
//! state is observed through [`AxisFeedback::drive_state`] on later cycles.

use crate::error::ErrorType;
use core::fmt;

/// The drive's power state, as in the CiA 402 state machine (object 0x6041 decoded).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveState {
    /// Initialising after power-on; accepts no command.
    NotReadyToSwitchOn,
    /// Initialised, high voltage may be off; the state after a fault reset or a disable.
    SwitchOnDisabled,
    /// Ready to switch on the power stage.
    ReadyToSwitchOn,
    /// Power stage on, motor not yet controlled.
    SwitchedOn,
    /// The position loop runs and follows target positions: the only state that moves.
    OperationEnabled,
    /// A quick stop is braking (or has braked) the motor; targets are refused.
    QuickStopActive,
    /// A fault was detected and the drive's fault reaction (braking) is running.
    FaultReactionActive,
    /// The drive is faulted; [`AxisFeedback::fault_code`] says why; needs a fault reset.
    Fault,
}

impl DriveState {
    /// True in the states where the drive reports a fault.
    pub fn is_fault(self) -> bool {
        matches!(self, DriveState::Fault | DriveState::FaultReactionActive)
    }

    /// True when the drive follows target positions.
    pub fn is_operational(self) -> bool {
        self == DriveState::OperationEnabled
    }
}

impl fmt::Display for DriveState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            DriveState::NotReadyToSwitchOn => "not ready to switch on",
            DriveState::SwitchOnDisabled => "switch on disabled",
            DriveState::ReadyToSwitchOn => "ready to switch on",
            DriveState::SwitchedOn => "switched on",
            DriveState::OperationEnabled => "operation enabled",
            DriveState::QuickStopActive => "quick stop active",
            DriveState::FaultReactionActive => "fault reaction active",
            DriveState::Fault => "fault",
        };
        f.write_str(s)
    }
}

/// A drive fault code, as in CiA 402 object 0x603F (CiA 301 error code classes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FaultCode(pub u16);

impl FaultCode {
    /// Generic error (0x1000).
    pub const GENERIC: FaultCode = FaultCode(0x1000);
    /// Continuous over-current (0x2310).
    pub const OVERCURRENT: FaultCode = FaultCode(0x2310);
    /// Motor blocked / stalled (0x7121).
    pub const MOTOR_BLOCKED: FaultCode = FaultCode(0x7121);
    /// Following error exceeded the drive's window (0x8611).
    pub const FOLLOWING_ERROR: FaultCode = FaultCode(0x8611);
}

impl fmt::Display for FaultCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:04X}", self.0)
    }
}

/// The state of the drive's own switch inputs (CiA 402 object 0x60FD: bit 0 negative
/// limit, bit 1 positive limit, bit 2 home switch). `true` means active (tripped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AxisSwitches {
    /// The negative-direction limit switch is active.
    pub negative_limit: bool,
    /// The positive-direction limit switch is active.
    pub positive_limit: bool,
    /// The home switch is active.
    pub home: bool,
}

/// Commands to a drive: the power state machine and cyclic synchronous position targets.
pub trait AxisDrive: ErrorType {
    /// Requests the drive to walk to [`DriveState::OperationEnabled`] (from switch-on
    /// disabled, or back from quick stop). Returns at once; the transition takes one or more
    /// cycles. Fails if the drive is faulted (reset it first).
    fn enable(&mut self) -> Result<(), Self::Error>;

    /// Requests the drive to switch its power stage off (to [`DriveState::SwitchOnDisabled`]).
    /// The motor is no longer controlled and coasts to a stop.
    fn disable(&mut self) -> Result<(), Self::Error>;

    /// Sets the target position for this cycle (CSP: call once per servo cycle while
    /// operational). Refused when the drive is not in [`DriveState::OperationEnabled`], while
    /// homing, or when the target would drive further into an active limit switch.
    fn set_target_position(&mut self, position: f64) -> Result<(), Self::Error>;

    /// Requests a quick stop: the drive brakes on its quick-stop ramp and holds in
    /// [`DriveState::QuickStopActive`] until enabled again or disabled.
    fn quick_stop(&mut self) -> Result<(), Self::Error>;

    /// Resets a fault: from [`DriveState::Fault`] to [`DriveState::SwitchOnDisabled`] and
    /// clears the fault code. Does nothing in other states.
    fn fault_reset(&mut self) -> Result<(), Self::Error>;
}

/// Everything a drive reports in one cycle, read at once by [`AxisFeedback::status`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisStatus {
    /// Actual position in machine units.
    pub position: f64,
    /// Actual velocity in machine units per second.
    pub velocity: f64,
    /// Power state.
    pub state: DriveState,
    /// Active fault code, if faulted.
    pub fault: Option<FaultCode>,
    /// Limit and home switches.
    pub switches: AxisSwitches,
}

/// What a drive reports back every cycle.
pub trait AxisFeedback: ErrorType {
    /// The actual position in machine units.
    fn actual_position(&mut self) -> Result<f64, Self::Error>;

    /// The actual velocity in machine units per second.
    fn actual_velocity(&mut self) -> Result<f64, Self::Error>;

    /// The drive's power state.
    fn drive_state(&mut self) -> Result<DriveState, Self::Error>;

    /// The active fault code, `None` when the drive is not faulted.
    fn fault_code(&mut self) -> Result<Option<FaultCode>, Self::Error>;

    /// The drive's switch inputs (limits, home).
    fn switches(&mut self) -> Result<AxisSwitches, Self::Error>;

    /// True when the drive follows target positions (a convenience over
    /// [`drive_state`](AxisFeedback::drive_state)).
    fn is_operational(&mut self) -> Result<bool, Self::Error> {
        Ok(self.drive_state()?.is_operational())
    }

    /// All feedback of this cycle in one value (what the drive task publishes to the
    /// monitor). A CANopen backend reads it from one TPDO, so it is consistent.
    fn status(&mut self) -> Result<AxisStatus, Self::Error> {
        Ok(AxisStatus {
            position: self.actual_position()?,
            velocity: self.actual_velocity()?,
            state: self.drive_state()?,
            fault: self.fault_code()?,
            switches: self.switches()?,
        })
    }

    /// The following error for a commanded `target`: `target - actual`. The monitor compares
    /// it with the axis' following error limit.
    fn following_error(&mut self, target: f64) -> Result<f64, Self::Error> {
        Ok(target - self.actual_position()?)
    }
}

/// How the drive finds its reference position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HomingMethod {
    /// Move at the search velocity until the home switch becomes active, then back off at
    /// the latch velocity until it releases; the release edge is the home position.
    HomeSwitch,
    /// As [`HomingMethod::HomeSwitch`], but on the limit switch in the search direction.
    LimitSwitch,
    /// No motion: the current position becomes the home position.
    CurrentPosition,
}

/// Parameters of one homing run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HomingParams {
    /// How to find the reference.
    pub method: HomingMethod,
    /// Search velocity in machine units per second; its sign is the search direction.
    pub search_velocity: f64,
    /// Back-off (latch) velocity magnitude in machine units per second; slower than the
    /// search so that the latched edge is precise.
    pub latch_velocity: f64,
    /// The position assigned to the reference edge.
    pub home_position: f64,
}

/// Progress of homing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HomingStatus {
    /// Never homed since power-on (positions are relative to an arbitrary start).
    NotHomed,
    /// A homing run is moving the axis.
    InProgress,
    /// The position is referenced.
    Homed,
    /// The last homing run failed; the axis is not referenced.
    Failed(HomingFailure),
}

/// Why a homing run failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HomingFailure {
    /// [`Homing::abort_homing`] was called.
    Aborted,
    /// A limit switch was hit before the home switch.
    LimitReached,
    /// The drive left `OperationEnabled` (fault, quick stop, disable) during the run.
    DriveStopped,
}

/// Drive-side homing (CiA 402 homing mode).
pub trait Homing: ErrorType {
    /// Starts a homing run. Requires [`DriveState::OperationEnabled`]; while it runs, target
    /// positions are refused.
    fn start_homing(&mut self, params: &HomingParams) -> Result<(), Self::Error>;

    /// Where homing stands.
    fn homing_status(&mut self) -> Result<HomingStatus, Self::Error>;

    /// Stops a running homing run (the axis brakes); the status becomes
    /// [`HomingFailure::Aborted`]. Does nothing if no run is active.
    fn abort_homing(&mut self) -> Result<(), Self::Error>;

    /// True when the axis position is referenced.
    fn is_homed(&mut self) -> Result<bool, Self::Error> {
        Ok(self.homing_status()? == HomingStatus::Homed)
    }
}

/// A complete axis: command, feedback and homing, with one error type. Blanket-implemented,
/// so `Box<dyn Axis<Error = E>>` can hold any backend's axis.
pub trait Axis: AxisDrive + AxisFeedback + Homing {}

impl<T: AxisDrive + AxisFeedback + Homing + ?Sized> Axis for T {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_states_and_operational_state() {
        assert!(DriveState::Fault.is_fault());
        assert!(DriveState::FaultReactionActive.is_fault());
        assert!(!DriveState::QuickStopActive.is_fault());
        assert!(DriveState::OperationEnabled.is_operational());
        assert!(!DriveState::SwitchedOn.is_operational());
    }

    #[test]
    fn fault_code_displays_as_hex() {
        assert_eq!(FaultCode::FOLLOWING_ERROR.to_string(), "0x8611");
        assert_eq!(FaultCode(0x12).to_string(), "0x0012");
    }
}
