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
//! now; [`canopen`] holds the sans-IO CANopen (CiA 301) master and CiA 402 layer with a
//! loopback drive, tested on the in-memory bus; [`socketcan`] is the [`CanBus`] on a Linux
//! SocketCAN socket. [`modbus`] holds the sans-IO Modbus pieces (register map,
//! read merging, server framing) and [`modbus::ModbusIo`], the I/O traits over a lock-free
//! image that the daemon's async poller (in the main crate, on `tokio-modbus`) fills.
//! Backends chosen by configuration live side by side behind [`Erased`] / [`DynAxis`],
//! which give every backend the same error type ([`HalError`]) without allocating.
//! This crate depends on nothing of the daemon.
//!
//! # How to add a backend
//!
//! 1. Give it its own module (`canopen/`, `modbus/`) and its own `thiserror` error enum;
//!    implement [`Error::kind`] for it, mapping link problems to
//!    [`ErrorKind::Timeout`]/[`ErrorKind::Disconnected`] and device refusals to the other
//!    kinds, never the other way round.
//! 2. Implement [`ErrorType`] and the capability traits the hardware has (an I/O coupler
//!    implements the I/O traits only). Keep every trait method non-blocking and bounded:
//!    slow links (Modbus TCP, SDO transfers) run on their own thread and exchange a
//!    process image with the realtime side through lock-free structures.
//! 3. Share a physical link through one owner (the bus) and hand out device handles (the
//!    `embedded-hal` `SpiBus`/`SpiDevice` split): one SocketCAN socket per interface
//!    implementing [`CanBus`], CANopen node handles routed by COB-ID above it.
//! 4. Test it against the simulator where one exists (a CANopen master against a simulated
//!    CiA 402 node on [`sim::SimCanBus`]) and check the no-allocation rule the way
//!    `tests/no_alloc.rs` does.
//! 5. Add its settings to the machine configuration (`backend = "..."` plus a sub-table)
//!    and mark it available there.

pub mod axis;
pub mod can;
pub mod canopen;
pub mod erased;
pub mod error;
pub mod io;
pub mod modbus;
pub mod sim;
#[cfg(target_os = "linux")]
pub mod socketcan;

pub use axis::{
    Axis, AxisDrive, AxisFeedback, AxisStatus, AxisSwitches, DriveState, FaultCode, Homing,
    HomingFailure, HomingMethod, HomingParams, HomingStatus,
};
pub use can::{CanBus, CanFrame, CanId, FrameError};
pub use erased::{dyn_axis, DynAxis, Erased, HalError};
pub use error::{Error, ErrorKind, ErrorType};
pub use io::{AnalogInputs, AnalogOutputs, DigitalInputs, DigitalOutputs};
