//! Lookahead: junction speeds from blend geometry, then backward and forward passes over a
//! window of moves (Klipper `toolhead.py` style), then emission of the time-parameterised
//! segments: per move an S-curve speed-up, a cruise and a slow-down, and a blend segment at
//! each junction that does not stop.
//!
//! Runs of moves are separated by barriers (dwell, or a command that needs motion stopped);
//! a spindle speed change, synchronised I/O or coolant is *not* a barrier: it rides in the
//! queue between the segments of the run and never flushes the lookahead.

use super::blend::Corner;
use super::limits::Limits;
use super::merge::merge;
use super::moves::{Junction, Move, MoveKind, Step};
use super::profile::Tangential;
use super::segment::{AuxItem, Item, Segment, SegmentKind};
use super::PlanError;
use crate::gcode::NUM_AXES;

/// A move with its derived data.
struct Prepared {
    mv: Move,
    u: [f64; NUM_AXES],
    len_mm: f64,
    vcap_mm_s: f64,
    tang: Tangential,
    aux_after: Vec<AuxItem>,
    /// Index of the last raw move merged into this one.
    last: usize,
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

fn prepare(moves: Vec<Move>, aux: Vec<Vec<AuxItem>>, lim: &Limits) -> Vec<Prepared> {
    let joinable: Vec<bool> = aux.iter().map(|a| a.is_empty()).collect();
    let (merged, last_index) = merge(moves, &joinable);
    let mut aux: Vec<Option<Vec<AuxItem>>> = aux.into_iter().map(Some).collect();
    merged
        .into_iter()
        .zip(last_index)
        .map(|(mv, j)| {
            let len_mm = mv.feed_length_mm();
            let mut u = [0.0; NUM_AXES];
            for i in 0..NUM_AXES {
                u[i] = (mv.end_mm[i] - mv.start_mm[i]) / len_mm;
            }
            let vcap = lim.vcap(&u).min(mv.feed_mm_s);
            Prepared {
                mv,
                u,
                len_mm,
                vcap_mm_s: vcap,
                tang: lim.tangential(&u),
                aux_after: aux.get_mut(j).and_then(Option::take).unwrap_or_default(),
                last: j,
            }
        })
        .collect()
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
    let p = prepare(moves, aux, lim);
    let n = p.len();
    let v_entry = entry.map_or(0.0, |e| e.v_mm_s);
    let entry_corner = entry.and_then(|e| e.corner);
    let continued = entry.is_some();

    // Junction k joins move k to move k + 1; the last junction is a stop.
    let corners: Vec<Option<Corner>> = (0..n)
        .map(|k| (k + 1 < n).then(|| Corner::new(&p[k].u, &p[k + 1].u, lim)))
        .collect();
    let jmax: Vec<f64> = (0..n)
        .map(|k| {
            let Some(c) = &corners[k] else { return 0.0 };
            let (a, b) = (&p[k], &p[k + 1]);
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
    // Move k must hold the blend halves at both ends plus its speed change:
    // g_k(a, b) = d_{k-1}(a) + d_k(b) + D_k(a, b) ≤ L_k, a and b the junction speeds.
    let half = |j: Option<usize>, v: f64| {
        j.and_then(|j| corners[j])
            .map_or(0.0, |c| c.half_length_mm(v))
    };
    let half_before = |k: usize, v: f64| match k.checked_sub(1) {
        Some(j) => half(Some(j), v),
        None => entry_corner.map_or(0.0, |c| c.half_length_mm(v)),
    };
    let g = |k: usize, a: f64, b: f64| {
        half_before(k, a) + half(Some(k), b) + p[k].tang.distance_mm(a, b)
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
        if a_cap <= b || g(k, a_cap, b) <= p[k].len_mm {
            a_cap
        } else {
            bisect(b, a_cap, &|a| g(k, a, b) <= p[k].len_mm)
        }
    };
    // Forward step over move k: highest exit speed b ≤ b_cap reachable from a.
    let exit = |k: usize, a: f64, b_cap: f64| {
        if b_cap <= a || g(k, a, b_cap) <= p[k].len_mm {
            b_cap
        } else {
            bisect(a, b_cap, &|b| g(k, a, b) <= p[k].len_mm)
        }
    };

    let passes = |jmax: &[f64]| {
        let mut vj = jmax.to_vec();
        let mut base = 0;
        let mut v_start = v_entry;
        while base < n {
            let end = (base + window).min(n);
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
            let commit = if end == n {
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
    let mut jmax = jmax;
    let mut vj = passes(&jmax);
    for round in 0.. {
        let mut bad = false;
        for k in 0..n {
            let a = if k > 0 { vj[k - 1] } else { v_entry };
            if g(k, a, vj[k]) > p[k].len_mm * (1.0 + 1e-12) + 1e-12 {
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
        Some(c) => p.iter().take_while(|m| m.last < c).count().min(n - 1),
        None => n,
    };
    for k in 0..emit {
        let v_in = if k > 0 { vj[k - 1] } else { v_entry };
        let before = if k > 0 { corners[k - 1] } else { entry_corner };
        emit_move(&p, &corners, before, k, v_in, vj[k], lim, out);
    }
    Ok(match (commit, emit) {
        (Some(_), e) if e > 0 => Some((
            Entry {
                v_mm_s: vj[e - 1],
                corner: corners[e - 1],
            },
            p[e - 1].last + 1,
        )),
        _ => None,
    })
}

fn kind_of(m: &Move) -> SegmentKind {
    match m.kind {
        MoveKind::Rapid => SegmentKind::Rapid,
        MoveKind::Feed => SegmentKind::Feed,
    }
}

fn push(out: &mut Vec<Item>, lim: &Limits, mut s: Segment) {
    if s.duration_s <= 0.0 {
        return;
    }
    s.override_cap = lim.override_cap(&s);
    out.push(Item::Segment(s));
}

/// Emits move `k` (S-curve up, cruise, S-curve down) and the blend at its end.
#[allow(clippy::too_many_arguments)]
fn emit_move(
    p: &[Prepared],
    corners: &[Option<Corner>],
    before: Option<Corner>,
    k: usize,
    v_in: f64,
    v_out: f64,
    lim: &Limits,
    out: &mut Vec<Item>,
) {
    let m = &p[k];
    let e = before.map_or(0.0, |c| c.half_length_mm(v_in));
    let x = corners[k].map_or(0.0, |c| c.half_length_mm(v_out));
    let mid = (m.len_mm - e - x).max(0.0);
    let kind = kind_of(&m.mv);
    let t = &m.tang;
    // Peak speed of the middle part.
    let fits = |vp: f64| t.distance_mm(v_in, vp) + t.distance_mm(vp, v_out) <= mid;
    let lo0 = v_in.max(v_out);
    let vp = if fits(m.vcap_mm_s) {
        m.vcap_mm_s
    } else if !fits(lo0) {
        lo0
    } else {
        let (mut lo, mut hi) = (lo0, m.vcap_mm_s);
        for _ in 0..60 {
            let c = 0.5 * (lo + hi);
            if fits(c) {
                lo = c;
            } else {
                hi = c;
            }
            if hi - lo <= 1e-9 * hi.max(1.0) {
                break;
            }
        }
        lo
    };
    let d_up = t.distance_mm(v_in, vp);
    let d_down = t.distance_mm(vp, v_out);
    let cruise = (mid - d_up - d_down).max(0.0);
    let mut pos = m.mv.start_mm;
    for i in 0..NUM_AXES {
        pos[i] += m.u[i] * e;
    }
    let mut done = e;
    let line = m.mv.line;
    let first_piece = out.len();
    let mut piece = |s0: f64,
                     s1: f64,
                     dur: f64,
                     jerk: f64,
                     len: f64,
                     pos: &mut [f64; NUM_AXES],
                     done: &mut f64| {
        *done += len;
        let mut end = *pos;
        for i in 0..NUM_AXES {
            end[i] += m.u[i] * len;
        }
        let seg = Segment {
            start_mm: *pos,
            end_mm: end,
            v0_mm_s: m.u.map(|c| c * s0),
            v1_mm_s: m.u.map(|c| c * s1),
            duration_s: dur,
            jerk_s: jerk,
            kind,
            line,
            length_mm: len,
            move_rest_mm: (m.len_mm - *done).max(0.0),
            override_cap: 1.0,
            end_override_cap: 1.0,
            scale_rate_max: 0.0,
            end_scale_rate_max: 0.0,
            scale_jerk_max: 0.0,
            brake_scale_jerk_max: 0.0,
            next_scale_jerk_max: 0.0,
        };
        *pos = end;
        push(out, lim, seg);
    };
    let up = t.shape(v_in, vp);
    piece(
        v_in,
        vp,
        up.duration_s,
        up.jerk_s,
        d_up,
        &mut pos,
        &mut done,
    );
    if cruise > 0.0 && vp > 0.0 {
        piece(vp, vp, cruise / vp, 0.0, cruise, &mut pos, &mut done);
    }
    let down = t.shape(vp, v_out);
    piece(
        vp,
        v_out,
        down.duration_s,
        down.jerk_s,
        d_down,
        &mut pos,
        &mut done,
    );
    // The blend starts from exact geometry, so rounding never accumulates.
    let mut corner_start = m.mv.end_mm;
    for i in 0..NUM_AXES {
        corner_start[i] -= m.u[i] * x;
    }
    // The last piece ends exactly where the blend (or the next move) starts.
    if out.len() > first_piece {
        if let Some(Item::Segment(last)) = out.last_mut() {
            last.end_mm = corner_start;
        }
    }
    out.extend(m.aux_after.iter().map(|a| Item::Aux(*a)));
    if let Some(c) = corners[k] {
        if v_out > 0.0 && !c.is_straight() {
            let nb = &p[k + 1];
            let sh = c.shape(v_out);
            let mut blend_end = nb.mv.start_mm;
            for i in 0..NUM_AXES {
                blend_end[i] += nb.u[i] * x;
            }
            let seg = Segment {
                start_mm: corner_start,
                end_mm: blend_end,
                v0_mm_s: m.u.map(|c| c * v_out),
                v1_mm_s: nb.u.map(|c| c * v_out),
                duration_s: sh.duration_s,
                jerk_s: sh.jerk_s,
                kind: if m.mv.kind == MoveKind::Rapid && nb.mv.kind == MoveKind::Rapid {
                    SegmentKind::Rapid
                } else {
                    SegmentKind::Feed
                },
                line: nb.mv.line,
                length_mm: v_out * sh.duration_s,
                move_rest_mm: (nb.len_mm - x).max(0.0),
                override_cap: 1.0,
                end_override_cap: 1.0,
                scale_rate_max: 0.0,
                end_scale_rate_max: 0.0,
                scale_jerk_max: 0.0,
                brake_scale_jerk_max: 0.0,
                next_scale_jerk_max: 0.0,
            };
            push(out, lim, seg);
        }
    }
}
