//! Folds canonical commands (program frame, current units, offsets as separate commands)
//! into machine-frame moves in mm, dwells and auxiliary items, each with its source line.
//!
//! Transform, as LinuxCNC's canon applies it: `machine = rotate(program·units + G92) + G5x +
//! tool offset`, where the rotation is the G10 L2 R rotation about the work origin. Offsets
//! are converted to mm with the units active when they were set.

use super::arcs::Arc;
use super::config::MotionConfig;
use super::moves::{Junction, Move, MoveKind, Step};
use super::segment::{AuxItem, AuxKind};
use super::PlanError;
use crate::gcode::canon::{CanonCmd, FeedMode, LengthUnits, MotionControl};
use crate::gcode::{Canon, NUM_AXES};

/// Indices of the linear axes (scaled by the length units).
const LINEAR: [usize; 6] = [0, 1, 2, 6, 7, 8];

/// The folded program.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Folded {
    /// Moves, dwells and auxiliary items in execution order.
    pub steps: Vec<Step>,
    /// Texts of `(MSG, …)` items, indexed by `AuxKind::Message::id`.
    pub messages: Vec<String>,
    /// Machine pose after the last move.
    pub end_mm: [f64; NUM_AXES],
    /// Units, offsets and modes at the end: where the next piece of a program interpreted
    /// in pieces (probing) continues, and the frame that converts a measured machine pose
    /// back into program coordinates.
    pub state: FoldState,
}

/// The modal state of the fold: units, offsets, rotation, feed and path modes. Carried from
/// one piece of a probing program to the next, since a piece's canonical commands do not
/// repeat what was set before it.
#[derive(Debug, Clone, PartialEq)]
pub struct FoldState {
    units: LengthUnits,
    g5x_mm: [f64; NUM_AXES],
    g92_mm: [f64; NUM_AXES],
    tool_mm: [f64; NUM_AXES],
    rotation_deg: f64,
    feed: f64,
    feed_mode: FeedMode,
    control: MotionControl,
    naivecam_tol: f64,
    spindle_rpm: f64,
    pos_mm: [f64; NUM_AXES],
    arc_id: u32,
    /// Pitch (program units per revolution) while feeds are spindle-synchronised.
    sync_pitch: Option<f64>,
    /// G96: S is a surface speed.
    css: bool,
    /// G96 D limit, rpm.
    css_max_rpm: f64,
    /// G96 S: surface speed per minute (m or ft).
    surface: f64,
}

impl Default for FoldState {
    fn default() -> Self {
        FoldState {
            units: LengthUnits::Millimeters,
            g5x_mm: [0.0; NUM_AXES],
            g92_mm: [0.0; NUM_AXES],
            tool_mm: [0.0; NUM_AXES],
            rotation_deg: 0.0,
            feed: 0.0,
            feed_mode: FeedMode::UnitsPerMinute,
            control: MotionControl::Continuous { tolerance: 0.0 },
            naivecam_tol: 0.0,
            spindle_rpm: 0.0,
            pos_mm: [0.0; NUM_AXES],
            arc_id: 0,
            sync_pitch: None,
            css: false,
            css_max_rpm: 0.0,
            surface: 0.0,
        }
    }
}

impl FoldState {
    /// The state at the start of a program: millimetres, no offsets, the configured
    /// nominal spindle speed.
    pub fn new(cfg: &MotionConfig) -> Self {
        FoldState {
            spindle_rpm: cfg.nominal_spindle_rpm,
            ..FoldState::default()
        }
    }

    /// A machine pose (mm, deg) in the program frame and units of this state: X Y Z A B C,
    /// as the interpreter wants a probe result.
    pub fn program_xyzabc(&self, machine_mm: &[f64; NUM_AXES]) -> [f64; 6] {
        let p = self.to_program(machine_mm);
        let mut out = [0.0; 6];
        out.copy_from_slice(&p[..6]);
        out
    }

    fn scale(&self) -> f64 {
        self.units.mm_per_unit()
    }

    fn to_mm(&self, p: &[f64; NUM_AXES]) -> [f64; NUM_AXES] {
        let mut q = *p;
        for i in LINEAR {
            q[i] *= self.scale();
        }
        q
    }

