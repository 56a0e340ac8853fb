//! Start-up of the drives of one interface, on the non-realtime path before the servo
//! thread starts: NMT reset communication, wait for every boot-up, configure each node
//! over SDO in pre-operational (heartbeat producer 0x1017, PDO mapping disable → clear →
//! map → enable, 0x6060 = 8 confirmed by 0x6061), then NMT start.
//!
//! Also the blocking SDO transfer used at runtime (`drive.sdo_read` / `drive.sdo_write`),
//! on a bus of its own, never on the servo thread.
//!
//! Time is passed in by `pass`: it lets a little time go by (a real sleep, or a simulated
//! step that also runs in-process loopback drives) and returns the current time.

use super::cia402::{Mode, ModeRequest};
use super::nmt::{NmtCommand, NmtState};
use super::pdo::CspLayout;
use super::sdo::{SdoClient, SdoStep};
use super::{CanOpenError, NodeId};
use crate::can::CanBus;
use std::time::Duration;

/// What start-up does for one node.
#[derive(Debug, Clone)]
pub struct NodePlan {
    /// The node.
    pub node: NodeId,
    /// Its PDO layout.
    pub layout: CspLayout,
    /// Heartbeat producer time, ms (0x1017).
    pub heartbeat_ms: u16,
    /// SDO answer timeout.
    pub sdo_timeout: Duration,
    /// The drive's own homing parameters, when it homes in homing mode.
    pub homing: Option<DriveHomingPlan>,
}

/// Homing parameters of a drive that homes itself (CiA 402 homing mode), in drive units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriveHomingPlan {
    /// Homing method 0x6098 (e.g. 17..=22 switches, 35/37 current position).
    pub method: i8,
    /// 0x6099:1 speed during search for switch, 0x6099:2 during search for zero, counts/s.
    pub speeds: [u32; 2],
    /// 0x609A homing acceleration, counts/s² (0: the drive's own).
    pub acceleration: u32,
    /// 0x607C home offset, counts.
    pub offset: i32,
}

impl DriveHomingPlan {
    /// The SDO writes (index, sub, little-endian data) that configure it.
    pub fn writes(&self) -> [(u16, u8, [u8; 4], usize); 5] {
        let w = |v: u32| v.to_le_bytes();
        [
            (0x6098, 0, w(u32::from(self.method as u8)), 1),
            (0x6099, 1, w(self.speeds[0]), 4),
            (0x6099, 2, w(self.speeds[1]), 4),
            (0x609A, 0, w(self.acceleration), 4),
            (0x607C, 0, self.offset.to_le_bytes(), 4),
        ]
    }
}

/// Why start-up failed; every variant names the interface and the node.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StartupError {
    /// No boot-up after NMT reset communication.
    #[error("{iface}: node {node} did not answer: no boot-up within {waited_ms} ms after NMT reset communication")]
    NoBootUp {
        /// The interface.
        iface: String,
        /// The silent node.
        node: NodeId,
        /// How long it was given.
        waited_ms: u64,
    },
    /// An SDO transfer or mode confirmation failed.
    #[error("{iface}: configuring node {node}: {source}")]
    Node {
        /// The interface.
        iface: String,
        /// The node.
        node: NodeId,
        /// What failed.
        source: CanOpenError,
    },
    /// The bus itself failed.
    #[error("{iface}: CAN bus error during start-up: {message}")]
    Bus {
        /// The interface.
        iface: String,
        /// The bus error.
        message: String,
    },
}

fn bus_error<E: core::fmt::Display>(iface: &str) -> impl Fn(E) -> StartupError + '_ {
    move |e| StartupError::Bus {
        iface: iface.to_string(),
        message: e.to_string(),
    }
}

/// One SDO transfer to completion: `Ok(None)` for a finished download, `Ok(Some(data))`
/// for an upload. Blocking (it calls `pass` until the answer or the client's timeout).
pub fn sdo_transfer<B: CanBus>(
    bus: &mut B,
    node: NodeId,
    timeout: Duration,
    index: u16,
    sub: u8,
    write: Option<&[u8]>,
    pass: &mut dyn FnMut() -> Duration,
) -> Result<Option<Vec<u8>>, SdoFailure> {
    let mut client = SdoClient::with_timeout(node, timeout);
    let now = pass();
    let first = match write {
        Some(d) => client.download(index, sub, d, now),
        None => client.upload(index, sub, now),
    }
    .map_err(SdoFailure::Protocol)?;
    bus.try_send(&first)
        .map_err(|e| SdoFailure::Bus(e.to_string()))?;
    loop {
        let now = pass();
        while let Some(f) = bus.try_recv().map_err(|e| SdoFailure::Bus(e.to_string()))? {
            match client.on_frame(&f, now) {
                SdoStep::Ignored => {}
                SdoStep::Send(f) => bus
                    .try_send(&f)
                    .map_err(|e| SdoFailure::Bus(e.to_string()))?,
                SdoStep::SendBlock(frames) => {
                    for f in &frames {
                        bus.try_send(f)
                            .map_err(|e| SdoFailure::Bus(e.to_string()))?;
                    }
                }
                SdoStep::Downloaded => return Ok(None),
                SdoStep::Uploaded(v) => return Ok(Some(v)),
                SdoStep::BlockUploaded { value, confirm } => {
                    bus.try_send(&confirm)
                        .map_err(|e| SdoFailure::Bus(e.to_string()))?;
                    return Ok(Some(value));
                }
                SdoStep::Failed { error, abort } => {
                    if let Some(a) = abort {
                        let _ = bus.try_send(&a);
                    }
                    return Err(SdoFailure::Protocol(error));
                }
            }
        }
        if let Some(SdoStep::Failed { error, abort }) = client.poll(now) {
            if let Some(a) = abort {
                let _ = bus.try_send(&a);
            }
            return Err(SdoFailure::Protocol(error));
        }
    }
}

