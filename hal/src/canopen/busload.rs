//! Bus-load budget of the cyclic traffic (SYNC + PDOs) and the check that refuses a
//! configuration the bus cannot carry.
//!
//! # Formula
//!
//! A classic CAN data frame with an 11-bit identifier and `s` data bytes has
//! `34 + 8s` bits that are subject to bit stuffing (SOF 1, identifier 11, RTR 1, IDE 1,
//! r0 1, DLC 4, data 8s, CRC 15) and 13 that are not (CRC delimiter 1, ACK slot and
//! delimiter 2, end of frame 7, intermission 3). The transmitter inserts a stuff bit after
//! five equal bits; the worst case (every stuff bit itself starts a new run of five) adds
//! `⌊(34 + 8s − 1) / 4⌋` bits (Davis, Burns, Bril, Lukkien: "Controller Area Network (CAN)
//! schedulability analysis: refuted, revisited and revised", 2007). So
//!
//! ```text
//! bits(s) = 8s + 47 + ⌊(34 + 8s − 1) / 4⌋        // 55 for SYNC (s = 0), 135 for s = 8
//! load    = (bits(sync) + N · Σ bits(pdo of one drive)) · f_servo / bitrate
//! ```
//!
//! The budget uses the worst case on purpose: the real stuffing depends on the data, and
//! a servo bus that fits only with lucky data is a bus that misses SYNCs on a bad day.
//! Other traffic (heartbeats, EMCY, SDO) is sporadic and is what the margin under 100 % is
//! for.

use crate::error::{Error, ErrorKind};
use core::fmt::{self, Write as _};

/// Default limit: 80 % of the bitrate for the cyclic traffic.
pub const DEFAULT_LIMIT: f64 = 0.80;

/// The servo rates suggested when a configuration does not fit, highest first.
pub const SUGGESTED_RATES_HZ: [u32; 8] = [4000, 2000, 1000, 500, 250, 200, 100, 50];

/// Worst-case length in bits of a classic CAN data frame with an 11-bit identifier and
/// `data_len` data bytes (see the module doc for the formula).
pub fn frame_bits(data_len: usize) -> u64 {
    // Cannot truncate: data_len <= 8 for a classic frame; larger values are clamped.
    let s = data_len.min(8) as u64;
    let stuffable = 34 + 8 * s;
    stuffable + 13 + (stuffable - 1) / 4
}

/// The cyclic traffic of one servo cycle: SYNC plus the PDOs of each drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CycleTraffic {
    /// SYNC data length (0, or 1 with counter).
    pub sync_len: usize,
    /// Data length of every PDO one drive exchanges per cycle (RPDOs and TPDOs).
    pub pdo_lens: Vec<usize>,
}

impl CycleTraffic {
    /// The default CSP layout ([`CspLayout`](super::pdo::CspLayout)): 6-byte RPDO1 and
    /// 6-byte TPDO1, plus the 5-byte velocity TPDO2 when `with_velocity`; SYNC without
    /// counter.
    pub fn csp_default(with_velocity: bool) -> CycleTraffic {
        let mut pdo_lens = vec![6, 6];
        if with_velocity {
            pdo_lens.push(5);
        }
        CycleTraffic {
            sync_len: 0,
            pdo_lens,
        }
    }

    /// The traffic of drives configured with `layout` (every PDO of it travels each
    /// cycle) and SYNC from `sync`: what the configuration check must budget.
    pub fn from_layout(
        layout: &super::pdo::CspLayout,
        sync: &super::sync::SyncProducer,
    ) -> CycleTraffic {
        CycleTraffic {
            sync_len: sync.data_len(),
            pdo_lens: layout.pdos().map(|p| p.mapping.data_len()).collect(),
        }
    }

    /// Bits on the wire per cycle for `drives` drives.
    pub fn bits_per_cycle(&self, drives: usize) -> u64 {
        let per_drive: u64 = self.pdo_lens.iter().map(|&l| frame_bits(l)).sum();
        frame_bits(self.sync_len) + per_drive * drives as u64
    }

    /// The load (fraction of the bitrate) of `drives` drives at `rate_hz` on `bitrate`.
    pub fn load(&self, drives: usize, rate_hz: u32, bitrate: u32) -> f64 {
        self.bits_per_cycle(drives) as f64 * f64::from(rate_hz) / f64::from(bitrate.max(1))
    }

