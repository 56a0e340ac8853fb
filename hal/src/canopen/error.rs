//! The CANopen layer's error enum and its mapping to the HAL's [`ErrorKind`].

use super::emcy::Emergency;
use super::sdo::SdoAbortCode;
use super::NodeId;
use crate::error::{Error, ErrorKind};

/// What went wrong in the CANopen layer. Every variant names the node (and object) involved,
/// so a fault event read in a log says which drive and which cause.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CanOpenError {
    /// A node id outside `1..=127`.
    #[error("CANopen node id {0} is outside 1..=127")]
    InvalidNodeId(u8),
    /// No heartbeat from a monitored node within its consumer time.
    #[error(
        "node {node}: heartbeat lost (none for {silent_ms} ms, consumer time {timeout_ms} ms)"
    )]
    HeartbeatLost {
        /// The silent node.
        node: NodeId,
        /// Time since its last heartbeat (or since monitoring started).
        silent_ms: u64,
        /// The configured consumer time.
        timeout_ms: u64,
    },
    /// A node sent a boot-up message while it was being monitored: it reset and lost its
    /// configuration.
    #[error("node {node}: unexpected boot-up (the node reset and lost its configuration)")]
    UnexpectedBootUp {
        /// The node that rebooted.
        node: NodeId,
    },
    /// A node sent an emergency message.
    #[error("node {node}: emergency {}", .emcy)]
    Emergency {
        /// The sender.
        node: NodeId,
        /// The decoded message.
        emcy: Emergency,
    },
    /// The drive's statusword reports the CiA 402 Fault state.
    #[error("node {node}: drive fault (statusword 0x{statusword:04X})")]
    DriveFault {
        /// The drive.
        node: NodeId,
        /// Its statusword.
        statusword: u16,
    },
    /// The SDO server (or this client) aborted a transfer.
    #[error("node {node}: SDO {index:04X}:{sub:02X} aborted: {abort}")]
    SdoAbort {
        /// The server node.
        node: NodeId,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Why.
        abort: SdoAbortCode,
    },
    /// The peer did not answer an SDO request in time.
    #[error("node {node}: SDO {index:04X}:{sub:02X} timed out after {timeout_ms} ms")]
    SdoTimeout {
        /// The server node.
        node: NodeId,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The configured timeout.
        timeout_ms: u64,
    },
    /// An SDO transfer was started while another one runs on the same channel.
    #[error("node {node}: SDO channel busy with {index:04X}:{sub:02X}")]
    SdoBusy {
        /// The server node.
        node: NodeId,
        /// The transfer in progress.
        index: u16,
        /// Its sub-index.
        sub: u8,
    },
    /// A PDO mapping that cannot be built.
    #[error("PDO mapping: {0}")]
    Mapping(&'static str),
    /// A frame that does not decode as the object it was routed to.
    #[error("malformed {what} frame from COB-ID 0x{cob:03X}: {why}")]
    Malformed {
        /// The protocol object (e.g. "EMCY").
        what: &'static str,
        /// The COB-ID received.
        cob: u32,
        /// What is wrong.
        why: &'static str,
    },
    /// The drive did not confirm a requested mode of operation in 0x6061.
    #[error("node {node}: mode of operation {wanted} requested, drive displays {actual}")]
    ModeNotConfirmed {
        /// The drive.
        node: NodeId,
        /// 0x6060 written.
        wanted: i8,
        /// 0x6061 read back.
        actual: i8,
    },
}

impl Error for CanOpenError {
    fn kind(&self) -> ErrorKind {
        match self {
            CanOpenError::InvalidNodeId(_) | CanOpenError::Mapping(_) => ErrorKind::InvalidArgument,
            CanOpenError::HeartbeatLost { .. } | CanOpenError::SdoTimeout { .. } => {
                ErrorKind::Timeout
            }
            CanOpenError::UnexpectedBootUp { .. }
            | CanOpenError::Emergency { .. }
            | CanOpenError::DriveFault { .. } => ErrorKind::DeviceFault,
            CanOpenError::SdoAbort { abort, .. } => abort.kind(),
            CanOpenError::SdoBusy { .. } => ErrorKind::WouldBlock,
            CanOpenError::ModeNotConfirmed { .. } => ErrorKind::NotReady,
            CanOpenError::Malformed { .. } => ErrorKind::Other,
        }
    }
}
