//! `[machine]`: the machine's name and kinematics.

use super::error::Issues;
use serde::{Deserialize, Serialize};

/// `[machine]`: what the machine is.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    /// Name shown in status, logs and the control socket.
    pub name: String,
    /// How axis (Cartesian) positions map to joint (drive) positions.
    #[serde(default)]
    pub kinematics: KinematicsKind,
    /// Link lengths, required with `kinematics = "scara"` and refused otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scara: Option<ScaraConfig>,
}

/// The kinematics family, chosen by `kinematics = "..."`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum KinematicsKind {
    /// Each axis drives one joint directly (a Cartesian mill, a lathe).
    #[default]
    Identity,
    /// A two-link planar arm: axes X and Y are the tool tip, joints are the two shoulder
    /// and elbow angles (see `[machine.scara]`).
    Scara,
}

/// `[machine.scara]`: link lengths of a SCARA arm.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ScaraConfig {
    /// Shoulder-to-elbow length in mm.
    pub link1_mm: f64,
    /// Elbow-to-tool length in mm.
    pub link2_mm: f64,
}

/// The kinematics with its parameters, as the motion layer consumes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kinematics {
    /// See [`KinematicsKind::Identity`].
    Identity,
    /// See [`KinematicsKind::Scara`].
    Scara {
        /// Shoulder-to-elbow length in mm.
        link1_mm: f64,
        /// Elbow-to-tool length in mm.
        link2_mm: f64,
    },
}

impl MachineSection {
    /// The kinematics with its parameters. Only meaningful on a validated configuration
    /// (a SCARA without `[machine.scara]` is reported by validation and yields `Identity`
    /// here).
    pub fn kinematics(&self) -> Kinematics {
        match (self.kinematics, self.scara) {
            (KinematicsKind::Scara, Some(s)) => Kinematics::Scara {
                link1_mm: s.link1_mm,
                link2_mm: s.link2_mm,
            },
            _ => Kinematics::Identity,
        }
    }

    pub(super) fn validate(&self, issues: &mut Issues) {
        issues.name("machine.name", &self.name);
        match (self.kinematics, &self.scara) {
            (KinematicsKind::Scara, None) => issues.push(
                "machine.scara",
                "required with kinematics = \"scara\" (link1_mm, link2_mm)",
            ),
            (KinematicsKind::Identity, Some(_)) => {
                issues.push("machine.scara", "only used with kinematics = \"scara\"")
            }
            (KinematicsKind::Scara, Some(s)) => {
                issues.positive("machine.scara.link1_mm", s.link1_mm);
                issues.positive("machine.scara.link2_mm", s.link2_mm);
            }
            (KinematicsKind::Identity, None) => {}
        }
    }
}
