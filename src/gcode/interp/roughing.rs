//! LinuxCNC's lathe profile cycles: G71/G71.1 (roughing along Z), G72/G72.1 (roughing
//! along X, facing) and G70 (finishing). The profile is the motion of the O-subroutine
//! named by Q (G0/G1/G2/G3; G0 counts as G1), executed in a recording mode (its O-word
//! statements and assignments run, its moves are recorded, its other words are ignored),
//! starting from the cycle's start point (the current position, or the X/Z of the
//! block). An A word on a line of it rounds the corner at the line's end with that
//! radius, as rs274 does (LinuxCNC's lathe_g70_71_demo.ngc); the A axis does not move.
//!
//! Roughing: D is the finishing allowance left along the profile, I the depth of each
//! pass (default 1), R the retract (default 0.5). Passes step down from the start point by
//! I; each feeds until the (offset) profile rises to its level, retracts by R on both
//! axes and traverses back. The last pass follows the profile, and G71/G72 then rough
//! every pocket of the profile level by level from its lip; G71.1/G72.1 bridge pockets.
//! G70: P passes (default 1) at allowances from D down to E (default 0 both).
//! The calls match rs274 2.9's, including its zero-length feeds under G7x.1.
//! With cutter radius compensation on, G71/G72 are refused and G70 runs its moves through
//! the compensation (`roughing_comp.rs`), as rs274 does.

use super::motion::pose6;
use super::roughing_geom::{self as geom, El, Pt};
use super::Interp;
use crate::gcode::canon::{CanonCmd, Plane};
use crate::gcode::modal::Block;
use crate::gcode::parser::{self, OKind};
use crate::gcode::GcodeError;

/// Maps X/Z onto the cycle frame (u: pass level, v: feed direction) and back, with
/// rs274's operations, so that the signs of zero coordinates come out as in its trace:
/// a point is the complex number Z + iX (v the real part, u the imaginary), G72 turns it
/// by −i (`-p * I`, a complex product), then the imaginary and real parts are negated as
/// needed; the way back is a product with ±i for G72 and negations.
#[derive(Clone, Copy)]
struct Frame {
    /// G72: u is Z and v is X.
    swap: bool,
    su: f64,
    sv: f64,
}

/// A complex number (real, imaginary).
type Cx = (f64, f64);

/// `x * y` as GCC multiplies `std::complex<double>` (no product is folded away, so the
/// signs of zero parts follow IEEE arithmetic).
fn cmul(x: Cx, y: Cx) -> Cx {
    (x.0 * y.0 - x.1 * y.1, x.0 * y.1 + x.1 * y.0)
}

impl Frame {
    /// rs274 negates the imaginary part (u) of the turned point: for G72 that is where u
    /// is Z with its sign (the turn gives −Z).
    fn flip_u(&self) -> bool {
        if self.swap {
            self.su > 0.0
        } else {
            self.su < 0.0
        }
    }
    fn to(&self, x: f64, z: f64) -> Pt {
        let mut p = (z, x);
        if self.swap {
            p = cmul((-p.0, -p.1), (0.0, 1.0));
        }
        if self.flip_u() {
            p.1 = -p.1;
        }
        if self.sv < 0.0 {
            p.0 = -p.0;
        }
        [p.1, p.0]
    }
    fn from(&self, p: Pt) -> (f64, f64) {
        let e = (p[1], p[0]);
        let (fu, fv) = (self.flip_u(), self.sv < 0.0);
        let q = if self.swap {
            // rs274's swapped_motion 4–7: i·e, conj(i·e), −conj(i·e), (−i)·e.
            match (fu, fv) {
                (false, false) => cmul((0.0, 1.0), e),
                (false, true) => {
                    let q = cmul((0.0, 1.0), e);
                    (q.0, -q.1)
                }
                (true, false) => {
                    let q = cmul((0.0, 1.0), e);
                    (-q.0, q.1)
                }
                (true, true) => cmul((-0.0, -1.0), e),
            }
        } else {
            (if fv { -e.0 } else { e.0 }, if fu { -e.1 } else { e.1 })
        };
        (q.1, q.0)
    }
    /// Counter-clockwise in (u, v) from counter-clockwise in rs274's (Z, X) arc plane.
    fn ccw(&self, ccw_zx: bool) -> bool {
        ccw_zx ^ !self.swap ^ (self.su < 0.0) ^ (self.sv < 0.0)
    }
}

/// One move of the profile: end X, end Z, for an arc its centre (X, Z) and whether it
/// turns counter-clockwise in the Z/X plane, and the radius of the round its A word asks
/// for at its end (0: a sharp corner).
type ProfileMove = (f64, f64, Option<((f64, f64), bool)>, f64);

