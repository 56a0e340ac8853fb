//! Deployment: the configuration flow. Add tasks to threads, configure them (ports, events,
//! peers), check the whole topology, then start them on periodic threads or on a stepped,
//! simulated-time runtime.
//!
//! Why check before starting: a miswired application must not start half-working. Every
//! problem is collected, each naming the task and the port (input connected to no writer, two
//! writers on one data object, a type mismatch, an unknown peer, an operation a peer does not
//! have, a subscription to an event nobody emits, a buffer nobody produces into, a buffer with
//! two consumers or declared with two capacities or policies), and [`Deployment::start`]
//! refuses with the whole list. Legal but suspicious layouts are warnings in the
//! [`CheckReport`]: a slower thread with a higher priority than a faster one (the paper:
//! priority follows rate), a buffer that nobody consumes.
//!
//! Data objects, buffers and events are named globally (`axis.x.position_mm`,
//! `monitor.tracking_error`); whichever task mentions a name first creates the object, so
//! configure order does not matter (a buffer first named by its consumer gets its capacity and
//! policy from its first producer: see [`super::buffer`]). Buffers and data objects have
//! separate names.

use super::buffer::FullPolicy;
use super::data_object::DataObjectError;
use super::task::TaskError;
use std::fmt;

/// Readers per data object created through a deployment.
pub const READERS_PER_OBJECT: usize = 16;
/// Queued commands per task.
pub const COMMAND_QUEUE_CAPACITY: usize = 32;

/// One problem found in the topology.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopologyError {
    /// The task concerned.
    pub task: String,
    /// The port, event, peer or operation concerned.
    pub port: String,
    /// What is wrong.
    pub kind: TopologyErrorKind,
}

/// Kinds of [`TopologyError`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TopologyErrorKind {
    /// An input reads a data object no task writes.
    InputWithoutWriter,
    /// More than one task writes the data object.
    MultipleWriters(Vec<String>),
    /// The data object or event is used with two different types.
    TypeMismatch {
        /// Type it was created with.
        existing: &'static str,
        /// Type this task asked for.
        requested: &'static str,
    },
    /// The peer task does not exist.
    UnknownTask,
    /// The peer exists but has no such operation.
    UnknownOperation,
    /// A subscription to an event no task emits.
    EventWithoutEmitter,
    /// The event already has an emitter.
    MultipleEmitters(Vec<String>),
    /// The data object has no free reader slot.
    TooManyReaders,
    /// A buffer input that no task produces into.
    BufferWithoutProducer,
    /// More than one task consumes the buffer (one consumer per buffer).
    MultipleConsumers(Vec<String>),
    /// A producer declared the buffer with another capacity or full policy than the producer
    /// that declared it first (declarations must agree exactly).
    BufferConflict {
        /// Capacity and policy as first declared.
        existing: (usize, FullPolicy),
        /// The task that declared them first.
        declared_by: String,
        /// Capacity and policy this task declared.
        requested: (usize, FullPolicy),
    },
    /// The task's `configure` hook failed.
    ConfigureFailed(TaskError),
}

