//! A CiA 402 slave core: the loopback drive that `hytask sim-drive` puts on vcan0, and
//! the counterpart the master is tested against on the in-memory bus.
//!
//! Sans-IO like the rest: [`DriveSlave::on_frame`] takes a received frame, [`DriveSlave::tick`]
//! the passing of time, and both append the frames to send to an [`Outbox`];
//! [`DriveSlave::poll`] does both over any [`CanBus`]. What it implements:
//!
//! * NMT (start, stop, pre-operational, reset node, reset communication) with boot-up;
//! * an SDO server (expedited, segmented, block) on its object dictionary: 0x1000, 0x1001, 0x1008,
//!   0x1017, 0x1018, 0x1400-3/0x1600-3, 0x1800-3/0x1A00-3, 0x603F, 0x6040, 0x6041, 0x6060,
//!   0x6061, 0x6064, 0x6065, 0x606C, 0x607A, 0x607C, 0x6098, 0x6099, 0x609A, 0x60FF, 0x6502,
//!   the simulated switches [`od::SWITCHES`] (0x2002), and the fault injection
//!   object [`od::INJECT`] (0x2000: drive fault, stop heartbeat, EMCY) and a domain for
//!   block transfers, [`od::DOMAIN`] (0x2001);
//! * PDOs by their mapping (RPDOs with a synchronous transmission type take effect at the
//!   next SYNC, TPDOs with type n go out every n-th SYNC);
//! * the heartbeat producer (0x1017), EMCY on faults (and 0x0000 on fault reset);
//! * the CiA 402 state machine, CSP following the target each SYNC with the simulated
//!   axis's motor model, PP moves and homing mode: methods 35/37 (current position), 17/18
//!   (limit switch) and 19-22 (home switch) with the speeds 0x6099, acceleration 0x609A and
//!   home offset 0x607C; statusword bit 12 homing attained, 10 target reached, 13 error.
//!
//! Motion advances one cycle per SYNC; without SYNCs (a master doing only SDO, or PP moves)
//! it free-runs on [`tick`](DriveSlave::tick) at the configured cycle.

mod drive;
pub mod od;
#[cfg(test)]
mod tests;

pub use drive::FOLLOWING_ERROR;

use super::emcy::Emergency;
use super::heartbeat::HeartbeatProducer;
use super::nmt::{NmtCommand, NmtState};
use super::sdo::SdoServer;
use super::sync::decode_sync;
use super::{NodeId, Outbox};
use crate::can::{CanBus, CanFrame};
use od::Core;
use std::time::Duration;

/// The SDO server's wait for a silent client: generous, since the loopback drive's
/// clients include python-canopen under software emulation on a loaded host.
pub const SDO_TIMEOUT: Duration = Duration::from_secs(5);

/// How many frames one call may produce (SDO reply, EMCYs, up to 4 TPDOs, heartbeat).
pub const OUTBOX: usize = 16;

/// Motor and timing parameters of the loopback drive, in counts and seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlaveConfig {
    /// The nominal SYNC period (also the free-running step without SYNC).
    pub cycle: Duration,
    /// Velocity limit, counts/s.
    pub max_velocity: f64,
    /// Acceleration limit, counts/s².
    pub max_acceleration: f64,
    /// Quick-stop and fault-reaction deceleration, counts/s².
    pub quick_stop_deceleration: f64,
    /// Position-loop time constant, s (following error = v · lag).
    pub lag_s: f64,
    /// Heartbeat producer time after reset (0x1017), ms; 0 = off.
    pub heartbeat_ms: u16,
}

impl Default for SlaveConfig {
    fn default() -> Self {
        SlaveConfig {
            cycle: Duration::from_millis(1),
            max_velocity: 1.0e6,
            max_acceleration: 1.0e7,
            quick_stop_deceleration: 2.0e7,
            lag_s: 0.002,
            heartbeat_ms: 0,
        }
    }
}

/// The loopback CiA 402 drive.
#[derive(Debug, Clone)]
pub struct DriveSlave {
    node: NodeId,
    nmt: Option<NmtState>,
    sdo: SdoServer,
    heartbeat: HeartbeatProducer,
    core: Core,
    /// Last data of each RPDO with a synchronous transmission type, applied at SYNC.
    rpdo_latched: [Option<([u8; 8], usize)>; 4],
    sync_count: u32,
    last_sync: Option<Duration>,
    motion_time: Option<Duration>,
}