/// What a roughing cycle does with the levels of the part and its pockets.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    /// G71/G72: passes at the levels start − k·I, then pockets roughed at those levels.
    Rough,
    /// G71.1/G72.1: the same passes; pockets bridged at their lip's level.
    Bridge,
    /// G71.2/G72.2 (LinuxCNC 2.9): no passes above the profile; the pass along it roughs
    /// each pocket at levels counted down by I from the pocket's lip (a second roughing
    /// tool, after G7x.1 bridged them).
    Profile,
}

/// The words of a G7x block.
struct Words {
    d: f64,
    i: f64,
    r: f64,
}

impl Interp<'_> {
    /// G70, G71, G71.1, G72, G72.1 (`m` in tenths).
    pub(super) fn profile_cycle(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let name = match m {
            700 => "G70",
            710 => "G71",
            711 => "G71.1",
            712 => "G71.2",
            720 => "G72",
            721 => "G72.1",
            _ => "G72.2",
        };
        // rs274 refuses compensation (on, even with a zero radius) for G71/G72 only, in its
        // words ("G71.0"); G70 runs through it (roughing_comp.rs).
        let comp = self.comp.side.is_some();
        if comp && m != 700 {
            return Err(self.err(
                col,
                format!(
                    "G{}.{} cannot be used with cutter compensation enabled",
                    m / 10,
                    m % 10
                ),
            ));
        }
        if self.s.plane != Plane::Xz {
            return Err(self.err(col, format!("{name} requires the XZ plane (G18)")));
        }
        let Some(q) = b.get(b'q') else {
            return Err(self.err(
                col,
                format!("{name} requires a Q word (profile subroutine)"),
            ));
        };
        let start = if comp {
            self.comp_cycle_start(b)
        } else {
            self.find_ends(b)
        };
        let profile = self.read_profile(q, start, name, col)?;
        let (Some(first), Some(last), true) = (profile.first(), profile.last(), profile.len() > 2)
        else {
            return Err(self.err(
                col,
                format!("{name}: profile subroutine o{q} needs at least two moves (a lead-in and the profile)"),
            ));
        };
        let swap = m >= 720;
        let lvl = |p: &ProfileMove| if swap { p.1 } else { p.0 };
        let trv = |p: &ProfileMove| if swap { p.0 } else { p.1 };
        let pstart = profile.get(1).unwrap_or(first);
        let fr = Frame {
            swap,
            su: if lvl(last) < lvl(pstart) { -1.0 } else { 1.0 },
            sv: if trv(last) > trv(pstart) { -1.0 } else { 1.0 },
        };
        let mut els = Vec::with_capacity(profile.len());
        let mut rounds = Vec::with_capacity(profile.len());
        // The first move only brings the tool to the profile: it is not part of it.
        let mut prev = fr.to(pstart.0, pstart.1);
        for p in profile.iter().skip(2) {
            let e = fr.to(p.0, p.1);
            els.push(El {
                a: prev,
                b: e,
                arc: p.2.map(|((cx, cz), ccw)| (fr.to(cx, cz), fr.ccw(ccw))),
                whole: true,
            });
            rounds.push(p.3);
            prev = e;
        }
        let els = geom::round_corners(&els, &rounds)
            .map_err(|m| self.err(col, format!("{name}: {m}")))?;
        if let Some(e) = els.iter().find(|e| !geom::monotonic(e)) {
            let (x, z) = fr.from(e.a);
            return Err(self.err(
                col,
                format!(
                    "{name}: the profile is not monotonic along {} (it turns back after X{x:.4} Z{z:.4})",
                    if swap { "X" } else { "Z" }
                ),
            ));
        }
        let w = Words {
            d: b.get(b'd').unwrap_or(0.0),
            i: b.get(b'i').unwrap_or(1.0),
            r: b.get(b'r').unwrap_or(0.5),
        };
        self.s.motion = m;
        let mut s0 = fr.to(start[0], start[2]);
        let pose = |p: Pt| {
            let (x, z) = fr.from(p);
            let mut v = start;
            v[0] = x;
            v[2] = z;
            v
        };
        let cap = MAX_CYCLE_MOVES.min(self.opts.limits.max_canon.saturating_sub(self.count));
        let mut cy = Cycle {
            out: Vec::new(),
            pose: &pose,
            cap,
            over: false,
        };
        // The move to the block's X/Z is an ordinary G0 (not mapped through the frame,
        // which could change the sign of a zero).
        cy.push(Move::Traverse(start));
        // A start beyond the profile's first point along the feed is brought level with
        // it, as rs274 does; the passes (and G70's returns) start from there.
        if let Some(e) = els.first() {
            if e.a[1] - s0[1] > 0.0 {
                s0[1] = e.a[1];
            }
        }
        if m != 700 {
            // rs274 moves the roughing profile and its start by the block's U/W (zero
            // here), which turns a -0 coordinate into +0.
            s0 = displaced(s0);
        }
        cy.traverse(s0);
        if m == 700 {
            self.finish_passes(b, &els, s0, &mut cy)?;
        } else {
            if w.i <= 0.0 {
                return Err(self.err(
                    b.col_of(b'i'),
                    format!("{name}: I (depth of cut) must be > 0"),
                ));
            }
            let contour: Vec<El> = geom::offset(&els, w.d * allowance_side(s0, &els))
                .map_err(|e| self.err(col, format!("{name}: {e}")))?
                .iter()
                .map(|e| El {
                    a: displaced(e.a),
                    b: displaced(e.b),
                    arc: e.arc.map(|(c, ccw)| (displaced(c), ccw)),
                    ..*e
                })
                .collect();
            let kind = match m % 10 {
                0 => Kind::Rough,
                1 => Kind::Bridge,
                _ => Kind::Profile,
            };
            rough(&contour, s0, &w, kind, &mut cy);
        }
        if cy.over {
            return Err(self.err(
                col,
                format!(
                    "{name}: more than {cap} moves (at most {MAX_CYCLE_MOVES} per cycle, and \
                     {} canonical commands in all); use fewer passes, a larger I, or a start \
                     nearer the profile",
                    self.opts.limits.max_canon
                ),
            ));
        }
        let out = cy.out;
        if comp {
            let end = (last.0, last.1);
            self.comp_cycle_moves(b, end, &out)?;
            self.s.motion = m;
            return Ok(());
        }
        for c in out {
            self.emit(match c {
                Move::Traverse(p) => CanonCmd::StraightTraverse(pose6(&p)),
                Move::Feed(p) => CanonCmd::StraightFeed(pose6(&p)),
                Move::Arc { end, center, ccw } => CanonCmd::ArcFeed {
                    first_end: end[2],
                    second_end: end[0],
                    first_center: center.1,
                    second_center: center.0,
                    rotation: if ccw { 1 } else { -1 },
                    axis_end: end[1],
                    plane: Plane::Xz,
                    end: pose6(&end),
                },
            })?;
            self.s.pos = match c {
                Move::Traverse(p) | Move::Feed(p) => p,
                Move::Arc { end, .. } => end,
            };
        }
        Ok(())
    }

    /// G70's passes: from allowance D (farthest first) down to E.
    fn finish_passes(
        &mut self,
        b: &Block,
        els: &[El],
        s0: Pt,
        cy: &mut Cycle,
    ) -> Result<(), GcodeError> {
        let d = b.get(b'd').unwrap_or(0.0);
        let e = b.get(b'e').unwrap_or(0.0);
        let passes = b.get(b'p').unwrap_or(1.0).round().max(1.0) as u32;
        for k in 1..=passes {
            if cy.over {
                break;
            }
            let allowance = e + f64::from(passes - k) * (d - e) / f64::from(passes);
            let contour = geom::offset(els, allowance * allowance_side(s0, els))
                .map_err(|m| self.err(self.loc.col, format!("G70: {m}")))?;
            if k > 1 {
                cy.traverse(s0);
            }
            if let Some(f) = contour.first() {
                cy.traverse(f.a);
            }
            for el in &contour {
                cy.element(el);
            }
        }
        Ok(())
    }

    /// Reads the motion of subroutine `o<q>` from `start`: per move its end X, Z and, for
    /// an arc, its centre and direction (counter-clockwise in the Z/X plane). The
    /// subroutine is called and executed, as rs274 does, in a recording mode: its O-word
    /// statements (loops, conditions, calls) and parameter assignments run, and each
    /// motion line is recorded into the profile instead of moving (`#<_x>`/`#<_z>`
    /// follow the recorded position); other words are ignored.
    fn read_profile(
        &mut self,
        q: f64,
        start: [f64; 6],
        name: &str,
        col: u32,
    ) -> Result<Vec<ProfileMove>, GcodeError> {
        let label = format!("{}", q.round() as i64);
        let f = self.pc.0;
        let sub = self.label_lines(f, &label).into_iter().find(|&l| {
            self.files[f]
                .olines
                .get(&l)
                .is_some_and(|o| o.kind == OKind::Sub)
        });
        let Some(s) = sub else {
            return Err(self.err(
                col,
                format!(
                    "{name}: profile subroutine o{label} (Q{label}) is not defined in this file"
                ),
            ));
        };
        let saved = (self.s.pos, self.s.absolute, self.loc.clone(), self.pc);
        let mut out = vec![(start[0], start[2], None, 0.0)];
        self.s.pos = start;
        let depth = self.frames.len();
        self.enter_sub(label.into(), (f, s), &[]);
        let mut r = self.record_profile(depth, name, &mut out);
        // An error inside leaves the calls it entered.
        while self.frames.len() > depth {
            if let Err(e) = self.leave_frame() {
                r = r.and(Err(e));
            }
        }
        self.s.pos = saved.0;
        self.s.absolute = saved.1;
        self.loc = saved.2;
        self.pc = saved.3;
        r?;
        Ok(out)
    }

    /// Executes the profile subroutine entered above call depth `depth` until it returns,
    /// recording its moves into `out`.
    fn record_profile(
        &mut self,
        depth: usize,
        name: &str,
        out: &mut Vec<ProfileMove>,
    ) -> Result<(), GcodeError> {
        let mut motion = 10;
        while self.frames.len() > depth {
            let (f, l) = self.locate_pc();
            if l >= self.files[f].end {
                return Err(self.err(
                    1,
                    format!("{name}: the profile subroutine ends without endsub or return"),
                ));
            }
            self.count_step()?;
            self.pc = (f, l + 1);
            let text = self.files[f].line_text(l).to_string();
            match self.files[f].kind.get(l).copied() {
                Some(2) => {}
                Some(1) => {
                    let Some(o) = self.files[f].olines.get(&l).cloned() else {
                        return Err(self.err(1, "internal: O-word line not indexed"));
                    };
                    let line = parser::parse_line(&text, self.opts.limits.max_expr_depth)
                        .map_err(|(c, m)| self.err(c, m))?;
                    self.exec_o(f, l, &o, &line)?;
                }
                _ => self.profile_line(&text, &mut motion, out)?,
            }
        }
        Ok(())
    }

    /// One plain line of a profile subroutine: its assignments run, its move (if any) is
    /// recorded. `motion` is the modal motion code (tenths) of the profile.
    fn profile_line(
        &mut self,
        text: &str,
        motion: &mut u16,
        out: &mut Vec<ProfileMove>,
    ) -> Result<(), GcodeError> {
        let line = parser::parse_line(text, self.opts.limits.max_expr_depth)
            .map_err(|(c, m)| self.err(c, m))?;
        let mut b = self.block_of(&line.words)?;
        self.diameter_words(&mut b);
        self.assign(&line)?;
        if let Some(d) = b.gcode(3) {
            self.s.absolute = d == 900;
        }
        if let Some(g) = b.gcode(1) {
            *motion = g;
        }
        if !b.has(b'x') && !b.has(b'z') {
            return Ok(());
        }
        let p0 = self.s.pos;
        // From the recorded point, also under compensation (whose programmed point is
        // the cycle's, not the profile's).
        let p = self.find_ends_from(&b, p0);
        let arc = match *motion {
            20 | 30 => {
                let (i, k) = (b.get(b'i').unwrap_or(0.0), b.get(b'k').unwrap_or(0.0));
                let c = if let Some(r) = b.get(b'r') {
                    r_center(p0, p, r, *motion == 20)
                } else {
                    (p0[0] + i, p0[2] + k)
                };
                Some((c, *motion == 30))
            }
            _ => None,
        };
        // An A word rounds the corner at the end of the move (rs274 does so in a profile;
        // the A axis does not move).
        out.push((p[0], p[2], arc, b.get(b'a').unwrap_or(0.0)));
        self.s.pos = p;
        Ok(())
    }
}

