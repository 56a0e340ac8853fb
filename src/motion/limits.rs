//! Per-axis limits as the planner uses them: velocity caps of a direction, tangential
//! acceleration/jerk along a move, the S-curve shape of any velocity change, the override
//! headroom of a segment, and soft limits.

use super::config::{KinematicsConfig, MotionConfig};
use super::profile::{Shape, Tangential};
use super::segment::{norm, Item, Segment, SegmentKind};
use super::{PlanError, AXIS_NAMES};
use crate::gcode::NUM_AXES;

/// Planning limits: velocity in full, acceleration and jerk reduced by the override reserve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Velocity, mm/s.
    pub vel: [f64; NUM_AXES],
    /// Planning acceleration, (1 - reserve)·max, mm/s².
    pub acc: [f64; NUM_AXES],
    /// Planning jerk, (1 - reserve)·max, mm/s³.
    pub jerk: [f64; NUM_AXES],
    /// Full acceleration, mm/s²: an arc's normal acceleration is planned against it with
    /// the vector bound (see [`Limits::arc`]).
    pub acc_full: [f64; NUM_AXES],
    /// Full jerk, mm/s³.
    pub jerk_full: [f64; NUM_AXES],
    /// The interpolator's always-safe scale rates `(k̇ max, k̈ max)` ([`override_rates`]).
    pub scale_floor: (f64, f64),
    /// Largest feed override.
    pub max_override: f64,
    /// Servo period, s: an acceleration step shows on the trace as jerk over one period.
    pub servo_period_s: f64,
    /// Whether dense gently turning chords are fitted into arcs ([`super::arcfit`]): on
    /// Cartesian machines (the arcs are planned against the axis limits of X and Y).
    pub fit_arcs: bool,
    /// Whether runs of tangent moves are planned as one speed profile ([`super::span`]).
    pub spans: bool,
    /// Tolerances at or below this (G61/G61.1's exact-path tolerance) keep their chords.
    pub exact_tolerance_mm: f64,
}

/// Share of the planning jerk an acceleration step at a curvature step may use (the arcs
/// and lines next to it keep the rest for their own jerk).
pub const STEP_SHARE: f64 = 0.5;
/// Largest share of the planning acceleration held as normal acceleration on an arc.
pub const NORMAL_SHARE: f64 = 0.9;

impl Limits {
    /// From the configuration.
    pub fn new(cfg: &MotionConfig) -> Self {
        let keep = 1.0 - cfg.override_reserve;
        Limits {
            vel: cfg.axes.map(|a| a.max_vel_mm_s),
            acc: cfg.axes.map(|a| a.max_acc_mm_s2 * keep),
            jerk: cfg.axes.map(|a| a.max_jerk_mm_s3 * keep),
            acc_full: cfg.axes.map(|a| a.max_acc_mm_s2),
            jerk_full: cfg.axes.map(|a| a.max_jerk_mm_s3),
            scale_floor: override_rates(cfg),
            max_override: cfg.max_feed_override,
            servo_period_s: cfg.servo_period_s,
            fit_arcs: cfg.fit_arcs && matches!(cfg.kinematics, KinematicsConfig::Identity),
            spans: cfg.spans,
            exact_tolerance_mm: cfg.exact_path_tolerance_mm,
        }
    }

    /// Largest acceleration step at a curvature step, mm/s² (`v²·|Δκ|` at a junction).
    pub fn step_budget_mm_s2(&self) -> f64 {
        STEP_SHARE * self.arc_jerk() * self.servo_period_s
    }

    /// Planning jerk of X/Y on arcs: the reduced jerk, and at most `J − 3·A·k1 − v·k2`, so
    /// that the interpolator's always-safe scale rates stay safe although an arc's
    /// acceleration may reach the full `A` ([`Limits::arc`]).
    fn arc_jerk(&self) -> f64 {
        let (k1, k2) = self.scale_floor;
        let full = self.jerk_full[0].min(self.jerk_full[1]);
        let a_full = self.acc_full[0].min(self.acc_full[1]);
        let vel = self.vel[0].min(self.vel[1]);
        self.jerk[0]
            .min(self.jerk[1])
            .min(full - 3.0 * a_full * k1 - vel * k2)
    }

