//! `[[drive]]`: how each axis' motor is reached: a simulated drive, or a CANopen CiA 402
//! drive.
//!
//! The backend is declared in the file (`backend = "sim" | "canopen"`) with its settings in
//! a sub-table named after it (`[drive.sim]`, `[drive.canopen]`). A backend that this build
//! cannot run still parses and validates, so a real machine's file can be checked on any
//! computer; deploying it reports "not available in this build" (see
//! [`DriveBackend::is_available`]).
//!
//! A CANopen drive on `interface = "sim"` runs as an in-process loopback CiA 402 drive on
//! an in-memory bus, stepped by the servo thread: the whole CANopen path without hardware.

use super::axis::{AxisConfig, HomeMethod};
use super::error::Issues;
use hytask_hal::sim::{FaultInjection, SimAxisConfig, SwitchRange};
use hytask_hal::FaultCode;
use serde::{Deserialize, Serialize};

/// How far the simulated drive's own velocity and acceleration limits exceed the axis'
/// planning limits: a real drive is sized with headroom, so the position loop can catch up
/// at full planned speed.
pub const SIM_DRIVE_HEADROOM: f64 = 1.25;

/// `[[drive]]`: one drive (joint).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DriveConfig {
    /// Name axes use to refer to this drive; unique.
    pub name: String,
    /// Which backend runs it.
    pub backend: DriveBackend,
    /// Settings of the simulated drive; only with `backend = "sim"` (defaults if absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim: Option<SimDriveConfig>,
    /// Settings of a CANopen drive; required with `backend = "canopen"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub canopen: Option<CanopenDriveConfig>,
}

/// Drive backends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriveBackend {
    /// The simulated axis of `hytask-hal` (motor model, switches, fault injection).
    Sim,
    /// A CiA 402 drive on a CAN bus (SocketCAN), in cyclic synchronous position mode.
    Canopen,
}

impl DriveBackend {
    /// True when this build can run the backend.
    pub fn is_available(self) -> bool {
        match self {
            DriveBackend::Sim => true,
            DriveBackend::Canopen => true,
        }
    }

    /// The name used in the file.
    pub fn as_str(self) -> &'static str {
        match self {
            DriveBackend::Sim => "sim",
            DriveBackend::Canopen => "canopen",
        }
    }
}

/// `[drive.sim]`: the simulated motor and machine. Positions are physical, in the axis'
/// machine units, as seen before homing (the simulator starts with reported = physical).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SimDriveConfig {
    /// Position-loop time constant in seconds: following error = speed × lag (0 ..= 1).
    #[serde(default = "default_lag_s")]
    pub lag_s: f64,
    /// Quick-stop deceleration in units/s². Default: twice the axis' max_acceleration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quick_stop_deceleration: Option<f64>,
    /// The drive's own following-error window (it faults beyond it); none if absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub following_error_window: Option<f64>,
    /// Position at power-on.
    #[serde(default)]
    pub initial_position: f64,
    /// Negative limit switch: active at and below this position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub negative_limit: Option<f64>,
    /// Positive limit switch: active at and above this position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positive_limit: Option<f64>,
    /// Home switch: active between `min` and `max`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub home_switch: Option<SwitchConfig>,
    /// Inject a drive fault at this simulated time (seconds after start).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fault_at_s: Option<f64>,
    /// Fault code of the injected fault (CiA 402 0x603F), e.g. 0x2310 over-current.
    #[serde(default = "default_fault_code")]
    pub fault_code: u16,
    /// Stall the motor (position stops following) at this simulated time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stall_at_s: Option<f64>,
}

fn default_lag_s() -> f64 {
    0.005
}

fn default_fault_code() -> u16 {
    FaultCode::GENERIC.0
}

impl Default for SimDriveConfig {
    fn default() -> Self {
        SimDriveConfig {
            lag_s: default_lag_s(),
            quick_stop_deceleration: None,
            following_error_window: None,
            initial_position: 0.0,
            negative_limit: None,
            positive_limit: None,
            home_switch: None,
            fault_at_s: None,
            fault_code: default_fault_code(),
            stall_at_s: None,
        }
    }
}

/// A switch's active region.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SwitchConfig {
    /// Lower end of the active region.
    pub min: f64,
    /// Upper end of the active region.
    pub max: f64,
}

