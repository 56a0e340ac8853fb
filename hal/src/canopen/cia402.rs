//! CiA 402 (IEC 61800-7-201) power state machine: the eight states decoded from the
//! statusword 0x6041, the controlword 0x6040 commands, the master-side controller that walks
//! a drive to Operation enabled (fault reset on a rising edge of bit 7), and modes of
//! operation 0x6060 / 0x6061 with confirmation. No allocation anywhere.

pub use crate::axis::DriveState;

/// The eight states of the power state machine: the HAL's [`DriveState`], one type for the
/// axis traits and the protocol (this name stays for the CiA 402 code that reads better
/// with it).
pub type State402 = DriveState;

impl DriveState {
    /// The state a statusword shows (CiA 402 table: bits 0-3, 5, 6).
    pub fn from_statusword(sw: u16) -> DriveState {
        if sw & 0x4F == 0x00 {
            DriveState::NotReadyToSwitchOn
        } else if sw & 0x4F == 0x40 {
            DriveState::SwitchOnDisabled
        } else if sw & 0x6F == 0x21 {
            DriveState::ReadyToSwitchOn
        } else if sw & 0x6F == 0x23 {
            DriveState::SwitchedOn
        } else if sw & 0x6F == 0x27 {
            DriveState::OperationEnabled
        } else if sw & 0x6F == 0x07 {
            DriveState::QuickStopActive
        } else if sw & 0x4F == 0x0F {
            DriveState::FaultReactionActive
        } else if sw & 0x4F == 0x08 {
            DriveState::Fault
        } else {
            // The remaining patterns are not defined; reading them as "not ready" keeps the
            // master from enabling a drive that says something it does not understand.
            DriveState::NotReadyToSwitchOn
        }
    }

    /// The state bits of the statusword (bits 0-3, 5, 6) a drive in this state reports.
    pub fn statusword_bits(self) -> u16 {
        match self {
            DriveState::NotReadyToSwitchOn => 0x00,
            DriveState::SwitchOnDisabled => 0x40,
            DriveState::ReadyToSwitchOn => 0x21,
            DriveState::SwitchedOn => 0x23,
            DriveState::OperationEnabled => 0x27,
            DriveState::QuickStopActive => 0x07,
            DriveState::FaultReactionActive => 0x0F,
            DriveState::Fault => 0x08,
        }
    }
}

/// Statusword bit 10: target reached.
pub const SW_TARGET_REACHED: u16 = 1 << 10;
/// Statusword bit 4: voltage enabled.
pub const SW_VOLTAGE_ENABLED: u16 = 1 << 4;
/// Statusword bit 9: remote (controlword processed).
pub const SW_REMOTE: u16 = 1 << 9;
/// Statusword bit 12: mode specific (CSP: drive follows the target; HM: homing attained).
pub const SW_OP_MODE_12: u16 = 1 << 12;
/// Statusword bit 13: mode specific (CSP/PP: following error; HM: homing error).
pub const SW_OP_MODE_13: u16 = 1 << 13;
/// Controlword bit 7: fault reset (acts on its rising edge).
pub const CW_FAULT_RESET: u16 = 1 << 7;
/// Controlword bit 4: mode specific (PP: new set-point; HM: start homing).
pub const CW_OP_MODE_4: u16 = 1 << 4;

/// A controlword command (device control commands, CiA 402).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Shutdown (x110): → Ready to switch on.
    Shutdown,
    /// Switch on (0111): → Switched on.
    SwitchOn,
    /// Switch on + enable operation (1111): → Operation enabled.
    EnableOperation,
    /// Disable operation (0111 from Operation enabled): → Switched on.
    DisableOperation,
    /// Disable voltage (xx0x): → Switch on disabled.
    DisableVoltage,
    /// Quick stop (x01x): → Quick stop active.
    QuickStop,
    /// Fault reset (rising edge of bit 7): Fault → Switch on disabled.
    FaultReset,
}

impl Command {
    /// The controlword bits 0-3 and 7 of the command.
    pub fn controlword(self) -> u16 {
        match self {
            Command::Shutdown => 0x06,
            Command::SwitchOn | Command::DisableOperation => 0x07,
            Command::EnableOperation => 0x0F,
            Command::DisableVoltage => 0x00,
            Command::QuickStop => 0x02,
            Command::FaultReset => 0x80,
        }
    }

