//! Events: typed notifications carrying data, published by one task and handled by others.
//!
//! Two kinds of handler (the paper's synchronous/asynchronous handlers):
//! - *immediate* handlers ([`Event::subscribe_immediate`]) run in the emitter's thread, inside
//!   [`EventSource::emit`]; they must be realtime safe and short.
//! - *deferred* handlers receive the event through a bounded lock-free queue
//!   ([`Event::subscribe`] → [`EventReceiver`]). A task drains its receivers in its
//!   `process_events` hook, the safe point at the end of its step, so the handler runs in the
//!   subscriber's thread with the subscriber's state. The same receiver works for a
//!   non-realtime consumer (the control socket) that drains it from an ordinary thread.
//!
//! Subscribing is configuration: it takes a mutex and may allocate, so it happens before the
//! emitter runs (at the latest, before its next emit; the emitter picks new subscribers up
//! with a non-blocking `try_lock`, never waiting). A full receiver queue loses the event
//! ([`FullPolicy::DropOldest`]: a late consumer wants the recent history); every loss is
//! counted, per receiver and per event, and emitting never blocks.

use super::buffer::{buffer, BufferReader, BufferWriter, FullPolicy, PushOutcome};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

type Immediate<T> = Box<dyn FnMut(&T) + Send>;

struct Subscribers<T> {
    immediate: Vec<Immediate<T>>,
    queues: Vec<(BufferWriter<T>, Option<Arc<AtomicBool>>)>,
}

impl<T> Default for Subscribers<T> {
    fn default() -> Self {
        Self {
            immediate: Vec::new(),
            queues: Vec::new(),
        }
    }
}

struct Shared<T> {
    name: String,
    pending: Mutex<Subscribers<T>>,
    has_pending: AtomicBool,
    source_taken: AtomicBool,
    emitted: AtomicU64,
    lost: AtomicU64,
}

/// Preallocated subscriber capacity of an emitter: subscribers beyond this are still served,
/// but picking them up allocates once.
const SUBSCRIBER_CAPACITY: usize = 16;

/// A named event type: the shared handle used to subscribe and to take the single
/// [`EventSource`]. Cloning is cheap.
pub struct Event<T> {
    shared: Arc<Shared<T>>,
}

impl<T> Clone for Event<T> {
    fn clone(&self) -> Self {
        Self {
            shared: self.shared.clone(),
        }
    }
}

/// Errors creating event handles.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EventError {
    /// The emitter handle of this event was already taken.
    #[error("event '{0}' already has an emitter")]
    SourceTaken(String),
}

impl<T: Clone + Send + 'static> Event<T> {
    /// A new event type named `name` (by convention `task.event`).
    pub fn new(name: &str) -> Self {
        Self {
            shared: Arc::new(Shared {
                name: name.to_owned(),
                pending: Mutex::new(Subscribers::default()),
                has_pending: AtomicBool::new(false),
                source_taken: AtomicBool::new(false),
                emitted: AtomicU64::new(0),
                lost: AtomicU64::new(0),
            }),
        }
    }

    /// The event's name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// Takes the emitter. One per event, so that emission order is well defined.
    pub fn source(&self) -> Result<EventSource<T>, EventError> {
        if self.shared.source_taken.swap(true, Ordering::AcqRel) {
            return Err(EventError::SourceTaken(self.shared.name.clone()));
        }
        Ok(EventSource {
            shared: self.shared.clone(),
            local: Subscribers {
                immediate: Vec::with_capacity(SUBSCRIBER_CAPACITY),
                queues: Vec::with_capacity(SUBSCRIBER_CAPACITY),
            },
        })
    }

    /// Adds a handler run in the emitter's thread on every emit. It must be realtime safe.
    pub fn subscribe_immediate(&self, handler: impl FnMut(&T) + Send + 'static) {
        let mut p = self
            .shared
            .pending
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        p.immediate.push(Box::new(handler));
        self.shared.has_pending.store(true, Ordering::Release);
    }

    /// Adds a deferred subscription: every emit queues a copy in the returned receiver (up to
    /// `capacity`, rounded up to a power of two; beyond, the oldest is dropped and counted).
    pub fn subscribe(&self, capacity: usize) -> EventReceiver<T> {
        self.subscribe_waking(capacity, None)
    }

    /// As [`subscribe`](Self::subscribe), also raising `wake` on every emit (used to wake a
    /// non-periodic task).
    pub fn subscribe_waking(
        &self,
        capacity: usize,
        wake: Option<Arc<AtomicBool>>,
    ) -> EventReceiver<T> {
        let (w, r) = buffer(capacity, FullPolicy::DropOldest);
        let mut p = self
            .shared
            .pending
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        p.queues.push((w, wake));
        self.shared.has_pending.store(true, Ordering::Release);
        EventReceiver {
            reader: r,
            name: self.shared.name.clone(),
        }
    }

    /// Emits so far.
    pub fn emitted(&self) -> u64 {
        self.shared.emitted.load(Ordering::Relaxed)
    }

    /// Deliveries lost to full receivers so far.
    pub fn lost(&self) -> u64 {
        self.shared.lost.load(Ordering::Relaxed)
    }

    /// A type-erased view of this event's emission count, for consumers that react to the
    /// fact of an emission and not its data (scripts waiting for an event by name).
    pub fn counter(&self) -> EventCounter {
        EventCounter(self.shared.clone())
    }
}

trait Emitted: Send + Sync {
    fn emitted(&self) -> u64;
    fn name(&self) -> &str;
}

impl<T: Send> Emitted for Shared<T> {
    fn emitted(&self) -> u64 {
        self.emitted.load(Ordering::Acquire)
    }
    fn name(&self) -> &str {
        &self.name
    }
}

