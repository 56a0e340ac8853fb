//! A Modbus server's core, sans I/O: the data tables of one unit, request handling
//! (function codes 1-6, 15, 16, 22) and the TCP (MBAP) and RTU (CRC-16) framing.
//!
//! The simulator (`hytask modbus-sim`) runs it over sockets and serial lines; tests feed it
//! bytes directly. Malformed requests get the exception the protocol prescribes, never a
//! panic.

use super::map::Table;

/// Exception codes used here.
pub mod exception {
    /// Function code not supported.
    pub const ILLEGAL_FUNCTION: u8 = 1;
    /// Address outside the unit's tables.
    pub const ILLEGAL_DATA_ADDRESS: u8 = 2;
    /// Malformed request (quantity, length, coil value).
    pub const ILLEGAL_DATA_VALUE: u8 = 3;
}

/// The four tables of one unit.
#[derive(Debug, Clone, PartialEq)]
pub struct Tables {
    /// Coils.
    pub coils: Vec<bool>,
    /// Discrete inputs.
    pub discrete_inputs: Vec<bool>,
    /// Holding registers.
    pub holding: Vec<u16>,
    /// Input registers.
    pub input: Vec<u16>,
}

fn be16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(at)?, *b.get(at + 1)?]))
}

fn pack_bits(bits: &[bool]) -> Vec<u8> {
    let mut out = vec![0u8; bits.len().div_ceil(8)];
    for (i, &b) in bits.iter().enumerate() {
        if b {
            out[i / 8] |= 1 << (i % 8);
        }
    }
    out
}

impl Tables {
    /// Tables of `len` items each, all zero.
    pub fn new(len: usize) -> Tables {
        Tables {
            coils: vec![false; len],
            discrete_inputs: vec![false; len],
            holding: vec![0; len],
            input: vec![0; len],
        }
    }

    /// Sets bit or register `address` of `table` to `value` (bits: non-zero is on).
    /// False when the address is outside the table.
    pub fn set(&mut self, table: Table, address: u16, value: u16) -> bool {
        let a = usize::from(address);
        let slot = match table {
            Table::Coil => self.coils.get_mut(a).map(|b| *b = value != 0),
            Table::DiscreteInput => self.discrete_inputs.get_mut(a).map(|b| *b = value != 0),
            Table::HoldingRegister => self.holding.get_mut(a).map(|r| *r = value),
            Table::InputRegister => self.input.get_mut(a).map(|r| *r = value),
        };
        slot.is_some()
    }

    /// Bit or register `address` of `table` (bits as 0/1).
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        let a = usize::from(address);
        match table {
            Table::Coil => self.coils.get(a).map(|&b| u16::from(b)),
            Table::DiscreteInput => self.discrete_inputs.get(a).map(|&b| u16::from(b)),
            Table::HoldingRegister => self.holding.get(a).copied(),
            Table::InputRegister => self.input.get(a).copied(),
        }
    }

    /// Handles one request PDU (function code first); returns the response PDU, an
    /// exception response (function | 0x80, code) for refused requests.
    pub fn handle(&mut self, pdu: &[u8]) -> Vec<u8> {
        let Some(&fc) = pdu.first() else {
            return vec![0x80, exception::ILLEGAL_FUNCTION];
        };
        match self.answer(fc, pdu) {
            Ok(r) => r,
            Err(code) => vec![fc | 0x80, code],
        }
    }

    fn answer(&mut self, fc: u8, pdu: &[u8]) -> Result<Vec<u8>, u8> {
        use exception::*;
        let addr = be16(pdu, 1).ok_or(ILLEGAL_DATA_VALUE)?;
        let second = be16(pdu, 3).ok_or(ILLEGAL_DATA_VALUE)?;
        let a = usize::from(addr);
        let range = |len: usize, count: u16, max: u16| -> Result<std::ops::Range<usize>, u8> {
            if count == 0 || count > max {
                return Err(ILLEGAL_DATA_VALUE);
            }
            let end = a + usize::from(count);
            if end > len {
                return Err(ILLEGAL_DATA_ADDRESS);
            }
            Ok(a..end)
        };
        match fc {
            1 | 2 => {
                let t = if fc == 1 {
                    &self.coils
                } else {
                    &self.discrete_inputs
                };
                let r = range(t.len(), second, 2000)?;
                let bytes = pack_bits(&t[r]);
                let mut out = vec![fc, bytes.len() as u8];
                out.extend(bytes);
                Ok(out)
            }
            3 | 4 => {
                let t = if fc == 3 { &self.holding } else { &self.input };
                let r = range(t.len(), second, 125)?;
                let mut out = vec![fc, (r.len() * 2) as u8];
                out.extend(t[r].iter().flat_map(|w| w.to_be_bytes()));
                Ok(out)
            }
            5 => {
                let on = match second {
                    0xFF00 => true,
                    0x0000 => false,
                    _ => return Err(ILLEGAL_DATA_VALUE),
                };
                *self.coils.get_mut(a).ok_or(ILLEGAL_DATA_ADDRESS)? = on;
                Ok(pdu[..5].to_vec())
            }
            6 => {
                *self.holding.get_mut(a).ok_or(ILLEGAL_DATA_ADDRESS)? = second;
                Ok(pdu[..5].to_vec())
            }
            15 | 16 => {
                let n = usize::from(*pdu.get(5).ok_or(ILLEGAL_DATA_VALUE)?);
                let data = pdu.get(6..6 + n).ok_or(ILLEGAL_DATA_VALUE)?;
                if fc == 15 {
                    let r = range(self.coils.len(), second, 1968)?;
                    if n != r.len().div_ceil(8) {
                        return Err(ILLEGAL_DATA_VALUE);
                    }
                    for (k, i) in r.enumerate() {
                        self.coils[i] = data[k / 8] & (1 << (k % 8)) != 0;
                    }
                } else {
                    let r = range(self.holding.len(), second, 123)?;
                    if n != r.len() * 2 {
                        return Err(ILLEGAL_DATA_VALUE);
                    }
                    for (k, i) in r.enumerate() {
                        self.holding[i] = u16::from_be_bytes([data[2 * k], data[2 * k + 1]]);
                    }
                }
                Ok(pdu[..5].to_vec())
            }
            22 => {
                let or = be16(pdu, 5).ok_or(ILLEGAL_DATA_VALUE)?;
                let reg = self.holding.get_mut(a).ok_or(ILLEGAL_DATA_ADDRESS)?;
                *reg = (*reg & second) | (or & !second);
                Ok(pdu[..7].to_vec())
            }
            _ => Err(ILLEGAL_FUNCTION),
        }
    }
}

