//! A simulated servo axis: a CiA 402-like drive state machine in cyclic synchronous position
//! mode, a motor model with velocity/acceleration limits and a first-order position lag,
//! limit and home switches, drive-side homing, and fault injection.
//!
//! The simulation advances only when [`SimAxis::tick`] is called with the elapsed time, so
//! a test runs N servo cycles deterministically and the daemon ticks it from the servo
//! thread with the real period. Nothing allocates after construction.
//!
//! Behaviour, cycle by cycle (`tick`):
//! 1. scheduled and handle-injected faults are applied;
//! 2. the state machine takes one step toward the requested state (enabling walks
//!    switch-on disabled → ready to switch on → switched on → operation enabled, one state
//!    per tick, like a real drive answering one controlword per cycle);
//! 3. the velocity demand is computed (position loop, homing motion, or braking) and the
//!    motor ramps toward it within its acceleration limit; a stalled motor does not move;
//! 4. switches, homing progress, the drive's following-error window and the end of braking
//!    are evaluated.

mod config;
mod error;
mod handle;
pub(crate) mod motor;
#[cfg(test)]
mod tests;

pub use config::{FaultInjection, SimAxisConfig, SwitchRange};
pub use error::SimAxisError;
pub use handle::SimAxisHandle;

use crate::axis::{
    AxisDrive, AxisFeedback, AxisSwitches, DriveState, FaultCode, Homing, HomingFailure,
    HomingMethod, HomingParams, HomingStatus,
};
use crate::error::ErrorType;
use handle::Shared;
use std::sync::Arc;
use std::time::Duration;

/// Where a homing run is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum HomingPhase {
    /// No run active.
    Idle,
    /// Moving at the search velocity until the reference switch becomes active.
    Search(HomingParams),
    /// Backing off at the latch velocity until the switch releases.
    Latch(HomingParams),
    /// Braking to a standstill after the latch, a failure or an abort.
    Settle,
}

/// A simulated axis. Owned by the servo thread; see the module doc for its behaviour and
/// [`SimAxis::handle`] for injecting faults from elsewhere.
#[derive(Debug)]
pub struct SimAxis {
    config: SimAxisConfig,
    shared: Arc<Shared>,
    state: DriveState,
    enable_requested: bool,
    fault: Option<FaultCode>,
    /// Physical position (the switches' frame).
    physical: f64,
    velocity: f64,
    /// Reported position = physical + offset; homing sets the offset.
    offset: f64,
    /// Target position in reported coordinates.
    target: f64,
    /// Target seen at the previous tick, to tell a moving target from a standing one.
    last_target: f64,
    time_s: f64,
    scheduled_fault_done: bool,
    homing: HomingPhase,
    homing_status: HomingStatus,
}

impl SimAxis {
    /// Creates an axis at `config.initial_position`, in `NotReadyToSwitchOn` (it reaches
    /// `SwitchOnDisabled` on the first tick, as a drive finishes booting).
    pub fn new(config: SimAxisConfig) -> Result<SimAxis, SimAxisError> {
        config.validate()?;
        Ok(SimAxis {
            config,
            shared: Arc::default(),
            state: DriveState::NotReadyToSwitchOn,
            enable_requested: false,
            fault: None,
            physical: config.initial_position,
            velocity: 0.0,
            offset: 0.0,
            target: config.initial_position,
            last_target: config.initial_position,
            time_s: 0.0,
            scheduled_fault_done: false,
            homing: HomingPhase::Idle,
            homing_status: HomingStatus::NotHomed,
        })
    }

    /// A handle for injecting faults, stalls and link loss from another thread.
    pub fn handle(&self) -> SimAxisHandle {
        SimAxisHandle {
            shared: Arc::clone(&self.shared),
        }
    }

    /// The parameters the axis was built with.
    pub fn config(&self) -> &SimAxisConfig {
        &self.config
    }

    /// Simulated time since creation, in seconds.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The last accepted target position (reported coordinates).
    pub fn target_position(&self) -> f64 {
        self.target
    }

    /// Advances the simulation by `dt` (one servo cycle). Non-blocking, allocation-free.
    pub fn tick(&mut self, dt: Duration) {
        self.step(dt.as_secs_f64());
    }

