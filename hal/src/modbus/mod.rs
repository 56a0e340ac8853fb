//! Modbus I/O (TCP and RTU): the sans-IO parts and the realtime-facing device.
//!
//! - [`map`]: where a channel lives (table, address, type, word order) and its encoding;
//! - [`plan`]: merging points into as few read requests as the protocol allows;
//! - [`image`]: the lock-free I/O image between a link's poller and the servo thread;
//! - [`device`]: [`ModbusIo`], the I/O traits over the image;
//! - [`fault`]: fault kinds (timeout, exception, dropped link) and reconnect backoff;
//! - [`server`]: a server's request handling and TCP/RTU framing (the simulator's core,
//!   also usable to check a client byte by byte).
//!
//! The poller that talks to the network is async (`tokio-modbus`) and lives in the daemon
//! crate: this crate stays synchronous and free of a runtime.

pub mod device;
pub mod fault;
pub mod image;
pub mod map;
pub mod plan;
pub mod server;

pub use device::{ModbusIo, ModbusIoError};
pub use fault::{exception_name, Backoff, FaultKind};
pub use image::{Image, InputCell, OutputCell, Quality, Sample};
pub use map::{DataType, MapError, PointSpec, Table, WordOrder};
pub use plan::{plan_reads, ReadBlock};