/// The side rs274 puts the allowance on: 1 for the left of the profile in (u, v) (the free
/// side of a profile fed toward lower v with the stock above it), -1 when the lead-in from
/// the start `s0` to the profile's first point turns clockwise from the line from `s0` to
/// the start of its last element (rs274: the sign of `imag(v1 / v2)`, libgcc's complex
/// division), as on a profile written for the other cycle (a turning profile under G72).
fn allowance_side(s0: Pt, els: &[El]) -> f64 {
    let (Some(first), Some(last)) = (els.first(), els.last()) else {
        return 1.0;
    };
    // rs274's complex numbers: real part v, imaginary part u.
    let v1 = (first.a[1] - s0[1], first.a[0] - s0[0]);
    let v2 = (last.a[1] - s0[1], last.a[0] - s0[0]);
    if super::roughing_steps::cdivc(v1, v2).1 < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// A point of the roughing profile after rs274's move by the cycle's U/W displacement,
/// which hytask does not read (rs274 adds `(W, U)` in its frame; zero here): adding +0
/// turns a -0 coordinate into +0, as in rs274's trace.
fn displaced(p: Pt) -> Pt {
    [p[0] + 0.0, p[1] + 0.0]
}

/// Centre (X, Z) of an R-format arc in the Z/X plane (rs274: negative R, the long way).
fn r_center(p0: [f64; 6], p: [f64; 6], r: f64, cw: bool) -> (f64, f64) {
    let (a, b) = ((p0[2], p0[0]), (p[2], p[0]));
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let chord = dx.hypot(dy);
    let h = (r * r - chord * chord / 4.0).max(0.0).sqrt();
    let (mx, my) = ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0);
    let mut sgn = if cw { -1.0 } else { 1.0 };
    if r < 0.0 {
        sgn = -sgn;
    }
    let (cz, cx) = (mx - sgn * h * dy / chord, my + sgn * h * dx / chord);
    (cx, cz)
}

