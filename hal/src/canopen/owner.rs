//! The bus owner of one CAN interface, in its two halves that run on the servo thread:
//! [`BusRx`] at the start of the cycle and [`BusTx`] at the end, with the axes in between
//! (the cycle order of [`super::master`]).
//!
//! Each half has its own [`CanBus`] (two sockets on the interface, or two ports of a
//! [`SimCanBus`](crate::sim::SimCanBus)) and its own [`CspMaster`] image: the rx half decodes
//! TPDOs, heartbeats and EMCYs with its master and publishes them to each drive's
//! [`DriveLink`]; the tx half copies statusword, target and power request from the links
//! into its master and writes RPDOs + SYNC. Neither allocates nor blocks.
//!
//! [`SimDrives`] are loopback [`DriveSlave`]s on a third port, stepped by the tx half right
//! after the SYNC: the in-process stand-in for real drives that makes the daemon's tests
//! deterministic on the simulated clock.

use super::axis::{DriveLink, LinkCause, LinkFault};
use super::bus_health::BusErrorClass;
use super::master::{CspMaster, MasterEvent};
use super::pdo::CspLayout;
use super::slave::{DriveSlave, OUTBOX};
use super::sync::SyncProducer;
use super::{CanOpenError, NodeId, Outbox};
use crate::can::CanBus;
use std::sync::Arc;
use std::time::Duration;

/// Most drives on one interface.
pub const MAX_DRIVES: usize = 8;

/// One drive of a bus: its link, PDO layout and heartbeat consumer time.
#[derive(Debug, Clone)]
pub struct BusDrive {
    /// The shared image.
    pub link: Arc<DriveLink>,
    /// Its PDO layout.
    pub layout: CspLayout,
    /// Heartbeat consumer time (`None`: not watched).
    pub heartbeat_timeout: Option<Duration>,
}

fn master(
    drives: &[BusDrive],
    sync: SyncProducer,
    now: Duration,
) -> Result<CspMaster<MAX_DRIVES>, CanOpenError> {
    let mut m = CspMaster::new(sync);
    for d in drives {
        m.add(d.layout, d.heartbeat_timeout, now)?;
    }
    Ok(m)
}

/// The receiving half.
pub struct BusRx<B: CanBus> {
    bus: B,
    master: CspMaster<MAX_DRIVES>,
    links: Vec<Arc<DriveLink>>,
    /// The time of the first cycle: the master counts from it, so heartbeats are watched
    /// from the first cycle whatever clock the servo thread runs on.
    epoch: Option<Duration>,
}

