//! Corner blends: at a junction the velocity vector moves from `V·u_a` to `V·u_b` along a
//! straight line in velocity space with the S-curve shape (see [`super::profile`]). The
//! blend starts `V·T/2` before the corner on the first move and ends `V·T/2` after it on the
//! second, exactly; its farthest point from the corner is `V·|u_b - u_a|·F(T/2)`, which is
//! kept within the path tolerance. Per-axis acceleration and jerk are those of the shape, so
//! no blend can overshoot the limits, however small (cf. LinuxCNC issue #3773).

use super::limits::Limits;

/// Largest share of each adjacent move a blend may use: with 1/2, blends on a dense curve
/// may tile the chords completely; the lookahead passes then lower junction speeds (which
/// shortens the blends) wherever a move needs straight room to change speed.
pub const BLEND_ROOM_FRACTION: f64 = 0.5;
use super::profile::{bisect_max, Shape};
use crate::gcode::NUM_AXES;

/// Geometry of one junction, independent of speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// `u_b - u_a`.
    pub du: [f64; NUM_AXES],
    /// |du|.
    pub du_norm: f64,
    /// Acceleration coefficient of `du` (see `Limits::change_coefficients`).
    pub alpha: f64,
    /// Jerk coefficient.
    pub beta: f64,
}

impl Corner {
    /// Corner between directions `u_a` and `u_b`.
    pub fn new(u_a: &[f64; NUM_AXES], u_b: &[f64; NUM_AXES], lim: &Limits) -> Self {
        let mut du = [0.0; NUM_AXES];
        for i in 0..NUM_AXES {
            du[i] = u_b[i] - u_a[i];
        }
        let du_norm = du.iter().map(|x| x * x).sum::<f64>().sqrt();
        let (alpha, beta) = lim.change_coefficients(&du);
        Corner {
            du,
            du_norm,
            alpha,
            beta,
        }
    }

    /// True when the directions agree (no blend needed).
    pub fn is_straight(&self) -> bool {
        self.du_norm < 1e-9
    }

    /// Shape of the blend at speed `v`.
    pub fn shape(&self, v_mm_s: f64) -> Shape {
        Shape::for_bounds(v_mm_s * self.alpha, v_mm_s * self.beta)
    }

    /// Length of each adjacent move the blend at speed `v` uses, mm.
    pub fn half_length_mm(&self, v_mm_s: f64) -> f64 {
        if self.is_straight() {
            return 0.0;
        }
        0.5 * v_mm_s * self.shape(v_mm_s).duration_s
    }

    /// Farthest distance of the blend from the corner, mm.
    pub fn deviation_mm(&self, v_mm_s: f64) -> f64 {
        let s = self.shape(v_mm_s);
        v_mm_s * self.du_norm * s.eval(0.5 * s.duration_s).1
    }

    /// Highest junction speed ≤ `cap` whose blend fits in half of each adjacent move and
    /// stays within `tolerance_mm`.
    pub fn max_speed(&self, cap_mm_s: f64, len_a_mm: f64, len_b_mm: f64, tolerance_mm: f64) -> f64 {
        self.max_speed_within(cap_mm_s, [len_a_mm, len_b_mm], tolerance_mm, 1e-9)
    }

    /// [`Self::max_speed`] found to `rel` of the cap (the answer always fits): estimates
    /// (`motion::fit_choice`) need far fewer bisection steps than the plan itself.
    pub fn max_speed_within(
        &self,
        cap_mm_s: f64,
        [len_a_mm, len_b_mm]: [f64; 2],
        tolerance_mm: f64,
        rel: f64,
    ) -> f64 {
        if self.is_straight() {
            return cap_mm_s;
        }
        let room = BLEND_ROOM_FRACTION * len_a_mm.min(len_b_mm);
        let ok = |v: f64| self.half_length_mm(v) <= room && self.deviation_mm(v) <= tolerance_mm;
        if ok(cap_mm_s) {
            return cap_mm_s;
        }
        // In closed form (below); a hair lower so that rounding cannot break `ok`, which is
        // checked. The bisection stays as the fallback it never needs to be in the tests.
        let v = cap_mm_s
            .min(self.speed_for_half_length(room))
            .min(self.speed_for_deviation(tolerance_mm));
        let v = v * (1.0 - 1e-12);
        if v >= 0.0 && ok(v) {
            return v;
        }
        bisect_max(0.0, cap_mm_s, rel, ok)
    }

    /// Speed at which the blend becomes accelerating-limited: below it the shape is two
    /// jerk phases (`T = 2·√(v·β)`), above it `T = v·α + β/α`.
    fn regime_speed(&self) -> f64 {
        self.beta / (self.alpha * self.alpha)
    }

