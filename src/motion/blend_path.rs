//! The geometry of a corner blend as a path, for stops that run along it at their own
//! speed (issue 14: "a hold still stops as fast as the limits allow").
//!
//! Why: a blend is planned as a velocity transition in time, `w(σ) = v0 + Δv·f(σ)` (see
//! [`super::blend`]), so its path length and curvature are not stored anywhere. A stop that
//! leaves the planned timing still follows the same curve `p(σ)` (any timing of it is a
//! time scaling), but needs, like on a line or an arc, the length it runs along and how
//! much the curve turns there:
//!
//! - the path length `s(σ) = ∫|w|`, by Gauss–Legendre quadrature over the shape's phases
//!   (the integrand is smooth within each), and its inverse by safeguarded Newton steps;
//! - the curvature `κ = |v0 ∧ v1|·f'/|w|³` (the wedge of `w` and `Δv·f'` is that of `v0`
//!   and `v1`, a constant), bounded by its value at the smallest `|w|`;
//! - its rate along the path, `dκ/ds = |v0 ∧ v1|·(f''/|w|⁴ − 3f'²(w·Δv)/|w|⁶)`, bounded
//!   term by term.
//!
//! All of it is a fixed amount of arithmetic on the segment alone (no allocation), used by
//! the interpolator only while a stop runs.

use super::segment::{norm, Segment};
use crate::gcode::NUM_AXES;

