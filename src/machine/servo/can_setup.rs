//! Builds the CANopen drives of a machine on the non-realtime path, before the servo
//! thread starts: groups the drives by interface, checks the bus-load budget, runs the
//! start-up (NMT reset, boot-up, SDO configuration, NMT start) and hands back the axes,
//! the bus-owner halves for the `can.<iface>.*` tasks, and the runtime SDO access.
//!
//! `interface = "sim"` puts loopback CiA 402 drives on an in-memory bus in this process:
//! the start-up steps them itself, then the `tx` task steps them after every SYNC. Any
//! other interface is SocketCAN, with three sockets filtered by COB-ID (rx, tx, SDO).

use super::can_bus::{RxHalf, SimTx, TxHalf};
use crate::config::{
    AxisConfig, CanopenDriveConfig, CanopenHoming, ConfigError, Issue, MachineConfig,
    SIM_DRIVE_HEADROOM, SIM_INTERFACE,
};
use hytask_hal::can::CanBus;
use hytask_hal::canopen::axis::{CanAxis, DriveLink};
use hytask_hal::canopen::busload::CycleTraffic;
use hytask_hal::canopen::owner::{BusDrive, BusRx, BusTx, SimDrives, MAX_DRIVES};
use hytask_hal::canopen::pdo::PdoDirection;
use hytask_hal::canopen::slave::{DriveSlave, SlaveConfig};
use hytask_hal::canopen::startup::{sdo_transfer, start_nodes, DriveHomingPlan, NodePlan};
use hytask_hal::canopen::sync::SyncProducer;
use hytask_hal::canopen::{NodeId, COB_EMCY, COB_HEARTBEAT, COB_SDO_TX};
use hytask_hal::sim::SimCanBus;
use hytask_hal::socketcan::{IdFilter, SocketCanBus};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Frames each port of an in-process bus buffers: enough for the SDO port, which hears
/// all cyclic traffic while a request waits for its answer.
const SIM_QUEUE: usize = 8192;

/// One interface's bus owner, ready to become its two tasks.
pub struct CanBusSetup {
    /// The interface name.
    pub iface: String,
    /// `can.<iface>.rx`.
    pub rx: Box<dyn RxHalf>,
    /// `can.<iface>.tx`.
    pub tx: Box<dyn TxHalf>,
}

/// A bus used for SDO transfers outside the servo thread.
pub trait SdoBus: Send {
    /// One transfer: a download of `write`, or an upload when `None`.
    fn transfer(
        &mut self,
        node: NodeId,
        timeout: Duration,
        index: u16,
        sub: u8,
        write: Option<&[u8]>,
    ) -> Result<Option<Vec<u8>>, String>;
}

struct SdoPort<B>(B);

impl<B: CanBus + Send> SdoBus for SdoPort<B> {
    fn transfer(
        &mut self,
        node: NodeId,
        timeout: Duration,
        index: u16,
        sub: u8,
        write: Option<&[u8]>,
    ) -> Result<Option<Vec<u8>>, String> {
        // This port hears all cyclic traffic; what came before the request is not for it.
        while let Ok(Some(_)) = self.0.try_recv() {}
        let t0 = Instant::now();
        let mut pass = || {
            std::thread::sleep(Duration::from_micros(200));
            t0.elapsed()
        };
        sdo_transfer(&mut self.0, node, timeout, index, sub, write, &mut pass)
            .map_err(|e| e.to_string())
    }
}

/// Runtime SDO access to the CANopen drives (`drive.sdo_read` / `drive.sdo_write`): one
/// bus per interface, used by one request at a time, never by the servo thread.
#[derive(Default)]
pub struct CanSdo {
    /// (drive name, bus index, node, SDO timeout).
    drives: Vec<(String, usize, NodeId, Duration)>,
    buses: Vec<Mutex<Box<dyn SdoBus>>>,
}

/// Why a runtime SDO request failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SdoError {
    /// The name is not a CANopen drive of this machine.
    #[error("no CANopen drive '{0}'")]
    UnknownDrive(String),
    /// The transfer failed (abort, timeout, bus error; names node and object).
    #[error("{0}")]
    Transfer(String),
}

impl CanSdo {
    /// Reads object `index:sub` of drive `drive`.
    pub fn read(&self, drive: &str, index: u16, sub: u8) -> Result<Vec<u8>, SdoError> {
        self.transfer(drive, index, sub, None)
            .map(Option::unwrap_or_default)
    }

