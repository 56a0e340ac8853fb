//! The machine task's side of the PLC (issue 11): requests to the PLC for the G-code
//! commands it handles (M6, M100–M199), their timeouts, and the PLC's commands to the
//! machine (feed hold, start inhibit, e-stop, its fault). Without `[plc]` the machine task
//! has no link and behaves exactly as before.

use super::Outputs;
use crate::gcode::canon::InputKind;
use crate::plc::link::{ports, PlcCommand, PlcRequest, RequestKind};
use crate::rt::prelude::*;

/// From `[plc]`, for the machine task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlcLinkSetup {
    /// M6 waits for the PLC's `m6.done` (an `m6.done` output is bound).
    pub handles_m6: bool,
    /// M100–M199 wait for `mcode.done` (an `mcode.done` output is bound).
    pub handles_mcodes: bool,
    /// Servo cycles an M6 may wait.
    pub tool_change_timeout_cycles: u64,
    /// Servo cycles an M100–M199 may wait.
    pub mcode_timeout_cycles: u64,
    /// A PLC fault stops the machine.
    pub safety_relevant: bool,
    /// M66 P0..P(n-1) wait on PLC variables (`plc.m66_digital`), not on physical inputs.
    pub m66_digital: usize,
    /// M66 E0..E(n-1) sample PLC variables (`plc.m66_analog`).
    pub m66_analog: usize,
}

/// The link: the request written to the PLC, the last command read from it.
pub struct PlcLink {
    /// Setup.
    pub setup: PlcLinkSetup,
    /// What is published to the PLC.
    pub request: PlcRequest,
    /// What the PLC published last.
    pub cmd: PlcCommand,
    last_estop: bool,
    fault_seen: bool,
    request_out: Option<DataWriter<PlcRequest>>,
    command_in: Option<DataReader<PlcCommand>>,
}

/// What the PLC asks of the machine this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PlcDemands {
    /// The PLC's e-stop output rose.
    pub estop: bool,
    /// The PLC went into fault this cycle (and it is safety relevant).
    pub fault: bool,
    /// Hold feed.
    pub feed_hold: bool,
}

impl PlcLink {
    /// A link for `setup`.
    pub fn new(setup: PlcLinkSetup) -> Self {
        PlcLink {
            setup,
            request: PlcRequest::default(),
            cmd: PlcCommand::default(),
            last_estop: false,
            fault_seen: false,
            request_out: None,
            command_in: None,
        }
    }

    /// Declares the ports.
    pub fn configure(&mut self, ctx: &mut Configure<'_>) {
        self.request_out = Some(ctx.output(ports::REQUEST));
        self.command_in = Some(ctx.input(ports::COMMAND));
    }

    /// Reads the PLC's command; returns what the machine must act on.
    pub fn read(&mut self) -> PlcDemands {
        if let Some(r) = &mut self.command_in {
            r.get(&mut self.cmd);
        }
        let estop = self.cmd.estop && !self.last_estop;
        self.last_estop = self.cmd.estop;
        let fault = self.cmd.fault && !self.fault_seen && self.setup.safety_relevant;
        self.fault_seen = self.cmd.fault;
        PlcDemands {
            estop,
            fault,
            feed_hold: self.cmd.feed_hold,
        }
    }

    /// What M66 reads on input `index` when the PLC provides it (`None`: a physical input):
    /// 0 or 1 for a digital one, the variable's value for an analog one.
    pub fn m66_value(&self, index: u32, input: InputKind) -> Option<f64> {
        let i = index as usize;
        match input {
            InputKind::Digital if i < self.setup.m66_digital => {
                Some(f64::from(u8::from(self.cmd.m66_digital & (1 << i) != 0)))
            }
            InputKind::Analog if i < self.setup.m66_analog => self.cmd.m66_analog.get(i).copied(),
            _ => None,
        }
    }

    /// The PLC refuses cycle start.
    pub fn start_inhibited(&self) -> bool {
        self.cmd.start_inhibit
    }

    /// Posts a request; returns its number.
    pub fn post(&mut self, kind: RequestKind, tool: u32, mcode: u32, p: f64, q: f64) -> u32 {
        let r = &mut self.request;
        r.seq = r.seq.wrapping_add(1);
        r.kind = kind;
        r.tool = tool;
        r.mcode = mcode;
        r.p = p;
        r.q = q;
        r.seq
    }

    /// The request `seq` is done.
    pub fn done(&self, seq: u32) -> bool {
        self.cmd.done_seq == seq
    }

    /// Withdraws the pending request (done, timed out, or the job ended).
    pub fn withdraw(&mut self) {
        self.request.kind = RequestKind::None;
    }

    /// An `estop.reset` was accepted.
    pub fn estop_reset(&mut self) {
        self.request.estop_reset_seq = self.request.estop_reset_seq.wrapping_add(1);
    }

    /// Publishes the request with the machine's own outputs and returns the outputs with
    /// the PLC's merged in.
    pub fn publish(&mut self, own: Outputs, in_position: bool) -> Outputs {
        self.request.outputs = own;
        self.request.in_position = in_position;
        if let Some(w) = &mut self.request_out {
            w.set(self.request);
        }
        self.cmd.merge(own)
    }
}