/// Most moves one G70–G72 cycle may make (about 70 MB while collected): far beyond any real
/// part, and the cycle is held in memory before it is emitted.
const MAX_CYCLE_MOVES: usize = 1_000_000;

pub(super) enum Move {
    Traverse([f64; 6]),
    Feed([f64; 6]),
    Arc {
        end: [f64; 6],
        center: (f64, f64),
        ccw: bool,
    },
}

/// The moves of one cycle, in the cycle frame, collected before they are emitted. At most
/// `cap` (what is left of `max_canon`): the pass count is the request's number (a start at
/// Z2147483647 made two billion passes, collected here until memory ran out), so the cycle
/// stops collecting, its loops stop, and the caller refuses it by position.
struct Cycle<'f> {
    out: Vec<Move>,
    pose: &'f dyn Fn(Pt) -> [f64; 6],
    cap: usize,
    over: bool,
}

impl Cycle<'_> {
    fn push(&mut self, m: Move) {
        if self.out.len() < self.cap {
            self.out.push(m);
        } else {
            self.over = true;
        }
    }
    fn traverse(&mut self, p: Pt) {
        self.push(Move::Traverse((self.pose)(p)));
    }
    fn feed(&mut self, p: Pt) {
        self.push(Move::Feed((self.pose)(p)));
    }
    fn element(&mut self, e: &El) {
        match e.arc {
            None => self.feed(e.b),
            Some((c, ccw)) => {
                let end = (self.pose)(e.b);
                // rs274 makes no arc to where the tool already is (X and Z within 0.0001,
                // its `equal`).
                let here = self.out.last().map(|m| match m {
                    Move::Traverse(p) | Move::Feed(p) | Move::Arc { end: p, .. } => *p,
                });
                if here
                    .is_some_and(|h| (h[0] - end[0]).abs() < 1e-4 && (h[2] - end[2]).abs() < 1e-4)
                {
                    return;
                }
                let cp = (self.pose)(c);
                self.push(Move::Arc {
                    end,
                    center: (cp[0], cp[2]),
                    ccw: self.zx_ccw(ccw),
                });
            }
        }
    }
    fn zx_ccw(&self, ccw_uv: bool) -> bool {
        // Probe the frame: map the u and v unit vectors and see the orientation in (Z, X).
        let o = (self.pose)([0.0, 0.0]);
        let pu = (self.pose)([1.0, 0.0]);
        let pv = (self.pose)([0.0, 1.0]);
        let (uz, ux) = (pu[2] - o[2], pu[0] - o[0]);
        let (vz, vx) = (pv[2] - o[2], pv[0] - o[0]);
        let det = uz * vx - ux * vz;
        ccw_uv == (det > 0.0)
    }
}

