//! The status snapshot: at the very end of each servo cycle, what every task published in it
//! (inputs, the machine's view and outputs, setpoints, feedback, following errors) is gathered
//! into one [`StatusSnapshot`] and written through one data object, stamped with the servo
//! cycle.
//!
//! Why: `status` used to read each data object on its own, so a reply could carry the
//! commanded position of one cycle and the job progress of the next (about 1 % of replies
//! during a job). A reader of this one object gets one complete cycle: every value in it
//! belongs to cycle [`StatusSnapshot::cycle`].

use super::{ports, AxisFeedback, Inputs, MachineSnapshot, MonitorSnapshot, Outputs, Setpoints};
use crate::gcode::NUM_AXES;
use crate::rt::prelude::*;

/// Everything `status` shows of the realtime side, from one servo cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StatusSnapshot {
    /// The servo cycle every value below was published in (the thread's cycle counter).
    pub cycle: u64,
    /// The machine task's view (mode, spindle, overrides, probe, trips).
    pub machine: MachineSnapshot,
    /// The interpolator's output (commanded position, line, progress in planned time).
    pub setpoints: Setpoints,
    /// Following errors.
    pub monitor: MonitorSnapshot,
    /// Feedback per pose index (unused indices stay at their default).
    pub feedback: [AxisFeedback; NUM_AXES],
    /// Inputs.
    pub inputs: Inputs,
    /// Outputs as the machine task commands them.
    pub outputs: Outputs,
}

/// Publishes the [`StatusSnapshot`] at the very end of a servo cycle. The monitor task,
/// last on the thread, owns it: it hands over what it read itself (setpoints, feedback) and
/// what it computed (following errors); the publisher reads the rest (inputs, the machine's
/// view, outputs), all of them already written in this cycle by the tasks before.
#[derive(Default)]
pub struct StatusPublisher {
    inputs_in: Option<DataReader<Inputs>>,
    outputs_in: Option<DataReader<Outputs>>,
    machine_in: Option<DataReader<MachineSnapshot>>,
    out: Option<DataWriter<StatusSnapshot>>,
    snap: StatusSnapshot,
}

impl StatusPublisher {
    /// Creates its ports on the owning task.
    pub fn configure(&mut self, ctx: &mut Configure<'_>) {
        self.inputs_in = Some(ctx.input(ports::INPUTS));
        self.outputs_in = Some(ctx.input(ports::OUTPUTS));
        self.machine_in = Some(ctx.input(ports::SNAPSHOT));
        self.out = Some(ctx.output(ports::STATUS));
    }

    /// Reads this cycle's inputs, outputs and machine view (step 1 of the owner).
    pub fn read_inputs(&mut self) {
        let s = &mut self.snap;
        if let Some(r) = &mut self.inputs_in {
            r.get(&mut s.inputs);
        }
        if let Some(r) = &mut self.outputs_in {
            r.get(&mut s.outputs);
        }
        if let Some(r) = &mut self.machine_in {
            r.get(&mut s.machine);
        }
    }

    /// Writes the snapshot of cycle `cycle` (last thing the owner does in its step).
    pub fn publish(
        &mut self,
        cycle: u64,
        setpoints: &Setpoints,
        feedback: &[AxisFeedback; NUM_AXES],
        monitor: &MonitorSnapshot,
    ) {
        let s = &mut self.snap;
        s.cycle = cycle;
        s.setpoints = *setpoints;
        s.feedback = *feedback;
        s.monitor = *monitor;
        if let Some(w) = &mut self.out {
            w.set(*s);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::Rig;
    use super::super::{ports, MonitorSnapshot, Outputs};
    use super::StatusSnapshot;
    use crate::machine::api::Mode;
    use crate::rt::prelude::*;

    /// Cycle by cycle through homing and motion: the snapshot is stamped with consecutive
    /// servo cycles and holds exactly what each task published in that cycle.
    #[test]
    fn the_status_snapshot_is_one_whole_servo_cycle() {
        let mut r = Rig::new();
        let mut status: DataReader<StatusSnapshot> = r.rt.reader(ports::STATUS).expect("status");
        let mut monitor: DataReader<MonitorSnapshot> =
            r.rt.reader(ports::MONITOR).expect("monitor");
        let mut outputs: DataReader<Outputs> = r.rt.reader(ports::OUTPUTS).expect("outputs");
        r.ready();
        let homed = status.latest().expect("snapshot");
        assert_eq!(homed.machine.mode, Mode::Idle);
        r.start_move(1, [250.0, 200.0, -20.0], 6000.0);
        let mut last = status.latest().expect("snapshot").cycle;
        let mut moving = 0;
        for _ in 0..1500 {
            r.rt.run_cycles(1);
            let st = status.latest().expect("snapshot");
            assert_eq!(st.cycle, last + 1, "one snapshot per cycle");
            last = st.cycle;
            assert_eq!(st.setpoints, r.sp.latest().expect("setpoints"));
            assert_eq!(st.machine, r.snap.latest().expect("machine"));
            assert_eq!(st.monitor, monitor.latest().expect("monitor"));
            assert_eq!(st.outputs, outputs.latest().expect("outputs"));
            for axis in 0..3 {
                assert_eq!(st.feedback[axis], r.feedback(axis));
            }
            if st.feedback[0].velocity.abs() > 1.0 {
                moving += 1;
            }
        }
        assert!(moving > 100, "the snapshots followed a motion");
    }
}
