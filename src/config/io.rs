//! `[[io]]`: I/O devices and their named channels.
//!
//! Every channel has a machine-wide unique name (`estop`, `coolant_flood`); the rest of the
//! configuration (spindle, coolant, safety) refers to channels by name, and a channel's
//! index on its device is its position in the device's list. `backend = "sim"` is the
//! simulated I/O of `hytask-hal`; `backend = "modbus_tcp"` is a Modbus TCP device at
//! `address`, `backend = "modbus_rtu"` a Modbus RTU device on the serial line
//! `[io.modbus] device`; each channel's `table`, `register`, `bit`, `type` and `word_order`
//! place it in the device's tables (see [`super::modbus`]), and `critical = true` marks an
//! input whose loss stops the machine.

use super::error::Issues;
use hytask_hal::sim::SimIo;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::fmt;

/// `[[io]]`: one I/O device.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct IoConfig {
    /// Device name; unique among `[[io]]`.
    pub name: String,
    /// Which backend runs it.
    pub backend: IoBackend,
    /// Network address `host:port` (Modbus TCP); refused otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub address: Option<String>,
    /// Modbus unit (slave) id; Modbus only, default 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit_id: Option<u8>,
    /// Digital inputs, in channel order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub digital_inputs: Vec<DigitalPoint>,
    /// Digital outputs, in channel order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub digital_outputs: Vec<DigitalPoint>,
    /// Analog inputs, in channel order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub analog_inputs: Vec<AnalogPoint>,
    /// Analog outputs, in channel order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub analog_outputs: Vec<AnalogPoint>,
    /// Modbus link settings (`[io.modbus]`); Modbus only, defaults apply when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modbus: Option<super::modbus::ModbusSettings>,
    /// Simulation only: a flat plate under the tool, so probing (G38.x) can be tried on the
    /// simulated machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub touch_plate: Option<TouchPlate>,
}

/// A simulated touch plate: digital input `input` of the device reads active while the
/// position of `axis` is at or below `top`, as a probe resting on a plate would. The input
/// follows the axis' actual position of the previous servo cycle.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TouchPlate {
    /// Name of one of this device's digital inputs.
    pub input: String,
    /// Axis whose position touches the plate (usually Z).
    pub axis: super::AxisName,
    /// The plate's surface: the input is active at or below it.
    pub top: f64,
}

/// I/O backends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum IoBackend {
    /// Simulated I/O (inputs set through the control socket or tests).
    Sim,
    /// A Modbus TCP device.
    ModbusTcp,
    /// A Modbus RTU device on a serial line.
    ModbusRtu,
}

impl IoBackend {
    /// True when this build can run the backend.
    pub fn is_available(self) -> bool {
        match self {
            IoBackend::Sim => true,
            IoBackend::ModbusTcp | IoBackend::ModbusRtu => true,
        }
    }

    /// The name used in the file.
    pub fn as_str(self) -> &'static str {
        match self {
            IoBackend::Sim => "sim",
            IoBackend::ModbusTcp => "modbus_tcp",
            IoBackend::ModbusRtu => "modbus_rtu",
        }
    }
}

/// A named digital channel.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DigitalPoint {
    /// Machine-wide unique channel name.
    pub name: String,
    /// Invert the signal (for normally-closed contacts such as an e-stop chain: the
    /// channel then reads "active" when the circuit opens). Applied by the machine when it
    /// reads or writes the channel by name ([`DigitalPoint::active`]), not by the backend.
    #[serde(default)]
    pub invert: bool,
    /// Modbus coil / discrete input number; Modbus only, default: the channel index.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub register: Option<u16>,
    /// Modbus table (default: discrete input for inputs, coil for outputs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<super::modbus::ModbusTable>,
    /// Modbus: bit 0..=15 of a register (with a register `table`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bit: Option<u8>,
    /// Inputs on Modbus: losing this input (timeout, exception, dropped link) stops the
    /// machine, and resuming needs a reset. For the e-stop chain, guard door, drive-enable
    /// feedback. The `[safety] estop_input` is always critical.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub critical: bool,
    /// Outputs only: the logical state the output takes in the machine's safe state (e-stop,
    /// machine off, daemon shutdown). Default `false` (inactive); set `true` for an output
    /// whose safe state is active, such as a clamp that must hold when the machine stops.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe: Option<bool>,
}

impl DigitalPoint {
    /// The logical state of this output in the machine's safe state.
    pub fn safe_state(&self) -> bool {
        self.safe.unwrap_or(false)
    }

    /// The channel's logical state ("active") from the level the device reports.
    pub fn active(&self, level: bool) -> bool {
        level != self.invert
    }