/// CRC-16/MODBUS of `data` (sent low byte first).
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// An RTU frame: `unit, pdu..., crc lo, crc hi`.
pub fn rtu_frame(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(pdu.len() + 3);
    f.push(unit);
    f.extend_from_slice(pdu);
    let crc = crc16(&f);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// What the head of an RTU receive buffer holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RtuRequest {
    /// Not enough bytes yet.
    Incomplete,
    /// A request frame of `len` bytes with a good CRC: unit and PDU.
    Frame {
        /// Bytes the frame takes.
        len: usize,
        /// Unit id.
        unit: u8,
        /// The PDU.
        pdu: Vec<u8>,
    },
    /// A complete frame of `len` bytes whose CRC is wrong (a server stays silent).
    BadCrc {
        /// Bytes to drop.
        len: usize,
    },
    /// A function code whose request length is unknown: drop the buffer after a silence.
    Unknown,
}

/// Length of a request frame from its first bytes (RTU has no length field: it follows
/// from the function code).
fn rtu_request_len(buf: &[u8]) -> Option<Option<usize>> {
    let fc = *buf.get(1)?;
    Some(match fc {
        1..=6 => Some(8),
        15 | 16 => Some(9 + usize::from(*buf.get(6)?)),
        22 => Some(10),
        _ => None,
    })
}

/// Parses the head of an RTU receive buffer.
pub fn parse_rtu_request(buf: &[u8]) -> RtuRequest {
    let len = match rtu_request_len(buf) {
        None => return RtuRequest::Incomplete,
        Some(None) => return RtuRequest::Unknown,
        Some(Some(n)) => n,
    };
    if buf.len() < len {
        return RtuRequest::Incomplete;
    }
    let body = &buf[..len - 2];
    let got = u16::from_le_bytes([buf[len - 2], buf[len - 1]]);
    if crc16(body) != got {
        return RtuRequest::BadCrc { len };
    }
    RtuRequest::Frame {
        len,
        unit: body[0],
        pdu: body[1..].to_vec(),
    }
}

/// A Modbus TCP request: transaction id, unit and PDU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TcpRequest {
    /// Transaction identifier (echoed).
    pub transaction: u16,
    /// Unit id.
    pub unit: u8,
    /// The PDU.
    pub pdu: Vec<u8>,
}

/// Why a TCP frame header is unusable (the connection should be closed).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TcpFrameError {
    /// Protocol identifier other than 0.
    #[error("protocol id {0} is not Modbus (0)")]
    Protocol(u16),
    /// Length field outside 2..=254.
    #[error("MBAP length {0} outside 2..=254")]
    Length(u16),
}

/// Parses the head of a TCP receive buffer: `Ok(None)` while incomplete, else the request
/// and the bytes it took.
pub fn parse_tcp_request(buf: &[u8]) -> Result<Option<(TcpRequest, usize)>, TcpFrameError> {
    let (Some(transaction), Some(proto), Some(len)) = (be16(buf, 0), be16(buf, 2), be16(buf, 4))
    else {
        return Ok(None);
    };
    if proto != 0 {
        return Err(TcpFrameError::Protocol(proto));
    }
    if !(2..=254).contains(&len) {
        return Err(TcpFrameError::Length(len));
    }
    let total = 6 + usize::from(len);
    if buf.len() < total {
        return Ok(None);
    }
    Ok(Some((
        TcpRequest {
            transaction,
            unit: buf[6],
            pdu: buf[7..total].to_vec(),
        },
        total,
    )))
}