/// `[drive.canopen]`: a CiA 402 drive on a CAN bus.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CanopenDriveConfig {
    /// SocketCAN interface (e.g. `can0`, `vcan0`); drives on one interface share one bus
    /// owner.
    pub interface: String,
    /// CANopen node id (1 ..= 127), unique per interface.
    pub node_id: u8,
    /// Heartbeat period the drive is configured to produce, in ms; a missed heartbeat is a
    /// link failure (`Timeout`).
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u32,
    /// How long to wait for an SDO answer during configuration, in ms.
    #[serde(default = "default_sdo_timeout_ms")]
    pub sdo_timeout_ms: u32,
    /// Mode of operation; only `"csp"` (cyclic synchronous position, 0x6060 = 8).
    #[serde(default)]
    pub mode: CanopenMode,
    /// PDO layout: also map velocity actual + modes display in TPDO2 (one more frame per
    /// drive and cycle). Without it the velocity reads 0.
    #[serde(default = "default_true")]
    pub velocity_pdo: bool,
    /// Bus bitrate in bit/s (for the bus-load budget); the same for every drive of the
    /// interface.
    #[serde(default = "default_bitrate")]
    pub bitrate: u32,
    /// Most bus load SYNC + PDOs may take, percent of the bitrate; the same for every
    /// drive of the interface. A configuration over it does not deploy.
    #[serde(default = "default_busload_limit_pct")]
    pub busload_limit_pct: u8,
    /// SYNC counter overflow value (2 ..= 240), or 0 for SYNC without counter; the same
    /// for every drive of the interface.
    #[serde(default)]
    pub sync_counter: u8,
    /// Where the axis homes: `"master"` (in CSP, the present position becomes
    /// `[axis.home] position`) or `"drive"` (the drive's own homing mode, method
    /// `homing_method`; 0x607C home offset = `[axis.home] position` × scale).
    #[serde(default)]
    pub homing: CanopenHoming,
    /// CiA 402 homing method 0x6098 with `homing = "drive"` (e.g. 17/18 limit switch,
    /// 19..=22 home switch, 35/37 current position).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub homing_method: Option<i8>,
    /// 0x6099 speeds with `homing = "drive"`: [search for switch, search for zero], in the
    /// drive's units (counts/s), written as they are.
    #[serde(default = "default_homing_speeds")]
    pub homing_speeds: [u32; 2],
    /// 0x609A homing acceleration with `homing = "drive"`, counts/s² (0: the drive's own).
    #[serde(default)]
    pub homing_acceleration: u32,
    /// How long drive-side homing may take, mode switches included, in ms.
    #[serde(default = "default_homing_timeout_ms")]
    pub homing_timeout_ms: u32,
    /// `interface = "sim"` only: the in-process loopback drive's position-loop lag in
    /// seconds (how far behind a moving target it runs: velocity × lag). Default 5 ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loopback_lag_s: Option<LagSeconds>,
    /// The drive's EDS file (CiA 306), for object names in `rpdo` / `tpdo`; a relative
    /// path is relative to the configuration file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eds: Option<std::path::PathBuf>,
    /// RPDO1 mapping by EDS object names, in order (default: controlword, target position,
    /// and modes of operation with `homing = "drive"`). Must map 0x6040 and 0x607A.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpdo: Option<Vec<String>>,
    /// TPDO1 mapping by EDS object names, in order (default: statusword, position actual,
    /// and modes display with `homing = "drive"`). Must map 0x6041 and 0x6064.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tpdo: Option<Vec<String>>,
}

/// A lag in seconds, `0.0 ..= 1.0` (checked by the validation), compared by its bits so
/// the drive configuration stays `Eq`.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(transparent)]
pub struct LagSeconds(pub f64);

impl PartialEq for LagSeconds {
    fn eq(&self, other: &Self) -> bool {
        self.0.to_bits() == other.0.to_bits()
    }
}

impl Eq for LagSeconds {}

/// `[drive.canopen] homing`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CanopenHoming {
    /// The master homes in CSP by an offset (current position, no motion).
    #[default]
    Master,
    /// The drive homes in CiA 402 homing mode, commanded through the process data.
    Drive,
}

fn default_homing_speeds() -> [u32; 2] {
    [20_000, 2_000]
}

fn default_homing_timeout_ms() -> u32 {
    60_000
}

/// `[drive.canopen] mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CanopenMode {
    /// Cyclic synchronous position: a target every SYNC.
    #[default]
    Csp,
}

/// The interface name that runs loopback drives in-process on an in-memory bus.
pub const SIM_INTERFACE: &str = "sim";

fn default_true() -> bool {
    true
}

fn default_bitrate() -> u32 {
    1_000_000
}

fn default_busload_limit_pct() -> u8 {
    80
}

fn default_heartbeat_ms() -> u32 {
    100
}

fn default_sdo_timeout_ms() -> u32 {
    100
}

