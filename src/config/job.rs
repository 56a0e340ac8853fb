//! `[job]`: how the daemon prepares jobs.

use super::Issues;
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// Default of `[job] prepare_timeout_s`.
pub const DEFAULT_PREPARE_TIMEOUT_S: f64 = 300.0;

/// `[job]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JobConfig {
    /// Wall-clock budget of one `job.load` (interpreting and planning), seconds. Preparations
    /// run one at a time, so a runaway program (a ten-million-iteration loop) would otherwise
    /// hold every other `job.load` for minutes; past the budget it is refused with an error
    /// naming this key. A real CAM job of a million lines prepares in a few seconds.
    #[serde(default = "default_prepare_timeout_s")]
    pub prepare_timeout_s: f64,
}

fn default_prepare_timeout_s() -> f64 {
    DEFAULT_PREPARE_TIMEOUT_S
}

impl Default for JobConfig {
    fn default() -> Self {
        JobConfig {
            prepare_timeout_s: DEFAULT_PREPARE_TIMEOUT_S,
        }
    }
}

impl JobConfig {
    /// Whether every key has its default (the section is then left out when written).
    pub fn is_default(&self) -> bool {
        *self == JobConfig::default()
    }

    /// The preparation budget.
    pub fn prepare_timeout(&self) -> Duration {
        Duration::try_from_secs_f64(self.prepare_timeout_s)
            .unwrap_or(Duration::from_secs_f64(DEFAULT_PREPARE_TIMEOUT_S))
    }

    pub(super) fn validate(&self, issues: &mut Issues) {
        issues.in_range(
            "job.prepare_timeout_s",
            self.prepare_timeout_s,
            0.001,
            86_400.0,
        );
    }
}
