//! SDO block transfer (CiA 301 §7.2.4.3.9 ff.), the parts client and server share.
//!
//! A block transfer moves the value in sub-blocks of up to 127 segments of 7 bytes, each
//! segment numbered 1..=blksize in its first byte (bit 7 marks the last segment of the
//! value), confirmed once per sub-block instead of once per segment. The receiver of the
//! data (server in a download, client in an upload) picks the sub-block size and
//! acknowledges the last segment it got in sequence; the sender resends from there. The end
//! frame says how many bytes of the last segment are padding and carries a CRC-16 of the
//! value when both sides announced CRC support.
//!
//! The frame layouts are symmetric: the acknowledgement (`0xA2`, ackseq, blksize), the end
//! frame (`0xC1 | n << 2`, CRC) and the end confirmation (`0xA1`) are byte for byte the
//! same in both directions, so [`SubBlockTx`] and [`SubBlockRx`] serve both roles.

use super::SdoAbortCode;

/// The sub-block size this side asks for when it receives (the maximum, 127 segments).
pub const BLKSIZE: u8 = 127;

/// Values longer than this go by block transfer when the client is allowed to use it
/// (shorter ones are cheaper segmented: the block protocol costs 4 extra frames).
pub const DEFAULT_BLOCK_THRESHOLD: usize = 32;

/// Bit 2 of the initiate frames: "I compute a CRC" (cc from the client, sc from the server).
pub(crate) const CRC_SUPPORTED: u8 = 0x04;

/// The acknowledgement of a sub-block: last segment received in sequence, next blksize.
pub(crate) const ACK: u8 = 0xA2;
/// The confirmation of the end frame.
pub(crate) const END_CONFIRM: u8 = 0xA1;

/// CRC-16-CCITT as CiA 301 specifies it for block transfer: polynomial x¹⁶ + x¹² + x⁵ + 1
/// (0x1021), initial value 0, no reflection, no final xor (the "XMODEM" variant).
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// The end frame of a block transfer of `data`: the padding of the last segment and the
/// CRC (sent even when the peer does not check it; CiA 301 then ignores the field).
pub(crate) fn end_frame(data: &[u8]) -> [u8; 8] {
    // Cannot truncate: the padding is 0..=6 (7 for an empty value: one empty segment).
    let padding = if data.is_empty() {
        7
    } else {
        ((7 - data.len() % 7) % 7) as u8
    };
    let c = crc16(data).to_le_bytes();
    [0xC1 | (padding << 2), c[0], c[1], 0, 0, 0, 0, 0]
}

/// Takes a received end frame `d` over the segments collected in `buf`: strips the
/// padding, checks the announced `size` and, when `check_crc`, the CRC.
pub(crate) fn finish(
    d: &[u8],
    buf: &mut Vec<u8>,
    size: Option<usize>,
    check_crc: bool,
) -> Result<(), SdoAbortCode> {
    if d[0] & 0xE3 != 0xC1 {
        return Err(SdoAbortCode::InvalidCommandSpecifier);
    }
    let padding = usize::from((d[0] >> 2) & 0x07);
    let len = buf
        .len()
        .checked_sub(padding)
        .ok_or(SdoAbortCode::LengthTooLow)?;
    buf.truncate(len);
    match size {
        Some(s) if len > s => return Err(SdoAbortCode::LengthTooHigh),
        Some(s) if len < s => return Err(SdoAbortCode::LengthTooLow),
        _ => {}
    }
    if check_crc && crc16(buf) != u16::from_le_bytes([d[1], d[2]]) {
        return Err(SdoAbortCode::CrcError);
    }
    Ok(())
}

/// The sending side of a block transfer: which part of the value the current sub-block
/// carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SubBlockTx {
    /// Byte offset of the first segment of the current sub-block.
    pub start: usize,
    /// Segments in the current sub-block (the receiver's blksize).
    pub blksize: u8,
}

impl SubBlockTx {
    /// A transfer starting at the value's first byte with the receiver's `blksize`.
    pub fn new(blksize: u8) -> Result<SubBlockTx, SdoAbortCode> {
        if !(1..=127).contains(&blksize) {
            return Err(SdoAbortCode::InvalidBlockSize);
        }
        Ok(SubBlockTx { start: 0, blksize })
    }

    /// The segment `seq` (1-based) of the current sub-block, if the value reaches it.
    pub fn segment(&self, data: &[u8], seq: u8) -> Option<[u8; 8]> {
        if seq == 0 || seq > self.blksize {
            return None;
        }
        let pos = self.start + usize::from(seq - 1) * 7;
        // An empty value still goes as one empty segment.
        if pos >= data.len() && !(pos == 0 && seq == 1) {
            return None;
        }
        let end = (pos + 7).min(data.len());
        let mut out = [0u8; 8];
        out[1..1 + end - pos].copy_from_slice(&data[pos..end]);
        out[0] = seq | if end == data.len() { 0x80 } else { 0 };
        Some(out)
    }

