//! Streaming planning: canonical commands in, in pieces of any size; segment-queue items out,
//! in program order, with memory bounded whatever the length of the program.
//!
//! This is the planner: [`super::plan_continue`] is a [`PlanStream`] fed the whole stream
//! at once and collecting the items. Each piece is folded (the modal state carries over),
//! every move in it is checked against the soft limits and the kinematics, and the moves go
//! through the [`Lookahead`] (which plans a long run in bounded chunks). The override caps
//! need what follows a segment: items are held until `2 × CAP_CHUNK` are waiting, then the
//! first `CAP_CHUNK` are finalised with the rest as their horizon
//! ([`limits::propagate_override_caps_open`]); at the end everything left is finalised as one
//! queue. A program whose queue has fewer than `2 × CAP_CHUNK` items and no run longer than a
//! lookahead chunk is therefore planned exactly as a whole.
//!
//! The planner is deterministic: the same commands from the same start under the same
//! configuration give the same items, bit for bit, however they are cut into pieces when
//! they are pushed at the lookahead's and the cap stage's boundaries (both count items and
//! moves, not pushes). A job relies on that to plan once to validate and again while it runs.

use super::from_canon::{self, FoldState};
use super::kinematics::{self, Kinematics};
use super::limits::{self, Limits};
use super::lookahead::Lookahead;
use super::moves::Step;
use super::segment::Item;
use super::{KinematicsConfig, MotionConfig, Plan, PlanError};
use crate::gcode::{Canon, NUM_AXES};
use std::collections::BTreeSet;

/// Items finalised at once by the override-cap stage (see the module doc).
pub const CAP_CHUNK: usize = 16_384;

/// A planner fed in pieces.
pub struct PlanStream {
    cfg: MotionConfig,
    kin: kinematics::Machine,
    start_mm: [f64; NUM_AXES],
    pos_mm: [f64; NUM_AXES],
    state: FoldState,
    la: Lookahead,
    /// Lookahead output (scratch).
    fresh: Vec<Item>,
    /// Items waiting for their override caps.
    pending: Vec<Item>,
    messages: Vec<String>,
    duration_s: f64,
    distance_mm: f64,
    segment_count: usize,
    item_count: u64,
    lines: BTreeSet<u32>,
}

/// What a finished stream planned: the plan without its items (they went to the sink) and
/// how many there were.
#[derive(Debug, Clone)]
pub struct Finished {
    /// Messages, poses, duration, distance, counts and end state; `items` is empty.
    pub plan: Plan,
    /// Items handed to the sink.
    pub items: u64,
}

impl PlanStream {
    /// A planner starting at machine pose `start_mm` with the modal state `state`
    /// ([`FoldState::new`] for a program, a previous piece's end state for a probing job).
    pub fn new(
        cfg: &MotionConfig,
        start_mm: [f64; NUM_AXES],
        state: FoldState,
    ) -> Result<Self, PlanError> {
        cfg.validate()?;
        let lim = Limits::new(cfg);
        Ok(PlanStream {
            cfg: cfg.clone(),
            kin: kinematics::Machine::new(&cfg.kinematics),
            start_mm,
            pos_mm: start_mm,
            state,
            la: Lookahead::new(&lim, cfg.lookahead_moves, start_mm),
            fresh: Vec::new(),
            pending: Vec::new(),
            messages: Vec::new(),
            duration_s: 0.0,
            distance_mm: 0.0,
            segment_count: 0,
            item_count: 0,
            lines: BTreeSet::new(),
        })
    }

    /// Plans the next piece of the canonical stream; finalised items go to `sink` in order.
    pub fn push(
        &mut self,
        canon: &[Canon],
        sink: &mut dyn FnMut(&[Item]),
    ) -> Result<(), PlanError> {
        let folded = from_canon::fold_from(
            canon,
            &self.cfg,
            self.pos_mm,
            std::mem::take(&mut self.state),
        )?;
        self.pos_mm = folded.end_mm;
        self.state = folded.state;
        let offset = self.messages.len() as u32;
        self.messages.extend(folded.messages);
        for step in &folded.steps {
            if let Step::Move(m) = step {
                limits::check_soft_limits(&m.end_mm, m.line, &self.cfg)?;
                self.kin
                    .inverse(&m.end_mm)
                    .map_err(|source| PlanError::Kinematics {
                        line: m.line,
                        source,
                    })?;
            }
        }
        for mut step in folded.steps {
            if let Step::Aux(a) = &mut step {
                if let Some(id) = a.kind.text_id_mut() {
                    *id += offset;
                }
            }
            self.la.push(step, &mut self.fresh)?;
            self.drain(sink)?;
        }
        Ok(())
    }

