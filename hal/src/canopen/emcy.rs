//! EMCY (COB-ID 0x080 + node): 2-byte error code, error register (0x1001), 5 manufacturer
//! bytes. The consumer turns a received EMCY into a fault naming node, code and the CiA 301
//! error-code class; code 0x0000 ("error reset or no error") clears instead.

use super::{frame, CanOpenError, NodeId, COB_EMCY};
use crate::can::CanFrame;
use core::fmt;

/// A decoded emergency message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emergency {
    /// Emergency error code (CiA 301 table 21, profile-specific codes in CiA 402).
    pub code: u16,
    /// The error register 0x1001 at the time of the event.
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub manufacturer: [u8; 5],
}

impl Emergency {
    /// An emergency without manufacturer data.
    pub fn new(code: u16, register: u8) -> Emergency {
        Emergency {
            code,
            register,
            manufacturer: [0; 5],
        }
    }

    /// The EMCY frame of `node`.
    pub fn frame(&self, node: NodeId) -> CanFrame {
        let c = self.code.to_le_bytes();
        let m = self.manufacturer;
        frame(
            node.cob(COB_EMCY),
            &[c[0], c[1], self.register, m[0], m[1], m[2], m[3], m[4]],
        )
    }

    /// Decodes an EMCY frame: `None` for a frame outside 0x081..=0x0FF, an error for an EMCY
    /// COB-ID with a wrong length. Never allocates.
    pub fn decode(f: &CanFrame) -> Option<Result<(NodeId, Emergency), CanOpenError>> {
        if f.id().is_extended() || f.is_remote() {
            return None;
        }
        let node = NodeId::from_cob(f.id().raw(), COB_EMCY)?;
        let d = f.data();
        if d.len() != 8 {
            return Some(Err(CanOpenError::Malformed {
                what: "EMCY",
                cob: f.id().raw(),
                why: "an emergency carries 8 data bytes",
            }));
        }
        Some(Ok((
            node,
            Emergency {
                code: u16::from_le_bytes([d[0], d[1]]),
                register: d[2],
                manufacturer: [d[3], d[4], d[5], d[6], d[7]],
            },
        )))
    }

    /// True for code 0x0000: the node reports its errors cleared.
    pub fn is_reset(&self) -> bool {
        self.code == 0
    }

    /// The CiA 301 class name of the code.
    pub fn class(&self) -> &'static str {
        error_class(self.code)
    }
}

impl fmt::Display for Emergency {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "0x{:04X} ({}), error register 0x{:02X}, manufacturer {:02X?}",
            self.code,
            self.class(),
            self.register,
            self.manufacturer
        )
    }
}

/// The name of an emergency error code's class (CiA 301 table 21, with the CiA 301
/// communication sub-codes and the CiA 402 following-error code drives send most).
pub fn error_class(code: u16) -> &'static str {
    match code {
        0x0000 => "error reset or no error",
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8150 => "CAN-ID collision",
        0x8210 => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x8230 => "DAM MPDO not processed, destination object not available",
        0x8240 => "unexpected SYNC data length",
        0x8250 => "RPDO timeout",
        0x8611 => "following error",
        _ => match code >> 8 {
            0x10..=0x1F => "generic error",
            0x21 => "current, device input side",
            0x22 => "current inside the device",
            0x23 => "current, device output side",
            0x20..=0x2F => "current",
            0x31 => "mains voltage",
            0x32 => "voltage inside the device",
            0x33 => "output voltage",
            0x30..=0x3F => "voltage",
            0x41 => "ambient temperature",
            0x42 => "device temperature",
            0x40..=0x4F => "temperature",
            0x50..=0x5F => "device hardware",
            0x61 => "internal software",
            0x62 => "user software",
            0x63 => "data set",
            0x60..=0x6F => "device software",
            0x70..=0x7F => "additional modules",
            0x81 => "communication",
            0x82 => "protocol error",
            0x80..=0x8F => "monitoring",
            0x90..=0x9F => "external error",
            0xF0..=0xFE => "additional functions",
            0xFF => "device specific",
            _ => "unknown error class",
        },
    }
}

/// Turns received EMCY frames into fault events. Keeps the last emergency of each node
/// (fixed array, no allocation) so a monitor can show the active error.
#[derive(Debug, Clone)]
pub struct EmcyConsumer {
    last: [Option<Emergency>; 128],
}

