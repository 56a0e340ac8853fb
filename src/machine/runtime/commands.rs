//! How the operator side drives the machine task: commands with an accept timeout, waiting for
//! a cycle, starting a job and its feeder (or the piece runner of a probing job). Why apart from the
//! API: these are the mechanisms every [`MachineApi`] call shares.

use super::{axis_letter, lock, ActiveJob, Machine, Measured, ACCEPT_TIMEOUT};
use crate::gcode::NUM_AXES;
use crate::machine::api::*;
use crate::machine::feeder::{feed, PrimeNews, Primer};
use crate::machine::job;
use crate::machine::job::PreparedJob;
use crate::machine::mode::{ModeMachine, Request};
use crate::machine::probing;
use crate::machine::servo::machine_task::MachineCmd;
use crate::machine::servo::status::StatusSnapshot;
use crate::machine::servo::{ports, MachineSnapshot};
use crate::rt::prelude::{CommandHandle, CommandStatus};
use serde_json::Value;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Longest wait for a job's feeder to prime the queue before the job starts anyway (the
/// interpolator then waits at rest for its first items; only a move cut short is harmful).
/// A guard for a stalled host: priming takes microseconds, or one batch of planning.
const PRIME_TIMEOUT: Duration = Duration::from_secs(10);

impl Machine {
    /// Sends a command and waits until the machine task accepted or rejected it.
    pub(super) fn command(&self, cmd: MachineCmd) -> Result<CommandHandle, ApiError> {
        let h = self
            .machine
            .send(cmd)
            .map_err(|e| ApiError::Rejected(e.to_string()))?;
        let status = h.wait_accepted(ACCEPT_TIMEOUT);
        self.wait_for_cycle_end();
        match status {
            CommandStatus::Rejected(r) => Err(ApiError::Rejected(r.to_string())),
            CommandStatus::Failed(why) => Err(ApiError::Failed(why.into())),
            CommandStatus::Pending => Err(ApiError::Timeout(
                "the machine task did not take the command".into(),
            )),
            _ => Ok(h),
        }
    }

    /// Waits until the servo cycle running now has finished (the next one has started). A
    /// command is accepted in the middle of a cycle and the machine task publishes its state
    /// at the end of it: waiting makes a command's effect visible in `status` by the time
    /// the operator's call returns. At most one servo period.
    pub(super) fn wait_for_cycle_end(&self) {
        let now = self.servo.stats.wakeup.summary().count;
        let t0 = Instant::now();
        while self.servo.stats.wakeup.summary().count <= now
            && self.servo.running()
            && t0.elapsed() < Duration::from_millis(100)
        {
            std::thread::sleep(Duration::from_micros(100));
        }
    }

    /// Sends a command and waits for its completion condition.
    pub(super) fn command_done(&self, cmd: MachineCmd, timeout: Duration) -> Result<(), ApiError> {
        let h = self.command(cmd)?;
        match h.wait(timeout) {
            CommandStatus::Done => Ok(()),
            CommandStatus::Failed(why) => Err(ApiError::Failed(why.into())),
            CommandStatus::Rejected(r) => Err(ApiError::Rejected(r.to_string())),
            _ => Err(ApiError::Timeout("the command did not complete".into())),
        }
    }

    /// What the realtime side published, all of it from one servo cycle.
    pub(super) fn snapshot(&self) -> StatusSnapshot {
        lock(&self.readers).status.latest().unwrap_or_default()
    }

    /// The machine's actual pose (machine frame).
    pub(super) fn actual_pose(&self) -> [f64; NUM_AXES] {
        let st = self.snapshot();
        let mut pose = st.setpoints.pose_mm;
        for (_, i) in self.axes() {
            if st.feedback[i].valid {
                pose[i] = st.feedback[i].actual;
            }
        }
        pose
    }

    /// The probe input as the last servo cycle saw it (`None`: the machine has none).
    fn probe_active(&self) -> Option<bool> {
        let name = self.config.motion.probe_input.as_deref()?;
        let i = self.io_map.di.iter().position(|c| c.point.name == name)?;
        Some(self.snapshot().inputs.di(i))
    }

    /// Refuses a run or jog the machine cannot take now (e-stop, off, fault, not homed,
    /// busy), with the machine task's own reason: checked before anything about the job, so
    /// that the operator hears about the e-stop, not about a job planned elsewhere.
    pub(super) fn check_can_run(&self, manual: bool) -> Result<(), ApiError> {
        let snap = self.snapshot().machine;
        let all = self.axes().iter().fold(0u32, |m, &(_, i)| m | 1 << i);
        let homed = snap.homed_mask & all == all;
        let req = if manual { Request::Jog } else { Request::Run };
        ModeMachine::check(snap.mode, req, homed || manual)
            .map_err(|why| ApiError::Rejected(why.into()))
    }

