//! Plane geometry of the lathe roughing and finishing cycles (G70, G71, G72), in a
//! normalised frame: `u` is the axis the passes step along (the cut depth grows as `u`
//! falls, the stock is at high `u`) and `v` the axis a pass feeds along (toward lower `v`).
//! The interpreter maps X/Z onto this frame and back, so one set of rules serves outside
//! and inside turning and facing alike.

/// A point `[u, v]`.
pub(super) type Pt = [f64; 2];

/// Coordinates closer than this are the same point.
pub(super) const EPS: f64 = 1e-9;

/// One element of a profile: a line, or an arc about `c` (counter-clockwise in the (u, v)
/// plane when `ccw`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct El {
    pub a: Pt,
    pub b: Pt,
    pub arc: Option<(Pt, bool)>,
    /// An element as programmed (or a corner or closing element), not a piece of one:
    /// G7x.1 feeds to the start of these first, as rs274 does.
    pub whole: bool,
}

pub(super) fn sub(p: Pt, q: Pt) -> Pt {
    [p[0] - q[0], p[1] - q[1]]
}
pub(super) fn add(p: Pt, q: Pt) -> Pt {
    [p[0] + q[0], p[1] + q[1]]
}
pub(super) fn mul(p: Pt, k: f64) -> Pt {
    [p[0] * k, p[1] * k]
}
pub(super) fn norm(p: Pt) -> f64 {
    p[0].hypot(p[1])
}
fn cross(p: Pt, q: Pt) -> f64 {
    p[0] * q[1] - p[1] * q[0]
}
/// `p` turned a quarter counter-clockwise.
fn left(p: Pt) -> Pt {
    [-p[1], p[0]]
}
fn unit(p: Pt) -> Pt {
    let n = norm(p);
    if n > 0.0 {
        mul(p, 1.0 / n)
    } else {
        p
    }
}
pub(super) fn same(p: Pt, q: Pt) -> bool {
    norm(sub(p, q)) < 1e-7
}

impl El {
    pub(super) fn line(a: Pt, b: Pt) -> El {
        El {
            a,
            b,
            arc: None,
            whole: true,
        }
    }

    /// Unit tangent (direction of travel) at `p`.
    pub(super) fn tangent(&self, p: Pt) -> Pt {
        match self.arc {
            None => unit(sub(self.b, self.a)),
            Some((c, ccw)) => {
                let t = unit(left(sub(p, c)));
                if ccw {
                    t
                } else {
                    mul(t, -1.0)
                }
            }
        }
    }

    /// Angle swept from `p` to `q` along the arc, in [0, 2π).
    pub(super) fn sweep(&self, p: Pt, q: Pt) -> f64 {
        let Some((c, ccw)) = self.arc else {
            return 0.0;
        };
        let (pa, qa) = (sub(p, c), sub(q, c));
        let mut s = qa[1].atan2(qa[0]) - pa[1].atan2(pa[0]);
        if !ccw {
            s = -s;
        }
        if s < -1e-12 {
            s += std::f64::consts::TAU;
        }
        s.max(0.0)
    }

    /// Points of the element with `u == level`, in travel order, after `from` (and at
    /// `from` itself when `inclusive`).
    fn at_level(&self, from: Pt, level: f64, inclusive: bool) -> Vec<Pt> {
        match self.arc {
            None => {
                let (a, b) = (from, self.b);
                let du = b[0] - a[0];
                if du.abs() < EPS {
                    return Vec::new();
                }
                let t = (level - a[0]) / du;
                let lo = if inclusive { -EPS } else { EPS };
                if t >= lo && t <= 1.0 + EPS {
                    vec![[level, a[1] + t * (b[1] - a[1])]]
                } else {
                    Vec::new()
                }
            }
            Some((c, _)) => {
                let r = norm(sub(self.a, c));
                let h = r * r - (level - c[0]).powi(2);
                if h < -EPS {
                    return Vec::new();
                }
                let dv = h.max(0.0).sqrt();
                let total = self.sweep(from, self.b);
                let mut v: Vec<(f64, Pt)> = [[level, c[1] + dv], [level, c[1] - dv]]
                    .into_iter()
                    .map(|p| (self.sweep(from, p), p))
                    .filter(|&(s, p)| {
                        (s > 1e-9 || (inclusive && same(p, from))) && s <= total + 1e-9
                    })
                    .collect();
                v.sort_by(|x, y| x.0.total_cmp(&y.0));
                v.into_iter().map(|x| x.1).collect()
            }
        }
    }

