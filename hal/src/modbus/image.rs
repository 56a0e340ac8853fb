//! The I/O image: the data object between a link's poller (non-realtime) and the machine's
//! I/O task (realtime).
//!
//! One block of atomics per device, allocated once. The poller publishes every input with
//! a timestamp and a quality; the realtime side only loads them. Outputs go the other way:
//! the realtime side stores the commanded value and bumps a sequence number when it
//! changes; the poller writes the value to the device and records the sequence it wrote,
//! so a change is never lost and never waits. No side ever blocks the other.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicU8, Ordering};
use std::time::Instant;

/// How trustworthy a point's value is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quality {
    /// Never read yet.
    Unknown,
    /// Read (or written) successfully by the last transaction.
    Good,
    /// The last transaction for the point failed; the value is the last good one.
    Bad,
}

impl Quality {
    fn from_u8(v: u8) -> Quality {
        match v {
            1 => Quality::Good,
            2 => Quality::Bad,
            _ => Quality::Unknown,
        }
    }

    fn to_u8(self) -> u8 {
        match self {
            Quality::Unknown => 0,
            Quality::Good => 1,
            Quality::Bad => 2,
        }
    }
}

/// An input point: value (f64 bits), quality, time of the last good read.
#[derive(Debug)]
pub struct InputCell {
    value: AtomicU64,
    quality: AtomicU8,
    stamp_ns: AtomicU64,
}

/// An output point: the commanded value, its change sequence, the sequence last written.
#[derive(Debug)]
pub struct OutputCell {
    value: AtomicU64,
    seq: AtomicU32,
    written: AtomicU32,
    quality: AtomicU8,
}

/// A snapshot of one input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Raw value (0/1 for digital points).
    pub value: f64,
    /// Quality.
    pub quality: Quality,
    /// Nanoseconds since the image was created, at the last good read.
    pub stamp_ns: u64,
}

impl InputCell {
    fn new() -> InputCell {
        InputCell {
            value: AtomicU64::new(0f64.to_bits()),
            quality: AtomicU8::new(Quality::Unknown.to_u8()),
            stamp_ns: AtomicU64::new(0),
        }
    }

    /// The current sample.
    pub fn sample(&self) -> Sample {
        Sample {
            quality: Quality::from_u8(self.quality.load(Ordering::Acquire)),
            value: f64::from_bits(self.value.load(Ordering::Acquire)),
            stamp_ns: self.stamp_ns.load(Ordering::Acquire),
        }
    }
}

impl OutputCell {
    fn new() -> OutputCell {
        OutputCell {
            value: AtomicU64::new(0f64.to_bits()),
            // seq != written: the initial value is written once the link is up.
            seq: AtomicU32::new(1),
            written: AtomicU32::new(0),
            quality: AtomicU8::new(Quality::Unknown.to_u8()),
        }
    }

    /// The commanded value.
    pub fn value(&self) -> f64 {
        f64::from_bits(self.value.load(Ordering::Acquire))
    }

    /// Commands `value`; bumps the sequence when it changed. Realtime-safe.
    pub fn command(&self, value: f64) {
        let bits = value.to_bits();
        if self.value.swap(bits, Ordering::AcqRel) != bits {
            self.seq.fetch_add(1, Ordering::AcqRel);
        }
    }

    /// The value to write and its sequence when it changed since the last confirmed write.
    pub fn pending(&self) -> Option<(u32, f64)> {
        let seq = self.seq.load(Ordering::Acquire);
        (seq != self.written.load(Ordering::Acquire)).then(|| (seq, self.value()))
    }

    /// The sequence and value now commanded, changed or not (periodic refresh).
    pub fn current(&self) -> (u32, f64) {
        (self.seq.load(Ordering::Acquire), self.value())
    }

    /// Records that the value of sequence `seq` reached the device.
    pub fn confirm(&self, seq: u32) {
        self.written.store(seq, Ordering::Release);
        self.quality.store(Quality::Good.to_u8(), Ordering::Release);
    }

    /// Marks the output as not written: it is written again once the link is back.
    pub fn invalidate(&self) {
        let seq = self.seq.load(Ordering::Acquire);
        self.written.store(seq.wrapping_sub(1), Ordering::Release);
        self.quality.store(Quality::Bad.to_u8(), Ordering::Release);
    }

    /// Quality of the last write.
    pub fn quality(&self) -> Quality {
        Quality::from_u8(self.quality.load(Ordering::Acquire))
    }
}

