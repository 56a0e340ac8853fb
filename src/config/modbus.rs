//! Modbus settings of an `[[io]]` device: the link (`[io.modbus]`) and each channel's place
//! in the device's tables (`table`, `register`, `bit`, `type`, `word_order`).
//!
//! Defaults follow the usual I/O coupler layout: digital inputs are discrete inputs,
//! digital outputs coils, analog inputs input registers and analog outputs holding
//! registers, each one `u16` at the channel's index. A digital channel can also be one bit
//! of a register (`table = "holding_register", bit = 3`).

use super::error::Issues;
use super::io::{AnalogPoint, DigitalPoint, IoBackend, IoConfig, IoKind};
use hytask_hal::modbus::{DataType, PointSpec, Table, WordOrder};
use serde::{Deserialize, Serialize};

/// `table` of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModbusTable {
    /// Coils (read/write bits).
    Coil,
    /// Discrete inputs (read-only bits).
    DiscreteInput,
    /// Holding registers (read/write).
    HoldingRegister,
    /// Input registers (read-only).
    InputRegister,
}

impl From<ModbusTable> for Table {
    fn from(t: ModbusTable) -> Table {
        match t {
            ModbusTable::Coil => Table::Coil,
            ModbusTable::DiscreteInput => Table::DiscreteInput,
            ModbusTable::HoldingRegister => Table::HoldingRegister,
            ModbusTable::InputRegister => Table::InputRegister,
        }
    }
}

/// `type` of an analog channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ValueType {
    /// One unsigned register.
    U16,
    /// One signed register.
    I16,
    /// Two registers, unsigned.
    U32,
    /// Two registers, signed.
    I32,
    /// Two registers, IEEE float.
    F32,
}

/// `word_order` of a 32-bit channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WordOrderConfig {
    /// High word first (default).
    HighFirst,
    /// Low word first.
    LowFirst,
}

/// Serial parity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Parity {
    /// No parity (default; use 2 stop bits per the standard, or what the device wants).
    #[default]
    None,
    /// Even parity (the Modbus RTU default of many devices).
    Even,
    /// Odd parity.
    Odd,
}

/// `[io.modbus]`: link settings. Devices with the same `address` (TCP) or `device` (RTU)
/// share one link and are polled in turn by one task.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ModbusSettings {
    /// RTU: the serial device (`/dev/ttyUSB0`, a pty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// RTU: baud rate (default 19200).
    #[serde(default = "default_baud")]
    pub baud_rate: u32,
    /// RTU: parity (default none).
    #[serde(default)]
    pub parity: Parity,
    /// RTU: stop bits, 1 or 2 (default 1).
    #[serde(default = "default_stop_bits")]
    pub stop_bits: u8,
    /// Poll period of this device in ms (default 10).
    #[serde(default = "default_poll_ms")]
    pub poll_ms: u32,
    /// Answer timeout per transaction in ms (default 100).
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: u32,
    /// Outputs are written again every `refresh_ms` even unchanged (default 1000; 0: never).
    #[serde(default = "default_refresh_ms")]
    pub refresh_ms: u32,
    /// Unused registers a read may span to merge two points into one request (default 0).
    #[serde(default)]
    pub max_gap: u16,
    /// Longest wait between reconnect attempts in ms (default 2000; starts at `poll_ms`).
    #[serde(default = "default_backoff_ms")]
    pub max_backoff_ms: u32,
}

fn default_baud() -> u32 {
    19200
}
fn default_stop_bits() -> u8 {
    1
}
fn default_poll_ms() -> u32 {
    10
}
fn default_timeout_ms() -> u32 {
    100
}
fn default_refresh_ms() -> u32 {
    1000
}
fn default_backoff_ms() -> u32 {
    2000
}

impl Default for ModbusSettings {
    fn default() -> Self {
        ModbusSettings {
            device: None,
            baud_rate: default_baud(),
            parity: Parity::None,
            stop_bits: default_stop_bits(),
            poll_ms: default_poll_ms(),
            timeout_ms: default_timeout_ms(),
            refresh_ms: default_refresh_ms(),
            max_gap: 0,
            max_backoff_ms: default_backoff_ms(),
        }
    }
}

