//! LinuxCNC's polar coordinates: `@` (distance from the origin of the active frame) and
//! `^` (angle in degrees, counter-clockwise from +X) in place of X and Y, in G17 only.
//!
//! In G90 a missing word keeps the current point's distance or angle; in G91 both add to
//! the current point's distance and angle about the origin (not about the current point),
//! so `G91 G1 @-.01 ^5` repeated draws a spiral toward the origin and `G91 G81 ^60 L6`
//! drills six holes on a circle. Behaviour checked against `rs274 -g` (corpus
//! `ncf_polar_*.ngc`).

use super::Interp;
use crate::gcode::canon::Plane;
use crate::gcode::modal::{Block, POLAR_A, POLAR_R};
use crate::gcode::GcodeError;

/// The point the polar words of `b` name, seen from the current point (`cx`, `cy`).
pub(super) fn polar_point(b: &Block, absolute: bool, cx: f64, cy: f64) -> (f64, f64) {
    let (mut r, mut t) = (cx.hypot(cy), cy.atan2(cx));
    // `deg * PI / 180` as LinuxCNC's D2R rounds it (see frame::rotate).
    let angle = b.get(POLAR_A).map(|d| d * std::f64::consts::PI / 180.0);
    if absolute {
        r = b.get(POLAR_R).unwrap_or(r);
        t = angle.unwrap_or(t);
    } else {
        r += b.get(POLAR_R).unwrap_or(0.0);
        t += angle.unwrap_or(0.0);
    }
    (r * t.cos(), r * t.sin())
}

impl Interp<'_> {
    /// rs274's checks of polar words before the block runs (the plane is the one in force
    /// before the line).
    pub(super) fn check_polar(&self, b: &Block, g0_uses_axes: bool) -> Result<(), GcodeError> {
        if !b.has_polar() {
            return Ok(());
        }
        let col = if b.has(POLAR_R) {
            b.col_of(POLAR_R)
        } else {
            b.col_of(POLAR_A)
        };
        if self.s.plane != Plane::Xy {
            return Err(self.err(col, "Cannot use polar coordinate except in G17 plane"));
        }
        for (c, name) in [(b'x', 'X'), (b'y', 'Y')] {
            if b.has(c) {
                return Err(self.err(
                    b.col_of(c),
                    format!("Cannot specify both polar coordinate and {name} word"),
                ));
            }
        }
        if g0_uses_axes {
            return Err(self.err(col, "Polar coordinates can only be used for motion"));
        }
        if b.gcode(0) == Some(530) {
            return Err(self.err(col, "Cannot use polar coordinates with G53"));
        }
        Ok(())
    }
}
