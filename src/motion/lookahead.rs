//! Lookahead: junction speeds from blend geometry, then backward and forward passes over a
//! window of moves (or spans of tangent moves, [`super::span`]; Klipper `toolhead.py` style),
//! then emission of the time-parameterised segments (`motion::emit`): per move an S-curve
//! speed-up, a cruise and a slow-down, and a blend segment at each junction that does not
//! stop.
//!
//! Runs of moves are separated by barriers (dwell, or a command that needs motion stopped);
//! a spindle speed change, synchronised I/O or coolant is *not* a barrier: it rides in the
//! queue between the segments of the run and never flushes the lookahead.

use super::arcfit::{self, V2};
use super::blend::Corner;
use super::emit::{emit_move, emit_span, kind_of, Span};
use super::fit_choice;
use super::limits::Limits;
use super::line_marks::{LineMarks, MAX_MARKS};
use super::merge::merge;
use super::moves::{Junction, Move, MoveKind, Step};
use super::profile::Tangential;
use super::segment::{AuxItem, Item, Segment, SegmentKind, Window};
use super::span;
use super::PlanError;
use crate::gcode::NUM_AXES;

/// A move with its derived data.
pub(super) struct Prepared {
    pub(super) mv: Move,
    /// Direction at the start (the direction of a line).
    pub(super) u: [f64; NUM_AXES],
    /// Direction at the end (differs from `u` on an arc).
    pub(super) u_out: [f64; NUM_AXES],
    /// Signed XY curvature, 1/mm (0 for a line), see [`arcfit`].
    pub(super) curv: f64,
    /// Heading at the start of an arc, rad.
    pub(super) heading: f64,
    pub(super) len_mm: f64,
    pub(super) vcap_mm_s: f64,
    pub(super) tang: Tangential,
    pub(super) aux_after: Vec<AuxItem>,
    /// Index of the last raw move merged into this one.
    pub(super) last: usize,
    /// Arc lengths at which a fitted arc passes the vertices of the source lines after
    /// `mv.line` (ascending, at most `MAX_MARKS`; empty for a line).
    pub(super) marks: Vec<f64>,
}

/// Moves of one run planned together before a chunk of them is committed (see
/// [`Lookahead`]). Runs up to `CHUNK_MOVES + overlap` moves are planned whole.
pub const CHUNK_MOVES: usize = 16_384;

/// Moves planned beyond a chunk before it is committed: at least the lookahead window and the
/// longest merge (256 moves), so a chunk's moves are planned and merged knowing what follows.
fn overlap(window: usize) -> usize {
    (2 * window).max(512)
}

/// Where a chunk of a long run continues from: the junction speed into its first move and the
/// corner between that move and the last committed one.
#[derive(Debug, Clone, Copy)]
struct Entry {
    v_mm_s: f64,
    corner: Option<Corner>,
}

/// Streaming lookahead: steps in, segment-queue items out, with memory bounded by the chunk
/// size whatever the length of the program.
///
/// A run (the moves between two barriers) of up to `CHUNK_MOVES` plus the overlap is planned
/// whole, exactly as it always was. A longer run is planned in chunks: the first
/// `CHUNK_MOVES` moves are planned together with the overlap that follows them (the windowed
/// backward pass ends in a stop at the end of the overlap, as it does at the end of any run),
/// only those first moves are committed, and the next chunk starts from the committed
/// junction speed and corner. Every committed move is verified to fit its speed changes and
/// blends as before; a chunk whose first move cannot fit with the speed it inherits is
/// refused with its line (never seen; the job is then refused before anything moves).
pub struct Lookahead {
    lim: Limits,
    window: usize,
    run: Vec<Move>,
    run_aux: Vec<Vec<AuxItem>>,
    entry: Option<Entry>,
    last_pose: [f64; NUM_AXES],
}

impl Lookahead {
    /// An empty lookahead with window `window` (moves), for a machine standing at `start_mm`
    /// (where a dwell before the first move stands).
    pub fn new(lim: &Limits, window: usize, start_mm: [f64; NUM_AXES]) -> Self {
        Lookahead {
            lim: *lim,
            window,
            run: Vec::new(),
            run_aux: Vec::new(),
            entry: None,
            last_pose: start_mm,
        }
    }