    /// Program pose (current units) → machine pose (mm).
    fn to_machine(&self, p: &[f64; NUM_AXES]) -> [f64; NUM_AXES] {
        let mut q = self.to_mm(p);
        for i in 0..NUM_AXES {
            q[i] += self.g92_mm[i];
        }
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let (x, y) = (q[0], q[1]);
        q[0] = c * x - s * y;
        q[1] = s * x + c * y;
        for i in 0..NUM_AXES {
            q[i] += self.g5x_mm[i] + self.tool_mm[i];
        }
        q
    }

    /// Machine pose (mm) → program pose (current units).
    pub fn to_program(&self, m: &[f64; NUM_AXES]) -> [f64; NUM_AXES] {
        let mut q = *m;
        for i in 0..NUM_AXES {
            q[i] -= self.g5x_mm[i] + self.tool_mm[i];
        }
        let (s, c) = (-self.rotation_deg.to_radians()).sin_cos();
        let (x, y) = (q[0], q[1]);
        q[0] = c * x - s * y;
        q[1] = s * x + c * y;
        for i in 0..NUM_AXES {
            q[i] -= self.g92_mm[i];
        }
        for i in LINEAR {
            q[i] /= self.scale();
        }
        q
    }

    fn blend_tolerance_mm(&self, cfg: &MotionConfig) -> f64 {
        match self.control {
            MotionControl::Continuous { tolerance } if tolerance > 0.0 => tolerance * self.scale(),
            MotionControl::Continuous { .. } => cfg.default_tolerance_mm,
            MotionControl::ExactPath | MotionControl::ExactStop => cfg.exact_path_tolerance_mm,
        }
    }

    /// Junction rule and merge tolerance of a move issued now.
    fn junction(&self, cfg: &MotionConfig) -> (Junction, f64) {
        match self.control {
            MotionControl::ExactStop => (Junction::ExactStop, 0.0),
            MotionControl::ExactPath => (
                Junction::Blend {
                    tolerance_mm: cfg.exact_path_tolerance_mm,
                },
                0.0,
            ),
            MotionControl::Continuous { .. } => {
                let p = self.blend_tolerance_mm(cfg);
                if self.naivecam_tol > 0.0 {
                    (
                        Junction::Blend { tolerance_mm: p },
                        self.naivecam_tol * self.scale(),
                    )
                } else {
                    let m = p * cfg.merge_fraction;
                    (
                        Junction::Blend {
                            tolerance_mm: p - m,
                        },
                        m,
                    )
                }
            }
        }
    }

    /// Path speed of a feed move of `len_mm`, mm/s (deg/s for rotary-only moves, whose F is
    /// in degrees per minute whatever the length units, as in LinuxCNC).
    fn feed_mm_s(&self, len_mm: f64, rotary_only: bool, line: u32) -> Result<f64, PlanError> {
        let scale = if rotary_only { 1.0 } else { self.scale() };
        let invalid = |what: &str| {
            Err(PlanError::Invalid {
                line,
                what: what.into(),
            })
        };
        if !(self.feed.is_finite() && self.feed > 0.0) {
            return invalid("feed move with zero or invalid feed rate (F)");
        }
        match self.feed_mode {
            FeedMode::UnitsPerMinute => Ok(self.feed * scale / 60.0),
            FeedMode::InverseTime => Ok(len_mm * self.feed / 60.0),
            FeedMode::UnitsPerRevolution => {
                if self.spindle_rpm > 0.0 {
                    Ok(self.feed * scale * self.spindle_rpm / 60.0)
                } else {
                    Err(PlanError::Unsupported {
                        line,
                        what: "G95 feed per revolution needs a spindle speed (S) or \
                               nominal_spindle_rpm in the motion config"
                            .into(),
                    })
                }
            }
        }
    }
}

fn check_finite(p: &[f64; NUM_AXES], line: u32) -> Result<(), PlanError> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(PlanError::Invalid {
            line,
            what: "non-finite coordinate".into(),
        })
    }
}