    /// Speed cap and tangential limits on an XY arc of curvature `kappa` at feed `feed`.
    ///
    /// The normal acceleration `v²·κ` may use [`NORMAL_SHARE`] of the *full* acceleration
    /// (not of the reserve-reduced one): a hold or a lower override only shrinks it (`k ≤ 1`
    /// scales it by `k²`) and adds tangential deceleration `v·k̇`, which is orthogonal to it.
    /// So the tangential acceleration is the larger of two always-safe choices: within the
    /// reduced acceleration as a vector with the normal one (then the override cap may
    /// exceed 1 and the reserve covers `v·k̇`, as on a line), or, at scale at most 1, such
    /// that `√((a_t + v·k1)² + a_n²) ≤ A` with the interpolator's always-safe scale rate
    /// `k1` (the override cap is then 1). The jerk terms of the curvature (`κ²·v³` and
    /// `3κ·v·s''`) and the share kept for curvature steps ([`STEP_SHARE`]) come out of the
    /// planning jerk, lowered so that `j + 3·A·k1 + v·k2 ≤ J` (an arc's acceleration may
    /// reach the full `A` in the jerk term `3·p''·k·k̇`).
    pub fn arc(&self, kappa: f64, feed_mm_s: f64) -> (f64, Tangential) {
        let a = self.acc[0].min(self.acc[1]);
        let a_full = self.acc_full[0].min(self.acc_full[1]);
        let vel = self.vel[0].min(self.vel[1]);
        let (k1, j) = (self.scale_floor.0, self.arc_jerk());
        let k = kappa.abs();
        let mut v = feed_mm_s.min(vel).min((NORMAL_SHARE * a_full / k).sqrt());
        let jt_free = (1.0 - STEP_SHARE) * j;
        let mut t = Tangential {
            acc_mm_s2: a,
            jerk_mm_s3: jt_free,
        };
        for _ in 0..60 {
            let an = k * v * v;
            let at = (a * a - an * an)
                .max(0.0)
                .sqrt()
                .max((a_full * a_full - an * an).max(0.0).sqrt() - v * k1);
            let jt = jt_free - k * k * v * v * v - 3.0 * k * v * at;
            t = Tangential {
                acc_mm_s2: at,
                jerk_mm_s3: jt,
            };
            if jt >= 0.2 * jt_free && at > 0.0 {
                break;
            }
            v *= 0.9;
        }
        (v, t)
    }

    /// Highest path speed along direction `u` (per unit feed length) within axis velocities.
    pub fn vcap(&self, u: &[f64; NUM_AXES]) -> f64 {
        let mut v = f64::INFINITY;
        for i in 0..NUM_AXES {
            if u[i] != 0.0 {
                v = v.min(self.vel[i] / u[i].abs());
            }
        }
        v
    }

    /// Tangential acceleration and jerk along `u`.
    pub fn tangential(&self, u: &[f64; NUM_AXES]) -> Tangential {
        let (mut a, mut j) = (0.0f64, 0.0f64);
        for i in 0..NUM_AXES {
            a = a.max(u[i].abs() / self.acc[i]);
            j = j.max(u[i].abs() / self.jerk[i]);
        }
        Tangential {
            acc_mm_s2: 1.0 / a,
            jerk_mm_s3: 1.0 / j,
        }
    }

    /// `(alpha, beta)` per unit of a velocity change `dv`: the shape of a change `s·dv` is
    /// `Shape::for_bounds(s·alpha, s·beta)`.
    pub fn change_coefficients(&self, dv: &[f64; NUM_AXES]) -> (f64, f64) {
        let (mut a, mut j) = (0.0f64, 0.0f64);
        for i in 0..NUM_AXES {
            a = a.max(dv[i].abs() / self.acc[i]);
            j = j.max(dv[i].abs() / self.jerk[i]);
        }
        (a, j)
    }

    /// Fastest S-curve for a velocity change `dv`.
    pub fn shape(&self, dv: &[f64; NUM_AXES]) -> Shape {
        let (a, j) = self.change_coefficients(dv);
        Shape::for_bounds(a, j)
    }