/// A Modbus TCP response frame.
pub fn tcp_frame(transaction: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(7 + pdu.len());
    f.extend_from_slice(&transaction.to_be_bytes());
    f.extend_from_slice(&0u16.to_be_bytes());
    f.extend_from_slice(&((pdu.len() + 1) as u16).to_be_bytes());
    f.push(unit);
    f.extend_from_slice(pdu);
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_and_writes_every_table() {
        let mut t = Tables::new(16);
        t.set(Table::DiscreteInput, 9, 1);
        assert_eq!(t.handle(&[2, 0, 8, 0, 3]), vec![2, 1, 0b010]);
        assert_eq!(t.handle(&[5, 0, 3, 0xFF, 0]), vec![5, 0, 3, 0xFF, 0]);
        assert_eq!(t.handle(&[1, 0, 0, 0, 10]), vec![1, 2, 0b1000, 0]);
        assert_eq!(
            t.handle(&[16, 0, 2, 0, 2, 4, 1, 2, 3, 4]),
            vec![16, 0, 2, 0, 2]
        );
        assert_eq!(t.handle(&[3, 0, 2, 0, 2]), vec![3, 4, 1, 2, 3, 4]);
        assert_eq!(
            t.handle(&[15, 0, 0, 0, 9, 2, 0xFF, 1]),
            vec![15, 0, 0, 0, 9]
        );
        assert!(t.coils[..9].iter().all(|&c| c));
        assert_eq!(
            t.handle(&[22, 0, 2, 0xFF, 0x00, 0x00, 0x0F]),
            vec![22, 0, 2, 0xFF, 0, 0, 0x0F]
        );
        assert_eq!(t.holding[2], 0x010F);
        t.set(Table::InputRegister, 0, 0xBEEF);
        assert_eq!(t.handle(&[4, 0, 0, 0, 1]), vec![4, 2, 0xBE, 0xEF]);
    }

    #[test]
    fn malformed_requests_get_exceptions_not_panics() {
        let mut t = Tables::new(8);
        assert_eq!(t.handle(&[]), vec![0x80, 1]);
        assert_eq!(t.handle(&[3]), vec![0x83, 3], "short request");
        assert_eq!(t.handle(&[3, 0, 0, 0, 0]), vec![0x83, 3], "zero quantity");
        assert_eq!(t.handle(&[3, 0, 7, 0, 2]), vec![0x83, 2], "past the table");
        assert_eq!(
            t.handle(&[5, 0, 0, 0x12, 0x34]),
            vec![0x85, 3],
            "bad coil value"
        );
        assert_eq!(
            t.handle(&[16, 0, 0, 0, 2, 4, 1]),
            vec![0x90, 3],
            "short data"
        );
        assert_eq!(
            t.handle(&[16, 0, 0, 0, 2, 2, 1, 2]),
            vec![0x90, 3],
            "count mismatch"
        );
        assert_eq!(t.handle(&[0x2B, 0, 0, 0, 0]), vec![0xAB, 1]);
        assert_eq!(t.handle(&[6, 0xFF, 0xFF, 0, 1]), vec![0x86, 2]);
    }

    #[test]
    fn rtu_framing_checks_the_crc() {
        // Read holding registers 0..2 of unit 1: the classic example frame.
        let f = rtu_frame(1, &[3, 0, 0, 0, 2]);
        assert_eq!(f, [1, 3, 0, 0, 0, 2, 0xC4, 0x0B]);
        assert_eq!(
            parse_rtu_request(&f),
            RtuRequest::Frame {
                len: 8,
                unit: 1,
                pdu: vec![3, 0, 0, 0, 2]
            }
        );
        assert_eq!(parse_rtu_request(&f[..5]), RtuRequest::Incomplete);
        let mut bad = f.clone();
        bad[7] ^= 1;
        assert_eq!(parse_rtu_request(&bad), RtuRequest::BadCrc { len: 8 });
        assert_eq!(parse_rtu_request(&[1, 0x2B, 0]), RtuRequest::Unknown);
        let w = rtu_frame(2, &[16, 0, 0, 0, 1, 2, 0xAB, 0xCD]);
        assert!(matches!(
            parse_rtu_request(&w),
            RtuRequest::Frame {
                len: 11,
                unit: 2,
                ..
            }
        ));
    }

    #[test]
    fn tcp_framing() {
        let f = tcp_frame(7, 1, &[3, 0, 0, 0, 1]);
        assert_eq!(f, [0, 7, 0, 0, 0, 6, 1, 3, 0, 0, 0, 1]);
        let (req, n) = parse_tcp_request(&f).unwrap().unwrap();
        assert_eq!((req.transaction, req.unit, n), (7, 1, 12));
        assert_eq!(parse_tcp_request(&f[..9]), Ok(None));
        assert_eq!(
            parse_tcp_request(&[0, 1, 0, 9, 0, 6, 1]),
            Err(TcpFrameError::Protocol(9))
        );
        assert_eq!(
            parse_tcp_request(&[0, 1, 0, 0, 0xFF, 0xFF, 1]),
            Err(TcpFrameError::Length(0xFFFF))
        );
    }
}
