//! Where a stop may leave the planned timing: the stretch of path ahead of the tool made of
//! straight segments and circular arcs joined tangentially, and the tangential
//! acceleration and jerk a stop along it may use (issue 14: "a hold still stops as fast as
//! the limits allow").
//!
//! Why: along a path whose geometry does not depend on the timing (a line, an arc, a
//! tangent run of them; not a corner blend, whose shape is made for one speed) the
//! interpolator may follow any speed profile, so a hold can follow the fastest
//! [`super::line_stop::LineStop`] instead of braking the time scale at the rates the
//! planner left free. On a line that stop has the axes' full limits along it. On an arc
//! part of the acceleration is the normal `v²κ`, and the jerk has the parts of a turning
//! acceleration: with tangential speed `v`, acceleration `a` and jerk `j`,
//!
//! `acc = a·T + v²κ·N`, `jerk = (j − κ²v³)·T + 3κva·N` (plus `v²Δκ/dt` in the one servo
//! period that crosses a curvature step `Δκ`),
//!
//! and each X/Y component is bounded by the norm of these vectors. [`Reach::limits`] gives
//! the tangential bounds that keep both norms within the X/Y limits for every speed up to
//! `v`: they only grow as the speed falls, so a stop planned with them stays feasible, and
//! one re-planned later from a lower speed is at least as fast.

use super::limits::AxisMax;
use super::line_stop::LineStop;
use super::segment::{norm, Segment, SegmentKind};
use crate::gcode::NUM_AXES;

/// Tangents meeting closer than this (unit vectors' difference) continue the path: the
/// planner's own test for a junction that needs no blend.
const TANGENT_TOL: f64 = 1e-9;

/// A stretch a stop may run along: its unit tangents at both ends and its curvature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// Unit tangent at the start.
    pub t_in: [f64; NUM_AXES],
    /// Unit tangent at the end.
    pub t_out: [f64; NUM_AXES],
    /// Signed curvature in the XY plane, 1/mm (0 for a line).
    pub kappa: f64,
}

/// The piece `s` is, or `None` for what a stop cannot leave its timing on: a corner blend
/// (its velocity turns but it is no arc), a dwell, a segment at rest throughout.
pub fn piece(s: &Segment) -> Option<Piece> {
    if s.kind == SegmentKind::Dwell || s.length_mm <= 0.0 {
        return None;
    }
    if s.curvature_per_mm != 0.0 {
        let tangent = |h: f64| {
            let mut t = [0.0; NUM_AXES];
            (t[1], t[0]) = h.sin_cos();
            t
        };
        let h1 = s.heading_rad + s.curvature_per_mm * s.length_mm;
        return Some(Piece {
            t_in: tangent(s.heading_rad),
            t_out: tangent(h1),
            kappa: s.curvature_per_mm,
        });
    }
    let (n0, n1) = (norm(&s.v0_mm_s), norm(&s.v1_mm_s));
    let big = n0.max(n1);
    if big <= 0.0 {
        return None;
    }
    let along = if n1 >= n0 { &s.v1_mm_s } else { &s.v0_mm_s };
    let u = along.map(|c| c / big);
    let collinear = (0..NUM_AXES).all(|i| {
        (s.v0_mm_s[i] - n0 * u[i]).abs() <= 1e-9 * big
            && (s.v1_mm_s[i] - n1 * u[i]).abs() <= 1e-9 * big
    });
    collinear.then_some(Piece {
        t_in: u,
        t_out: u,
        kappa: 0.0,
    })
}

/// The stretch from the tool to the end of the pieces taken so far, and what bounds a stop
/// along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// Path length from the tool to the end of the last piece, mm.
    pub room_mm: f64,
    kind: SegmentKind,
    last: Piece,
    /// Lowest velocity cap along the pieces, mm/s.
    vel: f64,
    /// Tangential acceleration and jerk of the straight pieces (infinite without any).
    line_acc: f64,
    line_jerk: f64,
    /// Vector limits of an XY arc: the smaller of X's and Y's.
    arc_acc: f64,
    arc_jerk: f64,
    /// Largest |κ| of the pieces, 1/mm.
    kappa: f64,
    /// Largest curvature step at a junction ahead, 1/mm.
    step: f64,
}

