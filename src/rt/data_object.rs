//! Data objects: the "latest value" connection of the data flow. One writer, many readers;
//! a read returns the latest complete write, never a torn value, and says whether it is new.
//!
//! # Design (why not a seqlock, why not Orocos' retry loop, why not a triple buffer per reader)
//! Both sides must be wait-free: a realtime reader must not spin while a preempted writer is
//! half-way through a write (a seqlock does exactly that), and Orocos' `DataObjectLockFree`
//! reader retries when the writer moves the read pointer under it. A triple buffer per reader
//! is wait-free but makes `set` copy the value once per reader, and a reader registered after
//! the last write needs a separate seeding path. This module implements Chen & Burns' wait-free
//! single-writer/multi-reader mechanism ("A fully asynchronous reader/writer mechanism for
//! multiprocessor real-time systems", 1997): for `N` readers there are `N + 2` value slots,
//! `latest` (the index of the last published slot) and one marker byte per reader entry,
//! `reading[i]`: `FREE` (not registered), `BUSY` (the reader is mid-acquire) or the index of the
//! slot the reader has pinned. `set` costs one copy whatever the number of readers.
//!
//! - Writer (`set`): one pass over the registered readers' markers. A pinned slot is taken.
//!   A reader caught `BUSY` is handed `latest` (completely written) by
//!   `compare_exchange(BUSY, latest)`; if that fails the reader has just pinned a slot itself,
//!   which the failed exchange returns, and that slot is taken. Then write value and sequence
//!   number into a slot that is neither `latest` nor taken (`N` readers take at most `N`, so of
//!   `N + 2` one is free) and publish it: `latest.store(slot)`.
//! - Reader (`read`): if `latest` is the slot it has pinned, nothing is new. Otherwise
//!   `reading[i].swap(BUSY)`, `l = latest.load()`, `compare_exchange(BUSY, l)`; if that fails the
//!   writer has handed it a slot, which it uses. Constant steps, no loop.
//! - A reader registering late claims a free entry (under a mutex `set` and `read` never take)
//!   and sets its bit in the `registered` mask; its first read is an ordinary acquire, so it
//!   gets the latest value with no seed. Sequence numbers in the slots (0: the initial default
//!   value, reported as no data) tell new from old data.
//!
//! Chen & Burns hand `BUSY` readers the new slot right after the `latest` store, in a second
//! pass over the markers. Handing them the then-latest slot in the next `set`'s one pass gives
//! the same guarantees (below; a reader is never handed a slot older than one it has returned,
//! since `latest` was stored before it went `BUSY`) for half the writer's work per reader.
//!
//! # Why the writer never writes a slot a reader is reading
//! Every access below is `SeqCst`, so they all fall in one total order, *S*. Set `k` loads the
//! `registered` mask and the markers after set `k - 1`'s `latest` store (program order). Take
//! set `k`, writing slot `s`, and a reader reading slot `s` after one acquire:
//! 1. If set `k` saw the reader's pin on `s`, or its failed exchange returned it, it skipped
//!    `s`; if it handed the reader `latest`, that is not `s`. If it saw a later marker, the
//!    reader had moved on: its read happens before the write (release/acquire through the
//!    marker).
//! 2. Otherwise set `k` read an older marker, or its mask load missed the reader's
//!    registration. Both precede the reader's `BUSY` swap in *S* and follow set `k - 1`'s
//!    `latest` store, so the reader's `latest` load returns set `k - 1`'s slot (which set `k`
//!    never writes: it is `latest`) or a newer one, whose write happens before that load.
//! 3. A slot a later set handed over was `latest` then: its writes happen before the reader's
//!    failed exchange reads it.
//!
//! Hence the writer must look at the markers only after its previous `latest` store, and must
//! take the slot a failed exchange returns: that slot may be older than `latest` (the reader
//! loaded `latest` before the previous store). `loom_tests` below model these races;
//! `sync::seqcst_order_for_loom` explains the fence loom needs to model `SeqCst` accesses.

