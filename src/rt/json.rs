//! Type-erased JSON views of data objects and events, for exporters (the Zenoh bridge).
//!
//! Why: ports and events are typed (`DataObject<T>`, `Event<T>`) and the deployment keeps
//! them as `Box<dyn Any>`; a bridge that exports "every port" by name cannot name `T`. A
//! value type is made exportable once with [`register_data`] / [`register_event`] (the
//! primitives and fixed arrays of `f64` are registered already); the deployment then hands
//! out [`JsonPortReader`]s and [`JsonEventReceiver`]s by name. A buffer no task consumes
//! can be handed out too, as an ordered stream ([`register_buffer`]; the exporter becomes
//! its single consumer, draining on its own thread as any consumer does).
//!
//! Realtime side: nothing changes. A JSON reader is an ordinary [`DataReader`] (lock-free;
//! registering it takes the object's registration mutex, never touched by `set`), and a JSON
//! event receiver is an ordinary deferred subscription (picked up by the emitter with a
//! `try_lock`). Serialisation happens on the exporter's thread. The registry below is
//! consulted only when a reader is made, never in a step.

use super::buffer::BufferReader;
use super::data_object::{DataObject, DataReader, FlowStatus};
use super::deploy::{buffer_ports_type, take_buffer_reader};
use super::event::{Event, EventReceiver};
use serde::Serialize;
use serde_json::Value;
use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::marker::PhantomData;
use std::sync::{Mutex, OnceLock};

/// A value's JSON form for types that are not `Serialize` (or should export a summary):
/// register them with [`register_data_view`] / [`register_event_view`].
pub trait JsonView {
    /// The value as JSON.
    fn json(&self) -> Value;
}

/// A data-object reader that serialises.
pub trait JsonPortReader: Send {
    /// The latest value, if one was written since the last call (`None` when unchanged or
    /// never written).
    fn fresh(&mut self) -> Option<Value>;
    /// The latest value whether new or not (`None` if never written).
    fn latest(&mut self) -> Option<Value>;
}

/// A deferred event subscription that serialises.
pub trait JsonEventReceiver: Send {
    /// Hands every queued event to `f`, in order; returns how many.
    fn drain(&mut self, f: &mut dyn FnMut(Value)) -> usize;
}

type AnyRef<'a> = &'a (dyn Any + Send + Sync);
type PortFactory = fn(AnyRef<'_>) -> Option<Box<dyn JsonPortReader>>;
type EventFactory = fn(AnyRef<'_>, usize) -> Option<Box<dyn JsonEventReceiver>>;
/// `None`: not a buffer of this type; `Some(None)`: its consumer handle is taken.
type BufferFactory = fn(&mut (dyn Any + Send + Sync)) -> Option<Option<Box<dyn JsonEventReceiver>>>;

#[derive(Default)]
struct Factories {
    /// By `TypeId` of `DataObject<T>`.
    ports: HashMap<TypeId, PortFactory>,
    /// By `TypeId` of `Event<T>`.
    events: HashMap<TypeId, EventFactory>,
    /// By `TypeId` of the registry's buffer handle (`deploy::buffer_ports_type`).
    buffers: HashMap<TypeId, BufferFactory>,
}

fn factories() -> &'static Mutex<Factories> {
    static F: OnceLock<Mutex<Factories>> = OnceLock::new();
    F.get_or_init(|| {
        let mut f = Factories::default();
        macro_rules! both {
            ($($t:ty),*) => {$(
                f.ports.insert(TypeId::of::<DataObject<$t>>(), port_factory::<$t>);
                f.events.insert(TypeId::of::<Event<$t>>(), event_factory::<$t>);
                f.buffers.insert(buffer_ports_type::<$t>(), buffer_factory::<$t>);
            )*};
        }
        both!(
            bool, f32, f64, i8, i16, i32, i64, u8, u16, u32, u64, usize, isize, String, [f64; 2],
            [f64; 3], [f64; 4], [f64; 6], [f64; 9], [bool; 8], [bool; 16]
        );
        Mutex::new(f)
    })
}

fn lock() -> std::sync::MutexGuard<'static, Factories> {
    factories()
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Makes data objects of type `T` exportable as JSON.
pub fn register_data<T: Serialize + Clone + Default + Send + Sync + 'static>() {
    lock()
        .ports
        .insert(TypeId::of::<DataObject<T>>(), port_factory::<T>);
}