    /// Starts a prepared job (or jog/MDI) as job `id`: feeder first, then the `run` command.
    pub(super) fn start_job(&self, job: Arc<PreparedJob>, manual: bool) -> Result<(), ApiError> {
        self.check_can_run(manual)?;
        // The end of the previous job may still wait in the event queue (the machine task
        // emits it in the cycle whose snapshot said idle). Applying it now, while that job
        // is still the active one, publishes its end and joins its feeder before this job
        // replaces it. (Events carry their job id, so a late one could not end this job
        // either: that was the benchmark's hung `mdi M8`.)
        self.pump_events();
        probing::check_probe_start(&job, self.probe_active())?;
        let pose = self.actual_pose();
        for &(c, i) in self.axes().iter() {
            if (job.plan.start_mm[i] - pose[i]).abs() > 0.01 {
                return Err(ApiError::Rejected(format!(
                    "axis {c} is at {:.4}, the job was planned from {:.4}: load it again",
                    pose[i], job.plan.start_mm[i]
                )));
            }
        }
        let id = self.next_job.fetch_add(1, Ordering::Relaxed);
        let cancel = Arc::new(AtomicBool::new(false));
        let messages = Arc::new(Mutex::new(Vec::new()));
        let measured = Arc::new(Mutex::new(None));
        let (primer, primed) = Primer::new();
        let (feeder, items) = match &job.probing {
            None => {
                lock(&messages).clone_from(&job.plan.messages);
                let queue = self.queue.clone();
                let items = job.clone();
                let cancel = cancel.clone();
                let (book, machine) = (self.book.clone(), self.machine.clone());
                let servo = self.servo.clone();
                let feeder = std::thread::Builder::new()
                    .name(format!("feeder-{id}"))
                    .spawn(move || match &items.replay {
                        None => {
                            feed(&queue, &items.plan.items, id, &cancel, &servo, &primer);
                        }
                        // A large job is planned again as it runs (see `job`).
                        Some(replay) => {
                            let run = replay.run_ahead(&mut |batch| {
                                feed(&queue, batch, id, &cancel, &servo, &primer)
                            });
                            if let Err(msg) = run {
                                if primer.failed(&msg) {
                                    return; // the starter reports it
                                }
                                tracing::error!("job {id}: {msg}");
                                if let Some(a) = lock(&book).active.as_mut().filter(|a| a.id == id)
                                {
                                    a.error = Some(msg);
                                }
                                if let Ok(h) = machine.send(MachineCmd::Abort) {
                                    let _ = h.wait_accepted(ACCEPT_TIMEOUT);
                                }
                            }
                        }
                    })
                    .map_err(|e| ApiError::Failed(format!("cannot start the feeder: {e}")))?;
                (feeder, job.item_count())
            }
            Some(src) => {
                self.start_piece_runner(src, &job, id, &cancel, (&messages, &measured), primer)?
            }
        };
        let mut book = lock(&self.book);
        book.status = JobStatus {
            name: job.name.clone(),
            state: "running".into(),
            line: 0,
            total_lines: job.total_lines,
            progress: 0.0,
            planned_time_s: job.plan.duration_s,
            elapsed_s: 0.0,
            distance_mm: job.plan.distance_mm,
            distance_to_go_mm: job.plan.distance_mm,
            ..JobStatus::default()
        };
        let previous = book.active.replace(ActiveJob {
            id,
            job,
            cancel: cancel.clone(),
            feeder: Some(feeder),
            started: Instant::now(),
            manual,
            messages,
            error: None,
            measured,
            log: super::job_log::JobLog::new(self.config.gcode.log_dir.clone()),
        });
        drop(book);
        if let Some(mut p) = previous {
            p.cancel.store(true, Ordering::Release);
            if let Some(f) = p.feeder.take() {
                let _ = f.join();
            }
        }
        let started = match wait_primed(&primed) {
            Ok(()) => self.command(MachineCmd::Run {
                job: id,
                items,
                manual,
            }),
            Err(why) => Err(ApiError::Rejected(why)),
        };
        match started {
            // `Failed` means accepted and already ended (a job that fails in its first cycles,
            // before this thread looked: easy on the unpaced simulated clock). It ran: its end
            // event reports why, like any job's, so it stays the active job.
            Ok(_) | Err(ApiError::Failed(_)) => Ok(()),
            Err(e) => {
                cancel.store(true, Ordering::Release);
                let mut book = lock(&self.book);
                if let Some(mut a) = book.active.take() {
                    if let Some(f) = a.feeder.take() {
                        drop(book);
                        let _ = f.join();
                        book = lock(&self.book);
                    }
                }
                book.status.state = "none".into();
                Err(e)
            }
        }
    }

