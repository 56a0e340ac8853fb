//! The per-task runner: one periodic step of a task in a fixed order, its command processor
//! and its lifecycle transitions.
//!
//! # Step order and why
//! 1. **read inputs** (`Task::read_inputs`): take a consistent snapshot of the inputs first,
//!    so the whole step computes on data of the same instant.
//! 2. **`update`**: the periodic algorithm; it writes the outputs that tasks later in the same
//!    thread read in this very cycle (that is why start order matters and needs no locks).
//! 3. **state machines**, then 4. **programs**: discrete logic reacts to the values just
//!    computed, and may change what the next `update` does; programs come after the state
//!    machines so a program sees the state the machine has settled in.
//! 5. **command processor**: completion conditions of accepted commands are evaluated on the
//!    state after this cycle's algorithm and logic, then at most one new command is taken
//!    (serial execution; only if no running command forbids it, the paper's Fig. 7). A
//!    command accepted here first has its completion evaluated next cycle.
//! 6. **deferred event handlers** (`Task::process_events`): last, the task's safe point,
//!    so that reactions to other tasks' events never interleave with the algorithm and see the
//!    effect of this cycle's commands.
//!
//! In `Exception` the `error` hook replaces steps 1–5 and queued commands are rejected; in any
//! other state than `Running` queued commands are rejected with the state as the reason.

use super::clock::monotonic_ns;
use super::command::{
    CommandReceiver, CommandStatus, Commands, DynCommandSender, NextCommand, Progress,
    RejectReason, Ticket,
};
use super::deploy::Configure;
use super::interface::TaskInterface;
use super::stats::{TimingStats, TimingSummary};
use super::task::{StateCell, StepContext, Task, TaskError, TaskState};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::Arc;

/// Maximum number of accepted commands a task evaluates at once.
pub const MAX_ACTIVE_COMMANDS: usize = 8;

const REQ_STOP: u8 = 1;
const REQ_START: u8 = 2;
const REQ_RECOVER: u8 = 4;

/// What non-realtime code sees of a task (shared with its runner).
pub(crate) struct TaskShared {
    pub(crate) name: String,
    pub(crate) state: Arc<StateCell>,
    pub(crate) stats: TimingStats,
    requests: AtomicU8,
    pub(crate) wake: Arc<AtomicBool>,
    interface: std::sync::Mutex<TaskInterface>,
    pub(crate) sender: Arc<dyn DynCommandSender>,
    pub(crate) periodic: bool,
    pub(crate) thread: String,
}

impl TaskShared {
    /// The interface (configuration and status only; never locked by a step).
    pub(crate) fn interface_mut(&self) -> std::sync::MutexGuard<'_, TaskInterface> {
        self.interface
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    pub(crate) fn new(
        name: &str,
        state: Arc<StateCell>,
        interface: TaskInterface,
        sender: Arc<dyn DynCommandSender>,
        periodic: bool,
        thread: &str,
    ) -> Self {
        Self {
            name: name.to_owned(),
            state,
            stats: TimingStats::for_task(),
            requests: AtomicU8::new(0),
            wake: Arc::new(AtomicBool::new(false)),
            interface: std::sync::Mutex::new(interface),
            sender,
            periodic,
            thread: thread.to_owned(),
        }
    }
}

/// A handle on a deployed task for non-realtime code: state, statistics, interface,
/// dynamic commands and lifecycle requests. Cheap to clone.
#[derive(Clone)]
pub struct TaskInfo {
    pub(crate) shared: Arc<TaskShared>,
}

