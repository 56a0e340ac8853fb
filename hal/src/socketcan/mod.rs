//! [`CanBus`] on a Linux SocketCAN raw socket (the `socketcan` crate).
//!
//! [`SocketCanBus`] owns one non-blocking raw socket bound to one interface (`can0`,
//! `vcan0`). Sends and receives never block, so the servo thread can drain the socket every
//! cycle; neither allocates. Bus health reaches the caller as errors naming the interface:
//!
//! * error frames are enabled and decoded: bus-off ([`ErrorKind::Disconnected`](crate::ErrorKind::Disconnected)),
//!   error-passive and lost frames (controller problems), no acknowledge
//!   ([`ErrorKind::Timeout`](crate::ErrorKind::Timeout)), protocol and transceiver faults;
//!   harmless state changes (back to error-active, warning level, restarted) only update
//!   [`SocketCanBus::state`] and are not errors;
//! * an interface that is down (`ENETDOWN`) or gone (`ENODEV`) is
//!   [`ErrorKind::Disconnected`](crate::ErrorKind::Disconnected);
//! * a full transmit queue (`ENOBUFS`, or `EAGAIN` from the socket's send buffer) is
//!   [`ErrorKind::WouldBlock`](crate::ErrorKind::WouldBlock): the frame was not sent, retry later.
//!
//! [`SocketCanBus::set_filters`] makes the kernel deliver only the COB-IDs a user needs, so a
//! socket per purpose (the servo thread's PDOs, a non-realtime SDO tool) reads nothing else.
//! Frames other sockets on the same host send are received (SocketCAN's loopback); the
//! socket's own frames are not.

mod error;

pub use error::SocketCanError;

use crate::can::{CanBus, CanFrame, CanId};
use crate::error::ErrorType;
use core::fmt;
use socketcan::errors::ControllerProblems;
use socketcan::{
    CanDataFrame, CanError, CanFilter, CanRemoteFrame, CanSocket, EmbeddedFrame, ErrorCause,
    ExtendedId, Id, Socket, SocketOptions, StandardId,
};
use std::os::fd::{AsRawFd, RawFd};

/// An interface name (at most 15 bytes, the kernel's `IFNAMSIZ - 1`), stored inline so that
/// errors carrying it are built without allocating.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct IfName {
    buf: [u8; 15],
    len: u8,
}

impl IfName {
    /// The name, or `None` when it is empty, longer than 15 bytes or contains `/`, a space
    /// or a NUL (which no interface name can).
    pub fn new(name: &str) -> Option<IfName> {
        let b = name.as_bytes();
        if b.is_empty() || b.len() > 15 || b.iter().any(|&c| c == b'/' || c == 0 || c == b' ') {
            return None;
        }
        let mut buf = [0u8; 15];
        buf[..b.len()].copy_from_slice(b);
        // Cannot truncate: at most 15.
        Some(IfName {
            buf,
            len: b.len() as u8,
        })
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        // Built from a &str and cut at its end, so always valid UTF-8.
        core::str::from_utf8(&self.buf[..usize::from(self.len)]).unwrap_or("?")
    }
}

impl fmt::Display for IfName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Debug for IfName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

/// The controller's error state as last reported by error frames (CAN's fault
/// confinement: active → warning (96) → passive (128) → bus-off (256)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum BusState {
    /// Normal operation.
    ErrorActive,
    /// An error counter passed the warning level; still working.
    ErrorWarning,
    /// An error counter passed 128: the node may no longer signal errors actively.
    ErrorPassive,
    /// The controller left the bus.
    BusOff,
}

/// Which received frames the kernel delivers to this socket: a frame passes when
/// `received_id & mask == id & mask`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IdFilter {
    id: CanId,
    mask: u32,
}

impl IdFilter {
    /// Exactly this identifier (data and remote frames; a standard id never matches an
    /// extended one of the same number).
    pub fn exact(id: CanId) -> IdFilter {
        let mask = if id.is_extended() {
            crate::can::MAX_EXTENDED_ID
        } else {
            crate::can::MAX_STANDARD_ID
        };
        IdFilter { id, mask }
    }

