//! SDO: the confirmed, segmented access to a node's object dictionary (client 0x600 + node →
//! server, server 0x580 + node → client).
//!
//! Command byte (first data byte), CiA 301 §7.2.4.3:
//!
//! | request (client → server) | ccs | response (server → client) | scs |
//! | --- | --- | --- | --- |
//! | initiate download | 1 (`0x20`, `n` bits 3-2, `e` bit 1, `s` bit 0) | initiate download | 3 (`0x60`) |
//! | download segment | 0 (`t` bit 4, `n` bits 3-1, `c` bit 0) | download segment | 1 (`0x20`, `t` bit 4) |
//! | initiate upload | 2 (`0x40`) | initiate upload | 2 (`0x40`, `n`, `e`, `s` as above) |
//! | upload segment | 3 (`0x60`, `t` bit 4) | upload segment | 0 (`t`, `n`, `c` as above) |
//! | abort | 4 (`0x80`) + index, sub, code | abort | 4 |
//! | block download | 6 (`cc` bit 2, `s` bit 1, `cs` bit 0) | block download | 5 (`sc` bit 2, `ss` bits 1-0) |
//! | block upload | 5 (`cc` bit 2, `cs` bits 1-0) | block upload | 6 (`sc`, `s`, `ss` bit 0) |
//!
//! Block transfer (module [`block`]): sub-blocks of up to 127 numbered segments, one
//! acknowledgement per sub-block, an end frame with padding count and CRC-16.
//!
//! Expedited transfers carry up to 4 bytes in the initiate frame; larger values go in
//! 7-byte segments whose toggle bit alternates, starting at 0.

mod abort;
pub mod block;
mod client;
mod server;

pub use abort::SdoAbortCode;
pub use client::{SdoClient, SdoStep};
pub use server::{ObjectAccess, SdoServer};

use super::{frame, NodeId, COB_SDO_RX, COB_SDO_TX};
use crate::can::CanFrame;

/// Default SDO timeout (CiA 301 leaves it to the application; drives answer in a few ms).
pub const DEFAULT_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(500);

pub(crate) fn multiplexer(d: &[u8]) -> (u16, u8) {
    (u16::from_le_bytes([d[1], d[2]]), d[3])
}

/// An abort frame in direction `function` (`COB_SDO_RX` from a client, `COB_SDO_TX` from a
/// server).
pub(crate) fn abort_frame(
    node: NodeId,
    function: u16,
    index: u16,
    sub: u8,
    code: SdoAbortCode,
) -> CanFrame {
    let i = index.to_le_bytes();
    let c = code.code().to_le_bytes();
    frame(
        node.cob(function),
        &[0x80, i[0], i[1], sub, c[0], c[1], c[2], c[3]],
    )
}

/// An abort frame sent by a client to `node`'s server.
pub fn client_abort(node: NodeId, index: u16, sub: u8, code: SdoAbortCode) -> CanFrame {
    abort_frame(node, COB_SDO_RX, index, sub, code)
}

/// An 8-byte SDO frame on `node`'s channel in direction `function`.
pub(crate) fn sdo_frame(node: NodeId, function: u16, data: [u8; 8]) -> CanFrame {
    frame(node.cob(function), &data)
}

/// Initiate/segment frame layout helper: command byte, multiplexer, 4 data bytes.
pub(crate) fn initiate(cmd: u8, index: u16, sub: u8, payload: [u8; 4]) -> [u8; 8] {
    let i = index.to_le_bytes();
    [
        cmd, i[0], i[1], sub, payload[0], payload[1], payload[2], payload[3],
    ]
}

/// Server-side COB-ID function code (kept here so client and server agree).
pub(crate) const TX: u16 = COB_SDO_TX;
/// Client-side COB-ID function code.
pub(crate) const RX: u16 = COB_SDO_RX;

#[cfg(test)]
mod tests;
