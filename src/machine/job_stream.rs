//! A job interpreted and planned as a stream, a chunk of commands at a time: the validating
//! pass of every job, and the [`Replay`] that plans a large job again while it runs, checked
//! batch by batch against the validating pass' digests (the memory design is in
//! [`super::job`]'s module doc).

use super::job::first_piece_end;
use crate::gcode::{self, InterpOptions, NUM_AXES};
use crate::machine::api::ApiError;
use crate::motion::stream::{Finished, PlanStream};
use crate::motion::{self, Item, MotionConfig};
use std::hash::Hasher;

/// Commands interpreted at a time by the streaming passes.
const CANON_CHUNK: usize = 4_096;

/// What a large job keeps to be planned again while it runs (see the module doc).
#[derive(Clone)]
pub struct Replay {
    pub(super) name: String,
    pub(super) text: String,
    pub(super) opts: InterpOptions,
    pub(super) motion: MotionConfig,
    pub(super) start_mm: [f64; NUM_AXES],
    /// Items the validating pass produced.
    pub items: u64,
    /// Digest of each batch of items the validating pass produced, in order.
    pub(super) digests: Vec<u64>,
}

impl std::fmt::Debug for Replay {
    /// Without the text (megabytes).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replay")
            .field("name", &self.name)
            .field("text_bytes", &self.text.len())
            .field("items", &self.items)
            .field("batches", &self.digests.len())
            .finish()
    }
}

impl Replay {
    /// Plans the job again and hands each batch of items to `push` once it is checked against
    /// the validated plan. `push` returns false to stop (job cancelled): then `Ok(false)`.
    /// An error (a batch that differs from the validated one, or that no longer plans) comes
    /// before that batch is handed over.
    pub fn run(&self, push: &mut dyn FnMut(&[Item]) -> bool) -> Result<bool, String> {
        let mut n = 0;
        let mut differs = false;
        let out = stream_pass(
            &self.name,
            self.text.clone(),
            &self.opts,
            &self.motion,
            self.start_mm,
            &mut |items| {
                if self.digests.get(n) != Some(&digest(items)) {
                    differs = true;
                    return false;
                }
                n += 1;
                push(items)
            },
        );
        let changed = || {
            format!(
                "{}: the job planned differently while it ran than when it was loaded \
                 (batch {n}; a subroutine or tool table file changed?): stopped",
                self.name
            )
        };
        match out {
            Err(e) => Err(e.to_string()),
            Ok(_) if differs => Err(changed()),
            Ok(Streamed::Stopped) => Ok(false),
            Ok(Streamed::Planned(..)) if n == self.digests.len() => Ok(true),
            Ok(_) => Err(changed()),
        }
    }
}

impl Replay {
    /// [`Replay::run`] with the planning on a thread of its own, up to two batches ahead of
    /// `push`: the queue is refilled from a planned batch while the next one is planned, so
    /// a job whose segments run faster than one batch is planned never starves the
    /// interpolator (an underrun at speed is an abrupt stop).
    pub fn run_ahead(&self, push: &mut dyn FnMut(&[Item]) -> bool) -> Result<bool, String> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<Item>>(2);
        std::thread::scope(|scope| {
            let planner = std::thread::Builder::new()
                .name("job-replay".into())
                .spawn_scoped(scope, move || {
                    self.run(&mut |batch| tx.send(batch.to_vec()).is_ok())
                })
                .map_err(|e| format!("cannot start the job's planner: {e}"))?;
            let mut pushed_all = true;
            for batch in rx.iter() {
                if !push(&batch) {
                    pushed_all = false;
                    break;
                }
            }
            // A planner blocked on a full channel sees it closed and stops.
            drop(rx);
            let planned = planner
                .join()
                .unwrap_or_else(|_| Err(format!("{}: the job's planner panicked", self.name)));
            match planned {
                Ok(_) if !pushed_all => Ok(false),
                other => other,
            }
        })
    }
}

/// How a streaming pass ended.
pub(super) enum Streamed {
    /// Planned to the end: the summary, the number of commands and the persistent
    /// parameters the program leaves.
    Planned(Box<Finished>, usize, Box<gcode::VarFile>),
    /// The program probes or waits for an input: it must be prepared whole.
    Probes,
    /// The batch consumer asked to stop.
    Stopped,
}

