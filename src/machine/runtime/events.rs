//! The bridge from the realtime side to operators: drains the machine task's events (mode,
//! job, fault) and the Modbus link events, keeps the job book, publishes progress, and words
//! each trip the way an operator reads it. Runs on the bridge thread and in `status`, never
//! on the servo thread.

#[allow(clippy::wildcard_imports)]
use super::*;

/// Words an operator can act on, for each trip.
pub fn describe_trip(trip: &Trip, line: u32) -> String {
    let at = if line > 0 {
        format!(" (line {line})")
    } else {
        String::new()
    };
    match *trip {
        Trip::Estop => format!("e-stop{at}"),
        Trip::DriveFault { axis, code } => {
            format!("axis {}: drive fault 0x{code:04X}{at}", axis_letter(axis))
        }
        Trip::FollowingError { axis, error, limit } => format!(
            "axis {}: following error {error:.4} exceeds the limit {limit}{at}",
            axis_letter(axis)
        ),
        Trip::SoftLimit { axis, position } => format!(
            "axis {}: commanded position {position:.4} outside the soft limits{at}",
            axis_letter(axis)
        ),
        Trip::LimitSwitch { axis } => format!("axis {}: limit switch hit{at}", axis_letter(axis)),
        Trip::CommunicationLost { axis } if axis == usize::MAX => {
            format!("I/O: communication lost, e-stop state unknown{at}")
        }
        Trip::CommunicationLost { axis } => {
            format!("axis {}: drive communication lost{at}", axis_letter(axis))
        }
        Trip::SpindleNotAtSpeed => format!("spindle did not reach speed{at}"),
        Trip::PlcFault => format!("PLC fault (see the plc.fault event){at}"),
        Trip::HomingFailed { axis } => format!("axis {}: homing failed", axis_letter(axis)),
        Trip::Fieldbus { axis, fault } => format!("axis {}: {fault}{at}", axis_letter(axis)),
        Trip::OverrunStorm { consecutive } => {
            format!("servo thread overran its period {consecutive} times in a row{at}")
        }
    }
}

fn trip_json(trip: &Trip, line: u32) -> Value {
    let (axis, value) = match *trip {
        Trip::DriveFault { axis, code } => (Some(axis), Some(f64::from(code))),
        Trip::Fieldbus { axis, fault } => (Some(axis), Some(f64::from(fault.code))),
        Trip::FollowingError { axis, error, .. } => (Some(axis), Some(error)),
        Trip::SoftLimit { axis, position } => (Some(axis), Some(position)),
        _ => (trip.axis(), None),
    };
    json!({
        "message": describe_trip(trip, line),
        "kind": format!("{trip:?}").split([' ', '{']).next().unwrap_or(""),
        "axis": axis.filter(|&a| a < NUM_AXES).map(|a| axis_letter(a).to_string()),
        "value": value,
        "line": line,
    })
}

/// Forwards realtime events to subscribers, keeps the job book, publishes progress.
/// The realtime side's event receivers, drained by the bridge thread and by `status`.
pub(super) struct Receivers {
    pub(super) mode: EventReceiver<ModeEvent>,
    pub(super) job: EventReceiver<JobNews>,
    pub(super) fault: EventReceiver<FaultEvent>,
    /// The PLC task's faults (`None` without `[plc]`).
    pub(super) plc: Option<EventReceiver<crate::plc::task::PlcFault>>,
    /// Job events lost so far to a full `job` receiver (already reported).
    pub(super) job_lost: u64,
}

impl Machine {
    /// This machine's identity for [`job_cancel::with_owner`]: its address, fixed while it
    /// lives (a deployed machine is shared in an `Arc`).
    pub(super) fn preparation_owner(&self) -> usize {
        self as *const Machine as usize
    }

    /// Keeps `msg` in the fault history (status `faults`), the oldest dropped when full.
    fn remember_fault(&self, msg: String) {
        let mut book = lock(&self.book);
        if book.faults.len() == FAULT_HISTORY {
            book.faults.pop_front();
        }
        book.faults.push_back(msg);
    }

