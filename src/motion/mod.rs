//! Motion: canonical commands to machine-frame moves, lookahead planning, kinematics and the
//! realtime interpolator that turns the segment queue into axis setpoints.
//!
//! Pipeline: [`from_canon::fold`] (units, offsets, rotation, feed modes, arcs → chords,
//! non-motion commands → [`AuxItem`]s) → [`lookahead`] (merging within G64 Q, junction
//! blends within G64 P, backward/forward passes over a window, S-curve segments) → a
//! [`Plan`] of `Copy` [`Item`]s → the [`Interpolator`] on the servo thread.
//! [`stream::PlanStream`] runs that pipeline on a stream of commands in bounded memory (the
//! whole-program [`plan_from`] is the same stream fed at once); a job of millions of lines
//! is planned that way (see `machine::job`).
//!
//! Every segment is one S-curve velocity transition between two velocity *vectors* (see
//! [`profile`]); corners are blends of that same shape ([`blend`]). That is what makes the
//! limits provable: each axis' velocity, acceleration and jerk inside a segment is known in
//! closed form and planned within the limits, velocity is continuous and acceleration is zero
//! at every segment boundary, so the trace is C² with bounded jerk everywhere.
//!
//! Runs of short, gently turning XY chords are fitted into tangent arcs first ([`arcfit`]):
//! an arc segment runs the same S-curve speed law along a circle, and two tangent arcs meet
//! with a bounded curvature step instead of a blend (see [`lookahead`]).
//!
//! Overrides, feed hold and abort are time scaling in the interpolator (`dσ/dt = k`). The
//! planner plans with `(1 - override_reserve)` of each axis' acceleration and jerk and
//! records per segment how far `k` may go ([`Segment::override_cap`]) and how fast it may
//! change ([`Segment::scale_rate_max`]); the interpolator never leaves those bounds, so no
//! override change, hold or abort exceeds a limit or leaves the path. Arcs are the exception
//! to the reserve: their normal acceleration is planned against the full acceleration, with
//! the vector bound `√((a_t + v·k̇)² + a_n²) ≤ A` (a hold only adds tangential deceleration,
//! orthogonal to `a_n`, while `a_n` falls with `k²`; see [`limits::Limits::arc`]). Above 100%, only the
//! parts of the path that are not already at a limit get faster (cruises below the axis
//! velocity), as with any planner.
//!
//! Non-motion commands ride in the queue in program order. Barriers ([`AuxKind::is_barrier`]:
//! M0/M1/M2, spindle start/stop, tool change, M66 wait, immediate I/O, user M-codes) end the
//! lookahead run at rest and the interpolator waits for `aux_done`; S changes, synchronised
//! I/O (M62/M63/M67), coolant and messages are reported when reached without slowing down.
//!
//! Usage (the lead wraps `step` in the servo task and feeds the queue through a lock-free
//! buffer implementing [`SegmentSource`]):
//!
//! ```
//! use hytask::gcode::{Canon, CanonCmd, SourceLoc};
//! use hytask::motion::{plan, Interpolator, InterpState, MotionConfig, SliceSource};
//!
//! let loc = |line| SourceLoc { file: "demo.ngc".into(), line, col: 1 };
//! let mut p = [0.0; 9];
//! p[0] = 10.0;
//! let canon = vec![
//!     Canon { loc: loc(1), cmd: CanonCmd::SetFeedRate(1200.0) },
//!     Canon { loc: loc(2), cmd: CanonCmd::StraightFeed(p) },
//! ];
//! let cfg = MotionConfig::default();
//! let planned = plan(&canon, &cfg).expect("plannable");
//! assert!(planned.duration_s > 0.5); // 10 mm at 20 mm/s, plus S-curves
//!
//! let mut interp = Interpolator::new(&cfg, planned.start_mm);
//! let mut queue = SliceSource::new(&planned.items);
//! interp.set_feed_override(0.5);
//! loop {
//!     let out = interp.step(&mut queue); // once per servo period
//!     if out.state == InterpState::Done {
//!         assert_eq!(out.pose_mm[0], 10.0);
//!         break;
//!     }
//! }
//! ```

