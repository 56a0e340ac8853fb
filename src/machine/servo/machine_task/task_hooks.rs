//! The [`Task`] hooks of the machine task: configure its ports and events, read inputs,
//! update, accept and progress commands, and handle deferred events. Why apart: the realtime
//! runner's view of the task, calling into the sequencing and I/O parts.

use super::{Barrier, MachineCmd, MachineTask, Motion};
use crate::machine::api::Mode;
use crate::machine::mode::{Fact, Request};
use crate::machine::safety::Trip;
use crate::machine::servo::{ports, JobEvent};
use crate::motion::InterpState;
use crate::rt::prelude::*;

impl Task for MachineTask {
    type Command = MachineCmd;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.inputs_in = Some(ctx.input(ports::INPUTS));
        self.setpoints_in = Some(ctx.input(ports::SETPOINTS));
        self.monitor_in = Some(ctx.input(ports::MONITOR));
        self.feedback_in = self
            .setup
            .axes
            .iter()
            .map(|&(name, _)| ctx.input(&ports::feedback(name)))
            .collect();
        self.outputs_out = Some(ctx.output(ports::OUTPUTS));
        self.drive_out = Some(ctx.output(ports::DRIVE_CONTROL));
        self.motion_out = Some(ctx.output(ports::MOTION_CONTROL));
        self.snapshot_out = Some(ctx.output(ports::SNAPSHOT));
        self.faults_in = Some(ctx.subscribe("monitor.fault", 64));
        self.overruns_in = Some(ctx.subscribe(&self.setup.overrun_event, 16));
        self.mode_ev = Some(ctx.event("mode"));
        self.fault_ev = Some(ctx.event("fault"));
        self.job_ev = Some(ctx.event("job"));
        if let Some(p) = &mut self.plc {
            p.configure(ctx);
        }
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        if let Some(r) = &mut self.inputs_in {
            r.get(&mut self.inputs);
        }
        if let Some(r) = &mut self.setpoints_in {
            r.get(&mut self.setpoints);
        }
        for (k, r) in self.feedback_in.iter_mut().enumerate() {
            if let Some(&(_, i)) = self.setup.axes.get(k) {
                r.get(&mut self.feedback[i]);
            }
        }
        if let Some(r) = &mut self.monitor_in {
            r.get(&mut self.monitor);
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.cycle = ctx.cycle;
        // 1. E-stop: pressed, or unreadable for too long.
        let stale = self.inputs.stale_cycles > self.setup.max_stale_io_cycles;
        let pressed = self.inputs.di(self.setup.estop_input) || stale;
        if pressed && self.mode.mode() != Mode::Estop {
            self.enter_estop(if stale {
                Trip::CommunicationLost { axis: usize::MAX }
            } else {
                Trip::Estop
            });
        }
        self.mode.set_estop_input(pressed);
        let requests = self.estop_request.as_ref().map_or(self.estop_seen, |r| {
            r.load(std::sync::atomic::Ordering::Acquire)
        });
        if requests != self.estop_seen {
            self.estop_seen = requests;
            if self.mode.mode() != Mode::Estop {
                self.enter_estop(Trip::Estop);
            }
        }
        self.poll_plc();
        self.motion.probe_input = self.setup.probe_input.is_some_and(|i| self.inputs.di(i));
        if self.mode.mode() == Mode::Estop {
            // The quick stop is requested until the drives are off.
            self.drive.quick_stop = self
                .setup
                .axes
                .iter()
                .any(|&(_, i)| self.feedback[i].state.is_operational());
        }
        // 2. Aux items reached by the interpolator (one per cycle at most).
        if self.setpoints.aux_seq != self.last_aux_seq {
            self.last_aux_seq = self.setpoints.aux_seq;
            if let Some(aux) = self.setpoints.aux {
                if self.current != Motion::None && self.stopping.is_none() {
                    self.run_aux(aux.kind, aux.line);
                }
            }
        }
        self.poll_step();
        self.poll_barrier();
        self.poll_homing();
        self.poll_motion();
        self.poll_stop();
        Ok(())
    }

