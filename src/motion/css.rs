//! G96 constant surface speed: the spindle speed follows the X radius of the tool.
//!
//! Under G96 the S word is a surface speed (metres per minute in G21, feet per minute in
//! G20) and the spindle turns at S / (2π·|X|), limited by the G96 D word (rs274 hands canon
//! 1e30 when there is none). The radius is the program X (the distance to the spindle axis
//! when the work offset puts X0 on it), as in LinuxCNC. The planner sets the speed before
//! each move, for the radius the move goes to (so G95 feeds use that rpm); within one long
//! facing move it does not change continuously, as LinuxCNC's motion does.

use crate::gcode::canon::LengthUnits;

/// Spindle rpm for `surface` (per minute, m in mm programs, ft in inch programs) at program
/// X `x` (current units), limited to `max_rpm`.
pub fn rpm(surface: f64, x: f64, units: LengthUnits, max_rpm: f64) -> f64 {
    let per_minute = match units {
        LengthUnits::Millimeters => surface * 1000.0,
        LengthUnits::Inches => surface * 12.0,
    };
    if per_minute.is_nan() || per_minute <= 0.0 {
        return 0.0;
    }
    let circumference = 2.0 * std::f64::consts::PI * x.abs();
    if circumference <= 0.0 {
        return max_rpm;
    }
    (per_minute / circumference).min(max_rpm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_speed_over_circumference_within_the_limit() {
        let r = rpm(100.0, 50.0, LengthUnits::Millimeters, 3000.0);
        assert!((r - 100_000.0 / (2.0 * std::f64::consts::PI * 50.0)).abs() < 1e-9);
        assert!((rpm(100.0, -50.0, LengthUnits::Millimeters, 3000.0) - r).abs() < 1e-12);
        assert_eq!(rpm(100.0, 0.0, LengthUnits::Millimeters, 3000.0), 3000.0);
        assert_eq!(rpm(0.0, 0.0, LengthUnits::Millimeters, 3000.0), 0.0);
        assert_eq!(rpm(100.0, 1.0, LengthUnits::Millimeters, 3000.0), 3000.0);
        let r = rpm(300.0, 1.0, LengthUnits::Inches, 1e30);
        assert!((r - 3600.0 / (2.0 * std::f64::consts::PI)).abs() < 1e-9);
    }
}
