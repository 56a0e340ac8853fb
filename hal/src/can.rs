//! CAN frames and the [`CanBus`] trait.
//!
//! [`CanBus`] is the *bus* in the `embedded-hal` bus/device split: exactly one owner of the
//! physical link (a SocketCAN socket, or a port of the in-memory
//! [`SimCanBus`](crate::sim::SimCanBus)). CANopen sits on top: a single bus owner
//! routes received frames to many node handles by COB-ID and sends their frames (SYNC,
//! RPDOs, SDO requests) out through this trait. Sending and receiving never block: the
//! servo thread polls [`CanBus::try_recv`] until it returns `None` and queues frames with
//! [`CanBus::try_send`], which fails with [`ErrorKind::WouldBlock`](crate::ErrorKind::WouldBlock)
//! when the transmit queue is full.

use crate::error::ErrorType;
use core::fmt;

/// The largest standard (11-bit) identifier.
pub const MAX_STANDARD_ID: u32 = 0x7FF;
/// The largest extended (29-bit) identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// A CAN identifier: 11-bit standard (as CANopen uses) or 29-bit extended. Constructed
/// checked, so a frame never carries an identifier its format cannot hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanId {
    raw: u32,
    extended: bool,
}

/// Why a frame or identifier could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The identifier does not fit its format.
    #[error("CAN id 0x{id:X} does not fit in {bits} bits")]
    IdOutOfRange {
        /// The rejected identifier.
        id: u32,
        /// 11 or 29.
        bits: u8,
    },
    /// More than 8 data bytes (classic CAN).
    #[error("CAN frame data is {len} bytes, at most 8 fit")]
    DataTooLong {
        /// The rejected length.
        len: usize,
    },
}

impl crate::error::Error for FrameError {
    fn kind(&self) -> crate::ErrorKind {
        crate::ErrorKind::InvalidArgument
    }
}

impl CanId {
    /// An 11-bit standard identifier (`0..=0x7FF`).
    pub fn standard(raw: u16) -> Result<CanId, FrameError> {
        if u32::from(raw) > MAX_STANDARD_ID {
            return Err(FrameError::IdOutOfRange {
                id: raw.into(),
                bits: 11,
            });
        }
        Ok(CanId {
            raw: raw.into(),
            extended: false,
        })
    }

    /// A 29-bit extended identifier (`0..=0x1FFF_FFFF`).
    pub fn extended(raw: u32) -> Result<CanId, FrameError> {
        if raw > MAX_EXTENDED_ID {
            return Err(FrameError::IdOutOfRange { id: raw, bits: 29 });
        }
        Ok(CanId {
            raw,
            extended: true,
        })
    }

    /// The numeric identifier (the COB-ID in CANopen).
    pub fn raw(self) -> u32 {
        self.raw
    }

    /// True for a 29-bit identifier.
    pub fn is_extended(self) -> bool {
        self.extended
    }
}

impl fmt::Display for CanId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "{:08X}", self.raw)
        } else {
            write!(f, "{:03X}", self.raw)
        }
    }
}

/// A classic CAN frame: identifier, data length code and up to 8 data bytes. `Copy` and of
/// fixed size, so frames move through queues without allocation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CanFrame {
    id: CanId,
    dlc: u8,
    data: [u8; 8],
    remote: bool,
}

impl CanFrame {
    /// A data frame carrying `data` (at most 8 bytes).
    #[inline]
    pub fn new(id: CanId, data: &[u8]) -> Result<CanFrame, FrameError> {
        if data.len() > 8 {
            return Err(FrameError::DataTooLong { len: data.len() });
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Ok(CanFrame {
            id,
            // Cannot truncate: checked <= 8 above.
            dlc: data.len() as u8,
            data: buf,
            remote: false,
        })
    }

    /// A remote (RTR) frame requesting `dlc` bytes (at most 8).
    pub fn remote(id: CanId, dlc: u8) -> Result<CanFrame, FrameError> {
        if dlc > 8 {
            return Err(FrameError::DataTooLong { len: dlc.into() });
        }
        Ok(CanFrame {
            id,
            dlc,
            data: [0; 8],
            remote: true,
        })
    }

    /// The identifier.
    pub fn id(&self) -> CanId {
        self.id
    }

    /// The data length code (number of data bytes, 0..=8).
    pub fn dlc(&self) -> u8 {
        self.dlc
    }

    /// The data bytes (`dlc` of them; empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.dlc)]
        }
    }

    /// True for a remote transmission request.
    pub fn is_remote(&self) -> bool {
        self.remote
    }
}

/// A CAN bus interface: non-blocking send and receive of frames. One owner per physical
/// link; see the module doc for how CANopen nodes share it.
pub trait CanBus: ErrorType {
    /// Queues `frame` for transmission. Fails with
    /// [`ErrorKind::WouldBlock`](crate::ErrorKind::WouldBlock) when the transmit queue is full
    /// and with a link failure kind when the bus is off or gone.
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), Self::Error>;

    /// Takes the next received frame, or `None` when nothing is pending.
    fn try_recv(&mut self) -> Result<Option<CanFrame>, Self::Error>;

    /// Receives into `out` until it is full or nothing is pending; returns how many frames
    /// were written. For draining the bus once per cycle without allocation.
    fn recv_into(&mut self, out: &mut [CanFrame]) -> Result<usize, Self::Error> {
        let mut n = 0;
        while n < out.len() {
            match self.try_recv()? {
                Some(f) => {
                    out[n] = f;
                    n += 1;
                }
                None => break,
            }
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_ids_are_checked() {
        assert_eq!(CanId::standard(0x7FF).unwrap().raw(), 0x7FF);
        assert_eq!(
            CanId::standard(0x800),
            Err(FrameError::IdOutOfRange {
                id: 0x800,
                bits: 11
            })
        );
        assert!(!CanId::standard(1).unwrap().is_extended());
    }

    #[test]
    fn extended_ids_are_checked() {
        assert!(CanId::extended(MAX_EXTENDED_ID).unwrap().is_extended());
        assert!(CanId::extended(MAX_EXTENDED_ID + 1).is_err());
    }

    #[test]
    fn frame_keeps_dlc_and_data() {
        let id = CanId::standard(0x181).unwrap();
        let f = CanFrame::new(id, &[1, 2, 3]).unwrap();
        assert_eq!(f.dlc(), 3);
        assert_eq!(f.data(), &[1, 2, 3]);
        assert_eq!(f.id(), id);
        assert!(!f.is_remote());
        assert_eq!(id.to_string(), "181");
    }

    #[test]
    fn frame_rejects_more_than_eight_bytes() {
        let id = CanId::standard(1).unwrap();
        assert_eq!(
            CanFrame::new(id, &[0; 9]),
            Err(FrameError::DataTooLong { len: 9 })
        );
        assert!(CanFrame::remote(id, 9).is_err());
    }

    #[test]
    fn remote_frame_has_dlc_but_no_data() {
        let f = CanFrame::remote(CanId::standard(0x701).unwrap(), 1).unwrap();
        assert!(f.is_remote());
        assert_eq!(f.dlc(), 1);
        assert!(f.data().is_empty());
    }
}
