//! The bounded lock-free ring under buffers and command queues (Vyukov's bounded queue: one
//! sequence stamp per slot, producers claim a position with a CAS on `tail`).
//!
//! Why this shape: every slot is preallocated at construction, so pushing and popping never
//! allocate; a producer never waits for a consumer (a full ring is reported, not waited on);
//! and the consumer side comes in two flavours. With a single consumer ([`Ring::pop_single`])
//! popping is two loads and two stores, no read-modify-write, which is what makes the command
//! queue cheaper than a general MPMC queue. When producers must also pop (the "drop oldest"
//! buffer policy) every popper uses the CAS flavour ([`Ring::pop_shared`]); a ring must use one
//! flavour for its whole life, which the owning types guarantee.

use super::sync::{AtomicUsize, Ordering, Padded, UnsafeCell};
use std::mem::MaybeUninit;

struct Slot<T> {
    /// `pos` when free for the producer of lap position `pos`, `pos + 1` when it holds the
    /// value pushed at `pos`.
    stamp: AtomicUsize,
    value: UnsafeCell<MaybeUninit<T>>,
}

/// A bounded multi-producer FIFO of `T` with a power-of-two capacity.
pub(crate) struct Ring<T> {
    head: Padded<AtomicUsize>,
    tail: Padded<AtomicUsize>,
    slots: Box<[Slot<T>]>,
    mask: usize,
}

// SAFETY: values move between threads through the ring (so T: Send); slot access is
// serialised by the stamp protocol.
unsafe impl<T: Send> Send for Ring<T> {}
// SAFETY: as above; `&Ring` only hands values out by move.
unsafe impl<T: Send> Sync for Ring<T> {}

impl<T> Ring<T> {
    /// Creates a ring holding at least `capacity` items (rounded up to a power of two, at
    /// least 2).
    pub(crate) fn new(capacity: usize) -> Self {
        // At least 2: with one slot the "published" stamp (pos + 1) equals the next
        // position's "free" stamp and the protocol breaks down.
        let cap = capacity.max(2).next_power_of_two();
        let slots = (0..cap)
            .map(|i| Slot {
                stamp: AtomicUsize::new(i),
                value: UnsafeCell::new(MaybeUninit::uninit()),
            })
            .collect::<Vec<_>>()
            .into_boxed_slice();
        Self {
            head: Padded(AtomicUsize::new(0)),
            tail: Padded(AtomicUsize::new(0)),
            slots,
            mask: cap - 1,
        }
    }

    /// Number of slots.
    pub(crate) fn capacity(&self) -> usize {
        self.mask + 1
    }

    /// Approximate number of queued items (exact when no push or pop is in flight).
    pub(crate) fn len(&self) -> usize {
        let tail = self.tail.load(Ordering::Acquire);
        let head = self.head.load(Ordering::Acquire);
        tail.wrapping_sub(head).min(self.capacity())
    }

    /// Appends `value`, or hands it back when the ring is full.
    #[inline]
    pub(crate) fn push(&self, value: T) -> Result<(), T> {
        let mut pos = self.tail.load(Ordering::Relaxed);
        loop {
            let slot = &self.slots[pos & self.mask];
            let stamp = slot.stamp.load(Ordering::Acquire);
            let diff = stamp.wrapping_sub(pos) as isize;
            if diff == 0 {
                match self.tail.compare_exchange_weak(
                    pos,
                    pos.wrapping_add(1),
                    Ordering::Relaxed,
                    Ordering::Relaxed,
                ) {
                    Ok(_) => {
                        // SAFETY: winning the CAS gives this producer exclusive use of the slot
                        // until it publishes the stamp below.
                        slot.value.with_mut(|p| unsafe { (*p).write(value) });
                        slot.stamp.store(pos.wrapping_add(1), Ordering::Release);
                        return Ok(());
                    }
                    Err(actual) => pos = actual,
                }
            } else if diff < 0 {
                // The slot still holds the value of the previous lap: full.
                return Err(value);
            } else {
                pos = self.tail.load(Ordering::Relaxed);
            }
        }
    }

    /// Removes the oldest value. Only valid while this is the ring's only popper.
    #[inline]
    pub(crate) fn pop_single(&self) -> Option<T> {
        let pos = self.head.load(Ordering::Relaxed);
        let slot = &self.slots[pos & self.mask];
        let stamp = slot.stamp.load(Ordering::Acquire);
        if stamp != pos.wrapping_add(1) {
            return None;
        }
        // SAFETY: the stamp says the value at `pos` is published and, being the only popper,
        // nobody else reads it.
        let value = slot.value.with(|p| unsafe { (*p).assume_init_read() });
        slot.stamp
            .store(pos.wrapping_add(self.mask + 1), Ordering::Release);
        self.head.store(pos.wrapping_add(1), Ordering::Relaxed);
        Some(value)
    }

