//! The realtime side of the master for CSP drives: a fixed process image of up to `N`
//! drives, fed by received frames and written out as RPDOs + SYNC once per servo cycle.
//!
//! One servo cycle, in this order (the servo thread owns bus timing):
//! 1. [`CspMaster::read_frame`] for every frame received since the last SYNC (TPDOs into the
//!    image, heartbeats, EMCYs → events), then [`CspMaster::check`] (heartbeat timeouts,
//!    drives entering Fault);
//! 2. the tasks run on the image (targets, power requests);
//! 3. [`CspMaster::write`]: one RPDO per drive, then SYNC.
//!
//! Feedback delay: a drive samples its actual values when it receives the SYNC of cycle k
//! and its TPDOs arrive during cycle k; the master reads them at the start of cycle k + 1.
//! So the tasks of cycle k + 1 see the position of the SYNC of cycle k (one servo period
//! old), and the target written in cycle k + 1 takes effect at that cycle's SYNC: the
//! loop through the master has two periods of dead time (plus the drive's own loop lag).
//!
//! Nothing here allocates; SDO configuration happens before, on the non-realtime path.

use super::cia402::{DriveState, PowerController, PowerRequest};
use super::emcy::{EmcyConsumer, EmcyEvent};
use super::heartbeat::{HeartbeatConsumer, HeartbeatEvent};
use super::pdo::CspLayout;
use super::sync::SyncProducer;
use super::{CanOpenError, NodeId};
use crate::can::{CanBus, CanFrame};
use std::time::Duration;

/// The process image of one CSP drive.
#[derive(Debug, Clone, Copy)]
pub struct DriveImage {
    /// The drive's node id.
    pub node: NodeId,
    /// Its PDO layout (as configured over SDO).
    pub layout: CspLayout,
    /// Master side of its power state machine.
    pub power: PowerController,
    /// Last statusword received.
    pub statusword: u16,
    /// Last position actual, counts.
    pub position: i32,
    /// Last velocity actual, counts/s (0 without the velocity TPDO).
    pub velocity: i32,
    /// Last modes of operation display (0 without the velocity TPDO).
    pub mode_display: i8,
    /// Target position sent with the next RPDO, counts.
    pub target: i32,
    /// Modes of operation 0x6060 sent with the next RPDO, where the layout maps it (CSP,
    /// 8, until the axis homes in the drive's homing mode).
    pub mode: i8,
    /// Operation-mode-specific controlword bits (4..=6, 8: homing start, halt) the axis
    /// adds to the power state machine's controlword.
    pub op_bits: u16,
    /// TPDO1 frames received since the last [`CspMaster::write`].
    pub fresh: u32,
    fault_reported: bool,
    seen: bool,
    /// The PDOs use the default CSP layout ([`CspLayout::new`]): decode and encode them at
    /// fixed offsets instead of walking the mapping (the per-cycle hot path).
    default_layout: bool,
}

impl DriveImage {
    /// The drive's CiA 402 state.
    pub fn state(&self) -> DriveState {
        DriveState::from_statusword(self.statusword)
    }
}

/// What a received frame or a check reported.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MasterEvent {
    /// A fault to act on (heartbeat lost, EMCY, drive fault, unexpected boot-up).
    Fault(CanOpenError),
    /// A node booted (first start or it reset).
    BootUp(NodeId),
    /// A node cleared its emergency (EMCY 0x0000).
    EmcyCleared(NodeId),
    /// A lost node is heard again.
    Recovered(NodeId),
}

/// The cyclic CSP master for up to `N` drives.
#[derive(Debug, Clone)]
pub struct CspMaster<const N: usize> {
    drives: [Option<DriveImage>; N],
    /// COB-ID → 1 + 2 · drive index + (0 for TPDO1, 1 for TPDO2); 0 = not a TPDO of ours.
    /// Makes routing a received frame O(1) instead of a scan over the drives.
    route: [u16; 0x800],
    heartbeat: HeartbeatConsumer,
    emcy: EmcyConsumer,
    sync: SyncProducer,
}