impl Reach {
    /// The rest of segment `s` after `from_mm` of it, or `None` when it is no [`piece`].
    pub fn new(s: &Segment, from_mm: f64, max: &AxisMax) -> Option<Reach> {
        let p = piece(s)?;
        let mut r = Reach {
            room_mm: (s.length_mm - from_mm).max(0.0),
            kind: s.kind,
            last: p,
            vel: f64::INFINITY,
            line_acc: f64::INFINITY,
            line_jerk: f64::INFINITY,
            arc_acc: max.acc[0].min(max.acc[1]),
            arc_jerk: max.jerk[0].min(max.jerk[1]),
            kappa: 0.0,
            step: 0.0,
        };
        r.take(&p, max);
        Some(r)
    }

    /// Adds `next` if it continues the path (a piece of the same kind, tangent to the last,
    /// entered at speed) and returns whether it did.
    pub fn extend(&mut self, next: &Segment, max: &AxisMax) -> bool {
        let Some(p) = piece(next) else {
            return false;
        };
        let tangent = (0..NUM_AXES).all(|i| (p.t_in[i] - self.last.t_out[i]).abs() <= TANGENT_TOL);
        if next.kind != self.kind || !tangent || norm(&next.v0_mm_s) <= 0.0 {
            return false;
        }
        self.step = self.step.max((p.kappa - self.last.kappa).abs());
        self.room_mm += next.length_mm;
        self.last = p;
        self.take(&p, max);
        true
    }

    fn take(&mut self, p: &Piece, max: &AxisMax) {
        if p.kappa == 0.0 {
            let (v, a, j) = max.along(&p.t_in);
            self.vel = self.vel.min(v);
            self.line_acc = self.line_acc.min(a);
            self.line_jerk = self.line_jerk.min(j);
        } else {
            self.vel = self.vel.min(max.vel[0].min(max.vel[1]));
            self.kappa = self.kappa.max(p.kappa.abs());
        }
    }

    /// Velocity cap along the reach, mm/s.
    pub fn vel(&self) -> f64 {
        self.vel
    }

    /// Tangential `(acceleration, jerk)` a stop may use at every speed up to `v` (mm/s) along
    /// the reach, servo period `dt`; `None` where the arcs leave none (their normal
    /// acceleration or jerk at `v` already takes the whole limit).
    pub fn limits(&self, v: f64, dt: f64) -> Option<(f64, f64)> {
        let (mut acc, mut jerk) = (self.line_acc, self.line_jerk);
        if self.kappa > 0.0 || self.step > 0.0 {
            let (big_a, big_j, k) = (self.arc_acc, self.arc_jerk, self.kappa);
            let normal = v * v * k;
            let normal_jerk = 3.0 * k * v * big_a + v * v * self.step / dt;
            if normal >= big_a || normal_jerk >= big_j {
                return None;
            }
            let tangential_jerk =
                (big_j * big_j - normal_jerk * normal_jerk).sqrt() - k * k * v * v * v;
            if tangential_jerk <= 0.0 {
                return None;
            }
            acc = acc.min((big_a * big_a - normal * normal).sqrt());
            jerk = jerk.min(tangential_jerk);
        }
        (acc.is_finite() && jerk.is_finite()).then_some((acc, jerk))
    }

    /// True when the bounds depend on the speed (an arc or a curvature step in reach): a
    /// stop along it gains by being re-planned as it slows.
    pub fn turns(&self) -> bool {
        self.kappa > 0.0 || self.step > 0.0
    }
}