    /// The level to write to the device for the logical state `active`.
    pub fn level(&self, active: bool) -> bool {
        active != self.invert
    }
}

/// A named analog channel, in engineering units: `value = raw * scale + offset`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AnalogPoint {
    /// Machine-wide unique channel name.
    pub name: String,
    /// Engineering units per raw unit; not 0.
    #[serde(default = "default_scale")]
    pub scale: f64,
    /// Engineering value at raw 0.
    #[serde(default)]
    pub offset: f64,
    /// Modbus register number; Modbus only, default: the channel index.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub register: Option<u16>,
    /// Modbus table (default: input register for inputs, holding register for outputs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<super::modbus::ModbusTable>,
    /// Modbus register encoding (default `u16`).
    #[serde(default, rename = "type", skip_serializing_if = "Option::is_none")]
    pub value_type: Option<super::modbus::ValueType>,
    /// Modbus: word order of a 32-bit value (default `high_first`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub word_order: Option<super::modbus::WordOrderConfig>,
    /// Inputs on Modbus: losing this input stops the machine (see [`DigitalPoint::critical`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub critical: bool,
    /// Outputs only: the value (engineering units) the output takes in the machine's safe
    /// state (e-stop, machine off, daemon shutdown). Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe: Option<f64>,
}

fn default_scale() -> f64 {
    1.0
}

/// The kinds of channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IoKind {
    /// A digital input.
    DigitalInput,
    /// A digital output.
    DigitalOutput,
    /// An analog input.
    AnalogInput,
    /// An analog output.
    AnalogOutput,
}

impl IoKind {
    /// Every kind, in the order of the lists.
    pub const ALL: [IoKind; 4] = [
        IoKind::DigitalInput,
        IoKind::DigitalOutput,
        IoKind::AnalogInput,
        IoKind::AnalogOutput,
    ];

    /// The key of this kind's list in `[[io]]`.
    pub fn list_key(self) -> &'static str {
        match self {
            IoKind::DigitalInput => "digital_inputs",
            IoKind::DigitalOutput => "digital_outputs",
            IoKind::AnalogInput => "analog_inputs",
            IoKind::AnalogOutput => "analog_outputs",
        }
    }
}

impl fmt::Display for IoKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            IoKind::DigitalInput => "digital input",
            IoKind::DigitalOutput => "digital output",
            IoKind::AnalogInput => "analog input",
            IoKind::AnalogOutput => "analog output",
        })
    }
}

/// Where a named channel lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct IoRef {
    /// Index of the `[[io]]` device.
    pub device: usize,
    /// Kind of channel.
    pub kind: IoKind,
    /// Channel index on the device.
    pub channel: usize,
}

impl IoConfig {
    /// The key prefix used in messages: `io[0] (panel)`.
    pub fn key(index: usize, name: &str) -> String {
        format!("io[{index}] ({name})")
    }

    /// The channel names of one kind, in channel order.
    pub fn names(&self, kind: IoKind) -> Vec<&str> {
        match kind {
            IoKind::DigitalInput => self
                .digital_inputs
                .iter()
                .map(|p| p.name.as_str())
                .collect(),
            IoKind::DigitalOutput => self
                .digital_outputs
                .iter()
                .map(|p| p.name.as_str())
                .collect(),
            IoKind::AnalogInput => self.analog_inputs.iter().map(|p| p.name.as_str()).collect(),
            IoKind::AnalogOutput => self
                .analog_outputs
                .iter()
                .map(|p| p.name.as_str())
                .collect(),
        }
    }

    /// A simulated device with this device's channel counts; `None` unless the backend is
    /// `sim`. Inversion and scaling stay with the channel definitions
    /// ([`DigitalPoint::active`], [`AnalogPoint::to_engineering`]): the simulator holds raw
    /// values, like real hardware.
    pub fn sim_io(&self) -> Option<SimIo> {
        (self.backend == IoBackend::Sim).then(|| {
            SimIo::new(
                self.digital_inputs.len(),
                self.digital_outputs.len(),
                self.analog_inputs.len(),
                self.analog_outputs.len(),
            )
        })
    }

