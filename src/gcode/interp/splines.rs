//! G5 (cubic spline) and G5.1 (quadratic B-spline) in the XY plane, as LinuxCNC 2.9's
//! interpreter reads them. Both become one `NURBS_FEED` whose control points are those of
//! the Bézier curve:
//! - G5 `X Y I J P Q`: from the current point P0, P1 = P0 + (I, J), P2 = end + (P, Q),
//!   P3 = end. Without I and J the curve starts in the direction the previous G5 ended
//!   (I, J = -P, -Q of it), so a chain of G5 blocks is tangent-continuous.
//! - G5.1 `X Y I J`: P0, P1 = P0 + (I, J), P2 = end.
//!
//! - G5.2 … G5.3, a NURBS block: the G5.2 line and every following line with X and Y is a
//!   control point with weight P (required and positive after the first line) and order L
//!   (default 3, any line may change it); G5.3 emits the curve from the current point
//!   through them (at least L points with the start). As in rs274: in G91 every point is
//!   relative to the position before G5.2, another motion code drops the block, G5.3 leaves
//!   no motion mode active (G80), and the plane is not checked (points are X and Y).
//!
//! I, J, P and Q are always relative (to the start, resp. the end), whatever G90/G91.1 say.
//! G5 and G5.1 do not change the modal motion: the next block without a G code moves as
//! the motion mode before them (rs274 behaves so).

use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::{CanonCmd, FeedMode, Plane};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;

/// Control points of a G5.2 block so far.
#[derive(Debug, Clone, Default)]
pub(crate) struct NurbsBlock {
    /// `[x, y, weight]`, without the start point.
    points: Vec<[f64; 3]>,
    /// Order (L), 3 by default.
    order: u8,
}

impl Interp<'_> {
    /// A line of a G5.2 block: the G5.2 line itself, or a later line with axis words while
    /// G5.2 is the motion mode.
    pub(super) fn nurbs_point(&mut self, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let first = b.gcode(1) == Some(52) || self.s.nurbs.is_none();
        if first {
            if self.s.feed_rate == 0.0 {
                return Err(self.err(col, "Cannot make a NURBS with 0 feedrate"));
            }
            self.s.motion = 52;
            self.s.nurbs = Some(NurbsBlock {
                points: Vec::new(),
                order: 3,
            });
        }
        let has_xy = (b.has(b'x'), b.has(b'y'));
        if !first || has_xy != (false, false) {
            if has_xy != (true, true) {
                return Err(self.err(
                    col,
                    "You must specify both X and Y coordinates for Control Points",
                ));
            }
            let weight = match b.get(b'p') {
                Some(p) if p > 0.0 => p,
                // The G5.2 line's own weight is not checked by rs274.
                _ if first => 1.0,
                _ => {
                    return Err(self.err(
                        col,
                        "Must specify positive weight P for every Control Point",
                    ))
                }
            };
            let end = self.find_ends(b);
            if let Some(n) = self.s.nurbs.as_mut() {
                n.points.push([end[0], end[1], weight]);
            }
        }
        if let (Some(l), Some(n)) = (b.get(b'l'), self.s.nurbs.as_mut()) {
            // Below 2 a B-spline has no segments: a polyline is the nearest meaning.
            n.order = l.round().clamp(2.0, 255.0) as u8;
        }
        Ok(())
    }

    /// G5.3: the NURBS block becomes one feed move.
    pub(super) fn nurbs_end(&mut self, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let Some(block) = self.s.nurbs.take() else {
            return Err(self.err(col, "Cannot use G5.3 without G5.2 first"));
        };
        if b.has(b'x') != b.has(b'y') {
            return Err(self.err(
                col,
                "You must specify both X and Y coordinates for Control Points",
            ));
        }
        self.s.motion = 800;
        let mut points = Vec::with_capacity(block.points.len() + 1);
        points.push([self.s.pos[0], self.s.pos[1], 1.0]);
        points.extend_from_slice(&block.points);
        if points.len() < usize::from(block.order) {
            return Err(self.err(
                col,
                format!(
                    "You must specify a number of control points at least equal to the order L = {}",
                    block.order
                ),
            ));
        }
        let mut end = self.s.pos;
        if let Some(last) = points.last() {
            end[0] = last[0];
            end[1] = last[1];
        }
        self.emit(CanonCmd::NurbsFeed {
            points,
            order: block.order,
            end: pose6(&end),
            inverse_time: None,
        })?;
        self.s.pos = end;
        Ok(())
    }

    pub(super) fn spline(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        self.refuse_with_comp(self.loc.col, "Cannot make a spline (G5/G5.1)")?;
        let col = self.loc.col;
        if self.s.plane != Plane::Xy {
            return Err(self.err(col, "Splines must be in the XY plane"));
        }
        if b"zabcuvw".iter().any(|&c| b.has(c)) {
            return Err(self.err(col, "Splines may not have motion in Z, A, B, or C"));
        }
        if !b.has(b'x') && !b.has(b'y') {
            return Err(self.err(col, "All axes missing with motion code"));
        }
        self.require_arc_feed(b, col)?;
        let (i, j) = (b.get(b'i'), b.get(b'j'));
        let end = self.find_ends(b);
        let start = [self.s.pos[0], self.s.pos[1]];
        let stop = [end[0], end[1]];
        let points: Vec<[f64; 3]> = if m == 50 {
            let (p, q) = match (b.get(b'p'), b.get(b'q')) {
                (Some(p), Some(q)) => (p, q),
                _ => return Err(self.err(col, "Must specify both P and Q with G5")),
            };
            let (i, j) = match (i, j) {
                (Some(i), Some(j)) => (i, j),
                (None, None) => (-self.s.last_g5_pq[0], -self.s.last_g5_pq[1]),
                _ => return Err(self.err(col, "Must specify both I and J, or neither")),
            };
            self.s.last_g5_pq = [p, q];
            vec![
                [start[0], start[1], 1.0],
                [start[0] + i, start[1] + j, 1.0],
                [stop[0] + p, stop[1] + q, 1.0],
                [stop[0], stop[1], 1.0],
            ]
        } else {
            let (Some(i), Some(j)) = (i, j) else {
                return Err(self.err(col, "Must specify both I and J with G5.1"));
            };
            vec![
                [start[0], start[1], 1.0],
                [start[0] + i, start[1] + j, 1.0],
                [stop[0], stop[1], 1.0],
            ]
        };
        let order = if m == 50 { 4 } else { 3 };
        let inverse_time = (self.s.feed_mode == FeedMode::InverseTime)
            .then(|| b.get(b'f'))
            .flatten();
        self.emit(CanonCmd::NurbsFeed {
            points,
            order,
            end: pose6(&end),
            inverse_time,
        })?;
        self.s.pos = end;
        Ok(())
    }
}
