//! Two-link SCARA with a prismatic Z. Joint 0: shoulder angle (deg), joint 1: elbow angle
//! (deg, relative to link 1), joint 2: Z (mm); joints 3.. pass A B C U V W through.
//!
//! Workspace: the annulus `|l1 - l2| ≤ r ≤ l1 + l2`. Outside it the inverse is `OutOfReach`;
//! at the centre of an equal-link arm (r = 0) the shoulder angle is undefined (`Singular`).
//! At full extension the solution is unique and returned (the Jacobian is singular there,
//! which the joint-speed check of a caller must respect).

use super::{check_finite, Kinematics};
use crate::gcode::NUM_AXES;
use crate::motion::config::ScaraConfig;
use crate::motion::KinematicsError;
use nalgebra::{Rotation2, Vector2};

/// Relative slack on the reach boundaries, to accept points on them despite rounding.
const REACH_EPS: f64 = 1e-9;

/// A SCARA arm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scara {
    cfg: ScaraConfig,
}

impl Scara {
    /// From its geometry and joint limits.
    pub fn new(cfg: ScaraConfig) -> Self {
        Scara { cfg }
    }

    fn check_joints(&self, j: &[f64; NUM_AXES]) -> Result<(), KinematicsError> {
        for (i, v) in j.iter().enumerate() {
            let (lo, hi) = (self.cfg.joint_min[i], self.cfg.joint_max[i]);
            if *v < lo - 1e-9 || *v > hi + 1e-9 {
                return Err(KinematicsError::JointLimit {
                    joint: i,
                    value: *v,
                    min: lo,
                    max: hi,
                });
            }
        }
        Ok(())
    }
}

impl Kinematics for Scara {
    fn forward(&self, joints: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError> {
        check_finite(joints)?;
        let (l1, l2) = (self.cfg.link1_mm, self.cfg.link2_mm);
        let r1 = Rotation2::new(joints[0].to_radians());
        let r12 = Rotation2::new((joints[0] + joints[1]).to_radians());
        let p = r1 * Vector2::new(l1, 0.0) + r12 * Vector2::new(l2, 0.0);
        let mut pose = *joints;
        pose[0] = p.x;
        pose[1] = p.y;
        Ok(pose)
    }

    fn inverse(&self, pose: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError> {
        check_finite(pose)?;
        let (l1, l2) = (self.cfg.link1_mm, self.cfg.link2_mm);
        let p = Vector2::new(pose[0], pose[1]);
        let r = p.norm();
        let (x_mm, y_mm) = (p.x, p.y);
        let scale = l1 + l2;
        if r > scale * (1.0 + REACH_EPS) || r < (l1 - l2).abs() - scale * REACH_EPS {
            return Err(KinematicsError::OutOfReach { x_mm, y_mm });
        }
        if r <= scale * REACH_EPS {
            return Err(KinematicsError::Singular { x_mm, y_mm });
        }
        let c2 = ((r * r - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)).clamp(-1.0, 1.0);
        let s2_abs = (1.0 - c2 * c2).max(0.0).sqrt();
        let s2 = if self.cfg.elbow_positive {
            s2_abs
        } else {
            -s2_abs
        };
        let theta2 = s2.atan2(c2);
        let theta1 = p.y.atan2(p.x) - (l2 * s2).atan2(l1 + l2 * c2);
        let mut j = *pose;
        // Shoulder angle in (-180, 180].
        let mut t1 = theta1.to_degrees();
        if t1 <= -180.0 {
            t1 += 360.0;
        } else if t1 > 180.0 {
            t1 -= 360.0;
        }
        j[0] = t1;
        j[1] = theta2.to_degrees();
        self.check_joints(&j)?;
        Ok(j)
    }
}
