//! What the machine task advances every cycle: the current barrier, program stop and single
//! step, homing group by group, stops and motion ends, and publishing its outputs last. Why apart:
//! these run in order each step and are the task's sequencing, not its command handling.

use super::{Barrier, MachineTask, Motion};
use crate::gcode::canon::WaitKind;
use crate::gcode::NUM_AXES;
use crate::machine::api::Mode;
use crate::machine::mode::{Fact, Request};
use crate::machine::safety::Trip;
use crate::machine::servo::{JobEvent, ModeEvent};
use crate::motion::InterpState;
use crate::rt::prelude::*;

impl MachineTask {
    /// Progress of the current barrier; releases the interpolator when it is met.
    pub(super) fn poll_barrier(&mut self) {
        let met = match self.barrier {
            Barrier::None | Barrier::ProgramStop | Barrier::Probe => false,
            Barrier::Plc { .. } => {
                self.poll_plc_barrier();
                return;
            }
            Barrier::SpindleAtSpeed { since } => {
                let at = self
                    .setup
                    .spindle
                    .and_then(|s| s.at_speed)
                    .is_none_or(|i| self.inputs.di(i));
                if !at && self.cycle - since > u64::from(self.setup.spindle_timeout_cycles) {
                    let line = self.setpoints.line;
                    self.on_trip(Trip::SpindleNotAtSpeed, line);
                    return;
                }
                at
            }
            Barrier::Wait {
                index,
                input,
                kind,
                deadline,
                last,
            } => {
                let now = self.input_level(index, input);
                let ok = match kind {
                    WaitKind::Immediate => true,
                    WaitKind::Rise => now && !last,
                    WaitKind::Fall => !now && last,
                    WaitKind::High => now,
                    WaitKind::Low => !now,
                };
                if let Barrier::Wait { last, .. } = &mut self.barrier {
                    *last = now;
                }
                // LinuxCNC semantics: a timeout is not an error, the program goes on.
                ok || self.cycle >= deadline
            }
        };
        if met {
            self.barrier = Barrier::None;
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        }
    }

    /// M0, M60 (and M1 with optional stop on): the interpolator waits at the barrier and the
    /// machine holds (mode and job "holding") until `resume` or `step` goes on with the next
    /// line, as LinuxCNC's pause and cycle start do.
    pub(super) fn program_stop(&mut self, line: u32) {
        self.barrier = Barrier::ProgramStop;
        self.mode.fact(Fact::ProgramStop);
        self.emit_job(JobEvent::Held { line });
    }

    /// Leaves a feed hold or an M0 stop.
    pub(super) fn resume_job(&mut self, homed: bool) -> Result<(), RejectReason> {
        self.mode
            .request(Request::Resume, homed)
            .map_err(RejectReason::Other)?;
        self.motion.hold = false;
        if self.barrier == Barrier::ProgramStop {
            self.barrier = Barrier::None;
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        }
        self.emit_job(JobEvent::Resumed);
        Ok(())
    }

    /// Single block: hold in the cycle a new source line starts executing.
    pub(super) fn poll_step(&mut self) {
        let Some(from) = self.step_from else {
            return;
        };
        if self.mode.mode() != Mode::Running {
            if self.current == Motion::None {
                self.step_from = None;
            }
            return;
        }
        let line = self.setpoints.line;
        if from == 0 {
            let begun = line != 0 && line != self.step_skip;
            self.step_from = Some(if begun { line } else { 0 });
        } else if line != 0 && line != from {
            self.step_from = None;
            if self.mode.request(Request::Pause, true).is_ok() {
                self.motion.hold = true;
                self.emit_job(JobEvent::Held { line });
            }
        }
    }

