//! What bounds a stop along one piece of the path ahead (a line, an arc or a corner blend;
//! see [`super::path_stop`]): the tangential acceleration and jerk it may use so that every
//! axis stays within its limits, at every speed up to a given one.
//!
//! Why a module of its own: the bounds are the arithmetic of a turning acceleration and
//! jerk against per-axis limits, independent of how the path ahead is gathered and of how
//! the stop is planned along it. Each bound is the larger of two sufficient conditions: the
//! vector one (the norm within the weakest axis' limit, exact for any direction in the
//! turn's plane) and the per-axis one (`|a|·|T_i| + a_n·|N_i| ≤ A_i` with the largest shares
//! of each axis in the tangent and the normal along the turn, better on a diagonal).

use super::limits::AxisMax;
use super::path_stop::Piece;
use crate::gcode::NUM_AXES;

/// Decelerations tried for a stop through turning pieces (shares of the most the
/// acceleration allows): a harder deceleration adds normal jerk `3κva` and leaves less
/// tangential jerk, so the one giving the shortest stop is taken.
const ACC_SHARES: [f64; 6] = [1.0, 0.8, 0.6, 0.4, 0.25, 0.1];

/// Largest `|c·cos φ + s·sin φ|` for `φ` in `[0, θ]`.
fn amplitude_max(c: f64, s: f64, theta: f64) -> f64 {
    let r = c.hypot(s);
    if r == 0.0 {
        return 0.0;
    }
    let peak = s.atan2(c).rem_euclid(std::f64::consts::PI);
    if theta >= std::f64::consts::PI || peak <= theta {
        return r;
    }
    c.abs().max((c * theta.cos() + s * theta.sin()).abs())
}

/// Per-axis shares of tangent and normal along a planar turn by `theta` (rad) from the unit
/// tangent `t_in` toward the unit vector `e2` orthogonal to it: the tangent is
/// `t_in·cos φ + e2·sin φ` and the normal `e2·cos φ − t_in·sin φ`, `φ` in `[0, θ]`.
pub(super) fn turn_shares(
    t_in: &[f64; NUM_AXES],
    e2: &[f64; NUM_AXES],
    theta: f64,
) -> ([f64; NUM_AXES], [f64; NUM_AXES]) {
    (
        std::array::from_fn(|i| amplitude_max(t_in[i], e2[i], theta)),
        std::array::from_fn(|i| amplitude_max(e2[i], -t_in[i], theta)),
    )
}

/// What bounds a stop along one piece of a reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bounds {
    /// Path length from the reach's origin to the piece's start, mm (0 for the first).
    pub(super) at_mm: f64,
    /// Velocity cap, mm/s.
    pub(super) vel: f64,
    /// Tangential acceleration and jerk of a line along the piece (infinite on a turn).
    line_acc: f64,
    line_jerk: f64,
    /// Vector limits of a turning piece: the smallest of the axes it turns in.
    turn_acc: f64,
    turn_jerk: f64,
    /// Largest |κ| (1/mm) and |dκ/ds| (1/mm²) along the piece.
    kappa: f64,
    kappa_rate: f64,
    /// Curvature step where the piece is entered, 1/mm.
    step: f64,
    /// Largest per-axis shares of tangent and normal along a turning piece.
    share_t: [f64; NUM_AXES],
    share_n: [f64; NUM_AXES],
}

impl Bounds {
    pub(super) fn new(p: &Piece, at_mm: f64, step: f64, max: &AxisMax) -> Bounds {
        let mut b = Bounds {
            at_mm,
            vel: f64::INFINITY,
            line_acc: f64::INFINITY,
            line_jerk: f64::INFINITY,
            turn_acc: f64::INFINITY,
            turn_jerk: f64::INFINITY,
            kappa: p.kappa_max,
            kappa_rate: p.kappa_rate,
            step,
            share_t: p.share_t,
            share_n: p.share_n,
        };
        if p.kappa_max == 0.0 {
            (b.vel, b.line_acc, b.line_jerk) = max.along(&p.t_in);
        }
        for i in 0..NUM_AXES {
            if p.share_t[i] > 0.0 || p.share_n[i] > 0.0 {
                b.turn_acc = b.turn_acc.min(max.acc[i]);
                b.turn_jerk = b.turn_jerk.min(max.jerk[i]);
            }
            if p.share_t[i] > 0.0 {
                b.vel = b.vel.min(max.vel[i] / p.share_t[i]);
            }
        }
        b
    }

    pub(super) fn turns(&self) -> bool {
        self.kappa > 0.0 || self.step > 0.0
    }

