//! The drive inside the loopback slave: the CiA 402 state machine on the slave side, CSP /
//! PP / homing motion on the simulated axis's motor model, and faults with their EMCY.

use super::super::cia402::{
    Command, State402, CW_OP_MODE_4, SW_OP_MODE_12, SW_OP_MODE_13, SW_REMOTE, SW_TARGET_REACHED,
    SW_VOLTAGE_ENABLED,
};
use super::super::emcy::Emergency;
use super::SlaveConfig;
use crate::sim::axis::motor;

/// CiA 402 following error (EMCY code).
pub const FOLLOWING_ERROR: u16 = 0x8611;

/// Mode codes the slave supports.
pub(crate) const MODE_PP: i8 = 1;
pub(crate) const MODE_HM: i8 = 6;
pub(crate) const MODE_CSP: i8 = 8;

#[derive(Debug, Clone)]
pub(crate) struct Drive {
    pub(crate) state: State402,
    pub(crate) controlword: u16,
    pub(crate) mode: i8,
    pub(crate) target_position: i32,
    pub(crate) target_velocity: i32,
    pub(crate) homing_method: i8,
    pub(crate) following_window: u32,
    pub(crate) error_code: u16,
    pub(crate) error_register: u8,
    /// Position in counts (f64 so the motor model integrates without rounding drift).
    pub(crate) position: f64,
    pub(crate) velocity: f64,
    last_target: i32,
    pp_target: f64,
    homing_attained: bool,
    homing_error: bool,
    following_error: bool,
}

impl Drive {
    pub(crate) fn new() -> Drive {
        Drive {
            state: State402::SwitchOnDisabled,
            controlword: 0,
            mode: 0,
            target_position: 0,
            target_velocity: 0,
            homing_method: 0,
            following_window: 0,
            error_code: 0,
            error_register: 0,
            position: 0.0,
            velocity: 0.0,
            last_target: 0,
            pp_target: 0.0,
            homing_attained: false,
            homing_error: false,
            following_error: false,
        }
    }

    /// Application reset (NMT reset node): state machine and set-points back to power-on,
    /// the physical position stays where the motor is.
    pub(crate) fn reset(&mut self) {
        let (p, v) = (self.position, self.velocity);
        *self = Drive::new();
        self.position = p;
        self.velocity = v;
    }

    pub(crate) fn position_actual(&self) -> i32 {
        self.position
            .round()
            .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    }

    pub(crate) fn velocity_actual(&self) -> i32 {
        self.velocity
            .round()
            .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    }

    pub(crate) fn statusword(&self) -> u16 {
        let mut sw = self.state.statusword_bits() | SW_REMOTE;
        if matches!(
            self.state,
            State402::ReadyToSwitchOn
                | State402::SwitchedOn
                | State402::OperationEnabled
                | State402::QuickStopActive
        ) {
            sw |= SW_VOLTAGE_ENABLED;
        }
        let enabled = self.state == State402::OperationEnabled;
        match self.mode {
            MODE_CSP => {
                if enabled {
                    sw |= SW_OP_MODE_12;
                }
                if self.following_error {
                    sw |= SW_OP_MODE_13;
                }
            }
            MODE_PP => {
                if (self.pp_target - self.position).abs() < 0.5 && self.velocity == 0.0 {
                    sw |= SW_TARGET_REACHED;
                }
                if self.following_error {
                    sw |= SW_OP_MODE_13;
                }
            }
            MODE_HM => {
                if self.homing_attained {
                    sw |= SW_OP_MODE_12 | SW_TARGET_REACHED;
                }
                if self.homing_error {
                    sw |= SW_OP_MODE_13;
                }
            }
            _ => {}
        }
        sw
    }

