//! Simulated backends: an axis with a motor model, digital/analog I/O and an in-memory CAN
//! bus. They implement the same traits as the real backends, are chosen by configuration
//! (`backend = "sim"`), and run the whole daemon without hardware: in tests, on a developer
//! machine, and as the built-in default machine.
//!
//! They are written to the same realtime rules as real backends: nothing allocates or blocks
//! per cycle, and the handles that tests or the control socket use from other threads to
//! set inputs or inject faults are lock-free (atomics), so they never stall the servo
//! thread.

pub mod axis;
pub mod can;
pub mod io;

pub use axis::{FaultInjection, SimAxis, SimAxisConfig, SimAxisError, SimAxisHandle, SwitchRange};
pub use can::{SimCanBus, SimCanError, SimCanPort};
pub use io::{SimIo, SimIoError, SimIoHandle};
