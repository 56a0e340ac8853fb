//! [`Deployment`]: the configuration flow of an application (add tasks to threads, configure
//! them, check the topology, start). Why separate from the runtimes: a deployment is what a
//! stopped runtime gives back, so it can be reconfigured and started again.

use super::registry::Registry;
use super::runtime::RuntimeCore;
use super::{
    CheckReport, Configure, DeployError, Runtime, SteppedRuntime, TopologyErrorKind,
    TopologyErrors, COMMAND_QUEUE_CAPACITY,
};
use crate::rt::activity::{
    Overrun, OverrunPolicy, PeriodicActivity, SimPace, SteppedActivity, TaskGroup, ThreadSpec,
};
use crate::rt::clock::SimClock;
use crate::rt::command::{command_queue, CommandHandle, CommandSender, Commands, SendError};
use crate::rt::data_object::DataReader;
use crate::rt::event::{Event, EventCounter};
use crate::rt::interface::TaskInterface;
use crate::rt::runner::{Runnable, TaskInfo, TaskRunner, TaskShared};
use crate::rt::stats::TimingStats;
use crate::rt::task::{StateCell, Task, TaskState};
use std::sync::Arc;

/// Scheduling of a periodic task; tasks with equal `(priority, period_ns)` share a thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Schedule {
    /// `SCHED_FIFO` priority (1..=99).
    pub priority: i32,
    /// Period in nanoseconds.
    pub period_ns: u64,
    /// CPU to pin the thread to (the first task of a thread decides).
    pub cpu: Option<usize>,
}

/// A task added to a deployment, with its typed command sender.
pub struct TaskHandle<C> {
    pub(super) info: TaskInfo,
    sender: CommandSender<C>,
}

impl<C> Clone for TaskHandle<C> {
    fn clone(&self) -> Self {
        Self {
            info: self.info.clone(),
            sender: self.sender.clone(),
        }
    }
}

impl<C: Commands> TaskHandle<C> {
    /// State, statistics, interface.
    pub fn info(&self) -> &TaskInfo {
        &self.info
    }
    /// The typed sender.
    pub fn sender(&self) -> &CommandSender<C> {
        &self.sender
    }
    /// Sends a typed command.
    pub fn send(&self, command: C) -> Result<CommandHandle, SendError> {
        self.sender.send(command)
    }
}

type RunnerAndHandle<C> = (Box<dyn Runnable>, TaskHandle<C>);

/// The configuration flow of an application.
pub struct Deployment {
    pub(super) reg: Registry,
    pub(super) groups: Vec<TaskGroup>,
    pub(super) tasks: Vec<TaskInfo>,
    pub(super) configured: bool,
    pub(super) policy: OverrunPolicy,
}

impl Default for Deployment {
    fn default() -> Self {
        Self::new()
    }
}

impl Deployment {
    /// An empty deployment with the default overrun policy.
    pub fn new() -> Self {
        Self {
            reg: Registry::default(),
            groups: Vec::new(),
            tasks: Vec::new(),
            configured: false,
            policy: OverrunPolicy::default(),
        }
    }

    /// Sets the overrun policy of threads created from now on.
    pub fn set_overrun_policy(&mut self, policy: OverrunPolicy) {
        self.policy = policy;
    }

    fn group_for(&mut self, s: Schedule) -> usize {
        if let Some(i) = self.groups.iter().position(|g| {
            g.info.spec.priority == s.priority && g.info.spec.period_ns == s.period_ns
        }) {
            return i;
        }
        let spec = ThreadSpec {
            name: format!("rt-p{}-{}us", s.priority, s.period_ns / 1000),
            priority: s.priority,
            period_ns: s.period_ns,
            cpu: s.cpu,
        };
        let mut group = TaskGroup::new(spec.clone(), TimingStats::new(1_000, 10_000), self.policy);
        let name = format!("{}.overrun", spec.name);
        if let Ok(ev) = self.reg.event::<Overrun>(&name) {
            if let Some(e) = self.reg.events.get_mut(&name) {
                e.emitters.push(spec.name.clone());
            }
            if let Ok(src) = ev.source() {
                group.set_overrun_event(src);
            }
        }
        self.groups.push(group);
        self.groups.len() - 1
    }