    /// Takes the next step; appends to `out` whatever is committed.
    pub fn push(&mut self, step: Step, out: &mut Vec<Item>) -> Result<(), PlanError> {
        match step {
            Step::Move(m) => {
                self.run.push(m);
                self.run_aux.push(Vec::new());
                if self.run.len() >= CHUNK_MOVES + overlap(self.window) {
                    self.plan_chunk(out)?;
                }
            }
            Step::Aux(a) if !a.kind.is_barrier() => match self.run_aux.last_mut() {
                Some(v) => v.push(a),
                None => out.push(Item::Aux(a)),
            },
            Step::Aux(a) => {
                self.flush(out)?;
                out.push(Item::Aux(a));
            }
            Step::Dwell { seconds, line } => {
                self.flush(out)?;
                let pos = self.last_pose;
                out.push(Item::Segment(Segment {
                    start_mm: pos,
                    end_mm: pos,
                    v0_mm_s: [0.0; NUM_AXES],
                    v1_mm_s: [0.0; NUM_AXES],
                    duration_s: seconds,
                    jerk_s: 0.0,
                    kind: SegmentKind::Dwell,
                    line,
                    length_mm: 0.0,
                    move_rest_mm: 0.0,
                    override_cap: self.lim.max_override,
                    end_override_cap: self.lim.max_override,
                    scale_rate_max: 0.0,
                    end_scale_rate_max: 0.0,
                    scale_jerk_max: 0.0,
                    brake_scale_jerk_max: 0.0,
                    next_scale_jerk_max: 0.0,
                    curvature_per_mm: 0.0,
                    heading_rad: 0.0,
                    step_jerk_mm_s3: 0.0,
                    line_marks: LineMarks::NONE,
                    window: Window::NONE,
                }));
            }
        }
        Ok(())
    }

    /// Plans what is left of the current run, to a stop.
    pub fn flush(&mut self, out: &mut Vec<Item>) -> Result<(), PlanError> {
        let moves = std::mem::take(&mut self.run);
        let aux = std::mem::take(&mut self.run_aux);
        let entry = self.entry.take();
        let from = out.len();
        plan_run(moves, aux, &self.lim, self.window, out, entry, None)?;
        self.note_pose(&out[from..]);
        Ok(())
    }

    /// Commits the first `CHUNK_MOVES` moves of a long run (planned with the overlap after
    /// them) and keeps the rest for the next chunk.
    fn plan_chunk(&mut self, out: &mut Vec<Item>) -> Result<(), PlanError> {
        let from = out.len();
        let (entry, used) = plan_run(
            self.run.clone(),
            self.run_aux.clone(),
            &self.lim,
            self.window,
            out,
            self.entry,
            Some(CHUNK_MOVES),
        )?
        .ok_or_else(|| PlanError::Invalid {
            line: self.run[0].line,
            what: "internal: a lookahead chunk committed nothing".into(),
        })?;
        self.run.drain(..used);
        self.run_aux.drain(..used);
        self.entry = Some(entry);
        self.note_pose(&out[from..]);
        Ok(())
    }

    fn note_pose(&mut self, items: &[Item]) {
        if let Some(p) = last_pose(items) {
            self.last_pose = p;
        }
    }
}

/// Plans a folded program that starts at `start_mm` into segment-queue items.
pub fn plan_steps(
    steps: Vec<Step>,
    lim: &Limits,
    window: usize,
    start_mm: [f64; NUM_AXES],
) -> Vec<Item> {
    let mut out = Vec::new();
    let mut la = Lookahead::new(lim, window, start_mm);
    // Without a chunked run nothing can fail; with one, a refused chunk ends the plan (the
    // streaming planner reports the error, see `Lookahead`).
    let ok = steps.into_iter().try_for_each(|s| la.push(s, &mut out));
    if ok.is_ok() {
        let _ = la.flush(&mut out);
    }
    out
}

fn last_pose(out: &[Item]) -> Option<[f64; NUM_AXES]> {
    out.iter().rev().find_map(|it| match it {
        Item::Segment(s) => Some(s.end_mm),
        Item::Aux(_) => None,
    })
}

