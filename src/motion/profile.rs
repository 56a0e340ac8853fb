//! The S-curve velocity transition every segment is made of.
//!
//! A transition changes the velocity *vector* from `v0` to `v1` along a straight line in
//! velocity space, `v(t) = v0 + (v1 - v0)·f(t)`, where `f` rises from 0 to 1 with a
//! trapezoidal acceleration (jerk phase `tj`, constant phase, jerk phase `tj`): the 7-phase
//! S-curve with zero acceleration at both ends. Because every axis follows the *same* `f`,
//! per-axis peaks are exact and cheap: |v_x| ≤ max(|v0_x|, |v1_x|) (convexity),
//! |a_x| = |Δv_x|·max f', |j_x| = |Δv_x|·max f''. A straight acceleration, a cruise and a
//! corner blend are all this one shape, which is what lets the tests prove the limits hold.

/// Duration and jerk-phase length of one transition.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Shape {
    /// Total duration, s.
    pub duration_s: f64,
    /// Length of each of the two jerk phases, s (0 ≤ tj ≤ duration/2).
    pub jerk_s: f64,
}

impl Shape {
    /// Shortest shape with `T - tj ≥ alpha_s` (acceleration bound: `alpha_s = max |Δv_x|/A_x`)
    /// and `(T - tj)·tj ≥ beta_s2` (jerk bound: `beta_s2 = max |Δv_x|/J_x`).
    pub fn for_bounds(alpha_s: f64, beta_s2: f64) -> Shape {
        if alpha_s <= 0.0 || beta_s2 <= 0.0 {
            return Shape::default();
        }
        if beta_s2 <= alpha_s * alpha_s {
            let tj = beta_s2 / alpha_s;
            Shape {
                duration_s: alpha_s + tj,
                jerk_s: tj,
            }
        } else {
            let tj = beta_s2.sqrt();
            Shape {
                duration_s: 2.0 * tj,
                jerk_s: tj,
            }
        }
    }

    /// Peak of f' (1/s): multiply by |Δv_x| for the axis' peak acceleration.
    pub fn peak_rate(&self) -> f64 {
        let d = self.duration_s - self.jerk_s;
        if d > 0.0 {
            1.0 / d
        } else {
            0.0
        }
    }

    /// Peak of |f''| (1/s²): multiply by |Δv_x| for the axis' peak jerk.
    pub fn peak_jerk(&self) -> f64 {
        if self.jerk_s > 0.0 {
            self.peak_rate() / self.jerk_s
        } else {
            0.0
        }
    }

    /// `(f(t), F(t))`: velocity fraction and its integral (s) at time `t` (clamped to the
    /// shape). `F(T) = T/2`.
    pub fn eval(&self, t: f64) -> (f64, f64) {
        let big_t = self.duration_s;
        if big_t <= 0.0 {
            return (1.0, 0.0);
        }
        let t = t.clamp(0.0, big_t);
        if t > 0.5 * big_t {
            // Symmetry: f(t) = 1 - f(T - t), F(t) = t - T/2 + F(T - t).
            let (f, cap_f) = self.eval_first_half(big_t - t);
            return (1.0 - f, t - 0.5 * big_t + cap_f);
        }
        self.eval_first_half(t)
    }

    /// `f'(t)` (1/s): multiply by `|Δv|` for the acceleration along a straight transition.
    pub fn rate(&self, t: f64) -> f64 {
        let big_t = self.duration_s;
        if big_t <= 0.0 {
            return 0.0;
        }
        let t = t.clamp(0.0, big_t);
        let t = t.min(big_t - t);
        if t < self.jerk_s {
            self.peak_rate() * t / self.jerk_s
        } else {
            self.peak_rate()
        }
    }

    fn eval_first_half(&self, t: f64) -> (f64, f64) {
        let tj = self.jerk_s;
        let ap = self.peak_rate();
        if t < tj {
            let f = ap * t * t / (2.0 * tj);
            (f, ap * t * t * t / (6.0 * tj))
        } else {
            let u = t - tj;
            let f = ap * tj / 2.0 + ap * u;
            (f, ap * tj * tj / 6.0 + ap * tj / 2.0 * u + ap * u * u / 2.0)
        }
    }
}

/// Largest `x` in `[lo, hi]` with `ok(x)`, for `ok` true at `lo` and monotone (true below
/// some value, false above): bisection to `rel` of `hi` (at least of 1), at most 60 steps.
/// The answer always satisfies `ok` (it is `lo` if nothing above it does). Every speed
/// search of the planner (cruise peaks, junction speeds, blend speeds) uses it.
pub fn bisect_max(mut lo: f64, mut hi: f64, rel: f64, ok: impl Fn(f64) -> bool) -> f64 {
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ok(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= rel * hi.max(1.0) {
            break;
        }
    }
    lo
}

/// 1D transition bounds along a straight move: tangential acceleration and jerk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tangential {
    /// Tangential acceleration limit, mm/s².
    pub acc_mm_s2: f64,
    /// Tangential jerk limit, mm/s³.
    pub jerk_mm_s3: f64,
}

impl Tangential {
    /// Shape of a speed change from `v0` to `v1` along the move.
    pub fn shape(&self, v0_mm_s: f64, v1_mm_s: f64) -> Shape {
        let dv = (v1_mm_s - v0_mm_s).abs();
        Shape::for_bounds(dv / self.acc_mm_s2, dv / self.jerk_mm_s3)
    }