impl ModbusSettings {
    pub(super) fn validate(&self, key: &str, backend: IoBackend, issues: &mut Issues) {
        let rtu = backend == IoBackend::ModbusRtu;
        match (&self.device, rtu) {
            (None, true) => issues.push(
                format!("{key}.device"),
                "required with backend = \"modbus_rtu\" (a serial device such as /dev/ttyUSB0)",
            ),
            (Some(_), false) => issues.push(
                format!("{key}.device"),
                "RTU only: a TCP device is reached at `address`",
            ),
            _ => {}
        }
        if self.baud_rate == 0 {
            issues.push(format!("{key}.baud_rate"), "must be > 0");
        }
        if !(1..=2).contains(&self.stop_bits) {
            issues.push(
                format!("{key}.stop_bits"),
                format!("must be 1 or 2, got {}", self.stop_bits),
            );
        }
        for (k, v, min) in [
            ("poll_ms", self.poll_ms, 1),
            ("timeout_ms", self.timeout_ms, 1),
            ("max_backoff_ms", self.max_backoff_ms, 1),
        ] {
            if v < min {
                issues.push(format!("{key}.{k}"), format!("must be >= {min}, got {v}"));
            }
        }
    }
}

/// The link a device is on: `tcp:host:port` or `rtu:/dev/...` (devices with the same link
/// share one poller).
pub fn link_name(io: &IoConfig) -> Option<String> {
    match io.backend {
        IoBackend::Sim => None,
        IoBackend::ModbusTcp => io.address.as_ref().map(|a| format!("tcp:{a}")),
        IoBackend::ModbusRtu => io
            .modbus
            .as_ref()
            .and_then(|m| m.device.as_ref())
            .map(|d| format!("rtu:{d}")),
    }
}

impl DigitalPoint {
    /// This channel's place on a Modbus device; `index` is its position in its list
    /// (the default address), `output` selects the default table.
    pub fn modbus_spec(&self, index: usize, output: bool) -> Result<PointSpec, (String, String)> {
        let default = if output {
            ModbusTable::Coil
        } else {
            ModbusTable::DiscreteInput
        };
        let table: Table = self.table.unwrap_or(default).into();
        let data_type = match (self.bit, table.is_bits()) {
            (None, true) => DataType::Bool,
            (Some(b), false) => DataType::Bit(b),
            (None, false) => {
                return Err((
                    "bit".into(),
                    format!("required for a digital channel in a {table} (0..=15)"),
                ))
            }
            (Some(_), true) => {
                return Err(("bit".into(), format!("not used with table {table}")));
            }
        };
        spec(
            table,
            self.register,
            index,
            data_type,
            WordOrder::HighFirst,
            output,
        )
    }
}

impl AnalogPoint {
    /// This channel's place on a Modbus device (see [`DigitalPoint::modbus_spec`]).
    pub fn modbus_spec(&self, index: usize, output: bool) -> Result<PointSpec, (String, String)> {
        let default = if output {
            ModbusTable::HoldingRegister
        } else {
            ModbusTable::InputRegister
        };
        let table: Table = self.table.unwrap_or(default).into();
        if table.is_bits() {
            return Err((
                "table".into(),
                format!("an analog channel needs a register table, not {table}"),
            ));
        }
        let data_type = match self.value_type.unwrap_or(ValueType::U16) {
            ValueType::U16 => DataType::U16,
            ValueType::I16 => DataType::I16,
            ValueType::U32 => DataType::U32,
            ValueType::I32 => DataType::I32,
            ValueType::F32 => DataType::F32,
        };
        if self.word_order.is_some() && data_type.width() == 1 {
            return Err((
                "word_order".into(),
                "only for 32-bit types (u32, i32, f32)".into(),
            ));
        }
        let order = match self.word_order {
            Some(WordOrderConfig::LowFirst) => WordOrder::LowFirst,
            _ => WordOrder::HighFirst,
        };
        spec(table, self.register, index, data_type, order, output)
    }
}