/// Folds a canonical stream starting at machine pose `start_mm`.
pub fn fold(
    canon: &[Canon],
    cfg: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<Folded, PlanError> {
    fold_from(canon, cfg, start_mm, FoldState::new(cfg))
}

/// Folds the next piece of a program interpreted in pieces: the modal state continues from
/// `state` (the previous piece's [`Folded::state`]) and the tool starts at `start_mm`
/// (where the machine actually stopped).
pub fn fold_from(
    canon: &[Canon],
    cfg: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    state: FoldState,
) -> Result<Folded, PlanError> {
    let mut st = FoldState {
        pos_mm: start_mm,
        ..state
    };
    let mut out = Folded::default();
    for c in canon {
        let line = c.loc.line;
        let aux = |kind: AuxKind| Step::Aux(AuxItem { kind, line });
        match &c.cmd {
            CanonCmd::UseLengthUnits(u) => st.units = *u,
            CanonCmd::SetG5xOffset { offset, .. } => st.g5x_mm = st.to_mm(offset),
            CanonCmd::SetG92Offset(o) => st.g92_mm = st.to_mm(o),
            CanonCmd::SetXyRotation(r) => st.rotation_deg = *r,
            CanonCmd::UseToolLengthOffset(o) => st.tool_mm = st.to_mm(o),
            CanonCmd::SelectPlane(_) | CanonCmd::Comment(_) => {}
            // Interpreter bookkeeping with no effect on motion: (PRINT,…) goes to the
            // interpreter's log, tool-table edits arrive as UseToolLengthOffset when used.
            CanonCmd::Print(_)
            | CanonCmd::PalletShuttle
            | CanonCmd::OnReset
            | CanonCmd::SetFeedReference
            | CanonCmd::Probe { .. }
            | CanonCmd::SetToolTableEntry { .. }
            | CanonCmd::Finish => {}
            CanonCmd::SetFeedRate(f) if *f != 0.0 && f.abs() < super::MIN_FEED => {
                return Err(PlanError::FeedTooSlow {
                    file: c.loc.file.to_string(),
                    line,
                    col: c.loc.col,
                    feed: *f,
                    min: super::MIN_FEED,
                });
            }
            CanonCmd::SetFeedRate(f) => st.feed = *f,
            CanonCmd::SetFeedMode(m) => st.feed_mode = *m,
            CanonCmd::SetMotionControl(m) => st.control = *m,
            CanonCmd::SetNaivecamTolerance(q) => st.naivecam_tol = q.max(0.0),
            CanonCmd::SetSpindleMode { css_max_rpm } => {
                st.css = *css_max_rpm > 0.0;
                st.css_max_rpm = *css_max_rpm;
            }
            CanonCmd::StraightFeed(p) if st.sync_pitch.is_some() => {
                check_finite(p, line)?;
                let end = st.to_machine(p);
                push_synced(&mut out, &mut st, cfg, end, false, line)?;
            }
            CanonCmd::StraightTraverse(p) | CanonCmd::StraightFeed(p) => {
                check_finite(p, line)?;
                if st.css {
                    css_speed(&mut out, &mut st, p[0], line);
                }
                let end = st.to_machine(p);
                let rapid = matches!(c.cmd, CanonCmd::StraightTraverse(_));
                push_line(&mut out, &st, cfg, end, rapid, 0, 0.0, line)?;
                st.pos_mm = end;
            }
            CanonCmd::ArcFeed {
                first_end,
                second_end,
                first_center,
                second_center,
                rotation,
                axis_end,
                plane,
                end,
            } => {
                check_finite(end, line)?;
                if st.css {
                    css_speed(&mut out, &mut st, end[0], line);
                }
                let (i1, i2, ia) = super::arcs::plane_axes(*plane);
                let mut e = *end;
                e[i1] = *first_end;
                e[i2] = *second_end;
                e[ia] = *axis_end;
                let arc = Arc {
                    start: st.to_program(&st.pos_mm),
                    end: e,
                    center_first: *first_center,
                    center_second: *second_center,
                    rotation: *rotation,
                    plane: *plane,
                };
                let tol_mm = cfg.arc_chord_tolerance_mm.min(st.blend_tolerance_mm(cfg));
                let chords = arc.chord_count(tol_mm / st.scale());
                if chords > super::arcs::MAX_ARC_CHORDS as f64 {
                    return Err(PlanError::Invalid {
                        line,
                        what: format!(
                            "arc of {} turns needs {chords:.0} chords, more than {} \
                             (split it into several arcs)",
                            rotation.unsigned_abs().max(1),
                            super::arcs::MAX_ARC_CHORDS
                        ),
                    });
                }
                let pts = arc.chord_points(tol_mm / st.scale());
                let machine: Vec<[f64; NUM_AXES]> = pts.iter().map(|p| st.to_machine(p)).collect();
                // Total arc length for inverse time: the whole arc takes 60/F.
                let total_mm = polyline_feed_length_mm(st.pos_mm, &machine);
                st.arc_id += 1;
                let feed = st.feed_mm_s(total_mm, false, line)?;
                for m in machine {
                    push_line(&mut out, &st, cfg, m, false, st.arc_id, feed, line)?;
                    st.pos_mm = m;
                }
            }
            CanonCmd::NurbsFeed {
                points,
                order,
                end,
                inverse_time,
            } => {
                check_finite(end, line)?;
                let curve =
                    super::nurbs::Nurbs::new(points, usize::from(*order)).ok_or_else(|| {
                        PlanError::Invalid {
                            line,
                            what: "spline with invalid control points".into(),
                        }
                    })?;
                let tol_mm = cfg.arc_chord_tolerance_mm.min(st.blend_tolerance_mm(cfg));
                let machine: Vec<[f64; NUM_AXES]> = curve
                    .chord_points(tol_mm / st.scale())
                    .iter()
                    .map(|p| {
                        let mut e = *end;
                        e[0] = p[0];
                        e[1] = p[1];
                        st.to_machine(&e)
                    })
                    .collect();
                let total_mm = polyline_feed_length_mm(st.pos_mm, &machine);
                st.arc_id += 1;
                let feed = match inverse_time {
                    // G93: the whole curve takes 1/F minutes.
                    Some(f) if f.is_finite() && *f > 0.0 => total_mm * f / 60.0,
                    Some(_) => {
                        return Err(PlanError::Invalid {
                            line,
                            what: "inverse time spline with zero or invalid F".into(),
                        })
                    }
                    None => st.feed_mm_s(total_mm, false, line)?,
                };
                for m in machine {
                    push_line(&mut out, &st, cfg, m, false, st.arc_id, feed, line)?;
                    st.pos_mm = m;
                }
            }
            CanonCmd::Dwell(s) => {
                if !(s.is_finite() && *s >= 0.0) {
                    return Err(PlanError::Invalid {
                        line,
                        what: "negative dwell".into(),
                    });
                }
                out.steps.push(Step::Dwell { seconds: *s, line });
            }
            CanonCmd::SetSpindleSpeed(s) if st.css => {
                st.surface = *s;
                let x = st.to_program(&st.pos_mm)[0];
                css_speed(&mut out, &mut st, x, line);
            }
            CanonCmd::SetSpindleSpeed(rpm) => {
                st.spindle_rpm = if *rpm > 0.0 {
                    *rpm
                } else {
                    cfg.nominal_spindle_rpm
                };
                out.steps.push(aux(AuxKind::SpindleSpeed { rpm: *rpm }));
            }
            CanonCmd::StartSpindle(d) => out.steps.push(aux(AuxKind::SpindleStart(*d))),
            CanonCmd::StopSpindle => out.steps.push(aux(AuxKind::SpindleStop)),
            // M19: the simulated spindle has no angular position loop; orienting stops it
            // (the interpreter counts it as stopped too), and there is nothing to wait for.
            CanonCmd::OrientSpindle { .. } => out.steps.push(aux(AuxKind::SpindleStop)),
            CanonCmd::WaitOrientComplete(_) => {}
            // Feeds locked to the spindle (G33, G76): see spindle_sync.
            CanonCmd::StartSpeedFeedSync { pitch } => st.sync_pitch = Some(*pitch),
            CanonCmd::StopSpeedFeedSync => st.sync_pitch = None,
            // Rigid tapping: in to the end point locked to the spindle, which reverses
            // there, and back out along the same helix to the start.
            CanonCmd::RigidTap { end } => {
                check_finite(end, line)?;
                let end = st.to_machine(end);
                push_synced(&mut out, &mut st, cfg, end, true, line)?;
            }
            CanonCmd::MistOn => out.steps.push(aux(AuxKind::Mist(true))),
            CanonCmd::MistOff => out.steps.push(aux(AuxKind::Mist(false))),
            CanonCmd::FloodOn => out.steps.push(aux(AuxKind::Flood(true))),
            CanonCmd::FloodOff => out.steps.push(aux(AuxKind::Flood(false))),
            CanonCmd::SelectTool(t) => out.steps.push(aux(AuxKind::SelectTool(*t))),
            CanonCmd::StartChange => out.steps.push(aux(AuxKind::StartToolChange)),
            CanonCmd::ChangeTool(t) => out.steps.push(aux(AuxKind::ChangeTool(*t))),
            CanonCmd::ChangeToolNumber(t) => out.steps.push(aux(AuxKind::ChangeToolNumber(*t))),
            CanonCmd::DigitalOutput { index, on, synced } => {
                out.steps.push(aux(AuxKind::DigitalOutput {
                    index: *index,
                    on: *on,
                    synced: *synced,
                }))
            }
            CanonCmd::AnalogOutput {
                index,
                value,
                synced,
            } => out.steps.push(aux(AuxKind::AnalogOutput {
                index: *index,
                value: *value,
                synced: *synced,
            })),
            CanonCmd::Wait {
                index,
                input,
                kind,
                timeout_s,
            } => out.steps.push(aux(AuxKind::Wait {
                index: *index,
                input: *input,
                kind: *kind,
                timeout_s: *timeout_s,
                answer: false,
            })),
            CanonCmd::StraightProbe { end, kind } => {
                // A move of its own, from rest to rest, between two barriers: the machine
                // checks the probe input before it starts (ProbeArm), the interpolator stops
                // on the input's change, and the machine reads the result at ProbeEnd.
                check_finite(end, line)?;
                let target = st.to_machine(end);
                out.steps.push(aux(AuxKind::ProbeArm { kind: *kind }));
                let saved = st.control;
                st.control = MotionControl::ExactStop;
                push_line(&mut out, &st, cfg, target, false, 0, 0.0, line)?;
                st.control = saved;
                out.steps.push(aux(AuxKind::ProbeEnd { kind: *kind }));
                st.pos_mm = target;
            }
            CanonCmd::OverrideEnable { which, on } => {
                out.steps.push(aux(AuxKind::OverrideEnable {
                    which: *which,
                    on: *on,
                }))
            }
            CanonCmd::Message(m) => {
                let id = out.messages.len() as u32;
                out.messages.push(m.clone());
                out.steps.push(aux(AuxKind::Message { id }));
            }
            CanonCmd::Log { kind, text } => {
                let id = out.messages.len() as u32;
                out.messages.push(text.clone());
                out.steps.push(aux(AuxKind::Log { id, kind: *kind }));
            }
            CanonCmd::ProgramStop => out.steps.push(aux(AuxKind::ProgramStop)),
            CanonCmd::OptionalProgramStop => out.steps.push(aux(AuxKind::OptionalProgramStop)),
            CanonCmd::ProgramEnd => out.steps.push(aux(AuxKind::ProgramEnd)),
            CanonCmd::UserMcode { code, p, q } => out.steps.push(aux(AuxKind::UserMcode {
                code: *code,
                p: *p,
                q: *q,
            })),
        }
    }
    out.end_mm = st.pos_mm;
    out.state = st;
    Ok(out)
}

/// G96: sets the spindle speed for program X `x` (a new speed item only when it changes).
fn css_speed(out: &mut Folded, st: &mut FoldState, x: f64, line: u32) {
    let rpm = super::css::rpm(st.surface, x, st.units, st.css_max_rpm);
    if rpm != st.spindle_rpm {
        st.spindle_rpm = rpm;
        out.steps.push(Step::Aux(AuxItem {
            kind: AuxKind::SpindleSpeed { rpm },
            line,
        }));
    }
}

fn blank() -> Move {
    Move {
        start_mm: [0.0; NUM_AXES],
        end_mm: [0.0; NUM_AXES],
        kind: MoveKind::Feed,
        feed_mm_s: 0.0,
        junction: Junction::ExactStop,
        merge_tol_mm: 0.0,
        arc_id: 0,
        chord_tol_mm: 0.0,
        line: 0,
    }
}

/// Appends a straight move from the current position to `end` (skipping zero-length ones).
/// `arc_feed_mm_s` > 0 gives the feed of an arc chord (computed over the whole arc).
/// Feed length of the chords from `start` through `points` (what inverse time divides by).
fn polyline_feed_length_mm(start: [f64; NUM_AXES], points: &[[f64; NUM_AXES]]) -> f64 {
    let mut prev = start;
    let mut total = 0.0;
    for m in points {
        total += Move {
            start_mm: prev,
            end_mm: *m,
            ..blank()
        }
        .feed_length_mm();
        prev = *m;
    }
    total
}

/// A spindle-synchronised move (G33 and the G76 passes; G33.1 with `tap`) from the current
/// position to `end`, between [`AuxKind::SpindleSync`] and [`AuxKind::SpindleSyncEnd`]. The
/// segments in between are planned velocity-locked to the commanded spindle speed (pitch ×
/// rpm, from rest to rest; G33.1 in and back out): what a trace shows, and what a machine
/// without a spindle position would run. A machine with one follows the measured spindle
/// position instead (`motion::spindle_lock`).
fn push_synced(
    out: &mut Folded,
    st: &mut FoldState,
    cfg: &MotionConfig,
    end: [f64; NUM_AXES],
    tap: bool,
    line: u32,
) -> Result<(), PlanError> {
    let pitch = st.sync_pitch.unwrap_or(0.0);
    let feed = super::spindle_sync::feed_mm_s(pitch, st.scale(), st.spindle_rpm, st.css, line)?;
    let start = st.pos_mm;
    let sync = AuxKind::SpindleSync {
        end_mm: end,
        pitch_mm: pitch * st.scale(),
        tap,
    };
    out.steps.push(Step::Aux(AuxItem { kind: sync, line }));
    let saved = st.control;
    st.control = MotionControl::ExactStop;
    push_line(out, st, cfg, end, false, 0, feed, line)?;
    st.pos_mm = end;
    if tap {
        push_line(out, st, cfg, start, false, 0, feed, line)?;
        st.pos_mm = start;
    }
    st.control = saved;
    out.steps.push(Step::Aux(AuxItem {
        kind: AuxKind::SpindleSyncEnd,
        line,
    }));
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn push_line(
    out: &mut Folded,
    st: &FoldState,
    cfg: &MotionConfig,
    end: [f64; NUM_AXES],
    rapid: bool,
    arc_id: u32,
    arc_feed_mm_s: f64,
    line: u32,
) -> Result<(), PlanError> {
    let (junction, merge_tol_mm) = st.junction(cfg);
    let mut mv = Move {
        start_mm: st.pos_mm,
        end_mm: end,
        kind: if rapid {
            MoveKind::Rapid
        } else {
            MoveKind::Feed
        },
        feed_mm_s: f64::INFINITY,
        junction,
        merge_tol_mm: if rapid { 0.0 } else { merge_tol_mm },
        arc_id,
        chord_tol_mm: 0.0,
        line,
    };
    let len = mv.feed_length_mm();
    if len <= 1e-9 {
        return Ok(());
    }
    if !rapid {
        mv.feed_mm_s = if arc_feed_mm_s > 0.0 {
            arc_feed_mm_s
        } else {
            let rotary_only = LINEAR.iter().all(|&i| mv.end_mm[i] == mv.start_mm[i]);
            st.feed_mm_s(len, rotary_only, line)?
        };
    }
    if arc_id != 0 {
        // Chords of one arc blend into each other within the chord tolerance.
        mv.chord_tol_mm = cfg.arc_chord_tolerance_mm.min(st.blend_tolerance_mm(cfg));
    }
    out.steps.push(Step::Move(mv));
    Ok(())
}
