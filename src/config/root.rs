//! The whole machine description ([`MachineConfig`]) and the checks that span sections:
//! references between sections (axis → drive, spindle/coolant/safety → I/O channels,
//! motion → thread) and uniqueness.

use super::axis::{AxisConfig, AxisName};
use super::drive::{DriveBackend, DriveConfig};
use super::error::{Issue, Issues};
use super::io::{self, IoConfig, IoKind, IoRef};
use super::machine::{KinematicsKind, MachineSection};
use super::settings::{ControlConfig, LoggingConfig, MotionConfig, SafetyConfig, ToolTableConfig};
use super::spindle::{CoolantConfig, SpindleConfig};
use super::thread::{self, ThreadConfig};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// A machine, as described by one TOML file. Field order is the order of the sections in
/// the resolved output of `hytask check`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MachineConfig {
    /// `[machine]`: name and kinematics.
    pub machine: MachineSection,
    /// `[[thread]]`: the realtime threads.
    #[serde(default, rename = "thread")]
    pub threads: Vec<ThreadConfig>,
    /// `[[axis]]`: the axes.
    #[serde(default, rename = "axis")]
    pub axes: Vec<AxisConfig>,
    /// `[[drive]]`: the drives moving the axes.
    #[serde(default, rename = "drive")]
    pub drives: Vec<DriveConfig>,
    /// `[[io]]`: I/O devices with named channels.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub io: Vec<IoConfig>,
    /// `[spindle]`: absent for a machine without a spindle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spindle: Option<SpindleConfig>,
    /// `[coolant]`: coolant valves.
    #[serde(default)]
    pub coolant: CoolantConfig,
    /// `[tool_table]`: absent for a machine without tool offsets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_table: Option<ToolTableConfig>,
    /// `[gcode]`: var file and `#<_ini[…]>` values.
    #[serde(default, skip_serializing_if = "super::GcodeConfig::is_default")]
    pub gcode: super::GcodeConfig,
    /// `[control]`: the control socket.
    #[serde(default)]
    pub control: ControlConfig,
    /// `[job]`: job preparation.
    #[serde(default, skip_serializing_if = "super::JobConfig::is_default")]
    pub job: super::JobConfig,
    /// `[logging]`.
    #[serde(default)]
    pub logging: LoggingConfig,
    /// `[motion]`: planner settings.
    #[serde(default)]
    pub motion: MotionConfig,
    /// `[safety]`: e-stop and overrun policy.
    pub safety: SafetyConfig,
    /// `[plc]`: absent for a machine without a PLC program.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plc: Option<super::PlcConfig>,
    /// `[zenoh]`: export the task interfaces over Zenoh; absent: no bridge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenoh: Option<super::ZenohConfig>,
    /// `[[remote]]`: peers in other processes watched over Zenoh (needs `[zenoh]`); losing
    /// a `critical` one stops the machine under control (`bridge::watch`).
    #[serde(default, rename = "remote", skip_serializing_if = "Vec::is_empty")]
    pub remotes: Vec<super::remote::RemoteConfig>,
}

