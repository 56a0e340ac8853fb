//! The SDO client: one transfer at a time on one node's channel, sans-IO. Start a transfer
//! with [`SdoClient::download`] / [`SdoClient::upload`] (they return the first frame to
//! send), feed every frame from the server to [`SdoClient::on_frame`], and call
//! [`SdoClient::poll`] with the time so a silent server becomes a timeout. Allocates (the
//! payload is a `Vec`): never call it from the servo step.

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
        }
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
        let cmd_data = if data.len() <= 4 {
            let mut p = [0u8; 4];
            p[..data.len()].copy_from_slice(data);
            // Cannot truncate: len <= 4. n = bytes of the 4 that carry no data; e = s = 1.
            let n = (4 - data.len()) as u8;
            initiate(0x20 | (n << 2) | 0x03, index, sub, p)
        } else {
            let size = u32::try_from(data.len()).map_err(|_| CanOpenError::SdoAbort {
                node: self.node,
                index,
                sub,
                abort: SdoAbortCode::OutOfMemory,
            })?;
            initiate(0x21, index, sub, size.to_le_bytes())
        };
        self.phase = Phase::DownInit {
            data: data.to_vec(),
        };
        Ok(sdo_frame(self.node, RX, cmd_data))
    }

    /// Starts reading `index:sub`. Returns the initiate frame to send.
    pub fn upload(&mut self, index: u16, sub: u8, now: Duration) -> Result<CanFrame, CanOpenError> {
        self.start(index, sub, now)?;
        self.phase = Phase::UpInit;
        Ok(sdo_frame(self.node, RX, initiate(0x40, index, sub, [0; 4])))
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