    /// Plans the rest (the end of the program is a stop) and returns the plan's summary.
    pub fn finish(mut self, sink: &mut dyn FnMut(&[Item])) -> Result<Finished, PlanError> {
        self.la.flush(&mut self.fresh)?;
        self.pending.append(&mut self.fresh);
        let mut last = std::mem::take(&mut self.pending);
        limits::propagate_override_caps_open(&mut last, &self.cfg, false);
        self.emit(&last, sink)?;
        Ok(Finished {
            plan: Plan {
                items: Vec::new(),
                messages: self.messages,
                start_mm: self.start_mm,
                end_mm: self.pos_mm,
                duration_s: self.duration_s,
                distance_mm: self.distance_mm,
                line_count: self.lines.len(),
                segment_count: self.segment_count,
                end_state: self.state,
            },
            items: self.item_count,
        })
    }

    /// Moves lookahead output on to the cap stage and finalises what has enough horizon.
    fn drain(&mut self, sink: &mut dyn FnMut(&[Item])) -> Result<(), PlanError> {
        if self.fresh.is_empty() {
            return Ok(());
        }
        self.pending.append(&mut self.fresh);
        while self.pending.len() >= 2 * CAP_CHUNK {
            let mut stretch = self.pending.clone();
            limits::propagate_override_caps_open(&mut stretch, &self.cfg, true);
            self.emit(&stretch[..CAP_CHUNK], sink)?;
            self.pending.drain(..CAP_CHUNK);
        }
        Ok(())
    }