impl MachineConfig {
    /// Checks every value and every cross-reference; returns all problems found (empty when
    /// the configuration is valid).
    pub fn validate(&self) -> Vec<Issue> {
        let mut issues = Issues::default();
        self.machine.validate(&mut issues);
        thread::validate(&self.threads, &mut issues);
        self.validate_axes(&mut issues);
        self.validate_drives(&mut issues);
        for (i, dev) in self.io.iter().enumerate() {
            dev.validate(&IoConfig::key(i, &dev.name), &mut issues);
        }
        for (i, dev) in self.io.iter().enumerate() {
            if let Some(t) = &dev.touch_plate {
                if !self.axes.iter().any(|a| a.name == t.axis) {
                    issues.push(
                        format!("{}.touch_plate.axis", IoConfig::key(i, &dev.name)),
                        format!("no [[axis]] named {}", t.axis),
                    );
                }
            }
        }
        let channels = io::index(&self.io, &mut issues);
        let mut need = |key: &str, name: &str, kind: IoKind| {
            check_channel(&channels, key, name, kind, &mut issues);
        };
        if let Some(s) = &self.spindle {
            need(
                "spindle.enable_output",
                &s.enable_output,
                IoKind::DigitalOutput,
            );
            if let Some(n) = &s.direction_output {
                need("spindle.direction_output", n, IoKind::DigitalOutput);
            }
            if let Some(n) = &s.speed_output {
                need("spindle.speed_output", n, IoKind::AnalogOutput);
            }
            if let Some(n) = &s.at_speed_input {
                need("spindle.at_speed_input", n, IoKind::DigitalInput);
            }
        }
        if let Some(n) = &self.coolant.flood_output {
            need("coolant.flood_output", n, IoKind::DigitalOutput);
        }
        if let Some(n) = &self.coolant.mist_output {
            need("coolant.mist_output", n, IoKind::DigitalOutput);
        }
        if let Some(n) = &self.motion.probe_input {
            need("motion.probe_input", n, IoKind::DigitalInput);
        }
        need(
            "safety.estop_input",
            &self.safety.estop_input,
            IoKind::DigitalInput,
        );
        if let Some(s) = &self.spindle {
            s.validate(&mut issues);
        }
        if let Some(t) = &self.tool_table {
            t.validate(&mut issues);
        }
        self.gcode.validate(&mut issues);
        self.control.validate(&mut issues);
        self.job.validate(&mut issues);
        self.motion.validate(&mut issues);
        if !self.threads.is_empty() && self.thread(&self.motion.servo_thread).is_none() {
            issues.push(
                "motion.servo_thread",
                format!(
                    "no [[thread]] named {:?} (threads: {})",
                    self.motion.servo_thread,
                    list(self.threads.iter().map(|t| t.name.as_str()))
                ),
            );
        }
        self.safety.validate(&mut issues);
        if let Some(p) = &self.plc {
            p.validate(&mut issues);
            if self.thread(&p.thread).is_none() {
                issues.push(
                    "plc.thread",
                    format!(
                        "no [[thread]] named {:?} (threads: {})",
                        p.thread,
                        list(self.threads.iter().map(|t| t.name.as_str()))
                    ),
                );
            }
        }
        if let Some(z) = &self.zenoh {
            z.validate(&mut issues);
        }
        for p in super::remote::RemoteConfig::problems(&self.remotes) {
            let (key, msg) = p.split_once(": ").unwrap_or(("remote", &p));
            issues.push(key, msg);
        }
        if !self.remotes.is_empty() && self.zenoh.is_none() {
            issues.push(
                "remote",
                "a [[remote]] is reached over Zenoh: add a [zenoh] table",
            );
        }
        issues.into_vec()
    }

    fn validate_axes(&self, issues: &mut Issues) {
        if self.axes.is_empty() {
            issues.push("axis", "at least one [[axis]] is required");
        }
        let mut names: HashMap<AxisName, usize> = HashMap::new();
        let mut drives_used: HashMap<&str, usize> = HashMap::new();
        for (i, a) in self.axes.iter().enumerate() {
            let key = AxisConfig::key(i, a.name);
            a.validate(&key, issues);
            if let Some(first) = names.insert(a.name, i) {
                issues.push(
                    format!("{key}.name"),
                    format!("duplicate of {}", AxisConfig::key(first, a.name)),
                );
            }
            if self.drive(&a.drive).is_none() {
                issues.push(
                    format!("{key}.drive"),
                    format!(
                        "no [[drive]] named {:?} (drives: {})",
                        a.drive,
                        list(self.drives.iter().map(|d| d.name.as_str()))
                    ),
                );
            } else if let Some(first) = drives_used.insert(&a.drive, i) {
                issues.push(
                    format!("{key}.drive"),
                    format!(
                        "drive {:?} already moves {}",
                        a.drive,
                        AxisConfig::key(first, self.axes[first].name)
                    ),
                );
            }
        }
        if self.machine.kinematics == KinematicsKind::Scara {
            for needed in [AxisName::X, AxisName::Y] {
                if self.axis(needed).is_none() {
                    issues.push(
                        "axis",
                        format!("kinematics = \"scara\" needs an axis {needed}"),
                    );
                }
            }
        }
    }

