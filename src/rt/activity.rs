//! Activities: what runs a group of tasks, and when.
//!
//! A [`PeriodicActivity`] is one thread per (priority, period): `SCHED_FIFO` at the given
//! priority, optionally pinned to a CPU, stack prefaulted, sleeping to absolute deadlines
//! (`clock_nanosleep(TIMER_ABSTIME)` on `CLOCK_MONOTONIC`, so wake-up error does not
//! accumulate into drift). Each cycle it steps its periodic tasks in start order, then its
//! non-periodic tasks that have work, and only while the cycle has time left, so they never
//! delay the next periodic cycle. It records the wake-up latency (actual wake-up minus
//! deadline) and the cycle's execution time, counts overruns (cycle end after the next
//! deadline), skips missed periods instead of bursting to catch up, and emits an
//! [`Overrun`] event after `storm_threshold` consecutive overruns.
//!
//! A [`SteppedActivity`] runs the same group code on the caller's thread against a
//! [`SimClock`](super::clock::SimClock): tests run N cycles deterministically.
//!
//! A periodic activity on a *simulated clock* ([`PeriodicActivity::spawn_simulated`]) runs
//! the same group on its own ordinary thread, but its time advances exactly one period per
//! cycle whatever the wall clock does: cycles run back to back (or paced at a multiple of
//! real time), none is ever skipped and no overrun is counted. A daemon under test then shows
//! the same cycle-by-cycle behaviour however loaded its host is (`[[thread]] clock =
//! "simulated"`).
//!
//! Without the privilege for `SCHED_FIFO` the thread still runs with ordinary scheduling,
//! logs one warning (see [`system::warn_not_realtime`]) and reports `realtime: false`.
//!
//! Every activity marks the thread it runs a cycle on while the cycle runs
//! ([`in_rt_step`]): a counting allocator in a test binary uses the mark to count the
//! allocations made inside realtime steps on any thread, the `SCHED_FIFO` one included.

use super::clock::{monotonic_ns, Clock, SimClock};
use super::event::EventSource;
use super::runner::Runnable;
use super::stats::TimingStats;
use super::system;
use super::task::StepContext;
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

thread_local! {
    /// Set while this thread runs a cycle of a task group. `const`-initialised and without a
    /// destructor, so reading it never allocates (a global allocator may read it).
    static IN_RT_STEP: Cell<bool> = const { Cell::new(false) };
}

/// True while the calling thread runs a realtime cycle (the steps of a task group, the
/// timing and overrun accounting after them), on any activity. For the zero-allocation
/// tests: their counting global allocator reads it to count allocations made inside steps on
/// every thread. Reading it never allocates and never panics (false during thread teardown).
#[doc(hidden)]
#[inline]
pub fn in_rt_step() -> bool {
    IN_RT_STEP.try_with(Cell::get).unwrap_or(false)
}

/// Runs `f` with the calling thread marked as inside a realtime cycle. Costs two
/// thread-local stores per cycle; the mark is cleared even if `f` unwinds.
#[inline]
fn in_cycle<R>(f: impl FnOnce() -> R) -> R {
    struct Clear;
    impl Drop for Clear {
        fn drop(&mut self) {
            let _ = IN_RT_STEP.try_with(|c| c.set(false));
        }
    }
    let _ = IN_RT_STEP.try_with(|c| c.set(true));
    let _clear = Clear;
    f()
}

/// Scheduling of one thread.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct ThreadSpec {
    /// Name (also the OS thread name, truncated to 15 bytes).
    pub name: String,
    /// `SCHED_FIFO` priority, 1..=99.
    pub priority: i32,
    /// Period in nanoseconds.
    pub period_ns: u64,
    /// CPU to pin to, if any.
    pub cpu: Option<usize>,
}

/// Payload of the overrun-storm event of a thread (`<thread>.overrun`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Overrun {
    /// Consecutive overruns when the event was raised.
    pub consecutive: u64,
    /// Overruns since start.
    pub total: u64,
    /// Cycle at which it was raised.
    pub cycle: u64,
}

/// What to do about overruns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct OverrunPolicy {
    /// Raise the thread's [`Overrun`] event when this many consecutive cycles overran (0:
    /// never). The event is raised once per storm (again only after an on-time cycle).
    pub storm_threshold: u64,
}

impl Default for OverrunPolicy {
    fn default() -> Self {
        Self { storm_threshold: 3 }
    }
}

