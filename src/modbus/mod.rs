//! Modbus I/O for the daemon: builds each `[[io]]` Modbus device's image and map from the
//! configuration, groups devices by link and runs one poller thread per link.
//!
//! The async poller ([`link`]) uses `tokio-modbus`; it lives here rather than in
//! `hytask-hal` so that the HAL stays a small synchronous crate without a runtime. Each
//! link gets its own OS thread with a single-threaded tokio runtime: an ordinary
//! (non-realtime) thread whose stalls never touch the servo thread, which only sees the
//! lock-free image through [`ModbusIo`].

pub mod event;
pub mod link;
pub mod sim;
pub mod stats;

pub use event::LinkEvent;
pub use link::{Endpoint, InputPoint, LinkConfig, OutputPoint, UnitConfig};

use crate::config::modbus::{link_name, specs, ModbusSettings, Parity};
use crate::config::{IoBackend, IoConfig, IoKind, MachineConfig};
use hytask_hal::modbus::{Image, ModbusIo};
use std::collections::BTreeMap;
use std::sync::mpsc::{channel, Receiver};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The Modbus side of a machine: one device per Modbus `[[io]]` (by `[[io]]` index) and
/// the receiver of every link's events.
pub struct ModbusSet {
    /// `(io index, device)`.
    pub devices: Vec<(usize, ModbusIo)>,
    /// Link events (health changes), for the machine's event bridge.
    pub events: Receiver<LinkEvent>,
}

/// Why the Modbus devices could not be built: the key and the message.
pub type BuildError = (String, String);

/// The link settings of a device (defaults when `[io.modbus]` is absent).
fn settings(io: &IoConfig) -> ModbusSettings {
    io.modbus.clone().unwrap_or_default()
}

fn endpoint(io: &IoConfig, s: &ModbusSettings) -> Option<Endpoint> {
    match io.backend {
        IoBackend::Sim => None,
        IoBackend::ModbusTcp => io.address.clone().map(Endpoint::Tcp),
        IoBackend::ModbusRtu => Some(Endpoint::Rtu {
            path: s.device.clone()?,
            baud: s.baud_rate,
            parity: match s.parity {
                Parity::None => tokio_serial::Parity::None,
                Parity::Even => tokio_serial::Parity::Even,
                Parity::Odd => tokio_serial::Parity::Odd,
            },
            stop_bits: if s.stop_bits == 2 {
                tokio_serial::StopBits::Two
            } else {
                tokio_serial::StopBits::One
            },
        }),
    }
}

/// The unit (device) of `io` with a fresh image. `estop` names the machine's e-stop input,
/// which is critical wherever it is.
pub fn unit(io: &IoConfig, key: &str, estop: &str) -> Result<UnitConfig, BuildError> {
    let spec = |kind| specs(io, kind).map_err(|(k, m)| (format!("{key}.{k}"), m));
    let (di, dout, ai, ao) = (
        spec(IoKind::DigitalInput)?,
        spec(IoKind::DigitalOutput)?,
        spec(IoKind::AnalogInput)?,
        spec(IoKind::AnalogOutput)?,
    );
    let di_crit: Vec<bool> = io
        .digital_inputs
        .iter()
        .map(|p| p.critical || p.name == estop)
        .collect();
    let ai_crit: Vec<bool> = io.analog_inputs.iter().map(|p| p.critical).collect();
    let mut inputs = Vec::new();
    for (i, (p, s)) in io.digital_inputs.iter().zip(&di).enumerate() {
        inputs.push(InputPoint {
            name: p.name.clone(),
            digital: true,
            index: i,
            spec: *s,
            critical: di_crit[i],
        });
    }
    for (i, (p, s)) in io.analog_inputs.iter().zip(&ai).enumerate() {
        inputs.push(InputPoint {
            name: p.name.clone(),
            digital: false,
            index: i,
            spec: *s,
            critical: p.critical,
        });
    }
    let mut outputs = Vec::new();
    for (i, (p, s)) in io.digital_outputs.iter().zip(&dout).enumerate() {
        outputs.push(OutputPoint {
            name: p.name.clone(),
            digital: true,
            index: i,
            spec: *s,
        });
    }
    for (i, (p, s)) in io.analog_outputs.iter().zip(&ao).enumerate() {
        outputs.push(OutputPoint {
            name: p.name.clone(),
            digital: false,
            index: i,
            spec: *s,
        });
    }
    let s = settings(io);
    let image = Arc::new(Image::new(di_crit, ai_crit, dout.len(), ao.len()));
    Ok(UnitConfig {
        device: io.name.clone(),
        unit: io.unit_id.unwrap_or(1),
        image,
        inputs,
        outputs,
        poll: Duration::from_millis(u64::from(s.poll_ms)),
        refresh: (s.refresh_ms > 0).then(|| Duration::from_millis(u64::from(s.refresh_ms))),
        max_gap: s.max_gap,
    })
}

