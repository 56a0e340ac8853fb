//! Outputs the machine task drives: the spindle, coolant, the auxiliary commands the
//! interpolator reaches (M3-M9, M62-M66, M0/M1, tool, messages) and the input levels M66 waits on.
//! Why apart: it is the task's I/O side, separate from sequencing.

use super::{Barrier, MachineTask};
use crate::gcode::canon::{InputKind, SpindleDir};
use crate::machine::servo::input_wait::{self, InputWait};
use crate::machine::servo::{JobError, JobEvent};
use crate::motion::AuxKind;
use crate::plc::link::RequestKind;

impl MachineTask {
    /// Every output to its configured safe state, the spindle's commanded state with them
    /// (e-stop, machine off).
    pub(super) fn outputs_safe(&mut self) {
        self.outputs = self.setup.safe_outputs;
        self.spindle_dir = None;
        self.snap.spindle_rpm = 0.0;
    }

    /// What LinuxCNC's task abort does besides stopping motion (its spindle abort, and the
    /// coolant off of its I/O abort): spindle and coolant off. The other outputs a program
    /// set (M62–M68) keep their state, as they do there.
    pub(super) fn spindle_and_coolant_off(&mut self) {
        self.spindle_stop();
        self.coolant(self.setup.flood_output, self.setup.mist_output, false);
    }

    fn spindle_stop(&mut self) {
        self.spindle_dir = None;
        self.apply_spindle();
    }

    pub(super) fn apply_spindle(&mut self) {
        let Some(sp) = self.setup.spindle else {
            return;
        };
        let rpm = (self.spindle_rpm * self.snap.spindle_override).clamp(0.0, sp.max_rpm);
        self.outputs.set_do(sp.enable, self.spindle_dir.is_some());
        if let Some(d) = sp.direction {
            self.outputs.set_do(
                d,
                (self.spindle_dir == Some(SpindleDir::CounterClockwise)) != self.spindle_reversed,
            );
        }
        if let Some(s) = sp.speed {
            if s < self.outputs.analog.len() {
                self.outputs.analog[s] = if self.spindle_dir.is_some() { rpm } else { 0.0 };
            }
        }
        self.snap.spindle_rpm = match self.spindle_dir {
            Some(SpindleDir::Clockwise) => rpm,
            Some(SpindleDir::CounterClockwise) => -rpm,
            None => 0.0,
        };
    }

