//! A watched remote peer lost (`[[remote]]`, `bridge::watch`): the loss is reported like a
//! fault, and a critical peer stops the machine under control. Runs on a Zenoh thread,
//! never on the servo thread; it meets the machine task only through its command queue.

use super::{lock, Machine, ACCEPT_TIMEOUT};
use crate::machine::servo::machine_task::MachineCmd;
use serde_json::json;

impl Machine {
    /// Pushes `message` on the `fault` topic, and when `critical` aborts what runs with a
    /// controlled stop: a running job ends failed with `message` as its reason (as a failed
    /// run-ahead does). The machine stays on: the status' fault list is for trips.
    pub(super) fn stop_for_lost_remote(&self, message: &str, critical: bool) {
        tracing::error!("{message}");
        self.publish(
            "fault",
            json!({ "message": message, "critical": critical, "source": "remote" }),
        );
        if !critical {
            return;
        }
        if let Some(a) = lock(&self.book).active.as_mut() {
            a.error = Some(format!("critical {message}"));
        }
        // Nothing may be moving (idle): the machine task refuses the abort then, which is
        // fine; otherwise it decelerates every axis under control.
        if let Ok(h) = self.machine.send(MachineCmd::Abort) {
            let _ = h.wait_accepted(ACCEPT_TIMEOUT);
        }
    }
}
