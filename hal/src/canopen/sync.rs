//! SYNC (COB-ID 0x080): the servo thread sends one per cycle, so drives and trajectory share
//! one clock. Optional counter (CiA 301 0x1019): 1, 2, …, overflow, 1, …

use super::{cob_id, frame, COB_SYNC};
use crate::can::CanFrame;

/// Produces SYNC frames; one [`next_frame`](SyncProducer::next_frame) per servo cycle.
#[derive(Debug, Clone)]
pub struct SyncProducer {
    overflow: Option<u8>,
    counter: u8,
}

impl SyncProducer {
    /// A producer without counter (0-byte SYNC).
    pub fn new() -> SyncProducer {
        SyncProducer {
            overflow: None,
            counter: 0,
        }
    }

    /// A producer with counter wrapping after `overflow` (CiA 301: 2..=240; clamped).
    pub fn with_counter(overflow: u8) -> SyncProducer {
        SyncProducer {
            overflow: Some(overflow.clamp(2, 240)),
            counter: 0,
        }
    }

    /// The data length of the frames this producer sends (0 or 1), for the bus-load budget.
    pub fn data_len(&self) -> usize {
        usize::from(self.overflow.is_some())
    }

    /// The next SYNC frame. Never allocates.
    pub fn next_frame(&mut self) -> CanFrame {
        match self.overflow {
            None => frame(cob_id(COB_SYNC), &[]),
            Some(max) => {
                self.counter = if self.counter >= max {
                    1
                } else {
                    self.counter + 1
                };
                frame(cob_id(COB_SYNC), &[self.counter])
            }
        }
    }
}

impl Default for SyncProducer {
    fn default() -> Self {
        SyncProducer::new()
    }
}

/// Decodes a SYNC frame: `Some(counter)` (counter `None` without one), `None` for any other
/// frame.
pub fn decode_sync(f: &CanFrame) -> Option<Option<u8>> {
    if f.id().is_extended() || f.id().raw() != u32::from(COB_SYNC) || f.is_remote() {
        return None;
    }
    match f.data() {
        [] => Some(None),
        [c] => Some(Some(*c)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_sync_is_empty_on_0x80() {
        let mut p = SyncProducer::new();
        let f = p.next_frame();
        assert_eq!(f.id().raw(), 0x80);
        assert!(f.data().is_empty());
        assert_eq!(decode_sync(&f), Some(None));
        assert_eq!(p.data_len(), 0);
    }

    #[test]
    fn counter_runs_one_to_overflow_and_wraps() {
        let mut p = SyncProducer::with_counter(3);
        let got: Vec<u8> = (0..7).map(|_| p.next_frame().data()[0]).collect();
        assert_eq!(got, [1, 2, 3, 1, 2, 3, 1]);
        assert_eq!(decode_sync(&p.next_frame()), Some(Some(2)));
        assert_eq!(SyncProducer::with_counter(250).overflow, Some(240));
        assert_eq!(p.data_len(), 1);
    }

    #[test]
    fn other_frames_are_not_sync() {
        assert_eq!(decode_sync(&frame(cob_id(0x81), &[])), None);
        assert_eq!(decode_sync(&frame(cob_id(0x80), &[1, 2])), None);
    }
}
