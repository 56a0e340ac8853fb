//! One speed profile across a run of tangent moves (issue 14).
//!
//! Why: every move used to be its own S-curve, with zero acceleration at both of its ends.
//! On dense curved CAM output (arcs fitted over 0.1 mm chords, about 1 mm each) a speed-up
//! from rest then pulses the acceleration up and down on every arc, and the tool needs
//! about four times the distance and time that one S-curve would (the spiral of the
//! benchmark took 0.43 s to reach its feed instead of 0.135 s). Where consecutive moves
//! meet tangentially and nothing at their junction caps the speed below theirs, the
//! lookahead plans them as one move (a *span*): one speed-up, one cruise, one slow-down,
//! cut at the moves' ends into windowed segments ([`super::segment::Window`]) so the
//! acceleration carries across.

use super::profile::{Shape, Tangential};

/// Most by which the speed caps of the moves in one span may differ, relative: only
/// rounding. A span runs at its slowest move's cap, so joining moves of different caps
/// slows the faster ones (the trochoid of benches/README.md, whose fitted arcs differ in
/// curvature by a few per cent, planned 0.3 % slower with 1 %).
pub const CAP_SPREAD: f64 = 1e-9;

/// What the grouping needs to know of one move.
#[derive(Debug, Clone, Copy)]
pub struct SpanMove {
    /// Speed cap along the move, mm/s.
    pub vcap_mm_s: f64,
    /// The junction after this move is tangent, not an exact stop, and joins a move of the
    /// same kind (feed or rapid): a span may continue across it.
    pub joins_next: bool,
    /// Speed cap at the junction after this move, mm/s.
    pub junction_cap_mm_s: f64,
}

/// Consecutive index ranges `(first, last)` covering `moves`: each is one move, or a run of
/// moves joined tangentially whose junctions allow the run's own (lowest) speed cap and
/// whose caps differ by at most [`CAP_SPREAD`].
pub fn groups(moves: &[SpanMove]) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(moves.len());
    let mut k = 0;
    while k < moves.len() {
        let first = k;
        let (mut lo, mut hi) = (moves[k].vcap_mm_s, moves[k].vcap_mm_s);
        while k + 1 < moves.len() && moves[k].joins_next {
            let next = moves[k + 1].vcap_mm_s;
            let (nlo, nhi) = (lo.min(next), hi.max(next));
            let fits = nlo > 0.0
                && nlo >= (1.0 - CAP_SPREAD) * nhi
                && moves[k].junction_cap_mm_s >= nlo * (1.0 - 1e-12);
            if !fits {
                break;
            }
            (lo, hi) = (nlo, nhi);
            k += 1;
        }
        out.push((first, k));
        k += 1;
    }
    out
}

/// The tangential limits of a span: the tightest of its moves'.
pub fn tangential(limits: impl Iterator<Item = Tangential>) -> Tangential {
    limits.fold(
        Tangential {
            acc_mm_s2: f64::INFINITY,
            jerk_mm_s3: f64::INFINITY,
        },
        |a, b| Tangential {
            acc_mm_s2: a.acc_mm_s2.min(b.acc_mm_s2),
            jerk_mm_s3: a.jerk_mm_s3.min(b.jerk_mm_s3),
        },
    )
}

/// One S-curve speed change along a path, `s(t) = s_start + (s_end − s_start)·f(t)`.
#[derive(Debug, Clone, Copy)]
pub struct Transition {
    /// Speed at the start, mm/s.
    pub s_start: f64,
    /// Speed at the end, mm/s.
    pub s_end: f64,
    /// The shape `f`.
    pub shape: Shape,
}

impl Transition {
    /// The transition from `s_start` to `s_end` within `tang`.
    pub fn new(tang: &Tangential, s_start: f64, s_end: f64) -> Self {
        Transition {
            s_start,
            s_end,
            shape: tang.shape(s_start, s_end),
        }
    }

    /// Speed at `t_s`, mm/s.
    pub fn speed(&self, t_s: f64) -> f64 {
        self.s_start + (self.s_end - self.s_start) * self.shape.eval(t_s).0
    }

    /// Distance travelled after `t_s`, mm.
    pub fn distance_mm(&self, t_s: f64) -> f64 {
        let t = t_s.clamp(0.0, self.shape.duration_s);
        self.s_start * t + (self.s_end - self.s_start) * self.shape.eval(t).1
    }

    /// Time at which the distance travelled reaches `d_mm` (clamped to the transition; the
    /// distance rises monotonically, so bisection is exact to the last bits).
    pub fn time_at(&self, d_mm: f64) -> f64 {
        let big_t = self.shape.duration_s;
        if d_mm <= 0.0 || big_t <= 0.0 {
            return 0.0;
        }
        if d_mm >= self.distance_mm(big_t) {
            return big_t;
        }
        let (mut lo, mut hi) = (0.0, big_t);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.distance_mm(mid) < d_mm {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * big_t {
                break;
            }
        }
        0.5 * (lo + hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mv(vcap: f64, joins: bool, cap: f64) -> SpanMove {
        SpanMove {
            vcap_mm_s: vcap,
            joins_next: joins,
            junction_cap_mm_s: cap,
        }
    }

    #[test]
    fn tangent_moves_at_one_cap_form_one_span() {
        let m = [
            mv(50.0, true, 50.0),
            mv(50.0, true, 50.0),
            mv(50.0, false, 0.0),
        ];
        assert_eq!(groups(&m), vec![(0, 2)]);
    }

    #[test]
    fn a_slow_junction_a_kink_or_a_different_cap_ends_the_span() {
        // Junction 0 caps below the moves: no span across it.
        let m = [
            mv(50.0, true, 30.0),
            mv(50.0, true, 50.0),
            mv(50.0, false, 0.0),
        ];
        assert_eq!(groups(&m), vec![(0, 0), (1, 2)]);
        // Not tangent after move 1.
        let m = [
            mv(50.0, true, 50.0),
            mv(50.0, false, 50.0),
            mv(50.0, true, 50.0),
        ];
        assert_eq!(groups(&m), vec![(0, 1), (2, 2)]);
        // A move at another feed keeps its own profile.
        let m = [
            mv(50.0, true, 50.0),
            mv(20.0, true, 50.0),
            mv(20.0, false, 0.0),
        ];
        assert_eq!(groups(&m), vec![(0, 0), (1, 2)]);
        // Equal caps up to rounding: one span, as long as the junctions allow it.
        let m = [mv(50.0, true, 50.0), mv(50.0 - 1e-12, false, 0.0)];
        assert_eq!(groups(&m), vec![(0, 1)]);
    }

    #[test]
    fn time_at_inverts_the_distance() {
        let tang = Tangential {
            acc_mm_s2: 400.0,
            jerk_mm_s3: 40_000.0,
        };
        for (a, b) in [(0.0, 50.0), (50.0, 0.0), (12.0, 31.0)] {
            let tr = Transition::new(&tang, a, b);
            let total = tr.distance_mm(tr.shape.duration_s);
            assert!((total - tang.distance_mm(a, b)).abs() < 1e-12);
            for i in 0..=20 {
                let d = total * i as f64 / 20.0;
                let t = tr.time_at(d);
                assert!((tr.distance_mm(t) - d).abs() < 1e-12, "{a} {b} {d}");
            }
        }
    }
}
