//! The SDO server: answers one client on one node's channel from an object dictionary
//! reached through [`ObjectAccess`]. Expedited, segmented and block transfer, both
//! directions. A block upload sends a whole sub-block per request: [`SdoServer::on_frame`]
//! returns its first segment and [`SdoServer::next_burst`] the others, so the caller can
//! pace them to its transmit queue.
//!
//! The server allocates once, when it is made: one value buffer of [`MAX_SEGMENTED`] bytes
//! that every transfer (upload value, download data) uses in turn. Answering a request
//! then allocates nothing as long as the object dictionary appends within that capacity,
//! so a drive (the loopback drive) can serve SDO on the same thread as its PDOs.

use super::block::{self, RxStep, SubBlockRx, SubBlockTx, BLKSIZE, CRC_SUPPORTED, END_CONFIRM};
use super::{abort_frame, initiate, multiplexer, sdo_frame, SdoAbortCode, DEFAULT_TIMEOUT, TX};
use crate::can::CanFrame;
use crate::canopen::NodeId;
use std::time::Duration;

/// The largest segmented download the server buffers (a client without size indication
/// cannot make it grow without bound).
pub const MAX_SEGMENTED: usize = 1 << 16;

/// An object dictionary as the SDO server sees it: values as little-endian bytes.
pub trait ObjectAccess {
    /// Appends the value of `index:sub` to `out` (empty, with capacity for
    /// [`MAX_SEGMENTED`] bytes), or says why it cannot be read.
    fn read(&mut self, index: u16, sub: u8, out: &mut Vec<u8>) -> Result<(), SdoAbortCode>;
    /// Stores `data` in `index:sub`, or says why not (wrong length, read-only, range…).
    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode>;
}

/// Where a transfer stands. The value itself (download data received so far, or the
/// upload value) is in the server's one buffer.
#[derive(Debug, Clone)]
enum Phase {
    Idle,
    Down {
        size: Option<usize>,
        toggle: bool,
    },
    Up {
        pos: usize,
        toggle: bool,
    },
    BlkDown {
        size: Option<usize>,
        crc: bool,
        rx: SubBlockRx,
    },
    BlkDownEnd {
        size: Option<usize>,
        crc: bool,
    },
    /// Block upload initiated, waiting for the client's start.
    BlkUpInit {
        tx: SubBlockTx,
    },
    /// Sending (`next` is the next segment number of the sub-block) or waiting for the
    /// acknowledgement of a sub-block.
    BlkUp {
        tx: SubBlockTx,
        next: u8,
    },
    BlkUpEnd,
}

/// An SDO server for the node `node`.
#[derive(Debug, Clone)]
pub struct SdoServer {
    node: NodeId,
    timeout: Duration,
    index: u16,
    sub: u8,
    deadline: Duration,
    phase: Phase,
    /// The value of the transfer in progress (capacity [`MAX_SEGMENTED`] + one segment,
    /// allocated once).
    buf: Vec<u8>,
}

impl SdoServer {
    /// A server for `node` with [`DEFAULT_TIMEOUT`] between segments.
    pub fn new(node: NodeId) -> SdoServer {
        SdoServer {
            node,
            timeout: DEFAULT_TIMEOUT,
            index: 0,
            sub: 0,
            deadline: Duration::ZERO,
            phase: Phase::Idle,
            buf: Vec::with_capacity(MAX_SEGMENTED + 8),
        }
    }

    fn abort(&mut self, code: SdoAbortCode) -> Option<CanFrame> {
        self.phase = Phase::Idle;
        Some(abort_frame(self.node, TX, self.index, self.sub, code))
    }

    fn reply(&mut self, data: [u8; 8], now: Duration) -> Option<CanFrame> {
        self.deadline = now + self.timeout;
        Some(sdo_frame(self.node, TX, data))
    }

    /// A server for `node` that aborts a transfer whose client is silent for `timeout`.
    pub fn with_timeout(node: NodeId, timeout: Duration) -> SdoServer {
        SdoServer {
            timeout,
            ..SdoServer::new(node)
        }
    }

    /// A segmented transfer whose client went silent is aborted with 0x05040000. While a
    /// block upload's sub-block is still going out, the client is not late: the wait
    /// for its acknowledgement counts from the last poll with segments left to send.
    pub fn poll(&mut self, now: Duration) -> Option<CanFrame> {
        let data = &self.buf;
        let sending =
            matches!(&self.phase, Phase::BlkUp { tx, next } if tx.segment(data, *next).is_some());
        if sending {
            self.deadline = now + self.timeout;
        }
        if !matches!(self.phase, Phase::Idle) && now > self.deadline {
            return self.abort(SdoAbortCode::ProtocolTimedOut);
        }
        None
    }

    /// The next segment of a block upload's sub-block, until the sub-block is out. Call it
    /// after [`SdoServer::on_frame`] (and again later if the transmit queue was full).
    pub fn next_burst(&mut self) -> Option<CanFrame> {
        let Phase::BlkUp { tx, next } = &mut self.phase else {
            return None;
        };
        let seg = tx.segment(&self.buf, *next)?;
        *next += 1;
        Some(sdo_frame(self.node, TX, seg))
    }

