//! The finishing allowance offset of a G7x profile the way rs274 2.9 makes it: not in one
//! shift but in steps, each at most half the smallest element (a line's length, the smaller
//! of an arc's chord and radius), after each of which the elements are joined again. Where
//! two elements meant to be tangent were written with rounded numbers, the joins of one
//! step move the ends the next step starts from, so the result depends on the steps; this
//! reproduces rs274's (LinuxCNC's lathe_g70_71_demo.ngc, a line into a groove arc after a
//! short line). Found by comparing traces with `rs274 -g`, with LinuxCNC's interp_g7x.cc
//! read to understand them.
//!
//! Per step: every element shifts toward the free side (lines along their normal, arcs
//! about their centre, scaled from their start's radius); elements shorter than 0.001 are
//! dropped; where an element now ends more than 0.01 before the next starts (along the
//! feed), an arc about their former joint joins them; then, pair by pair, an element that
//! runs against the feed is dropped (the smaller of it and the one before), one shorter
//! than 0.001 too, and the others are trimmed to where they meet ([`meet`]). At the end
//! each joint is the middle of the two ends.

use super::roughing_geom::{add, mul, norm, sub, El, Pt};

/// rs274's size of an element, which bounds a step (twice it).
fn size(e: &El) -> f64 {
    match e.arc {
        None => norm(sub(e.b, e.a)),
        Some((c, _)) => norm(sub(e.a, e.b)).min(norm(sub(e.a, c))),
    }
}

/// The element shifted `d` toward the free (left) side.
fn shift(e: &El, d: f64) -> El {
    match e.arc {
        None => {
            // rs274: i·d·(start − end) / |start − end|, in its (v, u) complex frame.
            let (x, y) = (e.a[1] - e.b[1], e.a[0] - e.b[0]);
            let len = x.hypot(y);
            let n = [(d * x) / len, (-(d * y)) / len];
            El {
                a: add(e.a, n),
                b: add(e.b, n),
                ..*e
            }
        }
        Some((c, ccw)) => {
            let r = norm(sub(e.a, c));
            let r2 = if ccw { r - d } else { r + d };
            let k = r2 / r;
            El {
                a: add(c, mul(sub(e.a, c), k)),
                b: add(c, mul(sub(e.b, c), k)),
                ..*e
            }
        }
    }
}

/// rs274's test that an element does not run against the feed (toward higher `v`).
fn forward(e: &El) -> bool {
    let dv = e.b[1] - e.a[1];
    match e.arc {
        None => dv <= 1e-3,
        Some((c, ccw)) => {
            let (entry, exit) = (e.a[0] - c[0], e.b[0] - c[0]);
            // rs274's counter-clockwise is clockwise in (u, v).
            if ccw {
                entry <= 1e-3 && exit <= 1e-3 && dv <= -1e-3
            } else {
                entry >= -1e-3 && exit >= -1e-3 && dv <= -1e-3
            }
        }
    }
}

/// A complex number as rs274 has it: (v, u) (real part along the feed).
pub(super) type C = (f64, f64);

fn cplx(p: Pt) -> C {
    (p[1], p[0])
}

fn cmul(x: C, y: C) -> C {
    (x.0 * y.0 - x.1 * y.1, x.0 * y.1 + x.1 * y.0)
}

/// `a / y` for a real `a`, in the order of operations of libgcc's complex division, so
/// that ties (a line through a circle's centre line, two crossings equally near) break as
/// in rs274.
fn cdiv(a: f64, y: C) -> C {
    let (c, d) = y;
    if c.abs() < d.abs() {
        let ratio = c / d;
        let denom = c * ratio + d;
        if ratio.abs() > f64::MIN_POSITIVE {
            ((a * ratio) / denom, (-a) / denom)
        } else {
            ((c * (a / d)) / denom, (-a) / denom)
        }
    } else {
        let ratio = d / c;
        let denom = d * ratio + c;
        if ratio.abs() > f64::MIN_POSITIVE {
            (a / denom, (0.0 - a * ratio) / denom)
        } else {
            (a / denom, (0.0 - d * (a / c)) / denom)
        }
    }
}