    fn accept(&mut self, c: &MachineCmd, ctx: &StepContext) -> Result<(), RejectReason> {
        let homed = self.all_homed();
        let reject = RejectReason::Other;
        match *c {
            MachineCmd::Estop => {
                self.mode.request(Request::Estop, homed).map_err(reject)?;
                self.enter_estop(Trip::Estop);
            }
            MachineCmd::EstopReset => {
                self.mode
                    .request(Request::EstopReset, homed)
                    .map_err(reject)?;
                self.drive.quick_stop = false;
                self.drive.fault_reset_seq = self.drive.fault_reset_seq.wrapping_add(1);
                if let Some(p) = &mut self.plc {
                    p.estop_reset();
                }
            }
            MachineCmd::On => {
                self.mode.request(Request::On, homed).map_err(reject)?;
                self.drive.fault_reset_seq = self.drive.fault_reset_seq.wrapping_add(1);
                self.drive.enable = true;
                self.drive.quick_stop = false;
                self.motion.track_actual = true;
                self.enable_since = ctx.cycle;
            }
            MachineCmd::Off => {
                let moving = self.current != Motion::None || self.homing_group.is_some();
                self.mode.request(Request::Off, homed).map_err(reject)?;
                self.outputs_safe();
                if moving {
                    let line = self.setpoints.line;
                    self.current = Motion::None;
                    self.controlled_stop(true, Some(JobEvent::Aborted { line }));
                    self.drive.home_abort_seq = self.drive.home_abort_seq.wrapping_add(1);
                } else {
                    self.drive.enable = false;
                }
            }
            MachineCmd::Home { mask } => {
                let mask = if mask == 0 { self.axes_mask() } else { mask };
                if mask & !self.axes_mask() != 0 {
                    return Err(RejectReason::BadParameters("no such axis"));
                }
                self.mode.request(Request::Home, homed).map_err(reject)?;
                self.homing_mask = mask;
                self.motion.track_actual = true;
                self.start_homing_group(0);
            }
            MachineCmd::Run { job, items, manual } => {
                let req = if manual { Request::Jog } else { Request::Run };
                if !manual {
                    self.refuse_if_plc_inhibits()?;
                }
                // Jogging is allowed before homing (that is how a machine is brought home by
                // hand); soft limits apply only to homed axes, checked by the planner.
                self.mode.request(req, homed || manual).map_err(reject)?;
                self.current = Motion::Job { job, items };
                self.job_id = job;
                self.ended = None;
                self.motion.job = job;
                self.motion.track_actual = false;
                self.motion.hold = false;
                self.emit_job(JobEvent::Started);
            }
            MachineCmd::Pause => {
                let running = self.mode.mode() == Mode::Running;
                self.mode.request(Request::Pause, homed).map_err(reject)?;
                self.motion.hold = true;
                // The job holds too (`job.state` "holding" until `Resumed`), as on an M0.
                if running {
                    let line = self.setpoints.line;
                    self.emit_job(JobEvent::Held { line });
                }
            }
            MachineCmd::Step => {
                // At a program stop the stop's own line is done: the step runs the next one.
                let at_stop = self.barrier == Barrier::ProgramStop;
                match self.mode.mode() {
                    Mode::Holding => self.resume_job(homed)?,
                    Mode::Running => {}
                    _ => return Err(RejectReason::Other("no job is running")),
                }
                self.step_skip = if at_stop { self.setpoints.line } else { 0 };
                self.step_from = Some(if at_stop { 0 } else { self.setpoints.line });
            }
            MachineCmd::Resume => {
                self.refuse_if_plc_inhibits()?;
                self.resume_job(homed)?;
                self.step_from = None;
            }
            MachineCmd::Abort => {
                let jog = self.mode.mode() == Mode::Manual;
                self.mode.request(Request::Abort, homed).map_err(reject)?;
                self.step_from = None;
                // A jog's stop is an abort too here, but stopping a jog leaves the spindle
                // and coolant alone (in LinuxCNC it is a jog stop, not a task abort).
                if !jog {
                    self.spindle_and_coolant_off();
                }
                let line = self.setpoints.line;
                if self.homing_group.is_some() {
                    self.drive.home_abort_seq = self.drive.home_abort_seq.wrapping_add(1);
                    self.homing_group = None;
                    self.mode.fact(Fact::HomingDone);
                } else {
                    self.current = Motion::None;
                    self.controlled_stop(false, Some(JobEvent::Aborted { line }));
                }
            }
            MachineCmd::Continue { job, items } => {
                let waiting = self.barrier == Barrier::Probe && self.snap.probe.job == job;
                let Motion::Job {
                    job: current,
                    items: total,
                } = self.current
                else {
                    return Err(RejectReason::Other("no job is running"));
                };
                if current != job || !waiting {
                    return Err(RejectReason::Other("the job is not waiting after a probe"));
                }
                self.current = Motion::Job {
                    job,
                    items: total + items,
                };
                self.barrier = Barrier::None;
                self.snap.probe.waiting = false;
                self.motion.aux_done_seq = self.motion.aux_done_seq.wrapping_add(1);
            }
            MachineCmd::OptionalStop { on } => self.snap.optional_stop = on,
            MachineCmd::Overrides {
                feed,
                rapid,
                spindle,
            } => {
                let ok = |v: f64, max: f64| v.is_finite() && (0.0..=max).contains(&v);
                if !ok(feed, self.setup.max_feed_override) || !ok(rapid, 1.0) || !ok(spindle, 2.0) {
                    return Err(RejectReason::BadParameters("override out of range"));
                }
                self.motion.feed_override = feed;
                self.motion.rapid_override = rapid;
                self.snap.spindle_override = spindle;
                self.apply_spindle();
            }
        }
        Ok(())
    }

