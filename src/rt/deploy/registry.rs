//! The registry: every named data object, buffer and event with the tasks on each end, and the
//! topology check over them. Why one place: configuration, the check and the running runtime
//! (JSON export, late readers) all look connections up by name.

use super::{DeployError, TopologyError, TopologyErrorKind, READERS_PER_OBJECT};
use crate::rt::buffer::{unsized_buffer, BufferReader, BufferWriter, FullPolicy};
use crate::rt::data_object::{DataObject, DataReader};
use crate::rt::event::{Event, EventCounter};
use crate::rt::json::{JsonEventReceiver, JsonPortReader};
use crate::rt::runner::TaskInfo;
use std::any::Any;
use std::collections::BTreeMap;

pub(super) struct ObjectEntry {
    pub(super) handle: Box<dyn Any + Send + Sync>,
    pub(super) type_name: &'static str,
    pub(super) writers: Vec<String>,
    pub(super) readers: Vec<String>,
}

/// A buffer's handles as kept by the registry: a producer handle to clone for each producer,
/// and the consumer handle until its consumer takes it.
pub(super) struct BufferPorts<T> {
    pub(super) writer: BufferWriter<T>,
    pub(super) reader: Option<BufferReader<T>>,
}

/// The `TypeId` of the registry's handle of a buffer of `T` (for [`crate::rt::json`]).
pub(crate) fn buffer_ports_type<T: Send + 'static>() -> std::any::TypeId {
    std::any::TypeId::of::<BufferPorts<T>>()
}

/// Takes the consumer handle of the buffer of `T` behind `handle`, if no consumer took it.
pub(crate) fn take_buffer_reader<T: Send + 'static>(
    handle: &mut (dyn Any + Send + Sync),
) -> Option<BufferReader<T>> {
    handle.downcast_mut::<BufferPorts<T>>()?.reader.take()
}

pub(super) struct BufferEntry {
    /// A `BufferPorts<T>`.
    pub(super) handle: Box<dyn Any + Send + Sync>,
    pub(super) type_name: &'static str,
    /// Capacity and policy as first declared, and the producer that declared them.
    pub(super) declared: Option<(usize, FullPolicy, String)>,
    pub(super) producers: Vec<String>,
    pub(super) consumers: Vec<String>,
}

pub(super) struct EventEntry {
    pub(super) handle: Box<dyn Any + Send + Sync>,
    /// The same event, type-erased (scripts look events up by name only).
    pub(super) counter: crate::rt::event::EventCounter,
    pub(super) type_name: &'static str,
    pub(super) emitters: Vec<String>,
    pub(super) subscribers: Vec<String>,
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
    pub(super) objects: BTreeMap<String, ObjectEntry>,
    pub(super) buffers: BTreeMap<String, BufferEntry>,
    pub(super) events: BTreeMap<String, EventEntry>,
    pub(super) tasks: BTreeMap<String, (TaskInfo, Box<dyn Any + Send + Sync>)>,
    pub(super) errors: Vec<TopologyError>,
}

impl Registry {
    pub(super) fn object<T: Clone + Default + Send + Sync + 'static>(
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
    pub(super) fn buffer_entry<T: Send + 'static>(&mut self, name: &str) -> &mut BufferEntry {
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

    pub(super) fn event<T: Clone + Send + 'static>(
        &mut self,
        name: &str,
    ) -> Result<Event<T>, &'static str> {
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

    pub(super) fn mismatch<T>(&mut self, task: &str, port: &str, existing: &'static str) {
        self.errors.push(TopologyError {
            task: task.to_owned(),
            port: port.to_owned(),
            kind: TopologyErrorKind::TypeMismatch {
                existing,
                requested: std::any::type_name::<T>(),
            },
        });
    }

    pub(super) fn error(&mut self, task: &str, port: &str, kind: TopologyErrorKind) {
        self.errors.push(TopologyError {
            task: task.to_owned(),
            port: port.to_owned(),
            kind,
        });
    }

    /// The whole-topology checks that need every task configured.
    pub(super) fn check(&self) -> Vec<TopologyError> {
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
    pub(super) fn warnings(&self) -> Vec<String> {
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

    pub(super) fn reader<T: Clone + Default + Send + Sync + 'static>(
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
    pub(super) fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.events
            .get(name)
            .map(|e| e.counter.clone())
            .ok_or_else(|| DeployError::NotFound {
                kind: "event",
                name: name.to_owned(),
                type_name: "any",
            })
    }

    /// A JSON reader of data object `name` (its type registered in [`crate::rt::json`]).
    pub(super) fn json_reader(&self, name: &str) -> Result<Box<dyn JsonPortReader>, DeployError> {
        let o = self
            .objects
            .get(name)
            .ok_or_else(|| DeployError::NotFound {
                kind: "data object",
                name: name.to_owned(),
                type_name: "any",
            })?;
        crate::rt::json::port_reader(o.handle.as_ref()).ok_or_else(|| DeployError::NotExportable {
            name: name.to_owned(),
            type_name: o.type_name,
        })
    }

    /// Buffer `name`'s items as JSON, in order, for an exporter that becomes its consumer
    /// (its item type registered in [`crate::rt::json`]); refused when a task consumes it.
    pub(super) fn json_buffer(
        &mut self,
        name: &str,
    ) -> Result<Box<dyn JsonEventReceiver>, DeployError> {
        let b = self
            .buffers
            .get_mut(name)
            .ok_or_else(|| DeployError::NotFound {
                kind: "buffer",
                name: name.to_owned(),
                type_name: "any",
            })?;
        if let Some(task) = b.consumers.first() {
            return Err(DeployError::BufferConsumed {
                name: name.to_owned(),
                consumer: format!("task '{task}'"),
            });
        }
        let type_name = b.type_name;
        match crate::rt::json::buffer_reader(b.handle.as_mut()) {
            Some(Some(r)) => Ok(r),
            Some(None) => Err(DeployError::BufferConsumed {
                name: name.to_owned(),
                consumer: "an exporter".to_owned(),
            }),
            None => Err(DeployError::NotExportable {
                name: name.to_owned(),
                type_name,
            }),
        }
    }

    /// A JSON subscription to event `name` (its payload type registered in [`crate::rt::json`]).
    pub(super) fn json_events(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn JsonEventReceiver>, DeployError> {
        let e = self.events.get(name).ok_or_else(|| DeployError::NotFound {
            kind: "event",
            name: name.to_owned(),
            type_name: "any",
        })?;
        crate::rt::json::event_receiver(e.handle.as_ref(), capacity).ok_or_else(|| {
            DeployError::NotExportable {
                name: name.to_owned(),
                type_name: e.type_name,
            }
        })
    }

    pub(super) fn find_event<T: Clone + Send + 'static>(
        &self,
        name: &str,
    ) -> Result<Event<T>, DeployError> {
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