/// `x / y` for complex numbers, in libgcc's order of operations.
pub(super) fn cdivc(x: C, y: C) -> C {
    let ((a, b), (c, d)) = (x, y);
    if c.abs() < d.abs() {
        let ratio = c / d;
        let denom = c * ratio + d;
        ((a * ratio + b) / denom, (b * ratio - a) / denom)
    } else {
        let ratio = d / c;
        let denom = d * ratio + c;
        ((b * ratio + a) / denom, (b - a * ratio) / denom)
    }
}

/// Where the line `l` crosses the circle about `c` through `on`, the crossing nearer `near`
/// (the point nearest `c` when they miss), computed as rs274 does: along the line from its
/// end, in a frame turned so that the line runs along the real axis.
fn line_circle(l: &El, c: Pt, on: Pt, near: Pt) -> Pt {
    let (s, e) = (cplx(l.a), cplx(l.b));
    let d = (s.0 - e.0, s.1 - e.1);
    let len = d.0.hypot(d.1);
    let rot = (d.0 / len, -d.1 / len);
    let (oc, cc) = (cplx(on), cplx(c));
    let pe = cmul((oc.0 - e.0, oc.1 - e.1), rot);
    let pc = cmul((cc.0 - e.0, cc.1 - e.1), rot);
    let (dr, di) = (pc.0 - pe.0, pc.1 - pe.1);
    let b = dr * dr + di * di - pc.1 * pc.1;
    let b = if b < 0.0 { 0.0 } else { b.sqrt() };
    let at = |x: f64| {
        let q = cdiv(x, rot);
        (q.0 + e.0, q.1 + e.1)
    };
    let (s1, s2) = (at(pc.0 + b), at(pc.0 - b));
    let n = cplx(near);
    let dist = |q: C| (n.0 - q.0).hypot(n.1 - q.1);
    let q = if dist(s1) < dist(s2) { s1 } else { s2 };
    [q.1, q.0]
}

/// Trims `p` and the element `n` after it to where they meet, as rs274 does.
fn meet(p: &mut El, n: &mut El) -> Result<(), String> {
    const TOL: f64 = 1e-6;
    let x = match (p.arc, n.arc) {
        (None, None) => {
            // In a frame turned so that `n` runs along the real axis from its end.
            let (s, e) = (cplx(n.a), cplx(n.b));
            let d = (s.0 - e.0, s.1 - e.1);
            let len = d.0.hypot(d.1);
            let rot = (d.0 / len, -d.1 / len);
            let (pa, pb) = (cplx(p.a), cplx(p.b));
            let ps = cmul((pa.0 - e.0, pa.1 - e.1), rot);
            let pe = cmul((pb.0 - e.0, pb.1 - e.1), rot);
            if ps.1 - pe.1 == 0.0 {
                return Err(
                    "two consecutive lines of the profile are parallel: with an \
                            allowance rs274 cannot join their offsets either (\"Cannot \
                            intersect parallel lines\"); make them one line"
                        .into(),
                );
            }
            let f = ps.1 / (ps.1 - pe.1);
            let q = (ps.0 + f * (pe.0 - ps.0), ps.1 + f * (pe.1 - ps.1));
            let q = cdivc(q, rot);
            [q.1 + e.1, q.0 + e.0]
        }
        (Some((c, _)), None) => {
            if norm(sub(n.a, p.b)) < TOL {
                return Ok(());
            }
            line_circle(n, c, p.b, n.a)
        }
        (None, Some((c, _))) => {
            if norm(sub(n.a, p.b)) < TOL {
                return Ok(());
            }
            line_circle(p, c, n.b, n.a)
        }
        (Some((c1, _)), Some((c2, _))) => {
            // From the second centre toward the first, turned by the angle at the second
            // centre (counter-clockwise in rs274's frame), at the second start's radius.
            let (r2, r1) = (norm(sub(n.a, c2)), norm(sub(p.a, c1)));
            let dist = norm(sub(c2, c1));
            if dist < 1e-12 {
                return Err("two arcs of the offset profile share their centre".into());
            }
            let cos = (dist * dist + r2 * r2 - r1 * r1) / 2.0 / r2 / dist;
            let rot = (cos, (1.0 - (cos * cos).min(1.0)).sqrt());
            let (cc1, cc2) = (cplx(c1), cplx(c2));
            let q = cmul(rot, (cc1.0 - cc2.0, cc1.1 - cc2.1));
            let q = ((q.0 / dist) * r2 + cc2.0, (q.1 / dist) * r2 + cc2.1);
            [q.1, q.0]
        }
    };
    p.b = x;
    n.a = x;
    Ok(())
}

