//! Planning and kinematics errors. A plan error names the G-code line that caused it, so a
//! job is refused as a whole, before any motion, with a message an operator can act on.

/// Why a program could not be planned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The motion configuration is inconsistent.
    #[error("motion config: {0}")]
    Config(String),
    /// A move leaves the soft limits of an axis.
    #[error("line {line}: axis {axis} would reach {value_mm:.4}, outside soft limits [{min_mm}, {max_mm}]")]
    SoftLimit {
        /// Source line of the move.
        line: u32,
        /// Axis letter.
        axis: char,
        /// Offending machine-frame coordinate.
        value_mm: f64,
        /// Lower soft limit.
        min_mm: f64,
        /// Upper soft limit.
        max_mm: f64,
    },
    /// The kinematics cannot reach a point of a move, or a joint limit is exceeded.
    #[error("line {line}: {source}")]
    Kinematics {
        /// Source line of the move.
        line: u32,
        /// What the kinematics said.
        source: KinematicsError,
    },
    /// A command the planner cannot execute (e.g. G95 without spindle speed, probing).
    #[error("line {line}: {what}")]
    Unsupported {
        /// Source line.
        line: u32,
        /// What is not supported and why.
        what: String,
    },
    /// A programmed feed between 0 and [`MIN_FEED`](super::MIN_FEED): named by position,
    /// as the G-code error it is (the planner is the one place every job, MDI line, probing
    /// piece and `hytask plan` passes through).
    #[error("{file}:{line}:{col}: feed F{feed:e} is below the slowest accepted {min:e}")]
    FeedTooSlow {
        /// File of the block.
        file: String,
        /// Line of the block.
        line: u32,
        /// Column of the F word.
        col: u32,
        /// The programmed feed.
        feed: f64,
        /// [`MIN_FEED`](super::MIN_FEED).
        min: f64,
    },
    /// A command carries a value that cannot be planned (zero feed, NaN coordinate, ...).
    #[error("line {line}: {what}")]
    Invalid {
        /// Source line.
        line: u32,
        /// What is wrong.
        what: String,
    },
}

/// Why a kinematics transform failed. Never a NaN: every unreachable case is named.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    /// The point lies outside the workspace (beyond full extension or inside the dead zone).
    #[error("point ({x_mm:.3}, {y_mm:.3}) is out of reach")]
    OutOfReach {
        /// X, mm.
        x_mm: f64,
        /// Y, mm.
        y_mm: f64,
    },
    /// The point is at a singularity where the joint solution is not unique.
    #[error("point ({x_mm:.3}, {y_mm:.3}) is at a singularity")]
    Singular {
        /// X, mm.
        x_mm: f64,
        /// Y, mm.
        y_mm: f64,
    },
    /// A joint would leave its limits.
    #[error("joint {joint} would reach {value:.4}, outside [{min}, {max}]")]
    JointLimit {
        /// Joint index.
        joint: usize,
        /// Joint value.
        value: f64,
        /// Lower limit.
        min: f64,
        /// Upper limit.
        max: f64,
    },
    /// A joint would move faster than its limit.
    #[error("joint {joint} would need {value:.3}/s, above its limit {max}/s")]
    JointVelocity {
        /// Joint index.
        joint: usize,
        /// Needed joint speed.
        value: f64,
        /// Limit.
        max: f64,
    },
    /// A non-finite input.
    #[error("non-finite coordinate")]
    NotFinite,
}