/// The thread-level state shared with non-realtime readers.
pub struct ThreadInfo {
    /// Scheduling.
    pub spec: ThreadSpec,
    /// Wake-up latency, cycle execution time, overruns.
    pub stats: TimingStats,
    realtime: AtomicBool,
    running: AtomicBool,
}

impl ThreadInfo {
    pub(crate) fn new(spec: ThreadSpec, stats: TimingStats) -> Self {
        Self {
            spec,
            stats,
            realtime: AtomicBool::new(false),
            running: AtomicBool::new(false),
        }
    }

    /// True if the thread got `SCHED_FIFO` (and memory is locked).
    pub fn realtime(&self) -> bool {
        self.realtime.load(Ordering::Acquire)
    }

    /// True while the thread runs.
    pub fn running(&self) -> bool {
        self.running.load(Ordering::Acquire)
    }
}

impl std::fmt::Debug for ThreadInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ThreadInfo")
            .field("spec", &self.spec)
            .field("realtime", &self.realtime())
            .finish()
    }
}

/// The tasks of one thread and the code of one cycle, shared by both activities.
pub struct TaskGroup {
    pub(crate) info: Arc<ThreadInfo>,
    pub(crate) periodic: Vec<Box<dyn Runnable>>,
    pub(crate) non_periodic: Vec<Box<dyn Runnable>>,
    pub(crate) policy: OverrunPolicy,
    pub(crate) overrun_event: Option<EventSource<Overrun>>,
    cycle: u64,
    storm_reported: bool,
}

impl TaskGroup {
    /// A group with no tasks (the latency tool measures exactly this).
    pub fn new(spec: ThreadSpec, stats: TimingStats, policy: OverrunPolicy) -> Self {
        Self {
            info: Arc::new(ThreadInfo::new(spec, stats)),
            periodic: Vec::new(),
            non_periodic: Vec::new(),
            policy,
            overrun_event: None,
            cycle: 0,
            storm_reported: false,
        }
    }

    /// Shared thread information (statistics, realtime flag).
    pub fn info(&self) -> &Arc<ThreadInfo> {
        &self.info
    }

    /// Sets the emitter of the thread's overrun event.
    pub fn set_overrun_event(&mut self, source: EventSource<Overrun>) {
        self.overrun_event = Some(source);
    }

    /// One cycle scheduled at `deadline_ns`: periodic tasks in start order, then non-periodic
    /// tasks with work while `now()` is before `budget_end_ns`.
    fn run_tasks(
        &mut self,
        deadline_ns: u64,
        budget_end_ns: u64,
        now: &dyn Fn() -> u64,
        mono: Option<u64>,
    ) {
        let ctx = StepContext {
            now_ns: deadline_ns,
            period_ns: self.info.spec.period_ns,
            cycle: self.cycle,
        };
        for t in &mut self.periodic {
            t.step(&ctx, mono);
        }
        let np_ctx = StepContext {
            period_ns: 0,
            ..ctx
        };
        for t in &mut self.non_periodic {
            if now() >= budget_end_ns {
                break;
            }
            if t.has_work() {
                t.step(&np_ctx, mono);
            }
        }
        self.cycle += 1;
    }

    /// Records the cycle's overrun state and raises the storm event when due.
    fn account_overrun(&mut self, overran: bool) {
        let stats = &self.info.stats;
        let consecutive = stats.record_overrun(overran);
        if consecutive == 0 {
            self.storm_reported = false;
            return;
        }
        let threshold = self.policy.storm_threshold;
        if threshold > 0 && consecutive >= threshold && !self.storm_reported {
            self.storm_reported = true;
            if let Some(ev) = &mut self.overrun_event {
                ev.emit(Overrun {
                    consecutive,
                    total: stats.overruns(),
                    cycle: self.cycle,
                });
            }
        }
    }

    /// Starts every task in start order (periodic first).
    pub(crate) fn start_tasks(&mut self) -> Result<(), (String, super::task::TaskError)> {
        for t in self.periodic.iter_mut().chain(self.non_periodic.iter_mut()) {
            t.start().map_err(|e| (t.shared().name.clone(), e))?;
        }
        Ok(())
    }

    /// Stops every task, in reverse start order.
    pub(crate) fn stop_tasks(&mut self) {
        for t in self
            .non_periodic
            .iter_mut()
            .rev()
            .chain(self.periodic.iter_mut().rev())
        {
            t.stop();
        }
    }

    /// Cycles run so far.
    pub fn cycles(&self) -> u64 {
        self.cycle
    }
}

