//! Identity kinematics: a Cartesian machine, joint i is axis i.

use super::{check_finite, Kinematics};
use crate::gcode::NUM_AXES;
use crate::motion::KinematicsError;

/// Joints equal axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Identity;

impl Kinematics for Identity {
    fn forward(&self, joints: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError> {
        check_finite(joints)?;
        Ok(*joints)
    }

    fn inverse(&self, pose: &[f64; NUM_AXES]) -> Result<[f64; NUM_AXES], KinematicsError> {
        check_finite(pose)?;
        Ok(*pose)
    }
}