    /// The part of the element from `p` to `q` (both on it).
    pub(super) fn piece(&self, p: Pt, q: Pt) -> El {
        El {
            a: p,
            b: q,
            arc: self.arc,
            whole: false,
        }
    }

    /// Lowest `u` on the element.
    fn min_u(&self) -> f64 {
        let m = self.a[0].min(self.b[0]);
        match self.arc {
            None => m,
            Some((c, _)) => {
                let r = norm(sub(self.a, c));
                let bottom = [c[0] - r, c[1]];
                let s = self.sweep(self.a, bottom);
                if s > 0.0 && s < self.sweep(self.a, self.b) {
                    m.min(bottom[0])
                } else {
                    m
                }
            }
        }
    }
}

/// An arc that passes over its highest `u` inside is cut there in two, as rs274 does for
/// the walk along the contour; anything else stays whole. rs274 cuts only an arc that
/// turns clockwise in (u, v) (counter-clockwise in its frame): one that turns the other
/// way can only pass over its top when the allowance offset joined it to the next element
/// at the far crossing of their circles (a profile that does not suit the cycle, such as a
/// turning profile under G72), and rs274 draws it whole.
pub(super) fn split_at_top(e: &El) -> Vec<El> {
    let Some((c, false)) = e.arc else {
        return vec![*e];
    };
    let top = [c[0] + norm(sub(e.a, c)), c[1]];
    let s = e.sweep(e.a, top);
    if s > 1e-9 && s < e.sweep(e.a, e.b) - 1e-9 {
        vec![El { b: top, ..*e }, El { a: top, ..*e }]
    } else {
        vec![*e]
    }
}

/// The element goes down from `p` (its start): its tangent points to lower `u`, or it is an
/// arc that starts level at its top (a corner arc, the second half of an arc split at its
/// top), where rs274 already bridges a pocket.
pub(super) fn dips(e: &El, p: Pt) -> bool {
    let t = e.tangent(p)[0];
    t < -EPS || (t.abs() <= 1e-7 && e.arc.is_some_and(|(c, _)| c[0] < p[0] - 1e-7))
}

/// The element never moves toward higher `v` (against the feed direction).
pub(super) fn monotonic(e: &El) -> bool {
    if e.tangent(e.a)[1] > 1e-7 || e.tangent(e.b)[1] > 1e-7 {
        return false;
    }
    let Some((c, _)) = e.arc else {
        return true;
    };
    let r = norm(sub(e.a, c));
    let total = e.sweep(e.a, e.b);
    [[c[0], c[1] + r], [c[0], c[1] - r]].into_iter().all(|p| {
        let s = e.sweep(e.a, p);
        s <= 1e-9 || s >= total - 1e-9
    })
}