fn spec(
    table: Table,
    register: Option<u16>,
    index: usize,
    data_type: DataType,
    order: WordOrder,
    output: bool,
) -> Result<PointSpec, (String, String)> {
    let address = match register {
        Some(r) => r,
        None => {
            u16::try_from(index).map_err(|_| ("register".into(), "index beyond 65535".into()))?
        }
    };
    let p = PointSpec::new(table, address, data_type, order)
        .map_err(|e| ("register".to_string(), e.to_string()))?;
    if output {
        p.writable()
            .map_err(|e| ("table".to_string(), e.to_string()))
    } else {
        Ok(p)
    }
}

type SpecResult = Result<PointSpec, (String, String)>;

/// Each channel of `kind`: its name and its spec (or the failing sub-key and message).
fn each(io: &IoConfig, kind: IoKind) -> Vec<(&str, SpecResult)> {
    let out = matches!(kind, IoKind::DigitalOutput | IoKind::AnalogOutput);
    match kind {
        IoKind::DigitalInput => digital_specs(&io.digital_inputs, out),
        IoKind::DigitalOutput => digital_specs(&io.digital_outputs, out),
        IoKind::AnalogInput => analog_specs(&io.analog_inputs, out),
        IoKind::AnalogOutput => analog_specs(&io.analog_outputs, out),
    }
}

fn digital_specs(l: &[DigitalPoint], out: bool) -> Vec<(&str, SpecResult)> {
    l.iter()
        .enumerate()
        .map(|(i, p)| (p.name.as_str(), p.modbus_spec(i, out)))
        .collect()
}

fn analog_specs(l: &[AnalogPoint], out: bool) -> Vec<(&str, SpecResult)> {
    l.iter()
        .enumerate()
        .map(|(i, p)| (p.name.as_str(), p.modbus_spec(i, out)))
        .collect()
}

/// Every channel's spec of one kind, in channel order; the error names the channel's key
/// (relative to the device).
pub fn specs(io: &IoConfig, kind: IoKind) -> Result<Vec<PointSpec>, (String, String)> {
    each(io, kind)
        .into_iter()
        .enumerate()
        .map(|(i, (name, r))| {
            r.map_err(|(k, m)| (format!("{}[{i}] ({name}).{k}", kind.list_key()), m))
        })
        .collect()
}

/// Checks every channel's spec and that no two outputs overlap.
pub(super) fn validate_points(io: &IoConfig, key: &str, issues: &mut Issues) {
    let mut written: Vec<(PointSpec, String)> = Vec::new();
    for kind in IoKind::ALL {
        let output = matches!(kind, IoKind::DigitalOutput | IoKind::AnalogOutput);
        for (i, (name, r)) in each(io, kind).into_iter().enumerate() {
            let here = format!("{key}.{}[{i}] ({name})", kind.list_key());
            match r {
                Err((k, m)) => issues.push(format!("{here}.{k}"), m),
                Ok(p) if output => {
                    if let Some((_, other)) = written.iter().find(|(q, _)| overlaps(&p, q)) {
                        issues.push(
                            format!("{here}.register"),
                            format!("overlaps the output {other}"),
                        );
                    }
                    written.push((p, here));
                }
                Ok(_) => {}
            }
        }
    }
}

/// True when two outputs write the same bits.
fn overlaps(a: &PointSpec, b: &PointSpec) -> bool {
    if a.table != b.table {
        return false;
    }
    let (a0, a1) = (a.address, a.address + a.width() - 1);
    let (b0, b1) = (b.address, b.address + b.width() - 1);
    let same_words = a0 <= b1 && b0 <= a1;
    match (a.data_type, b.data_type) {
        (DataType::Bit(x), DataType::Bit(y)) => same_words && x == y,
        _ => same_words,
    }
}

#[cfg(test)]
mod tests {
    use crate::config::error::Issues;
    use crate::config::IoConfig;

    fn keys(toml_text: &str) -> Vec<String> {
        let dev: IoConfig = toml::from_str(toml_text).expect("parse");
        let mut issues = Issues::default();
        dev.validate("io[0] (p)", &mut issues);
        issues
            .into_vec()
            .into_iter()
            .map(|i| format!("{}: {}", i.key, i.message))
            .collect()
    }

