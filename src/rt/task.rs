//! Tasks: the [`Task`] trait (lifecycle hooks, the periodic algorithm, commands) and the
//! lifecycle states.
//!
//! Lifecycle (Orocos `TaskState`): `Unconfigured --configure--> Stopped --start--> Running
//! --stop--> Stopped --cleanup--> Unconfigured`. A recoverable error from `update` moves a
//! running task to `Exception`, where its `error` hook runs every cycle instead of `update`
//! until it is recovered; a fatal error moves it to `Fatal`, where nothing runs any more.
//! Every hook has a default that does nothing, so a task implements only what it needs.

use super::command::{Commands, Progress, RejectReason};
use super::deploy::Configure;
use std::sync::atomic::{AtomicU8, Ordering};

/// Lifecycle state of a task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub enum TaskState {
    /// Created; `configure` not run yet (or undone by `cleanup`).
    Unconfigured,
    /// Configured, not running.
    Stopped,
    /// Running: stepped by its activity, accepting commands.
    Running,
    /// A recoverable error: `error` runs instead of `update`, commands are rejected.
    Exception,
    /// An unrecoverable error: nothing runs.
    Fatal,
}

impl TaskState {
    fn code(self) -> u8 {
        match self {
            Self::Unconfigured => 0,
            Self::Stopped => 1,
            Self::Running => 2,
            Self::Exception => 3,
            Self::Fatal => 4,
        }
    }

    fn from_code(c: u8) -> Self {
        match c {
            0 => Self::Unconfigured,
            1 => Self::Stopped,
            2 => Self::Running,
            3 => Self::Exception,
            _ => Self::Fatal,
        }
    }
}

/// A task's state, readable from any thread, written by whoever runs its hooks.
#[derive(Debug)]
pub struct StateCell(AtomicU8);

impl StateCell {
    pub(crate) fn new(s: TaskState) -> Self {
        Self(AtomicU8::new(s.code()))
    }

    /// Current state.
    pub fn get(&self) -> TaskState {
        TaskState::from_code(self.0.load(Ordering::Acquire))
    }

    pub(crate) fn set(&self, s: TaskState) {
        self.0.store(s.code(), Ordering::Release);
    }
}

/// An error returned by a task hook.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TaskError {
    /// The task can continue after its `error` hook handled this (state `Exception`).
    #[error("recoverable: {0}")]
    Recoverable(&'static str),
    /// The task cannot continue (state `Fatal`).
    #[error("fatal: {0}")]
    Fatal(&'static str),
}

/// What a task sees of the current cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepContext {
    /// Start time of this cycle (the deadline it was scheduled for), from the activity's clock.
    pub now_ns: u64,
    /// Period of the activity (0 for a non-periodic task woken by work).
    pub period_ns: u64,
    /// Cycle counter of the activity, from 0.
    pub cycle: u64,
}

/// A task: what it computes and which requests it serves, independent of which thread runs
/// it ("what vs when").
///
/// The hooks run on the task's activity thread once it is started, so `update`,
/// `read_inputs`, `state_machines`, `programs`, `accept`, `progress`, `process_events`,
/// `error` and `stop` must be realtime safe: no allocation, lock, blocking call or
/// synchronous logging. `configure`, `start` and `cleanup` run on the deploying thread.
pub trait Task: Send + 'static {
    /// The commands (operations) this task accepts; [`NoCommands`](super::command::NoCommands)
    /// if none.
    type Command: Commands;

    /// Creates ports, events, subscriptions and peer links through `ctx`.
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        let _ = ctx;
        Ok(())
    }
    /// Runs before the first cycle.
    fn start(&mut self) -> Result<(), TaskError> {
        Ok(())
    }
    /// Step 1: read input ports into the task's working copies.
    fn read_inputs(&mut self, ctx: &StepContext) {
        let _ = ctx;
    }
    /// Step 2: the periodic algorithm (also writes output ports).
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError>;
    /// Step 3: state machines (hook; their language is a later issue).
    fn state_machines(&mut self, ctx: &StepContext) {
        let _ = ctx;
    }
    /// Step 4: programs (hook; their language is a later issue).
    fn programs(&mut self, ctx: &StepContext) {
        let _ = ctx;
    }
    /// Step 5a: accept or reject a command taken from the queue. The default accepts.
    fn accept(&mut self, command: &Self::Command, ctx: &StepContext) -> Result<(), RejectReason> {
        let _ = (command, ctx);
        Ok(())
    }
    /// Step 5b: the completion condition of an accepted command, evaluated every cycle from
    /// the cycle after acceptance. The default completes at once.
    fn progress(&mut self, command: &Self::Command, ctx: &StepContext) -> Progress {
        let _ = (command, ctx);
        Progress::Done
    }
    /// Step 6: deferred event handlers (drain the task's event receivers here).
    fn process_events(&mut self, ctx: &StepContext) {
        let _ = ctx;
    }
    /// Runs instead of `update` every cycle while in `Exception`.
    fn error(&mut self, ctx: &StepContext) {
        let _ = ctx;
    }
    /// Runs when the task stops (on its activity thread).
    fn stop(&mut self) {}
    /// Undoes `configure`.
    fn cleanup(&mut self) {}
    /// For a non-periodic task: whether it has work besides queued commands (for example
    /// queued events), so the activity wakes it. Periodic tasks run every cycle regardless.
    fn has_work(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_codes_round_trip() {
        for s in [
            TaskState::Unconfigured,
            TaskState::Stopped,
            TaskState::Running,
            TaskState::Exception,
            TaskState::Fatal,
        ] {
            let c = StateCell::new(TaskState::Unconfigured);
            c.set(s);
            assert_eq!(c.get(), s);
        }
    }
}
