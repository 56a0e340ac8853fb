//! Spindle-synchronised feeds (G33, G76 passes, G33.1): the feed of a move between
//! `START_SPEED_FEED_SYNC(pitch)` and `STOP_SPEED_FEED_SYNCH()` is `pitch` per spindle
//! revolution.
//!
//! The planner plans each synchronised move locked to the commanded spindle speed
//! (velocity synchronisation, like G95): the path speed is pitch × rpm, from rest to rest
//! (G33.1: in and back out). That plan is what a trace or a plot shows. The machine
//! runs it locked to the *measured* spindle position instead, as LinuxCNC's motion does:
//! the plan marks the move with `AuxKind::SpindleSync` / `SpindleSyncEnd`, and the servo
//! cycle waits for the index and follows the spindle ([`super::spindle_lock`]). Constant
//! surface speed is not combined with synchronised moves: under G96 (S is then a surface
//! speed, not an rpm) they are refused.

use super::PlanError;

/// Path speed (mm/s) of a feed of `pitch` program units per revolution (`mm_per_unit` mm
/// each) at `rpm`, or why it cannot be planned.
pub fn feed_mm_s(
    pitch: f64,
    mm_per_unit: f64,
    rpm: f64,
    css: bool,
    line: u32,
) -> Result<f64, PlanError> {
    let unsupported = |what: String| Err(PlanError::Unsupported { line, what });
    if css {
        return unsupported(
            "spindle-synchronised move (G33/G76) under constant surface speed (G96): \
             the spindle speed is not known; use G97"
                .into(),
        );
    }
    if !(pitch.is_finite() && pitch > 0.0) {
        return Err(PlanError::Invalid {
            line,
            what: format!("spindle-synchronised move with pitch {pitch} (K/P must be > 0)"),
        });
    }
    if !(rpm.is_finite() && rpm > 0.0) {
        return unsupported(
            "spindle-synchronised move (G33/G76) needs a spindle speed (S) or \
             nominal_spindle_rpm in the motion config"
                .into(),
        );
    }
    Ok(pitch * mm_per_unit * rpm / 60.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pitch_times_rpm() {
        let v = feed_mm_s(1.5, 1.0, 600.0, false, 1).unwrap_or(0.0);
        assert!((v - 15.0).abs() < 1e-12);
        let v = feed_mm_s(0.0625, 25.4, 120.0, false, 1).unwrap_or(0.0);
        assert!((v - 0.0625 * 25.4 * 2.0).abs() < 1e-12);
        assert!(feed_mm_s(1.0, 1.0, 600.0, true, 1).is_err());
        assert!(feed_mm_s(0.0, 1.0, 600.0, false, 1).is_err());
        assert!(feed_mm_s(-1.0, 1.0, 600.0, false, 1).is_err());
        assert!(feed_mm_s(1.0, 1.0, 0.0, false, 1).is_err());
    }
}
