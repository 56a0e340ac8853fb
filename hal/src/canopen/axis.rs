//! A CiA 402 drive behind the HAL axis traits, over the bus owner's process image.
//!
//! The bus owner of an interface ([`super::owner`]) runs as two tasks on the servo thread:
//! `rx` at the start of the cycle (TPDOs, heartbeats, EMCYs into the image), `tx` at the end
//! (RPDOs from the image, then SYNC). The axis tasks run between them. They share one
//! [`DriveLink`] per drive: a block of atomics written by one side and read by the other.
//! All three run on the same thread in a fixed order, so the atomics never contend; they
//! only make the sharing `Send` without a lock, and nothing allocates.
//!
//! Homing, two ways (`[drive.canopen] homing`):
//! * on the master (the default): in CSP, method `current_position` makes the present
//!   position the home position by an offset kept here, exactly as CiA 402 methods 35/37
//!   would;
//! * in the drive ([`CanAxis::with_drive_homing`]): the drive runs its own homing method
//!   (0x6098, with speeds, acceleration and home offset written over SDO at start-up) in
//!   homing mode. The mode switch travels in the process data, not over SDO: the layout
//!   maps 0x6060 into RPDO1 and 0x6061 into TPDO1 ([`CspLayout::with_mode`](super::pdo::CspLayout::with_mode)).
//!   Why: SDO never runs on the servo thread, and switching from the non-realtime side
//!   would race with the RPDOs (which carry controlword and target every SYNC) and need the
//!   axis held by a second path; in the PDOs the switch happens at a SYNC like every other
//!   set-point, and its confirmation arrives with the statusword and position it applies
//!   to. The sequence, stepped once a cycle from [`Homing::homing_status`]: 0x6060 = 6,
//!   wait for 0x6061 = 6; controlword bit 4 (homing start); wait for statusword bit 12
//!   (homing attained) with bit 10, or bit 13 (homing error: a link fault naming the node);
//!   then the target becomes the drive's actual position and 0x6060 = 8, and the axis is
//!   homed once 0x6061 = 8. A bounded number of cycles (the timeout) covers it all.

use super::bus_health::BusFault;
use super::cia402::PowerRequest;
use super::cia402::{CW_OP_MODE_4, SW_OP_MODE_12, SW_OP_MODE_13, SW_TARGET_REACHED};
use super::NodeId;
use crate::axis::{
    AxisDrive, AxisFeedback, AxisSwitches, DriveState, FaultCode, Homing, HomingFailure,
    HomingMethod, HomingParams, HomingStatus,
};
use crate::error::{Error, ErrorKind, ErrorType};
use crate::socketcan::IfName;
use core::fmt;
use std::sync::atomic::{
    AtomicI32, AtomicI8, AtomicU16, AtomicU32, AtomicU64, AtomicU8, Ordering::Relaxed,
};
use std::sync::Arc;

/// Why the link to a drive failed (the cause a fault event names).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkCause {
    /// No heartbeat within the consumer time.
    HeartbeatLost,
    /// The drive sent an emergency message.
    Emergency,
    /// The statusword shows the CiA 402 Fault state.
    DriveFault,
    /// The drive booted again and lost its configuration.
    UnexpectedBootUp,
    /// The controller of the interface went bus-off.
    BusOff,
    /// The interface reported error frames (error-passive, no acknowledge, protocol
    /// errors, lost frames).
    ErrorFrame,
    /// The interface is down or gone.
    InterfaceDown,
    /// The interface's transmit queue was full: a frame was not sent.
    TxQueueFull,
    /// Any other failure of the interface.
    BusError,
    /// The drive reported a homing error (statusword bit 13 in homing mode).
    HomingError,
    /// Drive-side homing did not finish (or the mode switch was not confirmed) in time.
    HomingTimeout,
}

impl LinkCause {
    const ALL: [LinkCause; 11] = [
        LinkCause::HeartbeatLost,
        LinkCause::Emergency,
        LinkCause::DriveFault,
        LinkCause::UnexpectedBootUp,
        LinkCause::BusOff,
        LinkCause::ErrorFrame,
        LinkCause::InterfaceDown,
        LinkCause::TxQueueFull,
        LinkCause::BusError,
        LinkCause::HomingError,
        LinkCause::HomingTimeout,
    ];

