//! Time-optimal path parametrisation (TOPP) of a sampled path under per-axis velocity and
//! acceleration limits and a path-speed cap, by the classical bang-bang integration over
//! arc length: the maximum velocity curve from the constraints at every node, then a
//! backward pass (braking at the largest deceleration the constraints allow) and a forward
//! pass (accelerating at the largest acceleration), each clipped by the curve. Jerk is not
//! limited, so no jerk-limited planner can follow the same path faster: the result is a
//! lower bound for that path, up to the discretisation (nodes every servo period of the
//! planned motion, tangent and curvature by finite differences of the samples).
//!
//! With `s` the arc length (Euclidean over all axes), `u = dp/ds` and `c = d²p/ds²`, axis
//! `a` moves at `u_a·ṡ` and accelerates at `u_a·s̈ + c_a·ṡ²`. With `x = ṡ²` (so
//! `dx/ds = 2·s̈`) every axis limit is linear in (x, s̈): `|u_a·s̈ + c_a·x| ≤ A_a` and
//! `u_a²·x ≤ V_a²`.

use crate::gcode::NUM_AXES;

/// One sample of the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Node {
    /// Position, mm (deg for rotary axes).
    pub p: [f64; NUM_AXES],
    /// Largest XYZ path speed here (the programmed feed; infinite for rapids), mm/s.
    pub feed_mm_s: f64,
    /// The path must be at rest here (start, end, dwell, a command that waits for motion
    /// to stop).
    pub stop: bool,
}

/// Per-axis limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisLimits {
    /// Velocity, mm/s.
    pub vel: [f64; NUM_AXES],
    /// Acceleration, mm/s².
    pub acc: [f64; NUM_AXES],
}

/// Euclidean distance over all axes between two poses (the arc-length measure of the path
/// nodes, shared with the node builder in `bounds`).
pub(crate) fn distance_mm(a: &[f64; NUM_AXES], b: &[f64; NUM_AXES]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// Tangent and curvature vectors at the nodes by finite differences over arc length.
fn geometry(nodes: &[Node]) -> (Vec<f64>, Vec<[f64; NUM_AXES]>, Vec<[f64; NUM_AXES]>) {
    let n = nodes.len();
    let h: Vec<f64> = nodes
        .windows(2)
        .map(|w| distance_mm(&w[0].p, &w[1].p))
        .collect();
    let chord = |k: usize| {
        let mut d = [0.0; NUM_AXES];
        for (i, d) in d.iter_mut().enumerate() {
            *d = (nodes[k + 1].p[i] - nodes[k].p[i]) / h[k];
        }
        d
    };
    let mut u = vec![[0.0; NUM_AXES]; n];
    let mut c = vec![[0.0; NUM_AXES]; n];
    for k in 0..n {
        let d1 = if k > 0 { Some(chord(k - 1)) } else { None };
        let d2 = if k + 1 < n { Some(chord(k)) } else { None };
        match (d1, d2) {
            (Some(a), Some(b)) => {
                let span = h[k - 1] + h[k];
                let mut t = [0.0; NUM_AXES];
                for i in 0..NUM_AXES {
                    t[i] = a[i] + b[i];
                    c[k][i] = 2.0 * (b[i] - a[i]) / span;
                }
                let norm = t.iter().map(|x| x * x).sum::<f64>().sqrt();
                // A reversal (t = 0) has infinite curvature: any unit tangent will do.
                u[k] = if norm > 1e-12 { t.map(|x| x / norm) } else { b };
            }
            (Some(a), None) => u[k] = a,
            (None, Some(b)) => u[k] = b,
            (None, None) => {}
        }
    }
    (h, u, c)
}

/// Largest x = ṡ² at a node with tangent `u` and curvature `c` for which some s̈ satisfies
/// every axis' acceleration limit, also capped by the velocity limits and the feed.
fn max_x(u: &[f64; NUM_AXES], c: &[f64; NUM_AXES], feed: f64, lim: &AxisLimits) -> f64 {
    if u.iter().all(|&x| x == 0.0) {
        return 0.0; // a reversal
    }
    let mut x = f64::INFINITY;
    let xyz = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    if xyz > 1e-9 && feed.is_finite() {
        x = x.min((feed / xyz).powi(2));
    }
    // Axis a allows s̈ ∈ [-A_a/|u_a| - k_a·x, A_a/|u_a| - k_a·x] with k_a = c_a/u_a; an axis
    // that does not move along the tangent needs |c_a|·x ≤ A_a.
    for a in 0..NUM_AXES {
        if u[a].abs() > 1e-12 {
            x = x.min((lim.vel[a] / u[a]).powi(2));
        } else if c[a].abs() > 0.0 {
            x = x.min(lim.acc[a] / c[a].abs());
        }
    }
    for a in 0..NUM_AXES {
        if u[a].abs() <= 1e-12 {
            continue;
        }
        let (ka, ra) = (c[a] / u[a], lim.acc[a] / u[a].abs());
        for b in 0..NUM_AXES {
            if b == a || u[b].abs() <= 1e-12 {
                continue;
            }
            let (kb, rb) = (c[b] / u[b], lim.acc[b] / u[b].abs());
            // lo_a(x) ≤ hi_b(x): (k_b − k_a)·x ≤ r_a + r_b.
            if kb > ka {
                x = x.min((ra + rb) / (kb - ka));
            }
        }
    }
    x.max(0.0)
}

/// Range of s̈ at speed² `x` (empty, returned as lo > hi, above the velocity curve).
fn sdd_range(u: &[f64; NUM_AXES], c: &[f64; NUM_AXES], x: f64, lim: &AxisLimits) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..NUM_AXES {
        if u[a].abs() > 1e-12 {
            let (k, r) = (c[a] / u[a], lim.acc[a] / u[a].abs());
            lo = lo.max(-r - k * x);
            hi = hi.min(r - k * x);
        }
    }
    (lo, hi)
}

