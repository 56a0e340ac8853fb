//! Builds the HAL backends a configuration names, and the machine-wide numbering of I/O
//! channels.
//!
//! Backends sit behind the HAL's erased trait objects ([`DynAxis`], [`DynIo`]) so that the
//! realtime tasks do not care which backend the configuration chose. Digital and analog
//! channels are numbered machine-wide in configuration order across `[[io]]` devices: that
//! numbering is what M62–M68 `P`/`E` words and M66 address, and what the I/O task packs into
//! [`super::servo::Inputs`]/[`super::servo::Outputs`].

use super::servo::can_setup::CanDrives;
use super::servo::{Outputs, MAX_ANALOG, MAX_DIGITAL};
use crate::config::{AnalogPoint, AxisName, ConfigError, DigitalPoint, IoKind, MachineConfig};
use hytask_hal::canopen::axis::{CanAxis, LinkFault};
use hytask_hal::erased::{DynAxis, Erased, HalError};
use hytask_hal::error::ErrorType;
use hytask_hal::io::{AnalogInputs, AnalogOutputs, DigitalInputs, DigitalOutputs};
use hytask_hal::sim::{SimAxis, SimAxisHandle, SimIoHandle};
use hytask_hal::Axis;
use std::time::Duration;

/// An I/O device of any backend.
pub trait IoDevice:
    ErrorType<Error = HalError> + DigitalInputs + DigitalOutputs + AnalogInputs + AnalogOutputs + Send
{
}

impl<T> IoDevice for T where
    T: ErrorType<Error = HalError>
        + DigitalInputs
        + DigitalOutputs
        + AnalogInputs
        + AnalogOutputs
        + Send
{
}

/// An axis drive of any backend. Simulated drives are advanced by the servo thread with
/// the real period (they have no clock of their own); every other backend talks to real
/// hardware that moves by itself.
pub enum AxisDevice {
    /// A simulated drive.
    Sim(Box<Erased<SimAxis>>),
    /// A CiA 402 drive on a CAN bus (its bus owner runs as the `can.<iface>.*` tasks).
    Can(Box<Erased<CanAxis>>),
    /// Any other backend.
    Other(DynAxis),
}

impl AxisDevice {
    /// The drive, behind the HAL traits.
    pub fn axis(&mut self) -> &mut dyn Axis<Error = HalError> {
        match self {
            AxisDevice::Sim(s) => s.as_mut(),
            AxisDevice::Can(c) => c.as_mut(),
            AxisDevice::Other(d) => d.as_mut(),
        }
    }

    /// The fieldbus fault of a CANopen drive (node and cause), `None` for other backends.
    pub fn link_fault(&mut self) -> Option<LinkFault> {
        match self {
            AxisDevice::Can(c) => c.inner().link_fault(),
            _ => None,
        }
    }

    /// Cycles the position of a CANopen drive is older than usual (a late TPDO: the last
    /// values stand); 0 for other backends.
    pub fn feedback_age(&mut self) -> u32 {
        match self {
            AxisDevice::Can(c) => c.inner().feedback_age(),
            _ => 0,
        }
    }

    /// Advances a simulated drive by one servo period (no-op for real drives).
    pub fn tick(&mut self, dt: Duration) {
        if let AxisDevice::Sim(s) = self {
            s.inner().tick(dt);
        }
    }
}

/// An I/O device behind a trait object.
pub type DynIo = Box<dyn IoDevice>;

/// Where a machine-wide channel lives, with its conversion.
#[derive(Debug, Clone)]
pub struct DigitalChannel {
    /// Device index.
    pub device: usize,
    /// Channel on the device.
    pub channel: usize,
    /// Definition (name, inversion).
    pub point: DigitalPoint,
}

/// An analog channel with its scaling.
#[derive(Debug, Clone)]
pub struct AnalogChannel {
    /// Device index.
    pub device: usize,
    /// Channel on the device.
    pub channel: usize,
    /// Definition (name, scale, offset).
    pub point: AnalogPoint,
}

/// Machine-wide channel numbering.
#[derive(Debug, Clone, Default)]
pub struct IoMap {
    /// Digital inputs.
    pub di: Vec<DigitalChannel>,
    /// Digital outputs.
    pub dout: Vec<DigitalChannel>,
    /// Analog inputs.
    pub ai: Vec<AnalogChannel>,
    /// Analog outputs.
    pub ao: Vec<AnalogChannel>,
}

impl IoMap {
    /// Numbers the channels of `cfg`; fails when there are more than the servo data can carry.
    pub fn new(cfg: &MachineConfig) -> Result<IoMap, String> {
        // Machine-wide numbering: configuration order across devices, channel order within.
        fn number<P: Clone, C>(
            cfg: &MachineConfig,
            points: impl Fn(&crate::config::IoConfig) -> &[P],
            make: impl Fn(usize, usize, P) -> C,
        ) -> Vec<C> {
            cfg.io
                .iter()
                .enumerate()
                .flat_map(|(d, io)| {
                    points(io)
                        .iter()
                        .enumerate()
                        .map(|(c, p)| make(d, c, p.clone()))
                        .collect::<Vec<_>>()
                })
                .collect()
        }
        let digital = |device, channel, point| DigitalChannel {
            device,
            channel,
            point,
        };
        let analog = |device, channel, point| AnalogChannel {
            device,
            channel,
            point,
        };
        let m = IoMap {
            di: number(cfg, |io| &io.digital_inputs, digital),
            dout: number(cfg, |io| &io.digital_outputs, digital),
            ai: number(cfg, |io| &io.analog_inputs, analog),
            ao: number(cfg, |io| &io.analog_outputs, analog),
        };
        if m.di.len() > MAX_DIGITAL || m.dout.len() > MAX_DIGITAL {
            return Err(format!(
                "io: at most {MAX_DIGITAL} digital inputs and {MAX_DIGITAL} outputs per machine"
            ));
        }
        if m.ai.len() > MAX_ANALOG || m.ao.len() > MAX_ANALOG {
            return Err(format!(
                "io: at most {MAX_ANALOG} analog inputs and {MAX_ANALOG} outputs per machine"
            ));
        }
        Ok(m)
    }