    /// Largest time scale of `seg` within all limits, at least 1, at most `max_override`.
    pub fn override_cap(&self, seg: &Segment) -> f64 {
        if seg.kind == SegmentKind::Dwell {
            return self.max_override;
        }
        let mut k = self.max_override;
        for (i, [v, a, j]) in seg.peaks().into_iter().enumerate() {
            if v > 0.0 {
                k = k.min(self.vel[i] / v);
            }
            if a > 0.0 {
                k = k.min((self.acc[i] / a).sqrt());
            }
            if j > 0.0 {
                k = k.min((self.jerk[i] / j).cbrt());
            }
        }
        k.max(1.0)
    }
}

/// Rate limits of the override scale in the interpolator: `(k̇ max, k̈ max)`, from the reserve.
pub fn override_rates(cfg: &MotionConfig) -> (f64, f64) {
    let e = cfg.override_reserve;
    let (mut k1, mut k2) = (f64::INFINITY, f64::INFINITY);
    for a in &cfg.axes {
        // accel = p''k² + p'k̇: reserve e·A for p'k̇.
        k1 = k1.min(e * a.max_acc_mm_s2 / a.max_vel_mm_s);
        // jerk = p'''k³ + 3p''k·k̇ + p'k̈: half of e·J to each of the last two terms.
        k1 = k1.min(e * a.max_jerk_mm_s3 / (6.0 * (1.0 - e) * a.max_acc_mm_s2));
        k2 = k2.min(e * a.max_jerk_mm_s3 / (2.0 * a.max_vel_mm_s));
    }
    (k1, k2)
}

/// Lowers the override caps so that a scale above 1 can always be brought down in time
/// (at rate `k1` per second, real time ≥ planned time / max override) before a segment
/// that tolerates less; a margin covers the ramp's reversal lag. Then sets each segment's
/// scale-rate limit from the acceleration and jerk it leaves free, lowered so that the
/// interpolator (whose `k̈` is bounded) can always meet the next segment's limit.
pub fn propagate_override_caps(items: &mut [Item], cfg: &MotionConfig) {
    propagate_override_caps_open(items, cfg, false);
}

/// [`propagate_override_caps`] for a stretch of a longer queue (`open_end`): what follows
/// the stretch is not known yet, so it is assumed to tolerate the least any segment does
/// (cap 1, scale rate `k1`, scale jerk `k2`, the reserve-based values that are always safe).
/// The streaming planner finalises only the first part of such a stretch, far enough from its
/// end that these assumptions rarely matter; where they do, they only make the interpolator
/// more cautious.
pub fn propagate_override_caps_open(items: &mut [Item], cfg: &MotionConfig, open_end: bool) {
    let (k1, k2) = override_rates(cfg);
    let kmax = cfg.max_feed_override;
    let margin = 2.5 * k1 * k1 / k2;
    // Cap allowed at the start of the next segment.
    let mut line = if open_end { 1.0 } else { f64::INFINITY };
    // Scale rate allowed at the start of the next segment.
    let mut rate_line = if open_end { k1 } else { f64::INFINITY };
    for it in items.iter_mut().rev() {
        if let Item::Segment(s) = it {
            let raw = s.override_cap;
            let own = raw - margin.min(raw - 1.0);
            s.override_cap = own;
            s.end_override_cap = line.min(kmax);
            line = own.min(line + k1 * s.duration_s / kmax);
            let rate = scale_rate(s, raw, cfg, k1, k2);
            s.scale_rate_max = rate;
            s.end_scale_rate_max = rate_line;
            rate_line = rate.min(rate_line + 0.9 * k2 * s.duration_s / kmax);
            s.scale_jerk_max = scale_jerk(s, raw, rate, cfg, k2);
        }
    }
    // Braking guarantee: the smallest k̈ limit over the planned time one braking can span
    // (|k̇| ≤ √(2·k2·kmax) when braking at ≥ k2 over a scale range ≤ kmax, so a braking lasts
    // at most √(2·kmax/k2) s of real time, ≤ kmax times that of planned time).
    let beyond = if open_end { k2 } else { f64::INFINITY };
    let brake = min_ahead(items, kmax * (2.0 * kmax / k2).sqrt(), beyond);
    // A servo period can end in a later segment: the smallest limit within two periods.
    let step = min_ahead(items, 2.0 * kmax * cfg.servo_period_s, beyond);
    let mut n = 0;
    for it in items.iter_mut() {
        if let Item::Segment(s) = it {
            s.brake_scale_jerk_max = s.scale_jerk_max.min(brake[n]);
            s.next_scale_jerk_max = step[n];
            n += 1;
        }
    }
}