impl fmt::Display for TopologyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (t, p) = (&self.task, &self.port);
        match &self.kind {
            TopologyErrorKind::InputWithoutWriter => {
                write!(f, "task '{t}' input '{p}': connected to no writer")
            }
            TopologyErrorKind::MultipleWriters(w) => {
                write!(
                    f,
                    "task '{t}' output '{p}': data object has several writers: {}",
                    w.join(", ")
                )
            }
            TopologyErrorKind::TypeMismatch {
                existing,
                requested,
            } => write!(
                f,
                "task '{t}' port '{p}': type {requested} but the object has type {existing}"
            ),
            TopologyErrorKind::UnknownTask => {
                write!(f, "task '{t}': peer '{p}' is not a known task")
            }
            TopologyErrorKind::UnknownOperation => {
                write!(f, "task '{t}': operation '{p}' not found on the peer")
            }
            TopologyErrorKind::EventWithoutEmitter => {
                write!(
                    f,
                    "task '{t}' subscribes to event '{p}' which no task emits"
                )
            }
            TopologyErrorKind::MultipleEmitters(w) => {
                write!(
                    f,
                    "task '{t}' event '{p}': several emitters: {}",
                    w.join(", ")
                )
            }
            TopologyErrorKind::TooManyReaders => {
                write!(
                    f,
                    "task '{t}' input '{p}': data object has no free reader slot"
                )
            }
            TopologyErrorKind::BufferWithoutProducer => {
                write!(f, "task '{t}' buffer input '{p}': no task produces into it")
            }
            TopologyErrorKind::MultipleConsumers(c) => {
                write!(
                    f,
                    "task '{t}' buffer input '{p}': buffer has several consumers: {}",
                    c.join(", ")
                )
            }
            TopologyErrorKind::BufferConflict {
                existing: (cap0, policy0),
                declared_by,
                requested: (cap, policy),
            } => write!(
                f,
                "task '{t}' buffer output '{p}': capacity {cap} {policy:?} but task \
                 '{declared_by}' declared capacity {cap0} {policy0:?}"
            ),
            TopologyErrorKind::ConfigureFailed(e) => write!(f, "task '{t}': configure failed: {e}"),
        }
    }
}

/// All problems of a topology, displayed one per line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopologyErrors(pub Vec<TopologyError>);

impl fmt::Display for TopologyErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{} topology error(s):", self.0.len())?;
        for e in &self.0 {
            writeln!(f, "  - {e}")?;
        }
        Ok(())
    }
}

/// Errors of the configuration flow.
#[derive(Debug, thiserror::Error)]
pub enum DeployError {
    /// Two tasks with one name.
    #[error("a task named '{0}' already exists")]
    DuplicateTask(String),
    /// A non-periodic task needs a periodic thread of its priority to run after.
    #[error("no periodic thread with priority {priority} for non-periodic task '{task}'")]
    NoThreadForPriority {
        /// Task.
        task: String,
        /// Priority asked for.
        priority: i32,
    },
    /// `start` before `configure`.
    #[error("the deployment is not configured")]
    NotConfigured,
    /// The topology check failed.
    #[error("{0}")]
    Topology(TopologyErrors),
    /// A task's `start` hook failed.
    #[error("task '{task}' failed to start: {error}")]
    StartFailed {
        /// Task.
        task: String,
        /// Its error.
        error: TaskError,
    },
    /// A thread could not be started.
    #[error(transparent)]
    Activity(#[from] super::activity::ActivityError),
    /// No data object or event of that name and type.
    #[error("no {kind} named '{name}' with type {type_name}")]
    NotFound {
        /// "data object" or "event".
        kind: &'static str,
        /// Name.
        name: String,
        /// Type asked for.
        type_name: &'static str,
    },
    /// A data object refused a handle.
    #[error(transparent)]
    DataObject(#[from] DataObjectError),
    /// A port or event whose value type was not registered for export
    /// ([`super::json::register_data`]), or a data object without a free reader slot.
    #[error("'{name}' ({type_name}) cannot be exported: type not registered for JSON, or no reader slot left")]
    NotExportable {
        /// Port or event name.
        name: String,
        /// Its value type.
        type_name: &'static str,
    },
    /// A buffer an exporter wanted whose single consumer is a task (or another exporter).
    #[error("buffer '{name}' cannot be exported: it is consumed by {consumer} (one consumer per buffer)")]
    BufferConsumed {
        /// Buffer name.
        name: String,
        /// Who consumes it.
        consumer: String,
    },
}

/// Result of the topology check that did not prevent starting.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CheckReport {
    /// Warnings (a slower thread with a higher priority than a faster one, a buffer that no
    /// task consumes).
    pub warnings: Vec<String>,
}

mod configure;
mod deployment;
mod registry;
pub(crate) use registry::{buffer_ports_type, take_buffer_reader};
mod runtime;
#[cfg(all(test, not(loom)))]
mod tests;

pub use configure::Configure;
pub use deployment::{Deployment, Schedule, TaskHandle};
pub use runtime::{
    check_realtime, Runtime, RuntimeStatus, SteppedRuntime, TaskStatus, ThreadStatus,
};