    /// Whether a stop with tangential acceleration within `acc` and jerk within `jerk` stays
    /// within the limits along the piece at every speed up to `v`, servo period `dt`.
    pub(super) fn admits(&self, acc: f64, jerk: f64, v: f64, dt: f64, max: &AxisMax) -> bool {
        self.most_acc(v, max).is_some_and(|a| acc <= a)
            && self.jerk_for(acc, v, dt, max).is_some_and(|j| jerk <= j)
    }

    /// Largest tangential acceleration a stop may use along the piece at every speed up to
    /// `v`; `None` where its turning at `v` leaves none.
    fn most_acc(&self, v: f64, max: &AxisMax) -> Option<f64> {
        if !self.turns() {
            return Some(self.line_acc);
        }
        Some(
            self.line_acc
                .min(self.turning_acc(v * v * self.kappa, max)?),
        )
    }

    /// Largest tangential jerk a stop decelerating at up to `acc` may use along the piece at
    /// every speed up to `v`: what the normal jerk leaves, that of the turning itself
    /// (curvature step and rate) and `3κva` of the deceleration.
    fn jerk_for(&self, acc: f64, v: f64, dt: f64, max: &AxisMax) -> Option<f64> {
        if !self.turns() {
            return Some(self.line_jerk);
        }
        let k = self.kappa;
        let turning = v * v * self.step / dt + v * v * v * self.kappa_rate;
        let j = self.turning_jerk(turning + 3.0 * k * v * acc, k * k * v * v * v, max)?;
        Some(j.min(self.line_jerk))
    }

    /// Largest tangential acceleration with normal acceleration `normal`: the larger of the
    /// vector bound (the norm within the weakest axis' limit) and the per-axis one
    /// (`|a|·|T_i| + normal·|N_i| ≤ A_i`); `None` if neither leaves any.
    fn turning_acc(&self, normal: f64, max: &AxisMax) -> Option<f64> {
        let a = vector_share(self.turn_acc, normal).max(self.per_axis(&max.acc, normal));
        (a > 0.0 && a.is_finite()).then_some(a)
    }

    /// Largest tangential jerk with normal jerk `normal` and the turning's own tangential
    /// part `kappa2_v3` (`κ²v³`), as [`Self::turning_acc`] does for the acceleration.
    fn turning_jerk(&self, normal: f64, kappa2_v3: f64, max: &AxisMax) -> Option<f64> {
        let j = vector_share(self.turn_jerk, normal).max(self.per_axis(&max.jerk, normal));
        let j = j - kappa2_v3;
        (j > 0.0 && j.is_finite()).then_some(j)
    }

    /// Smallest `(limit_i − normal·|N_i|)/|T_i|` over the axes (−∞ if an axis the tangent
    /// does not move is already past its limit).
    fn per_axis(&self, limit: &[f64; NUM_AXES], normal: f64) -> f64 {
        (0..NUM_AXES).fold(f64::INFINITY, |m, i| {
            let left = limit[i] - normal * self.share_n[i];
            if self.share_t[i] > 0.0 {
                m.min(left / self.share_t[i])
            } else if left < 0.0 {
                f64::NEG_INFINITY
            } else {
                m
            }
        })
    }
}

/// Tangential `(acceleration, jerk)` a stop from speed `v` may use along `pieces`, each at
/// every speed up to its own in `speeds`: of the decelerations tried ([`ACC_SHARES`] of the
/// most they all allow), the one whose jerk gives the shortest stop from `v`. `None` where
/// a turn leaves none.
pub(super) fn joint_limits(
    pieces: &[Bounds],
    speeds: &[f64],
    v: f64,
    dt: f64,
    max: &AxisMax,
) -> Option<(f64, f64)> {
    let both = || pieces.iter().zip(speeds);
    let most = both().try_fold(f64::INFINITY, |m, (b, &u)| Some(m.min(b.most_acc(u, max)?)))?;
    let mut best: Option<(f64, f64, f64)> = None;
    for share in ACC_SHARES {
        let a = most * share;
        let Some(j) = both().try_fold(f64::INFINITY, |m, (b, &u)| {
            Some(m.min(b.jerk_for(a, u, dt, max)?))
        }) else {
            continue;
        };
        // The fastest stop's distance from `v` at rest acceleration.
        let d = if v * j >= a * a {
            0.5 * v * (v / a + a / j)
        } else {
            v * (v / j).sqrt()
        };
        if best.is_none_or(|b| d < b.0) {
            best = Some((d, a, j));
        }
    }
    best.map(|(_, a, j)| (a, j))
}

/// What a vector of norm ≤ `limit` leaves beside an orthogonal part `normal`.
fn vector_share(limit: f64, normal: f64) -> f64 {
    if normal < limit {
        (limit * limit - normal * normal).sqrt()
    } else {
        0.0
    }
}
