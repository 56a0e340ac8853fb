//! The SDO client: one transfer at a time on one node's channel, sans-IO. Start a transfer
//! with [`SdoClient::download`] / [`SdoClient::upload`] (they return the first frame to
//! send), feed every frame from the server to [`SdoClient::on_frame`], and call
//! [`SdoClient::poll`] with the time so a silent server becomes a timeout. Allocates (the
//! payload is a `Vec`): never call it from the servo step.
//!
//! Block transfer is used where the server offers it: a download longer than the block
//! threshold, and [`SdoClient::upload_block`], start as block transfers; a server that
//! answers abort 0x05040001 (command specifier unknown: no block support) gets the same
//! transfer again segmented, and this client does not try block with it again.

use super::block::{
    self, RxStep, SubBlockRx, SubBlockTx, BLKSIZE, CRC_SUPPORTED, DEFAULT_BLOCK_THRESHOLD,
    END_CONFIRM,
};
use super::{abort_frame, initiate, multiplexer, sdo_frame, SdoAbortCode, DEFAULT_TIMEOUT, RX, TX};
use crate::can::CanFrame;
use crate::canopen::{CanOpenError, NodeId};
use std::time::Duration;

#[derive(Debug, Clone)]
enum Phase {
    Idle,
    DownInit {
        data: Vec<u8>,
    },
    DownSeg {
        data: Vec<u8>,
        pos: usize,
        toggle: bool,
        last: bool,
    },
    UpInit,
    UpSeg {
        buf: Vec<u8>,
        size: Option<usize>,
        toggle: bool,
    },
    BlkDownInit {
        data: Vec<u8>,
    },
    BlkDownSub {
        data: Vec<u8>,
        tx: SubBlockTx,
    },
    BlkDownEnd,
    BlkUpInit,
    BlkUpSub {
        buf: Vec<u8>,
        size: Option<usize>,
        crc: bool,
        rx: SubBlockRx,
    },
    BlkUpEnd {
        buf: Vec<u8>,
        size: Option<usize>,
        crc: bool,
    },
}

/// What a frame (or the passing of time) did to the transfer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SdoStep {
    /// Not for this transfer (another COB-ID, or no transfer running).
    Ignored,
    /// Send this frame; the transfer continues.
    Send(CanFrame),
    /// The download finished: the server stored the value.
    Downloaded,
    /// The upload finished with this value.
    Uploaded(Vec<u8>),
    /// Send these frames in order (a sub-block of a block download); the transfer
    /// continues.
    SendBlock(Vec<CanFrame>),
    /// A block upload finished with `value`; send `confirm` (the client's end
    /// confirmation) so the server ends the transfer too.
    BlockUploaded {
        /// The value read.
        value: Vec<u8>,
        /// The end confirmation to send.
        confirm: CanFrame,
    },
    /// The transfer failed; send `abort` if given (the server does not know yet).
    Failed {
        /// Why, naming node and object.
        error: CanOpenError,
        /// The abort frame to send to the server.
        abort: Option<CanFrame>,
    },
}

/// An SDO client for one server node.
#[derive(Debug, Clone)]
pub struct SdoClient {
    node: NodeId,
    timeout: Duration,
    index: u16,
    sub: u8,
    deadline: Duration,
    phase: Phase,
    /// Values longer than this go by block transfer; `None`: never.
    block_threshold: Option<usize>,
    /// The server refused a block transfer (abort 0x05040001): segmented from now on.
    block_refused: bool,
}

impl SdoClient {
    /// A client for `node` with [`DEFAULT_TIMEOUT`].
    pub fn new(node: NodeId) -> SdoClient {
        SdoClient::with_timeout(node, DEFAULT_TIMEOUT)
    }

    /// A client for `node` that gives up when the server is silent for `timeout`.
    pub fn with_timeout(node: NodeId, timeout: Duration) -> SdoClient {
        SdoClient {
            node,
            timeout,
            index: 0,
            sub: 0,
            deadline: Duration::ZERO,
            phase: Phase::Idle,
            block_threshold: Some(DEFAULT_BLOCK_THRESHOLD),
            block_refused: false,
        }
    }

