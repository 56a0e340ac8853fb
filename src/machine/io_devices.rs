//! Builds the I/O devices of a machine: simulated ones in place, Modbus ones through their
//! link pollers ([`crate::modbus::start`]). Kept apart from `devices.rs` so that each
//! backend's construction stays in one short place.

use super::devices::DynIo;
use crate::config::{IoBackend, IoConfig, MachineConfig};
use crate::modbus::LinkEvent;
use hytask_hal::erased::Erased;
use hytask_hal::sim::SimIoHandle;
use std::sync::mpsc::Receiver;

/// The I/O devices in configuration order, the simulated devices' handles, and the Modbus
/// links' event receiver (`None` without Modbus devices).
pub struct IoDevices {
    /// Devices, by `[[io]]` index.
    pub io: Vec<DynIo>,
    /// Input handles of simulated devices.
    pub sim_io: Vec<Option<SimIoHandle>>,
    /// Modbus link events.
    pub link_events: Option<Receiver<LinkEvent>>,
}

/// Builds every `[[io]]` device; the error is `(key, message)`.
pub fn build_io(cfg: &MachineConfig) -> Result<IoDevices, (String, String)> {
    let modbus = cfg.io.iter().any(|d| d.backend != IoBackend::Sim);
    let mut set = if modbus {
        Some(crate::modbus::start(cfg)?)
    } else {
        None
    };
    let mut remote = set
        .as_mut()
        .map(|s| std::mem::take(&mut s.devices))
        .unwrap_or_default()
        .into_iter();
    let mut io: Vec<DynIo> = Vec::new();
    let mut sim_io = Vec::new();
    for (i, dev) in cfg.io.iter().enumerate() {
        if let Some(sim) = dev.sim_io() {
            sim_io.push(Some(sim.handle()));
            io.push(Box::new(Erased(sim)));
            continue;
        }
        match remote.next() {
            Some((k, d)) if k == i => {
                sim_io.push(None);
                io.push(Box::new(Erased(d)));
            }
            _ => {
                return Err((
                    format!("{}.backend", IoConfig::key(i, &dev.name)),
                    "backend not available in this build".into(),
                ))
            }
        }
    }
    Ok(IoDevices {
        io,
        sim_io,
        link_events: set.map(|s| s.events),
    })
}