    /// Frames of a running block transfer: `Some(reply)` when the frame belonged to it.
    /// (In a block download every frame of the sub-block is a segment, whatever its first
    /// byte.) The CRC is checked when the client announced it (this server always
    /// computes it).
    fn on_block_frame(
        &mut self,
        d: &[u8],
        now: Duration,
        od: &mut impl ObjectAccess,
    ) -> Option<Option<CanFrame>> {
        let cmd = d[0];
        let reply = match core::mem::replace(&mut self.phase, Phase::Idle) {
            Phase::BlkDown { size, crc, mut rx } => {
                if self.buf.len() > MAX_SEGMENTED {
                    return Some(self.abort(SdoAbortCode::OutOfMemory));
                }
                let step = rx.on_segment(d, &mut self.buf);
                let ack = matches!(step, RxStep::Ack(_));
                self.phase = if rx.last && ack {
                    Phase::BlkDownEnd { size, crc }
                } else {
                    Phase::BlkDown { size, crc, rx }
                };
                match step {
                    RxStep::Ack(a) => self.reply(a, now),
                    RxStep::More => {
                        self.deadline = now + self.timeout;
                        None
                    }
                }
            }
            Phase::BlkDownEnd { size, crc } if cmd & 0xE1 == 0xC1 => {
                if let Err(code) = block::finish(d, &mut self.buf, size, crc) {
                    return Some(self.abort(code));
                }
                match od.write(self.index, self.sub, &self.buf) {
                    Ok(()) => self.reply([END_CONFIRM, 0, 0, 0, 0, 0, 0, 0], now),
                    Err(code) => self.abort(code),
                }
            }
            Phase::BlkUpInit { tx } if cmd == 0xA3 => {
                self.phase = Phase::BlkUp { tx, next: 1 };
                self.deadline = now + self.timeout;
                self.next_burst()
            }
            Phase::BlkUp { mut tx, .. } if cmd & 0xE3 == block::ACK => {
                match tx.on_ack(d, &self.buf) {
                    Err(code) => self.abort(code),
                    Ok(true) => {
                        self.phase = Phase::BlkUpEnd;
                        self.reply(block::end_frame(&self.buf), now)
                    }
                    Ok(false) => {
                        self.phase = Phase::BlkUp { tx, next: 1 };
                        self.deadline = now + self.timeout;
                        self.next_burst()
                    }
                }
            }
            Phase::BlkUpEnd if cmd == END_CONFIRM => None,
            other => {
                self.phase = other;
                return None;
            }
        };
        Some(reply)
    }

