//! Data objects: the "latest value" connection of the data flow. One writer, many readers;
//! a read returns the latest complete write, never a torn value, and says whether it is new.
//!
//! # Design (why not a seqlock, why not Orocos' retry loop)
//! Both sides must be wait-free: a realtime reader must not spin while a preempted writer is
//! half-way through a write (a seqlock does exactly that), and Orocos' `DataObjectLockFree`
//! reader retries when the writer moves the read pointer under it. Here each reader owns a
//! *triple buffer* (three value slots and one atomic byte saying which slot is the published
//! "back" one). `set` writes the value into the back slot of every registered reader and
//! swaps it in with one atomic exchange per reader; `get` swaps in the newest back slot if
//! there is one, with one exchange. Neither side ever loops or waits, and no slot is written
//! while its reader may read it. The price is that `set` costs one copy per registered reader,
//! so readers are registered (at configure time) up to a fixed maximum chosen at construction.
//!
//! A reader registered after values were written must still see the latest one. The object
//! therefore keeps one more triple buffer, the *seed*, written on every `set` before the
//! reader set is read; a new reader (off the realtime path, under a mutex shared only by new
//! readers) first registers, then takes the seed. Sequentially consistent ordering of "publish
//! seed, then read the registrations" against "register, then read the seed" guarantees the
//! new reader gets the latest value through one of the two paths. Sequence numbers in every
//! slot let the reader discard anything older than what it already has.

use super::sync::{
    lock, Arc, AtomicBool, AtomicU64, AtomicU8, Mutex, Ordering, Padded, UnsafeCell,
};

/// What a read found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub enum FlowStatus {
    /// Nothing has been written yet.
    NoData,
    /// The value was already returned by an earlier read of this reader.
    OldData,
    /// A value this reader has not returned before.
    NewData,
}

/// Errors creating data object handles (configuration time, never in a step).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum DataObjectError {
    /// The single writer handle was already taken.
    #[error("data object '{0}' already has a writer")]
    WriterTaken(String),
    /// The object was made with [`DataObject::with_fixed_readers`] and has been written.
    #[error("data object '{0}' takes no readers after its first write (fixed readers)")]
    LateReader(String),
    /// Every reader slot is in use.
    #[error("data object '{name}' has no free reader slot (max {max})")]
    TooManyReaders {
        /// Object name.
        name: String,
        /// The maximum given at construction.
        max: usize,
    },
}

/// Maximum number of simultaneously registered readers of one data object.
pub const MAX_READERS: usize = 64;

const DIRTY: u8 = 4;
const INDEX: u8 = 3;

/// One value slot: the value first and 64-byte aligned, so a cache-line-sized payload is
/// copied without split (line-crossing) loads and stores; its sequence number after it.
#[repr(C, align(64))]
struct Slot<T> {
    value: T,
    seq: u64,
}

/// One triple buffer: three `(sequence, value)` slots, the shared "back" index, and the
/// private indices of its writer and its (current) reader kept here so a reader slot can be
/// handed from a dropped reader to a new one.
struct Triple<T> {
    slots: [UnsafeCell<Slot<T>>; 3],
    back: AtomicU8,
    writer_idx: AtomicU8,
    reader_idx: AtomicU8,
}

impl<T: Default> Triple<T> {
    fn new() -> Self {
        Self {
            slots: [
                UnsafeCell::new(Slot {
                    value: T::default(),
                    seq: 0,
                }),
                UnsafeCell::new(Slot {
                    value: T::default(),
                    seq: 0,
                }),
                UnsafeCell::new(Slot {
                    value: T::default(),
                    seq: 0,
                }),
            ],
            back: AtomicU8::new(1),
            writer_idx: AtomicU8::new(0),
            reader_idx: AtomicU8::new(2),
        }
    }
}

impl<T> Triple<T> {
    /// Writer side: fill the private slot and publish it. Only the single writer calls this.
    #[inline(always)]
    fn publish(&self, seq: u64, value: T) {
        let w = self.writer_idx.load(Ordering::Relaxed);
        // SAFETY: slot `w` is owned by the writer: it is neither the back slot nor the
        // reader's slot until the exchange below publishes it.
        self.slots[usize::from(w)].with_mut(|p| unsafe { *p = Slot { value, seq } });
        let old = self.back.swap(w | DIRTY, Ordering::SeqCst);
        self.writer_idx.store(old & INDEX, Ordering::Relaxed);
    }