    /// Runs an aux item the interpolator reached. Barriers hold the interpolator until
    /// `motion.aux_done_seq` moves on.
    pub(super) fn run_aux(&mut self, kind: AuxKind, line: u32) {
        let mut done = true;
        match kind {
            AuxKind::SpindleSpeed { rpm } => {
                self.spindle_rpm = rpm;
                self.apply_spindle();
            }
            AuxKind::SpindleStart(dir) => {
                self.spindle_dir = Some(dir);
                self.apply_spindle();
                if self.setup.spindle.and_then(|s| s.at_speed).is_some() {
                    self.barrier = Barrier::SpindleAtSpeed { since: self.cycle };
                    done = false;
                }
            }
            AuxKind::SpindleStop => self.spindle_stop(),
            AuxKind::Flood(on) => self.coolant(self.setup.flood_output, self.setup.mist_output, on),
            AuxKind::Mist(on) => self.coolant(self.setup.mist_output, self.setup.flood_output, on),
            AuxKind::SelectTool(_) | AuxKind::StartToolChange => {}
            AuxKind::ChangeTool(t) if self.plc.as_ref().is_some_and(|p| p.setup.handles_m6) => {
                done = !self.plc_request(RequestKind::ToolChange, 6, t, 0.0, 0.0);
            }
            AuxKind::UserMcode { code, p, q }
                if self.plc.as_ref().is_some_and(|p| p.setup.handles_mcodes) =>
            {
                done = !self.plc_request(RequestKind::UserMcode, code, 0, p, q);
            }
            AuxKind::ChangeTool(t) | AuxKind::ChangeToolNumber(t) => self.snap.tool = t,
            AuxKind::DigitalOutput { index, on, .. } => self.outputs.set_do(index as usize, on),
            AuxKind::AnalogOutput { index, value, .. } => {
                if let Some(v) = self.outputs.analog.get_mut(index as usize) {
                    *v = value;
                }
            }
            AuxKind::Wait {
                index,
                input,
                kind,
                timeout_s,
                answer,
            } => {
                let (period, now) = (self.setup.period_s, self.input_value(index, input));
                let w = InputWait::start(
                    index, input, kind, timeout_s, period, self.cycle, now, answer, line,
                );
                self.barrier = Barrier::Wait(w);
                input_wait::publish_start(&mut self.snap.wait, &w, self.job_id);
                done = false;
            }
            AuxKind::Message { id } => self.emit_job(JobEvent::Message { id, line }),
            AuxKind::Log { id, kind } => self.emit_job(JobEvent::Log { id, kind, line }),
            AuxKind::OverrideEnable { .. }
            | AuxKind::UserMcode { .. }
            | AuxKind::SpindleSyncEnd => {}
            // The interpolator task runs the move and goes on by itself.
            AuxKind::SpindleSync { .. } => done = false,
            AuxKind::ProgramStop => {
                self.program_stop(line);
                done = false;
            }
            AuxKind::OptionalProgramStop if self.snap.optional_stop => {
                self.program_stop(line);
                done = false;
            }
            AuxKind::OptionalProgramStop => {}
            AuxKind::ProgramEnd => self.spindle_and_coolant_off(),
            AuxKind::ProbeArm { kind } => {
                let error = match self.setup.probe_input {
                    None => Some(JobError::NoProbeInput),
                    Some(_) if kind.toward() && self.motion.probe_input => {
                        Some(JobError::ProbeAlreadyTripped(kind))
                    }
                    Some(_) if !kind.toward() && !self.motion.probe_input => {
                        Some(JobError::ProbeNotTripped(kind))
                    }
                    Some(_) => None,
                };
                if let Some(error) = error {
                    self.job_error(error, line);
                    return;
                }
            }
            AuxKind::ProbeEnd { kind } => {
                let tripped = self.setpoints.probe_tripped;
                if !tripped && kind.needs_contact() {
                    self.job_error(JobError::ProbeNoContact(kind), line);
                    return;
                }
                let stopped = self.setpoints.pose_mm;
                let p = &mut self.snap.probe;
                p.seq = p.seq.wrapping_add(1);
                p.job = self.job_id;
                p.line = line;
                p.tripped = tripped;
                p.probed_mm = if tripped {
                    self.setpoints.probe_pose_mm
                } else {
                    stopped
                };
                p.stopped_mm = stopped;
                p.waiting = true;
                self.barrier = Barrier::Probe;
                done = false;
            }
        }
        if done && kind.is_barrier() {
            self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
        }
    }

    /// M7/M8 switch one coolant on; M9 (`on` false) switches both off, as LinuxCNC does.
    fn coolant(&mut self, this: Option<usize>, other: Option<usize>, on: bool) {
        if let Some(o) = this {
            self.outputs.set_do(o, on);
        }
        if let (Some(o), false) = (other, on) {
            self.outputs.set_do(o, false);
        }
    }

    /// What M66 reads on an input: 0/1 for a digital one, the reading of an analog one.
    pub(super) fn input_value(&self, index: u32, input: InputKind) -> f64 {
        // `[plc] m66_digital` / `m66_analog`: the PLC's variables.
        if let Some(v) = self.plc.as_ref().and_then(|p| p.m66_value(index, input)) {
            return v;
        }
        match input {
            InputKind::Digital => f64::from(u8::from(self.inputs.di(index as usize))),
            InputKind::Analog => self
                .inputs
                .analog
                .get(index as usize)
                .copied()
                .unwrap_or(0.0),
        }
    }
}