/// How many times an event was emitted, readable from any thread without knowing the
/// event's data type: one atomic load, wait-free, no subscription (so nothing can be lost
/// and the emitter does no extra work). A consumer remembers the count it has seen and
/// compares.
#[derive(Clone)]
pub struct EventCounter(Arc<dyn Emitted>);

impl EventCounter {
    /// Emissions so far.
    #[inline]
    pub fn count(&self) -> u64 {
        self.0.emitted()
    }
    /// The event's name.
    pub fn name(&self) -> &str {
        self.0.name()
    }
}

impl std::fmt::Debug for EventCounter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EventCounter")
            .field("name", &self.name())
            .field("count", &self.count())
            .finish()
    }
}

/// The emitting side of an event. Owned by the emitting task.
pub struct EventSource<T> {
    shared: Arc<Shared<T>>,
    local: Subscribers<T>,
}

impl<T: Clone + Send + 'static> EventSource<T> {
    /// Runs the immediate handlers in this thread, then queues a copy for every deferred
    /// subscriber. Never blocks; allocates nothing as long as the subscribers fit the
    /// preallocated capacity (16 of each kind) and `T::clone` does not allocate.
    pub fn emit(&mut self, value: T) {
        if self.shared.has_pending.load(Ordering::Acquire) {
            self.pick_up_subscribers();
        }
        for h in &mut self.local.immediate {
            h(&value);
        }
        let mut value = Some(value);
        let n = self.local.queues.len();
        for (i, (q, wake)) in self.local.queues.iter().enumerate() {
            let v = if i + 1 == n {
                value.take()
            } else {
                value.clone()
            };
            if let Some(v) = v {
                if q.push(v) != PushOutcome::Stored {
                    self.shared.lost.fetch_add(1, Ordering::Relaxed);
                }
            }
            if let Some(w) = wake {
                w.store(true, Ordering::Release);
            }
        }
        self.shared.emitted.fetch_add(1, Ordering::Release);
    }

    #[cold]
    fn pick_up_subscribers(&mut self) {
        // Never wait for a subscriber being added: try again on the next emit.
        if let Ok(mut p) = self.shared.pending.try_lock() {
            self.local.immediate.append(&mut p.immediate);
            self.local.queues.append(&mut p.queues);
            self.shared.has_pending.store(false, Ordering::Release);
        }
    }

    /// The event's name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }
}

/// A deferred subscription: events queued for one consumer.
pub struct EventReceiver<T> {
    reader: BufferReader<T>,
    name: String,
}

impl<T: Send> EventReceiver<T> {
    /// The oldest queued event.
    pub fn pop(&mut self) -> Option<T> {
        self.reader.pop()
    }

    /// Handles every queued event (bounded by the capacity). Returns the count.
    pub fn drain(&mut self, f: impl FnMut(T)) -> usize {
        self.reader.drain(f)
    }

    /// True when events are queued.
    pub fn has_events(&self) -> bool {
        !self.reader.is_empty()
    }

    /// Events lost because this receiver was full.
    pub fn lost(&self) -> u64 {
        self.reader.overflows()
    }

    /// Name of the event.
    pub fn name(&self) -> &str {
        &self.name
    }
}

#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    #[test]
    fn immediate_in_emitter_thread_deferred_queued() {
        let ev = Event::<u32>::new("t.e");
        let seen = Arc::new(AtomicU64::new(0));
        let s2 = seen.clone();
        let emitter_thread = std::thread::current().id();
        ev.subscribe_immediate(move |v| {
            assert_eq!(std::thread::current().id(), emitter_thread);
            s2.fetch_add(u64::from(*v), Ordering::Relaxed);
        });
        let mut rx = ev.subscribe(4);
        let mut src = ev.source().unwrap();
        assert!(ev.source().is_err(), "one emitter per event");
        src.emit(3);
        src.emit(4);
        assert_eq!(seen.load(Ordering::Relaxed), 7);
        assert_eq!((rx.pop(), rx.pop(), rx.pop()), (Some(3), Some(4), None));
        assert_eq!(ev.emitted(), 2);
    }

    #[test]
    fn counter_sees_emissions_without_the_type() {
        let ev = Event::<(u32, f64)>::new("t.e");
        let c = ev.counter();
        assert_eq!((c.count(), c.name()), (0, "t.e"));
        let mut src = ev.source().unwrap();
        src.emit((1, 2.0));
        src.emit((3, 4.0));
        assert_eq!(c.count(), 2);
    }

    #[test]
    fn overflow_is_counted_never_blocks() {
        let ev = Event::<u32>::new("t.e");
        let mut rx = ev.subscribe(2);
        let mut src = ev.source().unwrap();
        for i in 0..5 {
            src.emit(i);
        }
        assert_eq!(rx.lost(), 3);
        assert_eq!(ev.lost(), 3);
        let mut got = vec![];
        rx.drain(|v| got.push(v));
        assert_eq!(got, vec![3, 4], "oldest dropped, recent kept");
    }

    #[test]
    fn non_rt_consumer_drains_from_another_thread() {
        let ev = Event::<u64>::new("t.e");
        let mut rx = ev.subscribe(1024);
        let mut src = ev.source().unwrap();
        let t = std::thread::spawn(move || {
            let mut sum = 0;
            let mut n = 0;
            while n < 100 {
                n += rx.drain(|v| sum += v);
                std::thread::yield_now();
            }
            sum
        });
        for i in 0..100 {
            src.emit(i);
        }
        assert_eq!(t.join().unwrap(), (0..100).sum::<u64>());
    }
}