impl DriveConfig {
    /// The key prefix used in messages: `drive[0] (x)`.
    pub fn key(index: usize, name: &str) -> String {
        format!("drive[{index}] ({name})")
    }

    /// Fills defaults that depend on the backend: a sim drive without `[drive.sim]` gets
    /// the default settings, so the resolved machine shows them.
    pub(super) fn resolve(&mut self, axis: Option<&AxisConfig>) {
        if self.backend == DriveBackend::Sim {
            let sim = self.sim.get_or_insert_with(SimDriveConfig::default);
            if let (None, Some(a)) = (sim.quick_stop_deceleration, axis) {
                sim.quick_stop_deceleration = Some(2.0 * a.max_acceleration);
            }
        }
    }

    /// The simulator's parameters for this drive moving `axis`; `None` unless the backend
    /// is `sim`.
    pub fn sim_axis_config(&self, axis: &AxisConfig) -> Option<SimAxisConfig> {
        if self.backend != DriveBackend::Sim {
            return None;
        }
        let sim = self.sim.clone().unwrap_or_default();
        Some(SimAxisConfig {
            max_velocity: axis.max_velocity * SIM_DRIVE_HEADROOM,
            max_acceleration: axis.max_acceleration * SIM_DRIVE_HEADROOM,
            lag_s: sim.lag_s,
            quick_stop_deceleration: sim
                .quick_stop_deceleration
                .unwrap_or(2.0 * axis.max_acceleration),
            following_error_window: sim.following_error_window,
            initial_position: sim.initial_position,
            negative_limit: sim.negative_limit,
            positive_limit: sim.positive_limit,
            home_switch: sim.home_switch.map(|s| SwitchRange {
                min: s.min,
                max: s.max,
            }),
            faults: FaultInjection {
                drive_fault_at_s: sim.fault_at_s,
                drive_fault_code: FaultCode(sim.fault_code),
                stall_at_s: sim.stall_at_s,
            },
        })
    }

    /// Checks the drive's own values; `axis` is the axis it moves (if any), to check that
    /// the simulated switches support the axis' homing method.
    pub(super) fn validate(&self, key: &str, axis: Option<&AxisConfig>, issues: &mut Issues) {
        issues.name(format!("{key}.name"), &self.name);
        let backend = self.backend.as_str();
        if self.backend != DriveBackend::Sim && self.sim.is_some() {
            issues.push(
                format!("{key}.sim"),
                format!("only used with backend = \"sim\" (backend is \"{backend}\")"),
            );
        }
        if self.backend != DriveBackend::Canopen && self.canopen.is_some() {
            issues.push(
                format!("{key}.canopen"),
                format!("only used with backend = \"canopen\" (backend is \"{backend}\")"),
            );
        }
        match self.backend {
            DriveBackend::Sim => {
                if let Some(sim) = &self.sim {
                    sim.validate(&format!("{key}.sim"), axis, issues);
                }
            }
            DriveBackend::Canopen => match &self.canopen {
                Some(c) => {
                    c.validate(&format!("{key}.canopen"), issues);
                    if let Some(a) = axis.filter(|a| a.home.method != HomeMethod::CurrentPosition) {
                        // The master cannot search a switch (the drive reads it): switch
                        // homing on a CANopen axis is the drive's own homing method.
                        issues.push(
                            format!("{key}.canopen"),
                            format!(
                                "axis {} homes with a switch, which the master cannot do on a CANopen drive: keep [axis.home] method = \"current_position\" and let the drive search its switch with homing = \"drive\" and homing_method (e.g. 19)",
                                a.name
                            ),
                        );
                    }
                }
                None => issues.push(
                    format!("{key}.canopen"),
                    "required with backend = \"canopen\" (interface, node_id)",
                ),
            },
        }
    }
}