impl TaskInfo {
    /// Task name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }
    /// Lifecycle state now.
    pub fn state(&self) -> TaskState {
        self.shared.state.get()
    }
    /// Statistics of its steps: `exec` = execution time; `wakeup` = start latency (cycle
    /// deadline to the task's start, on real threads only).
    pub fn stats(&self) -> &TimingStats {
        &self.shared.stats
    }
    /// Summary of [`stats`](Self::stats).
    pub fn timing(&self) -> TimingSummary {
        self.shared.stats.summary()
    }
    /// Operations, events, ports and peers, as data (a copy).
    pub fn interface(&self) -> TaskInterface {
        self.shared.interface_mut().clone()
    }
    /// Sends a command by operation name with dynamic arguments.
    pub fn commands(&self) -> &dyn DynCommandSender {
        &*self.shared.sender
    }
    /// Whether the task is periodic (else it runs when it has work).
    pub fn is_periodic(&self) -> bool {
        self.shared.periodic
    }
    /// Name of the thread (activity) that runs it.
    pub fn thread(&self) -> &str {
        &self.shared.thread
    }
    /// Asks the task's thread to stop the task (runs its `stop` hook there).
    pub fn request_stop(&self) {
        self.shared.requests.fetch_or(REQ_STOP, Ordering::AcqRel);
        self.shared.wake.store(true, Ordering::Release);
    }
    /// Asks the task's thread to start a stopped task again.
    pub fn request_start(&self) {
        self.shared.requests.fetch_or(REQ_START, Ordering::AcqRel);
        self.shared.wake.store(true, Ordering::Release);
    }
    /// Asks the task's thread to bring a task in `Exception` back to `Running`.
    pub fn request_recover(&self) {
        self.shared.requests.fetch_or(REQ_RECOVER, Ordering::AcqRel);
        self.shared.wake.store(true, Ordering::Release);
    }
}

impl std::fmt::Debug for TaskInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TaskInfo")
            .field("name", &self.name())
            .field("state", &self.state())
            .finish()
    }
}

/// The type-erased runner an activity drives.
pub(crate) trait Runnable: Send {
    fn shared(&self) -> &Arc<TaskShared>;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError>;
    fn start(&mut self) -> Result<(), TaskError>;
    /// One step. `deadline_mono_ns`: the cycle's deadline on `CLOCK_MONOTONIC` when running
    /// on a real thread, to record the task's start latency (`None` under simulated time).
    fn step(&mut self, ctx: &StepContext, deadline_mono_ns: Option<u64>);
    fn stop(&mut self);
    fn cleanup(&mut self);
    fn has_work(&self) -> bool;
}

struct Active<C> {
    command: C,
    ticket: Ticket,
    next: NextCommand,
}

/// Runs one task: its hooks, its command processor, its state.
pub(crate) struct TaskRunner<Tk: Task> {
    task: Tk,
    shared: Arc<TaskShared>,
    rx: CommandReceiver<Tk::Command>,
    active: Vec<Active<Tk::Command>>,
}

impl<Tk: Task> TaskRunner<Tk> {
    pub(crate) fn new(task: Tk, shared: Arc<TaskShared>, rx: CommandReceiver<Tk::Command>) -> Self {
        Self {
            task,
            shared,
            rx,
            active: Vec::with_capacity(MAX_ACTIVE_COMMANDS),
        }
    }

    fn set_state(&self, s: TaskState) {
        self.shared.state.set(s);
    }

    fn reject_queued(&mut self, state: TaskState) {
        while let Some((_, ticket)) = self.rx.pop() {
            ticket.set(CommandStatus::Rejected(RejectReason::WrongState(state)));
        }
    }

    fn fail_active(&mut self, why: &'static str) {
        for a in self.active.drain(..) {
            a.ticket.set(CommandStatus::Failed(why));
        }
    }

    fn handle_error(&mut self, e: TaskError) {
        match e {
            TaskError::Recoverable(_) => {
                self.set_state(TaskState::Exception);
                self.fail_active("task entered Exception");
            }
            TaskError::Fatal(_) => {
                self.set_state(TaskState::Fatal);
                self.fail_active("task entered Fatal");
            }
        }
    }