    /// The command a drive reads from `cw`, given the previous controlword `prev` (for the
    /// fault-reset edge). `None` for the undefined patterns.
    pub fn decode(cw: u16, prev: u16) -> Option<Command> {
        if cw & CW_FAULT_RESET != 0 && prev & CW_FAULT_RESET == 0 {
            return Some(Command::FaultReset);
        }
        if cw & 0x02 == 0 {
            Some(Command::DisableVoltage)
        } else if cw & 0x06 == 0x02 {
            Some(Command::QuickStop)
        } else if cw & 0x07 == 0x06 {
            Some(Command::Shutdown)
        } else if cw & 0x0F == 0x07 {
            Some(Command::SwitchOn)
        } else if cw & 0x0F == 0x0F {
            Some(Command::EnableOperation)
        } else {
            None
        }
    }
}

/// What the master wants from a drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PowerRequest {
    /// Walk to Operation enabled (resetting a fault on the way).
    Enable,
    /// Back to Switch on disabled (power stage off).
    Disable,
    /// Quick stop, then stay there until Disable.
    QuickStop,
    /// Reset a fault (rising edge of bit 7) and stay in Switch on disabled.
    FaultReset,
}

/// The master side of the power state machine: one [`step`](PowerController::step) per
/// cycle with the drive's statusword gives the next controlword (bits 0-3, 7; the caller ORs
/// mode-specific bits in). One transition per cycle, as drives take one controlword per
/// SYNC.
#[derive(Debug, Clone, Copy)]
pub struct PowerController {
    request: PowerRequest,
    last_cw: u16,
}

impl Default for PowerController {
    fn default() -> Self {
        PowerController {
            request: PowerRequest::Disable,
            last_cw: 0,
        }
    }
}

impl PowerController {
    /// Sets what the drive should do.
    pub fn request(&mut self, r: PowerRequest) {
        self.request = r;
    }

    /// The current request.
    pub fn current_request(&self) -> PowerRequest {
        self.request
    }

    /// The controlword to send for a drive reporting `statusword`. Never allocates.
    pub fn step(&mut self, statusword: u16) -> u16 {
        let state = DriveState::from_statusword(statusword);
        let cw = match (self.request, state) {
            // Fault reset needs a rising edge: send bit 7 low for a cycle first.
            (_, DriveState::Fault) => {
                let resetting = matches!(
                    self.request,
                    PowerRequest::Enable | PowerRequest::FaultReset
                );
                if resetting && self.last_cw & CW_FAULT_RESET == 0 {
                    Command::FaultReset.controlword()
                } else {
                    Command::DisableVoltage.controlword()
                }
            }
            (_, DriveState::FaultReactionActive | DriveState::NotReadyToSwitchOn) => {
                Command::DisableVoltage.controlword()
            }
            (PowerRequest::Disable | PowerRequest::FaultReset, _) => {
                Command::DisableVoltage.controlword()
            }
            (
                PowerRequest::QuickStop,
                DriveState::OperationEnabled | DriveState::QuickStopActive,
            ) => Command::QuickStop.controlword(),
            (PowerRequest::QuickStop, _) => Command::DisableVoltage.controlword(),
            (PowerRequest::Enable, DriveState::SwitchOnDisabled) => Command::Shutdown.controlword(),
            (PowerRequest::Enable, DriveState::ReadyToSwitchOn) => Command::SwitchOn.controlword(),
            (PowerRequest::Enable, DriveState::SwitchedOn | DriveState::OperationEnabled) => {
                Command::EnableOperation.controlword()
            }
            // Leave quick stop through Switch on disabled before enabling again.
            (PowerRequest::Enable, DriveState::QuickStopActive) => {
                Command::DisableVoltage.controlword()
            }
        };
        self.last_cw = cw;
        cw
    }
}

/// Modes of operation (0x6060 / 0x6061 values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Profile position (1).
    ProfilePosition,
    /// Profile velocity (3).
    ProfileVelocity,
    /// Homing (6).
    Homing,
    /// Cyclic synchronous position (8).
    CyclicSyncPosition,
    /// Cyclic synchronous velocity (9).
    CyclicSyncVelocity,
    /// Cyclic synchronous torque (10).
    CyclicSyncTorque,
}

impl Mode {
    /// The 0x6060 value.
    pub fn code(self) -> i8 {
        match self {
            Mode::ProfilePosition => 1,
            Mode::ProfileVelocity => 3,
            Mode::Homing => 6,
            Mode::CyclicSyncPosition => 8,
            Mode::CyclicSyncVelocity => 9,
            Mode::CyclicSyncTorque => 10,
        }
    }

    /// The mode of a 0x6061 value.
    pub fn from_code(c: i8) -> Option<Mode> {
        Some(match c {
            1 => Mode::ProfilePosition,
            3 => Mode::ProfileVelocity,
            6 => Mode::Homing,
            8 => Mode::CyclicSyncPosition,
            9 => Mode::CyclicSyncVelocity,
            10 => Mode::CyclicSyncTorque,
            _ => return None,
        })
    }
}

/// A requested mode change that counts as done only once 0x6061 shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModeRequest {
    wanted: Mode,
    confirmed: bool,
}

