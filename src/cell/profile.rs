//! A straight-line move with a trapezoidal speed profile (velocity and acceleration limits),
//! advanced one servo cycle at a time: the robot task's interpolator.

use super::types::{distance, Vec3, AXES};

/// One straight move in progress.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LineMove {
    start: Vec3,
    dir: Vec3,
    length: f64,
    s: f64,
    v: f64,
    vmax: f64,
    amax: f64,
}

/// The interpolated point of a cycle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sample {
    /// Position, mm.
    pub position_mm: Vec3,
    /// Velocity, mm/s.
    pub velocity_mm_s: Vec3,
    /// Acceleration, mm/s².
    pub acceleration_mm_s2: Vec3,
}

impl LineMove {
    /// A move from `from` to `to` at most `vmax` mm/s and `amax` mm/s².
    pub fn new(from: Vec3, to: Vec3, vmax: f64, amax: f64) -> Self {
        let length = distance(&from, &to);
        let mut dir = [0.0; AXES];
        if length > 0.0 {
            for (i, d) in dir.iter_mut().enumerate() {
                *d = (to[i] - from[i]) / length;
            }
        }
        Self {
            start: from,
            dir,
            length,
            s: 0.0,
            v: 0.0,
            vmax,
            amax,
        }
    }

    /// True once the setpoint is at the end.
    pub fn finished(&self) -> bool {
        self.s >= self.length
    }

    /// Advances by `dt` seconds and returns the new setpoint.
    pub fn advance(&mut self, dt: f64) -> Sample {
        let remaining = (self.length - self.s).max(0.0);
        let v_prev = self.v;
        let v_brake = (2.0 * self.amax * remaining).sqrt();
        let mut v = self.vmax.min(v_prev + self.amax * dt).min(v_brake);
        if remaining <= v * dt || remaining < 1e-9 {
            self.s = self.length;
            v = 0.0;
        } else {
            self.s += v * dt;
        }
        self.v = v;
        let a = if dt > 0.0 { (v - v_prev) / dt } else { 0.0 };
        let mut out = Sample::default();
        for i in 0..AXES {
            out.position_mm[i] = self.start[i] + self.dir[i] * self.s;
            out.velocity_mm_s[i] = self.dir[i] * v;
            out.acceleration_mm_s2[i] = self.dir[i] * a;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reaches_the_end_within_limits() {
        let mut m = LineMove::new([0.0; 3], [300.0, 400.0, 0.0], 1000.0, 5000.0);
        let mut cycles = 0;
        let mut last = Sample::default();
        while !m.finished() {
            let s = m.advance(1e-3);
            let speed = distance(&s.velocity_mm_s, &[0.0; 3]);
            assert!(speed <= 1000.0 + 1e-9);
            last = s;
            cycles += 1;
            assert!(cycles < 10_000);
        }
        assert_eq!(last.position_mm, [300.0, 400.0, 0.0]);
        // 500 mm at 1 m/s with 5 m/s²: 0.2 s ramps + 0.3 s cruise = 0.7 s.
        assert!((650..=760).contains(&cycles), "{cycles} cycles");
    }
}
