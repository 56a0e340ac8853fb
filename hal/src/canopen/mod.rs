//! A sans-IO CANopen (CiA 301) layer with the CiA 402 drive profile.
//!
//! Every codec and state machine here takes frames in, gives frames out and is told the time
//! (`now`, a [`Duration`](std::time::Duration) since any fixed epoch); nothing opens a socket or reads a clock.
//! That keeps the protocol logic unit-testable without a bus, and lets the same code run on
//! SocketCAN, on the in-memory [`SimCanBus`](crate::sim::SimCanBus) or inside a test.
//!
//! | module | job |
//! | --- | --- |
//! | [`nmt`] | NMT commands, NMT states, boot-up / heartbeat frames |
//! | [`heartbeat`] | heartbeat consumer (per node, timeout → fault naming the node) and producer |
//! | [`sync`] | SYNC producer with optional counter |
//! | [`sdo`] | SDO client and server (expedited and segmented), abort codes |
//! | [`pdo`] | PDO communication/mapping parameters, configuration as SDO writes, encode/decode |
//! | [`emcy`] | EMCY codec and consumer, CiA 301 error-code classes |
//! | [`cia402`] | CiA 402 power state machine, controlword, modes of operation |
//! | [`master`] | the cyclic CSP master: process image of N drives, TPDOs in, RPDOs + SYNC out |
//! | [`slave`] | a CiA 402 slave core (the loopback drive) with its object dictionary |
//! | [`busload`] | bus-load budget of SYNC + PDOs, and the table of what fits |
//! | [`axis`] | a CiA 402 drive behind the HAL axis traits, over a shared process image |
//! | [`owner`] | the bus owner's two servo-thread halves (rx at cycle start, tx at cycle end) |
//! | [`startup`] | NMT reset, boot-up, SDO configuration and NMT start before the servo thread |
//!
//! Order in a servo cycle and the resulting feedback delay: see [`master`] (read the
//! TPDOs that arrived since the last SYNC, run the tasks, write RPDOs, send SYNC; the tasks
//! see positions one servo period old).
//!
//! Realtime rule: the per-cycle path ([`master::CspMaster`], [`pdo::PdoMapping::encode`]/[`decode`](pdo::PdoMapping::decode),
//! [`sync::SyncProducer::next_frame`], [`heartbeat::HeartbeatConsumer::check`],
//! [`cia402::PowerController::step`], [`emcy::Emergency::decode`]) works on fixed arrays and
//! never allocates (checked by `hal/tests/canopen_no_alloc.rs`). The SDO client allocates
//! (its payloads are `Vec`s): it runs at configuration time or on a non-realtime path, never
//! in the servo step. The SDO server (the loopback drive's) reserves its value buffer once
//! and then answers without allocating (checked by the same test).
//!
//! Not yet here (issue 9): SDO block transfer (the server answers a block request with abort
//! 0x05040001, the client never starts one). The SocketCAN [`CanBus`](crate::CanBus) is
//! [`crate::socketcan`].

use crate::can::{CanFrame, CanId};
use core::fmt;

pub mod axis;
pub mod bus_health;
pub mod busload;
pub mod cia402;
pub mod eds;
pub mod emcy;
pub mod error;
pub mod heartbeat;
pub mod master;
pub mod nmt;
pub mod owner;
#[cfg(test)]
mod owner_tests;
pub mod pdo;
pub mod sdo;
pub mod slave;
pub mod startup;
pub mod sync;
#[cfg(test)]
mod tests;

pub use error::CanOpenError;

/// COB-ID of NMT commands.
pub const COB_NMT: u16 = 0x000;
/// COB-ID of SYNC.
pub const COB_SYNC: u16 = 0x080;
/// Function code of EMCY (plus node id).
pub const COB_EMCY: u16 = 0x080;
/// Function code of TPDO1 (plus node id); TPDO2..4 at +0x100 each.
pub const COB_TPDO1: u16 = 0x180;
/// Function code of RPDO1 (plus node id); RPDO2..4 at +0x100 each.
pub const COB_RPDO1: u16 = 0x200;
/// Function code of SDO server → client (plus node id).
pub const COB_SDO_TX: u16 = 0x580;
/// Function code of SDO client → server (plus node id).
pub const COB_SDO_RX: u16 = 0x600;
/// Function code of heartbeat / boot-up (plus node id).
pub const COB_HEARTBEAT: u16 = 0x700;

/// A CANopen node id, `1..=127`, checked at construction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(u8);

impl NodeId {
    /// A node id, refused outside `1..=127`.
    pub fn new(id: u8) -> Result<NodeId, CanOpenError> {
        if (1..=127).contains(&id) {
            Ok(NodeId(id))
        } else {
            Err(CanOpenError::InvalidNodeId(id))
        }
    }

    /// The numeric id.
    pub fn get(self) -> u8 {
        self.0
    }

    /// The COB-ID `function + node` as a standard CAN id.
    pub fn cob(self, function: u16) -> CanId {
        cob_id(function + u16::from(self.0))
    }

    /// The node whose COB-ID `raw` is under `function` (`function + 1 ..= function + 127`).
    pub fn from_cob(raw: u32, function: u16) -> Option<NodeId> {
        let f = u32::from(function);
        if raw > f && raw <= f + 127 {
            // Cannot truncate: 1..=127.
            Some(NodeId((raw - f) as u8))
        } else {
            None
        }
    }
}

impl fmt::Display for NodeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A standard id from a COB-ID that is known to fit 11 bits (all CANopen predefined ids do).
#[inline]
pub(crate) fn cob_id(raw: u16) -> CanId {
    CanId::standard(raw & 0x7FF).expect("an id masked to 11 bits is a standard id")
}

/// A frame with at most 8 bytes of data (longer input is cut at 8; callers never pass more).
#[inline]
pub(crate) fn frame(id: CanId, data: &[u8]) -> CanFrame {
    CanFrame::new(id, &data[..data.len().min(8)]).expect("at most 8 bytes fit a classic frame")
}

/// A fixed-capacity queue of outgoing frames: what a sans-IO state machine hands back for
/// sending, without allocating. Frames beyond the capacity are counted as overflow, never
/// silently lost.
#[derive(Debug, Clone)]
pub struct Outbox<const N: usize> {
    frames: [Option<CanFrame>; N],
    len: usize,
    overflow: u64,
}

impl<const N: usize> Default for Outbox<N> {
    fn default() -> Self {
        Outbox {
            frames: [None; N],
            len: 0,
            overflow: 0,
        }
    }
}

impl<const N: usize> Outbox<N> {
    /// Queues a frame; counts an overflow when full.
    pub fn push(&mut self, f: CanFrame) {
        if self.len < N {
            self.frames[self.len] = Some(f);
            self.len += 1;
        } else {
            self.overflow += 1;
        }
    }

    /// The queued frames, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &CanFrame> {
        self.frames[..self.len].iter().flatten()
    }

    /// Number of queued frames.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Empties the queue (keeps the overflow count).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Frames that did not fit since construction.
    pub fn overflow(&self) -> u64 {
        self.overflow
    }
}