    fn progress(&mut self, c: &MachineCmd, ctx: &StepContext) -> Progress {
        let mode = self.mode.mode();
        match *c {
            MachineCmd::On => {
                if mode != Mode::Idle {
                    return Progress::Failed("the machine left the idle mode while enabling");
                }
                let all_on = self
                    .setup
                    .axes
                    .iter()
                    .all(|&(_, i)| self.feedback[i].state.is_operational());
                if all_on {
                    Progress::Done
                } else if ctx.cycle - self.enable_since
                    > u64::from(self.setup.enable_timeout_cycles)
                {
                    self.drive.enable = false;
                    self.mode.fact(Fact::Faulted);
                    Progress::Failed("a drive did not reach operation enabled")
                } else {
                    Progress::Running
                }
            }
            MachineCmd::Off => {
                if self.stopping.is_some()
                    || self
                        .setup
                        .axes
                        .iter()
                        .any(|&(_, i)| self.feedback[i].state.is_operational())
                {
                    Progress::Running
                } else {
                    Progress::Done
                }
            }
            MachineCmd::Home { .. } => match mode {
                Mode::Homing => Progress::Running,
                Mode::Idle if self.homed_mask() & self.homing_mask == self.homing_mask => {
                    Progress::Done
                }
                Mode::Idle => Progress::Failed("homing was aborted"),
                _ => Progress::Failed("homing stopped by a fault or e-stop"),
            },
            MachineCmd::Run { job, .. } => match self.ended {
                Some((j, JobEvent::Finished { .. })) if j == job => Progress::Done,
                Some((j, JobEvent::Aborted { .. })) if j == job => Progress::Failed("aborted"),
                Some((j, JobEvent::Failed { .. })) if j == job => {
                    Progress::Failed("stopped by a fault or e-stop")
                }
                Some((j, JobEvent::Error { .. })) if j == job => {
                    Progress::Failed("stopped by a program error")
                }
                _ => Progress::Running,
            },
            // Done once nothing moves: held on the path, or standing at a barrier (M0, M66,
            // spindle at speed), where the interpolator waits and never reports `Holding`.
            // A pause that stayed active there kept one of the task's few command slots;
            // enough of them and the task took no command at all, e-stop included.
            MachineCmd::Pause => {
                if mode != Mode::Holding
                    || matches!(
                        self.setpoints.state,
                        InterpState::Holding
                            | InterpState::Waiting
                            | InterpState::Done
                            | InterpState::Idle
                    )
                {
                    Progress::Done
                } else {
                    Progress::Running
                }
            }
            MachineCmd::Abort => {
                if self.stopping.is_some() {
                    Progress::Running
                } else {
                    Progress::Done
                }
            }
            MachineCmd::Estop
            | MachineCmd::EstopReset
            | MachineCmd::Resume
            | MachineCmd::Continue { .. }
            | MachineCmd::Step
            | MachineCmd::OptionalStop { .. }
            | MachineCmd::Overrides { .. } => Progress::Done,
        }
    }

    fn process_events(&mut self, _ctx: &StepContext) {
        while let Some(f) = self.faults_in.as_mut().and_then(EventReceiver::pop) {
            self.on_trip(f.trip, f.line);
        }
        while let Some(o) = self.overruns_in.as_mut().and_then(EventReceiver::pop) {
            let line = self.setpoints.line;
            self.on_trip(
                Trip::OverrunStorm {
                    consecutive: o.consecutive as u32,
                },
                line,
            );
        }
        self.publish();
    }
}