    #[test]
    fn modbus_point_keys_are_checked_by_name() {
        let found = keys(
            r#"
            name = "p"
            backend = "modbus_tcp"
            address = "127.0.0.1:502"
            unit_id = 0
            modbus = { poll_ms = 0, stop_bits = 3 }
            digital_inputs = [
                { name = "a", table = "input_register" },
                { name = "b", table = "discrete_input", bit = 2 },
                { name = "c", table = "holding_register", bit = 16 },
            ]
            digital_outputs = [
                { name = "d", table = "discrete_input" },
                { name = "e", register = 4 },
                { name = "f", register = 4 },
            ]
            analog_inputs = [{ name = "g", table = "coil" }, { name = "h", word_order = "low_first" }]
            analog_outputs = [{ name = "i", register = 65535, type = "f32" }]
            "#,
        );
        let want = [
            "io[0] (p).unit_id: must be 1..=247 (0 is broadcast, which never answers)",
            "io[0] (p).modbus.stop_bits: must be 1 or 2, got 3",
            "io[0] (p).modbus.poll_ms: must be >= 1, got 0",
            "io[0] (p).digital_inputs[0] (a).bit: required for a digital channel in a input_register (0..=15)",
            "io[0] (p).digital_inputs[1] (b).bit: not used with table discrete_input",
            "io[0] (p).digital_inputs[2] (c).register: bit 16 out of range 0..=15",
            "io[0] (p).digital_outputs[0] (d).table: discrete_input is read-only: outputs need a coil or a holding register",
            "io[0] (p).digital_outputs[2] (f).register: overlaps the output io[0] (p).digital_outputs[1] (e)",
            "io[0] (p).analog_inputs[0] (g).table: an analog channel needs a register table, not coil",
            "io[0] (p).analog_inputs[1] (h).word_order: only for 32-bit types (u32, i32, f32)",
            "io[0] (p).analog_outputs[0] (i).register: address 65535 + 2 registers runs past 65535",
        ];
        for w in want {
            assert!(found.iter().any(|f| f == w), "missing {w:?} in {found:#?}");
        }
        assert_eq!(found.len(), want.len(), "{found:#?}");
    }

    #[test]
    fn rtu_needs_a_device_and_sim_refuses_modbus_keys() {
        let found = keys("name = \"p\"\nbackend = \"modbus_rtu\"\naddress = \"h:1\"\n");
        assert_eq!(
            found,
            [
                "io[0] (p).address: TCP only: an RTU device is on `modbus.device`",
                "io[0] (p).modbus.device: required with backend = \"modbus_rtu\" (a serial device such as /dev/ttyUSB0)",
            ]
        );
        let found = keys(
            "name = \"p\"\nbackend = \"sim\"\nmodbus = {}\ndigital_inputs = [{ name = \"x\", critical = true, bit = 1 }]\n",
        );
        assert_eq!(
            found,
            [
                "io[0] (p).modbus: not used with backend = \"sim\"",
                "io[0] (p).digital_inputs[0] (x).bit: Modbus only: not used with backend = \"sim\"",
                "io[0] (p).digital_inputs[0] (x).critical: Modbus only: not used with backend = \"sim\"",
            ]
        );
    }

    #[test]
    fn bits_and_32_bit_values_map_to_specs() {
        use hytask_hal::modbus::{DataType, Table, WordOrder};
        let dev: IoConfig = toml::from_str(
            r#"
            name = "p"
            backend = "modbus_tcp"
            address = "h:1"
            digital_outputs = [{ name = "run", table = "holding_register", register = 8, bit = 1 }]
            analog_inputs = [{ name = "f", type = "f32", word_order = "low_first", register = 4 }]
            "#,
        )
        .expect("parse");
        let o = super::specs(&dev, crate::config::IoKind::DigitalOutput).expect("specs");
        assert_eq!(
            (o[0].table, o[0].address, o[0].data_type),
            (Table::HoldingRegister, 8, DataType::Bit(1))
        );
        let a = super::specs(&dev, crate::config::IoKind::AnalogInput).expect("specs");
        assert_eq!(
            (a[0].table, a[0].data_type, a[0].word_order),
            (Table::InputRegister, DataType::F32, WordOrder::LowFirst)
        );
    }
}
