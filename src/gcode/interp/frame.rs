//! The program frame against the machine frame, with the XY rotation of `G10 L2 … R`.
//!
//! LinuxCNC's canon turns a program position into a machine position as
//! `machine = rotate(program + G92, R) + G5x + tool offset` (only X and Y rotate, about the
//! work origin); hytask's planner folds canon the same way (`motion::from_canon`). The
//! interpreter needs the inverse wherever a position is given in machine coordinates (G53,
//! G28/G30 homes) or the frame changes under a standing tool (a new coordinate system or
//! rotation), so that the machine ends where LinuxCNC's does.

use super::Interp;

/// (x, y) turned counter-clockwise by `deg` degrees.
pub(crate) fn rotate(x: f64, y: f64, deg: f64) -> (f64, f64) {
    // `deg * PI / 180`, not `to_radians`: the same two roundings as LinuxCNC's D2R, so
    // the signs of results that cancel to about 0 match rs274's.
    let t = deg * std::f64::consts::PI / 180.0;
    (x * t.cos() - y * t.sin(), x * t.sin() + y * t.cos())
}

impl Interp<'_> {
    /// How the program position moves when the tool length offset changes by `d` (old
    /// minus new, machine axes): the offset moves the machine frame, so its X/Y part shows
    /// in the program frame turned back by the `G10 L2 … R` rotation, as in rs274.
    pub(crate) fn program_shift_of_tool(&self, d: [f64; 6]) -> [f64; 6] {
        let mut v = d;
        (v[0], v[1]) = rotate(d[0], d[1], -self.s.rotation);
        v
    }

    /// Machine position (program units) of program position `p` in the active frame.
    /// `with_tool`: add the tool length offset (the tool tip's frame), as canon does.
    pub(crate) fn machine_of_program(&self, p: &[f64; 6], with_tool: bool) -> [f64; 6] {
        let s = &self.s;
        let mut m = [0.0; 6];
        for (i, v) in m.iter_mut().enumerate() {
            *v = p[i] + s.g92[i];
        }
        (m[0], m[1]) = rotate(m[0], m[1], s.rotation);
        for (i, v) in m.iter_mut().enumerate() {
            *v += s.g5x[i] + if with_tool { s.tool_offset[i] } else { 0.0 };
        }
        m
    }

    /// Program position in the active frame of machine position `m` (program units),
    /// the inverse of [`Self::machine_of_program`]. `with_tool`: `m` includes the tool length
    /// offset.
    pub(crate) fn program_of_machine(&self, m: &[f64; 6], with_tool: bool) -> [f64; 6] {
        let s = &self.s;
        let mut p = [0.0; 6];
        for (i, v) in p.iter_mut().enumerate() {
            *v = m[i] - s.g5x[i];
            if with_tool {
                *v -= s.tool_offset[i];
            }
        }
        (p[0], p[1]) = rotate(p[0], p[1], -s.rotation);
        for (i, v) in p.iter_mut().enumerate() {
            *v -= s.g92[i];
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_counter_clockwise_in_degrees() {
        let (x, y) = rotate(10.0, 0.0, 45.0);
        assert!((x - 7.0710678).abs() < 1e-6 && (y - 7.0710678).abs() < 1e-6);
        let (x, y) = rotate(x, y, -45.0);
        assert!((x - 10.0).abs() < 1e-12 && y.abs() < 1e-12);
    }
}