    fn handle_requests(&mut self) {
        let req = self.shared.requests.swap(0, Ordering::AcqRel);
        if req == 0 {
            return;
        }
        let state = self.shared.state.get();
        if req & REQ_STOP != 0 && matches!(state, TaskState::Running | TaskState::Exception) {
            self.stop();
        } else if req & REQ_RECOVER != 0 && state == TaskState::Exception {
            self.set_state(TaskState::Running);
        } else if req & REQ_START != 0 && state == TaskState::Stopped {
            if let Err(e) = self.start() {
                self.handle_error(e);
            }
        }
    }

    fn process_commands(&mut self, ctx: &StepContext) {
        let task = &mut self.task;
        self.active
            .retain(|a| match task.progress(&a.command, ctx) {
                Progress::Running => true,
                Progress::Done => {
                    a.ticket.set(CommandStatus::Done);
                    false
                }
                Progress::Failed(why) => {
                    a.ticket.set(CommandStatus::Failed(why));
                    false
                }
            });
        let blocked = self
            .active
            .iter()
            .any(|a| a.next == NextCommand::AfterCompletion);
        if blocked || self.active.len() == MAX_ACTIVE_COMMANDS {
            return;
        }
        let Some((command, ticket)) = self.rx.pop() else {
            return;
        };
        match self.task.accept(&command, ctx) {
            Ok(()) => {
                ticket.set(CommandStatus::Accepted);
                let next = Tk::Command::operations()
                    .get(command.operation_index())
                    .map_or(NextCommand::AfterCompletion, |d| d.next);
                self.active.push(Active {
                    command,
                    ticket,
                    next,
                });
            }
            Err(reason) => ticket.set(CommandStatus::Rejected(reason)),
        }
    }
}

impl<Tk: Task> Runnable for TaskRunner<Tk> {
    fn shared(&self) -> &Arc<TaskShared> {
        &self.shared
    }

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.task.configure(ctx)?;
        self.set_state(TaskState::Stopped);
        Ok(())
    }

    fn start(&mut self) -> Result<(), TaskError> {
        // Commands that raced with an earlier stop are answered now, not left pending.
        self.reject_queued(TaskState::Stopped);
        self.task.start()?;
        self.set_state(TaskState::Running);
        Ok(())
    }

    fn step(&mut self, ctx: &StepContext, deadline_mono_ns: Option<u64>) {
        self.handle_requests();
        let t0 = monotonic_ns();
        if let Some(d) = deadline_mono_ns {
            // Start latency: deadline to this task's start (includes earlier tasks' work).
            self.shared.stats.wakeup.record(t0.saturating_sub(d));
        }
        match self.shared.state.get() {
            TaskState::Running => {
                self.task.read_inputs(ctx);
                match self.task.update(ctx) {
                    Ok(()) => {
                        self.task.state_machines(ctx);
                        self.task.programs(ctx);
                        self.process_commands(ctx);
                    }
                    Err(e) => self.handle_error(e),
                }
                self.task.process_events(ctx);
            }
            TaskState::Exception => {
                self.task.error(ctx);
                self.reject_queued(TaskState::Exception);
                self.task.process_events(ctx);
            }
            other => self.reject_queued(other),
        }
        self.shared
            .stats
            .exec
            .record(monotonic_ns().saturating_sub(t0));
    }

    fn stop(&mut self) {
        let state = self.shared.state.get();
        if matches!(state, TaskState::Running | TaskState::Exception) {
            self.task.stop();
            self.fail_active("task stopped");
            self.set_state(TaskState::Stopped);
        }
        self.reject_queued(self.shared.state.get());
    }

    fn cleanup(&mut self) {
        if self.shared.state.get() == TaskState::Stopped {
            self.task.cleanup();
            self.set_state(TaskState::Unconfigured);
        }
    }

    fn has_work(&self) -> bool {
        self.shared.wake.swap(false, Ordering::AcqRel) | !self.rx.is_empty() | self.task.has_work()
    }
}