    /// A snapshot and the job book (the job's status and the fault history) in step: every
    /// job event of the snapshot's cycle and before is applied, and none after it.
    ///
    /// The machine task emits a job event in the same cycle as its mode change (an M0's hold,
    /// a job's end), and the snapshot is published at the end of that cycle. Events drained
    /// after the snapshot was read include every one of its cycle and before, so a status
    /// never shows the new mode with the old job state. But on a fast (unpaced, simulated)
    /// servo they may also include events of later cycles, which would show a job
    /// "holding" beside the mode and position of a cycle before the hold; then the snapshot
    /// is read again until it has caught up. The servo publishes within a cycle, so this
    /// ends at once; a stopped servo (nothing newer will come) ends it after a short wait.
    pub(super) fn consistent_view(&self) -> (StatusSnapshot, JobStatus, Vec<String>) {
        let deadline = Instant::now() + Duration::from_millis(50);
        loop {
            let st = self.snapshot();
            self.pump_events();
            // Checked and copied under one lock: the bridge thread applies events too.
            let book = lock(&self.book);
            if book.news_cycle <= st.cycle || Instant::now() >= deadline {
                let mut job = book.status.clone();
                if let Some(a) = &book.active {
                    apply_progress(&mut job, a, &st.setpoints);
                    job.input_wait =
                        crate::machine::servo::input_wait::status(&st.machine.wait, a.id);
                }
                let faults = book.faults.iter().cloned().collect();
                return (st, job, faults);
            }
            drop(book);
            std::thread::yield_now();
        }
    }

    /// Applies and forwards every pending realtime event. Called by the bridge every few
    /// milliseconds, and by `status` after it read the snapshot ([`Self::consistent_view`]).
    pub(super) fn pump_events(&self) {
        let mut guard = lock(&self.receivers);
        let Some(rx) = guard.as_mut() else {
            return;
        };
        while let Some(e) = rx.mode.pop() {
            if e.mode == Mode::Estop {
                // Whatever put the machine in e-stop (its e-stop input, the PLC, the socket):
                // a preparation in progress stops as for the `estop` method.
                job_cancel::cancel_current(self.preparation_owner(), job_cancel::Why::Estop);
            }
            let mode = serde_json::to_value(e.mode).unwrap_or(Value::Null);
            tracing::info!("mode: {mode}");
            self.publish("mode", json!({ "mode": mode }));
        }
        while let Some(f) = rx.fault.pop() {
            let msg = describe_trip(&f.trip, f.line);
            tracing::error!("fault: {msg}");
            self.remember_fault(msg);
            self.publish("fault", trip_json(&f.trip, f.line));
        }
        while let Some(f) = rx.plc.as_mut().and_then(EventReceiver::pop) {
            let msg = format!("PLC: {f}");
            tracing::error!("{msg}");
            self.remember_fault(msg.clone());
            self.publish("plc", json!({ "fault": msg }));
        }
        while let Some(e) = rx.job.pop() {
            handle_job_event(self, e);
        }
        // More messages or log lines reached in a burst than the receiver holds between two
        // drains (about 1,000 in 5 ms): say so rather than lose them silently.
        let lost = rx.job.lost();
        let newly = lost.saturating_sub(rx.job_lost);
        rx.job_lost = lost;
        drop(guard);
        if newly > 0 {
            let msg = format!(
                "{newly} job events (messages, log lines) were reached faster than they could \
                 be reported, and were lost"
            );
            tracing::warn!("{msg}");
            self.publish("message", json!({ "text": msg }));
        }
        if let Some(links) = lock(&self.link_events).as_ref() {
            while let Ok(e) = links.try_recv() {
                self.publish("io", e.to_json());
            }
        }
    }
}

pub(super) fn bridge_loop(machine: std::sync::Weak<Machine>, stop: Arc<AtomicBool>) {
    let mut last_progress = Instant::now();
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(Duration::from_millis(5));
        let Some(m) = machine.upgrade() else {
            return;
        };
        m.pump_events();
        if last_progress.elapsed() >= Duration::from_millis(100) {
            last_progress = Instant::now();
            let running = lock(&m.book).active.is_some();
            if running {
                update_progress(&m);
                let status = lock(&m.book).status.clone();
                m.publish(
                    "progress",
                    serde_json::to_value(status).unwrap_or(Value::Null),
                );
            }
        }
    }
}

fn update_progress(m: &Machine) {
    let sp = m.snapshot().setpoints;
    let mut book = lock(&m.book);
    let JobBook { active, status, .. } = &mut *book;
    if let Some(a) = active {
        apply_progress(status, a, &sp);
    }
}

