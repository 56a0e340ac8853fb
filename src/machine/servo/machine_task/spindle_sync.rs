//! The machine task's side of spindle-synchronised moves (G33, G76, G33.1), which the
//! interpolator task runs ([`crate::machine::servo::spindle_follow`]): it hands over the
//! commanded spindle speed the simulated spindle follows, reverses the spindle direction
//! output while a rigid tap comes out, and ends the job when a move could not follow the
//! spindle. Why apart: one concern, a few lines of the task's cycle.

use super::{MachineTask, Motion};
use crate::machine::servo::JobError;

impl MachineTask {
    /// Once per cycle, before the aux items.
    pub(super) fn poll_spindle_sync(&mut self) {
        self.motion.spindle_rpm = self.snap.spindle_rpm;
        if self.setpoints.spindle_reversed != self.spindle_reversed {
            self.spindle_reversed = self.setpoints.spindle_reversed;
            self.apply_spindle();
        }
        if let Some(e) = self.sync_errors.take(&self.setpoints) {
            if self.current != Motion::None && self.stopping.is_none() {
                self.job_error(JobError::SpindleSync(e), self.setpoints.line);
            }
        }
    }
}
