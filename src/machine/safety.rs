//! Safety checks run every servo cycle by the monitor task: drive faults, following error,
//! soft limits, limit switches and communication loss. (The e-stop input is read by the
//! machine task itself, and overrun storms come from the realtime core's overrun policy.)
//!
//! The checks are pure functions of one cycle's data so that each path is unit-tested
//! without threads; the monitor task wires them to data objects and turns a [`Trip`] into
//! the reaction the machine state machine and the interpolator carry out:
//! - [`Reaction::QuickStop`] (e-stop): every drive's quick stop this cycle, outputs safe.
//! - [`Reaction::ControlledStop`] (faults): the interpolator decelerates along the path
//!   within the axis limits, then the drives are disabled.
//!
//! Nothing here allocates: a trip names its axis by index and carries its value.

/// What tripped, with the axis and value involved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trip {
    /// The e-stop input (or `estop` command).
    Estop,
    /// A drive reports a fault.
    DriveFault {
        /// Axis index.
        axis: usize,
        /// Drive's fault code (CiA 402 error code for CANopen drives).
        code: u16,
    },
    /// |commanded - actual| exceeded the axis' following-error limit.
    FollowingError {
        /// Axis index.
        axis: usize,
        /// The error, mm or deg.
        error: f64,
        /// The limit.
        limit: f64,
    },
    /// A commanded position left the soft limits (the planner refuses such moves first; this
    /// catches jogs, rounding and bugs).
    SoftLimit {
        /// Axis index.
        axis: usize,
        /// Commanded position.
        position: f64,
    },
    /// A limit switch was hit.
    LimitSwitch {
        /// Axis index.
        axis: usize,
    },
    /// A drive stopped answering (no feedback for too many cycles).
    CommunicationLost {
        /// Axis index.
        axis: usize,
    },
    /// The spindle did not report at-speed in time after M3/M4.
    SpindleNotAtSpeed,
    /// Homing of an axis failed (switch not found, limit hit, drive stopped).
    HomingFailed {
        /// Axis index.
        axis: usize,
    },
    /// A CANopen drive's link failed: heartbeat lost, emergency, drive fault, boot-up, bus
    /// error (node and cause in `fault`).
    Fieldbus {
        /// Axis index.
        axis: usize,
        /// Node, cause and error code.
        fault: hytask_hal::canopen::axis::LinkFault,
    },
    /// The PLC (safety relevant) went into fault; its `plc.fault` event says where.
    PlcFault,
    /// The servo thread overran its period too many times in a row.
    OverrunStorm {
        /// Consecutive overruns seen.
        consecutive: u32,
    },
}

/// How the machine reacts to a trip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Quick-stop every drive now (e-stop category 1 style), outputs to safe state.
    QuickStop,
    /// Decelerate along the path within limits, then disable drives and enter `Fault`.
    ControlledStop,
}

impl Trip {
    /// The reaction this trip calls for.
    pub fn reaction(&self) -> Reaction {
        match self {
            Trip::Estop => Reaction::QuickStop,
            // A stalled or faulted drive cannot follow a planned deceleration; the others
            // still can, and stopping them on the path protects the part.
            _ => Reaction::ControlledStop,
        }
    }

    /// Axis involved, if any.
    pub fn axis(&self) -> Option<usize> {
        match *self {
            Trip::DriveFault { axis, .. }
            | Trip::FollowingError { axis, .. }
            | Trip::SoftLimit { axis, .. }
            | Trip::LimitSwitch { axis }
            | Trip::CommunicationLost { axis }
            | Trip::HomingFailed { axis }
            | Trip::Fieldbus { axis, .. } => Some(axis),
            Trip::Estop | Trip::OverrunStorm { .. } | Trip::SpindleNotAtSpeed | Trip::PlcFault => {
                None
            }
        }
    }
}

/// Limits of one axis that the monitor enforces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisGuard {
    /// Soft limit, low end.
    pub min: f64,
    /// Soft limit, high end.
    pub max: f64,
    /// Largest allowed |commanded - actual|.
    pub following_error_limit: f64,
    /// Cycles without fresh feedback before communication counts as lost.
    pub max_stale_cycles: u32,
}