/// The image of one device: digital and analog inputs and outputs in channel order, and
/// which inputs are critical.
#[derive(Debug)]
pub struct Image {
    /// Digital inputs.
    pub di: Box<[InputCell]>,
    /// Analog inputs.
    pub ai: Box<[InputCell]>,
    /// Digital outputs.
    pub dout: Box<[OutputCell]>,
    /// Analog outputs.
    pub ao: Box<[OutputCell]>,
    /// Digital inputs whose loss stops the machine.
    pub di_critical: Box<[bool]>,
    /// Analog inputs whose loss stops the machine.
    pub ai_critical: Box<[bool]>,
    epoch: Instant,
    closed: AtomicBool,
}

impl Image {
    /// An image for the given channels; `di_critical`/`ai_critical` give the counts of
    /// inputs and which are critical.
    pub fn new(
        di_critical: Vec<bool>,
        ai_critical: Vec<bool>,
        digital_outputs: usize,
        analog_outputs: usize,
    ) -> Image {
        Image {
            di: di_critical.iter().map(|_| InputCell::new()).collect(),
            ai: ai_critical.iter().map(|_| InputCell::new()).collect(),
            dout: (0..digital_outputs).map(|_| OutputCell::new()).collect(),
            ao: (0..analog_outputs).map(|_| OutputCell::new()).collect(),
            di_critical: di_critical.into(),
            ai_critical: ai_critical.into(),
            epoch: Instant::now(),
            closed: AtomicBool::new(false),
        }
    }

    /// Nanoseconds since the image was created.
    pub fn now_ns(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    /// Publishes a good read of an input.
    pub fn publish(cell: &InputCell, value: f64, stamp_ns: u64) {
        cell.value.store(value.to_bits(), Ordering::Release);
        cell.stamp_ns.store(stamp_ns, Ordering::Release);
        cell.quality.store(Quality::Good.to_u8(), Ordering::Release);
    }

    /// Marks an input bad (its last good value stays).
    pub fn mark_bad(cell: &InputCell) {
        cell.quality.store(Quality::Bad.to_u8(), Ordering::Release);
    }

    /// Tells the poller that the device is gone (the machine dropped it): it stops.
    pub fn close(&self) {
        self.closed.store(true, Ordering::Release);
    }

    /// True once [`close`](Image::close) was called.
    pub fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }

    /// True when every critical input has a good value.
    pub fn critical_ok(&self) -> bool {
        let ok = |cells: &[InputCell], crit: &[bool]| {
            cells
                .iter()
                .zip(crit)
                .all(|(c, &k)| !k || c.sample().quality == Quality::Good)
        };
        ok(&self.di, &self.di_critical) && ok(&self.ai, &self.ai_critical)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_change_is_pending_until_confirmed() {
        let img = Image::new(vec![], vec![], 1, 0);
        let o = &img.dout[0];
        // The initial value is pending so that the device gets it once connected.
        let (seq, v) = o.pending().unwrap();
        assert_eq!(v, 0.0);
        o.confirm(seq);
        assert_eq!(o.pending(), None);
        o.command(0.0);
        assert_eq!(o.pending(), None, "the same value is no change");
        o.command(1.0);
        let (s1, v) = o.pending().unwrap();
        assert_eq!(v, 1.0);
        // A change while the write is in flight stays pending after the confirmation.
        o.command(0.0);
        o.confirm(s1);
        assert_eq!(o.pending().map(|p| p.1), Some(0.0));
        let (s2, _) = o.pending().unwrap();
        o.confirm(s2);
        o.invalidate();
        assert!(o.pending().is_some(), "rewritten after a reconnect");
        assert_eq!(o.quality(), Quality::Bad);
    }

    #[test]
    fn inputs_carry_quality_and_timestamp() {
        let img = Image::new(vec![true, false], vec![false], 0, 0);
        assert_eq!(img.di[0].sample().quality, Quality::Unknown);
        assert!(!img.critical_ok());
        Image::publish(&img.di[0], 1.0, 42);
        assert_eq!(
            img.di[0].sample(),
            Sample {
                value: 1.0,
                quality: Quality::Good,
                stamp_ns: 42
            }
        );
        assert!(img.critical_ok(), "the non-critical points do not count");
        Image::mark_bad(&img.di[0]);
        assert_eq!(img.di[0].sample().value, 1.0, "the last good value stays");
        assert!(!img.critical_ok());
    }
}
