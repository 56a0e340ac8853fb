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

use super::activity::{
    Overrun, OverrunPolicy, PeriodicActivity, SimPace, SteppedActivity, TaskGroup, ThreadInfo,
    ThreadSpec,
};
use super::buffer::{unsized_buffer, BufferReader, BufferWriter, FullPolicy};
use super::clock::SimClock;
use super::command::{command_queue, CommandHandle, CommandSender, Commands, SendError};
use super::data_object::{DataObject, DataObjectError, DataReader, DataWriter};
use super::event::{Event, EventCounter, EventReceiver, EventSource};
use super::interface::{EventDescriptor, PortDescriptor, PortDirection, PortKind, TaskInterface};
use super::json::{JsonEventReceiver, JsonPortReader};
use super::runner::{Runnable, TaskInfo, TaskRunner, TaskShared};
use super::stats::TimingStats;
use super::system;
use super::task::{StateCell, Task, TaskError, TaskState};
use std::any::Any;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

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
}

/// Result of the topology check that did not prevent starting.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CheckReport {
    /// Warnings (a slower thread with a higher priority than a faster one, a buffer that no
    /// task consumes).
    pub warnings: Vec<String>,
}

struct ObjectEntry {
    handle: Box<dyn Any + Send + Sync>,
    type_name: &'static str,
    writers: Vec<String>,
    readers: Vec<String>,
}

/// A buffer's handles as kept by the registry: a producer handle to clone for each producer,
/// and the consumer handle until its consumer takes it.
struct BufferPorts<T> {
    writer: BufferWriter<T>,
    reader: Option<BufferReader<T>>,
}

struct BufferEntry {
    /// A `BufferPorts<T>`.
    handle: Box<dyn Any + Send + Sync>,
    type_name: &'static str,
    /// Capacity and policy as first declared, and the producer that declared them.
    declared: Option<(usize, FullPolicy, String)>,
    producers: Vec<String>,
    consumers: Vec<String>,
}

struct EventEntry {
    handle: Box<dyn Any + Send + Sync>,
    /// The same event, type-erased (scripts look events up by name only).
    counter: super::event::EventCounter,
    type_name: &'static str,
    emitters: Vec<String>,
    subscribers: Vec<String>,
}

/// One named connection (data object, buffer or event) as the topology check sees it: the
/// tasks on its source side and on its sink side.
struct Connection<'a> {
    port: &'a str,
    sources: &'a [String],
    sinks: &'a [String],
}

impl Connection<'_> {
    /// Every sink is an error when nothing feeds it (`unfed`); every task of the side that
    /// must be `single` past the first is an error too (`several`, with the whole list).
    fn errors(
        &self,
        errors: &mut Vec<TopologyError>,
        unfed: TopologyErrorKind,
        single: &[String],
        several: fn(Vec<String>) -> TopologyErrorKind,
    ) {
        let error = |task: &String, kind: TopologyErrorKind| TopologyError {
            task: task.clone(),
            port: self.port.to_owned(),
            kind,
        };
        if self.sources.is_empty() {
            errors.extend(self.sinks.iter().map(|t| error(t, unfed.clone())));
        }
        if let Some(rest) = single.get(1..) {
            errors.extend(rest.iter().map(|t| error(t, several(single.to_vec()))));
        }
    }
}

/// Names of everything connected, shared by configuration and (read-only) by the runtime.
#[derive(Default)]
pub(crate) struct Registry {
    objects: BTreeMap<String, ObjectEntry>,
    buffers: BTreeMap<String, BufferEntry>,
    events: BTreeMap<String, EventEntry>,
    tasks: BTreeMap<String, (TaskInfo, Box<dyn Any + Send + Sync>)>,
    errors: Vec<TopologyError>,
}