/// Makes data objects of type `T` exportable through its [`JsonView`].
pub fn register_data_view<T: JsonView + Clone + Default + Send + Sync + 'static>() {
    lock()
        .ports
        .insert(TypeId::of::<DataObject<T>>(), view_port_factory::<T>);
}

/// Makes events with payload `T` exportable through its [`JsonView`].
pub fn register_event_view<T: JsonView + Clone + Send + 'static>() {
    lock()
        .events
        .insert(TypeId::of::<Event<T>>(), view_event_factory::<T>);
}

/// Makes events with payload `T` exportable as JSON.
pub fn register_event<T: Serialize + Clone + Send + 'static>() {
    lock()
        .events
        .insert(TypeId::of::<Event<T>>(), event_factory::<T>);
}

/// Makes buffers of items `T` exportable as JSON streams.
pub fn register_buffer<T: Serialize + Send + 'static>() {
    lock()
        .buffers
        .insert(buffer_ports_type::<T>(), buffer_factory::<T>);
}

/// The consumer handle of the buffer behind `handle` (the registry's), as a JSON stream:
/// `None` if its item type is not registered, `Some(None)` if a consumer took it.
pub(crate) fn buffer_reader(
    handle: &mut (dyn Any + Send + Sync),
) -> Option<Option<Box<dyn JsonEventReceiver>>> {
    let f = *lock().buffers.get(&(*handle).type_id())?;
    f(handle)
}

fn buffer_factory<T: Serialize + Send + 'static>(
    h: &mut (dyn Any + Send + Sync),
) -> Option<Option<Box<dyn JsonEventReceiver>>> {
    if (*h).type_id() != buffer_ports_type::<T>() {
        return None;
    }
    Some(take_buffer_reader::<T>(h).map(|r| Box::new(BufferJson(r)) as Box<dyn JsonEventReceiver>))
}

/// A buffer's consumer handle, draining in order as JSON.
struct BufferJson<T>(BufferReader<T>);

impl<T: Serialize + Send> JsonEventReceiver for BufferJson<T> {
    fn drain(&mut self, f: &mut dyn FnMut(Value)) -> usize {
        self.0
            .drain(|v| f(serde_json::to_value(&v).unwrap_or(Value::Null)))
    }
}

/// A JSON reader of the data object behind `handle` (a `DataObject<T>` as the deployment
/// keeps it), or `None` if `T` is not registered or the object has no reader slot left.
pub fn port_reader(handle: AnyRef<'_>) -> Option<Box<dyn JsonPortReader>> {
    let f = *lock().ports.get(&handle.type_id())?;
    f(handle)
}

/// A JSON subscription to the event behind `handle` (an `Event<T>`), queueing up to
/// `capacity` events, or `None` if `T` is not registered.
pub fn event_receiver(handle: AnyRef<'_>, capacity: usize) -> Option<Box<dyn JsonEventReceiver>> {
    let f = *lock().events.get(&handle.type_id())?;
    f(handle, capacity)
}

fn port_factory<T: Serialize + Clone + Default + Send + Sync + 'static>(
    h: AnyRef<'_>,
) -> Option<Box<dyn JsonPortReader>> {
    port::<T, Serde>(h)
}

fn view_port_factory<T: JsonView + Clone + Default + Send + Sync + 'static>(
    h: AnyRef<'_>,
) -> Option<Box<dyn JsonPortReader>> {
    port::<T, View>(h)
}

fn event_factory<T: Serialize + Clone + Send + 'static>(
    h: AnyRef<'_>,
    capacity: usize,
) -> Option<Box<dyn JsonEventReceiver>> {
    event::<T, Serde>(h, capacity)
}

fn view_event_factory<T: JsonView + Clone + Send + 'static>(
    h: AnyRef<'_>,
    capacity: usize,
) -> Option<Box<dyn JsonEventReceiver>> {
    event::<T, View>(h, capacity)
}