    /// Advances the simulation to the absolute time `now` (measured from creation), for
    /// callers that pass a clock reading instead of a period: the step is the time since
    /// the last call, so a late servo cycle moves the motor further, as in reality. A `now`
    /// that is not later than the simulated time does nothing.
    pub fn advance_to(&mut self, now: Duration) {
        self.step(now.as_secs_f64() - self.time_s);
    }

    fn step(&mut self, dt: f64) {
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        self.time_s += dt;
        self.apply_injected_faults();
        self.step_state_machine();
        let (demand, decel) = self.velocity_demand(dt);
        self.move_motor(demand, decel, dt);
        self.after_motion();
    }

    fn position(&self) -> f64 {
        self.physical + self.offset
    }

    fn negative_limit_active(&self) -> bool {
        self.config
            .negative_limit
            .is_some_and(|l| self.physical <= l)
    }

    fn positive_limit_active(&self) -> bool {
        self.config
            .positive_limit
            .is_some_and(|l| self.physical >= l)
    }

    fn home_switch_active(&self) -> bool {
        self.config
            .home_switch
            .is_some_and(|h| h.contains(self.physical))
    }

    fn limit_active_toward(&self, direction: f64) -> bool {
        if direction > 0.0 {
            self.positive_limit_active()
        } else {
            self.negative_limit_active()
        }
    }

    /// The switch a homing run looks for, active now?
    fn reference_active(&self, params: &HomingParams) -> bool {
        match params.method {
            HomingMethod::HomeSwitch => self.home_switch_active(),
            HomingMethod::LimitSwitch => self.limit_active_toward(params.search_velocity),
            HomingMethod::CurrentPosition => true,
        }
    }

    fn apply_injected_faults(&mut self) {
        let inj = self.config.faults;
        if let Some(at) = inj.drive_fault_at_s {
            if !self.scheduled_fault_done && self.time_s >= at {
                self.scheduled_fault_done = true;
                self.enter_fault(inj.drive_fault_code);
            }
        }
        if let Some(code) = self.shared.take_fault() {
            self.enter_fault(code);
        }
    }

    fn stalled(&self) -> bool {
        self.shared.stalled()
            || self
                .config
                .faults
                .stall_at_s
                .is_some_and(|t| self.time_s >= t)
    }

    fn enter_fault(&mut self, code: FaultCode) {
        if self.state.is_fault() {
            return;
        }
        self.stop_homing(HomingFailure::DriveStopped);
        self.fault = Some(code);
        self.enable_requested = false;
        self.state = DriveState::FaultReactionActive;
    }

    /// Ends a homing run because the drive left `OperationEnabled` or the run failed.
    fn stop_homing(&mut self, why: HomingFailure) {
        if self.homing != HomingPhase::Idle {
            self.homing = HomingPhase::Idle;
            self.homing_status = HomingStatus::Failed(why);
        }
    }

    fn enter_operation_enabled(&mut self) {
        self.state = DriveState::OperationEnabled;
        // CSP: start from where the motor is, never jump to a stale target.
        self.target = self.position();
        self.last_target = self.target;
    }

    fn step_state_machine(&mut self) {
        self.state = match self.state {
            DriveState::NotReadyToSwitchOn => DriveState::SwitchOnDisabled,
            DriveState::SwitchOnDisabled if self.enable_requested => DriveState::ReadyToSwitchOn,
            DriveState::ReadyToSwitchOn if self.enable_requested => DriveState::SwitchedOn,
            DriveState::SwitchedOn if self.enable_requested => {
                self.enter_operation_enabled();
                DriveState::OperationEnabled
            }
            s => s,
        };
    }