/// Job progress from the setpoints of one servo cycle: `status` applies the cycle it shows
/// to its own copy, so its position and its progress never come from different cycles.
fn apply_progress(status: &mut JobStatus, a: &ActiveJob, sp: &Setpoints) {
    if sp.job != a.id || sp.tracking {
        return;
    }
    let planned = a.job.plan.duration_s.max(1e-9);
    status.line = sp.line;
    status.progress = (sp.planned_time_done_s / planned).clamp(0.0, 1.0);
    status.elapsed_s = a.started.elapsed().as_secs_f64();
    status.distance_to_go_mm = status.distance_mm * (1.0 - status.progress);
}

/// Operations `call` refuses, with what to use instead. `machine.run` and
/// `machine.continue` name a job by id and count the queue items its feeder pushed: called
/// by hand they start a "job" nothing feeds, which holds the machine in `running` with a
/// stale job status until an abort.
pub(super) fn internal_operation(task: &str, operation: &str) -> Option<&'static str> {
    match (task, operation) {
        ("machine", "run") => Some("job.run, mdi or jog"),
        ("machine", "continue") => Some("job.run (a probing job continues by itself)"),
        _ => None,
    }
}

fn handle_job_event(m: &Machine, news: JobNews) {
    let mut book = lock(&m.book);
    // News of an earlier job (drained after the next one started) must not touch this one.
    if book.active.as_ref().is_some_and(|a| a.id != news.job) {
        return;
    }
    book.news_cycle = book.news_cycle.max(news.cycle);
    let e = news.event;
    let (state, reason, end) = match e {
        JobEvent::Started => ("running", None, false),
        JobEvent::Held { line } => {
            book.status.line = line;
            ("holding", None, false)
        }
        JobEvent::Resumed => ("running", None, false),
        JobEvent::Finished { line } => {
            book.status.line = line;
            ("done", None, true)
        }
        JobEvent::Aborted { line } => match book.active.as_ref().and_then(|a| a.error.clone()) {
            Some(error) => ("failed", Some(error), true),
            None => ("aborted", Some(format!("aborted at line {line}")), true),
        },
        JobEvent::Error { line, error } => ("failed", Some(format!("line {line}: {error}")), true),
        JobEvent::Failed { line, trip } => ("failed", Some(describe_trip(&trip, line)), true),
        JobEvent::Message { id, line } => {
            let text = book
                .active
                .as_ref()
                .and_then(|a| lock(&a.messages).get(id as usize).cloned())
                .unwrap_or_default();
            drop(book);
            tracing::info!("message (line {line}): {text}");
            m.publish("message", json!({"text": text, "line": line}));
            return;
        }
        JobEvent::Log { id, kind, line } => {
            let Some(a) = book.active.as_mut() else {
                return;
            };
            let text = lock(&a.messages)
                .get(id as usize)
                .cloned()
                .unwrap_or_default();
            let refused = a.log.apply(kind, &text).err();
            drop(book);
            if let Some(why) = refused {
                tracing::warn!("line {line}: {why}");
                m.publish("message", json!({"text": why, "line": line}));
            }
            return;
        }
    };
    let manual = book.active.as_ref().is_some_and(|a| a.manual);
    book.status.state = state.into();
    if reason.is_some() {
        book.status.reason = reason;
    }
    let mut finished = None;
    if end {
        if let Some(mut a) = book.active.take() {
            a.cancel.store(true, Ordering::Release);
            book.status.elapsed_s = a.started.elapsed().as_secs_f64();
            if state == "done" {
                book.status.progress = 1.0;
                book.status.distance_to_go_mm = 0.0;
                // The job ran to its end: its persistent parameters become the machine's
                // (issue 13; a small file, written on this non-realtime thread).
                // A probing job's are those of its live run, not of its dry run.
                let measured = lock(&a.measured).take();
                let v = match a.job.probing {
                    Some(_) => measured,
                    None => a.job.parameters.clone(),
                };
                if let (Some(p), Some(v)) = (&m.params, v) {
                    if let Err(e) = p.commit(v) {
                        tracing::warn!("saving {}: {e}", p.path().display());
                    }
                }
            }
            finished = a.feeder.take();
        }
    }
    let status = book.status.clone();
    drop(book);
    if let Some(f) = finished {
        let _ = f.join();
    }
    if !manual {
        tracing::info!("job {}: {}", status.name, status.state);
        m.publish("job", serde_json::to_value(status).unwrap_or(Value::Null));
    }
}
