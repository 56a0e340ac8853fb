//! The started application: [`Runtime`] on periodic threads and [`SteppedRuntime`] on simulated
//! time, with their status as data. Why they share a core: both only differ in how their threads
//! are driven; lookups and stopping back into a [`Deployment`] are the same.

use super::registry::Registry;
use super::{DeployError, Deployment};
use crate::rt::activity::{
    OverrunPolicy, PeriodicActivity, SteppedActivity, TaskGroup, ThreadInfo, ThreadSpec,
};
use crate::rt::clock::SimClock;
use crate::rt::data_object::DataReader;
use crate::rt::event::{Event, EventCounter};
use crate::rt::json::{JsonEventReceiver, JsonPortReader};
use crate::rt::runner::TaskInfo;
use crate::rt::system;
use crate::rt::task::TaskState;
use std::sync::Arc;

/// Status of a runtime, as data.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RuntimeStatus {
    /// Every thread got `SCHED_FIFO` and memory is locked.
    pub realtime: bool,
    /// Per thread: spec, realtime flag, timing.
    pub threads: Vec<ThreadStatus>,
    /// Per task: name, state, timing.
    pub tasks: Vec<TaskStatus>,
}

/// Status of one thread.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ThreadStatus {
    /// Scheduling.
    pub spec: ThreadSpec,
    /// Got `SCHED_FIFO` with locked memory.
    pub realtime: bool,
    /// Timing.
    pub timing: crate::rt::stats::TimingSummary,
}

/// Status of one task.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TaskStatus {
    /// Name.
    pub name: String,
    /// State.
    pub state: TaskState,
    /// Thread running it.
    pub thread: String,
    /// Execution time of its steps.
    pub timing: crate::rt::stats::TimingSummary,
}

fn task_status(tasks: &[TaskInfo]) -> Vec<TaskStatus> {
    tasks
        .iter()
        .map(|t| TaskStatus {
            name: t.name().to_owned(),
            state: t.state(),
            thread: t.thread().to_owned(),
            timing: t.timing(),
        })
        .collect()
}

/// What both runtimes share: the registry of ports and events, the tasks and the overrun
/// policy. The runtimes differ only in how their threads are driven.
pub(super) struct RuntimeCore {
    pub(super) reg: Registry,
    pub(super) tasks: Vec<TaskInfo>,
    pub(super) policy: OverrunPolicy,
}

impl From<Deployment> for RuntimeCore {
    fn from(d: Deployment) -> Self {
        RuntimeCore {
            reg: d.reg,
            tasks: d.tasks,
            policy: d.policy,
        }
    }
}

impl RuntimeCore {
    fn task(&self, name: &str) -> Option<&TaskInfo> {
        self.tasks.iter().find(|t| t.name() == name)
    }

    /// Status as data; `simulated` threads never count as realtime.
    fn status(&self, threads: &[Arc<ThreadInfo>], simulated: bool) -> RuntimeStatus {
        let rt = |t: &ThreadInfo| !simulated && t.realtime();
        RuntimeStatus {
            realtime: threads.iter().all(|t| rt(t)),
            threads: threads
                .iter()
                .map(|t| ThreadStatus {
                    spec: t.spec.clone(),
                    realtime: rt(t),
                    timing: t.stats.summary(),
                })
                .collect(),
            tasks: task_status(&self.tasks),
        }
    }

    /// Back to a configured deployment holding the stopped `groups`.
    fn into_deployment(self, groups: Vec<TaskGroup>) -> Deployment {
        Deployment {
            reg: self.reg,
            groups,
            tasks: self.tasks,
            configured: true,
            policy: self.policy,
        }
    }
}

/// Tasks running on periodic threads.
pub struct Runtime {
    pub(super) core: RuntimeCore,
    pub(super) activities: Vec<PeriodicActivity>,
}

