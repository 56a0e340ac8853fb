//! The simulated axis' own error type.

use crate::axis::{DriveState, FaultCode};
use crate::error::{Error, ErrorKind};

/// Why a simulated axis refused a request.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SimAxisError {
    /// The simulated link is cut (injected through
    /// [`SimAxisHandle::set_disconnected`](super::SimAxisHandle::set_disconnected)).
    #[error("link to the simulated drive is down")]
    Disconnected,
    /// The drive is faulted.
    #[error("drive is faulted (fault code {0})")]
    Faulted(FaultCode),
    /// The drive is not in `OperationEnabled`.
    #[error("drive is not operational (state: {0})")]
    NotOperational(DriveState),
    /// Targets are refused while the drive homes itself.
    #[error("homing in progress")]
    HomingInProgress,
    /// The target would drive further into an active limit switch.
    #[error("{0} limit switch active: motion further that way refused")]
    LimitSwitch(&'static str),
    /// A request parameter is invalid.
    #[error("invalid argument: {0}")]
    InvalidArgument(&'static str),
    /// The homing method needs a switch this axis does not have.
    #[error("no {0} on this axis for the requested homing method")]
    NoSwitch(&'static str),
    /// The configuration is not physical.
    #[error("invalid simulated axis configuration: {0}")]
    InvalidConfig(&'static str),
}

impl Error for SimAxisError {
    fn kind(&self) -> ErrorKind {
        match self {
            SimAxisError::Disconnected => ErrorKind::Disconnected,
            SimAxisError::Faulted(_) => ErrorKind::DeviceFault,
            SimAxisError::NotOperational(_) | SimAxisError::HomingInProgress => ErrorKind::NotReady,
            SimAxisError::LimitSwitch(_) => ErrorKind::LimitReached,
            SimAxisError::InvalidArgument(_) | SimAxisError::InvalidConfig(_) => {
                ErrorKind::InvalidArgument
            }
            SimAxisError::NoSwitch(_) => ErrorKind::Unsupported,
        }
    }
}