/// The profile `els` offset by `d` toward its free side (away from it when negative), in
/// rs274's steps.
pub(super) fn offset(els: &[El], d: f64) -> Result<Vec<El>, String> {
    let mut cur: Vec<El> = els.to_vec();
    let mut done = 0.0;
    let mut guard = 0;
    while done != d {
        guard += 1;
        if guard > 100_000 || cur.is_empty() {
            return Err("the finishing allowance leaves no profile to follow".into());
        }
        let step = cur
            .iter()
            .map(|e| size(e) / 2.0)
            .fold(1e9, f64::min)
            .min((d - done).abs());
        let step = if d < 0.0 { -step } else { step };
        let next = cur
            .iter()
            .map(|e| shift(e, step))
            .filter(|s| size(s) >= 1e-3);
        // Outside corners: an arc about the former joint (the ends shifted back).
        let mut joined: Vec<El> = Vec::with_capacity(cur.len() * 2);
        for e in next {
            if let Some(last) = joined.last().copied() {
                if last.b[1] - e.a[1] > 1e-2 {
                    let (pb, na) = (shift(&last, -step).b, shift(&e, -step).a);
                    let centre = [(pb[0] + na[0]) / 2.0, (pb[1] + na[1]) / 2.0];
                    joined.push(El {
                        a: last.b,
                        b: e.a,
                        arc: Some((centre, d < 0.0)),
                        whole: true,
                    });
                }
            }
            joined.push(e);
        }
        cur = joined;
        let mut i = 0;
        while i + 1 < cur.len() {
            if !forward(&cur[i]) {
                let Some(j) = i.checked_sub(1) else {
                    return Err("the offset profile turns back at its start".into());
                };
                let drop = if size(&cur[i]) < size(&cur[j]) { i } else { j };
                cur.remove(drop);
                i = 0;
            }
            if i + 1 >= cur.len() {
                break;
            }
            if size(&cur[i]) < 1e-3 {
                cur.remove(i);
                i = 0;
            } else {
                let (l, r) = cur.split_at_mut(i + 1);
                meet(&mut l[i], &mut r[0])?;
            }
            i += 1;
        }
        done += step;
    }
    for i in 0..cur.len().saturating_sub(1) {
        let m = mul(add(cur[i].b, cur[i + 1].a), 0.5);
        cur[i].b = m;
        cur[i + 1].a = m;
    }
    Ok(cur)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_that_misses_a_circle_meets_it_at_the_nearest_point() {
        let line = El::line([1.0002, 2.0], [1.0002, -2.0]);
        let p = line_circle(&line, [0.0, 0.0], [1.0, 0.0], [1.0002, 0.1]);
        assert!((p[0] - 1.0002).abs() < 1e-12 && p[1].abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn of_two_crossings_the_one_nearer_the_given_point() {
        let line = El::line([0.6, 2.0], [0.6, -2.0]);
        let p = line_circle(&line, [0.0, 0.0], [1.0, 0.0], [0.6, 1.0]);
        assert!(
            (p[0] - 0.6).abs() < 1e-12 && (p[1] - 0.8).abs() < 1e-12,
            "{p:?}"
        );
        let q = line_circle(&line, [0.0, 0.0], [1.0, 0.0], [0.6, -1.0]);
        assert!((q[1] + 0.8).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn an_outside_corner_gets_an_arc_and_an_inside_corner_a_crossing_in_steps() {
        // Along -v at u=5 for 0.4 (steps of 0.2), down to u=4, along -v again.
        let els = [
            El::line([5.0, 0.0], [5.0, -0.4]),
            El::line([5.0, -0.4], [4.0, -1.4]),
            El::line([4.0, -1.4], [4.0, -5.0]),
        ];
        let o = offset(&els, 0.5).unwrap_or_default();
        assert_eq!(o.len(), 4, "{o:?}");
        assert_eq!(o[1].arc, Some(([5.0, -0.4], false)));
        assert!((norm(sub(o[1].b, [5.0, -0.4])) - 0.5).abs() < 1e-9, "{o:?}");
        assert!((o[2].b[0] - 4.5).abs() < 1e-9 && o[2].b == o[3].a, "{o:?}");
    }
}
