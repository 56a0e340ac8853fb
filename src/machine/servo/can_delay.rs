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

/// Cycles between a CANopen axis's setpoint and the feedback that answers it.
pub const CAN_FEEDBACK_DELAY: usize = 1;

/// The longest delay a history keeps.
pub const MAX_DELAY: usize = 4;

/// The setpoints of the last [`MAX_DELAY`] cycles of one axis: a fixed ring, no allocation.
#[derive(Debug, Clone, Copy, Default)]
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
            delay: delay.min(MAX_DELAY),
            ..SetpointHistory::default()
        }
    }

    /// Records this cycle's setpoint and returns the one the feedback of this cycle
    /// answers: `delay` cycles old, or the oldest recorded while the history is shorter.
    pub fn push(&mut self, setpoint: f64) -> f64 {
        self.head = (self.head + 1) % self.ring.len();
        self.ring[self.head] = setpoint;
        self.len = (self.len + 1).min(self.ring.len());
        let back = self.delay.min(self.len - 1);
        self.ring[(self.head + self.ring.len() - back) % self.ring.len()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn returns_the_setpoint_delay_cycles_old() {
        let mut h = SetpointHistory::new(2);
        assert_eq!(h.push(1.0), 1.0, "oldest while short");
        assert_eq!(h.push(2.0), 1.0);
        assert_eq!(h.push(3.0), 1.0);
        assert_eq!(h.push(4.0), 2.0);
        for k in 5..20 {
            assert_eq!(h.push(f64::from(k)), f64::from(k - 2));
        }
        let mut now = SetpointHistory::new(0);
        assert_eq!(now.push(7.0), 7.0);
        assert_eq!(SetpointHistory::new(99).delay, MAX_DELAY);
    }
}