impl Registry {
    fn object<T: Clone + Default + Send + Sync + 'static>(
        &mut self,
        name: &str,
    ) -> Result<DataObject<T>, &'static str> {
        let e = self
            .objects
            .entry(name.to_owned())
            .or_insert_with(|| ObjectEntry {
                handle: Box::new(DataObject::<T>::new(name, READERS_PER_OBJECT)),
                type_name: std::any::type_name::<T>(),
                writers: Vec::new(),
                readers: Vec::new(),
            });
        e.handle
            .downcast_ref::<DataObject<T>>()
            .cloned()
            .ok_or(e.type_name)
    }

    /// The entry of buffer `name`, created (unsized, typed `T`) on first mention. Its handle
    /// may hold another type: the callers check.
    fn buffer_entry<T: Send + 'static>(&mut self, name: &str) -> &mut BufferEntry {
        self.buffers.entry(name.to_owned()).or_insert_with(|| {
            let (writer, reader) = unsized_buffer::<T>();
            BufferEntry {
                handle: Box::new(BufferPorts {
                    writer,
                    reader: Some(reader),
                }),
                type_name: std::any::type_name::<T>(),
                declared: None,
                producers: Vec::new(),
                consumers: Vec::new(),
            }
        })
    }

    fn event<T: Clone + Send + 'static>(&mut self, name: &str) -> Result<Event<T>, &'static str> {
        let e = self.events.entry(name.to_owned()).or_insert_with(|| {
            let ev = Event::<T>::new(name);
            EventEntry {
                counter: ev.counter(),
                handle: Box::new(ev),
                type_name: std::any::type_name::<T>(),
                emitters: Vec::new(),
                subscribers: Vec::new(),
            }
        });
        e.handle
            .downcast_ref::<Event<T>>()
            .cloned()
            .ok_or(e.type_name)
    }

    fn mismatch<T>(&mut self, task: &str, port: &str, existing: &'static str) {
        self.errors.push(TopologyError {
            task: task.to_owned(),
            port: port.to_owned(),
            kind: TopologyErrorKind::TypeMismatch {
                existing,
                requested: std::any::type_name::<T>(),
            },
        });
    }

    fn error(&mut self, task: &str, port: &str, kind: TopologyErrorKind) {
        self.errors.push(TopologyError {
            task: task.to_owned(),
            port: port.to_owned(),
            kind,
        });
    }

    /// The whole-topology checks that need every task configured.
    fn check(&self) -> Vec<TopologyError> {
        use TopologyErrorKind as K;
        let mut errors = self.errors.clone();
        for (name, o) in &self.objects {
            let c = Connection {
                port: name,
                sources: &o.writers,
                sinks: &o.readers,
            };
            c.errors(
                &mut errors,
                K::InputWithoutWriter,
                &o.writers,
                K::MultipleWriters,
            );
        }
        for (name, b) in &self.buffers {
            let c = Connection {
                port: name,
                sources: &b.producers,
                sinks: &b.consumers,
            };
            // Many producers may feed a buffer; it has one consumer.
            c.errors(
                &mut errors,
                K::BufferWithoutProducer,
                &b.consumers,
                K::MultipleConsumers,
            );
        }
        for (name, e) in &self.events {
            let c = Connection {
                port: name,
                sources: &e.emitters,
                sinks: &e.subscribers,
            };
            c.errors(
                &mut errors,
                K::EventWithoutEmitter,
                &e.emitters,
                K::MultipleEmitters,
            );
        }
        errors
    }

    /// Warnings of the whole topology: buffers produced into but consumed by no task.
    ///
    /// Why a warning and not an error: nothing breaks (pushes never block; once the buffer
    /// is full items are dropped and counted), and a machine builder may deploy an optional
    /// consumer (a trace or logging task) only in some configurations. A misspelt buffer name
    /// on the consumer side is still an error: that consumer has no producer.
    fn warnings(&self) -> Vec<String> {
        self.buffers
            .iter()
            .filter(|(_, b)| b.consumers.is_empty() && !b.producers.is_empty())
            .map(|(name, b)| {
                let producers: Vec<String> = b.producers.iter().map(|p| format!("'{p}'")).collect();
                format!(
                    "buffer '{name}' (output of task {}) has no consumer: once full, every \
                     push is dropped",
                    producers.join(", ")
                )
            })
            .collect()
    }

    fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        let obj = self
            .objects
            .get(name)
            .and_then(|o| o.handle.downcast_ref::<DataObject<T>>())
            .ok_or_else(|| DeployError::NotFound {
                kind: "data object",
                name: name.to_owned(),
                type_name: std::any::type_name::<T>(),
            })?;
        Ok(obj.reader()?)
    }

    /// Event `name` as an emission counter, whatever its data type.
    fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.events
            .get(name)
            .map(|e| e.counter.clone())
            .ok_or_else(|| DeployError::NotFound {
                kind: "event",
                name: name.to_owned(),
                type_name: "any",
            })
    }

    /// A JSON reader of data object `name` (its type registered in [`super::json`]).
    fn json_reader(&self, name: &str) -> Result<Box<dyn JsonPortReader>, DeployError> {
        let o = self
            .objects
            .get(name)
            .ok_or_else(|| DeployError::NotFound {
                kind: "data object",
                name: name.to_owned(),
                type_name: "any",
            })?;
        super::json::port_reader(o.handle.as_ref()).ok_or_else(|| DeployError::NotExportable {
            name: name.to_owned(),
            type_name: o.type_name,
        })
    }

    /// A JSON subscription to event `name` (its payload type registered in [`super::json`]).
    fn json_events(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn JsonEventReceiver>, DeployError> {
        let e = self.events.get(name).ok_or_else(|| DeployError::NotFound {
            kind: "event",
            name: name.to_owned(),
            type_name: "any",
        })?;
        super::json::event_receiver(e.handle.as_ref(), capacity).ok_or_else(|| {
            DeployError::NotExportable {
                name: name.to_owned(),
                type_name: e.type_name,
            }
        })
    }

    fn find_event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.events
            .get(name)
            .and_then(|e| e.handle.downcast_ref::<Event<T>>())
            .cloned()
            .ok_or_else(|| DeployError::NotFound {
                kind: "event",
                name: name.to_owned(),
                type_name: std::any::type_name::<T>(),
            })
    }
}

/// What a task's `configure` hook uses to create its ports, events, subscriptions and peer
/// links. Every problem is recorded for the topology check; the methods still return usable
/// (detached) handles so configuration goes on and all errors are listed at once.
pub struct Configure<'a> {
    task: &'a str,
    reg: &'a mut Registry,
    iface: &'a mut TaskInterface,
    wake: Arc<AtomicBool>,
}

