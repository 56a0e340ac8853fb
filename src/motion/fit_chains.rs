//! Which runs of raw chords are fitted into arcs (issue 14, [`super::arcfit`]), and the
//! fitted moves that replace them: chains of gently turning XY feed chords are found, fitted,
//! and kept only where the fit is estimated not to run much slower than the chords
//! ([`super::fit_choice`]).

use super::arcfit::{self, V2};
use super::fit_choice;
use super::limits::Limits;
use super::line_marks::MAX_MARKS;
use super::lookahead::Prepared;
use super::moves::{Junction, Move, MoveKind};
use crate::gcode::NUM_AXES;

/// The fitted chains of `moves`, as `(first raw move, last raw move, fitted moves)` in order:
/// chains of moves that may be joined (`joinable`) are fitted, and where a fitted chain has
/// junctions much slower than its arcs (see [`split_at_slow_junctions`]) the chords around
/// them stay chords and the stretches between them are fitted again.
pub(super) fn fitted_chains(
    moves: &[Move],
    joinable: &[bool],
    lim: &Limits,
) -> Vec<(usize, usize, Vec<Prepared>)> {
    let mut out = Vec::new();
    for (i, j) in find_chains(moves, joinable, lim.exact_tolerance_mm) {
        fit_stretch(moves, i, j, lim, MAX_SPLITS, &mut out);
    }
    out
}

/// How many times a stretch is split again at its slow junctions.
const MAX_SPLITS: usize = 2;

/// Least share of a stretch's estimated time a split must be able to gain to be tried.
const MIN_SPLIT_GAIN: f64 = 0.02;

/// A junction between two fitted arcs is slow when the curvature step there caps the speed
/// below this share of the two arcs' own caps.
const SLOW_JUNCTION: f64 = 0.9;

/// Fits raw moves `i..=j` and pushes the fitted stretches to `out`; with `splits` left, a fit
/// with slow junctions is split there first.
fn fit_stretch(
    moves: &[Move],
    i: usize,
    j: usize,
    lim: &Limits,
    splits: usize,
    out: &mut Vec<(usize, usize, Vec<Prepared>)>,
) {
    let Some(arcs) = fit_arcs_raw(moves, i, j, lim) else {
        return;
    };
    let ends = gentle_ends(moves, i, j);
    // The fit is kept unless clearly slower than its chords (see `fit_choice::MARGIN`).
    let (pieces, junctions) = arc_pieces(&arcs, lim);
    let fit_ends = [
        end_speed(ends[0], arcs.first(), lim),
        end_speed(ends[1], arcs.last(), lim),
    ];
    let fit_s = fit_choice::estimate_s(&pieces, &junctions, fit_ends);
    let chords_s = estimate_chords(&moves[i..=j], ends, lim);
    let whole = if j + 1 - i >= MARGIN_CHAIN {
        fit_s <= (1.0 + fit_choice::MARGIN) * chords_s
    } else {
        fit_s < (1.0 - SHORT_CHAIN_GAIN) * chords_s
    };
    let whole_s = if whole { fit_s } else { chords_s };
    // A split is tried only where it could gain: not even the fit with its slow junctions
    // at the arcs' caps would run much faster than the choice so far (the common case on
    // clean curves, whose fitting then costs no more than before).
    let worth_splitting = splits > 0 && {
        let healed: Vec<f64> = arcs
            .windows(2)
            .zip(&junctions)
            .map(|(w, &v)| v.max(w[0].vcap_mm_s.min(w[1].vcap_mm_s)))
            .collect();
        fit_choice::estimate_s(&pieces, &healed, fit_ends) < (1.0 - MIN_SPLIT_GAIN) * whole_s
    };
    let cut = if worth_splitting {
        split_at_slow_junctions(&arcs, moves, i, j, lim)
    } else {
        Vec::new()
    };
    if cut.is_empty() {
        if whole {
            out.push((i, j, arcs));
        }
        return;
    }
    // Fit again the stretches between the chords that stay chords.
    let mut split = Vec::new();
    let mut from = i;
    for k in i..=j + 1 {
        if k > j || cut[k - i] {
            if k > from && k - from >= MIN_CHAIN {
                fit_stretch(moves, from, k - 1, lim, splits - 1, &mut split);
            }
            from = k + 1;
        }
    }
    // Keep the split only where it is estimated faster than the whole fit: on a clean fit
    // whose arcs differ in curvature (programmed arcs cut into chords and fitted back), the
    // chords around a junction can be far slower than the junction.
    if estimate_split(moves, i, j, &split, ends, lim) < whole_s {
        out.append(&mut split);
    } else if whole {
        out.push((i, j, arcs));
    }
}