    /// Removes the oldest value; any number of threads may call this concurrently.
    #[inline]
    pub(crate) fn pop_shared(&self) -> Option<T> {
        let mut pos = self.head.load(Ordering::Relaxed);
        loop {
            let slot = &self.slots[pos & self.mask];
            let stamp = slot.stamp.load(Ordering::Acquire);
            let diff = stamp.wrapping_sub(pos.wrapping_add(1)) as isize;
            if diff == 0 {
                match self.head.compare_exchange_weak(
                    pos,
                    pos.wrapping_add(1),
                    Ordering::Relaxed,
                    Ordering::Relaxed,
                ) {
                    Ok(_) => {
                        // SAFETY: winning the CAS gives this popper the published value at `pos`.
                        let value = slot.value.with(|p| unsafe { (*p).assume_init_read() });
                        slot.stamp
                            .store(pos.wrapping_add(self.mask + 1), Ordering::Release);
                        return Some(value);
                    }
                    Err(actual) => pos = actual,
                }
            } else if diff < 0 {
                return None;
            } else {
                pos = self.head.load(Ordering::Relaxed);
            }
        }
    }
}

impl<T> Drop for Ring<T> {
    fn drop(&mut self) {
        // Exclusive access: drop every published, unpopped value.
        while self.pop_shared().is_some() {}
    }
}

#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    #[test]
    fn fifo_order_and_full_hands_value_back() {
        let r = Ring::new(3);
        assert_eq!(r.capacity(), 4);
        for i in 0..4 {
            assert!(r.push(i).is_ok());
        }
        assert_eq!(r.push(99), Err(99));
        assert_eq!(r.len(), 4);
        assert_eq!(r.pop_single(), Some(0));
        assert!(r.push(4).is_ok());
        let got: Vec<_> = std::iter::from_fn(|| r.pop_single()).collect();
        assert_eq!(got, vec![1, 2, 3, 4]);
        assert_eq!(r.pop_shared(), None);
    }

    #[test]
    fn drop_releases_queued_values() {
        let v = std::sync::Arc::new(());
        let r = Ring::new(4);
        r.push(v.clone()).unwrap();
        r.push(v.clone()).unwrap();
        drop(r);
        assert_eq!(std::sync::Arc::strong_count(&v), 1);
    }

    #[test]
    fn many_producers_one_consumer_lose_nothing() {
        let r = std::sync::Arc::new(Ring::new(64));
        let producers: Vec<_> = (0..3u64)
            .map(|p| {
                let r = r.clone();
                std::thread::spawn(move || {
                    for i in 0..10_000u64 {
                        let mut v = p << 32 | i;
                        while let Err(back) = r.push(v) {
                            v = back;
                            std::thread::yield_now();
                        }
                    }
                })
            })
            .collect();
        let mut next = [0u64; 3];
        let mut got = 0;
        while got < 30_000 {
            match r.pop_single() {
                Some(v) => {
                    let (p, i) = ((v >> 32) as usize, v & 0xffff_ffff);
                    assert_eq!(i, next[p], "per-producer FIFO order");
                    next[p] += 1;
                    got += 1;
                }
                None => std::thread::yield_now(),
            }
        }
        for p in producers {
            p.join().unwrap();
        }
    }
}

#[cfg(all(test, loom))]
mod loom_tests {
    use super::*;
    use crate::rt::sync::Arc;

    #[test]
    fn two_producers_single_consumer() {
        loom::model(|| {
            let r = Arc::new(Ring::new(2));
            let a = {
                let r = r.clone();
                loom::thread::spawn(move || r.push(1u32).is_ok())
            };
            let b = {
                let r = r.clone();
                loom::thread::spawn(move || r.push(2u32).is_ok())
            };
            let mut seen = vec![];
            for _ in 0..2 {
                if let Some(v) = r.pop_single() {
                    seen.push(v);
                }
            }
            assert!(a.join().unwrap() && b.join().unwrap());
            while let Some(v) = r.pop_single() {
                seen.push(v);
            }
            seen.sort();
            assert_eq!(seen, vec![1, 2]);
        });
    }

    #[test]
    fn shared_pop_races_push() {
        loom::model(|| {
            let r = Arc::new(Ring::new(1));
            r.push(1u32).unwrap();
            let p = {
                let r = r.clone();
                loom::thread::spawn(move || {
                    // Producer making room ("drop oldest") and pushing.
                    let dropped = r.pop_shared();
                    (dropped, r.push(2).is_ok())
                })
            };
            let c = r.pop_shared();
            let (dropped, pushed) = p.join().unwrap();
            let mut all: Vec<u32> = [dropped, c, r.pop_shared()].into_iter().flatten().collect();
            all.sort();
            // Every pushed value is popped exactly once, whoever popped it.
            let expected = if pushed { vec![1, 2] } else { vec![1] };
            assert_eq!(all, expected);
        });
    }
}