/// The profile with each corner whose `rounds` entry (that of the element ending there) is
/// positive replaced by an arc of that radius tangent to both lines. Only corners between
/// two lines can be rounded.
pub(super) fn round_corners(els: &[El], rounds: &[f64]) -> Result<Vec<El>, String> {
    let mut out: Vec<El> = Vec::with_capacity(els.len() * 2);
    // Where the element after a round starts (the round's end).
    let mut from: Option<Pt> = None;
    for (i, e) in els.iter().enumerate() {
        let mut e = *e;
        if let Some(p) = from.take() {
            e.a = p;
        }
        out.push(e);
        let rho = rounds.get(i).copied().unwrap_or(0.0);
        if rho <= 0.0 {
            continue;
        }
        let Some(next) = els.get(i + 1) else {
            continue;
        };
        if e.arc.is_some() || next.arc.is_some() {
            return Err(format!(
                "a corner round (A{rho}) needs lines on both sides of its corner"
            ));
        }
        let q = e.b;
        let (t1, t2) = (e.tangent(q), next.tangent(q));
        let turn = cross(t1, t2);
        let cos = (t1[0] * t2[0] + t1[1] * t2[1]).clamp(-1.0, 1.0);
        if turn.abs() < EPS && cos > 0.0 {
            continue;
        }
        let reach = rho * (cos.acos() / 2.0).tan();
        let (p1, p2) = (sub(q, mul(t1, reach)), add(q, mul(t2, reach)));
        if reach > norm(sub(q, e.a)) + EPS || reach > norm(sub(next.b, q)) + EPS {
            return Err(format!(
                "the corner round A{rho} is longer than a line beside it"
            ));
        }
        let side = if turn > 0.0 { 1.0 } else { -1.0 };
        let c = add(p1, mul(left(t1), rho * side));
        if let Some(last) = out.last_mut() {
            last.b = p1;
        }
        out.push(El {
            a: p1,
            b: p2,
            arc: Some((c, turn > 0.0)),
            whole: true,
        });
        from = Some(p2);
    }
    Ok(out)
}

/// The profile shifted `d` toward its free (left) side, away from it when negative, as rs274
/// shifts it (`roughing_steps.rs`): elements that no longer meet are trimmed to their
/// crossing at inside corners, and joined by an arc about the corner at outside corners.
/// An arc smaller than the allowance on its inside shrinks in those steps until it is
/// dropped (below 0.001), as in rs274, which does not refuse it.
pub(super) fn offset(els: &[El], d: f64) -> Result<Vec<El>, String> {
    if d == 0.0 {
        return Ok(els.to_vec());
    }
    super::roughing_steps::offset(els, d)
}

/// Where the contour, walked from `from` on element `i`, first reaches `u >= level` (when
/// `strict`, the starting point itself does not count).
pub(super) fn first_reach(
    els: &[El],
    i: usize,
    from: Pt,
    level: f64,
    strict: bool,
) -> Option<(usize, Pt)> {
    for (j, e) in els.iter().enumerate().skip(i) {
        let start = if j == i { from } else { e.a };
        let at_start = !(j == i && strict);
        if at_start && start[0] >= level - 1e-7 {
            return Some((j, start));
        }
        for p in e.at_level(start, level, at_start) {
            let t = e.tangent(p);
            if t[0] > EPS || same(p, e.b) && e.b[0] >= level - 1e-7 {
                return Some((j, p));
            }
        }
        if e.b[0] >= level - 1e-7 && start[0] < level - 1e-7 {
            return Some((j, e.b));
        }
    }
    None
}

/// Where the contour, walked from `from` on element `i`, first comes down to `u <= level`.
pub(super) fn first_drop(els: &[El], i: usize, from: Pt, level: f64) -> Option<(usize, Pt)> {
    for (j, e) in els.iter().enumerate().skip(i) {
        let start = if j == i { from } else { e.a };
        if start[0] <= level + 1e-7 {
            return Some((j, start));
        }
        if let Some(p) = e.at_level(start, level, false).into_iter().next() {
            return Some((j, p));
        }
    }
    None
}

