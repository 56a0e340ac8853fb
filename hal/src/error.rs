//! The shared error vocabulary of the HAL.
//!
//! Backends keep their own detailed `thiserror` enums (a CANopen SDO abort code, a Modbus
//! exception, a simulator's injected fault) and map them to one [`ErrorKind`] through
//! [`Error::kind`]. Generic code, such as the error policy of the machine's monitor, matches
//! on the kind only; people reading logs get the backend's message. This is the
//! `embedded-hal` pattern (`ErrorType` + `Error::kind`).

use core::fmt;

/// What went wrong, in terms generic code can act on.
///
/// The kinds fall in two families that must not be confused (DESIGN.md example 3):
/// the *link* failed ([`Timeout`](ErrorKind::Timeout), [`Disconnected`](ErrorKind::Disconnected)),
/// so the device's state is unknown; or the *device* answered and refused or reported a
/// problem (everything else), so its state is known. [`ErrorKind::is_link_failure`] tells
/// which.
#[non_exhaustive]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// The device did not answer in time (a missed heartbeat, an SDO without response).
    Timeout,
    /// The link to the device is gone (bus off, cable unplugged, TCP connection closed).
    Disconnected,
    /// The device reports a fault of its own (a drive in the CiA 402 `Fault` state).
    DeviceFault,
    /// A limit switch or hardware travel limit blocks the requested motion.
    LimitReached,
    /// The request itself is invalid (index out of range, non-finite value, bad CAN id).
    InvalidArgument,
    /// The device is not in a state that accepts the request (e.g. a target position while
    /// the drive is not in `OperationEnabled`, or while it is homing).
    NotReady,
    /// A bounded queue is full or empty right now; retry on a later cycle.
    WouldBlock,
    /// The device or backend does not support this request.
    Unsupported,
    /// Anything else; the backend's own error carries the detail.
    Other,
}

impl ErrorKind {
    /// True when the link to the device failed, so the device's state is unknown and the
    /// safe reaction differs from a device that answered with a refusal.
    pub fn is_link_failure(self) -> bool {
        matches!(self, ErrorKind::Timeout | ErrorKind::Disconnected)
    }

    /// True when retrying on a later cycle may succeed without any other action.
    pub fn is_transient(self) -> bool {
        matches!(self, ErrorKind::WouldBlock)
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            ErrorKind::Timeout => "timeout",
            ErrorKind::Disconnected => "disconnected",
            ErrorKind::DeviceFault => "device fault",
            ErrorKind::LimitReached => "limit reached",
            ErrorKind::InvalidArgument => "invalid argument",
            ErrorKind::NotReady => "not ready",
            ErrorKind::WouldBlock => "would block",
            ErrorKind::Unsupported => "unsupported",
            ErrorKind::Other => "other error",
        };
        f.write_str(s)
    }
}

impl std::error::Error for ErrorKind {}

/// A backend error that can say which [`ErrorKind`] it is.
///
/// Implemented by every backend's error enum, and by [`ErrorKind`] itself so that adapters
/// that erase the backend (e.g. to put different backends behind one trait object) can use
/// the kind as their error type.
pub trait Error: std::error::Error + Send + Sync + 'static {
    /// The generic kind of this error.
    fn kind(&self) -> ErrorKind;
}

impl Error for ErrorKind {
    fn kind(&self) -> ErrorKind {
        *self
    }
}

/// Declares the error type of a device; shared by all capability traits so that one device
/// implementing several capabilities has one error type (`embedded-hal`'s `ErrorType`).
pub trait ErrorType {
    /// The backend's error type.
    type Error: Error;
}

impl<T: ErrorType + ?Sized> ErrorType for &mut T {
    type Error = T::Error;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_failures_are_distinct_from_device_refusals() {
        assert!(ErrorKind::Timeout.is_link_failure());
        assert!(ErrorKind::Disconnected.is_link_failure());
        for k in [
            ErrorKind::DeviceFault,
            ErrorKind::LimitReached,
            ErrorKind::InvalidArgument,
            ErrorKind::NotReady,
            ErrorKind::WouldBlock,
            ErrorKind::Unsupported,
            ErrorKind::Other,
        ] {
            assert!(!k.is_link_failure(), "{k} is not a link failure");
        }
    }

    #[test]
    fn only_would_block_is_transient() {
        assert!(ErrorKind::WouldBlock.is_transient());
        assert!(!ErrorKind::Timeout.is_transient());
        assert!(!ErrorKind::DeviceFault.is_transient());
    }

    #[test]
    fn error_kind_is_its_own_error() {
        let e: &dyn Error = &ErrorKind::LimitReached;
        assert_eq!(e.kind(), ErrorKind::LimitReached);
        assert_eq!(e.to_string(), "limit reached");
    }
}