/// For each segment (in order), the smallest `scale_jerk_max` of the segments that start
/// within `horizon_s` of planned time after it ends (infinity if none; at most `beyond` when
/// the horizon reaches past the last one). Sliding-window minimum, backwards, amortised O(1)
/// per segment.
fn min_ahead(items: &[Item], horizon_s: f64, beyond: f64) -> Vec<f64> {
    let segs: Vec<(f64, f64)> = items
        .iter()
        .filter_map(|it| match it {
            Item::Segment(s) => Some((s.duration_s, s.scale_jerk_max)),
            Item::Aux(_) => None,
        })
        .collect();
    let mut out = vec![f64::INFINITY; segs.len()];
    // (start σ, limit): front = latest added (earliest σ, largest limit), back = smallest.
    let mut window: std::collections::VecDeque<(f64, f64)> = std::collections::VecDeque::new();
    let mut sigma: f64 = segs.iter().map(|s| s.0).sum();
    let total = sigma;
    for (i, &(dur, own)) in segs.iter().enumerate().rev() {
        let end = sigma;
        sigma -= dur;
        while window.back().is_some_and(|&(st, _)| st > end + horizon_s) {
            window.pop_back();
        }
        out[i] = window.back().map_or(f64::INFINITY, |&(_, v)| v);
        if end + horizon_s >= total {
            out[i] = out[i].min(beyond);
        }
        while window.front().is_some_and(|&(_, v)| v >= own) {
            window.pop_front();
        }
        window.push_front((sigma, own));
    }
    out
}

/// Largest `k̈` in `seg` for any scale up to `cap` and `|k̇| ≤ rate`: per axis
/// `j·k³ + 3·a·k·k̇ + v·k̈ ≤ J`; never below the reserve-based `k2`, which is always safe.
fn scale_jerk(seg: &Segment, cap: f64, rate: f64, cfg: &MotionConfig, k2: f64) -> f64 {
    scale_jerk_at(seg, &seg.peaks(), cap, rate, &AxisMax::new(cfg)).max(k2)
}

/// Largest `k̇` in `seg` for any scale up to `cap`: per axis, acceleration
/// `a·k² + v·k̇ ≤ A` and jerk `j·k³ + 3·a·k·k̇ + v·k̈ ≤ J` with `k̈ ≤ k2`; never below the
/// reserve-based `k1`, which is always safe.
fn scale_rate(seg: &Segment, cap: f64, cfg: &MotionConfig, k1: f64, k2: f64) -> f64 {
    scale_rate_at(seg, &seg.peaks(), cap, &AxisMax::new(cfg), k2).max(k1)
}

/// Full acceleration and jerk of every axis (what the trace is checked against), kept by the
/// interpolator to compute scale rates at the current scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisMax {
    /// mm/s.
    pub vel: [f64; NUM_AXES],
    /// mm/s².
    pub acc: [f64; NUM_AXES],
    /// mm/s³.
    pub jerk: [f64; NUM_AXES],
}

impl AxisMax {
    /// From the configuration.
    pub fn new(cfg: &MotionConfig) -> Self {
        AxisMax {
            vel: cfg.axes.map(|a| a.max_vel_mm_s),
            acc: cfg.axes.map(|a| a.max_acc_mm_s2),
            jerk: cfg.axes.map(|a| a.max_jerk_mm_s3),
        }
    }