    fn make_runner<Tk: Task>(
        &mut self,
        name: &str,
        task: Tk,
        periodic: bool,
        thread: &str,
    ) -> Result<RunnerAndHandle<Tk::Command>, DeployError> {
        if self.reg.tasks.contains_key(name) {
            return Err(DeployError::DuplicateTask(name.to_owned()));
        }
        let state = Arc::new(StateCell::new(TaskState::Unconfigured));
        let (sender, rx) =
            command_queue::<Tk::Command>(name, COMMAND_QUEUE_CAPACITY, state.clone());
        let iface = TaskInterface {
            name: name.to_owned(),
            operations: Tk::Command::operations().to_vec(),
            ..TaskInterface::default()
        };
        let shared = Arc::new(TaskShared::new(
            name,
            state,
            iface,
            Arc::new(sender.clone()),
            periodic,
            thread,
        ));
        let info = TaskInfo {
            shared: shared.clone(),
        };
        self.reg
            .tasks
            .insert(name.to_owned(), (info.clone(), Box::new(sender.clone())));
        self.tasks.push(info.clone());
        Ok((
            Box::new(TaskRunner::new(task, shared, rx)),
            TaskHandle { info, sender },
        ))
    }

    /// Adds a periodic task. Tasks with the same `(priority, period)` share one thread and
    /// run in the order they were added (= started).
    pub fn add_periodic<Tk: Task>(
        &mut self,
        name: &str,
        task: Tk,
        schedule: Schedule,
    ) -> Result<TaskHandle<Tk::Command>, DeployError> {
        let g = self.group_for(schedule);
        let thread = self.groups[g].info.spec.name.clone();
        let (runner, handle) = self.make_runner(name, task, true, &thread)?;
        self.groups[g].periodic.push(runner);
        self.configured = false;
        Ok(handle)
    }

    /// Adds a non-periodic task: it runs on the (first) periodic thread of `priority`, after
    /// that thread's periodic tasks, in cycles where it has work (commands, events) and time
    /// is left, so it never delays the periodic work.
    pub fn add_non_periodic<Tk: Task>(
        &mut self,
        name: &str,
        task: Tk,
        priority: i32,
    ) -> Result<TaskHandle<Tk::Command>, DeployError> {
        let g = self
            .groups
            .iter()
            .position(|g| g.info.spec.priority == priority)
            .ok_or_else(|| DeployError::NoThreadForPriority {
                task: name.to_owned(),
                priority,
            })?;
        let thread = self.groups[g].info.spec.name.clone();
        let (runner, handle) = self.make_runner(name, task, false, &thread)?;
        self.groups[g].non_periodic.push(runner);
        self.configured = false;
        Ok(handle)
    }

    /// Runs every task's `configure` hook (in the order added), then checks the topology.
    /// Refuses with every error found; on success returns the warnings.
    pub fn configure(&mut self) -> Result<CheckReport, DeployError> {
        self.reg.errors.clear();
        for g in &mut self.groups {
            for r in g.periodic.iter_mut().chain(g.non_periodic.iter_mut()) {
                let shared = r.shared().clone();
                if shared.state.get() != TaskState::Unconfigured {
                    continue;
                }
                let mut iface = shared.interface_mut().clone();
                let mut ctx = Configure {
                    task: &shared.name,
                    reg: &mut self.reg,
                    iface: &mut iface,
                    wake: shared.wake.clone(),
                };
                if let Err(e) = r.configure(&mut ctx) {
                    self.reg
                        .error(&shared.name, "", TopologyErrorKind::ConfigureFailed(e));
                }
                // The interface grew during configure (ports, events, peers); publish it.
                *shared.interface_mut() = iface;
            }
        }
        let errors = self.reg.check();
        if !errors.is_empty() {
            return Err(DeployError::Topology(TopologyErrors(errors)));
        }
        let mut warnings = self.priority_warnings();
        warnings.extend(self.reg.warnings());
        let report = CheckReport { warnings };
        for w in &report.warnings {
            tracing::warn!("{w}");
        }
        self.configured = true;
        Ok(report)
    }