impl Configure<'_> {
    /// Name of the task being configured.
    pub fn task_name(&self) -> &str {
        self.task
    }

    /// Declares an output port: this task becomes the writer of data object `object`.
    pub fn output<T: Clone + Default + Send + Sync + 'static>(
        &mut self,
        object: &str,
    ) -> DataWriter<T> {
        self.declare_port::<T>(object, PortDirection::Output, PortKind::Data);
        match self.reg.object::<T>(object) {
            Ok(obj) => {
                if let Some(e) = self.reg.objects.get_mut(object) {
                    e.writers.push(self.task.to_owned());
                }
                obj.writer().unwrap_or_else(|_| detached_writer(object))
            }
            Err(existing) => {
                self.reg.mismatch::<T>(self.task, object, existing);
                detached_writer(object)
            }
        }
    }

    /// Declares an input port reading data object `object`.
    pub fn input<T: Clone + Default + Send + Sync + 'static>(
        &mut self,
        object: &str,
    ) -> DataReader<T> {
        self.declare_port::<T>(object, PortDirection::Input, PortKind::Data);
        match self.reg.object::<T>(object) {
            Ok(obj) => {
                if let Some(e) = self.reg.objects.get_mut(object) {
                    e.readers.push(self.task.to_owned());
                }
                obj.reader().unwrap_or_else(|_| {
                    self.reg
                        .error(self.task, object, TopologyErrorKind::TooManyReaders);
                    detached_reader(object)
                })
            }
            Err(existing) => {
                self.reg.mismatch::<T>(self.task, object, existing);
                detached_reader(object)
            }
        }
    }

    /// Records a port in the task's interface (what `hytask tasks` and peers see).
    fn declare_port<T>(&mut self, object: &str, direction: PortDirection, kind: PortKind) {
        self.iface.ports.push(PortDescriptor {
            object: object.to_owned(),
            direction,
            kind,
            type_name: std::any::type_name::<T>(),
        });
    }

    /// Declares a buffer output port: this task produces into buffer `name` (several tasks
    /// may), declaring its capacity (at least, rounded up to a power of two) and full policy.
    /// Every producer must declare the same capacity and policy (a topology error otherwise).
    /// A buffer without consumer is a warning of the check, not an error. The port appears in
    /// the task interface as a [`PortKind::Buffer`] output named after the buffer.
    pub fn buffer_out<T: Send + 'static>(
        &mut self,
        name: &str,
        capacity: usize,
        policy: FullPolicy,
    ) -> BufferWriter<T> {
        self.declare_port::<T>(name, PortDirection::Output, PortKind::Buffer);
        let task = self.task;
        let BufferEntry {
            handle,
            type_name,
            declared,
            producers,
            ..
        } = self.reg.buffer_entry::<T>(name);
        let Some(ports) = handle.downcast_mut::<BufferPorts<T>>() else {
            let existing = *type_name;
            self.reg.mismatch::<T>(task, name, existing);
            return unsized_buffer().0;
        };
        producers.push(task.to_owned());
        let writer = ports.writer.clone();
        let conflict = match declared {
            None => {
                writer.size(capacity, policy);
                *declared = Some((capacity, policy, task.to_owned()));
                None
            }
            Some((cap0, policy0, by)) if (*cap0, *policy0) != (capacity, policy) => {
                Some(TopologyErrorKind::BufferConflict {
                    existing: (*cap0, *policy0),
                    declared_by: by.clone(),
                    requested: (capacity, policy),
                })
            }
            Some(_) => None,
        };
        if let Some(kind) = conflict {
            self.reg.error(task, name, kind);
        }
        writer
    }

    /// Declares a buffer input port: this task is the single consumer of buffer `name`, whose
    /// capacity and policy its producers declare. A buffer without producer, or with a second
    /// consumer, is a topology error. The port appears in the task interface as an
    /// [`PortKind::Buffer`] input named after the buffer.
    pub fn buffer_in<T: Send + 'static>(&mut self, name: &str) -> BufferReader<T> {
        self.declare_port::<T>(name, PortDirection::Input, PortKind::Buffer);
        let task = self.task;
        let BufferEntry {
            handle,
            type_name,
            consumers,
            ..
        } = self.reg.buffer_entry::<T>(name);
        let Some(ports) = handle.downcast_mut::<BufferPorts<T>>() else {
            let existing = *type_name;
            self.reg.mismatch::<T>(task, name, existing);
            return unsized_buffer().1;
        };
        consumers.push(task.to_owned());
        // A second consumer gets a detached reader; the check reports it with every consumer.
        ports.reader.take().unwrap_or_else(|| unsized_buffer().1)
    }

    /// Declares an event this task emits, named `<task>.<name>`.
    pub fn event<T: Clone + Send + 'static>(&mut self, name: &str) -> EventSource<T> {
        let full = format!("{}.{name}", self.task);
        self.iface.emits.push(EventDescriptor {
            name: full.clone(),
            type_name: std::any::type_name::<T>(),
        });
        match self.reg.event::<T>(&full) {
            Ok(ev) => {
                if let Some(e) = self.reg.events.get_mut(&full) {
                    e.emitters.push(self.task.to_owned());
                }
                ev.source().unwrap_or_else(|_| detached_source(&full))
            }
            Err(existing) => {
                self.reg.mismatch::<T>(self.task, &full, existing);
                detached_source(&full)
            }
        }
    }

    /// Subscribes (deferred) to event `event` (full name): events are queued for this task,
    /// which handles them in `process_events`. A non-periodic task is woken by them.
    pub fn subscribe<T: Clone + Send + 'static>(
        &mut self,
        event: &str,
        capacity: usize,
    ) -> EventReceiver<T> {
        self.iface.subscribes.push(EventDescriptor {
            name: event.to_owned(),
            type_name: std::any::type_name::<T>(),
        });
        match self.reg.event::<T>(event) {
            Ok(ev) => {
                if let Some(e) = self.reg.events.get_mut(event) {
                    e.subscribers.push(self.task.to_owned());
                }
                ev.subscribe_waking(capacity, Some(self.wake.clone()))
            }
            Err(existing) => {
                self.reg.mismatch::<T>(self.task, event, existing);
                Event::<T>::new(event).subscribe(capacity)
            }
        }
    }

    /// Adds an immediate handler to event `event`: it runs in the emitter's thread.
    pub fn subscribe_immediate<T: Clone + Send + 'static>(
        &mut self,
        event: &str,
        handler: impl FnMut(&T) + Send + 'static,
    ) {
        match self.reg.event::<T>(event) {
            Ok(ev) => {
                if let Some(e) = self.reg.events.get_mut(event) {
                    e.subscribers.push(self.task.to_owned());
                }
                ev.subscribe_immediate(handler);
            }
            Err(existing) => self.reg.mismatch::<T>(self.task, event, existing),
        }
    }

    /// Looks up a peer task by name (recorded as a peer; an unknown name is a topology error).
    pub fn peer(&mut self, name: &str) -> Option<TaskInfo> {
        self.iface.peers.push(name.to_owned());
        let found = self.reg.tasks.get(name).map(|(i, _)| i.clone());
        if found.is_none() {
            self.reg
                .error(self.task, name, TopologyErrorKind::UnknownTask);
        }
        found
    }

    /// A typed command sender to peer `name`, whose command type must be `C`.
    pub fn peer_commands<C: Commands>(&mut self, name: &str) -> Option<CommandSender<C>> {
        self.peer(name)?;
        let sender = self
            .reg
            .tasks
            .get(name)
            .and_then(|(_, s)| s.downcast_ref::<CommandSender<C>>())
            .cloned();
        if sender.is_none() {
            self.reg
                .mismatch::<C>(self.task, name, "another command type");
        }
        sender
    }

    /// Declares that this task calls `operation` on peer `peer`; recorded as an error if the
    /// peer or the operation does not exist. Returns the peer for dynamic calls.
    pub fn require_operation(&mut self, peer: &str, operation: &str) -> Option<TaskInfo> {
        let info = self.peer(peer)?;
        if !info
            .interface()
            .operations
            .iter()
            .any(|o| o.name == operation)
        {
            self.reg.error(
                self.task,
                &format!("{peer}.{operation}"),
                TopologyErrorKind::UnknownOperation,
            );
            return None;
        }
        Some(info)
    }
}