impl SimDriveConfig {
    fn validate(&self, key: &str, axis: Option<&AxisConfig>, issues: &mut Issues) {
        issues.in_range(format!("{key}.lag_s"), self.lag_s, 0.0, 1.0);
        if let Some(d) = self.quick_stop_deceleration {
            issues.positive(format!("{key}.quick_stop_deceleration"), d);
        }
        if let Some(w) = self.following_error_window {
            issues.positive(format!("{key}.following_error_window"), w);
        }
        issues.finite(format!("{key}.initial_position"), self.initial_position);
        if let Some(n) = self.negative_limit {
            issues.finite(format!("{key}.negative_limit"), n);
        }
        if let Some(p) = self.positive_limit {
            issues.finite(format!("{key}.positive_limit"), p);
        }
        if let (Some(n), Some(p)) = (self.negative_limit, self.positive_limit) {
            if n >= p {
                issues.push(
                    format!("{key}.positive_limit"),
                    format!("must be above negative_limit ({n}), got {p}"),
                );
            }
        }
        if let Some(s) = self.home_switch {
            if !(s.min.is_finite() && s.max.is_finite() && s.min <= s.max) {
                issues.push(
                    format!("{key}.home_switch"),
                    format!("min must be <= max, got {}..{}", s.min, s.max),
                );
            }
        }
        if let Some(t) = self.fault_at_s {
            issues.non_negative(format!("{key}.fault_at_s"), t);
        }
        if let Some(t) = self.stall_at_s {
            issues.non_negative(format!("{key}.stall_at_s"), t);
        }
        let Some(axis) = axis else { return };
        let needs = match axis.home.method {
            HomeMethod::Switch if self.home_switch.is_none() => Some("home_switch"),
            HomeMethod::LimitSwitch
                if axis.home.velocity > 0.0 && self.positive_limit.is_none() =>
            {
                Some("positive_limit")
            }
            HomeMethod::LimitSwitch
                if axis.home.velocity < 0.0 && self.negative_limit.is_none() =>
            {
                Some("negative_limit")
            }
            _ => None,
        };
        if let Some(what) = needs {
            issues.push(
                format!("{key}.{what}"),
                format!(
                    "required: axis {} homes with method = \"{}\"",
                    axis.name,
                    match axis.home.method {
                        HomeMethod::Switch => "switch",
                        _ => "limit_switch",
                    }
                ),
            );
        }
    }
}

impl CanopenDriveConfig {
    fn validate(&self, key: &str, issues: &mut Issues) {
        // Linux interface names hold at most 15 bytes (IFNAMSIZ - 1).
        if self.interface.is_empty() || self.interface.len() > 15 {
            issues.push(
                format!("{key}.interface"),
                format!(
                    "must be a network interface name of 1..=15 bytes, got {:?}",
                    self.interface
                ),
            );
        }
        issues.in_range(format!("{key}.node_id"), self.node_id, 1, 127);
        issues.in_range(format!("{key}.heartbeat_ms"), self.heartbeat_ms, 1, 65_535);
        issues.in_range(
            format!("{key}.sdo_timeout_ms"),
            self.sdo_timeout_ms,
            1,
            10_000,
        );
        issues.in_range(format!("{key}.bitrate"), self.bitrate, 10_000, 1_000_000);
        issues.in_range(
            format!("{key}.busload_limit_pct"),
            self.busload_limit_pct,
            1,
            100,
        );
        if self.sync_counter == 1 || self.sync_counter > 240 {
            issues.push(
                format!("{key}.sync_counter"),
                format!(
                    "must be 0 (no counter) or 2..=240, got {}",
                    self.sync_counter
                ),
            );
        }
        match (self.homing, self.homing_method) {
            (CanopenHoming::Drive, None | Some(0)) => issues.push(
                format!("{key}.homing_method"),
                "required with homing = \"drive\": the drive's CiA 402 homing method (0x6098, e.g. 19 home switch, 35 current position), not 0",
            ),
            (CanopenHoming::Master, Some(m)) => issues.push(
                format!("{key}.homing_method"),
                format!("{m} is only used with homing = \"drive\" (homing is \"master\")"),
            ),
            _ => {}
        }
        for (what, names) in [("rpdo", &self.rpdo), ("tpdo", &self.tpdo)] {
            if names.is_some() && self.eds.is_none() {
                issues.push(
                    format!("{key}.{what}"),
                    "object names need the drive's EDS file: eds = \"<file>.eds\"",
                );
            }
        }
        if let Some(LagSeconds(lag)) = self.loopback_lag_s {
            issues.in_range(format!("{key}.loopback_lag_s"), lag, 0.0, 1.0);
            if self.interface != SIM_INTERFACE {
                issues.push(
                    format!("{key}.loopback_lag_s"),
                    format!(
                        "only used with interface = \"{SIM_INTERFACE}\" (interface is {:?})",
                        self.interface
                    ),
                );
            }
        }
        issues.in_range(
            format!("{key}.homing_timeout_ms"),
            self.homing_timeout_ms,
            1,
            3_600_000,
        );
    }
}

/// Makes the relative `[drive.canopen] eds` paths relative to `dir` (the configuration
/// file's directory).
pub(super) fn resolve_eds_paths(drives: &mut [DriveConfig], dir: &std::path::Path) {
    for c in drives.iter_mut().filter_map(|d| d.canopen.as_mut()) {
        if let Some(e) = &mut c.eds {
            if e.is_relative() {
                *e = dir.join(&*e);
            }
        }
    }
}