/// The estimate's pieces and junction caps of fitted `arcs` (a junction is capped by its
/// curvature step).
fn arc_pieces(arcs: &[Prepared], lim: &Limits) -> (Vec<fit_choice::Piece>, Vec<f64>) {
    let pieces = arcs
        .iter()
        .map(|p| fit_choice::Piece {
            len_mm: p.len_mm,
            cap_mm_s: p.vcap_mm_s,
            tang: p.tang,
        })
        .collect();
    let junctions = arcs
        .windows(2)
        .map(|w| {
            let cap = w[0].vcap_mm_s.min(w[1].vcap_mm_s);
            cap.min(step_speed(w[0].curv - w[1].curv, lim))
        })
        .collect();
    (pieces, junctions)
}

/// Speed allowed at a curvature step `dk`, mm/s.
fn step_speed(dk: f64, lim: &Limits) -> f64 {
    if dk == 0.0 {
        f64::INFINITY
    } else {
        (lim.step_budget_mm_s2() / dk.abs()).sqrt()
    }
}

/// Speed allowed at one end of a stretch: a stop where the neighbour is not a gentle XY move,
/// else the curvature step to the (straight) neighbour when the stretch ends in the arc
/// `arc`, and no limit when it ends in a chord (`None`).
fn end_speed(gentle: bool, arc: Option<&Prepared>, lim: &Limits) -> f64 {
    match (gentle, arc) {
        (false, _) => 0.0,
        (true, Some(p)) => step_speed(p.curv, lim),
        (true, None) => f64::INFINITY,
    }
}

/// Estimated time of chords `raw` as lines.
fn estimate_chords(raw: &[Move], gentle: [bool; 2], lim: &Limits) -> f64 {
    let (p, jn, blend_s) = fit_choice::chords(raw, lim);
    let ends = [
        end_speed(gentle[0], None, lim),
        end_speed(gentle[1], None, lim),
    ];
    fit_choice::estimate_s(&p, &jn, ends) + blend_s
}

/// Estimated time of raw moves `i..=j` planned as the fitted stretches `split` (in order)
/// with chords between them.
fn estimate_split(
    moves: &[Move],
    i: usize,
    j: usize,
    split: &[(usize, usize, Vec<Prepared>)],
    gentle: [bool; 2],
    lim: &Limits,
) -> f64 {
    let mut pieces = Vec::new();
    let mut junctions = Vec::new();
    let mut blend_s = 0.0;
    // Curvature at the end of what is already in `pieces` (0 after chords).
    let mut prev_curv: Option<f64> = None;
    let mut push = |p: Vec<fit_choice::Piece>, jn: Vec<f64>, curv: (f64, f64)| {
        if let Some(c) = prev_curv {
            junctions.push(step_speed(c - curv.0, lim));
        }
        pieces.extend(p);
        junctions.extend(jn);
        prev_curv = Some(curv.1);
    };
    let mut next = i;
    for (a, b, arcs) in split {
        if *a > next {
            let (p, jn, b) = fit_choice::chords(&moves[next..*a], lim);
            blend_s += b;
            push(p, jn, (0.0, 0.0));
        }
        let (p, jn) = arc_pieces(arcs, lim);
        let curv = (
            arcs.first().map_or(0.0, |p| p.curv),
            arcs.last().map_or(0.0, |p| p.curv),
        );
        push(p, jn, curv);
        next = b + 1;
    }
    if next <= j {
        let (p, jn, b) = fit_choice::chords(&moves[next..=j], lim);
        blend_s += b;
        push(p, jn, (0.0, 0.0));
    }
    let first_curv = split.first().filter(|s| s.0 == i).and_then(|s| s.2.first());
    let last_curv = split.last().filter(|s| s.1 == j).and_then(|s| s.2.last());
    let ends = [
        end_speed(gentle[0], first_curv, lim),
        end_speed(gentle[1], last_curv, lim),
    ];
    fit_choice::estimate_s(&pieces, &junctions, ends) + blend_s
}

