//! Arcs (ARC_FEED, with helix and full turns) cut into chords within a tolerance. The chord
//! junctions are then blended like any corner, so the tool never leaves the arc by more than
//! the chord tolerance and the limits are proven the same way as for lines.

use crate::gcode::canon::Plane;
use crate::gcode::NUM_AXES;
use std::f64::consts::PI;

/// Axis indices of a plane: (first in-plane, second in-plane, normal).
pub fn plane_axes(plane: Plane) -> (usize, usize, usize) {
    match plane {
        Plane::Xy => (0, 1, 2),
        Plane::Xz => (2, 0, 1),
        Plane::Yz => (1, 2, 0),
        Plane::Uv => (6, 7, 8),
        Plane::Uw => (8, 6, 7),
        Plane::Vw => (7, 8, 6),
    }
}

/// An arc in the program frame (program units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arc {
    /// Start pose.
    pub start: [f64; NUM_AXES],
    /// End pose.
    pub end: [f64; NUM_AXES],
    /// Centre, first in-plane axis.
    pub center_first: f64,
    /// Centre, second in-plane axis.
    pub center_second: f64,
    /// Signed turns (>0 CCW, <0 CW).
    pub rotation: i32,
    /// Plane.
    pub plane: Plane,
}

/// Most chords one arc (one G2/G3 block) may be cut into: about 300 MB of planned moves. A
/// thousand-turn helix of a 5 mm radius needs some 70,000; `G2 … P2000000000` would need
/// billions, and is refused by line instead of exhausting memory.
pub const MAX_ARC_CHORDS: usize = 1_000_000;

impl Arc {
    /// Swept angle, rad (signed: + is CCW).
    pub fn sweep_rad(&self) -> f64 {
        let (i1, i2, _) = plane_axes(self.plane);
        let a0 = (self.start[i2] - self.center_second).atan2(self.start[i1] - self.center_first);
        let a1 = (self.end[i2] - self.center_second).atan2(self.end[i1] - self.center_first);
        let turns = self.rotation.unsigned_abs().max(1) as f64;
        if self.rotation >= 0 {
            let mut s = (a1 - a0).rem_euclid(2.0 * PI);
            if s <= 1e-12 {
                s = 2.0 * PI;
            }
            s + (turns - 1.0) * 2.0 * PI
        } else {
            let mut s = (a0 - a1).rem_euclid(2.0 * PI);
            if s <= 1e-12 {
                s = 2.0 * PI;
            }
            -(s + (turns - 1.0) * 2.0 * PI)
        }
    }

    /// How many chords [`chord_points`](Self::chord_points) cuts the arc into for `tol`, as a
    /// float: callers check it against [`MAX_ARC_CHORDS`] before anything is allocated (a
    /// turn count `P` is any positive integer, so the count is only bounded by the request).
    pub fn chord_count(&self, tol: f64) -> f64 {
        let (i1, i2, _) = plane_axes(self.plane);
        let r0 = (self.start[i1] - self.center_first).hypot(self.start[i2] - self.center_second);
        let r1 = (self.end[i1] - self.center_first).hypot(self.end[i2] - self.center_second);
        let r = r0.max(r1);
        let max_step = if tol >= r {
            PI / 2.0
        } else {
            (2.0 * (1.0 - tol / r).acos()).min(PI / 2.0)
        };
        (self.sweep_rad().abs() / max_step).ceil().max(1.0)
    }

    /// Points along the arc (excluding the start, including the exact end) such that each
    /// chord stays within `tol` of the arc (program units). Radius, normal axis and the other
    /// axes vary linearly with the angle (helix, spiral).
    pub fn chord_points(&self, tol: f64) -> Vec<[f64; NUM_AXES]> {
        let (i1, i2, _) = plane_axes(self.plane);
        let r0 = (self.start[i1] - self.center_first).hypot(self.start[i2] - self.center_second);
        let r1 = (self.end[i1] - self.center_first).hypot(self.end[i2] - self.center_second);
        let sweep = self.sweep_rad();
        let n = (self.chord_count(tol) as usize).max(1);
        let a0 = (self.start[i2] - self.center_second).atan2(self.start[i1] - self.center_first);
        let mut pts = Vec::with_capacity(n);
        for k in 1..=n {
            if k == n {
                pts.push(self.end);
                break;
            }
            let s = k as f64 / n as f64;
            let ang = a0 + sweep * s;
            let rad = r0 + (r1 - r0) * s;
            let mut p = [0.0; NUM_AXES];
            for (i, p) in p.iter_mut().enumerate() {
                *p = self.start[i] + (self.end[i] - self.start[i]) * s;
            }
            p[i1] = self.center_first + rad * ang.cos();
            p[i2] = self.center_second + rad * ang.sin();
            pts.push(p);
        }
        pts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_circle_and_turns() {
        let mut start = [0.0; NUM_AXES];
        start[0] = 10.0;
        let a = Arc {
            start,
            end: start,
            center_first: 0.0,
            center_second: 0.0,
            rotation: 1,
            plane: Plane::Xy,
        };
        assert!((a.sweep_rad() - 2.0 * PI).abs() < 1e-12);
        let b = Arc { rotation: -2, ..a };
        assert!((b.sweep_rad() + 4.0 * PI).abs() < 1e-12);
        let pts = a.chord_points(0.01);
        assert_eq!(pts.last().copied(), Some(start));
        // Every chord midpoint within tolerance of the circle.
        let mut prev = start;
        for p in pts {
            let m = [(p[0] + prev[0]) / 2.0, (p[1] + prev[1]) / 2.0];
            assert!(10.0 - m[0].hypot(m[1]) <= 0.01 + 1e-12);
            prev = p;
        }
    }
}