    pub(super) fn poll_homing(&mut self) {
        let Some(g) = self.homing_group else {
            return;
        };
        let group = self.setup.homing_groups.get(g).copied().unwrap_or(0) & self.homing_mask;
        let mut all = true;
        for k in 0..self.setup.axes.len() {
            let i = self.setup.axes[k].1;
            if group & (1 << i) == 0 {
                continue;
            }
            let fb = self.feedback[i];
            if fb.homing_failed {
                self.homing_group = None;
                self.on_trip(Trip::HomingFailed { axis: i }, 0);
                return;
            }
            all &= fb.homed && !fb.homing;
        }
        if all {
            self.start_homing_group(g + 1);
        }
    }

    pub(super) fn start_homing_group(&mut self, g: usize) {
        let Some(&group) = self.setup.homing_groups.get(g) else {
            self.homing_group = None;
            self.mode.fact(Fact::HomingDone);
            return;
        };
        self.homing_group = Some(g);
        let group = group & self.homing_mask;
        for i in 0..NUM_AXES {
            if group & (1 << i) != 0 {
                self.drive.home_seq[i] = self.drive.home_seq[i].wrapping_add(1);
            }
        }
        if group == 0 {
            self.start_homing_group(g + 1);
        }
    }

    pub(super) fn poll_stop(&mut self) {
        let Some(s) = self.stopping else {
            return;
        };
        if !self.stopped(s.abort_seq) {
            return;
        }
        self.stopping = None;
        self.motion.track_actual = true;
        self.motion.hold = false;
        if s.disable {
            self.drive.enable = false;
        }
        if let Some(e) = s.end {
            self.emit_job(e);
        }
        if matches!(
            self.mode.mode(),
            Mode::Running | Mode::Holding | Mode::Manual
        ) {
            self.mode.fact(Fact::MotionDone);
        }
        self.current = Motion::None;
    }

    pub(super) fn poll_motion(&mut self) {
        let Motion::Job { job, items } = self.current else {
            return;
        };
        if self.stopping.is_some() {
            return;
        }
        let path_done = self.setpoints.job == job
            && self.setpoints.items_consumed >= items
            && matches!(self.setpoints.state, InterpState::Done | InterpState::Idle)
            && self.barrier == Barrier::None;
        if !path_done {
            self.settle_since = None;
            return;
        }
        // In position: every axis within the window, or the drives had their settling time.
        let since = *self.settle_since.get_or_insert(self.cycle);
        let in_position =
            self.setup.axes.iter().all(|&(_, i)| {
                self.monitor.following_error[i].abs() <= self.setup.in_position_window
            });
        if in_position || self.cycle - since >= u64::from(self.setup.settle_timeout_cycles) {
            self.current = Motion::None;
            self.motion.track_actual = true;
            self.mode.fact(Fact::MotionDone);
            let line = self.setpoints.line;
            self.emit_job(JobEvent::Finished { line });
        }
    }
}

impl MachineTask {
    /// Publishes the outputs of this step. Called last in the step (after the command
    /// processor and the deferred handlers), so a command accepted in this cycle is visible
    /// to the tasks after this one in this cycle, and to status readers, at once.
    pub(super) fn publish(&mut self) {
        self.snap.homed_mask = self.homed_mask();
        self.snap.mode = self.mode.mode();
        self.snap.feed_override = self.motion.feed_override;
        self.snap.rapid_override = self.motion.rapid_override;
        if self.snap.mode != self.last_mode {
            self.last_mode = self.snap.mode;
            if let Some(ev) = &mut self.mode_ev {
                ev.emit(ModeEvent {
                    mode: self.snap.mode,
                });
            }
        }
        let outputs = match &mut self.plc {
            Some(p) => {
                if !matches!(self.barrier, Barrier::Plc { .. }) {
                    p.withdraw();
                }
                p.publish(self.outputs, self.current == Motion::None)
            }
            None => self.outputs,
        };
        if let Some(w) = &mut self.outputs_out {
            w.set(outputs);
        }
        if let Some(w) = &mut self.drive_out {
            w.set(self.drive);
        }
        if let Some(w) = &mut self.motion_out {
            w.set(self.motion);
        }
        if let Some(w) = &mut self.snapshot_out {
            w.set(self.snap);
        }
    }
}