/// The links of a machine, each with its devices, in configuration order; with the
/// `[[io]]` index of every unit.
pub fn links(cfg: &MachineConfig) -> Result<Vec<(LinkConfig, Vec<usize>)>, BuildError> {
    let mut by_link: BTreeMap<String, (LinkConfig, Vec<usize>)> = BTreeMap::new();
    let mut order = Vec::new();
    for (i, io) in cfg.io.iter().enumerate() {
        let (Some(name), Some(ep)) = (link_name(io), endpoint(io, &settings(io))) else {
            continue;
        };
        let key = IoConfig::key(i, &io.name);
        let u = unit(io, &key, &cfg.safety.estop_input)?;
        let s = settings(io);
        let entry = by_link.entry(name.clone()).or_insert_with(|| {
            order.push(name.clone());
            (
                LinkConfig {
                    name: name.clone(),
                    endpoint: ep,
                    timeout: Duration::from_millis(u64::from(s.timeout_ms)),
                    max_backoff: Duration::from_millis(u64::from(s.max_backoff_ms)),
                    units: Vec::new(),
                },
                Vec::new(),
            )
        });
        entry.0.units.push(u);
        entry.1.push(i);
    }
    Ok(order
        .into_iter()
        .filter_map(|n| by_link.remove(&n))
        .collect())
}

/// Starts one poller thread per link; returns the devices for the machine. Waits (bounded
/// by each link's timeout plus a margin) for the first poll, so that a reachable device has
/// good inputs before the servo thread starts; an unreachable one just stays bad.
pub fn start(cfg: &MachineConfig) -> Result<ModbusSet, BuildError> {
    let (tx, rx) = channel();
    let mut devices = Vec::new();
    let mut wait = Duration::ZERO;
    for (link, indices) in links(cfg)? {
        wait = wait.max(link.timeout * 2 + Duration::from_millis(500));
        for (u, &i) in link.units.iter().zip(&indices) {
            devices.push((i, ModbusIo::new(u.image.clone())));
        }
        let events = tx.clone();
        let name = link.name.clone();
        let l = link::Link::new(link, events);
        std::thread::Builder::new()
            .name(format!("modbus {name}"))
            .spawn(move || {
                match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt.block_on(l.run()),
                    Err(e) => tracing::error!("modbus {name}: no runtime: {e}"),
                }
            })
            .map_err(|e| {
                (
                    "io".to_string(),
                    format!("cannot start a Modbus poller: {e}"),
                )
            })?;
    }
    let t0 = Instant::now();
    while t0.elapsed() < wait && !devices.iter().all(|(_, d)| first_poll_done(d.image())) {
        std::thread::sleep(Duration::from_millis(5));
    }
    devices.sort_by_key(|d| d.0);
    Ok(ModbusSet {
        devices,
        events: rx,
    })
}

fn first_poll_done(img: &Image) -> bool {
    use hytask_hal::modbus::Quality;
    img.di
        .iter()
        .chain(img.ai.iter())
        .all(|c| c.sample().quality != Quality::Unknown)
}
