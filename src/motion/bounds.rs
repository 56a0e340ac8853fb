//! Reference times for judging the planner: lower bounds no planner can beat under the same
//! limits, an estimate, and the time of a naive planner that stops at every corner.
//!
//! - **Feed-limited bound**: `Σ Lᵢ / min(Fᵢ, axis velocity caps along the move)`: the path
//!   at its top speed, with infinite acceleration.
//! - **Time-optimal bound** ([`time_optimal_s`]): the shortest time in which the path the
//!   planner actually produced (its blends, merged chords and stops, as the interpolator
//!   runs it) can be travelled within every axis' velocity and acceleration limit and the
//!   programmed feed, by time-optimal path parametrisation ([`topp`]). Jerk is not limited,
//!   so this is a true lower bound for that path: the planner's time divided by it is what
//!   its velocity profile (not its path) costs.
//! - **Corner estimate** (formerly called the "accel-aware bound", which it is not): the
//!   speed along the *programmed* path is additionally
//!   capped by the centripetal limit `v ≤ √(a_max·R)` at each vertex, with `R = L/θ` from the
//!   turning angle and the neighbouring chord lengths, and speed changes use at most
//!   `a_max` along the path, starting and ending at rest (forward/backward passes, no jerk
//!   limit, so still a lower bound). `a_max = ‖(A_x, A_y, A_z, ...)‖` over the axes the move
//!   uses: the largest acceleration any direction allows. On quantised CAM output the
//!   turning angles of the programmed chords are noise that the planner's merging and
//!   blending smooth away within the G64 tolerance, so this is *not* a lower bound there
//!   (issue 14: a contour job, estimate 16.8 s against a 3.6 s plan); it is kept as an estimate of what the
//!   programmed polyline itself allows.
//! - **Naive planner**: every move from rest to rest with the same S-curve limits (what G61
//!   exact stop gives).

pub mod topp;

use super::config::MotionConfig;
use super::from_canon::fold;
use super::interpolator::InterpState;
use super::limits::Limits;
use super::moves::{Move, Step};
use super::segment::{Item, SegmentKind};
use super::{trace, Plan, PlanError};
use crate::gcode::{Canon, NUM_AXES};
use std::collections::HashMap;

/// The reference times of a program, s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Bounds {
    /// Feed-limited lower bound.
    pub feed_limited_s: f64,
    /// Corner estimate on the programmed polyline (not a bound: see the module doc).
    pub corner_estimate_s: f64,
    /// Stop-at-every-corner planner.
    pub naive_stop_s: f64,
}

/// Computes the reference times of `canon` (dwells included in all three).
pub fn bounds(canon: &[Canon], cfg: &MotionConfig) -> Result<Bounds, PlanError> {
    let folded = fold(canon, cfg, [0.0; NUM_AXES])?;
    // Full limits, no override reserve: bounds must not be handicapped.
    let full = MotionConfig {
        override_reserve: 1e-9,
        ..cfg.clone()
    };
    let lim = Limits::new(&full);
    let mut b = Bounds::default();
    let mut run: Vec<Move> = Vec::new();
    let flush = |run: &mut Vec<Move>, b: &mut Bounds| {
        corner_estimate(run, &lim, cfg, b);
        run.clear();
    };
    for s in &folded.steps {
        match s {
            Step::Move(m) => run.push(*m),
            Step::Dwell { seconds, .. } => {
                flush(&mut run, &mut b);
                b.feed_limited_s += seconds;
                b.corner_estimate_s += seconds;
                b.naive_stop_s += seconds;
            }
            Step::Aux(a) if a.kind.is_barrier() => flush(&mut run, &mut b),
            Step::Aux(_) => {}
        }
    }
    flush(&mut run, &mut b);
    Ok(b)
}

fn direction(m: &Move) -> ([f64; NUM_AXES], f64) {
    let len = m.feed_length_mm();
    let mut u = [0.0; NUM_AXES];
    for i in 0..NUM_AXES {
        u[i] = (m.end_mm[i] - m.start_mm[i]) / len;
    }
    (u, len)
}

