//! A simulated spindle with a position: what an encoder with an index pulse reports on a
//! real lathe, so that spindle-synchronised motion ([`crate::motion::spindle_lock`]) can be
//! tested against a spindle that does *not* turn at exactly the commanded speed.
//!
//! The speed ramps toward the command at a bounded acceleration (a real drive takes a
//! while to reach speed and to reverse), and an optional load ripple modulates it
//! (`rps × (1 + ripple × sin(2π f t))`: a cutting load that varies with the part's
//! rotation, or a drive's speed loop hunting). The position integrates the speed; the
//! index pulse is reported in the cycle the position crosses a whole revolution, with the
//! exact revolution it marks, as an encoder's index latch does.

use crate::motion::spindle_lock::SpindleSample;

/// The spindle's dynamics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimSpindleParams {
    /// Acceleration of the speed ramp, rev/s² (> 0).
    pub accel_rps2: f64,
    /// Relative amplitude of the load ripple (0 for none; below 1).
    pub ripple: f64,
    /// Frequency of the ripple, Hz.
    pub ripple_hz: f64,
}

/// The simulated spindle (see the module documentation). Constant work per step, no
/// allocation: it can run in the servo cycle.
#[derive(Debug, Clone)]
pub struct SimSpindle {
    p: SimSpindleParams,
    /// Speed of the ramp (before the ripple), rev/s.
    base_rps: f64,
    revs: f64,
    t: f64,
}

impl SimSpindle {
    /// A spindle at rest at revolution `revs` (its angle at start-up).
    pub fn new(p: SimSpindleParams, revs: f64) -> SimSpindle {
        SimSpindle {
            p,
            base_rps: 0.0,
            revs,
            t: 0.0,
        }
    }

    /// Advances `dt` seconds toward the commanded speed `rpm` (signed: negative is M4).
    pub fn step(&mut self, dt: f64, rpm: f64) -> SpindleSample {
        let want = rpm / 60.0;
        let dv = (want - self.base_rps).clamp(-self.p.accel_rps2 * dt, self.p.accel_rps2 * dt);
        self.base_rps += dv;
        self.t += dt;
        let wobble = self.p.ripple * (std::f64::consts::TAU * self.p.ripple_hz * self.t).sin();
        let rps = self.base_rps * (1.0 + wobble);
        let before = self.revs;
        self.revs += rps * dt;
        // A whole revolution crossed (at most one per cycle at any realistic speed and
        // servo period): going up, one in (before, revs]; going down, one in [revs, before).
        let (index, index_at) = if self.revs >= before {
            let k = self.revs.floor();
            (k > before, k)
        } else {
            let k = self.revs.ceil();
            (k < before, k)
        };
        SpindleSample {
            revs: self.revs,
            rps,
            index,
            index_at,
        }
    }

    /// Position in revolutions.
    pub fn revs(&self) -> f64 {
        self.revs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_to_speed_and_marks_each_revolution_once() {
        let p = SimSpindleParams {
            accel_rps2: 50.0,
            ripple: 0.0,
            ripple_hz: 0.0,
        };
        let mut s = SimSpindle::new(p, 0.25);
        let mut marks = Vec::new();
        let mut last = SpindleSample::default();
        for _ in 0..2000 {
            last = s.step(0.001, 600.0);
            if last.index {
                marks.push(last.index_at);
            }
        }
        assert!((last.rps - 10.0).abs() < 1e-9, "at speed: {}", last.rps);
        // 0.2 s of ramp (0.25 + 1 rev) then 1.8 s at 10 rev/s: 19.25 revs.
        assert!((s.revs() - 19.25).abs() < 0.01, "{}", s.revs());
        let expect: Vec<f64> = (1..=19).map(f64::from).collect();
        assert_eq!(marks, expect);
    }
}