/// The roughing passes, then the finishing pass along the contour (with pockets roughed
/// level by level, or bridged, as `kind` says).
fn rough(contour: &[El], s0: Pt, w: &Words, kind: Kind, cy: &mut Cycle) {
    let Some(first) = contour.first() else {
        return;
    };
    let mut els: Vec<El> = contour.iter().flat_map(geom::split_at_top).collect();
    if let Some(last) = els.last().copied() {
        if last.b[0] < s0[0] - 1e-7 {
            els.push(El::line(last.b, [s0[0], last.b[1]]));
        }
    }
    let ps = first.a;
    let entry_v = |u: f64| {
        if (ps[0] - s0[0]).abs() < geom::EPS {
            s0[1]
        } else {
            s0[1] + (u - s0[0]) / (ps[0] - s0[0]) * (ps[1] - s0[1])
        }
    };
    // The levels are counted down from the start by subtracting I once per level, as
    // rs274 does (not start − k·I, which can differ in the last bit: a level that should
    // be 0 is then +0 or a tiny value of either sign, printed 0.0000 or -0.0000).
    let delta = w.i.max(MIN_DELTA);
    let mut u = s0[0];
    while kind != Kind::Profile && u > ps[0] + 1e-7 && !cy.over {
        let vk = entry_v(u);
        cy.traverse([u, vk]);
        let end = geom::first_reach(&els, 0, ps, u, false).map_or(els[els.len() - 1].b, |x| x.1);
        let ve = end[1];
        cy.feed([u, ve]);
        let r = retract(w.r, vk, ve);
        cy.traverse([u + r, ve + r]);
        cy.traverse([u + r, vk - r]);
        cy.traverse([u, vk]);
        u -= delta;
    }
    let traversed = s0[0] > ps[0] + 1e-7;
    if !traversed {
        // The start is level with the profile's first point, so no pass is needed above
        // it (also for G7x.2, which makes none): rs274 then cuts the move to the profile
        // as its first element, fed, not traversed.
        els.insert(0, El::line(s0, ps));
    } else {
        cy.traverse(ps);
    }
    finish_along(&els, s0, w, kind, traversed, cy);
}

