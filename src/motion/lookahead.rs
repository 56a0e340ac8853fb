//! Lookahead: junction speeds from blend geometry, then backward and forward passes over a
//! window of moves (or spans of tangent moves, [`super::span`]; Klipper `toolhead.py` style),
//! then emission of the time-parameterised segments (`motion::emit`): per move an S-curve
//! speed-up, a cruise and a slow-down, and a blend segment at each junction that does not
//! stop.
//!
//! Runs of moves are separated by barriers (dwell, or a command that needs motion stopped);
//! a spindle speed change, synchronised I/O or coolant is *not* a barrier: it rides in the
//! queue between the segments of the run and never flushes the lookahead.

use super::blend::Corner;
use super::emit::{emit_move, emit_span, kind_of, Span};
use super::fit_chains;
use super::limits::Limits;
use super::line_marks::{LineMarks, MAX_MARKS};
use super::merge::merge;
use super::moves::{Junction, Move, Step};
use super::profile::{bisect_max, Tangential};
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
    /// Arc lengths at which a fitted arc or a merged line passes the vertices of the source
    /// lines after `mv.line` (ascending, at most `MAX_MARKS`; empty for one source line).
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
        fitted = fit_chains::fitted_chains(&moves, &joinable, lim);
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
            let mut first = from;
            for (mv, j) in merged.into_iter().zip(last_index) {
                let mut line = line_move(mv, from + j, aux, lim);
                line.marks = merged_marks(&line, &moves[first..=from + j]);
                out.push(line);
                first = from + j + 1;
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

/// Where the merged line `line` passes the vertices between its raw moves `raw`, in
/// distance from its start: the reported line advances at each, as along a fitted arc
/// ([`LineMarks`]). None when the raw moves' lines do not follow each other or there are more
/// vertices than a segment can mark (the merged line then reports its first line throughout).
fn merged_marks(line: &Prepared, raw: &[Move]) -> Vec<f64> {
    let consecutive = raw.windows(2).all(|w| w[1].line == w[0].line + 1);
    if raw.len() < 2 || raw.len() > MAX_MARKS + 1 || !consecutive || line.len_mm <= 0.0 {
        return Vec::new();
    }
    raw[..raw.len() - 1]
        .iter()
        .map(|m| {
            let along: f64 = (0..NUM_AXES)
                .map(|i| (m.end_mm[i] - line.mv.start_mm[i]) * line.u[i])
                .sum();
            along.clamp(0.0, line.len_mm)
        })
        .collect()
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
    // Only in runs planned whole (a chunk boundary must fall at a move's end). A span may
    // first cross junctions capped below its moves; where its profile passes one too fast,
    // that junction binds and the runs are grouped and planned again.
    let can_span = commit.is_none() && !continued && lim.spans;
    let mut binds = vec![false; n];
    let ends = RunEnds {
        v_entry,
        entry_corner,
        continued,
    };
    let mut round = 0;
    let (groups, sp) = loop {
        if round == SPAN_ROUNDS {
            binds.fill(true);
        }
        let groups: Vec<(usize, usize)> = if can_span {
            let moves: Vec<span::SpanMove> = (0..n)
                .map(|k| span::SpanMove {
                    vcap_mm_s: p[k].vcap_mm_s,
                    joins_next: corners[k].is_some_and(|c| c.is_straight())
                        && p[k].mv.junction != Junction::ExactStop
                        && kind_of(&p[k].mv) == kind_of(&p[k + 1].mv),
                    junction_cap_mm_s: jmax[k],
                    junction_binds: binds[k],
                })
                .collect();
            span::groups(&moves)
        } else {
            (0..n).map(|k| (k, k)).collect()
        };
        let sp = group_speeds(&p, &corners, &jmax, &groups, &ends, window)?;
        let too_fast = passed_too_fast(&p, &jmax, &groups, &sp, &ends);
        if too_fast.is_empty() || round == SPAN_ROUNDS {
            break (groups, sp);
        }
        for k in too_fast {
            binds[k] = true;
        }
        round += 1;
    };
    let GroupSpeeds {
        glen,
        gtang,
        gcorners,
        vj,
    } = sp;
    let ng = groups.len();
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

/// How a run starts: its entry speed and the corner blend before it (a continued chunk).
struct RunEnds {
    v_entry: f64,
    entry_corner: Option<Corner>,
    continued: bool,
}

/// Rounds of grouping after which every junction a span crossed too fast binds.
const SPAN_ROUNDS: usize = 6;

/// Per group (a move or a span): its length, tangential limits, the corner after it, and the
/// planned speed at its end.
struct GroupSpeeds {
    glen: Vec<f64>,
    gtang: Vec<Tangential>,
    gcorners: Vec<Option<Corner>>,
    vj: Vec<f64>,
}

/// The junctions inside spans that the span's profile passes faster than their cap.
fn passed_too_fast(
    p: &[Prepared],
    jmax: &[f64],
    groups: &[(usize, usize)],
    sp: &GroupSpeeds,
    ends: &RunEnds,
) -> Vec<usize> {
    let mut out = Vec::new();
    for (k, &(a, b)) in groups.iter().enumerate() {
        if a == b {
            continue;
        }
        let v_in = if k > 0 { sp.vj[k - 1] } else { ends.v_entry };
        let before = if k > 0 {
            sp.gcorners[k - 1]
        } else {
            ends.entry_corner
        };
        let e = before.map_or(0.0, |c| c.half_length_mm(v_in));
        let x = sp.gcorners[k].map_or(0.0, |c| c.half_length_mm(sp.vj[k]));
        let cap = p[a..=b]
            .iter()
            .map(|m| m.vcap_mm_s)
            .fold(f64::INFINITY, f64::min);
        let profile = span::Profile::new(&sp.gtang[k], [v_in, sp.vj[k]], cap, [e, sp.glen[k], x]);
        let mut at = 0.0;
        for m in a..b {
            at += p[m].len_mm;
            if profile.speed_at(at) > jmax[m] * (1.0 + 1e-9) {
                out.push(m);
            }
        }
    }
    out
}

/// Plans the speeds at the ends of `groups` (backward and forward passes over the lookahead
/// window, then a repair of moves whose entry a window shift left without a feasible exit).
fn group_speeds(
    p: &[Prepared],
    corners: &[Option<Corner>],
    jmax: &[f64],
    groups: &[(usize, usize)],
    ends: &RunEnds,
    window: usize,
) -> Result<GroupSpeeds, PlanError> {
    let RunEnds {
        v_entry,
        entry_corner,
        continued,
    } = *ends;
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
    let bisect = |lo: f64, hi: f64, ok: &dyn Fn(f64) -> bool| bisect_max(lo, hi, 1e-9, ok);
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
    Ok(GroupSpeeds {
        glen,
        gtang,
        gcorners,
        vj,
    })
}