fn detached_writer<T: Clone + Default + Send>(object: &str) -> DataWriter<T> {
    // A fresh object always has its writer free.
    match DataObject::<T>::new(object, 1).writer() {
        Ok(w) => w,
        Err(_) => unreachable!("fresh data object has a writer"),
    }
}

fn detached_reader<T: Clone + Default + Send>(object: &str) -> DataReader<T> {
    match DataObject::<T>::new(object, 1).reader() {
        Ok(r) => r,
        Err(_) => unreachable!("fresh data object has a reader slot"),
    }
}

fn detached_source<T: Clone + Send + 'static>(name: &str) -> EventSource<T> {
    match Event::<T>::new(name).source() {
        Ok(s) => s,
        Err(_) => unreachable!("fresh event has its source"),
    }
}

/// Scheduling of a periodic task; tasks with equal `(priority, period_ns)` share a thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Schedule {
    /// `SCHED_FIFO` priority (1..=99).
    pub priority: i32,
    /// Period in nanoseconds.
    pub period_ns: u64,
    /// CPU to pin the thread to (the first task of a thread decides).
    pub cpu: Option<usize>,
}

/// A task added to a deployment, with its typed command sender.
pub struct TaskHandle<C> {
    info: TaskInfo,
    sender: CommandSender<C>,
}

impl<C> Clone for TaskHandle<C> {
    fn clone(&self) -> Self {
        Self {
            info: self.info.clone(),
            sender: self.sender.clone(),
        }
    }
}

impl<C: Commands> TaskHandle<C> {
    /// State, statistics, interface.
    pub fn info(&self) -> &TaskInfo {
        &self.info
    }
    /// The typed sender.
    pub fn sender(&self) -> &CommandSender<C> {
        &self.sender
    }
    /// Sends a typed command.
    pub fn send(&self, command: C) -> Result<CommandHandle, SendError> {
        self.sender.send(command)
    }
}

type RunnerAndHandle<C> = (Box<dyn Runnable>, TaskHandle<C>);

/// The configuration flow of an application.
pub struct Deployment {
    reg: Registry,
    groups: Vec<TaskGroup>,
    tasks: Vec<TaskInfo>,
    configured: bool,
    policy: OverrunPolicy,
}

impl Default for Deployment {
    fn default() -> Self {
        Self::new()
    }
}

impl Deployment {
    /// An empty deployment with the default overrun policy.
    pub fn new() -> Self {
        Self {
            reg: Registry::default(),
            groups: Vec::new(),
            tasks: Vec::new(),
            configured: false,
            policy: OverrunPolicy::default(),
        }
    }

    /// Sets the overrun policy of threads created from now on.
    pub fn set_overrun_policy(&mut self, policy: OverrunPolicy) {
        self.policy = policy;
    }