    /// A probing job: plans its first piece now (from the machine's position) and starts
    /// the thread that queues it and the pieces after each probe. Returns the thread and the
    /// first piece's item count.
    fn start_piece_runner(
        &self,
        src: &probing::ProbingSource,
        job: &PreparedJob,
        id: u32,
        cancel: &Arc<AtomicBool>,
        (messages, measured): (&Arc<Mutex<Vec<String>>>, &Measured),
        primer: Primer,
    ) -> Result<(std::thread::JoinHandle<()>, u64), ApiError> {
        // A job that only waits for inputs (M66) runs piece by piece without a probe.
        if let (None, Some(line)) = (
            &self.config.motion.probe_input,
            job::first_probe_line_of(job),
        ) {
            return Err(ApiError::Rejected(format!(
                "{}: line {line} probes (G38.x) but the machine has no probe input \
                 (set motion.probe_input)",
                job.name
            )));
        }
        let mut first = probing::first_piece(src, &self.motion_cfg, job.plan.start_mm)?;
        probing::append_messages(&mut first.plan, messages);
        let items = first.plan.items.len() as u64;
        let snapshot = lock(&self.runtime)
            .as_ref()
            .ok_or_else(|| ApiError::Failed("the machine is shutting down".into()))?
            .reader::<MachineSnapshot>(ports::SNAPSHOT)
            .map_err(|e| ApiError::Failed(e.to_string()))?;
        let runner = probing::PieceRunner {
            queue: self.queue.clone(),
            machine: self.machine.clone(),
            snapshot,
            cfg: self.motion_cfg.clone(),
            job: id,
            name: job.name.clone(),
            cancel: cancel.clone(),
            seen_probe_seq: self.snapshot().machine.probe.seq,
            servo: self.servo.clone(),
            messages: messages.clone(),
            parameters: measured.clone(),
            primer,
        };
        let book = self.book.clone();
        let machine = self.machine.clone();
        let thread = std::thread::Builder::new()
            .name(format!("pieces-{id}"))
            .spawn(move || {
                let primer = runner.primer.clone();
                if let probing::RunnerEnd::Failed(msg) = runner.run(first) {
                    if primer.failed(&msg) {
                        return; // the starter reports it
                    }
                    tracing::error!("job {id}: {msg}");
                    if let Some(a) = lock(&book).active.as_mut().filter(|a| a.id == id) {
                        a.error = Some(msg);
                    }
                    if let Ok(h) = machine.send(MachineCmd::Abort) {
                        let _ = h.wait_accepted(ACCEPT_TIMEOUT);
                    }
                }
            })
            .map_err(|e| ApiError::Failed(format!("cannot start the job thread: {e}")))?;
        Ok((thread, items))
    }

    pub(super) fn axes(&self) -> Vec<(char, usize)> {
        self.config
            .axes
            .iter()
            .map(|a| (axis_letter(a.name as usize), a.name as usize))
            .collect()
    }

    pub(super) fn publish(&self, topic: &str, data: Value) {
        let _ = self.events.send(MachineEvent {
            topic: topic.into(),
            data,
        });
    }
}

/// Waits until a starting job's feeder has primed the queue (see
/// [`feeder`](crate::machine::feeder)); the job's planning error if it failed first. A
/// feeder that ended without a word (cancelled, or its thread gone) and one slower than
/// [`PRIME_TIMEOUT`] let the job start: it then ends, or waits at rest, as before.
fn wait_primed(primed: &Receiver<PrimeNews>) -> Result<(), String> {
    match primed.recv_timeout(PRIME_TIMEOUT) {
        Ok(news) => news,
        Err(RecvTimeoutError::Disconnected) => Ok(()),
        Err(RecvTimeoutError::Timeout) => {
            tracing::warn!(
                "the job's feeder did not prime the queue within {} s; starting anyway",
                PRIME_TIMEOUT.as_secs()
            );
            Ok(())
        }
    }
}