    /// Reader side: take the newest published slot if there is one. Returns the reader's
    /// slot index. Only the current reader of this triple calls this.
    #[inline(always)]
    fn acquire_latest(&self) -> u8 {
        let r = self.reader_idx.load(Ordering::Relaxed);
        if self.back.load(Ordering::Relaxed) & DIRTY == 0 {
            return r;
        }
        let old = self.back.swap(r, Ordering::SeqCst);
        let r = old & INDEX;
        self.reader_idx.store(r, Ordering::Relaxed);
        r
    }

    /// Reader side: read the reader's own slot.
    #[inline(always)]
    fn with_slot<R>(&self, idx: u8, f: impl FnOnce(&Slot<T>) -> R) -> R {
        // SAFETY: slot `idx` is the reader's own; the writer never writes it.
        self.slots[usize::from(idx)].with(|p| f(unsafe { &*p }))
    }
}

struct Shared<T> {
    name: String,
    seed: Triple<T>,
    /// Serialises reader registration (never taken by `set` or `get`).
    join: Mutex<()>,
    readers: Box<[Padded<Triple<T>>]>,
    /// Bit `i` set: reader slot `i` is registered.
    registered: AtomicU64,
    writer_taken: AtomicBool,
    /// Sequence number of the last `set` (for non-realtime inspection only).
    last_seq: AtomicU64,
    /// Whether readers may register after the first write (then `set` keeps the seed).
    late_readers: bool,
}

// SAFETY: values cross threads by copy (T: Send); slot access is serialised by the triple
// buffer protocol (each slot is owned by exactly one side at a time).
unsafe impl<T: Send> Sync for Shared<T> {}
// SAFETY: as above.
unsafe impl<T: Send> Send for Shared<T> {}

/// A named data object: the shared handle from which its single [`DataWriter`] and its
/// [`DataReader`]s are made. Cloning it is cheap (a reference count).
pub struct DataObject<T> {
    shared: Arc<Shared<T>>,
}

impl<T> Clone for DataObject<T> {
    fn clone(&self) -> Self {
        Self {
            shared: self.shared.clone(),
        }
    }
}

impl<T: Clone + Default + Send> DataObject<T> {
    /// Creates a data object supporting up to `max_readers` simultaneous readers (capped at
    /// [`MAX_READERS`]). Allocates all slots now; `set` and `get` never allocate.
    pub fn new(name: &str, max_readers: usize) -> Self {
        Self::build(name, max_readers, true)
    }

    /// Like [`new`](Self::new), but readers can only register before the first `set`. `set`
    /// then skips the seed (one copy and one atomic exchange fewer: about the cost of a plain
    /// triple buffer per reader). For hot servo-loop connections wired at configure time.
    pub fn with_fixed_readers(name: &str, max_readers: usize) -> Self {
        Self::build(name, max_readers, false)
    }

    fn build(name: &str, max_readers: usize, late_readers: bool) -> Self {
        let max = max_readers.clamp(1, MAX_READERS);
        Self {
            shared: Arc::new(Shared {
                name: name.to_owned(),
                seed: Triple::new(),
                join: Mutex::new(()),
                readers: (0..max).map(|_| Padded(Triple::new())).collect(),
                registered: AtomicU64::new(0),
                writer_taken: AtomicBool::new(false),
                last_seq: AtomicU64::new(0),
                late_readers,
            }),
        }
    }

    /// The object's name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// Takes the single writer. Fails if it was already taken: the single-writer rule.
    pub fn writer(&self) -> Result<DataWriter<T>, DataObjectError> {
        if self.shared.writer_taken.swap(true, Ordering::AcqRel) {
            return Err(DataObjectError::WriterTaken(self.shared.name.clone()));
        }
        Ok(DataWriter {
            shared: self.shared.clone(),
            seq: self.shared.last_seq.load(Ordering::Acquire),
        })
    }

    /// Registers a new reader. It sees the latest value written so far (if any) as
    /// [`FlowStatus::NewData`] on its first read. Not for the realtime path (takes a mutex
    /// shared only with other registrations).
    pub fn reader(&self) -> Result<DataReader<T>, DataObjectError> {
        let s = &*self.shared;
        let _guard = lock(&s.join);
        if !s.late_readers && s.last_seq.load(Ordering::Acquire) > 0 {
            return Err(DataObjectError::LateReader(s.name.clone()));
        }
        let max = s.readers.len();
        let used = s.registered.load(Ordering::SeqCst);
        let Some(index) = (0..max).find(|i| used & (1u64 << i) == 0) else {
            return Err(DataObjectError::TooManyReaders {
                name: s.name.clone(),
                max,
            });
        };
        // Register first, then read the seed (see the module doc for why this order).
        s.registered.fetch_or(1u64 << index, Ordering::SeqCst);
        let idx = s.seed.acquire_latest();
        let (seed_seq, seed_value) = s.seed.with_slot(idx, |slot| (slot.seq, slot.value.clone()));
        Ok(DataReader {
            shared: self.shared.clone(),
            index,
            seed: seed_value,
            from_seed: true,
            have_seq: seed_seq,
            reported_seq: 0,
        })
    }

