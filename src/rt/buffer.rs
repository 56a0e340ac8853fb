//! Buffers: bounded lock-free FIFOs between tasks (or between a realtime task and a non-realtime
//! thread), with an explicit policy for a full buffer.
//!
//! Why a policy and not a blocking push: a realtime producer must never wait for its consumer.
//! What to lose when the consumer falls behind is an application decision, so it is named at
//! construction ([`FullPolicy`]) and every loss is counted ([`BufferReader::overflows`]). A
//! producer that *can* wait (the non-realtime planner feeding the interpolator's segment queue)
//! uses [`BufferWriter::try_push`], which hands the item back instead of dropping anything.
//!
//! Many writers (the writer handle is `Clone`), one reader (the reader handle is not).
//!
//! A deployment creates a buffer when a task first names it (`Configure::buffer_out` /
//! `Configure::buffer_in`), and its capacity and policy are declared by the producers. When
//! the consumer is configured first, the buffer exists *unsized* until its first producer
//! declares them, still during `configure`: that keeps configure order irrelevant, as for data
//! objects. An unsized buffer stores nothing (a push is dropped and counted, a pop finds
//! nothing); a deployment whose buffer never gets a producer fails its topology check, so
//! running tasks never see one. The price is one load of an already-initialised flag per push
//! and pop.

use super::ring::Ring;
use super::sync::{Arc, AtomicU64, Ordering};
use std::sync::OnceLock;

/// What [`BufferWriter::push`] does when the buffer is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum FullPolicy {
    /// Keep the queued items, discard the new one (a stream of samples where the consumer
    /// wants the continuity of what it has).
    DropNewest,
    /// Discard the oldest queued item to make room (the consumer wants the most recent
    /// history, e.g. events pushed to a monitoring client).
    DropOldest,
}

/// What happened to an item given to [`BufferWriter::push`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PushOutcome {
    /// Queued without loss.
    Stored,
    /// The buffer was full: the new item was discarded (policy [`FullPolicy::DropNewest`]).
    DroppedNewest,
    /// The buffer was full: the oldest item was discarded to queue the new one.
    DroppedOldest,
}

/// The storage and policy of a sized buffer.
struct Core<T> {
    ring: Ring<T>,
    policy: FullPolicy,
}

struct Shared<T> {
    /// Set once: at creation, or by the first producer of a deployment-made buffer.
    core: OnceLock<Core<T>>,
    overflows: AtomicU64,
}

/// Creates a buffer of at least `capacity` items (rounded up to a power of two) with the given
/// full policy. Allocates once, here; pushes and pops never allocate.
pub fn buffer<T: Send>(capacity: usize, policy: FullPolicy) -> (BufferWriter<T>, BufferReader<T>) {
    let (w, r) = unsized_buffer();
    w.size(capacity, policy);
    (w, r)
}

/// Creates a buffer without storage yet; [`BufferWriter::size`] gives it its capacity and
/// policy. For the deployment registry (module doc).
pub(crate) fn unsized_buffer<T: Send>() -> (BufferWriter<T>, BufferReader<T>) {
    let shared = Arc::new(Shared {
        core: OnceLock::new(),
        overflows: AtomicU64::new(0),
    });
    (
        BufferWriter {
            shared: shared.clone(),
        },
        BufferReader { shared },
    )
}

/// The producing side of a buffer. `Clone`: several producers may feed one buffer.
pub struct BufferWriter<T> {
    shared: Arc<Shared<T>>,
}

impl<T> Clone for BufferWriter<T> {
    fn clone(&self) -> Self {
        Self {
            shared: self.shared.clone(),
        }
    }
}

impl<T: Send> BufferWriter<T> {
    /// Gives an unsized buffer its capacity and policy (allocating its storage). Returns false
    /// if it was already sized, whatever with; configuration time only.
    pub(crate) fn size(&self, capacity: usize, policy: FullPolicy) -> bool {
        let mut sized = false;
        self.shared.core.get_or_init(|| {
            sized = true;
            Core {
                ring: Ring::new(capacity),
                policy,
            }
        });
        sized
    }

    /// Queues `item`, applying the buffer's [`FullPolicy`] if it is full. Never blocks, never
    /// allocates; a loss is counted.
    #[inline]
    pub fn push(&self, item: T) -> PushOutcome {
        let s = &*self.shared;
        let Some(core) = s.core.get() else {
            // Unsized (module doc): nowhere to put it.
            s.overflows.fetch_add(1, Ordering::Relaxed);
            return PushOutcome::DroppedNewest;
        };
        let Err(mut item) = core.ring.push(item) else {
            return PushOutcome::Stored;
        };
        s.overflows.fetch_add(1, Ordering::Relaxed);
        if core.policy == FullPolicy::DropOldest {
            // Make room and retry; bounded so that racing producers cannot starve us.
            for _ in 0..4 {
                drop(core.ring.pop_shared());
                match core.ring.push(item) {
                    Ok(()) => return PushOutcome::DroppedOldest,
                    Err(back) => item = back,
                }
            }
        }
        drop(item);
        PushOutcome::DroppedNewest
    }

