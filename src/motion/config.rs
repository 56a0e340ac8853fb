//! Plain-data motion configuration: per-axis limits, servo period, lookahead window and
//! tolerances. The machine TOML is mapped onto this struct by the machine layer; the planner
//! and the interpolator read nothing else, so a test or a CLI can build one in code.

use crate::gcode::NUM_AXES;

/// Limits of one Cartesian axis. Linear axes (X Y Z U V W) are in mm, rotary axes (A B C) in
/// degrees; the `_mm` suffixes then read as `_deg`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisLimits {
    /// Maximum velocity, mm/s (deg/s).
    pub max_vel_mm_s: f64,
    /// Maximum acceleration, mm/s² (deg/s²).
    pub max_acc_mm_s2: f64,
    /// Maximum jerk, mm/s³ (deg/s³): bounds how fast acceleration may change (S-curve).
    pub max_jerk_mm_s3: f64,
    /// Lower soft limit, machine frame, mm (deg). A move outside is refused at plan time.
    pub min_mm: f64,
    /// Upper soft limit, machine frame, mm (deg).
    pub max_mm: f64,
}

impl AxisLimits {
    /// Linear-axis defaults for a small mill: 50 mm/s, 500 mm/s², 50 000 mm/s³, ±1000 mm.
    pub const LINEAR_DEFAULT: AxisLimits = AxisLimits {
        max_vel_mm_s: 50.0,
        max_acc_mm_s2: 500.0,
        max_jerk_mm_s3: 50_000.0,
        min_mm: -1000.0,
        max_mm: 1000.0,
    };
    /// Rotary-axis defaults: 90 deg/s, 900 deg/s², 90 000 deg/s³, unlimited travel.
    pub const ROTARY_DEFAULT: AxisLimits = AxisLimits {
        max_vel_mm_s: 90.0,
        max_acc_mm_s2: 900.0,
        max_jerk_mm_s3: 90_000.0,
        min_mm: -1.0e9,
        max_mm: 1.0e9,
    };
}

/// Which kinematics maps the Cartesian pose (what the planner plans) to joints.
#[allow(clippy::large_enum_variant)] // plain data, copied to the servo thread: no Box
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum KinematicsConfig {
    /// Cartesian machine: joints are the axes.
    Identity,
    /// Two-link SCARA arm in X/Y with a prismatic Z; joints 0 and 1 are the shoulder and elbow
    /// angles (deg), joint 2 is Z (mm), joints 3.. pass A B C U V W through.
    Scara(ScaraConfig),
}

/// Geometry and joint limits of a two-link SCARA.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaraConfig {
    /// Shoulder-to-elbow length, mm.
    pub link1_mm: f64,
    /// Elbow-to-tool length, mm.
    pub link2_mm: f64,
    /// True: elbow angle positive ("left arm"); false: negative.
    pub elbow_positive: bool,
    /// Lower joint limits (deg for the two angles, mm for Z, axis units after).
    pub joint_min: [f64; NUM_AXES],
    /// Upper joint limits.
    pub joint_max: [f64; NUM_AXES],
    /// Joint velocity limits (deg/s for the two angles, mm/s for Z, axis units after):
    /// near full extension a modest Cartesian speed needs fast joints, so the planner
    /// refuses moves whose joint speeds would exceed these (at the allowed override).
    pub joint_max_vel: [f64; NUM_AXES],
}

/// Everything the planner and interpolator need to know about the machine.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionConfig {
    /// Per-axis limits, X Y Z A B C U V W.
    pub axes: [AxisLimits; NUM_AXES],
    /// Servo period of the interpolator, s.
    pub servo_period_s: f64,
    /// Lookahead window, in moves: the planner never lets a junction be faster than what
    /// allows a stop within this many moves ahead.
    pub lookahead_moves: usize,
    /// Path tolerance used by G64 without P, mm.
    pub default_tolerance_mm: f64,
    /// Path tolerance used at corners in G61.1 (exact path), mm: a tiny number, so corners
    /// are crawled through instead of stopped at.
    pub exact_path_tolerance_mm: f64,
    /// Maximum deviation of the chords an arc is cut into from the true arc, mm (the
    /// planner also never uses more than the active G64 tolerance).
    pub arc_chord_tolerance_mm: f64,
    /// Fraction (0..1) of the G64 P tolerance spent on merging nearly collinear short moves
    /// when no Q is given; the rest is spent on corner blends. 0 disables merging without Q.
    pub merge_fraction: f64,
    /// Fraction (0..0.5) of each axis' acceleration and jerk kept in reserve by the planner
    /// so the interpolator can change feed override, hold and abort without exceeding limits.
    pub override_reserve: f64,
    /// Largest feed override factor accepted (e.g. 2.0 = 200%).
    pub max_feed_override: f64,
    /// Spindle speed assumed for G95 (units per revolution) when no S word was given, rpm;
    /// 0 refuses G95 moves without S.
    pub nominal_spindle_rpm: f64,
    /// Kinematics of the machine.
    pub kinematics: KinematicsConfig,
    /// Fit runs of short, gently turning XY feed chords into tangent-continuous arcs within
    /// the G64 tolerance (issue 14, `motion::arcfit`; Cartesian kinematics only). False plans
    /// every chord with its own corner blend, as before.
    pub fit_arcs: bool,
    /// Plan runs of tangent moves as one speed profile (issue 14, `motion::span`). False
    /// gives every move its own S-curves, as before.
    pub spans: bool,
}