    /// Every output in its configured safe state (`safe` of each output channel; inactive and
    /// 0 by default): what the e-stop, machine off and shutdown leave on the outputs.
    pub fn safe_outputs(&self) -> Outputs {
        let mut out = Outputs::default();
        for (i, c) in self.dout.iter().enumerate() {
            out.set_do(i, c.point.safe_state());
        }
        for (v, c) in out.analog.iter_mut().zip(&self.ao) {
            *v = c.point.safe_value();
        }
        out
    }

    /// Machine-wide index of a named channel of `kind`.
    pub fn index(&self, kind: IoKind, name: &str) -> Option<usize> {
        match kind {
            IoKind::DigitalInput => self.di.iter().position(|c| c.point.name == name),
            IoKind::DigitalOutput => self.dout.iter().position(|c| c.point.name == name),
            IoKind::AnalogInput => self.ai.iter().position(|c| c.point.name == name),
            IoKind::AnalogOutput => self.ao.iter().position(|c| c.point.name == name),
        }
    }
}

/// Every device of a machine, ready to be handed to the realtime tasks.
pub struct Devices {
    /// Axes in configuration order, with their drives.
    pub axes: Vec<(AxisName, AxisDevice)>,
    /// I/O devices in configuration order.
    pub io: Vec<DynIo>,
    /// Channel numbering.
    pub io_map: IoMap,
    /// Fault-injection handles of simulated drives, by axis.
    pub sim_axes: Vec<(AxisName, SimAxisHandle)>,
    /// Input handles of simulated I/O devices (`None` for real devices), by device.
    pub sim_io: Vec<Option<SimIoHandle>>,
    /// CANopen bus owners, runtime SDO access and in-memory buses.
    pub can: CanDrives,
    /// Events of the Modbus links (`None` without Modbus devices).
    pub link_events: Option<std::sync::mpsc::Receiver<crate::modbus::LinkEvent>>,
}

/// Builds the backends. Fails, naming the key, for a backend this build does not have.
pub fn build(cfg: &MachineConfig) -> Result<Devices, ConfigError> {
    crate::config::require_available(cfg)?;
    let invalid = |key: String, message: String| ConfigError::Invalid {
        origin: cfg.machine.name.clone(),
        issues: vec![crate::config::Issue { key, message }],
    };
    let mut axes = Vec::new();
    let mut sim_axes = Vec::new();
    let mut can = super::servo::can_setup::build(cfg)?;
    for (i, a) in cfg.axes.iter().enumerate() {
        let key = crate::config::AxisConfig::key(i, a.name);
        if let Some(c) = can.axes.get_mut(i).and_then(Option::take) {
            axes.push((a.name, AxisDevice::Can(Box::new(Erased(c)))));
            continue;
        }
        let drive = cfg
            .drive(&a.drive)
            .ok_or_else(|| invalid(format!("{key}.drive"), format!("no drive '{}'", a.drive)))?;
        let sim_cfg = drive.sim_axis_config(a).ok_or_else(|| {
            invalid(
                format!("{key}.drive"),
                format!("backend of drive '{}' is not available", a.drive),
            )
        })?;
        let sim = SimAxis::new(sim_cfg)
            .map_err(|e| invalid(format!("drive ({}).sim", a.drive), e.to_string()))?;
        sim_axes.push((a.name, sim.handle()));
        axes.push((a.name, AxisDevice::Sim(Box::new(Erased(sim)))));
    }
    let super::io_devices::IoDevices {
        io,
        sim_io,
        link_events,
    } = super::io_devices::build_io(cfg).map_err(|(k, m)| invalid(k, m))?;
    let io_map = IoMap::new(cfg).map_err(|m| invalid("io".into(), m))?;
    Ok(Devices {
        axes,
        io,
        io_map,
        sim_axes,
        sim_io,
        can,
        link_events,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sim_mill_has_three_axes_and_named_channels() {
        let cfg = crate::config::builtin_sim().expect("config");
        let d = build(&cfg).expect("devices");
        assert_eq!(d.axes.len(), 3);
        assert_eq!(d.io.len(), 1);
        assert_eq!(d.io_map.index(IoKind::DigitalInput, "estop"), Some(0));
        assert_eq!(
            d.io_map.index(IoKind::DigitalOutput, "coolant_flood"),
            Some(2)
        );
        assert_eq!(d.io_map.index(IoKind::DigitalInput, "nope"), None);
    }
}