use super::sync::{
    lock, seqcst_order_for_loom, Arc, AtomicBool, AtomicU64, AtomicU8, Mutex, Ordering, Padded,
    UnsafeCell,
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

/// Marker of an unregistered reader entry: pins nothing, the writer ignores it.
const FREE: u8 = 127;
/// Marker of a reader between its `swap(BUSY)` and its compare-exchange: pins nothing yet; the
/// writer may complete the acquire for it.
const BUSY: u8 = 126;
// Slot indices (< MAX_READERS + 2) never collide with the markers, and the writer's slot masks
// (`SlotMask`) can take a marker's bit without a range check: it lies above every slot.
const _: () = assert!(MAX_READERS + 2 <= BUSY as usize && FREE < 128);
const _: () = assert!(BUSY & 63 == 62 && FREE & 63 == 63);

/// The writer's set of taken slots: `u64` for objects of at most [`U64_SLOTS`] slots (a
/// one-instruction bit set per reader), `u128` for larger ones.
trait SlotMask: Copy {
    /// The bit of slot `r`; for a marker, a bit above every slot.
    fn bit(r: u8) -> Self;
    /// Union.
    fn or(self, other: Self) -> Self;
    /// The lowest index whose bit is clear.
    fn lowest_clear(self) -> u8;
}

/// Most slots a `u64` mask handles: bits 62 and 63 are the markers'.
const U64_SLOTS: usize = 62;

/// The same three operations for both mask widths.
macro_rules! slot_mask {
    ($t:ty, $bits:expr) => {
        impl SlotMask for $t {
            #[inline(always)]
            fn bit(r: u8) -> Self {
                1 << (r & ($bits - 1))
            }
            #[inline(always)]
            fn or(self, other: Self) -> Self {
                self | other
            }
            #[inline(always)]
            fn lowest_clear(self) -> u8 {
                (!self).trailing_zeros() as u8
            }
        }
    };
}

slot_mask!(u64, 64);
slot_mask!(u128, 128);

const _: () = assert!(MAX_READERS <= 64, "the registered mask is a u64");

/// One value slot: the value first and 64-byte aligned, so a cache-line-sized payload is
/// copied without split (line-crossing) loads and stores; its sequence number after it.
#[repr(C, align(64))]
struct Slot<T> {
    value: T,
    seq: u64,
}

/// What the writer writes on every `set` and every reader polls: one cache line pair.
struct Published {
    /// Index of the last published slot.
    latest: AtomicU8,
    /// Sequence number of the last `set` (inspection and writer hand-over only).
    last_seq: AtomicU64,
}

/// What readers write (on acquire, registration, drop) and the writer scans on every `set`:
/// all markers in one cache line, so the scan touches one line whatever the reader count.
struct ReaderTable {
    /// Bit `i` set: entry `i` is registered.
    registered: AtomicU64,
    /// Per entry: `FREE`, `BUSY` or the pinned slot index.
    reading: [AtomicU8; MAX_READERS],
}

struct Shared<T> {
    published: Padded<Published>,
    table: Padded<ReaderTable>,
    /// `max_readers + 2` slots.
    slots: Box<[UnsafeCell<Slot<T>>]>,
    max_readers: usize,
    name: String,
    /// Serialises reader registration (never taken by `set` or `read`).
    join: Mutex<()>,
    writer_taken: AtomicBool,
    /// Whether readers may register after the first write.
    late_readers: bool,
}

// SAFETY: values are moved in by the writer (T: Send) and several readers on different threads
// may hold `&T` to the same slot at once (T: Sync). The protocol of the module doc keeps the
// writer out of every slot a reader may be reading.
unsafe impl<T: Send + Sync> Sync for Shared<T> {}
// SAFETY: as above.
unsafe impl<T: Send + Sync> Send for Shared<T> {}

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
    /// [`MAX_READERS`]), registered at any time. Allocates all `max_readers + 2` slots now;
    /// `set` and `read` never allocate.
    pub fn new(name: &str, max_readers: usize) -> Self {
        Self::build(name, max_readers, true)
    }

    /// Like [`new`](Self::new), but readers can only register before the first `set`
    /// ([`DataObjectError::LateReader`] afterwards). It used to make `set` cheaper; since late
    /// readers cost nothing any more it is kept for API compatibility and as a wiring check
    /// for connections meant to be complete at configure time. Same speed as `new`.
    pub fn with_fixed_readers(name: &str, max_readers: usize) -> Self {
        Self::build(name, max_readers, false)
    }

    fn build(name: &str, max_readers: usize, late_readers: bool) -> Self {
        let max = max_readers.clamp(1, MAX_READERS);
        let slots = (0..max + 2)
            .map(|_| {
                UnsafeCell::new(Slot {
                    value: T::default(),
                    seq: 0,
                })
            })
            .collect();
        Self {
            shared: Arc::new(Shared {
                published: Padded(Published {
                    latest: AtomicU8::new(0),
                    last_seq: AtomicU64::new(0),
                }),
                table: Padded(ReaderTable {
                    registered: AtomicU64::new(0),
                    reading: std::array::from_fn(|_| AtomicU8::new(FREE)),
                }),
                slots,
                max_readers: max,
                name: name.to_owned(),
                join: Mutex::new(()),
                writer_taken: AtomicBool::new(false),
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
        let s = &*self.shared;
        // AcqRel: a previous writer's publishes (its `latest`, `last_seq`) happen before ours.
        if s.writer_taken.swap(true, Ordering::AcqRel) {
            return Err(DataObjectError::WriterTaken(s.name.clone()));
        }
        Ok(DataWriter {
            shared: self.shared.clone(),
            seq: s.published.last_seq.load(Ordering::Acquire),
            latest: s.published.latest.load(Ordering::SeqCst),
        })
    }

    /// Registers a new reader. It sees the latest value written so far (if any) as
    /// [`FlowStatus::NewData`] on its first read. Not for the realtime path (takes a mutex
    /// shared only with other registrations).
    pub fn reader(&self) -> Result<DataReader<T>, DataObjectError> {
        let s = &*self.shared;
        let _guard = lock(&s.join);
        if !s.late_readers && s.published.last_seq.load(Ordering::Acquire) > 0 {
            return Err(DataObjectError::LateReader(s.name.clone()));
        }
        let max = s.max_readers;
        let used = s.table.registered.load(Ordering::SeqCst);
        let Some(index) = (0..max).find(|i| used & (1u64 << i) == 0) else {
            return Err(DataObjectError::TooManyReaders {
                name: s.name.clone(),
                max,
            });
        };
        // The entry is FREE: its previous reader stored FREE before clearing its bit. Nothing
        // else to prepare: the first read acquires the latest slot like any other.
        s.table.registered.fetch_or(1u64 << index, Ordering::SeqCst);
        Ok(DataReader {
            shared: self.shared.clone(),
            index,
            pinned: FREE,
            seq: 0,
            reported_seq: 0,
        })
    }

    /// Number of completed `set`s so far.
    pub fn writes(&self) -> u64 {
        self.shared.published.last_seq.load(Ordering::Relaxed)
    }

    /// Number of registered readers.
    pub fn readers(&self) -> usize {
        self.shared
            .table
            .registered
            .load(Ordering::Relaxed)
            .count_ones() as usize
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
    /// Private copy of `latest` (only this writer stores it), saving a load per `set`.
    latest: u8,
}

impl<T: Clone + Send> DataWriter<T> {
    /// Publishes `value` to every reader. Wait-free and one copy whatever the number of
    /// readers: one pass over the registered readers' markers (one cache line; a
    /// compare-exchange only for a reader caught mid-acquire), the copy, one atomic store.
    /// Never blocks, never allocates.
    #[inline]
    pub fn set(&mut self, value: T) {
        let s = &*self.shared;
        self.seq += 1;
        let seq = self.seq;
        let latest = self.latest;
        let slot = if s.slots.len() <= U64_SLOTS {
            pick_slot::<u64>(&s.table, latest)
        } else {
            pick_slot::<u128>(&s.table, latest)
        };
        debug_assert!(usize::from(slot) < s.slots.len());
        // SAFETY: no reader can read `slot` until it is published below (module doc).
        s.slots[usize::from(slot)].with_mut(|p| unsafe { *p = Slot { value, seq } });
        s.published.latest.store(slot, Ordering::SeqCst);
        self.latest = slot;
        // The next `set`'s loads of the mask and the markers come after this store.
        seqcst_order_for_loom();
        s.published.last_seq.store(seq, Ordering::Release);
    }

    /// Name of the object written.
    pub fn name(&self) -> &str {
        &self.shared.name
    }
}

/// The writer's one pass over the registered readers' markers (module doc): every slot a
/// reader may read is taken (`latest`, each pinned slot), a reader caught BUSY is handed
/// `latest`. Returns the lowest slot not taken. The mask and the markers are loaded after the
/// previous `latest` store (program order, SeqCst).
#[inline(always)]
fn pick_slot<M: SlotMask>(table: &ReaderTable, latest: u8) -> u8 {
    let mut taken = M::bit(latest);
    let mut mask = table.registered.load(Ordering::SeqCst);
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let entry = &table.reading[i];
        let mut r = entry.load(Ordering::SeqCst);
        if r == BUSY {
            // On failure the reader has just pinned a slot itself: the exchange returns it.
            r = match entry.compare_exchange(BUSY, latest, Ordering::SeqCst, Ordering::SeqCst) {
                Ok(_) => latest,
                Err(pinned) => pinned,
            };
        }
        taken = taken.or(M::bit(r));
    }
    // At most `readers + 1` of the `readers + 2` slots are taken, so this is a slot.
    taken.lowest_clear()
}

impl<T> Drop for DataWriter<T> {
    fn drop(&mut self) {
        // The object may get a new writer (e.g. a task reconfigured); sequence numbers continue
        // from the last write so readers keep seeing them as new.
        self.shared.writer_taken.store(false, Ordering::Release);
    }
}

/// One reader of a data object. Readers share the slots but never disturb each other: each
/// has its own marker, and the writer works around all of them. Not `Clone` (make another
/// with [`DataObject::reader`]).
pub struct DataReader<T> {
    shared: Arc<Shared<T>>,
    index: usize,
    /// The slot this reader has pinned (`FREE` before its first read).
    pinned: u8,
    /// Sequence number of the pinned slot's value.
    seq: u64,
    reported_seq: u64,
}

impl<T: Clone + Send> DataReader<T> {
    /// Looks at the latest value: its status and a reference to it (the type's default
    /// while the status is [`FlowStatus::NoData`]). Wait-free, never allocates.
    #[inline]
    pub fn read(&mut self) -> (FlowStatus, &T) {
        let s = &*self.shared;
        if s.published.latest.load(Ordering::Acquire) != self.pinned {
            self.acquire();
        }
        let seq = self.seq;
        let status = if seq == 0 {
            FlowStatus::NoData
        } else if seq > self.reported_seq {
            self.reported_seq = seq;
            FlowStatus::NewData
        } else {
            FlowStatus::OldData
        };
        // SAFETY: the slot stays pinned (the writer skips it) until the next `acquire`, which
        // needs `&mut self` and so cannot happen while the returned borrow lives.
        let value = self.shared.slots[usize::from(self.pinned)].with(|p| unsafe { &(*p).value });
        (status, value)
    }

    /// Pins the latest slot (Chen & Burns' reader; module doc). No loop.
    #[inline]
    fn acquire(&mut self) {
        let s = &*self.shared;
        let entry = &s.table.reading[self.index];
        entry.swap(BUSY, Ordering::SeqCst);
        seqcst_order_for_loom();
        let latest = s.published.latest.load(Ordering::SeqCst);
        // On failure the writer pinned a newer slot for us (Acquire: its write is visible).
        let slot = match entry.compare_exchange(BUSY, latest, Ordering::SeqCst, Ordering::Acquire) {
            Ok(_) => latest,
            Err(pinned_by_writer) => pinned_by_writer,
        };
        self.pinned = slot;
        // SAFETY: pinned just above; the writer does not write it while it stays pinned.
        self.seq = s.slots[usize::from(slot)].with(|p| unsafe { (*p).seq });
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
        let t = &self.shared.table;
        // Unpin first (release: our reads happen before the writer reuses the slot), then
        // free the entry for a new registration.
        t.reading[self.index].store(FREE, Ordering::SeqCst);
        t.registered
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

    #[test]
    fn memory_is_readers_plus_two_slots() {
        let obj = DataObject::<u64>::new("x", 8);
        assert_eq!(obj.shared.slots.len(), 8 + 2);
        let capped = DataObject::<u64>::new("y", 1000);
        assert_eq!(capped.shared.slots.len(), MAX_READERS + 2);
    }

    /// Counts clones, to show that `set` copies nothing per reader.
    #[derive(Default, Debug, PartialEq)]
    struct Counted(u64);
    static CLONES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    impl Clone for Counted {
        fn clone(&self) -> Self {
            CLONES.fetch_add(1, Ordering::Relaxed);
            Counted(self.0)
        }
    }

    #[test]
    fn set_makes_no_copy_per_reader() {
        let obj = DataObject::<Counted>::new("x", 8);
        let mut w = obj.writer().unwrap();
        let mut readers: Vec<_> = (0..8).map(|_| obj.reader().unwrap()).collect();
        let before = CLONES.load(Ordering::Relaxed);
        for i in 1..=100 {
            w.set(Counted(i));
            for r in &mut readers {
                assert_eq!(r.read(), (FlowStatus::NewData, &Counted(i)));
            }
        }
        assert_eq!(
            CLONES.load(Ordering::Relaxed),
            before,
            "set moves, read borrows"
        );
    }

    #[test]
    fn a_pinned_value_survives_any_number_of_writes() {
        let obj = DataObject::<u64>::new("x", 3);
        let mut w = obj.writer().unwrap();
        let mut a = obj.reader().unwrap();
        let mut b = obj.reader().unwrap();
        let mut c = obj.reader().unwrap();
        w.set(1);
        let held_a = a.read().1;
        w.set(2);
        let held_b = b.read().1;
        w.set(3);
        let held_c = c.read().1;
        // Three pinned slots plus `latest` out of five: the writer cycles through the rest.
        for i in 4..100 {
            w.set(i);
        }
        assert_eq!((*held_a, *held_b, *held_c), (1, 2, 3));
        assert_eq!(a.read(), (FlowStatus::NewData, &99));
        assert_eq!(b.read(), (FlowStatus::NewData, &99));
    }

    #[test]
    fn every_reader_pinning_its_own_slot_leaves_the_writer_one() {
        // 60 readers: 62 slots, the largest object on the u64 mask; 61 and 64: the u128 mask,
        // with slots 62..=65 in use.
        for n in [60u64, 61, 64] {
            let obj = DataObject::<u64>::new("x", n as usize);
            let mut w = obj.writer().unwrap();
            let mut readers: Vec<_> = (0..n).map(|_| obj.reader().unwrap()).collect();
            let mut held = Vec::new();
            for (i, r) in readers.iter_mut().enumerate() {
                w.set(i as u64 + 1);
                held.push(r.read().1);
            }
            // n pinned slots plus `latest`: exactly one slot is free for each of these writes.
            for i in 0..3 * n {
                w.set(1000 + i);
            }
            assert!(
                held.iter().enumerate().all(|(i, v)| **v == i as u64 + 1),
                "n={n}"
            );
            for r in &mut readers {
                assert_eq!(r.read(), (FlowStatus::NewData, &(1000 + 3 * n - 1)));
            }
        }
    }

    #[test]
    fn many_readers_late_and_early_and_dropped() {
        let obj = DataObject::<u64>::new("x", MAX_READERS);
        let mut w = obj.writer().unwrap();
        let mut readers: Vec<_> = (0..MAX_READERS / 2)
            .map(|_| obj.reader().unwrap())
            .collect();
        for i in 1..=10 {
            w.set(i);
        }
        readers.truncate(5);
        readers.extend((0..MAX_READERS - 5).map(|_| obj.reader().unwrap()));
        assert_eq!(obj.readers(), MAX_READERS);
        for r in &mut readers {
            assert_eq!(r.read(), (FlowStatus::NewData, &10));
        }
        w.set(11);
        for r in &mut readers {
            assert_eq!(r.read(), (FlowStatus::NewData, &11));
            assert_eq!(r.read(), (FlowStatus::OldData, &11));
        }
    }

    #[test]
    fn a_new_writer_continues_the_sequence() {
        let obj = DataObject::<u32>::new("x", 2);
        let mut r = obj.reader().unwrap();
        let mut w = obj.writer().unwrap();
        w.set(1);
        assert_eq!(r.read(), (FlowStatus::NewData, &1));
        drop(w);
        let mut w = obj.writer().unwrap();
        w.set(1);
        assert_eq!(r.read(), (FlowStatus::NewData, &1), "same value, new write");
        assert_eq!(obj.writes(), 2);
        let mut late = obj.reader().unwrap();
        assert_eq!(late.read(), (FlowStatus::NewData, &1));
    }

    #[test]
    fn reader_before_any_write_gets_no_data_then_the_first_write() {
        let obj = DataObject::<u32>::new("x", 1);
        let mut r = obj.reader().unwrap();
        assert_eq!(r.read(), (FlowStatus::NoData, &0));
        assert_eq!(r.latest(), None);
        let mut w = obj.writer().unwrap();
        w.set(0);
        assert_eq!(
            r.read(),
            (FlowStatus::NewData, &0),
            "a written default is data"
        );
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

    /// Test-only: the pinned slot's value, read again through loom's tracked cell. Loom
    /// reports a write to the slot that is not ordered with this read.
    impl<T: Clone> DataReader<T> {
        fn pinned_value(&self) -> T {
            // SAFETY: same as `read`: the slot is pinned.
            self.shared.slots[usize::from(self.pinned)].with(|p| unsafe { (*p).value.clone() })
        }
    }

    /// One read: whole, not older than `last`; then still the same after whatever the writer
    /// did meanwhile. Returns the value's number.
    fn read_and_hold(r: &mut DataReader<Pair>, last: u64) -> u64 {
        let (st, v) = r.read();
        let v = v.clone();
        assert_eq!(v.0, v.1, "torn read");
        assert!(v.0 >= last, "went back in time");
        assert_eq!(st == FlowStatus::NoData, v.0 == 0);
        loom::thread::yield_now();
        assert_eq!(r.pinned_value(), v, "pinned slot rewritten");
        v.0
    }

    #[test]
    fn slot_reuse_reader_acquiring_while_the_writer_publishes_twice() {
        // One reader: three slots, so the second publish must reuse a slot; the reader's
        // acquire interleaves with both publishes in every possible way.
        loom::model(|| {
            let obj = DataObject::<Pair>::new("p", 1);
            let mut w = obj.writer().unwrap();
            let mut r = obj.reader().unwrap();
            let t = loom::thread::spawn(move || {
                w.set(Pair(1, 1));
                w.set(Pair(2, 2));
            });
            let first = read_and_hold(&mut r, 0);
            read_and_hold(&mut r, first);
            t.join().unwrap();
            assert_eq!(r.read().1, &Pair(2, 2));
        });
    }

    #[test]
    fn late_reader_registering_during_writes_gets_the_latest() {
        // Registration races with two publishes (the second may reuse the slot the new
        // reader loaded as `latest`): case 2 of the module doc's argument.
        loom::model(|| {
            let obj = DataObject::<Pair>::new("p", 1);
            let mut w = obj.writer().unwrap();
            let t = loom::thread::spawn(move || {
                w.set(Pair(1, 1));
                w.set(Pair(2, 2));
            });
            let mut r = obj.reader().unwrap();
            read_and_hold(&mut r, 0);
            t.join().unwrap();
            let (st, v) = r.read();
            assert_eq!(v, &Pair(2, 2));
            assert_ne!(st, FlowStatus::NoData);
        });
    }

    #[test]
    fn two_readers_and_a_writer() {
        // Two readers pin up to two of the four slots; the writer must pick around both.
        // Unbounded exploration: about 30 s in release.
        loom::model(|| {
            let obj = DataObject::<Pair>::new("p", 2);
            let mut w = obj.writer().unwrap();
            let mut r1 = obj.reader().unwrap();
            let mut r2 = obj.reader().unwrap();
            let t = loom::thread::spawn(move || {
                w.set(Pair(1, 1));
                w.set(Pair(2, 2));
            });
            let t2 = loom::thread::spawn(move || {
                read_and_hold(&mut r2, 0);
                r2
            });
            read_and_hold(&mut r1, 0);
            t.join().unwrap();
            let mut r2 = t2.join().unwrap();
            assert_eq!(r1.read().1, &Pair(2, 2));
            assert_eq!(r2.read().1, &Pair(2, 2));
        });
    }
}
