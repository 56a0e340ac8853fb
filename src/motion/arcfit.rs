//! Arc fitting (issue 14): a run of short feed chords that turn gently (dense CAM output of a
//! curve) is replaced by a chain of tangent-continuous circular arcs (biarcs) that stays
//! within the blend tolerance of the programmed polyline.
//!
//! Why: on such a run every vertex used to be a blend pulse (sideways acceleration rising
//! from zero and back within half of each neighbouring chord), which caps the speed far below
//! what the curve needs (v³ ≲ J·L·R/4). Along an arc the sideways acceleration is held
//! (v²·κ), and between two tangent arcs the only discontinuity is a step of the curvature:
//! at speed `v` the acceleration steps by `v²·|Δκ|` within one servo period, which the
//! lookahead keeps within a share of the jerk limit (`v²·|Δκ| ≤ share·J·T`), see
//! [`super::lookahead`]. Fewer, longer moves also shrink the cost of the per-move S-curves.
//!
//! Exactness: only moves in the XY plane (no other axis moving), with the same feed, the same
//! blend tolerance (G64 P; never at G61, where the junction is an exact stop) and nothing
//! queued between them are fitted. Every fitted biarc is checked: each chord vertex it spans
//! lies within half the tolerance of it, and sampled points of it lie within 0.9 of the
//! tolerance of the chords it replaces; a run that cannot be fitted stays chords.

/// A point or vector in the XY plane.
pub type V2 = [f64; 2];

/// Longest span of chords one biarc may replace (bounds the fitting work per move).
pub const MAX_SPAN: usize = 24;
/// Largest turning angle between two chords of a fitted run, rad.
pub const MAX_TURN_RAD: f64 = 0.5;
/// Distance between the points a vertex tangent is estimated from, mm.
const STENCIL_MM: f64 = 0.5;
/// Largest half sweep of one arc, rad (so an arc never turns more than 120°).
const MAX_HALF_SWEEP_RAD: f64 = std::f64::consts::FRAC_PI_3;

fn sub(a: V2, b: V2) -> V2 {
    [a[0] - b[0], a[1] - b[1]]
}
fn dot(a: V2, b: V2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
fn cross(a: V2, b: V2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}
/// Length of `a`; plain `sqrt`, not `hypot`: coordinates in mm cannot overflow, and libm's
/// `hypot` was the largest single cost of fitting a trochoid.
fn norm(a: V2) -> f64 {
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}
fn unit(a: V2) -> Option<V2> {
    let n = norm(a);
    (n > 1e-15).then(|| [a[0] / n, a[1] / n])
}

/// `sin(x)/x`, accurate near 0.
fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

/// Displacement after arc length `s` along a path starting with heading `heading_rad` and
/// signed curvature `kappa` (1/mm, > 0 turns left), exact and stable for `kappa → 0`.
pub fn offset(heading_rad: f64, kappa: f64, s: f64) -> V2 {
    let half = 0.5 * kappa * s;
    let h = s * sinc(half);
    let a = heading_rad + half;
    [a.cos() * h, a.sin() * h]
}

/// One planar arc (or straight piece when the curvature is 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcPiece {
    /// Start point, mm.
    pub start: V2,
    /// Heading of the tangent at the start, rad.
    pub heading_rad: f64,
    /// Signed curvature, 1/mm (> 0 turns left, counter-clockwise).
    pub curvature_per_mm: f64,
    /// Arc length, mm.
    pub length_mm: f64,
}

impl ArcPiece {
    /// Point at arc length `s`.
    pub fn point_at(&self, s: f64) -> V2 {
        let d = offset(self.heading_rad, self.curvature_per_mm, s);
        [self.start[0] + d[0], self.start[1] + d[1]]
    }

    /// Unit tangent at arc length `s`.
    pub fn tangent_at(&self, s: f64) -> V2 {
        let h = self.heading_rad + self.curvature_per_mm * s;
        [h.cos(), h.sin()]
    }