fn corner_estimate(run: &[Move], lim: &Limits, cfg: &MotionConfig, b: &mut Bounds) {
    let n = run.len();
    if n == 0 {
        return;
    }
    let dirs: Vec<([f64; NUM_AXES], f64)> = run.iter().map(direction).collect();
    let a_max = |u: &[f64; NUM_AXES]| {
        (0..NUM_AXES)
            .filter(|&i| u[i] != 0.0)
            .map(|i| cfg.axes[i].max_acc_mm_s2.powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let mut vcap = Vec::with_capacity(n);
    for (k, m) in run.iter().enumerate() {
        let (u, len) = &dirs[k];
        let v = lim.vcap(u).min(m.feed_mm_s);
        vcap.push(v);
        b.feed_limited_s += len / v;
        let t = lim.tangential(u);
        let half = t.distance_mm(0.0, v);
        b.naive_stop_s += if 2.0 * half <= *len {
            2.0 * t.shape(0.0, v).duration_s + (len - 2.0 * half) / v
        } else {
            let vp = t.reach_mm_s(0.0, 0.5 * len, v);
            2.0 * t.shape(0.0, vp).duration_s
        };
    }
    // Vertex speed caps (vertex k joins move k and k + 1), centripetal limit.
    let mut vj = vec![0.0; n];
    for k in 0..n - 1 {
        let (ua, la) = &dirs[k];
        let (ub, lb) = &dirs[k + 1];
        let dot: f64 = (0..NUM_AXES).map(|i| ua[i] * ub[i]).sum();
        let na: f64 = ua.iter().map(|x| x * x).sum::<f64>().sqrt();
        let nb: f64 = ub.iter().map(|x| x * x).sum::<f64>().sqrt();
        let theta = (dot / (na * nb)).clamp(-1.0, 1.0).acos();
        let cap = vcap[k].min(vcap[k + 1]);
        vj[k] = if theta < 1e-12 {
            cap
        } else {
            let r = 0.5 * (la + lb) / theta;
            cap.min((a_max(ua).max(a_max(ub)) * r).sqrt())
        };
    }
    // Backward and forward passes with v² = v0² + 2·a·d.
    for k in (0..n - 1).rev() {
        let (u, l) = &dirs[k + 1];
        let next = vj[k + 1];
        vj[k] = vj[k].min((next * next + 2.0 * a_max(u) * l).sqrt());
    }
    let mut prev = 0.0f64;
    for k in 0..n {
        let (u, l) = &dirs[k];
        let a = a_max(u);
        let v_end = vj[k].min((prev * prev + 2.0 * a * l).sqrt());
        // Fastest time over the move: accelerate from prev, cruise at vcap, brake to v_end.
        let vc = vcap[k];
        let d_up = (vc * vc - prev * prev).max(0.0) / (2.0 * a);
        let d_down = (vc * vc - v_end * v_end).max(0.0) / (2.0 * a);
        b.corner_estimate_s += if d_up + d_down <= *l {
            (vc - prev) / a + (vc - v_end) / a + (l - d_up - d_down) / vc
        } else {
            let vp = ((2.0 * a * l + prev * prev + v_end * v_end) / 2.0).sqrt();
            (vp - prev) / a + (vp - v_end) / a
        };
        prev = v_end;
    }
}

/// Programmed path speed of every source line, mm/s (the largest when a line has several
/// moves; infinite for rapids, which run at the axis limits).
pub fn feed_by_line(
    canon: &[Canon],
    cfg: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<HashMap<u32, f64>, PlanError> {
    let folded = fold(canon, cfg, start_mm)?;
    let mut feed: HashMap<u32, f64> = HashMap::new();
    for s in &folded.steps {
        if let Step::Move(m) = s {
            let f = feed.entry(m.line).or_insert(0.0);
            *f = f.max(m.feed_mm_s);
        }
    }
    Ok(feed)
}

/// Nodes closer than this are merged (near a stop the servo-period samples are nanometres
/// apart, where finite differences would only measure rounding), mm.
const NODE_SPACING_MM: f64 = 1e-4;

/// Time-optimal lower bound for the path of `plan` (see the module doc), s: the plan is run
/// through the interpolator at the servo period, its samples are the path's nodes (at rest
/// where the trace waits or dwells), each with the feed of its source line, and the
/// shortest rest-to-rest time over them within the axis velocity and acceleration limits
/// is added to the dwells. Cartesian limits: exact for identity kinematics.
pub fn time_optimal_s(plan: &Plan, canon: &[Canon], cfg: &MotionConfig) -> Result<f64, PlanError> {
    let feed = feed_by_line(canon, cfg, plan.start_mm)?;
    let tr = trace::run_all(plan, cfg);
    let nodes = path_nodes(&tr, &feed);
    let lim = topp::AxisLimits {
        vel: std::array::from_fn(|a| cfg.axes[a].max_vel_mm_s),
        acc: std::array::from_fn(|a| cfg.axes[a].max_acc_mm_s2),
    };
    let dwell: f64 = plan
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Segment(s) if s.kind == SegmentKind::Dwell => Some(s.duration_s),
            _ => None,
        })
        .sum();
    Ok(topp::min_time_s(&nodes, &lim) + dwell)
}

/// The trace's poses as path nodes: merged below [`NODE_SPACING_MM`], at rest where the
/// trace stands still for two periods or more (a dwell, a wait) or waits for a command,
/// each with the largest feed of the lines its samples and its neighbours' belong to (a
/// blend between two moves may run at either feed).
fn path_nodes(tr: &trace::Trace, feed: &HashMap<u32, f64>) -> Vec<topp::Node> {
    let f_of = |line: u32| feed.get(&line).copied().unwrap_or(f64::INFINITY);
    let mut nodes = Vec::new();
    let Some(first) = tr.poses_mm.first() else {
        return nodes;
    };
    nodes.push(topp::Node {
        p: *first,
        feed_mm_s: 0.0,
        stop: true,
    });
    let mut still = 0usize;
    for i in 1..tr.poses_mm.len() {
        let p = tr.poses_mm[i];
        let f = f_of(tr.lines[i]);
        let last = nodes.len() - 1;
        nodes[last].feed_mm_s = nodes[last].feed_mm_s.max(f);
        if p == tr.poses_mm[i - 1] {
            still += 1;
            if still >= 2 || tr.states[i] == InterpState::Waiting {
                nodes[last].stop = true;
            }
            continue;
        }
        still = 0;
        if topp::distance_mm(&p, &nodes[last].p) >= NODE_SPACING_MM {
            nodes.push(topp::Node {
                p,
                feed_mm_s: f,
                stop: false,
            });
        }
    }
    // The end of the trace is the end of the path.
    let last = nodes.len() - 1;
    if let Some(end) = tr.poses_mm.last() {
        nodes[last].p = *end;
    }
    nodes[last].stop = true;
    let own: Vec<f64> = nodes.iter().map(|n| n.feed_mm_s).collect();
    for k in 0..nodes.len() {
        let lo = k.saturating_sub(1);
        let hi = (k + 1).min(nodes.len() - 1);
        nodes[k].feed_mm_s = own[lo..=hi].iter().copied().fold(0.0, f64::max);
    }
    nodes
}
