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

/// LinuxCNC's `D2R`: `deg * (M_PI / 180.)`, the constant rounded first.
fn d2r(deg: f64) -> f64 {
    const RAD_PER_DEG: f64 = std::f64::consts::PI / 180.0;
    deg * RAD_PER_DEG
}

/// The point the polar words of `b` name, seen from the current point (`cx`, `cy`).
///
/// In G91 rs274 applies the distance and the angle as two steps, each from the point the
/// one before left (distance first: its angle is re-measured with `atan2` for the angle
/// step); doing both at once rounds differently and turns some zeros' signs.
pub(super) fn polar_point(b: &Block, absolute: bool, cx: f64, cy: f64) -> (f64, f64) {
    let (dist, angle) = (b.get(POLAR_R), b.get(POLAR_A).map(d2r));
    if absolute {
        let r = dist.unwrap_or_else(|| cx.hypot(cy));
        let t = angle.unwrap_or_else(|| cy.atan2(cx));
        return (r * t.cos(), r * t.sin());
    }
    let (mut x, mut y) = (cx, cy);
    if let Some(d) = dist {
        let (r, t) = (y.hypot(x) + d, y.atan2(x));
        (x, y) = (r * t.cos(), r * t.sin());
    }
    if let Some(a) = angle {
        let (r, t) = (y.hypot(x), y.atan2(x) + a);
        (x, y) = (r * t.cos(), r * t.sin());
    }
    (x, y)
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