/// rs274's smallest depth of cut (twice its tolerance): a smaller I steps by this.
const MIN_DELTA: f64 = 2e-6;

/// The retract after a pass fed from `v0` to `v1`: R, but at most half the pass, so the
/// way back never runs forward (rs274 then retracts to the middle of the pass).
fn retract(r: f64, v0: f64, v1: f64) -> f64 {
    r.min((v0 - v1) / 2.0)
}

/// The last pass: along the contour, roughing (or bridging) each pocket on the way.
fn finish_along(els: &[El], s0: Pt, w: &Words, kind: Kind, start_dip: bool, cy: &mut Cycle) {
    let pockets = kind != Kind::Bridge;
    let mut i = 0;
    let mut cur = els[0].a;
    // G7x.2: the level of the pocket start rs274 keeps besides the cycle's start.
    let mut pocket_top: Option<f64> = None;
    // A profile that goes down from its first point (reached by a traverse after the
    // passes) has a pocket there: rs274 goes on with its levels into it, cutting each
    // across to where the contour is back at the level (also G7x.1, whose bridging is of
    // the pockets found later along the contour; G7x.2 makes no passes).
    // While the contour goes down from its first point rs274 draws it as it dives, without
    // G7x.1's zero-length feed to each element's start.
    let mut diving = start_dip && kind != Kind::Profile && geom::dips(&els[0], cur);
    let mut after_sinking = false;
    if diving {
        if let Some(back) = geom::first_reach(els, 0, cur, cur[0], true) {
            (i, cur) = rough_pocket(els, (0, cur), back, s0, w, Kind::Rough, cy);
        }
    }
    while i < els.len() {
        let e = els[i];
        // G7x.1 reaching an arc that turns more than half a turn counter-clockwise in
        // (u, v): see `climb_only_walk`.
        if kind == Kind::Bridge
            && e.arc.is_some_and(|(_, ccw)| ccw)
            && e.sweep(e.a, e.b) > std::f64::consts::PI
            && geom::same(cur, e.a)
        {
            climb_only_walk(&els[i..], cur, cy);
            return;
        }
        // rs274's climb_only: a line climbs unless its end is below its start, compared
        // without tolerance (one ending 7e-15 lower is not climbing); a climbing one is fed
        // to from where the tool is (a zero-length feed at its start), one that is not
        // climbing only drawn.
        let sinking_line = e.arc.is_none() && e.b[0] < e.a[0];
        diving = diving && geom::dips(&e, cur);
        // After a line that is not climbing (rs274 does not draw it), rs274's feed to where
        // the next element is at the tool's level is that line: no zero-length feed then.
        let fed_to_start = !pockets
            && e.whole
            && !sinking_line
            && !diving
            && !after_sinking
            && geom::same(cur, e.a);
        after_sinking = sinking_line;
        if fed_to_start {
            cy.feed(e.a);
        }
        cy.element(&e.piece(cur, e.b));
        cur = e.b;
        // A pocket starts where the contour turns down, not where a descent goes on into
        // another element (a line into a groove arc): rs274 dives on through it.
        let going_down = e.tangent(e.b)[0] < -geom::EPS;
        let lip = !going_down && els.get(i + 1).is_some_and(|n| geom::dips(n, e.b));
        // G7x.2: rs274 looks for a pocket at the end of every arc that climbs clockwise in
        // (u, v) (counter-clockwise in its frame) and at every lip, from the level of the
        // last pocket start it keeps (a lower one than that is kept, a higher one replaces
        // it).
        let arc_end = match e.arc {
            Some((c, false)) => e.a[1] >= c[1] && e.b[1] >= c[1],
            _ => false,
        };
        if kind == Kind::Profile && (lip || arc_end) {
            if pocket_top.is_some_and(|t| cur[0] > t) {
                pocket_top = None;
            }
            let top = *pocket_top.get_or_insert(cur[0]);
            if !lip {
                arc_end_pass(&e, cur, top, w, cy);
            }
        }
        if !lip {
            i += 1;
            continue;
        }
        let ul = e.b[0];
        let Some((j, back)) = geom::first_reach(els, i + 1, e.b, ul, true) else {
            i += 1;
            continue;
        };
        if !pockets {
            // G7x.1: straight across the pocket at the lip's level. A line fed to from its
            // start also feeds to the start of the (corner) arc that dips after it, as
            // rs274 does when the arc turns clockwise in (u, v) (counter-clockwise in its
            // frame: it feeds to the arc's nearer crossing of the level, its start; for the
            // other turn to the farther one, across the pocket).
            let cw_arc = els[i + 1].arc.is_some_and(|(_, ccw)| !ccw);
            if fed_to_start && e.arc.is_none() && els[i + 1].whole && cw_arc {
                cy.feed(e.b);
            }
            cy.feed(back);
            (i, cur) = next_from(els, j, back);
            continue;
        }
        (i, cur) = rough_pocket(els, (i + 1, e.b), (j, back), s0, w, kind, cy);
    }
}