    /// End point.
    pub fn end(&self) -> V2 {
        self.point_at(self.length_mm)
    }

    /// Distance from `p` to the arc (as a set of points).
    pub fn distance(&self, p: V2) -> f64 {
        ArcGeom::new(self).distance(p)
    }
}

/// An arc's end points and centre, computed once for many [`ArcPiece::distance`] queries
/// (the fit checks every chord vertex against every candidate biarc: with the sines,
/// cosines and arc tangents recomputed per query, that check was a fifth of planning a
/// trochoid).
#[derive(Debug, Clone, Copy)]
struct ArcGeom {
    a: V2,
    b: V2,
    /// Centre, radial vectors to `a` and `b`, radius, turning sign and whether the arc turns
    /// more than half a turn; `None` when straight.
    circle: Option<(V2, V2, V2, f64, f64, bool)>,
}

impl ArcGeom {
    fn new(arc: &ArcPiece) -> Self {
        let k = arc.curvature_per_mm;
        let (a, b) = (arc.start, arc.end());
        if k.abs() < 1e-9 {
            return ArcGeom { a, b, circle: None };
        }
        let t0 = arc.tangent_at(0.0);
        let c = [a[0] - t0[1] / k, a[1] + t0[0] / k];
        let wide = (k * arc.length_mm).abs() > std::f64::consts::PI;
        let circle = Some((c, sub(a, c), sub(b, c), 1.0 / k.abs(), k.signum(), wide));
        ArcGeom { a, b, circle }
    }

