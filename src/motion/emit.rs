//! Emission of the time-parameterised segments of planned moves (see [`super::lookahead`]):
//! per move an S-curve speed-up, a cruise and a slow-down, per span (issue 14, [`super::span`])
//! the same over a run of tangent moves cut into windowed pieces, and a blend segment at each
//! junction that does not stop.

use super::arcfit;
use super::blend::Corner;
use super::limits::Limits;
use super::line_marks::LineMarks;
use super::lookahead::Prepared;
use super::moves::{Move, MoveKind};
use super::profile::Tangential;
use super::segment::{Item, Segment, SegmentKind, Window};
use super::span::{cruise_speed, Profile};
use crate::gcode::NUM_AXES;

pub(super) fn kind_of(m: &Move) -> SegmentKind {
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

/// A run of tangent moves planned as one (see [`span`]).
pub(super) struct Span {
    /// First and last move of the span.
    pub(super) first: usize,
    pub(super) last: usize,
    /// Length of the span, mm.
    pub(super) len_mm: f64,
    /// Its tangential limits (the tightest of its moves').
    pub(super) tang: Tangential,
    /// Its speed cap, mm/s (the lowest of its moves').
    pub(super) vcap_mm_s: f64,
}

/// Where a move's piece starting (ending) at distance `d` along it is, and its direction.
fn move_point(m: &Prepared, d: f64) -> ([f64; NUM_AXES], [f64; NUM_AXES]) {
    let mut q = m.mv.start_mm;
    let mut u = m.u;
    if m.curv != 0.0 {
        let o = arcfit::offset(m.heading, m.curv, d);
        q[0] += o[0];
        q[1] += o[1];
        let h = m.heading + m.curv * d;
        u[0] = h.cos();
        u[1] = h.sin();
    } else {
        for i in 0..NUM_AXES {
            q[i] += m.u[i] * d;
        }
    }
    (q, u)
}

/// One piece of a move's profile: speeds, timing and where along the move it runs.
struct Piece {
    /// Where it starts (the previous piece's end).
    start: [f64; NUM_AXES],
    /// Speeds at its ends, mm/s.
    s: [f64; 2],
    duration_s: f64,
    jerk_s: f64,
    /// Distance along the move at its start and end, and its length, mm.
    from: f64,
    done: f64,
    len: f64,
    /// Curvature steps at the move's start and end, 1/mm.
    dk: [f64; 2],
    window: Window,
}

/// The segment of piece `pc` of move `m`: end pose and directions on the move, the jerk of
/// a curvature step at the move's ends, and the source-line marks it passes.
fn piece_segment(m: &Prepared, pc: &Piece, kind: SegmentKind, lim: &Limits) -> Segment {
    let step_jerk = |v: f64, dk: f64| v * v * dk / lim.servo_period_s;
    let (from, done) = (pc.from, pc.done);
    let (end, u1) = move_point(m, done);
    let u0 = move_point(m, from).1;
    let mut step = 0.0f64;
    if from <= 1e-12 {
        step = step_jerk(pc.s[0], pc.dk[0]);
    }
    if done >= m.len_mm - 1e-9 {
        step = step.max(step_jerk(pc.s[1], pc.dk[1]));
    }
    // Vertices passed before this piece advance its first line; those within it are its
    // marks (at most MAX_MARKS per move, so `new` cannot refuse them).
    let before = m.marks.iter().take_while(|&&q| q <= from).count();
    let within: Vec<f64> = m.marks[before..]
        .iter()
        .take_while(|&&q| q <= done)
        .map(|q| {
            if pc.len > 0.0 {
                (q - from) / pc.len
            } else {
                0.0
            }
        })
        .collect();
    Segment {
        start_mm: pc.start,
        end_mm: end,
        v0_mm_s: u0.map(|c| c * pc.s[0]),
        v1_mm_s: u1.map(|c| c * pc.s[1]),
        duration_s: pc.duration_s,
        jerk_s: pc.jerk_s,
        kind,
        line: m.mv.line + before as u32,
        length_mm: pc.len,
        move_rest_mm: (m.len_mm - done).max(0.0),
        override_cap: 1.0,
        end_override_cap: 1.0,
        scale_rate_max: 0.0,
        end_scale_rate_max: 0.0,
        scale_jerk_max: 0.0,
        brake_scale_jerk_max: 0.0,
        next_scale_jerk_max: 0.0,
        curvature_per_mm: m.curv,
        heading_rad: m.heading + m.curv * from,
        step_jerk_mm_s3: step,
        line_marks: LineMarks::new(&within).unwrap_or_default(),
        window: pc.window,
    }
}

/// Where the blend after move `m` starts: `x` mm before its end, along its exit direction
/// (exact geometry, so rounding never accumulates from piece to piece).
fn blend_start(m: &Prepared, x: f64) -> [f64; NUM_AXES] {
    let mut p = m.mv.end_mm;
    for i in 0..NUM_AXES {
        p[i] -= m.u[i] * x;
    }
    p
}

/// Ends move `m`'s pieces (those pushed after `first_piece`) exactly at `end`, then queues
/// the move's auxiliary items.
fn close_move(out: &mut Vec<Item>, first_piece: usize, end: [f64; NUM_AXES], m: &Prepared) {
    if out.len() > first_piece {
        if let Some(Item::Segment(last)) = out.last_mut() {
            last.end_mm = end;
        }
    }
    out.extend(m.aux_after.iter().map(|a| Item::Aux(*a)));
}

/// Emits the span `sp` (moves `sp.first..=sp.last`, joined tangentially): one S-curve up,
/// a cruise and one S-curve down over the whole span, cut at the moves' ends into windowed
/// segments, each move's auxiliary items after its last piece, and the blend after the span.
#[allow(clippy::too_many_arguments)]
pub(super) fn emit_span(
    p: &[Prepared],
    corners: &[Option<Corner>],
    dk: &[f64],
    before: Option<Corner>,
    sp: &Span,
    [v_in, v_out]: [f64; 2],
    lim: &Limits,
    out: &mut Vec<Item>,
) {
    let e = before.map_or(0.0, |c| c.half_length_mm(v_in));
    let x = corners[sp.last].map_or(0.0, |c| c.half_length_mm(v_out));
    let profile = Profile::new(&sp.tang, [v_in, v_out], sp.vcap_mm_s, [e, sp.len_mm, x]);
    let vp = profile.cruise_mm_s;
    // The profile's parts, in distance along the span from the first move's start; the
    // slow-down ends exactly where the exit blend starts.
    let mut parts = profile.parts();
    parts[2].1 = sp.len_mm - x;
    let kind = kind_of(&p[sp.first].mv);
    let mut c0 = 0.0;
    for k in sp.first..=sp.last {
        let m = &p[k];
        let c1 = if k == sp.last {
            sp.len_mm
        } else {
            c0 + m.len_mm
        };
        let lo = if k == sp.first { e } else { c0 };
        let hi = if k == sp.last { sp.len_mm - x } else { c1 };
        let (dk_in, dk_out) = (if k > 0 { dk[k - 1] } else { 0.0 }, dk[k]);
        let first_piece = out.len();
        for &(p0, p1, tr) in &parts {
            let (a, b) = (lo.max(p0), hi.min(p1));
            if b <= a {
                continue;
            }
            // Speeds, times and window of this piece.
            let (s0, s1, dur, jerk, window) = match tr {
                None => (
                    vp,
                    vp,
                    if vp > 0.0 { (b - a) / vp } else { 0.0 },
                    0.0,
                    Window::NONE,
                ),
                Some(tr) if a <= p0 && b >= p1 => (
                    tr.s_start,
                    tr.s_end,
                    tr.shape.duration_s,
                    tr.shape.jerk_s,
                    Window::NONE,
                ),
                Some(tr) => {
                    let ta = if a <= p0 { 0.0 } else { tr.time_at(a - p0) };
                    let tb = if b >= p1 {
                        tr.shape.duration_s
                    } else {
                        tr.time_at(b - p0)
                    };
                    (
                        tr.speed(ta),
                        tr.speed(tb),
                        tb - ta,
                        tr.shape.jerk_s,
                        Window {
                            offset_s: ta,
                            full_s: tr.shape.duration_s,
                            dv_mm_s: tr.s_end - tr.s_start,
                        },
                    )
                }
            };
            let (from, done) = (a - c0, b - c0);
            let pc = Piece {
                start: move_point(m, from).0,
                s: [s0, s1],
                duration_s: dur,
                jerk_s: jerk,
                from,
                done,
                len: b - a,
                dk: [dk_in, dk_out],
                window: if dur > 0.0 { window } else { Window::NONE },
            };
            push(out, lim, piece_segment(m, &pc, kind, lim));
        }
        // Each move's last piece ends exactly at its end (the blend's start for the last).
        let end = if k == sp.last {
            blend_start(m, x)
        } else {
            m.mv.end_mm
        };
        close_move(out, first_piece, end, m);
        c0 = c1;
    }
    if let Some(c) = corners[sp.last] {
        if v_out > 0.0 && !c.is_straight() {
            let corner_start = blend_start(&p[sp.last], x);
            emit_blend(p, sp.last, c, corner_start, v_out, x, lim, out);
        }
    }
}

/// Emits move `k` (S-curve up, cruise, S-curve down) and the blend at its end.
#[allow(clippy::too_many_arguments)]
pub(super) fn emit_move(
    p: &[Prepared],
    corners: &[Option<Corner>],
    before: Option<Corner>,
    k: usize,
    [v_in, v_out]: [f64; 2],
    [dk_in, dk_out]: [f64; 2],
    lim: &Limits,
    out: &mut Vec<Item>,
) {
    let m = &p[k];
    let e = before.map_or(0.0, |c| c.half_length_mm(v_in));
    let x = corners[k].map_or(0.0, |c| c.half_length_mm(v_out));
    let mid = (m.len_mm - e - x).max(0.0);
    let kind = kind_of(&m.mv);
    let t = &m.tang;
    let vp = cruise_speed(t, [v_in, v_out], m.vcap_mm_s, mid);
    let d_up = t.distance_mm(v_in, vp);
    let d_down = t.distance_mm(vp, v_out);
    let cruise = (mid - d_up - d_down).max(0.0);
    let mut pos = m.mv.start_mm;
    for i in 0..NUM_AXES {
        pos[i] += m.u[i] * e;
    }
    let mut done = e;
    let first_piece = out.len();
    let mut piece = |s0: f64,
                     s1: f64,
                     dur: f64,
                     jerk: f64,
                     len: f64,
                     pos: &mut [f64; NUM_AXES],
                     done: &mut f64| {
        let from = *done;
        *done += len;
        let pc = Piece {
            start: *pos,
            s: [s0, s1],
            duration_s: dur,
            jerk_s: jerk,
            from,
            done: *done,
            len,
            dk: [dk_in, dk_out],
            window: Window::NONE,
        };
        let seg = piece_segment(m, &pc, kind, lim);
        *pos = seg.end_mm;
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
    // The blend starts from exact geometry, so rounding never accumulates; the last piece
    // ends exactly there (or where the next move starts).
    let corner_start = blend_start(m, x);
    close_move(out, first_piece, corner_start, m);
    if let Some(c) = corners[k] {
        if v_out > 0.0 && !c.is_straight() {
            emit_blend(p, k, c, corner_start, v_out, x, lim, out);
        }
    }
}

/// Emits the corner blend after move `k`, from `corner_start` at speed `v_out` to `x` along
/// the next move.
#[allow(clippy::too_many_arguments)]
fn emit_blend(
    p: &[Prepared],
    k: usize,
    c: Corner,
    corner_start: [f64; NUM_AXES],
    v_out: f64,
    x: f64,
    lim: &Limits,
    out: &mut Vec<Item>,
) {
    let m = &p[k];
    let nb = &p[k + 1];
    let sh = c.shape(v_out);
    // The blend passes the vertex halfway (it is symmetric at one speed): the incoming line
    // is reported up to there, the next line after it, when they follow each other.
    let last_in = m.mv.line + m.marks.len() as u32;
    let (line, line_marks) = match LineMarks::new(&[0.5]) {
        Some(half) if nb.mv.line == last_in + 1 => (last_in, half),
        _ => (nb.mv.line, LineMarks::NONE),
    };
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
        line,
        length_mm: v_out * sh.duration_s,
        move_rest_mm: (nb.len_mm - x).max(0.0),
        override_cap: 1.0,
        end_override_cap: 1.0,
        scale_rate_max: 0.0,
        end_scale_rate_max: 0.0,
        scale_jerk_max: 0.0,
        brake_scale_jerk_max: 0.0,
        next_scale_jerk_max: 0.0,
        curvature_per_mm: 0.0,
        heading_rad: 0.0,
        step_jerk_mm_s3: 0.0,
        line_marks,
        window: Window::NONE,
    };
    push(out, lim, seg);
}
