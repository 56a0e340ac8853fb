//! hytask-hal: the hardware abstraction layer of hytask.
//!
//! Small fallible traits, one per capability (axis command, axis feedback, homing, digital and
//! analog I/O, CAN bus), each with a shared [`ErrorKind`]-style vocabulary and backends that
//! implement them: simulators first, CANopen CiA 402 over SocketCAN and Modbus later.
//! This crate depends on nothing of the daemon.