/// Errors starting a periodic activity.
#[derive(Debug, thiserror::Error)]
pub enum ActivityError {
    /// The OS refused to create the thread.
    #[error("cannot spawn thread '{name}': {source}")]
    Spawn {
        /// Thread name.
        name: String,
        /// OS error.
        source: std::io::Error,
    },
    /// Period 0.
    #[error("thread '{0}' has period 0")]
    ZeroPeriod(String),
}

/// Stack reserved and prefaulted for each realtime thread.
pub const RT_STACK_BYTES: usize = 512 * 1024;
const PREFAULT_BYTES: usize = 256 * 1024;

/// A running periodic thread. Stop it with [`stop`](Self::stop) to get its tasks back.
pub struct PeriodicActivity {
    info: Arc<ThreadInfo>,
    stop: Arc<AtomicBool>,
    handle: Option<std::thread::JoinHandle<TaskGroup>>,
}

impl PeriodicActivity {
    /// Spawns the thread and starts cycling `group` (its tasks must already be started).
    pub fn spawn(group: TaskGroup) -> Result<Self, ActivityError> {
        Self::spawn_with(group, None)
    }

    /// Spawns the thread on a simulated clock: an ordinary (not `SCHED_FIFO`) thread whose
    /// tasks see time advance one period per cycle, paced by `pace`; no overrun accounting.
    /// For tests of behaviour, not timing: see the module documentation.
    pub fn spawn_simulated(group: TaskGroup, pace: SimPace) -> Result<Self, ActivityError> {
        Self::spawn_with(group, Some(pace))
    }

    fn spawn_with(mut group: TaskGroup, sim: Option<SimPace>) -> Result<Self, ActivityError> {
        let spec = group.info.spec.clone();
        if spec.period_ns == 0 {
            return Err(ActivityError::ZeroPeriod(spec.name));
        }
        let info = group.info.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread_name: String = spec.name.chars().take(15).collect();
        let handle = std::thread::Builder::new()
            .name(thread_name)
            .stack_size(RT_STACK_BYTES)
            .spawn(move || {
                match sim {
                    None => {
                        thread_setup(&group.info);
                        run_loop(&mut group, &stop2);
                    }
                    Some(pace) => {
                        tracing::info!(
                            thread = %group.info.spec.name,
                            "simulated clock ({pace:?}): not realtime, no overrun accounting"
                        );
                        run_sim_loop(&mut group, &stop2, pace);
                    }
                }
                group.stop_tasks();
                group.info.running.store(false, Ordering::Release);
                group
            })
            .map_err(|source| ActivityError::Spawn {
                name: spec.name.clone(),
                source,
            })?;
        info.running.store(true, Ordering::Release);
        Ok(Self {
            info,
            stop,
            handle: Some(handle),
        })
    }

    /// Thread information and statistics.
    pub fn info(&self) -> &Arc<ThreadInfo> {
        &self.info
    }

    /// Stops the thread after its current cycle, runs the tasks' `stop` hooks on it, and
    /// returns the group. Waits at most about one period.
    pub fn stop(mut self) -> Option<TaskGroup> {
        self.stop.store(true, Ordering::Release);
        self.handle.take().and_then(|h| h.join().ok())
    }
}

