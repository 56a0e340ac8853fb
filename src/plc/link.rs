//! What the machine task and the PLC task exchange (data objects, one writer each): the
//! machine's requests and state to the PLC, the PLC's answers and commands to the machine.
//! Both are fixed-size `Copy` values, so the two tasks can run on different threads without
//! a lock.

use super::M66_ANALOG_MAX;
use crate::machine::servo::{Outputs, MAX_ANALOG};

/// Data object names.
pub mod ports {
    /// [`super::PlcRequest`], written by `machine`.
    pub const REQUEST: &str = "machine.plc_request";
    /// [`super::PlcCommand`], written by `plc`.
    pub const COMMAND: &str = "plc.command";
}

/// What a G-code command asks of the PLC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RequestKind {
    /// Nothing pending.
    #[default]
    None,
    /// M6: change to `tool`.
    ToolChange,
    /// M100–M199: `mcode` with `p` and `q`.
    UserMcode,
}

/// The machine's side: the pending request, the output image G-code asked for, and the
/// machine state the PLC may bind to.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlcRequest {
    /// Incremented with every new request; the PLC answers with this number.
    pub seq: u32,
    /// What is requested (`None` once answered or abandoned).
    pub kind: RequestKind,
    /// M6's tool number.
    pub tool: u32,
    /// M100–M199's number.
    pub mcode: u32,
    /// P word.
    pub p: f64,
    /// Q word.
    pub q: f64,
    /// The outputs the machine itself drives (spindle, coolant, M62–M68), before the PLC's
    /// own outputs are merged in.
    pub outputs: Outputs,
    /// Incremented with every accepted `estop.reset`.
    pub estop_reset_seq: u32,
    /// No motion is commanded or it has settled.
    pub in_position: bool,
}

/// The PLC's side: answers, commands, and the outputs it owns.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlcCommand {
    /// The request number the PLC finished (`m6.done` / `mcode.done`).
    pub done_seq: u32,
    /// Hold feed while true (`machine.feed_hold`).
    pub feed_hold: bool,
    /// Refuse cycle start while true (`machine.start_inhibit`).
    pub start_inhibit: bool,
    /// E-stop when this rises (`machine.estop`).
    pub estop: bool,
    /// The PLC is in fault (outputs at their safe values).
    pub fault: bool,
    /// Incremented with every scan (a stalled PLC is visible).
    pub scans: u64,
    /// Digital outputs the PLC owns, bit i = channel i.
    pub digital_mask: u64,
    /// Their values.
    pub digital: u64,
    /// Analog outputs the PLC owns, bit i = channel i.
    pub analog_mask: u16,
    /// Their values.
    pub analog: [f64; MAX_ANALOG],
    /// What M66 P`i` waits on, bit i (`plc.m66_digital`).
    pub m66_digital: u64,
    /// What M66 E`i` samples (`plc.m66_analog`).
    pub m66_analog: [f64; M66_ANALOG_MAX],
}

impl PlcCommand {
    /// `machine`'s outputs with the PLC's own ones put in.
    pub fn merge(&self, mut out: Outputs) -> Outputs {
        out.digital = (out.digital & !self.digital_mask) | (self.digital & self.digital_mask);
        for (i, v) in out.analog.iter_mut().enumerate() {
            if self.analog_mask & (1 << i) != 0 {
                *v = self.analog[i];
            }
        }
        out
    }
}
