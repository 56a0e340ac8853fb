//! A tiny seeded generator (SplitMix64) for the simulated world and camera: the same seed
//! gives the same object sequence and processing times on every machine, so tests can check
//! the sorted counts against the sequence. Not for anything but simulation.

/// SplitMix64 (Steele, Lea, Flood 2014): one 64-bit state, full period, good enough mixing
/// for picking object kinds and jitter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A value in `0..n` (`n > 0`; slightly biased for huge `n`, irrelevant here).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence_other_seed_other_sequence() {
        let (mut a, mut b, mut c) = (SplitMix64::new(7), SplitMix64::new(7), SplitMix64::new(8));
        let sa: Vec<u64> = (0..8).map(|_| a.below(3)).collect();
        let sb: Vec<u64> = (0..8).map(|_| b.below(3)).collect();
        let sc: Vec<u64> = (0..8).map(|_| c.below(3)).collect();
        assert_eq!(sa, sb);
        assert_ne!(sa, sc);
        assert!(sa.iter().all(|v| *v < 3));
    }
}