    fn group_for(&mut self, s: Schedule) -> usize {
        if let Some(i) = self.groups.iter().position(|g| {
            g.info.spec.priority == s.priority && g.info.spec.period_ns == s.period_ns
        }) {
            return i;
        }
        let spec = ThreadSpec {
            name: format!("rt-p{}-{}us", s.priority, s.period_ns / 1000),
            priority: s.priority,
            period_ns: s.period_ns,
            cpu: s.cpu,
        };
        let mut group = TaskGroup::new(spec.clone(), TimingStats::new(1_000, 10_000), self.policy);
        let name = format!("{}.overrun", spec.name);
        if let Ok(ev) = self.reg.event::<Overrun>(&name) {
            if let Some(e) = self.reg.events.get_mut(&name) {
                e.emitters.push(spec.name.clone());
            }
            if let Ok(src) = ev.source() {
                group.set_overrun_event(src);
            }
        }
        self.groups.push(group);
        self.groups.len() - 1
    }

    fn make_runner<Tk: Task>(
        &mut self,
        name: &str,
        task: Tk,
        periodic: bool,
        thread: &str,
    ) -> Result<RunnerAndHandle<Tk::Command>, DeployError> {
        if self.reg.tasks.contains_key(name) {
            return Err(DeployError::DuplicateTask(name.to_owned()));
        }
        let state = Arc::new(StateCell::new(TaskState::Unconfigured));
        let (sender, rx) =
            command_queue::<Tk::Command>(name, COMMAND_QUEUE_CAPACITY, state.clone());
        let iface = TaskInterface {
            name: name.to_owned(),
            operations: Tk::Command::operations().to_vec(),
            ..TaskInterface::default()
        };
        let shared = Arc::new(TaskShared::new(
            name,
            state,
            iface,
            Arc::new(sender.clone()),
            periodic,
            thread,
        ));
        let info = TaskInfo {
            shared: shared.clone(),
        };
        self.reg
            .tasks
            .insert(name.to_owned(), (info.clone(), Box::new(sender.clone())));
        self.tasks.push(info.clone());
        Ok((
            Box::new(TaskRunner::new(task, shared, rx)),
            TaskHandle { info, sender },
        ))
    }

    /// Adds a periodic task. Tasks with the same `(priority, period)` share one thread and
    /// run in the order they were added (= started).
    pub fn add_periodic<Tk: Task>(
        &mut self,
        name: &str,
        task: Tk,
        schedule: Schedule,
    ) -> Result<TaskHandle<Tk::Command>, DeployError> {
        let g = self.group_for(schedule);
        let thread = self.groups[g].info.spec.name.clone();
        let (runner, handle) = self.make_runner(name, task, true, &thread)?;
        self.groups[g].periodic.push(runner);
        self.configured = false;
        Ok(handle)
    }

    /// Adds a non-periodic task: it runs on the (first) periodic thread of `priority`, after
    /// that thread's periodic tasks, in cycles where it has work (commands, events) and time
    /// is left, so it never delays the periodic work.
    pub fn add_non_periodic<Tk: Task>(
        &mut self,
        name: &str,
        task: Tk,
        priority: i32,
    ) -> Result<TaskHandle<Tk::Command>, DeployError> {
        let g = self
            .groups
            .iter()
            .position(|g| g.info.spec.priority == priority)
            .ok_or_else(|| DeployError::NoThreadForPriority {
                task: name.to_owned(),
                priority,
            })?;
        let thread = self.groups[g].info.spec.name.clone();
        let (runner, handle) = self.make_runner(name, task, false, &thread)?;
        self.groups[g].non_periodic.push(runner);
        self.configured = false;
        Ok(handle)
    }

    /// Runs every task's `configure` hook (in the order added), then checks the topology.
    /// Refuses with every error found; on success returns the warnings.
    pub fn configure(&mut self) -> Result<CheckReport, DeployError> {
        self.reg.errors.clear();
        for g in &mut self.groups {
            for r in g.periodic.iter_mut().chain(g.non_periodic.iter_mut()) {
                let shared = r.shared().clone();
                if shared.state.get() != TaskState::Unconfigured {
                    continue;
                }
                let mut iface = shared.interface_mut().clone();
                let mut ctx = Configure {
                    task: &shared.name,
                    reg: &mut self.reg,
                    iface: &mut iface,
                    wake: shared.wake.clone(),
                };
                if let Err(e) = r.configure(&mut ctx) {
                    self.reg
                        .error(&shared.name, "", TopologyErrorKind::ConfigureFailed(e));
                }
                // The interface grew during configure (ports, events, peers); publish it.
                *shared.interface_mut() = iface;
            }
        }
        let errors = self.reg.check();
        if !errors.is_empty() {
            return Err(DeployError::Topology(TopologyErrors(errors)));
        }
        let mut warnings = self.priority_warnings();
        warnings.extend(self.reg.warnings());
        let report = CheckReport { warnings };
        for w in &report.warnings {
            tracing::warn!("{w}");
        }
        self.configured = true;
        Ok(report)
    }