impl ModeRequest {
    /// Requests `wanted` (the caller writes 0x6060).
    pub fn new(wanted: Mode) -> ModeRequest {
        ModeRequest {
            wanted,
            confirmed: false,
        }
    }

    /// Feeds a 0x6061 reading; true once the drive displays the wanted mode.
    pub fn on_display(&mut self, display: i8) -> bool {
        self.confirmed = display == self.wanted.code();
        self.confirmed
    }

    /// True once confirmed.
    pub fn is_confirmed(&self) -> bool {
        self.confirmed
    }

    /// The mode asked for.
    pub fn wanted(&self) -> Mode {
        self.wanted
    }

    /// The error to raise when the confirmation does not come in time.
    pub fn not_confirmed(&self, node: super::NodeId, display: i8) -> super::CanOpenError {
        super::CanOpenError::ModeNotConfirmed {
            node,
            wanted: self.wanted.code(),
            actual: display,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [DriveState; 8] = [
        DriveState::NotReadyToSwitchOn,
        DriveState::SwitchOnDisabled,
        DriveState::ReadyToSwitchOn,
        DriveState::SwitchedOn,
        DriveState::OperationEnabled,
        DriveState::QuickStopActive,
        DriveState::FaultReactionActive,
        DriveState::Fault,
    ];

    #[test]
    fn statusword_decodes_to_the_eight_states_ignoring_other_bits() {
        for s in ALL {
            assert_eq!(DriveState::from_statusword(s.statusword_bits()), s);
            // Voltage enabled, warning, remote, target reached, mode bits do not matter.
            let noisy = s.statusword_bits() | 0x3690;
            assert_eq!(DriveState::from_statusword(noisy), s, "{s}");
        }
        // Typical drive values.
        assert_eq!(
            DriveState::from_statusword(0x0250),
            DriveState::SwitchOnDisabled
        );
        assert_eq!(
            DriveState::from_statusword(0x0231),
            DriveState::ReadyToSwitchOn
        );
        assert_eq!(
            DriveState::from_statusword(0x1637),
            DriveState::OperationEnabled
        );
        assert_eq!(DriveState::from_statusword(0x0218), DriveState::Fault);
    }

    #[test]
    fn controlwords_decode_back_to_their_commands() {
        for c in [
            Command::Shutdown,
            Command::SwitchOn,
            Command::EnableOperation,
            Command::DisableVoltage,
            Command::QuickStop,
        ] {
            assert_eq!(Command::decode(c.controlword(), 0), Some(c));
        }
        assert_eq!(Command::decode(0x80, 0x00), Some(Command::FaultReset));
        assert_eq!(
            Command::decode(0x80, 0x80),
            Some(Command::DisableVoltage),
            "no edge"
        );
    }

    #[test]
    fn controller_walks_to_operation_enabled() {
        let mut p = PowerController::default();
        p.request(PowerRequest::Enable);
        assert_eq!(p.step(0x0250), 0x06);
        assert_eq!(p.step(0x0231), 0x07);
        assert_eq!(p.step(0x0233), 0x0F);
        assert_eq!(p.step(0x0237), 0x0F);
        p.request(PowerRequest::QuickStop);
        assert_eq!(p.step(0x0237), 0x02);
        assert_eq!(p.step(0x0217), 0x02);
        p.request(PowerRequest::Disable);
        assert_eq!(p.step(0x0217), 0x00);
    }

    #[test]
    fn fault_reset_is_a_rising_edge() {
        let mut p = PowerController::default();
        p.request(PowerRequest::Enable);
        assert_eq!(p.step(0x0208), 0x80, "edge");
        assert_eq!(
            p.step(0x0208),
            0x00,
            "still fault: drop bit 7 to make a new edge"
        );
        assert_eq!(p.step(0x0208), 0x80);
        assert_eq!(p.step(0x0240), 0x06);
        p.request(PowerRequest::Disable);
        assert_eq!(p.step(0x0208), 0x00, "no reset unless enabling");
    }

    #[test]
    fn mode_needs_confirmation() {
        assert_eq!(Mode::CyclicSyncPosition.code(), 8);
        assert_eq!(Mode::from_code(6), Some(Mode::Homing));
        assert_eq!(Mode::from_code(1), Some(Mode::ProfilePosition));
        let mut r = ModeRequest::new(Mode::CyclicSyncPosition);
        assert!(!r.on_display(1));
        assert!(!r.is_confirmed());
        assert!(r.on_display(8));
        let e = r.not_confirmed(crate::canopen::NodeId::new(2).unwrap(), 1);
        assert_eq!(
            e.to_string(),
            "node 2: mode of operation 8 requested, drive displays 1"
        );
    }
}
