//! G2/G3: centre (IJK) and radius (R) formats, full circles, helices, P turns, and
//! LinuxCNC's end-point checks with its tolerances and messages.
//!
//! The centre computation follows LinuxCNC's `arc_data_r`/`arc_data_ijk` operation for
//! operation, so traces match rs274 to the last printed digit (including `-0.0000`).

use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::{CanonCmd, FeedMode, LengthUnits, Plane};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;
use std::f64::consts::{PI, SQRT_2};

/// Tolerance for R-format arcs (LinuxCNC `RADIUS_TOLERANCE_INCH`).
const RADIUS_TOLERANCE_INCH: f64 = 0.00005;
/// Absolute tolerance for centre-format arcs, inch (`CENTER_ARC_RADIUS_TOLERANCE_INCH`).
/// LinuxCNC's value carries a factor √2 (the worst rounding of a centre whose two offsets
/// are each rounded by CAM); without it arcs that rs274 accepts are refused. Measured
/// against rs274: an end-radius error of 0.0025 in passes, 0.0029 in fails.
const CENTER_TOL_INCH: f64 = 2.0 * 0.001 * SQRT_2;
/// Absolute tolerance for centre-format arcs, mm (`CENTER_ARC_RADIUS_TOLERANCE_MM`), with
/// the same √2.
const CENTER_TOL_MM: f64 = 2.0 * 0.01 * SQRT_2;
/// Relative tolerance for centre-format arcs (`SPIRAL_RELATIVE_TOLERANCE`).
const SPIRAL_RELATIVE_TOLERANCE: f64 = 0.001;
/// `TINY` of arc_data_r.
const TINY: f64 = 1e-12;
/// `a + s * M_PI_2l` as rs274 computes it (extended sum, then stored to double).
pub(super) fn add_half_pi(a: f64, sign: f64) -> f64 {
    crate::gcode::ldouble::add_pi(a, 0.5 * sign)
}

/// C's `%.4g` (rs274 prints an arc's radius error so): four significant digits, fixed
/// notation for exponents -4 to 3, trailing zeros dropped.
fn c_fmt_g4(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let e = format!("{v:.3e}");
    let (mant, exp) = e.split_once('e').unwrap_or((&e, "0"));
    let x: i32 = exp.parse().unwrap_or(0);
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if (-4..4).contains(&x) {
        let decimals = usize::try_from(3 - x).unwrap_or(0);
        trim(&format!("{v:.decimals$}"))
    } else {
        let sign = if x < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim(mant), x.abs())
    }
}

/// Which axes (indices into X Y Z A B C) form the plane: first, second, normal.
pub(super) fn plane_axes(p: Plane) -> (usize, usize, usize) {
    match p {
        Plane::Xz => (2, 0, 1),
        Plane::Yz => (1, 2, 0),
        _ => (0, 1, 2),
    }
}