/// Why an SDO transfer failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SdoFailure {
    /// Abort, timeout or protocol error (names node and object).
    #[error("{0}")]
    Protocol(CanOpenError),
    /// The bus failed.
    #[error("CAN bus error: {0}")]
    Bus(String),
}

/// Runs the start-up of `nodes` on `bus` (the interface `iface`), allowing `boot_timeout`
/// for the boot-ups. On success every node is operational with its PDOs mapped and CSP
/// confirmed.
pub fn start_nodes<B: CanBus>(
    iface: &str,
    bus: &mut B,
    nodes: &[NodePlan],
    boot_timeout: Duration,
    pass: &mut dyn FnMut() -> Duration,
) -> Result<(), StartupError> {
    let err = bus_error(iface);
    // Reset communication, node by node, then collect every boot-up.
    let t0 = pass();
    for n in nodes {
        bus.try_send(&NmtCommand::ResetCommunication.frame(Some(n.node)))
            .map_err(&err)?;
    }
    let mut booted = vec![false; nodes.len()];
    while booted.iter().any(|b| !b) {
        let now = pass();
        while let Some(f) = bus.try_recv().map_err(&err)? {
            if let Some((node, NmtState::BootUp)) = NmtState::decode_heartbeat(&f) {
                if let Some(i) = nodes.iter().position(|n| n.node == node) {
                    booted[i] = true;
                }
            }
        }
        if now.saturating_sub(t0) > boot_timeout {
            if let Some(i) = booted.iter().position(|b| !b) {
                return Err(StartupError::NoBootUp {
                    iface: iface.to_string(),
                    node: nodes[i].node,
                    waited_ms: u64::try_from(boot_timeout.as_millis()).unwrap_or(u64::MAX),
                });
            }
        }
    }
    for n in nodes {
        configure_node(bus, n, pass).map_err(|e| match e {
            SdoFailure::Protocol(source) => StartupError::Node {
                iface: iface.to_string(),
                node: n.node,
                source,
            },
            SdoFailure::Bus(message) => StartupError::Bus {
                iface: iface.to_string(),
                message,
            },
        })?;
    }
    for n in nodes {
        bus.try_send(&NmtCommand::Start.frame(Some(n.node)))
            .map_err(&err)?;
    }
    Ok(())
}

fn configure_node<B: CanBus>(
    bus: &mut B,
    n: &NodePlan,
    pass: &mut dyn FnMut() -> Duration,
) -> Result<(), SdoFailure> {
    let mut write = |bus: &mut B, index: u16, sub: u8, data: &[u8]| {
        sdo_transfer(bus, n.node, n.sdo_timeout, index, sub, Some(data), pass).map(|_| ())
    };
    write(bus, 0x1017, 0, &n.heartbeat_ms.to_le_bytes())?;
    for w in n.layout.sdo_writes() {
        write(bus, w.index, w.sub, &w.data)?;
    }
    for (index, sub, data, len) in n.homing.iter().flat_map(DriveHomingPlan::writes) {
        write(bus, index, sub, &data[..len])?;
    }
    let mode = Mode::CyclicSyncPosition;
    write(bus, 0x6060, 0, &mode.code().to_le_bytes())?;
    // The drive may take a while to switch: read 0x6061 until it shows the mode, within
    // the SDO timeout.
    let mut req = ModeRequest::new(mode);
    let start = pass();
    loop {
        let shown = sdo_transfer(bus, n.node, n.sdo_timeout, 0x6061, 0, None, pass)?
            .and_then(|v| v.first().copied())
            .map_or(0, |b| b as i8);
        if req.on_display(shown) {
            return Ok(());
        }
        if pass().saturating_sub(start) > n.sdo_timeout {
            return Err(SdoFailure::Protocol(req.not_confirmed(n.node, shown)));
        }
    }
}