    /// Queues `item` or, if the buffer is full, hands it back untouched (nothing is dropped or
    /// counted). For producers that can wait and retry.
    #[inline]
    pub fn try_push(&self, item: T) -> Result<(), T> {
        match self.shared.core.get() {
            Some(core) => core.ring.push(item),
            None => Err(item),
        }
    }

    /// Free slots right now (approximate under concurrency): lets a producer decide how much
    /// to prepare.
    pub fn free(&self) -> usize {
        self.shared
            .core
            .get()
            .map_or(0, |c| c.ring.capacity() - c.ring.len())
    }
}

/// The consuming side of a buffer. Not `Clone`: one consumer.
pub struct BufferReader<T> {
    shared: Arc<Shared<T>>,
}

impl<T: Send> BufferReader<T> {
    /// Takes the oldest item, if any. Never blocks, never allocates.
    #[inline]
    pub fn pop(&mut self) -> Option<T> {
        let core = self.shared.core.get()?;
        match core.policy {
            FullPolicy::DropNewest => core.ring.pop_single(),
            // Producers pop too under this policy.
            FullPolicy::DropOldest => core.ring.pop_shared(),
        }
    }

    /// Pops every queued item into `f` (bounded by the capacity, so a fast producer cannot
    /// keep the consumer here forever). Returns how many were handled.
    pub fn drain(&mut self, mut f: impl FnMut(T)) -> usize {
        let cap = self.capacity();
        let mut n = 0;
        while n < cap {
            match self.pop() {
                Some(item) => {
                    f(item);
                    n += 1;
                }
                None => break,
            }
        }
        n
    }

    /// Number of queued items (approximate under concurrency).
    pub fn len(&self) -> usize {
        self.shared.core.get().map_or(0, |c| c.ring.len())
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Capacity in items (0 while unsized, see the module doc).
    pub fn capacity(&self) -> usize {
        self.shared.core.get().map_or(0, |c| c.ring.capacity())
    }

    /// The full policy (`None` while unsized, see the module doc).
    pub fn policy(&self) -> Option<FullPolicy> {
        self.shared.core.get().map(|c| c.policy)
    }

    /// Items lost to a full buffer since creation.
    pub fn overflows(&self) -> u64 {
        self.shared.overflows.load(Ordering::Relaxed)
    }
}

#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    #[test]
    fn drop_newest_keeps_old_items_and_counts() {
        let (w, mut r) = buffer(2, FullPolicy::DropNewest);
        assert_eq!(w.push(1), PushOutcome::Stored);
        assert_eq!(w.push(2), PushOutcome::Stored);
        assert_eq!(w.push(3), PushOutcome::DroppedNewest);
        assert_eq!(r.overflows(), 1);
        assert_eq!((r.pop(), r.pop(), r.pop()), (Some(1), Some(2), None));
    }

    #[test]
    fn drop_oldest_keeps_recent_items_and_counts() {
        let (w, mut r) = buffer(2, FullPolicy::DropOldest);
        w.push(1);
        w.push(2);
        assert_eq!(w.push(3), PushOutcome::DroppedOldest);
        assert_eq!(r.overflows(), 1);
        assert_eq!((r.pop(), r.pop(), r.pop()), (Some(2), Some(3), None));
    }

    #[test]
    fn try_push_hands_item_back_without_counting() {
        let (w, mut r) = buffer(2, FullPolicy::DropNewest);
        assert_eq!(w.try_push("a"), Ok(()));
        assert_eq!(w.try_push("b"), Ok(()));
        assert_eq!(w.try_push("c"), Err("c"));
        assert_eq!(w.free(), 0);
        assert_eq!(r.overflows(), 0);
        let mut seen = vec![];
        assert_eq!(r.drain(|x| seen.push(x)), 2);
        assert_eq!(seen, ["a", "b"]);
        assert!(r.is_empty());
    }

    #[test]
    fn unsized_buffer_stores_nothing_until_sized_once() {
        let (w, mut r) = unsized_buffer::<u32>();
        assert_eq!((r.capacity(), r.policy(), w.free()), (0, None, 0));
        assert_eq!(w.push(1), PushOutcome::DroppedNewest);
        assert_eq!(w.try_push(2), Err(2));
        assert_eq!((r.pop(), r.overflows()), (None, 1));
        let w2 = w.clone();
        assert!(w2.size(3, FullPolicy::DropOldest));
        assert!(!w.size(16, FullPolicy::DropNewest), "sized once");
        assert_eq!(
            (r.capacity(), r.policy()),
            (4, Some(FullPolicy::DropOldest))
        );
        for i in 0..5 {
            w.push(i);
        }
        let mut seen = vec![];
        r.drain(|x| seen.push(x));
        assert_eq!(seen, [1, 2, 3, 4]);
    }
}

#[cfg(all(test, loom))]
mod loom_tests {
    use super::*;

    #[test]
    fn drop_oldest_never_loses_the_newest() {
        loom::model(|| {
            let (w, mut r) = buffer(1, FullPolicy::DropOldest);
            w.push(1u32);
            let w2 = w.clone();
            let t = loom::thread::spawn(move || w2.push(2));
            let early = r.pop();
            t.join().unwrap();
            let late = r.pop();
            // The newest item survives, whether or not the consumer got the old one first.
            assert!(early == Some(2) || late == Some(2));
        });
    }
}