    fn priority_warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        for a in &self.groups {
            for b in &self.groups {
                let (sa, sb) = (&a.info.spec, &b.info.spec);
                if sa.period_ns > sb.period_ns && sa.priority > sb.priority {
                    out.push(format!(
                        "thread '{}' (period {} us) has priority {} above faster thread '{}' \
                         (period {} us, priority {}): priority should follow rate",
                        sa.name,
                        sa.period_ns / 1000,
                        sa.priority,
                        sb.name,
                        sb.period_ns / 1000,
                        sb.priority
                    ));
                }
            }
        }
        out
    }

    /// Every task, in the order added.
    pub fn tasks(&self) -> &[TaskInfo] {
        &self.tasks
    }

    /// A new reader of data object `name` (for non-realtime code).
    pub fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        self.reg.reader(name)
    }

    /// Event `name` (full name), to subscribe non-realtime consumers before start.
    pub fn event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.reg.find_event(name)
    }
    /// Event `name` as a type-erased emission counter (scripts wait for events by name).
    pub fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.reg.event_counter(name)
    }

    fn start_groups(&mut self) -> Result<(), DeployError> {
        if !self.configured {
            return Err(DeployError::NotConfigured);
        }
        for g in &mut self.groups {
            g.start_tasks()
                .map_err(|(task, error)| DeployError::StartFailed { task, error })?;
        }
        Ok(())
    }

    /// Starts every task (start hooks in start order, on this thread) and one periodic
    /// thread per (priority, period).
    pub fn start(self) -> Result<Runtime, DeployError> {
        self.start_with(None)
    }

    /// Starts every task like [`start`](Self::start), but each thread runs on a simulated
    /// clock ([`PeriodicActivity::spawn_simulated`]): one period per cycle whatever the wall
    /// clock does, no skipped cycles, no overrun accounting, no `SCHED_FIFO`. For tests of
    /// behaviour through the real daemon.
    pub fn start_simulated(self, pace: SimPace) -> Result<Runtime, DeployError> {
        self.start_with(Some(pace))
    }

    fn start_with(mut self, sim: Option<SimPace>) -> Result<Runtime, DeployError> {
        if let Err(e) = self.start_groups() {
            for g in &mut self.groups {
                g.stop_tasks();
            }
            return Err(e);
        }
        let mut activities = Vec::new();
        for g in self.groups.drain(..) {
            activities.push(match sim {
                None => PeriodicActivity::spawn(g)?,
                Some(pace) => PeriodicActivity::spawn_simulated(g, pace)?,
            });
        }
        Ok(Runtime {
            core: RuntimeCore::from(self),
            activities,
        })
    }

    /// Starts every task on a stepped runtime driven by `clock` (tests, simulation).
    pub fn start_stepped(mut self, clock: SimClock) -> Result<SteppedRuntime, DeployError> {
        self.start_groups()?;
        let activities = self
            .groups
            .drain(..)
            .map(|g| SteppedActivity::new(g, clock.clone()))
            .collect();
        Ok(SteppedRuntime {
            core: RuntimeCore::from(self),
            activities,
            clock,
        })
    }

    /// Runs every stopped task's `cleanup` hook (back to `Unconfigured`).
    pub fn cleanup(&mut self) {
        for g in &mut self.groups {
            for r in g.periodic.iter_mut().chain(g.non_periodic.iter_mut()) {
                r.cleanup();
                // What configure declared (ports, events, peers) is declared again by the
                // next configure; the operations are the task's own and stay.
                let mut iface = r.shared().interface_mut();
                iface.emits.clear();
                iface.subscribes.clear();
                iface.ports.clear();
                iface.peers.clear();
            }
        }
        // Cleanup undoes configure: the connections the tasks declared go too, and the next
        // `configure` builds them afresh (otherwise every port would be declared twice).
        // Handles taken from the deployment before (readers, events) belong to the old
        // connections: take new ones after configuring again.
        self.reg.objects.clear();
        self.reg.buffers.clear();
        self.reg.events.clear();
        self.reg.errors.clear();
        self.configured = false;
    }
}

/// Status of a runtime, as data.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RuntimeStatus {
    /// Every thread got `SCHED_FIFO` and memory is locked.
    pub realtime: bool,
    /// Per thread: spec, realtime flag, timing.
    pub threads: Vec<ThreadStatus>,
    /// Per task: name, state, timing.
    pub tasks: Vec<TaskStatus>,
}

/// Status of one thread.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ThreadStatus {
    /// Scheduling.
    pub spec: ThreadSpec,
    /// Got `SCHED_FIFO` with locked memory.
    pub realtime: bool,
    /// Timing.
    pub timing: super::stats::TimingSummary,
}

/// Status of one task.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TaskStatus {
    /// Name.
    pub name: String,
    /// State.
    pub state: TaskState,
    /// Thread running it.
    pub thread: String,
    /// Execution time of its steps.
    pub timing: super::stats::TimingSummary,
}

fn task_status(tasks: &[TaskInfo]) -> Vec<TaskStatus> {
    tasks
        .iter()
        .map(|t| TaskStatus {
            name: t.name().to_owned(),
            state: t.state(),
            thread: t.thread().to_owned(),
            timing: t.timing(),
        })
        .collect()
}

/// What both runtimes share: the registry of ports and events, the tasks and the overrun
/// policy. The runtimes differ only in how their threads are driven.
struct RuntimeCore {
    reg: Registry,
    tasks: Vec<TaskInfo>,
    policy: OverrunPolicy,
}

impl From<Deployment> for RuntimeCore {
    fn from(d: Deployment) -> Self {
        RuntimeCore {
            reg: d.reg,
            tasks: d.tasks,
            policy: d.policy,
        }
    }
}

