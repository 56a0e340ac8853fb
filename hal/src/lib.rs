//! hytask-hal: the hardware abstraction layer of hytask.
//!
//! Small fallible traits, one per capability, in the style of `embedded-hal`:
//!
//! | trait | capability |
//! | --- | --- |
//! | [`AxisDrive`] | power stage state machine (CiA 402-like) and cyclic synchronous position targets |
//! | [`AxisFeedback`] | actual position / velocity, drive state, fault code, drive switches |
//! | [`Homing`] | drive-side homing (search a switch, latch, set the position) |
//! | [`DigitalInputs`], [`DigitalOutputs`] | indexed digital I/O |
//! | [`AnalogInputs`], [`AnalogOutputs`] | indexed analog I/O |
//! | [`CanBus`] | non-blocking CAN frame send/receive (the bus owner; CANopen nodes sit above it) |
//!
//! Every trait is fallible. Each backend has its own `thiserror` error enum that maps to the
//! shared [`ErrorKind`] vocabulary through [`Error::kind`], so generic code (the monitor that
//! decides between ignoring, stopping a task or an e-stop) can react without knowing the
//! backend, while logs keep the backend's own detail. [`ErrorKind::is_link_failure`] keeps
//! "the link failed" apart from "the device refused".
//!
//! The realtime-facing methods are non-blocking and bounded: they are called every servo
//! cycle from a `SCHED_FIFO` thread, so an implementation must not allocate, block on I/O or
//! hold a lock across I/O inside them.
//!
//! Backends: [`sim`] (simulated axis with a motor model, simulated I/O, in-memory CAN bus)
//! now; CANopen CiA 402 over SocketCAN and Modbus come later and implement the same traits.
//! This crate depends on nothing of the daemon.

pub mod axis;
pub mod can;
pub mod erased;
pub mod error;
pub mod io;
pub mod sim;

pub use axis::{
    Axis, AxisDrive, AxisFeedback, AxisStatus, AxisSwitches, DriveState, FaultCode, Homing,
    HomingFailure, HomingMethod, HomingParams, HomingStatus,
};
pub use can::{CanBus, CanFrame, CanId, FrameError};
pub use erased::{dyn_axis, DynAxis, Erased, HalError};
pub use error::{Error, ErrorKind, ErrorType};
pub use io::{AnalogInputs, AnalogOutputs, DigitalInputs, DigitalOutputs};