    /// Distance from `p`: to the circle where `p` faces the arc, else to the nearer end. `p`
    /// faces an arc of at most half a turn when it lies on the turning side of the start
    /// radius and not past the end radius; a wider arc, when either holds.
    fn distance(&self, p: V2) -> f64 {
        let (a, b) = (self.a, self.b);
        let Some((c, ca, cb, r, sign, wide)) = self.circle else {
            let ab = sub(b, a);
            let l2 = dot(ab, ab);
            let t = if l2 > 0.0 {
                (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            return norm(sub(p, [a[0] + t * ab[0], a[1] + t * ab[1]]));
        };
        let cp = sub(p, c);
        let after_start = sign * cross(ca, cp) >= 0.0;
        let before_end = sign * cross(cp, cb) >= 0.0;
        let faces = if wide {
            after_start || before_end
        } else {
            after_start && before_end
        };
        if faces {
            (norm(cp) - r).abs()
        } else {
            norm(sub(p, a)).min(norm(sub(p, b)))
        }
    }
}

/// The arc from `p0` with unit tangent `t0` through `p1`; `None` if it would turn more than
/// 120° or the points coincide.
pub fn arc_to(p0: V2, t0: V2, p1: V2) -> Option<ArcPiece> {
    let c = sub(p1, p0);
    let l = norm(c);
    if l < 1e-12 {
        return None;
    }
    let psi = cross(t0, c).atan2(dot(t0, c));
    if psi.abs() > MAX_HALF_SWEEP_RAD {
        return None;
    }
    let length_mm = if psi.abs() < 1e-12 {
        l
    } else {
        l * psi / psi.sin()
    };
    Some(ArcPiece {
        start: p0,
        heading_rad: t0[1].atan2(t0[0]),
        curvature_per_mm: 2.0 * psi.sin() / l,
        length_mm,
    })
}

/// The equal-tangent biarc from (`p0`, `t0`) to (`p1`, `t1`): two arcs, tangent to each
/// other, starting with `t0` and ending with `t1`.
pub fn biarc(p0: V2, t0: V2, p1: V2, t1: V2) -> Option<[ArcPiece; 2]> {
    let d = sub(p1, p0);
    let v = [t0[0] + t1[0], t0[1] + t1[1]];
    let (a, dv, dd) = (dot(v, v) - 4.0, dot(d, v), dot(d, d));
    // |d − α·v| = 2α: a·α² − 2·dv·α + dd = 0, the positive root.
    let alpha = if a.abs() < 1e-12 {
        if dv <= 0.0 {
            return None;
        }
        dd / (2.0 * dv)
    } else {
        (dv - (dv * dv - a * dd).max(0.0).sqrt()) / a
    };
    if !(alpha.is_finite() && alpha > 0.0) {
        return None;
    }
    let q0 = [p0[0] + alpha * t0[0], p0[1] + alpha * t0[1]];
    let q1 = [p1[0] - alpha * t1[0], p1[1] - alpha * t1[1]];
    let j = [0.5 * (q0[0] + q1[0]), 0.5 * (q0[1] + q1[1])];
    let first = arc_to(p0, t0, j)?;
    let second = arc_to(j, first.tangent_at(first.length_mm), p1)?;
    let te = second.tangent_at(second.length_mm);
    (cross(te, t1).abs() < 1e-6 && dot(te, t1) > 0.0).then_some([first, second])
}

/// Unit tangent at `b` of the circle through `a`, `b`, `c` (the chord direction when they
/// are collinear).
pub fn circle_tangent(a: V2, b: V2, c: V2) -> Option<V2> {
    let (ba, bc) = (sub(a, b), sub(c, b));
    let (la, lc) = (dot(ba, ba), dot(bc, bc));
    unit([la * bc[0] - lc * ba[0], la * bc[1] - lc * ba[1]])
}

/// Reflection of the unit vector `t` across the direction of `chord`: the tangent at the
/// far end of a circular arc that starts with `t` along `chord`.
fn reflect(t: V2, chord: V2) -> Option<V2> {
    let c = unit(chord)?;
    let k = 2.0 * dot(t, c);
    Some([k * c[0] - t[0], k * c[1] - t[1]])
}

/// Distance from `p` to the polyline `pts`.
fn distance_to_polyline(p: V2, pts: &[V2]) -> f64 {
    let mut best = f64::INFINITY;
    for w in pts.windows(2) {
        let ab = sub(w[1], w[0]);
        let l2 = dot(ab, ab);
        let t = if l2 > 0.0 {
            (dot(sub(p, w[0]), ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        best = best.min(norm(sub(p, [w[0][0] + t * ab[0], w[0][1] + t * ab[1]])));
    }
    best
}

/// True when the biarc stays within the tolerance of the chords `pts` it replaces: every
/// inner vertex within half the tolerance of it, and points sampled along it within 0.9 of
/// the tolerance of the chords near them.
fn fits(b: &[ArcPiece; 2], pts: &[V2], tol: f64) -> bool {
    let g = [ArcGeom::new(&b[0]), ArcGeom::new(&b[1])];
    let inner = &pts[1..pts.len() - 1];
    if inner
        .iter()
        .any(|&p| g[0].distance(p).min(g[1].distance(p)) > 0.5 * tol)
    {
        return false;
    }
    let total = b[0].length_mm + b[1].length_mm;
    let chords = pts.len() - 1;
    let mut along = 0.0;
    b.iter().all(|a| {
        let ok = (1..4).all(|i| {
            let s = a.length_mm * i as f64 / 4.0;
            let q = a.point_at(s);
            // The chords near the sample's share of the length (the chords are about equal).
            let c = (((along + s) / total) * chords as f64) as usize;
            let lo = c.saturating_sub(2);
            let hi = (c + 3).min(chords);
            distance_to_polyline(q, &pts[lo..=hi]) <= 0.9 * tol
        });
        along += a.length_mm;
        ok
    })
}

/// A fitted arc and the index (into the fitted points) of the vertex its biarc ends at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fitted {
    /// The arc.
    pub arc: ArcPiece,
    /// Vertex index where the biarc this arc belongs to ends.
    pub vertex: usize,
    /// True for the second arc of a biarc (it ends exactly at `vertex`).
    pub ends_at_vertex: bool,
}

/// Fits the polyline `pts` (at least 3 points) with tangent-continuous biarcs within `tol`.
/// The chain starts with tangent `t_start` (else the tangent of a circle fitted there) and, when `t_end` is given, ends with it. Where it
/// can, it keeps the curvature step between consecutive arcs within `dk_max` (1/mm), so the
/// junctions can be passed at the programmed feed. `None` if some stretch cannot be fitted.
pub fn fit_chain(
    pts: &[V2],
    t_start: Option<V2>,
    t_end: Option<V2>,
    tol: f64,
    dk_max: f64,
) -> Option<Vec<Fitted>> {
    let m = pts.len().checked_sub(1)?;
    if m < 2 {
        return None;
    }
    // Tangents from circles through points about STENCIL_MM apart, so that the rounding of
    // CAM coordinates (1e-4 mm on 0.1 mm chords) does not tilt them.
    let total: f64 = pts.windows(2).map(|w| norm(sub(w[1], w[0]))).sum();
    let w = (2 * (STENCIL_MM * m as f64 / total / 2.0).ceil() as usize).clamp(1, 16);
    let mut tang = vec![[0.0; 2]; m + 1];
    for i in 1..m {
        let h = w.min(i).min(m - i);
        let t2 = circle_tangent(pts[i - h], pts[i], pts[i + h])?;
        // The circle's tangent is off by about κ'·(h·L)²: Richardson with half the stencil
        // cancels that where the curvature changes (sines), keeping the noise low.
        let h1 = h / 2;
        tang[i] = if h1 >= 1 && 2 * h1 == h {
            let t1 = circle_tangent(pts[i - h1], pts[i], pts[i + h1])?;
            unit([(4.0 * t1[0] - t2[0]) / 3.0, (4.0 * t1[1] - t2[1]) / 3.0])?
        } else {
            t2
        };
    }
    tang[m] = match t_end {
        Some(t) => t,
        None => reflect(tang[m - 1], sub(pts[m], pts[m - 1]))?,
    };
    let t_start = match t_start {
        Some(t) => t,
        None => reflect(tang[1], sub(pts[1], pts[0]))?,
    };
    let mut out = Vec::with_capacity(m);
    let (mut s, mut t, mut k_prev) = (0, t_start, None::<f64>);
    while s < m {
        // The longest span that fits and keeps the curvature steps within `dk_max`; if none
        // does, the one with the smallest step (short spans over rounded coordinates have
        // noisy curvatures, so the longest smooth span is the best estimate of the curve).
        let hi_max = (s + MAX_SPAN).min(m);
        // Candidates (span end, biarc, curvature step), cheapest checks first; the
        // deviation check runs only on the preferred ones until one passes.
        let mut cands: Vec<(usize, [ArcPiece; 2], f64)> = Vec::with_capacity(MAX_SPAN);
        let mut e = s;
        while e < hi_max {
            // Spans 1, 2, 3, 4, 6, 8, 11, 15, 20, 24: fine where curvature changes fast,
            // coarse where the spans are long.
            e = (e + 1 + (e - s) / 3).min(hi_max);
            let Some(b) = biarc(pts[s], t, pts[e], tang[e]) else {
                break;
            };
            let (k0, k1) = (b[0].curvature_per_mm, b[1].curvature_per_mm);
            let step = k_prev
                .map_or(0.0, |kp: f64| (k0 - kp).abs())
                .max((k1 - k0).abs())
                .max(dk_max);
            cands.push((e, b, step));
        }
        // Smallest step first (all smooth ones tie at `dk_max`), then the longest span.
        cands.sort_unstable_by(|x, y| x.2.total_cmp(&y.2).then(y.0.cmp(&x.0)));
        let best = cands
            .into_iter()
            .find(|(e, b, _)| fits(b, &pts[s..=*e], tol))
            .map(|(e, b, _)| (e, b));
        let (e, b) = best?;
        for (i, arc) in b.into_iter().enumerate() {
            if arc.length_mm > 1e-9 {
                out.push(Fitted {
                    arc,
                    vertex: e,
                    ends_at_vertex: i == 1,
                });
            }
        }
        // The second arc must end exactly at the vertex (it may be dropped when tiny).
        let last = out.last_mut()?;
        last.ends_at_vertex = true;
        t = b[1].tangent_at(b[1].length_mm);
        k_prev = Some(b[1].curvature_per_mm);
        s = e;
    }
    Some(out)
}

/// An arc of a fitted chain with the chord vertices it passes (issue 14: the reported line
/// advances at each, see [`super::line_marks`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Marked {
    /// The arc.
    pub fitted: Fitted,
    /// Chord the arc starts on (1-based: chord `k` runs from `pts[k - 1]` to `pts[k]`).
    pub chord: usize,
    /// Arc lengths (ascending, within the arc) at which it passes the next vertices: after
    /// the `n`-th the tool is on chord `chord + n`.
    pub marks: Vec<f64>,
}

/// Arc length of the foot of `p` on the circle (or line) of `arc`, measured from its start
/// (negative before it, beyond `length_mm` after it).
pub fn project(arc: &ArcPiece, p: V2) -> f64 {
    let t0 = arc.tangent_at(0.0);
    let d = sub(p, arc.start);
    let k = arc.curvature_per_mm;
    if (k * arc.length_mm.max(norm(d))).abs() < 1e-9 {
        return dot(d, t0);
    }
    let c = [arc.start[0] - t0[1] / k, arc.start[1] + t0[0] / k];
    let (a, b) = (sub(arc.start, c), sub(p, c));
    cross(a, b).atan2(dot(a, b)) / k
}

/// The chain `fitted` (from [`fit_chain`] over `pts`) with the vertices each arc passes,
/// every arc split (within its circle) so that none passes more than `max_marks` vertices.
pub fn mark_vertices(fitted: &[Fitted], pts: &[V2], max_marks: usize) -> Vec<Marked> {
    let mut out = Vec::with_capacity(fitted.len());
    // Next vertex to pass; the tool is on chord `v`.
    let mut v = 1;
    for f in fitted {
        let len = f.arc.length_mm;
        let (chord, mut marks) = (v, Vec::new());
        while v < f.vertex {
            let s = project(&f.arc, pts[v]);
            if !f.ends_at_vertex && s >= len {
                break; // on the other arc of the biarc
            }
            let prev = marks.last().copied().unwrap_or(0.0);
            marks.push(s.clamp(prev, len));
            v += 1;
        }
        if f.ends_at_vertex {
            v = f.vertex + 1;
        }
        split_marked(
            Marked {
                fitted: *f,
                chord,
                marks,
            },
            max_marks,
            &mut out,
        );
    }
    out
}

/// Splits `m` at its marks until no piece has more than `max_marks` (the piece after a split
/// starts on the vertex where it was cut), appending the pieces to `out`.
pub fn split_marked(mut m: Marked, max_marks: usize, out: &mut Vec<Marked>) {
    while m.marks.len() > max_marks {
        let cut = m.marks[max_marks];
        let arc = m.fitted.arc;
        let rest = ArcPiece {
            start: arc.point_at(cut),
            heading_rad: arc.heading_rad + arc.curvature_per_mm * cut,
            curvature_per_mm: arc.curvature_per_mm,
            length_mm: arc.length_mm - cut,
        };
        let tail = Marked {
            fitted: Fitted {
                arc: rest,
                ..m.fitted
            },
            chord: m.chord + max_marks + 1,
            marks: m.marks[max_marks + 1..].iter().map(|x| x - cut).collect(),
        };
        m.marks.truncate(max_marks);
        m.fitted.arc.length_mm = cut;
        m.fitted.ends_at_vertex = false;
        out.push(m);
        m = tail;
    }
    out.push(m);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The distance from precomputed geometry is the distance to a densely sampled arc, for
    /// arcs turning either way from 1° to 300° and points all around them.
    #[test]
    fn distance_matches_a_sampled_arc() {
        for (k, len) in [
            (0.5, 0.035),
            (0.5, 2.0),
            (-0.5, 4.0),
            (0.5, 6.0),
            (0.5, 10.0),
            (-2.0, 2.6),
        ] {
            let arc = ArcPiece {
                start: [1.0, 2.0],
                heading_rad: 0.7,
                curvature_per_mm: k,
                length_mm: len,
            };
            let samples: Vec<V2> = (0..=20000)
                .map(|i| arc.point_at(len * i as f64 / 20000.0))
                .collect();
            for i in 0..400 {
                let a = i as f64 * 0.0157;
                let rad = 0.3 + (i % 7) as f64 * 0.6;
                let p = [1.0 + rad * a.cos() * 3.0, 2.0 + rad * a.sin() * 3.0];
                let sampled = samples
                    .iter()
                    .map(|q| norm(sub(p, *q)))
                    .fold(f64::INFINITY, f64::min);
                let d = arc.distance(p);
                assert!(
                    d <= sampled + 1e-12 && d >= sampled - 1e-3,
                    "k {k} len {len} p {p:?}: {d} vs sampled {sampled}"
                );
            }
        }
    }

    #[test]
    fn marks_follow_the_vertices_and_split_long_arcs() {
        // 31 chords of 0.1 mm on a circle of radius 5, fitted as one arc.
        let pts: Vec<V2> = (0..=31)
            .map(|k| {
                let a = k as f64 * 0.02;
                [5.0 * a.sin(), 5.0 - 5.0 * a.cos()]
            })
            .collect();
        let arc = ArcPiece {
            start: pts[0],
            heading_rad: 0.0,
            curvature_per_mm: 0.2,
            length_mm: 31.0 * 0.1,
        };
        let fitted = [Fitted {
            arc,
            vertex: 31,
            ends_at_vertex: true,
        }];
        let m = mark_vertices(&fitted, &pts, 10);
        // 30 inner vertices: pieces of 10 marks, each cut at the 11th.
        assert_eq!(
            m.iter().map(|x| x.marks.len()).collect::<Vec<_>>(),
            [10, 10, 8]
        );
        assert_eq!(m.iter().map(|x| x.chord).collect::<Vec<_>>(), [1, 12, 23]);
        let total: f64 = m.iter().map(|x| x.fitted.arc.length_mm).sum();
        assert!((total - 3.1).abs() < 1e-12);
        // Each mark is at its vertex: k·0.1 mm along the whole arc.
        let mut offset = 0.0;
        for piece in &m {
            for (n, s) in piece.marks.iter().enumerate() {
                let vertex = piece.chord + n;
                assert!((offset + s - vertex as f64 * 0.1).abs() < 1e-9, "{vertex}");
            }
            offset += piece.fitted.arc.length_mm;
        }
        assert!(m[..2].iter().all(|x| !x.fitted.ends_at_vertex));
        assert!(m[2].fitted.ends_at_vertex);
    }

    #[test]
    fn arc_to_and_offset_agree() {
        let a = arc_to([0.0, 0.0], [1.0, 0.0], [1.0, 1.0]).unwrap();
        assert!((a.curvature_per_mm - 1.0).abs() < 1e-12);
        let e = a.end();
        assert!((e[0] - 1.0).abs() < 1e-12 && (e[1] - 1.0).abs() < 1e-12);
        // A quarter circle about (0, 1) of radius 1: a point inside is 1 − its distance from
        // the centre away, a point beyond the arc's ends is measured to the nearer end.
        assert!((a.distance([0.5, 0.5]) - (1.0 - 0.5f64.hypot(0.5))).abs() < 1e-12);
        assert!((a.distance([-1.0, 0.0]) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn biarc_meets_both_tangents() {
        let b = biarc([0.0, 0.0], [1.0, 0.0], [3.0, 1.0], [0.0, 1.0]).unwrap();
        let e = b[1].end();
        assert!((e[0] - 3.0).abs() < 1e-9 && (e[1] - 1.0).abs() < 1e-9);
        let j0 = b[0].end();
        let j1 = b[1].start;
        assert!((j0[0] - j1[0]).abs() < 1e-12 && (j0[1] - j1[1]).abs() < 1e-12);
    }
}