    /// The receiver acknowledged `d` (`0xA2`, ackseq, blksize): moves past the segments it
    /// confirmed. `Ok(true)` when the whole value is confirmed (send the end frame next).
    pub fn on_ack(&mut self, d: &[u8], data: &[u8]) -> Result<bool, SdoAbortCode> {
        if d[0] & 0xE3 != ACK {
            return Err(SdoAbortCode::InvalidCommandSpecifier);
        }
        let ackseq = d[1];
        let sent = (1..=self.blksize)
            .take_while(|&s| self.segment(data, s).is_some())
            .count();
        if usize::from(ackseq) > sent {
            return Err(SdoAbortCode::InvalidSequenceNumber);
        }
        let done = ackseq > 0 && self.segment(data, ackseq).is_some_and(|s| s[0] & 0x80 != 0);
        self.start = (self.start + usize::from(ackseq) * 7).min(data.len());
        if !done {
            *self = SubBlockTx::new(d[2]).map(|t| SubBlockTx {
                start: self.start,
                ..t
            })?;
        }
        Ok(done)
    }
}

/// The receiving side of a block transfer: the sequence number expected next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SubBlockRx {
    /// The last segment received in sequence in the current sub-block (0: none yet).
    pub seq: u8,
    /// True once the segment marked last arrived in sequence.
    pub last: bool,
}

/// What a received segment asks of the receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RxStep {
    /// Keep listening.
    More,
    /// The sub-block ended: send this acknowledgement (and expect the end frame next when
    /// [`SubBlockRx::last`] is set).
    Ack([u8; 8]),
}

impl SubBlockRx {
    /// Takes segment `d`; appends its 7 bytes to `buf` when it is the one expected.
    /// Segments out of sequence are dropped; the acknowledgement at the end of the
    /// sub-block tells the sender where to resume.
    pub fn on_segment(&mut self, d: &[u8], buf: &mut Vec<u8>) -> RxStep {
        let seq = d[0] & 0x7F;
        let last = d[0] & 0x80 != 0;
        if seq == self.seq.wrapping_add(1) && !self.last {
            buf.extend_from_slice(&d[1..8]);
            self.seq = seq;
            self.last = last;
        }
        if seq == BLKSIZE || last {
            let ack = [ACK, self.seq, BLKSIZE, 0, 0, 0, 0, 0];
            self.seq = 0;
            RxStep::Ack(ack)
        } else {
            RxStep::More
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_is_the_ccitt_xmodem_variant() {
        // The standard check value of CRC-16/XMODEM.
        assert_eq!(crc16(b"123456789"), 0x31C3);
        assert_eq!(crc16(&[]), 0);
    }

    #[test]
    fn end_frame_states_padding_of_the_last_segment() {
        assert_eq!(end_frame(&[0; 14])[0], 0xC1, "two full segments");
        assert_eq!(
            end_frame(&[0; 15])[0],
            0xC1 | (6 << 2),
            "one byte in the last"
        );
        assert_eq!(end_frame(&[])[0], 0xC1 | (7 << 2));
        let e = end_frame(b"123456789");
        assert_eq!(u16::from_le_bytes([e[1], e[2]]), 0x31C3);
    }

    #[test]
    fn resend_from_the_acknowledged_segment() {
        let data: Vec<u8> = (0..30).collect();
        let mut tx = SubBlockTx::new(3).unwrap();
        assert_eq!(tx.segment(&data, 1).unwrap()[..2], [1, 0]);
        assert_eq!(tx.segment(&data, 3).unwrap()[..2], [3, 14]);
        assert_eq!(tx.segment(&data, 4), None, "beyond blksize");
        // Segment 2 lost: the receiver confirms 1 and asks for 4 per block.
        assert_eq!(tx.on_ack(&[ACK, 1, 4, 0, 0, 0, 0, 0], &data), Ok(false));
        assert_eq!(tx.segment(&data, 1).unwrap()[..2], [1, 7]);
        assert_eq!(tx.segment(&data, 4).unwrap()[..2], [0x80 | 4, 28], "last");
        assert_eq!(tx.segment(&data, 5), None);
        assert_eq!(
            tx.on_ack(&[ACK, 5, 4, 0, 0, 0, 0, 0], &data),
            Err(SdoAbortCode::InvalidSequenceNumber)
        );
        assert_eq!(tx.on_ack(&[ACK, 4, 4, 0, 0, 0, 0, 0], &data), Ok(true));
        assert_eq!(
            SubBlockTx::new(0),
            Err(SdoAbortCode::InvalidBlockSize),
            "blksize 0"
        );
    }

    #[test]
    fn receiver_drops_segments_out_of_sequence_and_acks_the_last_good_one() {
        let mut rx = SubBlockRx {
            seq: 0,
            last: false,
        };
        let mut buf = Vec::new();
        assert_eq!(
            rx.on_segment(&[1, 1, 1, 1, 1, 1, 1, 1], &mut buf),
            RxStep::More
        );
        assert_eq!(
            rx.on_segment(&[3, 3, 3, 3, 3, 3, 3, 3], &mut buf),
            RxStep::More
        );
        let RxStep::Ack(a) = rx.on_segment(&[0x84, 4, 4, 4, 4, 4, 4, 4], &mut buf) else {
            panic!()
        };
        assert_eq!(a[..3], [ACK, 1, BLKSIZE]);
        assert_eq!(buf, [1; 7]);
        assert!(!rx.last);
    }
}