    /// True for a fault of the interface as a whole (every drive on it has it): the
    /// message names the interface, not the node.
    pub fn is_bus(self) -> bool {
        matches!(
            self,
            LinkCause::BusOff
                | LinkCause::ErrorFrame
                | LinkCause::InterfaceDown
                | LinkCause::TxQueueFull
                | LinkCause::BusError
        )
    }

    /// The CiA 301 error code of a bus cause (0x8140 recovered from bus-off, 0x8120
    /// error-passive, 0x8110 CAN overrun, 0x8100 communication); 0 for the others.
    pub fn bus_code(self) -> u16 {
        match self {
            LinkCause::BusOff => 0x8140,
            LinkCause::ErrorFrame => 0x8120,
            LinkCause::TxQueueFull => 0x8110,
            LinkCause::InterfaceDown | LinkCause::BusError => 0x8100,
            _ => 0,
        }
    }

    /// Words for the cause.
    pub fn text(self) -> &'static str {
        match self {
            LinkCause::HeartbeatLost => "heartbeat lost",
            LinkCause::Emergency => "emergency",
            LinkCause::DriveFault => "drive fault",
            LinkCause::UnexpectedBootUp => "unexpected boot-up",
            LinkCause::BusOff => "bus-off",
            LinkCause::ErrorFrame => "error frame",
            LinkCause::InterfaceDown => "interface down",
            LinkCause::TxQueueFull => "transmit queue full",
            LinkCause::BusError => "CAN bus error",
            LinkCause::HomingError => "homing error",
            LinkCause::HomingTimeout => "homing timed out",
        }
    }

    fn index(self) -> u64 {
        LinkCause::ALL.iter().position(|c| *c == self).unwrap_or(0) as u64
    }
}

/// A fault of a CANopen drive: node, cause and the CiA 301 error code (the EMCY code, or
/// 0x8130 heartbeat, 0x8100 communication, 0x8140 bus off, 0x1000 generic).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkFault {
    /// The node.
    pub node: u8,
    /// What happened.
    pub cause: LinkCause,
    /// CiA 301 error code.
    pub code: u16,
    /// The interface the drive is on (named by bus faults), if known.
    pub iface: Option<IfName>,
}

impl LinkFault {
    /// Error code of a lost heartbeat (CiA 301: life guard or heartbeat error).
    pub const HEARTBEAT_CODE: u16 = 0x8130;
    /// Error code of a communication fault (boot-up: configuration lost).
    pub const COMMUNICATION_CODE: u16 = 0x8100;
    /// Error code of a bus-off / interface failure.
    pub const BUS_OFF_CODE: u16 = 0x8140;
    /// Error code of a failed drive-side homing (CiA 402 positioning controller class).
    pub const HOMING_CODE: u16 = 0x8600;

    fn pack(self) -> u64 {
        1 << 40 | self.cause.index() << 24 | u64::from(self.node) << 16 | u64::from(self.code)
    }

    fn unpack(v: u64) -> Option<LinkFault> {
        if v & 1 << 40 == 0 {
            return None;
        }
        Some(LinkFault {
            iface: None,
            node: (v >> 16) as u8,
            cause: LinkCause::ALL[((v >> 24) & 0xFF) as usize % LinkCause::ALL.len()],
            code: v as u16,
        })
    }
}

impl fmt::Display for LinkFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.cause.is_bus() {
            match &self.iface {
                Some(i) => write!(f, "{i}: ")?,
                None => write!(f, "CAN interface of node {}: ", self.node)?,
            }
            return write!(
                f,
                "{} (error code 0x{:04X}, {})",
                self.cause.text(),
                self.code,
                super::emcy::error_class(self.code)
            );
        }
        write!(
            f,
            "CANopen node {}: {} (error code 0x{:04X}, {})",
            self.node,
            self.cause.text(),
            self.code,
            super::emcy::error_class(self.code)
        )
    }
}