/// Gauss–Legendre nodes and weights on [-1, 1], 8 points (exact for degree 15).
const GL_X: [f64; 4] = [
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
const GL_W: [f64; 4] = [
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// Sharpest turn a stop follows through a blend: where `|w|` dips below this share of its
/// larger end speed (a turn of about 120° for equal speeds), the curve is too tight for the
/// quadrature's accuracy and the stop's bounds; such corners are passed by time scaling.
const MIN_SPEED_SHARE: f64 = 0.5;

/// A corner blend's curve: what a stop needs to run along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlendPath {
    v0: [f64; NUM_AXES],
    dv: [f64; NUM_AXES],
    /// `|v0 ∧ v1|`, mm²/s².
    wedge: f64,
    /// Smallest speed `|w|` along the blend (planned timing), mm/s.
    w_min: f64,
    duration_s: f64,
    jerk_s: f64,
}

impl BlendPath {
    /// The curve of `s`, if it is a corner blend a stop may follow: no arc, no window, both
    /// end velocities non-zero and not parallel, and no sharper than [`MIN_SPEED_SHARE`].
    pub fn of(s: &Segment) -> Option<BlendPath> {
        if s.curvature_per_mm != 0.0 || s.window.is_some() || s.duration_s <= 0.0 {
            return None;
        }
        let (n0, n1) = (norm(&s.v0_mm_s), norm(&s.v1_mm_s));
        if n0 <= 0.0 || n1 <= 0.0 {
            return None;
        }
        let dot: f64 = (0..NUM_AXES).map(|i| s.v0_mm_s[i] * s.v1_mm_s[i]).sum();
        let wedge = ((n0 * n1).powi(2) - dot * dot).max(0.0).sqrt();
        if wedge <= 1e-9 * n0 * n1 {
            return None;
        }
        let dv: [f64; NUM_AXES] = std::array::from_fn(|i| s.v1_mm_s[i] - s.v0_mm_s[i]);
        let dv2: f64 = dv.iter().map(|x| x * x).sum();
        let v0_dv: f64 = (0..NUM_AXES).map(|i| s.v0_mm_s[i] * dv[i]).sum();
        let f_min = (-v0_dv / dv2).clamp(0.0, 1.0);
        let w_min = (n0 * n0 + 2.0 * f_min * v0_dv + f_min * f_min * dv2)
            .max(0.0)
            .sqrt();
        if w_min < MIN_SPEED_SHARE * n0.max(n1) {
            return None;
        }
        Some(BlendPath {
            v0: s.v0_mm_s,
            dv,
            wedge,
            w_min,
            duration_s: s.duration_s,
            jerk_s: s.jerk_s,
        })
    }

    fn shape(&self) -> super::profile::Shape {
        super::profile::Shape {
            duration_s: self.duration_s,
            jerk_s: self.jerk_s,
        }
    }

    /// Path speed `|w(σ)|` in the planned timing, mm/s.
    pub fn speed(&self, sigma_s: f64) -> f64 {
        let f = self.shape().eval(sigma_s).0;
        (0..NUM_AXES)
            .map(|i| (self.v0[i] + self.dv[i] * f).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Rate of the path speed `d|w|/dσ = (w·Δv)·f'/|w|` in the planned timing, mm/s².
    pub fn tangential_acc(&self, sigma_s: f64) -> f64 {
        let sh = self.shape();
        let f = sh.eval(sigma_s).0;
        let (mut w2, mut w_dv) = (0.0, 0.0);
        for i in 0..NUM_AXES {
            let w = self.v0[i] + self.dv[i] * f;
            w2 += w * w;
            w_dv += w * self.dv[i];
        }
        w_dv * sh.rate(sigma_s) / w2.sqrt()
    }

    /// Path length from the blend's start to planned time `σ` (clamped), mm.
    pub fn length_to(&self, sigma_s: f64) -> f64 {
        let big_t = self.duration_s;
        let end = sigma_s.clamp(0.0, big_t);
        let tj = self.jerk_s.min(0.5 * big_t);
        // The shape's phases (and the middle, where |w| is smallest for equal speeds): the
        // integrand is a smooth function of σ within each.
        let cuts = [0.0, tj, 0.5 * big_t, big_t - tj, big_t];
        let mut total = 0.0;
        for pair in cuts.windows(2) {
            let (a, b) = (pair[0], pair[1].min(end));
            if b <= a {
                // An empty phase (no constant-acceleration phase: `tj = T/2`), or past `σ`.
                continue;
            }
            let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
            let mut sum = 0.0;
            for (x, w) in GL_X.iter().zip(GL_W) {
                sum += w * (self.speed(mid - half * x) + self.speed(mid + half * x));
            }
            total += half * sum;
        }
        total
    }

    /// Whole path length of the blend, mm.
    pub fn length(&self) -> f64 {
        self.length_to(self.duration_s)
    }

    /// Planned time `σ` at which the path length from the start reaches `d_mm` (clamped to
    /// the blend), found from `lo_s` on (a time known not to be past it): Newton steps on
    /// `s(σ) − d` with `ds/dσ = |w| ≥ w_min`, kept within a shrinking bracket.
    pub fn time_at(&self, d_mm: f64, lo_s: f64) -> f64 {
        let total = self.length();
        if d_mm >= total {
            return self.duration_s;
        }
        let (mut lo, mut hi) = (lo_s.clamp(0.0, self.duration_s), self.duration_s);
        if d_mm <= self.length_to(lo) {
            return lo;
        }
        let mut t = lo + (d_mm - self.length_to(lo)) / self.speed(lo).max(self.w_min);
        for _ in 0..40 {
            if !(t > lo && t < hi) {
                t = 0.5 * (lo + hi);
            }
            let e = self.length_to(t) - d_mm;
            if e.abs() <= 1e-13 * total.max(1.0) {
                return t;
            }
            if e > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            t -= e / self.speed(t);
            if hi - lo <= 1e-15 * self.duration_s {
                return lo;
            }
        }
        t.clamp(lo, hi)
    }

    /// Upper bounds on the curvature `|κ|` (1/mm) and on its rate along the path `|dκ/ds|`
    /// (1/mm²) over the whole blend. The rate is bounded per phase of the shape: in the jerk
    /// phases `|f''|` is at its peak but `f'` and `w·Δv` are small (near the ends), in the
    /// middle phase `f'' = 0`; bounding both terms at once over the whole blend would double
    /// the bound of a gentle corner.
    pub fn curvature_bounds(&self) -> (f64, f64) {
        let sh = self.shape();
        let (rate, jerk) = (sh.peak_rate(), sh.peak_jerk());
        let w = self.w_min;
        let kappa = self.wedge * rate / w.powi(3);
        let dv2: f64 = self.dv.iter().map(|x| x * x).sum();
        let v0_dv: f64 = (0..NUM_AXES).map(|i| self.v0[i] * self.dv[i]).sum();
        // `w·Δv` is linear in f: its largest size over [f_a, f_b] is at an end.
        let w_dv = |fa: f64, fb: f64| (v0_dv + fa * dv2).abs().max((v0_dv + fb * dv2).abs());
        let tj = self.jerk_s.min(0.5 * self.duration_s);
        let f_tj = sh.eval(tj).0;
        let f_rate_tj = sh.rate(tj);
        let ends = jerk / w.powi(4)
            + 3.0 * f_rate_tj * f_rate_tj * w_dv(0.0, f_tj).max(w_dv(1.0 - f_tj, 1.0)) / w.powi(6);
        let middle = 3.0 * rate * rate * w_dv(f_tj, 1.0 - f_tj) / w.powi(6);
        (kappa, self.wedge * ends.max(middle))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::profile::Shape;

    /// A 40° blend at 40 mm/s in XY with an S-curve of 8 ms, jerk phases of 2 ms.
    fn blend(turn_deg: f64, speeds: (f64, f64)) -> Segment {
        let th = turn_deg.to_radians();
        let mut a = [0.0; NUM_AXES];
        let mut b = [0.0; NUM_AXES];
        a[0] = speeds.0;
        (b[0], b[1]) = (speeds.1 * th.cos(), speeds.1 * th.sin());
        Segment::for_test(a, b, 0.008, 0.002, 0.3)
    }

    /// Path length by a fine sum of the distances between poses of the planned timing.
    fn polyline_length(s: &Segment, upto: f64, n: usize) -> f64 {
        let mut len = 0.0;
        let mut last = s.pose_at(0.0);
        for k in 1..=n {
            let p = s.pose_at(upto * k as f64 / n as f64);
            len += (0..NUM_AXES)
                .map(|i| (p[i] - last[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            last = p;
        }
        len
    }

    #[test]
    fn length_matches_the_planned_poses_and_inverts() {
        for (turn, speeds) in [
            (40.0, (40.0, 40.0)),
            (5.0, (50.0, 50.0)),
            (100.0, (30.0, 20.0)),
        ] {
            let mut s = blend(turn, speeds);
            if turn == 5.0 {
                // No constant-acceleration phase.
                s.jerk_s = 0.5 * s.duration_s;
            }
            let b = BlendPath::of(&s).unwrap();
            for frac in [0.1, 0.5, 0.77, 0.999_999] {
                let t = frac * s.duration_s;
                let exact = polyline_length(&s, t, 200_000);
                let got = b.length_to(t);
                assert!(
                    (got - exact).abs() < 1e-9,
                    "{turn}° {frac}: {got} vs {exact}"
                );
                let back = b.time_at(got, 0.0);
                assert!((back - t).abs() < 1e-12, "{turn}° {frac}: {back} vs {t}");
            }
            // Shorter than the chord approximation V·T of the planner.
            assert!(b.length() < 0.5 * (speeds.0 + speeds.1) * s.duration_s);
        }
    }

    #[test]
    fn curvature_bounds_hold_along_the_blend() {
        for (turn, speeds) in [
            (40.0, (40.0, 40.0)),
            (5.0, (50.0, 50.0)),
            (100.0, (30.0, 20.0)),
        ] {
            let s = blend(turn, speeds);
            let b = BlendPath::of(&s).unwrap();
            let (k_max, k_rate) = b.curvature_bounds();
            // Curvature from the planned velocity and acceleration, and its rate by
            // differences along the path.
            let sh = Shape {
                duration_s: s.duration_s,
                jerk_s: s.jerk_s,
            };
            let kappa = |t: f64| {
                let f = sh.eval(t).0;
                let w: Vec<f64> = (0..2).map(|i| b.v0[i] + b.dv[i] * f).collect();
                let a: Vec<f64> = (0..2).map(|i| b.dv[i] * sh.rate(t)).collect();
                (w[0] * a[1] - w[1] * a[0]).abs() / (w[0].hypot(w[1])).powi(3)
            };
            let (mut seen_k, mut seen_rate) = (0.0f64, 0.0f64);
            let n = 4000;
            for k in 0..n {
                let (t0, t1) = (
                    s.duration_s * k as f64 / n as f64,
                    s.duration_s * (k + 1) as f64 / n as f64,
                );
                seen_k = seen_k.max(kappa(t0));
                let ds = b.length_to(t1) - b.length_to(t0);
                seen_rate = seen_rate.max((kappa(t1) - kappa(t0)).abs() / ds);
            }
            assert!(
                seen_k <= k_max * (1.0 + 1e-9),
                "{turn}°: {seen_k} > {k_max}"
            );
            assert!(
                seen_rate <= k_rate * 1.001,
                "{turn}°: {seen_rate} > {k_rate}"
            );
            if speeds.0 == speeds.1 {
                // Symmetric: the curvature bound is the curvature at the middle.
                assert!(seen_k >= 0.999 * k_max, "{turn}°: {seen_k} < {k_max}");
            }
            // The path speed's rate is the difference quotient of the speed.
            for t in [0.001, 0.003, 0.0047, 0.007] {
                let h = 1e-7;
                let fd = (b.speed(t + h) - b.speed(t - h)) / (2.0 * h);
                assert!((b.tangential_acc(t) - fd).abs() < 1e-3, "{turn}° at {t}");
            }
        }
    }

    #[test]
    fn straight_transitions_and_sharp_turns_are_no_blend_path() {
        assert!(BlendPath::of(&blend(0.0, (40.0, 20.0))).is_none());
        assert!(BlendPath::of(&blend(150.0, (40.0, 40.0))).is_none());
        assert!(BlendPath::of(&blend(110.0, (40.0, 40.0))).is_some());
    }
}
