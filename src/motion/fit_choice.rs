//! Whether a fitted arc chain is worth keeping (issue 14): an estimate of the time to run a
//! sequence of moves from the speed caps of its moves and junctions, to compare a fitted
//! chain with the chords it replaces.
//!
//! Why: arcs fitted over noisy chords (CAM coordinates rounded to 1 µm on chords alternating
//! 0.094 / 0.006 mm, as opencamlib's waterline writes them) meet with large curvature steps,
//! and each step is passed at `v ≤ √(budget/|Δκ|)`: the tool nearly stops every 0.1 mm,
//! where the chords' blends would have kept most of the feed. The estimate is the same
//! backward/forward pass as the lookahead's (without blend halves, and with coarse
//! bisections), so it is O(n) and cheap next to the planning itself.

use super::blend::Corner;
use super::limits::Limits;
use super::merge::merge;
use super::moves::{Junction, Move};
use super::profile::Tangential;
use crate::gcode::NUM_AXES;

/// Share of the chords' estimated time by which a fit may be estimated slower and still be
/// kept: the estimate is coarse (no jerk phases, no windows of the lookahead), and a fit
/// also gives the status line and the path a smoother run. 1.0 (2×) while the chords'
/// blends were left out of their estimate; with the blends counted, 0.3 keeps the fits that
/// plan faster (the benchmark spiral and sine, the trochoid) and gives up those that plan
/// slower (0.05 mm chords on a tight sine: 1.318 s fitted, 1.241 s as chords).
pub const MARGIN: f64 = 0.3;

/// One move of a candidate sequence.
#[derive(Debug, Clone, Copy)]
pub struct Piece {
    /// Length, mm.
    pub len_mm: f64,
    /// Speed cap along the move, mm/s.
    pub cap_mm_s: f64,
    /// Tangential limits along the move.
    pub tang: Tangential,
}

/// Highest speed ≤ `cap` reachable from `v0` within `dist`.
fn reach(t: &Tangential, v0: f64, dist: f64, cap: f64) -> f64 {
    t.reach_mm_s(v0, dist, cap).max(0.0)
}

/// Estimated time, s, to run `pieces`, entered at most at `ends[0]` and left at most at
/// `ends[1]`, whose junction `k` (between piece `k` and `k + 1`) is capped at `junction[k]`.
pub fn estimate_s(pieces: &[Piece], junction: &[f64], ends: [f64; 2]) -> f64 {
    let n = pieces.len();
    if n == 0 {
        return 0.0;
    }
    debug_assert_eq!(junction.len() + 1, n);
    // v[k]: speed at the start of piece k (v[n]: at the end of the last one).
    let mut v = Vec::with_capacity(n + 1);
    v.push(ends[0].min(pieces[0].cap_mm_s));
    v.extend_from_slice(junction);
    v.push(ends[1].min(pieces[n - 1].cap_mm_s));
    for k in (0..n).rev() {
        let p = &pieces[k];
        v[k] = reach(&p.tang, v[k + 1], p.len_mm, v[k].min(p.cap_mm_s));
    }
    for k in 0..n {
        let p = &pieces[k];
        v[k + 1] = reach(&p.tang, v[k], p.len_mm, v[k + 1].min(p.cap_mm_s));
    }
    pieces
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (a, b) = (v[k], v[k + 1]);
            let half = 0.5 * p.len_mm;
            let peak = reach(&p.tang, a, half, p.cap_mm_s)
                .min(reach(&p.tang, b, half, p.cap_mm_s))
                .max(a.max(b));
            let (d1, d2) = (p.tang.distance_mm(a, peak), p.tang.distance_mm(peak, b));
            let cruise = (p.len_mm - d1 - d2).max(0.0);
            let t = |d: f64, x: f64, y: f64| {
                if d > 0.0 {
                    2.0 * d / (x + y).max(1e-9)
                } else {
                    0.0
                }
            };
            t(d1, a, peak) + t(d2, peak, b) + cruise / peak.max(1e-9)
        })
        .sum()
}

/// Unit direction of an XY move (as an axis vector).
fn dir(m: &Move) -> [f64; NUM_AXES] {
    let (dx, dy) = (m.end_mm[0] - m.start_mm[0], m.end_mm[1] - m.start_mm[1]);
    let l = (dx * dx + dy * dy).sqrt();
    let mut u = [0.0; NUM_AXES];
    u[0] = dx / l;
    u[1] = dy / l;
    u
}

/// The XY chords `raw` as the lookahead would plan them as lines (short collinear ones
/// merged, G64 Q): their pieces, junction caps (blend within half of each neighbour and
/// the tolerance, a stop at G61) and the time of the blends, s: a blend takes half its
/// length from each chord, so the pieces keep only the rest for their speed changes, and
/// the blend is run at the junction's speed.
pub fn chords(raw: &[Move], lim: &Limits) -> (Vec<Piece>, Vec<f64>, f64) {
    let (raw, _) = merge(raw.to_vec(), &vec![true; raw.len()]);
    let pieces = raw
        .iter()
        .map(|m| {
            let u = dir(m);
            Piece {
                len_mm: m.feed_length_mm(),
                cap_mm_s: lim.vcap(&u).min(m.feed_mm_s),
                tang: lim.tangential(&u),
            }
        })
        .collect();
    let mut pieces: Vec<Piece> = pieces;
    let mut blend_s = 0.0;
    let junction = raw
        .windows(2)
        .enumerate()
        .map(|(k, w)| {
            let (ua, ub) = (dir(&w[0]), dir(&w[1]));
            let Junction::Blend { tolerance_mm } = w[0].junction else {
                return 0.0;
            };
            let cap = lim.vcap(&ua).min(lim.vcap(&ub)).min(w[0].feed_mm_s);
            let (la, lb) = (w[0].feed_length_mm(), w[1].feed_length_mm());
            let corner = Corner::new(&ua, &ub, lim);
            let v = corner.max_speed_within(cap, [la, lb], tolerance_mm, 1e-4);
            // The blend takes half its length from each chord: what is left for the chords'
            // own speed changes (at the junction's cap, the longest blend it allows).
            let half = corner.half_length_mm(v);
            for piece in &mut pieces[k..=k + 1] {
                piece.len_mm = (piece.len_mm - half).max(0.0);
            }
            if v > 0.0 {
                blend_s += 2.0 * half / v;
            }
            v
        })
        .collect();
    (pieces, junction, blend_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slow_junctions_cost_time() {
        let tang = Tangential {
            acc_mm_s2: 1000.0,
            jerk_mm_s3: 1e5,
        };
        let pieces = vec![
            Piece {
                len_mm: 1.0,
                cap_mm_s: 50.0,
                tang,
            };
            10
        ];
        let fast = estimate_s(&pieces, &[50.0; 9], [50.0; 2]);
        assert!((fast - 10.0 / 50.0).abs() < 1e-9, "{fast}");
        let slow = estimate_s(&pieces, &[1.0; 9], [50.0; 2]);
        assert!(slow > 2.0 * fast, "{slow} vs {fast}");
    }
}