    /// The Modbus-only keys each channel of `kind` sets (refused with `sim`).
    fn modbus_keys(&self, kind: IoKind) -> Vec<Vec<&'static str>> {
        let d = |p: &DigitalPoint| {
            let set = [
                (p.register.is_some(), "register"),
                (p.table.is_some(), "table"),
                (p.bit.is_some(), "bit"),
                (p.critical, "critical"),
            ];
            set.iter().filter(|s| s.0).map(|s| s.1).collect()
        };
        let a = |p: &AnalogPoint| {
            let set = [
                (p.register.is_some(), "register"),
                (p.table.is_some(), "table"),
                (p.value_type.is_some(), "type"),
                (p.word_order.is_some(), "word_order"),
                (p.critical, "critical"),
            ];
            set.iter().filter(|s| s.0).map(|s| s.1).collect()
        };
        match kind {
            IoKind::DigitalInput => self.digital_inputs.iter().map(d).collect(),
            IoKind::DigitalOutput => self.digital_outputs.iter().map(d).collect(),
            IoKind::AnalogInput => self.analog_inputs.iter().map(a).collect(),
            IoKind::AnalogOutput => self.analog_outputs.iter().map(a).collect(),
        }
    }

    /// Checks the device's own values.
    pub(super) fn validate(&self, key: &str, issues: &mut Issues) {
        issues.name(format!("{key}.name"), &self.name);
        match self.backend {
            IoBackend::Sim => {
                if let Some(t) = &self.touch_plate {
                    issues.finite(format!("{key}.touch_plate.top"), t.top);
                    if !self.digital_inputs.iter().any(|p| p.name == t.input) {
                        issues.push(
                            format!("{key}.touch_plate.input"),
                            format!("{:?} is not a digital input of this device", t.input),
                        );
                    }
                }
                if self.address.is_some() {
                    issues.push(format!("{key}.address"), "not used with backend = \"sim\"");
                }
                if self.unit_id.is_some() {
                    issues.push(format!("{key}.unit_id"), "not used with backend = \"sim\"");
                }
            }
            IoBackend::ModbusTcp => match &self.address {
                None => issues.push(
                    format!("{key}.address"),
                    "required with backend = \"modbus_tcp\" (\"host:port\")",
                ),
                Some(a) if !valid_host_port(a) => issues.push(
                    format!("{key}.address"),
                    format!("must be \"host:port\" with a port in 1..=65535, got {a:?}"),
                ),
                Some(_) => {}
            },
            IoBackend::ModbusRtu => {
                if self.address.is_some() {
                    issues.push(
                        format!("{key}.address"),
                        "TCP only: an RTU device is on `modbus.device`",
                    );
                }
                if self.modbus.is_none() {
                    issues.push(
                        format!("{key}.modbus.device"),
                        "required with backend = \"modbus_rtu\" (a serial device such as /dev/ttyUSB0)",
                    );
                }
            }
        }
        if self.backend == IoBackend::Sim {
            if self.modbus.is_some() {
                issues.push(format!("{key}.modbus"), "not used with backend = \"sim\"");
            }
        } else {
            if let Some(m) = &self.modbus {
                m.validate(&format!("{key}.modbus"), self.backend, issues);
            }
            if self.unit_id == Some(0) {
                issues.push(
                    format!("{key}.unit_id"),
                    "must be 1..=247 (0 is broadcast, which never answers)",
                );
            } else if self.unit_id.is_some_and(|u| u > 247) {
                issues.push(format!("{key}.unit_id"), "must be 1..=247");
            }
            super::modbus::validate_points(self, key, issues);
        }
        if self.backend != IoBackend::Sim && self.touch_plate.is_some() {
            issues.push(
                format!("{key}.touch_plate"),
                format!(
                    "simulation only: not used with backend = {:?}",
                    self.backend.as_str()
                ),
            );
        }
        for kind in [
            IoKind::DigitalInput,
            IoKind::DigitalOutput,
            IoKind::AnalogInput,
            IoKind::AnalogOutput,
        ] {
            let list = kind.list_key();
            for (i, (name, modbus_keys)) in self
                .names(kind)
                .into_iter()
                .zip(self.modbus_keys(kind))
                .enumerate()
            {
                issues.name(format!("{key}.{list}[{i}].name"), name);
                if self.backend == IoBackend::Sim {
                    for k in modbus_keys {
                        issues.push(
                            format!("{key}.{list}[{i}] ({name}).{k}"),
                            "Modbus only: not used with backend = \"sim\"",
                        );
                    }
                }
            }
        }
        for (i, p) in self.analog_inputs.iter().enumerate() {
            let k = format!("{key}.analog_inputs[{i}] ({})", p.name);
            p.validate(&k, issues);
            if p.safe.is_some() {
                issues.push(format!("{k}.safe"), SAFE_ON_INPUT);
            }
        }
        for (i, p) in self.analog_outputs.iter().enumerate() {
            let k = format!("{key}.analog_outputs[{i}] ({})", p.name);
            p.validate(&k, issues);
            if let Some(v) = p.safe {
                issues.finite(format!("{k}.safe"), v);
            }
        }
        for (i, p) in self.digital_inputs.iter().enumerate() {
            if p.safe.is_some() {
                issues.push(
                    format!("{key}.digital_inputs[{i}] ({}).safe", p.name),
                    SAFE_ON_INPUT,
                );
            }
        }
    }
}