    /// Applies a controlword (SDO or RPDO): the state transition it commands, and the
    /// mode-specific bit 4 edge (PP new set-point, HM start). Returns true when it reset a
    /// fault (the slave then sends the EMCY "error reset", code 0x0000).
    pub(crate) fn write_controlword(&mut self, cw: u16) -> bool {
        let was_fault = self.state == State402::Fault;
        let prev = self.controlword;
        self.controlword = cw;
        let Some(cmd) = Command::decode(cw, prev) else {
            return false;
        };
        use State402 as S;
        self.state = match (self.state, cmd) {
            (S::Fault, Command::FaultReset) => {
                self.error_code = 0;
                self.error_register = 0;
                self.following_error = false;
                S::SwitchOnDisabled
            }
            (S::Fault | S::FaultReactionActive | S::NotReadyToSwitchOn, _) => self.state,
            (_, Command::FaultReset) => self.state,
            (S::QuickStopActive, Command::DisableVoltage) => S::SwitchOnDisabled,
            (S::QuickStopActive, _) => S::QuickStopActive,
            (_, Command::DisableVoltage) => S::SwitchOnDisabled,
            (S::OperationEnabled, Command::QuickStop) => S::QuickStopActive,
            (_, Command::QuickStop) => S::SwitchOnDisabled,
            (S::SwitchOnDisabled, Command::Shutdown) => S::ReadyToSwitchOn,
            (S::SwitchOnDisabled, _) => S::SwitchOnDisabled,
            (_, Command::Shutdown) => S::ReadyToSwitchOn,
            (S::ReadyToSwitchOn, Command::SwitchOn | Command::EnableOperation) => S::SwitchedOn,
            (S::SwitchedOn, Command::EnableOperation) => {
                // Hold where the motor is: a stale target must not make the axis jump.
                self.target_position = self.position_actual();
                self.last_target = self.target_position;
                self.pp_target = self.position;
                S::OperationEnabled
            }
            (S::OperationEnabled, Command::SwitchOn | Command::DisableOperation) => S::SwitchedOn,
            (s, _) => s,
        };
        let rising4 = cw & CW_OP_MODE_4 != 0 && prev & CW_OP_MODE_4 == 0;
        if rising4 && self.state == S::OperationEnabled {
            match self.mode {
                MODE_PP => self.pp_target = f64::from(self.target_position),
                MODE_HM => self.home(),
                _ => {}
            }
        }
        was_fault && self.state == State402::SwitchOnDisabled
    }

    fn home(&mut self) {
        self.homing_attained = false;
        self.homing_error = false;
        match self.homing_method {
            // 35 (old) and 37: the current position is the home position (offset 0).
            35 | 37 => {
                self.position = 0.0;
                self.pp_target = 0.0;
                self.target_position = 0;
                self.last_target = 0;
                self.homing_attained = true;
            }
            // Switch-based methods need switches the loopback drive does not model yet.
            _ => self.homing_error = true,
        }
    }

    /// Raises a drive fault: Fault reaction active (braking), error code, register and the
    /// EMCY to send. Returns `None` when already in a fault.
    pub(crate) fn fault(&mut self, code: u16) -> Option<Emergency> {
        if self.state.is_fault() {
            return None;
        }
        self.state = State402::FaultReactionActive;
        self.error_code = code;
        self.error_register = error_register_bits(code);
        Some(Emergency::new(code, self.error_register))
    }

    /// Advances the drive by `dt` seconds: one servo cycle of motion. Returns an EMCY when
    /// a fault (following error) arises.
    pub(crate) fn step(&mut self, cfg: &SlaveConfig, dt: f64) -> Option<Emergency> {
        let (vmax, amax, qs) = (
            cfg.max_velocity,
            cfg.max_acceleration,
            cfg.quick_stop_deceleration,
        );
        let (demand, decel) = match self.state {
            State402::OperationEnabled => match self.mode {
                MODE_CSP => {
                    let moving = self.target_position != self.last_target;
                    self.last_target = self.target_position;
                    let error = f64::from(self.target_position) - self.position;
                    (
                        motor::position_loop(error, cfg.lag_s, dt, vmax, amax, moving),
                        amax,
                    )
                }
                MODE_PP => {
                    let error = self.pp_target - self.position;
                    (
                        motor::position_loop(error, 0.0, dt, vmax, amax, false),
                        amax,
                    )
                }
                _ => (0.0, amax),
            },
            State402::QuickStopActive | State402::FaultReactionActive => (0.0, qs),
            _ => {
                self.velocity = 0.0;
                return None;
            }
        };
        self.velocity = motor::ramp(self.velocity, demand, amax, decel, dt);
        self.position += self.velocity * dt;
        if self.state == State402::FaultReactionActive && self.velocity == 0.0 {
            self.state = State402::Fault;
        }
        if self.state == State402::OperationEnabled
            && self.mode == MODE_CSP
            && self.following_window > 0
            && (f64::from(self.target_position) - self.position).abs()
                > f64::from(self.following_window)
        {
            self.following_error = true;
            return self.fault(FOLLOWING_ERROR);
        }
        None
    }
}

/// The error register 0x1001 bits for an error code: bit 0 generic always, plus current
/// (1), voltage (2), temperature (3), communication (4), device profile (5) by class.
pub(crate) fn error_register_bits(code: u16) -> u8 {
    let class = match code >> 12 {
        0x2 => 1 << 1,
        0x3 => 1 << 2,
        0x4 => 1 << 3,
        0x8 if code >> 8 == 0x81 || code >> 8 == 0x82 => 1 << 4,
        0x8 => 1 << 5,
        _ => 0,
    };
    1 | class
}