fn prepare(moves: Vec<Move>, aux: Vec<Vec<AuxItem>>, lim: &Limits, fit: bool) -> Vec<Prepared> {
    let mut joinable: Vec<bool> = aux.iter().map(|a| a.is_empty()).collect();
    let mut fitted = Vec::new();
    if fit {
        for (i, j) in find_chains(&moves, &joinable, lim.exact_tolerance_mm) {
            if let Some(arcs) = fit_arcs(&moves, i, j, lim) {
                fitted.push((i, j, arcs));
            }
        }
    }
    // A fitted chain's moves are not merged, nor are the moves next to it merged with
    // anything: the chain is tangent to their directions.
    for &(i, j, _) in &fitted {
        for k in i.saturating_sub(2)..=(j + 1).min(moves.len() - 1) {
            joinable[k] = false;
        }
    }
    let mut aux: Vec<Option<Vec<AuxItem>>> = aux.into_iter().map(Some).collect();
    let mut out: Vec<Prepared> = Vec::with_capacity(moves.len());
    let lines =
        |from: usize, to: usize, out: &mut Vec<Prepared>, aux: &mut [Option<Vec<AuxItem>>]| {
            if from >= to {
                return;
            }
            let (merged, last_index) = merge(moves[from..to].to_vec(), &joinable[from..to]);
            for (mv, j) in merged.into_iter().zip(last_index) {
                out.push(line_move(mv, from + j, aux, lim));
            }
        };
    let mut next = 0;
    for (i, j, mut arcs) in fitted {
        lines(next, i, &mut out, &mut aux);
        if let Some(last) = arcs.last_mut() {
            last.aux_after = aux[j].take().unwrap_or_default();
        }
        out.extend(arcs);
        next = j + 1;
    }
    lines(next, moves.len(), &mut out, &mut aux);
    out
}

/// A straight (possibly merged) move whose last raw move is `j`.
fn line_move(mv: Move, j: usize, aux: &mut [Option<Vec<AuxItem>>], lim: &Limits) -> Prepared {
    let len_mm = mv.feed_length_mm();
    let mut u = [0.0; NUM_AXES];
    for i in 0..NUM_AXES {
        u[i] = (mv.end_mm[i] - mv.start_mm[i]) / len_mm;
    }
    Prepared {
        mv,
        u,
        u_out: u,
        curv: 0.0,
        heading: 0.0,
        len_mm,
        vcap_mm_s: lim.vcap(&u).min(mv.feed_mm_s),
        tang: lim.tangential(&u),
        aux_after: aux.get_mut(j).and_then(Option::take).unwrap_or_default(),
        marks: Vec::new(),
        last: j,
    }
}

/// Shortest run of chords worth fitting.
const MIN_CHAIN: usize = 3;

fn xy_only(m: &Move) -> bool {
    (2..NUM_AXES).all(|i| m.end_mm[i] == m.start_mm[i])
        && (m.end_mm[0] - m.start_mm[0]).hypot(m.end_mm[1] - m.start_mm[1]) > 1e-9
}

fn fittable(m: &Move, exact_mm: f64) -> bool {
    m.kind == MoveKind::Feed
        && m.arc_id == 0
        && matches!(m.junction, Junction::Blend { tolerance_mm } if tolerance_mm > exact_mm)
        && xy_only(m)
}

fn dir2(m: &Move) -> V2 {
    let (dx, dy) = (m.end_mm[0] - m.start_mm[0], m.end_mm[1] - m.start_mm[1]);
    let l = dx.hypot(dy);
    [dx / l, dy / l]
}