    /// The velocity the drive demands this tick, and the deceleration it brakes with.
    fn velocity_demand(&mut self, dt: f64) -> (f64, f64) {
        let c = &self.config;
        let (vmax, amax, qs) = (
            c.max_velocity,
            c.max_acceleration,
            c.quick_stop_deceleration,
        );
        match self.state {
            DriveState::OperationEnabled => match self.homing {
                HomingPhase::Search(p) => (p.search_velocity.clamp(-vmax, vmax), amax),
                HomingPhase::Latch(p) => (
                    -p.search_velocity.signum() * p.latch_velocity.min(vmax),
                    amax,
                ),
                HomingPhase::Settle => (0.0, amax),
                HomingPhase::Idle => {
                    let moving = self.target != self.last_target;
                    self.last_target = self.target;
                    let error = self.target - self.position();
                    let demand = motor::position_loop(error, c.lag_s, dt, vmax, amax, moving);
                    if self.limit_active_toward(demand) {
                        (0.0, qs)
                    } else {
                        (demand, amax)
                    }
                }
            },
            DriveState::QuickStopActive | DriveState::FaultReactionActive => (0.0, qs),
            // Power stage off: the motor coasts; friction stops it at the rated deceleration.
            _ => (0.0, amax),
        }
    }

    fn move_motor(&mut self, demand: f64, decel: f64, dt: f64) {
        if self.stalled() {
            self.velocity = 0.0;
            return;
        }
        self.velocity = motor::ramp(
            self.velocity,
            demand,
            self.config.max_acceleration,
            decel,
            dt,
        );
        self.physical += self.velocity * dt;
    }

    fn after_motion(&mut self) {
        let stopped = self.velocity == 0.0;
        match self.homing {
            HomingPhase::Search(p) => {
                if self.reference_active(&p) {
                    self.homing = HomingPhase::Latch(p);
                } else if self.limit_active_toward(p.search_velocity) {
                    self.homing = HomingPhase::Settle;
                    self.homing_status = HomingStatus::Failed(HomingFailure::LimitReached);
                }
            }
            HomingPhase::Latch(p) => {
                let backing_off = self.velocity * p.search_velocity < 0.0;
                if backing_off && !self.reference_active(&p) {
                    self.offset = p.home_position - self.physical;
                    self.homing = HomingPhase::Settle;
                }
            }
            HomingPhase::Settle if stopped => {
                self.homing = HomingPhase::Idle;
                self.target = self.position();
                self.last_target = self.target;
                if self.homing_status == HomingStatus::InProgress {
                    self.homing_status = HomingStatus::Homed;
                }
            }
            _ => {}
        }
        match self.state {
            DriveState::OperationEnabled if self.homing == HomingPhase::Idle => {
                if let Some(window) = self.config.following_error_window {
                    if (self.target - self.position()).abs() > window {
                        self.enter_fault(FaultCode::FOLLOWING_ERROR);
                    }
                }
            }
            DriveState::FaultReactionActive if stopped => self.state = DriveState::Fault,
            DriveState::QuickStopActive if stopped && self.enable_requested => {
                self.enter_operation_enabled();
            }
            _ => {}
        }
    }

    fn check_link(&self) -> Result<(), SimAxisError> {
        if self.shared.disconnected() {
            Err(SimAxisError::Disconnected)
        } else {
            Ok(())
        }
    }

    fn check_operational(&self) -> Result<(), SimAxisError> {
        self.check_link()?;
        match (self.state, self.fault) {
            (DriveState::OperationEnabled, _) => Ok(()),
            (_, Some(code)) => Err(SimAxisError::Faulted(code)),
            (s, None) => Err(SimAxisError::NotOperational(s)),
        }
    }
}

impl ErrorType for SimAxis {
    type Error = SimAxisError;
}

impl AxisDrive for SimAxis {
    fn enable(&mut self) -> Result<(), SimAxisError> {
        self.check_link()?;
        if let Some(code) = self.fault {
            return Err(SimAxisError::Faulted(code));
        }
        self.enable_requested = true;
        Ok(())
    }

    fn disable(&mut self) -> Result<(), SimAxisError> {
        self.check_link()?;
        self.enable_requested = false;
        if !self.state.is_fault() && self.state != DriveState::NotReadyToSwitchOn {
            self.stop_homing(HomingFailure::DriveStopped);
            self.state = DriveState::SwitchOnDisabled;
        }
        Ok(())
    }

