//! The `interpolator` task: wraps [`motion::Interpolator`](crate::motion::Interpolator) on
//! the servo thread.
//!
//! While the machine task asks it to *track* (no motion commanded: idle, homing, e-stop,
//! off, fault), the commanded position follows the actual position, so that enabling the
//! drives or starting a job never makes a jump. Otherwise it steps the interpolator on the
//! segment queue of the current job: queue items stamped with an older job id (leftovers of
//! an aborted job) are discarded, at most [`MAX_DISCARD_PER_CYCLE`] per cycle.

use super::spindle_follow::{SpindleFollower, StartOutcome};
use super::{ports, AxisFeedback, MotionControl, QueueItem, Setpoints};
use crate::gcode::NUM_AXES;
use crate::machine::sim_spindle::SimSpindleParams;
use crate::motion::kinematics::{Kinematics, Machine};
use crate::motion::spindle_lock::LockError;
use crate::motion::{
    AuxItem, AuxKind, InterpState, Interpolator, Item, MotionConfig, SegmentSource,
};
use crate::rt::prelude::*;

/// Bound on stale items dropped per cycle (bounded work per cycle).
pub const MAX_DISCARD_PER_CYCLE: usize = 1024;

/// The segment queue seen as the interpolator's source, for one job.
struct JobSource<'a> {
    reader: &'a mut BufferReader<QueueItem>,
    job: u32,
    /// An item of a newer job, kept until that job runs.
    parked: &'a mut Option<QueueItem>,
    consumed: &'a mut u64,
}

impl SegmentSource for JobSource<'_> {
    fn pop(&mut self) -> Option<Item> {
        if let Some(p) = *self.parked {
            if p.job == self.job {
                *self.parked = None;
                *self.consumed += 1;
                return Some(p.item);
            }
            if p.job.wrapping_sub(self.job) as i32 > 0 {
                return None;
            }
            *self.parked = None;
        }
        for _ in 0..MAX_DISCARD_PER_CYCLE {
            let q = self.reader.pop()?;
            if q.job == self.job {
                *self.consumed += 1;
                return Some(q.item);
            }
            if q.job.wrapping_sub(self.job) as i32 > 0 {
                *self.parked = Some(q);
                return None;
            }
        }
        None
    }
}

/// The interpolator task.
pub struct InterpolatorTask {
    cfg: MotionConfig,
    interp: Interpolator,
    kin: Machine,
    /// Pose index of each configured axis, in configuration order.
    axes: Vec<(char, usize)>,
    queue: BufferReader<QueueItem>,
    parked: Option<QueueItem>,
    control_in: Option<DataReader<MotionControl>>,
    feedback_in: Vec<DataReader<AxisFeedback>>,
    out: Option<DataWriter<Setpoints>>,
    control: MotionControl,
    feedback: [AxisFeedback; NUM_AXES],
    sp: Setpoints,
    last_abort: u32,
    last_aux_done: u32,
    /// Spindle-synchronised moves (G33, G76, G33.1).
    follow: SpindleFollower,
}

impl InterpolatorTask {
    /// An interpolator for `cfg` consuming `queue`.
    pub fn new(
        cfg: MotionConfig,
        axes: Vec<(char, usize)>,
        queue: BufferReader<QueueItem>,
    ) -> Self {
        let kin = Machine::new(&cfg.kinematics);
        InterpolatorTask {
            interp: Interpolator::new(&cfg, [0.0; NUM_AXES]),
            cfg,
            kin,
            axes,
            queue,
            parked: None,
            control_in: None,
            feedback_in: Vec::new(),
            out: None,
            control: MotionControl::default(),
            feedback: [AxisFeedback::default(); NUM_AXES],
            sp: Setpoints::default(),
            last_abort: 0,
            last_aux_done: 0,
            follow: SpindleFollower::new(None),
        }
    }

    /// The simulated machine's spindle, with a position and an index pulse: synchronised
    /// moves follow it ([`super::spindle_follow`]).
    pub fn with_sim_spindle(mut self, p: Option<SimSpindleParams>) -> Self {
        self.follow = SpindleFollower::new(p);
        self.interp = self.fresh_interp(self.sp.pose_mm);
        self
    }

    /// An idle interpolator at `pose` with this task's settings.
    fn fresh_interp(&self, pose: [f64; NUM_AXES]) -> Interpolator {
        let mut i = Interpolator::new(&self.cfg, pose);
        i.set_external_sync(self.follow.has_spindle());
        i.set_feed_override(self.control.feed_override);
        i.set_rapid_override(self.control.rapid_override);
        i
    }

    fn sync_error(&mut self, e: LockError) {
        self.sp.sync_error = Some(e);
        self.sp.sync_error_seq = self.sp.sync_error_seq.wrapping_add(1);
    }

    /// Starts the synchronised move the interpolator has stopped at, if `aux` is one.
    fn start_sync(&mut self, aux: Option<AuxItem>, at: [f64; NUM_AXES]) {
        let Some(AuxItem {
            kind:
                AuxKind::SpindleSync {
                    end_mm,
                    pitch_mm,
                    tap,
                },
            ..
        }) = aux
        else {
            return;
        };
        if self.sp.abort_ack != self.last_abort {
            // Aborting: the interpolator drops the move with the rest of the job.
            return;
        }
        match self.follow.start(&self.cfg, at, end_mm, pitch_mm, tap) {
            Ok(StartOutcome::Following) => {}
            Ok(StartOutcome::RunPlanned) => self.interp.aux_done(),
            // Not started: the tool is at rest; the machine aborts the job.
            Err(e) => self.sync_error(e),
        }
    }

