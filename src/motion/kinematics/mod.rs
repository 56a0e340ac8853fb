//! Kinematics: Cartesian pose (what the planner plans) ↔ joint positions (what drives move).
//! One small trait, two implementations chosen by [`KinematicsConfig`]: identity for
//! Cartesian machines and a two-link SCARA with Z. Every failure is a named
//! [`KinematicsError`], never a NaN.

mod identity;
mod scara;

pub use identity::Identity;
pub use scara::Scara;

use super::config::KinematicsConfig;
use super::segment::Segment;
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
#[allow(clippy::large_enum_variant)] // lives in the interpolator: no Box on the servo thread
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

/// Checks a planned segment in joint space: reach and joint position limits at samples one
/// servo period apart, and joint speeds between them (scaled by the segment's override cap)
/// against `joint_max_vel`. Identity kinematics needs nothing: axis limits are joint limits.
pub fn check_segment(
    kin: &Machine,
    seg: &Segment,
    joint_max_vel: &[f64; NUM_AXES],
    servo_period_s: f64,
) -> Result<(), KinematicsError> {
    if matches!(kin, Machine::Identity(_)) || seg.duration_s <= 0.0 {
        return Ok(());
    }
    let n = ((seg.duration_s / servo_period_s).ceil() as usize).max(2);
    let h = seg.duration_s / n as f64;
    let mut prev = kin.inverse(&seg.pose_at(0.0))?;
    for i in 1..=n {
        let q = kin.inverse(&seg.pose_at(i as f64 * h))?;
        for j in 0..NUM_AXES {
            let mut d = q[j] - prev[j];
            if j < 2 {
                // Angles are reported in (-180, 180]: take the short way round.
                d = (d + 180.0).rem_euclid(360.0) - 180.0;
            }
            let v = d.abs() / h * seg.override_cap;
            if v > joint_max_vel[j] * (1.0 + 1e-9) {
                return Err(KinematicsError::JointVelocity {
                    joint: j,
                    value: v,
                    max: joint_max_vel[j],
                });
            }
        }
        prev = q;
    }
    Ok(())
}

fn check_finite(p: &[f64; NUM_AXES]) -> Result<(), KinematicsError> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::NotFinite)
    }
}
