//! Kinematics: Cartesian pose (what the planner plans) ↔ joint positions (what drives move).
//! One small trait, two implementations chosen by [`KinematicsConfig`]: identity for
//! Cartesian machines and a two-link SCARA with Z. Every failure is a named
//! [`KinematicsError`], never a NaN.

mod identity;
mod scara;

pub use identity::Identity;
pub use scara::Scara;

use super::config::KinematicsConfig;
use super::KinematicsError;
use crate::gcode::NUM_AXES;

/// Forward and inverse kinematics of a machine.
pub trait Kinematics {
    /// Joints → Cartesian pose.
    fn forward(&self, joints: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError>;
    /// Cartesian pose → joints, within joint limits.
    fn inverse(&self, pose: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError>;
}

/// The kinematics a configuration selects (a `Copy` value, usable on the servo thread).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Machine {
    /// Cartesian.
    Identity(Identity),
    /// SCARA.
    Scara(Scara),
}

impl Machine {
    /// Builds the kinematics of `cfg`.
    pub fn new(cfg: &KinematicsConfig) -> Self {
        match cfg {
            KinematicsConfig::Identity => Machine::Identity(Identity),
            KinematicsConfig::Scara(s) => Machine::Scara(Scara::new(*s)),
        }
    }
}

impl Kinematics for Machine {
    fn forward(&self, joints: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError> {
        match self {
            Machine::Identity(k) => k.forward(joints),
            Machine::Scara(k) => k.forward(joints),
        }
    }

    fn inverse(&self, pose: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError> {
        match self {
            Machine::Identity(k) => k.inverse(pose),
            Machine::Scara(k) => k.inverse(pose),
        }
    }
}

fn check_finite(p: &[f64; NUM_AXES]) -> Result<(), KinematicsError> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::NotFinite)
    }
}