/// Runs `(first, last)` of raw moves that may be fitted into arcs: XY feed chords with one
/// feed and one blend tolerance, nothing queued between them, turning gently.
fn find_chains(moves: &[Move], joinable: &[bool], exact_mm: f64) -> Vec<(usize, usize)> {
    let turn = |k: usize| {
        let (u, w) = (dir2(&moves[k]), dir2(&moves[k + 1]));
        (u[0] * w[1] - u[1] * w[0]).atan2(u[0] * w[0] + u[1] * w[1])
    };
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
        let len: f64 = moves[i..=j]
            .iter()
            .map(|m| (m.end_mm[0] - m.start_mm[0]).hypot(m.end_mm[1] - m.start_mm[1]))
            .sum();
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
/// fails.
fn fit_arcs(moves: &[Move], i: usize, j: usize, lim: &Limits) -> Option<Vec<Prepared>> {
    let first = &moves[i];
    let Junction::Blend { tolerance_mm } = first.junction else {
        return None;
    };
    let gentle = |a: &Move, b: &Move| {
        let (u, w) = (dir2(a), dir2(b));
        matches!(a.junction, Junction::Blend { .. })
            && xy_only(a)
            && xy_only(b)
            && (u[0] * w[1] - u[1] * w[0])
                .atan2(u[0] * w[0] + u[1] * w[1])
                .abs()
                <= arcfit::MAX_TURN_RAD
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
    let ends = [t_start.is_some(), t_end.is_some()];
    faster_than_chords(&out, &moves[i..=j], ends, lim).then_some(out)
}

/// True when the fitted chain `arcs` is estimated to run faster than the chords `raw` it
/// replaces (see [`fit_choice`]): over noisy chords the curvature steps between the arcs can
/// cap the speed far below the chords' blends.
fn faster_than_chords(
    arcs: &[Prepared],
    raw: &[Move],
    gentle_ends: [bool; 2],
    lim: &Limits,
) -> bool {
    let piece = |p: &Prepared| fit_choice::Piece {
        len_mm: p.len_mm,
        cap_mm_s: p.vcap_mm_s,
        tang: p.tang,
    };
    let fitted: Vec<_> = arcs.iter().map(piece).collect();
    let fitted_j: Vec<f64> = arcs
        .windows(2)
        .map(|w| {
            let cap = w[0].vcap_mm_s.min(w[1].vcap_mm_s);
            let dk = (w[0].curv - w[1].curv).abs();
            if dk > 0.0 {
                cap.min((lim.step_budget_mm_s2() / dk).sqrt())
            } else {
                cap
            }
        })
        .collect();
    let (chords, chords_j) = fit_choice::chords(raw, lim);
    // At the ends: a stop where the neighbour is not a gentle XY move, else the chords go on at
    // their cap and the arcs at the curvature step to the (straight) neighbour.
    let step = |curv: f64| (lim.step_budget_mm_s2() / curv.abs().max(1e-12)).sqrt();
    let gentle = |g: bool, v: f64| if g { v } else { 0.0 };
    let (Some(first), Some(last)) = (arcs.first(), arcs.last()) else {
        return false;
    };
    let fit_ends = [
        gentle(gentle_ends[0], step(first.curv)),
        gentle(gentle_ends[1], step(last.curv)),
    ];
    let chord_ends = [
        gentle(gentle_ends[0], f64::INFINITY),
        gentle(gentle_ends[1], f64::INFINITY),
    ];
    // Only a clear loss refuses the fit (the estimate leaves out the chords' blend halves).
    fit_choice::estimate_s(&fitted, &fitted_j, fit_ends)
        <= (1.0 + fit_choice::MARGIN) * fit_choice::estimate_s(&chords, &chords_j, chord_ends)
}

/// Plans a run (or, with `commit` = `Some(c)`, a chunk of one: only the merged moves made of
/// the first `c` raw moves are emitted, and the entry of the rest is returned with the number
/// of raw moves used). `entry` continues a chunked run.
fn plan_run(
    moves: Vec<Move>,
    aux: Vec<Vec<AuxItem>>,
    lim: &Limits,
    window: usize,
    out: &mut Vec<Item>,
    entry: Option<Entry>,
    commit: Option<usize>,
) -> Result<Option<(Entry, usize)>, PlanError> {
    if moves.is_empty() {
        return Ok(None);
    }
    // Arcs are fitted only into runs planned whole: a chunk boundary could split a biarc.
    let fit = lim.fit_arcs && entry.is_none() && commit.is_none();
    let mut p = prepare(moves, aux, lim, fit);
    let n = p.len();
    let v_entry = entry.map_or(0.0, |e| e.v_mm_s);
    let entry_corner = entry.and_then(|e| e.corner);
    let continued = entry.is_some();

    // Junction k joins move k to move k + 1; the last junction is a stop.
    let corners: Vec<Option<Corner>> = (0..n)
        .map(|k| (k + 1 < n).then(|| Corner::new(&p[k].u_out, &p[k + 1].u, lim)))
        .collect();
    // Curvature step at each junction where an arc meets a tangent move (0 elsewhere).
    let dk: Vec<f64> = (0..n)
        .map(|k| match corners[k] {
            Some(c) if c.is_straight() && (p[k].curv != 0.0 || p[k + 1].curv != 0.0) => {
                (p[k].curv - p[k + 1].curv).abs()
            }
            _ => 0.0,
        })
        .collect();
    // A line next to a curvature step leaves the step its share of the jerk.
    for k in 0..n {
        let stepped = dk[k] > 0.0 || (k > 0 && dk[k - 1] > 0.0);
        if stepped && p[k].curv == 0.0 {
            p[k].tang.jerk_mm_s3 *= 1.0 - super::limits::STEP_SHARE;
        }
    }
    let p = p;
    let jmax: Vec<f64> = (0..n)
        .map(|k| {
            let Some(c) = &corners[k] else { return 0.0 };
            let (a, b) = (&p[k], &p[k + 1]);
            if a.curv != 0.0 || b.curv != 0.0 {
                // Arcs join only tangentially (a kink next to an arc is a stop), at a speed
                // whose acceleration step v²·|Δκ| stays within the step budget.
                if !c.is_straight() || a.mv.junction == Junction::ExactStop {
                    return 0.0;
                }
                let cap = a.vcap_mm_s.min(b.vcap_mm_s);
                return if dk[k] > 0.0 {
                    cap.min((lim.step_budget_mm_s2() / dk[k]).sqrt())
                } else {
                    cap
                };
            }
            let tol = if a.mv.arc_id != 0 && a.mv.arc_id == b.mv.arc_id {
                a.mv.chord_tol_mm
            } else {
                match a.mv.junction {
                    Junction::ExactStop => return 0.0,
                    Junction::Blend { tolerance_mm } => tolerance_mm,
                }
            };
            c.max_speed(a.vcap_mm_s.min(b.vcap_mm_s), a.len_mm, b.len_mm, tol)
        })
        .collect();
    // Runs of tangent moves that nothing between them slows are planned as one move (a
    // span, see [`span`]): one speed profile, so the acceleration carries across their ends.
    // Only in runs planned whole (a chunk boundary must fall at a move's end).
    let groups: Vec<(usize, usize)> = if commit.is_none() && !continued && lim.spans {
        let moves: Vec<span::SpanMove> = (0..n)
            .map(|k| span::SpanMove {
                vcap_mm_s: p[k].vcap_mm_s,
                joins_next: corners[k].is_some_and(|c| c.is_straight())
                    && p[k].mv.junction != Junction::ExactStop
                    && kind_of(&p[k].mv) == kind_of(&p[k + 1].mv),
                junction_cap_mm_s: jmax[k],
            })
            .collect();
        span::groups(&moves)
    } else {
        (0..n).map(|k| (k, k)).collect()
    };
    let ng = groups.len();
    let glen: Vec<f64> = groups
        .iter()
        .map(|&(a, b)| p[a..=b].iter().map(|m| m.len_mm).sum())
        .collect();
    let gtang: Vec<Tangential> = groups
        .iter()
        .map(|&(a, b)| span::tangential(p[a..=b].iter().map(|m| m.tang)))
        .collect();
    let gcorners: Vec<Option<Corner>> = groups.iter().map(|&(_, b)| corners[b]).collect();
    let gjmax: Vec<f64> = groups.iter().map(|&(_, b)| jmax[b]).collect();

    // Move (span) k must hold the blend halves at both ends plus its speed change:
    // g_k(a, b) = d_{k-1}(a) + d_k(b) + D_k(a, b) ≤ L_k, a and b the junction speeds.
    let half = |j: Option<usize>, v: f64| {
        j.and_then(|j| gcorners[j])
            .map_or(0.0, |c| c.half_length_mm(v))
    };
    let half_before = |k: usize, v: f64| match k.checked_sub(1) {
        Some(j) => half(Some(j), v),
        None => entry_corner.map_or(0.0, |c| c.half_length_mm(v)),
    };
    // A span's blend halves must also stay within its first and last moves (the blend
    // geometry runs along them); a single move's sum already ensures it.
    let (first_len, last_len): (Vec<f64>, Vec<f64>) = groups
        .iter()
        .map(|&(a, b)| (p[a].len_mm, p[b].len_mm))
        .unzip();
    let g = |k: usize, a: f64, b: f64| {
        let (h0, h1) = (half_before(k, a), half(Some(k), b));
        if h0 > first_len[k] || h1 > last_len[k] {
            return f64::INFINITY;
        }
        h0 + h1 + gtang[k].distance_mm(a, b)
    };
    let bisect = |mut lo: f64, mut hi: f64, ok: &dyn Fn(f64) -> bool| {
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if ok(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-9 * hi.max(1.0) {
                break;
            }
        }
        lo
    };
    // Backward step over move k: highest entry speed a ≤ a_cap that can slow to b.
    let entry = |k: usize, a_cap: f64, b: f64| {
        if a_cap <= b || g(k, a_cap, b) <= glen[k] {
            a_cap
        } else {
            bisect(b, a_cap, &|a| g(k, a, b) <= glen[k])
        }
    };
    // Forward step over move k: highest exit speed b ≤ b_cap reachable from a.
    let exit = |k: usize, a: f64, b_cap: f64| {
        if b_cap <= a || g(k, a, b_cap) <= glen[k] {
            b_cap
        } else {
            bisect(a, b_cap, &|b| g(k, a, b) <= glen[k])
        }
    };

    let passes = |jmax: &[f64]| {
        let mut vj = jmax.to_vec();
        let mut base = 0;
        let mut v_start = v_entry;
        while base < ng {
            let end = (base + window).min(ng);
            // Backward pass from a stop at the end of the window.
            vj[end - 1] = 0.0;
            for k in (base..end - 1).rev() {
                vj[k] = entry(k + 1, jmax[k], vj[k + 1]);
            }
            // Forward pass.
            let mut prev = v_start;
            for k in base..end {
                vj[k] = exit(k, prev, vj[k]);
                prev = vj[k];
            }
            let commit = if end == ng {
                end - base
            } else {
                ((end - base) / 2).max(1)
            };
            v_start = vj[base + commit - 1];
            base += commit;
        }
        vj
    };
    // The room a move needs is not monotone in its exit speed (a faster exit shortens the
    // slow-down but lengthens the blend), so a window shift can leave a move whose entry was
    // committed earlier without a feasible exit. Verify every move and repair by lowering
    // the junction speeds around it until all fit (speeds only go down, so this ends: at
    // worst in exact stops, which always fit).
    let mut jmax = gjmax;
    let mut vj = passes(&jmax);
    for round in 0.. {
        let mut bad = false;
        for k in 0..ng {
            let a = if k > 0 { vj[k - 1] } else { v_entry };
            if g(k, a, vj[k]) > glen[k] * (1.0 + 1e-12) + 1e-12 {
                bad = true;
                if k == 0 && continued && round > 40 {
                    // Only a chunk's first move has a speed it cannot lower (the previous
                    // chunk committed it); from rest every move fits.
                    return Err(PlanError::Invalid {
                        line: p[0].mv.line,
                        what: "the lookahead cannot continue this long run at this move \
                               (end the run here with G61 or a dwell)"
                            .into(),
                    });
                }
                let f = if round < 20 { 0.8 } else { 0.0 };
                if k > 0 {
                    jmax[k - 1] = jmax[k - 1].min(f * vj[k - 1]);
                }
                jmax[k] = jmax[k].min(f * vj[k]);
            }
        }
        if !bad {
            break;
        }
        vj = passes(&jmax);
    }
    let emit = match commit {
        Some(c) => groups
            .iter()
            .take_while(|&&(_, b)| p[b].last < c)
            .count()
            .min(ng - 1),
        None => ng,
    };
    for k in 0..emit {
        let v_in = if k > 0 { vj[k - 1] } else { v_entry };
        let before = if k > 0 { gcorners[k - 1] } else { entry_corner };
        let (a, b) = groups[k];
        let steps = [if a > 0 { dk[a - 1] } else { 0.0 }, dk[b]];
        if a == b {
            emit_move(&p, &corners, before, a, [v_in, vj[k]], steps, lim, out);
        } else {
            let sp = Span {
                first: a,
                last: b,
                len_mm: glen[k],
                tang: gtang[k],
                vcap_mm_s: p[a..=b]
                    .iter()
                    .map(|m| m.vcap_mm_s)
                    .fold(f64::INFINITY, f64::min),
            };
            emit_span(&p, &corners, &dk, before, &sp, [v_in, vj[k]], lim, out);
        }
    }
    Ok(match (commit, emit) {
        (Some(_), e) if e > 0 => Some((
            Entry {
                v_mm_s: vj[e - 1],
                corner: gcorners[e - 1],
            },
            p[groups[e - 1].1].last + 1,
        )),
        _ => None,
    })
}