impl Interp<'_> {
    pub(super) fn arc(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let plane = self.s.plane;
        if self.comp.arc_not_allowed {
            return Err(self.err(
                col,
                "The move just after exiting cutter compensation mode must be straight, not an arc",
            ));
        }
        if matches!(plane, Plane::Uv | Plane::Uw | Plane::Vw) {
            return Err(self.err(col, "Arcs in the UVW planes are not supported by hytask"));
        }
        let ijk = b.has(b'i') || b.has(b'j') || b.has(b'k');
        let r = b.get(b'r');
        if r.is_none() && !ijk {
            return Err(self.err(col, "R, I, J, and K words all missing for arc"));
        }
        if r.is_some() && ijk {
            return Err(self.err(col, "Mixed radius-ijk format for arc"));
        }
        self.require_arc_feed(b, col)?;
        let (a1, a2, _) = plane_axes(plane);
        let (words, forbidden, msg_missing, msg_forbidden) = match plane {
            Plane::Xz => (
                (b'z', b'x'),
                b'j',
                "X and Z words missing for arc in XZ plane",
                "J word given for arc in XZ plane",
            ),
            Plane::Yz => (
                (b'y', b'z'),
                b'i',
                "Y and Z words missing for arc in YZ plane",
                "I word given for arc in YZ plane",
            ),
            _ => (
                (b'x', b'y'),
                b'k',
                "X and Y words missing for arc in XY plane",
                "K word given for arc in XY plane",
            ),
        };
        // Only the radius format needs an end point in the plane (a full circle cannot be
        // given by R); a centre-format arc without one is a full circle, in LinuxCNC too.
        if r.is_some() && !b.has(words.0) && !b.has(words.1) && !b.has_polar() {
            return Err(self.err(col, msg_missing));
        }
        if b.has(forbidden) {
            return Err(self.err(b.col_of(forbidden), msg_forbidden));
        }
        let turns = match b.get(b'p') {
            Some(p) => {
                if p.fract() != 0.0 {
                    return Err(self.err(b.col_of(b'p'), "P value not an integer with G2 or G3"));
                }
                if p < 1.0 {
                    return Err(self.err(b.col_of(b'p'), "P value must be positive with G2 or G3"));
                }
                p as i32
            }
            None => 1,
        };
        let (o1, o2) = match plane {
            Plane::Xz => (b.get(b'k').unwrap_or(0.0), b.get(b'i').unwrap_or(0.0)),
            Plane::Yz => (b.get(b'j').unwrap_or(0.0), b.get(b'k').unwrap_or(0.0)),
            _ => (b.get(b'i').unwrap_or(0.0), b.get(b'j').unwrap_or(0.0)),
        };
        let end = self.find_ends(b);
        self.s.motion = m;
        let (c1, c2) = (self.s.pos[a1], self.s.pos[a2]);
        let (e1, e2) = (end[a1], end[a2]);
        let cw = m == 20;
        let names = match plane {
            Plane::Xz => ('Z', 'X'),
            Plane::Yz => ('Y', 'Z'),
            _ => ('X', 'Y'),
        };
        let inch = self.s.units == LengthUnits::Inches;
        let radius_tol = if inch {
            RADIUS_TOLERANCE_INCH
        } else {
            RADIUS_TOLERANCE_INCH * 25.4
        };
        if self.comp.active() && plane != Plane::Yz {
            let spiral_abs = if inch { CENTER_TOL_INCH } else { CENTER_TOL_MM };
            let spec = super::cutter_comp::ArcSpec {
                cw,
                r,
                off: (o1, o2),
                turns,
                names,
                ijk_absolute: self.s.ijk_absolute,
                radius_tol,
                spiral_abs,
                f: b.get(b'f'),
            };
            return self.comp_arc(&spec, end);
        }
        let (cen1, cen2, turn) = if let Some(r) = r {
            arc_data_r(cw, c1, c2, e1, e2, r, turns, radius_tol).map_err(|m| self.err(col, m))?
        } else {
            let spiral_abs = if inch { CENTER_TOL_INCH } else { CENTER_TOL_MM };
            arc_data_ijk(
                cw,
                names,
                (c1, c2),
                (e1, e2),
                self.s.ijk_absolute,
                (o1, o2),
                turns,
                radius_tol,
                spiral_abs,
            )
            .map_err(|m| self.err(col, m))?
        };
        let (_, _, n) = plane_axes(plane);
        if self.s.feed_mode == FeedMode::InverseTime {
            let radius = (c1 - cen1).hypot(c2 - cen2);
            let theta = find_turn(c1, c2, cen1, cen2, turn, e1, e2);
            let len = if end[n] == self.s.pos[n] {
                radius * theta.abs()
            } else {
                (radius * theta).hypot(end[n] - self.s.pos[n])
            };
            let rate = (len * b.get(b'f').unwrap_or(0.0)).max(0.1);
            self.s.feed_rate = rate;
            self.emit(CanonCmd::SetFeedRate(rate))?;
        }
        self.emit(CanonCmd::ArcFeed {
            first_end: e1,
            second_end: e2,
            first_center: cen1,
            second_center: cen2,
            rotation: turn,
            axis_end: end[n],
            plane,
            end: pose6(&end),
        })?;
        self.s.pos = end;
        Ok(())
    }
}

/// LinuxCNC `arc_data_r`.
#[allow(clippy::too_many_arguments)]
pub(super) fn arc_data_r(
    cw: bool,
    cx: f64,
    cy: f64,
    ex: f64,
    ey: f64,
    radius: f64,
    p: i32,
    tolerance: f64,
) -> Result<(f64, f64, i32), String> {
    if ex == cx && ey == cy {
        return Err("Current point same as end point of arc".into());
    }
    let abs_radius = radius.abs();
    let mid_x = (ex + cx) / 2.0;
    let mid_y = (ey + cy) / 2.0;
    let mut half_length = (mid_x - ex).hypot(mid_y - ey);
    if half_length - abs_radius > tolerance {
        return Err("Arc radius too small to reach end point".into());
    }
    if half_length / abs_radius > 1.0 - TINY {
        half_length = abs_radius;
    }
    let base = (ey - cy).atan2(ex - cx);
    let theta = if (cw && radius > 0.0) || (!cw && radius < 0.0) {
        add_half_pi(base, -1.0)
    } else {
        add_half_pi(base, 1.0)
    };
    let turn2 = (half_length / abs_radius).asin();
    let offset = abs_radius * turn2.cos();
    let center_x = mid_x + offset * theta.cos();
    let center_y = mid_y + offset * theta.sin();
    Ok((center_x, center_y, if cw { -p } else { p }))
}