fn port<T, C>(h: AnyRef<'_>) -> Option<Box<dyn JsonPortReader>>
where
    T: Clone + Default + Send + Sync + 'static,
    C: ToJson<T> + 'static,
{
    let reader = h.downcast_ref::<DataObject<T>>()?.reader().ok()?;
    Some(Box::new(PortJson::<T, C>(reader, PhantomData)))
}

fn event<T, C>(h: AnyRef<'_>, capacity: usize) -> Option<Box<dyn JsonEventReceiver>>
where
    T: Clone + Send + 'static,
    C: ToJson<T> + 'static,
{
    let rx = h.downcast_ref::<Event<T>>()?.subscribe(capacity);
    Some(Box::new(EventJson::<T, C>(rx, PhantomData)))
}

/// How values become JSON: through `Serialize` ([`Serde`]) or a [`JsonView`] ([`View`]).
trait ToJson<T> {
    fn to_json(v: &T) -> Value;
}
struct Serde;
struct View;
impl<T: Serialize> ToJson<T> for Serde {
    fn to_json(v: &T) -> Value {
        serde_json::to_value(v).unwrap_or(Value::Null)
    }
}
impl<T: JsonView> ToJson<T> for View {
    fn to_json(v: &T) -> Value {
        v.json()
    }
}

/// `fn() -> C` keeps the marker `Send` whatever `C` is.
struct PortJson<T, C>(DataReader<T>, PhantomData<fn() -> C>);

impl<T: Clone + Default + Send + Sync, C: ToJson<T>> JsonPortReader for PortJson<T, C> {
    fn fresh(&mut self) -> Option<Value> {
        match self.0.read() {
            (FlowStatus::NewData, v) => Some(C::to_json(v)),
            _ => None,
        }
    }
    fn latest(&mut self) -> Option<Value> {
        match self.0.read() {
            (FlowStatus::NoData, _) => None,
            (_, v) => Some(C::to_json(v)),
        }
    }
}

struct EventJson<T, C>(EventReceiver<T>, PhantomData<fn() -> C>);

impl<T: Clone + Send, C: ToJson<T>> JsonEventReceiver for EventJson<T, C> {
    fn drain(&mut self, f: &mut dyn FnMut(Value)) -> usize {
        self.0.drain(|v| f(C::to_json(&v)))
    }
}

// Not under loom: these build data objects and events outside a loom model.
#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    #[test]
    fn a_registered_port_reads_as_json_and_reports_only_fresh_values() {
        let obj = DataObject::<[f64; 3]>::new("p", 4);
        let mut w = obj.writer().unwrap();
        let any: Box<dyn Any + Send + Sync> = Box::new(obj.clone());
        let mut r = port_reader(any.as_ref()).expect("[f64; 3] is registered");
        assert_eq!(r.latest(), None);
        w.set([1.0, 2.0, 3.0]);
        assert_eq!(r.fresh(), Some(serde_json::json!([1.0, 2.0, 3.0])));
        assert_eq!(r.fresh(), None);
        assert_eq!(r.latest(), Some(serde_json::json!([1.0, 2.0, 3.0])));
    }

    #[derive(Clone, Default)]
    struct Opaque;

    #[test]
    fn an_unregistered_type_has_no_json_view() {
        let any: Box<dyn Any + Send + Sync> = Box::new(DataObject::<Opaque>::new("o", 2));
        assert!(port_reader(any.as_ref()).is_none());
    }

    #[derive(Clone, Default, Serialize)]
    struct Reading {
        mm: f64,
    }

    #[test]
    fn registered_events_arrive_in_order_as_json() {
        register_event::<Reading>();
        let ev = Event::<Reading>::new("e");
        let mut src = ev.source().unwrap();
        let any: Box<dyn Any + Send + Sync> = Box::new(ev.clone());
        let mut rx = event_receiver(any.as_ref(), 8).expect("registered");
        src.emit(Reading { mm: 1.5 });
        src.emit(Reading { mm: 2.5 });
        let mut got = Vec::new();
        assert_eq!(rx.drain(&mut |v| got.push(v)), 2);
        assert_eq!(
            got,
            vec![
                serde_json::json!({"mm": 1.5}),
                serde_json::json!({"mm": 2.5})
            ]
        );
    }
}