// Index loops over several parallel per-axis arrays read better than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod arcfit;
pub mod arcs;
pub mod blend;
pub mod blend_path;
pub mod bounds;
pub mod config;
pub mod css;
pub mod draw;
mod emit;
mod error;
pub mod fifo;
mod fit_chains;
pub mod fit_choice;
pub mod from_canon;
pub mod interpolator;
pub mod kinematics;
pub mod limits;
pub mod line_marks;
pub mod line_stop;
pub mod lookahead;
pub mod merge;
pub mod moves;
pub mod nurbs;
pub mod path_stop;
pub mod profile;
pub mod segment;
pub mod span;
pub mod spindle_lock;
pub mod spindle_sync;
pub mod stop_bounds;
pub mod stream;
pub mod svg;
pub mod trace;

/// Slowest programmed feed accepted other than 0: 1e-6 units/min (units/rev with G95, 1/min
/// with G93), below any machine's resolution and far below a fine inch feed per revolution
/// (0.0005 in/rev). `F` written with 320 zeros (a subnormal) was planned as a move of
/// ~1e321 s, and `hytask plan` overflowed sizing its trace.
pub const MIN_FEED: f64 = 1e-6;

pub use config::{AxisLimits, KinematicsConfig, MotionConfig, ScaraConfig};
pub use error::{KinematicsError, PlanError};
pub use interpolator::{
    InterpOutput, InterpState, Interpolator, IterSource, SegmentSource, SliceSource,
};
pub use segment::{AuxItem, AuxKind, Item, Segment, SegmentKind, Window};

use crate::gcode::{Canon, NUM_AXES};

/// Axis letters in pose order.
pub const AXIS_NAMES: [char; NUM_AXES] = ['X', 'Y', 'Z', 'A', 'B', 'C', 'U', 'V', 'W'];

/// A planned program: the segment queue plus what an operator wants to know before running.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The queue, in execution order.
    pub items: Vec<Item>,
    /// Texts of message items (`AuxKind::Message::id` indexes here).
    pub messages: Vec<String>,
    /// Machine pose at the start, mm.
    pub start_mm: [f64; NUM_AXES],
    /// Machine pose at the end, mm.
    pub end_mm: [f64; NUM_AXES],
    /// Planned motion time at 100% override (dwells included, waits for the machine not), s.
    pub duration_s: f64,
    /// Planned path length, mm (rotary-only moves count their degrees).
    pub distance_mm: f64,
    /// Number of distinct source lines that produced queue items.
    pub line_count: usize,
    /// Number of motion segments in the queue.
    pub segment_count: usize,
    /// Units, offsets and modes at the end (where a probing program's next piece goes on).
    pub end_state: from_canon::FoldState,
}

/// Plans a canonical stream starting at machine zero. See [`plan_from`].
pub fn plan(canon: &[Canon], cfg: &MotionConfig) -> Result<Plan, PlanError> {
    plan_from(canon, cfg, [0.0; NUM_AXES])
}

/// Plans a canonical stream starting at machine pose `start_mm`. The whole program is
/// checked (soft limits, kinematics) before anything is returned, so a refused program
/// never starts moving.
pub fn plan_from(
    canon: &[Canon],
    cfg: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<Plan, PlanError> {
    plan_continue(canon, cfg, start_mm, from_canon::FoldState::new(cfg))
}

/// Plans one straight feed move from `start_mm` to `end_mm` at `feed_mm_min`, reported as
/// coming from `loc`: what a jog is, and what tests queue by hand.
pub fn plan_straight_feed(
    start_mm: [f64; NUM_AXES],
    end_mm: [f64; NUM_AXES],
    feed_mm_min: f64,
    loc: crate::gcode::SourceLoc,
    cfg: &MotionConfig,
) -> Result<Plan, PlanError> {
    let canon = [
        Canon {
            loc: loc.clone(),
            cmd: crate::gcode::CanonCmd::SetFeedRate(feed_mm_min),
        },
        Canon {
            loc,
            cmd: crate::gcode::CanonCmd::StraightFeed(end_mm),
        },
    ];
    plan_from(&canon, cfg, start_mm)
}

/// Plans the next piece of a program interpreted in pieces (probing): like [`plan_from`],
/// with the units, offsets and modes the previous piece ended with ([`Plan::end_state`]).
pub fn plan_continue(
    canon: &[Canon],
    cfg: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    state: from_canon::FoldState,
) -> Result<Plan, PlanError> {
    let mut items = Vec::new();
    let mut sink = |chunk: &[Item]| items.extend_from_slice(chunk);
    let mut stream = stream::PlanStream::new(cfg, start_mm, state)?;
    stream.push(canon, &mut sink)?;
    let mut plan = stream.finish(&mut sink)?.plan;
    plan.items = items;
    Ok(plan)
}