impl AnalogPoint {
    /// Engineering value from the device's raw value.
    pub fn to_engineering(&self, raw: f64) -> f64 {
        raw * self.scale + self.offset
    }

    /// The value of this output in the machine's safe state.
    pub fn safe_value(&self) -> f64 {
        self.safe.unwrap_or(0.0)
    }

    /// Raw device value for an engineering value (the inverse of
    /// [`to_engineering`](AnalogPoint::to_engineering); `scale` is never 0 once validated).
    pub fn to_raw(&self, value: f64) -> f64 {
        (value - self.offset) / self.scale
    }

    fn validate(&self, key: &str, issues: &mut Issues) {
        if self.scale == 0.0 || !self.scale.is_finite() {
            issues.push(
                format!("{key}.scale"),
                format!("must be a non-zero finite number, got {}", self.scale),
            );
        }
        issues.finite(format!("{key}.offset"), self.offset);
    }
}

const SAFE_ON_INPUT: &str = "only outputs have a safe state";

/// `host:port` with a non-empty host and a port in 1..=65535 (IPv6 hosts in brackets).
fn valid_host_port(s: &str) -> bool {
    match s.rsplit_once(':') {
        Some((host, port)) => !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p != 0),
        None => false,
    }
}

/// Indexes every channel name of all devices; records duplicates as issues.
pub(super) fn index(devices: &[IoConfig], issues: &mut Issues) -> HashMap<String, IoRef> {
    let mut by_name: HashMap<String, IoRef> = HashMap::new();
    let mut device_names: HashMap<&str, usize> = HashMap::new();
    for (d, dev) in devices.iter().enumerate() {
        let key = IoConfig::key(d, &dev.name);
        if let Some(first) = device_names.insert(&dev.name, d) {
            issues.push(
                format!("{key}.name"),
                format!("duplicate of {}", IoConfig::key(first, &dev.name)),
            );
        }
        for kind in [
            IoKind::DigitalInput,
            IoKind::DigitalOutput,
            IoKind::AnalogInput,
            IoKind::AnalogOutput,
        ] {
            for (channel, name) in dev.names(kind).into_iter().enumerate() {
                let here = IoRef {
                    device: d,
                    kind,
                    channel,
                };
                if let Some(first) = by_name.get(name) {
                    issues.push(
                        format!("{key}.{}[{channel}].name", kind.list_key()),
                        format!(
                            "{name:?} is already used by {}.{}[{}]: channel names are machine-wide",
                            IoConfig::key(first.device, &devices[first.device].name),
                            first.kind.list_key(),
                            first.channel
                        ),
                    );
                } else {
                    by_name.insert(name.to_string(), here);
                }
            }
        }
    }
    by_name
}

#[cfg(test)]
mod tests {
    use super::{valid_host_port, IoConfig};
    use crate::config::error::Issues;

    #[test]
    fn a_safe_state_is_for_outputs_only() {
        let dev: IoConfig = toml::from_str(
            r#"
            name = "panel"
            backend = "sim"
            digital_inputs = [{ name = "estop", safe = true }]
            digital_outputs = [{ name = "clamp", safe = true }, { name = "lamp" }]
            analog_inputs = [{ name = "load", safe = 1.0 }]
            analog_outputs = [{ name = "speed", safe = 150.0 }]
            "#,
        )
        .expect("parse");
        assert!(dev.digital_outputs[0].safe_state());
        assert!(!dev.digital_outputs[1].safe_state());
        assert_eq!(dev.analog_outputs[0].safe_value(), 150.0);
        let mut issues = Issues::default();
        dev.validate("io[0] (panel)", &mut issues);
        let keys: Vec<String> = issues.into_vec().into_iter().map(|i| i.key).collect();
        assert_eq!(
            keys,
            [
                "io[0] (panel).analog_inputs[0] (load).safe",
                "io[0] (panel).digital_inputs[0] (estop).safe",
            ]
        );
    }

    #[test]
    fn host_port_addresses() {
        assert!(valid_host_port("192.168.1.20:502"));
        assert!(valid_host_port("plc.local:1502"));
        assert!(valid_host_port("[::1]:502"));
        assert!(!valid_host_port("192.168.1.20"));
        assert!(!valid_host_port(":502"));
        assert!(!valid_host_port("host:0"));
        assert!(!valid_host_port("host:99999"));
    }
}
