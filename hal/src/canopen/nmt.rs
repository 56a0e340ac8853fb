//! NMT: network management commands (COB-ID 0x000) and the NMT states nodes report in
//! their boot-up and heartbeat messages (COB-ID 0x700 + node).

use super::{cob_id, frame, NodeId, COB_HEARTBEAT, COB_NMT};
use crate::can::CanFrame;
use core::fmt;

/// An NMT command (CiA 301 command specifiers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtCommand {
    /// Start remote node → Operational (0x01).
    Start,
    /// Stop remote node → Stopped (0x02).
    Stop,
    /// Enter pre-operational (0x80).
    EnterPreOperational,
    /// Reset node: application and communication parameters, then boot-up (0x81).
    ResetNode,
    /// Reset communication parameters, then boot-up (0x82).
    ResetCommunication,
}

impl NmtCommand {
    /// The command specifier byte.
    pub fn specifier(self) -> u8 {
        match self {
            NmtCommand::Start => 0x01,
            NmtCommand::Stop => 0x02,
            NmtCommand::EnterPreOperational => 0x80,
            NmtCommand::ResetNode => 0x81,
            NmtCommand::ResetCommunication => 0x82,
        }
    }

    /// The command for a specifier byte.
    pub fn from_specifier(cs: u8) -> Option<NmtCommand> {
        Some(match cs {
            0x01 => NmtCommand::Start,
            0x02 => NmtCommand::Stop,
            0x80 => NmtCommand::EnterPreOperational,
            0x81 => NmtCommand::ResetNode,
            0x82 => NmtCommand::ResetCommunication,
            _ => return None,
        })
    }

    /// The NMT frame addressed to `node`, or to all nodes with `None`.
    pub fn frame(self, node: Option<NodeId>) -> CanFrame {
        frame(
            cob_id(COB_NMT),
            &[self.specifier(), node.map_or(0, NodeId::get)],
        )
    }

    /// Decodes an NMT frame: the command and whether it addresses `me` (directly or as a
    /// broadcast). `None` for any other frame.
    pub fn decode_for(f: &CanFrame, me: NodeId) -> Option<NmtCommand> {
        if f.id().is_extended() || f.id().raw() != u32::from(COB_NMT) || f.data().len() != 2 {
            return None;
        }
        let cmd = NmtCommand::from_specifier(f.data()[0])?;
        let target = f.data()[1];
        (target == 0 || target == me.get()).then_some(cmd)
    }
}

/// The NMT state a node reports (heartbeat byte, bit 7 is the legacy toggle and ignored).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtState {
    /// Boot-up message (0x00): the node just finished initialisation.
    BootUp,
    /// Stopped (0x04).
    Stopped,
    /// Operational (0x05): PDOs run.
    Operational,
    /// Pre-operational (0x7F): SDO only, where configuration happens.
    PreOperational,
}

impl NmtState {
    /// The heartbeat byte.
    pub fn byte(self) -> u8 {
        match self {
            NmtState::BootUp => 0x00,
            NmtState::Stopped => 0x04,
            NmtState::Operational => 0x05,
            NmtState::PreOperational => 0x7F,
        }
    }

    /// The state of a heartbeat byte.
    pub fn from_byte(b: u8) -> Option<NmtState> {
        Some(match b & 0x7F {
            0x00 => NmtState::BootUp,
            0x04 => NmtState::Stopped,
            0x05 => NmtState::Operational,
            0x7F => NmtState::PreOperational,
            _ => return None,
        })
    }

    /// The heartbeat (or boot-up) frame of `node` in this state.
    pub fn heartbeat_frame(self, node: NodeId) -> CanFrame {
        frame(node.cob(COB_HEARTBEAT), &[self.byte()])
    }

    /// Decodes a heartbeat/boot-up frame: the sender and its state.
    pub fn decode_heartbeat(f: &CanFrame) -> Option<(NodeId, NmtState)> {
        if f.id().is_extended() || f.is_remote() || f.data().len() != 1 {
            return None;
        }
        let node = NodeId::from_cob(f.id().raw(), COB_HEARTBEAT)?;
        Some((node, NmtState::from_byte(f.data()[0])?))
    }
}

impl fmt::Display for NmtState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            NmtState::BootUp => "boot-up",
            NmtState::Stopped => "stopped",
            NmtState::Operational => "operational",
            NmtState::PreOperational => "pre-operational",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn n(id: u8) -> NodeId {
        NodeId::new(id).unwrap()
    }

    #[test]
    fn commands_encode_as_cia301() {
        let f = NmtCommand::Start.frame(Some(n(3)));
        assert_eq!(f.id().raw(), 0);
        assert_eq!(f.data(), &[0x01, 3]);
        assert_eq!(
            NmtCommand::ResetCommunication.frame(None).data(),
            &[0x82, 0]
        );
        for c in [
            NmtCommand::Start,
            NmtCommand::Stop,
            NmtCommand::EnterPreOperational,
            NmtCommand::ResetNode,
            NmtCommand::ResetCommunication,
        ] {
            assert_eq!(NmtCommand::from_specifier(c.specifier()), Some(c));
        }
        assert_eq!(NmtCommand::from_specifier(0x03), None);
    }

    #[test]
    fn decode_honours_address_and_broadcast() {
        let f = NmtCommand::Stop.frame(Some(n(3)));
        assert_eq!(NmtCommand::decode_for(&f, n(3)), Some(NmtCommand::Stop));
        assert_eq!(NmtCommand::decode_for(&f, n(4)), None);
        let all = NmtCommand::Stop.frame(None);
        assert_eq!(NmtCommand::decode_for(&all, n(4)), Some(NmtCommand::Stop));
    }

    #[test]
    fn heartbeats_round_trip_and_ignore_toggle() {
        let f = NmtState::PreOperational.heartbeat_frame(n(5));
        assert_eq!(f.id().raw(), 0x705);
        assert_eq!(
            NmtState::decode_heartbeat(&f),
            Some((n(5), NmtState::PreOperational))
        );
        let toggled = frame(cob_id(0x705), &[0x85]);
        assert_eq!(
            NmtState::decode_heartbeat(&toggled),
            Some((n(5), NmtState::Operational))
        );
        assert_eq!(
            NmtState::decode_heartbeat(&frame(cob_id(0x705), &[0x33])),
            None
        );
        assert_eq!(
            NmtState::decode_heartbeat(&frame(cob_id(0x605), &[0])),
            None
        );
        assert_eq!(NmtState::BootUp.to_string(), "boot-up");
    }
}
