//! Cutter radius compensation (G40, G41, G42, G41.1, G42.1), as LinuxCNC 2.9's interpreter
//! does it, so traces match `rs274` call for call.
//!
//! The compensated path is computed in the plane of compensation (XY, or ZX for a lathe in
//! G18) with the programmed point (`prog`) and the tool point (`Settings::pos`) kept apart.
//! A compensated move cannot be sent before the next one is known: a concave corner moves
//! its end back to the intersection with the next offset path. So, like LinuxCNC, each move
//! is held in a queue until the next move decides its end; the queue also holds the
//! non-motion calls (comments, feed, spindle, coolant, dwell) issued in between so they
//! stay in program order, while every other call goes out at once (as in rs274's trace).
//! Convex corners get an arc around the programmed corner (a traverse for G0).

mod arc;
mod straight;

use super::arcs::{self, add_half_pi, find_turn, plane_axes};
use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::{CanonCmd, Plane, SourceLoc};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;

/// Angle below which a corner is straight (LinuxCNC `TOLERANCE_CONCAVE_CORNER`, radians).
pub(super) const SMALL: f64 = 0.05;
/// LinuxCNC `TOLERANCE_EQUAL`.
pub(super) const TOLERANCE_EQUAL: f64 = 0.0001;

/// Side of the programmed path the tool is kept on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Side {
    /// G41: left of the direction of travel.
    Left,
    /// G42: right.
    Right,
}

/// A compensated move (plane coordinates: first, second, normal) or a deferred call.
#[derive(Debug, Clone)]
pub(super) enum Item {
    /// STRAIGHT_FEED (feed) or STRAIGHT_TRAVERSE, with the direction of the programmed
    /// motion (a concave corner that reverses it would gouge).
    Line {
        feed: bool,
        dir: (f64, f64),
        end: [f64; 6],
    },
    /// ARC_FEED with the sweep it had when queued (0: never moved).
    Arc {
        sweep: f64,
        end: (f64, f64),
        center: (f64, f64),
        turn: i32,
        rest: [f64; 4],
    },
    /// Any other deferred call.
    Other(CanonCmd),
}

/// Compensation state and the queue of held calls.
#[derive(Debug)]
pub(crate) struct Comp {
    pub side: Option<Side>,
    /// Tool radius, program units (always >= 0; a negative one swaps the side).
    pub radius: f64,
    /// Lathe tool orientation (0 and 9: the controlled point is the tool centre).
    pub orientation: i32,
    /// The next move is the entry move.
    pub first: bool,
    /// Programmed (uncompensated) point X Y Z.
    pub prog: [f64; 3],
    /// The move after G40 turned compensation off must be straight.
    pub arc_not_allowed: bool,
    queue: Vec<(SourceLoc, Item)>,
    endpoint: (f64, f64),
    endpoint_valid: bool,
}

impl Default for Comp {
    fn default() -> Self {
        Comp {
            side: None,
            radius: 0.0,
            orientation: 0,
            first: true,
            prog: [0.0; 3],
            arc_not_allowed: false,
            queue: Vec::new(),
            endpoint: (0.0, 0.0),
            endpoint_valid: false,
        }
    }
}

impl Comp {
    /// Compensation changes the path (on, with a non-zero radius).
    pub(crate) fn active(&self) -> bool {
        self.side.is_some() && self.radius > 0.0
    }

    /// Moves are measured from the programmed point (on, after the entry move).
    pub(crate) fn measures_from_program(&self) -> bool {
        self.side.is_some() && !self.first
    }

    /// Calls wait behind a held move.
    pub(crate) fn holding(&self) -> bool {
        !self.queue.is_empty()
    }

    /// Holds a non-motion call behind the held move.
    pub(crate) fn hold(&mut self, loc: SourceLoc, cmd: CanonCmd) {
        self.queue.push((loc, Item::Other(cmd)));
    }