    /// The most drives that fit under `limit` (0 when not even SYNC alone fits).
    pub fn max_drives(&self, rate_hz: u32, bitrate: u32, limit: f64) -> usize {
        let budget = limit * f64::from(bitrate) / f64::from(rate_hz.max(1));
        let per_drive: u64 = self.pdo_lens.iter().map(|&l| frame_bits(l)).sum();
        let left = budget - frame_bits(self.sync_len) as f64;
        if left < 0.0 || per_drive == 0 {
            return 0;
        }
        // Cannot truncate meaningfully: a bus holds far fewer than usize::MAX drives.
        (left / per_drive as f64).floor() as usize
    }

    /// Checks a configuration against `limit`; the error says by how much it is over and
    /// what would fit.
    pub fn check(
        &self,
        drives: usize,
        rate_hz: u32,
        bitrate: u32,
        limit: f64,
    ) -> Result<f64, BusLoadError> {
        if bitrate == 0 || rate_hz == 0 || !(limit > 0.0 && limit <= 1.0) {
            return Err(BusLoadError::InvalidInput {
                bitrate,
                rate_hz,
                limit_pct: limit * 100.0,
            });
        }
        let load = self.load(drives, rate_hz, bitrate);
        if load <= limit {
            return Ok(load);
        }
        let slower = SUGGESTED_RATES_HZ
            .iter()
            .copied()
            .find(|&r| r < rate_hz && self.load(drives, r, bitrate) <= limit);
        Err(BusLoadError::OverBudget {
            drives,
            rate_hz,
            bitrate,
            load_pct: load * 100.0,
            limit_pct: limit * 100.0,
            max_drives: self.max_drives(rate_hz, bitrate, limit),
            slower_rate_hz: slower,
        })
    }

    /// A text table of the load for 1..=`max_drives` drives at each rate and bitrate,
    /// computed by the same code as [`check`](CycleTraffic::check); entries over `limit`
    /// are marked with `!`.
    pub fn table(
        &self,
        max_drives: usize,
        rates_hz: &[u32],
        bitrates: &[u32],
        limit: f64,
    ) -> String {
        let mut s = String::new();
        let _ = write!(s, "{:<12}{:>9}", "bitrate", "rate");
        for n in 1..=max_drives {
            let _ = write!(s, "{:>8}", format!("{n} dr"));
        }
        s.push('\n');
        for &b in bitrates {
            for &r in rates_hz {
                let _ = write!(
                    s,
                    "{:<12}{:>9}",
                    Bitrate(b).to_string(),
                    Rate(r).to_string()
                );
                for n in 1..=max_drives {
                    let load = self.load(n, r, b);
                    let mark = if load > limit { "!" } else { " " };
                    let _ = write!(s, "{:>7.1}{mark}", load * 100.0);
                }
                s.push('\n');
            }
        }
        let _ = writeln!(
            s,
            "load in % of the bitrate, worst-case bit stuffing; ! = over the {:.0} % limit",
            limit * 100.0
        );
        s
    }
}

struct Bitrate(u32);

impl fmt::Display for Bitrate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0;
        if b >= 1_000_000 && b.is_multiple_of(1_000_000) {
            write!(f, "{} Mbit/s", b / 1_000_000)
        } else if b >= 1000 && b.is_multiple_of(1000) {
            write!(f, "{} kbit/s", b / 1000)
        } else {
            write!(f, "{b} bit/s")
        }
    }
}

struct Rate(u32);

impl fmt::Display for Rate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = self.0;
        if r >= 1000 && r.is_multiple_of(1000) {
            write!(f, "{} kHz", r / 1000)
        } else {
            write!(f, "{r} Hz")
        }
    }
}

/// Why a bus configuration is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BusLoadError {
    /// The cyclic traffic exceeds the limit.
    #[error(
        "{drives} drives at {rate} need {need:.0} % of {rate_bits} (limit {limit_pct:.0} %, {over:.0} points over); {fit}",
        rate = Rate(*.rate_hz),
        rate_bits = Bitrate(*.bitrate),
        // Rounded up: the message must never understate the load.
        need = .load_pct.ceil(),
        over = (.load_pct - .limit_pct).ceil(),
        fit = fit_hint(*.max_drives, *.slower_rate_hz)
    )]
    OverBudget {
        /// Drives configured.
        drives: usize,
        /// Servo rate.
        rate_hz: u32,
        /// Bus bitrate.
        bitrate: u32,
        /// Load in percent.
        load_pct: f64,
        /// The limit in percent.
        limit_pct: f64,
        /// Most drives that fit at this rate.
        max_drives: usize,
        /// Highest suggested slower rate at which all drives fit.
        slower_rate_hz: Option<u32>,
    },
    /// Zero bitrate or rate, or a limit outside (0, 100] %.
    #[error("bus load: bitrate {bitrate} bit/s, servo rate {rate_hz} Hz and limit {limit_pct} % must be positive (limit at most 100 %)")]
    InvalidInput {
        /// Bus bitrate.
        bitrate: u32,
        /// Servo rate.
        rate_hz: u32,
        /// The limit in percent.
        limit_pct: f64,
    },
}

