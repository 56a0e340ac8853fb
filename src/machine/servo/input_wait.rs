//! M66 in the machine task: wait for an input, then tell the program what was read.
//!
//! LinuxCNC semantics (M66 and #5399): `L0` reads the input at once; `L1` waits for a rising
//! edge, `L2` a falling edge, `L3` a high level, `L4` a low level, each for at most `Q`
//! seconds. The value read goes to #5399 before the next line is interpreted: 0 or 1 for a
//! digital input (`P`), the reading of an analog one (`E`, `L0` only), or -1 when the wait
//! timed out. A timeout is not an error: the program may branch on it.
//!
//! The timeout counts servo cycles (machine time, the stepped simulation's time in tests),
//! never the wall clock. The wait state is plain data and a poll is a few comparisons, so it
//! runs inside the servo cycle.
//!
//! A live job (one the piece runner feeds, see [`crate::machine::probing`]) marks the M66
//! that ends a piece with `answer`: when that wait ends, the machine publishes the value in
//! its snapshot ([`super::InputWaitSnapshot`]) and holds, motion finished, until the next
//! piece, interpreted with #5399 set, is queued. Any other M66 (a job run without a live
//! interpreter) just goes on when the wait ends.

use super::InputWaitSnapshot;
use crate::gcode::canon::{InputKind, WaitKind};
use crate::gcode::NUM_AXES;
use crate::machine::api::InputWaitStatus;

/// What #5399 reads after a wait that timed out.
pub const TIMED_OUT: f64 = -1.0;

/// An M66 in progress.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputWait {
    /// Input number (`P` or `E` word).
    pub index: u32,
    /// Digital (`P`) or analog (`E`).
    pub input: InputKind,
    /// `L` word.
    pub kind: WaitKind,
    /// Servo cycle at which the wait times out.
    pub deadline: u64,
    /// The level in the previous cycle (edges).
    pub last: bool,
    /// The machine publishes the result and holds until the next piece is queued.
    pub answer: bool,
    /// Source line of the M66.
    pub line: u32,
}

impl InputWait {
    /// Starts a wait in cycle `cycle`, the input reading `value` now (0/1 for a digital one).
    /// `timeout_s` is turned into whole servo cycles of `period_s`.
    #[allow(clippy::too_many_arguments)]
    pub fn start(
        index: u32,
        input: InputKind,
        kind: WaitKind,
        timeout_s: f64,
        period_s: f64,
        cycle: u64,
        value: f64,
        answer: bool,
        line: u32,
    ) -> InputWait {
        let cycles = if period_s > 0.0 {
            (timeout_s / period_s).max(0.0) as u64
        } else {
            0
        };
        InputWait {
            index,
            input,
            kind,
            deadline: cycle.saturating_add(cycles),
            last: high(value),
            answer,
            line,
        }
    }

    /// One servo cycle of the wait, the input reading `value`: `Some(v)` when it is over, `v`
    /// being what #5399 gets (the value, or [`TIMED_OUT`]); `None` while it goes on.
    pub fn poll(&mut self, value: f64, cycle: u64) -> Option<f64> {
        let now = high(value);
        let met = match self.kind {
            WaitKind::Immediate => true,
            WaitKind::Rise => now && !self.last,
            WaitKind::Fall => !now && self.last,
            WaitKind::High => now,
            WaitKind::Low => !now,
        };
        self.last = now;
        if met {
            Some(value)
        } else if cycle >= self.deadline {
            Some(TIMED_OUT)
        } else {
            None
        }
    }
}

/// The snapshot as an M66 of job `job` starts: what it waits for.
pub fn publish_start(snap: &mut InputWaitSnapshot, w: &InputWait, job: u32) {
    snap.job = job;
    snap.line = w.line;
    snap.index = w.index;
    snap.analog = w.input == InputKind::Analog;
    snap.mode = match w.kind {
        WaitKind::Immediate => 0,
        WaitKind::Rise => 1,
        WaitKind::Fall => 2,
        WaitKind::High => 3,
        WaitKind::Low => 4,
    };
    snap.pending = true;
    snap.waiting = false;
}

/// The snapshot as the wait ends with `value` (#5399), the machine at rest at `pose_mm`.
pub fn publish_end(
    snap: &mut InputWaitSnapshot,
    w: &InputWait,
    value: f64,
    pose_mm: [f64; NUM_AXES],
) {
    snap.seq = snap.seq.wrapping_add(1);
    snap.value = value;
    snap.pending = false;
    snap.waiting = w.answer;
    snap.stopped_mm = pose_mm;
}