    /// Handles a frame; returns the response to send, if any.
    pub fn on_frame(
        &mut self,
        f: &CanFrame,
        now: Duration,
        od: &mut impl ObjectAccess,
    ) -> Option<CanFrame> {
        if f.id().is_extended()
            || f.id().raw() != self.node.cob(super::RX).raw()
            || f.data().len() != 8
        {
            return None;
        }
        let d = f.data();
        let cmd = d[0];
        if cmd != 0x80 {
            if let Some(reply) = self.on_block_frame(d, now, od) {
                return reply;
            }
        }
        let toggle_bit = cmd & 0x10 != 0;
        match cmd >> 5 {
            // Initiate download.
            1 => {
                (self.index, self.sub) = multiplexer(d);
                let (index, sub) = (self.index, self.sub);
                if cmd & 0x02 != 0 {
                    let len = if cmd & 0x01 != 0 {
                        4 - usize::from((cmd >> 2) & 0x03)
                    } else {
                        4
                    };
                    self.phase = Phase::Idle;
                    return match od.write(index, sub, &d[4..4 + len]) {
                        Ok(()) => self.reply(initiate(0x60, index, sub, [0; 4]), now),
                        Err(code) => self.abort(code),
                    };
                }
                let size = (cmd & 0x01 != 0).then(|| {
                    usize::try_from(u32::from_le_bytes([d[4], d[5], d[6], d[7]]))
                        .unwrap_or(usize::MAX)
                });
                if size.is_some_and(|s| s > MAX_SEGMENTED) {
                    return self.abort(SdoAbortCode::OutOfMemory);
                }
                self.buf.clear();
                self.phase = Phase::Down {
                    size,
                    toggle: false,
                };
                self.reply(initiate(0x60, index, sub, [0; 4]), now)
            }
            // Download segment.
            0 => {
                let Phase::Down { size, toggle } = &mut self.phase else {
                    return self.abort(SdoAbortCode::InvalidCommandSpecifier);
                };
                let buf = &mut self.buf;
                if toggle_bit != *toggle {
                    return self.abort(SdoAbortCode::ToggleBitNotAlternated);
                }
                let unused = usize::from((cmd >> 1) & 0x07);
                if buf.len() > MAX_SEGMENTED {
                    return self.abort(SdoAbortCode::OutOfMemory);
                }
                buf.extend_from_slice(&d[1..8 - unused]);
                let t = *toggle;
                *toggle = !t;
                if size.is_some_and(|s| buf.len() > s) {
                    return self.abort(SdoAbortCode::LengthTooHigh);
                }
                if cmd & 0x01 != 0 {
                    if size.is_some_and(|s| buf.len() < s) {
                        return self.abort(SdoAbortCode::LengthTooLow);
                    }
                    self.phase = Phase::Idle;
                    if let Err(code) = od.write(self.index, self.sub, &self.buf) {
                        return self.abort(code);
                    }
                }
                self.reply([0x20 | (u8::from(t) << 4), 0, 0, 0, 0, 0, 0, 0], now)
            }
            // Initiate upload.
            2 => {
                (self.index, self.sub) = multiplexer(d);
                let (index, sub) = (self.index, self.sub);
                self.buf.clear();
                if let Err(code) = od.read(index, sub, &mut self.buf) {
                    return self.abort(code);
                }
                let data = &self.buf;
                if data.len() <= 4 {
                    let mut p = [0u8; 4];
                    p[..data.len()].copy_from_slice(data);
                    // Cannot truncate: len <= 4.
                    let n = (4 - data.len()) as u8;
                    self.phase = Phase::Idle;
                    return self.reply(initiate(0x43 | (n << 2), index, sub, p), now);
                }
                let Ok(size) = u32::try_from(data.len()) else {
                    return self.abort(SdoAbortCode::OutOfMemory);
                };
                self.phase = Phase::Up {
                    pos: 0,
                    toggle: false,
                };
                self.reply(initiate(0x41, index, sub, size.to_le_bytes()), now)
            }
            // Upload segment.
            3 => {
                let Phase::Up { pos, toggle } = &mut self.phase else {
                    return self.abort(SdoAbortCode::InvalidCommandSpecifier);
                };
                let data = &self.buf;
                if toggle_bit != *toggle {
                    return self.abort(SdoAbortCode::ToggleBitNotAlternated);
                }
                let end = (*pos + 7).min(data.len());
                let mut out = [0u8; 8];
                out[1..1 + end - *pos].copy_from_slice(&data[*pos..end]);
                // Cannot truncate: at most 7 bytes per segment.
                let unused = (7 - (end - *pos)) as u8;
                let last = end == data.len();
                out[0] = (u8::from(*toggle) << 4) | (unused << 1) | u8::from(last);
                *pos = end;
                *toggle = !*toggle;
                if last {
                    self.phase = Phase::Idle;
                }
                self.reply(out, now)
            }
            // Abort from the client: drop the transfer, no answer.
            4 => {
                self.phase = Phase::Idle;
                None
            }
            // Block upload initiate (the other block frames came in a block phase).
            5 if cmd & 0x03 == 0 => {
                (self.index, self.sub) = multiplexer(d);
                let (index, sub) = (self.index, self.sub);
                self.buf.clear();
                if let Err(code) = od.read(index, sub, &mut self.buf) {
                    return self.abort(code);
                }
                let pst = usize::from(d[5]);
                if pst > 0 && self.buf.len() <= pst {
                    // Protocol switch: a short value goes the normal way.
                    self.phase = Phase::Idle;
                    return self.on_frame(
                        &sdo_frame(self.node, super::RX, initiate(0x40, index, sub, [0; 4])),
                        now,
                        od,
                    );
                }
                let tx = match SubBlockTx::new(d[4]) {
                    Ok(tx) => tx,
                    Err(code) => return self.abort(code),
                };
                let Ok(size) = u32::try_from(self.buf.len()) else {
                    return self.abort(SdoAbortCode::OutOfMemory);
                };
                self.phase = Phase::BlkUpInit { tx };
                let cmd = 0xC0 | CRC_SUPPORTED | 0x02;
                self.reply(initiate(cmd, index, sub, size.to_le_bytes()), now)
            }
            // Block download initiate.
            6 if cmd & 0x01 == 0 => {
                (self.index, self.sub) = multiplexer(d);
                let (index, sub) = (self.index, self.sub);
                let size = (cmd & 0x02 != 0).then(|| {
                    usize::try_from(u32::from_le_bytes([d[4], d[5], d[6], d[7]]))
                        .unwrap_or(usize::MAX)
                });
                if size.is_some_and(|s| s > MAX_SEGMENTED) {
                    return self.abort(SdoAbortCode::OutOfMemory);
                }
                self.buf.clear();
                self.phase = Phase::BlkDown {
                    size,
                    crc: cmd & CRC_SUPPORTED != 0,
                    rx: SubBlockRx {
                        seq: 0,
                        last: false,
                    },
                };
                let i = index.to_le_bytes();
                self.reply(
                    [0xA0 | CRC_SUPPORTED, i[0], i[1], sub, BLKSIZE, 0, 0, 0],
                    now,
                )
            }
            // Anything else.
            _ => {
                (self.index, self.sub) = multiplexer(d);
                self.abort(SdoAbortCode::InvalidCommandSpecifier)
            }
        }
    }
}