    /// Sets the length above which values go by block transfer (`None`: never use block
    /// transfer). The default is [`DEFAULT_BLOCK_THRESHOLD`].
    pub fn with_block_threshold(mut self, threshold: Option<usize>) -> SdoClient {
        self.block_threshold = threshold;
        self
    }

    /// True once the server refused a block transfer; later transfers go segmented.
    pub fn block_refused(&self) -> bool {
        self.block_refused
    }

    fn block_allowed(&self) -> bool {
        self.block_threshold.is_some() && !self.block_refused
    }

    /// The server node.
    pub fn node(&self) -> NodeId {
        self.node
    }

    /// True while a transfer runs.
    pub fn is_busy(&self) -> bool {
        !matches!(self.phase, Phase::Idle)
    }

    fn start(&mut self, index: u16, sub: u8, now: Duration) -> Result<(), CanOpenError> {
        if self.is_busy() {
            return Err(CanOpenError::SdoBusy {
                node: self.node,
                index: self.index,
                sub: self.sub,
            });
        }
        self.index = index;
        self.sub = sub;
        self.deadline = now + self.timeout;
        Ok(())
    }

    /// Starts writing `data` to `index:sub`: expedited up to 4 bytes, segmented above.
    /// Returns the initiate frame to send.
    pub fn download(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        now: Duration,
    ) -> Result<CanFrame, CanOpenError> {
        self.start(index, sub, now)?;
        if self.block_allowed() && self.block_threshold.is_some_and(|t| data.len() > t) {
            let size = self.size_of(data)?;
            self.phase = Phase::BlkDownInit {
                data: data.to_vec(),
            };
            let cmd = 0xC0 | CRC_SUPPORTED | 0x02;
            return Ok(sdo_frame(self.node, RX, initiate(cmd, index, sub, size)));
        }
        Ok(self.initiate_download(data.to_vec()))
    }

    fn size_of(&self, data: &[u8]) -> Result<[u8; 4], CanOpenError> {
        u32::try_from(data.len())
            .map(u32::to_le_bytes)
            .map_err(|_| CanOpenError::SdoAbort {
                node: self.node,
                index: self.index,
                sub: self.sub,
                abort: SdoAbortCode::OutOfMemory,
            })
    }

    /// The initiate frame of an expedited (up to 4 bytes) or segmented download.
    fn initiate_download(&mut self, data: Vec<u8>) -> CanFrame {
        let (index, sub) = (self.index, self.sub);
        let cmd_data = if data.len() <= 4 {
            let mut p = [0u8; 4];
            p[..data.len()].copy_from_slice(&data);
            // Cannot truncate: len <= 4. n = bytes of the 4 that carry no data; e = s = 1.
            let n = (4 - data.len()) as u8;
            initiate(0x20 | (n << 2) | 0x03, index, sub, p)
        } else {
            // Cannot truncate: download() checked the length with size_of.
            initiate(0x21, index, sub, (data.len() as u32).to_le_bytes())
        };
        self.phase = Phase::DownInit { data };
        sdo_frame(self.node, RX, cmd_data)
    }

    /// Starts reading `index:sub`. Returns the initiate frame to send.
    pub fn upload(&mut self, index: u16, sub: u8, now: Duration) -> Result<CanFrame, CanOpenError> {
        self.start(index, sub, now)?;
        self.phase = Phase::UpInit;
        Ok(sdo_frame(self.node, RX, initiate(0x40, index, sub, [0; 4])))
    }