    /// Number of completed `set`s so far.
    pub fn writes(&self) -> u64 {
        self.shared.last_seq.load(Ordering::Relaxed)
    }

    /// Number of registered readers.
    pub fn readers(&self) -> usize {
        self.shared.registered.load(Ordering::Relaxed).count_ones() as usize
    }

    /// True once the writer handle has been taken.
    pub fn has_writer(&self) -> bool {
        self.shared.writer_taken.load(Ordering::Relaxed)
    }
}

/// The single writer of a data object. Not `Clone`: one writer per object, by construction.
pub struct DataWriter<T> {
    shared: Arc<Shared<T>>,
    seq: u64,
}

impl<T: Clone + Send> DataWriter<T> {
    /// Publishes `value` to every reader. Wait-free: one copy and one atomic exchange per
    /// registered reader plus one for the seed; never blocks, never allocates (for `T`
    /// whose `Clone` does not).
    #[inline]
    pub fn set(&mut self, value: T) {
        let s = &*self.shared;
        self.seq += 1;
        let seq = self.seq;
        if s.late_readers {
            s.seed.publish(seq, value.clone());
        }
        // Read the registrations only after publishing the seed: the ordering argument of the
        // module doc needs it.
        let mut mask = s.registered.load(Ordering::SeqCst);
        if mask != 0 {
            // Clone for every reader but the last, which gets the value itself.
            let mut i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            while mask != 0 {
                s.readers[i].publish(seq, value.clone());
                i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
            }
            s.readers[i].publish(seq, value);
        }
        s.last_seq.store(seq, Ordering::Release);
    }

    /// Name of the object written.
    pub fn name(&self) -> &str {
        &self.shared.name
    }
}

impl<T> Drop for DataWriter<T> {
    fn drop(&mut self) {
        // The object may get a new writer (e.g. a task reconfigured); sequence numbers continue
        // from the last write so readers keep seeing them as new.
        self.shared.writer_taken.store(false, Ordering::Release);
    }
}

/// One reader of a data object. Each reader has its own slots, so readers never disturb each
/// other or the writer. Not `Clone` (make another with [`DataObject::reader`]).
pub struct DataReader<T> {
    shared: Arc<Shared<T>>,
    index: usize,
    /// The value taken from the seed at registration, used until the reader's own triple
    /// buffer delivers something newer.
    seed: T,
    from_seed: bool,
    have_seq: u64,
    reported_seq: u64,
}

impl<T: Clone + Send> DataReader<T> {
    /// Looks at the latest value: its status and a reference to it (the type's default
    /// while the status is [`FlowStatus::NoData`]). Wait-free, never allocates.
    #[inline]
    pub fn read(&mut self) -> (FlowStatus, &T) {
        let s = &*self.shared;
        let triple = &s.readers[self.index];
        let idx = triple.acquire_latest();
        let seq = triple.with_slot(idx, |slot| slot.seq);
        if seq > self.have_seq {
            self.have_seq = seq;
            self.from_seed = false;
        }
        let status = if self.have_seq == 0 {
            FlowStatus::NoData
        } else if self.have_seq > self.reported_seq {
            self.reported_seq = self.have_seq;
            FlowStatus::NewData
        } else {
            FlowStatus::OldData
        };
        let value = if self.from_seed {
            &self.seed
        } else {
            // SAFETY: slot `idx` is this reader's own until its next `acquire_latest`, which
            // needs `&mut self` and so cannot happen while the returned borrow lives.
            s.readers[self.index].slots[usize::from(idx)].with(|p| unsafe { &(*p).value })
        };
        (status, value)
    }

    /// Orocos-style read: copies the latest value into `out` unless there is no data.
    #[inline]
    pub fn get(&mut self, out: &mut T) -> FlowStatus {
        let (status, value) = self.read();
        if status != FlowStatus::NoData {
            out.clone_from(value);
        }
        status
    }

    /// The latest value, if any was written.
    #[inline]
    pub fn latest(&mut self) -> Option<T> {
        match self.read() {
            (FlowStatus::NoData, _) => None,
            (_, v) => Some(v.clone()),
        }
    }

    /// Name of the object read.
    pub fn name(&self) -> &str {
        &self.shared.name
    }
}

impl<T> Drop for DataReader<T> {
    fn drop(&mut self) {
        self.shared
            .registered
            .fetch_and(!(1u64 << self.index), Ordering::SeqCst);
    }
}

