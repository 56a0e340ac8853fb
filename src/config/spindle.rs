//! `[spindle]` and `[coolant]`: the non-motion devices that G-code switches (M3/M4/M5,
//! S, M7/M8/M9), wired to named I/O channels.

use super::error::Issues;
use serde::{Deserialize, Serialize};

/// `[spindle]`: a spindle driven through I/O (enable, direction, analog speed reference).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SpindleConfig {
    /// Highest speed in rpm (> 0); S words above it are clamped and reported.
    pub max_rpm: f64,
    /// Lowest non-zero speed in rpm (>= 0, below max_rpm).
    #[serde(default)]
    pub min_rpm: f64,
    /// Digital output that turns the spindle on.
    pub enable_output: String,
    /// Digital output selecting the direction (high = counter-clockwise, M4); absent for a
    /// spindle that only turns clockwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction_output: Option<String>,
    /// Analog output carrying the speed reference in rpm (scaled by the channel's scale).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_output: Option<String>,
    /// Digital input that reports "at speed"; without it, motion waits `spin_up_s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_speed_input: Option<String>,
    /// Seconds to wait after a speed change when there is no at-speed input (0 ..= 60).
    #[serde(default = "default_spin_up_s")]
    pub spin_up_s: f64,
}

fn default_spin_up_s() -> f64 {
    1.0
}

/// `[coolant]`: coolant valves (M7 mist, M8 flood, M9 off).
#[derive(Debug, Clone, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CoolantConfig {
    /// Digital output of the flood coolant valve (M8).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flood_output: Option<String>,
    /// Digital output of the mist coolant valve (M7).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mist_output: Option<String>,
}

impl SpindleConfig {
    /// Checks the spindle's own values (channel names are checked by the caller).
    pub(super) fn validate(&self, issues: &mut Issues) {
        issues.positive("spindle.max_rpm", self.max_rpm);
        issues.non_negative("spindle.min_rpm", self.min_rpm);
        // Compared only when max_rpm is valid (otherwise that is the one error to report).
        if self.min_rpm.is_finite() && self.max_rpm > 0.0 && self.min_rpm >= self.max_rpm {
            issues.push(
                "spindle.min_rpm",
                format!(
                    "must be below max_rpm ({}), got {}",
                    self.max_rpm, self.min_rpm
                ),
            );
        }
        issues.in_range("spindle.spin_up_s", self.spin_up_s, 0.0, 60.0);
    }
}