impl DriveSlave {
    /// A drive at `node`. It sends its boot-up message on the first
    /// [`tick`](DriveSlave::tick).
    pub fn new(node: NodeId, cfg: SlaveConfig) -> DriveSlave {
        DriveSlave {
            node,
            nmt: None,
            sdo: SdoServer::with_timeout(node, SDO_TIMEOUT),
            heartbeat: HeartbeatProducer::new(node, Duration::ZERO),
            core: Core::new(node, cfg),
            rpdo_latched: [None; 4],
            sync_count: 0,
            last_sync: None,
            motion_time: None,
        }
    }

    /// The node id.
    pub fn node(&self) -> NodeId {
        self.node
    }

    /// The NMT state (`None` before boot-up).
    pub fn nmt_state(&self) -> Option<NmtState> {
        self.nmt
    }

    /// The statusword.
    pub fn statusword(&self) -> u16 {
        self.core.drive.statusword()
    }

    /// Position actual, counts.
    pub fn position(&self) -> i32 {
        self.core.drive.position_actual()
    }

    /// Raises a drive fault with `code` (as a write of 0x2000:1 does).
    pub fn inject_fault(&mut self, code: u16, out: &mut Outbox<OUTBOX>) {
        if let Some(e) = self.core.drive.fault(code) {
            out.push(e.frame(self.node));
        }
    }

    fn boot(&mut self, out: &mut Outbox<OUTBOX>, now: Duration) {
        self.nmt = Some(NmtState::PreOperational);
        self.sdo = SdoServer::with_timeout(self.node, SDO_TIMEOUT);
        self.rpdo_latched = [None; 4];
        out.push(NmtState::BootUp.heartbeat_frame(self.node));
        self.core.heartbeat_changed = true;
        self.apply_heartbeat(now);
    }

    fn apply_heartbeat(&mut self, now: Duration) {
        if core::mem::take(&mut self.core.heartbeat_changed) {
            let ms = if self.core.heartbeat_stopped {
                0
            } else {
                self.core.heartbeat_ms
            };
            self.heartbeat
                .set_period(Duration::from_millis(u64::from(ms)), now);
        }
    }

    /// Segments of a block upload's sub-block, as many as leave room in `out` for the
    /// frames of a cycle (EMCY, TPDOs, heartbeat); the rest go on the next calls.
    fn push_burst(&mut self, out: &mut Outbox<OUTBOX>) {
        while out.len() + 8 < OUTBOX {
            match self.sdo.next_burst() {
                Some(f) => out.push(f),
                None => break,
            }
        }
    }

    fn flush_pending(&mut self, out: &mut Outbox<OUTBOX>) {
        for f in self.core.pending.iter() {
            out.push(*f);
        }
        self.core.pending.clear();
    }

    /// Handles one received frame.
    pub fn on_frame(&mut self, f: &CanFrame, now: Duration, out: &mut Outbox<OUTBOX>) {
        let Some(state) = self.nmt else { return };
        if let Some(cmd) = NmtCommand::decode_for(f, self.node) {
            match cmd {
                NmtCommand::Start => self.nmt = Some(NmtState::Operational),
                NmtCommand::Stop => self.nmt = Some(NmtState::Stopped),
                NmtCommand::EnterPreOperational => self.nmt = Some(NmtState::PreOperational),
                NmtCommand::ResetNode => {
                    self.core.drive.reset();
                    self.core.reset_communication();
                    self.boot(out, now);
                }
                NmtCommand::ResetCommunication => {
                    self.core.reset_communication();
                    self.boot(out, now);
                }
            }
            return;
        }
        if state == NmtState::Stopped {
            return;
        }
        if let Some(reply) = self.sdo.on_frame(f, now, &mut self.core) {
            out.push(reply);
            self.push_burst(out);
            self.flush_pending(out);
            self.apply_heartbeat(now);
            return;
        }
        if state != NmtState::Operational {
            return;
        }
        if decode_sync(f).is_some() {
            self.on_sync(now, out);
            return;
        }
        let raw = f.id().raw();
        for k in 0..4 {
            let p = self.core.rpdo[k];
            if !p.valid() || f.id().is_extended() || raw != p.cob || f.is_remote() {
                continue;
            }
            if f.data().len() < p.data_len() {
                // CiA 301: a too short RPDO is not processed and reported.
                out.push(Emergency::new(0x8210, 0x11).frame(self.node));
                return;
            }
            let mut buf = [0u8; 8];
            buf[..f.data().len()].copy_from_slice(f.data());
            if p.transmission <= 240 {
                self.rpdo_latched[k] = Some((buf, f.data().len()));
            } else {
                self.apply_rpdo(k, &buf);
                self.flush_pending(out);
            }
            return;
        }
    }