impl<const N: usize> CspMaster<N> {
    /// A master sending `sync` every cycle.
    pub fn new(sync: SyncProducer) -> Self {
        CspMaster {
            drives: [None; N],
            route: [0; 0x800],
            heartbeat: HeartbeatConsumer::default(),
            emcy: EmcyConsumer::default(),
            sync,
        }
    }

    /// Adds a drive; returns its index. The heartbeat of the node is watched from `now`
    /// with `heartbeat_timeout` (`None`: not watched).
    pub fn add(
        &mut self,
        layout: CspLayout,
        heartbeat_timeout: Option<Duration>,
        now: Duration,
    ) -> Result<usize, CanOpenError> {
        let node = NodeId::from_cob(u32::from(layout.tpdo1.cob_id), 0x180)
            .ok_or(CanOpenError::Mapping("TPDO1 is not on a predefined COB-ID"))?;
        let slot = self
            .drives
            .iter()
            .position(Option::is_none)
            .ok_or(CanOpenError::Mapping("no free drive slot in the master"))?;
        self.drives[slot] = Some(DriveImage {
            node,
            layout,
            power: PowerController::default(),
            statusword: 0,
            position: 0,
            velocity: 0,
            mode_display: 0,
            target: 0,
            mode: super::cia402::Mode::CyclicSyncPosition.code(),
            op_bits: 0,
            fresh: 0,
            fault_reported: false,
            seen: false,
            default_layout: CspLayout::new(node, layout.tpdo2.is_some()).is_ok_and(|d| d == layout),
        });
        // Cannot truncate: slot < N, and a route entry is only used for N < 32 767.
        let code = 1 + 2 * slot as u16;
        self.route[usize::from(layout.tpdo1.cob_id & 0x7FF)] = code;
        if let Some(t2) = &layout.tpdo2 {
            self.route[usize::from(t2.cob_id & 0x7FF)] = code + 1;
        }
        if let Some(t) = heartbeat_timeout {
            self.heartbeat.watch(node, t, now);
        }
        Ok(slot)
    }

    /// The image of drive `i`.
    pub fn drive(&self, i: usize) -> Option<&DriveImage> {
        self.drives.get(i)?.as_ref()
    }

    /// The image of drive `i`, to set its target and power request.
    pub fn drive_mut(&mut self, i: usize) -> Option<&mut DriveImage> {
        self.drives.get_mut(i)?.as_mut()
    }

    /// Sets the power request of every drive.
    pub fn request_all(&mut self, r: PowerRequest) {
        for d in self.drives.iter_mut().flatten() {
            d.power.request(r);
        }
    }

    /// The heartbeat consumer (NMT states of the nodes).
    pub fn heartbeat(&self) -> &HeartbeatConsumer {
        &self.heartbeat
    }

    /// Handles one received frame. Never allocates.
    pub fn read_frame(&mut self, f: &CanFrame, now: Duration) -> Option<MasterEvent> {
        let route = if f.id().is_extended() {
            0
        } else {
            self.route.get(f.id().raw() as usize).copied().unwrap_or(0)
        };
        if route != 0 {
            let slot = usize::from((route - 1) / 2);
            let d = self.drives.get_mut(slot).and_then(Option::as_mut)?;
            let data = f.data();
            if d.default_layout {
                // statusword u16 + position i32 / velocity i32 + mode i8, little-endian. A
                // malformed TPDO keeps the last image; the stale `fresh` count tells.
                if route % 2 == 1 && data.len() == 6 && !f.is_remote() {
                    d.statusword = u16::from_le_bytes([data[0], data[1]]);
                    d.position = i32::from_le_bytes([data[2], data[3], data[4], data[5]]);
                    d.fresh += 1;
                    d.seen = true;
                } else if route % 2 == 0 && data.len() == 5 && !f.is_remote() {
                    d.velocity = i32::from_le_bytes([data[0], data[1], data[2], data[3]]);
                    d.mode_display = data[4] as i8;
                }
                return None;
            }
            // Any other layout: each mapped object by its index. A malformed TPDO keeps the
            // last image; the stale `fresh` count tells.
            let mapping = if route % 2 == 1 {
                d.layout.tpdo1.mapping
            } else {
                match d.layout.tpdo2 {
                    Some(t2) => t2.mapping,
                    None => return None,
                }
            };
            if !f.is_remote() && decode_image(d, &mapping, f.data()) && route % 2 == 1 {
                d.fresh += 1;
                d.seen = true;
            }
            return None;
        }
        if let Some(ev) = self.heartbeat.on_frame(f, now) {
            return match ev {
                HeartbeatEvent::BootUp(node) => {
                    // A drive that already ran PDOs and boots again has lost its configuration.
                    if self
                        .drives
                        .iter()
                        .flatten()
                        .any(|d| d.node == node && d.seen)
                    {
                        Some(MasterEvent::Fault(CanOpenError::UnexpectedBootUp { node }))
                    } else {
                        Some(MasterEvent::BootUp(node))
                    }
                }
                HeartbeatEvent::Recovered(node) => Some(MasterEvent::Recovered(node)),
                HeartbeatEvent::StateChanged { .. } => None,
            };
        }
        match self.emcy.on_frame(f)? {
            EmcyEvent::Fault(e) => Some(MasterEvent::Fault(e)),
            EmcyEvent::Cleared(n) => Some(MasterEvent::EmcyCleared(n)),
        }
    }

