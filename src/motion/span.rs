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

use super::profile::{bisect_max, Shape, Tangential};

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
    /// The junction's cap is known to bind the run's profile: a span may cross it only if it
    /// allows the run's cap. When false, a span may also cross a junction capped lower
    /// (above 0): the caller checks that the span's profile passes it within its cap
    /// ([`Profile::speed_at`]) and marks it binding where it does not.
    pub junction_binds: bool,
}

/// Consecutive index ranges `(first, last)` covering `moves`: each is one move, or a run of
/// moves joined tangentially whose caps differ by at most [`CAP_SPREAD`] and whose
/// junctions allow the run's own (lowest) speed cap or are not known to bind
/// ([`SpanMove::junction_binds`]).
pub fn groups(moves: &[SpanMove]) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(moves.len());
    let mut k = 0;
    while k < moves.len() {
        let first = k;
        let (mut lo, mut hi) = (moves[k].vcap_mm_s, moves[k].vcap_mm_s);
        while k + 1 < moves.len() && moves[k].joins_next {
            let next = moves[k + 1].vcap_mm_s;
            let (nlo, nhi) = (lo.min(next), hi.max(next));
            let cap = moves[k].junction_cap_mm_s;
            let fits = nlo > 0.0
                && nlo >= (1.0 - CAP_SPREAD) * nhi
                && (cap >= nlo * (1.0 - 1e-12) || (!moves[k].junction_binds && cap > 0.0));
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

/// Peak (cruise) speed of a move or span whose middle part is `mid` mm long, entered at
/// `v_in` and left at `v_out`: the highest speed ≤ `cap` from which both speed changes fit.
pub fn cruise_speed(t: &Tangential, [v_in, v_out]: [f64; 2], cap: f64, mid: f64) -> f64 {
    let fits = |vp: f64| t.distance_mm(v_in, vp) + t.distance_mm(vp, v_out) <= mid;
    let lo0 = v_in.max(v_out);
    if fits(cap) {
        return cap;
    }
    if !fits(lo0) {
        return lo0;
    }
    bisect_max(lo0, cap, 1e-9, fits)
}

/// The speed profile of a span: a speed-up, a cruise and a slow-down between the blend
/// halves at its ends, in distance from the start of its first move.
#[derive(Debug, Clone, Copy)]
pub struct Profile {
    /// Where the speed-up starts (the end of the entry blend's half), mm.
    pub start_mm: f64,
    /// The speed-up.
    pub up: Transition,
    /// Its length, mm.
    pub up_mm: f64,
    /// Cruise speed, mm/s.
    pub cruise_mm_s: f64,
    /// Cruise length, mm.
    pub cruise_mm: f64,
    /// The slow-down.
    pub down: Transition,
    /// Its length, mm.
    pub down_mm: f64,
}

impl Profile {
    /// The profile over `len_mm`, entered at `v_in` after a blend half of `entry_mm` and left
    /// at `v_out` before one of `exit_mm`, at most at `cap`.
    pub fn new(
        t: &Tangential,
        [v_in, v_out]: [f64; 2],
        cap: f64,
        [entry_mm, len_mm, exit_mm]: [f64; 3],
    ) -> Self {
        let mid = (len_mm - entry_mm - exit_mm).max(0.0);
        let vp = cruise_speed(t, [v_in, v_out], cap, mid);
        let (up_mm, down_mm) = (t.distance_mm(v_in, vp), t.distance_mm(vp, v_out));
        Profile {
            start_mm: entry_mm,
            up: Transition::new(t, v_in, vp),
            up_mm,
            cruise_mm_s: vp,
            cruise_mm: (mid - up_mm - down_mm).max(0.0),
            down: Transition::new(t, vp, v_out),
            down_mm,
        }
    }

    /// Its parts `(from, to, transition)` in distance along the span (`None`: the cruise).
    pub fn parts(&self) -> [(f64, f64, Option<Transition>); 3] {
        let (a, b) = (self.start_mm, self.start_mm + self.up_mm);
        let c = b + self.cruise_mm;
        [
            (a, b, Some(self.up)),
            (b, c, None),
            (c, c + self.down_mm, Some(self.down)),
        ]
    }

    /// Speed at distance `x_mm` along the span, mm/s (the entry speed before the speed-up,
    /// the exit speed after the slow-down).
    pub fn speed_at(&self, x_mm: f64) -> f64 {
        let [(a, b, _), (_, c, _), _] = self.parts();
        if x_mm <= a {
            self.up.s_start
        } else if x_mm < b {
            self.up.speed(self.up.time_at(x_mm - a))
        } else if x_mm <= c {
            self.cruise_mm_s
        } else {
            self.down.speed(self.down.time_at(x_mm - c))
        }
    }
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
            junction_binds: true,
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
    #[test]
    fn a_junction_not_known_to_bind_is_crossed() {
        let mut m = [
            mv(50.0, true, 30.0),
            mv(50.0, true, 50.0),
            mv(50.0, false, 0.0),
        ];
        m[0].junction_binds = false;
        assert_eq!(groups(&m), vec![(0, 2)]);
        // A stop is never crossed.
        m[0].junction_cap_mm_s = 0.0;
        assert_eq!(groups(&m), vec![(0, 0), (1, 2)]);
    }

    #[test]
    fn the_profile_speeds_up_cruises_and_slows_down() {
        let t = Tangential {
            acc_mm_s2: 400.0,
            jerk_mm_s3: 40_000.0,
        };
        let p = Profile::new(&t, [5.0, 10.0], 50.0, [0.5, 20.0, 0.2]);
        assert_eq!(p.cruise_mm_s, 50.0);
        assert!(p.cruise_mm > 0.0);
        assert_eq!(p.speed_at(0.0), 5.0);
        assert_eq!(p.speed_at(0.5), 5.0);
        let mid = 0.5 + p.up_mm + 0.5 * p.cruise_mm;
        assert_eq!(p.speed_at(mid), 50.0);
        assert!((p.speed_at(20.0 - 0.2) - 10.0).abs() < 1e-6);
        // Rising through the speed-up, falling through the slow-down.
        let (a, b) = (
            p.speed_at(0.5 + 0.3 * p.up_mm),
            p.speed_at(0.5 + 0.6 * p.up_mm),
        );
        assert!(5.0 < a && a < b && b < 50.0, "{a} {b}");
        let end = 20.0 - 0.2;
        let (c, d) = (
            p.speed_at(end - 0.6 * p.down_mm),
            p.speed_at(end - 0.3 * p.down_mm),
        );
        assert!(50.0 > c && c > d && d > 10.0, "{c} {d}");
        // Too short for the cap: the peak is lower and the two changes meet.
        let q = Profile::new(&t, [0.0, 0.0], 50.0, [0.0, 1.0, 0.0]);
        assert!(q.cruise_mm_s < 50.0 && q.cruise_mm < 1e-6);
        assert!((q.up_mm + q.down_mm - 1.0).abs() < 1e-6);
    }
}