    /// `(velocity, acceleration, jerk)` allowed along unit direction `u`: the full limits of
    /// the axes it moves, each divided by its share (as [`Limits::vcap`] and
    /// [`Limits::tangential`] do with the planning limits).
    pub fn along(&self, u: &[f64; NUM_AXES]) -> (f64, f64, f64) {
        let mut out = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        for i in 0..NUM_AXES {
            if u[i] != 0.0 {
                out.0 = out.0.min(self.vel[i] / u[i].abs());
                out.1 = out.1.min(self.acc[i] / u[i].abs());
                out.2 = out.2.min(self.jerk[i] / u[i].abs());
            }
        }
        out
    }
}

/// Largest `k̈` in `seg` (segment peaks `peaks`, [`Segment::peaks`]) for any scale up to
/// `cap` and `|k̇| ≤ rate`: per axis `j·k³ + 3·a·k·k̇ + v·k̈ ≤ J`. No floor: may be negative
/// when no `k̈` is safe.
pub(crate) fn scale_jerk_at(
    seg: &Segment,
    peaks: &[[f64; 3]; NUM_AXES],
    cap: f64,
    rate: f64,
    max: &AxisMax,
) -> f64 {
    if seg.kind == SegmentKind::Dwell {
        return f64::INFINITY;
    }
    let mut r = f64::INFINITY;
    for (i, &[v, a, j]) in peaks.iter().enumerate() {
        if v > 0.0 {
            r = r.min((max.jerk[i] - j * cap.powi(3) - 3.0 * a * cap * rate) / v);
        }
    }
    r
}

/// Largest `k̇` in `seg` (segment peaks `peaks`) for any scale up to `cap`: per axis,
/// acceleration `a·k² + v·k̇ ≤ A` (on an arc the vector bound) and jerk
/// `j·k³ + 3·a·k·k̇ + v·k̈ ≤ J` with `k̈ ≤ k2`. No floor.
pub(crate) fn scale_rate_at(
    seg: &Segment,
    peaks: &[[f64; 3]; NUM_AXES],
    cap: f64,
    max: &AxisMax,
    k2: f64,
) -> f64 {
    if seg.kind == SegmentKind::Dwell {
        return f64::INFINITY;
    }
    let mut r = f64::INFINITY;
    let arc = arc_accelerations(seg);
    for (i, &[v, a, j]) in peaks.iter().enumerate() {
        let (acc, jerk) = (max.acc[i], max.jerk[i]);
        match arc {
            // Vector bound: `|p''k² + p'k̇|² = (a_t·k² + v·k̇)² + (a_n·k²)²`, the `k̇` term
            // is tangential only.
            Some((at, an)) if i < 2 && v > 0.0 => {
                let c2 = cap * cap;
                let room = (acc.powi(2) - (an * c2).powi(2)).max(0.0);
                r = r.min((room.sqrt() - at * c2) / v);
            }
            _ if v > 0.0 => r = r.min((acc - a * cap * cap) / v),
            _ => {}
        }
        if a > 0.0 {
            r = r.min((jerk - j * cap.powi(3) - v * k2) / (3.0 * a * cap));
        }
    }
    r
}

/// Peak tangential and normal acceleration of an arc segment at scale 1 (`None` for a
/// straight segment or a blend).
fn arc_accelerations(seg: &Segment) -> Option<(f64, f64)> {
    if seg.curvature_per_mm == 0.0 {
        return None;
    }
    let (s0, s1) = (norm(&seg.v0_mm_s), norm(&seg.v1_mm_s));
    let at = seg.tangential_acc_peak();
    Some((at, seg.curvature_per_mm.abs() * s0.max(s1).powi(2)))
}

/// Refuses a pose outside the soft limits, naming the line.
pub fn check_soft_limits(
    p: &[f64; NUM_AXES],
    line: u32,
    cfg: &MotionConfig,
) -> Result<(), PlanError> {
    for (i, a) in cfg.axes.iter().enumerate() {
        if p[i] < a.min_mm - 1e-9 || p[i] > a.max_mm + 1e-9 {
            return Err(PlanError::SoftLimit {
                line,
                axis: AXIS_NAMES[i],
                value_mm: p[i],
                min_mm: a.min_mm,
                max_mm: a.max_mm,
            });
        }
    }
    Ok(())
}