    /// Starts reading `index:sub` by block upload, for values expected to be long. The
    /// protocol switch threshold is the block threshold: a server may answer a shorter
    /// value expedited or segmented. Without block transfer (disabled, or refused by this
    /// server before) this is [`SdoClient::upload`].
    pub fn upload_block(
        &mut self,
        index: u16,
        sub: u8,
        now: Duration,
    ) -> Result<CanFrame, CanOpenError> {
        let Some(threshold) = self.block_threshold.filter(|_| !self.block_refused) else {
            return self.upload(index, sub, now);
        };
        self.start(index, sub, now)?;
        self.phase = Phase::BlkUpInit;
        let pst = u8::try_from(threshold).unwrap_or(u8::MAX);
        let i = index.to_le_bytes();
        let cmd = [0xA0 | CRC_SUPPORTED, i[0], i[1], sub, BLKSIZE, pst, 0, 0];
        Ok(sdo_frame(self.node, RX, cmd))
    }

    /// Gives up a running transfer; returns the abort frame for the server.
    pub fn abort(&mut self, code: SdoAbortCode) -> Option<CanFrame> {
        if !self.is_busy() {
            return None;
        }
        self.phase = Phase::Idle;
        Some(abort_frame(self.node, RX, self.index, self.sub, code))
    }

    /// Checks the timeout at `now`: a transfer whose server has been silent past the
    /// timeout fails with [`CanOpenError::SdoTimeout`] and an abort 0x05040000 frame.
    pub fn poll(&mut self, now: Duration) -> Option<SdoStep> {
        if self.is_busy() && now > self.deadline {
            let abort = self.abort(SdoAbortCode::ProtocolTimedOut);
            return Some(SdoStep::Failed {
                error: CanOpenError::SdoTimeout {
                    node: self.node,
                    index: self.index,
                    sub: self.sub,
                    timeout_ms: u64::try_from(self.timeout.as_millis()).unwrap_or(u64::MAX),
                },
                abort,
            });
        }
        None
    }

    /// Ends the transfer on a protocol error (the phase may already be taken for
    /// processing, so the abort frame is built unconditionally).
    fn fail(&mut self, code: SdoAbortCode) -> SdoStep {
        self.phase = Phase::Idle;
        let abort = Some(abort_frame(self.node, RX, self.index, self.sub, code));
        SdoStep::Failed {
            error: CanOpenError::SdoAbort {
                node: self.node,
                index: self.index,
                sub: self.sub,
                abort: code,
            },
            abort,
        }
    }

    fn send(&mut self, data: [u8; 8], now: Duration) -> SdoStep {
        self.deadline = now + self.timeout;
        SdoStep::Send(sdo_frame(self.node, RX, data))
    }

