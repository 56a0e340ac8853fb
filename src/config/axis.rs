//! `[[axis]]`: the machine's Cartesian (or rotary) axes, each driven by a drive.
//!
//! Axes are kept apart from drives (LinuxCNC's axes vs joints): an axis carries the motion
//! limits the planner uses, a `[[drive]]` says how the motor is reached. Units are machine
//! units: mm for X/Y/Z/U/V/W, degrees for A/B/C.

use super::error::Issues;
use hytask_hal::{HomingMethod, HomingParams};
use serde::{Deserialize, Serialize};
use std::fmt;

/// Axis letters, as in G-code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[allow(missing_docs)] // The letters are their own documentation.
pub enum AxisName {
    X,
    Y,
    Z,
    A,
    B,
    C,
    U,
    V,
    W,
}

impl AxisName {
    /// True for the rotary axes A, B and C (units are degrees).
    pub fn is_rotary(self) -> bool {
        matches!(self, AxisName::A | AxisName::B | AxisName::C)
    }
}

impl fmt::Display for AxisName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

/// `[[axis]]`: one axis.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AxisConfig {
    /// The axis letter (X, Y, Z, A, B, C, U, V, W); unique.
    pub name: AxisName,
    /// Name of the `[[drive]]` (joint) that moves this axis.
    pub drive: String,
    /// Drive units (encoder counts) per machine unit; the sign sets the direction. Not 0.
    #[serde(default = "default_scale")]
    pub scale: f64,
    /// Lower soft limit in machine units; motion below it is refused by the planner.
    pub min_limit: f64,
    /// Upper soft limit in machine units.
    pub max_limit: f64,
    /// Velocity limit in units/s (> 0).
    pub max_velocity: f64,
    /// Acceleration limit in units/s² (> 0).
    pub max_acceleration: f64,
    /// Jerk limit in units/s³ (> 0). Absent: the planner uses trapezoidal (acceleration-
    /// limited) profiles for this axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_jerk: Option<f64>,
    /// Largest tolerated |commanded - actual| in units; beyond it the monitor stops the
    /// machine (a crash or a stalled motor).
    pub following_error_limit: f64,
    /// How the axis finds its reference (`[axis.home]`); default: the current position.
    #[serde(default)]
    pub home: HomeConfig,
}

fn default_scale() -> f64 {
    1.0
}

/// `[axis.home]`: homing of one axis.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HomeConfig {
    /// How the reference is found.
    #[serde(default)]
    pub method: HomeMethod,
    /// Position assigned at the reference, in machine units; within the soft limits.
    #[serde(default)]
    pub position: f64,
    /// Search velocity in units/s; the sign is the search direction. Required (non-zero)
    /// for the switch methods.
    #[serde(default)]
    pub velocity: f64,
    /// Back-off velocity magnitude in units/s, slower than the search for a precise edge.
    /// Default: a tenth of `velocity`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latch_velocity: Option<f64>,
    /// Homing order: lower sequence numbers home first; equal numbers home together
    /// (home Z first so the tool clears the work).
    #[serde(default)]
    pub sequence: u8,
}

impl Default for HomeConfig {
    fn default() -> Self {
        HomeConfig {
            method: HomeMethod::CurrentPosition,
            position: 0.0,
            velocity: 0.0,
            latch_velocity: None,
            sequence: 0,
        }
    }
}

/// Homing methods, by name in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HomeMethod {
    /// No motion: the position at homing time becomes `position`.
    #[default]
    CurrentPosition,
    /// Search the home switch, back off, latch the release edge.
    Switch,
    /// As `switch`, on the limit switch in the search direction.
    LimitSwitch,
}

impl HomeConfig {
    /// The back-off velocity, with the default filled in.
    pub fn latch_velocity(&self) -> f64 {
        self.latch_velocity.unwrap_or(self.velocity.abs() / 10.0)
    }

    /// The HAL homing request for this axis.
    pub fn params(&self) -> HomingParams {
        HomingParams {
            method: match self.method {
                HomeMethod::CurrentPosition => HomingMethod::CurrentPosition,
                HomeMethod::Switch => HomingMethod::HomeSwitch,
                HomeMethod::LimitSwitch => HomingMethod::LimitSwitch,
            },
            search_velocity: self.velocity,
            latch_velocity: self.latch_velocity(),
            home_position: self.position,
        }
    }
}

impl AxisConfig {
    /// The key prefix used in messages: `axis[1] (Y)`.
    pub fn key(index: usize, name: AxisName) -> String {
        format!("axis[{index}] ({name})")
    }

    /// Checks this axis' own values (cross-references are checked by the caller).
    pub(super) fn validate(&self, key: &str, issues: &mut Issues) {
        if self.scale == 0.0 || !self.scale.is_finite() {
            issues.push(
                format!("{key}.scale"),
                format!("must be a non-zero finite number, got {}", self.scale),
            );
        }
        issues.finite(format!("{key}.min_limit"), self.min_limit);
        issues.finite(format!("{key}.max_limit"), self.max_limit);
        if self.min_limit.is_finite()
            && self.max_limit.is_finite()
            && self.min_limit >= self.max_limit
        {
            issues.push(
                format!("{key}.max_limit"),
                format!(
                    "must be greater than min_limit ({}), got {}",
                    self.min_limit, self.max_limit
                ),
            );
        }
        issues.positive(format!("{key}.max_velocity"), self.max_velocity);
        issues.positive(format!("{key}.max_acceleration"), self.max_acceleration);
        if let Some(j) = self.max_jerk {
            issues.positive(format!("{key}.max_jerk"), j);
        }
        issues.positive(
            format!("{key}.following_error_limit"),
            self.following_error_limit,
        );
        self.validate_home(key, issues);
    }

    fn validate_home(&self, key: &str, issues: &mut Issues) {
        let h = &self.home;
        let pos = h.position;
        if !pos.is_finite() || pos < self.min_limit || pos > self.max_limit {
            issues.push(
                format!("{key}.home.position"),
                format!(
                    "must be within the soft limits {}..={}, got {pos}",
                    self.min_limit, self.max_limit
                ),
            );
        }
        if h.method == HomeMethod::CurrentPosition {
            return;
        }
        let v = h.velocity;
        // Compare with max_velocity only when that is valid (it is reported on its own).
        let vmax = if self.max_velocity > 0.0 {
            self.max_velocity
        } else {
            f64::INFINITY
        };
        if !(v.is_finite() && v != 0.0 && v.abs() <= vmax) {
            issues.push(
                format!("{key}.home.velocity"),
                format!(
                    "must be non-zero (its sign is the search direction) and within max_velocity ({}), got {v}",
                    self.max_velocity
                ),
            );
        }
        if let Some(l) = h.latch_velocity {
            if !(l.is_finite() && l > 0.0 && l <= v.abs()) {
                issues.push(
                    format!("{key}.home.latch_velocity"),
                    format!(
                        "must be > 0 and at most |home.velocity| ({}), got {l}",
                        v.abs()
                    ),
                );
            }
        }
    }
}