    fn apply_rpdo(&mut self, k: usize, data: &[u8; 8]) {
        let p = self.core.rpdo[k];
        let mut pos = 0;
        for e in p.entries() {
            let n = usize::from(e.bits / 8);
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(&data[pos..pos + n]);
            self.core.set_mapped(e.index, u64::from_le_bytes(b));
            pos += n;
        }
    }

    fn on_sync(&mut self, now: Duration, out: &mut Outbox<OUTBOX>) {
        self.sync_count = self.sync_count.wrapping_add(1);
        self.last_sync = Some(now);
        for k in 0..4 {
            if let Some((data, _)) = self.rpdo_latched[k].take() {
                self.apply_rpdo(k, &data);
            }
        }
        self.flush_pending(out);
        let dt = self.core.cfg.cycle.as_secs_f64();
        if let Some(e) = self.core.drive.step(&self.core.cfg, dt) {
            out.push(e.frame(self.node));
        }
        self.motion_time = Some(now);
        for k in 0..4 {
            let p = self.core.tpdo[k];
            let due = match p.transmission {
                0 => true,
                n @ 1..=240 => self.sync_count.is_multiple_of(u32::from(n)),
                _ => false,
            };
            if p.valid() && due {
                out.push(self.tpdo_frame(k));
            }
        }
    }

    fn tpdo_frame(&self, k: usize) -> CanFrame {
        let p = self.core.tpdo[k];
        let mut buf = [0u8; 8];
        let mut pos = 0;
        for e in p.entries() {
            let n = usize::from(e.bits / 8);
            buf[pos..pos + n].copy_from_slice(&self.core.mapped_value(e.index).to_le_bytes()[..n]);
            pos += n;
        }
        // Cannot truncate: COB-IDs of valid PDOs are checked to 11 bits when written.
        super::frame(super::cob_id((p.cob & 0x7FF) as u16), &buf[..pos])
    }

    /// Lets time pass: boot-up on the first call, heartbeat, SDO timeout, and free-running
    /// motion while no SYNC arrives.
    pub fn tick(&mut self, now: Duration, out: &mut Outbox<OUTBOX>) {
        let Some(state) = self.nmt else {
            self.boot(out, now);
            return;
        };
        self.apply_heartbeat(now);
        if let Some(f) = self.heartbeat.poll(now, state) {
            out.push(f);
        }
        if let Some(f) = self.sdo.poll(now) {
            out.push(f);
        }
        self.push_burst(out);
        let cycle = self.core.cfg.cycle;
        let sync_alive = self
            .last_sync
            .is_some_and(|t| now.saturating_sub(t) <= cycle * 3);
        if !sync_alive {
            let mut t = *self.motion_time.get_or_insert(now);
            while t + cycle <= now {
                t += cycle;
                if let Some(e) = self.core.drive.step(&self.core.cfg, cycle.as_secs_f64()) {
                    out.push(e.frame(self.node));
                }
            }
            self.motion_time = Some(t);
        }
    }

    /// One round on a bus: handle every pending frame, let time pass, send what resulted.
    pub fn poll<B: CanBus>(&mut self, bus: &mut B, now: Duration) -> Result<(), B::Error> {
        let mut out = Outbox::<OUTBOX>::default();
        while let Some(f) = bus.try_recv()? {
            self.on_frame(&f, now, &mut out);
            for f in out.iter() {
                bus.try_send(f)?;
            }
            out.clear();
        }
        self.tick(now, &mut out);
        for f in out.iter() {
            bus.try_send(f)?;
        }
        Ok(())
    }
}
