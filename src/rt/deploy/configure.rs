//! [`Configure`]: what a task's `configure` hook uses to declare its ports, events, subscriptions
//! and peers. Why it never fails: every problem goes into the registry and a detached handle comes
//! back, so configuration goes on and the topology check lists all errors at once.

use super::registry::{BufferEntry, BufferPorts, Registry};
use super::TopologyErrorKind;
use crate::rt::buffer::{unsized_buffer, BufferReader, BufferWriter, FullPolicy};
use crate::rt::command::{CommandSender, Commands};
use crate::rt::data_object::{DataObject, DataReader, DataWriter};
use crate::rt::event::{Event, EventReceiver, EventSource};
use crate::rt::interface::{
    EventDescriptor, PortDescriptor, PortDirection, PortKind, TaskInterface,
};
use crate::rt::runner::TaskInfo;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// What a task's `configure` hook uses to create its ports, events, subscriptions and peer
/// links. Every problem is recorded for the topology check; the methods still return usable
/// (detached) handles so configuration goes on and all errors are listed at once.
pub struct Configure<'a> {
    pub(super) task: &'a str,
    pub(super) reg: &'a mut Registry,
    pub(super) iface: &'a mut TaskInterface,
    pub(super) wake: Arc<AtomicBool>,
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
