//! Parameters of a simulated axis: the motor model, the machine's switches and scheduled
//! fault injection.

use super::error::SimAxisError;
use crate::axis::FaultCode;

/// A region of physical travel where a switch is active (inclusive bounds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwitchRange {
    /// Lower end of the active region.
    pub min: f64,
    /// Upper end of the active region.
    pub max: f64,
}

impl SwitchRange {
    /// True when `position` is inside the region.
    pub fn contains(&self, position: f64) -> bool {
        position >= self.min && position <= self.max
    }
}

/// Faults the simulator raises by itself at a given simulated time, so a configuration can
/// describe a failing machine for testing the monitor and the error policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultInjection {
    /// Simulated time (seconds since creation) at which the drive faults, if any.
    pub drive_fault_at_s: Option<f64>,
    /// The fault code reported by the scheduled drive fault.
    pub drive_fault_code: FaultCode,
    /// Simulated time at which the motor stalls (position stops following), if any.
    pub stall_at_s: Option<f64>,
}

impl Default for FaultInjection {
    fn default() -> Self {
        FaultInjection {
            drive_fault_at_s: None,
            drive_fault_code: FaultCode::GENERIC,
            stall_at_s: None,
        }
    }
}

/// The parameters of a [`SimAxis`](super::SimAxis). Positions of switches are physical
/// (where the switch sits on the machine, in machine units from the simulator's origin),
/// so they do not move when homing re-references the reported position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimAxisConfig {
    /// Velocity limit of the drive in units/s.
    pub max_velocity: f64,
    /// Acceleration limit of the drive in units/s².
    pub max_acceleration: f64,
    /// Time constant of the position loop in seconds: the motor follows the target as a
    /// first-order lag, so at constant speed `v` the following error settles at `v * lag_s`.
    /// Zero follows exactly (within velocity and acceleration limits).
    pub lag_s: f64,
    /// Deceleration of quick stops, fault reactions and limit-switch stops, in units/s².
    pub quick_stop_deceleration: f64,
    /// The drive's own following-error window: beyond it the drive faults with
    /// [`FaultCode::FOLLOWING_ERROR`]. `None` leaves following-error supervision to the
    /// controller.
    pub following_error_window: Option<f64>,
    /// Physical position at power-on.
    pub initial_position: f64,
    /// Physical position at and below which the negative limit switch is active.
    pub negative_limit: Option<f64>,
    /// Physical position at and above which the positive limit switch is active.
    pub positive_limit: Option<f64>,
    /// Physical region where the home switch is active.
    pub home_switch: Option<SwitchRange>,
    /// Scheduled fault injection.
    pub faults: FaultInjection,
}

impl Default for SimAxisConfig {
    fn default() -> Self {
        SimAxisConfig {
            max_velocity: 100.0,
            max_acceleration: 1000.0,
            lag_s: 0.005,
            quick_stop_deceleration: 2000.0,
            following_error_window: None,
            initial_position: 0.0,
            negative_limit: None,
            positive_limit: None,
            home_switch: None,
            faults: FaultInjection::default(),
        }
    }
}

impl SimAxisConfig {
    /// Checks that the parameters describe a physical motor (positive, finite limits,
    /// ordered switches).
    pub fn validate(&self) -> Result<(), SimAxisError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.max_velocity) {
            return Err(SimAxisError::InvalidConfig("max_velocity must be > 0"));
        }
        if !positive(self.max_acceleration) {
            return Err(SimAxisError::InvalidConfig("max_acceleration must be > 0"));
        }
        if !positive(self.quick_stop_deceleration) {
            return Err(SimAxisError::InvalidConfig(
                "quick_stop_deceleration must be > 0",
            ));
        }
        if !(self.lag_s.is_finite() && self.lag_s >= 0.0) {
            return Err(SimAxisError::InvalidConfig("lag_s must be >= 0"));
        }
        if self.following_error_window.is_some_and(|w| !positive(w)) {
            return Err(SimAxisError::InvalidConfig(
                "following_error_window must be > 0",
            ));
        }
        if !self.initial_position.is_finite() {
            return Err(SimAxisError::InvalidConfig(
                "initial_position must be finite",
            ));
        }
        if let (Some(n), Some(p)) = (self.negative_limit, self.positive_limit) {
            if n >= p {
                return Err(SimAxisError::InvalidConfig(
                    "negative_limit must be below positive_limit",
                ));
            }
        }
        if let Some(h) = self.home_switch {
            if !(h.min.is_finite() && h.max.is_finite() && h.min <= h.max) {
                return Err(SimAxisError::InvalidConfig(
                    "home_switch min must be <= max",
                ));
            }
        }
        Ok(())
    }
}
