//! G70 under cutter radius compensation (G41/G42/G41.1/G42.1), as rs274 2.9 runs it.
//!
//! rs274 refuses compensation for G71/G72 but not for G70: it makes the finishing moves
//! (found from the uncompensated profile, exactly as without compensation) as ordinary
//! programmed G0/G1/G2/G3 moves, which its compensation then offsets by the tool radius,
//! with its usual entry move, corners and lathe tool orientation. Two of its details shape
//! the path and are reproduced here (found by comparing traces with `rs274 -g`):
//! - the G70 block's own move to its X/Z comes first (the compensation's entry move when
//!   compensation was just turned on; it must then be longer than the tool radius);
//! - reading the profile leaves rs274's current position at the profile's last programmed
//!   point, and under compensation that position is the tool's. The cycle's next move
//!   (to the start point again) is then a zero-length move held at that point, and the
//!   corner rule of the move after it (into the first pass) joins the two: the path enters
//!   through the end of the profile, moved off it by the corner's intersection. This is
//!   rs274's behaviour, not a sensible one; it is reproduced for parity.
//!
//! An arc whose programmed end is the (compensated) current point within 0.0001 is
//! skipped, as rs274's cycle does.

use super::roughing::Move;
use super::Interp;
use crate::gcode::modal::{li, Block};
use crate::gcode::GcodeError;

impl Interp<'_> {
    /// The G70 start point under compensation: rs274 takes the block's X/Z (G90, or added
    /// to the current point under G91) and otherwise the current (tool) point.
    pub(super) fn comp_cycle_start(&self, b: &Block) -> [f64; 6] {
        let mut start = self.s.pos;
        for (i, c) in [(0, b'x'), (2, b'z')] {
            if let Some(v) = b.get(c) {
                start[i] = if self.s.absolute { v } else { start[i] + v };
            }
        }
        start
    }

    /// Sends G70's moves (`moves`, the first being the move to the start point) through
    /// compensation; `end` is the profile's last programmed point (X, Z).
    pub(super) fn comp_cycle_moves(
        &mut self,
        b: &Block,
        end: (f64, f64),
        moves: &[Move],
    ) -> Result<(), GcodeError> {
        let saved = (self.s.absolute, self.s.ijk_absolute);
        // rs274 runs the cycle in absolute distance modes (its block's words unchanged).
        self.s.absolute = true;
        self.s.ijk_absolute = true;
        let r = self.comp_cycle_run(b, end, moves);
        (self.s.absolute, self.s.ijk_absolute) = saved;
        r
    }

    fn comp_cycle_run(
        &mut self,
        b: &Block,
        end: (f64, f64),
        moves: &[Move],
    ) -> Result<(), GcodeError> {
        let mut first = Block::default();
        for c in [b'x', b'z'] {
            first.val[li(c)] = b.get(c);
            first.col[li(c)] = b.col_of(c);
        }
        self.straight(0, &first)?;
        self.s.pos[0] = end.0;
        self.s.pos[2] = end.1;
        for m in moves.iter().skip(1) {
            let mut blk = Block::default();
            let (g, p) = match m {
                Move::Traverse(p) => (0, p),
                Move::Feed(p) => (10, p),
                Move::Arc { end, center, ccw } => {
                    let here = self.s.pos;
                    if (here[0] - end[0]).abs() < 1e-4 && (here[2] - end[2]).abs() < 1e-4 {
                        continue;
                    }
                    blk.val[li(b'i')] = Some(center.0);
                    blk.val[li(b'k')] = Some(center.1);
                    (if *ccw { 30 } else { 20 }, end)
                }
            };
            blk.val[li(b'x')] = Some(p[0]);
            blk.val[li(b'z')] = Some(p[2]);
            if g >= 20 {
                self.arc(g, &blk)?;
            } else {
                self.straight(g, &blk)?;
            }
        }
        Ok(())
    }
}
