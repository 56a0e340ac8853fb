//! The `monitor` task: last on the servo thread. Compares this cycle's setpoints with this
//! cycle's feedback through [`safety::check_axis`](crate::machine::safety::check_axis) and
//! emits a `monitor.fault` event when an axis trips (once per trip: it re-arms when the
//! condition has cleared). It also keeps the following errors and their maxima (reset when
//! a new job starts) for status and the job summary. Last in its step it publishes the
//! cycle's [`StatusSnapshot`](super::status::StatusSnapshot).
//!
//! The monitor only reports: the machine task decides the reaction (the error policy lives
//! outside the task that finds the error).

use super::can_delay::SetpointHistory;
use super::status::StatusPublisher;
use super::{ports, AxisFeedback, FaultEvent, MonitorSnapshot, MotionControl, Setpoints};
use crate::gcode::NUM_AXES;
use crate::machine::safety::{check_axis, AxisGuard, AxisSample, Trip};
use crate::rt::prelude::*;
use hytask_hal::axis::DriveState;

/// The monitor task.
pub struct MonitorTask {
    /// (name, pose index, guard) per configured axis.
    axes: Vec<(char, usize, AxisGuard)>,
    setpoints_in: Option<DataReader<Setpoints>>,
    control_in: Option<DataReader<MotionControl>>,
    feedback_in: Vec<DataReader<AxisFeedback>>,
    fault_ev: Option<EventSource<FaultEvent>>,
    out: Option<DataWriter<MonitorSnapshot>>,
    setpoints: Setpoints,
    control: MotionControl,
    feedback: [AxisFeedback; NUM_AXES],
    tripped: u32,
    snap: MonitorSnapshot,
    job: u32,
    /// The status snapshot of the cycle, published last.
    status: StatusPublisher,
    /// Per pose index: past setpoints, for axes whose feedback answers an older one.
    history: [SetpointHistory; NUM_AXES],
}

impl MonitorTask {
    /// A monitor for the given axes and their limits.
    pub fn new(axes: Vec<(char, usize, AxisGuard)>) -> Self {
        MonitorTask {
            axes,
            setpoints_in: None,
            control_in: None,
            feedback_in: Vec::new(),
            fault_ev: None,
            out: None,
            setpoints: Setpoints::default(),
            control: MotionControl::default(),
            feedback: [AxisFeedback::default(); NUM_AXES],
            tripped: 0,
            snap: MonitorSnapshot::default(),
            job: 0,
            status: StatusPublisher::default(),
            history: [SetpointHistory::new(0); NUM_AXES],
        }
    }

    /// Feedback of axis `index` answers the setpoint of `delay` cycles ago (CANopen axes:
    /// [`CAN_FEEDBACK_DELAY`](super::can_delay::CAN_FEEDBACK_DELAY)): the following error
    /// is taken against that setpoint.
    pub fn with_feedback_delay(mut self, index: usize, delay: usize) -> Self {
        if let Some(h) = self.history.get_mut(index) {
            *h = SetpointHistory::new(delay);
        }
        self
    }
}

impl Task for MonitorTask {
    type Command = NoCommands;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.setpoints_in = Some(ctx.input(ports::SETPOINTS));
        self.control_in = Some(ctx.input(ports::MOTION_CONTROL));
        self.feedback_in = self
            .axes
            .iter()
            .map(|&(name, _, _)| ctx.input(&ports::feedback(name)))
            .collect();
        self.fault_ev = Some(ctx.event("fault"));
        self.out = Some(ctx.output(ports::MONITOR));
        self.status.configure(ctx);
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        self.status.read_inputs();
        if let Some(r) = &mut self.setpoints_in {
            r.get(&mut self.setpoints);
        }
        if let Some(r) = &mut self.control_in {
            r.get(&mut self.control);
        }
        for (k, r) in self.feedback_in.iter_mut().enumerate() {
            if let Some(&(_, i, _)) = self.axes.get(k) {
                r.get(&mut self.feedback[i]);
            }
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if self.control.job != self.job && !self.control.track_actual {
            self.job = self.control.job;
            self.snap.max_following_error = [0.0; NUM_AXES];
        }
        for &(_, i, guard) in &self.axes {
            let fb = &self.feedback[i];
            let commanded = self.history[i].push(self.setpoints.joints[i], fb.age);
            if !fb.valid {
                continue;
            }
            let error = commanded - fb.actual;
            self.snap.following_error[i] = error;
            let moving = !self.setpoints.tracking;
            if moving && error.abs() > self.snap.max_following_error[i] {
                self.snap.max_following_error[i] = error.abs();
            }
            let sample = AxisSample {
                commanded,
                actual: fb.actual,
                fault: fb.fault.or(fb.state.is_fault().then_some(0)),
                limit_switch: fb.limit_switch && !fb.homing,
                stale_cycles: fb.stale_cycles,
                homed: fb.homed,
                enabled: fb.state == DriveState::OperationEnabled && !fb.homing,
            };
            let bit = 1u32 << i;
            let trip = match fb.link {
                Some(fault) => Some(Trip::Fieldbus { axis: i, fault }),
                None => check_axis(i, &guard, &sample),
            };
            match trip {
                Some(trip) if self.tripped & bit == 0 => {
                    self.tripped |= bit;
                    if let Some(ev) = &mut self.fault_ev {
                        ev.emit(FaultEvent {
                            trip,
                            line: self.setpoints.line,
                        });
                    }
                }
                Some(_) => {}
                None => self.tripped &= !bit,
            }
        }
        if let Some(w) = &mut self.out {
            w.set(self.snap);
        }
        self.status
            .publish(ctx.cycle, &self.setpoints, &self.feedback, &self.snap);
        Ok(())
    }
}