    /// Handles a frame from the bus.
    pub fn on_frame(&mut self, f: &CanFrame, now: Duration) -> SdoStep {
        if !self.is_busy()
            || f.id().is_extended()
            || f.id().raw() != self.node.cob(TX).raw()
            || f.data().len() != 8
        {
            return SdoStep::Ignored;
        }
        let d = f.data();
        let cmd = d[0];
        if cmd == 0x80 {
            let code = SdoAbortCode::from_code(u32::from_le_bytes([d[4], d[5], d[6], d[7]]));
            if let Some(step) = self.fall_back(code, multiplexer(d), now) {
                return step;
            }
            self.phase = Phase::Idle;
            return SdoStep::Failed {
                error: CanOpenError::SdoAbort {
                    node: self.node,
                    index: self.index,
                    sub: self.sub,
                    abort: code,
                },
                abort: None,
            };
        }
        let scs = cmd >> 5;
        let toggle_bit = cmd & 0x10 != 0;
        match core::mem::replace(&mut self.phase, Phase::Idle) {
            Phase::Idle => SdoStep::Ignored,
            Phase::BlkDownInit { data } => self.on_block_download_init(d, data, now),
            Phase::BlkDownSub { data, mut tx } => match tx.on_ack(d, &data) {
                Err(code) => self.fail(code),
                Ok(true) => {
                    self.phase = Phase::BlkDownEnd;
                    self.send(block::end_frame(&data), now)
                }
                Ok(false) => self.send_sub_block(data, tx, now),
            },
            Phase::BlkDownEnd => {
                if cmd & 0xE3 != END_CONFIRM {
                    return self.fail(SdoAbortCode::InvalidCommandSpecifier);
                }
                SdoStep::Downloaded
            }
            Phase::BlkUpInit if scs == 2 => {
                // The server switched to the normal protocol (value up to the threshold).
                self.phase = Phase::UpInit;
                self.on_frame(f, now)
            }
            Phase::BlkUpInit => {
                if cmd & 0xE1 != 0xC0 {
                    return self.fail(SdoAbortCode::InvalidCommandSpecifier);
                }
                if multiplexer(d) != (self.index, self.sub) {
                    return self.fail(SdoAbortCode::GeneralError);
                }
                let size = (cmd & 0x02 != 0).then(|| {
                    usize::try_from(u32::from_le_bytes([d[4], d[5], d[6], d[7]]))
                        .unwrap_or(usize::MAX)
                });
                self.phase = Phase::BlkUpSub {
                    buf: Vec::with_capacity(size.unwrap_or(0).min(1 << 16)),
                    size,
                    crc: cmd & CRC_SUPPORTED != 0,
                    rx: SubBlockRx {
                        seq: 0,
                        last: false,
                    },
                };
                self.send([0xA3, 0, 0, 0, 0, 0, 0, 0], now)
            }
            Phase::BlkUpSub {
                mut buf,
                size,
                crc,
                mut rx,
            } => {
                let step = rx.on_segment(d, &mut buf);
                if size.is_some_and(|s| buf.len() > s + 7) {
                    return self.fail(SdoAbortCode::LengthTooHigh);
                }
                self.phase = if rx.last && matches!(step, RxStep::Ack(_)) {
                    Phase::BlkUpEnd { buf, size, crc }
                } else {
                    Phase::BlkUpSub { buf, size, crc, rx }
                };
                match step {
                    RxStep::More => {
                        self.deadline = now + self.timeout;
                        SdoStep::Ignored
                    }
                    RxStep::Ack(ack) => self.send(ack, now),
                }
            }
            Phase::BlkUpEnd { mut buf, size, crc } => {
                if let Err(code) = block::finish(d, &mut buf, size, crc) {
                    return self.fail(code);
                }
                SdoStep::BlockUploaded {
                    value: buf,
                    confirm: sdo_frame(self.node, RX, [END_CONFIRM, 0, 0, 0, 0, 0, 0, 0]),
                }
            }
            Phase::DownInit { data } => {
                if scs != 3 {
                    return self.fail(SdoAbortCode::InvalidCommandSpecifier);
                }
                if multiplexer(d) != (self.index, self.sub) {
                    return self.fail(SdoAbortCode::GeneralError);
                }
                if data.len() <= 4 {
                    return SdoStep::Downloaded;
                }
                self.next_segment(data, 0, false, now)
            }
            Phase::DownSeg {
                data,
                pos,
                toggle,
                last,
            } => {
                if scs != 1 {
                    return self.fail(SdoAbortCode::InvalidCommandSpecifier);
                }
                if toggle_bit != toggle {
                    return self.fail(SdoAbortCode::ToggleBitNotAlternated);
                }
                if last {
                    SdoStep::Downloaded
                } else {
                    self.next_segment(data, pos, !toggle, now)
                }
            }
            Phase::UpInit => {
                if scs != 2 {
                    return self.fail(SdoAbortCode::InvalidCommandSpecifier);
                }
                if multiplexer(d) != (self.index, self.sub) {
                    return self.fail(SdoAbortCode::GeneralError);
                }
                let expedited = cmd & 0x02 != 0;
                let sized = cmd & 0x01 != 0;
                if expedited {
                    let len = if sized {
                        4 - usize::from((cmd >> 2) & 0x03)
                    } else {
                        4
                    };
                    return SdoStep::Uploaded(d[4..4 + len].to_vec());
                }
                let size = sized.then(|| {
                    usize::try_from(u32::from_le_bytes([d[4], d[5], d[6], d[7]]))
                        .unwrap_or(usize::MAX)
                });
                self.phase = Phase::UpSeg {
                    buf: Vec::with_capacity(size.unwrap_or(0).min(1 << 16)),
                    size,
                    toggle: false,
                };
                self.send([0x60, 0, 0, 0, 0, 0, 0, 0], now)
            }
            Phase::UpSeg {
                mut buf,
                size,
                toggle,
            } => {
                if scs != 0 {
                    return self.fail(SdoAbortCode::InvalidCommandSpecifier);
                }
                if toggle_bit != toggle {
                    return self.fail(SdoAbortCode::ToggleBitNotAlternated);
                }
                let unused = usize::from((cmd >> 1) & 0x07);
                buf.extend_from_slice(&d[1..8 - unused]);
                if size.is_some_and(|s| buf.len() > s) {
                    return self.fail(SdoAbortCode::LengthTooHigh);
                }
                if cmd & 0x01 != 0 {
                    if size.is_some_and(|s| buf.len() != s) {
                        return self.fail(SdoAbortCode::LengthTooLow);
                    }
                    return SdoStep::Uploaded(buf);
                }
                let next = !toggle;
                self.phase = Phase::UpSeg {
                    buf,
                    size,
                    toggle: next,
                };
                self.send([0x60 | (u8::from(next) << 4), 0, 0, 0, 0, 0, 0, 0], now)
            }
        }
    }