/// Which raw moves of `i..=j` (flags indexed from `i`) stay chords because a junction of the
/// fitted `arcs` on or in them is slow: the curvature step caps the speed there below
/// [`SLOW_JUNCTION`] of the arcs' caps. Over noisy chords (CAM points rounded to 1 µm on
/// chords alternating 0.094 / 0.006 mm) a few biarcs meet with large curvature steps, and the
/// tool nearly stops there, while the rest of the chain fits well: only the chords around
/// such a junction are given up. Empty when no junction is slow.
fn split_at_slow_junctions(
    arcs: &[Prepared],
    moves: &[Move],
    i: usize,
    j: usize,
    lim: &Limits,
) -> Vec<bool> {
    let mut cut = vec![false; j + 1 - i];
    let mut any = false;
    let budget = lim.step_budget_mm_s2();
    let mut span_start = i;
    for w in arcs.windows(2) {
        let dk = (w[0].curv - w[1].curv).abs();
        let cap = w[0].vcap_mm_s.min(w[1].vcap_mm_s);
        let slow = dk > 0.0 && (budget / dk).sqrt() < SLOW_JUNCTION * cap;
        let at_vertex = w[0].mv.end_mm == moves[w[0].last].end_mm;
        if slow {
            any = true;
            // At a vertex: the chords on both sides of it; inside a biarc: its whole span.
            let (lo, hi) = if at_vertex {
                (w[0].last, (w[0].last + 1).min(j))
            } else {
                (span_start, w[0].last)
            };
            for c in &mut cut[lo - i..=hi - i] {
                *c = true;
            }
        }
        if at_vertex {
            span_start = (w[0].last + 1).min(j);
        }
    }
    if any {
        cut
    } else {
        Vec::new()
    }
}

/// Whether the moves before `i` and after `j` continue the chain gently (tangent ends).
fn gentle_ends(moves: &[Move], i: usize, j: usize) -> [bool; 2] {
    [
        i.checked_sub(1)
            .is_some_and(|h| gentle(&moves[h], &moves[i])),
        moves.get(j + 1).is_some_and(|n| gentle(&moves[j], n)),
    ]
}

/// Two XY moves joined by a blend that turn gently enough to be fitted across.
fn gentle(a: &Move, b: &Move) -> bool {
    matches!(a.junction, Junction::Blend { .. })
        && xy_only(a)
        && xy_only(b)
        && turn(a, b).abs() <= arcfit::MAX_TURN_RAD
}

/// Signed turning angle from XY move `a` to XY move `b`, rad (> 0 turns left).
fn turn(a: &Move, b: &Move) -> f64 {
    let (u, w) = (dir2(a), dir2(b));
    (u[0] * w[1] - u[1] * w[0]).atan2(u[0] * w[0] + u[1] * w[1])
}

/// Shortest run of chords given the estimate's margin ([`fit_choice::MARGIN`]). Shorter runs,
/// a few chords between rounding-noise flips as in opencamlib's waterlines, are fitted only
/// where the estimate gains [`SHORT_CHAIN_GAIN`]: the estimate sees the run alone, but a
/// fitted run also keeps its neighbours from being merged and meets them with curvature
/// steps. Fitted within the margin, the dome waterline's short runs planned 13.9 s against
/// 13.1 s as chords; one run estimated 1 % faster cost it 0.14 s.
const MARGIN_CHAIN: usize = 12;

/// Share of its chords' estimated time a short run's fit must save to be kept.
const SHORT_CHAIN_GAIN: f64 = 0.1;

/// Shortest run of chords worth fitting.
const MIN_CHAIN: usize = 3;

/// XY length of a move (`sqrt`, not libm's slower `hypot`: mm cannot overflow).
fn xy_len(m: &Move) -> f64 {
    let (dx, dy) = (m.end_mm[0] - m.start_mm[0], m.end_mm[1] - m.start_mm[1]);
    (dx * dx + dy * dy).sqrt()
}

fn xy_only(m: &Move) -> bool {
    (2..NUM_AXES).all(|i| m.end_mm[i] == m.start_mm[i]) && xy_len(m) > 1e-9
}

fn fittable(m: &Move, exact_mm: f64) -> bool {
    m.kind == MoveKind::Feed
        && m.arc_id == 0
        && matches!(m.junction, Junction::Blend { tolerance_mm } if tolerance_mm > exact_mm)
        && xy_only(m)
}

fn dir2(m: &Move) -> V2 {
    let (dx, dy) = (m.end_mm[0] - m.start_mm[0], m.end_mm[1] - m.start_mm[1]);
    let l = (dx * dx + dy * dy).sqrt();
    [dx / l, dy / l]
}