    fn validate_drives(&self, issues: &mut Issues) {
        let mut names: HashMap<&str, usize> = HashMap::new();
        let mut nodes: HashMap<(&str, u8), usize> = HashMap::new();
        for (i, d) in self.drives.iter().enumerate() {
            let key = DriveConfig::key(i, &d.name);
            d.validate(&key, self.axis_of_drive(&d.name), issues);
            if let Some(first) = names.insert(&d.name, i) {
                issues.push(
                    format!("{key}.name"),
                    format!("duplicate of {}", DriveConfig::key(first, &d.name)),
                );
            }
            if let (DriveBackend::Canopen, Some(c)) = (d.backend, &d.canopen) {
                if let Some(first) = nodes.insert((&c.interface, c.node_id), i) {
                    issues.push(
                        format!("{key}.canopen.node_id"),
                        format!(
                            "node {} on {} is already {}",
                            c.node_id,
                            c.interface,
                            DriveConfig::key(first, &self.drives[first].name)
                        ),
                    );
                }
            }
        }
    }

    /// Fills defaults that depend on other sections (simulated drive settings, homing
    /// latch velocities), so that the resolved configuration states every value in use.
    pub fn resolve(&mut self) {
        for a in &mut self.axes {
            if a.home.method != super::axis::HomeMethod::CurrentPosition {
                a.home.latch_velocity = Some(a.home.latch_velocity());
            }
        }
        for i in 0..self.drives.len() {
            let axis = self
                .axes
                .iter()
                .find(|a| a.drive == self.drives[i].name)
                .cloned();
            self.drives[i].resolve(axis.as_ref());
        }
    }

    /// Backends named in the file that this build cannot run, one issue per device. The
    /// deployment refuses to start while this is non-empty; `hytask check` only reports
    /// it, so real-machine files can be checked anywhere.
    pub fn unavailable_backends(&self) -> Vec<Issue> {
        let mut out = Vec::new();
        for (i, d) in self.drives.iter().enumerate() {
            if !d.backend.is_available() {
                out.push(Issue {
                    key: format!("{}.backend", DriveConfig::key(i, &d.name)),
                    message: format!(
                        "backend {:?} is not available in this build",
                        d.backend.as_str()
                    ),
                });
            }
        }
        for (i, d) in self.io.iter().enumerate() {
            if !d.backend.is_available() {
                out.push(Issue {
                    key: format!("{}.backend", IoConfig::key(i, &d.name)),
                    message: format!(
                        "backend {:?} is not available in this build",
                        d.backend.as_str()
                    ),
                });
            }
        }
        out
    }

    /// The axis with letter `name`.
    pub fn axis(&self, name: AxisName) -> Option<&AxisConfig> {
        self.axes.iter().find(|a| a.name == name)
    }

    /// The axes grouped in homing order: groups by ascending `home.sequence`; the axes of
    /// one group home together, in file order within the group.
    pub fn homing_order(&self) -> Vec<Vec<AxisName>> {
        let mut sequences: Vec<u8> = self.axes.iter().map(|a| a.home.sequence).collect();
        sequences.sort_unstable();
        sequences.dedup();
        sequences
            .into_iter()
            .map(|s| {
                self.axes
                    .iter()
                    .filter(|a| a.home.sequence == s)
                    .map(|a| a.name)
                    .collect()
            })
            .collect()
    }

    /// The drive named `name`.
    pub fn drive(&self, name: &str) -> Option<&DriveConfig> {
        self.drives.iter().find(|d| d.name == name)
    }

    /// The axis moved by drive `name`.
    pub fn axis_of_drive(&self, name: &str) -> Option<&AxisConfig> {
        self.axes.iter().find(|a| a.drive == name)
    }

    /// The thread named `name`.
    pub fn thread(&self, name: &str) -> Option<&ThreadConfig> {
        self.threads.iter().find(|t| t.name == name)
    }

    /// The servo thread (`motion.servo_thread`); always present in a validated config.
    pub fn servo_thread(&self) -> Option<&ThreadConfig> {
        self.thread(&self.motion.servo_thread)
    }

    /// Where the I/O channel `name` lives.
    pub fn find_io(&self, name: &str) -> Option<IoRef> {
        let mut ignored = Issues::default();
        io::index(&self.io, &mut ignored).get(name).copied()
    }

    /// The configuration as TOML, every default filled in (what `hytask check` prints).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(self)
    }
}

fn check_channel(
    channels: &HashMap<String, IoRef>,
    key: &str,
    name: &str,
    kind: IoKind,
    issues: &mut Issues,
) {
    match channels.get(name) {
        None => issues.push(key, format!("no {kind} named {name:?} in any [[io]]")),
        Some(r) if r.kind != kind => {
            issues.push(key, format!("{name:?} is a {}, expected a {kind}", r.kind));
        }
        Some(_) => {}
    }
}

fn list<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let v: Vec<&str> = names.collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}