/// The process image of one drive shared by the bus owner and the axis (see the module
/// doc). Rx side: [`publish`](DriveLink::publish), [`raise`](DriveLink::raise); axis side:
/// the request, target and fault reset.
#[derive(Debug)]
pub struct DriveLink {
    node: NodeId,
    iface: Option<IfName>,
    statusword: AtomicU32,
    position: AtomicI32,
    velocity: AtomicI32,
    fresh: AtomicU32,
    fault: AtomicU64,
    request: AtomicU8,
    target: AtomicI32,
    /// Modes of operation to send (where the layout maps 0x6060).
    mode: AtomicI8,
    /// Last modes of operation display received.
    mode_display: AtomicI8,
    /// Operation-mode controlword bits (homing start) added to the power controlword.
    op_bits: AtomicU16,
}

impl DriveLink {
    /// The link of `node`, power request Disable, no data yet.
    pub fn new(node: NodeId) -> Arc<DriveLink> {
        DriveLink::on_bus(node, "")
    }

    /// The link of `node` on interface `iface` (named by bus faults; an invalid name is
    /// left out).
    pub fn on_bus(node: NodeId, iface: &str) -> Arc<DriveLink> {
        Arc::new(DriveLink {
            node,
            iface: IfName::new(iface),
            statusword: AtomicU32::new(0),
            position: AtomicI32::new(0),
            velocity: AtomicI32::new(0),
            fresh: AtomicU32::new(0),
            fault: AtomicU64::new(0),
            request: AtomicU8::new(0),
            target: AtomicI32::new(0),
            mode: AtomicI8::new(MODE_CSP),
            mode_display: AtomicI8::new(0),
            op_bits: AtomicU16::new(0),
        })
    }

    /// The node.
    pub fn node(&self) -> NodeId {
        self.node
    }

    /// Rx: a fresh TPDO image (statusword, position and velocity in counts).
    pub fn publish(&self, statusword: u16, position: i32, velocity: i32) {
        self.statusword.store(u32::from(statusword), Relaxed);
        self.position.store(position, Relaxed);
        self.velocity.store(velocity, Relaxed);
        self.fresh.fetch_add(1, Relaxed);
    }

    /// Rx: the modes of operation display of a fresh TPDO image (before [`publish`](Self::publish)).
    pub fn publish_mode(&self, display: i8) {
        self.mode_display.store(display, Relaxed);
    }

    /// Tx: modes of operation to send.
    pub fn mode(&self) -> i8 {
        self.mode.load(Relaxed)
    }

    /// Tx: operation-mode controlword bits to add.
    pub fn op_bits(&self) -> u16 {
        self.op_bits.load(Relaxed)
    }

    /// Rx: records a fault. The first cause is kept (it is what went wrong first), except
    /// that a drive fault following its own EMCY names the fault with the EMCY's code.
    pub fn raise(&self, cause: LinkCause, code: u16) {
        let new = LinkFault {
            node: self.node.get(),
            cause,
            code,
            iface: None,
        };
        let _ = self
            .fault
            .fetch_update(Relaxed, Relaxed, |old| match LinkFault::unpack(old) {
                None => Some(new.pack()),
                Some(f) if f.cause == LinkCause::Emergency && cause == LinkCause::DriveFault => {
                    Some(
                        LinkFault {
                            cause,
                            code: f.code,
                            ..f
                        }
                        .pack(),
                    )
                }
                Some(_) => None,
            });
    }

    /// The recorded fault, if any.
    pub fn fault(&self) -> Option<LinkFault> {
        LinkFault::unpack(self.fault.load(Relaxed)).map(|f| LinkFault {
            iface: self.iface,
            ..f
        })
    }

    /// Rx: a failure of the interface, on this drive's link.
    pub fn raise_bus(&self, cause: BusFault) {
        let c = cause.link_cause();
        self.raise(c, c.bus_code());
    }

    /// Last statusword received.
    pub fn statusword(&self) -> u16 {
        self.statusword.load(Relaxed) as u16
    }

    /// Tx: what the axis asks of the power state machine.
    pub fn request(&self) -> PowerRequest {
        match self.request.load(Relaxed) {
            1 => PowerRequest::Enable,
            2 => PowerRequest::QuickStop,
            3 => PowerRequest::FaultReset,
            _ => PowerRequest::Disable,
        }
    }

