//! Where a stop may leave the planned timing: the stretch of path ahead of the tool made of
//! straight segments, circular arcs and corner blends joined tangentially, and the
//! tangential acceleration and jerk a stop along it may use (issue 14: "a hold still stops
//! as fast as the limits allow").
//!
//! Why: the tool follows a curve `p(σ)` whatever the timing (any timing of it is a time
//! scaling), so a hold can follow the fastest [`super::line_stop::LineStop`] along the path
//! instead of braking the time scale at the rates the planner left free. On a line that
//! stop has the axes' full limits along it. On a turn part of the acceleration is the
//! normal `v²κ`, and the jerk has the parts of a turning acceleration: with tangential speed
//! `v`, acceleration `a` and jerk `j`,
//!
//! `acc = a·T + v²κ·N`, `jerk = (j − κ²v³)·T + (3κva + v³·dκ/ds)·N` (plus `v²Δκ/dt` in the
//! one servo period that crosses a curvature step `Δκ`).
//!
//! An arc has constant `κ`; a corner blend's curvature rises from zero at both ends, and its
//! length, curvature and curvature rate are bounded by [`BlendPath`]. Each piece's bounds
//! ([`super::stop_bounds`]) keep every axis within its limits at every speed up to the one
//! they are taken at, so they only grow as the speed falls: a stop reaches a turn further on
//! slower than it is now, and [`plan`] takes each piece's bounds at the speed the stop enters
//! it with. A stop re-planned later from a lower speed is at least as fast.

use super::blend_path::BlendPath;
use super::limits::AxisMax;
use super::line_stop::LineStop;
use super::segment::{norm, Segment, SegmentKind};
use super::stop_bounds::{joint_limits, turn_shares, Bounds};
use crate::gcode::NUM_AXES;

/// Tangents meeting closer than this (unit vectors' difference) continue the path: the
/// planner's own test for a junction that needs no blend.
const TANGENT_TOL: f64 = 1e-9;

/// A stretch a stop may run along: its unit tangents at both ends, its curvature and its
/// path length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// Unit tangent at the start.
    pub t_in: [f64; NUM_AXES],
    /// Unit tangent at the end.
    pub t_out: [f64; NUM_AXES],
    /// Signed curvature in the XY plane at both ends, 1/mm (0 for a line or a blend).
    pub kappa: f64,
    /// Largest |curvature| along the piece, 1/mm.
    pub kappa_max: f64,
    /// Largest |rate of the curvature along the path|, 1/mm² (a blend's).
    pub kappa_rate: f64,
    /// Largest share `|T_i|` of each axis in the tangent along a turning piece (0 for a
    /// line): an axis takes that share of the tangential acceleration and jerk.
    pub share_t: [f64; NUM_AXES],
    /// Largest share `|N_i|` of each axis in the normal along a turning piece.
    pub share_n: [f64; NUM_AXES],
    /// Path length, mm.
    pub length_mm: f64,
}