/// Runs `(first, last)` of raw moves that may be fitted into arcs: XY feed chords with one
/// feed and one blend tolerance, nothing queued between them, turning gently.
fn find_chains(moves: &[Move], joinable: &[bool], exact_mm: f64) -> Vec<(usize, usize)> {
    // Each vertex's turn is looked at up to three times (link, and flips on both sides).
    let turns: Vec<f64> = moves.windows(2).map(|w| turn(&w[0], &w[1])).collect();
    let turn = |k: usize| turns[k];
    let link = |k: usize| {
        let (a, b) = (&moves[k], &moves[k + 1]);
        joinable[k]
            && fittable(a, exact_mm)
            && fittable(b, exact_mm)
            && a.feed_mm_s == b.feed_mm_s
            && a.junction == b.junction
            && turn(k).abs() <= arcfit::MAX_TURN_RAD
    };
    // A curve turns one way for many chords; a run whose turns flip at every vertex is a
    // jitter around a line (naive CAM), which merging (G64 Q) straightens better.
    let flips = |k: usize| {
        let (a, b) = (turn(k - 1), turn(k));
        a * b < 0.0 && a.abs().min(b.abs()) > FLIP_RAD
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < moves.len() {
        if !link(i) {
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j + 1 < moves.len() && link(j) && !flips(j) {
            j += 1;
        }
        let len: f64 = moves[i..=j].iter().map(xy_len).sum();
        if j + 1 - i >= MIN_CHAIN && len >= MIN_MEAN_CHORD_MM * (j + 1 - i) as f64 {
            out.push((i, j));
        }
        i = j + 1;
    }
    out
}

/// Shortest mean chord of a fitted run, mm. On shorter chords the arcs that keep the
/// curvature steps small are only a few chords long, and as every move starts and ends its
/// speed change at zero acceleration, speeding up over them crawls (10,000 chords of 0.02 mm
/// on a sine: 1.24× the feed bound fitted, 1.08× merged); merging does better there.
const MIN_MEAN_CHORD_MM: f64 = 0.05;

/// Turning angle below which a change of turning direction counts as rounding noise, rad.
const FLIP_RAD: f64 = 2e-3;

/// The arcs fitted over raw moves `i..=j`, tangent to the raw move before and to the one
/// after when they are XY moves joined by a blend and turning gently; `None` if the fit
/// fails. Whether the fit is worth keeping is decided by the caller.
fn fit_arcs_raw(moves: &[Move], i: usize, j: usize, lim: &Limits) -> Option<Vec<Prepared>> {
    let first = &moves[i];
    let Junction::Blend { tolerance_mm } = first.junction else {
        return None;
    };
    let t_start = i
        .checked_sub(1)
        .map(|h| &moves[h])
        .filter(|h| gentle(h, first))
        .map(dir2);
    let t_end = moves.get(j + 1).filter(|n| gentle(&moves[j], n)).map(dir2);
    let mut pts: Vec<V2> = Vec::with_capacity(j - i + 2);
    pts.push([first.start_mm[0], first.start_mm[1]]);
    pts.extend(moves[i..=j].iter().map(|m| [m.end_mm[0], m.end_mm[1]]));
    let dk_max = lim.step_budget_mm_s2() / (first.feed_mm_s * first.feed_mm_s);
    // The reported line advances by one at each vertex mark (`LineMarks`): fit only runs of
    // consecutive source lines.
    if moves[i..=j].windows(2).any(|w| w[1].line != w[0].line + 1) {
        return None;
    }
    let fitted = arcfit::fit_chain(&pts, t_start, t_end, tolerance_mm, dk_max)?;
    let marked = arcfit::mark_vertices(&fitted, &pts, MAX_MARKS);
    let mut out = Vec::with_capacity(marked.len());
    let mut start = first.start_mm;
    for arcfit::Marked {
        fitted: f,
        chord,
        marks,
    } in marked
    {
        let raw = &moves[i + f.vertex - 1];
        let mut end = raw.end_mm;
        if !f.ends_at_vertex {
            let e = f.arc.end();
            end[0] = e[0];
            end[1] = e[1];
        }
        let (t0, t1) = (f.arc.tangent_at(0.0), f.arc.tangent_at(f.arc.length_mm));
        let mut u = [0.0; NUM_AXES];
        let mut u_out = [0.0; NUM_AXES];
        u[..2].copy_from_slice(&t0);
        u_out[..2].copy_from_slice(&t1);
        let kappa = f.arc.curvature_per_mm;
        let (vcap_mm_s, tang) = if kappa != 0.0 {
            lim.arc(kappa, first.feed_mm_s)
        } else {
            (lim.vcap(&u).min(first.feed_mm_s), lim.tangential(&u))
        };
        let mv = Move {
            start_mm: start,
            end_mm: end,
            junction: if f.ends_at_vertex {
                raw.junction
            } else {
                first.junction
            },
            line: moves[(i + chord - 1).min(j)].line,
            ..*first
        };
        start = end;
        out.push(Prepared {
            mv,
            u,
            u_out,
            curv: kappa,
            heading: f.arc.heading_rad,
            len_mm: f.arc.length_mm,
            vcap_mm_s,
            tang,
            aux_after: Vec::new(),
            last: i + f.vertex - 1,
            marks,
        });
    }
    Some(out)
}
