//! Jobs that probe (G38.2–G38.5) run piece by piece: the machine side of
//! [`gcode::Session`](crate::gcode::Session).
//!
//! The job is validated as a whole first (interpreted with simulated probes and planned in
//! full, as every job is). When it runs, the program is interpreted again, live: the first
//! piece (up to and including the first probe line) is planned from the machine's position
//! and queued like any job. The machine task stops at the end of the probe move (a barrier)
//! and publishes the result in its snapshot; the [`PieceRunner`] thread converts it into
//! program coordinates with the offsets in effect, lets the interpreter continue, plans the
//! next piece from where the machine actually stopped, queues it and tells the machine
//! task to continue. Everything but the probe itself is off the realtime path; the probe
//! input is checked inside the servo cycle by the interpolator.
//!
//! M66 works the same way (issue 11; LinuxCNC's M66 is a queue buster too): the session
//! ends a piece at every M66 (`Session::live_waits`), the runner marks that piece's last
//! wait item with `answer`, the machine waits for the input (or the timeout, in servo
//! cycles), publishes the value read (-1 on a timeout) and holds; the runner hands it to
//! the interpreter as #5399 and queues the next piece, which may branch on it.
//!
//! An error that only shows with the measured values (say a probed Z that sends the next
//! move past a soft limit) ends the job with the error's file, line and column; the
//! machine is standing still at the probe when it is found.