/// LinuxCNC `arc_data_ijk`.
#[allow(clippy::too_many_arguments)]
pub(super) fn arc_data_ijk(
    cw: bool,
    names: (char, char),
    cur: (f64, f64),
    end: (f64, f64),
    ij_absolute: bool,
    off: (f64, f64),
    p: i32,
    radius_tol: f64,
    spiral_abs: f64,
) -> Result<(f64, f64, i32), String> {
    let (center_x, center_y) = if ij_absolute {
        off
    } else {
        (cur.0 + off.0, cur.1 + off.1)
    };
    let radius = (center_x - cur.0).hypot(center_y - cur.1);
    let radius2 = (center_x - end.0).hypot(center_y - end.1);
    let (a, bn) = names;
    // Built only on error: arcs are on the hot path.
    let where_ = || {
        format!(
            "start=({a}{:.4},{bn}{:.4}) center=({a}{:.4},{bn}{:.4}) end=({a}{:.4},{bn}{:.4}) r1={:.4} r2={:.4}",
            cur.0, cur.1, center_x, center_y, end.0, end.1, radius, radius2
        )
    };
    if radius < radius_tol || radius2 < radius_tol {
        return Err(format!("Zero-radius arc: {}", where_()));
    }
    let abs_err = (radius - radius2).abs();
    let rel_err = abs_err / radius.max(radius2);
    if abs_err > spiral_abs * 100.0 || (rel_err > SPIRAL_RELATIVE_TOLERANCE && abs_err > spiral_abs)
    {
        return Err(format!(
            "Radius to end of arc differs from radius to start: {} abs_err={} rel_err={:.4}%",
            where_(),
            c_fmt_g4(abs_err),
            rel_err * 100.0
        ));
    }
    Ok((center_x, center_y, if cw { -p } else { p }))
}

/// LinuxCNC `find_turn`: signed angle swept by an arc, radians.
pub(super) fn find_turn(x1: f64, y1: f64, cx: f64, cy: f64, turn: i32, x2: f64, y2: f64) -> f64 {
    if turn == 0 {
        return 0.0;
    }
    let mut alpha = (y1 - cy).atan2(x1 - cx);
    let mut beta = (y2 - cy).atan2(x2 - cx);
    if turn > 0 {
        if beta <= alpha {
            beta += 2.0 * PI;
        }
        (beta - alpha) + f64::from(turn - 1) * 2.0 * PI
    } else {
        if alpha <= beta {
            alpha += 2.0 * PI;
        }
        (beta - alpha) + f64::from(turn + 1) * 2.0 * PI
    }
}

impl Interp<'_> {
    /// rs274's feed checks of an arc (and of a G5/G5.1 spline, which it checks as an arc):
    /// an F word on the line in G93, a feed rate otherwise.
    pub(super) fn require_arc_feed(&self, b: &Block, col: u32) -> Result<(), GcodeError> {
        if self.s.feed_mode == FeedMode::InverseTime {
            if !b.has(b'f') {
                return Err(self.err(col, "F word missing with inverse time arc move"));
            }
        } else if self.s.feed_rate == 0.0 {
            return Err(self.err(col, "Cannot make arc with zero feed rate"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn radius_error_prints_as_c_g4() {
        // rs274's messages for LinuxCNC's bad-arc tests
        assert_eq!(c_fmt_g4(0.285_67), "0.2857");
        assert_eq!(c_fmt_g4(2.856_7), "2.857");
        assert_eq!(c_fmt_g4(0.3), "0.3");
        assert_eq!(c_fmt_g4(3.0), "3");
        assert_eq!(c_fmt_g4(0.002_856_7), "0.002857");
        assert_eq!(c_fmt_g4(1.0), "1");
        assert_eq!(c_fmt_g4(12345.0), "1.234e+04");
        assert_eq!(c_fmt_g4(0.000_012_34), "1.234e-05");
        assert_eq!(c_fmt_g4(9999.6), "1e+04");
    }

    #[test]
    fn half_pi_sum_rounds_once() {
        assert_eq!(add_half_pi(0.0, -1.0), -FRAC_PI_2);
        assert!((add_half_pi(1.0, 1.0) - (1.0 + FRAC_PI_2)).abs() < 1e-15);
    }

    #[test]
    fn r_format_semicircle_centre() {
        let (x, y, t) =
            arc_data_r(true, 0.0, 0.0, 2.0, 0.0, 1.0, 1, 0.00127).unwrap_or((9.0, 9.0, 0));
        assert!((x - 1.0).abs() < 1e-12 && y.abs() < 1e-12);
        assert_eq!(t, -1);
        assert!(arc_data_r(true, 0.0, 0.0, 3.0, 0.0, 1.0, 1, 0.00127).is_err());
    }

    #[test]
    fn ijk_tolerance_is_absolute_and_relative() {
        let n = ('X', 'Y');
        let ok = arc_data_ijk(
            true,
            n,
            (1.0, 0.0),
            (-1.019, 0.0),
            false,
            (-1.0, 0.0),
            1,
            0.00127,
            0.02,
        );
        assert!(ok.is_ok());
        // 0.025 mm off on a 10 mm radius: beyond 0.02, within 0.02·√2 (rs274 accepts it).
        let sqrt2 = arc_data_ijk(
            false,
            n,
            (10.0, 0.0),
            (-10.025, 0.0),
            false,
            (-10.0, 0.0),
            1,
            0.00127,
            CENTER_TOL_MM,
        );
        assert!(sqrt2.is_ok());
        let bad = arc_data_ijk(
            true,
            n,
            (100.0, 0.0),
            (-100.5, 0.0),
            false,
            (-100.0, 0.0),
            1,
            0.00127,
            0.02,
        );
        assert!(bad.is_err());
    }
}