impl<B: CanBus> BusRx<B>
where
    B::Error: BusErrorClass,
{
    /// The rx half over `bus` for `drives`; heartbeats are watched from the first cycle.
    pub fn new(bus: B, drives: &[BusDrive]) -> Result<Self, CanOpenError> {
        Ok(BusRx {
            bus,
            master: master(drives, SyncProducer::new(), Duration::ZERO)?,
            links: drives.iter().map(|d| d.link.clone()).collect(),
            epoch: None,
        })
    }

    fn raise(&self, node: NodeId, cause: LinkCause, code: u16) {
        if let Some(l) = self.links.iter().find(|l| l.node() == node) {
            l.raise(cause, code);
        }
    }

    fn on_error(&self, e: &CanOpenError) {
        match *e {
            CanOpenError::HeartbeatLost { node, .. } => {
                self.raise(node, LinkCause::HeartbeatLost, LinkFault::HEARTBEAT_CODE)
            }
            CanOpenError::UnexpectedBootUp { node } => self.raise(
                node,
                LinkCause::UnexpectedBootUp,
                LinkFault::COMMUNICATION_CODE,
            ),
            CanOpenError::Emergency { node, emcy } => {
                self.raise(node, LinkCause::Emergency, emcy.code)
            }
            CanOpenError::DriveFault { node, .. } => {
                self.raise(node, LinkCause::DriveFault, crate::FaultCode::GENERIC.0)
            }
            _ => {}
        }
    }

    /// Start of the cycle: every frame received since the last one, then heartbeat and
    /// drive-fault checks, then the fresh images to the links. A bus error (error frame,
    /// bus-off, interface down) raises its [`BusFault`](super::bus_health::BusFault) on
    /// every drive of the interface. Never allocates.
    pub fn cycle_start(&mut self, now: Duration) {
        let now = now.saturating_sub(*self.epoch.get_or_insert(now));
        loop {
            match self.bus.try_recv() {
                Ok(Some(f)) => {
                    if let Some(MasterEvent::Fault(e)) = self.master.read_frame(&f, now) {
                        self.on_error(&e);
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    let fault = e.bus_fault();
                    for l in &self.links {
                        l.raise_bus(fault);
                    }
                    break;
                }
            }
        }
        while let Some(e) = self.master.check(now) {
            self.on_error(&e);
        }
        for (i, l) in self.links.iter().enumerate() {
            if let Some(d) = self.master.drive_mut(i) {
                if d.fresh > 0 {
                    d.fresh = 0;
                    l.publish_mode(d.mode_display);
                    l.publish(d.statusword, d.position, d.velocity);
                }
            }
        }
    }
}

/// The transmitting half.
pub struct BusTx<B: CanBus> {
    bus: B,
    master: CspMaster<MAX_DRIVES>,
    links: Vec<Arc<DriveLink>>,
}

impl<B: CanBus> BusTx<B>
where
    B::Error: BusErrorClass,
{
    /// The tx half over `bus` for `drives`, sending `sync` every cycle.
    pub fn new(bus: B, drives: &[BusDrive], sync: SyncProducer) -> Result<Self, CanOpenError> {
        Ok(BusTx {
            bus,
            master: master(drives, sync, Duration::ZERO)?,
            links: drives.iter().map(|d| d.link.clone()).collect(),
        })
    }

    /// End of the cycle: one RPDO per drive (controlword from its power state machine,
    /// target), then SYNC. A send error (transmit queue full, bus-off, interface down)
    /// raises its bus fault on every drive. Never allocates.
    pub fn cycle_end(&mut self) {
        for (i, l) in self.links.iter().enumerate() {
            if let Some(d) = self.master.drive_mut(i) {
                d.statusword = l.statusword();
                d.target = l.target();
                d.mode = l.mode();
                d.op_bits = l.op_bits();
                d.power.request(l.request());
            }
        }
        if let Err(e) = self.master.write(&mut self.bus) {
            let fault = e.bus_fault();
            for l in &self.links {
                l.raise_bus(fault);
            }
        }
    }
}

/// Loopback CiA 402 drives on one port of an in-process bus.
pub struct SimDrives<B: CanBus> {
    bus: B,
    slaves: Vec<DriveSlave>,
    out: Outbox<OUTBOX>,
    /// (drives' time at `epoch`, the caller's time `epoch` of the first [`step`](Self::step)):
    /// the drives' clock continues from start-up whatever clock the servo thread runs on.
    clock: (Duration, Option<Duration>),
}

impl<B: CanBus> SimDrives<B> {
    /// The drives `slaves` on `bus`.
    pub fn new(bus: B, slaves: Vec<DriveSlave>) -> Self {
        SimDrives {
            bus,
            slaves,
            out: Outbox::default(),
            clock: (Duration::ZERO, None),
        }
    }

    /// Steps with the drives' own time advanced by `dt` (start-up, before the servo runs).
    pub fn step_by(&mut self, dt: Duration) -> Duration {
        let t = self.clock.0 + dt;
        self.clock = (t, None);
        self.step_at(t);
        t
    }

    /// Every frame received goes to every drive, then time passes for each; what they send
    /// goes out. Errors of the simulated bus end the step (the drives are then silent, as
    /// real ones behind a broken bus).
    pub fn step(&mut self, now: Duration) {
        let base = self.clock.0;
        let epoch = *self.clock.1.get_or_insert(now);
        self.step_at(base + now.saturating_sub(epoch));
    }

    fn step_at(&mut self, now: Duration) {
        while let Ok(Some(f)) = self.bus.try_recv() {
            for s in &mut self.slaves {
                s.on_frame(&f, now, &mut self.out);
            }
            if self.flush().is_err() {
                return;
            }
        }
        for s in &mut self.slaves {
            s.tick(now, &mut self.out);
        }
        let _ = self.flush();
    }

    fn flush(&mut self) -> Result<(), B::Error> {
        let r = self.out.iter().try_for_each(|f| self.bus.try_send(f));
        self.out.clear();
        r
    }
}