/// Every cycle, before the snapshot goes out: a wait is pending only while its barrier is,
/// and a hold after it only while the machine holds for the next piece (an abort, e-stop
/// or fault clears the barrier, and with it both).
pub fn publish_barrier(snap: &mut InputWaitSnapshot, waiting_for_input: bool, holding: bool) {
    snap.pending &= waiting_for_input;
    snap.waiting &= holding;
}

/// What `status` shows of the M66 job `job` waits at (`None` when it waits at none).
pub fn status(snap: &InputWaitSnapshot, job: u32) -> Option<InputWaitStatus> {
    if !snap.pending || snap.job != job {
        return None;
    }
    let until = ["immediate", "rise", "fall", "high", "low"];
    Some(InputWaitStatus {
        line: snap.line,
        input: if snap.analog { "analog" } else { "digital" }.into(),
        index: snap.index,
        until: until
            .get(usize::from(snap.mode))
            .unwrap_or(&"?")
            .to_string(),
    })
}

/// A reading as a level: high above 0.5 (a digital input reads 0 or 1).
fn high(value: f64) -> bool {
    value > 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: f64 = 0.001;

    fn wait(kind: WaitKind, timeout_s: f64, value: f64) -> InputWait {
        InputWait::start(
            0,
            InputKind::Digital,
            kind,
            timeout_s,
            PERIOD,
            100,
            value,
            true,
            7,
        )
    }

    /// Polls cycles 101.. with the given readings; returns (cycle, result) of the end.
    fn run(w: &mut InputWait, readings: &[f64]) -> Option<(u64, f64)> {
        readings
            .iter()
            .enumerate()
            .find_map(|(i, &v)| w.poll(v, 101 + i as u64).map(|r| (101 + i as u64, r)))
    }

    #[test]
    fn each_wait_type_ends_on_its_condition_with_the_value_read() {
        // (L, reading at the start, readings after, expected (cycle, #5399))
        let cases = [
            (WaitKind::Immediate, 0.0, vec![0.0], Some((101, 0.0))),
            (WaitKind::Immediate, 1.0, vec![1.0], Some((101, 1.0))),
            (
                WaitKind::Rise,
                1.0,
                vec![1.0, 0.0, 0.0, 1.0],
                Some((104, 1.0)),
            ),
            (WaitKind::Fall, 0.0, vec![0.0, 1.0, 0.0], Some((103, 0.0))),
            (WaitKind::High, 0.0, vec![0.0, 0.0, 1.0], Some((103, 1.0))),
            (WaitKind::High, 1.0, vec![1.0], Some((101, 1.0))),
            (WaitKind::Low, 1.0, vec![1.0, 0.0], Some((102, 0.0))),
        ];
        for (kind, start, readings, want) in cases {
            let mut w = wait(kind, 1.0, start);
            assert_eq!(run(&mut w, &readings), want, "{kind:?} from {start}");
        }
    }

    #[test]
    fn a_wait_that_is_not_met_times_out_in_machine_cycles_with_minus_one() {
        // Q0.01 at 1 ms: 10 cycles from cycle 100.
        let mut w = wait(WaitKind::High, 0.01, 0.0);
        assert_eq!(run(&mut w, &[0.0; 30]), Some((110, TIMED_OUT)));
        // A level that stays high never makes an edge.
        let mut w = wait(WaitKind::Rise, 0.01, 1.0);
        assert_eq!(run(&mut w, &[1.0; 30]), Some((110, TIMED_OUT)));
        // Met in the deadline's own cycle: the value wins.
        let mut w = wait(WaitKind::Low, 0.01, 1.0);
        let mut readings = [1.0; 10];
        readings[9] = 0.0;
        assert_eq!(run(&mut w, &readings), Some((110, 0.0)));
    }

    #[test]
    fn an_analog_read_gives_the_reading_itself() {
        let mut w = InputWait::start(
            2,
            InputKind::Analog,
            WaitKind::Immediate,
            0.0,
            PERIOD,
            5,
            3.25,
            true,
            1,
        );
        assert_eq!(w.poll(4.25, 6), Some(4.25));
    }
}