    /// Identifiers equal to `id` in the bits of `mask` (e.g. `0x580` with mask `0x780`:
    /// every SDO response, 0x580..=0x5FF).
    pub fn masked(id: CanId, mask: u32) -> IdFilter {
        IdFilter { id, mask }
    }

    fn to_kernel(self) -> CanFilter {
        let eff = if self.id.is_extended() {
            libc::CAN_EFF_FLAG
        } else {
            0
        };
        // Matching the EFF flag too keeps standard and extended ids apart.
        CanFilter::new(self.id.raw() | eff, self.mask | libc::CAN_EFF_FLAG)
    }
}

/// A [`CanBus`] on one SocketCAN interface. See the module doc.
#[derive(Debug)]
pub struct SocketCanBus {
    sock: CanSocket,
    iface: IfName,
    state: BusState,
    error_frames: u64,
}

impl SocketCanBus {
    /// Opens a non-blocking raw socket on `iface` with every error class enabled and every
    /// frame accepted (narrow it with [`set_filters`](SocketCanBus::set_filters)).
    pub fn open(iface: &str) -> Result<SocketCanBus, SocketCanError> {
        let name = IfName::new(iface).ok_or_else(|| SocketCanError::BadName {
            name: iface.to_owned(),
        })?;
        let io = |op| move |e| SocketCanError::from_io(name, op, e);
        let sock = CanSocket::open(iface).map_err(io("open"))?;
        sock.set_nonblocking(true).map_err(io("set non-blocking"))?;
        sock.set_error_filter_accept_all()
            .map_err(io("enable error frames"))?;
        Ok(SocketCanBus {
            sock,
            iface: name,
            state: BusState::ErrorActive,
            error_frames: 0,
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        self.iface.as_str()
    }

    /// The controller state from the last error frames.
    pub fn state(&self) -> BusState {
        self.state
    }

    /// How many error frames were received.
    pub fn error_frames(&self) -> u64 {
        self.error_frames
    }

    /// Delivers only frames that pass one of `filters` (error frames are always
    /// delivered). An empty slice receives no frames at all.
    pub fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), SocketCanError> {
        let k: Vec<CanFilter> = filters.iter().map(|f| f.to_kernel()).collect();
        self.sock
            .set_filters(&k)
            .map_err(|e| SocketCanError::from_io(self.iface, "set filters", e))
    }

    /// Receives every frame again (the state after [`open`](SocketCanBus::open)).
    pub fn accept_all(&mut self) -> Result<(), SocketCanError> {
        self.sock
            .set_filter_accept_all()
            .map_err(|e| SocketCanError::from_io(self.iface, "set filters", e))
    }
}

/// Decodes an error frame: `Some(error)` for a condition the caller must see, `None`
/// for a state change that needs no action (recorded in `state`).
fn decode_error(iface: IfName, err: &CanError, state: &mut BusState) -> Option<SocketCanError> {
    let mut worst: Option<SocketCanError> = None;
    let mut rank = 0;
    let mut keep = |r: u8, e: SocketCanError, worst: &mut Option<SocketCanError>| {
        if r > rank {
            rank = r;
            *worst = Some(e);
        }
    };
    for cause in err.causes() {
        match *cause {
            ErrorCause::BusOff => {
                *state = BusState::BusOff;
                keep(6, SocketCanError::BusOff { iface }, &mut worst);
            }
            ErrorCause::Restarted => *state = BusState::ErrorActive,
            ErrorCause::Controller(p) => {
                if p.intersects(ControllerProblems::RX_PASSIVE | ControllerProblems::TX_PASSIVE) {
                    *state = BusState::ErrorPassive;
                    keep(
                        5,
                        SocketCanError::ErrorPassive { iface, problems: p },
                        &mut worst,
                    );
                } else if p
                    .intersects(ControllerProblems::RX_WARNING | ControllerProblems::TX_WARNING)
                {
                    *state = BusState::ErrorWarning;
                } else if p.contains(ControllerProblems::ACTIVE) {
                    *state = BusState::ErrorActive;
                }
                if p.intersects(ControllerProblems::RX_OVERFLOW | ControllerProblems::TX_OVERFLOW) {
                    keep(
                        4,
                        SocketCanError::Controller { iface, problems: p },
                        &mut worst,
                    );
                }
            }
            ErrorCause::NoAck | ErrorCause::TransmitTimeout => {
                keep(3, SocketCanError::NoAck { iface }, &mut worst);
            }
            ErrorCause::Counters { .. } | ErrorCause::LostArbitration(_) => {}
            other => keep(
                2,
                SocketCanError::ErrorFrame {
                    iface,
                    cause: other,
                },
                &mut worst,
            ),
        }
    }
    worst
}

/// The hal frame as a SocketCAN frame.
fn to_socketcan(iface: IfName, f: &CanFrame) -> Result<socketcan::CanFrame, SocketCanError> {
    let bad = |what| SocketCanError::BadFrame { iface, what };
    let id: Id = if f.id().is_extended() {
        ExtendedId::new(f.id().raw())
            .ok_or(bad("extended id out of range"))?
            .into()
    } else {
        // Cannot truncate: a standard CanId is at most 0x7FF.
        StandardId::new(f.id().raw() as u16)
            .ok_or(bad("standard id out of range"))?
            .into()
    };
    if f.is_remote() {
        CanRemoteFrame::new_remote(id, usize::from(f.dlc()))
            .map(socketcan::CanFrame::Remote)
            .ok_or(bad("remote frame dlc"))
    } else {
        CanDataFrame::new(id, f.data())
            .map(socketcan::CanFrame::Data)
            .ok_or(bad("data longer than 8 bytes"))
    }
}

/// A received SocketCAN data or remote frame as a hal frame.
fn from_socketcan(iface: IfName, f: &socketcan::CanFrame) -> Result<CanFrame, SocketCanError> {
    let bad = |what| SocketCanError::BadFrame { iface, what };
    let id = match EmbeddedFrame::id(f) {
        Id::Standard(s) => CanId::standard(s.as_raw()),
        Id::Extended(e) => CanId::extended(e.as_raw()),
    }
    .map_err(|_| bad("identifier"))?;
    if f.is_remote_frame() {
        // Cannot truncate: socketcan clamps the dlc to 8.
        CanFrame::remote(id, f.dlc() as u8).map_err(|_| bad("remote frame dlc"))
    } else {
        CanFrame::new(id, EmbeddedFrame::data(f)).map_err(|_| bad("data longer than 8 bytes"))
    }
}

impl ErrorType for SocketCanBus {
    type Error = SocketCanError;
}

impl CanBus for SocketCanBus {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SocketCanError> {
        let f = to_socketcan(self.iface, frame)?;
        self.sock
            .write_frame(&f)
            .map_err(|e| SocketCanError::from_io(self.iface, "send", e))
    }

    fn try_recv(&mut self) -> Result<Option<CanFrame>, SocketCanError> {
        loop {
            let f = match self.sock.read_frame() {
                Ok(f) => f,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(None),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(SocketCanError::from_io(self.iface, "receive", e)),
            };
            match f {
                socketcan::CanFrame::Error(ef) => {
                    self.error_frames += 1;
                    if let Some(e) = decode_error(self.iface, &ef.into_error(), &mut self.state) {
                        return Err(e);
                    }
                }
                other => return from_socketcan(self.iface, &other).map(Some),
            }
        }
    }
}

impl AsRawFd for SocketCanBus {
    /// The socket, for `poll(2)` by a thread that waits for frames.
    fn as_raw_fd(&self) -> RawFd {
        self.sock.as_raw_fd()
    }
}

#[cfg(test)]
mod tests;