    fn set_request(&self, r: PowerRequest) {
        let v = match r {
            PowerRequest::Disable => 0,
            PowerRequest::Enable => 1,
            PowerRequest::QuickStop => 2,
            PowerRequest::FaultReset => 3,
        };
        self.request.store(v, Relaxed);
    }

    /// Tx: the target position, counts.
    pub fn target(&self) -> i32 {
        self.target.load(Relaxed)
    }
}

/// Why a CANopen axis refused a request or has no fresh feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CanAxisError {
    /// Enable while faulted.
    #[error("CANopen node {0}: drive is faulted, reset the fault first")]
    Faulted(u8),
    /// A target while not in Operation enabled.
    #[error("CANopen node {0}: not in operation enabled")]
    NotOperational(u8),
    /// No TPDO arrived since the last cycle.
    #[error("CANopen node {0}: no process data this cycle")]
    Stale(u8),
    /// The link failed.
    #[error("{0}")]
    Link(LinkFault),
    /// A homing method the master cannot run in CSP.
    #[error("CANopen node {0}: the master homes on the current position only; a switch search is the drive's own homing method (homing = \"drive\")")]
    HomingUnsupported(u8),
    /// A target that does not fit the drive's 32-bit position.
    #[error("CANopen node {0}: target out of the drive's position range")]
    OutOfRange(u8),
}

impl Error for CanAxisError {
    fn kind(&self) -> ErrorKind {
        match self {
            CanAxisError::Faulted(_) | CanAxisError::Link(_) => ErrorKind::DeviceFault,
            CanAxisError::NotOperational(_) => ErrorKind::NotReady,
            CanAxisError::Stale(_) => ErrorKind::Timeout,
            CanAxisError::HomingUnsupported(_) => ErrorKind::Unsupported,
            CanAxisError::OutOfRange(_) => ErrorKind::InvalidArgument,
        }
    }
}

/// Modes of operation codes used here.
const MODE_HM: i8 = 6;
const MODE_CSP: i8 = 8;

/// Where a drive-side homing run stands (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum HomePhase {
    /// No run.
    Idle,
    /// 0x6060 = 6 sent, waiting for 0x6061 = 6.
    ToHoming,
    /// Homing start sent, waiting for attained or error.
    Running,
    /// Back to CSP at the actual position, waiting for 0x6061 = 8.
    ToCsp,
}

/// A drive-side homing run: its phase, the TPDO count when the phase began, the cycles
/// it has taken and may take.
#[derive(Debug, Clone, Copy)]
struct DriveHomingRun {
    phase: HomePhase,
    mark: u32,
    cycles: u32,
    timeout_cycles: u32,
}

/// A CiA 402 drive in CSP as a HAL axis. Positions are `counts / scale + offset`.
#[derive(Debug)]
pub struct CanAxis {
    link: Arc<DriveLink>,
    scale: f64,
    offset: f64,
    homing: HomingStatus,
    seen: u32,
    missed: u32,
    max_missed: u32,
    drive_homing: Option<DriveHomingRun>,
}

impl CanAxis {
    /// The axis of `link`, `scale` counts per machine unit (non-zero, finite).
    pub fn new(link: Arc<DriveLink>, scale: f64) -> CanAxis {
        CanAxis {
            link,
            scale,
            offset: 0.0,
            homing: HomingStatus::NotHomed,
            seen: 0,
            missed: 0,
            max_missed: 0,
            drive_homing: None,
        }
    }

    /// Homes in the drive's own homing mode (the method, speeds and offset are the drive's,
    /// written at start-up), allowing `timeout_cycles` servo cycles for the whole run. The
    /// drive's layout must map 0x6060 / 0x6061 ([`CspLayout::with_mode`](super::pdo::CspLayout::with_mode)).
    pub fn with_drive_homing(mut self, timeout_cycles: u32) -> CanAxis {
        self.drive_homing = Some(DriveHomingRun {
            phase: HomePhase::Idle,
            mark: 0,
            cycles: 0,
            timeout_cycles,
        });
        self
    }

    /// True while a drive-side homing run owns the drive (targets are not sent).
    fn drive_homing_active(&self) -> bool {
        self.drive_homing
            .is_some_and(|r| r.phase != HomePhase::Idle)
    }