impl Default for EmcyConsumer {
    fn default() -> Self {
        EmcyConsumer { last: [None; 128] }
    }
}

/// What one received EMCY frame means.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EmcyEvent {
    /// A new error: the fault to raise ([`CanOpenError::Emergency`]).
    Fault(CanOpenError),
    /// The node cleared its errors (code 0x0000).
    Cleared(NodeId),
}

impl EmcyConsumer {
    /// Handles a frame; `None` if it is not an EMCY. A malformed EMCY is returned as a fault
    /// too (the node tried to report something).
    pub fn on_frame(&mut self, f: &CanFrame) -> Option<EmcyEvent> {
        match Emergency::decode(f)? {
            Err(e) => Some(EmcyEvent::Fault(e)),
            Ok((node, emcy)) => {
                let slot = &mut self.last[usize::from(node.get())];
                if emcy.is_reset() {
                    *slot = None;
                    Some(EmcyEvent::Cleared(node))
                } else {
                    *slot = Some(emcy);
                    Some(EmcyEvent::Fault(CanOpenError::Emergency { node, emcy }))
                }
            }
        }
    }

    /// The last uncleared emergency of `node`.
    pub fn active(&self, node: NodeId) -> Option<Emergency> {
        self.last[usize::from(node.get())]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::{Error, ErrorKind};

    fn n(id: u8) -> NodeId {
        NodeId::new(id).unwrap()
    }

    #[test]
    fn emcy_round_trips() {
        let e = Emergency {
            code: 0x2310,
            register: 0x03,
            manufacturer: [1, 2, 3, 4, 5],
        };
        let f = e.frame(n(7));
        assert_eq!(f.id().raw(), 0x87);
        assert_eq!(f.data(), &[0x10, 0x23, 0x03, 1, 2, 3, 4, 5]);
        assert_eq!(Emergency::decode(&f), Some(Ok((n(7), e))));
    }

    #[test]
    fn classes_follow_cia301() {
        assert_eq!(error_class(0x1000), "generic error");
        assert_eq!(error_class(0x2310), "current, device output side");
        assert_eq!(error_class(0x3210), "voltage inside the device");
        assert_eq!(error_class(0x4210), "device temperature");
        assert_eq!(error_class(0x5000), "device hardware");
        assert_eq!(error_class(0x6320), "data set");
        assert_eq!(error_class(0x7000), "additional modules");
        assert_eq!(error_class(0x8130), "life guard or heartbeat error");
        assert_eq!(error_class(0x8400), "monitoring");
        assert_eq!(error_class(0x9000), "external error");
        assert_eq!(error_class(0xFF01), "device specific");
        assert_eq!(error_class(0xF000), "additional functions");
        assert_eq!(error_class(0x0100), "unknown error class");
    }

    #[test]
    fn consumer_raises_a_fault_naming_node_and_code_and_clears_on_reset() {
        let mut c = EmcyConsumer::default();
        let f = Emergency::new(0x4210, 0x09).frame(n(2));
        let Some(EmcyEvent::Fault(err)) = c.on_frame(&f) else {
            panic!("expected a fault")
        };
        assert_eq!(err.kind(), ErrorKind::DeviceFault);
        let msg = err.to_string();
        assert!(
            msg.contains("node 2") && msg.contains("0x4210") && msg.contains("device temperature"),
            "{msg}"
        );
        assert_eq!(c.active(n(2)).map(|e| e.code), Some(0x4210));
        assert_eq!(
            c.on_frame(&Emergency::new(0, 0).frame(n(2))),
            Some(EmcyEvent::Cleared(n(2)))
        );
        assert_eq!(c.active(n(2)), None);
    }

    #[test]
    fn short_emcy_is_malformed_and_sync_is_not_emcy() {
        let mut c = EmcyConsumer::default();
        let short = frame(n(2).cob(COB_EMCY), &[1, 2]);
        assert!(matches!(
            c.on_frame(&short),
            Some(EmcyEvent::Fault(CanOpenError::Malformed { .. }))
        ));
        assert_eq!(c.on_frame(&frame(super::super::cob_id(0x80), &[])), None);
    }
}