#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    #[test]
    fn fixed_readers_refuse_late_registration_but_work() {
        let obj = DataObject::<u32>::with_fixed_readers("x", 2);
        let mut r = obj.reader().unwrap();
        let mut w = obj.writer().unwrap();
        w.set(5);
        assert_eq!(r.read(), (FlowStatus::NewData, &5));
        assert_eq!(
            obj.reader().err(),
            Some(DataObjectError::LateReader("x".into()))
        );
    }

    #[test]
    fn reports_no_new_old_data() {
        let obj = DataObject::<f64>::new("x", 4);
        let mut w = obj.writer().unwrap();
        let mut r = obj.reader().unwrap();
        assert_eq!(r.read().0, FlowStatus::NoData);
        w.set(1.5);
        assert_eq!(r.read(), (FlowStatus::NewData, &1.5));
        assert_eq!(r.read(), (FlowStatus::OldData, &1.5));
        w.set(2.0);
        w.set(3.0);
        let mut out = 0.0;
        assert_eq!(r.get(&mut out), FlowStatus::NewData);
        assert_eq!(out, 3.0, "latest complete set, skipping older ones");
        assert_eq!(obj.writes(), 2 + 1);
    }

    #[test]
    fn single_writer_is_enforced() {
        let obj = DataObject::<u32>::new("x", 1);
        let w = obj.writer().unwrap();
        assert_eq!(
            obj.writer().err(),
            Some(DataObjectError::WriterTaken("x".into()))
        );
        drop(w);
        assert!(obj.writer().is_ok());
    }

    #[test]
    fn reader_limit_and_slot_reuse() {
        let obj = DataObject::<u32>::new("x", 2);
        let a = obj.reader().unwrap();
        let _b = obj.reader().unwrap();
        assert!(matches!(
            obj.reader(),
            Err(DataObjectError::TooManyReaders { max: 2, .. })
        ));
        drop(a);
        assert_eq!(obj.readers(), 1);
        assert!(obj.reader().is_ok());
    }

    #[test]
    fn late_reader_sees_latest_value_then_updates() {
        let obj = DataObject::<u32>::new("x", 4);
        let mut w = obj.writer().unwrap();
        let mut early = obj.reader().unwrap();
        w.set(7);
        w.set(8);
        let mut late = obj.reader().unwrap();
        assert_eq!(late.read(), (FlowStatus::NewData, &8));
        assert_eq!(late.read(), (FlowStatus::OldData, &8));
        w.set(9);
        assert_eq!(late.read(), (FlowStatus::NewData, &9));
        assert_eq!(early.read(), (FlowStatus::NewData, &9));
    }

    #[test]
    fn reused_reader_slot_ignores_stale_values() {
        let obj = DataObject::<u32>::new("x", 1);
        let mut w = obj.writer().unwrap();
        let a = obj.reader().unwrap();
        w.set(1); // left unread in slot 0's triple buffer
        drop(a);
        w.set(2); // slot 0 unregistered: only the seed gets it
        let mut b = obj.reader().unwrap();
        assert_eq!(b.read(), (FlowStatus::NewData, &2));
        assert_eq!(b.read(), (FlowStatus::OldData, &2));
    }
}

#[cfg(all(test, loom))]
mod loom_tests {
    use super::*;

    /// A value whose halves must always match: a torn read would show different halves.
    #[derive(Clone, Default, Debug, PartialEq)]
    struct Pair(u64, u64);

    #[test]
    fn readers_never_see_torn_or_older_values() {
        loom::model(|| {
            let obj = DataObject::<Pair>::new("p", 2);
            let mut w = obj.writer().unwrap();
            let mut r1 = obj.reader().unwrap();
            let t = loom::thread::spawn(move || {
                for i in 1..=2 {
                    w.set(Pair(i, i));
                }
            });
            let mut last = 0;
            for _ in 0..2 {
                let (st, v) = r1.read();
                assert_eq!(v.0, v.1, "torn read");
                if st != FlowStatus::NoData {
                    assert!(v.0 >= last, "went back in time");
                    last = v.0;
                }
            }
            t.join().unwrap();
            assert_eq!(r1.read().1, &Pair(2, 2));
        });
    }

    #[test]
    fn reader_registering_during_writes_gets_latest() {
        loom::model(|| {
            let obj = DataObject::<u64>::new("p", 1);
            let mut w = obj.writer().unwrap();
            w.set(1);
            let t = loom::thread::spawn(move || {
                w.set(2);
            });
            let mut r = obj.reader().unwrap();
            t.join().unwrap();
            // Whatever the interleaving, once the write completed the new reader has it.
            assert_eq!(r.read().1, &2);
        });
    }
}
