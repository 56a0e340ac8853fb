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

use super::servo::QueueItem;
use crate::motion::Item;
use crate::rt::activity::ThreadInfo;
use crate::rt::prelude::BufferWriter;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Shortest nap while waiting for room: below this a sleep costs more than it saves.
const MIN_NAP: Duration = Duration::from_micros(20);
/// Longest nap: twice a real 1 kHz servo period, what the feeder used to sleep.
const MAX_NAP: Duration = Duration::from_millis(2);

/// Pushes a job's items into the segment queue, waiting while it is full, until done or
/// cancelled (then false).
pub(crate) fn feed(
    queue: &BufferWriter<QueueItem>,
    items: &[Item],
    job: u32,
    cancel: &AtomicBool,
    servo: &ThreadInfo,
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
                    clock.nap();
                }
            }
        }
    }
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