    /// A server without block transfer aborted our block initiate with 0x05040001: start
    /// the same transfer again with the normal protocol.
    fn fall_back(&mut self, code: SdoAbortCode, mux: (u16, u8), now: Duration) -> Option<SdoStep> {
        if code != SdoAbortCode::InvalidCommandSpecifier || mux != (self.index, self.sub) {
            return None;
        }
        let f = match core::mem::replace(&mut self.phase, Phase::Idle) {
            Phase::BlkDownInit { data } => self.initiate_download(data),
            Phase::BlkUpInit => {
                self.phase = Phase::UpInit;
                sdo_frame(self.node, RX, initiate(0x40, self.index, self.sub, [0; 4]))
            }
            other => {
                self.phase = other;
                return None;
            }
        };
        self.block_refused = true;
        self.deadline = now + self.timeout;
        Some(SdoStep::Send(f))
    }

    fn on_block_download_init(&mut self, d: &[u8], data: Vec<u8>, now: Duration) -> SdoStep {
        if d[0] & 0xE3 != 0xA0 {
            return self.fail(SdoAbortCode::InvalidCommandSpecifier);
        }
        if multiplexer(d) != (self.index, self.sub) {
            return self.fail(SdoAbortCode::GeneralError);
        }
        match SubBlockTx::new(d[4]) {
            Ok(tx) => self.send_sub_block(data, tx, now),
            Err(code) => self.fail(code),
        }
    }

    /// Sends the segments of the current sub-block at once; the server acknowledges them
    /// together.
    fn send_sub_block(&mut self, data: Vec<u8>, tx: SubBlockTx, now: Duration) -> SdoStep {
        let frames = (1..=tx.blksize)
            .map_while(|s| tx.segment(&data, s))
            .map(|seg| sdo_frame(self.node, RX, seg))
            .collect();
        self.phase = Phase::BlkDownSub { data, tx };
        self.deadline = now + self.timeout;
        SdoStep::SendBlock(frames)
    }

    fn next_segment(&mut self, data: Vec<u8>, pos: usize, toggle: bool, now: Duration) -> SdoStep {
        let end = (pos + 7).min(data.len());
        let chunk = &data[pos..end];
        let last = end == data.len();
        let mut out = [0u8; 8];
        out[1..1 + chunk.len()].copy_from_slice(chunk);
        // Cannot truncate: chunk.len() <= 7.
        let unused = (7 - chunk.len()) as u8;
        out[0] = (u8::from(toggle) << 4) | (unused << 1) | u8::from(last);
        self.phase = Phase::DownSeg {
            data,
            pos: end,
            toggle,
            last,
        };
        self.send(out, now)
    }
}