/// One axis' data in one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AxisSample {
    /// Commanded position.
    pub commanded: f64,
    /// Actual position.
    pub actual: f64,
    /// Whether the drive reports a fault, and its code.
    pub fault: Option<u16>,
    /// A limit switch is active.
    pub limit_switch: bool,
    /// Cycles since the last fresh feedback.
    pub stale_cycles: u32,
    /// The axis is homed (soft limits only apply once the position is known).
    pub homed: bool,
    /// The drive is enabled (following error only matters when it is).
    pub enabled: bool,
}

/// Checks one axis; the first trip found, in order of severity.
pub fn check_axis(axis: usize, guard: &AxisGuard, s: &AxisSample) -> Option<Trip> {
    if let Some(code) = s.fault {
        return Some(Trip::DriveFault { axis, code });
    }
    if s.stale_cycles > guard.max_stale_cycles {
        return Some(Trip::CommunicationLost { axis });
    }
    if s.limit_switch {
        return Some(Trip::LimitSwitch { axis });
    }
    if s.enabled {
        let error = s.commanded - s.actual;
        if error.abs() > guard.following_error_limit || !error.is_finite() {
            return Some(Trip::FollowingError {
                axis,
                error,
                limit: guard.following_error_limit,
            });
        }
    }
    if s.homed && (s.commanded < guard.min || s.commanded > guard.max) {
        return Some(Trip::SoftLimit {
            axis,
            position: s.commanded,
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const GUARD: AxisGuard = AxisGuard {
        min: 0.0,
        max: 100.0,
        following_error_limit: 0.5,
        max_stale_cycles: 3,
    };

    fn ok_sample() -> AxisSample {
        AxisSample {
            commanded: 10.0,
            actual: 9.9,
            fault: None,
            limit_switch: false,
            stale_cycles: 0,
            homed: true,
            enabled: true,
        }
    }

    #[test]
    fn healthy_axis_does_not_trip() {
        assert_eq!(check_axis(0, &GUARD, &ok_sample()), None);
    }

    #[test]
    fn each_fault_path_trips_with_axis_and_value() {
        let s = AxisSample {
            actual: 9.0,
            ..ok_sample()
        };
        assert_eq!(
            check_axis(2, &GUARD, &s),
            Some(Trip::FollowingError {
                axis: 2,
                error: 1.0,
                limit: 0.5
            })
        );
        let s = AxisSample {
            fault: Some(0x7500),
            ..ok_sample()
        };
        assert_eq!(
            check_axis(1, &GUARD, &s),
            Some(Trip::DriveFault {
                axis: 1,
                code: 0x7500
            })
        );
        let s = AxisSample {
            commanded: 100.5,
            actual: 100.4,
            ..ok_sample()
        };
        assert_eq!(
            check_axis(0, &GUARD, &s),
            Some(Trip::SoftLimit {
                axis: 0,
                position: 100.5
            })
        );
        let s = AxisSample {
            stale_cycles: 4,
            ..ok_sample()
        };
        assert_eq!(
            check_axis(0, &GUARD, &s),
            Some(Trip::CommunicationLost { axis: 0 })
        );
        let s = AxisSample {
            limit_switch: true,
            ..ok_sample()
        };
        assert_eq!(
            check_axis(0, &GUARD, &s),
            Some(Trip::LimitSwitch { axis: 0 })
        );
        let s = AxisSample {
            actual: f64::NAN,
            ..ok_sample()
        };
        assert!(matches!(
            check_axis(0, &GUARD, &s),
            Some(Trip::FollowingError { .. })
        ));
    }

    #[test]
    fn soft_limits_wait_for_homing_and_following_error_for_enable() {
        let s = AxisSample {
            commanded: -5.0,
            actual: -5.0,
            homed: false,
            ..ok_sample()
        };
        assert_eq!(check_axis(0, &GUARD, &s), None);
        let s = AxisSample {
            actual: 0.0,
            enabled: false,
            ..ok_sample()
        };
        assert_eq!(check_axis(0, &GUARD, &s), None);
    }

    #[test]
    fn estop_quick_stops_and_faults_stop_under_control() {
        assert_eq!(Trip::Estop.reaction(), Reaction::QuickStop);
        assert_eq!(
            Trip::SoftLimit {
                axis: 0,
                position: 1.0
            }
            .reaction(),
            Reaction::ControlledStop
        );
    }
}