/// The fastest stop along `reach` from tangential speed `v` > 0 and acceleration `a`:
/// `None` where none stays within the limits (the arcs leave no room at
/// the speed it reaches, it would exceed the velocity cap while it ends an acceleration,
/// or `a` is already beyond what the reach allows).
///
/// Begun while still accelerating, the speed first rises by `a²/2J` and the bounds must
/// hold up to that peak; they fall as the speed rises, so the peak is found by a short
/// fixed-point iteration and checked.
pub fn plan(reach: &Reach, v: f64, a: f64, dt: f64) -> Option<LineStop> {
    let rise = |jerk: f64| a.max(0.0).powi(2) / (2.0 * jerk);
    let (_, mut jerk) = reach.limits(v, dt)?;
    let mut peak = v + rise(jerk);
    for _ in 0..4 {
        let (acc, j) = reach.limits(peak, dt)?;
        jerk = j;
        if v + rise(jerk) <= peak {
            if peak > reach.vel() || a.abs() > acc * (1.0 + 1e-9) {
                return None;
            }
            return LineStop::new(v, a, acc, jerk);
        }
        peak = (v + rise(jerk)) * (1.0 + 1e-9);
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(v0: [f64; 2], v1: [f64; 2], kappa: f64, heading: f64, len: f64) -> Segment {
        let mut a = [0.0; NUM_AXES];
        let mut b = [0.0; NUM_AXES];
        (a[0], a[1], b[0], b[1]) = (v0[0], v0[1], v1[0], v1[1]);
        Segment {
            curvature_per_mm: kappa,
            heading_rad: heading,
            ..Segment::for_test(a, b, 1.0, 0.1, len)
        }
    }

    fn max() -> AxisMax {
        AxisMax {
            vel: [50.0; NUM_AXES],
            acc: [500.0; NUM_AXES],
            jerk: [50_000.0; NUM_AXES],
        }
    }

    /// A line along X has X's own limits; a diagonal one the limits divided by its share.
    #[test]
    fn a_line_has_the_full_limits_along_it() {
        let r = Reach::new(&seg([10.0, 0.0], [10.0, 0.0], 0.0, 0.0, 5.0), 1.0, &max()).unwrap();
        assert_eq!(r.room_mm, 4.0);
        assert_eq!(r.limits(50.0, 1e-3), Some((500.0, 50_000.0)));
        assert!(!r.turns());
        let d = 10.0 / 2f64.sqrt();
        let r = Reach::new(&seg([d, d], [d, d], 0.0, 0.0, 5.0), 0.0, &max()).unwrap();
        let (a, j) = r.limits(50.0, 1e-3).unwrap();
        assert!((a - 500.0 * 2f64.sqrt()).abs() < 1e-9, "{a}");
        assert!((j - 50_000.0 * 2f64.sqrt()).abs() < 1e-6, "{j}");
    }

    /// On an arc the tangential share is what the normal acceleration leaves, and it grows
    /// as the speed falls; none is left at the normal-acceleration limit.
    #[test]
    fn an_arc_leaves_the_rest_of_the_acceleration_to_the_stop() {
        let r = Reach::new(
            &seg(
                [0.0, 47.0],
                [0.0, 47.0],
                0.2,
                std::f64::consts::FRAC_PI_2,
                3.0,
            ),
            0.0,
            &max(),
        )
        .unwrap();
        assert!(r.turns());
        let (a, j) = r.limits(47.4, 1e-3).unwrap();
        let normal = 47.4 * 47.4 * 0.2;
        assert!((a - (500.0f64.powi(2) - normal * normal).sqrt()).abs() < 1e-9);
        assert!(j > 40_000.0 && j < 50_000.0, "{j}");
        let mut last = (a, j);
        for v in [40.0, 30.0, 20.0, 10.0, 1.0] {
            let now = r.limits(v, 1e-3).unwrap();
            assert!(
                now.0 > last.0 && now.1 > last.1,
                "{v}: {now:?} after {last:?}"
            );
            last = now;
        }
        assert_eq!(r.limits(50.0, 1e-3), None, "v²κ = A");
    }

    /// Only tangent pieces of the same kind continue a reach; a blend (turning velocity, no
    /// arc) or a kink ends it, and the curvature step at a junction costs jerk.
    #[test]
    fn only_tangent_lines_and_arcs_continue_a_reach() {
        let m = max();
        let line = seg([10.0, 0.0], [10.0, 0.0], 0.0, 0.0, 2.0);
        let mut r = Reach::new(&line, 0.0, &m).unwrap();
        let blend = seg([10.0, 0.0], [0.0, 10.0], 0.0, 0.0, 1.0);
        assert!(!r.extend(&blend, &m));
        let kink = seg([10.0, 1.0], [10.0, 1.0], 0.0, 0.0, 1.0);
        assert!(!r.extend(&kink, &m));
        let mut rapid = line;
        rapid.kind = SegmentKind::Rapid;
        assert!(!r.extend(&rapid, &m));
        let before = r.limits(20.0, 1e-3).unwrap();
        let arc = seg([10.0, 0.0], [0.0, 10.0], 0.01, 0.0, 2.0);
        assert!(r.extend(&arc, &m));
        assert_eq!(r.room_mm, 4.0);
        let after = r.limits(20.0, 1e-3).unwrap();
        assert!(
            after.1 < before.1,
            "the step costs jerk: {after:?} {before:?}"
        );
    }
}
