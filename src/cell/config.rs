//! The cell's configuration file (`config/pickplace.toml`): a `[cell]` section beside the
//! daemon's `[control]` section. A file with a top-level `[cell]` table is a cell; any other
//! is a machine ([`is_cell_document`]), so `hytask serve --config` takes either without a
//! new flag and the mill's configuration types stay as they are.
//!
//! Every table rejects unknown keys; every value has a default except the world's seed, so
//! the smallest cell file is `[cell.world]` with `seed = N`.

use super::camera::CameraConfig;
use super::pid::PidConfig;
use super::robot::RobotConfig;
use super::selection::SelectionConfig;
use super::world::{Layout, WorldConfig};
use crate::config::ControlConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Scheduling of one of the cell's threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ThreadSched {
    /// Period, µs.
    pub period_us: u64,
    /// `SCHED_FIFO` priority.
    pub priority: i32,
    /// CPU to pin to.
    #[serde(default)]
    pub cpu: Option<usize>,
}

impl ThreadSched {
    /// As a deployment schedule.
    pub fn schedule(&self) -> crate::rt::deploy::Schedule {
        crate::rt::deploy::Schedule {
            priority: self.priority,
            period_ns: self.period_us * 1000,
            cpu: self.cpu,
        }
    }
}

/// The cell's threads: priority follows rate. The non-periodic camera task runs on the
/// selection thread, after the selection's step and only in the time the cycle has left.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CellThreads {
    /// Sensor, robot, PID, effector, simulated hardware.
    #[serde(default = "default_servo")]
    pub servo: ThreadSched,
    /// The selection state machine, and the camera task when it has work.
    #[serde(default = "default_selection")]
    pub selection: ThreadSched,
}

fn default_servo() -> ThreadSched {
    ThreadSched {
        period_us: 1000,
        priority: 80,
        cpu: None,
    }
}
fn default_selection() -> ThreadSched {
    ThreadSched {
        period_us: 10_000,
        priority: 60,
        cpu: None,
    }
}

impl Default for CellThreads {
    fn default() -> Self {
        Self {
            servo: default_servo(),
            selection: default_selection(),
        }
    }
}

/// `[cell]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CellConfig {
    /// Name shown in status.
    #[serde(default = "default_name")]
    pub name: String,
    /// Run the threads on simulated time at this multiple of real time (e.g. 10) instead of
    /// `SCHED_FIFO` real time: for demos and tests of the daemon path. Absent: real time.
    #[serde(default)]
    pub sim_speed: Option<f64>,
    /// `[cell.threads]`.
    #[serde(default)]
    pub threads: CellThreads,
    /// `[cell.robot]`.
    #[serde(default)]
    pub robot: RobotConfig,
    /// `[cell.pid]`.
    #[serde(default)]
    pub pid: PidConfig,
    /// `[cell.world]`.
    pub world: WorldConfig,
    /// `[cell.layout]`.
    #[serde(default)]
    pub layout: Layout,
    /// `[cell.camera]`.
    #[serde(default)]
    pub camera: CameraConfig,
    /// `[cell.selection]`.
    #[serde(default)]
    pub selection: SelectionConfig,
}

fn default_name() -> String {
    "pick-and-place".into()
}

impl CellConfig {
    /// The defaults with world seed `seed`.
    pub fn with_seed(seed: u64) -> Self {
        Self {
            name: default_name(),
            sim_speed: None,
            threads: CellThreads::default(),
            robot: RobotConfig::default(),
            pid: PidConfig::default(),
            world: WorldConfig::with_seed(seed),
            layout: Layout::default(),
            camera: CameraConfig::default(),
            selection: SelectionConfig::default(),
        }
    }

    /// Every problem, each naming its key.
    pub fn validate(&self) -> Vec<String> {
        let mut issues = Vec::new();
        let points = [
            ("cell.layout.home_mm", self.layout.home_mm),
            ("cell.layout.pick_mm", self.layout.pick_mm),
            ("cell.layout.camera_mm", self.layout.camera_mm),
            ("cell.layout.containers_mm[0]", self.layout.containers_mm[0]),
            ("cell.layout.containers_mm[1]", self.layout.containers_mm[1]),
            ("cell.layout.containers_mm[2]", self.layout.containers_mm[2]),
        ];
        let (lo, hi) = (self.robot.min_mm, self.robot.max_mm);
        for (key, p) in points {
            if (0..3).any(|i| !(lo[i]..=hi[i]).contains(&p[i])) {
                issues.push(format!(
                    "{key}: {p:?} is outside the workspace cell.robot.min_mm {lo:?} .. max_mm {hi:?}"
                ));
            }
        }
        let positive = [
            ("cell.robot.max_velocity_mm_s", self.robot.max_velocity_mm_s),
            (
                "cell.robot.max_acceleration_mm_s2",
                self.robot.max_acceleration_mm_s2,
            ),
            ("cell.world.mass_kg", self.world.mass_kg),
            ("cell.pid.max_force_n", self.pid.max_force_n),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                issues.push(format!("{key}: must be > 0, got {v}"));
            }
        }
        if self.camera.processing_min_ms > self.camera.processing_max_ms {
            issues.push(format!(
                "cell.camera.processing_min_ms: {} is above processing_max_ms {}",
                self.camera.processing_min_ms, self.camera.processing_max_ms
            ));
        }
        if let Some(s) = self.sim_speed {
            if !(s.is_finite() && s > 0.0) {
                issues.push(format!("cell.sim_speed: must be > 0, got {s}"));
            }
        }
        for (key, t) in [
            ("cell.threads.servo", self.threads.servo),
            ("cell.threads.selection", self.threads.selection),
        ] {
            if t.period_us == 0 || !(1..=99).contains(&t.priority) {
                issues.push(format!(
                    "{key}: period_us must be > 0 and priority 1..=99, got {} us, {}",
                    t.period_us, t.priority
                ));
            }
        }
        issues
    }
}

