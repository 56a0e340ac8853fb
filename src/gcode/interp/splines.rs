//! G5 (cubic spline) and G5.1 (quadratic B-spline) in the XY plane, as LinuxCNC 2.9's
//! interpreter reads them. Both become one `NURBS_FEED` whose control points are those of
//! the Bézier curve:
//! - G5 `X Y I J P Q`: from the current point P0, P1 = P0 + (I, J), P2 = end + (P, Q),
//!   P3 = end. Without I and J the curve starts in the direction the previous G5 ended
//!   (I, J = -P, -Q of it), so a chain of G5 blocks is tangent-continuous.
//! - G5.1 `X Y I J`: P0, P1 = P0 + (I, J), P2 = end.
//!
//! I, J, P and Q are always relative (to the start, resp. the end), whatever G90/G91.1 say.
//! G5 and G5.1 do not change the modal motion: the next block without a G code moves as
//! the motion mode before them (rs274 behaves so).

use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::{CanonCmd, FeedMode, Plane};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;

impl Interp<'_> {
    pub(super) fn spline(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
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
        let inverse = self.s.feed_mode == FeedMode::InverseTime;
        if inverse && !b.has(b'f') {
            return Err(self.err(col, "F word missing with inverse time arc move"));
        }
        if !inverse && self.s.feed_rate == 0.0 {
            return Err(self.err(col, "Cannot make arc with zero feed rate"));
        }
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
