//! Timing statistics: wake-up latency and execution time (min/avg/max, histogram, overruns)
//! recorded by the realtime thread without locks and read by anyone.
//!
//! Why plain relaxed loads and stores: each [`TimingStats`] has exactly one writer (the thread
//! that runs the measured code), so no read-modify-write is needed and recording costs a few
//! ordinary stores. A reader may see a snapshot in which, say, `count` is one ahead of `sum`;
//! for monitoring that is harmless and it never disturbs the writer.

use std::sync::atomic::{AtomicU64, Ordering};

/// A histogram with fixed-width buckets plus one overflow bucket. Single writer.
#[derive(Debug)]
pub struct Histogram {
    bucket_ns: u64,
    buckets: Box<[AtomicU64]>,
    overflow: AtomicU64,
}

impl Histogram {
    /// `buckets` buckets of `bucket_ns` each; samples beyond go to the overflow bucket.
    pub fn new(bucket_ns: u64, buckets: usize) -> Self {
        Self {
            bucket_ns: bucket_ns.max(1),
            buckets: (0..buckets.max(1)).map(|_| AtomicU64::new(0)).collect(),
            overflow: AtomicU64::new(0),
        }
    }

    #[inline]
    fn record(&self, ns: u64) {
        let i = (ns / self.bucket_ns) as usize;
        let b = self.buckets.get(i).unwrap_or(&self.overflow);
        b.store(b.load(Ordering::Relaxed) + 1, Ordering::Relaxed);
    }

    /// Bucket width in nanoseconds.
    pub fn bucket_ns(&self) -> u64 {
        self.bucket_ns
    }

    /// Counts per bucket (bucket `i` covers `[i*bucket_ns, (i+1)*bucket_ns)`).
    pub fn counts(&self) -> Vec<u64> {
        self.buckets
            .iter()
            .map(|b| b.load(Ordering::Relaxed))
            .collect()
    }

    /// Samples above the last bucket.
    pub fn overflow(&self) -> u64 {
        self.overflow.load(Ordering::Relaxed)
    }

    /// The value below which `q` (0..=1) of the samples lie, at bucket resolution (upper edge
    /// of the bucket). `None` without samples or when the quantile falls in the overflow.
    pub fn quantile_ns(&self, q: f64) -> Option<u64> {
        let counts = self.counts();
        let total: u64 = counts.iter().sum::<u64>() + self.overflow();
        if total == 0 {
            return None;
        }
        let target = ((total as f64) * q.clamp(0.0, 1.0)).ceil().max(1.0) as u64;
        let mut acc = 0;
        for (i, c) in counts.iter().enumerate() {
            acc += c;
            if acc >= target {
                return Some((i as u64 + 1) * self.bucket_ns);
            }
        }
        None
    }

    /// Number of samples at or above `ns` (bucket resolution: buckets starting at or above it).
    pub fn count_at_or_above_ns(&self, ns: u64) -> u64 {
        let first = ns.div_ceil(self.bucket_ns) as usize;
        self.buckets
            .iter()
            .skip(first)
            .map(|b| b.load(Ordering::Relaxed))
            .sum::<u64>()
            + self.overflow()
    }
}

/// min/avg/max and histogram of one quantity. Single writer.
#[derive(Debug)]
pub struct Series {
    count: AtomicU64,
    sum_ns: AtomicU64,
    min_ns: AtomicU64,
    max_ns: AtomicU64,
    histogram: Histogram,
}

/// A copy of a [`Series`]' summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct SeriesSummary {
    /// Samples recorded.
    pub count: u64,
    /// Smallest sample (0 without samples).
    pub min_ns: u64,
    /// Mean (0 without samples).
    pub avg_ns: u64,
    /// Largest sample.
    pub max_ns: u64,
}

impl Series {
    /// A series whose histogram has `buckets` buckets of `bucket_ns`.
    pub fn new(bucket_ns: u64, buckets: usize) -> Self {
        Self {
            count: AtomicU64::new(0),
            sum_ns: AtomicU64::new(0),
            min_ns: AtomicU64::new(u64::MAX),
            max_ns: AtomicU64::new(0),
            histogram: Histogram::new(bucket_ns, buckets),
        }
    }