    /// Back to CSP holding the drive's actual position (so CSP takes over without a jump).
    fn back_to_csp(&self) {
        self.link
            .target
            .store(self.link.position.load(Relaxed), Relaxed);
        self.link.op_bits.store(0, Relaxed);
        self.link.mode.store(MODE_CSP, Relaxed);
    }

    fn fail_drive_homing(&mut self, cause: Option<LinkCause>, failure: HomingFailure) {
        if let Some(c) = cause {
            self.link.raise(c, LinkFault::HOMING_CODE);
        }
        self.back_to_csp();
        if let Some(r) = &mut self.drive_homing {
            r.phase = HomePhase::Idle;
        }
        self.homing = HomingStatus::Failed(failure);
    }

    /// One cycle of a drive-side homing run. A phase reads the drive only from the second
    /// TPDO after its request: the first may answer a SYNC sent before it (a TPDO one
    /// cycle late), the second answers a SYNC that carried the request.
    fn step_drive_homing(&mut self) {
        let Some(mut run) = self.drive_homing else {
            return;
        };
        if run.phase == HomePhase::Idle {
            return;
        }
        run.cycles = run.cycles.saturating_add(1);
        let fresh = self.link.fresh.load(Relaxed);
        let settled = fresh.wrapping_sub(run.mark) >= 2;
        let sw = self.link.statusword();
        let shown = self.link.mode_display.load(Relaxed);
        if !self.state().is_operational() {
            return self.fail_drive_homing(None, HomingFailure::DriveStopped);
        }
        match run.phase {
            HomePhase::ToHoming if settled && shown == MODE_HM => {
                self.link.op_bits.store(CW_OP_MODE_4, Relaxed);
                run.phase = HomePhase::Running;
                run.mark = fresh;
            }
            HomePhase::Running if settled && sw & SW_OP_MODE_13 != 0 => {
                return self
                    .fail_drive_homing(Some(LinkCause::HomingError), HomingFailure::LimitReached);
            }
            HomePhase::Running
                if settled
                    && sw & (SW_OP_MODE_12 | SW_TARGET_REACHED)
                        == SW_OP_MODE_12 | SW_TARGET_REACHED =>
            {
                self.back_to_csp();
                run.phase = HomePhase::ToCsp;
                run.mark = fresh;
            }
            HomePhase::ToCsp if settled && shown == MODE_CSP => {
                run.phase = HomePhase::Idle;
                self.offset = 0.0;
                self.homing = HomingStatus::Homed;
            }
            _ => {}
        }
        self.drive_homing = Some(run);
        if run.phase != HomePhase::Idle && run.cycles > run.timeout_cycles {
            self.fail_drive_homing(Some(LinkCause::HomingTimeout), HomingFailure::Aborted);
        }
    }

    /// Tolerates `n` consecutive cycles without a TPDO (the last values stand) before the
    /// feedback counts as stale: a drive on a real bus may answer a SYNC a little after the
    /// next cycle starts. A lost drive is caught by its heartbeat anyway.
    pub fn with_missed_cycles(mut self, n: u32) -> CanAxis {
        self.max_missed = n;
        self
    }

    /// Cycles since the last fresh TPDO (0 when one arrived this cycle): how much older than
    /// usual the position of [`AxisFeedback::actual_position`] is, while the last values
    /// stand in for a drive that answers SYNC late.
    pub fn feedback_age(&self) -> u32 {
        self.missed
    }

    /// The link fault of this drive, if any (the monitor names node and cause with it).
    pub fn link_fault(&self) -> Option<LinkFault> {
        self.link.fault()
    }

    fn node(&self) -> u8 {
        self.link.node.get()
    }

    fn state(&self) -> DriveState {
        DriveState::from_statusword(self.link.statusword())
    }

    fn position(&self) -> f64 {
        f64::from(self.link.position.load(Relaxed)) / self.scale + self.offset
    }
}

impl ErrorType for CanAxis {
    type Error = CanAxisError;
}

impl AxisDrive for CanAxis {
    fn enable(&mut self) -> Result<(), CanAxisError> {
        if self.state().is_fault() || self.link.fault().is_some() {
            return Err(CanAxisError::Faulted(self.node()));
        }
        self.link.set_request(PowerRequest::Enable);
        Ok(())
    }

