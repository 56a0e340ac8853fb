//! The `axis.<name>` tasks: one per axis, after the interpolator on the servo thread.
//!
//! Each cycle: apply the machine task's drive requests (enable, disable, quick stop, fault
//! reset, homing), send this cycle's setpoint (CSP: a new target every cycle) while the drive
//! is operational and not homing, advance a simulated drive by one period, and publish the
//! drive's feedback. A drive call that fails counts a stale cycle; the monitor turns too
//! many into "communication lost".

use super::{ports, AxisFeedback, DriveControl, Setpoints};
use crate::machine::devices::AxisDevice;
use crate::rt::prelude::*;
use hytask_hal::axis::{DriveState, HomingParams, HomingStatus};
use std::time::Duration;

/// One axis' task.
pub struct AxisTask {
    name: char,
    /// Pose/joint index.
    index: usize,
    device: AxisDevice,
    homing: HomingParams,
    control_in: Option<DataReader<DriveControl>>,
    setpoints_in: Option<DataReader<Setpoints>>,
    out: Option<DataWriter<AxisFeedback>>,
    control: DriveControl,
    setpoints: Setpoints,
    seen: DriveControl,
    fb: AxisFeedback,
    homing_requested: bool,
}

impl AxisTask {
    /// The task of axis `name` (pose index `index`) driving `device`.
    pub fn new(name: char, index: usize, device: AxisDevice, homing: HomingParams) -> Self {
        AxisTask {
            name,
            index,
            device,
            homing,
            control_in: None,
            setpoints_in: None,
            out: None,
            control: DriveControl::default(),
            setpoints: Setpoints::default(),
            seen: DriveControl::default(),
            fb: AxisFeedback::default(),
            homing_requested: false,
        }
    }

    /// Applies the drive requests; returns false if a drive call failed.
    fn apply_control(&mut self) -> bool {
        let c = self.control;
        let i = self.index;
        let axis = self.device.axis();
        let mut ok = true;
        if c.fault_reset_seq != self.seen.fault_reset_seq {
            ok &= axis.fault_reset().is_ok();
        }
        if c.home_abort_seq != self.seen.home_abort_seq && self.homing_requested {
            ok &= axis.abort_homing().is_ok();
            self.homing_requested = false;
        }
        if c.home_seq[i] != self.seen.home_seq[i] {
            ok &= axis.start_homing(&self.homing).is_ok();
            self.homing_requested = true;
            self.fb.homing_failed = false;
        }
        let state = self.fb.state;
        if c.quick_stop {
            if state == DriveState::OperationEnabled {
                ok &= axis.quick_stop().is_ok();
            } else if state == DriveState::QuickStopActive && self.fb.velocity.abs() < 1e-9 {
                ok &= axis.disable().is_ok();
            }
        } else if c.enable {
            if !state.is_operational() && !state.is_fault() {
                ok &= axis.enable().is_ok();
            }
        } else if state.is_operational() || state == DriveState::QuickStopActive {
            ok &= axis.disable().is_ok();
        }
        self.seen = c;
        ok
    }

    fn read_feedback(&mut self) -> bool {
        let axis = self.device.axis();
        let mut ok = true;
        match axis.actual_position() {
            Ok(p) => self.fb.actual = p,
            Err(_) => ok = false,
        }
        match axis.actual_velocity() {
            Ok(v) => self.fb.velocity = v,
            Err(_) => ok = false,
        }
        match axis.drive_state() {
            Ok(s) => self.fb.state = s,
            Err(_) => ok = false,
        }
        match axis.fault_code() {
            Ok(f) => self.fb.fault = f.map(|c| c.0),
            Err(_) => ok = false,
        }
        match axis.switches() {
            Ok(s) => self.fb.limit_switch = s.negative_limit || s.positive_limit,
            Err(_) => ok = false,
        }
        match axis.homing_status() {
            Ok(HomingStatus::Homed) => {
                self.fb.homed = true;
                self.fb.homing = false;
            }
            Ok(HomingStatus::InProgress) => {
                self.fb.homing = true;
                self.fb.homed = false;
            }
            Ok(HomingStatus::Failed(_)) => {
                self.fb.homing = false;
                self.fb.homed = false;
                self.fb.homing_failed = self.homing_requested;
                self.homing_requested = false;
            }
            Ok(HomingStatus::NotHomed) => {
                self.fb.homing = false;
                self.fb.homed = false;
            }
            Err(_) => ok = false,
        }
        ok
    }
}

impl Task for AxisTask {
    type Command = NoCommands;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.control_in = Some(ctx.input(ports::DRIVE_CONTROL));
        self.setpoints_in = Some(ctx.input(ports::SETPOINTS));
        self.out = Some(ctx.output(&ports::feedback(self.name)));
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        if let Some(r) = &mut self.control_in {
            r.get(&mut self.control);
        }
        if let Some(r) = &mut self.setpoints_in {
            r.get(&mut self.setpoints);
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let mut ok = self.apply_control();
        if self.fb.state == DriveState::OperationEnabled
            && !self.fb.homing
            && !self.control.quick_stop
        {
            ok &= self
                .device
                .axis()
                .set_target_position(self.setpoints.joints[self.index])
                .is_ok();
        }
        self.device.tick(Duration::from_nanos(ctx.period_ns));
        ok &= self.read_feedback();
        self.fb.link = self.device.link_fault();
        self.fb.age = self.device.feedback_age();
        self.fb.stale_cycles = if ok {
            0
        } else {
            self.fb.stale_cycles.saturating_add(1)
        };
        if ok {
            self.fb.valid = true;
        }
        if let Some(w) = &mut self.out {
            w.set(self.fb);
        }
        Ok(())
    }
}
