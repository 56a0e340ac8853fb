//! Round-trip statistics of a link's transactions: a histogram of 1 µs bins up to 20 ms
//! (atomics: recorded by the poller without blocking, read by anyone). The benchmark
//! records its bare `tokio-modbus` reference loop into the same type, so that both sides are
//! binned and summarised by the same code.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Width of a [`TxStats`] bin.
pub const TX_BIN_US: u64 = 1;
/// Bins of a [`TxStats`]; the last one also holds every longer round trip.
const BINS: usize = 20_000;

/// A histogram of transaction round trips.
#[derive(Debug)]
pub struct TxStats {
    bins: Box<[AtomicU64]>,
}

impl Default for TxStats {
    fn default() -> Self {
        TxStats {
            bins: (0..BINS).map(|_| AtomicU64::new(0)).collect(),
        }
    }
}

impl TxStats {
    /// Records one round trip.
    pub fn record(&self, d: Duration) {
        let i = usize::try_from(d.as_micros() / u128::from(TX_BIN_US)).unwrap_or(usize::MAX);
        self.bins[i.min(BINS - 1)].fetch_add(1, Ordering::Relaxed);
    }

    /// The bins' counts now (subtract two snapshots for a window).
    pub fn snapshot(&self) -> Vec<u64> {
        self.bins
            .iter()
            .map(|b| b.load(Ordering::Relaxed))
            .collect()
    }

    /// Transactions recorded.
    pub fn count(&self) -> u64 {
        self.snapshot().iter().sum()
    }

    /// The `p` quantile (0..=1) of every round trip recorded, in µs.
    pub fn quantile_us(&self, p: f64) -> u64 {
        quantile_us(&self.snapshot(), p)
    }
}

/// The `p` quantile (0..=1) of a histogram of [`TxStats`] bins, in µs: the upper edge of the
/// bin where the quantile falls; 0 for an empty histogram.
pub fn quantile_us(bins: &[u64], p: f64) -> u64 {
    let n: u64 = bins.iter().sum();
    if n == 0 {
        return 0;
    }
    let want = (((n as f64) * p).ceil() as u64).max(1);
    let mut seen = 0;
    for (i, b) in bins.iter().enumerate() {
        seen += b;
        if seen >= want {
            return (i as u64 + 1) * TX_BIN_US;
        }
    }
    bins.len() as u64 * TX_BIN_US
}

/// `after - before`, bin by bin: the histogram of a window.
pub fn window(before: &[u64], after: &[u64]) -> Vec<u64> {
    after
        .iter()
        .zip(before)
        .map(|(a, b)| a.saturating_sub(*b))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_upper_bin_edges_of_the_window() {
        let s = TxStats::default();
        let before = s.snapshot();
        for us in [3, 3, 3, 10, 50_000] {
            s.record(Duration::from_micros(us));
        }
        let w = window(&before, &s.snapshot());
        assert_eq!(w.iter().sum::<u64>(), 5);
        assert_eq!(quantile_us(&w, 0.5), 4);
        assert_eq!(quantile_us(&w, 0.8), 11);
        assert_eq!(
            quantile_us(&w, 1.0),
            20_000,
            "overflow lands in the last bin"
        );
        assert_eq!(quantile_us(&[0; 4], 0.5), 0);
        assert_eq!(s.count(), 5);
    }
}