    /// G20/G21 with moves held: everything held scales with the units.
    pub(crate) fn scale(&mut self, k: f64) {
        self.radius *= k;
        for v in &mut self.prog {
            *v *= k;
        }
        if self.queue.is_empty() {
            return;
        }
        for (_, it) in &mut self.queue {
            self.endpoint.0 *= k;
            self.endpoint.1 *= k;
            match it {
                Item::Line { end, .. } => {
                    for v in &mut end[..3] {
                        *v *= k;
                    }
                }
                Item::Arc {
                    end, center, rest, ..
                } => {
                    end.0 *= k;
                    end.1 *= k;
                    center.0 *= k;
                    center.1 *= k;
                    rest[0] *= k;
                }
                Item::Other(_) => {}
            }
        }
    }
}

/// True for the calls LinuxCNC queues behind a held move (its `enqueue_*` calls).
pub(crate) fn deferred(cmd: &CanonCmd) -> bool {
    matches!(
        cmd,
        CanonCmd::SetFeedRate(_)
            | CanonCmd::Dwell(_)
            | CanonCmd::SetFeedMode(_)
            | CanonCmd::MistOn
            | CanonCmd::MistOff
            | CanonCmd::FloodOn
            | CanonCmd::FloodOff
            | CanonCmd::StartSpindle(_)
            | CanonCmd::StopSpindle
            | CanonCmd::SetSpindleMode { .. }
            | CanonCmd::SetSpindleSpeed(_)
            | CanonCmd::Comment(_)
    )
}

/// The arc words of a G2/G3 block, to find its centre from any start point.
pub(crate) struct ArcSpec {
    pub cw: bool,
    pub r: Option<f64>,
    pub off: (f64, f64),
    pub turns: i32,
    pub names: (char, char),
    pub ijk_absolute: bool,
    pub radius_tol: f64,
    pub spiral_abs: f64,
    /// F word (inverse time).
    pub f: Option<f64>,
}

impl ArcSpec {
    pub(super) fn center(
        &self,
        start: (f64, f64),
        end: (f64, f64),
    ) -> Result<(f64, f64, i32), String> {
        match self.r {
            Some(r) => arcs::arc_data_r(
                self.cw,
                start.0,
                start.1,
                end.0,
                end.1,
                r,
                self.turns,
                self.radius_tol,
            ),
            None => arcs::arc_data_ijk(
                self.cw,
                self.names,
                start,
                end,
                self.ijk_absolute,
                self.off,
                self.turns,
                self.radius_tol,
                self.spiral_abs,
            ),
        }
    }
}

/// The arc round a convex corner: from the end of the last offset move to `mid`, centred
/// on the programmed corner, turning against the side (its end is never moved, so its
/// sweep is not needed); the normal axis stays where it is (`cz`), the rotary axes end.
pub(super) fn corner_arc(
    side: Side,
    mid: (f64, f64),
    corner: (f64, f64),
    cz: f64,
    end: &[f64; 6],
) -> Item {
    Item::Arc {
        sweep: 0.0,
        end: mid,
        center: corner,
        turn: if side == Side::Left { -1 } else { 1 },
        rest: [cz, end[3], end[4], end[5]],
    }
}

/// A held arc: end, centre, turn.
pub(super) type HeldArc = ((f64, f64), (f64, f64), i32);

/// The tool is on the inside of an arc turning `turn` (LinuxCNC `TOOL_INSIDE_ARC`).
pub(super) fn inside(side: Side, turn: i32) -> bool {
    (side == Side::Left && turn > 0) || (side == Side::Right && turn < 0)
}

pub(super) const TOOL_TOO_BIG: &str =
    "Tool radius not less than arc radius with cutter radius compensation";

