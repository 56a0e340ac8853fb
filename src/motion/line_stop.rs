//! The fastest jerk-limited stop along a straight line, in closed form (issue 14: "a hold
//! still stops as fast as the limits allow").
//!
//! Why: a hold by time scaling (`dσ/dt = k`, see [`super::interpolator`]) brakes with the
//! rates of `k` the planner left free in every segment one braking may reach, so from a
//! cruise at full feed it took 2.1× the distance of the fastest stop. On a straight segment
//! the path does not depend on the timing, so the interpolator may instead follow any speed
//! profile along it: this one. From speed `v0` and acceleration `a0` along the line, the
//! acceleration goes to `-A` (or to the lower peak that suffices) with jerk `J`, stays, and
//! returns to 0 with jerk `J` exactly as the speed reaches 0: the time-optimal stop for
//! `|a| ≤ A`, `|j| ≤ J` (the three-phase velocity profile of online trajectory generation,
//! Kröger; Berscheid & Kröger's Ruckig for one degree of freedom).

/// A stop in three phases of constant jerk, from `(v0, a0)` at `t = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineStop {
    v0: f64,
    a0: f64,
    jerk: [f64; 3],
    dur: [f64; 3],
}

impl LineStop {
    /// The fastest stop from speed `v0` > 0 (mm/s) with acceleration `a0` along the motion
    /// (mm/s², clamped to `±acc`) within `acc` and `jerk`, ending at rest with zero
    /// acceleration. `None` where no such stop exists without reversing (a deceleration so
    /// strong at so low a speed that bringing it to zero alone passes through rest:
    /// `v0 < a0²/2J` with `a0 < 0`) or the limits are not positive.
    pub fn new(v0: f64, a0: f64, acc: f64, jerk: f64) -> Option<Self> {
        if !(v0 > 0.0 && acc > 0.0 && jerk > 0.0) {
            return None;
        }
        let a0 = a0.clamp(-acc, acc);
        if v0 + a0 * a0.abs() / (2.0 * jerk) <= 0.0 {
            return None;
        }
        // Mirrored (speed and acceleration negated): raise the acceleration to the peak
        // `ap`, hold it, lower it to 0; the speed rises from -v0 to 0.
        let am = -a0;
        let ap = acc.min((jerk * v0 + 0.5 * am * am).sqrt());
        let t1 = (ap - am).abs() / jerk;
        let j1 = if ap >= am { jerk } else { -jerk };
        let v1 = -v0 + 0.5 * (am + ap) * t1;
        let t3 = ap / jerk;
        let t2 = ((-v1 - 0.5 * ap * ap / jerk) / ap).max(0.0);
        Some(LineStop {
            v0,
            a0,
            jerk: [-j1, 0.0, jerk],
            dur: [t1, t2, t3],
        })
    }

    /// Duration of the stop, s.
    pub fn duration_s(&self) -> f64 {
        self.dur.iter().sum()
    }

    /// Distance to rest, mm.
    pub fn distance_mm(&self) -> f64 {
        self.eval(f64::INFINITY).0
    }

    /// The highest speed the stop has from where it has covered `d_mm` on (the speed there,
    /// or the peak where it is still accelerating), or `None` if it ends before. The phase
    /// that covers `d_mm` is found by walking the three, and the time in it by Newton steps
    /// on its cubic kept within a shrinking bracket (the distance grows with time); the
    /// speed is taken at the bracket's early end, so it is never below the true one.
    pub fn speed_at_distance(&self, d_mm: f64) -> Option<f64> {
        let peak = if self.a0 > 0.0 {
            self.v0 + self.a0 * self.a0 / (2.0 * self.jerk[2])
        } else {
            self.v0
        };
        if d_mm <= 0.0 {
            return Some(peak);
        }
        let (mut s, mut v, mut a) = (0.0, self.v0, self.a0);
        for (j, dur) in self.jerk.into_iter().zip(self.dur) {
            let at = |h: f64| s + v * h + a * h * h / 2.0 + j * h * h * h / 6.0;
            if at(dur) > d_mm {
                let (mut lo, mut hi) = (0.0, dur);
                let mut h = ((d_mm - s) / v.max(1e-9)).clamp(0.0, dur);
                for _ in 0..40 {
                    let e = at(h) - d_mm;
                    if e > 0.0 {
                        hi = h;
                    } else {
                        lo = h;
                    }
                    if e.abs() <= 1e-12 * d_mm.max(1.0) || hi - lo <= 1e-15 {
                        break;
                    }
                    let rate = v + a * h + j * h * h / 2.0;
                    h = if rate > 0.0 { h - e / rate } else { f64::NAN };
                    if !(h > lo && h < hi) {
                        h = 0.5 * (lo + hi);
                    }
                }
                let early = lo.min(h);
                if a + j * early > 0.0 {
                    return Some(peak);
                }
                return Some((v + a * early + j * early * early / 2.0).max(0.0));
            }
            s = at(dur);
            v += a * dur + j * dur * dur / 2.0;
            a += j * dur;
        }
        None
    }