/// Lowest `u` of the contour from (`i`, `from`) to (`j`, `to`).
pub(super) fn min_between(els: &[El], i: usize, from: Pt, j: usize, to: Pt) -> f64 {
    let mut m = from[0].min(to[0]);
    for (k, e) in els.iter().enumerate().take(j + 1).skip(i) {
        let a = if k == i { from } else { e.a };
        let b = if k == j { to } else { e.b };
        m = m.min(e.piece(a, b).min_u());
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_corner_gets_an_arc_inside_corner_a_crossing() {
        // Shoulder: along -v at u=5, out to u=8, along -v again.
        let els = [
            El::line([5.0, 0.0], [5.0, -5.0]),
            El::line([5.0, -5.0], [8.0, -5.0]),
            El::line([8.0, -5.0], [8.0, -10.0]),
        ];
        let o = offset(&els, 1.0).unwrap();
        assert_eq!(o.len(), 4);
        assert!(same(o[0].b, [6.0, -4.0]) && same(o[1].a, [6.0, -4.0]));
        assert!(same(o[1].b, [8.0, -4.0]));
        assert_eq!(o[2].arc, Some(([8.0, -5.0], false)));
        assert!(same(o[2].b, [9.0, -5.0]) && same(o[3].b, [9.0, -10.0]));
    }

    #[test]
    fn a_round_is_tangent_to_both_lines_and_refused_next_to_an_arc() {
        // Along -v, then a right angle out to higher u: a round of 1 at (5, -5).
        let els = [
            El::line([5.0, 0.0], [5.0, -5.0]),
            El::line([5.0, -5.0], [8.0, -5.0]),
        ];
        let r = round_corners(&els, &[1.0, 0.0]).unwrap();
        assert_eq!(r.len(), 3);
        assert!(same(r[0].b, [5.0, -4.0]) && same(r[1].a, [5.0, -4.0]));
        assert!(same(r[1].b, [6.0, -5.0]) && same(r[2].a, [6.0, -5.0]));
        assert_eq!(r[1].arc, Some(([6.0, -4.0], true)));
        assert!(same(r[2].b, [8.0, -5.0]));
        // No round asked: the profile is unchanged.
        assert_eq!(round_corners(&els, &[0.0, 0.0]).unwrap(), els.to_vec());
        // Longer than the line beside it.
        assert!(round_corners(&els, &[4.0, 0.0]).is_err());
        let arc = [
            els[0],
            El {
                a: [5.0, -5.0],
                b: [7.0, -7.0],
                arc: Some(([7.0, -5.0], true)),
                whole: true,
            },
        ];
        assert!(round_corners(&arc, &[0.5, 0.0]).is_err());
    }

    #[test]
    fn an_arc_starting_level_at_its_top_dips() {
        // Corner arc about (3, -4) from its top (4, -4), clockwise in (u, v): goes down.
        let corner = El {
            a: [4.0, -4.0],
            b: [3.866, -4.5],
            arc: Some(([3.0, -4.0], false)),
            whole: true,
        };
        assert!(dips(&corner, corner.a));
        // Level along -v, and an arc leaving its bottom: neither dips.
        assert!(!dips(&El::line([4.0, 0.0], [4.0, -4.0]), [4.0, 0.0]));
        let up = El {
            a: [2.0, -4.0],
            b: [3.0, -5.0],
            arc: Some(([3.0, -4.0], true)),
            whole: true,
        };
        assert!(!dips(&up, up.a));
        assert!(dips(&El::line([4.0, 0.0], [3.0, -1.0]), [4.0, 0.0]));
    }

    #[test]
    fn reach_and_drop_on_lines_and_arcs() {
        let els = [
            El::line([5.0, 0.0], [9.0, -4.0]),
            El {
                a: [9.0, -4.0],
                b: [9.0, -8.0],
                arc: Some(([9.0, -6.0], true)),
                whole: true,
            },
        ];
        let (j, p) = first_reach(&els, 0, [5.0, 0.0], 7.0, false).unwrap();
        assert_eq!(j, 0);
        assert!(same(p, [7.0, -2.0]));
        // The arc dips to u=7 at v=-6 and climbs back to 9.
        let (j, p) = first_drop(&els, 1, [9.0, -4.0], 8.0).unwrap();
        assert_eq!(j, 1);
        assert!((p[0] - 8.0).abs() < 1e-9 && p[1] > -6.0);
        let (_, p) = first_reach(&els, 1, p, 8.0, true).unwrap();
        assert!((p[0] - 8.0).abs() < 1e-9 && p[1] < -6.0);
        assert!((min_between(&els, 0, [5.0, 0.0], 1, [9.0, -8.0]) - 5.0).abs() < 1e-12);
        assert!((els[1].min_u() - 7.0).abs() < 1e-12);
    }
}