    fn disable(&mut self) -> Result<(), CanAxisError> {
        self.link.set_request(PowerRequest::Disable);
        Ok(())
    }

    fn set_target_position(&mut self, position: f64) -> Result<(), CanAxisError> {
        if self.drive_homing_active() {
            // The drive's homing mode owns the motion; CSP resumes at its actual position.
            return Ok(());
        }
        if !self.state().is_operational() {
            return Err(CanAxisError::NotOperational(self.node()));
        }
        let counts = ((position - self.offset) * self.scale).round();
        if !(counts >= f64::from(i32::MIN) && counts <= f64::from(i32::MAX)) {
            return Err(CanAxisError::OutOfRange(self.node()));
        }
        // In range (checked above), so the cast is exact.
        self.link.target.store(counts as i32, Relaxed);
        Ok(())
    }

    fn quick_stop(&mut self) -> Result<(), CanAxisError> {
        self.link.set_request(PowerRequest::QuickStop);
        Ok(())
    }

    fn fault_reset(&mut self) -> Result<(), CanAxisError> {
        self.link.fault.store(0, Relaxed);
        if self.state().is_fault() {
            self.link.set_request(PowerRequest::FaultReset);
        }
        Ok(())
    }
}

impl AxisFeedback for CanAxis {
    /// Fails when no TPDO arrived in more than the tolerated cycles
    /// ([`CanAxis::with_missed_cycles`]): the drive task counts that as a stale cycle, and
    /// the monitor turns too many into "communication lost".
    fn actual_position(&mut self) -> Result<f64, CanAxisError> {
        let fresh = self.link.fresh.load(Relaxed);
        if fresh == self.seen {
            self.missed = self.missed.saturating_add(1);
            if self.missed > self.max_missed || fresh == 0 {
                return Err(CanAxisError::Stale(self.node()));
            }
        } else {
            self.missed = 0;
        }
        self.seen = fresh;
        Ok(self.position())
    }

    fn actual_velocity(&mut self) -> Result<f64, CanAxisError> {
        Ok(f64::from(self.link.velocity.load(Relaxed)) / self.scale)
    }

    fn drive_state(&mut self) -> Result<DriveState, CanAxisError> {
        Ok(self.state())
    }

    fn fault_code(&mut self) -> Result<Option<FaultCode>, CanAxisError> {
        Ok(match self.link.fault() {
            Some(f) => Some(FaultCode(f.code)),
            None if self.state().is_fault() => Some(FaultCode::GENERIC),
            None => None,
        })
    }

    fn switches(&mut self) -> Result<AxisSwitches, CanAxisError> {
        Ok(AxisSwitches::default())
    }
}

impl Homing for CanAxis {
    fn start_homing(&mut self, params: &HomingParams) -> Result<(), CanAxisError> {
        if let Some(run) = &mut self.drive_homing {
            // The drive homes with its own method; the configuration allows no other.
            if !DriveState::from_statusword(self.link.statusword()).is_operational() {
                self.homing = HomingStatus::Failed(HomingFailure::DriveStopped);
                return Err(CanAxisError::NotOperational(self.link.node.get()));
            }
            *run = DriveHomingRun {
                phase: HomePhase::ToHoming,
                mark: self.link.fresh.load(Relaxed),
                cycles: 0,
                timeout_cycles: run.timeout_cycles,
            };
            self.link.op_bits.store(0, Relaxed);
            self.link.mode.store(MODE_HM, Relaxed);
            self.homing = HomingStatus::InProgress;
            return Ok(());
        }
        if params.method != HomingMethod::CurrentPosition {
            self.homing = HomingStatus::Failed(HomingFailure::Aborted);
            return Err(CanAxisError::HomingUnsupported(self.node()));
        }
        if !self.state().is_operational() {
            self.homing = HomingStatus::Failed(HomingFailure::DriveStopped);
            return Err(CanAxisError::NotOperational(self.node()));
        }
        let counts = f64::from(self.link.position.load(Relaxed));
        self.offset = params.home_position - counts / self.scale;
        // Hold where the motor is, in the new coordinates.
        self.link
            .target
            .store(self.link.position.load(Relaxed), Relaxed);
        self.homing = HomingStatus::Homed;
        Ok(())
    }