impl Runtime {
    /// Every task, in the order added.
    pub fn tasks(&self) -> &[TaskInfo] {
        &self.core.tasks
    }
    /// A task by name.
    pub fn task(&self, name: &str) -> Option<&TaskInfo> {
        self.core.task(name)
    }
    /// The threads.
    pub fn threads(&self) -> Vec<Arc<ThreadInfo>> {
        self.activities.iter().map(|a| a.info().clone()).collect()
    }
    /// True if every thread runs `SCHED_FIFO` with locked memory.
    pub fn realtime(&self) -> bool {
        self.activities.iter().all(|a| a.info().realtime())
    }
    /// Status of threads and tasks, as data.
    pub fn status(&self) -> RuntimeStatus {
        self.core.status(&self.threads(), false)
    }
    /// A new reader of data object `name`.
    pub fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        self.core.reg.reader(name)
    }
    /// A JSON reader of data object `name`, for exporters (see [`crate::rt::json`]).
    pub fn json_reader(&self, name: &str) -> Result<Box<dyn JsonPortReader>, DeployError> {
        self.core.reg.json_reader(name)
    }
    /// Buffer `name` as an ordered JSON stream: the exporter becomes the buffer's single
    /// consumer, so only a buffer no task consumes can be exported (see [`crate::rt::json`]).
    pub fn json_buffer(&mut self, name: &str) -> Result<Box<dyn JsonEventReceiver>, DeployError> {
        self.core.reg.json_buffer(name)
    }
    /// A JSON subscription to event `name` queueing up to `capacity` events, for exporters.
    pub fn json_events(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn JsonEventReceiver>, DeployError> {
        self.core.reg.json_events(name, capacity)
    }
    /// Event `name`: a non-realtime consumer may subscribe (its queue is picked up by the
    /// emitter at its next emit, without blocking it).
    pub fn event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.core.reg.find_event(name)
    }
    /// Event `name` as a type-erased emission counter (scripts wait for events by name).
    pub fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.core.reg.event_counter(name)
    }
    /// Stops every thread (tasks' `stop` hooks run on their threads) and returns the
    /// configured deployment, which can be started again or cleaned up.
    pub fn stop(self) -> Deployment {
        let groups = self
            .activities
            .into_iter()
            .filter_map(PeriodicActivity::stop)
            .collect();
        self.core.into_deployment(groups)
    }
}

/// Tasks stepped on the caller's thread against a simulated clock.
pub struct SteppedRuntime {
    pub(super) core: RuntimeCore,
    pub(super) activities: Vec<SteppedActivity>,
    pub(super) clock: SimClock,
}

impl SteppedRuntime {
    /// Runs every thread's cycles due up to time `t_ns`, in deadline order (ties: higher
    /// priority first), exactly as the threads would have run them.
    pub fn run_until_ns(&mut self, t_ns: u64) {
        loop {
            let next = self
                .activities
                .iter_mut()
                .filter(|a| a.next_deadline_ns() <= t_ns)
                .min_by_key(|a| (a.next_deadline_ns(), -a.group().info().spec.priority));
            match next {
                Some(a) => a.step(),
                None => break,
            }
        }
        self.clock.set_ns(t_ns);
    }

    /// Runs `n` periods of the fastest thread (and whatever slower threads are due).
    pub fn run_cycles(&mut self, n: u64) {
        let Some(period) = self
            .activities
            .iter()
            .map(|a| a.group().info().spec.period_ns)
            .min()
        else {
            return;
        };
        let start = self
            .activities
            .iter()
            .map(SteppedActivity::next_deadline_ns)
            .min()
            .unwrap_or(0);
        self.run_until_ns(start + n * period - 1);
    }

    /// The simulated clock.
    pub fn clock(&self) -> &SimClock {
        &self.clock
    }
    /// Every task.
    pub fn tasks(&self) -> &[TaskInfo] {
        &self.core.tasks
    }
    /// A task by name.
    pub fn task(&self, name: &str) -> Option<&TaskInfo> {
        self.core.task(name)
    }
    /// The threads' information.
    pub fn threads(&self) -> Vec<Arc<ThreadInfo>> {
        self.activities
            .iter()
            .map(|a| a.group().info().clone())
            .collect()
    }
    /// Status as data (`realtime` is always false: simulated time).
    pub fn status(&self) -> RuntimeStatus {
        self.core.status(&self.threads(), true)
    }
    /// A new reader of data object `name`.
    pub fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        self.core.reg.reader(name)
    }
    /// Event `name`.
    pub fn event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.core.reg.find_event(name)
    }
    /// Event `name` as a type-erased emission counter (scripts wait for events by name).
    pub fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.core.reg.event_counter(name)
    }
    /// Stops every task and returns the deployment.
    pub fn stop(self) -> Deployment {
        let groups = self
            .activities
            .into_iter()
            .map(SteppedActivity::stop)
            .collect();
        self.core.into_deployment(groups)
    }
}

/// Whether this process can run realtime, with the warning logged once if not.
pub fn check_realtime() -> system::Capabilities {
    let caps = system::capabilities();
    if !caps.realtime {
        system::warn_not_realtime(if caps.fifo_scheduling {
            "memory not locked"
        } else {
            "no permission for SCHED_FIFO"
        });
    }
    caps
}