    /// Distance travelled while changing speed from `v0` to `v1`, mm.
    pub fn distance_mm(&self, v0_mm_s: f64, v1_mm_s: f64) -> f64 {
        0.5 * (v0_mm_s + v1_mm_s) * self.shape(v0_mm_s, v1_mm_s).duration_s
    }

    /// Highest speed ≤ `cap` reachable from `v0` within `dist_mm` (the same for braking to
    /// `v0`, by symmetry). The answer always satisfies `distance_mm(v0, answer) ≤ dist_mm`.
    ///
    /// In closed form (the planner's passes and `fit_choice`'s estimates call it for every
    /// move): with `x = v − v0`, the distance `(v0 + x/2)·T(x)` is `(2·v0 + y²)·y/√J` for
    /// `y = √x` below the speed change that reaches the full acceleration (`x < A²/J`, a
    /// cubic in `y`, solved by Cardano's formula rearranged so that nothing cancels) and a
    /// quadratic in `x` above it.
    pub fn reach_mm_s(&self, v0_mm_s: f64, dist_mm: f64, cap_mm_s: f64) -> f64 {
        if cap_mm_s <= v0_mm_s {
            return cap_mm_s;
        }
        if self.distance_mm(v0_mm_s, cap_mm_s) <= dist_mm {
            return cap_mm_s;
        }
        let (a, j, v0, d) = (self.acc_mm_s2, self.jerk_mm_s3, v0_mm_s, dist_mm.max(0.0));
        if !(a > 0.0 && j > 0.0 && d > 0.0) {
            return v0;
        }
        let x_full = a * a / j;
        let x = if d <= (v0 + 0.5 * x_full) * 2.0 * a / j {
            // y³ + p·y − q = 0 with p = 2·v0, q = d·√J: y = u − w with u³ − w³ = q and
            // u·w = p/3, written as q/(u² + u·w + w²) so that nothing cancels.
            let (p, q) = (2.0 * v0, d * j.sqrt());
            let u = (0.5 * q + (0.25 * q * q + p * p * p / 27.0).sqrt()).cbrt();
            let w = if u > 0.0 { p / (3.0 * u) } else { 0.0 };
            let den = u * u + p / 3.0 + w * w;
            let y = if den > 0.0 { q / den } else { 0.0 };
            y.max(0.0).powi(2)
        } else {
            // x² + b·x + c = 0, c < 0: the positive root without cancellation.
            let b = 2.0 * v0 + x_full;
            let c = 2.0 * v0 * x_full - 2.0 * a * d;
            (-2.0 * c / (b + (b * b - 4.0 * c).sqrt())).max(0.0)
        };
        let v = (v0 + x).min(cap_mm_s);
        // Rounding (of `v − v0` above all, when the change is tiny next to `v0`) may leave the
        // answer slightly too far: step back by growing shares of the change until it fits.
        let mut back = 1e-12;
        while back < 1.0 {
            let w = v0 + (v - v0) * (1.0 - back);
            if self.distance_mm(v0, w) <= dist_mm {
                return w;
            }
            back *= 4.0;
        }
        v0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_meets_bounds_and_integrates_to_half() {
        for (alpha, beta) in [(0.1, 0.001), (0.01, 0.01), (1.0, 1e-6)] {
            let s = Shape::for_bounds(alpha, beta);
            assert!(s.duration_s - s.jerk_s >= alpha - 1e-12);
            assert!((s.duration_s - s.jerk_s) * s.jerk_s >= beta * (1.0 - 1e-9));
            let (f, cap_f) = s.eval(s.duration_s);
            assert!((f - 1.0).abs() < 1e-12);
            assert!((cap_f - s.duration_s / 2.0).abs() < 1e-12);
            // Continuity at the symmetry point.
            let h = s.duration_s / 2.0;
            let (a, b) = s.eval(h - 1e-12);
            let (c, d) = s.eval(h + 1e-12);
            assert!((a - c).abs() < 1e-9 && (b - d).abs() < 1e-9);
        }
    }

    #[test]
    fn reach_is_feasible_and_tight() {
        let t = Tangential {
            acc_mm_s2: 500.0,
            jerk_mm_s3: 50_000.0,
        };
        let v = t.reach_mm_s(0.0, 1.0, 1000.0);
        assert!(t.distance_mm(0.0, v) <= 1.0);
        assert!(t.distance_mm(0.0, v * 1.001) > 1.0);
        // Both regimes (below and above the full acceleration), from rest and from speed,
        // over distances from µm to metres: feasible, and tight to 1e-9.
        for v0 in [0.0, 0.3, 5.0, 40.0, 200.0] {
            for d in [1e-6, 1e-3, 0.05, 0.5, 3.0, 40.0, 2000.0] {
                let v = t.reach_mm_s(v0, d, 1e6);
                assert!(t.distance_mm(v0, v) <= d, "v0 {v0} d {d}");
                let above = v0 + (v - v0) * (1.0 + 1e-9) + 1e-12;
                assert!(t.distance_mm(v0, above) > d, "v0 {v0} d {d}: not tight");
            }
        }
    }
}
