//! Errors of the SocketCAN bus, each naming the interface, mapped to the HAL's
//! [`ErrorKind`](crate::ErrorKind) so the machine's monitor can react without knowing
//! SocketCAN.

use super::IfName;
use crate::error::{Error, ErrorKind};
use socketcan::errors::ControllerProblems;
use std::io;

/// What went wrong on a SocketCAN interface. Every variant names the interface; none
/// allocates when it is built, so the servo thread may create them.
#[derive(Debug, thiserror::Error)]
pub enum SocketCanError {
    /// The interface name is empty or longer than the kernel's 15 characters.
    #[error("CAN interface name {name:?} is invalid (1 to 15 characters)")]
    BadName {
        /// The rejected name.
        name: String,
    },
    /// No interface of that name exists (not created, or the adapter is unplugged).
    #[error("CAN interface {iface}: no such interface (create it and bring it up: `ip link set {iface} up type can bitrate ...`)")]
    NoSuchInterface {
        /// The interface.
        iface: IfName,
    },
    /// The interface disappeared while in use (`ENODEV`: the adapter was unplugged or the
    /// interface deleted).
    #[error("CAN interface {iface} is gone (adapter unplugged or interface deleted)")]
    Gone {
        /// The interface.
        iface: IfName,
    },
    /// The interface is administratively down (`ENETDOWN`).
    #[error("CAN interface {iface} is down (`ip link set {iface} up`)")]
    InterfaceDown {
        /// The interface.
        iface: IfName,
    },
    /// The transmit queue of the interface (or the socket's send buffer) is full
    /// (`ENOBUFS`/`EAGAIN`); the frame was not sent.
    #[error("CAN interface {iface}: transmit queue full, frame not sent")]
    TxQueueFull {
        /// The interface.
        iface: IfName,
    },
    /// The controller went bus-off after too many transmit errors: it takes no part in
    /// bus traffic until it is restarted.
    #[error("CAN interface {iface}: bus off")]
    BusOff {
        /// The interface.
        iface: IfName,
    },
    /// The controller reached error-passive (error counter >= 128): the bus is badly
    /// disturbed (wiring, termination, bitrate).
    #[error("CAN interface {iface}: controller error-passive ({problems})")]
    ErrorPassive {
        /// The interface.
        iface: IfName,
        /// The controller flags of the error frame.
        problems: ControllerProblems,
    },
    /// The controller lost frames (receive or transmit buffer overflow).
    #[error("CAN interface {iface}: controller problem: {problems}")]
    Controller {
        /// The interface.
        iface: IfName,
        /// The controller flags of the error frame.
        problems: ControllerProblems,
    },
    /// No node acknowledged a frame, or the driver timed out sending it: nobody else is
    /// on the bus, or the cable is off.
    #[error(
        "CAN interface {iface}: no acknowledge / transmit timeout (is any other node on the bus?)"
    )]
    NoAck {
        /// The interface.
        iface: IfName,
    },
    /// Another error frame (protocol violation, transceiver fault, bus error).
    #[error("CAN interface {iface}: {cause}")]
    ErrorFrame {
        /// The interface.
        iface: IfName,
        /// The decoded cause.
        cause: socketcan::ErrorCause,
    },
    /// A frame the hal cannot represent (a CAN FD frame on a classic socket).
    #[error("CAN interface {iface}: cannot convert frame ({what})")]
    BadFrame {
        /// The interface.
        iface: IfName,
        /// What was wrong.
        what: &'static str,
    },
    /// Any other system error, with the operation that failed.
    #[error("CAN interface {iface}: {op}: {source}")]
    Io {
        /// The interface.
        iface: IfName,
        /// What was being done (`open`, `send`, `receive`, `set filters`).
        op: &'static str,
        /// The system error.
        #[source]
        source: io::Error,
    },
}

impl Error for SocketCanError {
    fn kind(&self) -> ErrorKind {
        match self {
            SocketCanError::BadName { .. } | SocketCanError::NoSuchInterface { .. } => {
                ErrorKind::InvalidArgument
            }
            SocketCanError::Gone { .. }
            | SocketCanError::InterfaceDown { .. }
            | SocketCanError::BusOff { .. } => ErrorKind::Disconnected,
            SocketCanError::TxQueueFull { .. } => ErrorKind::WouldBlock,
            SocketCanError::NoAck { .. } => ErrorKind::Timeout,
            SocketCanError::BadFrame { .. } => ErrorKind::Unsupported,
            SocketCanError::ErrorPassive { .. }
            | SocketCanError::Controller { .. }
            | SocketCanError::ErrorFrame { .. }
            | SocketCanError::Io { .. } => ErrorKind::Other,
        }
    }
}

impl SocketCanError {
    /// Classifies a system error of operation `op` on `iface`.
    pub(crate) fn from_io(iface: IfName, op: &'static str, e: io::Error) -> SocketCanError {
        match e.raw_os_error() {
            Some(libc::ENETDOWN) => SocketCanError::InterfaceDown { iface },
            Some(libc::ENODEV | libc::ENXIO) if op == "open" => {
                SocketCanError::NoSuchInterface { iface }
            }
            Some(libc::ENODEV | libc::ENXIO) => SocketCanError::Gone { iface },
            Some(libc::ENOBUFS) => SocketCanError::TxQueueFull { iface },
            Some(libc::EAGAIN) if op == "send" => SocketCanError::TxQueueFull { iface },
            _ => SocketCanError::Io {
                iface,
                op,
                source: e,
            },
        }
    }
}