    /// Checks and counts finalised items, then hands them to the sink.
    fn emit(&mut self, items: &[Item], sink: &mut dyn FnMut(&[Item])) -> Result<(), PlanError> {
        for it in items {
            match it {
                Item::Segment(s) => {
                    self.duration_s += s.duration_s;
                    self.distance_mm += s.length_mm;
                    self.segment_count += 1;
                    self.lines.insert(s.line);
                    if let KinematicsConfig::Scara(sc) = &self.cfg.kinematics {
                        // Reach, joint limits and joint speeds along the way (blends and arcs
                        // leave the chords; joint speeds grow near full extension).
                        kinematics::check_segment(
                            &self.kin,
                            s,
                            &sc.joint_max_vel,
                            self.cfg.servo_period_s,
                        )
                        .map_err(|source| PlanError::Kinematics {
                            line: s.line,
                            source,
                        })?;
                    }
                }
                Item::Aux(a) => {
                    self.lines.insert(a.line);
                }
            }
        }
        self.item_count += items.len() as u64;
        if !items.is_empty() {
            sink(items);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::{CanonCmd, SourceLoc};
    use crate::motion::lookahead::CHUNK_MOVES;
    use crate::motion::Segment;

    /// A zig-zag of `n` short G1 moves in one G64 run (longer than a lookahead chunk).
    fn zigzag(n: usize) -> Vec<Canon> {
        let loc = |line| SourceLoc {
            file: "z.ngc".into(),
            line,
            col: 1,
        };
        let mut c = vec![Canon {
            loc: loc(1),
            cmd: CanonCmd::SetFeedRate(3000.0),
        }];
        for i in 0..n {
            let mut p = [0.0; NUM_AXES];
            p[0] = 10.0 + (i % 500) as f64 * 0.2;
            p[1] = 10.0 + (i / 500) as f64 * 0.3;
            p[2] = -1.0 - 0.4 * ((i % 7) as f64);
            c.push(Canon {
                loc: loc(i as u32 + 2),
                cmd: CanonCmd::StraightFeed(p),
            });
        }
        c
    }

    fn plan_in_pieces(canon: &[Canon], piece: usize, cfg: &MotionConfig) -> (Vec<Item>, Plan) {
        let start = [10.0, 10.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut items = Vec::new();
        let mut sink = |c: &[Item]| items.extend_from_slice(c);
        let mut s = PlanStream::new(cfg, start, FoldState::new(cfg)).unwrap();
        for c in canon.chunks(piece) {
            s.push(c, &mut sink).unwrap();
        }
        let f = s.finish(&mut sink).unwrap();
        assert_eq!(f.items, items.len() as u64);
        (items, f.plan)
    }

    fn segments(items: &[Item]) -> Vec<&Segment> {
        items
            .iter()
            .filter_map(|i| match i {
                Item::Segment(s) => Some(s),
                Item::Aux(_) => None,
            })
            .collect()
    }

    /// A dwell before the first move stands where the machine is, not at pose 0 (a dwell at 0
    /// from a machine elsewhere was a step of the setpoint and tripped the following-error
    /// limit).
    #[test]
    fn a_dwell_before_any_move_stands_at_the_start_pose() {
        let cfg = MotionConfig::default();
        let loc = SourceLoc {
            file: "d.ngc".into(),
            line: 1,
            col: 1,
        };
        let canon = [Canon {
            loc,
            cmd: CanonCmd::Dwell(0.5),
        }];
        let (items, _) = plan_in_pieces(&canon, 1, &cfg);
        let segs = segments(&items);
        assert_eq!(segs.len(), 1);
        let start = [10.0, 10.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(segs[0].start_mm, start);
        assert_eq!(segs[0].end_mm, start);
    }

    #[test]
    fn a_run_longer_than_a_chunk_is_continuous_and_within_the_limits() {
        let cfg = MotionConfig::default();
        let n = 2 * CHUNK_MOVES + 1000;
        let canon = zigzag(n);
        let (items, plan) = plan_in_pieces(&canon, canon.len(), &cfg);
        let segs = segments(&items);
        assert!(segs.len() > 2 * CAP_CHUNK, "{}", segs.len());
        for w in segs.windows(2) {
            let (a, b) = (w[0], w[1]);
            for i in 0..NUM_AXES {
                assert!(
                    (a.end_mm[i] - b.start_mm[i]).abs() < 1e-9,
                    "pose jumps at line {}",
                    b.line
                );
                assert!(
                    (a.v1_mm_s[i] - b.v0_mm_s[i]).abs() < 1e-6,
                    "velocity jumps at line {}",
                    b.line
                );
            }
        }
        let lim = Limits::new(&cfg);
        for s in &segs {
            assert!(s.override_cap >= 1.0 && s.end_override_cap >= 1.0);
            for (i, [v, a, j]) in s.peaks().into_iter().enumerate() {
                assert!(v <= lim.vel[i] * (1.0 + 1e-9), "v {v} line {}", s.line);
                // An arc's normal acceleration is planned against the full limit.
                let acc = if s.curvature_per_mm != 0.0 {
                    lim.acc_full[i]
                } else {
                    lim.acc[i]
                };
                assert!(a <= acc * (1.0 + 1e-6), "a {a} line {}", s.line);
                assert!(j <= lim.jerk[i] * (1.0 + 1e-6), "j {j} line {}", s.line);
            }
        }
        // It never stops in the middle of the run (a chunk boundary is not a stop).
        let stops = segs
            .windows(2)
            .filter(|w| w[0].v1_mm_s.iter().all(|v| *v == 0.0))
            .count();
        assert_eq!(stops, 0);
        assert!((plan.end_mm[1] - (10.0 + ((n - 1) / 500) as f64 * 0.3)).abs() < 1e-9);
    }

    #[test]
    fn how_the_commands_are_cut_does_not_change_the_plan() {
        let cfg = MotionConfig::default();
        let canon = zigzag(CHUNK_MOVES + 3000);
        let (whole, p1) = plan_in_pieces(&canon, canon.len(), &cfg);
        let (pieces, p2) = plan_in_pieces(&canon, 777, &cfg);
        assert_eq!(whole, pieces);
        assert_eq!(p1, p2);
        // And a short program is planned as a whole queue: same as `plan_from`.
        let short = &canon[..2000];
        let (items, _) = plan_in_pieces(short, 100, &cfg);
        let start = [10.0, 10.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(
            items,
            crate::motion::plan_from(short, &cfg, start).unwrap().items
        );
    }
}