    /// One cycle of the running synchronised move: its pose replaces the interpolator's,
    /// which waits at the move's barrier meanwhile.
    fn follow_step(&mut self, dt_s: f64) {
        let Some(f) = self.follow.step(dt_s) else {
            return;
        };
        if let Some(e) = f.error {
            self.sync_error(e);
        }
        if f.done {
            self.interp.aux_done();
        }
        if f.stopped {
            // Aborted (or failed) on the line: the rest of the job is dropped from here.
            self.interp = self.fresh_interp(f.pose_mm);
            self.interp.abort();
        }
        self.sp.pose_mm = f.pose_mm;
        match self.kin.inverse(&f.pose_mm) {
            Ok(j) => self.sp.joints = j,
            // Out of reach: stop here (the joints keep their last value).
            Err(_) => self.follow.stop(),
        }
        self.sp.distance_to_go_mm = f.to_go_mm;
        self.sp.state = InterpState::Running;
        self.sp.scale = 1.0;
    }

    /// The actual pose from the axis feedback (commanded joints where there is none).
    fn actual_pose(&self) -> Option<[f64; NUM_AXES]> {
        let mut joints = self.sp.joints;
        for &(_, i) in &self.axes {
            if self.feedback[i].valid {
                joints[i] = self.feedback[i].actual;
            }
        }
        self.kin.forward(&joints).ok()
    }

    /// Follow the drives: commanded = actual.
    fn track(&mut self) {
        let mut joints = self.sp.joints;
        for &(_, i) in &self.axes {
            if self.feedback[i].valid {
                joints[i] = self.feedback[i].actual;
            }
        }
        let pose = self.kin.forward(&joints).unwrap_or(self.sp.pose_mm);
        self.follow.cancel();
        self.interp = self.fresh_interp(pose);
        self.sp.joints = joints;
        self.sp.pose_mm = pose;
        self.sp.state = InterpState::Idle;
        self.sp.aux = None;
        self.sp.distance_to_go_mm = 0.0;
        self.sp.scale = 0.0;
        self.sp.tracking = true;
        self.sp.abort_ack = self.control.abort_seq;
        self.last_abort = self.control.abort_seq;
        self.last_aux_done = self.control.aux_done_seq;
    }
}

impl Task for InterpolatorTask {
    type Command = NoCommands;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.control_in = Some(ctx.input(ports::MOTION_CONTROL));
        self.feedback_in = self
            .axes
            .iter()
            .map(|&(name, _)| ctx.input(&ports::feedback(name)))
            .collect();
        self.out = Some(ctx.output(ports::SETPOINTS));
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        if let Some(r) = &mut self.control_in {
            r.get(&mut self.control);
        }
        for (k, r) in self.feedback_in.iter_mut().enumerate() {
            if let Some(&(_, i)) = self.axes.get(k) {
                r.get(&mut self.feedback[i]);
            }
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let c = self.control;
        let dt_s = ctx.period_ns as f64 * 1e-9;
        self.follow.spindle_step(dt_s, c.spindle_rpm);
        let spindle = self.follow.sample();
        self.sp.spindle_revs = spindle.revs;
        self.sp.spindle_rps = spindle.rps;
        if c.track_actual {
            self.track();
        } else {
            if self.sp.tracking || c.job != self.sp.job {
                // A new motion starts from where tracking left the interpolator.
                self.sp.tracking = false;
                self.sp.job = c.job;
                self.sp.items_consumed = 0;
                self.sp.planned_time_done_s = 0.0;
            }
            self.interp.set_feed_override(c.feed_override);
            self.interp.set_rapid_override(c.rapid_override);
            self.interp.set_probe_input(c.probe_input);
            if c.hold {
                self.interp.hold();
            } else {
                self.interp.resume();
            }
            if c.abort_seq != self.last_abort {
                self.last_abort = c.abort_seq;
                if self.follow.active() {
                    // The follower brakes on the line, then aborts the interpolator.
                    self.follow.stop();
                } else {
                    self.interp.abort();
                }
            }
            if c.aux_done_seq != self.last_aux_done {
                self.last_aux_done = c.aux_done_seq;
                self.interp.aux_done();
            }
            let mut src = JobSource {
                reader: &mut self.queue,
                job: c.job,
                parked: &mut self.parked,
                consumed: &mut self.sp.items_consumed,
            };
            let out = *self.interp.step(&mut src);
            // Planned time passes only while a move runs (or decelerates into a hold): the
            // scale keeps its last value at a barrier (M0, M66, spindle at speed), where
            // the job stands still.
            if matches!(out.state, InterpState::Running | InterpState::Holding) {
                self.sp.planned_time_done_s += dt_s * out.scale;
            }
            self.sp.joints = out.joints;
            self.sp.pose_mm = out.pose_mm;
            self.sp.line = out.line;
            self.sp.state = out.state;
            self.sp.distance_to_go_mm = out.distance_to_go_mm;
            self.sp.scale = out.scale;
            self.sp.aux = out.aux;
            self.sp.probe_tripped = out.probe_tripped;
            if out.probe_trip_now {
                // Where the axes actually were when the input changed (the command leads
                // the feedback by the following error).
                self.sp.probe_pose_mm = self.actual_pose().unwrap_or(out.probe_pose_mm);
            }
            if out.aux.is_some() {
                self.sp.aux_seq = self.sp.aux_seq.wrapping_add(1);
            }
            self.start_sync(out.aux, out.pose_mm);
            self.follow_step(dt_s);
            self.sp.spindle_reversed = self.follow.reversed();
            if matches!(self.sp.state, InterpState::Idle | InterpState::Done) {
                self.sp.abort_ack = self.last_abort;
            }
        }
        if let Some(w) = &mut self.out {
            w.set(self.sp);
        }
        Ok(())
    }
}