    /// Highest speed whose blend uses at most `room` of each move: `v·T/2 ≤ room`, i.e.
    /// `v^1.5·√β ≤ room` in the jerk regime and `α/2·v² + β/(2α)·v ≤ room` above it.
    fn speed_for_half_length(&self, room: f64) -> f64 {
        let (a, b) = (self.alpha, self.beta);
        let v = (room / b.sqrt()).powf(2.0 / 3.0);
        if v <= self.regime_speed() {
            return v;
        }
        let p = b / (2.0 * a);
        (-p + (p * p + 2.0 * a * room).sqrt()) / a
    }

    /// Highest speed whose blend stays within `tol` of the corner: the farthest point is
    /// `v·|du|·F(T/2)`, which is `v^1.5·|du|·√β/6` in the jerk regime and
    /// `|du|/α·(w²/8 + tj²/24)` with `w = v·α`, `tj = β/α` above it.
    fn speed_for_deviation(&self, tol: f64) -> f64 {
        let (a, b) = (self.alpha, self.beta);
        let v = (6.0 * tol / (self.du_norm * b.sqrt())).powf(2.0 / 3.0);
        if v <= self.regime_speed() {
            return v;
        }
        let tj = b / a;
        let w2 = 8.0 * (tol * a / self.du_norm - tj * tj / 24.0);
        w2.max(0.0).sqrt() / a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::segment::Segment;
    use crate::motion::MotionConfig;

    fn unit(x: f64, y: f64) -> [f64; NUM_AXES] {
        let n = x.hypot(y);
        let mut u = [0.0; NUM_AXES];
        u[0] = x / n;
        u[1] = y / n;
        u
    }

    /// The closed-form junction speed is the bisection's (to its 1e-9), and always fits:
    /// corners from 1° to 179°, rooms and tolerances from µm to mm, both shape regimes.
    #[test]
    fn closed_form_junction_speed_matches_the_bisection() {
        let lim = Limits::new(&MotionConfig::default());
        for deg in [1.0f64, 5.0, 30.0, 90.0, 150.0, 179.0] {
            let r = deg.to_radians();
            let c = Corner::new(&unit(1.0, 0.0), &unit(r.cos(), r.sin()), &lim);
            for len in [0.001, 0.02, 0.1, 1.0, 10.0, 100.0] {
                for tol in [0.0001, 0.001, 0.01, 0.1, 1.0] {
                    let cap = 200.0;
                    let v = c.max_speed(cap, len, 2.0 * len, tol);
                    let room = BLEND_ROOM_FRACTION * len;
                    let ok = |v: f64| c.half_length_mm(v) <= room && c.deviation_mm(v) <= tol;
                    let b = bisect_max(0.0, cap, 1e-12, ok);
                    assert!(ok(v), "{deg}° len {len} tol {tol}: {v} does not fit");
                    assert!(
                        (v - b).abs() <= 1e-9 * cap,
                        "{deg}° len {len} tol {tol}: {v} vs {b}"
                    );
                }
            }
        }
    }

    /// The blend segment starts and ends exactly on the two moves, and no point of it is
    /// farther from the corner than `deviation_mm` says.
    #[test]
    fn blend_geometry_matches_its_formulas() {
        let lim = Limits::new(&MotionConfig::default());
        for (deg, v) in [
            (5.0f64, 50.0),
            (45.0, 30.0),
            (90.0, 20.0),
            (170.0, 5.0),
            (179.9, 1.0),
        ] {
            let (ua, ub) = (
                unit(1.0, 0.0),
                unit(deg.to_radians().cos(), deg.to_radians().sin()),
            );
            let c = Corner::new(&ua, &ub, &lim);
            let sh = c.shape(v);
            let d = c.half_length_mm(v);
            let mut start = [0.0; NUM_AXES];
            start[0] = -d; // corner at the origin
            let seg = Segment {
                start_mm: start,
                end_mm: ub.map(|x| x * d),
                ..Segment::for_test(
                    ua.map(|x| x * v),
                    ub.map(|x| x * v),
                    sh.duration_s,
                    sh.jerk_s,
                    0.0,
                )
            };
            let end = seg.integrated_end_mm();
            assert!(
                (end[0] - ub[0] * d).abs() < 1e-12 && (end[1] - ub[1] * d).abs() < 1e-12,
                "{deg}"
            );
            let mut far = 0.0f64;
            for i in 0..=1000 {
                let p = seg.pose_at(sh.duration_s * i as f64 / 1000.0);
                far = far.max(p[0].hypot(p[1]));
            }
            // The farthest point from the corner is where the blend starts (d away); the
            // deviation bound is about the point nearest to the corner: the blend passes
            // within it, and the bound is never exceeded by the mid-point.
            let mid = seg.pose_at(sh.duration_s / 2.0);
            assert!(
                (mid[0].hypot(mid[1]) - c.deviation_mm(v)).abs() < 1e-9,
                "{deg}"
            );
            assert!(far <= d + 1e-12);
        }
    }
}
