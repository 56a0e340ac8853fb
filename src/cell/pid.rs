//! The PID task and the effector task of the servo thread.
//!
//! The PID closes the position loop per axis with velocity and acceleration feed-forward
//! from the robot's setpoint (the plant's mass and friction are known to the controller
//! within the configured values, so the feedback terms only correct what they miss), and
//! raises `tracking_error` when an axis lags its setpoint by more than the limit (once per
//! excursion). The effector clamps the forces to what the amplifiers deliver and writes them,
//! the enable and the gripper output to the hardware.

use super::names;
use super::types::{DriveOutput, Feedback, Setpoint, TrackingError, Vec3, AXES};
use crate::rt::prelude::*;

/// Gains and limits of the position loop.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct PidConfig {
    /// Proportional gain, N/mm.
    #[serde(default = "default_kp")]
    pub kp_n_mm: f64,
    /// Integral gain, N/(mm·s).
    #[serde(default = "default_ki")]
    pub ki_n_mm_s: f64,
    /// Derivative gain, N·s/mm.
    #[serde(default = "default_kd")]
    pub kd_n_s_mm: f64,
    /// Feed-forward mass per axis, kg.
    #[serde(default = "default_ff_mass")]
    pub ff_mass_kg: f64,
    /// Feed-forward viscous friction, N·s/m.
    #[serde(default = "default_ff_friction")]
    pub ff_friction_n_s_m: f64,
    /// Tracking error that raises `tracking_error`, mm.
    #[serde(default = "default_tracking_limit")]
    pub tracking_limit_mm: f64,
    /// Largest force the amplifiers deliver, N.
    #[serde(default = "default_max_force")]
    pub max_force_n: f64,
}

fn default_kp() -> f64 {
    7.2
}
fn default_ki() -> f64 {
    20.0
}
fn default_kd() -> f64 {
    0.24
}
fn default_ff_mass() -> f64 {
    2.0
}
fn default_ff_friction() -> f64 {
    20.0
}
fn default_tracking_limit() -> f64 {
    2.0
}
fn default_max_force() -> f64 {
    100.0
}

impl Default for PidConfig {
    fn default() -> Self {
        Self {
            kp_n_mm: default_kp(),
            ki_n_mm_s: default_ki(),
            kd_n_s_mm: default_kd(),
            ff_mass_kg: default_ff_mass(),
            ff_friction_n_s_m: default_ff_friction(),
            tracking_limit_mm: default_tracking_limit(),
            max_force_n: default_max_force(),
        }
    }
}

/// The PID task.
pub struct Pid {
    cfg: PidConfig,
    setpoint_in: Option<DataReader<Setpoint>>,
    sensed_in: Option<DataReader<Feedback>>,
    force_out: Option<DataWriter<Vec3>>,
    tracking_error: Option<EventSource<TrackingError>>,
    setpoint: Setpoint,
    sensed: Feedback,
    integral: Vec3,
    last_error: Vec3,
    over: [bool; AXES],
}

impl Pid {
    /// A PID with `cfg`.
    pub fn new(cfg: PidConfig) -> Self {
        Self {
            cfg,
            setpoint_in: None,
            sensed_in: None,
            force_out: None,
            tracking_error: None,
            setpoint: Setpoint::default(),
            sensed: Feedback::default(),
            integral: [0.0; AXES],
            last_error: [0.0; AXES],
            over: [false; AXES],
        }
    }
}

impl Task for Pid {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.setpoint_in = Some(ctx.input(names::SETPOINT));
        self.sensed_in = Some(ctx.input(names::SENSED));
        self.force_out = Some(ctx.output(names::FORCE));
        self.tracking_error = Some(ctx.event("tracking_error"));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.setpoint_in {
            r.get(&mut self.setpoint);
        }
        if let Some(r) = &mut self.sensed_in {
            r.get(&mut self.sensed);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let dt = ctx.period_ns as f64 * 1e-9;
        let c = self.cfg;
        let mut force = [0.0; AXES];
        for (axis, f) in force.iter_mut().enumerate() {
            let e = self.setpoint.position_mm[axis] - self.sensed.position_mm[axis];
            if !self.setpoint.enabled {
                // Open loop: nothing accumulates while the axes are braked.
                self.integral[axis] = 0.0;
                self.last_error[axis] = e;
                self.over[axis] = false;
                continue;
            }
            self.integral[axis] += e * dt;
            let d = if dt > 0.0 {
                (e - self.last_error[axis]) / dt
            } else {
                0.0
            };
            self.last_error[axis] = e;
            let ff = c.ff_mass_kg * self.setpoint.acceleration_mm_s2[axis] * 1e-3
                + c.ff_friction_n_s_m * self.setpoint.velocity_mm_s[axis] * 1e-3;
            *f = ff + c.kp_n_mm * e + c.ki_n_mm_s * self.integral[axis] + c.kd_n_s_mm * d;
            let over = e.abs() > c.tracking_limit_mm;
            if over && !self.over[axis] {
                if let Some(ev) = &mut self.tracking_error {
                    ev.emit(TrackingError { axis, error_mm: e });
                }
            }
            self.over[axis] = over;
        }
        if let Some(o) = &mut self.force_out {
            o.set(force);
        }
        Ok(())
    }
}

/// The effector task.
pub struct Effector {
    max_force_n: f64,
    force_in: Option<DataReader<Vec3>>,
    setpoint_in: Option<DataReader<Setpoint>>,
    drive_out: Option<DataWriter<DriveOutput>>,
    force: Vec3,
    setpoint: Setpoint,
}

impl Effector {
    /// An effector whose amplifiers deliver at most `max_force_n`.
    pub fn new(max_force_n: f64) -> Self {
        Self {
            max_force_n,
            force_in: None,
            setpoint_in: None,
            drive_out: None,
            force: [0.0; AXES],
            setpoint: Setpoint::default(),
        }
    }
}

impl Task for Effector {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.force_in = Some(ctx.input(names::FORCE));
        self.setpoint_in = Some(ctx.input(names::SETPOINT));
        self.drive_out = Some(ctx.output(names::DRIVE));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.force_in {
            r.get(&mut self.force);
        }
        if let Some(r) = &mut self.setpoint_in {
            r.get(&mut self.setpoint);
        }
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        let enabled = self.setpoint.enabled;
        let max = self.max_force_n;
        let force_n = self
            .force
            .map(|f| if enabled { f.clamp(-max, max) } else { 0.0 });
        if let Some(o) = &mut self.drive_out {
            o.set(DriveOutput {
                force_n,
                enabled,
                gripper_close: self.setpoint.gripper_close,
            });
        }
        Ok(())
    }
}
