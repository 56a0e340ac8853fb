//! The PLC's part of the machine task: requests that M6 and M100-M199 wait on, and the PLC's
//! feed hold, start inhibit, e-stop and fault acting on the machine (the link itself is in
//! `plc_link`).

use super::{Barrier, MachineTask};
use crate::machine::api::Mode;
use crate::machine::mode::Request;
use crate::machine::safety::Trip;
use crate::machine::servo::plc_link::{PlcLink, PlcLinkSetup};
use crate::machine::servo::{JobError, JobEvent};
use crate::plc::link::RequestKind;
use crate::rt::prelude::*;

/// The PLC's part of the machine task (the link itself is in `plc_link`).
impl MachineTask {
    /// Links the machine task to a PLC task (`[plc]`): M6 and M100–M199 wait for it as
    /// configured, its feed hold, start inhibit, e-stop and fault act on the machine.
    pub fn with_plc(mut self, setup: PlcLinkSetup) -> Self {
        self.plc = Some(PlcLink::new(setup));
        self
    }

    /// Posts a request to the PLC and holds the interpolator at a barrier until it answers.
    /// Returns false when there is no PLC to ask.
    pub(super) fn plc_request(
        &mut self,
        kind: RequestKind,
        mcode: u32,
        tool: u32,
        p: f64,
        q: f64,
    ) -> bool {
        let Some(link) = &mut self.plc else {
            return false;
        };
        let seq = link.post(kind, tool, mcode, p, q);
        let timeout = if kind == RequestKind::ToolChange {
            link.setup.tool_change_timeout_cycles
        } else {
            link.setup.mcode_timeout_cycles
        };
        self.barrier = Barrier::Plc {
            seq,
            mcode,
            tool,
            deadline: self.cycle + timeout,
        };
        true
    }

    /// Releases the PLC barrier when the PLC answered; a timeout ends the job with its line.
    pub(super) fn poll_plc_barrier(&mut self) {
        let Barrier::Plc {
            seq,
            mcode,
            tool,
            deadline,
        } = self.barrier
        else {
            return;
        };
        let Some(link) = &mut self.plc else {
            return;
        };
        if link.done(seq) {
            link.withdraw();
            if mcode == 6 {
                self.snap.tool = tool;
            }
            self.barrier = Barrier::None;
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        } else if self.cycle >= deadline {
            link.withdraw();
            self.barrier = Barrier::None;
            let line = self.setpoints.line;
            self.job_error(JobError::PlcTimeout { mcode }, line);
        }
    }

    /// Acts on what the PLC asks: e-stop on its rising e-stop output, a controlled stop on
    /// its fault (when safety relevant), a feed hold while it holds feed.
    pub(super) fn poll_plc(&mut self) {
        let Some(link) = &mut self.plc else {
            return;
        };
        let d = link.read();
        if d.estop && self.mode.mode() != Mode::Estop {
            self.enter_estop(Trip::Estop);
        }
        if d.fault {
            let line = self.setpoints.line;
            self.on_trip(Trip::PlcFault, line);
        }
        if d.feed_hold
            && self.mode.mode() == Mode::Running
            && self.mode.request(Request::Pause, true).is_ok()
        {
            self.motion.hold = true;
            let line = self.setpoints.line;
            self.emit_job(JobEvent::Held { line });
        }
    }

    /// Cycle start and resume are refused while the PLC inhibits them (e.g. guard door).
    pub(super) fn refuse_if_plc_inhibits(&self) -> Result<(), RejectReason> {
        match &self.plc {
            Some(p) if p.start_inhibited() => Err(RejectReason::Other(
                "the PLC inhibits cycle start (machine.start_inhibit)",
            )),
            _ => Ok(()),
        }
    }
}