/// G7x.1 from an arc that turns more than half a turn counter-clockwise in (u, v)
/// (clockwise in rs274's frame), which only an unsuitable profile gives (the allowance
/// offset joined the arc to the next element at the far crossing of their circles: a
/// turning profile under G72.1, random lathe seeds 24 and 55). rs274's test whether a
/// point is on an arc (two half-plane tests against the radii through its ends) is wrong
/// for such an arc, so its walk along the contour (`climb_only`) skips it and goes on at
/// the tool's level. From there on this is that walk, element by element, from `loc`:
/// a line that climbs is fed to where it crosses the tool's level, then to its end; an
/// arc is fed to the crossing rs274 picks (none, or one on the wrong side of its centre:
/// skipped) and cut to its end, or to its top when it passes over it. The contour's arcs
/// split at their top are taken whole again, as rs274 has them.
fn climb_only_walk(els: &[El], mut loc: Pt, cy: &mut Cycle) {
    const TOL: f64 = 1e-6;
    let mut whole: Vec<El> = Vec::with_capacity(els.len());
    for e in els {
        if let (Some(prev), Some((c, ccw))) = (whole.last_mut(), e.arc) {
            let top = prev
                .arc
                .map(|(pc, _)| [pc[0] + geom::norm(geom::sub(prev.a, pc)), pc[1]]);
            if prev.arc == Some((c, ccw)) && prev.b == e.a && top == Some(e.a) {
                prev.b = e.b;
                continue;
            }
        }
        whole.push(*e);
    }
    // Cross product in rs274's (real v, imaginary u): imag(conj(p) * q).
    let cross = |p: Pt, q: Pt| p[1] * q[0] - p[0] * q[1];
    for e in &whole {
        let level = loc[0];
        let Some((c, ccw_uv)) = e.arc else {
            if e.b[0] < e.a[0] {
                continue;
            }
            let (lo, hi) = (e.a[0].min(e.b[0]), e.a[0].max(e.b[0]));
            if lo > level + TOL || hi < level - TOL {
                continue;
            }
            loc[1] = if (e.a[0] - e.b[0]).abs() < TOL {
                e.a[1]
            } else {
                (level - e.a[0]) / (e.b[0] - e.a[0]) * (e.b[1] - e.a[1]) + e.a[1]
            };
            cy.feed(loc);
            cy.feed(e.b);
            loc = e.b;
            continue;
        };
        // rs274's sense of turning: counter-clockwise in its frame is clockwise in (u, v).
        let ccw = !ccw_uv;
        let r = geom::norm(geom::sub(e.a, c));
        let s = -((level - r - c[0]) * (level + r - c[0]));
        if s < -TOL {
            continue;
        }
        let s = s.max(0.0).sqrt();
        let (sa, sb) = (geom::sub(e.a, c), geom::sub(e.b, c));
        let on = |v: f64| {
            let q = [level - c[0], v - c[1]];
            if ccw {
                cross(sa, q) >= -TOL && cross(sb, q) <= TOL
            } else {
                cross(sa, q) <= TOL && cross(sb, q) >= -TOL
            }
        };
        let is: Vec<f64> = [c[1] + s, c[1] - s]
            .into_iter()
            .filter(|&v| on(v))
            .collect();
        let (Some(&front), Some(&back)) = (is.first(), is.last()) else {
            continue;
        };
        let end = if ccw {
            if front < c[1] {
                continue;
            }
            loc[1] = front;
            if e.b[1] < c[1] {
                [c[0] + r, c[1]]
            } else {
                e.b
            }
        } else {
            if back > c[1] {
                continue;
            }
            loc[1] = back;
            e.b
        };
        cy.feed(loc);
        if geom::norm(geom::sub(loc, end)) > 1e-3 {
            cy.element(&e.piece(loc, end));
        }
        loc = end;
    }
}