impl Default for MotionConfig {
    fn default() -> Self {
        let l = AxisLimits::LINEAR_DEFAULT;
        let r = AxisLimits::ROTARY_DEFAULT;
        MotionConfig {
            axes: [l, l, l, r, r, r, l, l, l],
            servo_period_s: 0.001,
            lookahead_moves: 256,
            default_tolerance_mm: 0.05,
            exact_path_tolerance_mm: 0.001,
            arc_chord_tolerance_mm: 0.005,
            merge_fraction: 0.5,
            override_reserve: 0.2,
            max_feed_override: 2.0,
            nominal_spindle_rpm: 0.0,
            kinematics: KinematicsConfig::Identity,
            fit_arcs: true,
            spans: true,
        }
    }
}

impl MotionConfig {
    /// Sets velocity, acceleration and jerk of the three linear axes X Y Z at once (the
    /// usual CLI override).
    pub fn with_xyz_limits(mut self, vel_mm_s: f64, acc_mm_s2: f64, jerk_mm_s3: f64) -> Self {
        for a in &mut self.axes[0..3] {
            a.max_vel_mm_s = vel_mm_s;
            a.max_acc_mm_s2 = acc_mm_s2;
            a.max_jerk_mm_s3 = jerk_mm_s3;
        }
        self
    }

    /// Checks the numbers make sense, naming the offending field.
    pub fn validate(&self) -> Result<(), super::PlanError> {
        let bad = |what: String| Err(super::PlanError::Config(what));
        for (i, a) in self.axes.iter().enumerate() {
            let name = super::AXIS_NAMES[i];
            for (v, n) in [
                (a.max_vel_mm_s, "max_vel_mm_s"),
                (a.max_acc_mm_s2, "max_acc_mm_s2"),
                (a.max_jerk_mm_s3, "max_jerk_mm_s3"),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    return bad(format!("axis {name}: {n} must be finite and > 0, got {v}"));
                }
            }
            if a.min_mm.is_nan() || a.max_mm.is_nan() || a.min_mm > a.max_mm {
                return bad(format!("axis {name}: min_mm must be <= max_mm"));
            }
        }
        if !(self.servo_period_s > 0.0 && self.servo_period_s < 1.0) {
            return bad("servo_period_s must be in (0, 1)".into());
        }
        if self.lookahead_moves < 2 {
            return bad("lookahead_moves must be >= 2".into());
        }
        for (v, n) in [
            (self.default_tolerance_mm, "default_tolerance_mm"),
            (self.exact_path_tolerance_mm, "exact_path_tolerance_mm"),
            (self.arc_chord_tolerance_mm, "arc_chord_tolerance_mm"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{n} must be finite and > 0, got {v}"));
            }
        }
        if !(0.0..1.0).contains(&self.merge_fraction) {
            return bad("merge_fraction must be in [0, 1)".into());
        }
        if !(self.override_reserve > 0.0 && self.override_reserve <= 0.5) {
            return bad("override_reserve must be in (0, 0.5]".into());
        }
        if !(1.0..=10.0).contains(&self.max_feed_override) {
            return bad("max_feed_override must be in [1, 10]".into());
        }
        if let KinematicsConfig::Scara(s) = &self.kinematics {
            if !(s.link1_mm > 0.0 && s.link2_mm > 0.0) {
                return bad("kinematics.scara: link lengths must be > 0".into());
            }
        }
        Ok(())
    }
}