impl Interp<'_> {
    /// A setting that cannot change while compensation is on.
    pub(super) fn refuse_with_comp(&self, col: u32, what: &str) -> Result<(), GcodeError> {
        if self.comp.side.is_some() {
            return Err(self.err(col, format!("{what} with cutter radius compensation on")));
        }
        Ok(())
    }

    pub(super) fn comp_plane(&self) -> Result<(usize, usize, usize), GcodeError> {
        match self.s.plane {
            Plane::Xy | Plane::Xz => Ok(plane_axes(self.s.plane)),
            _ => Err(self.err(
                self.loc.col,
                "Cutter radius compensation works only in the XY (G17) or XZ (G18) plane",
            )),
        }
    }

    /// Group 7: G40, G41, G42, G41.1, G42.1.
    pub(super) fn cutter_comp(&mut self, g: u16, b: &Block) -> Result<(), GcodeError> {
        if g == 400 {
            return self.comp_off();
        }
        let col = self.loc.col;
        if !matches!(self.s.plane, Plane::Xy | Plane::Xz) {
            return Err(self.err(col, "Cutter radius compensation can be turned on only in the XY (G17) or XZ (G18) plane"));
        }
        if self.comp.side.is_some() {
            return Err(self.err(col, "Cannot turn cutter radius comp on when already on"));
        }
        let mut side = if g == 410 || g == 411 {
            Side::Left
        } else {
            Side::Right
        };
        let name = g / 10;
        let (mut radius, orientation) = if g == 411 || g == 421 {
            let d = b
                .get(b'd')
                .ok_or_else(|| self.err(col, format!("G{name}.1 with no D word")))?;
            let orientation = match b.get(b'l') {
                Some(l) => {
                    if self.s.plane != Plane::Xz {
                        return Err(self.err(
                            b.col_of(b'l'),
                            format!("G{name}.1 with L word, but plane is not G18"),
                        ));
                    }
                    l as i32
                }
                None => 0,
            };
            (d / 2.0, orientation)
        } else {
            let entry = match b.get(b'd') {
                None => self.s.spindle_tool.clone(),
                Some(d) => {
                    let tool = (d + 0.5) as i64;
                    if (tool as f64 - d).abs() >= 0.0001 || tool < 0 {
                        return Err(self.err(
                            b.col_of(b'd'),
                            format!("G{name} requires D word to be a whole number (a tool number)"),
                        ));
                    }
                    if tool == 0 {
                        self.s.spindle_tool.clone()
                    } else {
                        let slot = u32::try_from(tool)
                            .ok()
                            .and_then(|t| self.tools.slot_of(t))
                            .ok_or_else(|| {
                                self.err(
                                    b.col_of(b'd'),
                                    format!("Requested tool {tool} not found in the tool table"),
                                )
                            })?;
                        self.tools.at_slot(slot).cloned()
                    }
                }
            };
            let (dia, orientation) = entry.map_or((0.0, 0), |t| (t.diameter, t.orientation));
            if self.s.plane != Plane::Xz && orientation != 0 && orientation != 9 {
                return Err(self.err(
                    col,
                    format!("G{name} with lathe tool, but plane is not G18"),
                ));
            }
            (self.s.user_to_prog(dia) / 2.0, orientation)
        };
        if radius < 0.0 {
            radius = -radius;
            side = if side == Side::Left {
                Side::Right
            } else {
                Side::Left
            };
        }
        self.emit(CanonCmd::Comment(
            if side == Side::Right {
                "interpreter: cutter radius compensation on right"
            } else {
                "interpreter: cutter radius compensation on left"
            }
            .into(),
        ))?;
        self.comp.radius = radius;
        self.comp.orientation = orientation;
        self.comp.side = Some(side);
        Ok(())
    }

    fn comp_off(&mut self) -> Result<(), GcodeError> {
        self.emit(CanonCmd::Comment(
            "interpreter: cutter radius compensation off".into(),
        ))?;
        if self.comp.active() && !self.comp.first {
            let (a1, a2, _) = self.comp_plane()?;
            let (cx, cy) = (self.s.pos[a1], self.s.pos[a2]);
            self.move_endpoint_and_flush(cx, cy)?;
            // rs274 dequeues once more here, which leaves no valid endpoint: the next
            // entry move's held arc is not checked against where this pass ended
            self.dequeue()?;
            let mut tool = [0.0; 3];
            tool.copy_from_slice(&self.s.pos[..3]);
            self.s.pos[..3].copy_from_slice(&self.comp.prog);
            self.s.comp_tool_left = Some(tool);
            self.comp.arc_not_allowed = true;
        }
        self.comp.side = None;
        self.comp.first = true;
        Ok(())
    }

    /// M0/M1/M2/M30/M60: held calls go out; a program end also turns compensation off.
    pub(super) fn comp_at_stop(&mut self, end: bool) -> Result<(), GcodeError> {
        if self.comp.active() && !self.comp.first {
            // As rs274: the held move is checked (a reversed one gouges) and sent.
            let (a1, a2, _) = self.comp_plane()?;
            let (cx, cy) = (self.s.pos[a1], self.s.pos[a2]);
            self.move_endpoint_and_flush(cx, cy)?;
        }
        self.dequeue()?;
        if end {
            self.comp.side = None;
            self.comp.first = true;
            self.comp.arc_not_allowed = false;
        }
        Ok(())
    }

    pub(super) fn set_endpoint(&mut self, x: f64, y: f64) {
        self.comp.endpoint = (x, y);
        self.comp.endpoint_valid = true;
    }

    pub(super) fn enqueue(&mut self, item: Item) {
        self.comp.queue.push((self.loc.clone(), item));
    }

    /// Sends every held call (LinuxCNC `dequeue_canons`).
    pub(super) fn dequeue(&mut self) -> Result<(), GcodeError> {
        self.comp.endpoint_valid = false;
        if self.comp.queue.is_empty() {
            return Ok(());
        }
        // Emitted with the queue empty (so nothing is held again); its buffer is kept.
        let mut q = std::mem::take(&mut self.comp.queue);
        let here = self.loc.clone();
        let plane = self.s.plane;
        let (a1, a2, n) = plane_axes(plane);
        let lathe = plane == Plane::Xz;
        let (o, r) = (self.comp.orientation, self.comp.radius);
        // The controlled point of a lathe tool is not its centre (LinuxCNC latheorigin_*).
        let ox = |x: f64| match o {
            _ if !lathe => x,
            1 | 2 | 6 => x - r,
            3 | 4 | 8 => x + r,
            _ => x,
        };
        let oz = |z: f64| match o {
            _ if !lathe => z,
            2 | 3 | 7 => z - r,
            1 | 4 | 5 => z + r,
            _ => z,
        };
        let fix = |p: &mut [f64; 6]| {
            p[0] = ox(p[0]);
            p[2] = oz(p[2]);
        };
        for (loc, it) in q.drain(..) {
            self.loc = loc;
            let cmd = match it {
                Item::Line { feed, end, .. } => {
                    let mut p = [0.0; 6];
                    p[a1] = end[0];
                    p[a2] = end[1];
                    p[n] = end[2];
                    p[3..].copy_from_slice(&end[3..]);
                    fix(&mut p);
                    if feed {
                        CanonCmd::StraightFeed(pose6(&p))
                    } else {
                        CanonCmd::StraightTraverse(pose6(&p))
                    }
                }
                Item::Arc {
                    end,
                    center,
                    turn,
                    rest,
                    ..
                } => {
                    let (mut e1, mut e2, mut c1, mut c2) = (end.0, end.1, center.0, center.1);
                    if lathe {
                        (e1, e2, c1, c2) = (oz(e1), ox(e2), oz(c1), ox(c2));
                    }
                    let mut p = [0.0; 6];
                    p[a1] = e1;
                    p[a2] = e2;
                    p[n] = rest[0];
                    p[3..].copy_from_slice(&rest[1..]);
                    CanonCmd::ArcFeed {
                        first_end: e1,
                        second_end: e2,
                        first_center: c1,
                        second_center: c2,
                        rotation: turn,
                        axis_end: rest[0],
                        plane,
                        end: pose6(&p),
                    }
                }
                Item::Other(c) => c,
            };
            self.emit(cmd)?;
        }
        self.comp.queue = q;
        self.loc = here;
        Ok(())
    }

    /// Moves the end of every held move to (x, y), checks that none reverses, and sends
    /// them (LinuxCNC `move_endpoint_and_flush`).
    pub(super) fn move_endpoint_and_flush(&mut self, x: f64, y: f64) -> Result<(), GcodeError> {
        if self.comp.queue.is_empty() {
            return Ok(());
        }
        let (ep, valid) = (self.comp.endpoint, self.comp.endpoint_valid);
        // rs274's allowance for a held arc's sweep growing: 0.001 in, 0.0254 mm
        let sweep_tol = match self.s.units {
            crate::gcode::canon::LengthUnits::Inches => 0.001,
            crate::gcode::canon::LengthUnits::Millimeters => 0.0254,
        };
        let mut err = None;
        for (_, it) in &mut self.comp.queue {
            match it {
                Item::Arc {
                    sweep,
                    end,
                    center,
                    turn,
                    ..
                } => {
                    let r1 = (end.0 - center.0).hypot(end.1 - center.1);
                    let r2 = (x - center.0).hypot(y - center.1);
                    let l2 = find_turn(ep.0, ep.1, center.0, center.1, *turn, x, y);
                    if (r1 - r2).abs() > 0.01 {
                        // rs274 reports this as a bug of its own; it refuses the program too.
                        err = Some("Cutter compensation cannot join these moves: the corner point is off the compensated arc (mismatched radii)");
                    } else if *sweep != 0.0 && valid && l2.abs() > sweep.abs() + sweep_tol {
                        err = Some("Arc move in concave corner cannot be reached by the tool without gouging");
                    }
                    *end = (x, y);
                }
                Item::Line { feed, dir, end } => {
                    let dot = dir.0 * (x - ep.0) + dir.1 * (y - ep.1);
                    if valid && dot < 0.0 {
                        err = Some(if *feed {
                            "Straight feed in concave corner cannot be reached by the tool without gouging"
                        } else {
                            "Straight traverse in concave corner cannot be reached by the tool without gouging"
                        });
                    }
                    end[0] = x;
                    end[1] = y;
                }
                Item::Other(_) => {}
            }
            if let Some(m) = err {
                let col = self.loc.col;
                return Err(self.err(col, format!("{m} (tool radius {:.4})", self.comp.radius)));
            }
        }
        self.dequeue()?;
        self.set_endpoint(x, y);
        Ok(())
    }

    /// The first held move, when it is an arc: (end, centre, turn).
    pub(super) fn front_arc(&self) -> Option<HeldArc> {
        match self.comp.queue.first() {
            Some((
                _,
                Item::Arc {
                    end, center, turn, ..
                },
            )) => Some((*end, *center, *turn)),
            _ => None,
        }
    }

    /// Current (tool) point in plane coordinates.
    pub(super) fn comp_current(&self, ax: (usize, usize, usize)) -> (f64, f64, f64) {
        (self.s.pos[ax.0], self.s.pos[ax.1], self.s.pos[ax.2])
    }

    pub(super) fn comp_programmed(&self, ax: (usize, usize, usize)) -> (f64, f64, f64) {
        let p = &self.comp.prog;
        (p[ax.0], p[ax.1], p[ax.2])
    }

    /// Ends a compensated move: the tool at (x, y, z) in plane coordinates, the programmed
    /// point at `prog`, rotary axes at `end`.
    pub(super) fn comp_finish(
        &mut self,
        ax: (usize, usize, usize),
        tool: (f64, f64, f64),
        end: &[f64; 6],
    ) {
        let (a1, a2, n) = ax;
        let mut pos = *end;
        pos[a1] = tool.0;
        pos[a2] = tool.1;
        pos[n] = tool.2;
        self.s.pos = pos;
        self.comp.prog.copy_from_slice(&end[..3]);
    }
}