impl Drop for PeriodicActivity {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn thread_setup(info: &ThreadInfo) {
    let spec = &info.spec;
    if let Some(cpu) = spec.cpu {
        if let Err(e) = system::pin_to_cpu(cpu) {
            tracing::warn!(thread = %spec.name, "{e}");
        }
    }
    let fifo = system::set_fifo_priority(spec.priority);
    if let Err(e) = &fifo {
        system::warn_not_realtime(&e.to_string());
    } else if !system::memory_locked() {
        system::warn_not_realtime("memory not locked: call rt::system::lock_memory() at start");
    }
    info.realtime
        .store(fifo.is_ok() && system::memory_locked(), Ordering::Release);
    system::prefault_stack(PREFAULT_BYTES);
}

/// Sleeps until `deadline_ns` on `CLOCK_MONOTONIC` (absolute, restarts on signals).
#[inline]
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec; null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

fn run_loop(group: &mut TaskGroup, stop: &AtomicBool) {
    let period = group.info.spec.period_ns;
    let mut deadline = monotonic_ns() + period;
    while !stop.load(Ordering::Acquire) {
        sleep_until_ns(deadline);
        deadline = in_cycle(|| real_time_cycle(group, deadline));
    }
}

/// One cycle of the real-time loop scheduled at `deadline`; returns the next deadline.
#[inline]
fn real_time_cycle(group: &mut TaskGroup, deadline: u64) -> u64 {
    let period = group.info.spec.period_ns;
    let woke = monotonic_ns();
    group
        .info
        .stats
        .wakeup
        .record(woke.saturating_sub(deadline));
    let next = deadline + period;
    // Non-periodic work may use up to three quarters of the period.
    group.run_tasks(
        deadline,
        deadline + period * 3 / 4,
        &monotonic_ns,
        Some(deadline),
    );
    let end = monotonic_ns();
    group.info.stats.exec.record(end.saturating_sub(woke));
    let overran = end > next;
    group.account_overrun(overran);
    if overran {
        // Skip the periods already missed rather than running them back to back.
        let missed = (end - next) / period + 1;
        next + missed * period
    } else {
        next
    }
}

/// How a periodic activity on a simulated clock keeps pace with the wall clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimPace {
    /// Cycles back to back, as fast as the CPU allows.
    Unpaced,
    /// At most `speed` simulated seconds per wall-clock second (1.0: real time); a cycle
    /// that is late runs at once, and later ones catch up, none skipped.
    Speed(f64),
}

/// The loop of a periodic activity on a simulated clock: time advances one period per cycle
/// whatever the wall clock says, so the tasks see exactly the cycles a stepped runtime would
/// run; nothing is skipped and no overrun is counted (there is no deadline to miss).
fn run_sim_loop(group: &mut TaskGroup, stop: &AtomicBool, pace: SimPace) {
    let period = group.info.spec.period_ns;
    let wall_start = monotonic_ns();
    let mut deadline = wall_start;
    let mut n: u64 = 0;
    while !stop.load(Ordering::Acquire) {
        if let SimPace::Speed(speed) = pace {
            let due = wall_start + ((n as f64 * period as f64) / speed) as u64;
            if monotonic_ns() < due {
                sleep_until_ns(due);
            }
        }
        in_cycle(|| {
            let woke = monotonic_ns();
            group.info.stats.wakeup.record(0);
            // Simulated time stands still during the cycle: every non-periodic task with
            // work runs, as on the stepped activity.
            // No start latency per task: the deadline is not on `CLOCK_MONOTONIC`.
            group.run_tasks(deadline, u64::MAX, &|| deadline, None);
            group
                .info
                .stats
                .exec
                .record(monotonic_ns().saturating_sub(woke));
        });
        deadline += period;
        n += 1;
    }
}

/// Runs a group on the caller's thread against a simulated clock: one call, one cycle.
pub struct SteppedActivity {
    group: TaskGroup,
    clock: SimClock,
    next_deadline_ns: u64,
}

impl SteppedActivity {
    /// Wraps `group` (tasks already started); the first cycle runs at the clock's current time.
    pub fn new(group: TaskGroup, clock: SimClock) -> Self {
        let next_deadline_ns = clock.now_ns();
        Self {
            group,
            clock,
            next_deadline_ns,
        }
    }

    /// Deadline of the next cycle.
    pub fn next_deadline_ns(&self) -> u64 {
        self.next_deadline_ns
    }

    /// Runs one cycle: moves the clock to the cycle's deadline, steps the tasks, and counts an
    /// overrun if the tasks moved the simulated clock past the next deadline.
    pub fn step(&mut self) {
        in_cycle(|| self.step_cycle());
    }

    fn step_cycle(&mut self) {
        let deadline = self.next_deadline_ns;
        self.clock.set_ns(deadline);
        self.group.info.stats.wakeup.record(0);
        let period = self.group.info.spec.period_ns;
        let clock = self.clock.clone();
        self.group
            .run_tasks(deadline, u64::MAX, &move || clock.now_ns(), None);
        let end = self.clock.now_ns();
        self.group.info.stats.exec.record(end - deadline);
        let overran = end > deadline + period;
        self.group.account_overrun(overran);
        self.next_deadline_ns = deadline + period;
    }

    /// Runs `n` cycles.
    pub fn run_cycles(&mut self, n: u64) {
        for _ in 0..n {
            self.step();
        }
    }

    /// The group.
    pub fn group(&self) -> &TaskGroup {
        &self.group
    }

    /// Stops the tasks (their `stop` hooks run here) and returns the group.
    pub fn stop(mut self) -> TaskGroup {
        self.group.stop_tasks();
        self.group
    }
}
