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

/// The loopback drive's simulated switches, in motor counts (the motor's own coordinate,
/// which homing does not move): set through object 0x2002.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Switches {
    /// The home switch is active at and above this position (methods 19/20) or at and below
    /// it (21/22).
    pub(crate) home: i32,
    /// The negative limit switch is active at and below this position (method 17).
    pub(crate) negative_limit: i32,
    /// The positive limit switch is active at and above this position (method 18).
    pub(crate) positive_limit: i32,
}

/// A homing run in progress: which switch, and whether it is still searching for the
/// switch (fast, 0x6099:1) or backing off it to the edge (slow, 0x6099:2).
#[derive(Debug, Clone, Copy, PartialEq)]
struct HomingRun {
    /// Direction of the search: +1 or -1.
    dir: f64,
    /// True once the switch was found: moving back (-dir) until it releases.
    backing: bool,
}

#[derive(Debug, Clone)]
pub(crate) struct Drive {
    pub(crate) state: State402,
    pub(crate) controlword: u16,
    pub(crate) mode: i8,
    pub(crate) target_position: i32,
    pub(crate) target_velocity: i32,
    pub(crate) homing_method: i8,
    /// 0x6099:1 speed during search for switch, :2 during search for zero (counts/s).
    pub(crate) homing_speeds: [u32; 2],
    /// 0x609A homing acceleration (counts/s²; 0: the drive's own limit).
    pub(crate) homing_acceleration: u32,
    /// 0x607C home offset: the position the home point takes after homing.
    pub(crate) home_offset: i32,
    pub(crate) switches: Switches,
    /// Position minus motor counts: homing sets the position without moving the motor.
    shift: f64,
    homing: Option<HomingRun>,
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
            homing_speeds: [20_000, 2_000],
            homing_acceleration: 0,
            home_offset: 0,
            switches: Switches {
                home: 10_000,
                negative_limit: -200_000,
                positive_limit: 200_000,
            },
            shift: 0.0,
            homing: None,
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
        let (p, v, shift, sw) = (self.position, self.velocity, self.shift, self.switches);
        *self = Drive::new();
        self.position = p;
        self.velocity = v;
        self.shift = shift;
        self.switches = sw;
    }

    /// The motor position in counts (where the switches are).
    fn motor(&self) -> f64 {
        self.position - self.shift
    }

    /// Whether the switch of homing method `method` is active at the motor's position.
    fn switch_active(&self, method: i8) -> Option<bool> {
        let m = self.motor();
        let s = self.switches;
        Some(match method {
            17 => m <= f64::from(s.negative_limit),
            18 => m >= f64::from(s.positive_limit),
            19 | 20 => m >= f64::from(s.home),
            21 | 22 => m <= f64::from(s.home),
            _ => return None,
        })
    }

    /// The position becomes the home offset here, without moving the motor.
    fn set_home_here(&mut self) {
        let home = f64::from(self.home_offset);
        self.shift += home - self.position;
        self.position = home;
        self.pp_target = home;
        self.target_position = self.home_offset;
        self.last_target = self.home_offset;
        self.homing = None;
        self.homing_attained = true;
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
                // Bit 12 homing attained, bit 10 target reached once at rest (or halted).
                if self.homing_attained {
                    sw |= SW_OP_MODE_12;
                }
                if self.homing.is_none() && self.velocity == 0.0 {
                    sw |= SW_TARGET_REACHED;
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

    /// Starts homing (controlword bit 4 rising in homing mode) with method 0x6098.
    fn home(&mut self) {
        self.homing_attained = false;
        self.homing_error = false;
        let method = self.homing_method;
        // Which way the search goes: toward the limit switch (17/18), toward the home
        // switch's active side (19/20 above, 21/22 below).
        let dir = match method {
            // 35 (old) and 37: the current position is the home position.
            35 | 37 => return self.set_home_here(),
            17 | 21 | 22 => -1.0,
            18..=20 => 1.0,
            _ => {
                self.homing_error = true;
                return;
            }
        };
        // Already on the switch: only the slow move off it to its edge remains.
        let backing = self.switch_active(method) == Some(true);
        self.homing = Some(HomingRun { dir, backing });
    }

    /// One cycle of a homing run: the velocity demand, and the edge found.
    fn homing_demand(&mut self) -> f64 {
        let Some(run) = self.homing else { return 0.0 };
        let active = self.switch_active(self.homing_method) == Some(true);
        let [search, zero] = self.homing_speeds.map(f64::from);
        if !run.backing && active {
            self.homing = Some(HomingRun {
                backing: true,
                ..run
            });
            return -run.dir * zero;
        }
        if run.backing && !active {
            self.set_home_here();
            return 0.0;
        }
        let m = self.motor();
        let s = self.switches;
        let beyond = m < f64::from(s.negative_limit) - 1.0 || m > f64::from(s.positive_limit) + 1.0;
        if beyond && !matches!(self.homing_method, 17 | 18) {
            // A limit switch before the home switch: homing error, stop.
            self.homing = None;
            self.homing_error = true;
            return 0.0;
        }
        if run.backing {
            -run.dir * zero
        } else {
            run.dir * search
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
                MODE_HM => {
                    let acc = match self.homing_acceleration {
                        0 => amax,
                        a => f64::from(a),
                    };
                    (self.homing_demand(), acc)
                }
                _ => (0.0, amax),
            },
            State402::QuickStopActive | State402::FaultReactionActive => (0.0, qs),
            _ => {
                self.velocity = 0.0;
                return None;
            }
        };
        // Homing ramps with its own acceleration (0x609A) both ways.
        let accel = if self.mode == MODE_HM && self.state == State402::OperationEnabled {
            decel
        } else {
            amax
        };
        self.velocity = motor::ramp(self.velocity, demand, accel, decel, dt);
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