/// rs274's pocket check at the end `p` of a climbing arc `e` (G7x.2), with the pocket start
/// level `top`: when `p` is on a level counted down from `top` (within 1e-6), rs274 cuts
/// the arc at `p`'s level, with the radius of the arc's start (as `intersection_z`), and
/// where that crossing lies more than 1e-6 ahead of `p` along the feed (the end of an offset
/// arc is a little off the circle through its start) it makes a pass of that length: feed,
/// retract, return, feed back (random lathe program 267: a pass 3.7e-6 long).
fn arc_end_pass(e: &El, p: Pt, top: f64, w: &Words, cy: &mut Cycle) {
    const TOL: f64 = 1e-6;
    let Some((c, _)) = e.arc else {
        return;
    };
    let delta = w.i.max(MIN_DELTA);
    let mut x = top;
    let mut n = 0;
    while x - TOL > p[0] {
        x -= delta;
        n += 1;
        if n > MAX_CYCLE_MOVES {
            return;
        }
    }
    if (p[0] - x).abs() > TOL {
        return;
    }
    // In rs274's frame: real part v, imaginary part u.
    let level = p[0];
    let r = geom::norm(geom::sub(e.a, c));
    let s = -((level - r - c[0]) * (level + r - c[0]));
    if s < -TOL {
        return;
    }
    let s = if s < 0.0 { 0.0 } else { s }.sqrt();
    // Imaginary part of conj(q - c) * (pt - c), as GCC multiplies.
    let side = |q: Pt, v: f64| (q[1] - c[1]) * (level - c[0]) + (-(q[0] - c[0])) * (v - c[1]);
    let on = |v: f64| side(e.a, v) >= -TOL && side(e.b, v) <= TOL;
    let dest = [c[1] - s, c[1] + s].into_iter().find(|&v| on(v));
    let Some(dest) = dest else {
        return;
    };
    let distance = (dest - p[1]).abs();
    if dest - TOL > p[1] || distance < TOL {
        return;
    }
    cy.feed([level, dest]);
    let k = (distance / 2.0 / w.r).min(1.0) * w.r;
    cy.traverse([level + k, dest + k]);
    cy.traverse([level + k, p[1] - k]);
    cy.feed(p);
}

/// Roughs the pocket from its lip (`lip`: the element after it and the lip point) to where
/// the contour is back at the lip's level (`back`), level by level, and returns the
/// element and point to go on from.
fn rough_pocket(
    els: &[El],
    lip: (usize, Pt),
    back: (usize, Pt),
    s0: Pt,
    w: &Words,
    kind: Kind,
    cy: &mut Cycle,
) -> (usize, Pt) {
    let delta = w.i.max(MIN_DELTA);
    let ul = lip.1[0];
    let bottom = geom::min_between(els, lip.0, lip.1, back.0, back.1);
    // G7x: the cycle's levels below the lip; G7x.2: the lip's level, then down by I.
    // (rs274: the first level not above the lip by more than 1e-6.)
    let mut u = match kind {
        Kind::Profile => ul,
        _ => {
            let (mut u, mut n) = (s0[0], 0);
            while u - 1e-6 > ul {
                u -= delta;
                n += 1;
                if n > MAX_CYCLE_MOVES {
                    cy.over = true;
                    break;
                }
            }
            u
        }
    };
    let (mut ci, mut cp) = lip;
    loop {
        if u <= bottom + 1e-7 || cy.over {
            break;
        }
        let Some((ai, a)) = geom::first_drop(els, ci, cp, u) else {
            break;
        };
        feed_along(els, ci, cp, ai, a, kind == Kind::Rough, cy);
        let Some((_, bpt)) = geom::first_reach(els, ai, a, u, true) else {
            break;
        };
        cy.feed(bpt);
        let r = retract(w.r, a[1], bpt[1]);
        cy.traverse([u + r, bpt[1] + r]);
        cy.traverse([u + r, a[1] - r]);
        cy.feed(a);
        ci = ai;
        cp = a;
        u -= delta;
    }
    // Continue along the contour from where the pocket passes left it.
    next_from(els, ci, cp)
}

/// The element and point to go on from after reaching `p` on element `j`.
fn next_from(els: &[El], j: usize, p: Pt) -> (usize, Pt) {
    if geom::same(p, els[j].b) {
        (j + 1, els.get(j + 1).map_or(p, |e| e.a))
    } else {
        (j, p)
    }
}

/// Feeds along the contour from (`i`, `p`) to (`j`, `q`); `zero` makes the zero-length
/// feed rs274's G7x makes when `p` is `q`.
fn feed_along(els: &[El], i: usize, p: Pt, j: usize, q: Pt, zero: bool, cy: &mut Cycle) {
    if i == j {
        if geom::same(p, q) {
            // rs274's G7x feeds to the pocket level even when the lip is on it (G7x.2 not),
            // down a line; an arc it would cut there is a zero-length one, which it skips.
            if zero && els[i].arc.is_none() {
                cy.feed(q);
            }
        } else {
            cy.element(&els[i].piece(p, q));
        }
        return;
    }
    cy.element(&els[i].piece(p, els[i].b));
    for e in &els[i + 1..j] {
        cy.element(e);
    }
    cy.element(&els[j].piece(els[j].a, q));
}
