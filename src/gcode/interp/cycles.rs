//! Canned cycles in the XY, XZ and YZ planes (drilling along Z, Y and X): G73, G81–G86,
//! G88, G89 with G98/G99 retract,
//! sticky R/Z/Q/P values, L repeats and incremental mode, generated exactly as LinuxCNC's
//! `convert_cycle_xy` does (including its switch to exact-path mode around the cycle).

use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::{CanonCmd, MotionControl, Plane};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;

impl Interp<'_> {
    /// A cycle move to plane coordinates (`x`, `y`) and drilling-axis height `z`, mapped to
    /// the real axes by `ax` (indices of the plane's first, second and normal axis).
    fn cycle_move(&mut self, feed: bool, x: f64, y: f64, z: f64) -> Result<(), GcodeError> {
        let ax = self.cycle_axes;
        let mut p = self.s.pos;
        p[ax.0] = x;
        p[ax.1] = y;
        p[ax.2] = z;
        self.s.pos = p;
        let pose = pose6(&p);
        self.emit(if feed {
            CanonCmd::StraightFeed(pose)
        } else {
            CanonCmd::StraightTraverse(pose)
        })
    }

    pub(super) fn cycle(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        self.refuse_with_comp(self.loc.col, "Cannot use canned cycles")?;
        let col = self.loc.col;
        // LinuxCNC convert_cycle_xy / _zx / _yz: (first, second, drilling) axes.
        let (ax, letters, plane_name): ((usize, usize, usize), [u8; 3], &str) = match self.s.plane {
            Plane::Xy => ((0, 1, 2), *b"xyz", "XY"),
            Plane::Xz => ((2, 0, 1), *b"zxy", "XZ"),
            Plane::Yz => ((1, 2, 0), *b"yzx", "YZ"),
            _ => {
                return Err(self.err(
                    col,
                    "Canned cycles are not supported in the UVW planes by hytask",
                ))
            }
        };
        self.cycle_axes = ax;
        let depth_name = (letters[2] as char).to_ascii_uppercase();
        if b.has(b'a') || b.has(b'b') || b.has(b'c') {
            return Err(self.err(col, "Cannot put an A, B, or C in a canned cycle"));
        }
        let same = self.s.motion == m;
        let z = match b.get(letters[2]) {
            Some(z) => z,
            None if same => self.s.cycle_z,
            None => {
                return Err(self.err(
                    col,
                    format!("{depth_name} value unspecified in canned cycle"),
                ))
            }
        };
        let r_word = match b.get(b'r') {
            Some(r) => r,
            None if same => self.s.cycle_r,
            None => return Err(self.err(col, "R clearance plane unspecified in cycle")),
        };
        let l = match b.get(b'l') {
            Some(l) => {
                if l.fract() != 0.0 || l < 1.0 {
                    return Err(self.err(b.col_of(b'l'), "Cannot do zero repeats of cycle"));
                }
                l as u64
            }
            None => 1,
        };
        let q = match b.get(b'q') {
            Some(q) => q,
            None => self.s.cycle_q,
        };
        if matches!(m, 730 | 830) && q <= 0.0 {
            return Err(self.err(col, "Q word missing or not positive with G73 or G83"));
        }
        if matches!(m, 820 | 860 | 880 | 890) && !b.has(b'p') && !same {
            return Err(self.err(col, format!("Dwell time p word missing with g{}", m / 10)));
        }
        let p = b.get(b'p').unwrap_or(self.s.cycle_p);
        if p < 0.0 {
            return Err(self.err(b.col_of(b'p'), "Negative dwell time with canned cycle"));
        }
        if self.s.feed_rate == 0.0 {
            return Err(self.err(col, "Cannot feed with zero feed rate in a canned cycle"));
        }
        if m == 860 && self.s.spindle == 0 {
            return Err(self.err(col, "Spindle not turning in G86"));
        }
        if m == 840 && self.s.spindle != 1 {
            return Err(self.err(col, "Spindle not turning clockwise in G84"));
        }
        if m == 880 && self.s.spindle == 0 {
            return Err(self.err(col, "Spindle not turning in G88"));
        }
        // A series of contiguous cycles remembers the Z it started from (G98's "old Z").
        let first = !matches!(self.s.motion, 730 | 810..=890);
        let cur_z = self.s.pos[ax.2];
        if first {
            self.s.cycle_start_z = cur_z;
        }
        let start_z = self.s.cycle_start_z;
        let mut old_z = cur_z;
        let (mut x, mut y, dx, dy, r, bottom) = if self.s.absolute {
            (
                b.get(letters[0]).unwrap_or(self.s.pos[ax.0]),
                b.get(letters[1]).unwrap_or(self.s.pos[ax.1]),
                0.0,
                0.0,
                r_word,
                z,
            )
        } else {
            // A sticky R (not on this block) is the R plane already computed, not added
            // to the current height again (observed rs274 2.9 behaviour).
            // An R word counts from the height the series of cycles started at.
            let r = if b.has(b'r') {
                r_word + start_z
            } else {
                self.s.cycle_r_abs
            };
            (
                self.s.pos[ax.0],
                self.s.pos[ax.1],
                b.get(letters[0]).unwrap_or(0.0),
                b.get(letters[1]).unwrap_or(0.0),
                r,
                r + z,
            )
        };
        if r < bottom {
            return Err(self.err(
                col,
                format!("R less than {depth_name} in cycle in {plane_name} plane"),
            ));
        }
        // The preliminary rapid to the R plane and the retract height follow rs274 2.9
        // (observed behaviour, see tests/gcode/corpus/cycles_*.ngc).
        let pre = if first { cur_z < r } else { start_z < r };
        if cur_z < r {
            old_z = if !first && self.s.retract_old_z {
                start_z.max(r)
            } else {
                r
            };
        }
        if pre {
            let (cx, cy) = (self.s.pos[ax.0], self.s.pos[ax.1]);
            self.cycle_move(false, cx, cy, r)?;
            // the tool is now at the R plane, even when it came down to it (G91 series)
            old_z = r;
        }
        let clear = if self.s.retract_old_z {
            start_z.max(r)
        } else {
            r
        };

        let saved = self.s.control;
        if saved != MotionControl::ExactPath {
            self.emit(CanonCmd::SetMotionControl(MotionControl::ExactPath))?;
        }
        let delta = if self.s.units == crate::gcode::canon::LengthUnits::Inches {
            0.010
        } else {
            0.254
        };
        let polar = b.has_polar();
        if polar && self.s.absolute {
            (x, y) = super::polar::polar_point(b, true, x, y);
        }
        for _ in 0..l {
            if polar && !self.s.absolute {
                // each repeat steps distance and angle about the origin
                (x, y) = super::polar::polar_point(b, false, x, y);
            }
            x += dx;
            y += dy;
            self.cycle_move(false, x, y, old_z)?;
            if old_z != r {
                self.cycle_move(false, x, y, r)?;
            }
            match m {
                810 => {
                    self.cycle_move(true, x, y, bottom)?;
                    self.cycle_move(false, x, y, clear)?;
                }
                820 => {
                    self.cycle_move(true, x, y, bottom)?;
                    self.emit(CanonCmd::Dwell(p))?;
                    self.cycle_move(false, x, y, clear)?;
                }
                830 | 730 => {
                    let mut depth = r - q;
                    while depth > bottom {
                        self.cycle_move(true, x, y, depth)?;
                        if m == 830 {
                            self.cycle_move(false, x, y, r)?;
                        }
                        self.cycle_move(false, x, y, depth + delta)?;
                        depth -= q;
                    }
                    self.cycle_move(true, x, y, bottom)?;
                    self.cycle_move(false, x, y, clear)?;
                }
                850 | 890 => {
                    self.cycle_move(true, x, y, bottom)?;
                    if m == 890 {
                        self.emit(CanonCmd::Dwell(p))?;
                    }
                    // rs274 2.9: G85 feeds out to R then rapids to the clearance height;
                    // G89 feeds out straight to the clearance height.
                    if m == 850 {
                        self.cycle_move(true, x, y, r)?;
                        self.cycle_move(false, x, y, clear)?;
                    } else {
                        self.cycle_move(true, x, y, clear)?;
                    }
                }
                840 => {
                    // Right-hand tapping: overrides off, reverse at the bottom, feed out.
                    let ov = |which, on| CanonCmd::OverrideEnable { which, on };
                    use crate::gcode::canon::{OverrideKind, SpindleDir};
                    self.emit(ov(OverrideKind::Feed, false))?;
                    self.emit(ov(OverrideKind::Spindle, false))?;
                    self.cycle_move(true, x, y, bottom)?;
                    self.emit(CanonCmd::StopSpindle)?;
                    self.emit(CanonCmd::StartSpindle(SpindleDir::CounterClockwise))?;
                    self.emit(CanonCmd::Dwell(p))?;
                    self.cycle_move(true, x, y, clear)?;
                    self.emit(CanonCmd::StopSpindle)?;
                    self.emit(CanonCmd::StartSpindle(SpindleDir::Clockwise))?;
                    // Overrides come back only if they were on before the cycle.
                    if self.s.feed_override {
                        self.emit(ov(OverrideKind::Feed, true))?;
                    }
                    if self.s.speed_override {
                        self.emit(ov(OverrideKind::Spindle, true))?;
                    }
                }
                880 => {
                    // Boring, manual retract: stop, wait for the operator, restart.
                    self.cycle_move(true, x, y, bottom)?;
                    self.emit(CanonCmd::Dwell(p))?;
                    self.emit(CanonCmd::StopSpindle)?;
                    self.emit(CanonCmd::ProgramStop)?;
                    let dir = if self.s.spindle > 0 {
                        crate::gcode::canon::SpindleDir::Clockwise
                    } else {
                        crate::gcode::canon::SpindleDir::CounterClockwise
                    };
                    self.emit(CanonCmd::StartSpindle(dir))?;
                }
                _ => {
                    // G86
                    self.cycle_move(true, x, y, bottom)?;
                    self.emit(CanonCmd::Dwell(p))?;
                    self.emit(CanonCmd::StopSpindle)?;
                    self.cycle_move(false, x, y, clear)?;
                    let dir = if self.s.spindle > 0 {
                        crate::gcode::canon::SpindleDir::Clockwise
                    } else {
                        crate::gcode::canon::SpindleDir::CounterClockwise
                    };
                    self.emit(CanonCmd::StartSpindle(dir))?;
                }
            }
            old_z = clear;
        }
        self.s.pos[ax.0] = x;
        self.s.pos[ax.1] = y;
        self.s.pos[ax.2] = clear;
        self.s.cycle_z = z;
        self.s.cycle_r = r_word;
        self.s.cycle_r_abs = r;
        self.s.cycle_q = q;
        self.s.cycle_p = p;
        self.s.motion = m;
        if saved != MotionControl::ExactPath {
            // rs274 restores the mode and then the naive-CAM tolerance, whatever the mode.
            self.emit(CanonCmd::SetMotionControl(saved))?;
            self.emit(CanonCmd::SetNaivecamTolerance(self.s.naive_tol))?;
        }
        Ok(())
    }
}