use super::api::ApiError;
use super::servo::machine_task::MachineCmd;
use super::servo::{MachineSnapshot, QueueItem};
use crate::gcode::{InterpOptions, PieceEnd, ProbeResult, Session, NUM_AXES};
use crate::motion::from_canon::FoldState;
use crate::motion::AuxKind;
use crate::motion::{self, Item, MotionConfig, Plan};
use crate::rt::prelude::{BufferWriter, CommandStatus, DataReader, TaskHandle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// What a probing job needs to be interpreted again when it runs.
#[derive(Debug, Clone)]
pub struct ProbingSource {
    /// Name used in locations and errors.
    pub name: String,
    /// The program text that was validated (not re-read from disk).
    pub text: String,
    /// Interpreter options (subroutine path, program directory, MDI mode).
    pub opts: InterpOptions,
}

/// The first piece of a probing job, planned from `start_mm`, and the session to go on.
pub struct FirstPiece {
    /// The live interpreter.
    pub session: Session,
    /// The first piece's plan.
    pub plan: Plan,
    /// Whether a probe or an M66 ends it (otherwise the program has none after all).
    pub more: bool,
    /// What ends it.
    pub end: PieceEnd,
}

/// Marks the M66 that ends a piece (its last wait item) so that the machine publishes what
/// it reads and holds for the next piece; the waits before it in the piece (none: every
/// M66 ends a piece) stay as they are.
fn mark_answer(plan: &mut Plan, end: &PieceEnd) {
    if !matches!(end, PieceEnd::Wait { .. }) {
        return;
    }
    let last = plan.items.iter_mut().rev().find_map(|i| match i {
        Item::Aux(a) => match &mut a.kind {
            AuxKind::Wait { answer, .. } => Some(answer),
            _ => None,
        },
        Item::Segment(_) => None,
    });
    if let Some(answer) = last {
        *answer = true;
    }
}

/// Where a piece stopped, as the machine published it.
enum Stop {
    /// The probe move's result.
    Probe(super::servo::ProbeSnapshot),
    /// The M66's: what #5399 gets, and where the machine stands.
    Wait(f64, [f64; NUM_AXES]),
}

/// Opens the live session and plans the first piece.
pub fn first_piece(
    src: &ProbingSource,
    cfg: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<FirstPiece, ApiError> {
    let mut opts = src.opts.clone();
    let mut p = [0.0; 6];
    p.copy_from_slice(&start_mm[..6]);
    opts.initial_position = Some(p);
    let gcode = |e: crate::gcode::GcodeError| ApiError::Gcode(e.to_string());
    let mut session = Session::open_str(&src.name, &src.text, &opts).map_err(gcode)?;
    session.live_waits(true);
    let (canon, end) = session.next_piece().map_err(gcode)?;
    let mut plan = motion::plan_continue(&canon, cfg, start_mm, FoldState::new(cfg))
        .map_err(|e| ApiError::Gcode(format!("{}: {e}", src.name)))?;
    mark_answer(&mut plan, &end);
    Ok(FirstPiece {
        session,
        plan,
        more: end != PieceEnd::End,
        end,
    })
}

/// The thread that feeds a probing job, piece by piece.
pub struct PieceRunner {
    /// The segment queue.
    pub queue: BufferWriter<QueueItem>,
    /// The machine task.
    pub machine: TaskHandle<MachineCmd>,
    /// The machine task's snapshot (probe results).
    pub snapshot: DataReader<MachineSnapshot>,
    /// Planner configuration.
    pub cfg: MotionConfig,
    /// Job id.
    pub job: u32,
    /// Program name, for errors.
    pub name: String,
    /// Set when the job has ended (or is replaced): the runner stops.
    pub cancel: Arc<AtomicBool>,
    /// Probe results already seen before this job started.
    pub seen_probe_seq: u32,
    /// The servo thread, whose cycles pace the feeder's waits for room in the queue.
    pub servo: Arc<crate::rt::activity::ThreadInfo>,
    /// The job's `(MSG, …)` texts: each piece's are appended, and the message ids of its
    /// queue items shifted to match (each piece's plan numbers its own from 0).
    pub messages: Arc<Mutex<Vec<String>>>,
    /// The persistent parameters as the live run leaves them, set once the last piece is
    /// interpreted (before it is queued, so before the job can end "done"): the var file is
    /// saved from these, not from the dry run's simulated probes (issue 13).
    pub parameters: Arc<Mutex<Option<crate::gcode::VarFile>>>,
    /// Tells the job's starter when the first piece is queued.
    pub(crate) primer: super::feeder::Primer,
}

/// Appends a piece's message and log texts to the job's and renumbers the piece's items
/// that carry one.
pub fn append_messages(plan: &mut Plan, messages: &Mutex<Vec<String>>) {
    let mut all = messages.lock().unwrap_or_else(|p| p.into_inner());
    let offset = all.len() as u32;
    all.extend(plan.messages.iter().cloned());
    for item in &mut plan.items {
        if let Item::Aux(a) = item {
            if let Some(id) = a.kind.text_id_mut() {
                *id += offset;
            }
        }
    }
}

/// How a runner ended, for the job book.
#[derive(Debug, Clone, PartialEq)]
pub enum RunnerEnd {
    /// Every piece was queued (or the job was cancelled).
    Done,
    /// A later piece could not be interpreted or planned: the job must fail with this text.
    Failed(String),
}

impl PieceRunner {
    /// Queues the first piece, then waits for each probe result or M66 answer and queues the
    /// next piece, until the program ends, the job is cancelled, or a piece fails.
    pub fn run(mut self, first: FirstPiece) -> RunnerEnd {
        let FirstPiece {
            mut session,
            plan,
            more,
            mut end,
        } = first;
        if !more {
            self.keep_parameters(&session);
        }
        if !self.feed(&plan.items) || !more {
            return RunnerEnd::Done;
        }
        let mut plan = plan;
        let mut seen_wait_seq = None;
        loop {
            let Some(stop) = self.wait_for_stop(&end, &mut seen_wait_seq) else {
                return RunnerEnd::Done;
            };
            let state = plan.end_state.clone();
            let start_mm = match stop {
                Stop::Probe(p) => {
                    session.probe_result(&ProbeResult {
                        tripped: p.tripped,
                        probed: state.program_xyzabc(&p.probed_mm),
                        stopped: state.program_xyzabc(&p.stopped_mm),
                    });
                    p.stopped_mm
                }
                Stop::Wait(value, stopped_mm) => {
                    session.wait_result(value);
                    stopped_mm
                }
            };
            let canon;
            (canon, end) = match session.next_piece() {
                Ok(piece) => piece,
                Err(e) => return RunnerEnd::Failed(e.to_string()),
            };
            plan = match motion::plan_continue(&canon, &self.cfg, start_mm, state) {
                Ok(plan) => plan,
                Err(e) => return RunnerEnd::Failed(format!("{}: {e}", self.name)),
            };
            mark_answer(&mut plan, &end);
            append_messages(&mut plan, &self.messages);
            if end == PieceEnd::End {
                self.keep_parameters(&session);
            }
            // Queue what fits, release the machine, then queue the rest as it drains: the
            // interpolator consumes nothing until `continue`, so a piece longer than the
            // queue would otherwise never fit.
            let first = self.push_available(&plan.items);
            let h = self.machine.send(MachineCmd::Continue {
                job: self.job,
                items: plan.items.len() as u64,
            });
            let accepted = h.is_ok_and(|h| {
                matches!(
                    h.wait_accepted(Duration::from_secs(2)),
                    CommandStatus::Accepted | CommandStatus::Done
                )
            });
            if !accepted || !self.feed(&plan.items[first..]) || end == PieceEnd::End {
                return RunnerEnd::Done;
            }
        }
    }

    /// Records the parameters of a session that has interpreted its last piece.
    fn keep_parameters(&self, session: &Session) {
        *self.parameters.lock().unwrap_or_else(|p| p.into_inner()) = Some(session.parameters());
    }

    /// Waits until the machine publishes the end of this job's piece that ended with `end`:
    /// the result of its probe, or the answer to its M66 (one not seen before: `seen_wait`
    /// is the last one taken); `None` when the job was cancelled first.
    fn wait_for_stop(&mut self, end: &PieceEnd, seen_wait: &mut Option<u32>) -> Option<Stop> {
        let probe = matches!(end, PieceEnd::Probe { .. });
        loop {
            if self.cancel.load(Ordering::Acquire) {
                return None;
            }
            if let Some(s) = self.snapshot.latest() {
                let (p, w) = (s.probe, s.wait);
                if probe && p.seq != self.seen_probe_seq && p.job == self.job && p.waiting {
                    self.seen_probe_seq = p.seq;
                    return Some(Stop::Probe(p));
                }
                if !probe && *seen_wait != Some(w.seq) && w.job == self.job && w.waiting {
                    *seen_wait = Some(w.seq);
                    return Some(Stop::Wait(w.value, w.stopped_mm));
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Pushes items while the queue has room; returns how many went in.
    fn push_available(&self, items: &[Item]) -> usize {
        for (n, &item) in items.iter().enumerate() {
            if self
                .queue
                .try_push(QueueItem {
                    job: self.job,
                    item,
                })
                .is_err()
            {
                return n;
            }
        }
        items.len()
    }

    /// Pushes every item, waiting while the queue is full; false if cancelled.
    fn feed(&self, items: &[Item]) -> bool {
        super::feeder::feed(
            &self.queue,
            items,
            self.job,
            &self.cancel,
            &self.servo,
            &self.primer,
        )
    }
}

/// Refuses a job whose first move is a probe move that cannot start: G38.2/G38.3 with the
/// probe already tripped, G38.4/G38.5 with it not tripped (`probe_active`: the probe input
/// as the last servo cycle saw it; `None` on a machine without one, which the piece runner
/// refuses with its own message). The machine task checks the same rule again in the cycle
/// the move arms; checking it here as well makes the reply to an MDI probe against a
/// touching stylus an error every time, instead of an acceptance or a failure depending on
/// which servo cycle the call's wait ends in.
pub fn check_probe_start(
    job: &super::job::PreparedJob,
    probe_active: Option<bool>,
) -> Result<(), ApiError> {
    use super::servo::JobError;
    let Some(active) = probe_active else {
        return Ok(());
    };
    let first = job.plan.items.iter().find_map(|i| match i {
        Item::Segment(_) => Some(None),
        Item::Aux(a) => match a.kind {
            AuxKind::ProbeArm { kind } => Some(Some((kind, a.line))),
            _ => None,
        },
    });
    let Some(Some((kind, line))) = first else {
        return Ok(());
    };
    let error = match (kind.toward(), active) {
        (true, true) => JobError::ProbeAlreadyTripped(kind),
        (false, false) => JobError::ProbeNotTripped(kind),
        _ => return Ok(()),
    };
    Err(ApiError::Rejected(format!(
        "{}: line {line}: {error}",
        job.name
    )))
}