/// The piece `s` is, or `None` for what a stop cannot leave its timing on: a dwell, a
/// segment at rest throughout, a corner sharper than a [`BlendPath`] follows.
pub fn piece(s: &Segment) -> Option<Piece> {
    if s.kind == SegmentKind::Dwell || s.length_mm <= 0.0 {
        return None;
    }
    if let Some(b) = BlendPath::of(s) {
        let (kappa_max, kappa_rate) = b.curvature_bounds();
        let t_in = s.v0_mm_s.map(|c| c / norm(&s.v0_mm_s));
        let t_out = s.v1_mm_s.map(|c| c / norm(&s.v1_mm_s));
        let cos: f64 = (0..NUM_AXES).map(|i| t_in[i] * t_out[i]).sum();
        let across: [f64; NUM_AXES] = std::array::from_fn(|i| t_out[i] - cos * t_in[i]);
        let e2 = across.map(|c| c / norm(&across));
        let (share_t, share_n) = turn_shares(&t_in, &e2, cos.clamp(-1.0, 1.0).acos());
        return Some(Piece {
            t_in,
            t_out,
            kappa: 0.0,
            kappa_max,
            kappa_rate,
            share_t,
            share_n,
            length_mm: b.length(),
        });
    }
    if s.curvature_per_mm != 0.0 {
        let tangent = |h: f64| {
            let mut t = [0.0; NUM_AXES];
            (t[1], t[0]) = h.sin_cos();
            t
        };
        let k = s.curvature_per_mm;
        let h1 = s.heading_rad + k * s.length_mm;
        let t_in = tangent(s.heading_rad);
        let e2 = tangent(s.heading_rad + k.signum() * std::f64::consts::FRAC_PI_2);
        let (share_t, share_n) = turn_shares(&t_in, &e2, k.abs() * s.length_mm);
        return Some(Piece {
            t_in,
            t_out: tangent(h1),
            kappa: k,
            kappa_max: k.abs(),
            kappa_rate: 0.0,
            share_t,
            share_n,
            length_mm: s.length_mm,
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
        kappa_max: 0.0,
        kappa_rate: 0.0,
        share_t: [0.0; NUM_AXES],
        share_n: [0.0; NUM_AXES],
        length_mm: s.length_mm,
    })
}

/// Path length of segment `s`, mm: exact where [`piece`] follows it (a blend's `length_mm`
/// is the planner's `V·T`, longer than its curve).
pub fn length_of(s: &Segment) -> f64 {
    BlendPath::of(s).map_or(s.length_mm, |b| b.length())
}

/// Path length along `s` up to planned time `t_s`, mm (on the scale of [`length_of`]).
pub fn travelled(s: &Segment, t_s: f64) -> f64 {
    BlendPath::of(s).map_or_else(|| s.travelled_mm(t_s), |b| b.length_to(t_s))
}

/// Rate of the path speed at planned time `t_s`, mm/s² (a blend's speed dips in the middle).
pub fn tangential_acc(s: &Segment, t_s: f64) -> f64 {
    BlendPath::of(s).map_or_else(|| s.tangential_acc_at(t_s), |b| b.tangential_acc(t_s))
}

/// Planned time in `s`, not before `from_s`, at which the path length [`travelled`] reaches
/// `d_mm` (clamped to the segment).
pub fn time_at(s: &Segment, d_mm: f64, from_s: f64) -> f64 {
    if let Some(b) = BlendPath::of(s) {
        return b.time_at(d_mm, from_s);
    }
    // The distance grows with time: bisection, a fixed number of cheap steps.
    let (mut lo, mut hi) = (from_s, s.duration_s);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if s.travelled_mm(mid) <= d_mm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Most pieces a reach holds: the current segment and the interpolator's items taken ahead.
pub const MAX_PIECES: usize = 9;

/// The stretch from the tool to the end of the pieces taken so far, and what bounds a stop
/// along each of them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// Path length from the reach's origin (the tool when it was made) to the end of the last
    /// piece, mm.
    pub room_mm: f64,
    kind: SegmentKind,
    last: Piece,
    bounds: [Bounds; MAX_PIECES],
    count: usize,
    /// The axes' limits.
    max: AxisMax,
}

impl Reach {
    /// The rest of segment `s` after `from_mm` of it, or `None` when it is no [`piece`].
    pub fn new(s: &Segment, from_mm: f64, max: &AxisMax) -> Option<Reach> {
        let p = piece(s)?;
        let first = Bounds::new(&p, 0.0, 0.0, max);
        Some(Reach {
            room_mm: (p.length_mm - from_mm).max(0.0),
            kind: s.kind,
            last: p,
            bounds: [first; MAX_PIECES],
            count: 1,
            max: *max,
        })
    }

    /// Adds `next` if it continues the path (a piece of the same kind, tangent to the last,
    /// entered at speed) and there is room for it, and returns whether it did.
    pub fn extend(&mut self, next: &Segment) -> bool {
        let Some(p) = piece(next) else {
            return false;
        };
        let tangent = (0..NUM_AXES).all(|i| (p.t_in[i] - self.last.t_out[i]).abs() <= TANGENT_TOL);
        if next.kind != self.kind
            || !tangent
            || norm(&next.v0_mm_s) <= 0.0
            || self.count == MAX_PIECES
        {
            return false;
        }
        let step = (p.kappa - self.last.kappa).abs();
        self.bounds[self.count] = Bounds::new(&p, self.room_mm, step, &self.max);
        self.count += 1;
        self.room_mm += p.length_mm;
        self.last = p;
        true
    }

    fn pieces(&self) -> &[Bounds] {
        &self.bounds[..self.count]
    }

    /// Velocity cap along the reach, mm/s.
    pub fn vel(&self) -> f64 {
        self.pieces()
            .iter()
            .fold(f64::INFINITY, |m, b| m.min(b.vel))
    }

    /// Tangential `(acceleration, jerk)` a stop may use at every speed up to `v` (mm/s) along
    /// the whole reach, servo period `dt`; `None` where a turn leaves none (its normal
    /// acceleration or jerk at `v` already takes the whole limit).
    pub fn limits(&self, v: f64, dt: f64) -> Option<(f64, f64)> {
        joint_limits(
            self.pieces(),
            &[v; MAX_PIECES][..self.count],
            v,
            dt,
            &self.max,
        )
    }

    /// True when the bounds depend on the speed (a turn or a curvature step in reach): a
    /// stop along it gains by being re-planned as it slows.
    pub fn turns(&self) -> bool {
        self.pieces().iter().any(Bounds::turns)
    }
}

/// Iterations of [`plan`]'s search for limits that hold at the speeds the stop reaches
/// each piece with.
const PLAN_ROUNDS: usize = 8;

/// The fastest stop along `reach` from tangential speed `v` > 0 and acceleration `a`, begun
/// `gone_mm` after the reach's origin: `None` where none stays within the limits (a turn
/// leaves no room at the speed the stop reaches it with, it would exceed the velocity cap
/// while it ends an acceleration, or `a` is already beyond what the reach allows).
///
/// The stop slows down as it goes, so a turn further on is reached slower and leaves more
/// to the stop than at the current speed. The limits are therefore taken per piece at the
/// speed the stop has where it enters it (at the peak for the piece under the tool, which
/// a stop begun while still accelerating first rises to): start from the piece under the
/// tool, plan, and lower the limits to those of any piece that does not admit the stop at
/// its entry speed; lower limits only make the stop slower, so each round's check is
/// against the speeds the stop really reaches, and the answer is checked against all.
pub fn plan(reach: &Reach, gone_mm: f64, v: f64, a: f64, dt: f64) -> Option<LineStop> {
    let pieces = reach.pieces();
    let max = &reach.max;
    // The pieces ahead of the tool: the one under it, and those after.
    let first = pieces.iter().rposition(|b| b.at_mm <= gone_mm).unwrap_or(0);
    let ahead = &pieces[first..];
    let rise = |jerk: f64| a.max(0.0).powi(2) / (2.0 * jerk);
    let under = &ahead[..1];
    let (_, mut jerk) = joint_limits(under, &[v], v, dt, max)?;
    let mut peak = v + rise(jerk);
    let mut lim = None;
    for _ in 0..4 {
        let (acc, j) = joint_limits(under, &[peak], v, dt, max)?;
        jerk = j;
        if v + rise(jerk) <= peak {
            lim = Some((acc, j));
            break;
        }
        peak = (v + rise(jerk)) * (1.0 + 1e-9);
    }
    let (mut acc, mut jerk) = lim?;
    let vel = ahead.iter().fold(f64::INFINITY, |m, b| m.min(b.vel));
    if peak > vel {
        return None;
    }
    // Entry speeds the limits are taken at: only ever raised, so the rounds converge.
    let mut speeds = [0.0; MAX_PIECES];
    speeds[0] = peak;
    let mut reached = 1;
    for _ in 0..PLAN_ROUNDS {
        if a.abs() > acc * (1.0 + 1e-9) {
            return None;
        }
        let stop = LineStop::new(v, a, acc, jerk)?;
        let mut admitted = true;
        for (k, b) in ahead.iter().enumerate().skip(1) {
            let Some(u) = stop.speed_at_distance(b.at_mm - gone_mm) else {
                break;
            };
            speeds[k] = speeds[k].max(u);
            reached = reached.max(k + 1);
            admitted &= b.admits(acc, jerk, speeds[k], dt, max);
        }
        if admitted {
            return Some(stop);
        }
        (acc, jerk) = joint_limits(&ahead[..reached], &speeds[..reached], v, dt, max)?;
    }
    // Not settled: the limits of every piece at the peak hold whatever the entry speeds.
    let (acc, jerk) = joint_limits(ahead, &[peak; MAX_PIECES][..ahead.len()], v, dt, max)?;
    if a.abs() > acc * (1.0 + 1e-9) {
        return None;
    }
    LineStop::new(v, a, acc, jerk)
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
        // As the speed falls the turning takes less: the stop from each speed, relative to
        // the fastest stop along a line from that speed, gets nearer to it.
        let ratio = |v: f64| {
            let (a, j) = r.limits(v, 1e-3).unwrap();
            let on_arc = LineStop::new(v, 0.0, a, j).unwrap().duration_s();
            on_arc / LineStop::new(v, 0.0, 500.0, 50_000.0).unwrap().duration_s()
        };
        let mut last = ratio(47.4);
        for v in [40.0, 30.0, 20.0, 10.0, 1.0] {
            let now = ratio(v);
            assert!(now >= 1.0 - 1e-12 && now < last, "{v}: {now} after {last}");
            last = now;
        }
        assert!(last < 1.01, "{last}");
        assert_eq!(r.limits(50.0, 1e-3), None, "v²κ = A");
    }

    /// Only tangent pieces of the same kind continue a reach; a kink or a blend entered in
    /// another direction ends it, and the curvature step at a junction costs jerk.
    #[test]
    fn only_tangent_lines_and_arcs_continue_a_reach() {
        let m = max();
        let line = seg([10.0, 0.0], [10.0, 0.0], 0.0, 0.0, 2.0);
        let mut r = Reach::new(&line, 0.0, &m).unwrap();
        let blend = seg([0.0, 10.0], [10.0, 0.0], 0.0, 0.0, 1.0);
        assert!(!r.extend(&blend));
        let kink = seg([10.0, 1.0], [10.0, 1.0], 0.0, 0.0, 1.0);
        assert!(!r.extend(&kink));
        let mut rapid = line;
        rapid.kind = SegmentKind::Rapid;
        assert!(!r.extend(&rapid));
        let before = r.limits(20.0, 1e-3).unwrap();
        let arc = seg([10.0, 0.0], [0.0, 10.0], 0.01, 0.0, 2.0);
        assert!(r.extend(&arc));
        assert_eq!(r.room_mm, 4.0);
        let after = r.limits(20.0, 1e-3).unwrap();
        assert!(
            after.1 < before.1,
            "the step costs jerk: {after:?} {before:?}"
        );
    }

    /// A corner blend continues a reach entered along its first direction: its exact length
    /// is added, and its turning (curvature and curvature rate) leaves the stop less than a
    /// line, more as the speed falls; a line after it continues the reach.
    #[test]
    fn a_blend_continues_a_reach_with_its_turning_bounded() {
        let m = max();
        let line = seg([40.0, 0.0], [40.0, 0.0], 0.0, 0.0, 2.0);
        let mut r = Reach::new(&line, 0.0, &m).unwrap();
        let alone = r.limits(40.0, 1e-3).unwrap();
        let th = 0.3f64;
        // Planned at 400 mm/s² and 40,000 mm/s³ (Δv = 11.95 mm/s).
        let mut blend = seg(
            [40.0, 0.0],
            [40.0 * th.cos(), 40.0 * th.sin()],
            0.0,
            0.0,
            1.6,
        );
        (blend.duration_s, blend.jerk_s) = (0.04, 0.01);
        let exact = BlendPath::of(&blend).unwrap().length();
        // An XY blend turns in X and Y only.
        let p = piece(&blend).unwrap();
        assert!(p.share_t[..2]
            .iter()
            .chain(&p.share_n[..2])
            .all(|s| *s > 0.0));
        assert!(p.share_t[2..]
            .iter()
            .chain(&p.share_n[2..])
            .all(|s| *s == 0.0));
        assert!(r.extend(&blend));
        assert!((r.room_mm - 2.0 - exact).abs() < 1e-12 && exact < 1.6);
        assert!(r.turns());
        let at_40 = r.limits(40.0, 1e-3).unwrap();
        assert!(
            at_40.0 < alone.0 && at_40.1 < alone.1,
            "{at_40:?} {alone:?}"
        );
        let at_20 = r.limits(20.0, 1e-3).unwrap();
        assert!(
            at_20.0 > at_40.0 && at_20.1 > at_40.1,
            "{at_20:?} {at_40:?}"
        );
        let after = seg(
            [40.0 * th.cos(), 40.0 * th.sin()],
            [40.0 * th.cos(), 40.0 * th.sin()],
            0.0,
            0.0,
            1.0,
        );
        assert!(r.extend(&after));
        assert!((r.room_mm - 3.0 - exact).abs() < 1e-12);
    }
}