    /// Also steps a drive-side homing run: the axis task asks once a cycle.
    fn homing_status(&mut self) -> Result<HomingStatus, CanAxisError> {
        self.step_drive_homing();
        Ok(self.homing)
    }

    fn abort_homing(&mut self) -> Result<(), CanAxisError> {
        if self.drive_homing_active() {
            self.fail_drive_homing(None, HomingFailure::Aborted);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis() -> (Arc<DriveLink>, CanAxis) {
        let link = DriveLink::new(NodeId::new(3).unwrap());
        (link.clone(), CanAxis::new(link, 1000.0))
    }

    #[test]
    fn fault_packs_and_keeps_the_first_cause_but_names_a_drive_fault_after_its_emcy() {
        let (link, mut a) = axis();
        link.raise(LinkCause::Emergency, 0x2310);
        link.raise(LinkCause::DriveFault, 0x1000);
        let f = a.link_fault().unwrap();
        assert_eq!(
            (f.node, f.cause, f.code),
            (3, LinkCause::DriveFault, 0x2310)
        );
        link.raise(LinkCause::HeartbeatLost, 0x8130);
        assert_eq!(a.link_fault().unwrap().cause, LinkCause::DriveFault);
        assert_eq!(a.fault_code().unwrap(), Some(FaultCode(0x2310)));
        assert!(f
            .to_string()
            .starts_with("CANopen node 3: drive fault (error code 0x2310"));
        assert!(a.enable().is_err());
        a.fault_reset().unwrap();
        assert_eq!(a.link_fault(), None);
    }

    #[test]
    fn positions_scale_feedback_is_fresh_once_and_homing_offsets() {
        let (link, mut a) = axis();
        assert_eq!(a.actual_position(), Err(CanAxisError::Stale(3)));
        link.publish(0x0237, 12_500, -2000);
        assert_eq!(a.actual_position().unwrap(), 12.5);
        assert_eq!(a.actual_position(), Err(CanAxisError::Stale(3)));
        assert_eq!(a.actual_velocity().unwrap(), -2.0);
        let mut tolerant = CanAxis::new(link.clone(), 1000.0).with_missed_cycles(2);
        assert_eq!(tolerant.actual_position().unwrap(), 12.5);
        assert_eq!(tolerant.feedback_age(), 0);
        assert_eq!(tolerant.actual_position().unwrap(), 12.5, "1 missed");
        assert_eq!(tolerant.actual_position().unwrap(), 12.5, "2 missed");
        assert_eq!(
            tolerant.feedback_age(),
            2,
            "the position is 2 cycles older than usual"
        );
        assert_eq!(tolerant.actual_position(), Err(CanAxisError::Stale(3)));
        assert_eq!(a.drive_state().unwrap(), DriveState::OperationEnabled);
        let home = HomingParams {
            method: HomingMethod::CurrentPosition,
            search_velocity: 0.0,
            latch_velocity: 0.0,
            home_position: 100.0,
        };
        a.start_homing(&home).unwrap();
        assert!(a.is_homed().unwrap());
        link.publish(0x0237, 12_500, 0);
        assert_eq!(a.actual_position().unwrap(), 100.0);
        a.set_target_position(101.0).unwrap();
        assert_eq!(link.target(), 13_500);
        let switch = HomingParams {
            method: HomingMethod::HomeSwitch,
            ..home
        };
        assert_eq!(
            a.start_homing(&switch),
            Err(CanAxisError::HomingUnsupported(3))
        );
    }

    #[test]
    fn requests_reach_the_link() {
        let (link, mut a) = axis();
        assert_eq!(link.request(), PowerRequest::Disable);
        a.enable().unwrap();
        assert_eq!(link.request(), PowerRequest::Enable);
        a.quick_stop().unwrap();
        assert_eq!(link.request(), PowerRequest::QuickStop);
        link.publish(0x0208, 0, 0);
        assert_eq!(
            a.set_target_position(1.0),
            Err(CanAxisError::NotOperational(3))
        );
        a.fault_reset().unwrap();
        assert_eq!(link.request(), PowerRequest::FaultReset);
    }
}
