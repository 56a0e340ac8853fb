//! A task's interface as data: operations, events and ports.
//!
//! Why: the control socket lists tasks and calls their operations by name, and a later issue
//! exports tasks over the network. Both need the interface without knowing the task's Rust
//! types, so it is plain, serialisable data collected when the task is added (operations) and
//! configured (ports, events).

use super::command::OperationDescriptor;

/// Direction of a data port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum PortDirection {
    /// The task reads the data object.
    Input,
    /// The task writes the data object (its single writer).
    Output,
}

/// What a port connects to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum PortKind {
    /// A data object: the latest value.
    Data,
    /// A buffer: every item, in order (an input consumes, an output produces).
    Buffer,
}

/// A port of a task: which data object or buffer it reads or writes.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct PortDescriptor {
    /// Name of the data object (global, e.g. `axis.x.position_mm`).
    pub object: String,
    /// Read or written.
    pub direction: PortDirection,
    /// Data object or buffer.
    pub kind: PortKind,
    /// Rust type name of the value (informative).
    pub type_name: &'static str,
}

/// An event a task emits or subscribes to.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct EventDescriptor {
    /// Event name (`task.event`).
    pub name: String,
    /// Rust type name of the payload (informative).
    pub type_name: &'static str,
}

/// Everything a task offers and uses, as data.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize)]
pub struct TaskInterface {
    /// Task name.
    pub name: String,
    /// Operations callable by command.
    pub operations: Vec<OperationDescriptor>,
    /// Events it emits.
    pub emits: Vec<EventDescriptor>,
    /// Events it subscribes to (deferred).
    pub subscribes: Vec<EventDescriptor>,
    /// Data ports.
    pub ports: Vec<PortDescriptor>,
    /// Peers it knows by name.
    pub peers: Vec<String>,
}
