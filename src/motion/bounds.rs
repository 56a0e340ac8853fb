//! Reference times for judging the planner: lower bounds no planner can beat under the same
//! limits, and the time of a naive planner that stops at every corner.
//!
//! - **Feed-limited bound**: `Σ Lᵢ / min(Fᵢ, axis velocity caps along the move)`: the path
//!   at its top speed, with infinite acceleration.
//! - **Acceleration-aware bound**: the speed along the (programmed) path is additionally
//!   capped by the centripetal limit `v ≤ √(a_max·R)` at each vertex, with `R = L/θ` from the
//!   turning angle and the neighbouring chord lengths, and speed changes use at most
//!   `a_max` along the path, starting and ending at rest (forward/backward passes, no jerk
//!   limit, so still a lower bound). `a_max = ‖(A_x, A_y, A_z, ...)‖` over the axes the move
//!   uses: the largest acceleration any direction allows. Corners within a blend tolerance
//!   could be cut, so on a path with sharp corners this bound is only approximate; on dense
//!   smooth curves (the benchmark case) it holds to within the tolerance.
//! - **Naive planner**: every move from rest to rest with the same S-curve limits (what G61
//!   exact stop gives).

use super::config::MotionConfig;
use super::from_canon::fold;
use super::limits::Limits;
use super::moves::{Move, Step};
use super::PlanError;
use crate::gcode::{Canon, NUM_AXES};

/// The reference times of a program, s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Bounds {
    /// Feed-limited lower bound.
    pub feed_limited_s: f64,
    /// Acceleration-aware lower bound.
    pub accel_aware_s: f64,
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
        accel_aware(run, &lim, cfg, b);
        run.clear();
    };
    for s in &folded.steps {
        match s {
            Step::Move(m) => run.push(*m),
            Step::Dwell { seconds, .. } => {
                flush(&mut run, &mut b);
                b.feed_limited_s += seconds;
                b.accel_aware_s += seconds;
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

fn accel_aware(run: &[Move], lim: &Limits, cfg: &MotionConfig, b: &mut Bounds) {
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
        b.accel_aware_s += if d_up + d_down <= *l {
            (vc - prev) / a + (vc - v_end) / a + (l - d_up - d_down) / vc
        } else {
            let vp = ((2.0 * a * l + prev * prev + v_end * v_end) / 2.0).sqrt();
            (vp - prev) / a + (vp - v_end) / a
        };
        prev = v_end;
    }
}