/// Shortest time to travel the sampled path `nodes` from rest to rest (and through rest at
/// every `stop` node) within `lim` and each node's feed, s.
pub fn min_time_s(nodes: &[Node], lim: &AxisLimits) -> f64 {
    let n = nodes.len();
    if n < 2 {
        return 0.0;
    }
    let (h, u, c) = geometry(nodes);
    let mut x: Vec<f64> = (0..n)
        .map(|k| {
            if nodes[k].stop || k == 0 || k + 1 == n {
                0.0
            } else {
                max_x(&u[k], &c[k], nodes[k].feed_mm_s, lim)
            }
        })
        .collect();
    // Backward: arriving at k + 1 with x[k+1], node k can be at most what braking at the
    // largest deceleration allowed at k + 1 reaches.
    for k in (0..n - 1).rev() {
        // At a reversal no axis bounds s̈ (no tangent): use the neighbour's limits.
        let at = if u[k + 1].iter().all(|&v| v == 0.0) {
            k
        } else {
            k + 1
        };
        let (lo, hi) = sdd_range(&u[at], &c[at], x[k + 1], lim);
        let dec = if lo <= hi { -lo.min(0.0) } else { 0.0 };
        x[k] = x[k].min(x[k + 1] + 2.0 * dec * h[k]);
    }
    for k in 0..n - 1 {
        let at = if u[k].iter().all(|&v| v == 0.0) {
            k + 1
        } else {
            k
        };
        let (lo, hi) = sdd_range(&u[at], &c[at], x[k], lim);
        let acc = if lo <= hi { hi.max(0.0) } else { 0.0 };
        x[k + 1] = x[k + 1].min(x[k] + 2.0 * acc * h[k]);
    }
    // Constant s̈ over each interval: t = 2h / (√x₀ + √x₁). Both ends at rest (two stops
    // side by side, a corner next to a stop): accelerate and brake at the path's largest
    // acceleration, still a lower bound.
    let a_any = lim.acc.iter().map(|a| a * a).sum::<f64>().sqrt();
    (0..n - 1)
        .map(|k| {
            let s = x[k].sqrt() + x[k + 1].sqrt();
            if s > 1e-9 * (h[k] * a_any).sqrt() {
                2.0 * h[k] / s
            } else {
                2.0 * (h[k] / a_any).sqrt()
            }
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lim() -> AxisLimits {
        AxisLimits {
            vel: [50.0; NUM_AXES],
            acc: [500.0; NUM_AXES],
        }
    }

    fn node(x: f64, y: f64) -> Node {
        let mut p = [0.0; NUM_AXES];
        p[0] = x;
        p[1] = y;
        Node {
            p,
            feed_mm_s: f64::INFINITY,
            stop: false,
        }
    }

    /// 100 mm along X at 50 mm/s and 500 mm/s²: 0.1 s up, 1.9 s cruise, 0.1 s down.
    #[test]
    fn a_straight_line_takes_the_trapezoid_time() {
        let nodes: Vec<Node> = (0..=2000).map(|i| node(i as f64 * 0.05, 0.0)).collect();
        let t = min_time_s(&nodes, &lim());
        assert!((t - 2.1).abs() < 2e-3, "{t}");
    }

    /// A slower feed caps the path speed; on the diagonal each axis moves at F/√2, so the
    /// XYZ feed, not the axis velocity, is the limit.
    #[test]
    fn the_feed_caps_the_path_speed() {
        let nodes: Vec<Node> = (0..=2000)
            .map(|i| {
                let mut n = node(i as f64 * 0.05, i as f64 * 0.05);
                n.feed_mm_s = 20.0;
                n
            })
            .collect();
        let len = 100.0 * 2f64.sqrt();
        let t = min_time_s(&nodes, &lim());
        // Accelerating to 20 mm/s takes 20 / (500·√2) s with both axes at their limit.
        let ramp = 20.0 / (500.0 * 2f64.sqrt());
        assert!((t - (len / 20.0 + ramp)).abs() < 2e-3, "{t}");
    }

    /// On a circle of radius 2 mm the normal acceleration caps the speed: where one axis
    /// carries all of v²/R, v ≤ √(500·2) = 31.6 mm/s; at 45° both share it, v ≤ 37.6 mm/s.
    #[test]
    fn curvature_caps_the_speed_on_a_circle() {
        let r = 2.0;
        let n = 4000;
        let nodes: Vec<Node> = (0..=n)
            .map(|i| {
                let a = 4.0 * std::f64::consts::PI * i as f64 / n as f64;
                node(r * a.cos(), r * a.sin())
            })
            .collect();
        let len = 4.0 * std::f64::consts::PI * r;
        let t = min_time_s(&nodes, &lim());
        let by_acc = len / (500.0 * r).sqrt();
        let by_acc_diag = len / (500.0 * 2f64.sqrt() * r).sqrt();
        assert!(
            t > by_acc_diag && t < by_acc + 0.2,
            "{t}: {by_acc_diag} .. {by_acc}"
        );
    }

    /// A stop flag brings the path to rest.
    #[test]
    fn stops_are_passed_at_rest() {
        let mut nodes: Vec<Node> = (0..=1000).map(|i| node(i as f64 * 0.05, 0.0)).collect();
        let once = min_time_s(&nodes, &lim());
        nodes[500].stop = true;
        let stopped = min_time_s(&nodes, &lim());
        assert!((stopped - once - 0.1).abs() < 2e-3, "{once} {stopped}");
    }
}
