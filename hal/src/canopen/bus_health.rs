//! Bus health: what a failed access to a CAN interface means for the CANopen layer.
//!
//! The bus owner's halves classify every error of their bus into a [`BusFault`] and raise
//! it on every drive of the interface; the fault's message names the interface ("can0:
//! bus-off"), not a node, since the interface failed, not a drive.

use super::axis::LinkCause;
use crate::sim::SimCanError;
use crate::socketcan::SocketCanError;

/// A failure of a CAN interface as a whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusFault {
    /// The controller went bus-off.
    BusOff,
    /// Error frames: error-passive, no acknowledge, protocol errors, lost frames.
    ErrorFrame,
    /// The interface is down or gone.
    InterfaceDown,
    /// The transmit queue is full: a frame was not sent.
    TxQueueFull,
    /// Anything else (a system error).
    Other,
}

impl BusFault {
    /// The drive-link cause that carries it.
    pub fn link_cause(self) -> LinkCause {
        match self {
            BusFault::BusOff => LinkCause::BusOff,
            BusFault::ErrorFrame => LinkCause::ErrorFrame,
            BusFault::InterfaceDown => LinkCause::InterfaceDown,
            BusFault::TxQueueFull => LinkCause::TxQueueFull,
            BusFault::Other => LinkCause::BusError,
        }
    }
}

/// Errors of a CAN bus that say which [`BusFault`] they are.
pub trait BusErrorClass {
    /// The bus fault this error is.
    fn bus_fault(&self) -> BusFault;
}

impl BusErrorClass for SocketCanError {
    fn bus_fault(&self) -> BusFault {
        match self {
            SocketCanError::BusOff { .. } => BusFault::BusOff,
            SocketCanError::InterfaceDown { .. }
            | SocketCanError::Gone { .. }
            | SocketCanError::NoSuchInterface { .. } => BusFault::InterfaceDown,
            SocketCanError::TxQueueFull { .. } => BusFault::TxQueueFull,
            SocketCanError::ErrorPassive { .. }
            | SocketCanError::Controller { .. }
            | SocketCanError::NoAck { .. }
            | SocketCanError::ErrorFrame { .. } => BusFault::ErrorFrame,
            SocketCanError::BadName { .. }
            | SocketCanError::BadFrame { .. }
            | SocketCanError::Io { .. } => BusFault::Other,
        }
    }
}

impl BusErrorClass for SimCanError {
    fn bus_fault(&self) -> BusFault {
        match self {
            SimCanError::BusOff => BusFault::BusOff,
            SimCanError::ErrorFrame => BusFault::ErrorFrame,
            SimCanError::InterfaceDown => BusFault::InterfaceDown,
            SimCanError::TxQueueFull => BusFault::TxQueueFull,
            SimCanError::InvalidSize => BusFault::Other,
        }
    }
}