    /// `(distance, speed, acceleration)` at `t` s into the stop (clamped to it; the speed is
    /// never below 0).
    pub fn eval(&self, t: f64) -> (f64, f64, f64) {
        let (mut s, mut v, mut a) = (0.0, self.v0, self.a0);
        let mut left = t.max(0.0);
        for (j, d) in self.jerk.into_iter().zip(self.dur) {
            let h = left.min(d);
            s += v * h + a * h * h / 2.0 + j * h * h * h / 6.0;
            v += a * h + j * h * h / 2.0;
            a += j * h;
            left -= h;
            if left <= 0.0 {
                break;
            }
        }
        if left > 0.0 || t >= self.duration_s() {
            // At rest: exactly, whatever the rounding of the phases.
            return (s, 0.0, 0.0);
        }
        (s, v.max(0.0), a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: f64 = 500.0;
    const J: f64 = 50_000.0;

    /// The speed where the stop has covered a distance agrees with its timing, and is the
    /// peak while it still accelerates.
    #[test]
    fn speed_at_distance_follows_the_stop() {
        for (v, a) in [(50.0, 0.0), (30.0, 400.0), (40.0, -300.0), (2.0, 0.0)] {
            let s = LineStop::new(v, a, A, J).unwrap();
            let peak = v + a.max(0.0).powi(2) / (2.0 * J);
            for k in 1..100 {
                let t = s.duration_s() * f64::from(k) / 100.0;
                let (d, speed, acc) = s.eval(t);
                let got = s.speed_at_distance(d).unwrap();
                let want = if acc > 0.0 { peak } else { speed };
                assert!(
                    got >= want - 1e-9 && got <= want + 1e-6,
                    "{v} {a} {t}: {got} {want}"
                );
            }
            assert_eq!(s.speed_at_distance(s.distance_mm() + 1e-9), None);
            assert_eq!(s.speed_at_distance(0.0), Some(peak));
        }
    }

    /// From a cruise the stop is the symmetric S-curve: `T = v/A + A/J` once the full
    /// acceleration is reached, `2·√(v/J)` below that, distance `v·T/2`.
    #[test]
    fn from_a_cruise_it_is_the_symmetric_s_curve() {
        for v in [1.0, 5.0, 20.0, 50.0, 166.0] {
            let s = LineStop::new(v, 0.0, A, J).unwrap();
            let t = if v >= A * A / J {
                v / A + A / J
            } else {
                2.0 * (v / J).sqrt()
            };
            assert!((s.duration_s() - t).abs() < 1e-12, "{v}");
            assert!((s.distance_mm() - v * t / 2.0).abs() < 1e-9, "{v}");
        }
    }

    /// From any speed and acceleration within the limits, the stop ends at rest with zero
    /// acceleration, never reverses, and stays within both limits (checked at 10 µs steps
    /// by finite differences as well as in closed form).
    #[test]
    fn every_stop_ends_at_rest_within_the_limits() {
        let mut n = 0;
        for vi in 0..40 {
            let v0 = 0.1 + vi as f64 * 2.5;
            for ai in -10..=10 {
                let a0 = A * ai as f64 / 10.0;
                let Some(s) = LineStop::new(v0, a0, A, J) else {
                    assert!(a0 < 0.0 && v0 < a0 * a0 / (2.0 * J) + 1e-9, "{v0} {a0}");
                    continue;
                };
                n += 1;
                let end = s.eval(s.duration_s());
                assert_eq!((end.1, end.2), (0.0, 0.0));
                // The last phase brings speed and acceleration to 0 together.
                let before = s.eval(s.duration_s() * (1.0 - 1e-9));
                assert!(
                    before.1.abs() < 1e-6 && before.2.abs() < 1e-3,
                    "{v0} {a0}: {before:?}"
                );
                let dt = 1e-5;
                let mut prev = s.eval(0.0);
                let mut prev_a = a0;
                let mut t = dt;
                while t < s.duration_s() + dt {
                    let x = s.eval(t);
                    assert!(x.0 >= prev.0 - 1e-12, "{v0} {a0}: moved back at {t}");
                    assert!(x.2.abs() <= A * (1.0 + 1e-9), "{v0} {a0}: a {} at {t}", x.2);
                    assert!(
                        (x.2 - prev_a).abs() <= J * dt * (1.0 + 1e-6),
                        "{v0} {a0}: jerk at {t}"
                    );
                    prev = x;
                    prev_a = x.2;
                    t += dt;
                }
            }
        }
        assert!(n > 700, "{n} stops");
    }

    /// Braking while still accelerating: the acceleration first falls to zero (the speed
    /// still rises by `a0²/2J`), then the stop proceeds; no stop is faster than reaching
    /// zero acceleration first and then the cruise stop from that higher speed.
    #[test]
    fn a_stop_while_accelerating_first_ends_the_acceleration() {
        let (v0, a0) = (30.0, 400.0);
        let s = LineStop::new(v0, a0, A, J).unwrap();
        let t0 = a0 / J;
        let peak = v0 + a0 * a0 / (2.0 * J);
        let bound = t0 + LineStop::new(peak, 0.0, A, J).unwrap().duration_s();
        assert!(s.duration_s() <= bound + 1e-12);
        let top = (0..1000)
            .map(|i| s.eval(s.duration_s() * i as f64 / 1000.0).1)
            .fold(0.0, f64::max);
        assert!((top - peak).abs() < 1e-3, "{top} vs {peak}");
    }
}