    /// Records one sample. Call only from the series' single writer thread.
    #[inline]
    pub fn record(&self, ns: u64) {
        let r = Ordering::Relaxed;
        self.count.store(self.count.load(r) + 1, r);
        self.sum_ns.store(self.sum_ns.load(r).wrapping_add(ns), r);
        if ns < self.min_ns.load(r) {
            self.min_ns.store(ns, r);
        }
        if ns > self.max_ns.load(r) {
            self.max_ns.store(ns, r);
        }
        self.histogram.record(ns);
    }

    /// Summary of the samples so far.
    pub fn summary(&self) -> SeriesSummary {
        let r = Ordering::Relaxed;
        let count = self.count.load(r);
        if count == 0 {
            return SeriesSummary::default();
        }
        SeriesSummary {
            count,
            min_ns: self.min_ns.load(r),
            avg_ns: self.sum_ns.load(r) / count,
            max_ns: self.max_ns.load(r),
        }
    }

    /// The histogram.
    pub fn histogram(&self) -> &Histogram {
        &self.histogram
    }
}

/// Wake-up latency, execution time and overruns of a thread or a task.
#[derive(Debug)]
pub struct TimingStats {
    /// Time from the deadline the thread slept until to when it actually ran (threads only).
    pub wakeup: Series,
    /// Time spent executing one step.
    pub exec: Series,
    overruns: AtomicU64,
    consecutive: AtomicU64,
}

/// A copy of a [`TimingStats`]' summaries, for status reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct TimingSummary {
    /// Wake-up latency.
    pub wakeup: SeriesSummary,
    /// Execution time.
    pub exec: SeriesSummary,
    /// Steps that did not finish before the next deadline.
    pub overruns: u64,
}

impl TimingStats {
    /// Histograms of `buckets` buckets of `bucket_ns`.
    pub fn new(bucket_ns: u64, buckets: usize) -> Self {
        Self {
            wakeup: Series::new(bucket_ns, buckets),
            exec: Series::new(bucket_ns, buckets),
            overruns: AtomicU64::new(0),
            consecutive: AtomicU64::new(0),
        }
    }

    /// Default resolution for tasks: 1 µs buckets up to 2 ms.
    pub fn for_task() -> Self {
        Self::new(1_000, 2_000)
    }

    /// Records whether the last step overran; returns the number of consecutive overruns
    /// (0 when this step was on time). Single writer.
    #[inline]
    pub fn record_overrun(&self, overran: bool) -> u64 {
        let r = Ordering::Relaxed;
        if overran {
            self.overruns.store(self.overruns.load(r) + 1, r);
            let c = self.consecutive.load(r) + 1;
            self.consecutive.store(c, r);
            c
        } else {
            self.consecutive.store(0, r);
            0
        }
    }

    /// Total overruns.
    pub fn overruns(&self) -> u64 {
        self.overruns.load(Ordering::Relaxed)
    }

    /// Current run of consecutive overruns.
    pub fn consecutive_overruns(&self) -> u64 {
        self.consecutive.load(Ordering::Relaxed)
    }

    /// Summary copy.
    pub fn summary(&self) -> TimingSummary {
        TimingSummary {
            wakeup: self.wakeup.summary(),
            exec: self.exec.summary(),
            overruns: self.overruns(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_quantiles_and_tail_counts() {
        let s = Series::new(1_000, 100);
        for ns in [1_500, 2_500, 2_700, 50_000, 250_000] {
            s.record(ns);
        }
        let sum = s.summary();
        assert_eq!((sum.count, sum.min_ns, sum.max_ns), (5, 1_500, 250_000));
        assert_eq!(sum.avg_ns, (1_500 + 2_500 + 2_700 + 50_000 + 250_000) / 5);
        let h = s.histogram();
        assert_eq!(h.quantile_ns(0.5), Some(3_000));
        assert_eq!(h.quantile_ns(0.2), Some(2_000));
        assert_eq!(h.quantile_ns(1.0), None, "max is in the overflow bucket");
        assert_eq!(h.count_at_or_above_ns(50_000), 2);
        assert_eq!(h.overflow(), 1);
    }

    #[test]
    fn consecutive_overruns_reset_when_on_time() {
        let t = TimingStats::for_task();
        assert_eq!(t.record_overrun(true), 1);
        assert_eq!(t.record_overrun(true), 2);
        assert_eq!(t.record_overrun(false), 0);
        assert_eq!(t.record_overrun(true), 1);
        assert_eq!(t.overruns(), 3);
    }
}