    fn priority_warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        for a in &self.groups {
            for b in &self.groups {
                let (sa, sb) = (&a.info.spec, &b.info.spec);
                if sa.period_ns > sb.period_ns && sa.priority > sb.priority {
                    out.push(format!(
                        "thread '{}' (period {} us) has priority {} above faster thread '{}' \
                         (period {} us, priority {}): priority should follow rate",
                        sa.name,
                        sa.period_ns / 1000,
                        sa.priority,
                        sb.name,
                        sb.period_ns / 1000,
                        sb.priority
                    ));
                }
            }
        }
        out
    }

    /// Every task, in the order added.
    pub fn tasks(&self) -> &[TaskInfo] {
        &self.tasks
    }

    /// A new reader of data object `name` (for non-realtime code).
    pub fn reader<T: Clone + Default + Send + Sync + 'static>(
        &self,
        name: &str,
    ) -> Result<DataReader<T>, DeployError> {
        self.reg.reader(name)
    }

    /// Event `name` (full name), to subscribe non-realtime consumers before start.
    pub fn event<T: Clone + Send + 'static>(&self, name: &str) -> Result<Event<T>, DeployError> {
        self.reg.find_event(name)
    }
    /// Event `name` as a type-erased emission counter (scripts wait for events by name).
    pub fn event_counter(&self, name: &str) -> Result<EventCounter, DeployError> {
        self.reg.event_counter(name)
    }

    fn start_groups(&mut self) -> Result<(), DeployError> {
        if !self.configured {
            return Err(DeployError::NotConfigured);
        }
        for g in &mut self.groups {
            g.start_tasks()
                .map_err(|(task, error)| DeployError::StartFailed { task, error })?;
        }
        Ok(())
    }

    /// Starts every task (start hooks in start order, on this thread) and one periodic
    /// thread per (priority, period).
    pub fn start(self) -> Result<Runtime, DeployError> {
        self.start_with(None)
    }

    /// Starts every task like [`start`](Self::start), but each thread runs on a simulated
    /// clock ([`PeriodicActivity::spawn_simulated`]): one period per cycle whatever the wall
    /// clock does, no skipped cycles, no overrun accounting, no `SCHED_FIFO`. For tests of
    /// behaviour through the real daemon.
    pub fn start_simulated(self, pace: SimPace) -> Result<Runtime, DeployError> {
        self.start_with(Some(pace))
    }

    fn start_with(mut self, sim: Option<SimPace>) -> Result<Runtime, DeployError> {
        if let Err(e) = self.start_groups() {
            for g in &mut self.groups {
                g.stop_tasks();
            }
            return Err(e);
        }
        let mut activities = Vec::new();
        for g in self.groups.drain(..) {
            activities.push(match sim {
                None => PeriodicActivity::spawn(g)?,
                Some(pace) => PeriodicActivity::spawn_simulated(g, pace)?,
            });
        }
        Ok(Runtime {
            core: RuntimeCore::from(self),
            activities,
        })
    }

    /// Starts every task on a stepped runtime driven by `clock` (tests, simulation).
    pub fn start_stepped(mut self, clock: SimClock) -> Result<SteppedRuntime, DeployError> {
        self.start_groups()?;
        let activities = self
            .groups
            .drain(..)
            .map(|g| SteppedActivity::new(g, clock.clone()))
            .collect();
        Ok(SteppedRuntime {
            core: RuntimeCore::from(self),
            activities,
            clock,
        })
    }

    /// Runs every stopped task's `cleanup` hook (back to `Unconfigured`).
    pub fn cleanup(&mut self) {
        for g in &mut self.groups {
            for r in g.periodic.iter_mut().chain(g.non_periodic.iter_mut()) {
                r.cleanup();
                // What configure declared (ports, events, peers) is declared again by the
                // next configure; the operations are the task's own and stay.
                let mut iface = r.shared().interface_mut();
                iface.emits.clear();
                iface.subscribes.clear();
                iface.ports.clear();
                iface.peers.clear();
            }
        }
        // Cleanup undoes configure: the connections the tasks declared go too, and the next
        // `configure` builds them afresh (otherwise every port would be declared twice).
        // Handles taken from the deployment before (readers, events) belong to the old
        // connections: take new ones after configuring again.
        self.reg.objects.clear();
        self.reg.buffers.clear();
        self.reg.events.clear();
        self.reg.errors.clear();
        self.configured = false;
    }
}
