//! The feeder: pushes a job's items into the segment queue from an ordinary thread, waiting
//! while the queue is full. The realtime side never waits for it.
//!
//! Why the wait follows the servo thread and not a fixed wall-clock sleep: room in the queue
//! appears only as the interpolator consumes items, one servo cycle at a time, and a servo
//! cycle lasts a period of wall time only on the real clock. On a simulated clock the
//! machine runs as fast as the host allows (hundreds of cycles per millisecond unpaced): a
//! feeder napping 2 ms of wall time at each full queue let a fast-consuming job run the
//! queue dry and stand still between refills, so the job took as long as its refills in
//! wall time, not as long as the simulation. The feeder therefore naps about one servo
//! cycle of the runtime's clock, as measured from the servo thread's cycle counter.
//!
//! Why a job starts only once its queue is primed ([`Primer`]): a move is several queue
//! items (its acceleration, cruise and braking pieces). If the interpolator took the first
//! piece before the freshly spawned feeder had pushed the next, it ran dry at speed: an
//! abrupt stop, then a velocity step when the rest arrived. On the unpaced simulated clock
//! (hundreds of cycles per millisecond) a feeder descheduled for a millisecond on a loaded
//! host was enough to trip the following-error limit on a job's first rapid.

use super::servo::QueueItem;
use crate::motion::Item;
use crate::rt::activity::ThreadInfo;
use crate::rt::prelude::BufferWriter;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Shortest nap while waiting for room: below this a sleep costs more than it saves.
const MIN_NAP: Duration = Duration::from_micros(20);
/// Longest nap: twice a real 1 kHz servo period, what the feeder used to sleep.
const MAX_NAP: Duration = Duration::from_millis(2);

/// What the feeder tells the thread that starts its job: the queue is primed (`Ok`), or the
/// job could not be planned (`Err`, the reason). Sent at most once.
pub(crate) type PrimeNews = Result<(), String>;

/// The feeder's side of the start hand-shake: signals, once, that the queue holds all of the
/// job's first batch or is full. A feeder that ends without signalling (cancelled) drops it,
/// which the starter sees as a disconnected channel. Clones share the one signal.
#[derive(Clone)]
pub(crate) struct Primer(Arc<Mutex<Option<SyncSender<PrimeNews>>>>);

impl Primer {
    /// A primer and the receiver the starter waits on.
    pub(crate) fn new() -> (Primer, Receiver<PrimeNews>) {
        let (tx, rx) = sync_channel(1);
        (Primer(Arc::new(Mutex::new(Some(tx)))), rx)
    }

    /// A primer nobody waits on.
    #[cfg(test)]
    pub(crate) fn none() -> Primer {
        Primer(Arc::new(Mutex::new(None)))
    }

    fn take(&self) -> Option<SyncSender<PrimeNews>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).take()
    }

    /// The queue is primed (no-op after the first time).
    pub(crate) fn primed(&self) {
        if let Some(tx) = self.take() {
            let _ = tx.send(Ok(()));
        }
    }

    /// The job failed before its queue was primed: tells the starter, which reports `why`
    /// instead of starting. False if the starter was already told the queue is primed (the
    /// job runs: the caller ends it).
    pub(crate) fn failed(&self, why: &str) -> bool {
        match self.take() {
            Some(tx) => {
                let _ = tx.send(Err(why.to_string()));
                true
            }
            None => false,
        }
    }
}

/// Pushes a job's items into the segment queue, waiting while it is full, until done or
/// cancelled (then false). Signals `primer` when all of `items` are queued or the queue is
/// full, whichever comes first.
pub(crate) fn feed(
    queue: &BufferWriter<QueueItem>,
    items: &[Item],
    job: u32,
    cancel: &AtomicBool,
    servo: &ThreadInfo,
    primer: &Primer,
) -> bool {
    let mut clock = ServoClock::new(servo);
    for &item in items {
        let mut q = QueueItem { job, item };
        loop {
            if cancel.load(Ordering::Acquire) {
                return false;
            }
            match queue.try_push(q) {
                Ok(()) => break,
                Err(back) => {
                    q = back;
                    primer.primed();
                    clock.nap();
                }
            }
        }
    }
    primer.primed();
    true
}

/// The servo thread's pace as seen from an ordinary thread: wall time per servo cycle,
/// measured from its cycle counter.
struct ServoClock<'a> {
    servo: &'a ThreadInfo,
    seen: (Instant, u64),
    nap: Duration,
}

impl<'a> ServoClock<'a> {
    fn new(servo: &'a ThreadInfo) -> Self {
        ServoClock {
            servo,
            seen: (Instant::now(), Self::cycles(servo)),
            nap: MIN_NAP,
        }
    }