    fn set_target_position(&mut self, position: f64) -> Result<(), SimAxisError> {
        self.check_operational()?;
        if self.homing != HomingPhase::Idle {
            return Err(SimAxisError::HomingInProgress);
        }
        if !position.is_finite() {
            return Err(SimAxisError::InvalidArgument(
                "target position is not finite",
            ));
        }
        if position > self.target && self.positive_limit_active() {
            return Err(SimAxisError::LimitSwitch("positive"));
        }
        if position < self.target && self.negative_limit_active() {
            return Err(SimAxisError::LimitSwitch("negative"));
        }
        self.target = position;
        Ok(())
    }

    fn quick_stop(&mut self) -> Result<(), SimAxisError> {
        self.check_link()?;
        self.enable_requested = false;
        match self.state {
            DriveState::OperationEnabled => {
                self.stop_homing(HomingFailure::DriveStopped);
                self.state = DriveState::QuickStopActive;
            }
            DriveState::ReadyToSwitchOn | DriveState::SwitchedOn => {
                self.state = DriveState::SwitchOnDisabled;
            }
            _ => {}
        }
        Ok(())
    }

    fn fault_reset(&mut self) -> Result<(), SimAxisError> {
        self.check_link()?;
        if self.state == DriveState::Fault {
            self.fault = None;
            self.enable_requested = false;
            self.state = DriveState::SwitchOnDisabled;
        }
        Ok(())
    }
}

impl AxisFeedback for SimAxis {
    fn actual_position(&mut self) -> Result<f64, SimAxisError> {
        self.check_link()?;
        Ok(self.position())
    }

    fn actual_velocity(&mut self) -> Result<f64, SimAxisError> {
        self.check_link()?;
        Ok(self.velocity)
    }

    fn drive_state(&mut self) -> Result<DriveState, SimAxisError> {
        self.check_link()?;
        Ok(self.state)
    }

    fn fault_code(&mut self) -> Result<Option<FaultCode>, SimAxisError> {
        self.check_link()?;
        Ok(self.fault)
    }

    fn switches(&mut self) -> Result<AxisSwitches, SimAxisError> {
        self.check_link()?;
        Ok(AxisSwitches {
            negative_limit: self.negative_limit_active(),
            positive_limit: self.positive_limit_active(),
            home: self.home_switch_active(),
        })
    }
}

impl Homing for SimAxis {
    fn start_homing(&mut self, params: &HomingParams) -> Result<(), SimAxisError> {
        self.check_operational()?;
        if self.homing != HomingPhase::Idle {
            return Err(SimAxisError::HomingInProgress);
        }
        if !params.home_position.is_finite() {
            return Err(SimAxisError::InvalidArgument("home position is not finite"));
        }
        if params.method == HomingMethod::CurrentPosition {
            self.offset = params.home_position - self.physical;
            self.target = self.position();
            self.last_target = self.target;
            self.homing_status = HomingStatus::Homed;
            return Ok(());
        }
        if !(params.search_velocity.is_finite() && params.search_velocity != 0.0) {
            return Err(SimAxisError::InvalidArgument(
                "search velocity must be finite and non-zero",
            ));
        }
        if !(params.latch_velocity.is_finite() && params.latch_velocity > 0.0) {
            return Err(SimAxisError::InvalidArgument("latch velocity must be > 0"));
        }
        let has_switch = match params.method {
            HomingMethod::HomeSwitch => self.config.home_switch.is_some(),
            HomingMethod::LimitSwitch if params.search_velocity > 0.0 => {
                self.config.positive_limit.is_some()
            }
            _ => self.config.negative_limit.is_some(),
        };
        if !has_switch {
            return Err(SimAxisError::NoSwitch(match params.method {
                HomingMethod::HomeSwitch => "home switch",
                _ => "limit switch in the search direction",
            }));
        }
        self.homing = HomingPhase::Search(*params);
        self.homing_status = HomingStatus::InProgress;
        Ok(())
    }

    fn homing_status(&mut self) -> Result<HomingStatus, SimAxisError> {
        self.check_link()?;
        Ok(self.homing_status)
    }

    fn abort_homing(&mut self) -> Result<(), SimAxisError> {
        self.check_link()?;
        if matches!(self.homing, HomingPhase::Search(_) | HomingPhase::Latch(_)) {
            self.homing = HomingPhase::Settle;
            self.homing_status = HomingStatus::Failed(HomingFailure::Aborted);
        }
        Ok(())
    }
}