impl RuntimeCore {
    fn task(&self, name: &str) -> Option<&TaskInfo> {
        self.tasks.iter().find(|t| t.name() == name)
    }

    /// Status as data; `simulated` threads never count as realtime.
    fn status(&self, threads: &[Arc<ThreadInfo>], simulated: bool) -> RuntimeStatus {
        let rt = |t: &ThreadInfo| !simulated && t.realtime();
        RuntimeStatus {
            realtime: threads.iter().all(|t| rt(t)),
            threads: threads
                .iter()
                .map(|t| ThreadStatus {
                    spec: t.spec.clone(),
                    realtime: rt(t),
                    timing: t.stats.summary(),
                })
                .collect(),
            tasks: task_status(&self.tasks),
        }
    }

    /// Back to a configured deployment holding the stopped `groups`.
    fn into_deployment(self, groups: Vec<TaskGroup>) -> Deployment {
        Deployment {
            reg: self.reg,
            groups,
            tasks: self.tasks,
            configured: true,
            policy: self.policy,
        }
    }
}

/// Tasks running on periodic threads.
pub struct Runtime {
    core: RuntimeCore,
    activities: Vec<PeriodicActivity>,
}

impl Runtime {
    /// Every task, in the order added.
    pub fn tasks(&self) -> &[TaskInfo] {
        &self.core.tasks
    }
    /// A task by name.
    pub fn task(&self, name: &str) -> Option<&TaskInfo> {
        self.core.task(name)
    }
    /// The threads.
    pub fn threads(&self) -> Vec<Arc<ThreadInfo>> {
        self.activities.iter().map(|a| a.info().clone()).collect()
    }
    /// True if every thread runs `SCHED_FIFO` with locked memory.
    pub fn realtime(&self) -> bool {
        self.activities.iter().all(|a| a.info().realtime())
    }
    /// Status of threads and tasks, as data.
    pub fn status(&self) -> RuntimeStatus {
        self.core.status(&self.threads(), false)
    }
    /// A new reader of data object `name`.
    pub fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        self.core.reg.reader(name)
    }
    /// A JSON reader of data object `name`, for exporters (see [`super::json`]).
    pub fn json_reader(&self, name: &str) -> Result<Box<dyn JsonPortReader>, DeployError> {
        self.core.reg.json_reader(name)
    }
    /// A JSON subscription to event `name` queueing up to `capacity` events, for exporters.
    pub fn json_events(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn JsonEventReceiver>, DeployError> {
        self.core.reg.json_events(name, capacity)
    }
    /// Event `name`: a non-realtime consumer may subscribe (its queue is picked up by the
    /// emitter at its next emit, without blocking it).
    pub fn event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.core.reg.find_event(name)
    }
    /// Event `name` as a type-erased emission counter (scripts wait for events by name).
    pub fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.core.reg.event_counter(name)
    }
    /// Stops every thread (tasks' `stop` hooks run on their threads) and returns the
    /// configured deployment, which can be started again or cleaned up.
    pub fn stop(self) -> Deployment {
        let groups = self
            .activities
            .into_iter()
            .filter_map(PeriodicActivity::stop)
            .collect();
        self.core.into_deployment(groups)
    }
}

/// Tasks stepped on the caller's thread against a simulated clock.
pub struct SteppedRuntime {
    core: RuntimeCore,
    activities: Vec<SteppedActivity>,
    clock: SimClock,
}

impl SteppedRuntime {
    /// Runs every thread's cycles due up to time `t_ns`, in deadline order (ties: higher
    /// priority first), exactly as the threads would have run them.
    pub fn run_until_ns(&mut self, t_ns: u64) {
        loop {
            let next = self
                .activities
                .iter_mut()
                .filter(|a| a.next_deadline_ns() <= t_ns)
                .min_by_key(|a| (a.next_deadline_ns(), -a.group().info().spec.priority));
            match next {
                Some(a) => a.step(),
                None => break,
            }
        }
        self.clock.set_ns(t_ns);
    }

    /// Runs `n` periods of the fastest thread (and whatever slower threads are due).
    pub fn run_cycles(&mut self, n: u64) {
        let Some(period) = self
            .activities
            .iter()
            .map(|a| a.group().info().spec.period_ns)
            .min()
        else {
            return;
        };
        let start = self
            .activities
            .iter()
            .map(SteppedActivity::next_deadline_ns)
            .min()
            .unwrap_or(0);
        self.run_until_ns(start + n * period - 1);
    }

    /// The simulated clock.
    pub fn clock(&self) -> &SimClock {
        &self.clock
    }
    /// Every task.
    pub fn tasks(&self) -> &[TaskInfo] {
        &self.core.tasks
    }
    /// A task by name.
    pub fn task(&self, name: &str) -> Option<&TaskInfo> {
        self.core.task(name)
    }
    /// The threads' information.
    pub fn threads(&self) -> Vec<Arc<ThreadInfo>> {
        self.activities
            .iter()
            .map(|a| a.group().info().clone())
            .collect()
    }
    /// Status as data (`realtime` is always false: simulated time).
    pub fn status(&self) -> RuntimeStatus {
        self.core.status(&self.threads(), true)
    }
    /// A new reader of data object `name`.
    pub fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        self.core.reg.reader(name)
    }
    /// Event `name`.
    pub fn event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.core.reg.find_event(name)
    }
    /// Event `name` as a type-erased emission counter (scripts wait for events by name).
    pub fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.core.reg.event_counter(name)
    }
    /// Stops every task and returns the deployment.
    pub fn stop(self) -> Deployment {
        let groups = self
            .activities
            .into_iter()
            .map(SteppedActivity::stop)
            .collect();
        self.core.into_deployment(groups)
    }
}