    fn cycles(servo: &ThreadInfo) -> u64 {
        servo.stats.wakeup.summary().count
    }

    /// Sleeps about one servo cycle: the wall time a cycle took since the last nap that saw
    /// cycles pass (between [`MIN_NAP`] and [`MAX_NAP`]); twice as long as the last nap when
    /// no cycle passed (a stopped or stalled servo thread is not polled hot).
    fn nap(&mut self) {
        std::thread::sleep(self.nap);
        let (now, count) = (Instant::now(), Self::cycles(self.servo));
        let (then, before) = self.seen;
        let passed = count.saturating_sub(before);
        self.nap = if passed == 0 {
            self.nap * 2
        } else {
            let per_cycle = now.duration_since(then) / u32::try_from(passed).unwrap_or(u32::MAX);
            self.seen = (now, count);
            per_cycle
        }
        .clamp(MIN_NAP, MAX_NAP);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::{AuxItem, AuxKind};
    use crate::rt::activity::ThreadSpec;
    use crate::rt::buffer::{buffer, FullPolicy};
    use crate::rt::stats::TimingStats;
    use std::sync::mpsc::TryRecvError;

    fn items(n: u32) -> Vec<Item> {
        (0..n)
            .map(|line| {
                Item::Aux(AuxItem {
                    kind: AuxKind::Flood(true),
                    line,
                })
            })
            .collect()
    }

    fn servo() -> ThreadInfo {
        let spec = ThreadSpec {
            name: "servo".into(),
            priority: 80,
            period_ns: 1_000_000,
            cpu: None,
        };
        ThreadInfo::new(spec, TimingStats::new(1000, 10))
    }

    #[test]
    fn a_job_that_fits_is_primed_only_once_all_of_it_is_queued() {
        let (w, mut r) = buffer::<QueueItem>(16, FullPolicy::DropNewest);
        let (primer, primed) = Primer::new();
        let (cancel, servo) = (AtomicBool::new(false), servo());
        let job = items(10);
        assert_eq!(primed.try_recv(), Err(TryRecvError::Empty));
        assert!(feed(&w, &job[..4], 7, &cancel, &servo, &primer));
        // A first batch primes the queue; the second says nothing more.
        assert_eq!(primed.try_recv(), Ok(Ok(())));
        assert!(feed(&w, &job[4..], 7, &cancel, &servo, &primer));
        assert!(primed.try_recv().is_err());
        let mut n = 0;
        while let Some(q) = r.pop() {
            assert_eq!((q.job, q.item), (7, job[n]));
            n += 1;
        }
        assert_eq!(n, 10);
        // Too late to fail the start: the job runs, and whoever ends it reports the error.
        assert!(!primer.failed("late"));
    }

    #[test]
    fn a_job_larger_than_the_queue_is_primed_when_the_queue_is_full() {
        let (w, mut r) = buffer::<QueueItem>(8, FullPolicy::DropNewest);
        let capacity = r.capacity();
        let (primer, primed) = Primer::new();
        let (cancel, servo) = (AtomicBool::new(false), servo());
        let job = items(100);
        std::thread::scope(|s| {
            let feeder = s.spawn(|| feed(&w, &job, 1, &cancel, &servo, &primer));
            assert_eq!(primed.recv(), Ok(Ok(())));
            // Primed while the feeder waits for room: the queue is full.
            assert_eq!(r.len(), capacity);
            let mut n = 0;
            while n < job.len() {
                match r.pop() {
                    Some(q) => {
                        assert_eq!(q.item, job[n]);
                        n += 1;
                    }
                    None => std::thread::yield_now(),
                }
            }
            assert!(feeder.join().unwrap_or(false));
        });
    }

    #[test]
    fn a_job_that_fails_before_its_queue_is_primed_tells_the_starter_why() {
        let (primer, primed) = Primer::new();
        let clone = primer.clone();
        assert!(clone.failed("line 3: no such tool"));
        assert_eq!(primed.try_recv(), Ok(Err("line 3: no such tool".into())));
        assert!(!primer.failed("again"));
        primer.primed();
        assert!(primed.try_recv().is_err());
    }

    #[test]
    fn a_feeder_that_is_cancelled_never_primes_and_the_starter_sees_it_gone() {
        let (w, _r) = buffer::<QueueItem>(4, FullPolicy::DropNewest);
        let (primer, primed) = Primer::new();
        let (cancel, servo) = (AtomicBool::new(true), servo());
        assert!(!feed(&w, &items(3), 1, &cancel, &servo, &primer));
        drop(primer);
        assert_eq!(primed.try_recv(), Err(TryRecvError::Disconnected));
    }
}