    /// Writes `data` (little-endian) to object `index:sub` of drive `drive`.
    pub fn write(&self, drive: &str, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoError> {
        self.transfer(drive, index, sub, Some(data)).map(|_| ())
    }

    fn transfer(
        &self,
        drive: &str,
        index: u16,
        sub: u8,
        data: Option<&[u8]>,
    ) -> Result<Option<Vec<u8>>, SdoError> {
        let unknown = || SdoError::UnknownDrive(drive.to_string());
        let &(_, bus, node, timeout) = self
            .drives
            .iter()
            .find(|d| d.0 == drive)
            .ok_or_else(unknown)?;
        let bus = self.buses.get(bus).ok_or_else(unknown)?;
        let mut bus = bus.lock().unwrap_or_else(|p| p.into_inner());
        bus.transfer(node, timeout, index, sub, data)
            .map_err(SdoError::Transfer)
    }
}

/// Everything the CANopen drives of a machine bring.
#[derive(Default)]
pub struct CanDrives {
    /// Per `[[axis]]` index: its CANopen axis (`None` for other backends).
    pub axes: Vec<Option<CanAxis>>,
    /// One bus owner per interface.
    pub buses: Vec<CanBusSetup>,
    /// Runtime SDO access.
    pub sdo: CanSdo,
    /// The in-memory buses of `sim` interfaces (to take them off in tests).
    pub sim_buses: Vec<SimCanBus>,
}

struct Member<'a> {
    axis_index: usize,
    axis: &'a AxisConfig,
    drive: &'a str,
    key: String,
    co: &'a CanopenDriveConfig,
}

fn invalid(cfg: &MachineConfig, key: String, message: String) -> ConfigError {
    ConfigError::Invalid {
        origin: cfg.machine.name.clone(),
        issues: vec![Issue { key, message }],
    }
}