    /// Heartbeat timeouts and drives that entered Fault, one per call (call until `None`).
    /// Never allocates.
    pub fn check(&mut self, now: Duration) -> Option<CanOpenError> {
        if let Some(e) = self.heartbeat.check(now) {
            return Some(e);
        }
        for d in self.drives.iter_mut().flatten() {
            let fault = d.state().is_fault();
            if fault && !d.fault_reported {
                d.fault_reported = true;
                return Some(CanOpenError::DriveFault {
                    node: d.node,
                    statusword: d.statusword,
                });
            }
            if !fault {
                d.fault_reported = false;
            }
        }
        None
    }

    /// Sends one RPDO per drive (controlword from its power state machine, target), then
    /// SYNC. Never allocates.
    pub fn write<B: CanBus>(&mut self, bus: &mut B) -> Result<(), B::Error> {
        for d in self.drives.iter_mut().flatten() {
            let cw = d.power.step(d.statusword) | d.op_bits;
            let r = &d.layout.rpdo1;
            if d.default_layout {
                let c = cw.to_le_bytes();
                let t = d.target.to_le_bytes();
                bus.try_send(&super::frame(
                    r.can_id(),
                    &[c[0], c[1], t[0], t[1], t[2], t[3]],
                ))?;
                d.fresh = 0;
                continue;
            }
            // Any other layout: each mapped object by its index (unknown objects send 0).
            let mut v = [0i64; 8];
            for (slot, e) in v.iter_mut().zip(r.mapping.entries()) {
                *slot = match e.index {
                    0x6040 => i64::from(cw),
                    0x607A => i64::from(d.target),
                    0x6060 => i64::from(d.mode),
                    _ => 0,
                };
            }
            if let Ok(f) = r
                .mapping
                .encode(r.can_id(), &v[..r.mapping.entries().len()])
            {
                bus.try_send(&f)?;
            }
            d.fresh = 0;
        }
        bus.try_send(&self.sync.next_frame())
    }
}

/// Decodes a TPDO of any mapping into the image by object index (statusword 0x6041,
/// position 0x6064, velocity 0x606C, modes display 0x6061; others ignored). False when
/// the data does not match the mapping. Never allocates.
fn decode_image(d: &mut DriveImage, mapping: &super::pdo::PdoMapping, data: &[u8]) -> bool {
    let mut v = [0i64; 8];
    let mut signed = [false; 8];
    for (s, e) in signed.iter_mut().zip(mapping.entries()) {
        *s = matches!(e.index, 0x6064 | 0x606C | 0x6061);
    }
    if mapping.decode(data, &signed, &mut v).is_err() {
        return false;
    }
    for (e, v) in mapping.entries().iter().zip(v) {
        // Truncations are the mapped widths.
        match e.index {
            0x6041 => d.statusword = v as u16,
            0x6064 => d.position = v as i32,
            0x606C => d.velocity = v as i32,
            0x6061 => d.mode_display = v as i8,
            _ => {}
        }
    }
    true
}