/// Interprets and plans `text` a chunk at a time, handing each finalised batch of items to
/// `batch` (which returns false to stop).
pub(super) fn stream_pass(
    name: &str,
    text: String,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    batch: &mut dyn FnMut(&[Item]) -> bool,
) -> Result<Streamed, ApiError> {
    let gcode = |e: gcode::GcodeError| ApiError::Gcode(e.to_string());
    let refuse = |e: motion::PlanError| ApiError::Gcode(format!("{name}: {e}"));
    let mut run = gcode::Chunked::open_str(name, text, opts, CANON_CHUNK).map_err(gcode)?;
    let mut planner = PlanStream::new(motion, start_mm, motion::from_canon::FoldState::new(motion))
        .map_err(refuse)?;
    let stopped = std::cell::Cell::new(false);
    let mut sink = |items: &[Item]| {
        if !stopped.get() {
            stopped.set(!batch(items));
        }
    };
    let (mut chunk, mut commands) = (Vec::new(), 0);
    loop {
        let more = run.next_chunk(&mut chunk).map_err(gcode)?;
        if first_piece_end(&chunk).is_some() {
            return Ok(Streamed::Probes);
        }
        commands += chunk.len();
        planner.push(&chunk, &mut sink).map_err(refuse)?;
        if opts
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
        {
            return Err(ApiError::Failed(format!("{name}: preparation cancelled")));
        }
        if stopped.get() {
            return Ok(Streamed::Stopped);
        }
        if !more {
            break;
        }
    }
    drop(chunk);
    let vars = Box::new(run.parameters());
    drop(run);
    let finished = planner.finish(&mut sink).map_err(refuse)?;
    Ok(if stopped.get() {
        Streamed::Stopped
    } else {
        Streamed::Planned(Box::new(finished), commands, vars)
    })
}

/// A digest of a batch of items (the bits of every field).
pub(super) fn digest(items: &[Item]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for it in items {
        match it {
            Item::Segment(s) => {
                let arrays = [&s.start_mm, &s.end_mm, &s.v0_mm_s, &s.v1_mm_s];
                for v in arrays.into_iter().flatten() {
                    h.write_u64(v.to_bits());
                }
                for v in [
                    s.duration_s,
                    s.jerk_s,
                    s.length_mm,
                    s.move_rest_mm,
                    s.override_cap,
                    s.end_override_cap,
                    s.scale_rate_max,
                    s.end_scale_rate_max,
                    s.scale_jerk_max,
                    s.brake_scale_jerk_max,
                    s.next_scale_jerk_max,
                    s.curvature_per_mm,
                    s.heading_rad,
                    s.step_jerk_mm_s3,
                    s.window.offset_s,
                    s.window.full_s,
                    s.window.dv_mm_s,
                ] {
                    h.write_u64(v.to_bits());
                }
                h.write_u32(s.line);
                std::hash::Hash::hash(&s.line_marks, &mut h);
                h.write_u8(s.kind as u8);
            }
            // Rare: the debug text names every field (f64 in its shortest exact form).
            Item::Aux(a) => h.write(format!("{a:?}").as_bytes()),
        }
    }
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::line_marks::LineMarks;

    /// The digest covers every field a replayed batch could differ in, the line marks of
    /// fitted arcs included (they set the line the machine reports).
    #[test]
    fn the_digest_sees_every_field_of_a_segment() {
        let cfg = MotionConfig::default();
        let loc = crate::gcode::SourceLoc {
            file: std::sync::Arc::from("t"),
            line: 1,
            col: 1,
        };
        let mut end = [0.0; NUM_AXES];
        end[0] = 10.0;
        let plan = motion::plan_straight_feed([0.0; NUM_AXES], end, 600.0, loc, &cfg).unwrap();
        let items = plan.items;
        let Some(i) = items.iter().position(|it| matches!(it, Item::Segment(_))) else {
            panic!("no segment in {items:?}");
        };
        let mut marked = items.clone();
        if let Item::Segment(s) = &mut marked[i] {
            s.line_marks = LineMarks::new(&[0.5]).unwrap();
        }
        assert_ne!(digest(&items), digest(&marked));
        let mut other_line = items.clone();
        if let Item::Segment(s) = &mut other_line[i] {
            s.line += 1;
        }
        assert_ne!(digest(&items), digest(&other_line));
        assert_eq!(digest(&items), digest(&items.clone()));
    }
}