fn fit_hint(max_drives: usize, slower: Option<u32>) -> String {
    let drives = match max_drives {
        0 => "not even one drive fits".to_string(),
        1 => "at most 1 fits".to_string(),
        n => format!("at most {n} fit"),
    };
    match slower {
        Some(r) => format!("{drives}, or use {}", Rate(r)),
        None => format!("{drives}, and no servo rate down to 50 Hz fits them all"),
    }
}

impl Error for BusLoadError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::InvalidArgument
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lengths_with_worst_case_stuffing() {
        assert_eq!(frame_bits(0), 55);
        assert_eq!(frame_bits(1), 65);
        assert_eq!(frame_bits(6), 115);
        assert_eq!(frame_bits(8), 135);
        assert_eq!(frame_bits(9), 135, "clamped to classic CAN");
    }

    #[test]
    fn load_of_the_default_layout() {
        let t = CycleTraffic::csp_default(false);
        assert_eq!(t.bits_per_cycle(1), 55 + 230);
        assert!((t.load(3, 1000, 1_000_000) - 0.745).abs() < 1e-9);
        assert_eq!(t.max_drives(1000, 1_000_000, DEFAULT_LIMIT), 3);
        assert_eq!(t.max_drives(250, 1_000_000, DEFAULT_LIMIT), 13);
        let v = CycleTraffic::csp_default(true);
        assert_eq!(v.bits_per_cycle(1), 55 + 335);
    }

    #[test]
    fn traffic_follows_the_configured_layout() {
        use crate::canopen::{pdo::CspLayout, sync::SyncProducer, NodeId};
        let l = CspLayout::new(NodeId::new(1).unwrap(), true).unwrap();
        let t = CycleTraffic::from_layout(&l, &SyncProducer::with_counter(10));
        assert_eq!(
            t,
            CycleTraffic {
                sync_len: 1,
                pdo_lens: vec![6, 6, 5]
            }
        );
        let l = CspLayout::new(NodeId::new(1).unwrap(), false).unwrap();
        assert_eq!(
            CycleTraffic::from_layout(&l, &SyncProducer::new()),
            CycleTraffic::csp_default(false)
        );
    }

    #[test]
    fn a_fitting_configuration_passes() {
        let t = CycleTraffic::csp_default(false);
        let load = t.check(3, 1000, 1_000_000, DEFAULT_LIMIT).unwrap();
        assert!(load < 0.8);
    }

    #[test]
    fn over_budget_says_by_how_much_and_what_fits() {
        let t = CycleTraffic::csp_default(false);
        let e = t.check(7, 1000, 1_000_000, DEFAULT_LIMIT).unwrap_err();
        assert_eq!(
            e.to_string(),
            "7 drives at 1 kHz need 167 % of 1 Mbit/s (limit 80 %, 87 points over); at most 3 fit, or use 250 Hz"
        );
        assert_eq!(e.kind(), ErrorKind::InvalidArgument);
        let e = t.check(3, 2000, 500_000, DEFAULT_LIMIT).unwrap_err();
        assert!(
            e.to_string()
                .ends_with("not even one drive fits, or use 500 Hz"),
            "{e}"
        );
        let e = t.check(200, 1000, 125_000, DEFAULT_LIMIT).unwrap_err();
        assert!(
            e.to_string()
                .ends_with("no servo rate down to 50 Hz fits them all"),
            "{e}"
        );
    }

    #[test]
    fn invalid_inputs_are_refused() {
        let t = CycleTraffic::csp_default(false);
        assert!(matches!(
            t.check(1, 0, 1_000_000, 0.8),
            Err(BusLoadError::InvalidInput { .. })
        ));
        assert!(t.check(1, 1000, 0, 0.8).is_err());
        assert!(t.check(1, 1000, 1_000_000, 1.5).is_err());
    }

    #[test]
    fn table_for_1_to_8_drives() {
        let t = CycleTraffic::csp_default(false);
        let table = t.table(
            8,
            &[250, 500, 1000, 2000],
            &[1_000_000, 500_000],
            DEFAULT_LIMIT,
        );
        println!("{table}");
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 1 + 8 + 1);
        assert!(
            lines[3].starts_with("1 Mbit/s        1 kHz"),
            "{}",
            lines[3]
        );
        // 1 drive at 1 kHz on 1 Mbit/s: 285 bits per ms.
        assert!(lines[3].contains("   28.5 "), "{}", lines[3]);
        assert!(lines[3].contains("  166.5!"), "7 drives: {}", lines[3]);
    }
}