/// A cell configuration file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CellFile {
    /// `[cell]`.
    pub cell: CellConfig,
    /// `[control]`: the control socket, as for a machine.
    #[serde(default)]
    pub control: ControlConfig,
    /// `[peers]`: cell tasks run by remote peers, `camera = "<remote>/<task>"`
    /// (`cell::remote`).
    #[serde(default, skip_serializing_if = "Peers::is_empty")]
    pub peers: Peers,
    /// `[[remote]]`: the remote peers `[peers]` names.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub remote: Vec<crate::config::remote::RemoteConfig>,
    /// `[zenoh]`: the session remote peers are reached on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenoh: Option<crate::config::ZenohConfig>,
}

/// `[peers]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Peers {
    /// The camera task in another process: `"<remote>/<task>"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<String>,
}

impl Peers {
    fn is_empty(&self) -> bool {
        self.camera.is_none()
    }
}

/// Errors loading a cell file.
#[derive(Debug, thiserror::Error)]
pub enum CellConfigError {
    /// The file cannot be read, or a key is malformed, unknown, missing or mistyped (the
    /// machine configuration's errors, naming file and key the same way).
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// Values out of range.
    #[error("{origin}: invalid cell:\n  {}", .issues.join("\n  "))]
    Invalid {
        /// File.
        origin: String,
        /// Every problem.
        issues: Vec<String>,
    },
}

/// True if `text` is a cell configuration (has a top-level `[cell]` table). Malformed TOML
/// is not a cell: the machine loader reports it.
pub fn is_cell_document(text: &str) -> bool {
    toml::from_str::<toml::Table>(text).is_ok_and(|t| t.contains_key("cell"))
}

/// True if the file at `path` is a cell configuration (false if it cannot be read).
pub fn is_cell_file(path: &Path) -> bool {
    std::fs::read_to_string(path).is_ok_and(|t| is_cell_document(&t))
}

/// Parses and validates a cell file's text. `origin` names it in messages.
pub fn parse(text: &str, origin: &str) -> Result<CellFile, CellConfigError> {
    let file: CellFile = crate::config::deserialize(text, origin)?;
    let issues = file.cell.validate();
    if !issues.is_empty() {
        return Err(CellConfigError::Invalid {
            origin: origin.into(),
            issues,
        });
    }
    Ok(file)
}

/// Reads and checks a cell file.
pub fn load(path: &Path) -> Result<CellFile, CellConfigError> {
    let text = crate::config::read(path)?;
    let mut file = parse(&text, &path.display().to_string())?;
    // The selection script is named relative to the configuration file.
    if let Some(s) = &mut file.cell.selection.script {
        if s.is_relative() {
            *s = path.parent().unwrap_or(Path::new("")).join(&*s);
        }
    }
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_file_and_errors_name_the_key() {
        let f = parse("[cell.world]\nseed = 5\n", "t").unwrap();
        assert_eq!(f.cell.world.seed, 5);
        assert!(is_cell_document("[cell.world]\nseed = 5\n"));
        assert!(!is_cell_document("[machine]\nname = \"m\"\n"));
        let e = parse("[cell.world]\nseed = 5\nbogus = 1\n", "t").unwrap_err();
        assert!(e.to_string().contains("cell.world"), "{e}");
        let e = parse(
            "[cell.world]\nseed = 5\n[cell.layout]\nhome_mm=[0,0,900]\npick_mm=[0,0,0]\n\
             camera_mm=[0,0,0]\ncontainers_mm=[[0,0,0],[0,0,0],[0,0,0]]\ntravel_z_mm=50\n",
            "t",
        )
        .unwrap_err();
        assert!(e.to_string().contains("cell.layout.home_mm"), "{e}");
    }

    #[test]
    fn selection_script_is_relative_to_the_file_and_script_is_the_default() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cell.toml");
        let text = "[cell.world]\nseed = 5\n[cell.selection]\nscript = \"scripts/s.st\"\n";
        std::fs::write(&path, text).unwrap();
        let f = load(&path).unwrap();
        assert_eq!(
            f.cell.selection.script,
            Some(dir.path().join("scripts/s.st"))
        );
        assert_eq!(
            f.cell.selection.kind,
            super::super::selection::SelectionKind::Script
        );
        let f = parse(
            "[cell.world]\nseed = 5\n[cell.selection]\nkind = \"rust\"\n",
            "t",
        )
        .unwrap();
        assert_eq!(
            f.cell.selection.kind,
            super::super::selection::SelectionKind::Rust
        );
    }
}