/// Builds and starts every CANopen drive of `cfg`. A node that does not answer names
/// itself in the error, and nothing deploys.
pub fn build(cfg: &MachineConfig) -> Result<CanDrives, ConfigError> {
    let mut out = CanDrives {
        axes: cfg.axes.iter().map(|_| None).collect(),
        ..CanDrives::default()
    };
    let mut groups: Vec<(String, Vec<Member<'_>>)> = Vec::new();
    for (i, a) in cfg.axes.iter().enumerate() {
        let Some(d) = cfg.drive(&a.drive) else {
            continue;
        };
        let Some(co) = &d.canopen else { continue };
        let idx = cfg
            .drives
            .iter()
            .position(|x| x.name == d.name)
            .unwrap_or(0);
        let m = Member {
            axis_index: i,
            axis: a,
            drive: &d.name,
            key: format!("{}.canopen", crate::config::DriveConfig::key(idx, &d.name)),
            co,
        };
        match groups.iter_mut().find(|g| g.0 == co.interface) {
            Some(g) => g.1.push(m),
            None => groups.push((co.interface.clone(), vec![m])),
        }
    }
    let period_us = cfg.servo_thread().map_or(1000, |t| t.period_us);
    for (iface, members) in groups {
        build_bus(cfg, &iface, &members, period_us, &mut out)?;
    }
    Ok(out)
}

fn check_group(
    cfg: &MachineConfig,
    iface: &str,
    members: &[Member<'_>],
) -> Result<(), ConfigError> {
    if members.len() > MAX_DRIVES {
        return Err(invalid(
            cfg,
            format!("{}.interface", members[MAX_DRIVES].key),
            format!(
                "at most {MAX_DRIVES} drives per interface, {iface} has {}",
                members.len()
            ),
        ));
    }
    let first = &members[0];
    for (k, m) in members.iter().enumerate() {
        if members[..k].iter().any(|o| o.co.node_id == m.co.node_id) {
            return Err(invalid(
                cfg,
                format!("{}.node_id", m.key),
                format!("node {} is used twice on {iface}", m.co.node_id),
            ));
        }
        for (what, a, b) in [
            ("bitrate", m.co.bitrate, first.co.bitrate),
            (
                "busload_limit_pct",
                u32::from(m.co.busload_limit_pct),
                u32::from(first.co.busload_limit_pct),
            ),
            (
                "sync_counter",
                u32::from(m.co.sync_counter),
                u32::from(first.co.sync_counter),
            ),
        ] {
            if a != b {
                return Err(invalid(
                    cfg,
                    format!("{}.{what}", m.key),
                    format!(
                        "{a} differs from {b} of drive '{}' on the same interface {iface}",
                        first.drive
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn build_bus(
    cfg: &MachineConfig,
    iface: &str,
    members: &[Member<'_>],
    period_us: u32,
    out: &mut CanDrives,
) -> Result<(), ConfigError> {
    check_group(cfg, iface, members)?;
    let first = &members[0];
    let sync = match first.co.sync_counter {
        0 => SyncProducer::new(),
        n => SyncProducer::with_counter(n),
    };
    let mut drives = Vec::new();
    let mut plans = Vec::new();
    for m in members {
        let node = NodeId::new(m.co.node_id)
            .map_err(|e| invalid(cfg, format!("{}.node_id", m.key), e.to_string()))?;
        let drive_homing = drive_homing_plan(m);
        let layout = super::can_pdo_names::layout(m.co, node, drive_homing.is_some())
            .map_err(|e| invalid(cfg, format!("{}.{}", m.key, e.key), e.message))?;
        let link = DriveLink::on_bus(node, iface);
        // 50 ms (at least 3 cycles) without process data is a lost drive; shorter gaps are
        // a drive answering SYNC late, and the last values stand.
        let missed = (50_000 / period_us.max(1)).max(3);
        let mut axis = CanAxis::new(link.clone(), m.axis.scale).with_missed_cycles(missed);
        if drive_homing.is_some() {
            let cycles = u64::from(m.co.homing_timeout_ms) * 1000 / u64::from(period_us.max(1));
            axis = axis.with_drive_homing(u32::try_from(cycles).unwrap_or(u32::MAX));
        }
        out.axes[m.axis_index] = Some(axis);
        let hb = Duration::from_millis(u64::from(m.co.heartbeat_ms));
        drives.push(BusDrive {
            link,
            layout,
            heartbeat_timeout: Some(hb * 2),
        });
        plans.push(NodePlan {
            node,
            layout,
            heartbeat_ms: u16::try_from(m.co.heartbeat_ms).unwrap_or(u16::MAX),
            sdo_timeout: Duration::from_millis(u64::from(m.co.sdo_timeout_ms)),
            homing: drive_homing,
        });
        out.sdo.drives.push((
            m.drive.to_string(),
            out.sdo.buses.len(),
            node,
            Duration::from_millis(u64::from(m.co.sdo_timeout_ms)),
        ));
    }
    // The budget, by the same code as the table in benches/README.md.
    let rate_hz = 1_000_000 / period_us.max(1);
    CycleTraffic::from_layout(&drives[0].layout, &sync)
        .check(
            drives.len(),
            rate_hz,
            first.co.bitrate,
            f64::from(first.co.busload_limit_pct) / 100.0,
        )
        .map_err(|e| {
            invalid(
                cfg,
                format!("{}.interface ({iface})", first.key),
                e.to_string(),
            )
        })?;
    let boot_timeout = Duration::from_millis(u64::from(first.co.sdo_timeout_ms.max(1000)));
    let startup = |e: hytask_hal::canopen::startup::StartupError| {
        invalid(cfg, format!("{}.interface", first.key), e.to_string())
    };
    let rx_err = |e: hytask_hal::canopen::CanOpenError| {
        invalid(cfg, format!("{}.interface", first.key), e.to_string())
    };
    if iface == SIM_INTERFACE {
        let (wire, mut ports) = SimCanBus::new(4, SIM_QUEUE)
            .map_err(|e| invalid(cfg, format!("{}.interface", first.key), e.to_string()))?;
        let (Some(sdo), Some(slaves_port), Some(tx), Some(rx)) =
            (ports.pop(), ports.pop(), ports.pop(), ports.pop())
        else {
            return Err(invalid(
                cfg,
                first.key.clone(),
                "in-memory bus has no ports".into(),
            ));
        };
        let slaves = members
            .iter()
            .zip(&plans)
            .map(|(m, p)| DriveSlave::new(p.node, slave_config(m.axis, m.co, period_us)))
            .collect();
        let mut sim = SimDrives::new(slaves_port, slaves);
        let mut sdo = sdo;
        let mut pass = || sim.step_by(Duration::from_millis(1));
        start_nodes(iface, &mut sdo, &plans, boot_timeout, &mut pass).map_err(startup)?;
        out.buses.push(CanBusSetup {
            iface: iface.to_string(),
            rx: Box::new(BusRx::new(rx, &drives).map_err(rx_err)?),
            tx: Box::new(SimTx {
                tx: BusTx::new(tx, &drives, sync).map_err(rx_err)?,
                drives: sim,
            }),
        });
        out.sdo.buses.push(Mutex::new(Box::new(SdoPort(sdo))));
        out.sim_buses.push(wire);
        return Ok(());
    }
    // SocketCAN: one socket per purpose, each filtered to what it reads. rx: the TPDOs,
    // heartbeats and EMCYs of these nodes; tx: nothing; SDO/start-up: SDO answers and
    // boot-ups.
    let open = |filters: &[IdFilter]| {
        let mut b = SocketCanBus::open(iface)
            .map_err(|e| invalid(cfg, format!("{}.interface", first.key), e.to_string()))?;
        b.set_filters(filters)
            .map_err(|e| invalid(cfg, format!("{}.interface", first.key), e.to_string()))?;
        Ok::<_, ConfigError>(b)
    };
    let mut rx_ids = Vec::new();
    let mut sdo_ids = Vec::new();
    for (d, p) in drives.iter().zip(&plans) {
        let tpdos = d
            .layout
            .pdos()
            .filter(|p| p.direction == PdoDirection::Tpdo);
        rx_ids.extend(tpdos.map(|t| IdFilter::exact(t.can_id())));
        rx_ids.push(IdFilter::exact(p.node.cob(COB_HEARTBEAT)));
        rx_ids.push(IdFilter::exact(p.node.cob(COB_EMCY)));
        sdo_ids.push(IdFilter::exact(p.node.cob(COB_SDO_TX)));
        sdo_ids.push(IdFilter::exact(p.node.cob(COB_HEARTBEAT)));
    }
    let rx = open(&rx_ids)?;
    let tx = open(&[])?;
    let mut sdo = open(&sdo_ids)?;
    let t0 = Instant::now();
    let mut pass = || {
        std::thread::sleep(Duration::from_micros(500));
        t0.elapsed()
    };
    start_nodes(iface, &mut sdo, &plans, boot_timeout, &mut pass).map_err(startup)?;
    out.buses.push(CanBusSetup {
        iface: iface.to_string(),
        rx: Box::new(BusRx::new(rx, &drives).map_err(rx_err)?),
        tx: Box::new(BusTx::new(tx, &drives, sync).map_err(rx_err)?),
    });
    out.sdo.buses.push(Mutex::new(Box::new(SdoPort(sdo))));
    Ok(())
}

/// The drive's own homing parameters when `homing = "drive"`: method, speeds and
/// acceleration as configured, home offset 0x607C = `[axis.home] position` in counts (so
/// the axis reads its home position after homing, with no offset on the master).
fn drive_homing_plan(m: &Member<'_>) -> Option<DriveHomingPlan> {
    if m.co.homing != CanopenHoming::Drive {
        return None;
    }
    let offset = (m.axis.home.position * m.axis.scale)
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX));
    Some(DriveHomingPlan {
        method: m.co.homing_method.unwrap_or(0),
        speeds: m.co.homing_speeds,
        acceleration: m.co.homing_acceleration,
        // Clamped to the i32 range above.
        offset: offset as i32,
    })
}

/// The loopback drive's motor for `axis`, in counts: the simulated axis's headroom over
/// the planning limits.
fn slave_config(axis: &AxisConfig, co: &CanopenDriveConfig, period_us: u32) -> SlaveConfig {
    let k = axis.scale.abs();
    SlaveConfig {
        cycle: Duration::from_micros(u64::from(period_us)),
        max_velocity: axis.max_velocity * SIM_DRIVE_HEADROOM * k,
        max_acceleration: axis.max_acceleration * SIM_DRIVE_HEADROOM * k,
        quick_stop_deceleration: 2.0 * axis.max_acceleration * k,
        lag_s: co.loopback_lag_s.map_or(0.005, |l| l.0),
        heartbeat_ms: 0,
    }
}
