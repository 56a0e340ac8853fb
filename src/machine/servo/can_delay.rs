//! Past setpoints for the following-error check of axes whose feedback is late.
//!
//! A simulated axis moves in its own task, so the monitor compares this cycle's setpoint
//! with this cycle's position. A CANopen axis does not: its setpoint of cycle k leaves
//! with the RPDO before SYNC k, the drive follows it at that SYNC and reports the position
//! in the TPDO the master reads at the start of cycle k + 1 (see
//! `hytask_hal::canopen::master`). So the position the monitor sees in cycle k + 1 answers
//! the setpoint of cycle k: [`CAN_FEEDBACK_DELAY`] cycles. Comparing it with the setpoint of
//! cycle k + 1 would add one cycle's travel to every following error (0.2 mm at 100 mm/s
//! and 2 ms), and a limit tighter than that would trip at full feed with a perfect drive.
//!
//! A drive that answers a SYNC late (a loaded host, the emulator of the vcan tests) leaves
//! the last position standing for a cycle or more (`AxisFeedback::age`): that position
//! answers a setpoint `age` cycles further back, and is compared with that one. Otherwise
//! every late TPDO would add a cycle's travel to the error and trip a sound drive.

/// Cycles between a CANopen axis's setpoint and the feedback that answers it.
pub const CAN_FEEDBACK_DELAY: usize = 1;

/// The longest delay a history keeps, late cycles included; an older position is compared
/// with the oldest setpoint kept.
pub const MAX_DELAY: usize = 63;

/// The setpoints of the last [`MAX_DELAY`] cycles of one axis: a fixed ring, no allocation.
#[derive(Debug, Clone, Copy)]
pub struct SetpointHistory {
    ring: [f64; MAX_DELAY + 1],
    head: usize,
    len: usize,
    delay: usize,
}

impl SetpointHistory {
    /// A history matching feedback `delay` cycles late (at most [`MAX_DELAY`]).
    pub fn new(delay: usize) -> Self {
        SetpointHistory {
            ring: [0.0; MAX_DELAY + 1],
            head: 0,
            len: 0,
            delay: delay.min(MAX_DELAY),
        }
    }

    /// Records this cycle's setpoint and returns the one the feedback of this cycle
    /// answers: `delay + late` cycles old (`late`: cycles the feedback is older than
    /// usual), or the oldest recorded while the history is shorter.
    pub fn push(&mut self, setpoint: f64, late: u32) -> f64 {
        self.head = (self.head + 1) % self.ring.len();
        self.ring[self.head] = setpoint;
        self.len = (self.len + 1).min(self.ring.len());
        let late = usize::try_from(late).unwrap_or(usize::MAX);
        let back = self.delay.saturating_add(late).min(self.len - 1);
        self.ring[(self.head + self.ring.len() - back) % self.ring.len()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn returns_the_setpoint_delay_cycles_old() {
        let mut h = SetpointHistory::new(2);
        assert_eq!(h.push(1.0, 0), 1.0, "oldest while short");
        assert_eq!(h.push(2.0, 0), 1.0);
        assert_eq!(h.push(3.0, 0), 1.0);
        assert_eq!(h.push(4.0, 0), 2.0);
        for k in 5..20 {
            assert_eq!(h.push(f64::from(k), 0), f64::from(k - 2));
        }
        let mut now = SetpointHistory::new(0);
        assert_eq!(now.push(7.0, 0), 7.0);
        assert_eq!(SetpointHistory::new(99).delay, MAX_DELAY);
    }

    #[test]
    fn a_late_position_answers_an_older_setpoint_and_a_very_late_one_the_oldest_kept() {
        let mut h = SetpointHistory::new(1);
        for k in 0..100 {
            h.push(f64::from(k), 0);
        }
        assert_eq!(h.push(100.0, 0), 99.0);
        assert_eq!(h.push(101.0, 2), 98.0, "two cycles late: three back");
        assert_eq!(
            h.push(102.0, 1000),
            102.0 - MAX_DELAY as f64,
            "clamped to the ring"
        );
    }
}
