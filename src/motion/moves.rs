//! Machine-frame moves: what `from_canon` produces and the lookahead consumes.

use super::segment::AuxItem;
use crate::gcode::NUM_AXES;

/// How a move may be joined to the next one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Junction {
    /// G61: stop at the end of the move.
    ExactStop,
    /// Blend into the next move, deviating at most this much from the programmed corner, mm
    /// (G64 P, G61.1 with a tiny tolerance, or the chord tolerance inside an arc).
    Blend {
        /// Largest allowed path deviation, mm.
        tolerance_mm: f64,
    },
}

/// Rapid or feed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MoveKind {
    /// G0: at the axis limits.
    Rapid,
    /// G1/G2/G3: at the programmed feed (arcs arrive here as chords).
    Feed,
}

/// A straight move in the machine frame, mm (deg for A B C).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Move {
    /// Start pose.
    pub start_mm: [f64; NUM_AXES],
    /// End pose.
    pub end_mm: [f64; NUM_AXES],
    /// Rapid or feed.
    pub kind: MoveKind,
    /// Requested path speed, mm/s (infinite for rapids: axis limits apply).
    pub feed_mm_s: f64,
    /// How to join the next move.
    pub junction: Junction,
    /// Nearly collinear moves within this distance may be merged (G64 Q), mm; 0 = never.
    pub merge_tol_mm: f64,
    /// Arc this chord belongs to (0 = a line); junctions inside one arc use the chord
    /// tolerance whatever the path mode.
    pub arc_id: u32,
    /// Blend tolerance at a junction with the next chord of the same arc, mm.
    pub chord_tol_mm: f64,
    /// Source line.
    pub line: u32,
}

impl Move {
    /// Length in which the feed rate is expressed (LinuxCNC rule: XYZ if any moves, else
    /// UVW, else ABC).
    pub fn feed_length_mm(&self) -> f64 {
        let d = |idx: [usize; 3]| {
            idx.iter()
                .map(|&i| (self.end_mm[i] - self.start_mm[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let xyz = d([0, 1, 2]);
        if xyz > 1e-12 {
            return xyz;
        }
        let uvw = d([6, 7, 8]);
        if uvw > 1e-12 {
            return uvw;
        }
        d([3, 4, 5])
    }
}

/// One step of a folded program: motion, dwell or a non-motion command.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// A straight move.
    Move(Move),
    /// G4: stop and wait.
    Dwell {
        /// Seconds.
        seconds: f64,
        /// Source line.
        line: u32,
    },
    /// A non-motion command.
    Aux(AuxItem),
}