/// Whether this process can run realtime, with the warning logged once if not.
pub fn check_realtime() -> system::Capabilities {
    let caps = system::capabilities();
    if !caps.realtime {
        system::warn_not_realtime(if caps.fifo_scheduling {
            "memory not locked"
        } else {
            "no permission for SCHED_FIFO"
        });
    }
    caps
}

#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    /// Runs `f` as task `task`'s configure hook on `reg`; returns what `f` returns.
    fn configure<R>(
        reg: &mut Registry,
        iface: &mut TaskInterface,
        task: &str,
        f: impl FnOnce(&mut Configure<'_>) -> R,
    ) -> R {
        let mut ctx = Configure {
            task,
            reg,
            iface,
            wake: Arc::new(AtomicBool::new(false)),
        };
        f(&mut ctx)
    }

    #[test]
    fn a_buffer_named_first_by_its_consumer_is_sized_by_its_first_producer() {
        let mut reg = Registry::default();
        let (mut ci, mut pi) = (TaskInterface::default(), TaskInterface::default());
        let mut r = configure(&mut reg, &mut ci, "c", |c| c.buffer_in::<u32>("q"));
        assert_eq!(
            (r.capacity(), r.policy()),
            (0, None),
            "unsized until a producer"
        );
        let w = configure(&mut reg, &mut pi, "p", |c| {
            c.buffer_out::<u32>("q", 3, FullPolicy::DropOldest)
        });
        assert_eq!(
            (r.capacity(), r.policy()),
            (4, Some(FullPolicy::DropOldest))
        );
        w.push(7);
        assert_eq!(r.pop(), Some(7));
        assert_eq!(reg.check(), []);
        assert_eq!(reg.warnings(), Vec::<String>::new());
        assert_eq!(
            (ci.ports[0].direction, pi.ports[0].direction),
            (PortDirection::Input, PortDirection::Output)
        );
        assert_eq!(pi.ports[0].object, "q");
    }

    #[test]
    fn agreeing_producers_share_one_buffer_and_a_second_consumer_is_detached() {
        let mut reg = Registry::default();
        let mut iface = TaskInterface::default();
        let w1 = configure(&mut reg, &mut iface, "p1", |c| {
            c.buffer_out::<u8>("q", 8, FullPolicy::DropNewest)
        });
        let w2 = configure(&mut reg, &mut iface, "p2", |c| {
            c.buffer_out::<u8>("q", 8, FullPolicy::DropNewest)
        });
        let mut r1 = configure(&mut reg, &mut iface, "c1", |c| c.buffer_in::<u8>("q"));
        let mut r2 = configure(&mut reg, &mut iface, "c2", |c| c.buffer_in::<u8>("q"));
        w1.push(1);
        w2.push(2);
        assert_eq!((r1.pop(), r1.pop()), (Some(1), Some(2)));
        assert_eq!(r2.pop(), None, "the second consumer's reader is detached");
        let errors = reg.check();
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert_eq!(
            (errors[0].task.as_str(), errors[0].port.as_str()),
            ("c2", "q")
        );
        assert_eq!(
            errors[0].kind,
            TopologyErrorKind::MultipleConsumers(vec!["c1".into(), "c2".into()])
        );
    }

    #[test]
    fn conflicts_mismatches_and_missing_ends_are_reported() {
        let mut reg = Registry::default();
        let mut iface = TaskInterface::default();
        configure(&mut reg, &mut iface, "p1", |c| {
            c.buffer_out::<u8>("q", 8, FullPolicy::DropNewest)
        });
        let w = configure(&mut reg, &mut iface, "p2", |c| {
            c.buffer_out::<u8>("q", 8, FullPolicy::DropOldest)
        });
        // The conflicting producer still writes into the one buffer (sized as first declared).
        let mut r = configure(&mut reg, &mut iface, "c", |c| c.buffer_in::<u8>("q"));
        w.push(5);
        assert_eq!(
            (r.pop(), r.policy()),
            (Some(5), Some(FullPolicy::DropNewest))
        );
        configure(&mut reg, &mut iface, "x", |c| {
            c.buffer_out::<u16>("q", 8, FullPolicy::DropNewest)
        });
        configure(&mut reg, &mut iface, "lonely", |c| {
            c.buffer_in::<u8>("void")
        });
        configure(&mut reg, &mut iface, "tracer", |c| {
            c.buffer_out::<u8>("trace", 8, FullPolicy::DropOldest)
        });
        let errors: Vec<String> = reg.check().iter().map(ToString::to_string).collect();
        assert_eq!(
            errors,
            [
                "task 'p2' buffer output 'q': capacity 8 DropOldest but task 'p1' declared \
                 capacity 8 DropNewest",
                "task 'x' port 'q': type u16 but the object has type u8",
                "task 'lonely' buffer input 'void': no task produces into it",
            ]
        );
        assert_eq!(
            reg.warnings(),
            [
                "buffer 'trace' (output of task 'tracer') has no consumer: once full, every push \
              is dropped"
            ]
        );
    }
}
