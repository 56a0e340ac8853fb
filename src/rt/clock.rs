//! Clocks: the monotonic system clock for real threads and a simulated clock for tests.
//!
//! Why a trait: a task does not know its thread ("what vs when"). The stepped activity reads a
//! [`SimClock`] that only moves when the test moves it, so N cycles run deterministically and
//! time-dependent logic (timeouts, completion conditions) is testable.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// A source of monotonic time in nanoseconds.
pub trait Clock: Send + Sync {
    /// Current time in nanoseconds from an arbitrary origin.
    fn now_ns(&self) -> u64;
}

/// `CLOCK_MONOTONIC`, the clock the periodic activity sleeps on.
#[derive(Debug, Clone, Copy, Default)]
pub struct MonotonicClock;

/// Reads `CLOCK_MONOTONIC` in nanoseconds (a vDSO call: no syscall, safe in a step).
#[inline]
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

impl Clock for MonotonicClock {
    #[inline]
    fn now_ns(&self) -> u64 {
        monotonic_ns()
    }
}

/// A clock that moves only when told to. Cloning shares the same time.
#[derive(Debug, Clone, Default)]
pub struct SimClock {
    now_ns: Arc<AtomicU64>,
}

impl SimClock {
    /// A clock at time `start_ns`.
    pub fn new(start_ns: u64) -> Self {
        Self {
            now_ns: Arc::new(AtomicU64::new(start_ns)),
        }
    }

    /// Moves time forward by `ns`.
    pub fn advance_ns(&self, ns: u64) {
        self.now_ns.fetch_add(ns, Ordering::AcqRel);
    }

    /// Sets the time (must not go backwards; ignored if it would).
    pub fn set_ns(&self, ns: u64) {
        self.now_ns.fetch_max(ns, Ordering::AcqRel);
    }
}

impl Clock for SimClock {
    fn now_ns(&self) -> u64 {
        self.now_ns.load(Ordering::Acquire)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sim_clock_moves_only_when_told_and_never_back() {
        let c = SimClock::new(10);
        let c2 = c.clone();
        c.advance_ns(5);
        assert_eq!(c2.now_ns(), 15);
        c.set_ns(3);
        assert_eq!(c.now_ns(), 15);
        let a = MonotonicClock.now_ns();
        assert!(MonotonicClock.now_ns() >= a);
    }
}
